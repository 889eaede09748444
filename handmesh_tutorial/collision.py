"""Collision detection between finite solid cylinders (Ketchel–Larochelle), capsules and bodies.

The INTER-SH generator (paper, supplementary "Generating Mesh Interactions") approximates hands and
objects by cylinders and annuli and moves them until two primitives intersect. This module holds:

* [`Cylinders`][handmesh_tutorial.collision.Cylinders]: a body (hand, object, chain) as a batch of
cylinders, metres.
* [`cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect]: exact, batched test for
finite solid cylinders.
* [`capsules_intersect`][handmesh_tutorial.collision.capsules_intersect]: the simple conservative
alternative (a cylinder lies in its capsule).
* scene queries [`bodies_collide`][handmesh_tutorial.collision.bodies_collide],
[`colliding_pairs`][handmesh_tutorial.collision.colliding_pairs],
[`self_collisions`][handmesh_tutorial.collision.self_collisions].
* the hand as cylinders: [`hand_cylinders`][handmesh_tutorial.collision.hand_cylinders],
[`fit_cylinders`][handmesh_tutorial.collision.fit_cylinders],
[`coverage`][handmesh_tutorial.collision.coverage].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def _as_points(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {tuple(np.shape(x))}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf")
    return a


@dataclass
class Cylinders:
    """A body as a batch of finite solid cylinders (axis end points and radius), in metres.

    Attributes:
        p0: (N, 3) float64, first axis end point of each cylinder, metres.
        p1: (N, 3) float64, second axis end point, metres.
        radius: (N,) float64, radius, metres.
        names: N names, e.g. ``"index_1"`` or ``"palm_middle"``.
        parts: (N,) int, the part (finger, link, ...) of each cylinder; informative only.
        adjacent: (M, 2) int, pairs ``(i, j)`` with ``i < j`` of cylinders of this body that touch
            by design (they share a joint);
            [`self_collisions`][handmesh_tutorial.collision.self_collisions] skips them.
    """

    p0: np.ndarray
    p1: np.ndarray
    radius: np.ndarray
    names: tuple[str, ...] = ()
    parts: np.ndarray = field(default=None)  # type: ignore[assignment]
    adjacent: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self):
        self.p0 = _as_points(self.p0, "p0")
        self.p1 = _as_points(self.p1, "p1")
        n = len(self.p0)
        if self.p1.shape != (n, 3):
            raise ValueError(f"p1 must have shape ({n}, 3) like p0, got {self.p1.shape}")
        self.radius = np.asarray(self.radius, dtype=np.float64).reshape(-1)
        if self.radius.shape == (1,) and n != 1:
            self.radius = np.full(n, self.radius[0])
        if self.radius.shape != (n,):
            raise ValueError(f"radius must have shape ({n},), got {self.radius.shape}")
        if not np.all(np.isfinite(self.radius)) or np.any(self.radius < 0):
            raise ValueError("radius must be finite and non-negative")
        if not self.names:
            self.names = tuple(f"cyl{i}" for i in range(n))
        self.names = tuple(str(s) for s in self.names)
        if len(self.names) != n:
            raise ValueError(f"names must have {n} entries, got {len(self.names)}")
        self.parts = (np.zeros(n, dtype=np.int64) if self.parts is None
                      else np.asarray(self.parts, dtype=np.int64).reshape(-1))
        if self.parts.shape != (n,):
            raise ValueError(f"parts must have shape ({n},), got {self.parts.shape}")
        adj = (np.zeros((0, 2), dtype=np.int64) if self.adjacent is None
               else np.asarray(self.adjacent, dtype=np.int64).reshape(-1, 2))
        if adj.size and (adj.min() < 0 or adj.max() >= n):
            raise ValueError(f"adjacent holds indices outside [0, {n})")
        self.adjacent = np.unique(np.sort(adj, axis=1), axis=0) if adj.size else adj

    def __len__(self) -> int:
        return len(self.p0)

    @property
    def length(self) -> np.ndarray:
        """(N,) axis lengths, metres."""
        return np.linalg.norm(self.p1 - self.p0, axis=1)

    def transform(self, R, t) -> Cylinders:
        """Rigidly move the body: ``p -> R @ p + t``.

        Args:
            R: (3, 3) rotation matrix.
            t: (3,) translation, metres.

        Returns:
            A new [`Cylinders`][handmesh_tutorial.collision.Cylinders] (names, parts and adjacency
            kept).
        """
        R = np.asarray(R, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        if R.shape != (3, 3):
            raise ValueError(f"R must have shape (3, 3), got {R.shape}")
        if t.shape != (3,):
            raise ValueError(f"t must have shape (3,), got {t.shape}")
        return Cylinders(self.p0 @ R.T + t, self.p1 @ R.T + t, self.radius.copy(), self.names,
                         self.parts.copy(), self.adjacent.copy())

    def subset(self, index) -> Cylinders:
        """The cylinders selected by ``index`` (int array or bool mask); adjacency re-indexed."""
        idx = np.arange(len(self))[index]
        remap = -np.ones(len(self), dtype=np.int64)
        remap[idx] = np.arange(len(idx))
        adj = remap[self.adjacent] if len(self.adjacent) else self.adjacent
        adj = adj[(adj >= 0).all(axis=1)] if len(adj) else adj
        return Cylinders(self.p0[idx], self.p1[idx], self.radius[idx],
                         tuple(self.names[i] for i in idx), self.parts[idx], adj)

    @staticmethod
    def concat(bodies) -> Cylinders:
        """Join several bodies into one; adjacency indices are offset, parts kept as given.

        Args:
            bodies: a sequence of [`Cylinders`][handmesh_tutorial.collision.Cylinders].

        Returns:
            One [`Cylinders`][handmesh_tutorial.collision.Cylinders] with all cylinders in order.
        """
        bodies = list(bodies)
        if not bodies:
            raise ValueError("concat needs at least one Cylinders")
        offsets = np.cumsum([0] + [len(b) for b in bodies[:-1]])
        return Cylinders(
            np.concatenate([b.p0 for b in bodies]), np.concatenate([b.p1 for b in bodies]),
            np.concatenate([b.radius for b in bodies]),
            tuple(n for b in bodies for n in b.names),
            np.concatenate([b.parts for b in bodies]),
            np.concatenate([b.adjacent + o for b, o in zip(bodies, offsets, strict=True)]),
        )


# --------------------------------------------------------------------------------------------------
# Tolerances. Everything is in metres and tuned for hand-scale primitives (lengths below ~0.3 m).
# --------------------------------------------------------------------------------------------------

ATOL = 1e-9
"""Default contact tolerance of the tests, metres: cylinders are grown by ``atol / 2`` (radius and
each end) before an exact test, so touching counts as intersecting and rounding cannot flip it.
"""
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


BACKEND: str = "numpy"
"""Which implementation the exact tests use: ``"numpy"`` (the vectorised reference below, the
default), ``"numba"`` (the compiled kernels of ``handmesh_tutorial._collision_numba``, opt-in: docs
page "Performance" says why it is not the default) or ``"auto"`` (numba when it imports, else
numpy). Every public test also takes ``backend=``."""
_NUMBA_STATE: list = []  # [module or None], filled on first use (numba imports in ~0.3 s)


def _kernels(backend):
    """The numba kernels module for this call, or None for the numpy path."""
    backend = BACKEND if backend is None else backend
    if backend == "numpy":
        return None
    if backend not in ("auto", "numba"):
        raise ValueError(f"backend must be 'auto', 'numba' or 'numpy', got {backend!r}")
    if not _NUMBA_STATE:
        try:
            from . import _collision_numba
        except ImportError:
            _collision_numba = None
        _NUMBA_STATE.append(_collision_numba)
    if _NUMBA_STATE[0] is None and backend == "numba":
        raise ImportError("backend='numba' needs the numba package (pip install numba)")
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


def _any_perpendicular(n):
    """A unit vector perpendicular to each unit column of n (3, K)."""
    helper = np.zeros_like(n)
    use_x = np.abs(n[0]) < 0.9
    helper[0, use_x] = 1.0
    helper[1, ~use_x] = 1.0
    e = _x(n, helper)
    return e / np.sqrt(_d(e, e))


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
    inside = g1 * g1 <= kappa * kappa * (r * r - g2 * g2)
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

    Example:
        >>> a0, a1, b0, b1 = [0, 0, 0], [0, 0, 0.04], [0.019, 0, 0.02], [0.019, 0.04, 0.02]
        >>> cylinders_intersect(a0, a1, 0.01, b0, b1, 0.01)
        array(True)
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
    [`cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect]. The two differ near
    the end caps, where a capsule sticks out by up to its radius.

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
        ValueError: as [`cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect].
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


# --------------------------------------------------------------------------------------------------
# Reference geometry: distances, projections, support functions and an independent oracle.
# --------------------------------------------------------------------------------------------------


def _pts(x, name):
    a = _check_points(x, name)
    return a.reshape(-1, 3)


def point_cylinder_distance(points, p0, p1, radius) -> np.ndarray:
    """Euclidean distance from points to solid cylinders (0 inside), broadcast.

    A solid cylinder is the product of an interval (along the axis) and a disk (across it), so the
    distance is ``hypot(max(rho - r, 0), max(-tau, tau - L, 0))`` with ``tau`` the axial and
    ``rho`` the radial coordinate.

    Args:
        points: (..., 3) query points, metres.
        p0: (..., 3) axis end points, metres.
        p1: (..., 3) axis end points, metres.
        radius: (...,) radii, metres.

    Returns:
        (...,) distances, metres.
    """
    x, p0, p1 = (_check_points(a, n) for a, n in ((points, "points"), (p0, "p0"), (p1, "p1")))
    r = _check_radius(radius, "radius")
    d = p1 - p0
    length = np.linalg.norm(d, axis=-1)
    if not (length > 0).all():
        raise ValueError("axis p0->p1 has zero length")
    u = d / length[..., None]
    w = x - p0
    tau = np.sum(w * u, axis=-1)
    rho = np.linalg.norm(w - tau[..., None] * u, axis=-1)
    return np.hypot(np.maximum(rho - r, 0.0), np.maximum(np.maximum(-tau, tau - length), 0.0))


def project_to_cylinder(points, p0, p1, radius) -> np.ndarray:
    """Nearest point of each solid cylinder to each point (Euclidean projection), broadcast.

    Clamp the axial coordinate to ``[0, L]`` and the radial vector to length ``<= r``; this is the
    exact projection because the cylinder is a product of an interval and a disk in orthogonal
    coordinates.

    Args:
        points: (..., 3) points, metres.
        p0: (..., 3) axis end points.
        p1: (..., 3) axis end points.
        radius: (...,) radii.

    Returns:
        (..., 3) projected points, metres.
    """
    d = p1 - p0
    length = np.linalg.norm(d, axis=-1)
    u = d / length[..., None]
    w = points - p0
    tau = np.sum(w * u, axis=-1)
    rad = w - tau[..., None] * u
    rho = np.linalg.norm(rad, axis=-1)
    f = np.minimum(1.0, radius / np.maximum(rho, 1e-300))
    return p0 + np.clip(tau, 0.0, length)[..., None] * u + f[..., None] * rad


def cylinder_support(directions, p0, p1, radius) -> np.ndarray:
    """Support function ``h(n) = max_{x in cylinder} n . x``, broadcast.

    ``h(n) = max(n . p0, n . p1) + r |n - (n . u) u|``: the farther end disk, then its rim point
    along n's component across the axis.

    Args:
        directions: (..., 3) directions n (any length).
        p0: (..., 3) axis end points, metres.
        p1: (..., 3) axis end points, metres.
        radius: (...,) radii, metres.

    Returns:
        (...,) support values (metres times |n|).
    """
    d = p1 - p0
    u = d / np.linalg.norm(d, axis=-1)[..., None]
    across = directions - np.sum(directions * u, axis=-1)[..., None] * u
    return (np.maximum(np.sum(directions * p0, axis=-1), np.sum(directions * p1, axis=-1))
            + radius * np.linalg.norm(across, axis=-1))


def distance_bounds(a0, a1, ra, b0, b1, rb, *, iters: int = 2000, tol: float = 1e-13,
                    refine_at: float | None = None, return_points: bool = False):
    """Lower and upper bounds on the distance between two solid cylinders: an independent oracle.

    Nothing here shares code with
    [`cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect]. The upper bound is
    ``|x - y|`` for points ``x`` in A and ``y`` in B from alternating projections (von Neumann; they
    converge to a closest pair, or to a common point when the solids meet). The lower bound is the
    width of a separating slab: for a unit ``n``, every point of B is at least ``-h_B(-n) - h_A(n)``
    further along n than every point of A (support functions,
    [`cylinder_support`][handmesh_tutorial.collision.cylinder_support]), tried for the current
    ``y - x`` and for the axes and their cross product. Two convex solids meet iff their distance is
    0, so ``upper <= eps`` certifies contact within eps and ``lower > eps`` certifies a gap larger
    than eps. Iterations stop per pair once ``upper - lower <= tol``. Near tangent contact the
    projections converge slowly and the bounds may stay apart; pairs for which the bounds do not yet
    decide whether the distance is at most ``refine_at`` (``lower <= refine_at < upper``) are then
    refined one by one with SciPy's
    SLSQP: the deepest point inside both solids (maximise the margin ``delta`` with ``x`` at least
    ``delta`` inside A and B) and the widest separating slab (maximise over unit ``n``). Both
    results are re-checked with the closed forms above, so the bounds stay valid whatever the
    optimiser does.

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
        x = project_to_cylinder(y, a0[act], a1[act], ra[act])
        y = project_to_cylinder(x, b0[act], b1[act], rb[act])
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


# --------------------------------------------------------------------------------------------------
# Other primitives: spheres, rings (annuli), boxes.
# --------------------------------------------------------------------------------------------------


def sphere_cylinder_intersect(center, radius, p0, p1, r, *, atol: float = ATOL) -> np.ndarray:
    """Do solid spheres and solid cylinders intersect? Exact (closed form), broadcast.

    Args:
        center: (..., 3) sphere centres, metres.
        radius: (...,) sphere radii, metres.
        p0: (..., 3) cylinder axis end points.
        p1: (..., 3) cylinder axis end points.
        r: (...,) cylinder radii.
        atol: contact tolerance, metres (touching counts).

    Returns:
        bool array of the broadcast batch shape.
    """
    radius = _check_radius(radius, "radius")
    return point_cylinder_distance(center, p0, p1, r) <= radius + atol


def _frame(normal):
    """Two unit vectors completing a unit normal (3,) to a right-handed frame."""
    n = np.asarray(normal, dtype=np.float64)
    e1 = _any_perpendicular(n[:, None])[:, 0]
    return e1, np.cross(n, e1)


def ring_cylinders(center, normal, major_radius: float, minor_radius: float, n: int = 12,
                   *, name: str = "ring", part: int = 0) -> Cylinders:
    """A ring (torus / annulus) as ``n`` short cylinders along its centre circle.

    Cylinder ``k`` joins the circle points at angles ``2 pi k / n`` and ``2 pi (k + 1) / n``
    (a chord) and has radius ``minor_radius``. The chords cut inside the circle by the sagitta
    ``R (1 - cos(pi / n))`` (0.34 mm for R = 2 cm, n = 12), so raise ``n`` for a closer fit.
    Consecutive cylinders share an end point and are marked adjacent.

    Args:
        center: (3,) ring centre, metres.
        normal: (3,) axis of the ring (normalised here).
        major_radius: radius of the centre circle, metres.
        minor_radius: radius of the tube, metres.
        n: number of cylinders, >= 3.
        name: prefix of the cylinder names.
        part: value of ``parts`` for every cylinder.

    Returns:
        [`Cylinders`][handmesh_tutorial.collision.Cylinders] with ``n`` cylinders.
    """
    c = _check_points(center, "center").reshape(3)
    nrm = _check_points(normal, "normal").reshape(3)
    if n < 3:
        raise ValueError(f"n must be >= 3, got {n}")
    if not major_radius > 0 or minor_radius < 0:
        raise ValueError(f"need major_radius > 0 and minor_radius >= 0, got "
                         f"{major_radius}, {minor_radius}")
    length = np.linalg.norm(nrm)
    if length == 0:
        raise ValueError("normal must be non-zero")
    e1, e2 = _frame(nrm / length)
    ang = 2 * np.pi * np.arange(n + 1) / n
    pts = c + major_radius * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    adj = np.stack([np.arange(n), (np.arange(n) + 1) % n], 1)
    return Cylinders(pts[:-1], pts[1:], np.full(n, float(minor_radius)),
                     tuple(f"{name}_{k}" for k in range(n)), np.full(n, part), adj)


def box_cylinders(center, rotation, half_extents, cells: int = 2, *, name: str = "box",
                  part: int = 0) -> Cylinders:
    """A box covered by parallel cylinders along its longest edge (a conservative stand-in).

    The box cross-section across the longest axis is split into a grid of about square cells
    (``cells`` along the shorter side); each cell gets a cylinder through its centre whose radius is
    half the cell diagonal, so the union contains the box and sticks out by at most ~21 % of a cell.

    Args:
        center: (3,) box centre, metres.
        rotation: (3, 3) box axes as columns (box frame -> world).
        half_extents: (3,) half edge lengths along the box axes, metres.
        cells: cells along the shorter side of the cross-section, >= 1.
        name: prefix of the names. part: value of ``parts``.

    Returns:
        [`Cylinders`][handmesh_tutorial.collision.Cylinders]; cylinders in neighbouring cells are
        marked adjacent.
    """
    c = _check_points(center, "center").reshape(3)
    R = np.asarray(rotation, dtype=np.float64)
    h = np.asarray(half_extents, dtype=np.float64).reshape(3)
    if R.shape != (3, 3):
        raise ValueError(f"rotation must have shape (3, 3), got {R.shape}")
    if not (h > 0).all():
        raise ValueError(f"half_extents must be positive, got {h}")
    ax = int(np.argmax(h))
    o1, o2 = [k for k in range(3) if k != ax]
    if h[o1] > h[o2]:
        o1, o2 = o2, o1
    n1 = max(int(cells), 1)
    n2 = max(int(np.ceil(n1 * h[o2] / h[o1] - 1e-9)), 1)
    s1, s2 = 2 * h[o1] / n1, 2 * h[o2] / n2
    rad = 0.5 * np.hypot(s1, s2)
    p0, p1, adj = [], [], []
    for i in range(n1):
        for j in range(n2):
            local = np.zeros(3)
            local[o1] = -h[o1] + (i + 0.5) * s1
            local[o2] = -h[o2] + (j + 0.5) * s2
            lo, hi = local.copy(), local.copy()
            lo[ax], hi[ax] = -h[ax], h[ax]
            p0.append(c + R @ lo)
            p1.append(c + R @ hi)
            k = i * n2 + j
            if j + 1 < n2:
                adj.append((k, k + 1))
            if i + 1 < n1:
                adj.append((k, k + n2))
    m = len(p0)
    return Cylinders(np.array(p0), np.array(p1), np.full(m, rad),
                     tuple(f"{name}_{k}" for k in range(m)), np.full(m, part),
                     np.array(adj, dtype=np.int64).reshape(-1, 2))


# --------------------------------------------------------------------------------------------------
# Scene queries between bodies.
# --------------------------------------------------------------------------------------------------


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
        A: the first body, a [`Cylinders`][handmesh_tutorial.collision.Cylinders].
        B: the second body.
        atol: contact tolerance, metres.
        backend: see
            [`cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect].

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
        A: the first body, a [`Cylinders`][handmesh_tutorial.collision.Cylinders] (e.g. a hand).
        B: the second body (e.g. another hand, or an object).
        atol: contact tolerance, metres.
        backend: see
            [`cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect].

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
"""Fraction of each radius [`self_collisions`][handmesh_tutorial.collision.self_collisions] lets
soft tissue compress (measured on the MakeHuman hand: 0.3 keeps a plain fist, a pinch and a flat
hand free of self-collisions while a finger crossed through its neighbour still collides).
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
    [`hand_cylinders`][handmesh_tutorial.collision.hand_cylinders] these are: consecutive phalanges
    of a finger; every phalanx with every palm cylinder (the proximal segment sits on the palm; the
    others curl onto it in a fist, a contact the flexion limits bound); all palm cylinders with each
    other; and the proximal phalanges of neighbouring fingers (index-middle, middle-ring,
    ring-pinky), which sit side by side on the knuckle line, joined by the finger webs.

    Skin is soft: two parts of one hand pressed together (fingers side by side, thumb on a
    finger) overlap as cylinders before anything passes through anything. The test therefore
    shrinks every radius by the fraction ``compression`` first (0 = the exact cylinders).

    Args:
        body: a [`Cylinders`][handmesh_tutorial.collision.Cylinders].
        atol: contact tolerance, metres.
        compression: fraction of each radius that may be compressed, in [0, 1).
        backend: see
            [`cylinders_intersect`][handmesh_tutorial.collision.cylinders_intersect].

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


# --------------------------------------------------------------------------------------------------
# Articulated bodies (hands, chains) as cylinders fitted to their meshes.
# --------------------------------------------------------------------------------------------------


def fit_cylinders(vertices, segments, assignment, *, percentile: float = 95.0, extend=None,
                  names=None, parts=None, adjacent=None, min_radius: float = 1e-4) -> Cylinders:
    """Fit one cylinder per link of an articulated mesh: axis = the link's segment, radius fitted.

    The radius of cylinder ``k`` is the ``percentile`` of the distances to its axis line of the
    vertices assigned to it (those whose projection falls between the end points), so the union
    of cylinders hugs the mesh. Ends flagged in ``extend`` move outwards along the axis until they
    cover the axial range of the assigned vertices (e.g. the palm behind the wrist joint).

    Args:
        vertices: (V, 3) mesh vertices, metres.
        segments: (N, 2, 3) end points of each link's axis, metres.
        assignment: (V,) int, the link of each vertex, or -1 for a vertex no cylinder must cover.
        percentile: in (0, 100]; 100 covers every assigned vertex whose projection is inside.
        extend: optional (N, 2) bool, whether end 0 / end 1 of each link may be moved outwards.
        names: passed to [`Cylinders`][handmesh_tutorial.collision.Cylinders].
        parts: passed to [`Cylinders`][handmesh_tutorial.collision.Cylinders].
        adjacent: passed to [`Cylinders`][handmesh_tutorial.collision.Cylinders].
        min_radius: radius of a link without assigned vertices, metres.

    Returns:
        [`Cylinders`][handmesh_tutorial.collision.Cylinders] with N cylinders.
    """
    v = _pts(vertices, "vertices")
    seg = np.asarray(segments, dtype=np.float64)
    if seg.ndim != 3 or seg.shape[1:] != (2, 3):
        raise ValueError(f"segments must have shape (N, 2, 3), got {seg.shape}")
    a = np.asarray(assignment).reshape(-1)
    if a.shape != (len(v),):
        raise ValueError(f"assignment must have shape ({len(v)},), got {a.shape}")
    if a.size and (a.min() < -1 or a.max() >= len(seg)):
        raise ValueError(f"assignment values must be in [-1, {len(seg)})")
    if not 0 < percentile <= 100:
        raise ValueError(f"percentile must be in (0, 100], got {percentile}")
    ext = (np.zeros((len(seg), 2), bool) if extend is None
           else np.asarray(extend, dtype=bool).reshape(len(seg), 2))
    p0, p1 = seg[:, 0].copy(), seg[:, 1].copy()
    radius = np.full(len(seg), float(min_radius))
    for k in range(len(seg)):
        d = p1[k] - p0[k]
        length = np.linalg.norm(d)
        if length == 0:
            raise ValueError(f"segment {k} has zero length")
        u = d / length
        w = v[a == k] - p0[k]
        if len(w) == 0:
            continue
        tau = w @ u
        rho = np.linalg.norm(w - tau[:, None] * u, axis=1)
        if ext[k, 0] and tau.min() < 0:
            p0[k] = p0[k] + tau.min() * u
            length, tau = length - tau.min(), tau - tau.min()
        if ext[k, 1] and tau.max() > length:
            p1[k] = p0[k] + tau.max() * u
            length = tau.max()
        inside = (tau >= 0) & (tau <= length)
        if inside.any():
            radius[k] = max(float(np.percentile(rho[inside], percentile)), min_radius)
    return Cylinders(p0, p1, radius, names or (), parts, adjacent)


HAND_CYLINDER_NAMES: tuple[str, ...] = tuple(
    f"{f}_{k}" for f in ("thumb", "index", "middle", "ring", "pinky") for k in (1, 2, 3)
) + ("palm_thumb", "palm_index", "palm_middle", "palm_ring", "palm_pinky")
"""Names of the 20 cylinders of [`hand_cylinders`][handmesh_tutorial.collision.hand_cylinders]: 15
phalanges (3 per finger, thumb to pinky, base to tip; ``thumb_1`` is the thumb metacarpal) and 5
palm cylinders.
"""


def _hand_adjacency() -> np.ndarray:
    adj = []
    for f in range(5):
        adj += [(3 * f, 3 * f + 1), (3 * f + 1, 3 * f + 2)]        # consecutive phalanges
        adj += [(3 * f + s, 15 + p) for s in range(3) for p in range(5)]   # phalanges and palm
    adj += [(15 + p, 15 + q) for p in range(5) for q in range(p + 1, 5)]  # palm with palm
    adj += [(3, 6), (6, 9), (9, 12)]                       # neighbouring proximal phalanges
    return np.array(adj, dtype=np.int64)


def hand_segments(joints21, palm_spread: float = 0.7) -> np.ndarray:
    """Axis segments of the 20 hand cylinders from the 21 FreiHAND keypoints.

    Phalanges join consecutive keypoints of each finger (tips included). The palm has one cylinder
    from the wrist to the thumb CMC and one per finger towards its MCP joint, starting at the wrist
    shifted sideways by ``palm_spread`` times the MCP's offset from the middle MCP (the palm is
    almost as wide at the wrist as at the knuckles).

    Args:
        joints21: (21, 3) keypoints, FreiHAND order, metres.
        palm_spread: sideways spread of the palm cylinders at the wrist, in [0, 1].

    Returns:
        (20, 2, 3) end points, in the order of
        [`HAND_CYLINDER_NAMES`][handmesh_tutorial.collision.HAND_CYLINDER_NAMES].
    """
    j = np.asarray(joints21, dtype=np.float64)
    if j.shape != (21, 3):
        raise ValueError(f"joints21 must have shape (21, 3), got {j.shape}")
    seg = [(j[b + s], j[b + s + 1]) for b in (1, 5, 9, 13, 17) for s in range(3)]
    seg.append((j[0], j[1]))
    seg += [(j[0] + palm_spread * (j[k] - j[9]), j[k]) for k in (5, 9, 13, 17)]
    return np.array(seg)


def _to_numpy(x, name):
    if x is None:
        return None
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=np.float64)


def hand_cylinders(output_or_vertices, joints21=None, model=None, index: int = 0, *,
                   percentile: float = 95.0, palm_spread: float = 0.7) -> Cylinders:
    """The hand as 20 cylinders (15 phalanges + 5 palm) fitted to its posed mesh.

    Vertices are assigned to cylinders by the model's skinning weights (argmax joint -> the bone
    leaving that joint; wrist-weighted vertices -> the nearest palm cylinder); without a model, each
    vertex goes to the nearest axis segment. Radii come from
    [`fit_cylinders`][handmesh_tutorial.collision.fit_cylinders] with ``percentile``; the palm
    cylinders extend back over the wrist. ``parts`` is the finger (0 thumb .. 4 pinky, 5 palm);
    ``adjacent`` follows the rule in
    [`self_collisions`][handmesh_tutorial.collision.self_collisions].

    Args:
        output_or_vertices: a hand model output (with ``.vertices`` (B, V, 3) and ``.joints``
            (B, 21, 3)), or vertices (B, V, 3) / (V, 3); torch or numpy, metres.
        joints21: (B, 21, 3) / (21, 3) FreiHAND keypoints; taken from the output when None.
        model: the [`HandModel`][handmesh_tutorial.hand.HandModel] (for ``skinning_weights``), or
            None.
        index: which batch element to use.
        percentile: radius percentile, see
            [`fit_cylinders`][handmesh_tutorial.collision.fit_cylinders].
        palm_spread: see [`hand_segments`][handmesh_tutorial.collision.hand_segments].

    Returns:
        [`Cylinders`][handmesh_tutorial.collision.Cylinders] with names
        [`HAND_CYLINDER_NAMES`][handmesh_tutorial.collision.HAND_CYLINDER_NAMES], metres.
    """
    verts = _to_numpy(getattr(output_or_vertices, "vertices", output_or_vertices), "vertices")
    if joints21 is None:
        joints21 = getattr(output_or_vertices, "joints", None)
        if joints21 is None:
            raise ValueError("joints21 is required when vertices are passed without an output")
    joints = _to_numpy(joints21, "joints21")
    if verts.ndim == 3:
        verts = verts[index]
    if joints.ndim == 3:
        joints = joints[index]
    if verts.ndim != 2 or verts.shape[1] != 3:
        raise ValueError(f"vertices must have shape (B, V, 3) or (V, 3), got {verts.shape}")
    seg = hand_segments(joints, palm_spread)
    palm = np.arange(15, 20)
    if model is not None and getattr(model, "skinning_weights", None) is not None:
        w = np.asarray(model.skinning_weights)
        if w.shape != (len(verts), 16):
            raise ValueError(f"model.skinning_weights must have shape ({len(verts)}, 16), "
                             f"got {w.shape}")
        from .hand import MANO_TO_FREIHAND
        # MANO joint m sits at FreiHAND keypoint f; the bone leaving it is cylinder
        # (f - 1) - (f - 1) // 4 (3 per finger, in FreiHAND finger order).
        bone = np.full(16, -1)
        for f, m in enumerate(MANO_TO_FREIHAND):
            if 1 <= m <= 15:
                bone[m] = (f - 1) - (f - 1) // 4
        arg = w.argmax(1)
        assign = bone[arg]
        wrist = arg == 0
        if wrist.any():
            d = point_cylinder_distance(verts[wrist][:, None], seg[palm, 0], seg[palm, 1],
                                        np.zeros(5))
            assign[wrist] = palm[d.argmin(1)]
    else:
        d = point_cylinder_distance(verts[:, None], seg[:, 0], seg[:, 1], np.zeros(len(seg)))
        assign = d.argmin(1)
    extend = np.zeros((20, 2), bool)
    extend[palm, 0] = True
    parts = np.r_[np.repeat(np.arange(5), 3), np.full(5, 5)]
    return fit_cylinders(verts, seg, assign, percentile=percentile, extend=extend,
                         names=HAND_CYLINDER_NAMES, parts=parts, adjacent=_hand_adjacency())


def coverage(vertices, body: Cylinders, *, tol: float = 1e-6) -> dict:
    """How much of a mesh lies outside the union of its cylinders.

    Args:
        vertices: (V, 3) mesh vertices, metres.
        body: the [`Cylinders`][handmesh_tutorial.collision.Cylinders] meant to cover them.
        tol: a vertex counts as outside when it is further than this from every cylinder, metres.

    Returns:
        dict with ``fraction_outside`` (of the vertices), ``max_outside_mm``, ``mean_outside_mm``
        (over the outside vertices, 0 when none) and ``distance`` ((V,) metres, 0 when covered).
    """
    v = _pts(_to_numpy(vertices, "vertices"), "vertices")
    d = point_cylinder_distance(v[:, None], body.p0[None], body.p1[None], body.radius[None])
    d = d.min(1)
    out = d > tol
    return {"fraction_outside": float(out.mean()), "max_outside_mm": float(d.max() * 1e3),
            "mean_outside_mm": float(d[out].mean() * 1e3) if out.any() else 0.0, "distance": d}
