"""Image sequences: frame folders and lists of image files, and :func:`read_frames`.

:func:`list_frame_files` lists the still images of a folder in natural order
(:func:`natural_key`: ``frame2.png`` before ``frame10.png``); :func:`read_frames` reads
a list of image files, a folder or (through :class:`~varflow.io.video_reader.VideoReader`)
a video into one array.  See :mod:`varflow.io.video` for the conventions.
"""

from __future__ import annotations

import errno
import logging
import os
import re
from collections.abc import Iterator, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from .checks import PathLike, check_selection, select
from .codecs import VIDEO_EXTENSIONS
from .images import read_image
from .video_reader import VideoReader

__all__ = [
    "DEFAULT_FOLDER_FPS",
    "FrameSource",
    "IMAGE_EXTENSIONS",
    "list_frame_files",
    "missing_input_error",
    "natural_key",
    "no_frames_message",
    "not_a_sequence_message",
    "read_frames",
    "single_image_message",
    "too_few_frames_message",
]

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

#: The extensions named first in messages (the rest are summed up as "...").
_USUAL_IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp")
_USUAL_VIDEO_EXTENSIONS = (".mp4", ".mkv", ".mov", ".avi", ".webm")


def _usual(extensions: frozenset[str], usual: Sequence[str]) -> str:
    """The usual ones of ``extensions``, then ``...`` when there are more."""
    named = [e for e in usual if e in extensions] or sorted(extensions)[:5]
    return ", ".join(named) + (", ..." if len(named) < len(extensions) else "")


# Input errors: one wording for every command that reads a frame folder or a video
# (``varflow track``, ``varflow retime``, the inputs of ``varflow batch``).


def missing_input_error(path: PathLike, origin: str | None = None) -> FileNotFoundError:
    """The error for an input path that does not exist.

    Parameters
    ----------
    path : str or path-like
        The missing path.
    origin : str, optional
        Where the path was given (e.g. ``list.txt:3``), named before the message.

    Returns
    -------
    FileNotFoundError
        ``errno`` 2, ``strerror`` ``"input not found"``, ``filename`` the path.
    """
    what = "input not found" if origin is None else f"{origin}: input not found"
    return FileNotFoundError(errno.ENOENT, what, os.fspath(path))


def no_frames_message(folder: PathLike) -> str:
    """The message for a folder that holds no image files.

    Parameters
    ----------
    folder : str or path-like

    Returns
    -------
    str
        ``"<folder>: no image files in the folder (looked for .png, .jpg, ...)"``.
    """
    return (
        f"{os.fspath(folder)}: no image files in the folder (looked for "
        f"{_usual(IMAGE_EXTENSIONS, _USUAL_IMAGE_EXTENSIONS)})"
    )


def too_few_frames_message(source: PathLike, found: int) -> str:
    """The message for a sequence of fewer than 2 frames.

    Parameters
    ----------
    source : str or path-like
        The folder, video or list the frames come from.
    found : int
        The frames it holds.

    Returns
    -------
    str
        ``"<source>: need at least 2 frames, found <found>"``.
    """
    return f"{os.fspath(source)}: need at least 2 frames, found {found}"


def single_image_message(path: PathLike) -> str:
    """The message for a single image given where a sequence is needed.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    str
        ``"<path>: a single image; give the folder of the frames or a video"``.
    """
    return f"{os.fspath(path)}: a single image; give the folder of the frames or a video"


def not_a_sequence_message(path: PathLike) -> str:
    """The message for a file that is neither a video nor an image.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    str
        ``"<path>: neither a video nor a folder of frames (unknown extension '.xyz';
        videos end in .mp4, .mkv, ...)"``.
    """
    p = Path(os.fspath(path))
    what = f"unknown extension {p.suffix!r}" if p.suffix else "no extension"
    return (
        f"{p}: neither a video nor a folder of frames ({what}; videos end in "
        f"{_usual(VIDEO_EXTENSIONS, _USUAL_VIDEO_EXTENSIONS)})"
    )


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


#: Frame rate of a folder of frames, and of a video without a usable rate, when none
#: is given: the PAL rate, a common default of image-sequence tools.
DEFAULT_FOLDER_FPS = Fraction(25)


class FrameSource:
    """A video file or a folder of frames, read one frame at a time.

    What ``varflow retime`` and ``varflow video`` stream from: the frames are never
    all in memory.  Opening checks the input (the messages of this module) and, for
    a video, that it is complete (:func:`varflow.io.probe.check_video_complete`).

    Parameters
    ----------
    path : str or path-like
        A folder (its image files in natural order, :func:`list_frame_files`) or a
        video file.
    rate : Fraction, optional
        The input's frame rate, replacing a video's own; a folder's
        (:data:`DEFAULT_FOLDER_FPS` when not given).

    Attributes
    ----------
    path : Path
    n : int
        Frames of the input.
    rate : Fraction
        Its frame rate.
    kind : str
        ``"video"`` or ``"folder"``.

    Raises
    ------
    FileNotFoundError
        A missing path.
    ValueError
        An empty folder, a single image, a file that is neither a video nor an
        image, or an unreadable, corrupt or truncated video.
    """

    def __init__(self, path: PathLike, rate: Fraction | None = None) -> None:
        from .probe import check_video_complete, video_rate

        self.path = Path(os.fspath(path))
        self.reader: VideoReader | None = None
        self.files: list[Path] = []
        if not self.path.exists():
            raise missing_input_error(self.path)
        if self.path.is_dir():
            self.files = list_frame_files(self.path)
            if not self.files:
                raise ValueError(no_frames_message(self.path))
            self.kind = "folder"
            self.n = len(self.files)
            self.rate = DEFAULT_FOLDER_FPS if rate is None else rate
            return
        suffix = self.path.suffix.lower()
        if suffix in IMAGE_EXTENSIONS:
            raise ValueError(single_image_message(self.path))
        try:
            self.reader = VideoReader(self.path)
        except ValueError as exc:
            if suffix in VIDEO_EXTENSIONS:
                raise
            # Any file FFmpeg reads is a video; one it cannot read, with an unknown
            # extension, is most likely not meant to be one.
            raise ValueError(not_a_sequence_message(self.path)) from exc
        try:
            check_video_complete(self.path)
        except BaseException:
            self.reader.close()
            raise
        self.kind = "video"
        self.n = len(self.reader)
        if rate is None:
            rate = video_rate(self.path)
            if rate is None:
                logger.warning("%s: no frame rate in the file; using %s fps", self.path,
                               DEFAULT_FOLDER_FPS)
        self.rate = rate or DEFAULT_FOLDER_FPS

    def frames(self, start: int = 0, stop: int | None = None,
               stride: int = 1) -> Iterator[np.ndarray]:
        """The frames ``start, start + stride, ... < stop``, decoded one at a time.

        A folder's frames must share the first one's shape and dtype (the message
        names the file that does not); a video's do by construction.
        """
        if self.reader is not None:
            yield from self.reader.iter_frames(start, stop, stride)
            return
        first: tuple[tuple[int, ...], np.dtype] | None = None
        for k in range(self.n)[start:stop:stride]:
            f = self.files[k]
            try:
                frame = read_image(f)
            except ValueError as exc:
                raise ValueError(f"{self.path}: cannot read frame {k} ({f.name}): {exc}") from exc
            if first is None:
                first = (frame.shape, frame.dtype)
            elif (frame.shape, frame.dtype) != first:
                raise ValueError(
                    f"{self.path}: frame {k} ({f.name}) has shape {frame.shape} and dtype "
                    f"{frame.dtype}, but the first frame has shape {first[0]} and dtype "
                    f"{first[1]}"
                )
            yield frame

    def close(self) -> None:
        """Close the video (nothing to do for a folder)."""
        if self.reader is not None:
            self.reader.close()

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
        selected frames (the message names ``start``, ``stop``, ``step`` and
        ``max_frames`` only when they are not the defaults), or invalid
        ``start``/``stop``/``step``/``max_frames``.  The messages of a missing path,
        a folder without images, a single image and an unknown file type are those
        of :func:`missing_input_error`, :func:`no_frames_message`,
        :func:`single_image_message` and :func:`not_a_sequence_message`.
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
            raise missing_input_error(path)
        if path.is_dir():
            files = list_frame_files(path)
            if not files:
                raise ValueError(no_frames_message(path))
            what = str(path)
        elif path.suffix.lower() in VIDEO_EXTENSIONS:
            return _read_video(path, start, stop, step, max_frames)
        elif path.suffix.lower() in IMAGE_EXTENSIONS:
            raise ValueError(single_image_message(path))
        else:
            raise ValueError(not_a_sequence_message(path))
    else:
        raise TypeError(
            "read_frames: source must be a path or a list/tuple of paths, got "
            f"{type(source).__name__}"
        )

    selected = [files[i] for i in select(len(files), start, stop, step, max_frames)]
    if len(selected) < 2:
        raise ValueError(_too_few(what, len(files), len(selected), start, stop, step, max_frames))
    for p in selected:  # fail on a missing file before decoding anything
        if not p.exists():
            raise FileNotFoundError(2, "frame file not found", str(p))
    frames = _read_files(selected)
    logger.debug(
        "read %d frames of %s %s from %s", len(frames), frames.shape[1:], frames.dtype, what
    )
    return frames


def _too_few(
    what: str,
    n: int,
    n_selected: int,
    start: int,
    stop: int | None,
    step: int,
    max_frames: int | None,
) -> str:
    """:func:`too_few_frames_message`, naming the selection keywords only when they were
    changed from their defaults (the whole sequence has fewer than 2 frames otherwise)."""
    changed = [
        f"{name}={value}"
        for name, value, default in (
            ("start", start, 0),
            ("stop", stop, None),
            ("step", step, 1),
            ("max_frames", max_frames, None),
        )
        if value != default
    ]
    if not changed:
        return too_few_frames_message(what, n)
    return f"{what}: need at least 2 frames, {n_selected} of {n} selected with {', '.join(changed)}"


def _read_video(
    path: Path, start: int, stop: int | None, step: int, max_frames: int | None
) -> np.ndarray:
    """The selected frames of a video (at least 2), via :class:`VideoReader`."""
    with VideoReader(path) as reader:
        selected = select(len(reader), start, stop, step, max_frames)
        if len(selected) < 2:
            raise ValueError(
                _too_few(str(path), len(reader), len(selected), start, stop, step, max_frames)
            )
        frames = reader.read_indices(selected)
    logger.debug("decoded %d frames of %s from %s", len(frames), frames.shape[1:], path)
    return frames
