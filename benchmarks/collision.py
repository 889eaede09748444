"""Benchmark: the vectorised exact cylinder test vs python-fcl and vs the capsule test.

Prints, measured in the same run on the same pairs:

1. Pairs per second of :func:`hmt.collision.cylinders_intersect` on ``--pairs`` random
   finger-sized pairs (radius 5-12 mm, length 15-50 mm, centres in a 6 cm cube; ~20 % intersect),
   and on the hard subset whose capsules overlap (every such pair reaches the exact stages).
   Target: >= 1M exact cylinder pairs/s.
2. The same for :func:`hmt.collision.capsules_intersect` (the conservative pre-filter).
3. python-fcl (``fcl.Cylinder`` + ``fcl.collide``, GJK/EPA, one call per pair from Python, objects
   built beforehand) on a ``--fcl-pairs`` subsample; its rate is extrapolated. Also fcl's agreement
   with ours: disagreements are located with the independent oracle
   (:func:`hmt.collision.distance_bounds`), i.e. how far from contact they are.
4. A full hand-vs-hand query (two hands as 20 cylinders each, all 400 primitive pairs):
   median :func:`bodies_collide` and :func:`colliding_pairs` times over random relative poses near
   contact, vs fcl's per-pair loop on the same primitives. Target: well under a millisecond.

Run: ``python benchmarks/collision.py [--pairs 1000000] [--fcl-pairs 20000]``.
"""

from __future__ import annotations

import argparse
import time
import timeit

import numpy as np
from scipy.spatial.transform import Rotation

import handmesh_tutorial as hmt
from handmesh_tutorial import collision as C


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


def best_time(fn, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


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
    C.cylinders_intersect(*(p[:1000] for p in pairs))  # warm-up
    res = C.cylinders_intersect(*pairs)
    cap = C.capsules_intersect(*pairs)
    t_cyl = best_time(lambda: C.cylinders_intersect(*pairs))
    t_cap = best_time(lambda: C.capsules_intersect(*pairs))
    hard = np.flatnonzero(cap)
    hard_pairs = tuple(p[hard] for p in pairs)
    t_hard = best_time(lambda: C.cylinders_intersect(*hard_pairs))
    print(f"intersecting: cylinders {res.mean():.1%}, capsules {cap.mean():.1%}; "
          f"cylinder but not capsule: {int((res & ~cap).sum())} (must be 0)")
    print(f"cylinders_intersect : {n / t_cyl / 1e6:8.2f} M pairs/s  ({t_cyl * 1e3:.0f} ms)")
    print(f"capsules_intersect  : {n / t_cap / 1e6:8.2f} M pairs/s  ({t_cap * 1e3:.0f} ms)")
    print(f"cylinders, capsule-overlapping subset ({hard.size:,} pairs, all reach the exact "
          f"stages): {hard.size / t_hard / 1e6:.2f} M pairs/s")
    print(f"ratio capsule / cylinder time: {t_cap / t_cyl:.2f}")

    if fcl is not None:
        m = min(args.fcl_pairs, n)
        sub = tuple(p[:m] for p in pairs)
        oa, ob = fcl_objects(fcl, *sub[:3]), fcl_objects(fcl, *sub[3:])
        got = fcl_collide_all(fcl, oa, ob)
        t_fcl = best_time(lambda: fcl_collide_all(fcl, oa, ob))  # best of 3, like ours
        fcl_rate = m / t_fcl
        print(f"\n# python-fcl on {m:,} of the pairs (one fcl.collide per pair, objects prebuilt, "
              f"best of 3)")
        print(f"fcl.collide         : {fcl_rate / 1e6:8.3f} M pairs/s  "
              f"(extrapolated to {n:,}: {n / fcl_rate:.1f} s)")
        print(f"speed-up of cylinders_intersect over fcl: {(n / t_cyl) / fcl_rate:.0f}x")
        mine = res[:m]
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
    t_hit, t_miss, t_pairs, t_fcl_hand = [], [], [], []
    for k in range(args.hand_poses):
        R = Rotation.random(random_state=k).as_matrix()
        t = rng.normal(size=3)
        t *= rng.uniform(0.02, 0.12) / np.linalg.norm(t)
        B = A.transform(R, t)
        hit = C.bodies_collide(A, B)
        tb = np.median(timeit.repeat(lambda B=B: C.bodies_collide(A, B), number=20, repeat=5)) / 20
        (t_hit if hit else t_miss).append(tb)
        t_pairs.append(np.median(timeit.repeat(lambda B=B: C.colliding_pairs(A, B), number=20,
                                               repeat=5)) / 20)
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
    print(f"bodies_collide, colliding poses    : median {med(t_hit):6.0f} us "
          f"({len(t_hit)} poses)")
    print(f"bodies_collide, non-colliding poses: median {med(t_miss):6.0f} us "
          f"({len(t_miss)} poses)")
    print(f"colliding_pairs (all 400 pairs)    : median {med(t_pairs):6.0f} us")
    if t_fcl_hand:
        print(f"fcl per-pair loop over 400 pairs   : median {med(t_fcl_hand):6.0f} us  "
              f"(ratio fcl / colliding_pairs: {np.median(t_fcl_hand) / np.median(t_pairs):.1f})")


if __name__ == "__main__":
    main()
