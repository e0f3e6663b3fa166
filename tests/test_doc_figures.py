"""Every figure the docs quote comes from the results page, benchmarks/README.md.

A "figure" is a decimal number in the prose of the landing page and of the hand-written
documentation pages (code, parameter values written ``name = value``, table and chapter
numbers of the book and the README picture's caption, which tests/test_readme.py
re-measures, are not figures).  Each must appear, written the same way, in
benchmarks/README.md, so a page cannot quote a rounded, stale or untraceable number.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Hand-written pages that quote benchmark figures.  The results page itself and the
#: history (benchmarks/HISTORY.md, every experiment with its own figure) are the sources.
PAGES = sorted(
    [ROOT / "README.md", ROOT / "docs" / "getting_started.rst", ROOT / "docs" / "index.rst",
     ROOT / "docs" / "book.rst", ROOT / "docs" / "benchmarks.md"]
    + list((ROOT / "docs" / "guide").glob("*.md")))

_NUMBER = re.compile(r"(?<![\w.])[+−-]?(\d+\.\d+)(?![\w.]*\d)")
_NOT_FIGURES = [
    re.compile(r"```.*?```", re.S),                      # Markdown code blocks
    re.compile(r"^\.\. code-block::.*?(?=^\S)", re.S | re.M),  # reST code blocks
    re.compile(r"``[^`]*``|`[^`]*`"),                    # inline code
    re.compile(r"!\[[^\]]*\]"),                          # image alt text (measured elsewhere)
    re.compile(r"\b(?:Tables?|ch\.|chapter|§)\s*\d+\.\d+(?:\s*/\s*\d+\.\d+)?", re.I),
    re.compile(r"[=≈]\s*[+−-]?\d+(?:\.\d+)?"),            # parameter values
]


def figures(text: str) -> list[tuple[int, str]]:
    """``(line, number)`` of the decimal figures of a page's prose."""
    for pattern in _NOT_FIGURES:
        text = pattern.sub(lambda m: "\n" * m.group(0).count("\n"), text)
    return [(i, m.group(1)) for i, line in enumerate(text.splitlines(), 1)
            for m in _NUMBER.finditer(line)]


def test_the_filter_keeps_figures_and_drops_the_rest() -> None:
    text = ("AEE **0.624** against 0.660 (ε_H = 0.02, `t=0.5`), Table 3.3 / 3.4,\n"
            "```\nvarflow bench --x 1.5\n```\n![caption 7.90 px](p.png) +3.49 dB")
    assert figures(text) == [(1, "0.624"), (1, "0.660"), (5, "3.49")]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_quoted_figure_is_on_the_results_page(page: Path) -> None:
    results = (ROOT / "benchmarks" / "README.md").read_text(encoding="utf-8")
    known = {m.group(1) for m in _NUMBER.finditer(results)}
    missing = [f"line {i}: {x}" for i, x in figures(page.read_text(encoding="utf-8"))
               if x not in known]
    assert not missing, (f"{page.relative_to(ROOT)} quotes figures that benchmarks/README.md "
                         f"does not have: {', '.join(missing)}")
