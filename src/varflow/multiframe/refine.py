"""The multi-frame refinement shared by RLR and MFSF.

:func:`refine_trajectories` builds every frame's pyramid, initialises the
trajectories (:func:`initial_trajectories`), estimates their visibility, then runs
the two-frame driver's level and warp loop over the ``F`` displacement fields, each
warp alternating the coupling target of a :class:`Coupling` (RLR's L-step, MFSF's
projection) with the U-step of :mod:`varflow.multiframe.ustep`; the final repair
follows.  The methods that drive it are :mod:`varflow.multiframe.rlr` and
:mod:`varflow.multiframe.mfsf`; their parameters are in
:mod:`varflow.multiframe.params`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..ops.differences import derivative_planes
from ..ops.fusion import repair_with, support_weights
from ..ops.primal_dual import row_blocks
from ..ops.prox import project_l2_ball
from ..ops.pyramid import pyramid_shapes, resize_bilinear, resize_flow, smooth_image
from ..ops.warp import warp_bicubic
from ..twoframe.coarse_to_fine import (
    coarse_to_fine_pyramids,
    guide_pyramid,
    noise_adapted,
    run_levels,
    working_channels,
)
from ..twoframe.tvl1 import (
    TVL1Params,
    TVL1State,
    data_channels,
    edge_weight,
    gradient_channel_count,
)
from ..twoframe.tvl1 import solve_warp as tvl1_solve_warp
from .params import FINAL_REPAIR_DISTANCES, MultiFrameParams
from .propagate import frame_pyramids, propagate_trajectories
from .track import TrackCallback
from .ustep import link_channels, set_link_targets, ustep_iterations, ustep_iterations_numpy
from .visibility import backward_flows, visibility_from

__all__ = [
    "Coupling",
    "MultiFrameLevel",
    "fit_gate",
    "initial_trajectories",
    "clip_noise_rule",
    "refine_trajectories",
    "refinement_warps",
]

log = logging.getLogger(__name__)


def _resize_dual(p: np.ndarray, shape: tuple[int, int], g: np.ndarray) -> np.ndarray:
    h, w = shape
    q = resize_bilinear(np.moveaxis(p, 0, -1), (h, w)).reshape(h, w, 2, 2)
    q = project_l2_ball(q, g[..., None]).reshape(h, w, 4)
    return np.ascontiguousarray(np.moveaxis(q, -1, 0), dtype=np.float32)


@dataclass
class Coupling:
    """How a multi-frame method ties the frames together in the U-step.

    Attributes
    ----------
    kind : {"l1", "l2"}
        ``weight · ||U − T||_1`` (RLR's robust link, exact in the point-wise prox)
        or ``weight/2 · ||U − T||²`` (MFSF's soft subspace constraint).
    weight : float
        τ or β; 0 decouples the frames.
    target : callable
        ``target(traj, visible) -> (F, h, w, 2)``: the coupling target ``T`` from the
        current trajectories at the current level (RLR: the L-step; MFSF: the
        projection onto the basis), computed before every U-step; ``visible`` is
        the ``(F, h, w)`` bool visibility at that level, or None.
    edge_scaled : bool
        Scale an "l1" weight by the edge weight g(x).
    seconds : float
        Time spent in ``target`` (filled in by the driver).
    hidden_weight : float, optional
        An "l1" weight for the entries marked hidden (default: ``weight``).
    adjacent_factor : float
        Factor of the "l1" weights (of the visible and of the hidden entries) of
        the two frames next to the reference, ``ref ± 1``.  Default 1.
    """

    kind: str
    weight: float
    target: Any
    edge_scaled: bool = False
    seconds: float = 0.0
    hidden_weight: float | None = None
    adjacent_factor: float = 1.0
    gate: Any = None


def fit_gate(traj: np.ndarray, target: np.ndarray, ref: int, visible: np.ndarray | None,
             k: float, sigma: float = 2.0, floor: float = 0.05) -> np.ndarray:
    """Per-pixel factor of the link weight from how well the motion fits the low-rank model.

    ``r(x)``: the mean over the visible frames ``n ≠ ref`` of
    ``|u_n(x) − l_n(x)| / |n − ref|`` (the misfit of the trajectory to its low-rank
    target, in pixels per frame), smoothed by a Gaussian of ``sigma`` pixels so that
    it describes a region, not a pixel; ``m`` its median over the frame.  The factor
    is ``1 / (1 + (r / (k m + floor))²)``: about 1 where a region fits the model as
    well as the clip does (rigid motion; uniformly noisy frames, whose misfit is the
    noise everywhere), and → 0 where it fits much worse (an object whose motion the
    basis does not hold: the refinement there is decoupled).

    Parameters
    ----------
    traj, target : ndarray, shape (F, h, w, 2)
    ref : int
    visible : ndarray, shape (F, h, w), bool, or None
    k : float
        Misfit, in medians, at which the link is halved.
    sigma, floor : float
        Smoothing (pixels) and the misfit floor (pixels per frame) below which a fit
        counts as exact.

    Returns
    -------
    ndarray, shape (h, w), float32, in (0, 1]
    """
    f = traj.shape[0]
    num = np.zeros(traj.shape[1:3], np.float64)
    den = np.zeros(traj.shape[1:3], np.float64)
    for n in range(f):
        if n == ref:
            continue
        e = np.hypot(*(traj[n] - target[n]).transpose(2, 0, 1)) / abs(n - ref)
        wgt = np.ones_like(e) if visible is None else visible[n].astype(np.float64)
        num += wgt * e
        den += wgt
    r = np.where(den > 0, num / np.maximum(den, 1), 0.0).astype(np.float32)
    r = smooth_image(r[..., None], sigma)[..., 0]
    scale = k * float(np.median(r)) + floor
    return (1.0 / (1.0 + (r / np.float32(scale)) ** 2)).astype(np.float32)


def _link_ratio(weight: float, params: MultiFrameParams, g: np.ndarray,
                edge_scaled: bool) -> Any:
    """``τ/λ_D`` of a link weight at a level: a scalar, or ``(h, w)`` when scaled by the
    edge weight ``g`` (which holds λ_TV) or zero (so that the link channels exist)."""
    r = np.float32(weight / float(params.flow_params.data_weight))
    if edge_scaled:
        return np.ascontiguousarray(r * g / np.float32(params.tv_weight), np.float32)
    return np.full(g.shape, r, np.float32) if r == 0 else r


def _level_mask(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """A boolean ``(H, W)`` mask at a pyramid level: area average, then > 1/2."""
    if mask.shape == shape:
        return mask
    m = resize_bilinear(mask[..., None].astype(np.float32), shape)[..., 0]
    return m > 0.5


def initial_trajectories(frames: np.ndarray, ref: int, params: MultiFrameParams,
                         pyramids: list[list[np.ndarray]],
                         callback: TrackCallback | None = None) -> np.ndarray:
    """The initial trajectories of ``params.init`` (see :class:`MultiFrameParams`).

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32
    ref : int
    params : MultiFrameParams
    pyramids : list
        :func:`varflow.multiframe.propagate.frame_pyramids` of ``frames``.
    callback : callable, optional
        ``callback(done, total)`` after each frame.

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
    """
    if params.init == "propagate":
        return propagate_trajectories(frames, ref, params.flow_params, pyramids,
                                      repair_adjacent=params.repair_adjacent,
                                      repair_cost=params.repair_cost,
                                      levels=params.propagate_levels,
                                      direct=params.propagate_direct,
                                      matching=params.propagate_matching, callback=callback)
    if params.init == "twoframe":
        traj = np.zeros(frames.shape[:3] + (2,), np.float32)
        others = [n for n in range(frames.shape[0]) if n != ref]
        for i, n in enumerate(others):
            traj[n] = coarse_to_fine_pyramids(pyramids[ref], pyramids[n], tvl1_solve_warp,
                                              params.flow_params)
            if callback is not None:
                callback(i + 1, len(others))
        return traj
    return np.zeros(frames.shape[:3] + (2,), np.float32)


def _linearised_frame(i0: np.ndarray, i1: np.ndarray, about: np.ndarray,
                      visible: np.ndarray | None, hidden_data_weight: float,
                      link_ratio: Any, energy: TVL1Params, level_state: TVL1State) -> tuple:
    """One frame's data term linearised about ``about`` (and its link channels).

    The channels of the two-frame energy, built by TV-L1's own
    :func:`~varflow.twoframe.tvl1.data_channels` (the colour or grey term and, with
    γ > 0, gradient constancy; ζ > 0 normalises them), so that the U-step has the
    data term of ``tvl1``.  Built when the frame's U-step needs it, so that the
    warped planes of all frames are never held at once.  ``visible`` (H, W) bool or
    None; ``link_ratio`` None (no l1 link) or the link-to-data ratio (scalar or
    (H, W)); ``level_state`` TV-L1's level state shared by the frames (it caches
    the reference's smoothed gradients).
    """
    n_ch = i0.shape[2]
    warped, inside = warp_bicubic(derivative_planes(i1), about)
    if visible is not None and hidden_data_weight == 0:
        inside &= visible
    lin = data_channels(i0, warped[..., :n_ch], warped[..., n_ch:2 * n_ch],
                        warped[..., 2 * n_ch:], inside, about, energy, level_state)
    if visible is not None and 0 < hidden_data_weight < 1:
        fac = np.where(visible, np.float32(1), np.float32(hidden_data_weight))
        lin = tuple((c * fac).astype(np.float32) for c in lin)
    if link_ratio is None:
        return lin
    return link_channels(*lin, np.zeros((2,) + i0.shape[:2], np.float32), link_ratio)


def clip_noise_rule(params: MultiFrameParams, frames: np.ndarray, ref: int,
                    stats: dict | None = None) -> MultiFrameParams:
    """TV-L1's noise rule (``noise_reference`` of the energy) read off a clip.

    :meth:`~varflow.twoframe.tvl1.TVL1Params.for_frames` of the reference and the
    frame next to it (``ref + 1``, or ``ref − 1`` at the end of the clip), on the
    working channels: the data weights λ and γ of ``params.flow_params`` are scaled
    by ``σ_0/σ̂`` on noisy footage, for the initial flows, the visibility's
    backward flows and the U-step alike.  ``stats`` gains ``noise_sigma`` and
    ``data_scale`` when the rule is on.
    """
    energy = params.flow_params
    if energy.noise_reference <= 0 or frames.shape[0] < 2:
        return params
    near = ref + 1 if ref + 1 < frames.shape[0] else ref - 1
    pair_stats: dict = {}
    out = energy.for_frames(working_channels(frames[ref], energy),
                            working_channels(frames[near], energy), pair_stats)
    if stats is not None:
        stats.update(pair_stats)
    return params if out is energy else replace(params, flow_params=out)


@dataclass
class MultiFrameLevel:
    """The state of one pyramid level of the multi-frame refinement (:class:`_UStep`).

    Attributes
    ----------
    level : int
        Pyramid level, 0 = finest.
    i0 : ndarray, shape (h, w, C), float32
        The reference frame at the level (pre-processed, working channels).
    g : ndarray, shape (h, w), float32
        ``λ_TV g(x)``: the radius of the TV dual ball.
    p : ndarray, shape (F, 4, h, w), float32
        Every frame's TV dual variables, warm started from the coarser level.
    visible : ndarray, shape (F, h, w), bool, or None
        The visibility at the level.
    link, link_adjacent : float or ndarray (h, w), float32
        The link-to-data ratio ``τ/λ_D`` of the visible entries, of the frames
        further from the reference and of ``ref ± 1``.
    hidden_link, hidden_link_adjacent : float32
        Likewise for the hidden entries.
    blocks : ndarray, shape (n+1,), int64
        Row blocks of the kernels (:func:`varflow.ops.primal_dual.row_blocks`).
    ubar : ndarray, shape (2, h, w), float32
        Scratch of the U-step kernel.
    data : TVL1State
        TV-L1's data-term cache of the level (the reference's smoothed gradients),
        shared by the frames.
    q : ndarray, shape (F, K, h, w), float32, or None
        Every frame's data-prox duals (made at the level's first U-step, when the
        number of channels ``K`` is known).
    """

    level: int
    i0: np.ndarray
    g: np.ndarray
    p: np.ndarray
    visible: np.ndarray | None
    link: Any
    link_adjacent: Any
    hidden_link: np.float32
    hidden_link_adjacent: np.float32
    blocks: np.ndarray
    ubar: np.ndarray
    data: TVL1State
    q: np.ndarray | None = None


class _UStep:
    """The level set-up and the warp step of the multi-frame refinement, for
    :func:`varflow.twoframe.coarse_to_fine.run_levels`.

    A warp re-linearises every frame's data term about its displacement at the
    start of the warp and alternates ``params.alternations`` times the coupling
    target ``T = coupling.target(U, visible)`` with the per-frame primal-dual U-step
    coupled to ``T`` (see :func:`refine_trajectories`).
    """

    def __init__(self, pyrs, ref, others, params, coupling, visible, kernel, exact, l1,
                 weight, w_hidden, a_adj):
        self.pyrs, self.ref, self.others = pyrs, ref, others
        self.params, self.coupling, self.visible = params, coupling, visible
        self.kernel, self.exact, self.l1 = kernel, exact, l1
        self.weight, self.w_hidden, self.a_adj = weight, w_hidden, a_adj
        self.energy = params.flow_params
        self.n_frames = len(pyrs)
        self.seconds = 0.0  # U-step time (with each frame's warp and linearisation)

    def start_level(self, level: int, traj: np.ndarray,
                    previous: MultiFrameLevel | None) -> MultiFrameLevel:
        params, energy, n_frames = self.params, self.energy, self.n_frames
        h, w = traj.shape[1:3]
        vis_l = None if self.visible is None else np.stack(
            [_level_mask(self.visible[n], (h, w)) for n in range(n_frames)])
        i0 = self.pyrs[self.ref][level]
        g = edge_weight(i0, energy.edge_weight, energy.edge_weight_min)
        g = np.ascontiguousarray(g * np.float32(params.tv_weight), np.float32)
        if previous is None:
            p = np.zeros((n_frames, 4, h, w), np.float32)
        else:
            p = np.stack([_resize_dual(previous.p[n], (h, w), g) for n in range(n_frames)])
        link, link_adj = (_link_ratio(wt, params, g, self.coupling.edge_scaled)
                          for wt in (self.weight, self.a_adj * self.weight))
        lam = float(energy.data_weight)
        return MultiFrameLevel(
            level=level, i0=i0, g=g, p=p, visible=vis_l, link=link, link_adjacent=link_adj,
            hidden_link=np.float32(self.w_hidden / lam),
            hidden_link_adjacent=np.float32(self.a_adj * self.w_hidden / lam),
            blocks=row_blocks(h), ubar=np.empty((2, h, w), np.float32),
            data=TVL1State(level=level))

    def warp(self, st: MultiFrameLevel, traj: np.ndarray, k: int) -> np.ndarray:
        params, energy, coupling, l1 = self.params, self.energy, self.coupling, self.l1
        lam = np.float32(energy.data_weight)
        s = np.float32(params.primal_step)
        beta = np.float32(self.weight if coupling.kind == "l2" else 0.0)
        huber = np.float32(energy.huber)
        theta = np.float32(energy.coupling if params.relaxed_data else 0.0)
        no_target = np.zeros((2, 1, 1), np.float32)
        vis_l = st.visible
        # every alternation linearises about the flow at the start of the warp
        start = traj.copy() if params.alternations > 1 else traj
        for _a in range(params.alternations):
            t0 = time.perf_counter()
            target = coupling.target(traj, vis_l) if (self.weight > 0 or l1) else None
            gate = None
            if l1 and target is not None and coupling.gate is not None:
                gate = coupling.gate(traj, target, vis_l)
            t1 = time.perf_counter()
            coupling.seconds += t1 - t0
            for n in self.others:  # U-step with the target fixed, frame by frame
                # (with one alternation traj[n] is still the flow of the warp's start)
                vis_n = None if vis_l is None else vis_l[n]
                adjacent = abs(n - self.ref) == 1
                rn = st.link_adjacent if adjacent else st.link
                if gate is not None:  # the visible entries' link follows the fit
                    rn = (rn * gate).astype(np.float32)
                if l1 and vis_n is not None and (self.w_hidden != self.weight
                                                 or gate is not None):
                    rn = np.where(vis_n, rn,
                                  st.hidden_link_adjacent if adjacent else st.hidden_link)
                    rn = rn.astype(np.float32)
                ix, iy, a = _linearised_frame(st.i0, self.pyrs[n][st.level], start[n], vis_n,
                                              params.hidden_data_weight,
                                              rn if l1 else None, energy, st.data)
                n_data = a.shape[0] - (2 if l1 else 0)
                tk = None if target is None else np.ascontiguousarray(
                    np.moveaxis(target[n], -1, 0))
                if l1 and tk is not None:
                    set_link_targets(a, n_data, tk, rn)
                m = tk if (tk is not None and not l1) else no_target
                u = np.ascontiguousarray(np.moveaxis(traj[n], -1, 0))
                if st.q is None:  # the data channels' count is known now
                    st.q = np.zeros((self.n_frames,) + a.shape, np.float32)
                self.kernel(ix, iy, a, st.g, u, st.p[n], st.q[n], st.ubar, m, beta, lam, s,
                            params.ustep_iterations, np.float32(params.ustep_tolerance),
                            energy.data_sweeps, self.exact, st.blocks, huber,
                            theta, n_data)
                traj[n] = np.moveaxis(u, 0, -1)
            self.seconds += time.perf_counter() - t1
        return traj


def _refinement_inputs(frames: np.ndarray, ref: int, params: MultiFrameParams,
                       pyrs: list[list[np.ndarray]], tick: Any, stats: dict,
                       t_start: float) -> tuple:
    """The initial trajectories, the backward flows and the visibility of a refinement."""
    energy = params.flow_params
    init = initial_trajectories(frames, ref, params, pyrs, tick)
    stats["init_seconds"] = time.perf_counter() - t_start
    visible = None
    back = None
    if params.visibility:
        t0 = time.perf_counter()
        vparams = params.visibility_params()
        bparams = replace(energy, n_warps=params.visibility_warps)
        back = backward_flows(init, ref, pyrs, bparams, vparams.backward_levels, tick,
                              splat=params.propagate_matching)
        visible = visibility_from(init, back, ref, [p[0] for p in pyrs], vparams)
        stats["visibility_seconds"] = time.perf_counter() - t0
    return init, back, visible


def refine_trajectories(frames: np.ndarray, ref: int, params: MultiFrameParams,
                        coupling: Coupling, callback: TrackCallback | None = None,
                        engine: str = "numba", stats: dict | None = None,
                        pyramids: list[list[np.ndarray]] | None = None,
                        reuse: dict | None = None, extra_ticks: int = 0) -> np.ndarray:
    """The multi-frame refinement shared by RLR and MFSF.

    Builds every frame's pyramid once, initialises (``params.init``), estimates the
    visibility of the initial trajectories (``params.visibility``), then runs the
    two-frame driver's level and warp loop
    (:func:`varflow.twoframe.coarse_to_fine.run_levels`) on the ``F`` displacement
    fields over the finest ``params.refine_levels`` levels (every level from zero
    motion).  Every warp re-warps every frame around its current displacement,
    linearises its data term with TV-L1's own
    :func:`~varflow.twoframe.tvl1.data_channels` (switched off where the point is
    hidden or leaves the frame), and alternates ``params.alternations`` times the
    coupling target ``T = coupling.target(U, visible)`` with the per-frame
    primal-dual U-step coupled to ``T``; the driver's filters (median, weighted
    median) follow each warp.  The per-level state is a :class:`MultiFrameLevel`.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32
        From :func:`varflow.multiframe.track.check_frames`.
    ref : int
        Reference frame.
    params : MultiFrameParams
    coupling : Coupling
    callback : callable, optional
        ``callback(done, total)`` after each flow of the initialisation, each
        backward flow of the visibility estimate and each warp of the
        multi-frame pyramid.
    engine : {"numba", "numpy"}
        U-step kernel.
    stats : dict, optional
        Filled with ``levels``, ``warps``, ``init_seconds``, ``visibility_seconds``,
        ``ustep_seconds`` (with each frame's warp and linearisation),
        ``coupling_seconds``, ``seconds`` and ``visible``: the ``(F, H, W)`` bool
        visibility of the result (estimated with the backward
        flows of the initial trajectories; None with ``params.visibility`` off).
    pyramids : list, optional
        :func:`varflow.multiframe.propagate.frame_pyramids` of ``frames`` (built
        here when omitted).
    reuse : dict, optional
        A dict that carries the inputs of the refinement from one call to the next
        on the same frames with the same ``params``: when it holds ``init``,
        ``backward`` and ``pyramids`` (the initial trajectories, the backward flows
        of the visibility and the frame pyramids) they are used instead of being
        computed; otherwise they are stored in it.
    extra_ticks : int
        Added to the ``total`` of ``callback`` (the warps of a refinement that follows).

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
    """
    if engine not in ("numba", "numpy"):
        raise ValueError(f"engine: must be 'numba' or 'numpy', got {engine!r}")
    if coupling.kind not in ("l1", "l2"):
        raise ValueError(f"coupling: kind must be 'l1' or 'l2', got {coupling.kind!r}")
    stats = {} if stats is None else stats
    t_start = time.perf_counter()
    n_frames = frames.shape[0]
    params = clip_noise_rule(params, frames, ref, stats)
    energy = params.flow_params
    energy = noise_adapted(energy, (working_channels(frames[ref], energy),), stats)
    params = replace(params, flow_params=energy)
    others = [n for n in range(n_frames) if n != ref]
    reused = reuse is not None and "init" in reuse
    if reused:
        pyrs = reuse["pyramids"]
    else:
        pyrs = frame_pyramids(frames, energy) if pyramids is None else pyramids
    shapes = [p.shape[:2] for p in pyrs[ref]]
    n_levels = len(shapes)
    n_run = n_levels
    if params.init != "zero" and params.refine_levels > 0:
        n_run = min(params.refine_levels, n_levels)
    n_init = len(others) if params.init != "zero" and not reused else 0
    n_vis = len(others) if params.visibility and not reused else 0
    n_warps = sum(energy.level_warps(shp) for shp in shapes[:n_run])
    total = n_init + n_vis + n_warps + extra_ticks
    done = 0

    def tick(*_: Any) -> None:
        nonlocal done
        done += 1
        if callback is not None:
            callback(done, total)

    if reused:
        init, back, visible = reuse["init"], reuse["backward"], reuse["visible"]
    else:
        init, back, visible = _refinement_inputs(frames, ref, params, pyrs, tick, stats,
                                                 t_start)
        if reuse is not None:
            reuse.update(init=init, backward=back, pyramids=pyrs, visible=visible)

    weight = float(coupling.weight)
    w_hidden = weight if coupling.hidden_weight is None else float(coupling.hidden_weight)
    a_adj = float(coupling.adjacent_factor)
    l1 = coupling.kind == "l1" and (weight > 0 or (visible is not None and w_hidden > 0))
    n_work = pyrs[ref][0].shape[2]  # the channels the energy works on (1 with grey)
    n_terms = n_work + 2 * gradient_channel_count(energy, n_work)  # channels of the data term
    exact = params.data_prox == "exact" or (params.data_prox == "auto" and n_terms == 1)
    kernel = ustep_iterations if engine == "numba" else ustep_iterations_numpy
    coupling.seconds = 0.0

    traj = np.stack([resize_flow(init[n], shapes[n_run - 1]) for n in range(n_frames)])
    del init  # not needed again here; one (F, H, W, 2) array less at the peak
    guide = guide_pyramid(working_channels(frames[ref], energy), energy, shapes)
    ustep = _UStep(pyrs, ref, others, params, coupling, visible, kernel, exact, l1, weight,
                   w_hidden, a_adj)
    traj = run_levels(traj, shapes[:n_run], energy, ustep.start_level, ustep.warp,
                      guide=None if guide is None else guide[:n_run], active=others, tick=tick)
    t_u = ustep.seconds
    traj[ref] = 0.0
    if params.final_repair:
        weights = support_weights(frames[ref])
        for n in others:
            if abs(n - ref) == 1 and not params.repair_adjacent:
                continue
            traj[n] = repair_with(params.repair_cost, frames[ref], frames[n], traj[n], weights,
                                  FINAL_REPAIR_DISTANCES)
    if back is not None:
        visible = visibility_from(traj, back, ref, [p[0] for p in pyrs],
                                  params.visibility_params())
    stats.update(levels=n_run, warps=n_warps, ustep_seconds=t_u,
                 coupling_seconds=coupling.seconds, seconds=time.perf_counter() - t_start,
                 visible=visible)
    log.debug("multi-frame refinement: %d levels, U-step %.2fs, coupling %.2fs", n_run, t_u,
              coupling.seconds)
    return traj.astype(np.float32, copy=False)


def refinement_warps(frames: np.ndarray, params: MultiFrameParams) -> int:
    """The warps of :func:`refine_trajectories` on ``frames`` (its progress ticks
    after the initialisation and the visibility)."""
    energy = params.flow_params
    shapes = pyramid_shapes(frames.shape[1:3], energy.max_levels, energy.scale_factor,
                            energy.min_size)
    n_run = len(shapes)
    if params.init != "zero" and params.refine_levels > 0:
        n_run = min(params.refine_levels, n_run)
    return sum(energy.level_warps(shp) for shp in shapes[:n_run])
