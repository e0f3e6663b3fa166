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
    """5x5 median of planar ``(K, H, W)`` data with replicated borders.

    The interior columns go through 25 shifted 1-D row views indexed by the loop
    variable only, so the comparator network vectorises across the row; the two
    border columns on each side use clamped indices.
    """
    k, h, w = src.shape
    for r in nb.prange(k * h):
        c = r // h
        i = r - c * h
        s0 = src[c, max(i - 2, 0)]
        s1 = src[c, max(i - 1, 0)]
        s2 = src[c, i]
        s3 = src[c, min(i + 1, h - 1)]
        s4 = src[c, min(i + 2, h - 1)]
        o = out[c, i]
        for j in list(range(min(2, w))) + list(range(max(w - 2, 2), w)):
            c0 = max(j - 2, 0)
            c1 = max(j - 1, 0)
            c3 = min(j + 1, w - 1)
            c4 = min(j + 2, w - 1)
            o[j] = median25(
                s0[c0], s0[c1], s0[j], s0[c3], s0[c4],
                s1[c0], s1[c1], s1[j], s1[c3], s1[c4],
                s2[c0], s2[c1], s2[j], s2[c3], s2[c4],
                s3[c0], s3[c1], s3[j], s3[c3], s3[c4],
                s4[c0], s4[c1], s4[j], s4[c3], s4[c4],
            )
        n = w - 4
        if n <= 0:
            continue
        a0, a1, a2, a3, a4 = s0[0:n], s0[1 : n + 1], s0[2 : n + 2], s0[3 : n + 3], s0[4 : n + 4]
        b0, b1, b2, b3, b4 = s1[0:n], s1[1 : n + 1], s1[2 : n + 2], s1[3 : n + 3], s1[4 : n + 4]
        d0, d1, d2, d3, d4 = s2[0:n], s2[1 : n + 1], s2[2 : n + 2], s2[3 : n + 3], s2[4 : n + 4]
        e0, e1, e2, e3, e4 = s3[0:n], s3[1 : n + 1], s3[2 : n + 2], s3[3 : n + 3], s3[4 : n + 4]
        f0, f1, f2, f3, f4 = s4[0:n], s4[1 : n + 1], s4[2 : n + 2], s4[3 : n + 3], s4[4 : n + 4]
        oc = o[2 : n + 2]
        for jj in range(n):
            oc[jj] = median25(
                a0[jj], a1[jj], a2[jj], a3[jj], a4[jj],
                b0[jj], b1[jj], b2[jj], b3[jj], b4[jj],
                d0[jj], d1[jj], d2[jj], d3[jj], d4[jj],
                e0[jj], e1[jj], e2[jj], e3[jj], e4[jj],
                f0[jj], f1[jj], f2[jj], f3[jj], f4[jj],
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
        For ``size`` 5, a view of planar ``(K, H, W)`` data (not C-contiguous).
    """
    if size < 1 or size % 2 == 0:
        raise ValueError(f"median size must be a positive odd integer, got {size}")
    if size == 5:
        # planar in and out; a flow that is a view of planar data (the TV-L1 solvers
        # return one) is read without a copy, and the result is such a view too
        planar = np.ascontiguousarray(np.moveaxis(flow, -1, 0), dtype=np.float32)
        res = np.empty_like(planar)
        _median5_kernel(planar, res)
        return np.moveaxis(res, 0, -1)
    src = np.ascontiguousarray(flow, dtype=np.float32)
    if size == 1:
        return src.copy()
    out = np.empty_like(src)
    _median_kernel(src, out, size)
    return out
