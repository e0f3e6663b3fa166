"""Images of the report: downscaling, frames, error and visibility maps, PNG data URIs.

All images are ``(H, W, 3)`` uint8 RGB arrays until :func:`png_data_uri` encodes
them; input frames (grey or colour, ``uint8``, ``uint16`` or float) are brought to
that form by :func:`unit_rgb_frames` and :func:`to_uint8`.  Downscaling uses
Pillow's box filter (the mean over each source area), so a region of one colour keeps
that exact colour.
"""

from __future__ import annotations

import base64
import io
import logging
from collections.abc import Sequence

import numpy as np
from PIL import Image

__all__ = [
    "downscale",
    "unit_rgb_frames",
    "to_uint8",
    "grey_outside",
    "png_bytes",
    "png_data_uri",
    "error_map",
    "error_colorbar",
    "visibility_image",
    "neutral_background",
    "UNKNOWN_GREY",
    "HIDDEN_COLOUR",
    "VISIBLE_COLOUR",
]

logger = logging.getLogger(__name__)

#: Colour of pixels without ground truth or estimate in error maps.
UNKNOWN_GREY = (128, 128, 128)
#: Visibility maps: visible pixels white, hidden ones dark.
VISIBLE_COLOUR = (255, 255, 255)
HIDDEN_COLOUR = (40, 40, 40)
#: Anchors of the error colour map, from 0 to the top of the scale (dark blue -> yellow).
_ERROR_ANCHORS = np.array(
    [[0, 0, 48], [40, 40, 160], [150, 40, 150], [230, 90, 40], [255, 230, 60]], np.float64
)


def downscale(image: np.ndarray, max_side: int) -> np.ndarray:
    """Shrink an RGB image so that its longer side is at most ``max_side`` pixels.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint8
    max_side : int
        ``>= 1``.

    Returns
    -------
    ndarray, uint8
        ``image`` itself when it is small enough, else a box-filtered copy with the
        aspect ratio kept (each side at least 1 pixel).
    """
    h, w = image.shape[:2]
    if max(h, w) <= max_side:
        return image
    f = max_side / max(h, w)
    size = (max(1, round(w * f)), max(1, round(h * f)))
    out = Image.fromarray(np.ascontiguousarray(image)).resize(size, Image.Resampling.BOX)
    return np.asarray(out, dtype=np.uint8)


def unit_rgb_frames(frames: Sequence[np.ndarray], names: Sequence[str]) -> list[np.ndarray]:
    """Frames as float RGB in ``[0, 1]``, by varflow's intensity convention.

    ``uint8`` / ``uint16`` frames are divided by 255 / 65535; float frames already in
    ``[0, 1]`` are kept, others are scaled *jointly* from their common range (the
    rule of :mod:`varflow._validate`, so the frames of one pair stay comparable).
    Grey frames are repeated into three channels.

    Parameters
    ----------
    frames : sequence of ndarray, each (H, W) or (H, W, C)
    names : sequence of str
        One per frame, for error messages.

    Returns
    -------
    list of ndarray, each (H, W, 3) float32

    Raises
    ------
    ValueError
        On an unsupported dtype or shape, or non-finite values (naming the frame).
    """
    from .._validate import as_float_frames

    out = []
    for f in as_float_frames(list(frames), list(names)):
        rgb = f[..., :3] if f.shape[2] >= 3 else np.repeat(f[..., :1], 3, axis=2)
        out.append(np.ascontiguousarray(rgb, dtype=np.float32))
    return out


def to_uint8(image: np.ndarray) -> np.ndarray:
    """A float image in ``[0, 1]`` as ``uint8`` (rounded, clipped)."""
    return np.floor(255.0 * np.clip(image, 0.0, 1.0) + 0.5).astype(np.uint8)


def grey_outside(image: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """A copy of an RGB uint8 image with :data:`UNKNOWN_GREY` where ``inside`` is False."""
    out = np.array(image, dtype=np.uint8, copy=True)
    out[~np.asarray(inside, bool)] = UNKNOWN_GREY
    return out


def png_bytes(image: np.ndarray) -> bytes:
    """Encode an RGB (or grey) uint8 image as PNG."""
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG", compress_level=9)
    return buf.getvalue()


def png_data_uri(image: np.ndarray) -> str:
    """``data:image/png;base64,...`` URI of an image."""
    return "data:image/png;base64," + base64.b64encode(png_bytes(image)).decode("ascii")


def _ramp(t: np.ndarray) -> np.ndarray:
    """Colours of ``t`` in ``[0, 1]`` on the error colour map, ``(..., 3)`` uint8."""
    n = len(_ERROR_ANCHORS) - 1
    x = np.clip(t, 0.0, 1.0) * n
    k = np.minimum(np.floor(x).astype(np.int64), n - 1)
    frac = (x - k)[..., None]
    col = (1.0 - frac) * _ERROR_ANCHORS[k] + frac * _ERROR_ANCHORS[k + 1]
    return np.rint(col).astype(np.uint8)


def error_map(epe: np.ndarray, vmax: float) -> np.ndarray:
    """Colour-code an endpoint-error map.

    Parameters
    ----------
    epe : ndarray, shape (H, W)
        Endpoint error in pixels; NaN where unknown.
    vmax : float
        Error shown with the brightest colour (larger errors are clipped), ``> 0``.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
        Dark blue (0 px) through purple and orange to yellow (``vmax`` and above);
        unknown pixels are :data:`UNKNOWN_GREY`.
    """
    e = np.asarray(epe, np.float64)
    known = np.isfinite(e)
    img = _ramp(np.where(known, e, 0.0) / vmax)
    img[~known] = UNKNOWN_GREY
    return img


def error_colorbar(width: int = 256, height: int = 14) -> np.ndarray:
    """Horizontal colour bar of :func:`error_map` from 0 (left) to ``vmax`` (right)."""
    t = np.linspace(0.0, 1.0, width)
    return np.repeat(_ramp(t)[None], height, axis=0)


def visibility_image(visible: np.ndarray) -> np.ndarray:
    """White where visible, dark grey where hidden; ``(H, W)`` bool -> ``(H, W, 3)`` uint8."""
    vis = np.asarray(visible, bool)
    img = np.empty(vis.shape + (3,), np.uint8)
    img[vis] = VISIBLE_COLOUR
    img[~vis] = HIDDEN_COLOUR
    return img


def neutral_background(height: int, width: int) -> np.ndarray:
    """A plain light-grey frame (float in [0, 1]) to draw trajectories on."""
    return np.full((height, width), 0.8, np.float32)
