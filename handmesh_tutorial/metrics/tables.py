"""Score tables: per visibility-ratio bin (the paper's Table 2), per group, comparisons, markdown.

The VR bins are defined once, in [`visibility`][handmesh_tutorial.visibility]:
[0.40,0.60), [0.60,0.80), [0.80,0.95), [0.95,1.00] (half-open, the last closed).

Taught in notebook 09 ("Evaluation").
"""

from __future__ import annotations

import math

import numpy as np

from ..visibility import VR_BINS, vr_bin_index
from .pck import PAPER_THRESHOLDS, auc, pck_curve

__all__ = [
    "VR_BIN_LABELS",
    "comparison_table",
    "format_table",
    "scores_by_group",
    "scores_by_vr_bin",
]


VR_BIN_LABELS = ("[0.40, 0.60)", "[0.60, 0.80)", "[0.80, 0.95)", "[0.95, 1.00]")
"""Printable labels of [`VR_BINS`][handmesh_tutorial.visibility.VR_BINS] (half-open, the last
closed)."""


def scores_by_vr_bin(per_sample: dict, vr, bins=VR_BINS,
                     thresholds=PAPER_THRESHOLDS) -> list[dict]:
    """A table of scores per visibility-ratio bin (the paper's Table 2 layout).

    Args:
        per_sample: output of
            [`per_sample_scores`][handmesh_tutorial.metrics.scores.per_sample_scores] for N samples.
        vr: (N,) visibility ratio of each sample's target hand, each in [0, 1] (values
            below the first bin's low end, 0.40 for the paper's, fall in no bin).
        bins: the VR bins; see [`vr_bin_index`][handmesh_tutorial.visibility.vr_bin_index].
        thresholds: PCK thresholds (metres) of the AUC; the paper's 0-20 mm, 20 values.

    Returns:
        One dict per bin with ``bin`` (label), ``lo``, ``hi``, ``count``, ``mpjpe``, ``rr_mpjpe``
        (root-relative), ``pa_mpjpe`` (mm), ``auc`` (aligned joints, in [0,1]) and, when vertices
        were scored, ``pa_mpvpe`` (mm), ``f_at_5mm``, ``f_at_15mm``; the
        [`SURFACE_KEYS`][handmesh_tutorial.metrics.tables.SURFACE_KEYS] averaged when ``per_sample``
        holds them. Empty bins have ``count`` 0 and NaN scores.

    Raises:
        ValueError: ``vr`` has another length than the samples, or a value that is not a
            ratio in [0, 1] (NaN, negative, above 1): such samples were dropped silently
            before.
    """
    v = np.asarray(vr, dtype=np.float64).ravel()
    n = per_sample["joint_err"].shape[0]
    if v.shape[0] != n:
        raise ValueError(f"vr has {v.shape[0]} values but per_sample has {n} samples")
    bad = np.flatnonzero(~((v >= 0.0) & (v <= 1.0)))
    if bad.size:
        raise ValueError(f"vr must be visibility ratios in [0, 1], got {float(v[bad[0]])!r} "
                         f"at sample {int(bad[0])} ({bad.size} such values); a VR is visible / "
                         "alone pixels, so NaN, negative or > 1 values mean a bookkeeping error "
                         "(score samples without a VR with scores_by_group or freihand_scores)")
    idx = vr_bin_index(v, bins)
    labels = VR_BIN_LABELS if tuple(map(tuple, bins)) == VR_BINS else [
        f"[{lo:.2f}, {hi:.2f}" + ("]" if k == len(bins) - 1 else ")")
        for k, (lo, hi) in enumerate(bins)]
    rows = []
    for k, (lo, hi) in enumerate(bins):
        row = {"bin": labels[k], "lo": lo, "hi": hi}
        row.update(_group_scores(per_sample, idx == k, thresholds))
        rows.append(row)
    return rows


SURFACE_KEYS = ("roughness_deg", "flipped")
"""Per-sample surface scores that group rows average when ``per_sample`` holds them
([`handmesh_tutorial.metrics.surface.roughness_deg`][handmesh_tutorial.metrics.surface.roughness_deg],
``flipped_face_fraction``).
"""


def _group_scores(per_sample: dict, sel: np.ndarray, thresholds) -> dict:
    """Mean scores of the samples ``sel`` (bool mask): a row of the VR / kind tables."""
    row = {"count": int(sel.sum())}
    empty = row["count"] == 0

    def mm(key):
        return math.nan if empty else 1000.0 * float(per_sample[key][sel].mean())

    row["mpjpe"] = mm("joint_err")
    row["rr_mpjpe"] = mm("joint_err_rr")
    row["pa_mpjpe"] = mm("joint_err_pa")
    row["auc"] = (math.nan if empty else
                  auc(pck_curve(per_sample["joint_err_pa"][sel], thresholds), thresholds))
    if "vert_err_pa" in per_sample:
        row["pa_mpvpe"] = mm("vert_err_pa")
        ths = list(np.round(np.asarray(per_sample["fscore_thresholds"]) * 1000, 6))
        for th_mm in (5.0, 15.0):
            if th_mm in ths:
                j = ths.index(th_mm)
                row[f"f_at_{int(th_mm)}mm"] = (math.nan if empty else
                                               float(per_sample["fscore"][sel, j].mean()))
    for key in SURFACE_KEYS:
        if key in per_sample:
            row[key] = math.nan if empty else float(np.asarray(per_sample[key])[sel].mean())
    return row


def scores_by_group(per_sample: dict, labels, order=None,
                    thresholds=PAPER_THRESHOLDS) -> list[dict]:
    """A table of scores per group of samples, e.g. per scene kind (rows as in
    [`scores_by_vr_bin`][handmesh_tutorial.metrics.tables.scores_by_vr_bin]).

    Args:
        per_sample: output of
            [`per_sample_scores`][handmesh_tutorial.metrics.scores.per_sample_scores] for N samples
            (optionally with the [`SURFACE_KEYS`][handmesh_tutorial.metrics.tables.SURFACE_KEYS]
            added, ``(N,)`` each).
        labels: ``(N,)`` group label of each sample (``None`` = in no group).
        order: the groups to report, in order (default: the distinct labels, sorted); a group
            with no sample gets ``count`` 0 and NaN scores.
        thresholds: PCK thresholds (metres) of the AUC.

    Returns:
        One dict per group with ``bin`` (the label) and the scores of
        [`scores_by_vr_bin`][handmesh_tutorial.metrics.tables.scores_by_vr_bin].
    """
    lab = np.array([None if x is None else str(x) for x in labels], dtype=object)
    n = per_sample["joint_err"].shape[0]
    if lab.shape[0] != n:
        raise ValueError(f"labels has {lab.shape[0]} values but per_sample has {n} samples")
    if order is None:
        order = sorted({x for x in lab if x is not None})
    return [{"bin": str(g), **_group_scores(per_sample, lab == str(g), thresholds)}
            for g in order]


def comparison_table(rows: list[dict], *baseline_rows: list[dict],
                     columns=("pa_mpjpe", "pa_mpvpe", "f_at_15mm", "roughness_deg", "flipped"),
                     first: str = "group") -> str:
    """Markdown table of a model beside one or more baselines: each cell ``model / baseline``
    (``model / baseline 1 / baseline 2 ...``).

    Args:
        rows: the model's rows
            ([`scores_by_vr_bin`][handmesh_tutorial.metrics.tables.scores_by_vr_bin],
            [`scores_by_group`][handmesh_tutorial.metrics.tables.scores_by_group], or an overall row
            with ``bin`` ``"all"``).
        *baseline_rows: each baseline's rows on the same samples, same order and labels.
        columns: score keys to show (those missing from the rows are left out).
        first: title of the label column.

    Returns:
        The table (str).

    Raises:
        ValueError: no baseline, or a baseline's labels differ from the model's.
    """
    if not baseline_rows:
        raise ValueError("give at least one baseline's rows")
    labels = [r.get("bin") for r in rows]
    for b in baseline_rows:
        if [r.get("bin") for r in b] != labels:
            raise ValueError(f"rows {labels} and baseline rows {[r.get('bin') for r in b]} "
                             "differ")
    known = {k: (title, fmt) for k, title, fmt in _COLUMNS}
    cols = [k for k in columns if rows and k in rows[0]
            and all(k in b[0] for b in baseline_rows)]
    header = [first, "N"] + [known.get(k, (k, ""))[0] for k in cols]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]

    def cell(val, fmt):
        return "-" if isinstance(val, float) and math.isnan(val) else fmt.format(val)

    for i, r in enumerate(rows):
        cells = [str(r.get("bin", "")), str(r.get("count", ""))]
        for k in cols:
            fmt = known.get(k, (k, "{:.4g}"))[1]
            cells.append(" / ".join(cell(x[k], fmt) for x in
                                    (r, *(b[i] for b in baseline_rows))))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


_COLUMNS = (("count", "N", "{:d}"), ("auc", "AUC 0-20mm", "{:.3f}"),
            ("pa_mpjpe", "PA-MPJPE (mm)", "{:.2f}"), ("pa_mpvpe", "PA-MPVPE (mm)", "{:.2f}"),
            ("mpjpe", "MPJPE (mm)", "{:.2f}"), ("rr_mpjpe", "RR-MPJPE (mm)", "{:.2f}"),
            ("f_at_5mm", "F@5mm", "{:.3f}"), ("f_at_15mm", "F@15mm", "{:.3f}"),
            ("roughness_deg", "roughness (deg)", "{:.1f}"), ("flipped", "flipped faces", "{:.1%}"))


def format_table(rows: list[dict], columns=None) -> str:
    """Format [`scores_by_vr_bin`][handmesh_tutorial.metrics.tables.scores_by_vr_bin] rows (or any
    list of such dicts) as a markdown table.

    Args:
        rows: list of dicts with a ``bin`` label and score keys.
        columns: keys to show, in order; the default shows those present among count, AUC,
            PA-MPJPE, PA-MPVPE, MPJPE, RR-MPJPE, F@5mm, F@15mm.

    Returns:
        A markdown table (str), one line per row; NaN shows as ``-``.
    """
    known = {k: (title, fmt) for k, title, fmt in _COLUMNS}
    if columns is None:
        columns = [k for k, _, _ in _COLUMNS if rows and k in rows[0]]
    header = ["VR"] + [known.get(k, (k, ""))[0] for k in columns]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        cells = [str(r.get("bin", ""))]
        for k in columns:
            val = r.get(k, math.nan)
            fmt = known.get(k, (k, "{:.4g}"))[1]
            if isinstance(val, float) and math.isnan(val):
                cells.append("-")
            else:
                cells.append(fmt.format(val))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
