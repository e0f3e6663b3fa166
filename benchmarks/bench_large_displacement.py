"""Large displacements: ``tvl1-ld`` against ``tvl1``, OpenCV DIS and DeepFlow, and its stages.

Part 1 runs :func:`varflow.evaluation.bench.twoframe.run_twoframe` on the large-motion
sets (the generator's pairs of :mod:`varflow.generators.large_pairs`, reporting split
by default, and the MPI-Sintel pairs with mean motion above 10 px) and on Middlebury
(where the motion is small and the large-displacement mode must cost nothing), with the
peers in the same process, and prints one table per set (AEE, AEE over non-occluded
pixels, seconds).

Part 2 times ``tvl1-ld`` on each 1024x436 Sintel pair, ``--repeats`` times, and prints
the median seconds of each stage (matching, interpolation, fusion, the coarse-to-fine
TV-L1 without the fusion) and its share of the total.

Run on an otherwise idle machine::

    python benchmarks/bench_large_displacement.py [--data DIR] [--split reporting]
        [--repeats 3] [--skip-table]
"""

from __future__ import annotations

import argparse
import statistics
import time

from varflow.evaluation.bench.twoframe import (
    SINTEL_LARGE_PAIRS,
    format_twoframe_table,
    run_twoframe,
    sintel_pairs_present,
)
from varflow.evaluation.datasets import data_root, load_sintel_pair
from varflow.twoframe.large_displacement import tvl1_ld
from varflow.twoframe.params import preset


def stage_table(root, repeats: int) -> str:
    """Median seconds per stage of ``tvl1-ld`` on each large-motion Sintel pair."""
    params = preset("tvl1-ld")
    pairs = sintel_pairs_present(root, SINTEL_LARGE_PAIRS)[0]
    clip, pass_, n = pairs[0]
    f0, f1, *_ = load_sintel_pair(clip, n, pass_, root)
    tvl1_ld(f0, f1, params)  # JIT warm-up, not timed
    lines = ["| pair | total s | matching | interpolation | fusion | TV-L1 levels |",
             "|---|---:|---:|---:|---:|---:|"]
    for clip, pass_, n in pairs:
        f0, f1, *_ = load_sintel_pair(clip, n, pass_, root)
        runs = []
        for _ in range(repeats):
            st: dict = {}
            t0 = time.perf_counter()
            tvl1_ld(f0, f1, params, stats=st)
            total = time.perf_counter() - t0
            fusion = st.get("fusion_seconds", 0.0)
            runs.append((total, st["match_seconds"], st["interp_seconds"], fusion,
                         st["seconds"] - fusion))
        med = [statistics.median(r[k] for r in runs) for k in range(5)]
        shares = " | ".join(f"{m:.2f} ({100 * m / med[0]:.0f} %)" for m in med[1:])
        lines.append(f"| {clip} {pass_} {n}->{n + 1} | {med[0]:.2f} | {shares} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="data folder (default $VARFLOW_DATA)")
    ap.add_argument("--split", default="reporting", choices=("tuning", "reporting", "both"))
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per Sintel pair")
    ap.add_argument("--skip-table", action="store_true", help="only the stage timing")
    args = ap.parse_args()
    root = data_root(args.data)
    if not args.skip_table:
        first = True
        for s in ("large", "sintel-large", "middlebury"):
            rows = run_twoframe(["tvl1", "tvl1-ld"], peers="dis,deepflow", sets=[s],
                                split=args.split, root=root, progress=False, warm_up=first)
            first = False
            print(format_twoframe_table(rows))
            print()
    print(f"tvl1-ld stages on the 1024x436 Sintel pairs (median of {args.repeats} runs; "
          "seconds, share of the total):")
    print()
    print(stage_table(root, max(1, args.repeats)))


if __name__ == "__main__":
    main()
