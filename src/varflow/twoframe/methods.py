"""The two-frame flow methods, registered in :data:`varflow.registry.FLOW`.

Each :class:`~varflow.registry.Method` names a preset of
:class:`~varflow.twoframe.params.TVL1Params` (:data:`~varflow.twoframe.params.PRESETS`),
its single-level warp solver (plugged into
:func:`varflow.twoframe.coarse_to_fine.coarse_to_fine`), a one-line description, its
memory model and kernels and, for a method with stages around the driver
(``tvl1-ld``), the function that runs it.  :func:`run_method` runs one, as
:func:`varflow.flow` does; :class:`FlowComposed` serves the parameter classes of the
methods built on a two-frame method (trackers, interpolators).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from .._validate import check_field
from ..parameters import Routed
from ..registry import DEFAULT_METHOD, FLOW, MemoryFactors, Method
from . import large_displacement as _ld
from . import sparse as _sparse
from . import tensor as _tensor
from . import tvl1 as _tvl1
from .coarse_to_fine import ProgressCallback, coarse_to_fine
from .params import PRESETS, TVL1Params

__all__ = ["DEFAULT_METHOD", "Method", "METHODS", "FlowChoice", "get_method", "run_method",
           "FlowComposed"]

METHODS = FLOW

_MIB = 2**20
_TVL1 = ("varflow.twoframe.tvl1:tvl1_iterations",)
_WMEDIAN = ("varflow.ops.median:_weighted_median_kernel",)
_SPARSE = ("varflow.twoframe.sparse:nesterov_iterations", "varflow.sparse.omp:_batch_omp_kernel")


def _preset(name: str):
    return lambda: PRESETS[name]


def _register(name: str, solve_warp: Any, description: str, memory: MemoryFactors,
              kernels: tuple[str, ...], compile_seconds: int, run: Any = None) -> None:
    use, knobs = _USE[name]
    FLOW.register(Method(name=name, description=description, defaults=_preset(name),
                         memory=memory, kernels=kernels, compile_seconds=compile_seconds,
                         solve_warp=solve_warp, run=run, use=use, knobs=knobs))


_DATA = ("data_weight", "λ: higher follows the images more closely (sharper edges, more "
         "noise), lower gives smoother flow")
_WARPS = ("n_warps", "re-linearisations per pyramid level: more for large or non-linear "
          "motion, fewer for speed")
_GREY = ("grey", "--no-grey uses every colour channel: for scenes whose parts differ in "
         "colour but not in brightness")
_SPARSE_KNOBS = (_DATA, ("sparse_weight", "λ_SP: how strongly the flow must be a few "
                         "dictionary patches; higher gives simpler motion"),
                 ("patch_size", "side of the flow patches, pixels: larger for smoother motion"))
_TENSOR_KNOBS = (_DATA, ("tensor_a", "smoothing across image edges: higher keeps motion "
                         "boundaries on edges sharper; 0 is isotropic TV"))
_USE: dict[str, tuple[str, tuple[tuple[str, str], ...]]] = {
    "tvl1": ("the default: accurate flow for small and medium motion", (_DATA, _WARPS, _GREY)),
    "tvl1-fast": ("previews and long clips: about twice as fast as tvl1, a little less "
                  "accurate", (_DATA, _WARPS)),
    "tvl1-ld": ("large or fast motion (things moving farther than their own size, low frame "
                "rates): adds patch matching",
                (_DATA, ("match_max_displacement", "largest motion searched, pixels: raise it "
                         "for motion beyond it"), _WARPS)),
    "tensor": ("thin or oriented structure (fibres, vessels, text) on the book's energy; "
               "tvl1-tensor is usually better", _TENSOR_KNOBS),
    "sparse-dct": ("research: the book's sparse regulariser with a fixed dictionary; slow",
                   _SPARSE_KNOBS),
    "sparse-1d": ("research: the book's sparse regulariser, one learned dictionary; slow",
                  _SPARSE_KNOBS),
    "sparse-2x1d": ("research: the book's sparse regulariser, a dictionary per component; "
                    "slow", _SPARSE_KNOBS),
    "sparse-2d": ("research: the book's sparse regulariser, joint (u, v) patches; slow",
                  _SPARSE_KNOBS),
    "tvl1-tensor": ("thin or oriented structure (fibres, vessels, text), with tvl1's "
                    "robustness", _TENSOR_KNOBS),
    "tvl1-sparse-dct": ("sparse regularisation with a fixed dictionary, with tvl1's "
                        "robustness; slow", _SPARSE_KNOBS),
    "tvl1-sparse-1d": ("sparse regularisation with one learned dictionary, with tvl1's "
                       "robustness; slow", _SPARSE_KNOBS),
    "tvl1-sparse-2x1d": ("sparse regularisation with a dictionary per component, with "
                         "tvl1's robustness; slow", _SPARSE_KNOBS),
    "tvl1-sparse-2d": ("sparse regularisation of joint (u, v) patches, with tvl1's "
                       "robustness; slow", _SPARSE_KNOBS),
}


# Memory factors: bytes per pixel measured by benchmarks/bench_memory.py (varflow._memory).
_register("tvl1", _tvl1.solve_warp,
          "TV-L1 (grey L1 + gradient-constancy data terms, edge-weighted Huber-TV, "
          "ROF texture, median)",
          MemoryFactors(base=205, per_channel=10), _TVL1 + _WMEDIAN, 20)
_register("tvl1-fast", _tvl1.solve_warp,
          "TV-L1 preview preset (pyramid ratio 0.5, 3 warps, 30 iterations)",
          MemoryFactors(base=170, per_channel=15), _TVL1, 35)
_register("tvl1-ld", _tvl1.solve_warp,
          "TV-L1 for large displacements (PatchMatch matches, edge-aware interpolation, "
          "fused per level)",
          MemoryFactors(base=490, per_channel=25),
          _TVL1 + ("varflow.ops.matching:_patchmatch_pair",
                   "varflow.ops.interpolation:_fit_kernel"), 60, run=_ld.tvl1_ld)
_register("tensor", _tensor.solve_warp,
          "tensor-directed TV-L1 (anisotropic TV following image structure)",
          MemoryFactors(base=205, per_channel=60), _TVL1, 35)
_register("sparse-dct", _sparse.solve_warp,
          "sparse-regularised TV-L1, fixed overcomplete DCT dictionary",
          MemoryFactors(base=280, per_channel=50, fixed=10 * _MIB), _SPARSE, 60)
_register("sparse-1d", _sparse.solve_warp,
          "sparse-regularised TV-L1, MOD dictionary shared by u and v",
          MemoryFactors(base=285, per_channel=65, fixed=11 * _MIB), _SPARSE, 60)
_register("sparse-2x1d", _sparse.solve_warp,
          "sparse-regularised TV-L1, MOD dictionaries for u and for v",
          MemoryFactors(base=275, per_channel=70), _SPARSE, 60)
_register("sparse-2d", _sparse.solve_warp,
          "sparse-regularised TV-L1, MOD dictionary of joint [u; v] patches",
          MemoryFactors(base=325, per_channel=55, fixed=3 * _MIB), _SPARSE, 60)
# the same regularisers on tvl1's energy (grey L1 + gradient constancy, Huber-TV,
# noise rule, weighted median, sharpness match); the ones above keep the book's
_register("tvl1-tensor", _tensor.solve_warp, "tensor-directed TV-L1 on tvl1's energy",
          MemoryFactors(base=250), _TVL1 + _WMEDIAN, 40)
_register("tvl1-sparse-dct", _sparse.solve_warp,
          "sparse-regularised TV-L1 on tvl1's energy, fixed overcomplete DCT dictionary",
          MemoryFactors(base=340, per_channel=5, fixed=7 * _MIB), _SPARSE + _WMEDIAN, 65)
_register("tvl1-sparse-1d", _sparse.solve_warp,
          "sparse-regularised TV-L1 on tvl1's energy, MOD dictionary shared by u and v",
          MemoryFactors(base=335, per_channel=5, fixed=10 * _MIB), _SPARSE + _WMEDIAN, 65)
_register("tvl1-sparse-2x1d", _sparse.solve_warp,
          "sparse-regularised TV-L1 on tvl1's energy, MOD dictionaries for u and for v",
          MemoryFactors(base=305, per_channel=15, fixed=2 * _MIB), _SPARSE + _WMEDIAN, 65)
_register("tvl1-sparse-2d", _sparse.solve_warp,
          "sparse-regularised TV-L1 on tvl1's energy, MOD dictionary of joint [u; v] "
          "patches",
          MemoryFactors(base=360, fixed=5 * _MIB), _SPARSE + _WMEDIAN, 65)


def get_method(name: str) -> Method:
    """Look a method up by name; unknown names raise ``ValueError`` listing the choices."""
    return FLOW.entry(name)


class FlowChoice(Protocol):
    """The parameters of a method built on a two-frame method: its name and parameters."""

    flow_method: str
    flow_params: TVL1Params


class FlowComposed(Routed):
    """Mixin of a parameter dataclass built on a two-frame method, which declares the
    fields ``flow_method`` (a name of :data:`FLOW`) and ``flow_params``.

    ``flow_params`` is composed (flat names of the energy are routed to it); a new
    ``flow_method`` without ``flow_params`` starts from :meth:`default_flow_params`;
    ``__post_init__`` fills ``flow_params`` None with those defaults and checks that it
    suits the method (its preset's terms), raising ``ValueError`` naming
    ``flow_method`` or ``flow_params``.  A subclass with checks of its own calls
    ``super().__post_init__()`` first.
    """

    __slots__ = ()

    _COMPOSED = ("flow_params",)
    _DEPENDENT = {"flow_method": "flow_params"}

    @classmethod
    def default_flow_params(cls, flow_method: str) -> TVL1Params:
        """The ``flow_params`` of a ``flow_method`` named without them: its defaults (a
        class may choose others)."""
        return FLOW[flow_method].defaults()

    def __post_init__(self) -> None:
        method = FLOW.get(self.flow_method) if isinstance(self.flow_method, str) else None
        check_field(method is not None, "flow_method",
                    f"unknown two-frame method {self.flow_method!r}; available: "
                    f"{', '.join(FLOW.names())}")
        if self.flow_params is None:
            object.__setattr__(self, "flow_params",
                               type(self).default_flow_params(self.flow_method))
        try:
            method.check_params(self.flow_params)
        except ValueError as exc:
            raise ValueError(f"flow_params: {str(exc).removeprefix('params: ')}") from None


def run_method(
    method: Method,
    frame0: np.ndarray,
    frame1: np.ndarray,
    params: TVL1Params,
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
    params : TVL1Params
        The method's parameters (:meth:`varflow.registry.Registry.make_params`).
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
