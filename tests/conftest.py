"""Shared fixtures: the location of the benchmark data, one Numba thread, a count of
:func:`varflow.flow` calls."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from varflow.evaluation import datasets


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "data: needs the benchmark data (VARFLOW_DATA); runs in CI (.ci/run)"
    )


@pytest.fixture
def one_numba_thread() -> Iterator[None]:
    """Run a test with one Numba thread (small frames: faster, and steady on a loaded
    machine), restoring the count afterwards."""
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(old)


@pytest.fixture
def flow_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """A list that gains an entry at every call of :func:`varflow.flow` during the test
    (the library calls it through the package attribute, so the wrapper sees them all);
    ``len()`` is the count, ``clear()`` starts it again."""
    import varflow

    calls: list[int] = []
    original = varflow.flow

    def counted(*args: object, **kwargs: object) -> object:
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(varflow, "flow", counted)
    return calls


@pytest.fixture(scope="session")
def data_root() -> Path:
    """The benchmark data folder (see :func:`varflow.evaluation.datasets.data_root`).

    Skips the test when the folder does not exist, or fails it when the environment
    variable ``VARFLOW_REQUIRE_DATA=1`` (as in CI).
    """
    root = datasets.data_root()
    if not root.is_dir():
        msg = f"benchmark data not found at {root}; set {datasets.ENV_VAR}"
        if os.environ.get("VARFLOW_REQUIRE_DATA", "").strip() == "1":
            pytest.fail(msg)
        pytest.skip(msg)
    return root


_WARM_UP = """
import numpy as np, varflow
from varflow.generators.pairs import synthetic_pair
f0, f1, _ = synthetic_pair("translation", shape=(40, 48), magnitude=1.0, seed=0)
for m in ("tvl1", "tvl1-fast", "tensor"):
    varflow.flow(f0, f1, m)
frames = np.stack([f0, f1, f0, f1, f0])
for t in ("rlr", "chain", "twoframe"):
    varflow.track(frames, 2, t)
varflow.denoise(np.stack([f0, f1, f0]), 0.05, radius=1)
"""


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile and cache the main Numba kernels in a subprocess before any test runs.

    A kernel compiled in a process can give results that differ in the last bits from
    the same kernel loaded from Numba's cache (the two compilation paths of
    ``parallel=True, fastmath=True`` kernels); the tests that compare outputs across
    processes (batch workers, thread counts) need every process to run the cached
    code, as every run after the first does.
    """
    import subprocess
    import sys

    subprocess.run([sys.executable, "-c", _WARM_UP], check=False, capture_output=True,
                   timeout=1800)


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator:
    """Headless Chromium driven through the DevTools protocol (tests/_browser.py), one per
    test module; the test is skipped where Chromium is absent."""
    from _browser import DevTools, chromium_or_skip

    tools = DevTools(chromium_or_skip(), tmp_path_factory.mktemp("chromium"))
    try:
        yield tools
    finally:
        tools.close()
