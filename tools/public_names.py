"""Count the library's public surface: the names in every public module's ``__all__``.

Usage: ``python tools/public_names.py [--json] [--fixture]``. A public module is one whose path has
no ``_``-prefixed part (``handmesh_tutorial.nn.spiral``, not ``handmesh_tutorial.collision._numba``).
A name re-exported by its package (``hmt.collision.Cylinders`` is ``hmt.collision.cylinders.Cylinders``)
counts once: names are deduplicated by (name, object). Prints the total and the count per folder
(``nn``, ``data``, ``apps``...; a name counts in the folder of the first module that lists it,
a submodule listed in ``__all__`` is not counted); ``--json`` prints ``{module: [names]}``.
Docs page "The pipeline", "Map of the library".
"""

from __future__ import annotations

import argparse
import importlib
import json
import pkgutil
import types
import warnings
from collections import Counter
from pathlib import Path

import handmesh_tutorial as hmt

PREFIX = "handmesh_tutorial."


def public_modules() -> list[str]:
    """Full names of the package's modules whose path has no ``_``-prefixed part."""
    root = str(Path(hmt.__file__).parent)
    names = ["handmesh_tutorial"] + [
        i.name for i in pkgutil.walk_packages([root], prefix=PREFIX)]
    return sorted(n for n in names if not any(p.startswith("_") for p in n.split(".")[1:]))


def folder(module: str) -> str:
    """The top-level part of the library a module belongs to (``nn``, ``data``, ``visibility``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "(top)"


def surface() -> dict[str, list[str]]:
    """``{module: sorted __all__}`` for every public module (full module names)."""
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        for name in public_modules():
            out[name] = sorted(getattr(importlib.import_module(name), "__all__", ()))
    return out


def unique_names(table: dict[str, list[str]]) -> dict[tuple[str, int], str]:
    """(name, id of its object) -> the first module that lists it (packages before their
    submodules, the top-level package last); submodules listed in an ``__all__`` are not names."""
    seen: dict[tuple[str, int], str] = {}
    for module in sorted(table, key=lambda m: (m == "handmesh_tutorial", m.count("."), m)):
        mod = importlib.import_module(module)
        for name in table[module]:
            obj = getattr(mod, name, None)
            if not isinstance(obj, types.ModuleType):  # a listed submodule is a path, not a name
                seen.setdefault((name, id(obj)), module)
    return seen


def count(table: dict[str, list[str]] | None = None) -> tuple[int, Counter]:
    """Total unique public names and their count per folder."""
    seen = unique_names(surface() if table is None else table)
    return len(seen), Counter(folder(m) for m in seen.values())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print {module: [names]} as JSON")
    args = ap.parse_args(argv)
    table = surface()
    if args.json:
        print(json.dumps({m.removeprefix(PREFIX): n for m, n in table.items() if n}, indent=1))
        return 0
    total, per_folder = count(table)
    listed = sum(len(v) for v in table.values())
    print(f"public names: {total} unique ({listed} listed in {len(table)} modules' __all__)")
    for name, n in sorted(per_folder.items(), key=lambda kv: -kv[1]):
        print(f"  {name:12s} {n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
