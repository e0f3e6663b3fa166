"""TV-L1 optical flow: L1 (colour) constancy + (edge-weighted) total variation.

Energy at one warp, linearised around ``u0`` (Zach, Pock & Bischof 2007; Wedel et
al. 2009; Sánchez, Meinhardt-Llopis & Facciolo, IPOL 2013)::

    E(u) = Σ_x g(x) |∇u_1| + g(x) |∇u_2| + λ Σ_c |ρ_c(u)|,
    ρ_c(u) = I1w_c + ∇I1w_c · (u - u0) - I0_c

The scheme introduces an auxiliary flow v coupled to u by ||u - v||²/(2θ) and
alternates

1. ``v = prox_{λθ Σ|ρ_c|}(u)`` — point-wise; for colour images the vector-valued
   data term of Rakêt et al. (2011) is solved through its box-constrained dual by
   coordinate descent over the channels (exact for grey images);
2. ``u = v + θ div p`` and ``p ← Π_{|p| ≤ g}(p + (τ/θ) ∇u)`` — Chambolle's dual
   step for the (weighted) ROF problem of each flow component.

until the mean squared update falls below ε² (tested after every second iteration:
the kernel runs two iterations per pass over the data) or ``max_iterations`` is
reached.

Robust data terms (off by default).  A *gradient-constancy* term (Brox, Bruhn,
Papenberg & Weickert 2004; DeepFlow, Weinzaepfel et al. 2013) adds
``γ Σ_c |ρ_cx(u)| + |ρ_cy(u)|``, the linearised constancy of the image gradient::

    ρ_cx(u) = ∂_x J1w_c + ∇(∂_x J1w_c) · (u - u0) - ∂_x J0_c     (likewise for y)

on the frames smoothed by a Gaussian of σ_g (``J = G_σg * I``).  It is blind to
additive brightness changes, which the colour term is not.  A *normalisation*
(Zimmer, Bruhn & Weickert 2011) divides every linearised constraint by
``sqrt(|∇ρ|² + ζ²)``, ``∇ρ`` the spatial gradient of the constancy it linearises,
so that it measures a distance in pixels to its constraint line rather than a
residual scaled by the local contrast.  Both are point-wise and linear in ``u``:
they enter step 1 as more channels of the same multi-channel L1 prox, a channel
of weight ``w`` scaled by ``w/λ`` (``w |ρ| = λ |(w/λ) ρ|``), so the kernels are
unchanged (:func:`data_channels` builds the channels).

Symbol map: λ = ``data_weight``, θ = ``coupling``, τ = ``tv_step``,
ε = ``tolerance``, c of g(x) = exp(-c |∇I|²) = ``edge_weight``,
γ = ``gradient_weight``, σ_g = ``gradient_sigma``, ζ = ``data_normalisation``,
ε_H = ``huber`` (Huber-TV: the dual step ``Π_{|p| ≤ g}((p + (τ/θ)∇u) / (1 + τ ε_H / (θ g)))``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from .._jit import FASTMATH
from ..ops.differences import (
    derivative_planes,
    derivative_planes_numpy,
    divergence,
    gradient,
    image_derivatives,
    stencil5,
    stencil5_indices,
)
from ..ops.primal_dual import (
    F0,
    F1,
    NO_TENSOR,
    dual_row,
    ordered_sum,
    project_dual,
    prox_primal_row,
    row_blocks,
)
from ..ops.prox import prox_huber_conjugate, prox_linear_l1
from ..ops.pyramid import resize_bilinear, smooth_image, smooth_planes
from .coarse_to_fine import LevelState, coarse_to_fine
from .params import PRESETS, TVL1Params, deprecated_preset

__all__ = [
    "TVL1Params",
    "TVL1State",
    "level_state",
    "PlainTVL1Params",
    "TVL1FastParams",
    "solve_warp",
    "tvl1",
    "tvl1_iterations",
    "tvl1_iterations_numpy",
    "edge_weight",
    "data_channels",
    "data_duals",
    "gradient_channel_count",
]


@dataclass
class TVL1State:
    """What the TV-L1 solvers keep for one pyramid level (owned by the solver).

    Created on a level's first warp (:func:`level_state`) and updated in place; the
    driver holds it in ``LevelState.data`` and knows nothing of its fields.

    Attributes
    ----------
    level : int
        Pyramid level, 0 = finest (the gradient term's σ_g follows it).
    previous : TVL1State or None
        The coarser level's state (its own ``previous`` dropped), for warm starts.
    iterations : int
        Primal-dual iterations run at this level so far.
    g : ndarray, shape (h, w), float32, or None
        Radius of the TV dual ball: the edge weight g(x).
    tensor : ndarray, shape (3, h, w), float32, or None
        ``T = D^{1/2}`` as (T11, T12, T22) of tensor-directed TV; None: isotropic.
    p, tp : ndarray, shape (4, h, w), float32, or None
        TV dual variables (p1x, p1y, p2x, p2y) and ``T p`` (``tp is p`` when isotropic).
    q : ndarray, shape (C, h, w), float32, or None
        Dual variables of the data prox's colour channels (warm started across warps).
    q_all : ndarray, shape (K, h, w), float32, or None
        The data prox's duals of every channel when the data term has more than the
        colour channels (``q`` is then a view of its first planes).
    grad0 : ndarray or tuple or None
        The smoothed derivatives of the first frame for gradient constancy
        (:func:`data_channels`).
    """

    level: int = 0
    previous: TVL1State | None = None
    iterations: int = 0
    g: np.ndarray | None = None
    tensor: np.ndarray | None = None
    p: np.ndarray | None = None
    tp: np.ndarray | None = None
    q: np.ndarray | None = None
    q_all: np.ndarray | None = None
    grad0: Any = None


def level_state(state: LevelState, kind: type[TVL1State] = TVL1State) -> TVL1State:
    """The solver's state of the driver's level ``state``: ``state.data``, created as a
    ``kind`` (linked to the coarser level's, whose own link is dropped) if unset."""
    if state.data is None:
        prev = None if state.previous is None else state.previous.data
        if prev is not None:
            prev.previous = None  # keep one level of history
        state.data = kind(level=state.level, previous=prev)
    return state.data


def edge_weight(image: np.ndarray, c: float, g_min: float = 0.05) -> np.ndarray:
    """Edge weight g(x) = max(exp(-c |∇I|²), g_min) of an ``(H, W, C)`` image.

    ``|∇I|²`` is the squared gradient magnitude averaged over channels.

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    if c <= 0:
        return np.ones(image.shape[:2], np.float32)
    dx, dy = image_derivatives(image)
    mag2 = (dx * dx + dy * dy).mean(axis=2)
    return np.maximum(np.exp(-c * mag2), g_min).astype(np.float32)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def tvl1_iterations(
    ix, iy, a, g, tens, u, p, tp, q, lam, theta, tau, max_iter, tol, n_sweeps, aniso, blocks,
    huber=0.0,
):
    """Numba TV-L1 iterations at one warp; updates ``u``, ``p``, ``tp``, ``q`` in place.

    Two iterations per pass over the data (temporal blocking): rows are split
    into contiguous blocks (one task each) and a block is swept once, row by row,
    carrying two iterations in a wavefront.  At row ``i`` the first iteration
    updates the primal of row ``i`` and the dual of row ``i - 1`` (which needs the
    new ``u`` of rows ``i - 1`` and ``i``); the second then updates the primal of
    row ``i - 1`` and the dual of row ``i - 2``.  The data terms of a row are thus
    read once for two iterations while in cache.  The few updates at the edges of
    a block that need a neighbouring block's rows wait for three short passes.
    The result equals the classic two-pass (Jacobi) scheme exactly: every primal
    update sees the dual variables of the previous iteration.  The stopping test
    runs after every second iteration (an odd ``max_iter`` ends with one
    single-iteration pass).

    Parameters
    ----------
    ix, iy : (C, H, W) float32
        Derivatives of the warped second frame, planar (zero where the data term is off).
    a : (C, H, W) float32
        Residual at zero flow, ``I1w - I0 - ix*u0_1 - iy*u0_2`` (zero where off).
    g : (H, W) float32
        Radius of the dual ball (TV edge weight g(x)).
    tens : (3, H, W) float32
        Symmetric tensor ``T = D^{1/2}`` as (T11, T12, T22); read only if ``aniso``.
    u : (2, H, W) float32
        Flow (u1, u2), planar, updated in place.
    p : (4, H, W) float32
        Dual TV variables (p1x, p1y, p2x, p2y).
    tp : (4, H, W) float32
        ``T p``; pass ``p`` itself when not ``aniso``.
    q : (C, H, W) float32
        Dual variable of the data prox (warm start).
    lam, theta, tau, tol : float
        λ, θ, τ, ε.
    max_iter, n_sweeps : int
    aniso : bool
        Use the tensor (tensor-directed TV ``Σ |T ∇u_k|``).
    blocks : (n+1,) int64
        Row-block bounds from :func:`row_blocks`.
    huber : float
        ε_H of Huber-TV (0: TV).

    Returns
    -------
    int
        Iterations performed.
    """
    nc, h, w = a.shape
    t = lam * theta
    step = tau / theta
    tol2 = tol * tol
    n_blk = blocks.shape[0] - 1
    errs = np.zeros(h, np.float64)  # per row: the stopping test does not depend on blocks
    buf = np.empty((n_blk, 2, w), np.float32)
    it = 0
    while it < max_iter:
        two = max_iter - it >= 2  # else one last iteration: the wavefront without B
        it += 2 if two else 1
        # phase 0, the wavefront: iteration A at rows i (primal) and i - 1 (dual),
        # iteration B at i - 1 (primal) and i - 2 (dual); B's primal at the block's
        # first row and everything that needs the next block's rows is left to the
        # phases after it: 1, A's dual of the last row (next block's first u); 2, B's
        # primal of the first and last rows; 3, B's duals left.  One parallel loop
        # serves the four phases (one gufunc to compile; each phase ends in a barrier)
        for phase in range(4 if two else 2):
            for b in nb.prange(n_blk):
                r0 = blocks[b]
                r1 = blocks[b + 1]
                d1 = buf[b, 0]
                d2 = buf[b, 1]
                if phase == 0:
                    for i in range(r0, r1):
                        err = prox_primal_row(ix, iy, a, q, u, tp, i, d1, d2, t, theta,
                                              n_sweeps)
                        if not two:
                            errs[i] = err
                        if i > r0:
                            dual_row(u, p, tp, g, tens, i - 1, step, aniso, huber)
                        if two and i - 1 > r0:
                            errs[i - 1] = prox_primal_row(ix, iy, a, q, u, tp, i - 1, d1, d2,
                                                           t, theta, n_sweeps)
                        if two and i - 2 > r0:
                            dual_row(u, p, tp, g, tens, i - 2, step, aniso, huber)
                elif phase == 1:
                    dual_row(u, p, tp, g, tens, r1 - 1, step, aniso, huber)
                elif phase == 2:
                    errs[r0] = prox_primal_row(ix, iy, a, q, u, tp, r0, d1, d2, t, theta,
                                               n_sweeps)
                    if r1 - 1 > r0:
                        errs[r1 - 1] = prox_primal_row(ix, iy, a, q, u, tp, r1 - 1, d1, d2,
                                                       t, theta, n_sweeps)
                else:
                    dual_row(u, p, tp, g, tens, r0, step, aniso, huber)
                    if r1 - 2 > r0:
                        dual_row(u, p, tp, g, tens, r1 - 2, step, aniso, huber)
                    if r1 - 1 > r0:
                        dual_row(u, p, tp, g, tens, r1 - 1, step, aniso, huber)
        if ordered_sum(errs) / (h * w) < tol2:
            break
    return it


def tvl1_iterations_numpy(
    ix, iy, a, g, tens, u, p, tp, q, lam, theta, tau, max_iter, tol, n_sweeps, aniso, blocks=None,
    huber=0.0,
):
    """NumPy reference of :func:`tvl1_iterations` (same arguments and in-place updates).

    Written with the operators of :mod:`varflow.ops` on ``(H, W, ...)`` views.
    """
    _, h, w = a.shape
    t = lam * theta
    hw = lambda x: np.moveaxis(x, 0, -1)  # noqa: E731 - planar -> channels last view
    T = None
    if aniso:
        T = np.stack([np.stack([tens[0], tens[1]], -1), np.stack([tens[1], tens[2]], -1)], -2)
    it = 0
    while it < max_iter:
        it += 1
        d, qn = prox_linear_l1(hw(u), hw(a), hw(ix), hw(iy), t, n_sweeps=n_sweeps, q0=hw(q))
        q[...] = np.moveaxis(qn, -1, 0)
        new = np.stack([d[..., k] + theta * divergence(hw(tp[2 * k : 2 * k + 2])) for k in (0, 1)])
        err = float(((new - u) ** 2).sum()) / (h * w)
        u[...] = new
        for k in (0, 1):
            grad = gradient(u[k])
            if aniso:
                grad = np.einsum("hwab,hwb->hwa", T, grad)
            pk = prox_huber_conjugate(hw(p[2 * k : 2 * k + 2]) + (tau / theta) * grad,
                                      tau / theta, huber, g)
            p[2 * k : 2 * k + 2] = np.moveaxis(pk, -1, 0)
            if aniso:
                tp[2 * k : 2 * k + 2] = np.moveaxis(np.einsum("hwab,hwb->hwa", T, pk), -1, 0)
        if err < tol * tol and it % 2 == 0:  # tested every second iteration, as the kernel
            break
    return it


def init_level_state(
    state: TVL1State, shape: tuple[int, int, int], g: np.ndarray,
    tensor: np.ndarray | None = None,
) -> None:
    """Set up the per-level state of the primal-dual iterations (first warp of a level).

    The TV dual variables are warm started from the coarser level (bilinear
    resampling, then projection onto the new ball of radius ``g``).

    Parameters
    ----------
    state : TVL1State
        The level's solver state; sets ``g``, ``tensor``, ``p``, ``tp`` and ``q``.
    shape : (H, W, C)
    g : ndarray, shape (H, W), float32
        Radius of the dual ball (edge weight).
    tensor : ndarray, shape (3, H, W), float32, optional
        ``T = D^{1/2}`` as (T11, T12, T22) for tensor-directed TV; ``None`` for
        isotropic TV.
    """
    h, w, nc = shape
    state.g = np.ascontiguousarray(g, dtype=np.float32)
    state.tensor = None if tensor is None else np.ascontiguousarray(tensor, dtype=np.float32)
    prev = state.previous
    if prev is not None and prev.p is not None:
        p = planar(resize_bilinear(np.moveaxis(prev.p, 0, -1), (h, w)))
        project_dual(p, state.g)
    else:
        p = np.zeros((4, h, w), np.float32)
    state.p = p
    if state.tensor is None:
        state.tp = p
    else:
        t11, t12, t22 = state.tensor
        tp = np.empty_like(p)
        for k in (0, 2):
            tp[k] = t11 * p[k] + t12 * p[k + 1]
            tp[k + 1] = t12 * p[k] + t22 * p[k + 1]
        state.tp = tp
    state.q = np.zeros((nc, h, w), np.float32)
    state.q_all = None


def planar(x: np.ndarray, copy: bool = False) -> np.ndarray:
    """``(H, W, K)`` -> C-contiguous planar ``(K, H, W)`` float32 (the kernels' layout).

    Without ``copy`` a view of ``x`` when ``x`` already is planar data; with it always a
    new array (for the solvers, which update their flow in place: the flow they start
    from may be such a view, e.g. the median filter's output).
    """
    x = np.moveaxis(x, -1, 0)
    if copy:
        return np.array(x, dtype=np.float32, order="C")
    return np.ascontiguousarray(x, dtype=np.float32)


def linearise_numpy(I0, I1w, I1w_dx, I1w_dy, inside, flow0):
    """Reference NumPy implementation of :func:`linearise`."""
    m = inside[..., None].astype(np.float32)
    ixh = I1w_dx * m
    iyh = I1w_dy * m
    ah = (I1w - I0 - ixh * flow0[..., :1] - iyh * flow0[..., 1:2]) * m
    return planar(ixh), planar(iyh), planar(ah)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _linearise_kernel(I0, I1w, I1w_dx, I1w_dy, inside, flow0, ix, iy, a):
    """One task per channel and row: the row views let the loop run without a
    per-pixel branch (the ``inside`` mask multiplies).  ``flow0`` is planar
    ``(2, H, W)``."""
    h, w, nc = I0.shape
    for task in nb.prange(nc * h):
        c = task // h
        i = task - c * h
        r0 = I0[i, :, c]
        r1 = I1w[i, :, c]
        rx = I1w_dx[i, :, c]
        ry = I1w_dy[i, :, c]
        ins = inside[i]
        u0 = flow0[0, i]
        v0 = flow0[1, i]
        ox = ix[c, i]
        oy = iy[c, i]
        oa = a[c, i]
        for j in range(w):
            m = F1 if ins[j] else F0
            gx = rx[j] * m
            gy = ry[j] * m
            ox[j] = gx
            oy[j] = gy
            oa[j] = (r1[j] - r0[j]) * m - gx * u0[j] - gy * v0[j]


def linearise(I0, I1w, I1w_dx, I1w_dy, inside, flow0):
    """The linearised colour constancy residual ``ρ_c(u) = a_c + ∇I1w_c · u`` of one warp.

    A Numba kernel; :func:`linearise_numpy` is its reference.

    Parameters
    ----------
    I0, I1w, I1w_dx, I1w_dy : ndarray, shape (H, W, C), float32
    inside : ndarray, shape (H, W), bool
        The data term is switched off (all of ``ix, iy, a`` zero) outside.
    flow0 : ndarray, shape (H, W, 2)
        Linearisation point.

    Returns
    -------
    ix, iy, a : ndarray, shape (C, H, W), float32, planar
        ``a = I1w - I0 - ∇I1w · flow0``.
    """
    h, w, nc = I0.shape
    ix = np.empty((nc, h, w), np.float32)
    iy = np.empty_like(ix)
    a = np.empty_like(ix)
    f32 = [np.asarray(x, dtype=np.float32) for x in (I0, I1w, I1w_dx, I1w_dy)]
    _linearise_kernel(f32[0], f32[1], f32[2], f32[3], np.asarray(inside, np.bool_),
                      planar(flow0), ix, iy, a)
    return ix, iy, a


def robust_data_term(params: TVL1Params) -> bool:
    """True if ``params`` asks for more than the plain colour term (γ > 0 or ζ > 0)."""
    return params.gradient_weight > 0 or params.data_normalisation > 0


def data_channels(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TVL1Params,
                  state: TVL1State):
    """All channels of the linearised data term of one warp, weights folded in.

    The colour channels of :func:`linearise`, then (γ > 0) two gradient-constancy
    channels per colour channel c::

        ρ_cx(u) = ∂_x J1w_c - ∂_x J0_c + ∇(∂_x J1w_c) · (u - u0)
        ρ_cy(u) = ∂_y J1w_c - ∂_y J0_c + ∇(∂_y J1w_c) · (u - u0)

    with ``J = G_σ * I`` (``σ = gradient_sigma · η^level``; the warped first
    derivatives are smoothed, and their derivatives, symmetrised, stand for the
    warped Hessian), scaled by ``γ/λ`` so that the prox with step ``λθ`` applies
    the weight γ.  ``∇J0`` is computed once per level and kept in ``state.grad0``.
    With ζ > 0 every channel is then divided by ``sqrt(|∇ρ|² + ζ²)``, ``∇ρ`` the
    unweighted gradient of its constraint (Zimmer et al. 2011).  With γ = ζ = 0 this
    is exactly :func:`linearise`.  Numba kernels; :func:`data_channels_numpy` is the
    reference.

    Parameters
    ----------
    I0, I1w, I1w_dx, I1w_dy, inside, flow0
        As in :func:`solve_warp`.
    params : TVL1Params
    state : LevelState
        The level state: reads ``level``, caches ``grad0``.

    Returns
    -------
    ix, iy, a : ndarray, shape (K, H, W), float32, planar
        ``K = C`` without the gradient term, else ``3 C`` (colour channels, then
        the x and then the y gradient channels), ``C + 2`` with ``gradient_grey``.
    """
    if not robust_data_term(params):
        return linearise(I0, I1w, I1w_dx, I1w_dy, inside, flow0)
    h, w, nc = I0.shape
    n_k = nc + 2 * gradient_channel_count(params, nc)
    ix = np.empty((n_k, h, w), np.float32)
    iy = np.empty_like(ix)
    a = np.empty_like(ix)
    f32 = [np.asarray(x, dtype=np.float32) for x in (I0, I1w, I1w_dx, I1w_dy)]
    inside = np.asarray(inside, np.bool_)
    fp = planar(flow0)  # free when the driver keeps its flows planar
    _linearise_kernel(f32[0], f32[1], f32[2], f32[3], inside, fp, ix[:nc], iy[:nc], a[:nc])
    w_grad = np.float32(params.gradient_weight / params.data_weight)
    if params.gradient_weight > 0:
        gdx, gdy, w_grad = _gradient_inputs(f32[2], f32[3], params)
        sigma, i0 = _reference_gradients(f32[0], params, state)
        j1 = _smoothed_stack(gdx, gdy, sigma)
        _gradient_channels_kernel(j1, i0, inside, fp, w_grad, nc, ix, iy, a)
    if params.data_normalisation > 0:
        scale = _normalisation(ix, iy, nc, w_grad, params.data_normalisation)
        ix *= scale
        iy *= scale
        a *= scale
    return ix, iy, a


def _normalisation(ix, iy, nc: int, w_grad, zeta: float) -> np.ndarray:
    """Factor ``1 / sqrt(|∇ρ|² + ζ²)`` of every channel of :func:`data_channels`, (K, H, W).

    ``|∇ρ|`` is that of the unweighted constraint: the channels from ``nc`` on (the
    gradient term) carry the weight ``w_grad``, undone first.
    """
    wts = np.ones((ix.shape[0], 1, 1), np.float32)
    wts[nc:] = w_grad
    zeta2 = np.float32(zeta) ** 2
    return np.float32(1) / np.sqrt((ix * ix + iy * iy) / (wts * wts) + zeta2)


def gradient_channel_count(params: TVL1Params, nc: int) -> int:
    """Colour channels the gradient term is built from: 0 (γ = 0), 1 (grey) or ``nc``."""
    if params.gradient_weight <= 0:
        return 0
    return 1 if params.gradient_grey else nc


def _gradient_inputs(dx, dy, params: TVL1Params):
    """``(∂x I, ∂y I, γ/λ)`` as the gradient term sees the ``(H, W, C)`` derivatives.

    With ``gradient_grey`` the channel means, and the weight times ``C``.
    """
    w_grad = np.float32(params.gradient_weight / params.data_weight)
    if not params.gradient_grey:
        return dx, dy, w_grad
    nc = dx.shape[2]
    grey = [np.ascontiguousarray(x.mean(axis=2, keepdims=True), np.float32) for x in (dx, dy)]
    return grey[0], grey[1], np.float32(w_grad * nc)


def _reference_gradients(I0, params: TVL1Params, state: TVL1State, engine: str = "numba"):
    """``(σ, J0)`` of the level: the smoothed first-frame derivatives, cached in ``state``.

    Built by the very operations that give the second frame's side in
    :func:`data_channels` (the driver's :func:`~varflow.ops.differences.derivative_planes`,
    the channel mean of :func:`_gradient_inputs`, then the Gaussian of σ on the
    derivatives), so that two identical frames give gradient residuals of exactly
    zero at zero flow.  With ``engine="numba"`` ``J0`` is planar ``(2G, H, W)``
    (``[∂x J0, ∂y J0]``, the layout of :func:`_gradient_channels_kernel`);
    ``engine="numpy"`` uses the NumPy references of those operations and gives the
    pair ``(∂x J0, ∂y J0)``, each ``(H, W, G)``.  Both cache under ``grad0``: a
    level state serves one engine.
    """
    sigma = params.gradient_sigma * params.scale_factor ** state.level
    if state.grad0 is None:
        nc = I0.shape[2]
        if engine == "numba":
            planes = derivative_planes(I0)
        else:
            planes = derivative_planes_numpy(I0)
        dx, dy, _ = _gradient_inputs(planes[..., nc:2 * nc], planes[..., 2 * nc:], params)
        if engine == "numba":
            state.grad0 = _smoothed_stack(dx, dy, sigma)
        else:
            g = dx.shape[2]
            j0 = smooth_image(np.concatenate([dx, dy], axis=2), sigma)
            state.grad0 = (np.ascontiguousarray(j0[..., :g]),
                              np.ascontiguousarray(j0[..., g:]))
    return sigma, state.grad0


def _smoothed_stack(dx, dy, sigma: float) -> np.ndarray:
    """``[G_σ * ∂x I, G_σ * ∂y I]`` as one planar ``(2G, H, W)`` stack (the layout of
    :func:`_gradient_channels_kernel`) from two ``(H, W, G)`` arrays or views; both
    frames' sides of the gradient term are built by it."""
    ng = dx.shape[2]
    out = np.empty((2 * ng,) + dx.shape[:2], np.float32)
    smooth_planes(dx, sigma, out=out[:ng])
    smooth_planes(dy, sigma, out=out[ng:])
    return out


@nb.njit(cache=True, fastmath=FASTMATH, inline="always")
def _gradient_pixel(ins, jx, jy, gx0, gy0, hxx, hxy1, hyx, hyy, u0, v0, wg):
    """The two gradient-constancy channels of one pixel: ``(ix, iy, a)`` of the x
    channel, then of the y channel (zero outside)."""
    m = wg if ins else F0
    hxy = np.float32(0.5) * (hxy1 + hyx)
    return (m * hxx, m * hxy, m * (jx - gx0 - hxx * u0 - hxy * v0),
            m * hxy, m * hyy, m * (jy - gy0 - hxy * u0 - hyy * v0))


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _gradient_channels_kernel(j1, i0, inside, flow0, wg, k0, ix, iy, a):
    """Gradient-constancy channels ``k0 .. k0 + 2G`` of :func:`data_channels` in one pass.

    ``j1`` (2G, H, W): the smoothed warped derivatives ``[∂x J1w, ∂y J1w]`` of the
    G channels the term is built from, planar; their 5-point derivatives give the
    (symmetrised) Hessian.  ``i0`` (2G, H, W): the same of the first frame;
    ``flow0`` (2, H, W).  The interior columns run on shifted row views (indexed
    by the loop variable only, so the loop vectorises); the two columns at each
    side use clamped indices.
    """
    g2, h, w = j1.shape
    ng = g2 // 2
    for task in nb.prange(ng * h):
        c = task // h
        i = task - c * h
        im2, im1, ip1, ip2 = stencil5_indices(i, h)
        xr = j1[c, i]
        yr = j1[ng + c, i]
        xm2, xm1, xp1, xp2 = j1[c, im2], j1[c, im1], j1[c, ip1], j1[c, ip2]
        ym2, ym1, yp1, yp2 = j1[ng + c, im2], j1[ng + c, im1], j1[ng + c, ip1], j1[ng + c, ip2]
        gx0 = i0[c, i]
        gy0 = i0[ng + c, i]
        ins = inside[i]
        u0 = flow0[0, i]
        v0 = flow0[1, i]
        kx = k0 + c
        ky = k0 + ng + c
        o1, o2, o3 = ix[kx, i], iy[kx, i], a[kx, i]
        o4, o5, o6 = ix[ky, i], iy[ky, i], a[ky, i]
        for j in list(range(min(2, w))) + list(range(max(w - 2, 2), w)):
            jm2, jm1, jp1, jp2 = stencil5_indices(j, w)
            r = _gradient_pixel(
                ins[j], xr[j], yr[j], gx0[j], gy0[j],
                stencil5(xr[jm2], xr[jm1], xr[jp1], xr[jp2]),
                stencil5(xm2[j], xm1[j], xp1[j], xp2[j]),
                stencil5(yr[jm2], yr[jm1], yr[jp1], yr[jp2]),
                stencil5(ym2[j], ym1[j], yp1[j], yp2[j]),
                u0[j], v0[j], wg)
            o1[j], o2[j], o3[j], o4[j], o5[j], o6[j] = r
        n = w - 4
        if n <= 0:
            continue
        # column j = jj + 2 of the interior
        xl2, xl1, xc, xr1, xr2 = xr[0:n], xr[1:n + 1], xr[2:n + 2], xr[3:n + 3], xr[4:n + 4]
        yl2, yl1, yc, yr1, yr2 = yr[0:n], yr[1:n + 1], yr[2:n + 2], yr[3:n + 3], yr[4:n + 4]
        xm2c, xm1c, xp1c, xp2c = xm2[2:n + 2], xm1[2:n + 2], xp1[2:n + 2], xp2[2:n + 2]
        ym2c, ym1c, yp1c, yp2c = ym2[2:n + 2], ym1[2:n + 2], yp1[2:n + 2], yp2[2:n + 2]
        gx0c, gy0c, insc = gx0[2:n + 2], gy0[2:n + 2], ins[2:n + 2]
        u0c, v0c = u0[2:n + 2], v0[2:n + 2]
        p1, p2, p3 = o1[2:n + 2], o2[2:n + 2], o3[2:n + 2]
        p4, p5, p6 = o4[2:n + 2], o5[2:n + 2], o6[2:n + 2]
        for jj in range(n):
            r = _gradient_pixel(
                insc[jj], xc[jj], yc[jj], gx0c[jj], gy0c[jj],
                stencil5(xl2[jj], xl1[jj], xr1[jj], xr2[jj]),
                stencil5(xm2c[jj], xm1c[jj], xp1c[jj], xp2c[jj]),
                stencil5(yl2[jj], yl1[jj], yr1[jj], yr2[jj]),
                stencil5(ym2c[jj], ym1c[jj], yp1c[jj], yp2c[jj]),
                u0c[jj], v0c[jj], wg)
            p1[jj], p2[jj], p3[jj], p4[jj], p5[jj], p6[jj] = r


def data_channels_numpy(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TVL1Params,
                        state: TVL1State):
    """Reference NumPy implementation of :func:`data_channels` (same arguments, same
    state cache, same outputs)."""
    ix, iy, a = linearise_numpy(I0, I1w, I1w_dx, I1w_dy, inside, flow0)
    if not robust_data_term(params):
        return ix, iy, a
    nc = I0.shape[2]
    w_grad = np.float32(params.gradient_weight / params.data_weight)
    if params.gradient_weight > 0:
        gdx, gdy, w_grad = _gradient_inputs(I1w_dx, I1w_dy, params)
        sigma, (i0x, i0y) = _reference_gradients(np.asarray(I0, np.float32), params, state,
                                                 engine="numpy")
        j1x = smooth_image(gdx, sigma)
        j1y = smooth_image(gdy, sigma)
        hxx, hxy = image_derivatives(j1x)
        hyx, hyy = image_derivatives(j1y)
        hxy = np.float32(0.5) * (hxy + hyx)
        gx, gy, ga = linearise_numpy(np.concatenate([i0x, i0y], 2), np.concatenate([j1x, j1y], 2),
                               np.concatenate([hxx, hxy], 2), np.concatenate([hxy, hyy], 2),
                               inside, flow0)
        ix = np.concatenate([ix, w_grad * gx])
        iy = np.concatenate([iy, w_grad * gy])
        a = np.concatenate([a, w_grad * ga])
    if params.data_normalisation > 0:
        scale = _normalisation(ix, iy, nc, w_grad, params.data_normalisation)
        ix, iy, a = ix * scale, iy * scale, a * scale
    return (np.ascontiguousarray(ix, np.float32), np.ascontiguousarray(iy, np.float32),
            np.ascontiguousarray(a, np.float32))


def kernel_tensor(state: TVL1State) -> tuple[np.ndarray, bool]:
    """``(tensor, aniso)`` arguments of the kernels from the level state.

    The kernels need an array even for isotropic TV: a (3, 1, 1) placeholder that
    they never read.
    """
    tens = state.tensor
    return (NO_TENSOR, False) if tens is None else (tens, True)


def data_duals(state: TVL1State, n_channels: int) -> np.ndarray:
    """The dual variables ``q`` of the data prox for ``n_channels`` channels of
    :func:`data_channels` (warm started across the warps of a level).

    ``state.q`` holds those of the colour channels; with extra channels (the
    gradient-constancy term) one array ``state.q_all`` holds every dual variable
    and ``state.q`` becomes a view of its first planes.
    """
    nc = state.q.shape[0]
    if n_channels == nc:
        return state.q
    q = state.q_all
    if q is None or q.shape[0] != n_channels:
        extra = np.zeros((n_channels - nc,) + state.q.shape[1:], np.float32)
        q = np.concatenate([state.q, extra])
        state.q_all = q
        state.q = q[:nc]
    return q


def run_warp(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TVL1Params, state: TVL1State,
             engine: str = "numba") -> np.ndarray:
    """Run the TV-L1 iterations of one warp on a level prepared by :func:`init_level_state`.

    Shared by every TV-L1 flavour (isotropic, edge-weighted, tensor-directed): they
    differ only in ``state.g`` and ``state.tensor``.  Arguments as in
    :func:`solve_warp`.
    """
    if engine not in ("numba", "numpy"):
        raise ValueError(f"engine: must be 'numba' or 'numpy', got {engine!r}")
    ix, iy, a = data_channels(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params, state)
    u = planar(flow0, copy=True)
    tens, aniso = kernel_tensor(state)
    q = data_duals(state, ix.shape[0])
    args = (
        ix, iy, a, state.g, tens, u, state.p, state.tp, q,
        np.float32(params.data_weight), np.float32(params.coupling), np.float32(params.tv_step),
        params.max_iterations, np.float32(params.tolerance), params.data_sweeps, aniso,
    )
    if engine == "numba":
        n = tvl1_iterations(*args, row_blocks(I0.shape[0]), np.float32(params.huber))
    else:
        n = tvl1_iterations_numpy(*args, None, params.huber)
    state.iterations += n
    return np.moveaxis(u, 0, -1)  # a view: the driver's median reads it planar, uncopied


def solve_warp(
    I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TVL1Params, state: LevelState,
    engine: str = "numba",
):
    """Single-level, single-warp TV-L1 solver (the method's plug-in to the driver).

    Parameters
    ----------
    I0, I1w, I1w_dx, I1w_dy : ndarray, shape (H, W, C), float32
        Reference frame, warped second frame and its warped derivatives.
    inside : ndarray, shape (H, W), bool
        Pixels whose warped position lies inside the second frame; the data term is
        switched off elsewhere.
    flow0 : ndarray, shape (H, W, 2), float32
        Linearisation point (and initial value).
    params : TVL1Params
    state : LevelState
        The driver's per-level state; the solver keeps its own (:class:`TVL1State`:
        dual variables ``p`` and ``q``, the edge weight ``g``) in ``state.data``.
    engine : {"numba", "numpy"}

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    st = level_state(state)
    if st.g is None:
        g = edge_weight(I0, params.edge_weight, params.edge_weight_min)
        init_level_state(st, I0.shape, g)
    return run_warp(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params, st, engine)


#: The driver may keep the flows planar (:func:`~varflow.twoframe.coarse_to_fine.run_levels`):
#: the solver's kernels take planar data.
solve_warp.planar_flow = True  # type: ignore[attr-defined]


def tvl1(frame0, frame1, params: TVL1Params | None = None, init_flow=None, callback=None,
         levels: int | None = None):
    """TV-L1 optical flow from ``frame0`` to ``frame1``.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float (see :mod:`varflow._validate`).  Colour images use
        the vector-valued data term (one L1 residual per channel).
    params : TVL1Params, optional
    init_flow : ndarray, shape (H, W, 2), optional
    callback : callable, optional
        ``callback(done, total)`` after every warp.
    levels : int, optional
        Run only the finest ``levels`` pyramid levels (to refine ``init_flow``).

    Returns
    -------
    ndarray, shape (H, W, 2), float32

    References
    ----------
    C. Zach, T. Pock, H. Bischof, "A duality based approach for realtime TV-L1
    optical flow", DAGM 2007.  A. Wedel et al., "An improved algorithm for TV-L1
    optical flow", 2009.  L. Rakêt et al., "TV-L1 optical flow for vector valued
    images", EMMCVPR 2011.  D. Sun, S. Roth, M. Black, "Secrets of optical flow
    estimation and their principles", CVPR 2010.
    """
    return coarse_to_fine(
        frame0, frame1, solve_warp, params or PRESETS["tvl1"], init_flow=init_flow,
        callback=callback, levels=levels,
    )


PlainTVL1Params = deprecated_preset("PlainTVL1Params", "plain")
TVL1FastParams = deprecated_preset("TVL1FastParams", "fast")
