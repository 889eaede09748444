"""Procedural objects for hand-object scenes, with cylinder collision primitives and colours.

The paper uses YCB objects plus self-made ones; YCB is not downloadable here, so every object is
built by code (``trimesh`` + ``manifold3d`` booleans): watertight meshes of at most a few thousand
faces, sized like everyday objects, each with

* per-vertex colours from a random palette and a simple procedural pattern (solid, stripes,
  checker, speckle), and
* collision primitives as finite cylinders (`handmesh_tutorial.collision.Cylinders`), annuli
  as rings of short cylinders, so that the INTER-SH generator can test hand-object contact with
  the same Ketchel-Larochelle test it uses for two hands.

Static kinds (`OBJECT_KINDS`): ``cylinder`` (can), ``bottle``, ``box``, ``sphere``, ``torus``
(a ring a finger passes through), ``mug`` (the handle lets a finger through), ``plate`` (a
perforated plate: a lattice of bars whose square holes a finger fits through). The dynamic
chain of interlocking rings is built by `make_chain` and posed by `Chain.pose`.

Object frame: metres, origin at the centre of the bounding box; z is the axis of revolution
(cylinder, bottle, mug, torus normal), the box's edges are along x, y, z (z usually the longest),
the plate lies in the xy-plane, the mug's handle points to +x in the xz-plane.
``Body.transformed(R, t)`` places a body in a scene (OpenCV camera frame for rendering).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import trimesh

from .collision import Cylinders, box_cylinders, ring_cylinders

__all__ = [
    "CHAIN_SIZE_RANGES",
    "OBJECT_KINDS",
    "SIZE_RANGES",
    "Body",
    "Chain",
    "make_chain",
    "distance_to_cylinders",
    "make_object",
    "primitive_fit",
    "random_colors",
]


# --------------------------------------------------------------------------------------------
# Body
# --------------------------------------------------------------------------------------------

@dataclass
class Body:
    """A rigid body: mesh, vertex colours and cylinder collision primitives, one frame.

    Attributes:
        name: human-readable name, e.g. ``"mug"``.
        kind: one of `OBJECT_KINDS` (or ``"chain_link"``).
        vertices: (V, 3) float64, metres, in the body's frame.
        faces: (F, 3) int64, counter-clockwise seen from outside; the mesh is watertight.
        colors: (V, 3) float64 RGB in [0, 1].
        cylinders: collision primitives in the same frame as ``vertices``.
        params: the sampled dimensions (metres), e.g. ``{"radius": 0.035, "height": 0.12}``.
    """

    name: str
    kind: str
    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    cylinders: Cylinders
    params: dict

    def transformed(self, R: Any, t: Any) -> Body:
        """The body rigidly moved: ``x -> R @ x + t`` for vertices and cylinders.

        Args:
            R: (3, 3) rotation matrix.
            t: (3,) translation, metres.

        Returns:
            A new `Body` (faces, colours and params shared with this one).
        """
        R = np.asarray(R, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        if R.shape != (3, 3):
            raise ValueError(f"R must have shape (3, 3), got {R.shape}")
        if t.shape != (3,):
            raise ValueError(f"t must have shape (3,), got {t.shape}")
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("R must be a rotation matrix (orthonormal, det +1)")
        return replace(self, vertices=self.vertices @ R.T + t,
                       cylinders=self.cylinders.transform(R, t))

    def render_mesh(self, label: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """``(vertices, faces, colors, label)``: the input format of ``Renderer.render``."""
        return (self.vertices, self.faces, self.colors, int(label))

    def trimesh(self) -> trimesh.Trimesh:
        """The mesh as a ``trimesh.Trimesh`` (vertex colours attached, no processing)."""
        c = (np.clip(self.colors, 0, 1) * 255 + 0.5).astype(np.uint8)
        return trimesh.Trimesh(self.vertices, self.faces, vertex_colors=c, process=False)


# --------------------------------------------------------------------------------------------
# Colours
# --------------------------------------------------------------------------------------------

_PATTERNS = ("solid", "stripes", "checker", "speckle")


def _hsv_to_rgb(h: float, s: float, v: float) -> np.ndarray:
    import colorsys

    return np.array(colorsys.hsv_to_rgb(h % 1.0, s, v))


def random_colors(vertices: Any, rng: np.random.Generator | int | None,
                  pattern: str | None = None, scale: float = 0.02) -> np.ndarray:
    """Per-vertex colours: a random two-colour palette and a procedural pattern.

    Patterns: ``solid`` (one colour, slight per-vertex jitter), ``stripes`` (bands along z),
    ``checker`` (angle around z x height), ``speckle`` (random spots). The palette is two
    colours of random hue, saturation and value, the second a shifted hue.

    Args:
        vertices: (V, 3) positions, metres, in the object frame.
        rng: a ``numpy.random.Generator`` or a seed.
        pattern: one of the patterns above, or ``None`` to draw one.
        scale: pattern period, metres.

    Returns:
        (V, 3) float64 RGB in [0, 1].

    Raises:
        ValueError: unknown pattern.
    """
    rng = np.random.default_rng(rng)
    v = np.asarray(vertices, dtype=np.float64)
    if pattern is None:
        pattern = _PATTERNS[int(rng.integers(len(_PATTERNS)))]
    if pattern not in _PATTERNS:
        raise ValueError(f"unknown pattern {pattern!r}; expected one of {_PATTERNS}")
    h = rng.random()
    c0 = _hsv_to_rgb(h, rng.uniform(0.3, 0.9), rng.uniform(0.4, 0.95))
    c1 = _hsv_to_rgb(h + rng.uniform(0.25, 0.75), rng.uniform(0.2, 0.9), rng.uniform(0.3, 1.0))
    if pattern == "solid":
        t = np.zeros(len(v))
    elif pattern == "stripes":
        t = (np.floor(v[:, 2] / scale) % 2).astype(float)
    elif pattern == "checker":
        ang = np.arctan2(v[:, 1], v[:, 0])
        k = max(2, int(round(2 * np.pi * 0.03 / scale)))
        t = ((np.floor(ang / (2 * np.pi) * 2 * k) + np.floor(v[:, 2] / scale)) % 2).astype(float)
    else:
        centres = v[rng.choice(len(v), size=max(1, len(v) // 40), replace=False)]
        d = np.min(np.linalg.norm(v[:, None] - centres[None], axis=-1), axis=1)
        t = (d < 0.35 * scale).astype(float)
    col = c0 + t[:, None] * (c1 - c0) + rng.normal(0.0, 0.015, (len(v), 3))
    return np.clip(col, 0.0, 1.0)


# --------------------------------------------------------------------------------------------
# Mesh helpers
# --------------------------------------------------------------------------------------------

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


# --------------------------------------------------------------------------------------------
# Object builders: each returns (mesh, cylinders in the mesh's frame before centring, params)
# --------------------------------------------------------------------------------------------

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


# --------------------------------------------------------------------------------------------
# How well do the primitives fit the mesh?
# --------------------------------------------------------------------------------------------

def distance_to_cylinders(points: Any, cylinders: Cylinders) -> np.ndarray:
    """Distance from points to the union of solid cylinders (0 inside).

    Args:
        points: (N, 3) metres.
        cylinders: the primitives.

    Returns:
        (N,) float64 metres.
    """
    P = np.asarray(points, dtype=np.float64)
    axis = cylinders.p1 - cylinders.p0  # (C, 3)
    L = np.linalg.norm(axis, axis=1)
    u = axis / np.maximum(L, 1e-12)[:, None]
    d = P[:, None, :] - cylinders.p0[None]  # (N, C, 3)
    along = np.einsum("ncd,cd->nc", d, u)
    radial = np.linalg.norm(d - along[..., None] * u[None], axis=-1)
    out_r = np.maximum(radial - cylinders.radius[None], 0.0)
    out_a = np.maximum(np.maximum(-along, along - L[None]), 0.0)
    return np.hypot(out_r, out_a).min(axis=1)


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
    sd = trimesh.proximity.signed_distance(mesh, inner)  # > 0 inside the mesh
    excess = np.maximum(-sd, 0.0)
    return {"coverage": float(np.mean(d_surf <= tol)),
            "uncovered_max_mm": float(d_surf.max() * 1e3),
            "excess_p95_mm": float(np.percentile(excess, 95) * 1e3),
            "excess_max_mm": float(excess.max() * 1e3),
            "excess_frac_2mm": float(np.mean(excess > 0.002))}


# --------------------------------------------------------------------------------------------
# The articulated chain of interlocking rings
# --------------------------------------------------------------------------------------------

CHAIN_SIZE_RANGES: dict[str, tuple[float, float]] = {
    "major_radius": (0.016, 0.022),
    "tube_ratio": (0.17, 0.21),
    "clearance": (0.001, 0.002),
}
"""Chain dimension ranges: ring centre-line radius (metres), tube radius as a fraction of it,
clearance at the hook (metres). Thin enough tubes keep link ``k`` and link ``k + 2`` (same plane)
apart: their tubes are ``2 major - 6 tube - 4 clearance`` apart at rest.
"""

_RING_CYLINDERS = 16  # short cylinders per ring (annulus primitive)


@dataclass
class Chain:
    """An articulated chain of interlocking rings (torus links), at rest, in the chain frame.

    Link ``k`` is a torus whose centre-line circle (radius ``major_radius``) lies in a plane that
    contains the chain axis ``z``: the xz-plane for even ``k``, the yz-plane for odd ``k``, so
    consecutive links are perpendicular. Centres are ``pitch`` apart along ``z`` with
    ``pitch = 2 (major_radius - tube_radius - clearance)``: each link passes through its
    neighbours' holes (interlocked) and, at rest, the two tubes are ``2 * clearance`` apart where
    they hook (not colliding); links ``k`` and ``k + 2`` share a plane and are
    ``params["skip_one_gap"]`` apart.

    Each link rotates about its **pivot**, the contact point with its parent: the midpoint of
    the two centres (for link 0, the same distance below its centre). The per-link LCS (paper,
    supplementary: "LCS for dynamic objects") comes from `handmesh_tutorial.lcs.local_frames`
    with joints = pivots, ``z`` towards the next pivot (the far end of the ring for the last link)
    and ``x`` towards a flexion point in the link's own plane, so ``y`` is the ring's normal.

    Attributes:
        links: rest links as `Body` (``kind="chain_link"``), chain frame, metres.
        pivots: (L, 3) rest pivot of each link.
        parents: (L,) int parent link, -1 for link 0.
        articulation: ``lcs.Articulation`` with the rest frames and angle limits (radians), axis
            order ``(x, y, z)``; angles are composed as in `handmesh_tutorial.lcs`.
        params: ``major_radius``, ``tube_radius``, ``clearance``, ``pitch`` (metres), ``num_links``.
    """

    links: list[Body]
    pivots: np.ndarray
    parents: np.ndarray
    articulation: Any
    params: dict

    @property
    def num_links(self) -> int:
        """Number of links L."""
        return len(self.links)

    def zero_angles(self) -> np.ndarray:
        """(L, 3) zeros: the rest pose."""
        return np.zeros((self.num_links, 3))

    def link_transforms(self, angles: Any) -> tuple[np.ndarray, np.ndarray]:
        """Rigid transform of every link for per-link LCS angles (forward kinematics).

        Link ``k`` turns by ``F_k R(a_k) F_k^T`` about its pivot, relative to its parent:
        ``G_k = G_parent R_k``, ``P_k = P_parent + G_parent (pivot_k - pivot_parent)``, and a rest
        point ``x`` of link ``k`` goes to ``G_k (x - pivot_k) + P_k``.

        Args:
            angles: (L, 3) radians about each link's LCS axes ``(x, y, z)``.

        Returns:
            ``(R, t)``: (L, 3, 3) rotations and (L, 3) translations, ``x -> R_k x + t_k``.
        """
        a = np.asarray(angles, dtype=np.float64)
        if a.shape != (self.num_links, 3):
            raise ValueError(f"angles must have shape ({self.num_links}, 3), got {a.shape}")
        local = self.articulation.rotations(a)  # (L, 3, 3) in rest axes
        G = np.empty_like(local)
        P = np.empty((self.num_links, 3))
        for k, p in enumerate(self.parents):
            if p < 0:
                G[k], P[k] = local[k], self.pivots[k]
            else:
                G[k] = G[p] @ local[k]
                P[k] = P[p] + G[p] @ (self.pivots[k] - self.pivots[p])
        t = P - np.einsum("kab,kb->ka", G, self.pivots)
        return G, t

    def pose(self, angles: Any = None, R: Any = None, t: Any = None) -> list[Body]:
        """The posed links (meshes and ring cylinders), optionally moved rigidly as a whole.

        Args:
            angles: (L, 3) radians per link (``None`` = rest pose).
            R: optional (3, 3) rotation of the whole chain (applied after the articulation).
            t: optional (3,) translation of the whole chain, metres.

        Returns:
            L `Body` objects; their cylinders concatenated with
            ``Cylinders.concat([b.cylinders for b in bodies])`` give the chain's primitives.
        """
        a = self.zero_angles() if angles is None else angles
        G, tr = self.link_transforms(a)
        Rw = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
        tw = np.zeros(3) if t is None else np.asarray(t, dtype=np.float64)
        return [link.transformed(Rw @ G[k], Rw @ tr[k] + tw) for k, link in enumerate(self.links)]

    def cylinders(self, angles: Any = None, R: Any = None, t: Any = None) -> Cylinders:
        """All ring cylinders of the posed chain, one ``Cylinders`` (``parts`` = link index).

        Cylinder pairs of the same link are marked adjacent and pairs of different links are
        not, so ``collision.self_collisions(chain.cylinders(angles))`` lists exactly the
        link-link contacts: the test that keeps interlocked links from passing through each
        other while the chain moves.
        """
        return Cylinders.concat([b.cylinders for b in self.pose(angles, R, t)])

    def joint_positions(self, angles: Any = None) -> np.ndarray:
        """(L, 3) posed pivots (chain frame)."""
        a = self.zero_angles() if angles is None else angles
        G, tr = self.link_transforms(a)
        return np.einsum("kab,kb->ka", G, self.pivots) + tr


def make_chain(num_links: int = 4, rng: np.random.Generator | int | None = None,
               limit_deg: float = 60.0, root_fixed: bool = True,
               pattern: str | None = None) -> Chain:
    """Build a chain of ``num_links`` interlocking rings (see `Chain`).

    Args:
        num_links: number of links L (>= 2).
        rng: a ``numpy.random.Generator`` or a seed (sizes from `CHAIN_SIZE_RANGES`,
            palette).
        limit_deg: symmetric limit on every LCS axis of every link, degrees (the paper limits
            hand joints to 60 degrees; collisions between links bound the motion further).
        root_fixed: when ``True`` link 0's limits are zero (it is placed by the rigid ``R, t``
            of `Chain.pose` instead).
        pattern: colour pattern of `random_colors` (``None`` draws one).

    Returns:
        A `Chain` at rest, chain frame centred on its bounding box, axis ``z``.

    Raises:
        ValueError: ``num_links < 2``.
    """
    from .lcs import Articulation, local_frames

    if int(num_links) < 2:
        raise ValueError(f"num_links must be >= 2, got {num_links}")
    L = int(num_links)
    rng = np.random.default_rng(rng)
    R = float(rng.uniform(*CHAIN_SIZE_RANGES["major_radius"]))
    r = R * float(rng.uniform(*CHAIN_SIZE_RANGES["tube_ratio"]))
    gap = float(rng.uniform(*CHAIN_SIZE_RANGES["clearance"]))
    pitch = 2.0 * (R - r - gap)
    colour_seed = int(rng.integers(2**32))
    ez = np.array([0.0, 0.0, 1.0])
    centres = np.array([[0.0, 0.0, k * pitch] for k in range(L)])
    centres -= 0.5 * (centres[0] + centres[-1])  # bounding box centred at the origin
    pivots = centres - 0.5 * pitch * ez
    torus = trimesh.creation.torus(R, r, major_sections=40, minor_sections=12)
    base_v = np.asarray(torus.vertices, dtype=np.float64)  # in the xy-plane, normal z
    faces = np.asarray(torus.faces, dtype=np.int64)
    links, flex = [], []
    for k in range(L):
        in_plane = np.array([1.0, 0, 0]) if k % 2 == 0 else np.array([0, 1.0, 0])
        normal = np.cross(in_plane, ez)  # ring normal (-y for even, +x for odd links)
        rot = np.stack([in_plane, ez, normal], axis=1)  # rotation: torus x, y, z -> these
        v = base_v @ rot.T + centres[k]
        cols = random_colors(base_v, colour_seed, pattern)
        cyls = _pack(_ring_cyls(centres[k], normal, R, r, _RING_CYLINDERS, f"link{k}"),
                     np.zeros(3), part=k)
        links.append(Body(f"chain_link{k}", "chain_link", v, faces, cols, cyls,
                          {"major_radius": R, "tube_radius": r}))
        flex.append(pivots[k] + R * in_plane)
    children = np.vstack([pivots[1:], centres[-1] + R * ez])
    frames = local_frames(pivots, children, np.array(flex))
    lim = np.full((L, 3), np.deg2rad(limit_deg))
    lower, upper = -lim, lim.copy()
    if root_fixed:
        lower[0] = upper[0] = 0.0
    art = Articulation(names=tuple(f"link{k}" for k in range(L)), joints=pivots, frames=frames,
                       lower=lower, upper=upper, child_points=children,
                       flexion_points=np.array(flex), joint_ids=np.arange(L), side=None,
                       limits_name="custom")
    params = {"major_radius": R, "tube_radius": r, "clearance": gap, "pitch": pitch,
              "num_links": L, "inner_diameter": 2 * (R - r),
              "skip_one_gap": 2 * R - 6 * r - 4 * gap}  # tube gap of links k and k+2 at rest
    return Chain(links, pivots, np.arange(L) - 1, art, params)
