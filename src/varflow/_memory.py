"""Memory estimates: refuse an input that cannot fit *before* the run starts.

:func:`estimate_bytes` predicts the peak memory of one :func:`varflow.flow` or
:func:`varflow.track` call from the frame shape, the number of frames and the
method; :func:`available_bytes` reads how much memory the process may still use;
:func:`check_memory` raises :class:`InsufficientMemoryError` (a ``ValueError`` and a
``MemoryError``) with a one-line message when the first exceeds the second, e.g.::

    needs about 31.2 GiB for 8000x8000 with tvl1, 12.1 GiB available; downscale or crop

The environment variable ``VARFLOW_MEMORY_LIMIT`` (bytes, or a number with a unit
such as ``512M``, ``8G``, ``1.5GiB``) replaces the measured available memory;
``0``, ``none`` or ``off`` disables the check.

How the factors were measured
-----------------------------
Peak resident memory of one call in a fresh process (Linux ``VmHWM`` after
resetting it with ``/proc/self/clear_refs`` once the kernels were loaded from Numba's
cache on a small input), minus the resident memory before the call; ``uint8`` inputs
created before the baseline, default parameters, ``NUMBA_NUM_THREADS=1``
(``benchmarks/bench_memory.py``).  Two-frame methods at 256x320 and 512x640 grey and
256x320 RGB; trackers at 128x160 and 256x320 with 5 frames, 128x160 with 9 frames and
128x160 RGB with 5 frames.  Measured peaks, bytes per pixel:

================  ============  ============  ============
method            256x320       512x640       RGB 256x320
================  ============  ============  ============
tvl1              195           203           207
tvl1-fast         161           169           188
tvl1-ld           478           486           524
tensor            194           205           312
sparse-1d         417           315           547
sparse-2d         365           333           470
sparse-2x1d       287           272           417
sparse-dct        403           308           496
tvl1-tensor       245           247           240
tvl1-sparse-1d    461           365           470
tvl1-sparse-2d    425           373           415
tvl1-sparse-2x1d  335           312           365
tvl1-sparse-dct   431           359           432
================  ============  ============  ============

=============  ============  ============  ============  ============
tracker        128x160 F=5   256x320 F=5   128x160 F=9   RGB 128x160 F=5
=============  ============  ============  ============  ============
rlr            728           765           1303          1046
mfsf           681           812           1219          933
chain          141           175           195           345
twoframe       154           176           207           352
=============  ============  ============  ============  ============

The trackers' figures were taken with their earlier default energy (colour channels),
with the JIT compiling in the measuring process; ``bench_memory.py`` re-measures them.
The model fitted to them is ``fixed + pixels * (base + per_frame * F +
per_channel * (C - 1) * F')`` with ``F' = 1`` for two-frame methods and ``F' = F``
for trackers (each registry entry's :class:`~varflow.registry.MemoryFactors`),
times a safety margin :data:`MARGIN`.  The
sparse methods carry up to 11 MiB that does not grow with the image (dictionary,
Gram matrices), hence their higher cost per pixel on small images.
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .registry import FLOW, TRACK, Entry, MemoryFactors

__all__ = [
    "ENV_VAR",
    "InsufficientMemoryError",
    "MemoryFactors",
    "available_bytes",
    "check_memory",
    "estimate_bytes",
]

log = logging.getLogger(__name__)

#: Environment variable that overrides the available memory (``0``/``off``: no check).
ENV_VAR = "VARFLOW_MEMORY_LIMIT"

_MIB = 2**20
_GIB = 2**30


#: Used for a method without measured factors: the largest of each kind.
_FALLBACK = {
    "flow": MemoryFactors(base=490, per_channel=80, fixed=16 * _MIB),
    "track": MemoryFactors(base=145, per_frame=145, per_channel=32),
}
#: Multiplies every estimate: allocator slack, run-to-run variation, other parameters.
MARGIN = 1.25


class InsufficientMemoryError(ValueError, MemoryError):
    """The estimated memory of a run exceeds the memory available (raised before it)."""


def _name(method_or_kind: Any) -> str:
    return str(getattr(method_or_kind, "name", method_or_kind))


def _is_tracker(name: str) -> bool:
    if name == "track":
        return True
    if name == "flow":
        return False
    return name in TRACK


def _factors(method_or_kind: Any, name: str, tracker: bool) -> MemoryFactors:
    """The entry's :class:`~varflow.registry.MemoryFactors`, else the largest of its kind."""
    entry = method_or_kind if isinstance(method_or_kind, Entry) else \
        (TRACK if tracker else FLOW).get(name)
    memory = getattr(entry, "memory", None)
    return memory if memory is not None else _FALLBACK["track" if tracker else "flow"]


def estimate_bytes(
    method_or_kind: Any,
    shape: Sequence[int],
    n_frames: int = 2,
    params: Any = None,
) -> int:
    """Estimated peak memory of one run, in bytes.

    Parameters
    ----------
    method_or_kind : str or registry entry
        A two-frame method (``"tvl1"``...), a tracker (``"rlr"``...), a
        :class:`~varflow.registry.Method` / :class:`~varflow.registry.Tracker`, or
        the kind ``"flow"`` / ``"track"`` (the most expensive method of that kind).
    shape : sequence of int
        Frame shape ``(H, W)`` or ``(H, W, C)``.
    n_frames : int
        Number of frames (2 for a two-frame method).
    params : dataclass, optional
        The run's parameters.  The factors were measured with the defaults; the
        estimate does not depend on them yet (the margin covers usual settings).

    Returns
    -------
    int
        Bytes, including :data:`MARGIN`.
    """
    del params  # reserved: the measured factors are those of the default parameters
    name = _name(method_or_kind)
    tracker = _is_tracker(name)
    factors = _factors(method_or_kind, name, tracker)
    dims = tuple(int(s) for s in shape)
    if len(dims) not in (2, 3):
        raise ValueError(f"estimate_bytes: shape must be (H, W) or (H, W, C), got {dims}")
    h, w = dims[:2]
    c = dims[2] if len(dims) == 3 else 1
    pixels = max(h, 0) * max(w, 0)
    f = max(int(n_frames), 2)
    per_pixel = factors.base + factors.per_frame * f
    per_pixel += factors.per_channel * max(c - 1, 0) * (f if tracker else 1)
    return int(math.ceil(MARGIN * (factors.fixed + pixels * per_pixel)))


_UNITS = {
    "": 1, "b": 1,
    "k": 2**10, "kb": 10**3, "kib": 2**10,
    "m": 2**20, "mb": 10**6, "mib": 2**20,
    "g": 2**30, "gb": 10**9, "gib": 2**30,
    "t": 2**40, "tb": 10**12, "tib": 2**40,
}  # fmt: skip
_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([a-zA-Z]*)\s*$")


def parse_size(text: str) -> int:
    """Parse ``"512M"``, ``"8G"``, ``"1.5GiB"``, ``"1000000"`` into bytes (K/M/G are binary).

    Raises
    ------
    ValueError
        If ``text`` is not a size.
    """
    m = _SIZE.match(text)
    unit = m.group(2).lower() if m else ""
    if m is None or unit not in _UNITS:
        raise ValueError(f"{ENV_VAR}: expected a size such as 8G or 512M, got {text!r}")
    return int(float(m.group(1)) * _UNITS[unit])


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _stat_value(path: Path, key: str) -> int:
    try:
        for line in path.read_text().splitlines():
            name, _, value = line.partition(" ")
            if name == key and value.strip().isdigit():
                return int(value)
    except OSError:
        pass
    return 0


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_available(root: Path = Path("/sys/fs/cgroup")) -> int | None:
    """Room left under a cgroup memory limit (v2, else v1); None without a limit."""
    limit = _read_int(root / "memory.max")  # v2; "max" (no limit) reads as None
    if limit is not None:
        used = _read_int(root / "memory.current")
        stat = root / "memory.stat"
    else:
        v1 = root / "memory"
        limit = _read_int(v1 / "memory.limit_in_bytes")
        if limit is None or limit >= 2**60:  # v1 reports "no limit" as ~2**63
            return None
        used = _read_int(v1 / "memory.usage_in_bytes")
        stat = v1 / "memory.stat"
    if used is None:
        return None
    reclaimable = _stat_value(stat, "inactive_file") or _stat_value(stat, "total_inactive_file")
    return max(limit - used + reclaimable, 0)


def available_bytes() -> int | None:
    """Memory this process may still use, in bytes; None if unknown.

    ``VARFLOW_MEMORY_LIMIT`` when set (``0``, ``none``, ``off``: None, i.e. no
    check); otherwise the smaller of ``MemAvailable`` (``/proc/meminfo``) and the
    room under a cgroup limit (``/sys/fs/cgroup/memory.max`` or the v1
    ``memory.limit_in_bytes``), falling back to ``psutil`` when neither exists.

    Raises
    ------
    ValueError
        If ``VARFLOW_MEMORY_LIMIT`` is set but is not a size.
    """
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        if env.lower() in ("0", "none", "off", "no"):
            return None
        return parse_size(env)
    known = [v for v in (_meminfo_available(), _cgroup_available()) if v is not None]
    if known:
        return min(known)
    try:
        import psutil  # optional
    except ImportError:
        return None
    try:
        return int(psutil.virtual_memory().available)
    except Exception:  # noqa: BLE001 - psutil on an exotic platform: unknown
        return None


def _gib(n: float) -> str:
    if n >= 0.1 * _GIB:
        return f"{n / _GIB:.1f} GiB"
    return f"{n / _MIB:.0f} MiB" if n >= _MIB else f"{n / 1024:.0f} KiB"


def check_memory(
    method_or_kind: Any,
    shape: Sequence[int],
    n_frames: int = 2,
    params: Any = None,
) -> int:
    """Raise before a run whose estimated memory exceeds the available memory.

    Parameters
    ----------
    method_or_kind, shape, n_frames, params
        As in :func:`estimate_bytes`.

    Returns
    -------
    int
        The estimate, bytes.

    Raises
    ------
    InsufficientMemoryError
        A ``ValueError`` (and ``MemoryError``) with a one-line message such as
        ``"needs about 31.2 GiB for 8000x8000 with tvl1, 12.1 GiB available;
        downscale or crop"``.  Nothing is raised when the available memory is
        unknown.
    """
    need = estimate_bytes(method_or_kind, shape, n_frames, params)
    have = available_bytes()
    if have is not None and need > have:
        h, w = (int(s) for s in tuple(shape)[:2])
        frames = f" x {int(n_frames)} frames" if _is_tracker(_name(method_or_kind)) else ""
        raise InsufficientMemoryError(
            f"needs about {_gib(need)} for {w}x{h}{frames} with {_name(method_or_kind)}, "
            f"{_gib(have)} available; downscale or crop"
        )
    log.debug("memory: about %s needed, %s available", _gib(need),
              "unknown" if have is None else _gib(have))
    return need
