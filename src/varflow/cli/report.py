"""``varflow report``: a self-contained HTML page of results (:mod:`varflow.report`).

Synopsis::

    varflow report PATH -o REPORT.html [--gt GT.flo] [--title T] [--max-frames N]
                   [--frames FRAME [FRAME]]

``--frames``: for a flow file, its input frames ``FRAME0 [FRAME1]`` (shown in the row
of the flow; with both, frame 1 warped back by the flow and its photometric error);
for a trajectory ``.npz``, exactly one reference frame image or folder of frames.

Errors are raised as ``ValueError``/``OSError`` and become one ``varflow: error: ...``
line.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from ..report.build import DEFAULT_MAX_FRAMES, build_report

__all__ = ["add_parser", "run"]


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


def run(args: argparse.Namespace) -> int:
    """Write the report and print one summary line."""
    info = build_report(args.path, args.output, gt=args.gt, title=args.title,
                        max_frames=args.max_frames, frames=args.frames)
    print(f"{info.kind} report: {info.n_images} images, {info.n_bytes / 1e6:.2f} MB "
          f"-> {info.output}")
    return 0


def add_parser(sub: Any, common: argparse.ArgumentParser,
               argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """Add ``report`` to the sub-command parsers ``sub``.

    Parameters
    ----------
    sub : argparse sub-parsers action
        From ``parser.add_subparsers``.
    common : ArgumentParser
        Parent parser with the options every command has (``-v``).
    argv : sequence of str, optional
        The command line (unused: ``report`` has no parameter flags).

    Returns
    -------
    ArgumentParser
        The new sub-parser.
    """
    p = sub.add_parser(
        "report", parents=[common], help="self-contained HTML report of results",
        description="Write one static HTML page (images inlined, no external requests, no "
        "JavaScript) about PATH: a batch output folder (flows and trajectory windows per "
        "video, parameters from manifest.sqlite, failed tasks), a 'varflow bench --csv' file "
        "(per-sequence tables, per-method summary and bar charts), a .flo / KITTI .png flow "
        "(with --gt: error map and AEE/AAE/RMS/R1/R3; with --frames: its input frames in "
        "the same row) or a trajectory .npz (trajectory plot, displacement and visibility "
        "per frame).  Flows of one video share one colour scale, stated in pixels; batch "
        "flows are shown beside the first frame of their pair when the input can be read.")
    p.add_argument("path", metavar="PATH",
                   help="batch output folder, bench .csv, .flo/.png flow or trajectory .npz")
    p.add_argument("-o", "--output", required=True, metavar="REPORT.html",
                   help="the HTML file to write (atomically)")
    p.add_argument("--gt", metavar="GT.flo", help="ground-truth flow (single flow file only)")
    p.add_argument("--title", metavar="T", help="page title (default: from PATH)")
    p.add_argument("--max-frames", type=_positive_int, default=DEFAULT_MAX_FRAMES, metavar="N",
                   help=f"thumbnails per video, evenly spaced (default {DEFAULT_MAX_FRAMES})")
    p.add_argument("--frames", metavar="FRAME", nargs="+",
                   help="for a .flo/.png flow: its input frames FRAME0 [FRAME1] (images of "
                   "the flow's size), shown side by side with the flow; with both, also "
                   "frame 1 warped back by the flow and its photometric error (mean |I1(x+w) "
                   "- I0(x)| on 0-255), a check without ground truth.  For a trajectory "
                   ".npz: one reference frame image (or folder of frames) to draw the "
                   "trajectories on (default: the frame named in its metadata, else a "
                   "neutral background)")
    p.set_defaults(func=run)
    return p
