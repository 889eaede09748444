"""handmesh_tutorial: rebuild, understand and reuse MSMR-Net, INTER-SH and the visibility ratio.

Import it as ``import handmesh_tutorial as hmt``. Submodules (``hmt.hand``, ``hmt.spiral``, ...)
are imported on first attribute access, so ``import handmesh_tutorial`` stays fast and does not
start an OpenGL context or load torch until a module that needs it is used.
"""

from __future__ import annotations

import importlib

from ._version import __version__
from .budget import Budget, budget

# One module per concept; see docs/index.md for the data flow between them.
_SUBMODULES = (
    "augment", "blocks", "budget", "camera", "cli", "collision", "dataset", "decoder", "demo",
    "encoder", "fit", "freihand", "hand", "inference", "interact", "keypoints", "lcs", "losses",
    "makehuman",
    "mano", "metrics", "model", "objects", "pose_encoder", "pretrained", "render", "rotation",
    "sampling", "skinned", "spiral", "surface", "testing", "train", "visibility", "viz",
)

__all__ = ["Budget", "budget", "__version__", *_SUBMODULES]


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_SUBMODULES))
