"""Determinism: the same input and parameters give bit-identical outputs.

Across runs in one process and across processes with different Numba thread counts
(``NUMBA_NUM_THREADS=1`` and ``=2``): two-frame flows (``tvl1`` and ``tensor``) and
``rlr`` trajectories of a 5-frame 48x64 clip.  Outputs are compared byte for byte
(``np.array_equal(..., equal_nan=True)`` and equal ``tobytes()``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import varflow

_CASES = textwrap.dedent(
    """
    import numpy as np
    from scipy import ndimage as ndi

    import varflow


    def inputs():
        rng = np.random.default_rng(7)
        base = ndi.gaussian_filter(rng.random((70, 90, 3)), (1.5, 1.5, 0))
        pair = (base[4:52, 6:70], base[5:53, 4:68])
        clip = np.stack([base[2 + k:50 + k, 3 + 2 * k:67 + 2 * k, 0] for k in range(5)])
        return pair, (clip * 255).astype(np.uint8)


    def run():
        (f0, f1), clip = inputs()
        return {
            "tvl1": varflow.flow(f0, f1, "tvl1"),
            "tensor": varflow.flow(f0[..., 0], f1[..., 0], "tensor"),
            "rlr": varflow.track(clip, method="rlr"),
        }
    """
)


def _run_in_process() -> dict[str, np.ndarray]:
    namespace: dict = {}
    exec(compile(_CASES, "<determinism cases>", "exec"), namespace)  # noqa: S102
    return namespace["run"]()


def _run_in_subprocess(tmp_path: Path, threads: int) -> dict[str, np.ndarray]:
    out = tmp_path / f"out_{threads}.npz"
    script = _CASES + f"\nnp.savez({str(out)!r}, **run())\n"
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    with np.load(out) as data:
        return {k: data[k] for k in data.files}


def _assert_identical(a: dict[str, np.ndarray], b: dict[str, np.ndarray], what: str) -> None:
    assert sorted(a) == sorted(b)
    for key in a:
        assert a[key].dtype == b[key].dtype and a[key].shape == b[key].shape, (what, key)
        diff = np.abs(a[key] - b[key])
        assert np.array_equal(a[key], b[key], equal_nan=True), (
            f"{what}: {key} differs (max |diff| {np.nanmax(diff):.3g})"
        )
        assert a[key].tobytes() == b[key].tobytes(), (what, key)


@pytest.fixture(scope="module")
def in_process() -> dict[str, np.ndarray]:
    return _run_in_process()


def test_outputs_are_real(in_process: dict[str, np.ndarray]) -> None:
    assert in_process["tvl1"].shape == (48, 64, 2)
    assert in_process["rlr"].shape == (5, 48, 64, 2)
    for key, value in in_process.items():
        assert np.abs(np.nan_to_num(value)).max() > 0.5, key  # the methods did work


def test_repeated_runs_in_one_process(in_process: dict[str, np.ndarray]) -> None:
    _assert_identical(in_process, _run_in_process(), "second run in process")


def test_thread_counts_give_identical_bytes(tmp_path: Path,
                                            in_process: dict[str, np.ndarray]) -> None:
    one = _run_in_subprocess(tmp_path, 1)
    two = _run_in_subprocess(tmp_path, 2)
    _assert_identical(one, two, "NUMBA_NUM_THREADS=1 vs 2")
    _assert_identical(one, in_process, "subprocess vs this process")


def test_numba_threads_are_what_the_subprocesses_ask_for(tmp_path: Path) -> None:
    """Guard: the 2-thread run really has 2 threads (else the test above proves little)."""
    env = dict(os.environ, NUMBA_NUM_THREADS="2")
    proc = subprocess.run(
        [sys.executable, "-c", "import numba; print(numba.config.NUMBA_NUM_THREADS)"],
        env=env, capture_output=True, text=True, timeout=120,
    )
    assert proc.stdout.strip() == "2"
    assert varflow.flow is not None
