"""Exact, batched intersection tests between finite solid cylinders (Ketchel–Larochelle structure),
the capsule test and the segment-segment distance they build on.

The numpy kernels here are the reference; ``_numba.py`` mirrors them operation for operation
and is used by default when numba imports ([`BACKEND`][handmesh_tutorial.collision.BACKEND] or
``backend=`` choose). Inside, a batch
of K vectors is one (3, K) array (structure of arrays). Taught in notebook 03 (cylinder collision).
"""

from __future__ import annotations

import numpy as np

from ._common import (
    _AXES_PARALLEL_SIN,
    _COPLANAR,
    _PARALLEL_SIN,
    _any_perpendicular,
    _check_length,
    _contig,
    _d,
    _kernels,
    _prepare,
    _rows,
    _x,
)

__all__ = ["ATOL", "segment_segment_distance", "cylinders_intersect", "capsules_intersect"]

ATOL = 1e-9
"""Default contact tolerance of the tests, metres: cylinders are grown by ``atol / 2`` (radius and
each end) before an exact test, so touching counts as intersecting and rounding cannot flip it.
"""


def _segment_closest(p0, d1, q0, d2):
    """Parameters ``s, t`` in [0, 1] of the closest points of segments ``p0 + s d1``, ``q0 + t d2``.

    (3, K) inputs, (K,) outputs. Ericson, Real-Time Collision Detection, 5.1.9: clamped, and robust
    for parallel segments (any closest pair is returned). ``d1`` and ``d2`` must be non-zero.
    """
    r = p0 - q0
    a, e = _d(d1, d1), _d(d2, d2)
    b, c, f = _d(d1, d2), _d(d1, r), _d(d2, r)
    denom = a * e - b * b
    # (parallel segments: denom == 0 and any s in [0, 1] will do, the clamping below repairs it)
    s = np.clip((b * f - c * e) / np.maximum(denom, 1e-300), 0.0, 1.0)
    t = (b * s + f) / e
    s = np.where(t < 0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    return s, np.clip(t, 0.0, 1.0)


def segment_segment_distance(p0, p1, q0, q1, return_params: bool = False):
    """Distance between segments ``p0-p1`` and ``q0-q1``, batched.

    Args:
        p0: (..., 3) end points of the first segments, metres.
        p1: (..., 3) end points of the first segments, metres.
        q0: (..., 3) end points of the second segments (broadcast against the first).
        q1: (..., 3) end points of the second segments (broadcast against the first).
        return_params: also return the closest-point parameters.

    Returns:
        (...,) distances in metres; with ``return_params`` a tuple ``(dist, s, t)`` where the
        closest points are ``p0 + s (p1 - p0)`` and ``q0 + t (q1 - q0)``, ``s, t`` in [0, 1].

    Raises:
        ValueError: wrong shapes, NaN/inf or a zero-length segment.

    Shapes:
        ``p0, p1, q0, q1 (..., 3)`` (broadcast) -> ``(...)`` metres.
    """
    p0, p1, _, q0, q1, _, shape = _prepare(p0, p1, 0.0, q0, q1, 0.0, 0.0)
    p0, p1, q0, q1 = _rows(p0), _rows(p1), _rows(q0), _rows(q1)
    d1, d2 = p1 - p0, q1 - q0
    _check_length(d1, "p0->p1")
    _check_length(d2, "q0->q1")
    s, t = _segment_closest(p0, d1, q0, d2)
    pq = q0 + t * d2 - p0 - s * d1
    dist = np.sqrt(_d(pq, pq)).reshape(shape)
    if return_params:
        return dist, s.reshape(shape), t.reshape(shape)
    return dist


def _inside(x, p0, v, length, r):
    """Is point x inside the solid cylinder (p0, unit axis v, length, radius r)? (3, K) -> (K,)."""
    w = x - p0
    tau = _d(w, v)
    rad = w - tau * v
    return (tau >= 0) & (tau <= length) & (_d(rad, rad) <= r * r)


def _disk_closest_to_line(c, n, r, p, v):
    """Point of each disk (centre c, unit normal n, radius r) nearest to the line ``p + t v``.

    The squared distance to the line, restricted to the disk's plane, is a convex quadratic
    ``y^T M y + 2 g^T y + const`` of in-plane coordinates ``y``, with ``M = diag(kappa, 1)``
    and ``kappa = (v . n)^2`` in a basis whose first axis is v's projection onto the plane.
    Minimising it over ``|y| <= r`` is a trust-region subproblem: either the unconstrained
    minimiser lies in the disk, or ``y = -(M + mu I)^-1 g`` on the circle, where ``mu >= 0``
    solves the secular equation ``|y(mu)| = r``: one unknown, solved by Newton on
    ``1/|y(mu)| - 1/r``, which is concave and increasing, so Newton started from a lower bound of
    the root rises monotonically onto it.

    Args: (3, K) c, n, p, v (n, v unit), (K,) r. Returns: (3, K) points.
    """
    vn = _d(v, n)
    kappa = vn * vn
    w = v - vn * n
    alpha = np.sqrt(_d(w, w))
    # In-plane basis: e1 along v's projection where that is well defined, e2 = n x e1.
    small = alpha <= 1e-8
    e1 = w / np.where(small, 1.0, alpha)
    if small.any():
        e1[:, small] = _any_perpendicular(n[:, small])
    e1 = e1 - _d(e1, n) * n  # re-orthogonalise: w carries rounding when alpha is small
    e1 /= np.sqrt(_d(e1, e1))
    e2 = _x(n, e1)
    alpha = np.where(small, 0.0, _d(v, e1))
    d = c - p
    g1 = _d(d, e1) - _d(v, d) * alpha
    g2 = _d(d, e2)
    y1 = np.zeros_like(g1)
    y2 = -g2
    # Unconstrained minimiser (-g1 / kappa, -g2) inside the disk? Division-free. When kappa == 0
    # (line parallel to the plane) and g1 == 0, a whole chord is optimal: y1 = 0 is one of it.
    # The chord is in the disk only if |g2| <= r: with kappa == 0 the first test reads
    # 0 <= 0 * (r^2 - g2^2), true (as -0.0) even for |g2| > r, so the second one is needed.
    inside = (g1 * g1 <= kappa * kappa * (r * r - g2 * g2)) & (g2 * g2 <= r * r)
    ok = inside & (kappa > 0)
    y1[ok] = -g1[ok] / kappa[ok]
    todo = np.flatnonzero(~inside & (r > 0))
    if todo.size:
        G1, G2, K, R = g1[todo], g2[todo], kappa[todo], r[todo]
        G1s, G2s = G1 * G1, G2 * G2
        # Lower bound of the root: |y(mu)| >= |g_i| / (lambda_i + mu).
        mu = np.maximum(np.maximum(np.abs(G1) / R - K, np.abs(G2) / R - 1.0), 0.0)
        for _ in range(50):
            q1, q2 = 1.0 / (K + mu), 1.0 / (1.0 + mu)
            a1, a2 = G1s * q1 * q1, G2s * q2 * q2
            ny2 = a1 + a2
            ny = np.sqrt(ny2)
            # psi = 1/|y| - 1/r, psi' = (sum g_i^2 / (lambda_i + mu)^3) / |y|^3
            step = (1.0 / R - 1.0 / ny) * ny2 * ny / (a1 * q1 + a2 * q2)
            mu = mu + np.maximum(step, 0.0)
            if (np.abs(step) <= 1e-13 * (1.0 + mu)).all():
                break
        Y1, Y2 = -G1 / (K + mu), -G2 / (1.0 + mu)
        scale = R / np.maximum(np.sqrt(Y1 * Y1 + Y2 * Y2), 1e-300)
        y1[todo], y2[todo] = Y1 * scale, Y2 * scale
    y2 = np.where(r > 0, y2, 0.0)
    return c + y1 * e1 + y2 * e2


def _disks_intersect(c1, n1, r1, c2, n2, r2):
    """Do two disks in 3-D intersect? (3, K) centres and unit normals, (K,) radii; closed form.

    Non-parallel planes meet in a line L. Disk i meets L in a chord iff its centre lies within
    ``r_i`` of L; inside its plane, the distance of c1 to L is ``|n2 . (c1 - c2)| / sin(theta)``.
    The disks intersect iff both chords exist and overlap along L, whose direction is
    ``n1 x n2 / sin(theta)``. Parallel planes intersect only when coplanar, and then it is 2-D.
    """
    m = _x(n1, n2)
    sin = np.sqrt(_d(m, m))
    dc = c1 - c2
    s21 = _d(n2, dc)        # signed distance of c1 from plane 2
    s12 = -_d(n1, dc)       # signed distance of c2 from plane 1
    par = sin <= _PARALLEL_SIN
    hit = np.zeros(sin.shape, dtype=bool)
    if par.any():
        dcp, n1p = dc[:, par], n1[:, par]
        inplane = dcp - _d(dcp, n1p) * n1p
        hit[par] = ((np.abs(s12[par]) <= _COPLANAR)
                    & (_d(inplane, inplane) <= (r1[par] + r2[par]) ** 2))
    npar = ~par
    if npar.any():
        sn = sin[npar]
        R1, R2, S21, S12 = r1[npar], r2[npar], s21[npar], s12[npar]
        reach = (np.abs(S21) <= R1 * sn) & (np.abs(S12) <= R2 * sn)
        h1 = np.sqrt(np.maximum(R1 * R1 - (S21 / sn) ** 2, 0.0))
        h2 = np.sqrt(np.maximum(R2 * R2 - (S12 / sn) ** 2, 0.0))
        along = np.abs(_d(m[:, npar], dc[:, npar])) / sn
        hit[npar] = reach & (along <= h1 + h2)
    return hit


def _cylinders_core(a0, a1, ra, b0, b1, rb, grow, early=False):
    """Exact test on validated (K, 3) end points and (K,) radii, after growing both cylinders by
    ``grow`` (radius and each end). Returns (K,) bool; with ``early`` it stops at the first stage
    that finds a hit (then only ``.any()`` of the result is meaningful)."""
    a0, a1, b0, b1 = a0.T, a1.T, b0.T, b1.T  # (3, K) views; order="C" below makes rows contiguous
    da = np.subtract(a1, a0, order="C")
    db = np.subtract(b1, b0, order="C")
    r = np.subtract(a0, b0, order="C")
    la2, lb2 = _check_length(da, "a0->a1"), _check_length(db, "b0->b1")
    rsum = ra + rb + 2 * grow
    out = np.zeros(la2.shape, dtype=bool)
    # 1. Infinite cylinders (K-L): reject when the common normal of the axis lines is longer than
    #    ra + rb: (r . n)^2 > (ra + rb)^2 |n|^2 with n = da x db (no division, no normalisation).
    #    Growing along the axes does not move the lines, so only the radii count here.
    n = _x(da, db)
    nn = _d(n, n)
    rn = _d(r, n)
    live = ~((nn > _AXES_PARALLEL_SIN ** 2 * la2 * lb2) & (rn * rn > rsum * rsum * nn))
    idx = np.flatnonzero(live)
    la, lb = np.sqrt(la2[idx]), np.sqrt(lb2[idx])
    U, V = da[:, idx] / la, db[:, idx] / lb
    out[idx] = _core_units(a0[:, idx] - grow * U, U, la + 2 * grow, ra[idx] + grow,
                           b0[:, idx] - grow * V, V, lb + 2 * grow, rb[idx] + grow, early)
    return out


def _core_units(A0, U, LA, RA, B0, V, LB, RB, early=False):
    """Stages 2-4 of the test on cylinders given as start point, unit axis, length, radius
    ((3, K) and (K,) arrays, already grown). Returns (K,) bool."""
    out = np.zeros(LA.shape, dtype=bool)
    # 2. Capsule rejection: closest points of the axis SEGMENTS further apart than ra + rb.
    s, t = _segment_closest(A0, U * LA, B0, V * LB)
    p = A0 + (s * LA) * U
    pq = B0 + (t * LB) * V - p
    rs = RA + RB
    idx = np.flatnonzero(_d(pq, pq) <= rs * rs)
    if idx.size == 0:
        return out
    if idx.size < LA.size:
        A0, U, LA, RA, p = A0[:, idx], U[:, idx], LA[idx], RA[idx], p[:, idx]
        B0, V, LB, RB, pq = B0[:, idx], V[:, idx], LB[idx], RB[idx], pq[:, idx]
    out[idx] = _exact_stages(A0, U, LA, RA, B0, V, LB, RB, p, pq, early)
    return out


def _exact_stages(A0, U, LA, RA, B0, V, LB, RB, p, pq, early=False):
    """Stages 3-4 for pairs whose capsules meet; ``p`` is the closest point on A's axis segment
    and ``pq`` the vector to the closest point on B's. (3, K)/(K,) -> (K,) bool."""
    # 3. Side touches side (K-L: both feet of the common normal inside the segments): the point z
    #    splitting the closest-point segment in the ratio ra : rb lies in both solids. It is a
    #    witness, checked rather than assumed, so near-parallel axes need no special case.
    z = p + (RA / np.maximum(RA + RB, 1e-300)) * pq
    out = _inside(z, A0, U, LA, RA) & _inside(z, B0, V, LB, RB)
    if early and out.any():
        return out
    rest = np.flatnonzero(~out)
    if rest.size == 0:
        return out
    if rest.size < out.size:
        A0, U, LA, RA = A0[:, rest], U[:, rest], LA[rest], RA[rest]
        B0, V, LB, RB = B0[:, rest], V[:, rest], LB[rest], RB[rest]
    # 4. One or both feet outside (K-L): then the solids meet iff an end-cap disk of one meets the
    #    other solid. A disk D meets solid B iff D meets one of B's cap disks (disk/disk, closed
    #    form), or the point of D nearest to B's axis line lies inside B (trust-region 1-D root).
    out[rest] = _caps_meet(A0, U, LA, RA, B0, V, LB, RB, early)
    return out


def _caps_meet(A0, U, LA, RA, B0, V, LB, RB, early=False):
    """Does an end-cap disk of A meet solid B, or one of B meet solid A? (3, K)/(K,) -> (K,) bool.

    The four disks of each pair (A's two caps against B, B's two caps against A) are stacked into
    one batch of 4K disk/solid problems, so each sub-test is one vectorised call. Cheap
    sufficient checks run first; pairs they decide drop out of the later, dearer ones.
    """
    K = LA.size
    A1, B1 = A0 + LA * U, B0 + LB * V
    # disk k of pair p is row p + k K: centre, normal, radius; and the solid it is tested against
    c = np.concatenate([A0, A1, B0, B1], axis=1)
    n = np.concatenate([U, U, V, V], axis=1)
    r = np.concatenate([RA, RA, RB, RB])
    o0 = np.concatenate([B0, B0, A0, A0], axis=1)
    ov = np.concatenate([V, V, U, U], axis=1)
    ol = np.concatenate([LB, LB, LA, LA])
    orad = np.concatenate([RB, RB, RA, RA])
    pair = np.tile(np.arange(K), 4)
    hit = np.zeros(K, dtype=bool)

    def drop(rows, found):
        """Record hits; return the rows whose pair is still undecided."""
        hit[pair[rows[found]]] = True
        rows = rows[~hit[pair[rows]]]
        return rows

    # A disk lies in the ball around its centre and the solid in its capsule: rows whose centre is
    # further than r + r_other from the other axis segment cannot meet and are dropped at once.
    # Likewise rows whose disk plane the other capsule does not reach (both axis ends further than
    # r_other from the plane, on the same side).
    w = c - o0
    h0 = -_d(w, n)
    h1 = h0 + ol * _d(ov, n)
    tau = np.clip(_d(w, ov), 0.0, ol)
    w -= tau * ov
    reach = r + orad
    near_plane = (np.minimum(h0, h1) <= orad) & (np.maximum(h0, h1) >= -orad)
    rows = np.flatnonzero((_d(w, w) <= reach * reach) & near_plane)
    if rows.size == 0:
        return hit
    # (a) a cap centre inside the other solid (covers coaxial and deep overlaps)
    rows = drop(rows, _inside(c[:, rows], o0[:, rows], ov[:, rows], ol[rows], orad[rows]))
    if rows.size == 0 or (early and hit.any()):
        return hit
    # (b) the disk's point nearest to the other axis lies inside the other solid
    x = _disk_closest_to_line(c[:, rows], n[:, rows], r[rows], o0[:, rows], ov[:, rows])
    rows = drop(rows, _inside(x, o0[:, rows], ov[:, rows], ol[rows], orad[rows]))
    if rows.size == 0 or (early and hit.any()):
        return hit
    # (c) cap disk against cap disk: A's caps (rows < 2K) against both caps of B
    rows = rows[rows < 2 * K]
    p = pair[rows]
    for cb in (B0, B1):
        found = _disks_intersect(c[:, rows], n[:, rows], r[rows], cb[:, p], V[:, p], RB[p])
        hit[p[found]] = True
    return hit


def cylinders_intersect(a0, a1, ra, b0, b1, rb, *, atol: float = ATOL,
                        backend: str | None = None) -> np.ndarray:
    """Exact intersection test for finite solid cylinders, batched (Ketchel–Larochelle structure).

    A cylinder is its axis end points and radius. The test follows Ketchel and Larochelle (2005):
    (1) reject when the common normal of the two axis lines is longer than ``ra + rb`` (the
    infinite cylinders are apart), then when the axis *segments* are further apart than
    ``ra + rb`` (the capsules are apart); (2) accept when the feet of the common normal lie inside
    both segments (side touches side), confirmed by a witness point inside both solids; (3)
    otherwise the cylinders meet iff an end-cap disk of one meets the other solid, decided exactly
    by disk/disk tests (closed form) and by the disk's point nearest to the other axis (a 1-D
    secular equation). Parallel, anti-parallel, coplanar and intersecting axes need no special case
    in (2) and (3); where a formula is ill-conditioned (parallel axes or disks) its limit is used.

    Tolerance: both cylinders are grown by ``atol / 2`` (radius, and length at each end) and the
    grown cylinders are tested exactly. So touching counts as intersecting, cylinders further apart
    than ``sqrt(2) * atol`` never do, and rounding cannot flip an answer. The rounding error of the
    kernels is ~1e-10 m for hand-scale sizes (lengths below ~0.3 m).

    Args:
        a0: (..., 3) first axis end points of the first cylinders, metres; ``a0 != a1``.
        a1: (..., 3) second axis end points of the first cylinders, metres.
        ra: (...,) radii of the first cylinders, metres, ``>= 0``.
        b0: (..., 3) axis end points of the second cylinders.
        b1: (..., 3) axis end points of the second cylinders.
        rb: (...,) radii of the second cylinders.
        atol: contact tolerance, metres (default 1e-9).
        backend: ``"numba"`` (compiled, one pair at a time), ``"numpy"`` (vectorised reference)
            or ``"auto"``; None: [`BACKEND`][handmesh_tutorial.collision.BACKEND]. Both give the
            same answers (tested).

    Returns:
        bool array of the broadcast batch shape (e.g. (N,) for (N, 3) inputs; (N, M) for
        (N, 1, 3) against (1, M, 3)).

    Raises:
        ValueError: wrong shapes, NaN/inf, negative radius, zero-length axis (names the argument).

    Shapes:
        ``a0, a1, b0, b1 (..., 3)``, ``ra, rb (...)`` (broadcast) -> ``(...)`` bool.

    Examples:
        >>> from handmesh_tutorial.collision import cylinders_intersect
        >>> a0, a1, b0, b1 = [0, 0, 0], [0, 0, 0.04], [0.019, 0, 0.02], [0.019, 0.04, 0.02]
        >>> cylinders_intersect(a0, a1, 0.01, b0, b1, 0.01)  # two 1-cm radii, axes 1.9 cm apart
        array(True)
        >>> cylinders_intersect([a0, a0], [a1, a1], 0.01, [b0, b0], [b1, b1], [0.01, 0.008])
        array([ True, False])
    """
    a0, a1, ra, b0, b1, rb, shape = _prepare(a0, a1, ra, b0, b1, rb, atol)
    nb = _kernels(backend)
    if nb is None:
        return _cylinders_core(a0, a1, ra, b0, b1, rb, 0.5 * atol).reshape(shape)
    out = np.empty(ra.shape, dtype=bool)
    if nb.cylinders_core(*_contig(a0, a1, ra, b0, b1, rb), 0.5 * atol, out) >= 0:
        _check_length(_rows(a1 - a0), "a0->a1")  # raises with the numpy path's message
        _check_length(_rows(b1 - b0), "b0->b1")
    return out.reshape(shape)


def capsules_intersect(a0, a1, ra, b0, b1, rb, *, atol: float = ATOL) -> np.ndarray:
    """Intersection test for capsules (segment swept by a ball): axis distance <= ra + rb + atol.

    A capsule contains the cylinder with the same axis and radius, so ``capsules_intersect`` is a
    conservative (it never misses a cylinder contact) and cheaper stand-in for
    [`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect]. The two differ
    near the end caps, where a capsule sticks out by up to its radius.

    Args:
        a0: (..., 3) axis end points of the first capsules, metres.
        a1: (..., 3) axis end points of the first capsules, metres.
        ra: (...,) radii, metres.
        b0: (..., 3) axis end points of the second capsules.
        b1: (..., 3) axis end points of the second capsules.
        rb: (...,) radii.
        atol: contact tolerance, metres.

    Returns:
        bool array of the broadcast batch shape.

    Raises:
        ValueError: as
            [`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect].

    Shapes:
        ``a0, a1, b0, b1 (..., 3)``, ``ra, rb (...)`` (broadcast) -> ``(...)`` bool.

    Examples:
        >>> from handmesh_tutorial.collision import capsules_intersect, cylinders_intersect
        >>> a0, a1 = [0, 0, 0], [0, 0, 0.04]  # 4 cm long, radius 1 cm
        >>> b0, b1 = [0.015, 0, 0.048], [0.015, 0, 0.088]  # past a's end cap, 1.5 cm aside
        >>> capsules_intersect(a0, a1, 0.01, b0, b1, 0.01)  # the round caps meet...
        array(True)
        >>> cylinders_intersect(a0, a1, 0.01, b0, b1, 0.01)  # ...the flat-capped solids do not
        array(False)
    """
    a0, a1, ra, b0, b1, rb, shape = _prepare(a0, a1, ra, b0, b1, rb, atol)
    a0, a1, b0, b1 = _rows(a0), _rows(a1), _rows(b0), _rows(b1)
    da, db = a1 - a0, b1 - b0
    _check_length(da, "a0->a1")
    _check_length(db, "b0->b1")
    s, t = _segment_closest(a0, da, b0, db)
    pq = b0 + t * db - a0 - s * da
    rs = ra + rb + atol
    return (_d(pq, pq) <= rs * rs).reshape(shape)
