"""The report of flow results: the flow videos of a batch folder and a single flow file.

:func:`flow_thumbnails` shows the flows of one batch video, evenly spaced, each beside
the first frame of its pair read from the recorded input; :func:`report_flow` shows a
single ``.flo``/KITTI ``.png`` flow in one row with its input frames, frame 1 warped
back with the photometric error, the ground truth and the error map.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from .._errors import error_line
from .common import (
    LARGE_SIDE,
    ROW_WIDTH,
    THUMB_SIDE,
    PathArg,
    flow_stats,
    legend,
    max_magnitude,
    read_chosen,
    read_frame_file,
    size_note,
    size_text,
)
from .figures import downscale, error_colorbar, error_map, grey_outside, to_uint8, unit_rgb_frames
from .html import Page, table
from .sources import Video, evenly_spaced

__all__ = ["flow_thumbnails", "report_flow"]

logger = logging.getLogger(__name__)


#: Largest number of bytes of decoded video frames held at once (batch input frames).
_FRAME_CHUNK_BYTES = 256 * 2**20


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
    from ..io.sequences import list_frame_files
    from ..io.video_reader import VideoReader

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


def flow_thumbnails(page: Page, video: Video, max_frames: int) -> list[str]:
    """Thumbnails of a flow video, each beside its first input frame when the input
    can be read; returns problems (unreadable flow files)."""
    from ..io import read_flow
    from ..viz.colorwheel import flow_to_color

    chosen = evenly_spaced(len(video.files), max_frames)
    flows, problems = read_chosen(video, chosen, read_flow)
    if not flows:
        page.para("No readable flow file.")
        return problems
    scale = max_magnitude([f for _, f in flows])
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
        stats.append((video.labels[i], *flow_stats(flow)))
    orig = sorted(shapes)[0]
    sizes = size_note(orig, shown_size) if len(shapes) == 1 else (
        f"sizes {', '.join(size_text(s) for s in sorted(shapes))} px, longer side at most "
        f"{THUMB_SIDE} px")
    page.para(f"Showing {len(flows)} of {len(video.files)} flows, evenly spaced; one colour "
              f"scale for the video: full saturation at {scale:.4g} px (the largest |w| of the "
              f"flows shown); {sizes}.", cls="note scale")
    page.para(input_note, cls="note frames")
    page.add('<div class="thumbs">' + legend(page, scale) + "".join(thumbs) + "</div>")
    page.add("<details><summary>magnitudes of the flows shown</summary>")
    page.add(table(("flow", "mean |w| px", "max |w| px", "unknown %"), stats))
    page.add("</details>")
    return problems


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


def report_flow(page: Page, path: Path, gt_path: PathArg | None,
                frame_paths: Sequence[Path] = ()) -> None:
    """Add the report of a single flow file (with ``--gt`` and ``--frames``) to ``page``."""
    from ..evaluation.metrics import endpoint_error_map, evaluate
    from ..io import read_flow
    from ..viz.colorwheel import flow_to_color

    flow = read_flow(path)
    shape = flow.shape[:2]
    gt = None
    if gt_path is not None:
        gt = read_flow(gt_path)
        if gt.shape != flow.shape:
            raise ValueError(f"--gt: {gt_path} is {size_text(gt.shape)} px, the flow is "
                             f"{size_text(flow.shape)} px")
    raw = [read_frame_file(p, shape, "the flow") for p in frame_paths]
    try:
        frames = unit_rgb_frames(raw, [f"--frames: {p}" for p in frame_paths])
    except ValueError as exc:
        raise ValueError(error_line(exc)) from exc
    del raw
    # one row: frame 0, frame 1, frame 1 warped back, estimate, ground truth, error map
    n_row = len(frames) + (len(frames) == 2) + 1 + (2 if gt is not None else 0)
    side = _row_side(n_row)
    scale = max_magnitude([gt if gt is not None else flow])
    img = downscale(flow_to_color(flow, max_radius=scale), side)
    mean, top, unknown = flow_stats(flow)
    which = "ground truth" if gt is not None else "flow"
    page.para(f"One colour scale: full saturation at {scale:.4g} px (the largest |w| of the "
              f"{which}); {size_note(flow.shape, img.shape)}.", cls="note scale")
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
    figs.append(legend(page, scale))
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
                       [(size_text(flow.shape), mean, top, unknown)], cls="stats"))
        page.para("No ground truth given (--gt GT.flo adds the error map and AEE/AAE/RMS/R1/R3).")
        return
    page.para(f"Endpoint error map: dark blue 0 px to yellow {vmax:.3g} px (the 99th "
              f"percentile, at least 1 px; larger errors clipped); grey: no ground truth or "
              f"estimate; {size_note(flow.shape, emap.shape)}.")
    page.add(table(("size", "mean |w| px", "max |w| px", "unknown %"),
                   [(size_text(flow.shape), mean, top, unknown)], cls="stats"))
    scores = evaluate(flow, gt)
    page.heading("Error against the ground truth", level=2, anchor="error")
    labels = (("aee", "AEE", "px"), ("aae", "AAE", "deg"), ("rms", "RMS", "px"),
              ("r1", "R1", "% EPE > 1 px"), ("r3", "R3", "% EPE > 3 px"),
              ("r5", "R5", "% EPE > 5 px"), ("missing", "missing", "% without estimate"))
    page.add(table(("measure", "value", "unit"),
                   [(lab, scores[k], u) for k, lab, u in labels if k in scores], n_text=1,
                   cls="metrics"))
