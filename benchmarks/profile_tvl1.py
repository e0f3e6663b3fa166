"""Where a two-frame method spends its time: seconds per stage and iterations per level.

Usage::

    python benchmarks/profile_tvl1.py [--sets middlebury,sintel] [--data DIR]
        [--<field> VALUE ...]

Runs ``tvl1`` (with any :class:`~varflow.twoframe.tvl1.TVL1Params` field changed by
``--field value``) on the 8 Middlebury pairs and the three small-motion Sintel pairs
(alley_1 final 1→2, alley_2 clean 2→3, bandage_1 final 35→36), timing each stage of the
coarse-to-fine driver by wrapping its calls: pre-processing and pyramids, derivatives,
bicubic warps, linearisation of the data term, the primal-dual iterations, the median
filter.  Prints the per-pair AEE and seconds, the stage table and the mean iteration
count per warp at every level height.  Time it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from typing import Any

import numpy as np

import varflow
import varflow.twoframe.coarse_to_fine as c2f
import varflow.twoframe.tvl1 as tv
from varflow.evaluation.datasets import (
    MIDDLEBURY_SEQUENCES,
    load_middlebury_pair,
    load_sintel_pair,
)

SINTEL_SMALL = [("alley_1", 1, "final"), ("alley_2", 2, "clean"), ("bandage_1", 35, "final")]
STAGES = ["pyramid+rof", "derivatives", "warp", "linearise", "iterations", "median"]

seconds: dict[Any, float] = collections.defaultdict(float)
iterations: dict[int, list[int]] = collections.defaultdict(list)


def _timed(module: Any, name: str, key: str) -> None:
    inner = getattr(module, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        out = inner(*args, **kwargs)
        seconds[key] += time.perf_counter() - t0
        return out

    setattr(module, name, wrapper)


def _instrument() -> None:
    _timed(c2f, "prepare_pyramid", "pyramid+rof")
    _timed(c2f, "derivative_planes", "derivatives")
    _timed(c2f, "warp_bicubic", "warp")
    _timed(c2f, "median_filter_flow", "median")
    _timed(tv, "data_channels", "linearise")
    kernel = tv.tvl1_iterations

    def counted(*args: Any) -> int:
        t0 = time.perf_counter()
        n = kernel(*args)
        dt = time.perf_counter() - t0
        seconds["iterations"] += dt
        seconds[("level", args[0].shape[1])] += dt
        iterations[args[0].shape[1]].append(int(n))
        return n

    tv.tvl1_iterations = counted


def _value(text: str) -> Any:
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default="middlebury,sintel")
    ap.add_argument("--data", default=None, help="data folder (default ../shared/data)")
    args, rest = ap.parse_known_args(argv)
    if len(rest) % 2 or any(not r.startswith("--") for r in rest[::2]):
        ap.error("parameter overrides go as --field value pairs")
    pairs = zip(rest[::2], rest[1::2], strict=True)
    overrides = {k[2:].replace("-", "_"): _value(v) for k, v in pairs}
    params = tv.TVL1Params(**overrides)
    sets = args.sets.split(",")
    cases = []
    if "middlebury" in sets:
        cases += [(s, *load_middlebury_pair(s, args.data)) for s in MIDDLEBURY_SEQUENCES]
    if "sintel" in sets:
        for clip, frame, pass_ in SINTEL_SMALL:
            f0, f1, gt, *_ = load_sintel_pair(clip, frame, pass_, args.data)
            cases.append((f"{clip} {pass_} {frame}", f0, f1, gt))
    _instrument()
    tv.tvl1(cases[0][1][:64, :64], cases[0][2][:64, :64], params)  # JIT warm-up
    seconds.clear()
    iterations.clear()
    total, aees = 0.0, []
    for name, f0, f1, gt in cases:
        t0 = time.perf_counter()
        flow = tv.tvl1(f0, f1, params)
        dt = time.perf_counter() - t0
        total += dt
        aees.append(varflow.evaluate(flow, gt)["aee"])
        print(f"{name:20s} AEE {aees[-1]:.4f}  {dt:.2f} s")
    print(f"\nmean AEE {np.mean(aees):.4f}, total {total:.2f} s, parameters changed: "
          f"{overrides or 'none'}\n")
    print("| stage | seconds | share |\n|---|---:|---:|")
    for key in STAGES:
        print(f"| {key} | {seconds[key]:.2f} | {seconds[key] / total:.0%} |")
    rest = total - sum(seconds[k] for k in STAGES)
    print(f"| rest | {rest:.2f} | {rest / total:.0%} |\n")
    print("| level height | warps | mean iterations | max | seconds |\n|---:|---:|---:|---:|---:|")
    for h in sorted(iterations, reverse=True):
        its = iterations[h]
        print(f"| {h} | {len(its)} | {np.mean(its):.1f} | {max(its)} | "
              f"{seconds[('level', h)]:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
