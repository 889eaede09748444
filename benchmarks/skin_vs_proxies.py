"""The cylinder proxies against the skin: which finger pairs each names, pose by pose.

Random poses of the MakeHuman hand within its anatomical joint limits
(``hand_lcs(hand).random_pose``, the generator's valid poses; seed ``--seed``). For each pose:
the finger pairs whose proxies intersect (``hmt.collision.finger_collisions``, radii shrunk 30 %
as the generator tests them, and not shrunk), and the finger pairs whose skin triangles
intersect (``hmt.collision.skin_collisions``: every phalanx, and the distal phalanges only).
Prints how often the two name the same pairs, and the pairs each names alone. Also times both.

Run: ``python benchmarks/skin_vs_proxies.py [--poses 40] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import numpy as np
import torch

import handmesh_tutorial as hmt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    hand = hmt.hand.HandModel()
    rng = np.random.default_rng(args.seed)
    art = hmt.lcs.hand_lcs(hand)
    pose = torch.from_numpy(np.asarray(art.random_pose(rng, args.poses), np.float32))
    out = hand(pose=pose)
    t = time.perf_counter()
    rows = {"proxies, shrunk 30 %": hmt.collision.finger_collisions(out, model=hand)}
    t_prox = (time.perf_counter() - t) / args.poses
    rows["proxies, not shrunk"] = hmt.collision.finger_collisions(out, model=hand, compression=0)
    t = time.perf_counter()
    rows["skin, every phalanx"] = hmt.collision.skin_collisions(
        out.vertices, hand.faces, hmt.collision.finger_of_vertices(hand))
    t_skin = (time.perf_counter() - t) / args.poses
    rows["skin, distal phalanges"] = hmt.collision.skin_collisions(
        out.vertices, hand.faces, hmt.collision.finger_of_vertices(hand, phalanges=(2,)))
    names = list(rows)
    print(f"{args.poses} poses (seed {args.seed}); same finger pairs, pose by pose:")
    print(f"{'':26s}" + "".join(f"{n[:22]:>24s}" for n in names))
    for a in names:
        same = [sum(x == y for x, y in zip(rows[a], rows[b], strict=True)) for b in names]
        print(f"{a:26s}" + "".join(f"{s:>24d}" for s in same))
    for a, b in ((names[0], names[2]), (names[0], names[3])):
        only_a = Counter(p for x, y in zip(rows[a], rows[b], strict=True) for p in x - y)
        only_b = Counter(p for x, y in zip(rows[a], rows[b], strict=True) for p in y - x)
        print(f"{a} alone: {dict(only_a)}; {b} alone: {dict(only_b)}")
    print(f"time per pose: proxies {t_prox * 1e3:.1f} ms (cylinder fit included), skin "
          f"{t_skin * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
