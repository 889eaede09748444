"""Headless rendering of INTER-SH scenes with pyrender: image, label mask, depth, bodies alone.

Everything public here is in the **OpenCV camera frame** (x right, y down, z forward, metres) with a
pinhole intrinsic matrix ``K`` in the OpenCV convention::

    K = [[fx, 0, cx],
         [0, fy, cy],
         [0,  0,  1]]      u = fx * X / Z + cx,   v = fy * Y / Z + cy   (pixels)

where pixel ``(row v, column u)`` has its *centre* at integer coordinates. OpenGL's frame appears
only inside [`renderer`][handmesh_tutorial.render.renderer]. Taught in notebook 05 ("Rendering and
the visibility ratio"); the conventions are on the docs page ``docs/concepts/rendering.md``.

Submodules (each name below is also importable from ``handmesh_tutorial.render``):

* `renderer`: the offscreen `Renderer`, `RenderMesh`, `RenderResult`, `CV_TO_GL`.
* `backend`: whether this process has opened an OpenGL context (`gl_opened`); and, private,
  pyrender's one import (EGL when headless, the NumPy 2 fix: docs page "Rendering and cameras").
* `lights`: `Light`, `default_lights`, `random_lights`, and the generator's `scene_lights`.
* `color`: `srgb_to_linear` and black-body light colours (`color_temperature`).
* `backgrounds`: procedural (`random_background`) and photograph (`photo_background`,
  `BACKGROUND_PHOTOS`) backgrounds, the generator's mix (`scene_background`).
* the camera (`intrinsics`, `crop_camera`, `framing`, `project`) lives in
  [`handmesh_tutorial.render.camera`][handmesh_tutorial.render.camera] and is re-exported here;
  ``project`` is `camera.project_checked` (one camera, (N, 3) points, ``Z > 0`` checked).
"""

from __future__ import annotations

from .backend import gl_opened, import_pyrender  # noqa: F401 - import_pyrender: not public
from .backgrounds import (
    BACKGROUND_PHOTOS,
    PHOTO_PROB,
    BackgroundPhoto,
    photo_background,
    photo_pixels,
    random_background,
    scene_background,
)
from .camera import check_intrinsics as _check_K  # noqa: F401 - used by benchmarks/render.py
from .camera import crop_camera, framing, intrinsics
from .camera import project_checked as project
from .color import color_temperature, srgb_to_linear
from .lights import Light, default_lights, random_lights, scene_lights

# _as_meshes, _label_color, _vertex_normals, _check_K: private names that makehuman.py,
# hand/mesh.py and benchmarks/render.py import from ``render``
from .renderer import (  # noqa: F401
    CV_TO_GL,
    Renderer,
    RenderMesh,
    RenderResult,
    _as_meshes,
    _label_color,
    _vertex_normals,
)

__all__ = [
    "BACKGROUND_PHOTOS",
    "PHOTO_PROB",
    "CV_TO_GL",
    "BackgroundPhoto",
    "Light",
    "RenderMesh",
    "RenderResult",
    "Renderer",
    "color_temperature",
    "crop_camera",
    "default_lights",
    "framing",
    "gl_opened",
    "intrinsics",
    "photo_background",
    "photo_pixels",
    "project",
    "random_background",
    "random_lights",
    "scene_background",
    "scene_lights",
    "srgb_to_linear",
]
