"""The frame-interpolation benchmark: varflow's interpolators against minterpolate and friends.

:func:`run_interpolation_bench` runs registered interpolation methods
(:data:`varflow.retime.methods.INTERPOLATORS`, by default all of them) and the peers
of :data:`varflow.evaluation.interpolation_peers.INTERPOLATION_PEERS` (FFmpeg's
minterpolate, the cross-fade ``blend`` and frame ``repeat``) on the cases of
:mod:`varflow.evaluation.interpolation_sets` (Middlebury, UCF101 triplets and
MPI-Sintel alley_1; tuning / reporting splits) and scores every synthesised frame
against the true one with :func:`varflow.evaluation.frame_metrics.frame_scores`:
PSNR and SSIM, Baker et al.'s IE and NE, and the mean absolute difference MAE
(0-255 units; MAE is what learned methods call "IE" on Middlebury).  Methods whose
:attr:`~varflow.retime.methods.Interpolator.context` is 1 get the frames before
and after the pair (``previous`` / ``following``) where the set has them (Sintel);
the others, and the peers, get only the pair.  Every method first runs once,
untimed, on a small synthetic pair so that Numba compilation is not timed.

:func:`run_interpolation_timing` measures the seconds per 960 × 540 frame of every
method and peer on one real pair resized to that size (the median of a few timed
runs after an untimed one), and the ratio to minterpolate.

:func:`format_tables` prints the per-case tables, the per-set summaries (means, the
PSNR gain over minterpolate and over ``naive``, the cases won against minterpolate,
median seconds per frame) and the timing table.
"""

from __future__ import annotations

import logging
import math
import os
import statistics
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..datasets import data_root
from ..frame_metrics import frame_scores
from ..interpolation_peers import INTERPOLATION_PEERS
from ..interpolation_sets import (
    INTERPOLATION_SETS,
    SINTEL_CLIP,
    SINTEL_PASS,
    CaseFrames,
    InterpolationCase,
    check_sets,
    check_split,
    interpolation_cases,
)
from .common import _nanmean, _num, markdown_table

__all__ = [
    "BASELINE_METHOD",
    "BASELINE_PEER",
    "DEFAULT_PEERS",
    "INTERPOLATION_CSV_FIELDS",
    "TIMING_CLIP_FRAMES",
    "TIMING_SHAPE",
    "check_methods",
    "check_peers",
    "format_tables",
    "format_timing_table",
    "run_interpolation_bench",
    "run_interpolation_timing",
    "timing_clip",
    "timing_pair",
    "worst_decile",
]

log = logging.getLogger(__name__)

#: The peers run when none are named: all of them.
DEFAULT_PEERS: tuple[str, ...] = tuple(INTERPOLATION_PEERS)

#: The peer the PSNR gains, wins and time ratios are measured against.
BASELINE_PEER = "minterpolate"

#: The varflow method of the second PSNR gain: the simple baseline.
BASELINE_METHOD = "naive"

#: (H, W) of the frames of :func:`run_interpolation_timing`.
TIMING_SHAPE: tuple[int, int] = (540, 960)

#: The leading columns of the benchmark's CSV.
INTERPOLATION_CSV_FIELDS: tuple[str, ...] = (
    "set", "split", "case", "t", "method", "kind", "context", "psnr", "ssim", "ie", "ne",
    "mae", "seconds",
)


# --------------------------------------------------------------------------- options


def _names(value: str | Sequence[str] | None) -> list[str]:
    if value is None:
        return []
    items = value.split(",") if isinstance(value, str) else list(value)
    return list(dict.fromkeys(str(v).strip() for v in items if str(v).strip()))


def check_methods(methods: str | Sequence[str] | None) -> list[str]:
    """Validate interpolation method names.

    Parameters
    ----------
    methods : str, sequence of str or None
        Names of :data:`~varflow.retime.methods.INTERPOLATORS` (a comma-separated
        string is split); None: all of them.

    Returns
    -------
    list of str

    Raises
    ------
    ValueError
        ``methods: ...`` for an unknown name.
    """
    from ...retime.methods import INTERPOLATORS

    if methods is None:
        return list(INTERPOLATORS)
    names = _names(methods)
    for m in names:
        if m not in INTERPOLATORS:
            raise ValueError(f"methods: unknown interpolation method {m!r}; available: "
                             f"{', '.join(INTERPOLATORS)}")
    return names


def check_peers(peers: str | Sequence[str] | None) -> list[str]:
    """Validate peer names.

    Parameters
    ----------
    peers : str, sequence of str or None
        Names of :data:`~varflow.evaluation.interpolation_peers.INTERPOLATION_PEERS`,
        ``"all"`` or ``"none"`` (a comma-separated string is split); None: all.

    Returns
    -------
    list of str
        In :data:`INTERPOLATION_PEERS` order.

    Raises
    ------
    ValueError
        ``peers: ...`` for an unknown name.
    """
    if peers is None:
        return list(DEFAULT_PEERS)
    names = _names(peers)
    if names in ([], ["none"]):
        return []
    if names == ["all"]:
        return list(DEFAULT_PEERS)
    for p in names:
        if p not in INTERPOLATION_PEERS:
            raise ValueError(f"peers: unknown peer {p!r}; expected some of "
                             f"{', '.join(INTERPOLATION_PEERS)}, all or none")
    return [p for p in INTERPOLATION_PEERS if p in names]


# --------------------------------------------------------------------------- running


def _resolve(methods: str | Sequence[str] | None, peers: str | Sequence[str] | None,
             overrides: Mapping[str, Mapping[str, Any]] | None) -> tuple[
                 list[str], list[str], dict[str, Any]]:
    from ...retime.methods import make_interp_params

    names = check_methods(methods)
    peer_names = check_peers(peers)
    if not names and not peer_names:
        raise ValueError("methods: give at least one interpolation method or peer")
    for m in overrides or {}:
        if m not in names:
            raise ValueError(f"overrides: method {m!r} is not among {', '.join(names) or '-'}")
    params = {m: make_interp_params(m, **dict((overrides or {}).get(m, {}))) for m in names}
    return names, peer_names, params


def _warm_up_method(method: str, params: Any) -> None:
    """Run an interpolation method once on a small synthetic pair (JIT not timed)."""
    from ...retime.methods import interpolate

    rng = np.random.default_rng(0)
    f0 = rng.integers(0, 256, (40, 48, 3)).astype(np.uint8)
    f1 = np.roll(f0, 1, axis=1)
    interpolate(f0, f1, 0.5, method, params=params, previous=np.roll(f0, -1, axis=1),
                following=np.roll(f0, 2, axis=1))


#: Sets whose consecutive cases are frames between one pair (``sintel-x4``: t = 1/4,
#: 1/2, 3/4 between frames c - 2 and c + 2): a method estimates the pair's motion once
#: for all of them through a :class:`~varflow.retime.motion.FlowCache`, as
#: ``varflow retime`` does.
SHARED_MOTION_SETS = frozenset({"sintel-x4"})


def _run_one(name: str, kind: str, frames: Any, t: float, params: Any,
             use_context: bool, flow_cache: Any = None) -> tuple[np.ndarray, float]:
    """One interpolated frame and its wall time (``flow_cache``: the flows are looked
    up and kept there)."""
    from ...retime.methods import interpolate

    t0 = time.perf_counter()
    if kind == "varflow":
        ctx = {"previous": frames.previous, "following": frames.following} if use_context else {}
        est = interpolate(frames.frame0, frames.frame1, t, name, params=params,
                          flow_cache=flow_cache, **ctx)
    else:
        est = INTERPOLATION_PEERS[name](frames.frame0, frames.frame1, t)
    return est, time.perf_counter() - t0


def run_interpolation_bench(
    sets: str | Sequence[str] = INTERPOLATION_SETS,
    split: str = "reporting",
    methods: str | Sequence[str] | None = None,
    peers: str | Sequence[str] | None = DEFAULT_PEERS,
    root: str | os.PathLike[str] | None = None,
    max_cases: int | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    progress: bool = True,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Run interpolation methods and peers on the interpolation sets.

    Parameters
    ----------
    sets : str or sequence of str
        Some of :data:`~varflow.evaluation.interpolation_sets.INTERPOLATION_SETS`.
    split : {"tuning", "reporting", "all"}
        See :mod:`varflow.evaluation.interpolation_sets`.
    methods : str, sequence of str or None
        Registered interpolation methods (None: all of
        :data:`~varflow.retime.methods.INTERPOLATORS`; empty: peers only).
    peers : str, sequence of str or None
        Peers of :data:`~varflow.evaluation.interpolation_peers.INTERPOLATION_PEERS`,
        ``"all"`` or ``"none"`` (None: all).
    root : path-like, optional
        The data folder (see :func:`varflow.evaluation.datasets.data_root`).
    max_cases : int, optional
        Run only the first ``max_cases`` cases (in sorted order) of each set and split.
    overrides : mapping, optional
        ``{method: {field: value}}`` parameter overrides
        (:func:`~varflow.retime.methods.make_interp_params`).
    progress : bool
        A tqdm bar on stderr (only on a terminal).
    warm_up : bool
        First run every method once, untimed, on a small synthetic pair.

    Returns
    -------
    list of dict
        One row per (set, case, method) in set, case, method order (the varflow
        methods first, then the peers): ``set``, ``split``, ``case``, ``method``,
        ``t`` (the time of the true frame between the pair), ``kind`` (``"varflow"``
        or ``"peer"``), ``context`` (how many of
        ``previous`` / ``following`` the method was given), ``psnr`` (dB),
        ``ssim``, ``ie``, ``ne``, ``mae`` (0-255 units) and ``seconds`` (wall time
        of the one frame, reading excluded; in the sets of
        :data:`SHARED_MOTION_SETS` the first frame between a pair includes the
        flows that the next ones reuse).

    Raises
    ------
    ValueError
        Unknown set, split, method, peer or parameter; nothing to run;
        ``max_cases`` < 1.
    FileNotFoundError
        A requested set is missing under the data folder (checked before any run).
    """
    from tqdm import tqdm

    from ...retime.methods import get_interpolator
    from ...retime.motion import FlowCache

    sets_ = check_sets(list(sets) if not isinstance(sets, str) else sets)
    check_split(split)
    if max_cases is not None and max_cases < 1:
        raise ValueError(f"max_cases: must be at least 1, got {max_cases}")
    names, peer_names, params = _resolve(methods, peers, overrides)
    root_path = data_root(root)
    cases: list[InterpolationCase] = []
    for s in sets_:  # all sets checked before any work
        found = interpolation_cases(s, split, root_path)
        cases += found[:max_cases] if max_cases is not None else found
    if warm_up:
        for m in names:
            _warm_up_method(m, params[m])

    runners = [(m, "varflow") for m in names] + [(p, "peer") for p in peer_names]
    caches = {m: FlowCache() for m in names}  # for SHARED_MOTION_SETS only
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(cases) * len(runners), desc="interpolation", unit="frame",
               file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        for case in cases:
            frames = case.load()
            for name, kind in runners:
                bar.set_postfix_str(f"{case.set} {case.name} {name}")
                use_context = kind == "varflow" and get_interpolator(name).context >= 1
                cache = caches.get(name) if case.set in SHARED_MOTION_SETS else None
                est, seconds = _run_one(name, kind, frames, case.t, params.get(name),
                                        use_context, cache)
                scores = frame_scores(est, frames.gt)
                n_ctx = sum(f is not None for f in (frames.previous, frames.following))
                row = {"set": case.set, "split": case.split, "case": case.name,
                       "t": case.t, "method": name, "kind": kind,
                       "context": n_ctx if use_context else 0, **scores,
                       "seconds": seconds}
                log.info("%s %s %s: PSNR %.2f SSIM %.4f IE %.2f in %.2fs", case.set,
                         case.name, name, scores["psnr"], scores["ssim"], scores["ie"],
                         seconds)
                rows.append(row)
                bar.update(1)
    finally:
        bar.close()
    return rows


def timing_pair(root: str | os.PathLike[str] | None = None,
                shape: tuple[int, int] = TIMING_SHAPE) -> tuple[str, CaseFrames]:
    """The frames of :func:`run_interpolation_timing`, resized (bicubic) to ``shape``.

    MPI-Sintel final/alley_1 frames 9 → 11 with the context frames 7 and 13 when the
    clip is on disk, else Middlebury Urban2 frame10 → frame11 (no context).

    Parameters
    ----------
    root : path-like, optional
        The data folder.
    shape : (int, int)
        (H, W) of the resized frames.

    Returns
    -------
    label : str
    frames : CaseFrames
        uint8 RGB (H, W, 3) frames, writable (``gt`` is the resized true middle frame).

    Raises
    ------
    FileNotFoundError
        Neither pair is on disk.
    """
    from PIL import Image

    base = data_root(root)
    h, w = shape
    sintel = [c for c in _cases_with_timing("sintel", base) if c.name == "frame_0010"]
    if sintel:
        case, label = sintel[0], f"Sintel {SINTEL_PASS}/{SINTEL_CLIP} 9 -> 11"
    else:
        mb = [c for c in _cases_with_timing("middlebury", base) if c.name == "Urban2"]
        if not mb:
            raise FileNotFoundError(
                2, "no timing pair (Sintel alley_1 or Middlebury Urban2) found; pass --data "
                "DIR or set VARFLOW_DATA", str(base))
        case, label = mb[0], "Middlebury Urban2 frame10 -> frame11"
    frames = case.load()

    def resize(a: np.ndarray | None) -> np.ndarray | None:
        if a is None:
            return None
        # a writable, owning copy (np.asarray of a PIL image is a read-only view)
        return np.array(Image.fromarray(a).resize((w, h), Image.Resampling.BICUBIC))

    return f"{label}, resized to {w}x{h}", CaseFrames(*(resize(a) for a in frames))


def _cases_with_timing(set_name: str, root: os.PathLike[str] | str) -> list[
        InterpolationCase]:
    """:func:`~varflow.evaluation.interpolation_sets.interpolation_cases` of every split,
    empty when the set is not on disk; the Sintel list also has the even frames
    (``frame_0010``: 9 → 11, context 7 and 13) used by :func:`timing_pair`."""
    try:
        cases = interpolation_cases(set_name, "all", root)
    except FileNotFoundError:
        return []
    if set_name != "sintel" or not cases:
        return cases
    folder = cases[0].gt.parent

    def frame(n: int) -> Any:
        return folder / f"frame_{n:04d}.png"

    extra = InterpolationCase("sintel", "frame_0010", frame(9), frame(11), frame(10), 0.5,
                              "timing", previous=frame(7), following=frame(13))
    return cases + ([extra] if all(p.is_file() for p in extra.paths) else [])


#: Frames of the clip of :func:`timing_clip` (slow motion x2 of it is timed).
TIMING_CLIP_FRAMES = 6


def timing_clip(root: str | os.PathLike[str] | None = None,
                shape: tuple[int, int] = TIMING_SHAPE,
                n: int = TIMING_CLIP_FRAMES) -> tuple[str, list[np.ndarray]]:
    """The clip of the stream timing, resized (bicubic) to ``shape``.

    MPI-Sintel final/alley_1 frames 5, 7, 9, ... (every second frame, the spacing
    of the Sintel cases) when the clip is on disk, else Middlebury RubberWhale
    frames 07, 08, ...

    Returns
    -------
    label : str
    frames : list of ndarray
        ``n`` uint8 RGB (H, W, 3) frames.

    Raises
    ------
    FileNotFoundError
        Neither clip is on disk.
    """
    from PIL import Image

    from ...io.images import read_image

    base = data_root(root)
    h, w = shape
    sintel = base / "sintel" / "training" / SINTEL_PASS / SINTEL_CLIP
    paths = [sintel / f"frame_{5 + 2 * k:04d}.png" for k in range(n)]
    label = f"Sintel {SINTEL_PASS}/{SINTEL_CLIP} frames 5, 7, ..., {5 + 2 * (n - 1)}"
    if not all(p.is_file() for p in paths):
        rw = base / "middlebury" / "other-data" / "RubberWhale"
        paths = [rw / f"frame{7 + k:02d}.png" for k in range(n)]
        label = f"Middlebury RubberWhale frames 07-{6 + n:02d}"
        if not all(p.is_file() for p in paths):
            raise FileNotFoundError(
                2, "no timing clip (Sintel alley_1 or Middlebury RubberWhale) found; pass "
                "--data DIR or set VARFLOW_DATA", str(base))
    frames = [np.array(Image.fromarray(read_image(p)).resize((w, h), Image.Resampling.BICUBIC))
              for p in paths]
    return f"{label}, resized to {w}x{h}", frames


def _run_stream(name: str, kind: str, frames: list[np.ndarray], params: Any) -> float:
    """Seconds per in-between frame of x2 slow motion of ``frames``."""
    from ...retime.schedule import slowmo_schedule
    from ...retime.stream import retime_frames
    from ..interpolation_peers import minterpolate_stream

    t0 = time.perf_counter()
    if kind == "varflow":
        for _ in retime_frames(frames, slowmo_schedule(len(frames), 2), name, params=params):
            pass
    elif name == BASELINE_PEER:
        minterpolate_stream(frames, 2)
    else:
        for a, b in zip(frames, frames[1:], strict=False):
            INTERPOLATION_PEERS[name](a, b, 0.5)
    return (time.perf_counter() - t0) / (len(frames) - 1)


def run_interpolation_timing(
    methods: str | Sequence[str] | None = None,
    peers: str | Sequence[str] | None = DEFAULT_PEERS,
    root: str | os.PathLike[str] | None = None,
    repeats: int = 3,
    shape: tuple[int, int] = TIMING_SHAPE,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Seconds per frame of every method and peer at 960 × 540, for a pair and in a stream.

    *Pair*: one in-between frame of the two frames of :func:`timing_pair` (no
    context frames), as ``varflow interpolate`` makes it.  *Stream*: x2 slow motion
    of the clip of :func:`timing_clip`, per in-between frame, as ``varflow retime``
    makes it (methods with context get the neighbouring frames and share the
    flows of neighbouring pairs; minterpolate runs once over the clip).  Each runs
    once untimed (JIT compilation, caches, library start-up), then ``repeats``
    times timed; the medians are reported.

    Parameters
    ----------
    methods, peers, overrides
        As :func:`run_interpolation_bench`.
    root : path-like, optional
        The data folder.
    repeats : int
        Timed runs per method (at least 1).
    shape : (int, int)
        (H, W) of the frames (default 540 × 960).
    progress : bool
        A tqdm bar on stderr (only on a terminal).

    Returns
    -------
    list of dict
        One row per method then peer: ``set`` (``"timing"``), ``case`` (the
        pair's label), ``clip`` (the clip's), ``method``, ``kind``, ``seconds``
        (pair, median), ``seconds_min``, ``seconds_stream`` (median per frame of
        the stream), ``repeats``, ``psnr`` (of the pair's frame against the resized
        true frame, for reference), ``ratio_minterpolate`` and
        ``ratio_minterpolate_stream`` (over minterpolate's when it ran, else None).

    Raises
    ------
    ValueError
        Unknown method or peer, ``repeats`` < 1.
    FileNotFoundError
        No timing pair or clip on disk.
    """
    from tqdm import tqdm

    from ..frame_metrics import psnr

    if repeats < 1:
        raise ValueError(f"repeats: must be at least 1, got {repeats}")
    names, peer_names, params = _resolve(methods, peers, overrides)
    label, frames = timing_pair(root, shape)
    clip_label, clip = timing_clip(root, shape)
    runners = [(m, "varflow") for m in names] + [(p, "peer") for p in peer_names]
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(runners) * 2 * (repeats + 1), desc="timing", unit="run",
               file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        for name, kind in runners:
            bar.set_postfix_str(name)
            _run_one(name, kind, frames, 0.5, params.get(name), False)  # untimed
            bar.update(1)
            times = []
            est = None
            for _ in range(repeats):
                est, seconds = _run_one(name, kind, frames, 0.5, params.get(name), False)
                times.append(seconds)
                bar.update(1)
            stream = []
            for k in range(repeats + 1):  # the first untimed
                seconds = _run_stream(name, kind, clip, params.get(name))
                if k:
                    stream.append(seconds)
                bar.update(1)
            rows.append({"set": "timing", "split": None, "case": label, "clip": clip_label,
                         "method": name, "kind": kind, "context": 0,
                         "seconds": statistics.median(times), "seconds_min": min(times),
                         "seconds_stream": statistics.median(stream), "repeats": repeats,
                         "psnr": psnr(est, frames.gt)})
            log.info("timing %s: %.3f s per frame (pair), %.3f (stream)", name,
                     rows[-1]["seconds"], rows[-1]["seconds_stream"])
    finally:
        bar.close()
    base = next((r for r in rows if r["method"] == BASELINE_PEER), None)
    for r in rows:
        r["ratio_minterpolate"] = r["seconds"] / base["seconds"] if base else None
        r["ratio_minterpolate_stream"] = (r["seconds_stream"] / base["seconds_stream"]
                                          if base else None)
    return rows


# --------------------------------------------------------------------------- tables


def _val(row: Mapping[str, Any] | None, key: str) -> float:
    v = None if row is None else row.get(key)
    if v is None or v == "":
        return math.nan
    return float(v)


_MEASURES = (("psnr", "PSNR", 2), ("ssim", "SSIM", 4), ("ie", "IE", 2), ("ne", "NE", 3),
             ("mae", "MAE", 2))

_SET_TITLES = {
    "middlebury": "Middlebury interpolation (frame10, frame11 -> frame10i11)",
    "ucf101": "UCF101 triplets (frame0, frame2 -> frame1)",
    "sintel": f"MPI-Sintel {SINTEL_PASS}/{SINTEL_CLIP} (frames i-1, i+1 -> i, i odd; "
              "context i-3, i+3 for methods that use it)",
    "sintel-x4": f"MPI-Sintel {SINTEL_PASS}/{SINTEL_CLIP} x4 (frames c-2, c+2 -> c-1, c, c+1 "
                 "at t = 1/4, 1/2, 3/4, c = 3, 7, ..., 47; context c-6, c+6)",
}


def _case_table(rows: Sequence[Mapping[str, Any]]) -> str:
    header = ["case", "method"] + [h for _, h, _ in _MEASURES] + ["s"]
    body = [[str(r["case"]), str(r["method"])]
            + [_num(_val(r, k), d) for k, _, d in _MEASURES]
            + [_num(_val(r, "seconds"), 3)] for r in rows]
    return markdown_table(header, body, n_left=2)


def _summary_table(rows: Sequence[Mapping[str, Any]]) -> str:
    methods = list(dict.fromkeys(str(r["method"]) for r in rows))
    cell = {(str(r["case"]), str(r["method"])): r for r in rows}
    cases = list(dict.fromkeys(str(r["case"]) for r in rows))

    def gain(m: str, ref: str) -> str:
        if ref not in methods or m == ref:
            return "-"
        d = [_val(cell.get((c, m)), "psnr") - _val(cell.get((c, ref)), "psnr")
             for c in cases]
        return _num(_nanmean(d), 2)

    def wins(m: str) -> str:
        if BASELINE_PEER not in methods or m == BASELINE_PEER:
            return "-"
        both = _against_baseline(cell, cases, m)
        return f"{sum(a > b for _, a, b in both)}/{len(both)}"

    header = (["method", "n", "PSNR", "worst 10 %"] + [h for _, h, _ in _MEASURES[1:]]
              + [f"dPSNR vs {BASELINE_PEER}", f"dPSNR vs {BASELINE_METHOD}",
                 f"wins vs {BASELINE_PEER}", "s/frame (median)"])
    body = []
    for m in methods:
        mine = [cell[(c, m)] for c in cases if (c, m) in cell]
        secs = [_val(r, "seconds") for r in mine]
        secs = [s for s in secs if math.isfinite(s)]
        means = [_num(_nanmean([_val(r, k) for r in mine]), d) for k, _, d in _MEASURES]
        body.append([m, str(len(mine)), means[0],
                     _num(worst_decile([_val(r, "psnr") for r in mine]), 2)] + means[1:]
                    + [gain(m, BASELINE_PEER), gain(m, BASELINE_METHOD), wins(m),
                       _num(statistics.median(secs) if secs else math.nan, 3)])
    return markdown_table(header, body)


def worst_decile(values: Sequence[float]) -> float:
    """The mean of the worst 10 % of ``values`` (the lowest ``ceil(n / 10)``, NaN left
    out): what a user retiming a clip sees on its worst frames.  NaN when none."""
    finite = sorted(v for v in values if math.isfinite(v))
    if not finite:
        return math.nan
    k = math.ceil(len(finite) / 10)
    return float(np.mean(finite[:k]))


def _against_baseline(cell: Mapping[tuple[str, str], Mapping[str, Any]],
                      cases: Sequence[str], method: str) -> list[tuple[str, float, float]]:
    """``(case, PSNR of method, PSNR of the baseline peer)`` for the cases where both
    ran (``cell`` keyed by ``(case, method)``)."""
    out = []
    for c in cases:
        a, b = _val(cell.get((c, method)), "psnr"), _val(cell.get((c, BASELINE_PEER)), "psnr")
        if not (math.isnan(a) or math.isnan(b)):
            out.append((c, a, b))
    return out


def _losses(rows: Sequence[Mapping[str, Any]]) -> str:
    """The cases each varflow method loses against the baseline peer (its PSNR not
    above the peer's): one line per method, ``case (method / peer dB)``."""
    cell = {(str(r["case"]), str(r["method"])): r for r in rows}
    cases = list(dict.fromkeys(str(r["case"]) for r in rows))
    lines = []
    for m in dict.fromkeys(str(r["method"]) for r in rows if r.get("kind") == "varflow"):
        lost = [f"{c} ({a:.2f} / {b:.2f})" for c, a, b in _against_baseline(cell, cases, m)
                if not a > b]
        lines.append(f"- `{m}`: {', '.join(lost) if lost else 'none'}")
    return "\n".join(lines)


def format_timing_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """The timing table of :func:`run_interpolation_timing` rows (titled)."""
    if not rows:
        return "(no timing)"
    r0 = rows[0]
    title = (f"Timing: seconds per in-between frame, median of {r0.get('repeats', '?')} "
             f"runs after an untimed one; pair: {r0['case']} (two frames, no context); "
             f"stream: x2 slow motion of {r0.get('clip', '?')}")
    body = [[str(r["method"]), str(r["kind"]), _num(_val(r, "seconds"), 3),
             _num(_val(r, "ratio_minterpolate"), 2), _num(_val(r, "seconds_stream"), 3),
             _num(_val(r, "ratio_minterpolate_stream"), 2)]
            for r in rows]
    header = ["method", "kind", "pair s/frame", f"pair x {BASELINE_PEER}",
              "stream s/frame", f"stream x {BASELINE_PEER}"]
    return title + "\n\n" + markdown_table(header, body, n_left=2)


def format_tables(rows: Sequence[Mapping[str, Any]],
                  timing: Sequence[Mapping[str, Any]] | None = None,
                  per_case: bool = True) -> str:
    """Markdown tables of :func:`run_interpolation_bench` rows (and timing rows).

    Per set (in :data:`INTERPOLATION_SETS` order), a title, then (``per_case``) the
    per-case table: a line per (case, method) with PSNR (dB), SSIM, IE, NE, MAE
    (0-255) and seconds; then the summary (and, for a set whose cases have several
    times ``t``, one summary per time): per method the number of cases ``n``,
    the mean of each measure and the mean PSNR of the worst 10 % of the cases
    (:func:`worst_decile`), ``dPSNR vs minterpolate`` and ``dPSNR vs naive`` (the
    mean over the cases of the method's PSNR minus the reference's; "-" when the
    reference did not run), ``wins vs minterpolate`` (cases with a strictly higher
    PSNR than minterpolate, of those both ran) and the median seconds per frame;
    after the set's summary, the cases each varflow method loses against
    minterpolate (when both ran).  Then the timing table
    (:func:`format_timing_table`) when ``timing`` is given.

    Parameters
    ----------
    rows : sequence of mapping
        Rows of :func:`run_interpolation_bench` (or read back from its CSV).
    timing : sequence of mapping, optional
        Rows of :func:`run_interpolation_timing`.
    per_case : bool
        Include the per-case tables.

    Returns
    -------
    str
        The tables separated by blank lines, without a trailing newline.
    """
    parts: list[str] = []
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault(str(r["set"]), []).append(r)
    order = {s: i for i, s in enumerate(INTERPOLATION_SETS)}
    for set_name in sorted(groups, key=lambda s: (order.get(s, len(order)), s)):
        group = groups[set_name]
        present = {str(r.get("split") or "") for r in group}
        splits = [s for s in ("tuning", "reporting") if s in present]
        n = len({str(r["case"]) for r in group})
        plural = "s" if n != 1 else ""
        title = (f"{_SET_TITLES.get(set_name, set_name)}: {n} case{plural}, split "
                 f"{' + '.join(splits) or '-'}")
        if per_case:
            parts.append(f"{title}, per case\n\n{_case_table(group)}")
        parts.append(f"{title}, means\n\n{_summary_table(group)}")
        if any(str(r["method"]) == BASELINE_PEER for r in group) and any(
                r.get("kind") == "varflow" for r in group):
            parts.append(f"{title}, cases lost against {BASELINE_PEER} (PSNR of the "
                         f"method / {BASELINE_PEER})\n\n{_losses(group)}")
        times = sorted({t for t in (_val(r, "t") for r in group) if math.isfinite(t)})
        if len(times) > 1:  # one summary per time (the x4 protocol)
            for t in times:
                at_t = [r for r in group if _val(r, "t") == t]
                parts.append(f"{title}, means at t = {t:g}\n\n{_summary_table(at_t)}")
    if timing:
        parts.append(format_timing_table(timing))
    return "\n\n".join(parts) if parts else "(no results)"
