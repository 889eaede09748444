"""Matplotlib figures shared by the notebooks, the docs and the demo report.

Everything here draws on plain matplotlib (static figures render in the docs and in CI); matplotlib
itself is imported inside the functions that need it. Interactive viewers (meshcat, ipywidgets) are
optional extras that notebooks import lazily. Every name below is importable from
``handmesh_tutorial.viz`` itself; the submodules:

* [`mesh3d`][handmesh_tutorial.viz.mesh3d]: 3D hands, meshes, skeletons, joint frames, cylinders
  (notebooks 01 "Hand model" and 03 "Cylinder collision").
* [`images`][handmesh_tutorial.viz.images]: meshes drawn over images, prediction vs ground-truth
  overlays (notebooks 08 "Training" and 09 "Evaluation").
* [`charts`][handmesh_tutorial.viz.charts]: PCK curves, VR tables, error vs VR, loss curves
  (notebooks 08 and 09).
* [`files`][handmesh_tutorial.viz.files]: `save_figure`, the atomic PNG writer.
"""

from __future__ import annotations

from .charts import plot_error_vs_vr, plot_loss_curves, plot_pck_curves, plot_vr_table
from .files import save_figure
from .images import plot_mesh_on_image, plot_overlays
from .mesh3d import (
    FINGER_COLORS,
    HAND_LIGHT,
    HAND_VIEW,
    plot_cylinders,
    plot_frames,
    plot_hand,
    plot_mesh,
    plot_skeleton,
    save_hand_gallery,
    set_axes_equal,
    shade_faces,
)

__all__ = [
    "FINGER_COLORS", "HAND_VIEW", "HAND_LIGHT", "set_axes_equal", "shade_faces", "plot_mesh",
    "plot_skeleton", "plot_frames", "plot_hand", "save_hand_gallery", "plot_cylinders",
    "plot_mesh_on_image", "plot_overlays", "plot_pck_curves", "plot_vr_table", "plot_error_vs_vr",
    "plot_loss_curves", "save_figure",
]
