"""The mesh hierarchy of a template: levels of decreasing resolution with their down and up
matrices ([`MeshHierarchy`][handmesh_tutorial.nn.hierarchy.hierarchy.MeshHierarchy]), built by
[`mesh_hierarchy`][handmesh_tutorial.nn.hierarchy.hierarchy.mesh_hierarchy] and cached on disk.

Level 0 is the input (finest), (V_l, 3) vertices per level. Taught in notebook 06 (mesh hierarchy
and spiral convolution).
"""

from __future__ import annotations

import hashlib
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..._io import atomic_savez
from ..._untrusted import open_npz
from ._common import _check_mesh
from .matrices import barycentric_upsampling, selection_matrix
from .qslim import decimate

__all__ = ["MeshHierarchy", "mesh_hierarchy"]

ALGORITHM_VERSION = "2"
"""Bumped whenever the decimation or the matrices change, so stale cache files are not reused."""


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


CACHE_ENV = "HANDMESH_CACHE"
"""Environment variable naming the hierarchy cache folder (it wins over ``XDG_CACHE_HOME``)."""


def default_cache_dir() -> Path:
    """Where hierarchies are cached by default.

    Returns:
        ``$HANDMESH_CACHE`` when set (non-empty), else ``$XDG_CACHE_HOME/handmesh_tutorial`` when
        that is set to an absolute path (the XDG rule), else ``~/.cache/handmesh_tutorial``. The
        folder need not exist or be writable: [`mesh_hierarchy`][handmesh_tutorial.nn.hierarchy.
        hierarchy.mesh_hierarchy] then computes in memory (with a warning).

    Raises:
        RuntimeError: none of the variables is set and the home folder cannot be determined.
    """
    own = os.environ.get(CACHE_ENV, "")
    if own:
        return Path(own).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if xdg and os.path.isabs(xdg):
        return Path(xdg) / "handmesh_tutorial"
    return Path.home() / ".cache" / "handmesh_tutorial"


def _warn_no_cache(where, err: Exception) -> None:
    warnings.warn(f"cannot write the mesh-hierarchy cache in {where} ({err}); computing in "
                  f"memory instead (set {CACHE_ENV} to a writable folder to keep it on disk)",
                  UserWarning, stacklevel=3)


def _cache_key(v: np.ndarray, f: np.ndarray, factors: tuple[float, ...]) -> str:
    h = hashlib.sha256()
    h.update(f"handmesh_tutorial.nn.hierarchy v{ALGORITHM_VERSION};".encode())
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
    with open_npz(path) as z:
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
            [`default_cache_dir`][handmesh_tutorial.nn.hierarchy.hierarchy.default_cache_dir]
            (``$HANDMESH_CACHE``, else ``$XDG_CACHE_HOME/handmesh_tutorial``, else
            ``~/.cache/handmesh_tutorial``). A folder that cannot be created or written is no
            error: the hierarchy is computed in memory and a ``UserWarning`` names the folder.
        use_cache: read and write the cache (``False`` always recomputes and writes nothing).

    Returns:
        A [`MeshHierarchy`][handmesh_tutorial.nn.hierarchy.hierarchy.MeshHierarchy] with
        ``len(factors) + 1`` levels, finest first.

    Raises:
        ValueError: bad shapes, ids out of range, degenerate faces, unused vertices, bad factors.
        RuntimeError: a level cannot be reached without breaking the mesh.

    Shapes:
        ``vertices (V, 3)``, ``faces (F, 3)`` -> per level ``vertices (V_l, 3)``,
        ``faces (F_l, 3)``.

    Examples:
        >>> import numpy as np, trimesh
        >>> from handmesh_tutorial.nn.hierarchy import mesh_hierarchy
        >>> sphere = trimesh.creation.icosphere(subdivisions=1)  # 42 vertices
        >>> h = mesh_hierarchy(sphere.vertices, sphere.faces, (2, 2), use_cache=False)
        >>> [len(v) for v in h.vertices]
        [42, 21, 11]
        >>> h.down[0].shape, h.up[0].shape  # D: (V_1, V_0), U: (V_0, V_1)
        ((21, 42), (42, 21))
        >>> bool(np.array_equal(h.down[0] @ h.vertices[0], h.vertices[1]))  # a vertex subset
        True
        >>> bool(np.allclose(h.up[0].sum(axis=1), 1.0))  # barycentric rows
        True
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
    try:
        root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    except RuntimeError as e:  # no home folder and no variable set
        hier = _build(v, f, factors)
        _warn_no_cache("the default folder", e)
        return hier
    path = root / f"hierarchy_{_cache_key(v, f, factors)}.npz"
    try:
        found = path.is_file()
    except OSError:  # e.g. a folder we may not search
        found = False
    if found:
        try:
            hier = _load(path)
            if (hier.factors == factors and np.array_equal(hier.vertices[0], v)
                    and np.array_equal(hier.faces[0], f)):
                return hier
        except (OSError, KeyError, ValueError):
            pass  # unreadable or foreign file: rebuild and overwrite it
    hier = _build(v, f, factors)
    try:
        _save(path, hier)
    except OSError as e:  # cannot create or write the folder: the cache is only an optimisation
        _warn_no_cache(root, e)
    return hier
