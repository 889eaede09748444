"""Docs tables that restate the code, written from the code between markers.

Usage (from the repository root)::

    python tools/code_tables.py           # rewrite every table whose code changed
    python tools/code_tables.py --check   # exit 1 and name the pages whose table is stale

A page holds a table between ``<!-- code-table NAME -->`` and ``<!-- /code-table -->``; the
text between is replaced by ``TABLES[NAME]()``. ``tests/test_docs.py`` fails when a committed
table differs from what its code says now, so a changed constant cannot leave its page behind.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = {"lcs-limits": ROOT / "docs" / "api" / "lcs.md"}


def _range(lo: float, hi: float) -> str:
    if lo == hi == 0:
        return "0"
    if lo == -hi:
        return f"±{hi:g}"
    return f"{lo:g} .. {hi:g}"


def lcs_limits() -> str:
    """The anatomical joint limits (`hmt.lcs.ANATOMICAL_LIMITS_DEG`) and the paper's."""
    from handmesh_tutorial.lcs import ANATOMICAL_LIMITS_DEG, PAPER_LIMIT_DEG

    names = {"mcp": "finger MCP", "pip": "finger PIP", "dip": "finger DIP",
             "thumb_cmc": "thumb CMC", "thumb_mcp": "thumb MCP", "thumb_ip": "thumb IP"}
    rows = ["| joint | x: abduction (°) | y: flexion (°, + towards palm) | z: twist (°) |",
            "|---|---|---|---|"]
    for key, axes in ANATOMICAL_LIMITS_DEG.items():
        rows.append(f"| {names.get(key, key)} | " + " | ".join(_range(*a) for a in axes) + " |")
    paper = _range(-PAPER_LIMIT_DEG, PAPER_LIMIT_DEG)
    rows.append(f"| paper (every joint) | {paper} | {paper} | {paper} |")
    return "\n".join(rows) + "\n"


TABLES = {"lcs-limits": lcs_limits}


def block(name: str) -> re.Pattern:
    return re.compile(rf"(<!-- code-table {re.escape(name)} -->\n)(.*?)(<!-- /code-table -->)",
                      re.S)


def updated(text: str, name: str) -> str:
    """``text`` with the table ``name`` rewritten between its markers (ValueError: no markers)."""
    pattern = block(name)
    if not pattern.search(text):
        raise ValueError(f"no '<!-- code-table {name} -->' ... '<!-- /code-table -->' markers")
    return pattern.sub(lambda m: m.group(1) + TABLES[name]() + m.group(3), text, count=1)


def stale(pages: dict = PAGES) -> list[str]:
    """Names of the tables whose page differs from what the code says now."""
    return [name for name, page in pages.items()
            if updated(page.read_text(encoding="utf-8"), name) != page.read_text(encoding="utf-8")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="only say which tables are stale")
    args = ap.parse_args(argv)
    old = stale()
    if args.check:
        for name in old:
            print(f"{PAGES[name].relative_to(ROOT)}: table {name} is stale "
                  "(python tools/code_tables.py rewrites it)")
        return 1 if old else 0
    for name in old:
        page = PAGES[name]
        page.write_text(updated(page.read_text(encoding="utf-8"), name), encoding="utf-8")
        print(f"rewrote {name} in {page.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
