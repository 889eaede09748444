"""handmesh_tutorial: rebuild, understand and reuse MSMR-Net, INTER-SH and the visibility ratio.

Import it as ``import handmesh_tutorial as hmt``. Submodules (``hmt.hand``, ``hmt.nn.spiral``, ...)
are imported on first attribute access, so ``import handmesh_tutorial`` stays fast and does not
start an OpenGL context or load torch until a module that needs it is used.
"""

from __future__ import annotations

import importlib

from . import _aliases
from ._version import __version__
from .budget import Budget, budget

# The library in the paper's data-flow order (docs page "The pipeline"); `apps` sits on top.
_SUBMODULES = (
    "hand", "lcs", "collision", "objects", "scenes", "render", "visibility", "data", "nn",
    "train", "metrics", "viz", "pretrained", "export", "inference", "budget", "testing", "apps",
)

__all__ = ["Budget", "budget", "__version__", *(m for m in _SUBMODULES if m != "budget")]

_aliases.install()  # four module paths of 0.1 that are fixed entry points (``hmt.spiral``...)


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _aliases.MOVED:
        return importlib.import_module(f"{__name__}.{name}")  # a stand-in, with a FutureWarning
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_SUBMODULES))
