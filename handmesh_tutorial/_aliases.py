"""The four module paths of 0.1 that DESIGN's fixed entry points name, kept importable.

``hmt.spiral.spiral_indices`` / ``hmt.spiral.SpiralConv``, ``hmt.sampling.mesh_hierarchy``,
``hmt.model.build_model`` and ``hmt.model.pretrained`` and ``hmt.dataset.InterSHDataset`` are the
project's fixed public entry points (tests, docs and outside checks call them), so their paths
stay: each is a stand-in module that hands out the names of its new home, with a
``FutureWarning`` that names that home (new code imports it). The other stand-ins of 0.1 and the
0.1 names of plumbing made private in 0.2 are removed after 0.6.0 (``CHANGELOG.md``), as promised
for 0.4.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__all__ = ["MOVED", "MOVED_NAMES", "install", "moved_attribute"]

_P = "handmesh_tutorial."

MOVED: dict[str, tuple[str, ...]] = {
    # old module path -> its new home(s), first match wins for a name
    "dataset": ("data",),
    "model": ("nn.model",),
    "sampling": ("nn.hierarchy",),
    "spiral": ("nn.spiral",),
}
"""Old module (without the ``handmesh_tutorial.`` prefix) -> new module(s). A submodule of a moved
package moves with it (``dataset.files`` -> ``data.files``)."""

MOVED_NAMES: dict[str, dict[str, str]] = {
    # names that left a module which still exists: module -> {name: new module}
    "model": {"pretrained": "pretrained"},
}
"""Names that moved out of a module: old module -> {name: its new module}."""

_KEPT = "the old path stays (a fixed entry point); new code imports the new one"


def _targets(old: str) -> tuple[str, ...] | None:
    """New modules of an old module path (full names), or None when it did not move."""
    rel = old[len(_P):] if old.startswith(_P) else None
    if rel is None:
        return None
    best = max((k for k in MOVED if rel == k or rel.startswith(k + ".")), key=len, default=None)
    if best is None:
        return None
    rest = rel[len(best):]
    return tuple(_P + t + rest for t in MOVED[best])


def moved_attribute(module: str, name: str):
    """``name`` of a module from its new home (`MOVED_NAMES`), with a ``FutureWarning``.

    Raises:
        AttributeError: ``name`` did not move out of ``module``.
    """
    rel = module[len(_P):] if module.startswith(_P) else module
    new = MOVED_NAMES.get(rel, {}).get(name)
    if new is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    warnings.warn(f"{module}.{name} is now {_P}{new}.{name}; {_KEPT}", FutureWarning,
                  stacklevel=3)
    return getattr(importlib.import_module(_P + new), name)


_MISSING = object()


def _is_module(old: str) -> bool:
    """Whether an old dotted path names a module in its new home (not a function, not nothing)."""
    for target in _targets(old) or ():
        try:
            if importlib.util.find_spec(target) is not None:
                return True
        except (ImportError, ValueError):  # the parent is a plain module, not a package
            continue
    return False


class _Moved(types.ModuleType):
    """Stand-in for an old module path: attributes come from the new module(s)."""

    def __init__(self, name: str, targets: tuple[str, ...]):
        super().__init__(name, f"moved to {', '.join(targets)}")
        self.__dict__["_targets"] = targets

    def _modules(self):
        return [importlib.import_module(t) for t in self.__dict__["_targets"]]

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        for mod in self._modules():
            value = getattr(mod, name, _MISSING)  # once: a renamed name warns on each access
            if value is not _MISSING:
                return value
        if name in MOVED_NAMES.get(self.__name__[len(_P):], {}):  # a name that left the module
            return moved_attribute(self.__name__, name)  # before submodules: hmt.model.pretrained
        if _is_module(f"{self.__name__}.{name}"):  # an old submodule: its stand-in
            return importlib.import_module(f"{self.__name__}.{name}")
        raise AttributeError(f"module {self.__name__!r} (now {self.__dict__['_targets']}) has "
                             f"no attribute {name!r}")

    def __dir__(self):
        return sorted({n for m in self._modules() for n in dir(m)})

    @property
    def __all__(self):  # noqa: D401 - the new modules' public names
        return [n for m in self._modules() for n in getattr(m, "__all__", ())]


class _Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old module paths (before the package's own finder) and makes their stand-ins."""

    def find_spec(self, fullname, path=None, target=None):
        targets = _targets(fullname)
        if targets is None:
            return None
        is_pkg = any(importlib.util.find_spec(t) is not None
                     and importlib.util.find_spec(t).submodule_search_locations is not None
                     for t in targets[:1])
        return importlib.util.spec_from_loader(fullname, self, is_package=is_pkg)

    def create_module(self, spec):
        targets = _targets(spec.name)
        warnings.warn(f"{spec.name} is now {' and '.join(targets)}; {_KEPT}", FutureWarning,
                      stacklevel=2)
        return _Moved(spec.name, targets)

    def exec_module(self, module):
        pass


_FINDER = _Finder()


def install() -> None:
    """Put the finder of the old paths first on ``sys.meta_path`` (idempotent)."""
    if _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)
