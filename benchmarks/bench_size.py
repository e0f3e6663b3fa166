"""Cost of one two-frame flow against image size: seconds and peak memory per megapixel.

Usage::

    python benchmarks/bench_size.py [--method tvl1] [--rounds 3] [--sizes 240p,1mp,4k]
                                    [--grey] [--csv out.csv]

The pair is frames 0 and 1 of the ``restoration/bigbuckbunny`` clip (960x540 RGB, real
footage) under the data root (``$VARFLOW_DATA``, default ``../shared/data``), resized to
each size of the ladder with OpenCV (``INTER_AREA`` down, ``INTER_CUBIC`` up): from
0.1 MP (426x240) to 8.3 MP (3840x2160, a 4K pair).  The 1 MP row (1336x752) is the
reference of the "per MP against 1 MP" column.  An up-scaled pair has the scene's
motion scaled with it (four times the pixels of motion at 4K as at 960x540), so the
coarse-to-fine pyramid gets the levels it would get on native footage of that size.

Every measurement runs in a fresh Python process (this script with a hidden
``--child`` flag) with the default thread count and ``VARFLOW_MEMORY_LIMIT=off``: the
child resizes the pair, runs the method once on the 240p pair (Numba loads its kernels
from the cache, which a priming process fills first), resets the peak resident memory
(``/proc/self/clear_refs``), reads ``VmRSS`` as the baseline, times one
``varflow.flow`` call with the default parameters and reads ``VmHWM``.  The sizes are
interleaved: round 1 runs every size once, then round 2, ...; the table quotes the
median over the rounds of the seconds and of the peak (the peak above the baseline,
and the process's whole peak).  Linux only.

Prints the table to stdout (markdown), progress to stderr.
"""

from __future__ import annotations

import argparse
import csv
import gc
import json
import os
import statistics
import sys
import time
from pathlib import Path

from bench_memory import _status, run_child

MIB = 2**20
GIB = 2**30

#: (label, (width, height)) of the ladder, smallest first.
SIZES = [
    ("240p", (426, 240)),
    ("360p", (640, 360)),
    ("540p", (960, 540)),
    ("1mp", (1336, 752)),
    ("1080p", (1920, 1080)),
    ("1440p", (2560, 1440)),
    ("4k", (3840, 2160)),
]
REFERENCE = "1mp"
CLIP = Path("restoration") / "bigbuckbunny"


def data_root() -> Path:
    """The benchmark data root: ``$VARFLOW_DATA`` or ``../shared/data``."""
    return Path(os.environ.get("VARFLOW_DATA", "../shared/data"))


def load_pair(size: tuple[int, int], grey: bool):
    """Frames 0 and 1 of the clip resized to ``size`` = (W, H): two uint8 arrays."""
    import cv2
    import numpy as np

    folder = data_root() / CLIP
    out = []
    for name in ("frame_0000.png", "frame_0001.png"):
        path = folder / name
        img = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise SystemExit(f"bench_size: cannot read {path} (set VARFLOW_DATA)")
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if grey else cv2.COLOR_BGR2RGB)
        h, w = img.shape[:2]
        interp = cv2.INTER_AREA if size[0] * size[1] < w * h else cv2.INTER_CUBIC
        out.append(np.ascontiguousarray(cv2.resize(img, size, interpolation=interp)))
    return out


# ----------------------------------------------------------------------------- child


def child(spec: dict) -> dict:
    """One timed call in this (fresh) process; returns its figures."""
    import varflow

    method, grey = spec["method"], spec["grey"]
    small = load_pair(dict(SIZES)["240p"], grey)
    if spec.get("prime"):
        varflow.flow(*small, method)
        return {}
    pair = load_pair(tuple(spec["size"]), grey)
    varflow.flow(*small, method)  # load the kernels
    del small
    gc.collect()
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # VmHWM := VmRSS
    baseline = _status("VmRSS")["VmRSS"]
    t0 = time.perf_counter()
    flow = varflow.flow(*pair, method)
    seconds = time.perf_counter() - t0
    hwm = _status("VmHWM")["VmHWM"]
    return {"seconds": seconds, "peak_bytes": hwm - baseline, "hwm_bytes": hwm,
            "finite": bool(flow.size and float(abs(flow).max()) < 1e6)}


# ---------------------------------------------------------------------------- parent


def measure(spec: dict) -> dict | None:
    """Run :func:`child` in a fresh interpreter (default threads); None if it fails."""
    return run_child(__file__, spec)


def table(rows: list[dict]) -> list[str]:
    """Markdown lines of the per-size medians."""
    ref = next((r for r in rows if r["label"] == REFERENCE), None)
    lines = ["| size | MP | seconds | s per MP | per MP / 1 MP | peak above baseline, MiB "
             "| bytes per pixel | process peak, GiB |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        rel = f"{r['s_per_mp'] / ref['s_per_mp']:.2f}" if ref else "n/a"
        lines.append(f"| {r['w']}x{r['h']} | {r['mp']:.2f} | {r['seconds']:.2f} | "
                     f"{r['s_per_mp']:.2f} | {rel} | {r['peak_bytes'] / MIB:.0f} | "
                     f"{r['peak_bytes'] / (r['w'] * r['h']):.0f} | "
                     f"{r['hwm_bytes'] / GIB:.2f} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="tvl1", help="a two-frame method (default tvl1)")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (default 3)")
    ap.add_argument("--sizes", default=",".join(label for label, _ in SIZES),
                    help="comma-separated labels of the ladder (default: all)")
    ap.add_argument("--grey", action="store_true", help="grey frames instead of RGB")
    ap.add_argument("--csv", type=Path, help="write every measurement to this CSV")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(json.loads(args.child))))
        return 0
    known = dict(SIZES)
    labels = [s.strip() for s in args.sizes.split(",") if s.strip()]
    bad = [s for s in labels if s not in known]
    if bad:
        ap.error(f"unknown size(s) {bad}; choose from {list(known)}")
    labels = [label for label, _ in SIZES if label in labels]  # ladder order
    base = {"method": args.method, "grey": args.grey}
    print(f"priming the Numba cache ({args.method})", file=sys.stderr)
    if measure(dict(base, prime=True)) is None:
        return 1
    runs: dict[str, list[dict]] = {label: [] for label in labels}
    for k in range(args.rounds):
        for label in labels:
            res = measure(dict(base, size=list(known[label])))
            if res is None:
                return 1
            runs[label].append(res)
            print(f"round {k + 1}/{args.rounds} {label}: {res['seconds']:.2f} s, "
                  f"peak {res['peak_bytes'] / MIB:.0f} MiB", file=sys.stderr)
    rows = []
    for label in labels:
        w, h = known[label]
        mp = w * h / 1e6
        med = {key: statistics.median(r[key] for r in runs[label])
               for key in ("seconds", "peak_bytes", "hwm_bytes")}
        rows.append(dict(label=label, w=w, h=h, mp=mp, s_per_mp=med["seconds"] / mp,
                         finite=all(r["finite"] for r in runs[label]), **med))
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            wr = csv.writer(f)
            wr.writerow(["size", "round", "seconds", "peak_bytes", "hwm_bytes"])
            for label in labels:
                for k, r in enumerate(runs[label]):
                    wr.writerow([label, k + 1, f"{r['seconds']:.4f}", r["peak_bytes"],
                                 r["hwm_bytes"]])
    mode = "grey" if args.grey else "RGB"
    print(f"`{args.method}`, {mode}, medians of {args.rounds} interleaved rounds, "
          f"{os.cpu_count()} CPUs\n")
    print("\n".join(table(rows)))
    if not all(r["finite"] for r in rows):
        print("\nwarning: a flow had non-finite or huge values", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
