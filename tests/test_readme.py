"""The README is a landing page whose links, picture and figures hold."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def test_readme_is_a_short_landing_page() -> None:
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    # the two set-up commands: install and run the demo, then the tests (.ci/run runs them)
    assert "pip install -e . && varflow demo\n" in text
    assert 'pip install -e ".[test]" && python -m pytest -q\n' in text
    assert "python -m sphinx -W -b html docs docs/_build/html" in text


def test_readme_links_point_at_files() -> None:
    text = README.read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text)
    assert len(targets) >= 10
    for target in targets:
        assert not target.startswith(("http:", "https:")), target
        assert (ROOT / target).exists(), target


def test_readme_picture_states_what_its_generator_measures() -> None:
    """The picture's caption quotes the two errors that tools/make_readme_picture.py
    draws on it; they are measured again here (a margin for other CPUs' last bits)."""
    import varflow
    from varflow.generators.large_pairs import make_large_pair

    text = README.read_text(encoding="utf-8")
    m = re.search(r"!\[[^\]]*tvl1's flow \(AEE ([\d.]+) px\) and tvl1-ld's \(([\d.]+) px\)\]"
                  r"\((docs/_static/varflow.png)\)", text)
    assert m, "the picture's caption"
    assert (ROOT / m.group(3)).is_file()
    pair = make_large_pair("objects", seed=100, shape=(240, 320))
    gt = np.where(pair.valid[..., None], pair.flow, np.nan).astype(np.float32)
    for method, stated in (("tvl1", m.group(1)), ("tvl1-ld", m.group(2))):
        aee = varflow.evaluate(varflow.flow(pair.frame0, pair.frame1, method), gt)["aee"]
        assert abs(aee - float(stated)) < 0.05 * max(1.0, float(stated)), (method, aee)
