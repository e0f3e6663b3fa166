"""Batch orthogonal matching pursuit (Rubinstein, Zibulevsky & Elad 2008).

OMP greedily builds the code ``a`` of a signal ``y`` over a dictionary ``D``: pick the
atom most correlated with the residual, re-fit all chosen coefficients by least
squares, repeat.  *Batch* OMP (Rubinstein et al., "Efficient implementation of the
K-SVD algorithm using batch orthogonal matching pursuit", Technion CS-2008-08) never
forms the residual: with the Gram matrix ``G = DᵀD`` and ``α⁰ = Dᵀy`` (one BLAS product
for a whole chunk of signals) the correlations are ``α = α⁰ − G_I γ_I`` and the least
squares system is solved through a progressively updated Cholesky factor of
``G_II``.  The residual energy is evaluated from the residual ``y − D_I γ_I``
(``dim·|I|`` operations, like the correlation update) rather than as
``‖y‖² − γ_Iᵀ α⁰_I``, which cancels badly in float32 for patches with a large mean
(e.g. a 20 px flow).

Stopping rule
-------------
A signal stops when

* its residual is small: ``‖r‖²_w <= tol² · n_w`` where ``n_w`` is the number of real
  (unmasked) entries, i.e. **the root-mean-square residual per real entry is at most**
  ``tol`` (same unit as the signal: pixels for flow patches; the book's μ = 0.05 is
  read as 0.05 px RMS, independent of patch size and layout), or
* it uses ``max_atoms`` atoms (``L``), or
* no atom is left that improves the fit (all correlations zero, or the next atom is
  numerically in the span of the chosen ones), or the fit is exact to float32
  precision (``‖r‖² <= 1e-10 ‖y‖²``).

Masks (apron)
-------------
``mask[i, p] = False`` removes entry ``i`` of signal ``p`` from the problem: the
inner products become ``<a, b>_w = Σ_i w_i a_i b_i``, atoms are selected by their
normalised correlation ``|<d_j, r>_w| / ‖d_j‖_w`` and the Gram columns of the chosen
atoms are formed for that signal only.  Values of ``y`` at masked entries are never
read.  Fully valid signals (the vast majority) take the fast shared-Gram path.

Codes
-----
Returned as a ``scipy.sparse.csc_array`` of shape ``(K, P)`` (column ``p`` = code of
signal ``p``, sorted indices, float32): with a few atoms per signal this is ~``L/K`` the
memory of a dense ``(K, P)`` array (a dense one would be 0.5–1 GB at 480×640, k = 1).
:func:`reconstruct` computes ``D @ A`` with a parallel Numba kernel.
"""

from __future__ import annotations

import logging
from typing import Literal

import numba as nb
import numpy as np
from scipy import sparse

__all__ = ["omp", "omp_numpy", "reconstruct", "residual_energy"]

logger = logging.getLogger(__name__)

Engine = Literal["numba", "numpy"]

_DEP_TOL = 1e-10  # relative Schur complement below which an atom counts as dependent
_NORM_TOL = 1e-12  # squared (masked) atom norm below which an atom is unusable
_EXACT = 1e-10  # residual energy below _EXACT·‖y‖² counts as an exact fit (float32 data)


# --------------------------------------------------------------------------- checks
def _check_dictionary(dictionary: np.ndarray) -> np.ndarray:
    d = np.asarray(dictionary)
    if d.ndim != 2 or d.shape[0] < 1 or d.shape[1] < 1:
        raise ValueError(f"dictionary: expected shape (dim, n_atoms), got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError("dictionary: contains NaN or infinite values")
    return d.astype(np.float32, copy=False)


def _check_signals(signals: np.ndarray, dim: int, name: str = "signals") -> np.ndarray:
    y = np.asarray(signals)
    if y.ndim != 2 or y.shape[0] != dim:
        raise ValueError(f"{name}: expected shape ({dim}, P) like the dictionary, got {y.shape}")
    return y.astype(np.float32, copy=False)


def _check_mask(mask: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray | None:
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.shape != shape:
        raise ValueError(f"mask: expected shape {shape} like the signals, got {m.shape}")
    return m.astype(bool, copy=False)


def _check_stopping(tol: float | None, max_atoms: int | None, dim: int, n_atoms: int) -> int:
    if tol is None and max_atoms is None:
        raise ValueError("tol: give an error threshold tol and/or max_atoms")
    if tol is not None and not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"tol: must be a finite number >= 0, got {tol}")
    if max_atoms is not None and max_atoms < 1:
        raise ValueError(f"max_atoms: must be >= 1, got {max_atoms}")
    cap = min(dim, n_atoms)
    return cap if max_atoms is None else min(int(max_atoms), cap)


def _thresholds(tol: float | None, dim: int, mask: np.ndarray | None, p0: int, p1: int):
    """Residual-energy threshold per signal, ``tol² · (number of real entries)``."""
    t2 = 0.0 if tol is None else float(tol) ** 2
    if mask is None:
        return np.full(p1 - p0, t2 * dim), np.ones(p1 - p0, dtype=bool)
    n_real = mask[:, p0:p1].sum(axis=0)
    return t2 * n_real.astype(np.float64), n_real == dim


# --------------------------------------------------------------------------- Numba kernel
@nb.njit(cache=True, parallel=True)
def _batch_omp_kernel(
    dt, gram, ydt, y, mask, full, thr, max_atoms, n_blocks, out_idx, out_val, out_n
):
    """Batch OMP over the columns of ``y``; writes ``out_idx``, ``out_val``, ``out_n``.

    Signals are rows here (chunk-transposed for contiguous access):
    dt (K, dim) f64 = Dᵀ; gram (K, K) f64; ydt (P, K) f32 = yᵀD (used when full[p]);
    y (P, dim) f32; mask (P, dim) bool (read only where not full[p]); thr (P,) f64;
    out_idx (P, L) i32, out_val (P, L) f32, out_n (P,) i32.
    """
    n_atoms, dim = dt.shape
    n_sig = y.shape[0]
    inv_diag = np.empty(n_atoms)
    for j in range(n_atoms):
        inv_diag[j] = 1.0 / gram[j, j] if gram[j, j] > _NORM_TOL else 0.0
    big_l = max_atoms
    for blk in nb.prange(n_blocks):
        p_start = blk * n_sig // n_blocks
        p_stop = (blk + 1) * n_sig // n_blocks
        a0 = np.empty(n_atoms)
        alpha = np.empty(n_atoms)
        nrm2 = np.empty(n_atoms)
        inv_nrm2 = np.empty(n_atoms)
        used = np.empty(n_atoms, dtype=np.bool_)
        idx = np.empty(big_l, dtype=np.int64)
        chol = np.zeros((big_l, big_l))
        tmp = np.empty(big_l)
        gam = np.empty(big_l)
        gw = np.empty((n_atoms, big_l))  # Gram columns of the chosen atoms (masked path)
        yw = np.empty(dim)
        wt = np.empty(dim)
        for p in range(p_start, p_stop):
            is_full = full[p]
            y2 = 0.0
            if is_full:
                for i in range(dim):
                    v = np.float64(y[p, i])
                    y2 += v * v
                for j in range(n_atoms):
                    a0[j] = ydt[p, j]
                    nrm2[j] = gram[j, j]
                    inv_nrm2[j] = inv_diag[j]
            else:
                for i in range(dim):
                    if mask[p, i]:
                        wt[i] = 1.0
                        yw[i] = y[p, i]
                    else:
                        wt[i] = 0.0
                        yw[i] = 0.0
                    y2 += yw[i] * yw[i]
                for j in range(n_atoms):
                    s = 0.0
                    s2 = 0.0
                    for i in range(dim):
                        dji = dt[j, i] * wt[i]
                        s += dji * yw[i]
                        s2 += dji * dji
                    a0[j] = s
                    nrm2[j] = s2
                    inv_nrm2[j] = 1.0 / s2 if s2 > _NORM_TOL else 0.0
            for j in range(n_atoms):
                alpha[j] = a0[j]
                used[j] = False
            eps = y2
            stop = max(thr[p], _EXACT * y2)
            n = 0
            while n < big_l and eps > stop:
                best = -1
                best_v = 0.0
                for j in range(n_atoms):
                    if not used[j]:
                        v = alpha[j] * alpha[j] * inv_nrm2[j]
                        if v > best_v:
                            best_v = v
                            best = j
                if best < 0:
                    break
                k = best
                used[k] = True
                if not is_full:
                    for j in range(n_atoms):
                        s = 0.0
                        for i in range(dim):
                            s += dt[j, i] * dt[k, i] * wt[i]
                        gw[j, n] = s
                gkk = nrm2[k]
                # Cholesky update: solve chol[:n, :n] w = G[I, k]
                wsq = 0.0
                for r in range(n):
                    s = gram[idx[r], k] if is_full else gw[idx[r], n]
                    for c in range(r):
                        s -= chol[r, c] * tmp[c]
                    tmp[r] = s / chol[r, r]
                    wsq += tmp[r] * tmp[r]
                schur = gkk - wsq
                if schur <= _DEP_TOL * gkk:
                    continue  # numerically in the span of the chosen atoms: skip it
                for c in range(n):
                    chol[n, c] = tmp[c]
                chol[n, n] = np.sqrt(schur)
                idx[n] = k
                n += 1
                # gam = (L Lᵀ)⁻¹ α⁰_I
                for r in range(n):
                    s = a0[idx[r]]
                    for c in range(r):
                        s -= chol[r, c] * tmp[c]
                    tmp[r] = s / chol[r, r]
                for r in range(n - 1, -1, -1):
                    s = tmp[r]
                    for c in range(r + 1, n):
                        s -= chol[c, r] * gam[c]
                    gam[r] = s / chol[r, r]
                # α = α⁰ − G_I γ
                if is_full:
                    for j in range(n_atoms):
                        alpha[j] = a0[j]
                    for t in range(n):
                        row = idx[t]
                        g = gam[t]
                        for j in range(n_atoms):
                            alpha[j] -= gram[row, j] * g
                else:
                    for j in range(n_atoms):
                        s = a0[j]
                        for t in range(n):
                            s -= gw[j, t] * gam[t]
                        alpha[j] = s
                # residual energy from the residual itself (‖y‖² − γᵀα⁰_I would cancel)
                eps = 0.0
                for i in range(dim):
                    r = np.float64(y[p, i]) if is_full else yw[i]
                    for t in range(n):
                        r -= dt[idx[t], i] * gam[t]
                    if is_full or wt[i] > 0.0:
                        eps += r * r
            # insertion sort by atom index (canonical CSC)
            for r in range(1, n):
                ki = idx[r]
                kv = gam[r]
                c = r - 1
                while c >= 0 and idx[c] > ki:
                    idx[c + 1] = idx[c]
                    gam[c + 1] = gam[c]
                    c -= 1
                idx[c + 1] = ki
                gam[c + 1] = kv
            for r in range(n):
                out_idx[p, r] = idx[r]
                out_val[p, r] = gam[r]
            out_n[p] = n


@nb.njit(cache=True, parallel=True)
def _reconstruct_kernel(dt, indptr, indices, data, n_blocks, out):
    """``out[:, p] = Σ_q dt[indices[q]] · data[q]`` over the CSC column ``p``."""
    dim = dt.shape[1]
    n_sig = out.shape[1]
    for blk in nb.prange(n_blocks):
        buf = np.empty(dim)
        for p in range(blk * n_sig // n_blocks, (blk + 1) * n_sig // n_blocks):
            buf[:] = 0.0
            for q in range(indptr[p], indptr[p + 1]):
                k = indices[q]
                v = np.float64(data[q])
                for i in range(dim):
                    buf[i] += dt[k, i] * v
            for i in range(dim):
                out[i, p] = buf[i]


@nb.njit(cache=True, parallel=True)
def _residual_kernel(dt, indptr, indices, data, y, mask, use_mask, n_blocks, out):
    """``out[p] = Σ_i w_ip (y_ip − (D a_p)_i)²``."""
    dim = dt.shape[1]
    n_sig = y.shape[1]
    for blk in nb.prange(n_blocks):
        buf = np.empty(dim)
        for p in range(blk * n_sig // n_blocks, (blk + 1) * n_sig // n_blocks):
            for i in range(dim):
                buf[i] = y[i, p]
            for q in range(indptr[p], indptr[p + 1]):
                k = indices[q]
                v = np.float64(data[q])
                for i in range(dim):
                    buf[i] -= dt[k, i] * v
            s = 0.0
            for i in range(dim):
                if (not use_mask) or mask[i, p]:
                    s += buf[i] * buf[i]
            out[p] = s


def _n_blocks(n: int) -> int:
    return max(1, min(n, 8 * nb.get_num_threads()))


def _as_csc(codes, n_signals: int | None = None) -> sparse.csc_array:
    a = codes if isinstance(codes, sparse.csc_array) else sparse.csc_array(codes)
    if n_signals is not None and a.shape[1] != n_signals:
        raise ValueError(f"codes: expected {n_signals} columns, got shape {a.shape}")
    return a


# --------------------------------------------------------------------------- public API
def omp(
    dictionary: np.ndarray,
    signals: np.ndarray,
    *,
    tol: float | None = 0.05,
    max_atoms: int | None = None,
    mask: np.ndarray | None = None,
    engine: Engine = "numba",
    chunk_size: int = 8192,
) -> sparse.csc_array:
    """Sparse codes of many signals by (batch) orthogonal matching pursuit.

    Parameters
    ----------
    dictionary : ndarray, shape (dim, K)
        Atoms as columns, normally of unit L2 norm (any non-zero norm works: atoms are
        selected by normalised correlation).
    signals : ndarray, shape (dim, P)
        Signals as columns (e.g. a patch matrix from :class:`~varflow.sparse.PatchGrid`).
    tol : float or None
        RMS residual per real entry at which a signal stops (``‖r‖² <= tol²·n_real``),
        in signal units.  Default 0.05 (the book's μ).  None: stop on ``max_atoms``
        only.
    max_atoms : int or None
        ``L``, maximum atoms per signal; None means ``min(dim, K)``.
    mask : ndarray of bool, shape (dim, P), optional
        False on entries to ignore (apron).  None: all entries are real.
    engine : {"numba", "numpy"}
        ``"numba"``: parallel batch OMP (fast).  ``"numpy"``: plain per-signal OMP with
        :func:`numpy.linalg.lstsq` (slow reference, same result).
    chunk_size : int
        Signals per ``Dᵀy`` product (bounds memory to ``K·chunk_size`` floats).

    Returns
    -------
    scipy.sparse.csc_array, shape (K, P), float32
        Column ``p`` holds the code of signal ``p`` (sorted row indices).

    Raises
    ------
    ValueError
        On mismatched shapes, non-finite dictionary, neither ``tol`` nor
        ``max_atoms``, ``tol < 0`` or ``max_atoms < 1``.

    References
    ----------
    Rubinstein, Zibulevsky & Elad (2008), Technion CS-2008-08; Pati, Rezaiifar &
    Krishnaprasad (1993), Asilomar.
    """
    d = _check_dictionary(dictionary)
    dim, n_atoms = d.shape
    y = _check_signals(signals, dim)
    m = _check_mask(mask, y.shape)
    big_l = _check_stopping(tol, max_atoms, dim, n_atoms)
    if engine == "numpy":
        return omp_numpy(d, y, tol=tol, max_atoms=big_l, mask=m)
    if engine != "numba":
        raise ValueError(f"engine: expected 'numba' or 'numpy', got {engine!r}")
    if chunk_size < 1:
        raise ValueError(f"chunk_size: must be >= 1, got {chunk_size}")

    n_sig = y.shape[1]
    dt64 = np.ascontiguousarray(d.T, dtype=np.float64)
    gram = dt64 @ dt64.T
    dummy_mask = np.ones((1, 1), dtype=bool)
    counts = np.zeros(n_sig, np.int32)
    idx_parts: list[np.ndarray] = []
    val_parts: list[np.ndarray] = []
    for p0 in range(0, n_sig, chunk_size):
        p1 = min(p0 + chunk_size, n_sig)
        yc = np.ascontiguousarray(y[:, p0:p1].T)  # (chunk, dim): signals as rows
        ydt = yc @ d
        thr, full = _thresholds(tol, dim, m, p0, p1)
        mc = dummy_mask if m is None or full.all() else np.ascontiguousarray(m[:, p0:p1].T)
        out_idx = np.empty((p1 - p0, big_l), np.int32)
        out_val = np.empty((p1 - p0, big_l), np.float32)
        out_n = np.empty(p1 - p0, np.int32)
        _batch_omp_kernel(
            dt64, gram, ydt, yc, mc, full, thr, big_l, _n_blocks(p1 - p0), out_idx, out_val, out_n
        )
        keep = np.arange(big_l)[None, :] < out_n[:, None]
        idx_parts.append(out_idx[keep])
        val_parts.append(out_val[keep])
        counts[p0:p1] = out_n
    indptr = np.zeros(n_sig + 1, np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices = np.concatenate(idx_parts) if idx_parts else np.zeros(0, np.int32)
    data = np.concatenate(val_parts) if val_parts else np.zeros(0, np.float32)
    codes = sparse.csc_array((data, indices, indptr), shape=(n_atoms, n_sig))
    codes.has_sorted_indices = True
    logger.debug("omp: %d signals, mean %.2f atoms", n_sig, counts.mean() if n_sig else 0.0)
    return codes


def omp_numpy(
    dictionary: np.ndarray,
    signals: np.ndarray,
    *,
    tol: float | None = 0.05,
    max_atoms: int | None = None,
    mask: np.ndarray | None = None,
) -> sparse.csc_array:
    """Reference OMP: per-signal loop, residual recomputed with ``lstsq`` (float64).

    Same parameters, stopping rule and result as :func:`omp` (which it backs for
    ``engine="numpy"``); orders of magnitude slower — for tests and small problems.
    """
    d = _check_dictionary(dictionary).astype(np.float64)
    dim, n_atoms = d.shape
    y = _check_signals(signals, dim)
    m = _check_mask(mask, y.shape)
    big_l = _check_stopping(tol, max_atoms, dim, n_atoms)
    t2 = 0.0 if tol is None else float(tol) ** 2
    rows, cols, vals = [], [], []
    for p in range(y.shape[1]):
        keep = np.ones(dim, bool) if m is None else m[:, p]
        dm = d[keep]
        yp = y[keep, p].astype(np.float64)
        nrm2 = (dm * dm).sum(axis=0)
        usable = nrm2 > _NORM_TOL
        stop = max(t2 * keep.sum(), _EXACT * float(yp @ yp))
        chosen: list[int] = []
        coef = np.zeros(0)
        r = yp
        tried = np.zeros(n_atoms, bool)
        while len(chosen) < big_l and float(r @ r) > stop:
            score = np.where(usable & ~tried, (dm.T @ r) ** 2 / np.where(usable, nrm2, 1.0), 0.0)
            k = int(np.argmax(score))
            if score[k] <= 0.0:
                break
            tried[k] = True
            sub = dm[:, chosen + [k]]
            # skip an atom (numerically) in the span of the chosen ones, as the kernel does
            if chosen:
                proj = np.linalg.lstsq(dm[:, chosen], dm[:, k], rcond=None)[0]
                res = dm[:, k] - dm[:, chosen] @ proj
                if float(res @ res) <= _DEP_TOL * nrm2[k]:
                    continue
            chosen.append(k)
            coef = np.linalg.lstsq(sub, yp, rcond=None)[0]
            r = yp - sub @ coef
        order = np.argsort(chosen)
        rows.extend(np.asarray(chosen, int)[order])
        cols.extend([p] * len(chosen))
        vals.extend(coef[order])
    a = sparse.coo_array(
        (np.asarray(vals, np.float32), (np.asarray(rows, np.int64), np.asarray(cols, np.int64))),
        shape=(n_atoms, y.shape[1]),
    )
    return sparse.csc_array(a)


def reconstruct(dictionary: np.ndarray, codes) -> np.ndarray:
    """``D @ A`` for sparse codes, with a parallel Numba kernel.

    Parameters
    ----------
    dictionary : ndarray, shape (dim, K)
    codes : sparse array or ndarray, shape (K, P)
        Typically the output of :func:`omp`.

    Returns
    -------
    ndarray, shape (dim, P), float32
    """
    d = _check_dictionary(dictionary)
    a = _as_csc(codes)
    if a.shape[0] != d.shape[1]:
        raise ValueError(f"codes: expected {d.shape[1]} rows (atoms), got shape {a.shape}")
    out = np.empty((d.shape[0], a.shape[1]), np.float32)
    if a.shape[1]:
        dt = np.ascontiguousarray(d.T, dtype=np.float64)
        _reconstruct_kernel(dt, a.indptr, a.indices, a.data, _n_blocks(a.shape[1]), out)
    return out


def residual_energy(
    dictionary: np.ndarray, codes, signals: np.ndarray, mask: np.ndarray | None = None
) -> np.ndarray:
    """Per-signal squared residual ``Σ_i w_ip (y_ip − (D a_p)_i)²`` (masked entries skipped).

    Returns
    -------
    ndarray, shape (P,), float64
    """
    d = _check_dictionary(dictionary)
    y = _check_signals(signals, d.shape[0])
    a = _as_csc(codes, y.shape[1])
    m = _check_mask(mask, y.shape)
    out = np.empty(y.shape[1], np.float64)
    if y.shape[1]:
        dt = np.ascontiguousarray(d.T, dtype=np.float64)
        mk = np.ones((1, 1), bool) if m is None else m
        nblk = _n_blocks(y.shape[1])
        _residual_kernel(dt, a.indptr, a.indices, a.data, y, mk, m is not None, nblk, out)
    return out
