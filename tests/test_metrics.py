"""Tests of handmesh_tutorial.metrics against hand-built cases and an independent reference.

The reference below is a deliberately plain, per-sample re-statement of the official FreiHAND
evaluation (lmb-freiburg/freihand eval.py + utils/eval_util.py): loops, scipy's
orthogonal_procrustes, cKDTree nearest neighbours, per-keypoint PCK/AUC averaged over keypoints.
"""

import math

import numpy as np
import pytest
import torch
from scipy.linalg import orthogonal_procrustes
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from handmesh_tutorial import metrics as M

torch.set_num_threads(1)

TOL = 1e-6


# ----------------------------------------------------------------------------- reference


def ref_align(gt, pred):
    t1, t2 = gt.mean(0), pred.mean(0)
    a, b = gt - t1, pred - t2
    s1 = np.linalg.norm(a) + 1e-8
    s2 = np.linalg.norm(b) + 1e-8
    a, b = a / s1, b / s2
    r, s = orthogonal_procrustes(a, b)
    return (b @ r.T) * s * s1 + t1


def ref_fscore(gt, pred, th):
    d_gt = cKDTree(pred).query(gt)[0]  # each gt point to the prediction
    d_pr = cKDTree(gt).query(pred)[0]
    recall = float(np.sum(d_pr < th)) / len(d_pr)  # official naming
    precision = float(np.sum(d_gt < th)) / len(d_gt)
    return 2 * recall * precision / (recall + precision) if recall + precision > 0 else 0.0


def ref_measures(per_kp_errors, lo, hi, steps):
    """EvalUtil.get_measures: per-keypoint mean error, PCK (<=), trapz AUC / trapz(ones)."""
    thr = np.linspace(lo, hi, steps)
    norm = np.trapezoid(np.ones_like(thr), thr)
    means, aucs = [], []
    for data in per_kp_errors:  # one list of errors per keypoint
        data = np.array(data)
        means.append(np.mean(data))
        pck = np.array([np.mean((data <= t).astype(float)) for t in thr])
        aucs.append(np.trapezoid(pck, thr) / norm)
    return np.mean(means), np.mean(aucs)


def ref_eval(pj, gj, pv, gv):
    nj, nv = gj.shape[1], gv.shape[1]
    kp, kp_al = [[] for _ in range(nj)], [[] for _ in range(nj)]
    vx, vx_al = [[] for _ in range(nv)], [[] for _ in range(nv)]
    f5, f15 = [], []
    for i in range(len(gj)):
        xyz, verts, xyz_p, verts_p = gj[i], gv[i], pj[i], pv[i]
        xyz_al = ref_align(xyz, xyz_p)
        verts_al = ref_align(verts, verts_p)
        for store, a, b in ((kp, xyz, xyz_p), (kp_al, xyz, xyz_al), (vx, verts, verts_p),
                            (vx_al, verts, verts_al)):
            d = np.sqrt(np.sum(np.square(a - b), axis=1))
            for k in range(len(d)):
                store[k].append(d[k])
        f5.append(ref_fscore(verts, verts_al, 0.005))
        f15.append(ref_fscore(verts, verts_al, 0.015))
    out = {}
    out["mpjpe"], out["auc_joints_unaligned"] = ref_measures(kp, 0.0, 0.05, 100)
    out["pa_mpjpe"], out["auc_joints"] = ref_measures(kp_al, 0.0, 0.05, 100)
    out["mpvpe"], out["auc_verts_unaligned"] = ref_measures(vx, 0.0, 0.05, 100)
    out["pa_mpvpe"], out["auc_verts"] = ref_measures(vx_al, 0.0, 0.05, 100)
    _, out["auc_joints_20mm"] = ref_measures(kp_al, 0.0, 0.02, 20)
    _, out["auc_verts_20mm"] = ref_measures(vx_al, 0.0, 0.02, 20)
    for k in ("mpjpe", "pa_mpjpe", "mpvpe", "pa_mpvpe"):
        out[k] *= 1000.0
    out["f_at_5mm"], out["f_at_15mm"] = float(np.mean(f5)), float(np.mean(f15))
    return out


# ----------------------------------------------------------------------------- fixtures


def hand_like(rng, n, v=120, nj=21):
    """Random point sets with hand-like extent (~10 cm) placed ~0.5 m in front of a camera."""
    base = rng.normal(size=(n, v, 3)) * np.array([0.04, 0.03, 0.015])
    base += np.array([0.0, 0.0, 0.5]) + rng.normal(size=(n, 1, 3)) * 0.05
    joints = base[:, :nj] + rng.normal(size=(n, nj, 3)) * 0.002
    return joints, base


def random_similarity(rng, n):
    rot = Rotation.random(n, random_state=rng).as_matrix()
    scale = rng.uniform(0.5, 2.0, size=n)
    trans = rng.normal(size=(n, 3)) * 0.1
    return rot, scale, trans


def apply(x, rot, scale, trans):
    return np.einsum("npj,nij->npi", x, rot) * scale[:, None, None] + trans[:, None, :]


# ----------------------------------------------------------------------------- reference match


@pytest.mark.parametrize("noise", [0.004, 0.012])
def test_matches_independent_reference(noise):
    rng = np.random.default_rng(7)
    gj, gv = hand_like(rng, 12)
    pj = gj + rng.normal(size=gj.shape) * noise
    pv = gv + rng.normal(size=gv.shape) * noise
    # and a similarity transform on top, which Procrustes must remove
    rot, scale, trans = random_similarity(rng, 12)
    pj, pv = apply(pj, rot, scale, trans), apply(pv, rot, scale, trans)
    ours = M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=gv,
                             unaligned_fscore=True)
    ref = ref_eval(pj, gj, pv, gv)
    for key, val in ref.items():
        assert ours[key] == pytest.approx(val, abs=TOL), key
    for key, th in (("f_at_5mm_unaligned", 0.005), ("f_at_15mm_unaligned", 0.015)):
        expect = np.mean([ref_fscore(gv[i], pv[i], th) for i in range(len(gv))])
        assert ours[key] == pytest.approx(expect, abs=TOL)
    # the case must be non-trivial: F-scores strictly between 0 and 1
    assert 0.0 < ours["f_at_5mm"] < 1.0
    assert ours["num_samples"] == 12


def test_joints_only_scores_equal_the_joint_scores_with_vertices():
    """Without vertices: the joint keys, equal to those of a call with vertices, and no vertex
    keys at all (documented); half-given vertices and unaligned F-scores are refused."""
    rng = np.random.default_rng(5)
    gj, gv = hand_like(rng, 6)
    pj = apply(gj + rng.normal(size=gj.shape) * 0.006, *random_similarity(rng, 6))
    pv = gv + rng.normal(size=gv.shape) * 0.006
    full = M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=gv)
    only = M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=None, gt_verts=None)
    assert only == M.freihand_scores(pred_joints=pj, gt_joints=gj)  # vertices default to None
    joint_keys = {"mpjpe", "pa_mpjpe", "auc_joints", "auc_joints_unaligned", "auc_joints_20mm",
                  "num_samples"}
    assert set(only) == joint_keys
    for key in joint_keys:
        assert only[key] == full[key], key
    ref = ref_eval(pj, gj, pv, gv)  # the independent reference, joint part
    for key in joint_keys - {"num_samples"}:
        assert only[key] == pytest.approx(ref[key], abs=TOL), key
    assert only["pa_mpjpe"] > 1.0
    with pytest.raises(ValueError, match="both pred_verts and gt_verts"):
        M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=None)
    with pytest.raises(ValueError, match="unaligned_fscore needs vertices"):
        M.freihand_scores(pred_joints=pj, gt_joints=gj, unaligned_fscore=True)


def test_torch_float32_inputs_accepted():
    rng = np.random.default_rng(3)
    gj, gv = hand_like(rng, 4)
    pj, pv = gj + 0.003, gv + rng.normal(size=gv.shape) * 0.003
    a = M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=gv)
    b = M.freihand_scores(pred_joints=torch.tensor(pj), gt_joints=torch.tensor(gj),
                          pred_verts=torch.tensor(pv), gt_verts=torch.tensor(gv))
    assert a == b


def test_procrustes_matches_scipy_per_sample():
    rng = np.random.default_rng(11)
    gt = rng.normal(size=(20, 30, 3))
    pred = rng.normal(size=(20, 30, 3))
    ours = M.procrustes_align(pred, gt)
    for i in range(20):
        np.testing.assert_allclose(ours[i], ref_align(gt[i], pred[i]), atol=1e-12)


def test_fscore_matches_kdtree_on_many_clouds():
    rng = np.random.default_rng(5)
    gt = rng.normal(size=(30, 200, 3)) * 0.03 + np.array([0.1, -0.05, 0.6])
    pred = gt[:, :150] + rng.normal(size=(30, 150, 3)) * 0.006  # different point counts
    got = M.f_score(pred, gt, (0.002, 0.005, 0.015))["f"]
    for i in range(30):
        for k, th in enumerate((0.002, 0.005, 0.015)):
            assert got[i, k] == pytest.approx(ref_fscore(gt[i], pred[i], th), abs=1e-12)


def test_nearest_distances_match_brute_force():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(3, 50, 3)), rng.normal(size=(3, 40, 3))
    brute = np.sqrt(((a[:, :, None] - b[:, None]) ** 2).sum(-1)).min(-1)
    np.testing.assert_allclose(M.nearest_distances(a, b), brute, atol=1e-15)


# ----------------------------------------------------------------------------- hand-built cases


def test_identical_prediction_is_perfect():
    rng = np.random.default_rng(0)
    gj, gv = hand_like(rng, 3)
    s = M.freihand_scores(pred_joints=gj, gt_joints=gj, pred_verts=gv, gt_verts=gv)
    assert s["mpjpe"] == 0.0 and s["mpvpe"] == 0.0
    # the official +1e-8 on both norms shrinks the aligned set by ~2e-8/|A|: a few nm, not 0
    for k in ("pa_mpjpe", "pa_mpvpe"):
        assert 0.0 < s[k] < 1e-4
    for k in ("f_at_5mm", "f_at_15mm", "auc_joints_unaligned", "auc_verts_unaligned"):
        assert s[k] == 1.0
    # ... and those nm fail the first PCK threshold (error <= 0): the aligned AUC of a perfect
    # prediction is 1 - 0.5/99 over 100 thresholds (1 - 0.5/19 over the paper's 20)
    for k in ("auc_joints", "auc_verts"):
        assert s[k] == pytest.approx(1 - 0.5 / 99, abs=1e-12)
    assert s["auc_joints_20mm"] == pytest.approx(1 - 0.5 / 19, abs=1e-12)


def test_translated_prediction_has_known_raw_error_and_zero_pa_error():
    rng = np.random.default_rng(1)
    gj, gv = hand_like(rng, 3)
    shift = np.array([0.003, -0.004, 0.0])  # 5 mm
    s = M.freihand_scores(pred_joints=gj + shift, gt_joints=gj, pred_verts=gv + shift,
                          gt_verts=gv)
    assert s["mpjpe"] == pytest.approx(5.0, abs=1e-9)
    assert s["mpvpe"] == pytest.approx(5.0, abs=1e-9)
    assert s["pa_mpjpe"] < 1e-4 and s["pa_mpvpe"] < 1e-4  # mm (official eps: nm)
    # raw errors are all exactly ~5 mm: the raw 0-50 mm AUC is the area right of 5 mm
    assert s["auc_joints_unaligned"] == pytest.approx(0.9, abs=0.011)


def test_rotated_scaled_prediction_is_removed_by_procrustes():
    rng = np.random.default_rng(4)
    gj, gv = hand_like(rng, 5)
    rot, scale, trans = random_similarity(rng, 5)
    pj, pv = apply(gj, rot, scale, trans), apply(gv, rot, scale, trans)
    for refl in (True, False):
        s = M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=gv,
                              allow_reflection=refl)
        assert s["pa_mpjpe"] < 1e-4 and s["pa_mpvpe"] < 1e-4  # mm (official eps: nm)
        assert s["f_at_5mm"] == 1.0
    raw = np.linalg.norm(pj - gj, axis=-1).mean() * 1000
    assert s["mpjpe"] == pytest.approx(raw, rel=1e-12)
    _, tf = M.procrustes_align(pv, gv, return_transform=True)
    # recovered transform = inverse of the applied one
    np.testing.assert_allclose(tf["scale"], 1.0 / scale, rtol=1e-6)
    np.testing.assert_allclose(tf["rotation"], np.linalg.inv(rot), atol=1e-6)


def test_mirrored_prediction_reflection_vs_proper_rotation():
    rng = np.random.default_rng(6)
    gj, gv = hand_like(rng, 4)
    mirror = np.array([-1.0, 1.0, 1.0])  # a left hand for a right hand
    pj, pv = gj * mirror, gv * mirror
    with_refl = M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=gv)
    proper = M.freihand_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=gv,
                               allow_reflection=False)
    assert with_refl["pa_mpjpe"] < 1e-4 and with_refl["pa_mpvpe"] < 1e-4
    assert proper["pa_mpjpe"] > 1.0 and proper["pa_mpvpe"] > 1.0  # millimetres
    _, tf = M.procrustes_align(pv, gv, return_transform=True)
    assert np.allclose(np.linalg.det(tf["rotation"]), -1.0)
    _, tf = M.procrustes_align(pv, gv, allow_reflection=False, return_transform=True)
    assert np.allclose(np.linalg.det(tf["rotation"]), 1.0)


def test_proper_rotation_variant_is_optimal_among_rotations():
    # no random proper rotation may beat the allow_reflection=False solution
    rng = np.random.default_rng(9)
    gt = rng.normal(size=(1, 25, 3))
    pred = rng.normal(size=(1, 25, 3))
    al = M.procrustes_align(pred, gt, allow_reflection=False)
    best = np.sum((al - gt) ** 2)
    a = gt[0] - gt[0].mean(0)
    b = pred[0] - pred[0].mean(0)
    for r in Rotation.random(300, random_state=1).as_matrix():
        br = b @ r.T
        c = np.sum(a * br) / np.sum(br * br)  # best scale for this rotation
        assert np.sum((c * br - a) ** 2) >= best - 1e-12


def test_zero_prediction_is_aligned_to_the_gt_centroid():
    # the official README's "zero predictor": aligned prediction collapses to the centroid
    rng = np.random.default_rng(8)
    gj, gv = hand_like(rng, 3)
    zj, zv = np.zeros_like(gj), np.zeros_like(gv)
    s = M.freihand_scores(pred_joints=zj, gt_joints=gj, pred_verts=zv, gt_verts=gv)
    expect = np.linalg.norm(gj - gj.mean(1, keepdims=True), axis=-1).mean() * 1000
    assert s["pa_mpjpe"] == pytest.approx(expect, rel=1e-9)
    assert s["mpjpe"] == pytest.approx(np.linalg.norm(gj, axis=-1).mean() * 1000, rel=1e-12)
    ref = ref_eval(zj, gj, zv, gv)
    for key in ("f_at_5mm", "f_at_15mm", "pa_mpvpe"):
        assert s[key] == pytest.approx(ref[key], abs=TOL)


def test_threshold_edges_pck_inclusive_fscore_strict():
    gt = np.zeros((1, 1, 3))
    pred = np.array([[[0.005, 0.0, 0.0]]])  # exactly 5 mm away
    assert M.point_errors(pred, gt)[0, 0] == 0.005
    assert M.pck_curve(M.point_errors(pred, gt), [0.005])[0] == 1.0  # <= counts it
    assert M.f_score(pred, gt, 0.005)["f"][0, 0] == 0.0  # < does not
    assert M.f_score(pred, gt, np.nextafter(0.005, 1))["f"][0, 0] == 1.0


def test_fscore_exact_ties_at_threshold_in_a_large_cloud():
    # many points at exactly 5 mm from their only neighbour: all land in the float32 "unsure"
    # band and must be decided by the exact float64 re-check
    rng = np.random.default_rng(12)
    gt = rng.uniform(-0.05, 0.05, size=(2, 300, 3)).round(3)  # 1 mm grid, >= 1 mm apart mostly
    gt = np.unique(gt[0], axis=0)[None].repeat(2, 0)
    pred = gt + np.array([0.0, 0.0, 0.005])
    got = M.f_score(pred, gt, (0.005, 0.0050001))
    for i in range(2):
        assert got["f"][i, 0] == pytest.approx(ref_fscore(gt[i], pred[i], 0.005), abs=1e-15)
        assert got["f"][i, 1] == pytest.approx(ref_fscore(gt[i], pred[i], 0.0050001), abs=1e-15)


def test_fscore_zero_when_precision_and_recall_are_zero():
    gt = np.zeros((2, 4, 3))
    pred = np.ones((2, 4, 3))
    out = M.f_score(pred, gt, 0.015)
    assert np.all(out["f"] == 0.0) and not np.any(np.isnan(out["f"]))


def test_fscore_precision_and_recall_are_directional():
    gt = np.array([[[0.0, 0, 0], [1.0, 0, 0]]])
    pred = np.array([[[0.0, 0, 0], [0.001, 0, 0], [0.002, 0, 0], [0.003, 0, 0]]])
    out = M.f_score(pred, gt, 0.01)
    assert out["precision"][0, 0] == 1.0  # every predicted point is near a gt point
    assert out["recall"][0, 0] == 0.5  # the gt point at x=1 is missed
    assert out["f"][0, 0] == pytest.approx(2 * 0.5 / 1.5)


def test_pck_and_auc_known_values():
    thr = np.array([0.0, 0.01, 0.02])
    np.testing.assert_allclose(M.pck_curve([0.0, 0.01, 0.015, 0.03], thr), [0.25, 0.5, 0.75])
    # trapezoid over [0, 0.02] of (0.25, 0.5, 0.75) = 0.01, normalised by 0.02
    assert M.auc([0.25, 0.5, 0.75], thr) == pytest.approx(0.5)
    assert M.auc(np.ones(100)) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="thresholds"):
        M.auc([1.0, 1.0], [0.0, 0.01, 0.02])


def test_bad_inputs_name_the_argument():
    g = np.zeros((2, 21, 3))
    with pytest.raises(ValueError, match="pred_joints"):
        M.freihand_scores(pred_joints=np.zeros((2, 20, 3)), gt_joints=g,
                          pred_verts=np.zeros((2, 5, 3)), gt_verts=np.zeros((2, 5, 3)))
    with pytest.raises(ValueError, match="pred_verts.*NaN"):
        M.freihand_scores(pred_joints=g, gt_joints=g, pred_verts=np.full((2, 5, 3), np.nan),
                          gt_verts=np.zeros((2, 5, 3)))
    with pytest.raises(ValueError, match="sample counts"):
        M.procrustes_align(np.zeros((3, 4, 3)), np.zeros((2, 4, 3)))
    with pytest.raises(ValueError, match="dimensions"):
        M.procrustes_align(np.zeros((4, 3)), np.zeros((4, 3)))


# ----------------------------------------------------------------------------- VR bins


@pytest.mark.parametrize("vr,expected", [(0.4, 0), (0.6, 1), (0.95, 3), (1.0, 3), (0.39, -1),
                                         (0.5999999, 0), (0.8, 2), (1.0000001, -1),
                                         (float("nan"), -1)])
def test_vr_bin_edges(vr, expected):
    from handmesh_tutorial import visibility

    assert M.vr_bin_index(vr) == expected
    assert visibility.vr_bin(vr) == expected  # one definition of the bins, two entry points
    assert M.VR_BINS is visibility.VR_BINS


def test_vr_bin_index_vectorised():
    np.testing.assert_array_equal(M.vr_bin_index(np.array([0.1, 0.45, 0.7, 0.9, 0.97])),
                                  [-1, 0, 1, 2, 3])


def test_scores_by_vr_bin_groups_samples():
    rng = np.random.default_rng(10)
    gj, gv = hand_like(rng, 6)
    noise = np.array([0.001, 0.001, 0.004, 0.004, 0.008, 0.002])[:, None, None]
    pj = gj + rng.normal(size=gj.shape) * noise
    pv = gv + rng.normal(size=gv.shape) * noise
    vr = np.array([0.45, 0.55, 0.7, 0.65, 0.3, 1.0])  # sample 4 is outside every bin
    ps = M.per_sample_scores(pred_joints=pj, gt_joints=gj, pred_verts=pv, gt_verts=gv)
    rows = M.scores_by_vr_bin(ps, vr)
    assert [r["count"] for r in rows] == [2, 2, 0, 1]
    # each bin equals the full evaluation restricted to its samples
    for row, sel in ((rows[0], [0, 1]), (rows[1], [2, 3]), (rows[3], [5])):
        ref = M.freihand_scores(pred_joints=pj[sel], gt_joints=gj[sel], pred_verts=pv[sel],
                                gt_verts=gv[sel])
        assert row["pa_mpjpe"] == pytest.approx(ref["pa_mpjpe"], abs=1e-9)
        assert row["pa_mpvpe"] == pytest.approx(ref["pa_mpvpe"], abs=1e-9)
        assert row["auc"] == pytest.approx(ref["auc_joints_20mm"], abs=1e-12)
        assert row["f_at_5mm"] == pytest.approx(ref["f_at_5mm"], abs=1e-12)
    assert math.isnan(rows[2]["pa_mpjpe"])
    table = M.format_table(rows)
    lines = table.splitlines()
    assert len(lines) == 6 and lines[0].startswith("| VR | N | AUC 0-20mm")
    assert "[0.95, 1.00] | 1 |" in table and "| - |" in lines[4]
    with pytest.raises(ValueError, match="vr has 5 values"):
        M.scores_by_vr_bin(ps, vr[:5])


def test_viz_pck_curves_and_vr_bars():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from handmesh_tutorial import viz

    errors = np.array([0.001, 0.004, 0.012, 0.03])
    fig, (a, b) = plt.subplots(1, 2)
    viz.plot_pck_curves(a, {"m": errors, "pre": (M.PAPER_THRESHOLDS, np.ones(20))})
    labels = [t.get_text() for t in a.get_legend().get_texts()]
    expect = M.auc(M.pck_curve(errors))
    assert labels == [f"m (AUC {expect:.3f})", "pre (AUC 1.000)"]
    np.testing.assert_allclose(a.lines[0].get_xdata(), M.FREIHAND_THRESHOLDS * 1000)
    rows = [{"bin": "[0.40, 0.60)", "count": 2, "auc": 0.5},
            {"bin": "[0.60, 0.80)", "count": 0, "auc": math.nan}]
    bars = viz.plot_vr_table(b, rows, "auc")
    assert [p.get_height() for p in bars][0] == 0.5 and len(bars) == 2
    plt.close(fig)


def test_bad_thresholds_errors_samples_and_vr_are_refused_with_the_value():
    # issue 43 item 10: each of these gave a number (0, a curve, NaN) or dropped samples silently
    rng = np.random.default_rng(3)
    gj, gv = hand_like(rng, 3)
    for th in (float("nan"), float("inf"), (0.005, float("nan")), ()):
        with pytest.raises(ValueError, match="thresholds must be one or more finite positive"):
            M.f_score(gv, gv, th)
    with pytest.raises(ValueError, match=r"errors must be distances >= 0 .*got min -0.001"):
        M.pck_curve(np.array([0.002, -0.001]))
    for th in ([0.0, np.nan], [0.02, 0.01], [-0.01, 0.0]):
        with pytest.raises(ValueError, match="strictly increasing distances"):
            M.pck_curve(np.array([0.002]), th)
    with pytest.raises(ValueError, match=r"pck values must be fractions in \[0, 1\].*nan"):
        M.auc([0.5, np.nan], [0.0, 0.05])
    with pytest.raises(ValueError, match="pred_joints has 0 samples"):
        M.freihand_scores(pred_joints=gj[:0], gt_joints=gj[:0], pred_verts=gv[:0],
                          gt_verts=gv[:0])
    ps = M.per_sample_scores(pred_joints=gj, gt_joints=gj)
    for bad in (np.nan, 2.0, -1.0):
        with pytest.raises(ValueError, match=rf"vr must be visibility ratios in \[0, 1\], got "
                                             rf"{bad!r} at sample 1"):
            M.scores_by_vr_bin(ps, np.array([0.5, bad, 0.7]))
    # a VR below the first bin is a valid ratio, in no bin (as before)
    assert [r["count"] for r in M.scores_by_vr_bin(ps, [0.1, 0.5, 0.7])] == [1, 1, 0, 0]
