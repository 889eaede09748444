"""Throughput of the INTER-SH interaction generator (``handmesh generate``) at 224x224.

Four measurements:

1. **Time split**, in-process, one sample at a time: simulation (``interact.build_scene``: the six
   steps on cylinders plus the mesh settle), rendering (``interact.render_scene``: camera, scene
   image, label mask, each body alone, VR) and writing (``dataset.encode_sample`` + atomic write of
   the folder, with and without fsync). The baseline measured in the same run is one SEG render
   pass of the same scene: every stage is also given as a multiple of it.
2. **End to end**, ``handmesh generate`` in a fresh process with 1 and 2 workers: samples/s
   including start-up (imports, hand models, OpenGL context per process) and in the steady
   state (rate over the samples after the first of each worker, from the folders' times).
3. **Worker start method**: 100 hand-hand scenes with 2 workers, spawned (the baseline: every
   worker imports torch, the library and pyrender again and tears the interpreter down at the
   end) against ``mp_context="auto"`` (forked where it is safe), interleaved; same bytes.

Usage: ``python benchmarks/generate.py [--num 12] [--split 8] [--kinds hand-hand,...]
[--start-num 100] [--start-repeats 2] [--sim 20]``.
The machine is shared: run it when it is otherwise idle, and read ratios rather than absolute
times when it is not.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

SIZE = 224


def split(kind: str, n: int) -> dict:
    import torch

    from handmesh_tutorial import data as dataset
    from handmesh_tutorial import scenes as interact

    torch.set_num_threads(1)
    r = interact.get_renderer(SIZE)
    interact.make_sample(10_000, kind, SIZE)  # warm-up: models, shaders
    t_sim, t_ren, t_write, t_write_sync = [], [], [], []
    tmp = Path(tempfile.mkdtemp(prefix="bench_gen_"))
    seg = []
    try:
        for i in range(n):
            seed = dataset.sample_seed(1, i)
            scene_ss, view_ss, _ = np.random.SeedSequence(seed).spawn(3)
            t0 = time.perf_counter()
            scene = interact.build_scene(kind, np.random.default_rng(scene_ss))
            t1 = time.perf_counter()
            smp = interact.render_scene(scene, np.random.default_rng(view_ss), SIZE, r)
            t2 = time.perf_counter()
            files = dataset.encode_sample(smp)
            dataset._write_folder(tmp / f"a{i}", files, durable=False)
            t3 = time.perf_counter()
            dataset._write_folder(tmp / f"b{i}", files, durable=True)
            t4 = time.perf_counter()
            t_sim.append(t1 - t0)
            t_ren.append(t2 - t1)
            t_write.append(t3 - t2)
            t_write_sync.append(t4 - t3)
            meshes = [(v, f, np.full((len(v), 3), 0.7), lab)
                      for lab, (v, f) in smp["meshes"].items()]
            ts = time.perf_counter()
            r.render(meshes, smp["K"], color=False)  # the baseline: one SEG pass
            seg.append(time.perf_counter() - ts)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    ms = {k: 1e3 * float(np.median(v)) for k, v in
          (("simulation", t_sim), ("rendering", t_ren), ("writing", t_write),
           ("writing+fsync", t_write_sync), ("seg_pass", seg))}
    return ms


def end_to_end(kind: str, num: int, workers: int, start: str = "cli") -> dict:
    """Generate ``num`` scenes in a fresh process (start-up included, as a user sees it).

    ``start="cli"`` runs ``handmesh generate`` (workers forked where it is safe); ``"spawn"`` /
    ``"auto"`` call ``interact.generate_interactions(mp_context=start)`` in a fresh process, the
    same work with the worker start method pinned (``"spawn"`` is the path before issue 14).
    """
    import subprocess
    import sys

    tmp = Path(tempfile.mkdtemp(prefix="bench_gen_e2e_"))
    try:
        if start == "cli":
            cmd = [sys.executable, "-m", "handmesh_tutorial.apps.cli", "generate", "--kind", kind,
                   "--num", str(num), "--seed", "0", "--out", str(tmp / "ds"), "--image-size",
                   str(SIZE), "--workers", str(workers), "--no-progress", "--no-fsync"]
        else:
            cmd = [sys.executable, "-c",
                   "import sys; from handmesh_tutorial.scenes import generate_interactions as g; "
                   f"g(sys.argv[1], {kind!r}, {num}, 0, image_size={SIZE}, workers={workers}, "
                   f"progress=False, durable=False, mp_context={start!r})", str(tmp / "ds")]
        t = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        wall = time.perf_counter() - t
        # steady state: finishing times of the sample folders after each worker's first one
        mt = sorted(p.stat().st_mtime for p in (tmp / "ds" / "samples").iterdir())
        steady = ((len(mt) - workers) / (mt[-1] - mt[workers - 1])
                  if len(mt) > workers and mt[-1] > mt[workers - 1] else float("nan"))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"written": len(mt), "wall_s": wall, "rate": len(mt) / wall, "steady": steady}


def start_methods(kind: str, num: int, workers: int, repeats: int) -> None:
    """Worker start-up: spawn (the baseline) against auto (fork where safe), interleaved."""
    walls: dict[str, list[float]] = {"spawn": [], "auto": []}
    for _ in range(repeats):
        for start in walls:
            walls[start].append(end_to_end(kind, num, workers, start)["wall_s"])
    med = {k: float(np.median(v)) for k, v in walls.items()}
    for start, w in med.items():
        print(f"{kind:12s} {start:>6s} {workers:7d} {num:7d} {w:7.2f} {num / w:9.2f}   "
              f"RATIO vs spawn ({num / med['spawn']:.2f} samples/s): {med['spawn'] / w:.2f}x"
              f"   (runs: {', '.join(f'{x:.2f}' for x in walls[start])} s)")


def kernels(kinds: list[str], n: int) -> None:
    """Part 4: the simulation with the numpy reference against the numba kernels."""
    import torch

    import handmesh_tutorial as hmt
    from handmesh_tutorial import scenes as interact
    from handmesh_tutorial.scenes.contact import _MeshSDF

    torch.set_num_threads(1)
    for backend in ("numpy", "numba"):   # warm-up: hand models, numba's cache
        hmt.collision.BACKEND = backend
        interact.build_scene("hand-hand", 123)
    try:
        for kind in kinds:
            times: dict[str, list[float]] = {"numpy": [], "numba": []}
            for i in range(n):
                for backend in times:
                    hmt.collision.BACKEND = backend
                    t = time.perf_counter()
                    try:
                        interact.build_scene(kind, 1000 + i)
                    except interact.InteractionError:
                        pass
                    times[backend].append(time.perf_counter() - t)
            ref, new = (1e3 * float(np.median(times[b])) for b in ("numpy", "numba"))
            print(f"{kind:12s} build_scene {ref:6.1f} ms numpy  {new:6.1f} ms numba   "
                  f"RATIO vs numpy: {ref / new:.2f}x")
        sc = interact.build_scene("hand-hand", 7)
        (va, fa), (vb, fb) = [(b.vertices, b.faces) for b in sc.bodies]
        sdf = _MeshSDF(vb, fb)
        dist: dict[str, np.ndarray] = {}
        per_call: dict[str, list[float]] = {"numpy": [], "numba": []}
        for backend in ("numpy", "numba") * 3:
            t = time.perf_counter()
            for _ in range(20):
                dist[backend] = sdf(va, backend)
            per_call[backend].append((time.perf_counter() - t) / 20)
        ref, new = (1e3 * float(np.median(per_call[b])) for b in ("numpy", "numba"))
        same = np.array_equal(np.abs(dist["numpy"]), np.abs(dist["numba"]))
        print(f"{'hand-hand':12s} signed distance, {len(va)} vertices vs a hand: {ref:.2f} ms "
              f"numpy  {new:.2f} ms numba   RATIO vs numpy: {ref / new:.2f}x   "
              f"(same distances: {same})")
    finally:
        hmt.collision.BACKEND = "auto"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--num", type=int, default=12, help="samples per end-to-end run")
    ap.add_argument("--split", type=int, default=8, help="samples per kind for the time split")
    ap.add_argument("--kinds", default="hand-hand,hand-object,hand-chain")
    ap.add_argument("--start-num", type=int, default=100,
                    help="samples of the start-method comparison (hand-hand, 2 workers)")
    ap.add_argument("--start-repeats", type=int, default=2)
    ap.add_argument("--sim", type=int, default=20, help="scenes per kind for part 4")
    args = ap.parse_args()
    kinds = args.kinds.split(",")
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; "
          f"image {SIZE}x{SIZE}\n")
    print("1. time split per sample, one process (median ms; x = multiples of one SEG pass)")
    print(f"{'kind':12s} {'simulation':>14s} {'rendering':>14s} {'writing':>12s} "
          f"{'write+fsync':>12s} {'sim share':>10s}")
    for kind in kinds:
        m = split(kind, args.split)
        base = m["seg_pass"]
        total = m["simulation"] + m["rendering"] + m["writing"]
        print(f"{kind:12s} {m['simulation']:7.0f} ({m['simulation'] / base:4.1f}x) "
              f"{m['rendering']:7.0f} ({m['rendering'] / base:4.1f}x) "
              f"{m['writing']:5.0f} ({m['writing'] / base:3.1f}x) {m['writing+fsync']:12.0f} "
              f"{m['simulation'] / total:9.0%}   (SEG pass {base:.0f} ms)")
    print("\n2. end to end (handmesh generate in a fresh process, --no-fsync)")
    print(f"{'kind':12s} {'workers':>7s} {'samples':>7s} {'wall s':>7s} {'samples/s':>9s} "
          f"{'steady/s':>9s} {'speed-up':>8s}")
    for kind in kinds:
        one = None
        for w in (1, 2):
            r = end_to_end(kind, args.num, w)
            one = one or r["rate"]
            print(f"{kind:12s} {w:7d} {r['written']:7d} {r['wall_s']:7.1f} {r['rate']:9.2f} "
                  f"{r['steady']:9.2f} {r['rate'] / one:7.2f}x")
    print(f"\n3. worker start method, {args.start_num} hand-hand samples, 2 workers, fresh "
          f"process each (median of {args.start_repeats}, interleaved)")
    print(f"{'kind':12s} {'start':>6s} {'workers':>7s} {'samples':>7s} {'wall s':>7s} "
          f"{'samples/s':>9s}")
    start_methods("hand-hand", args.start_num, 2, args.start_repeats)
    print(f"\n4. compiled kernels in the simulation, {args.sim} scenes per kind, one process "
          "(median, interleaved)")
    kernels(kinds, args.sim)
    print(f"\nload average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
