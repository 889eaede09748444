"""The demo's report: the headline table of scores, ``report.md``, and reading the table back.

Scores as in ``eval.json``: errors in millimetres, AUCs and F-scores in [0, 1]. Taught in notebook
00 ("Quickstart") and notebook 08 ("Training").
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

from ..._io import atomic_write_text
from .config import DemoConfig

__all__ = ["headline", "write_report", "parse_headline", "HEADLINE", "MODEL_ROW", "BASELINE_ROW",
           "MEAN_ROW", "PRETRAINED_ROW"]

MODEL_ROW, BASELINE_ROW, MEAN_ROW = ("MSMR-Net", "rest hand (no network)",
                                     "mean training hand (no network)")
"""Row names of the headline table: the trained network and the two constant baselines of
[`handmesh_tutorial.train.evaluate`][handmesh_tutorial.train.evaluation.evaluate]: the rest hand
(the template's open hand) and the mean training hand
([`handmesh_tutorial.train.mean_hand`][handmesh_tutorial.train.baselines.mean_hand]), each predicted
for every image.
"""
PRETRAINED_ROW = "pretrained MSMR-Net (shipped)"
"""Row name of the network that ships with the package
([`handmesh_tutorial.pretrained`][handmesh_tutorial.pretrained]), scored on the same scenes."""

HEADLINE = (("mpjpe", "MPJPE (mm)", "{:.2f}"), ("pa_mpjpe", "PA-MPJPE (mm)", "{:.2f}"),
            ("pa_mpvpe", "PA-MPVPE (mm)", "{:.2f}"),
            ("f_at_5mm", "F@5mm", "{:.3f}"), ("f_at_15mm", "F@15mm", "{:.3f}"),
            ("auc_joints", "AUC joints 0-50mm", "{:.3f}"),
            ("auc_joints_20mm", "AUC joints 0-20mm", "{:.3f}"),
            ("roughness_deg", "roughness (deg)", "{:.1f}"), ("flipped", "flipped faces", "{:.3f}"))
"""Scores in the report's headline table: (eval.json key, column title, format)."""


def headline(scores: dict, baseline: dict | None = None, mean: dict | None = None,
             pretrained: dict | None = None) -> str:
    """The headline scores as a markdown table (formats of
    [`HEADLINE`][handmesh_tutorial.apps.demo.report.HEADLINE]).

    Args:
        scores: ``eval.json`` ``scores``
            ([`freihand_scores`][handmesh_tutorial.metrics.freihand_scores]), the row `MODEL_ROW`.
        baseline: optional scores of the rest-hand baseline on the same scenes (``eval.json``
            ``baseline.scores``), the row `BASELINE_ROW`.
        mean: optional scores of the mean training hand (``eval.json``
            ``mean_hand_baseline.scores``), the row `MEAN_ROW`.
        pretrained: optional scores of the shipped pretrained network on the same scenes, the
            row `PRETRAINED_ROW` (second).

    Returns:
        A markdown table.
    """
    head = "| | " + " | ".join(t for _, t, _ in HEADLINE) + " |"
    sep = "|---|" + "---|" * len(HEADLINE)
    rows = ([(MODEL_ROW, scores)] + ([(PRETRAINED_ROW, pretrained)] if pretrained else [])
            + ([(BASELINE_ROW, baseline)] if baseline else [])
            + ([(MEAN_ROW, mean)] if mean else []))
    lines = [head, sep] + ["| " + name + " | " + " | ".join(
        f.format(sc[k]) if k in sc else "-" for k, _, f in HEADLINE) + " |" for name, sc in rows]
    return "\n".join(lines)


def write_report(path: str | os.PathLike, *, scores: dict, table: str, config: DemoConfig,
                 seconds: dict, figures: dict, counts: dict, train_info: dict,
                 baseline: dict | None = None, comparison: str = "",
                 mean: dict | None = None, pretrained: dict | None = None,
                 intervals: dict | None = None, encoder: str | None = None) -> Path:
    """Write ``report.md`` (atomically).

    Args:
        path: the report file.
        scores: held-out scores (``eval.json`` ``scores``).
        table: VR table (markdown) from [`evaluate`][handmesh_tutorial.train.evaluation.evaluate].
        config: the run's [`DemoConfig`][handmesh_tutorial.apps.demo.config.DemoConfig].
        seconds: wall time per stage.
        figures: caption -> figure path (relative links are made from the report's folder).
        counts: ``train``/``test`` scene counts and VR histograms.
        train_info: ``epochs``, ``steps``, ``checkpoint``, ``parameters``, ``size_ratio``
            (mean predicted / true bounding-box diagonal over the test scenes).
        baseline: scores of the rest-hand baseline (a second row of the headline table).
        mean: scores of the mean training hand (a third row).
        comparison: model / rest hand / mean hand per VR bin and scene kind (``evaluate``'s
            ``comparison``).
        pretrained: scores of the shipped pretrained network on the same scenes (a row after
            the model's).
        intervals: row name -> the model's PA-MPJPE minus that row's, paired per scene
            ([`paired_difference`][handmesh_tutorial.metrics.intervals.paired_difference]).
        encoder: where the encoder's weights came from (one sentence).

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
        + (": the library's CPU recipe, not the paper's: 2D keypoint head with features "
           "pooled at the joints, global-rotation head, skinned decoder output, keypoint and "
           "aligned-joint losses beside the paper's L1"
           if config.recipe == "cpu"
           else ": the paper's network and loss: the decoder regresses the vertex coordinates, "
           "one L1 loss on the root-centred vertices")
        + ") trained on CPU for "
        f"{train_info['epochs']} epochs ({train_info['steps']} steps, batch "
        f"{config.batch_size}, Adam lr {config.lr:g}).",
        "",
        *([f"Encoder: {encoder}. Everything after the encoder starts from random weights.", ""]
          if encoder else []),
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
        "normal points against the true one after alignment."
        + (f" The row `{PRETRAINED_ROW}` is the network that ships with the package "
           "(`hmt.pretrained.pretrained()`), trained on a GPU on 224-px scenes of other seeds; "
           "here it reads crops of these scenes at its own input size." if pretrained else ""),
        "",
        headline(scores, baseline, mean, pretrained),
        "",
        *(["PA-MPJPE of the network minus each other row's, paired scene by scene (95 % "
           "Student-t interval over the test scenes; an interval that contains 0 does not tell "
           "the two apart):", "",
           "| compared with | difference (mm) | 95 % interval | network better on |",
           "|---|---|---|---|",
           *[f"| {name} | {d['difference']:+.2f} | {d['low']:+.2f} to {d['high']:+.2f} | "
             f"{100 * d['a_better']:.0f} % of {d['n']} scenes |" for name, d in intervals.items()],
           ""] if intervals else []),
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
        f"These numbers come from a network whose mesh part trained for minutes on "
        f"{counts['train']} synthetic scenes, not the paper's ImageNet-pretrained encoder and "
        "200 epochs on FreiHAND: they show the pipeline working end to end at laptop scale, "
        "not the paper's accuracy (see notebooks 08-10).",
        "",
    ]
    atomic_write_text(path, "\n".join(lines))
    return path


def parse_headline(report: str, row: str = MODEL_ROW) -> dict:
    """Read the headline scores back from a report's text (the inverse of
    [`headline`][handmesh_tutorial.apps.demo.report.headline]).

    Args:
        report: the text of ``report.md``.
        row: `MODEL_ROW`, `PRETRAINED_ROW`, `BASELINE_ROW` or `MEAN_ROW`.

    Returns:
        {score key: float} for the keys of
        [`HEADLINE`][handmesh_tutorial.apps.demo.report.HEADLINE].

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
