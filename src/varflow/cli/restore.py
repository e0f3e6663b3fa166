"""``varflow restore``: repair archival footage (weave, flicker, dirt, noise).

Synopsis::

    varflow restore IN -o OUT [--stabilise] [--deflicker] [--dirt] [--denoise]
                    [--sigma S] [--denoise-method NAME] [--set STAGE.FIELD=VALUE ...]
                    [--mask-video MASK] [--start N] [--stop N] [--input-fps R]
                    [--codec C] [--quality Q] [--no-audio] [--no-scene-cuts]
                    [--chunk K] [-q]

The stages named (all four when none is) run in the order restoration practice
uses, whatever the order of the flags: ``stabilise`` (gate weave), ``deflicker``,
``dirt`` (dust and blotches), ``denoise``
(:func:`varflow.restore.video.restore_video`, streamed with bounded memory, scene cuts
respected).  IN and OUT are as for ``varflow denoise`` (a video or a folder of
frames; a lossless video where the container allows it; the audio copied; written
atomically).  ``--mask-video MASK`` writes a second output, white where the dirt
stage replaced the picture.

A stage's parameters (the fields of its dataclass, ``varflow methods NAME``) are
set with ``--set STAGE.FIELD=VALUE``, repeatable: ``--set dirt.sensitivity=1.5
--set denoise.grain=0.2``.  The summary on stdout gives the frames written and the
seconds per frame of each stage.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..evaluation.bench.common import parse_value
from ..registry import REPAIR, RESTORE
from ._common import (
    _claim,
    _claim_inputs,
    _compile_notice,
    _Progress,
    int_at_least,
)
from .denoise import SIGMA_HELP, add_stream_flags, sigma_arg

__all__ = ["add_chain_flags", "add_parser", "parse_settings", "resolve_chain", "summary_line"]

log = logging.getLogger("varflow.cli")

#: The stage flags, in the order of the chain.
_STAGE_FLAGS = (("stabilise", "remove gate weave and camera shake (keeps pans)"),
                ("deflicker", "remove brightness flicker (keeps fades)"),
                ("dirt", "remove dust, dirt and blotches on one frame"),
                ("denoise", "remove noise (motion-compensated NL-Bayes)"))


def _epilog() -> str:
    lines = ["stages (run in this order; 'varflow methods NAME' lists a stage's parameters):"]
    for name, entry in REPAIR.items():
        lines.append(f"  {name:<10} {entry.use}")
    lines.append(f"  {'denoise':<10} --denoise-method: {', '.join(RESTORE.names())}")
    lines.append("example: varflow restore reel.mkv -o clean.mkv --deflicker --dirt "
                 "--mask-video dirt.mkv --set dirt.sensitivity=1.5")
    return "\n".join(lines)


def add_parser(sub: Any, common: argparse.ArgumentParser, argv: Sequence[str] | None) -> None:
    """Register ``restore``.

    The ``add_parser`` protocol of :mod:`varflow.cli` (its notes say what ``sub``,
    ``common`` and ``argv`` are).
    """
    p = sub.add_parser(
        "restore", parents=[common],
        help="repair archival footage: gate weave, flicker, dirt, noise",
        description="Restore a video or a folder of frames with its motion: the stages "
        "named (all when none is) run in the order of practice (stabilise, deflicker, "
        "dirt, denoise), streamed with bounded memory; scene cuts are respected, the "
        "audio is copied and a video output is lossless where its container allows it.",
        epilog=_epilog(),
    )
    p.add_argument("source", metavar="IN", help="video file or folder of frames")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="video (.mkv: lossless FFV1; .mp4: lossless H.264; ...) or folder of "
                   "PNG frames of the input's bit depth")
    add_chain_flags(p)
    p.add_argument("--mask-video", metavar="MASK",
                   help="also write the dirt stage's mask (white: replaced) as a video "
                   "or a folder of PNG frames")
    add_stream_flags(p)
    p.add_argument("--no-scene-cuts", dest="scene_cuts", action="store_false",
                   help="one scene: stages look across scene cuts too")
    p.add_argument("--chunk", type=int_at_least(1), default=None, metavar="K",
                   help="frames given out per window of a repair stage (default 24)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    p.set_defaults(func=_cmd_restore)


def add_chain_flags(p: argparse.ArgumentParser) -> None:
    """The stage flags, ``--sigma``, ``--denoise-method`` and ``--set`` (shared with
    ``varflow batch restore``)."""
    for name, text in _STAGE_FLAGS:
        p.add_argument(f"--{name}", action="store_true", help=text)
    p.add_argument("--sigma", type=sigma_arg, metavar="S", help=SIGMA_HELP)
    p.add_argument("--denoise-method", default=RESTORE.default, metavar="NAME",
                   help=f"the denoiser (default {RESTORE.default}; "
                   f"{', '.join(RESTORE.names())})")
    p.add_argument("--set", dest="settings", action="append", default=[],
                   metavar="STAGE.FIELD=VALUE",
                   help="a stage's parameter, e.g. dirt.sensitivity=1.5 (repeatable)")


def resolve_chain(args: argparse.Namespace) -> Any:
    """The :class:`~varflow.restore.chain.ChainParams` of the stage flags (all stages
    when none is given) and ``--set``; errors before any work."""
    from ..restore.chain import STAGES, ChainParams

    stages = [name for name in STAGES if getattr(args, name)] or list(STAGES)
    params = parse_settings(args.settings, stages, args.denoise_method)
    return ChainParams.resolve(stages, params, args.denoise_method)


def parse_settings(settings: Sequence[str], stages: Sequence[str],
                   denoise_method: str) -> dict[str, dict[str, Any]]:
    """``{stage: {field: value}}`` from ``--set STAGE.FIELD=VALUE`` strings.

    Raises
    ------
    ValueError
        A malformed setting, a stage not run, a field the stage does not have, a
        value of the wrong type (each naming the setting).
    """
    out: dict[str, dict[str, Any]] = {}
    for text in settings:
        key, eq, value = text.partition("=")
        stage, dot, name = key.strip().partition(".")
        if not eq or not dot or not stage or not name:
            raise ValueError(f"--set: expected STAGE.FIELD=VALUE, got {text!r}")
        if stage not in stages:
            raise ValueError(f"--set {key}: the stage {stage!r} is not run (stages: "
                             f"{', '.join(stages)})")
        registry, method = (RESTORE, denoise_method) if stage == "denoise" else (REPAIR, stage)
        fields = {f: d for f, d, _ in registry.fields(method)}
        name = name.replace("-", "_")
        if name not in fields:
            raise ValueError(f"--set {key}: not a parameter of {stage} (see 'varflow "
                             f"methods {method}')")
        out.setdefault(stage, {})[name] = parse_value(value, fields[name], f"--set {key}")
    return out


def _cmd_restore(args: argparse.Namespace) -> int:
    from ..restore.video import restore_video

    chain = resolve_chain(args)
    _claim_inputs((args.source, "IN"))
    _claim(Path(args.output), "-o/--output")
    if args.mask_video is not None:
        if "dirt" not in chain.stages:
            raise ValueError("--mask-video: the dirt stage is not run (add --dirt)")
        _claim(Path(args.mask_video), "--mask-video")
    for name, p in chain.params:
        flow_method = getattr(p, "flow_method", None)
        if flow_method is not None:
            entry = RESTORE[chain.denoise_method] if name == "denoise" else None
            _compile_notice(flow_method, args.quiet, entry)
            break
    with _Progress("restore", args.quiet, unit="frame") as progress:
        s = restore_video(
            args.source, args.output, **chain.as_kwargs(), sigma=args.sigma,
            mask=args.mask_video, start=args.start,
            stop=args.stop, input_fps=args.input_fps, codec=args.codec,
            quality=args.quality, audio=args.audio, scene_cuts=args.scene_cuts,
            chunk=args.chunk, callback=progress,
        )
    print(summary_line(s))
    return 0


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def summary_line(s: Any) -> str:
    """The lines ``varflow restore`` prints for a
    :class:`~varflow.restore.video.RestoreSummary`: what was written, then the seconds
    per frame of each stage."""
    colour = {1: "grey", 3: "RGB"}.get(s.channels, f"{s.channels}-channel")
    last = s.start + s.n_frames - 1
    section = "" if s.n_frames == s.n_input else f" (frames {s.start}..{last} of {s.n_input})"
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
    extra = []
    if "dirt" in s.stages:
        extra.append(f"dirt replaced {100 * s.masked:.3f} % of the pixels")
    if s.sigma is not None:
        how = "estimated" if s.sigma_estimated else "given"
        extra.append(f"σ {s.sigma:.3g} ({how}, 0-255 scale)")
    if s.mask is not None:
        extra.append(f"mask -> {s.mask}")
    if s.audio:
        extra.append(f"audio {s.audio}")
    rate = s.rate.numerator if s.rate.denominator == 1 else f"{float(s.rate):.6g}"
    n = max(s.n_frames, 1)
    per_stage = ", ".join(
        f"{name}{' ' + s.denoise_method if name == 'denoise' else ''} "
        f"{s.stage_seconds.get(name, 0.0) / n:.2f}" for name in s.stages)
    head = (f"restore {' + '.join(s.stages)}: {_plural(s.n_frames, 'frame')}{section} of "
            f"{s.width}x{s.height} {colour} {s.bits}-bit at {rate} fps, {cuts}, "
            f"{s.seconds_per_frame:.2f} s/frame ({s.seconds:.2f} s) -> {where}")
    tail = "; ".join(extra)
    return head + (f"; {tail}" if tail else "") + f"\nseconds per frame: {per_stage}"
