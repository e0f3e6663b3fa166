"""The parameters of the multi-frame methods.

:class:`MultiFrameParams` (the fields shared by RLR and MFSF, with their two-frame
energy), :class:`RLRParams` (RLR's own), the default energy :data:`TVL1_ENERGY` and
the offsets of the final repair, :data:`FINAL_REPAIR_DISTANCES`.  The methods are
described in :mod:`varflow.multiframe.rlr` and :mod:`varflow.multiframe.mfsf`; the
refinement that reads most of these fields is :mod:`varflow.multiframe.refine`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .._validate import check_field as _check
from ..registry import DEFAULT_METHOD, FLOW
from ..twoframe.methods import FlowComposed
from ..twoframe.params import PRESETS, TVL1Params
from ..twoframe.tvl1 import solve_warp as tvl1_solve_warp
from .propagate import DEFAULT_REPAIR_COST, REPAIR_COSTS
from .visibility import VisibilityParams

__all__ = ["TVL1_ENERGY", "FINAL_REPAIR_DISTANCES", "MultiFrameParams", "RLRParams"]

#: Offsets (pixels) of the final repair.  Default (4,): as accurate on the photographic
#: clips as (2, 4) and (2, 4, 8), at a third of the cost of three distances; see
#: benchmarks/HISTORY.md.
FINAL_REPAIR_DISTANCES = (4,)

#: The default two-frame energy of the multi-frame methods: ``tvl1``'s data term and
#: regulariser — the grey channel, λ_D = 15 with gradient constancy γ = 140, Huber-TV
#: ε_H = 0.02, edge weight c = 30, texture α = 0.3 and the noise rule — with the plain
#: energy's solver settings (5 warps per level, 50 iterations of the initial flows), the
#: weighted median on every level (r = 3) and no sharpness match (it matches two
#: frames).  With it rlr is more accurate than with the book's plain energy on the
#: photographic clips, most under a change of light; the link's fit gate (``link_gate``)
#: keeps its link from dragging a small fast object off its track.  See
#: benchmarks/HISTORY.md.
TVL1_ENERGY = PRESETS["multiframe"]


@dataclass(frozen=True)
class MultiFrameParams(FlowComposed):
    """Fields shared by the multi-frame methods (RLR, MFSF), and their two-frame energy.

    The two-frame energy is composed: ``flow_method`` and ``flow_params`` are the
    two-frame method whose energy the trajectories minimise, frame by frame, and whose flows
    initialise them.  Its fields serve the initial flows and the multi-frame
    refinement alike: the pyramid (``scale_factor``, ``min_size``, ``n_warps``…),
    the pre-processing, the median filters, the data term (λ_D = ``data_weight``,
    γ = ``gradient_weight``, ζ = ``data_normalisation``, ``grey``, the noise rule
    ``noise_reference``), Huber-TV (``huber``) and the edge weight
    (``edge_weight``, ``edge_weight_min``), and θ (``coupling``) of the relaxed
    data term (``relaxed_data``); ``max_iterations`` and ``tolerance``
    serve the two-frame flows (the U-step has ``ustep_iterations`` and
    ``ustep_tolerance``).  A flat field of the energy goes to ``flow_params``
    (:func:`varflow.parameters.replace`, and so :func:`varflow.track` and the
    CLI).  The method must be TV-L1's (``tvl1``, ``tvl1-fast``, ``tvl1-ld``: the
    U-step has its data term and isotropic TV); its ``sharpness_match`` matches two
    frames and must be off.  A method named without ``flow_params`` takes
    :meth:`default_flow_params`.

    Attributes
    ----------
    flow_method : str
        The two-frame method of the initial flows and of the energy: ``tvl1``,
        ``tvl1-fast`` or ``tvl1-ld`` (the U-step has TV-L1's data term and isotropic
        TV).  Default ``"tvl1"``.
    flow_params : TVL1Params or None
        Its parameters; None (default) gives :meth:`default_flow_params`.
    tv_weight : float
        λ_TV, weight of the edge-weighted TV of every frame's displacement
        (relative to λ_D = ``data_weight`` as in TV-L1).  Default 1.
    primal_step : float
        s, primal step of the primal-dual iteration; the dual step is
        σ = 1 / (8 s) (so that s σ ||∇||² ≤ 1).  Default 0.25.
    ustep_iterations : int
        Primal-dual iterations of the U-step per warp and alternation.  Default 50,
        the ``max_iterations`` of the initial flows in :data:`TVL1_ENERGY`.
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
        visibility's backward flows.  Default True: it finds again a structure that
        moves farther than its size, and rlr is more accurate with it on every
        family of the photographic clips, most on objects and noise; see
        benchmarks/HISTORY.md.
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
        from the inverted initial trajectories.  Default 1: the accuracy of 3
        levels (occlusions found no worse) at a third of the time; see
        benchmarks/HISTORY.md.
    visibility_warps : int
        Warps per level of those backward flows.  Default 2: as accurate as 5
        warps on the photographic clips, for less time; see benchmarks/HISTORY.md.
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
        footage the repair's photometric cost is less reliable than those flows.
        Default False: on MPI-Sintel final/alley_1 (frame r + 1 of 9-frame
        windows) this repair brings the error up to that of the two-frame flow;
        see benchmarks/HISTORY.md.
    repair_cost : {"colour", "relit", "census"}
        The residual that the propagation's repair and the final repair compare
        (:func:`varflow.ops.fusion.repair_with`): the frames' colours; the colours
        with the reference under the other frame's light, fitted along the flow
        (a gain that varies linearly across the frame and an offset,
        :func:`varflow.ops.fusion.relight`); or their soft census planes, which a
        change of light leaves alone but which also drop the colours.  Under a
        change of light the colour cost prefers wrong vectors that land on a
        matching brightness.  Default "relit": it repairs the illumination family
        of the photographic clips, which "colour" loses, for slightly higher
        errors on objects and noise; "census" repairs the light changes too but
        gives worse initial trajectories on objects and noise.  See
        benchmarks/HISTORY.md.
    relaxed_data : bool
        Relax the U-step's data term as TV-L1 does (Zach et al. 2007): the term
        becomes ``min_v |u − v|²/(2θ) + λ_D D(v)`` with θ = ``coupling`` of the
        two-frame energy (0.3), the energy that ``tvl1``'s own solver minimises —
        quadratic for residuals below ``λ_D θ |∇I|²``, L1 beyond.  The link stays an
        exact L1 term on the trajectories.  False keeps the data term itself (the
        book's U-step).  Default True: on real footage the relaxed term is the
        better one (MPI-Sintel final/alley_1 at every reference, RubberWhale frame
        11), while on the photographic tuning clips it is slightly worse on the
        mean (lower on affine and nonrigid, higher on the other families); see
        benchmarks/HISTORY.md.
    hidden_data_weight : float
        Factor of the data term of the entries marked hidden, in [0, 1]: 0 switches
        it off, 1 keeps it (the visibility then only steers the coupling: the
        L-step's weights and ``hidden_link_weight``).  Default 0: slightly more
        accurate than 1 on photographic development clips, the same on RubberWhale
        and the noisy synthetic clips; see benchmarks/HISTORY.md.
    """

    flow_method: str = DEFAULT_METHOD
    flow_params: TVL1Params | None = None
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
    def default_flow_params(cls, flow_method: str) -> TVL1Params:
        """The energy of a ``flow_method`` named without ``flow_params``:
        :data:`TVL1_ENERGY` for ``tvl1`` (its data term and regulariser), another
        method's defaults with the sharpness match off (it matches two frames)."""
        if flow_method == DEFAULT_METHOD:
            return TVL1_ENERGY
        defaults = FLOW[flow_method].defaults()
        if defaults.sharpness_match:
            defaults = replace(defaults, sharpness_match=False)
        return defaults

    def __post_init__(self) -> None:
        super().__post_init__()
        _check(FLOW[self.flow_method].solve_warp is tvl1_solve_warp, "flow_method",
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
        the frames (no L-step).  Default 2, chosen on the tuning clips (see
        benchmarks/HISTORY.md).
    adjacent_link_factor : float
        a_min, the smallest factor of the link weight of the two frames next to
        the reference, ``ref ± 1``: their link weights (τ, and τ_h where hidden)
        are scaled by ``a_1 = min(1, max(a_min, (σ/σ_0)²))``, ``σ`` the noise of their
        residual estimated from the frames (:func:`adjacent_factor`).  Their data
        term is the most reliable of the clip (the smallest displacement,
        occlusion and change of appearance) unless the frames are noisy, while the
        low-rank fit of their rows follows the other frames: on clean real
        footage, whose trajectories are not low rank over a few frames, a strong
        link drags them (on RubberWhale a_1 = 1 is well above the two-frame flow,
        the rule on a par with it), and on noisy frames the link is what averages
        the noise out.  In [0, 1]; 1 links every frame alike.  Default 0.01; see
        benchmarks/HISTORY.md.
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
        ``L`` as many tiny singular values.  Default 0.003: 0.03 underfits a small
        moving object of the photographic clips; see benchmarks/HISTORY.md.
    rank_rule : {"relative", "noise"}
        Rank of the L-step's basis: the ``rank_tol`` threshold relative to the
        largest singular value, or the optimal hard threshold of Gavish & Donoho
        (2014) for the noise level estimated from the singular values
        (:func:`varflow.multiframe.lowrank.noise_rank`).  Default "relative", the
        more accurate of the two on RubberWhale; see benchmarks/HISTORY.md.
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
        Default True: more accurate on the synthetic suite and on RubberWhale; see
        benchmarks/HISTORY.md.
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
        target for the next U-step, not a result, so a loose tolerance costs a
        small fraction of a pixel and saves iterations.  Default 1e-4; see
        benchmarks/HISTORY.md.

    link_gate : float
        k of the link's fit gate (:func:`fit_gate`): the link weight of the visible
        entries of a region is scaled by ``1 / (1 + (r / (k m))²)``, ``r`` the
        region's misfit to the low-rank target and ``m`` the clip's median misfit,
        so that where the motion is not low rank the refinement is decoupled; 0
        turns the gate off.  Default 1: lower or equal errors than k = 2 on every
        family of the photographic clips, and a small fast object stays nearer its
        track than at k = 2 or ungated; see benchmarks/HISTORY.md.
    decoupled_fusion : bool
        Also refine without the link (``link_weight = 0``, the same initial
        trajectories and visibility) and keep, per pixel and frame, whichever of
        the two fits the frames better by the soft-census cost
        (:func:`fuse_decoupled`), the linked one unless the decoupled one is better
        by the margin ``m = fusion_margin + fusion_noise · σ²``, σ the residual noise
        of the frames (:func:`residual_noise`), blended near the margin
        (``fusion_softness``).  The link thus stays where the
        motion is low rank or the frames are too noisy to tell, and gives way where
        it pulls a region off its data.  Default True: on the photographic clips
        the fusion is more accurate than either refinement alone (below the
        decoupled one on every family, below the linked one on every family but
        affine); see benchmarks/HISTORY.md.  Costs a second refinement (not a
        second initialisation).
    fusion_margin : float
        m₀, the cost advantage the decoupled displacement needs on clean frames
        (units of the truncated census cost, :func:`varflow.ops.fusion.flow_cost`).
        Default 0.005: the most accurate of 0, 0.005 and 0.02 on the photographic
        tuning clips (0 loses on affine); see benchmarks/HISTORY.md.
    fusion_noise : float
        β of the margin's noise term ``β σ²``: on noisy frames a lower census cost
        is as likely the noise as the motion.  Default 15: on a noisy clip the
        fusion then keeps the linked refinement, which averages the noise, while
        5 to 30 are on a par on the photographic tuning clips; see
        benchmarks/HISTORY.md.
    fusion_softness : float
        κ, the width of the fusion's blend as a fraction of the margin m
        (:func:`fuse_decoupled`): the decoupled displacement's weight is the
        logistic function of ``(C_c − C_d − m) / (κ m)``, ½ at a cost advantage of m
        and near 0 or 1 a few κ·m away, so the two refinements are mixed where the
        census cost hardly tells them apart; 0 is the hard choice.  Default 0.5:
        lower or equal errors than the hard choice on every family of the
        photographic tuning clips; see benchmarks/HISTORY.md.
    fusion_evidence : float
        γ, the weight of the region's cost difference in the fusion
        (:func:`fuse_decoupled`): a pixel's ``C_c − C_d`` gains γ times its mean
        over the textured pixels around it, so that a flat region, where both runs
        fit the frames equally, follows the textured surroundings that tell them
        apart.  0 compares each pixel alone.  Default 3 (with ``fusion_radius``
        8): the lowest mean error of the grid of γ and σ tried on the photographic
        tuning clips, and every family and the far frames lower than at 0; see
        benchmarks/HISTORY.md.
    fusion_radius : float
        σ of the region of ``fusion_evidence``, pixels.  Default 8 (see there).

    The default energy is :data:`TVL1_ENERGY` (:meth:`MultiFrameParams.default_flow_params`);
    ``flow_params=preset("plain", weighted_median_radius=3)`` is the book's plain
    energy with the weighted median.
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
