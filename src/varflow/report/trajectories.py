"""The report of trajectories: the windows of a batch folder and a trajectory file.

:func:`track_video` shows the trajectory windows of one batch video;
:func:`report_trajectories` shows a single trajectory ``.npz`` over its reference
frame.  Both draw the tracks of a grid of points, the displacement of evenly spaced
frames and the visibility.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from .common import (
    LARGE_SIDE,
    THUMB_SIDE,
    WINDOW_THUMB_SIDE,
    flow_stats,
    legend,
    max_magnitude,
    params_block,
    read_chosen,
    read_frame_file,
    size_note,
    size_text,
)
from .figures import downscale, neutral_background, visibility_image
from .html import Page, table
from .sources import Video, evenly_spaced

__all__ = ["report_trajectories", "track_video"]

logger = logging.getLogger(__name__)


#: Largest F * H * W (after enlarging) of a trajectory plot drawn enlarged.
_MAX_PLOT_VALUES = 8_000_000


def _read_reference(frames: Path | None, ref: int,
                    metadata: dict[str, Any], shape: tuple[int, int]) -> tuple[Any, str]:
    """The reference frame to draw on, and a note saying where it came from."""
    from ..io import read_image

    if frames is not None:
        p = frames
        if p.is_dir():
            from ..io.sequences import list_frame_files

            files = list_frame_files(p)
            if not 0 <= ref < len(files):
                raise ValueError(f"--frames: {p} has {len(files)} images, the reference frame "
                                 f"is number {ref}")
            p = files[ref]
        img = read_frame_file(p, shape, "the trajectories")
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
              f"reference positions; {size_note((h, w), plot.shape)}.")
    page.add('<div class="thumbs">' + page.image(
        plot, role="trajectories", caption=f"trajectories, {label}", extra={"ref": ref})
        + legend(page, scale) + "</div>")

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
        mean, top, unknown = flow_stats(traj[n])
        row: list[Any] = [tag, mean, top, unknown]
        if visibility is not None:
            vis.append(page.image(downscale(visibility_image(visibility[n]), thumb_side),
                                  role="visibility", caption=tag, extra={"frame": n}))
            row.append(100.0 * float(visibility[n].mean()))
        rows.append(row)
    page.para(f"Displacement relative to reference frame {ref}: {len(chosen)} of {n_f} frames, "
              f"evenly spaced; one colour scale, full saturation at {scale:.4g} px; "
              f"{size_note((h, w), shown)}.", cls="note scale")
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


def track_video(page: Page, video: Video, max_frames: int) -> list[str]:
    """Add the trajectory windows of a batch video to ``page``; returns problems
    (unreadable files)."""
    from ..io.trajectories import read_trajectories

    chosen = evenly_spaced(len(video.files), max(1, max_frames // 4))
    loaded, problems = read_chosen(video, chosen, read_trajectories)
    if not loaded:
        page.para("No readable trajectory window.")
        return problems
    scale = max_magnitude([tf.trajectories.reshape(-1, 1, 2) for _, tf in loaded])
    page.para(f"Showing {len(loaded)} of {len(video.files)} trajectory windows, evenly spaced; "
              f"one colour scale for the video: full saturation at {scale:.4g} px (the largest "
              f"displacement of the windows shown).", cls="note scale")
    for i, tf in loaded:
        page.heading(video.labels[i], level=4)
        if tf.metadata and not video.tasks:
            params_block(page, tf.metadata.get("method"), tf.metadata.get("params"))
        h, w = tf.trajectories.shape[1:3]
        _trajectory_block(page, tf.trajectories, tf.ref, tf.visibility, scale=scale,
                          max_frames=max_frames, plot_side=2 * WINDOW_THUMB_SIDE,
                          thumb_side=WINDOW_THUMB_SIDE, background=neutral_background(h, w),
                          background_note="on a neutral background", label=video.labels[i])
    return problems


def report_trajectories(page: Page, path: Path, frames: Path | None,
                        max_frames: int) -> None:
    """Add the report of a single trajectory file (over ``frames``, the reference) to
    ``page``."""
    from ..io.trajectories import read_trajectories

    tf = read_trajectories(path)
    traj, ref = tf.trajectories, tf.ref
    n_f, h, w = traj.shape[:3]
    background, note = _read_reference(frames, ref, tf.metadata, (h, w))
    meta = dict(tf.metadata)
    params = meta.pop("params", None)
    method = meta.pop("method", None)
    extra: dict[str, Any] = {"frames": n_f, "size": size_text((h, w)), "reference frame": ref}
    listed = meta.pop("frames", None)
    if isinstance(listed, list) and listed:
        extra["input"] = str(listed[0]) if len(listed) == 1 else (
            f"{listed[0]} … {listed[-1]} ({len(listed)} files)")
    for k, v in meta.items():
        extra[str(k)] = v
    params_block(page, method if isinstance(method, str) else None,
                 params if isinstance(params, dict) else None, extra)
    scale = max_magnitude([traj.reshape(-1, 1, 2)])
    _trajectory_block(page, traj, ref, tf.visibility, scale=scale, max_frames=max_frames,
                      plot_side=LARGE_SIDE, thumb_side=THUMB_SIDE, background=background,
                      background_note=note, label=path.name)
