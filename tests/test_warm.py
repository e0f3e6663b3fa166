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
import time
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
    monkeypatch.setattr(_jit, "_helper", None)  # start() records its fake helper there
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


def test_await_kernel_waits_for_the_helper_only_while_it_can_help(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from varflow import _jit

    spec = "varflow.ops.median:_weighted_median_kernel"
    monkeypatch.setattr(_jit, "_helper", None)
    assert _jit.await_kernel(spec, timeout=5.0) is False  # no helper: at once

    polls = []

    def cached_on_third(method=None, kernels=None):
        polls.append(kernels)
        return len(polls) >= 3

    monkeypatch.setattr(_jit, "kernels_cached", cached_on_third)
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        _jit.set_helper(sleeper, _warm.LATE_KERNELS["tvl1"])
        assert _jit.await_kernel("varflow.ops.rof:_rof_kernel", timeout=5.0) is False
        assert polls == []  # not one of the helper's kernels: no wait
        assert _jit.await_kernel(spec, timeout=5.0, poll=0.01) is True
        assert len(polls) == 3 and polls[0] == (spec,)
        # never cached: gives up after the timeout, the run compiles it itself
        monkeypatch.setattr(_jit, "kernels_cached", lambda method=None, kernels=None: False)
        t0 = time.monotonic()
        assert _jit.await_kernel(spec, timeout=0.3, poll=0.01) is False
        assert 0.3 <= time.monotonic() - t0 < 5.0
        # cannot tell: no wait
        monkeypatch.setattr(_jit, "kernels_cached", lambda method=None, kernels=None: None)
        assert _jit.await_kernel(spec, timeout=5.0) is False
        monkeypatch.setattr(_jit, "kernels_cached", lambda method=None, kernels=None: False)
        _jit.clear_helper(object())  # another process: kept
        assert _jit._helper is not None
        _warm.finish(sleeper, timeout=0.1)  # stops it and forgets it
        assert _jit._helper is None
    finally:
        sleeper.kill()
        sleeper.wait()
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    _jit.set_helper(done, _warm.LATE_KERNELS["tvl1"])
    t0 = time.monotonic()
    assert _jit.await_kernel(spec, timeout=5.0) is False  # the helper has exited
    assert time.monotonic() - t0 < 1.0
