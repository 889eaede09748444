"""The optional dependencies (pip extras) and the one helper that imports them.

The core install (``pip install handmesh_tutorial``) is what the components a researcher lifts
need: torch, numpy, scipy, trimesh, tqdm and pillow. Scene generation and rendering, figures,
the notebooks' widgets and ONNX export need more; they come as extras (``pip install
"handmesh_tutorial[scenes]"``, ``[notebooks]``, ``[export]``, ``[docs]``, ``[dev]``; ``make setup``
installs them all). The library imports an extra's package only inside the function that needs
it, through `require`, so a missing extra fails there with an `ImportError` that names the extra
to install. Docs page "Installation".
"""

from __future__ import annotations

import importlib
import importlib.util
import types

__all__ = ["EXTRAS", "missing_extra_message", "require"]

EXTRAS: dict[str, tuple[str, str]] = {
    # import name: (distribution on PyPI, the extra of pyproject.toml that installs it)
    "pyrender": ("pyrender", "scenes"),
    "OpenGL": ("PyOpenGL", "scenes"),
    "manifold3d": ("manifold3d", "scenes"),
    "rtree": ("rtree", "scenes"),
    "skimage": ("scikit-image", "scenes"),
    "numba": ("numba", "scenes"),
    "matplotlib": ("matplotlib", "notebooks"),
    "ipywidgets": ("ipywidgets", "notebooks"),
    "meshcat": ("meshcat", "notebooks"),
    "onnx": ("onnx", "export"),
    "onnxscript": ("onnxscript", "export"),
    "onnxruntime": ("onnxruntime", "export"),
}
"""Each optional package the library imports: import name -> (PyPI distribution, extra)."""


def missing_extra_message(module: str, what: str) -> str:
    """The message for a missing optional package: what needs it and the install line.

    Args:
        module: import name (a key of `EXTRAS`; a dotted name counts by its first part).
        what: the feature that needs it, e.g. ``"hmt.viz figures"``.

    Raises:
        KeyError: ``module`` is not an optional package of the library.
    """
    dist, extra = EXTRAS[module.partition(".")[0]]
    return (f"{what} needs {dist}, which the core install leaves out: "
            f'pip install "handmesh_tutorial[{extra}]" (in a clone, `make setup` installs '
            "every extra)")


def require(module: str, what: str) -> types.ModuleType:
    """Import an optional package (or one of its submodules), naming the extra when it is missing.

    Args:
        module: import name, e.g. ``"matplotlib.pyplot"``; its first part is a key of `EXTRAS`.
        what: the feature that needs it (goes into the message).

    Returns:
        The imported module.

    Raises:
        ModuleNotFoundError: the package is not installed; the message names the extra
            (``pip install "handmesh_tutorial[scenes]"``). An import error from *inside* an
            installed package (a dependency of its own, a missing submodule) is raised unchanged.
    """
    top = module.partition(".")[0]
    try:
        return importlib.import_module(module)
    except ImportError as err:
        if top not in EXTRAS or _installed(top):  # installed but broken inside: a real error
            raise
        raise ModuleNotFoundError(missing_extra_message(top, what), name=top) from err


def _installed(top: str) -> bool:
    try:
        return importlib.util.find_spec(top) is not None
    except (ImportError, ValueError):  # a half-imported module without a spec
        return False
