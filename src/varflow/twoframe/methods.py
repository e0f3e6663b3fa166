"""The registry of two-frame methods: a plain dict that the trackers, the API, the CLI and the
benchmarks read (re-exported by :mod:`varflow.registry`).

:data:`METHODS` maps a two-frame method name to a :class:`Method`: its frozen
parameter dataclass, its single-level warp solver (plugged into
:func:`varflow.twoframe.coarse_to_fine.coarse_to_fine`), a one-line description and,
for a method with stages around the driver (``tvl1-ld``), the function that runs it.
:func:`run_method` runs one, as :func:`varflow.flow` does.  It lives in the
two-frame package so that the multi-frame methods, which build on any two-frame
method, can use it without importing :mod:`varflow.registry` (which lists them).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import large_displacement as _ld
from . import sparse as _sparse
from . import tensor as _tensor
from . import tvl1 as _tvl1
from .coarse_to_fine import CoarseToFineParams, ProgressCallback, WarpSolver, coarse_to_fine

__all__ = ["DEFAULT_METHOD", "Method", "METHODS", "get_method", "run_method"]

#: The method of :func:`varflow.flow` when none is named, and of the trackers built on
#: two-frame flows (``twoframe``, ``chain``).
DEFAULT_METHOD = "tvl1"


@dataclass(frozen=True)
class Method:
    """A registered two-frame method.

    Attributes
    ----------
    name : str
    params : type
        Frozen dataclass of its parameters (a :class:`CoarseToFineParams` subclass).
    solve_warp : callable
        Single-level, single-warp solver.
    description : str
    run : callable, optional
        ``run(frame0, frame1, params, init_flow=None, callback=None, stats=None)``
        for a method whose pipeline has stages around the coarse-to-fine driver
        (which it calls with ``solve_warp``); None: the driver alone.
    """

    name: str
    params: type[CoarseToFineParams]
    solve_warp: WarpSolver
    description: str
    run: Callable[..., Any] | None = None


METHODS: dict[str, Method] = {
    "tvl1": Method(
        name="tvl1",
        params=_tvl1.TVL1Params,
        solve_warp=_tvl1.solve_warp,
        description="TV-L1 (grey L1 + gradient-constancy data terms, edge-weighted Huber-TV, "
        "ROF texture, median)",
    ),
    "tvl1-fast": Method(
        name="tvl1-fast",
        params=_tvl1.TVL1FastParams,
        solve_warp=_tvl1.solve_warp,
        description="TV-L1 preview preset (pyramid ratio 0.5, 3 warps, 30 iterations)",
    ),
    "tvl1-ld": Method(
        name="tvl1-ld",
        params=_ld.LargeDisplacementParams,
        solve_warp=_tvl1.solve_warp,
        description="TV-L1 for large displacements (PatchMatch matches, edge-aware "
        "interpolation, fused per level)",
        run=_ld.tvl1_ld,
    ),
    "tensor": Method(
        name="tensor",
        params=_tensor.TensorParams,
        solve_warp=_tensor.solve_warp,
        description="tensor-directed TV-L1 (anisotropic TV following image structure)",
    ),
    "sparse-dct": Method(
        name="sparse-dct",
        params=_sparse.SparseDCTParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1, fixed overcomplete DCT dictionary",
    ),
    "sparse-1d": Method(
        name="sparse-1d",
        params=_sparse.Sparse1DParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1, MOD dictionary shared by u and v",
    ),
    "sparse-2x1d": Method(
        name="sparse-2x1d",
        params=_sparse.Sparse2x1DParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1, MOD dictionaries for u and for v",
    ),
    "sparse-2d": Method(
        name="sparse-2d",
        params=_sparse.Sparse2DParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1, MOD dictionary of joint [u; v] patches",
    ),
    # the same regularisers on tvl1's energy (grey L1 + gradient constancy, Huber-TV,
    # noise rule, weighted median, sharpness match); the ones above keep the book's
    "tvl1-tensor": Method(
        name="tvl1-tensor",
        params=_tensor.TVL1TensorParams,
        solve_warp=_tensor.solve_warp,
        description="tensor-directed TV-L1 on tvl1's energy",
    ),
    "tvl1-sparse-dct": Method(
        name="tvl1-sparse-dct",
        params=_sparse.TVL1SparseDCTParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1 on tvl1's energy, fixed overcomplete DCT "
        "dictionary",
    ),
    "tvl1-sparse-1d": Method(
        name="tvl1-sparse-1d",
        params=_sparse.TVL1Sparse1DParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1 on tvl1's energy, MOD dictionary shared by u "
        "and v",
    ),
    "tvl1-sparse-2x1d": Method(
        name="tvl1-sparse-2x1d",
        params=_sparse.TVL1Sparse2x1DParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1 on tvl1's energy, MOD dictionaries for u and "
        "for v",
    ),
    "tvl1-sparse-2d": Method(
        name="tvl1-sparse-2d",
        params=_sparse.TVL1Sparse2DParams,
        solve_warp=_sparse.solve_warp,
        description="sparse-regularised TV-L1 on tvl1's energy, MOD dictionary of joint "
        "[u; v] patches",
    ),
}


def get_method(name: str) -> Method:
    """Look a method up by name; unknown names raise ``ValueError`` listing the choices."""
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(
            f"method: unknown method {name!r}; available: {', '.join(sorted(METHODS))}"
        ) from None


def run_method(
    method: Method,
    frame0: np.ndarray,
    frame1: np.ndarray,
    params: CoarseToFineParams,
    init_flow: np.ndarray | None = None,
    callback: ProgressCallback | None = None,
    stats: dict | None = None,
) -> np.ndarray:
    """Run a registered method with resolved parameters: the body of :func:`varflow.flow`.

    Parameters
    ----------
    method : Method
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        As for :func:`varflow.flow`.
    params : CoarseToFineParams
        An instance of ``method.params``.
    init_flow, callback, stats
        As for :func:`varflow.flow`.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    if method.run is not None:  # a pipeline with stages around the driver (tvl1-ld)
        return method.run(frame0, frame1, params, init_flow=init_flow, callback=callback,
                          stats=stats)
    return coarse_to_fine(frame0, frame1, method.solve_warp, params, init_flow=init_flow,
                          callback=callback, stats=stats)
