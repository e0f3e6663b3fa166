"""Median filtering of flow fields (Sun, Roth & Black, CVPR 2010 / IJCV 2014).

Applied to each flow component after every warping step; it removes outliers of
the linearised solution and is the heuristic behind much of the accuracy of
modern TV-L1 implementations.  Borders replicate the edge pixels.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from scipy import ndimage

from ._median_network import median25

__all__ = ["median_filter_flow", "median_filter_flow_numpy"]


def median_filter_flow_numpy(flow: np.ndarray, size: int = 5) -> np.ndarray:
    """Reference implementation with :func:`scipy.ndimage.median_filter`."""
    out = np.empty_like(flow, dtype=np.float32)
    for c in range(flow.shape[2]):
        out[..., c] = ndimage.median_filter(flow[..., c], size=size, mode="nearest")
    return out


@nb.njit(cache=True, inline="always")
def _select(buf, n, k):
    """k-th smallest of buf[:n] in place (Wirth's selection, average O(n))."""
    lo = 0
    hi = n - 1
    while lo < hi:
        x = buf[k]
        i = lo
        j = hi
        while True:
            while buf[i] < x:
                i += 1
            while x < buf[j]:
                j -= 1
            if i <= j:
                t = buf[i]
                buf[i] = buf[j]
                buf[j] = t
                i += 1
                j -= 1
            if i > j:
                break
        if j < k:
            lo = i
        if k < i:
            hi = j
    return buf[k]


@nb.njit(cache=True, parallel=True)
def _median_kernel(src, out, size):
    h, w, k = src.shape
    r = size // 2
    n = size * size
    half = n // 2
    for i in nb.prange(h):
        buf = np.empty(n, np.float32)
        for c in range(k):
            for j in range(w):
                m = 0
                for di in range(-r, r + 1):
                    ii = min(max(i + di, 0), h - 1)
                    for dj in range(-r, r + 1):
                        jj = min(max(j + dj, 0), w - 1)
                        buf[m] = src[ii, jj, c]
                        m += 1
                out[i, j, c] = _select(buf, n, half)


@nb.njit(cache=True, parallel=True, fastmath=True)
def _median5_kernel(src, out):
    h, w, k = src.shape
    for i in nb.prange(h):
        r0 = max(i - 2, 0)
        r1 = max(i - 1, 0)
        r2 = i
        r3 = min(i + 1, h - 1)
        r4 = min(i + 2, h - 1)
        for j in range(w):
            c0 = max(j - 2, 0)
            c1 = max(j - 1, 0)
            c2 = j
            c3 = min(j + 1, w - 1)
            c4 = min(j + 2, w - 1)
            for c in range(k):
                out[i, j, c] = median25(
                    src[r0, c0, c], src[r0, c1, c], src[r0, c2, c], src[r0, c3, c], src[r0, c4, c],
                    src[r1, c0, c], src[r1, c1, c], src[r1, c2, c], src[r1, c3, c], src[r1, c4, c],
                    src[r2, c0, c], src[r2, c1, c], src[r2, c2, c], src[r2, c3, c], src[r2, c4, c],
                    src[r3, c0, c], src[r3, c1, c], src[r3, c2, c], src[r3, c3, c], src[r3, c4, c],
                    src[r4, c0, c], src[r4, c1, c], src[r4, c2, c], src[r4, c3, c], src[r4, c4, c],
                )


def median_filter_flow(flow: np.ndarray, size: int = 5) -> np.ndarray:
    """Median-filter each flow component over a ``size x size`` window.

    Parameters
    ----------
    flow : ndarray, shape (H, W, K), float32
    size : int
        Odd window size (the literature uses 5).

    Returns
    -------
    ndarray, shape (H, W, K), float32
    """
    if size < 1 or size % 2 == 0:
        raise ValueError(f"median size must be a positive odd integer, got {size}")
    src = np.ascontiguousarray(flow, dtype=np.float32)
    if size == 1:
        return src.copy()
    out = np.empty_like(src)
    if size == 5:
        _median5_kernel(src, out)
    else:
        _median_kernel(src, out, size)
    return out
