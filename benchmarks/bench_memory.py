"""Peak memory of one ``varflow.flow`` / ``varflow.track`` call, in bytes per pixel.

Usage::

    python benchmarks/bench_memory.py [--methods tvl1,rlr,...] [--quick] [--repeat N]

Follows the protocol of :mod:`varflow._memory` (the source of the registered
:class:`~varflow.registry.MemoryFactors`).  Every measurement runs in a fresh Python
process (this script with a hidden ``--child`` flag) with ``NUMBA_NUM_THREADS=1`` and
``VARFLOW_MEMORY_LIMIT=off``.  The child creates the ``uint8`` frames (seeded smoothed
noise, shifted by one pixel per frame so that the flow is real), runs the method once
on a 64x80 input of the same kind (Numba loads its kernels), resets the peak resident
memory (``/proc/self/clear_refs``), reads ``VmRSS`` as the baseline, runs the measured
call with the default parameters and reads ``VmHWM``.  Reported: ``(VmHWM - baseline)
/ (H * W)``, bytes per pixel of one frame.  Before its cases, each method runs once in
a process of its own that only fills Numba's cache: a compilation in the measuring
process would leave freed heap that the measured call reuses (a lower peak).  Linux
only.

Cases: two-frame methods (:data:`varflow.registry.FLOW`) at 256x320 and 512x640 grey
and 256x320 RGB; trackers (:data:`varflow.registry.TRACK`) at 128x160 and 256x320 with
5 frames, 128x160 with 9 frames and 128x160 RGB with 5 frames.  ``--quick`` measures
only the first case of each kind (no fit).  ``--repeat N`` measures every case N
times (N processes) and keeps the median: the peak varies by a few per cent from
one process to the next.

Prints to stdout the table of bytes per pixel, then for each method its registered
``MemoryFactors`` and the ones fitted to the measurements:

* two-frame methods: ``base`` = grey at 512x640, ``per_channel`` = (RGB - grey at
  256x320) / 2; the line through the two grey sizes (``slope`` and ``fixed``: bytes
  that do not grow with the image) is printed too, and when ``fixed`` is over 2 MiB the
  proposal takes ``base`` = slope and ``fixed`` rounded to MiB;
* trackers: ``base + per_frame * F`` through the two grey values at 128x160 (F = 5, 9),
  ``per_channel`` = (RGB - grey) / (2 F); also ``base`` solved at 256x320 F = 5.

The proposal rounds ``base`` and a two-frame ``per_channel`` up to a multiple of
5 bytes, a tracker's ``per_frame`` and ``per_channel`` up to a byte.  Progress goes to
stderr.  Memory, not time, is measured: other jobs on the machine do not matter much
(the sparse methods take a few minutes at 512x640).
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import statistics
import subprocess
import sys
import time

MIB = 2**20
WARMUP_SHAPE = (64, 80)
SEED = 20260101

#: (label, (H, W), channels, frames) of the two kinds, in table order.
FLOW_CASES = [
    ("256x320", (256, 320), 1, 2),
    ("512x640", (512, 640), 1, 2),
    ("RGB 256x320", (256, 320), 3, 2),
]
TRACK_CASES = [
    ("128x160 F=5", (128, 160), 1, 5),
    ("256x320 F=5", (256, 320), 1, 5),
    ("128x160 F=9", (128, 160), 1, 9),
    ("RGB 128x160 F=5", (128, 160), 3, 5),
]


# ----------------------------------------------------------------------------- child


def _status(*keys: str) -> dict[str, int]:
    """Fields of /proc/self/status in bytes (e.g. VmRSS, VmHWM)."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            name, _, value = line.partition(":")
            if name in keys:
                out[name] = int(value.split()[0]) * 1024  # kB
    return out


def make_frames(shape: tuple[int, int], channels: int, n_frames: int, seed: int = SEED):
    """``(n_frames, H, W[, C])`` uint8: smoothed noise moving by (1, 1) px per frame."""
    import numpy as np
    from scipy.ndimage import gaussian_filter

    h, w = shape
    rng = np.random.default_rng(seed)
    size = (h + n_frames, w + n_frames) + ((channels,) if channels > 1 else ())
    sigma = (1.5, 1.5) + ((0.0,) if channels > 1 else ())
    tex = gaussian_filter(rng.random(size), sigma)
    tex = (255 * (tex - tex.min()) / (tex.max() - tex.min())).round().astype(np.uint8)
    # frame k sees the texture moved by k px right and down
    frames = np.stack([tex[n_frames - k:n_frames - k + h, n_frames - k:n_frames - k + w]
                       for k in range(n_frames)])
    return np.ascontiguousarray(frames)


def _run(kind: str, method: str, frames):
    import varflow

    if kind == "flow":
        return varflow.flow(frames[0], frames[1], method)
    return varflow.track(frames, method=method)


def child(spec: dict) -> dict:
    """One measurement in this (fresh) process; returns the figures."""
    kind, method = spec["kind"], spec["method"]
    shape, channels, n_frames = tuple(spec["shape"]), spec["channels"], spec["frames"]
    small = make_frames(WARMUP_SHAPE, channels, n_frames, seed=SEED + 1)
    if spec.get("prime"):  # only fill Numba's cache
        _run(kind, method, small)
        return {}
    frames = make_frames(shape, channels, n_frames)
    t0 = time.perf_counter()
    out = _run(kind, method, small)  # compile / load the kernels
    warmup = time.perf_counter() - t0
    del out, small
    gc.collect()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset VmHWM to the current VmRSS
    baseline = _status("VmRSS")["VmRSS"]
    t0 = time.perf_counter()
    out = _run(kind, method, frames)
    seconds = time.perf_counter() - t0
    hwm = _status("VmHWM")["VmHWM"]
    pixels = shape[0] * shape[1]
    return {"bytes_per_pixel": (hwm - baseline) / pixels, "peak_bytes": hwm - baseline,
            "baseline_bytes": baseline, "seconds": seconds, "warmup_seconds": warmup,
            "out_shape": list(out.shape)}


# ---------------------------------------------------------------------------- parent


def measure(kind: str, method: str, shape: tuple[int, int], channels: int,
            n_frames: int, prime: bool = False) -> dict | None:
    """Run :func:`child` in a fresh interpreter; None (and the error on stderr) if it fails.

    ``prime``: only run the small call, so that Numba's cache holds the kernels (a
    compilation inside the measuring process would leave freed heap that the measured
    call reuses, and lower its peak)."""
    spec = {"kind": kind, "method": method, "shape": list(shape), "channels": channels,
            "frames": n_frames, "prime": prime}
    return run_child(__file__, spec, NUMBA_NUM_THREADS="1")


def run_child(script: str, spec: dict, **env: str) -> dict | None:
    """Run ``script --child JSON(spec)`` in a fresh interpreter with ``env`` added to
    the environment (and ``VARFLOW_MEMORY_LIMIT=off``); the JSON of its last stdout
    line, or None (and the error on stderr) if it fails."""
    env = dict(os.environ, VARFLOW_MEMORY_LIMIT="off", **env)
    proc = subprocess.run([sys.executable, os.path.abspath(script), "--child",
                           json.dumps(spec)], env=env, capture_output=True, text=True)
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        print(f"  FAILED ({proc.returncode}): {proc.stderr.strip()[-2000:]}", file=sys.stderr)
        return None
    return json.loads(lines[-1])


def _ceil(x: float, step: float) -> float:
    return max(0, math.ceil(x / step - 1e-9) * step)


def _fmt(x: float) -> str:
    return f"{x:.0f}" if float(x).is_integer() else f"{x:.1f}"


def _factors_repr(base: float, per_frame: float = 0.0, per_channel: float = 0.0,
                  fixed: float = 0.0) -> str:
    parts = [f"base={_fmt(base)}"]
    if per_frame:
        parts.append(f"per_frame={_fmt(per_frame)}")
    if per_channel:
        parts.append(f"per_channel={_fmt(per_channel)}")
    if fixed:
        mib = fixed / MIB
        parts.append(f"fixed={mib:.0f} * _MIB" if mib.is_integer() else f"fixed={mib:.1f} MiB")
    return f"MemoryFactors({', '.join(parts)})"


def fit_flow(bpp: dict[str, float | None]) -> list[str]:
    """Lines describing the factors fitted to a two-frame method's measurements."""
    g1, g2, rgb = (bpp.get(label) for label, *_ in FLOW_CASES)
    if g1 is None or g2 is None or rgb is None:
        return ["fitted: n/a (needs all three cases)"]
    p1 = FLOW_CASES[0][1][0] * FLOW_CASES[0][1][1]
    p2 = FLOW_CASES[1][1][0] * FLOW_CASES[1][1][1]
    slope = (g2 * p2 - g1 * p1) / (p2 - p1)
    fixed = g1 * p1 - slope * p1
    per_channel = (rgb - g1) / 2
    raw = f"fitted: base={g2:.1f} per_channel={per_channel:.1f} " \
          f"(line through the grey sizes: slope={slope:.1f} B/px, fixed={fixed / MIB:.1f} MiB)"
    if fixed > 2 * MIB:
        proposal = _factors_repr(_ceil(slope, 5), per_channel=_ceil(per_channel, 5),
                                 fixed=round(fixed / MIB) * MIB)
    else:
        proposal = _factors_repr(_ceil(g2, 5), per_channel=_ceil(per_channel, 5))
    return [raw, f"proposed: {proposal}"]


def fit_track(bpp: dict[str, float | None]) -> list[str]:
    """Lines describing the factors fitted to a tracker's measurements."""
    b5, b5_large, b9, rgb = (bpp.get(label) for label, *_ in TRACK_CASES)
    if b5 is None or b9 is None or rgb is None:
        return ["fitted: n/a (needs 128x160 F=5, F=9 and RGB)"]
    f5, f9 = TRACK_CASES[0][3], TRACK_CASES[2][3]
    per_frame = (b9 - b5) / (f9 - f5)
    base = b5 - per_frame * f5
    per_channel = (rgb - b5) / (2 * f5)
    raw = f"fitted: base={base:.1f} per_frame={per_frame:.1f} per_channel={per_channel:.1f}"
    if b5_large is not None:
        raw += f" (base at 256x320 F=5: {b5_large - per_frame * f5:.1f})"
    proposal = _factors_repr(_ceil(base, 5), per_frame=_ceil(per_frame, 1),
                             per_channel=_ceil(per_channel, 1))
    return [raw, f"proposed: {proposal}"]


def main(argv: list[str] | None = None) -> int:
    """Measure, print the table and the fitted factors; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--methods", help="comma-separated names (default: every registered "
                        "two-frame and trajectory method)")
    parser.add_argument("--quick", action="store_true",
                        help="only the first case of each kind (no fit)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="processes per case; the median is kept (default 1)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.child:
        print(json.dumps(child(json.loads(args.child))), flush=True)
        return 0

    from varflow.registry import FLOW, TRACK

    names = args.methods.split(",") if args.methods else FLOW.names() + TRACK.names()
    names = [n.strip() for n in names if n.strip()]
    unknown = [n for n in names if n not in FLOW and n not in TRACK]
    if unknown:
        parser.error(f"unknown methods: {', '.join(unknown)}; available: "
                     f"{', '.join(FLOW.names() + TRACK.names())}")
    flow_cases = FLOW_CASES[:1] if args.quick else FLOW_CASES
    track_cases = TRACK_CASES[:1] if args.quick else TRACK_CASES

    results: dict[str, dict[str, float | None]] = {}
    for name in names:
        kind, cases = ("flow", flow_cases) if name in FLOW else ("track", track_cases)
        results[name] = {}
        for channels, n_frames in sorted({(c[2], c[3]) for c in cases}):
            print(f"{name}: priming Numba's cache (C={channels}, F={n_frames})",
                  file=sys.stderr, flush=True)
            measure(kind, name, WARMUP_SHAPE, channels, n_frames, prime=True)
        for label, shape, channels, n_frames in cases:
            print(f"{name} {label} ...", file=sys.stderr, flush=True)
            values = []
            for _ in range(max(1, args.repeat)):
                r = measure(kind, name, shape, channels, n_frames)
                if r is None:
                    continue
                values.append(r["bytes_per_pixel"])
                print(f"  {r['bytes_per_pixel']:.0f} B/px ({r['peak_bytes'] / MIB:.1f} MiB "
                      f"over a {r['baseline_bytes'] / MIB:.0f} MiB baseline), "
                      f"{r['seconds']:.1f} s (warm-up {r['warmup_seconds']:.1f} s)",
                      file=sys.stderr, flush=True)
            results[name][label] = statistics.median(values) if values else None

    def cell(x: float | None) -> str:
        return "failed" if x is None else f"{x:.0f}"

    for kind, registry, cases in (("flow", FLOW, flow_cases), ("track", TRACK, track_cases)):
        chosen = [n for n in names if n in registry]
        if not chosen:
            continue
        width = max(len("tracker"), *(len(n) for n in chosen))
        header = ["method" if kind == "flow" else "tracker"] + [c[0] for c in cases]
        widths = [width] + [max(len(c[0]), 6) for c in cases]
        print()
        print("Peak memory, bytes per pixel (two-frame methods)" if kind == "flow"
              else "Peak memory, bytes per pixel of one frame (trackers)")
        print("  ".join(h.ljust(w) if i == 0 else h.rjust(w)
                        for i, (h, w) in enumerate(zip(header, widths, strict=True))))
        for n in chosen:
            row = [n] + [cell(results[n].get(c[0])) for c in cases]
            print("  ".join(v.ljust(w) if i == 0 else v.rjust(w)
                            for i, (v, w) in enumerate(zip(row, widths, strict=True))))

    print()
    print("Memory factors (bytes per pixel)")
    for n in names:
        kind_registry = FLOW if n in FLOW else TRACK
        print(f"{n}:")
        print(f"  registered: {kind_registry[n].memory}")
        if args.quick:
            continue
        fit = fit_flow if n in FLOW else fit_track
        for line in fit(results[n]):
            print(f"  {line}")
    return 0 if all(v is not None for r in results.values() for v in r.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
