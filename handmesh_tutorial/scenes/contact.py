"""Mesh-level contact: signed distances to closed meshes with exact inside/outside signs, and the
contact / penetration of two meshes (`mesh_contact`), used by the generator's settle step.

Points and vertices in metres; ``mesh_contact`` reports millimetres. Taught in notebook 04
("Generating interactions").
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.spatial import cKDTree

from ..collision import Cylinders
from ..collision._common import _kernels

__all__ = ["closest_points_on_triangles", "mesh_contact", "signed_distance"]

# one copy of the tolerances, read by the numba kernel too (``_contact_numba``)
_TINY = 1e-300
"""Guard against zero denominators in the closest-point formulas."""
_SPHERE_SLACK = 1 + 1e-9
"""Relative slack of the bounding-sphere test (plus ``_SPHERE_ABS`` metres): a superset of the
faces that can hold a point's closest surface point, whatever the rounding."""
_SPHERE_ABS = 1e-12


def closest_points_on_triangles(p, a, b, c):
    """Closest points on triangles ``abc`` to points ``p`` (Ericson, *Real-Time Collision
    Detection*, 5.1.5), vectorised over broadcast batches.

    Args:
        p: (..., 3) query points, metres.
        a: (..., 3) first triangle corners.
        b: (..., 3) second triangle corners.
        c: (..., 3) third triangle corners.

    Returns:
        ``(q, region)``: (..., 3) closest points and (...,) int feature codes: 0 the face
        interior, 1/2/3 the edges opposite ``a``/``b``/``c`` (bc, ca, ab), 4/5/6 the corners
        ``a``/``b``/``c``.
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = p - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = p - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    tiny = _TINY
    # face interior (default)
    denom = va + vb + vc
    denom = np.where(np.abs(denom) < tiny, tiny, denom)
    v, w = vb / denom, vc / denom
    q = a + ab * v[..., None] + ac * w[..., None]
    region = np.zeros(p.shape[:-1], int)

    def put(mask, point, code):
        nonlocal q, region
        q = np.where(mask[..., None], point, q)
        region = np.where(mask, code, region)

    # edge bc (region 1)
    e_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
    t = (d4 - d3) / np.where(e_bc, (d4 - d3) + (d5 - d6), 1.0).clip(tiny)
    put(e_bc, b + (c - b) * t[..., None], 1)
    # edge ac (region 2)
    e_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    t = d2 / np.where(e_ac, d2 - d6, 1.0).clip(tiny)
    put(e_ac, a + ac * t[..., None], 2)
    # edge ab (region 3)
    e_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    t = d1 / np.where(e_ab, d1 - d3, 1.0).clip(tiny)
    put(e_ab, a + ab * t[..., None], 3)
    # corners (regions 4, 5, 6) take precedence over edges
    put((d6 >= 0) & (d5 <= d6), np.broadcast_to(c, q.shape), 6)
    put((d3 >= 0) & (d4 <= d3), np.broadcast_to(b, q.shape), 5)
    put((d1 <= 0) & (d2 <= 0), np.broadcast_to(a, q.shape), 4)
    return q, region


def _sum_rows_by(index: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray:
    """(n, 3): ``out[index[k]] += rows[k]`` for k in order (``np.add.at``'s result, faster)."""
    if len(index) == 0:
        return np.zeros((n, 3))
    return np.stack([np.bincount(index, rows[:, a], minlength=n) for a in range(3)], 1)


@functools.lru_cache(maxsize=32)   # hands, objects, chain links: a few layouts
def _edge_ids_cached(key: bytes, shape: tuple, num_vertices: int) -> tuple[np.ndarray, int]:
    f = np.frombuffer(key, np.int64).reshape(shape)
    e = np.sort(np.stack([f[:, [1, 2]], f[:, [2, 0]], f[:, [0, 1]]], 1), axis=2)
    _, inv = np.unique(e[..., 0] * num_vertices + e[..., 1], return_inverse=True)
    inv = inv.reshape(-1)
    inv.setflags(write=False)
    return inv, int(inv.max()) + 1 if inv.size else 0


def _edge_ids(faces: np.ndarray, num_vertices: int) -> tuple[np.ndarray, int]:
    """``(edge id of each face's edges (3F,), number of edges)``; edge ``i`` of a face is
    opposite its corner ``i``. Topology only: computed once per mesh layout (the generator's hands
    share two), read-only."""
    f = np.ascontiguousarray(faces, np.int64)
    return _edge_ids_cached(f.tobytes(), f.shape, int(num_vertices))


class _MeshSDF:
    """Signed distance to a closed triangle mesh with angle-weighted pseudo-normals.

    The sign of ``p - c`` (``c`` the closest surface point) against the pseudo-normal of the
    feature holding ``c`` (face, edge or vertex) is exact for closed, consistently oriented
    meshes (Baerentzen & Aanaes 2005), so no ray casting is needed. Closest points are exact:
    for a query at distance ``r`` from its nearest mesh vertex, every face whose bounding sphere
    (centroid, radius ``rho``) comes within ``r`` is tested (k-d trees of vertices and of face
    centroids).

    Finding those faces fast: the faces are split by size. Faces with ``rho`` above
    ``big_face`` (the wrist cap's fan, an object's large flat sides) are tested against every
    point. For the others, each point takes its ``k`` nearest face centroids in one vectorised
    k-d tree query; that set is complete when the ``k``-th centroid is farther than ``r`` plus the
    largest small-face radius, and only the few points where it is not fall back to a radius
    query. Why the split: one radius query with ``r`` plus the *largest* face radius (the wrist
    cap's) returns hundreds of faces per point (costs: docs page "Performance", "Generator").
    """

    big_face = 0.012
    """Faces whose bounding radius exceeds this (metres) are tested against every point."""
    k = 48
    """Nearest small-face centroids gathered per point in the vectorised query."""

    def __init__(self, vertices, faces):
        v = np.asarray(vertices, float)
        f = np.asarray(faces, np.int64)
        self.v, self.f = v, f
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        fn /= np.linalg.norm(fn, axis=1, keepdims=True) + 1e-30
        self.fn = fn
        # angle-weighted vertex normals: the three corners' contributions summed per vertex in
        # the order corner 0 of every face, corner 1, corner 2 (one bincount per axis adds in
        # input order, as three np.add.at calls did, so the sums are bitwise the same)
        weighted = []
        for i in range(3):
            e1 = v[f[:, (i + 1) % 3]] - v[f[:, i]]
            e2 = v[f[:, (i + 2) % 3]] - v[f[:, i]]
            cosang = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
                                         + 1e-30)
            weighted.append(np.arccos(np.clip(cosang, -1, 1))[:, None] * fn)
        self.vn = _sum_rows_by(f.T.reshape(-1), np.concatenate(weighted), len(v))
        # edge pseudo-normals (sum of the two adjacent face normals); edge i of a face is
        # opposite its corner i
        inv, num_edges = _edge_ids(f, len(v))
        self.edge_of = inv.reshape(-1, 3)
        self.en = _sum_rows_by(inv, np.repeat(fn, 3, axis=0), num_edges)
        self.centroid = v[f].mean(1)
        self.rho = np.linalg.norm(v[f] - self.centroid[:, None], axis=2).max(1)
        big = self.rho > self.big_face
        self.big_ids = np.flatnonzero(big)
        self.small_ids = np.flatnonzero(~big)
        self.rho_small = float(self.rho[self.small_ids].max()) if len(self.small_ids) else 0.0
        self._kernel_args = None   # the numba path's arrays, made on its first call

    # the k-d trees serve the numpy path only: built on its first call
    @functools.cached_property
    def tree(self) -> cKDTree:
        """k-d tree of the vertices."""
        return cKDTree(self.v)

    @functools.cached_property
    def ctree(self) -> cKDTree | None:
        """k-d tree of the small faces' centroids (``None`` when every face is big)."""
        return cKDTree(self.centroid[self.small_ids]) if len(self.small_ids) else None

    def _candidates(self, p: np.ndarray, dmin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(point ids, face ids)`` of every (point, face) pair whose face's bounding sphere
        comes within the point's nearest-vertex distance ``dmin`` (a superset of the faces that
        hold each point's closest surface point)."""
        n = len(p)
        slack = _SPHERE_SLACK

        def reaches(dist, pid, face):   # the bounding sphere comes within dmin of the point
            return dist <= dmin[pid] + self.rho[face] * slack + _SPHERE_ABS

        pid_parts, face_parts = [], []
        if len(self.small_ids):
            k = min(self.k, len(self.small_ids))
            dist, idx = self.ctree.query(p, k=k)
            dist, idx = dist.reshape(n, k), idx.reshape(n, k)
            reach = dmin + self.rho_small * slack + _SPHERE_ABS
            complete = np.full(n, True) if k == len(self.small_ids) else dist[:, -1] > reach
            pid = np.repeat(np.flatnonzero(complete), k)
            face = self.small_ids[idx[complete].ravel()]
            keep = reaches(dist[complete].ravel(), pid, face)
            pid_parts.append(pid[keep])
            face_parts.append(face[keep])
            rest = np.flatnonzero(~complete)
            if len(rest):   # more than k small faces may reach these points: a radius query
                near = self.ctree.query_ball_point(p[rest], reach[rest])
                pid = np.repeat(rest, [len(x) for x in near])
                face = self.small_ids[np.concatenate([np.asarray(x, np.int64) for x in near])]
                keep = reaches(np.linalg.norm(p[pid] - self.centroid[face], axis=1), pid, face)
                pid_parts.append(pid[keep])
                face_parts.append(face[keep])
        if len(self.big_ids):   # every point against every big face, as one (N, B) matrix
            c = self.centroid[self.big_ids]
            dist = np.sqrt(((p[:, None, :] - c[None]) ** 2).sum(-1))
            reach_big = dmin[:, None] + self.rho[self.big_ids] * slack + _SPHERE_ABS
            pid, j = np.nonzero(dist <= reach_big)
            pid_parts.append(pid)
            face_parts.append(self.big_ids[j])
        return np.concatenate(pid_parts), np.concatenate(face_parts)

    def __call__(self, points, backend: str | None = None) -> np.ndarray:
        """(N,) signed distances of points (N,3), metres: negative inside the mesh.

        ``backend`` as in [`signed_distance`][handmesh_tutorial.scenes.contact.signed_distance].
        """
        p = np.asarray(points, float).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0)
        if _kernels(backend) is not None:
            return self._compiled(p)
        f = self.f
        dmin, _ = self.tree.query(p)  # the nearest vertex bounds the distance to the surface
        pid, face = self._candidates(p, dmin)
        tri = self.v[f[face]]
        q, reg = closest_points_on_triangles(p[pid], tri[:, 0], tri[:, 1], tri[:, 2])
        d2 = ((q - p[pid]) ** 2).sum(-1)
        order = np.lexsort((d2, pid))
        first = order[np.r_[True, pid[order][1:] != pid[order][:-1]]]  # per point: its minimum
        qc, reg, face, d = q[first], reg[first], face[first], np.sqrt(d2[first])
        n = self.fn[face].copy()
        on_edge = (reg >= 1) & (reg <= 3)
        n[on_edge] = self.en[self.edge_of[face[on_edge], reg[on_edge] - 1]]
        on_vert = reg >= 4
        n[on_vert] = self.vn[f[face[on_vert], reg[on_vert] - 4]]
        return np.where(((p - qc) * n).sum(1) < 0, -d, d)

    def _compiled(self, p: np.ndarray) -> np.ndarray:
        """The numba kernel's signed distances (contiguous copies of the mesh arrays made once)."""
        if self._kernel_args is None:
            self._kernel_args = [np.ascontiguousarray(a, dtype=np.int64 if a.dtype.kind == "i"
                                                      else np.float64)
                                 for a in (self.v, self.f, self.fn, self.en, self.vn,
                                           self.edge_of, self.centroid, self.rho)]
        from ._contact_numba import signed_distances
        return signed_distances(np.ascontiguousarray(p, dtype=np.float64), *self._kernel_args)


def signed_distance(points, vertices, faces, backend: str | None = None) -> np.ndarray:
    """Signed distance of points to a closed triangle mesh (negative inside).

    Args:
        points: (N, 3) metres.
        vertices: (V, 3) mesh vertices, metres.
        faces: (F, 3) int, consistently oriented, closed (watertight) mesh.
        backend: ``"numba"`` (a compiled kernel that walks the faces point by point),
            ``"numpy"`` (the vectorised reference with k-d trees), ``"auto"`` (numba when it
            imports), or ``None``: [`hmt.collision.BACKEND`][handmesh_tutorial.collision.BACKEND],
            the switch of the cylinder test. Both give the same distances.

    Returns:
        (N,) float64 metres: ``> 0`` outside, ``< 0`` inside (the opposite sign of
        ``trimesh.proximity.signed_distance``).
    """
    return _MeshSDF(vertices, faces)(points, backend)


def _near(points, cyl_p0, cyl_p1, radius, dist: float) -> np.ndarray:
    """(N,) bool: points within ``dist`` of some capsule (a superset of "of some cylinder")."""
    d = cyl_p1 - cyl_p0                                     # (C,3)
    w = points[:, None] - cyl_p0[None]                      # (N,C,3)
    t = np.clip((w * d).sum(-1) / (d * d).sum(1), 0, 1)
    e = w - t[..., None] * d
    r = radius + dist
    return ((e * e).sum(-1) <= r * r).any(1)


def mesh_contact(a_vertices, a_faces, b_vertices, b_faces, *, a_cylinders: Cylinders | None = None,
                 b_cylinders: Cylinders | None = None, near: float = 0.01, a_shift=None,
                 sdf_a=None, sdf_b=None, backend: str | None = None) -> dict:
    """Contact and penetration between two closed meshes, measured on their vertices.

    Each mesh's vertices are tested against the other mesh's surface (signed distance with an exact
    sign, see [`signed_distance`][handmesh_tutorial.scenes.contact.signed_distance]). With
    cylinders given, only vertices within ``near`` of the other body's cylinders are tested (a
    prefilter: the cylinders cover their mesh to within a few millimetres, so farther vertices
    cannot set the contact); when no vertex passes it, every vertex is tested.

    Args:
        a_vertices: (V, 3) vertices of the first mesh (closed), metres.
        a_faces: (F, 3) its triangles.
        b_vertices: (V', 3) vertices of the second mesh (closed), metres.
        b_faces: (F', 3) its triangles.
        a_cylinders: optional collision cylinders of the first mesh, for the prefilter.
        b_cylinders: optional collision cylinders of the second mesh.
        near: prefilter distance, metres.
        a_shift: optional (3,) translation applied to mesh A (and its cylinders), metres.
        sdf_a: optional prebuilt signed-distance object of the (unshifted) first mesh.
        sdf_b: optional prebuilt signed-distance object of the second mesh.
        backend: the signed-distance path, as in
            [`signed_distance`][handmesh_tutorial.scenes.contact.signed_distance].

    Returns:
        dict with ``contact_mm`` (smallest vertex-to-surface distance, 0 when some vertex is
        inside the other mesh), ``gap_mm`` (that distance over the outside vertices only),
        ``penetration_mm`` (depth of the deepest vertex inside the other mesh, 0 when none),
        ``inside`` (count of such vertices), ``tested`` (vertices tested).
    """
    av, bv = np.asarray(a_vertices, float), np.asarray(b_vertices, float)
    sh = np.zeros(3) if a_shift is None else np.asarray(a_shift, float).reshape(3)
    sa = sdf_a if sdf_a is not None else _MeshSDF(av, a_faces)
    sb = sdf_b if sdf_b is not None else _MeshSDF(bv, b_faces)
    pa, pb = av + sh, bv
    if b_cylinders is not None:
        pa = pa[_near(pa, b_cylinders.p0, b_cylinders.p1, b_cylinders.radius, near)]
    if a_cylinders is not None:
        pb = pb[_near(pb, a_cylinders.p0 + sh, a_cylinders.p1 + sh, a_cylinders.radius, near)]
    if len(pa) == 0 or len(pb) == 0:  # nothing near the other body: test every vertex
        pa, pb = av + sh, bv
    d = np.concatenate([sb(pa, backend), sa(pb - sh, backend)])
    inside = d < 0
    gap = float(d[~inside].min()) if (~inside).any() else float("inf")
    pen = float(-d[inside].min()) if inside.any() else 0.0
    return {"contact_mm": 0.0 if inside.any() else 1e3 * gap, "gap_mm": 1e3 * gap,
            "penetration_mm": 1e3 * pen, "inside": int(inside.sum()), "tested": int(d.size)}
