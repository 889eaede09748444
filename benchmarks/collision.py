"""Benchmark: the exact cylinder test (numba kernels and numpy reference) vs python-fcl.

Prints, measured in the same run on the same pairs (repeats interleaved, medians), each figure with
its baseline and the ratio:

1. Pairs per second of :func:`hmt.collision.cylinders_intersect` on ``--pairs`` random
   finger-sized pairs (radius 5-12 mm, length 15-50 mm, centres in a 6 cm cube; ~20 % intersect)
   with ``backend="numba"`` (the default when numba is installed) and ``backend="numpy"`` (the
   vectorised reference, the library's only path before issue 14); the same on the hard subset
   whose capsules overlap (every such pair reaches the exact stages). Target: >= 5 M pairs/s.
2. :func:`hmt.collision.capsules_intersect` (the conservative pre-filter, numpy).
3. python-fcl (``fcl.Cylinder`` + ``fcl.collide``, GJK/EPA, one call per pair from Python, objects
   built beforehand) on a ``--fcl-pairs`` subsample; its rate is extrapolated. Target: the numba
   path >= 6x fcl. Also fcl's agreement with ours: disagreements are located with the independent
   oracle (:func:`hmt.collision.distance_bounds`), i.e. how far from contact they are.
4. A full hand-vs-hand query (two hands as 20 cylinders each, all 400 primitive pairs):
   median :func:`bodies_collide` and :func:`colliding_pairs` times over random relative poses near
   contact, numba vs numpy (target: >= 3x), and fcl's per-pair loop on the same primitives.

Run: ``python benchmarks/collision.py [--pairs 1000000] [--fcl-pairs 20000]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

import handmesh_tutorial as hmt
from handmesh_tutorial import collision as C
from handmesh_tutorial.collision._common import _kernels


def random_pairs(n: int, seed: int = 0, box: float = 0.03):
    rng = np.random.default_rng(seed)

    def one():
        c = rng.uniform(-box, box, (n, 3))
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        length = rng.uniform(0.015, 0.05, n)
        r = rng.uniform(0.005, 0.012, n)
        return c - 0.5 * length[:, None] * d, c + 0.5 * length[:, None] * d, r

    return (*one(), *one())


def interleaved(fns: dict, repeats: int = 3, number: int = 1) -> dict:
    """Median seconds per call of each function, repeats interleaved (A B A B ...) so that the
    load of a shared machine falls on all of them alike."""
    times = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t = time.perf_counter()
            for _ in range(number):
                fn()
            times[k].append((time.perf_counter() - t) / number)
    return {k: float(np.median(v)) for k, v in times.items()}


def fcl_objects(fcl, p0, p1, r):
    d = p1 - p0
    length = np.linalg.norm(d, axis=1)
    z = np.array([0.0, 0.0, 1.0])
    out = []
    for k in range(len(p0)):
        axis = d[k] / length[k]
        v = np.cross(z, axis)
        s, c = np.linalg.norm(v), axis[2]
        rot = (Rotation.from_rotvec(v / s * np.arctan2(s, c)).as_matrix() if s > 1e-12
               else np.diag([1.0, np.sign(c), np.sign(c)]))
        out.append(fcl.CollisionObject(fcl.Cylinder(float(r[k]), float(length[k])),
                                       fcl.Transform(rot, 0.5 * (p0[k] + p1[k]))))
    return out


def fcl_collide_all(fcl, objs_a, objs_b):
    req = fcl.CollisionRequest()
    return np.array([fcl.collide(a, b, req, fcl.CollisionResult()) > 0
                     for a, b in zip(objs_a, objs_b, strict=True)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=1_000_000)
    parser.add_argument("--fcl-pairs", type=int, default=20_000)
    parser.add_argument("--hand-poses", type=int, default=40)
    args = parser.parse_args()
    try:
        import fcl
    except ImportError:  # pragma: no cover - fcl is a dev dependency
        fcl = None

    n = args.pairs
    pairs = random_pairs(n)
    print(f"# cylinder pairs: {n:,} random finger-sized pairs")
    backends = ["numba", "numpy"] if _kernels("auto") is not None else ["numpy"]
    for b in backends:  # warm-up (loads or compiles the numba kernels)
        C.cylinders_intersect(*(p[:1000] for p in pairs), backend=b)
    res = {b: C.cylinders_intersect(*pairs, backend=b) for b in backends}
    cap = C.capsules_intersect(*pairs)
    hard = np.flatnonzero(cap)
    hard_pairs = tuple(p[hard] for p in pairs)
    t_cyl = interleaved({b: (lambda b=b: C.cylinders_intersect(*pairs, backend=b))
                         for b in backends} | {"capsules": lambda: C.capsules_intersect(*pairs)})
    t_hard = interleaved({b: (lambda b=b: C.cylinders_intersect(*hard_pairs, backend=b))
                          for b in backends})
    ref = res["numpy"]
    print(f"intersecting: cylinders {ref.mean():.1%}, capsules {cap.mean():.1%}; "
          f"cylinder but not capsule: {int((ref & ~cap).sum())} (must be 0)")
    if "numba" in res:
        print(f"numba and numpy answers differ on {int((res['numba'] != ref).sum())} pairs "
              f"(must be 0)")
    for b in backends:
        print(f"cylinders_intersect, {b:5s}: {n / t_cyl[b] / 1e6:8.2f} M pairs/s  "
              f"({t_cyl[b] * 1e3:.0f} ms); capsule-overlapping subset ({hard.size:,} pairs, all "
              f"reach the exact stages): {hard.size / t_hard[b] / 1e6:.2f} M pairs/s")
    print(f"capsules_intersect (numpy): {n / t_cyl['capsules'] / 1e6:8.2f} M pairs/s  "
          f"({t_cyl['capsules'] * 1e3:.0f} ms)")
    if "numba" in res:
        print(f"RATIO cylinders_intersect numba / numpy (baseline {n / t_cyl['numpy'] / 1e6:.2f} "
              f"M pairs/s): {t_cyl['numpy'] / t_cyl['numba']:.1f}x; capsule-overlapping subset "
              f"{t_hard['numpy'] / t_hard['numba']:.1f}x")
    fast = backends[0]

    if fcl is not None:
        m = min(args.fcl_pairs, n)
        sub = tuple(p[:m] for p in pairs)
        oa, ob = fcl_objects(fcl, *sub[:3]), fcl_objects(fcl, *sub[3:])
        got = fcl_collide_all(fcl, oa, ob)
        t_fcl = interleaved({"fcl": lambda: fcl_collide_all(fcl, oa, ob)})["fcl"]
        fcl_rate = m / t_fcl
        print(f"\n# python-fcl on {m:,} of the pairs (one fcl.collide per pair, objects prebuilt, "
              f"median of 3)")
        print(f"fcl.collide         : {fcl_rate / 1e6:8.3f} M pairs/s  "
              f"(extrapolated to {n:,}: {n / fcl_rate:.1f} s)")
        for b in backends:
            print(f"RATIO cylinders_intersect {b} / fcl (baseline {fcl_rate / 1e6:.2f} M pairs/s):"
                  f" {(n / t_cyl[b]) / fcl_rate:.1f}x")
        mine = res[fast][:m]
        bad = np.flatnonzero(got != mine)
        print(f"agreement with fcl: {m - bad.size:,}/{m:,} ({1 - bad.size / m:.3%})")
        if bad.size:
            lo, hi = C.distance_bounds(*(p[bad] for p in sub), refine_at=1e-9)
            print("  disagreements (ours / fcl, oracle distance bounds in metres):")
            for k in range(min(bad.size, 8)):
                print(f"   pair {bad[k]}: ours {mine[bad[k]]}, fcl {got[bad[k]]}, "
                      f"distance in [{lo[k]:.2e}, {hi[k]:.2e}]")
            near = np.maximum(lo, 0) <= 1e-6
            print(f"  {int(near.sum())}/{bad.size} disagreements lie within 1 um of contact "
                  f"(distance lower bound <= 1e-6 m)")

    print("\n# hand vs hand: 2 x 20 cylinders, 400 primitive pairs per query")
    import torch
    torch.set_num_threads(1)
    model = hmt.hand.HandModel("right")
    out = model(pose=torch.as_tensor(hmt.hand.example_pose("pinch"))[None])
    A = C.hand_cylinders(out, model=model)
    rng = np.random.default_rng(0)
    t_hit = {b: [] for b in backends}
    t_miss = {b: [] for b in backends}
    t_pairs = {b: [] for b in backends}
    t_fcl_hand = []
    for k in range(args.hand_poses):
        R = Rotation.random(random_state=k).as_matrix()
        t = rng.normal(size=3)
        t *= rng.uniform(0.02, 0.12) / np.linalg.norm(t)
        B = A.transform(R, t)
        hit = C.bodies_collide(A, B)
        tb = interleaved({b: (lambda B=B, b=b: C.bodies_collide(A, B, backend=b))
                          for b in backends}, number=20, repeats=5)
        tp = interleaved({b: (lambda B=B, b=b: C.colliding_pairs(A, B, backend=b))
                          for b in backends}, number=20, repeats=5)
        for b in backends:
            (t_hit if hit else t_miss)[b].append(tb[b])
            t_pairs[b].append(tp[b])
        if fcl is not None and k < 10:
            ia, ib = np.divmod(np.arange(400), 20)
            oa = fcl_objects(fcl, A.p0[ia], A.p1[ia], A.radius[ia])
            ob = fcl_objects(fcl, B.p0[ib], B.p1[ib], B.radius[ib])
            t0 = time.perf_counter()
            got = fcl_collide_all(fcl, oa, ob)
            t_fcl_hand.append(time.perf_counter() - t0)
            i, j = C.colliding_pairs(A, B)
            mine = np.zeros(400, bool)
            mine[i * 20 + j] = True
            if (got != mine).any():
                print(f"  pose {k}: fcl disagrees on {int((got != mine).sum())} primitive pairs")
    med = lambda x: np.median(x) * 1e6 if x else float("nan")  # noqa: E731
    for b in backends:
        print(f"{b:5s} bodies_collide: colliding poses median {med(t_hit[b]):6.1f} us "
              f"({len(t_hit[b])} poses), non-colliding {med(t_miss[b]):6.1f} us "
              f"({len(t_miss[b])}); colliding_pairs (all 400 pairs) {med(t_pairs[b]):6.1f} us")
    if "numba" in backends:
        all_b = {b: t_hit[b] + t_miss[b] for b in backends}
        print(f"RATIO bodies_collide numba / numpy (baseline {med(all_b['numpy']):.0f} us): "
              f"{np.median(all_b['numpy']) / np.median(all_b['numba']):.0f}x; colliding_pairs "
              f"(baseline {med(t_pairs['numpy']):.0f} us): "
              f"{np.median(t_pairs['numpy']) / np.median(t_pairs['numba']):.0f}x")
    if t_fcl_hand:
        print(f"fcl per-pair loop over 400 pairs   : median {med(t_fcl_hand):6.0f} us  "
              f"(ratio fcl / colliding_pairs {fast}: "
              f"{np.median(t_fcl_hand) / np.median(t_pairs[fast]):.1f})")

if __name__ == "__main__":
    main()
