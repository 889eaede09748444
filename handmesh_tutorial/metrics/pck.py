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
        errors: errors of any shape (metres), numpy or torch; flattened; finite and ``>= 0``.
        thresholds: (T,) strictly increasing thresholds in metres, finite and ``>= 0``.

    Returns:
        (T,) float64 fractions in [0, 1].

    Raises:
        ValueError: no errors, a NaN, infinite or negative error (a signed difference is not
            a distance), or thresholds that are not finite, non-negative and increasing.
    """
    e = _as_f64(errors, "errors", last=None, ndim=None).ravel()
    if e.size == 0:
        raise ValueError("errors is empty")
    if e.min() < 0:
        raise ValueError(f"errors must be distances >= 0 (metres), got min {e.min():.6g}: pass "
                         "point_errors(pred, gt), not signed differences")
    return _pck_sorted(np.sort(e), _check_thresholds(thresholds))


def _check_thresholds(thresholds) -> np.ndarray:
    """(T,) float64 thresholds: finite, >= 0, increasing; else a ValueError that shows them."""
    t = np.asarray(thresholds, dtype=np.float64)
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or t.min() < 0 \
            or np.any(np.diff(t) <= 0):
        raise ValueError("thresholds must be a 1-D array of finite, non-negative, strictly "
                         f"increasing distances in metres, got {np.asarray(thresholds)!r}")
    return t


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
        pck: (T,) PCK values from [`pck_curve`][handmesh_tutorial.metrics.pck.pck_curve],
            each in [0, 1].
        thresholds: (T,) the thresholds (metres) the curve was computed at: T >= 2, finite,
            ``>= 0``, strictly increasing.

    Returns:
        The AUC, a float in [0, 1].

    Raises:
        ValueError: shapes that differ, fewer than 2 thresholds, thresholds that are not
            finite, non-negative and increasing, or a PCK value outside [0, 1] (NaN included).
    """
    y = np.asarray(pck, dtype=np.float64)
    t = np.asarray(thresholds, dtype=np.float64)
    if y.shape != t.shape or t.ndim != 1 or t.size < 2:
        raise ValueError(f"pck {y.shape} and thresholds {t.shape} must be equal 1-D shapes, "
                         "at least 2 thresholds")
    _check_thresholds(t)
    bad = np.flatnonzero(~((y >= 0) & (y <= 1)))
    if bad.size:
        raise ValueError(f"pck values must be fractions in [0, 1] (pck_curve's output), got "
                         f"{float(y[bad[0]])!r} at index {int(bad[0])} ({bad.size} such values)")
    return _trapezoid(y, t) / _trapezoid(np.ones_like(t), t)
