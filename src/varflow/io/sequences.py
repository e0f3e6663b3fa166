"""Image sequences: frame folders and lists of image files, and :func:`read_frames`.

:func:`list_frame_files` lists the still images of a folder in natural order
(:func:`natural_key`: ``frame2.png`` before ``frame10.png``); :func:`read_frames` reads
a list of image files, a folder or (through :class:`~varflow.io.video_reader.VideoReader`)
a video into one array.  See :mod:`varflow.io.video` for the conventions.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from .checks import PathLike, check_selection, select
from .codecs import VIDEO_EXTENSIONS
from .images import read_image
from .video_reader import VideoReader

__all__ = ["IMAGE_EXTENSIONS", "list_frame_files", "natural_key", "read_frames"]

logger = logging.getLogger(__name__)


_STILL_IMAGE_CANDIDATES = {
    ".png", ".jpg", ".jpeg", ".jpe", ".jfif", ".bmp", ".dib", ".tif", ".tiff", ".ppm",
    ".pgm", ".pbm", ".pnm", ".webp", ".tga", ".gif", ".jp2", ".j2k", ".qoi", ".pcx",
    ".sgi", ".ras",
}  # fmt: skip

#: Still-image formats picked up from a directory (lower case, with the dot): the usual
#: photo/scientific formats, restricted to those the installed Pillow can open.  Formats
#: Pillow registers but that are not frame images (MPEG, EPS, HDF5 stubs, ...) are excluded.
IMAGE_EXTENSIONS: frozenset[str] = frozenset(
    ext
    for ext, fmt in Image.registered_extensions().items()
    if fmt in Image.OPEN and ext in _STILL_IMAGE_CANDIDATES
)


_DIGITS = re.compile(r"([0-9]+)")


def natural_key(name: str) -> tuple[list[Any], str]:
    """Sort key: digit runs compare as numbers, text case-insensitively; ties by name.

    The order of :func:`list_frame_files` (``frame2`` before ``frame10``), also used by
    :mod:`varflow.batch` to order the files of an input list or pattern.

    Parameters
    ----------
    name : str
        A file name (or path string).

    Returns
    -------
    tuple
        ``(key, name)``: ``key`` alternates text (case-folded) and integers.
    """
    parts = _DIGITS.split(name)  # alternates text, digits, text, ... (starts with text)
    key = [int(p) if i % 2 else p.casefold() for i, p in enumerate(parts)]
    return key, name


def list_frame_files(directory: PathLike) -> list[Path]:
    """List the image files of a directory in natural order.

    Parameters
    ----------
    directory : str or path-like

    Returns
    -------
    list of Path
        Regular files whose lower-cased extension is in :data:`IMAGE_EXTENSIONS`,
        sorted so that runs of digits compare by value (``frame2`` < ``frame10``)
        and text case-insensitively.  Hidden files (names starting with ``.``) and
        sub-directories are ignored.  The list may be empty.

    Raises
    ------
    FileNotFoundError
        If ``directory`` does not exist.
    NotADirectoryError
        If ``directory`` is not a directory.
    """
    path = Path(os.fspath(directory))
    if not path.exists():
        raise FileNotFoundError(2, "frame directory not found", str(path))
    if not path.is_dir():
        raise NotADirectoryError(20, "not a directory", str(path))
    files = [
        p
        for p in path.iterdir()
        if not p.name.startswith(".") and p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file()
    ]
    files.sort(key=lambda p: natural_key(p.name))
    return files


def _read_files(files: Sequence[Path]) -> np.ndarray:
    """Read and stack image files; every frame must match the first one."""
    frames: np.ndarray | None = None
    first: np.ndarray | None = None
    for k, path in enumerate(files):
        try:
            arr = read_image(path)
        except ValueError as exc:
            raise ValueError(f"read_frames: cannot read frame {k} ({path}): {exc}") from exc
        if first is None:
            first = arr
            frames = np.empty((len(files), *arr.shape), dtype=arr.dtype)
        elif arr.shape != first.shape or arr.dtype != first.dtype:
            raise ValueError(
                f"read_frames: {path} (frame {k}) has shape {arr.shape} and dtype "
                f"{arr.dtype}, but {files[0]} (frame 0) has shape {first.shape} and dtype "
                f"{first.dtype}; all frames must share shape and dtype"
            )
        assert frames is not None
        frames[k] = arr
    assert frames is not None
    return frames


def read_frames(
    source: PathLike | Sequence[PathLike],
    *,
    start: int = 0,
    stop: int | None = None,
    step: int = 1,
    max_frames: int | None = None,
) -> np.ndarray:
    """Read a sequence of frames from image files, an image directory or a video.

    Parameters
    ----------
    source : str, path-like, or list/tuple of them
        * a list or tuple of image files, read in the order given;
        * a directory: all files with an extension in :data:`IMAGE_EXTENSIONS`, in
          natural order (:func:`list_frame_files`);
        * a video file with an extension in :data:`VIDEO_EXTENSIONS`, decoded with
          PyAV (:class:`VideoReader`).
    start, stop, step : int
        Frame selection, as the slice ``frames[start:stop:step]`` of the full
        sequence (``start >= 0``, ``stop`` None or ``>= 0``, ``step >= 1``).
    max_frames : int, optional
        Keep at most this many of the selected frames (the first ones).

    Returns
    -------
    frames : ndarray, shape (F, H, W, C) or (F, H, W)
        Colour frames are RGB (``C = 3``), grey frames have no channel axis; the
        dtype is that of the files (``uint8`` or ``uint16``; video is ``uint16`` for
        pixel formats deeper than 8 bits).  ``F >= 2``.

    Raises
    ------
    FileNotFoundError
        If ``source`` or one of the listed files does not exist (the message
        names the path).
    ValueError
        On an empty directory or list, an unknown file extension, an unreadable or
        corrupted image or video (the message names the file), frames that differ
        in shape or dtype (naming the offending file or frame), fewer than 2
        selected frames, or invalid ``start``/``stop``/``step``/``max_frames``.
    TypeError
        If ``source`` is neither a path nor a list/tuple of paths.

    Notes
    -----
    Only the selected frames are decoded.  A video is entered by seeking to the
    keyframe before ``start`` and decoded forward (GOPs without a selected frame are
    skipped), see :class:`VideoReader`.

    Examples
    --------
    >>> frames = read_frames("clip/", step=2, max_frames=9)  # doctest: +SKIP
    >>> frames.shape  # doctest: +SKIP
    (9, 480, 640, 3)
    """
    check_selection(start, stop, step, max_frames)
    if isinstance(source, list | tuple):
        files = [Path(os.fspath(p)) for p in source]
        if not files:
            raise ValueError("read_frames: the list of frame files is empty")
        what = "list of frame files"
    elif isinstance(source, str | os.PathLike):
        path = Path(os.fspath(source))
        if not path.exists():
            raise FileNotFoundError(2, "frame source not found", str(path))
        if path.is_dir():
            files = list_frame_files(path)
            if not files:
                raise ValueError(
                    f"read_frames: no image files in the directory {path} (looked for "
                    f"{', '.join(sorted(IMAGE_EXTENSIONS))})"
                )
            what = f"directory {path}"
        elif path.suffix.lower() in VIDEO_EXTENSIONS:
            return _read_video(path, start, stop, step, max_frames)
        elif path.suffix.lower() in IMAGE_EXTENSIONS:
            raise ValueError(
                f"read_frames: {path} is a single image; pass a directory, a list of image "
                "files or a video"
            )
        else:
            raise ValueError(
                f"read_frames: {path}: unknown extension {path.suffix!r}; pass a directory, "
                f"a list of image files or a video ({', '.join(sorted(VIDEO_EXTENSIONS))})"
            )
    else:
        raise TypeError(
            "read_frames: source must be a path or a list/tuple of paths, got "
            f"{type(source).__name__}"
        )

    selected = [files[i] for i in select(len(files), start, stop, step, max_frames)]
    if len(selected) < 2:
        raise ValueError(
            f"read_frames: {len(selected)} frame(s) selected from the {what} ({len(files)} "
            f"file(s)) with start={start}, stop={stop}, step={step}, max_frames={max_frames}; "
            "need at least 2"
        )
    for p in selected:  # fail on a missing file before decoding anything
        if not p.exists():
            raise FileNotFoundError(2, "frame file not found", str(p))
    frames = _read_files(selected)
    logger.debug(
        "read %d frames of %s %s from the %s", len(frames), frames.shape[1:], frames.dtype, what
    )
    return frames


def _read_video(
    path: Path, start: int, stop: int | None, step: int, max_frames: int | None
) -> np.ndarray:
    """The selected frames of a video (at least 2), via :class:`VideoReader`."""
    with VideoReader(path) as reader:
        selected = select(len(reader), start, stop, step, max_frames)
        if len(selected) < 2:
            raise ValueError(
                f"read_frames: {len(selected)} frame(s) selected from the video {path} "
                f"({len(reader)} frames) with start={start}, stop={stop}, step={step}, "
                f"max_frames={max_frames}; need at least 2"
            )
        frames = reader.read_indices(selected)
    logger.debug("decoded %d frames of %s from %s", len(frames), frames.shape[1:], path)
    return frames
