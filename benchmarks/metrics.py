"""Benchmark: batched FreiHAND metrics vs a per-sample loop (the official evaluation's structure).

Prints, measured in the same run on the same data:

1. F@5mm/F@15mm on aligned vertices: ``hmt.metrics.f_score`` (one float32 distance matrix per
   sample + exact float64 re-check near the thresholds) vs a per-sample ``scipy.spatial.cKDTree``
   loop (two trees and two queries per sample, as the official code does with Open3D).
2. The whole evaluation: ``hmt.metrics.freihand_scores`` vs a per-sample loop with
   ``scipy.linalg.orthogonal_procrustes`` + cKDTree + per-keypoint PCK/AUC.

Sizes come from ``hmt.budget().eval_samples`` (``full`` = 3960, FreiHAND's evaluation set);
``--samples N`` overrides. Run: ``python benchmarks/metrics.py [--samples 3960]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from scipy.linalg import orthogonal_procrustes
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

import handmesh_tutorial as hmt
from handmesh_tutorial import metrics as M


def make_data(n: int, v: int = 778, seed: int = 0):
    """Hand-sized point clouds ~0.5 m from the camera and noisy, similarity-moved predictions."""
    rng = np.random.default_rng(seed)
    gv = rng.normal(size=(n, v, 3)) * np.array([0.04, 0.03, 0.015]) + np.array([0, 0, 0.5])
    gj = gv[:, :21] + rng.normal(size=(n, 21, 3)) * 0.002
    rot = Rotation.random(n, random_state=seed).as_matrix()
    scale = rng.uniform(0.8, 1.2, size=n)[:, None, None]
    shift = rng.normal(size=(n, 1, 3)) * 0.02
    pv = np.einsum("npj,nij->npi", gv + rng.normal(size=gv.shape) * 0.006, rot) * scale + shift
    pj = np.einsum("npj,nij->npi", gj + rng.normal(size=gj.shape) * 0.006, rot) * scale + shift
    return pj, gj, pv, gv


def fscore_kdtree_loop(pred, gt, ths=(0.005, 0.015)):
    out = np.empty((len(gt), len(ths)))
    for i in range(len(gt)):
        d_gt = cKDTree(pred[i]).query(gt[i])[0]
        d_pr = cKDTree(gt[i]).query(pred[i])[0]
        for k, th in enumerate(ths):
            r, p = np.mean(d_gt < th), np.mean(d_pr < th)
            out[i, k] = 2 * p * r / (p + r) if p + r > 0 else 0.0
    return out


def _align(gt, pred):
    t1, t2 = gt.mean(0), pred.mean(0)
    a, b = gt - t1, pred - t2
    s1, s2 = np.linalg.norm(a) + 1e-8, np.linalg.norm(b) + 1e-8
    r, s = orthogonal_procrustes(a / s1, b / s2)
    return (b / s2) @ r.T * s * s1 + t1


def evaluation_loop(pj, gj, pv, gv):
    """Per-sample evaluation in the official structure (Procrustes, errors, F-scores, AUC)."""
    thr = M.FREIHAND_THRESHOLDS
    je, jpa, vpa, fs = [], [], [], []
    for i in range(len(gj)):
        pj_al, pv_al = _align(gj[i], pj[i]), _align(gv[i], pv[i])
        je.append(np.linalg.norm(gj[i] - pj[i], axis=1))
        jpa.append(np.linalg.norm(gj[i] - pj_al, axis=1))
        vpa.append(np.linalg.norm(gv[i] - pv_al, axis=1))
        fs.append(fscore_kdtree_loop(pv_al[None], gv[i][None])[0])
    jpa, vpa = np.array(jpa), np.array(vpa)
    auc_j = np.mean([np.trapezoid([np.mean(jpa[:, k] <= t) for t in thr], thr) / 0.05
                     for k in range(jpa.shape[1])])
    return {"mpjpe": 1000 * np.mean(je), "pa_mpjpe": 1000 * jpa.mean(),
            "pa_mpvpe": 1000 * vpa.mean(), "f_at_5mm": np.mean(fs, 0)[0], "auc_joints": auc_j}


def interleaved(fns: dict, repeats: int):
    """Run the functions in turn, ``repeats`` rounds: each sees the same machine load.

    Returns ({name: [seconds per round]}, {name: last output}).
    """
    times = {k: [] for k in fns}
    outs = {}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            outs[name] = fn()
            times[name].append(time.perf_counter() - t0)
    return times, outs


def report(title: str, times: dict, base: str, ours: str) -> None:
    tb, to = np.array(times[base]), np.array(times[ours])
    print(f"{title}: {base} min {tb.min():7.3f} s | {ours} min {to.min():7.3f} s | "
          f"speed-up x{tb.min() / to.min():.2f} (min vs min), "
          f"x{np.median(tb / to):.2f} (median of per-round ratios)")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=None,
                        help="samples (default: hmt.budget().eval_samples)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    n = args.samples or hmt.budget().eval_samples
    torch.set_num_threads(1)  # single-threaded on both sides: a like-for-like comparison
    pj, gj, pv, gv = make_data(n)
    pv_al = M.procrustes_align(pv, gv)
    print(f"samples={n} vertices={gv.shape[1]} torch threads={torch.get_num_threads()} "
          f"rounds={args.repeats} (interleaved)")

    times, out = interleaved({
        "cKDTree loop": lambda: fscore_kdtree_loop(pv_al, gv),
        "f_score": lambda: M.f_score(pv_al, gv)["f"],
    }, args.repeats)
    report("F@5/15mm  ", times, "cKDTree loop", "f_score")
    fdiff = np.abs(out["cKDTree loop"] - out["f_score"]).max()
    print(f"           max |F difference| = {fdiff:.1e}")

    times, out = interleaved({
        "per-sample loop": lambda: evaluation_loop(pj, gj, pv, gv),
        "freihand_scores": lambda: M.freihand_scores(pred_joints=pj, gt_joints=gj,
                                                     pred_verts=pv, gt_verts=gv),
    }, args.repeats)
    report("evaluation", times, "per-sample loop", "freihand_scores")
    ref, ours = out["per-sample loop"], out["freihand_scores"]
    diff = max(abs(ours[k] - ref[k]) for k in ref)
    print(f"           max |difference| over {sorted(ref)} = {diff:.1e}")
    print("scores: " + ", ".join(f"{k}={v:.4f}" for k, v in ours.items()))


if __name__ == "__main__":
    main()
