"""The U-step of the multi-frame methods: one frame's primal-dual iterations.

With the coupling target of the other frames fixed, the energy of the trajectories
splits into one problem per frame: TV-L1's data term (relaxed or not), the
edge-weighted (Huber-)TV and the coupling — RLR's L1 link as two more linear-L1
"channels" of the data term (:func:`link_channels`), MFSF's quadratic pull.  It is
solved by Condat's primal-dual iteration (step 1 of :mod:`varflow.multiframe.rlr`):
:func:`ustep_iterations` (Numba, rows in parallel) and its NumPy reference
:func:`ustep_iterations_numpy`.  The point-wise prox is :mod:`varflow.ops.prox`'s, the
TV rows :mod:`varflow.ops.primal_dual`'s; the driver is
:mod:`varflow.multiframe.refine`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._jit import FASTMATH
from ..ops.differences import divergence, gradient
from ..ops.primal_dual import F0, F1, NO_TENSOR, dual_row, ordered_sum, primal_row
from ..ops.prox import (
    certify_prox_row,
    data_prox_row,
    project_l2_ball,
    prox_huber_conjugate,
    prox_linear_l1,
    prox_linear_l1_exact,
    shrink_towards,
    soft_threshold,
)

__all__ = ["link_channels", "set_link_targets", "ustep_iterations", "ustep_iterations_numpy"]


def link_channels(ix: np.ndarray, iy: np.ndarray, a: np.ndarray, lk: np.ndarray | None,
                  ratio: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Append the link terms ``(τ/λ_D) |u_k − l_k|`` as two extra data "channels".

    ``τ |u_k − l_k| = λ_D |r (u_k − l_k)|`` with ``r = τ / λ_D``: a linear-L1 term
    with gradient ``r e_k`` and constant ``−r l_k``, so the data prox of TV-L1
    treats it like a colour channel.

    Parameters
    ----------
    ix, iy, a : ndarray, shape (C, H, W)
        Linearised data terms of one frame.
    lk : ndarray, shape (2, H, W), or None
        The low-rank trajectories of this frame; None (or ``ratio == 0``) adds nothing.
    ratio : float or ndarray, shape (H, W)
        ``τ / λ_D`` (per pixel when an array, e.g. scaled by the edge weight).

    Returns
    -------
    ix, iy, a : ndarray, shape (C + 2, H, W) (or (C, H, W)), float32
    """
    if lk is None or (np.isscalar(ratio) and ratio == 0):
        return ix, iy, a
    c, h, w = a.shape
    r = np.asarray(ratio, np.float32)
    ixe = np.zeros((c + 2, h, w), np.float32)
    iye = np.zeros((c + 2, h, w), np.float32)
    ae = np.empty((c + 2, h, w), np.float32)
    ixe[:c], iye[:c], ae[:c] = ix, iy, a
    ixe[c] = r
    iye[c + 1] = r
    set_link_targets(ae, c, lk, r)
    return ixe, iye, ae


def set_link_targets(a: np.ndarray, n_data: int, lk: np.ndarray,
                     ratio: float | np.ndarray) -> None:
    """Point the link channels of :func:`link_channels` at new targets, in place.

    ``a[n_data:] = −(τ/λ_D) lk``; the gradients of the link channels do not change.
    """
    a[n_data:] = -np.asarray(ratio, np.float32) * lk


# ------------------------------------------------------------------------ U-step
@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _ustep_primal_row(ix, iy, a, q, u, p, ubar, m, beta, i, old, s, t, n_sweeps, exact, sc):
    """Primal step of row ``i``: ``ũ = prox_{sG}(u + s div p)``; ``ubar = 2ũ − u``.

    With ``beta > 0``, ``G`` has the extra term ``β/2 |u − m|²``, folded into the prox:
    ``prox_{sG}(z) = prox_{s' G_0}((z + sβ m) / (1 + sβ))`` with ``s' = s / (1 + sβ)``.
    """
    w = u.shape[2]
    o1 = old[0]
    o2 = old[1]
    for j in range(w):
        o1[j] = u[0, i, j]
        o2[j] = u[1, i, j]
    primal_row(u, p, i, 0, o1, s)  # u = old + s div p (reads p only)
    primal_row(u, p, i, 1, o2, s)
    d1 = u[0, i]
    d2 = u[1, i]
    if beta > F0:
        sb = s * beta
        c = F1 / (F1 + sb)
        m1 = m[0, i]
        m2 = m[1, i]
        for j in range(w):
            d1[j] = (d1[j] + sb * m1[j]) * c
            d2[j] = (d2[j] + sb * m2[j]) * c
        t = t * c
    b1 = ubar[0, i]
    b2 = ubar[1, i]
    if exact:  # keep the prox argument z in ubar's row until the end
        for j in range(w):
            b1[j] = d1[j]
            b2[j] = d2[j]
    data_prox_row(ix, iy, a, q, i, d1, d2, t, n_sweeps)
    if exact:  # certify the active set the dual descent found (see prox_certified)
        certify_prox_row(ix, iy, a, q, i, b1, b2, d1, d2, t, sc)
    return _extrapolate_row(u, ubar, i, o1, o2)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _extrapolate_row(u, ubar, i, o1, o2):
    """``ubar = 2u − old`` on row ``i``; returns the squared change of the row."""
    d1 = u[0, i]
    d2 = u[1, i]
    b1 = ubar[0, i]
    b2 = ubar[1, i]
    err = F0
    for j in range(u.shape[2]):
        e1 = d1[j] - o1[j]
        e2 = d2[j] - o2[j]
        err += e1 * e1 + e2 * e2
        b1[j] = d1[j] + e1
        b2[j] = d2[j] + e2
    return err


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _relaxed_primal_row(ix, iy, a, q, u, p, v, m, beta, i, old, s, lam, theta, n_data,
                        n_sweeps, exact, sc, ubar):
    """Primal step of row ``i`` of the relaxed U-step (``theta`` = θ > 0).

    The energy is ``TV(u) + |u − v|²/(2θ) + λ D(v) + link(u) [+ β/2 |u − m|²]``, TV-L1's
    relaxation of the data term ``D`` (Zach et al.) with the link kept exact on
    ``u``.  First ``v = prox_{λθ D}(u)`` (the data channels ``< n_data`` only), then
    ``u = prox_{s G}(u + s div p)`` with ``G = |u − v|²/(2θ) + link [+ β/2 |u − m|²]``:
    the quadratics combine into one centre ``c`` with weight ``W = 1/s + 1/θ + β``, and
    each link channel ``λ r_k |u_k − l_k|`` moves ``c_k`` towards ``l_k`` by at most
    ``λ r_k / W``.  ``v``: (2, W) scratch for the row of ``v``.
    """
    w = u.shape[2]
    o1 = old[0]
    o2 = old[1]
    v1 = v[0]
    v2 = v[1]
    for j in range(w):
        o1[j] = u[0, i, j]
        o2[j] = u[1, i, j]
        v1[j] = o1[j]
        v2[j] = o2[j]
    dx = ix[:n_data]
    dy = iy[:n_data]
    da = a[:n_data]
    dq = q[:n_data]
    lt = lam * theta
    data_prox_row(dx, dy, da, dq, i, v1, v2, lt, n_sweeps)
    if exact:
        certify_prox_row(dx, dy, da, dq, i, o1, o2, v1, v2, lt, sc[:, :n_data])
    primal_row(u, p, i, 0, o1, s)  # u = old + s div p (reads p only)
    primal_row(u, p, i, 1, o2, s)
    d1 = u[0, i]
    d2 = u[1, i]
    inv_s = F1 / s
    inv_th = F1 / theta
    wq = inv_s + inv_th + beta
    inv_w = F1 / wq
    link = a.shape[0] > n_data
    for j in range(w):
        c1 = inv_s * d1[j] + inv_th * v1[j]
        c2 = inv_s * d2[j] + inv_th * v2[j]
        if beta > F0:
            c1 += beta * m[0, i, j]
            c2 += beta * m[1, i, j]
        c1 *= inv_w
        c2 *= inv_w
        if link:
            r1 = ix[n_data, i, j]
            r2 = iy[n_data + 1, i, j]
            if r1 > F0:
                c1 = shrink_towards(c1, -a[n_data, i, j] / r1, lam * r1 * inv_w)
            if r2 > F0:
                c2 = shrink_towards(c2, -a[n_data + 1, i, j] / r2, lam * r2 * inv_w)
        d1[j] = c1
        d2[j] = c2
    return _extrapolate_row(u, ubar, i, o1, o2)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def ustep_iterations(ix, iy, a, g, u, p, q, ubar, m, beta, lam, s, max_iter, tol, n_sweeps,
                     exact, blocks, huber=F0, theta=F0, n_data=-1):
    """Numba primal-dual (Condat / Chambolle-Pock) iterations of one frame's U-step.

    Minimises ``λ Σ_k |a_k + (ix_k, iy_k)·u| + Σ_x g (|∇u_1| + |∇u_2|)`` (the data and
    link terms of :func:`link_channels`, the TV weight folded into ``g``; with
    ``theta`` > 0 the data terms relaxed), with
    Huber-TV ``g h_ε(|∇u_k|)`` when ``huber`` = ε_H > 0; updates ``u``, ``p``, ``q``
    and the scratch ``ubar`` in place.

    Parameters
    ----------
    ix, iy, a : (K, H, W) float32
        Linear-L1 terms (zero where a data term is off).
    g : (H, W) float32
        Radius of the dual ball, ``λ_TV g(x)``.
    u : (2, H, W) float32
        Displacement of this frame, planar.
    p : (4, H, W) float32
        Dual TV variables (p1x, p1y, p2x, p2y).
    q : (K, H, W) float32
        Dual variables of the point-wise prox (warm start, updated).
    ubar : (2, H, W) float32
        Scratch for the extrapolated primal ``2ũ − u``.
    m : (2, H, W) float32
        Target of the quadratic coupling ``β/2 |u − m|²`` (MFSF's subspace
        projection); read only if ``beta > 0``.
    beta : float
        β ≥ 0; 0 switches the quadratic coupling off.
    lam, s : float
        λ_D and the primal step s; the dual step is ``1 / (8 s)``.
    max_iter : int
    tol : float
        Stop when the RMS change of ``u`` is below ``tol`` pixels.
    n_sweeps : int
        Coordinate-descent sweeps per iteration.
    exact : bool
        Certify every pixel's prox (see :func:`prox_certified`) instead of keeping
        the coordinate-descent point.
    blocks : (n+1,) int64
        Row-block bounds.
    huber : float
        ε_H of Huber-TV (the dual step becomes the prox of its conjugate, as in
        TV-L1's :func:`~varflow.twoframe.tvl1.tvl1_iterations`); 0 gives TV.
    theta : float
        θ > 0 relaxes the data term as TV-L1 does (Zach et al. 2007): the U-step
        minimises ``min_v |u − v|²/(2θ) + λ Σ_k |ρ_k(v)|`` (the Moreau envelope of the
        data term, quadratic for small residuals) plus TV and the link, which stays
        an L1 term on ``u`` (see :func:`_relaxed_primal_row`); 0 gives the data term
        itself.
    n_data : int
        The channels of ``a`` that are data terms; the rest (two) are the link's
        (:func:`link_channels`).  Read only with ``theta`` > 0; −1: all channels.

    Returns
    -------
    int
        Iterations performed.
    """
    nk, h, w = a.shape
    t = lam * s
    nd = nk if n_data < 0 else n_data
    relaxed = theta > F0
    sigma = F1 / (np.float32(8.0) * s)
    tol2 = tol * tol
    n_blk = blocks.shape[0] - 1
    errs = np.zeros(h, np.float64)  # per row: the stopping test does not depend on blocks
    old = np.empty((n_blk, 2, w), np.float32)
    vrow = np.empty((n_blk, 2, w), np.float32)  # v of the relaxed data term, one row
    sc = np.empty((n_blk, 4, nk), np.float64)
    it = 0
    while it < max_iter:
        it += 1
        for b in nb.prange(n_blk):
            for i in range(blocks[b], blocks[b + 1]):
                if relaxed:
                    errs[i] = _relaxed_primal_row(ix, iy, a, q, u, p, vrow[b], m, beta, i,
                                                  old[b], s, lam, theta, nd, n_sweeps, exact,
                                                  sc[b], ubar)
                else:
                    errs[i] = _ustep_primal_row(ix, iy, a, q, u, p, ubar, m, beta, i, old[b],
                                                s, t, n_sweeps, exact, sc[b])
        for b in nb.prange(n_blk):
            for i in range(blocks[b], blocks[b + 1]):
                dual_row(ubar, p, p, g, NO_TENSOR, i, sigma, False, huber)
        if ordered_sum(errs) / (h * w) < tol2:
            break
    return it


def _relaxed_prox_numpy(ix, iy, a, q, old, z, m, beta, lam, s, theta, n_data, n_sweeps,
                        exact):
    """The relaxed primal step of :func:`ustep_iterations_numpy` (see
    :func:`_relaxed_primal_row`); returns ``u`` channels last and updates ``q``."""
    nd = a.shape[0] if n_data < 0 else n_data
    hw = lambda x: np.moveaxis(x, 0, -1)  # noqa: E731
    lt = lam * theta
    if exact:
        v = prox_linear_l1_exact(hw(old), hw(a[:nd]), hw(ix[:nd]), hw(iy[:nd]), lt)
    else:
        v, qn = prox_linear_l1(hw(old), hw(a[:nd]), hw(ix[:nd]), hw(iy[:nd]), lt,
                               n_sweeps=n_sweeps, q0=hw(q[:nd]))
        q[:nd] = np.moveaxis(qn, -1, 0)
    wq = 1.0 / s + 1.0 / theta + beta
    c = (hw(z) / s + v / theta + (beta * hw(m) if beta > 0 else 0.0)) / wq
    for k in range(a.shape[0] - nd):  # the link channels: λ r_k |u_k − l_k|
        r = (ix if k == 0 else iy)[nd + k]
        lk = np.where(r > 0, -a[nd + k] / np.where(r > 0, r, 1), 0)
        thr = lam * r / wq
        c[..., k] = np.where(r > 0, lk + soft_threshold(c[..., k] - lk, thr), c[..., k])
    return c


def ustep_iterations_numpy(ix, iy, a, g, u, p, q, ubar, m, beta, lam, s, max_iter, tol,
                           n_sweeps, exact, blocks=None, huber=0.0, theta=0.0, n_data=-1):
    """NumPy reference of :func:`ustep_iterations` (same arguments, in-place updates)."""
    _, h, w = a.shape
    t = float(lam) * float(s)
    sigma = 1.0 / (8.0 * float(s))
    hw = lambda x: np.moveaxis(x, 0, -1)  # noqa: E731 - planar -> channels last view
    it = 0
    while it < max_iter:
        it += 1
        old = u.copy()
        z = np.stack([u[k] + s * divergence(hw(p[2 * k: 2 * k + 2])) for k in (0, 1)])
        if beta > 0 and theta <= 0:
            z = (z + s * beta * m) / (1 + s * beta)
            t = float(lam) * float(s) / (1 + float(s) * float(beta))
        if theta > 0:
            d = _relaxed_prox_numpy(ix, iy, a, q, old, z, m, float(beta), float(lam),
                                    float(s), float(theta), n_data, n_sweeps, exact)
        elif exact:
            d = prox_linear_l1_exact(hw(z), hw(a), hw(ix), hw(iy), t)
        else:
            d, qn = prox_linear_l1(hw(z), hw(a), hw(ix), hw(iy), t, n_sweeps=n_sweeps,
                                   q0=hw(q))
            q[...] = np.moveaxis(qn, -1, 0)
        u[...] = np.moveaxis(d, -1, 0)
        ubar[...] = 2 * u - old
        for k in (0, 1):
            pk = hw(p[2 * k: 2 * k + 2]) + sigma * gradient(ubar[k])
            if huber > 0:  # the prox of the conjugate of g h_ε: shrink, then project
                pk = prox_huber_conjugate(pk, sigma, float(huber), g)
            else:
                pk = project_l2_ball(pk, g)
            p[2 * k: 2 * k + 2] = np.moveaxis(pk, -1, 0)
        if float(((u - old) ** 2).sum()) / (h * w) < tol * tol:
            break
    return it
