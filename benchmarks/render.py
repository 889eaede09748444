"""Cost of the render passes at 224x224 (EGL, CPU llvmpipe here): colour, SEG, alone passes.

Prints milliseconds per call and ratios to the SEG pass measured in the same run. The scene is
two bodies of realistic size (a ~1300-face sphere-like hand stand-in and a ~2500-face mug).
"""

from __future__ import annotations

import time

import numpy as np
import trimesh

from handmesh_tutorial import render as R


def _scene():
    hand = trimesh.creation.icosphere(subdivisions=3, radius=0.045)
    hand.apply_scale((1.0, 0.5, 1.6))
    mug = trimesh.creation.cylinder(0.04, 0.1, sections=48).subdivide()
    v1 = hand.vertices + [0.0, 0.0, 0.45]
    v2 = mug.vertices + [0.03, 0.02, 0.5]
    return [(v1, hand.faces, np.tile([0.85, 0.6, 0.5], (len(v1), 1)), 1),
            (v2, mug.faces, np.tile([0.2, 0.4, 0.8], (len(v2), 1)), 2)]


def _time(fn, n):
    fn()  # warm-up (shader compilation, buffers)
    t = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t) / n * 1e3


def main(n: int = 30, size: int = 224) -> None:
    meshes = _scene()
    K = R.crop_camera(np.vstack([m[0] for m in meshes]), size, 0.1)
    rng = np.random.default_rng(0)
    bg = R.random_background(rng, size)
    lights = R.random_lights(rng)
    with R.Renderer(size) as r:
        pr = r._pr
        scene, nodes = r._scene(R._as_meshes(meshes), R._check_K(K), lights, 0.25)
        seg_map = {n: R._label_color(lab) for lab, n in nodes.items()}
        one = {nodes[1]: R._label_color(1)}
        r._seg(scene, seg_map)
        t_seg = _time(lambda: r._seg(scene, seg_map), n)
        t_alone = _time(lambda: r._seg(scene, one), n)
        t_color = _time(lambda: r._color(scene, bg), n)
        t_shadow = _time(lambda: r._r.render(scene, flags=pr.RenderFlags.RGBA
                                              | pr.RenderFlags.SHADOWS_DIRECTIONAL), max(3, n // 5))
        t_build = _time(lambda: r._scene(R._as_meshes(meshes), R._check_K(K), lights, 0.25), n)
        t_full = _time(lambda: r.render(meshes, K, lights=lights, background=bg), n)
        t_all = _time(lambda: r.render(meshes, K, lights=lights, background=bg, alone=True), n)
        t_bg = _time(lambda: R.random_background(rng, size), n)
    print(f"image {size}x{size}, {sum(len(m[1]) for m in meshes)} faces, {n} repeats")
    rows = [("SEG pass (label mask + depth)", t_seg), ("alone pass (SEG, one body)", t_alone),
            ("colour pass (RGBA + composite)", t_color),
            ("colour pass with directional shadows", t_shadow),
            ("scene build (no GL)", t_build),
            ("render(): build + upload + colour + SEG", t_full),
            ("render(alone=True), 2 bodies", t_all), ("random_background", t_bg)]
    for name, t in rows:
        print(f"  {name:42s} {t:7.2f} ms   x{t / t_seg:5.2f} SEG")


if __name__ == "__main__":
    main()
