"""``varflow video``: a colour-coded flow video of a video.

Synopsis::

    varflow video VIDEO -o OUT.(mp4|mkv|avi) [--method NAME] [--start N] [--stop N]
                  [--stride S] [--layout flow|side-by-side|warped] [--max-radius R]
                  [--codec C] [--quality Q] [-q]

The frames ``start, start + S, start + 2S, ... < stop`` are read (streaming, with
:meth:`varflow.io.video.VideoReader.iter_frames`) and the flow of every consecutive
pair of them, ``(i, i + S)``, becomes one frame of the output, at the input frame
rate divided by ``S`` (so the output lasts as long as the input section).

One colour scale for the whole video: with ``--max-radius R`` every flow is
rendered and written as soon as it is computed.  Without it the scale is the
largest flow magnitude of all pairs, which is only known at the end: the flows are
then kept in a temporary ``np.memmap`` file (``P * H * W * 2`` float32 on disk,
not in RAM; deleted afterwards), and a second pass renders them (re-reading the
frames for ``--layout side-by-side``).
"""

from __future__ import annotations

import argparse
import logging
import math
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..registry import METHODS, get_method
from ._common import _check_output, _compile_notice, _max_radius, _Progress

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
        help="colour-coded flow video of a video",
        description="Compute the flow between consecutive (sub-sampled) frames of VIDEO and "
        "write it as a colour-coded video on one colour scale (or side by side with the "
        "frames and the warped next frame).",
    )
    p.add_argument("video", metavar="VIDEO", help="input video (any format FFmpeg reads)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="output video: .mp4 (H.264), .mkv (lossless FFV1) or .avi (MPEG-4)")
    p.add_argument("--method", default="tvl1", metavar="NAME",
                   help=f"one of: {', '.join(METHODS)} (default tvl1)")
    p.add_argument("--start", type=int, default=0, metavar="N",
                   help="first frame (default 0)")
    p.add_argument("--stop", type=int, default=None, metavar="N",
                   help="end frame, exclusive (default: the end of the video)")
    p.add_argument("--stride", type=int, default=1, metavar="S",
                   help="use every S-th frame; flows of the pairs (i, i+S) (default 1)")
    p.add_argument("--layout", choices=("flow", "side-by-side", "warped"), default="flow",
                   help="colour flow only; frame | colour flow | warped next frame; or the "
                   "next frame warped back onto each frame by its flow (grey where the flow "
                   "points outside it)")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="flow magnitude of full colour saturation (default: the maximum over "
                   "all pairs, computed in a first pass)")
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
    radius: float, legend: bool,
) -> np.ndarray:
    from ..viz.video import flow_frame, grey_out_invalid, side_by_side, warp_next_frame

    if layout == "flow":
        return flow_frame(flow, radius, legend=legend)
    assert f0 is not None and f1 is not None
    if layout == "warped":
        warped, valid = warp_next_frame(f1, flow)
        return grey_out_invalid(warped, valid)
    return side_by_side(f0, flow, f1, radius, legend=legend)


def _pairs(frames: Iterator[np.ndarray]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    prev = next(frames, None)
    for frame in frames:
        assert prev is not None
        yield prev, frame
        prev = frame


def _cmd_video(args: argparse.Namespace) -> int:
    import varflow
    from varflow.io.video_reader import VideoReader
    from varflow.io.video_writer import VideoWriter

    method = get_method(args.method)
    out = _check_output(args.output, _OUTPUT_SUFFIXES, "-o/--output")
    max_radius = _max_radius(args.max_radius)
    _check_int(args.start, "--start", 0)
    _check_int(args.stop, "--stop", 0)
    _check_int(args.stride, "--stride", 1)
    _check_int(args.quality, "--quality", 0)

    with VideoReader(args.video) as reader:
        info = reader.info
        selected = range(len(reader))[args.start : args.stop : args.stride]
        n_pairs = len(selected) - 1
        if n_pairs < 1:
            raise ValueError(
                f"{args.video}: {len(selected)} frame(s) selected of {len(reader)} with "
                f"--start {args.start} --stop {args.stop} --stride {args.stride}; need at least 2"
            )
        h, w = info.height, info.width
        fps = info.fps / args.stride if math.isfinite(info.fps) and info.fps > 0 else 25.0
        log.info("%s: %s; %d pairs, method %s", args.video, info, n_pairs, method.name)

        def frames() -> Iterator[np.ndarray]:
            return reader.iter_frames(args.start, args.stop, args.stride)

        peak = 0.0
        _compile_notice(method.name, args.quiet)
        t0 = time.perf_counter()
        with (
            VideoWriter(out, fps, codec=args.codec, quality=args.quality) as writer,
            tempfile.TemporaryDirectory(prefix="varflow-video-") as tmp,
            _Progress(method.name, args.quiet, unit="pair") as progress,
        ):
            store = None
            if max_radius is None:  # flows on disk until the common scale is known
                store = np.lib.format.open_memmap(
                    Path(tmp) / "flows.npy", mode="w+", dtype=np.float32,
                    shape=(n_pairs, h, w, 2),
                )
            progress(0, n_pairs)
            for k, (f0, f1) in enumerate(_pairs(frames())):
                flow = varflow.flow(f0, f1, method.name)
                mag = np.hypot(flow[..., 0], flow[..., 1])
                mag = mag[np.isfinite(mag)]
                peak = max(peak, float(mag.max()) if mag.size else 0.0)
                if store is None:
                    assert max_radius is not None
                    writer.write(_render(args.layout, flow, f0, f1, max_radius, args.legend))
                else:
                    store[k] = flow
                progress(k + 1, n_pairs)
            seconds = time.perf_counter() - t0
            if store is not None:
                radius = peak * (1.0 + 1e-5) if peak > 0 else 1.0
                store.flush()
                pairs = _pairs(frames()) if args.layout != "flow" else None
                for k in range(n_pairs):
                    f0, f1 = next(pairs) if pairs is not None else (None, None)
                    writer.write(_render(args.layout, np.asarray(store[k]), f0, f1, radius,
                                         args.legend))
                del store
            else:
                assert max_radius is not None
                radius = max_radius
    last = selected[-1]
    print(
        f"{method.name}: {n_pairs} flows of {w}x{h} (frames {selected[0]}..{last}, stride "
        f"{args.stride}) in {seconds:.2f} s, max |w| {peak:.3f} px, colour scale "
        f"{radius:.3f} px -> {out} ({writer.frames_written} frames, {fps:.6g} fps)"
    )
    return 0
