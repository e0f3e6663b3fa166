"""The frame-interpolation methods, registered in :data:`varflow.registry.INTERPOLATE`,
and :func:`interpolate`.

Each :class:`~varflow.registry.Interpolator` names its parameter defaults, its
``prepare`` function, a one-line description and how many neighbouring frames it
can use.
``prepare`` estimates the motion of a pair once and returns a :class:`PairMotion`;
its ``render(t)`` synthesises the frame at any time ``t`` in ``(0, 1)`` from it.
:func:`interpolate` (re-exported as :func:`varflow.interpolate`) runs one.

Frames are synthesised as float32: uint8 / uint16 frames divided by 255 / 65535
(as :func:`varflow.flow` reads them), float frames as they are; the result goes
back to the input's dtype and units, and ``t = 0`` and ``t = 1`` return the inputs
exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import check_field
from ..registry import DEFAULT_METHOD, INTERPOLATE, Interpolator
from ..twoframe.coarse_to_fine import ProgressCallback
from ..twoframe.methods import FlowComposed
from ..twoframe.params import TVL1Params
from .motion import FlowCache, PairMotion, bidirectional_flows
from .splatting import SplatParams, prepare_splat, splat_fast_defaults

__all__ = [
    "DEFAULT_INTERPOLATOR",
    "INTERPOLATORS",
    "Interpolator",
    "NaiveParams",
    "PairMotion",
    "check_times",
    "get_interpolator",
    "interpolate",
    "make_interp_params",
]


# --------------------------------------------------------------------------- naive


@dataclass(frozen=True)
class NaiveParams(FlowComposed):
    """Parameters of ``naive``: the simple way to interpolate with varflow's flow.

    The default :func:`varflow.flow` both ways, the flows at time t approximated
    linearly, ``F_t→0 ≈ −t(1−t) F01 + t² F10`` and ``F_t→1 ≈ (1−t)² F01 − t(1−t) F10``
    (Jiang et al. 2018, Super SloMo, eq. 4), both frames warped backwards
    (bilinear) and blended with weights ``1−t`` and ``t``.  The baseline that the
    other methods must beat.

    Attributes
    ----------
    flow_method : str
        The two-frame method (default that of :func:`varflow.flow`).
    flow_params : TVL1Params or None
        Its parameters (None: its defaults).
    """

    flow_method: str = DEFAULT_METHOD
    flow_params: TVL1Params | None = None


class _NaiveMotion(PairMotion):
    def __init__(self, frame0: np.ndarray, frame1: np.ndarray, f01: np.ndarray,
                 f10: np.ndarray) -> None:
        super().__init__(frame0, frame1)
        self.f01 = f01
        self.f10 = f10

    def render(self, t: float) -> np.ndarray:
        from ..ops.warp import warp_bilinear

        t = np.float32(t)
        ft0 = -t * (1 - t) * self.f01 + t * t * self.f10
        ft1 = (1 - t) * (1 - t) * self.f01 - t * (1 - t) * self.f10
        w0, _ = warp_bilinear(self.frame0, ft0)
        w1, _ = warp_bilinear(self.frame1, ft1)
        return (1 - t) * w0 + t * w1


def _prepare_naive(frame0: np.ndarray, frame1: np.ndarray, params: NaiveParams,
                   previous: np.ndarray | None = None, following: np.ndarray | None = None,
                   callback: ProgressCallback | None = None, stats: dict | None = None,
                   cache: FlowCache | None = None) -> PairMotion:
    f01, f10 = bidirectional_flows(frame0, frame1, params, callback, stats, cache)
    return _NaiveMotion(frame0, frame1, f01, f10)


# --------------------------------------------------------------------------- registry

INTERPOLATORS = INTERPOLATE

_FLOW_KNOB = ("flow_method",
              "the two-frame method of the flows: tvl1-ld for fast motion, tvl1-fast for "
              "speed")
_PIXELS_KNOB = ("flow_max_pixels",
                "frames larger than this many pixels get their flows on a reduced copy: "
                "lower is faster; 0 never")

# Memory: estimated as the flows' method on the pair (varflow._memory); kernels: the
# flows' and the splatting's.
INTERPOLATE.register(Interpolator(
    name="naive",
    description="varflow.flow both ways, linear flows at time t, backward warps blended by "
    "time (the simple baseline)",
    defaults=NaiveParams,
    kernels=("varflow.twoframe.tvl1:tvl1_iterations",),
    use="the simple baseline, for comparisons: ghosts where things appear or disappear",
    knobs=(_FLOW_KNOB,),
    prepare=_prepare_naive,
))
INTERPOLATE.register(Interpolator(
    name="splat",
    description="flows both ways, splatted to time t (softmax z-buffer, holes filled "
    "outside in), occlusion-aware bicubic blend (Baker et al. 2011); quadratic "
    "trajectories from the neighbouring frames when given (Xu et al. 2019)",
    defaults=SplatParams,
    kernels=("varflow.twoframe.tvl1:tvl1_iterations",),
    use="the best quality: slow motion and frame-rate conversion",
    knobs=(_FLOW_KNOB, _PIXELS_KNOB),
    prepare=prepare_splat,
    context=1,
))
INTERPOLATE.register(Interpolator(
    name="splat-fast",
    description="splat on tvl1-fast flows of frames reduced to at most 150 000 pixels "
    "(within 3x of minterpolate's time)",
    defaults=splat_fast_defaults,
    kernels=("varflow.twoframe.tvl1:tvl1_iterations",),
    use="previews and long videos: several times faster than splat, within 3x of "
    "minterpolate's time",
    knobs=(_PIXELS_KNOB,),
    prepare=prepare_splat,
    context=1,
))

#: The method of :func:`interpolate` when none is named.
DEFAULT_INTERPOLATOR = INTERPOLATE.default


def get_interpolator(name: str) -> Interpolator:
    """``INTERPOLATE.entry(name)``: an interpolation method by name (``ValueError`` if
    unknown)."""
    return INTERPOLATE.entry(name)


def make_interp_params(method: str | Interpolator, params: Any = None,
                       **overrides: Any) -> Any:
    """``INTERPOLATE.make_params``: an interpolation method's parameters
    (:meth:`varflow.registry.Registry.make_params`)."""
    return INTERPOLATE.make_params(method, params, **overrides)


def check_times(t: Any) -> tuple[list[float], bool]:
    """Validate ``t``: a number or a sequence of numbers in [0, 1].

    Returns
    -------
    times : list of float
    scalar : bool
        Was ``t`` a single number?
    """
    scalar = np.ndim(t) == 0
    try:
        arr = np.asarray(t, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"t: expected a number or a sequence of numbers, got {t!r}") from None
    check_field(arr.size > 0, "t", "expected at least one time")
    check_field(bool(np.all(np.isfinite(arr))), "t", f"times must be finite, got {t!r}")
    check_field(bool(np.all((arr >= 0) & (arr <= 1))), "t",
                f"times must lie in [0, 1], got {t!r}")
    return [float(x) for x in arr], scalar


def _working(frame: Any, name: str) -> np.ndarray:
    """A frame as (H, W, C) float32: uint8 / uint16 divided by 255 / 65535, floats as
    they are."""
    a = np.asarray(frame)
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (1, 3, 4)):
        raise ValueError(f"{name}: expected shape (H, W) or (H, W, C) with C in 1, 3, 4, "
                         f"got {a.shape}")
    if min(a.shape[:2]) < 3:  # what the flow methods take
        raise ValueError(f"{name}: image too small, shape {a.shape} (at least 3 x 3)")
    if not (a.dtype in (np.uint8, np.uint16) or np.issubdtype(a.dtype, np.floating)):
        raise ValueError(f"{name}: unsupported dtype {a.dtype} (uint8, uint16 or float)")
    f = a.astype(np.float32)
    if a.dtype in (np.uint8, np.uint16):
        f /= np.float32(np.iinfo(a.dtype).max)
    if np.issubdtype(a.dtype, np.floating) and not np.all(np.isfinite(f)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return np.ascontiguousarray(f if f.ndim == 3 else f[..., None])


def _restore(frame: np.ndarray, like: np.ndarray) -> np.ndarray:
    """``frame`` (H, W, C) float32 of :func:`_working` back to ``like``'s dtype and shape."""
    out = frame if like.ndim == 3 else frame[..., 0]
    if like.dtype in (np.uint8, np.uint16):
        top = np.iinfo(like.dtype).max
        return np.clip(np.rint(out * np.float32(top)), 0, top).astype(like.dtype)
    return out.astype(like.dtype)


def interpolate(
    frame0: np.ndarray,
    frame1: np.ndarray,
    t: float | Sequence[float] = 0.5,
    method: str | None = None,
    *,
    params: Any = None,
    previous: np.ndarray | None = None,
    following: np.ndarray | None = None,
    callback: ProgressCallback | None = None,
    stats: dict | None = None,
    flow_cache: FlowCache | None = None,
    **overrides: Any,
) -> np.ndarray:
    """The frame (or frames) at time ``t`` between ``frame0`` (t = 0) and ``frame1`` (t = 1).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float (finite), of one shape and dtype; C in 1, 3, 4.
    t : float or sequence of float
        Time(s) in [0, 1].  ``t = 0`` and ``t = 1`` return copies of the inputs
        exactly.  The motion is estimated once for all the times.
    method : str, optional
        A name of :data:`INTERPOLATORS` (default :data:`DEFAULT_INTERPOLATOR`).
    params : dataclass, optional
        A parameter object of the method.
    previous, following : ndarray, optional
        The frames before ``frame0`` and after ``frame1`` (same shape and dtype), for
        methods that use more than two frames; ignored by the others.
    callback : callable, optional
        ``callback(done, total)`` as the motion is estimated.
    stats : dict, optional
        Filled with counters of the run (``flows`` estimated, ``cached_flows``).
    flow_cache : FlowCache, optional
        Flows are looked up in it and stored there (a stream of pairs shares
        flows between neighbouring pairs).
    **overrides
        Parameter fields to change (for methods built on a two-frame method, its
        fields too, e.g. ``data_weight=30.0``).

    Returns
    -------
    ndarray
        Shape and dtype of ``frame0``; for a sequence ``t``, a stack
        ``(len(t),) + frame0.shape``.  Integer frames are rounded and clipped.

    Raises
    ------
    ValueError
        Unknown method or parameter, invalid value, bad frames or times.

    References
    ----------
    Baker, Scharstein, Lewis, Roth, Black & Szeliski (2011), "A Database and
    Evaluation Methodology for Optical Flow", IJCV 92, section 3 (interpolation).
    """
    m = get_interpolator(DEFAULT_INTERPOLATOR if method is None else method)
    p = make_interp_params(m, params, **overrides)
    times, scalar = check_times(t)
    a0, a1 = np.asarray(frame0), np.asarray(frame1)
    w0, w1 = _working(a0, "frame0"), _working(a1, "frame1")
    if a0.shape != a1.shape:
        raise ValueError(f"frame1: shape {a1.shape} differs from frame0 {a0.shape}")
    if a0.dtype != a1.dtype:
        raise ValueError(f"frame1: dtype {a1.dtype} differs from frame0 {a0.dtype}")
    ctx = []
    for name, f in (("previous", previous), ("following", following)):
        if f is None:
            ctx.append(None)
            continue
        a = np.asarray(f)
        if a.shape != a0.shape or a.dtype != a0.dtype:
            raise ValueError(f"{name}: shape {a.shape} / dtype {a.dtype} differ from frame0's "
                             f"{a0.shape} / {a0.dtype}")
        ctx.append(_working(a, name))
    motion = None
    out = []
    for x in times:
        if x == 0.0:
            out.append(a0.copy())
        elif x == 1.0:
            out.append(a1.copy())
        else:
            if motion is None:
                motion = m.prepare(w0, w1, p, previous=ctx[0], following=ctx[1],
                                   callback=callback, stats=stats, cache=flow_cache)
            out.append(_restore(motion.render(x), a0))
    return out[0] if scalar else np.stack(out)
