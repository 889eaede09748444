"""3D figures of hands and bodies: shaded meshes, skeletons, joint frames, cylinders, hand views.

Everything draws on a matplotlib ``Axes3D`` with plain matplotlib (static figures render in the
docs and in CI). Positions in metres; meshes (V, 3) vertices and (F, 3) faces; keypoints (21, 3)
in FreiHAND order. Taught in notebook 01 ("Hand model"); the cylinders in notebook 03 ("Cylinder
collision").
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._optional import require
from ._common import _to_numpy
from .files import save_figure

__all__ = ["FINGER_COLORS", "HAND_VIEW", "HAND_LIGHT", "view_direction", "hand_axes",
           "set_axes_equal", "shade_faces", "plot_mesh", "plot_skeleton", "plot_frames",
           "plot_hand", "save_hand_gallery", "plot_cylinders"]

# One colour per finger, FreiHAND order: thumb, index, middle, ring, pinky.
FINGER_COLORS = ("#d62728", "#ff7f0e", "#2ca02c", "#1f77b4", "#9467bd")


def set_axes_equal(ax, points: np.ndarray | None = None, pad: float = 0.05) -> None:
    """Give a 3D axes equal scale on x, y and z.

    Args:
        ax: a matplotlib ``Axes3D``.
        points: (N,3) points to frame; when ``None`` the current axis limits are used.
        pad: extra margin as a fraction of the largest extent.

    Shapes:
        ``points (N, 3)``.
    """
    if points is None:
        lims = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])
    else:
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        lims = np.stack([pts.min(0), pts.max(0)], axis=1)
    centre = lims.mean(axis=1)
    radius = 0.5 * (lims[:, 1] - lims[:, 0]).max() * (1 + pad)
    ax.set_xlim3d(centre[0] - radius, centre[0] + radius)
    ax.set_ylim3d(centre[1] - radius, centre[1] + radius)
    ax.set_zlim3d(centre[2] - radius, centre[2] + radius)
    ax.set_box_aspect((1, 1, 1))


def _lambert_factor(normals: np.ndarray, light) -> np.ndarray:
    """Brightness (P,) 0.35 + 0.65 * max(0, n . -light) of unit normals (P, 3)."""
    light_dir = -np.asarray(light, dtype=float).reshape(3)
    light_dir /= np.linalg.norm(light_dir)
    return 0.35 + 0.65 * np.clip(normals @ light_dir, 0.0, 1.0)


def shade_faces(vertices: np.ndarray, faces: np.ndarray, base_colors: np.ndarray | None = None,
                light: tuple[float, float, float] = (0.3, -0.5, -1.0)) -> np.ndarray:
    """Per-face RGBA colours with simple Lambert shading, for ``Poly3DCollection``.

    Args:
        vertices: (V,3) positions.
        faces: (F,3) vertex indices.
        base_colors: (V,3) or (F,3) RGB in [0,1]; a skin-like grey when ``None``.
        light: direction *towards* which the light travels, any length.

    Returns:
        (F,4) RGBA in [0,1].

    Shapes:
        ``vertices (V, 3)``, ``faces (F, 3)``, ``base_colors (V, 3)`` or ``(F, 3)`` -> ``(F, 4)``.
    """
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces)
    tri = v[f]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12
    if base_colors is None:
        rgb = np.tile([0.85, 0.68, 0.58], (len(f), 1))
    else:
        c = np.asarray(base_colors, dtype=float)
        if c.max() > 1.0:
            c = c / 255.0
        rgb = c[f].mean(axis=1) if len(c) == len(v) and len(c) != len(f) else c
    shaded = rgb * _lambert_factor(normals, light)[:, None]
    return np.concatenate([np.clip(shaded, 0, 1), np.ones((len(f), 1))], axis=1)


def plot_mesh(ax, vertices, faces, colors=None, alpha: float = 1.0, edgecolor=None,
              linewidth: float = 0.0, light=(0.3, -0.5, -1.0)):
    """Draw a triangle mesh on a 3D axes with Lambert shading.

    Args:
        ax: a matplotlib ``Axes3D``.
        vertices: (V,3) positions (any unit; metres in this library); numpy or torch.
        faces: (F,3) vertex indices.
        colors: optional (V,3) or (F,3) RGB in [0,1] (or 0-255).
        alpha: face opacity.
        edgecolor: colour of triangle edges (``None`` draws none).
        linewidth: edge width.
        light: light direction for shading.

    Returns:
        The added ``Poly3DCollection``.

    Shapes:
        ``vertices (V, 3)``, ``faces (F, 3)``, ``colors (V, 3)`` or ``(F, 3)``.
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    v = _to_numpy(vertices)
    f = np.asarray(_to_numpy(faces), dtype=np.int64)
    facecolors = shade_faces(v, f, colors, light=light)
    facecolors[:, 3] = alpha
    coll = Poly3DCollection(v[f], facecolors=facecolors,
                            edgecolors=edgecolor if edgecolor is not None else "none",
                            linewidths=linewidth)
    ax.add_collection3d(coll)
    set_axes_equal(ax, v)
    return coll


def plot_skeleton(ax, joints, parents=None, colors=FINGER_COLORS, linewidth: float = 2.0,
                  marker_size: float = 12.0) -> None:
    """Draw the 21-keypoint skeleton (FreiHAND order) on a 3D axes, one colour per finger.

    Args:
        ax: a matplotlib ``Axes3D``.
        joints: (21,3) keypoints, FreiHAND order (0 wrist, 1-4 thumb, ..., 17-20 pinky).
        parents: (21,) parent index per keypoint (-1 for the wrist); FreiHAND's when ``None``.
        colors: five colours, thumb to pinky.
        linewidth: bone line width.
        marker_size: joint marker size.

    Shapes:
        ``joints (21, 3)``, ``parents (21,)``.
    """
    j = _to_numpy(joints).reshape(-1, 3)
    if parents is None:
        parents = [-1] + [0 if k % 4 == 1 else k - 1 for k in range(1, 21)]
    for k, p in enumerate(parents):
        if p < 0:
            continue
        c = colors[(k - 1) // 4]
        ax.plot(*np.stack([j[p], j[k]]).T, color=c, linewidth=linewidth)
    ax.scatter(*j.T, s=marker_size, c="k", depthshade=False)


def plot_frames(ax, origins, frames, length: float = 0.012,
                colors=("#d62728", "#2ca02c", "#1f77b4"), linewidth: float = 1.5,
                labels: bool = False) -> None:
    """Draw local coordinate systems as three arrows each (x red, y green, z blue by default).

    Args:
        ax: a matplotlib ``Axes3D``.
        origins: (J,3) frame origins (e.g. joint positions), metres.
        frames: (J,3,3) rotation matrices whose *columns* are the x, y, z axes
            ([`handmesh_tutorial.lcs.local_frames`][handmesh_tutorial.lcs.local_frames]).
        length: arrow length, same unit as ``origins``.
        colors: colours of the x, y and z arrows.
        linewidth: arrow line width.
        labels: write "x", "y", "z" at the arrow tips of the first frame (for a legend).

    Shapes:
        ``origins (J, 3)``, ``frames (J, 3, 3)``.
    """
    o = _to_numpy(origins).reshape(-1, 3)
    f = _to_numpy(frames).reshape(-1, 3, 3)
    for axis in range(3):
        d = f[:, :, axis] * length
        ax.quiver(o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2], color=colors[axis],
                  linewidth=linewidth, arrow_length_ratio=0.25)
        if labels and len(o):
            tip = o[0] + 1.15 * d[0]
            ax.text(*tip, "xyz"[axis], color=colors[axis], fontsize=9)


HAND_VIEW = {"elev": 45.0, "azim": 25.0, "vertical_axis": "y"}
"""The one camera for hands in the hand template's frame (+x wrist to fingers, palm -y, right
thumb -z): a three-quarter view from above the back of the hand (+y up), from the pinky side of
a right hand and a little towards the fingertips, never from the wrist end. ``ax.view_init``
keywords; [`view_direction`][handmesh_tutorial.viz.mesh3d.view_direction] gives its viewing
direction, which [`plot_hand`][handmesh_tutorial.viz.mesh3d.plot_hand],
[`hand_axes`][handmesh_tutorial.viz.mesh3d.hand_axes] and the browser views of
[`handmesh_tutorial.viz.web3d`][handmesh_tutorial.viz.web3d] share.
"""
HAND_LIGHT = (-0.3, -1.0, -0.6)
"""Light for that view (travels down and away from the viewer)."""

_AXES = {"x": 0, "y": 1, "z": 2}


def view_direction(view: dict | None = None) -> np.ndarray:
    """Unit vector along which a matplotlib 3D view looks (from the eye towards the target).

    Matplotlib places the eye at ``(cos e cos a, cos e sin a, sin e)`` for the vertical axis z,
    the components rolled so that the third one lands on ``vertical_axis``
    ([`Axes3D.view_init`](https://matplotlib.org/stable/api/toolkits/mplot3d/view_angles.html)).

    Args:
        view: ``ax.view_init`` keywords ``elev``, ``azim`` (degrees), ``vertical_axis``
            (``"x"``, ``"y"`` or ``"z"``, default ``"z"``);
            [`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW] when ``None``.

    Returns:
        ``(3,)`` unit vector in the data frame, pointing from the eye to the target.

    Raises:
        ValueError: an unknown ``vertical_axis``.
    """
    view = HAND_VIEW if view is None else view
    axis = view.get("vertical_axis", "z")
    if axis not in _AXES:
        raise ValueError(f"vertical_axis must be 'x', 'y' or 'z', got {axis!r}")
    e, a = np.deg2rad(view.get("elev", 30.0)), np.deg2rad(view.get("azim", -60.0))
    eye = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    return -np.roll(eye, _AXES[axis] - 2)


def hand_axes(fig, *subplot, view: dict | None = None):
    """A 3D axes on ``fig`` seen from the shared hand camera, axes hidden.

    For figures of hands that draw with the primitives (``plot_mesh``, ``plot_skeleton``,
    ``plot_frames``) rather than [`plot_hand`][handmesh_tutorial.viz.mesh3d.plot_hand].

    Args:
        fig: a matplotlib ``Figure``.
        *subplot: ``fig.add_subplot`` position, e.g. ``1, 3, 2`` (default ``1, 1, 1``).
        view: ``ax.view_init`` keywords; [`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW]
            when ``None``.

    Returns:
        The ``Axes3D``.
    """
    ax = fig.add_subplot(*(subplot or (1, 1, 1)), projection="3d")
    ax.view_init(**(HAND_VIEW if view is None else view))
    ax.set_axis_off()
    return ax


def plot_hand(ax, vertices, faces, colors=None, joints=None, view: dict | None = None,
              title: str | None = None, light=HAND_LIGHT, edgecolor=None,
              linewidth: float = 0.0) -> None:
    """Draw one hand (mesh, optionally its 21 keypoints) on a 3D axes, axes hidden.

    Args:
        ax: a matplotlib ``Axes3D``.
        vertices: (V,3) metres (numpy or torch).
        faces: (F,3) int.
        colors: (V,3) RGB in [0,1], e.g. ``HandModel.vertex_colors()``.
        joints: optional (21,3) keypoints, FreiHAND order, drawn on top.
        view: ``ax.view_init`` keywords; [`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW] when
            ``None``.
        title: axes title.
        light: light direction for the shading (flipped to the palm side for views from below).
        edgecolor: triangle edge colour (``None``: no edges).
        linewidth: triangle edge width.

    Shapes:
        ``vertices (V, 3)``, ``faces (F, 3)``, ``colors (V, 3)``, ``joints (21, 3)``.
    """
    view = HAND_VIEW if view is None else view
    if light is HAND_LIGHT and view.get("elev", 0) < 0:
        light = (light[0], -light[1], light[2])   # seen from below: light the palm side
    plot_mesh(ax, vertices, faces, colors=colors, light=light, edgecolor=edgecolor,
              linewidth=linewidth, alpha=0.55 if joints is not None else 1.0)
    if joints is not None:
        plot_skeleton(ax, joints, linewidth=1.5, marker_size=6)
    ax.view_init(**view)
    ax.set_box_aspect((1, 1, 1), zoom=1.5)  # a hand fills little of its bounding cube
    ax.set_axis_off()
    if title:
        ax.set_title(title, fontsize=10)


def save_hand_gallery(path: str | os.PathLike, seed: int = 0, dpi: int = 90) -> Path:
    """Figure of the hand model, right and left, in a few poses, saved atomically as PNG.

    Rows: right hand, left hand (the left is posed with the mirrored pose, see
    [`handmesh_tutorial.hand.mirror_axis_angle`][handmesh_tutorial.hand.mirror_axis_angle]).
    Columns: flat (rest), fist, pointing, pinch, and a random pose drawn from ``seed``.

    Args:
        path: output ``.png`` (parent folders are created).
        seed: seed of the random pose and of the skin tones.
        dpi: resolution.

    Returns:
        The written path.
    """
    matplotlib = require("matplotlib", "hmt.viz figures")

    if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        matplotlib.use("Agg")  # headless-safe; harmless when already on Agg
    import matplotlib.pyplot as plt
    import torch

    from .. import hand

    rng = np.random.default_rng(seed)
    tones = rng.choice(4, size=2, replace=False)   # the lighter tones read best in print
    random_right = hand.random_pose(rng, 1)[0]
    names = ("flat", "fist", "point", "pinch", "random")
    fig = plt.figure(figsize=(3.0 * len(names), 6.2))
    for row, side in enumerate(("right", "left")):
        model = hand.HandModel(side)
        colors = model.vertex_colors(tone=int(tones[row]), rng=seed)
        for col, name in enumerate(names):
            if name == "random":
                pose = random_right if side == "right" else hand.mirror_axis_angle(random_right)
            else:
                pose = hand.example_pose(name, side)
            with torch.no_grad():
                out = model(pose=torch.as_tensor(pose)[None])
            ax = fig.add_subplot(2, len(names), row * len(names) + col + 1, projection="3d")
            plot_hand(ax, out.vertices[0], model.faces, colors=colors,
                      title=f"{side}: {name}")
    fig.suptitle(f"MakeHuman hand ({model.num_vertices} vertices), right and left, seed={seed}",
                 fontsize=11)
    fig.tight_layout()
    try:
        return save_figure(fig, path, dpi=dpi)
    finally:
        plt.close(fig)


def _cylinder_polygons(p0, p1, r, n: int = 24):
    """Side quads and two cap polygons of one cylinder, (k, 3) arrays in metres."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    u = p1 - p0
    u = u / np.linalg.norm(u)
    helper = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    ang = np.linspace(0, 2 * np.pi, n + 1)
    ring = r * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    bottom, top = p0 + ring, p1 + ring
    quads = [np.array([bottom[k], bottom[k + 1], top[k + 1], top[k]]) for k in range(n)]
    return quads, [bottom[:-1], top[:-1]]


def _same_length(polygons: list) -> np.ma.MaskedArray:
    """Polygons of different vertex counts as one masked (P, max count, 3) array: each padded
    with copies of its last vertex, the padding masked (matplotlib then ignores it when it sorts
    and draws, as it does for a ragged list).

    Matplotlib's ``Poly3DCollection`` stores a ragged list in an uninitialised (``np.empty``)
    array and autoscales the axes on all of it, padding included (matplotlib 3.11), so whatever
    the heap held there could reach the axis limits: infinite limits or a singular projection in
    a long-running Jupyter kernel, never in a fresh script. Here the padding is finite and inside
    the polygon's own bounds.
    """
    counts = np.array([len(p) for p in polygons])
    m = int(counts.max())
    data = np.stack([np.concatenate([p, np.repeat(p[-1:], m - len(p), axis=0)])
                     for p in map(np.asarray, polygons)])
    pad = np.arange(m)[None, :, None] >= counts[:, None, None]
    return np.ma.MaskedArray(data, mask=np.broadcast_to(pad, data.shape))


def _polygon_normals(polygons: list) -> np.ndarray:
    """Unit normals (P, 3) of planar polygons by Newell's method (robust to repeated vertices)."""
    n = np.stack([np.cross(q, np.roll(q, -1, axis=0)).sum(0) for q in map(np.asarray, polygons)])
    return n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-300)


def plot_cylinders(ax, cylinders, colors=None, alpha=0.35, segments: int = 24,
                   edgecolor=None, axes: bool = True, labels: bool = False,
                   capsule: bool = False, light=None):
    """Draw a [`Cylinders`][handmesh_tutorial.collision.Cylinders] body on a 3D axes.

    Flat colours by default (one artist per cylinder). With ``light`` the polygons are shaded
    like [`shade_faces`][handmesh_tutorial.viz.mesh3d.shade_faces] (Lambert, outward normals,
    ambient 0.35) and all cylinders go into *one* artist, so matplotlib depth-sorts their
    polygons against each other (separate artists are sorted whole, which draws a cylinder
    behind another over it); that is what makes overlapping opaque cylinders, e.g. a hand,
    readable.

    Args:
        ax: a matplotlib ``Axes3D``.
        cylinders: the body (or any object with ``p0``, ``p1`` (N,3) and ``radius`` (N,), metres).
        colors: one colour for all, or N colours; default: by ``parts`` (finger colours).
        alpha: face opacity, one for all or N values (e.g. a see-through palm).
        segments: polygons around each cylinder.
        edgecolor: polygon edge colour (None: no edges).
        axes: also draw each axis segment as a line.
        labels: write each cylinder's name at its middle.
        capsule: draw capsules (hemispherical ends) instead of flat end caps.
        light: direction *towards* which the light travels, any length (e.g.
            [`HAND_LIGHT`][handmesh_tutorial.viz.mesh3d.HAND_LIGHT]); ``None``: flat colours.

    Returns:
        The list of added ``Poly3DCollection`` artists: one per cylinder, or one in all with
        ``light``.

    Raises:
        ValueError: ``light`` of zero length; ``alpha`` neither one value nor N.
    """
    to_rgba = require("matplotlib.colors", "hmt.viz figures").to_rgba
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    p0, p1 = np.asarray(cylinders.p0, float), np.asarray(cylinders.p1, float)
    radius = np.asarray(cylinders.radius, float)
    n = len(p0)
    if colors is None:
        parts = np.asarray(getattr(cylinders, "parts", np.zeros(n, int)))
        palette = FINGER_COLORS + ("#8c564b", "#7f7f7f", "#bcbd22", "#17becf")
        colors = [palette[int(k) % len(palette)] for k in parts]
    elif isinstance(colors, str) or np.ndim(colors) == 1 and len(colors) in (3, 4) and n != 3:
        colors = [colors] * n
    alphas = np.broadcast_to(np.asarray(alpha, dtype=float), (n,)) if np.ndim(alpha) == 0 \
        else np.asarray(alpha, dtype=float)
    if alphas.shape != (n,):
        raise ValueError(f"alpha must be one value or {n} values, got {np.shape(alpha)}")
    if light is not None:
        if not np.linalg.norm(np.asarray(light, dtype=float)) > 0:
            raise ValueError(f"light must be a non-zero direction, got {light!r}")
        shaded_polys, shaded_rgba = [], []
    artists = []
    for k in range(n):
        quads, caps = _cylinder_polygons(p0[k], p1[k], radius[k], segments)
        polys = quads
        if capsule:
            u = (p1[k] - p0[k]) / np.linalg.norm(p1[k] - p0[k])
            lat = np.linspace(0, np.pi / 2, max(segments // 4, 3))
            for end, sign in ((p0[k], -1.0), (p1[k], 1.0)):
                rings = []
                for a in lat:
                    q, _ = _cylinder_polygons(end, end + u, radius[k] * np.cos(a), segments)
                    rings.append(np.array([qq[0] for qq in q]) + sign * radius[k] * np.sin(a) * u)
                for r0, r1 in zip(rings[:-1], rings[1:], strict=True):
                    m = len(r0)
                    polys = polys + [np.array([r0[i], r0[(i + 1) % m], r1[(i + 1) % m], r1[i]])
                                     for i in range(m)]
        else:
            polys = polys + caps
        if light is not None:
            normals = _polygon_normals(polys)
            centre = 0.5 * (p0[k] + p1[k])
            outward = np.stack([np.asarray(q).mean(0) for q in polys]) - centre
            normals *= np.where((normals * outward).sum(1) < 0, -1.0, 1.0)[:, None]
            rgba = np.tile(to_rgba(colors[k], alphas[k]), (len(polys), 1))
            rgba[:, :3] *= _lambert_factor(normals, light)[:, None]
            shaded_polys += polys
            shaded_rgba.append(rgba)
        else:
            col = Poly3DCollection(_same_length(polys), facecolor=to_rgba(colors[k], alphas[k]),
                                   edgecolor=edgecolor or "none", linewidth=0.3)
            ax.add_collection3d(col)
            artists.append(col)
        if axes:
            ax.plot(*np.stack([p0[k], p1[k]]).T, color=colors[k], linewidth=1.0)
        if labels:
            names = getattr(cylinders, "names", None)
            if names:
                ax.text(*(0.5 * (p0[k] + p1[k])), names[k], fontsize="x-small")
    if light is not None and shaded_polys:
        col = Poly3DCollection(_same_length(shaded_polys), facecolors=np.concatenate(shaded_rgba),
                               edgecolor=edgecolor or "none", linewidth=0.3)
        ax.add_collection3d(col)
        artists.append(col)
    return artists
