"""The profiler of benchmarks/profile_methods.py counts what it claims: the bytes of a
kernel's arrays (written ones twice, returned ones once, times its passes) and each
stage's exclusive time."""

from __future__ import annotations

import importlib.util
import time
from pathlib import Path

import numba as nb
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def prof():
    spec = importlib.util.spec_from_file_location(
        "profile_methods", ROOT / "benchmarks" / "profile_methods.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@nb.njit(cache=False)
def _add_into(a, b, out):
    for i in range(a.size):
        out[i] = a[i] + b[i]


@nb.njit(cache=False)
def _twice(a):
    return a * np.float32(2.0)


@nb.njit(cache=False)
def _sum_of(a):
    return _twice(a).sum()  # a kernel called by a kernel is its caller's time


def test_kernel_bytes_counted_from_the_arrays(prof):
    a = np.ones(1000, np.float32)
    b = np.ones(1000, np.float32)
    out = np.zeros(1000, np.float32)
    _add_into(a, b, out), _twice(a), _sum_of(a)  # compiled before timing
    rec = prof.Recorder()
    undo = prof.install_kernel_timer(rec)
    try:
        rec.learning = True  # the untimed run: a write is found by a change
        out[:] = 0.0
        _add_into(a, b, out)
        _twice(a)
        _sum_of(a)
        rec.learning, rec.active = False, True
        assert not rec.kernel_calls  # learning counts nothing
        _add_into(a, b, out)
        _add_into(a, b, out)  # unchanged output now: written, as learnt
        _twice(a)
        _sum_of(a)
        _twice(np.ones(10, np.float32))  # a shape not learnt: its argument read only
        rec.active = False
        _twice(a)  # not counted when inactive
    finally:
        undo()
    assert rec.unlearned == 1
    mod = _add_into.py_func.__module__.removeprefix("varflow.")
    assert rec.kernel_calls[f"{mod}._add_into"] == 2
    assert rec.kernel_bytes[f"{mod}._add_into"] == 2 * (4000 + 4000 + 2 * 4000)
    assert rec.kernel_bytes[f"{mod}._twice"] == 4000 + 4000 + 40 + 40
    assert rec.kernel_calls[f"{mod}._sum_of"] == 1
    assert rec.kernel_bytes[f"{mod}._sum_of"] == 4000
    assert all(s > 0 for s in rec.kernel_s.values())


def test_iterative_kernels_count_their_passes(prof):
    assert prof.PASSES["tvl1_iterations"]((), 7) == 4  # two iterations per sweep
    assert prof.PASSES["ustep_iterations"]((), 12) == 12
    sched = np.zeros((50, 3), np.float32)
    assert prof.PASSES["_rof_kernel"]((None, None, sched), None) == 50


def test_stages_are_exclusive(prof):
    rec = prof.Recorder()

    def inner():
        time.sleep(0.05)

    wrapped_inner = rec.stage("inner", inner)

    def outer():
        time.sleep(0.05)
        wrapped_inner()

    wrapped_outer = rec.stage("outer", outer)
    wrapped_outer()
    assert not rec.stage_s  # inactive: nothing recorded
    rec.active = True
    wrapped_outer()
    assert rec.stage_s["inner"] == pytest.approx(0.05, abs=0.04)
    assert rec.stage_s["outer"] == pytest.approx(0.05, abs=0.04)
    assert not rec.stack
