"""Checks and error messages shared by the frame and video readers and writers.

The frame selection ``start:stop:step`` with ``max_frames`` (:func:`check_selection`,
:func:`select`), the check of a video path (:func:`check_video_path`), and the
translation of PyAV/FFmpeg exceptions into one-line :class:`ValueError` messages that
name the file (:func:`av_errors`, :data:`AV_ERRORS`, :func:`describe`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import av
import av.error
import numpy as np

__all__ = [
    "AV_ERRORS",
    "PathLike",
    "av_errors",
    "check_selection",
    "check_video_path",
    "describe",
    "is_int",
    "select",
]

#: A path argument: a string or an :class:`os.PathLike`.
PathLike = str | os.PathLike[str]

#: Exceptions PyAV/FFmpeg raise on bad input; all become one-line ValueErrors.
AV_ERRORS: tuple[type[BaseException], ...] = (
    av.error.FFmpegError,
    EOFError,
    OverflowError,
    UnicodeError,
)


def is_int(x: object) -> bool:
    """True for a Python or NumPy integer (not a bool)."""
    return isinstance(x, int | np.integer) and not isinstance(x, bool)


def check_selection(
    start: int, stop: int | None, step: int, max_frames: int | None, who: str = "read_frames"
) -> None:
    """Check a frame selection ``start:stop:step`` (slice semantics) and ``max_frames``.

    Parameters
    ----------
    start : int
        ``>= 0``.
    stop : int or None
        None or ``>= 0``.
    step : int
        ``>= 1``.
    max_frames : int or None
        None or ``>= 1``.
    who : str
        The function named in the messages.

    Raises
    ------
    ValueError
        A one-line message naming ``who`` and the offending argument.
    """
    if not is_int(start) or start < 0:
        raise ValueError(f"{who}: start must be an integer >= 0, got {start!r}")
    if stop is not None and (not is_int(stop) or stop < 0):
        raise ValueError(f"{who}: stop must be None or an integer >= 0, got {stop!r}")
    if not is_int(step) or step < 1:
        raise ValueError(f"{who}: step must be an integer >= 1, got {step!r}")
    if max_frames is not None and (not is_int(max_frames) or max_frames < 1):
        raise ValueError(f"{who}: max_frames must be None or an integer >= 1, got {max_frames!r}")


def select(n: int, start: int, stop: int | None, step: int, max_frames: int | None) -> range:
    """Indices ``range(n)[start:stop:step][:max_frames]``."""
    selected = range(n)[int(start) : None if stop is None else int(stop) : int(step)]
    return selected if max_frames is None else selected[: int(max_frames)]


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def describe(exc: BaseException) -> str:
    """A short description of a PyAV/FFmpeg exception (without the file name it repeats)."""
    strerror = getattr(exc, "strerror", None)
    if isinstance(exc, av.error.FFmpegError) and strerror:
        return _one_line(strerror)
    return _one_line(f"{type(exc).__name__}: {exc}")


@contextlib.contextmanager
def av_errors(path: Path, action: str = "read the video") -> Iterator[None]:
    """Turn FFmpeg/PyAV errors raised inside the block into one-line ValueErrors."""
    try:
        yield
    except AV_ERRORS as exc:
        raise ValueError(f"{path}: cannot {action} ({describe(exc)})") from exc


def check_video_path(path: PathLike) -> Path:
    """``path`` as a :class:`~pathlib.Path`, checked to exist and not to be a directory.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is a directory.
    """
    p = Path(os.fspath(path))
    if not p.exists():
        raise FileNotFoundError(2, "video not found", str(p))
    if p.is_dir():
        raise ValueError(f"{p}: is a directory, not a video file")
    return p
