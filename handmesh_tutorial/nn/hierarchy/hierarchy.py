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
import zipfile
import zlib
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

ALGORITHM_VERSION = "3"
"""Bumped whenever the decimation, the matrices or the cache file's format change, so stale cache
files are not reused (3: the file holds a digest of its arrays)."""


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
        RuntimeError: none of the variables is set and the home folder cannot be determined or
            is not an existing folder (``HOME=/nonexistent/x``): a missing home folder is never
            created.
    """
    own = os.environ.get(CACHE_ENV, "")
    if own:
        return Path(own).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if xdg and os.path.isabs(xdg):
        return Path(xdg) / "handmesh_tutorial"
    home = Path.home()
    if not home.is_dir():
        raise RuntimeError(f"the home folder {home} does not exist (it is never created)")
    return home / ".cache" / "handmesh_tutorial"


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


def _digest(arrays: dict) -> str:
    """SHA-256 of a cache file's arrays (names, dtypes, shapes, bytes), in name order."""
    h = hashlib.sha256(f"handmesh_tutorial.nn.hierarchy v{ALGORITHM_VERSION};".encode())
    for name in sorted(k for k in arrays if k != "digest"):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes())
    return h.hexdigest()


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
    arrays["digest"] = np.asarray(_digest(arrays))
    atomic_savez(path, compressed=False, **arrays)


class _BadCache(ValueError):
    """A cache file that is not a valid hierarchy of the requested mesh (the reason)."""


def _int_array(z: dict, name: str, ndim: int) -> np.ndarray:
    a = z[name]
    if a.ndim != ndim or (a.size and not np.issubdtype(a.dtype, np.integer)):
        raise _BadCache(f"{name} must be a {ndim}-D integer array, got {a.dtype} {a.shape}")
    return a.astype(np.int64)


def _check_up(z: dict, l: int, n_fine: int, n_coarse: int, kept: np.ndarray):
    """The CSR parts of up-matrix ``l`` checked before scipy sees them (bad ids crash it)."""
    data = z[f"up_data_{l}"]
    indices = _int_array(z, f"up_indices_{l}", 1)
    indptr = _int_array(z, f"up_indptr_{l}", 1)
    if data.ndim != 1 or not np.issubdtype(data.dtype, np.floating):
        raise _BadCache(f"up_data_{l} must be a 1-D float array, got {data.dtype} {data.shape}")
    if (len(indptr) != n_fine + 1 or indptr[0] != 0 or np.any(np.diff(indptr) < 1)
            or np.any(np.diff(indptr) > 3)):
        raise _BadCache(f"up_indptr_{l} must hold {n_fine + 1} offsets from 0 with 1 to 3 "
                        "entries per row")
    if not len(indices) == len(data) == indptr[-1]:
        raise _BadCache(f"up level {l}: {len(indices)} indices, {len(data)} weights, "
                        f"{indptr[-1]} announced by up_indptr_{l}")
    if len(indices) and (indices.min() < 0 or indices.max() >= n_coarse):
        raise _BadCache(f"up_indices_{l} holds ids in [{indices.min()}, {indices.max()}], "
                        f"level {l + 1} has {n_coarse} vertices")
    if not np.all(np.isfinite(data)) or np.any(data < 0) or np.any(data > 1 + 1e-9):
        raise _BadCache(f"up_data_{l} holds weights outside [0, 1] (NaN, inf or out of range)")
    rows = np.repeat(np.arange(n_fine), np.diff(indptr))
    if np.any((rows[1:] == rows[:-1]) & (indices[1:] <= indices[:-1])):
        raise _BadCache(f"up_indices_{l}: a row repeats or does not sort its column ids")
    sums = np.bincount(rows, weights=data, minlength=n_fine)
    if not np.allclose(sums, 1.0, rtol=0, atol=1e-9):
        worst = int(np.argmax(np.abs(sums - 1.0)))
        raise _BadCache(f"up level {l}: row {worst} sums to {sums[worst]:.6g}, not 1")
    own = indptr[kept]  # a kept vertex maps to itself: one weight 1 at its coarse id
    if (np.any(np.diff(indptr)[kept] != 1) or np.any(indices[own] != np.arange(len(kept)))
            or np.any(data[own] != 1.0)):
        raise _BadCache(f"up level {l}: a kept vertex is not its own coarse vertex")
    return sp.csr_matrix((data.astype(np.float64), indices, indptr), shape=(n_fine, n_coarse))


def _load(path: Path, v: np.ndarray, f: np.ndarray, factors: tuple[float, ...]) -> MeshHierarchy:
    """Read a cache file and check every level against the mesh it must have been built from.

    Raises:
        _BadCache: a missing or malformed array, another mesh or factors, a digest that does not
            match the arrays, a coarse level that is not a subset of the finer one, a face with a
            bad id, an up matrix with ids out of range, weights that are not finite and in
            [0, 1], rows that do not sum to 1, a kept vertex not mapped to itself.
        OSError, ValueError: an unreadable or refused file (`open_npz`).
    """
    try:
        with open_npz(path) as z:
            z = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, zlib.error) as e:  # a member that fails its CRC...
        raise _BadCache(f"unreadable ({type(e).__name__}: {e})") from None
    n = len(factors) + 1
    names = ["factors", "digest", *(f"{a}_{l}" for l in range(n) for a in ("vertices", "faces")),
             *(f"{a}_{l}" for l in range(n - 1)
               for a in ("kept", "up_data", "up_indices", "up_indptr"))]
    missing = [k for k in names if k not in z]
    if missing:
        raise _BadCache(f"missing arrays {missing[:4]}")
    if str(z["digest"]) != _digest({k: z[k] for k in names}):
        raise _BadCache("its digest does not match its arrays (edited or from another version)")
    stored = z["factors"]
    if stored.shape != (n - 1,) or tuple(float(x) for x in stored) != factors:
        raise _BadCache(f"built for factors {stored.tolist()}, not {list(factors)}")
    if (z["vertices_0"].shape != v.shape or not np.array_equal(z["vertices_0"], v)
            or z["faces_0"].shape != f.shape or not np.array_equal(z["faces_0"], f)):
        raise _BadCache("built from another mesh (level 0 differs)")
    vertices, faces, kept_all, down, up = [v], [f], [], [], []
    for l, factor in enumerate(factors):
        n_fine = len(vertices[l])
        kept = _int_array(z, f"kept_{l}", 1)
        if len(kept) != math.ceil(n_fine / factor) or len(kept) == 0:
            raise _BadCache(f"kept_{l} has {len(kept)} ids, level {l + 1} needs "
                            f"{math.ceil(n_fine / factor)}")
        if kept.min() < 0 or kept.max() >= n_fine or len(np.unique(kept)) != len(kept):
            raise _BadCache(f"kept_{l} must hold distinct ids in [0, {n_fine})")
        cv = z[f"vertices_{l + 1}"]
        if cv.shape != (len(kept), 3) or not np.array_equal(cv, vertices[l][kept]):
            raise _BadCache(f"vertices_{l + 1} are not the kept vertices of level {l}")
        try:
            _, cf = _check_mesh(vertices[l][kept], z[f"faces_{l + 1}"])
        except ValueError as e:
            raise _BadCache(f"faces_{l + 1}: {e}") from None
        if len(np.unique(cf)) != len(kept):
            raise _BadCache(f"faces_{l + 1} leave vertices of level {l + 1} unused")
        up.append(_check_up(z, l, n_fine, len(kept), kept))
        down.append(selection_matrix(kept, n_fine))
        vertices.append(vertices[l][kept])
        faces.append(cf)
        kept_all.append(kept)
    return MeshHierarchy(vertices, faces, down, up, kept_all, factors)


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
            A cache file is trusted only after every level is checked against this mesh (its
            digest, the kept ids, coarse vertices and faces, the up matrices' ids, finite
            weights in [0, 1] and rows summing to 1): a file that fails is rebuilt and
            overwritten, with a ``UserWarning`` naming it and the reason (an edited cache would
            otherwise crash scipy or silently change the network's output).

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
            return _load(path, v, f, factors)
        except (OSError, ValueError) as e:  # unreadable, foreign or edited: rebuild, overwrite it
            why = str(e).removeprefix(f"{path}: ")
            warnings.warn(f"the mesh-hierarchy cache {path} is not a valid hierarchy of this "
                          f"mesh ({why}); rebuilding it", UserWarning, stacklevel=2)
    hier = _build(v, f, factors)
    try:
        _save(path, hier)
    except OSError as e:  # cannot create or write the folder: the cache is only an optimisation
        _warn_no_cache(root, e)
    return hier
