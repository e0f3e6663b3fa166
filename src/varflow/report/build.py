"""The content of the report for each kind of input, and :func:`build_report`.

Colour scale
    Flows are coded with the Middlebury colour wheel
    (:func:`varflow.viz.colorwheel.flow_to_color`).  Within one video (a batch
    sub-folder, a trajectory file, or an estimate with its ground truth) every image
    uses ONE saturation radius, stated on the page in pixels: the largest known
    magnitude over the images shown (the ground truth's when there is one).
Sizes
    At most ``max_frames`` flows per video are shown, evenly spaced (first and last
    included); trajectory folders show at most ``max(1, max_frames // 4)`` windows,
    each with at most ``max_frames`` frames.  Images are box-filtered down so their
    longer side is at most ``thumb_side`` (thumbnails) or ``large_side`` (single
    images) pixels; the page states the original and the shown sizes.  The images of
    the single-flow row (frames, warped frame, estimate, ground truth, error map)
    share one size: each longer side is ``ROW_WIDTH // n`` for ``n`` images, kept
    between ``thumb_side`` and ``large_side``, so that the row stays side by side.
Input frames
    A single flow may come with its input frames (``--frames F0 [F1]``): they are shown
    in the row of the flow, and with both frames, frame 1 warped back by the estimate
    (bilinear) with its photometric error, the mean absolute difference to frame 0 on
    0–255 over the pixels whose target lands inside frame 1.  In a batch folder, each
    flow thumbnail is paired with the thumbnail of the first frame of its pair, read
    from the input the manifest records (each frame once; a video in one forward
    pass); when that input is gone the flows are shown alone, with a note.

Modules
    This module holds the entry points (:func:`render_report`, :func:`build_report`);
    the content of each kind of input lives in its own module:
    :mod:`varflow.report.batch` (a batch output folder),
    :mod:`varflow.report.flows` (flow videos of a batch folder, a single flow file),
    :mod:`varflow.report.trajectories` (trajectory windows of a batch folder, a single
    trajectory file) and :mod:`varflow.report.bench` (a bench CSV), on the shared
    pieces of :mod:`varflow.report.common`.
"""

from __future__ import annotations

import dataclasses
import datetime
import logging
import os
from collections.abc import Sequence
from pathlib import Path

from .batch import MAX_FAILED_ROWS as MAX_FAILED_ROWS
from .batch import report_batch
from .bench import report_bench
from .common import LARGE_SIDE, THUMB_SIDE, PathArg
from .common import LEGEND_SIDE as LEGEND_SIDE
from .common import ROW_WIDTH as ROW_WIDTH
from .common import WINDOW_THUMB_SIDE as WINDOW_THUMB_SIDE
from .flows import report_flow
from .html import Page
from .sources import detect_kind, load_batch, load_bench_csv
from .trajectories import report_trajectories

__all__ = ["ReportInfo", "render_report", "build_report", "DEFAULT_MAX_FRAMES"]

logger = logging.getLogger(__name__)

#: Default cap on the thumbnails per video.
DEFAULT_MAX_FRAMES = 12

_KIND_TEXT = {
    "batch": "batch output folder",
    "bench": "benchmark CSV",
    "flow": "flow file",
    "trajectories": "trajectory file",
}


@dataclasses.dataclass
class ReportInfo:
    """What :func:`build_report` wrote."""

    #: Input kind: "batch", "bench", "flow" or "trajectories".
    kind: str
    #: Number of inlined images.
    n_images: int
    #: Size of the HTML document in bytes (UTF-8).
    n_bytes: int
    #: The output path.
    output: Path


def _frame_paths(frames: PathArg | Sequence[PathArg] | None) -> list[Path]:
    """``--frames`` as a list of paths (one path alone is a list of one)."""
    if frames is None:
        return []
    if isinstance(frames, str | os.PathLike):
        return [Path(os.fspath(frames))]
    return [Path(os.fspath(f)) for f in frames]


def render_report(
    path: str | os.PathLike[str],
    *,
    gt: str | os.PathLike[str] | None = None,
    title: str | None = None,
    max_frames: int = DEFAULT_MAX_FRAMES,
    frames: PathArg | Sequence[PathArg] | None = None,
) -> tuple[str, ReportInfo]:
    """Build the HTML report of a batch folder, bench CSV, flow or trajectory file.

    Parameters
    ----------
    path : str or path-like
        The input (see :func:`varflow.report.sources.detect_kind`).
    gt : str or path-like, optional
        Ground-truth flow; only for a single flow file.
    title : str, optional
        Page title (default: ``"varflow report: <name>"``).
    max_frames : int
        Thumbnails per video, ``>= 1``.
    frames : str, path-like or sequence of them, optional
        For a single flow file: its input frames, frame 0 and optionally frame 1
        (images of the flow's size), shown in the row of the flow; with both, frame 1
        warped back by the flow and its photometric error.  For a single trajectory
        file: exactly one reference frame (an image, or a folder of frames).

    Returns
    -------
    html : str
    info : ReportInfo
        ``output`` is the input path here; :func:`build_report` fills it in.

    Raises
    ------
    ValueError, OSError
        On a bad input or option (one-line messages).
    """
    from .._version import __version__

    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 1:
        raise ValueError(f"--max-frames: must be an integer >= 1, got {max_frames!r}")
    src = Path(os.fspath(path))
    kind = detect_kind(src)
    if gt is not None and kind != "flow":
        raise ValueError(f"--gt: only for a single flow file, not a {_KIND_TEXT[kind]}")
    frame_paths = _frame_paths(frames)
    if frame_paths and kind not in ("flow", "trajectories"):
        raise ValueError(f"--frames: only for a single flow or trajectory file, not a "
                         f"{_KIND_TEXT[kind]}")
    if kind == "trajectories" and len(frame_paths) > 1:
        raise ValueError(f"--frames: a trajectory file takes one reference frame (an image or "
                         f"a folder of frames), got {len(frame_paths)} paths")
    if kind == "flow" and len(frame_paths) > 2:
        raise ValueError(f"--frames: a flow takes its two input frames (frame 0 [frame 1]), "
                         f"got {len(frame_paths)} paths")
    page = Page(title or f"varflow report: {src.resolve().name or src}")
    if kind == "batch":
        report_batch(page, load_batch(src), max_frames)
    elif kind == "bench":
        report_bench(page, load_bench_csv(src))
    elif kind == "flow":
        report_flow(page, src, gt, frame_paths)
    else:
        report_trajectories(page, src, frame_paths[0] if frame_paths else None, max_frames)
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    header = [
        f"varflow {__version__} · generated {now}",
        f"source ({_KIND_TEXT[kind]}): {src.resolve()}",
    ]
    if page.n_images:
        header.append(f"{page.n_images} images inlined as PNG ({page.image_bytes / 1e6:.2f} MB "
                      f"of data URIs); thumbnails at most {THUMB_SIDE} px, single images at most "
                      f"{LARGE_SIDE} px, up to {max_frames} frames per video")
    if gt is not None:
        header.insert(2, f"ground truth: {Path(os.fspath(gt)).resolve()}")
    if frame_paths:
        header.insert(2, "frames: " + ", ".join(str(p.resolve()) for p in frame_paths))
    text = page.render(header)
    info = ReportInfo(kind, page.n_images, len(text.encode("utf-8")), src)
    return text, info


def build_report(
    path: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    gt: str | os.PathLike[str] | None = None,
    title: str | None = None,
    max_frames: int = DEFAULT_MAX_FRAMES,
    frames: PathArg | Sequence[PathArg] | None = None,
) -> ReportInfo:
    """Write the self-contained HTML report of ``path`` to ``output`` atomically.

    Parameters
    ----------
    path : str or path-like
        Batch output folder, bench CSV, ``.flo``/``.png`` flow or trajectory ``.npz``.
    output : str or path-like
        The ``.html`` file; its directory must exist.  Nothing is written on error.
    gt, title, max_frames, frames
        As in :func:`render_report`.

    Returns
    -------
    ReportInfo
    """
    from ..io._atomic import atomic_write

    out = Path(os.fspath(output))
    if out.suffix.lower() not in (".html", ".htm"):
        raise ValueError(f"-o/--output: {out} must end in .html")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(2, "-o/--output: directory does not exist", str(parent))
    if out.is_dir():
        raise IsADirectoryError(21, "-o/--output: is a directory", str(out))
    text, info = render_report(path, gt=gt, title=title, max_frames=max_frames, frames=frames)
    with atomic_write(out, "w") as f:
        f.write(text)
    logger.info("wrote %s: %d images, %d bytes", out, info.n_images, info.n_bytes)
    return dataclasses.replace(info, output=out)
