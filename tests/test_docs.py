"""The library's docstrings are written for mkdocstrings (what renders the API pages).

mkdocstrings reads Markdown, not reStructuredText: a Sphinx role such as ``:func:`x``` prints
literally on the site. Cross-references use autorefs' syntax, ``[`x`][handmesh_tutorial.mod.x]``,
and `mkdocs build --strict` fails if a target does not exist. Attribute documentation must be a
docstring under the assignment: griffe ignores Sphinx's ``#:`` comments, so they never reach the
site.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
MODULES = sorted((ROOT / "handmesh_tutorial").rglob("*.py"))  # subpackages included
MODULE_IDS = [str(p.relative_to(ROOT / "handmesh_tutorial")) for p in MODULES]
SPHINX_ROLE = re.compile(r":(?:py:)?(?:mod|class|func|meth|attr|data|obj|exc|const|ref|doc|term):`")


def docstrings(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every docstring: module, class, function and attribute docstrings."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if not isinstance(body, list):
            continue
        for i, stmt in enumerate(body):
            is_doc = isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Constant) and (
                isinstance(stmt.value.value, str))
            # first statement of a module/class/function, or a string right after an assignment
            if is_doc and (i == 0 or isinstance(body[i - 1], (ast.Assign, ast.AnnAssign))):
                found.append((stmt.lineno, stmt.value.value))
    return found


def test_the_scanner_sees_docstrings():
    found = docstrings(ROOT / "handmesh_tutorial" / "nn" / "model.py")
    assert any("MSMR-Net" in text for _, text in found)
    assert any("smoothing" in text for _, text in found), "attribute docstrings are scanned too"


def test_the_pattern_catches_sphinx_roles():
    for text in (":func:`build_model`", ":class:`~handmesh_tutorial.hand.HandModel`",
                 ":py:meth:`x`", ":mod:`handmesh_tutorial.nn.spiral`", ":data:`VR_BINS`"):
        assert SPHINX_ROLE.search(text), text
    assert not SPHINX_ROLE.search("[`build_model`][handmesh_tutorial.nn.model.build_model]")


@pytest.mark.parametrize("path", MODULES, ids=MODULE_IDS)
def test_no_sphinx_roles_in_docstrings(path):
    leftovers = [
        f"{path.name}:{line + text[: m.start()].count(chr(10))}: "
        f"{text[m.start(): m.start() + 60]!r}"
        for line, text in docstrings(path)
        for m in SPHINX_ROLE.finditer(text)
    ]
    assert not leftovers, (
        "Sphinx roles do not render in mkdocstrings; write "
        "[`name`][handmesh_tutorial.module.name]:\n"
        + "\n".join(leftovers)
    )


@pytest.mark.parametrize("path", MODULES, ids=MODULE_IDS)
def test_attribute_docs_are_docstrings(path):
    lines = path.read_text(encoding="utf-8").splitlines()
    comments = [f"{path.name}:{i}: {ln.strip()}" for i, ln in enumerate(lines, 1)
                if ln.lstrip().startswith("#:")]
    assert not comments, (
        "'#:' comments never reach the docs (griffe reads docstrings); put a string literal "
        "under the assignment instead:\n" + "\n".join(comments[:20])
    )


# Docstrings are contracts (what, shapes, units, raises, one line of why, one link); timings,
# benchmark ratios, dates, commit hashes and run logs belong on the docs pages (issue 35).
RUN_HISTORY = re.compile(
    r"\b\d+(?:\.\d+)? ?(?:ms|µs)\b"  # a timing
    r"|\babout \d+(?:\.\d+)? ?s\b"  # "about 2 s"
    r"|\b\d+(?:\.\d+)?x (?:faster|slower)\b"  # a benchmark ratio
    r"|\b20\d\d-\d\d-\d\d\b"  # a date
    r"|\bcommits? `{0,2}[0-9a-f]{7,40}\b"  # a commit hash
    r"|\b[Rr]un \d+\b"  # a numbered run
)


def test_the_pattern_catches_run_history():
    for text in ("takes 4.3 ms instead of 6.1", "the kernels are 10x faster", "(about 2 s)",
                 "on 2026-11-26", "commit `4bd7cd5`", "run 3 scored", "68 ms", "12.5 µs"):
        assert RUN_HISTORY.search(text), text
    for text in ("(B, V, 3) metres", "0-50 mm, 100 thresholds", "a 2D keypoint head",
                 "seconds between checkpoints", "ResNet-10", "3x3 intrinsics", "run_demo"):
        assert not RUN_HISTORY.search(text), text


CHECKED = MODULES


@pytest.mark.parametrize("path", CHECKED,
                         ids=[str(p.relative_to(ROOT / "handmesh_tutorial")) for p in CHECKED])
def test_no_run_history_in_docstrings(path):
    found = [f"{path.name}:{line + text[: m.start()].count(chr(10))}: "
             f"{text[max(0, m.start() - 30): m.end() + 30]!r}"
             for line, text in docstrings(path) for m in RUN_HISTORY.finditer(text)]
    assert not found, (
        "measurements and run history go to a docs page (docs/concepts/*.md); leave a pointer "
        "such as 'docs page \"Performance\"':\n" + "\n".join(found))


# --- the built site (tools/mkdocs_hooks.py, tools/docs_check.py; issue 44) -------------------

def _tool(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "tools" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


def test_the_link_check_finds_dead_pages_and_anchors(tmp_path):
    check_links = _tool("docs_check").check_links
    _write(tmp_path / "index.html", '<a href="a/">a</a><a href="a/#top">ok</a>'
           '<a href="https://example.org/#x">other host</a><a href="#">top</a>'
           '<a href="mailto:x@y.z">mail</a><a href="assets/style.css">css</a>')
    _write(tmp_path / "assets" / "style.css", "")
    _write(tmp_path / "a" / "index.html",
           '<h2 id="top">Top</h2><a name="old"></a><a href="#top">ok</a><a href="#old">ok</a>'
           '<a href="#gone">dead here</a><a href="../b/#x">no page</a>'
           '<a href="../index.html#nowhere">dead there</a><a href="../a/index.html#top">ok</a>')
    dead = check_links(tmp_path)
    assert set(dead) == {"a/index.html"}
    problems = " | ".join(dead["a/index.html"])
    assert len(dead["a/index.html"]) == 3, problems
    assert "#gone -> no id 'gone' in this page" in problems
    assert "../b/#x -> no such file: b/index.html" in problems
    assert "../index.html#nowhere -> no id 'nowhere' in index.html" in problems


def test_notebook_contents_links_point_at_their_headings():
    """mkdocs-jupyter's contents drop inline code from an id (``what-...``) while the rendered
    heading keeps it (``predjson-what-...``): notebook 11's contents link was dead."""
    from types import SimpleNamespace as Item

    fix_toc = _tool("mkdocs_hooks")._fix_toc
    content = ('<h2 id="intro">Intro</h2><h3 id="predjson-what-freihands-evaluation-expects">'
               '<code>pred.json</code>: what FreiHAND\'s evaluation expects'
               '<a class="anchor-link" href="#predjson-what-freihands-evaluation-expects">¶</a>'
               '</h3>'
               '<h3 id="what-freihands-evaluation-expects-1">again</h3>')
    inner = Item(id="what-freihands-evaluation-expects",
                 title=": what FreiHAND's evaluation expects", children=[])
    toc = [Item(id="intro", title="Intro", children=[inner])]
    assert fix_toc(toc, content) == 1
    assert inner.id == "predjson-what-freihands-evaluation-expects"
    assert inner.title == "pred.json: what FreiHAND's evaluation expects"
    assert toc[0].id == "intro"
    assert fix_toc(toc, content) == 0                    # already right: nothing changes


def test_code_cells_stay_out_of_the_search_index():
    exclude = _tool("mkdocs_hooks")._exclude_code_from_search
    cell = ('<div class="jp-InputPrompt jp-InputArea-prompt">In [1]:</div>'
            '<div class="jp-CodeMirrorEditor jp-Editor jp-InputArea-editor" data-type="inline">'
            '<span class="notice" hidden="">Copied!</span>x = 1</div>'
            '<div class="jp-RenderedHTMLCommon jp-RenderedMarkdown">prose</div>')
    out = exclude(cell)
    assert out.count("data-search-exclude") == 2
    assert '<div class="jp-RenderedHTMLCommon jp-RenderedMarkdown">prose' in out


def test_notebook_pages_share_their_css_and_keep_figures_as_files(tmp_path):
    import base64
    from types import SimpleNamespace

    lighten = _tool("mkdocs_hooks")._lighten
    png = b"\x89PNG\r\n\x1a\n not decoded, only moved"
    css = ".jupyter-wrapper{color:red}" + " " * 3000
    dest = str(tmp_path / "notebooks/x/index.html")
    page = SimpleNamespace(url="notebooks/x/", file=SimpleNamespace(abs_dest_path=dest))
    html = (f'<style type="text/css">{css}</style><style>small{{}}</style>'
            f'<img alt="fig" src="data:image/png;base64,{base64.b64encode(png).decode()}">')
    out = lighten(html, page, tmp_path)
    link = re.search(
        r'<link rel="stylesheet" href="(\.\./\.\./assets/notebook-css/[0-9a-f]+\.css)">', out)
    assert link and (tmp_path / "notebooks/x" / link.group(1)).resolve().read_text() == css
    assert "<style>small{}</style>" in out                  # small blocks stay inline
    img = re.search(r'<img alt="fig" loading="lazy" src="(figures/[0-9a-f]+\.png)"', out)
    assert img and (tmp_path / "notebooks/x" / img.group(1)).read_bytes() == png
    assert "base64" not in out


def test_the_api_landing_page_links_every_module_page():
    index = (ROOT / "docs" / "api" / "index.md").read_text(encoding="utf-8")
    pages = sorted(p.name for p in (ROOT / "docs" / "api").glob("*.md") if p.name != "index.md")
    missing = [p for p in pages if f"]({p})" not in index]
    assert not missing, f"docs/api/index.md does not link {missing}"


def test_learning_path_rows_carry_their_notebook_numbers():
    row_link = _tool("notebook_runtimes").path_row_link
    assert row_link({"stem": "08_training", "title": "Training"}) == \
        "**[08 · Training](08_training.ipynb)**"
    page = (ROOT / "notebooks" / "learning_path.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| \*\*\[(.*?)\]\((\d\d)_\w+\.ipynb\)", page, re.M)
    assert len(rows) >= 12
    assert all(title.startswith(f"{num} · ") for title, num in rows), rows


def test_copy_buttons_leave_doctest_prompts_out():
    """Material marks a block data-md-copying while it reads its innerText: hidden prompts
    (``>>> ``, ``... ``: Pygments' .gp) and outputs (.go) stay out of the clipboard."""
    css = (ROOT / "docs" / "stylesheets" / "site.css").read_text(encoding="utf-8")
    rule = re.search(r"((?:\[data-md-copying\] \.g[po],?\s*)+)\{\s*display:\s*none", css)
    assert rule and ".gp" in rule.group(1) and ".go" in rule.group(1)
    config = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    assert "stylesheets/site.css" in config and "content.code.copy" in config


# --- the shipped network's scores in the docs (tools/pretrained_scores.py) ------------------

def _scores_result(rng) -> dict:
    """A result of tools/pretrained_scores.py's `score` with made-up per-scene errors."""
    from handmesh_tutorial.metrics.intervals import paired_difference

    def row(errors):
        return {"pa_mpjpe": float(np.mean(errors)), "pa_mpvpe": 0.0, "mpjpe": 0.0,
                "roughness_deg": 2.0, "flipped": 0.001,
                "per_scene": {"pa_mpjpe": list(errors)}}

    kinds, pooled = {}, {"file": [], "rest hand": [], "mean hand": []}
    for shift, kind in zip((0.0, 1.0, 2.0), ("hand-hand", "hand-object", "hand-chain"),
                           strict=True):
        g = {"file": row(5 + shift + rng.normal(0, 1, 10)),
             "rest hand": row(11 + shift + rng.normal(0, 1, 10)),
             "mean hand": row(8 + shift + rng.normal(0, 1, 10))}
        for k in pooled:
            pooled[k] += g[k]["per_scene"]["pa_mpjpe"]
        g["intervals"] = {f"file - {k}": paired_difference(g["file"]["per_scene"]["pa_mpjpe"],
                                                           g[k]["per_scene"]["pa_mpjpe"])
                          for k in ("rest hand", "mean hand")}
        kinds[kind] = g
    everything = {k: row(v) for k, v in pooled.items()}
    everything["intervals"] = {f"file - {k}": paired_difference(pooled["file"], pooled[k])
                               for k in ("rest hand", "mean hand")}
    return {"seed": 12345, "per_kind": 10, "kinds": kinds, "all": everything}


def test_the_scores_tool_writes_its_tables_between_the_markers_only(tmp_path):
    tool = _tool("pretrained_scores")
    result = _scores_result(np.random.default_rng(0))
    table = tool.render_block(result, "table")
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ") for line in table.splitlines()[2:]}
    assert list(rows) == ["hand-hand", "hand-object", "hand-chain", "all"]
    a = result["all"]
    assert rows["all"][1] == "30" and rows["all"][2] == f"{a['file']['pa_mpjpe']:.2f}"
    assert rows["all"][5] == f"{a['file']['pa_mpjpe'] / a['rest hand']['pa_mpjpe']:.2f}"
    summary = tool.render_block(result, "summary")
    assert "30 fresh scenes (seed 12345" in summary
    with pytest.raises(ValueError, match="unknown block 'tables'"):
        tool.render_block(result, "tables")
    for rel in tool.DOCS:
        _write(tmp_path / rel, "before\n<!-- pretrained-scores table -->\nold\n"
                               "<!-- /pretrained-scores -->\nbetween\n"
                               "<!-- pretrained-scores summary -->\nold\n"
                               "<!-- /pretrained-scores -->\nafter\n")
    assert tool.write_docs(result, tmp_path) == list(tool.DOCS)
    text = (tmp_path / "README.md").read_text()
    assert text == ("before\n<!-- pretrained-scores table -->\n" + table
                    + "<!-- /pretrained-scores -->\nbetween\n<!-- pretrained-scores summary -->\n"
                    + summary + "<!-- /pretrained-scores -->\nafter\n")
    assert tool.write_docs(result, tmp_path) == []  # the same result: nothing to change


def test_the_score_tables_fill_only_their_markers_and_a_rerun_changes_nothing(tmp_path):
    tool = _tool("pretrained_scores")

    def row(pa, mpjpe):
        return {"pa_mpjpe": pa, "mpjpe": mpjpe, "roughness_deg": 2.04, "flipped": 0.0013,
                "per_scene": {"pa_mpjpe": [pa, pa]}}

    def group(pa):
        return {"file": row(pa, 13.4), "rest hand": row(10.0, 77.4), "mean hand": row(8.0, 77.9),
                "intervals": {"file - mean hand": {"difference": -1.5, "low": -2.0,
                                                   "high": -1.0}}}

    result = {"per_kind": 2, "seed": 123, "kinds": {k: group(5.0) for k in tool.KINDS},
              "all": group(5.5)}
    table = tool.render_block(result, "table")
    assert "| all | 2 | 5.50 | 10.00 | 8.00 | 0.55 | -1.50 (-2.00 to -1.00) | 13 / 77 | 2.0 | " \
           "0.13 % |" in table
    summary = tool.render_block(result, "summary")
    assert "0.55x the rest hand (10.00 mm) and 1.50 mm (1.00 to 2.00) below the mean" in summary
    result["demo"] = {"file": row(5.0, 13.0), "demo": row(4.9, 12.0),
                      "file - demo": {"difference": 0.1, "low": -0.2, "high": 0.4}}
    assert "demo's 2 held-out scenes 5.00 mm against the demo network's 4.90 mm, paired " \
           "difference +0.10 (-0.20 to +0.40), not told apart." in tool.render_block(result,
                                                                                 "summary")
    page = ("intro\n<!-- pretrained-scores table -->\nstale table\n<!-- /pretrained-scores -->\n"
            "middle\n<!-- pretrained-scores summary -->\nstale\n<!-- /pretrained-scores -->\nend\n")
    for rel in tool.DOCS:
        _write(tmp_path / rel, page if rel == "README.md" else "no markers here\n")
    assert tool.write_docs(result, tmp_path) == ["README.md"]
    text = (tmp_path / "README.md").read_text()
    assert "stale" not in text and text.startswith("intro\n") and "\nmiddle\n" in text
    assert text.endswith("<!-- /pretrained-scores -->\nend\n") and table in text
    assert tool.write_docs(result, tmp_path) == []
    _write(tmp_path / "README.md",
           "<!-- pretrained-scores graph -->\nx\n<!-- /pretrained-scores -->\n")
    with pytest.raises(ValueError, match="'graph'"):
        tool.write_docs(result, tmp_path)


# --- tables that restate the code (tools/code_tables.py) --------------------------------------

def test_every_code_table_in_the_docs_is_what_its_code_says_now():
    tool = _tool("code_tables")
    assert tool.stale() == [], "run python tools/code_tables.py"


def test_a_code_table_is_rewritten_only_between_its_markers(tmp_path):
    tool = _tool("code_tables")
    page = tmp_path / "p.md"
    page.write_text("intro\n<!-- code-table lcs-limits -->\n| old |\n<!-- /code-table -->\nend\n")
    assert tool.stale({"lcs-limits": page}) == ["lcs-limits"]
    text = tool.updated(page.read_text(), "lcs-limits")
    assert text.startswith("intro\n<!-- code-table lcs-limits -->\n| joint |")
    assert text.endswith("| paper (every joint) | ±60 | ±60 | ±60 |\n<!-- /code-table -->\nend\n")
    assert "| finger PIP | ±10 | 0 .. 110 | ±10 |" in text
    page.write_text(text)
    assert tool.stale({"lcs-limits": page}) == []
    with pytest.raises(ValueError, match="code-table lcs-limits"):
        tool.updated("no markers", "lcs-limits")
