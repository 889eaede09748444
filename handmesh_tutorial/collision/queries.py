"""Scene queries between bodies of cylinders: which pairs collide, does anything collide, and which
non-adjacent parts of one body collide with each other (fingers crossing).

Bodies are [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders]; every query runs the
exact test of ``exact.py`` (or its numba mirror) on all primitive pairs at once. The INTER-SH
generator calls these thousands of times per scene. Taught in notebook 03 (cylinder collision);
used by the generator in notebook 04.
"""

from __future__ import annotations

import numpy as np

from ._common import _contig, _d, _kernels, _zero_length_error
from .cylinders import Cylinders
from .exact import ATOL, _core_units, _exact_stages, _segment_closest

__all__ = ["colliding_pairs", "bodies_collide", "SELF_CONTACT_COMPRESSION", "self_collisions"]


def _units(body: Cylinders, grow: float):
    """(3, N) grown start points and unit axes, (N,) grown lengths and radii of a body."""
    d = (body.p1 - body.p0).T
    length = np.sqrt(_d(d, d))
    if not (length > 0).all():
        _zero_length_error(length, "p0->p1 of a Cylinders")
    u = d / length
    return body.p0.T - grow * u, u, length + 2 * grow, body.radius + grow


def _pairs_test(A: Cylinders, B: Cylinders, i, j, atol: float, early: bool):
    """Exact test of the listed pairs (A[i], B[j]); (K,) bool."""
    ua, ub = _units(A, 0.5 * atol), _units(B, 0.5 * atol)
    return _core_units(ua[0][:, i], ua[1][:, i], ua[2][i], ua[3][i],
                       ub[0][:, j], ub[1][:, j], ub[2][j], ub[3][j], early)


def _all_pairs_test(A: Cylinders, B: Cylinders, atol: float, early: bool):
    """Exact test of every pair (A[i], B[j]): the capsule stage broadcasts (N_A, 1) against
    (1, N_B) without gathering; only the survivors are gathered. Returns (i, j, hit)."""
    (a0, u, la, ra), (b0, v, lb, rb) = _units(A, 0.5 * atol), _units(B, 0.5 * atol)
    A0, UL = a0[:, :, None], (u * la)[:, :, None]
    B0, VL = b0[:, None, :], (v * lb)[:, None, :]
    s, t = _segment_closest(A0, UL, B0, VL)
    p = A0 + s * UL
    pq = B0 + t * VL - p
    rs = ra[:, None] + rb[None, :]
    i, j = np.nonzero(_d(pq, pq) <= rs * rs)
    if i.size == 0:
        return i, j, np.zeros(0, dtype=bool)
    hit = _exact_stages(a0[:, i], u[:, i], la[i], ra[i], b0[:, j], v[:, j], lb[j], rb[j],
                        p[:, i, j], pq[:, i, j], early)
    return i, j, hit


def colliding_pairs(A: Cylinders, B: Cylinders, *, atol: float = ATOL,
                    backend: str | None = None):
    """All pairs of intersecting cylinders between two bodies.

    Every primitive pair is tested at once (vectorised): capsule prefilter, then the exact
    cylinder test on the survivors.

    Args:
        A: the first body, a [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders].
        B: the second body.
        atol: contact tolerance, metres.
        backend: see
            [`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect].

    Returns:
        ``(i, j)``: two int arrays, cylinder ``A[i[k]]`` meets ``B[j[k]]``, in row-major order.
    """
    if len(A) == 0 or len(B) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    nb = _kernels(backend)
    if nb is not None:
        hit = np.empty((len(A), len(B)), dtype=bool)
        if nb.all_pairs(*_contig(A.p0, A.p1, A.radius, B.p0, B.p1, B.radius), float(atol), hit):
            i, j = np.nonzero(hit)
            return i.astype(np.int64, copy=False), j.astype(np.int64, copy=False)
        _units(A, 0.0), _units(B, 0.0)  # raises with the numpy path's message
    i, j, hit = _all_pairs_test(A, B, atol, early=False)
    return i[hit], j[hit]


def bodies_collide(A: Cylinders, B: Cylinders, *, atol: float = ATOL,
                   backend: str | None = None) -> bool:
    """Does any cylinder of body A intersect any cylinder of body B?

    Bounding boxes of the whole bodies first (most generator steps are far from contact), then all
    primitive pairs at once: capsule prefilter, exact test, stopping at the first stage with a hit.

    Args:
        A: the first body, a [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders]
            (e.g. a hand).
        B: the second body (e.g. another hand, or an object).
        atol: contact tolerance, metres.
        backend: see
            [`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect].

    Returns:
        True when at least one pair of primitives intersects.
    """
    if len(A) == 0 or len(B) == 0:
        return False
    nb = _kernels(backend)
    if nb is not None:
        res = nb.bodies_collide(*_contig(A.p0, A.p1, A.radius, B.p0, B.p1, B.radius), float(atol))
        if res >= 0:
            return bool(res)
        _units(A, 0.0), _units(B, 0.0)  # raises with the numpy path's message
    ra, rb = A.radius[:, None], B.radius[:, None]
    lo_a = np.minimum(A.p0, A.p1) - ra
    hi_a = np.maximum(A.p0, A.p1) + ra
    lo_b = np.minimum(B.p0, B.p1) - rb
    hi_b = np.maximum(B.p0, B.p1) + rb
    if ((lo_a.min(0) > hi_b.max(0) + atol) | (lo_b.min(0) > hi_a.max(0) + atol)).any():
        return False
    return bool(_all_pairs_test(A, B, atol, early=True)[2].any())


SELF_CONTACT_COMPRESSION: float = 0.3
"""Fraction of each radius
[`self_collisions`][handmesh_tutorial.collision.queries.self_collisions] lets soft tissue compress
(why 0.3: on the MakeHuman hand it keeps a plain fist, a pinch and a flat hand free of
self-collisions while a finger crossed through its neighbour still collides).
"""


_PAIRS_CACHE: dict = {}


def _non_adjacent_pairs(n: int, adjacent: np.ndarray):
    """(i, j) with i < j over n cylinders, minus the adjacent pairs; cached per topology (the
    generator asks for the same hand's pairs thousands of times). Returns copies."""
    key = (n, adjacent.tobytes())
    hit = _PAIRS_CACHE.get(key)
    if hit is None:
        i, j = np.triu_indices(n, 1)
        if len(adjacent):
            code = adjacent[:, 0] * n + adjacent[:, 1]
            keep = ~np.isin(i * n + j, code)
            i, j = i[keep], j[keep]
        if len(_PAIRS_CACHE) > 64:
            _PAIRS_CACHE.clear()
        hit = _PAIRS_CACHE[key] = (i, j)
    return hit[0].copy(), hit[1].copy()


def self_collisions(body: Cylinders, *, atol: float = ATOL,
                    compression: float = SELF_CONTACT_COMPRESSION, backend: str | None = None):
    """Intersecting pairs of NON-ADJACENT cylinders of one body (e.g. fingers crossing).

    Pairs listed in ``body.adjacent`` touch by design and are skipped. For hands built by
    [`hand_cylinders`][handmesh_tutorial.collision.hand_proxies.hand_cylinders] these are:
    consecutive phalanges of a finger; every phalanx with every palm cylinder (the proximal segment
    sits on the palm; the others curl onto it in a fist, a contact the flexion limits bound); all
    palm cylinders with each other; and the proximal phalanges of neighbouring fingers
    (index-middle, middle-ring, ring-pinky), which sit side by side on the knuckle line, joined by
    the finger webs.

    Skin is soft: two parts of one hand pressed together (fingers side by side, thumb on a
    finger) overlap as cylinders before anything passes through anything. The test therefore
    shrinks every radius by the fraction ``compression`` first (0 = the exact cylinders).

    Args:
        body: a [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders].
        atol: contact tolerance, metres.
        compression: fraction of each radius that may be compressed, in [0, 1).
        backend: see
            [`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect].

    Returns:
        ``(i, j)`` int arrays with ``i < j``.
    """
    i, j = _non_adjacent_pairs(len(body), body.adjacent)
    if i.size == 0:
        return i, j
    if not 0 <= compression < 1:
        raise ValueError(f"compression must be in [0, 1), got {compression}")
    nb = _kernels(backend)
    if nb is not None:
        hit = np.empty(i.size, dtype=bool)
        radius = body.radius * (1.0 - compression) if compression else body.radius
        if nb.listed_pairs(*_contig(body.p0, body.p1, radius), i, j, float(atol), hit):
            return i[hit], j[hit]
        _units(body, 0.0)  # raises with the numpy path's message
    if compression:
        body = Cylinders(body.p0, body.p1, body.radius * (1.0 - compression), body.names,
                         body.parts, body.adjacent)
    hit = _pairs_test(body, body, i, j, atol, early=False)
    return i[hit], j[hit]
