"""Robust Low-Rank (RLR) dense trajectories (Gibson & Marques 2016, ch. 4).

Energy over the trajectories ``U`` of the reference pixels in all ``F`` frames
(matrix view ``(2F, N)``, see :mod:`varflow.multiframe.lowrank`) and an auxiliary
low-rank matrix ``L``::

    E(U, L) = Σ_n [ λ_D Σ_c |ρ_{n,c}(u_n)| + λ_TV Σ_x g(x) (|∇u_{n,1}| + |∇u_{n,2}|) ]
              + α ||L||_*  +  τ ||U − L||_1

with ``ρ_{n,c}`` the colour constancy residual of frame ``n`` against the reference,
linearised around the current estimate and re-warped coarse to fine, and ``g`` the
edge weight of the reference frame.  The data term is TV-L1's whole one (issue 27):
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
   gradient term) and coordinate descent otherwise: for colour both give the same
   errors (coordinate descent against exact: RubberWhale with τ = 0.02 0.0982 /
   0.0983, synthetic suite mean EPE 0.0644 / 0.0646), and for TV-L1's grey + gradient
   term (3 channels) too (a 15-frame noisy photographic clip: 0.300 against 0.303,
   in 0.39 of the time).  With the relaxed data term each iteration first sets
   ``v = prox_{λ_D θ D}(u)`` by the same data-term machinery, then takes the
   primal step with ``G_n = |u − v|²/(2θ) + τ |u − l_n|_1``, in closed form (the
   quadratics' centre moved towards ``l_n`` by the link's soft threshold,
   :func:`_relaxed_primal_row`); its fixed point is the minimiser of TV-L1's relaxed
   energy (tested against TV-L1's own scheme).
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
from dataclasses import dataclass, replace
from typing import Any

import numba as nb
import numpy as np
from scipy.special import expit

from .._jit import FASTMATH
from .._validate import check_field as _check
from ..ops.differences import derivative_planes, divergence, gradient
from ..ops.fusion import (
    census_planes,
    flow_cost,
    fuse,
    noise_sigma,
    repair_with,
    support_weights,
)
from ..ops.primal_dual import (
    F0,
    F1,
    NO_TENSOR,
    dual_row,
    ordered_sum,
    primal_row,
    row_blocks,
)
from ..ops.prox import (
    certify_prox_row,
    data_prox_row,
    project_l2_ball,
    prox_certified,
    prox_faces,
    prox_huber_conjugate,
    prox_linear_l1,
    prox_linear_l1_exact,
    shrink_towards,
    soft_threshold,
)
from ..ops.pyramid import pyramid_shapes, resize_bilinear, resize_flow, smooth_image
from ..ops.warp import warp_bicubic
from ..twoframe.coarse_to_fine import (
    CoarseToFineParams,
    LevelState,
    coarse_to_fine_pyramids,
    guide_pyramid,
    noise_adapted,
    run_levels,
    working_channels,
)
from ..twoframe.methods import DEFAULT_METHOD, METHODS
from ..twoframe.tvl1 import (
    TVL1Params,
    data_channels,
    edge_weight,
    gradient_channel_count,
)
from ..twoframe.tvl1 import solve_warp as tvl1_solve_warp
from .lowrank import lowrank_step, matrix_to_trajectories, trajectories_to_matrix
from .propagate import (
    DEFAULT_REPAIR_COST,
    REPAIR_COSTS,
    frame_pyramids,
    propagate_trajectories,
)
from .track import FlowTrackParams, TrackCallback
from .visibility import VisibilityParams, backward_flows, visibility_from

#: Offsets (pixels) of the final repair.  Tuning split of the photographic clips,
#: mean EPE / occlusion accuracy: (2, 4, 8) 0.874 / 0.966, (2, 4) 0.861 / 0.967,
#: (4,) 0.860 / 0.966 (objects 0.732 → 0.745, illumination 2.93 → 2.84) at a third
#: of the cost of three distances.
FINAL_REPAIR_DISTANCES = (4,)

__all__ = [
    "TVL1_ENERGY",
    "MultiFrameParams",
    "RLRParams",
    "Coupling",
    "initial_trajectories",
    "refine_trajectories",
    "track_rlr",
    "adjacent_factor",
    "residual_noise",
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

#: The default two-frame energy of the multi-frame methods (issue 27): ``tvl1``'s data
#: term and regulariser — the grey channel, λ_D = 15 with gradient constancy γ = 140,
#: Huber-TV ε_H = 0.02, edge weight c = 30, texture α = 0.3 and the noise rule — with
#: the plain energy's solver settings (5 warps per level, 50 iterations of the initial
#: flows), the weighted median on every level (r = 3, as RLR had since issue 11) and no
#: sharpness match (it matches two frames).  rlr on the photographic tuning split (with
#: the link's fit gate, ``link_gate`` 2): mean EPE 0.665 against 0.851 with the book's
#: plain energy (affine 0.034 / 0.041, nonrigid 0.104 / 0.104, objects 0.651 / 0.677,
#: illumination 2.05 / 2.90, noise 0.48 / 0.53).  Without the gate its link drags a small
#: fast object off its track (the fast-object clip of the tests: far frames 5.2-6.7 px
#: over L-step seeds, 0.12 px decoupled).
TVL1_ENERGY = TVL1Params(max_iterations=50, n_warps=5, weighted_median_levels=0,
                         sharpness_match=False)


@dataclass(frozen=True)
class MultiFrameParams(FlowTrackParams):
    """Fields shared by the multi-frame methods (RLR, MFSF), and their two-frame energy.

    Composed, not inherited (issue 27): ``flow_method`` and ``flow_params`` (of
    :class:`~varflow.multiframe.track.FlowTrackParams`) are the two-frame method
    whose energy the trajectories minimise, frame by frame, and whose flows
    initialise them.  Its fields serve the initial flows and the multi-frame
    refinement alike: the pyramid (``scale_factor``, ``min_size``, ``n_warps``…),
    the pre-processing, the median filters, the data term (λ_D = ``data_weight``,
    γ = ``gradient_weight``, ζ = ``data_normalisation``, ``grey``, the noise rule
    ``noise_reference``), Huber-TV (``huber``) and the edge weight
    (``edge_weight``, ``edge_weight_min``), and θ (``coupling``) of the relaxed
    data term (``relaxed_data``); ``max_iterations`` and ``tolerance``
    serve the two-frame flows (the U-step has ``ustep_iterations`` and
    ``ustep_tolerance``).  :func:`varflow.registry.make_track_params` (and so
    :func:`varflow.track` and the CLI) routes a field of the energy to
    ``flow_params``.  The method must be TV-L1's (``tvl1``, ``tvl1-fast``,
    ``tvl1-ld``: the U-step has its data term and isotropic TV); its
    ``sharpness_match`` matches two frames and must be off.  A method named without
    ``flow_params`` takes :meth:`default_flow_params`.

    Attributes
    ----------
    tv_weight : float
        λ_TV, weight of the edge-weighted TV of every frame's displacement
        (relative to λ_D = ``data_weight`` as in TV-L1).  Default 1.
    primal_step : float
        s, primal step of the primal-dual iteration; the dual step is
        σ = 1 / (8 s) (so that s σ ||∇||² ≤ 1).  Default 0.25.
    ustep_iterations : int
        Primal-dual iterations of the U-step per warp and alternation.  Default 50
        (the plain energy's ``max_iterations``, which served both before).
    alternations : int
        Coupling-target / U-step alternations per warp.  Default 1.
    data_prox : {"auto", "exact", "cd"}
        Point-wise prox of data + link terms: exact (dual coordinate descent
        proposes the active set, an optimality certificate accepts it, else face
        enumeration; :func:`prox_certified`), dual coordinate descent alone
        (``data_sweeps`` sweeps per iteration, warm started), or "auto" = exact for
        a one-channel data term (grey frames, no gradient term), coordinate descent
        for more channels (the same errors, the U-step about 5x faster for colour).
    init : {"propagate", "twoframe", "zero"}
        Initial trajectories: propagated outward from the reference and refined
        against it frame by frame
        (:func:`~varflow.multiframe.propagate.propagate_trajectories`), TV-L1 from
        the reference to every frame independently, or zero.  Default "propagate".
    refine_levels : int
        With an initialisation other than "zero", the multi-frame refinement runs
        on this many of the finest pyramid levels, starting from the initial
        trajectories resized to the coarsest of them; 0 = every level.  Restarting
        the refinement from the coarsest level would throw the initialisation's
        detail away.  Default 3.
    ustep_tolerance : float
        Stop a U-step early when the RMS change of a frame's displacement per
        primal-dual iteration is below this many pixels; 0 runs
        ``ustep_iterations`` iterations.  The primal-dual steps are small, so the
        TV-L1 ``tolerance`` (which serves the initialisation) would stop it after a
        few iterations.  Default 0.
    propagate_levels : int
        With ``init="propagate"``: pyramid levels of the refinement of a frame's
        trajectory extrapolated from its neighbours
        (:func:`varflow.multiframe.propagate.propagate_trajectories`).  Default 3.
    propagate_direct : bool
        With ``init="propagate"``: also compute each far frame's direct two-frame
        flow from the reference and keep, per pixel, the candidate that fits the
        frames better.  Default False.
    propagate_matching : bool
        With ``init="propagate"``: add every frame's ``tvl1-ld`` flow from the
        reference (descriptor matches fused into the pyramid, computed as
        ``varflow.flow(frames[ref], frames[n], "tvl1-ld")`` does) as a candidate,
        kept per pixel where it fits the frames better by the census cost of
        :mod:`varflow.multiframe.propagate`, and offer the splatted inverse to the
        visibility's backward flows.  Default True (tuning split of the
        photographic clips, 31 frames: mean EPE 0.578 against 0.665 without,
        lower on every family; affine 0.0334 / 0.0335, nonrigid 0.102 / 0.104,
        objects 0.438 / 0.651, illumination 1.99 / 2.05, noise 0.325 / 0.483).
    visibility : bool
        Estimate which reference points are hidden in which frame from the
        initial trajectories (:mod:`varflow.multiframe.visibility`) and switch the
        data term off there: a hidden point has nothing to match, so the
        regulariser and the coupling decide it.  Default True.
    fb_tolerance : float
        Largest forward-backward error of a visible point, pixels.  Default 1.5.
    photo_factor : float
        A visible point's photometric cost is at most this many times the frame's
        median cost.  Default 4.
    visibility_levels : int
        Pyramid levels of the backward flows of the visibility estimate, refined
        from the inverted initial trajectories.  Default 1 (tuning split of the
        photographic clips: occlusion accuracy 0.966 against 0.959 with 3 levels,
        mean EPE 0.874 for both; a third of the time).
    visibility_warps : int
        Warps per level of those backward flows.  Default 2 (tuning split of the
        photographic clips: mean EPE 0.858 / occlusion accuracy 0.967, against
        0.861 / 0.966 with 5 warps).
    final_repair : bool
        After the refinement, let every pixel of every frame take the vector of a
        pixel a few pixels away where that fits the frames better
        (:func:`varflow.ops.fusion.repair`), as the propagation does: the TV of
        the refinement lets a band of one surface's motion bleed over object
        edges.  It tries the vectors 4 pixels away in 8 directions
        (:data:`FINAL_REPAIR_DISTANCES`); the frames ``ref ± 1`` only with
        ``repair_adjacent``.  Default True.
    repair_adjacent : bool
        Also repair the two frames next to the reference, ``ref ± 1``, in the
        propagation and in the final repair.  Their flows come from the whole
        pyramid (no propagated band along object edges to undo), and on real
        footage the repair's photometric cost is less reliable than those flows:
        on MPI-Sintel final/alley_1 (9-frame windows, frame r+1 against the
        ground truth, references 5…10) the defaults' mean AEE is 0.297, and 0.328
        with this repair (measured while ``adjacent_link_factor`` still spared the
        hidden entries; the two-frame flow: 0.329; at r = 10 0.311 against 0.359).
        Default False.
    repair_cost : {"colour", "relit", "census"}
        The residual that the propagation's repair and the final repair compare
        (:func:`varflow.ops.fusion.repair_with`): the frames' colours; the colours
        with the reference under the other frame's light, fitted along the flow
        (a gain that varies linearly across the frame and an offset,
        :func:`varflow.ops.fusion.relight`); or their soft census planes, which a
        change of light leaves alone but which also drop the colours.  Under a
        change of light the colour cost prefers wrong vectors that land on a
        matching brightness.  Default "relit" (photographic suite, full rlr, mean
        EPE colour → relit: tuning split 0.5529 → 0.2280, illumination 1.9649 →
        0.3272, objects and noise 2 % worse; reporting split 0.6244 → 0.2251,
        illumination 2.3816 → 0.3866; census repaired the light changes as well,
        but its initial trajectories were worse on the tuning split's objects and
        noise clips).
    relaxed_data : bool
        Relax the U-step's data term as TV-L1 does (Zach et al. 2007): the term
        becomes ``min_v |u − v|²/(2θ) + λ_D D(v)`` with θ = ``coupling`` of the
        two-frame energy (0.3), the energy that ``tvl1``'s own solver minimises —
        quadratic for residuals below ``λ_D θ |∇I|²``, L1 beyond.  The link stays an
        exact L1 term on the trajectories.  False keeps the data term itself (the
        book's U-step).  Default True: on real footage the relaxed term is the
        better one (MPI-Sintel final/alley_1, 9-frame windows, frame r + 1: 0.2508
        against 0.2586, lower at every reference r = 5…10; RubberWhale frame 11:
        0.0967 against 0.0992), while the photographic tuning split measures mean
        EPE 0.2284 against 0.2254 (affine and nonrigid lower, objects, illumination
        and noise higher; see benchmarks/HISTORY.md).
    hidden_data_weight : float
        Factor of the data term of the entries marked hidden, in [0, 1]: 0 switches
        it off, 1 keeps it (the visibility then only steers the coupling: the
        L-step's weights and ``hidden_link_weight``).  Default 0 (development clips
        of the tuning split: mean EPE 0.189 against 0.193 with 1; RubberWhale and
        the noisy synthetic clips the same within 1 %).
    """

    tv_weight: float = 1.0
    primal_step: float = 0.25
    ustep_iterations: int = 50
    alternations: int = 1
    data_prox: str = "auto"
    init: str = "propagate"
    refine_levels: int = 3
    ustep_tolerance: float = 0.0
    propagate_levels: int = 3
    propagate_direct: bool = False
    propagate_matching: bool = True
    visibility: bool = True
    fb_tolerance: float = 1.5
    photo_factor: float = 4.0
    visibility_levels: int = 1
    visibility_warps: int = 2
    final_repair: bool = True
    repair_adjacent: bool = False
    repair_cost: str = DEFAULT_REPAIR_COST
    hidden_data_weight: float = 0.0
    relaxed_data: bool = True

    @classmethod
    def default_flow_params(cls, flow_method: str) -> CoarseToFineParams:
        """The energy of a ``flow_method`` named without ``flow_params``:
        :data:`TVL1_ENERGY` for ``tvl1`` (its data term and regulariser), another
        method's defaults with the sharpness match off (it matches two frames)."""
        if flow_method == DEFAULT_METHOD:
            return TVL1_ENERGY
        defaults = super().default_flow_params(flow_method)
        if getattr(defaults, "sharpness_match", False):
            defaults = replace(defaults, sharpness_match=False)
        return defaults

    def __post_init__(self) -> None:
        super().__post_init__()
        _check(METHODS[self.flow_method].solve_warp is tvl1_solve_warp, "flow_method",
               f"the multi-frame U-step has TV-L1's energy (isotropic TV); "
               f"{self.flow_method!r} is not a TV-L1 method")
        _check(not self.flow_params.sharpness_match, "sharpness_match",
               "must be False here: it matches two frames, the multi-frame methods "
               "see a whole clip")
        _check(self.ustep_iterations >= 1, "ustep_iterations",
               f"must be >= 1, got {self.ustep_iterations}")
        _check(self.tv_weight > 0, "tv_weight", f"must be > 0, got {self.tv_weight}")
        _check(self.primal_step > 0, "primal_step", f"must be > 0, got {self.primal_step}")
        _check(self.alternations >= 1, "alternations", f"must be >= 1, got {self.alternations}")
        _check(
            self.data_prox in ("auto", "exact", "cd"),
            "data_prox",
            f"must be 'auto', 'exact' or 'cd', got {self.data_prox!r}",
        )
        _check(
            self.init in ("propagate", "twoframe", "zero"),
            "init",
            f"must be 'propagate', 'twoframe' or 'zero', got {self.init!r}",
        )
        _check(self.refine_levels >= 0, "refine_levels",
               f"must be >= 0, got {self.refine_levels}")
        _check(self.ustep_tolerance >= 0, "ustep_tolerance",
               f"must be >= 0, got {self.ustep_tolerance}")
        _check(self.propagate_levels >= 1, "propagate_levels",
               f"must be >= 1, got {self.propagate_levels}")
        _check(self.repair_cost in REPAIR_COSTS, "repair_cost",
               f"must be 'colour', 'relit' or 'census', got {self.repair_cost!r}")
        _check(0 <= self.hidden_data_weight <= 1, "hidden_data_weight",
               f"must be in [0, 1], got {self.hidden_data_weight}")
        _check(self.visibility_levels >= 1, "visibility_levels",
               f"must be >= 1, got {self.visibility_levels}")
        _check(self.visibility_warps >= 1, "visibility_warps",
               f"must be >= 1, got {self.visibility_warps}")
        self.visibility_params()  # validates fb_tolerance and photo_factor

    def visibility_params(self) -> VisibilityParams:
        """The :class:`~varflow.multiframe.visibility.VisibilityParams` of these fields."""
        return VisibilityParams(fb_tolerance=self.fb_tolerance, photo_factor=self.photo_factor,
                                backward_levels=self.visibility_levels)


@dataclass(frozen=True)
class RLRParams(MultiFrameParams):
    """Parameters of Robust Low-Rank trajectories (and those of :class:`MultiFrameParams`).

    Attributes
    ----------
    link_weight : float
        τ, weight of the robust link ``||U − L||_1`` (per pixel and component, in
        the units of the TV weight); the frames next to the reference take a
        fraction of it on clean footage (``adjacent_link_factor``).  0 decouples
        the frames (no L-step).  Default 2 (chosen on the tuning split of the
        photographic clips, :mod:`varflow.generators.photo`).
    adjacent_link_factor : float
        a_min, the smallest factor of the link weight of the two frames next to
        the reference, ``ref ± 1``: their link weights (τ, and τ_h where hidden)
        are scaled by ``a_1 = min(1, max(a_min, (σ/σ_0)²))``, ``σ`` the noise of their
        residual estimated from the frames (:func:`adjacent_factor`).  Their data
        term is the most reliable of the clip (the smallest displacement,
        occlusion and change of appearance) unless the frames are noisy, while the
        low-rank fit of their rows follows the other frames: on clean real
        footage, whose trajectories are not low rank over a few frames, a strong
        link drags them (RubberWhale frame 11: AEE 0.1305 at a_1 = 1, 0.0987 with
        the rule, a_1 ≈ 0.011, against 0.0994 for the two-frame flow), and on noisy frames
        the link is what averages the noise out (the noisy procedural clip of the
        tests, σ ≈ 0.04: mean EPE 0.074 at a_1 = 1, 0.101 at 0.1).  In [0, 1];
        1 links every frame alike.  Default 0.01.
    adjacent_noise : float
        σ_0 of that rule, intensity units of [0, 1] frames: the residual noise at
        which the adjacent frames are linked as strongly as the others (a_1 = 1);
        the weight falls with the square of the noise, as the inverse variance
        of the data term's estimate would.  Default 0.08.
    hidden_link_weight : float
        τ_h, the link weight of the entries the visibility estimate marks hidden
        (they have nothing reliable to match, so the low-rank fit should decide
        them rather than the TV of their neighbours).  Default 2.
    pcp_scale : float
        κ: the L-step solves PCP with ``λ = τ/α = κ / sqrt(max(2F, N))`` (the
        standard weight of Candès et al. for κ = 1); it sets the nuclear-norm weight
        α.  Larger κ keeps more rank.  Default 1.
    rank_tol : float
        Relative singular-value threshold of the L-step's basis: directions of the
        seed PCP's low-rank part with ``σ_i ≤ rank_tol · σ_1`` are dropped (the
        rank is estimated, never given).  Dense estimation noise otherwise enters
        ``L`` as many tiny singular values.  Default 0.003 (tuning split of the
        photographic clips: 0.03 underfits a small moving object, fitted to the
        exact trajectories it leaves 0.44 px against 0.02 px).
    rank_rule : {"relative", "noise"}
        Rank of the L-step's basis: the ``rank_tol`` threshold relative to the
        largest singular value, or the optimal hard threshold of Gavish & Donoho
        (2014) for the noise level estimated from the singular values
        (:func:`varflow.multiframe.lowrank.noise_rank`).  Default "relative"
        (RubberWhale frame-11 AEE 0.132 against 0.141 with "noise").
    lowrank_method : {"linear", "exact"}
        L-step solver: l1 filtering on a random column sample (linear cost) or full
        PCP (reference; its L is truncated by the same ``rank_tol`` rule).
        Default "linear".
    lowrank_samples : int
        Columns sampled by the linear L-step; 0 = the solver's default
        (``max(20 · 2F, 4000)``, :data:`varflow.multiframe.lowrank.DEFAULT_MIN_SAMPLES`).
        Default 0.
    seed : int
        Seed of the L-step's column sampling (local generator).  Default 0.
    link_edge : bool
        Scale the link weight by the edge weight g(x) (weaker link across image
        edges).  Default False.
    velocity_rows : bool
        Run the L-step on mean velocities: frame n's rows divided by ``|n − ref|``
        (then multiplied back), so that far frames, whose displacements are larger,
        do not dominate the fit; constant-velocity motion becomes rank 2.
        Default True (synthetic suite: mean EPE 0.0644 against 0.0674 without;
        RubberWhale frame-11 AEE 0.176 against 0.283).
    lowrank_strata : int
        Motion clusters of the L-step's stratified column sample
        (:func:`varflow.multiframe.lowrank.sample_columns`); 0 = a uniform sample,
        which can miss a small moving object.  Default 8.
    level_basis : bool
        Find the low-rank basis (seed PCP and rank) at the first warp of every
        pyramid level and keep it for the level's other warps, which then only
        refit every column to it (l1 filtering).  Default True.
    lowrank_tolerance : float
        Relative residual at which the l1 fit of a column stops
        (:func:`varflow.multiframe.lowrank.l1_regression`, ``tol``).  The fit is a
        target for the next U-step, not a result: 1e-4 differs from 1e-7 by
        2.5e-4 px on average and takes 0.6× the iterations.  Default 1e-4.

    link_gate : float
        k of the link's fit gate (:func:`fit_gate`): the link weight of the visible
        entries of a region is scaled by ``1 / (1 + (r / (k m))²)``, ``r`` the
        region's misfit to the low-rank target and ``m`` the clip's median misfit,
        so that where the motion is not low rank the refinement is decoupled; 0
        turns the gate off.  Default 1 (tuning split of the photographic clips with
        the matching-guided candidates: mean EPE 0.564 at k = 1 against 0.578 at
        k = 2, lower or equal on every family; the decoupled refinement,
        ``link_weight=0``, 0.535: the link still costs on the objects and
        illumination families.  The fast-object clip of the tests, far frames
        0.22-0.48 px at k = 1, 0.36-1.04 at k = 2, 0.9-4.4 ungated, 0.12-0.15
        decoupled).
    decoupled_fusion : bool
        Also refine without the link (``link_weight = 0``, the same initial
        trajectories and visibility) and keep, per pixel and frame, whichever of
        the two fits the frames better by the soft-census cost
        (:func:`fuse_decoupled`), the linked one unless the decoupled one is better
        by the margin ``m = fusion_margin + fusion_noise · σ²``, σ the residual noise
        of the frames (:func:`residual_noise`), blended near the margin
        (``fusion_softness``).  The link thus stays where the
        motion is low rank or the frames are too noisy to tell, and gives way where
        it pulls a region off its data.  Default True (tuning split of the
        photographic clips, warm kernel cache, the two refinements fused after the
        fact: mean EPE 0.544 against 0.581 without and 0.567 for ``link_weight=0``;
        below the decoupled refinement on every family and below the linked one on
        every family but affine, 0.0338 against 0.0336).  Costs a second refinement
        (not a second initialisation).
    fusion_margin : float
        m₀, the cost advantage the decoupled displacement needs on clean frames
        (units of the truncated census cost, :func:`varflow.ops.fusion.flow_cost`).
        Default 0.005 (tuning split with ``fusion_noise`` 0: margin 0 gives 0.5454
        with affine 0.0396, 0.005 gives 0.5449, 0.02 gives 0.5497).
    fusion_noise : float
        β of the margin's noise term ``β σ²``: on noisy frames a lower census cost
        is as likely the noise as the motion.  Default 15 (tuning split 0.5442; 5
        gives 0.5439, 30 0.5453; a 12-frame affine clip with noise σ = 0.04, σ_r =
        0.057: margin 0 gives 0.117, 0.005 gives 0.109, 0.054 (β = 15) 0.090, the
        linked refinement alone 0.089, the decoupled one 0.147).
    fusion_softness : float
        κ, the width of the fusion's blend as a fraction of the margin m
        (:func:`fuse_decoupled`): the decoupled displacement's weight is the
        logistic function of ``(C_c − C_d − m) / (κ m)``, ½ at a cost advantage of m
        and near 0 or 1 a few κ·m away, so the two refinements are mixed where the
        census cost hardly tells them apart; 0 is the hard choice.  Default 0.5
        (tuning split, the same refinements fused afterwards: mean EPE / far EPE
        0.2279 / 0.489 hard, 0.2254 / 0.483 at 0.5, 0.2253 / 0.481 at 1, 0.2267 /
        0.483 at 2; at 0.5 lower or equal on every family, affine 0.0331 against
        0.0332, illumination 0.3245 against 0.3280).
    fusion_evidence : float
        γ, the weight of the region's cost difference in the fusion
        (:func:`fuse_decoupled`): a pixel's ``C_c − C_d`` gains γ times its mean
        over the textured pixels around it, so that a flat region, where both runs
        fit the frames equally, follows the textured surroundings that tell them
        apart.  0 compares each pixel alone (0.7.1).  Default 3 (tuning
        split, the two refinements of 0.7.1 fused afterwards, mean EPE / mean far
        EPE over the families: 0 0.2317 / 0.4748; γ 1 / 2 / 3 at radius 8 0.2288 /
        0.4658, 0.2281 / 0.4639, 0.2279 / 0.4637; at radius 16 0.2293 / 0.2287 /
        0.2286; over the whole frame 0.2293 / 0.2285 / 0.2284; every family lower at
        γ 3, radius 8, than at 0).
    fusion_radius : float
        σ of the region of ``fusion_evidence``, pixels.  Default 8 (see there).

    The default energy is :data:`TVL1_ENERGY` (:meth:`MultiFrameParams.default_flow_params`);
    ``flow_params=PlainTVL1Params(weighted_median_radius=3)`` is the book's plain
    energy with the weighted median, RLR's default before issue 27.
    """

    link_weight: float = 2.0
    adjacent_link_factor: float = 0.01
    adjacent_noise: float = 0.08
    hidden_link_weight: float = 2.0
    pcp_scale: float = 1.0
    rank_tol: float = 0.003
    rank_rule: str = "relative"
    lowrank_method: str = "linear"
    lowrank_samples: int = 0
    seed: int = 0
    link_edge: bool = False
    velocity_rows: bool = True
    lowrank_strata: int = 8
    level_basis: bool = True
    lowrank_tolerance: float = 1e-4
    link_gate: float = 1.0
    decoupled_fusion: bool = True
    fusion_margin: float = 0.005
    fusion_noise: float = 15.0
    fusion_softness: float = 0.5
    fusion_evidence: float = 3.0
    fusion_radius: float = 8.0

    def __post_init__(self) -> None:
        super().__post_init__()
        _check(self.link_weight >= 0, "link_weight", f"must be >= 0, got {self.link_weight}")
        _check(self.hidden_link_weight >= 0, "hidden_link_weight",
               f"must be >= 0, got {self.hidden_link_weight}")
        _check(0 <= self.adjacent_link_factor <= 1, "adjacent_link_factor",
               f"must be in [0, 1], got {self.adjacent_link_factor}")
        _check(self.adjacent_noise > 0, "adjacent_noise",
               f"must be > 0, got {self.adjacent_noise}")
        _check(self.pcp_scale > 0, "pcp_scale", f"must be > 0, got {self.pcp_scale}")
        _check(0 < self.rank_tol < 1, "rank_tol", f"must be in (0, 1), got {self.rank_tol}")
        _check(
            self.lowrank_method in ("linear", "exact"),
            "lowrank_method",
            f"must be 'linear' or 'exact', got {self.lowrank_method!r}",
        )
        _check(self.rank_rule in ("relative", "noise"), "rank_rule",
               f"must be 'relative' or 'noise', got {self.rank_rule!r}")
        _check(self.lowrank_strata >= 0, "lowrank_strata",
               f"must be >= 0, got {self.lowrank_strata}")
        _check(0 < self.lowrank_tolerance < 1, "lowrank_tolerance",
               f"must be in (0, 1), got {self.lowrank_tolerance}")
        _check(self.link_gate >= 0, "link_gate", f"must be >= 0, got {self.link_gate}")
        _check(self.fusion_margin >= 0, "fusion_margin",
               f"must be >= 0, got {self.fusion_margin}")
        _check(self.fusion_noise >= 0, "fusion_noise",
               f"must be >= 0, got {self.fusion_noise}")
        _check(self.fusion_softness >= 0, "fusion_softness",
               f"must be >= 0, got {self.fusion_softness}")
        _check(self.fusion_evidence >= 0, "fusion_evidence",
               f"must be >= 0, got {self.fusion_evidence}")
        _check(self.fusion_radius > 0, "fusion_radius",
               f"must be > 0, got {self.fusion_radius}")
        _check(
            self.lowrank_samples >= 0,
            "lowrank_samples",
            f"must be >= 0, got {self.lowrank_samples}",
        )


def link_channels(ix: np.ndarray, iy: np.ndarray, a: np.ndarray, lk: np.ndarray | None,
                  ratio: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Append the link terms ``(τ/λ_D) |u_k − l_k|`` as two extra data "channels".

    ``τ |u_k − l_k| = λ_D |r (u_k − l_k)|`` with ``r = τ / λ_D``: a linear-L1 term
    with gradient ``r e_k`` and constant ``−r l_k``, so the data prox of TV-L1
    treats it like a colour channel.

    Parameters
    ----------
    ix, iy, a : ndarray, shape (C, H, W)
        Linearised data terms of one frame.
    lk : ndarray, shape (2, H, W), or None
        The low-rank trajectories of this frame; None (or ``ratio == 0``) adds nothing.
    ratio : float or ndarray, shape (H, W)
        ``τ / λ_D`` (per pixel when an array, e.g. scaled by the edge weight).

    Returns
    -------
    ix, iy, a : ndarray, shape (C + 2, H, W) (or (C, H, W)), float32
    """
    if lk is None or (np.isscalar(ratio) and ratio == 0):
        return ix, iy, a
    c, h, w = a.shape
    r = np.asarray(ratio, np.float32)
    ixe = np.zeros((c + 2, h, w), np.float32)
    iye = np.zeros((c + 2, h, w), np.float32)
    ae = np.empty((c + 2, h, w), np.float32)
    ixe[:c], iye[:c], ae[:c] = ix, iy, a
    ixe[c] = r
    iye[c + 1] = r
    set_link_targets(ae, c, lk, r)
    return ixe, iye, ae


def set_link_targets(a: np.ndarray, n_data: int, lk: np.ndarray,
                     ratio: float | np.ndarray) -> None:
    """Point the link channels of :func:`link_channels` at new targets, in place.

    ``a[n_data:] = −(τ/λ_D) lk``; the gradients of the link channels do not change.
    """
    a[n_data:] = -np.asarray(ratio, np.float32) * lk


# ------------------------------------------------------------------------ U-step
@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _ustep_primal_row(ix, iy, a, q, u, p, ubar, m, beta, i, old, s, t, n_sweeps, exact, sc):
    """Primal step of row ``i``: ``ũ = prox_{sG}(u + s div p)``; ``ubar = 2ũ − u``.

    With ``beta > 0``, ``G`` has the extra term ``β/2 |u − m|²``, folded into the prox:
    ``prox_{sG}(z) = prox_{s' G_0}((z + sβ m) / (1 + sβ))`` with ``s' = s / (1 + sβ)``.
    """
    w = u.shape[2]
    o1 = old[0]
    o2 = old[1]
    for j in range(w):
        o1[j] = u[0, i, j]
        o2[j] = u[1, i, j]
    primal_row(u, p, i, 0, o1, s)  # u = old + s div p (reads p only)
    primal_row(u, p, i, 1, o2, s)
    d1 = u[0, i]
    d2 = u[1, i]
    if beta > F0:
        sb = s * beta
        c = F1 / (F1 + sb)
        m1 = m[0, i]
        m2 = m[1, i]
        for j in range(w):
            d1[j] = (d1[j] + sb * m1[j]) * c
            d2[j] = (d2[j] + sb * m2[j]) * c
        t = t * c
    b1 = ubar[0, i]
    b2 = ubar[1, i]
    if exact:  # keep the prox argument z in ubar's row until the end
        for j in range(w):
            b1[j] = d1[j]
            b2[j] = d2[j]
    data_prox_row(ix, iy, a, q, i, d1, d2, t, n_sweeps)
    if exact:  # certify the active set the dual descent found (see prox_certified)
        certify_prox_row(ix, iy, a, q, i, b1, b2, d1, d2, t, sc)
    return _extrapolate_row(u, ubar, i, o1, o2)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _extrapolate_row(u, ubar, i, o1, o2):
    """``ubar = 2u − old`` on row ``i``; returns the squared change of the row."""
    d1 = u[0, i]
    d2 = u[1, i]
    b1 = ubar[0, i]
    b2 = ubar[1, i]
    err = F0
    for j in range(u.shape[2]):
        e1 = d1[j] - o1[j]
        e2 = d2[j] - o2[j]
        err += e1 * e1 + e2 * e2
        b1[j] = d1[j] + e1
        b2[j] = d2[j] + e2
    return err


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _relaxed_primal_row(ix, iy, a, q, u, p, v, m, beta, i, old, s, lam, theta, n_data,
                        n_sweeps, exact, sc, ubar):
    """Primal step of row ``i`` of the relaxed U-step (``theta`` = θ > 0).

    The energy is ``TV(u) + |u − v|²/(2θ) + λ D(v) + link(u) [+ β/2 |u − m|²]``, TV-L1's
    relaxation of the data term ``D`` (Zach et al.) with the link kept exact on
    ``u``.  First ``v = prox_{λθ D}(u)`` (the data channels ``< n_data`` only), then
    ``u = prox_{s G}(u + s div p)`` with ``G = |u − v|²/(2θ) + link [+ β/2 |u − m|²]``:
    the quadratics combine into one centre ``c`` with weight ``W = 1/s + 1/θ + β``, and
    each link channel ``λ r_k |u_k − l_k|`` moves ``c_k`` towards ``l_k`` by at most
    ``λ r_k / W``.  ``v``: (2, W) scratch for the row of ``v``.
    """
    w = u.shape[2]
    o1 = old[0]
    o2 = old[1]
    v1 = v[0]
    v2 = v[1]
    for j in range(w):
        o1[j] = u[0, i, j]
        o2[j] = u[1, i, j]
        v1[j] = o1[j]
        v2[j] = o2[j]
    dx = ix[:n_data]
    dy = iy[:n_data]
    da = a[:n_data]
    dq = q[:n_data]
    lt = lam * theta
    data_prox_row(dx, dy, da, dq, i, v1, v2, lt, n_sweeps)
    if exact:
        certify_prox_row(dx, dy, da, dq, i, o1, o2, v1, v2, lt, sc[:, :n_data])
    primal_row(u, p, i, 0, o1, s)  # u = old + s div p (reads p only)
    primal_row(u, p, i, 1, o2, s)
    d1 = u[0, i]
    d2 = u[1, i]
    inv_s = F1 / s
    inv_th = F1 / theta
    wq = inv_s + inv_th + beta
    inv_w = F1 / wq
    link = a.shape[0] > n_data
    for j in range(w):
        c1 = inv_s * d1[j] + inv_th * v1[j]
        c2 = inv_s * d2[j] + inv_th * v2[j]
        if beta > F0:
            c1 += beta * m[0, i, j]
            c2 += beta * m[1, i, j]
        c1 *= inv_w
        c2 *= inv_w
        if link:
            r1 = ix[n_data, i, j]
            r2 = iy[n_data + 1, i, j]
            if r1 > F0:
                c1 = shrink_towards(c1, -a[n_data, i, j] / r1, lam * r1 * inv_w)
            if r2 > F0:
                c2 = shrink_towards(c2, -a[n_data + 1, i, j] / r2, lam * r2 * inv_w)
        d1[j] = c1
        d2[j] = c2
    return _extrapolate_row(u, ubar, i, o1, o2)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def ustep_iterations(ix, iy, a, g, u, p, q, ubar, m, beta, lam, s, max_iter, tol, n_sweeps,
                     exact, blocks, huber=F0, theta=F0, n_data=-1):
    """Numba primal-dual (Condat / Chambolle-Pock) iterations of one frame's U-step.

    Minimises ``λ Σ_k |a_k + (ix_k, iy_k)·u| + Σ_x g (|∇u_1| + |∇u_2|)`` (the data and
    link terms of :func:`link_channels`, the TV weight folded into ``g``; with
    ``theta`` > 0 the data terms relaxed), with
    Huber-TV ``g h_ε(|∇u_k|)`` when ``huber`` = ε_H > 0; updates ``u``, ``p``, ``q``
    and the scratch ``ubar`` in place.

    Parameters
    ----------
    ix, iy, a : (K, H, W) float32
        Linear-L1 terms (zero where a data term is off).
    g : (H, W) float32
        Radius of the dual ball, ``λ_TV g(x)``.
    u : (2, H, W) float32
        Displacement of this frame, planar.
    p : (4, H, W) float32
        Dual TV variables (p1x, p1y, p2x, p2y).
    q : (K, H, W) float32
        Dual variables of the point-wise prox (warm start, updated).
    ubar : (2, H, W) float32
        Scratch for the extrapolated primal ``2ũ − u``.
    m : (2, H, W) float32
        Target of the quadratic coupling ``β/2 |u − m|²`` (MFSF's subspace
        projection); read only if ``beta > 0``.
    beta : float
        β ≥ 0; 0 switches the quadratic coupling off.
    lam, s : float
        λ_D and the primal step s; the dual step is ``1 / (8 s)``.
    max_iter : int
    tol : float
        Stop when the RMS change of ``u`` is below ``tol`` pixels.
    n_sweeps : int
        Coordinate-descent sweeps per iteration.
    exact : bool
        Certify every pixel's prox (see :func:`prox_certified`) instead of keeping
        the coordinate-descent point.
    blocks : (n+1,) int64
        Row-block bounds.
    huber : float
        ε_H of Huber-TV (the dual step becomes the prox of its conjugate, as in
        TV-L1's :func:`~varflow.twoframe.tvl1.tvl1_iterations`); 0 gives TV.
    theta : float
        θ > 0 relaxes the data term as TV-L1 does (Zach et al. 2007): the U-step
        minimises ``min_v |u − v|²/(2θ) + λ Σ_k |ρ_k(v)|`` (the Moreau envelope of the
        data term, quadratic for small residuals) plus TV and the link, which stays
        an L1 term on ``u`` (see :func:`_relaxed_primal_row`); 0 gives the data term
        itself.
    n_data : int
        The channels of ``a`` that are data terms; the rest (two) are the link's
        (:func:`link_channels`).  Read only with ``theta`` > 0; −1: all channels.

    Returns
    -------
    int
        Iterations performed.
    """
    nk, h, w = a.shape
    t = lam * s
    nd = nk if n_data < 0 else n_data
    relaxed = theta > F0
    sigma = F1 / (np.float32(8.0) * s)
    tol2 = tol * tol
    n_blk = blocks.shape[0] - 1
    errs = np.zeros(h, np.float64)  # per row: the stopping test does not depend on blocks
    old = np.empty((n_blk, 2, w), np.float32)
    vrow = np.empty((n_blk, 2, w), np.float32)  # v of the relaxed data term, one row
    sc = np.empty((n_blk, 4, nk), np.float64)
    it = 0
    while it < max_iter:
        it += 1
        for b in nb.prange(n_blk):
            for i in range(blocks[b], blocks[b + 1]):
                if relaxed:
                    errs[i] = _relaxed_primal_row(ix, iy, a, q, u, p, vrow[b], m, beta, i,
                                                  old[b], s, lam, theta, nd, n_sweeps, exact,
                                                  sc[b], ubar)
                else:
                    errs[i] = _ustep_primal_row(ix, iy, a, q, u, p, ubar, m, beta, i, old[b],
                                                s, t, n_sweeps, exact, sc[b])
        for b in nb.prange(n_blk):
            for i in range(blocks[b], blocks[b + 1]):
                dual_row(ubar, p, p, g, NO_TENSOR, i, sigma, False, huber)
        if ordered_sum(errs) / (h * w) < tol2:
            break
    return it


def _relaxed_prox_numpy(ix, iy, a, q, old, z, m, beta, lam, s, theta, n_data, n_sweeps,
                        exact):
    """The relaxed primal step of :func:`ustep_iterations_numpy` (see
    :func:`_relaxed_primal_row`); returns ``u`` channels last and updates ``q``."""
    nd = a.shape[0] if n_data < 0 else n_data
    hw = lambda x: np.moveaxis(x, 0, -1)  # noqa: E731
    lt = lam * theta
    if exact:
        v = prox_linear_l1_exact(hw(old), hw(a[:nd]), hw(ix[:nd]), hw(iy[:nd]), lt)
    else:
        v, qn = prox_linear_l1(hw(old), hw(a[:nd]), hw(ix[:nd]), hw(iy[:nd]), lt,
                               n_sweeps=n_sweeps, q0=hw(q[:nd]))
        q[:nd] = np.moveaxis(qn, -1, 0)
    wq = 1.0 / s + 1.0 / theta + beta
    c = (hw(z) / s + v / theta + (beta * hw(m) if beta > 0 else 0.0)) / wq
    for k in range(a.shape[0] - nd):  # the link channels: λ r_k |u_k − l_k|
        r = (ix if k == 0 else iy)[nd + k]
        lk = np.where(r > 0, -a[nd + k] / np.where(r > 0, r, 1), 0)
        thr = lam * r / wq
        c[..., k] = np.where(r > 0, lk + soft_threshold(c[..., k] - lk, thr), c[..., k])
    return c


def ustep_iterations_numpy(ix, iy, a, g, u, p, q, ubar, m, beta, lam, s, max_iter, tol,
                           n_sweeps, exact, blocks=None, huber=0.0, theta=0.0, n_data=-1):
    """NumPy reference of :func:`ustep_iterations` (same arguments, in-place updates)."""
    _, h, w = a.shape
    t = float(lam) * float(s)
    sigma = 1.0 / (8.0 * float(s))
    hw = lambda x: np.moveaxis(x, 0, -1)  # noqa: E731 - planar -> channels last view
    it = 0
    while it < max_iter:
        it += 1
        old = u.copy()
        z = np.stack([u[k] + s * divergence(hw(p[2 * k: 2 * k + 2])) for k in (0, 1)])
        if beta > 0 and theta <= 0:
            z = (z + s * beta * m) / (1 + s * beta)
            t = float(lam) * float(s) / (1 + float(s) * float(beta))
        if theta > 0:
            d = _relaxed_prox_numpy(ix, iy, a, q, old, z, m, float(beta), float(lam),
                                    float(s), float(theta), n_data, n_sweeps, exact)
        elif exact:
            d = prox_linear_l1_exact(hw(z), hw(a), hw(ix), hw(iy), t)
        else:
            d, qn = prox_linear_l1(hw(z), hw(a), hw(ix), hw(iy), t, n_sweeps=n_sweeps,
                                   q0=hw(q))
            q[...] = np.moveaxis(qn, -1, 0)
        u[...] = np.moveaxis(d, -1, 0)
        ubar[...] = 2 * u - old
        for k in (0, 1):
            pk = hw(p[2 * k: 2 * k + 2]) + sigma * gradient(ubar[k])
            if huber > 0:  # the prox of the conjugate of g h_ε: shrink, then project
                pk = prox_huber_conjugate(pk, sigma, float(huber), g)
            else:
                pk = project_l2_ball(pk, g)
            p[2 * k: 2 * k + 2] = np.moveaxis(pk, -1, 0)
        if float(((u - old) ** 2).sum()) / (h * w) < tol * tol:
            break
    return it


# ------------------------------------------------------------------------ driver
def _pcp_alpha(tau: float, kappa: float, shape: tuple[int, int]) -> float:
    """Nuclear weight α with ``τ / α = κ / sqrt(max(m, n))``."""
    return tau * math.sqrt(max(shape)) / kappa


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
                      link_ratio: Any, energy: TVL1Params, level_state: LevelState) -> tuple:
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
    data : LevelState
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
    data: LevelState
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
            data=LevelState(level=level))

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


def texture_mask(image: np.ndarray) -> np.ndarray:
    """The textured half of an image: gradient magnitude of its channel mean above the median.

    Parameters
    ----------
    image : ndarray, shape (H, W[, C]), float

    Returns
    -------
    ndarray, shape (H, W), float32, 0 or 1 (all 0 on a flat image)
    """
    grey = np.asarray(image, np.float32)
    if grey.ndim == 3:
        grey = grey.mean(axis=-1)
    gy, gx = np.gradient(grey)
    mag = np.hypot(gx, gy)
    return (mag > np.median(mag)).astype(np.float32)


def regional_evidence(diff: np.ndarray, texture: np.ndarray, radius: float,
                      support: np.ndarray | None = None) -> np.ndarray:
    """The Gaussian-weighted mean of ``diff`` over the textured pixels around each pixel.

    ``E = G_σ * (diff · t) / G_σ * t`` (:func:`varflow.ops.pyramid.smooth_image`,
    σ = ``radius``), 0 where no textured pixel is near (``G_σ * t`` < 1e-6).

    Parameters
    ----------
    diff : ndarray, shape (H, W), float32
    texture : ndarray, shape (H, W), float32
        :func:`texture_mask` of the reference.
    radius : float
        σ in pixels.
    support : ndarray, shape (H, W), float32, optional
        ``G_σ * t``, when the caller smooths one texture for many ``diff``
        (computed here when omitted).

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    num = smooth_image((diff * texture)[..., None], radius)[..., 0]
    den = smooth_image(texture[..., None], radius)[..., 0] if support is None else support
    out = np.zeros_like(num)
    np.divide(num, den, out=out, where=den >= 1e-6)
    return out


def fuse_decoupled(frames: np.ndarray, ref: int, coupled: np.ndarray, decoupled: np.ndarray,
                   margin: float, softness: float = 0.0, evidence: float = 0.0,
                   radius: float = 8.0) -> tuple[np.ndarray, float]:
    """Per pixel and frame, the coupled or the decoupled trajectory, by the data.

    For every frame ``n ≠ ref`` the edge-aware soft-census cost of both
    displacement fields (:func:`varflow.ops.fusion.flow_cost` on
    :func:`~varflow.ops.fusion.census_planes`, truncation 0.5, the support weights
    of the reference) is compared.  With ``softness`` 0 the decoupled displacement
    is kept where its cost ``C_d`` is lower than the coupled one's ``C_c`` by more
    than ``margin`` (as :func:`varflow.ops.fusion.fuse` with that margin).  With
    ``softness`` κ > 0 the two are blended,

    ``w = 1 / (1 + exp(−(C_c − C_d − m) / (κ m)))``,  ``u = u_c + w (u_d − u_c)``,

    a logistic step of width κ·m centred on the margin: where the cost tells the two
    apart clearly the result is the better one, and where it hardly does (a flat
    region, a change of light) it is a mixture, which lies between the two and is
    closer than either where their errors point different ways.  The low-rank link
    thus stays where the frames do not say otherwise, and a region whose motion the
    link has pulled off the data gets the decoupled refinement back.

    With ``evidence`` γ > 0 the cost difference of a pixel is joined by that of its
    region: ``C_c − C_d`` is replaced by ``C_c − C_d + γ E``, E the mean of
    ``C_c − C_d`` over the textured pixels within about ``radius`` pixels
    (:func:`regional_evidence` on :func:`texture_mask` of the reference).  Where
    the two runs fit equally (a flat sky, a smooth wall) the textured surroundings,
    whose costs do tell them apart, decide: if the link has pulled the textured
    part of a region off its data in frame n, it is not trusted over the flat part
    either.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32
    ref : int
    coupled, decoupled : ndarray, shape (F, H, W, 2), float32
        Trajectories refined with the link and without it (``link_weight = 0``).
    margin : float
        m, the cost advantage the decoupled displacement needs (the centre of the
        blend when ``softness`` > 0).
    softness : float
        κ, the width of the blend as a fraction of ``margin``; 0 (or ``margin`` 0)
        is the hard choice.
    evidence : float
        γ, the weight of the regional cost difference; 0 compares each pixel alone.
    radius : float
        σ of the region, pixels.

    Returns
    -------
    traj : ndarray, shape (F, H, W, 2), float32
    share : float
        Mean weight of the decoupled displacement over the (pixel, frame) pairs,
        reference excluded (with the hard choice, the share that took it).
    """
    out = np.array(coupled, np.float32, copy=True)
    planes = census_planes(frames[ref])
    weights = support_weights(frames[ref])
    width = float(softness) * float(margin)
    texture = texture_mask(frames[ref]) if evidence > 0 else None
    support = None  # G_σ * texture: the same for every frame
    if texture is not None:
        support = smooth_image(texture[..., None], radius)[..., 0]
    taken = 0.0
    others = [n for n in range(frames.shape[0]) if n != ref]
    for n in others:
        planes_n = census_planes(frames[n])
        if width > 0 or texture is not None:
            cost_c = flow_cost(planes, planes_n, coupled[n], weights, truncation=0.5)
            cost_d = flow_cost(planes, planes_n, decoupled[n], weights, truncation=0.5)
            diff = cost_c - cost_d
            if texture is not None:
                diff = diff + np.float32(evidence) * regional_evidence(diff, texture, radius,
                                                                       support)
            if width > 0:
                w = expit((diff - np.float32(margin)) / np.float32(width))
                out[n] += w[..., None] * (np.asarray(decoupled[n], np.float32) - out[n])
                taken += float(w.sum(dtype=np.float64))
            else:  # the hard choice keeps either displacement bit for bit
                choice = diff > np.float32(margin)
                out[n][choice] = np.asarray(decoupled[n], np.float32)[choice]
                taken += int(choice.sum())
        else:
            out[n], choice = fuse(planes, planes_n, [coupled[n], decoupled[n]], weights,
                                  truncation=0.5, margin=margin)
            taken += int(choice.sum())
    share = taken / max(1, len(others) * frames.shape[1] * frames.shape[2])
    return out, float(share)


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
            umat = trajectories_to_matrix(traj) * row_w
            kw: dict = {}
            level = traj.shape[1:3]
            if params.lowrank_method == "linear":
                kw = {"seed": params.seed, "rank_tol": params.rank_tol,
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
            out = matrix_to_trajectories(lm / row_w, traj.shape[1], traj.shape[2])
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
