"""Mesh tools of the hand: the keypoint regressor, quality checks and the forearm for rendering.

[`joint_regressor_from_mesh`][handmesh_tutorial.hand.mesh.joint_regressor_from_mesh] builds the
(21,V) regressor that reads keypoints off a mesh;
[`mesh_checks`][handmesh_tutorial.hand.mesh.mesh_checks]
and [`self_intersections`][handmesh_tutorial.hand.mesh.self_intersections] measure a template's
topology and quality (used by the build and the tests);
[`forearm_mesh`][handmesh_tutorial.hand.mesh.forearm_mesh] continues the wrist into a forearm tube
(scenery for rendering, not part of the model). Vertices in metres, faces (F,3) int.

Taught in notebook 01 (the hand model); the forearm appears in notebook 05 (rendering).
"""

from __future__ import annotations

import numpy as np

from ._common import _unit
from .joints import MANO_PARENTS, MANO_TO_FREIHAND

__all__ = ["joint_regressor_from_mesh", "self_intersections", "mesh_checks", "forearm_mesh"]


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

