"""An independent oracle for the exact test: lower and upper bounds on the distance between two
solid cylinders (alternating projections, separating slabs, SLSQP refinement).

It shares no code with
[`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect] (only the input
checks and the closed forms of ``distance.py``); the tests certify the exact test against it. Taught
in notebook 03 (cylinder collision).
"""

from __future__ import annotations

import numpy as np

from ._common import _prepare
from .distance import _project, cylinder_support, point_cylinder_distance

__all__ = ["distance_bounds"]


def distance_bounds(a0, a1, ra, b0, b1, rb, *, iters: int = 2000, tol: float = 1e-13,
                    refine_at: float | None = None, return_points: bool = False):
    """Lower and upper bounds on the distance between two solid cylinders: an independent oracle.

    Nothing here shares code with
    [`cylinders_intersect`][handmesh_tutorial.collision.exact.cylinders_intersect]. The upper bound
    is ``|x - y|`` for points ``x`` in A and ``y`` in B from alternating projections (von Neumann;
    they converge to a closest pair, or to a common point when the solids meet). The lower bound is
    the width of a separating slab: for a unit ``n``, every point of B is at least ``-h_B(-n) -
    h_A(n)`` further along n than every point of A (support functions,
    [`cylinder_support`][handmesh_tutorial.collision.distance.cylinder_support]), tried for the
    current ``y - x`` and for the axes and their cross product. Two convex solids meet iff their
    distance is 0, so ``upper <= eps`` certifies contact within eps and ``lower > eps`` certifies a
    gap larger than eps. Iterations stop per pair once ``upper - lower <= tol``. Near tangent
    contact the projections converge slowly and the bounds may stay apart; pairs for which the
    bounds do not yet decide whether the distance is at most ``refine_at`` (``lower <= refine_at <
    upper``) are then refined one by one with SciPy's SLSQP: the deepest point inside both solids
    (maximise the margin ``delta`` with ``x`` at least ``delta`` inside A and B) and the widest
    separating slab (maximise over unit ``n``). Both results are re-checked with the closed forms
    of ``distance.py``, so the bounds stay valid whatever the optimiser does.

    Args:
        a0: (N, 3) axis end points of the first cylinders, metres.
        a1: (N, 3) axis end points of the first cylinders, metres.
        ra: (N,) radii.
        b0: (N, 3) axis end points of the second cylinders.
        b1: (N, 3) axis end points of the second cylinders.
        rb: (N,) radii.
        iters: maximum number of projection rounds.
        tol: stop when the bounds are this close, metres.
        refine_at: a distance threshold (metres) the bounds should decide; None: no refinement.
        return_points: also return the best projection pair.

    Returns:
        ``(lower, upper)``, two (N,) arrays in metres, ``0 <= lower <= distance <= upper``; with
        ``return_points`` also ``x`` (N, 3) in A and ``y`` (N, 3) in B with ``|x - y| = upper``.

    Shapes:
        ``a0, a1, b0, b1 (N, 3)``, ``ra, rb (N,)`` -> ``lower, upper (N,)`` metres
        (and ``x, y (N, 3)``).
    """
    a0, a1, ra, b0, b1, rb, _ = _prepare(a0, a1, ra, b0, b1, rb, 0.0)
    n_pairs = len(a0)
    u = (a1 - a0) / np.linalg.norm(a1 - a0, axis=1)[:, None]
    v = (b1 - b0) / np.linalg.norm(b1 - b0, axis=1)[:, None]

    def gap(n, i):
        n = n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
        return -cylinder_support(-n, b0[i], b1[i], rb[i]) - cylinder_support(n, a0[i], a1[i], ra[i])

    everyone = np.arange(n_pairs)
    lower = np.full(n_pairs, -np.inf)
    for n in (u, v, np.cross(u, v)):
        lower = np.maximum(lower, np.maximum(gap(n, everyone), gap(-n, everyone)))
    upper = np.full(n_pairs, np.inf)
    best_x, best_y = np.zeros((n_pairs, 3)), np.zeros((n_pairs, 3))
    act = everyone
    y = 0.5 * (b0 + b1)
    for _ in range(iters):
        x = _project(y, a0[act], a1[act], ra[act])
        y = _project(x, b0[act], b1[act], rb[act])
        d = y - x
        dn = np.linalg.norm(d, axis=1)
        better = dn <= upper[act]
        upper[act[better]] = dn[better]
        best_x[act[better]], best_y[act[better]] = x[better], y[better]
        pos = dn > 0
        if pos.any():
            lower[act[pos]] = np.maximum(lower[act[pos]], gap(d[pos], act[pos]))
        done = upper[act] - np.maximum(lower[act], 0.0) <= tol
        act, y = act[~done], y[~done]
        if act.size == 0:
            break
    lower = np.maximum(lower, 0.0)
    if refine_at is not None:
        for k in np.flatnonzero((lower <= refine_at) & (upper > refine_at)):
            d = best_y[k] - best_x[k]
            nd = np.linalg.norm(d)
            n0 = d / nd if nd > 0 else np.cross(u[k], v[k]) + 1e-3 * u[k]
            lk, hk = _refine_bounds(a0[k], a1[k], ra[k], b0[k], b1[k], rb[k],
                                    0.5 * (best_x[k] + best_y[k]), n0 / np.linalg.norm(n0))
            lower[k], upper[k] = max(lower[k], lk), min(upper[k], hk)
    if return_points:
        return lower, upper, best_x, best_y
    return lower, upper


def _refine_bounds(a0, a1, ra, b0, b1, rb, x0, n0):
    """One pair: (lower, upper) distance bounds from two SLSQP searches (see distance_bounds)."""
    from scipy.optimize import minimize

    la, lb = np.linalg.norm(a1 - a0), np.linalg.norm(b1 - b0)
    u, v = (a1 - a0) / la, (b1 - b0) / lb
    s = 1e-2  # work in centimetres: SLSQP's tolerances are absolute

    def margin(p0, w, length, r):
        def f(z):
            x, d = z[:3], z[3]
            q = x - p0
            tau = q @ w
            rad = q - tau * w
            return np.array([tau - d, length - tau - d, (r - d) ** 2 - rad @ rad, r - d]) / s
        return f

    res = minimize(lambda z: -z[3] / s, np.r_[x0, 0.0], method="SLSQP",
                   constraints=[{"type": "ineq", "fun": margin(a0, u, la, ra)},
                                {"type": "ineq", "fun": margin(b0, v, lb, rb)}],
                   options={"ftol": 1e-16, "maxiter": 200})
    x = res.x[:3]
    upper = float(point_cylinder_distance(x, a0, a1, ra) + point_cylinder_distance(x, b0, b1, rb))

    def gap(n):
        n = n / np.linalg.norm(n)
        return float(-cylinder_support(-n, b0, b1, rb) - cylinder_support(n, a0, a1, ra))

    def slab(z):  # n.(b_j - a_i) - ra |n_perp_u| - rb |n_perp_v| >= gamma, epigraph alpha, beta
        n, al, be, g = z[:3], z[3], z[4], z[5]
        pu, pv = n - (n @ u) * u, n - (n @ v) * v
        c = [n @ bj - n @ ai - ra * al - rb * be - g for ai in (a0, a1) for bj in (b0, b1)]
        return np.array(c + [al * al - pu @ pu, be * be - pv @ pv, al, be, 1 - n @ n]) / s

    pu, pv = n0 - (n0 @ u) * u, n0 - (n0 @ v) * v
    z0 = np.r_[n0, np.linalg.norm(pu), np.linalg.norm(pv), gap(n0)]
    res2 = minimize(lambda z: -z[5] / s, z0, method="SLSQP",
                    constraints=[{"type": "ineq", "fun": slab}],
                    options={"ftol": 1e-16, "maxiter": 200})
    lower = gap(n0)
    if np.linalg.norm(res2.x[:3]) > 0:
        lower = max(lower, gap(res2.x[:3]))
    return max(lower, 0.0), upper
