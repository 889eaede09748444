"""Prediction, validation and evaluation of a trained network.

[`evaluate`][handmesh_tutorial.train.evaluation.evaluate] scores a checkpoint (or a network) on
deterministic crops: FreiHAND-style scores, per-sample errors, the table per visibility-ratio bin
and per scene kind, the constant baselines on the same items, and (with ``out_dir``) ``eval.json``,
``predictions.npz`` and the figures. Errors are computed in millimetres from metre inputs.

Taught in notebook 09 ("Evaluation").

Why one file: prediction, validation and evaluation share the batching, scoring and file
writing here; split, each part would import the others.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .. import metrics as M
from .. import viz
from .._io import (
    atomic_savez,
    check_writable,
    claim_out_dir,
    json_record,
    remove_outputs,
    write_json,
)
from .._optional import require
from .._progress import progress_bar
from ..budget import MAX_BATCH_SIZE, check_count, check_image_size, check_threads
from ..data import KINDS, InterSHDataset
from ..data import augment as A
from ..data import torch_views as TV
from ..data.freihand import NUM_VERTICES, FreiHAND, write_predictions
from ..metrics.surface import flipped_face_fraction, roughness_deg
from ..nn.losses import vertex_loss
from ._distributed import _resolve_device
from .baselines import MEAN_HAND, REST_HAND, _rest_template, constant_hand_predictions
from .checkpoints import load_checkpoint
from .features import model_outputs
from .templates import resolve_template

__all__ = ["predict", "validate", "evaluate"]


def predict(model: nn.Module, images, batch_size: int = 32,
            device: str | torch.device | None = None) -> dict:
    """Run the network on crops, in eval mode, without gradients.

    Args:
        model: an [`MSMRNet`][handmesh_tutorial.nn.model.MSMRNet].
        images: ``(B, 3, S, S)`` normalised float tensor (as the datasets return), or uint8
            ``(B, S, S, 3)`` / ``(S, S, 3)`` RGB crops (normalised here).
        batch_size: images per forward pass.
        device: default: the model's device.

    Returns:
        dict with ``vertices`` ``(B, V, 3)`` and ``joints`` ``(B, 21, 3)`` CPU float32 tensors:
        right-hand, root-relative network frame (see
        [`to_camera`][handmesh_tutorial.data.augment.to_camera] to go back to the camera).

    Shapes:
        ``images (B, 3, S, S)`` float or ``(B, S, S, 3)`` / ``(S, S, 3)`` uint8 -> ``vertices
        (B, V, 3)``, ``joints (B, 21, 3)``.
    """
    if not isinstance(images, torch.Tensor) or images.dtype == torch.uint8:
        arr = images if isinstance(images, torch.Tensor) else np.asarray(images)
        if arr.dtype not in (np.uint8, torch.uint8):
            raise ValueError(f"array images must be uint8 RGB (B, S, S, 3), got {arr.dtype}")
        images = A.normalize_image(arr)
    if images.dim() == 3:
        images = images[None]
    if images.dim() != 4 or images.shape[1] != 3:
        raise ValueError(f"images must be (B, 3, S, S), got {tuple(images.shape)}")
    dev = next(model.parameters()).device if device is None else _resolve_device(device)
    was_training = model.training
    model.eval()
    outs = []
    try:
        with torch.no_grad():
            for s in range(0, images.shape[0], batch_size):
                o = model(images[s:s + batch_size].to(dev))
                outs.append({k: o[k].float().cpu() for k in ("vertices", "joints")})
    finally:
        model.train(was_training)
    return {k: torch.cat([o[k] for o in outs]) for k in ("vertices", "joints")}


def _run_dataset(model: nn.Module, dataset, batch_size: int, device: torch.device,
                 num_workers: int = 0, progress: bool = False, desc: str = "eval") -> dict:
    loader = torch.utils.data.DataLoader(dataset, batch_size=batch_size, shuffle=False,
                                         num_workers=num_workers)
    keys = ("vertices", "joints", "root", "R", "mirrored", "vr", "index", "K")
    acc: dict[str, list] = {k: [] for k in (*keys, "pred_vertices", "pred_joints")}
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            for batch in progress_bar(loader, desc=desc, disable=not progress, leave=False):
                out = model_outputs(model, batch, device)
                acc["pred_vertices"].append(out["vertices"].float().cpu())
                acc["pred_joints"].append(out["joints"].float().cpu())
                for k in keys:
                    acc[k].append(batch[k])
    finally:
        model.train(was_training)
    return {k: torch.cat(v) for k, v in acc.items()}


def validate(model: nn.Module, dataset, batch_size: int = 16, device=None,
             progress: bool = False) -> dict:
    """Loss and FreiHAND-style scores of a model on a (non-augmented) dataset.

    Errors are computed in the root-centred network frame (ground-truth root; mirroring and
    rotation do not change distances).

    Args:
        model: the network.
        dataset: a [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset]
            (``train=False``).
        batch_size: evaluation batch size.
        device: default: the model's device.
        progress: tqdm bar.

    Returns:
        dict: ``loss`` (metres) and the keys of
        [`freihand_scores`][handmesh_tutorial.metrics.freihand_scores] (mm, AUCs, F-scores).
    """
    dev = next(model.parameters()).device if device is None else _resolve_device(device)
    r = _run_dataset(model, dataset, batch_size, dev, progress=progress, desc="validate")
    scores = M.freihand_scores(pred_joints=r["pred_joints"], gt_joints=r["joints"],
                               pred_verts=r["pred_vertices"], gt_verts=r["vertices"])
    scores["loss"] = float(vertex_loss(r["pred_vertices"], r["vertices"]))
    return scores


def _item_kinds(dataset, index: np.ndarray) -> list | None:
    """Scene kind of each evaluated item (INTER-SH readers only), else ``None``.

    Only an [`InterSHDataset`][handmesh_tutorial.data.InterSHDataset] source has scene kinds;
    other readers with an ``annotation`` method (FreiHAND's takes a file key, not an index) and
    in-memory sample lists give ``None``.
    """
    base = dataset
    while isinstance(base, torch.utils.data.Subset):
        base = base.dataset
    source = getattr(base, "source", None)
    if not isinstance(source, InterSHDataset):
        return None
    return [source.annotation(int(i)).get("kind") for i in index]


def _vr_table(errors: dict, vr: np.ndarray) -> list[dict]:
    """The per-VR rows over the samples that have a VR (NaN: unknown, e.g. FreiHAND); a
    warning names how many were left out when only some have one."""
    known = np.isfinite(vr)
    if not known.any():
        return []
    if not known.all():
        warnings.warn(f"{int((~known).sum())} of {len(vr)} samples have no visibility ratio "
                      "(NaN); the per-VR table counts the others only", RuntimeWarning,
                      stacklevel=3)
        errors = {k: (v if k == "fscore_thresholds" else np.asarray(v)[known])
                  for k, v in errors.items()}
    return M.scores_by_vr_bin(errors, vr[known])


def _score_predictions(pred_joints, pred_vertices, r: dict, vr: np.ndarray, kinds,
                       faces) -> dict:
    """Scores, per-sample errors and the VR / kind / overall rows of one set of predictions;
    joints only when the predicted mesh has another vertex count than the ground truth's."""
    verts = pred_vertices.shape[1] == r["vertices"].shape[1]
    errors = M.per_sample_scores(pred_joints=pred_joints, gt_joints=r["joints"],
                                 pred_verts=pred_vertices if verts else None,
                                 gt_verts=r["vertices"] if verts else None)
    scores = M.scores_from_errors(errors)
    if faces is not None and verts:
        pv, gv = pred_vertices.double().numpy(), r["vertices"].double().numpy()
        errors["roughness_deg"] = roughness_deg(pv, gv, faces)
        errors["flipped"] = flipped_face_fraction(pv, gv, faces)
        scores["roughness_deg"] = float(errors["roughness_deg"].mean())
        scores["flipped"] = float(errors["flipped"].mean())
    per_sample = {
        "index": r["index"].numpy(), "vr": vr, "mirrored": r["mirrored"].numpy(),
        "mpjpe": 1000 * errors["joint_err"].mean(1),
        "pa_mpjpe": 1000 * errors["joint_err_pa"].mean(1),
    }
    if verts:
        per_sample.update(mpvpe=1000 * errors["vert_err"].mean(1),
                          pa_mpvpe=1000 * errors["vert_err_pa"].mean(1),
                          f_at_5mm=errors["fscore"][:, 0], f_at_15mm=errors["fscore"][:, 1])
    for key in M.SURFACE_KEYS:
        if key in errors:
            per_sample[key] = errors[key]
    if kinds is not None:
        per_sample["kind"] = np.array([str(k) for k in kinds])
    vr_table = _vr_table(errors, vr)
    kind_table = [] if kinds is None else M.scores_by_group(
        errors, kinds, order=[k for k in KINDS if k in set(kinds)])
    overall = {"bin": "all", "count": len(vr), "mpjpe": scores["mpjpe"],
               "rr_mpjpe": 1000 * float(errors["joint_err_rr"].mean()),
               "pa_mpjpe": scores["pa_mpjpe"], "auc": scores["auc_joints_20mm"]}
    for key in ("pa_mpvpe", "f_at_5mm", "f_at_15mm", *M.SURFACE_KEYS):
        if key in scores:
            overall[key] = scores[key]
    return {"errors": errors, "scores": scores, "per_sample": per_sample, "vr_table": vr_table,
            "kind_table": kind_table, "overall": overall}


def evaluate(checkpoint_or_model, data=None, *, dataset=None, kind: str | None = None,
             split: str = "evaluation", image_size: int | None = None, batch_size: int = 16,
             device: str = "auto", out_dir: str | os.PathLike | None = None,
             camera_frame: bool = True, num_samples: int | None = None, template=None,
             progress: bool = True, threads: int | None = None, baseline: bool = True,
             mean_hand=None, skip_bad: bool = False, overwrite: bool = False) -> dict:
    """Evaluate a trained network: FreiHAND-style scores, per-sample errors, VR table, figures.

    Every item is the deterministic crop of its target hand (no augmentation); errors are
    measured in the root-centred frame with the ground-truth root (FreiHAND's protocol reports
    aligned and root-relative numbers; mirroring is undone for the predictions only where
    ``camera_frame`` asks for it, distances do not change).

    Args:
        checkpoint_or_model: a checkpoint path, or a network (then give ``image_size``).
        data: INTER-SH root (``kind="intersh"``) or FreiHAND root (``kind="freihand"``, split
            ``split``).
        dataset: a ready [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset]
            instead of
            ``data``.
        kind: ``"intersh"`` or ``"freihand"`` (default: the checkpoint's ``dataset``, else
            ``"intersh"``).
        split: FreiHAND split.
        image_size: crop side (default: the checkpoint's ``image_size``).
        batch_size: evaluation batch size.
        device: ``"auto"``, ``"cpu"``, ``"cuda"``.
        out_dir: when given, writes ``eval.json``, ``predictions.npz``, ``pck.png``,
            ``vr.png`` (the figures need matplotlib, the ``notebooks`` extra: without it a
            warning says so and the other files are written), and on FreiHAND data
            ``pred.json`` (the official submission format,
            [`write_predictions`][handmesh_tutorial.data.freihand.write_predictions]: camera frame,
            the evaluated items in order) when the network predicts MANO's 778 vertices; else
            ``notes`` says why it was not written. The files are one evaluation's: those of an
            earlier evaluation in ``out_dir`` are removed before the new ones are written,
            ``eval.json`` last (an interrupted write leaves no ``eval.json``, never a mix). A
            folder holding files ``evaluate`` did not write is refused before evaluating,
            unless ``overwrite``.
        camera_frame: predictions un-mirrored and moved back to the source camera frame
            (ground-truth root added); ``False``: the network's root-centred right-hand frame.
        num_samples: evaluate only the first ``num_samples`` items.
        template: template for loading a checkpoint (see
            [`load_checkpoint`][handmesh_tutorial.train.checkpoints.load_checkpoint]).
        progress: tqdm bar.
        threads: ``torch.set_num_threads`` value.
        baseline: also score the **rest-hand baseline** on the same items: the network's template
            (the open rest-pose hand, root-centred) predicted for every image, no network at all
            ([`constant_hand_predictions`][handmesh_tutorial.train.baselines.constant_hand_predictions]).
            After Procrustes alignment it is the bar a model must clear to have learnt the hand's
            articulation.
        mean_hand: ``(V, 3)`` network-frame vertices of a second constant baseline scored the same
            way, normally [`mean_hand`][handmesh_tutorial.train.baselines.mean_hand] of the training
            data (the data's average articulation): the bar a model must clear to read *each* hand's
            pose from its image.
        skip_bad: load every item once first and leave out those that cannot be read (listed
            in ``skipped``); ``False``: the first bad sample stops the evaluation, named.
        overwrite: write into an ``out_dir`` that holds files ``evaluate`` did not write (files
            of its output names are replaced, the others left).

    Returns:
        dict with ``scores`` ([`freihand_scores`][handmesh_tutorial.metrics.freihand_scores]: mm,
        AUC, F-scores, plus the surface scores ``roughness_deg`` and ``flipped`` when the network
        has ``faces``: [`roughness_deg`][handmesh_tutorial.metrics.surface.roughness_deg], the mean
        [`flipped_face_fraction`][handmesh_tutorial.metrics.surface.flipped_face_fraction]),
        ``per_sample`` (``index``, ``vr``, ``mirrored``, ``kind`` (INTER-SH) and per-sample
        ``mpjpe``, ``mpvpe``,
        ``pa_mpjpe``, ``pa_mpvpe`` in mm, ``f_at_5mm``, ``f_at_15mm``, ``roughness_deg``,
        ``flipped``; (N,) arrays), ``errors``
        ([`per_sample_scores`][handmesh_tutorial.metrics.per_sample_scores], metres), ``vr_table``
        (rows of [`scores_by_vr_bin`][handmesh_tutorial.metrics.scores_by_vr_bin] over the target
        hands' VR; empty when no sample has a VR), ``kind_table`` (rows of
        [`scores_by_group`][handmesh_tutorial.metrics.scores_by_group] per scene kind, INTER-SH
        only, else empty), ``table`` (markdown), ``baseline`` (with ``baseline=True``: the rest
        hand's ``scores``, ``per_sample``, ``errors``, ``vr_table``, ``kind_table`` on the same
        items, else ``None``), ``mean_hand_baseline`` (the same for ``mean_hand``, or ``None``),
        ``comparison`` (markdown, model / rest hand / mean hand, those scored, per VR bin, kind and
        overall; ``""`` without either baseline), ``predictions`` (``vertices`` (N, V, 3),
        ``joints`` (N, 21, 3) numpy, metres), ``num_samples``, ``files`` (paths written) and
        ``skipped`` (``[{"index": reader index, "sample": folder name such as "000015",
        "error": message}, ...]``, the items ``skip_bad`` left out; also in ``eval.json``),
        ``notes`` (list of str: files not written, and why; on an INTER-SH root missing
        planned samples, "scored N of M planned samples" and why they may be missing),
        ``planned`` (the samples the INTER-SH root's ``meta.json`` plans, else ``None``). A
        network whose mesh is not the data's (the shipped MakeHuman hand on FreiHAND's
        778-vertex MANO meshes) is scored on its joints only: the vertex and surface keys are
        absent and a note says so.

    Shapes:
        ``mean_hand (V, 3)``; ``predictions``: ``vertices (N, V, 3)``, ``joints (N, 21, 3)``;
        ``per_sample`` entries ``(N,)``.
    """
    if image_size is not None:  # before anything is read or allocated
        check_image_size(image_size)
    check_count(batch_size, "batch_size", 1, MAX_BATCH_SIZE, "MAX_BATCH_SIZE")
    if threads is not None:
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"threads must be a positive integer or None, got {threads!r}")
        check_threads(threads)
    dev = _resolve_device(device)
    if threads is not None:
        torch.set_num_threads(threads)
    if out_dir is not None:  # a folder we may not or cannot write is found now, not after
        claim_out_dir(out_dir, "evaluate", EVAL_OUTPUTS, overwrite=overwrite,
                      recognise=lambda d: json_record(d / "eval.json", "scores", "num_samples"))
        check_writable(out_dir)
    source = None
    if isinstance(checkpoint_or_model, str | os.PathLike):
        source = str(checkpoint_or_model)
        net, ck = load_checkpoint(checkpoint_or_model, dev, template)
        cfg = ck["config"]
        image_size = check_image_size(image_size or cfg["image_size"])
        box_scale = cfg.get("box_scale", 1.5)
        kind = kind or cfg.get("dataset", "intersh")
    else:
        net = checkpoint_or_model.to(dev)
        box_scale = 1.5
    planned, coverage = None, ""
    if dataset is None:
        if data is None:
            raise ValueError("give data (a data root) or dataset")
        if image_size is None:
            raise ValueError("image_size is needed when evaluating a model object")
        kind = kind or "intersh"
        if kind == "intersh":
            dataset = TV.InterSHTorchDataset(data, image_size, train=False, box_scale=box_scale)
            planned, coverage = dataset.source.num_planned, dataset.source.coverage()
        elif kind == "freihand":
            dataset = TV.FreiHANDTorchDataset(data, split, image_size, train=False)
        else:
            raise ValueError(f"kind must be 'intersh' or 'freihand', got {kind!r}")
        if num_samples is not None:
            dataset = torch.utils.data.Subset(dataset, range(min(num_samples, len(dataset))))
    elif num_samples is not None:
        dataset = torch.utils.data.Subset(dataset, range(min(num_samples, len(dataset))))
    skipped = []
    if skip_bad:
        dataset, bad = TV.drop_bad_items(dataset, progress, "evaluation")
        skipped = [{"index": b["index"], "sample": b["sample"], "error": b["error"]}
                   for b in bad]
    if len(dataset) == 0:
        raise ValueError(coverage.replace(" present (", " present, none to score (")
                         if coverage else "the evaluation set is empty")

    r = _run_dataset(net, dataset, batch_size, dev, progress=progress, desc="evaluate")
    finite = torch.isfinite(r["pred_vertices"]).flatten(1).all(1) & \
        torch.isfinite(r["pred_joints"]).flatten(1).all(1)
    if not finite.all():  # scores would be NaN: say why instead of printing them
        first = int(r["index"][int(torch.nonzero(~finite)[0])])
        raise ValueError(f"{source or 'the network'} predicts NaN or infinity for "
                         f"{int((~finite).sum())} of {len(finite)} items (first: sample index "
                         f"{first}): its weights are damaged or overflow")
    faces = getattr(net, "faces", None)
    kinds = _item_kinds(dataset, r["index"].numpy())
    vr = r["vr"].double().numpy()
    model = _score_predictions(r["pred_joints"], r["pred_vertices"], r, vr, kinds, faces)
    rest = None
    if baseline:
        tv = getattr(net, "template", None)
        rest_v, rest_j = constant_hand_predictions(
            tv if tv is not None else _rest_template(resolve_template(template)),
            net.joint_regressor, len(vr))
        rest = _score_predictions(rest_j, rest_v, r, vr, kinds, faces)
    mean = None
    if mean_hand is not None:
        mv = torch.as_tensor(mean_hand, dtype=torch.float64).detach().cpu().numpy()
        if mv.shape != tuple(r["pred_vertices"].shape[1:]):
            raise ValueError(f"mean_hand must be {tuple(r['pred_vertices'].shape[1:])}, got "
                             f"{mv.shape}: the network's vertices")
        mean_v, mean_j = constant_hand_predictions(mv, net.joint_regressor, len(vr))
        mean = _score_predictions(mean_j, mean_v, r, vr, kinds, faces)
    table = M.format_table([*model["vr_table"], *model["kind_table"], model["overall"]])
    comparison = ""
    if rest is not None or mean is not None:
        comparison = M.comparison_table(
            *[[*x["vr_table"], *x["kind_table"], x["overall"]]
              for x in (model, rest, mean) if x is not None], first="VR bin / kind")
    scores, errors, per_sample = model["scores"], model["errors"], model["per_sample"]
    vr_table = model["vr_table"]
    if camera_frame:
        batch = {"root": r["root"], "R": r["R"], "mirrored": r["mirrored"]}
        pv, pj = A.to_camera(r["pred_vertices"], batch), A.to_camera(r["pred_joints"], batch)
    else:
        pv, pj = r["pred_vertices"], r["pred_joints"]
    result = {
        "scores": scores, "per_sample": per_sample, "errors": errors, "vr_table": vr_table,
        "kind_table": model["kind_table"], "table": table, "num_samples": int(len(vr)),
        "baseline": None if rest is None else {k: rest[k] for k in (
            "scores", "per_sample", "errors", "vr_table", "kind_table")},
        "mean_hand_baseline": None if mean is None else {k: mean[k] for k in (
            "scores", "per_sample", "errors", "vr_table", "kind_table")},
        "comparison": comparison,
        "predictions": {"vertices": pv.numpy(), "joints": pj.numpy(),
                        "frame": "camera" if camera_frame else "network"},
        "files": {},
        "skipped": skipped,
        "planned": planned,
    }
    result["notes"] = [f"scored {len(vr)} of {planned} planned samples: {coverage}"] \
        if coverage else []
    nv, ngt = r["pred_vertices"].shape[1], r["vertices"].shape[1]
    if nv != ngt:
        result["notes"].append(
            f"vertex scores left out: the network predicts {nv} vertices, the ground truth has "
            f"{ngt} (another mesh); joints only. To score vertices, train with the data's mesh "
            "(FreiHAND: handmesh train --template MANO_RIGHT.pkl)")
    if out_dir is not None:
        result["files"] = _write_eval(Path(out_dir), result, source, errors,
                                      _is_freihand(dataset))
    return result


EVAL_OUTPUTS = ("eval.json", "predictions.npz", "pck.png", "vr.png", "pred.json")
"""The files of one evaluation in its ``out_dir``, its record ``eval.json`` first: an evaluation
removes them all before it writes (``eval.json`` then written last)."""


def _is_freihand(dataset) -> bool:
    base = dataset
    while isinstance(base, torch.utils.data.Subset):
        base = base.dataset
    return isinstance(getattr(base, "source", None), FreiHAND)


def _write_freihand_submission(out: Path, res: dict, files: dict) -> None:
    """``pred.json`` of the predictions when FreiHAND's evaluation can score it, else a note."""
    p = res["predictions"]
    nv = p["vertices"].shape[1]
    if p["frame"] != "camera":
        res["notes"].append("pred.json not written: the predictions are in the network frame; "
                            "FreiHAND's evaluation wants the camera frame")
    elif nv != NUM_VERTICES:
        res["notes"].append(
            f"pred.json not written: the network predicts {nv} vertices, FreiHAND's evaluation "
            f"compares MANO's {NUM_VERTICES} vertex by vertex; train with a MANO template "
            "(handmesh train --template MANO_RIGHT.pkl)")
    else:
        files["pred_json"] = write_predictions(out / "pred.json", p["joints"], p["vertices"])


def _write_eval(out: Path, res: dict, source: str | None, errors: dict,
                freihand: bool = False) -> dict:
    """Write one evaluation's files: the old set removed first, ``eval.json`` (its record)
    written last, so the folder never holds files of two evaluations."""
    out.mkdir(parents=True, exist_ok=True)
    remove_outputs(out, EVAL_OUTPUTS)
    files = {"json": out / "eval.json"}
    _write_eval_files(out, res, errors, files)
    if freihand:
        _write_freihand_submission(out, res, files)
    summary = {"checkpoint": source, "scores": res["scores"], "vr_table": res["vr_table"],
               "kind_table": res["kind_table"], "num_samples": res["num_samples"],
               "per_sample": {k: v.tolist() for k, v in res["per_sample"].items()},
               "baseline": None if res["baseline"] is None else {
                   "name": REST_HAND, "scores": res["baseline"]["scores"],
                   "vr_table": res["baseline"]["vr_table"],
                   "kind_table": res["baseline"]["kind_table"],
                   "per_sample": {k: v.tolist()
                                  for k, v in res["baseline"]["per_sample"].items()}},
               "mean_hand_baseline": None if res["mean_hand_baseline"] is None else {
                   "name": MEAN_HAND, "scores": res["mean_hand_baseline"]["scores"],
                   "vr_table": res["mean_hand_baseline"]["vr_table"],
                   "kind_table": res["mean_hand_baseline"]["kind_table"]},
               "comparison": res["comparison"],
               "predictions_frame": res["predictions"]["frame"],
               "skipped": res.get("skipped", []), "planned": res.get("planned"),
               "notes": res.get("notes", [])}
    write_json(files["json"], summary)
    return files


def _write_eval_files(out: Path, res: dict, errors: dict, files: dict) -> None:
    """``predictions.npz`` and the figures (into ``files``)."""
    p = res["predictions"]
    files["predictions"] = out / "predictions.npz"
    atomic_savez(files["predictions"], compressed=False,
                 vertices=p["vertices"].astype(np.float32), joints=p["joints"].astype(np.float32),
                 index=res["per_sample"]["index"], vr=res["per_sample"]["vr"],
                 mirrored=res["per_sample"]["mirrored"])
    try:  # the scores and predictions need no extra; the figures need matplotlib
        plt = require("matplotlib.pyplot", "evaluate's figures (pck.png, vr.png)")
    except ModuleNotFoundError as err:
        warnings.warn(f"{err}; {out} holds eval.json and predictions.npz, without the figures",
                      UserWarning, stacklevel=4)
        return

    fig, ax = plt.subplots(figsize=(5, 3.6))
    curves = {"joints (PA)": errors["joint_err_pa"], "vertices (PA)": errors.get("vert_err_pa"),
              "joints (root-rel.)": errors["joint_err_rr"]}
    curves = {k: v for k, v in curves.items() if v is not None}  # joints only: no vertices
    if res["baseline"] is not None:  # the bar to clear, on the same samples
        curves["rest hand, joints (PA)"] = res["baseline"]["errors"]["joint_err_pa"]
    if res["mean_hand_baseline"] is not None:
        curves["mean hand, joints (PA)"] = res["mean_hand_baseline"]["errors"]["joint_err_pa"]
    viz.plot_pck_curves(ax, curves)
    ax.set_title(f"3D PCK, {res['num_samples']} samples")
    files["pck"] = viz.save_figure(fig, out / "pck.png", dpi=90)
    plt.close(fig)
    if res["vr_table"]:
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
        viz.plot_error_vs_vr(axes[0], res["per_sample"]["vr"], res["per_sample"]["pa_mpjpe"],
                             label="PA-MPJPE")
        viz.plot_vr_table(axes[1], res["vr_table"], metric="pa_mpjpe")
        axes[1].set_ylabel("PA-MPJPE (mm)")
        files["vr"] = viz.save_figure(fig, out / "vr.png", dpi=90)
        plt.close(fig)
