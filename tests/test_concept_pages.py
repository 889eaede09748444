"""The concept pages state the current state; dated history lives in the changelog.

A long page opens with a short "What to know" summary (issue 35): the facts a reader needs, each
linking to the section that shows it. Dates and commit hashes belong to `CHANGELOG.md` (the
site's *Changelog* page), so a page reads as what is true now, not as a lab log.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs" / "concepts").glob("*.md"))
PAGE_IDS = [p.name for p in PAGES]
LONG_PAGE_WORDS = 1500
MAX_SUMMARY_LINES = 15
DATE = re.compile(r"\b20\d\d-[01]\d-[0-3]\d\b")
# a commit hash: 7-40 lower-case hex digits with at least one letter and one digit
HASH = re.compile(r"(?<![\w./-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![\w-])")


def summary_lines(text: str) -> list[str] | None:
    """The lines of the "What to know" block between the title and the first section, or None."""
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if ln.strip() == "**What to know**"), None)
    first_section = next((i for i, ln in enumerate(lines) if ln.startswith("## ")), len(lines))
    if start is None or start > first_section:
        return None
    body = lines[start + 1:first_section]
    end = next((i for i, ln in enumerate(body) if ln.strip() and not ln.startswith(("- ", "  "))),
               len(body))
    return [ln for ln in body[:end] if ln.strip()]


def test_the_patterns_find_dates_and_hashes_but_not_numbers():
    assert DATE.search("measured 2026-11-25 on main")
    assert HASH.search("at commit `54cd67b`") and HASH.search("commit 58490cc:")
    for text in ("1,416 GFLOP/s", "seed 1286656552236609", "a 2048-square matmul", "deadbee",
                 "decoder", "x86_64", "https://example.org/a1b2c3d4e5"):
        assert not HASH.search(text), text


def test_summary_lines_reads_the_block():
    text = "# T\n\n**What to know**\n\n- one\n  more\n- two\n\nIntro.\n\n## S\n"
    assert summary_lines(text) == ["- one", "  more", "- two"]
    assert summary_lines("# T\n\n## S\n\n**What to know**\n") is None


@pytest.mark.parametrize("page", PAGES, ids=PAGE_IDS)
def test_long_pages_open_with_a_short_summary(page):
    text = page.read_text(encoding="utf-8")
    if len(text.split()) <= LONG_PAGE_WORDS:
        return
    lines = summary_lines(text)
    assert lines, (
        f"{page.name}: over {LONG_PAGE_WORDS} words; open it with a '**What to know**' list")
    assert len(lines) <= MAX_SUMMARY_LINES, (
        f"{page.name}: the summary has {len(lines)} lines, at most {MAX_SUMMARY_LINES}")
    links = sum("](" in ln for ln in lines)
    assert links >= 3, (
        f"{page.name}: the summary links {links} sections; link where each fact is shown")


@pytest.mark.parametrize("page", PAGES, ids=PAGE_IDS)
def test_pages_hold_no_dates_or_commit_hashes(page):
    found = [f"{page.name}:{i}: {m.group(0)}"
             for i, ln in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
             for m in (*DATE.finditer(ln), *HASH.finditer(ln))]
    assert not found, "dated history belongs in CHANGELOG.md:\n" + "\n".join(found)
