"""The one coarse-to-fine driver that every two-frame method uses.

It owns everything that is not the single-level optimisation: conversion of the
inputs, structure-texture pre-processing, the image pyramid, the warping of the
second frame (bicubic, with an inside-the-image mask), the median filter after
each warp (plain, and weighted near motion boundaries after a level's last warp),
and the upsampling of the flow between levels.  A method plugs in a *warp solver*::

    solve_warp(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params, state) -> flow

that minimises its energy linearised around ``flow0`` at one pyramid level;
``state`` is the :class:`LevelState` that lives for one level: the driver's
``level``, ``warp`` (the index of the current warp, ``params.level_warps(shape)``
warps per level) and ``previous`` (the coarser level's state), and ``data``, which
the solver owns (its dual variables, edge weights…; ``state.previous.data`` warm
starts them across levels).  A solver whose kernels work on planar data sets the
attribute ``solve_warp.planar_flow = True``: the driver then keeps the flows in planar
memory and ``flow0`` is a ``(H, W, 2)`` view of it, which the solver and the filters
read without transposing (:func:`run_levels`, ``planar``).

The level and warp loop itself is :func:`run_levels`: it carries a stack of flows
through the levels (upsampling between them), calls a per-level set-up and a
per-warp step, and filters every flow after each warp.  The two-frame driver runs it
on one flow; the multi-frame refinement of :mod:`varflow.multiframe.refine` (RLR
and MFSF) on the ``F`` displacement fields of a clip, with its own warp step (the
coupled U-step) and typed level state.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from .._validate import check_field, check_pair
from ..ops.differences import derivative_planes
from ..ops.fusion import noise_sigma_flat
from ..ops.median import median_filter_flow, weighted_median_flow
from ..ops.pyramid import build_pyramid, pyramid_shapes, resize_flow
from ..ops.rof import structure_texture
from ..ops.sharpness import match_sharpness
from ..ops.warp import warp_bicubic
from .params import TVL1Params

#: The driver's parameters are those of the TV-L1 energy (its pyramid, warping,
#: pre-processing and filter fields); the name is kept for code written against it.
CoarseToFineParams = TVL1Params

__all__ = [
    "CoarseToFineParams",
    "LevelState",
    "WarpSolver",
    "run_levels",
    "coarse_to_fine",
    "coarse_to_fine_pyramids",
    "prepare_pyramid",
    "working_channels",
    "filter_flow",
    "guide_pyramid",
    "noise_adapted",
    "ProgressCallback",
    "LevelHook",
    "LevelStart",
    "WarpStep",
]

log = logging.getLogger(__name__)

ProgressCallback = Callable[[int, int], None]

#: ``level_hook(level, i0, i1, flow, stats) -> flow``: called at the start of every
#: pyramid level, before its first warp, with the level's pre-processed frames
#: ``(h, w, C)`` and the flow carried from the coarser level ``(h, w, 2)`` (in this
#: level's pixels); it returns the flow the level starts from (e.g. fused with a
#: candidate from feature matching, see :mod:`varflow.twoframe.large_displacement`).
LevelHook = Callable[[int, np.ndarray, np.ndarray, np.ndarray, dict], np.ndarray]


_check = check_field  # the twoframe modules' short name


@dataclass
class LevelState:
    """What the driver keeps for one pyramid level (a new one per level).

    The driver sets ``level``, ``warp``, ``previous`` and ``stats``; ``data`` is the
    solver's own state of the level (e.g. :class:`varflow.twoframe.tvl1.TVL1State`),
    which the solver creates on the level's first warp and the driver never reads.

    Attributes
    ----------
    level : int
        Pyramid level, 0 = finest.
    stats : dict
        The run's statistics (the ``stats`` of :func:`coarse_to_fine`), for a
        solver to record counters and seconds in.
    previous : LevelState or None
        The coarser level's state (its own ``previous`` dropped), for warm starts.
    warp : int
        Index of the current warp at this level.
    data : object or None
        The solver's state of this level.
    """

    level: int = 0
    stats: dict = dataclasses.field(default_factory=dict)
    previous: LevelState | None = None
    warp: int = 0
    data: Any = None


class WarpSolver(Protocol):
    def __call__(
        self,
        I0: np.ndarray,
        I1w: np.ndarray,
        I1w_dx: np.ndarray,
        I1w_dy: np.ndarray,
        inside: np.ndarray,
        flow0: np.ndarray,
        params: Any,
        state: LevelState,
    ) -> np.ndarray: ...


def working_channels(image: np.ndarray, params: TVL1Params) -> np.ndarray:
    """The channels a method works on: the frame itself, or with ``params.grey`` the
    mean of its channels, ``(H, W, 1)`` float32 (a one-channel frame is returned as is).
    """
    if not params.grey or image.shape[2] == 1:
        return image
    return np.mean(image, axis=2, keepdims=True, dtype=np.float32)


def preprocess(image: np.ndarray, params: TVL1Params) -> np.ndarray:
    """Apply the configured pre-processing to an ``(H, W, C)`` float image."""
    if params.structure_texture:
        return structure_texture(
            image, alpha=params.texture_alpha, theta=params.rof_theta, n_iter=params.rof_iterations
        )
    return image


def prepare_pyramid(frame: np.ndarray, params: TVL1Params,
                    shapes: list[tuple[int, int]] | None = None) -> list[np.ndarray]:
    """Pre-process one ``(H, W, C)`` float frame and build its pyramid (finest first).

    With ``params.grey`` the frame is first reduced to the mean of its channels.

    The inputs of :func:`coarse_to_fine_pyramids`; a multi-frame method builds each
    frame's pyramid once and pairs it with several others.

    Parameters
    ----------
    frame : ndarray, shape (H, W, C), float32 in [0, 1]
    params : TVL1Params
    shapes : list of (int, int), optional
        Level shapes; default :func:`varflow.ops.pyramid.pyramid_shapes` of ``params``.

    Returns
    -------
    list of ndarray, each (h, w, C) float32 (C = 1 with ``params.grey``)
    """
    frame = working_channels(frame, params)
    if shapes is None:
        shapes = pyramid_shapes(frame.shape[:2], params.max_levels, params.scale_factor,
                                params.min_size)
    return build_pyramid(preprocess(frame, params), shapes, params.scale_factor,
                         params.pyramid_sigma)


def filter_flow(flow: np.ndarray, params: TVL1Params,
                guide: np.ndarray | None, last_warp: bool = True, level: int = 0) -> np.ndarray:
    """The filtering of the flow after a warp: the plain median (``median_size``),
    and with ``weighted_median_radius`` > 0 the weighted median near motion
    boundaries, guided by ``guide`` ``(h, w, C)``, after a level's last warp
    (``last_warp``) or every warp, on pyramid level ``level`` (0 = finest) if
    it is one of the ``weighted_median_levels`` finest (see :class:`TVL1Params`).

    Returns ``flow`` itself when both are off.
    """
    out = median_filter_flow(flow, params.median_size) if params.median_size > 1 else flow
    in_levels = params.weighted_median_levels == 0 or level < params.weighted_median_levels
    if (params.weighted_median_radius > 0 and guide is not None and in_levels
            and (last_warp or params.weighted_median_every_warp)):
        out = weighted_median_flow(
            flow, guide, params.weighted_median_radius, params.weighted_median_sigma_space,
            params.weighted_median_sigma_colour, params.weighted_median_threshold, base=out,
            sigma_divergence=params.weighted_median_sigma_divergence,
        )
    return out


def noise_adapted(params: TVL1Params, frames: tuple[np.ndarray, ...],
                  stats: dict | None = None) -> TVL1Params:
    """``params`` with the weighted median's colour σ_c widened by the frames' noise.

    σ_c' = sqrt(σ_c² + (k σ̂)²), ``k = params.weighted_median_noise``, σ̂ the mean of
    :func:`varflow.ops.fusion.noise_sigma_flat` over ``frames`` (working channels),
    or ``stats["noise_sigma"]`` when TV-L1's noise rule has measured it.  Returns
    ``params`` unchanged when the weighted median or the rule is off.
    """
    k = params.weighted_median_noise
    if params.weighted_median_radius <= 0 or k <= 0:
        return params
    sigma = None if stats is None else stats.get("noise_sigma")
    if sigma is None:
        sigma = float(np.mean([noise_sigma_flat(f) for f in frames]))
        if stats is not None:
            stats["noise_sigma"] = sigma
    sc = math.hypot(params.weighted_median_sigma_colour, k * sigma)
    if stats is not None:
        stats["weighted_median_sigma_colour"] = sc
    return dataclasses.replace(params, weighted_median_sigma_colour=sc)


def guide_pyramid(frame: np.ndarray, params: TVL1Params,
                  shapes: list[tuple[int, int]]) -> list[np.ndarray] | None:
    """The pyramid of ``frame`` (H, W, C) float32 in [0, 1], before any pre-processing,
    on the level ``shapes``, that guides the weighted median; None when
    ``params.weighted_median_radius`` is 0.
    """
    if params.weighted_median_radius <= 0:
        return None
    return build_pyramid(frame, shapes, params.scale_factor, params.pyramid_sigma)


def coarse_to_fine(
    frame0: np.ndarray,
    frame1: np.ndarray,
    solve_warp: WarpSolver,
    params: TVL1Params,
    init_flow: np.ndarray | None = None,
    callback: ProgressCallback | None = None,
    stats: dict | None = None,
    levels: int | None = None,
    level_hook: LevelHook | None = None,
) -> np.ndarray:
    """Estimate the flow from ``frame0`` to ``frame1`` coarse to fine.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float (float frames outside [0, 1] are scaled jointly; see
        :mod:`varflow._validate`).
    solve_warp : callable
        The method's single-level, single-warp solver (see module docstring).
    params : TVL1Params
    init_flow : ndarray, shape (H, W, 2), optional
        Initial flow at full resolution; it is downsampled to the coarsest level run.
    callback : callable, optional
        ``callback(done, total)`` after each warp.
    stats : dict, optional
        Filled with counters and per-stage seconds: ``levels``, ``warps``,
        ``seconds``, ``blur_sigma`` (with ``sharpness_match``: the σ of the
        Gaussian applied to each frame), what the parameters read off the frames
        (``noise_sigma`` and ``data_scale`` of TV-L1's noise rule) and whatever
        the solver records (it sees the same dict as ``state.stats``, e.g. the
        sparse method's ``sparse_seconds``).
    levels : int, optional
        Run only the finest ``levels`` pyramid levels (refining ``init_flow``);
        default all.
    level_hook : callable, optional
        :data:`LevelHook`, called at the start of every level.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        ``[..., 0]`` = u (horizontal), ``[..., 1]`` = v (vertical).
    """
    I0, I1 = check_pair(frame0, frame1)
    t_start = time.perf_counter()
    stats = {} if stats is None else stats
    I0, I1 = working_channels(I0, params), working_channels(I1, params)
    guide_frame = I0  # before the sharpness match and the structure-texture step
    params = params.for_frames(I0, I1, stats)
    params = noise_adapted(params, (I0, I1), stats)
    if params.sharpness_match:
        I0, I1, sigma0, sigma1 = match_sharpness(I0, I1)
        stats["blur_sigma"] = (sigma0, sigma1)
    shapes = pyramid_shapes(I0.shape[:2], params.max_levels, params.scale_factor, params.min_size)
    if levels is not None:
        _check(levels >= 1, "levels", f"must be >= 1, got {levels}")
        shapes = shapes[:levels]
    pyr0 = prepare_pyramid(I0, params, shapes)
    pyr1 = prepare_pyramid(I1, params, shapes)
    guide = guide_pyramid(guide_frame, params, shapes)
    flow = coarse_to_fine_pyramids(pyr0, pyr1, solve_warp, params, init_flow, callback, stats,
                                   level_hook=level_hook, guide=guide)
    stats["seconds"] = time.perf_counter() - t_start
    return flow


def coarse_to_fine_pyramids(
    pyr0: list[np.ndarray],
    pyr1: list[np.ndarray],
    solve_warp: WarpSolver,
    params: TVL1Params,
    init_flow: np.ndarray | None = None,
    callback: ProgressCallback | None = None,
    stats: dict | None = None,
    levels: int | None = None,
    level_hook: LevelHook | None = None,
    guide: list[np.ndarray] | None = None,
) -> np.ndarray:
    """:func:`coarse_to_fine` on pyramids built by :func:`prepare_pyramid`.

    Parameters
    ----------
    pyr0, pyr1 : list of ndarray, each (h, w, C) float32
        Pre-processed pyramids of the two frames, finest first, of equal shapes.
    solve_warp, params, init_flow, callback, stats, levels, level_hook
        As in :func:`coarse_to_fine` (``levels`` takes the finest levels of the
        given pyramids).
    guide : list of ndarray, each (h, w, C'), optional
        The first frame's pyramid (intensities in [0, 1], the shapes of ``pyr0``)
        that guides the weighted median (``params.weighted_median_radius`` > 0);
        default ``pyr0`` itself.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    t_start = time.perf_counter()
    n_levels = min(len(pyr0), len(pyr1))
    if levels is not None:
        _check(levels >= 1, "levels", f"must be >= 1, got {levels}")
        n_levels = min(n_levels, levels)
    shapes = [p.shape[:2] for p in pyr0[:n_levels]]
    total = sum(params.level_warps(shp) for shp in shapes)
    done = 0
    if init_flow is not None:
        flows = np.array(init_flow, np.float32)[None]  # a copy: updated in place
    else:
        flows = np.zeros((1,) + shapes[-1] + (2,), np.float32)
    n_ch = pyr0[0].shape[2]
    stats = {} if stats is None else stats
    planes: list[np.ndarray] = []  # the second frame's derivative planes at the level

    def start_level(level: int, flows: np.ndarray, previous: LevelState | None) -> LevelState:
        if level_hook is not None:
            flows[0] = level_hook(level, pyr0[level], pyr1[level],
                                  np.ascontiguousarray(flows[0]), stats)
        planes[:] = [derivative_planes(pyr1[level])]
        return LevelState(level=level, stats=stats, previous=previous)

    def warp_step(state: LevelState, flows: np.ndarray, k: int) -> np.ndarray:
        state.warp = k
        warped, inside = warp_bicubic(planes[0], flows[0])
        flows[0] = solve_warp(
            pyr0[state.level],
            warped[..., :n_ch],
            warped[..., n_ch : 2 * n_ch],
            warped[..., 2 * n_ch :],
            inside,
            flows[0],
            params,
            state,
        )
        return flows

    def tick() -> None:
        nonlocal done
        done += 1
        if callback is not None:
            callback(done, total)

    flows = run_levels(flows, shapes, params, start_level, warp_step,
                       guide=guide if guide is not None else pyr0, tick=tick,
                       planar=getattr(solve_warp, "planar_flow", False))
    seconds = time.perf_counter() - t_start
    stats.update(levels=n_levels, warps=total, seconds=seconds)
    log.debug("coarse_to_fine: %d levels, %d warps in %.3fs", n_levels, total, seconds)
    return np.ascontiguousarray(flows[0], dtype=np.float32)


#: ``start_level(level, flows, previous) -> state``: set up a pyramid level (after the
#: flows were brought to its size; it may change them in place, e.g. a level hook) and
#: return the level's state; ``previous`` is the coarser level's state or None.
LevelStart = Callable[[int, np.ndarray, Any], Any]

#: ``warp_step(state, flows, k) -> flows``: warp ``k`` of the level: re-linearise about
#: the current flows and solve the level's energy (in place or a new stack).
WarpStep = Callable[[Any, np.ndarray, int], np.ndarray]


def run_levels(
    flows: np.ndarray,
    shapes: list[tuple[int, int]],
    params: TVL1Params,
    start_level: LevelStart,
    warp_step: WarpStep,
    guide: list[np.ndarray] | None = None,
    active: list[int] | None = None,
    tick: Callable[[], None] | None = None,
    planar: bool = False,
) -> np.ndarray:
    """The level and warp loop of coarse-to-fine warping, on a stack of flows.

    For every level, coarsest first: the flows are brought to the level's size
    (:func:`~varflow.ops.pyramid.resize_flow`, which scales the vectors),
    ``start_level`` sets the level up, then ``params.level_warps(shape)`` times
    ``warp_step`` runs one warp and every active flow is filtered
    (:func:`filter_flow`: the median after every warp, the weighted median after a
    level's last); ``tick`` follows each warp.  A level's state keeps the coarser
    level's (``previous``) and no more: ``previous.previous`` is dropped.

    The two-frame driver (:func:`coarse_to_fine_pyramids`) runs it on one flow, the
    multi-frame refinement (:func:`varflow.multiframe.refine.refine_trajectories`) on
    the ``F`` displacement fields of a clip.

    Parameters
    ----------
    flows : ndarray, shape (K, h, w, 2), float32
        The initial flows, at any resolution (resized to the coarsest level run);
        updated in place while they have a level's size.
    shapes : list of (int, int)
        The levels to run, finest first (the last is run first).
    params : TVL1Params
        Warps per level and the filters.
    start_level : callable
        :data:`LevelStart`.
    warp_step : callable
        :data:`WarpStep`.
    guide : list of ndarray, each (h, w, C), optional
        Per level, the image that guides the weighted median; None: no weighted
        median.
    active : list of int, optional
        The flows that are filtered (default all; e.g. not a reference frame's
        zero displacement).
    tick : callable, optional
        Called after every warp.
    planar : bool
        Keep the flows in planar memory, ``(K, 2, h, w)`` behind the ``(K, h, w, 2)``
        view that the steps see: solvers and filters that work on planar data then
        read and write them without transposing (the result is the same).  For
        steps whose kernels take any layout.  Default False.

    Returns
    -------
    ndarray, shape (K, H, W, 2), float32
        The flows at the finest level run (``shapes[0]``); with ``planar`` a view of
        planar memory.
    """
    flows = np.asarray(flows, np.float32)
    if planar:
        flows = _planar_stack(list(flows), flows.shape[1:3])
    rows = list(range(flows.shape[0])) if active is None else list(active)
    state: Any = None
    for level in range(len(shapes) - 1, -1, -1):
        shape = tuple(shapes[level])
        if flows.shape[1:3] != shape:
            flows = _resize_stack(flows, shape, planar)
        if state is not None and hasattr(state, "previous"):
            state.previous = None  # keep one level of history
        state = start_level(level, flows, state)
        n_warps = params.level_warps(shape)
        for k in range(n_warps):
            flows = warp_step(state, flows, k)
            for n in rows:
                flows[n] = filter_flow(flows[n], params, None if guide is None else guide[level],
                                       last_warp=k == n_warps - 1, level=level)
            if tick is not None:
                tick()
    return flows


def _stack_memory(n: int, shape: tuple[int, ...], planar: bool) -> np.ndarray:
    """New float32 memory for ``n`` flows of ``shape``, seen as ``(n, h, w, 2)``: planar
    ``(n, 2, h, w)`` underneath when ``planar``."""
    if planar:
        return np.moveaxis(np.empty((n, 2) + tuple(shape), np.float32), 1, -1)
    return np.empty((n,) + tuple(shape) + (2,), np.float32)


def _planar_stack(flows: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    """The ``(h, w, 2)`` flows as a ``(K, h, w, 2)`` view of new planar memory
    ``(K, 2, h, w)``."""
    view = _stack_memory(len(flows), shape, True)
    for k, f in enumerate(flows):
        view[k] = f
    return view


def _resize_stack(flows: np.ndarray, shape: tuple[int, ...], planar: bool) -> np.ndarray:
    """The ``(K, h, w, 2)`` flows resized to ``shape`` (:func:`resize_flow`) one at a
    time into new memory (:func:`_stack_memory`; no list of K resized flows beside the
    stack)."""
    out = _stack_memory(len(flows), shape, planar)
    for k, f in enumerate(flows):
        out[k] = resize_flow(f, shape)
    return out
