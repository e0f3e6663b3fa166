"""Initial trajectories that survive cumulative motion: outward propagation with fusion.

Independent two-frame flows from the reference ``r`` to every frame (the
``twoframe`` tracker) fail once the displacement grows beyond what the pyramid can
follow — a thin or small structure that moves farther than its own size vanishes
at the coarse levels.  Here the frames are visited outward from the reference,
``r ± 1, r ± 2, …``, and every frame ``n`` gets one or two candidates:

* **propagated** ``P_n``: the neighbour's trajectory extrapolated at constant
  velocity, ``T_{n−s} + (T_{n−s} − T_{n−2s})`` (``s = ±1`` the direction,
  ``T_r = 0``), refined against the reference frame directly by the two-frame
  solver on the finest ``propagate_levels`` pyramid levels only, so that it
  corrects the extrapolation (the acceleration and the neighbour's errors)
  without having to find the whole displacement again;
* **direct** ``D_n`` (only with ``direct=True``): the two-frame flow from the
  reference to frame ``n`` over the whole pyramid, from zero motion (what
  ``twoframe`` computes).  Off by default: on the photographic clips the fusion
  lets chance matches of the direct flow in on the far frames (see
  benchmarks/HISTORY.md).

* **matching-guided** (only with ``matching=True``): the two-frame flow from the
  reference to frame ``n`` of the ``tvl1-ld`` method, computed exactly as
  ``varflow.flow(frames[r], frames[n], "tvl1-ld")`` does
  (:mod:`varflow.twoframe.large_displacement`: descriptor matches between the
  two frames, interpolated edge-aware, fused into every pyramid level).  It is a
  candidate of every frame, ``r ± 1`` included, so a structure that moves
  farther than its size between the reference and a far frame is found again
  even when the propagation lost it.

Where they disagree the pixel keeps the candidate with the smaller edge-aware
cost (:func:`varflow.ops.fusion.fuse`: a residual aggregated with adaptive
support weights of the reference frame); the propagated candidate wins ties.
The residual is that of the frames' soft census planes
(:func:`varflow.ops.fusion.census_planes`, ``cost="census"``), which a change of
brightness or contrast leaves alone, or of their colours (``"colour"``).  The
census cost is the default: under an illumination drift the colour residual is
truncated everywhere and the choice is left to chance, and on the photographic
clips the census fusion gives better initial trajectories than the colour fusion
or either candidate alone (see benchmarks/HISTORY.md).  For ``n = r ± 1`` there is
nothing to propagate: the direct flow is the first candidate.  Last,
:func:`varflow.ops.fusion.repair` lets every pixel take the vector of a pixel a
few pixels away where that fits the frames better: the coarse-to-fine smoothing
leaves a band of the wrong motion along object edges, and a propagated band
would grow by a pixel or so per frame.  The frames ``r ± 1`` can skip the repair
(``repair_adjacent=False``): their flows were not propagated, and on real
footage the photometric cost is the less reliable of the two.

Every frame is pre-processed and its pyramid built once
(:func:`frame_pyramids`); the pyramids are shared by every pair and by the
multi-frame refinement that follows.

References
----------
N. Sundaram, T. Brox, K. Keutzer, "Dense point trajectories by GPU-accelerated
large displacement optical flow", ECCV 2010 (trajectories by propagating flows).

J. Gibson, O. Marques, "Optical Flow and Trajectory Estimation Methods",
SpringerBriefs in Computer Science, Springer 2016, ch. 4.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..ops.fusion import census_planes, fuse, repair_with, support_weights
from ..ops.pyramid import pyramid_shapes
from ..twoframe.coarse_to_fine import (
    coarse_to_fine_pyramids,
    guide_pyramid,
    prepare_pyramid,
    working_channels,
)
from ..twoframe.methods import METHODS, run_method
from ..twoframe.params import PRESETS
from ..twoframe.tvl1 import TVL1Params, solve_warp
from .track import TrackCallback

__all__ = [
    "DEFAULT_REPAIR_COST",
    "REPAIR_COSTS",
    "frame_pyramids",
    "extrapolate",
    "propagate_trajectories",
]

log = logging.getLogger(__name__)

#: The residuals a repair can compare (:func:`varflow.ops.fusion.repair_with`).
REPAIR_COSTS: tuple[str, ...] = ("colour", "relit", "census")
#: The default of :func:`propagate_trajectories` and of
#: :attr:`varflow.multiframe.params.MultiFrameParams.repair_cost` (one value for both).
DEFAULT_REPAIR_COST = "relit"


def frame_pyramids(frames: np.ndarray, params: TVL1Params) -> list[list[np.ndarray]]:
    """Pre-processed pyramids of every frame, on one set of level shapes.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32 in [0, 1]
    params : TVL1Params
        Pre-processing and pyramid fields.

    Returns
    -------
    list of F lists of ndarray
        ``pyrs[n][level]``, shape ``(h_l, w_l, C)`` float32, finest first.
    """
    shapes = pyramid_shapes(frames.shape[1:3], params.max_levels, params.scale_factor,
                            params.min_size)
    return [prepare_pyramid(f, params, shapes) for f in frames]


def extrapolate(prev: np.ndarray, prev2: np.ndarray | None) -> np.ndarray:
    """Constant-velocity guess ``prev + (prev − prev2)`` (``prev2 = None``: zero)."""
    if prev2 is None:
        return (2.0 * prev).astype(np.float32)
    return (2.0 * prev - prev2).astype(np.float32)


def propagate_trajectories(
    frames: np.ndarray,
    ref: int,
    params: TVL1Params,
    pyramids: list[list[np.ndarray]] | None = None,
    *,
    levels: int = 3,
    direct: bool = False,
    matching: bool = False,
    matching_params: TVL1Params | None = None,
    cost: str = "census",
    repair_distances: tuple[int, ...] = (2, 4, 8),
    repair_adjacent: bool = True,
    repair_cost: str = DEFAULT_REPAIR_COST,
    support_radius: int = 2,
    support_gamma: float = 0.1,
    callback: TrackCallback | None = None,
    stats: dict | None = None,
) -> np.ndarray:
    """Initial trajectories by outward propagation, repair and fusion (see the module notes).

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32
        From :func:`varflow.multiframe.track.check_frames`.
    ref : int
    params : TVL1Params
        Of the two-frame solver (TV-L1).
    pyramids : list, optional
        :func:`frame_pyramids` of ``frames`` (built here when omitted).
    levels : int
        Pyramid levels of the refinement of a propagated candidate.
    direct : bool
        Also compute the direct candidate of every frame beyond ``r ± 1`` and fuse;
        False keeps the propagated candidates alone.
    matching : bool
        Add the matching-guided candidate of every frame (see the module notes).
    matching_params : TVL1Params, optional
        Of that candidate; default ``tvl1-ld``'s defaults (what ``varflow.flow``
        runs).
    cost : {"census", "colour"}
        Residual of the fusion cost: of the frames' soft census planes or of
        their colours (see the module notes).
    repair_distances : tuple of int
        Offsets of :func:`varflow.ops.fusion.repair`; empty = no repair.
    repair_adjacent : bool
        Repair the frames ``ref ± 1`` too.  Their flows come from the whole
        pyramid, not from a propagated neighbour, so no band has grown along the
        object edges, and on real footage the photometric cost of the repair is
        less reliable than the flow (see
        :attr:`varflow.multiframe.params.MultiFrameParams.repair_adjacent`).
    repair_cost : {"colour", "relit", "census"}
        Residual of the repair's cost (:func:`varflow.ops.fusion.repair_with`): the
        frames' colours, the colours with the reference relit to the other frame's
        light, or their soft census planes.  Default "relit" (see
        :attr:`varflow.multiframe.params.MultiFrameParams.repair_cost`).
    support_radius, support_gamma : int, float
        Window radius R and colour scale γ of the photometric cost
        (:func:`varflow.ops.fusion.support_weights` of the reference frame).
    callback : callable, optional
        ``callback(done, total)`` after each frame.
    stats : dict, optional
        Filled with ``seconds``, ``flows`` (two-frame problems solved),
        ``direct_share`` (share of the pixels of the fused frames that kept
        another candidate than the first: the direct or the matching-guided
        flow over the propagated one, the matching-guided over the direct at
        ``r ± 1``) and ``repaired`` (mean share of the pixels the
        repair changed).

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
    """
    if cost not in ("census", "colour"):
        raise ValueError(f"cost: must be 'census' or 'colour', got {cost!r}")
    if repair_cost not in REPAIR_COSTS:
        raise ValueError(f"repair_cost: must be 'colour', 'relit' or 'census', "
                         f"got {repair_cost!r}")
    t0 = time.perf_counter()
    n_frames, height, width = frames.shape[:3]
    pyrs = frame_pyramids(frames, params) if pyramids is None else pyramids
    weights = support_weights(frames[ref], support_radius, support_gamma)
    guide = guide_pyramid(working_channels(frames[ref], params), params,
                          [p.shape[:2] for p in pyrs[ref]])
    traj = np.zeros((n_frames, height, width, 2), np.float32)
    todo = [n for n in range(ref + 1, n_frames)] + [n for n in range(ref - 1, -1, -1)]
    n_flows = 0
    kept_direct: list[float] = []
    repaired: list[float] = []
    ld_params = None
    if matching:
        ld_params = PRESETS["tvl1-ld"] if matching_params is None else matching_params
    planes = census_planes(frames[ref]) if cost == "census" else frames[ref]
    for i, n in enumerate(todo):
        s = 1 if n > ref else -1
        cands = []
        if abs(n - ref) > 1:
            prev2 = None if abs(n - ref) == 2 else traj[n - 2 * s]
            guess = extrapolate(traj[n - s], prev2)
            cands.append(coarse_to_fine_pyramids(pyrs[ref], pyrs[n], solve_warp, params,
                                                 init_flow=guess, levels=levels,
                                                 guide=guide))
        if direct or not cands:
            cands.append(coarse_to_fine_pyramids(pyrs[ref], pyrs[n], solve_warp, params,
                                                 guide=guide))
        if ld_params is not None:
            cands.append(run_method(METHODS["tvl1-ld"], frames[ref], frames[n], ld_params))
        n_flows += len(cands)
        if len(cands) > 1:
            other = census_planes(frames[n]) if cost == "census" else frames[n]
            flow, choice = fuse(planes, other, cands, weights,
                                truncation=0.5 if cost == "census" else 0.1)
            kept_direct.append(float((choice > 0).mean()))
        else:
            flow = cands[0]
        if repair_distances and (repair_adjacent or abs(n - ref) > 1):
            rs: dict = {}
            flow = repair_with(repair_cost, frames[ref], frames[n], flow, weights,
                               repair_distances, stats=rs)
            repaired.append(rs["changed"])
        traj[n] = flow
        if callback is not None:
            callback(i + 1, len(todo))
    if stats is not None:
        stats.update(seconds=time.perf_counter() - t0, flows=n_flows,
                     direct_share=float(np.mean(kept_direct)) if kept_direct else 0.0,
                     repaired=float(np.mean(repaired)) if repaired else 0.0)
    log.debug("propagation: %d flows in %.2fs", n_flows, time.perf_counter() - t0)
    return traj
