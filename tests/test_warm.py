"""The warm-up helper (:mod:`varflow._warm`): a second process compiles the kernels a
first ``tvl1`` run needs last.

It only helps if each warm-up call gives its kernel the very argument types the
method's run gives it (else the run compiles a second version anyway): the types of
every call are recorded and compared.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numba
import pytest

import varflow
from varflow import _warm
from varflow.cli.flow import _to_uint8
from varflow.generators.pairs import synthetic_pair


def _record_calls(monkeypatch: pytest.MonkeyPatch, spec: str, calls: list) -> None:
    """Record the Numba argument types of every call of kernel ``spec`` through any
    varflow module that binds it."""
    module, _, name = spec.partition(":")
    kernel = getattr(importlib.import_module(module), name)

    def recorder(*args):
        calls.append(tuple(numba.typeof(a) for a in args))
        return kernel(*args)

    for mod in list(sys.modules.values()):
        if getattr(mod, "__name__", "").startswith("varflow") and \
                getattr(mod, name, None) is kernel:
            monkeypatch.setattr(mod, name, recorder)


def test_warm_up_calls_the_kernels_with_the_types_of_a_tvl1_run(
        monkeypatch: pytest.MonkeyPatch) -> None:
    specs = _warm.LATE_KERNELS["tvl1"]
    warm = {s: [] for s in specs}
    run = {s: [] for s in specs}
    for s in specs:
        _record_calls(monkeypatch, s, warm[s])
    _warm.warm_up("tvl1")
    monkeypatch.undo()
    for s in specs:
        _record_calls(monkeypatch, s, run[s])
    f0, f1, _ = synthetic_pair("smooth", shape=(96, 128), magnitude=3.0, seed=4)
    varflow.flow(_to_uint8(f0), _to_uint8(f1), "tvl1")  # as the demo calls it
    for s in specs:
        assert warm[s], f"the warm-up never called {s}"
        assert run[s], f"tvl1 never called {s}: LATE_KERNELS is out of date"
        assert set(run[s]) <= set(warm[s]), (s, set(run[s]) - set(warm[s]))


def test_no_helper_when_it_cannot_help(monkeypatch: pytest.MonkeyPatch) -> None:
    from varflow import _jit

    started = []
    monkeypatch.setattr(_warm.subprocess, "Popen",
                        lambda *a, **k: started.append(a) or SimpleNamespace(pid=0))
    monkeypatch.setattr(_jit, "kernels_cached", lambda method=None, kernels=None: True)
    assert _warm.start("tvl1") is None  # the cache already holds them
    monkeypatch.setattr(_jit, "kernels_cached", lambda method=None, kernels=None: None)
    assert _warm.start("tvl1") is None  # cannot tell
    monkeypatch.setattr(_jit, "kernels_cached", lambda method=None, kernels=None: False)
    assert _warm.start("tvl1-ld") is None  # no late kernels listed
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    assert _warm.start("tvl1") is None  # one core: nothing to overlap
    assert not started
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert _warm.start("tvl1") is not None
    assert started and started[0][0][-2:] == ["varflow._warm", "tvl1"]
    _warm.finish(None)
    with pytest.raises(ValueError, match="method"):
        _warm.warm_up("no-such-method")


@pytest.mark.slow
def test_helper_fills_an_empty_cache(tmp_path: Path) -> None:
    """``python -m varflow._warm tvl1`` on an empty Numba cache leaves every late
    kernel cached, and a process that then checks finds them."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    check = ("from varflow import _jit, _warm; "
             "print(_jit.kernels_cached(kernels=_warm.LATE_KERNELS['tvl1']))")
    before = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                            env=env, timeout=300)
    assert before.stdout.strip() == "False", before.stderr
    done = subprocess.run([sys.executable, "-m", "varflow._warm", "tvl1"],
                          capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    after = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True,
                           env=env, timeout=300)
    assert after.stdout.strip() == "True", after.stderr
