"""Backward warping of images by a flow with bicubic (Keys, a = -0.5) interpolation.

``warp(I, flow)[y, x] = I(y + v(y, x), x + u(y, x))``.  Samples outside the image
are evaluated with the border replicated, and a boolean mask reports which target
points fell inside ``[0, W-1] x [0, H-1]``; the solvers switch the data term off
where the mask is false, so pixels that leave the frame are filled in by the
regulariser instead of by clamped border colours.

Two engines with the same signature: :func:`warp_bicubic_numpy` (the reference)
and the Numba kernel used by :func:`warp_bicubic`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["warp_bicubic", "warp_bicubic_numpy", "keys_weights", "in_bounds"]

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


@nb.njit(cache=True, inline="always")
def _near(t):
    return ((_A + 2.0) * t - (_A + 3.0)) * t * t + 1.0


@nb.njit(cache=True, inline="always")
def _far(t):
    return ((_A * t - 5.0 * _A) * t + 8.0 * _A) * t - 4.0 * _A


# fast-math without the no-NaN/no-inf assumptions: NaN flows must be detected
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@nb.njit(cache=True, parallel=True, fastmath=_FASTMATH)
def _warp_kernel(planes, flow, out, inside):
    h, w, k = planes.shape
    for i in nb.prange(h):
        wx = np.empty(4, np.float32)
        wy = np.empty(4, np.float32)
        xs = np.empty(4, np.int64)
        ys = np.empty(4, np.int64)
        acc = np.empty(k, np.float32)
        for j in range(w):
            x = j + flow[i, j, 0]
            y = i + flow[i, j, 1]
            inside[i, j] = (x >= 0.0) and (x <= w - 1.0) and (y >= 0.0) and (y <= h - 1.0)
            if not (x == x and y == y):  # NaN flow: treat as outside
                x = -2.0
                y = -2.0
            # keep the far-away samples finite and bounded
            x = min(max(x, -2.0), w + 1.0)
            y = min(max(y, -2.0), h + 1.0)
            fx0 = np.floor(x)
            fy0 = np.floor(y)
            fx = x - fx0
            fy = y - fy0
            wx[0] = _far(1.0 + fx)
            wx[1] = _near(fx)
            wx[2] = _near(1.0 - fx)
            wx[3] = _far(2.0 - fx)
            wy[0] = _far(1.0 + fy)
            wy[1] = _near(fy)
            wy[2] = _near(1.0 - fy)
            wy[3] = _far(2.0 - fy)
            ix0 = np.int64(fx0)
            iy0 = np.int64(fy0)
            for n in range(4):
                xs[n] = min(max(ix0 + n - 1, 0), w - 1)
                ys[n] = min(max(iy0 + n - 1, 0), h - 1)
            # taps outer, channels inner: the K planes of a tap are contiguous
            for c in range(k):
                acc[c] = 0.0
            for m in range(4):
                ym = ys[m]
                for n in range(4):
                    wt = wy[m] * wx[n]
                    xn = xs[n]
                    for c in range(k):
                        acc[c] += wt * planes[ym, xn, c]
            for c in range(k):
                out[i, j, c] = acc[c]


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
    flow = np.ascontiguousarray(flow, dtype=np.float32)
    if planes.ndim != 3 or flow.shape != planes.shape[:2] + (2,):
        raise ValueError(f"warp: planes {planes.shape} and flow {flow.shape} do not match")
    out = np.empty_like(planes)
    inside = np.empty(planes.shape[:2], dtype=np.bool_)
    _warp_kernel(planes, flow, out, inside)
    return out, inside
