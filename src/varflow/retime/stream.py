"""Streaming retiming of videos and frame folders: new frame rates and slow motion.

:func:`retime_frames` turns a stream of source frames into the output frames of a
:class:`~varflow.retime.schedule.Schedule`, in order, reading the source one frame
at a time and holding at most four source frames (the pair being interpolated and
one frame each side, the context of the four-frame methods).  Every pair with
in-between frames is interpolated once for all its times with
:func:`varflow.interpolate`; pass-through frames are the source frames unchanged.
:func:`retime_video` does it from a video file or a frame folder to a video file or
a frame folder, atomically, copying the audio of a video.

Scene cuts
----------
Interpolating across a cut blends two unrelated shots.  :func:`cut_score` measures
how unrelated two frames are, cheaply and without being fooled by fast camera
motion: both frames are reduced to grey thumbnails of at most
:data:`THUMB_SIZE` pixels on the long side; for every global shift of the
thumbnails up to :data:`MAX_SHIFT` of their size, the difference of the
overlapping parts has its mean removed (a change of exposure is not a cut) and
its mean absolute value taken; the smallest one is kept (a pan is a shift),
divided by the frames' own contrast (their mean absolute deviation).  The score is
about 0 for frames of one shot under a global motion and about 1.4 for two
unrelated frames of similar statistics (``E|X - Y| / E|X| = sqrt(2)`` for
independent Gaussian ``X, Y``).
:func:`is_scene_cut` calls a cut when the score is at least
:data:`CUT_THRESHOLD` and, when the neighbouring pairs are known, a spike among
them: at least :data:`CUT_RATIO` times the smaller of their scores and
:data:`CUT_MARGIN` above the larger (a shot of non-rigid motion, water or crowds,
has high scores in every pair; a cut from a calm shot to a busy one has one
neighbour as high as half its own score).  At a cut the
output frames of the pair repeat the nearer source frame (``t < 1/2``: the
first, else the second) instead of interpolating, and a four-frame method is not
given context frames from across a cut.  Gradual transitions (fades, dissolves)
are not cuts; they are interpolated like any motion.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from .methods import DEFAULT_INTERPOLATOR, get_interpolator, interpolate, make_interp_params
from .motion import FlowCache
from .schedule import Schedule, fps_schedule, parse_rate, slowmo_schedule

__all__ = [
    "DEFAULT_INPUT_FPS",  # noqa: F822 - module __getattr__
    "CUT_MARGIN",
    "CUT_RATIO",
    "CUT_THRESHOLD",
    "MAX_SHIFT",
    "RetimeSummary",
    "THUMB_SIZE",
    "cut_score",
    "is_scene_cut",
    "retime_frames",
    "retime_video",
]

log = logging.getLogger(__name__)

#: Long side of the grey thumbnails of :func:`cut_score`, in pixels.
THUMB_SIZE = 48
#: Largest global shift searched by :func:`cut_score`, as a fraction of the thumbnail's
#: width and height (the frames of a pan faster than this per frame are not aligned).
MAX_SHIFT = 0.2
def __getattr__(name: str) -> Any:
    # DEFAULT_INPUT_FPS, the source rate of a frame folder (and of a video without a
    # usable rate) when no input_fps is given, is the readers' own constant
    # (varflow.io.sequences.DEFAULT_FOLDER_FPS), imported on use: it loads PyAV.
    if name == "DEFAULT_INPUT_FPS":
        from ..io.sequences import DEFAULT_FOLDER_FPS

        return DEFAULT_FOLDER_FPS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: :func:`cut_score` at and above which a pair can be a cut.
CUT_THRESHOLD = 0.6
#: A cut's score is at least this many times the smaller score of its neighbour pairs...
CUT_RATIO = 2.0
#: ... and at least this much above the larger one.
CUT_MARGIN = 0.3
#: File names of the frames of a folder output: ``000000.png``, ``000001.png``, ...
FRAME_NAME = "{:06d}.png"
_FRAME_FILE = re.compile(r"^\d{6}\.png$")

#: The source frames the generator holds at most.
MAX_HELD = 4


def _default_dir_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o777 & ~mask


# Read once at import (os.umask can only be queried by setting it; not thread-safe).
_NEW_DIR_MODE = _default_dir_mode()

ProgressCallback = Callable[[int, int], None]


# --------------------------------------------------------------------------- scene cuts


def _thumb(frame: np.ndarray) -> np.ndarray:
    """Grey thumbnail (long side <= THUMB_SIZE, block means), float64, mean removed."""
    a = np.asarray(frame)
    if a.dtype in (np.uint8, np.uint16):
        g = a.astype(np.float64) / np.iinfo(a.dtype).max
    else:
        g = a.astype(np.float64)
    if g.ndim == 3:
        g = g[..., :3].mean(axis=2) if g.shape[2] >= 3 else g[..., 0]
    f = max(1, -(-max(g.shape) // THUMB_SIZE))
    h, w = (g.shape[0] // f) * f, (g.shape[1] // f) * f
    if h == 0 or w == 0:
        h, w, f = g.shape[0], g.shape[1], 1
    g = g[:h, :w].reshape(h // f, f, w // f, f).mean(axis=(1, 3))
    return g - g.mean()


def _score(a: np.ndarray, b: np.ndarray) -> float:
    """:func:`cut_score` of two thumbnails of :func:`_thumb`."""
    if a.shape != b.shape:
        return float("inf")
    h, w = a.shape
    ry, rx = max(1, round(MAX_SHIFT * h)), max(1, round(MAX_SHIFT * w))
    best = np.inf
    for dy in range(-ry, ry + 1):
        ya, yb = (slice(dy, h), slice(0, h - dy)) if dy >= 0 else (slice(0, h + dy),
                                                                   slice(-dy, h))
        for dx in range(-rx, rx + 1):
            xa, xb = (slice(dx, w), slice(0, w - dx)) if dx >= 0 else (slice(0, w + dx),
                                                                       slice(-dx, w))
            d = a[ya, xa] - b[yb, xb]
            best = min(best, float(np.abs(d - d.mean()).mean()))
    contrast = 0.5 * (float(np.abs(a).mean()) + float(np.abs(b).mean()))
    return best / (contrast + 1.0 / 255.0)


def cut_score(frame0: np.ndarray, frame1: np.ndarray) -> float:
    """How unrelated two frames are, after the best global shift (see the module notes).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float in [0, 1].

    Returns
    -------
    float
        About 0 for two frames of one shot under a global motion (up to
        :data:`MAX_SHIFT` of the frame per frame), about 1.4 for unrelated frames;
        ``inf`` for frames of different sizes.
    """
    return _score(_thumb(frame0), _thumb(frame1))


def is_scene_cut(
    frame0: np.ndarray,
    frame1: np.ndarray,
    *,
    previous: np.ndarray | None = None,
    following: np.ndarray | None = None,
    threshold: float = CUT_THRESHOLD,
    ratio: float = CUT_RATIO,
    margin: float = CUT_MARGIN,
) -> bool:
    """Is there a scene cut between ``frame0`` and ``frame1``?

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
    previous, following : ndarray, optional
        The frames before ``frame0`` and after ``frame1``: with them the pair's
        score must also stand out from its neighbours' (``ratio``).
    threshold : float
        Least :func:`cut_score` of a cut.
    ratio : float
        Least ratio of the pair's score to the smaller of its neighbours'.
    margin : float
        Least difference between the pair's score and the larger of its
        neighbours'.

    Returns
    -------
    bool
    """
    t0, t1 = _thumb(frame0), _thumb(frame1)
    prev = None if previous is None else _score(_thumb(previous), t0)
    foll = None if following is None else _score(t1, _thumb(following))
    return _decide(_score(t0, t1), prev, foll, threshold, ratio, margin)


def _decide(score: float, prev: float | None, foll: float | None, threshold: float,
            ratio: float, margin: float = CUT_MARGIN) -> bool:
    if not score >= threshold:
        return False
    neighbours = [s for s in (prev, foll) if s is not None and np.isfinite(s)]
    return not neighbours or (score >= ratio * min(neighbours)
                              and score >= max(neighbours) + margin)


# --------------------------------------------------------------------------- streaming


def retime_frames(
    frames: Iterable[np.ndarray],
    schedule: Schedule,
    method: str | None = None,
    *,
    params: Any = None,
    scene_cuts: bool = True,
    stats: dict[str, Any] | None = None,
    callback: ProgressCallback | None = None,
    **overrides: Any,
) -> Iterator[np.ndarray]:
    """The output frames of ``schedule`` made from a stream of source frames.

    Parameters
    ----------
    frames : iterable of ndarray, each (H, W) or (H, W, C)
        The ``schedule.n_source`` source frames in order, of one shape and dtype
        (uint8, uint16 or float); read lazily, one at a time.
    schedule : Schedule
        From :func:`~varflow.retime.schedule.fps_schedule` or
        :func:`~varflow.retime.schedule.slowmo_schedule`.
    method : str, optional
        An interpolation method (default
        :data:`~varflow.retime.methods.DEFAULT_INTERPOLATOR`).
    params : dataclass, optional
        Its parameters.
    scene_cuts : bool
        Repeat the nearer source frame across a scene cut (:func:`is_scene_cut`)
        instead of interpolating.
    stats : dict, optional
        Filled with counters: ``read`` (source frames), ``passthrough``,
        ``held_last`` (the pass-through frames that repeat the frame before them: the
        last source frame held to the end of the output), ``interpolated``,
        ``cut_frames`` (outputs repeated at a cut), ``cuts``
        (pairs with output frames found to be cuts), ``pairs`` (pairs
        interpolated), ``flows`` (estimated), ``cached_flows`` (flows of a
        neighbouring pair reused: a four-frame method estimates two flows per pair
        once the stream is under way), ``max_held`` (source frames held at once, at most
        :data:`MAX_HELD`).
    callback : callable, optional
        ``callback(done, total)`` after every output frame.
    **overrides
        Parameter fields of the method (as :func:`varflow.interpolate`).

    Yields
    ------
    ndarray
        Shape and dtype of the source frames.  A pass-through frame is the source
        array itself (bit-exact).  The frames of one pair are computed together
        (one motion estimate), so a pair with ``m`` output frames holds ``m``
        frames besides the source frames.

    Raises
    ------
    ValueError
        Bad method or parameters (before anything is read), a source that ends
        before ``schedule.n_source`` frames or whose frames differ in shape or
        dtype.
    """
    interp = get_interpolator(DEFAULT_INTERPOLATOR if method is None else method)
    p = make_interp_params(interp, params, **overrides)
    counters = stats if stats is not None else {}
    for key in ("read", "passthrough", "held_last", "interpolated", "cut_frames", "cuts",
                "pairs", "max_held"):
        counters.setdefault(key, 0)
    return _retime(iter(frames), schedule, interp, p, scene_cuts, counters, callback)


def _retime(it: Iterator[np.ndarray], schedule: Schedule, interp: Any, p: Any,
            scene_cuts: bool, stats: dict[str, Any],
            callback: ProgressCallback | None) -> Iterator[np.ndarray]:
    n = schedule.n_source
    held: dict[int, np.ndarray] = {}
    thumbs: dict[int, np.ndarray] = {}
    scores: dict[int, float] = {}
    first: list[tuple[tuple[int, ...], np.dtype]] = []  # shape and dtype of frame 0

    def read_to(j: int) -> None:
        j = min(j, n - 1)
        while stats["read"] <= j:
            k = stats["read"]
            try:
                frame = np.asarray(next(it))
            except StopIteration:
                raise ValueError(
                    f"the source ended after {k} frames; {n} were expected (truncated?)"
                ) from None
            if not first:
                first.append((frame.shape, frame.dtype))
            elif (frame.shape, frame.dtype) != first[0]:
                raise ValueError(
                    f"source frame {k} has shape {frame.shape} and dtype {frame.dtype}, but "
                    f"frame 0 has shape {first[0][0]} and dtype {first[0][1]}"
                )
            held[k] = frame
            if scene_cuts:
                thumbs[k] = _thumb(frame)
            stats["read"] = k + 1
            for old in [i for i in held if i <= k - MAX_HELD]:  # a sliding window
                del held[old]
                thumbs.pop(old, None)
            for old in [i for i in scores if i < k - MAX_HELD]:
                del scores[old]
            stats["max_held"] = max(stats["max_held"], len(held))

    def score(i: int) -> float | None:
        if i < 0 or i + 1 >= n or i not in thumbs or i + 1 not in thumbs:
            return None
        if i not in scores:
            scores[i] = _score(thumbs[i], thumbs[i + 1])
        return scores[i]

    def is_cut(i: int) -> bool:
        si = score(i) if scene_cuts else None
        return si is not None and _decide(si, score(i - 1), score(i + 1), CUT_THRESHOLD,
                                          CUT_RATIO)

    cache = FlowCache()  # neighbouring pairs share flows: each is estimated once
    done = 0
    total = schedule.n_output
    for step in schedule.steps():
        if step.pair is None:
            read_to(step.source)
            outs: Iterable[np.ndarray] = (held[step.source] for _ in step.frames)
            stats["passthrough"] += len(step.frames)
            stats["held_last"] += len(step.frames) - 1  # only the last frame repeats
        else:
            i = step.pair
            read_to(i + 2)  # holds i - 1 .. i + 2
            if is_cut(i):
                log.info("scene cut between source frames %d and %d (score %.2f)", i, i + 1,
                         score(i))
                stats["cuts"] += 1
                stats["cut_frames"] += len(step.frames)
                outs = [held[f.source] for f in step.frames]
            else:
                previous = following = None
                if interp.context:  # no context frames from across a cut
                    if i - 1 in held and not is_cut(i - 1):
                        previous = held[i - 1]
                    if i + 2 in held and not is_cut(i + 1):
                        following = held[i + 2]
                outs = interpolate(held[i], held[i + 1], step.times, interp.name, params=p,
                                   previous=previous, following=following, stats=stats,
                                   flow_cache=cache)
                stats["pairs"] += 1
                stats["interpolated"] += len(step.frames)
        for out in outs:
            yield out
            done += 1
            if callback is not None:
                callback(done, total)


# --------------------------------------------------------------------------- files


@dataclass
class RetimeSummary:
    """What :func:`retime_video` did.

    Attributes
    ----------
    source, output : Path
    method : str
    n_source, n_output : int
        Source and output frames.
    rate_in, rate_out : Fraction
        Source and output frame rates.
    passthrough, interpolated, cut_frames : int
        Output frames that are source frames by the schedule, interpolated, and
        repeated source frames at scene cuts (they add up to ``n_output``).
    held_last : int
        Of the ``passthrough`` frames, those that repeat the frame before them: the
        last source frame held for extra frames to reach the output's duration
        (``passthrough - held_last`` distinct source frames are passed through).
    cuts : int
        The scene cuts (pairs) found.
    flows : int
        Flow fields estimated.
    audio : str or None
        ``"copied (codec)"``, ``"re-encoded (codec)"``, or why there is none.
    seconds : float
        Wall time.
    stats : dict
        The counters of :func:`retime_frames`.
    """

    source: Path
    output: Path
    method: str
    n_source: int
    n_output: int
    rate_in: Fraction
    rate_out: Fraction
    passthrough: int = 0
    held_last: int = 0
    interpolated: int = 0
    cut_frames: int = 0
    cuts: int = 0
    flows: int = 0
    audio: str | None = None
    seconds: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)


def _video_write_extensions() -> frozenset[str]:
    from ..io.video import VIDEO_WRITE_EXTENSIONS

    return VIDEO_WRITE_EXTENSIONS


def _output_kind(output: Path) -> str:
    """``"video"`` or ``"folder"``; a bad target raises before any work."""
    suffix = output.suffix.lower()
    parent = output.parent if str(output.parent) else Path(".")
    if suffix in _video_write_extensions():
        if output.is_dir():
            raise IsADirectoryError(21, "output: is a directory", str(output))
        kind = "video"
    elif output.is_dir() or not suffix:
        if output.exists() and not output.is_dir():
            raise NotADirectoryError(20, "output: exists and is not a folder", str(output))
        if output.is_dir():
            others = [e.name for e in output.iterdir() if not _FRAME_FILE.match(e.name)]
            if others:
                raise ValueError(
                    f"output: the folder {output} holds other files than retimed frames "
                    f"({others[0]}, ...); remove them or choose another folder"
                )
        kind = "folder"
    else:
        raise ValueError(
            f"output: {output} must be a video ({', '.join(sorted(_video_write_extensions()))}) "
            "or a folder (a path without extension)"
        )
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


def _write_folder(output: Path, frames: Iterable[np.ndarray]) -> int:
    """Write frames as ``000000.png ...`` into a temporary folder, then rename it."""
    from ..io.images import write_image

    parent = output.parent if str(output.parent) else Path(".")
    tmp = Path(tempfile.mkdtemp(prefix=f".{output.name}.", suffix=".tmp", dir=parent))
    count = 0
    try:
        for frame in frames:
            write_image(tmp / FRAME_NAME.format(count), frame)
            count += 1
        os.chmod(tmp, _NEW_DIR_MODE)
        if output.is_dir() and any(output.iterdir()):  # an earlier retime's frames
            trash = Path(tempfile.mkdtemp(prefix=f".{output.name}.", suffix=".old",
                                          dir=parent))
            os.replace(output, trash)
            try:
                os.replace(tmp, output)
            except BaseException:
                os.replace(trash, output)
                raise
            shutil.rmtree(trash, ignore_errors=True)
        else:
            os.replace(tmp, output)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _fsync_dir(parent)
    return count


def retime_video(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    fps: Any = None,
    slowmo: int | None = None,
    method: str | None = None,
    params: Any = None,
    input_fps: Any = None,
    codec: str | None = None,
    quality: int | None = None,
    audio: bool | None = None,
    scene_cuts: bool = True,
    callback: ProgressCallback | None = None,
    **overrides: Any,
) -> RetimeSummary:
    """Retime a video or a frame folder to a new frame rate or to slow motion.

    Parameters
    ----------
    source : str or path-like
        A video file (anything FFmpeg reads) or a folder of frames (natural order,
        :func:`varflow.io.video.list_frame_files`).
    output : str or path-like
        A video file (an extension of
        :data:`varflow.io.video.VIDEO_WRITE_EXTENSIONS`; ``.mkv`` is lossless FFV1,
        which keeps pass-through frames bit-exact) or a folder (a path without
        extension, or an existing folder), which receives ``000000.png``,
        ``000001.png``, ...  An existing folder is replaced only when it holds
        nothing but such frames.
    fps : str, float or Fraction
        The output rate (``"24000/1001"``, ``60``); the duration is kept
        (:func:`~varflow.retime.schedule.fps_schedule`).
    slowmo : int
        ``K >= 2``: ``K - 1`` new frames between every two, at the source rate
        (:func:`~varflow.retime.schedule.slowmo_schedule`).  Exactly one of ``fps``
        and ``slowmo``.
    method, params, **overrides
        The interpolation method and its parameters (as :func:`varflow.interpolate`).
    input_fps : str, float or Fraction, optional
        The source rate: required meaning for a frame folder (default 25); for a
        video it replaces the stream's own rate (exact, from the container).
    codec, quality : optional
        Encoder and quality of a video output (:class:`varflow.io.video.VideoWriter`).
    audio : bool, optional
        Copy the first audio stream of a video source into a video output: None
        (default) copies it when the duration is kept (``fps``), not for slow
        motion (the video is ``K`` times longer than the sound); True copies it in
        both cases, False never.  The packets are remuxed, or re-encoded when the
        output container cannot hold the codec (the summary says which).
    scene_cuts : bool
        Repeat the nearer frame across scene cuts instead of interpolating.
    callback : callable, optional
        ``callback(done, total)`` after every output frame.

    Returns
    -------
    RetimeSummary

    Raises
    ------
    FileNotFoundError
        A missing source or output directory.
    ValueError
        Not exactly one of ``fps`` / ``slowmo``, bad rates, method or parameters, an
        unreadable, corrupt or truncated source (checked against its header before
        the work, and while decoding), fewer than 2 source frames, frames of
        different sizes, a bad output.  Nothing is left at ``output`` (an existing
        output stays as it was).
    """
    t0 = time.perf_counter()
    if (fps is None) == (slowmo is None):
        raise ValueError("give exactly one of fps (a new frame rate) and slowmo (a factor)")
    if slowmo is not None and (isinstance(slowmo, bool) or not isinstance(slowmo, int)
                               or slowmo < 2):
        raise ValueError(f"slowmo: expected an integer >= 2, got {slowmo!r}")
    rate_out = parse_rate(fps, "fps") if fps is not None else None
    interp = get_interpolator(DEFAULT_INTERPOLATOR if method is None else method)
    p = make_interp_params(interp, params, **overrides)
    src_path, out_path = Path(os.fspath(source)), Path(os.fspath(output))
    kind = _output_kind(out_path)
    if src_path.exists() and out_path.exists() and src_path.resolve() == out_path.resolve():
        raise ValueError(f"output: {out_path} is the source")
    from ..io.sequences import FrameSource

    src = FrameSource(src_path, None if input_fps is None
                      else parse_rate(input_fps, "input fps"))
    try:
        if src.n < 2:
            from ..io.sequences import too_few_frames_message

            raise ValueError(too_few_frames_message(src_path, src.n))
        schedule = (fps_schedule(src.n, src.rate, rate_out) if rate_out is not None
                    else slowmo_schedule(src.n, int(slowmo or 0), src.rate))
        log.info("%s: %d frames at %s fps -> %d frames at %s fps (%s)", src_path, src.n,
                 src.rate, schedule.n_output, schedule.rate_out, interp.name)
        stats: dict[str, Any] = {}
        frames = retime_frames(src.frames(), schedule, interp.name, params=p,
                               scene_cuts=scene_cuts, stats=stats, callback=callback)
        audio_note: str | None = None
        if kind == "video":
            from ..io.video import VideoWriter

            copy_audio = src.kind == "video" and (audio if audio is not None
                                                   else slowmo is None)
            if src.kind == "video" and audio is None and slowmo is not None:
                audio_note = "left out (slow motion changes the duration)"
            with VideoWriter(out_path, schedule.rate_out, codec=codec, quality=quality,
                             audio=src_path if copy_audio else None) as writer:
                for frame in frames:
                    writer.write(frame)
            if writer.audio_mode == "copy":
                audio_note = f"copied ({writer.audio_codec})"
            elif writer.audio_mode == "encode":
                audio_note = f"re-encoded ({writer.audio_codec})"
            elif copy_audio:
                audio_note = "none in the source"
            written = writer.frames_written
        else:
            if codec is not None or quality is not None:
                raise ValueError("codec/quality: the output is a folder of PNG frames")
            if src.kind == "video":
                audio_note = "left out (the output is a folder of frames)"
            written = _write_folder(out_path, frames)
    finally:
        src.close()
    assert written == schedule.n_output, (written, schedule.n_output)
    return RetimeSummary(
        source=src_path, output=out_path, method=interp.name, n_source=src.n,
        n_output=written, rate_in=schedule.rate_in, rate_out=schedule.rate_out,
        passthrough=stats["passthrough"], held_last=stats["held_last"],
        interpolated=stats["interpolated"], cut_frames=stats["cut_frames"],
        cuts=stats["cuts"], flows=int(stats.get("flows", 0)), audio=audio_note,
        seconds=time.perf_counter() - t0, stats=stats,
    )
