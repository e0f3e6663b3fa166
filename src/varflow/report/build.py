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
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import logging
import math
import os
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import error_line
from .figures import (
    downscale,
    error_colorbar,
    error_map,
    grey_outside,
    neutral_background,
    to_uint8,
    unit_rgb_frames,
    visibility_image,
)
from .html import Page, bar_chart_svg, esc, key_value_table, table
from .sources import (
    BatchFolder,
    BenchTable,
    Video,
    detect_kind,
    evenly_spaced,
    finite,
    load_batch,
    load_bench_csv,
)

__all__ = ["ReportInfo", "render_report", "build_report", "DEFAULT_MAX_FRAMES"]

logger = logging.getLogger(__name__)

#: Default cap on the thumbnails per video.
DEFAULT_MAX_FRAMES = 12
#: Longer side of thumbnails and of single images, in pixels.
THUMB_SIDE = 256
LARGE_SIDE = 640
#: Width shared by the images of the single-flow row (see the module notes).
ROW_WIDTH = 1280
#: Side of the colour-wheel legend image.
LEGEND_SIDE = 101
#: Thumbnails of the frames of trajectory windows in a batch folder.
WINDOW_THUMB_SIDE = 160
#: Largest F * H * W (after enlarging) of a trajectory plot drawn enlarged.
_MAX_PLOT_VALUES = 8_000_000
#: Rows shown in the table of failed tasks.
MAX_FAILED_ROWS = 500
#: Largest number of bytes of decoded video frames held at once (batch input frames).
_FRAME_CHUNK_BYTES = 256 * 2**20

PathArg = str | os.PathLike[str]

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


# --------------------------------------------------------------------------- helpers


def _magnitude(flow: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        mag = np.hypot(flow[..., 0].astype(np.float64), flow[..., 1].astype(np.float64))
        mag[~np.isfinite(mag) | (mag > 1e9)] = np.nan
    return mag


def _max_magnitude(arrays: Sequence[np.ndarray]) -> float:
    """Largest known magnitude over flows; 1.0 when there is none or all are zero."""
    top = 0.0
    for a in arrays:
        m = _magnitude(a)
        if np.isfinite(m).any():
            top = max(top, float(np.nanmax(m)))
    return top * (1.0 + 1e-5) if top > 0 else 1.0


def _flow_stats(flow: np.ndarray) -> tuple[float, float, float]:
    """(mean |w|, max |w|, unknown %) of a flow."""
    m = _magnitude(flow)
    known = np.isfinite(m)
    if not known.any():
        return math.nan, math.nan, 100.0
    return float(m[known].mean()), float(m[known].max()), 100.0 * float(1.0 - known.mean())


def _frame_paths(frames: PathArg | Sequence[PathArg] | None) -> list[Path]:
    """``--frames`` as a list of paths (one path alone is a list of one)."""
    if frames is None:
        return []
    if isinstance(frames, str | os.PathLike):
        return [Path(os.fspath(frames))]
    return [Path(os.fspath(f)) for f in frames]


def _size(shape: Sequence[int]) -> str:
    return f"{shape[1]}×{shape[0]}"


def _size_note(orig: Sequence[int], shown: Sequence[int]) -> str:
    if tuple(orig[:2]) == tuple(shown[:2]):
        return f"{_size(orig)} px (full size)"
    return f"{_size(orig)} px shown at {_size(shown)}"


def _legend(page: Page, scale: float) -> str:
    from ..viz.colorwheel import color_wheel_legend

    return page.image(color_wheel_legend(LEGEND_SIDE), role="legend",
                      caption=f"colour wheel, rim = {scale:.4g} px",
                      alt=f"colour wheel: direction = hue, |w| = {scale:.4g} px at the rim "
                          f"(full saturation), darker beyond",
                      extra={"scale": f"{scale:.6g}"})


def _params_block(page: Page, method: str | None, params: dict[str, Any] | None,
                  extra: dict[str, Any] | None = None) -> None:
    items: dict[str, Any] = {}
    if method:
        items["method"] = method
    items.update(extra or {})
    if items:
        page.add(key_value_table(items, cls="info"))
    if params:
        page.add('<details open><summary>parameters</summary>')
        page.add(key_value_table(params, cls="params"))
        page.add("</details>")


# --------------------------------------------------------------------------- flows


def _read_chosen(video: Video, chosen: Sequence[int],
                 reader: Any) -> tuple[list[tuple[int, Any]], list[str]]:
    """``(index, reader(file))`` for the chosen files of a video; unreadable ones are
    logged and returned as ``"name: error"`` problems instead."""
    loaded: list[tuple[int, Any]] = []
    problems: list[str] = []
    for i in chosen:
        try:
            loaded.append((i, reader(video.files[i])))
        except (ValueError, OSError) as exc:
            problems.append(f"{video.files[i].name}: {exc}")
            logger.warning("report: cannot read %s: %s", video.files[i], exc)
    return loaded, problems


def _check_frame_range(src: Path, n: int, wanted: Sequence[int], what: str) -> None:
    if wanted and wanted[-1] >= n:
        raise ValueError(f"{src} has {n} {what}, the flows need frame {wanted[-1]}")


def _iter_input_frames(src: Path, wanted: Sequence[int]) -> Iterator[tuple[int, np.ndarray]]:
    """``(index, frame)`` for the increasing frame indices ``wanted`` of a batch input.

    A frame folder: its image files in natural order (the batch's numbering), each
    read once.  A video: :meth:`VideoReader.read_indices` in chunks of at most
    ``_FRAME_CHUNK_BYTES`` of decoded frames, one forward pass that seeks past the
    GOPs holding no wanted frame and decodes nothing after the last one.
    """
    from ..io import read_image
    from ..io.video import VideoReader, list_frame_files

    if not src.exists():
        raise FileNotFoundError(2, "input not found", str(src))
    if src.is_dir():
        files = list_frame_files(src)
        _check_frame_range(src, len(files), wanted, "images")
        for i in wanted:
            yield i, read_image(files[i])
        return
    with VideoReader(src) as reader:
        _check_frame_range(src, len(reader), wanted, "frames")
        info = reader.info
        frame_bytes = max(1, int(np.prod(info.frame_shape)) * np.dtype(info.dtype).itemsize)
        chunk = max(1, _FRAME_CHUNK_BYTES // frame_bytes)
        for k in range(0, len(wanted), chunk):
            part = list(wanted[k:k + chunk])
            yield from zip(part, reader.read_indices(part), strict=True)


def _input_thumbnails(video: Video, indices: Sequence[int]) -> tuple[dict[int, np.ndarray], str]:
    """Thumbnails of the input frames ``indices`` of a flow video, and a note line.

    Returns
    -------
    thumbs : dict of int to ndarray
        Frame index -> ``(h, w, 3)`` uint8 thumbnail; empty when the input is not
        recorded, missing or unreadable (the note then says why).
    note : str
    """
    if video.input is None:
        why = ("the manifest does not name the input" if video.tasks
               else "no manifest row names the input of this video")
        return {}, f"Input frames not shown: {why}."
    src = Path(video.input)
    thumbs: dict[int, np.ndarray] = {}
    try:
        for i, frame in _iter_input_frames(src, sorted(set(indices))):
            rgb = unit_rgb_frames([frame], [f"{src.name} frame {i}"])[0]
            thumbs[i] = downscale(to_uint8(rgb), THUMB_SIDE)
    except (ValueError, OSError) as exc:
        logger.info("report: input frames of %s not shown: %s", video.name, exc)
        return {}, f"Input frames not shown: {error_line(exc)}; the flows are shown alone."
    return thumbs, f"Beside each flow: the first frame of its pair, from the input {src}."


def _flow_thumbnails(page: Page, video: Video, max_frames: int) -> list[str]:
    """Thumbnails of a flow video, each beside its first input frame when the input
    can be read; returns problems (unreadable flow files)."""
    from ..io import read_flow
    from ..viz.colorwheel import flow_to_color

    chosen = evenly_spaced(len(video.files), max_frames)
    flows, problems = _read_chosen(video, chosen, read_flow)
    if not flows:
        page.para("No readable flow file.")
        return problems
    scale = _max_magnitude([f for _, f in flows])
    shapes = {f.shape[:2] for _, f in flows}
    first = {i: (video.pairs[i][0] if i < len(video.pairs) and video.pairs[i] is not None
                 else video.numbers[i]) for i, _ in flows}
    inputs, input_note = _input_thumbnails(video, list(first.values()))
    thumbs = []
    stats = []
    shown_size = None
    for i, flow in flows:
        img = downscale(flow_to_color(flow, max_radius=scale), THUMB_SIDE)
        shown_size = img.shape[:2]
        fig = page.image(img, role="flow", caption=video.labels[i],
                         extra={"frame": video.numbers[i], "scale": f"{scale:.6g}"})
        if first[i] in inputs:  # frame | flow, wrapping together
            fig = (f'<div class="pair" data-frame="{first[i]}">'
                   + page.image(inputs[first[i]], role="frame", caption=f"frame {first[i]}",
                                extra={"frame": first[i]})
                   + fig + "</div>")
        thumbs.append(fig)
        stats.append((video.labels[i], *_flow_stats(flow)))
    orig = sorted(shapes)[0]
    sizes = _size_note(orig, shown_size) if len(shapes) == 1 else (
        f"sizes {', '.join(_size(s) for s in sorted(shapes))} px, longer side at most "
        f"{THUMB_SIDE} px")
    page.para(f"Showing {len(flows)} of {len(video.files)} flows, evenly spaced; one colour "
              f"scale for the video: full saturation at {scale:.4g} px (the largest |w| of the "
              f"flows shown); {sizes}.", cls="note scale")
    page.para(input_note, cls="note frames")
    page.add('<div class="thumbs">' + _legend(page, scale) + "".join(thumbs) + "</div>")
    page.add("<details><summary>magnitudes of the flows shown</summary>")
    page.add(table(("flow", "mean |w| px", "max |w| px", "unknown %"), stats))
    page.add("</details>")
    return problems


# --------------------------------------------------------------------------- trajectories


def _read_frame_file(path: Path, shape: tuple[int, int], against: str) -> np.ndarray:
    """An image given with ``--frames``, checked to be ``shape`` (H, W) like ``against``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is a folder, cannot be read as an image or has another size (one line
        naming ``--frames``, the file and both sizes).
    """
    from ..io import read_image

    if not path.exists():
        raise FileNotFoundError(2, "--frames: image not found", str(path))
    if path.is_dir():
        raise ValueError(f"--frames: {path} is a folder; give the image files")
    try:
        img = read_image(path)
    except ValueError as exc:
        raise ValueError(f"--frames: {error_line(exc)}") from exc
    if img.shape[:2] != tuple(shape):
        raise ValueError(f"--frames: {path} is {_size(img.shape)} px, {against} "
                         f"{'are' if against.endswith('s') else 'is'} {_size(shape)} px")
    return img


def _read_reference(frames: Path | None, ref: int,
                    metadata: dict[str, Any], shape: tuple[int, int]) -> tuple[Any, str]:
    """The reference frame to draw on, and a note saying where it came from."""
    from ..io import read_image

    if frames is not None:
        p = frames
        if p.is_dir():
            from ..io.video import list_frame_files

            files = list_frame_files(p)
            if not 0 <= ref < len(files):
                raise ValueError(f"--frames: {p} has {len(files)} images, the reference frame "
                                 f"is number {ref}")
            p = files[ref]
        img = _read_frame_file(p, shape, "the trajectories")
        return img, f"over reference frame {p.name}"
    listed = metadata.get("frames")
    if isinstance(listed, list) and len(listed) > ref and all(isinstance(f, str) for f in listed):
        p = Path(listed[ref]) if len(listed) > 1 else None
        if p is not None and p.is_file():
            try:
                img = read_image(p)
                if img.shape[:2] == shape:
                    return img, f"over reference frame {p.name} (from the file's metadata)"
            except (ValueError, OSError) as exc:
                logger.info("report: reference frame %s not usable: %s", p, exc)
    return neutral_background(*shape), "on a neutral background (no reference frame given)"


def _trajectory_block(page: Page, traj: np.ndarray, ref: int, visibility: np.ndarray | None,
                      *, scale: float, max_frames: int, plot_side: int, thumb_side: int,
                      background: Any, background_note: str, label: str) -> None:
    from ..viz.colorwheel import flow_to_color
    from ..viz.plots import draw_trajectories

    n_f, h, w = traj.shape[:3]
    # Small frames are drawn enlarged (an integer factor k, nearest-neighbour background,
    # displacements times k) so that the tracks stay readable; large ones are drawn at full
    # size and box-filtered down.
    k = max(1, min(plot_side // max(h, w), 4))
    while k > 1 and n_f * h * w * k * k > _MAX_PLOT_VALUES:
        k -= 1
    step = max(6, round(max(h, w) / 16))
    line = max(1, round(max(h, w) * k / plot_side))
    if k > 1:
        bg = np.asarray(background)
        background = np.repeat(np.repeat(bg, k, axis=0), k, axis=1)
        traj_k = np.repeat(np.repeat(traj, k, axis=1), k, axis=2) * np.float32(k)
        vis_k = None if visibility is None else np.repeat(np.repeat(visibility, k, axis=1), k,
                                                          axis=2)
        plot = draw_trajectories(background, traj_k, ref, step=step * k, visibility=vis_k,
                                 line_width=line, max_radius=None)
        del traj_k, vis_k
    else:
        plot = draw_trajectories(background, traj, ref, step=step, visibility=visibility,
                                 line_width=line, max_radius=None)
    plot = downscale(plot, plot_side)
    hidden_note = ", grey where hidden" if visibility is not None else ""
    page.para(f"{label}: trajectories of a grid of points every {step} px {background_note}; "
              f"colour = direction of the overall motion{hidden_note}; dots mark the "
              f"reference positions; {_size_note((h, w), plot.shape)}.")
    page.add('<div class="thumbs">' + page.image(
        plot, role="trajectories", caption=f"trajectories, {label}", extra={"ref": ref})
        + _legend(page, scale) + "</div>")

    chosen = evenly_spaced(n_f, max_frames)
    disp = []
    vis = []
    rows = []
    shown = (h, w)
    for n in chosen:
        img = downscale(flow_to_color(traj[n], max_radius=scale), thumb_side)
        shown = img.shape[:2]
        tag = f"frame {n}" + (" (reference)" if n == ref else "")
        disp.append(page.image(img, role="displacement", caption=tag,
                               extra={"frame": n, "scale": f"{scale:.6g}"}))
        mean, top, unknown = _flow_stats(traj[n])
        row: list[Any] = [tag, mean, top, unknown]
        if visibility is not None:
            vis.append(page.image(downscale(visibility_image(visibility[n]), thumb_side),
                                  role="visibility", caption=tag, extra={"frame": n}))
            row.append(100.0 * float(visibility[n].mean()))
        rows.append(row)
    page.para(f"Displacement relative to reference frame {ref}: {len(chosen)} of {n_f} frames, "
              f"evenly spaced; one colour scale, full saturation at {scale:.4g} px; "
              f"{_size_note((h, w), shown)}.", cls="note scale")
    page.add('<div class="thumbs">' + "".join(disp) + "</div>")
    if visibility is not None:
        hidden = 100.0 * float(1.0 - visibility[np.arange(n_f) != ref].mean()) if n_f > 1 else 0.0
        page.para(f"Visibility (white: visible, dark: hidden); {hidden:.1f}% of the (pixel, "
                  f"frame) pairs outside the reference are hidden.")
        page.add('<div class="thumbs">' + "".join(vis) + "</div>")
    else:
        page.para("No visibility stored in this file.")
    header = ["frame", "mean |d| px", "max |d| px", "unknown %"]
    if visibility is not None:
        header.append("visible %")
    page.add("<details><summary>per-frame numbers</summary>")
    page.add(table(header, rows))
    page.add("</details>")


def _track_video(page: Page, video: Video, max_frames: int) -> list[str]:
    from ..io.trajectories import read_trajectories

    chosen = evenly_spaced(len(video.files), max(1, max_frames // 4))
    loaded, problems = _read_chosen(video, chosen, read_trajectories)
    if not loaded:
        page.para("No readable trajectory window.")
        return problems
    scale = _max_magnitude([tf.trajectories.reshape(-1, 1, 2) for _, tf in loaded])
    page.para(f"Showing {len(loaded)} of {len(video.files)} trajectory windows, evenly spaced; "
              f"one colour scale for the video: full saturation at {scale:.4g} px (the largest "
              f"displacement of the windows shown).", cls="note scale")
    for i, tf in loaded:
        page.heading(video.labels[i], level=4)
        if tf.metadata and not video.tasks:
            _params_block(page, tf.metadata.get("method"), tf.metadata.get("params"))
        h, w = tf.trajectories.shape[1:3]
        _trajectory_block(page, tf.trajectories, tf.ref, tf.visibility, scale=scale,
                          max_frames=max_frames, plot_side=2 * WINDOW_THUMB_SIDE,
                          thumb_side=WINDOW_THUMB_SIDE, background=neutral_background(h, w),
                          background_note="on a neutral background", label=video.labels[i])
    return problems


# --------------------------------------------------------------------------- batch


def _video_params(page: Page, video: Video) -> None:
    if not video.tasks:
        page.para("No manifest entry for this video (outputs found by scanning the folder).")
        return
    groups: Counter[str] = Counter()
    done = [t for t in video.tasks if t.status == "done"]
    for t in done or video.tasks:  # the settings of the outputs shown
        groups[json.dumps([t.method, t.version, t.params], sort_keys=True, default=str)] += 1
    inputs = sorted({t.input for t in video.tasks if t.input})
    for key, count in groups.items():
        method, version, params = json.loads(key)
        extra: dict[str, Any] = {}
        if inputs:
            extra["input"] = inputs[0] if len(inputs) == 1 else f"{len(inputs)} inputs"
        if version:
            extra["varflow version"] = version
        if len(groups) > 1:
            extra["tasks"] = count
        _params_block(page, method, params, extra)


def _batch(page: Page, src: BatchFolder, max_frames: int) -> None:
    tasks = src.tasks
    status = Counter(t.status or "unknown" for t in tasks)
    if src.manifest_error:
        page.add(f'<p class="warn">{esc(src.manifest_error)}; the folder was scanned '
                 f"instead.</p>")
    elif src.manifest is None:
        page.para("No manifest.sqlite: outputs found by scanning the folder; no parameters "
                  "or task states.")
    kinds = Counter(v.kind for v in src.videos)
    summary = (f"{len(src.videos)} videos ({kinds.get('flow', 0)} flow, "
               f"{kinds.get('track', 0)} trajectory)")
    if tasks:
        summary += "; tasks: " + ", ".join(f"{n} {s}" for s, n in sorted(status.items()))
        secs = finite([t.seconds for t in tasks])
        if secs:
            summary += f"; {sum(secs):.1f} s of computation"
    page.para(summary + ".")
    if src.meta:
        page.heading("Batch settings", level=3)
        page.add(key_value_table({k: _meta_value(k, v) for k, v in src.meta.items()},
                                 cls="meta"))

    page.heading("Videos", level=2, anchor="videos")
    rows = []
    for v in src.videos:
        c = Counter(t.status for t in v.tasks)
        methods = sorted({t.method for t in v.tasks if t.method})
        rows.append((v.name, v.kind, ", ".join(methods) or "—", len(v.files),
                     c.get("done", 0) if v.tasks else "—", c.get("failed", 0) if v.tasks else "—",
                     c.get("pending", 0) + c.get("running", 0) if v.tasks else "—",
                     sum(finite([t.seconds for t in v.tasks])) if v.tasks else None))
    page.add(table(("video", "kind", "method", "outputs", "done", "failed",
                    "pending/running", "seconds"), rows, n_text=3, cls="videos"))

    failed = [t for t in tasks if t.status == "failed"]
    if failed:
        page.heading(f"Failed tasks ({len(failed)})", level=2, anchor="failed")
        frows = [(t.task_id, t.name or "—", _frames_text(t.frames), t.attempts, t.error or "")
                 for t in failed[:MAX_FAILED_ROWS]]
        page.add(table(("task", "video", "frames", "attempts", "error"), frows, n_text=5,
                       cls="failed"))
        if len(failed) > MAX_FAILED_ROWS:
            page.para(f"… and {len(failed) - MAX_FAILED_ROWS} more failed tasks.")
    missing = [t for t in tasks if t.status == "done" and t.output
               and not (src.root / t.output).is_file()]
    if missing:
        page.add(f'<p class="warn">{len(missing)} tasks are marked done but their output is '
                 f"missing, e.g. {esc(missing[0].output)}.</p>")

    for v in src.videos:
        page.heading(f"{v.name} ({'flow' if v.kind == 'flow' else 'trajectories'})", level=2)
        _video_params(page, v)
        if not v.files:
            page.para("No output file yet.")
            continue
        if v.kind == "flow":
            problems = _flow_thumbnails(page, v, max_frames)
        else:
            problems = _track_video(page, v, max_frames)
        if problems:
            page.add('<p class="warn">Unreadable outputs: '
                     + "; ".join(esc(p) for p in problems) + "</p>")


def _meta_value(key: str, value: str) -> str:
    """A ``meta`` value for display: POSIX times of time-like keys as UTC dates."""
    if key in ("created", "updated", "started", "finished"):
        try:
            t = float(value)
        except ValueError:
            return value
        if 1e9 < t < 1e10:
            stamp = datetime.datetime.fromtimestamp(t, datetime.UTC)
            return stamp.strftime("%Y-%m-%d %H:%M:%S UTC")
    return value


def _frames_text(frames: list[int] | None) -> str:
    if not frames:
        return "—"
    if len(frames) <= 3:
        return ", ".join(map(str, frames))
    return f"{frames[0]}–{frames[-1]} ({len(frames)})"


# --------------------------------------------------------------------------- bench CSV

#: Columns that name a group of rows (one table per value).
_GROUP_COLUMNS = ("set", "suite", "dataset")
#: Columns that identify a sequence within a group, in label order.
_ID_COLUMNS = ("sequence", "scene", "variant", "split", "family", "seed", "pair", "window")
#: Descriptive columns left out of labels and summaries (shown in the full rows).
_DESCRIPTIVE = frozenset({"method", "kind", "motion", "shared", "frames", "ref", "ref_index",
                          "book_tv_aee", "book_aee", "mean_motion", "max_motion", "occluded",
                          "seconds"})
#: Metric columns in display order, with units (others numeric columns follow).
_METRICS = {"aee": "px", "aee_noc": "px", "aae": "deg", "epe": "px", "far_epe": "px",
            "rms": "px", "r1": "%", "r3": "%", "occ_accuracy": "", "hidden_recall": ""}


def _numeric(rows: Sequence[dict[str, Any]], column: str) -> bool:
    values = [r.get(column) for r in rows if r.get(column) is not None]
    return bool(values) and all(isinstance(v, float) for v in values)


def _label(row: dict[str, Any], id_cols: Sequence[str]) -> str:
    parts = []
    for c in id_cols:
        v = row.get(c)
        if v is None:
            continue
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        parts.append(str(v))
    return " / ".join(parts) or "(all)"


def _bench(page: Page, src: BenchTable) -> None:
    rows = src.rows
    cols = src.columns
    primary = "aee" if finite([r.get("aee") for r in rows]) else "epe"
    group_col = next((c for c in _GROUP_COLUMNS if any(r.get(c) is not None for r in rows)), None)
    id_cols = [c for c in _ID_COLUMNS if c in cols and any(r.get(c) is not None for r in rows)]
    id_cols += [c for c in cols if c not in id_cols and c not in _DESCRIPTIVE
                and c not in _METRICS and c not in _GROUP_COLUMNS and not _numeric(rows, c)
                and any(r.get(c) is not None for r in rows)]
    metrics = [m for m in _METRICS if m in cols and finite([r.get(m) for r in rows])]
    metrics += [c for c in cols if c not in metrics and c not in _DESCRIPTIVE
                and c not in id_cols and c not in _GROUP_COLUMNS and _numeric(rows, c)
                and finite([r.get(c) for r in rows])]
    methods = list(dict.fromkeys(str(r["method"]) for r in rows if r.get("method") is not None))
    unit = _METRICS.get(primary, "")
    page.para(f"{len(rows)} rows, {len(methods)} methods; main error measure: "
              f"{primary.upper()} ({unit}), lower is better; best per row in bold.")

    # per-method summary
    page.heading("Summary per method", level=2, anchor="summary")
    srows = []
    means: dict[str, float] = {}
    secs: dict[str, float] = {}
    for m in methods:
        mine = [r for r in rows if r.get("method") == m]
        vals = {k: finite([r.get(k) for r in mine]) for k in metrics}
        s = finite([r.get("seconds") for r in mine])
        means[m] = float(np.mean(vals[primary])) if vals.get(primary) else math.nan
        secs[m] = float(np.mean(s)) if s else math.nan
        srows.append([m, len(mine)] + [float(np.mean(vals[k])) if vals[k] else None
                                       for k in metrics]
                     + [secs[m] if s else None, float(sum(s)) if s else None])
    header = ["method", "rows"] + [f"mean {k} {_METRICS.get(k, '')}".strip() for k in metrics]
    header += ["mean s", "total s"]
    best_col = 2 + metrics.index(primary) if primary in metrics else None
    best = None
    if best_col is not None:
        good = finite(list(means.values()))
        best = [{best_col} if good and math.isfinite(means[m]) and means[m] == min(good)
                else set() for m in methods]
    page.add(table(header, srows, best=best, cls="summary"))
    page.add('<div class="thumbs"><figure>'
             + bar_chart_svg(methods, [means[m] for m in methods], unit=unit,
                             title=f"mean {primary.upper()} per method")
             + "</figure><figure>"
             + bar_chart_svg(methods, [secs[m] for m in methods], unit="s",
                             title="mean seconds per row")
             + "</figure></div>")

    # per-sequence tables, one per group
    groups: dict[Any, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(r.get(group_col) if group_col else None, []).append(r)
    for g, grows in groups.items():
        title = f"{group_col} {g}" if group_col and g is not None else "Per sequence"
        page.heading(title if group_col else "Per sequence", level=2)
        gmetric = primary if finite([r.get(primary) for r in grows]) else next(
            (m for m in metrics if finite([r.get(m) for r in grows])), primary)
        gid = [c for c in id_cols if any(r.get(c) is not None for r in grows)]
        gmethods = list(dict.fromkeys(str(r["method"]) for r in grows
                                      if r.get("method") is not None))
        cells: dict[str, dict[str, list[float]]] = {}
        for r in grows:
            cells.setdefault(_label(r, gid), {}).setdefault(str(r.get("method")), []).extend(
                finite([r.get(gmetric)]))
        trows = []
        best_sets = []
        for lab, per in cells.items():
            vals = [float(np.mean(per[m])) if per.get(m) else None for m in gmethods]
            trows.append([lab, *vals])
            good = [v for v in vals if v is not None]
            best_sets.append({1 + j for j, v in enumerate(vals) if good and v == min(good)}
                             if len(good) > 1 else set())
        mean_row: list[Any] = ["mean"]
        for j in range(len(gmethods)):
            col = [r[1 + j] for r in trows if r[1 + j] is not None]
            mean_row.append(float(np.mean(col)) if col else None)
        trows.append(mean_row)
        best_sets.append(set())
        page.para(f"{gmetric.upper()} ({_METRICS.get(gmetric, '')}) per "
                  f"{' / '.join(gid) or 'row'} and method.")
        page.add(table([" / ".join(gid) or "row", *gmethods], trows, best=best_sets,
                       summary_rows=1, cls="sequences"))
        shown = [c for c in cols if any(r.get(c) is not None for r in grows)]
        page.add(f"<details><summary>all {len(grows)} rows</summary>")
        page.add(table(shown, ([r.get(c) for c in shown] for r in grows), n_text=0,
                       cls="rows"))
        page.add("</details>")


# --------------------------------------------------------------------------- single files


def _row_side(n_images: int) -> int:
    """Longer side of each of the ``n_images`` images of the single-flow row."""
    return max(THUMB_SIDE, min(LARGE_SIDE, ROW_WIDTH // max(1, n_images)))


def _photometric(frame0: np.ndarray, frame1: np.ndarray,
                 flow: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Frame 1 warped back by the flow, where it lands inside, and the photometric error.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, 3), float in [0, 1]
    flow : ndarray, shape (H, W, 2)
        From frame 0 to frame 1.

    Returns
    -------
    warped : ndarray, shape (H, W, 3), float32
        ``frame1(x + w(x))``, bilinear (:func:`varflow.ops.warp.warp_bilinear`).
    inside : ndarray, shape (H, W), bool
        Where ``x + w(x)`` is known and inside frame 1.
    error : float
        Mean absolute difference between ``warped`` and ``frame0`` over ``inside``
        (and the channels), on 0–255; NaN when no pixel lands inside.
    """
    from ..ops.warp import warp_bilinear

    known = np.isfinite(flow).all(axis=2) & (np.abs(flow) <= 1e9).all(axis=2)
    uv = np.where(known[..., None], flow, 0.0).astype(np.float32)
    warped, inside = warp_bilinear(frame1, uv)
    inside &= known
    if not inside.any():
        return warped, inside, math.nan
    diff = np.abs(warped[inside].astype(np.float64) - frame0[inside])
    return warped, inside, 255.0 * float(diff.mean())


def _single_flow(page: Page, path: Path, gt_path: PathArg | None,
                 frame_paths: Sequence[Path] = ()) -> None:
    from ..evaluation.metrics import endpoint_error_map, evaluate
    from ..io import read_flow
    from ..viz.colorwheel import flow_to_color

    flow = read_flow(path)
    shape = flow.shape[:2]
    gt = None
    if gt_path is not None:
        gt = read_flow(gt_path)
        if gt.shape != flow.shape:
            raise ValueError(f"--gt: {gt_path} is {_size(gt.shape)} px, the flow is "
                             f"{_size(flow.shape)} px")
    raw = [_read_frame_file(p, shape, "the flow") for p in frame_paths]
    try:
        frames = unit_rgb_frames(raw, [f"--frames: {p}" for p in frame_paths])
    except ValueError as exc:
        raise ValueError(error_line(exc)) from exc
    del raw
    # one row: frame 0, frame 1, frame 1 warped back, estimate, ground truth, error map
    n_row = len(frames) + (len(frames) == 2) + 1 + (2 if gt is not None else 0)
    side = _row_side(n_row)
    scale = _max_magnitude([gt if gt is not None else flow])
    img = downscale(flow_to_color(flow, max_radius=scale), side)
    mean, top, unknown = _flow_stats(flow)
    which = "ground truth" if gt is not None else "flow"
    page.para(f"One colour scale: full saturation at {scale:.4g} px (the largest |w| of the "
              f"{which}); {_size_note(flow.shape, img.shape)}.", cls="note scale")
    figs = []
    for k, (p, frame) in enumerate(zip(frame_paths, frames, strict=True)):
        figs.append(page.image(downscale(to_uint8(frame), side), role=f"frame{k}",
                               caption=f"frame {k}: {p.name}"))
    if len(frames) == 2:
        warped, inside, photo = _photometric(frames[0], frames[1], flow)
        share = 100.0 * float(inside.mean())
        wimg = downscale(grey_outside(to_uint8(warped), inside), side)
        err_text = f"{photo:.2f}" if math.isfinite(photo) else "n/a"
        figs.append(page.image(
            wimg, role="warped",
            caption=f"frame 1 warped back by the estimate; photometric error {err_text} "
                    f"(mean |difference| to frame 0 on 0–255) over the {share:.1f} % of "
                    f"pixels that land inside",
            extra={"photometric": f"{photo:.6g}", "inside": f"{share / 100.0:.6g}"}))
        del warped
    figs.append(page.image(img, role="flow", caption=f"estimate {path.name}",
                           extra={"scale": f"{scale:.6g}"}))
    if gt is not None:
        gimg = downscale(flow_to_color(gt, max_radius=scale), side)
        figs.append(page.image(gimg, role="gt", caption=f"ground truth {Path(gt_path).name}",
                               extra={"scale": f"{scale:.6g}"}))
    figs.append(_legend(page, scale))
    vmax = 1.0
    if gt is not None:
        epe = endpoint_error_map(flow, gt)
        known = epe[np.isfinite(epe)]
        vmax = max(1.0, float(np.percentile(known, 99))) if known.size else 1.0
        emap = downscale(error_map(epe, vmax), side)
        bar = error_colorbar(256, 14)
        figs += [page.image(emap, role="error", caption="endpoint error",
                            extra={"vmax": f"{vmax:.6g}"}),
                 page.image(bar, role="colorbar", caption=f"0 px … {vmax:.3g} px",
                            extra={"vmax": f"{vmax:.6g}"})]
    # everything side by side, in one row
    page.add('<div class="thumbs row">' + "".join(figs) + "</div>")
    if frames:
        text = (f"Input frames {', '.join(p.name for p in frame_paths)} at the size of the "
                f"flow images")
        if len(frames) == 2:
            text += ("; frame 1 warped back by the estimate (bilinear) should look like frame "
                     "0 where the flow is right: its photometric error is the mean absolute "
                     "difference to frame 0 on 0–255 over the pixels whose target lands "
                     "inside frame 1 (grey: outside or no estimate), a check that needs no "
                     "ground truth")
        else:
            text += " (--frames F0 F1 adds frame 1 warped back by the estimate)"
        page.para(text + ".", cls="note frames")
    if gt is None:
        page.add(table(("size", "mean |w| px", "max |w| px", "unknown %"),
                       [(_size(flow.shape), mean, top, unknown)], cls="stats"))
        page.para("No ground truth given (--gt GT.flo adds the error map and AEE/AAE/RMS/R1/R3).")
        return
    page.para(f"Endpoint error map: dark blue 0 px to yellow {vmax:.3g} px (the 99th "
              f"percentile, at least 1 px; larger errors clipped); grey: no ground truth or "
              f"estimate; {_size_note(flow.shape, emap.shape)}.")
    page.add(table(("size", "mean |w| px", "max |w| px", "unknown %"),
                   [(_size(flow.shape), mean, top, unknown)], cls="stats"))
    scores = evaluate(flow, gt)
    page.heading("Error against the ground truth", level=2, anchor="error")
    labels = (("aee", "AEE", "px"), ("aae", "AAE", "deg"), ("rms", "RMS", "px"),
              ("r1", "R1", "% EPE > 1 px"), ("r3", "R3", "% EPE > 3 px"),
              ("r5", "R5", "% EPE > 5 px"), ("missing", "missing", "% without estimate"))
    page.add(table(("measure", "value", "unit"),
                   [(lab, scores[k], u) for k, lab, u in labels if k in scores], n_text=1,
                   cls="metrics"))


def _single_trajectories(page: Page, path: Path, frames: Path | None,
                         max_frames: int) -> None:
    from ..io.trajectories import read_trajectories

    tf = read_trajectories(path)
    traj, ref = tf.trajectories, tf.ref
    n_f, h, w = traj.shape[:3]
    background, note = _read_reference(frames, ref, tf.metadata, (h, w))
    meta = dict(tf.metadata)
    params = meta.pop("params", None)
    method = meta.pop("method", None)
    extra: dict[str, Any] = {"frames": n_f, "size": _size((h, w)), "reference frame": ref}
    listed = meta.pop("frames", None)
    if isinstance(listed, list) and listed:
        extra["input"] = str(listed[0]) if len(listed) == 1 else (
            f"{listed[0]} … {listed[-1]} ({len(listed)} files)")
    for k, v in meta.items():
        extra[str(k)] = v
    _params_block(page, method if isinstance(method, str) else None,
                  params if isinstance(params, dict) else None, extra)
    scale = _max_magnitude([traj.reshape(-1, 1, 2)])
    _trajectory_block(page, traj, ref, tf.visibility, scale=scale, max_frames=max_frames,
                      plot_side=LARGE_SIDE, thumb_side=THUMB_SIDE, background=background,
                      background_note=note, label=path.name)


# --------------------------------------------------------------------------- entry points


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
        _batch(page, load_batch(src), max_frames)
    elif kind == "bench":
        _bench(page, load_bench_csv(src))
    elif kind == "flow":
        _single_flow(page, src, gt, frame_paths)
    else:
        _single_trajectories(page, src, frame_paths[0] if frame_paths else None, max_frames)
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
