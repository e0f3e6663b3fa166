"""Sparse-coding building blocks of the sparse-regularised flow model.

Jia, Wang & Tang (ICCV 2011); Gibson & Marques (2016), ch. 3: patches of the flow on
an offset-k grid (:class:`PatchGrid`) are coded over a dictionary (overcomplete DCT or
learned by MOD, :func:`learn_mod`) with orthogonal matching pursuit (:func:`omp`).

Conventions: float32 data; patch matrices are ``(c·m·n, P)`` with one vectorised patch
per column (channel-major, row-major inside the patch); codes are ``(K, P)``
``scipy.sparse.csc_array``; masks are bool arrays, False on apron (padding) entries.
"""

from .dictionaries import (
    LAYOUTS,
    Layout,
    check_layout,
    dct_dictionary,
    dictionary_from_data,
    layout_atom_dim,
    layout_dct,
    merge_problems,
    normalize_columns,
    split_problems,
)
from .mod import MODResult, learn_mod
from .omp import omp, omp_numpy, reconstruct, residual_energy
from .patches import PatchGrid

__all__ = [
    "LAYOUTS",
    "Layout",
    "MODResult",
    "PatchGrid",
    "check_layout",
    "dct_dictionary",
    "dictionary_from_data",
    "layout_atom_dim",
    "layout_dct",
    "learn_mod",
    "merge_problems",
    "normalize_columns",
    "omp",
    "omp_numpy",
    "reconstruct",
    "residual_energy",
    "split_problems",
]
