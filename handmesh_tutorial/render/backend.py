"""pyrender's setup: EGL (headless OpenGL), the NumPy 2 fix, one import, one shared EGL display.

pyrender is imported lazily, only here, through `import_pyrender`, which first selects the EGL
platform when no display exists (`_ensure_egl`) and applies the NumPy 2 fix
`_patch_pyrender_numpy2` (see ``docs/concepts/rendering.md``). `_keep_egl_display` lets one
[`Renderer`][handmesh_tutorial.render.renderer.Renderer] close without breaking the others of the
process, which share one EGL display.

Taught in notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

import os
import types
from typing import Any

import numpy as np

from .._optional import require

__all__ = ["gl_opened"]


def _ensure_egl() -> str | None:
    """Select EGL (headless OpenGL) for PyOpenGL when there is no display.

    Sets ``PYOPENGL_PLATFORM=egl`` with ``os.environ.setdefault`` when ``DISPLAY`` and
    ``WAYLAND_DISPLAY`` are unset, so a user's explicit choice (e.g. ``osmesa``) wins. It must run
    before PyOpenGL is first imported, which `import_pyrender` guarantees. Also sets
    ``PYGLET_HEADLESS=1`` the same way: pyrender imports pyglet's window module (for its viewer,
    which offscreen rendering never opens), and without it pyglet loads X11 libraries that a
    headless server may not have (a GPU machine of this project's did not).

    Returns:
        The value of ``PYOPENGL_PLATFORM`` afterwards (``None`` if unset: a display exists).
    """
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        os.environ.setdefault("PYGLET_HEADLESS", "1")
    return os.environ.get("PYOPENGL_PLATFORM")


class _NumpyWithInfty(types.ModuleType):
    """A stand-in for ``numpy`` that forwards every attribute and adds ``infty = inf``."""

    infty = np.inf

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)


def _patch_pyrender_numpy2(mesh_module: types.ModuleType) -> bool:
    """Make pyrender 0.1.45's ``Mesh.bounds`` work under NumPy 2, without touching NumPy.

    ``pyrender/mesh.py`` computes ``Mesh.bounds`` starting from ``np.infty``, an alias NumPy 2
    removed. Every code path that needs bounds then raises ``AttributeError``: ``Mesh.bounds``,
    ``Mesh.centroid``/``extents``/``scale``, ``Scene.bounds``/``centroid``/``scale``, directional
    shadows (the shadow camera is sized from the scene bounds) and the interactive viewer.

    The fix rebinds the *module-local* name ``np`` inside ``pyrender.mesh`` to a proxy module that
    forwards everything to NumPy and adds ``infty = numpy.inf``. NumPy itself is left alone (no
    removed alias resurrected for the whole process), nothing is forked or pinned, and the function
    is a no-op on NumPy 1.x or when already applied.

    Args:
        mesh_module: the ``pyrender.mesh`` module.

    Returns:
        ``True`` when the patch was applied by this call, ``False`` when not needed.
    """
    current = getattr(mesh_module, "np", None)
    if isinstance(current, _NumpyWithInfty):
        return False
    if current is not None and hasattr(current, "infty"):  # NumPy 1.x: nothing to fix
        return False
    mesh_module.np = _NumpyWithInfty("numpy")
    return True


_PYRENDER = None
_GL_OPENED = False  # set by the first Renderer of this process, never reset


def gl_opened() -> bool:
    """Whether this process has opened an OpenGL context (any
    [`Renderer`][handmesh_tutorial.render.renderer.Renderer], even one closed since).

    A forked child inherits a copy of the graphics driver's state without the driver's threads
    (Mesa's llvmpipe rasterises in its own threads); creating a context there can hang. Worker
    pools therefore fork only from a process where this is ``False``
    ([`generate_dataset`][handmesh_tutorial.data.generate_dataset], ``mp_context="auto"``).
    Importing pyrender (`import_pyrender`) opens no context.
    """
    return _GL_OPENED


def import_pyrender() -> types.ModuleType:
    """Import pyrender once: EGL when headless (`_ensure_egl`), then the NumPy 2 fix.

    This is the only place in the library that imports pyrender.

    Returns:
        The ``pyrender`` module.
    """
    global _PYRENDER
    if _PYRENDER is None:
        _ensure_egl()
        require("OpenGL", "rendering (pyrender)")
        pyrender = require("pyrender", "rendering")
        require("pyrender.mesh", "rendering")

        _patch_pyrender_numpy2(pyrender.mesh)
        _PYRENDER = pyrender
    return _PYRENDER


def _keep_egl_display(platform: Any) -> None:
    """Make a pyrender EGL platform's ``delete_context`` destroy its context only, without
    ``eglTerminate`` on the display that the process's other renderers still use."""
    if platform is None or not hasattr(platform, "_egl_display"):
        return

    def delete_context() -> None:
        from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglDestroyContext, eglMakeCurrent

        if platform._egl_display is not None:
            if platform._egl_context is not None:
                eglMakeCurrent(platform._egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE,
                               EGL_NO_CONTEXT)
                eglDestroyContext(platform._egl_display, platform._egl_context)
                platform._egl_context = None
            platform._egl_display = None

    platform.delete_context = delete_context
