"""What every kind of report shares: image sizes, the colour scale, the legend, tables.

The sizes of thumbnails and single images, the largest known flow magnitude that
sets one colour scale per video (:func:`max_magnitude`), flow statistics, size
notes, the colour-wheel legend, the method and parameter block, and the reading of
the files shown (:func:`read_chosen`) and of input frames given with ``--frames``
(:func:`read_frame_file`).  See :mod:`varflow.report.build` for the layout rules.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import error_line
from .html import Page, key_value_table
from .sources import Video

__all__ = ["LARGE_SIDE", "LEGEND_SIDE", "ROW_WIDTH", "THUMB_SIDE", "WINDOW_THUMB_SIDE",
           "PathArg", "flow_stats", "legend", "max_magnitude", "params_block",
           "read_chosen", "read_frame_file", "size_note", "size_text"]

logger = logging.getLogger(__name__)


#: Longer side of thumbnails and of single images, in pixels.
THUMB_SIDE = 256
LARGE_SIDE = 640
#: Width shared by the images of the single-flow row (see :mod:`varflow.report.build`).
ROW_WIDTH = 1280
#: Side of the colour-wheel legend image.
LEGEND_SIDE = 101
#: Thumbnails of the frames of trajectory windows in a batch folder.
WINDOW_THUMB_SIDE = 160


PathArg = str | os.PathLike[str]


def _magnitude(flow: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        mag = np.hypot(flow[..., 0].astype(np.float64), flow[..., 1].astype(np.float64))
        mag[~np.isfinite(mag) | (mag > 1e9)] = np.nan
    return mag


def max_magnitude(arrays: Sequence[np.ndarray]) -> float:
    """Largest known magnitude over flows; 1.0 when there is none or all are zero."""
    top = 0.0
    for a in arrays:
        m = _magnitude(a)
        if np.isfinite(m).any():
            top = max(top, float(np.nanmax(m)))
    return top * (1.0 + 1e-5) if top > 0 else 1.0


def flow_stats(flow: np.ndarray) -> tuple[float, float, float]:
    """(mean |w|, max |w|, unknown %) of a flow."""
    m = _magnitude(flow)
    known = np.isfinite(m)
    if not known.any():
        return math.nan, math.nan, 100.0
    return float(m[known].mean()), float(m[known].max()), 100.0 * float(1.0 - known.mean())


def size_text(shape: Sequence[int]) -> str:
    """``"W×H"`` of an array shape ``(H, W, ...)``."""
    return f"{shape[1]}×{shape[0]}"


def size_note(orig: Sequence[int], shown: Sequence[int]) -> str:
    """``"W×H px (full size)"``, or the original and the shown size of a downscaled image."""
    if tuple(orig[:2]) == tuple(shown[:2]):
        return f"{size_text(orig)} px (full size)"
    return f"{size_text(orig)} px shown at {size_text(shown)}"


def legend(page: Page, scale: float) -> str:
    """The colour-wheel legend with its rim at ``scale`` px, as a figure of ``page``."""
    from ..viz.colorwheel import color_wheel_legend

    return page.image(color_wheel_legend(LEGEND_SIDE), role="legend",
                      caption=f"colour wheel, rim = {scale:.4g} px",
                      alt=f"colour wheel: direction = hue, |w| = {scale:.4g} px at the rim "
                          f"(full saturation), darker beyond",
                      extra={"scale": f"{scale:.6g}"})


def params_block(page: Page, method: str | None, params: dict[str, Any] | None,
                 extra: dict[str, Any] | None = None) -> None:
    """Add the method and ``extra`` items, then the parameters (a ``<details>``), to ``page``."""
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


def read_chosen(video: Video, chosen: Sequence[int],
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


def read_frame_file(path: Path, shape: tuple[int, int], against: str) -> np.ndarray:
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
        raise ValueError(f"--frames: {path} is {size_text(img.shape)} px, {against} "
                         f"{'are' if against.endswith('s') else 'is'} {size_text(shape)} px")
    return img
