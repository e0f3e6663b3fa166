"""Trajectory benchmark on the synthetic sequences (the layout of the book's Table 4.2).

:func:`run_trajectories` runs registered trajectory methods
(:data:`varflow.registry.TRACKERS`) on the sequences of
:func:`varflow.generators.sequences.benchmark_suite` — every scene under every
variant (clean, Gaussian noise, salt & pepper, passing occluder) — and scores them
with :func:`varflow.evaluation.trajectory_metrics.trajectory_errors` over all frames
but the reference and the visible pixels.  :func:`format_trajectory_table` prints one
line per (scene, variant) with the mean endpoint error and RMS of every method, then
the mean over the rows and each method's ratio to the first method's mean.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..generators.sequences import SCENES, VARIANTS, benchmark_suite
from ..registry import TRACKERS, get_tracker, make_track_params
from .bench import split_overrides
from .trajectory_metrics import trajectory_errors

__all__ = ["run_trajectories", "format_trajectory_table", "tracker_params"]

log = logging.getLogger(__name__)


def tracker_params(
    methods: Sequence[str], overrides: Mapping[str, Any] | None
) -> tuple[list[str], dict[str, Any]]:
    """Check trajectory method names and build each one's parameters.

    ``overrides`` are distributed by :func:`varflow.evaluation.bench.split_overrides`.

    Returns
    -------
    methods : list of str
    params : dict
        ``{method: params}``.

    Raises
    ------
    ValueError
        No method, an unknown method or parameter, or an invalid value.
    """
    methods = list(methods)
    if not methods:
        raise ValueError("methods: need at least one trajectory method")
    for m in methods:
        get_tracker(m)
    per_method = split_overrides(methods, overrides, registry=TRACKERS)
    return methods, {m: make_track_params(m, **per_method[m]) for m in methods}


def run_trajectories(
    methods: Sequence[str],
    *,
    n_frames: int = 30,
    shape: tuple[int, int] = (96, 128),
    scenes: Sequence[str] = SCENES,
    variants: Sequence[str] = VARIANTS,
    seed: int = 0,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Run trajectory methods on the synthetic suite.

    Parameters
    ----------
    methods : sequence of str
        Names from :data:`varflow.registry.TRACKERS`.
    n_frames, shape, seed
        Of the generated sequences (reference: the centre frame).
    scenes, variants : sequence of str
        Rows of the table.
    overrides : mapping, optional
        ``{field: value}`` applied to every method that has the field.
    progress : bool
        A tqdm bar on stderr (only on a terminal).

    Returns
    -------
    list of dict
        One row per (scene, variant, method): ``scene``, ``variant``, ``method``,
        ``epe``, ``rms`` (pixels, visible points of all frames but the reference),
        ``seconds``.

    Raises
    ------
    ValueError
        Unknown method, scene, variant or parameter.
    """
    from tqdm import tqdm

    import varflow

    methods, params = tracker_params(methods, overrides)
    rows: list[dict[str, Any]] = []
    n_rows = len(scenes) * len(variants)
    bar = tqdm(total=n_rows * len(methods), desc="trajectories", unit="run", file=sys.stderr,
               disable=None if progress else True, leave=False)
    try:
        for seq in benchmark_suite(n_frames=n_frames, shape=shape, seed=seed, scenes=scenes,
                                   variants=variants):
            for m in methods:
                bar.set_postfix_str(f"{seq.name}/{seq.variant} {m}")
                t0 = time.perf_counter()
                est = varflow.track(seq.frames, seq.ref, m, params=params[m])
                seconds = time.perf_counter() - t0
                err = trajectory_errors(est, seq.trajectories, seq.visibility, ref=seq.ref)
                rows.append({"scene": seq.name, "variant": seq.variant, "method": m,
                             "epe": float(err["epe"]), "rms": float(err["rms"]),
                             "seconds": seconds})
                log.info("%s/%s %s: EPE %.4f RMS %.4f in %.2fs", seq.name, seq.variant, m,
                         err["epe"], err["rms"], seconds)
                bar.update(1)
    finally:
        bar.close()
    return rows


def format_trajectory_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table: a line per (scene, variant), EPE / RMS / seconds per method.

    Under the rows: the mean of each column, and the ratio of each method's mean
    EPE to the first method's.
    """
    if not rows:
        return "(no results)"
    methods: list[str] = []
    keys: list[tuple[str, str]] = []
    cell: dict[tuple[str, str, str], Mapping[str, Any]] = {}
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
        k = (r["scene"], r["variant"])
        if k not in keys:
            keys.append(k)
        cell[(*k, r["method"])] = r

    def val(k: tuple[str, str], m: str, f: str) -> float:
        r = cell.get((*k, m))
        return math.nan if r is None else float(r[f])

    header = ["scene", "variant"]
    for m in methods:
        header += [f"{m} EPE", f"{m} RMS", f"{m} s"]
    body = []
    for k in keys:
        line = [k[0], k[1]]
        for m in methods:
            line += [f"{val(k, m, 'epe'):.4f}", f"{val(k, m, 'rms'):.4f}",
                     f"{val(k, m, 'seconds'):.2f}"]
        body.append(line)
    means = {m: {f: float(np.nanmean([val(k, m, f) for k in keys])) for f in
                 ("epe", "rms", "seconds")} for m in methods}
    line = ["mean", ""]
    for m in methods:
        line += [f"{means[m]['epe']:.4f}", f"{means[m]['rms']:.4f}", f"{means[m]['seconds']:.2f}"]
    body.append(line)
    base = means[methods[0]]["epe"]
    line = [f"EPE ratio to {methods[0]}", ""]
    for m in methods:
        line += [f"{means[m]['epe'] / base:.3f}" if base > 0 else "-", "", ""]
    body.append(line)
    widths = [max(len(header[i]), *(len(b[i]) for b in body)) for i in range(len(header))]

    def render(cells: Sequence[str]) -> str:
        left = [cells[0].ljust(widths[0]), cells[1].ljust(widths[1])]
        right = [c.rjust(w) for c, w in zip(cells[2:], widths[2:], strict=True)]
        return "| " + " | ".join(left + right) + " |"

    sep = "|" + "|".join(("-" * (w + 2)) if i < 2 else ("-" * (w + 1) + ":")
                         for i, w in enumerate(widths)) + "|"
    return "\n".join([render(header), sep] + [render(b) for b in body])
