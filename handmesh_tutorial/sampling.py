"""Mesh hierarchy for the decoder: QSlim decimation to vertex subsets, down and up matrices.

MSMR-Net (paper, "Multi-path Mesh Decoder") decodes on five resolutions of the hand mesh. Each
coarser mesh is made by *contracting edges* in order of the quadric error metric (Garland and
Heckbert's QSlim, as in COMA, Ranjan et al. 2018) until the vertex count drops by a factor (2):
778 -> 389 -> 195 -> 98 -> 49 for a MANO-size mesh.

Two choices make the matrices between levels simple and exact:

* **Vertex subsets.** A contracted edge keeps the *cheaper* of its two end points at its original
  position (as COMA's QSlim does) instead of moving it to an optimal point. Every coarse vertex is
  therefore an original vertex, and the down matrix ``D`` (``V_{l+1} x V_l``) is a 0/1 selection
  with one 1 per row: ``D @ V_l == V_{l+1}`` exactly.
* **True barycentric up matrices.** Each fine vertex is projected onto the closest triangle of the
  coarse mesh; the barycentric coordinates of that closest point are its row of ``U``
  (``V_l x V_{l+1}``). Rows are non-negative and sum to 1, so ``U`` commutes with translations
  (``U (V + t) = U V + t``), and a vertex kept in the coarse mesh maps to itself exactly.
  COMA's published code instead solves a small least-squares problem per vertex, whose rows neither
  sum to 1 nor stay non-negative; we do not reproduce that.

Every contraction is checked so that the coarse meshes stay manifold and keep their orientation:
the *link condition* (the end points share exactly the neighbours opposite the edge), no interior
edge between two boundary vertices, no duplicate faces, no triangle that flips or degenerates.

The hierarchy depends only on the template and the factors, so it is cached on disk (``.npz``
read with ``allow_pickle=False``) under a key that hashes the vertices, faces, factors and the
algorithm version.
"""

from __future__ import annotations

import hashlib
import heapq
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import trimesh

from ._io import atomic_savez

__all__ = [
    "ALGORITHM_VERSION",
    "MeshHierarchy",
    "barycentric_upsampling",
    "decimate",
    "default_cache_dir",
    "mesh_hierarchy",
    "selection_matrix",
    "to_torch_sparse",
    "vertex_quadrics",
]

ALGORITHM_VERSION = "2"
"""Bumped whenever the decimation or the matrices change, so stale cache files are not reused."""

# Weight of the planes that pin open boundaries (Garland & Heckbert's "boundary constraints"),
# relative to a face plane. Closed meshes (the hand) never use it.
_BOUNDARY_WEIGHT = 10.0


# ----------------------------------------------------------------------------------------------
# Input checks
# ----------------------------------------------------------------------------------------------
def _check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {tuple(v.shape)}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices contain NaN or inf")
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {tuple(f.shape)}")
    if f.size and not np.issubdtype(f.dtype, np.integer):
        raise ValueError(f"faces must be integer vertex ids, got dtype {f.dtype}")
    f = f.astype(np.int64)
    if len(f) == 0:
        raise ValueError("faces is empty: a mesh needs at least one triangle")
    if f.min() < 0 or f.max() >= len(v):
        raise ValueError(f"faces reference vertex ids in [{f.min()}, {f.max()}], "
                         f"but there are {len(v)} vertices")
    if np.any((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])):
        raise ValueError("faces contain degenerate triangles (a repeated vertex id)")
    return np.ascontiguousarray(v), np.ascontiguousarray(f)


# ----------------------------------------------------------------------------------------------
# QSlim decimation keeping vertex subsets
# ----------------------------------------------------------------------------------------------
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
    """
    v, f = _check_mesh(vertices, faces)
    used = len(np.unique(f))
    if not 1 <= num_vertices <= len(v):
        raise ValueError(f"num_vertices must be in [1, {len(v)}], got {num_vertices}")
    if used != len(v):
        raise ValueError(f"{len(v) - used} vertices are not used by any face; remove them first")
    return _Decimator(v, f).run(int(num_vertices))


# ----------------------------------------------------------------------------------------------
# Down and up matrices
# ----------------------------------------------------------------------------------------------
def selection_matrix(kept, num_fine: int) -> sp.csr_matrix:
    """0/1 down-sampling matrix that picks the kept vertices.

    Args:
        kept: (V_coarse,) int ids of the fine vertices that survive, in coarse order.
        num_fine: V_fine, the number of fine vertices.

    Returns:
        (V_coarse, V_fine) float64 CSR matrix with a single 1 per row, at column ``kept[i]``.
    """
    kept = np.asarray(kept, dtype=np.int64)
    n = len(kept)
    return sp.csr_matrix((np.ones(n), (np.arange(n), kept)), shape=(n, num_fine))


def barycentric_upsampling(fine_vertices, coarse_vertices, coarse_faces, kept=None,
                           chunk: int = 256) -> sp.csr_matrix:
    """Up-sampling matrix from closest-point barycentric coordinates on the coarse mesh.

    Every fine vertex is projected onto the closest point of the closest coarse triangle (an
    exact search over all triangles, pruned by bounding spheres, so the result does not depend
    on a spatial index; ties go to the lowest triangle id); the
    barycentric coordinates of that point, clipped at 0 and renormalised against rounding, are
    its row. Rows therefore sum to 1 and are non-negative, which makes the map commute with
    translations. Rows of kept vertices are set to exactly one 1.

    Args:
        fine_vertices: (V_fine, 3) positions of the fine mesh.
        coarse_vertices: (V_coarse, 3) positions of the coarse mesh.
        coarse_faces: (F_coarse, 3) int triangles of the coarse mesh.
        kept: optional (V_coarse,) ids of the fine vertices that are the coarse vertices.
        chunk: fine vertices processed at once (memory ~ chunk * F_coarse * 50 bytes).

    Returns:
        (V_fine, V_coarse) float64 CSR matrix with at most 3 non-zeros per row.
    """
    fine = np.asarray(fine_vertices, dtype=np.float64)
    cv, cf = _check_mesh(coarse_vertices, coarse_faces)
    tris = cv[cf]  # (F, 3, 3)
    # Bounding spheres prune the exact search: the centroid is on the triangle (an upper bound
    # of the distance) and no triangle point is farther than `radius` from it (a lower bound).
    centre = tris.mean(axis=1)
    radius = np.linalg.norm(tris - centre[:, None], axis=2).max(axis=1)
    rows, cols, vals = [], [], []
    for start in range(0, len(fine), chunk):
        pts = fine[start:start + chunk]
        m = len(pts)
        dc = np.linalg.norm(pts[:, None] - centre[None], axis=2)  # (m, F)
        upper = dc.min(axis=1, keepdims=True)
        pi, ti = np.nonzero(dc - radius[None] <= upper * (1 + 1e-9) + 1e-12)
        closest = trimesh.triangles.closest_point(tris[ti], pts[pi])
        d2 = np.einsum("ij,ij->i", closest - pts[pi], closest - pts[pi])
        # Per point, the candidate with the smallest distance, ties to the lowest triangle id
        # (candidates come sorted by point, then triangle id).
        order = np.lexsort((ti, d2, pi))
        first = order[np.r_[True, pi[order][1:] != pi[order][:-1]]]
        best = ti[first]
        bary = trimesh.triangles.points_to_barycentric(tris[best], closest[first])
        bary = np.clip(bary, 0.0, None)
        bary /= bary.sum(axis=1, keepdims=True)
        rows.append(np.repeat(np.arange(start, start + m), 3))
        cols.append(cf[best].reshape(-1))
        vals.append(bary.reshape(-1))
    up = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(len(fine), len(cv))).tocsr()
    if kept is not None:
        kept = np.asarray(kept, dtype=np.int64)
        up = up.tolil()
        for i, k in enumerate(kept.tolist()):
            up.rows[k] = [i]
            up.data[k] = [1.0]
        up = up.tocsr()
    up.eliminate_zeros()
    up.sort_indices()
    return up


def to_torch_sparse(matrix: sp.spmatrix, dtype=None):
    """Convert a scipy sparse matrix to a coalesced ``torch.sparse_coo_tensor`` (float32).

    Args:
        matrix: (M, N) scipy sparse matrix, e.g. ``hierarchy.down[l]`` or ``hierarchy.up[l]``.
        dtype: torch dtype, default ``torch.float32``.

    Returns:
        (M, N) sparse COO tensor; use ``torch.sparse.mm(t, x)`` with ``x`` (N, C).
    """
    import torch

    coo = sp.coo_matrix(matrix)
    idx = torch.from_numpy(np.vstack([coo.row, coo.col]).astype(np.int64))
    val = torch.from_numpy(coo.data).to(dtype or torch.float32)
    return torch.sparse_coo_tensor(idx, val, coo.shape, check_invariants=True).coalesce()


# ----------------------------------------------------------------------------------------------
# Hierarchy
# ----------------------------------------------------------------------------------------------
@dataclass
class MeshHierarchy:
    """Meshes of decreasing resolution and the matrices between consecutive levels.

    Level 0 is the input (finest). For ``L`` factors there are ``L + 1`` levels.

    Attributes:
        vertices: per level, (V_l, 3) float64 positions (the input's unit). Coarse vertices are
            exact copies of rows of the finer level.
        faces: per level, (F_l, 3) int64 triangles, same orientation as the input.
        down: per step ``l -> l+1``, (V_{l+1}, V_l) CSR 0/1 matrix with one 1 per row.
        up: per step ``l+1 -> l``, (V_l, V_{l+1}) CSR barycentric matrix, rows sum to 1.
        kept: per step, (V_{l+1},) int64 ids into level ``l`` of the vertices kept.
        factors: the reduction factors used.
    """

    vertices: list[np.ndarray]
    faces: list[np.ndarray]
    down: list[sp.csr_matrix]
    up: list[sp.csr_matrix]
    kept: list[np.ndarray]
    factors: tuple[float, ...] = field(default=())

    @property
    def num_vertices(self) -> list[int]:
        """Vertex count per level, finest first (e.g. ``[778, 389, 195, 98, 49]``)."""
        return [len(v) for v in self.vertices]

    @property
    def num_levels(self) -> int:
        """Number of levels (``len(factors) + 1``)."""
        return len(self.vertices)

    def original_index(self, level: int) -> np.ndarray:
        """Ids in level 0 of the vertices of ``level``, (V_level,) int64."""
        idx = np.arange(len(self.vertices[0]))
        for k in self.kept[:level]:
            idx = idx[k]
        return idx

    def reconstruction_errors(self, vertices=None) -> list[tuple[float, float]]:
        """Mean and max distance ``|| U_l D_l V_l - V_l ||`` per step, in the vertices' unit.

        Args:
            vertices: optional (V_0, 3) positions to test (default: the template). Each level is
                down-sampled from the previous one, then up-sampled one step.

        Returns:
            ``[(mean, max), ...]``, one pair per step ``l -> l+1 -> l``.
        """
        x = self.vertices[0] if vertices is None else np.asarray(vertices, dtype=np.float64)
        out = []
        for d, u in zip(self.down, self.up, strict=True):
            err = np.linalg.norm(u @ (d @ x) - x, axis=1)
            out.append((float(err.mean()), float(err.max())))
            x = d @ x
        return out


def default_cache_dir() -> Path:
    """``~/.cache/handmesh_tutorial``, where hierarchies are cached by default."""
    return Path.home() / ".cache" / "handmesh_tutorial"


def _cache_key(v: np.ndarray, f: np.ndarray, factors: tuple[float, ...]) -> str:
    h = hashlib.sha256()
    h.update(f"handmesh_tutorial.sampling v{ALGORITHM_VERSION};".encode())
    h.update(repr(tuple(float(x) for x in factors)).encode())
    h.update(str(v.shape).encode() + np.ascontiguousarray(v, dtype="<f8").tobytes())
    h.update(str(f.shape).encode() + np.ascontiguousarray(f, dtype="<i8").tobytes())
    return h.hexdigest()[:24]


def _save(path: Path, hier: MeshHierarchy) -> None:
    arrays = {"factors": np.asarray(hier.factors, dtype=np.float64)}
    for l, (v, f) in enumerate(zip(hier.vertices, hier.faces, strict=True)):
        arrays[f"vertices_{l}"] = v
        arrays[f"faces_{l}"] = f
    for l, (k, u) in enumerate(zip(hier.kept, hier.up, strict=True)):
        arrays[f"kept_{l}"] = k
        arrays[f"up_data_{l}"] = u.data
        arrays[f"up_indices_{l}"] = u.indices.astype(np.int64)
        arrays[f"up_indptr_{l}"] = u.indptr.astype(np.int64)
    atomic_savez(path, compressed=False, **arrays)


def _load(path: Path) -> MeshHierarchy:
    with np.load(path, allow_pickle=False) as z:
        factors = tuple(float(x) for x in z["factors"])
        n = len(factors) + 1
        vertices = [z[f"vertices_{l}"] for l in range(n)]
        faces = [z[f"faces_{l}"] for l in range(n)]
        kept = [z[f"kept_{l}"] for l in range(n - 1)]
        up = [sp.csr_matrix((z[f"up_data_{l}"], z[f"up_indices_{l}"], z[f"up_indptr_{l}"]),
                            shape=(len(vertices[l]), len(vertices[l + 1]))) for l in range(n - 1)]
    down = [selection_matrix(k, len(vertices[l])) for l, k in enumerate(kept)]
    return MeshHierarchy(vertices, faces, down, up, kept, factors)


def _build(v: np.ndarray, f: np.ndarray, factors: tuple[float, ...]) -> MeshHierarchy:
    vertices, faces, down, up, kept_all = [v], [f], [], [], []
    for factor in factors:
        target = math.ceil(len(vertices[-1]) / factor)
        kept, cf = decimate(vertices[-1], faces[-1], target)
        cv = vertices[-1][kept]
        down.append(selection_matrix(kept, len(vertices[-1])))
        up.append(barycentric_upsampling(vertices[-1], cv, cf, kept=kept))
        vertices.append(cv)
        faces.append(cf)
        kept_all.append(kept)
    return MeshHierarchy(vertices, faces, down, up, kept_all, tuple(factors))


def mesh_hierarchy(vertices, faces, factors: Sequence[float] = (2, 2, 2, 2), *,
                   cache_dir: str | os.PathLike | None = None,
                   use_cache: bool = True) -> MeshHierarchy:
    """Build (or load from the cache) the QSlim hierarchy of a template mesh.

    Level ``l + 1`` has ``ceil(V_l / factors[l])`` vertices, a subset of level ``l``'s.
    For a MANO-size hand (778 vertices) and the default factors: 778, 389, 195, 98, 49.

    Args:
        vertices: (V, 3) template positions, metres (numpy array or CPU tensor).
        faces: (F, 3) int triangles of a manifold, consistently oriented mesh; every vertex must
            belong to a face.
        factors: reduction factor per step, each > 1.
        cache_dir: directory of the cache; ``None`` means
            [`default_cache_dir`][handmesh_tutorial.sampling.default_cache_dir].
        use_cache: read and write the cache (``False`` always recomputes and writes nothing).

    Returns:
        A [`MeshHierarchy`][handmesh_tutorial.sampling.MeshHierarchy] with ``len(factors) + 1``
        levels, finest first.

    Raises:
        ValueError: bad shapes, ids out of range, degenerate faces, unused vertices, bad factors.
        RuntimeError: a level cannot be reached without breaking the mesh.
    """
    v, f = _check_mesh(vertices, faces)
    factors = tuple(float(x) for x in factors)
    if any(not (x > 1.0 and math.isfinite(x)) for x in factors):
        raise ValueError(f"every factor must be a finite number > 1, got {factors}")
    if len(np.unique(f)) != len(v):
        raise ValueError(f"{len(v) - len(np.unique(f))} vertices are not used by any face; "
                         "remove unreferenced vertices first")
    if not use_cache:
        return _build(v, f, factors)
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = root / f"hierarchy_{_cache_key(v, f, factors)}.npz"
    if path.exists():
        try:
            hier = _load(path)
            if (hier.factors == factors and np.array_equal(hier.vertices[0], v)
                    and np.array_equal(hier.faces[0], f)):
                return hier
        except (OSError, KeyError, ValueError):
            pass  # unreadable or foreign file: rebuild and overwrite it
    hier = _build(v, f, factors)
    _save(path, hier)
    return hier
