"""Charts of numbers: 3D PCK curves, scores per visibility-ratio bin, error against VR, and the
training / validation curves of a run.

Errors come in metres and are drawn in millimetres. Taught in notebook 09 ("Evaluation"); the loss
curves in notebook 08 ("Training").
"""

from __future__ import annotations

import math

import numpy as np

from .. import metrics
from .._optional import require
from ..visibility import VR_BINS
from ._common import _to_numpy

__all__ = ["plot_pck_curves", "plot_vr_table", "plot_error_vs_vr", "plot_loss_curves"]


def plot_pck_curves(ax, curves: dict, thresholds=None, unit: str = "mm", show_auc: bool = True):
    """Draw 3D PCK curves (fraction of points with error <= threshold), one line per entry.

    Args:
        ax: a matplotlib ``Axes``.
        curves: {label: errors or (thresholds, pck)}: either an array of point errors in metres (any
            shape; the curve is computed with
            [`handmesh_tutorial.metrics.pck_curve`][handmesh_tutorial.metrics.pck_curve]) or a
            precomputed pair of (T,) thresholds in metres and (T,) PCK values.
        thresholds: (T,) thresholds in metres for error arrays; FreiHAND's 0-50 mm, 100 values
            when ``None``.
        unit: x-axis unit, ``"mm"`` or ``"m"``.
        show_auc: append the normalised AUC to each legend label.

    Shapes:
        ``curves[label]``: errors of any shape (metres), or ``((T,), (T,))``; ``thresholds (T,)``.
    """
    thr_default = metrics.FREIHAND_THRESHOLDS if thresholds is None else np.asarray(thresholds)
    factor = 1000.0 if unit == "mm" else 1.0
    for label, data in curves.items():
        if isinstance(data, tuple) and len(data) == 2:
            thr, pck = np.asarray(data[0], dtype=float), np.asarray(data[1], dtype=float)
        else:
            thr, pck = thr_default, metrics.pck_curve(_to_numpy(data), thr_default)
        text = f"{label} (AUC {metrics.auc(pck, thr):.3f})" if show_auc else str(label)
        ax.plot(thr * factor, pck, label=text)
    ax.set_xlabel(f"error threshold ({unit})")
    ax.set_ylabel("3D PCK")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")


def plot_vr_table(ax, rows: list, metric: str = "auc", label: str | None = None,
                  color=None, offset: float = 0.0, width: float = 0.8):
    """Bar chart of one score per visibility-ratio bin (rows of ``metrics.scores_by_vr_bin``).

    Call it once per model with different ``offset``/``width`` to get grouped bars.

    Args:
        ax: a matplotlib ``Axes``.
        rows: list of per-bin dicts with ``bin``, ``count`` and the ``metric`` key.
        metric: the score to draw, e.g. ``"auc"``, ``"pa_mpjpe"``, ``"f_at_5mm"``.
        label: legend label (e.g. the model name).
        color: bar colour.
        offset: horizontal shift of the bars (for grouped bars).
        width: bar width.

    Returns:
        The matplotlib ``BarContainer``.
    """
    x = np.arange(len(rows)) + offset
    values = [float(r.get(metric, np.nan)) for r in rows]
    bars = ax.bar(x, values, width=width, label=label, color=color)
    for xi, v, r in zip(x, values, rows, strict=True):
        if np.isfinite(v):
            ax.annotate(f"n={r.get('count', '?')}", (xi, v), ha="center", va="bottom",
                        fontsize="x-small")
    ax.set_xticks(np.arange(len(rows)), [str(r.get("bin", "")) for r in rows])
    ax.set_xlabel("visibility ratio (VR) bin")
    ax.set_ylabel(metric)
    return bars


def plot_error_vs_vr(ax, vr, errors, bins=None, label: str = "error", unit: str = "mm",
                     color=None):
    """Scatter of a per-sample error against the target hand's visibility ratio, with bin means.

    Args:
        ax: a matplotlib ``Axes``.
        vr: (N,) visibility ratios in [0, 1] (NaN samples are skipped).
        errors: (N,) per-sample errors (e.g. PA-MPJPE in mm).
        bins: VR bins drawn as shaded bands with their mean error (default the paper's
            ``visibility.VR_BINS``).
        label: legend / y-axis label of the error.
        unit: unit shown on the y axis.
        color: point colour.

    Returns:
        The scatter ``PathCollection``.

    Shapes:
        ``vr (N,)``, ``errors (N,)``; ``bins`` a list of ``(lo, hi)``.
    """
    bins = VR_BINS if bins is None else bins
    v, e = np.asarray(_to_numpy(vr), float).ravel(), np.asarray(_to_numpy(errors), float).ravel()
    ok = np.isfinite(v) & np.isfinite(e)
    pts = ax.scatter(v[ok], e[ok], s=10, alpha=0.6, color=color, label=f"{label} per sample")
    labelled = False
    for k, (lo, hi) in enumerate(bins):
        last = k == len(bins) - 1
        sel = ok & (v >= lo) & ((v <= hi) if last else (v < hi))
        ax.axvspan(lo, hi, color="0.5" if k % 2 else "0.8", alpha=0.15, lw=0)
        if sel.any():
            m = float(e[sel].mean())
            ax.hlines(m, lo, hi, colors="k", lw=2, label=None if labelled else "bin mean")
            labelled = True
            ax.annotate(f"n={int(sel.sum())}", ((lo + hi) / 2, m), ha="center", va="bottom",
                        fontsize="x-small")
    ax.set_xlabel("visibility ratio of the target hand")
    ax.set_ylabel(f"{label} ({unit})")
    low = min(bins[0][0], float(v[ok].min()) if ok.any() else 1.0) - 0.05
    ax.set_xlim(max(low, 0.0), 1.02)
    ax.legend(fontsize="small")
    return pts


def plot_loss_curves(history: list, step_losses: list, baselines: dict | None = None):
    """Figure: training loss per step and per epoch, validation PA-MPJPE / PA-MPVPE per epoch.

    Args:
        history: rows of ``metrics.csv`` (dicts with ``epoch``, ``step``, ``train_loss`` in
            metres, ``val_pa_mpjpe``, ``val_pa_mpvpe`` in mm).
        step_losses: training loss of every step, metres.
        baselines: ``{name: scores}`` of constant baselines on the validation scenes
            ([`constant_hand_scores`][handmesh_tutorial.train.baselines.constant_hand_scores]: the
            rest hand, the mean training hand): dashed / dotted lines at their PA-MPJPE and
            PA-MPVPE, the bars the curves must go under. The validation legend sits outside the
            panel, right of it, so that it covers none of these lines.

    Returns:
        The matplotlib figure.

    Shapes:
        ``step_losses (S,)`` (S optimiser steps); ``history`` one dict per epoch.
    """
    plt = require("matplotlib.pyplot", "hmt.viz figures")

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 3.4), width_ratios=(1, 1.05))
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
    # outside, to the right: inside, the legend covered the baselines' horizontal lines
    b.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    return fig
