"""Meshes drawn over images: a camera-frame mesh projected with the image's intrinsics, and the
demo's prediction-versus-ground-truth overlays.

Vertices in metres in the OpenCV camera frame (x right, y down, z forward); ``K`` (3, 3) in pixels;
images (H, W, 3) uint8. Taught in notebook 08 ("Training") and notebook 09 ("Evaluation").
"""

from __future__ import annotations

import math

import numpy as np

from .._optional import require
from ..render.camera import project
from ._common import _to_numpy

__all__ = ["plot_mesh_on_image", "plot_overlays"]


def plot_mesh_on_image(ax, image, vertices, faces, K, color=(0.35, 0.6, 1.0), alpha: float = 0.6,
                       wireframe: bool = False, linewidth: float = 0.3, zoom: float | None = 1.4,
                       title: str | None = None):
    """Draw a camera-frame mesh over an image: projected with ``K``, depth-sorted, shaded.

    Faces are drawn back to front (painter's algorithm, no z-buffer), shaded by how directly they
    face the camera, so a hand reads as a 3D surface; ``wireframe=True`` draws only the edges.

    Args:
        ax: a matplotlib 2D ``Axes``.
        image: (H, W, 3) uint8 image (shown as the background); ``None`` draws on a blank axes.
        vertices: (V, 3) mesh in the camera frame (OpenCV: x right, y down, z forward), metres.
        faces: (F, 3) vertex indices.
        K: (3, 3) intrinsics of ``image``.
        color: RGB in [0, 1] of the mesh.
        alpha: face opacity.
        wireframe: edges only (no filled faces).
        linewidth: edge width.
        zoom: frame the view on the projected mesh, this many times its bounding box (``None``
            keeps the whole image).
        title: axes title.

    Returns:
        The ``PolyCollection`` drawn.

    Shapes:
        ``image (H, W, 3)``, ``vertices (V, 3)``, ``faces (F, 3)``, ``K (3, 3)``.
    """
    PolyCollection = require("matplotlib.collections", "hmt.viz figures").PolyCollection

    v = np.asarray(_to_numpy(vertices), dtype=np.float64)
    f = np.asarray(_to_numpy(faces), dtype=np.int64)
    k = np.asarray(_to_numpy(K), dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3), got {v.shape}")
    if k.shape != (3, 3):
        raise ValueError(f"K must be (3, 3), got {k.shape}")
    # points at or behind the camera plane are drawn at z = 1e-6 m (finite, far off the image)
    uv = project(np.column_stack([v[:, :2], np.clip(v[:, 2], 1e-6, None)]), k)
    if image is not None:
        ax.imshow(image)
    tri = v[f]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12
    view = tri.mean(1)
    view /= np.linalg.norm(view, axis=1, keepdims=True) + 1e-12
    shade = 0.35 + 0.65 * np.abs((normals * view).sum(1))
    order = np.argsort(-tri[:, :, 2].mean(1))  # far faces first
    rgba = np.zeros((len(f), 4))
    rgba[:, :3] = np.clip(np.asarray(color, dtype=float)[None] * shade[:, None], 0, 1)
    rgba[:, 3] = alpha
    if wireframe:
        coll = PolyCollection(uv[f][order], facecolors="none", edgecolors=[(*color, alpha)],
                              linewidths=linewidth)
    else:
        coll = PolyCollection(uv[f][order], facecolors=rgba[order], edgecolors="none")
    ax.add_collection(coll)
    if zoom is not None:
        lo, hi = uv.min(0), uv.max(0)
        c, half = (lo + hi) / 2, max(float((hi - lo).max()), 1.0) * zoom / 2
        ax.set_xlim(c[0] - half, c[0] + half)
        ax.set_ylim(c[1] + half, c[1] - half)  # image rows grow downwards
    elif image is not None:
        ax.set_xlim(-0.5, image.shape[1] - 0.5)
        ax.set_ylim(image.shape[0] - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title is not None:
        ax.set_title(title, fontsize="small")
    return coll


def plot_overlays(samples: list, pred_vertices, faces, titles: list | None = None,
                  gt_color=(0.2, 0.8, 0.3), pred_color=(0.35, 0.6, 1.0)):
    """Figure: per sample, the input scene, the ground-truth mesh and the predicted mesh on it.

    Args:
        samples: INTER-SH sample dicts (``image``, ``K``, ``meshes``, ``target``, ``kind``,
            ``vr``).
        pred_vertices: (N, V, 3) predictions in each sample's camera frame, metres.
        faces: (F, 3) faces of the predicted meshes.
        titles: optional extra text per sample (e.g. its error).
        gt_color: RGB of the ground truth.
        pred_color: RGB of the prediction.

    Returns:
        The matplotlib figure (rows of 3 panels, two samples per row).

    Shapes:
        ``pred_vertices (N, V, 3)``, ``faces (F, 3)``; ``samples`` and ``titles`` of length N.
    """
    plt = require("matplotlib.pyplot", "hmt.viz figures")

    n = len(samples)
    if len(pred_vertices) != n:
        raise ValueError(f"{n} samples but {len(pred_vertices)} predictions")
    rows = math.ceil(n / 2)
    # constrained layout keeps the two-line titles of the prediction panels clear of the row above
    fig, axes = plt.subplots(rows, 6, figsize=(12, 2.2 * rows), squeeze=False,
                             layout="constrained")
    for ax in axes.ravel():
        ax.axis("off")
    for i, s in enumerate(samples):
        r, c = divmod(i, 2)
        a = axes[r, 3 * c: 3 * c + 3]
        t = s["target"]
        gv, gf = s["meshes"][t]
        extra = "" if titles is None else f"\n{titles[i]}"
        plot_mesh_on_image(a[0], s["image"], gv, gf, s["K"], alpha=0.0,
                               title=f"{s['kind']}, VR {s['vr'][t]:.2f}")
        plot_mesh_on_image(a[1], s["image"], gv, gf, s["K"], color=gt_color,
                               title="ground truth")
        plot_mesh_on_image(a[2], s["image"], pred_vertices[i], faces, s["K"],
                               color=pred_color, title=f"prediction{extra}")
        # identical framing in the three panels: the ground-truth box
        for ax in a[1:]:
            ax.set_xlim(a[0].get_xlim())
            ax.set_ylim(a[0].get_ylim())
        for ax in a:
            ax.axis("on")
            ax.set_xticks([])
            ax.set_yticks([])
    return fig
