"""Pictures of dense multi-frame trajectories (Pillow only, no Matplotlib).

* :func:`draw_tracks` draws what trajectory papers and TAP-Vid draw: a few hundred
  points, each with a coloured tail of its past positions, over one frame of the clip
  in colour; hidden parts dashed in grey, hidden points as rings; optionally with a
  legend and a title under the picture.
  :func:`track_animation` draws it for every frame (a video of the tracks).
* :func:`draw_trajectories` draws a grid of sampled trajectories as polylines over
  a dimmed grey copy of the reference frame.
* :func:`displacement_panels` tiles the Middlebury colour coding of the
  displacement in every frame, with one colour scale shared by all frames.

Trajectories follow the package convention: shape ``(F, H, W, 2)``, ``[n, y, x]``
is the displacement ``(u, v)`` of reference pixel ``(x, y)`` in frame ``n``
(u = ``[..., 0]`` rightwards, v = ``[..., 1]`` downwards), NaN where unknown; its
position in frame ``n`` is ``(x + u, y + v)``.  Pixel ``(x, y)`` of an output image
is row ``y``, column ``x``, and positions are rounded to the nearest pixel.
"""

from __future__ import annotations

import logging
import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from .._validate import as_float_image
from .colorwheel import color_wheel, flow_to_color

__all__ = ["draw_trajectories", "draw_tracks", "displacement_panels", "grey_out",
           "sample_points", "track_animation", "HIDDEN_GREY"]

logger = logging.getLogger(__name__)

#: Brightness factor of the grey reference frame under the tracks.
_DIM = 0.5
#: Positions are clipped to this many pixels (PIL draws with C ints; larger values are
#: meaningless for a picture).
_COORD_LIMIT = 1e5
#: Colour of the hidden parts of a trajectory (:func:`draw_trajectories`).
HIDDEN_GREY = (150, 150, 150)
#: Colour of the gaps between panels and of empty cells (never produced by flow_to_color).
_GAP_COLOUR = (128, 128, 128)
#: Components beyond this magnitude are unknown (the .flo 1e10 convention).
_UNKNOWN_THRESHOLD = 1e9
#: Step along the colour wheel between consecutive track indices (golden ratio).
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0

ColourBy = str | Sequence[int]


def _is_int(x: object) -> bool:
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)


def _check_traj(traj: Any, fn: str) -> np.ndarray:
    arr = np.asarray(traj)
    if arr.ndim != 4 or arr.shape[3] != 2 or min(arr.shape[:3]) < 1:
        raise ValueError(
            f"{fn}: traj must have shape (F, H, W, 2) with F, H, W >= 1, got {arr.shape}"
        )
    if arr.dtype == np.bool_ or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ):
        raise ValueError(f"{fn}: traj must be a real-valued array, got dtype {arr.dtype}")
    out = arr.astype(np.float64)
    with np.errstate(invalid="ignore"):
        out[np.abs(out) > _UNKNOWN_THRESHOLD] = np.nan
    return out


def _check_ref(ref: Any, n_frames: int, fn: str) -> int:
    if not _is_int(ref) or not 0 <= int(ref) < n_frames:
        raise ValueError(f"{fn}: ref must be an integer in 0..{n_frames - 1}, got {ref!r}")
    return int(ref)


def _check_max_radius(max_radius: Any, fn: str) -> float | None:
    if max_radius is None:
        return None
    value = float(max_radius)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{fn}: max_radius must be positive and finite, got {max_radius!r}")
    return value


def _background(reference_frame: Any, shape: tuple[int, int]) -> np.ndarray:
    """Dimmed grey RGB copy of the reference frame, ``(H, W, 3)`` uint8."""
    arr = np.asarray(reference_frame)
    if arr.shape[:2] != shape or arr.ndim not in (2, 3):
        raise ValueError(
            f"draw_trajectories: reference_frame must have shape (H, W) or (H, W, C) with "
            f"(H, W) = {shape} as in traj, got {arr.shape}"
        )
    img = as_float_image(arr, name="draw_trajectories: reference_frame")
    if img.shape[2] >= 3:
        grey = img[..., :3] @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    else:  # grey or grey + alpha
        grey = img[..., 0]
    value = np.floor(255.0 * _DIM * grey + 0.5).astype(np.uint8)
    return np.repeat(value[..., None], 3, axis=2)


def _direction_colours(disp: np.ndarray, max_radius: float | None) -> np.ndarray:
    """Middlebury colours of displacements ``(K, 2)``: hue only, or hue + saturation."""
    if max_radius is None:
        radius = np.hypot(disp[:, 0], disp[:, 1])
        unit = np.zeros_like(disp)
        moving = radius > 0
        # Slightly inside the unit circle: fully saturated but never "out of scale" dark.
        unit[moving] = disp[moving] / radius[moving, None] * (1.0 - 1e-9)
        return flow_to_color(unit[None], max_radius=1.0)[0]
    return flow_to_color(disp[None], max_radius=max_radius)[0]


def _track_colours(colour_by: ColourBy, disp: np.ndarray, max_radius: float | None) -> np.ndarray:
    """Colours ``(K, 3)`` uint8 of ``K`` tracks with overall displacements ``disp``."""
    n = disp.shape[0]
    if isinstance(colour_by, str):
        if colour_by == "direction":
            return _direction_colours(disp, max_radius)
        if colour_by == "index":
            wheel = color_wheel()
            idx = np.floor((np.arange(n) * _GOLDEN) % 1.0 * len(wheel)).astype(np.int64)
            return wheel[idx % len(wheel)]
        raise ValueError(
            f"draw_trajectories: colour_by must be 'direction', 'index' or an RGB triple, "
            f"got {colour_by!r}"
        )
    try:
        rgb = np.asarray(colour_by)
        ok = rgb.shape == (3,) and all(_is_int(c) or float(c).is_integer() for c in rgb.tolist())
        ok = ok and bool(np.all((rgb >= 0) & (rgb <= 255)))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(
            f"draw_trajectories: colour_by must be 'direction', 'index' or an RGB triple of "
            f"integers in 0..255, got {colour_by!r}"
        )
    return np.tile(rgb.astype(np.uint8), (n, 1))


def draw_trajectories(
    reference_frame: np.ndarray,
    traj: np.ndarray,
    ref: int,
    *,
    step: int = 16,
    mask: np.ndarray | None = None,
    colour_by: ColourBy = "direction",
    line_width: int = 1,
    show_points: bool = True,
    max_radius: float | None = None,
    visibility: np.ndarray | None = None,
) -> np.ndarray:
    """Draw sampled trajectories as polylines over the reference frame.

    Reference pixels are sampled on a grid every ``step`` pixels, starting at
    ``min(step // 2, (size - 1) // 2)`` along each axis (so a ``step`` larger than
    the frame still samples its centre), optionally only where ``mask`` is True.
    Each sampled pixel ``(x, y)`` becomes the polyline through its positions
    ``(x, y) + traj[n, y, x]`` for ``n = 0 .. F-1``, drawn over a grey copy of the
    reference frame dimmed to half brightness; unknown (NaN) positions break the
    line, and a dot marks the reference position ``(x, y)``.

    Parameters
    ----------
    reference_frame : ndarray, shape (H, W) or (H, W, C)
        ``uint8``, ``uint16`` or float (outside ``[0, 1]`` scaled from its range,
        see :mod:`varflow._validate`); colour frames are converted to grey (Rec. 601
        luma of the first three channels).
    traj : ndarray, shape (F, H, W, 2)
        Trajectories relative to the reference frame (see the module docstring);
        NaN, infinite or ``|value| > 1e9`` components mark unknown positions.
    ref : int
        Index of the reference frame, ``0 <= ref < F`` (validated; the reference
        position of every track is its pixel ``(x, y)``).
    step : int, default 16
        Grid spacing in pixels, ``>= 1``.
    mask : ndarray, shape (H, W), bool, optional
        Only draw tracks of sampled pixels where ``mask`` is True.
    colour_by : {"direction", "index"} or sequence of 3 ints, default "direction"
        ``"direction"``: Middlebury colour-wheel colour
        (:func:`~varflow.viz.colorwheel.flow_to_color`) of the overall displacement
        of the track, from its first to its last known position;
        ``"index"``: a distinct wheel hue per track (golden-ratio steps around the
        wheel, so neighbouring tracks differ); an RGB triple: one fixed colour.
    line_width : int, default 1
        Line width in pixels, ``>= 1``; dots have radius ``line_width + 1``.
    show_points : bool, default True
        Mark the reference position of every drawn track with a dot.
    max_radius : float, optional
        Only for ``colour_by="direction"``.  None: colour by direction alone
        (fully saturated hue).  A number: the Middlebury coding with this
        saturation radius, so short tracks are paler and tracks longer than
        ``max_radius`` are darkened.
    visibility : ndarray, shape (F, H, W), bool, optional
        Where a point is hidden (False), the segments that reach its position in
        that frame are drawn in grey (:data:`HIDDEN_GREY`) instead of the track's
        colour.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        RGB image.

    Raises
    ------
    ValueError
        On a wrong ``traj`` shape or dtype, ``reference_frame`` or ``mask`` not
        matching ``(H, W)``, ``ref`` out of range, ``step < 1``,
        ``line_width < 1``, an invalid ``colour_by`` or a non-positive
        ``max_radius`` (the message names the argument).

    Notes
    -----
    Tracks with no known position are not drawn (no dot either).  A known
    position between two unknown ones is drawn as a single point.  Positions are
    rounded to the nearest pixel and clipped to ``±1e5``.  Drawing costs one
    Pillow call per track segment, so ``step=1`` on a large frame is slow.
    """
    fn = "draw_trajectories"
    uv = _check_traj(traj, fn)
    n_frames, height, width = uv.shape[:3]
    ref = _check_ref(ref, n_frames, fn)
    if not _is_int(step) or step < 1:
        raise ValueError(f"{fn}: step must be an integer >= 1, got {step!r}")
    if not _is_int(line_width) or line_width < 1:
        raise ValueError(f"{fn}: line_width must be an integer >= 1, got {line_width!r}")
    radius = _check_max_radius(max_radius, fn)
    background = _background(reference_frame, (height, width))

    # Grid offset step // 2, but at least one sample (the centre) if step exceeds the image.
    y0, x0 = min(step // 2, (height - 1) // 2), min(step // 2, (width - 1) // 2)
    ys, xs = np.mgrid[y0:height:step, x0:width:step]
    ys, xs = ys.ravel(), xs.ravel()
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != (height, width):
            raise ValueError(
                f"{fn}: mask must have shape (H, W) = {(height, width)}, got {m.shape}"
            )
        if m.dtype != np.bool_:
            if not np.issubdtype(m.dtype, np.integer) or not np.isin(m, (0, 1)).all():
                raise ValueError(f"{fn}: mask must be boolean (or integers 0/1), got {m.dtype}")
            m = m.astype(np.bool_)
        keep = m[ys, xs]
        ys, xs = ys[keep], xs[keep]

    vis = None
    if visibility is not None:
        vis = np.asarray(visibility)
        if vis.shape != (n_frames, height, width) or vis.dtype != np.bool_:
            raise ValueError(f"{fn}: visibility must be a boolean array of shape "
                             f"{(n_frames, height, width)}, got {vis.dtype} {vis.shape}")
    track_uv = uv[:, ys, xs]  # (F, K, 2)
    known = np.isfinite(track_uv).all(axis=2)  # (F, K)
    drawn = known.any(axis=0)
    ys, xs, track_uv, known = ys[drawn], xs[drawn], track_uv[:, drawn], known[:, drawn]
    seen = None if vis is None else vis[:, ys, xs]  # (F, K)
    n_tracks = ys.size
    logger.debug("%s: %d tracks (step %d) over %d frames", fn, n_tracks, step, n_frames)

    first = np.argmax(known, axis=0)
    last = n_frames - 1 - np.argmax(known[::-1], axis=0)
    cols = np.arange(n_tracks)
    disp = track_uv[last, cols] - track_uv[first, cols]  # (K, 2)
    colours = _track_colours(colour_by, disp, radius)

    pos = np.stack([xs, ys], axis=-1)[None] + track_uv  # (F, K, 2) as (x, y)
    pos = np.rint(np.clip(np.nan_to_num(pos), -_COORD_LIMIT, _COORD_LIMIT)).astype(np.int64)

    image = Image.fromarray(background)
    draw = ImageDraw.Draw(image)
    half = (line_width - 1) / 2.0
    for k in range(n_tracks):
        fill = tuple(int(c) for c in colours[k])
        ok = known[:, k]
        # Runs of consecutive known frames: boundaries where ``ok`` changes.
        edges = np.flatnonzero(np.diff(np.concatenate([[False], ok, [False]]).astype(np.int8)))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            points = [(int(p[0]), int(p[1])) for p in pos[a:b, k]]
            if len(points) > 1 and seen is not None and not seen[a:b, k].all():
                # segment by segment: grey where either end is hidden
                for i in range(len(points) - 1):
                    ok_seg = seen[a + i, k] and seen[a + i + 1, k]
                    draw.line(points[i:i + 2], fill=fill if ok_seg else HIDDEN_GREY,
                              width=line_width)
            elif len(points) > 1:
                draw.line(points, fill=fill, width=line_width, joint="curve")
            elif line_width == 1:
                draw.point(points, fill=fill)
            else:
                x, y = points[0]
                draw.ellipse([x - half, y - half, x + half, y + half], fill=fill)
    if show_points:
        r = line_width + 1
        for k in range(n_tracks):
            x, y = int(xs[k]), int(ys[k])
            draw.ellipse([x - r, y - r, x + r, y + r], fill=tuple(int(c) for c in colours[k]))
    return np.asarray(image, dtype=np.uint8).copy()


def _shared_radius(uv: np.ndarray) -> float:
    """Largest known displacement magnitude (plus 1e-5 relative), 1.0 if there is none."""
    magnitude = np.hypot(uv[..., 0], uv[..., 1])
    known = np.isfinite(magnitude)
    top = float(magnitude[known].max()) if known.any() else 0.0
    return top * (1.0 + 1e-5) if top > 0 else 1.0


def _label(
    draw: ImageDraw.ImageDraw, font: Any, x0: int, y0: int, w: int, h: int, text: str
) -> None:
    """Black text on a white box in the top-left corner of a panel, if it fits."""
    left, top, right, bottom = draw.textbbox((0, 0), text, font=font)
    tw, th = right - left, bottom - top
    if tw + 4 > w or th + 4 > h:
        return
    draw.rectangle([x0, y0, x0 + tw + 3, y0 + th + 3], fill=(255, 255, 255))
    draw.text((x0 + 2 - left, y0 + 2 - top), text, fill=(0, 0, 0), font=font)


def displacement_panels(
    traj: np.ndarray,
    ref: int,
    *,
    max_radius: float | None = None,
    columns: int | None = None,
    gap: int = 2,
    labels: bool = True,
) -> np.ndarray:
    """Tile the colour-coded displacement of every frame into one image.

    Parameters
    ----------
    traj : ndarray, shape (F, H, W, 2)
        Trajectories relative to the reference frame; NaN where unknown (drawn
        black, as in :func:`~varflow.viz.colorwheel.flow_to_color`).
    ref : int
        Index of the reference frame, ``0 <= ref < F``; its panel is labelled
        ``"<ref> ref"``.
    max_radius : float, optional
        Saturation radius shared by all panels, so that colours compare across
        frames.  Default: the largest known displacement magnitude of the whole
        clip (all-zero or all-unknown clips use 1).
    columns : int, optional
        Panels per row, ``>= 1``; default ``ceil(sqrt(F))``.  Frames fill the grid
        row by row; ``rows = ceil(F / columns)``.
    gap : int, default 2
        Width in pixels of the grey (128) separation between panels, ``>= 0``.
        Empty cells of the last row are grey too.
    labels : bool, default True
        Write the frame index in the top-left corner of each panel (Pillow's
        default font, black on a white box), when the text fits in the panel.

    Returns
    -------
    ndarray, shape (rows * H + (rows - 1) * gap, columns * W + (columns - 1) * gap, 3)
        ``uint8`` RGB image; panel ``n`` has its top-left corner at
        ``((n // columns) * (H + gap), (n % columns) * (W + gap))``.

    Raises
    ------
    ValueError
        On a wrong ``traj`` shape or dtype, ``ref`` out of range, ``columns < 1``,
        ``gap < 0`` or a non-positive ``max_radius`` (the message names the
        argument).
    """
    fn = "displacement_panels"
    uv = _check_traj(traj, fn)
    n_frames, height, width = uv.shape[:3]
    ref = _check_ref(ref, n_frames, fn)
    radius = _check_max_radius(max_radius, fn)
    if columns is None:
        columns = math.ceil(math.sqrt(n_frames))
    elif not _is_int(columns) or columns < 1:
        raise ValueError(f"{fn}: columns must be None or an integer >= 1, got {columns!r}")
    if not _is_int(gap) or gap < 0:
        raise ValueError(f"{fn}: gap must be an integer >= 0, got {gap!r}")
    columns, gap = int(columns), int(gap)
    rows = math.ceil(n_frames / columns)
    if radius is None:
        radius = _shared_radius(uv)
    logger.debug("%s: %d panels in %d x %d, max_radius %.6g", fn, n_frames, rows, columns, radius)

    canvas = np.empty(
        (rows * height + (rows - 1) * gap, columns * width + (columns - 1) * gap, 3), np.uint8
    )
    canvas[:] = _GAP_COLOUR
    for n in range(n_frames):
        y0, x0 = (n // columns) * (height + gap), (n % columns) * (width + gap)
        canvas[y0 : y0 + height, x0 : x0 + width] = flow_to_color(uv[n], max_radius=radius)
    if not labels:
        return canvas
    image = Image.fromarray(canvas)
    draw = ImageDraw.Draw(image)
    font = ImageFont.load_default()
    for n in range(n_frames):
        y0, x0 = (n // columns) * (height + gap), (n % columns) * (width + gap)
        _label(draw, font, x0, y0, width, height, f"{n} ref" if n == ref else str(n))
    return np.asarray(image, dtype=np.uint8).copy()


def grey_out(image: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """Show hidden pixels as a flat mid grey over a faint copy of the image.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3), uint8
    visible : ndarray, shape (H, W), bool

    Returns
    -------
    ndarray, same shape as ``image``, uint8
        ``image`` where visible; ``0.25 image + 0.75 · 128`` elsewhere.
    """
    img = np.asarray(image)
    vis = np.asarray(visible, bool)
    if img.shape[:2] != vis.shape:
        raise ValueError(f"grey_out: visible must have shape {img.shape[:2]}, got {vis.shape}")
    out = img.copy()
    hidden = ~vis
    out[hidden] = (0.25 * img[hidden].astype(np.float32) + 96.0).round().astype(np.uint8)
    return out



# --------------------------------------------------------------------------- TAP-Vid style

#: Points :func:`draw_tracks` samples by default.
DEFAULT_POINTS = 300
#: Length and gap of the dashes of hidden segments, pixels.
_DASH = (4.0, 3.0)


def sample_points(shape: tuple[int, int], n: int, seed: int = 0,
                  mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """About ``n`` reference pixels spread over the frame: one per cell of a grid, jittered.

    The grid has about ``n`` square cells; each cell gives one pixel drawn uniformly
    inside it by a generator seeded with ``seed`` (the same points on every call).

    Parameters
    ----------
    shape : (int, int)
        ``(H, W)``.
    n : int
        Points wanted, >= 1.
    seed : int
    mask : ndarray, shape (H, W), bool, optional
        Only pixels where it is True (cells whose drawn pixel is outside the mask are
        dropped).

    Returns
    -------
    ys, xs : ndarray of int
        Rows and columns, in raster order of the cells.
    """
    h, w = int(shape[0]), int(shape[1])
    if not _is_int(n) or n < 1:
        raise ValueError(f"sample_points: n must be an integer >= 1, got {n!r}")
    cell = max(1.0, math.sqrt(h * w / n))
    rows, cols = max(1, round(h / cell)), max(1, round(w / cell))
    edges_y = np.linspace(0, h, rows + 1)
    edges_x = np.linspace(0, w, cols + 1)
    rng = np.random.default_rng(seed)
    gy, gx = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    ys = np.floor(edges_y[gy] + rng.random(gy.shape) * (edges_y[gy + 1] - edges_y[gy]))
    xs = np.floor(edges_x[gx] + rng.random(gx.shape) * (edges_x[gx + 1] - edges_x[gx]))
    ys = np.clip(ys.ravel().astype(np.int64), 0, h - 1)
    xs = np.clip(xs.ravel().astype(np.int64), 0, w - 1)
    if mask is not None:
        m = np.asarray(mask, bool)
        if m.shape != (h, w):
            raise ValueError(f"sample_points: mask must have shape {(h, w)}, got {m.shape}")
        keep = m[ys, xs]
        ys, xs = ys[keep], xs[keep]
    return ys, xs


def _position_colours(ys: np.ndarray, xs: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A colour per point from its place in the reference frame: the Middlebury wheel of
    the vector from the frame's centre (neighbours get similar colours, as in TAP-Vid's
    pictures, and the colours span the wheel)."""
    h, w = shape
    v = np.stack([(xs - (w - 1) / 2) / max(w / 2, 1), (ys - (h - 1) / 2) / max(h / 2, 1)], -1)
    v = v / max(float(np.abs(v).max()), 1e-9) * 0.95
    return flow_to_color(v[None].astype(np.float32), max_radius=1.0)[0]


def _colour_frame(frame: Any, shape: tuple[int, int], fn: str) -> np.ndarray:
    arr = np.asarray(frame)
    if arr.shape[:2] != shape or arr.ndim not in (2, 3):
        raise ValueError(f"{fn}: frame must have shape (H, W) or (H, W, C) with (H, W) = "
                         f"{shape} as in traj, got {arr.shape}")
    img = as_float_image(arr, name=f"{fn}: frame")
    rgb = img[..., :3] if img.shape[2] >= 3 else np.repeat(img[..., :1], 3, axis=2)
    return np.floor(255.0 * np.clip(rgb, 0, 1) + 0.5).astype(np.uint8)


def _dashed(draw: ImageDraw.ImageDraw, a: tuple[float, float], b: tuple[float, float],
            fill: tuple[int, int, int], width: int) -> None:
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    if length == 0:
        return
    on, off = _DASH
    t = 0.0
    while t < length:
        t1 = min(t + on, length)
        p = (a[0] + (b[0] - a[0]) * t / length, a[1] + (b[1] - a[1]) * t / length)
        q = (a[0] + (b[0] - a[0]) * t1 / length, a[1] + (b[1] - a[1]) * t1 / length)
        draw.line([p, q], fill=fill, width=width)
        t = t1 + off


def _tracks_on(image: Image.Image, pos: np.ndarray, known: np.ndarray, seen: np.ndarray,
               colours: np.ndarray, upto: int, tail: int, line_width: int) -> None:
    """Tails of frames ``upto - tail … upto`` and the points of frame ``upto``."""
    draw = ImageDraw.Draw(image)
    start = max(0, upto - tail)
    r = line_width + 1.5
    for k in range(pos.shape[1]):
        fill = tuple(int(c) for c in colours[k])
        for n in range(start, upto):
            if not (known[n, k] and known[n + 1, k]):
                continue
            a, b = tuple(pos[n, k]), tuple(pos[n + 1, k])
            if seen[n, k] and seen[n + 1, k]:
                draw.line([a, b], fill=fill, width=line_width)
            else:
                _dashed(draw, a, b, HIDDEN_GREY, line_width)
        if known[upto, k]:
            x, y = pos[upto, k]
            box = [x - r, y - r, x + r, y + r]
            if seen[upto, k]:
                draw.ellipse(box, fill=fill, outline=(0, 0, 0))
            else:
                draw.ellipse(box, outline=HIDDEN_GREY, width=1)


def _track_setup(traj: Any, ref: Any, visibility: Any, points: int, seed: int,
                 mask: Any, fn: str):
    uv = _check_traj(traj, fn)
    n_frames, height, width = uv.shape[:3]
    ref = _check_ref(ref, n_frames, fn)
    ys, xs = sample_points((height, width), points, seed, mask)
    track_uv = uv[:, ys, xs]
    known = np.isfinite(track_uv).all(axis=2)
    if visibility is None:
        seen = np.ones_like(known)
    else:
        vis = np.asarray(visibility)
        if vis.shape != (n_frames, height, width) or vis.dtype != np.bool_:
            raise ValueError(f"{fn}: visibility must be a boolean array of shape "
                             f"{(n_frames, height, width)}, got {vis.dtype} {vis.shape}")
        seen = vis[:, ys, xs]
    pos = np.stack([xs, ys], axis=-1)[None] + np.nan_to_num(track_uv)
    pos = np.clip(pos, -_COORD_LIMIT, _COORD_LIMIT)
    colours = _position_colours(ys, xs, (height, width))
    return uv, ref, pos, known, seen, colours


def draw_tracks(
    frame: np.ndarray,
    traj: np.ndarray,
    ref: int,
    frame_index: int | None = None,
    *,
    points: int = DEFAULT_POINTS,
    tail: int | None = None,
    visibility: np.ndarray | None = None,
    line_width: int = 2,
    seed: int = 0,
    mask: np.ndarray | None = None,
    legend: bool = False,
    title: str | None = None,
) -> np.ndarray:
    """Tracks as TAP-Vid draws them: sampled points with coloured tails over a frame.

    About ``points`` reference pixels (:func:`sample_points`), each coloured by its
    place in the reference frame; over ``frame`` (frame ``frame_index`` of the clip,
    in colour), each point's positions in the frames ``frame_index − tail`` …
    ``frame_index`` are joined into its tail, and a dot marks where it is in
    ``frame_index``.  Where the point is hidden (``visibility`` False) the tail is
    dashed in grey (:data:`HIDDEN_GREY`) and the dot is a grey ring.

    Parameters
    ----------
    frame : ndarray, shape (H, W) or (H, W, C)
        The frame to draw on (uint8, uint16 or float in [0, 1]).
    traj : ndarray, shape (F, H, W, 2)
        Trajectories relative to the reference frame; NaN where unknown.
    ref : int
        Index of the reference frame.
    frame_index : int, optional
        Which frame ``frame`` is (default the last, so that the tails run through
        the whole clip).
    points : int
        About this many points.
    tail : int, optional
        Frames of history in each tail (default all, back to frame 0).
    visibility : ndarray, shape (F, H, W), bool, optional
    line_width : int
        Width of the tails, pixels (dots have radius ``line_width + 1.5``).
    seed : int
        Seeds the choice of the points.
    mask : ndarray, shape (H, W), bool, optional
        Only points whose reference pixel is in the mask.
    legend : bool
        Add a white band under the picture saying what a dot, a tail (and, with
        ``visibility``, a grey ring and a grey dashed tail) mean.
    title : str, optional
        Text at the top of that band (e.g. which frame is the reference), wrapped to
        the picture's width; a newline starts a new line.  With ``legend`` and no
        ``title``, the reference frame and ``frame_index`` are named.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        With ``legend`` or ``title``: shape ``(H + B, max(W, L), 3)``, the picture in
        the top-left corner (unchanged) and the band of height ``B`` under it (the
        picture is widened with white to the band's width ``L`` if narrower).

    Raises
    ------
    ValueError
        Wrong shapes or values (the message names the argument).
    """
    fn = "draw_tracks"
    uv, ref, pos, known, seen, colours = _track_setup(traj, ref, visibility, points, seed,
                                                      mask, fn)
    n_frames = uv.shape[0]
    upto = n_frames - 1 if frame_index is None else frame_index
    if not _is_int(upto) or not 0 <= upto < n_frames:
        raise ValueError(f"{fn}: frame_index must be an integer in 0..{n_frames - 1}, "
                         f"got {frame_index!r}")
    if tail is not None and (not _is_int(tail) or tail < 0):
        raise ValueError(f"{fn}: tail must be an integer >= 0, got {tail!r}")
    if not _is_int(line_width) or line_width < 1:
        raise ValueError(f"{fn}: line_width must be an integer >= 1, got {line_width!r}")
    if title is not None and not isinstance(title, str):
        raise ValueError(f"{fn}: title must be a string, got {type(title).__name__}")
    image = Image.fromarray(_colour_frame(frame, uv.shape[1:3], fn))
    n_tail = n_frames if tail is None else tail
    _tracks_on(image, pos, known, seen, colours, int(upto), n_tail, line_width)
    if legend or title is not None:
        if legend and title is None:
            title = f"reference frame {ref} of {n_frames}\ndrawn on frame {upto}"
        entries = _legend_entries(int(upto), max(0, int(upto) - n_tail),
                                  visibility is not None) if legend else []
        image = _with_legend(image, title, entries, line_width)
    return np.asarray(image, dtype=np.uint8).copy()


#: Colour of the sample dot and tail in a legend (a mid orange of the colour wheel).
_LEGEND_COLOUR = (230, 120, 20)
#: The line of the legend on the colours of the points.
_COLOUR_NOTE = "colour: where the point is in the reference frame"


def _legend_entries(upto: int, start: int, hidden: bool) -> list[tuple[str, str]]:
    """``(symbol, text)`` of the legend of :func:`draw_tracks`: what is drawn."""
    span = f"frame {upto}" if start == upto else f"frames {start}-{upto}"
    entries = [("dot", f"point in frame {upto}"), ("tail", f"its path, {span}")]
    if hidden:
        entries += [("ring", f"point hidden in frame {upto}"), ("dashes", "path while hidden")]
    return entries


def _legend_font(size: int) -> Any:
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: one bitmap size
        return ImageFont.load_default()


def _wrap(draw: ImageDraw.ImageDraw, text: str, font: Any, width: float) -> list[str]:
    """``text`` in lines at most ``width`` pixels wide where it has spaces to break at."""
    lines: list[str] = []
    for word in text.split():
        if lines and draw.textlength(f"{lines[-1]} {word}", font=font) <= width:
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word)
    return lines


def _with_legend(image: Image.Image, title: str | None, entries: list[tuple[str, str]],
                 line_width: int) -> Image.Image:
    """``image`` over a white band: ``title``, the legend entries (in as many columns as
    fit the picture's width) and the note on the colours, one row each."""
    w, h = image.size
    size = min(24, max(12, round(w / 45)))
    font = _legend_font(size)
    measure = ImageDraw.Draw(image)
    pad, row, symbol = size // 2 + 2, round(1.6 * size), 3 * size  # symbol column
    cell = max((symbol + measure.textlength(t, font=font) for _, t in entries), default=0.0)
    cell = math.ceil(cell) + 2 * size  # an entry and the space after it
    columns = max(1, min(len(entries), (w - 2 * pad + 2 * size) // cell)) if entries else 1
    width = max(w, 2 * pad + (columns * cell - 2 * size if entries else 0))
    text_rows = [line for part in (title or "").splitlines()
                 for line in _wrap(measure, part, font, width - 2 * pad)]
    notes = _wrap(measure, _COLOUR_NOTE, font, width - 2 * pad) if entries else []
    width = max([width] + [2 * pad + math.ceil(measure.textlength(t, font=font))
                           for t in text_rows + notes])
    entry_rows = -(-len(entries) // columns)
    band = 2 * pad + row * (len(text_rows) + entry_rows + len(notes))
    canvas = Image.new("RGB", (width, h + band), (255, 255, 255))
    canvas.paste(image, (0, 0))
    draw = ImageDraw.Draw(canvas)

    def text_at(x: float, k: int, text: str) -> float:
        y = h + pad + k * row + row / 2  # middle of row k
        _, top, _, bottom = draw.textbbox((0, 0), text, font=font)
        draw.text((x, y - (top + bottom) / 2), text, fill=(0, 0, 0), font=font)
        return y

    for k, text in enumerate(text_rows):
        text_at(pad, k, text)
    r = line_width + 1.5
    for n, (sym, text) in enumerate(entries):
        k, x = len(text_rows) + n // columns, pad + (n % columns) * cell
        y = text_at(x + symbol, k, text)
        x0, x1 = x + r, x + symbol - size
        if sym == "dot":
            draw.ellipse([x1 - r, y - r, x1 + r, y + r], fill=_LEGEND_COLOUR, outline=(0, 0, 0))
        elif sym == "tail":
            draw.line([(x0, y), (x1, y)], fill=_LEGEND_COLOUR, width=line_width)
        elif sym == "ring":
            draw.ellipse([x1 - r, y - r, x1 + r, y + r], outline=HIDDEN_GREY, width=1)
        else:
            _dashed(draw, (x0, y), (x1, y), HIDDEN_GREY, line_width)
    for k, text in enumerate(notes):
        text_at(pad, len(text_rows) + entry_rows + k, text)
    return canvas


def track_animation(
    frames: np.ndarray,
    traj: np.ndarray,
    ref: int,
    *,
    points: int = DEFAULT_POINTS,
    tail: int = 10,
    visibility: np.ndarray | None = None,
    line_width: int = 2,
    seed: int = 0,
    mask: np.ndarray | None = None,
):
    """:func:`draw_tracks` for every frame of the clip, in order: a video of the tracks.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W[, C])
        The clip (the frame ``n`` of the output is drawn on ``frames[n]``).
    traj, ref, points, visibility, line_width, seed, mask
        As :func:`draw_tracks`.
    tail : int
        Frames of history in each tail (default 10).

    Yields
    ------
    ndarray, shape (H, W, 3), uint8
        One picture per frame (a generator: write them as they come).
    """
    fn = "track_animation"
    uv, ref, pos, known, seen, colours = _track_setup(traj, ref, visibility, points, seed,
                                                      mask, fn)
    clip = np.asarray(frames)
    if clip.shape[0] != uv.shape[0]:
        raise ValueError(f"{fn}: frames has {clip.shape[0]} frames, traj {uv.shape[0]}")
    if not _is_int(tail) or tail < 0:
        raise ValueError(f"{fn}: tail must be an integer >= 0, got {tail!r}")
    for n in range(uv.shape[0]):
        image = Image.fromarray(_colour_frame(clip[n], uv.shape[1:3], fn))
        _tracks_on(image, pos, known, seen, colours, n, tail, line_width)
        yield np.asarray(image, dtype=np.uint8).copy()
