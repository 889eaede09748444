"""Surface-quality metrics for predicted meshes: roughness and flipped faces.

Vertex errors (MPVPE) say how far a predicted mesh is from the truth but not whether it *looks*
like a hand: a prediction a few millimetres off everywhere can be smooth, or a crumpled sheet of
foil with the same error. Two metrics that see the difference, both computed per sample on meshes
with the same topology (vertex ``i`` of the prediction corresponds to vertex ``i`` of the truth):

* [`roughness_deg`][handmesh_tutorial.metrics.surface.roughness_deg]: the mean absolute difference
  between the predicted and the true *signed dihedral angle* (bending angle) over the interior
  edges, in degrees. Invariant to rigid motion and uniform scale of either mesh; 0 for a copy of the
  truth.
* [`flipped_face_fraction`][handmesh_tutorial.metrics.surface.flipped_face_fraction]: after a
  per-sample Procrustes alignment with scale (no reflection by default), the fraction of faces whose
  normal points away from the true face's normal (negative dot product).

The signed dihedral angle of an edge shared by faces ``f1`` and ``f2`` with unit normals ``n1``,
``n2`` is ``atan2((n1 x n2) . e, n1 . n2)``, ``e`` the unit edge direction as it runs in ``f1``:
0 for a flat pair, positive for a convex fold and negative for a concave one when the faces are
consistently oriented (the sign does not depend on which face is called ``f1``). Its difference
is wrapped to ``[0, 180]`` degrees.

Both functions take numpy arrays or torch tensors (detached, computed in float64 numpy) and
return numpy arrays ``(B,)``.

Taught in notebook 07 ("Multi-path mesh decoder", roughness of the decoders' meshes); used in the
tables of notebook 10 (ablation).
"""

from __future__ import annotations

import numpy as np

__all__ = ["face_normals", "dihedral_angles", "roughness_deg", "flipped_face_fraction"]


def _as_batch(x, name: str) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().double().numpy()
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[-1] != 3:
        raise ValueError(f"{name} must be (B, V, 3) or (V, 3), got shape {a.shape}")
    return a


def _as_faces(faces, num_vertices: int) -> np.ndarray:
    if hasattr(faces, "detach"):
        faces = faces.detach().cpu().numpy()
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be (F, 3) integers, got {f.shape} {f.dtype}")
    if f.size and (f.min() < 0 or f.max() >= num_vertices):
        raise ValueError(f"face ids must lie in [0, {num_vertices}), got "
                         f"[{f.min()}, {f.max()}]")
    return f.astype(np.int64)


def interior_edges(faces) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The edges shared by exactly two faces.

    Args:
        faces: ``(F, 3)`` int triangles.

    Returns:
        ``(edges, face_pairs, edge_in_first)``: ``edges`` ``(E, 2)`` vertex ids ``(a, b)`` in the
        order the edge runs in the first face, ``face_pairs`` ``(E, 2)`` the two face ids,
        ``edge_in_first`` ``(E,)`` the edge's slot in the first face (``k`` in 0..2: the
        edge runs from corner ``k`` to corner ``k + 1``). Edges on the boundary
        (one face) or non-manifold edges (three or more) are left out.
    """
    f = np.asarray(faces, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must be (F, 3), got {f.shape}")
    a = f.reshape(-1)
    b = f[:, [1, 2, 0]].reshape(-1)
    face = np.repeat(np.arange(len(f)), 3)
    slot = np.tile(np.arange(3), len(f))
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    keep = counts[inverse] == 2
    idx = np.flatnonzero(keep)
    idx = idx[np.argsort(inverse[idx], kind="stable")]  # the two half-edges of an edge adjacent
    first, second = idx[0::2], idx[1::2]
    edges = np.stack([a[first], b[first]], axis=1)
    pairs = np.stack([face[first], face[second]], axis=1)
    return edges, pairs, slot[first]


def face_normals(vertices, faces) -> np.ndarray:
    """Unit face normals (right-hand rule over the corner order).

    Args:
        vertices: ``(B, V, 3)`` or ``(V, 3)``, any length unit.
        faces: ``(F, 3)`` int.

    Returns:
        ``(B, F, 3)`` float64 unit normals (zero for degenerate faces).
    """
    v = _as_batch(vertices, "vertices")
    f = _as_faces(faces, v.shape[1])
    n = np.cross(v[:, f[:, 1]] - v[:, f[:, 0]], v[:, f[:, 2]] - v[:, f[:, 0]])
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


def dihedral_angles(vertices, faces, edges=None) -> np.ndarray:
    """Signed dihedral (bending) angle of every interior edge.

    Args:
        vertices: ``(B, V, 3)`` or ``(V, 3)``.
        faces: ``(F, 3)`` int.
        edges: precomputed [`interior_edges`][handmesh_tutorial.metrics.surface.interior_edges] of
            ``faces`` (optional).

    Returns:
        ``(B, E)`` float64 angles in radians, in ``(-pi, pi]``; 0 where the two faces are coplanar
        (the ``E`` interior edges in the order of
        [`interior_edges`][handmesh_tutorial.metrics.surface.interior_edges]).
    """
    v = _as_batch(vertices, "vertices")
    f = _as_faces(faces, v.shape[1])
    e, pairs, _ = interior_edges(f) if edges is None else edges
    n = face_normals(v, f)
    n1, n2 = n[:, pairs[:, 0]], n[:, pairs[:, 1]]
    d = v[:, e[:, 1]] - v[:, e[:, 0]]
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
    sin = np.einsum("bek,bek->be", np.cross(n1, n2), d)
    cos = np.einsum("bek,bek->be", n1, n2)
    return np.arctan2(sin, cos)


def roughness_deg(pred_vertices, gt_vertices, faces) -> np.ndarray:
    """Mean absolute difference of the signed dihedral angles to the ground truth, in degrees.

    A smooth prediction that bends where the true hand bends scores near 0; a crumpled one
    (spikes, folds, zig-zag) scores tens of degrees even at a small vertex error. Invariant to
    rigid motion and uniform scale of either mesh (no alignment is needed). A mirrored copy of
    the truth scores ``mean min(2 |angle|, 360 - 2 |angle|)`` (mirroring flips the sign of every
    bending angle).

    Args:
        pred_vertices: ``(B, V, 3)`` (or ``(V, 3)``) predicted vertices, any length unit.
        gt_vertices: ``(B, V, 3)`` (or ``(V, 3)``) ground-truth vertices, same topology.
        faces: ``(F, 3)`` int triangles shared by both meshes.

    Returns:
        ``(B,)`` float64 mean over interior edges of ``|angle_pred - angle_gt|`` wrapped to
        ``[0, 180]``, degrees.

    Raises:
        ValueError: shapes differ, or the mesh has no interior edge.
    """
    p = _as_batch(pred_vertices, "pred_vertices")
    g = _as_batch(gt_vertices, "gt_vertices")
    if p.shape != g.shape:
        raise ValueError(f"pred_vertices {p.shape} and gt_vertices {g.shape} differ")
    f = _as_faces(faces, p.shape[1])
    edges = interior_edges(f)
    if len(edges[0]) == 0:
        raise ValueError("the mesh has no interior edge (no two faces share an edge)")
    diff = dihedral_angles(p, f, edges) - dihedral_angles(g, f, edges)
    diff = np.abs((diff + np.pi) % (2 * np.pi) - np.pi)
    return np.degrees(diff.mean(axis=1))


def flipped_face_fraction(pred_vertices, gt_vertices, faces, align: bool = True,
                          allow_reflection: bool = False) -> np.ndarray:
    """Fraction of predicted faces whose normal points against the true face's normal.

    Args:
        pred_vertices: ``(B, V, 3)`` (or ``(V, 3)``) predicted vertices, metres.
        gt_vertices: ``(B, V, 3)`` (or ``(V, 3)``) ground truth, same topology.
        faces: ``(F, 3)`` int triangles.
        align: first align each prediction to its truth with a similarity transform
            ([`handmesh_tutorial.metrics.procrustes_align`][handmesh_tutorial.metrics.procrustes.procrustes_align]).
        allow_reflection: let that alignment mirror the prediction. Off by default: a mirrored
            hand is a different (inside-out) surface, so a mirrored copy of the truth has every
            face flipped.

    Returns:
        ``(B,)`` float64 fraction in ``[0, 1]`` of faces with ``n_pred . n_gt < 0``
        (degenerate faces count as not flipped).
    """
    from . import procrustes_align

    p = _as_batch(pred_vertices, "pred_vertices")
    g = _as_batch(gt_vertices, "gt_vertices")
    if p.shape != g.shape:
        raise ValueError(f"pred_vertices {p.shape} and gt_vertices {g.shape} differ")
    f = _as_faces(faces, p.shape[1])
    if align:
        p = procrustes_align(p, g, allow_reflection=allow_reflection)
    dots = np.einsum("bfk,bfk->bf", face_normals(p, f), face_normals(g, f))
    return (dots < 0).mean(axis=1)
