"""Trajectory benchmark on the synthetic sequences (the layout of the book's Table 4.2).

:func:`run_trajectories` runs registered trajectory methods
(:data:`varflow.registry.TRACKERS`) on the sequences of
:func:`varflow.generators.sequences.benchmark_suite` — every scene under every
variant (clean, Gaussian noise, salt & pepper, passing occluder) — and scores them
with :func:`varflow.evaluation.trajectory_metrics.trajectory_errors` over all frames
but the reference and the visible pixels.  :func:`format_trajectory_table` prints one
line per (scene, variant) with the mean endpoint error and RMS of every method, then
the mean over the rows and each method's ratio to the first method's mean.

:func:`run_photo_trajectories` is the *photographic generalisation suite*: the
clips of :func:`varflow.generators.photo.make_photo_clip` (real photographs under
known motions, with exact trajectories and visibility), per split (``"tuning"``
seeds for choosing defaults, ``"reporting"`` seeds for the numbers one quotes) and
family.  Every method returns its trajectories and visibility
(``varflow.track(..., return_visibility=True)``); they are scored by the endpoint
error over the visible points of all frames but the reference, the *far* EPE (the
two frames at each end of the clip, where errors accumulate) and TAP-Vid's
occlusion accuracy (:func:`varflow.evaluation.trajectory_metrics.occlusion_accuracy`).
:func:`format_photo_table` prints a table per split, one line per family.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...generators.photo import FAMILIES, SPLITS, make_photo_clip, photo_cases
from ...generators.photo import MAX_FRAMES as _PHOTO_MAX_FRAMES
from ...generators.photo import MIN_SIZE as _PHOTO_MIN_SIZE
from ...generators.sequences import SCENES, VARIANTS, benchmark_suite
from ...registry import TRACKERS, get_tracker, make_track_params
from ..trajectory_metrics import occlusion_accuracy, trajectory_errors
from .common import _nanmean, _num, markdown_table, spec_name, split_overrides

__all__ = [
    "run_trajectories",
    "format_trajectory_table",
    "tracker_params",
    "PHOTO_SPLITS",
    "check_photo_options",
    "end_frames",
    "far_epe",
    "run_photo_trajectories",
    "format_photo_table",
]

PHOTO_SPLITS: tuple[str, ...] = ("tuning", "reporting")
"""Default splits of the photographic suite (keys of :data:`varflow.generators.photo.SPLITS`)."""

log = logging.getLogger(__name__)


def tracker_params(
    methods: Sequence[str], overrides: Mapping[str, Any] | None
) -> tuple[list[str], dict[str, Any]]:
    """Check trajectory method specs and build each one's parameters.

    ``methods`` are specs (:func:`~varflow.evaluation.bench.common.method_spec`: a
    name, optionally with ``:field=value`` parts, e.g. ``rlr:link_weight=0`` or
    ``twoframe:tvl1-ld``); ``overrides`` are distributed by
    :func:`varflow.evaluation.bench.common.split_overrides`.

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
    methods = list(dict.fromkeys(methods))
    if not methods:
        raise ValueError("methods: need at least one trajectory method")
    for m in methods:
        get_tracker(spec_name(m))
    per_method = split_overrides(methods, overrides, registry=TRACKERS)
    return methods, {m: make_track_params(spec_name(m), **per_method[m]) for m in methods}


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
                est = varflow.track(seq.frames, seq.ref, spec_name(m), params=params[m])
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


# --------------------------------------------------------------------------- photo suite


def check_photo_options(
    splits: Sequence[str],
    families: Sequence[str],
    n_frames: int,
    shape: tuple[int, int],
) -> tuple[list[str], list[str], int, tuple[int, int]]:
    """Check the configuration of the photographic suite before any work.

    Parameters
    ----------
    splits : sequence of str
        Keys of :data:`varflow.generators.photo.SPLITS` (duplicates dropped).
    families : sequence of str
        Names from :data:`varflow.generators.photo.FAMILIES` (duplicates dropped).
    n_frames : int
        Frames per clip.
    shape : (int, int)
        Frame size ``(H, W)``.

    Returns
    -------
    splits, families : list of str
    n_frames : int
    shape : (int, int)

    Raises
    ------
    ValueError
        The message starts with the argument's name.
    """
    for name, value in (("splits", splits), ("families", families)):
        if isinstance(value, str):
            raise ValueError(f"{name}: expected a sequence of names, got the string {value!r}")
    splits = list(dict.fromkeys(splits))
    families = list(dict.fromkeys(families))
    if not splits:
        raise ValueError(f"splits: need at least one of {tuple(SPLITS)}")
    if not families:
        raise ValueError(f"families: need at least one of {FAMILIES}")
    for s in splits:
        if s not in SPLITS:
            raise ValueError(f"splits: expected names from {tuple(SPLITS)}, got {s!r}")
    for f in families:
        if f not in FAMILIES:
            raise ValueError(f"families: expected names from {FAMILIES}, got {f!r}")
    if (isinstance(n_frames, bool) or not isinstance(n_frames, int | np.integer)
            or not 2 <= n_frames <= _PHOTO_MAX_FRAMES):
        raise ValueError(f"n_frames: expected an integer in [2, {_PHOTO_MAX_FRAMES}], "
                         f"got {n_frames!r}")
    try:
        h, w = (int(v) for v in shape)
        ok = all(not isinstance(v, bool) and int(v) == v for v in shape)
    except (TypeError, ValueError):
        ok = False
    if not ok or min(h, w) < _PHOTO_MIN_SIZE:
        raise ValueError(f"shape: expected (H, W) with integers H, W >= {_PHOTO_MIN_SIZE}, "
                         f"got {shape!r}")
    return splits, families, int(n_frames), (h, w)


def end_frames(n_frames: int) -> list[int]:
    """The frames of the far EPE: the two at each end, ``0, 1, F-2, F-1`` (distinct).

    Parameters
    ----------
    n_frames : int
        Number of frames F >= 1.

    Returns
    -------
    list of int
        Sorted, without repetitions (``[0, 1]`` for F = 2).
    """
    return sorted({i for i in (0, 1, n_frames - 2, n_frames - 1) if 0 <= i < n_frames})


def far_epe(epe_per_frame: np.ndarray) -> float:
    """Mean of the per-frame EPE over the :func:`end_frames`, ignoring NaN.

    Parameters
    ----------
    epe_per_frame : ndarray, shape (F,)
        ``trajectory_errors(...)["epe_per_frame"]`` (NaN for the reference frame and
        frames without visible points).

    Returns
    -------
    float
        NaN when none of the end frames has a value.
    """
    per_frame = np.asarray(epe_per_frame, np.float64)
    vals = per_frame[end_frames(per_frame.shape[0])]
    vals = vals[np.isfinite(vals)]
    return float(vals.mean()) if vals.size else math.nan


def _warm_up_photo(frames: np.ndarray, methods: Sequence[str], params: Mapping[str, Any]) -> None:
    """Run every method once on a small crop of a clip so JIT compilation is not timed."""
    import varflow

    crop = np.ascontiguousarray(frames[:3, :48, :64])
    for m in methods:
        try:
            varflow.track(crop, 1, spec_name(m), params=params[m], return_visibility=True)
        except Exception as exc:  # noqa: BLE001 - a warm-up only; the real run reports
            log.warning("warm-up of %s failed (%s); its time includes compilation", m, exc)


def run_photo_trajectories(
    methods: Sequence[str],
    *,
    splits: Sequence[str] = PHOTO_SPLITS,
    families: Sequence[str] = FAMILIES,
    n_frames: int = 31,
    shape: tuple[int, int] = (192, 256),
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Run trajectory methods on the photographic generalisation suite.

    Every ``(family, seed)`` clip of every split (:func:`varflow.generators.photo.
    photo_cases`) is generated once by :func:`~varflow.generators.photo.make_photo_clip`
    (reference: the centre frame) and every method tracks it with
    ``varflow.track(..., return_visibility=True)``.

    Parameters
    ----------
    methods : sequence of str
        Names from :data:`varflow.registry.TRACKERS`.
    splits : sequence of str
        ``"tuning"`` (seeds 0, 1, 2) and/or ``"reporting"`` (seeds 100, 101, 102).
    families : sequence of str
        Subset of :data:`varflow.generators.photo.FAMILIES`.
    n_frames, shape
        Of the generated clips.
    overrides : mapping, optional
        ``{field: value}`` applied to every method that has the field.
    progress : bool
        A tqdm bar on stderr (only on a terminal).
    warm_up : bool
        First run every method, untimed, on a 3-frame crop of the first clip so
        that ``seconds`` excludes JIT compilation.

    Returns
    -------
    list of dict
        One row per (split, family, seed, method): ``split``, ``family``, ``seed``,
        ``method``; ``epe``, ``rms`` (pixels, visible points of all frames but the
        reference); ``far_epe`` (:func:`far_epe`, the mean per-frame EPE of frames
        ``0, 1, F-2, F-1``); ``occ_accuracy`` and ``hidden_recall`` (TAP-Vid
        occlusion accuracy of the estimated visibility and the share of the truly
        hidden (pixel, frame) pairs labelled hidden, reference frame excluded; see
        :func:`~varflow.evaluation.trajectory_metrics.occlusion_accuracy`);
        ``seconds`` (tracking with the visibility estimate).

    Raises
    ------
    ValueError
        Unknown method, split, family or parameter, or an invalid clip size.
    """
    from tqdm import tqdm

    import varflow

    methods, params = tracker_params(methods, overrides)
    splits, families, n_frames, shape = check_photo_options(splits, families, n_frames, shape)
    cases = [(split, family, seed) for split in splits
             for family, seed in photo_cases(split, families)]
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(cases) * len(methods), desc="photo trajectories", unit="run",
               file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        for split, family, seed in cases:
            bar.set_postfix_str(f"{split} {family}/{seed} generating")
            clip = make_photo_clip(family, seed=seed, n_frames=n_frames, shape=shape)
            if warm_up:
                _warm_up_photo(clip.frames, methods, params)
                warm_up = False
            for m in methods:
                bar.set_postfix_str(f"{split} {family}/{seed} {m}")
                t0 = time.perf_counter()
                est, visible = varflow.track(clip.frames, clip.ref, spec_name(m),
                                             params=params[m], return_visibility=True)
                seconds = time.perf_counter() - t0
                err = trajectory_errors(est, clip.trajectories, clip.visibility, ref=clip.ref)
                occ = occlusion_accuracy(visible, clip.visibility, clip.ref)
                row = {"split": split, "family": family, "seed": seed, "method": m,
                       "epe": float(err["epe"]), "far_epe": far_epe(err["epe_per_frame"]),
                       "rms": float(err["rms"]), "occ_accuracy": float(occ["accuracy"]),
                       "hidden_recall": float(occ["hidden_recall"]), "seconds": seconds}
                rows.append(row)
                log.info("%s %s/%d %s: EPE %.4f far %.4f occ acc %.4f hidden recall %.4f "
                         "in %.2fs", split, family, seed, m, row["epe"], row["far_epe"],
                         row["occ_accuracy"], row["hidden_recall"], seconds)
                bar.update(1)
    finally:
        bar.close()
    return rows


_PHOTO_COLUMNS = (("epe", "EPE", 4), ("far_epe", "far EPE", 4), ("occ_accuracy", "occ acc", 4),
                  ("hidden_recall", "hidden rec", 4), ("seconds", "s", 2))


def format_photo_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown tables of :func:`run_photo_trajectories` rows, one per split.

    Each table follows a heading line ``"<split> split (seeds ...)"`` and has a line
    per family (the mean over the split's seeds) with, per method, the EPE, the far
    EPE, the occlusion accuracy, the hidden recall and the seconds; then the mean
    over the families and each method's ratio of mean EPE and of mean far EPE to
    the first method's.  Missing values (no hidden point, ...) print as ``-``.

    Parameters
    ----------
    rows : sequence of mapping
        With ``split``, ``family``, ``seed``, ``method`` and the numeric fields.

    Returns
    -------
    str
    """
    if not rows:
        return "(no results)"
    methods = list(dict.fromkeys(r["method"] for r in rows))
    splits = list(dict.fromkeys(r["split"] for r in rows))
    base = methods[0]
    tables = []
    for split in splits:
        srows = [r for r in rows if r["split"] == split]
        families = list(dict.fromkeys(r["family"] for r in srows))
        seeds = sorted({int(r["seed"]) for r in srows})
        cells: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
        for r in srows:
            cells.setdefault((r["family"], r["method"]), []).append(r)

        def val(family: str, m: str, f: str, cells=cells) -> float:
            return _nanmean([float(r[f]) for r in cells.get((family, m), [])])

        header = ["family"]
        for m in methods:
            header += [f"{m} {label}" for _, label, _ in _PHOTO_COLUMNS]
        body = []
        for family in families:
            line = [family]
            for m in methods:
                line += [_num(val(family, m, f), d) for f, _, d in _PHOTO_COLUMNS]
            body.append(line)
        means = {m: {f: _nanmean([val(fam, m, f) for fam in families])
                     for f, _, _ in _PHOTO_COLUMNS} for m in methods}
        line = ["mean"]
        for m in methods:
            line += [_num(means[m][f], d) for f, _, d in _PHOTO_COLUMNS]
        body.append(line)
        line = [f"EPE, far EPE ratio to {base}"]
        for m in methods:
            ratios = []
            for f in ("epe", "far_epe"):
                b = means[base][f]
                ok = math.isfinite(b) and b > 0 and math.isfinite(means[m][f])
                ratios.append(f"{means[m][f] / b:.3f}" if ok else "-")
            line += ratios + [""] * (len(_PHOTO_COLUMNS) - 2)
        body.append(line)
        heading = f"{split} split (seeds {', '.join(map(str, seeds))})"
        tables.append(heading + "\n" + markdown_table(header, body))
    return "\n\n".join(tables)
