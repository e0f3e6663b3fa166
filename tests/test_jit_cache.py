"""The first-run notice: "varflow: compiling kernels, once per machine, about N s".

:func:`varflow._jit.kernels_cached` reads Numba's cache index of a few
representative kernels (no compilation); the CLI prints the notice on stderr only
when it is sure they are not cached.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from varflow import _jit

NOTICE = "varflow: compiling kernels, once per machine, about"


def _fresh_env(cache: Path) -> dict[str, str]:
    return {**os.environ, "NUMBA_CACHE_DIR": str(cache)}


def test_kernels_cached_answers(tmp_path: Path) -> None:
    from varflow.registry import METHODS, TRACKERS

    for name in (*METHODS, *TRACKERS):  # every listed kernel exists
        for spec in _jit.method_kernels(name):
            module, _, function = spec.partition(":")
            assert hasattr(__import__(module, fromlist=[function]), function), spec
        assert _jit.compile_seconds(name), name
    assert _jit.kernels_cached(kernels=["varflow.ops.warp:no_such_kernel"]) is None
    assert _jit.kernels_cached(kernels=["no.such.module:f"]) is None
    # an empty cache folder: not cached, and the check compiles nothing
    code = ("from varflow import _jit; import varflow.registry as r; "
            "print([_jit.kernels_cached(m) for m in (*r.METHODS, *r.TRACKERS)])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=_fresh_env(tmp_path / "cache"), timeout=300)
    assert out.returncode == 0, out.stderr
    assert set(ast.literal_eval(out.stdout)) == {False}
    assert not list((tmp_path / "cache").rglob("*.nbi"))


@pytest.mark.slow
def test_first_demo_says_it_compiles_second_does_not(tmp_path: Path) -> None:
    """A fresh Numba cache: the first demo (about 20 s of compiling on two cores) says so, once."""
    env = _fresh_env(tmp_path / "cache")
    cmd = [sys.executable, "-m", "varflow.cli", "demo", "-o", str(tmp_path / "demo")]
    first = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1200)
    assert first.returncode == 0, first.stderr
    lines = first.stderr.splitlines()
    assert [ln for ln in lines if ln.startswith(NOTICE)] == [
        f"{NOTICE} {_jit.compile_seconds('tvl1')} s"], first.stderr
    assert "AEE" in first.stdout
    second = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1200)
    assert second.returncode == 0, second.stderr
    assert NOTICE not in second.stderr


@pytest.mark.parametrize(("cached", "quiet", "shown"), [
    (False, False, True), (False, True, False), (True, False, False), (None, False, False),
])
def test_notice_only_when_sure_and_not_quiet(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    cached: bool | None, quiet: bool, shown: bool,
) -> None:
    from varflow import _warm, cli

    asked = []
    monkeypatch.setattr(_jit, "kernels_cached", lambda m=None, k=None: asked.append(m) or cached)
    monkeypatch.setattr(_warm, "start", lambda method: None)  # no helper process here
    rc = cli.main(["demo", "-o", str(tmp_path / "demo"), *(["-q"] if quiet else [])])
    err = capsys.readouterr().err
    assert rc == 0
    assert (NOTICE in err) is shown, err
    assert asked == ([] if quiet else ["tvl1"])


_REPRO = """
import sys
import numpy as np
import varflow
from varflow.generators.photo import make_photo_clip

clip = make_photo_clip("illumination", 101, n_frames=7, shape=(64, 96))
traj = varflow.track(clip.frames, clip.ref, "rlr")
flow = varflow.flow(clip.frames[clip.ref], clip.frames[0], "tvl1-ld")
np.save(sys.argv[1], np.concatenate([traj.ravel(), flow.ravel()]))
"""


@pytest.mark.slow
def test_cold_and_warm_cache_agree_bit_for_bit(tmp_path: Path) -> None:
    """The first run on a machine (kernels compiled in the process) and a later one
    (kernels loaded from Numba's cache) give the same bits: rlr and tvl1-ld on a
    clip whose sky the trackers find hard (before ``varflow._jit.FASTMATH`` dropped
    ``nsz`` they differed by pixels)."""
    env = _fresh_env(tmp_path / "cache")
    script = tmp_path / "repro.py"
    script.write_text(_REPRO)
    outs = []
    for run in ("cold", "warm"):
        out = tmp_path / f"{run}.npy"
        done = subprocess.run([sys.executable, str(script), str(out)], capture_output=True,
                              text=True, env=env, timeout=1200)
        assert done.returncode == 0, done.stderr
        outs.append(np.load(out))
    assert outs[0].tobytes() == outs[1].tobytes(), float(np.nanmax(np.abs(outs[0] - outs[1])))
