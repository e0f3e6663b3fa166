"""Compile the kernels a first run needs last in a second process, while it computes.

A method's first run on a machine compiles its Numba kernels one after the other, on
one core, in the order the run first calls them (:mod:`varflow._jit`).  For ``tvl1``
the kernels of the filters after a warp (the 5 × 5 median, the flow-edge mask, the
weighted median), the dual projection of a new level and the gradient-constancy
channels with their smoothing come after the others and make up about two fifths of
the compile time.
:func:`start` launches ``python -m varflow._warm`` to compile those into Numba's
cache on another core; by the time the run reaches them it loads them from the
cache.  Nothing is shared but the cache, whose files Numba writes atomically: if the
helper is late, fails or is absent, the run compiles the kernels itself, as it
would without it, and its results do not change (a kernel loaded from the cache
computes the same bits as one compiled in the process, ``tests/test_jit_cache.py``).

Each warm-up call gives its kernel the argument types of the method's own call;
``tests/test_warm.py`` checks that the method then compiles no second version.
"""

from __future__ import annotations

import contextlib
import logging
import os
import subprocess
import sys
from collections.abc import Callable, Iterator

import numba
import numpy as np

from ._jit import clear_helper, set_helper

__all__ = ["LATE_KERNELS", "beside", "finish", "start", "warm_up"]

log = logging.getLogger(__name__)

#: Per method, the kernels the helper compiles (``"module:function"``), in the order
#: the method first needs them.
LATE_KERNELS: dict[str, tuple[str, ...]] = {
    "tvl1": (
        "varflow.ops.pyramid:_smooth_planar_kernel",
        "varflow.twoframe.tvl1:_gradient_channels_kernel",
        "varflow.ops.median:_median5_kernel",
        "varflow.ops.primal_dual:project_dual",
        "varflow.ops.median:_edge_kernel",
        "varflow.ops.median:_dilate_rows",
        "varflow.ops.median:_dilate_cols",
        "varflow.ops.median:_weighted_median_kernel",
    ),
}


def _warm_tvl1() -> None:
    """Call the late kernels of ``tvl1`` once on small arrays of the types its run
    passes them."""
    from .ops.median import median_filter_flow, weighted_median_flow
    from .ops.primal_dual import project_dual
    from .ops.pyramid import smooth_planes
    from .twoframe.tvl1 import _gradient_channels_kernel

    h, w, nc = 24, 32, 3
    f32 = np.float32
    planes = np.zeros((h, w, 3 * nc), f32)  # the warped frame and its derivatives
    smooth_planes(planes[..., nc:2 * nc], 1.0, out=np.empty((2 * nc, h, w), f32)[:nc])
    stack = np.zeros((2 * nc, h, w), f32)
    ix = np.zeros((3 * nc, h, w), f32)
    _gradient_channels_kernel(stack, stack.copy(), np.ones((h, w), np.bool_),
                              np.zeros((2, h, w), f32), f32(1.0), nc, ix, ix.copy(),
                              ix.copy())
    flow = np.zeros((h, w, 2), f32)
    flow[:, w // 2:, 0] = 4.0  # a motion edge, so the weighted median has work
    median_filter_flow(flow, 5)
    weighted_median_flow(flow, np.zeros((h, w, nc), f32), base=flow)
    project_dual(np.zeros((4, h, w), f32), np.ones((h, w), f32))


_WARMERS: dict[str, Callable[[], None]] = {"tvl1": _warm_tvl1}


def warm_up(method: str) -> None:
    """Compile (or load) the late kernels of ``method`` in this process.

    Raises
    ------
    ValueError
        If no warm-up is defined for ``method``.
    """
    if method not in _WARMERS:
        raise ValueError(f"method: no warm-up for {method!r} (have {sorted(_WARMERS)})")
    _WARMERS[method]()


def start(method: str) -> subprocess.Popen | None:
    """Launch the helper for ``method`` when it can help, else None.

    It helps when Numba's cache lacks one of the method's late kernels
    (:func:`varflow._jit.kernels_cached` says False), the machine has two cores or
    more and Numba's JIT is on.  The helper writes nothing but the cache; its
    output is discarded.
    """
    from ._jit import kernels_cached

    if method not in LATE_KERNELS or (os.cpu_count() or 1) < 2:
        return None
    if numba.config.DISABLE_JIT:
        return None
    if kernels_cached(kernels=LATE_KERNELS[method]) is not False:
        return None
    try:
        proc = subprocess.Popen([sys.executable, "-m", "varflow._warm", method],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
    except OSError as exc:  # no interpreter to start: compile in this process
        log.debug("warm-up helper not started: %s", exc)
        return None
    log.debug("warm-up helper %d compiling the late kernels of %s", proc.pid, method)
    set_helper(proc, LATE_KERNELS[method])  # the run may wait for it (await_kernel)
    return proc


def finish(proc: subprocess.Popen | None, timeout: float = 1.0) -> None:
    """Stop the helper once the run is done: whatever it has not compiled yet, the
    run compiled (and cached) itself.  It gets ``timeout`` seconds to finish the
    kernel it is on; a kernel it was writing is left out of the cache, never half
    written."""
    if proc is None:
        return
    clear_helper(proc)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.terminate()
        proc.wait()


@contextlib.contextmanager
def beside(method: str) -> Iterator[None]:
    """Run the body with the helper of ``method`` compiling beside it (:func:`start`,
    then :func:`finish`, also when the body raises)."""
    proc = start(method)
    try:
        yield
    finally:
        finish(proc)


if __name__ == "__main__":  # pragma: no cover - the helper process
    warm_up(sys.argv[1] if len(sys.argv) > 1 else "tvl1")
