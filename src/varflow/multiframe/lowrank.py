"""The low-rank step (L-step) of Robust Low-Rank trajectories (Gibson & Marques 2016, ch. 4).

With the trajectories fixed, the RLR energy reduces to::

    min_L  α ||L||_* + τ ||U − L||_1                                        (1)

over the trajectory matrix ``U`` of shape ``(2F, N)``.  Writing ``S = U − L`` and
dividing by α this is exactly principal component pursuit (PCP, robust PCA;
Candès, Li, Ma & Wright 2011)::

    min_{L, S}  ||L||_* + λ ||S||_1   subject to   U = L + S,   λ = τ / α     (2)

because the equality constraint only names the residual: every feasible pair has
``S = U − L``, and the objective of (2) is (1) divided by α.  :func:`lowrank_step`
does this mapping; the solvers take λ (``lam``).

Matrix view of trajectories
---------------------------
Trajectories are stored as ``(F, H, W, 2)`` arrays (displacements relative to the
reference frame, ``[..., 0] = u``, ``[..., 1] = v``).  The matrix view used here is
``U`` of shape ``(2F, N)`` with ``N = H * W``::

    U[2 n,     y * W + x] = traj[n, y, x, 0]   # u of frame n
    U[2 n + 1, y * W + x] = traj[n, y, x, 1]   # v of frame n

i.e. rows interleave ``u_0, v_0, u_1, v_1, ...`` and the columns are the pixels in
raster (C) order; one column is the whole trajectory of one pixel.  See
:func:`trajectories_to_matrix` and :func:`matrix_to_trajectories`.

Solvers
-------
* :func:`rpca_exact` — PCP by the inexact augmented Lagrange multiplier method
  (Lin, Chen & Ma 2010) with a full SVD per iteration.  Cost ``O((2F)² N)`` per
  iteration; the reference.
* :func:`rpca_linear` — PCP in linear time by l1 filtering (Liu, Lin, Yan, Sun, Yuan
  & Ma 2016): exact PCP on a random sub-set of columns gives a basis of the
  column space; every column of ``U`` is then fitted to that basis by robust L1
  regression (independent tiny problems, Numba-parallel).  Cost ``O(2F r N)``.
* :func:`l1_regression` / :func:`l1_regression_numpy` — the l1-filtering kernel
  (Numba and NumPy reference with the same signature and algorithm).

References
----------
E. J. Candès, X. Li, Y. Ma, J. Wright, "Robust principal component analysis?",
J. ACM 58(3), 2011.

Z. Lin, M. Chen, Y. Ma, "The augmented Lagrange multiplier method for exact
recovery of corrupted low-rank matrices", UIUC Tech. Rep. UILU-ENG-09-2215, 2010
(arXiv:1009.5055).

R. Liu, Z. Lin, S. Yan, J. Sun, X. Yuan, Y. Ma (arXiv 2011: "Solving principal
component pursuit in linear time via l1 filtering"), Neurocomputing 2016.

J. Gibson, O. Marques, "Optical Flow and Trajectory Estimation Methods",
SpringerBriefs in Computer Science, Springer 2016, ch. 4.
"""

from __future__ import annotations

import logging
import math
from typing import Any, Literal

import numba as nb
import numpy as np

from .._jit import FASTMATH

__all__ = [
    "trajectories_to_matrix",
    "matrix_to_trajectories",
    "rpca_exact",
    "rpca_linear",
    "l1_regression",
    "l1_regression_numpy",
    "estimate_basis",
    "sample_columns",
    "noise_rank",
    "lowrank_step",
    "DEFAULT_SAMPLES_PER_ROW",
    "DEFAULT_MIN_SAMPLES",
    "DEFAULT_RANK_TOL",
]

logger = logging.getLogger(__name__)

#: Default column sample of :func:`rpca_linear`:
#: ``min(N, max(DEFAULT_SAMPLES_PER_ROW * 2F, DEFAULT_MIN_SAMPLES))``.
DEFAULT_SAMPLES_PER_ROW = 20
#: The smallest default column sample.  The basis of the seed PCP is a random
#: variable of the sample; with 20 · 2F columns alone a short clip (2F = 10: 200
#: columns, ~25 per motion stratum) gets a basis that differs from one sample to the
#: next by enough to move a small fast object's trajectories by pixels, and a
#: last-bit difference of the kernels changes the sample (through the k-means of
#: the strata).  4000 columns make the basis, and a small fast object's far-frame
#: error, far steadier across seeds and builds (see benchmarks/HISTORY.md).  The seed
#: PCP costs ``O(m² s)`` per iteration, small beside the l1 filtering of all columns.
DEFAULT_MIN_SAMPLES = 4000
#: Default relative threshold of the rank estimate: keep ``σ_i > DEFAULT_RANK_TOL · σ_1``.
#: The seed PCP returns an exactly low-rank L (singular value thresholding), whose
#: spurious singular values sit at the 1e-8..1e-7 level of the solver tolerance and of
#: float32 data; 1e-4 is far above that and far below motion components of interest.
DEFAULT_RANK_TOL = 1e-4

_MU_RANGE = 1e7  # μ_max / μ_0 of both ALM schemes (Lin, Chen & Ma 2010)
_BLOCK = 64  # columns per Numba work item (scratch buffers are allocated once per block)


# --------------------------------------------------------------------------- helpers
def trajectories_to_matrix(traj: np.ndarray) -> np.ndarray:
    """Matrix view ``U`` of shape ``(2F, H*W)`` of trajectories ``(F, H, W, 2)``.

    ``U[2n + k, y*W + x] = traj[n, y, x, k]`` (k = 0: u, k = 1: v).

    Parameters
    ----------
    traj : ndarray, shape (F, H, W, 2)

    Returns
    -------
    ndarray, shape (2F, H*W), same dtype as ``traj``, C-contiguous
    """
    arr = np.asarray(traj)
    if arr.ndim != 4 or arr.shape[3] != 2:
        raise ValueError(f"traj: expected shape (F, H, W, 2), got {arr.shape}")
    f, h, w, _ = arr.shape
    return np.ascontiguousarray(arr.transpose(0, 3, 1, 2).reshape(2 * f, h * w))


def matrix_to_trajectories(U: np.ndarray, height: int, width: int) -> np.ndarray:
    """Inverse of :func:`trajectories_to_matrix`.

    Parameters
    ----------
    U : ndarray, shape (2F, height*width)
    height, width : int

    Returns
    -------
    ndarray, shape (F, height, width, 2), same dtype as ``U``, C-contiguous
    """
    arr = np.asarray(U)
    if arr.ndim != 2 or arr.shape[0] % 2 or arr.shape[1] != height * width:
        raise ValueError(
            f"U: expected shape (2F, {height * width}) with an even row count, got {arr.shape}"
        )
    f = arr.shape[0] // 2
    return np.ascontiguousarray(arr.reshape(f, 2, height, width).transpose(0, 2, 3, 1))


def _check_matrix(U: np.ndarray, name: str = "U") -> np.ndarray:
    """Validate a real, finite, non-empty 2-D matrix; returns it as an ndarray (no copy)."""
    arr = np.asarray(U)
    if arr.ndim != 2:
        raise ValueError(f"{name}: expected a 2-D matrix (2F, N), got ndim={arr.ndim}")
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name}: empty matrix of shape {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name}: expected a real numeric dtype, got {arr.dtype}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr


def _out_dtype(arr: np.ndarray) -> type:
    """float64 for float64 input, float32 otherwise (the library's data type)."""
    return np.float64 if arr.dtype == np.float64 else np.float32


def _check_positive(value: float, name: str) -> float:
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name}: must be a positive finite number, got {value!r}")
    return v


def _check_rho(rho: float, name: str = "rho") -> float:
    r = float(rho)
    if not math.isfinite(r) or r <= 1.0:
        raise ValueError(f"{name}: must be a finite number > 1, got {rho!r}")
    return r


def _check_int(value: int, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or int(value) != value or int(value) < minimum:
        raise ValueError(f"{name}: must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _default_lam(shape: tuple[int, int]) -> float:
    """The standard PCP weight ``λ = 1 / sqrt(max(m, n))`` (Candès et al. 2011)."""
    return 1.0 / math.sqrt(max(shape))


# ------------------------------------------------------------------ exact (reference)
def rpca_exact(
    U: np.ndarray,
    lam: float | None = None,
    *,
    tol: float = 1e-7,
    max_iter: int = 500,
    rho: float = 1.2,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Principal component pursuit by the inexact ALM method with a full SVD.

    Solves ``min ||L||_* + λ ||S||_1  s.t.  U = L + S`` by the inexact ALM scheme of
    Lin, Chen & Ma (2010) in the update order of their reference code: with
    ``Y_0 = U / max(||U||_2, ||U||_∞ / λ)``, ``μ_0 = 1.25 / ||U||_2``,
    ``μ_max = 10⁷ μ_0`` and ``μ_{k+1} = min(ρ μ_k, μ_max)``, alternate

    * ``S ← shrink(U − L + Y/μ, λ/μ)`` (element-wise soft threshold),
    * ``L ← SVT(U − S + Y/μ, 1/μ)`` (singular value thresholding, full thin SVD of the
      wide ``(2F, N)`` matrix by :func:`numpy.linalg.svd`),
    * ``Y ← Y + μ (U − L − S)``,

    until ``||U − L − S||_F / ||U||_F < tol``.  Computed in float64.

    Parameters
    ----------
    U : ndarray, shape (m, n)
        Data matrix (for trajectories ``m = 2F`` rows, ``n = N`` pixels).  Finite.
    lam : float, optional
        λ > 0, the weight of ``||S||_1``.  Default ``1 / sqrt(max(m, n))``.
    tol : float
        Stopping threshold on the relative constraint residual.
    max_iter : int
        Iteration cap (a warning is logged when it is reached).
    rho : float
        Growth factor of the penalty μ (> 1).  Lin et al. use 1.5; on the wide
        ``(2F, N)`` matrices of this module 1.5 often meets ``tol`` at a point that
        is not the PCP minimiser (planted low-rank + 5 % outliers, 60 x 4096: recovery
        error ~2e-3 with ρ = 1.5 against ~2e-8 with ρ = 1.2, at ~1.8x the
        iterations), hence the default 1.2.

    Returns
    -------
    L : ndarray, shape (m, n)
        Low-rank part; float64 if ``U`` is float64, else float32.
    S : ndarray, shape (m, n)
        Sparse part, same dtype.
    info : dict
        ``iterations``, ``relative_residual`` (``||U − L − S||_F / ||U||_F`` in float64
        before the cast), ``converged``, ``rank`` (singular values kept by the last
        SVT), ``objective`` (``||L||_* + λ ||S||_1`` of the returned float64 pair),
        ``lam``.

    Raises
    ------
    ValueError
        If ``U`` is not a finite 2-D matrix or a parameter is out of range (the
        message names the argument).
    """
    arr = _check_matrix(U)
    lam = _default_lam(arr.shape) if lam is None else _check_positive(lam, "lam")
    tol = _check_positive(tol, "tol")
    max_iter = _check_int(max_iter, "max_iter")
    rho = _check_rho(rho)
    out_dtype = _out_dtype(arr)

    D = np.array(arr, dtype=np.float64)
    d_norm = float(np.linalg.norm(D))
    info: dict[str, Any] = {"lam": lam, "iterations": 0, "relative_residual": 0.0,
                            "converged": True, "rank": 0, "objective": 0.0}
    if d_norm == 0.0:
        z = np.zeros(arr.shape, out_dtype)
        return z, z.copy(), info

    norm_two = float(np.linalg.svd(D, compute_uv=False)[0])
    norm_inf = float(np.abs(D).max()) / lam
    Y = D / max(norm_two, norm_inf)
    mu = 1.25 / norm_two
    mu_bar = mu * _MU_RANGE
    L = np.zeros_like(D)
    S = np.zeros_like(D)
    T = np.empty_like(D)
    rank = 0
    nuclear = 0.0
    res = 1.0
    it = 0
    while it < max_iter:
        it += 1
        inv_mu = 1.0 / mu
        # S-step: soft threshold of U - L + Y/mu by lam/mu
        np.subtract(D, L, out=T)
        T += inv_mu * Y
        thr = lam * inv_mu
        np.copyto(S, np.sign(T) * np.maximum(np.abs(T) - thr, 0.0))
        # L-step: singular value thresholding of U - S + Y/mu by 1/mu
        np.subtract(D, S, out=T)
        T += inv_mu * Y
        uu, sv, vt = np.linalg.svd(T, full_matrices=False)
        rank = int(np.count_nonzero(sv > inv_mu))
        nuclear = float((sv[:rank] - inv_mu).sum())
        if rank:
            np.matmul(uu[:, :rank] * (sv[:rank] - inv_mu), vt[:rank], out=L)
        else:
            L.fill(0.0)
        # dual ascent on the constraint
        np.subtract(D, L, out=T)
        T -= S
        res = float(np.linalg.norm(T)) / d_norm
        T *= mu
        Y += T
        mu = min(mu * rho, mu_bar)
        if res < tol:
            break
    converged = res < tol
    if not converged:
        logger.warning("rpca_exact: no convergence after %d iterations (residual %.3g)",
                       it, res)
    logger.debug("rpca_exact: %d iterations, residual %.3g, rank %d", it, res, rank)
    objective = nuclear + lam * float(np.abs(S).sum())
    info.update(iterations=it, relative_residual=res, converged=converged, rank=rank,
                objective=objective)
    return L.astype(out_dtype), S.astype(out_dtype), info


# ------------------------------------------------------------- l1 filtering kernels
def _prepare_basis(basis: np.ndarray, m: int) -> np.ndarray:
    """Validate a ``(m, r)`` basis and return an orthonormal basis of its span (float64)."""
    b = np.asarray(basis)
    if b.ndim != 2 or b.shape[0] != m or not 1 <= b.shape[1] <= m:
        raise ValueError(f"basis: expected shape ({m}, r) with 1 <= r <= {m}, got {b.shape}")
    if not (np.issubdtype(b.dtype, np.floating) or np.issubdtype(b.dtype, np.integer)):
        raise ValueError(f"basis: expected a real numeric dtype, got {b.dtype}")
    b = b.astype(np.float64)
    if not np.all(np.isfinite(b)):
        raise ValueError("basis: contains NaN or infinite values")
    q, r = np.linalg.qr(b)
    d = np.abs(np.diag(r))
    if d.min() <= 1e-10 * max(d.max(), 1e-300):
        raise ValueError("basis: columns are (numerically) linearly dependent")
    return np.ascontiguousarray(q)


def _l1_checks(U, basis, tol, rho, max_iter):
    arr = _check_matrix(U)
    q = _prepare_basis(basis, arr.shape[0])
    return (arr, q, _check_positive(tol, "tol"), _check_rho(rho),
            _check_int(max_iter, "max_iter"))


def _check_weights(weights: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray | None:
    """Validate entry weights: ``None`` or a finite, non-negative ``shape`` array (float32)."""
    if weights is None:
        return None
    w = np.asarray(weights)
    if w.shape != shape:
        raise ValueError(f"weights: expected shape {shape}, got {w.shape}")
    w = np.ascontiguousarray(w, dtype=np.float32)
    if not np.all(np.isfinite(w)) or (w < 0).any():
        raise ValueError("weights: must be finite and non-negative")
    return w


def _l1_info(iters: np.ndarray, max_iter: int, unconverged: int) -> dict[str, Any]:
    if unconverged:
        logger.warning("l1_regression: %d columns did not converge in %d iterations",
                       unconverged, max_iter)
    return {
        "iterations": iters,
        "iterations_mean": float(iters.mean()) if iters.size else 0.0,
        "iterations_max": int(iters.max()) if iters.size else 0,
        "unconverged": int(unconverged),
    }


def l1_regression_numpy(
    U: np.ndarray,
    basis: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    tol: float = 1e-7,
    rho: float = 1.5,
    max_iter: int = 200,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Robust L1 fit of every column to a basis (NumPy reference, vectorised).

    Same algorithm, parameters and results as :func:`l1_regression` (the Numba
    kernel); see there.  Columns are processed together; a column stops updating
    when its own stopping rule holds (it is then removed from the active set).
    """
    arr, q, tol, rho, max_iter = _l1_checks(U, basis, tol, rho, max_iter)
    wts = _check_weights(weights, arr.shape)
    m, n = arr.shape
    qt = np.ascontiguousarray(q.T)
    out = np.zeros((m, n), _out_dtype(arr))
    iters = np.zeros(n, np.int64)
    u_all = arr.astype(np.float64)
    nrm = np.sqrt((u_all * u_all).sum(0))
    idx = np.flatnonzero(nrm > 0.0)
    ua = u_all[:, idx]
    wa = np.ones_like(ua) if wts is None else wts[:, idx].astype(np.float64)
    tol2 = (tol * nrm[idx]) ** 2
    mu = 1.25 / nrm[idx]
    mu_max = mu * _MU_RANGE
    e = np.zeros_like(ua)
    y = np.zeros_like(ua)
    unconverged = 0
    for k in range(max_iter):
        if idx.size == 0:
            break
        inv = 1.0 / mu
        c = qt @ (ua - e + y * inv)
        bc = q @ c
        d = ua - bc
        t = d + y * inv
        e = np.sign(t) * np.maximum(np.abs(t) - inv * wa, 0.0)
        z = d - e
        y += mu * z
        res = (z * z).sum(0)
        mu = np.minimum(mu * rho, mu_max)
        done = res <= tol2
        if k == max_iter - 1:
            unconverged = int(np.count_nonzero(~done))
            done[:] = True
        if done.any():
            out[:, idx[done]] = bc[:, done]
            iters[idx[done]] = k + 1
            keep = ~done
            idx, ua, e, y, wa = idx[keep], ua[:, keep], e[:, keep], y[:, keep], wa[:, keep]
            tol2, mu, mu_max = tol2[keep], mu[keep], mu_max[keep]
    return out, _l1_info(iters, max_iter, unconverged)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _l1_kernel(U, qt, wts, tol, rho, max_iter, out, iters):
    m, n = U.shape
    weighted = wts.shape[0] == m
    r = qt.shape[0]
    n_blocks = (n + _BLOCK - 1) // _BLOCK
    unconverged = np.zeros(n_blocks, np.int64)
    for blk in nb.prange(n_blocks):
        u = np.empty(m)
        e = np.empty(m)
        y = np.empty(m)
        w = np.empty(m)
        bc = np.empty(m)
        c = np.empty(r)
        for j in range(blk * _BLOCK, min(n, (blk + 1) * _BLOCK)):
            nrm2 = 0.0
            for i in range(m):
                u[i] = U[i, j]
                nrm2 += u[i] * u[i]
            if nrm2 == 0.0:
                for i in range(m):
                    out[i, j] = 0.0
                iters[j] = 0
                continue
            nrm = math.sqrt(nrm2)
            tol2 = (tol * nrm) ** 2
            mu = 1.25 / nrm
            mu_max = mu * _MU_RANGE
            for i in range(m):
                e[i] = 0.0
                y[i] = 0.0
            k = 0
            done = False
            while k < max_iter and not done:
                inv = 1.0 / mu
                for i in range(m):
                    w[i] = u[i] - e[i] + y[i] * inv
                for p in range(r):
                    s = 0.0
                    for i in range(m):
                        s += qt[p, i] * w[i]
                    c[p] = s
                for i in range(m):
                    bc[i] = 0.0
                for p in range(r):
                    cp = c[p]
                    for i in range(m):
                        bc[i] += qt[p, i] * cp
                res = 0.0
                for i in range(m):
                    d = u[i] - bc[i]
                    t = d + y[i] * inv
                    th = inv * wts[i, j] if weighted else inv
                    if t > th:
                        ei = t - th
                    elif t < -th:
                        ei = t + th
                    else:
                        ei = 0.0
                    z = d - ei
                    y[i] += mu * z
                    e[i] = ei
                    res += z * z
                mu = min(mu * rho, mu_max)
                k += 1
                done = res <= tol2
            if not done:
                unconverged[blk] += 1
            iters[j] = k
            for i in range(m):
                out[i, j] = bc[i]
    return unconverged.sum()


def l1_regression(
    U: np.ndarray,
    basis: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    tol: float = 1e-7,
    rho: float = 1.5,
    max_iter: int = 200,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Robust L1 fit of every column of ``U`` to the span of ``basis`` (l1 filtering).

    For each column ``u_j`` solves ``min_c Σ_i w_ij |u_ij − (B c)_i|`` (``w = 1``
    without ``weights``) and returns ``l_j = B c``.  A zero weight leaves the entry
    out of the fit (e.g. a point hidden in that frame); the soft threshold of the
    ``e``-step below becomes ``w_ij / μ`` (free entries carry no residual, so a
    column with many of them converges more slowly and stops a little short:
    max error ~1e-3 of the values with 60 % free).  ``basis`` is first replaced by an
    orthonormal basis ``Q`` of its span (thin QR), which leaves the fitted columns
    unchanged.  Each column is the
    L1 problem ``min ||e||_1  s.t.  u = Q c + e``, solved by the inexact augmented
    Lagrangian method (the scheme of Lin et al. 2010 applied to one column; the
    c-step is exact because ``QᵀQ = I``)::

        c ← Qᵀ (u − e + y/μ)
        e ← shrink(u − Q c + y/μ, 1/μ)
        y ← y + μ (u − Q c − e),      μ ← min(ρ μ, 10⁷ μ_0),   μ_0 = 1.25 / ||u||_2

    with ``e = y = 0`` initially.  Stopping rule, per column: the constraint
    residual ``||u − Q c − e||_2 <= tol · ||u||_2``, or ``max_iter`` iterations.
    Zero columns give zero.  With ρ = 1.5 a column takes up to about 40 iterations
    for ``tol = 1e-7`` (one or two if it lies in the span); a column with at most a
    few gross outliers on top of an element of the span is recovered to ~tol.  On
    data that is not exactly low rank plus sparse the geometric μ schedule stops
    slightly short of the L1 optimum (relative objective gap up to ~5e-4, median
    ~3e-5, measured against an LP solver for ρ = 1.5; smaller ρ closes it at the
    price of more iterations).

    Columns are independent; this Numba kernel runs them in parallel, in blocks of
    64 columns, in float64.  Cost ``O(m r)`` per column and iteration, i.e. linear
    in ``n``.  :func:`l1_regression_numpy` is the vectorised NumPy reference.

    Parameters
    ----------
    U : ndarray, shape (m, n)
        Columns to fit; finite.
    basis : ndarray, shape (m, r)
        Basis of the subspace, ``1 <= r <= m``, full column rank.
    weights : ndarray, shape (m, n), optional
        Non-negative entry weights ``w``.
    tol : float
        Relative residual of the per-column stopping rule.
    rho : float
        Growth factor of μ (> 1).
    max_iter : int
        Per-column iteration cap.

    Returns
    -------
    L : ndarray, shape (m, n)
        The fitted columns ``Q c_j``; float64 if ``U`` is float64, else float32.
    info : dict
        ``iterations`` (ndarray (n,), per column), ``iterations_mean``,
        ``iterations_max``, ``unconverged`` (columns that hit ``max_iter``).
    """
    arr, q, tol, rho, max_iter = _l1_checks(U, basis, tol, rho, max_iter)
    wts = _check_weights(weights, arr.shape)
    # one compiled specialisation per dtype: C-contiguous float32 or float64
    arr = np.ascontiguousarray(arr, dtype=_out_dtype(arr))
    m, n = arr.shape
    out = np.empty((m, n), arr.dtype)
    iters = np.empty(n, np.int64)
    qt = np.ascontiguousarray(q.T)
    wk = np.zeros((0, 0), np.float32) if wts is None else wts
    unconverged = int(_l1_kernel(arr, qt, wk, tol, rho, max_iter, out, iters))
    return out, _l1_info(iters, max_iter, unconverged)


# ---------------------------------------------------------------------- linear time
def estimate_basis(
    L: np.ndarray, rank_tol: float = DEFAULT_RANK_TOL, max_rank: int | None = None
) -> np.ndarray:
    """Orthonormal basis of the numerical column space of a low-rank matrix.

    The rank is ``r = #{i : σ_i > rank_tol · σ_1}`` (at most ``max_rank``, at least 1
    unless ``L = 0``); the basis is the first ``r`` left singular vectors.

    Parameters
    ----------
    L : ndarray, shape (m, n)
    rank_tol : float
        Relative singular value threshold, in (0, 1).
    max_rank : int, optional
        Upper bound on ``r``.

    Returns
    -------
    ndarray, shape (m, r), float64 (``r = 0`` if ``L`` is zero)
    """
    arr = _check_matrix(L, "L")
    rank_tol = _check_positive(rank_tol, "rank_tol")
    if rank_tol >= 1.0:
        raise ValueError(f"rank_tol: must lie in (0, 1), got {rank_tol!r}")
    uu, sv, _ = np.linalg.svd(arr.astype(np.float64), full_matrices=False)
    if sv.size == 0 or sv[0] == 0.0:
        return np.zeros((arr.shape[0], 0))
    r = int(np.count_nonzero(sv > rank_tol * sv[0]))
    if max_rank is not None:
        r = min(r, _check_int(max_rank, "max_rank"))
    return np.ascontiguousarray(uu[:, :r])


def noise_rank(data: np.ndarray) -> tuple[int, float]:
    """Rank of the signal in a noisy matrix by the optimal hard threshold.

    Gavish & Donoho (2014): for an ``m × n`` matrix (``m <= n`` after transposing)
    of a low-rank signal plus white noise of unknown level, the singular values
    of the noise are bounded by ``ω(β) · σ_med``, ``β = m / n``, ``σ_med`` the
    median singular value and ``ω(β) ≈ 0.56 β³ − 0.95 β² + 1.82 β + 1.43``; the
    rank is the number of singular values above it.  The threshold is read from
    the data, so it follows the estimation noise of the footage instead of a
    fixed share of the largest singular value.

    Parameters
    ----------
    data : ndarray, shape (m, n)

    Returns
    -------
    rank : int
        At least 1 unless ``data`` is zero.
    threshold : float
        ``ω(β) σ_med``.

    References
    ----------
    M. Gavish, D. L. Donoho, "The optimal hard threshold for singular values is
    4/√3", IEEE Trans. Inf. Theory 60(8), 2014.
    """
    arr = _check_matrix(data, "data").astype(np.float64)
    m, n = sorted(arr.shape)
    sv = np.linalg.svd(arr, compute_uv=False)
    if sv.size == 0 or sv[0] == 0.0:
        return 0, 0.0
    beta = m / n
    omega = 0.56 * beta**3 - 0.95 * beta**2 + 1.82 * beta + 1.43
    thr = float(omega * np.median(sv))
    return max(int(np.count_nonzero(sv > thr)), 1), thr


def _kmeans_labels(x: np.ndarray, k: int, rng: np.random.Generator,
                   iterations: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Lloyd's k-means on the rows of ``x`` (k-means++ seeding); returns centres, labels."""
    n = x.shape[0]
    k = min(k, n)
    centres = np.empty((k, x.shape[1]), np.float64)
    centres[0] = x[rng.integers(n)]
    d2 = ((x - centres[0]) ** 2).sum(1)
    for i in range(1, k):
        total = d2.sum()
        j = rng.integers(n) if total <= 0 else rng.choice(n, p=d2 / total)
        centres[i] = x[j]
        d2 = np.minimum(d2, ((x - centres[i]) ** 2).sum(1))
    labels = np.zeros(n, np.int64)
    for _ in range(iterations):
        labels = _nearest(x, centres)
        for i in range(k):
            sel = labels == i
            if sel.any():
                centres[i] = x[sel].mean(0)
    return centres, labels


def _nearest(x: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Index of the nearest centre of every row of ``x`` (in chunks: linear memory)."""
    out = np.empty(x.shape[0], np.int64)
    cn = (centres * centres).sum(1)
    for s in range(0, x.shape[0], 65536):
        xs = x[s:s + 65536]
        out[s:s + 65536] = np.argmin(cn[None, :] - 2.0 * xs @ centres.T, axis=1)
    return out


def sample_columns(
    U: np.ndarray,
    n_samples: int,
    rng: np.random.Generator,
    strata: int = 0,
    reliable: np.ndarray | None = None,
) -> np.ndarray:
    """The column sample of the linear-time L-step.

    Parameters
    ----------
    U : ndarray, shape (m, n)
    n_samples : int
    rng : numpy.random.Generator
    strata : int
        0: a uniform sample.  k > 0: stratified by motion: k-means with k clusters
        on a uniform pilot sample of ``min(n, 4 n_samples)`` columns, every column
        assigned to its nearest centre (``O(m k n)``), then an equal share of the
        sample from every cluster (all of a smaller cluster, the rest spread over
        the others).  A motion layer that covers a few percent of the pixels then
        has as many seed columns as the dominant one, so the seed PCP keeps its
        direction instead of taking it for sparse outliers.
    reliable : ndarray, shape (n,), bool, optional
        Prefer these columns (e.g. pixels visible in every frame): within a
        cluster, the others are drawn only when the reliable ones run out.

    Returns
    -------
    ndarray, shape (n_samples,), int64
        Sorted distinct column indices.
    """
    n = U.shape[1]
    n_samples = min(n_samples, n)
    if strata <= 0 or n_samples >= n:
        pool = np.arange(n) if reliable is None else np.flatnonzero(reliable)
        if pool.size >= n_samples:
            return np.sort(rng.choice(pool, size=n_samples, replace=False))
        rest = np.setdiff1d(np.arange(n), pool)
        extra = rng.choice(rest, size=n_samples - pool.size, replace=False)
        return np.sort(np.concatenate([pool, extra]))
    x = np.asarray(U, np.float64).T
    pilot = rng.choice(n, size=min(n, 4 * n_samples), replace=False)
    centres, _ = _kmeans_labels(x[pilot], strata, rng)
    labels = _nearest(x, centres)
    groups = [np.flatnonzero(labels == i) for i in range(centres.shape[0])]
    groups = [g for g in groups if g.size]
    quota = np.zeros(len(groups), np.int64)
    left = n_samples
    open_ = list(range(len(groups)))
    while left > 0 and open_:  # equal shares, capped by the cluster sizes
        share = max(left // len(open_), 1)
        for i in list(open_):
            take = min(share, groups[i].size - quota[i], left)
            quota[i] += take
            left -= take
            if quota[i] >= groups[i].size:
                open_.remove(i)
            if left == 0:
                break
    picks = []
    for g, q in zip(groups, quota, strict=True):
        if q == 0:
            continue
        if reliable is not None:
            good, bad = g[reliable[g]], g[~reliable[g]]
            first = rng.choice(good, size=min(q, good.size), replace=False)
            picks.append(first)
            if q > good.size:
                picks.append(rng.choice(bad, size=q - good.size, replace=False))
        else:
            picks.append(rng.choice(g, size=q, replace=False))
    return np.sort(np.concatenate(picks))


def rpca_linear(
    U: np.ndarray,
    lam: float | None = None,
    n_samples: int | None = None,
    seed: int | np.random.Generator | None = 0,
    *,
    weights: np.ndarray | None = None,
    strata: int = 0,
    basis: np.ndarray | None = None,
    rank_tol: float = DEFAULT_RANK_TOL,
    rank_rule: Literal["relative", "noise"] = "relative",
    max_rank: int | None = None,
    tol: float = 1e-7,
    max_iter: int = 500,
    l1_tol: float = 1e-7,
    l1_max_iter: int = 200,
    rho: float = 1.2,
    l1_rho: float = 1.5,
    engine: Literal["numba", "numpy"] = "numba",
    residual: bool = True,
) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    """Principal component pursuit in linear time by l1 filtering (Liu et al. 2016).

    1. *Seed.*  Draw ``s = n_samples`` distinct columns at random (local
       :func:`numpy.random.default_rng` from ``seed``): uniformly, or stratified by
       motion clusters (``strata``, :func:`sample_columns`); columns whose entries
       all have positive ``weights`` first.  All ``m = 2F`` rows are kept (``m`` is
       small), so only columns are sampled.
    2. *Seed PCP.*  Solve PCP on the ``(m, s)`` sub-matrix with :func:`rpca_exact`,
       with ``λ_s = λ · sqrt(n / s)`` (the weight that keeps the balance of the two
       terms when n columns shrink to s: the nuclear norm of an incoherent matrix
       scales with ``sqrt(#columns)``, the L1 norm with ``#columns``; for the
       standard ``λ = 1/sqrt(n)`` it gives the standard ``1/sqrt(s)``).  The basis
       ``B`` is the left singular vectors of its low-rank part with
       ``σ_i > rank_tol · σ_1`` (:func:`estimate_basis`).
    3. *l1 filtering.*  Every column of ``U`` (sampled ones included) is replaced by
       its robust L1 fit ``l_j = B argmin_c Σ_i w_ij |u_ij − (B c)_i|``
       (:func:`l1_regression`).  ``S = U − L``.

    In the exact-recovery regime (``U = L0 + S0`` with PCP recovering ``L0`` both on
    the seed and on the full matrix) the result is ``L0``, the PCP solution.  Outside
    it the result is not the PCP minimiser of the full matrix: it is the column-wise
    L1 projection onto the seed's subspace, with no nuclear-norm shrinkage inside
    that subspace.  Cost: the seed PCP depends on ``s`` only (``O(m² s)`` per
    iteration), the filtering is ``O(m r n)``.

    Parameters
    ----------
    U : ndarray, shape (m, n)
        Data matrix, ``m = 2F`` rows (see the module docstring for the row order).
    lam : float, optional
        PCP weight λ > 0 for the full matrix; default ``1 / sqrt(max(m, n))``.
    n_samples : int, optional
        Number of sampled columns; default ``min(n, max(20 m, 4000))``
        (:data:`DEFAULT_SAMPLES_PER_ROW` · m, at least :data:`DEFAULT_MIN_SAMPLES`).
        Clipped to n.
    seed : int or Generator, optional
        Seed of the local random generator for the column sample.
    weights : ndarray, shape (m, n), optional
        Non-negative entry weights of the l1 filtering (0 = left out, e.g. a point
        hidden in that frame); columns with all weights positive are sampled first.
    strata : int
        Motion clusters of a stratified sample (0 = uniform); see
        :func:`sample_columns`.
    basis : ndarray, shape (m, r), optional
        Warm start: skip steps 1-2 and filter against this basis (e.g.
        ``info["basis"]`` of the previous RLR iteration).  The rank is then fixed.
    rank_tol : float
        Relative singular-value threshold of the rank estimate (default 1e-4).
    rank_rule : {"relative", "noise"}
        "relative": keep ``σ_i > rank_tol · σ_1`` of the seed PCP's low-rank part;
        "noise": the rank of the seed columns by the optimal hard threshold of
        :func:`noise_rank` (at most the rank of the seed PCP's low-rank part; at
        least ``rank_tol`` of σ_1 as well).
    max_rank : int, optional
        Upper bound on the estimated rank.
    tol, max_iter : float, int
        Stopping rule of the seed PCP (:func:`rpca_exact`).
    l1_tol, l1_max_iter : float, int
        Stopping rule of the per-column L1 regression.
    rho : float
        μ growth factor of the seed PCP (see :func:`rpca_exact`).
    l1_rho : float
        μ growth factor of the L1 regression (see :func:`l1_regression`).
    engine : {"numba", "numpy"}
        Kernel of the l1 filtering.
    residual : bool
        Return ``S``; False returns None in its place (a caller that needs only
        ``L`` saves a matrix of U's size).  Default True.

    Returns
    -------
    L : ndarray, shape (m, n)
        Low-rank part; float64 if ``U`` is float64, else float32.
    S : ndarray, shape (m, n), or None
        ``U − L``, same dtype (None when ``residual`` is False).
    info : dict
        ``basis`` (m, r) float64 orthonormal, ``rank``, ``n_samples``, ``columns``
        (sampled indices, None on warm start), ``lam``, ``lam_sample``,
        ``seed_info`` (info of the seed PCP, None on warm start), ``warm_start``,
        ``l1_iterations_mean``, ``l1_iterations_max``, ``l1_unconverged``.

    Raises
    ------
    ValueError
        On invalid input (the message names the argument).
    """
    arr = _check_matrix(U)
    m, n = arr.shape
    lam = _default_lam(arr.shape) if lam is None else _check_positive(lam, "lam")
    if engine not in ("numba", "numpy"):
        raise ValueError(f"engine: expected 'numba' or 'numpy', got {engine!r}")
    _check_rho(rho, "rho")
    _check_rho(l1_rho, "l1_rho")
    _check_positive(l1_tol, "l1_tol")
    _check_int(l1_max_iter, "l1_max_iter")
    if not 0.0 < float(rank_tol) < 1.0:
        raise ValueError(f"rank_tol: must lie in (0, 1), got {rank_tol!r}")
    if rank_rule not in ("relative", "noise"):
        raise ValueError(f"rank_rule: expected 'relative' or 'noise', got {rank_rule!r}")
    if max_rank is not None:
        _check_int(max_rank, "max_rank")
    if n_samples is None:
        n_samples = min(n, max(DEFAULT_SAMPLES_PER_ROW * m, DEFAULT_MIN_SAMPLES))
    n_samples = min(_check_int(n_samples, "n_samples"), n)
    out_dtype = _out_dtype(arr)
    if arr.dtype != out_dtype:
        arr = arr.astype(out_dtype)

    info: dict[str, Any] = {"lam": lam, "warm_start": basis is not None, "columns": None,
                            "seed_info": None, "lam_sample": None}
    wts = _check_weights(weights, arr.shape)
    if basis is None:
        rng = np.random.default_rng(seed)
        reliable = None if wts is None else (wts > 0).all(axis=0)
        cols = sample_columns(arr, n_samples, rng, strata, reliable)
        lam_s = lam * math.sqrt(n / n_samples)
        l_s, _, seed_info = rpca_exact(arr[:, cols], lam_s, tol=tol, max_iter=max_iter,
                                       rho=rho)
        q = estimate_basis(l_s, rank_tol, max_rank)
        if rank_rule == "noise":
            r_noise, _ = noise_rank(arr[:, cols])
            q = q[:, :r_noise]
        info.update(columns=cols, seed_info=seed_info, lam_sample=lam_s, n_samples=n_samples)
        logger.debug("rpca_linear: seed PCP on %d columns, %d iterations, rank %d",
                     n_samples, seed_info["iterations"], q.shape[1])
    else:
        q = _prepare_basis(basis, m)
        info.update(n_samples=0)
    info.update(basis=q, rank=int(q.shape[1]))

    if q.shape[1] == 0:
        L = np.zeros((m, n), out_dtype)
        info.update(l1_iterations_mean=0.0, l1_iterations_max=0, l1_unconverged=0)
    else:
        solver = l1_regression if engine == "numba" else l1_regression_numpy
        L, l1 = solver(arr, q, weights=wts, tol=l1_tol, rho=l1_rho, max_iter=l1_max_iter)
        info.update(l1_iterations_mean=l1["iterations_mean"],
                    l1_iterations_max=l1["iterations_max"], l1_unconverged=l1["unconverged"])
    return L, (arr - L if residual else None), info


# ------------------------------------------------------------------------ the L-step
def lowrank_step(
    U: np.ndarray,
    alpha: float,
    tau: float,
    method: Literal["linear", "exact"] = "linear",
    **kwargs: Any,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """L-step of RLR: ``argmin_L α ||L||_* + τ ||U − L||_1``.

    Equivalent to PCP (2) of the module docstring with ``λ = τ / α`` and ``S = U − L``
    (divide the energy by α; the constraint ``U = L + S`` only names the residual).

    Parameters
    ----------
    U : ndarray, shape (2F, N)
        Trajectory matrix (:func:`trajectories_to_matrix`).
    alpha : float
        α > 0, weight of the nuclear norm (the relaxed rank term).
    tau : float
        τ > 0, weight of ``||U − L||_1``.
    method : {"linear", "exact"}
        :func:`rpca_linear` (default) or :func:`rpca_exact`.
    **kwargs
        Passed to the solver (e.g. ``basis=info["basis"]`` to warm-start the linear
        method, ``n_samples``, ``seed``, ``tol``).

    Returns
    -------
    L, S, info
        As returned by the solver; ``info["lam"] = τ / α``.
    """
    alpha = _check_positive(alpha, "alpha")
    tau = _check_positive(tau, "tau")
    lam = tau / alpha
    if method == "linear":
        return rpca_linear(U, lam, **kwargs)
    if method == "exact":
        return rpca_exact(U, lam, **kwargs)
    raise ValueError(f"method: expected 'linear' or 'exact', got {method!r}")
