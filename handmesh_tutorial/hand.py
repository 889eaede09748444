"""The open hand: a licence-free, MANO-like, rigged hand mesh built by library code.

MANO (Romero et al. 2017) cannot be downloaded without a licence, so the library ships its own hand.
It is treated by the rest of the pipeline exactly like MANO: same 16-joint kinematic tree, linear
blend skinning, axis-angle pose per joint, 21 keypoints in FreiHAND order, left and right sides.

How it is built (:func:`build_template`, run once; the result ships as
``handmesh_tutorial/assets/open_hand.npz`` and :class:`HandModel` just loads it):

1. :func:`neutral_skeleton`: 21 keypoints of an adult right hand (palm ~8.6 cm wide, middle finger
   ~8.3 cm from knuckle to tip, thumb with its CMC joint) plus a radius per keypoint.
2. :func:`build_union_mesh`: one tapered capsule per phalanx (convex hull of two spheres, so two
   phalanges meet in a shared sphere = a smooth knuckle), a palm volume (hull of spheres), a thenar
   hull and finger webs, united with ``manifold3d`` (exact, watertight booleans).
3. :func:`isotropic_remesh`: split long / collapse short edges, flip edges towards valence 6,
   tangential relaxation projected back onto the union surface; target edge length from a sizing
   field (denser on the thin fingers, coarser on the palm), ~800 vertices like MANO's 778.
4. :func:`skinning_weights`: nearest bone (distance to bone segments), then Laplacian smoothing on
   the mesh graph so joints bend without tearing.
5. :func:`joint_regressor_from_mesh`: a (21,V) non-negative matrix whose rows sum to 1 and reproduce
   the rest joints from the vertices (the decoder uses it on predicted meshes).

Template frame (right hand, metres): origin at the wrist joint; **+x points from the wrist to the
fingers**, **the palm faces -y** (the back of the hand faces +y), and for the right hand the thumb
is on the **-z** side (pinky on +z); x, y, z is right-handed. The rest pose is a flat hand with the
fingers slightly spread.

Left hand = exact mirror of the right through the plane z = 0 (z negated, faces re-oriented so the
normals stay outward). Both hands therefore rest palm down (-y), fingers along +x, thumb towards the
body's midline. A pose of the right hand becomes the mirrored pose of the left hand by
:func:`mirror_axis_angle`: axis-angle ``(x, y, z) -> (-x, -y, z)`` for every joint and for
``global_orient``; translations mirror as ``(x, y, z) -> (x, y, -z)``. Then
``left(mirror(pose)) == mirror(right(pose))`` (tested).

Joint orders (one place for the whole library): :data:`MANO_JOINT_NAMES` / :data:`MANO_PARENTS`
(16-joint kinematic tree: 0 wrist, 1-3 index, 4-6 middle, 7-9 pinky, 10-12 ring, 13-15 thumb) and
:data:`FREIHAND_JOINT_NAMES` / :data:`FREIHAND_PARENTS` (21 keypoints: 0 wrist, 1-4 thumb base to
tip, 5-8 index, 9-12 middle, 13-16 ring, 17-20 pinky). :data:`MANO_TO_FREIHAND` maps between them.
"""

from __future__ import annotations

import functools
import os
import tempfile
import time
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import torch
from torch import nn

__all__ = [
    "MANO_JOINT_NAMES", "MANO_PARENTS", "FREIHAND_JOINT_NAMES", "FREIHAND_PARENTS",
    "MANO_TO_FREIHAND", "FINGERTIP_NAMES", "FINGER_NAMES", "MIRROR_AXIS", "SHAPE_PARAM_NAMES",
    "SHAPE_STEP", "SKIN_TONES", "ASSET_PATH",
    "Skeleton", "HandTemplate", "HandOutput", "HandModel",
    "neutral_skeleton", "build_union_mesh", "sizing_field", "isotropic_remesh", "skinning_weights",
    "joint_regressor_from_mesh", "build_template", "write_template_asset", "load_template",
    "axis_angle_to_matrix", "lbs", "mirror_points", "mirror_axis_angle",
    "self_intersections", "mesh_checks", "flexion_axes", "example_pose", "random_pose",
]

# ------------------------------------------------------------------------------------------------
# Constants: the joint orders of the whole library live here (and only here).
# ------------------------------------------------------------------------------------------------

#: The 16 joints of the MANO kinematic tree, in MANO order ("1" = the joint nearest the wrist).
#: For the thumb, ``thumb1`` is the carpometacarpal (CMC) joint, ``thumb2`` the MCP,
#: ``thumb3`` the IP.
MANO_JOINT_NAMES: tuple[str, ...] = (
    "wrist",
    "index1", "index2", "index3",
    "middle1", "middle2", "middle3",
    "pinky1", "pinky2", "pinky3",
    "ring1", "ring2", "ring3",
    "thumb1", "thumb2", "thumb3",
)

#: Parent of each MANO joint (-1 for the root); parents come before their children.
MANO_PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14)

#: Fingers in FreiHAND order (also the order of the 5 fingertips everywhere in the library).
FINGER_NAMES: tuple[str, ...] = ("thumb", "index", "middle", "ring", "pinky")

#: The 5 fingertip keypoints (vertices of the mesh), thumb to pinky.
FINGERTIP_NAMES: tuple[str, ...] = tuple(f"{f}_tip" for f in FINGER_NAMES)

#: The 21 keypoints in FreiHAND order: wrist, then per finger (thumb, index, middle, ring, pinky)
#: four points from the base to the tip. For the thumb these are CMC, MCP, IP, tip; for the other
#: fingers MCP, PIP, DIP, tip.
FREIHAND_JOINT_NAMES: tuple[str, ...] = ("wrist",) + tuple(
    f"{finger}{k}" for finger in FINGER_NAMES for k in ("1", "2", "3", "_tip"))

#: Parent of each FreiHAND keypoint (-1 for the wrist).
FREIHAND_PARENTS: tuple[int, ...] = (-1,) + tuple(
    0 if k % 4 == 1 else k - 1 for k in range(1, 21))

#: FreiHAND keypoint ``i`` = row ``MANO_TO_FREIHAND[i]`` of the (21,3) array
#: ``[16 MANO joints in MANO order, 5 fingertips thumb..pinky]``, i.e.
#: ``joints21 = np.concatenate([joints_mano, tips])[MANO_TO_FREIHAND]``.
MANO_TO_FREIHAND: tuple[int, ...] = (
    0,
    13, 14, 15, 16,   # thumb: CMC, MCP, IP, tip
    1, 2, 3, 17,      # index
    4, 5, 6, 18,      # middle
    10, 11, 12, 19,   # ring
    7, 8, 9, 20,      # pinky
)

#: Axis negated to turn the right hand into the left hand (z: the thumb-to-pinky axis).
MIRROR_AXIS: int = 2

#: Shape parameters (``shape[:, i]``), 0 = template; each unit changes the quantity by
#: :data:`SHAPE_STEP` (15 %), useful range [-1, 1] (about -15 % .. +15 %).
SHAPE_PARAM_NAMES: tuple[str, ...] = ("size", "finger_length", "palm_width", "thickness")

#: Relative change per unit of a shape parameter.
SHAPE_STEP: float = 0.15

#: A small palette of realistic skin tones (linear-ish sRGB in [0,1]), light to dark; the palm and
#: the palmar side of the fingers are drawn lighter than the back of the hand.
SKIN_TONES: tuple[tuple[float, float, float], ...] = (
    (0.96, 0.80, 0.69),
    (0.90, 0.72, 0.60),
    (0.80, 0.60, 0.47),
    (0.67, 0.47, 0.34),
    (0.50, 0.34, 0.24),
    (0.36, 0.24, 0.17),
)

#: Where the shipped template lives (package data).
ASSET_PATH: Path = Path(__file__).resolve().parent / "assets" / "open_hand.npz"

_MANO_INDEX = {name: i for i, name in enumerate(MANO_JOINT_NAMES)}
# MANO joints of each finger (base -> distal), FreiHAND finger order.
_FINGER_MANO = {f: tuple(_MANO_INDEX[f"{f}{k}"] for k in (1, 2, 3)) for f in FINGER_NAMES}

# ------------------------------------------------------------------------------------------------
# 1. Skeleton
# ------------------------------------------------------------------------------------------------

_CM = 0.01


@dataclass(frozen=True)
class Skeleton:
    """The neutral skeleton the open hand is built from.

    Attributes:
        keypoints: (21,3) float64, metres, FreiHAND order; the tips are points on the skin.
        radii: (21,) float64, metres: radius of the finger (capsule) at each keypoint; for the
            wrist the half-thickness of the palm.
        palm_centres: (P,3) sphere centres whose convex hull is the palm volume, metres.
        palm_radii: (P,) their radii, metres.
    """

    keypoints: np.ndarray
    radii: np.ndarray
    palm_centres: np.ndarray
    palm_radii: np.ndarray


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def neutral_skeleton() -> Skeleton:
    """The adult right-hand skeleton of the template (rest pose, template frame, metres).

    Proportions follow anthropometric averages of adult hands: MCP joints on an arc 7.9-9.0 cm in
    front of the wrist joint, phalanx lengths (MCP->PIP->DIP->tip) index 3.6/2.2/1.9 cm,
    middle 3.9/2.45/1.95 cm, ring 3.7/2.3/1.95 cm, pinky 2.9/1.75/1.8 cm, thumb metacarpal
    4.6 cm, proximal 3.1 cm, distal 2.6 cm; palm about 8.6 cm wide across the knuckles and 2.5 cm
    thick. Fingers are straight and fan out by -7..+12 degrees (slightly spread).

    Returns:
        The :class:`Skeleton` (FreiHAND keypoint order).
    """
    kp = np.zeros((21, 3))
    radii = np.zeros(21)
    radii[0] = 1.25 * _CM
    # name: (MCP position [cm], yaw towards +z [deg], phalanx lengths [cm], radii MCP,PIP,DIP,tip)
    fingers = {
        "index": ((8.7, 0.0, -2.75), -7.0, (3.6, 2.2, 1.9), (0.98, 0.86, 0.76, 0.66)),
        "middle": ((9.0, 0.0, -0.75), -1.0, (3.9, 2.45, 1.95), (1.00, 0.90, 0.78, 0.68)),
        "ring": ((8.6, 0.0, 1.20), 5.0, (3.7, 2.3, 1.95), (0.94, 0.84, 0.74, 0.64)),
        "pinky": ((7.9, 0.0, 2.95), 12.0, (2.9, 1.75, 1.8), (0.84, 0.74, 0.66, 0.58)),
    }
    for name, (mcp, yaw, lengths, rad) in fingers.items():
        base = 1 + 4 * FINGER_NAMES.index(name)
        a = np.deg2rad(yaw)
        direction = np.array([np.cos(a), 0.0, np.sin(a)])
        p = np.asarray(mcp, dtype=float)
        kp[base] = p
        for k, length in enumerate(lengths):
            p = p + length * direction
            kp[base + k + 1] = p
        radii[base:base + 4] = rad
    # Thumb: CMC deep in the thenar, pointing out sideways, forwards and a little palmwards.
    cmc = np.array([1.6, -0.9, -2.0])
    mcp = cmc + 4.6 * _unit([0.62, -0.30, -0.72])
    ip = mcp + 3.1 * _unit([0.80, -0.22, -0.56])
    tip = ip + 2.6 * _unit([0.88, -0.15, -0.45])
    kp[1:5] = [cmc, mcp, ip, tip]
    radii[1:5] = (1.55, 1.10, 0.98, 0.82)
    palm_c = np.array([
        (-1.0, 0.0, -1.7), (-1.0, 0.0, 1.7), (1.0, 0.0, -2.3), (1.0, 0.0, 2.3),
        (6.0, 0.0, -3.2), (5.5, 0.0, 3.2),
        (8.4, -0.1, -2.7), (8.8, -0.1, -0.75), (8.4, -0.1, 1.2), (7.6, -0.1, 2.9),
    ])
    palm_r = np.array([1.25, 1.25, 1.3, 1.25, 1.3, 1.2, 1.2, 1.2, 1.2, 1.15])
    radii = radii * _CM
    radii[0] = 1.25 * _CM
    return Skeleton(keypoints=kp * _CM, radii=radii, palm_centres=palm_c * _CM,
                    palm_radii=palm_r * _CM)


def _mano_rest_joints(skel: Skeleton) -> np.ndarray:
    """(16,3) MANO-order joints from the 21 FreiHAND keypoints (drops the tips)."""
    out = np.zeros((16, 3))
    for i, row in enumerate(MANO_TO_FREIHAND):
        if row < 16:
            out[row] = skel.keypoints[i]
    return out


def _bone_segments(skel: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Line segments of the 16 bones: bone k is driven by MANO joint k.

    Returns:
        (starts (S,3), ends (S,3), bone id (S,), radius (S,)) with several segments for bone 0
        (the palm: wrist to each finger's base, and a short stub into the wrist).
    """
    kp = skel.keypoints
    starts, ends, ids, rad = [], [], [], []
    for f_i, finger in enumerate(FINGER_NAMES):
        base = 1 + 4 * f_i
        # Palm segment from the wrist to this finger's base (MCP; CMC for the thumb).
        starts.append(kp[0])
        ends.append(kp[base])
        ids.append(0)
        rad.append(skel.radii[0])
        for k in range(3):
            a, b = kp[base + k], kp[base + k + 1]
            if k == 2:  # the last bone ends at the centre of the tip's sphere, not on the skin
                b = b - skel.radii[base + 3] * _unit(b - a)
            starts.append(a)
            ends.append(b)
            ids.append(_FINGER_MANO[finger][k])
            rad.append(0.5 * (skel.radii[base + k] + skel.radii[base + k + 1]))
    starts.append(kp[0])
    ends.append(kp[0] + np.array([-1.2 * _CM, 0, 0]))
    ids.append(0)
    rad.append(skel.radii[0])
    return np.array(starts), np.array(ends), np.array(ids), np.array(rad)


def _segment_distances(points: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(N,S) Euclidean distance from each point to each line segment."""
    d = ends - starts                                           # (S,3)
    rel = points[:, None, :] - starts[None]                     # (N,S,3)
    t = np.clip((rel * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-30), 0.0, 1.0)
    return np.linalg.norm(rel - t[..., None] * d, axis=-1)


# ------------------------------------------------------------------------------------------------
# 2. Union of capsules and palm volume (manifold3d)
# ------------------------------------------------------------------------------------------------

def _sphere_points(centre, radius: float, segments: int) -> np.ndarray:
    import manifold3d as m3d

    pts = np.asarray(m3d.Manifold.sphere(float(radius), segments).to_mesh().vert_properties)
    return pts[:, :3].astype(float) + np.asarray(centre, dtype=float)


def _hull_of_spheres(centres, radii, segments: int):
    import manifold3d as m3d

    pts = np.vstack([_sphere_points(c, r, segments) for c, r in zip(centres, radii, strict=True)])
    return m3d.Manifold.hull_points(pts)


def build_union_mesh(skeleton: Skeleton | None = None, segments: int = 24,
                     return_parts: bool = False):
    """Capsules per phalanx + palm + thenar + finger webs, united with ``manifold3d``.

    Each phalanx is the convex hull of a sphere at each of its two joints (a tapered capsule);
    neighbouring phalanges share the sphere at their joint, so the union is smooth there.

    Args:
        skeleton: the skeleton; :func:`neutral_skeleton` when ``None``.
        segments: circular segments of each sphere (resolution of the union mesh).
        return_parts: also return the list of part meshes (for figures).

    Returns:
        ``(vertices (V,3) float64 metres, faces (F,3) int64)`` of the watertight union, and the
        parts as a list of ``(vertices, faces)`` when ``return_parts``.
    """
    import manifold3d as m3d

    skel = neutral_skeleton() if skeleton is None else skeleton
    kp, rad = skel.keypoints, skel.radii
    parts = []
    for f_i in range(5):
        base = 1 + 4 * f_i
        for k in range(3):
            a, b = kp[base + k], kp[base + k + 1]
            rb = rad[base + k + 1]
            if k == 2:  # the tip keypoint is on the skin: put the sphere centre one radius back
                b = b - rb * _unit(b - a)
            parts.append(_hull_of_spheres([a, b], [rad[base + k], rb], segments))
    parts.append(_hull_of_spheres(skel.palm_centres, skel.palm_radii, segments))
    # Thenar eminence: the fleshy ball of the thumb, between CMC, thumb MCP and the index base.
    cmc, tmcp = kp[1], kp[2]
    parts.append(_hull_of_spheres(
        [cmc, tmcp - 0.3 * _CM * _unit(tmcp - cmc), [5.5 * _CM, -0.3 * _CM, -2.8 * _CM],
         [1.5 * _CM, -0.3 * _CM, -1.0 * _CM]],
        [1.45 * _CM, 0.95 * _CM, 1.2 * _CM, 1.3 * _CM], segments))
    # Webs between neighbouring fingers, a third of the way up the proximal phalanges, palmar.
    for fa, fb in (("index", "middle"), ("middle", "ring"), ("ring", "pinky")):
        ia, ib = 1 + 4 * FINGER_NAMES.index(fa), 1 + 4 * FINGER_NAMES.index(fb)
        down = np.array([0.0, -0.25 * _CM, 0.0])
        pa = kp[ia] + 0.35 * (kp[ia + 1] - kp[ia]) + down
        pb = kp[ib] + 0.35 * (kp[ib + 1] - kp[ib]) + down
        parts.append(_hull_of_spheres([pa, pb, kp[ia], kp[ib]],
                                      [0.55 * _CM, 0.55 * _CM, 0.8 * _CM, 0.8 * _CM], segments))
    union = m3d.Manifold.batch_boolean(parts, m3d.OpType.Add)
    mesh = union.to_mesh()
    verts = np.asarray(mesh.vert_properties)[:, :3].astype(np.float64)
    faces = np.asarray(mesh.tri_verts).astype(np.int64)
    if not return_parts:
        return verts, faces
    part_meshes = []
    for p in parts:
        pm = p.to_mesh()
        part_meshes.append((np.asarray(pm.vert_properties)[:, :3].astype(np.float64),
                            np.asarray(pm.tri_verts).astype(np.int64)))
    return verts, faces, part_meshes


# ------------------------------------------------------------------------------------------------
# 3. Isotropic remeshing (split / collapse / flip / relax + project)
# ------------------------------------------------------------------------------------------------
# Written here rather than taken from a library: the ready-made decimators that install here
# (fast-simplification's QEM) produce slivers and even broke the topology of this mesh, and
# the hierarchy built on top of the template wants near-uniform triangles.

def _halfedges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return he, np.tile(np.arange(len(faces)), 3)


def _unique_edges(faces: np.ndarray) -> np.ndarray:
    he, _ = _halfedges(faces)
    return np.unique(np.sort(he, axis=1), axis=0)


def _face_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-30)


def _split_long_edges(v: np.ndarray, f: np.ndarray, sizing) -> tuple[np.ndarray, np.ndarray]:
    verts = list(v)
    f = f.copy()
    while True:
        va = np.asarray(verts)
        he, fid = _halfedges(f)
        length = np.linalg.norm(va[he[:, 0]] - va[he[:, 1]], axis=1)
        hi = 4.0 / 3.0 * sizing(0.5 * (va[he[:, 0]] + va[he[:, 1]]))
        twin = {(int(a), int(b)): i for i, (a, b) in enumerate(he)}
        used = np.zeros(len(f), bool)
        new_faces = []
        for i in np.argsort(-(length / hi), kind="stable"):
            if length[i] <= hi[i]:
                break
            a, b = int(he[i, 0]), int(he[i, 1])
            f1, f2 = fid[i], fid[twin[(b, a)]]
            if used[f1] or used[f2]:
                continue
            used[f1] = used[f2] = True
            m = len(verts)
            verts.append(0.5 * (va[a] + va[b]))
            c = int(f[f1][(f[f1] != a) & (f[f1] != b)][0])
            d = int(f[f2][(f[f2] != a) & (f[f2] != b)][0])
            f[f1] = [a, m, c]          # f1 = (a, b, c) in rotation
            new_faces.append([m, b, c])
            f[f2] = [b, m, d]          # f2 = (b, a, d) in rotation
            new_faces.append([m, a, d])
        if not new_faces:
            return np.asarray(verts), f
        f = np.vstack([f, np.asarray(new_faces, dtype=f.dtype)])


def _collapse_short_edges(v: np.ndarray, f: np.ndarray, sizing) -> tuple[np.ndarray, np.ndarray]:
    v = v.copy()
    f = f.copy()
    while True:
        nv = len(v)
        edges = _unique_edges(f)
        mid = 0.5 * (v[edges[:, 0]] + v[edges[:, 1]])
        size = sizing(mid)
        ratio = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1) / size
        cand = np.argsort(ratio, kind="stable")
        cand = cand[ratio[cand] < 0.8]
        if len(cand) == 0:
            break
        vf = sp.csr_matrix((np.ones(f.size), (f.ravel(), np.repeat(np.arange(len(f)), 3))),
                           shape=(nv, len(f))).tolil().rows
        fn = _face_normals(v, f)
        locked = np.zeros(nv, bool)
        dead_f = np.zeros(len(f), bool)
        dead_v = np.zeros(nv, bool)
        count = 0
        for i in cand:
            a, b = int(edges[i, 0]), int(edges[i, 1])
            if locked[a] or locked[b]:
                continue
            fa, fb = set(vf[a]), set(vf[b])
            shared = fa & fb
            if len(shared) != 2:
                continue
            na = set(f[list(fa)].ravel().tolist()) - {a}
            nb = set(f[list(fb)].ravel().tolist()) - {b}
            common = (na & nb) - {a, b}
            # Link condition (keeps the surface a manifold) and no valence-3 vertex left behind.
            if len(common) != 2 or any(len(vf[c]) <= 3 for c in common):
                continue
            p = mid[i]
            ring = (na | nb) - {a, b}
            ring_l = np.array(sorted(ring))
            if np.any(np.linalg.norm(v[ring_l] - p, axis=1) > 4.0 / 3.0 * size[i]):
                continue
            ok = True
            for fi in (fa | fb) - shared:
                tri = f[fi]
                pts = v[tri].copy()
                pts[(tri == a) | (tri == b)] = p
                n = np.cross(pts[1] - pts[0], pts[2] - pts[0])
                ln = np.linalg.norm(n)
                if ln < 1e-14 or (n / ln) @ fn[fi] < 0.5:   # no flipped or folded triangle
                    ok = False
                    break
            if not ok:
                continue
            v[a] = p
            for fi in fb - shared:
                f[fi][f[fi] == b] = a
            dead_f[list(shared)] = True
            dead_v[b] = True
            locked[ring_l] = True
            locked[[a, b]] = True
            count += 1
        f = f[~dead_f]
        remap = -np.ones(nv, np.int64)
        remap[~dead_v] = np.arange(int((~dead_v).sum()))
        v, f = v[~dead_v], remap[f]
        if count == 0:
            break
    return v, f


def _flip_to_valence(v: np.ndarray, f: np.ndarray, passes: int = 5,
                     dihedral_cos: float = 0.7) -> np.ndarray:
    f = f.copy()
    for _ in range(passes):
        he, fid = _halfedges(f)
        twin = {(int(a), int(b)): i for i, (a, b) in enumerate(he)}
        val = np.bincount(f.ravel(), minlength=len(v))
        fn = _face_normals(v, f)
        used = np.zeros(len(f), bool)
        edges = _unique_edges(f)
        edge_set = set(map(tuple, edges.tolist()))
        flips = 0
        for a, b in edges.tolist():
            i = twin[(a, b)]
            f1, f2 = fid[i], fid[twin[(b, a)]]     # f1 holds the half-edge a->b
            if used[f1] or used[f2]:
                continue
            c = int(f[f1][(f[f1] != a) & (f[f1] != b)][0])
            d = int(f[f2][(f[f2] != a) & (f[f2] != b)][0])
            if (min(c, d), max(c, d)) in edge_set or val[a] <= 3 or val[b] <= 3:
                continue
            before = abs(val[a] - 6) + abs(val[b] - 6) + abs(val[c] - 6) + abs(val[d] - 6)
            after = abs(val[a] - 7) + abs(val[b] - 7) + abs(val[c] - 5) + abs(val[d] - 5)
            if after >= before or fn[f1] @ fn[f2] < dihedral_cos:
                continue
            n1, n2 = np.array([a, d, c]), np.array([d, b, c])
            m = _face_normals(v, np.stack([n1, n2]))
            if m[0] @ fn[f1] < 0.5 or m[1] @ fn[f1] < 0.5 or m[0] @ m[1] < dihedral_cos:
                continue
            f[f1], f[f2] = n1, n2
            used[f1] = used[f2] = True
            val[[a, b]] -= 1
            val[[c, d]] += 1
            edge_set.discard((a, b))
            edge_set.add((min(c, d), max(c, d)))
            flips += 1
        if flips == 0:
            break
    return f


def _vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])   # area-weighted
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], n)
    return vn / (np.linalg.norm(vn, axis=1, keepdims=True) + 1e-30)


def _adjacency(f: np.ndarray, nv: int) -> sp.csr_matrix:
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    a = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(nv, nv))
    return ((a + a.T) > 0).astype(np.float64).tocsr()


def _relax(v: np.ndarray, f: np.ndarray, reference, lam: float = 0.5,
           fixed: np.ndarray | None = None) -> np.ndarray:
    import trimesh

    adj = _adjacency(f, len(v))
    n = _vertex_normals(v, f)
    d = (adj @ v) / np.asarray(adj.sum(1)) - v
    d -= (d * n).sum(1, keepdims=True) * n          # tangential only: keeps the shape
    out, _, _ = trimesh.proximity.closest_point(reference, v + lam * d)
    out = np.asarray(out, dtype=np.float64)
    if fixed is not None:
        out[fixed] = v[fixed]
    return out


def _reference_surface(vertices: np.ndarray, faces: np.ndarray, length: float):
    import manifold3d as m3d
    import trimesh

    man = m3d.Manifold(m3d.Mesh(vert_properties=np.asarray(vertices, np.float32),
                                tri_verts=np.asarray(faces, np.uint32)))
    dense = man.refine_to_length(length).to_mesh()
    return trimesh.Trimesh(np.asarray(dense.vert_properties)[:, :3],
                           np.asarray(dense.tri_verts), process=False)


def isotropic_remesh(vertices: np.ndarray, faces: np.ndarray, sizing, iterations: int = 6,
                     reference_length: float = 0.002) -> tuple[np.ndarray, np.ndarray]:
    """Isotropic remeshing (Botsch & Kobbelt 2004) onto the surface of a closed mesh.

    Each iteration splits edges longer than 4/3 of the target length, collapses edges shorter
    than 4/5 of it (link condition and fold checks keep the mesh a closed 2-manifold), flips
    edges to bring valences towards 6, and moves vertices tangentially to the centroid of their
    neighbours, then projects them back onto the input surface.

    Args:
        vertices: (V,3) float, metres, of a watertight mesh.
        faces: (F,3) int.
        sizing: callable mapping (N,3) points to (N,) target edge lengths in metres.
        iterations: remeshing iterations.
        reference_length: the input is refined to this edge length (metres) for the projection.

    Returns:
        ``(vertices (V',3) float64, faces (F',3) int64)``.
    """
    reference = _reference_surface(vertices, faces, reference_length)
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    for _ in range(iterations):
        v, f = _split_long_edges(v, f, sizing)
        v, f = _collapse_short_edges(v, f, sizing)
        f = _flip_to_valence(v, f)
        v = _relax(v, f, reference)
    return v, f


def sizing_field(skeleton: Skeleton | None = None, scale: float = 0.74, lo: float = 0.0045,
                 hi: float = 0.0105):
    """Target edge length of the remesher: proportional to the local limb radius.

    Args:
        skeleton: the skeleton; :func:`neutral_skeleton` when ``None``.
        scale: edge length / distance to the nearest bone.
        lo: shortest target edge length, metres.
        hi: longest target edge length, metres.

    Returns:
        A callable mapping (N,3) points (metres) to (N,) target edge lengths (metres).
    """
    skel = neutral_skeleton() if skeleton is None else skeleton
    starts, ends, _, _ = _bone_segments(skel)

    def sizing(points: np.ndarray) -> np.ndarray:
        # Distance to the nearest bone ~ local radius of the limb: thin fingers get short edges.
        r = _segment_distances(np.asarray(points, float), starts, ends).min(1)
        return np.clip(scale * r, lo, hi)

    return sizing


# ------------------------------------------------------------------------------------------------
# 4./5. Skinning weights, joint regressor, shape directions, labels
# ------------------------------------------------------------------------------------------------

def skinning_weights(vertices: np.ndarray, faces: np.ndarray, skeleton: Skeleton | None = None,
                     smooth_iterations: int = 5, smooth_lambda: float = 0.5,
                     prune: float = 1e-3) -> np.ndarray:
    """Skinning weights from bone distance, smoothed over the mesh.

    Every vertex first belongs to its nearest bone (distance to the bone's line segments, the
    palm being bone 0); then ``smooth_iterations`` steps of ``w <- (1-l) w + l * mean(w of the
    1-ring)`` blend the weights across each joint over about one ring of triangles each side, so
    bending a joint stretches a band of skin instead of tearing it. Weights below ``prune`` are
    dropped and rows renormalised.

    Args:
        vertices: (V,3) rest vertices, metres (template frame).
        faces: (F,3) int.
        skeleton: the skeleton the mesh was built from; :func:`neutral_skeleton` if ``None``.
        smooth_iterations: Laplacian smoothing steps on the mesh graph.
        smooth_lambda: step size of each smoothing step.
        prune: weights below this are set to 0.

    Returns:
        (V,16) float64, non-negative, rows sum to 1, MANO joint order.
    """
    skel = neutral_skeleton() if skeleton is None else skeleton
    starts, ends, ids, _ = _bone_segments(skel)
    dist = _segment_distances(np.asarray(vertices, float), starts, ends)      # (V,S)
    nearest = ids[np.argmin(dist, axis=1)]
    w = np.zeros((len(vertices), 16))
    w[np.arange(len(vertices)), nearest] = 1.0
    adj = _adjacency(np.asarray(faces), len(vertices))
    deg = np.asarray(adj.sum(1))
    for _ in range(smooth_iterations):
        w = (1 - smooth_lambda) * w + smooth_lambda * (adj @ w) / deg
    w[w < prune] = 0.0
    return w / w.sum(1, keepdims=True)


def joint_regressor_from_mesh(vertices: np.ndarray, weights: np.ndarray, joints: np.ndarray,
                              tip_ids: np.ndarray, parents=MANO_PARENTS,
                              radius_factor: float = 1.6, smoothness: float = 1e-3) -> np.ndarray:
    """A (21,V) joint regressor: keypoints as convex combinations of nearby vertices.

    For each skeleton joint, the vertices within ``radius_factor`` x (distance to the nearest
    vertex) of it are selected (a ring of skin around the joint) and non-negative weights summing
    to 1 are fitted so that the weighted mean of the rest vertices equals the rest joint, with a
    small pull (``smoothness``) towards equal weights so the ring moves as a whole when posed.
    Fingertip rows are one-hot on the tip vertices.

    Args:
        vertices: (V,3) rest vertices, metres.
        weights: (V,16) skinning weights (prefers vertices skinned to the joint or its parent).
        joints: (16,3) rest joints, MANO order, metres.
        tip_ids: (5,) fingertip vertex ids, thumb..pinky.
        parents: (16,) parents of the MANO joints.
        radius_factor: ring radius relative to the distance from the joint to the skin.
        smoothness: weight of the pull towards uniform weights.

    Returns:
        (21,V) float64 in FreiHAND order; rows are non-negative and sum to 1.
    """
    from scipy.optimize import nnls

    v = np.asarray(vertices, float)
    nv = len(v)
    rows = np.zeros((21, nv))
    for j in range(16):
        d = np.linalg.norm(v - joints[j], axis=1)
        near = d <= radius_factor * d.min()
        related = weights[:, j] + (weights[:, parents[j]] if parents[j] >= 0 else 0.0)
        sel = np.flatnonzero(near & (related > 0.05))
        if len(sel) < 4:
            sel = np.argsort(d, kind="stable")[:12]
        n = len(sel)
        # min |V^T w - J|^2 + s|w - 1/n|^2 + big (sum w - 1)^2, w >= 0
        big = 10.0
        a = np.vstack([v[sel].T, np.sqrt(smoothness) * np.eye(n) * d.min(),
                       big * np.ones((1, n)) * d.min()])
        b = np.concatenate([joints[j], np.sqrt(smoothness) * np.full(n, 1.0 / n) * d.min(),
                            [big * d.min()]])
        sol, _ = nnls(a, b)
        sol = sol / sol.sum()
        rows[j, sel] = sol
    full = np.concatenate([rows[:16], np.zeros((5, nv))])
    full[16 + np.arange(5), np.asarray(tip_ids)] = 1.0
    return full[list(MANO_TO_FREIHAND)]


def _shape_dirs(vertices, weights, joints, skel: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Linear shape directions (V,3,4) and (16,3,4) of the 4 shape parameters (per unit)."""
    s = SHAPE_STEP
    v = np.asarray(vertices, float)
    nv = len(v)
    vd = np.zeros((nv, 3, 4))
    jd = np.zeros((16, 3, 4))
    # 0 size: uniform scaling about the wrist joint (the origin).
    vd[:, :, 0] = s * v
    jd[:, :, 0] = s * joints
    # 1 finger length: each finger bone stretches along its axis, distal joints move outwards.
    # 2 palm width: the palm scales along z; fingers move sideways with their base.
    # 3 thickness: every bone's cross-section scales about its axis (palm: about y = 0).
    bone_end = np.zeros((16, 3))
    for f_i, finger in enumerate(FINGER_NAMES):
        base = 1 + 4 * f_i
        for k, j in enumerate(_FINGER_MANO[finger]):
            bone_end[j] = skel.keypoints[base + k + 1]
    per_bone_len = np.zeros((16, nv, 3))
    per_bone_width = np.zeros((16, nv, 3))
    per_bone_thick = np.zeros((16, nv, 3))
    per_bone_thick[0][:, 1] = s * v[:, 1]
    per_bone_width[0][:, 2] = s * v[:, 2]
    for finger in FINGER_NAMES:
        chain = _FINGER_MANO[finger]
        offset = np.zeros(3)   # how far this finger's joint moves when fingers lengthen
        root_z = joints[chain[0], 2]
        for j in chain:
            jd[j, :, 1] = offset
            jd[j, 2, 2] = s * root_z
            u = _unit(bone_end[j] - joints[j])
            rel = v - joints[j]
            along = rel @ u
            per_bone_len[j] = offset + s * along[:, None] * u
            per_bone_width[j][:, 2] = s * root_z
            per_bone_thick[j] = s * (rel - along[:, None] * u)
            offset = offset + s * (bone_end[j] - joints[j])
    for i, per_bone in ((1, per_bone_len), (2, per_bone_width), (3, per_bone_thick)):
        vd[:, :, i] = np.einsum("vj,jvc->vc", weights, per_bone)
    return vd, jd


# ------------------------------------------------------------------------------------------------
# Mesh checks
# ------------------------------------------------------------------------------------------------

def self_intersections(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Pairs of non-adjacent triangles that intersect (a mesh's self-intersections).

    Candidate pairs come from overlapping bounding spheres; a pair intersects when an edge of
    one triangle crosses the other (exact for non-coplanar triangles).

    Args:
        vertices: (V,3) float.
        faces: (F,3) int.

    Returns:
        (K,2) int64 face index pairs (i < j), empty (0,2) for a clean mesh.
    """
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    tri = v[f]
    cen = tri.mean(1)
    rad = np.linalg.norm(tri - cen[:, None], axis=2).max(1)
    pairs = cKDTree(cen).query_pairs(2 * rad.max(), output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((0, 2), np.int64)
    i, j = pairs[:, 0], pairs[:, 1]
    keep = np.linalg.norm(cen[i] - cen[j], axis=1) <= rad[i] + rad[j]
    shares = (f[i][:, :, None] == f[j][:, None, :]).any((1, 2))
    i, j = i[keep & ~shares], j[keep & ~shares]
    hit = _edges_cross(tri[i], tri[j]) | _edges_cross(tri[j], tri[i])
    return np.stack([i[hit], j[hit]], 1)


def _edges_cross(t1: np.ndarray, t2: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """(N,) whether any edge of triangles t1 (N,3,3) crosses triangles t2 (Moller-Trumbore)."""
    out = np.zeros(len(t1), bool)
    e1, e2 = t2[:, 1] - t2[:, 0], t2[:, 2] - t2[:, 0]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        o, d = t1[:, a], t1[:, b] - t1[:, a]
        p = np.cross(d, e2)
        det = (e1 * p).sum(1)
        ok = np.abs(det) > eps
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = o - t2[:, 0]
        u = (s * p).sum(1) * inv
        q = np.cross(s, e1)
        w = (d * q).sum(1) * inv
        t = (e2 * q).sum(1) * inv
        out |= ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t >= 0) & (t <= 1)
    return out


def mesh_checks(vertices: np.ndarray, faces: np.ndarray) -> dict:
    """Topology and quality numbers of a triangle mesh (used by the build and the tests).

    Args:
        vertices: (V,3) float, metres.
        faces: (F,3) int.

    Returns:
        dict with ``num_vertices``, ``num_faces``, ``watertight`` (bool), ``euler``
        (Euler characteristic, 2 for genus 0), ``components``, ``self_intersections`` (count),
        ``volume`` (m^3), ``edge_mean``/``edge_min``/``edge_max`` (m), ``edge_cv`` (std/mean)
        and ``min_angle_deg``.
    """
    import trimesh

    tm = trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces), process=False)
    e = tm.edges_unique_length
    return {
        "num_vertices": len(tm.vertices), "num_faces": len(tm.faces),
        "watertight": bool(tm.is_watertight), "euler": int(tm.euler_number),
        "components": int(trimesh.graph.connected_components(tm.edges, nodes=np.arange(
            len(tm.vertices)), min_len=1).__len__()),
        "self_intersections": int(len(self_intersections(tm.vertices, tm.faces))),
        "volume": float(tm.volume),
        "edge_mean": float(e.mean()), "edge_min": float(e.min()), "edge_max": float(e.max()),
        "edge_cv": float(e.std() / e.mean()),
        "min_angle_deg": float(np.degrees(tm.face_angles.min())),
    }


# ------------------------------------------------------------------------------------------------
# The template (build, save, load)
# ------------------------------------------------------------------------------------------------

@dataclass
class HandTemplate:
    """Everything :class:`HandModel` needs, as numpy arrays (right hand unless ``side``).

    Attributes:
        vertices: (V,3) float32 rest vertices, metres, template frame.
        faces: (F,3) int64, counter-clockwise seen from outside (outward normals).
        weights: (V,16) float32 skinning weights, MANO joint order, rows sum to 1.
        rest_joints: (16,3) float32 rest joints, MANO order, metres.
        tip_ids: (5,) int64 fingertip vertex ids, thumb..pinky.
        joint_regressor: (21,V) float32, FreiHAND order, rows non-negative and sum to 1.
        shape_dirs: (V,3,4) float32 vertex offsets per unit of each shape parameter.
        joint_shape_dirs: (16,3,4) float32 joint offsets per unit of each shape parameter.
        palmar: (V,) float32 in [0,1], 1 on the palm side (palm and palmar side of fingers).
        nail: (V,) float32 in [0,1], 1 on the finger nails.
        bone_radii: (16,) float32 mean radius of each bone's limb, metres (palm: half-thickness).
        keypoints: (21,3) float32 the skeleton's keypoints (FreiHAND order) = the rest keypoints.
        side: "right" or "left".
    """

    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    rest_joints: np.ndarray
    tip_ids: np.ndarray
    joint_regressor: np.ndarray
    shape_dirs: np.ndarray
    joint_shape_dirs: np.ndarray
    palmar: np.ndarray
    nail: np.ndarray
    bone_radii: np.ndarray
    keypoints: np.ndarray
    side: str = "right"

    def mirrored(self) -> HandTemplate:
        """The other side: z negated (:data:`MIRROR_AXIS`), faces re-oriented."""
        def mir(a, axis):
            a = np.array(a, copy=True)
            idx = [slice(None)] * a.ndim
            idx[axis] = MIRROR_AXIS
            a[tuple(idx)] *= -1
            return a

        return HandTemplate(
            vertices=mir(self.vertices, 1), faces=self.faces[:, ::-1].copy(),
            weights=self.weights.copy(), rest_joints=mir(self.rest_joints, 1),
            tip_ids=self.tip_ids.copy(), joint_regressor=self.joint_regressor.copy(),
            shape_dirs=mir(self.shape_dirs, 1), joint_shape_dirs=mir(self.joint_shape_dirs, 1),
            palmar=self.palmar.copy(), nail=self.nail.copy(), bone_radii=self.bone_radii.copy(),
            keypoints=mir(self.keypoints, 1),
            side="left" if self.side == "right" else "right")


def build_template(skeleton: Skeleton | None = None, target_scale: float = 0.74,
                   min_edge: float = 0.0045, max_edge: float = 0.0105, iterations: int = 6,
                   verbose: bool = False) -> HandTemplate:
    """Build the right-hand template from scratch (deterministic; a few seconds).

    Steps: skeleton -> union of capsules and palm (:func:`build_union_mesh`) -> isotropic remesh
    with edge length ``clip(target_scale * distance to nearest bone, min_edge, max_edge)`` ->
    fingertip vertices snapped onto the skeleton's tips -> skinning weights -> joint regressor,
    shape directions and palm / nail labels. Raises if the result is not a watertight, genus-0,
    single-component mesh free of self-intersections.

    Args:
        skeleton: the skeleton; :func:`neutral_skeleton` when ``None``.
        target_scale: edge length relative to the local limb radius.
        min_edge: shortest target edge length, metres.
        max_edge: longest target edge length, metres.
        iterations: remeshing iterations.
        verbose: print the step timings.

    Returns:
        The :class:`HandTemplate` of the right hand.

    Raises:
        RuntimeError: the built mesh fails one of the topology checks.
    """
    t0 = time.perf_counter()
    skel = neutral_skeleton() if skeleton is None else skeleton
    v0, f0 = build_union_mesh(skel)
    t1 = time.perf_counter()
    v, f = isotropic_remesh(v0, f0, sizing_field(skel, target_scale, min_edge, max_edge),
                            iterations=iterations)
    t2 = time.perf_counter()
    joints = _mano_rest_joints(skel)
    # Fingertips: the vertex nearest each skeleton tip, moved exactly onto it (it is on the skin).
    tip_ids = np.zeros(5, np.int64)
    for f_i in range(5):
        tip = skel.keypoints[4 + 4 * f_i]
        tip_ids[f_i] = int(np.argmin(np.linalg.norm(v - tip, axis=1)))
        v[tip_ids[f_i]] = tip
    reference = _reference_surface(v0, f0, 0.002)
    for _ in range(2):   # let the neighbours of the moved tips settle
        v = _relax(v, f, reference, fixed=tip_ids)
    # Rig the float32 vertices that get stored, so the weights can be recomputed from the asset.
    v = v.astype(np.float32).astype(np.float64)
    w = skinning_weights(v, f, skel)
    reg = joint_regressor_from_mesh(v, w, joints, tip_ids)
    vd, jd = _shape_dirs(v, w, joints, skel)
    normals = _vertex_normals(v, f)
    adj = _adjacency(f, len(v))
    palmar = np.clip(0.5 - 1.2 * normals[:, 1], 0.0, 1.0)
    for _ in range(2):
        palmar = 0.5 * palmar + 0.5 * (adj @ palmar) / np.asarray(adj.sum(1)).ravel()
    nail = np.zeros(len(v))
    for f_i in range(5):
        base = 1 + 4 * f_i
        tip = skel.keypoints[base + 3]
        u = _unit(tip - skel.keypoints[base + 2])
        along = (tip - v) @ u                   # distance behind the tip along the finger
        nail += (normals[:, 1] > 0.45) * np.clip(1.0 - along / (1.3 * _CM), 0, 1) \
            * (along < 1.25 * _CM) * (np.linalg.norm(v - tip, axis=1) < 1.6 * _CM)
    nail = np.clip(nail * 1.5, 0, 1)
    _, _, ids, rads = _bone_segments(skel)
    bone_radii = np.array([rads[ids == k].mean() for k in range(16)])
    t3 = time.perf_counter()
    checks = mesh_checks(v, f)
    if not (checks["watertight"] and checks["euler"] == 2 and checks["components"] == 1
            and checks["self_intersections"] == 0):
        raise RuntimeError(f"open hand build failed its topology checks: {checks}")
    if verbose:
        print(f"union {t1 - t0:.2f}s, remesh {t2 - t1:.2f}s, rig {t3 - t2:.2f}s; {checks}")
    f32 = np.float32
    return HandTemplate(
        vertices=v.astype(f32), faces=f.astype(np.int64), weights=w.astype(f32),
        rest_joints=joints.astype(f32), tip_ids=tip_ids, joint_regressor=reg.astype(f32),
        shape_dirs=vd.astype(f32), joint_shape_dirs=jd.astype(f32), palmar=palmar.astype(f32),
        nail=nail.astype(f32), bone_radii=bone_radii.astype(f32),
        keypoints=skel.keypoints.astype(f32), side="right")


def write_template_asset(path: str | os.PathLike | None = None, **build_kwargs) -> Path:
    """Build the template and save it (atomically) as the package-data asset.

    This is how ``handmesh_tutorial/assets/open_hand.npz`` was made:
    ``python -c "import handmesh_tutorial as hmt; hmt.hand.write_template_asset()"``.

    Args:
        path: output ``.npz``; :data:`ASSET_PATH` when ``None``.
        **build_kwargs: passed to :func:`build_template`.

    Returns:
        The written path.
    """
    path = Path(ASSET_PATH if path is None else path)
    tpl = build_template(**build_kwargs)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {fl.name: getattr(tpl, fl.name) for fl in fields(tpl) if fl.name != "side"}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp.npz")
    os.close(fd)
    try:
        np.savez_compressed(tmp, **arrays)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    load_template.cache_clear()
    return path


@functools.lru_cache(maxsize=4)
def load_template(path: str | os.PathLike | None = None) -> HandTemplate:
    """Load the right-hand template from the asset (cached; call ``.mirrored()`` for the left).

    Args:
        path: an ``.npz`` written by :func:`write_template_asset`; :data:`ASSET_PATH` if ``None``.

    Returns:
        The :class:`HandTemplate` (treat its arrays as read-only: they are shared).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: a key is missing.
    """
    path = Path(ASSET_PATH if path is None else path)
    if not path.exists():
        raise FileNotFoundError(f"open hand asset not found: {path} (rebuild it with "
                                "handmesh_tutorial.hand.write_template_asset())")
    with np.load(path, allow_pickle=False) as data:
        names = [fl.name for fl in fields(HandTemplate) if fl.name != "side"]
        missing = [n for n in names if n not in data]
        if missing:
            raise ValueError(f"{path}: missing keys {missing}")
        return HandTemplate(**{n: data[n] for n in names}, side="right")


# ------------------------------------------------------------------------------------------------
# Torch: rotations, linear blend skinning, mirroring
# ------------------------------------------------------------------------------------------------

def axis_angle_to_matrix(rotvec: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula, batched and differentiable (also at zero rotation).

    Args:
        rotvec: (...,3) axis-angle vectors, radians.

    Returns:
        (...,3,3) rotation matrices (exactly the identity for a zero vector).
    """
    theta2 = (rotvec * rotvec).sum(-1, keepdim=True)[..., None]           # (...,1,1)
    theta = torch.sqrt(theta2 + 1e-16)
    x, y, z = rotvec.unbind(-1)
    zero = torch.zeros_like(x)
    k = torch.stack([zero, -z, y, z, zero, -x, -y, x, zero], -1).reshape(*rotvec.shape[:-1], 3, 3)
    small = theta2 < 1e-8
    # sin(t)/t and (1-cos t)/t^2 with Taylor series near 0 (exact gradients at the identity).
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / (theta2 + 1e-30))
    eye = torch.eye(3, dtype=rotvec.dtype, device=rotvec.device)
    return eye + a * k + b * (k @ k)


def lbs(vertices: torch.Tensor, joints: torch.Tensor, rotations: torch.Tensor,
        weights: torch.Tensor, parents) -> tuple[torch.Tensor, torch.Tensor]:
    """Linear blend skinning along a kinematic tree.

    Args:
        vertices: (B,V,3) rest (shaped) vertices.
        joints: (B,J,3) rest joints.
        rotations: (B,J,3,3) local rotations; joint k's rotation is expressed in the rest-pose
            axes and applied about joint k, after its parent's (``rotations[:,0]`` = global).
        weights: (V,J) skinning weights.
        parents: (J,) parent indices, -1 for the root, parents before children.

    Returns:
        ``(posed vertices (B,V,3), world transforms (B,J,4,4))``; transform k maps the joint's
        rest frame (axes of the template, origin at joint k) to the posed world.
    """
    batch, n = rotations.shape[:2]
    rot_w = [rotations[:, 0]]
    pos_w = [joints[:, 0]]
    for k in range(1, n):
        p = int(parents[k])
        rot_w.append(rot_w[p] @ rotations[:, k])
        pos_w.append(pos_w[p] + (rot_w[p] @ (joints[:, k] - joints[:, p])[..., None])[..., 0])
    rot_w = torch.stack(rot_w, 1)                                          # (B,J,3,3)
    pos_w = torch.stack(pos_w, 1)                                          # (B,J,3)
    trans = pos_w - (rot_w @ joints[..., None])[..., 0]                    # t_k = p_k - R_k J_k
    blend_r = torch.einsum("vj,bjrc->bvrc", weights, rot_w)
    blend_t = torch.einsum("vj,bjc->bvc", weights, trans)
    posed = (blend_r @ vertices[..., None])[..., 0] + blend_t
    bottom = torch.zeros(batch, n, 1, 4, dtype=rot_w.dtype, device=rot_w.device)
    bottom[..., 0, 3] = 1
    transforms = torch.cat([torch.cat([rot_w, pos_w[..., None]], -1), bottom], -2)
    return posed, transforms


def mirror_points(points):
    """Mirror points (or vectors) between right and left: negate :data:`MIRROR_AXIS` (z).

    Args:
        points: (...,3) numpy array or torch tensor.

    Returns:
        The mirrored copy, same type and shape.
    """
    sign = [1.0, 1.0, 1.0]
    sign[MIRROR_AXIS] = -1.0
    if isinstance(points, torch.Tensor):
        return points * points.new_tensor(sign)
    return np.asarray(points) * np.asarray(sign)


def mirror_axis_angle(rotvec):
    """Mirror axis-angle rotations (pose or global_orient) between right and left.

    A rotation R seen in a mirror is M R M with M = diag(1,1,-1); its axis-angle vector is
    ``-M r``, i.e. ``(x, y, z) -> (-x, -y, z)``. Works for (...,3) and (B,45) layouts.

    Args:
        rotvec: (...,3) or (B,45) numpy array or torch tensor, radians.

    Returns:
        The mirrored copy, same type and shape.
    """
    sign = [-1.0, -1.0, -1.0]
    sign[MIRROR_AXIS] = 1.0
    if isinstance(rotvec, torch.Tensor):
        shp = rotvec.shape
        return (rotvec.reshape(*shp[:-1], -1, 3) * rotvec.new_tensor(sign)).reshape(shp)
    r = np.asarray(rotvec)
    return (r.reshape(*r.shape[:-1], -1, 3) * np.asarray(sign)).reshape(r.shape)


# ------------------------------------------------------------------------------------------------
# Example poses
# ------------------------------------------------------------------------------------------------

def flexion_axes(side: str = "right") -> np.ndarray:
    """Unit rotation axes that curl each articulated joint towards the palm (rest frame).

    For the four fingers the axis is ``finger direction x palm normal (-y)``; for the thumb the
    thumb direction crossed with a direction towards the palm centre, so a positive angle about
    the axis flexes the joint.

    Args:
        side: ``"right"`` or ``"left"`` (the left axes are the mirrored right axes).

    Returns:
        (15,3) float64, MANO order of the articulated joints (index1..thumb3).
    """
    skel = neutral_skeleton()
    kp = skel.keypoints
    axes = np.zeros((15, 3))
    palm_normal = np.array([0.0, -1.0, 0.0])
    for f_i, finger in enumerate(FINGER_NAMES):
        base = 1 + 4 * f_i
        for k, j in enumerate(_FINGER_MANO[finger]):
            d = _unit(kp[base + k + 1] - kp[base + k])
            if finger == "thumb":
                axes[j - 1] = _unit(np.cross(d, _unit([0.0, -0.5, 1.0])))
            else:
                axes[j - 1] = _unit(np.cross(d, palm_normal))
    return axes if side == "right" else mirror_axis_angle(axes)


def example_pose(name: str, side: str = "right") -> np.ndarray:
    """A few named poses for figures and tests.

    Args:
        name: ``"flat"`` (the rest pose), ``"fist"``, ``"point"`` (index extended),
            ``"pinch"`` (thumb and index tips close) or ``"spread"`` (fingers fanned out).
        side: ``"right"`` or ``"left"``.

    Returns:
        (15,3) float32 axis-angle pose, MANO order.

    Raises:
        ValueError: unknown name or side.
    """
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    axes = flexion_axes("right")
    flex = np.zeros(15)
    pose = np.zeros((15, 3))
    fing = {f: [j - 1 for j in _FINGER_MANO[f]] for f in FINGER_NAMES}
    if name == "flat":
        pass
    elif name == "fist":
        for f in ("index", "middle", "ring", "pinky"):
            flex[fing[f]] = np.deg2rad([80, 95, 60])
        flex[fing["thumb"]] = np.deg2rad([45, 35, 40])
    elif name == "point":
        for f in ("middle", "ring", "pinky"):
            flex[fing[f]] = np.deg2rad([80, 95, 60])
        flex[fing["index"]] = np.deg2rad([5, 5, 5])
        flex[fing["thumb"]] = np.deg2rad([45, 35, 40])
    elif name == "pinch":
        flex[fing["index"]] = np.deg2rad([40, 45, 25])
        for f in ("middle", "ring", "pinky"):
            flex[fing[f]] = np.deg2rad([20, 25, 15])
        flex[fing["thumb"]] = np.deg2rad([25, 20, 15])
    elif name == "spread":
        for f, ang in zip(("index", "middle", "ring", "pinky"), (-12, -3, 8, 18), strict=True):
            pose[fing[f][0]] = np.deg2rad(ang) * np.array([0.0, -1.0, 0.0])  # +: towards pinky
        pose[fing["thumb"][0]] = np.deg2rad(-15) * _unit([0.0, -1.0, 1.2])
    else:
        raise ValueError(f"unknown pose name {name!r}; expected flat, fist, point, pinch, spread")
    pose = pose + flex[:, None] * axes
    pose = pose if side == "right" else mirror_axis_angle(pose)
    return pose.astype(np.float32)


def random_pose(rng: np.random.Generator | int | None = None, batch: int = 1,
                side: str = "right", max_flexion_deg: float = 90.0,
                max_spread_deg: float = 10.0) -> np.ndarray:
    """Random, loosely plausible poses: flexion in [0, max] per joint, small MCP sideways spread.

    Not anatomically limited (see ``lcs.py`` for joint limits); meant for figures and tests.

    Args:
        rng: generator or seed.
        batch: number of poses B.
        side: ``"right"`` or ``"left"``.
        max_flexion_deg: largest flexion per joint, degrees.
        max_spread_deg: largest sideways rotation of the MCP joints, degrees.

    Returns:
        (B,15,3) float32 axis-angle poses, MANO order.
    """
    gen = np.random.default_rng(rng)
    axes = flexion_axes("right")
    flex = gen.uniform(0.0, np.deg2rad(max_flexion_deg), size=(batch, 15))
    pose = flex[..., None] * axes
    spread = gen.uniform(-1, 1, size=(batch, 5)) * np.deg2rad(max_spread_deg)
    for f_i, finger in enumerate(FINGER_NAMES):
        pose[:, _FINGER_MANO[finger][0] - 1, 1] += spread[:, f_i]
    pose = pose if side == "right" else mirror_axis_angle(pose)
    return pose.astype(np.float32)


# ------------------------------------------------------------------------------------------------
# The model
# ------------------------------------------------------------------------------------------------

@dataclass
class HandOutput:
    """Output of :class:`HandModel` (and of :class:`~handmesh_tutorial.mano.ManoModel`).

    Attributes:
        vertices: (B,V,3) float32, metres.
        joints: (B,21,3) float32, metres, FreiHAND order (16 posed joints + 5 tip vertices).
        joints_mano: (B,16,3) float32, metres, posed skeleton joints in MANO order.
        transforms: (B,16,4,4) float32 world transform of each joint: rotation = the joint's
            accumulated rotation (its rest frame has the template axes), translation = its
            posed position (``transl`` included).
    """

    vertices: torch.Tensor
    joints: torch.Tensor
    joints_mano: torch.Tensor | None = None
    transforms: torch.Tensor | None = None


class HandModel(nn.Module):
    """The open hand as a torch module: pose and shape in, mesh and 21 keypoints out.

    Loads the shipped template (no rebuild). Right hand by default; the left hand is its exact
    mirror (z negated, see the module docstring for mirroring poses). Parameters follow MANO's
    conventions: axis-angle per joint, each joint's rotation expressed in the rest-pose axes and
    relative to its parent, applied about the joint; ``global_orient`` rotates the whole hand
    about the wrist joint (which sits at the origin); ``transl`` is added last. No pose-dependent
    corrective shapes (plain LBS).

    Attributes (numpy, read-only by convention):
        faces: (F,3) int64. template_vertices: (V,3) float32 metres. skinning_weights: (V,16).
        rest_joints: (16,3) MANO order. fingertip_vertex_ids: (5,) thumb..pinky.
        parents: (16,) int64. joint_regressor: (21,V) float32 (FreiHAND order; rows sum to 1,
        reproduces the rest keypoints to < 1 mm). shape_dirs: (V,3,4). bone_radii: (16,).
        palmar: (V,) palm-side label in [0,1]. side: "right" | "left".

    Example:
        >>> model = HandModel("right")
        >>> out = model(pose=torch.zeros(2, 15, 3))
        >>> out.vertices.shape, out.joints.shape
        (torch.Size([2, 799, 3]), torch.Size([2, 21, 3]))
    """

    num_joints: int = 16
    num_shape_params: int = len(SHAPE_PARAM_NAMES)

    def __init__(self, side: str = "right", template: HandTemplate | None = None):
        """Args:
            side: ``"right"`` or ``"left"``.
            template: a right- or left-hand template to use instead of the shipped asset (for a
                rebuilt or modified hand); mirrored when its side differs from ``side``.

        Raises:
            ValueError: unknown side.
        """
        super().__init__()
        if side not in ("right", "left"):
            raise ValueError(f"side must be 'right' or 'left', got {side!r}")
        tpl = load_template() if template is None else template
        if tpl.side != side:
            tpl = tpl.mirrored()
        self.side = side
        self.template = tpl
        self.faces = np.asarray(tpl.faces, np.int64)
        self.parents = np.asarray(MANO_PARENTS, np.int64)
        self.template_vertices = np.asarray(tpl.vertices, np.float32)
        self.skinning_weights = np.asarray(tpl.weights, np.float32)
        self.rest_joints = np.asarray(tpl.rest_joints, np.float32)
        self.fingertip_vertex_ids = np.asarray(tpl.tip_ids, np.int64)
        self.joint_regressor = np.asarray(tpl.joint_regressor, np.float32)
        self.shape_dirs = np.asarray(tpl.shape_dirs, np.float32)
        self.bone_radii = np.asarray(tpl.bone_radii, np.float32)
        self.palmar = np.asarray(tpl.palmar, np.float32)
        f32 = torch.float32
        self.register_buffer("v_template", torch.as_tensor(self.template_vertices, dtype=f32))
        self.register_buffer("weights", torch.as_tensor(self.skinning_weights, dtype=f32))
        self.register_buffer("j_template", torch.as_tensor(self.rest_joints, dtype=f32))
        self.register_buffer("v_shapedirs", torch.as_tensor(self.shape_dirs, dtype=f32))
        self.register_buffer("j_shapedirs", torch.as_tensor(tpl.joint_shape_dirs, dtype=f32))
        self.register_buffer("tip_ids", torch.as_tensor(self.fingertip_vertex_ids))
        self.register_buffer("to_freihand", torch.as_tensor(MANO_TO_FREIHAND, dtype=torch.long))

    @property
    def num_vertices(self) -> int:
        """Number of mesh vertices V."""
        return int(self.template_vertices.shape[0])

    @property
    def rest_keypoints(self) -> np.ndarray:
        """(21,3) float32 rest keypoints in FreiHAND order (joints + tip vertices), metres."""
        tips = self.template_vertices[self.fingertip_vertex_ids]
        return np.concatenate([self.rest_joints, tips])[list(MANO_TO_FREIHAND)]

    # -- inputs -----------------------------------------------------------------------------------
    def _tensor(self, x, name: str, shapes: tuple[tuple[int, ...], ...]):
        if x is None:
            return None
        # float32 (or the module's dtype after .double()), on the module's device
        t = torch.as_tensor(x, device=self.v_template.device).to(self.v_template.dtype)
        for shp in shapes:
            if t.dim() == len(shp) + 1 and tuple(t.shape[1:]) == shp:
                return t
        want = " or ".join("(B," + ",".join(map(str, s)) + ")" for s in shapes)
        raise ValueError(f"{name} must have shape {want}, got {tuple(t.shape)}")

    def forward(self, pose=None, shape=None, global_orient=None, transl=None) -> HandOutput:
        """Pose and shape the hand.

        Args:
            pose: (B,15,3) or (B,45) axis-angle (radians) of the 15 articulated joints in MANO
                order (index1..thumb3): joint k's rotation in the rest-pose axes, relative to its
                parent, about the joint. ``None`` = flat rest pose.
            shape: (B,4) shape parameters :data:`SHAPE_PARAM_NAMES` (size, finger_length,
                palm_width, thickness); 0 = template, each unit = 15 %, sensible range [-1,1].
            global_orient: (B,3) axis-angle of the whole hand about the wrist joint.
            transl: (B,3) translation, metres, added last.

        Returns:
            :class:`HandOutput` with ``vertices`` (B,V,3), ``joints`` (B,21,3) FreiHAND order,
            ``joints_mano`` (B,16,3), ``transforms`` (B,16,4,4); float32, metres. The batch size
            comes from whichever input is given (1 when none).

        Raises:
            ValueError: an input has the wrong shape or batch sizes disagree.
        """
        pose = self._tensor(pose, "pose", ((15, 3), (45,)))
        shape = self._tensor(shape, "shape", ((self.num_shape_params,),))
        go = self._tensor(global_orient, "global_orient", ((3,),))
        transl = self._tensor(transl, "transl", ((3,),))
        sizes = {t.shape[0] for t in (pose, shape, go, transl) if t is not None}
        if len(sizes) > 1:
            raise ValueError("inconsistent batch sizes among pose/shape/global_orient/transl: "
                             f"{sorted(sizes)}")
        batch = sizes.pop() if sizes else 1
        dev, f32 = self.v_template.device, self.v_template.dtype
        if pose is None:
            pose = torch.zeros(batch, 15, 3, device=dev, dtype=f32)
        if go is None:
            go = torch.zeros(batch, 3, device=dev, dtype=f32)
        full = torch.cat([go[:, None], pose.reshape(batch, 15, 3)], 1)         # (B,16,3)
        verts = self.v_template.expand(batch, -1, -1)
        joints = self.j_template.expand(batch, -1, -1)
        if shape is not None:
            verts = verts + torch.einsum("vcs,bs->bvc", self.v_shapedirs, shape)
            joints = joints + torch.einsum("jcs,bs->bjc", self.j_shapedirs, shape)
        posed, transforms = lbs(verts, joints, axis_angle_to_matrix(full), self.weights,
                                self.parents)
        if transl is not None:
            posed = posed + transl[:, None]
            transforms = torch.cat([transforms[..., :3, :3],
                                    transforms[..., :3, 3:] + transl[:, None, :, None],
                                    ], -1)
            transforms = torch.cat([transforms, self._bottom(batch)], -2)
        joints_mano = transforms[..., :3, 3]
        tips = posed[:, self.tip_ids]
        joints21 = torch.cat([joints_mano, tips], 1)[:, self.to_freihand]
        return HandOutput(vertices=posed, joints=joints21, joints_mano=joints_mano,
                          transforms=transforms)

    def _bottom(self, batch: int) -> torch.Tensor:
        b = torch.zeros(batch, 16, 1, 4, device=self.v_template.device,
                        dtype=self.v_template.dtype)
        b[..., 0, 3] = 1
        return b

    # -- appearance ------------------------------------------------------------------------------
    def vertex_colors(self, tone=None, rng: np.random.Generator | int | None = None,
                      variation: float = 0.04) -> np.ndarray:
        """Per-vertex skin colour: a skin tone, lighter palm, pinkish nails, subtle blotches.

        Args:
            tone: index into :data:`SKIN_TONES`, an RGB triple in [0,1], or ``None``: a random
                palette tone when ``rng`` is given, else tone 1.
            rng: ``numpy.random.Generator`` or seed for the tone choice and the variation;
                ``None`` = fixed seed 0 (same colours every call).
            variation: amplitude of the low-frequency brightness variation.

        Returns:
            (V,3) float32 RGB in [0,1].

        Raises:
            ValueError: bad tone index or triple.
        """
        gen = np.random.default_rng(0 if rng is None else rng)
        if tone is None:
            tone = int(gen.integers(len(SKIN_TONES))) if rng is not None else 1
        if isinstance(tone, (int, np.integer)):
            if not 0 <= int(tone) < len(SKIN_TONES):
                raise ValueError(f"tone index must be in [0,{len(SKIN_TONES) - 1}], got {tone}")
            base = np.asarray(SKIN_TONES[int(tone)])
        else:
            base = np.asarray(tone, dtype=float).reshape(-1)
            if base.shape != (3,) or base.min() < 0 or base.max() > 1:
                raise ValueError(f"tone must be an index or an RGB triple in [0,1], got {tone!r}")
        palm = base + (1.0 - base) * np.array([0.30, 0.26, 0.24])            # palm lighter
        palm = palm * np.array([1.0, 0.97, 0.97])                            # and a bit pinker
        nail = base + (1.0 - base) * np.array([0.45, 0.30, 0.30])
        p = self.palmar[:, None]
        col = (1 - p) * base + p * palm
        n = self.template.nail[:, None]
        col = (1 - n) * col + n * nail
        noise = gen.standard_normal(self.num_vertices)
        adj = _adjacency(self.faces, self.num_vertices)
        deg = np.asarray(adj.sum(1)).ravel()
        for _ in range(4):                       # smooth the noise into soft blotches
            noise = 0.5 * noise + 0.5 * (adj @ noise) / deg
        noise /= noise.std() + 1e-12
        col = col * (1.0 + variation * noise[:, None])
        return np.clip(col, 0.0, 1.0).astype(np.float32)
