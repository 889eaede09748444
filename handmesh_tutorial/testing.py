"""Fast stand-in samples for tests, benchmarks and quick demos (not INTER-SH scenes).

* `synthetic_sample`: two spheres ray-cast with numpy, no hands, no OpenGL (dataset tests).
* `toy_sample`: two posed hands of the hand model, point-splatted, no OpenGL (training tests).

Both return a sample dict that [`write_sample`][handmesh_tutorial.dataset.write_sample] and
[`generate_dataset`][handmesh_tutorial.dataset.generate_dataset] accept, with masks, VR, meshes
and joints consistent with each other, so the whole pipeline runs on them in seconds. Real scenes
come from [`interact`][handmesh_tutorial.interact]. Used by the tests and benchmarks (docs page
*Reliability*, ``benchmarks/train.py``); no notebook needs them.
"""

from __future__ import annotations

import numpy as np
import torch

from .dataset import KINDS

__all__ = ["synthetic_sample", "toy_sample"]


def _uv_sphere(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit UV sphere: ``resolution`` latitude bands, ``2 * resolution`` longitudes, two poles.

    Returns vertices (2 + (r - 1) * 2r, 3) and faces (4r(r - 1), 3), counter-clockwise seen
    from outside (normals point out).
    """
    r, n = resolution, 2 * resolution
    theta = np.linspace(0.0, np.pi, r + 1)[1:-1]
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    rings = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0.0, 0.0, 1.0]], rings, [[0.0, 0.0, -1.0]]])
    j = np.arange(n)
    ring = lambda k: 1 + k * n + j  # noqa: E731 - vertex ids of ring k
    faces = [np.stack([np.zeros(n, int), ring(0), np.roll(ring(0), -1)], -1)]
    for k in range(r - 2):
        a, b, c, d = ring(k), np.roll(ring(k), -1), ring(k + 1), np.roll(ring(k + 1), -1)
        faces += [np.stack([a, c, d], -1), np.stack([a, d, b], -1)]
    last, south = ring(r - 2), len(verts) - 1
    faces.append(np.stack([last, np.full(n, south), np.roll(last, -1)], -1))
    return verts, np.concatenate(faces).astype(np.int32)


def synthetic_sample(seed: int, kind: str = "hand-hand", image_size: int = 64,
                     resolution: int = 8) -> dict:
    """A stand-in INTER-SH sample: two spheres ray-cast with numpy (no hands, no OpenGL).

    Body 1 is the target "hand", body 2 the other hand (``hand-hand``) or an object; body 2 sits
    a little nearer the camera with a random sideways offset, so the target's VR covers (0, 1].
    Masks, VR and meshes are mutually consistent: ``scene_mask`` is the nearest sphere per pixel,
    ``alone_masks`` each sphere alone, ``vr`` = visible / alone pixels; meshes are UV spheres of
    the same centres and radii; joints are 21 points on each hand's sphere.

    Args:
        seed: the sample seed.
        kind: one of ``KINDS`` (changes only names and sides).
        image_size: image side, pixels.
        resolution: latitude bands of the sphere meshes (8 -> 114 vertices, 20 -> 762, about
            the size of a MANO hand).

    Returns:
        A sample dict accepted by [`write_sample`][handmesh_tutorial.dataset.write_sample] /
        ``make_sample`` of [`generate_dataset`][handmesh_tutorial.dataset.generate_dataset].
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    rng = np.random.default_rng(seed)
    s = image_size
    f = 1.6 * s
    c = (s - 1) / 2  # OpenCV: pixel centres at integer coordinates, as in render.py
    K = np.array([[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]])
    r1, r2 = rng.uniform(0.03, 0.05), rng.uniform(0.03, 0.05)
    c1 = np.array([*rng.uniform(-0.03, 0.03, 2), rng.uniform(0.45, 0.55)])
    ang = rng.uniform(0, 2 * np.pi)
    off = rng.uniform(0.0, 1.3) * (r1 + r2)
    c2 = c1 + np.array([off * np.cos(ang), off * np.sin(ang), -rng.uniform(0.1, 0.15)])
    u, v = np.meshgrid(np.arange(s, dtype=np.float64), np.arange(s, dtype=np.float64))
    rays = np.stack([(u - K[0, 2]) / f, (v - K[1, 2]) / f, np.ones_like(u)], -1)
    depth = []
    for ctr, r in ((c1, r1), (c2, r2)):  # nearest root of |t d - ctr|^2 = r^2
        a, b, cc = (rays**2).sum(-1), (rays @ ctr), ctr @ ctr - r * r
        disc = b * b - a * cc
        t = np.where(disc >= 0, (b - np.sqrt(np.maximum(disc, 0))) / a, np.inf)
        depth.append(t)
    depth = np.stack(depth)
    alone = np.isfinite(depth)
    scene = np.where(alone.any(0), depth.argmin(0) + 1, 0).astype(np.int32)
    colours = rng.integers(60, 255, size=(3, 3)).astype(np.float64)
    shade = np.clip(1.2 - 2.0 * (np.min(np.where(alone, depth, 1.0), 0) - 0.35), 0.3, 1.0)
    image = colours[scene] * np.where(scene > 0, shade, 1.0)[..., None]
    image = np.clip(image + rng.normal(0, 4, image.shape), 0, 255).astype(np.uint8)
    vr = {lab: float((scene == lab).sum() / alone[lab - 1].sum()) if alone[lab - 1].any()
          else 0.0 for lab in (1, 2)}
    sv, sf = _uv_sphere(resolution)
    dirs = rng.normal(size=(21, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    side1 = "left" if kind == "hand-hand" else str(rng.choice(["left", "right"]))
    other = {"hand-hand": "right_hand", "hand-object": "sphere", "hand-chain": "chain"}[kind]
    sides = {1: side1, 2: "right"} if kind == "hand-hand" else {1: side1}
    gap_mm = 1000 * (np.linalg.norm(c2 - c1) - r1 - r2)
    return {
        "image": image, "scene_mask": scene,
        "alone_masks": {1: alone[0], 2: alone[1]},
        "meshes": {1: ((sv * r1 + c1).astype(np.float32), sf),
                   2: ((sv * r2 + c2).astype(np.float32), sf)},
        "joints": {lab: (c1 + r1 * dirs if lab == 1 else c2 + r2 * dirs).astype(np.float32)
                   for lab in sides},
        "pose": {lab: rng.normal(0, 0.3, (15, 3)).astype(np.float32) for lab in sides},
        "K": K, "vr": vr, "kind": kind, "target": 1, "sides": sides,
        "names": {1: f"{side1}_hand", 2: other},
        "stats": {"gap_mm": float(gap_mm), "stop": "synthetic"},
    }


_TOY_HANDS: dict = {}


def _toy_hand(side: str):
    if side not in _TOY_HANDS:
        from .hand import HandModel

        hm = HandModel(side)
        _TOY_HANDS[side] = (hm, hm.vertex_colors())
    return _TOY_HANDS[side]


def _splat(points, colors, K, size):
    """Nearest-point z-buffer of 3D points (P, 3) with colours; returns depth, colour, mask."""
    uvw = points @ K.T
    uv = np.round(uvw[:, :2] / uvw[:, 2:]).astype(np.int64)
    ok = (uv[:, 0] >= 0) & (uv[:, 0] < size) & (uv[:, 1] >= 0) & (uv[:, 1] < size) & \
        (points[:, 2] > 0)
    pix = uv[ok, 1] * size + uv[ok, 0]
    z = points[ok, 2]
    depth = np.full(size * size, np.inf)
    np.minimum.at(depth, pix, z)
    win = z <= depth[pix]
    col = np.zeros((size * size, 3))
    col[pix[win]] = colors[ok][win]
    return depth.reshape(size, size), col.reshape(size, size, 3)


def toy_sample(seed: int, image_size: int = 64, side: str | None = None) -> dict:
    """A fast stand-in INTER-SH ``hand-hand`` sample: two posed hands, point-splatted.

    No OpenGL: the faces of both meshes are sampled at 10 points each, projected and z-buffered
    (shaded by the face normal), over a random colour gradient. Masks, VR, meshes and joints are
    mutually consistent, so it trains, evaluates and stratifies by VR like the real data (just
    simpler images). Use it with [`generate_dataset`][handmesh_tutorial.dataset.generate_dataset]
    for tests and quick demos; the real scenes come from ``interact``.

    Args:
        seed: sample seed (same seed -> same sample).
        image_size: image side, pixels.
        side: side of the target hand (label 1); ``None`` = random. The other hand (label 2)
            is of the opposite side and a little nearer the camera.

    Returns:
        A sample dict for [`write_sample`][handmesh_tutorial.dataset.write_sample].
    """
    from scipy.spatial.transform import Rotation

    from .hand import random_pose, random_shape

    rng = np.random.default_rng(seed)
    if side is None:
        side = "left" if rng.random() < 0.5 else "right"
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left', 'right' or None, got {side!r}")
    other = "right" if side == "left" else "left"
    s = int(image_size)
    f = 1.6 * s
    c = (s - 1) / 2.0
    K = np.array([[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]])
    centre1 = np.array([*rng.uniform(-0.03, 0.03, 2), rng.uniform(0.45, 0.55)])
    ang = rng.uniform(0, 2 * np.pi)
    off = rng.uniform(0.03, 0.14)
    centre2 = centre1 + np.array([off * np.cos(ang), off * np.sin(ang), -rng.uniform(0.03, 0.1)])
    bary = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [.5, .5, 0], [0, .5, .5], [.5, 0, .5],
                     [1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6],
                     [1 / 6, 1 / 6, 2 / 3]])
    meshes, joints, poses, layers = {}, {}, {}, {}
    for lab, sd, centre in ((1, side, centre1), (2, other, centre2)):
        hm, colors = _toy_hand(sd)
        pose = random_pose(rng, 1, sd, max_flexion_deg=70.0)
        orient = Rotation.random(random_state=rng).as_rotvec()[None].astype(np.float32)
        shape = random_shape(rng, 1, 0.5)
        with torch.no_grad():
            o = hm(pose=pose, shape=shape, global_orient=orient)
        v, j = o.vertices[0].double().numpy(), o.joints[0].double().numpy()
        shift = centre - v.mean(0)
        v, j = v + shift, j + shift
        meshes[lab], joints[lab], poses[lab] = (v, hm.faces), j, pose[0]
        tri = v[hm.faces]  # (F, 3, 3)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
        view = tri.mean(1) / np.linalg.norm(tri.mean(1), axis=1, keepdims=True)
        shade = 0.35 + 0.65 * np.abs((n * view).sum(1))
        pts = np.einsum("kc,fcd->fkd", bary, tri).reshape(-1, 3)
        col = (colors[hm.faces].mean(1) * shade[:, None])[:, None].repeat(len(bary), 1)
        layers[lab] = _splat(pts, col.reshape(-1, 3), K, s)
    depth = np.stack([layers[1][0], layers[2][0]])
    alone = np.isfinite(depth)
    scene = np.where(alone.any(0), depth.argmin(0) + 1, 0).astype(np.int32)
    yy, xx = np.mgrid[0:s, 0:s] / max(s - 1, 1)
    c0, c1 = rng.uniform(0.1, 0.9, 3), rng.uniform(0.1, 0.9, 3)
    t = (0.5 * (xx + yy))[..., None]
    image = (1 - t) * c0 + t * c1
    for lab in (1, 2):
        image = np.where((scene == lab)[..., None], layers[lab][1], image)
    image = np.clip(255 * image + rng.normal(0, 3, image.shape), 0, 255).astype(np.uint8)
    vr = {lab: float((scene == lab).sum() / alone[lab - 1].sum()) if alone[lab - 1].any()
          else 0.0 for lab in (1, 2)}
    return {
        "image": image, "scene_mask": scene,
        "alone_masks": {1: alone[0], 2: alone[1]},
        "meshes": {lab: (m[0].astype(np.float32), m[1]) for lab, m in meshes.items()},
        "joints": {lab: jj.astype(np.float32) for lab, jj in joints.items()},
        "pose": {lab: p.astype(np.float32) for lab, p in poses.items()},
        "K": K, "vr": vr, "kind": "hand-hand", "target": 1, "sides": {1: side, 2: other},
        "names": {1: f"{side}_hand", 2: f"{other}_hand"},
        "stats": {"stop": "toy"},
    }
