"""The library's layout: public surface, module sizes, module docstrings, no import cycles.

`fixtures/public_names.json` is the record of the public surface: every public module's
``__all__`` (a public module has no ``_``-prefixed part in its path). The surface changes only
on purpose: a name that leaves an ``__all__`` or joins one fails a test here until the fixture is
edited in the same commit (a name that is renamed keeps working for one version,
``handmesh_tutorial/_aliases.py``, and is noted in ``CHANGELOG.md``). ``python
tools/public_names.py`` counts the surface, names re-exported by a package counted once.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import json
import pkgutil
from pathlib import Path

import pytest

import handmesh_tutorial as hmt

PACKAGE_DIR = Path(hmt.__file__).parent
PUBLIC_NAMES = json.loads((Path(__file__).parent / "fixtures" / "public_names.json").read_text())
MAX_LINES = 500  # DESIGN: "split past ~500 lines"
SIZE_NOTE = "Why one file"  # a longer module says why in its docstring


def _all_modules() -> list[str]:
    names = []
    for info in pkgutil.walk_packages([str(PACKAGE_DIR)], prefix="handmesh_tutorial."):
        names.append(info.name)
    return sorted(names)


def _source(module: str) -> Path:
    rel = Path(*module.split(".")[1:])
    pkg = PACKAGE_DIR / rel / "__init__.py"
    return pkg if pkg.exists() else PACKAGE_DIR / rel.with_suffix(".py")


MODULES = _all_modules()
PUBLIC_MODULES = [m for m in MODULES if not any(p.startswith("_") for p in m.split(".")[1:])]


@pytest.mark.parametrize("module", sorted(PUBLIC_NAMES))
def test_every_public_name_of_the_fixture_is_still_exported(module):
    mod = importlib.import_module(f"handmesh_tutorial.{module}")
    exported = set(getattr(mod, "__all__", ()))
    missing = [n for n in PUBLIC_NAMES[module] if n not in exported or not hasattr(mod, n)]
    assert not missing, (f"handmesh_tutorial.{module} no longer exports {missing}: if on "
                         "purpose, drop them from tests/fixtures/public_names.json")


@pytest.mark.parametrize("module", PUBLIC_MODULES)
def test_the_public_surface_grows_only_on_purpose(module):
    mod = importlib.import_module(module)
    short = module.removeprefix("handmesh_tutorial.")
    new = sorted(set(getattr(mod, "__all__", ())) - set(PUBLIC_NAMES.get(short, ())))
    assert not new, (f"{module}.__all__ lists {new}, which tests/fixtures/public_names.json does "
                     f"not record under {short!r}: add them there if they are meant to be public "
                     "(what a user calls, passes or reads), else keep them out of __all__")


def test_the_package_lists_each_name_once():
    assert len(set(hmt.__all__)) == len(hmt.__all__), sorted(
        n for n in hmt.__all__ if hmt.__all__.count(n) > 1)
    assert all(hasattr(hmt, n) for n in hmt.__all__)


def test_the_surface_count_names_a_re_exported_name_once():
    spec = importlib.util.spec_from_file_location(
        "public_names", PACKAGE_DIR.parent / "tools" / "public_names.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    table = {"handmesh_tutorial.collision": ["Cylinders", "coverage", "hand_proxies"],
             "handmesh_tutorial.collision.cylinders": ["Cylinders"],
             "handmesh_tutorial.collision.hand_proxies": ["coverage"],
             "handmesh_tutorial.data": ["KINDS"], "handmesh_tutorial.scenes": ["KINDS"]}
    total, per_folder = tool.count(table)
    # Cylinders and coverage once each; hand_proxies is a submodule, not a name; scenes.KINDS is
    # data.schema.KINDS (one object, one name); collision's names count in collision/
    assert hmt.scenes.KINDS is hmt.data.KINDS
    assert total == 3 and per_folder == {"collision": 2, "data": 1}


def test_the_0_1_stand_ins_promised_for_removal_are_gone():
    """Issue 54: 0.1's paths and plumbing names that were to go in 0.4 are gone; the four module
    paths of the fixed entry points stay."""
    import sys

    from handmesh_tutorial import _aliases

    assert set(_aliases.MOVED) == {"dataset", "model", "sampling", "spiral"}
    for old in ("interact", "augment", "train.pose_pretraining", "surface"):
        sys.modules.pop(f"handmesh_tutorial.{old}", None)
        with pytest.raises(ModuleNotFoundError):
            importlib.import_module(f"handmesh_tutorial.{old}")
    for module, name in (("data", "TMP_PREFIX"), ("data.schema", "LOCK_FILE"),
                         ("render", "ensure_egl"), ("train", "remove_stale_temp_files"),
                         ("pretrained", "PretrainedRecipe")):
        with pytest.raises(AttributeError, match=f"no attribute '{name}'"):
            getattr(importlib.import_module(f"handmesh_tutorial.{module}"), name)
    assert not hasattr(hmt, "interact")


@pytest.mark.parametrize("module", PUBLIC_MODULES)
def test_every_public_module_declares_all_and_every_listed_name_exists(module):
    mod = importlib.import_module(module)
    assert hasattr(mod, "__all__"), f"{module} has no __all__"
    assert len(set(mod.__all__)) == len(mod.__all__), f"{module}.__all__ repeats a name"
    absent = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not absent, f"{module}.__all__ lists names it does not define: {absent}"


@pytest.mark.parametrize("module", MODULES)
def test_modules_stay_small_or_say_why(module):
    path = _source(module)
    text = path.read_text()
    lines = text.count("\n")
    doc = ast.get_docstring(ast.parse(text)) or ""
    assert lines <= MAX_LINES or SIZE_NOTE in doc, (
        f"{path.relative_to(PACKAGE_DIR.parent)} has {lines} lines (> {MAX_LINES}) and its "
        f"docstring has no '{SIZE_NOTE}' note")


@pytest.mark.parametrize("module", PUBLIC_MODULES)
def test_every_public_module_has_a_docstring_that_points_to_a_notebook_or_page(module):
    doc = ast.get_docstring(ast.parse(_source(module).read_text())) or ""
    assert doc.strip(), f"{module} has no docstring"
    assert "notebook" in doc.lower() or "docs page" in doc.lower() or "see docs" in doc.lower(), (
        f"{module}'s docstring names no notebook or docs page that teaches it")


def _imports(module: str, *, at_import_time: bool = False) -> set[str]:
    """Library modules that ``module`` imports: every import statement, those inside functions
    too (``at_import_time=False``), or only the module-level ones (not under TYPE_CHECKING)."""
    path = _source(module)
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    base = module.split(".") if is_pkg else module.split(".")[:-1]
    if at_import_time:
        stmts = []
        for node in tree.body:
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                continue  # annotations only: not imported at run time
            if isinstance(node, ast.If | ast.Try):
                stmts += [n for n in ast.walk(node) if isinstance(n, ast.Import | ast.ImportFrom)]
            else:
                stmts.append(node)
    else:
        stmts = list(ast.walk(tree))
    found = set()
    for st in stmts:
        if isinstance(st, ast.Import):
            found |= {a.name for a in st.names if a.name.startswith("handmesh_tutorial")}
        elif isinstance(st, ast.ImportFrom):
            if st.level:
                parent = base[: len(base) - (st.level - 1)]
                target = ".".join(parent + ([st.module] if st.module else []))
            elif st.module and st.module.startswith("handmesh_tutorial"):
                target = st.module
            else:
                continue
            found.add(target)
            for a in st.names:  # `from . import spiral` imports a submodule
                if f"{target}.{a.name}" in MODULES:
                    found.add(f"{target}.{a.name}")
    return {m for m in found if m in MODULES and m != module}


def _folder(module: str) -> str:
    """The top-level part of the library a module belongs to (``nn``, ``data``, ``visibility``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan)."""
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return cycles


def test_the_cycle_finder_finds_cycles_and_only_cycles():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_the_import_graph_has_no_cycles_at_import_time():
    graph = {m: _imports(m, at_import_time=True) for m in MODULES}
    # a submodule's import of its own package's __init__ is how Python loads it, not a cycle
    for m, deps in graph.items():
        graph[m] = {d for d in deps if not m.startswith(d + ".")}
    assert graph.get("handmesh_tutorial.nn.model"), "graph empty"
    assert not _cycles(graph), f"import cycles: {_cycles(graph)}"


def test_the_folders_form_layers_counting_imports_inside_functions():
    # every import, function-level ones included: the folders (nn, data, train...) import each
    # other in one direction only, so each can be read, tested and lifted without those above it
    edges: dict[str, set[str]] = {}
    why: dict[tuple[str, str], str] = {}
    for m in MODULES:
        for d in _imports(m):
            a, b = _folder(m), _folder(d)
            if a != b and a != "handmesh_tutorial":
                edges.setdefault(a, set()).add(b)
                why.setdefault((a, b), f"{m} -> {d}")
    cycles = _cycles(edges)
    detail = [why[a, b] for c in cycles for a in c for b in c if (a, b) in why]
    assert not cycles, f"folders that import each other: {cycles}; through {detail}"


def test_the_library_never_imports_the_apps():
    library = [m for m in MODULES if _folder(m) != "apps" and m != "handmesh_tutorial"]
    up = {m: sorted(d for d in _imports(m) if _folder(d) == "apps") for m in library}
    up = {m: d for m, d in up.items() if d}
    assert not up, f"library modules that import the apps layer: {up}"


def test_the_fixed_entry_points_old_module_paths_still_work(monkeypatch):
    import sys
    import warnings

    from handmesh_tutorial import _aliases

    for old, new in _aliases.MOVED.items():
        full = f"handmesh_tutorial.{old}"  # a stand-in imported by an earlier test warned then
        for name in [m for m in sys.modules if m == full or m.startswith(full + ".")]:
            monkeypatch.delitem(sys.modules, name)
        with pytest.warns(FutureWarning, match="the old path stays"):
            mod = importlib.import_module(f"handmesh_tutorial.{old}")
        target = importlib.import_module(f"handmesh_tutorial.{new[0]}")
        name = next(iter(getattr(target, "__all__", ())), None)
        if name is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # the stand-in warns once, on import
                assert getattr(mod, name) is getattr(target, name), (old, name)
    assert hmt.spiral.SpiralConv is hmt.nn.spiral.SpiralConv


def test_the_library_map_names_every_module_file():
    page = (PACKAGE_DIR.parent / "docs" / "concepts" / "pipeline.md").read_text()
    files = [p.relative_to(PACKAGE_DIR).as_posix() for p in sorted(PACKAGE_DIR.rglob("*.py"))
             if "__pycache__" not in p.parts and p.name != "__init__.py"
             and not (p.name.startswith("_") and p.name != "_numba.py" and p.parent != PACKAGE_DIR)]
    missing = [f for f in files if f"`{f}`" not in page]
    assert not missing, f"docs/concepts/pipeline.md 'Map of the library' does not name {missing}"


def test_the_0_1_name_hmt_model_pretrained_still_works(monkeypatch):
    """Issue 43 item 18: ``hmt.model.pretrained`` of 0.1 (now ``hmt.pretrained.pretrained``)."""
    import sys

    for name in [m for m in sys.modules if m == "handmesh_tutorial.model"]:
        monkeypatch.delitem(sys.modules, name)
    with pytest.warns(FutureWarning, match=r"handmesh_tutorial\.pretrained\.pretrained.*stays"):
        old = hmt.model.pretrained
    assert old is hmt.pretrained.pretrained
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        hmt.model.nope  # noqa: B018 - an unknown name stays an AttributeError, not an import error
