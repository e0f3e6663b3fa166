"""Per-pixel choice between flow candidates by an edge-aware photometric cost.

The cost of a flow ``w`` at pixel ``x`` is the colour-constancy residual
``r_w(y) = min(mean_c |I1_c(y + w(y)) − I0_c(y)|, T)`` (bilinear sampling of
``I1``; ``T`` = ``truncation``) aggregated over a ``(2R + 1)²`` window with
adaptive support weights (Yoon & Kweon 2006)::

    C_w(x) = Σ_k W_k(x) r_w(x + o_k) / Σ_k W_k(x)    (over the y = x + o_k with
                                                       y + w(y) inside I1),
    W_k(x) ∝ exp(−|I0(x + o_k) − I0(x)|₁ / γ − |o_k| / (R + 1)),   Σ_k W_k(x) = 1,

so that a window at a motion boundary listens mostly to the pixels of its own
surface (those with the reference colour of ``x``).  Residuals of targets outside
``I1`` are unknown and left out (the cost is ``T`` when none is inside): a flow
is neither rewarded nor punished for pointing out of the frame.

Uses:

* :func:`fuse` — keep, per pixel, the candidate field with the smallest cost.
* :func:`candidate_costs` — the costs of several candidates with the weights made
  on the fly (no weight planes), for a single use of them (a level of ``tvl1-ld``).
* :func:`census_planes` — a soft census transform of a frame: planes whose
  residual is insensitive to a change of brightness or contrast, for a fusion
  cost that holds under illumination drift (pass them as ``i0``/``i1``).
* :func:`repair` — spatial propagation of flow vectors in the manner of
  PatchMatch (Barnes et al. 2009): every pixel tries the current vectors of the
  pixels at a few offsets (8 directions × ``distances``) and keeps one that lowers
  its cost.  It stops the flow of one surface from bleeding over a motion
  boundary into another (the coarse-to-fine smoothing leaves a band of a few
  pixels of the wrong motion along object edges, which a warping refinement
  cannot undo once the error exceeds the linearisation range): the pixels of the
  band take the vector of their own surface's interior.

Each kernel has a NumPy reference with the same signature (``engine="numpy"``).

References
----------
K.-J. Yoon, I. S. Kweon, "Adaptive support-weight approach for correspondence
search", IEEE TPAMI 28(4), 2006.

C. Barnes, E. Shechtman, A. Finkelstein, D. B. Goldman, "PatchMatch: a randomized
correspondence algorithm for structural image editing", SIGGRAPH 2009.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._jit import FASTMATH, FASTMATH_NO_REASSOC
from .warp import in_bounds

__all__ = [
    "support_weights",
    "flow_cost",
    "fuse",
    "census_planes",
    "candidate_costs",
    "repair",
    "repair_with",
    "relight",
    "noise_sigma",
    "noise_sigma_flat",
    "repair_margin",
    "REPAIR_DIRECTIONS",
]

#: The 8 unit directions ``(dy, dx)`` of :func:`repair`, scaled by each distance.
#: Residual marker of a target outside ``I1``: left out of the window's mean.
_OUT = np.float32(-1.0)

REPAIR_DIRECTIONS = ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1), (-1, 1), (1, -1))


def _offsets(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    dy, dx = np.meshgrid(r, r, indexing="ij")
    return np.stack([dy.ravel(), dx.ravel()], 1).astype(np.int64)


def _check_image(img: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(img)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3:
        raise ValueError(f"{name}: expected shape (H, W) or (H, W, C), got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _check_flow(flow: np.ndarray, shape: tuple[int, int], name: str = "flow") -> np.ndarray:
    arr = np.asarray(flow)
    if arr.shape != shape + (2,):
        raise ValueError(f"{name}: expected shape {shape + (2,)}, got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _check_engine(engine: str) -> None:
    if engine not in ("numba", "numpy"):
        raise ValueError(f"engine: must be 'numba' or 'numpy', got {engine!r}")


# ----------------------------------------------------------------- support weights
def _support_weights_numpy(img: np.ndarray, radius: int, gamma: float) -> np.ndarray:
    h, w, _ = img.shape
    offs = _offsets(radius)
    pad = np.pad(img, ((radius, radius), (radius, radius), (0, 0)), mode="edge")
    out = np.empty((len(offs), h, w), np.float32)
    for k, (dy, dx) in enumerate(offs):
        nb_ = pad[radius + dy: radius + dy + h, radius + dx: radius + dx + w]
        d = np.abs(nb_ - img).sum(axis=2)
        out[k] = np.exp(-d / gamma - math.hypot(dy, dx) / (radius + 1))
    out /= out.sum(axis=0)
    return out


@nb.njit(cache=True, fastmath=FASTMATH_NO_REASSOC, inline="always")
def _exp_neg_row(x, out, bits):
    """``out = exp(x)`` for float32 ``x <= 0``, in loops the compiler vectorises.

    Range reduction ``x = n ln 2 + r`` (ln 2 in two parts, Cody & Waite), Cephes'
    ``expf`` polynomial ``1 + r + r² P5(r)`` on ``|r| <= ln 2 / 2``, and the
    factor ``2^n`` assembled in the exponent bits of ``bits`` (int32).  ``x`` is
    clamped at -87 (``exp(-87)`` ~ 1.6e-38, the smallest normal float32 is 1.2e-38);
    the relative error is below 1e-7 (tests).  ``libm``'s ``expf`` is a scalar call,
    the bulk of :func:`support_weights` without this.
    """
    log2e = np.float32(1.44269504088896341)
    c1 = np.float32(0.693359375)
    c2 = np.float32(-2.12194440e-4)
    lo = np.float32(-87.0)
    for j in range(x.shape[0]):
        xv = max(x[j], lo)
        n = np.floor(xv * log2e + np.float32(0.5))
        r = xv - n * c1
        r = r - n * c2
        q = np.float32(1.9875691500e-4)
        q = q * r + np.float32(1.3981999507e-3)
        q = q * r + np.float32(8.3334519073e-3)
        q = q * r + np.float32(4.1665795894e-2)
        q = q * r + np.float32(1.6666665459e-1)
        q = q * r + np.float32(5.0000001201e-1)
        out[j] = q * r * r + r + np.float32(1.0)
        bits[j] = (np.int32(n) + np.int32(127)) << np.int32(23)
    scale = bits.view(np.float32)
    for j in range(x.shape[0]):
        out[j] = out[j] * scale[j]


@nb.njit(cache=True, inline="always")
def _spatial_exponents(offs, radius):
    """``|o_k| / (R + 1)`` of the window offsets ``offs`` (K, 2), float32."""
    spat = np.empty(offs.shape[0], np.float32)
    for k in range(offs.shape[0]):
        spat[k] = math.sqrt(offs[k, 0] ** 2 + offs[k, 1] ** 2) / (radius + 1)
    return spat


@nb.njit(cache=True, fastmath=FASTMATH_NO_REASSOC, inline="always")
def _window_exponent_row(planar, i, yi, dx, w, inv_g, sk, d):
    """``d[j] = -|I(yi, j + dx) - I(i, j)|₁ / γ - s_k`` for row ``i`` of ``planar`` (C, H, W).

    Columns whose neighbour ``j + dx`` is outside take the edge column's value.
    The middle run indexes slices with the bare loop variable, so that Numba
    drops its negative-index checks and LLVM vectorises it.
    """
    nc = planar.shape[0]
    lo = min(max(0, -dx), w)  # columns lo..hi-1 need no clamping
    hi = max(min(w, w - dx), lo)
    for j in range(w):
        d[j] = 0.0
    dm = d[lo:hi]
    for c in range(nc):
        cur = planar[c, i]
        nbr = planar[c, yi]
        curm = cur[lo:hi]
        nbrm = nbr[lo + dx:hi + dx]
        for jj in range(hi - lo):
            dm[jj] += abs(nbrm[jj] - curm[jj])
        for j in range(lo):
            d[j] += abs(nbr[min(max(j + dx, 0), w - 1)] - cur[j])
        for j in range(hi, w):
            d[j] += abs(nbr[min(max(j + dx, 0), w - 1)] - cur[j])
    for j in range(w):
        d[j] = -d[j] * inv_g - sk


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH_NO_REASSOC)
def _support_weights_kernel(planar, offs, gamma, radius, out):
    h, w = planar.shape[1:]
    nk = offs.shape[0]
    inv_g = np.float32(1.0 / gamma)
    spat = _spatial_exponents(offs, radius)
    for i in nb.prange(h):
        tot = np.zeros(w, np.float32)
        d = np.empty(w, np.float32)
        e = np.empty(w, np.float32)
        bits = np.empty(w, np.int32)
        for k in range(nk):
            yi = min(max(i + offs[k, 0], 0), h - 1)
            _window_exponent_row(planar, i, yi, offs[k, 1], w, inv_g, spat[k], d)
            _exp_neg_row(d, e, bits)
            row = out[k, i]
            for j in range(w):
                row[j] = e[j]
                tot[j] += e[j]
        for j in range(w):
            tot[j] = np.float32(1.0) / tot[j]
        for k in range(nk):
            row = out[k, i]
            for j in range(w):
                row[j] *= tot[j]


def support_weights(image: np.ndarray, radius: int = 2, gamma: float = 0.1,
                    engine: str = "numba") -> np.ndarray:
    """Adaptive support weights of the reference image (see the module notes).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Reference frame, float in [0, 1].
    radius : int
        R: the window is ``(2R + 1)²``, offsets in raster order (dy major).
    gamma : float
        γ, colour-similarity scale (sum of absolute channel differences).
    engine : {"numba", "numpy"}

    Returns
    -------
    ndarray, shape ((2R + 1)², H, W), float32
        Non-negative, summing to 1 over the first axis.
    """
    _check_engine(engine)
    if radius < 0:
        raise ValueError(f"radius: must be >= 0, got {radius}")
    if not gamma > 0:
        raise ValueError(f"gamma: must be > 0, got {gamma}")
    img = _check_image(image, "image")
    if engine == "numpy":
        return _support_weights_numpy(img, radius, gamma)
    offs = _offsets(radius)
    out = np.empty((len(offs),) + img.shape[:2], np.float32)
    planar = np.ascontiguousarray(img.transpose(2, 0, 1))
    _support_weights_kernel(planar, offs, np.float32(gamma), radius, out)
    return out


# ------------------------------------------------------------------------- costs
def _bilinear_residual_numpy(i0, i1, flow, dy, dx, trunc):
    """Residual of the field ``flow`` shifted by ``(dy, dx)``: ``flow(y + (dy, dx))`` at y."""
    h, w, _ = i0.shape
    ys = np.clip(np.arange(h) + dy, 0, h - 1)
    xs = np.clip(np.arange(w) + dx, 0, w - 1)
    f = flow[ys][:, xs]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    x = xx + f[..., 0]
    y = yy + f[..., 1]
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    xc = np.clip(x, 0, w - 1)
    yc = np.clip(y, 0, h - 1)
    x0 = np.minimum(np.floor(xc).astype(np.int64), max(w - 2, 0))
    y0 = np.minimum(np.floor(yc).astype(np.int64), max(h - 2, 0))
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = (xc - x0)[..., None]
    fy = (yc - y0)[..., None]
    s = (i1[y0, x0] * (1 - fx) + i1[y0, x1] * fx) * (1 - fy) \
        + (i1[y1, x0] * (1 - fx) + i1[y1, x1] * fx) * fy
    r = np.minimum(np.abs(s - i0).mean(axis=2), trunc)
    r[~inside] = _OUT
    return r.astype(np.float32)


def _aggregate_numpy(res, weights, radius, trunc):
    h, w = res.shape
    pad = np.pad(res, radius, mode="edge")
    out = np.zeros((h, w), np.float32)
    tot = np.zeros((h, w), np.float32)
    for k, (dy, dx) in enumerate(_offsets(radius)):
        r = pad[radius + dy: radius + dy + h, radius + dx: radius + dx + w]
        ok = r >= 0
        out += np.where(ok, weights[k] * r, 0)
        tot += np.where(ok, weights[k], 0)
    return np.where(tot > 0, out / np.maximum(tot, 1e-30), trunc).astype(np.float32)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _residual_kernel(i0, i1, flow, dy, dx, trunc, out):
    h, w, nc = i0.shape
    inv_c = np.float32(1.0 / nc)
    for i in nb.prange(h):
        si = min(max(i + dy, 0), h - 1)
        for j in range(w):
            sj = min(max(j + dx, 0), w - 1)
            x = j + flow[si, sj, 0]
            y = i + flow[si, sj, 1]
            if not (x >= 0.0 and x <= w - 1.0 and y >= 0.0 and y <= h - 1.0):
                out[i, j] = _OUT
                continue
            x0 = min(int(x), max(w - 2, 0))
            y0 = min(int(y), max(h - 2, 0))
            x1 = min(x0 + 1, w - 1)
            y1 = min(y0 + 1, h - 1)
            fx = x - x0
            fy = y - y0
            acc = np.float32(0.0)
            for c in range(nc):
                top = i1[y0, x0, c] * (1 - fx) + i1[y0, x1, c] * fx
                bot = i1[y1, x0, c] * (1 - fx) + i1[y1, x1, c] * fx
                acc += abs(top * (1 - fy) + bot * fy - i0[i, j, c])
            out[i, j] = min(acc * inv_c, trunc)


@nb.njit(cache=True, inline="always")
def _aggregate_row(res, weights, offs, i, trunc, acc, tot):
    """Weighted mean of the in-frame residuals of row ``i``'s windows, into ``acc``."""
    h, w = res.shape
    for j in range(w):
        acc[j] = 0.0
        tot[j] = 0.0
    for k in range(offs.shape[0]):
        yi = min(max(i + offs[k, 0], 0), h - 1)
        for j in range(w):
            xj = min(max(j + offs[k, 1], 0), w - 1)
            r = res[yi, xj]
            if r >= 0.0:
                acc[j] += weights[k, i, j] * r
                tot[j] += weights[k, i, j]
    for j in range(w):
        acc[j] = acc[j] / tot[j] if tot[j] > 0.0 else trunc


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _aggregate_kernel(res, weights, offs, trunc, out):
    h, w = res.shape
    for i in nb.prange(h):
        acc = np.empty(w, np.float32)
        tot = np.empty(w, np.float32)
        _aggregate_row(res, weights, offs, i, trunc, acc, tot)
        for j in range(w):
            out[i, j] = acc[j]


@nb.njit(cache=True, inline="always")
def _inside(i, j, u, v, h, w):
    x = j + u
    y = i + v
    return x >= 0.0 and x <= w - 1.0 and y >= 0.0 and y <= h - 1.0


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _repair_step_kernel(i0, i1, src, dy, dx, weights, offs, trunc, margin, res, best, cost,
                        changed):
    """One candidate of :func:`repair`: the field ``src`` shifted by ``(dy, dx)``."""
    h, w, _ = i0.shape
    _residual_kernel(i0, i1, src, dy, dx, trunc, res)
    for i in nb.prange(h):
        si = min(max(i + dy, 0), h - 1)
        acc = np.empty(w, np.float32)
        tot = np.empty(w, np.float32)
        _aggregate_row(res, weights, offs, i, trunc, acc, tot)
        for j in range(w):
            if acc[j] < cost[i, j] - margin:
                sj = min(max(j + dx, 0), w - 1)
                if not (_inside(i, j, best[i, j, 0], best[i, j, 1], h, w)
                        and _inside(i, j, src[si, sj, 0], src[si, sj, 1], h, w)):
                    continue
                cost[i, j] = acc[j]
                best[i, j, 0] = src[si, sj, 0]
                best[i, j, 1] = src[si, sj, 1]
                changed[i, j] = True


def _radius_of(weights: np.ndarray) -> int:
    side = int(round(math.sqrt(weights.shape[0])))
    if side * side != weights.shape[0] or side % 2 == 0:
        raise ValueError(f"weights: expected (2R+1)^2 planes, got {weights.shape[0]}")
    return side // 2


def _shifted_cost(i0, i1, flow, dy, dx, weights, trunc, engine):
    radius = _radius_of(weights)
    if engine == "numpy":
        res = _bilinear_residual_numpy(i0, i1, flow, dy, dx, trunc)
        return _aggregate_numpy(res, weights, radius, trunc)
    res = np.empty(i0.shape[:2], np.float32)
    _residual_kernel(i0, i1, flow, dy, dx, np.float32(trunc), res)
    out = np.empty_like(res)
    _aggregate_kernel(res, weights, _offsets(radius), np.float32(trunc), out)
    return out


def flow_cost(i0: np.ndarray, i1: np.ndarray, flow: np.ndarray, weights: np.ndarray,
              truncation: float = 0.1, engine: str = "numba") -> np.ndarray:
    """Edge-aware photometric cost ``C_w`` of a flow field (see the module notes).

    Parameters
    ----------
    i0, i1 : ndarray, shape (H, W) or (H, W, C), float32
        Reference frame and the frame the flow points into.
    flow : ndarray, shape (H, W, 2)
    weights : ndarray, shape ((2R+1)², H, W)
        :func:`support_weights` of ``i0``.
    truncation : float
        T, the largest residual per pixel (and the cost of a window whose targets
        all lie outside ``i1``).
    engine : {"numba", "numpy"}

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    _check_engine(engine)
    i0 = _check_image(i0, "i0")
    i1 = _check_image(i1, "i1")
    if i1.shape != i0.shape:
        raise ValueError(f"i1: shape {i1.shape} differs from i0 {i0.shape}")
    flow = _check_flow(flow, i0.shape[:2])
    if weights.shape[1:] != i0.shape[:2]:
        raise ValueError(f"weights: expected (K,) + {i0.shape[:2]}, got {weights.shape}")
    return _shifted_cost(i0, i1, flow, 0, 0, weights, truncation, engine)


def fuse(i0: np.ndarray, i1: np.ndarray, candidates: list[np.ndarray], weights: np.ndarray,
         truncation: float = 0.1, engine: str = "numba",
         margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the candidate flow with the smallest :func:`flow_cost`.

    Parameters
    ----------
    i0, i1, weights, truncation, engine
        As in :func:`flow_cost`.
    candidates : list of ndarray, each (H, W, 2)
        In order of preference: a later candidate wins only where its cost is
        smaller by more than ``margin``.
    margin : float
        The cost advantage a later candidate needs (0: strictly smaller).

    Returns
    -------
    flow : ndarray, shape (H, W, 2), float32
    choice : ndarray, shape (H, W), int8
        Index of the kept candidate.
    """
    if not candidates:
        raise ValueError("candidates: need at least one flow")
    best = np.array(candidates[0], np.float32, copy=True)
    best_cost = flow_cost(i0, i1, best, weights, truncation, engine)
    choice = np.zeros(best_cost.shape, np.int8)
    for k, cand in enumerate(candidates[1:], start=1):
        cost = flow_cost(i0, i1, cand, weights, truncation, engine)
        better = cost < best_cost - np.float32(margin)
        best[better] = np.asarray(cand, np.float32)[better]
        best_cost = np.where(better, cost, best_cost)
        choice[better] = k
    return best, choice


def relight(i0: np.ndarray, i1: np.ndarray, flow: np.ndarray,
            trim: float = 2.5) -> np.ndarray:
    """The reference frame under the light of the other frame: a fitted change of light.

    Per channel ``c``, the model ``I1_c(x + w(x)) ≈ (a_c + b_c·x̂ + c_c·ŷ)·I0_c(x) + d_c``
    (a gain that varies linearly across the frame, ``x̂, ŷ`` in [−1, 1], and an
    offset) is fitted by least squares to the pixels whose target lies inside
    ``I1``, then fitted again to those whose residual is within ``trim`` times the
    median absolute residual, so that occlusions and wrong vectors do not pull the
    fit.  The result ``(a_c + b_c·x̂ + c_c·ŷ)·I0_c + d_c``, clipped to [0, 1], is what
    ``I0`` looks like under the light of ``I1``: compared with ``I1`` it gives a
    colour residual that a slow change of gain, offset or a gain gradient across the
    frame leaves alone, and with no change of light the fit is the identity up to
    noise.

    Parameters
    ----------
    i0, i1 : ndarray, shape (H, W) or (H, W, C), float32
        Intensities in [0, 1].
    flow : ndarray, shape (H, W, 2)
        From ``i0`` to ``i1`` (NaN = unknown, left out of the fit).
    trim : float
        Outlier threshold of the second fit, in median absolute residuals.

    Returns
    -------
    ndarray, shape of ``i0``, float32
    """
    from .warp import warp_bilinear

    a0 = np.asarray(i0, np.float32)
    a1 = np.asarray(i1, np.float32)
    planes0 = a0.reshape(a0.shape[:2] + (-1,))
    planes1 = a1.reshape(a1.shape[:2] + (-1,))
    h, w = planes0.shape[:2]
    fl = np.asarray(flow, np.float32)
    known = np.isfinite(fl).all(axis=2)
    warped, inside = warp_bilinear(planes1, np.where(known[..., None], fl, 0.0))
    use = (inside & known).ravel()
    if use.sum() < 16:
        return a0.copy()
    yy, xx = np.mgrid[0:h, 0:w]
    xs = (2.0 * xx / max(w - 1, 1) - 1.0).ravel()
    ys = (2.0 * yy / max(h - 1, 1) - 1.0).ravel()
    out = np.empty_like(planes0)
    for c in range(planes0.shape[2]):
        v0 = planes0[..., c].ravel().astype(np.float64)
        v1 = warped[..., c].ravel().astype(np.float64)
        design = np.stack([v0, xs * v0, ys * v0, np.ones_like(v0)], axis=1)
        keep = use
        coef = np.array([1.0, 0.0, 0.0, 0.0])
        for _ in range(2):
            if keep.sum() < 16:
                break
            coef = np.linalg.lstsq(design[keep], v1[keep], rcond=None)[0]
            res = np.abs(design @ coef - v1)
            keep = use & (res <= trim * max(float(np.median(res[use])), 1e-6))
        out[..., c] = np.clip(design @ coef, 0.0, 1.0).reshape(h, w)
    return out.reshape(a0.shape)


def repair_with(cost: str, i0: np.ndarray, i1: np.ndarray, flow: np.ndarray,
                weights: np.ndarray, distances: tuple[int, ...] = (2, 4, 8),
                engine: str = "numba", stats: dict | None = None) -> np.ndarray:
    """:func:`repair` of a flow on the frames' colours, relit colours or census planes.

    Parameters
    ----------
    cost : {"colour", "relit", "census"}
        ``"colour"``: the residual of the colours, truncated at 0.1.  ``"relit"``:
        the same with the reference frame under the other frame's light
        (:func:`relight`, fitted along ``flow``): where the light changes, the
        colour residual of the true vector grows with the change, and a wrong vector
        that lands on a matching brightness can win.  ``"census"``: the residual of
        :func:`census_planes` of both frames, truncated at 0.5 (the planes lie in
        [−½, ½]), blind to the light but also to the colours.
    i0, i1 : ndarray, shape (H, W[, C]), float32
        The frames, intensities in [0, 1].
    flow, weights, distances, engine, stats
        As in :func:`repair`; the margin is :func:`repair_margin` of the frames.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    margin = repair_margin(i0, i1)
    if cost == "census":
        return repair(census_planes(i0), census_planes(i1), flow, weights, distances,
                      truncation=0.5, margin=margin, engine=engine, stats=stats)
    if cost == "relit":
        i0 = relight(i0, i1, flow)
    elif cost != "colour":
        raise ValueError(f"cost: must be 'colour', 'relit' or 'census', got {cost!r}")
    return repair(i0, i1, flow, weights, distances, margin=margin, engine=engine, stats=stats)


#: The 8 neighbours ``(dy, dx)`` of :func:`census_planes`.
CENSUS_OFFSETS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def census_planes(image: np.ndarray, eps: float = 0.02) -> np.ndarray:
    """Soft census transform: ``½ tanh((I(x + o) − I(x)) / ε)`` for the 8 neighbours ``o``.

    ``I`` is the mean of the channels.  Each plane says, smoothly, whether a
    neighbour is brighter or darker than the pixel, so that the residual of
    :func:`flow_cost` between two frames' planes (values in [−½, ½], pass
    ``truncation=0.5``) is unchanged by a brightness offset and nearly so by a
    contrast change, where the colour residual is truncated everywhere (Zabih &
    Woodfill 1994, census transform; the ``tanh`` keeps it differentiable in
    ``I`` and quiet on noise below ``ε``).  Borders replicate the edge pixel.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C), float
        Intensities in [0, 1].
    eps : float
        ε, the intensity difference at which a comparison is 76 % decided, > 0.

    Returns
    -------
    ndarray, shape (H, W, 8), float32

    References
    ----------
    R. Zabih, J. Woodfill, "Non-parametric local transforms for computing visual
    correspondence", ECCV 1994.
    """
    if not eps > 0:
        raise ValueError(f"eps: must be > 0, got {eps}")
    img = _check_image(image, "image")
    g = img.mean(axis=2, dtype=np.float32)
    h, w = g.shape
    pad = np.pad(g, 1, mode="edge")
    out = np.empty((h, w, len(CENSUS_OFFSETS)), np.float32)
    inv = np.float32(1.0 / eps)
    for k, (dy, dx) in enumerate(CENSUS_OFFSETS):
        out[..., k] = np.tanh((pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] - g) * inv) * 0.5
    return out


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH_NO_REASSOC)
def _candidate_costs_kernel(planar, res, offs, gamma, radius, trunc, out):
    """:func:`candidate_costs` with the support weights made on the fly, row by row.

    ``planar`` (C, H, W) is ``i0``; ``res`` (K, H, W) each candidate's truncated
    residual (``_OUT`` off-frame).  The unnormalised weights
    ``exp(-d/γ - |o|/(R + 1))`` serve every candidate; their normalisation cancels
    in the weighted mean.
    """
    h, w = planar.shape[1:]
    nk = offs.shape[0]
    ncand = res.shape[0]
    inv_g = np.float32(1.0 / gamma)
    spat = _spatial_exponents(offs, radius)
    for i in nb.prange(h):
        d = np.empty(w, np.float32)
        e = np.empty(w, np.float32)
        bits = np.empty(w, np.int32)
        acc = np.zeros((ncand, w), np.float32)
        tot = np.zeros((ncand, w), np.float32)
        for k in range(nk):
            yi = min(max(i + offs[k, 0], 0), h - 1)
            dx = offs[k, 1]
            _window_exponent_row(planar, i, yi, dx, w, inv_g, spat[k], d)
            _exp_neg_row(d, e, bits)
            lo = min(max(0, -dx), w)
            hi = max(min(w, w - dx), lo)
            em = e[lo:hi]
            for m in range(ncand):
                rr = res[m, yi]
                rm = rr[lo + dx:hi + dx]
                am = acc[m, lo:hi]
                tm = tot[m, lo:hi]
                for jj in range(hi - lo):
                    r = rm[jj]
                    ok = r >= 0.0
                    am[jj] += em[jj] * r if ok else np.float32(0.0)
                    tm[jj] += em[jj] if ok else np.float32(0.0)
                for j in range(lo):
                    r = rr[min(max(j + dx, 0), w - 1)]
                    if r >= 0.0:
                        acc[m, j] += e[j] * r
                        tot[m, j] += e[j]
                for j in range(hi, w):
                    r = rr[min(max(j + dx, 0), w - 1)]
                    if r >= 0.0:
                        acc[m, j] += e[j] * r
                        tot[m, j] += e[j]
        for m in range(ncand):
            for j in range(w):
                out[m, i, j] = acc[m, j] / tot[m, j] if tot[m, j] > 0.0 else trunc


def candidate_costs(i0: np.ndarray, i1: np.ndarray, candidates: list[np.ndarray],
                    radius: int = 2, gamma: float = 0.1, truncation: float = 0.1,
                    engine: str = "numba") -> np.ndarray:
    """:func:`flow_cost` of several candidates without the weight planes.

    Equal (to rounding) to ``flow_cost(i0, i1, c, support_weights(i0, radius,
    gamma), truncation)`` for each candidate ``c``, but the Numba engine makes the
    weights of each window on the fly and aggregates every candidate's residuals
    with them in one pass: no ``(2R + 1)²`` planes are written and read back.  For
    a single use of the weights (a pyramid level of ``tvl1-ld``) this is the cheap
    path; :func:`fuse` suits weights reused over many fusions.

    Parameters
    ----------
    i0, i1 : ndarray, shape (H, W) or (H, W, C), float32
    candidates : list of ndarray, each (H, W, 2)
    radius, gamma : as in :func:`support_weights`.
    truncation : float
        T, as in :func:`flow_cost`.
    engine : {"numba", "numpy"}
        ``"numpy"``: :func:`support_weights` and :func:`flow_cost` (NumPy engines).

    Returns
    -------
    ndarray, shape (K, H, W), float32
        The cost of each candidate.
    """
    _check_engine(engine)
    if not candidates:
        raise ValueError("candidates: need at least one flow")
    if radius < 0:
        raise ValueError(f"radius: must be >= 0, got {radius}")
    if not gamma > 0:
        raise ValueError(f"gamma: must be > 0, got {gamma}")
    i0 = _check_image(i0, "i0")
    i1 = _check_image(i1, "i1")
    if i1.shape != i0.shape:
        raise ValueError(f"i1: shape {i1.shape} differs from i0 {i0.shape}")
    flows = [_check_flow(c, i0.shape[:2], f"candidates[{k}]") for k, c in enumerate(candidates)]
    if engine == "numpy":
        weights = _support_weights_numpy(i0, radius, gamma)
        return np.stack([_shifted_cost(i0, i1, f, 0, 0, weights, truncation, "numpy")
                         for f in flows])
    h, w = i0.shape[:2]
    res = np.empty((len(flows), h, w), np.float32)
    for k, f in enumerate(flows):
        _residual_kernel(i0, i1, f, 0, 0, np.float32(truncation), res[k])
    out = np.empty_like(res)
    planar = np.ascontiguousarray(i0.transpose(2, 0, 1))
    _candidate_costs_kernel(planar, res, _offsets(radius), np.float32(gamma), radius,
                            np.float32(truncation), out)
    return out


def noise_sigma(image: np.ndarray) -> float:
    """Standard deviation of additive white noise in an image (Immerkær 1996).

    The 3x3 operator ``N = [[1, −2, 1], [−2, 4, −2], [1, −2, 1]]`` (the difference
    of two Laplacians) cancels locally planar structure; for white Gaussian noise
    of standard deviation σ, ``E|N * I| = σ·sqrt(36 · 2/π)``, hence::

        σ ≈ sqrt(π/2) · mean |N * I| / 6    (interior pixels, mean over channels).

    Edges and fine texture add to it, so on a clean photograph it returns a small
    positive value (about 0.005–0.015 for [0, 1] images), not zero.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C), H, W >= 3

    Returns
    -------
    float
        σ in the units of ``image``.

    References
    ----------
    J. Immerkær, "Fast noise variance estimation", Computer Vision and Image
    Understanding 64(2), 300–302, 1996.
    """
    return float(_IMMERKAER * np.mean(_immerkaer_response(image)))


_IMMERKAER = math.sqrt(math.pi / 2.0) / 6.0


def _immerkaer_response(image: np.ndarray) -> np.ndarray:
    """``|N * I|`` of :func:`noise_sigma` on the interior, channels averaged: (H-2, W-2)."""
    img = np.asarray(image, np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[0] < 3 or img.shape[1] < 3:
        raise ValueError(f"image: expected (H, W[, C]) with H, W >= 3, got {img.shape}")
    c = img[1:-1, 1:-1]
    edges = img[:-2, 1:-1] + img[2:, 1:-1] + img[1:-1, :-2] + img[1:-1, 2:]
    corners = img[:-2, :-2] + img[:-2, 2:] + img[2:, :-2] + img[2:, 2:]
    return np.abs(4.0 * c - 2.0 * edges + corners).mean(axis=2)


def noise_sigma_flat(image: np.ndarray, block: int = 16, percentile: float = 10.0) -> float:
    """:func:`noise_sigma` read on the flattest parts of the image.

    The mean response ``|N * I|`` of every ``block × block`` tile is taken, and the
    ``percentile``-th of those tile means is converted to σ as in
    :func:`noise_sigma`.  Texture and edges raise the response of their tiles only,
    so a photograph with flat regions reads its sensor noise rather than its
    texture: on the Middlebury pairs 0.0015–0.0087, on photographic pairs with
    added noise of σ 0.015–0.04 about 0.010–0.033 (:func:`noise_sigma` gives
    0.003–0.024 on the former).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C), H, W >= 3
    block : int
        Tile side, pixels (the tiles that fit; an image smaller than one tile is
        one tile).
    percentile : float
        In [0, 100].

    Returns
    -------
    float
        σ in the units of ``image``.
    """
    resp = _immerkaer_response(image)
    h, w = resp.shape
    bh, bw = min(block, h), min(block, w)
    nh, nw = h // bh, w // bw
    tiles = resp[:nh * bh, :nw * bw].reshape(nh, bh, nw, bw).mean(axis=(1, 3))
    return float(_IMMERKAER * np.percentile(tiles, percentile))


def repair_margin(i0: np.ndarray, i1: np.ndarray, floor: float = 0.005,
                  factor: float = 0.5) -> float:
    """The margin of :func:`repair` for a pair of frames: ``max(floor, factor·σ)``.

    ``σ`` is the noise of the residual ``I1(x + w) − I0(x)``: the root sum of the
    frames' :func:`noise_sigma`.  On noisy frames the window cost of a vector
    fluctuates by a fraction of σ from one candidate to the next; a fixed margin
    would let those chance differences swap good vectors for their neighbours'.

    Parameters
    ----------
    i0, i1 : ndarray, shape (H, W[, C])
    floor : float
        Margin of clean frames, intensity units.
    factor : float
        Margin per unit of residual noise σ.

    Returns
    -------
    float
    """
    sigma = math.hypot(noise_sigma(i0), noise_sigma(i1))
    return max(float(floor), float(factor) * sigma)


def repair(i0: np.ndarray, i1: np.ndarray, flow: np.ndarray, weights: np.ndarray,
           distances: tuple[int, ...] = (2, 4, 8), iterations: int = 1,
           truncation: float = 0.1, margin: float = 0.005, engine: str = "numba",
           stats: dict | None = None) -> np.ndarray:
    """Spatial propagation of flow vectors across motion boundaries (see the module notes).

    For every distance ``d`` and direction ``e`` of :data:`REPAIR_DIRECTIONS` in
    turn, the field shifted by ``d·e`` is a candidate: pixel ``x`` takes the vector
    at ``x + d·e`` where that lowers its cost ``C`` (the cost of the candidate
    field at ``x``, computed with every pixel of the window using the shifted
    field).  The whole sequence runs ``iterations`` times.

    Parameters
    ----------
    i0, i1, weights, truncation, engine
        As in :func:`flow_cost`.
    flow : ndarray, shape (H, W, 2)
    distances : tuple of int
        Offsets in pixels.
    iterations : int
    margin : float
        A candidate must lower the cost by more than this (intensity units): a
        smooth field's neighbour vectors differ by a fraction of a pixel, and
        chance matches of the texture must not swap them in.
    stats : dict, optional
        Gains ``changed`` (share of the pixels whose vector changed).

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        A pixel changes only where the candidate field's cost is lower than the
        best cost met so far (each cost is that of a whole field, so a window's
        other pixels may not have taken the same candidate).
    """
    _check_engine(engine)
    i0 = _check_image(i0, "i0")
    i1 = _check_image(i1, "i1")
    best = np.array(_check_flow(flow, i0.shape[:2]), copy=True)
    cost = _shifted_cost(i0, i1, best, 0, 0, weights, truncation, engine)
    changed = np.zeros(i0.shape[:2], bool)
    h, w = i0.shape[:2]
    offs = _offsets(_radius_of(weights))
    res = np.empty((h, w), np.float32)
    trunc = np.float32(truncation)
    for _ in range(iterations):
        for d in distances:
            for ey, ex in REPAIR_DIRECTIONS:
                dy, dx = ey * d, ex * d
                src = best.copy()
                if engine == "numba":
                    _repair_step_kernel(i0, i1, src, dy, dx, weights, offs, trunc,
                                        np.float32(margin), res, best, cost, changed)
                    continue
                c = _shifted_cost(i0, i1, src, dy, dx, weights, truncation, engine)
                ys = np.clip(np.arange(h) + dy, 0, h - 1)
                xs = np.clip(np.arange(w) + dx, 0, w - 1)
                shifted = src[ys][:, xs]
                better = (c < cost - margin) & in_bounds(best) & in_bounds(shifted)
                best[better] = shifted[better]
                cost = np.where(better, c, cost)
                changed |= better
    if stats is not None:
        stats["changed"] = float(changed.mean())
    return best
