"""Robust Low-Rank (RLR) dense trajectories (Gibson & Marques 2016, ch. 4).

Energy over the trajectories ``U`` of the reference pixels in all ``F`` frames
(matrix view ``(2F, N)``, see :mod:`varflow.multiframe.lowrank`) and an auxiliary
low-rank matrix ``L``::

    E(U, L) = Σ_n [ λ_D Σ_c |ρ_{n,c}(u_n)| + λ_TV Σ_x g(x) (|∇u_{n,1}| + |∇u_{n,2}|) ]
              + α ||L||_*  +  τ ||U − L||_1

with ``ρ_{n,c}`` the colour constancy residual of frame ``n`` against the reference,
linearised around the current estimate and re-warped coarse to fine, and ``g`` the
edge weight of the reference frame.  The data term is TV-L1's whole one:
the channels of :func:`varflow.twoframe.tvl1.data_channels` — colour or grey
(``grey``), gradient constancy (γ = ``gradient_weight``), the normalisation ζ
(``data_normalisation``) — with TV-L1's noise rule (``noise_reference``,
:func:`clip_noise_rule`), and the TV may be Huber-TV (``huber``); the book's energy
is the case γ = ζ = ε_H = 0.  By default (``relaxed_data``) the data term of each
frame is relaxed as TV-L1 relaxes it, ``min_v |u_n − v|²/(2θ) + λ_D Σ_c |ρ_{n,c}(v)|``
with θ = ``coupling`` (the energy ``tvl1``'s own solver minimises); the link stays
L1 on ``u_n``.  The frames are coupled only through ``L``.
It is minimised by alternation, after every warp of every pyramid level:

1. **U-step** (``L`` fixed).  The energy splits into one problem per frame,
   ``G_n(u_n) + H(∇u_n)`` with the point-wise ``G_n = λ_D Σ_c |ρ_{n,c}| + τ |u_n − l_n|_1``
   and ``H`` the weighted TV.  It is solved by Condat's primal-dual algorithm
   (Condat 2013) without smooth term and relaxation ρ = 1, which is the
   Chambolle-Pock iteration::

       ũ = prox_{s G}(u + s div p)
       p ← Π_{|p| ≤ λ_TV g}(p + σ ∇(2ũ − u)),   u ← ũ,          s σ ||∇||² ≤ 1

   over all frames (a Numba kernel per frame, rows in parallel).  The prox of
   ``G_n`` is a sum of ``C + 2`` linear-L1 terms — the link terms are the
   residuals ``u_{n,k} − l_{n,k}`` with gradients along the axes — so the data-term
   machinery of TV-L1 applies with two extra "channels".  It is computed
   **exactly** (``data_prox="exact"``, :func:`prox_certified`): the warm-started
   dual coordinate descent of TV-L1 proposes the active set, whose point is kept
   only when it passes the optimality conditions; the few pixels that fail take
   more descent sweeps, then the enumeration of the faces of the
   piecewise-quadratic energy (23 candidates for a grey frame, 122 for colour,
   :func:`prox_faces`).  Or (``data_prox="cd"``) by the dual coordinate descent
   alone (:func:`varflow.ops.prox.prox_linear_l1`), which converges to the same
   point and costs about a fifth per iteration for colour.  ``data_prox="auto"``
   (default) is exact for a data term of one channel (a grey frame without the
   gradient term) and coordinate descent otherwise: for colour and for TV-L1's
   grey + gradient term (3 channels) both give the same errors, coordinate descent
   in a fraction of the time (see benchmarks/HISTORY.md).  With the relaxed data
   term each iteration first sets ``v = prox_{λ_D θ D}(u)`` by the same data-term
   machinery, then takes the primal step with ``G_n = |u − v|²/(2θ) + τ |u − l_n|_1``,
   in closed form (the quadratics' centre moved towards ``l_n`` by the link's soft
   threshold, :func:`_relaxed_primal_row`); its fixed point is the minimiser of
   TV-L1's relaxed energy (tested against TV-L1's own scheme).
2. **L-step** (``U`` fixed).  ``min_L α ||L||_* + τ ||U − L||_1`` is principal
   component pursuit with ``λ = τ / α``, solved in linear time by l1 filtering
   (:func:`varflow.multiframe.lowrank.lowrank_step`).  ``α`` follows from the
   PCP weight ``λ = κ / sqrt(max(2F, N))`` (``κ = pcp_scale``), so that the balance
   of the two terms does not depend on the size of the pyramid level.  The
   rank is estimated: singular directions below ``rank_tol`` of the largest are
   dropped, and by default the L-step sees mean velocities (frame n's rows divided
   by ``|n − ref|``, ``velocity_rows``) so that far frames do not dominate it.

The reference row of ``U`` is zero by definition and kept fixed.  With ``τ = 0``
the U-step is ``F − 1`` independent two-frame TV-L1 problems.

Beyond the book (``init``, ``visibility``, ``final_repair``):

* **Initial trajectories** (``init="propagate"``, default) are propagated outward
  from the reference: frame ``n`` starts from the constant-velocity extrapolation
  of frames ``n ∓ 1, n ∓ 2`` and is refined against the reference on the finest
  ``propagate_levels`` levels, then repaired across motion edges
  (:mod:`varflow.multiframe.propagate`).  Independent two-frame flows
  (``init="twoframe"``) lose far frames once the displacement outgrows the
  pyramid; zero motion is the book's start.  The refinement then runs over the
  finest ``refine_levels`` levels (all levels from zero motion).
* **Visibility** (:mod:`varflow.multiframe.visibility`): image bounds,
  forward-backward consistency with backward flows and the photometric residual
  mark the entries of ``U`` that are hidden.  They get no data term
  (``hidden_data_weight``), the link weight ``hidden_link_weight`` and weight 0 in
  the L-step's l1 fit, so they neither pull on the low-rank basis nor keep the
  spurious match of an occluder.
* **Adjacent frames** (``adjacent_link_factor``, ``adjacent_noise``): the two
  frames next to the reference keep a weak link on clean footage, where their
  own data term is better than the low-rank fit of the clip, and the full link on
  noisy frames, where the link averages the noise out; the rule reads the noise
  off the frames (:func:`adjacent_factor`).
* **Decoupled fusion** (``decoupled_fusion``, ``fusion_margin``, ``fusion_noise``,
  ``fusion_softness``): the same initial trajectories are refined a second time
  without the link, and every (pixel, frame) takes the decoupled displacement where
  the soft-census data cost says it fits better by a noise-dependent margin
  (:func:`fuse_decoupled`), the linked one where it does not, and a mixture of the
  two where the cost is within a band around the margin: the link stays where the
  motion is low rank or the frames are too noisy to tell.  A pixel's cost
  difference is joined by that of the textured pixels around it
  (``fusion_evidence``, ``fusion_radius``), so flat regions follow their
  surroundings.
* **L-step sample**: the columns of the l1 filtering's seed are sampled per motion
  cluster (``lowrank_strata``) so that a small moving object has basis vectors.
* **Final repair**: every frame's field is repaired across motion edges
  (:func:`varflow.ops.fusion.repair`, margin scaled by the frames' noise).  This
  repair and the propagation's compare the colours with the reference relit to
  the other frame's light (``repair_cost``, :func:`varflow.ops.fusion.relight`),
  so a change of light does not favour a wrong vector of matching brightness.

Each alternation runs the L-step on the current ``U`` first, then the U-step
linked to that ``L``.

References
----------
J. Gibson, O. Marques, "Optical Flow and Trajectory Estimation Methods",
SpringerBriefs in Computer Science, Springer 2016, ch. 4.

L. Condat, "A primal-dual splitting method for convex optimization involving
Lipschitzian, proximable and linear composite terms", J. Optim. Theory Appl.
158(2), 2013.

A. Chambolle, T. Pock, "A first-order primal-dual algorithm for convex problems
with applications to imaging", J. Math. Imaging Vis. 40(1), 2011.

R. Liu, Z. Lin, S. Yan, J. Sun, X. Yuan, Y. Ma, "Solving principal component
pursuit in linear time via l1 filtering", Neurocomputing 2016.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np

from ..ops.fusion import noise_sigma
from ..ops.prox import prox_certified, prox_faces
from .fuse import fuse_decoupled, regional_evidence, texture_mask
from .lowrank import lowrank_step, matrix_to_trajectories, trajectories_to_matrix
from .params import FINAL_REPAIR_DISTANCES, TVL1_ENERGY, MultiFrameParams, RLRParams
from .refine import (
    Coupling,
    clip_noise_rule,
    fit_gate,
    initial_trajectories,
    refine_trajectories,
    refinement_warps,
)
from .track import TrackCallback
from .ustep import link_channels, set_link_targets, ustep_iterations, ustep_iterations_numpy
from .visibility import visibility_from

__all__ = [
    "track_rlr",
    "adjacent_factor",
    "residual_noise",
    # Re-exported so that code importing them from this module keeps working (varflow
    # itself imports them from their homes): the parameters from
    # varflow.multiframe.params, the refinement from .refine, the fusion from .fuse,
    # the U-step from .ustep, the exact prox from varflow.ops.prox.
    "TVL1_ENERGY",
    "FINAL_REPAIR_DISTANCES",
    "MultiFrameParams",
    "RLRParams",
    "Coupling",
    "initial_trajectories",
    "refine_trajectories",
    "fuse_decoupled",
    "regional_evidence",
    "texture_mask",
    "refinement_warps",
    "clip_noise_rule",
    "fit_gate",
    "ustep_iterations",
    "ustep_iterations_numpy",
    "prox_faces",
    "prox_certified",
    "link_channels",
    "set_link_targets",
]

log = logging.getLogger(__name__)


def _pcp_alpha(tau: float, kappa: float, shape: tuple[int, int]) -> float:
    """Nuclear weight α with ``τ / α = κ / sqrt(max(m, n))``."""
    return tau * math.sqrt(max(shape)) / kappa


def residual_noise(frames: np.ndarray, ref: int) -> float | None:
    """The mean over ``ref ± 1`` of ``hypot(σ_ref, σ_n)``, the noise of a frame
    difference (:func:`varflow.ops.fusion.noise_sigma` of each frame); None for a
    single frame."""
    near = [n for n in (ref - 1, ref + 1) if 0 <= n < frames.shape[0]]
    if not near:
        return None
    s_ref = noise_sigma(frames[ref])
    return float(np.mean([math.hypot(s_ref, noise_sigma(frames[n])) for n in near]))


def adjacent_factor(frames: np.ndarray, ref: int, params: RLRParams) -> float:
    """The link factor ``a_1`` of the frames next to the reference (see :class:`RLRParams`).

    ``a_1 = min(1, max(a_min, (σ/σ_0)²))`` with ``σ`` the mean over ``ref ± 1`` of
    the residual noise ``hypot(σ_ref, σ_n)`` (:func:`varflow.ops.fusion.noise_sigma`
    of each frame), ``a_min = adjacent_link_factor``, ``σ_0 = adjacent_noise``.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32 in [0, 1]
    ref : int
    params : RLRParams

    Returns
    -------
    float
    """
    if params.adjacent_link_factor >= 1:
        return 1.0
    sigma = residual_noise(frames, ref)
    if sigma is None:
        return 1.0
    a = min(1.0, max(float(params.adjacent_link_factor), (sigma / params.adjacent_noise) ** 2))
    log.debug("adjacent frames: residual noise %.4f, link factor %.3f", sigma, a)
    return a


def track_rlr(frames: np.ndarray, ref: int, params: RLRParams,
              callback: TrackCallback | None = None, engine: str = "numba",
              stats: dict | None = None) -> np.ndarray:
    """Robust Low-Rank trajectories (see the module docstring).

    Arguments as in :func:`refine_trajectories`; ``stats`` also gains
    ``lstep_seconds`` and ``ranks`` (the rank found by each L-step, of both
    refinements), and with the decoupled fusion ``decoupled_share`` (the share of the
    (pixel, frame) pairs that took the decoupled displacement, its mean weight with a
    soft fusion), ``fusion_margin`` (the margin m used) and ``decoupled_seconds``;
    ``visible`` is that of the fused result.

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
    """
    stats = {} if stats is None else stats
    tau = float(params.link_weight)
    ranks: list[int] = []
    n_frames = frames.shape[0]
    row_w = np.ones((2 * n_frames, 1), np.float32)
    if params.velocity_rows:
        row_w[:, 0] = np.repeat([1.0 / max(abs(n - ref), 1) for n in range(n_frames)], 2)

    def make_lstep() -> Any:
        bases: dict = {}  # the basis of a level, found at its first warp

        def lstep(traj: np.ndarray, visible: np.ndarray | None) -> np.ndarray:
            umat = trajectories_to_matrix(traj)  # a copy: scaled in place
            umat *= row_w
            kw: dict = {}
            level = traj.shape[1:3]
            if params.lowrank_method == "linear":
                kw = {"seed": params.seed, "rank_tol": params.rank_tol, "residual": False,
                      "l1_tol": params.lowrank_tolerance,
                      "strata": params.lowrank_strata, "rank_rule": params.rank_rule}
                if params.lowrank_samples:
                    kw["n_samples"] = params.lowrank_samples
                if visible is not None:
                    kw["weights"] = np.repeat(visible.reshape(n_frames, -1), 2, axis=0)
                if params.level_basis and level in bases:
                    kw["basis"] = bases[level]
            # only λ = τ/α matters to the L-step (its energy divided by τ)
            alpha = _pcp_alpha(1.0, params.pcp_scale, umat.shape)
            lm, _, info = lowrank_step(umat, alpha, 1.0, method=params.lowrank_method, **kw)
            if params.lowrank_method == "exact":  # the same rank rule as the linear solver
                uu, sv, vt = np.linalg.svd(lm.astype(np.float64), full_matrices=False)
                keep = sv > params.rank_tol * sv[0] if sv.size and sv[0] > 0 else sv > 0
                lm = ((uu[:, keep] * sv[keep]) @ vt[keep]).astype(umat.dtype)
                info["rank"] = int(keep.sum())
            ranks.append(int(info.get("rank", -1)))
            if "basis" in info and info["rank"] > 0:
                bases[level] = info["basis"]
            lm = np.divide(lm, row_w, out=lm if lm.dtype == row_w.dtype else None)
            out = matrix_to_trajectories(lm, traj.shape[1], traj.shape[2])
            out[ref] = 0.0
            return out

        return lstep

    gate = None
    if params.link_gate > 0:
        def gate(traj: np.ndarray, target: np.ndarray, visible: np.ndarray | None) -> np.ndarray:
            return fit_gate(traj, target, ref, visible, params.link_gate)

    a_1 = adjacent_factor(frames, ref, params)
    coupling = Coupling("l1", tau, make_lstep(), edge_scaled=params.link_edge,
                        hidden_weight=float(params.hidden_link_weight),
                        adjacent_factor=a_1, gate=gate)
    fusion = params.decoupled_fusion and tau > 0
    reuse: dict | None = {} if fusion else None
    extra = refinement_warps(frames, params) if fusion else 0
    seen = [0]  # the ticks of the coupled run, which the decoupled one continues

    def first(done: int, total: int) -> None:
        seen[0] = done
        if callback is not None:
            callback(done, total)

    def later(done: int, total: int) -> None:
        if callback is not None:
            callback(seen[0] + done, seen[0] + total)

    traj = refine_trajectories(frames, ref, params, coupling, first, engine, stats,
                               reuse=reuse, extra_ticks=extra)
    lstep_seconds = coupling.seconds
    if reuse is not None:
        t0 = time.perf_counter()
        decoupled = Coupling("l1", 0.0, make_lstep(), edge_scaled=params.link_edge,
                             hidden_weight=float(params.hidden_link_weight),
                             adjacent_factor=a_1)
        dstats: dict = {}
        free = refine_trajectories(frames, ref, params, decoupled, later, engine, dstats,
                                   reuse=reuse)
        sigma = residual_noise(frames, ref) or 0.0
        margin = params.fusion_margin + params.fusion_noise * sigma * sigma
        traj, share = fuse_decoupled(frames, ref, traj, free, margin,
                                      params.fusion_softness, params.fusion_evidence,
                                      params.fusion_radius)
        del free
        back = reuse["backward"]
        if back is not None:
            stats["visible"] = visibility_from(traj, back, ref,
                                               [p[0] for p in reuse["pyramids"]],
                                               params.visibility_params())
        lstep_seconds += decoupled.seconds
        stats.update(decoupled_share=share, fusion_margin=margin,
                     decoupled_seconds=time.perf_counter() - t0,
                     seconds=stats.get("seconds", 0.0) + time.perf_counter() - t0)
    stats.update(lstep_seconds=lstep_seconds, ranks=ranks)
    return traj
