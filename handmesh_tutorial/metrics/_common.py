"""Input handling shared by the metrics: numpy/torch -> float64 numpy with named shape checks.

Taught in notebook 09 ("Evaluation").
"""

from __future__ import annotations

import numpy as np


def _as_f64(x, name: str, last: int | None = 3, ndim: int | None = 3) -> np.ndarray:
    """numpy/torch -> float64 numpy, with a shape check that names the argument."""
    if x is None:
        raise ValueError(f"{name} is required")
    if hasattr(x, "detach"):
        x = x.detach().cpu().double().numpy()
    arr = np.asarray(x, dtype=np.float64)
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must have {ndim} dimensions (N,P,3), got shape {arr.shape}")
    if last is not None and arr.shape[-1] != last:
        raise ValueError(f"{name} must end with {last} coordinates, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def _pair(pred, gt, pred_name: str, gt_name: str, same_points: bool = True):
    p = _as_f64(pred, pred_name)
    g = _as_f64(gt, gt_name)
    if p.shape[0] != g.shape[0]:
        raise ValueError(f"{pred_name} and {gt_name} have different sample counts: "
                         f"{p.shape[0]} vs {g.shape[0]}")
    if same_points and p.shape != g.shape:
        raise ValueError(f"{pred_name} shape {p.shape} does not match {gt_name} shape {g.shape}")
    if p.shape[1] == 0 or g.shape[1] == 0:
        raise ValueError(f"{pred_name}/{gt_name} have no points: {p.shape}, {g.shape}")
    return p, g


def _sq_norm(x: np.ndarray) -> np.ndarray:
    """(..., 3) -> (...) squared lengths, (x^2 + y^2) + z^2 like np.sum(np.square(x), -1)."""
    out = np.square(x[..., 0])
    out += np.square(x[..., 1])
    out += np.square(x[..., 2])
    return out
