"""The paper's local coordinate system (LCS) of each joint, for any articulated mesh.

``z`` points from the joint to the next point along its chain, ``x`` towards a mesh vertex that
follows the joint's flexion (projected off ``z``), ``y = z × x``:
[`local_frames`][handmesh_tutorial.lcs.frames.local_frames] builds the (J,3,3) frames (columns
``x, y, z``) and [`select_flexion_vertices`][handmesh_tutorial.lcs.frames.select_flexion_vertices]
picks the vertices. Positions in metres.

Taught in notebook 02 (local coordinate systems); the generator (notebook 04) samples poses with it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["local_frames"]


def _unit(v: np.ndarray, what: str) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        bad = np.flatnonzero(n.reshape(-1) < 1e-12).tolist()
        raise ValueError(f"{what} has zero length for joint(s) {bad}")
    return v / n


def local_frames(joints, children, flexion_points) -> np.ndarray:
    """The paper's LCS of each joint, for any articulated mesh.

    Args:
        joints: (J,3) joint positions in the rest pose (metres).
        children: either (J,) int indices into ``joints`` of each joint's next joint along the
            chain, or (J,3) positions of that next point (e.g. a fingertip).
        flexion_points: (J,3) points (usually mesh vertices ``v_i``) whose direction from the
            joint follows the joint's flexion direction.

    Returns:
        (J,3,3) float64 rotation matrices whose *columns* are ``x``, ``y``, ``z``.

    Raises:
        ValueError: shapes disagree, a child coincides with its joint, or a flexion point lies
            on the joint's ``z`` axis.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 2 or joints.shape[1] != 3:
        raise ValueError(f"joints must have shape (J,3), got {joints.shape}")
    children = np.asarray(children)
    if children.ndim == 1 and np.issubdtype(children.dtype, np.integer):
        if children.shape[0] != len(joints) or children.min() < 0 or \
                children.max() >= len(joints):
            raise ValueError(f"children must be {len(joints)} indices in 0..{len(joints) - 1}, "
                             f"got {children.tolist()}")
        child_pts = joints[children]
    else:
        child_pts = np.asarray(children, dtype=np.float64)
    flex = np.asarray(flexion_points, dtype=np.float64)
    for name, arr in (("children", child_pts), ("flexion_points", flex)):
        if arr.shape != joints.shape:
            raise ValueError(f"{name} must have shape {joints.shape}, got {arr.shape}")
    z = _unit(child_pts - joints, "z (child - joint)")
    x_hat = flex - joints
    x = x_hat - np.sum(x_hat * z, -1, keepdims=True) * z  # projection onto the plane ⟂ z
    x = _unit(x, "x (flexion point projected off z)")
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)


def select_flexion_vertices(vertices, joints, child_points, directions, *, weights=None,
                            joint_ids=None, parents=None, slab: float = 0.25) -> np.ndarray:
    """Pick, per joint, the mesh vertex that best follows a flexion direction.

    The rule: among candidate vertices (dominant skinning joint is the joint or its parent, when
    ``weights`` are given; within ``slab`` x bone length of the joint's cross-section plane),
    take the one whose offset from the joint, projected off the bone axis, has the largest
    cosine with ``directions``. The constraints are dropped (weights first, then the slab) if
    they leave no candidate.

    Args:
        vertices: (V,3) rest-pose mesh vertices.
        joints: (J,3) joint positions.
        child_points: (J,3) next point along the chain of each joint (defines ``z``).
        directions: (J,3) desired flexion directions (need not be unit or ⟂ ``z``).
        weights: optional (V,K) skinning weights over the model's K joints.
        joint_ids: (J,) index of each joint among the K skinning joints (with ``weights``).
        parents: (K,) parent of each skinning joint (with ``weights``).
        slab: half-thickness of the candidate slab as a fraction of the bone length.

    Returns:
        (J,) int64 vertex ids.
    """
    verts = np.asarray(vertices, dtype=np.float64)
    joints = np.asarray(joints, dtype=np.float64)
    z = _unit(np.asarray(child_points, dtype=np.float64) - joints, "bone")
    bone = np.linalg.norm(np.asarray(child_points, dtype=np.float64) - joints, axis=-1)
    d = np.asarray(directions, dtype=np.float64)
    d = _unit(d - np.sum(d * z, -1, keepdims=True) * z, "flexion direction off z")
    if weights is not None and (joint_ids is None or parents is None):
        raise ValueError("select_flexion_vertices: weights need joint_ids and parents too")
    owner = None if weights is None else np.argmax(np.asarray(weights), axis=1)
    ids = np.empty(len(joints), dtype=np.int64)
    for i in range(len(joints)):
        off = verts - joints[i]
        along = off @ z[i]
        perp = off - along[:, None] * z[i]
        cos = (perp @ d[i]) / (np.linalg.norm(perp, axis=1) + 1e-12)
        in_slab = np.abs(along) <= slab * bone[i]
        masks = []
        if owner is not None:
            k = int(joint_ids[i])
            mine = (owner == k) | (owner == int(parents[k])) if parents[k] >= 0 else owner == k
            masks.append(mine & in_slab)
        masks += [in_slab, np.ones(len(verts), bool)]
        mask = next(m for m in masks if m.any())
        ids[i] = np.flatnonzero(mask)[np.argmax(cos[mask])]
    return ids

