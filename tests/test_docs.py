"""The documentation: its generated pages match the code, and the built site renders.

The site is built by ``python -m sphinx -W -b html docs docs/_build/html`` (``.ci/run``
does it before the suite; ``$VARFLOW_DOCS_HTML`` points elsewhere).  Without a build
the rendering tests skip, unless ``VARFLOW_REQUIRE_DOCS=1`` (as in CI), which makes them
fail.  In headless Chromium, the front page and a gallery page must load without
console errors, exceptions or external requests, and their screenshots must not be
blank; the screenshots are kept next to the build (``_screenshots/``).
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from _browser import DevTools
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _ext():
    spec = importlib.util.spec_from_file_location("varflow_docs", DOCS / "_ext" / "varflow_docs.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("varflow_docs", module)
    spec.loader.exec_module(module)
    return module


def built_html() -> Path:
    path = Path(os.environ.get("VARFLOW_DOCS_HTML", DOCS / "_build" / "html"))
    if not (path / "index.html").is_file():
        msg = (f"the documentation is not built at {path} (python -m sphinx -W -b html docs "
               "docs/_build/html)")
        if os.environ.get("VARFLOW_REQUIRE_DOCS", "").strip() == "1":
            pytest.fail(msg)
        pytest.skip(msg)
    return path


# --------------------------------------------------------------------------- generated


def test_cli_reference_covers_every_command() -> None:
    """Every command and sub-command of the parser has its help on the CLI page."""
    texts = dict(_ext().cli_help_texts())
    for command in ("varflow", "varflow flow", "varflow track", "varflow interpolate",
                    "varflow retime", "varflow bench interpolation", "varflow batch retime",
                    "varflow report", "varflow methods"):
        assert command in texts, command
        assert texts[command].startswith("usage: " + command), command


def test_parameter_tables_are_the_dataclasses() -> None:
    """The generated tables list every field of every registered method, with the
    dataclass's default."""
    import dataclasses

    from varflow.cli._common import flag_of
    from varflow.registry import REPAIR, parameter_fields

    ext = _ext()
    for kind, registry in ext.registries().items():
        text = "\n".join(ext.parameter_rst(kind))
        for name, entry in registry.items():
            assert f"``{name}``" in text
            for field, default, _ in parameter_fields(entry):
                flag = flag_of(name, field)
                assert flag == (f"--set {name}.{field}=" if registry is REPAIR
                                else f"--{field.replace('_', '-')}")
                assert f"``{field}`` (``{flag}``)" in text, (name, field)
                assert f"``{default!r}``" in text, (name, field)
        assert all(dataclasses.is_dataclass(e.params_type) for e in registry.values())


def test_api_page_lists_the_public_names() -> None:
    import varflow
    import varflow.io.video as video

    page = _ext().api_page()
    for name in ("flow", "track", "interpolate", "evaluate"):
        assert name in varflow.__all__ and f"   {name}\n" in page
    for name in video.__all__:
        assert f"   {name}\n" in page
    for cls in ("varflow.twoframe.params.TVL1Params", "varflow.twoframe.params.SparseTerm",
                "varflow.multiframe.params.RLRParams",
                "varflow.retime.splatting.SplatParams"):
        assert f"   {cls}\n" in page


def test_the_gallery_has_eight_examples_with_a_measured_number() -> None:
    scripts = sorted((ROOT / "examples").rglob("plot_*.py"))
    assert len(scripts) >= 8
    for script in scripts:
        text = script.read_text(encoding="utf-8")
        assert text.startswith('"""\n'), script  # a title docstring
        assert "plt.show()" in text and "print(" in text, script


# --------------------------------------------------------------------------- the site


def _not_blank(shot: np.ndarray) -> None:
    grey = shot.mean(axis=2)
    assert grey.std() > 10, "the screenshot is almost uniform"
    assert (np.abs(np.diff(grey, axis=0)) > 30).mean() > 0.002, "no visible content"


@pytest.mark.parametrize("page", ["index.html",
                                  "auto_examples/flow/plot_first_flow.html",
                                  "auto_examples/interpolation/plot_interpolation.html"])
def test_pages_render_without_errors(browser: DevTools, page: str) -> None:
    html = built_html()
    path = html / page
    assert path.is_file(), path
    browser.load(path.as_uri())
    assert browser.problems() == []
    assert browser.evaluate("document.title").strip()
    images = browser.evaluate("[...document.images].filter(i => i.complete && "
                              "i.naturalWidth > 0).length")
    if page.startswith("auto_examples"):
        assert images >= 1, "the example's figure is missing"
    shot = browser.screenshot()
    out = html.parent / "_screenshots"
    out.mkdir(exist_ok=True)
    Image.fromarray(shot).save(out / (page.replace("/", "_") + ".png"))
    _not_blank(shot)
