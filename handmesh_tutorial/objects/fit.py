"""How well a body's cylinders approximate its mesh: `primitive_fit` (coverage and excess) and
`distance_to_cylinders`.

Metres in, millimetres in the report. Taught in notebook 04 ("Generating interactions").
"""

from __future__ import annotations

from typing import Any

import numpy as np
import trimesh

from .._optional import require
from ..collision import Cylinders, point_cylinder_distance
from .body import Body

__all__ = ["primitive_fit"]


def distance_to_cylinders(points: Any, cylinders: Cylinders) -> np.ndarray:
    """Distance from points to the union of solid cylinders (0 inside).

    Args:
        points: (N, 3) metres.
        cylinders: the primitives.

    Returns:
        (N,) float64 metres.
    """
    P = np.asarray(points, dtype=np.float64)
    return point_cylinder_distance(P[:, None, :], cylinders.p0, cylinders.p1,
                                   cylinders.radius).min(axis=1)


def _sample_in_cylinders(cyl: Cylinders, per_cylinder: int, rng: np.random.Generator):
    out = []
    for a, b, r in zip(cyl.p0, cyl.p1, cyl.radius, strict=True):
        u = b - a
        L = np.linalg.norm(u)
        u = u / L
        helper = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
        e1 = np.cross(u, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(u, e1)
        rr = r * np.sqrt(rng.random(per_cylinder))
        th = rng.uniform(0, 2 * np.pi, per_cylinder)
        t = rng.uniform(0, L, per_cylinder)
        out.append(a + t[:, None] * u + (rr * np.cos(th))[:, None] * e1
                   + (rr * np.sin(th))[:, None] * e2)
    return np.concatenate(out)


def primitive_fit(body: Body, samples: int = 2000, tol: float = 0.001,
                  rng: np.random.Generator | int | None = 0) -> dict[str, float]:
    """Measure how well a body's cylinders approximate its mesh.

    Two directions: (1) **coverage**, the fraction of points sampled uniformly on the mesh
    surface that lie inside the union of cylinders (within ``tol``): a part of the mesh outside
    every primitive would be invisible to collision tests; (2) **excess**, for points sampled
    inside each cylinder, how far they lie outside the mesh: a primitive sticking out would
    stop a hand before it touches the visible surface.

    Args:
        body: the body.
        samples: number of surface samples (and roughly of primitive samples).
        tol: distance below which a surface point counts as covered, metres.
        rng: generator or seed of the samples.

    Returns:
        ``{"coverage": fraction in [0, 1], "uncovered_max_mm": largest distance of a surface
        sample to the primitives, "excess_p95_mm" / "excess_max_mm": 95th percentile / maximum
        distance of primitive samples outside the mesh (0 inside), "excess_frac_2mm": fraction
        of primitive samples more than 2 mm outside the mesh}``.
    """
    rng = np.random.default_rng(rng)
    mesh = trimesh.Trimesh(body.vertices, body.faces, process=False)
    surf, _ = trimesh.sample.sample_surface(mesh, samples, seed=int(rng.integers(2**31)))
    d_surf = distance_to_cylinders(surf, body.cylinders)
    per = max(8, samples // max(len(body.cylinders), 1))
    inner = _sample_in_cylinders(body.cylinders, per, rng)
    require("rtree", "primitive_fit (trimesh's proximity queries)")
    sd = trimesh.proximity.signed_distance(mesh, inner)  # > 0 inside the mesh
    excess = np.maximum(-sd, 0.0)
    return {"coverage": float(np.mean(d_surf <= tol)),
            "uncovered_max_mm": float(d_surf.max() * 1e3),
            "excess_p95_mm": float(np.percentile(excess, 95) * 1e3),
            "excess_max_mm": float(excess.max() * 1e3),
            "excess_frac_2mm": float(np.mean(excess > 0.002))}
