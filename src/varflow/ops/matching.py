"""Large-displacement correspondences by coarse-to-fine PatchMatch on a seed grid (CPM).

Coarse-to-fine warping follows motions of a few pixels per pyramid level; fast
objects (30–150 px per frame) are lost before the finest level is reached.  This
module finds sparse but reliable matches for such motions in the manner of CPM
(Hu, Song & Li 2016), to be densified by an edge-aware interpolation and refined
by a variational solver.

Algorithm
---------
1. **Descriptors.**  A dense SIFT-like descriptor per pixel (Lowe 2004; the dense
   variant of SIFT Flow, Liu et al. 2011): the luminance gradient magnitude is
   split into ``orientations`` planes by linear interpolation between orientation
   bins, each plane is filtered with a separable triangle of half-width
   ``cell_size`` (the bilinear spatial binning of SIFT), and the planes are read at
   the centres of a ``cells × cells`` grid of cells around the pixel, weighted by a
   Gaussian of σ = half the descriptor width.  The vector is L2-normalised,
   clipped at ``clip``, renormalised and quantised to ``uint8``
   (``round(512 v)``, at most 255): ``cells² · orientations`` bytes per pixel
   (128 for the default 4 × 4 × 8).
2. **Seeds.**  Frame 0 is covered by a grid of seeds with spacing ``step`` (d),
   the first one at ``(d // 2, d // 2)``.  On the pyramid (factor 1/2 per level,
   ``levels`` = k levels, descriptors recomputed per level) the same seeds are
   placed at their scaled positions, rounded to pixels.
3. **PatchMatch on the seed graph, coarse to fine.**  The matching cost of an
   integer displacement ``w`` at seed ``s`` is the SAD (L1 distance) of the
   descriptors ``D0(s)`` and ``D1(s + w)``; targets are kept inside the image
   (the displacement is clamped).  At the coarsest level the displacements start
   at random in ``[-R, R]²`` with ``R`` = ``max_displacement`` scaled to that
   level; at every finer level they start from the coarser result scaled by 2.
   Each of ``iterations`` (n) sweeps visits the seeds in raster order (odd sweeps
   in reverse order) and tries (a) the displacements of the two neighbouring seeds
   already visited in this sweep (propagation) and (b) random displacements
   around the current best at radii ``R, R/2, R/4, …, 1`` (random search, α = 1/2),
   with ``R`` = ``search_radius`` (r) below the coarsest level, which limits how
   far a finer level may depart from the coarser one.
4. **Sub-pixel.**  At the finest level an equiangular (V-shaped) fit of the SAD
   at ``w ± 1`` along each axis (Shimizu & Okutomi 2001) gives a fractional
   offset in ``[-1/2, 1/2]``.
5. **Forward-backward consistency.**  The same procedure matches frame 1 to
   frame 0 on the same grid; a forward match ``w`` of a seed ``p`` is kept when
   the backward displacement ``b`` of at least one of the four backward seeds
   around the arrival point ``p + w`` satisfies ``|w + b| <= fb_threshold``
   (CPM keeps the matches that pass this cross check).  Optionally seeds with a
   mean per-dimension descriptor difference above ``max_cost`` are dropped too.

Determinism: the random numbers are a counter-based hash (SplitMix64 finaliser)
of ``(seed, level, direction, sweep, seed index, trial)``, so results do not
depend on the thread count or on earlier calls.  PatchMatch is sequential; the
forward and backward problems run in parallel (two threads), the descriptor
kernel in parallel over rows.

Two engines with the same results: ``engine="numba"`` (the kernels) and
``engine="numpy"`` (a Python/NumPy reference of the same algorithm, slow, for
tests on small images).  Both use the same integer costs and random numbers, so
the integer matches are identical and the sub-pixel offsets agree to rounding.

References
----------
Y. Hu, R. Song, Y. Li, "Efficient coarse-to-fine PatchMatch for large displacement
optical flow", CVPR 2016.

C. Barnes, E. Shechtman, A. Finkelstein, D. B. Goldman, "PatchMatch: a randomized
correspondence algorithm for structural image editing", SIGGRAPH 2009.

D. G. Lowe, "Distinctive image features from scale-invariant keypoints", IJCV 60(2),
2004.

C. Liu, J. Yuen, A. Torralba, "SIFT Flow: dense correspondence across scenes and its
applications", IEEE TPAMI 33(5), 2011.

M. Shimizu, M. Okutomi, "Precise sub-pixel estimation on area-based matching",
ICCV 2001.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np
from scipy import ndimage

from .._validate import as_float_image
from .pyramid import build_pyramid

__all__ = ["MatchParams", "Matches", "match", "descriptors", "seed_grid"]

logger = logging.getLogger(__name__)

#: Added to the descriptor norm so that flat regions get small (not amplified) vectors.
_NORM_EPS = np.float32(1e-3)
#: Quantisation of the unit-norm descriptor: ``min(255, round(512 v))`` as in SIFT.
_QUANT = np.float32(512.0)
_MASK64 = (1 << 64) - 1
#: Luminance weights (ITU-R BT.601) for colour frames.
_LUMA = np.array([0.299, 0.587, 0.114], np.float32)


# ------------------------------------------------------------------------ parameters
@dataclass(frozen=True)
class MatchParams:
    """Parameters of :func:`match` (symbols of Hu, Song & Li 2016 in brackets).

    Attributes
    ----------
    step : int
        d, spacing of the seed grid in frame 0, pixels.  Default 3.
    levels : int
        k, number of pyramid levels (factor 1/2 per level).  Fewer are used when the
        coarsest level would be smaller than ``min_level_size``.  Default 4 (the
        default ``max_displacement`` becomes a 20 px search radius at 1/8 size).
    max_displacement : float
        Largest expected motion, pixels at full resolution: the random
        initialisation and random search radius at the coarsest level is this
        value scaled to that level.  Default 160.
    iterations : int
        n, PatchMatch sweeps (propagation + random search) per level.  Default 6.
    search_radius : int
        r, random-search radius at the levels below the coarsest, pixels of the
        level; it bounds how far a level departs from the coarser result.  Default 4.
    wide_iterations : int
        At the levels below the coarsest, the first ``wide_iterations`` sweeps search
        at radii from ``max_displacement`` (scaled to the level) down, as plain
        PatchMatch does, before the ``search_radius`` sweeps.  A structure smaller
        than the descriptor at the coarse levels (a thin limb, a small fast object)
        takes its surroundings' motion there; the wide sweeps let it find its own
        at the level where it is resolved, and propagation spreads the match over
        it.  0 gives CPM's search.  Default 2.
    fb_threshold : float
        Forward-backward consistency threshold, pixels at full resolution: a match
        is kept when ``|w + b| <=`` this value.  ``inf`` disables the check.
        Default 3.
    max_cost : float or None
        Drop matches whose cost (mean absolute descriptor difference per
        dimension, quantised units 0–255) exceeds this value.  Default None (off).
    cells : int
        Cells per side of the descriptor grid (4 gives SIFT's 4 × 4).  Default 4.
    cell_size : int
        Width of a descriptor cell, pixels of each level.  Default 3.
    orientations : int
        Orientation bins of the gradient histogram.  Default 8.
    gradient_sigma : float
        σ of the Gaussian smoothing before the gradient, pixels; 0 for none.
        Default 1.
    clip : float
        Clipping of the normalised descriptor components (SIFT's 0.2), in (0, 1].
    subpixel : bool
        Sub-pixel refinement of the finest-level matches.  Default True.
    min_level_size : int
        Smallest side of the coarsest pyramid level, pixels.  Default 16.
    seed : int
        Seed of the random search (non-negative).  Default 0.
    """

    step: int = 3
    levels: int = 4
    max_displacement: float = 160.0
    iterations: int = 6
    search_radius: int = 4
    wide_iterations: int = 2
    fb_threshold: float = 3.0
    max_cost: float | None = None
    cells: int = 4
    cell_size: int = 3
    orientations: int = 8
    gradient_sigma: float = 1.0
    clip: float = 0.2
    subpixel: bool = True
    min_level_size: int = 16
    seed: int = 0

    def __post_init__(self) -> None:
        def need_int(name: str, lo: int, hi: int | None = None) -> None:
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, int | np.integer):
                raise ValueError(f"{name}: must be an integer, got {val!r}")
            if val < lo or (hi is not None and val > hi):
                rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
                raise ValueError(f"{name}: must be {rng}, got {val}")

        def need_float(name: str, lo: float, hi: float = math.inf, *, strict: bool = True,
                       allow_inf: bool = False) -> None:
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, int | float | np.number):
                raise ValueError(f"{name}: must be a number, got {val!r}")
            val = float(val)
            if math.isnan(val) or (math.isinf(val) and not allow_inf):
                raise ValueError(f"{name}: must be finite, got {val}")
            if (val <= lo if strict else val < lo) or val > hi:
                op = ">" if strict else ">="
                raise ValueError(f"{name}: must be {op} {lo} and <= {hi}, got {val}")

        need_int("step", 1)
        need_int("levels", 1, 12)
        need_float("max_displacement", 0.0)
        need_int("iterations", 1, 1000)
        need_int("search_radius", 0)
        need_int("wide_iterations", 0, 1000)
        need_float("fb_threshold", 0.0, strict=False, allow_inf=True)
        if self.max_cost is not None:
            need_float("max_cost", 0.0, strict=False)
        need_int("cells", 1, 8)
        need_int("cell_size", 1, 64)
        need_int("orientations", 2, 32)
        need_float("gradient_sigma", 0.0, 20.0, strict=False)
        need_float("clip", 0.0, 1.0)
        if not isinstance(self.subpixel, bool | np.bool_):
            raise ValueError(f"subpixel: must be a bool, got {self.subpixel!r}")
        need_int("min_level_size", 2)
        need_int("seed", 0, 2**63 - 1)
        if self.cells**2 * self.orientations > 1024:
            raise ValueError(
                f"cells: descriptor of cells**2 * orientations = "
                f"{self.cells**2 * self.orientations} > 1024 dimensions"
            )

    @property
    def dims(self) -> int:
        """Descriptor length ``cells² · orientations``."""
        return self.cells**2 * self.orientations


class Matches(NamedTuple):
    """Result of :func:`match`.

    Attributes
    ----------
    points : ndarray, shape (N, 2), float32
        ``(x, y)`` positions in frame 0 of the kept seeds (raster order).
    flow : ndarray, shape (N, 2), float32
        ``(u, v)`` displacement: the match of ``points[i]`` is ``points[i] + flow[i]``.
    cost : ndarray, shape (N,), float32
        Mean absolute descriptor difference per dimension at the integer match
        (quantised units, 0–255).
    grid_flow : ndarray, shape (gh, gw, 2), float32
        The whole seed grid (seed ``(i, j)`` at ``x = d//2 + j d, y = d//2 + i d``),
        NaN for rejected seeds.
    step : int
        d, the seed spacing.
    """

    points: np.ndarray
    flow: np.ndarray
    cost: np.ndarray
    grid_flow: np.ndarray
    step: int


def _check_engine(engine: str) -> None:
    if engine not in ("numba", "numpy"):
        raise ValueError(f"engine: must be 'numba' or 'numpy', got {engine!r}")


# ------------------------------------------------------------------------ descriptors
def _luminance(img: np.ndarray) -> np.ndarray:
    """``(H, W, C)`` float32 -> ``(H, W)`` luminance (BT.601 for 3 channels, else mean)."""
    if img.shape[2] == 3:
        return np.ascontiguousarray(img @ _LUMA, dtype=np.float32)
    return np.ascontiguousarray(img.mean(axis=2), dtype=np.float32)


def _triangle_taps(cell_size: int) -> np.ndarray:
    """Triangle of half-width ``cell_size`` (the bilinear binning weights), unit sum."""
    t = np.arange(-(cell_size - 1), cell_size, dtype=np.float64)
    k = cell_size - np.abs(t)
    return (k / k.sum()).astype(np.float32)


def _orientation_planes(lum: np.ndarray, p: MatchParams, engine: str = "numpy") -> np.ndarray:
    """Spatially binned orientation planes, ``(H, W, orientations)`` float32.

    Gradient magnitude split between the two nearest of ``orientations`` bins over
    ``[0, 2π)``, then filtered with the separable triangle of :func:`_triangle_taps`
    (edge values repeated).  ``engine="numba"`` bins and filters in
    :func:`_bin_filter_kernel`, bit-identical to the SciPy filters of the reference.
    """
    g = lum
    if p.gradient_sigma > 0:
        g = ndimage.gaussian_filter(lum, p.gradient_sigma, mode="nearest")
    gp = np.pad(g, 1, mode="edge")
    gx = 0.5 * (gp[1:-1, 2:] - gp[1:-1, :-2])
    gy = 0.5 * (gp[2:, 1:-1] - gp[:-2, 1:-1])
    mag = np.hypot(gx, gy).astype(np.float32)
    n = p.orientations
    b = (np.arctan2(gy, gx) % (2.0 * np.pi)) * (n / (2.0 * np.pi))
    b0 = np.floor(b)
    f = (b - b0).astype(np.float32)
    b0 = b0.astype(np.int64) % n
    taps = _triangle_taps(p.cell_size)
    if engine == "numba":
        out = np.empty(lum.shape + (n,), np.float32)
        _bin_filter_kernel(mag, f, b0, taps, out)
        return out
    b1 = (b0 + 1) % n
    h, w = lum.shape
    planes = np.zeros((h * w, n), np.float32)
    idx = np.arange(h * w)
    planes[idx, b0.ravel()] = (mag * (1.0 - f)).ravel()
    planes[idx, b1.ravel()] = (mag * f).ravel()  # b1 != b0: no overlap
    planes = planes.reshape(h, w, n)
    planes = ndimage.correlate1d(planes, taps, axis=0, mode="nearest")
    planes = ndimage.correlate1d(planes, taps, axis=1, mode="nearest")
    return np.ascontiguousarray(planes, dtype=np.float32)


@nb.njit(cache=True, parallel=True)
def _bin_filter_kernel(mag, frac, b0, taps, out):
    """Orientation binning and the separable triangle filter of :func:`_orientation_planes`.

    ``mag``, ``frac`` (float32) and ``b0`` (int64, in ``[0, n)``) are ``(H, W)``: pixel
    ``(i, j)`` puts ``mag (1 - frac)`` in bin ``b0`` and ``mag frac`` in bin
    ``b0 + 1 (mod n)``.  ``taps`` is symmetric, of odd length ``2r + 1``.  Each pass
    sums in float64 in the order of ``scipy.ndimage.correlate1d`` for a symmetric
    filter (centre tap, then the pairs from the outermost in) and rounds to float32,
    so ``out`` ``(H, W, n)`` equals the reference bit for bit.  Rows are in parallel;
    the flattened ``(W · n)`` rows make the inner loops contiguous.
    """
    h, w, n = out.shape
    r = taps.shape[0] // 2
    m = w * n
    raw = np.empty((h, m), np.float32)
    tmp = np.empty((h, m), np.float32)
    res = out.reshape(h, m)
    one = np.float32(1.0)
    t = taps.astype(np.float64)
    for i in nb.prange(h):
        row = raw[i]
        for q in range(m):
            row[q] = 0.0
        for j in range(w):
            k = b0[i, j]
            k1 = k + 1 if k + 1 < n else 0
            row[j * n + k] = mag[i, j] * (one - frac[i, j])
            row[j * n + k1] = mag[i, j] * frac[i, j]
    for i in nb.prange(h):  # vertical pass
        c = raw[i]
        acc = np.empty(m, np.float64)
        for q in range(m):
            acc[q] = np.float64(c[q]) * t[r]
        for s in range(r, 0, -1):
            a = raw[max(i - s, 0)]
            b = raw[min(i + s, h - 1)]
            ts = t[r - s]
            for q in range(m):
                acc[q] += (np.float64(a[q]) + np.float64(b[q])) * ts
        dst = tmp[i]
        for q in range(m):
            dst[q] = np.float32(acc[q])
    lo = min(r, w) * n  # horizontal pass: interior columns need no clamping
    hi = max(w - r, lo // n) * n
    for i in nb.prange(h):
        c = tmp[i]
        dst = res[i]
        for q in range(lo, hi):
            v = np.float64(c[q]) * t[r]
            for s in range(r, 0, -1):
                v += (np.float64(c[q - s * n]) + np.float64(c[q + s * n])) * t[r - s]
            dst[q] = np.float32(v)
        for j in range(w):
            if lo <= j * n < hi:
                continue
            for o in range(n):
                v = np.float64(c[j * n + o]) * t[r]
                for s in range(r, 0, -1):
                    a = c[max(j - s, 0) * n + o]
                    b = c[min(j + s, w - 1) * n + o]
                    v += (np.float64(a) + np.float64(b)) * t[r - s]
                dst[j * n + o] = np.float32(v)


def _cell_layout(p: MatchParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer ``(dy, dx)`` of the cell centres (row-major cells) and their Gaussian weights.

    Centres at ``floor((i − (cells − 1)/2) · cell_size)``: for an even number of odd
    cells the descriptor is centred half a pixel up-left of the pixel, the same in
    both frames, so displacements are unaffected.
    """
    c = np.floor((np.arange(p.cells) - (p.cells - 1) / 2.0) * p.cell_size).astype(np.int64)
    dy, dx = np.meshgrid(c, c, indexing="ij")
    centre = (np.arange(p.cells) - (p.cells - 1) / 2.0) * p.cell_size
    cy, cx = np.meshgrid(centre, centre, indexing="ij")
    sigma = 0.5 * p.cells * p.cell_size
    wt = np.exp(-(cx**2 + cy**2) / (2.0 * sigma**2))
    return dy.ravel(), dx.ravel(), wt.ravel().astype(np.float32)


def _describe_numpy(planes: np.ndarray, dy: np.ndarray, dx: np.ndarray, wt: np.ndarray,
                    clip: np.float32) -> np.ndarray:
    """Reference of :func:`_describe_kernel`: float32, the same summation order."""
    h, w, n = planes.shape
    nc = len(dy)
    d = nc * n
    v = np.empty((h, w, d), np.float32)
    rows = np.arange(h)
    cols = np.arange(w)
    eps, quant, one, half = _NORM_EPS, _QUANT, np.float32(1.0), np.float32(0.5)
    for rep in range(2):  # normalise, clip, normalise again
        acc = np.zeros((h, w, n), np.float32)
        for c in range(nc):
            if rep == 0:
                yi = np.clip(rows + dy[c], 0, h - 1)
                xi = np.clip(cols + dx[c], 0, w - 1)
                v[:, :, c * n:(c + 1) * n] = wt[c] * planes[yi][:, xi]
            blk = v[:, :, c * n:(c + 1) * n]
            acc += blk * blk
        s = np.zeros((h, w), np.float32)
        for o in range(n):
            s += acc[:, :, o]
        inv = one / (np.sqrt(s) + eps)
        v *= inv[:, :, None]
        if rep == 0:
            np.minimum(v, clip, out=v)
    q = np.minimum(np.floor(v * quant + half), np.float32(255.0))
    return q.astype(np.uint8)


#: Pixels per work item of :func:`_describe_kernel`: its ``dims × _DESC_BLOCK``
#: float32 buffer (16 KiB for 128 dimensions) stays in the L1 cache.
_DESC_BLOCK = 32


@nb.njit(cache=True, parallel=True)
def _describe_kernel(planar, dy, dx, wt, clip, eps, quant, out):
    """Descriptors of :func:`_describe_numpy` from the planar ``(n, H, W)`` planes.

    Work items are runs of ``_DESC_BLOCK`` pixels of a row; the loops run along the
    pixels of the run (contiguous, vectorised) with the per-pixel operations and
    summation order of the reference, so the bytes are identical.
    """
    n, h, w = planar.shape
    nc = dy.shape[0]
    d = nc * n
    one = np.float32(1.0)
    half = np.float32(0.5)
    top = np.float32(255.0)
    blk = _DESC_BLOCK
    nblk = (w + blk - 1) // blk
    for item in nb.prange(h * nblk):
        i = item // nblk
        j0 = (item - i * nblk) * blk
        m = min(blk, w - j0)
        v = np.empty((d, blk), np.float32)
        acc = np.empty((n, blk), np.float32)
        s = np.empty(blk, np.float32)
        for c in range(nc):
            yi = min(max(i + dy[c], 0), h - 1)
            off = dx[c]
            wc = wt[c]
            inner = j0 + off >= 0 and j0 + m - 1 + off <= w - 1
            for o in range(n):
                src = planar[o, yi]
                dst = v[c * n + o]
                if inner:
                    for j in range(m):
                        dst[j] = wc * src[j0 + j + off]
                else:
                    for j in range(m):
                        dst[j] = wc * src[min(max(j0 + j + off, 0), w - 1)]
        for rep in range(2):  # normalise, clip, normalise again
            for o in range(n):
                for j in range(m):
                    acc[o, j] = 0.0
            for c in range(nc):
                for o in range(n):
                    for j in range(m):
                        acc[o, j] += v[c * n + o, j] * v[c * n + o, j]
            for j in range(m):
                s[j] = 0.0
            for o in range(n):
                for j in range(m):
                    s[j] += acc[o, j]
            for j in range(m):
                s[j] = one / (np.sqrt(s[j]) + eps)
            for k in range(d):
                for j in range(m):
                    v[k, j] = v[k, j] * s[j]
                if rep == 0:
                    for j in range(m):
                        v[k, j] = min(v[k, j], clip)
        for j in range(m):
            for k in range(d):
                out[i, j0 + j, k] = np.uint8(min(np.floor(v[k, j] * quant + half), top))


def _describe_planes(planes: np.ndarray, p: MatchParams, engine: str,
                     out: np.ndarray | None = None) -> np.ndarray:
    dy, dx, wt = _cell_layout(p)
    if engine == "numpy":
        res = _describe_numpy(planes, dy, dx, wt, np.float32(p.clip))
        if out is not None:
            out[...] = res
            return out
        return res
    h, w, _ = planes.shape
    if out is None:
        out = np.empty((h, w, p.dims), np.uint8)
    planar = np.ascontiguousarray(planes.transpose(2, 0, 1))
    _describe_kernel(planar, dy, dx, wt, np.float32(p.clip), _NORM_EPS, _QUANT, out)
    return out


def descriptors(image: np.ndarray, params: MatchParams | None = None,
                engine: str = "numba") -> np.ndarray:
    """Dense SIFT-like descriptors of one image (step 1 of the module notes).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        ``uint8``/``uint16`` or float in [0, 1]; colour images use the luminance.
    params : MatchParams, optional
        ``cells``, ``cell_size``, ``orientations``, ``gradient_sigma`` and ``clip``
        are used.
    engine : {"numba", "numpy"}

    Returns
    -------
    ndarray, shape (H, W, cells² · orientations), uint8
        Quantised unit-norm descriptors (``round(512 v)``, at most 255); component
        ``c · orientations + o`` is orientation bin ``o`` of cell ``c`` (row-major).
    """
    _check_engine(engine)
    p = MatchParams() if params is None else params
    img = as_float_image(image, "image")
    return _describe_planes(_orientation_planes(_luminance(img), p, engine), p, engine)


# ------------------------------------------------------------------------------ seeds
def seed_grid(shape: tuple[int, int], step: int) -> tuple[np.ndarray, np.ndarray]:
    """Seed coordinates of an image of ``shape = (H, W)``: ``x = d//2 + j d``, ``y = d//2 + i d``.

    Returns
    -------
    xs : ndarray, shape (gw,), int64
    ys : ndarray, shape (gh,), int64
    """
    h, w = shape
    off = step // 2
    return np.arange(off, w, step, dtype=np.int64), np.arange(off, h, step, dtype=np.int64)


def _level_step(step: int, full: tuple[int, int], shape: tuple[int, int]) -> int:
    """Seed spacing at a level: ``d`` scaled to the level, rounded, at least 1 pixel."""
    ratio = 0.5 * (shape[0] / full[0] + shape[1] / full[1])
    return max(1, int(math.floor(step * ratio + 0.5)))


def _grid(xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    sy, sx = np.meshgrid(ys, xs, indexing="ij")
    return np.ascontiguousarray(sx), np.ascontiguousarray(sy)


def _upsample_init(flow: np.ndarray, coarse: tuple[int, int], step_c: int,
                   xs: np.ndarray, ys: np.ndarray, fine: tuple[int, int]) -> np.ndarray:
    """Initial displacements of the seeds ``xs × ys`` of a finer level from the coarser grid.

    Each fine seed takes the displacement of the nearest coarse seed (pixel-centre
    mapping), scaled by the size ratio of the levels and rounded.

    Returns
    -------
    ndarray, shape (2, len(ys), len(xs), 2), int64
    """
    hc, wc = coarse
    hf, wf = fine
    off = step_c // 2
    gh_c, gw_c = flow.shape[1:3]
    xc = (xs + 0.5) * (wc / wf) - 0.5
    yc = (ys + 0.5) * (hc / hf) - 0.5
    jc = np.clip(np.rint((xc - off) / step_c), 0, gw_c - 1).astype(np.int64)
    ic = np.clip(np.rint((yc - off) / step_c), 0, gh_c - 1).astype(np.int64)
    out = flow[:, ic][:, :, jc].astype(np.float64)
    out[..., 0] *= wf / wc
    out[..., 1] *= hf / hc
    return np.rint(out).astype(np.int64)


def _level_shapes(shape: tuple[int, int], p: MatchParams) -> list[tuple[int, int]]:
    h, w = shape
    shapes = [(h, w)]
    for lev in range(1, p.levels):
        hl, wl = int(round(h * 0.5**lev)), int(round(w * 0.5**lev))
        if min(hl, wl) < p.min_level_size:
            break
        shapes.append((hl, wl))
    return shapes


# ---------------------------------------------------------------- random numbers (hash)
def _splitmix_py(x: int) -> int:
    z = (x + 0x9E3779B97F4A7C15) & _MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


def _rand_py(key: int, a: int, b: int) -> int:
    return _splitmix_py(key ^ ((a & 0xFFFFFFFF) << 32) ^ (b & 0xFFFFFFFF))


@nb.njit(cache=True, inline="always")
def _rand_nb(key, a, b):
    x = key ^ (np.uint64(a & 0xFFFFFFFF) << np.uint64(32)) ^ np.uint64(b & 0xFFFFFFFF)
    z = x + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def _level_key(seed: int, level: int, direction: int) -> int:
    return _splitmix_py(_splitmix_py(seed) ^ (level << 8) ^ direction)


# ---------------------------------------------------------------- PatchMatch (NumPy)
def _sad_numpy(src, sy, sx, dst, ty, tx) -> int:
    return int(np.abs(src[sy, sx].astype(np.int32) - dst[ty, tx].astype(np.int32)).sum())


def _patchmatch_numpy(src, dst, sx, sy, flow, cost, n_iter, radius, key, init_random,
                      wide_radius=0, n_wide=0):
    """Reference of :func:`_patchmatch_one` (same visiting order, costs and random numbers)."""
    gh, gw = sx.shape
    h, w = dst.shape[:2]
    ns = gh * gw
    span = 2 * radius + 1
    for idx in range(ns):
        i, j = divmod(idx, gw)
        x0, y0 = int(sx[i, j]), int(sy[i, j])
        if init_random:
            r = _rand_py(key, 0, idx)
            u = (r & 0xFFFFFFFF) % span - radius
            v = (r >> 32) % span - radius
        else:
            u, v = int(flow[i, j, 0]), int(flow[i, j, 1])
        u = min(max(u, -x0), w - 1 - x0)
        v = min(max(v, -y0), h - 1 - y0)
        flow[i, j, 0] = u
        flow[i, j, 1] = v
        cost[i, j] = _sad_numpy(src, y0, x0, dst, y0 + v, x0 + u)
    for it in range(n_iter):
        fwd = it % 2 == 0
        for t in range(ns):
            idx = t if fwd else ns - 1 - t
            i, j = divmod(idx, gw)
            x0, y0 = int(sx[i, j]), int(sy[i, j])
            bu, bv, bc = int(flow[i, j, 0]), int(flow[i, j, 1]), int(cost[i, j])
            step = -1 if fwd else 1
            for ni, nj in ((i, j + step), (i + step, j)):
                if not (0 <= ni < gh and 0 <= nj < gw):
                    continue
                cu = min(max(int(flow[ni, nj, 0]), -x0), w - 1 - x0)
                cv = min(max(int(flow[ni, nj, 1]), -y0), h - 1 - y0)
                if cu == bu and cv == bv:
                    continue
                c = _sad_numpy(src, y0, x0, dst, y0 + cv, x0 + cu)
                if c < bc:
                    bu, bv, bc = cu, cv, c
            rad = wide_radius if it < n_wide else radius
            trial = 0
            while rad >= 1:
                r = _rand_py(key, (it + 1) * 64 + trial, idx)
                sp = 2 * rad + 1
                cu = bu + (r & 0xFFFFFFFF) % sp - rad
                cv = bv + (r >> 32) % sp - rad
                cu = min(max(cu, -x0), w - 1 - x0)
                cv = min(max(cv, -y0), h - 1 - y0)
                if cu != bu or cv != bv:
                    c = _sad_numpy(src, y0, x0, dst, y0 + cv, x0 + cu)
                    if c < bc:
                        bu, bv, bc = cu, cv, c
                rad //= 2
                trial += 1
            flow[i, j, 0] = bu
            flow[i, j, 1] = bv
            cost[i, j] = bc


def _vfit(cm: float, c0: float, cp: float) -> float:
    """Equiangular (V) fit of three costs at -1, 0, +1: the offset of the minimum."""
    top = max(cm, cp)
    if top <= c0:
        return 0.0
    return min(max((cm - cp) / (2.0 * (top - c0)), -0.5), 0.5)


def _subpixel_numpy(src, dst, sx, sy, flow, cost, out):
    gh, gw = sx.shape
    h, w = dst.shape[:2]
    for i in range(gh):
        for j in range(gw):
            x0, y0 = int(sx[i, j]), int(sy[i, j])
            u, v = int(flow[i, j, 0]), int(flow[i, j, 1])
            c0 = float(cost[i, j])
            fu = fv = 0.0
            tx, ty = x0 + u, y0 + v
            if 1 <= tx <= w - 2:
                fu = _vfit(float(_sad_numpy(src, y0, x0, dst, ty, tx - 1)), c0,
                           float(_sad_numpy(src, y0, x0, dst, ty, tx + 1)))
            if 1 <= ty <= h - 2:
                fv = _vfit(float(_sad_numpy(src, y0, x0, dst, ty - 1, tx)), c0,
                           float(_sad_numpy(src, y0, x0, dst, ty + 1, tx)))
            out[i, j, 0] = u + fu
            out[i, j, 1] = v + fv


# ---------------------------------------------------------------- PatchMatch (Numba)
@nb.njit(cache=True, inline="always")
def _sad_nb(src, sy, sx, dst, ty, tx):
    a = src[sy, sx]
    b = dst[ty, tx]
    s = 0
    for k in range(a.shape[0]):
        x = a[k]
        y = b[k]
        s += max(x, y) - min(x, y)
    return s


@nb.njit(cache=True)
def _patchmatch_one(src, dst, sx, sy, flow, cost, n_iter, radius, key, init_random,
                    wide_radius, n_wide):
    gh, gw = sx.shape
    h, w = dst.shape[0], dst.shape[1]
    ns = gh * gw
    span = np.uint64(2 * radius + 1)
    lo32 = np.uint64(0xFFFFFFFF)
    for idx in range(ns):
        i = idx // gw
        j = idx - i * gw
        x0 = sx[i, j]
        y0 = sy[i, j]
        if init_random:
            r = _rand_nb(key, 0, idx)
            u = np.int64((r & lo32) % span) - radius
            v = np.int64((r >> np.uint64(32)) % span) - radius
        else:
            u = np.int64(flow[i, j, 0])
            v = np.int64(flow[i, j, 1])
        u = min(max(u, -x0), w - 1 - x0)
        v = min(max(v, -y0), h - 1 - y0)
        flow[i, j, 0] = u
        flow[i, j, 1] = v
        cost[i, j] = _sad_nb(src, y0, x0, dst, y0 + v, x0 + u)
    for it in range(n_iter):
        fwd = it % 2 == 0
        step = -1 if fwd else 1
        for t in range(ns):
            idx = t if fwd else ns - 1 - t
            i = idx // gw
            j = idx - i * gw
            x0 = sx[i, j]
            y0 = sy[i, j]
            bu = np.int64(flow[i, j, 0])
            bv = np.int64(flow[i, j, 1])
            bc = np.int64(cost[i, j])
            for nbh in range(2):
                ni = i if nbh == 0 else i + step
                nj = j + step if nbh == 0 else j
                if ni < 0 or ni >= gh or nj < 0 or nj >= gw:
                    continue
                cu = min(max(np.int64(flow[ni, nj, 0]), -x0), w - 1 - x0)
                cv = min(max(np.int64(flow[ni, nj, 1]), -y0), h - 1 - y0)
                if cu == bu and cv == bv:
                    continue
                c = _sad_nb(src, y0, x0, dst, y0 + cv, x0 + cu)
                if c < bc:
                    bu = cu
                    bv = cv
                    bc = c
            rad = wide_radius if it < n_wide else radius
            trial = 0
            while rad >= 1:
                r = _rand_nb(key, (it + 1) * 64 + trial, idx)
                sp = np.uint64(2 * rad + 1)
                cu = bu + np.int64((r & lo32) % sp) - rad
                cv = bv + np.int64((r >> np.uint64(32)) % sp) - rad
                cu = min(max(cu, -x0), w - 1 - x0)
                cv = min(max(cv, -y0), h - 1 - y0)
                if cu != bu or cv != bv:
                    c = _sad_nb(src, y0, x0, dst, y0 + cv, x0 + cu)
                    if c < bc:
                        bu = cu
                        bv = cv
                        bc = c
                rad //= 2
                trial += 1
            flow[i, j, 0] = bu
            flow[i, j, 1] = bv
            cost[i, j] = bc


@nb.njit(cache=True, parallel=True)
def _patchmatch_pair(desc, sx, sy, flows, costs, n_iter, radius, keys, init_random,
                     wide_radius, n_wide):
    """Forward (0 -> 1) and backward (1 -> 0) PatchMatch, one thread each."""
    for p in nb.prange(2):
        _patchmatch_one(desc[p], desc[1 - p], sx, sy, flows[p], costs[p], n_iter, radius,
                        keys[p], init_random, wide_radius, n_wide)


@nb.njit(cache=True, inline="always")
def _vfit_nb(cm, c0, cp):
    top = max(cm, cp)
    if top <= c0:
        return 0.0
    return min(max((cm - cp) / (2.0 * (top - c0)), -0.5), 0.5)


@nb.njit(cache=True, parallel=True)
def _subpixel_pair(desc, sx, sy, flows, costs, out):
    gh, gw = sx.shape
    h, w = desc.shape[1], desc.shape[2]
    for t in nb.prange(2 * gh):
        p = t // gh
        i = t - p * gh
        src = desc[p]
        dst = desc[1 - p]
        for j in range(gw):
            x0 = sx[i, j]
            y0 = sy[i, j]
            u = np.int64(flows[p, i, j, 0])
            v = np.int64(flows[p, i, j, 1])
            c0 = np.float64(costs[p, i, j])
            tx = x0 + u
            ty = y0 + v
            fu = 0.0
            fv = 0.0
            if tx >= 1 and tx <= w - 2:
                fu = _vfit_nb(np.float64(_sad_nb(src, y0, x0, dst, ty, tx - 1)), c0,
                              np.float64(_sad_nb(src, y0, x0, dst, ty, tx + 1)))
            if ty >= 1 and ty <= h - 2:
                fv = _vfit_nb(np.float64(_sad_nb(src, y0, x0, dst, ty - 1, tx)), c0,
                              np.float64(_sad_nb(src, y0, x0, dst, ty + 1, tx)))
            out[p, i, j, 0] = u + fu
            out[p, i, j, 1] = v + fv


# ------------------------------------------------------------------ consistency check
def _fb_error(fwd: np.ndarray, bwd: np.ndarray, xs: np.ndarray, ys: np.ndarray,
              step: int) -> np.ndarray:
    """``min |w + b|`` over the four backward seeds around each forward arrival point.

    Parameters
    ----------
    fwd, bwd : ndarray, shape (gh, gw, 2)
        Forward and backward displacements on the same seed grid (full-resolution px).
    xs, ys : ndarray
        Seed coordinates of the grid (:func:`seed_grid`).

    Returns
    -------
    ndarray, shape (gh, gw), float32
    """
    gh, gw = fwd.shape[:2]
    off = step // 2
    qx = xs[None, :] + fwd[..., 0]
    qy = ys[:, None] + fwd[..., 1]
    j0 = np.floor((qx - off) / step).astype(np.int64)
    i0 = np.floor((qy - off) / step).astype(np.int64)
    best = np.full((gh, gw), np.inf, np.float64)
    for di in (0, 1):
        ii = np.clip(i0 + di, 0, gh - 1)
        for dj in (0, 1):
            jj = np.clip(j0 + dj, 0, gw - 1)
            b = bwd[ii, jj]
            err = np.hypot(fwd[..., 0] + b[..., 0], fwd[..., 1] + b[..., 1])
            np.minimum(best, err, out=best)
    return best.astype(np.float32)


# ----------------------------------------------------------------------------- driver
def match(frame0: np.ndarray, frame1: np.ndarray, params: MatchParams | None = None,
          engine: str = "numba") -> Matches:
    """Sparse large-displacement matches from frame 0 to frame 1 (CPM, see the module notes).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        ``uint8``/``uint16`` or float in [0, 1], same shape.  Colour frames are
        matched on their luminance gradients.
    params : MatchParams, optional
        Defaults to ``MatchParams()``.
    engine : {"numba", "numpy"}
        Numba kernels or the (slow) NumPy reference of the same algorithm.

    Returns
    -------
    Matches
        Kept seeds (``points`` (N, 2) ``(x, y)``, ``flow`` (N, 2) ``(u, v)``,
        ``cost`` (N,)), the seed grid ``grid_flow`` (gh, gw, 2) with NaN for the
        rejected seeds, and ``step``.

    Raises
    ------
    ValueError
        On invalid images, different frame shapes or an unknown engine.
    """
    _check_engine(engine)
    p = MatchParams() if params is None else params
    if not isinstance(p, MatchParams):
        raise ValueError(f"params: expected MatchParams, got {type(p).__name__}")
    i0 = as_float_image(frame0, "frame0")
    i1 = as_float_image(frame1, "frame1")
    if i0.shape[:2] != i1.shape[:2]:
        raise ValueError(f"frame1: shape {i1.shape[:2]} differs from frame0 {i0.shape[:2]}")
    h, w = i0.shape[:2]
    t_start = time.perf_counter()

    shapes = _level_shapes((h, w), p)
    nlev = len(shapes)
    lum = [_luminance(i0)[..., None], _luminance(i1)[..., None]]
    pyr = [build_pyramid(x, shapes, 0.5) for x in lum]
    t_pyr = time.perf_counter()

    flows = costs = None
    prev: tuple[tuple[int, int], int] | None = None
    t_desc = t_pm = 0.0
    desc = None
    for lev in range(nlev - 1, -1, -1):
        hl, wl = shapes[lev]
        t0 = time.perf_counter()
        desc = np.empty((2, hl, wl, p.dims), np.uint8)
        for k in range(2):
            planes = _orientation_planes(pyr[k][lev][..., 0], p, engine)
            _describe_planes(planes, p, engine, out=desc[k])
        t1 = time.perf_counter()
        step_l = p.step if lev == 0 else _level_step(p.step, (h, w), (hl, wl))
        xs, ys = seed_grid((hl, wl), step_l)
        sx, sy = _grid(xs, ys)
        top = prev is None
        scale = 0.5 * (wl / w + hl / h)
        wide = int(min(math.ceil(p.max_displacement * scale), max(hl, wl)))
        if prev is None:
            flows = np.zeros((2, len(ys), len(xs), 2), np.int64)
            radius, n_wide = wide, 0
        else:
            flows = _upsample_init(flows, prev[0], prev[1], xs, ys, (hl, wl))
            radius, n_wide = p.search_radius, min(p.wide_iterations, p.iterations)
        costs = np.zeros(flows.shape[:3], np.int64)
        prev = ((hl, wl), step_l)
        keys = [_level_key(p.seed, lev, k) for k in range(2)]
        if engine == "numpy":
            for k in range(2):
                _patchmatch_numpy(desc[k], desc[1 - k], sx, sy, flows[k], costs[k],
                                  p.iterations, radius, keys[k], top, wide, n_wide)
        else:
            _patchmatch_pair(desc, sx, sy, flows, costs, p.iterations, radius,
                             np.array(keys, np.uint64), top, wide, n_wide)
        t2 = time.perf_counter()
        t_desc += t1 - t0
        t_pm += t2 - t1
        logger.debug("level %d (%dx%d, %d seeds): descriptors %.3fs, patchmatch %.3fs "
                     "(radius %d)", lev, wl, hl, sx.size, t1 - t0, t2 - t1, radius)

    assert desc is not None and flows is not None and costs is not None
    gh, gw = sx.shape
    t0 = time.perf_counter()
    sub = flows.astype(np.float64)
    if p.subpixel:
        if engine == "numpy":
            for k in range(2):
                _subpixel_numpy(desc[k], desc[1 - k], sx, sy, flows[k], costs[k], sub[k])
        else:
            _subpixel_pair(desc, sx, sy, flows, costs, sub)
    fwd = sub[0].astype(np.float32)
    bwd = sub[1].astype(np.float32)
    cost = (costs[0] / p.dims).astype(np.float32)
    keep = np.ones((gh, gw), bool)
    if math.isfinite(p.fb_threshold):
        keep &= _fb_error(fwd, bwd, xs, ys, p.step) <= p.fb_threshold
    if p.max_cost is not None:
        keep &= cost <= p.max_cost
    t_fb = time.perf_counter() - t0
    grid = fwd.copy()
    grid[~keep] = np.nan
    py, px = np.nonzero(keep)
    points = np.stack([xs[px], ys[py]], axis=1).astype(np.float32)
    logger.debug(
        "match %dx%d: %d levels, %d/%d seeds kept; pyramid %.3fs, descriptors %.3fs, "
        "patchmatch %.3fs, subpixel+check %.3fs, total %.3fs",
        w, h, nlev, int(keep.sum()), keep.size, t_pyr - t_start, t_desc, t_pm, t_fb,
        time.perf_counter() - t_start,
    )
    return Matches(points=points, flow=np.ascontiguousarray(fwd[keep]), cost=cost[keep],
                   grid_flow=grid, step=p.step)
