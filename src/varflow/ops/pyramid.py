"""Image pyramids and flow resampling for the coarse-to-fine driver.

Level 0 is the input resolution; level ``l`` has size ``round(H * eta**l)`` by
``round(W * eta**l)``.  Each level is obtained from the previous one by Gaussian
anti-alias smoothing with ``sigma = sigma_scale * sqrt(r**-2 - 1)``, ``r`` the size
ratio between the two levels, followed by bilinear sampling at pixel centres
(Sánchez, Meinhardt-Llopis & Facciolo, IPOL 2013 use the same rule with
``sigma_scale = 0.6``).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy import ndimage

from .._jit import FASTMATH

__all__ = [
    "pyramid_shapes",
    "build_pyramid",
    "smooth_image",
    "smooth_image_fast",
    "smooth_planes",
    "resize_bilinear",
    "resize_flow",
]


def pyramid_shapes(
    shape: tuple[int, int], n_levels: int, factor: float, min_size: int
) -> list[tuple[int, int]]:
    """Shapes of the pyramid levels, finest first.

    Levels stop before the shorter side drops below ``min_size`` pixels or when
    ``n_levels`` levels exist.
    """
    h, w = shape
    shapes = [(h, w)]
    for level in range(1, n_levels):
        s = factor**level
        hl, wl = int(round(h * s)), int(round(w * s))
        if min(hl, wl) < min_size:
            break
        shapes.append((hl, wl))
    return shapes


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _resize_kernel(src, out):
    hs, ws, k = src.shape
    hd, wd, _ = out.shape
    sy = hs / hd
    sx = ws / wd
    for i in nb.prange(hd):
        y = (i + 0.5) * sy - 0.5
        y = min(max(y, 0.0), hs - 1.0)
        y0 = min(int(y), hs - 2) if hs > 1 else 0
        fy = y - y0
        y1 = min(y0 + 1, hs - 1)
        for j in range(wd):
            x = (j + 0.5) * sx - 0.5
            x = min(max(x, 0.0), ws - 1.0)
            x0 = min(int(x), ws - 2) if ws > 1 else 0
            fx = x - x0
            x1 = min(x0 + 1, ws - 1)
            for c in range(k):
                top = src[y0, x0, c] * (1.0 - fx) + src[y0, x1, c] * fx
                bot = src[y1, x0, c] * (1.0 - fx) + src[y1, x1, c] * fx
                out[i, j, c] = top * (1.0 - fy) + bot * fy


def resize_bilinear(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear resampling at pixel centres.

    Parameters
    ----------
    image : ndarray, shape (H, W, K)
    shape : (int, int)
        Target ``(H', W')``.

    Returns
    -------
    ndarray, shape (H', W', K), float32
    """
    src = np.ascontiguousarray(image, dtype=np.float32)
    out = np.empty((shape[0], shape[1], src.shape[2]), dtype=np.float32)
    _resize_kernel(src, out)
    return out


def smooth_image(image: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing of the rows and columns of an ``(H, W, K)`` array, edges replicated.

    ``scipy.ndimage.gaussian_filter`` with σ pixels along both image axes and none
    across the planes (truncated at 4σ); σ ≤ 0 returns ``image`` itself.  The
    reference of :func:`smooth_image_fast`.

    Returns
    -------
    ndarray, shape (H, W, K), float32
    """
    if sigma <= 0:
        return image
    return ndimage.gaussian_filter(image, sigma=(sigma, sigma, 0),
                                   mode="nearest").astype(np.float32, copy=False)


def _gaussian_taps(sigma: float) -> np.ndarray:
    """The 1-D taps of :func:`smooth_image` (``scipy.ndimage.gaussian_filter``, truncate 4)."""
    r = int(4.0 * sigma + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * x * x / (sigma * sigma))
    return (k / k.sum()).astype(np.float32)


def smooth_image_fast(image: np.ndarray, sigma: float) -> np.ndarray:
    """:func:`smooth_image` as a Numba kernel (same taps and edge handling, float32 sums).

    :func:`smooth_planes` with the layout of the input, C-contiguous; σ ≤ 0 returns a
    C-contiguous float32 view or copy of ``image``.
    """
    x = np.ascontiguousarray(image, np.float32)
    if sigma <= 0:
        return x
    return np.ascontiguousarray(np.moveaxis(smooth_planes(x, sigma), 0, -1))


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _smooth_planar_kernel(x, taps, out):
    """Separable smoothing of the rows and columns of a (possibly strided) ``(H, W, K)``
    view into planar ``(K, H, W)`` output, edges replicated (each row is first copied
    into a buffer padded with its end values, so the row pass needs no clamping)."""
    h, w, k = x.shape
    r = taps.shape[0] // 2
    n = 2 * r + 1
    tmp = np.empty((k, h, w), np.float32)
    for task in nb.prange(k * h):
        c = task // h
        i = task - c * h
        row = np.empty(w + 2 * r, np.float32)
        for j in range(w):
            row[r + j] = x[i, j, c]
        for j in range(r):
            row[j] = x[i, 0, c]
            row[r + w + j] = x[i, w - 1, c]
        dst = tmp[c, i]
        for j in range(w):
            acc = np.float32(0.0)
            for t in range(n):
                acc += taps[t] * row[j + t]
            dst[j] = acc
    for task in nb.prange(k * h):
        c = task // h
        i = task - c * h
        dst = out[c, i]
        for j in range(w):
            dst[j] = 0.0
        for t in range(-r, r + 1):
            src = tmp[c, min(max(i + t, 0), h - 1)]
            wt = taps[t + r]
            for j in range(w):
                dst[j] += wt * src[j]


def smooth_planes(image: np.ndarray, sigma: float, out: np.ndarray | None = None) -> np.ndarray:
    """:func:`smooth_image` as a Numba kernel with planar output: ``(H, W, K)`` in,
    ``(K, H, W)`` out (same taps and edge handling, float32 sums).

    ``image`` may be a strided view (e.g. some channels of a stack of warped
    planes): it is read without a copy.

    Parameters
    ----------
    image : ndarray, shape (H, W, K), float32
    sigma : float
        σ of the Gaussian, pixels; ≤ 0 copies the channels out.
    out : ndarray, shape (K, H, W), float32, optional
        C-contiguous array to write into (e.g. part of a larger planar stack).

    Returns
    -------
    ndarray, shape (K, H, W), float32
    """
    x = np.asarray(image, np.float32)
    h, w, k = x.shape
    if out is None:
        out = np.empty((k, h, w), np.float32)
    if sigma <= 0:
        out[...] = np.moveaxis(x, -1, 0)
        return out
    _smooth_planar_kernel(x, _gaussian_taps(sigma), out)
    return out


def build_pyramid(
    image: np.ndarray, shapes: list[tuple[int, int]], factor: float, sigma_scale: float = 0.6
) -> list[np.ndarray]:
    """Gaussian pyramid of an ``(H, W, C)`` image for the given level shapes (finest first).

    ``factor`` is kept for the signature's sake; the smoothing of each level is
    derived from the actual size ratio to the previous level.
    """
    levels = [np.ascontiguousarray(image, dtype=np.float32)]
    for shp in shapes[1:]:
        prev = levels[-1]
        ratio = min(shp[0] / prev.shape[0], shp[1] / prev.shape[1])
        sigma = sigma_scale * math.sqrt(max(ratio**-2 - 1.0, 0.0))
        levels.append(resize_bilinear(smooth_image(prev, sigma), shp))
    return levels


def resize_flow(flow: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Resample a flow field to ``shape`` and rescale its vectors accordingly.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
    shape : (int, int)

    Returns
    -------
    ndarray, shape (shape[0], shape[1], 2), float32
        u scaled by ``W'/W`` and v by ``H'/H``.
    """
    out = resize_bilinear(flow, shape)
    out[..., 0] *= shape[1] / flow.shape[1]
    out[..., 1] *= shape[0] / flow.shape[0]
    return out
