"""F-scores of aligned meshes: exact nearest-neighbour distances in both directions.

The candidate search runs in float32 torch with a proven error margin, and every distance
near a threshold is recomputed exactly in float64 (see `f_score`). Points in metres,
shapes (N, P, 3).

Taught in notebook 09 ("Evaluation").
"""

from __future__ import annotations

import numpy as np

from ._common import _pair, _sq_norm

__all__ = ["FSCORE_THRESHOLDS", "f_score", "nearest_distances"]


FSCORE_THRESHOLDS = (0.005, 0.015)
"""F-score distances of the official evaluation (metres): F@5mm and F@15mm."""

_U32 = 2.0 ** -24  # unit roundoff of float32


def nearest_distances(src, dst) -> np.ndarray:
    """Exact distance from every ``src`` point to its nearest ``dst`` point, per sample.

    A straightforward per-sample ``scipy.spatial.cKDTree`` query (the same quantity the official
    code gets from Open3D). [`f_score`][handmesh_tutorial.metrics.fscore.f_score] does not need the
    distances themselves and uses a faster batched search.

    Args:
        src: (N,P,3) query points, metres.
        dst: (N,Q,3) reference points, metres.

    Returns:
        (N,P) distances in metres.
    """
    from scipy.spatial import cKDTree

    s, d = _pair(src, dst, "src", "dst", same_points=False)
    return np.stack([cKDTree(d[i]).query(s[i], k=1)[0] for i in range(len(s))])


def _min_sq_dist_f32(gt: np.ndarray, pred: np.ndarray, block: int = 256):
    """Approximate squared nearest-neighbour distances in both directions, float32.

    Returns (gt_to_pred, pred_to_gt, gt_norm, pred_norm): (N,G), (N,P) squared distances and the
    lengths (N,G), (N,P) of the centred points, from which `_fraction_within` bounds the rounding
    error. One (G,5)x(5,P) product per sample gives the whole squared-distance matrix
    ``|x|^2 + |y|^2 - 2 x.y``; one sample at a time keeps it in cache, which is what makes this
    faster than two KD-tree builds and queries.
    """
    import torch

    g2p = np.empty(gt.shape[:2], dtype=np.float32)
    p2g = np.empty(pred.shape[:2], dtype=np.float32)
    # centre on the ground-truth centroid: small coordinates -> small float32 error
    c = gt.mean(axis=1, keepdims=True)
    x64 = gt - c
    y64 = pred - c
    # the error bound assumes true float32 products: no bf16/TF32 shortcuts while we run
    precision = torch.get_float32_matmul_precision()
    torch.set_float32_matmul_precision("highest")
    try:
        _fill_min_sq(torch, x64, y64, g2p, p2g, block)
    finally:
        torch.set_float32_matmul_precision(precision)
    return g2p, p2g, np.sqrt(_sq_norm(x64)), np.sqrt(_sq_norm(y64))


def _fill_min_sq(torch, x64, y64, g2p, p2g, block):
    n, g = x64.shape[:2]
    p = y64.shape[1]
    with torch.no_grad():
        for s0 in range(0, n, block):
            s1 = min(n, s0 + block)
            # augmented float32 rows [x, |x|^2, 1] and columns [-2y; 1; |y|^2], built in place
            xa = np.empty((s1 - s0, g, 5), dtype=np.float32)
            xa[..., :3] = x64[s0:s1]
            xa[..., 3] = _sq_norm(xa[..., :3])
            xa[..., 4] = 1.0
            ya = np.empty((s1 - s0, 5, p), dtype=np.float32)
            y32 = y64[s0:s1].astype(np.float32)
            ya[:, :3] = -2.0 * y32.transpose(0, 2, 1)
            ya[:, 3] = 1.0
            ya[:, 4] = _sq_norm(y32)
            xa_t, ya_t = torch.from_numpy(xa), torch.from_numpy(ya)
            out_g = torch.from_numpy(g2p[s0:s1])
            out_p = torch.from_numpy(p2g[s0:s1])
            for i in range(s1 - s0):
                dmat = xa_t[i] @ ya_t[i]  # (G,P) squared distances
                torch.amin(dmat, dim=1, out=out_g[i])
                torch.amin(dmat, dim=0, out=out_p[i])


def _exact_min_dist(src: np.ndarray, dst: np.ndarray, sample: np.ndarray, row: np.ndarray,
                    chunk: int = 512) -> np.ndarray:
    """Exact float64 nearest distance of the listed (sample, row) points of src to dst."""
    out = np.empty(len(sample))
    for k0 in range(0, len(sample), chunk):
        s = sample[k0:k0 + chunk]
        q = src[s, row[k0:k0 + chunk]]  # (K,3)
        d2 = _sq_norm(dst[s] - q[:, None, :])  # (K,Q)
        out[k0:k0 + chunk] = np.sqrt(d2.min(axis=1))
    return out


def _fraction_within(approx_sq, norm, src, dst, thresholds):
    """(N,T) fraction of src points whose nearest dst point is closer than each threshold.

    Rounding bound: with X, Y the float32 roundings of centred points x, y and u = 2^-24,
    fl32(|X|^2 + |Y|^2 - 2 X.Y) differs from |x - y|^2 by at most ~10u(|x| + |y|)^2 (coordinate
    rounding 2u(1+u)(.)^2; squared norms gamma_3 and the length-5 dot product gamma_5 add
    8u(1+u)(.)^2). Only neighbours closer than about ``th`` decide "closer than th", and those
    have |y| <= |x| + th, so ``m = 24u(2|x| + th)^2`` (2.4x the bound) separates sure decisions
    from the few that are re-checked with exact float64 distances.
    """
    n, m = approx_sq.shape
    frac = np.empty((n, len(thresholds)))
    for k, th in enumerate(thresholds):
        th2 = th * th
        margin = 24.0 * _U32 * np.square(2.0 * norm + th) + 1e-30
        sure = approx_sq < th2 - margin
        unsure = np.abs(approx_sq - th2) <= margin
        count = sure.sum(axis=1).astype(np.float64)
        if unsure.any():
            s_idx, r_idx = np.nonzero(unsure)
            exact = _exact_min_dist(src, dst, s_idx, r_idx)
            count += np.bincount(s_idx, weights=(exact < th), minlength=n)
        frac[:, k] = count / m
    return frac


def f_score(pred, gt, thresholds=FSCORE_THRESHOLDS) -> dict:
    """Per-sample F-score of two point clouds at distance thresholds (official definition).

    Precision = fraction of predicted points whose nearest ground-truth point is closer than
    ``d`` (strict ``<``); recall = fraction of ground-truth points whose nearest predicted point
    is closer than ``d``; ``F = 2PR/(P+R)``, 0 when ``P+R = 0``. (The official ``eval.py`` names
    the two fractions the other way round; F is symmetric, so the number is the same.)

    The nearest-neighbour search is batched: a float32 squared-distance matrix per sample gives
    every decision that is farther than a proven rounding bound from the threshold; the few
    points within that bound are re-checked with exact float64 distances. The result therefore
    equals exact nearest-neighbour distances compared with ``<``.

    Args:
        pred: (N,P,3) predicted points (metres); P may differ from G.
        gt: (N,G,3) ground-truth points (metres).
        thresholds: distance thresholds in metres, a float or a sequence of T floats, each
            finite and ``> 0``.

    Returns:
        dict with ``f``, ``precision``, ``recall``: (N,T) float64 arrays (T = 1 for a float).

    Raises:
        ValueError: bad shapes, NaN or inf points, or a threshold that is not a finite
            positive number (a NaN threshold would make every point "not closer" and F = 0).
    """
    p, g = _pair(pred, gt, "pred", "gt", same_points=False)
    ths = np.atleast_1d(np.asarray(thresholds, dtype=np.float64))
    if ths.ndim != 1 or ths.size == 0 or not np.all(np.isfinite(ths) & (ths > 0)):
        raise ValueError("thresholds must be one or more finite positive distances in metres "
                         f"(e.g. 0.005), got {thresholds!r}")
    g2p, p2g, g_norm, p_norm = _min_sq_dist_f32(g, p)
    recall = _fraction_within(g2p, g_norm, g, p, ths)
    precision = _fraction_within(p2g, p_norm, p, g, ths)
    denom = precision + recall
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(denom > 0, 2.0 * precision * recall / np.where(denom > 0, denom, 1.0), 0.0)
    return {"f": f, "precision": precision, "recall": recall}
