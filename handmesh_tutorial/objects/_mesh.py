"""Mesh and primitive helpers shared by the static objects and the chain (private): solids of
revolution, unions, centring, and packing cylinders into a rigid body's `Cylinders`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh

from .._optional import require
from ..collision import Cylinders, ring_cylinders


def _densify(profile: np.ndarray, step: float) -> np.ndarray:
    """Insert points along a 2-D polyline so that no segment is longer than ``step``."""
    out = [profile[0]]
    for a, b in zip(profile[:-1], profile[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.extend(a + (b - a) * k / n for k in range(1, n + 1))
    return np.array(out)


def _revolve(profile: Any, sections: int = 40, step: float = 0.008) -> trimesh.Trimesh:
    """A watertight solid of revolution about z from a (radius, z) profile that starts and ends
    on the axis."""
    return trimesh.creation.revolve(_densify(np.asarray(profile, float), step), sections=sections)


def _union(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    require("manifold3d", "procedural objects (mesh booleans)")
    return trimesh.boolean.union(meshes, engine="manifold")


def _centre(mesh: trimesh.Trimesh) -> np.ndarray:
    """Translate the mesh so its bounding box is centred at the origin; returns the shift."""
    shift = -mesh.bounds.mean(0)
    mesh.apply_translation(shift)
    return shift


def _cyl(p0, p1, r, name):
    return np.asarray(p0, float), np.asarray(p1, float), float(r), name


def _pack(cyls: list[tuple], shift: np.ndarray, part: int = 0) -> Cylinders:
    """Cylinders of one rigid body. Every pair is marked adjacent: a rigid body cannot collide
    with itself, so ``collision.self_collisions`` of a body (or of the concatenated links of a
    chain) only reports contacts between different bodies (links)."""
    p0 = np.array([c[0] for c in cyls]) + shift
    p1 = np.array([c[1] for c in cyls]) + shift
    n = len(cyls)
    return Cylinders(p0, p1, np.array([c[2] for c in cyls]), tuple(c[3] for c in cyls),
                     parts=np.full(n, part), adjacent=np.stack(np.triu_indices(n, 1), axis=1))


def _from_cylinders(c: Cylinders) -> list[tuple]:
    return [_cyl(c.p0[i], c.p1[i], c.radius[i], c.names[i]) for i in range(len(c))]


def _stacked_revolution(profile_fn: Callable[[np.ndarray], np.ndarray], z0: float, z1: float,
                        n: int, name: str) -> list[tuple]:
    """Cover a solid of revolution ``r(z)`` on ``[z0, z1]`` by ``n`` coaxial cylinders, each with
    the largest radius of its slab (so the mesh stays inside)."""
    edges = np.linspace(z0, z1, n + 1)
    out = []
    for i in range(n):
        zs = np.linspace(edges[i], edges[i + 1], 17)
        out.append(_cyl((0, 0, edges[i]), (0, 0, edges[i + 1]), profile_fn(zs).max(),
                        f"{name}{i}"))
    return out


def _ring_cyls(center, normal, major: float, minor: float, n: int, name: str) -> list[tuple]:
    """An annulus (torus) as ``n`` chord cylinders (``collision.ring_cylinders``), grown to
    contain the torus: the radius by the chords' sagitta ``major (1 - cos(pi / n))``, and each
    axis by ``radius * tan(pi / n)`` at both ends to close the wedge gaps on the outer side
    where consecutive chords meet."""
    sagitta = major * (1.0 - np.cos(np.pi / n))
    ring = ring_cylinders(np.asarray(center, float), np.asarray(normal, float), major,
                          minor + sagitta, n, name=name)
    u = ring.p1 - ring.p0
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    ext = (ring.radius * np.tan(np.pi / n))[:, None] * u
    return _from_cylinders(Cylinders(ring.p0 - ext, ring.p1 + ext, ring.radius, ring.names))
