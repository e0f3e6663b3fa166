"""The book's Table 4.1 protocol on real footage: MPI-Sintel ``final/alley_1``.

Every trajectory method tracks each reference frame r (5 … 10 by default) through
windows of the clip around r (:func:`protocol_window`: 9, 13 and 19 frames, plus the
whole clip); its displacement in frame r + 1 is scored against
``flow/alley_1/frame_r.flo``.  :func:`plan_sintel_protocol` checks the arguments
against the data on disk before any work; :func:`run_sintel_trajectories` runs it.
See :mod:`varflow.evaluation.bench.multiframe`.
"""

from __future__ import annotations

import logging
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
    DATA_HINT,
    SINTEL_PASSES,
    data_root,
    nan_unknown,
    read_mask,
    require_file,
    to_rgb,
)
from .common import spec_name
from .multiframe_data import Crop, apply_crop, check_crop, check_crop_fits, frame_runs
from .multiframe_run import score_estimate, warm_up_methods
from .trajectories import tracker_params

__all__ = [
    "PROTOCOL_BASELINE",
    "PROTOCOL_CLIP",
    "PROTOCOL_METHODS",
    "PROTOCOL_PASS",
    "PROTOCOL_REFS",
    "PROTOCOL_WINDOWS",
    "SHARED_METHODS",
    "ProtocolWindow",
    "plan_sintel_protocol",
    "protocol_window",
    "protocol_windows",
    "run_sintel_trajectories",
    "sintel_clip_numbers",
]

log = logging.getLogger(__name__)


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
                     for r in frame_runs(numbers)) or "none"


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
                                f"(data root {base}); {DATA_HINT}")
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
                                f"frame_NNNN.flo (data root {base}); {DATA_HINT}")
    runs = frame_runs(numbers)
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
        img = to_rgb(read_image(require_file(tr / pass_ / clip / f"frame_{n:04d}.png",
                                             f"{what} frame_{n:04d}", base)))
        if shape is None:
            shape = img.shape
            check_crop_fits(crop, shape, what)
        elif img.shape != shape:
            raise ValueError(f"{what}: frame_{n:04d} is {img.shape}, frame_{needed[0]:04d} "
                             f"{shape}")
        frames[n] = apply_crop(img, crop)
    assert shape is not None
    log.info("%s: %d frames %dx%d read", what, len(frames), shape[1], shape[0])
    truth = {}
    for r in plan:
        gt = nan_unknown(read_flo(require_file(tr / "flow" / clip / f"frame_{r:04d}.flo",
                                               f"{what} flow", base)))
        if gt.shape[:2] != shape[:2]:
            raise ValueError(f"{what}: flow frame_{r:04d}.flo is {gt.shape[:2]}, the frames "
                             f"{shape[:2]}")
        occ = read_mask(tr / "occlusions" / clip / f"frame_{r:04d}.png")
        inv = read_mask(tr / "invalid" / clip / f"frame_{r:04d}.png")
        for m, name in ((occ, "occlusions"), (inv, "invalid")):
            if m is not None and m.shape != shape[:2]:
                raise ValueError(f"{what}: {name} mask frame_{r:04d}.png is {m.shape}, the "
                                 f"frames {shape[:2]}")
        occ, inv = apply_crop(occ, crop), apply_crop(inv, crop)
        truth[r] = (apply_crop(gt, crop), None if inv is None else ~inv, occ)
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
    crop = check_crop(crop)
    base_dir = data_root(root)
    plan = plan_sintel_protocol(base_dir, clip=clip, pass_=pass_, refs=refs, windows=windows,
                                include_whole=include_whole)
    frames, truth = _load_protocol_data(base_dir, clip, pass_, plan, crop)
    if warm_up:
        warm_up_methods(methods, params, False)
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
        scores = score_estimate(traj[ref_index + 1], *truth[r])
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
