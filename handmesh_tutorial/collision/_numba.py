"""Compiled (numba) kernels of the exact cylinder test: one pair at a time, scalar code.

This is the fast path of `handmesh_tutorial.collision`; the numpy functions of ``exact.py`` and
``queries.py`` remain the reference and the fallback when numba is missing. Each function below
mirrors one numpy kernel operation for operation (same formulas, same order of floating-point
operations, no ``fastmath``), so both paths compute the same numbers; they differ only in control
flow: the scalar code stops at the first stage that decides a pair, and the trust-region Newton
iteration stops per pair rather than when the whole batch has converged (a difference of at most a
few ulps in a point that is then tested against a tolerance of ``atol``).
``tests/test_collision.py`` compares the two paths on random, near-contact, near-parallel and
degenerate pairs.

Why scalar code: the numpy path is a sequence of whole-array passes, each of which reads and writes
(K,) temporaries and compacts the survivors of each stage; most pairs are decided by a cheap
rejection test, so memory traffic and per-stage bookkeeping dominate. One compiled loop keeps a pair
in registers from the first stage to the last and allocates nothing.

3-vectors are passed as tuples of three floats (numba keeps them in registers).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the tolerances of the numpy path (one copy, in _common.py; numba freezes them when compiling)
from ._common import _AXES_PARALLEL_SIN, _COPLANAR, _PARALLEL_SIN

_jit = njit(cache=True, error_model="numpy", nogil=True)


@_jit
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@_jit
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@_jit
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@_jit
def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@_jit
def _mul(s, a):
    return (s * a[0], s * a[1], s * a[2])


@_jit
def _div(a, s):
    return (a[0] / s, a[1] / s, a[2] / s)


@_jit
def _clip01(x):
    return min(max(x, 0.0), 1.0)


@_jit
def _segment_closest(p0, d1, q0, d2):
    """exact._segment_closest for one pair: parameters (s, t) in [0, 1]."""
    r = _sub(p0, q0)
    a, e = _dot(d1, d1), _dot(d2, d2)
    b, c, f = _dot(d1, d2), _dot(d1, r), _dot(d2, r)
    denom = a * e - b * b
    s = _clip01((b * f - c * e) / max(denom, 1e-300))
    t = (b * s + f) / e
    if t < 0:
        s = _clip01(-c / a)
    elif t > 1:
        s = _clip01((b - c) / a)
    return s, _clip01(t)


@_jit
def _inside(x, p0, v, length, r):
    """exact._inside: is point x in the solid cylinder (p0, unit v, length, r)?"""
    w = _sub(x, p0)
    tau = _dot(w, v)
    rad = _sub(w, _mul(tau, v))
    return (tau >= 0) and (tau <= length) and (_dot(rad, rad) <= r * r)


@_jit
def _any_perpendicular(n):
    if abs(n[0]) < 0.9:
        e = _cross(n, (1.0, 0.0, 0.0))
    else:
        e = _cross(n, (0.0, 1.0, 0.0))
    return _div(e, math.sqrt(_dot(e, e)))


@_jit
def _disk_closest_to_line(c, n, r, p, v):
    """exact._disk_closest_to_line for one disk: its point nearest to the line p + t v."""
    vn = _dot(v, n)
    kappa = vn * vn
    w = _sub(v, _mul(vn, n))
    alpha = math.sqrt(_dot(w, w))
    small = alpha <= 1e-8
    if small:
        e1 = _any_perpendicular(n)
    else:
        e1 = _div(w, alpha)
    e1 = _sub(e1, _mul(_dot(e1, n), n))
    e1 = _div(e1, math.sqrt(_dot(e1, e1)))
    e2 = _cross(n, e1)
    alpha = 0.0 if small else _dot(v, e1)
    d = _sub(c, p)
    g1 = _dot(d, e1) - _dot(v, d) * alpha
    g2 = _dot(d, e2)
    y1 = 0.0
    y2 = -g2
    inside = (g1 * g1 <= kappa * kappa * (r * r - g2 * g2)) and (g2 * g2 <= r * r)
    if inside and kappa > 0:
        y1 = -g1 / kappa
    if (not inside) and r > 0:
        g1s, g2s = g1 * g1, g2 * g2
        mu = max(max(abs(g1) / r - kappa, abs(g2) / r - 1.0), 0.0)
        for _ in range(50):
            q1, q2 = 1.0 / (kappa + mu), 1.0 / (1.0 + mu)
            a1, a2 = g1s * q1 * q1, g2s * q2 * q2
            ny2 = a1 + a2
            ny = math.sqrt(ny2)
            step = (1.0 / r - 1.0 / ny) * ny2 * ny / (a1 * q1 + a2 * q2)
            mu = mu + max(step, 0.0)
            if abs(step) <= 1e-13 * (1.0 + mu):
                break
        Y1, Y2 = -g1 / (kappa + mu), -g2 / (1.0 + mu)
        scale = r / max(math.sqrt(Y1 * Y1 + Y2 * Y2), 1e-300)
        y1, y2 = Y1 * scale, Y2 * scale
    if not r > 0:
        y2 = 0.0
    return _add(_add(c, _mul(y1, e1)), _mul(y2, e2))


@_jit
def _disks_intersect(c1, n1, r1, c2, n2, r2):
    """exact._disks_intersect for one pair of disks (closed form)."""
    m = _cross(n1, n2)
    sin = math.sqrt(_dot(m, m))
    dc = _sub(c1, c2)
    s21 = _dot(n2, dc)
    s12 = -_dot(n1, dc)
    if sin <= _PARALLEL_SIN:
        inplane = _sub(dc, _mul(_dot(dc, n1), n1))
        rr = r1 + r2
        return abs(s12) <= _COPLANAR and _dot(inplane, inplane) <= rr * rr
    reach = abs(s21) <= r1 * sin and abs(s12) <= r2 * sin
    q1, q2 = s21 / sin, s12 / sin
    h1 = math.sqrt(max(r1 * r1 - q1 * q1, 0.0))
    h2 = math.sqrt(max(r2 * r2 - q2 * q2, 0.0))
    along = abs(_dot(m, dc)) / sin
    return reach and along <= h1 + h2


@_jit
def _cap_row_live(c, n, r, o0, ov, ol, orad):
    """The cheap prefilter of exact._caps_meet: can this cap disk meet the other solid?"""
    w = _sub(c, o0)
    h0 = -_dot(w, n)
    h1 = h0 + ol * _dot(ov, n)
    tau = min(max(_dot(w, ov), 0.0), ol)
    w = _sub(w, _mul(tau, ov))
    reach = r + orad
    near_plane = (min(h0, h1) <= orad) and (max(h0, h1) >= -orad)
    return (_dot(w, w) <= reach * reach) and near_plane


@_jit
def _caps_meet(A0, U, LA, RA, B0, V, LB, RB):
    """exact._caps_meet for one pair: does an end-cap disk of one meet the other solid?"""
    A1 = _add(A0, _mul(LA, U))
    B1 = _add(B0, _mul(LB, V))
    live0 = _cap_row_live(A0, U, RA, B0, V, LB, RB)
    live1 = _cap_row_live(A1, U, RA, B0, V, LB, RB)
    live2 = _cap_row_live(B0, V, RB, A0, U, LA, RA)
    live3 = _cap_row_live(B1, V, RB, A0, U, LA, RA)
    # (a) a cap centre inside the other solid
    if live0 and _inside(A0, B0, V, LB, RB):
        return True
    if live1 and _inside(A1, B0, V, LB, RB):
        return True
    if live2 and _inside(B0, A0, U, LA, RA):
        return True
    if live3 and _inside(B1, A0, U, LA, RA):
        return True
    # (b) the disk's point nearest to the other axis lies inside the other solid
    if live0 and _inside(_disk_closest_to_line(A0, U, RA, B0, V), B0, V, LB, RB):
        return True
    if live1 and _inside(_disk_closest_to_line(A1, U, RA, B0, V), B0, V, LB, RB):
        return True
    if live2 and _inside(_disk_closest_to_line(B0, V, RB, A0, U), A0, U, LA, RA):
        return True
    if live3 and _inside(_disk_closest_to_line(B1, V, RB, A0, U), A0, U, LA, RA):
        return True
    # (c) A's cap disks against B's cap disks
    if live0 and (_disks_intersect(A0, U, RA, B0, V, RB) or _disks_intersect(A0, U, RA, B1, V, RB)):
        return True
    if live1 and (_disks_intersect(A1, U, RA, B0, V, RB) or _disks_intersect(A1, U, RA, B1, V, RB)):
        return True
    return False


@_jit
def _core_units(A0, U, LA, RA, B0, V, LB, RB):
    """exact._core_units for one pair (stages 2-4 on grown cylinders, unit axes)."""
    s, t = _segment_closest(A0, _mul(LA, U), B0, _mul(LB, V))
    p = _add(A0, _mul(s * LA, U))
    pq = _sub(_add(B0, _mul(t * LB, V)), p)
    rs = RA + RB
    if not _dot(pq, pq) <= rs * rs:
        return False
    z = _add(p, _mul(RA / max(RA + RB, 1e-300), pq))
    if _inside(z, A0, U, LA, RA) and _inside(z, B0, V, LB, RB):
        return True
    return _caps_meet(A0, U, LA, RA, B0, V, LB, RB)


@_jit
def _vec(a, k):
    return (a[k, 0], a[k, 1], a[k, 2])


@_jit
def cylinders_core(a0, a1, ra, b0, b1, rb, grow, out):
    """exact._cylinders_core over K pairs: (K, 3) end points, (K,) radii -> out (K,) bool.

    Returns -1, or the first index whose A axis (then B axis) has zero length, times 2 (+1 for B),
    so the caller can raise the numpy path's error; ``out`` is then incomplete.
    """
    K = out.shape[0]
    for k in range(K):
        pa0, pb0 = _vec(a0, k), _vec(b0, k)
        da = _sub(_vec(a1, k), pa0)
        db = _sub(_vec(b1, k), pb0)
        la2, lb2 = _dot(da, da), _dot(db, db)
        if not la2 > 0:
            return 2 * k
        if not lb2 > 0:
            return 2 * k + 1
        r = _sub(pa0, pb0)
        rsum = ra[k] + rb[k] + 2 * grow
        # 1. infinite cylinders apart (Ketchel-Larochelle), division-free
        n = _cross(da, db)
        nn = _dot(n, n)
        rn = _dot(r, n)
        if (nn > _AXES_PARALLEL_SIN ** 2 * la2 * lb2) and (rn * rn > rsum * rsum * nn):
            out[k] = False
            continue
        la, lb = math.sqrt(la2), math.sqrt(lb2)
        U, V = _div(da, la), _div(db, lb)
        out[k] = _core_units(_sub(pa0, _mul(grow, U)), U, la + 2 * grow, ra[k] + grow,
                             _sub(pb0, _mul(grow, V)), V, lb + 2 * grow, rb[k] + grow)
    return -1


@_jit
def units(p0, p1, radius, grow, s0, u, length, rad):
    """queries._units into preallocated (N, 3), (N, 3), (N,), (N,) arrays; False: zero axis."""
    for k in range(p0.shape[0]):
        d = _sub(_vec(p1, k), _vec(p0, k))
        ln = math.sqrt(_dot(d, d))
        if not ln > 0:
            return False
        uk = _div(d, ln)
        sk = _sub(_vec(p0, k), _mul(grow, uk))
        for c in range(3):
            u[k, c] = uk[c]
            s0[k, c] = sk[c]
        length[k] = ln + 2 * grow
        rad[k] = radius[k] + grow
    return True


@_jit
def _pair(s0a, ua, la, ra, i, s0b, ub, lb, rb, j):
    return _core_units(_vec(s0a, i), _vec(ua, i), la[i], ra[i],
                       _vec(s0b, j), _vec(ub, j), lb[j], rb[j])


@_jit
def _aabb_apart(p0a, p1a, ra, p0b, p1b, rb, atol):
    """queries.bodies_collide's whole-body bounding-box rejection."""
    for c in range(3):
        lo_a, hi_a, lo_b, hi_b = np.inf, -np.inf, np.inf, -np.inf
        for k in range(p0a.shape[0]):
            lo_a = min(lo_a, min(p0a[k, c], p1a[k, c]) - ra[k])
            hi_a = max(hi_a, max(p0a[k, c], p1a[k, c]) + ra[k])
        for k in range(p0b.shape[0]):
            lo_b = min(lo_b, min(p0b[k, c], p1b[k, c]) - rb[k])
            hi_b = max(hi_b, max(p0b[k, c], p1b[k, c]) + rb[k])
        if lo_a > hi_b + atol or lo_b > hi_a + atol:
            return True
    return False


@_jit
def _body_units(p0a, p1a, rada, p0b, p1b, radb, atol):
    """Grown unit axes of two bodies: ``(ok, sa, ua, la, ra, sb, ub, lb, rb)``; ok False on a
    zero-length axis (the arrays are then incomplete)."""
    na, nb = p0a.shape[0], p0b.shape[0]
    grow = 0.5 * atol
    sa, ua, la, ra = np.empty((na, 3)), np.empty((na, 3)), np.empty(na), np.empty(na)
    sb, ub, lb, rb = np.empty((nb, 3)), np.empty((nb, 3)), np.empty(nb), np.empty(nb)
    ok = (units(p0a, p1a, rada, grow, sa, ua, la, ra)
          and units(p0b, p1b, radb, grow, sb, ub, lb, rb))
    return ok, sa, ua, la, ra, sb, ub, lb, rb


@_jit
def bodies_collide(p0a, p1a, rada, p0b, p1b, radb, atol):
    """queries.bodies_collide on raw arrays: 1 hit, 0 none, -1 zero-length axis."""
    if _aabb_apart(p0a, p1a, rada, p0b, p1b, radb, atol):
        return 0
    ok, sa, ua, la, ra, sb, ub, lb, rb = _body_units(p0a, p1a, rada, p0b, p1b, radb, atol)
    if not ok:
        return -1
    na, nb = p0a.shape[0], p0b.shape[0]
    for i in range(na):
        for j in range(nb):
            if _pair(sa, ua, la, ra, i, sb, ub, lb, rb, j):
                return 1
    return 0


@_jit
def all_pairs(p0a, p1a, rada, p0b, p1b, radb, atol, hit):
    """queries.colliding_pairs on raw arrays into hit (NA, NB) bool; False on a zero axis."""
    ok, sa, ua, la, ra, sb, ub, lb, rb = _body_units(p0a, p1a, rada, p0b, p1b, radb, atol)
    if not ok:
        return False
    na, nb = p0a.shape[0], p0b.shape[0]
    for i in range(na):
        for j in range(nb):
            hit[i, j] = _pair(sa, ua, la, ra, i, sb, ub, lb, rb, j)
    return True


@_jit
def listed_pairs(p0, p1, radius, ii, jj, atol, hit):
    """queries._pairs_test of one body with itself on listed pairs (ii[k], jj[k]) into hit."""
    n = p0.shape[0]
    s, u, ln, rad = np.empty((n, 3)), np.empty((n, 3)), np.empty(n), np.empty(n)
    if not units(p0, p1, radius, 0.5 * atol, s, u, ln, rad):
        return False
    for k in range(ii.shape[0]):
        hit[k] = _pair(s, u, ln, rad, ii[k], s, u, ln, rad, jj[k])
    return True
