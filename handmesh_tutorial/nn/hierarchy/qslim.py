"""QSlim decimation that keeps vertex subsets: per-vertex quadric error matrices and edge
contraction in order of cost, checked so the coarse mesh stays manifold and keeps its orientation.

Vertices (V, 3) float (metres in this library), faces (F, 3) int. Taught in notebook 06 (mesh
hierarchy and spiral convolution).
"""

from __future__ import annotations

import heapq

import numpy as np

from ._common import _check_mesh

__all__ = ["vertex_quadrics", "decimate"]

# Weight of the planes that pin open boundaries (Garland & Heckbert's "boundary constraints"),
# relative to a face plane. Closed meshes (the hand) never use it.
_BOUNDARY_WEIGHT = 10.0


def vertex_quadrics(vertices, faces) -> np.ndarray:
    """Quadric error matrix of every vertex (Garland & Heckbert), as COMA's QSlim builds it.

    Each face contributes its unit-normal plane ``p = (n, -n . x0)`` as ``p p^T`` to its three
    vertices (unweighted by area), so for a homogeneous point ``h = (x, 1)``, ``h^T Q_v h`` is the
    sum of squared distances from ``x`` to the planes of the faces around ``v``. Edges on an open
    boundary also add a plane through the edge, perpendicular to its face (weight 10), so the
    outline is preserved. Contracting edge ``(a, b)`` into ``a`` costs ``h_a^T (Q_a + Q_b) h_a``.

    Args:
        vertices: (V, 3) positions.
        faces: (F, 3) int triangles.

    Returns:
        (V, 4, 4) float64 symmetric positive semi-definite matrices (squared distance units).

    Shapes:
        ``vertices (V, 3)``, ``faces (F, 3)`` -> ``(V, 4, 4)``.
    """
    v, f = _check_mesh(vertices, faces)
    tri = v[f]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = normal / np.maximum(norm, 1e-300)
    planes = np.concatenate([normal, -(normal * tri[:, 0]).sum(1, keepdims=True)], axis=1)
    q = np.zeros((len(v), 4, 4))
    outer = planes[:, :, None] * planes[:, None, :]
    for k in range(3):
        np.add.at(q, f[:, k], outer)

    # Boundary edges: directed edges whose reverse does not exist.
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    face_of = np.tile(np.arange(len(f)), 3)
    key = edges[:, 0] * len(v) + edges[:, 1]
    rev = edges[:, 1] * len(v) + edges[:, 0]
    boundary = ~np.isin(key, rev)
    if boundary.any():
        e = edges[boundary]
        d = v[e[:, 1]] - v[e[:, 0]]
        n = np.cross(d, normal[face_of[boundary]])
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        bp = np.concatenate([n, -(n * v[e[:, 0]]).sum(1, keepdims=True)], axis=1)
        bq = _BOUNDARY_WEIGHT * bp[:, :, None] * bp[:, None, :]
        np.add.at(q, e[:, 0], bq)
        np.add.at(q, e[:, 1], bq)
    return q


def _normal(a, b, c) -> tuple[float, float, float]:
    """Unnormalised normal of triangle (a, b, c); plain floats (np.cross is slow on 3-vectors)."""
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    return (uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx)


def _dot(a, b) -> float:
    return float(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])


class _Decimator:
    """Edge contraction with a lazy heap; vertices never move (subset property).

    The inner loop works on Python lists and floats: it is faster than numpy for the tiny
    per-vertex neighbourhoods, and plain float arithmetic in a fixed order (no BLAS) makes the
    contraction order, hence the hierarchy, the same on every machine.
    """

    def __init__(self, v: np.ndarray, f: np.ndarray):
        n = len(v)
        self.pos: list[list[float]] = v.tolist()
        self.faces: list[list[int]] = f.tolist()
        self.face_alive = [True] * len(f)
        self.vert_faces: list[set[int]] = [set() for _ in range(n)]
        for fi, tri in enumerate(self.faces):
            for x in tri:
                self.vert_faces[x].add(fi)
        self.alive = [len(s) > 0 for s in self.vert_faces]
        self.num_alive = sum(self.alive)
        self.q: list[list[float]] = vertex_quadrics(v, f).reshape(n, 16).tolist()
        self.version = [0] * n
        self.heap: list = []
        self.blocked: set[tuple[int, int]] = set()
        scale = float(np.ptp(v, axis=0).max()) if n > 1 else 1.0
        self.area_eps = (1e-12 * scale) ** 2
        # Closed meshes may not shrink below a tetrahedron.
        self.closed = not any(c == 1 for a in range(n) for c in self.neighbours(a).values())

    def neighbours(self, a: int) -> dict[int, int]:
        """Neighbour -> number of faces on the edge (1 on a boundary edge, 2 inside)."""
        count: dict[int, int] = {}
        for fi in self.vert_faces[a]:
            for x in self.faces[fi]:
                if x != a:
                    count[x] = count.get(x, 0) + 1
        return count

    # -- costs ----------------------------------------------------------------------------------
    def cost(self, keep: int, remove: int) -> float:
        """``h^T (Q_keep + Q_remove) h`` at the kept vertex ``h = (x, 1)``."""
        q = [a + b for a, b in zip(self.q[keep], self.q[remove], strict=True)]
        x, y, z = self.pos[keep]
        return (x * (q[0] * x + q[1] * y + q[2] * z + q[3])
                + y * (q[4] * x + q[5] * y + q[6] * z + q[7])
                + z * (q[8] * x + q[9] * y + q[10] * z + q[11])
                + (q[12] * x + q[13] * y + q[14] * z + q[15]))

    def push_edge(self, a: int, b: int) -> None:
        # Both directions: the cheaper end point is tried first, the other if that one is illegal.
        lo, hi = min(a, b), max(a, b)
        va, vb = self.version[a], self.version[b]
        heapq.heappush(self.heap, (self.cost(a, b), lo, hi, a, b, va, vb))
        heapq.heappush(self.heap, (self.cost(b, a), lo, hi, b, a, vb, va))

    # -- legality -------------------------------------------------------------------------------
    def legal(self, keep: int, remove: int) -> bool:
        na, nb = self.neighbours(keep), self.neighbours(remove)
        shared = self.vert_faces[remove] & self.vert_faces[keep]
        if not shared:
            return False
        opposite = {x for fi in shared for x in self.faces[fi] if x != keep and x != remove}
        # Link condition: common neighbours are exactly the apexes of the edge's faces.
        if (na.keys() & nb.keys()) != opposite:
            return False
        # An interior edge joining two boundary vertices would pinch the surface.
        if len(shared) == 2 and 1 in na.values() and 1 in nb.values():
            return False
        if self.closed and self.num_alive <= 4:
            return False
        # Keep at least one face around the merged vertex (a lone triangle cannot shrink).
        if len(self.vert_faces[keep] | self.vert_faces[remove]) == len(shared):
            return False
        # Faces of `remove` that survive: no duplicates, no flips, no slivers of zero area.
        existing = {frozenset(self.faces[fi]) for fi in self.vert_faces[keep]}
        for fi in self.vert_faces[remove] - shared:
            tri = self.faces[fi]
            new = [keep if x == remove else x for x in tri]
            if frozenset(new) in existing:
                return False
            n_old = _normal(*(self.pos[x] for x in tri))
            n_new = _normal(*(self.pos[x] for x in new))
            if _dot(n_new, n_new) <= self.area_eps or _dot(n_old, n_new) <= 0.0:
                return False
        return True

    # -- contraction ----------------------------------------------------------------------------
    def collapse(self, keep: int, remove: int) -> None:
        for fi in list(self.vert_faces[remove]):
            tri = self.faces[fi]
            if keep in tri:
                self.face_alive[fi] = False
                for x in tri:
                    self.vert_faces[x].discard(fi)
            else:
                tri[tri.index(remove)] = keep
                self.vert_faces[keep].add(fi)
        self.vert_faces[remove] = set()
        self.alive[remove] = False
        self.num_alive -= 1
        self.q[keep] = [a + b for a, b in zip(self.q[keep], self.q[remove], strict=True)]
        self.version[keep] += 1
        self.version[remove] += 1

    def run(self, target: int) -> tuple[np.ndarray, np.ndarray]:
        n = len(self.pos)
        for a in range(n):
            for b in self.neighbours(a):
                if a < b:
                    self.push_edge(a, b)
        while self.num_alive > target:
            if not self.heap:
                raise RuntimeError(
                    f"decimation stuck at {self.num_alive} vertices (target {target}): "
                    "no edge can be contracted without breaking manifoldness or flipping a face")
            _, lo, hi, a, b, va, vb = heapq.heappop(self.heap)
            if not (self.alive[a] and self.alive[b]):
                continue
            if va != self.version[a] or vb != self.version[b]:
                continue  # stale: a newer entry for this edge exists
            if not self.vert_faces[a] & self.vert_faces[b]:
                continue  # no longer an edge
            if not self.legal(a, b):
                self.blocked.add((lo, hi))
                continue
            self.collapse(a, b)
            # Re-cost the edges at `a`; retry blocked edges whose neighbourhood just changed.
            ring = self.neighbours(a)
            for x in ring:
                self.push_edge(a, x)
            touched = ring.keys() | {a}
            retry = [e for e in self.blocked if e[0] in touched or e[1] in touched]
            for e in retry:
                self.blocked.discard(e)
                if self.alive[e[0]] and self.alive[e[1]] \
                        and self.vert_faces[e[0]] & self.vert_faces[e[1]]:
                    self.push_edge(*e)
        kept = np.flatnonzero(self.alive)
        remap = -np.ones(n, dtype=np.int64)
        remap[kept] = np.arange(len(kept))
        faces = np.array([t for t, ok in zip(self.faces, self.face_alive, strict=True) if ok],
                         dtype=np.int64).reshape(-1, 3)
        return kept, remap[faces]


def decimate(vertices, faces, num_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Contract edges by quadric error until ``num_vertices`` remain, keeping original vertices.

    Each contraction keeps the end point with the lower quadric error at its original position
    (COMA's QSlim variant), so the result is a subset of the input vertices. Contractions that
    would break manifoldness (link condition), pinch a boundary, duplicate a face, or flip or
    degenerate a triangle are skipped. Ties are broken by vertex id and costs are evaluated in
    plain float arithmetic (no BLAS), so the result is deterministic and does not depend on the
    linear-algebra library of the machine.

    Args:
        vertices: (V, 3) float vertex positions (any unit; metres in this library).
        faces: (F, 3) int triangles, consistently oriented.
        num_vertices: vertices to keep, ``1 <= num_vertices <= V``.

    Returns:
        ``(kept, coarse_faces)``: ``kept`` (V', ) int64 sorted ids of the kept input vertices and
        ``coarse_faces`` (F', 3) int64 triangles indexing ``kept`` (same orientation as the input).

    Raises:
        ValueError: bad shapes, ids out of range, degenerate faces, or a bad ``num_vertices``.
        RuntimeError: no legal contraction is left before reaching ``num_vertices``.

    Shapes:
        ``vertices (V, 3)``, ``faces (F, 3)`` -> ``kept (V',)``, ``coarse_faces (F', 3)``.
    """
    v, f = _check_mesh(vertices, faces)
    used = len(np.unique(f))
    if not 1 <= num_vertices <= len(v):
        raise ValueError(f"num_vertices must be in [1, {len(v)}], got {num_vertices}")
    if used != len(v):
        raise ValueError(f"{len(v) - used} vertices are not used by any face; remove them first")
    return _Decimator(v, f).run(int(num_vertices))
