"""Speed and accuracy of varflow's TV-L1 against OpenCV and scikit-image on Middlebury.

Usage::

    pip install -e ".[bench]"
    python benchmarks/bench_speed_middlebury.py [--data DIR] [--repeats 3] [--sequences Venus ...]

In one process, for each of the 8 Middlebury pairs with public ground truth
(frame10 -> frame11):

* varflow ``tvl1`` with its default parameters on the colour frames;
* OpenCV ``cv2.optflow.DualTVL1OpticalFlow_create()`` with its defaults on the grey
  frames (uint8);
* scikit-image ``skimage.registration.optical_flow_tvl1`` with its defaults on the
  grey frames (float in [0, 1]); it returns ``(v, u)``, converted here to varflow's
  ``(..., [u, v])`` layout.

One warm-up call of varflow on the first pair runs before any timing (Numba JIT
compilation and cache loading) and is excluded.  Each engine then runs ``--repeats``
times per pair; the median wall time is reported together with the AEE of each
engine, the ratios varflow/OpenCV and varflow/skimage, a totals row (sums of the
medians, mean AEE) and whether the varflow total is at most half the OpenCV total.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np


def _grey_u8(rgb: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)


def _median_seconds(
    fn: Callable[[np.ndarray, np.ndarray], np.ndarray], a: np.ndarray, b: np.ndarray, repeats: int
) -> tuple[float, np.ndarray]:
    """Median wall time of ``fn(a, b)`` over ``repeats`` calls, and the last result."""
    times = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn(a, b)
        times.append(time.perf_counter() - t0)
    assert out is not None
    return statistics.median(times), out


def main(argv: list[str] | None = None) -> int:
    """Run the comparison and print the table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", help="data folder (default $VARFLOW_DATA or ../shared/data)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per engine and pair")
    parser.add_argument("--sequences", nargs="+", help="subset of the 8 sequences (smoke tests)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")

    import cv2
    import numba
    from skimage.registration import optical_flow_tvl1

    import varflow
    from varflow.evaluation.datasets import (
        MIDDLEBURY_SEQUENCES,
        data_root,
        load_middlebury_pair,
        middlebury_sequence,
    )
    from varflow.evaluation.metrics import evaluate

    try:
        seqs = [middlebury_sequence(s) for s in (args.sequences or MIDDLEBURY_SEQUENCES)]
        root = data_root(args.data)
        pairs = {s: load_middlebury_pair(s, root) for s in seqs}
    except (ValueError, OSError) as exc:
        print(f"bench_speed_middlebury: error: {exc}", file=sys.stderr)
        return 2

    import skimage

    print(f"data: {root}")
    print(f"varflow {varflow.__version__} (numba {numba.__version__}, "
          f"numba.get_num_threads() = {numba.get_num_threads()}); "
          f"OpenCV {cv2.__version__} (cv2.getNumThreads() = {cv2.getNumThreads()}); "
          f"scikit-image {skimage.__version__}")
    print(f"repeats per engine and pair: {args.repeats} (median reported); all defaults; "
          "varflow on colour frames, OpenCV and skimage on grey frames")

    f0, f1, _ = pairs[seqs[0]]
    t0 = time.perf_counter()
    varflow.flow(f0, f1, "tvl1")
    print(f"warm-up: one varflow call on {seqs[0]} ({time.perf_counter() - t0:.2f} s, "
          "JIT compilation / cache loading), excluded from the timings")
    print()

    def run_varflow(f0: np.ndarray, f1: np.ndarray) -> np.ndarray:
        return varflow.flow(f0, f1, "tvl1")

    def run_opencv(g0: np.ndarray, g1: np.ndarray) -> np.ndarray:
        tvl1 = cv2.optflow.DualTVL1OpticalFlow_create()
        return tvl1.calc(g0, g1, None)

    def run_skimage(g0: np.ndarray, g1: np.ndarray) -> np.ndarray:
        v, u = optical_flow_tvl1(g0.astype(np.float32) / 255.0, g1.astype(np.float32) / 255.0)
        return np.stack([u, v], axis=-1).astype(np.float32)  # (v, u) -> (..., [u, v])

    head = (f"{'sequence':<12} {'varflow s':>9} {'opencv s':>9} {'skimage s':>9} "
            f"{'vf/cv':>6} {'vf/sk':>6} {'varflow AEE':>11} {'opencv AEE':>10} "
            f"{'skimage AEE':>11}")
    print(head)
    print("-" * len(head))
    tot = {"varflow": 0.0, "opencv": 0.0, "skimage": 0.0}
    aees: dict[str, list[float]] = {k: [] for k in tot}
    for s in seqs:
        f0, f1, gt = pairs[s]
        g0, g1 = _grey_u8(f0), _grey_u8(f1)
        res = {
            "varflow": _median_seconds(run_varflow, f0, f1, args.repeats),
            "opencv": _median_seconds(run_opencv, g0, g1, args.repeats),
            "skimage": _median_seconds(run_skimage, g0, g1, args.repeats),
        }
        sec = {k: v[0] for k, v in res.items()}
        aee = {k: evaluate(v[1], gt)["aee"] for k, v in res.items()}
        for k in tot:
            tot[k] += sec[k]
            aees[k].append(aee[k])
        print(f"{s:<12} {sec['varflow']:9.2f} {sec['opencv']:9.2f} {sec['skimage']:9.2f} "
              f"{sec['varflow'] / sec['opencv']:6.2f} {sec['varflow'] / sec['skimage']:6.2f} "
              f"{aee['varflow']:11.4f} {aee['opencv']:10.4f} {aee['skimage']:11.4f}",
              flush=True)
    print("-" * len(head))
    mean = {k: float(np.mean(v)) for k, v in aees.items()}
    print(f"{'total/mean':<12} {tot['varflow']:9.2f} {tot['opencv']:9.2f} {tot['skimage']:9.2f} "
          f"{tot['varflow'] / tot['opencv']:6.2f} {tot['varflow'] / tot['skimage']:6.2f} "
          f"{mean['varflow']:11.4f} {mean['opencv']:10.4f} {mean['skimage']:11.4f}")
    print("(times: sums of per-pair medians; AEE: mean over the pairs)")
    ok = tot["varflow"] <= 0.5 * tot["opencv"]
    print(f"varflow total {tot['varflow']:.2f} s {'<=' if ok else '>'} 0.5 x OpenCV total "
          f"{tot['opencv']:.2f} s ({0.5 * tot['opencv']:.2f} s): {'YES' if ok else 'NO'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
