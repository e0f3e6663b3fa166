"""Writing a video atomically: :class:`VideoWriter` and :func:`write_video`.

Frames are encoded into a hidden temporary file in the target directory and moved onto
the target when the writer closes; the encoder and its settings come from
:mod:`varflow.io.codecs`, the optional audio from :mod:`varflow.io.audio`.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import stat
import tempfile
from collections.abc import Iterable, Mapping
from fractions import Fraction
from pathlib import Path
from types import TracebackType
from typing import Any

import av
import numpy as np

from ._atomic import _NEW_FILE_MODE, _fsync_directory
from .audio import AudioCopy
from .checks import PathLike, av_errors, check_video_path, is_int
from .codecs import (
    EVEN_SIZE_CODECS,
    VIDEO_WRITE_EXTENSIONS,
    chroma_subsampled,
    codec_options,
    default_pix_fmt,
    default_video_codec,
    has_encoder,
    input_format,
)

__all__ = ["VideoWriter", "write_video"]

logger = logging.getLogger(__name__)


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
        if not has_encoder(self.codec):
            raise ValueError(f"{self.path}: the encoder {self.codec!r} is not available")
        formats = av.codec.Codec(self.codec, "w").video_formats or ()
        self._supported = [f.name for f in formats]
        if pix_fmt is not None and self._supported and pix_fmt not in self._supported:
            raise ValueError(
                f"{self.path}: the encoder {self.codec} does not support pix_fmt {pix_fmt!r}; "
                f"supported: {', '.join(self._supported)}"
            )
        self.pix_fmt = pix_fmt
        if quality is not None and (not is_int(quality) or quality < 0):
            raise ValueError(f"VideoWriter: quality must be an integer >= 0, got {quality!r}")
        self._options = codec_options(self.codec, quality)
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
        self._audio_source = None if audio is None else check_video_path(audio)
        self._audio: AudioCopy | None = None
        self.audio_mode: str | None = None
        self.audio_codec: str | None = None

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
        pix_fmt = self.pix_fmt or default_pix_fmt(self.codec, self._supported, grey, deep)
        if self.codec in EVEN_SIZE_CODECS and chroma_subsampled(pix_fmt):
            self._pad = (h % 2, w % 2)
            if any(self._pad):
                logger.info(
                    "%s: %s with %s needs even sizes; %dx%d frames padded to %dx%d",
                    self.path, self.codec, pix_fmt, w, h, w + self._pad[1], h + self._pad[0],
                )  # fmt: skip
        if deep and pix_fmt in ("yuv420p", "yuv422p", "yuv444p", "bgr0", "rgb24", "gray"):
            logger.warning("%s: uint16 frames stored with 8 bits (%s)", self.path, pix_fmt)
        self._in_format = input_format(grey, deep)
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{self.path.stem}.", suffix=self.path.suffix, dir=self.path.parent
        )
        os.close(fd)
        self._tmp = Path(tmp_name)
        with av_errors(self.path, f"write the video with {self.codec}"):
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
            self._audio = AudioCopy(self._audio_source, self._container, self.path)
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
        with av_errors(self.path, f"write the video with {self.codec}"):
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
            with av_errors(self.path, f"write the video with {self.codec}"):
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
