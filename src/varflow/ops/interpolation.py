"""Edge-preserving interpolation of sparse matches into a dense flow (EpicFlow).

Revaud et al. (2015) turn a sparse set of matches ``(p_m, f_m)`` into a dense
flow with a kernel regression whose distance is *geodesic*: the cost of a path
is the integral of an edge map ``C`` along it, so that matches on the far side
of an image edge (where motion boundaries usually are) count little.

Stages (each a Numba kernel with a NumPy/SciPy reference, ``engine="numpy"``):

1. **Cost map** :func:`edge_cost`.  EpicFlow uses structured edges (SED,
   Dollár & Zitnick 2013), which we do not have; we use the colour gradient
   magnitude of the Gaussian-smoothed image instead::

       g(x) = sqrt( Σ_c |∇(G_σ * I_c)(x)|² / C )            (per pixel, [0, 1] images)
       C(x) = min(g(x) / s, 1) + ε

   ``g`` averages the squared gradients of the C channels, so a grey image
   stored as RGB gives the grey gradient and colour edges of equal luminance
   still count.  ``s`` (``edge_scale``) is the gradient (intensity per px) that
   counts as a full edge, which keeps ``C`` in ``[ε, 1 + ε]`` like an edge
   probability; ``ε`` (``edge_floor``, EpicFlow's additive "euc" constant) makes
   distances grow in flat areas too.
2. **Geodesic Voronoi partition** :func:`geodesic_voronoi`: a multi-source
   Dijkstra on the pixel grid (8-neighbourhood, edge weight
   ``(C(p) + C(q)) / 2 · |p − q|``) gives every pixel its geodesically nearest
   seed ``L(x)`` and the distance ``d(x)`` to it.
3. **Seed graph** :func:`seed_graph`: seeds whose cells touch are adjacent,
   with weight ``min over touching pixel pairs (p, q) of d(p) + w(p, q) + d(q)``
   (the geodesic path through the common boundary).
4. **K nearest seeds** :func:`nearest_seeds`: a Dijkstra over the seed graph
   from every seed, stopped after K settled seeds, gives ``D(s, m)``.  The
   approximate geodesic distance of pixel ``x`` to seed ``m`` is
   ``d(x) + D(L(x), m)`` (EpicFlow's approximation, Sec. 3.2).
5. **Interpolation** :func:`fit_models`.  With kernel weights
   ``k(x, m) = exp(−a (d(x) + D(L(x), m)))`` the factor ``exp(−a d(x))`` is common
   to all the matches of a pixel and cancels in the normalisation, so every pixel
   of a cell uses the model of its seed ``s``, fitted once with the weights
   ``w_m = exp(−a D(s, m))`` over the K nearest seeds of ``s``:

   * NW (Nadaraya–Watson): ``F(x) = Σ_m w_m f_m / Σ_m w_m`` (constant per cell);
   * LA (locally-weighted affine): ``F(x) = A_s x + t_s``, the weighted least
     squares affine fit of the ``f_m`` at the ``p_m``.  Written about the
     weighted centroid ``p̄``: ``F(x) = f̄ + J (x − p̄)`` with ``J = Cov(f, p) Σ⁻¹``,
     ``Σ`` the weighted covariance of the positions.  When the eigenvalues of
     ``Σ`` satisfy ``λ_min <= fallback_cond · λ_max`` (fewer than three seeds,
     seeds on or near a line) the fit is ill-conditioned and NW is used.  The
     test is scale-free: a seed whose neighbours all weigh little (a cell walled
     in by edges) still gets an exact affine fit of an affine field.

Defaults.  K = 128 as in the paper (LA).  The paper's kernel is ``exp(−a D)``
with a ≈ 1 on SED edges (values in [0, 1], thin, near 0 on texture) plus a tiny
constant; our gradient edges also respond to texture and are wider, so the
distance scale is set for this cost map: ``a = 3``, ``s = 0.05``,
``ε = 0.05``, ``σ = 0.5`` (a full edge one px wide divides a weight by e³; a seed
3 px away in a flat area keeps e^−0.45 ≈ 0.64).  They are tuned on ground-truth
samples (3 px grid) of the Sintel final pairs ``market_5`` 2, ``cave_2`` 2,
``bandage_1`` 35 and ``alley_1`` 5, not on the pair the tests report
(``market_5`` 9 → 10); larger ``a`` favours perfect matches, smaller ``a``
averages noisy ones.

References
----------
J. Revaud, P. Weinzaepfel, Z. Harchaoui, C. Schmid, "EpicFlow: Edge-Preserving
Interpolation of Correspondences for Optical Flow", CVPR 2015.

P. Dollár, C. L. Zitnick, "Structured forests for fast edge detection", ICCV 2013.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy import ndimage

from .._validate import as_float_image

__all__ = [
    "InterpParams",
    "interpolate",
    "edge_cost",
    "geodesic_voronoi",
    "seed_graph",
    "nearest_seeds",
    "fit_models",
]

log = logging.getLogger(__name__)

_SQRT2 = math.sqrt(2.0)
#: Forward half of the 8-neighbourhood ``(dy, dx)``; the other half is its mirror.
_FWD_DY = np.array([0, 1, 1, 1], np.int64)
_FWD_DX = np.array([1, -1, 0, 1], np.int64)
_FWD_STEP = np.array([1.0, _SQRT2, 1.0, _SQRT2], np.float64)
_ALL_DY = np.array([0, 1, 1, 1, 0, -1, -1, -1], np.int64)
_ALL_DX = np.array([1, -1, 0, 1, -1, 1, 0, -1], np.int64)
_ALL_STEP = np.array([1.0, _SQRT2, 1.0, _SQRT2, 1.0, _SQRT2, 1.0, _SQRT2], np.float64)
_MODES = ("la", "nw")


@dataclass(frozen=True)
class InterpParams:
    """Parameters of :func:`interpolate` (symbols as in the module notes).

    Attributes
    ----------
    mode : {"la", "nw"}
        Interpolator: locally-weighted affine (LA, default) or Nadaraya–Watson.
    k : int
        K, number of geodesically nearest seeds of each seed used by its model
        (default 128, the paper's value for LA).
    a : float
        a, distance scale of the kernel ``exp(−a D)``, in 1/(cost · px)
        (default 3.0).
    edge_sigma : float
        σ, standard deviation in px of the Gaussian smoothing before the
        gradient of the cost map (default 0.5; 0 = none).
    edge_scale : float
        s, gradient magnitude (intensity of a [0, 1] image per px) that counts as
        a full edge, ``C = min(g / s, 1) + ε`` (default 0.05).
    edge_floor : float
        ε, cost per px of a flat area, > 0 (default 0.05).
    fallback_cond : float
        LA falls back to NW for a seed when the smallest eigenvalue of the
        weighted covariance of its neighbours' positions is at most
        ``fallback_cond`` times the largest, in [0, 1) (default 1e-3).
    """

    mode: str = "la"
    k: int = 128
    a: float = 3.0
    edge_sigma: float = 0.5
    edge_scale: float = 0.05
    edge_floor: float = 0.05
    fallback_cond: float = 1e-3

    def __post_init__(self) -> None:
        if self.mode not in _MODES:
            raise ValueError(f"mode: must be one of {_MODES}, got {self.mode!r}")
        if isinstance(self.k, bool) or not isinstance(self.k, int | np.integer) or self.k < 1:
            raise ValueError(f"k: must be an integer >= 1, got {self.k!r}")
        for name in ("a", "edge_scale", "edge_floor"):
            v = getattr(self, name)
            if not (isinstance(v, int | float | np.floating) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        v = self.edge_sigma
        if not (isinstance(v, int | float | np.floating) and math.isfinite(v) and v >= 0):
            raise ValueError(f"edge_sigma: must be a finite number >= 0, got {v!r}")
        v = self.fallback_cond
        if not (isinstance(v, int | float | np.floating) and 0 <= v < 1):
            raise ValueError(f"fallback_cond: must be a number in [0, 1), got {v!r}")


def _check_engine(engine: str) -> None:
    if engine not in ("numba", "numpy"):
        raise ValueError(f"engine: must be 'numba' or 'numpy', got {engine!r}")


# --------------------------------------------------------------------------- cost
def edge_cost(frame0: np.ndarray, params: InterpParams | None = None) -> np.ndarray:
    """Edge cost map ``C`` of an image (see the module notes, stage 1).

    Parameters
    ----------
    frame0 : ndarray, shape (H, W) or (H, W, C)
        Image, converted by :func:`varflow._validate.as_float_image`.
    params : InterpParams, optional
        Uses ``edge_sigma``, ``edge_scale`` and ``edge_floor``.

    Returns
    -------
    ndarray, shape (H, W), float32
        Values in ``[ε, 1 + ε]``.
    """
    p = InterpParams() if params is None else params
    img = as_float_image(frame0, "frame0")
    if p.edge_sigma > 0:
        img = ndimage.gaussian_filter(img, (p.edge_sigma, p.edge_sigma, 0), mode="nearest")
    gy, gx = np.gradient(img, axis=(0, 1))
    g = np.sqrt((gx * gx + gy * gy).mean(axis=2))
    return (np.minimum(g / np.float32(p.edge_scale), 1.0) + p.edge_floor).astype(np.float32)


# --------------------------------------------------------------------------- heap
@nb.njit(cache=True, inline="always")
def _less(k1, v1, k2, v2):
    return k1 < k2 or (k1 == k2 and v1 < v2)


@nb.njit(cache=True)
def _heap_push(keys, vals, size, key, val):
    """Push ``(key, val)`` on the 4-ary min-heap ``keys[:size]``; returns the new size.

    Entries are ordered by key, then by value, so that the pop order is fully
    determined (equal distances: lower index first).
    """
    i = size
    while i > 0:
        parent = (i - 1) >> 2
        if _less(key, val, keys[parent], vals[parent]):
            keys[i] = keys[parent]
            vals[i] = vals[parent]
            i = parent
        else:
            break
    keys[i] = key
    vals[i] = val
    return size + 1


@nb.njit(cache=True)
def _heap_pop(keys, vals, size):
    """Remove the top ``(keys[0], vals[0])`` (read it first); returns the new size."""
    size -= 1
    if size == 0:
        return 0
    key = keys[size]
    val = vals[size]
    i = 0
    while True:
        c = 4 * i + 1
        if c >= size:
            break
        best = c
        bk = keys[c]
        bv = vals[c]
        for cc in range(c + 1, min(c + 4, size)):
            if _less(keys[cc], vals[cc], bk, bv):
                best = cc
                bk = keys[cc]
                bv = vals[cc]
        if _less(bk, bv, key, val):
            keys[i] = bk
            vals[i] = bv
            i = best
        else:
            break
    keys[i] = key
    vals[i] = val
    return size


@nb.njit(cache=True)
def _grow(keys, vals):
    nk = np.empty(2 * keys.size, keys.dtype)
    nv = np.empty(2 * vals.size, vals.dtype)
    nk[: keys.size] = keys
    nv[: vals.size] = vals
    return nk, nv


# ------------------------------------------------------------------ voronoi
@nb.njit(cache=True)
def _voronoi_kernel(cost, seeds, labels, dist):
    """Multi-source Dijkstra on the 8-connected grid; ``seeds`` are flat indices."""
    h, w = cost.shape
    n = h * w
    c = cost.reshape(n)
    lab = labels.reshape(n)
    dd = dist.reshape(n)
    lab[:] = -1
    dd[:] = np.inf
    done = np.zeros(n, np.bool_)
    cap = max(n // 2, seeds.size + 16)
    keys = np.empty(cap, np.float64)
    vals = np.empty(cap, np.int64)
    size = 0
    for i in range(seeds.size):
        s = seeds[i]
        if lab[s] < 0:
            lab[s] = i
            dd[s] = 0.0
            if size == keys.size:
                keys, vals = _grow(keys, vals)
            size = _heap_push(keys, vals, size, 0.0, s)
    while size > 0:
        d = keys[0]
        p = vals[0]
        size = _heap_pop(keys, vals, size)
        if done[p]:
            continue
        done[p] = True
        py = p // w
        px = p - py * w
        for t in range(8):
            qy = py + _ALL_DY[t]
            qx = px + _ALL_DX[t]
            if qy < 0 or qy >= h or qx < 0 or qx >= w:
                continue
            q = qy * w + qx
            if done[q]:
                continue
            nd = d + 0.5 * (c[p] + c[q]) * _ALL_STEP[t]
            if nd < dd[q]:
                dd[q] = nd
                lab[q] = lab[p]
                if size == keys.size:
                    keys, vals = _grow(keys, vals)
                size = _heap_push(keys, vals, size, nd, q)


def _grid_graph(cost: np.ndarray):
    """Sparse 8-neighbourhood graph of the pixel grid (upper triangle, float64)."""
    from scipy import sparse

    h, w = cost.shape
    c = cost.astype(np.float64)
    idx = np.arange(h * w).reshape(h, w)
    rows, cols, wts = [], [], []
    for dy, dx, step in zip(_FWD_DY, _FWD_DX, _FWD_STEP, strict=True):
        y0, y1 = 0, h - dy
        x0, x1 = max(0, -dx), w - max(0, dx)
        p = idx[y0:y1, x0:x1]
        q = idx[y0 + dy:y1 + dy, x0 + dx:x1 + dx]
        rows.append(p.ravel())
        cols.append(q.ravel())
        wts.append(0.5 * (c.ravel()[p.ravel()] + c.ravel()[q.ravel()]) * step)
    return sparse.csr_matrix(
        (np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(h * w,) * 2
    )


def _voronoi_numpy(cost: np.ndarray, seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from scipy.sparse import csgraph

    h, w = cost.shape
    dist, _, src = csgraph.dijkstra(
        _grid_graph(cost), directed=False, indices=seeds, min_only=True,
        return_predecessors=True,
    )
    order = np.full(h * w, -1, np.int64)
    order[seeds[::-1]] = np.arange(seeds.size)[::-1]  # first occurrence wins
    labels = np.where(src >= 0, order[np.maximum(src, 0)], -1).astype(np.int32)
    return labels.reshape(h, w), dist.reshape(h, w)


def _check_cost(cost: np.ndarray) -> np.ndarray:
    c = np.asarray(cost)
    if c.ndim != 2 or min(c.shape) < 1:
        raise ValueError(f"cost: expected shape (H, W), got {c.shape}")
    c = np.ascontiguousarray(c, dtype=np.float64)
    if not (np.all(np.isfinite(c)) and np.all(c > 0)):
        raise ValueError("cost: must be finite and > 0 everywhere")
    return c


def _flat_seeds(seeds_yx: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    s = np.asarray(seeds_yx)
    if s.ndim != 2 or s.shape[1] != 2 or s.shape[0] < 1:
        raise ValueError(f"seeds_yx: expected shape (N, 2) with N >= 1, got {s.shape}")
    if not np.issubdtype(s.dtype, np.integer):
        raise ValueError(f"seeds_yx: expected integer pixel indices, got {s.dtype}")
    h, w = shape
    if np.any(s[:, 0] < 0) or np.any(s[:, 0] >= h) or np.any(s[:, 1] < 0) or np.any(s[:, 1] >= w):
        raise ValueError(f"seeds_yx: positions must lie inside the {h}x{w} image")
    return (s[:, 0].astype(np.int64) * w + s[:, 1]).astype(np.int64)


def geodesic_voronoi(
    cost: np.ndarray, seeds_yx: np.ndarray, engine: str = "numba"
) -> tuple[np.ndarray, np.ndarray]:
    """Geodesic Voronoi partition of the pixel grid (stage 2 of the module notes).

    Parameters
    ----------
    cost : ndarray, shape (H, W)
        C > 0, the cost per px of passing through each pixel (:func:`edge_cost`).
        The weight of the step between 8-neighbours p, q is
        ``(C(p) + C(q)) / 2 · |p − q|``.
    seeds_yx : ndarray of int, shape (N, 2)
        Seed pixels (row, column), inside the image.  A repeated pixel belongs to
        its first occurrence.
    engine : {"numba", "numpy"}
        Heap-based Dijkstra kernel, or :func:`scipy.sparse.csgraph.dijkstra`.

    Returns
    -------
    labels : ndarray, shape (H, W), int32
        Index (into ``seeds_yx``) of the geodesically nearest seed.
    dist : ndarray, shape (H, W), float64
        Geodesic distance to that seed (cost · px).
    """
    _check_engine(engine)
    c = _check_cost(cost)
    seeds = _flat_seeds(seeds_yx, c.shape)
    if engine == "numpy":
        return _voronoi_numpy(c, seeds)
    labels = np.empty(c.shape, np.int32)
    dist = np.empty(c.shape, np.float64)
    _voronoi_kernel(c, seeds, labels, dist)
    return labels, dist


# ------------------------------------------------------------------ seed graph
@nb.njit(cache=True)
def _boundary_pairs(labels, dist, c, n_seeds):
    """Per smaller label ``a``: the (b, weight) of every touching pixel pair, bucketed."""
    h, w = labels.shape
    count = np.zeros(n_seeds + 1, np.int64)
    for y in range(h):
        for x in range(w):
            a = labels[y, x]
            for t in range(4):
                qy = y + _FWD_DY[t]
                qx = x + _FWD_DX[t]
                if qy >= h or qx < 0 or qx >= w:
                    continue
                b = labels[qy, qx]
                if b != a:
                    count[min(a, b) + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    other = np.empty(start[-1], np.int64)
    weight = np.empty(start[-1], np.float64)
    for y in range(h):
        for x in range(w):
            a = labels[y, x]
            for t in range(4):
                qy = y + _FWD_DY[t]
                qx = x + _FWD_DX[t]
                if qy >= h or qx < 0 or qx >= w:
                    continue
                b = labels[qy, qx]
                if b != a:
                    wt = dist[y, x] + 0.5 * (c[y, x] + c[qy, qx]) * _FWD_STEP[t] + dist[qy, qx]
                    lo = min(a, b)
                    other[fill[lo]] = max(a, b)
                    weight[fill[lo]] = wt
                    fill[lo] += 1
    return start, other, weight


@nb.njit(cache=True)
def _seed_graph_kernel(labels, dist, c, n_seeds):
    start, other, weight = _boundary_pairs(labels, dist, c, n_seeds)
    stamp = np.full(n_seeds, -1, np.int64)
    slot = np.zeros(n_seeds, np.int64)
    ea = np.empty(other.size, np.int64)
    eb = np.empty(other.size, np.int64)
    ew = np.empty(other.size, np.float64)
    ne = 0
    for a in range(n_seeds):
        first = ne
        for e in range(start[a], start[a + 1]):
            b = other[e]
            if stamp[b] != a:
                stamp[b] = a
                slot[b] = ne
                ea[ne] = a
                eb[ne] = b
                ew[ne] = weight[e]
                ne += 1
            elif weight[e] < ew[slot[b]]:
                ew[slot[b]] = weight[e]
        # insertion sort of this bucket by b (few entries)
        for i in range(first + 1, ne):
            bb = eb[i]
            ww = ew[i]
            j = i - 1
            while j >= first and eb[j] > bb:
                eb[j + 1] = eb[j]
                ew[j + 1] = ew[j]
                j -= 1
            eb[j + 1] = bb
            ew[j + 1] = ww
    # symmetric CSR, neighbours in increasing order
    deg = np.zeros(n_seeds + 1, np.int64)
    for e in range(ne):
        deg[ea[e] + 1] += 1
        deg[eb[e] + 1] += 1
    indptr = np.cumsum(deg)
    pos = indptr[:-1].copy()
    indices = np.empty(2 * ne, np.int64)
    weights = np.empty(2 * ne, np.float64)
    for e in range(ne):
        a = ea[e]
        b = eb[e]
        indices[pos[a]] = b
        weights[pos[a]] = ew[e]
        pos[a] += 1
        indices[pos[b]] = a
        weights[pos[b]] = ew[e]
        pos[b] += 1
    return indptr, indices, weights


def _seed_graph_numpy(labels, dist, c, n_seeds):
    from scipy import sparse

    h, w = labels.shape
    a_l, b_l, w_l = [], [], []
    for dy, dx, step in zip(_FWD_DY, _FWD_DX, _FWD_STEP, strict=True):
        y1 = h - dy
        x0, x1 = max(0, -dx), w - max(0, dx)
        la, lb = labels[0:y1, x0:x1], labels[dy:y1 + dy, x0 + dx:x1 + dx]
        wt = dist[0:y1, x0:x1] + 0.5 * (c[0:y1, x0:x1] + c[dy:y1 + dy, x0 + dx:x1 + dx]) * step \
            + dist[dy:y1 + dy, x0 + dx:x1 + dx]
        m = la != lb
        a_l.append(np.minimum(la, lb)[m])
        b_l.append(np.maximum(la, lb)[m])
        w_l.append(wt[m])
    a = np.concatenate(a_l).astype(np.int64)
    b = np.concatenate(b_l).astype(np.int64)
    wt = np.concatenate(w_l)
    key = a * n_seeds + b
    order = np.argsort(key, kind="stable")
    key, wt = key[order], wt[order]
    first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if key.size else np.zeros(0, int)
    wmin = np.minimum.reduceat(wt, first) if key.size else wt
    ua, ub = key[first] // n_seeds, key[first] % n_seeds
    g = sparse.csr_matrix(
        (np.r_[wmin, wmin], (np.r_[ua, ub], np.r_[ub, ua])), shape=(n_seeds, n_seeds)
    )
    g.sort_indices()
    return g.indptr.astype(np.int64), g.indices.astype(np.int64), g.data.astype(np.float64)


def seed_graph(
    labels: np.ndarray, dist: np.ndarray, cost: np.ndarray, n_seeds: int, engine: str = "numba"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Adjacency graph of the geodesic Voronoi cells (stage 3 of the module notes).

    Parameters
    ----------
    labels, dist : ndarray, shape (H, W)
        Output of :func:`geodesic_voronoi`.
    cost : ndarray, shape (H, W)
        The cost map given to :func:`geodesic_voronoi`.
    n_seeds : int
        N, the number of seeds.
    engine : {"numba", "numpy"}

    Returns
    -------
    indptr : ndarray, shape (N + 1,), int64
    indices : ndarray, shape (E,), int64
    weights : ndarray, shape (E,), float64
        Symmetric CSR graph, neighbours in increasing order; the weight of
        (a, b) is the shortest ``d(p) + w(p, q) + d(q)`` over 8-neighbour pixel
        pairs p in cell a, q in cell b.
    """
    _check_engine(engine)
    labels = np.ascontiguousarray(labels, np.int32)
    dist = np.ascontiguousarray(dist, np.float64)
    c = _check_cost(cost)
    if labels.shape != c.shape or dist.shape != c.shape:
        raise ValueError(f"labels: shapes differ: {labels.shape}, {dist.shape}, cost {c.shape}")
    if labels.min() < 0 or labels.max() >= n_seeds:
        raise ValueError(f"labels: must lie in [0, {n_seeds}), got [{labels.min()}, "
                         f"{labels.max()}]")
    if engine == "numpy":
        return _seed_graph_numpy(labels, dist, c, n_seeds)
    return _seed_graph_kernel(labels, dist, c, n_seeds)


# ------------------------------------------------------------------ K nearest seeds
@nb.njit(cache=True)
def _knn_range(indptr, indices, weights, k, nn_idx, nn_dist, lo, hi):
    """Dijkstra from the seeds ``lo..hi-1``, each stopped after k settled seeds.

    ``best[v]`` is the tentative distance of ``v`` in the current run (valid when
    ``seen[v]`` is the current seed), −1 once settled; stale heap entries have a
    key above ``best``.  Ties settle the lower index first.
    """
    n = indptr.size - 1
    best = np.empty(n, np.float64)
    seen = np.full(n, -1, np.int32)
    keys = np.empty(4 * k + 64, np.float64)
    vals = np.empty(4 * k + 64, np.int32)
    for s in range(lo, hi):
        s32 = np.int32(s)
        size = _heap_push(keys, vals, 0, 0.0, s32)
        best[s] = 0.0
        seen[s] = s32
        m = 0
        while size > 0:
            d = keys[0]
            v = vals[0]
            size = _heap_pop(keys, vals, size)
            if d > best[v]:
                continue
            best[v] = -1.0
            nn_idx[s, m] = v
            nn_dist[s, m] = d
            m += 1
            if m == k:
                break
            for e in range(indptr[v], indptr[v + 1]):
                u = indices[e]
                nd = d + weights[e]
                if seen[u] != s32:
                    seen[u] = s32
                elif not nd < best[u]:
                    continue
                best[u] = nd
                if size == keys.size:
                    keys, vals = _grow(keys, vals)
                size = _heap_push(keys, vals, size, nd, u)
        for t in range(m, k):
            nn_idx[s, t] = -1
            nn_dist[s, t] = np.inf


@nb.njit(cache=True, parallel=True)
def _knn_kernel(indptr, indices, weights, k, nn_idx, nn_dist, n_chunks):
    """:func:`_knn_range` over ``n_chunks`` blocks of seeds in parallel (deterministic)."""
    n = indptr.size - 1
    for chunk in nb.prange(n_chunks):
        _knn_range(indptr, indices, weights, k, nn_idx, nn_dist,
                   chunk * n // n_chunks, (chunk + 1) * n // n_chunks)


def _knn_numpy(indptr, indices, weights, k):
    from scipy import sparse
    from scipy.sparse import csgraph

    n = indptr.size - 1
    g = sparse.csr_matrix((weights, indices, indptr), shape=(n, n))
    nn_idx = np.full((n, k), -1, np.int64)
    nn_dist = np.full((n, k), np.inf)
    block = max(1, 2_000_000 // max(n, 1))
    for lo in range(0, n, block):
        rows = np.arange(lo, min(n, lo + block))
        d = csgraph.dijkstra(g, directed=True, indices=rows)
        for r, s in enumerate(rows):
            order = np.lexsort((np.arange(n), d[r]))[:k]
            order = order[np.isfinite(d[r, order])]
            nn_idx[s, : order.size] = order
            nn_dist[s, : order.size] = d[r, order]
    return nn_idx, nn_dist


def nearest_seeds(
    indptr: np.ndarray, indices: np.ndarray, weights: np.ndarray, k: int, engine: str = "numba"
) -> tuple[np.ndarray, np.ndarray]:
    """The K geodesically nearest seeds of every seed (stage 4 of the module notes).

    Parameters
    ----------
    indptr, indices, weights : ndarray
        The CSR seed graph of :func:`seed_graph` (N seeds).
    k : int
        K >= 1 (the seed itself is its first neighbour, at distance 0).
    engine : {"numba", "numpy"}
        Parallel per-seed heap Dijkstra, or :func:`scipy.sparse.csgraph.dijkstra`
        from every seed (memory O(N²) per block: small problems only).

    Returns
    -------
    nn_idx : ndarray, shape (N, K), int64
        Neighbours by increasing distance (ties: lower index first); -1 pads
        when fewer than K seeds are reachable.
    nn_dist : ndarray, shape (N, K), float64
        D(s, m), the seed-graph distance; inf where padded.
    """
    _check_engine(engine)
    if isinstance(k, bool) or int(k) != k or k < 1:
        raise ValueError(f"k: must be an integer >= 1, got {k!r}")
    k = int(k)
    indptr = np.ascontiguousarray(indptr, np.int64)
    indices = np.ascontiguousarray(indices, np.int64)
    weights = np.ascontiguousarray(weights, np.float64)
    if engine == "numpy":
        return _knn_numpy(indptr, indices, weights, k)
    n = indptr.size - 1
    nn_idx = np.empty((n, k), np.int64)
    nn_dist = np.empty((n, k), np.float64)
    _knn_kernel(indptr, indices.astype(np.int32), weights, k, nn_idx, nn_dist, min(n, 64))
    return nn_idx, nn_dist


# ------------------------------------------------------------------ models
@nb.njit(cache=True, parallel=True)
def _fit_kernel(pos, val, nn_idx, nn_dist, a, affine, cond, centre, mean, jac):
    n, k = nn_idx.shape
    for s in nb.prange(n):
        sw = 0.0
        sx = 0.0
        sy = 0.0
        su = 0.0
        sv = 0.0
        cnt = 0
        for t in range(k):
            m = nn_idx[s, t]
            if m < 0:
                break
            wt = math.exp(-a * nn_dist[s, t])
            sw += wt
            sx += wt * pos[m, 0]
            sy += wt * pos[m, 1]
            su += wt * val[m, 0]
            sv += wt * val[m, 1]
            cnt += 1
        mx = sx / sw
        my = sy / sw
        mu = su / sw
        mv = sv / sw
        centre[s, 0] = mx
        centre[s, 1] = my
        mean[s, 0] = mu
        mean[s, 1] = mv
        jac[s, 0, 0] = 0.0
        jac[s, 0, 1] = 0.0
        jac[s, 1, 0] = 0.0
        jac[s, 1, 1] = 0.0
        if not affine or cnt < 3:
            continue
        cxx = 0.0
        cxy = 0.0
        cyy = 0.0
        cux = 0.0
        cuy = 0.0
        cvx = 0.0
        cvy = 0.0
        for t in range(cnt):
            m = nn_idx[s, t]
            wt = math.exp(-a * nn_dist[s, t])
            dx = pos[m, 0] - mx
            dy = pos[m, 1] - my
            du = val[m, 0] - mu
            dv = val[m, 1] - mv
            cxx += wt * dx * dx
            cxy += wt * dx * dy
            cyy += wt * dy * dy
            cux += wt * du * dx
            cuy += wt * du * dy
            cvx += wt * dv * dx
            cvy += wt * dv * dy
        cxx /= sw
        cxy /= sw
        cyy /= sw
        half_tr = 0.5 * (cxx + cyy)
        root = math.sqrt(0.25 * (cxx - cyy) ** 2 + cxy * cxy)
        if not half_tr - root > cond * (half_tr + root):
            continue
        det = cxx * cyy - cxy * cxy
        cux /= sw
        cuy /= sw
        cvx /= sw
        cvy /= sw
        jac[s, 0, 0] = (cyy * cux - cxy * cuy) / det
        jac[s, 0, 1] = (cxx * cuy - cxy * cux) / det
        jac[s, 1, 0] = (cyy * cvx - cxy * cvy) / det
        jac[s, 1, 1] = (cxx * cvy - cxy * cvx) / det


def _fit_numpy(pos, val, nn_idx, nn_dist, a, affine, cond):
    valid = nn_idx >= 0
    idx = np.where(valid, nn_idx, 0)
    wt = np.where(valid, np.exp(-a * np.where(valid, nn_dist, 0.0)), 0.0)
    sw = wt.sum(1)
    p = pos[idx]  # (N, K, 2)
    f = val[idx]
    centre = (wt[..., None] * p).sum(1) / sw[:, None]
    mean = (wt[..., None] * f).sum(1) / sw[:, None]
    jac = np.zeros((len(pos), 2, 2))
    if affine:
        dp = p - centre[:, None]
        df = f - mean[:, None]
        cov = np.einsum("nk,nki,nkj->nij", wt, dp, dp) / sw[:, None, None]
        cfp = np.einsum("nk,nki,nkj->nij", wt, df, dp) / sw[:, None, None]
        cxx, cxy, cyy = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
        root = np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy**2)
        ok = (valid.sum(1) >= 3) & (0.5 * (cxx + cyy) - root > cond * (0.5 * (cxx + cyy) + root))
        jac[ok] = np.linalg.solve(cov[ok], cfp[ok].transpose(0, 2, 1)).transpose(0, 2, 1)
    return centre, mean, jac


def fit_models(
    pos: np.ndarray,
    val: np.ndarray,
    nn_idx: np.ndarray,
    nn_dist: np.ndarray,
    params: InterpParams | None = None,
    engine: str = "numba",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-seed NW or LA model (stage 5 of the module notes).

    Parameters
    ----------
    pos : ndarray, shape (N, 2)
        Seed positions (x, y) in px.
    val : ndarray, shape (N, 2)
        Their flow (u, v).
    nn_idx, nn_dist : ndarray, shape (N, K)
        Output of :func:`nearest_seeds`.
    params : InterpParams, optional
        Uses ``mode``, ``a`` and ``fallback_cond``.
    engine : {"numba", "numpy"}

    Returns
    -------
    centre : ndarray, shape (N, 2), float64
        Weighted centroid p̄ of the neighbour positions.
    mean : ndarray, shape (N, 2), float64
        Weighted mean flow f̄ (the NW estimate).
    jac : ndarray, shape (N, 2, 2), float64
        J with ``F(x) = f̄ + J (x − p̄)``; rows (u, v), columns (x, y); zero for NW
        and for the LA fallback.
    """
    _check_engine(engine)
    p = InterpParams() if params is None else params
    pos = np.ascontiguousarray(pos, np.float64)
    val = np.ascontiguousarray(val, np.float64)
    nn_idx = np.ascontiguousarray(nn_idx, np.int64)
    nn_dist = np.ascontiguousarray(nn_dist, np.float64)
    affine = p.mode == "la"
    if engine == "numpy":
        return _fit_numpy(pos, val, nn_idx, nn_dist, p.a, affine, p.fallback_cond)
    n = len(pos)
    centre = np.empty((n, 2))
    mean = np.empty((n, 2))
    jac = np.empty((n, 2, 2))
    _fit_kernel(pos, val, nn_idx, nn_dist, float(p.a), affine, float(p.fallback_cond),
                centre, mean, jac)
    return centre, mean, jac


@nb.njit(cache=True, parallel=True)
def _render_kernel(labels, centre, mean, jac, out):
    h, w = labels.shape
    for y in nb.prange(h):
        for x in range(w):
            s = labels[y, x]
            dx = x - centre[s, 0]
            dy = y - centre[s, 1]
            out[y, x, 0] = mean[s, 0] + jac[s, 0, 0] * dx + jac[s, 0, 1] * dy
            out[y, x, 1] = mean[s, 1] + jac[s, 1, 0] * dx + jac[s, 1, 1] * dy


def _render_numpy(labels, centre, mean, jac):
    h, w = labels.shape
    yy, xx = np.mgrid[0:h, 0:w]
    d = np.stack([xx - centre[labels, 0], yy - centre[labels, 1]], -1)
    return (mean[labels] + np.einsum("hwij,hwj->hwi", jac[labels], d)).astype(np.float32)


# ------------------------------------------------------------------ driver
def _valid_seeds(points, flow, shape):
    """Drop NaN, out-of-image and repeated seeds; returns kept index and pixel (y, x)."""
    pts = np.asarray(points)
    fl = np.asarray(flow)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points: expected shape (N, 2), got {pts.shape}")
    if fl.shape != pts.shape:
        raise ValueError(f"flow: expected shape {pts.shape} (one (u, v) per point), got "
                         f"{fl.shape}")
    for name, arr in (("points", pts), ("flow", fl)):
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise ValueError(f"{name}: expected a numeric dtype, got {arr.dtype}")
    pts = pts.astype(np.float64)
    fl = fl.astype(np.float64)
    h, w = shape
    ok = np.isfinite(pts).all(1) & np.isfinite(fl).all(1)
    xi = np.rint(np.where(ok, pts[:, 0], -1)).astype(np.int64)
    yi = np.rint(np.where(ok, pts[:, 1], -1)).astype(np.int64)
    inside = ok & (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    if np.count_nonzero(ok & ~inside):
        log.debug("interpolate: %d seeds outside the image dropped",
                  np.count_nonzero(ok & ~inside))
    keep = np.flatnonzero(inside)
    _, first = np.unique(yi[keep] * w + xi[keep], return_index=True)
    keep = keep[np.sort(first)]
    if keep.size == 0:
        raise ValueError("points: no valid seed (all NaN, outside the image, or none given)")
    return keep, pts[keep], fl[keep], np.stack([yi[keep], xi[keep]], 1)


def interpolate(
    frame0: np.ndarray,
    points: np.ndarray,
    flow: np.ndarray,
    params: InterpParams | None = None,
    engine: str = "numba",
) -> np.ndarray:
    """Edge-preserving dense interpolation of sparse matches (EpicFlow, see module notes).

    Parameters
    ----------
    frame0 : ndarray, shape (H, W) or (H, W, C)
        Reference image (uint8/uint16 or float in [0, 1]); its edges shape the
        geodesic distance.
    points : ndarray, shape (N, 2)
        Seed positions (x, y) in ``frame0``, px; rounded to the nearest pixel for
        the Voronoi partition, used as given in the LA fit.
    flow : ndarray, shape (N, 2)
        Their flow (u, v), px.  Seeds with a NaN in ``points`` or ``flow``, outside
        the image, or on a pixel already taken by an earlier seed are dropped.
    params : InterpParams, optional
        Defaults to ``InterpParams()``.
    engine : {"numba", "numpy"}
        Numba kernels, or the NumPy/SciPy references (small images only).

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        Dense flow, [..., 0] = u, [..., 1] = v.

    Raises
    ------
    ValueError
        Wrong shapes or engine, or no valid seed.
    """
    _check_engine(engine)
    p = InterpParams() if params is None else params
    if not isinstance(p, InterpParams):
        raise ValueError(f"params: expected InterpParams, got {type(p).__name__}")
    img = as_float_image(frame0, "frame0")
    h, w = img.shape[:2]
    _, pos, val, yx = _valid_seeds(points, flow, (h, w))
    n = len(pos)
    k = min(p.k, n)
    t0 = time.perf_counter()
    cost = edge_cost(img, p).astype(np.float64)
    t1 = time.perf_counter()
    labels, dist = geodesic_voronoi(cost, yx, engine)
    t2 = time.perf_counter()
    graph = seed_graph(labels, dist, cost, n, engine)
    t3 = time.perf_counter()
    nn_idx, nn_dist = nearest_seeds(*graph, k, engine=engine)
    t4 = time.perf_counter()
    centre, mean, jac = fit_models(pos, val, nn_idx, nn_dist, p, engine)
    if engine == "numpy":
        out = _render_numpy(labels, centre, mean, jac)
    else:
        out = np.empty((h, w, 2), np.float32)
        _render_kernel(labels, centre, mean, jac, out)
    t5 = time.perf_counter()
    log.debug(
        "interpolate: %d seeds, %dx%d; cost %.3fs, voronoi %.3fs, graph %.3fs, knn %.3fs, "
        "fit+render %.3fs", n, h, w, t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4,
    )
    return out
