"""The FreiHAND evaluation: per-sample errors and the official summary scores.

Inputs (N, 21, 3) joints and (N, V, 3) vertices in metres; reports in millimetres.

Taught in notebook 09 ("Evaluation").
"""

from __future__ import annotations

import numpy as np

from ._common import _pair
from .fscore import FSCORE_THRESHOLDS, f_score
from .pck import FREIHAND_THRESHOLDS, PAPER_THRESHOLDS, _pck_sorted, auc, point_errors
from .procrustes import procrustes_align

__all__ = ["ROOT_INDEX", "freihand_scores", "per_sample_scores"]


ROOT_INDEX = 9
"""Root keypoint (middle-finger MCP, FreiHAND order) for root-relative errors."""


def _check_some_samples(x, name: str) -> None:
    """A ValueError when ``x`` (N, ...) has N = 0: the means of zero samples are NaN."""
    n = len(x) if hasattr(x, "__len__") else None
    if n == 0:
        raise ValueError(f"{name} has 0 samples; the scores are means over samples (N >= 1)")


def per_sample_scores(*, pred_joints, gt_joints, pred_verts=None, gt_verts=None,
                      allow_reflection: bool = True, fscore_thresholds=FSCORE_THRESHOLDS,
                      root_index: int = ROOT_INDEX) -> dict:
    """Per-sample errors behind
    [`freihand_scores`][handmesh_tutorial.metrics.scores.freihand_scores] (for tables stratified
    by VR, plots...).

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


def freihand_scores(*, pred_joints, gt_joints, pred_verts=None, gt_verts=None,
                    allow_reflection: bool = True, unaligned_fscore: bool = False) -> dict:
    """The official FreiHAND evaluation, batched: errors in mm, AUCs and F-scores.

    Equals ``eval.py`` of ``lmb-freiburg/freihand`` to 1e-6 (same predictions and ground truth
    as its ``pred.json`` and ``evaluation_xyz.json``/``evaluation_verts.json``), with
    ``allow_reflection=True``.

    Args:
        pred_joints: (N,21,3) predicted keypoints, metres, numpy or torch.
        gt_joints: (N,21,3) ground-truth keypoints, metres.
        pred_verts: (N,V,3) predicted mesh vertices, metres (V = 778 for MANO), or ``None``
            (joints-only scoring, with ``gt_verts=None`` too).
        gt_verts: (N,V,3) ground-truth vertices, same topology, or ``None``.
        allow_reflection: official Procrustes (may mirror); ``False`` = proper rotations only.
        unaligned_fscore: also compute the official unaligned F-scores (doubles the F-score time;
            needs vertices).

    Returns:
        dict of floats: ``mpjpe``, ``mpvpe``, ``pa_mpjpe``, ``pa_mpvpe`` (mm); ``f_at_5mm``,
        ``f_at_15mm`` (aligned vertices); ``auc_joints``, ``auc_verts`` (aligned, 0-50 mm, 100
        thresholds); ``auc_joints_unaligned``, ``auc_verts_unaligned`` (raw, 0-50 mm);
        ``auc_joints_20mm``, ``auc_verts_20mm`` (aligned, 0-20 mm, 20 thresholds, as the paper's
        Table 2); ``num_samples``; with ``unaligned_fscore`` also ``f_at_5mm_unaligned``,
        ``f_at_15mm_unaligned``. Without vertices only the joint keys (``mpjpe``, ``pa_mpjpe``,
        ``auc_joints``, ``auc_joints_unaligned``, ``auc_joints_20mm``, ``num_samples``), equal to
        those of a call with vertices; the vertex keys are **absent** (not NaN).

    Raises:
        ValueError: only one of ``pred_verts`` / ``gt_verts`` given, ``unaligned_fscore``
            without vertices, zero samples (every mean would be NaN), or bad shapes (the
            message names the argument).

    Examples:
        >>> import numpy as np
        >>> from handmesh_tutorial.metrics import freihand_scores
        >>> gt = np.random.default_rng(0).normal(scale=0.03, size=(1, 21, 3))  # metres
        >>> s = freihand_scores(pred_joints=gt + [0.01, 0, 0], gt_joints=gt)  # 1 cm off in x
        >>> round(s["mpjpe"], 3), round(s["pa_mpjpe"], 3)  # mm; alignment removes the shift
        (10.0, 0.0)
    """
    if unaligned_fscore and pred_verts is None:
        raise ValueError("unaligned_fscore needs vertices: give pred_verts and gt_verts")
    _check_some_samples(pred_joints, "pred_joints")
    ps = per_sample_scores(pred_joints=pred_joints, gt_joints=gt_joints, pred_verts=pred_verts,
                           gt_verts=gt_verts, allow_reflection=allow_reflection)
    scores = scores_from_errors(ps)
    if unaligned_fscore:
        fu = f_score(pred_verts, gt_verts, FSCORE_THRESHOLDS)["f"]
        scores["f_at_5mm_unaligned"] = float(fu[:, 0].mean())
        scores["f_at_15mm_unaligned"] = float(fu[:, 1].mean())
    return scores


def scores_from_errors(ps: dict) -> dict:
    """The scores of [`freihand_scores`][handmesh_tutorial.metrics.scores.freihand_scores] from
    already computed per-sample errors.

    Args:
        ps: [`per_sample_scores`][handmesh_tutorial.metrics.scores.per_sample_scores] output,
            with vertices (the F-scores at the default thresholds, 5 and 15 mm) or without.

    Returns:
        The dict of [`freihand_scores`][handmesh_tutorial.metrics.scores.freihand_scores] without
        the unaligned F-scores; without vertex errors in ``ps``, only its joint keys.

    Raises:
        ValueError: ``ps`` holds zero samples.
    """
    je, jpa = ps["joint_err"], ps["joint_err_pa"]
    _check_some_samples(je, "ps['joint_err']")
    ft, pt = FREIHAND_THRESHOLDS, PAPER_THRESHOLDS
    s_je, s_jpa = (np.sort(e, axis=None) for e in (je, jpa))  # sort once
    scores = {
        "mpjpe": 1000.0 * float(je.mean()),
        "pa_mpjpe": 1000.0 * float(jpa.mean()),
        "auc_joints": auc(_pck_sorted(s_jpa, ft), ft),
        "auc_joints_unaligned": auc(_pck_sorted(s_je, ft), ft),
        "auc_joints_20mm": auc(_pck_sorted(s_jpa, pt), pt),
        "num_samples": int(je.shape[0]),
    }
    if "vert_err" not in ps:
        return scores
    ve, vpa = ps["vert_err"], ps["vert_err_pa"]
    s_ve, s_vpa = (np.sort(e, axis=None) for e in (ve, vpa))
    scores.update({
        "mpvpe": 1000.0 * float(ve.mean()),
        "pa_mpvpe": 1000.0 * float(vpa.mean()),
        "f_at_5mm": float(ps["fscore"][:, 0].mean()),
        "f_at_15mm": float(ps["fscore"][:, 1].mean()),
        "auc_verts": auc(_pck_sorted(s_vpa, ft), ft),
        "auc_verts_unaligned": auc(_pck_sorted(s_ve, ft), ft),
        "auc_verts_20mm": auc(_pck_sorted(s_vpa, pt), pt),
    })
    # the key order of a call with vertices, as before
    order = ("mpjpe", "mpvpe", "pa_mpjpe", "pa_mpvpe", "f_at_5mm", "f_at_15mm", "auc_joints",
             "auc_verts", "auc_joints_unaligned", "auc_verts_unaligned", "auc_joints_20mm",
             "auc_verts_20mm", "num_samples")
    return {k: scores[k] for k in order}
