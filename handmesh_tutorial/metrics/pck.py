"""Per-point errors, PCK curves and their AUC (the official FreiHAND thresholds and the paper's).

A point counts as correct when ``error <= threshold`` (metres); the AUC is the trapezoid
integral of the PCK curve divided by that of 1 over the same thresholds.

Taught in notebook 09 ("Evaluation").
"""

from __future__ import annotations

import numpy as np

from ._common import _as_f64, _pair, _sq_norm

__all__ = ["FREIHAND_THRESHOLDS", "PAPER_THRESHOLDS", "auc", "pck_curve", "point_errors"]


FREIHAND_THRESHOLDS = np.linspace(0.0, 0.05, 100)
"""PCK thresholds of the official FreiHAND AUC: 0 to 50 mm, 100 values (metres)."""
PAPER_THRESHOLDS = np.linspace(0.0, 0.02, 20)
"""PCK thresholds of the paper's INTER-SH table (Table 2): 0 to 20 mm, 20 values (metres)."""


def point_errors(pred, gt) -> np.ndarray:
    """Per-point Euclidean errors ``||pred_i - gt_i||`` (official formula, float64).

    Args:
        pred: (N,P,3) metres.
        gt: (N,P,3) metres.

    Returns:
        (N,P) errors in metres.
    """
    p, g = _pair(pred, gt, "pred", "gt")
    return np.sqrt(_sq_norm(g - p))


def pck_curve(errors, thresholds=FREIHAND_THRESHOLDS) -> np.ndarray:
    """Percentage of correct points: fraction of errors ``<= t`` for each threshold ``t``.

    With every keypoint visible (FreiHAND), the official per-keypoint curves averaged over
    keypoints equal this fraction over all (sample, point) pairs.

    Args:
        errors: errors of any shape (metres), numpy or torch; flattened.
        thresholds: (T,) increasing thresholds in metres.

    Returns:
        (T,) float64 fractions in [0, 1].
    """
    e = _as_f64(errors, "errors", last=None, ndim=None).ravel()
    if e.size == 0:
        raise ValueError("errors is empty")
    return _pck_sorted(np.sort(e), thresholds)


def _pck_sorted(sorted_errors: np.ndarray, thresholds) -> np.ndarray:
    t = np.asarray(thresholds, dtype=np.float64)
    # side='right' counts the errors <= t
    return np.searchsorted(sorted_errors, t, side="right") / sorted_errors.size


def _trapezoid(y, x):
    fn = getattr(np, "trapezoid", None) or np.trapz  # noqa: NPY201 (numpy < 2 has only trapz)
    return float(fn(y, x))


def auc(pck, thresholds=FREIHAND_THRESHOLDS) -> float:
    """Area under a PCK curve, normalised to [0, 1] (official ``EvalUtil.get_measures``).

    ``trapezoid(pck, thresholds) / trapezoid(ones, thresholds)``: for ``linspace(0, 0.05, 100)``
    the normaliser is 0.05.

    Args:
        pck: (T,) PCK values from [`pck_curve`][handmesh_tutorial.metrics.pck.pck_curve].
        thresholds: (T,) the thresholds (metres) the curve was computed at.

    Returns:
        The AUC, a float in [0, 1].
    """
    y = np.asarray(pck, dtype=np.float64)
    t = np.asarray(thresholds, dtype=np.float64)
    if y.shape != t.shape or t.ndim != 1 or t.size < 2:
        raise ValueError(f"pck {y.shape} and thresholds {t.shape} must be equal 1-D shapes, "
                         "at least 2 thresholds")
    return _trapezoid(y, t) / _trapezoid(np.ones_like(t), t)
