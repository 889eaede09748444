"""Figures shared by the notebooks, the docs and the demo report: matplotlib, and 3D views.

Everything here draws on plain matplotlib (static figures render in the docs and in CI); matplotlib
itself is imported inside the functions that need it. The interactive views (meshcat,
ipywidgets) are optional extras, imported when first used. Every name below is importable from
``handmesh_tutorial.viz`` itself; the submodules:

* [`mesh3d`][handmesh_tutorial.viz.mesh3d]: 3D hands, meshes, skeletons, joint frames, cylinders
  (notebooks 01 "Hand model" and 03 "Cylinder collision").
* [`images`][handmesh_tutorial.viz.images]: meshes drawn over images, prediction vs ground-truth
  overlays (notebooks 08 "Training" and 09 "Evaluation").
* [`charts`][handmesh_tutorial.viz.charts]: PCK curves, VR tables, error vs VR, loss curves
  (notebooks 08 and 09).
* [`files`][handmesh_tutorial.viz.files]: `save_figure`, the atomic PNG writer.
* [`web3d`][handmesh_tutorial.viz.web3d]: 3D views you turn with the mouse, in Jupyter and on the
  docs site (meshcat's viewer, nothing from another host; docs page "3D views").
* [`explore`][handmesh_tutorial.viz.explore]: sliders over a figure in Jupyter, a strip of frames
  on static pages (notebooks 02 and 05).

Every 3D figure of a hand uses one camera,
[`HAND_VIEW`][handmesh_tutorial.viz.mesh3d.HAND_VIEW] (a three-quarter view, never from the
wrist end): `plot_hand`, `hand_axes` and the browser views.
"""

from __future__ import annotations

from .charts import plot_error_vs_vr, plot_loss_curves, plot_pck_curves, plot_vr_table
from .explore import Explorer, explore
from .files import save_figure
from .images import plot_mesh_on_image, plot_overlays
from .mesh3d import (
    FINGER_COLORS,
    HAND_LIGHT,
    HAND_VIEW,
    hand_axes,
    plot_cylinders,
    plot_frames,
    plot_hand,
    plot_mesh,
    plot_skeleton,
    save_hand_gallery,
    set_axes_equal,
    shade_faces,
    view_direction,
)
from .web3d import View3D, view_hand, view_meshes, view_prediction, viewer_js_path

__all__ = [
    "FINGER_COLORS", "HAND_VIEW", "HAND_LIGHT", "view_direction", "hand_axes", "set_axes_equal",
    "shade_faces", "plot_mesh", "plot_skeleton", "plot_frames", "plot_hand", "save_hand_gallery",
    "plot_cylinders",
    "plot_mesh_on_image", "plot_overlays", "plot_pck_curves", "plot_vr_table", "plot_error_vs_vr",
    "plot_loss_curves", "save_figure", "View3D", "view_meshes", "view_hand", "view_prediction",
    "viewer_js_path", "Explorer", "explore",
]
