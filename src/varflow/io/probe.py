"""Probing a video: its packet index, :class:`VideoInfo`, exact rate and completeness.

Opening a video demuxes (without decoding) every packet of its first video stream
once (:class:`PacketIndex`); the index and the :class:`VideoInfo` are cached per file
(:func:`probe`).  :func:`video_info`, :func:`video_rate` and
:func:`check_video_complete` are the public entry points; see :mod:`varflow.io.video`
for how the index serves frame-accurate seeking.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
from collections import OrderedDict
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import numpy as np

from .checks import AV_ERRORS, PathLike, av_errors, check_video_path, describe
from .codecs import output_format

__all__ = [
    "PacketIndex",
    "VideoInfo",
    "check_video_complete",
    "open_input",
    "probe",
    "video_info",
    "video_rate",
]

logger = logging.getLogger(__name__)


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


@dataclasses.dataclass(frozen=True)
class PacketIndex:
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


def _scan(container: Any, stream: Any, path: Path) -> PacketIndex:
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
    except AV_ERRORS as exc:  # damaged data: keep what precedes it
        if not pts:
            raise
        logger.warning(
            "%s: demuxing stopped after %d packets (%s); later frames are ignored",
            path, len(pts), describe(exc),
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
    return PacketIndex(
        pts=tuple(pts),
        dts=tuple(dts),
        key=key_arr,
        order=order,
        keypos=np.flatnonzero(key_arr),
        seekable=seekable,
        dec_of_pts=dec_of_pts,
        frame_of_pts=frame_of_pts,
    )


def open_input(path: Path) -> tuple[Any, Any]:
    """Open ``path`` and return ``(container, first video stream)``; errors wrapped."""
    with av_errors(path, "open the video"):
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


def _frame_rate(stream: Any, index: PacketIndex) -> float:
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
_cache: OrderedDict[tuple[Any, ...], tuple[PacketIndex, VideoInfo]] = OrderedDict()
_cache_lock = threading.Lock()


def _cache_key(path: Path) -> tuple[Any, ...]:
    st = path.stat()
    return (str(path.resolve()), st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino)


def probe(path: Path) -> tuple[PacketIndex, VideoInfo]:
    """Index and info of a video (cached per path, size and modification time)."""
    key = _cache_key(path)
    with _cache_lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
            return hit
    container, stream = open_input(path)
    try:
        with av_errors(path):
            index = _scan(container, stream, path)
            if index.n_frames == 0:
                raise ValueError(f"{path}: the video stream has no frames")
            fps = _frame_rate(stream, index)
            codec = str(stream.codec_context.name)
            height, width, pix_fmt = _stream_format(container, stream, path)
    finally:
        container.close()
    try:
        _, channels, dtype = output_format(pix_fmt)
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
    return probe(check_video_path(path))[1]


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
    p = check_video_path(path)
    container, stream = open_input(p)
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
    p = check_video_path(path)
    index, info = probe(p)
    container, stream = open_input(p)
    try:
        with av_errors(p, "read the video to its end"):
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
