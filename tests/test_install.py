"""What an install needs (issue 26): the core without the ``batch`` extra, one version.

``import varflow``, building the ``varflow`` parser and running ``demo``, ``flow``
and ``track`` never import dask, distributed or zarr (the ``batch`` extra);
``varflow batch`` without them stops with one line naming the extra.
"""

from __future__ import annotations

import importlib.metadata
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import varflow
from varflow import cli

EXTRA = ("dask", "distributed", "zarr")
MESSAGE = ('varflow: error: varflow batch needs dask, distributed and zarr: '
           'pip install "varflow[batch]"')


def test_one_version() -> None:
    from varflow._version import __version__

    assert varflow.__version__ == __version__ == importlib.metadata.version("varflow")
    out = subprocess.run([sys.executable, "-m", "varflow.cli", "--version"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == f"varflow {__version__}"


def test_core_commands_do_not_import_the_batch_extra(tmp_path: Path) -> None:
    """In a fresh interpreter: import, parser, demo, flow and track; then sys.modules."""
    from varflow.io import write_image

    frames = tmp_path / "clip"
    frames.mkdir()
    rng = np.random.default_rng(0)
    base = (rng.random((24, 40, 3)) * 255).astype(np.uint8)
    for k in range(3):
        write_image(frames / f"f{k}.png", np.roll(base, k, axis=1))
    script = textwrap.dedent(f"""
        import json, sys
        import varflow, varflow.cli
        from varflow.cli import build_parser, main
        stages = {{}}
        def loaded(stage):
            stages[stage] = sorted(m for m in sys.modules
                                   if m.split(".")[0] in {EXTRA!r})
        loaded("import")
        build_parser()
        build_parser(["batch", "flow", "--method", "tvl1", "--help"])
        loaded("parser")
        d = {str(tmp_path / "demo")!r}
        assert main(["demo", "-o", d, "-q"]) == 0
        loaded("demo")
        assert main(["flow", d + "/frame0.png", d + "/frame1.png", "-o", d + "/f.flo",
                     "--method", "tvl1-fast", "-q"]) == 0
        loaded("flow")
        assert main(["track", {str(frames)!r}, "-o", d + "/t.npz", "--method", "chain",
                     "-q"]) == 0
        loaded("track")
        print(json.dumps(stages), file=sys.stderr)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr
    stages = json.loads(out.stderr.strip().splitlines()[-1])
    assert list(stages) == ["import", "parser", "demo", "flow", "track"]
    assert stages == {k: [] for k in stages}, stages


@pytest.mark.parametrize("missing", EXTRA)
def test_batch_without_the_extra_is_one_line(
    missing: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setitem(sys.modules, missing, None)  # "import <missing>" raises ImportError
    for kind in (["flow"], ["track", "--window", "3", "--overlap", "1"]):
        rc = cli.main(["batch", *kind, str(tmp_path), "-o", str(tmp_path / "out")])
        out, err = capsys.readouterr()
        assert rc == 2 and not out
        assert err == MESSAGE + "\n"
    assert not (tmp_path / "out").exists()


def test_batch_without_dask_in_a_fresh_process(tmp_path: Path) -> None:
    """As a user without the extra sees it: no traceback; --help still works."""
    pre = "import sys; sys.modules['dask'] = None; from varflow.cli import main; "
    out = subprocess.run(
        [sys.executable, "-c", pre + f"raise SystemExit(main(['batch', 'flow', "
         f"{str(tmp_path)!r}, '-o', {str(tmp_path / 'out')!r}]))"],
        capture_output=True, text=True, timeout=300)
    assert out.returncode == 2 and out.stderr == MESSAGE + "\n" and not out.stdout
    out = subprocess.run(
        [sys.executable, "-c", pre + "raise SystemExit(main(['batch', 'flow', '--help']))"],
        capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and "--n-warps" in out.stdout, out.stderr


def test_core_dependencies_leave_the_batch_stack_to_its_extra() -> None:
    """``pip install -e .`` installs no dask, distributed or zarr (pyproject and metadata)."""
    import re
    import tomllib

    heavy = {"dask", "distributed", "zarr"}

    def name(req: str) -> str:
        return re.split(r"[\s;<>=!~\[]", req, maxsplit=1)[0].lower()

    project = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml")
                            .read_text(encoding="utf-8"))["project"]
    assert not heavy & {name(r) for r in project["dependencies"]}
    assert {name(r) for r in project["optional-dependencies"]["batch"]} == heavy
    assert "varflow[batch]" in project["optional-dependencies"]["test"]
    core = [r for r in importlib.metadata.requires("varflow") or [] if "extra ==" not in r]
    assert core and not heavy & {name(r) for r in core}, core
