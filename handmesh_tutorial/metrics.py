"""FreiHAND-exact hand pose and mesh metrics, PCK/AUC, F-scores and visibility-ratio tables.

Everything here reproduces the official FreiHAND evaluation (``eval.py`` and
``utils/eval_util.py`` of the ``lmb-freiburg/freihand`` repository) to 1e-6, batched over samples:

* **Procrustes with scale, per sample**
  ([`procrustes_align`][handmesh_tutorial.metrics.procrustes_align]): both point sets are centred,
  divided by their Frobenius norm plus ``1e-8``, and the rotation comes from the orthogonal
  Procrustes solution ``R = U V^T`` of ``svd(A^T B)`` with scale ``sum(singular values)``
  (``scipy.linalg.orthogonal_procrustes``). That ``R`` may be a *reflection* (det -1); this is the
  default, as in the official code. ``allow_reflection=False`` gives the proper-rotation (Kabsch /
  Umeyama) variant.
* **Joints and vertices are aligned separately**, each with its own Procrustes.
* **MPJPE / MPVPE**: mean Euclidean distance, raw and aligned (PA-), reported in millimetres.
* **PCK** counts an error as correct when ``error <= threshold``; **AUC** is the trapezoid integral
  of the PCK curve over ``linspace(0, 0.05, 100)`` metres divided by the integral of 1 over the
  same thresholds (= 0.05). The paper's INTER-SH table uses 0-20 mm with 20 thresholds.
* **F-score at d** on aligned vertices: nearest-neighbour distances in both directions, a point
  counts when its distance is ``< d`` (strict); ``F = 2PR/(P+R)``, 0 when ``P+R = 0``, averaged
  over samples.

Inputs are metres, numpy arrays or torch tensors; everything is computed in float64 numpy (the
F-score's candidate search runs in float32 torch with a proven error margin; see
[`f_score`][handmesh_tutorial.metrics.f_score]).
"""

from __future__ import annotations

import math

import numpy as np

# The VR bins are defined once, in visibility.py: [0.40,0.60), [0.60,0.80), [0.80,0.95),
# [0.95,1.00] (half-open, the last closed). Re-exported here for tables.
from .visibility import VR_BINS, vr_bin_index  # noqa: F401 - vr_bin_index: part of the VR tables

FREIHAND_THRESHOLDS = np.linspace(0.0, 0.05, 100)
"""PCK thresholds of the official FreiHAND AUC: 0 to 50 mm, 100 values (metres)."""
PAPER_THRESHOLDS = np.linspace(0.0, 0.02, 20)
"""PCK thresholds of the paper's INTER-SH table (Table 2): 0 to 20 mm, 20 values (metres)."""
FSCORE_THRESHOLDS = (0.005, 0.015)
"""F-score distances of the official evaluation (metres): F@5mm and F@15mm."""
VR_BIN_LABELS = ("[0.40, 0.60)", "[0.60, 0.80)", "[0.80, 0.95)", "[0.95, 1.00]")
"""Printable labels of [`VR_BINS`][handmesh_tutorial.visibility.VR_BINS] (half-open, the last
closed)."""
ROOT_INDEX = 9
"""Root keypoint (middle-finger MCP, FreiHAND order) for root-relative errors."""

_EPS_NORM = 1e-8  # added to both Frobenius norms, as in the official align_w_scale
_U32 = 2.0 ** -24  # unit roundoff of float32


# --------------------------------------------------------------------------------------------
# input handling


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


# --------------------------------------------------------------------------------------------
# Procrustes


def procrustes_align(pred, gt, allow_reflection: bool = True, return_transform: bool = False):
    """Align each predicted point set to its ground truth with a similarity transform.

    This is the official FreiHAND ``align_w_scale``, batched: per sample, centre both sets,
    divide each by its Frobenius norm + 1e-8, take ``U, W, V^T = svd(A^T B)`` (``A`` = normalised
    ground truth, ``B`` = normalised prediction), rotation ``R = U V^T`` and scale ``s = sum(W)``,
    and map the prediction to ``s * s_gt * B R^T + mean(gt)``.

    With ``allow_reflection=True`` (official) ``R`` is the orthogonal matrix closest to the
    cross-covariance and may have determinant -1, i.e. mirror the prediction. With ``False`` the
    smallest singular direction is flipped when needed (``R = U diag(1,1,det(UV^T)) V^T``,
    ``s = W1 + W2 + det * W3``), so ``R`` is always a proper rotation.

    Args:
        pred: (N,P,3) predicted points, metres (numpy or torch).
        gt: (N,P,3) ground-truth points, metres, same P (point i corresponds to point i).
        allow_reflection: allow det(R) = -1 (official FreiHAND behaviour).
        return_transform: also return the transform.

    Returns:
        (N,P,3) float64 aligned prediction (metres); with ``return_transform`` a tuple
        ``(aligned, transform)`` where ``transform`` is a dict with ``rotation`` (N,3,3),
        ``scale`` (N,) (total scale applied to the centred prediction) and ``pred_center``,
        ``gt_center`` (N,3), so that ``aligned = scale * (pred - pred_center) @ R^T + gt_center``.

    Raises:
        ValueError: shapes differ or are not (N,P,3), or values are not finite.
    """
    p, g = _pair(pred, gt, "pred", "gt")
    ones = np.full(g.shape[1], 1.0 / g.shape[1])
    t_gt = (ones @ g)[:, None, :]  # centroids as a BLAS product: much faster than .mean(1)
    t_pr = (ones @ p)[:, None, :]
    a = g - t_gt
    b = p - t_pr
    s_gt = np.sqrt(np.einsum("npk,npk->n", a, a)) + _EPS_NORM
    s_pr = np.sqrt(np.einsum("npk,npk->n", b, b)) + _EPS_NORM
    # scipy.linalg.orthogonal_procrustes(a / s_gt, b / s_pr): svd(A^T B) -> R = U V^T,
    # scale = sum(W). Scaling the 3x3 product instead of the point sets saves two big copies.
    m = np.matmul(a.transpose(0, 2, 1), b) / (s_gt * s_pr)[:, None, None]
    u, w, vt = np.linalg.svd(m)
    if allow_reflection:
        rot = u @ vt
        scale = w.sum(axis=1)
    else:
        det = np.sign(np.linalg.det(u @ vt))
        det[det == 0] = 1.0
        u = u.copy()
        u[:, :, 2] *= det[:, None]
        rot = u @ vt
        scale = w[:, 0] + w[:, 1] + det * w[:, 2]
    total = scale * s_gt / s_pr  # aligned = s * s_gt * (b / s_pr) R^T + mean(gt)
    aligned = np.matmul(b, rot.transpose(0, 2, 1) * total[:, None, None])
    aligned += t_gt
    if not return_transform:
        return aligned
    transform = {"rotation": rot, "scale": total, "pred_center": t_pr[:, 0],
                 "gt_center": t_gt[:, 0]}
    return aligned, transform


# --------------------------------------------------------------------------------------------
# distances, PCK, AUC


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
        pck: (T,) PCK values from [`pck_curve`][handmesh_tutorial.metrics.pck_curve].
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


def nearest_distances(src, dst) -> np.ndarray:
    """Exact distance from every ``src`` point to its nearest ``dst`` point, per sample.

    A straightforward per-sample ``scipy.spatial.cKDTree`` query (the same quantity the official
    code gets from Open3D). [`f_score`][handmesh_tutorial.metrics.f_score] does not need the
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


def _sq_norm(x: np.ndarray) -> np.ndarray:
    """(..., 3) -> (...) squared lengths, (x^2 + y^2) + z^2 like np.sum(np.square(x), -1)."""
    out = np.square(x[..., 0])
    out += np.square(x[..., 1])
    out += np.square(x[..., 2])
    return out


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
        thresholds: distance thresholds in metres, a float or a sequence of T floats.

    Returns:
        dict with ``f``, ``precision``, ``recall``: (N,T) float64 arrays (T = 1 for a float).
    """
    p, g = _pair(pred, gt, "pred", "gt", same_points=False)
    ths = np.atleast_1d(np.asarray(thresholds, dtype=np.float64))
    if ths.ndim != 1 or np.any(ths <= 0):
        raise ValueError(f"thresholds must be positive distances in metres, got {thresholds!r}")
    g2p, p2g, g_norm, p_norm = _min_sq_dist_f32(g, p)
    recall = _fraction_within(g2p, g_norm, g, p, ths)
    precision = _fraction_within(p2g, p_norm, p, g, ths)
    denom = precision + recall
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(denom > 0, 2.0 * precision * recall / np.where(denom > 0, denom, 1.0), 0.0)
    return {"f": f, "precision": precision, "recall": recall}


# --------------------------------------------------------------------------------------------
# the FreiHAND evaluation


def per_sample_scores(*, pred_joints, gt_joints, pred_verts=None, gt_verts=None,
                      allow_reflection: bool = True, fscore_thresholds=FSCORE_THRESHOLDS,
                      root_index: int = ROOT_INDEX) -> dict:
    """Per-sample errors behind [`freihand_scores`][handmesh_tutorial.metrics.freihand_scores] (for
    tables stratified by VR, plots...).

    Args:
        pred_joints: (N,21,3) predicted keypoints, metres (FreiHAND order).
        gt_joints: (N,21,3) ground-truth keypoints, metres.
        pred_verts: (N,V,3) predicted vertices, metres, or ``None`` (joints only).
        gt_verts: (N,V,3) ground-truth vertices (same V, same topology), or ``None``.
        allow_reflection: Procrustes may mirror (official); ``False`` = proper rotations only.
        fscore_thresholds: F-score distances in metres.
        root_index: keypoint subtracted for root-relative errors (9 = middle MCP).

    Returns:
        dict of float64 arrays, distances in metres:
        ``joint_err`` (N,21) raw, ``joint_err_rr`` (N,21) root-relative, ``joint_err_pa``
        (N,21) after Procrustes; with vertices also ``vert_err`` (N,V), ``vert_err_pa`` (N,V),
        ``fscore`` (N,T) on aligned vertices and ``fscore_thresholds`` (T,).
    """
    pj, gj = _pair(pred_joints, gt_joints, "pred_joints", "gt_joints")
    out = {
        "joint_err": point_errors(pj, gj),
        "joint_err_rr": point_errors(pj - pj[:, root_index:root_index + 1],
                                     gj - gj[:, root_index:root_index + 1]),
        "joint_err_pa": point_errors(procrustes_align(pj, gj, allow_reflection), gj),
    }
    if (pred_verts is None) != (gt_verts is None):
        raise ValueError("give both pred_verts and gt_verts, or neither")
    if pred_verts is not None:
        pv, gv = _pair(pred_verts, gt_verts, "pred_verts", "gt_verts")
        if pv.shape[0] != pj.shape[0]:
            raise ValueError(f"pred_verts has {pv.shape[0]} samples, pred_joints {pj.shape[0]}")
        # vertices get their own Procrustes, as in the official eval (same topology case)
        pv_al = procrustes_align(pv, gv, allow_reflection)
        ths = np.atleast_1d(np.asarray(fscore_thresholds, dtype=np.float64))
        out["vert_err"] = point_errors(pv, gv)
        out["vert_err_pa"] = point_errors(pv_al, gv)
        out["fscore"] = f_score(pv_al, gv, ths)["f"]
        out["fscore_thresholds"] = ths
    return out


def freihand_scores(*, pred_joints, gt_joints, pred_verts, gt_verts,
                    allow_reflection: bool = True, unaligned_fscore: bool = False) -> dict:
    """The official FreiHAND evaluation, batched: errors in mm, AUCs and F-scores.

    Equals ``eval.py`` of ``lmb-freiburg/freihand`` to 1e-6 (same predictions and ground truth
    as its ``pred.json`` and ``evaluation_xyz.json``/``evaluation_verts.json``), with
    ``allow_reflection=True``.

    Args:
        pred_joints: (N,21,3) predicted keypoints, metres, numpy or torch.
        gt_joints: (N,21,3) ground-truth keypoints, metres.
        pred_verts: (N,V,3) predicted mesh vertices, metres (V = 778 for MANO).
        gt_verts: (N,V,3) ground-truth vertices, same topology.
        allow_reflection: official Procrustes (may mirror); ``False`` = proper rotations only.
        unaligned_fscore: also compute the official unaligned F-scores (doubles the F-score time).

    Returns:
        dict of floats: ``mpjpe``, ``mpvpe``, ``pa_mpjpe``, ``pa_mpvpe`` (mm); ``f_at_5mm``,
        ``f_at_15mm`` (aligned vertices); ``auc_joints``, ``auc_verts`` (aligned, 0-50 mm, 100
        thresholds); ``auc_joints_unaligned``, ``auc_verts_unaligned`` (raw, 0-50 mm);
        ``auc_joints_20mm``, ``auc_verts_20mm`` (aligned, 0-20 mm, 20 thresholds, as the paper's
        Table 2); ``num_samples``; with ``unaligned_fscore`` also ``f_at_5mm_unaligned``,
        ``f_at_15mm_unaligned``.
    """
    ps = per_sample_scores(pred_joints=pred_joints, gt_joints=gt_joints, pred_verts=pred_verts,
                           gt_verts=gt_verts, allow_reflection=allow_reflection)
    scores = scores_from_errors(ps)
    if unaligned_fscore:
        fu = f_score(pred_verts, gt_verts, FSCORE_THRESHOLDS)["f"]
        scores["f_at_5mm_unaligned"] = float(fu[:, 0].mean())
        scores["f_at_15mm_unaligned"] = float(fu[:, 1].mean())
    return scores


def scores_from_errors(ps: dict) -> dict:
    """The scores of [`freihand_scores`][handmesh_tutorial.metrics.freihand_scores] from already
    computed per-sample errors.

    Args:
        ps: [`per_sample_scores`][handmesh_tutorial.metrics.per_sample_scores] output with vertices
            (the F-scores at the default thresholds, 5 and 15 mm).

    Returns:
        The dict of [`freihand_scores`][handmesh_tutorial.metrics.freihand_scores] without the
        unaligned F-scores.
    """
    je, jpa, ve, vpa = ps["joint_err"], ps["joint_err_pa"], ps["vert_err"], ps["vert_err_pa"]
    ft, pt = FREIHAND_THRESHOLDS, PAPER_THRESHOLDS
    s_je, s_jpa, s_ve, s_vpa = (np.sort(e, axis=None) for e in (je, jpa, ve, vpa))  # sort once
    scores = {
        "mpjpe": 1000.0 * float(je.mean()),
        "mpvpe": 1000.0 * float(ve.mean()),
        "pa_mpjpe": 1000.0 * float(jpa.mean()),
        "pa_mpvpe": 1000.0 * float(vpa.mean()),
        "f_at_5mm": float(ps["fscore"][:, 0].mean()),
        "f_at_15mm": float(ps["fscore"][:, 1].mean()),
        "auc_joints": auc(_pck_sorted(s_jpa, ft), ft),
        "auc_verts": auc(_pck_sorted(s_vpa, ft), ft),
        "auc_joints_unaligned": auc(_pck_sorted(s_je, ft), ft),
        "auc_verts_unaligned": auc(_pck_sorted(s_ve, ft), ft),
        "auc_joints_20mm": auc(_pck_sorted(s_jpa, pt), pt),
        "auc_verts_20mm": auc(_pck_sorted(s_vpa, pt), pt),
        "num_samples": int(je.shape[0]),
    }
    return scores


# --------------------------------------------------------------------------------------------
# visibility-ratio stratification


def scores_by_vr_bin(per_sample: dict, vr, bins=VR_BINS,
                     thresholds=PAPER_THRESHOLDS) -> list[dict]:
    """A table of scores per visibility-ratio bin (the paper's Table 2 layout).

    Args:
        per_sample: output of [`per_sample_scores`][handmesh_tutorial.metrics.per_sample_scores] for
            N samples.
        vr: (N,) visibility ratio of each sample's target hand.
        bins: the VR bins; see [`vr_bin_index`][handmesh_tutorial.metrics.vr_bin_index].
        thresholds: PCK thresholds (metres) of the AUC; the paper's 0-20 mm, 20 values.

    Returns:
        One dict per bin with ``bin`` (label), ``lo``, ``hi``, ``count``, ``mpjpe``, ``rr_mpjpe``
        (root-relative), ``pa_mpjpe`` (mm), ``auc`` (aligned joints, in [0,1]) and, when vertices
        were scored, ``pa_mpvpe`` (mm), ``f_at_5mm``, ``f_at_15mm``; the
        [`SURFACE_KEYS`][handmesh_tutorial.metrics.SURFACE_KEYS] averaged when ``per_sample`` holds
        them. Empty bins have ``count`` 0 and NaN scores.
    """
    v = np.asarray(vr, dtype=np.float64).ravel()
    n = per_sample["joint_err"].shape[0]
    if v.shape[0] != n:
        raise ValueError(f"vr has {v.shape[0]} values but per_sample has {n} samples")
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
([`handmesh_tutorial.surface.roughness_deg`][handmesh_tutorial.surface.roughness_deg],
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
    [`scores_by_vr_bin`][handmesh_tutorial.metrics.scores_by_vr_bin]).

    Args:
        per_sample: output of [`per_sample_scores`][handmesh_tutorial.metrics.per_sample_scores] for
            N samples (optionally with the [`SURFACE_KEYS`][handmesh_tutorial.metrics.SURFACE_KEYS]
            added, ``(N,)`` each).
        labels: ``(N,)`` group label of each sample (``None`` = in no group).
        order: the groups to report, in order (default: the distinct labels, sorted); a group
            with no sample gets ``count`` 0 and NaN scores.
        thresholds: PCK thresholds (metres) of the AUC.

    Returns:
        One dict per group with ``bin`` (the label) and the scores of
        [`scores_by_vr_bin`][handmesh_tutorial.metrics.scores_by_vr_bin].
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
        rows: the model's rows ([`scores_by_vr_bin`][handmesh_tutorial.metrics.scores_by_vr_bin],
            [`scores_by_group`][handmesh_tutorial.metrics.scores_by_group], or an overall row with
            ``bin`` ``"all"``).
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
    """Format [`scores_by_vr_bin`][handmesh_tutorial.metrics.scores_by_vr_bin] rows (or any list of
    such dicts) as a markdown table.

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
