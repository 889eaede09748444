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
