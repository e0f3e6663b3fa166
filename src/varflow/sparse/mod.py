"""Dictionary learning by the Method of Optimal Directions (Engan, Aase & Husøy 1999).

MOD alternates

1. sparse coding ``A = OMP(D, Y)`` (:func:`varflow.sparse.omp.omp`, error threshold
   ``tol`` and/or ``max_atoms``), and
2. the least-squares dictionary update ``D = Y Aᵀ (A Aᵀ + εI)⁻¹`` followed by column
   normalisation.  ``ε = ridge · trace(A Aᵀ)/K`` only regularises atoms that are
   (almost) unused.

Atoms that no signal uses (or whose update vanishes) are replaced by the currently
worst-represented training signals (largest residual energy), normalised — the usual
K-SVD/MOD remedy.  The loop stops after ``n_iterations`` coding + update passes or
when both the relative representation error ``Σ‖r_p‖² / Σ‖y_p‖²`` and the mean number of
atoms per signal change by less than ``rel_tol`` (relative) between two codings
(with an error-threshold OMP the error stays near ``tol`` while the codes become
sparser, so both are watched).

Masked signals (apron)
----------------------
Training uses the signals whose fraction of real entries is at least
``min_valid_fraction`` (default 1: only patches entirely inside the image — with
``k = 1`` there is no apron at all, with ``k > 1`` only the last patch row/column
touches it).  When partly masked signals are admitted, coding ignores their masked
entries (masked OMP) and the update fills those entries with the current
approximation ``(D a_p)_i`` before forming ``Y Aᵀ`` — the expectation–maximisation
(majorise–minimise) step for missing data: for fixed codes it does not increase the
masked objective ``Σ_p ‖M_p (y_p − D a_p)‖²`` (up to the ridge and the column
normalisation).  Apron values therefore never influence the result.  Signals whose
(masked) energy is already below the OMP threshold get an empty code and are dropped
from training.

Randomness (the optional subset of ``max_signals`` signals) comes from a local
``np.random.default_rng(seed)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy import linalg

from .dictionaries import normalize_columns
from .omp import Engine, _check_dictionary, _check_mask, _check_signals, omp

__all__ = ["MODResult", "learn_mod"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class MODResult:
    """Outcome of :func:`learn_mod`.

    Attributes
    ----------
    dictionary : ndarray, shape (dim, K), float32
        Learned dictionary, unit-norm columns.
    errors : ndarray, shape (n_codings,), float64
        Relative representation error ``Σ‖M(y − D a)‖² / Σ‖M y‖²`` of each coding pass
        (with the dictionary before that pass's update; the final dictionary is not
        re-coded, to save one OMP pass).
    mean_atoms : ndarray, shape (n_codings,), float64
        Mean number of atoms per training signal of each coding pass.
    n_updates : int
        Dictionary updates performed.
    n_replaced : int
        Atoms replaced in total (unused atoms).
    n_signals : int
        Training signals used.
    converged : bool
        True if the relative-change criterion stopped the loop.
    """

    dictionary: np.ndarray
    errors: np.ndarray
    mean_atoms: np.ndarray
    n_updates: int
    n_replaced: int
    n_signals: int
    converged: bool


@nb.njit(cache=True, parallel=True)
def _mod_stats_kernel(dt, indptr, indices, data, y, mask, full, energy, bt_part, c_part):
    """Residual energies and the MOD normal equations, accumulated per block.

    energy[p] = Σ_i w (y − D a)²; bt_part[b] += A (filled Y)ᵀ ; c_part[b] += A Aᵀ.
    Masked entries of partial signals are filled with (D a)_i (EM imputation).
    """
    n_atoms, dim = dt.shape
    n_sig = y.shape[1]
    n_blocks = bt_part.shape[0]
    for blk in nb.prange(n_blocks):
        rec = np.empty(dim)
        yf = np.empty(dim)
        bt = bt_part[blk]
        cc = c_part[blk]
        for p in range(blk * n_sig // n_blocks, (blk + 1) * n_sig // n_blocks):
            rec[:] = 0.0
            q0 = indptr[p]
            q1 = indptr[p + 1]
            for q in range(q0, q1):
                k = indices[q]
                v = np.float64(data[q])
                for i in range(dim):
                    rec[i] += dt[k, i] * v
            s = 0.0
            for i in range(dim):
                if full[p] or mask[i, p]:
                    yi = np.float64(y[i, p])
                    r = yi - rec[i]
                    s += r * r
                    yf[i] = yi
                else:
                    yf[i] = rec[i]
            energy[p] = s
            for q in range(q0, q1):
                k = indices[q]
                v = np.float64(data[q])
                for i in range(dim):
                    bt[k, i] += v * yf[i]
                for q2 in range(q0, q1):
                    cc[k, indices[q2]] += v * data[q2]


def _mod_stats(d, codes, y, mask):
    """``(energy (P,), B = Y Aᵀ (dim, K), C = A Aᵀ (K, K))`` in float64."""
    n_atoms = d.shape[1]
    dt = np.ascontiguousarray(d.T, dtype=np.float64)
    n_sig = y.shape[1]
    if mask is None:
        full = np.ones(n_sig, bool)
        mk = np.ones((1, 1), bool)
    else:
        full = mask.all(axis=0)
        mk = mask
    n_blocks = max(1, min(n_sig, nb.get_num_threads()))
    energy = np.empty(n_sig, np.float64)
    bt = np.zeros((n_blocks, n_atoms, d.shape[0]), np.float64)
    cc = np.zeros((n_blocks, n_atoms, n_atoms), np.float64)
    _mod_stats_kernel(dt, codes.indptr, codes.indices, codes.data, y, mk, full, energy, bt, cc)
    return energy, bt.sum(axis=0).T, cc.sum(axis=0)


def learn_mod(
    signals: np.ndarray,
    dictionary: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    tol: float | None = 0.05,
    max_atoms: int | None = None,
    n_iterations: int = 10,
    rel_tol: float = 1e-3,
    ridge: float = 1e-6,
    min_valid_fraction: float = 1.0,
    max_signals: int | None = None,
    seed: int | None = 0,
    engine: Engine = "numba",
) -> MODResult:
    """Learn a dictionary with MOD, starting from ``dictionary``.

    Parameters
    ----------
    signals : ndarray, shape (dim, P)
        Training signals as columns (a patch matrix, or one problem of
        :func:`~varflow.sparse.dictionaries.split_problems`).
    dictionary : ndarray, shape (dim, K)
        Initial dictionary (e.g. :func:`~varflow.sparse.dictionaries.dct_dictionary` or
        :func:`~varflow.sparse.dictionaries.dictionary_from_data`); normalised first.
    mask : ndarray of bool, shape (dim, P), optional
        False on apron entries.
    tol, max_atoms : float or None, int or None
        OMP stopping rule (RMS residual per real entry, atoms per signal); see
        :func:`~varflow.sparse.omp.omp`.  Default ``tol = 0.05`` (book's μ).
    n_iterations : int
        Maximum coding + update passes (book: 10 per call); a pass that meets the
        ``rel_tol`` criterion stops before its update.
    rel_tol : float
        Stop when the relative change of both the representation error and the mean
        code size falls below this.  Default 1e-3.
    ridge : float
        ε of the update relative to the mean diagonal of ``A Aᵀ`` (> 0).
    min_valid_fraction : float
        Minimum fraction of real entries for a signal to be used, in (0, 1].
    max_signals : int or None
        Train on a random subset of at most this many signals (seeded).
    seed : int or None
        Seed of the local random generator.
    engine : {"numba", "numpy"}
        OMP engine.

    Returns
    -------
    MODResult

    Raises
    ------
    ValueError
        On invalid shapes or parameter values.

    References
    ----------
    Engan, Aase & Husøy (1999), "Method of optimal directions for frame design",
    ICASSP; Jia, Wang & Tang (2011), "Optical flow estimation using learned sparse
    model", ICCV; Gibson & Marques (2016), ch. 3.
    """
    d = _check_dictionary(dictionary)
    dim, n_atoms = d.shape
    y = _check_signals(signals, dim)
    m = _check_mask(mask, y.shape)
    if n_iterations < 1:
        raise ValueError(f"n_iterations: must be >= 1, got {n_iterations}")
    if not rel_tol >= 0:
        raise ValueError(f"rel_tol: must be >= 0, got {rel_tol}")
    if not ridge > 0:
        raise ValueError(f"ridge: must be > 0, got {ridge}")
    if not 0 < min_valid_fraction <= 1:
        raise ValueError(f"min_valid_fraction: must be in (0, 1], got {min_valid_fraction}")
    if max_signals is not None and max_signals < 1:
        raise ValueError(f"max_signals: must be >= 1, got {max_signals}")
    if tol is None and max_atoms is None:
        raise ValueError("tol: give an error threshold tol and/or max_atoms")
    rng = np.random.default_rng(seed)

    # ---- training set: mostly-real signals above the coding threshold
    if m is None:
        n_real = np.full(y.shape[1], dim)
        energy0 = np.einsum("ip,ip->p", y, y, dtype=np.float64)
    else:
        n_real = m.sum(axis=0)
        ym = np.where(m, y, np.float32(0))
        energy0 = np.einsum("ip,ip->p", ym, ym, dtype=np.float64)
        del ym
    t2 = 0.0 if tol is None else float(tol) ** 2
    keep = (n_real >= min_valid_fraction * dim) & (n_real > 0) & (energy0 > t2 * n_real)
    cols = np.flatnonzero(keep)
    if max_signals is not None and cols.size > max_signals:
        cols = np.sort(rng.choice(cols, size=max_signals, replace=False))
    d, _ = normalize_columns(d)
    if cols.size == 0:
        logger.info("learn_mod: no signal above the coding threshold; dictionary unchanged")
        return MODResult(d, np.zeros(0), np.zeros(0), 0, 0, 0, False)
    if cols.size == y.shape[1]:  # no copy of a (possibly 240 MB) patch matrix
        y_t, m_t = np.ascontiguousarray(y), None if m is None else np.ascontiguousarray(m)
    else:
        y_t = np.ascontiguousarray(y[:, cols])
        m_t = None if m is None else np.ascontiguousarray(m[:, cols])
    if m_t is not None and m_t.all():
        m_t = None
    full_t = np.ones(cols.size, bool) if m_t is None else m_t.all(axis=0)
    total = float(energy0[cols].sum())

    errors: list[float] = []
    mean_atoms: list[float] = []
    n_updates = 0
    n_replaced = 0
    converged = False
    for it in range(n_iterations):
        codes = omp(d, y_t, tol=tol, max_atoms=max_atoms, mask=m_t, engine=engine)
        energy, b, c = _mod_stats(d, codes, y_t, m_t)
        errors.append(float(energy.sum()) / total)
        mean_atoms.append(codes.nnz / cols.size)
        logger.debug(
            "learn_mod: pass %d, relative error %.4g, %.2f atoms/signal",
            it,
            errors[-1],
            mean_atoms[-1],
        )
        if it > 0:
            de = abs(errors[-2] - errors[-1]) <= rel_tol * max(errors[-2], 1e-300)
            dn = abs(mean_atoms[-2] - mean_atoms[-1]) <= rel_tol * max(mean_atoms[-2], 1e-300)
            if de and dn:
                converged = True
                break
        eps = ridge * max(float(np.trace(c)) / n_atoms, 1e-12)
        c[np.diag_indices(n_atoms)] += eps
        d_new = linalg.solve(c, np.ascontiguousarray(b.T), assume_a="pos").T
        d_new, norms = normalize_columns(d_new)
        usage = np.bincount(codes.indices, minlength=n_atoms)
        dead = np.flatnonzero((usage == 0) | (norms <= 1e-8 * max(float(norms.max()), 1e-30)))
        if dead.size:
            cand = np.flatnonzero(full_t & (energy > 0))
            cand = cand[np.argsort(-energy[cand], kind="stable")][: dead.size]
            repl = dead[: cand.size]
            if cand.size:
                d_new[:, repl] = normalize_columns(y_t[:, cand])[0]
            d_new[:, dead[cand.size :]] = d[:, dead[cand.size :]]
            n_replaced += int(repl.size)
            logger.debug("learn_mod: replaced %d unused atoms", repl.size)
        d = d_new
        n_updates += 1
    logger.info(
        "learn_mod: %d signals, %d updates, error %.4g, %.2f atoms/signal, %d replaced",
        cols.size,
        n_updates,
        errors[-1],
        mean_atoms[-1],
        n_replaced,
    )
    return MODResult(
        dictionary=d,
        errors=np.asarray(errors),
        mean_atoms=np.asarray(mean_atoms),
        n_updates=n_updates,
        n_replaced=n_replaced,
        n_signals=int(cols.size),
        converged=converged,
    )
