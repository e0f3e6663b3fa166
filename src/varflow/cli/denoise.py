"""``varflow denoise``: remove the noise of a video or a folder of frames.

Synopsis::

    varflow denoise IN -o OUT [--sigma S] [--method NAME] [--start N] [--stop N]
                    [--input-fps R] [--codec C] [--quality Q] [--no-audio]
                    [--no-scene-cuts] [--chunk K] [-q] [--<parameter> VALUE ...]

IN is a video file or a folder of frames (its image files in natural order, as
``varflow retime`` and ``varflow video`` read it); the frames ``start <= k < stop``
are streamed through the motion-compensated denoiser
(:func:`varflow.restore.denoise.iter_denoise`: a frame is written once the frames
after it that it needs are read, memory holds about ``chunk + 4 · radius`` frames)
by :func:`varflow.restore.video.denoise_video`.

OUT is a video or a folder (a path without extension) of ``000000.png ...`` of the
input's bit depth (8 or 16 bits).  A video keeps the input's frame rate (a folder's:
``--input-fps``, default 25) and is lossless where the container allows it: FFV1 in
``.mkv`` and ``.avi``, lossless RGB H.264 in ``.mp4``/``.mov``/``.m4v``, lossless VP9
in ``.webm`` (16-bit frames are kept exactly only in ``.mkv`` and ``.avi``; the summary
says when a video is not lossless).  ``--codec``/``--quality`` choose the encoder
instead.  The audio of a video input is copied when every frame is denoised
(``--no-audio``: never).  Written atomically: a failure leaves no output.

``--sigma S`` is the noise's standard deviation on the 0-255 scale whatever the bit
depth (16-bit values are ``S * 257``); without it σ is estimated on the first frames
(:func:`varflow.estimate_noise`).  Scene cuts (:func:`varflow.retime.stream.is_scene_cut`,
the detector of ``varflow retime``) are not crossed by the patch search
(``--no-scene-cuts``: one scene).

The parameter flags are the fields of the restoration methods' parameter dataclasses
(:data:`varflow.registry.RESTORE`), e.g. ``--radius``, ``--grain`` and
``--flow-method`` with the fields of the two-frame method it names.  The summary line
on stdout gives the frames written, σ and whether it was estimated or given, the
scene cuts and the seconds per frame.
"""

from __future__ import annotations

import argparse
import logging
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..registry import RESTORE
from ._common import (
    _add_param_flags,
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

__all__ = ["add_parser", "add_stream_flags", "sigma_arg"]

log = logging.getLogger("varflow.cli")


def sigma_arg(text: str) -> float:
    """argparse ``type`` of ``--sigma``: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0 (the noise's "
                                         f"standard deviation, 0-255 scale), got {text!r}")
    return value


#: The help of ``--sigma``, shared with ``varflow batch denoise``.
SIGMA_HELP = ("standard deviation of the noise on the 0-255 scale, whatever the bit depth "
              "(default: estimated from the first frames)")


def add_parser(sub: Any, common: argparse.ArgumentParser, argv: Sequence[str] | None) -> None:
    """Register ``denoise``.

    The ``add_parser`` protocol of :mod:`varflow.cli` (its notes say what ``sub``,
    ``common`` and ``argv`` are).
    """
    p = sub.add_parser(
        "denoise", parents=[common], help="remove the noise of a video or a folder of frames",
        description="Denoise a video or a folder of frames with its motion (patches "
        "matched along the optical flow over neighbouring frames), streamed with bounded "
        "memory.  Scene cuts are not crossed; the audio of a video is copied; a video "
        "output is lossless where its container allows it.",
        epilog=methods_epilog(RESTORE),
    )
    p.add_argument("source", metavar="IN", help="video file or folder of frames")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="video (.mkv: lossless FFV1; .mp4: lossless H.264; ...) or folder of "
                   "PNG frames of the input's bit depth")
    p.add_argument("--sigma", type=sigma_arg, metavar="S", help=SIGMA_HELP)
    p.add_argument("--method", default=RESTORE.default, metavar="NAME",
                   help=f"the method (default {RESTORE.default}; list below)")
    add_stream_flags(p)
    p.add_argument("--no-scene-cuts", dest="scene_cuts", action="store_false",
                   help="search patches across scene cuts too (one scene)")
    p.add_argument("--chunk", type=int_at_least(1), default=None, metavar="K",
                   help="frames denoised together: more uses the cores better and holds "
                   "more frames (default: the denoiser's)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    _add_param_flags(p, _collect_params(RESTORE), RESTORE, chosen_methods(argv, RESTORE))
    p.set_defaults(func=_cmd_denoise)


def add_stream_flags(p: argparse.ArgumentParser) -> None:
    """``--start``, ``--stop``, ``--input-fps``, ``--codec``, ``--quality`` and
    ``--no-audio``: the section, rate and encoding of a streamed video job (shared with
    ``varflow restore``)."""
    p.add_argument("--start", type=int_at_least(0), default=0, metavar="N",
                   help="first frame (default 0)")
    p.add_argument("--stop", type=int_at_least(0), default=None, metavar="N",
                   help="end frame, exclusive (default: the end of the input)")
    p.add_argument("--input-fps", type=rate_arg, metavar="R",
                   help="input frame rate, also the output's (default: the video's own; 25 "
                   "for a folder)")
    p.add_argument("--codec", metavar="C",
                   help="FFmpeg encoder of a video output (default: lossless, after the "
                   "extension)")
    p.add_argument("--quality", type=int_at_least(0), metavar="Q",
                   help="encoder quality (CRF for libx264; lower is better); not lossless")
    p.add_argument("--no-audio", dest="audio", action="store_false",
                   help="leave the audio of a video input out")


def resolve(args: argparse.Namespace) -> tuple[Any, Any]:
    """The restoration method of ``--method`` and its parameters from the flags given.

    Shared with ``varflow batch denoise``.

    Raises
    ------
    ValueError
        An unknown method, a flag that is not one of its parameters, a bad value.
    """
    entry = RESTORE.entry(args.method)
    params = RESTORE.make_params(entry, **_own_params(args, entry, "restoration method"))
    return entry, params


def _cmd_denoise(args: argparse.Namespace) -> int:
    from ..restore.video import denoise_video

    entry, params = resolve(args)
    _claim_inputs((args.source, "IN"))
    _claim(Path(args.output), "-o/--output")
    _compile_notice(params.flow_method, args.quiet, entry)  # the flows' kernels and its own
    with _Progress(f"denoise {entry.name}", args.quiet, unit="frame") as progress:
        s = denoise_video(
            args.source, args.output, sigma=args.sigma, method=entry.name, params=params,
            start=args.start, stop=args.stop, input_fps=args.input_fps, codec=args.codec,
            quality=args.quality, audio=args.audio, scene_cuts=args.scene_cuts,
            chunk=args.chunk, callback=progress,
        )
    print(summary_line(s))
    return 0


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def summary_line(s: Any) -> str:
    """The line ``varflow denoise`` prints for a
    :class:`~varflow.restore.video.DenoiseSummary`."""
    colour = {1: "grey", 3: "RGB"}.get(s.channels, f"{s.channels}-channel")
    last = s.start + s.n_frames - 1
    section = "" if s.n_frames == s.n_input else f" (frames {s.start}..{last} of {s.n_input})"
    how = "estimated" if s.sigma_estimated else "given"
    scale = ", 0-255 scale" if s.bits != 8 else ""
    if s.cuts is None:
        cuts = "scene cuts not detected"
    else:
        cuts = "no scene cut" if s.cuts == 0 else _plural(s.cuts, "scene cut")
    if s.codec is None:
        where = f"{s.output} ({_plural(s.n_frames, 'PNG frame')})"
    elif s.lossless:
        where = f"{s.output} ({s.codec}, lossless)"
    elif s.lossless is None:
        where = f"{s.output} ({s.codec})"
    else:
        where = f"{s.output} ({s.codec}, not lossless: {s.video_note})"
    audio = f"; audio {s.audio}" if s.audio else ""
    rate = s.rate.numerator if s.rate.denominator == 1 else f"{float(s.rate):.6g}"
    return (f"denoise {s.method}: {_plural(s.n_frames, 'frame')}{section} of "
            f"{s.width}x{s.height} {colour} {s.bits}-bit at {rate} fps, σ {s.sigma:.3g} "
            f"({how}{scale}), {cuts}, {s.seconds_per_frame:.2f} s/frame "
            f"({s.seconds:.2f} s) -> {where}{audio}")
