"""Matplotlib figures shared by the notebooks, the docs and the demo report.

Everything here draws on plain matplotlib (static figures render in the docs and in CI). Interactive
viewers (meshcat, ipywidgets) are optional extras that notebooks import lazily.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

# One colour per finger, FreiHAND order: thumb, index, middle, ring, pinky.
FINGER_COLORS = ("#d62728", "#ff7f0e", "#2ca02c", "#1f77b4", "#9467bd")


def set_axes_equal(ax, points: np.ndarray | None = None, pad: float = 0.05) -> None:
    """Give a 3D axes equal scale on x, y and z.

    Args:
        ax: a matplotlib ``Axes3D``.
        points: (N,3) points to frame; when ``None`` the current axis limits are used.
        pad: extra margin as a fraction of the largest extent.
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
    """
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces)
    tri = v[f]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12
    light_dir = -np.asarray(light, dtype=float)
    light_dir /= np.linalg.norm(light_dir)
    lambert = np.clip(normals @ light_dir, 0.0, 1.0)
    if base_colors is None:
        rgb = np.tile([0.85, 0.68, 0.58], (len(f), 1))
    else:
        c = np.asarray(base_colors, dtype=float)
        if c.max() > 1.0:
            c = c / 255.0
        rgb = c[f].mean(axis=1) if len(c) == len(v) and len(c) != len(f) else c
    shaded = rgb * (0.35 + 0.65 * lambert[:, None])
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


def save_figure(fig, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Save a matplotlib figure atomically (temp file + rename) and return its path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp" + path.suffix)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=path.suffix.lstrip(".") or "png")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def _to_numpy(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)
