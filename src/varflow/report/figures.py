"""Images of the report: downscaling, error and visibility maps, PNG data URIs.

All images are ``(H, W, 3)`` uint8 RGB arrays until :func:`png_data_uri` encodes
them.  Downscaling uses Pillow's box filter (the mean over each source area), so a
region of one colour keeps that exact colour.
"""

from __future__ import annotations

import base64
import io
import logging

import numpy as np
from PIL import Image

__all__ = [
    "downscale",
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
