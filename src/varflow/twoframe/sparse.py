"""Sparse-regularised TV-L1: flow patches coded over an overcomplete dictionary.

Energy (Jia, Wang & Tang, "Optical flow estimation using learned sparse model",
ICCV 2011; Gibson & Marques 2016, ch. 3), at one pyramid level::

    E(u, α) = λ Σ_c |ρ_c(u)| + λ_TV Σ_k R(u_k) + λ_SP Σ_p ||R_p u − D α_p||²,
    α_p sparse,

with ``R`` the (edge-weighted) isotropic TV ``g |∇u_k|`` or the tensor-directed TV
``|D_x ∇u_k|`` (:mod:`varflow.twoframe.tensor`), ``R_p`` the extraction of the
``m × n`` flow patch ``p`` on a grid with offset ``k`` (:class:`varflow.sparse.PatchGrid`)
and ``D`` an overcomplete dictionary (fixed 2-D DCT, or learned by MOD in the "1D",
"2x1D" or "2D" layout, :mod:`varflow.sparse.dictionaries`).

Because ``Σ_p ||R_p u − D α_p||² = Σ_x c(x) |u(x) − ū(x)|² + const`` with ``c(x)`` the
number of patches covering ``x`` and ``ū`` the average of the overlapping patch
approximations, the sparse term is a weighted quadratic pull towards the sparse
approximation ``ū``.  The weight is normalised by the mean coverage ``m n / k²`` so
that λ_SP means the same for every patch size and offset.

Bootstrap, at each pyramid level whose smaller side is at least ``sparse_min_size``
(the driver's warps ``0 … n_warps-1`` are the TV-only stage, the next
``sparse_warps`` the sparse stage):

1. the TV-only (or tensor) TV-L1 flow of the level, as in :mod:`varflow.twoframe.tvl1`;
2. the dictionary is refreshed from that flow by MOD (``mod_iterations`` passes,
   tolerance ``mod_tolerance``), starting from the coarser level's dictionary
   (the overcomplete DCT at the first level), or kept fixed for ``dictionary="dct"``;
3. at every sparse warp the current flow is coded by batch OMP (error threshold
   μ = ``omp_tolerance``) to give ``ū``, and the combined energy, linearised at the
   warp and smoothed (Huber with μ_data, μ_TV), is minimised by Nesterov's
   accelerated gradient method with NESTA's continuation on the smoothing
   (Becker, Bobin & Candès 2011) and a diagonal (Gershgorin) preconditioner
   (``combined_solver="nesterov"``), or, unsmoothed, by the TV-L1 primal-dual
   scheme whose point-wise data step absorbs the quadratic pull towards ``ū``
   (``combined_solver="primal-dual"``, :func:`sparse_pd_iterations`).

The 5×5 median filter of the driver follows every warp, as in the book.

The energy's data term and TV are those of the parameter class: the book's plain
energy (:class:`SparseParams`, the ``sparse-*`` methods) or ``tvl1``'s
(:class:`TVL1SparseParams`, ``tvl1-sparse-*``: the "more sophisticated variational
approach" the book says the sparse term could be added to).  The sparse warps use
every channel of :func:`~varflow.twoframe.tvl1.data_channels` (the gradient-constancy
channels too) and the Huber-TV of ε_H = ``huber``: exactly in the primal-dual step; in
Nesterov's method, Huber-TV smoothed with μ_TV is the Huber function of ε_H + μ_TV.
The driver applies the noise rule, the sharpness match, the grey channel and the
weighted median (after the last, sparse, warp of a level) for both.

Symbol map: λ = ``data_weight``, λ_TV = ``sparse_tv_weight``, λ_SP =
``sparse_weight`` (times ``sparse_weight_decay`` per coarser level), μ =
``omp_tolerance``, μ_TV = ``smoothing_tv``, μ_data = ``smoothing_data``, k =
``patch_offset``, m = n = ``patch_size``.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from functools import lru_cache

import numba as nb
import numpy as np

from .._jit import FASTMATH
from ..ops.differences import divergence, gradient
from ..ops.primal_dual import dual_row, ordered_sum, primal_row, row_blocks
from ..ops.prox import (
    data_prox_row_pixel_step,
    prox_huber_conjugate,
    prox_linear_l1_pixel_step,
)
from ..sparse import (
    PatchGrid,
    layout_dct,
    learn_mod,
    merge_problems,
    omp,
    reconstruct,
    split_problems,
)
from .coarse_to_fine import LevelState
from .params import SparseTerm, TVL1Params, deprecated_preset
from .tensor import init_tensor_level
from .tvl1 import (
    TVL1State,
    data_channels,
    data_duals,
    edge_weight,
    init_level_state,
    kernel_tensor,
    level_state,
    planar,
    run_warp,
)

__all__ = [
    "SparseTerm",
    "SparseState",
    "SparseFields",
    "SparseParams",
    "SparseDCTParams",
    "Sparse1DParams",
    "Sparse2x1DParams",
    "Sparse2DParams",
    "TVL1SparseParams",
    "TVL1SparseDCTParams",
    "TVL1Sparse1DParams",
    "TVL1Sparse2x1DParams",
    "TVL1Sparse2DParams",
    "solve_warp",
    "sparse_approximation",
    "learn_dictionaries",
    "nesterov_iterations",
    "nesterov_iterations_numpy",
    "sparse_pd_iterations",
    "sparse_pd_iterations_numpy",
    "smoothed_energy",
]

log = logging.getLogger(__name__)

_F0 = np.float32(0.0)
_F1 = np.float32(1.0)


SparseFields = SparseTerm  # the former mixin's name
SparseParams = deprecated_preset("SparseParams", "sparse-1d")
SparseDCTParams = deprecated_preset("SparseDCTParams", "sparse-dct")
Sparse1DParams = deprecated_preset("Sparse1DParams", "sparse-1d")
Sparse2x1DParams = deprecated_preset("Sparse2x1DParams", "sparse-2x1d")
Sparse2DParams = deprecated_preset("Sparse2DParams", "sparse-2d")
TVL1SparseParams = deprecated_preset("TVL1SparseParams", "tvl1-sparse-1d")
TVL1SparseDCTParams = deprecated_preset("TVL1SparseDCTParams", "tvl1-sparse-dct")
TVL1Sparse1DParams = deprecated_preset("TVL1Sparse1DParams", "tvl1-sparse-1d")
TVL1Sparse2x1DParams = deprecated_preset("TVL1Sparse2x1DParams", "tvl1-sparse-2x1d")
TVL1Sparse2DParams = deprecated_preset("TVL1Sparse2DParams", "tvl1-sparse-2d")


@dataclass
class SparseState(TVL1State):
    """TV-L1's per-level state and the sparse term's.

    Attributes
    ----------
    dictionaries : list of ndarray or None
        The level's dictionaries (learned on its first sparse warp).
    coverage : ndarray, shape (h, w), float32, or None
        The sparse term's per-pixel weight (:func:`coverage_weight`).
    """

    dictionaries: list | None = None
    coverage: np.ndarray | None = None


def _term(params: SparseTerm | TVL1Params) -> SparseTerm:
    """The sparse term of ``params`` (an energy with one, or the term itself)."""
    return params.sparse if isinstance(params, TVL1Params) else params


# --------------------------------------------------------------------- dictionaries


@lru_cache(maxsize=16)
def _dct(layout: str, patch_size: int, n_atoms: int) -> tuple[np.ndarray, ...]:
    dicts = layout_dct(layout, (patch_size, patch_size), n_atoms)
    for d in dicts:
        d.setflags(write=False)
    return tuple(dicts)


def _grid(shape: tuple[int, int], params: SparseTerm) -> PatchGrid:
    return PatchGrid(shape[0], shape[1], (params.patch_size, params.patch_size),
                     params.patch_offset)


def _problems(flow: np.ndarray, grid: PatchGrid, layout: str):
    y = grid.extract(flow)
    mask = grid.patch_mask(2) if grid.has_apron else None
    return split_problems(layout, y, mask)


def learn_dictionaries(
    flow: np.ndarray, params: SparseTerm | TVL1Params, init: list[np.ndarray] | None = None
) -> list[np.ndarray]:
    """Learn (or refresh) the dictionaries of ``params.layout`` from a flow by MOD.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2), float32
    params : SparseTerm or TVL1Params
        The sparse term (or an energy that has one).
    init : list of ndarray, optional
        Starting dictionaries (the coarser level's); the overcomplete DCT if absent.

    Returns
    -------
    list of ndarray
        One ``(dim, n_atoms)`` float32 dictionary per problem of the layout (1 for
        "1D" and "2D", 2 for "2x1D").
    """
    params = _term(params)
    start = list(init) if init is not None else list(_dct(params.layout, params.patch_size,
                                                          params.n_atoms))
    grid = _grid(flow.shape[:2], params)
    out = []
    for (y, m), d0 in zip(_problems(flow, grid, params.layout), start, strict=True):
        res = learn_mod(
            y, d0, m,
            tol=params.omp_tolerance,
            max_atoms=params.omp_max_atoms or None,
            n_iterations=params.mod_iterations,
            rel_tol=params.mod_tolerance,
            max_signals=params.mod_max_signals or None,
            seed=params.seed,
        )
        out.append(res.dictionary)
    return out


def sparse_approximation(
    flow: np.ndarray, dictionaries: list[np.ndarray], params: SparseTerm | TVL1Params
) -> np.ndarray:
    """``ū``: the average of the overlapping OMP approximations of the flow's patches.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2), float32
    dictionaries : list of ndarray
        As returned by :func:`learn_dictionaries` (or the DCT of the layout).
    params : SparseTerm or TVL1Params
        The sparse term (or an energy that has one).

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    params = _term(params)
    grid = _grid(flow.shape[:2], params)
    parts = []
    for (y, m), d in zip(_problems(flow, grid, params.layout), dictionaries, strict=True):
        codes = omp(d, y, tol=params.omp_tolerance, max_atoms=params.omp_max_atoms or None,
                    mask=m)
        parts.append(reconstruct(d, codes))
    approx = grid.average(merge_problems(params.layout, parts))
    return np.ascontiguousarray(approx, dtype=np.float32)


def coverage_weight(shape: tuple[int, int], params: SparseTerm | TVL1Params) -> np.ndarray:
    """Patch coverage ``c(x)`` normalised by its mean ``m n / k²``, shape (H, W)."""
    params = _term(params)
    grid = _grid(shape, params)
    density = params.patch_size**2 / params.patch_offset**2
    return (grid.count / np.float32(density)).astype(np.float32)


# --------------------------------------------------------------------- Nesterov


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _huber_dual_row(y, s, g, tens, i, mu, aniso):
    """``s_k = D (g D∇y_k / max(μ, |D∇y_k|))`` for row ``i`` (both components)."""
    h = y.shape[1]
    w = y.shape[2]
    cy = _F1 if i < h - 1 else _F0
    ip = min(i + 1, h - 1)
    gr = g[i]
    for k in range(2):
        yc = y[k, i]
        yn = y[k, ip]
        sx = s[2 * k, i]
        sy = s[2 * k + 1, i]
        if not aniso:
            for j in range(w):
                gx = yc[min(j + 1, w - 1)] - yc[j]
                gy = cy * (yn[j] - yc[j])
                sc = gr[j] / max(mu, math.sqrt(gx * gx + gy * gy))
                sx[j] = gx * sc
                sy[j] = gy * sc
        else:
            t11r = tens[0, i]
            t12r = tens[1, i]
            t22r = tens[2, i]
            for j in range(w):
                dx = yc[min(j + 1, w - 1)] - yc[j]
                dy = cy * (yn[j] - yc[j])
                t11 = t11r[j]
                t12 = t12r[j]
                t22 = t22r[j]
                gx = t11 * dx + t12 * dy
                gy = t12 * dx + t22 * dy
                sc = gr[j] / max(mu, math.sqrt(gx * gx + gy * gy))
                gx *= sc
                gy *= sc
                sx[j] = t11 * gx + t12 * gy
                sy[j] = t12 * gx + t22 * gy


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _nesterov_row(ix, iy, a, y, s, ubar, wsp, pinv, u, i, lam, lam_tv, mu_d, g1, g2):
    """Gradient step ``u = y − P⁻¹ ∇E(y)`` for row ``i`` (g1, g2: row work buffers).

    Row views indexed by loop variables only, so that the loops vectorise (see
    :mod:`varflow.twoframe.tvl1`).
    """
    nc = a.shape[0]
    h = y.shape[1]
    w = y.shape[2]
    cm = lam_tv if i > 0 else _F0
    im = max(i - 1, 0)
    cy = lam_tv if i < h - 1 else _F0
    inv_mu = _F1 / mu_d
    y1 = y[0, i]
    y2 = y[1, i]
    wr = wsp[i]
    b1 = ubar[0, i]
    b2 = ubar[1, i]
    for j in range(w):
        ws = 2 * wr[j]
        g1[j] = ws * (y1[j] - b1[j])
        g2[j] = ws * (y2[j] - b2[j])
    for c in range(nc):
        ixr = ix[c, i]
        iyr = iy[c, i]
        ar = a[c, i]
        for j in range(w):
            gx = ixr[j]
            gy = iyr[j]
            r = (ar[j] + gx * y1[j] + gy * y2[j]) * inv_mu
            r = lam * min(max(r, -_F1), _F1)
            g1[j] += gx * r
            g2[j] += gy * r
    for k in range(2):
        gk = g1 if k == 0 else g2
        sx = s[2 * k, i]
        sy = s[2 * k + 1, i]
        sym = s[2 * k + 1, im]
        # -λ_TV div: backward differences, the last column / row x / y parts ignored
        gk[0] -= lam_tv * sx[0]
        gk[w - 1] += lam_tv * sx[w - 2]
        sxc = sx[1 : w - 1]
        sxl = sx[: w - 2]
        gkc = gk[1 : w - 1]
        for jj in range(w - 2):
            gkc[jj] -= lam_tv * (sxc[jj] - sxl[jj])
        for j in range(w):
            gk[j] -= cy * sy[j] - cm * sym[j]
    pr = pinv[i]
    u1 = u[0, i]
    u2 = u[1, i]
    for j in range(w):
        u1[j] = y1[j] - pr[j] * g1[j]
        u2[j] = y2[j] - pr[j] * g2[j]


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def nesterov_iterations(ix, iy, a, g, tens, aniso, ubar, wsp, u, lam, lam_tv, mu_t_seq,
                        mu_d_seq, n_iter, blocks):
    """Preconditioned Nesterov iterations on the smoothed combined energy (in place on u).

    Minimises :func:`smoothed_energy` with continuation: ``mu_t_seq`` and
    ``mu_d_seq`` hold the smoothing of each stage (the last is the target); each
    stage runs ``n_iter`` iterations from the previous stage's result with the
    momentum restarted.  The step is the diagonal majorant
    ``P = λ Σ_c |∇I_c|²/μ_d + 8 λ_TV/μ_TV + 2 w_SP`` (Gershgorin bound of the
    Hessian), so the method is Nesterov's for a 1-smooth function in the P-norm.

    Parameters
    ----------
    ix, iy, a : (C, H, W) float32
        Linearised data term ``ρ_c(u) = a_c + ix_c u_1 + iy_c u_2`` (planar).
    g : (H, W) float32
        TV edge weight.
    tens : (3, H, W) float32
        Tensor (D11, D12, D22) if ``aniso``, else any (3, 1, 1) array.
    aniso : bool
    ubar : (2, H, W) float32
        Sparse approximation ``ū``.
    wsp : (H, W) float32
        Sparse weight λ_SP·c(x) (normalised coverage).
    u : (2, H, W) float32
        Initial flow, overwritten with the result.
    lam, lam_tv : float
        λ and λ_TV.
    mu_t_seq, mu_d_seq : (S,) float32
        Smoothing per continuation stage.
    n_iter : int
        Iterations per stage.
    blocks : (n+1,) int64
        Row blocks for the parallel loops.
    """
    nc, h, w = a.shape
    n_blk = blocks.shape[0] - 1
    y = np.empty_like(u)
    up = np.empty_like(u)
    s = np.empty((4, h, w), np.float32)
    pinv = np.empty((h, w), np.float32)
    buf = np.empty((n_blk, 2, w), np.float32)
    for st in range(mu_t_seq.shape[0]):
        mu_t = mu_t_seq[st]
        mu_d = mu_d_seq[st]
        for b in nb.prange(n_blk):
            for i in range(blocks[b], blocks[b + 1]):
                for j in range(w):
                    nn = _F0
                    for c in range(nc):
                        nn += ix[c, i, j] * ix[c, i, j] + iy[c, i, j] * iy[c, i, j]
                    pinv[i, j] = _F1 / (lam * nn / mu_d + 8 * lam_tv / mu_t + 2 * wsp[i, j])
                    up[0, i, j] = u[0, i, j]
                    up[1, i, j] = u[1, i, j]
        for it in range(n_iter):
            beta = np.float32(it / (it + 3.0))
            for b in nb.prange(n_blk):
                for i in range(blocks[b], blocks[b + 1]):
                    for k in range(2):
                        ur = u[k, i]
                        upr = up[k, i]
                        yr = y[k, i]
                        for j in range(w):
                            un = ur[j]
                            yr[j] = un + beta * (un - upr[j])
                            upr[j] = un
            for b in nb.prange(n_blk):
                for i in range(blocks[b], blocks[b + 1]):
                    _huber_dual_row(y, s, g, tens, i, mu_t, aniso)
            for b in nb.prange(n_blk):
                for i in range(blocks[b], blocks[b + 1]):
                    _nesterov_row(ix, iy, a, y, s, ubar, wsp, pinv, u, i, lam, lam_tv, mu_d,
                                  buf[b, 0], buf[b, 1])


def _tensor_matrices(tens):
    return np.stack([np.stack([tens[0], tens[1]], -1), np.stack([tens[1], tens[2]], -1)], -2)


def smoothed_energy(u, ix, iy, a, g, tens, aniso, ubar, wsp, lam, lam_tv, mu_t, mu_d) -> float:
    """The smoothed combined energy that :func:`nesterov_iterations` minimises.

    ``E = λ Σ_c h_μd(ρ_c(u)) + λ_TV Σ_k Σ_x g h_μt(|D ∇u_k|) + Σ_x w_SP |u − ū|²`` with
    the Huber function ``h_μ(r) = r²/(2μ)`` for ``|r| ≤ μ``, ``|r| − μ/2`` otherwise.
    Arguments are planar as in :func:`nesterov_iterations`.
    """

    def huber(r, mu):
        r = np.abs(r)
        return np.where(r <= mu, r * r / (2 * mu), r - mu / 2)

    u = np.asarray(u, np.float64)
    rho = a + ix * u[0] + iy * u[1]
    e = lam * huber(rho, mu_d).sum()
    for k in range(2):
        q = gradient(u[k])
        if aniso:
            q = np.einsum("hwab,hwb->hwa", _tensor_matrices(tens), q)
        e += lam_tv * (g * huber(np.sqrt((q * q).sum(-1)), mu_t)).sum()
    e += (wsp * ((u - ubar) ** 2).sum(0)).sum()
    return float(e)


def nesterov_iterations_numpy(ix, iy, a, g, tens, aniso, ubar, wsp, u, lam, lam_tv, mu_t_seq,
                              mu_d_seq, n_iter, blocks=None):
    """NumPy reference of :func:`nesterov_iterations` (same arguments, in place on u)."""
    T = _tensor_matrices(tens) if aniso else None
    for mu_t, mu_d in zip(mu_t_seq, mu_d_seq, strict=True):
        pinv = 1.0 / (lam * (ix * ix + iy * iy).sum(0) / mu_d + 8 * lam_tv / mu_t + 2 * wsp)
        up = u.copy()
        for it in range(n_iter):
            beta = np.float32(it / (it + 3.0))
            y = u + beta * (u - up)
            up = u.copy()
            r = np.clip((a + ix * y[0] + iy * y[1]) / mu_d, -1.0, 1.0)
            grad = lam * np.stack([(ix * r).sum(0), (iy * r).sum(0)])
            grad += 2 * wsp * (y - ubar)
            for k in range(2):
                q = gradient(y[k])
                if aniso:
                    q = np.einsum("hwab,hwb->hwa", T, q)
                sk = g[..., None] * q / np.maximum(mu_t, np.sqrt((q * q).sum(-1)))[..., None]
                if aniso:
                    sk = np.einsum("hwab,hwb->hwa", T, sk)
                grad[k] -= lam_tv * divergence(sk)
            u[...] = (y - pinv * grad).astype(np.float32)


def _continuation(mu: float, stages: int) -> np.ndarray:
    return np.array([mu * 4.0 ** (stages - 1 - s) for s in range(stages)], np.float32)


# --------------------------------------------------------------------- primal-dual


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def sparse_pd_iterations(ix, iy, a, g, tens, u, p, tp, q, ubar, wsp, lam, lam_tv, theta, tau,
                         max_iter, tol, n_sweeps, aniso, blocks, huber=0.0):
    """Exact TV-L1 primal-dual iterations on the combined energy (in place on u, p, tp, q).

    The scheme of :func:`varflow.twoframe.tvl1.tvl1_iterations` (one iteration
    per pass, the stopping test after every iteration) with the sparse quadratic
    folded into the point-wise step::

        v = argmin_v |v − u|²/(2θ) + w |v − ū|² + λ Σ_c |ρ_c(v)|
          = prox_{t' Σ|ρ_c|}(z),  z = (u + 2θw ū)/(1 + 2θw),  t' = λθ/(1 + 2θw),

    and the TV weighted by λ_TV (the dual ball radius ``λ_TV g``; with ε_H > 0 the
    Huber-TV step of :func:`~varflow.twoframe.tvl1.tvl1_iterations`).  With
    ``w ≡ 0`` and ``λ_TV = 1`` it is :func:`~varflow.twoframe.tvl1.tvl1_iterations`.

    Parameters
    ----------
    ix, iy, a, g, tens, u, p, tp, q
        As in :func:`~varflow.twoframe.tvl1.tvl1_iterations`.
    ubar : (2, H, W) float32
        Sparse approximation ``ū``.
    wsp : (H, W) float32
        Sparse weight w = λ_SP·c(x).
    lam, lam_tv, theta, tau, tol : float
        λ, λ_TV, θ, τ, ε.
    max_iter, n_sweeps : int
    aniso : bool
    blocks : (n+1,) int64
        Row-block bounds from :func:`~varflow.ops.primal_dual.row_blocks`.
    huber : float
        ε_H of Huber-TV (0: TV).

    Returns
    -------
    int
        Iterations performed.
    """
    nc, h, w = a.shape
    step = tau / theta
    tol2 = tol * tol
    n_blk = blocks.shape[0] - 1
    gs = g * lam_tv
    # s = 1/(1 + 2θw): centre weight of u and step factor; z = s u + (1 - s) ū
    sw = np.empty((h, w), np.float32)
    for b in nb.prange(n_blk):
        for i in range(blocks[b], blocks[b + 1]):
            for j in range(w):
                sw[i, j] = _F1 / (_F1 + 2 * theta * wsp[i, j])
    errs = np.zeros(h, np.float64)  # per row: the stopping test does not depend on blocks
    buf = np.empty((n_blk, 3, w), np.float32)
    it = 0
    while it < max_iter:
        it += 1
        for b in nb.prange(n_blk):
            r0 = blocks[b]
            r1 = blocks[b + 1]
            d1 = buf[b, 0]
            d2 = buf[b, 1]
            tr = buf[b, 2]
            for i in range(r0, r1):
                sr = sw[i]
                u1 = u[0, i]
                u2 = u[1, i]
                b1 = ubar[0, i]
                b2 = ubar[1, i]
                for j in range(w):
                    s = sr[j]
                    d1[j] = s * u1[j] + (_F1 - s) * b1[j]
                    d2[j] = s * u2[j] + (_F1 - s) * b2[j]
                    tr[j] = lam * theta * s
                data_prox_row_pixel_step(ix, iy, a, q, i, d1, d2, tr, n_sweeps)
                err = primal_row(u, tp, i, 0, d1, theta)
                errs[i] = err + primal_row(u, tp, i, 1, d2, theta)
                if i > r0:
                    dual_row(u, p, tp, gs, tens, i - 1, step, aniso, huber)
        for b in nb.prange(n_blk):
            dual_row(u, p, tp, gs, tens, blocks[b + 1] - 1, step, aniso, huber)
        if ordered_sum(errs) / (h * w) < tol2:
            break
    return it


def sparse_pd_iterations_numpy(ix, iy, a, g, tens, u, p, tp, q, ubar, wsp, lam, lam_tv, theta,
                               tau, max_iter, tol, n_sweeps, aniso, blocks=None, huber=0.0):
    """NumPy reference of :func:`sparse_pd_iterations` (same arguments, in place)."""
    _, h, w = a.shape
    s = (1.0 / (1.0 + 2 * theta * wsp)).astype(np.float32)
    t = (lam * theta * s).astype(np.float32)
    gs = (g * lam_tv).astype(np.float32)
    T = _tensor_matrices(tens) if aniso else None
    it = 0
    while it < max_iter:
        it += 1
        # point-wise step: prox of t Σ_c |ρ_c| at z, dual coordinate descent (warm q)
        d0, d1 = prox_linear_l1_pixel_step((s * u[0] + (1 - s) * ubar[0],
                                            s * u[1] + (1 - s) * ubar[1]), a, ix, iy, t, q,
                                           n_sweeps)
        new = np.stack([dk + theta * divergence(np.moveaxis(tp[2 * k : 2 * k + 2], 0, -1))
                        for k, dk in enumerate((d0, d1))])
        err = float(((new - u) ** 2).sum()) / (h * w)
        u[...] = new
        for k in (0, 1):
            grad = gradient(u[k])
            if aniso:
                grad = np.einsum("hwab,hwb->hwa", T, grad)
            pk = prox_huber_conjugate(
                np.moveaxis(p[2 * k : 2 * k + 2], 0, -1) + (tau / theta) * grad, tau / theta,
                huber, gs)
            p[2 * k : 2 * k + 2] = np.moveaxis(pk, -1, 0)
            if aniso:
                tp[2 * k : 2 * k + 2] = np.moveaxis(np.einsum("hwab,hwb->hwa", T, pk), -1, 0)
        if err < tol * tol:
            break
    return it


# --------------------------------------------------------------------- the solver


def _init_level(I0, params: TVL1Params, state: TVL1State) -> None:
    if params.sparse.regulariser == "tensor":
        init_tensor_level(I0, params, state)
    else:
        init_level_state(state, I0.shape, edge_weight(I0, params.edge_weight,
                                                      params.edge_weight_min))


def solve_warp(
    I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TVL1Params, state: LevelState,
    engine: str = "numba",
):
    """Single-level, single-warp solver of sparse-regularised TV-L1 (driver plug-in).

    Warps ``0 … n_warps-1`` of a level run TV-L1 (isotropic or tensor); on levels
    where :meth:`~varflow.twoframe.params.TVL1Params.sparse_active` holds, the
    following ``sparse_warps`` learn the dictionaries (first sparse warp), code the
    current flow and minimise the combined energy with Nesterov's method or the
    primal-dual scheme (``combined_solver``).  ``params.sparse`` is the
    :class:`~varflow.twoframe.params.SparseTerm`; the solver keeps a
    :class:`SparseState` in ``state.data``.  Arguments as in
    :func:`varflow.twoframe.tvl1.solve_warp`.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    st = level_state(state, SparseState)
    sp = params.sparse
    if st.g is None:
        _init_level(I0, params, st)
    if state.warp < params.n_warps or not params.sparse_active(I0.shape[:2]):
        return run_warp(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params, st, engine)

    stats = state.stats
    t0 = time.perf_counter()
    if st.dictionaries is None:
        prev = None if st.previous is None else st.previous.dictionaries
        if sp.dictionary == "dct":
            st.dictionaries = list(_dct(sp.layout, sp.patch_size, sp.n_atoms))
        else:
            st.dictionaries = learn_dictionaries(flow0, sp, prev)
        st.coverage = coverage_weight(I0.shape[:2], sp)
    ubar = sparse_approximation(flow0, st.dictionaries, sp)
    t1 = time.perf_counter()

    lam_sp = sp.sparse_weight * sp.sparse_weight_decay ** st.level
    if engine not in ("numba", "numpy"):
        raise ValueError(f"engine: must be 'numba' or 'numpy', got {engine!r}")
    # every channel of the energy's data term (the gradient constancy too), weights folded in
    ix, iy, a = data_channels(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params, st)
    u = planar(flow0, copy=True)
    tens, aniso = kernel_tensor(st)
    wsp = (np.float32(lam_sp) * st.coverage).astype(np.float32)
    if sp.combined_solver == "primal-dual":
        args = (
            ix, iy, a, st.g, tens, u, st.p, st.tp,
            data_duals(st, ix.shape[0]), planar(ubar),
            wsp, np.float32(params.data_weight), np.float32(sp.sparse_tv_weight),
            np.float32(sp.combined_coupling), np.float32(params.tv_step),
            sp.combined_iterations, np.float32(sp.combined_tolerance),
            params.data_sweeps, aniso,
        )
        if engine == "numba":
            n = sparse_pd_iterations(*args, row_blocks(I0.shape[0]), np.float32(params.huber))
        else:
            n = sparse_pd_iterations_numpy(*args, None, params.huber)
        st.iterations += n
    else:
        stages = sp.nesterov_stages
        # Huber-TV (ε_H) smoothed with μ_TV is the Huber function of ε_H + μ_TV
        # (Moreau envelopes add their parameters)
        args = (
            ix, iy, a, st.g, tens, aniso, planar(ubar), wsp, u,
            np.float32(params.data_weight), np.float32(sp.sparse_tv_weight),
            _continuation(sp.smoothing_tv + params.huber, stages),
            _continuation(sp.smoothing_data, stages),
            max(1, sp.nesterov_iterations // stages),
        )
        if engine == "numba":
            nesterov_iterations(*args, row_blocks(I0.shape[0]))
        else:
            nesterov_iterations_numpy(*args)
    t2 = time.perf_counter()
    stats["sparse_seconds"] = stats.get("sparse_seconds", 0.0) + (t1 - t0)
    stats["nesterov_seconds"] = stats.get("nesterov_seconds", 0.0) + (t2 - t1)
    stats["sparse_warps"] = stats.get("sparse_warps", 0) + 1
    return np.ascontiguousarray(np.moveaxis(u, 0, -1))
