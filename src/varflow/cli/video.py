"""``varflow video``: a colour-coded flow video of a video or a folder of frames.

Synopsis::

    varflow video IN -o OUT.(mp4|mkv|avi) [--method NAME] [--start N] [--stop N]
                  [--stride S] [--input-fps R] [--layout flow|side-by-side|warped]
                  [--max-radius R] [--no-scene-cuts] [--codec C] [--quality Q] [-q]

IN is a video file or a folder of frames (its image files in natural order, as
``varflow retime`` and ``varflow track`` read it).  The frames ``start, start + S,
start + 2S, ... < stop`` are read one at a time (a video with
:meth:`varflow.io.video.VideoReader.iter_frames`) and the flow of every consecutive
pair of them, ``(i, i + S)``, becomes one frame of the output, at the input frame
rate divided by ``S`` (so the output lasts as long as the input section).  The input
rate is the video's own, or ``--input-fps``; a folder has none and defaults to
:data:`varflow.io.sequences.DEFAULT_FOLDER_FPS` (25), as in ``varflow retime``.

Scene cuts: the flow between two shots is meaningless, so a pair across a cut
(:func:`varflow.retime.stream.is_scene_cut`, the detector of ``varflow retime``,
with the neighbouring pairs as context) is given no flow: its frame is rendered as
unknown flow, flat mid grey (:data:`varflow.viz.video.INVALID_GREY`, legend kept) in
the ``flow`` layout, grey flow and a greyed-out next frame in the others (the
side-by-side caption says "scene cut").  The output keeps one frame per pair, so its
timing is unchanged.  ``--no-scene-cuts`` computes every pair's flow.

One colour scale for the whole video: with ``--max-radius R`` every flow is
rendered and written as soon as it is computed.  Without it the scale is the
99th percentile of ``|w|`` over all known pixels of all pairs not across a cut
(:func:`varflow.viz.video.flow_percentile_radius`; a few wrong vectors do not wash
the video out, longer vectors are shown darkened), which is only known at the end:
the flows are then kept in a temporary ``np.memmap`` file (``P * H * W * 2`` float32
on disk, not in RAM; NaN for the pairs across a cut; deleted afterwards), and a
second pass renders them (re-reading the frames for the layouts that show them).
The summary line on stdout gives the maximum ``|w|``, the scale and where it comes
from, and the number of cuts.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..registry import METHODS, get_method
from ._common import (
    _check_output,
    _claim_inputs,
    _compile_notice,
    _max_radius,
    _Progress,
    rate_arg,
)

__all__ = ["add_parser"]

log = logging.getLogger(__name__)

_OUTPUT_SUFFIXES = (".mp4", ".mkv", ".avi")


def add_parser(sub: Any, common: argparse.ArgumentParser,
               argv: Sequence[str] | None = None) -> None:
    """Register the ``video`` sub-command.

    Parameters
    ----------
    sub : argparse sub-parsers action
        From ``parser.add_subparsers()``.
    common : argparse.ArgumentParser
        Parent parser with the options every command has (``-v``).
    argv : sequence of str, optional
        The command line (unused: ``video`` has no parameter flags).
    """
    p = sub.add_parser(
        "video",
        parents=[common],
        help="colour-coded flow video of a video or a folder of frames",
        description="Compute the flow between consecutive (sub-sampled) frames of a video "
        "or a folder of frames and write it as a colour-coded video on one colour scale (or "
        "side by side with the frames and the warped next frame).  Pairs across a scene cut "
        "get no flow: their frames are flat mid grey (unknown flow).",
    )
    p.add_argument("video", metavar="IN",
                   help="input video (any format FFmpeg reads) or folder of frames (its "
                   "image files in natural order)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output video: .mp4 (H.264), .mkv (lossless FFV1) or .avi (MPEG-4)")
    p.add_argument("--method", default="tvl1", metavar="NAME",
                   help=f"one of: {', '.join(METHODS)} (default tvl1)")
    p.add_argument("--start", type=int, default=0, metavar="N",
                   help="first frame (default 0)")
    p.add_argument("--stop", type=int, default=None, metavar="N",
                   help="end frame, exclusive (default: the end of the input)")
    p.add_argument("--stride", type=int, default=1, metavar="S",
                   help="use every S-th frame; flows of the pairs (i, i+S) (default 1)")
    p.add_argument("--input-fps", type=rate_arg, metavar="R",
                   help="input frame rate, e.g. 30 or 24000/1001 (default: the video's own; "
                   "25 for a folder); the output runs at R / S")
    p.add_argument("--layout", choices=("flow", "side-by-side", "warped"), default="flow",
                   help="colour flow only; frame | colour flow | warped next frame; or the "
                   "next frame warped back onto each frame by its flow (grey where the flow "
                   "points outside it)")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="flow magnitude of full colour saturation (default: the 99th "
                   "percentile of |w| over all pixels of all pairs not across a scene cut, "
                   "computed in a first pass; longer vectors are darkened)")
    p.add_argument("--no-scene-cuts", dest="scene_cuts", action="store_false",
                   help="compute the flow across scene cuts too")
    p.add_argument("--codec", metavar="C", help="FFmpeg encoder (default after the extension)")
    p.add_argument("--quality", type=int, metavar="Q",
                   help="encoder quality (CRF for libx264; lower is better)")
    p.add_argument("--no-legend", dest="legend", action="store_false",
                   help="no colour-wheel legend")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    p.set_defaults(func=_cmd_video)


def _check_int(value: int | None, name: str, minimum: int) -> None:
    if value is not None and value < minimum:
        raise ValueError(f"{name}: must be >= {minimum}, got {value}")


def _render(
    layout: str, flow: np.ndarray, f0: np.ndarray | None, f1: np.ndarray | None,
    radius: float, legend: bool, cut: bool = False,
) -> np.ndarray:
    from ..viz.video import flow_frame, grey_out_invalid, side_by_side, warp_next_frame

    if layout == "flow":
        return flow_frame(flow, radius, legend=legend)
    assert f0 is not None and f1 is not None
    if layout == "warped":
        warped, valid = warp_next_frame(f1, flow)
        return grey_out_invalid(warped, valid)
    labels: Sequence[str] | bool = ("frame", "scene cut", "next, warped") if cut else True
    return side_by_side(f0, flow, f1, radius, labels=labels, legend=legend)


def _pairs(frames: Iterator[np.ndarray]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    prev = next(frames, None)
    for frame in frames:
        assert prev is not None
        yield prev, frame
        prev = frame


def _pairs_and_cuts(
    frames: Iterator[np.ndarray], detect: bool,
) -> Iterator[tuple[np.ndarray, np.ndarray, bool]]:
    """``(f0, f1, across a scene cut)`` of consecutive frames.

    The detector of ``varflow retime``, given the frames before ``f0`` and after
    ``f1`` (a cut's score must stand out from its neighbours'): holds four frames.
    """
    from ..retime.stream import CUT_THRESHOLD, cut_score, is_scene_cut

    before = None
    f0, f1 = next(frames, None), next(frames, None)
    while f0 is not None and f1 is not None:
        after = next(frames, None)
        # the pair's own score decides first (cheap); the neighbours only when it is high
        cut = (detect and cut_score(f0, f1) >= CUT_THRESHOLD
               and is_scene_cut(f0, f1, previous=before, following=after))
        yield f0, f1, cut
        before, f0, f1 = f0, f1, after


def _too_few(args: argparse.Namespace, n: int, n_selected: int) -> str:
    """The message for fewer than 2 selected frames, naming the selection options that
    were given."""
    from ..io.sequences import too_few_frames_message

    changed = [f"{flag} {value}" for flag, value, default in (
        ("--start", args.start, 0), ("--stop", args.stop, None), ("--stride", args.stride, 1))
        if value != default]
    if not changed:
        return too_few_frames_message(args.video, n)
    return (f"{args.video}: need at least 2 frames, {n_selected} of {n} selected with "
            f"{' '.join(changed)}")


def _scale_text(source: str, cuts: int | None) -> str:
    """``"(99th percentile of |w|, 1 scene cut skipped)"``."""
    if cuts is None:
        return f"({source}, scene cuts not detected)"
    if cuts == 0:
        return f"({source}, no scene cut)"
    return f"({source}, {cuts} scene cut{'s' if cuts > 1 else ''} skipped)"


def _cmd_video(args: argparse.Namespace) -> int:
    import varflow
    from varflow.io.sequences import FrameSource
    from varflow.io.video_writer import VideoWriter
    from varflow.viz.video import SCALE_PERCENTILE, flow_percentile_radius

    method = get_method(args.method)
    _claim_inputs((args.video, "IN"))
    out = _check_output(args.output, _OUTPUT_SUFFIXES, "-o/--output")
    max_radius = _max_radius(args.max_radius)
    _check_int(args.start, "--start", 0)
    _check_int(args.stop, "--stop", 0)
    _check_int(args.stride, "--stride", 1)
    _check_int(args.quality, "--quality", 0)

    with FrameSource(args.video, args.input_fps) as clip:
        selected = range(clip.n)[args.start : args.stop : args.stride]
        n_pairs = len(selected) - 1
        if n_pairs < 1:
            raise ValueError(_too_few(args, clip.n, len(selected)))
        fps = clip.rate / args.stride
        log.info("%s: %s of %d frames at %s fps; %d pairs, method %s", args.video, clip.kind,
                 clip.n, clip.rate, n_pairs, method.name)

        def frames() -> Iterator[np.ndarray]:
            return clip.frames(args.start, args.stop, args.stride)

        peak = 0.0
        cuts: list[bool] = []
        h = w = 0
        _compile_notice(method.name, args.quiet)
        t0 = time.perf_counter()
        with (
            VideoWriter(out, fps, codec=args.codec, quality=args.quality) as writer,
            tempfile.TemporaryDirectory(prefix="varflow-video-") as tmp,
            _Progress(method.name, args.quiet, unit="pair") as progress,
        ):
            store = None
            progress(0, n_pairs)
            for k, (f0, f1, cut) in enumerate(_pairs_and_cuts(frames(), args.scene_cuts)):
                if k == 0:
                    h, w = f0.shape[:2]
                    if max_radius is None:  # flows on disk until the common scale is known
                        store = np.lib.format.open_memmap(
                            Path(tmp) / "flows.npy", mode="w+", dtype=np.float32,
                            shape=(n_pairs, h, w, 2),
                        )
                cuts.append(cut)
                if cut:
                    log.info("scene cut between frames %d and %d: no flow", selected[k],
                             selected[k + 1])
                    flow = np.full((h, w, 2), np.nan, np.float32)
                else:
                    flow = varflow.flow(f0, f1, method.name)
                    mag = np.hypot(flow[..., 0], flow[..., 1])
                    mag = mag[np.isfinite(mag)]
                    peak = max(peak, float(mag.max()) if mag.size else 0.0)
                if store is None:
                    assert max_radius is not None
                    writer.write(_render(args.layout, flow, f0, f1, max_radius, args.legend,
                                         cut))
                else:
                    store[k] = flow
                progress(k + 1, n_pairs)
            if len(cuts) != n_pairs:
                raise ValueError(f"{args.video}: the input ended after {len(cuts) + 1} of "
                                 f"{n_pairs + 1} selected frames (truncated?)")
            seconds = time.perf_counter() - t0
            if store is not None:
                store.flush()
                radius = flow_percentile_radius(store, SCALE_PERCENTILE)
                source = f"{SCALE_PERCENTILE:g}th percentile of |w|"
                pairs = _pairs(frames()) if args.layout != "flow" else None
                for k in range(n_pairs):
                    f0, f1 = next(pairs) if pairs is not None else (None, None)
                    writer.write(_render(args.layout, np.asarray(store[k]), f0, f1, radius,
                                         args.legend, cuts[k]))
                del store
            else:
                assert max_radius is not None
                radius = max_radius
                source = "--max-radius"
    n_cuts = sum(cuts) if args.scene_cuts else None
    print(
        f"{method.name}: {n_pairs - sum(cuts)} flows of {w}x{h} (frames {selected[0]}.."
        f"{selected[-1]}, stride {args.stride}) in {seconds:.2f} s, max |w| {peak:.3f} px, "
        f"colour scale {radius:.3f} px {_scale_text(source, n_cuts)} -> {out} "
        f"({writer.frames_written} frames, {float(fps):.6g} fps)"
    )
    return 0
