"""Backward warping of images by a flow with bicubic (Keys, a = -0.5) interpolation.

``warp(I, flow)[y, x] = I(y + v(y, x), x + u(y, x))``.  Samples outside the image
are evaluated with the border replicated, and a boolean mask reports which target
points fell inside ``[0, W-1] x [0, H-1]``; the solvers switch the data term off
where the mask is false, so pixels that leave the frame are filled in by the
regulariser instead of by clamped border colours.

Two engines with the same signature: :func:`warp_bicubic_numpy` (the reference)
and the Numba kernel used by :func:`warp_bicubic`; likewise :func:`warp_bilinear_numpy`
and :func:`warp_bilinear` for bilinear interpolation (the frame synthesis of
:mod:`varflow.retime`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._jit import FASTMATH_NAN

__all__ = ["warp_bicubic", "warp_bicubic_numpy", "warp_bilinear", "warp_bilinear_numpy",
           "keys_weights", "in_bounds", "bilinear_at", "bilinear_cell"]

_A = -0.5


def keys_weights(f: np.ndarray) -> np.ndarray:
    """Keys cubic-convolution weights for fractional offsets ``f`` in ``[0, 1)``.

    Returns
    -------
    ndarray, shape f.shape + (4,)
        Weights of the samples at integer offsets -1, 0, 1, 2.
    """
    f = np.asarray(f, dtype=np.float32)
    a = np.float32(_A)

    def near(t):
        return ((a + 2) * t - (a + 3)) * t * t + 1

    def far(t):
        return ((a * t - 5 * a) * t + 8 * a) * t - 4 * a

    return np.stack([far(1 + f), near(f), near(1 - f), far(2 - f)], axis=-1)


def in_bounds(flow: np.ndarray) -> np.ndarray:
    """``x + w(x)`` inside ``[0, W−1] × [0, H−1]``: ``(H, W)`` bool.

    The ``inside`` mask of :func:`warp_bicubic` without the sampling.
    """
    h, w = flow.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    x = xx + flow[..., 0]
    y = yy + flow[..., 1]
    return (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)


def warp_bicubic_numpy(planes: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference NumPy implementation of :func:`warp_bicubic`."""
    planes = np.asarray(planes, dtype=np.float32)
    h, w, k = planes.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    x = xx + flow[..., 0]
    y = yy + flow[..., 1]
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    x0 = np.floor(x)
    y0 = np.floor(y)
    wx = keys_weights(x - x0)
    wy = keys_weights(y - y0)
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    out = np.zeros((h, w, k), dtype=np.float32)
    for m in range(4):
        yi = np.clip(y0 + m - 1, 0, h - 1)
        for n in range(4):
            xi = np.clip(x0 + n - 1, 0, w - 1)
            out += (wy[..., m] * wx[..., n])[..., None] * planes[yi, xi]
    return out, inside


# Keys' polynomials with float32 coefficients (a = -0.5), so that the kernel's
# arithmetic stays in float32
_N2 = np.float32(_A + 2.0)
_N3 = np.float32(_A + 3.0)
_FA = np.float32(_A)
_F5A = np.float32(5.0 * _A)
_F8A = np.float32(8.0 * _A)
_F4A = np.float32(4.0 * _A)
_ONE = np.float32(1.0)


@nb.njit(cache=True, inline="always")
def _near(t):
    return (_N2 * t - _N3) * t * t + _ONE


@nb.njit(cache=True, inline="always")
def _far(t):
    return ((_FA * t - _F5A) * t + _F8A) * t - _F4A


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH_NAN)  # NaN flows must be detected
def _warp_kernel(planes, flow, out, inside):
    """Bicubic samples of ``planes`` (H, W, K) at ``x + flow``; ``flow`` planar (2, H, W)."""
    h, w, k = planes.shape
    f2 = np.float32(2.0)
    xmax = np.float32(w - 1.0)
    ymax = np.float32(h - 1.0)
    for i in nb.prange(h):
        fu = flow[0, i]
        fv = flow[1, i]
        ins = inside[i]
        o = out[i]
        for j in range(w):
            x = np.float32(j) + fu[j]
            y = np.float32(i) + fv[j]
            ins[j] = (x >= 0.0) and (x <= xmax) and (y >= 0.0) and (y <= ymax)
            if not (x == x and y == y):  # NaN flow: treat as outside
                x = -f2
                y = -f2
            # keep the far-away samples finite and bounded
            x = min(max(x, -f2), np.float32(w + 1.0))
            y = min(max(y, -f2), np.float32(h + 1.0))
            ix0 = int(x + f2) - 2  # floor (truncation of a positive number)
            iy0 = int(y + f2) - 2
            fx = x - np.float32(ix0)
            fy = y - np.float32(iy0)
            # the weights stay in scalars and the 4 x 4 taps are summed row by row
            # (separably): no per-pixel arrays, every product in registers
            wx0 = _far(_ONE + fx)
            wx1 = _near(fx)
            wx2 = _near(_ONE - fx)
            wx3 = _far(f2 - fx)
            wy0 = _far(_ONE + fy)
            wy1 = _near(fy)
            wy2 = _near(_ONE - fy)
            wy3 = _far(f2 - fy)
            if ix0 >= 1 and ix0 <= w - 3 and iy0 >= 1 and iy0 <= h - 3:  # no clamping
                x0 = ix0 - 1
                x1 = ix0
                x2 = ix0 + 1
                x3 = ix0 + 2
                r0 = planes[iy0 - 1]
                r1 = planes[iy0]
                r2 = planes[iy0 + 1]
                r3 = planes[iy0 + 2]
            else:
                x0 = min(max(ix0 - 1, 0), w - 1)
                x1 = min(max(ix0, 0), w - 1)
                x2 = min(max(ix0 + 1, 0), w - 1)
                x3 = min(max(ix0 + 2, 0), w - 1)
                r0 = planes[min(max(iy0 - 1, 0), h - 1)]
                r1 = planes[min(max(iy0, 0), h - 1)]
                r2 = planes[min(max(iy0 + 1, 0), h - 1)]
                r3 = planes[min(max(iy0 + 2, 0), h - 1)]
            for c in range(k):
                s0 = wx0 * r0[x0, c] + wx1 * r0[x1, c] + wx2 * r0[x2, c] + wx3 * r0[x3, c]
                s1 = wx0 * r1[x0, c] + wx1 * r1[x1, c] + wx2 * r1[x2, c] + wx3 * r1[x3, c]
                s2 = wx0 * r2[x0, c] + wx1 * r2[x1, c] + wx2 * r2[x2, c] + wx3 * r2[x3, c]
                s3 = wx0 * r3[x0, c] + wx1 * r3[x1, c] + wx2 * r3[x2, c] + wx3 * r3[x3, c]
                o[j, c] = wy0 * s0 + wy1 * s1 + wy2 * s2 + wy3 * s3


def warp_bicubic(planes: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Warp stacked image planes backwards by a flow with bicubic interpolation.

    Parameters
    ----------
    planes : ndarray, shape (H, W, K), float32
        Any number of planes sampled at the same points (e.g. the colour channels
        of ``I1`` and their derivatives).
    flow : ndarray, shape (H, W, 2), float32
        ``[..., 0]`` = u (x), ``[..., 1]`` = v (y).

    Returns
    -------
    warped : ndarray, shape (H, W, K), float32
    inside : ndarray, shape (H, W), bool
        True where ``(x + u, y + v)`` lies inside the image.
    """
    planes = np.ascontiguousarray(planes, dtype=np.float32)
    flow = np.asarray(flow)
    if planes.ndim != 3 or flow.shape != planes.shape[:2] + (2,):
        raise ValueError(f"warp: planes {planes.shape} and flow {flow.shape} do not match")
    # the kernel reads the flow planar: no copy for the planar views the solvers and
    # the median filter return
    flow_p = np.ascontiguousarray(np.moveaxis(flow, -1, 0), dtype=np.float32)
    out = np.empty_like(planes)
    inside = np.empty(planes.shape[:2], dtype=np.bool_)
    _warp_kernel(planes, flow_p, out, inside)
    return out, inside


def warp_bilinear_numpy(planes: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference engine of :func:`warp_bilinear` (NumPy)."""
    planes = np.asarray(planes, dtype=np.float32)
    h, w = planes.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    x = xx + flow[..., 0].astype(np.float32)
    y = yy + flow[..., 1].astype(np.float32)
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    x = np.clip(np.nan_to_num(x, nan=0.0), 0, w - 1)
    y = np.clip(np.nan_to_num(y, nan=0.0), 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2) if w > 1 else np.zeros_like(x, np.int64)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2) if h > 1 else np.zeros_like(y, np.int64)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    top = planes[y0, x0] * (1 - fx) + planes[y0, x1] * fx
    bottom = planes[y1, x0] * (1 - fx) + planes[y1, x1] * fx
    return (top * (1 - fy) + bottom * fy).astype(np.float32), inside


@nb.njit(cache=True, inline="always")
def bilinear_cell(x, y, h, w):
    """The bilinear cell of the point ``(x, y)``, clamped into an ``h × w`` image:
    ``(x0, x1, y0, y1, fx, fy)`` with the weights ``1 − fx, fx`` on columns ``x0, x1``
    and ``1 − fy, fy`` on rows ``y0, y1``; a NaN point is the top-left pixel.  Shared
    by the Numba kernels that sample bilinearly."""
    if x != x or y != y:
        x = np.float32(0.0)
        y = np.float32(0.0)
    x = min(max(x, np.float32(0.0)), np.float32(w - 1.0))
    y = min(max(y, np.float32(0.0)), np.float32(h - 1.0))
    x0 = min(int(np.floor(x)), w - 2) if w > 1 else 0
    y0 = min(int(np.floor(y)), h - 2) if h > 1 else 0
    return (x0, min(x0 + 1, w - 1), y0, min(y0 + 1, h - 1), x - np.float32(x0),
            y - np.float32(y0))


@nb.njit(cache=True, inline="always")
def bilinear_at(img, c, x0, x1, y0, y1, fx, fy):
    """Channel ``c`` of ``img`` (H, W, K) sampled in the cell of :func:`bilinear_cell`."""
    one = np.float32(1.0)
    top = img[y0, x0, c] * (one - fx) + img[y0, x1, c] * fx
    bottom = img[y1, x0, c] * (one - fx) + img[y1, x1, c] * fx
    return top * (one - fy) + bottom * fy


@nb.njit(cache=True, parallel=True)
def _bilinear_kernel(planes, flow, out, inside):
    """Bilinear samples of ``planes`` (H, W, K) at ``x + flow``; ``flow`` planar (2, H, W)."""
    h, w, k = planes.shape
    xmax = np.float32(w - 1.0)
    ymax = np.float32(h - 1.0)
    for i in nb.prange(h):
        for j in range(w):
            x = np.float32(j) + flow[0, i, j]
            y = np.float32(i) + flow[1, i, j]
            inside[i, j] = x >= 0 and x <= xmax and y >= 0 and y <= ymax  # False for NaN
            x0, x1, y0, y1, fx, fy = bilinear_cell(x, y, h, w)
            for c in range(k):
                out[i, j, c] = bilinear_at(planes, c, x0, x1, y0, y1, fx, fy)


def warp_bilinear(planes: np.ndarray, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Warp stacked image planes backwards by a flow with bilinear interpolation.

    ``out[y, x] = planes(y + v, x + u)``, the border replicated outside the image;
    a NaN flow samples the top-left pixel and is reported outside.

    Parameters
    ----------
    planes : ndarray, shape (H, W, K)
        Converted to float32.
    flow : ndarray, shape (H, W, 2)
        ``[..., 0]`` = u (x), ``[..., 1]`` = v (y).

    Returns
    -------
    warped : ndarray, shape (H, W, K), float32
    inside : ndarray, shape (H, W), bool
        True where ``(x + u, y + v)`` lies inside ``[0, W-1] x [0, H-1]``.
    """
    planes = np.ascontiguousarray(planes, dtype=np.float32)
    flow = np.asarray(flow)
    if planes.ndim != 3 or flow.shape != planes.shape[:2] + (2,):
        raise ValueError(f"warp: planes {planes.shape} and flow {flow.shape} do not match")
    flow_p = np.ascontiguousarray(np.moveaxis(flow, -1, 0), dtype=np.float32)
    out = np.empty_like(planes)
    inside = np.empty(planes.shape[:2], dtype=np.bool_)
    _bilinear_kernel(planes, flow_p, out, inside)
    return out, inside
