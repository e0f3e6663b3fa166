"""Frames for flow videos: one colour scale for a whole video, side-by-side panels.

A flow video shows the flow between consecutive frame pairs.  Colours are only
comparable across the video if every frame uses the same saturation radius, so the
helpers here take ``max_radius`` explicitly; :func:`flow_max_radius` computes it
over all flows, :func:`flow_percentile_radius` robustly as a percentile of their
magnitudes (both streaming: they accept any iterable).

* :func:`flow_frame` — Middlebury colour coding (:func:`varflow.viz.flow_to_color`)
  on a given scale, unknown flow in grey, optional colour-wheel legend.
* :func:`warp_next_frame` — the next frame warped back onto the current one with
  the flow (:func:`varflow.ops.warp.warp_bicubic`) and its validity mask.
* :func:`grey_out_invalid` — flat grey over a faint copy where pixels are invalid.
* :func:`side_by_side` — ``frame | colour flow | warped next frame`` with optional
  labels above the panels.
* :func:`write_flow_video` — the above for in-memory arrays, written with
  :func:`varflow.io.video.write_video`.

Every output is an RGB ``uint8`` image; frames may be grey or RGB, ``uint8`` or
``uint16`` (shown with their top 8 bits), or float in [0, 1].
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Iterable, Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from ..ops.warp import warp_bicubic
from .colorwheel import color_wheel_legend, flow_to_color

__all__ = [
    "INVALID_GREY",
    "SCALE_PERCENTILE",
    "flow_max_radius",
    "flow_percentile_radius",
    "flow_frame",
    "to_display_rgb",
    "warp_next_frame",
    "grey_out_invalid",
    "side_by_side",
    "write_flow_video",
]

logger = logging.getLogger(__name__)

#: RGB colour of unknown flow in :func:`flow_frame`.
INVALID_GREY: tuple[int, int, int] = (128, 128, 128)
#: Flow components beyond this magnitude count as unknown (the ``.flo`` convention).
_UNKNOWN = 1e9
#: Default percentile of :func:`flow_percentile_radius`: the scale of ``varflow video``.
SCALE_PERCENTILE = 99.0
#: Magnitude histogram of :func:`flow_percentile_radius`: geometric bins of
#: ``10 ** (1 / _BINS_PER_DECADE)`` (0.23 %) from ``_LOWEST`` up; below it is "no motion".
_LOWEST = 1e-4
_BINS_PER_DECADE = 1000
_DECADES = 14  # up to 1e10, past the unknown threshold


def _known(flow: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: both components finite and below the unknown threshold."""
    with np.errstate(invalid="ignore"):
        return (np.isfinite(flow) & (np.abs(flow) <= _UNKNOWN)).all(axis=-1)


def _check_flow(flow: np.ndarray, who: str) -> np.ndarray:
    arr = np.asarray(flow)
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise ValueError(f"{who}: expected a flow of shape (H, W, 2), got {arr.shape}")
    return arr


def flow_max_radius(flows: Iterable[np.ndarray] | np.ndarray) -> float:
    """Largest known flow magnitude over many flows: one colour scale for a video.

    Parameters
    ----------
    flows : ndarray, shape (F, H, W, 2) or (H, W, 2), or iterable of (H, W, 2)
        Unknown components (NaN, inf, ``|x| > 1e9``) are ignored.

    Returns
    -------
    float
        ``max |w|`` times ``1 + 1e-5`` (so the longest vector is just inside the
        scale), or 1.0 if every flow is zero or unknown.  Always positive.
    """
    if isinstance(flows, np.ndarray) and flows.ndim == 3:
        flows = [flows]
    peak = 0.0
    for k, flow in enumerate(flows):
        f = _check_flow(flow, f"flow_max_radius (flow {k})")
        known = _known(f)
        if known.any():
            mag = np.hypot(f[..., 0][known].astype(np.float64), f[..., 1][known])
            peak = max(peak, float(mag.max()))
    return peak * (1.0 + 1e-5) if peak > 0 else 1.0


def flow_percentile_radius(
    flows: Iterable[np.ndarray] | np.ndarray, percentile: float = SCALE_PERCENTILE
) -> float:
    """A percentile of the known flow magnitudes of many flows: a robust colour scale.

    A few wrong vectors (occlusions, borders, a pair across a scene cut) set the
    maximum of :func:`flow_max_radius` and leave every other frame almost white; a
    high percentile ignores them, and the longer vectors are shown darkened
    (:func:`flow_frame`).

    Parameters
    ----------
    flows : ndarray, shape (F, H, W, 2) or (H, W, 2), or iterable of (H, W, 2)
        Unknown components (NaN, inf, ``|x| > 1e9``) are ignored, so a flow of NaN
        (a pair without a flow) does not count.
    percentile : float, default :data:`SCALE_PERCENTILE`
        In ``(0, 100]``, over all known pixels of all flows together.

    Returns
    -------
    float
        The percentile, from a histogram of the magnitudes: at most 0.25 % above
        the exact value (the upper edge of its bin), never above the maximum.  When
        it is 0 (magnitudes below 1e-4 px count as no motion), the maximum; 1.0 if
        every flow is zero or unknown.  Always positive.

    Raises
    ------
    ValueError
        If ``percentile`` is outside ``(0, 100]`` or a flow is not ``(H, W, 2)``.
    """
    q = float(percentile)
    if not (0.0 < q <= 100.0):
        raise ValueError(f"flow_percentile_radius: percentile must be in (0, 100], got {q!r}")
    if isinstance(flows, np.ndarray) and flows.ndim == 3:
        flows = [flows]
    n_bins = _DECADES * _BINS_PER_DECADE
    counts = np.zeros(n_bins + 1, np.int64)  # counts[0]: below _LOWEST
    peak = 0.0
    for k, flow in enumerate(flows):
        f = _check_flow(flow, f"flow_percentile_radius (flow {k})")
        known = _known(f)
        if not known.any():
            continue
        mag = np.hypot(f[..., 0][known].astype(np.float64), f[..., 1][known])
        peak = max(peak, float(mag.max()))
        moving = mag >= _LOWEST
        idx = np.floor(np.log10(mag[moving] / _LOWEST) * _BINS_PER_DECADE).astype(np.int64)
        counts += np.bincount(np.minimum(idx, n_bins - 1) + 1, minlength=n_bins + 1)
        counts[0] += int(mag.size - moving.sum())
    total = int(counts.sum())
    if total == 0 or peak == 0.0:
        return 1.0
    rank = math.ceil(q / 100.0 * total)  # the rank-th smallest magnitude (1-based)
    b = int(np.searchsorted(np.cumsum(counts), rank))
    if b == 0:
        return peak * (1.0 + 1e-5)
    upper = _LOWEST * 10.0 ** (b / _BINS_PER_DECADE)
    return min(upper, peak * (1.0 + 1e-5))


def flow_frame(
    flow: np.ndarray,
    max_radius: float,
    *,
    legend: bool = False,
    invalid_color: Sequence[int] = INVALID_GREY,
) -> np.ndarray:
    """Colour-code one flow of a video on a fixed scale.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
        u = ``[..., 0]``, v = ``[..., 1]``; NaN where unknown.
    max_radius : float
        Magnitude of full saturation, the same for every frame of the video
        (:func:`flow_max_radius`); longer vectors are darkened.
    legend : bool, default False
        Paste a colour-wheel legend (side ``min(H, W) // 4``, if at least 8 px) in
        the top-right corner.
    invalid_color : sequence of 3 ints, default mid grey
        Colour of unknown pixels.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
    """
    f = _check_flow(flow, "flow_frame")
    if not (math.isfinite(max_radius) and max_radius > 0):
        raise ValueError(f"flow_frame: max_radius must be positive, got {max_radius!r}")
    img = flow_to_color(f, max_radius=max_radius, unknown_color=invalid_color)
    if legend:
        h, w = img.shape[:2]
        size = min(h, w) // 4
        if size >= 8:
            img[:size, w - size :] = color_wheel_legend(size, max_radius=max_radius)
    return img


def to_display_rgb(frame: np.ndarray) -> np.ndarray:
    """Convert a frame to RGB ``uint8`` for display.

    Parameters
    ----------
    frame : ndarray, shape (H, W), (H, W, 1) or (H, W, 3)
        ``uint8``, ``uint16`` (top 8 bits kept) or float in [0, 1] (clipped).

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
    """
    arr = np.asarray(frame)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"to_display_rgb: expected (H, W) or (H, W, 3), got {arr.shape}")
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr)
    if arr.dtype == np.uint16:
        return (arr >> 8).astype(np.uint8)
    if np.issubdtype(arr.dtype, np.floating):
        return np.clip(np.rint(np.nan_to_num(arr) * 255.0), 0, 255).astype(np.uint8)
    raise ValueError(f"to_display_rgb: unsupported dtype {arr.dtype}")


def warp_next_frame(next_frame: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Warp the next frame back onto the current one with the flow.

    Parameters
    ----------
    next_frame : ndarray, shape (H, W) or (H, W, 3)
        Frame ``I1``; any dtype :func:`to_display_rgb` accepts.
    flow : ndarray, shape (H, W, 2)
        Flow from the current frame ``I0`` to ``I1``.

    Returns
    -------
    warped : ndarray, shape (H, W, 3), uint8
        ``I1(x + w(x))`` (bicubic); should look like ``I0`` where the flow is right.
    valid : ndarray, shape (H, W), bool
        False where the flow is unknown or points outside the image.
    """
    f = _check_flow(flow, "warp_next_frame")
    rgb = to_display_rgb(next_frame)
    if rgb.shape[:2] != f.shape[:2]:
        raise ValueError(
            f"warp_next_frame: frame {rgb.shape[:2]} and flow {f.shape[:2]} differ in size"
        )
    known = _known(f)
    uv = np.where(known[..., None], f, 0.0).astype(np.float32)
    warped, inside = warp_bicubic(rgb.astype(np.float32), uv)
    out = np.clip(np.rint(warped), 0, 255).astype(np.uint8)
    return out, inside & known


def grey_out_invalid(image: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Show invalid pixels as flat grey over a faint copy of the image.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3) or (H, W), uint8
    valid : ndarray, shape (H, W), bool

    Returns
    -------
    ndarray, same shape, uint8
        ``image`` where valid, ``round(0.25 image + 96)`` elsewhere.
    """
    img = np.asarray(image)
    ok = np.asarray(valid, dtype=bool)
    if img.dtype != np.uint8 or img.shape[:2] != ok.shape:
        raise ValueError(
            f"grey_out_invalid: need a uint8 image and an (H, W) mask, got {img.shape} "
            f"{img.dtype} and {ok.shape}"
        )
    out = img.copy()
    bad = ~ok
    out[bad] = np.rint(0.25 * img[bad].astype(np.float32) + 96.0).astype(np.uint8)
    return out


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType: fixed bitmap font
        return ImageFont.load_default()


def _label_bar(texts: Sequence[str], widths: Sequence[int], gap: int, height: int) -> np.ndarray:
    total = sum(widths) + gap * (len(widths) - 1)
    bar = Image.new("RGB", (total, height), (0, 0, 0))
    draw = ImageDraw.Draw(bar)
    font = _font(max(8, height - 4))
    x = 0
    for text, w in zip(texts, widths, strict=True):
        draw.text((x + 3, 1), text, fill=(255, 255, 255), font=font)
        x += w + gap
    return np.asarray(bar)


def side_by_side(
    frame: np.ndarray,
    flow: np.ndarray,
    next_frame: np.ndarray,
    max_radius: float,
    *,
    labels: Sequence[str] | bool = True,
    legend: bool = True,
    gap: int = 4,
) -> np.ndarray:
    """Compose ``frame | colour flow | warped next frame`` into one image.

    Parameters
    ----------
    frame, next_frame : ndarray, shape (H, W) or (H, W, 3)
        The pair ``I0``, ``I1`` (any dtype of :func:`to_display_rgb`).
    flow : ndarray, shape (H, W, 2)
        Flow from ``I0`` to ``I1``.
    max_radius : float
        Colour scale shared by the video (:func:`flow_max_radius`).
    labels : sequence of 3 str or bool, default True
        Captions above the panels; True gives ``"frame"``, ``"flow (R px)"``,
        ``"next, warped"``; False or an empty sequence gives no caption bar.
    legend : bool, default True
        Colour-wheel legend in the flow panel.
    gap : int, default 4
        Black columns between panels.

    Returns
    -------
    ndarray, shape (H + B, 3 W + 2 gap, 3), uint8
        ``B`` is the caption bar height (0 without labels, else
        ``max(12, H // 12)`` rounded up to even).  Invalid pixels of the warped
        frame (unknown flow or outside the image) are greyed out, unknown flow is
        grey in the flow panel.
    """
    f = _check_flow(flow, "side_by_side")
    left = to_display_rgb(frame)
    if left.shape[:2] != f.shape[:2]:
        raise ValueError(f"side_by_side: frame {left.shape[:2]} and flow {f.shape[:2]} differ")
    if gap < 0:
        raise ValueError(f"side_by_side: gap must be >= 0, got {gap}")
    colour = flow_frame(f, max_radius, legend=legend)
    warped, valid = warp_next_frame(next_frame, f)
    right = grey_out_invalid(warped, valid)
    h, w = f.shape[:2]
    spacer = np.zeros((h, gap, 3), np.uint8)
    panels = np.concatenate([left, spacer, colour, spacer, right], axis=1)
    if labels is True:
        texts: Sequence[str] = ("frame", f"flow ({max_radius:.3g} px)", "next, warped")
    elif labels is False:
        texts = ()
    else:
        texts = tuple(labels)
    if not texts:
        return panels
    if len(texts) != 3:
        raise ValueError(f"side_by_side: labels must be 3 strings, got {len(texts)}")
    bar_h = max(12, h // 12)
    bar_h += bar_h % 2
    bar = _label_bar(texts, (w, w, w), gap, bar_h)
    return np.concatenate([bar, panels], axis=0)


def write_flow_video(
    path: str | os.PathLike[str],
    flows: np.ndarray,
    fps: float = 25.0,
    *,
    frames: np.ndarray | None = None,
    max_radius: float | None = None,
    layout: str = "flow",
    labels: bool = True,
    legend: bool = True,
    codec: str | None = None,
    quality: int | None = None,
) -> float:
    """Write colour-coded flows (or side-by-side panels) as a video, on one scale.

    Parameters
    ----------
    path : str or path-like
        Output video (see :func:`varflow.io.video.write_video`).
    flows : ndarray, shape (P, H, W, 2)
        Flow ``k`` goes from ``frames[k]`` to ``frames[k + 1]``.
    fps : float, default 25
    frames : ndarray, shape (P + 1, H, W[, 3]), optional
        Needed for ``layout="side-by-side"``.
    max_radius : float, optional
        Colour scale; default :func:`flow_max_radius` of all flows.
    layout : {"flow", "side-by-side"}
    labels, legend : bool
        Captions (side-by-side only) and colour-wheel legend.
    codec, quality : optional
        Passed to the writer.

    Returns
    -------
    float
        The colour scale used.
    """
    from ..io.video_writer import write_video

    fl = np.asarray(flows)
    if fl.ndim != 4 or fl.shape[3] != 2 or fl.shape[0] < 1:
        raise ValueError(f"write_flow_video: flows must have shape (P, H, W, 2), got {fl.shape}")
    if layout not in ("flow", "side-by-side"):
        raise ValueError(
            f"write_flow_video: layout must be 'flow' or 'side-by-side', got {layout!r}"
        )
    if layout == "side-by-side":
        if frames is None or len(frames) != len(fl) + 1:
            raise ValueError("write_flow_video: side-by-side needs frames of length P + 1")
    radius = flow_max_radius(fl) if max_radius is None else float(max_radius)

    def render():
        for k in range(len(fl)):
            if layout == "flow":
                yield flow_frame(fl[k], radius, legend=legend)
            else:
                assert frames is not None
                yield side_by_side(
                    frames[k], fl[k], frames[k + 1], radius, labels=labels, legend=legend
                )

    write_video(path, render(), fps, codec=codec, quality=quality)
    return radius
