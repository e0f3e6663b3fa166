"""Median filtering of flow fields (Sun, Roth & Black, CVPR 2010 / IJCV 2014).

Applied to each flow component after every warping step; it removes outliers of
the linearised solution and is the heuristic behind much of the accuracy of
modern TV-L1 implementations.  Borders replicate the edge pixels.

The weighted (non-local) median of the same papers replaces the plain median near
motion boundaries: each neighbour's vote is weighted by its distance and its
colour difference to the centre pixel in the first frame, so the flow of one
surface does not bleed across an image edge into the next
(:func:`weighted_median_flow`, :func:`flow_edge_mask`).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from scipy import ndimage

from .._jit import FASTMATH, FASTMATH_NO_REASSOC, await_kernel
from ._median_network import median25
from .fusion import _exp_neg_row

__all__ = [
    "median_filter_flow",
    "median_filter_flow_numpy",
    "flow_edge_mask",
    "flow_edge_mask_numpy",
    "weighted_median_flow",
    "weighted_median_flow_numpy",
    "flow_visibility",
    "EDGE_DILATION",
]

#: Half-side, in pixels, of the square by which :func:`flow_edge_mask` grows the
#: flow edges (a 5 x 5 dilation, as in Sun, Roth & Black's fast variant).
EDGE_DILATION = 2


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


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _median5_kernel(src, out):
    """5x5 median of planar ``(K, H, W)`` data with replicated borders.

    The five rows of a window are copied into rows padded with two replicated
    values at each end; 25 shifted 1-D views of them, indexed by the loop variable
    only, feed the comparator network, which vectorises across the row.  Every
    column, borders included, goes through that one loop (one copy of the network
    to compile).
    """
    k, h, w = src.shape
    for r in nb.prange(k * h):
        c = r // h
        i = r - c * h
        pad = np.empty((5, w + 4), np.float32)
        for q in range(5):
            s = src[c, min(max(i + q - 2, 0), h - 1)]
            row = pad[q]
            row[0] = s[0]
            row[1] = s[0]
            row[2:w + 2] = s
            row[w + 2] = s[w - 1]
            row[w + 3] = s[w - 1]
        s0 = pad[0]
        s1 = pad[1]
        s2 = pad[2]
        s3 = pad[3]
        s4 = pad[4]
        a0, a1, a2, a3, a4 = s0[0:w], s0[1 : w + 1], s0[2 : w + 2], s0[3 : w + 3], s0[4 : w + 4]
        b0, b1, b2, b3, b4 = s1[0:w], s1[1 : w + 1], s1[2 : w + 2], s1[3 : w + 3], s1[4 : w + 4]
        d0, d1, d2, d3, d4 = s2[0:w], s2[1 : w + 1], s2[2 : w + 2], s2[3 : w + 3], s2[4 : w + 4]
        e0, e1, e2, e3, e4 = s3[0:w], s3[1 : w + 1], s3[2 : w + 2], s3[3 : w + 3], s3[4 : w + 4]
        f0, f1, f2, f3, f4 = s4[0:w], s4[1 : w + 1], s4[2 : w + 2], s4[3 : w + 3], s4[4 : w + 4]
        o = out[c, i]
        for jj in range(w):
            o[jj] = median25(
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


# --------------------------------------------------------------------------- weighted median


def _planar(flow: np.ndarray, name: str = "flow") -> np.ndarray:
    flow = np.asarray(flow)
    if flow.ndim != 3 or flow.shape[2] < 1:
        raise ValueError(f"{name}: expected an (H, W, K) array, got shape {flow.shape}")
    # a view of planar data (what the solvers and median_filter_flow return) is not copied
    return np.ascontiguousarray(np.moveaxis(flow, -1, 0), dtype=np.float32)


def flow_edge_mask_numpy(
    flow: np.ndarray, threshold: float, dilation: int = EDGE_DILATION
) -> np.ndarray:
    """Reference of :func:`flow_edge_mask` in NumPy and SciPy."""
    f = np.asarray(flow, np.float32)
    h, w = f.shape[:2]
    m = np.zeros((h, w), np.float32)
    for c in range(f.shape[2]):
        a = np.pad(f[..., c], 1, mode="edge")
        m += 0.5 * np.abs(a[1:-1, 2:] - a[1:-1, :-2]) + 0.5 * np.abs(a[2:, 1:-1] - a[:-2, 1:-1])
    edge = m >= np.float32(threshold)
    if dilation > 0:
        edge = ndimage.maximum_filter(edge, size=2 * dilation + 1, mode="nearest")
    return edge


@nb.njit(cache=True, parallel=True)
def _edge_kernel(src, thr, out):
    k, h, w = src.shape
    for i in nb.prange(h):
        up = max(i - 1, 0)
        dn = min(i + 1, h - 1)
        for j in range(w):
            lf = max(j - 1, 0)
            rt = min(j + 1, w - 1)
            m = np.float32(0.0)
            for c in range(k):
                m += np.float32(0.5) * abs(src[c, i, rt] - src[c, i, lf])
                m += np.float32(0.5) * abs(src[c, dn, j] - src[c, up, j])
            out[i, j] = 1 if m >= thr else 0


@nb.njit(cache=True, parallel=True)
def _dilate_rows(src, r, out):
    h, w = src.shape
    for i in nb.prange(h):
        for j in range(w):
            v = 0
            for jj in range(max(j - r, 0), min(j + r + 1, w)):
                if src[i, jj]:
                    v = 1
                    break
            out[i, j] = v


@nb.njit(cache=True, parallel=True)
def _dilate_cols(src, r, out):
    h, w = src.shape
    for i in nb.prange(h):
        lo = max(i - r, 0)
        hi = min(i + r + 1, h)
        for j in range(w):
            v = 0
            for ii in range(lo, hi):
                if src[ii, j]:
                    v = 1
                    break
            out[i, j] = v


def _edge_mask_planar(planar: np.ndarray, threshold: float, dilation: int) -> np.ndarray:
    h, w = planar.shape[1:]
    edge = np.empty((h, w), np.uint8)
    _edge_kernel(planar, np.float32(threshold), edge)
    if dilation > 0:
        tmp = np.empty_like(edge)
        _dilate_rows(edge, dilation, tmp)
        _dilate_cols(tmp, dilation, edge)
    return edge


def flow_edge_mask(flow: np.ndarray, threshold: float, dilation: int = EDGE_DILATION) -> np.ndarray:
    """Pixels near motion boundaries: where the flow varies by ``threshold`` or more.

    The measure is ``sum_k |∂x f_k| + |∂y f_k|`` over the flow components, with
    central differences (one-sided halves at the borders, replicated edge); the
    pixels where it reaches ``threshold`` are grown by a square of half-side
    ``dilation``.

    Parameters
    ----------
    flow : ndarray, shape (H, W, K), float
    threshold : float
        Pixels per pixel; 0 marks every pixel.
    dilation : int
        Half-side of the dilation square, pixels (default :data:`EDGE_DILATION`).

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    if threshold < 0 or dilation < 0:
        raise ValueError(
            f"threshold and dilation must be >= 0, got {threshold} and {dilation}"
        )
    return _edge_mask_planar(_planar(flow), threshold, int(dilation)).view(bool)


def _space_weights(radius: int, sigma_space: float) -> np.ndarray:
    d = np.arange(-radius, radius + 1, dtype=np.float64)
    d2 = d[:, None] ** 2 + d[None, :] ** 2
    return np.exp(-d2 / (2.0 * sigma_space**2)).astype(np.float32).ravel()


def _colour_scale(sigma_colour: float, n_channels: int) -> np.float32:
    # the squared colour distance is averaged over the channels
    return np.float32(1.0 / (2.0 * sigma_colour**2 * n_channels))


def flow_visibility(flow: np.ndarray, sigma_divergence: float) -> np.ndarray:
    """Visibility o(x) = exp(-d(x)² / (2 σ_d²)), d = min(div f, 0) (Sun et al. 2014).

    Where the flow converges (negative divergence) a surface is being covered; its
    pixels are likely occluded in the second frame and their flow is unreliable.
    Central differences, replicated edge.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
    sigma_divergence : float
        σ_d, pixels per pixel; 0 returns ones.

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    f = np.asarray(flow, np.float32)
    if sigma_divergence <= 0:
        return np.ones(f.shape[:2], np.float32)
    u = np.pad(f[..., 0], 1, mode="edge")
    v = np.pad(f[..., 1], 1, mode="edge")
    div = 0.5 * (u[1:-1, 2:] - u[1:-1, :-2]) + 0.5 * (v[2:, 1:-1] - v[:-2, 1:-1])
    d = np.minimum(div, 0.0)
    return np.exp(-(d * d) / np.float32(2.0 * sigma_divergence**2)).astype(np.float32)


def _check_weighted(flow, guide, radius, sigma_space, sigma_colour, threshold, base,
                    sigma_divergence=0.0):
    if not (np.isfinite(sigma_divergence) and sigma_divergence >= 0):
        raise ValueError(f"sigma_divergence: must be a finite number >= 0, got {sigma_divergence}")
    if sigma_divergence > 0 and np.shape(flow)[2:] != (2,):
        raise ValueError(f"flow: the visibility weight needs (H, W, 2), got {np.shape(flow)}")
    if radius < 1:
        raise ValueError(f"radius: must be >= 1, got {radius}")
    if not sigma_space > 0:
        raise ValueError(f"sigma_space: must be > 0, got {sigma_space}")
    if not sigma_colour > 0:
        raise ValueError(f"sigma_colour: must be > 0, got {sigma_colour}")
    if threshold < 0:
        raise ValueError(f"threshold: must be >= 0, got {threshold}")
    g = np.asarray(guide, np.float32)
    if g.ndim == 2:
        g = g[..., None]
    if g.ndim != 3 or g.shape[:2] != np.shape(flow)[:2]:
        raise ValueError(
            f"guide: expected (H, W) or (H, W, C) with (H, W) = {np.shape(flow)[:2]}, "
            f"got shape {np.shape(guide)}"
        )
    if base is not None and np.shape(base) != np.shape(flow):
        raise ValueError(f"base: expected shape {np.shape(flow)}, got {np.shape(base)}")
    return g


def weighted_median_flow_numpy(
    flow: np.ndarray,
    guide: np.ndarray,
    radius: int = 3,
    sigma_space: float = 7.0,
    sigma_colour: float = 0.05,
    threshold: float = 0.5,
    base: np.ndarray | None = None,
    sigma_divergence: float = 0.0,
) -> np.ndarray:
    """Reference of :func:`weighted_median_flow`: one pixel at a time, by sorting."""
    g = _check_weighted(flow, guide, radius, sigma_space, sigma_colour, threshold, base,
                        sigma_divergence)
    f = np.asarray(flow, np.float32)
    vis = flow_visibility(f, sigma_divergence)
    out = np.array(f if base is None else base, np.float32, copy=True)
    mask = flow_edge_mask_numpy(f, threshold)
    sw = _space_weights(radius, sigma_space).reshape(2 * radius + 1, 2 * radius + 1)
    sc = _colour_scale(sigma_colour, g.shape[2])
    h, w = mask.shape
    for i, j in zip(*np.nonzero(mask), strict=True):
        i0, i1 = max(i - radius, 0), min(i + radius + 1, h)
        j0, j1 = max(j - radius, 0), min(j + radius + 1, w)
        d2 = np.sum((g[i0:i1, j0:j1] - g[i, j]) ** 2, axis=2, dtype=np.float32)
        wts = sw[i0 - i + radius : i1 - i + radius, j0 - j + radius : j1 - j + radius] * np.exp(
            -d2 * sc
        ) * vis[i0:i1, j0:j1]
        wts = wts.ravel().astype(np.float64)
        half = 0.5 * wts.sum()
        if not half > 0:
            out[i, j] = f[i, j]
            continue
        for c in range(f.shape[2]):
            vals = f[i0:i1, j0:j1, c].ravel()
            order = np.argsort(vals, kind="stable")
            cum = np.cumsum(wts[order])
            out[i, j, c] = vals[order][np.searchsorted(cum, half)]
    return out


@nb.njit(cache=True, fastmath=FASTMATH)
def _weighted_median_padded(v, w, n, half):
    """Smallest v[a] with sum(w[v <= v[a]]) >= half, without branches on the data.

    ``v``, ``w`` hold ``n`` entries, ``n`` a multiple of 4; padding entries are +inf
    with weight 0.  Each candidate's weight below it is a sum over all entries (a
    loop that vectorises); four candidates at a time keep four sums in flight.
    O(n²), faster than sorting or selecting for n up to about 100, where those lose
    their time to mispredicted branches.  Compiled on its own (not inlined) with
    ``reassoc``, which the sums need to vectorise and the caller's flags leave out.
    """
    best = np.float32(np.inf)
    zero = np.float32(0.0)
    for a in range(0, n, 4):
        v0 = v[a]
        v1 = v[a + 1]
        v2 = v[a + 2]
        v3 = v[a + 3]
        s0 = zero
        s1 = zero
        s2 = zero
        s3 = zero
        for b in range(n):
            vb = v[b]
            wb = w[b]
            s0 += wb if vb <= v0 else zero
            s1 += wb if vb <= v1 else zero
            s2 += wb if vb <= v2 else zero
            s3 += wb if vb <= v3 else zero
        if s0 >= half:
            best = min(best, v0)
        if s1 >= half:
            best = min(best, v1)
        if s2 >= half:
            best = min(best, v2)
        if s3 >= half:
            best = min(best, v3)
    return best


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH_NO_REASSOC)
def _weighted_median_kernel(src, guide, vis, pixels, radius, sw, sc, out):
    """Weighted median of planar ``src`` (K, H, W) into ``out`` at flat ``pixels``.

    ``guide`` is planar (C, H, W); ``vis`` (H, W) the neighbours' visibility
    factors; ``sw`` the (2r+1)² spatial weights, ``sc`` the colour scale
    1 / (2 σ_c² C).  Neighbours outside the frame do not vote (weight
    0).  The pixels are split in equal chunks, so edges bunched in a few rows do
    not leave a thread idle.  The colour weights come from the vectorised exp of
    :mod:`varflow.ops.fusion` (whose range reduction needs fast-math without
    ``reassoc``, hence this kernel's flags).
    """
    k, h, w = src.shape
    nc = guide.shape[0]
    side = 2 * radius + 1
    nn = side * side
    n = (nn + 3) // 4 * 4
    m = pixels.shape[0]
    chunk = 256
    for t in nb.prange((m + chunk - 1) // chunk):
        vals = np.empty(n, np.float32)
        wts = np.empty(n, np.float32)
        d2 = np.empty(nn, np.float32)  # the colour exponents, -‖ΔI‖² sc
        fac = np.empty(nn, np.float32)  # visibility x spatial weight, 0 outside the frame
        e = np.empty(nn, np.float32)
        bits = np.empty(nn, np.int32)
        for p in range(t * chunk, min(m, (t + 1) * chunk)):
            i = pixels[p] // w
            j = pixels[p] - i * w
            if i >= radius and i + radius < h and j >= radius and j + radius < w:
                # inside: row slices of the window, loops that vectorise
                d2[:] = np.float32(0.0)
                for c in range(nc):
                    g = guide[c]
                    g0 = g[i, j]
                    for di in range(side):
                        row = g[i - radius + di, j - radius : j + radius + 1]
                        q = di * side
                        for dj in range(side):
                            dg = row[dj] - g0
                            d2[q + dj] -= dg * dg * sc
                for di in range(side):
                    vrow = vis[i - radius + di, j - radius : j + radius + 1]
                    q = di * side
                    for dj in range(side):
                        fac[q + dj] = vrow[dj] * sw[q + dj]
            else:
                # near the border: neighbours outside the frame get weight 0
                for di in range(side):
                    for dj in range(side):
                        ii = i - radius + di
                        jj = j - radius + dj
                        q = di * side + dj
                        d = np.float32(0.0)
                        fac[q] = np.float32(0.0)
                        if 0 <= ii < h and 0 <= jj < w:
                            for c in range(nc):
                                dg = guide[c, ii, jj] - guide[c, i, j]
                                d -= dg * dg * sc
                            fac[q] = vis[ii, jj] * sw[q]
                        d2[q] = d
            _exp_neg_row(d2, e, bits)
            tot = np.float32(0.0)
            for q in range(nn):
                wts[q] = fac[q] * e[q]
                tot += wts[q]
            for q in range(nn, n):
                wts[q] = np.float32(0.0)
            if not tot > 0:
                # every vote is 0 (an invisible neighbourhood): the pixel keeps its value
                for c in range(k):
                    out[c, i, j] = src[c, i, j]
                continue
            half = np.float32(0.5) * tot
            for c in range(k):
                f = src[c]
                for di in range(side):
                    ii = min(max(i - radius + di, 0), h - 1)
                    for dj in range(side):
                        jj = min(max(j - radius + dj, 0), w - 1)
                        q = di * side + dj
                        # outside the frame: weight 0, and +inf keeps it out of the candidates
                        vals[q] = f[ii, jj] if wts[q] > 0 else np.float32(np.inf)
                for q in range(nn, n):
                    vals[q] = np.float32(np.inf)
                out[c, i, j] = _weighted_median_padded(vals, wts, n, half)


def weighted_median_flow(
    flow: np.ndarray,
    guide: np.ndarray,
    radius: int = 3,
    sigma_space: float = 7.0,
    sigma_colour: float = 0.05,
    threshold: float = 0.5,
    base: np.ndarray | None = None,
    sigma_divergence: float = 0.0,
) -> np.ndarray:
    """Weighted (non-local) median of the flow near motion boundaries.

    At each pixel of :func:`flow_edge_mask` (``threshold``), each flow component
    becomes the weighted median of its ``(2r+1)²`` neighbours (the pixel itself
    included) with weights

        w(i, j) = exp(-|i - j|² / (2 σ_s²)) · exp(-‖I(i) - I(j)‖² / (2 σ_c² C)) · o(j),

    the minimiser over û of Σ_j w(i, j) |û - u(j)|, Sun, Roth & Black's non-local
    term; o(j) is the visibility of :func:`flow_visibility` (``sigma_divergence``
    σ_d; 1 when 0), their occlusion factor without its warping-error part.
    Neighbours outside the frame do not vote.
    Elsewhere the result is ``base`` (e.g. the plain median of ``flow``), or
    ``flow`` itself; a pixel whose votes are all 0 keeps its value.

    Parameters
    ----------
    flow : ndarray, shape (H, W, K), float
        The flow to filter (after a warp's solve).
    guide : ndarray, shape (H, W) or (H, W, C), float
        The first frame at the flow's resolution, intensities in [0, 1].
    radius : int
        r, half-side of the window, pixels (default 3: 7 x 7).
    sigma_space : float
        σ_s, pixels (default 7).
    sigma_colour : float
        σ_c, intensity units of the guide; the squared distance is averaged over
        its C channels (default 0.05).
    threshold : float
        Flow-edge threshold of :func:`flow_edge_mask`, pixels per pixel; 0 filters
        every pixel (default 0.5).
    base : ndarray, shape (H, W, K), optional
        The values away from the edges.
    sigma_divergence : float
        σ_d of the visibility factor, pixels per pixel (needs K = 2); 0 leaves it
        out (default 0).

    Returns
    -------
    ndarray, shape (H, W, K), float32
        A view of planar ``(K, H, W)`` data (as :func:`median_filter_flow`).

    References
    ----------
    D. Sun, S. Roth, M. J. Black, "Secrets of optical flow estimation and their
    principles", CVPR 2010; "A quantitative analysis of current practices in
    optical flow estimation and the principles behind them", IJCV 106, 2014.
    """
    g = _check_weighted(flow, guide, radius, sigma_space, sigma_colour, threshold, base,
                        sigma_divergence)
    src = _planar(flow)
    out = np.array(_planar(base, "base") if base is not None else src, copy=True)
    mask = _edge_mask_planar(src, threshold, EDGE_DILATION)
    pixels = np.flatnonzero(mask)
    if pixels.size == 0:
        return np.moveaxis(out, 0, -1)
    vis = flow_visibility(np.moveaxis(src, 0, -1), sigma_divergence)
    await_kernel(f"{__name__}:_weighted_median_kernel")  # a first run's helper has it soon
    _weighted_median_kernel(
        src, np.ascontiguousarray(np.moveaxis(g, -1, 0)), vis, pixels, int(radius),
        _space_weights(radius, sigma_space), _colour_scale(sigma_colour, g.shape[2]), out,
    )
    return np.moveaxis(out, 0, -1)
