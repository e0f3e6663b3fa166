"""Denoising and restoring a video or a frame folder into a video or a frame folder.

:func:`denoise_video` streams the frames of a video file or of a folder of frames
(:class:`varflow.io.sequences.FrameSource`) through the streaming denoiser
(:func:`varflow.restore.denoise.iter_denoise`: bounded memory, no patch searched
across a scene cut found by :func:`varflow.retime.stream.is_scene_cut`) into a video
(:class:`varflow.io.video.VideoWriter`, the audio of a video input copied) or a
folder of PNG frames, atomically: a failure leaves nothing at the output.  It is the
work of ``varflow denoise`` and the task of ``varflow batch denoise``.
:func:`restore_video` streams them the same way through the restoration chain
(:func:`varflow.restore.chain.iter_restore`), for ``varflow restore``, with the dirt
stage's mask as a second output if asked.  This module needs none of the ``batch``
extra's packages.

Noise level
-----------
``sigma`` is given on the 0-255 scale whatever the bit depth of the frames: 16-bit
frames (16-bit PNG, and videos of more than 8 bits per component, which are decoded
to the full ``uint16`` range) get ``sigma * 257``.  When it is not given it is
estimated on the first frames (:func:`varflow.estimate_noise`) and reported on the
same scale.

Video output
------------
Restoration keeps every bit it computed: without ``codec`` and ``quality`` the video
is lossless where the container allows it (:func:`video_settings`): FFV1 in ``.mkv``
and ``.avi`` (8 and 16 bits), lossless RGB H.264 (``libx264rgb``, CRF 0) in ``.mp4``,
``.mov`` and ``.m4v``, lossless VP9 in ``.webm``.  16-bit frames are stored with 10
bits in ``.mp4`` (H.264 at QP 0) and 8 bits in ``.webm``: not lossless (the summary
says so; use ``.mkv``).  With ``codec`` or ``quality`` the writer's usual settings
apply (:class:`~varflow.io.video.VideoWriter`).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["DenoiseSummary", "FolderWriter", "RestoreSummary", "VideoSettings",
           "denoise_video", "output_kind", "restore_video", "video_settings"]

log = logging.getLogger(__name__)

#: File names of the frames of a folder output: ``000000.png``, ``000001.png``, ...
#: (as ``varflow retime`` names them).
FRAME_NAME = "{:06d}.png"
_FRAME_FILE = re.compile(r"^\d{6}\.png$")

#: ``sigma`` of 16-bit frames is ``sigma * UINT16_SCALE`` (0-255 mapped onto 0-65535).
UINT16_SCALE = 65535 / 255

ProgressCallback = Callable[[int, int], None]


def _default_dir_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o777 & ~mask


# Read once at import (os.umask can only be queried by setting it; not thread-safe).
_NEW_DIR_MODE = _default_dir_mode()


@dataclass
class DenoiseSummary:
    """What :func:`denoise_video` did.

    Attributes
    ----------
    source, output : Path
    method : str
    n_frames : int
        Frames written.
    n_input : int
        Frames of the input (``n_frames`` of them from ``start`` on were denoised).
    start : int
        The first frame denoised.
    rate : Fraction
        Frame rate of the input and the output.
    width, height : int
    channels : int
        1 (grey) or the frames' channels.
    bits : int
        The frames' bit depth: 8 or 16.
    sigma : float
        The noise standard deviation used, on the 0-255 scale.
    sigma_estimated : bool
        Whether ``sigma`` was estimated (else given).
    cuts : int or None
        Scene cuts found (None: not looked for).
    codec : str or None
        The encoder of a video output (None for a folder).
    lossless : bool or None
        Whether the video stores the denoised frames exactly (None: a codec or quality
        chosen by the caller; a folder of PNG frames is lossless).
    video_note : str or None
        Why a video output is not lossless.
    audio : str or None
        ``"copied (codec)"``, ``"re-encoded (codec)"``, or why there is none; None
        for an input without audio or a frame folder.
    seconds : float
        Wall time.
    stats : dict
        The counters of :func:`~varflow.restore.denoise.iter_denoise`.
    """

    source: Path
    output: Path
    method: str
    n_frames: int
    n_input: int
    start: int
    rate: Fraction
    width: int
    height: int
    channels: int
    bits: int
    sigma: float
    sigma_estimated: bool
    cuts: int | None
    codec: str | None = None
    lossless: bool | None = True
    video_note: str | None = None
    audio: str | None = None
    seconds: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def seconds_per_frame(self) -> float:
        """Wall time per frame written."""
        return self.seconds / self.n_frames if self.n_frames else 0.0


@dataclass(frozen=True)
class VideoSettings:
    """The encoder settings of a video output (:func:`video_settings`).

    Attributes
    ----------
    codec : str or None
        FFmpeg encoder (None: the writer's default for the extension).
    pix_fmt : str or None
        Stream pixel format (None: the writer's choice).
    quality : int or None
        :class:`~varflow.io.video.VideoWriter`'s ``quality``.
    options : dict of str to str
        Further encoder options.
    lossless : bool or None
        Whether the frames are stored exactly (None: not known, the caller's choice).
    note : str or None
        Why not, when they are not.
    """

    codec: str | None
    pix_fmt: str | None = None
    quality: int | None = None
    options: dict[str, str] = field(default_factory=dict)
    lossless: bool | None = None
    note: str | None = None


def video_settings(path: str | os.PathLike[str], grey: bool, deep: bool,
                   codec: str | None = None, quality: int | None = None) -> VideoSettings:
    """The encoder settings of a denoised video (see the module notes).

    Parameters
    ----------
    path : str or path-like
        The output; its extension names the container.
    grey, deep : bool
        One channel; 16-bit frames.
    codec, quality : optional
        The caller's choice: given either, the writer's usual settings apply.

    Returns
    -------
    VideoSettings
    """
    from ..io.codecs import default_video_codec, has_encoder

    if codec is not None or quality is not None:
        name = codec if codec is not None else default_video_codec(path)
        return VideoSettings(codec, quality=quality,
                             lossless=True if name == "ffv1" and quality is None else None)
    ext = Path(os.fspath(path)).suffix.lower()
    if ext in (".mkv", ".avi") and has_encoder("ffv1"):
        return VideoSettings("ffv1", lossless=True)
    if ext in (".mp4", ".mov", ".m4v"):
        if deep and has_encoder("libx264"):  # QP 0 (CRF 0 is not lossless above 8 bits)
            return VideoSettings("libx264", "gray10le" if grey else "yuv444p10le",
                                 options={"crf": "-1", "qp": "0"}, lossless=False,
                                 note=f"16-bit frames stored with 10 bits in {ext}; use .mkv")
        if not deep and has_encoder("libx264rgb"):
            return VideoSettings("libx264rgb", "rgb24", quality=0, lossless=True)
    if ext == ".webm" and has_encoder("libvpx-vp9"):
        return VideoSettings("libvpx-vp9", "gbrp", quality=0, options={"lossless": "1"},
                             lossless=not deep,
                             note="16-bit frames stored with 8 bits in .webm; use .mkv"
                             if deep else None)
    return VideoSettings(None, lossless=False,
                         note=f"no lossless encoder for {ext} in this FFmpeg; use .mkv")


def output_kind(output: str | os.PathLike[str]) -> str:
    """``"video"`` or ``"folder"``; a bad target raises before any work.

    Parameters
    ----------
    output : str or path-like
        A video file (an extension of :data:`varflow.io.video.VIDEO_WRITE_EXTENSIONS`)
        or a folder: a path without extension, or an existing folder that holds
        nothing but frames named as :data:`FRAME_NAME` (an earlier run's).

    Returns
    -------
    str

    Raises
    ------
    FileNotFoundError
        The output's directory does not exist.
    IsADirectoryError, NotADirectoryError, ValueError
        A folder named like a video, a file where a folder is meant, a folder
        holding other files, another extension.
    """
    from ..io.video import VIDEO_WRITE_EXTENSIONS

    out = Path(os.fspath(output))
    suffix = out.suffix.lower()
    parent = out.parent if str(out.parent) else Path(".")
    if suffix in VIDEO_WRITE_EXTENSIONS:
        if out.is_dir():
            raise IsADirectoryError(21, "output: is a directory", str(out))
        kind = "video"
    elif out.is_dir() or not suffix:
        if out.exists() and not out.is_dir():
            raise NotADirectoryError(20, "output: exists and is not a folder", str(out))
        if out.is_dir():
            others = [e.name for e in out.iterdir() if not _FRAME_FILE.match(e.name)]
            if others:
                raise ValueError(
                    f"output: the folder {out} holds other files than frames 000000.png... "
                    f"({others[0]}, ...); remove them or choose another folder")
        kind = "folder"
    else:
        raise ValueError(
            f"output: {out} must be a video ({', '.join(sorted(VIDEO_WRITE_EXTENSIONS))}) "
            "or a folder (a path without extension)")
    if not parent.is_dir():
        raise FileNotFoundError(2, "output: directory does not exist", str(parent))
    return kind


def _fsync_dir(directory: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


class FolderWriter:
    """Frames written as ``000000.png ...`` into a temporary folder, renamed onto
    ``output`` by :meth:`close` (the protocol of :class:`~varflow.io.video.VideoWriter`:
    ``write``, ``close``, ``abort``, a context manager that aborts on an error).

    An existing ``output`` (holding an earlier run's frames, :func:`output_kind`) is
    replaced only once every frame is written; on any failure the temporary folder
    is removed and ``output`` is left as it was.
    """

    def __init__(self, output: str | os.PathLike[str]) -> None:
        self.output = Path(os.fspath(output))
        self.parent = self.output.parent if str(self.output.parent) else Path(".")
        self.tmp: Path | None = Path(tempfile.mkdtemp(prefix=f".{self.output.name}.",
                                                      suffix=".tmp", dir=self.parent))
        self.frames_written = 0

    def write(self, frame: np.ndarray) -> None:
        """Write the next frame (PNG of its bit depth)."""
        from ..io.images import write_image

        if self.tmp is None:
            raise ValueError(f"{self.output}: the writer is closed")
        write_image(self.tmp / FRAME_NAME.format(self.frames_written), frame)
        self.frames_written += 1

    def close(self) -> None:
        """Move the frames onto ``output``."""
        tmp, out, parent = self.tmp, self.output, self.parent
        if tmp is None:
            return
        self.tmp = None
        try:
            os.chmod(tmp, _NEW_DIR_MODE)
            if out.is_dir() and any(out.iterdir()):  # an earlier run's frames
                trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old",
                                              dir=parent))
                os.replace(out, trash)
                try:
                    os.replace(tmp, out)
                except BaseException:
                    os.replace(trash, out)
                    raise
                shutil.rmtree(trash, ignore_errors=True)
            else:
                os.replace(tmp, out)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        _fsync_dir(parent)

    def abort(self) -> None:
        """Remove the temporary folder; ``output`` stays as it was."""
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp = None

    def __enter__(self) -> FolderWriter:
        return self

    def __exit__(self, exc_type: Any, *rest: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def write_frame_folder(output: Path, frames: Iterable[np.ndarray]) -> int:
    """Write frames as ``000000.png ...`` atomically (:class:`FolderWriter`).

    Returns
    -------
    int
        Frames written.
    """
    with FolderWriter(output) as writer:
        for frame in frames:
            writer.write(frame)
    return writer.frames_written


def _check_sigma(sigma: Any) -> float | None:
    if sigma is None:
        return None
    ok = isinstance(sigma, int | float | np.integer | np.floating) and not isinstance(
        sigma, bool) and math.isfinite(float(sigma)) and sigma >= 0
    if not ok:
        raise ValueError(f"sigma: must be a finite number >= 0, got {sigma!r}")
    return float(sigma)


def _check_index(value: Any, name: str, allow_none: bool = False) -> None:
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ValueError(f"{name}: must be an integer >= 0, got {value!r}")


def _counted(frames: Iterator[np.ndarray], expected: int, source: Path) -> Iterator[np.ndarray]:
    """``frames``, raising at their end when fewer than ``expected`` came."""
    k = 0
    for frame in frames:
        k += 1
        yield frame
    if k < expected:
        raise ValueError(f"{source}: the input ended after {k} of {expected} selected frames "
                         "(truncated?)")


def _check_chunk(chunk: Any) -> None:
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, int)
                              or chunk < 1):
        raise ValueError(f"chunk: must be an integer >= 1, got {chunk!r}")


@dataclass
class _Result:
    """What :meth:`_Job.run` wrote."""

    first: np.ndarray
    n_input: int
    rate: Fraction
    written: int
    codec: str | None
    lossless: bool | None
    video_note: str | None
    audio: str | None


@dataclass
class _Job:
    """A video or frame folder streamed through a per-frame process into an output
    (and optionally a mask output), atomically: the machinery of
    :func:`denoise_video` and :func:`restore_video`."""

    source: Path
    output: Path
    kind: str
    start: int
    stop: int | None
    rate: Fraction | None
    codec: str | None
    quality: int | None
    mask: Path | None = None
    mask_kind: str | None = None

    @classmethod
    def check(cls, source: Any, output: Any, start: Any, stop: Any, input_fps: Any,
              codec: str | None, quality: int | None, mask: Any = None) -> _Job:
        """Check the arguments before any work (see :func:`denoise_video`)."""
        from ..retime.schedule import parse_rate

        _check_index(start, "start")
        _check_index(stop, "stop", allow_none=True)
        rate = None if input_fps is None else parse_rate(input_fps, "input fps")
        src_path, out_path = Path(os.fspath(source)), Path(os.fspath(output))
        kind = output_kind(out_path)
        if kind == "folder" and (codec is not None or quality is not None):
            raise ValueError("codec/quality: the output is a folder of PNG frames")
        paths = [("output", out_path)]
        mask_path = mask_kind = None
        if mask is not None:
            mask_path = Path(os.fspath(mask))
            mask_kind = output_kind(mask_path)
            paths.append(("mask", mask_path))
            if mask_path.resolve() == out_path.resolve():
                raise ValueError(f"mask: {mask_path} is also the output")
        for name, path in paths:
            if src_path.exists() and path.exists() and src_path.resolve() == path.resolve():
                raise ValueError(f"{name}: {path} is the input")
        return cls(src_path, out_path, kind, start, stop, rate, codec, quality, mask_path,
                   mask_kind)

    def run(self, process: Callable[..., Iterator[tuple[np.ndarray, np.ndarray | None]]],
            audio: bool, callback: ProgressCallback | None) -> _Result:
        """Stream the selected frames through ``process(first, frames, n)`` (which
        yields ``(frame, mask)``, one per frame, in order) into the outputs."""
        from ..io.sequences import FrameSource

        src = FrameSource(self.source, self.rate)
        try:
            selected = range(src.n)[self.start:self.stop]
            if not selected:
                given = f"start {self.start}" + ("" if self.stop is None else
                                                 f", stop {self.stop}")
                raise ValueError(f"{self.source}: no frame selected ({given}); the input "
                                 f"has {src.n} frames")
            frames = _counted(src.frames(self.start, self.stop), len(selected), self.source)
            first = next(frames)
            log.info("%s: %s of %d frames at %s fps", self.source, src.kind, src.n, src.rate)
            outputs = process(first, chain([first], frames), len(selected))
            if callback is not None:
                callback(0, len(selected))
            settings = VideoSettings(None)
            audio_note: str | None = None
            deep = first.dtype == np.uint16
            if self.kind == "video":
                from ..io.video import VideoWriter

                settings = video_settings(self.output, first.ndim == 2, deep, self.codec,
                                          self.quality)
                whole = self.start == 0 and len(selected) == src.n
                copy_audio = audio and src.kind == "video" and whole
                if audio and src.kind == "video" and not whole:
                    audio_note = "left out (a section of the input)"
                writer: Any = VideoWriter(
                    self.output, src.rate, codec=settings.codec, pix_fmt=settings.pix_fmt,
                    quality=settings.quality, options=settings.options,
                    audio=self.source if copy_audio else None)
            else:
                if src.kind == "video" and audio:
                    audio_note = "left out (the output is a folder of frames)"
                writer = FolderWriter(self.output)
            with writer, self._mask_writer(src.rate) as masks:
                for k, (frame, mask) in enumerate(outputs, 1):
                    writer.write(frame)
                    if masks is not None:
                        m = np.zeros(first.shape[:2], bool) if mask is None else mask
                        masks.write(np.where(m, np.uint8(255), np.uint8(0)))
                    if callback is not None:
                        callback(k, len(selected))
            codec_used: str | None = None
            if self.kind == "video":
                if writer.audio_mode == "copy":
                    audio_note = f"copied ({writer.audio_codec})"
                elif writer.audio_mode == "encode":
                    audio_note = f"re-encoded ({writer.audio_codec})"
                codec_used = writer.codec
        finally:
            src.close()
        return _Result(first, src.n, src.rate, writer.frames_written, codec_used,
                       settings.lossless if self.kind == "video" else True, settings.note,
                       audio_note)

    def _mask_writer(self, rate: Fraction) -> Any:
        if self.mask is None:
            return contextlib.nullcontext()
        if self.mask_kind == "folder":
            return FolderWriter(self.mask)
        from ..io.video import VideoWriter

        s = video_settings(self.mask, True, False)
        return VideoWriter(self.mask, rate, codec=s.codec, pix_fmt=s.pix_fmt,
                           quality=s.quality, options=s.options)


def denoise_video(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    sigma: float | None = None,
    method: str | None = None,
    params: Any = None,
    start: int = 0,
    stop: int | None = None,
    input_fps: Any = None,
    codec: str | None = None,
    quality: int | None = None,
    audio: bool = True,
    scene_cuts: bool = True,
    chunk: int | None = None,
    callback: ProgressCallback | None = None,
    **overrides: Any,
) -> DenoiseSummary:
    """Denoise a video or a frame folder into a video or a frame folder.

    Parameters
    ----------
    source : str or path-like
        A video file (anything FFmpeg reads) or a folder of frames (natural order,
        :func:`varflow.io.sequences.list_frame_files`).
    output : str or path-like
        A video (lossless where the container allows it, see the module notes) or a
        folder (a path without extension, or an existing folder of an earlier run's
        frames), which receives ``000000.png``, ``000001.png``, ... of the input's
        bit depth.  Written atomically: on any failure nothing is left at ``output``
        (an existing output stays as it was).
    sigma : float, optional
        Noise standard deviation on the 0-255 scale (``* 257`` for 16-bit frames);
        None: estimated on the first frames.
    method, params, **overrides
        A method of :data:`varflow.registry.RESTORE` (its default when None) and its
        parameters (as :func:`varflow.denoise`).
    start, stop : int, optional
        The frames ``start <= k < stop`` (default: all of them).
    input_fps : str, float or Fraction, optional
        The input's frame rate (a folder's: default 25), also the output's.
    codec, quality : optional
        Encoder and quality of a video output (:class:`varflow.io.video.VideoWriter`);
        default: lossless.
    audio : bool
        Copy the first audio stream of a video input into a video output (only when
        every frame is denoised: the audio of a section would be out of step).
    scene_cuts : bool
        Search no patch across a scene cut.
    chunk : int, optional
        Frames estimated per batch (the denoiser's default when None).
    callback : callable, optional
        ``callback(done, total)`` after every frame written.

    Returns
    -------
    DenoiseSummary

    Raises
    ------
    FileNotFoundError
        A missing input or output directory.
    ValueError
        A bad method, parameter, ``sigma``, ``start``/``stop``, rate or output; an
        unreadable, corrupt or truncated input (checked against its header before
        the work, and while decoding), an empty folder, a single image, frames of
        different sizes, no frame selected.
    """
    from ..registry import RESTORE
    from ..retime.stream import is_scene_cut
    from .denoise import iter_denoise

    t0 = time.perf_counter()
    entry = RESTORE.entry(method if method is not None else RESTORE.default)
    p = RESTORE.make_params(entry, params, **overrides)
    sigma = _check_sigma(sigma)
    _check_chunk(chunk)
    job = _Job.check(source, output, start, stop, input_fps, codec, quality)
    stats: dict[str, Any] = {}

    def process(first: np.ndarray, frames: Iterator[np.ndarray], n: int
                ) -> Iterator[tuple[np.ndarray, None]]:
        scale = UINT16_SCALE if first.dtype == np.uint16 else 1.0
        kwargs: dict[str, Any] = {} if chunk is None else {"chunk": chunk}
        log.info("%s: %d frames selected; %s, %s", job.source, n, entry.name, p)
        for frame in iter_denoise(
                frames, None if sigma is None else sigma * scale, entry.name, params=p,
                is_cut=is_scene_cut if scene_cuts else None, stats=stats, **kwargs):
            yield frame, None

    r = job.run(process, audio, callback)
    scale = UINT16_SCALE if r.first.dtype == np.uint16 else 1.0
    first = r.first
    return DenoiseSummary(
        source=job.source, output=job.output, method=entry.name, n_frames=r.written,
        n_input=r.n_input, start=start, rate=r.rate, width=first.shape[1],
        height=first.shape[0], channels=1 if first.ndim == 2 else first.shape[2],
        bits=8 * first.dtype.itemsize, sigma=float(stats.get("sigma", 0.0)) / scale,
        sigma_estimated=sigma is None,
        cuts=int(stats.get("cuts", 0)) if scene_cuts else None, codec=r.codec,
        lossless=r.lossless, video_note=r.video_note, audio=r.audio,
        seconds=time.perf_counter() - t0, stats=stats,
    )


@dataclass
class RestoreSummary:
    """What :func:`restore_video` did.

    Attributes
    ----------
    source, output : Path
    stages : list of str
        The stages run, in order.
    denoise_method : str or None
        The denoiser of the ``denoise`` stage.
    n_frames, n_input, start, rate, width, height, channels, bits
        As in :class:`DenoiseSummary`.
    sigma : float or None
        The noise standard deviation of ``denoise`` on the 0-255 scale.
    sigma_estimated : bool
    cuts : int or None
    masked : float
        Fraction of the pixels the dirt stage replaced.
    mask : Path or None
        The mask output.
    codec, lossless, video_note, audio
        As in :class:`DenoiseSummary`.
    seconds : float
        Wall time.
    stage_seconds : dict of str to float
        Wall time of each stage (reading, writing and scene-cut tests are outside
        them).
    """

    source: Path
    output: Path
    stages: list[str]
    denoise_method: str | None
    n_frames: int
    n_input: int
    start: int
    rate: Fraction
    width: int
    height: int
    channels: int
    bits: int
    sigma: float | None
    sigma_estimated: bool
    cuts: int | None
    masked: float
    mask: Path | None
    codec: str | None
    lossless: bool | None
    video_note: str | None
    audio: str | None
    seconds: float
    stage_seconds: dict[str, float] = field(default_factory=dict)

    @property
    def seconds_per_frame(self) -> float:
        """Wall time per frame written."""
        return self.seconds / self.n_frames if self.n_frames else 0.0


def restore_video(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    stages: Iterable[str] | None = None,
    *,
    sigma: float | None = None,
    params: Mapping[str, Any] | None = None,
    denoise_method: str | None = None,
    mask: str | os.PathLike[str] | None = None,
    start: int = 0,
    stop: int | None = None,
    input_fps: Any = None,
    codec: str | None = None,
    quality: int | None = None,
    audio: bool = True,
    scene_cuts: bool = True,
    chunk: int | None = None,
    callback: ProgressCallback | None = None,
) -> RestoreSummary:
    """Restore a video or a frame folder (stabilise, deflicker, dirt, denoise) into a
    video or a frame folder, streamed (:func:`varflow.restore.chain.iter_restore`).

    Parameters
    ----------
    source, output, start, stop, input_fps, codec, quality, audio, scene_cuts, callback
        As in :func:`denoise_video`.
    stages : iterable of str, optional
        Names of :data:`varflow.restore.chain.STAGES`; default all of them.  They
        run in the order of practice whatever the order given.
    sigma : float, optional
        The noise's standard deviation on the 0-255 scale (``denoise``); None:
        estimated on the repaired frames.
    params : mapping, optional
        ``{stage: parameter dataclass or dict of fields}``.
    denoise_method : str, optional
        The denoiser (:data:`varflow.registry.RESTORE`).
    mask : str or path-like, optional
        A second output (video or folder, as ``output``): per frame, white where the
        dirt stage replaced the picture.  Written atomically too.
    chunk : int, optional
        Frames given out per window of a repair stage (default 24).

    Returns
    -------
    RestoreSummary

    Raises
    ------
    FileNotFoundError, ValueError
        As :func:`denoise_video`; a bad stage or parameter (named).
    """
    from ..retime.stream import is_scene_cut
    from .chain import DENOISE, iter_restore, resolve_stages

    t0 = time.perf_counter()
    resolved = resolve_stages(stages, params, denoise_method)  # checked before any work
    names = [name for name, _, _ in resolved]
    method = next((e.name for name, e, _ in resolved if name == DENOISE), None)
    sigma = _check_sigma(sigma)
    _check_chunk(chunk)
    job = _Job.check(source, output, start, stop, input_fps, codec, quality, mask)
    stats: dict[str, Any] = {}
    given = {name: p for name, _, p in resolved}

    def process(first: np.ndarray, frames: Iterator[np.ndarray], n: int
                ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        scale = UINT16_SCALE if first.dtype == np.uint16 else 1.0
        log.info("%s: %d frames selected; stages %s", job.source, n, ", ".join(names))
        yield from iter_restore(
            frames, names, sigma=None if sigma is None else sigma * scale, params=given,
            denoise_method=method, chunk=24 if chunk is None else chunk,
            is_cut=is_scene_cut if scene_cuts else None, stats=stats)

    r = job.run(process, audio, callback)
    first = r.first
    scale = UINT16_SCALE if first.dtype == np.uint16 else 1.0
    pixels = max(r.written * first.shape[0] * first.shape[1], 1)
    return RestoreSummary(
        source=job.source, output=job.output, stages=names, denoise_method=method,
        n_frames=r.written, n_input=r.n_input, start=start, rate=r.rate,
        width=first.shape[1], height=first.shape[0],
        channels=1 if first.ndim == 2 else first.shape[2], bits=8 * first.dtype.itemsize,
        sigma=None if method is None else float(stats.get("sigma", 0.0)) / scale,
        sigma_estimated=sigma is None, cuts=int(stats.get("cuts", 0)) if scene_cuts else None,
        masked=float(stats.get("masked", 0)) / pixels, mask=job.mask, codec=r.codec,
        lossless=r.lossless, video_note=r.video_note, audio=r.audio,
        seconds=time.perf_counter() - t0, stage_seconds=dict(stats.get("seconds", {})),
    )
