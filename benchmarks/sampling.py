"""Timing of the mesh hierarchy, the spiral tables and the spiral convolution's gather.

Run: ``python benchmarks/sampling.py``. Prints seconds and ratios against baselines measured in the
same run: building the hierarchy vs loading it from the cache, and SpiralConv's ``index_select``
gather vs plain advanced indexing ``x[:, indices]``.
"""

from __future__ import annotations

import importlib.util
import tempfile
import time

import numpy as np
import torch
import trimesh

import handmesh_tutorial as hmt
from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
from handmesh_tutorial.nn.spiral import SpiralConv, spiral_indices


def best_of(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def meshes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    ico = trimesh.creation.icosphere(subdivisions=3)
    out = {"icosphere(3)": (np.asarray(ico.vertices), np.asarray(ico.faces))}
    if importlib.util.find_spec("handmesh_tutorial.hand") is not None:
        hand = hmt.hand.HandModel("right")
        out["hand"] = (np.asarray(hand.template_vertices, dtype=np.float64), np.asarray(hand.faces))
    return out


def bench_mesh(name: str, v: np.ndarray, f: np.ndarray, batch: int) -> None:
    build = best_of(lambda: mesh_hierarchy(v, f, use_cache=False), repeat=2)
    with tempfile.TemporaryDirectory() as tmp:
        h = mesh_hierarchy(v, f, cache_dir=tmp)
        load = best_of(lambda: mesh_hierarchy(v, f, cache_dir=tmp))
    print(f"\n{name}: levels {h.num_vertices}")
    print(f"  mesh_hierarchy build   {build * 1e3:8.1f} ms")
    print(f"  mesh_hierarchy cached  {load * 1e3:8.1f} ms   (build/cached = {build / load:.0f}x)")
    for length in (9, 27):
        t = best_of(lambda length=length: [spiral_indices(fl, length) for fl in h.faces])
        print(f"  spiral_indices L={length:<3d} all levels {t * 1e3:8.1f} ms")

    idx = spiral_indices(h.faces[0], 9)
    conv = SpiralConv(64, 64, idx)
    x = torch.randn(batch, len(idx), 64)
    it = torch.as_tensor(idx)
    with torch.no_grad():
        t_sel = best_of(lambda: x.index_select(1, conv.indices.view(-1)), repeat=20)
        t_adv = best_of(lambda: x[:, it], repeat=20)
        t_fwd = best_of(lambda: conv(x), repeat=20)
    print(f"  gather (B={batch}, V={len(idx)}, L=9, C=64): index_select "
          f"{t_sel * 1e3:.2f} ms, x[:, idx] {t_adv * 1e3:.2f} ms "
          f"(ratio {t_adv / t_sel:.2f}); full SpiralConv forward {t_fwd * 1e3:.2f} ms")


def main() -> None:
    b = hmt.budget()
    torch.set_num_threads(b.threads)
    print(f"budget={b.name}  torch threads={torch.get_num_threads()}")
    for name, (v, f) in meshes().items():
        bench_mesh(name, v, f, b.batch_size)


if __name__ == "__main__":
    main()
