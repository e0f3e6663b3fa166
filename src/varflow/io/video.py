"""Frame sequences and video files: reading image sequences, reading and writing video.

Frame arrays are ``(F, H, W, 3)`` for colour (RGB) and ``(F, H, W)`` for grey, with
the dtype of the source (``uint8`` or ``uint16``); no intensity scaling is done here
(see :mod:`varflow._validate` for that).

Image sequences (:func:`read_frames`)
    * A list or tuple of image paths is read in the order given with
      :func:`varflow.io.images.read_image`.
    * A directory contributes every still-image file in it (see
      :data:`IMAGE_EXTENSIONS`; hidden files are ignored) in *natural* order, so that
      ``frame2.png`` comes before ``frame10.png`` (:func:`list_frame_files`).

Video (PyAV, i.e. FFmpeg)
    * :func:`video_info` describes a video; its frame count is exact (packets are
      counted, the container header is not trusted).
    * :class:`VideoReader` gives frame-accurate random access (``read(i)``) and
      streaming (``iter_frames``) with bounded memory.  Frames are RGB ``uint8``
      ``(H, W, 3)`` for 8-bit colour, RGB ``uint16`` for pixel formats with more than
      8 bits per component (``yuv420p10le``, ``rgb48le``, 16-bit FFV1, ...; values
      use the full 0..65535 range), and ``(H, W)`` for grey pixel formats.
    * :class:`VideoWriter` / :func:`write_video` encode ``uint8`` or ``uint16``
      frames atomically (temporary file in the target directory, then
      :func:`os.replace`); ``.mkv`` defaults to lossless FFV1.  With ``audio=PATH``
      the writer also copies the first audio stream of ``PATH`` (remuxed, or
      re-encoded when the container cannot hold its codec).
    * :func:`video_rate` gives a stream's exact rational frame rate and
      :func:`check_video_complete` detects a file cut short (its header promises
      more than is there).

A corrupt, truncated or non-video file raises a one-line :class:`ValueError` (a
missing path :class:`FileNotFoundError`); FFmpeg's own exceptions never escape.

Frame-accurate seeking
----------------------
Opening a video demuxes (without decoding) every packet of its video stream once and
records its presentation timestamp (pts), decode timestamp and keyframe flag; the
result is cached per file (path, size, modification time).  Frame ``i`` is the
packet with the ``i``-th smallest pts.  To read it, the reader picks the last
keyframe that precedes the frame's packet in decode order and is not displayed after
the frame, seeks there (verifying where the demuxer actually landed and falling back
to an earlier keyframe or to the start of the file), and decodes forward until the
decoder outputs the frame with the wanted pts.  This is exact with B-frames, open or
closed GOPs and streams whose first pts is not 0.  Streams without usable
timestamps (missing or repeated pts) are read sequentially from the start.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
import operator
import os
import re
import stat
import tempfile
import threading
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Mapping, Sequence
from fractions import Fraction
from pathlib import Path
from types import TracebackType
from typing import Any

import av
import av.error
import numpy as np
from PIL import Image

from ._atomic import _NEW_FILE_MODE, _fsync_directory
from .images import read_image

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_EXTENSIONS",
    "VIDEO_WRITE_EXTENSIONS",
    "VideoInfo",
    "VideoReader",
    "VideoWriter",
    "default_video_codec",
    "check_video_complete",
    "list_frame_files",
    "read_frames",
    "video_info",
    "video_rate",
    "write_video",
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

#: File extensions :func:`read_frames` decodes as video (lower case, with the dot).
VIDEO_EXTENSIONS: frozenset[str] = frozenset(
    {
        ".mp4", ".m4v", ".avi", ".mov", ".mkv", ".webm", ".mpg", ".mpeg", ".wmv",
        ".flv", ".ogv", ".3gp", ".mts", ".m2ts", ".ts", ".mjpeg", ".mjpg",
    }
)  # fmt: skip

#: Default encoders per output extension, in order of preference (the first one the
#: installed FFmpeg offers is used).
_DEFAULT_CODECS: dict[str, tuple[str, ...]] = {
    ".mp4": ("libx264", "mpeg4"),
    ".m4v": ("libx264", "mpeg4"),
    ".mov": ("libx264", "mpeg4"),
    ".mkv": ("ffv1",),
    ".avi": ("mpeg4", "ffv1"),
    ".webm": ("libvpx-vp9", "libvpx"),
}

#: Extensions :class:`VideoWriter` can write.
VIDEO_WRITE_EXTENSIONS: frozenset[str] = frozenset(_DEFAULT_CODECS)

_DIGITS = re.compile(r"([0-9]+)")

PathLike = str | os.PathLike[str]

# Exceptions PyAV/FFmpeg raise on bad input; all become one-line ValueErrors.
_AV_ERRORS: tuple[type[BaseException], ...] = (
    av.error.FFmpegError,
    EOFError,
    OverflowError,
    UnicodeError,
)


# --------------------------------------------------------------------------- image sequences


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


def _is_int(x: object) -> bool:
    return isinstance(x, int | np.integer) and not isinstance(x, bool)


def _check_selection(
    start: int, stop: int | None, step: int, max_frames: int | None, who: str = "read_frames"
) -> None:
    if not _is_int(start) or start < 0:
        raise ValueError(f"{who}: start must be an integer >= 0, got {start!r}")
    if stop is not None and (not _is_int(stop) or stop < 0):
        raise ValueError(f"{who}: stop must be None or an integer >= 0, got {stop!r}")
    if not _is_int(step) or step < 1:
        raise ValueError(f"{who}: step must be an integer >= 1, got {step!r}")
    if max_frames is not None and (not _is_int(max_frames) or max_frames < 1):
        raise ValueError(f"{who}: max_frames must be None or an integer >= 1, got {max_frames!r}")


def _select(n: int, start: int, stop: int | None, step: int, max_frames: int | None) -> range:
    """Indices ``range(n)[start:stop:step][:max_frames]``."""
    selected = range(n)[int(start) : None if stop is None else int(stop) : int(step)]
    return selected if max_frames is None else selected[: int(max_frames)]


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


# --------------------------------------------------------------------------- errors


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _describe(exc: BaseException) -> str:
    """A short description of a PyAV/FFmpeg exception (without the file name it repeats)."""
    strerror = getattr(exc, "strerror", None)
    if isinstance(exc, av.error.FFmpegError) and strerror:
        return _one_line(strerror)
    return _one_line(f"{type(exc).__name__}: {exc}")


@contextlib.contextmanager
def _av_errors(path: Path, action: str = "read the video") -> Iterator[None]:
    """Turn FFmpeg/PyAV errors raised inside the block into one-line ValueErrors."""
    try:
        yield
    except _AV_ERRORS as exc:
        raise ValueError(f"{path}: cannot {action} ({_describe(exc)})") from exc


def _check_video_path(path: PathLike) -> Path:
    p = Path(os.fspath(path))
    if not p.exists():
        raise FileNotFoundError(2, "video not found", str(p))
    if p.is_dir():
        raise ValueError(f"{p}: is a directory, not a video file")
    return p


# --------------------------------------------------------------------------- video info


@dataclasses.dataclass(frozen=True, slots=True)
class VideoInfo:
    """Description of the first video stream of a file.

    Attributes
    ----------
    n_frames : int
        Exact number of frames (video packets counted by demuxing the file).
    fps : float
        Average frame rate; ``nan`` if the file gives no usable rate.
    height, width : int
        Frame size in pixels.
    channels : int
        3 for colour (frames are RGB), 1 for grey (frames have no channel axis).
    dtype : numpy dtype
        ``uint8``, or ``uint16`` for pixel formats with more than 8 bits per
        component.
    codec : str
        FFmpeg decoder name, e.g. ``"h264"``, ``"ffv1"``.
    pix_fmt : str
        FFmpeg pixel format of the stream, e.g. ``"yuv420p"``, ``"gray16le"``.
    """

    n_frames: int
    fps: float
    height: int
    width: int
    channels: int
    dtype: np.dtype
    codec: str
    pix_fmt: str

    @property
    def frame_shape(self) -> tuple[int, ...]:
        """Shape of one decoded frame: ``(H, W, 3)`` for colour, ``(H, W)`` for grey."""
        if self.channels == 1:
            return (self.height, self.width)
        return (self.height, self.width, self.channels)


def _output_format(pix_fmt: str) -> tuple[str, int, np.dtype]:
    """``(format passed to to_ndarray, channels, dtype)`` for a stream pixel format."""
    fmt = av.VideoFormat(pix_fmt)
    comps = fmt.components
    bits = max((c.bits for c in comps), default=8)
    grey = not fmt.has_palette and (
        len(comps) == 1 or (len(comps) == 2 and pix_fmt.startswith("ya"))
    )
    deep = bits > 8 and not fmt.has_palette
    if grey:
        return ("gray16le" if deep else "gray"), 1, np.dtype(np.uint16 if deep else np.uint8)
    return ("rgb48le" if deep else "rgb24"), 3, np.dtype(np.uint16 if deep else np.uint8)


@dataclasses.dataclass(frozen=True)
class _Index:
    """Packet table of a video stream (decode order) and the presentation order."""

    pts: tuple[int | None, ...]  # per packet, decode order
    dts: tuple[int | None, ...]
    key: np.ndarray  # (P,) bool
    order: np.ndarray  # (F,) decode position of presentation frame i
    keypos: np.ndarray  # decode positions of keyframes, ascending
    seekable: bool  # unique pts on every packet: random access possible
    dec_of_pts: dict[int, int]
    frame_of_pts: dict[int, int]

    @property
    def n_frames(self) -> int:
        return int(self.order.size)

    def start_packet(self, frame: int) -> int | None:
        """Decode position of the keyframe to start decoding ``frame`` from (None: start)."""
        p = int(self.order[frame])
        target = self.pts[p]
        assert target is not None
        j = int(np.searchsorted(self.keypos, p, side="right")) - 1
        while j >= 0:
            q = int(self.keypos[j])
            pts_q = self.pts[q]
            if pts_q is not None and pts_q <= target:
                return q
            j -= 1
        return None


def _scan(container: Any, stream: Any, path: Path) -> _Index:
    """Demux (without decoding) every packet of ``stream`` and index them."""
    pts: list[int | None] = []
    dts: list[int | None] = []
    key: list[bool] = []
    shown: list[bool] = []
    try:
        for packet in container.demux(stream):
            if packet.size == 0:  # the empty packet that flushes the decoder at EOF
                continue
            pts.append(packet.pts)
            dts.append(packet.dts)
            key.append(bool(packet.is_keyframe))
            shown.append(not packet.is_discard)
    except _AV_ERRORS as exc:  # damaged data: keep what precedes it
        if not pts:
            raise
        logger.warning(
            "%s: demuxing stopped after %d packets (%s); later frames are ignored",
            path, len(pts), _describe(exc),
        )  # fmt: skip
    key_arr = np.asarray(key, dtype=bool)
    shown_pos = [i for i, s in enumerate(shown) if s]
    seekable = all(t is not None for t in pts) and len(set(pts)) == len(pts)
    if seekable:
        order = np.asarray(sorted(shown_pos, key=lambda i: pts[i]), dtype=np.int64)
        dec_of_pts = {t: i for i, t in enumerate(pts) if t is not None}
        frame_of_pts: dict[int, int] = {pts[int(p)]: f for f, p in enumerate(order)}
    else:
        logger.info("%s: missing or repeated timestamps; frames are read sequentially", path)
        order = np.asarray(shown_pos, dtype=np.int64)
        dec_of_pts, frame_of_pts = {}, {}
    return _Index(
        pts=tuple(pts),
        dts=tuple(dts),
        key=key_arr,
        order=order,
        keypos=np.flatnonzero(key_arr),
        seekable=seekable,
        dec_of_pts=dec_of_pts,
        frame_of_pts=frame_of_pts,
    )


def _open_input(path: Path) -> tuple[Any, Any]:
    """Open ``path`` and return ``(container, first video stream)``; errors wrapped."""
    with _av_errors(path, "open the video"):
        container = av.open(str(path), "r", metadata_errors="replace")
    try:
        if not container.streams.video:
            raise ValueError(f"{path}: no video stream in the file")
        stream = container.streams.video[0]
        if stream.codec_context is None:
            raise ValueError(f"{path}: no decoder for the video stream's codec")
        return container, stream
    except BaseException:
        container.close()
        raise


def _stream_format(container: Any, stream: Any, path: Path) -> tuple[int, int, str]:
    """``(height, width, pix_fmt)`` from the codec parameters or, if missing, a frame."""
    cc = stream.codec_context
    fmt = cc.format
    if fmt is not None and cc.width > 0 and cc.height > 0:
        return int(cc.height), int(cc.width), str(fmt.name)
    # Parameters not found by probing: decode the first frame (at most 64 packets).
    container.seek(0)
    cc.flush_buffers()
    for k, packet in enumerate(container.demux(stream)):
        for frame in packet.decode():
            return int(frame.height), int(frame.width), str(frame.format.name)
        if k >= 64:
            break
    raise ValueError(f"{path}: cannot determine the frame size and pixel format of the video")


def _frame_rate(stream: Any, index: _Index) -> float:
    for rate in (stream.average_rate, stream.guessed_rate):
        if rate is not None and rate > 0 and math.isfinite(float(rate)):
            return float(rate)
    if index.seekable and index.n_frames > 1 and stream.time_base:
        first = index.pts[int(index.order[0])]
        last = index.pts[int(index.order[-1])]
        if first is not None and last is not None and last > first:
            return (index.n_frames - 1) / float((last - first) * stream.time_base)
    return math.nan


_CACHE_SIZE = 16
_cache: OrderedDict[tuple[Any, ...], tuple[_Index, VideoInfo]] = OrderedDict()
_cache_lock = threading.Lock()


def _cache_key(path: Path) -> tuple[Any, ...]:
    st = path.stat()
    return (str(path.resolve()), st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)


def _probe(path: Path) -> tuple[_Index, VideoInfo]:
    """Index and info of a video (cached per path, size and modification time)."""
    key = _cache_key(path)
    with _cache_lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
            return hit
    container, stream = _open_input(path)
    try:
        with _av_errors(path):
            index = _scan(container, stream, path)
            if index.n_frames == 0:
                raise ValueError(f"{path}: the video stream has no frames")
            fps = _frame_rate(stream, index)
            codec = str(stream.codec_context.name)
            height, width, pix_fmt = _stream_format(container, stream, path)
    finally:
        container.close()
    try:
        _, channels, dtype = _output_format(pix_fmt)
    except ValueError as exc:
        raise ValueError(f"{path}: unsupported pixel format {pix_fmt!r}") from exc
    info = VideoInfo(
        n_frames=index.n_frames,
        fps=fps,
        height=height,
        width=width,
        channels=channels,
        dtype=dtype,
        codec=codec,
        pix_fmt=pix_fmt,
    )
    with _cache_lock:
        _cache[key] = (index, info)
        while len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
    logger.debug("%s: %s", path, info)
    return index, info


def video_info(path: PathLike) -> VideoInfo:
    """Describe the first video stream of a file.

    Parameters
    ----------
    path : str or path-like
        Any container/codec FFmpeg can read (the extension is not checked).

    Returns
    -------
    VideoInfo
        ``n_frames`` is exact: the stream's packets are counted (one demuxing pass
        over the file, no decoding; the result is cached per file).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not a readable video (corrupt, truncated before the first
        frame, no video stream, a directory, ...).

    Examples
    --------
    >>> info = video_info("clip.mp4")  # doctest: +SKIP
    >>> info.n_frames, info.frame_shape, info.dtype  # doctest: +SKIP
    (120, (480, 640, 3), dtype('uint8'))
    """
    return _probe(_check_video_path(path))[1]


def video_rate(path: PathLike) -> Fraction | None:
    """The exact frame rate of the first video stream, as FFmpeg gives it.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    Fraction or None
        The stream's average rate (``24000/1001`` for NTSC film), else its guessed
        rate; None when the file gives neither.  A rate within a relative 1e-6 of an
        integer, a half-integer or a multiple of ``1/1001`` is that number:
        containers with coarse timestamps (Matroska stores frame durations in
        nanoseconds) turn ``48000/1001`` into ``7001/146``.

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`video_info`.
    """
    p = _check_video_path(path)
    container, stream = _open_input(p)
    try:
        for rate in (stream.average_rate, stream.guessed_rate):
            if rate is not None and rate > 0:
                exact = Fraction(rate.numerator, rate.denominator)
                for d in (1, 2, 1001):  # 30, 25/2, 30000/1001, ...
                    near = Fraction(round(exact * d), d)
                    if near > 0 and abs(near - exact) <= exact * Fraction(1, 10**6):
                        return near
                return exact
        return None
    finally:
        container.close()


def check_video_complete(path: PathLike) -> None:
    """Fail when a video's data end before what its header declares (a truncated file).

    Demuxes every packet of the file once (no decoding) and compares with the
    container header: the video stream's declared frame count (AVI, MP4) and the
    container's declared duration (Matroska writes it first) against the last
    packet's end time of any stream.  A file cut off in the middle of its data
    still opens and decodes up to the cut, so :class:`VideoReader` alone reads it
    as a shorter video.

    Parameters
    ----------
    path : str or path-like

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not a readable video, its packets cannot be demuxed to the
        end, or it holds fewer frames (more than one frame period less time) than
        its header declares.
    """
    p = _check_video_path(path)
    index, info = _probe(p)
    container, stream = _open_input(p)
    try:
        with _av_errors(p, "read the video to its end"):
            end = -math.inf
            for packet in container.demux():
                if packet.size == 0 or packet.time_base is None:
                    continue
                ts = packet.pts if packet.pts is not None else packet.dts
                if ts is None:
                    continue
                end = max(end, float((ts + (packet.duration or 0)) * packet.time_base))
            declared_frames = int(stream.frames or 0)
            declared = container.duration / 1e6 if container.duration else None
            start = container.start_time / 1e6 if container.start_time else 0.0
    finally:
        container.close()
    if declared_frames > info.n_frames:
        raise ValueError(
            f"{p}: the video is truncated or damaged: its header declares {declared_frames} "
            f"frames, {info.n_frames} are present"
        )
    period = 1.0 / info.fps if math.isfinite(info.fps) and info.fps > 0 else 0.04
    if declared is not None and math.isfinite(end) and end - start < declared - 1.5 * period:
        raise ValueError(
            f"{p}: the video is truncated or damaged: its header declares {declared:.3f} s, "
            f"the data end after {max(0.0, end - start):.3f} s ({info.n_frames} frames)"
        )


# --------------------------------------------------------------------------- reading


class _Session:
    """An open input container positioned for decoding selected frames."""

    def __init__(self, path: Path, index: _Index, info: VideoInfo) -> None:
        self.path = path
        self.index = index
        self.info = info
        self.out_format = _output_format(info.pix_fmt)[0]
        self.container: Any = None
        self.stream: Any = None

    def close(self) -> None:
        if self.container is not None:
            with contextlib.suppress(*_AV_ERRORS):
                self.container.close()
        self.container = self.stream = None

    def reopen(self) -> Iterator[Any]:
        """Reopen the file and return its packet iterator from the first packet."""
        self.close()
        self.container, self.stream = _open_input(self.path)
        return self.container.demux(self.stream)

    def convert(self, frame: Any, i: int) -> np.ndarray:
        arr = frame.to_ndarray(format=self.out_format)
        if arr.shape != self.info.frame_shape:
            raise ValueError(
                f"{self.path}: frame {i} decodes to shape {arr.shape}, but the video stream "
                f"has frames of shape {self.info.frame_shape}"
            )
        return np.ascontiguousarray(arr, dtype=self.info.dtype)

    def _seek(self, kpos: int | None) -> Iterator[Any]:
        """Packet iterator starting at a keyframe at or before decode position ``kpos``."""
        idx = self.index
        if kpos is None or kpos == 0:
            return self.reopen()
        if self.container is None:
            self.reopen()
        candidates = [int(q) for q in idx.keypos[idx.keypos <= kpos][::-1][:3]]
        for q in candidates:
            ts = idx.dts[q] if idx.dts[q] is not None else idx.pts[q]
            if ts is None or q == 0:
                break
            self.container.seek(int(ts), stream=self.stream, backward=True, any_frame=False)
            self.stream.codec_context.flush_buffers()
            packets = self.container.demux(self.stream)
            first = next((p for p in packets if p.size > 0), None)
            if first is None or first.pts is None:
                continue
            landed = idx.dec_of_pts.get(first.pts)
            if landed is not None and landed <= kpos and idx.key[landed]:
                return itertools.chain([first], packets)
            logger.debug("%s: seek for packet %d landed on packet %s", self.path, kpos, landed)
        return self.reopen()

    def frames(self, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        """Decode the frames ``wanted`` (ascending presentation indices), in order."""
        if not wanted:
            return
        if not self.index.seekable:
            yield from self._sequential(wanted)
            return
        idx = self.index
        w = 0
        target = wanted[0]
        sought = idx.start_packet(target)
        packets = self._seek(sought)
        last_pos = -1
        while True:
            reseek = False
            for packet in packets:
                if packet.pts is not None:
                    last_pos = max(last_pos, idx.dec_of_pts.get(packet.pts, last_pos))
                for frame in packet.decode():
                    f = idx.frame_of_pts.get(frame.pts) if frame.pts is not None else None
                    if f is None or f < target:
                        continue
                    if f > target:
                        raise ValueError(f"{self.path}: frame {target} could not be decoded")
                    yield self.convert(frame, f)
                    w += 1
                    if w == len(wanted):
                        return
                    target = wanted[w]
                kpos = idx.start_packet(target)
                if kpos is not None and kpos > last_pos + 1 and kpos > (sought or 0):
                    sought = kpos  # the next selected frame is GOPs ahead: seek there
                    packets = self._seek(kpos)
                    reseek = True
                    break
            if not reseek:
                raise ValueError(
                    f"{self.path}: frame {target} could not be decoded (the data ends early "
                    "or is damaged)"
                )

    def _sequential(self, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        """Decode from the start and count frames (no usable timestamps)."""
        w = 0
        count = 0
        for packet in self.reopen():
            for frame in packet.decode():
                if count == wanted[w]:
                    yield self.convert(frame, count)
                    w += 1
                    if w == len(wanted):
                        return
                count += 1
        raise ValueError(
            f"{self.path}: frame {wanted[w]} could not be decoded (only {count} frames decode)"
        )


class VideoReader:
    """Frame-accurate reader of the first video stream of a file.

    Parameters
    ----------
    path : str or path-like
        Any file FFmpeg can read.

    Attributes
    ----------
    path : Path
    info : VideoInfo

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is not a readable video.  Reading a damaged frame later also raises
        ValueError.

    Notes
    -----
    Frames are RGB ``(H, W, 3)`` ``uint8`` (8-bit colour), RGB ``uint16``
    (higher bit depths, full 0..65535 range) or ``(H, W)`` for grey pixel formats;
    see :attr:`VideoInfo.frame_shape`.  Opening indexes the packets of the file once
    (cached); :meth:`read` then seeks to the keyframe before the wanted frame and
    decodes forward, so random access costs at most one GOP of decoding.  Use
    :meth:`iter_frames` or :meth:`read_range` for sequences: they decode each
    packet at most once.  The reader is not thread-safe.

    Examples
    --------
    >>> with VideoReader("clip.mp4") as video:  # doctest: +SKIP
    ...     last = video.read(len(video) - 1)
    ...     for frame in video.iter_frames(step=5):
    ...         pass
    """

    def __init__(self, path: PathLike) -> None:
        self.path = _check_video_path(path)
        self._index, self.info = _probe(self.path)
        self._session = _Session(self.path, self._index, self.info)

    def __len__(self) -> int:
        return self.info.n_frames

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        i = self.info
        return (
            f"VideoReader({str(self.path)!r}, {i.n_frames} frames {i.width}x{i.height} "
            f"{i.pix_fmt} {i.codec})"
        )

    def close(self) -> None:
        """Release the decoder (the reader can still be used; it reopens the file)."""
        self._session.close()

    def _selection(self, start: int, stop: int | None, step: int, who: str) -> range:
        _check_selection(start, stop, step, None, who=who)
        return _select(len(self), start, stop, step, None)

    def _decode(self, session: _Session, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        gen = session.frames(wanted)
        while True:
            with _av_errors(self.path, "decode the video"):
                try:
                    frame = next(gen)
                except StopIteration:
                    return
            yield frame

    def read(self, index: int) -> np.ndarray:
        """Decode one frame exactly.

        Parameters
        ----------
        index : int
            Frame index in presentation order; negative values count from the end.

        Returns
        -------
        ndarray, shape (H, W, 3) or (H, W)
            ``uint8`` or ``uint16``.

        Raises
        ------
        IndexError
            If ``index`` is out of range.
        ValueError
            If the frame cannot be decoded (damaged file).
        """
        i = operator.index(index)
        n = len(self)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(f"{self.path}: frame index {index} out of range for {n} frames")
        for frame in self._decode(self._session, [i]):
            return frame
        raise ValueError(f"{self.path}: frame {i} could not be decoded")  # pragma: no cover

    def read_indices(self, indices: Sequence[int]) -> np.ndarray:
        """Decode the frames ``indices`` (ascending, in range) into one array.

        Parameters
        ----------
        indices : sequence of int
            Strictly increasing frame indices.

        Returns
        -------
        ndarray, shape (len(indices), H, W[, 3])
        """
        idx = [operator.index(i) for i in indices]
        if any(b <= a for a, b in zip(idx, idx[1:], strict=False)) or (
            idx and not (0 <= idx[0] and idx[-1] < len(self))
        ):
            raise ValueError(
                f"{self.path}: frame indices must increase strictly within 0..{len(self) - 1}"
            )
        out = np.empty((len(idx), *self.info.frame_shape), dtype=self.info.dtype)
        k = 0
        for k, frame in enumerate(self._decode(self._session, idx), start=1):
            out[k - 1] = frame
        if k != len(idx):  # pragma: no cover - frames() raises first
            raise ValueError(f"{self.path}: only {k} of {len(idx)} frames could be decoded")
        return out

    def read_range(self, start: int, stop: int | None, step: int = 1) -> np.ndarray:
        """Decode the frames ``start:stop:step`` (slice semantics, clipped to the video).

        Parameters
        ----------
        start : int
            First frame (``>= 0``).
        stop : int or None
            End (exclusive); None for the end of the video.
        step : int, default 1

        Returns
        -------
        ndarray, shape (F, H, W, 3) or (F, H, W)
            ``F`` may be 0.
        """
        return self.read_indices(self._selection(start, stop, step, "read_range"))

    def iter_frames(
        self, start: int = 0, stop: int | None = None, step: int = 1
    ) -> Iterator[np.ndarray]:
        """Stream the frames ``start:stop:step`` one by one (bounded memory).

        Parameters
        ----------
        start, stop, step : int
            As in :meth:`read_range`.

        Yields
        ------
        ndarray, shape (H, W, 3) or (H, W)

        Notes
        -----
        The iterator has its own decoder, so :meth:`read` may be called while it is
        in use.  It seeks past GOPs that contain no selected frame.
        """
        wanted = self._selection(start, stop, step, "iter_frames")  # checked before iterating
        return self._stream(wanted)

    def _stream(self, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        session = _Session(self.path, self._index, self.info)
        try:
            yield from self._decode(session, wanted)
        finally:
            session.close()


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


def _read_video(
    path: Path, start: int, stop: int | None, step: int, max_frames: int | None
) -> np.ndarray:
    """The selected frames of a video (at least 2), via :class:`VideoReader`."""
    with VideoReader(path) as reader:
        selected = _select(len(reader), start, stop, step, max_frames)
        if len(selected) < 2:
            raise ValueError(
                f"read_frames: {len(selected)} frame(s) selected from the video {path} "
                f"({len(reader)} frames) with start={start}, stop={stop}, step={step}, "
                f"max_frames={max_frames}; need at least 2"
            )
        frames = reader.read_indices(selected)
    logger.debug("decoded %d frames of %s from %s", len(frames), frames.shape[1:], path)
    return frames


# --------------------------------------------------------------------------- writing


def _has_encoder(name: str) -> bool:
    try:
        codec = av.codec.Codec(name, "w")
    except Exception:  # noqa: BLE001 - unknown codec names raise various errors
        return False
    return codec.type == "video"


def default_video_codec(path: PathLike) -> str:
    """The encoder :class:`VideoWriter` uses for a file name when none is given.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    str
        ``.mp4``/``.m4v``/``.mov``: ``libx264`` (``mpeg4`` if the installed FFmpeg
        lacks it); ``.mkv``: ``ffv1`` (lossless); ``.avi``: ``mpeg4``; ``.webm``:
        ``libvpx-vp9`` (or ``libvpx``).

    Raises
    ------
    ValueError
        For another extension, or if no encoder for it is installed.
    """
    ext = Path(os.fspath(path)).suffix.lower()
    if ext not in _DEFAULT_CODECS:
        raise ValueError(
            f"{path}: cannot write video with extension {ext!r}; use one of "
            f"{', '.join(sorted(VIDEO_WRITE_EXTENSIONS))}"
        )
    for name in _DEFAULT_CODECS[ext]:
        if _has_encoder(name):
            return name
    raise ValueError(
        f"{path}: none of the encoders {', '.join(_DEFAULT_CODECS[ext])} is available in "
        "this FFmpeg build"
    )


_LOSSLESS = frozenset({"ffv1", "ffvhuff", "huffyuv", "utvideo", "png", "rawvideo"})
_CRF_CODECS = frozenset({"libx264", "libx264rgb", "libx265", "libvpx-vp9", "libvpx",
                         "libaom-av1", "libsvtav1"})  # fmt: skip
_QSCALE_CODECS = frozenset({"mpeg4", "mpeg2video", "mpeg1video", "mjpeg", "msmpeg4",
                            "msmpeg4v2"})  # fmt: skip
_DEFAULT_QUALITY = {"libx264": 18, "libx265": 20, "libvpx-vp9": 30, "libvpx": 10}
_DEFAULT_QSCALE = 2
_EVEN_SIZE_CODECS = frozenset({"libx264", "libx265", "h264_nvenc", "hevc_nvenc"})
#: FFmpeg's FF_QP2LAMBDA: global_quality is a quantiser scale times this.
_QP2LAMBDA = 118


def _input_format(grey: bool, deep: bool) -> str:
    """Pixel format of the NumPy frames handed to PyAV."""
    if grey:
        return "gray16le" if deep else "gray"
    return "rgb48le" if deep else "rgb24"


def _default_pix_fmt(codec: str, supported: Sequence[str], grey: bool, deep: bool) -> str:
    if codec in ("ffv1", "ffvhuff"):  # lossless: keep every bit and the RGB values
        lossless = {
            (False, False): "bgr0" if codec == "ffv1" else "rgb24",
            (True, False): "gray",
            (False, True): "gbrp16le",
            (True, True): "gray16le",
        }[(grey, deep)]
        if lossless in supported:
            return lossless
    preferred = ["yuv420p10le", "yuv420p"] if deep else ["yuv420p"]
    for fmt in preferred:
        if not supported or fmt in supported:
            return fmt
    return supported[0]


def _chroma_subsampled(pix_fmt: str) -> bool:
    f = av.VideoFormat(pix_fmt)
    return (
        not f.is_rgb
        and len(f.components) >= 3
        and ("420" in pix_fmt or "422" in pix_fmt or pix_fmt.startswith("nv"))
    )


#: Audio encoders tried, in order, when a container cannot hold the source's codec
#: (after the container's own default).
_AUDIO_ENCODERS = ("aac", "libopus", "libvorbis", "libmp3lame", "flac")


class _AudioCopy:
    """The first audio stream of a file, copied into an output container by time."""

    def __init__(self, source: Path, container: Any, target: Path) -> None:
        self.source = source
        self.mode: str | None = None
        self.codec: str | None = None
        self._src: Any = None
        self._pending: Any = None
        self._container = container
        with _av_errors(source, "read the audio"):
            self._src = av.open(str(source), "r", metadata_errors="replace")
            if not self._src.streams.audio:
                logger.info("%s: no audio stream; %s gets none", source, target)
                self.close()
                return
            ain = self._src.streams.audio[0]
            offset = 0.0
            if self._src.streams.video:
                v = self._src.streams.video[0]
                if v.start_time is not None and v.time_base is not None:
                    offset = float(v.start_time * v.time_base)
            self._offset = offset
            self._in = ain
            name = ain.codec_context.name
            supported = container.supported_codecs
            if name in supported:
                self.out = container.add_stream_from_template(ain)
                self.mode, self.codec = "copy", name
            else:
                encoder = self._encoder(container, supported)
                if encoder is None:
                    self.close()
                    raise ValueError(
                        f"{target}: the container cannot hold the {name} audio of {source}, "
                        "and no encoder for an audio codec it accepts is installed; write "
                        "a .mkv, or leave the audio out"
                    )
                layout = {1: "mono", 2: "stereo"}.get(ain.channels, ain.layout.name)
                self.out = container.add_stream(encoder, rate=ain.sample_rate, layout=layout)
                self.mode, self.codec = "encode", encoder
                logger.info("%s: %s audio re-encoded as %s (the container cannot hold %s)",
                            target, name, encoder, name)
            self._packets = self._src.demux(ain)

    @staticmethod
    def _encoder(container: Any, supported: Any) -> str | None:
        for name in (container.default_audio_codec, *_AUDIO_ENCODERS):
            if not name or name not in supported:
                continue
            try:
                codec = av.codec.Codec(name, "w")
            except Exception:  # noqa: BLE001 - unknown codec names raise various errors
                continue
            if codec.type == "audio" and not codec.experimental:
                return name
        return None

    def _time(self, packet: Any) -> float | None:
        ts = packet.pts if packet.pts is not None else packet.dts
        if ts is None or packet.time_base is None:
            return None
        return float(ts * packet.time_base) - self._offset

    def _emit(self, packet: Any, container: Any) -> None:
        if self.mode == "copy":
            if packet.size == 0:
                return
            if self._offset:
                shift = round(self._offset / packet.time_base)
                if packet.pts is not None:
                    packet.pts -= shift
                if packet.dts is not None:
                    packet.dts -= shift
            packet.stream = self.out
            container.mux(packet)
            return
        for frame in packet.decode():
            t = float(frame.pts * frame.time_base) - self._offset if frame.pts is not None else None
            if t is not None:
                frame.pts = round(t * frame.sample_rate)
                frame.time_base = Fraction(1, frame.sample_rate)
            for out in self.out.encode(frame):
                container.mux(out)

    def mux_until(self, seconds: float | None) -> None:
        """Mux the source's audio packets that start before ``seconds`` (None: all)."""
        if self._src is None:
            return
        container = self._container
        with _av_errors(self.source, "copy the audio"):
            while True:
                packet = self._pending
                self._pending = None
                if packet is None:
                    packet = next(self._packets, None)
                    if packet is None:
                        return
                t = self._time(packet)
                if seconds is not None and t is not None and t >= seconds and packet.size:
                    self._pending = packet
                    return
                self._emit(packet, container)

    def finish(self) -> None:
        """Mux the rest of the audio and flush the encoder, then close the source."""
        if self._src is None:
            return
        self.mux_until(None)
        if self.mode == "encode":
            with _av_errors(self.source, "copy the audio"):
                for out in self.out.encode(None):
                    self._container.mux(out)
        self.close()

    def close(self) -> None:
        if self._src is not None:
            with contextlib.suppress(*_AV_ERRORS):
                self._src.close()
        self._src = None


class VideoWriter:
    """Encode frames into a video file, atomically.

    Parameters
    ----------
    path : str or path-like
        Target file; the extension selects the container (one of
        :data:`VIDEO_WRITE_EXTENSIONS`).  Its directory must exist.
    fps : float, default 25
        Frame rate (positive).
    codec : str, optional
        FFmpeg encoder; default :func:`default_video_codec` of ``path``.
    pix_fmt : str, optional
        Pixel format of the encoded stream (must be supported by the encoder).
        Default: lossless formats for FFV1 (``bgr0``, ``gray``, ``gbrp16le``,
        ``gray16le`` after the input's type), ``yuv420p10le`` for ``uint16`` input
        where the encoder offers it, else ``yuv420p``.
    quality : int, optional
        Constant-quality setting, lower is better: CRF for ``libx264``/``libx265``
        (0..51, default 18/20; ``libx264rgb``: default 23, 0 is lossless) and
        ``libvpx(-vp9)`` (0..63, default 30 for VP9), the quantiser scale for
        ``mpeg4``/``mjpeg`` (1..31, default 2).  Ignored (with a log message) by
        lossless encoders.
    options : mapping of str to str, optional
        Further encoder options, e.g. ``{"g": "12", "bf": "2", "preset": "fast"}``;
        they override the ones derived from ``quality``.
    audio : str or path-like, optional
        A media file whose first audio stream is copied into the output (none by
        default; a file without audio adds none).  Its packets are remuxed
        unchanged when the container can hold the codec, else decoded and
        re-encoded with the first encoder of the container's default audio codec,
        AAC, Opus, Vorbis, MP3 or FLAC it accepts (:attr:`audio_mode` says which);
        they are interleaved with the video by time, shifted so that the source's
        first video frame and the output's coincide, and the whole stream is
        copied (it is not cut to the video's length).

    Attributes
    ----------
    audio_mode : str or None
        After the first frame: ``"copy"``, ``"encode"`` or None (no audio).
    audio_codec : str or None
        The output's audio codec.

    Raises
    ------
    ValueError
        Unknown extension or encoder, unsupported pixel format, bad ``fps`` or
        ``quality``; from :meth:`write`, frames of another shape or dtype than the
        first one or an encoder error; an unreadable ``audio`` file, or an audio
        codec the container cannot hold when no encoder for one it can is
        installed.
    FileNotFoundError
        If the target directory does not exist.

    Notes
    -----
    Frames are ``(H, W, 3)`` RGB or ``(H, W)`` grey, ``uint8`` or ``uint16``; the
    stream is created from the first frame.  Encoders that need even sizes with
    chroma subsampling (``libx264``, ``libx265``) get frames padded by one
    replicated row/column when ``H`` or ``W`` is odd (the file is then one pixel
    larger; a message is logged).  The video is encoded into a hidden temporary file
    with the same extension in the target directory and moved onto ``path`` by
    :meth:`close` (``os.replace``); if the ``with`` block fails, or :meth:`abort` is
    called, the temporary file is deleted and ``path`` is left as it was.

    Examples
    --------
    >>> with VideoWriter("out.mkv", fps=30) as writer:  # doctest: +SKIP
    ...     for frame in frames:
    ...         writer.write(frame)
    """

    def __init__(
        self,
        path: PathLike,
        fps: float = 25.0,
        *,
        codec: str | None = None,
        pix_fmt: str | None = None,
        quality: int | None = None,
        options: Mapping[str, str] | None = None,
        audio: PathLike | None = None,
    ) -> None:
        self.path = Path(os.fspath(path))
        ext = self.path.suffix.lower()
        if ext not in VIDEO_WRITE_EXTENSIONS:
            raise ValueError(
                f"{self.path}: cannot write video with extension {ext!r}; use one of "
                f"{', '.join(sorted(VIDEO_WRITE_EXTENSIONS))}"
            )
        directory = self.path.parent
        if not directory.is_dir():
            raise FileNotFoundError(
                2, f"cannot write {self.path}: directory does not exist", str(directory)
            )
        if self.path.is_dir():
            raise IsADirectoryError(21, "cannot write video: is a directory", str(self.path))
        try:
            rate = Fraction(fps).limit_denominator(65535)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ValueError(f"VideoWriter: fps must be a positive number, got {fps!r}") from exc
        if not (math.isfinite(float(fps)) and rate > 0):
            raise ValueError(f"VideoWriter: fps must be a positive number, got {fps!r}")
        self.fps = float(fps)
        self._rate = rate
        self.codec = codec if codec is not None else default_video_codec(self.path)
        if not _has_encoder(self.codec):
            raise ValueError(f"{self.path}: the encoder {self.codec!r} is not available")
        formats = av.codec.Codec(self.codec, "w").video_formats or ()
        self._supported = [f.name for f in formats]
        if pix_fmt is not None and self._supported and pix_fmt not in self._supported:
            raise ValueError(
                f"{self.path}: the encoder {self.codec} does not support pix_fmt {pix_fmt!r}; "
                f"supported: {', '.join(self._supported)}"
            )
        self.pix_fmt = pix_fmt
        if quality is not None and (not _is_int(quality) or quality < 0):
            raise ValueError(f"VideoWriter: quality must be an integer >= 0, got {quality!r}")
        self._options = self._codec_options(quality)
        self._options.update({str(k): str(v) for k, v in (options or {}).items()})
        self.frames_written = 0
        self._shape: tuple[int, ...] | None = None
        self._dtype: np.dtype | None = None
        self._pad = (0, 0)
        self._in_format = ""
        self._frame_time_base = Fraction(1, 1) / self._rate
        self._container: Any = None
        self._stream: Any = None
        self._tmp: Path | None = None
        self._closed = False
        self._audio_source = None if audio is None else _check_video_path(audio)
        self._audio: _AudioCopy | None = None
        self.audio_mode: str | None = None
        self.audio_codec: str | None = None

    def _codec_options(self, quality: int | None) -> dict[str, str]:
        name = self.codec
        if name in _LOSSLESS:
            if quality is not None:
                logger.info("%s is lossless; quality=%s ignored", name, quality)
            return {"level": "3", "slicecrc": "1"} if name == "ffv1" else {}
        if name in _CRF_CODECS:
            crf = _DEFAULT_QUALITY.get(name, 23) if quality is None else int(quality)
            opts = {"crf": str(crf)}
            if name.startswith("libvpx"):
                opts["b"] = "0"  # constant quality without a bit-rate cap
            return opts
        if name in _QSCALE_CODECS:
            q = _DEFAULT_QSCALE if quality is None else int(quality)
            return {"flags": "+qscale", "global_quality": str(max(1, q) * _QP2LAMBDA)}
        if quality is not None:
            logger.info("quality is not mapped for encoder %s; ignored", name)
        return {}

    # -- context manager

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:  # never leave a temporary file behind
        if not getattr(self, "_closed", True):
            with contextlib.suppress(Exception):
                self.abort()

    # -- writing

    def _start(self, arr: np.ndarray) -> None:
        grey = arr.ndim == 2
        deep = arr.dtype == np.uint16
        h, w = arr.shape[:2]
        pix_fmt = self.pix_fmt or _default_pix_fmt(self.codec, self._supported, grey, deep)
        if self.codec in _EVEN_SIZE_CODECS and _chroma_subsampled(pix_fmt):
            self._pad = (h % 2, w % 2)
            if any(self._pad):
                logger.info(
                    "%s: %s with %s needs even sizes; %dx%d frames padded to %dx%d",
                    self.path, self.codec, pix_fmt, w, h, w + self._pad[1], h + self._pad[0],
                )  # fmt: skip
        if deep and pix_fmt in ("yuv420p", "yuv422p", "yuv444p", "bgr0", "rgb24", "gray"):
            logger.warning("%s: uint16 frames stored with 8 bits (%s)", self.path, pix_fmt)
        self._in_format = _input_format(grey, deep)
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{self.path.stem}.", suffix=self.path.suffix, dir=self.path.parent
        )
        os.close(fd)
        self._tmp = Path(tmp_name)
        with _av_errors(self.path, f"write the video with {self.codec}"):
            self._container = av.open(str(self._tmp), "w")
            stream = self._container.add_stream(
                self.codec, rate=self._rate, options=dict(self._options)
            )
            stream.width = w + self._pad[1]
            stream.height = h + self._pad[0]
            stream.pix_fmt = pix_fmt
            self._stream = stream
            self._frame_time_base = Fraction(1, 1) / self._rate
        if self._audio_source is not None:
            self._audio = _AudioCopy(self._audio_source, self._container, self.path)
            self.audio_mode, self.audio_codec = self._audio.mode, self._audio.codec
        self.pix_fmt = pix_fmt
        self._shape = arr.shape
        self._dtype = arr.dtype
        logger.debug(
            "writing %s: %s %s, %dx%d, %.6g fps, options %s",
            self.path, self.codec, pix_fmt, w, h, self.fps, self._options,
        )  # fmt: skip

    def write(self, frame: np.ndarray) -> None:
        """Encode one frame.

        Parameters
        ----------
        frame : ndarray, shape (H, W, 3), (H, W, 1) or (H, W), uint8 or uint16
            RGB or grey; every frame must match the first in shape and dtype.
        """
        if self._closed:
            raise ValueError(f"{self.path}: the video writer is closed")
        arr = np.asarray(frame)
        if arr.ndim == 3 and arr.shape[2] == 1:
            arr = arr[..., 0]
        if arr.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"VideoWriter: frames must be uint8 or uint16, got {arr.dtype}")
        if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)) or min(arr.shape[:2]) < 1:
            raise ValueError(
                f"VideoWriter: a frame must have shape (H, W, 3) or (H, W), got {arr.shape}"
            )
        if self._container is None:
            self._start(arr)
        elif arr.shape != self._shape or arr.dtype != self._dtype:
            raise ValueError(
                f"VideoWriter: frame {self.frames_written} has shape {arr.shape} and dtype "
                f"{arr.dtype}, but frame 0 has shape {self._shape} and dtype {self._dtype}"
            )
        if any(self._pad):
            pad = [(0, self._pad[0]), (0, self._pad[1])] + [(0, 0)] * (arr.ndim - 2)
            arr = np.pad(arr, pad, mode="edge")
        with _av_errors(self.path, f"write the video with {self.codec}"):
            vframe = av.VideoFrame.from_ndarray(np.ascontiguousarray(arr), format=self._in_format)
            vframe.pts = self.frames_written
            vframe.time_base = self._frame_time_base
            for packet in self._stream.encode(vframe):
                self._container.mux(packet)
        self.frames_written += 1
        if self._audio is not None:
            self._audio.mux_until(self.frames_written / self._rate)

    def close(self) -> None:
        """Flush the encoder and move the finished file onto the target.

        Raises
        ------
        ValueError
            If no frame was written (nothing is created) or encoding fails (the
            temporary file is removed).
        """
        if self._closed:
            return
        if self._container is None:
            self._closed = True
            raise ValueError(f"{self.path}: no frames were written; no video created")
        try:
            with _av_errors(self.path, f"write the video with {self.codec}"):
                for packet in self._stream.encode(None):
                    self._container.mux(packet)
                if self._audio is not None:
                    self._audio.finish()
                    self._audio = None
                self._container.close()
            self._container = None
            assert self._tmp is not None
            fd = os.open(self._tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            try:
                perm = stat.S_IMODE(self.path.stat().st_mode)
            except FileNotFoundError:
                perm = _NEW_FILE_MODE
            os.chmod(self._tmp, perm)
            os.replace(self._tmp, self.path)
            self._tmp = None
        except BaseException:
            self.abort()
            raise
        self._closed = True
        _fsync_directory(self.path.parent)
        logger.debug("wrote %d frames to %s", self.frames_written, self.path)

    def abort(self) -> None:
        """Stop writing and delete the temporary file; the target is left untouched."""
        self._closed = True
        if self._audio is not None:
            self._audio.close()
            self._audio = None
        if self._container is not None:
            with contextlib.suppress(Exception):
                self._container.close()
            self._container = None
        if self._tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                self._tmp.unlink()
            self._tmp = None


def write_video(
    path: PathLike,
    frames: np.ndarray | Iterable[np.ndarray],
    fps: float = 25.0,
    *,
    codec: str | None = None,
    pix_fmt: str | None = None,
    quality: int | None = None,
    options: Mapping[str, str] | None = None,
) -> int:
    """Write frames to a video file atomically (see :class:`VideoWriter`).

    Parameters
    ----------
    path : str or path-like
        ``.mp4``, ``.mkv`` (lossless FFV1 by default), ``.avi``, ``.mov``, ``.m4v``
        or ``.webm``.
    frames : ndarray, shape (F, H, W, 3) or (F, H, W), or iterable of frames
        ``uint8`` or ``uint16``; an iterable may be a generator (frames are encoded
        as they come).
    fps : float, default 25
    codec, pix_fmt, quality, options
        As in :class:`VideoWriter`.

    Returns
    -------
    int
        Number of frames written.

    Raises
    ------
    ValueError
        On bad frames, no frames, or encoder errors; nothing is left at ``path``
        (an existing file stays as it was).
    """
    if isinstance(frames, np.ndarray) and frames.ndim not in (3, 4):
        raise ValueError(
            f"write_video: frames must have shape (F, H, W, 3) or (F, H, W), got {frames.shape}"
        )
    with VideoWriter(
        path, fps, codec=codec, pix_fmt=pix_fmt, quality=quality, options=options
    ) as writer:
        for frame in frames:
            writer.write(frame)
    return writer.frames_written
