"""A body as a batch of finite solid cylinders
([`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders]), and builders for objects made of
cylinders: rings (annuli) and boxes.

Shapes: a body of N cylinders holds (N, 3) axis end points ``p0``, ``p1`` and (N,) radii, metres.
Taught in notebook 03 (cylinder collision); objects built from them in notebook 04.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from ._common import _any_perpendicular, _check_points

__all__ = ["Cylinders", "ring_cylinders", "box_cylinders"]


def _as_points(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {tuple(np.shape(x))}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf")
    return a


@functools.lru_cache(maxsize=64)
def _default_names(n: int) -> tuple[str, ...]:
    # made once per size: the generator builds thousands of unnamed bodies per scene
    return tuple(f"cyl{i}" for i in range(n))


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
            [`self_collisions`][handmesh_tutorial.collision.queries.self_collisions] skips them.

    Shapes:
        ``p0, p1 (N, 3)``, ``radius (N,)`` (or one value for all), ``parts (N,)``,
        ``adjacent (M, 2)``; metres.
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
        self.names = tuple(map(str, self.names)) if self.names else _default_names(n)
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

    @classmethod
    def _unchecked(cls, p0: np.ndarray, p1: np.ndarray, radius: np.ndarray,
                   names: tuple[str, ...] = (), parts: np.ndarray | None = None,
                   adjacent: np.ndarray | None = None) -> Cylinders:
        """A body from arrays already in canonical form, without the checks of the constructor.

        For hot internal loops (the generator's rigs build a body per collision query, some
        hundred per scene, and the checks cost more than the query). The caller guarantees what
        ``__post_init__`` would establish: ``p0, p1`` (N, 3) finite float64, ``radius`` (N,)
        non-negative float64, ``names`` empty or N strings, ``parts`` (N,) int64 or None,
        ``adjacent`` (M, 2) int64, sorted and unique, or None. The arrays are not copied.
        """
        n = len(p0)
        body = cls.__new__(cls)
        body.p0, body.p1, body.radius = p0, p1, radius
        body.names = names if names else _default_names(n)
        body.parts = np.zeros(n, dtype=np.int64) if parts is None else parts
        body.adjacent = np.zeros((0, 2), dtype=np.int64) if adjacent is None else adjacent
        return body

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
            A new [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders] (names, parts and
            adjacency kept).
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
            bodies: a sequence of [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders].

        Returns:
            One [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders] with all cylinders
            in order.
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
        [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders] with ``n`` cylinders.

    Shapes:
        ``center, normal (3,)`` -> ``n`` cylinders.
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
        [`Cylinders`][handmesh_tutorial.collision.cylinders.Cylinders]; cylinders in neighbouring
        cells are marked adjacent.

    Shapes:
        ``center (3,)``, ``rotation (3, 3)``, ``half_extents (3,)`` -> a grid of cylinders.
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
