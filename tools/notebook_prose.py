"""Every number a notebook's text states is one its outputs show, or is marked as quoted.

Usage (from the repository root)::

    python tools/notebook_prose.py [notebooks/NN_x.ipynb ...]   # exit 1 and a list if any fails

A *stated number* is a number followed by a unit in a Markdown cell (mm, cm, m, s, ms, min,
h, %, px, degrees, MB, GB, KB, or a ratio ``0.72x``). It *holds* when

- an output (stream text, ``text/plain``, ``text/html`` and ``text/markdown`` results) or the
  source of a code cell the reader has seen by then (every cell before it, and the next code
  cell) shows a number that rounds to it at the precision it is written with (``5.7 mm`` holds for a printed ``5.66``; ``3,000`` for
  ``3000``); a range ``4.6-5.1 mm`` needs both ends;
- or it is listed in a *quote mark* of the same cell, an HTML comment that names its source and
  does not render::

      <!-- quoted from the paper's Table 3: 7.5 mm, 7.4 mm, 7.2 mm -->

  A quote mark must name a source after ``quoted from`` (the paper's published text, a shipped
  results file, another page); the numbers it lists are then taken as stated there.

Numbers in the "Before you start" cell (written by ``tools/notebook_runtimes.py`` from the run's
own timestamps) and in headings are not checked. Numbers without a unit (counts, seeds, indices)
are not checked either: they are settings, not measurements.
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]
HEADER_MARK = "<!-- before-you-start"

UNITS = r"(?:mm|cm|µm|m|ms|s|sec|seconds|min|minutes|h|hours|%|px|pixels|degrees|°|MB|GB|KB|x)"
NUMBER = r"\d{1,3}(?:,\d{3})+(?:\.\d+)?|\d+(?:\.\d+)?"
# a number (or a range "a-b" / "a to b") right before a unit, not inside a word or a version
STATED = re.compile(rf"(?<![\w.])(?P<a>{NUMBER})(?:\s*(?:-|–|to)\s*(?P<b>{NUMBER}))?"
                    rf"\s?(?P<unit>{UNITS})(?![\w])")
QUOTE = re.compile(r"<!--\s*quoted from (?P<source>[^:]+?):(?P<numbers>.*?)-->", re.S)
SHOWN = re.compile(rf"(?<![\w.])-?(?:{NUMBER})")


@dataclass
class Unsupported:
    notebook: str
    cell: int
    text: str

    def __str__(self) -> str:
        return f"{self.notebook} cell {self.cell}: '{self.text}' is not in its outputs"


def _value(token: str) -> float:
    return float(token.replace(",", ""))


def _decimals(token: str) -> int:
    return len(token.split(".")[1]) if "." in token else 0


def shown_numbers(cells) -> list[str]:
    """Every number token that ``cells`` show: outputs of code cells and their sources."""
    texts = []
    for cell in cells:
        if cell.cell_type != "code":
            continue
        texts.append(cell.source)
        for out in cell.get("outputs", []):
            if out.get("output_type") == "stream":
                texts.append(out.get("text", ""))
            for mime in ("text/plain", "text/html", "text/markdown"):
                data = out.get("data", {}).get(mime)
                if data:
                    texts.append(data if isinstance(data, str) else "".join(data))
            if out.get("output_type") == "error":
                texts.append(" ".join(out.get("traceback", [])))
    return SHOWN.findall("\n".join(texts))


def holds(token: str, shown: list[float], exact_ints: set[float]) -> bool:
    """Whether a printed number rounds to ``token`` at the precision it is written with."""
    value, places = _value(token), _decimals(token)
    if places == 0 and value in exact_ints:
        return True
    half = 0.5 * 10.0 ** -places
    return any(abs(abs(s) - value) <= half + 1e-9 for s in shown)


def check(path: Path) -> list[Unsupported]:
    nb = nbformat.read(path, as_version=4)
    problems = []
    for i, cell in enumerate(nb.cells):
        if cell.cell_type != "markdown" or HEADER_MARK in cell.source:
            continue
        # what the reader has seen by then: every cell up to the next code cell's outputs
        nxt = next((j for j in range(i + 1, len(nb.cells)) if nb.cells[j].cell_type == "code"),
                   len(nb.cells) - 1)
        shown = [_value(t.lstrip("-")) for t in shown_numbers(nb.cells[:nxt + 1])]
        exact_ints = {v for v in shown if float(v).is_integer()}
        quoted = set()
        for q in QUOTE.finditer(cell.source):
            quoted |= {m.group(0).strip() for m in STATED.finditer(q.group("numbers"))}
        body = "\n".join(line for line in QUOTE.sub("", cell.source).splitlines()
                         if not line.lstrip().startswith("#"))
        body = re.sub(r"`[^`]*`", "", body)  # code spans are names and settings, not claims
        for m in STATED.finditer(body):
            if m.group(0).strip() in quoted:
                continue
            ends = [m.group("a")] + ([m.group("b")] if m.group("b") else [])
            if not all(holds(t, shown, exact_ints) for t in ends):
                problems.append(Unsupported(path.name, i, m.group(0).strip()))
    return problems


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("notebooks", nargs="*", type=Path)
    args = ap.parse_args(argv)
    paths = args.notebooks or sorted((ROOT / "notebooks").glob("*.ipynb"))
    problems = [p for path in paths for p in check(path)]
    for p in problems:
        print(p)
    print(f"{len(problems)} stated numbers not shown by their notebook's outputs "
          f"({len(paths)} notebooks)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
