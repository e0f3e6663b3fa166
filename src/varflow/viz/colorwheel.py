"""Middlebury colour coding of flow fields.

The flow direction selects a hue on a 55-entry colour wheel and the magnitude
the saturation: zero flow is white, a vector of length ``max_radius`` gets the
fully saturated wheel colour, longer vectors are darkened (factor 0.75) to flag
that they are out of the scale.  The wheel runs through red, yellow, green, cyan,
blue and magenta with the segment lengths RY = 15, YG = 6, GC = 4, CB = 11,
BM = 13, MR = 6, chosen to make the hues roughly perceptually equidistant
(Baker et al. 2011, section 4.2 and their ``flowToColor`` reference code).

With image coordinates (x right, y down) the hue angle is
``atan2(-v, -u) / pi`` in ``[-1, 1]``, mapped linearly onto the wheel: rightwards
flow is red, downwards orange-yellow, leftwards cyan, upwards blue-violet.

References
----------
Baker, Scharstein, Lewis, Roth, Black & Szeliski, "A Database and Evaluation
Methodology for Optical Flow", IJCV 92(1):1-31, 2011.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

__all__ = ["color_wheel", "flow_to_color", "color_wheel_legend", "flow_to_color_with_legend"]

logger = logging.getLogger(__name__)

#: (number of entries, channel that changes, rising?) per segment, starting at red.
_SEGMENTS = (
    (15, 1, True),  # RY: red -> yellow, green rises
    (6, 0, False),  # YG: yellow -> green, red falls
    (4, 2, True),  # GC: green -> cyan, blue rises
    (11, 1, False),  # CB: cyan -> blue, green falls
    (13, 0, True),  # BM: blue -> magenta, red rises
    (6, 2, False),  # MR: magenta -> red, blue falls
)
#: Relative margin added to the largest magnitude when no ``max_radius`` is given.
_EPS = 1e-5
#: Flow components beyond this magnitude are unknown (the ``.flo`` 1e10 convention).
_UNKNOWN_THRESHOLD = 1e9


def color_wheel() -> np.ndarray:
    """The 55-entry Middlebury colour wheel.

    Returns
    -------
    ndarray, shape (55, 3), uint8
        RGB colours; entry 0 is pure red and the hue advances through yellow,
        green, cyan, blue and magenta.
    """
    rows = []
    colour = np.array([255, 0, 0], dtype=np.int64)
    for n, channel, rising in _SEGMENTS:
        ramp = (255 * np.arange(n)) // n
        seg = np.tile(colour, (n, 1))
        seg[:, channel] = ramp if rising else 255 - ramp
        rows.append(seg)
        colour = seg[-1].copy()
        colour[channel] = 255 if rising else 0
    return np.concatenate(rows).astype(np.uint8)


_WHEEL = color_wheel().astype(np.float64) / 255.0


def _check_flow(flow: np.ndarray) -> np.ndarray:
    arr = np.asarray(flow)
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise ValueError(f"flow_to_color: expected a flow of shape (H, W, 2), got {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"flow_to_color: expected a real-valued flow, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def _check_colour(colour: Sequence[int]) -> np.ndarray:
    c = np.asarray(colour)
    if c.shape != (3,) or np.any(c < 0) or np.any(c > 255):
        raise ValueError(f"unknown_color must be three values in 0..255, got {colour!r}")
    return c.astype(np.uint8)


def flow_to_color(
    flow: np.ndarray,
    max_radius: float | None = None,
    unknown_color: Sequence[int] = (0, 0, 0),
) -> np.ndarray:
    """Colour-code a flow field with the Middlebury colour wheel.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
        ``[..., 0]`` = u (rightwards), ``[..., 1]`` = v (downwards).  Pixels with a
        NaN, infinite or ``|value| > 1e9`` component are unknown.
    max_radius : float, optional
        Flow magnitude mapped to full saturation.  ``None`` uses the largest
        magnitude of the known pixels of this flow (plus a relative ``1e-5``, so
        all-zero flow is white).  Pass one value for several frames to make their
        colours comparable; longer vectors are then darkened (colour × 0.75).
    unknown_color : sequence of 3 ints, default (0, 0, 0)
        RGB colour of unknown pixels.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        RGB image.

    Raises
    ------
    ValueError
        On a wrong flow shape, a non-positive or non-finite ``max_radius`` or a bad
        ``unknown_color``.

    Notes
    -----
    With ``r = |flow| / max_radius`` and ``a = atan2(-v, -u) / pi``, the wheel is
    sampled at ``(a + 1) / 2 * 54`` with linear interpolation between entries
    (wrapping from entry 54 back to 0); the colour ``c`` becomes
    ``1 - r (1 - c)`` for ``r <= 1`` and ``0.75 c`` otherwise, and the byte value
    is ``floor(255 c)`` (with a 1e-6 guard against round-off).
    """
    uv = _check_flow(flow)
    unknown_rgb = _check_colour(unknown_color)
    with np.errstate(invalid="ignore"):
        unknown = (~np.isfinite(uv) | (np.abs(uv) > _UNKNOWN_THRESHOLD)).any(axis=-1)
    uv[unknown] = 0.0
    uv += 0.0  # turn -0.0 into +0.0 so that the angle of exactly horizontal flow is stable
    u, v = uv[..., 0], uv[..., 1]
    radius = np.hypot(u, v)
    if max_radius is None:
        scale = float(radius.max()) if radius.size else 0.0
        scale = scale * (1.0 + _EPS) + np.finfo(np.float64).tiny
    else:
        scale = float(max_radius)
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(
                f"flow_to_color: max_radius must be positive and finite, got {max_radius!r}"
            )
    logger.debug("flow_to_color: max_radius %.6g", scale)

    rad = radius / scale
    angle = np.arctan2(-v, -u) / np.pi
    ncols = _WHEEL.shape[0]
    fk = (angle + 1.0) / 2.0 * (ncols - 1)
    k0 = np.floor(fk).astype(np.int64)
    frac = (fk - k0)[..., None]
    k0 %= ncols
    k1 = (k0 + 1) % ncols
    col = (1.0 - frac) * _WHEEL[k0] + frac * _WHEEL[k1]
    inside = (rad <= 1.0)[..., None]
    col = np.where(inside, 1.0 - rad[..., None] * (1.0 - col), 0.75 * col)
    # The small offset keeps exact wheel values (e.g. 209/255 * 255) from flooring one below.
    img = np.floor(255.0 * col + 1e-6).clip(0, 255).astype(np.uint8)
    img[unknown] = unknown_rgb
    return img


def color_wheel_legend(size: int = 151, max_radius: float = 1.0) -> np.ndarray:
    """Image of the colour coding used by :func:`flow_to_color`.

    Pixel ``(y, x)`` shows the colour of the flow pointing from the centre to it,
    scaled so that the edge of the inscribed disc has magnitude ``max_radius``.

    Parameters
    ----------
    size : int, default 151
        Side length in pixels (at least 3; odd sizes have an exact white centre).
    max_radius : float, default 1.0
        Flow magnitude at the edge of the disc.  The image itself does not depend
        on it (the coding is scale-free); it is validated and documents the scale.

    Returns
    -------
    ndarray, shape (size, size, 3), uint8
        Pixels outside the disc are white.
    """
    size = int(size)
    if size < 3:
        raise ValueError(f"color_wheel_legend: size must be >= 3, got {size}")
    if not (np.isfinite(max_radius) and max_radius > 0):
        raise ValueError(f"color_wheel_legend: max_radius must be positive, got {max_radius!r}")
    centre = (size - 1) / 2.0
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    flow = np.stack([(xx - centre) / centre, (yy - centre) / centre], axis=-1)
    outside = np.hypot(flow[..., 0], flow[..., 1]) > 1.0
    # Colours depend only on flow / max_radius; code the normalised field directly so that
    # round-off cannot push pixels on the rim of the disc past the saturation radius.
    img = flow_to_color(flow, max_radius=1.0)
    img[outside] = 255
    return img


def flow_to_color_with_legend(
    flow: np.ndarray,
    max_radius: float | None = None,
    legend_size: int | None = None,
) -> np.ndarray:
    """Colour-code a flow field and paste a colour-wheel legend in the top-right corner.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
    max_radius : float, optional
        As in :func:`flow_to_color`.
    legend_size : int, optional
        Side of the square legend; default ``min(H, W) // 4`` (the legend is left
        out if that is below 3 pixels).

    Returns
    -------
    ndarray, shape (H, W, 3), uint8

    Raises
    ------
    ValueError
        If ``legend_size`` is below 3 or larger than ``min(H, W)``.
    """
    img = flow_to_color(flow, max_radius=max_radius)
    h, w = img.shape[:2]
    if legend_size is None:
        legend_size = min(h, w) // 4
        if legend_size < 3:
            logger.debug("flow_to_color_with_legend: image too small for a legend")
            return img
    legend_size = int(legend_size)
    if not 3 <= legend_size <= min(h, w):
        raise ValueError(
            f"flow_to_color_with_legend: legend_size must be in 3..{min(h, w)}, got {legend_size}"
        )
    img[:legend_size, w - legend_size :] = color_wheel_legend(legend_size)
    return img
