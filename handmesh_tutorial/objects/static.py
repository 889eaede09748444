"""The static objects of hand-object scenes: `make_object` builds a random can, bottle, box,
sphere, torus, mug or perforated plate (`OBJECT_KINDS`, sizes in `SIZE_RANGES`).

Each builder returns ``(mesh, cylinders in the mesh's frame before centring, params)``. Object
frame, metres. Taught in notebook 04 ("Generating interactions").
"""

from __future__ import annotations

import numpy as np
import trimesh

from .._optional import require
from ..collision import box_cylinders
from ._mesh import (
    _centre,
    _cyl,
    _from_cylinders,
    _pack,
    _revolve,
    _ring_cyls,
    _stacked_revolution,
    _union,
)
from .body import Body
from .colors import random_colors

__all__ = ["OBJECT_KINDS", "SIZE_RANGES", "make_object"]


SIZE_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "cylinder": {"radius": (0.030, 0.040), "height": (0.08, 0.14)},
    "bottle": {"radius": (0.030, 0.040), "height": (0.16, 0.22), "neck_radius": (0.011, 0.015)},
    "box": {"x": (0.04, 0.09), "y": (0.04, 0.07), "z": (0.08, 0.16)},
    "sphere": {"radius": (0.030, 0.040)},
    "torus": {"inner_radius": (0.015, 0.020), "tube_radius": (0.004, 0.007)},
    "mug": {"radius": (0.035, 0.045), "height": (0.085, 0.11), "wall": (0.005, 0.007),
            "handle_gap": (0.020, 0.026)},
    "plate": {"pitch": (0.028, 0.034), "bar": (0.007, 0.010), "holes": (2, 3)},
}
"""Sampled dimension ranges per kind, metres (low, high)."""

_SECTIONS = 40


def _u(rng: np.random.Generator, kind: str, key: str) -> float:
    lo, hi = SIZE_RANGES[kind][key]
    return float(rng.uniform(lo, hi))


def _build_cylinder(rng):
    r, h = _u(rng, "cylinder", "radius"), _u(rng, "cylinder", "height")
    mesh = _revolve([[0, 0], [r, 0], [r, h], [0, h]], _SECTIONS)
    return mesh, [_cyl((0, 0, 0), (0, 0, h), r, "body")], {"radius": r, "height": h}


def _bottle_profile(r, h, rn):
    zb, zs = 0.6 * h, 0.78 * h  # body top, shoulder top (neck starts)

    def radius(z):
        z = np.asarray(z, float)
        t = np.clip((z - zb) / (zs - zb), 0, 1)
        shoulder = rn + (r - rn) * 0.5 * (1 + np.cos(np.pi * t))
        return np.where(z <= zb, r, np.where(z >= zs, rn, shoulder))

    zs_shoulder = np.linspace(zb, zs, 9)
    pts = [[0, 0], [r, 0]] + [[radius(z), z] for z in zs_shoulder] + [[rn, h], [0, h]]
    return np.array(pts, float), radius, zb, zs


def _build_bottle(rng):
    r, h = _u(rng, "bottle", "radius"), _u(rng, "bottle", "height")
    rn = _u(rng, "bottle", "neck_radius")
    profile, radius, zb, zs = _bottle_profile(r, h, rn)
    mesh = _revolve(profile, _SECTIONS)
    cyls = [_cyl((0, 0, 0), (0, 0, zb), r, "body")]
    cyls += _stacked_revolution(radius, zb, zs, 6, "shoulder")
    cyls.append(_cyl((0, 0, zs), (0, 0, h), rn, "neck"))
    return mesh, cyls, {"radius": r, "height": h, "neck_radius": rn}


def _build_box(rng):
    ex = np.array([_u(rng, "box", k) for k in ("x", "y", "z")])
    mesh = trimesh.creation.box(extents=ex)
    for _ in range(3):  # uniform subdivision keeps it watertight and gives vertices to colour
        mesh = mesh.subdivide()
    # parallel cylinders along the longest edge over a grid of cells of about 1.5 cm
    # (collision.box_cylinders: radius = half the cell diagonal)
    cells = max(1, int(np.ceil(np.sort(ex)[0] / 0.015)))
    cyls = _from_cylinders(box_cylinders(np.zeros(3), np.eye(3), ex / 2, cells, name="column"))
    return mesh, cyls, {"x": ex[0], "y": ex[1], "z": ex[2]}


def _build_sphere(rng):
    r = _u(rng, "sphere", "radius")
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=r)
    # slabs of equal latitude angle; each slab's radius is the sphere's largest in it
    lat = np.linspace(-np.pi / 2, np.pi / 2, 12)
    zs = r * np.sin(lat)
    cyls = []
    for i in range(len(zs) - 1):
        a, b = zs[i], zs[i + 1]
        rad = r if a <= 0 <= b else np.sqrt(max(r * r - min(a * a, b * b), 0.0))
        cyls.append(_cyl((0, 0, a), (0, 0, b), rad, f"slab{i}"))
    return mesh, cyls, {"radius": r}


def _build_torus(rng):
    ri, rt = _u(rng, "torus", "inner_radius"), _u(rng, "torus", "tube_radius")
    R = ri + rt
    mesh = trimesh.creation.torus(R, rt, major_sections=48, minor_sections=16)
    cyls = _ring_cyls((0, 0, 0), (0, 0, 1), R, rt, 16, "ring")
    return mesh, cyls, {"major_radius": R, "tube_radius": rt, "inner_diameter": 2 * ri}


def _build_mug(rng):
    r, h = _u(rng, "mug", "radius"), _u(rng, "mug", "height")
    w, gap = _u(rng, "mug", "wall"), _u(rng, "mug", "handle_gap")
    b = w + 0.002  # bottom thickness
    cup = _revolve([[0, 0], [r, 0], [r, h], [r - w, h], [r - w, b], [0, b]], _SECTIONS)
    rt = 0.005  # handle tube radius
    Rh = 0.5 * gap + rt + 0.004  # handle major radius: gap between wall and handle ~ gap
    handle = trimesh.creation.torus(Rh, rt, major_sections=40, minor_sections=12)
    handle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    xc = r + gap + rt - Rh  # the handle tube's inner side is `gap` away from the outer wall
    handle.apply_translation([xc, 0, h / 2])
    # keep only the part of the handle outside the mid-wall cylinder (its cut ends sit in the wall)
    keep = trimesh.creation.box(extents=[0.2, 0.2, 0.2])
    keep.apply_translation([0.1 + (r - w / 2), 0, h / 2])
    require("manifold3d", "procedural objects (mesh booleans)")
    handle = trimesh.boolean.intersection([handle, keep], engine="manifold")
    mesh = _union([cup, handle])
    # wall: vertical staves around the circumference; bottom: one disc
    n = 24
    rc = r - w / 2
    chord = 2 * rc * np.sin(np.pi / n)
    rs = float(np.hypot(chord / 2, w / 2)) + 1e-4
    cyls = [_cyl((rc * np.cos(a), rc * np.sin(a), 0), (rc * np.cos(a), rc * np.sin(a), h), rs,
                 f"wall{i}") for i, a in enumerate(np.linspace(0, 2 * np.pi, n, endpoint=False))]
    cyls.append(_cyl((0, 0, 0), (0, 0, b), r, "bottom"))
    # the handle's ring pieces, cut like the handle mesh at the mid-wall radius
    cyls += _clip_outside_radius(_ring_cyls((xc, 0, h / 2), (0, 1, 0), Rh, rt, 16, "handle"),
                                 rc)
    return mesh, cyls, {"radius": r, "height": h, "wall": w, "handle_gap": gap,
                        "handle_major_radius": Rh, "handle_tube_radius": rt}


def _clip_outside_radius(cyls: list[tuple], rho: float) -> list[tuple]:
    """Keep the parts of cylinder axes that lie outside the z-axis cylinder of radius ``rho``."""
    out = []
    for p0, p1, r, name in cyls:
        r0, r1 = np.hypot(p0[0], p0[1]), np.hypot(p1[0], p1[1])
        if r0 < rho and r1 < rho:
            continue
        if r0 < rho or r1 < rho:  # crossing: move the inner end point onto the radius
            a, b = (p1, p0) if r0 < rho else (p0, p1)  # a outside, b inside
            d = b - a
            # |a_xy + t d_xy|^2 = rho^2: the smaller root is where the axis enters the radius
            qa = d[0] ** 2 + d[1] ** 2
            qb = 2 * (a[0] * d[0] + a[1] * d[1])
            qc = a[0] ** 2 + a[1] ** 2 - rho ** 2
            t = (-qb - np.sqrt(max(qb * qb - 4 * qa * qc, 0.0))) / (2 * qa)
            p0, p1 = a, a + np.clip(t, 0.0, 1.0) * d
        out.append((p0, p1, r, name))
    return out


def _build_plate(rng):
    pitch, bar = _u(rng, "plate", "pitch"), _u(rng, "plate", "bar")
    lo, hi = SIZE_RANGES["plate"]["holes"]
    holes = int(rng.integers(int(lo), int(hi) + 1))
    thick = bar
    L = holes * pitch + bar  # outer size
    bars = []
    cyls = []
    rb = 0.5 * np.hypot(bar, thick) + 1e-4
    for i in range(holes + 1):
        c = -L / 2 + bar / 2 + i * pitch
        bx = trimesh.creation.box(extents=[bar, L, thick])
        bx.apply_translation([c, 0, 0])
        by = trimesh.creation.box(extents=[L, bar, thick])
        by.apply_translation([0, c, 0])
        bars += [bx, by]
        cyls.append(_cyl((c, -L / 2, 0), (c, L / 2, 0), rb, f"bar_x{i}"))
        cyls.append(_cyl((-L / 2, c, 0), (L / 2, c, 0), rb, f"bar_y{i}"))
    mesh = _union(bars)
    while len(mesh.faces) * 4 <= 3000:  # vertices for the colour pattern, few thousand faces
        mesh = mesh.subdivide()
    return mesh, cyls, {"pitch": pitch, "bar": bar, "holes": holes, "size": L,
                        "hole_size": pitch - bar}


_BUILDERS = {
    "cylinder": _build_cylinder,
    "bottle": _build_bottle,
    "box": _build_box,
    "sphere": _build_sphere,
    "torus": _build_torus,
    "mug": _build_mug,
    "plate": _build_plate,
}

OBJECT_KINDS: tuple[str, ...] = tuple(_BUILDERS)
"""The static object kinds `make_object` builds."""


def make_object(kind: str, rng: np.random.Generator | int | None = None,
                pattern: str | None = None) -> Body:
    """Build a random static object of a given kind.

    Args:
        kind: one of `OBJECT_KINDS`.
        rng: a ``numpy.random.Generator`` or a seed; dimensions (within `SIZE_RANGES`),
            palette and pattern are drawn from it. Same seed, same bytes.
        pattern: colour pattern (see `random_colors`), ``None`` to draw one.

    Returns:
        A `Body` in its object frame (bounding box centred at the origin, metres).

    Raises:
        ValueError: unknown kind.
    """
    if kind not in _BUILDERS:
        raise ValueError(f"unknown object kind {kind!r}; expected one of {OBJECT_KINDS}")
    rng = np.random.default_rng(rng)
    mesh, cyls, params = _BUILDERS[kind](rng)
    shift = _centre(mesh)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    colors = random_colors(v, rng, pattern)
    params = {k: (int(x) if isinstance(x, (int, np.integer)) else float(x))
              for k, x in params.items()}
    return Body(kind, kind, v, f, colors, _pack(cyls, shift), params)
