"""Trajectory methods scored on real sequences: Middlebury RubberWhale and Sintel snippets.

There is no public dense *trajectory* ground truth on real images, so the
multi-frame methods are scored the way the book does it: on the one pair of the
sequence that has two-frame ground truth.

* :func:`run_middlebury_multiframe` — every trajectory method of
  :data:`varflow.registry.TRACKERS` runs on the 8 frames ``frame07 … frame14`` of
  RubberWhale with the reference ``frame10`` (index 3); the displacement it gives
  frame11 (index 4) is compared with ``flow10.flo`` (frame10 → frame11) over the
  pixels with known ground truth: AEE and AAE.  A row ``tvl1 (two-frame)``
  (``varflow.flow(frame10, frame11, "tvl1")`` with default parameters) is the pair
  baseline.
* :func:`run_sintel_multiframe` — the same on every MPI-Sintel snippet found on disk
  (runs of consecutive frames, 4 per clip and pass here); a report, without bounds.
  The reference of a snippet is the frame N whose ground truth ``frame_N.flo``
  (N → N + 1) exists with frame N + 1 in the snippet, preferring one that has an
  occlusion mask (so the non-occluded AEE can be given): frame_0002 of a
  0001–0004 snippet, i.e. index 1, with one frame before and two after.  AEE over
  all valid pixels (the ``invalid`` mask removed when present) and over the
  non-occluded ones.

:func:`format_multiframe_table` prints the rows as a Markdown table, one line per
(sequence, method), with each method's AEE relative to the ``tvl1`` pair baseline of
the same sequence.

The book's Table 4.1 protocol on real footage (Gibson & Marques 2016) runs on the
whole 50-frame MPI-Sintel clip ``final/alley_1``:

* :func:`run_sintel_trajectories` — for every reference frame r (5 … 10 by default)
  and every window of the clip around r (9, 13 and 19 frames placed by
  :func:`protocol_window`, plus the whole clip), every trajectory method tracks r's
  pixels through the window; its displacement in frame r + 1 is scored against
  ``flow/alley_1/frame_r.flo``.  :func:`plan_sintel_protocol` checks the
  arguments against the data on disk before any work, and
  :func:`format_protocol_table` prints one line per (reference, window) with each
  method's AEE and its ratio to ``twoframe``, the means, and at how many references
  each method beats ``twoframe``.
"""

from __future__ import annotations

import logging
import math
import operator
import os
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...registry import TRACKERS
from ..datasets import (
    _HINT,
    SINTEL_PASSES,
    _mask,
    _nan_unknown,
    _require,
    _rgb,
    data_root,
    load_middlebury_pair,
)
from .common import markdown_table, spec_name
from .trajectories import tracker_params

__all__ = [
    "BASELINE_LABEL",
    "DEFAULT_METHODS",
    "RUBBERWHALE_FRAMES",
    "RUBBERWHALE_REF",
    "SintelSnippet",
    "default_methods",
    "load_rubberwhale_clip",
    "sintel_snippets",
    "run_middlebury_multiframe",
    "run_sintel_multiframe",
    "format_multiframe_table",
    "PROTOCOL_CLIP",
    "PROTOCOL_PASS",
    "PROTOCOL_METHODS",
    "PROTOCOL_REFS",
    "PROTOCOL_WINDOWS",
    "SHARED_METHODS",
    "ProtocolWindow",
    "protocol_window",
    "protocol_windows",
    "sintel_clip_numbers",
    "plan_sintel_protocol",
    "run_sintel_trajectories",
    "format_protocol_table",
]

log = logging.getLogger(__name__)

#: Method label of the two-frame baseline rows.
BASELINE_LABEL = "tvl1 (two-frame)"

#: Preferred trajectory method specs, in table order (:func:`~varflow.evaluation.bench.
#: common.method_spec`): rlr, rlr decoupled (τ = 0), mfsf, the library's two-frame flow
#: from the reference (default method and ``tvl1-ld``) and chained;
#: :func:`default_methods` keeps the registered ones.
DEFAULT_METHODS: tuple[str, ...] = ("rlr", "rlr:link_weight=0", "mfsf", "twoframe",
                                    "twoframe:tvl1-ld", "chain")

#: Frame numbers of the RubberWhale clip and the index of the reference (frame10).
RUBBERWHALE_FRAMES: tuple[int, ...] = tuple(range(7, 15))
RUBBERWHALE_REF = RUBBERWHALE_FRAMES.index(10)

Crop = tuple[int, int, int, int]


def default_methods() -> list[str]:
    """The registered ones of :data:`DEFAULT_METHODS`, in that order."""
    return [m for m in DEFAULT_METHODS if spec_name(m) in TRACKERS]


def load_rubberwhale_clip(
    root: str | os.PathLike[str] | None = None,
) -> tuple[np.ndarray, int, np.ndarray]:
    """The 8-frame RubberWhale clip with the ground truth of its reference pair.

    Parameters
    ----------
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.

    Returns
    -------
    frames : ndarray, shape (8, H, W, 3), uint8
        ``middlebury/other-data/RubberWhale/frame07.png`` … ``frame14.png``.
    ref : int
        Index of frame10 in ``frames`` (3).
    gt : ndarray, shape (H, W, 2), float32
        ``middlebury/other-gt-flow/RubberWhale/flow10.flo`` (frame10 → frame11, as read
        by :func:`~varflow.evaluation.datasets.load_middlebury_pair`); unknown
        pixels are NaN.

    Raises
    ------
    FileNotFoundError
        A frame or the flow file is missing (the message says how to point at the data).
    ValueError
        Frames of different sizes, or frame10/11 differing from the pair loader's.
    """
    from ...io.images import read_image

    base = data_root(root)
    d = base / "middlebury" / "other-data" / "RubberWhale"
    paths = [_require(d / f"frame{n:02d}.png", f"Middlebury RubberWhale frame{n:02d}", base)
             for n in RUBBERWHALE_FRAMES]
    f10, f11, gt = load_middlebury_pair("RubberWhale", base)
    frames = [_rgb(read_image(p)) for p in paths]
    shapes = {f.shape for f in frames}
    if len(shapes) != 1:
        raise ValueError(f"Middlebury RubberWhale: frames of different sizes {sorted(shapes)}")
    clip = np.stack(frames)
    ref = RUBBERWHALE_REF
    if not (np.array_equal(clip[ref], f10) and np.array_equal(clip[ref + 1], f11)):
        raise ValueError("Middlebury RubberWhale: frame10/frame11 differ from the pair loader's")
    return clip, ref, gt


@dataclass(frozen=True)
class SintelSnippet:
    """A run of consecutive Sintel training frames with the reference pair chosen.

    Attributes
    ----------
    clip : str
    pass_ : str
        ``"clean"`` or ``"final"``.
    numbers : tuple of int
        Frame numbers N of ``frame_NNNN.png``, consecutive.
    ref : int
        Index into ``numbers`` of the reference; ``frame_{numbers[ref]}.flo`` exists.
    """

    clip: str
    pass_: str
    numbers: tuple[int, ...]
    ref: int

    @property
    def name(self) -> str:
        return f"{self.clip} {self.numbers[0]:04d}-{self.numbers[-1]:04d}"

    @property
    def pair(self) -> str:
        n = self.numbers[self.ref]
        return f"{n:04d}->{n + 1:04d}"


def _runs(numbers: Sequence[int]) -> list[tuple[int, ...]]:
    runs: list[list[int]] = []
    for n in sorted(numbers):
        if runs and n == runs[-1][-1] + 1:
            runs[-1].append(n)
        else:
            runs.append([n])
    return [tuple(r) for r in runs]


def sintel_snippets(
    root: str | os.PathLike[str] | None = None,
    passes: Sequence[str] = SINTEL_PASSES,
    clips: Sequence[str] | None = None,
    before: int = 1,
    after: int = 2,
) -> list[SintelSnippet]:
    """The Sintel snippets on disk that have ground truth for one of their pairs.

    In every maximal run of consecutive ``frame_NNNN.png`` of one clip and pass,
    the reference N is the first frame with ``flow/<clip>/frame_N.flo`` and N + 1
    in the run that also has an occlusion mask, else the first with the flow
    alone; runs without any such N are skipped.  The snippet is the window of the
    run from ``before`` frames before N to ``after`` frames after it (shorter at
    the ends of the run): frames 0001-0004 around 0002 by default, also on a clip
    whose whole 50 frames are on disk.

    Parameters
    ----------
    root : path-like, optional
    passes : sequence of {"clean", "final"}
    clips : sequence of str, optional
        Restrict to these clip names.
    before, after : int
        Frames kept before the reference and after it (``after`` >= 1).

    Returns
    -------
    list of SintelSnippet
        Sorted by pass, clip and first frame.
    """
    for p in passes:
        if p not in SINTEL_PASSES:
            raise ValueError(f"passes: expected some of {SINTEL_PASSES}, got {p!r}")
    if before < 0 or after < 1:
        raise ValueError(f"before, after: need before >= 0 and after >= 1, got {before}, {after}")
    tr = data_root(root) / "sintel" / "training"
    out = []
    for p in passes:
        if not (tr / p).is_dir():
            continue
        for d in sorted(x for x in (tr / p).iterdir() if x.is_dir()):
            if clips is not None and d.name not in clips:
                continue
            numbers = []
            for f in d.glob("frame_*.png"):
                try:
                    numbers.append(int(f.stem.split("_")[1]))
                except (IndexError, ValueError):
                    continue
            for run in _runs(numbers):
                cands = [i for i, n in enumerate(run[:-1])
                         if (tr / "flow" / d.name / f"frame_{n:04d}.flo").is_file()]
                if not cands:
                    continue
                masked = [i for i in cands
                          if (tr / "occlusions" / d.name / f"frame_{run[i]:04d}.png").is_file()]
                i = (masked or cands)[0]
                lo = max(0, i - before)
                out.append(SintelSnippet(d.name, p, run[lo:i + after + 1], i - lo))
    return out


def _load_snippet(
    s: SintelSnippet, root: Path
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    from ...io.flo import read_flo
    from ...io.images import read_image

    tr = root / "sintel" / "training"
    what = f"Sintel {s.pass_}/{s.clip}"
    frames = np.stack([
        _rgb(read_image(_require(tr / s.pass_ / s.clip / f"frame_{n:04d}.png",
                                 f"{what} frame_{n:04d}", root)))
        for n in s.numbers
    ])
    n = s.numbers[s.ref]
    gt = _nan_unknown(read_flo(_require(tr / "flow" / s.clip / f"frame_{n:04d}.flo",
                                        f"{what} flow", root)))
    if gt.shape[:2] != frames.shape[1:3]:
        raise ValueError(f"{what}: flow {gt.shape} does not match the frames {frames.shape}")
    occ = _mask(tr / "occlusions" / s.clip / f"frame_{n:04d}.png")
    inv = _mask(tr / "invalid" / s.clip / f"frame_{n:04d}.png")
    return frames, gt, occ, inv


def _crop(a: np.ndarray | None, crop: Crop | None, lead: int = 0) -> np.ndarray | None:
    if a is None or crop is None:
        return a
    y0, y1, x0, x1 = crop
    idx = (slice(None),) * lead + (slice(y0, y1), slice(x0, x1))
    return np.ascontiguousarray(a[idx])


def _check_crop(crop: Crop | None) -> Crop | None:
    if crop is None:
        return None
    try:
        y0, y1, x0, x1 = (int(v) for v in crop)
    except (TypeError, ValueError):
        raise ValueError(f"crop: expected (y0, y1, x0, x1), got {crop!r}") from None
    if not (0 <= y0 < y1 and 0 <= x0 < x1):
        raise ValueError(f"crop: need 0 <= y0 < y1 and 0 <= x0 < x1, got {crop!r}")
    return y0, y1, x0, x1


def _check_crop_fits(crop: Crop | None, shape: tuple[int, ...], what: str) -> None:
    if crop is not None and (crop[1] > shape[0] or crop[3] > shape[1]):
        raise ValueError(f"crop: {crop} exceeds the {shape[1]}x{shape[0]} frames of {what} "
                         f"(crop is y0, y1, x0, x1)")


def _warm_up(methods: Sequence[str], params: Mapping[str, Any], baseline: bool) -> None:
    """Run every method once on a tiny synthetic clip so JIT compilation is not timed."""
    import varflow

    from ...generators.pairs import synthetic_pair

    f0, f1, _ = synthetic_pair("translation", shape=(48, 64), magnitude=1.0, seed=0)
    if baseline:
        varflow.flow(f0, f1, "tvl1")
    for m in methods:
        try:
            varflow.track(np.stack([f0, f1, f0]), 1, spec_name(m), params=params[m])
        except Exception as exc:  # noqa: BLE001 - a warm-up only; the real run reports
            log.warning("warm-up of %s failed (%s); its time includes compilation", m, exc)


def _score(est: np.ndarray, gt: np.ndarray, valid: np.ndarray | None,
           occ: np.ndarray | None) -> dict[str, float]:
    from ..metrics import endpoint_error, evaluate

    s = evaluate(est, gt, mask=valid)
    noc = None
    if occ is not None:
        noc = float(endpoint_error(est, gt, mask=~occ if valid is None else valid & ~occ))
    return {"aee": float(s["aee"]), "aae": float(s["aae"]), "aee_noc": noc}


def _run_clip(
    rows: list[dict[str, Any]],
    base: Mapping[str, Any],
    frames: np.ndarray,
    ref: int,
    gt: np.ndarray,
    valid: np.ndarray | None,
    occ: np.ndarray | None,
    methods: Sequence[str],
    params: Mapping[str, Any],
    baseline: bool,
    bar: Any,
) -> None:
    import varflow

    label = f"{base['dataset']} {base['sequence']}"
    for m in methods:
        bar.set_postfix_str(f"{label} {m}")
        t0 = time.perf_counter()
        traj = varflow.track(frames, ref, spec_name(m), params=params[m])
        seconds = time.perf_counter() - t0
        row = {**base, "method": m, **_score(traj[ref + 1], gt, valid, occ),
               "seconds": seconds}
        log.info("%s %s: AEE %.4f AAE %.3f in %.2fs", label, m, row["aee"], row["aae"], seconds)
        rows.append(row)
        bar.update(1)
    if baseline:
        bar.set_postfix_str(f"{label} tvl1")
        t0 = time.perf_counter()
        est = varflow.flow(frames[ref], frames[ref + 1], "tvl1")
        seconds = time.perf_counter() - t0
        row = {**base, "method": BASELINE_LABEL, **_score(est, gt, valid, occ),
               "seconds": seconds}
        log.info("%s tvl1 pair: AEE %.4f AAE %.3f in %.2fs", label, row["aee"], row["aae"],
                 seconds)
        rows.append(row)
        bar.update(1)


def run_middlebury_multiframe(
    methods: Sequence[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    *,
    root: str | os.PathLike[str] | None = None,
    baseline: bool = True,
    crop: Crop | None = None,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Trajectory methods on the 8-frame RubberWhale clip, scored on frame10 → frame11.

    Every method tracks the pixels of frame10 (reference, index 3) through
    ``frame07 … frame14``; its displacement in frame11 is compared with
    ``flow10.flo`` over the pixels with known ground truth (AEE, AAE).  Each method
    first runs once on a tiny synthetic clip (not timed) so ``seconds`` — the wall
    time of :func:`varflow.track` alone — excludes Numba compilation.

    Parameters
    ----------
    methods : sequence of str, optional
        Names from :data:`varflow.registry.TRACKERS`; :func:`default_methods` when None.
    overrides : mapping, optional
        ``{field: value}`` applied to every method that has the field, or
        ``{method: {field: value}}``; see :func:`varflow.evaluation.bench.common.split_overrides`.
        The baseline always uses the default ``tvl1`` parameters.
    progress : bool
        A tqdm bar on stderr (only on a terminal).
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.
    baseline : bool
        Add the row ``tvl1 (two-frame)``: ``varflow.flow(frame10, frame11, "tvl1")``.
    crop : (y0, y1, x0, x1), optional
        Score a window of the clip only (frames and ground truth cropped before
        running; for quick tests); it must lie inside the frames.
    warm_up : bool
        Do the untimed warm-up run.

    Returns
    -------
    list of dict
        One row per method, then the baseline: ``dataset`` ("middlebury"),
        ``sequence`` ("RubberWhale"), ``pair`` ("frame10->frame11"), ``ref`` (3),
        ``frames`` (8), ``method``, ``aee`` (px), ``aae`` (degrees), ``aee_noc``
        (None: Middlebury has no occlusion masks), ``seconds``.

    Raises
    ------
    ValueError
        Unknown method or parameter, invalid parameter value or crop.
    FileNotFoundError
        When the data are missing.
    """
    from tqdm import tqdm

    methods, params = tracker_params(default_methods() if methods is None else methods,
                                       overrides)
    crop = _check_crop(crop)
    frames, ref, gt = load_rubberwhale_clip(root)
    _check_crop_fits(crop, frames.shape[1:3], "Middlebury RubberWhale")
    frames, gt = _crop(frames, crop, lead=1), _crop(gt, crop)
    if warm_up:
        _warm_up(methods, params, baseline)
    rows: list[dict[str, Any]] = []
    base = {"dataset": "middlebury", "sequence": "RubberWhale", "pair": "frame10->frame11",
            "ref": ref, "frames": int(frames.shape[0])}
    bar = tqdm(total=len(methods) + int(baseline), desc="middlebury-multiframe", unit="run",
               file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        _run_clip(rows, base, frames, ref, gt, None, None, methods, params, baseline, bar)
    finally:
        bar.close()
    return rows


def run_sintel_multiframe(
    methods: Sequence[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    *,
    root: str | os.PathLike[str] | None = None,
    snippets: Sequence[SintelSnippet] | None = None,
    passes: Sequence[str] = SINTEL_PASSES,
    clips: Sequence[str] | None = None,
    baseline: bool = True,
    crop: Crop | None = None,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Trajectory methods on the MPI-Sintel snippets, scored on their reference pair.

    A report, without bounds.  For every snippet of :func:`sintel_snippets` each
    method tracks the reference frame's pixels through the snippet's frames; its
    displacement in the next frame is compared with ``frame_N.flo``: AEE and AAE over
    the valid pixels (pixels of the ``invalid`` mask removed when there is one) and
    the AEE over the non-occluded ones when there is an occlusion mask.

    Parameters
    ----------
    methods, overrides, progress, root, baseline, crop, warm_up
        As in :func:`run_middlebury_multiframe` (the baseline is ``tvl1`` from the
        reference to the next frame).
    snippets : sequence of SintelSnippet, optional
        What to run; by default ``sintel_snippets(root, passes, clips)``.
    passes, clips
        Selection passed to :func:`sintel_snippets`.

    Returns
    -------
    list of dict
        Rows as in :func:`run_middlebury_multiframe` with ``dataset``
        ``"sintel-<pass>"``, ``sequence`` ``"<clip> NNNN-MMMM"``, ``pair``
        ``"NNNN->NNNN+1"`` and ``aee_noc`` (None without an occlusion mask).

    Raises
    ------
    ValueError
        Unknown method, parameter or pass.
    FileNotFoundError
        When no snippet with ground truth is found (or a file is missing).
    """
    from tqdm import tqdm

    methods, params = tracker_params(default_methods() if methods is None else methods,
                                       overrides)
    crop = _check_crop(crop)
    base_dir = data_root(root)
    if snippets is None:
        snippets = sintel_snippets(base_dir, passes=passes, clips=clips)
    snippets = list(snippets)
    if not snippets:
        raise FileNotFoundError(
            f"no Sintel snippet with ground truth under {base_dir / 'sintel' / 'training'}; "
            f"{_HINT}"
        )
    if warm_up:
        _warm_up(methods, params, baseline)
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(snippets) * (len(methods) + int(baseline)), desc="sintel-multiframe",
               unit="run", file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        for s in snippets:
            frames, gt, occ, inv = _load_snippet(s, base_dir)
            frames, gt = _crop(frames, crop, lead=1), _crop(gt, crop)
            occ, inv = _crop(occ, crop), _crop(inv, crop)
            base = {"dataset": f"sintel-{s.pass_}", "sequence": s.name, "pair": s.pair,
                    "ref": s.ref, "frames": len(s.numbers)}
            valid = None if inv is None else ~inv
            _run_clip(rows, base, frames, s.ref, gt, valid, occ, methods, params, baseline, bar)
    finally:
        bar.close()
    return rows


def _fmt(value: Any, digits: int) -> str:
    if value is None or value == "":
        return "-"
    v = float(value)
    return "-" if math.isnan(v) else f"{v:.{digits}f}"


def format_multiframe_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table, one line per (dataset, sequence, method).

    Columns: dataset, sequence, scored pair, reference index / number of frames,
    method, AEE, AAE (degrees), AEE over non-occluded pixels ("-" without occlusion
    mask), seconds, and the ratio of the AEE to the ``tvl1 (two-frame)`` baseline of
    the same sequence (< 1: the trajectory method beats the pair flow).  When several
    sequences are present, a ``mean`` line per method follows (over the sequences
    where it ran).

    Parameters
    ----------
    rows : sequence of mapping
        As returned by :func:`run_middlebury_multiframe` / :func:`run_sintel_multiframe`.

    Returns
    -------
    str
        The table, without a trailing newline.
    """
    if not rows:
        return "(no results)"
    base_aee = {(r["dataset"], r["sequence"]): r["aee"] for r in rows
                if r["method"] == BASELINE_LABEL}

    def ratio(r: Mapping[str, Any]) -> float | None:
        b = base_aee.get((r["dataset"], r["sequence"]))
        if b is None or r.get("aee") is None:
            return None
        b = float(b)
        return float(r["aee"]) / b if b > 0 else None

    header = ["dataset", "sequence", "pair", "ref/F", "method", "AEE", "AAE", "AEE noc", "s",
              "AEE / tvl1 pair"]
    body = []
    for r in rows:
        ref_f = f"{r['ref']}/{r['frames']}" if "ref" in r and "frames" in r else "-"
        body.append([str(r["dataset"]), str(r["sequence"]), str(r.get("pair", "-")), ref_f,
                     str(r["method"]), _fmt(r.get("aee"), 4), _fmt(r.get("aae"), 3),
                     _fmt(r.get("aee_noc"), 4), _fmt(r.get("seconds"), 2),
                     _fmt(ratio(r), 3)])
    n_left = 5
    seqs = {(r["dataset"], r["sequence"]) for r in rows}
    if len(seqs) > 1:
        methods: list[str] = []
        for r in rows:
            if r["method"] not in methods:
                methods.append(r["method"])

        def mean(vals: list[Any]) -> float | None:
            v = [float(x) for x in vals if x is not None and x != ""
                 and not math.isnan(float(x))]
            return float(np.mean(v)) if v else None

        for m in methods:
            mine = [r for r in rows if r["method"] == m]
            body.append(["mean", f"{len(mine)} sequences", "", "", m,
                         _fmt(mean([r.get("aee") for r in mine]), 4),
                         _fmt(mean([r.get("aae") for r in mine]), 3),
                         _fmt(mean([r.get("aee_noc") for r in mine]), 4),
                         _fmt(mean([r.get("seconds") for r in mine]), 2),
                         _fmt(mean([ratio(r) for r in mine]), 3)])
    return markdown_table(header, body, n_left)


# ----------------------------------------------------------------------------- Table 4.1 protocol

#: Clip and pass of the Table 4.1 protocol: the whole 50-frame clip is on disk.
PROTOCOL_CLIP = "alley_1"
PROTOCOL_PASS = "final"

#: Default trajectory methods, reference frame numbers (1-based, as in the file names)
#: and window lengths of :func:`run_sintel_trajectories`.
PROTOCOL_METHODS: tuple[str, ...] = ("twoframe", "twoframe:tvl1-ld", "mfsf",
                                     "rlr:link_weight=0", "rlr")
PROTOCOL_REFS: tuple[int, ...] = (5, 6, 7, 8, 9, 10)
PROTOCOL_WINDOWS: tuple[int, ...] = (9, 13, 19)

#: The method the others are compared with by :func:`format_protocol_table`.
PROTOCOL_BASELINE = "twoframe"

#: Methods whose estimate of frame r + 1 does not depend on the window: the two-frame
#: flow from r to r + 1 for ``twoframe`` (any ``flow_method``).
#: :func:`run_sintel_trajectories` runs them once per reference on the two frames
#: r, r + 1 and reuses the result for every window.
SHARED_METHODS: frozenset[str] = frozenset({"twoframe"})


def _as_int(value: Any, name: str) -> int:
    if isinstance(value, bool):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    try:
        return operator.index(value)
    except TypeError:
        raise ValueError(f"{name}: expected an integer, got {value!r}") from None


def _spans(numbers: Sequence[int]) -> str:
    """``"0001-0010, 0012"`` for the frame numbers ``numbers``."""
    return ", ".join(f"{r[0]:04d}" if len(r) == 1 else f"{r[0]:04d}-{r[-1]:04d}"
                     for r in _runs(numbers)) or "none"


@dataclass(frozen=True)
class ProtocolWindow:
    """Frames ``first … last`` of a clip (1-based numbers, inclusive) around a reference.

    Attributes
    ----------
    ref : int
        Frame number r of the reference; ``first <= ref < last`` so that the scored
        frame r + 1 is in the window.
    first, last : int
        First and last frame number of the window.
    length : int or None
        The requested length ``last - first + 1``; None for the whole clip.
    """

    ref: int
    first: int
    last: int
    length: int | None

    @property
    def n_frames(self) -> int:
        """Number of frames in the window."""
        return self.last - self.first + 1

    @property
    def ref_index(self) -> int:
        """Index of the reference in the window's frames."""
        return self.ref - self.first

    @property
    def numbers(self) -> tuple[int, ...]:
        """The frame numbers ``first … last``."""
        return tuple(range(self.first, self.last + 1))

    @property
    def label(self) -> str:
        """``"9: 0001-0009"``, or ``"whole: 0001-0050"`` for the whole clip."""
        kind = "whole" if self.length is None else str(self.length)
        return f"{kind}: {self.first:04d}-{self.last:04d}"


def protocol_window(ref: int, length: int | None, first: int, last: int) -> ProtocolWindow:
    """The window of ``length`` frames around reference ``ref`` in the clip ``first … last``.

    The window is centred on r as far as the clip allows: frames
    ``r − (L − 1) // 2 … r + L // 2`` (for an even L one frame more after r than
    before it, so that L = 2 gives r, r + 1), shifted inward by as many frames as it
    sticks out at the clip's start or end.  It always lies inside the clip and
    contains r and r + 1.

    Parameters
    ----------
    ref : int
        Reference frame number r, ``first <= r <= last - 1``.
    length : int or None
        Window length L, ``2 <= L <= last - first + 1``; None for the whole clip.
    first, last : int
        Frame numbers of the clip's first and last frame.

    Returns
    -------
    ProtocolWindow

    Raises
    ------
    ValueError
        A reference outside ``first … last - 1``, a length below 2 or above the
        clip's number of frames.
    """
    ref, first, last = (_as_int(v, n) for v, n in ((ref, "ref"), (first, "first"),
                                                    (last, "last")))
    n = last - first + 1
    if n < 2:
        raise ValueError(f"clip: need at least 2 frames, got {first:04d}-{last:04d}")
    if not first <= ref < last:
        raise ValueError(f"refs: reference frame {ref} must be in {first}..{last - 1} for the "
                         f"clip's frames {first:04d}-{last:04d} (frame r + 1 is scored)")
    if length is None:
        return ProtocolWindow(ref, first, last, None)
    length = _as_int(length, "windows")
    if length < 2:
        raise ValueError(f"windows: a window needs at least 2 frames (r and r + 1), "
                         f"got {length}")
    if length > n:
        raise ValueError(f"windows: length {length} exceeds the {n} frames of the clip "
                         f"({first:04d}-{last:04d})")
    lo = ref - (length - 1) // 2
    lo = min(max(lo, first), last - length + 1)
    return ProtocolWindow(ref, lo, lo + length - 1, length)


def protocol_windows(
    ref: int,
    lengths: Sequence[int],
    first: int,
    last: int,
    include_whole: bool = True,
) -> list[ProtocolWindow]:
    """The windows of :func:`protocol_window` for every length, then the whole clip.

    Parameters
    ----------
    ref : int
        Reference frame number r.
    lengths : sequence of int
        Window lengths (repeats are dropped, the order is kept).
    first, last : int
        Frame numbers of the clip's first and last frame.
    include_whole : bool
        Add the whole clip ``first … last`` as the last window.

    Returns
    -------
    list of ProtocolWindow

    Raises
    ------
    ValueError
        As :func:`protocol_window`, or no window at all.
    """
    out = [protocol_window(ref, n, first, last) for n in dict.fromkeys(lengths)]
    if include_whole:
        out.append(protocol_window(ref, None, first, last))
    if not out:
        raise ValueError("windows: give at least one window length or include the whole clip")
    return out


def _check_pass(pass_: str) -> None:
    if pass_ not in SINTEL_PASSES:
        raise ValueError(f"pass_: expected one of {SINTEL_PASSES}, got {pass_!r}")


def sintel_clip_numbers(
    root: str | os.PathLike[str] | None = None,
    clip: str = PROTOCOL_CLIP,
    pass_: str = PROTOCOL_PASS,
) -> tuple[int, ...]:
    """Frame numbers N of the ``frame_NNNN.png`` of a Sintel training clip on disk.

    Parameters
    ----------
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.
    clip : str
    pass_ : {"clean", "final"}

    Returns
    -------
    tuple of int
        Sorted (1 … 50 for the whole ``final/alley_1``).

    Raises
    ------
    ValueError
        Unknown pass.
    FileNotFoundError
        No frame of the clip (the message says how to point at the data).
    """
    _check_pass(pass_)
    base = data_root(root)
    d = base / "sintel" / "training" / pass_ / clip
    numbers = []
    for f in d.glob("frame_*.png") if d.is_dir() else ():
        try:
            numbers.append(int(f.stem.split("_")[1]))
        except (IndexError, ValueError):
            continue
    if not numbers:
        raise FileNotFoundError(f"Sintel {pass_}/{clip} frames not found: {d}/frame_NNNN.png "
                                f"(data root {base}); {_HINT}")
    return tuple(sorted(numbers))


def plan_sintel_protocol(
    root: str | os.PathLike[str] | None = None,
    *,
    clip: str = PROTOCOL_CLIP,
    pass_: str = PROTOCOL_PASS,
    refs: Sequence[int] = PROTOCOL_REFS,
    windows: Sequence[int] = PROTOCOL_WINDOWS,
    include_whole: bool = True,
) -> dict[int, list[ProtocolWindow]]:
    """Check the protocol's arguments against the data on disk and place the windows.

    The clip is the run of consecutive frames on disk that holds the references
    (the whole 50 frames of ``final/alley_1``); every reference r needs frame r + 1
    in it and the ground truth ``flow/<clip>/frame_r.flo``.  Nothing is read but
    the file names, so a caller can fail fast before a long run.

    Parameters
    ----------
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.
    clip, pass_ : str
        Sintel training clip and pass.
    refs : sequence of int
        Reference frame numbers r (repeats are dropped, the order is kept).
    windows : sequence of int
        Window lengths, each >= 2; see :func:`protocol_window`.
    include_whole : bool
        Add the whole clip as a window of every reference.

    Returns
    -------
    dict
        ``{r: [ProtocolWindow, ...]}`` in the order of ``refs``.

    Raises
    ------
    ValueError
        No reference, a reference without frame r + 1 or ground truth, references in
        different runs of frames, a window length < 2 or longer than the clip, no
        window.
    FileNotFoundError
        No frame of the clip, or no ground truth for the clip at all.
    """
    refs = list(dict.fromkeys(_as_int(r, "refs") for r in refs))
    lengths = [_as_int(n, "windows") for n in windows]
    if not refs:
        raise ValueError("refs: give at least one reference frame number")
    for n in lengths:
        if n < 2:
            raise ValueError(f"windows: a window needs at least 2 frames (r and r + 1), got {n}")
    if not lengths and not include_whole:
        raise ValueError("windows: give at least one window length or include the whole clip")
    numbers = sintel_clip_numbers(root, clip, pass_)
    base = data_root(root)
    flow_dir = base / "sintel" / "training" / "flow" / clip
    with_gt = sorted(n for n in numbers if (flow_dir / f"frame_{n:04d}.flo").is_file())
    if not (flow_dir.is_dir() and any(flow_dir.glob("frame_*.flo"))):
        raise FileNotFoundError(f"Sintel {clip} ground truth not found: {flow_dir}/"
                                f"frame_NNNN.flo (data root {base}); {_HINT}")
    runs = _runs(numbers)
    plan: dict[int, list[ProtocolWindow]] = {}
    clip_run: tuple[int, ...] | None = None
    for r in refs:
        run = next((x for x in runs if x[0] <= r < x[-1]), None)
        if run is None:
            raise ValueError(f"refs: reference frame {r} needs frames {r} and {r + 1} of "
                             f"Sintel {pass_}/{clip} (frame r + 1 is scored); frames on disk: "
                             f"{_spans(numbers)}")
        if clip_run is not None and run != clip_run:
            raise ValueError(f"refs: references {refs[0]} and {r} lie in different runs of "
                             f"frames ({_spans(numbers)}); run them separately")
        clip_run = run
        if r not in with_gt:
            raise ValueError(f"refs: no ground truth for reference frame {r} "
                             f"({flow_dir / f'frame_{r:04d}.flo'} missing); frames with "
                             f"ground truth: {_spans(with_gt)}")
        plan[r] = protocol_windows(r, lengths, run[0], run[-1], include_whole)
    return plan


def _load_protocol_data(
    base: Path,
    clip: str,
    pass_: str,
    plan: Mapping[int, Sequence[ProtocolWindow]],
    crop: Crop | None,
) -> tuple[dict[int, np.ndarray], dict[int, tuple[np.ndarray, np.ndarray | None,
                                                  np.ndarray | None]]]:
    """Every frame the windows need (read once, uint8, cropped) and each reference's truth."""
    from ...io.flo import read_flo
    from ...io.images import read_image

    tr = base / "sintel" / "training"
    what = f"Sintel {pass_}/{clip}"
    needed = sorted({n for wins in plan.values() for w in wins for n in w.numbers})
    frames: dict[int, np.ndarray] = {}
    shape: tuple[int, ...] | None = None
    for n in needed:
        img = _rgb(read_image(_require(tr / pass_ / clip / f"frame_{n:04d}.png",
                                       f"{what} frame_{n:04d}", base)))
        if shape is None:
            shape = img.shape
            _check_crop_fits(crop, shape, what)
        elif img.shape != shape:
            raise ValueError(f"{what}: frame_{n:04d} is {img.shape}, frame_{needed[0]:04d} "
                             f"{shape}")
        frames[n] = _crop(img, crop)
    assert shape is not None
    log.info("%s: %d frames %dx%d read", what, len(frames), shape[1], shape[0])
    truth = {}
    for r in plan:
        gt = _nan_unknown(read_flo(_require(tr / "flow" / clip / f"frame_{r:04d}.flo",
                                            f"{what} flow", base)))
        if gt.shape[:2] != shape[:2]:
            raise ValueError(f"{what}: flow frame_{r:04d}.flo is {gt.shape[:2]}, the frames "
                             f"{shape[:2]}")
        occ = _mask(tr / "occlusions" / clip / f"frame_{r:04d}.png")
        inv = _mask(tr / "invalid" / clip / f"frame_{r:04d}.png")
        for m, name in ((occ, "occlusions"), (inv, "invalid")):
            if m is not None and m.shape != shape[:2]:
                raise ValueError(f"{what}: {name} mask frame_{r:04d}.png is {m.shape}, the "
                                 f"frames {shape[:2]}")
        occ, inv = _crop(occ, crop), _crop(inv, crop)
        truth[r] = (_crop(gt, crop), None if inv is None else ~inv, occ)
    return frames, truth


def run_sintel_trajectories(
    methods: Sequence[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    *,
    root: str | os.PathLike[str] | None = None,
    clip: str = PROTOCOL_CLIP,
    pass_: str = PROTOCOL_PASS,
    refs: Sequence[int] = PROTOCOL_REFS,
    windows: Sequence[int] = PROTOCOL_WINDOWS,
    include_whole: bool = True,
    crop: Crop | None = None,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """The book's Table 4.1 protocol on real footage: MPI-Sintel ``final/alley_1``.

    For every reference frame r and every window of :func:`plan_sintel_protocol`
    (lengths 9, 13 and 19 placed around r by :func:`protocol_window`, then the whole
    clip 0001-0050), every method tracks r's pixels through the window's frames
    (``varflow.track(frames, r - first, method)``); its displacement in frame r + 1 is
    scored against ``flow/<clip>/frame_r.flo`` (r → r + 1): AEE and AAE over the valid
    pixels (the ``invalid`` mask removed when there is one) and the AEE over the
    non-occluded ones when there is an occlusion mask for r (on alley_1 only for
    frame 2, so ``aee_noc`` is None for the default references).

    ``twoframe``'s estimate of frame r + 1 is TV-L1 from r to r + 1: it does not
    depend on the window.  The methods of :data:`SHARED_METHODS` are therefore run
    once per reference on the two frames r, r + 1 (the same result) and their row is
    reused for every window, marked ``shared`` with the seconds of that one run.
    Every frame the windows need is read from disk once (uint8, cropped; the 50
    frames of alley_1 take 67 MB) and the windows are sliced from memory.  Each
    method first runs once on a tiny synthetic clip (untimed, unless ``warm_up`` is
    False) so ``seconds`` excludes Numba compilation.

    Parameters
    ----------
    methods : sequence of str, optional
        Names from :data:`varflow.registry.TRACKERS`; by default the registered ones
        of :data:`PROTOCOL_METHODS` (``twoframe``, ``mfsf``, ``rlr``).
    overrides : mapping, optional
        ``{field: value}`` applied to every method that has the field, or
        ``{method: {field: value}}``; see :func:`varflow.evaluation.bench.common.split_overrides`.
    progress : bool
        A tqdm bar on stderr (only on a terminal).
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.
    clip, pass_ : str
        Sintel training clip and pass (``alley_1``, ``final``).
    refs : sequence of int
        Reference frame numbers r (1-based, as in ``frame_NNNN.png``); each needs
        frame r + 1 and ``frame_r.flo``.  Default 5 … 10.
    windows : sequence of int
        Window lengths (>= 2).  Default 9, 13, 19.
    include_whole : bool
        Also track through the whole clip from every reference.
    crop : (y0, y1, x0, x1), optional
        Run on a window of the frames only (frames and ground truth cropped when
        read; for quick tests).
    warm_up : bool
        Do the untimed warm-up run.

    Returns
    -------
    list of dict
        One row per (reference, window, method) in that order: ``dataset``
        (``"sintel-final"``), ``sequence`` (``"alley_1"``), ``ref`` (r), ``pair``
        (``"0005->0006"``), ``window`` (``"9: 0001-0009"``, ``"whole: 0001-0050"``),
        ``frames`` (of the window), ``ref_index`` (r's index in the window),
        ``method``, ``aee`` (px), ``aae`` (degrees), ``aee_noc`` (px, or None without
        occlusion mask), ``seconds`` (of the :func:`varflow.track` call) and
        ``shared`` (True when the row reuses the one run on r, r + 1).

    Raises
    ------
    ValueError
        Unknown method or parameter, invalid parameter value, a bad reference
        (outside the clip's first … last − 1 or without ground truth), window length
        or crop.
    FileNotFoundError
        When the data are missing.

    Notes
    -----
    Cost: every non-shared method tracks ``sum(window lengths)`` frames per reference
    at full resolution (1024×436), ``len(refs) × (9 + 13 + 19 + 50)`` = 546 frames
    with the defaults; see the benchmark README for an estimate.
    """
    from tqdm import tqdm

    if methods is None:
        methods = [m for m in PROTOCOL_METHODS if spec_name(m) in TRACKERS]
    methods, params = tracker_params(methods, overrides)
    crop = _check_crop(crop)
    base_dir = data_root(root)
    plan = plan_sintel_protocol(base_dir, clip=clip, pass_=pass_, refs=refs, windows=windows,
                                include_whole=include_whole)
    frames, truth = _load_protocol_data(base_dir, clip, pass_, plan, crop)
    if warm_up:
        _warm_up(methods, params, False)
    shared = [m for m in methods if spec_name(m) in SHARED_METHODS]
    windowed = [m for m in methods if spec_name(m) not in SHARED_METHODS]
    total = sum(len(shared) + len(wins) * len(windowed) for wins in plan.values())
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=total, desc="sintel-trajectories", unit="run", file=sys.stderr,
               disable=None if progress else True, leave=False)

    def run(m: str, numbers: Sequence[int], ref_index: int, r: int) -> dict[str, Any]:
        import varflow

        bar.set_postfix_str(f"r={r} {numbers[0]:04d}-{numbers[-1]:04d} {m}")
        clip_frames = np.stack([frames[n] for n in numbers])
        t0 = time.perf_counter()
        traj = varflow.track(clip_frames, ref_index, spec_name(m), params=params[m])
        seconds = time.perf_counter() - t0
        scores = _score(traj[ref_index + 1], *truth[r])
        log.info("%s r=%d frames %04d-%04d %s: AEE %.4f AAE %.3f in %.2fs", clip, r,
                 numbers[0], numbers[-1], m, scores["aee"], scores["aae"], seconds)
        bar.update(1)
        return {**scores, "seconds": seconds}

    try:
        for r, wins in plan.items():
            once = {m: run(m, (r, r + 1), 0, r) for m in shared}
            for w in wins:
                head = {"dataset": f"sintel-{pass_}", "sequence": clip, "ref": r,
                        "pair": f"{r:04d}->{r + 1:04d}", "window": w.label,
                        "frames": w.n_frames, "ref_index": w.ref_index}
                for m in methods:
                    if m in once:
                        rows.append({**head, "method": m, **once[m], "shared": True})
                    else:
                        rows.append({**head, "method": m,
                                     **run(m, w.numbers, w.ref_index, r), "shared": False})
    finally:
        bar.close()
    return rows


def _mean_of(values: Sequence[Any]) -> float | None:
    v = [float(x) for x in values if x is not None and x != "" and not math.isnan(float(x))]
    return float(np.mean(v)) if v else None


def format_protocol_table(
    rows: Sequence[Mapping[str, Any]], baseline: str = PROTOCOL_BASELINE
) -> str:
    """Markdown table of the Table 4.1 protocol, then a verdict line per method.

    One line per (reference, window) with each method's AEE and, for the others, its
    ratio to ``baseline`` (< 1: the method beats it); then per reference the mean
    over its windows (when it has several) and the mean over all lines.  Below the
    table: for every other method, at how many references its mean AEE over the
    windows is below the baseline's; which methods' rows are shared between the
    windows; and the total seconds per method (a shared run counted once).

    Parameters
    ----------
    rows : sequence of mapping
        As returned by :func:`run_sintel_trajectories` (``ref``, ``window``,
        ``frames``, ``method``, ``aee``, optional ``seconds`` and ``shared``).
    baseline : str
        The method the others are compared with.

    Returns
    -------
    str
        Without a trailing newline; ``"(no results)"`` for no rows.
    """
    if not rows:
        return "(no results)"
    methods = list(dict.fromkeys(str(r["method"]) for r in rows))
    keys = list(dict.fromkeys((r["ref"], str(r["window"])) for r in rows))
    refs = list(dict.fromkeys(k[0] for k in keys))
    aee = {(r["ref"], str(r["window"]), str(r["method"])): r.get("aee") for r in rows}
    n_frames = {(r["ref"], str(r["window"])): r.get("frames") for r in rows}
    has_base = baseline in methods
    others = [m for m in methods if m != baseline]

    header = ["ref", "window", "F"]
    for m in methods:
        header.append(f"{m} AEE")
        if has_base and m != baseline:
            header.append(f"{m} / {baseline}")

    def cells(vals: Mapping[str, Any]) -> list[str]:
        out = []
        b = _mean_of([vals.get(baseline)]) if has_base else None
        for m in methods:
            v = _mean_of([vals.get(m)])
            out.append(_fmt(v, 4))
            if has_base and m != baseline:
                out.append(_fmt(v / b if v is not None and b else None, 3))
        return out

    body = [[str(ref), w, str(n_frames.get((ref, w), "") or "")]
            + cells({m: aee.get((ref, w, m)) for m in methods}) for ref, w in keys]
    ref_means = {}
    for ref in refs:
        wins = [w for x, w in keys if x == ref]
        ref_means[ref] = {m: _mean_of([aee.get((ref, w, m)) for w in wins]) for m in methods}
        if len(wins) > 1:
            body.append([str(ref), f"mean of {len(wins)} windows", ""] + cells(ref_means[ref]))
    if len(keys) > 1:
        overall = {m: _mean_of([aee.get((ref, w, m)) for ref, w in keys]) for m in methods}
        body.append(["all", f"mean of {len(keys)} lines", ""] + cells(overall))
    lines = [markdown_table(header, body, 2), ""]

    if not has_base:
        lines.append(f"no {baseline} rows: nothing to compare with")
    for m in others if has_base else []:
        both = [ref for ref in refs
                if ref_means[ref][m] is not None and ref_means[ref][baseline] is not None]
        wins = [ref for ref in both if ref_means[ref][m] < ref_means[ref][baseline]]
        where = f" ({', '.join(str(ref) for ref in wins)})" if wins else ""
        lines.append(f"{m} beats {baseline} at {len(wins)} of {len(both)} references{where} "
                     f"(mean AEE over each reference's windows)")
    for m in methods:
        if any(r.get("shared") for r in rows if r["method"] == m):
            lines.append(f"{m}: one run per reference on frames r, r+1, reused for every "
                         f"window (its estimate of frame r+1 does not depend on the window)")
    runs: dict[str, dict[tuple[Any, ...], float]] = {m: {} for m in methods}
    for r in rows:
        if r.get("seconds") is None:
            continue
        key = (r["ref"],) if r.get("shared") else (r["ref"], str(r["window"]))
        runs[str(r["method"])][key] = float(r["seconds"])
    timed = [f"{m} {sum(runs[m].values()):.1f} s in {len(runs[m])} runs" for m in methods
             if runs[m]]
    if timed:
        lines.append("seconds: " + ", ".join(timed))
    return "\n".join(lines)
