"""The data of the multi-frame benchmarks: RubberWhale and Sintel snippets, and crops.

:func:`load_rubberwhale_clip` reads the 8-frame Middlebury RubberWhale clip with the
ground truth of its reference pair; :func:`sintel_snippets` finds the runs of
consecutive MPI-Sintel frames with ground truth for one of their pairs and
:func:`load_snippet` reads one; :func:`check_crop` and :func:`apply_crop` restrict a
run to a window of the frames.  See :mod:`varflow.evaluation.bench.multiframe`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..datasets import (
    SINTEL_PASSES,
    data_root,
    load_middlebury_pair,
    nan_unknown,
    read_mask,
    require_file,
    to_rgb,
)

__all__ = [
    "RUBBERWHALE_FRAMES",
    "RUBBERWHALE_REF",
    "Crop",
    "SintelSnippet",
    "apply_crop",
    "check_crop",
    "check_crop_fits",
    "frame_runs",
    "load_rubberwhale_clip",
    "load_snippet",
    "sintel_snippets",
]


#: Frame numbers of the RubberWhale clip and the index of the reference (frame10).
RUBBERWHALE_FRAMES: tuple[int, ...] = tuple(range(7, 15))
RUBBERWHALE_REF = RUBBERWHALE_FRAMES.index(10)

#: A window of the frames, ``(y0, y1, x0, x1)`` (rows y0 … y1 - 1, columns x0 … x1 - 1).
Crop = tuple[int, int, int, int]


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
    paths = [require_file(d / f"frame{n:02d}.png", f"Middlebury RubberWhale frame{n:02d}", base)
             for n in RUBBERWHALE_FRAMES]
    f10, f11, gt = load_middlebury_pair("RubberWhale", base)
    frames = [to_rgb(read_image(p)) for p in paths]
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


def frame_runs(numbers: Sequence[int]) -> list[tuple[int, ...]]:
    """The maximal runs of consecutive frame numbers in ``numbers``, ascending."""
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
            for run in frame_runs(numbers):
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


def load_snippet(
    s: SintelSnippet, root: Path
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The frames of a snippet (uint8 RGB), the ground truth of its reference pair, and its
    occlusion and invalid masks (None when missing)."""
    from ...io.flo import read_flo
    from ...io.images import read_image

    tr = root / "sintel" / "training"
    what = f"Sintel {s.pass_}/{s.clip}"
    frames = np.stack([
        to_rgb(read_image(require_file(tr / s.pass_ / s.clip / f"frame_{n:04d}.png",
                                       f"{what} frame_{n:04d}", root)))
        for n in s.numbers
    ])
    n = s.numbers[s.ref]
    gt = nan_unknown(read_flo(require_file(tr / "flow" / s.clip / f"frame_{n:04d}.flo",
                                           f"{what} flow", root)))
    if gt.shape[:2] != frames.shape[1:3]:
        raise ValueError(f"{what}: flow {gt.shape} does not match the frames {frames.shape}")
    occ = read_mask(tr / "occlusions" / s.clip / f"frame_{n:04d}.png")
    inv = read_mask(tr / "invalid" / s.clip / f"frame_{n:04d}.png")
    return frames, gt, occ, inv


def apply_crop(a: np.ndarray | None, crop: Crop | None, lead: int = 0) -> np.ndarray | None:
    """The window ``crop`` of ``a`` after ``lead`` leading axes (a contiguous copy); ``a``
    itself when either is None."""
    if a is None or crop is None:
        return a
    y0, y1, x0, x1 = crop
    idx = (slice(None),) * lead + (slice(y0, y1), slice(x0, x1))
    return np.ascontiguousarray(a[idx])


def check_crop(crop: Crop | None) -> Crop | None:
    """``crop`` as four ints with ``0 <= y0 < y1`` and ``0 <= x0 < x1`` (ValueError else)."""
    if crop is None:
        return None
    try:
        y0, y1, x0, x1 = (int(v) for v in crop)
    except (TypeError, ValueError):
        raise ValueError(f"crop: expected (y0, y1, x0, x1), got {crop!r}") from None
    if not (0 <= y0 < y1 and 0 <= x0 < x1):
        raise ValueError(f"crop: need 0 <= y0 < y1 and 0 <= x0 < x1, got {crop!r}")
    return y0, y1, x0, x1


def check_crop_fits(crop: Crop | None, shape: tuple[int, ...], what: str) -> None:
    """Fail (ValueError) when ``crop`` reaches beyond frames of ``shape`` (H, W, ...)."""
    if crop is not None and (crop[1] > shape[0] or crop[3] > shape[1]):
        raise ValueError(f"crop: {crop} exceeds the {shape[1]}x{shape[0]} frames of {what} "
                         f"(crop is y0, y1, x0, x1)")
