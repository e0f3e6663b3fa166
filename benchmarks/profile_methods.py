"""Where ``tvl1``, ``tvl1-ld`` and ``rlr`` spend their time, and how near memory speed.

Usage::

    python benchmarks/profile_methods.py [--methods tvl1,tvl1-ld,rlr] [--data DIR]
        [--rlr-frames 8] [--top 12]

For each method, on real frames (``tvl1``: the 8 Middlebury pairs and three
small-motion Sintel pairs; ``tvl1-ld``: the large-motion Sintel pairs; ``rlr``: the
first ``--rlr-frames`` frames of Sintel alley_1 final, 1024×436), after a warm-up
run that compiles every kernel:

- the **stage table**: seconds spent in each stage of the method (exclusive: a stage
  called inside another is counted once, in the inner one) and its share of the
  method's wall time; the stages are the method's Python-level steps, wrapped
  wherever the library binds them;
- the **kernel table** (a roofline against memory bandwidth): every Numba kernel
  called from Python — calls, seconds, share of the wall time, and the bytes it
  moves, counted from its arrays: each array argument once as read, once more as
  written if the call changed it (found in an untimed run of the same case before
  the timed one, by comparing a copy of the arguments on the kernel's first call
  with those shapes), each returned array as written, all of it times the kernel's
  passes over memory (its iteration count for the iterative solvers, below; scratch
  arrays a kernel allocates inside are not counted); then GB/s and the share of the
  copy bandwidth measured in the same run (``numpy.copyto`` and a parallel Numba copy
  of a 256 MiB float32 array, the faster of the two, two bytes counted per byte
  copied).

A kernel far below the copy bandwidth is bound by arithmetic or latency (or by a
small working set: arrays that fit in cache can exceed it). Time it on an otherwise
idle machine.
"""

from __future__ import annotations

import argparse
import collections
import functools
import math
import sys
import time
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba as nb
import numpy as np
from numba.core.registry import CPUDispatcher

import varflow
from varflow.evaluation.bench.twoframe import SINTEL_LARGE_PAIRS, sintel_pairs_present
from varflow.evaluation.datasets import (
    MIDDLEBURY_SEQUENCES,
    data_root,
    load_middlebury_pair,
    load_sintel_pair,
)

SINTEL_SMALL = [("alley_1", 1, "final"), ("alley_2", 2, "clean"), ("bandage_1", 35, "final")]

#: The stages of each method: (module, function, label).  A function is replaced in
#: every loaded ``varflow`` module that binds it, so ``from x import f`` is covered.
STAGES: dict[str, list[tuple[str, str, str]]] = {
    "tvl1": [
        ("varflow.twoframe.coarse_to_fine", "prepare_pyramid", "pre-processing and pyramids"),
        ("varflow.ops.rof", "structure_texture", "structure-texture (ROF)"),
        ("varflow.ops.differences", "derivative_planes", "derivatives"),
        ("varflow.ops.warp", "warp_bicubic", "bicubic warps"),
        ("varflow.twoframe.tvl1", "data_channels", "data term (linearisation)"),
        ("varflow.twoframe.tvl1", "tvl1_iterations", "primal-dual iterations"),
        ("varflow.twoframe.coarse_to_fine", "median_filter_flow", "median filter"),
        ("varflow.ops.pyramid", "resize_flow", "flow upsampling"),
    ],
    "tvl1-ld": [
        ("varflow.twoframe.large_displacement", "matching_flow", "matching set-up"),
        ("varflow.ops.matching", "match", "matching (PatchMatch on descriptors)"),
        ("varflow.ops.interpolation", "interpolate", "edge-aware interpolation"),
        ("varflow.twoframe.large_displacement", "fusion_hook", "fusion"),
    ],
    "rlr": [
        ("varflow.multiframe.refine", "initial_trajectories", "initial trajectories"),
        ("varflow.multiframe.visibility", "backward_flows", "visibility: backward flows"),
        ("varflow.multiframe.visibility", "visibility_from", "visibility"),
        ("varflow.multiframe.ustep", "ustep_iterations", "U-step iterations"),
        ("varflow.multiframe.ustep", "link_channels", "U-step link terms"),
        ("varflow.multiframe.refine", "_linearised_frame", "U-step data terms"),
        ("varflow.multiframe.lowrank", "lowrank_step", "L-step (low rank)"),
        ("varflow.multiframe.fuse", "fuse_decoupled", "decoupled fusion"),
    ],
}
STAGES["tvl1-ld"] = STAGES["tvl1"] + STAGES["tvl1-ld"]
STAGES["rlr"] = STAGES["tvl1"] + STAGES["rlr"]


def _passes_tvl1(args: tuple, result: Any) -> float:
    # two iterations per sweep over the data (the kernel's temporal blocking)
    return math.ceil(int(result) / 2)


#: Passes over memory of the iterative kernels, from their arguments and result;
#: every other kernel counts one.
PASSES: dict[str, Callable[[tuple, Any], float]] = {
    "tvl1_iterations": _passes_tvl1,
    "ustep_iterations": lambda args, result: float(result),
    "_rof_kernel": lambda args, result: float(args[2].shape[0]),
    "_l1_kernel": lambda args, result: float(np.mean(args[7])) if args[7].size else 1.0,
}


class Recorder:
    """Exclusive seconds per stage and, per kernel, calls, seconds and bytes."""

    def __init__(self) -> None:
        self.stage_s: dict[str, float] = collections.defaultdict(float)
        self.stack: list[list[float]] = []  # [start, seconds of inner stages]
        self.kernel_s: dict[str, float] = collections.defaultdict(float)
        self.kernel_calls: dict[str, int] = collections.defaultdict(int)
        self.kernel_bytes: dict[str, float] = collections.defaultdict(float)
        self.written: dict[tuple, tuple[bool, ...]] = {}
        self.active = False  # timing and counting
        self.learning = False  # finding which arguments each kernel writes
        self.unlearned = 0  # timed calls whose writes were not learnt (counted as reads)

    def stage(self, label: str, func: Callable) -> Callable:
        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            if not self.active:
                return func(*args, **kwargs)
            self.stack.append([time.perf_counter(), 0.0])
            try:
                return func(*args, **kwargs)
            finally:
                start, inner = self.stack.pop()
                total = time.perf_counter() - start
                self.stage_s[label] += total - inner
                if self.stack:
                    self.stack[-1][1] += total

        return wrapper


def _arrays(values: Any) -> list[np.ndarray]:
    out = []
    for v in values:
        if isinstance(v, np.ndarray):
            out.append(v)
        elif isinstance(v, (tuple, list)):
            out.extend(x for x in v if isinstance(x, np.ndarray))
    return out


def _changed(before: np.ndarray, after: np.ndarray) -> bool:
    if before.dtype.kind in "fc":
        return not np.array_equal(before, after, equal_nan=True)
    return not np.array_equal(before, after)


def install_kernel_timer(rec: Recorder) -> Callable[[], None]:
    """Time every Numba kernel called from Python (jitted callers are not affected:
    a kernel called from another kernel counts in its caller).  Returns the undo."""
    original = CPUDispatcher.__call__

    def timed(self: Any, *args: Any, **kwargs: Any) -> Any:
        if not (rec.active or rec.learning):
            return original(self, *args, **kwargs)
        name = self.py_func.__name__
        arrays = _arrays((*args, *kwargs.values()))
        key = (self.py_func.__module__, name, tuple((a.shape, a.dtype.str) for a in arrays))
        if rec.learning:
            if key in rec.written:
                return original(self, *args, **kwargs)
            copies = [a.copy() for a in arrays]
            result = original(self, *args, **kwargs)
            rec.written[key] = tuple(_changed(c, a) for c, a in zip(copies, arrays, strict=True))
            return result
        t0 = time.perf_counter()
        result = original(self, *args, **kwargs)
        dt = time.perf_counter() - t0
        flags = rec.written.get(key)
        if flags is None:
            rec.unlearned += 1
            flags = (False,) * len(arrays)
        moved = sum(a.nbytes * (2 if w else 1) for a, w in zip(arrays, flags, strict=True))
        ids = {id(a) for a in arrays}
        moved += sum(r.nbytes for r in _arrays(result if isinstance(result, tuple)
                                               else (result,)) if id(r) not in ids)
        passes = PASSES.get(name)
        moved *= passes(args, result) if passes is not None else 1.0
        label = f"{self.py_func.__module__.removeprefix('varflow.')}.{name}"
        rec.kernel_s[label] += dt
        rec.kernel_calls[label] += 1
        rec.kernel_bytes[label] += moved
        return result

    CPUDispatcher.__call__ = timed

    def undo() -> None:
        CPUDispatcher.__call__ = original

    return undo


def install_stages(rec: Recorder, method: str) -> Callable[[], None]:
    """Wrap the method's stages in every loaded varflow module; returns the undo."""
    import importlib

    undo: list[tuple[types.ModuleType, str, Any]] = []
    for module_name, func_name, label in STAGES[method]:
        target = getattr(importlib.import_module(module_name), func_name)
        wrapper = rec.stage(label, target)
        for mod in list(sys.modules.values()):
            if not isinstance(mod, types.ModuleType):
                continue
            if not getattr(mod, "__name__", "").startswith("varflow"):
                continue
            for attr, value in list(vars(mod).items()):
                if value is target:
                    undo.append((mod, attr, value))
                    setattr(mod, attr, wrapper)

    def restore() -> None:
        for mod, attr, value in reversed(undo):
            setattr(mod, attr, value)

    return restore


@nb.njit(cache=True, parallel=True)
def _parallel_copy(src: np.ndarray, dst: np.ndarray) -> None:
    n = src.size
    chunk = 1 << 16
    for c in nb.prange((n + chunk - 1) // chunk):
        for i in range(c * chunk, min(n, (c + 1) * chunk)):
            dst[i] = src[i]


def copy_bandwidth(n_bytes: int = 256 << 20, repeats: int = 7) -> tuple[float, float]:
    """GB/s of ``numpy.copyto`` and of a parallel Numba copy (read + write counted)."""
    src = np.random.default_rng(0).random(n_bytes // 4, dtype=np.float32)
    dst = np.empty_like(src)
    _parallel_copy(src[:1024], dst[:1024])
    out = []
    for fn in (lambda: np.copyto(dst, src), lambda: _parallel_copy(src, dst)):
        fn()
        best = min(_seconds(fn) for _ in range(repeats))
        out.append(2 * src.nbytes / best / 1e9)
    return out[0], out[1]


def _seconds(fn: Callable[[], Any]) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _sintel_frames(root: Path, clip: str, n: int, pass_: str = "final") -> np.ndarray:
    folder = root / "sintel" / "training" / pass_ / clip
    paths = sorted(folder.glob("frame_*.png"))[:n]
    if len(paths) < n:
        raise SystemExit(f"{folder}: {len(paths)} frames, {n} needed")
    return np.stack([varflow.read_image(p) for p in paths]).astype(np.float32)


def cases(method: str, root: Path, rlr_frames: int) -> tuple[list[tuple[str, Callable]], Callable]:
    """The timed runs of ``method`` and its warm-up run."""
    if method == "tvl1":
        runs = []
        for s in MIDDLEBURY_SEQUENCES:
            f0, f1, _ = load_middlebury_pair(s, root)
            runs.append((s, functools.partial(varflow.flow, f0, f1, method="tvl1")))
        for clip, frame, pass_ in SINTEL_SMALL:
            f0, f1, *_ = load_sintel_pair(clip, frame, pass_, root)
            runs.append((f"{clip} {pass_} {frame}",
                         functools.partial(varflow.flow, f0, f1, method="tvl1")))
        return runs, runs[0][1]
    if method == "tvl1-ld":
        runs = []
        for clip, pass_, n in sintel_pairs_present(root, SINTEL_LARGE_PAIRS)[0]:
            f0, f1, *_ = load_sintel_pair(clip, n, pass_, root)
            runs.append((f"{clip} {pass_} {n}",
                         functools.partial(varflow.flow, f0, f1, method="tvl1-ld")))
        return runs, runs[0][1]
    if method == "rlr":
        frames = _sintel_frames(root, "alley_1", rlr_frames)
        ref = rlr_frames // 2
        run = functools.partial(varflow.track, frames, ref=ref, method="rlr")
        small = np.ascontiguousarray(frames[:4, :96, :128])
        warm = functools.partial(varflow.track, small, ref=1, method="rlr")
        return [(f"alley_1 final, {rlr_frames} frames", run)], warm
    raise SystemExit(f"unknown method {method!r}")


def profile(method: str, root: Path, rlr_frames: int, copy_gbs: float, top: int) -> None:
    rec = Recorder()
    runs, warm = cases(method, root, rlr_frames)
    undo_stages = install_stages(rec, method)
    undo_kernels = install_kernel_timer(rec)
    try:
        warm()  # compiles every kernel the runs need (not timed)
        total = 0.0
        print(f"## {method}\n")
        print("| case | seconds |\n|---|---:|")
        for name, run in runs:
            rec.learning = True  # an untimed run finds which arrays the kernels write
            run()
            rec.learning, rec.active = False, True
            dt = _seconds(run)
            rec.active = False
            total += dt
            print(f"| {name} | {dt:.2f} |")
    finally:
        undo_kernels()
        undo_stages()
    print(f"| total | {total:.2f} |\n")
    print("| stage | seconds | share |\n|---|---:|---:|")
    for label, s in sorted(rec.stage_s.items(), key=lambda kv: -kv[1]):
        print(f"| {label} | {s:.2f} | {s / total:.1%} |")
    rest = total - sum(rec.stage_s.values())
    print(f"| rest (outside the stages) | {rest:.2f} | {rest / total:.1%} |\n")
    print("| kernel | calls | seconds | share | GB moved | GB/s | of copy |\n"
          "|---|---:|---:|---:|---:|---:|---:|")
    ranked = sorted(rec.kernel_s.items(), key=lambda kv: -kv[1])
    for label, s in ranked[:top]:
        gb = rec.kernel_bytes[label] / 1e9
        rate = gb / s if s > 0 else float("nan")
        print(f"| {label} | {rec.kernel_calls[label]} | {s:.2f} | {s / total:.1%} | "
              f"{gb:.1f} | {rate:.1f} | {rate / copy_gbs:.0%} |")
    others = sum(s for _, s in ranked[top:])
    inside = sum(rec.kernel_s.values())
    print(f"| {len(ranked) - min(top, len(ranked))} other kernels | | {others:.2f} | "
          f"{others / total:.1%} | | | |")
    print(f"| outside every kernel (Python, NumPy, OpenCV) | | {total - inside:.2f} | "
          f"{(total - inside) / total:.1%} | | | |\n")
    if rec.unlearned:
        print(f"({rec.unlearned} kernel calls with argument shapes not seen in the untimed "
              "run: their arrays counted as read only)\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", default="tvl1,tvl1-ld,rlr")
    ap.add_argument("--data", default=None, help="data folder (default ../shared/data)")
    ap.add_argument("--rlr-frames", type=int, default=8)
    ap.add_argument("--top", type=int, default=12, help="kernels listed by name")
    args = ap.parse_args(argv)
    root = data_root(args.data)
    numpy_gbs, numba_gbs = copy_bandwidth()
    copy_gbs = max(numpy_gbs, numba_gbs)
    print(f"varflow {varflow.__version__}, {nb.get_num_threads()} threads; copy bandwidth "
          f"(256 MiB float32, read + write): numpy.copyto {numpy_gbs:.1f} GB/s, parallel "
          f"Numba {numba_gbs:.1f} GB/s\n")
    for method in args.methods.split(","):
        profile(method, root, args.rlr_frames, copy_gbs, args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main())
