"""Is Numba's cache of the kernels warm?  (The first run of a method compiles them.)

Every kernel is ``@njit(cache=True)``: the first call of a method on a machine
compiles its kernels (tens of seconds) and stores them in Numba's cache, and later
runs load them in a fraction of a second.  Importing varflow compiles nothing (no
kernel has an explicit signature and none is called at import time).

:func:`kernels_cached` tells, cheaply (a few small files read, no compilation),
whether the cache holds the representative kernels of a method for this machine,
so that the command line can say why its first run is slow
(:data:`COMPILE_SECONDS`).  It answers None when it cannot tell.
"""

from __future__ import annotations

import importlib
import logging
import os
import time
from collections.abc import Sequence
from typing import Any

__all__ = ["AWAIT_SECONDS", "FASTMATH", "FASTMATH_NAN", "FASTMATH_NO_REASSOC",
           "await_kernel", "clear_helper", "compile_seconds", "kernels_cached",
           "method_kernels", "set_helper"]

log = logging.getLogger(__name__)

#: Fast-math flags of the kernels: Numba's ``fastmath=True`` without ``nsz`` (no
#: signed zeros).  With ``nsz`` and ``reassoc`` together, the code LLVM makes when a
#: kernel is compiled in the running process and the code Numba stores in, and later
#: loads from, its cache round differently (one unit in the last place on 29 % of
#: the pixels of ROF's primal-dual iterations), so that the first run of a method on
#: a machine (cold cache) and every later run (warm cache) disagreed, and a chaotic
#: clip amplified that into pixels (rlr on a 9-frame clip: up to 72 px).  Either flag
#: alone gives the same code both ways; ``reassoc`` is kept because the sums need it
#: to vectorise.  ``tests/test_jit_cache.py`` checks a cold and a warm run agree bit
#: for bit.
FASTMATH = {"nnan", "ninf", "arcp", "contract", "afn", "reassoc"}  # a set, as Numba wants

#: :data:`FASTMATH` without the no-NaN and no-infinity assumptions, for kernels that
#: must detect NaN (invalid flow).
FASTMATH_NAN = {"arcp", "contract", "afn", "reassoc"}

#: Fast-math flags without ``reassoc``, for kernels whose arithmetic order matters:
#: the two-constant range reduction of :func:`varflow.ops.fusion._exp_neg_row` must
#: not be folded into one multiplication (fusion's support weights, the weighted
#: median).  ``nsz`` without ``reassoc`` gives the same code cold and warm.
FASTMATH_NO_REASSOC = {"nnan", "ninf", "nsz", "arcp", "contract", "afn"}

#: Kernels (``"module:function"``) every two-frame and trajectory method compiles.
SHARED_KERNELS = ("varflow.ops.warp:_warp_kernel", "varflow.ops.pyramid:_resize_kernel")

def _entry(method: str) -> Any:
    """The registry entry named ``method`` (two-frame, trajectory, interpolation or
    restoration), or None."""
    from .registry import REGISTRIES

    for registry in REGISTRIES:
        if method in registry:
            return registry[method]
    return None


def method_kernels(method: str) -> tuple[str, ...]:
    """The kernels :func:`kernels_cached` checks for ``method`` (``"module:function"``):
    :data:`SHARED_KERNELS` and the entry's own (:attr:`varflow.registry.Entry.kernels`)."""
    entry = _entry(method)
    return SHARED_KERNELS + (tuple(entry.kernels) if entry is not None else ())


def compile_seconds(method: str) -> int | None:
    """Rough seconds the first run of ``method`` spends compiling
    (:attr:`varflow.registry.Entry.compile_seconds`; None if unknown)."""
    entry = _entry(method)
    return None if entry is None else entry.compile_seconds


def _cached(dispatcher: Any) -> bool | None:
    """Does Numba's cache hold a version of ``dispatcher`` for this machine?"""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    index_path = getattr(cache_file, "_index_path", None)
    if index_path is None:  # caching off for this function, or another Numba
        return None
    if not os.path.exists(index_path):
        return False
    overloads = cache_file._load_index()  # {} when stale (source or Numba changed)
    if not overloads:
        return False
    magic = dispatcher.targetctx.codegen().magic_tuple()  # target triple, CPU, features
    return any(key[1] == magic for key in overloads)


def kernels_cached(method: str | None = None,
                   kernels: Sequence[str] | None = None) -> bool | None:
    """Whether the first call of a method will load its kernels rather than compile.

    Parameters
    ----------
    method : str, optional
        A registered method or trajectory method: checks :func:`method_kernels`.
    kernels : sequence of str, optional
        Or these kernels, as ``"module:function"``.

    Returns
    -------
    bool or None
        True when Numba's cache (``NUMBA_CACHE_DIR``, else ``__pycache__`` next to
        the sources, else Numba's per-user folder) holds every kernel checked,
        compiled for this machine; False when one is missing or stale; None when it
        cannot tell (caching off, a kernel not found, Numba internals changed).
    """
    names = tuple(kernels) if kernels is not None else method_kernels(method or "tvl1")
    try:
        answers = []
        for name in names:
            module, _, function = name.partition(":")
            answers.append(_cached(getattr(importlib.import_module(module), function)))
    except Exception as exc:  # noqa: BLE001 - unsure: say nothing rather than fail
        log.debug("kernels_cached: cannot tell (%s: %s)", type(exc).__name__, exc)
        return None
    if any(a is None for a in answers):
        return None
    return all(answers)


#: The longest :func:`await_kernel` waits for the helper, seconds: about what the
#: weighted median's kernel takes to compile here, so that a helper far behind costs
#: the run at most one more compilation's time.
AWAIT_SECONDS = 5.0

#: The warm-up helper this process started (:func:`varflow._warm.start`) and has not
#: finished: its process (a ``subprocess.Popen``) and the kernels it compiles.
_helper: tuple[Any, tuple[str, ...]] | None = None


def set_helper(proc: Any, kernels: Sequence[str]) -> None:
    """Record ``proc`` as this process's warm-up helper, compiling ``kernels``."""
    global _helper
    _helper = (proc, tuple(kernels))


def clear_helper(proc: Any) -> None:
    """Forget the helper ``proc`` (when it is the recorded one)."""
    global _helper
    if _helper is not None and _helper[0] is proc:
        _helper = None


def await_kernel(spec: str, timeout: float = AWAIT_SECONDS, poll: float = 0.05) -> bool:
    """Before the first call of kernel ``spec`` (``"module:function"``): if this
    process's warm-up helper is to compile it and is still running, wait until the
    kernel is in Numba's cache, the helper exits or ``timeout`` seconds pass.

    A first ``tvl1`` run reaches the weighted median a second or two before the
    helper has it: compiling it in the run as well would cost four.  Without a
    helper, or for a kernel it does not compile, returns at once.  Only the time
    changes: the run then loads the kernel or compiles it as it would have.

    Returns
    -------
    bool
        True when the kernel is in the cache after the wait.
    """
    helper = _helper
    if helper is None or spec not in helper[1]:
        return False
    proc = helper[0]
    deadline = time.monotonic() + timeout
    while True:
        cached = kernels_cached(kernels=(spec,))
        if cached is not False:  # in the cache, or cannot tell: no use waiting
            return bool(cached)
        if proc.poll() is not None or time.monotonic() >= deadline:
            return False
        time.sleep(poll)
