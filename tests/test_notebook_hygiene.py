"""Every committed notebook follows the project's notebook rules (see README, "Notebooks")."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
MAX_BYTES = 2_500_000  # "under ~2 MB": a little slack over 2 MiB before a notebook fails


def _cells(path: Path) -> list[dict]:
    return json.loads(path.read_text(encoding="utf-8"))["cells"]


def _source(cell: dict) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def test_notebook_names_are_numbered():
    for nb in NOTEBOOKS:
        assert re.fullmatch(r"\d\d_[a-z0-9_]+\.ipynb", nb.name), f"{nb.name}: want NN_name.ipynb"


def test_every_notebook_is_in_the_docs_nav():
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    missing = [nb.name for nb in NOTEBOOKS if f"notebooks/{nb.name}" not in nav]
    assert not missing, f"notebooks missing from mkdocs.yml nav: {missing}"


def test_notebook_nav_titles_are_named_one_way():
    """Each notebook's nav entry is titled "NN · Title", NN its file's number (one naming)."""
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    # mkdocs-jupyter would put each notebook's own H1 in the navigation instead
    assert re.search(r"^\s*ignore_h1_titles: true$", nav, re.M), "mkdocs.yml: ignore_h1_titles"
    for nb in NOTEBOOKS:
        entry = re.search(rf'^\s*- "(.+)": notebooks/{re.escape(nb.name)}$', nav, re.M)
        assert entry, f"mkdocs.yml: notebooks/{nb.name} wants a title, '- \"NN · Title\": ...'"
        assert re.fullmatch(rf"{nb.name[:2]} · [A-Z].+", entry.group(1)), (
            f"mkdocs.yml: {nb.name} is titled {entry.group(1)!r}; want '{nb.name[:2]} · Title'")


def test_notebook_titles_carry_no_number():
    """The number lives in the file name and the nav, not in the notebook's own title."""
    for nb in NOTEBOOKS:
        title = _source(_cells(nb)[0]).lstrip().splitlines()[0]
        assert not re.match(r"#\s*\d", title), f"{nb.name}: title {title!r} starts with a number"


def test_docs_reach_the_notebooks():
    link = ROOT / "docs" / "notebooks"
    assert link.resolve() == (ROOT / "notebooks").resolve(), "docs/notebooks must link notebooks/"


@pytest.mark.parametrize("nb", NOTEBOOKS, ids=[nb.name for nb in NOTEBOOKS])
class TestNotebook:
    def test_first_cell_is_a_single_title(self, nb):
        first = _cells(nb)[0]
        assert first["cell_type"] == "markdown", f"{nb.name}: first cell must be markdown"
        titles = [ln for ln in _source(first).splitlines() if re.match(r"#\s", ln)]
        assert len(titles) == 1 and _source(first).lstrip().startswith("# "), (
            f"{nb.name}: first cell must start with one '# Title' line")

    def test_uses_the_library_and_the_budget(self, nb):
        code = "\n".join(_source(c) for c in _cells(nb) if c["cell_type"] == "code")
        assert "import handmesh_tutorial as hmt" in code, f"{nb.name}: import the library as hmt"
        assert "sys.path" not in code, f"{nb.name}: no sys.path hacks"
        aliases = re.findall(
            r"^\s*(?:from handmesh_tutorial\S* import .*|import handmesh_tutorial\.\S*.*)$",
            code, re.M)
        assert not aliases, f"{nb.name}: use hmt.<module> instead of {aliases}"
        assert "hmt.budget()" in code, f"{nb.name}: sizes must come from hmt.budget()"
        assert "HANDMESH_BUDGET" not in code, f"{nb.name}: only hmt.budget() reads HANDMESH_BUDGET"

    def test_needs_nothing_outside_the_package(self, nb):
        """A pip-installed copy has no tools/ or benchmarks/: a notebook imports what it runs."""
        code = "\n".join(_source(c) for c in _cells(nb) if c["cell_type"] == "code")
        loads = re.findall(r"spec_from_file_location|Path\.cwd\(\)\.parent|runpy\."
                           r"|[\"'/](?:tools|benchmarks)(?:/|[\"'] */)", code)
        assert not loads, (
            f"{nb.name}: loads code from outside the package ({loads}); a pip-installed copy "
            "has no tools/ or benchmarks/: move what it needs into handmesh_tutorial")

    def test_ends_with_summary_and_exercises(self, nb):
        md = [_source(c) for c in _cells(nb) if c["cell_type"] == "markdown"]
        headings = [ln.strip() for m in md for ln in m.splitlines() if ln.startswith("## ")]
        assert any(h.lower().startswith("## summary") for h in headings), f"{nb.name}: no Summary"
        assert any(h.lower().startswith("## exercises") for h in headings), (
            f"{nb.name}: no Exercises")

    def test_executed_without_errors(self, nb):
        code = [c for c in _cells(nb) if c["cell_type"] == "code"]
        assert any(c.get("outputs") for c in code), f"{nb.name}: commit it executed (no outputs)"
        for i, c in enumerate(code):
            if c.get("outputs"):
                assert c.get("execution_count") is not None, (
                    f"{nb.name}: code cell {i} has outputs but no execution count")
            for out in c.get("outputs", []):
                assert out.get("output_type") != "error", f"{nb.name}: code cell {i} holds an error"

    def test_opens_with_before_you_start(self, nb):
        cells = _cells(nb)
        header = _source(cells[1]) if len(cells) > 1 else ""
        first = cells[1]["cell_type"] == "markdown" and header.startswith("<!-- before-you-start")
        assert first, (
            f"{nb.name}: the second cell must be the 'Before you start' cell "
            "(python tools/notebook_runtimes.py writes it)")
        for item in ("You will learn", "Prerequisites", "Runtime on a laptop CPU",
                     "Needs a trained model"):
            assert item in header, f"{nb.name}: 'Before you start' lacks {item!r}"

    def test_no_mkdocs_admonitions(self, nb):
        md = [_source(c) for c in _cells(nb) if c["cell_type"] == "markdown"]
        bad = [ln for m in md for ln in m.splitlines() if ln.lstrip().startswith("!!!")]
        assert not bad, (f"{nb.name}: '!!!' admonitions print literally in Jupyter and on the "
                         f"site; use a '> **Note.** ...' quote: {bad}")

    def test_size_under_cap(self, nb):
        size = nb.stat().st_size
        assert size < MAX_BYTES, f"{nb.name}: {size / 1e6:.2f} MB, over the ~2 MB cap"
