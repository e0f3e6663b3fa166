"""``varflow interpolate`` and ``varflow retime``: in-between frames, new frame rates.

Synopsis::

    varflow interpolate A B -o OUT [--t T | -n K] [--method NAME] [-q]
                        [--<parameter> VALUE ...]
    varflow retime IN -o OUT (--fps F | --slowmo K) [--method NAME] [--input-fps R]
                   [--codec C] [--quality Q] [--audio auto|copy|none] [--no-scene-cuts]
                   [-q] [--<parameter> VALUE ...]

``interpolate`` writes the frame at time ``T`` (default 0.5) between the images A
(t = 0) and B (t = 1) to OUT, with the dtype and channels of A.  With ``-n K`` it
writes the ``K`` evenly spaced in-between frames ``t = k / (K + 1)``, ``k = 1..K``
(the motion is estimated once), named after OUT:

* OUT with a printf field (``mid_%02d.png``): ``OUT % k``;
* OUT an existing folder or ending in ``/``: ``OUT/01.png .. OUT/K.png`` (at least
  two digits; the folder is created when its parent exists);
* any other OUT (``mid.png``): ``mid_01.png .. mid_K.png``.

``retime`` retimes a video or a folder of frames (:func:`varflow.retime.stream.retime_video`):
``--fps F`` to a new rate with the same duration (``F`` may be a ratio such as
``24000/1001``; the source's rate is the stream's exact rational rate, or
``--input-fps``, default 25 for a frame folder), ``--slowmo K`` with ``K - 1`` new
frames between every two at the source rate.  OUT is a video (``.mkv`` is lossless
FFV1: the source frames the schedule passes through stay bit-exact) or a folder
(``000000.png ...``).  The audio of a video is copied into a video output when
the duration is kept (``--audio copy`` also for slow motion, ``none`` never).
Scene cuts repeat the nearer source frame instead of interpolating
(``--no-scene-cuts`` interpolates across them).

The parameter flags are the fields of the interpolation methods' parameter
dataclasses (:data:`varflow.retime.methods.INTERPOLATORS`), e.g. ``--flow-method``
and the fields of the two-frame method they compose (``--data-weight``).
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..retime.methods import (
    DEFAULT_INTERPOLATOR,
    INTERPOLATORS,
    get_interpolator,
    interpolate,
    make_interp_params,
)
from ._common import (
    _add_param_flags,
    _check_output,
    _claim,
    _claim_inputs,
    _collect_params,
    _compile_notice,
    _own_params,
    _Progress,
    chosen_methods,
    int_at_least,
    methods_epilog,
    rate_arg,
)

__all__ = ["add_parser"]

log = logging.getLogger("varflow.cli")


def _time(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and 0.0 <= value <= 1.0):
        raise argparse.ArgumentTypeError(f"must be a number in [0, 1], got {text!r}")
    return value


def add_parser(sub: Any, common: argparse.ArgumentParser, argv: Sequence[str] | None) -> None:
    """Register ``interpolate`` and ``retime``.

    The ``add_parser`` protocol of :mod:`varflow.cli` (its notes say what ``sub``,
    ``common`` and ``argv`` are).
    """
    params = _collect_params(INTERPOLATORS)
    chosen = chosen_methods(argv, INTERPOLATORS)

    p = sub.add_parser(
        "interpolate", parents=[common], help="in-between frames of two images",
        description="Synthesise the frame at time T between image A (t = 0) and image B "
        "(t = 1), or K evenly spaced in-between frames, from the motion between them.",
        epilog="With -n K the frames are named after OUT: 'mid_%02d.png' -> mid_01.png...; "
        "a folder (existing or ending in /) -> DIR/01.png...; 'mid.png' -> mid_01.png...\n\n"
        + methods_epilog(INTERPOLATORS),
    )
    p.add_argument("frame0", metavar="A", help="first image (t = 0)")
    p.add_argument("frame1", metavar="B", help="second image (t = 1)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output image (with -n: a pattern, a folder or a base name)")
    x = p.add_mutually_exclusive_group()
    x.add_argument("--t", type=_time, default=None, metavar="T",
                   help="time of the frame, in [0, 1] (default 0.5)")
    x.add_argument("-n", type=int_at_least(1), default=None, metavar="K",
                   help="write K frames at t = k / (K + 1), k = 1..K")
    p.add_argument("--method", default=DEFAULT_INTERPOLATOR, metavar="NAME",
                   help=f"the method (default {DEFAULT_INTERPOLATOR}; list below)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    _add_param_flags(p, params, INTERPOLATORS, chosen)
    p.set_defaults(func=_cmd_interpolate)

    r = sub.add_parser(
        "retime", parents=[common], help="new frame rate or slow motion of a video",
        description="Retime a video or a folder of frames by frame interpolation: --fps F "
        "for a new rate with the same duration, --slowmo K for K-1 new frames between every "
        "two at the source rate.  Source frames that fall on output times are passed "
        "through unchanged; scene cuts repeat the nearer frame.",
        epilog=methods_epilog(INTERPOLATORS),
    )
    r.add_argument("source", metavar="IN", help="video file or folder of frames")
    r.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="video (.mkv: lossless FFV1; .mp4: H.264; ...) or folder of PNG frames")
    x = r.add_mutually_exclusive_group(required=True)
    x.add_argument("--fps", type=rate_arg, metavar="F",
                   help="output frame rate, e.g. 60, 50 or 24000/1001")
    x.add_argument("--slowmo", type=int_at_least(2), metavar="K",
                   help="slow motion: K-1 new frames between every two (K >= 2)")
    r.add_argument("--method", default=DEFAULT_INTERPOLATOR, metavar="NAME",
                   help=f"the method (default {DEFAULT_INTERPOLATOR}; list below)")
    r.add_argument("--input-fps", type=rate_arg, metavar="R",
                   help="source frame rate (default: the video's own; 25 for a folder)")
    r.add_argument("--codec", metavar="C",
                   help="FFmpeg encoder of a video output (default after the extension)")
    r.add_argument("--quality", type=int, metavar="Q",
                   help="encoder quality (CRF for libx264; lower is better)")
    r.add_argument("--audio", choices=("auto", "copy", "none"), default="auto",
                   help="audio of a video source: copied when the duration is kept (auto, "
                   "default), also for slow motion (copy), or left out (none)")
    r.add_argument("--no-scene-cuts", dest="scene_cuts", action="store_false",
                   help="interpolate across scene cuts too")
    r.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    _add_param_flags(r, params, INTERPOLATORS, chosen)
    r.set_defaults(func=_cmd_retime)


def _resolve(args: argparse.Namespace) -> tuple[Any, Any]:
    interp = get_interpolator(args.method)
    params = make_interp_params(interp, **_own_params(args, interp, "interpolation method"))
    return interp, params


def _notice(params: Any, quiet: bool) -> None:
    flow_method = getattr(params, "flow_method", None)
    if isinstance(flow_method, str):
        _compile_notice(flow_method, quiet)


def _output_names(output: str, k: int) -> list[Path]:
    """The file names of ``-n K`` (see the module notes)."""
    if "%" in output:
        try:
            names = [output % i for i in range(1, k + 1)]
        except (TypeError, ValueError):
            raise ValueError(f"-o/--output: {output!r} is not a pattern with one integer "
                             "field such as mid_%02d.png") from None
        if len(set(names)) != k:
            raise ValueError(f"-o/--output: the pattern {output!r} gives the same name twice")
        return [Path(n) for n in names]
    digits = max(2, len(str(k)))
    out = Path(output)
    if output.endswith(("/", "\\")) or out.is_dir():
        return [out / f"{i:0{digits}d}.png" for i in range(1, k + 1)]
    return [out.with_name(f"{out.stem}_{i:0{digits}d}{out.suffix}") for i in range(1, k + 1)]


def _cmd_interpolate(args: argparse.Namespace) -> int:
    from ..io.images import read_image, write_image

    interp, params = _resolve(args)
    _claim_inputs((args.frame0, "A"), (args.frame1, "B"))
    folder: Path | None = None  # an output folder -n creates
    if args.n is not None:
        times = [i / (args.n + 1) for i in range(1, args.n + 1)]
        outputs = _output_names(args.output, args.n)
        if args.output.endswith(("/", "\\")) and not Path(args.output).is_dir():
            folder = Path(args.output)
            parent = folder.parent if str(folder.parent) else Path(".")
            if not parent.is_dir():
                raise FileNotFoundError(2, "-o/--output: directory does not exist", str(parent))
            if folder.exists():
                raise NotADirectoryError(20, "-o/--output: not a directory", str(folder))
        else:
            outputs = [_check_output(str(o), None, "-o/--output") for o in outputs]
    else:
        times = [0.5 if args.t is None else args.t]
        outputs = [_check_output(args.output, None, "-o/--output")]
    a, b = read_image(args.frame0), read_image(args.frame1)
    if a.shape[:2] != b.shape[:2]:
        raise ValueError(f"{args.frame1}: size {b.shape[1]}x{b.shape[0]} differs from "
                         f"{args.frame0}'s {a.shape[1]}x{a.shape[0]}")
    if a.shape != b.shape or a.dtype != b.dtype:
        raise ValueError(f"{args.frame1}: {b.dtype} with shape {b.shape}, but {args.frame0} "
                         f"is {a.dtype} with shape {a.shape}; convert one of them")
    _notice(params, args.quiet)
    t0 = time.perf_counter()
    with _Progress(interp.name, args.quiet) as progress:
        frames = interpolate(a, b, times, interp.name, params=params, callback=progress)
    seconds = time.perf_counter() - t0
    if folder is not None:
        folder.mkdir(exist_ok=True)
    for path, frame in zip(outputs, frames, strict=True):
        write_image(path, frame)
    where = str(outputs[0]) if len(outputs) == 1 else f"{outputs[0]} .. {outputs[-1]}"
    ts = ", ".join(f"{t:.4g}" for t in times)
    print(f"{interp.name}: {len(times)} frame(s) at t = {ts} of {a.shape[1]}x{a.shape[0]} in "
          f"{seconds:.2f} s -> {where}")
    return 0


def _cmd_retime(args: argparse.Namespace) -> int:
    from ..retime.stream import retime_video

    interp, params = _resolve(args)
    _claim_inputs((args.source, "IN"))
    _claim(Path(args.output), "-o/--output")
    if args.quality is not None and args.quality < 0:
        raise ValueError(f"--quality: must be >= 0, got {args.quality}")
    audio = {"auto": None, "copy": True, "none": False}[args.audio]
    _notice(params, args.quiet)
    with _Progress(f"retime {interp.name}", args.quiet, unit="frame") as progress:
        summary = retime_video(
            args.source, args.output, fps=args.fps, slowmo=args.slowmo, method=interp.name,
            params=params, input_fps=args.input_fps, codec=args.codec, quality=args.quality,
            audio=audio, scene_cuts=args.scene_cuts, callback=progress,
        )
    s = summary
    audio_text = f"; audio {s.audio}" if s.audio else ""
    print(f"retime {s.method}: {s.n_source} frames at {_rate_text(s.rate_in)} fps -> "
          f"{s.n_output} frames at {_rate_text(s.rate_out)} fps ({_made_of(s)}) in "
          f"{s.seconds:.2f} s -> {s.output}{audio_text}")
    return 0


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _made_of(s: Any) -> str:
    """What the output frames of a :class:`RetimeSummary` are; the counts add up to
    ``n_output``, each source frame passed through counted once."""
    parts = [f"{_plural(s.passthrough - s.held_last, 'source frame')} passed through",
             f"{s.interpolated} interpolated"]
    if s.cuts:
        parts.append(f"{s.cut_frames} repeated at {_plural(s.cuts, 'scene cut')}")
    if s.held_last:
        parts.append(f"last frame held for {_plural(s.held_last, 'extra frame')}")
    return ", ".join(parts)


def _rate_text(rate: Any) -> str:
    if rate.denominator == 1:
        return str(rate.numerator)
    return f"{rate.numerator}/{rate.denominator} ({float(rate):.6g})"

