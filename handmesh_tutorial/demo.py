"""The main demo job (``handmesh demo`` / ``make demo``): data -> training -> evaluation -> report.

One call runs the whole paper pipeline at laptop scale, on CPU:

1. **Data.** Two INTER-SH sets of mixed scenes (hand-hand, hand-object and hand-chain, one kind
   drawn per sample; natural poses: the generator's default anatomical joint limits, not the paper's
   ±60°; [`handmesh_tutorial.dataset.generate_dataset`][handmesh_tutorial.dataset.generate_dataset]
   with [`handmesh_tutorial.interact.make_sample`][handmesh_tutorial.interact.make_sample]):
   ``OUT/data/train`` (seed ``seed``, the generator's natural VR distribution) and the held-out
   ``OUT/data/test`` (seed ``seed + 1``, never seen in training, ``balance_vr=True``: the target
   hands spread evenly over the paper's four VR bins, so every row of the VR table has the same
   weight).
2. **Training.** MSMR-Net (ResNet-10 encoder, multi-path decoder, coarse-mesh attention) with
   [`handmesh_tutorial.train.train`][handmesh_tutorial.train.train] into ``OUT/train`` (10% of the
   training set held out for per-epoch validation; ``checkpoint_best.pt`` keeps the best validation
   PA-MPVPE).
3. **Evaluation** of the best checkpoint on the test set with
   [`handmesh_tutorial.train.evaluate`][handmesh_tutorial.train.evaluate] into ``OUT/eval``
   (``eval.json``, ``predictions.npz``, ``pck.png``, ``vr.png``).
4. **Report.** ``OUT/report.md`` with the FreiHAND-style scores, the table per VR bin (the
   paper's Table 2 layout), predicted meshes drawn over held-out images next to the ground truth
   (``overlays.png``), the loss curves (``loss.png``), PCK curves and error vs VR; ``OUT/demo.json``
   holds the same numbers and the timings.

**Resumable.** Rerunning the same command skips finished work: the data generators skip samples
already on disk, training continues from ``OUT/train/checkpoint_last.pt`` (exactly, see
[`handmesh_tutorial.train`][handmesh_tutorial.train]), and a finished training is not repeated.
Evaluation and report are cheap and always redone.

**Sizes** come from the run-size tier
([`handmesh_tutorial.budget.budget`][handmesh_tutorial.budget.budget]) through
[`DemoConfig.from_budget`][handmesh_tutorial.demo.DemoConfig.from_budget]; the demo's own choices,
made so that the ``default`` tier finishes in about twelve minutes on a 2-core CPU:

* training scenes = 5 x ``budget.samples`` (``default``: 3,000; about 7 scenes/s with two
  workers at 128 px on a 2-core CPU) and VR-balanced test scenes = 1/2 of
  ``budget.eval_samples`` (``default``: 100; balancing rejects candidates, about 5 renders per
  kept scene). Training needs *many different* scenes far more than it needs balanced ones;
* network crop = 1/2 of ``budget.image_size`` (``default``: 64 px; images are rendered at
  ``budget.image_size``, where the target hand spans 45-75 % of the side; the network's crop is
  cut around it), batch ``budget.batch_size`` (``default``: 16), ``budget.epochs / 2`` epochs
  (``default``: 10, about 1,700 steps), learning rate ``1e-3`` (as MobRecon/HandMesh; the
  paper's ``1e-4`` is for 200 epochs with a pretrained encoder), halved once, after three
  quarters of the run;
* **ResNet-10** instead of the paper's ImageNet-pretrained ResNet-50 / HRNet, **no augmentation**
  below the ``full`` tier, and the **CPU recipe** ([`RECIPES`][handmesh_tutorial.demo.RECIPES]): a
  2D keypoint head whose features are pooled at the joints, a global-rotation head, the skinned
  decoder output (the decoder's field read as joint rotations and shape, then skinning: smooth
  hand surfaces), and keypoint and aligned-joint losses beside the paper's L1. With the paper's
  recipe (``recipe="paper"``) a from-scratch network stays for thousands of steps on a plateau
  of the L1 loss (about 28 mm) where it predicts one average mesh for every image. The docs page
  "Training from scratch on a CPU" has the measurements behind every choice.

The ``full`` tier is the paper's scale instead: ``budget.samples`` training scenes (40,000),
``budget.epochs`` epochs (200), augmentation on.

What to expect at the ``default`` size (measured on a 2-core CPU, seed 0, 2026-11-25, 12.4 min in
all: 5.5 min generating, 6.8 min training): on the 100 held-out scenes MPJPE 37.2 mm, PA-MPJPE
10.35 mm, PA-MPVPE 9.5 mm, roughness 3.9 degrees, 1.0% flipped faces. The rest hand (the
template's open hand for every image) scores PA-MPJPE 13.1 mm, the mean training hand
([`mean_hand`][handmesh_tutorial.train.mean_hand]) 10.3 mm: the network has learnt the hand's
orientation and the data's average articulation, not yet each hand's finger pose.

Example::

    import handmesh_tutorial as hmt
    result = hmt.demo.run_demo("runs/demo", seed=0)
    print(result.report, result.scores["pa_mpjpe"])
"""

from __future__ import annotations

import json
import math
import os
import re
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ._io import atomic_write_text, json_safe

__all__ = ["DemoConfig", "DemoResult", "run_demo", "generate_data", "train_config", "plot_overlays",
           "plot_loss_curves", "write_report", "headline", "parse_headline", "HEADLINE",
           "MODEL_ROW", "BASELINE_ROW", "MEAN_ROW", "RECIPES"]

RECIPES = {
    "paper": {},
    "cpu": {"model_kwargs": {"keypoints": True, "global_rotation": True, "output": "skinned"},
            "keypoint_weight": 0.5, "aligned_weight": 1.0},
}
"""Training recipes ([`TrainConfig`][handmesh_tutorial.train.TrainConfig] fields on top of
[`train_config`][handmesh_tutorial.demo.train_config]): the paper's (one L1 vertex loss, an encoder
that ends in global average pooling) and the CPU recipe, which adds a 2D keypoint head whose
features are pooled at the joints ([`handmesh_tutorial.keypoints`][handmesh_tutorial.keypoints]), a
global-rotation head ([`handmesh_tutorial.rotation`][handmesh_tutorial.rotation]), the skinned
decoder output ([`handmesh_tutorial.skinned`][handmesh_tutorial.skinned]: every prediction is a
skinned hand surface) and the keypoint and aligned-joint losses
([`handmesh_tutorial.losses`][handmesh_tutorial.losses]). Why: docs page "Training from scratch on
a CPU".
"""

MODEL_ROW, BASELINE_ROW, MEAN_ROW = ("MSMR-Net", "rest hand (no network)",
                                     "mean training hand (no network)")
"""Row names of the headline table: the trained network and the two constant baselines of
[`handmesh_tutorial.train.evaluate`][handmesh_tutorial.train.evaluate]: the rest hand (the
template's open hand) and the mean training hand
([`handmesh_tutorial.train.mean_hand`][handmesh_tutorial.train.mean_hand]), each predicted for every
image.
"""

HEADLINE = (("mpjpe", "MPJPE (mm)", "{:.2f}"), ("pa_mpjpe", "PA-MPJPE (mm)", "{:.2f}"),
            ("pa_mpvpe", "PA-MPVPE (mm)", "{:.2f}"),
            ("f_at_5mm", "F@5mm", "{:.3f}"), ("f_at_15mm", "F@15mm", "{:.3f}"),
            ("auc_joints", "AUC joints 0-50mm", "{:.3f}"),
            ("auc_joints_20mm", "AUC joints 0-20mm", "{:.3f}"),
            ("roughness_deg", "roughness (deg)", "{:.1f}"), ("flipped", "flipped faces", "{:.3f}"))
"""Scores in the report's headline table: (eval.json key, column title, format)."""


@dataclass
class DemoConfig:
    """Sizes and choices of one demo run (see the module docstring for why these values).

    Attributes:
        train_samples: training scenes generated (all kinds together).
        test_samples: held-out test scenes (always VR-balanced).
        render_size: side of the rendered scene images, pixels.
        image_size: side of the network's input crop, pixels.
        epochs: training epochs.
        batch_size: training batch size.
        lr: Adam learning rate.
        encoder: image encoder name.
        decoder: ``"multi"`` or ``"single"``.
        attention: coarse-mesh transformer on.
        augment: random crop / scale / rotation / colour jitter of training crops.
        recipe: ``"cpu"`` (default; [`RECIPES`][handmesh_tutorial.demo.RECIPES]: 2D keypoint head
            with pose pooling, a global-rotation head, the skinned decoder output, keypoint and
            aligned-joint losses beside the paper's L1) or ``"paper"`` (L1 vertex loss only,
            global-pooling encoder).
        balance_train: VR-balance the training scenes too (about 5x slower to generate).
        threads: torch threads.
        workers: data-generation processes.
        overlays: held-out samples drawn in ``overlays.png``.
        budget: name of the tier the sizes came from.
    """

    train_samples: int = 3000
    test_samples: int = 100
    render_size: int = 128
    image_size: int = 64
    epochs: int = 10
    batch_size: int = 16
    lr: float = 1e-3
    encoder: str = "resnet10"
    decoder: str = "multi"
    attention: bool = True
    augment: bool = False
    recipe: str = "cpu"
    balance_train: bool = False
    threads: int = 2
    workers: int = 2
    overlays: int = 8
    budget: str = "default"

    @classmethod
    def from_budget(cls, budget=None, **overrides) -> DemoConfig:
        """The demo's sizes for a run-size tier.

        Args:
            budget: a [`Budget`][handmesh_tutorial.budget.Budget] (default ``hmt.budget()``).
            **overrides: any field.

        Returns:
            The config.
        """
        if budget is None:
            from .budget import budget as _budget

            budget = _budget()
        full = budget.name == "full"  # the paper's scale: its data size, epochs, augmentation
        sized = dict(train_samples=budget.samples if full else max(8, 5 * budget.samples),
                     test_samples=max(4, budget.eval_samples // 2),
                     render_size=budget.image_size,
                     image_size=max(32, budget.image_size // 2),
                     epochs=budget.epochs if full else max(1, budget.epochs // 2),
                     batch_size=max(2, budget.batch_size), augment=full,
                     threads=budget.threads, workers=min(2, budget.threads),
                     overlays=8 if budget.name != "smoke" else 4, budget=budget.name)
        sized.update(overrides)
        return cls(**sized)


@dataclass
class DemoResult:
    """What [`run_demo`][handmesh_tutorial.demo.run_demo] returns.

    Attributes:
        out_dir: the output folder.
        report: path of ``report.md``.
        scores: the held-out scores (``eval.json`` ``scores``: mm, AUC, F-scores).
        vr_table: rows per VR bin (``eval.json`` ``vr_table``).
        table: the VR table as markdown.
        files: name -> path of everything written.
        seconds: wall time per stage (``generate``, ``train``, ``evaluate``, ``report``,
            ``total``) of this call.
        config: the [`DemoConfig`][handmesh_tutorial.demo.DemoConfig] used.
        train_epochs: epochs completed by the training run.
        baseline_scores: scores of the rest-hand baseline on the same test scenes.
        comparison: markdown, model / rest hand / mean hand per VR bin, scene kind and overall.
        mean_hand_scores: scores of the mean training hand on the same test scenes.
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


def _generate(root: Path, num: int, seed: int, cfg: DemoConfig, progress: bool, balance: bool):
    import functools

    from .dataset import generate_dataset
    from .interact import KINDS, InteractionConfig, init_worker, make_sample

    # a seed whose scene cannot be built raises InteractionError, a SampleRejected: the
    # writer then tries the next attempt's seed
    fn = functools.partial(make_sample, kind="mixed", image_size=cfg.render_size)
    config = {k: (list(v) if isinstance(v, tuple) else v)
              for k, v in asdict(InteractionConfig()).items()}
    params = {"generator": "handmesh_tutorial.interact.make_sample", "kind": "mixed",
              "limits": config["limits"], "config": config}
    return generate_dataset(root, fn, num, seed, list(KINDS), workers=cfg.workers,
                            progress=progress, params=params,
                            image_size=cfg.render_size, balance_vr=balance,
                            worker_init=functools.partial(init_worker, cfg.render_size))


def generate_data(root: str | os.PathLike, config: DemoConfig | None = None, seed: int = 0,
                  progress: bool = True) -> dict:
    """Generate (or resume) the demo's two sets: ``root/train`` and the VR-balanced ``root/test``.

    Notebooks share data through this call: the same ``root``, sizes and seed reuse what is on
    disk (nothing is regenerated).

    Args:
        root: folder of the two sets.
        config: sizes (``train_samples``, ``test_samples``, ``render_size``, ``workers``,
            ``balance_train``); default
            [`DemoConfig.from_budget`][handmesh_tutorial.demo.DemoConfig.from_budget].
        seed: seed of the training set; the test set uses ``seed + 1``.
        progress: tqdm bars.

    Returns:
        dict with ``train`` and ``test`` roots (``Path``) and their
        [`GenerationSummary`][handmesh_tutorial.dataset.GenerationSummary] as ``train_summary`` and
        ``test_summary``.
    """
    cfg = config or DemoConfig.from_budget()
    root = Path(root)
    tr = _generate(root / "train", cfg.train_samples, seed, cfg, progress, cfg.balance_train)
    te = _generate(root / "test", cfg.test_samples, seed + 1, cfg, progress, True)
    return {"train": root / "train", "test": root / "test", "train_summary": tr,
            "test_summary": te}


def plot_overlays(samples: list, pred_vertices, faces, titles: list | None = None,
                  gt_color=(0.2, 0.8, 0.3), pred_color=(0.35, 0.6, 1.0)):
    """Figure: per sample, the input scene, the ground-truth mesh and the predicted mesh on it.

    Args:
        samples: INTER-SH sample dicts (``image``, ``K``, ``meshes``, ``target``, ``kind``,
            ``vr``).
        pred_vertices: (N, V, 3) predictions in each sample's camera frame, metres.
        faces: (F, 3) faces of the predicted meshes.
        titles: optional extra text per sample (e.g. its error).
        gt_color: RGB of the ground truth.
        pred_color: RGB of the prediction.

    Returns:
        The matplotlib figure (rows of 3 panels, two samples per row).
    """
    import matplotlib.pyplot as plt

    from . import viz

    n = len(samples)
    if len(pred_vertices) != n:
        raise ValueError(f"{n} samples but {len(pred_vertices)} predictions")
    rows = math.ceil(n / 2)
    fig, axes = plt.subplots(rows, 6, figsize=(12, 2.2 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for i, s in enumerate(samples):
        r, c = divmod(i, 2)
        a = axes[r, 3 * c: 3 * c + 3]
        t = s["target"]
        gv, gf = s["meshes"][t]
        extra = "" if titles is None else f"\n{titles[i]}"
        viz.plot_mesh_on_image(a[0], s["image"], gv, gf, s["K"], alpha=0.0,
                               title=f"{s['kind']}, VR {s['vr'][t]:.2f}")
        viz.plot_mesh_on_image(a[1], s["image"], gv, gf, s["K"], color=gt_color,
                               title="ground truth")
        viz.plot_mesh_on_image(a[2], s["image"], pred_vertices[i], faces, s["K"],
                               color=pred_color, title=f"prediction{extra}")
        # identical framing in the three panels: the ground-truth box
        for ax in a[1:]:
            ax.set_xlim(a[0].get_xlim())
            ax.set_ylim(a[0].get_ylim())
        for ax in a:
            ax.axis("on")
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    return fig


def plot_loss_curves(history: list, step_losses: list, baselines: dict | None = None):
    """Figure: training loss per step and per epoch, validation PA-MPJPE / PA-MPVPE per epoch.

    Args:
        history: rows of ``metrics.csv`` (dicts with ``epoch``, ``step``, ``train_loss`` in
            metres, ``val_pa_mpjpe``, ``val_pa_mpvpe`` in mm).
        step_losses: training loss of every step, metres.
        baselines: ``{name: scores}`` of constant baselines on the validation scenes
            ([`constant_hand_scores`][handmesh_tutorial.train.constant_hand_scores]: the rest hand,
            the mean training hand): dashed / dotted lines at their PA-MPJPE and PA-MPVPE, the bars
            the curves must go under.

    Returns:
        The matplotlib figure.
    """
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.4))
    sl = 1000 * np.asarray(step_losses, dtype=float)
    if len(sl):
        a.plot(np.arange(1, len(sl) + 1), sl, lw=0.6, alpha=0.5, label="per step")
    ep = [r["step"] for r in history]
    a.plot(ep, [1000 * r["train_loss"] for r in history], "o-", ms=3, label="epoch mean")
    a.set_yscale("log")  # the first steps are 10x the plateau
    a.set_xlabel("optimiser step")
    a.set_ylabel("L1 vertex loss (mm, log scale)")
    a.set_title("training loss")
    a.grid(alpha=0.3)
    a.legend(fontsize="small")
    e = [r["epoch"] for r in history]
    for key, label in (("val_pa_mpjpe", "PA-MPJPE"), ("val_pa_mpvpe", "PA-MPVPE"),
                       ("val_mpjpe", "MPJPE (root-rel.)")):
        vals = [r.get(key, math.nan) for r in history]
        if np.isfinite(vals).any():
            line = b.plot(e, vals, "o-", ms=3, label=label)[0]
            base_key = key[len("val_"):]
            for (name, sc), style in zip((baselines or {}).items(), ("--", ":", "-."),
                                         strict=False):
                if base_key in sc and base_key != "mpjpe":
                    b.axhline(sc[base_key], ls=style, lw=1, color=line.get_color(),
                              label=f"{label}, {name}")
    b.set_xlabel("epoch")
    b.set_ylabel("validation error (mm)")
    b.set_title("validation (10% of the training scenes)")
    b.grid(alpha=0.3)
    b.legend(fontsize="small")
    fig.tight_layout()
    return fig


def headline(scores: dict, baseline: dict | None = None, mean: dict | None = None) -> str:
    """The headline scores as a markdown table (formats of
    [`HEADLINE`][handmesh_tutorial.demo.HEADLINE]).

    Args:
        scores: ``eval.json`` ``scores``
            ([`freihand_scores`][handmesh_tutorial.metrics.freihand_scores]), the row `MODEL_ROW`.
        baseline: optional scores of the rest-hand baseline on the same scenes (``eval.json``
            ``baseline.scores``), the row `BASELINE_ROW`.
        mean: optional scores of the mean training hand (``eval.json``
            ``mean_hand_baseline.scores``), the row `MEAN_ROW`.

    Returns:
        A markdown table.
    """
    head = "| | " + " | ".join(t for _, t, _ in HEADLINE) + " |"
    sep = "|---|" + "---|" * len(HEADLINE)
    rows = ([(MODEL_ROW, scores)] + ([(BASELINE_ROW, baseline)] if baseline else [])
            + ([(MEAN_ROW, mean)] if mean else []))
    lines = [head, sep] + ["| " + name + " | " + " | ".join(
        f.format(sc[k]) if k in sc else "-" for k, _, f in HEADLINE) + " |" for name, sc in rows]
    return "\n".join(lines)


def write_report(path: str | os.PathLike, *, scores: dict, table: str, config: DemoConfig,
                 seconds: dict, figures: dict, counts: dict, train_info: dict,
                 baseline: dict | None = None, comparison: str = "",
                 mean: dict | None = None) -> Path:
    """Write ``report.md`` (atomically).

    Args:
        path: the report file.
        scores: held-out scores (``eval.json`` ``scores``).
        table: VR table (markdown) from [`evaluate`][handmesh_tutorial.train.evaluate].
        config: the run's [`DemoConfig`][handmesh_tutorial.demo.DemoConfig].
        seconds: wall time per stage.
        figures: caption -> figure path (relative links are made from the report's folder).
        counts: ``train``/``test`` scene counts and VR histograms.
        train_info: ``epochs``, ``steps``, ``checkpoint``, ``parameters``, ``size_ratio``
            (mean predicted / true bounding-box diagonal over the test scenes).
        baseline: scores of the rest-hand baseline (a second row of the headline table).
        mean: scores of the mean training hand (a third row).
        comparison: model / rest hand / mean hand per VR bin and scene kind (``evaluate``'s
            ``comparison``).

    Returns:
        The report path.
    """
    path = Path(path)
    rel = {k: os.path.relpath(v, path.parent) for k, v in figures.items()}
    lines = [
        "# handmesh demo: MSMR-Net on a small INTER-SH set",
        "",
        f"Budget tier `{config.budget}`: {counts['train']} training scenes and "
        f"{counts['test']} held-out test scenes (hand-hand, hand-object, hand-chain; target-hand "
        f"VR of the test scenes balanced over the paper's four bins), rendered at "
        f"{config.render_size} px, network "
        f"crops of {config.image_size} px. MSMR-Net ({config.encoder} encoder, "
        f"{config.decoder}-path decoder, attention {'on' if config.attention else 'off'}, "
        f"{train_info['parameters'] / 1e6:.1f} M parameters; recipe `{config.recipe}`"
        + (": 2D keypoint head with features pooled at the joints, global-rotation head, "
           "skinned decoder output, keypoint and aligned-joint losses beside the paper's L1"
           if config.recipe == "cpu"
           else ": the paper's L1 only")
        + ") trained from scratch on CPU for "
        f"{train_info['epochs']} epochs ({train_info['steps']} steps, batch "
        f"{config.batch_size}, Adam lr {config.lr:g}).",
        "",
        "## Held-out scores",
        "",
        "FreiHAND protocol (MPJPE root-relative, root = joint 9; PA- = after Procrustes "
        "alignment; F-scores on aligned vertices; AUC of the 3D PCK of aligned joints), over all "
        "test scenes, target hand only. The other rows need no network, each predicts one "
        "constant mesh for every image: the template's open rest-pose hand, and the mean "
        "training hand (the Procrustes mean of the training meshes: the data's average "
        "articulation). After alignment they are the bars to clear: below the rest hand, a "
        "model has learnt the data's typical pose; below the mean hand, it reads each hand's "
        "pose from its image. (Their MPJPE, without alignment, is not meaningful: they never "
        "turn.) Roughness: mean |dihedral-angle difference| to the true surface over interior "
        "edges (crumpled meshes score tens of degrees); flipped faces: share of faces whose "
        "normal points against the true one after alignment.",
        "",
        headline(scores, baseline, mean),
        "",
        "## Scores per visibility-ratio bin (paper Table 2 layout)",
        "",
        "AUC over 0-20 mm (20 thresholds) as in the paper; `all` = every test scene.",
        "",
        table,
        "",
        *(["## Model / rest hand / mean hand per VR bin and scene kind", "",
           "Each cell: the network's score / the rest hand's"
           + (" / the mean training hand's" if mean else "") + ", on the same scenes.", "",
           comparison, ""] if comparison else []),
        "## Figures",
        "",
    ]
    for caption, p in rel.items():
        lines += [f"**{caption}**", "", f"![{caption}]({p})", ""]
    lines += [
        "## Run",
        "",
        "| stage | seconds |",
        "|---|---|",
        *[f"| {k} | {v:.1f} |" for k, v in seconds.items()],
        "",
        f"Training VR histogram {counts['train_vr']}, test {counts['test_vr']} "
        "(bins [0.40, 0.60), [0.60, 0.80), [0.80, 0.95), [0.95, 1.00]).",
        f"Evaluated checkpoint: `{train_info['checkpoint']}`.",
        "",
        f"Predicted meshes span on average {100 * train_info['size_ratio']:.0f}% of the size of "
        "the true hand (bounding-box diagonal). Far below 100% means the network is still on the "
        "first plateau of the loss, predicting one small, nearly pose-independent mesh near the "
        "root (the L1-optimal answer while it cannot read the hand's 3D orientation); the "
        "aligned errors above then measure that mesh's shape, not a pose estimate.",
        "",
        f"These numbers come from a model trained from scratch for minutes on {counts['train']} "
        "synthetic scenes, not the paper's ImageNet-pretrained encoder and 200 epochs on tens "
        "of thousands: they show the pipeline working end to end at laptop scale, not the "
        "paper's accuracy (see notebooks 08-10).",
        "",
    ]
    atomic_write_text(path, "\n".join(lines))
    return path


def train_config(config: DemoConfig, data: str | os.PathLike, out_dir: str | os.PathLike,
                 seed: int = 0, progress: bool = True, **overrides):
    """The demo's [`TrainConfig`][handmesh_tutorial.train.TrainConfig] (notebooks 08-10 train with
    it).

    10% of ``data`` is held out for per-epoch validation; the learning rate is halved once, after
    three quarters of the epochs; crops are cached in memory; CPU; the loss terms and keypoint head
    of ``config.recipe`` ([`RECIPES`][handmesh_tutorial.demo.RECIPES]).

    Args:
        config: the demo's sizes and choices.
        data: INTER-SH training root.
        out_dir: the run's folder.
        seed: initialisation, data order, split and augmentation seed.
        progress: tqdm bars.
        **overrides: any [`TrainConfig`][handmesh_tutorial.train.TrainConfig] field (e.g.
            ``decoder``, ``attention`` for the ablation).

    Returns:
        The config.
    """
    from .train import TrainConfig

    if config.recipe not in RECIPES:
        raise ValueError(f"recipe must be one of {sorted(RECIPES)}, got {config.recipe!r}")
    kw = dict(data=str(data), out_dir=str(out_dir), val_fraction=0.1,
              image_size=config.image_size, epochs=config.epochs, batch_size=config.batch_size,
              lr=config.lr, lr_step=max(1, round(0.75 * config.epochs)), augment=config.augment,
              encoder=config.encoder, decoder=config.decoder, attention=config.attention,
              seed=seed, device="cpu", threads=config.threads, cache_data=True,
              progress=progress, **RECIPES[config.recipe])
    kw.update(overrides)
    return TrainConfig(**kw)


def run_demo(out: str | os.PathLike = "runs/demo", seed: int = 0, config: DemoConfig | None = None,
             progress: bool = True, log=print) -> DemoResult:
    """Generate data, train, evaluate and write the report (resumable; see the module docs).

    Args:
        out: output folder.
        seed: seed of the training data (the test data uses ``seed + 1``), of the network
            initialisation, data order and augmentation.
        config: sizes (default
            [`DemoConfig.from_budget`][handmesh_tutorial.demo.DemoConfig.from_budget] of
            ``hmt.budget()``).
        progress: tqdm bars.
        log: called with one-line progress messages (``None``: silent).

    Returns:
        A [`DemoResult`][handmesh_tutorial.demo.DemoResult].

    Raises:
        ValueError: ``out`` holds a run of another configuration (the message says what
            differs; delete the folder or pick another ``--out``).
    """
    import matplotlib.pyplot as plt

    from . import train as T
    from . import viz
    from .dataset import InterSHDataset
    from .model import parameter_counts

    cfg = config or DemoConfig.from_budget()
    say = log or (lambda *_: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    seconds = {}

    say(f"[1/4] generating {cfg.train_samples} training + {cfg.test_samples} test scenes "
        f"(mixed kinds; test set VR-balanced) in {out / 'data'}")
    t = time.perf_counter()
    data = generate_data(out / "data", cfg, seed, progress)
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
    files["overlays"] = viz.save_figure(fig, out / "overlays.png", dpi=80)
    plt.close(fig)
    fig = plot_loss_curves(res.history, res.step_losses, val_baselines)
    files["loss"] = viz.save_figure(fig, out / "loss.png", dpi=90)
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
                                   comparison=ev["comparison"], mean=mean_scores)
    summary = {"config": asdict(cfg), "seed": seed, "scores": ev["scores"],
               "baseline_scores": baseline, "baseline": BASELINE_ROW,
               "mean_hand_scores": mean_scores, "mean_hand": MEAN_ROW,
               "vr_table": ev["vr_table"], "kind_table": ev["kind_table"],
               "baseline_vr_table": ev["baseline"]["vr_table"],
               "baseline_kind_table": ev["baseline"]["kind_table"],
               "mean_hand_vr_table": ev["mean_hand_baseline"]["vr_table"],
               "mean_hand_kind_table": ev["mean_hand_baseline"]["kind_table"], "seconds": seconds,
               "counts": counts,
               "train": train_info, "files": {k: str(v) for k, v in files.items()}}
    files["json"] = out / "demo.json"
    atomic_write_text(files["json"], json.dumps(json_safe(summary), indent=1))
    return DemoResult(out_dir=out, report=files["report"], scores=ev["scores"],
                      vr_table=ev["vr_table"], table=ev["table"], files=files, seconds=seconds,
                      config=cfg, train_epochs=res.epochs, baseline_scores=baseline,
                      comparison=ev["comparison"], mean_hand_scores=mean_scores)


def parse_headline(report: str, row: str = MODEL_ROW) -> dict:
    """Read the headline scores back from a report's text (the inverse of
    [`headline`][handmesh_tutorial.demo.headline]).

    Args:
        report: the text of ``report.md``.
        row: `MODEL_ROW`, `BASELINE_ROW` or `MEAN_ROW`.

    Returns:
        {score key: float} for the keys of [`HEADLINE`][handmesh_tutorial.demo.HEADLINE].

    Raises:
        ValueError: the report has no headline table, or the table has no such row.
    """
    titles = r" \| ".join(re.escape(t) for _, t, _ in HEADLINE)
    m = re.search(r"\| \| " + titles + r" \|\n\|[-|]+\n((?:\|[^\n]+\|\n?)+)", report)
    if m is None:
        raise ValueError("no headline table in the report")
    found = {}
    for line in m.group(1).strip().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        found[cells[0]] = cells[1:]
    if row not in found:
        raise ValueError(f"the headline table has no row {row!r} (rows: {list(found)})")
    vals = [math.nan if x == "-" else float(x) for x in found[row]]
    return {k: v for (k, _, _), v in zip(HEADLINE, vals, strict=True)}
