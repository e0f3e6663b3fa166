"""Forward splatting of values along a flow, and outside-in hole filling.

Backward warping (:mod:`varflow.ops.warp`) asks, for every target pixel, where it
comes from.  Forward splatting answers the other question, where every source pixel
goes: source pixel ``x`` carries its value ``f(x)`` to the point ``x + s·w(x)``
(``w`` a flow, ``s`` a time scale such as the ``t`` of an in-between frame) and
shares it between the four pixels around that point with the bilinear weights,
multiplied by an importance ``z(x) > 0``::

    acc[p] += b_p(x) z(x) f(x),    tot[p] += b_p(x) z(x)

and the splatted field is ``acc / tot`` where ``tot`` is positive.  With
``z = exp(−α Z)`` for a cost ``Z`` this is the softmax splatting of Niklaus & Liu
(2020): where several surfaces land on one pixel, the one of lowest cost dominates
(α large: a z-buffer; α = 0: the average).  Pixels that nothing lands on are
holes; :func:`fill_holes` fills them outside in, each hole pixel taking the mean of
its already known 8-neighbours, ring by ring (Baker et al. 2011 fill the holes of
their forward-warped flow "outside-in").

Two engines with the same results: the NumPy references (:func:`splat_numpy`,
:func:`fill_holes_numpy`) and the Numba kernels behind :func:`splat` and
:func:`fill_holes`.  Splatting is sequential (several sources write to one target;
a sequential sum is also deterministic), the hole filling processes each ring in
parallel (a ring reads only earlier rings).

References
----------
S. Baker, D. Scharstein, J. P. Lewis, S. Roth, M. J. Black, R. Szeliski, "A Database
and Evaluation Methodology for Optical Flow", IJCV 92(1), 2011, section 3.3
(frame interpolation: the flow splatted to time t, holes filled outside in).
S. Niklaus, F. Liu, "Softmax Splatting for Video Frame Interpolation", CVPR 2020.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["fill_holes", "fill_holes_numpy", "splat", "splat_numpy", "splat_trajectories",
           "splat_trajectories_numpy"]


def _check(values: np.ndarray, flow: np.ndarray, weights: np.ndarray,
           scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    values = np.asarray(values, np.float32)
    if values.ndim == 2:
        values = values[..., None]
    flow = np.asarray(flow, np.float32)
    weights = np.asarray(weights, np.float64)
    if values.ndim != 3 or flow.shape != values.shape[:2] + (2,):
        raise ValueError(f"splat: values {values.shape} and flow {flow.shape} do not match")
    if weights.shape != values.shape[:2]:
        raise ValueError(f"splat: weights {weights.shape} do not match values {values.shape}")
    if not np.isfinite(scale):
        raise ValueError(f"splat: scale must be finite, got {scale}")
    return values, flow, weights


def splat_numpy(values: np.ndarray, flow: np.ndarray, weights: np.ndarray,
                scale: float = 1.0, acc: np.ndarray | None = None,
                tot: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Reference engine of :func:`splat` (NumPy, ``np.add.at``)."""
    values, flow, weights = _check(values, flow, weights, scale)
    h, w, k = values.shape
    acc = np.zeros((h, w, k), np.float64) if acc is None else acc
    tot = np.zeros((h, w), np.float64) if tot is None else tot
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    s = np.float32(scale)
    px = xx + s * flow[..., 0]
    py = yy + s * flow[..., 1]
    ok = np.isfinite(px) & np.isfinite(py) & np.isfinite(weights) & (weights > 0)
    px, py, z, vals = px[ok], py[ok], weights[ok], values[ok]
    x0 = np.floor(px).astype(np.int64)
    y0 = np.floor(py).astype(np.int64)
    fx = (px - x0).astype(np.float64)
    fy = (py - y0).astype(np.float64)
    flat_acc = acc.reshape(-1, k)
    flat_tot = tot.reshape(-1)
    for dy, dx, b in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)),
                      (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        tx, ty = x0 + dx, y0 + dy
        m = (tx >= 0) & (tx < w) & (ty >= 0) & (ty < h) & (b > 0)
        idx = ty[m] * w + tx[m]
        bz = b[m] * z[m]
        np.add.at(flat_tot, idx, bz)
        np.add.at(flat_acc, idx, vals[m].astype(np.float64) * bz[:, None])
    return acc, tot


@nb.njit(cache=True, inline="always")
def _scatter(px, py, vals, z, acc, tot):
    """Add ``z · vals`` (1-D, K values) at the point ``(px, py)`` to the four pixels
    around it with the bilinear weights (those inside the image)."""
    h, w = tot.shape
    if not (np.isfinite(px) and np.isfinite(py)):
        return
    fx0 = np.floor(px)
    fy0 = np.floor(py)
    if fx0 < -1.0 or fy0 < -1.0 or fx0 > w or fy0 > h:
        return
    x0 = int(fx0)
    y0 = int(fy0)
    fx = np.float64(px - fx0)
    fy = np.float64(py - fy0)
    for dy in range(2):
        ty = y0 + dy
        if ty < 0 or ty >= h:
            continue
        by = fy if dy == 1 else 1.0 - fy
        for dx in range(2):
            tx = x0 + dx
            if tx < 0 or tx >= w:
                continue
            b = (fx if dx == 1 else 1.0 - fx) * by
            if b <= 0.0:
                continue
            bz = b * z
            tot[ty, tx] += bz
            for c in range(vals.shape[0]):
                acc[ty, tx, c] += np.float64(vals[c]) * bz


@nb.njit(cache=True)
def _splat_kernel(values, flow, weights, scale, acc, tot):
    h, w, k = values.shape
    for i in range(h):
        for j in range(w):
            z = weights[i, j]
            if not z > 0:  # also NaN
                continue
            px = np.float32(j) + scale * flow[i, j, 0]
            py = np.float32(i) + scale * flow[i, j, 1]
            _scatter(px, py, values[i, j], np.float64(z), acc, tot)


def splat(values: np.ndarray, flow: np.ndarray, weights: np.ndarray, scale: float = 1.0,
          acc: np.ndarray | None = None,
          tot: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Forward-splat ``values`` along ``scale · flow`` with importance ``weights``.

    Parameters
    ----------
    values : ndarray, shape (H, W, K) or (H, W)
        What every source pixel carries (a flow, colours, ...); float32.
    flow : ndarray, shape (H, W, 2)
        Source pixel ``(y, x)`` lands at ``(x + s u, y + s v)``; NaN entries are
        skipped.
    weights : ndarray, shape (H, W)
        Importance ``z`` of every source pixel (float64, so that importances
        such as ``exp(−α Z)`` far below float32's range still count); entries
        that are not positive (or NaN) are skipped.
    scale : float
        ``s``.
    acc, tot : ndarray, optional
        float64 accumulators of shape (H, W, K) and (H, W) to add to (so that two
        sources can be splatted into one field); new zero arrays by default.

    Returns
    -------
    acc : ndarray, shape (H, W, K), float64
        ``Σ b z f`` per target pixel.
    tot : ndarray, shape (H, W), float64
        ``Σ b z`` per target pixel (0 where nothing landed).
    """
    values, flow, weights = _check(values, flow, weights, scale)
    h, w, k = values.shape
    if acc is None:
        acc = np.zeros((h, w, k), np.float64)
    if tot is None:
        tot = np.zeros((h, w), np.float64)
    if acc.shape != (h, w, k) or tot.shape != (h, w) or acc.dtype != np.float64 \
            or tot.dtype != np.float64:
        raise ValueError("splat: acc and tot must be float64 arrays of shape "
                         f"{(h, w, k)} and {(h, w)}")
    _splat_kernel(np.ascontiguousarray(values), np.ascontiguousarray(flow),
                  np.ascontiguousarray(weights), np.float32(scale), acc, tot)
    return acc, tot


def _trajectory_check(flow, accel, weights, time):
    flow = np.asarray(flow, np.float32)
    accel = np.asarray(accel, np.float32)
    weights = np.asarray(weights, np.float64)
    if flow.ndim != 3 or flow.shape[2] != 2 or accel.shape != flow.shape \
            or weights.shape != flow.shape[:2]:
        raise ValueError(f"splat_trajectories: flow {flow.shape}, accel {accel.shape} and "
                         f"weights {weights.shape} do not match")
    if not 0.0 <= time <= 1.0:
        raise ValueError(f"splat_trajectories: time must lie in [0, 1], got {time}")
    return flow, accel, weights


def splat_trajectories_numpy(flow: np.ndarray, accel: np.ndarray, weights: np.ndarray,
                             time: float, own_first: bool, acc: np.ndarray | None = None,
                             tot: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Reference engine of :func:`splat_trajectories` (through :func:`splat_numpy`)."""
    flow, accel, weights = _trajectory_check(flow, accel, weights, time)
    s = np.float32(time)
    d = s * flow + accel * ((s * s - s) / np.float32(2))
    own, other = -d, flow - d
    values = np.concatenate([own, other] if own_first else [other, own], axis=2)
    return splat_numpy(values, d, weights, 1.0, acc, tot)


@nb.njit(cache=True)
def _trajectory_kernel(flow, accel, weights, s, own_first, acc, tot):
    h, w = weights.shape
    half = (s * s - s) / np.float32(2.0)
    vals = np.empty(4, np.float64)
    k = 0 if own_first else 2
    for i in range(h):
        for j in range(w):
            z = weights[i, j]
            if not z > 0:
                continue
            dx = s * flow[i, j, 0] + accel[i, j, 0] * half
            dy = s * flow[i, j, 1] + accel[i, j, 1] * half
            vals[k] = -dx
            vals[k + 1] = -dy
            vals[2 - k] = flow[i, j, 0] - dx
            vals[3 - k] = flow[i, j, 1] - dy
            _scatter(np.float32(j) + dx, np.float32(i) + dy, vals, np.float64(z), acc, tot)


def splat_trajectories(flow: np.ndarray, accel: np.ndarray, weights: np.ndarray, time: float,
                       own_first: bool, acc: np.ndarray | None = None,
                       tot: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Splat a frame's pixels to where they are at ``time`` along quadratic trajectories.

    A pixel with flow ``f`` to the other frame of a pair and acceleration ``a``
    moves by ``d = s f + a (s² − s) / 2`` after a fraction ``s`` of the interval
    (``s`` = ``time``); it lands at ``x + d`` (bilinear weights times ``weights``,
    as :func:`splat`) carrying the vectors from there to its own frame, ``−d``,
    and to the other frame, ``f − d``.  One fused pass; the same sums as
    :func:`splat` of the four channels (the NumPy reference).

    Parameters
    ----------
    flow, accel : ndarray, shape (H, W, 2)
    weights : ndarray, shape (H, W)
        Importances (float64).
    time : float
        ``s`` in [0, 1].
    own_first : bool
        Channel order of the carried vectors: ``(own, other)`` or ``(other, own)``.
    acc, tot : ndarray, optional
        Accumulators (H, W, 4) and (H, W), float64, to add to.

    Returns
    -------
    acc : ndarray, shape (H, W, 4), float64
    tot : ndarray, shape (H, W), float64
    """
    flow, accel, weights = _trajectory_check(flow, accel, weights, time)
    h, w = weights.shape
    if acc is None:
        acc = np.zeros((h, w, 4), np.float64)
    if tot is None:
        tot = np.zeros((h, w), np.float64)
    if acc.shape != (h, w, 4) or tot.shape != (h, w) or acc.dtype != np.float64 \
            or tot.dtype != np.float64:
        raise ValueError("splat_trajectories: acc and tot must be float64 arrays of shape "
                         f"{(h, w, 4)} and {(h, w)}")
    _trajectory_kernel(np.ascontiguousarray(flow), np.ascontiguousarray(accel),
                       np.ascontiguousarray(weights), np.float32(time), bool(own_first),
                       acc, tot)
    return acc, tot


def _check_fill(field: np.ndarray, known: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    field = np.asarray(field, np.float32)
    if field.ndim == 2:
        field = field[..., None]
    known = np.asarray(known, bool)
    if field.ndim != 3 or known.shape != field.shape[:2]:
        raise ValueError(f"fill_holes: field {field.shape} and known {known.shape} do not match")
    return field, known


def fill_holes_numpy(field: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Reference engine of :func:`fill_holes` (NumPy, one ring per pass)."""
    field, known = _check_fill(field, known)
    h, w, k = field.shape
    out = np.where(known[..., None], field, 0).astype(np.float64)
    have = known.copy()
    if not have.any():
        return np.zeros_like(field)
    while not have.all():
        pad_v = np.pad(out * have[..., None], ((1, 1), (1, 1), (0, 0)))
        pad_n = np.pad(have.astype(np.float64), 1)
        s = np.zeros((h, w, k))
        n = np.zeros((h, w))
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy == 0 and dx == 0:
                    continue
                s += pad_v[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                n += pad_n[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
        ring = ~have & (n > 0)
        out[ring] = s[ring] / n[ring][:, None]
        have |= ring
    return out.astype(np.float32)


@nb.njit(cache=True, parallel=True)
def _ring_kernel(out, have, ring_y, ring_x, n_ring, newv):
    h, w, k = out.shape
    for r in nb.prange(n_ring):
        i = ring_y[r]
        j = ring_x[r]
        cnt = 0
        for c in range(k):
            newv[r, c] = 0.0
        for dy in range(-1, 2):
            y = i + dy
            if y < 0 or y >= h:
                continue
            for dx in range(-1, 2):
                x = j + dx
                if (dy == 0 and dx == 0) or x < 0 or x >= w or not have[y, x]:
                    continue
                cnt += 1
                for c in range(k):
                    newv[r, c] += out[y, x, c]
        for c in range(k):
            newv[r, c] /= cnt


@nb.njit(cache=True)
def _known_neighbour(have, i, j):
    h, w = have.shape
    for y in range(max(i - 1, 0), min(i + 2, h)):
        for x in range(max(j - 1, 0), min(j + 2, w)):
            if have[y, x] and (y != i or x != j):
                return True
    return False


@nb.njit(cache=True)
def _fill_kernel(out, have):
    """Fill ``out`` where ``have`` is False, ring by ring (see :func:`fill_holes`)."""
    h, w, k = out.shape
    n = h * w
    ring_y = np.empty(n, np.int64)
    ring_x = np.empty(n, np.int64)
    next_y = np.empty(n, np.int64)
    next_x = np.empty(n, np.int64)
    queued = np.zeros((h, w), np.bool_)
    n_ring = 0
    for i in range(h):  # the first ring: holes next to a known pixel
        for j in range(w):
            if not have[i, j] and _known_neighbour(have, i, j):
                queued[i, j] = True
                ring_y[n_ring] = i
                ring_x[n_ring] = j
                n_ring += 1
    newv = np.empty((n, k), np.float64)
    while n_ring > 0:
        _ring_kernel(out, have, ring_y, ring_x, n_ring, newv)
        for r in range(n_ring):
            for c in range(k):
                out[ring_y[r], ring_x[r], c] = newv[r, c]
            have[ring_y[r], ring_x[r]] = True
        n_next = 0
        for r in range(n_ring):  # the next ring: unknown, unqueued neighbours
            i = ring_y[r]
            j = ring_x[r]
            for dy in range(-1, 2):
                y = i + dy
                if y < 0 or y >= h:
                    continue
                for dx in range(-1, 2):
                    x = j + dx
                    if 0 <= x < w and not have[y, x] and not queued[y, x]:
                        queued[y, x] = True
                        next_y[n_next] = y
                        next_x[n_next] = x
                        n_next += 1
        ring_y, next_y = next_y, ring_y
        ring_x, next_x = next_x, ring_x
        n_ring = n_next


def fill_holes(field: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Fill the unknown pixels of a field outside in.

    Ring by ring: the unknown pixels with a known 8-neighbour take the mean of
    their known 8-neighbours and become known; repeated until every pixel is
    known.  Known pixels keep their values.

    Parameters
    ----------
    field : ndarray, shape (H, W, K) or (H, W)
        float32; values at unknown pixels are ignored.
    known : ndarray, shape (H, W), bool

    Returns
    -------
    ndarray, shape (H, W, K), float32
        All zeros when no pixel is known.
    """
    field, known = _check_fill(field, known)
    if not known.any():
        return np.zeros_like(field)
    out = np.where(known[..., None], field, 0).astype(np.float64)
    have = np.ascontiguousarray(known.copy())
    _fill_kernel(out, have)
    return out.astype(np.float32)
