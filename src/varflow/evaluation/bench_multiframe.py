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
"""

from __future__ import annotations

import logging
import math
import os
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..registry import TRACKERS
from .bench_trajectories import tracker_params
from .datasets import (
    _HINT,
    SINTEL_PASSES,
    _mask,
    _nan_unknown,
    _require,
    _rgb,
    data_root,
    load_middlebury_pair,
)

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
]

log = logging.getLogger(__name__)

#: Method label of the two-frame baseline rows.
BASELINE_LABEL = "tvl1 (two-frame)"

#: Preferred trajectory methods, in table order; :func:`default_methods` keeps the
#: registered ones.
DEFAULT_METHODS: tuple[str, ...] = ("rlr", "mfsf", "twoframe", "chain")

#: Frame numbers of the RubberWhale clip and the index of the reference (frame10).
RUBBERWHALE_FRAMES: tuple[int, ...] = tuple(range(7, 15))
RUBBERWHALE_REF = RUBBERWHALE_FRAMES.index(10)

Crop = tuple[int, int, int, int]


def default_methods() -> list[str]:
    """The registered ones of :data:`DEFAULT_METHODS`, in that order."""
    return [m for m in DEFAULT_METHODS if m in TRACKERS]


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
    from ..io.images import read_image

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
    from ..io.flo import read_flo
    from ..io.images import read_image

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


def _warm_up(methods: Sequence[str], params: Mapping[str, Any], baseline: bool) -> None:
    """Run every method once on a tiny synthetic clip so JIT compilation is not timed."""
    import varflow

    from ..generators.pairs import synthetic_pair

    f0, f1, _ = synthetic_pair("translation", shape=(48, 64), magnitude=1.0, seed=0)
    if baseline:
        varflow.flow(f0, f1, "tvl1")
    for m in methods:
        try:
            varflow.track(np.stack([f0, f1, f0]), 1, m, params=params[m])
        except Exception as exc:  # noqa: BLE001 - a warm-up only; the real run reports
            log.warning("warm-up of %s failed (%s); its time includes compilation", m, exc)


def _score(est: np.ndarray, gt: np.ndarray, valid: np.ndarray | None,
           occ: np.ndarray | None) -> dict[str, float]:
    from .metrics import endpoint_error, evaluate

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
        traj = varflow.track(frames, ref, m, params=params[m])
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
        ``{method: {field: value}}``; see :func:`varflow.evaluation.bench.split_overrides`.
        The baseline always uses the default ``tvl1`` parameters.
    progress : bool
        A tqdm bar on stderr (only on a terminal).
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.
    baseline : bool
        Add the row ``tvl1 (two-frame)``: ``varflow.flow(frame10, frame11, "tvl1")``.
    crop : (y0, y1, x0, x1), optional
        Score a window of the clip only (frames and ground truth cropped before
        running; for quick tests).
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
    widths = [max(len(header[i]), *(len(b[i]) for b in body)) for i in range(len(header))]

    def render(cells: Sequence[str]) -> str:
        left = [c.ljust(w) for c, w in zip(cells[:n_left], widths[:n_left], strict=True)]
        right = [c.rjust(w) for c, w in zip(cells[n_left:], widths[n_left:], strict=True)]
        return "| " + " | ".join(left + right) + " |"

    sep = "|" + "|".join(("-" * (w + 2)) if i < n_left else ("-" * (w + 1) + ":")
                         for i, w in enumerate(widths)) + "|"
    return "\n".join([render(header), sep] + [render(b) for b in body])
