"""Kernels of the motion-compensated NL-Bayes denoiser (:mod:`varflow.restore.denoise`).

One pass of NL-Bayes (Lebrun, Buades & Morel 2013) on a clip, with the patch search
of its video form VNLB (Arias & Morel 2018): for a reference patch of frame ``t``,
similar patches are searched in a window of frame ``t`` and in small windows of the
frames ``t ± 1 .. t ± radius`` centred where the reference patch's centre goes along
the flows between consecutive frames.  The chain stops at the first step whose flow
the forward-backward check rejects: a neighbour frame where the patch is hidden is
never searched.  The ``n_similar`` nearest patches (squared distance over the
patch, on the *guide*: the noisy clip's luminance in the first pass, where the
colour channels add operations but no accuracy, and all channels of the first
estimate in the second) form the group, and each channel of the group is
estimated by an empirical Wiener filter (:func:`estimate_group`):

* first pass: ``P̂ = μ + (C − β σ² I) C⁻¹ (P − μ)`` with ``μ, C`` the mean and
  covariance of the noisy group;
* second pass ("oracle"): ``P̂ = μ + C_b (C_b + σ² I)⁻¹ (P − μ)`` with ``C_b`` the
  covariance of the first estimate's group and ``μ`` the mean of the noisy group;

and a group whose variance is within ``flat · σ²`` of the noise is replaced by its
mean (NL-Bayes' homogeneous-area rule).  Every estimated patch of the group is
added to the sums of its own frame, as VNLB aggregates, so a pixel of frame ``t``
gathers the estimates of the groups formed in frames ``t ± radius``; a position of
frame ``t`` covered by a patch of one of frame ``t``'s groups is not a reference
again (the "paste trick"), and each frame is its sum over its count.  The
reference frames are taken one after the other in increasing order.

Work is split in bands of reference rows.  A band writes only the rows from
``search`` above to ``search + patch − 1`` below its own, in every frame (a patch
of a neighbour frame farther out is used in the estimate but not added), so two
bands of one phase (even, then odd) write disjoint rows: each phase runs in
parallel without races and the sums do not depend on the number of threads.  A
frame's sums do not depend on which frames before it were references, so a stream
that takes the same references in the same order gets the same bytes.

:func:`estimate_group` (the Wiener step) has the NumPy reference
:func:`estimate_group_reference`; the tests compare them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit, prange

__all__ = ["band_height", "denoise_pass", "estimate_group", "estimate_group_reference",
           "group_workspace"]


def estimate_group_reference(group: np.ndarray, pilot: np.ndarray | None, sigma2: float,
                             beta: float, flat: float) -> np.ndarray:
    """NumPy reference of :func:`estimate_group` (same arguments, every patch estimated)."""
    g = group.astype(np.float64)  # (C, d, m)
    out = np.empty_like(g)
    if flat > 0 and np.all(g.reshape(g.shape[0], -1).var(axis=1) < flat * sigma2):
        out[:] = g.mean(axis=(1, 2), keepdims=True)
        return out.astype(np.float32)
    d, m = g.shape[1:]
    for c in range(g.shape[0]):
        x = g[c]
        mu = x.mean(axis=1, keepdims=True)
        if pilot is None and m - 1 < d:  # the Gram form of a small group
            xc = x - mu
            lam, vec = np.linalg.eigh(xc.T @ xc / (m - 1))
            b = beta * (1.0 + np.sqrt(d / (m - 1))) ** 2
            w = np.where(lam > 0, np.maximum(lam - b * sigma2, 0) / np.where(lam > 0, lam, 1),
                         0)
            out[c] = mu + xc @ (vec * w) @ vec.T
        elif pilot is None:
            a = np.cov(x) + _RIDGE * sigma2 * np.eye(d)
            out[c] = x - beta * sigma2 * np.linalg.solve(a, x - mu)
        else:
            a = np.cov(pilot[c].astype(np.float64)) + sigma2 * np.eye(d)
            out[c] = x - sigma2 * np.linalg.solve(a, x - mu)
    return out.astype(np.float32)


#: Ridge added to the noisy group's covariance in the first pass, in units of σ²: a
#: group of nearly equal patches (m close to d) keeps a well-conditioned matrix.
_RIDGE = 1e-3


@njit(cache=True)
def estimate_group(group, pilot, sigma2, beta, flat, keep, out, cov, low, vec,
                   buf):  # pragma: no cover - numba
    """Empirical Wiener estimate of a group of patches, channel by channel.

    ``P̂ = P − β σ² C⁻¹ (P − μ)`` in the first pass (C the noisy group's covariance,
    i.e. ``μ + (C − β σ² I) C⁻¹ (P − μ)``) and ``P̂ = P − σ² (C_b + σ² I)⁻¹ (P − μ)``
    in the final pass (C_b the first estimate's), both by a Cholesky factorisation;
    μ is the noisy group's mean.

    Parameters
    ----------
    group : ndarray, shape (C, d, m), float32
        The noisy patches (d values per channel, m patches, m >= 2).
    pilot : ndarray, shape (C, d, m), float32, or shape (C, d, 0)
        The first estimate's patches of the same group (final pass), or empty
        (first pass).
    sigma2 : float
        Noise variance σ², in the squared units of the values.
    beta : float
        β of the first pass.
    flat : float
        γ of the homogeneous-area rule (0: off).
    keep : ndarray, shape (m,), bool
        The patches to estimate (the others are left as they are in ``out``).
    out : ndarray, shape (C, d, m), float32
        The estimates (written).
    cov, low : ndarray, shape (d, d), float64
        Workspace.
    vec : ndarray, shape (2, d), float64
        Workspace.
    buf : ndarray, shape (>= 2 d m,), float64
        Workspace (:func:`group_workspace` makes all four).
    """
    nc, d, m = group.shape
    if flat > 0:
        homogeneous = True
        for c in range(nc):
            s = 0.0
            s2 = 0.0
            for j in range(d):
                for i in range(m):
                    v = np.float64(group[c, j, i])
                    s += v
                    s2 += v * v
            n = m * d
            mean = s / n
            if s2 / n - mean * mean >= flat * sigma2:
                homogeneous = False
                break
        if homogeneous:
            for c in range(nc):
                s = 0.0
                for j in range(d):
                    for i in range(m):
                        s += group[c, j, i]
                mean = s / (m * d)
                for j in range(d):
                    for i in range(m):
                        if keep[i]:
                            out[c, j, i] = mean
            return
    oracle = pilot.shape[2] == m
    if not oracle and m - 1 < d:
        _estimate_small(group, sigma2, beta, keep, out)
        return
    mu = vec[0]
    nk = 0
    for i in range(m):
        if keep[i]:
            nk += 1
    xs = buf[:d * m].reshape((d, m))  # the centred patches, one per column
    zs = buf[d * m:d * m + d * nk].reshape((d, nk))
    for c in range(nc):
        gc = group[c]  # (d, m)
        oc = out[c]
        for j in range(d):
            s = 0.0
            for i in range(m):
                s += gc[j, i]
            mu[j] = s / m
        if oracle:
            pc = pilot[c]
            for j in range(d):
                s = 0.0
                for i in range(m):
                    s += pc[j, i]
                s /= m
                for i in range(m):
                    xs[j, i] = pc[j, i] - s
        else:
            for j in range(d):
                for i in range(m):
                    xs[j, i] = gc[j, i] - mu[j]
        np.dot(xs, xs.T, cov)
        ridge = sigma2 if oracle else _RIDGE * sigma2
        for j in range(d):
            cov[j, j] = cov[j, j] / (m - 1) + ridge
        # Cholesky: cov = L Lᵀ (only the lower triangle of cov is read)
        for j in range(d):
            s = cov[j, j]
            for k in range(j):
                s -= low[j, k] * low[j, k]
            ljj = np.sqrt(max(s, 1e-12 * sigma2 + 1e-30))
            low[j, j] = ljj
            for i in range(j + 1, d):
                s = cov[i, j] / (m - 1)
                for k in range(j):
                    s -= low[i, k] * low[j, k]
                low[i, j] = s / ljj
        # the kept patches, centred, then L Lᵀ z = x - μ for all of them at once
        for j in range(d):
            q = 0
            for i in range(m):
                if keep[i]:
                    zs[j, q] = gc[j, i] - mu[j]
                    q += 1
        for j in range(d):
            zj = zs[j]
            for k in range(j):
                lk = low[j, k]
                zk = zs[k]
                for q in range(nk):
                    zj[q] -= lk * zk[q]
            inv = 1.0 / low[j, j]
            for q in range(nk):
                zj[q] *= inv
        for j in range(d - 1, -1, -1):
            zj = zs[j]
            for k in range(j + 1, d):
                lk = low[k, j]
                zk = zs[k]
                for q in range(nk):
                    zj[q] -= lk * zk[q]
            inv = 1.0 / low[j, j]
            for q in range(nk):
                zj[q] *= inv
        factor = sigma2 if oracle else beta * sigma2
        for j in range(d):
            q = 0
            for i in range(m):
                if keep[i]:
                    oc[j, i] = gc[j, i] - factor * zs[j, q]
                    q += 1
    return


@njit(cache=True)
def _estimate_small(group, sigma2, beta, keep, out):  # pragma: no cover - numba
    """First-pass estimate of a group of fewer patches than dimensions (m - 1 < d),
    in the m × m Gram matrix: ``P̂ − μ = X V diag(w) Vᵀ`` for the centred group X
    and the eigenpairs (λ, V) of ``XᵀX / (m − 1)``, ``w = max(λ − β' σ², 0) / λ``
    with ``β' = β (1 + √(d / (m − 1)))²``, the upper edge of the Marchenko-Pastur
    law: the noise of d dimensions lies in the m − 1 of the group's span, where its
    eigenvalues reach that many times σ²."""
    nc, d, m = group.shape
    b = beta * (1.0 + np.sqrt(d / (m - 1))) ** 2
    xs = np.empty((d, m), np.float64)
    for c in range(nc):
        for j in range(d):
            s = 0.0
            for i in range(m):
                s += group[c, j, i]
            mu = s / m
            for i in range(m):
                xs[j, i] = group[c, j, i] - mu
        gram = np.dot(xs.T, xs) / (m - 1)
        lam, vec = np.linalg.eigh(gram)
        for k in range(m):
            w = max(lam[k] - b * sigma2, 0.0) / lam[k] if lam[k] > 0 else 0.0
            for i in range(m):
                vec[i, k] *= np.sqrt(w)
        proj = np.dot(vec, vec.T)  # V diag(w) Vᵀ
        est = np.dot(xs, proj)
        for j in range(d):
            mu = 0.0
            for i in range(m):
                mu += group[c, j, i]
            mu /= m
            for i in range(m):
                if keep[i]:
                    out[c, j, i] = est[j, i] + mu
    return


def group_workspace(d: int, m: int) -> tuple[np.ndarray, ...]:
    """The workspace arrays of :func:`estimate_group` for groups of at most ``m``
    patches of ``d`` values per channel: ``(cov, low, vec, buf)``."""
    return (np.zeros((d, d)), np.zeros((d, d)), np.zeros((2, d)), np.zeros(2 * d * m))


def band_height(search: int, patch: int) -> int:
    """Rows of reference positions per band: two bands of one phase never write the
    same rows (a band writes ``search`` rows above and ``search + patch - 1`` below
    its own)."""
    return max(32, 2 * search + patch)


@njit(cache=True)
def _chain(flows, oks, t, cy, cx, radius, step, h, w, pos_y, pos_x, alive):  # pragma: no cover
    """Follow the centre (cy, cx) of frame t along the consecutive flows, ``step``
    +1 (forward: ``flows``/``oks`` hold frame s -> s + 1 at index s) or -1 (backward:
    frame s -> s - 1 at index s - 1); fill pos_y/pos_x/alive for 1..radius."""
    nf = flows.shape[0] + 1
    qy = cy
    qx = cx
    s = t
    for j in range(1, radius + 1):
        alive[j] = False
        nxt = s + step
        if nxt < 0 or nxt >= nf:
            break
        k = s if step > 0 else s - 1
        iy = int(np.floor(qy + 0.5))
        ix = int(np.floor(qx + 0.5))
        if iy < 0 or iy >= h or ix < 0 or ix >= w or not oks[k, iy, ix]:
            break
        qx = qx + flows[k, iy, ix, 0]
        qy = qy + flows[k, iy, ix, 1]
        if not (qy > -0.5 and qy < h - 0.5 and qx > -0.5 and qx < w - 0.5):
            break
        pos_y[j] = qy
        pos_x[j] = qx
        alive[j] = True
        s = nxt
    return


@njit(cache=True)
def _before(cd, a, b):  # pragma: no cover - numba
    """Candidate a comes before b: a smaller distance, or an equal one found earlier
    (candidates are stored in the order they are found)."""
    return cd[a] < cd[b] or (cd[a] == cd[b] and a < b)


@njit(cache=True)
def _select(cd, idx, count, k):  # pragma: no cover - numba
    """Reorder ``idx[:count]`` (a permutation of candidate numbers) so that
    ``idx[k]`` is the (k + 1)-th first candidate in (distance, order) and the
    ones before it come before it (a quickselect, O(count) on average)."""
    lo = 0
    hi = count - 1
    while lo < hi:
        mid = (lo + hi) // 2  # the median of three as the pivot
        if _before(cd, idx[mid], idx[lo]):
            idx[mid], idx[lo] = idx[lo], idx[mid]
        if _before(cd, idx[hi], idx[lo]):
            idx[hi], idx[lo] = idx[lo], idx[hi]
        if _before(cd, idx[hi], idx[mid]):
            idx[hi], idx[mid] = idx[mid], idx[hi]
        pivot = idx[mid]
        i = lo
        j = hi
        while i <= j:
            while _before(cd, idx[i], pivot):
                i += 1
            while _before(cd, pivot, idx[j]):
                j -= 1
            if i <= j:
                idx[i], idx[j] = idx[j], idx[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return
    return


@njit(cache=True)
def _first(cd, idx, count, n):  # pragma: no cover - numba
    """Put the first ``n`` of ``count`` > ``n`` candidates in (distance, order) in
    ``idx[:n]`` (in no particular order, the n-th at ``idx[n - 1]``); return the
    n-th's distance."""
    for i in range(count):
        idx[i] = i
    _select(cd, idx, count, n - 1)
    return cd[idx[n - 1]]


@njit(cache=True)
def _nearest(cd, idx, count, n, order):  # pragma: no cover - numba
    """The first ``min(n, count)`` candidates in (distance, order), in that order,
    into ``order``; returns how many."""
    if count > n:
        _first(cd, idx, count, n)
        count = n
        chosen = np.sort(idx[:count])  # in the order found, then stably by distance
    else:
        chosen = np.arange(count)
    ranked = np.argsort(cd[chosen], kind="mergesort")
    for i in range(count):
        order[i] = chosen[ranked[i]]
    return count


@njit(cache=True)
def _band(noisy, guide, gplane, pilot_on, fwd, bwd, fwd_ok, bwd_ok, t, y_lo, y_hi, patch, stride,
          search, search_t, radius, n_similar, dist_channels, tau, n_min, sigma2, beta,
          flat, acc, weight, done):  # pragma: no cover - numba
    """One band of reference rows [y_lo, y_hi) of frame t (see the module)."""
    nf, h, w, nc = noisy.shape
    d = patch * patch
    half = (patch - 1) // 2
    hd = np.empty(n_similar, np.float64)
    hf = np.empty(n_similar, np.int32)
    hy = np.empty(n_similar, np.int32)
    hx = np.empty(n_similar, np.int32)
    most = 1 + (2 * search + 1) ** 2 + 2 * radius * (2 * search_t + 1) ** 2
    cd = np.empty(most, np.float64)  # the candidates kept, in the order found
    cf = np.empty(most, np.int32)
    cy = np.empty(most, np.int32)
    cx = np.empty(most, np.int32)
    idx = np.empty(most, np.int64)
    order = np.empty(n_similar, np.int64)
    pos_y = np.empty(radius + 1, np.float64)
    pos_x = np.empty(radius + 1, np.float64)
    alive = np.zeros(radius + 1, np.bool_)
    group_ws = np.empty((nc, d, n_similar), np.float32)
    pilot_ws = np.empty((nc, d, n_similar), np.float32)
    est_ws = np.empty((nc, d, n_similar), np.float32)
    keep_ws = np.zeros(n_similar, np.bool_)
    ref = np.empty((dist_channels, patch, patch), np.float32)
    drow = np.empty(2 * max(search, search_t) + 1, np.float64)
    cov = np.zeros((d, d), np.float64)
    low = np.zeros((d, d), np.float64)
    vec = np.zeros((2, d), np.float64)
    buf = np.zeros(2 * d * n_similar, np.float64)
    ymax = h - patch
    xmax = w - patch
    zone_lo = y_lo - search  # the top rows of the patches this band may add
    zone_hi = y_hi - 1 + search
    for y in range(y_lo, min(y_hi, ymax + 1)):
        if not (y % stride == 0 or y == ymax):
            continue
        for x in range(0, xmax + 1):
            if not (x % stride == 0 or x == xmax):
                continue
            if done[t, y, x]:
                continue
            for c in range(dist_channels):
                for py in range(patch):
                    for px in range(patch):
                        ref[c, py, px] = gplane[t, c, y + py, x + px]
            # candidates in a fixed order (the reference itself first, then frame
            # t's window, then the windows along the flows); after each window the
            # n_similar-th nearest so far bounds the distance of the ones kept
            cd[0] = -1.0
            cf[0] = t
            cy[0] = y
            cx[0] = x
            count = 1
            limit = np.inf
            for side in range(2):
                fr_step = 1 if side == 0 else -1
                if radius > 0:
                    if side == 0:
                        _chain(fwd, fwd_ok, t, y + half, x + half, radius, 1, h, w,
                               pos_y, pos_x, alive)
                    else:
                        _chain(bwd, bwd_ok, t, y + half, x + half, radius, -1, h, w,
                               pos_y, pos_x, alive)
                for j in range(0 if side == 0 else 1, radius + 1):
                    if j == 0:
                        f = t
                        oy = y
                        ox = x
                        win = search
                    else:
                        if not alive[j]:
                            break
                        f = t + fr_step * j
                        oy = int(np.floor(pos_y[j] + 0.5)) - half
                        ox = int(np.floor(pos_x[j] + 0.5)) - half
                        win = search_t
                    xa = max(0, ox - win)
                    nx = min(xmax, ox + win) + 1 - xa
                    if nx <= 0:
                        continue
                    for yy in range(max(0, oy - win), min(ymax, oy + win) + 1):
                        # the distances of the row's candidates together (each summed
                        # in a fixed order); the row is dropped once every one of
                        # them reaches the bound
                        for k in range(nx):
                            drow[k] = 0.0
                        for py in range(patch):
                            for px in range(patch):
                                for c in range(dist_channels):
                                    r = ref[c, py, px]
                                    line = gplane[f, c, yy + py]
                                    for k in range(nx):
                                        diff = line[xa + px + k] - r
                                        drow[k] += diff * diff
                            low_d = drow[0]
                            for k in range(1, nx):
                                low_d = min(low_d, drow[k])
                            if low_d >= limit:
                                break
                        for k in range(nx):
                            xx = xa + k
                            if (f == t and yy == y and xx == x) or drow[k] >= limit:
                                continue
                            cd[count] = drow[k]
                            cf[count] = f
                            cy[count] = yy
                            cx[count] = xx
                            count += 1
                    if count > n_similar:  # a later candidate at this distance is not kept
                        limit = _first(cd, idx, count, n_similar)
            m = _nearest(cd, idx, count, n_similar, order)
            for i in range(m):
                q = order[i]
                hd[i] = cd[q]
                hf[i] = cf[q]
                hy[i] = cy[q]
                hx[i] = cx[q]
            if tau > 0:  # only the candidates within tau of the reference
                limit = tau * sigma2 * d * dist_channels
                kept = 0
                while kept < m and hd[kept] <= limit:
                    kept += 1
                m = max(kept, min(n_min, m))
            if m < 2:
                continue
            group = group_ws[:, :, :m]
            pilot = pilot_ws[:, :, :m] if pilot_on else pilot_ws[:, :, :0]
            keep = keep_ws[:m]
            for i in range(m):
                f = hf[i]
                y0 = hy[i]
                x0 = hx[i]
                keep[i] = f == t or (y0 >= zone_lo and y0 <= zone_hi)
                for py in range(patch):
                    row = noisy[f, y0 + py, x0:x0 + patch]  # (patch, C)
                    for px in range(patch):
                        for c in range(nc):
                            group[c, py * patch + px, i] = row[px, c]
                    if pilot_on:
                        row = guide[f, y0 + py, x0:x0 + patch]
                        for px in range(patch):
                            for c in range(nc):
                                pilot[c, py * patch + px, i] = row[px, c]
            est = est_ws[:, :, :m]
            estimate_group(group, pilot, sigma2, beta, flat, keep, est, cov, low, vec, buf)
            for i in range(m):
                if not keep[i]:
                    continue
                f = hf[i]
                y0 = hy[i]
                x0 = hx[i]
                for py in range(patch):
                    arow = acc[f, y0 + py, x0:x0 + patch]  # (patch, C)
                    wrow = weight[f, y0 + py, x0:x0 + patch]
                    for px in range(patch):
                        wrow[px] += 1.0
                        for c in range(nc):
                            arow[px, c] += est[c, py * patch + px, i]
                if hf[i] == t:
                    done[t, hy[i], hx[i]] = True
    return


@njit(cache=True, parallel=True)
def _phase(noisy, guide, gplane, pilot_on, fwd, bwd, fwd_ok, bwd_ok, tasks, band, patch, stride,
           search, search_t, radius, n_similar, dist_channels, tau, n_min, sigma2, beta,
           flat, acc, weight, done):  # pragma: no cover - numba
    h = noisy.shape[1]
    for i in prange(tasks.shape[0]):
        t = tasks[i, 0]
        y_lo = tasks[i, 1] * band
        y_hi = min(y_lo + band, h)
        _band(noisy, guide, gplane, pilot_on, fwd, bwd, fwd_ok, bwd_ok, t, y_lo, y_hi, patch,
              stride, search, search_t, radius, n_similar, dist_channels, tau, n_min, sigma2,
              beta, flat, acc, weight, done)


def accumulate_pass(noisy: np.ndarray, guide: np.ndarray, oracle: bool, fwd: np.ndarray,
                    bwd: np.ndarray, fwd_ok: np.ndarray, bwd_ok: np.ndarray,
                    acc: np.ndarray, weight: np.ndarray, done: np.ndarray, *,
                    refs: Sequence[int], sigma: float, patch: int, stride: int, search: int,
                    search_t: int, radius: int, n_similar: int, beta: float, flat: float,
                    dist_channels: int = 0, tau: float = 0.0, n_min: int = 2) -> None:
    """Add the groups of reference frames ``refs`` (in that order) to the sums.

    Parameters
    ----------
    noisy, guide : ndarray, shape (F, H, W, C), float32
        The noisy clip and the clip the patches are compared on (the noisy clip in
        the first pass, the first estimate in the second).
    oracle : bool
        Second pass: the guide's groups give the statistics.
    fwd, bwd : ndarray, shape (F - 1, H, W, 2), float32
        Flows frame s -> s + 1 and s + 1 -> s at index s (zeros and
        ``radius = 0`` for a single frame).
    fwd_ok, bwd_ok : ndarray, shape (F - 1, H, W), bool
        Where each flow passed the forward-backward check.
    acc : ndarray, shape (F, H, W, C), float32
        Sums of the estimates (added to).
    weight : ndarray, shape (F, H, W), float32
        Their counts (added to).
    done : ndarray, shape (F, H, W), bool
        Positions of each reference frame already covered (set).
    refs : sequence of int
        The reference frames, in the order they are taken.
    sigma : float
        Noise standard deviation (units of the values).
    patch, stride, search, search_t, radius, n_similar, beta, flat
        See :class:`varflow.restore.methods.NLBayesParams`.
    dist_channels : int
        The patches are compared on the first ``dist_channels`` channels (the
        luminance alone with 1); 0: all.
    tau : float
        Of the ``n_similar`` nearest, only those within ``tau σ²`` per compared
        value of the reference join its group (at least ``n_min``); 0: all.
    n_min : int
        The smallest group under ``tau``.
    """
    nf, h, w, nc = noisy.shape
    band = band_height(search, patch)
    nbands = -(-h // band)
    if fwd.shape[0] == 0:
        fwd = np.zeros((1, h, w, 2), np.float32)
        bwd = fwd
        fwd_ok = np.zeros((1, h, w), np.bool_)
        bwd_ok = fwd_ok
        radius = 0
    channels = dist_channels if 0 < dist_channels <= nc else nc
    guide = np.ascontiguousarray(guide, np.float32)
    # the compared channels as planes (F, channels, H, W): a row of candidates reads
    # consecutive values
    gplane = np.ascontiguousarray(guide[..., :channels].transpose(0, 3, 1, 2))
    args = (np.ascontiguousarray(noisy, np.float32), guide, gplane, bool(oracle),
            np.ascontiguousarray(fwd, np.float32), np.ascontiguousarray(bwd, np.float32),
            np.ascontiguousarray(fwd_ok), np.ascontiguousarray(bwd_ok))
    for t in refs:
        for parity in (0, 1):
            tasks = np.array([(int(t), b) for b in range(parity, nbands, 2)],
                             np.int64).reshape(-1, 2)
            if len(tasks):
                _phase(*args, tasks, band, patch, stride, search, search_t, radius, n_similar,
                       channels, float(tau),
                       int(n_min), float(sigma) ** 2, float(beta), float(flat), acc, weight,
                       done)


def denoise_pass(noisy: np.ndarray, guide: np.ndarray, oracle: bool, fwd: np.ndarray,
                 bwd: np.ndarray, fwd_ok: np.ndarray, bwd_ok: np.ndarray, *, sigma: float,
                 patch: int, stride: int, search: int, search_t: int, radius: int,
                 n_similar: int, beta: float, flat: float, dist_channels: int = 0,
                 tau: float = 0.0, n_min: int = 2,
                 frames: Sequence[int] | None = None) -> np.ndarray:
    """One NL-Bayes pass over a clip (see the module and :func:`accumulate_pass`).

    Parameters
    ----------
    noisy, guide, oracle, fwd, bwd, fwd_ok, bwd_ok
        As :func:`accumulate_pass`.
    sigma, patch, stride, search, search_t, radius, n_similar, beta, flat
        As :func:`accumulate_pass`.
    dist_channels, tau, n_min
        As :func:`accumulate_pass`.
    frames : sequence of int, optional
        The reference frames, in increasing order (default all).  A frame's
        estimate is complete when every frame within ``radius`` of it is one.

    Returns
    -------
    ndarray, shape (F, H, W, C), float32
        The estimate; zeros where no group reached.
    """
    nf, h, w, nc = noisy.shape
    refs = range(nf) if frames is None else [int(k) for k in frames]
    acc = np.zeros((nf, h, w, nc), np.float32)
    weight = np.zeros((nf, h, w), np.float32)
    done = np.zeros((nf, h, w), np.bool_)
    accumulate_pass(noisy, guide, oracle, fwd, bwd, fwd_ok, bwd_ok, acc, weight, done,
                    refs=refs, sigma=sigma, patch=patch, stride=stride, search=search,
                    search_t=search_t, radius=radius, n_similar=n_similar, beta=beta,
                    flat=flat, dist_channels=dist_channels, tau=tau, n_min=n_min)
    return normalise(acc, weight)


def normalise(acc: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``acc / weight`` where ``weight > 0``, else 0: shapes (..., C) and (...)."""
    out = np.zeros_like(acc)
    np.divide(acc, weight[..., None], out=out, where=weight[..., None] > 0)
    return out
