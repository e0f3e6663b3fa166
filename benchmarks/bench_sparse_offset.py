"""Patch-offset trade-off of sparse-regularised TV-L1 on Middlebury.

Usage::

    python benchmarks/bench_sparse_offset.py [--data DIR] [--method sparse-1d]
        [--offsets 1 2 3 4 5 6 7 8] [--sequences RubberWhale ...] [--patch-size 10]

For each patch offset k (10 x 10 patches by default) the chosen sparse method runs on
the Middlebury pairs (frame10 -> frame11).  Printed per k: the time of the sparse step
(dictionary learning by MOD + OMP coding of the flow patches, summed over the pairs;
``stats["sparse_seconds"]``), its speed-up over k = 1, the time of the Nesterov
solves, the total wall time, the mean AEE and its change relative to k = 1 (the
first offset listed), and then the per-pair AEE.  A last line checks the issue's
criterion for the method's default k: sparse step >= 10x faster than k = 1 with the
AEE within 2 %.

One warm-up call (Numba compilation) runs first and is not timed.  Time it on an
otherwise idle machine: the sparse step runs BLAS and Numba on all cores.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    """Run the sweep and print the table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", help="data folder (default $VARFLOW_DATA or ../shared/data)")
    parser.add_argument("--method", default="sparse-1d", help="a sparse method (default sparse-1d)")
    parser.add_argument("--offsets", nargs="+", type=int, default=list(range(1, 9)))
    parser.add_argument("--sequences", nargs="+", help="subset of the 8 sequences")
    parser.add_argument("--patch-size", type=int, default=10)
    args = parser.parse_args(argv)

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
        default_k = varflow.make_params(args.method).patch_offset
        for k in args.offsets:
            varflow.make_params(args.method, patch_offset=k, patch_size=args.patch_size)
    except (ValueError, OSError) as exc:
        print(f"bench_sparse_offset: error: {exc}", file=sys.stderr)
        return 2

    f0, f1, _ = pairs[seqs[0]]
    varflow.flow(f0[:96, :128], f1[:96, :128], args.method)  # JIT warm-up, not timed
    print(f"data: {root}; method {args.method}, {args.patch_size}x{args.patch_size} patches; "
          f"pairs: {', '.join(seqs)}")
    head = (f"{'k':>2} {'sparse s':>9} {'speed-up':>8} {'nesterov s':>10} {'total s':>8} "
            f"{'mean AEE':>9} {'dAEE %':>7} | " + " ".join(f"{s[:9]:>9}" for s in seqs))
    print(head)
    print("-" * len(head))
    results = {}
    for k in args.offsets:
        sparse_s = nest_s = total = 0.0
        aees = []
        for s in seqs:
            f0, f1, gt = pairs[s]
            stats: dict = {}
            t0 = time.perf_counter()
            est = varflow.flow(f0, f1, args.method, stats=stats, patch_offset=k,
                               patch_size=args.patch_size)
            total += time.perf_counter() - t0
            sparse_s += stats.get("sparse_seconds", 0.0)
            nest_s += stats.get("nesterov_seconds", 0.0)
            aees.append(evaluate(est, gt)["aee"])
        mean = float(np.mean(aees))
        results[k] = (sparse_s, mean)
        k0 = args.offsets[0]
        ref_s, ref_aee = results[k0]
        print(f"{k:>2} {sparse_s:9.2f} {ref_s / sparse_s:8.1f} {nest_s:10.2f} {total:8.2f} "
              f"{mean:9.4f} {100 * (mean - ref_aee) / ref_aee:+7.2f} | "
              + " ".join(f"{a:9.4f}" for a in aees), flush=True)
    if 1 in results and default_k in results:
        s1, a1 = results[1]
        sk, ak = results[default_k]
        fast = s1 / sk >= 10
        close = (ak - a1) / a1 <= 0.02
        print(f"default k = {default_k}: sparse step {s1 / sk:.1f}x faster than k = 1 "
              f"({'>=' if fast else '<'} 10x), AEE {100 * (ak - a1) / a1:+.2f} % "
              f"({'within' if close else 'outside'} 2 %): {'YES' if fast and close else 'NO'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
