"""The frame-interpolation cases: a frame pair, the true in-between frame and context.

The data are read in place under the data folder (:func:`varflow.evaluation.datasets.
data_root`: ``--data``, else ``$VARFLOW_DATA``, else ``../shared/data``)::

    <root>/interpolation/middlebury/<Seq>/frame10.png, frame11.png, frame10i11.png
    <root>/interpolation/ucf101/NN/frame0.png, frame1.png, frame2.png
    <root>/sintel/training/final/alley_1/frame_0001.png ... frame_0050.png

The sets (:data:`INTERPOLATION_SETS`):

``"middlebury"``
    The 12 Middlebury sequences with interpolation ground truth
    (:data:`MIDDLEBURY_INTERP_SEQUENCES`): frame10 and frame11 → frame10i11 at
    t = 0.5 (Baker et al. 2011); no neighbouring frames.
``"ucf101"``
    21 triplets of UCF101 frames (:data:`UCF101_TRIPLETS`, "01" ... "21"): frame0 and
    frame2 → frame1 at t = 0.5; no neighbouring frames.
``"sintel"``
    MPI-Sintel final/alley_1 (50 frames, 1-based names): every odd frame i with
    both neighbours, i = 3, 5, ..., 49, interpolated from frames i − 1 and i + 1 at
    t = 0.5; with the 4-frame context ``previous`` = frame i − 3 and ``following`` =
    frame i + 3 when they exist (i − 3 ≥ 1, i + 3 ≤ 50), else None.  The case is
    named ``frame_NNNN`` after its middle frame.
``"sintel-x4"``
    ×4 slow motion on the same clip: for each group centre c = 3, 7, ..., 47 the
    pair c − 2, c + 2 and the three frames between it, c − 1, c and c + 1, at
    t = 1/4, 1/2 and 3/4; context ``previous`` = frame c − 6 and ``following`` =
    frame c + 6 when they exist.  12 groups, 36 cases, each named after its true
    frame (``frame_0002`` ... ``frame_0048``).

Tuning and reporting splits
---------------------------
Fixed: in each set the cases are sorted by name and alternate, the even positions
(0, 2, 4, ...) forming the ``"tuning"`` split (for choosing parameters) and the odd
positions the ``"reporting"`` split (for the numbers one quotes); in ``"sintel-x4"``
the groups alternate, the three times of a group staying together.  Both splits
cover every set: Middlebury 6 + 6 (tuning: Beanbags, DogDance, Grove3,
MiniCooper, Urban2, Venus), UCF101 11 + 10, Sintel 12 + 12, Sintel ×4 18 + 18
(6 + 6 groups).  ``"all"`` is both.
The split of a case depends only on its position in the full, fixed list of its
set, never on which files are on disk.

References
----------
Baker, Scharstein, Lewis, Roth, Black & Szeliski (2011), "A Database and Evaluation
Methodology for Optical Flow", IJCV 92(1).  Soomro, Zamir & Shah (2012), "UCF101: A
Dataset of 101 Human Actions Classes From Videos in The Wild", arXiv:1212.0402.
Butler, Wulff, Stanley & Black (2012), "A naturalistic open source movie for optical
flow evaluation", ECCV.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .datasets import ENV_VAR, data_root

__all__ = [
    "INTERPOLATION_SETS",
    "INTERPOLATION_SPLITS",
    "MIDDLEBURY_INTERP_SEQUENCES",
    "SINTEL_CLIP",
    "SINTEL_FRAMES",
    "SINTEL_PASS",
    "X4_TIMES",
    "UCF101_TRIPLETS",
    "CaseFrames",
    "InterpolationCase",
    "check_sets",
    "check_split",
    "interpolation_cases",
    "split_of",
]

#: The sets, in the order the benchmark runs them.
INTERPOLATION_SETS: tuple[str, ...] = ("middlebury", "ucf101", "sintel", "sintel-x4")

#: Values of ``split``.
INTERPOLATION_SPLITS: tuple[str, ...] = ("tuning", "reporting", "all")

#: The 12 Middlebury "other" sequences with interpolation ground truth (sorted).
MIDDLEBURY_INTERP_SEQUENCES: tuple[str, ...] = (
    "Beanbags", "Dimetrodon", "DogDance", "Grove2", "Grove3", "Hydrangea",
    "MiniCooper", "RubberWhale", "Urban2", "Urban3", "Venus", "Walking",
)

#: The UCF101 triplets (folder names, sorted).
UCF101_TRIPLETS: tuple[str, ...] = tuple(f"{i:02d}" for i in range(1, 22))

#: The MPI-Sintel clip, pass and frame count of the ``"sintel"`` set.
SINTEL_CLIP = "alley_1"
SINTEL_PASS = "final"
SINTEL_FRAMES = 50

#: The times of the ``"sintel-x4"`` cases between their pair (frames c - 2, c + 2).
X4_TIMES: tuple[float, ...] = (0.25, 0.5, 0.75)

_HINT = (f"pass --data DIR or set {ENV_VAR} to the folder holding interpolation/ "
         "(and sintel/)")


class CaseFrames(NamedTuple):
    """The frames of a case, uint8 RGB (H, W, 3).

    Attributes
    ----------
    frame0, frame1 : ndarray
        The pair (t = 0 and t = 1).
    gt : ndarray
        The true frame at the case's ``t``.
    previous, following : ndarray or None
        The frames before ``frame0`` and after ``frame1`` at the pair's spacing
        (the Sintel sets), else None.
    """

    frame0: np.ndarray
    frame1: np.ndarray
    gt: np.ndarray
    previous: np.ndarray | None
    following: np.ndarray | None


@dataclass(frozen=True)
class InterpolationCase:
    """One interpolation case of a set.

    Attributes
    ----------
    set : str
        One of :data:`INTERPOLATION_SETS`.
    name : str
        Its label (``"Urban2"``, ``"07"``, ``"frame_0011"``).
    frame0, frame1, gt : Path
        The pair and the true in-between frame.
    t : float
        The time of ``gt`` between ``frame0`` (0) and ``frame1`` (1).
    split : {"tuning", "reporting"}
    previous, following : Path or None
        Context frames (Sintel), else None.
    """

    set: str
    name: str
    frame0: Path
    frame1: Path
    gt: Path
    t: float
    split: str
    previous: Path | None = None
    following: Path | None = None

    @property
    def paths(self) -> tuple[Path, ...]:
        """Every file of the case (the pair, the ground truth, the context frames)."""
        return tuple(p for p in (self.previous, self.frame0, self.frame1, self.following,
                                 self.gt) if p is not None)

    def load(self) -> CaseFrames:
        """Read the frames.

        Returns
        -------
        CaseFrames
            uint8 RGB arrays (grey files are replicated to three channels).

        Raises
        ------
        FileNotFoundError
            A file of the case is missing (named in the message).
        ValueError
            A file is not an 8-bit image or the frames differ in size.
        """
        from ..io.images import read_image

        def read(path: Path | None) -> np.ndarray | None:
            if path is None:
                return None
            if not path.is_file():
                raise FileNotFoundError(2, f"{self.set} {self.name}: file not found; {_HINT}",
                                        str(path))
            a = read_image(path)
            if a.dtype != np.uint8:
                raise ValueError(f"{path}: expected an 8-bit image, got {a.dtype}")
            if a.ndim == 2:
                a = np.repeat(a[..., None], 3, axis=2)
            return np.ascontiguousarray(a)

        frames = CaseFrames(read(self.frame0), read(self.frame1), read(self.gt),
                            read(self.previous), read(self.following))
        shape = frames.frame0.shape
        for name, f in zip(CaseFrames._fields, frames, strict=True):
            if f is not None and f.shape != shape:
                raise ValueError(f"{self.set} {self.name}: {name} has shape {f.shape}, "
                                 f"frame0 {shape}")
        return frames


def split_of(position: int) -> str:
    """The split of the case at ``position`` (0-based) in its set's sorted list:
    even → ``"tuning"``, odd → ``"reporting"``."""
    return "tuning" if position % 2 == 0 else "reporting"


def check_sets(sets: str | list[str] | tuple[str, ...]) -> list[str]:
    """Validate set names (a comma-separated string is split).

    Returns
    -------
    list of str
        In :data:`INTERPOLATION_SETS` order, without repetitions.

    Raises
    ------
    ValueError
        ``sets: ...`` for an unknown name or none.
    """
    names = [s.strip() for s in sets.split(",")] if isinstance(sets, str) else list(sets)
    names = [s for s in names if s]
    if not names:
        raise ValueError(f"sets: give at least one of {', '.join(INTERPOLATION_SETS)}")
    for s in names:
        if s not in INTERPOLATION_SETS:
            raise ValueError(f"sets: unknown set {s!r}; expected some of "
                             f"{', '.join(INTERPOLATION_SETS)}")
    return [s for s in INTERPOLATION_SETS if s in names]


def check_split(split: str) -> str:
    """Validate ``split`` (one of :data:`INTERPOLATION_SPLITS`); ``split: ...`` otherwise."""
    if split not in INTERPOLATION_SPLITS:
        raise ValueError(f"split: expected one of {', '.join(INTERPOLATION_SPLITS)}, "
                         f"got {split!r}")
    return split


def _all_cases(set_name: str, root: Path) -> tuple[Path, list[InterpolationCase]]:
    """The folder of a set and its full, fixed list of cases (sorted, with splits)."""
    cases: list[InterpolationCase] = []
    if set_name == "middlebury":
        folder = root / "interpolation" / "middlebury"
        for i, seq in enumerate(sorted(MIDDLEBURY_INTERP_SEQUENCES)):
            d = folder / seq
            cases.append(InterpolationCase("middlebury", seq, d / "frame10.png",
                                           d / "frame11.png", d / "frame10i11.png", 0.5,
                                           split_of(i)))
    elif set_name == "ucf101":
        folder = root / "interpolation" / "ucf101"
        for i, name in enumerate(sorted(UCF101_TRIPLETS)):
            d = folder / name
            cases.append(InterpolationCase("ucf101", name, d / "frame0.png", d / "frame2.png",
                                           d / "frame1.png", 0.5, split_of(i)))
    elif set_name in ("sintel", "sintel-x4"):
        folder = root / "sintel" / "training" / SINTEL_PASS / SINTEL_CLIP

        def frame(n: int) -> Path | None:
            return folder / f"frame_{n:04d}.png" if 1 <= n <= SINTEL_FRAMES else None

        if set_name == "sintel":
            for pos, i in enumerate(range(3, SINTEL_FRAMES, 2)):
                cases.append(InterpolationCase(
                    "sintel", f"frame_{i:04d}", frame(i - 1), frame(i + 1), frame(i), 0.5,
                    split_of(pos), previous=frame(i - 3), following=frame(i + 3)))
        else:
            for pos, c in enumerate(range(3, SINTEL_FRAMES - 1, 4)):
                for k, t in enumerate(X4_TIMES):
                    i = c - 1 + k
                    cases.append(InterpolationCase(
                        "sintel-x4", f"frame_{i:04d}", frame(c - 2), frame(c + 2), frame(i),
                        t, split_of(pos), previous=frame(c - 6), following=frame(c + 6)))
    else:
        check_sets([set_name])
        raise AssertionError(set_name)  # pragma: no cover - check_sets raised
    return folder, cases


def interpolation_cases(
    set_name: str,
    split: str = "reporting",
    root: str | os.PathLike[str] | None = None,
) -> list[InterpolationCase]:
    """The cases of one set and split, in sorted order.

    Parameters
    ----------
    set_name : str
        One of :data:`INTERPOLATION_SETS`.
    split : {"tuning", "reporting", "all"}
        See the module notes.
    root : path-like, optional
        The data folder (see :func:`varflow.evaluation.datasets.data_root`).

    Returns
    -------
    list of InterpolationCase

    Raises
    ------
    ValueError
        Unknown set or split.
    FileNotFoundError
        The set's folder, or a file of one of its cases, is missing (the message
        names the path and ``VARFLOW_DATA``).
    """
    check_sets([set_name])
    check_split(split)
    base = data_root(root)
    folder, cases = _all_cases(set_name, base)
    if not folder.is_dir():
        raise FileNotFoundError(2, f"{set_name} interpolation data not found; {_HINT}",
                                str(folder))
    for c in cases:
        for p in c.paths:
            if not p.is_file():
                raise FileNotFoundError(2, f"{set_name} {c.name}: file not found; {_HINT}",
                                        str(p))
    return [c for c in cases if split == "all" or c.split == split]
