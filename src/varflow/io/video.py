"""Reading frame sequences: lists of image files, image directories and video files.

Every reader returns the frames stacked into one array, ``(F, H, W, C)`` for colour
and ``(F, H, W)`` for grey, with the dtype of the source (``uint8`` or ``uint16``;
no intensity scaling is done here, see :mod:`varflow._validate` for that).

* A list or tuple of image paths is read in the order given with
  :func:`varflow.io.images.read_image`.
* A directory contributes every still-image file in it (see
  :data:`IMAGE_EXTENSIONS`; hidden files are ignored) in *natural* order, so that
  ``frame2.png`` comes before ``frame10.png`` (:func:`list_frame_files`).
* A video file (:data:`VIDEO_EXTENSIONS`) is decoded with OpenCV
  (``cv2.VideoCapture``) and converted from BGR to RGB.  OpenCV is an optional
  dependency (``pip install varflow[bench]``); it is imported only when a video is
  read.
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

from .images import read_image

__all__ = ["IMAGE_EXTENSIONS", "VIDEO_EXTENSIONS", "list_frame_files", "read_frames"]

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

#: File extensions decoded as video with OpenCV (lower case, with the dot).
VIDEO_EXTENSIONS: frozenset[str] = frozenset(
    {
        ".mp4", ".m4v", ".avi", ".mov", ".mkv", ".webm", ".mpg", ".mpeg", ".wmv",
        ".flv", ".ogv", ".3gp", ".mts", ".m2ts", ".ts", ".mjpeg", ".mjpg",
    }
)  # fmt: skip

_DIGITS = re.compile(r"([0-9]+)")

PathLike = str | os.PathLike[str]


def _natural_key(name: str) -> tuple[list[Any], str]:
    """Sort key: digit runs compare as numbers, text case-insensitively; ties by name."""
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
    files.sort(key=lambda p: _natural_key(p.name))
    return files


def _check_selection(start: int, stop: int | None, step: int, max_frames: int | None) -> None:
    def is_int(x: object) -> bool:
        return isinstance(x, int | np.integer) and not isinstance(x, bool)

    if not is_int(start) or start < 0:
        raise ValueError(f"read_frames: start must be an integer >= 0, got {start!r}")
    if stop is not None and (not is_int(stop) or stop < 0):
        raise ValueError(f"read_frames: stop must be None or an integer >= 0, got {stop!r}")
    if not is_int(step) or step < 1:
        raise ValueError(f"read_frames: step must be an integer >= 1, got {step!r}")
    if max_frames is not None and (not is_int(max_frames) or max_frames < 1):
        raise ValueError(
            f"read_frames: max_frames must be None or an integer >= 1, got {max_frames!r}"
        )


def _select(n: int, start: int, stop: int | None, step: int, max_frames: int | None) -> range:
    """Indices ``range(n)[start:stop:step][:max_frames]``."""
    selected = range(n)[start:stop:step]
    return selected if max_frames is None else selected[:max_frames]


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


def _read_video(
    path: Path, start: int, stop: int | None, step: int, max_frames: int | None
) -> np.ndarray:
    """Decode the selected frames of a video with OpenCV, as RGB (or grey)."""
    try:
        import cv2  # optional dependency
    except ImportError as exc:
        raise ValueError(
            f"read_frames: reading the video {path} needs OpenCV, which is not installed; "
            "install it with `pip install varflow[bench]` (or `pip install "
            "opencv-python-headless`), or extract the frames to image files"
        ) from exc
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise ValueError(
                f"read_frames: OpenCV cannot open the video {path} (corrupted file or "
                "unsupported codec)"
            )
        frames: list[np.ndarray] = []
        index = 0
        while stop is None or index < stop:
            if max_frames is not None and len(frames) >= max_frames:
                break
            wanted = index >= start and (index - start) % step == 0
            if wanted:
                ok, frame = cap.read()
            else:
                ok, frame = cap.grab(), None  # skip without decoding
            if not ok:
                break
            if wanted:
                assert frame is not None
                if frame.ndim == 3 and frame.shape[2] == 3:
                    frame = frame[..., ::-1]  # BGR -> RGB
                elif frame.ndim == 3 and frame.shape[2] == 4:
                    frame = frame[..., 2::-1]  # BGRA -> RGB
                elif frame.ndim == 3 and frame.shape[2] == 1:
                    frame = frame[..., 0]
                frame = np.ascontiguousarray(frame)
                if frames and (frame.shape != frames[0].shape or frame.dtype != frames[0].dtype):
                    raise ValueError(
                        f"read_frames: {path}: frame {index} has shape {frame.shape} and dtype "
                        f"{frame.dtype}, but frame {start} has shape {frames[0].shape} and "
                        f"dtype {frames[0].dtype}; all frames must share shape and dtype"
                    )
                frames.append(frame)
            index += 1
    finally:
        cap.release()
    if len(frames) < 2:
        raise ValueError(
            f"read_frames: only {len(frames)} frame(s) decoded from the video {path} with "
            f"start={start}, stop={stop}, step={step}, max_frames={max_frames}; need at least 2"
        )
    logger.debug("decoded %d frames of %s from %s", len(frames), frames[0].shape, path)
    return np.stack(frames)


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
          OpenCV (optional dependency, ``varflow[bench]``).
    start, stop, step : int
        Frame selection, as the slice ``frames[start:stop:step]`` of the full
        sequence (``start >= 0``, ``stop`` None or ``>= 0``, ``step >= 1``).
    max_frames : int, optional
        Keep at most this many of the selected frames (the first ones).

    Returns
    -------
    frames : ndarray, shape (F, H, W, C) or (F, H, W)
        Colour frames are RGB (``C = 3``), grey frames have no channel axis; the
        dtype is that of the files (``uint8`` or ``uint16``; video is ``uint8``).
        ``F >= 2``.

    Raises
    ------
    FileNotFoundError
        If ``source`` or one of the listed files does not exist (the message
        names the path).
    ValueError
        On an empty directory or list, an unknown file extension, an unreadable or
        corrupted image or video (the message names the file), frames that differ
        in shape or dtype (naming the offending file or frame), fewer than 2
        selected frames, a video when OpenCV is not installed, or invalid
        ``start``/``stop``/``step``/``max_frames``.
    TypeError
        If ``source`` is neither a path nor a list/tuple of paths.

    Notes
    -----
    For image files only the selected files are decoded.  A video is decoded
    sequentially from the start (frames before ``start`` and between steps are
    grabbed but not converted); decoding stops after ``stop`` or ``max_frames``.

    Examples
    --------
    >>> frames = read_frames("clip/", step=2, max_frames=9)  # doctest: +SKIP
    >>> frames.shape  # doctest: +SKIP
    (9, 480, 640, 3)
    """
    _check_selection(start, stop, step, max_frames)
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

    selected = [files[i] for i in _select(len(files), start, stop, step, max_frames)]
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
