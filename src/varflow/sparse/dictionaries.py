"""Dictionaries for flow patches: overcomplete DCT, data initialisation, layouts.

Overcomplete DCT
----------------
The classic separable overcomplete DCT of the K-SVD literature (Aharon, Elad &
Bruckstein 2006; Elad's ``odctdict``/``odct2dict``): a 1-D dictionary of ``K₁``
atoms of length ``m`` with atom ``j`` equal to ``cos(π j t / K₁)``, ``t = 0..m−1``,
mean removed for ``j >= 1`` and normalised; the 2-D dictionary is the Kronecker
product of a vertical (``m × K₁``) and a horizontal (``n × K₂``) one, so an atom is
the outer product of a vertical and a horizontal cosine, vectorised row-major like the
patches of :class:`~varflow.sparse.PatchGrid`.  Atoms are ordered by total frequency
``j₁ + j₂`` (ties by ``j₁``), so the first atom is the constant (DC) one and
truncation to exactly ``n_atoms`` columns drops the highest frequencies.

Layouts of flow patches
-----------------------
``"1D"``
    One dictionary of ``m·n``-element atoms shared by both flow components: the
    u-patches and the v-patches are all columns of one ``(m·n, 2P)`` problem.
``"2x1D"``
    One dictionary per component: two ``(m·n, P)`` problems.
``"2D"``
    Joint patches ``[u; v]`` of ``2·m·n`` entries: one ``(2·m·n, P)`` problem.  Its
    DCT initialisation is block-diagonal (half the atoms code u, half code v).

:func:`split_problems` turns the flow patch matrix (``extract`` of an ``(H, W, 2)``
flow, rows ``[u-patch; v-patch]``) into the list of ``(signals, mask)`` problems of a
layout and :func:`merge_problems` assembles per-problem results back.
"""

from __future__ import annotations

import logging
import math
from typing import Literal, get_args

import numpy as np

__all__ = [
    "Layout",
    "LAYOUTS",
    "check_layout",
    "dct_dictionary",
    "dictionary_from_data",
    "layout_atom_dim",
    "layout_dct",
    "merge_problems",
    "normalize_columns",
    "split_problems",
]

logger = logging.getLogger(__name__)

Layout = Literal["1D", "2x1D", "2D"]
LAYOUTS: tuple[str, ...] = get_args(Layout)


def check_layout(layout: str) -> Layout:
    """Return ``layout`` if it is one of :data:`LAYOUTS`, else raise ``ValueError``."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout: expected one of {LAYOUTS}, got {layout!r}")
    return layout  # type: ignore[return-value]


def normalize_columns(d: np.ndarray, min_norm: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Scale columns to unit L2 norm.

    Returns
    -------
    normalized : ndarray, same shape, float32
        Columns with norm ``<= min_norm`` are left as they are (zero).
    norms : ndarray, shape (K,), float64
    """
    d64 = np.asarray(d, np.float64)
    norms = np.sqrt((d64 * d64).sum(axis=0))
    scale = np.where(norms > min_norm, 1.0 / np.maximum(norms, min_norm), 1.0)
    return (d64 * scale).astype(np.float32), norms


def _odct_1d(length: int, n_atoms: int) -> np.ndarray:
    """``(length, n_atoms)`` 1-D overcomplete DCT (Elad's ``odctdict``), float64."""
    t = np.arange(length)[:, None]
    j = np.arange(n_atoms)[None, :]
    d = np.cos(np.pi * t * j / n_atoms)
    d[:, 1:] -= d[:, 1:].mean(axis=0)
    norms = np.linalg.norm(d, axis=0)
    # a mean-free cosine that vanishes on the grid cannot occur for j < n_atoms, length >= 2
    d /= np.where(norms > 0, norms, 1.0)
    return d


def dct_dictionary(m: int, n: int, n_atoms: int) -> np.ndarray:
    """Overcomplete separable 2-D DCT dictionary for ``m × n`` patches.

    Parameters
    ----------
    m, n : int
        Patch height and width (``>= 1``).
    n_atoms : int
        Number of atoms ``K >= 1``.  For ``K >= m·n`` the 1-D dictionaries have
        ``K₁ = max(m, ceil(sqrt(K)))`` and ``K₂ = max(n, ceil(K / K₁))`` atoms (400 →
        20 × 20, 800 → 29 × 28 with 12 dropped).  An *undercomplete* ``K < m·n`` is
        allowed: the ``K`` lowest frequencies of the ``K₁ = m``, ``K₂ = n`` dictionary.

    Returns
    -------
    ndarray, shape (m·n, K), float32
        Unit-norm columns; column 0 is the constant atom ``1/sqrt(m·n)``; entries are
        row-major over the patch (row ``a·n + b``).

    Raises
    ------
    ValueError
        If a size is < 1.

    References
    ----------
    Aharon, Elad & Bruckstein (2006), K-SVD, IEEE TSP 54(11); Elad (2010), *Sparse and
    Redundant Representations*, Springer.
    """
    for name, val in (("m", m), ("n", n), ("n_atoms", n_atoms)):
        if int(val) != val or val < 1:
            raise ValueError(f"{name}: must be a positive integer, got {val}")
    if m == 1 and n == 1 and n_atoms > 1:
        raise ValueError(f"n_atoms: 1×1 patches admit a single (constant) atom, got {n_atoms}")
    if n_atoms < m * n:
        k1, k2 = m, n
    elif m == 1 or n == 1:  # a length-1 direction has only the constant 1-D atom
        k1, k2 = (1, n_atoms) if m == 1 else (n_atoms, 1)
    else:
        k1 = max(m, math.ceil(math.sqrt(n_atoms)))
        k2 = max(n, math.ceil(n_atoms / k1))
    d1 = _odct_1d(m, k1)
    d2 = _odct_1d(n, k2)
    j1, j2 = np.meshgrid(np.arange(k1), np.arange(k2), indexing="ij")
    order = np.lexsort((j1.ravel(), (j1 + j2).ravel()))[:n_atoms]
    j1, j2 = j1.ravel()[order], j2.ravel()[order]
    # atom (j1, j2): d1[:, j1] ⊗ d2[:, j2], entry (a, b) at row a·n + b
    atoms = d1[:, None, j1] * d2[None, :, j2]
    d = atoms.reshape(m * n, n_atoms)
    d /= np.linalg.norm(d, axis=0)
    return d.astype(np.float32)


def layout_atom_dim(layout: str, patch_size: tuple[int, int]) -> int:
    """Length of an atom in a layout: ``m·n`` for "1D"/"2x1D", ``2·m·n`` for "2D"."""
    mn = int(patch_size[0]) * int(patch_size[1])
    return 2 * mn if check_layout(layout) == "2D" else mn


def layout_dct(layout: str, patch_size: tuple[int, int], n_atoms: int) -> list[np.ndarray]:
    """Initial DCT dictionaries of a layout (one per problem of :func:`split_problems`).

    Parameters
    ----------
    layout : {"1D", "2x1D", "2D"}
    patch_size : (m, n)
    n_atoms : int
        Atoms per dictionary.  For "2D" (needs ``n_atoms >= 2``) the ``(2·m·n, K)``
        dictionary is block-diagonal: ``ceil(K/2)`` DCT atoms in the u-half and
        ``floor(K/2)`` in the v-half.

    Returns
    -------
    list of ndarray
        ``[D]`` for "1D" and "2D", ``[D_u, D_v]`` for "2x1D"; float32, unit columns.
    """
    layout = check_layout(layout)
    m, n = (int(s) for s in patch_size)
    if layout == "1D":
        return [dct_dictionary(m, n, n_atoms)]
    if layout == "2x1D":
        d = dct_dictionary(m, n, n_atoms)
        return [d, d.copy()]
    if n_atoms < 2:
        raise ValueError(f"n_atoms: the 2D layout needs >= 2 atoms, got {n_atoms}")
    ku = (n_atoms + 1) // 2
    out = np.zeros((2 * m * n, n_atoms), np.float32)
    out[: m * n, :ku] = dct_dictionary(m, n, ku)
    out[m * n :, ku:] = dct_dictionary(m, n, n_atoms - ku)
    return [out]


def _check_patches(y: np.ndarray, mask: np.ndarray | None, n_channels: int):
    y = np.asarray(y)
    if y.ndim != 2 or n_channels < 1 or y.shape[0] % n_channels or y.shape[0] == 0:
        raise ValueError(
            f"patches: expected shape (n_channels·m·n, P) with n_channels={n_channels}, "
            f"got {y.shape}"
        )
    if mask is not None and np.shape(mask) != y.shape:
        raise ValueError(f"mask: expected shape {y.shape}, got {np.shape(mask)}")
    return y, (None if mask is None else np.asarray(mask, bool))


def split_problems(
    layout: str, patches: np.ndarray, mask: np.ndarray | None = None, n_channels: int = 2
) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Split a flow patch matrix into the coding / learning problems of a layout.

    Parameters
    ----------
    layout : {"1D", "2x1D", "2D"}
    patches : ndarray, shape (c·m·n, P)
        Patch matrix of a ``c``-channel field, channel-major rows (``extract``).
    mask : ndarray of bool, same shape, optional
        Real-entry mask (``PatchGrid.patch_mask``).
    n_channels : int
        ``c``, 2 for a flow.  (The layouts generalise: "1D" stacks all channels as
        columns, "2x1D" gives one problem per channel, "2D" one joint problem.)

    Returns
    -------
    list of (signals, mask)
        "1D": ``[((m·n, c·P), ...)]`` with the channel-0 patches first;
        "2x1D": ``c`` problems ``(m·n, P)``; "2D": the input itself.
    """
    layout = check_layout(layout)
    y, msk = _check_patches(patches, mask, n_channels)
    if layout == "2D":
        return [(y, msk)]
    mn = y.shape[0] // n_channels
    ys = [y[c * mn : (c + 1) * mn] for c in range(n_channels)]
    ms = [None if msk is None else msk[c * mn : (c + 1) * mn] for c in range(n_channels)]
    if layout == "2x1D":
        return list(zip(ys, ms, strict=True))
    return [(np.hstack(ys), None if msk is None else np.hstack(ms))]


def merge_problems(layout: str, parts: list[np.ndarray], n_channels: int = 2) -> np.ndarray:
    """Inverse of :func:`split_problems`: assemble per-problem matrices.

    Parameters
    ----------
    layout : {"1D", "2x1D", "2D"}
    parts : list of ndarray
        One matrix per problem, shaped like the signals of :func:`split_problems`
        (e.g. their approximations ``D @ A``).
    n_channels : int

    Returns
    -------
    ndarray, shape (c·m·n, P)
    """
    layout = check_layout(layout)
    expected = n_channels if layout == "2x1D" else 1
    if len(parts) != expected:
        raise ValueError(f"parts: layout {layout} expects {expected} matrices, got {len(parts)}")
    if layout == "2D":
        return np.asarray(parts[0])
    if layout == "2x1D":
        return np.vstack(parts)
    x = np.asarray(parts[0])
    if x.ndim != 2 or x.shape[1] % n_channels:
        raise ValueError(f"parts: expected shape (m·n, {n_channels}·P), got {x.shape}")
    return np.vstack(np.hsplit(x, n_channels))


def dictionary_from_data(
    signals: np.ndarray,
    n_atoms: int,
    mask: np.ndarray | None = None,
    *,
    method: Literal["random", "largest"] = "random",
    seed: int | None = 0,
) -> np.ndarray:
    """Initial dictionary made of (normalised) training signals, e.g. for MOD.

    Only fully real signals (mask all True) with non-negligible norm are candidates.
    ``"random"`` takes a seeded random subset, ``"largest"`` the signals of largest
    norm.  If there are fewer candidates than atoms, the rest are seeded Gaussian
    random atoms.

    Parameters
    ----------
    signals : ndarray, shape (dim, P)
    n_atoms : int
    mask : ndarray of bool, shape (dim, P), optional
    method : {"random", "largest"}
    seed : int or None
        Seed of the local generator (``np.random.default_rng(seed)``).

    Returns
    -------
    ndarray, shape (dim, n_atoms), float32, unit-norm columns
    """
    y = np.asarray(signals)
    if y.ndim != 2 or y.shape[0] < 1:
        raise ValueError(f"signals: expected shape (dim, P), got {y.shape}")
    if n_atoms < 1:
        raise ValueError(f"n_atoms: must be >= 1, got {n_atoms}")
    if method not in ("random", "largest"):
        raise ValueError(f"method: expected 'random' or 'largest', got {method!r}")
    if mask is not None and np.shape(mask) != y.shape:
        raise ValueError(f"mask: expected shape {y.shape}, got {np.shape(mask)}")
    rng = np.random.default_rng(seed)
    norms = np.sqrt((y.astype(np.float64) ** 2).sum(axis=0))
    ok = norms > 1e-6 * max(float(norms.max(initial=0.0)), 1e-30)
    if mask is not None:
        ok &= np.asarray(mask, bool).all(axis=0)
    cand = np.flatnonzero(ok)
    if method == "largest":
        cand = cand[np.argsort(-norms[cand], kind="stable")][:n_atoms]
    else:
        cand = rng.permutation(cand)[:n_atoms]
    d = np.empty((y.shape[0], n_atoms), np.float64)
    d[:, : cand.size] = y[:, cand] / norms[cand]
    if cand.size < n_atoms:
        logger.info("dictionary_from_data: %d random atoms added", n_atoms - cand.size)
        d[:, cand.size :] = rng.standard_normal((y.shape[0], n_atoms - cand.size))
    return normalize_columns(d)[0]
