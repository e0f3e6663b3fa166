"""The method registries: plain dicts that the API, the CLI and the benchmarks read.

:data:`METHODS` maps a two-frame method name to a :class:`Method`: its frozen
parameter dataclass, its single-level warp solver (plugged into
:func:`varflow.twoframe.coarse_to_fine.coarse_to_fine`), a one-line description and,
for a method with stages around the driver (``tvl1-ld``), the function that runs it.
:data:`TRACKERS` maps a multi-frame (trajectory) method name to a :class:`Tracker`:
its parameter dataclass and its ``track(frames, ref, params, callback)`` function.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .multiframe import mfsf as _mfsf
from .multiframe import rlr as _rlr
from .multiframe import track as _track
from .twoframe import large_displacement as _ld
from .twoframe import sparse as _sparse
from .twoframe import tensor as _tensor
from .twoframe import tvl1 as _tvl1
from .twoframe.coarse_to_fine import CoarseToFineParams, WarpSolver

__all__ = [
    "Method",
    "METHODS",
    "Tracker",
    "TRACKERS",
    "get_method",
    "get_tracker",
    "make_params",
    "make_track_params",
]


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
}


@dataclass(frozen=True)
class Tracker:
    """A registered multi-frame (trajectory) method.

    Attributes
    ----------
    name : str
    params : type
        Frozen dataclass of its parameters.
    track : callable
        ``track(frames, ref, params, callback, stats=None) -> (F, H, W, 2)`` with
        ``frames`` as returned by :func:`varflow.multiframe.track.check_frames`;
        ``stats`` (a dict) may gain ``visible``, the ``(F, H, W)`` bool visibility
        when the method estimates it.
    description : str
    """

    name: str
    params: type
    track: Any
    description: str


TRACKERS: dict[str, Tracker] = {
    "rlr": Tracker(
        name="rlr",
        params=_rlr.RLRParams,
        track=_rlr.track_rlr,
        description="robust low-rank trajectories (data + TV_g + nuclear norm + L1 link)",
    ),
    "mfsf": Tracker(
        name="mfsf",
        params=_mfsf.MFSFParams,
        track=_mfsf.track_mfsf,
        description="multi-frame subspace flow (Garg et al.): soft constraint to a PCA/DCT "
        "trajectory basis",
    ),
    "twoframe": Tracker(
        name="twoframe",
        params=_track.TwoFrameTrackParams,
        track=_track.track_twoframe,
        description="independent TV-L1 flows from the reference to every frame",
    ),
    "chain": Tracker(
        name="chain",
        params=_track.ChainTrackParams,
        track=_track.track_chain,
        description="TV-L1 flows between consecutive frames, composed along the trajectory",
    ),
}


def get_tracker(name: str) -> Tracker:
    """Look a trajectory method up by name; unknown names raise ``ValueError``."""
    try:
        return TRACKERS[name]
    except KeyError:
        raise ValueError(
            f"method: unknown trajectory method {name!r}; available: {', '.join(TRACKERS)}"
        ) from None


def get_method(name: str) -> Method:
    """Look a method up by name; unknown names raise ``ValueError`` listing the choices."""
    try:
        return METHODS[name]
    except KeyError:
        raise ValueError(
            f"method: unknown method {name!r}; available: {', '.join(sorted(METHODS))}"
        ) from None


def make_params(method: str | Method, params: Any = None, **overrides: Any) -> CoarseToFineParams:
    """Build a method's parameter object from defaults, an existing object and overrides.

    Raises
    ------
    ValueError
        For an unknown field name (named in the message) or an invalid value.
    """
    m = get_method(method) if isinstance(method, str) else method
    return _make(m, params, **overrides)


def make_track_params(method: str | Tracker, params: Any = None, **overrides: Any) -> Any:
    """:func:`make_params` for a trajectory method of :data:`TRACKERS`."""
    m = get_tracker(method) if isinstance(method, str) else method
    return _make(m, params, **overrides)


def _make(m: Method | Tracker, params: Any, **overrides: Any) -> Any:
    base = params if params is not None else m.params()
    if not isinstance(base, m.params):
        raise ValueError(f"params: expected {m.params.__name__}, got {type(base).__name__}")
    names = {f.name for f in dataclasses.fields(m.params)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ValueError(
            f"{unknown[0]}: not a parameter of method {m.name!r} "
            f"(valid: {', '.join(sorted(names))})"
        )
    return dataclasses.replace(base, **overrides) if overrides else base
