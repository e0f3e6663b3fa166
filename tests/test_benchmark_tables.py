"""The tables of benchmarks/README.md generated from benchmark CSVs are what the
generator prints now (benchmarks/tables.py)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _tables():
    spec = importlib.util.spec_from_file_location("tables", ROOT / "benchmarks" / "tables.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def generated_blocks(text: str) -> dict[str, str]:
    """``{area: block}`` between ``<!-- generated: AREA ... -->`` and ``<!-- end generated -->``."""
    pattern = re.compile(r"<!-- generated: (\w+)[^>]*-->\n(.*?)\n<!-- end generated -->", re.S)
    return {m.group(1): m.group(2) for m in pattern.finditer(text)}


def test_interpolation_tables_are_generated_from_the_csv() -> None:
    text = (ROOT / "benchmarks" / "README.md").read_text(encoding="utf-8")
    blocks = generated_blocks(text)
    assert "interpolation" in blocks
    assert blocks["interpolation"] == _tables().interpolation()


def test_twoframe_table_is_generated_from_the_csv() -> None:
    text = (ROOT / "benchmarks" / "README.md").read_text(encoding="utf-8")
    block = generated_blocks(text).get("twoframe")
    assert block == _tables().twoframe()
    # the bold AEE is the lowest, and DeepFlow's time ratio is 1
    assert "| OpenCV DeepFlow | 0.295 | 0.357 | 1.00 |" in block
    assert block.count("**") == 2


def test_the_readme_quotes_the_interpolation_table() -> None:
    """The landing page's interpolation figures are those of the generated table."""
    tables = _tables()
    rows = tables.read_rows(tables.DEFAULT_CSV)
    table = tables.reporting_table(rows)
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    gains = re.findall(r"\| `splat` \| \*\*[\d.]+\*\* \| [\d.]+ \| [\d.]+ \| [\d.]+ \| [\d.]+ \| "
                       r"([+-][\d.]+) \|", table)
    assert len(gains) == 3
    quoted = "above FFmpeg `minterpolate` by " + " / ".join(g.lstrip("+") for g in gains)
    assert quoted in readme
