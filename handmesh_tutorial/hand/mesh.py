"""Mesh tools of the hand: the keypoint regressor, quality checks and the forearm for rendering.

[`joint_regressor_from_mesh`][handmesh_tutorial.hand.mesh.joint_regressor_from_mesh] builds the
(21,V) regressor that reads keypoints off a mesh;
[`mesh_checks`][handmesh_tutorial.hand.mesh.mesh_checks]
and [`self_intersections`][handmesh_tutorial.hand.mesh.self_intersections] measure a template's
topology and quality (used by the build and the tests);
[`forearm_mesh`][handmesh_tutorial.hand.mesh.forearm_mesh] continues the wrist into a forearm tube
(scenery for rendering, not part of the model), and
[`wrist_seam_normals`][handmesh_tutorial.hand.mesh.wrist_seam_normals] and
[`forearm_colors`][handmesh_tutorial.hand.mesh.forearm_colors] make the two shade and colour as
one surface at the wrist. Vertices in metres, faces (F,3) int.

Taught in notebook 01 (the hand model); the forearm appears in notebook 05 (rendering).
"""

from __future__ import annotations

import numpy as np

from ._common import _unit
from .joints import MANO_PARENTS, MANO_TO_FREIHAND

__all__ = ["self_intersections", "mesh_checks", "forearm_mesh", "forearm_colors"]


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


def wrist_seam_normals(hand_vertices: np.ndarray, hand_faces: np.ndarray, cap_faces,
                       loop: np.ndarray, forearm_vertices: np.ndarray,
                       forearm_faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertex normals of a hand and its forearm that agree along the wrist, for rendering.

    A renderer that computes each mesh's normals on its own draws a visible ring at the wrist:
    there the hand's normals also average the cap's faces (which point along the arm) and the
    forearm's first ring sees only the tube. Here the wrist loop's vertices (``loop`` on the hand,
    the first ``len(loop)`` vertices of the forearm, as
    [`forearm_mesh`][handmesh_tutorial.hand.mesh.forearm_mesh] makes them) get one normal: the
    mean of the two sides' normals, each side's the area-weighted normal of its own faces next to
    the vertex (the two sides count equally, since the tube's faces are several times larger
    than the hand's). The cap's faces count nowhere; with the forearm in place the cap is inside
    and never seen. Every other vertex gets its area-weighted normal.

    Args:
        hand_vertices: (V,3) the posed hand, metres (any frame, same as the forearm).
        hand_faces: (F,3) the hand's faces, cap included.
        cap_faces: (F,) bool mask of the cap's faces in ``hand_faces``.
        loop: (L,) the wrist loop's vertex ids on the hand, in the forearm's ring order.
        forearm_vertices: (N,3) the forearm, whose first L vertices lie on the loop.
        forearm_faces: (M,3) the forearm's faces.

    Returns:
        ``(hand normals (V,3), forearm normals (N,3))``, unit length.

    Raises:
        ValueError: the forearm's first ring is not the hand's wrist loop.
    """
    hv = np.asarray(hand_vertices, float)
    fv = np.asarray(forearm_vertices, float)
    loop = np.asarray(loop, np.int64)
    cap = np.asarray(cap_faces, bool)
    hf = np.asarray(hand_faces, np.int64)
    if cap.shape != (len(hf),):
        raise ValueError(f"cap_faces must be a ({len(hf)},) mask, got shape {cap.shape}")
    L = len(loop)
    if len(fv) < L or np.abs(fv[:L] - hv[loop]).max() > 1e-9:
        raise ValueError("the forearm's first ring must be the hand's wrist loop, vertex for "
                         "vertex (see forearm_mesh)")
    from ..render import _vertex_normals  # the renderer's own rule (render imports no hand)

    skin = hf[~cap]
    hand_unit = _vertex_normals(hv, skin)
    # the cap's centre (and any vertex only the cap uses) keeps the cap's own normal
    only_cap = np.ones(len(hv), bool)
    only_cap[skin.ravel()] = False
    if only_cap.any():
        hand_unit[only_cap] = _vertex_normals(hv, hf[cap])[only_cap]
    arm_unit = _vertex_normals(fv, np.asarray(forearm_faces, np.int64))
    rim = hand_unit[loop] + arm_unit[:L]
    rim /= np.linalg.norm(rim, axis=1, keepdims=True)
    hand_unit[loop] = rim
    arm_unit[:L] = rim
    return hand_unit, arm_unit


def forearm_colors(loop_colors: np.ndarray, rings: int = 8, smooth: float = 2.0) -> np.ndarray:
    """sRGB colours of a forearm that continue the hand's colours at the wrist.

    The first ring takes the wrist loop's colours as they are (no step at the seam); the further
    rings take them smoothed around the arm (a circular Gaussian of ``smooth`` loop vertices), so
    the lighter inner side of the wrist continues along the arm as it does on a real forearm,
    while a blotch of the hand's skin does not become a stripe. The far end's centre gets the
    loop's mean. Layout as in [`forearm_mesh`][handmesh_tutorial.hand.mesh.forearm_mesh].

    Args:
        loop_colors: (L,3) sRGB colours of the wrist loop's vertices, in the forearm's ring order.
        rings: rings after the first (as in ``forearm_mesh``).
        smooth: standard deviation of the smoothing around the arm, in loop vertices (> 0).

    Returns:
        (L*(rings+1)+1, 3) colours in [0,1].
    """
    c = np.asarray(loop_colors, float)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"loop_colors must have shape (L, 3), got {c.shape}")
    if not smooth > 0:
        raise ValueError(f"smooth must be > 0, got {smooth}")
    L = len(c)
    d = np.arange(L)[:, None] - np.arange(L)[None, :]
    d = np.minimum(np.abs(d), L - np.abs(d))          # distance around the loop
    w = np.exp(-0.5 * (d / smooth) ** 2)
    smoothed = (w @ c) / w.sum(1, keepdims=True)
    rows = [c] + [smoothed] * rings + [c.mean(0, keepdims=True)]
    return np.clip(np.concatenate(rows), 0.0, 1.0)
