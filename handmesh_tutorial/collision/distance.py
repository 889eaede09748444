"""Reference geometry of one solid cylinder: point distance, Euclidean projection, support function,
and the sphere-cylinder test built on the distance.

Closed forms (a solid cylinder is an interval along its axis times a disk across it), broadcast
over ``(..., 3)`` points and ``(...,)`` radii, metres. They back the independent oracle
([`distance_bounds`][handmesh_tutorial.collision.oracle.distance_bounds]) and the hand proxies'
radius fit. Taught in notebook 03 (cylinder collision).
"""

from __future__ import annotations

import numpy as np

from ._common import _check_points, _check_radius
from .exact import ATOL

__all__ = ["point_cylinder_distance", "project_to_cylinder", "sphere_cylinder_intersect"]


def _check_cylinder(points, p0, p1, radius):
    """Validated float64 ``points, p0, p1, radius`` and the axis lengths of one call.

    Raises:
        ValueError: a point array that is not ``(..., 3)``, NaN or inf anywhere, a negative
            radius, or an axis of zero length (the message gives its flat index and count).
    """
    x, p0, p1 = (_check_points(a, n) for a, n in ((points, "points"), (p0, "p0"), (p1, "p1")))
    r = _check_radius(radius, "radius")
    length = np.linalg.norm(p1 - p0, axis=-1)
    if not (length > 0).all():
        bad = np.flatnonzero(~(length > 0))
        raise ValueError(f"axis p0->p1 has zero length at flat index {int(bad[0])} "
                         f"({bad.size} such entries); a cylinder needs two distinct end points")
    return x, p0, p1, r, length


def point_cylinder_distance(points, p0, p1, radius) -> np.ndarray:
    """Euclidean distance from points to solid cylinders (0 inside), broadcast.

    A solid cylinder is the product of an interval (along the axis) and a disk (across it), so the
    distance is ``hypot(max(rho - r, 0), max(-tau, tau - L, 0))`` with ``tau`` the axial and
    ``rho`` the radial coordinate.

    Args:
        points: (..., 3) query points, metres.
        p0: (..., 3) axis end points, metres.
        p1: (..., 3) axis end points, metres.
        radius: (...,) radii, metres, finite and ``>= 0``.

    Returns:
        (...,) distances, metres.

    Shapes:
        ``points, p0, p1 (..., 3)``, ``radius (...)`` (broadcast) -> ``(...)`` metres.

    Raises:
        ValueError: a point array that is not ``(..., 3)``, NaN or inf anywhere, a negative
            radius, or an axis of zero length (``p0 == p1``).
    """
    x, p0, p1, r, length = _check_cylinder(points, p0, p1, radius)
    u = (p1 - p0) / length[..., None]
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
        p0: (..., 3) axis end points, metres, finite.
        p1: (..., 3) axis end points, metres, finite, each different from its ``p0``.
        radius: (...,) radii, metres, finite and ``>= 0``.

    Returns:
        (..., 3) projected points, metres.

    Shapes:
        ``points, p0, p1 (..., 3)``, ``radius (...)`` (broadcast) -> ``(..., 3)`` metres.

    Raises:
        ValueError: as ``point_cylinder_distance``: a point array that is not ``(..., 3)``,
            NaN or inf, a negative radius, or an axis of zero length (``p0 == p1``: no
            direction to project along).
    """
    points, p0, p1, radius, _ = _check_cylinder(points, p0, p1, radius)
    return _project(points, p0, p1, radius)


def _project(points, p0, p1, radius) -> np.ndarray:
    """`project_to_cylinder` without the checks (callers that already validated, in loops)."""
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

    Shapes:
        ``directions, p0, p1 (..., 3)``, ``radius (...)`` (broadcast) -> ``(...)``.
    """
    d = p1 - p0
    u = d / np.linalg.norm(d, axis=-1)[..., None]
    across = directions - np.sum(directions * u, axis=-1)[..., None] * u
    return (np.maximum(np.sum(directions * p0, axis=-1), np.sum(directions * p1, axis=-1))
            + radius * np.linalg.norm(across, axis=-1))


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

    Shapes:
        ``center, p0, p1 (..., 3)``, ``radius, r (...)`` (broadcast) -> ``(...)`` bool.
    """
    radius = _check_radius(radius, "radius")
    return point_cylinder_distance(center, p0, p1, r) <= radius + atol
