"""The demo job itself: generate the data, train, evaluate, draw the figures and write the report
([`run_demo`][handmesh_tutorial.apps.demo.run.run_demo]; steps and sizes in the docstring of
[`handmesh_tutorial.apps.demo`][handmesh_tutorial.apps.demo]).

Taught in notebook 00 ("Quickstart"); notebooks 08-10 share its data through
[`generate_data`][handmesh_tutorial.apps.demo.run.generate_data].
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..._io import claim_out_dir, json_record, write_json
from ..._optional import require
from ...metrics.intervals import paired_difference
from ...viz import plot_loss_curves, plot_overlays, save_figure
from .config import DemoConfig, train_config
from .report import BASELINE_ROW, MEAN_ROW, PRETRAINED_ROW, write_report

__all__ = ["DemoResult", "run_demo", "generate_data", "generate_scenes"]


@dataclass
class DemoResult:
    """What [`run_demo`][handmesh_tutorial.apps.demo.run.run_demo] returns.

    Attributes:
        out_dir: the output folder.
        report: path of ``report.md``.
        scores: the held-out scores (``eval.json`` ``scores``: mm, AUC, F-scores).
        vr_table: rows per VR bin (``eval.json`` ``vr_table``).
        table: the VR table as markdown.
        files: name -> path of everything written.
        seconds: wall time per stage (``generate``, ``train``, ``evaluate``, ``report``,
            ``total``) of this call.
        config: the [`DemoConfig`][handmesh_tutorial.apps.demo.config.DemoConfig] used.
        train_epochs: epochs completed by the training run.
        baseline_scores: scores of the rest-hand baseline on the same test scenes.
        comparison: markdown, model / rest hand / mean hand per VR bin, scene kind and overall.
        mean_hand_scores: scores of the mean training hand on the same test scenes.
        pretrained_scores: scores of the shipped pretrained network on the same test scenes
            (``None`` when this installation has none).
        differences: the network's PA-MPJPE minus each other row's, paired per test scene: row
            name -> [`paired_difference`][handmesh_tutorial.metrics.intervals.paired_difference]
            (mm, 95 % interval, share of scenes where the network is better).
    """

    out_dir: Path
    report: Path
    scores: dict
    vr_table: list
    table: str
    files: dict
    seconds: dict
    config: DemoConfig
    train_epochs: int = 0
    baseline_scores: dict | None = None
    comparison: str = ""
    mean_hand_scores: dict | None = None
    pretrained_scores: dict | None = None
    differences: dict | None = None


def _encoder_lineage(init_encoder) -> str:
    """One sentence on where the encoder's weights came from, read from the file's metadata."""
    if init_encoder is None:
        return "random weights (the whole network trained from scratch)"
    from ...nn.pose_encoder import encoder_lineage, encoder_source_path, read_pose_encoder

    info = read_pose_encoder(encoder_source_path(init_encoder))[1]
    what = {"pretrained": "the shipped hand encoder",
            "neutral": "the shipped decoder-neutral encoder"}.get(
        str(init_encoder), f"the pose-encoder file {Path(init_encoder).name}")
    return f"{what}, frozen: {encoder_lineage(info)['sentence']}"


def generate_scenes(root: str | os.PathLike, num: int, seed: int, *, render_size: int,
                    workers: int, progress: bool = True, balance: bool = False,
                    shard: tuple[int, int] | None = None):
    """The demo's scenes: ``generate_interactions(root, "mixed", num, seed, ...)``.

    A thin call of the one scene driver,
    [`scenes.generate_interactions`][handmesh_tutorial.scenes.generate.generate_interactions],
    under the demo's argument names.

    Args:
        root: the dataset folder.
        num: scenes of the whole set (all shards).
        seed: the set's seed.
        render_size: image side, pixels (``image_size`` of the driver).
        workers: generator processes.
        progress: tqdm bar.
        balance: spread the target VRs over the VR bins (``balance_vr``).
        shard: ``(k, n)``: only the k-th of n parts of the set.

    Returns:
        The [`GenerationSummary`][handmesh_tutorial.data.GenerationSummary].
    """
    from ...scenes import generate_interactions

    return generate_interactions(root, "mixed", num, seed, image_size=render_size,
                                 workers=workers, progress=progress, balance_vr=balance,
                                 shard=shard)


def generate_data(root: str | os.PathLike, config: DemoConfig | None = None, seed: int = 0,
                  progress: bool = True) -> dict:
    """Generate (or resume) the demo's two sets: ``root/train`` and the VR-balanced ``root/test``.

    Notebooks share data through this call: the same ``root``, sizes and seed reuse what is on
    disk (nothing is regenerated).

    Args:
        root: folder of the two sets.
        config: sizes (``train_samples``, ``test_samples``, ``render_size``, ``workers``,
            ``balance_train``); default
            [`DemoConfig.from_budget`][handmesh_tutorial.apps.demo.config.DemoConfig.from_budget].
        seed: seed of the training set; the test set uses ``seed + 1``.
        progress: tqdm bars.

    Returns:
        dict with ``train`` and ``test`` roots (``Path``) and their
        [`GenerationSummary`][handmesh_tutorial.data.GenerationSummary] as ``train_summary`` and
        ``test_summary``.
    """
    cfg = config or DemoConfig.from_budget()
    root = Path(root)
    size = {"render_size": cfg.render_size, "workers": cfg.workers, "progress": progress}
    tr = generate_scenes(root / "train", cfg.train_samples, seed, balance=cfg.balance_train,
                         **size)
    te = generate_scenes(root / "test", cfg.test_samples, seed + 1, balance=True, **size)
    return {"train": root / "train", "test": root / "test", "train_summary": tr,
            "test_summary": te}


DEMO_OUTPUTS = ("report.md", "demo.json", "overlays.png", "loss.png", "data", "train", "eval")
"""What the demo writes in its folder (files and sub-folders)."""


def _is_demo_folder(out: Path) -> bool:
    """A demo folder of an older version (before the ``.handmesh-demo`` marker): its
    ``demo.json`` record, or its generated training set."""
    return (json_record(out / "demo.json", "config", "scores")
            or json_record(out / "data" / "train" / "meta.json", "seed", "num_samples"))


def run_demo(out: str | os.PathLike = "runs/demo", seed: int = 0, config: DemoConfig | None = None,
             progress: bool = True, log=print, overwrite: bool = False) -> DemoResult:
    """Generate data, train, evaluate and write the report (resumable; see the module docs).

    Args:
        out: output folder.
        seed: seed of the training data (the test data uses ``seed + 1``), of the network
            initialisation, data order and augmentation.
        config: sizes (default
            [`DemoConfig.from_budget`][handmesh_tutorial.apps.demo.config.DemoConfig.from_budget] of
            ``hmt.budget()``).
        progress: tqdm bars.
        log: called with one-line progress messages (``None``: silent).
        overwrite: write into an ``out`` that holds files the demo did not write (the user's
            ``report.md``...): files of the demo's names are then replaced, the others left.
            Without it such a folder is refused before any work.

    Returns:
        A [`DemoResult`][handmesh_tutorial.apps.demo.run.DemoResult].

    Raises:
        ValueError: ``out`` holds a run of another configuration (the message says what
            differs; delete the folder or pick another ``--out``), or ``out`` is empty.
        FileExistsError: ``out`` holds files the demo did not write (listed) and no
            ``overwrite``.
    """
    plt = require("matplotlib.pyplot", "the demo (its figures)")

    from ...data import InterSHDataset

    cfg = config or DemoConfig.from_budget()
    say = log or (lambda *_: None)
    from ..pretraining_data import check_start_file

    check_start_file(cfg.init_encoder, "encoder", "--init-encoder")  # before the scenes
    out = claim_out_dir(out, "demo", DEMO_OUTPUTS, overwrite=overwrite,
                        recognise=_is_demo_folder)
    t0 = time.perf_counter()
    seconds = {}

    say(f"[1/4] generating {cfg.train_samples} training + {cfg.test_samples} test scenes "
        f"(mixed kinds; test set VR-balanced) in {out / 'data'}")
    t = time.perf_counter()
    data = generate_data(out / "data", cfg, seed, progress)
    # torch only now: the generator's workers fork only from a process without torch
    # (dataset.generate_dataset, mp_context="auto"), which saves seconds of start-up
    from ... import train as T
    from ...nn.model import parameter_counts

    gen_train, gen_test = data["train_summary"], data["test_summary"]
    seconds["generate"] = time.perf_counter() - t
    say(f"      {gen_train.written + gen_test.written} written, "
        f"{gen_train.skipped + gen_test.skipped} reused, {seconds['generate']:.0f} s")

    t = time.perf_counter()
    tcfg = train_config(cfg, out / "data" / "train", out / "train", seed=seed, progress=progress)
    last = out / "train" / "checkpoint_last.pt"
    resume = last.exists()
    say(f"[2/4] training MSMR-Net for {cfg.epochs} epochs in {out / 'train'}"
        + (" (resuming from checkpoint_last.pt)" if resume else ""))
    try:
        res = T.train(tcfg, resume=resume)
    except ValueError as e:
        raise ValueError(f"{e}\n(the folder {out} holds another demo configuration: delete "
                         f"{out / 'train'} or choose another --out)") from None
    seconds["train"] = time.perf_counter() - t
    ckpt = res.best_checkpoint or res.checkpoint
    say(f"      {res.epochs} epochs, {res.steps} steps, {seconds['train']:.0f} s")

    say(f"[3/4] evaluating {ckpt.name} on the {cfg.test_samples} held-out scenes")
    t = time.perf_counter()
    train_ds, val_ds = T.make_datasets(tcfg)
    mean = T.mean_hand(train_ds)  # the data's average articulation: the second constant bar
    ev = T.evaluate(ckpt, str(out / "data" / "test"), out_dir=out / "eval", device="cpu",
                    threads=cfg.threads, progress=progress, mean_hand=mean)
    pre = ev_pre = None
    try:  # the shipped network on the same scenes, at its own crop size (one read of the file)
        net_pre, ck_pre = T.load_checkpoint("pretrained")
        ev_pre = T.evaluate(net_pre, str(out / "data" / "test"), device="cpu",
                            image_size=ck_pre["config"]["image_size"],
                            threads=cfg.threads, progress=False, baseline=False)
        pre = ev_pre["scores"]
    except FileNotFoundError:
        say("      (no pretrained network in this installation: its row is left out)")
    # each held-out scene scored by both: the differences, not the scores, carry the comparison
    mine = ev["per_sample"]["pa_mpjpe"]
    intervals = {name: paired_difference(mine, other["per_sample"]["pa_mpjpe"])
                 for name, other in ((BASELINE_ROW, ev["baseline"]),
                                     (MEAN_ROW, ev["mean_hand_baseline"]),
                                     (PRETRAINED_ROW, ev_pre)) if other is not None}
    val_baselines = None if val_ds is None or not len(val_ds) else {
        "rest hand": T.constant_hand_scores(val_ds),
        "mean hand": T.constant_hand_scores(val_ds, mean)}
    seconds["evaluate"] = time.perf_counter() - t

    say("[4/4] drawing figures and writing the report")
    t = time.perf_counter()
    test = InterSHDataset(out / "data" / "test")
    per = ev["per_sample"]
    n = len(per["index"])
    # an even spread over the error ranking, best to worst: what typical predictions look like
    order = np.argsort(per["pa_mpjpe"], kind="stable")
    pick = order[np.unique(np.linspace(0, n - 1, min(cfg.overlays, n)).round().astype(int))]
    samples = [test[int(per["index"][i])] for i in pick]
    faces = res.model.faces  # the template's; same topology as the data's meshes
    titles = [f"PA-MPJPE {per['pa_mpjpe'][i]:.1f} mm" for i in pick]
    fig = plot_overlays(samples, ev["predictions"]["vertices"][pick], faces, titles)
    files = dict(ev["files"])
    files["overlays"] = save_figure(fig, out / "overlays.png", dpi=80)
    plt.close(fig)
    fig = plot_loss_curves(res.history, res.step_losses, val_baselines)
    files["loss"] = save_figure(fig, out / "loss.png", dpi=90)
    plt.close(fig)
    figures = {"Predicted meshes (blue) vs ground truth (green) on held-out images, best to "
               "worst PA-MPJPE": files["overlays"],
               "Training loss and validation error": files["loss"],
               "3D PCK curves (held-out)": files["pck"]}
    if "vr" in files:
        figures["Error vs visibility ratio and PA-MPJPE per VR bin"] = files["vr"]
    pred_v = ev["predictions"]["vertices"]
    ratios = []
    for k, i in enumerate(per["index"]):
        s = test[int(i)]
        gv = np.asarray(s["meshes"][s["target"]][0], dtype=np.float64)
        diag = np.linalg.norm(np.ptp(gv, axis=0))
        ratios.append(float(np.linalg.norm(np.ptp(pred_v[k], axis=0)) / diag))
    counts = {"train": len(InterSHDataset(out / "data" / "train")), "test": len(test),
              "train_vr": gen_train.vr_histogram, "test_vr": gen_test.vr_histogram}
    train_info = {"epochs": res.epochs, "steps": res.steps,
                  "checkpoint": os.path.relpath(ckpt, out),
                  "parameters": parameter_counts(res.model)["total"],
                  "size_ratio": float(np.mean(ratios))}
    baseline = ev["baseline"]["scores"]
    mean_scores = ev["mean_hand_baseline"]["scores"]
    seconds["report"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    files["report"] = write_report(out / "report.md", scores=ev["scores"], table=ev["table"],
                                   config=cfg, seconds=seconds, figures=figures, counts=counts,
                                   train_info=train_info, baseline=baseline,
                                   comparison=ev["comparison"], mean=mean_scores,
                                   pretrained=pre, intervals=intervals,
                                   encoder=_encoder_lineage(cfg.init_encoder))
    summary = {"config": asdict(cfg), "seed": seed, "scores": ev["scores"],
               "baseline_scores": baseline, "baseline": BASELINE_ROW,
               "mean_hand_scores": mean_scores, "mean_hand": MEAN_ROW,
               "pretrained_scores": pre, "pretrained": PRETRAINED_ROW,
               "pa_mpjpe_differences": intervals,
               "vr_table": ev["vr_table"], "kind_table": ev["kind_table"],
               "baseline_vr_table": ev["baseline"]["vr_table"],
               "baseline_kind_table": ev["baseline"]["kind_table"],
               "mean_hand_vr_table": ev["mean_hand_baseline"]["vr_table"],
               "mean_hand_kind_table": ev["mean_hand_baseline"]["kind_table"], "seconds": seconds,
               "counts": counts,
               "train": train_info, "files": {k: str(v) for k, v in files.items()}}
    files["json"] = out / "demo.json"
    write_json(files["json"], summary, sort_keys=False)  # keys in the order above
    return DemoResult(out_dir=out, report=files["report"], scores=ev["scores"],
                      vr_table=ev["vr_table"], table=ev["table"], files=files, seconds=seconds,
                      config=cfg, train_epochs=res.epochs, baseline_scores=baseline,
                      comparison=ev["comparison"], mean_hand_scores=mean_scores,
                      pretrained_scores=pre, differences=intervals)
