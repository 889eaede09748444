"""Fast stand-ins for tests, benchmarks and quick demos: samples and files in foreign formats.

* `synthetic_sample`: two spheres ray-cast with numpy, no hands, no OpenGL (dataset tests).
* `toy_sample`: two posed hands of the hand model, point-splatted, no OpenGL (training tests).
* `mano_format_params` / `write_mano_pickle`: a tiny MANO-format pickle built from the MakeHuman
  hand (its 778 skin vertices, open at the wrist like MANO), for code that reads
  ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl`` ([`load_mano`][handmesh_tutorial.hand.mano.load_mano],
  ``handmesh train --template``) where the licence-gated files are absent.
* `write_freihand_root`: a tiny FreiHAND-format folder (both splits, official file names and
  layout) of posed MANO-format hands, for code that reads FreiHAND
  ([`FreiHAND`][handmesh_tutorial.data.freihand.FreiHAND], ``handmesh train/evaluate --dataset
  freihand``).

The samples are dicts that [`write_sample`][handmesh_tutorial.data.write_sample] and
[`generate_dataset`][handmesh_tutorial.data.generate_dataset] accept, with masks, VR, meshes
and joints consistent with each other, so the whole pipeline runs on them in seconds. Real scenes
come from [`interact`][handmesh_tutorial.scenes]. Used by the tests and benchmarks (docs page
*Reliability*, ``benchmarks/train.py``) and meant for users' own tests; no notebook needs them.
"""

from __future__ import annotations

import json
import os
import pickle
from pathlib import Path

import numpy as np
import torch

from ._io import atomic_write_with
from .data import KINDS

__all__ = ["synthetic_sample", "toy_sample", "mano_format_params", "write_mano_pickle",
           "write_freihand_root"]


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
        A sample dict accepted by [`write_sample`][handmesh_tutorial.data.write_sample] /
        ``make_sample`` of [`generate_dataset`][handmesh_tutorial.data.generate_dataset].
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
    simpler images). Use it with [`generate_dataset`][handmesh_tutorial.data.generate_dataset]
    for tests and quick demos; the real scenes come from ``interact``.

    Args:
        seed: sample seed (same seed -> same sample).
        image_size: image side, pixels.
        side: side of the target hand (label 1); ``None`` = random. The other hand (label 2)
            is of the opposite side and a little nearer the camera.

    Returns:
        A sample dict for [`write_sample`][handmesh_tutorial.data.write_sample].
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


# ------------------------------------------------------------------ MANO and FreiHAND formats


def mano_format_params(side: str = "right") -> dict:
    """The MakeHuman hand as the arrays of an official MANO pickle (``MANO_KEYS`` and more).

    The hand's 778 skin vertices (the wrist cap's centre and faces are dropped, so the mesh is
    open at the wrist like MANO), its skinning weights, its 16-joint tree and its phenotype shape
    space (6 directions, padded with zeros to MANO's 10 betas). ``J_regressor`` (16, 778, scipy
    ``csc``) is corrected (least norm) so that it regresses the hand's rest joints exactly, also
    for every shape; ``posedirs`` are zero (the hand has no pose correctives), ``hands_components``
    the identity and ``hands_mean`` zero. A left hand carries the official ``MANO_LEFT.pkl``'s
    ``shapedirs`` quirk (x column of the wrong sign), so ``load_mano``'s default fix undoes it.

    Posed with the same pose, shape, orientation and translation, a
    [`ManoModel`][handmesh_tutorial.hand.mano.ManoModel] of these arrays loaded with
    ``fingertips=tuple(HandModel(side).fingertip_vertex_ids)`` gives the vertices ``[:778]`` and
    the joints of [`HandModel`][handmesh_tutorial.hand.HandModel] (float32 round-off). With
    MANO's own fingertip ids (the default ``"smplx"``) the 5 tips are other vertices of this mesh.

    Args:
        side: ``"right"`` or ``"left"``.

    Returns:
        dict: ``v_template`` (778, 3) float64 m, ``shapedirs`` (778, 3, 10), ``posedirs``
        (778, 3, 135), ``J_regressor`` (16, 778) sparse, ``weights`` (778, 16),
        ``kintree_table`` (2, 16) int64 (root parent 4294967295 as in the official files),
        ``f`` (F, 3) uint32, ``hands_components`` (45, 45), ``hands_mean`` (45,), ``J`` (16, 3),
        ``bs_style``, ``bs_type``.
    """
    import scipy.sparse as sp

    from .hand import MANO_TO_FREIHAND, HandModel

    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    model = HandModel(side)
    t = model.template
    skin = ~np.asarray(t.cap_faces, bool)
    faces = np.asarray(t.faces)[skin]
    nv = int(faces.max()) + 1  # the cap's centre is the last vertex
    verts = np.asarray(t.vertices, np.float64)[:nv]
    sdirs = np.asarray(t.shape_dirs, np.float64)[:nv]
    jdirs = np.asarray(t.joint_shape_dirs, np.float64)
    rest = np.asarray(t.rest_joints, np.float64)
    # start from the 21-joint regressor's 16 joint rows (vertex weights of each joint), then the
    # least-norm correction that maps the rest mesh and every shape direction to the joints'
    rows = np.asarray(t.joint_regressor, np.float64)[:, :nv]
    reg = np.stack([rows[list(MANO_TO_FREIHAND).index(k)] for k in range(16)])
    basis = np.concatenate([verts, sdirs.reshape(nv, -1)], 1)  # (V, 3 + 3S)
    target = np.concatenate([rest, jdirs.reshape(16, -1)], 1)
    reg = reg + (target - reg @ basis) @ np.linalg.pinv(basis)
    shapedirs = np.zeros((nv, 3, 10))
    shapedirs[:, :, :sdirs.shape[2]] = sdirs
    if side == "left":  # the official left file's quirk, undone by load_mano's default
        shapedirs[:, 0, :] *= -1
    parents = np.asarray(model.parents, np.int64)
    return {
        "v_template": verts, "shapedirs": shapedirs, "posedirs": np.zeros((nv, 3, 135)),
        "J_regressor": sp.csc_matrix(reg), "weights": np.asarray(t.weights, np.float64)[:nv],
        "kintree_table": np.stack([parents % 2**32, np.arange(16)]),
        "f": faces.astype(np.uint32), "hands_components": np.eye(45), "hands_mean": np.zeros(45),
        "J": rest, "bs_style": "lbs", "bs_type": "lrotmin",
    }


def write_mano_pickle(path: str | os.PathLike, side: str = "right", protocol: int = 2) -> Path:
    """Write a tiny MANO-format pickle built from the MakeHuman hand (about 3 MB).

    The arrays of [`mano_format_params`][handmesh_tutorial.testing.mano_format_params], pickled
    as plain numpy arrays and a scipy sparse ``J_regressor`` (the official files also hold chumpy
    objects; the loader turns both into arrays). Loads with
    [`load_mano`][handmesh_tutorial.hand.mano.load_mano] and serves as ``handmesh train
    --template``; name it ``..._RIGHT.pkl`` / ``..._LEFT.pkl`` so that the side can be inferred.

    Args:
        path: output file, written atomically.
        side: ``"right"`` or ``"left"``.
        protocol: pickle protocol (the official files are protocol 2).

    Returns:
        The path written.
    """
    params = mano_format_params(side)
    return atomic_write_with(path, lambda fh: pickle.dump(params, fh, protocol=protocol))


def write_freihand_root(root: str | os.PathLike, num_samples: int = 3, *, image_size: int = 32,
                        seed: int = 0, hand=None) -> Path:
    """Write a tiny FreiHAND-format folder: both splits, the official file names and layout.

    ``training_K/xyz/verts.json`` with ``num_samples`` entries and ``training/rgb`` with four
    images per sample (the versions ``gs, hom, sample, auto``, each with its own background),
    ``training/mask`` (one per sample), and the same for ``evaluation`` (one image per sample,
    no masks). Each sample is ``hand`` in a random pose (up to about 0.4 rad per joint) and
    orientation, 0.5-0.6 m in front of the camera and near the optical axis, point-splatted in a
    skin tone over a colour gradient (no OpenGL); ``xyz`` are the hand's 21 keypoints and
    ``verts`` its vertices, camera frame, metres; ``K`` has a focal length of 2.2 image sides,
    as FreiHAND's 224-px crops. ``mano`` and ``scale`` files are not written (optional in the
    reader).

    Args:
        root: output folder (created; files in it are replaced).
        num_samples: unique samples per split.
        image_size: image side, pixels.
        seed: same seed -> same files.
        hand: a hand model with 778 vertices called like
            [`HandModel`][handmesh_tutorial.hand.HandModel] (e.g. your
            [`load_mano`][handmesh_tutorial.hand.mano.load_mano] model); default the MANO-format
            MakeHuman hand of [`mano_format_params`][handmesh_tutorial.testing.mano_format_params].

    Returns:
        The root folder.

    Raises:
        ValueError: ``hand`` has another vertex count than MANO's 778 (FreiHAND stores MANO
            meshes), or ``num_samples < 1``.
    """
    from PIL import Image
    from scipy.spatial.transform import Rotation

    from .data.freihand import NUM_VERTICES, SAMPLE_VERSIONS

    if num_samples < 1:
        raise ValueError(f"num_samples must be >= 1, got {num_samples}")
    if hand is None:
        from .hand import HandModel
        from .hand.mano import ManoModel

        tips = tuple(int(i) for i in HandModel("right").fingertip_vertex_ids)
        hand = ManoModel(mano_format_params("right"), "right", fingertips=tips)
    if hand.num_vertices != NUM_VERTICES:
        raise ValueError(f"hand has {hand.num_vertices} vertices, but FreiHAND stores MANO's "
                         f"{NUM_VERTICES}; give a MANO-topology hand (e.g. load_mano(...))")
    root = Path(root)
    rng = np.random.default_rng(seed)
    s = int(image_size)
    f = 2.2 * s
    K = np.array([[f, 0.0, (s - 1) / 2], [0.0, f, (s - 1) / 2], [0.0, 0.0, 1.0]])
    faces = np.asarray(hand.faces)
    yy, xx = np.mgrid[0:s, 0:s] / max(s - 1, 1)
    ramp = (0.5 * (xx + yy))[..., None]
    for split, versions in (("training", len(SAMPLE_VERSIONS)), ("evaluation", 1)):
        pose = rng.uniform(-0.4, 0.4, (num_samples, 15, 3)).astype(np.float32)
        orient = Rotation.random(num_samples, random_state=rng).as_rotvec().astype(np.float32)
        with torch.no_grad():
            out = hand(pose=torch.as_tensor(pose), global_orient=torch.as_tensor(orient))
        v, j = out.vertices.double().numpy(), out.joints.double().numpy()
        centre = np.stack([*rng.uniform(-0.02, 0.02, (2, num_samples)),
                           rng.uniform(0.5, 0.6, num_samples)], 1)[:, None]
        shift = centre - v.mean(1, keepdims=True)
        v, j = v + shift, j + shift
        for key, arr in (("K", np.repeat(K[None], num_samples, 0)), ("xyz", j), ("verts", v)):
            payload = arr.tolist()
            atomic_write_with(root / f"{split}_{key}.json",
                              lambda fh, p=payload: json.dump(p, fh), binary=False)
        (root / split / "rgb").mkdir(parents=True, exist_ok=True)
        if split == "training":
            (root / split / "mask").mkdir(parents=True, exist_ok=True)
        for i in range(num_samples):
            pts = np.concatenate([v[i], v[i][faces].mean(1)])
            tone = np.array([0.85, 0.65, 0.52]) * rng.uniform(0.7, 1.0)
            depth, col = _splat(pts, np.tile(tone, (len(pts), 1)), K, s)
            hand_px = np.isfinite(depth)
            for version in range(versions):
                c0, c1 = rng.uniform(0.1, 0.9, 3), rng.uniform(0.1, 0.9, 3)
                image = (1 - ramp) * c0 + ramp * c1
                image = np.where(hand_px[..., None], col, image)
                image = np.clip(255 * image + rng.normal(0, 3, image.shape), 0, 255)
                Image.fromarray(image.astype(np.uint8)).save(
                    root / split / "rgb" / f"{i + version * num_samples:08d}.jpg", quality=95)
            if split == "training":
                Image.fromarray((255 * hand_px).astype(np.uint8)).save(
                    root / split / "mask" / f"{i:08d}.jpg")
    return root
