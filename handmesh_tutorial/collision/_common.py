"""Private helpers shared by the collision submodules: input checks, tolerances, the (3, K)
"structure of arrays" vector kernels and the numpy/numba backend switch.

Everything is in metres and tuned for hand-scale primitives (lengths below ~0.3 m). Taught (as
background of the exact test) in notebook 03 (cylinder collision).
"""

from __future__ import annotations

import sys

import numpy as np

from .._optional import missing_extra_message

# Below this sine of the angle between two disk normals the disks are treated as parallel; the tilt
# this ignores moves a 1 cm disk by 1e-12 m.
_PARALLEL_SIN = 1e-10
# Two parallel disks closer than this along their normal are coplanar (metres).
_COPLANAR = 1e-12
# Below this sine of the angle between two axes the common normal is ill-defined and the
# infinite-cylinder rejection is skipped (the capsule rejection that follows still runs).
_AXES_PARALLEL_SIN = 1e-6

# The geometry kernels below work on "structure of arrays": a batch of K vectors is one (3, K)
# array, so every operation is a plain element-wise numpy call on contiguous (K,) rows.


def _d(a, b):
    """Row-wise dot product of (3, K) arrays -> (K,)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _x(a, b):
    """Row-wise cross product of (3, K) arrays -> (3, K)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


def _check_points(x, name):
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 1 or a.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3) (e.g. (N, 3)), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} contains NaN or inf")
    return a


def _check_radius(x, name):
    a = np.asarray(x, dtype=np.float64)
    if not np.isfinite(a).all():
        raise ValueError(f"{name} contains NaN or inf")
    if (a < 0).any():
        raise ValueError(f"{name} must be non-negative, got min {a.min()}")
    return a


def _prepare(a0, a1, ra, b0, b1, rb, atol):
    """Validate and broadcast two batches of primitives.

    Returns the points as (K, 3) arrays (views where no broadcasting was needed), the radii as
    (K,) and the broadcast batch shape.
    """
    a0, a1 = _check_points(a0, "a0"), _check_points(a1, "a1")
    b0, b1 = _check_points(b0, "b0"), _check_points(b1, "b1")
    ra, rb = _check_radius(ra, "ra"), _check_radius(rb, "rb")
    if not np.isfinite(atol) or atol < 0:
        raise ValueError(f"atol must be finite and non-negative, got {atol}")
    try:
        shape = np.broadcast_shapes(a0.shape[:-1], a1.shape[:-1], b0.shape[:-1], b1.shape[:-1],
                                    ra.shape, rb.shape)
    except ValueError as err:
        raise ValueError(
            f"shapes do not broadcast: a0 {a0.shape}, a1 {a1.shape}, ra {ra.shape}, "
            f"b0 {b0.shape}, b1 {b1.shape}, rb {rb.shape} (points (..., 3), radii (...))") from err
    pts = [np.broadcast_to(p, shape + (3,)).reshape(-1, 3) for p in (a0, a1, b0, b1)]
    rad = [np.broadcast_to(r, shape).reshape(-1) for r in (ra, rb)]
    return pts[0], pts[1], rad[0], pts[2], pts[3], rad[1], shape


_NUMBA_STATE: list = []  # [module or None], filled on first use (numba imports in ~0.3 s)


def _kernels(backend):
    """The numba kernels module for this call, or None for the numpy path.

    ``backend=None`` reads [`BACKEND`][handmesh_tutorial.collision.BACKEND] from the package at
    call time, so ``hmt.collision.BACKEND = "numba"`` (set on the package, as users do) takes effect
    in every submodule.
    """
    backend = sys.modules[__package__].BACKEND if backend is None else backend
    if backend == "numpy":
        return None
    if backend not in ("auto", "numba"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}")
    if not _NUMBA_STATE:
        try:
            from . import _numba
        except ImportError:
            _numba = None
        _NUMBA_STATE.append(_numba)
    if _NUMBA_STATE[0] is None and backend == "numba":
        raise ModuleNotFoundError(missing_extra_message("numba", "backend='numba'"), name="numba")
    return _NUMBA_STATE[0]


def _contig(*arrays):
    return [np.ascontiguousarray(a, dtype=np.float64) for a in arrays]


def _rows(p):
    """(K, 3) -> contiguous (3, K)."""
    return np.ascontiguousarray(p.T)


def _zero_length_error(length2, name):
    bad = np.flatnonzero(~(length2 > 0))
    raise ValueError(f"axis {name} has zero length at flat index {int(bad[0])} "
                     f"({bad.size} such entries); a cylinder needs two distinct end points")


def _check_length(d, name):
    """Raise if any (3, K) axis vector is zero; returns squared lengths (K,)."""
    length2 = _d(d, d)
    if not (length2 > 0).all():
        _zero_length_error(length2, name)
    return length2


def _any_perpendicular(n):
    """A unit vector perpendicular to each unit column of n (3, K)."""
    helper = np.zeros_like(n)
    use_x = np.abs(n[0]) < 0.9
    helper[0, use_x] = 1.0
    helper[1, ~use_x] = 1.0
    e = _x(n, helper)
    return e / np.sqrt(_d(e, e))
