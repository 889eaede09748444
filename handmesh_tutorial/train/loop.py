"""The training loop: objective, steps, exact resume, DDP
([`train`][handmesh_tutorial.train.loop.train]).

Paper, Sec. "Training": the L1 distance between predicted and true vertices, centred on the
middle MCP joint (keypoint 9); the recipe's numbers are the defaults of
[`TrainConfig`][handmesh_tutorial.train.config.TrainConfig]. Our loss is the mean absolute error
over vertices and coordinates (the paper's per-vertex L1 / 3, a factor Adam ignores);
[`training_loss`][handmesh_tutorial.train.loop.training_loss] adds the optional terms.

What the loop guarantees:

* **Determinism.** Model initialisation uses ``torch.manual_seed(seed)``; the sample order of epoch
  ``e`` is ``numpy.random.default_rng([seed, e]).permutation``; augmentation draws come from
  ``(seed, epoch, index)`` (see [`handmesh_tutorial.data.augment`][handmesh_tutorial.data.augment]).
  No global RNG is touched by the data pipeline.
* **Exact resume.** ``checkpoint_last.pt`` (written atomically after every
  ``checkpoint_every`` epochs) holds the model, optimiser, scheduler, epoch, step, the torch /
  numpy / python RNG states, the history and the config; ``train(cfg, resume=True)`` continues
  from it and ends with the same weights as an uninterrupted run (same threads, CPU); it refuses
  other settings or other data (a fingerprint of ``meta.json`` and the sample ids).
* **Batches and DDP.** ``batch_size`` is the *global* batch. Launched with ``torchrun`` (env
  vars ``WORLD_SIZE``, ``RANK``, ``LOCAL_RANK``, ``MASTER_ADDR``, ``MASTER_PORT``), every
  global batch is cut into ``world_size * micro_batches`` equal consecutive chunks; rank ``r``
  processes chunks ``r * micro_batches ... (r + 1) * micro_batches - 1`` (gradient accumulation
  within a rank), each chunk's mean loss counts equally, so DDP on ``W`` processes computes the
  same update as one process with ``micro_batches = W`` (BatchNorm statistics are per chunk in
  both cases). A last, incomplete global batch is filled up with the epoch's first samples, so
  every step sees exactly ``batch_size`` samples. Backend ``gloo`` on CPU, ``nccl`` on CUDA.
  Only rank 0 validates and writes files.
* **Failure.** A NaN or infinite loss stops training with ``FloatingPointError`` naming the epoch
  and step (before the optimiser step, so the last checkpoint stays good).

Taught in notebook 08 ("Training").

Why one file: resume, DDP, the frozen parts and the checkpoints all act on the one run's state
(network, optimiser, sampler, history) inside `train`; apart, each would take that state whole.
"""

from __future__ import annotations

import contextlib
import math
import os
import random
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .._io import single_writer, write_json
from .._progress import progress_bar
from ..budget import check_threads, check_workers
from ..data import torch_views as TV
from ..nn.keypoints import keypoint_loss, normalised_keypoints
from ..nn.losses import aligned_joint_loss, edge_length_loss, normal_loss, vertex_loss
from ._distributed import (
    _barrier,
    _broadcast_row,
    _init_distributed,
    _mean_over_ranks,
    _resolve_device,
)
from .checkpoints import (
    METRIC_COLUMNS,
    _read_checkpoint,
    _remove_stale_temp_files,
    _set_rng_state,
    _write_logs,
    claim_run_dir,
    existing_run,
    save_checkpoint,
)
from .config import RESUMABLE_KEYS, TrainConfig, changed_settings
from .data import EpochBatchSampler, _checked_fingerprint, make_datasets
from .evaluation import validate
from .features import EncodedDataset, is_deterministic, model_outputs
from .templates import build_model_from_config, resolve_template, template_hash

__all__ = ["TrainResult", "train", "training_loss"]

TRAIN_LOCK = ".train.lock"
"""Lock file in a run folder while a process trains into it."""

_VAL_KEYS = ("mpjpe", "mpvpe", "pa_mpjpe", "pa_mpvpe", "auc_joints", "auc_verts", "f_at_5mm",
             "f_at_15mm")


@dataclass
class TrainResult:
    """What [`train`][handmesh_tutorial.train.loop.train] returns.

    Attributes:
        out_dir: the output folder.
        checkpoint: ``checkpoint_last.pt`` (``None`` on ranks other than 0).
        best_checkpoint: ``checkpoint_best.pt`` (lowest validation PA-MPVPE; model weights
            and config, no optimiser state), or ``None``.
        metrics_csv: ``metrics.csv`` (one row per epoch; columns
            [`METRIC_COLUMNS`][handmesh_tutorial.train.checkpoints.METRIC_COLUMNS]).
        history: the rows of ``metrics.csv`` as dicts (NaN where missing).
        step_losses: training loss of every step so far (mean over ranks), metres.
        final: the last row of ``history``.
        epochs: epochs completed.
        steps: optimiser steps completed.
        seconds: wall time of this call.
        model: the trained network (unwrapped from DDP), on the training device.
        rank: this process's rank.
        world_size: the number of processes.
        skipped: with ``TrainConfig.skip_bad``, the items left out:
            ``[{"split": "train" | "val", "index": reader index, "sample": folder name
            such as "000015", "error": message}, ...]``.
    """

    out_dir: Path
    checkpoint: Path | None
    best_checkpoint: Path | None
    metrics_csv: Path | None
    history: list
    step_losses: list
    final: dict
    epochs: int
    steps: int
    seconds: float
    model: nn.Module
    rank: int = 0
    world_size: int = 1
    skipped: list = field(default_factory=list)


def training_loss(out: dict, batch: Mapping, config: TrainConfig,
                  faces: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
    """The objective of one (micro-)batch: the paper's L1 vertex loss plus the optional terms.

    Args:
        out: the network's output (``vertices``, ``joints``, and ``uv`` with a keypoint
            encoder).
        batch: the items (``vertices``, ``joints``, ``root``, ``K``), on ``out``'s device.
        config: weights ``keypoint_weight``, ``aligned_weight``, ``edge_weight``, ``normal_weight``
            (0 = term off; see [`handmesh_tutorial.nn.losses`][handmesh_tutorial.nn.losses]) and
            ``image_size``.
        faces: ``(F, 3)`` int64 faces (needed by the edge and normal terms).

    Returns:
        ``(total, parts)``: the scalar to minimise and a dict of each active term's value
        (floats; ``vertex`` in metres).

    Raises:
        ValueError: a keypoint weight without a ``uv`` output, or a mesh term without faces.

    Shapes:
        ``out["vertices"] (B, V, 3)``, ``out["joints"] (B, 21, 3)``, ``out["uv"] (B, 21, 2)``;
        ``batch`` alike plus ``root (B, 3)``, ``K (B, 3, 3)``; ``faces (F, 3)``.
    """
    loss = vertex_loss(out["vertices"], batch["vertices"])
    parts = {"vertex": float(loss.detach())}

    def add(name, weight, value):
        nonlocal loss
        loss = loss + weight * value
        parts[name] = float(value.detach())

    if config.keypoint_weight:
        if "uv" not in out:
            raise ValueError("keypoint_weight > 0 needs a model with a keypoint encoder "
                             "(model_kwargs={'keypoints': True})")
        target = normalised_keypoints(batch["joints"], batch["root"], batch["K"],
                                      config.image_size)
        add("keypoint", config.keypoint_weight, keypoint_loss(out["uv"], target))
    if config.aligned_weight:
        add("aligned", config.aligned_weight, aligned_joint_loss(out["joints"], batch["joints"]))
    if config.edge_weight or config.normal_weight:
        if faces is None:
            raise ValueError("edge_weight / normal_weight need the mesh faces")
        if config.edge_weight:
            add("edge", config.edge_weight,
                edge_length_loss(out["vertices"], batch["vertices"], faces))
        if config.normal_weight:
            add("normal", config.normal_weight,
                normal_loss(out["vertices"], batch["vertices"], faces))
    return loss, parts


def _train_step(net, batch: dict, chunks: int, device: torch.device, ddp: bool,
                config: TrainConfig, faces: torch.Tensor | None) -> float:
    """Forward/backward over ``chunks`` equal micro-batches.

    Returns the mean chunk L1 vertex loss (metres; comparable across recipes), or NaN when the
    objective was not finite."""
    n = len(batch["joints"])
    if n % chunks:
        raise RuntimeError(f"batch of {n} not divisible into {chunks} micro-batches")
    per = n // chunks
    total = 0.0
    keys = ("vertices", "joints", "root", "K")
    for c in range(chunks):
        sl = slice(c * per, (c + 1) * per)
        sync = (not ddp) or c == chunks - 1
        ctx = contextlib.nullcontext() if sync else net.no_sync()
        half = config.precision == "bfloat16"
        with ctx:
            with torch.autocast(device.type, dtype=torch.bfloat16, enabled=half):
                out = model_outputs(net, batch, device, sl)
                if half:  # the losses (Procrustes, keypoints) in float32
                    out = {k: v.float() for k, v in out.items()}
            part = {k: batch[k][sl].to(device, non_blocking=True) for k in keys if k in batch}
            loss, parts = training_loss(out, part, config, faces)
            (loss / chunks).backward()
        if not math.isfinite(float(loss.detach())):
            return math.nan
        total += parts["vertex"] / chunks
    return total


def train(config: TrainConfig, *, resume: bool = False, overwrite: bool = False, dataset=None,
          val_dataset=None, template=None,
          callback: Callable[[dict], None] | None = None) -> TrainResult:
    """Train MSMR-Net (single process, or one rank of a ``torchrun`` job).

    Args:
        config: the run (see [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig]).
        resume: continue from ``out_dir/checkpoint_last.pt`` (must exist); the architecture
            and template must match; ``epochs`` may be larger than before.
        overwrite: start afresh in an ``out_dir`` holding a run (all its files are removed first)
            or files ``train`` did not write (left); without it (or ``resume``) both are refused,
            so a forgotten ``--resume`` never destroys a run nor a user's ``config.json``.
        dataset: a training dataset to use instead of ``config.data`` (items as
            [`HandCropDataset`][handmesh_tutorial.data.torch_views.HandCropDataset] returns;
            ``set_epoch`` is
            called when it exists).
        val_dataset: a validation dataset (with ``dataset``), or ``None``.
        template: overrides ``config.template`` (object or path; only its hash is stored).
        callback: called on every rank after each epoch with that epoch's metrics row.

    Returns:
        A [`TrainResult`][handmesh_tutorial.train.loop.TrainResult].

    Raises:
        FloatingPointError: the loss became NaN or infinite (message names epoch and step).
        FileNotFoundError: ``resume`` without a checkpoint, or missing data.
        FileExistsError: ``out_dir`` holds a run or files ``train`` did not write (listed).
        RuntimeError: another process is training into ``out_dir`` (it holds ``.train.lock``).
        ValueError: inconsistent config, template/data vertex counts that differ, a
            checkpoint of another architecture, or (``resume``) data that changed since the
            run started (its ``meta.json`` or sample ids; the message lists what differs). A
            resumed run's ``data`` or ``val_data`` may name another folder (the data moved):
            it resumes, with a warning, when that folder holds the same data.
    """
    t_start = time.perf_counter()
    # what this machine can hold, checked here (a checkpoint made on a larger machine still
    # loads): before any folder is claimed or anything allocated
    check_workers(config.num_workers)
    if config.threads is not None:
        check_threads(config.threads)
        torch.set_num_threads(int(config.threads))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    device = _resolve_device(config.device, local_rank)
    if device.type == "cuda":
        torch.cuda.set_device(device)
    rank, world, owns_pg = _init_distributed(device)
    try:
        lock = contextlib.nullcontext()
        if rank == 0:  # one writer per run folder: a second train() into it is refused
            claim_run_dir(config.out_dir, overwrite=overwrite, lock=TRAIN_LOCK)
            lock = single_writer(Path(config.out_dir) / TRAIN_LOCK, f"{config.out_dir} (training)")
        with lock:
            return _train(config, resume, overwrite, dataset, val_dataset, template, callback,
                          device, rank, world, t_start)
    finally:
        if owns_pg:
            import torch.distributed as dist

            dist.destroy_process_group()


def _train(config, resume, overwrite, dataset, val_dataset, template, callback, device, rank,
           world, t_start) -> TrainResult:
    out = Path(config.out_dir)
    is_main = rank == 0
    if not resume and not overwrite and (found := existing_run(out)):
        raise FileExistsError(
            f"{out} already holds a training run ({', '.join(found)}): resume it "
            "(train(..., resume=True), handmesh train --resume), replace it (overwrite=True, "
            "--overwrite) or choose another out_dir")
    if is_main:
        claim_run_dir(out, overwrite=overwrite, lock=TRAIN_LOCK, fresh=overwrite and not resume)
        _remove_stale_temp_files(out)
    tmpl = resolve_template(config.template if template is None else template)
    t_id = template_hash(tmpl)

    last, best_path = out / "checkpoint_last.pt", out / "checkpoint_best.pt"
    ck = None
    if resume and not last.exists() and (out / "config.json").exists():
        # a run killed before its first checkpoint: nothing to continue, nothing to lose
        warnings.warn(f"{out}: no checkpoint_last.pt yet (the run stopped before its first "
                      "checkpoint); starting from epoch 1", stacklevel=3)
        resume = False
    moved: dict = {}
    if resume:  # check before building anything
        ck = _read_checkpoint(last, map_location=device)
        _check_same_network(ck, config, t_id, str(last), "checkpoint")
        changed = changed_settings(ck["config"], config, run_dir=out)
        # a data root may move (the run's folder moved with it, or --data names the new
        # place): its fingerprint, compared below, says whether it holds the same data
        moved = {k: changed.pop(k) for k in ("data", "val_data")
                 if k in changed and ck.get("data_fingerprint") and dataset is None
                 and None not in changed[k]}
        if changed:
            raise ValueError(
                f"{last}: cannot resume with other settings (checkpoint, now): {changed}. "
                f"Resume with the run's settings (only {', '.join(RESUMABLE_KEYS)} may "
                "change; data and val_data may name where the same data moved), or start a "
                "new run in another out_dir")
    fingerprint = _checked_fingerprint(config, dataset, ck, last)
    if ck is not None and moved:
        warnings.warn(f"{last}: the run's data moved ("
                      + ", ".join(f"{k} {a} -> {b}" for k, (a, b) in moved.items())
                      + "): the same meta.json and samples, so the run resumes there",
                      stacklevel=3)

    torch.manual_seed(config.seed)
    np.random.seed(config.seed % 2**32)  # noqa: NPY002 - for user code relying on it
    random.seed(config.seed)
    net = build_model_from_config(config, tmpl)
    if ck is None and config.init is not None:
        _load_init(net, config, t_id)
    if ck is None and config.init_encoder is not None:
        from ..nn.pose_encoder import load_pretrained_encoder

        load_pretrained_encoder(net, config.init_encoder)
    net = net.to(device)
    faces = torch.as_tensor(np.asarray(tmpl.faces), dtype=torch.int64, device=device)
    # fused: one kernel for all parameters instead of ~10 small ops per tensor (about 300
    # tensors here); same update rule (a resumed run keeps the flag saved in its checkpoint)
    opt = torch.optim.Adam(_param_groups(net, config), lr=config.lr,
                           weight_decay=config.weight_decay, fused=device.type in ("cpu", "cuda"))
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=config.lr_step, gamma=config.lr_gamma)

    start_epoch, step, history, step_losses, best = 0, 0, [], [], math.inf
    rng_to_restore = None
    if ck is not None:
        net.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optimizer"])
        sched.load_state_dict(ck["scheduler"])
        # the config's schedule wins (a resumed run may change epochs / lr_step)
        sched.step_size, sched.gamma = config.lr_step, config.lr_gamma
        start_epoch, step = int(ck["epoch"]), int(ck["step"])
        history = [dict(r) for r in ck["history"]]
        step_losses = [float(x) for x in ck["step_losses"].tolist()]
        best = float(ck["best"])
        rng_to_restore = ck["rng"]
        if is_main:  # logs written after the checkpoint by a killed run go back to it
            _write_logs(out, history, step_losses, config.durable)

    if dataset is None:
        train_ds, val_ds = make_datasets(config)
    else:
        train_ds, val_ds = dataset, val_dataset
    skipped = []
    if config.skip_bad:
        train_ds, val_ds, skipped = _skip_bad_items(train_ds, val_ds, config.progress and is_main)
        if is_main:
            write_json(out / "skipped.json", {"skipped": skipped})
    fixed = _fixed_parts(net, config)  # train_only: the parts that never train
    encoder_fixed = config.freeze_encoder >= config.epochs or "encoder" in fixed
    if encoder_fixed and world == 1 and is_deterministic(train_ds) \
            and (val_ds is None or is_deterministic(val_ds)):
        # frozen throughout and no augmentation: each crop's features are the same every epoch
        kw = dict(batch_size=config.val_batch_size or 64, progress=config.progress and is_main)
        train_ds = EncodedDataset(train_ds, net.encoder, **kw)
        val_ds = None if val_ds is None else EncodedDataset(val_ds, net.encoder, **kw)
    n_vert = int(net.joint_regressor.shape[1])
    got = tuple(train_ds[0]["vertices"].shape)
    if got != (n_vert, 3):
        raise ValueError(f"training targets have vertices {got}, the template has ({n_vert}, 3):"
                         " train with the template of the data (TrainConfig.template)")

    for part in fixed.values():  # before DDP: it then syncs the trained parts only
        part.requires_grad_(False)
    if encoder_fixed:
        net.encoder.requires_grad_(False)
    elif world > 1 and config.freeze_encoder:
        raise ValueError(f"freeze_encoder={config.freeze_encoder} of {config.epochs} epochs: under "
                         "DDP the encoder is either frozen for the whole run or trained throughout "
                         "(a DDP model's set of trained weights cannot change)")
    model = net
    if world > 1:
        from torch.nn.parallel import DistributedDataParallel as DDP  # noqa: N817

        model = DDP(net, device_ids=[device.index] if device.type == "cuda" else None)
    if rng_to_restore is not None:
        _set_rng_state(rng_to_restore)
    # the batch against the training items: refused before the run's record is written
    sampler = EpochBatchSampler(len(train_ds), config.batch_size, config.seed, rank, world,
                                config.micro_batches)
    if is_main:
        write_json(out / "config.json", {"config": config.to_dict(), "template_hash": t_id,
                                          "world_size": world,
                                          "data_fingerprint": fingerprint})
    val_bs = config.val_batch_size or config.batch_size

    for epoch in range(start_epoch, config.epochs):
        t_epoch = time.perf_counter()
        sampler.set_epoch(epoch)
        if hasattr(train_ds, "set_epoch"):
            train_ds.set_epoch(epoch)
        loader = torch.utils.data.DataLoader(
            train_ds, batch_sampler=sampler, num_workers=config.num_workers,
            pin_memory=device.type == "cuda",
            generator=torch.Generator().manual_seed(config.seed * 100003 + epoch))
        model.train()
        frozen = epoch < config.freeze_encoder
        if config.freeze_encoder and "encoder" not in fixed:
            # frozen: no gradients (Adam skips the weights) and fixed BatchNorm statistics
            net.encoder.requires_grad_(not frozen)
            if frozen:
                net.encoder.eval()
        for part in fixed.values():  # train_only: fixed weights and BatchNorm statistics
            part.eval()
        lr = opt.param_groups[0]["lr"]
        losses = []
        bar = progress_bar(loader, desc=f"epoch {epoch + 1}/{config.epochs}", per="epoch",
                   disable=not (config.progress and is_main), leave=False)
        for batch in bar:
            opt.zero_grad(set_to_none=True)
            loss = _train_step(model, batch, config.micro_batches, device, world > 1,
                               config, faces)
            loss = _mean_over_ranks(loss, world, device)
            if not math.isfinite(loss):
                raise FloatingPointError(
                    f"loss is {loss} at epoch {epoch + 1} (1-based), step {step + 1} (global, "
                    f"1-based), batch {len(losses) + 1} of the epoch; the optimiser step was "
                    f"not taken. Check the data for NaN/inf targets or lower lr ({lr:g}).")
            opt.step()
            step += 1
            losses.append(loss)
            step_losses.append(loss)
            bar.set_postfix(loss_mm=f"{1000 * loss:.2f}", lr=f"{lr:.2g}")
        bar.close()
        sched.step()
        row = {c: math.nan for c in METRIC_COLUMNS}
        row.update(epoch=epoch + 1, step=step, train_loss=float(np.mean(losses)), lr=lr,
                   seconds=time.perf_counter() - t_epoch)
        last_epoch = epoch + 1 == config.epochs
        if val_ds is not None and ((epoch + 1) % config.val_every == 0 or last_epoch):
            if is_main:
                v = validate(net, val_ds, val_bs, device)
                row["val_loss"] = v["loss"]
                row.update({f"val_{k}": float(v[k]) for k in _VAL_KEYS})
            row = _broadcast_row(row, world)
        history.append(row)
        improved = math.isfinite(row["val_pa_mpvpe"]) and row["val_pa_mpvpe"] < best
        if improved:
            best = row["val_pa_mpvpe"]
        if is_main:
            kw = dict(model=net, config=config, template_id=t_id, epoch=epoch + 1, step=step,
                      history=history, step_losses=step_losses, best=best,
                      durable=config.durable, extra={"data_fingerprint": fingerprint})
            # Order matters for a kill between two writes: best before last, so that a resume
            # from the older last checkpoint redoes this epoch and rewrites best; the CSVs
            # after both, and a resume rewrites them from the checkpoint's history.
            if improved:  # weights only (no optimiser state): for evaluation, not for resuming
                save_checkpoint(best_path, **kw)
            if (epoch + 1) % config.checkpoint_every == 0 or last_epoch:
                save_checkpoint(last, optimizer=opt, scheduler=sched, **kw)
            _write_logs(out, history, step_losses, config.durable)
        if callback is not None:
            callback(dict(row))
        _barrier(world)

    done = len(history)
    return TrainResult(
        out_dir=out, checkpoint=last if is_main and last.exists() else None,
        best_checkpoint=best_path if is_main and best_path.exists() else None,
        metrics_csv=out / "metrics.csv" if is_main and history else None,
        history=history, step_losses=step_losses, final=dict(history[-1]) if history else {},
        epochs=done, steps=step, seconds=time.perf_counter() - t_start, model=net, rank=rank,
        world_size=world, skipped=skipped)


def _fixed_parts(net: nn.Module, config: TrainConfig) -> dict[str, nn.Module]:
    """The network's child modules that ``config.train_only`` leaves out (none without it)."""
    if config.train_only is None:
        return {}
    parts = dict(net.named_children())
    unknown = sorted(set(config.train_only) - set(parts))
    if unknown:
        raise ValueError(f"train_only names {unknown}, which this network does not have; its "
                         f"parts are {sorted(parts)}")
    return {k: m for k, m in parts.items() if k not in config.train_only}


def _param_groups(net: nn.Module, config: TrainConfig) -> list[dict]:
    """One group of all weights, or the encoder's apart when it has its own rate or a frozen
    start (the group's ``lr`` is ``encoder_lr_scale * lr``)."""
    if config.encoder_lr_scale == 1.0 and not config.freeze_encoder:
        return [{"params": list(net.parameters())}]
    enc = {id(p) for p in net.encoder.parameters()}
    return [{"params": [p for p in net.parameters() if id(p) not in enc]},
            {"params": list(net.encoder.parameters()),
             "lr": config.lr * config.encoder_lr_scale}]


def _check_same_network(ck: dict, config: TrainConfig, t_id: str, where: str, what: str) -> None:
    """Raise ``ValueError`` unless checkpoint ``ck`` has this run's template and architecture."""
    if ck["template_hash"] != t_id:
        raise ValueError(f"{where}: trained with template {ck['template_hash']}, this run uses "
                         f"{t_id}")
    old, new = TrainConfig.from_dict(ck["config"]).architecture(), config.architecture()
    if old != new:
        diff = {k: (old[k], new[k]) for k in old if old[k] != new[k]}
        raise ValueError(f"{where}: architecture differs from the config ({what}, config): "
                         f"{diff}")


def _load_init(net, config: TrainConfig, t_id: str) -> None:
    """Start ``net`` from the weights of ``config.init`` (a checkpoint, or ``"pretrained"``)."""
    init = _read_checkpoint(config.init)
    _check_same_network(init, config, t_id, f"init {config.init}", "init")
    net.load_state_dict(init["model"])


def _skip_bad_items(train_ds, val_ds, progress: bool):
    """``(train_ds, val_ds, skipped)`` without the items that cannot be loaded."""
    skipped = []
    found = {}
    for split, ds in (("train", train_ds), ("val", val_ds)):
        if ds is None:
            continue
        found[split], bad = TV.drop_bad_items(ds, progress, "training" if split == "train"
                                             else "validation", allow_empty=split == "val")
        skipped += [{"split": split, "index": b["index"], "sample": b["sample"],
                     "error": b["error"]} for b in bad]
        if bad:
            warnings.warn(f"skipping {len(bad)} of {len(ds)} {split} samples that cannot be "
                          f"read (first: {bad[0]['error']})", stacklevel=4)
    val = found.get("val")
    return found["train"], None if val is not None and len(val) == 0 else val, skipped
