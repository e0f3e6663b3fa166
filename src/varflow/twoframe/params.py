"""The parameters of the two-frame methods: one TV-L1 energy, optional terms, named presets.

:class:`TVL1Params` holds everything a two-frame method of the TV-L1 family reads:
the pyramid, warping and pre-processing of the coarse-to-fine driver
(:mod:`varflow.twoframe.coarse_to_fine`), the filters after each warp, the data term
and the regulariser of TV-L1 (:mod:`varflow.twoframe.tvl1`).  A method that adds to
that energy has a typed field for it, None when unused:

* ``tensor`` — :class:`TensorTerm`, the tensor-directed regulariser
  (:mod:`varflow.twoframe.tensor`);
* ``sparse`` — :class:`SparseTerm`, the learned-dictionary sparse term
  (:mod:`varflow.twoframe.sparse`; its ``regulariser="tensor"`` reads ``tensor``);
* ``matching`` — :class:`MatchingTerm`, the matching, interpolation and fusion
  stages of large displacements (:mod:`varflow.twoframe.large_displacement`).

The defaults of :class:`TVL1Params` are those of ``tvl1``.  :data:`PRESETS` names the
other starting points: ``plain`` (the book's energy: colour term and TV), ``fast``
and ``multiframe``, and one per registered method.  Flat names route to the term
that owns them (:func:`varflow.parameters.replace`): ``params.replace(tensor_a=1)``
changes ``params.tensor``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import check_field as _check
from ..ops.fusion import noise_sigma_flat
from ..ops.interpolation import InterpParams
from ..ops.matching import MatchParams
from ..parameters import Routed
from ..parameters import replace as _route
from ..sparse import check_layout

__all__ = [
    "TVL1Params",
    "TensorTerm",
    "SparseTerm",
    "MatchingTerm",
    "PRESETS",
    "preset",
    "FULL_ENERGY_TENSOR_A",
    "TERMS",
    "deprecated_preset",
]

#: The names of :class:`TVL1Params`' optional terms.
TERMS = ("tensor", "sparse", "matching")

#: a of the tensor-directed regulariser on ``tvl1``'s energy (``tvl1-tensor`` and the
#: ``tvl1-sparse-*`` methods): with the gradient term and Huber-TV the flow wants a
#: gentler anisotropy than the plain energy's a = 3 (benchmarks/HISTORY.md).
FULL_ENERGY_TENSOR_A = 0.5


@dataclass(frozen=True)
class TensorTerm(Routed):
    """The tensor-directed regulariser ``Σ_k |D ∇u_k|``, ``D = I − (1 − g) n nᵀ``.

    Attributes
    ----------
    tensor_a : float
        a of g(s) = exp(-a s^b), the weight across edges (``s = |∇I|`` in
        intensity/pixel, images in [0, 1]); 0 gives D = identity (isotropic TV).
        Default 3 (the ``tensor`` method; ``tvl1-tensor`` uses
        :data:`FULL_ENERGY_TENSOR_A`).
    tensor_b : float
        b of g(s) = exp(-a s^b), > 0.  Default 0.5.
    tensor_sigma : float
        σ of the Gaussian that smooths the structure tensor, pixels; 0 uses the
        gradient itself.  Default 1.
    """

    tensor_a: float = 3.0
    tensor_b: float = 0.5
    tensor_sigma: float = 1.0

    def __post_init__(self) -> None:
        _check(self.tensor_a >= 0, "tensor_a", f"must be >= 0, got {self.tensor_a}")
        _check(self.tensor_b > 0, "tensor_b", f"must be > 0, got {self.tensor_b}")
        _check(self.tensor_sigma >= 0, "tensor_sigma", f"must be >= 0, got {self.tensor_sigma}")


@dataclass(frozen=True)
class SparseTerm(Routed):
    """The sparse term ``λ_SP Σ_p ||R_p u − D α_p||²`` over a learned or fixed dictionary.

    Attributes
    ----------
    regulariser : str
        "tv" (isotropic, edge-weighted TV) or "tensor" (tensor-directed TV, the
        energy's ``tensor`` term).  Default "tv".
    dictionary : str
        "mod" (learned from the flow by MOD, bootstrapped level by level) or "dct"
        (fixed overcomplete 2-D DCT).  Default "mod".
    layout : str
        "1D" (one dictionary for u and v patches), "2x1D" (one each) or "2D" (joint
        [u; v] patches).  Default "1D".
    n_atoms : int
        Number of atoms of each dictionary (the book uses 400 and 800).  Default 400.
    patch_size : int
        m = n, side of the square flow patches, pixels.  Default 10.
    patch_offset : int
        k, step of the patch grid, pixels (1 = fully overlapping), 1 ≤ k ≤ m.
        Default 5: it divides the default patch size (uniform coverage) and makes
        the sparse step an order of magnitude faster than k = 1 at the same accuracy
        (benchmarks/bench_sparse_offset.py).
    omp_tolerance : float
        μ, OMP stops when the RMS residual per patch entry is ≤ μ pixels.  Default 0.05.
    omp_max_atoms : int
        Maximum atoms per patch (0: no limit).  Default 16.
    mod_iterations : int
        MOD passes per pyramid level (book: 10).  Default 10.
    mod_tolerance : float
        MOD stops early when the representation error and the code size change by
        less than this (relative).  Default 1e-3.
    mod_max_signals : int
        MOD trains on the patches of the offset-k grid (so k sets the cost of learning
        as well as of coding), at most this many, drawn at random (seeded); 0 = all.
        Default 0.
    sparse_weight : float
        λ_SP, weight of the sparse term at the finest level (per pixel of mean patch
        coverage, 1/pixel²).  Default 2.
    sparse_weight_decay : float
        Factor applied to λ_SP per coarser level, in (0, 1].  Default 1.
    sparse_tv_weight : float
        λ_TV, weight of the TV term in the combined (sparse) stage, relative to the
        TV-only stage.  Default 1.
    sparse_warps : int
        Warps of the combined energy per level (after the ``n_warps`` TV-only
        warps).  Default 2.
    sparse_min_size : int
        Levels whose smaller side is below this skip the sparse stage (pixels, at
        least ``patch_size``).  Default 40.
    nesterov_iterations : int
        Nesterov iterations per sparse warp (split over the continuation stages).
        Default 90.
    nesterov_stages : int
        NESTA continuation stages: the smoothing goes from 4^(stages-1) μ down to μ.
        Default 1: the stage starts from the TV-L1 flow of the level, which a
        coarser smoothing would first blur.
    smoothing_tv : float
        μ_TV, Huber smoothing of the TV term (pixels/pixel); with Huber-TV (ε_H =
        ``huber`` > 0) Nesterov's method minimises the Huber function of ε_H + μ_TV.
        Default 0.01.
    smoothing_data : float
        μ_data, Huber smoothing of the L1 data term (intensity).  Default 0.01.
    seed : int
        Seed of the random choices (MOD training subset).  Default 0.
    combined_solver : str
        Solver of the combined energy at each sparse warp: "nesterov" (Nesterov's
        method on the Huber-smoothed energy, fields ``nesterov_*`` and
        ``smoothing_*``) or "primal-dual" (the exact TV-L1 primal-dual scheme with the
        sparse quadratic folded into the point-wise data step; fields ``tv_step``,
        ``data_sweeps`` and ``combined_*``).  Default "nesterov".
    combined_coupling : float
        θ of the primal-dual iterations of a sparse warp ("primal-dual" only; the
        TV-only warps use ``coupling``).  The result is u = ROF_θ(v) with v the
        flow the sparse term pulls towards ū, so a tighter coupling passes more of
        the pull on.  Default 0.1.
    combined_iterations : int
        Maximum primal-dual iterations per sparse warp ("primal-dual" only).
        Default 50.
    combined_tolerance : float
        ε of the primal-dual iterations of a sparse warp ("primal-dual" only): stop
        when the RMS update of the flow is below ε pixels; 0 runs all
        ``combined_iterations``.  Default 0: warm-started iterations would stop
        before the pull towards ``ū`` acts.
    """

    regulariser: str = "tv"
    dictionary: str = "mod"
    layout: str = "1D"
    n_atoms: int = 400
    patch_size: int = 10
    patch_offset: int = 5
    omp_tolerance: float = 0.05
    omp_max_atoms: int = 16
    mod_iterations: int = 10
    mod_tolerance: float = 1e-3
    mod_max_signals: int = 0
    sparse_weight: float = 2.0
    sparse_weight_decay: float = 1.0
    sparse_tv_weight: float = 1.0
    sparse_warps: int = 2
    sparse_min_size: int = 40
    nesterov_iterations: int = 90
    nesterov_stages: int = 1
    smoothing_tv: float = 0.01
    smoothing_data: float = 0.01
    seed: int = 0
    combined_solver: str = "nesterov"
    combined_coupling: float = 0.1
    combined_iterations: int = 50
    combined_tolerance: float = 0.0

    def __post_init__(self) -> None:
        _check(self.regulariser in ("tv", "tensor"), "regulariser",
               f"must be 'tv' or 'tensor', got {self.regulariser!r}")
        _check(self.dictionary in ("mod", "dct"), "dictionary",
               f"must be 'mod' or 'dct', got {self.dictionary!r}")
        try:
            check_layout(self.layout)
        except ValueError:
            raise ValueError(
                f"layout: must be one of '1D', '2x1D', '2D', got {self.layout!r}"
            ) from None
        _check(self.patch_size >= 2, "patch_size", f"must be >= 2, got {self.patch_size}")
        _check(1 <= self.patch_offset <= self.patch_size, "patch_offset",
               f"must be in [1, patch_size={self.patch_size}], got {self.patch_offset}")
        mn = self.patch_size**2 * (2 if self.layout == "2D" else 1)
        _check(self.n_atoms >= 1, "n_atoms", f"must be >= 1, got {self.n_atoms}")
        _check(self.dictionary == "dct" or self.n_atoms >= mn // 4, "n_atoms",
               f"{self.n_atoms} atoms are too few to learn {mn}-element patches")
        _check(self.omp_tolerance > 0, "omp_tolerance",
               f"must be > 0, got {self.omp_tolerance}")
        _check(self.omp_max_atoms >= 0, "omp_max_atoms",
               f"must be >= 0, got {self.omp_max_atoms}")
        _check(self.mod_iterations >= 1, "mod_iterations",
               f"must be >= 1, got {self.mod_iterations}")
        _check(self.mod_tolerance >= 0, "mod_tolerance",
               f"must be >= 0, got {self.mod_tolerance}")
        _check(self.mod_max_signals == 0 or self.mod_max_signals >= 100, "mod_max_signals",
               f"must be 0 (all) or >= 100, got {self.mod_max_signals}")
        _check(self.sparse_weight >= 0, "sparse_weight",
               f"must be >= 0, got {self.sparse_weight}")
        _check(0 < self.sparse_weight_decay <= 1, "sparse_weight_decay",
               f"must be in (0, 1], got {self.sparse_weight_decay}")
        _check(self.sparse_tv_weight > 0, "sparse_tv_weight",
               f"must be > 0, got {self.sparse_tv_weight}")
        _check(self.sparse_warps >= 0, "sparse_warps", f"must be >= 0, got {self.sparse_warps}")
        _check(self.sparse_min_size >= self.patch_size, "sparse_min_size",
               f"must be >= patch_size={self.patch_size}, got {self.sparse_min_size}")
        _check(self.nesterov_iterations >= 1, "nesterov_iterations",
               f"must be >= 1, got {self.nesterov_iterations}")
        _check(1 <= self.nesterov_stages <= self.nesterov_iterations, "nesterov_stages",
               f"must be in [1, nesterov_iterations], got {self.nesterov_stages}")
        _check(self.smoothing_tv > 0, "smoothing_tv", f"must be > 0, got {self.smoothing_tv}")
        _check(self.smoothing_data > 0, "smoothing_data",
               f"must be > 0, got {self.smoothing_data}")
        _check(self.combined_solver in ("nesterov", "primal-dual"), "combined_solver",
               f"must be 'nesterov' or 'primal-dual', got {self.combined_solver!r}")
        _check(self.combined_coupling > 0, "combined_coupling",
               f"must be > 0, got {self.combined_coupling}")
        _check(self.combined_iterations >= 1, "combined_iterations",
               f"must be >= 1, got {self.combined_iterations}")
        _check(self.combined_tolerance >= 0, "combined_tolerance",
               f"must be >= 0, got {self.combined_tolerance}")

    def active(self, shape: tuple[int, int]) -> bool:
        """Whether a pyramid level of size ``shape`` runs the sparse stage."""
        return self.sparse_warps > 0 and min(shape) >= self.sparse_min_size


@dataclass(frozen=True)
class MatchingTerm(Routed):
    """The matching, interpolation and fusion stages of large displacements (``tvl1-ld``).

    Attributes
    ----------
    match_step : int
        d, spacing in pixels of the seed grid of the matching
        (:class:`varflow.ops.matching.MatchParams` ``step``).  Default 4.
    match_levels : int
        k, pyramid levels of the matching (factor 1/2 each).  Default 4.
    match_iterations : int
        n, PatchMatch sweeps per matching level (:class:`~varflow.ops.matching.MatchParams`
        ``iterations``).  Default 6.
    match_max_displacement : float
        Largest displacement searched at the coarsest matching level, pixels.
        Default 160.
    match_fb_threshold : float
        Forward-backward tolerance of a kept match, pixels of the matched images.
        Default 3.
    match_scale : float
        The matching and the interpolation run on the frames resized by this factor
        (in (0, 1]; Gaussian pre-smoothing σ = 0.6/scale − 0.6 px against aliasing),
        and their flow is resized back: the variational refinement restores the
        detail, and the cost falls with the area.  Default 1.
    interp_max_pixels : int
        The interpolation (its geodesic distances, Voronoi cells and rendering) runs
        on the matched frame resized to at most this many pixels (the matches keep
        their positions, scaled to that grid), and its flow is resized back: the
        geodesic Voronoi partition, a sequential Dijkstra over every pixel, is the
        stage's largest cost and the variational refinement restores the detail.
        Default 2**17 = 131072 (a 1024x436 frame is interpolated at 0.54 of its size).
    interp_k : int
        K, geodesically nearest matches of each match in its locally affine model
        (:class:`varflow.ops.interpolation.InterpParams` ``k``); the per-seed Dijkstra
        costs in proportion.  Default 32.
    interp_a : float
        a, scale of the interpolation kernel ``exp(-a D)`` over geodesic distances
        D.  Default 1.
    fusion_radius : int
        R of the fusion cost's ``(2R + 1)²`` window (pixels of the level).  Default 2.
    fusion_gamma : float
        γ_f, colour scale of the adaptive support weights (sum of absolute channel
        differences).  Default 0.1.
    fusion_truncation : float
        T, the largest photometric residual of a pixel in the fusion cost
        (intensity units).  Default 0.1.
    fusion_threshold : float
        τ, pixels of the level: only where the two candidates differ by more than
        τ may the matching candidate replace the carried flow (where they agree,
        the variational flow is the more accurate one).  Default 1.
    fusion_min_size : int
        The matching candidate is offered only on levels whose smaller side has at
        least this many pixels (the coarsest levels are too blurred to judge it).
        Default 24.
    support_radius : int
        A pixel's matching flow is supported when a seed within this many grid steps
        of its nearest seed kept its match (0: the nearest seed itself).  Default 0.
    min_matches : int
        Fewer surviving matches than this and the method is plain ``tvl1`` (no
        candidate).  Default 16.
    """

    match_step: int = 4
    match_levels: int = 4
    match_iterations: int = 6
    match_max_displacement: float = 160.0
    match_fb_threshold: float = 3.0
    match_scale: float = 1.0
    interp_max_pixels: int = 1 << 17
    interp_k: int = 32
    interp_a: float = 1.0
    fusion_radius: int = 2
    fusion_gamma: float = 0.1
    fusion_truncation: float = 0.1
    fusion_threshold: float = 1.0
    fusion_min_size: int = 24
    support_radius: int = 0
    min_matches: int = 16

    def __post_init__(self) -> None:
        _check(isinstance(self.support_radius, int | np.integer) and self.support_radius >= 0,
               "support_radius", f"must be an integer >= 0, got {self.support_radius!r}")
        for name in ("match_step", "match_levels", "match_iterations", "interp_k",
                     "fusion_min_size", "min_matches"):
            value = getattr(self, name)
            _check(isinstance(value, int | np.integer) and not isinstance(value, bool)
                   and value >= 1, name, f"must be an integer >= 1, got {value!r}")
        _check(isinstance(self.fusion_radius, int | np.integer) and self.fusion_radius >= 0,
               "fusion_radius", f"must be an integer >= 0, got {self.fusion_radius!r}")
        _check(math.isfinite(self.fusion_threshold) and self.fusion_threshold >= 0,
               "fusion_threshold", f"must be a finite number >= 0, got {self.fusion_threshold}")
        _check(0.0 < self.match_scale <= 1.0, "match_scale",
               f"must be in (0, 1], got {self.match_scale}")
        _check(isinstance(self.interp_max_pixels, int | np.integer)
               and not isinstance(self.interp_max_pixels, bool)
               and self.interp_max_pixels >= 64, "interp_max_pixels",
               f"must be an integer >= 64, got {self.interp_max_pixels!r}")
        for name in ("match_max_displacement", "match_fb_threshold", "interp_a",
                     "fusion_gamma", "fusion_truncation"):
            value = getattr(self, name)
            _check(math.isfinite(value) and value > 0, name,
                   f"must be a finite number > 0, got {value}")
        self.match_params()  # the stages check their own fields too
        self.interp_params()

    def match_params(self) -> MatchParams:
        """The :class:`~varflow.ops.matching.MatchParams` of the matching stage."""
        return MatchParams(step=int(self.match_step), levels=int(self.match_levels),
                           iterations=int(self.match_iterations),
                           max_displacement=float(self.match_max_displacement
                                                  * self.match_scale),
                           fb_threshold=float(self.match_fb_threshold))

    def interp_params(self) -> InterpParams:
        """The :class:`~varflow.ops.interpolation.InterpParams` of the interpolation."""
        return InterpParams(k=int(self.interp_k), a=float(self.interp_a))


@dataclass(frozen=True)
class TVL1Params(Routed):
    """The TV-L1 energy and its coarse-to-fine solver: every two-frame method's parameters.

    Intensities are in [0, 1]; flows in pixels.  The defaults are those of the
    ``tvl1`` method: the grey channel mean, a brightness-constancy term of weight
    λ = 15 beside a gradient-constancy term of weight γ = 140, Huber-TV, texture
    α = 0.3, the sharpness match, the noise rule and the weighted median on the
    finest levels, chosen on the photographic tuning pairs and Middlebury
    (benchmarks/README.md).  :data:`PRESETS` holds the other starting points
    (``plain``: the book's energy, colour term and TV).

    Attributes
    ----------
    scale_factor : float
        η, ratio between the sizes of consecutive pyramid levels, in (0, 1).
        Default 0.8.
    max_levels : int
        Maximum number of pyramid levels (the finest included).  Default 40; in
        practice ``min_size`` decides.
    min_size : int
        Smallest allowed side of the coarsest level, pixels.  Default 16.
    n_warps : int
        Number of warps (re-linearisations) per level.  Default 4: with the
        weighted median as accurate as 5, at 0.8 times the work.
    median_size : int
        Side of the median filter applied to the flow after each warp (Sun, Roth
        & Black 2010); 0 or 1 disables it.  Default 5.
    weighted_median_radius : int
        r of the weighted (non-local) median of Sun, Roth & Black (2010, 2014):
        after the last warp of every level (``weighted_median_every_warp``: after
        every warp), at the pixels near motion boundaries, each flow component
        becomes the median of its (2r+1)² neighbours weighted by their distance and
        their colour difference in the first frame
        (:func:`varflow.ops.median.weighted_median_flow`); the plain median
        (``median_size``) serves everywhere else.  Pixels; 0 disables it.
        Default 3 (7 × 7 windows).
    weighted_median_sigma_space : float
        σ_s of its spatial weight exp(-d²/(2σ_s²)), pixels.  Default 7.
    weighted_median_sigma_colour : float
        σ_c of its colour weight exp(-‖ΔI‖²/(2σ_c² C)), intensity units (the guide
        is the first frame's working channels at the level's size, before the
        sharpness match and the structure-texture step).  Default 0.05.
    weighted_median_threshold : float
        The flow edges where it applies: ``Σ_k |∂x f_k| + |∂y f_k|`` at least this
        (pixels per pixel), grown by 2 pixels (:func:`varflow.ops.median.flow_edge_mask`);
        0 applies it everywhere.  Default 0.5.
    weighted_median_sigma_divergence : float
        σ_d of the visibility factor of the weighted median's votes,
        exp(-min(div f, 0)² / (2σ_d²)) (:func:`varflow.ops.median.flow_visibility`:
        where the flow converges a surface is being covered, and its flow is
        unreliable), pixels per pixel; 0 leaves it out.  Default 0.3 (Sun et al.).
    weighted_median_noise : float
        k of the noise rule of the colour weight: with σ̂ the noise of the frames
        (:func:`varflow.ops.fusion.noise_sigma_flat` of the working channels), the
        colour weight uses σ_c' = sqrt(σ_c² + (k σ̂)²), so that on noisy frames the
        votes are not weighted by the noise of the guide.  0 turns the rule off.
        Default 5.
    weighted_median_levels : int
        Apply the weighted median on the finest this many pyramid levels only (each
        level costs 0.64 of the next finer one at η = 0.8, and the flow edges of
        the coarse levels are rough anyway); 0: on every level.  Default 3.
    weighted_median_every_warp : bool
        Apply the weighted median after every warp, as Sun, Roth & Black do,
        instead of after each level's last warp only: about five times its cost
        for about the same accuracy.  Default False.
    structure_texture : bool
        Run on the texture part ``I - α ROF(I)`` (Wedel et al. 2009).  Default True.
    texture_alpha : float
        α of the structure-texture blend ``I - α ROF(I)``, in [0, 1]; the original
        paper uses 0.95.  Default 0.3 (the ``plain`` preset 0.65: without the
        gradient term the data term needs more of the image's shading).
    rof_theta : float
        θ of the ROF model used for the structure part (intensity units, images in
        [0, 1]).  Default 0.125.
    rof_iterations : int
        Iterations of the ROF solver.  Default 50.
    pyramid_sigma : float
        Anti-alias smoothing: σ = pyramid_sigma · sqrt(η^(-2l) − 1) at level l.
        Default 0.6.
    sharpness_match : bool
        Before anything else, blur the sharper frame by a Gaussian until both frames
        are equally sharp when their sharpness (``mean |∇I|² / var I``) differs by more
        than :data:`varflow.ops.sharpness.SHARPNESS_TOLERANCE` in log units (one
        frame motion-blurred or out of focus); pairs of equal sharpness are
        untouched.  Two-frame runs only.  Default True.
    grey : bool
        Work on the mean of the colour channels (one channel, as DeepFlow does)
        instead of one data residual per channel: a third of the data-term work for
        about the same accuracy.  Applied before everything else, the noise rule
        and the sharpness match included.  Default True.
    data_weight : float
        λ, weight of the L1 data term per channel (1/intensity units).  Default 15
        (the ``plain`` preset, without the gradient term: 40).
    coupling : float
        θ, coupling between the data and TV sub-problems (pixels²·…); small values
        tie u and v closely.  Default 0.3.
    tv_step : float
        τ, step of the dual TV update; stable for τ ≤ 1/4.  Default 0.25.
    max_iterations : int
        Maximum iterations per warp.  Default 24: later iterations barely move the
        flow once the weighted median filters it.
    tolerance : float
        ε, stop when the root-mean-square update of the flow is below ε pixels
        (tested after every second iteration).  Default 0.01.
    edge_weight : float
        c of the TV edge weight ``g(x) = exp(-c |∇I0|²)`` (``|∇I0|²`` in
        intensity²/pixel², averaged over channels, of the pre-processed frame); 0
        gives g ≡ 1 (plain TV).  Default 30.
    edge_weight_min : float
        Lower bound of g, in (0, 1].  Default 0.05.
    data_sweeps : int
        Coordinate-descent sweeps of the colour data prox per iteration (warm
        started across iterations; grey images are exact with 1).  Default 1: a
        second sweep costs 1.3x for no measurable gain.
    gradient_weight : float
        γ, weight of the L1 gradient-constancy term ``γ Σ_c |ρ_cx| + |ρ_cy|``, the
        linearised constancy of ∂_x I_c and ∂_y I_c for every channel of the
        pre-processed frames (Brox et al. 2004; 1/(intensity/pixel) units), added to
        the colour term of weight λ.  Blind to additive brightness changes, which
        make the colour term drift on the coarse levels.  0 turns it off.
        Default 140.
    gradient_sigma : float
        σ_g of the Gaussian pre-smoothing of the frames whose gradients enter the
        gradient-constancy term, in pixels of the finest level (σ_g η^l at level
        l, so it follows the pyramid); 0 for none.  Read only when γ > 0.
        Default 1: it halves the error on noisy and blurred pairs.
    data_normalisation : float
        ζ of the data-term normalisation of Zimmer et al. (2011): every linearised
        constraint (colour and gradient) is divided by ``sqrt(|∇ρ|² + ζ²)``, the
        norm of its own spatial gradient (intensity/pixel units), so that it
        measures a distance in pixels to its constraint line; λ and γ then weigh
        pixels, not intensities (retune them: the scale of the data term grows by
        up to 1/ζ).  0 turns it off.  Default 0.
    huber : float
        ε_H of Huber-TV (Werlberger et al. 2009), in flow-gradient units (pixels per
        pixel): the regulariser is quadratic, ``g |∇u_k|²/(2ε_H)``, below ε_H and TV
        above, so smooth (affine, non-rigid) motion does not staircase.  0 gives TV.
        Default 0.02 (larger values let noise into the flow).
    gradient_grey : bool
        Put the gradient-constancy term on the mean of the colour channels: one x
        and one y channel weighted ``C γ`` (so that γ keeps its meaning) instead of
        ``2 C`` channels.  Read only when γ > 0.  Default False.
    noise_reference : float
        σ_0 of the noise rule, intensity units: on frames whose noise σ̂ exceeds it
        the data weights λ and γ are multiplied by σ_0/σ̂ (a stronger regulariser
        where the data are noisier); σ̂ is the mean over the two frames of
        :func:`varflow.ops.fusion.noise_sigma_flat` (Immerkær's estimator on the
        flattest tiles), read on the working channels before any other
        pre-processing.  0 turns it off.  Default 0.01.
    tensor : TensorTerm or None
        The tensor-directed regulariser; None: isotropic (edge-weighted) TV.
        Default None.
    sparse : SparseTerm or None
        The sparse term and its extra warps per level; None: none.  Default None.
    matching : MatchingTerm or None
        The large-displacement stages (matching, interpolation, fusion); None:
        none.  Default None.
    """

    scale_factor: float = 0.8
    max_levels: int = 40
    min_size: int = 16
    n_warps: int = 4
    median_size: int = 5
    weighted_median_radius: int = 3
    weighted_median_sigma_space: float = 7.0
    weighted_median_sigma_colour: float = 0.05
    weighted_median_threshold: float = 0.5
    weighted_median_sigma_divergence: float = 0.3
    weighted_median_noise: float = 5.0
    weighted_median_levels: int = 3
    weighted_median_every_warp: bool = False
    structure_texture: bool = True
    texture_alpha: float = 0.3
    rof_theta: float = 0.125
    rof_iterations: int = 50
    pyramid_sigma: float = 0.6
    sharpness_match: bool = True
    grey: bool = True
    data_weight: float = 15.0
    coupling: float = 0.3
    tv_step: float = 0.25
    max_iterations: int = 24
    tolerance: float = 0.01
    edge_weight: float = 30.0
    edge_weight_min: float = 0.05
    data_sweeps: int = 1
    gradient_weight: float = 140.0
    gradient_sigma: float = 1.0
    data_normalisation: float = 0.0
    huber: float = 0.02
    gradient_grey: bool = False
    noise_reference: float = 0.01
    tensor: TensorTerm | None = None
    sparse: SparseTerm | None = None
    matching: MatchingTerm | None = None

    _COMPOSED = TERMS

    def __post_init__(self) -> None:
        _check(0.0 < self.scale_factor < 1.0, "scale_factor",
               f"must be in (0, 1), got {self.scale_factor}")
        _check(self.max_levels >= 1, "max_levels", f"must be >= 1, got {self.max_levels}")
        _check(self.min_size >= 2, "min_size", f"must be >= 2, got {self.min_size}")
        _check(self.n_warps >= 1, "n_warps", f"must be >= 1, got {self.n_warps}")
        _check(
            self.median_size >= 0 and (self.median_size <= 1 or self.median_size % 2 == 1),
            "median_size",
            f"must be 0, 1 or an odd integer, got {self.median_size}",
        )
        for name in ("weighted_median_radius", "weighted_median_levels"):
            value = getattr(self, name)
            _check(value >= 0, name, f"must be >= 0, got {value}")
        for name in ("weighted_median_sigma_space", "weighted_median_sigma_colour"):
            value = getattr(self, name)
            _check(math.isfinite(value) and value > 0, name,
                   f"must be a finite number > 0, got {value}")
        for name in ("weighted_median_threshold", "weighted_median_sigma_divergence",
                     "weighted_median_noise"):
            value = getattr(self, name)
            _check(math.isfinite(value) and value >= 0, name,
                   f"must be a finite number >= 0, got {value}")
        _check(0.0 <= self.texture_alpha <= 1.0, "texture_alpha",
               f"must be in [0, 1], got {self.texture_alpha}")
        _check(self.rof_theta > 0, "rof_theta", f"must be > 0, got {self.rof_theta}")
        _check(self.rof_iterations >= 1, "rof_iterations",
               f"must be >= 1, got {self.rof_iterations}")
        _check(self.pyramid_sigma >= 0, "pyramid_sigma", f"must be >= 0, got {self.pyramid_sigma}")
        _check(self.data_weight > 0, "data_weight", f"must be > 0, got {self.data_weight}")
        _check(self.coupling > 0, "coupling", f"must be > 0, got {self.coupling}")
        _check(0 < self.tv_step <= 0.25, "tv_step", f"must be in (0, 0.25], got {self.tv_step}")
        _check(self.max_iterations >= 1, "max_iterations",
               f"must be >= 1, got {self.max_iterations}")
        _check(self.tolerance >= 0, "tolerance", f"must be >= 0, got {self.tolerance}")
        _check(self.edge_weight >= 0, "edge_weight", f"must be >= 0, got {self.edge_weight}")
        _check(0 < self.edge_weight_min <= 1, "edge_weight_min",
               f"must be in (0, 1], got {self.edge_weight_min}")
        _check(self.data_sweeps >= 1, "data_sweeps", f"must be >= 1, got {self.data_sweeps}")
        for name in ("gradient_weight", "gradient_sigma", "data_normalisation", "huber",
                     "noise_reference"):
            value = getattr(self, name)
            _check(math.isfinite(value) and value >= 0, name,
                   f"must be a finite number >= 0, got {value}")
        for name, kind in (("tensor", TensorTerm), ("sparse", SparseTerm),
                           ("matching", MatchingTerm)):
            value = getattr(self, name)
            _check(value is None or isinstance(value, kind), name,
                   f"expected a {kind.__name__} or None, got {type(value).__name__}")

    def terms(self) -> frozenset[str]:
        """The names of the optional terms that are set (a subset of :data:`TERMS`)."""
        return frozenset(name for name in TERMS if getattr(self, name) is not None)

    def for_frames(self, I0: np.ndarray, I1: np.ndarray, stats: dict) -> TVL1Params:
        """Apply the noise rule (``noise_reference``) to a pair of ``(H, W, C)`` frames.

        Records ``noise_sigma`` (σ̂) and ``data_scale`` (the factor on λ and γ) in
        ``stats`` when the rule is on.
        """
        if self.noise_reference <= 0:
            return self
        sigma = 0.5 * (noise_sigma_flat(I0) + noise_sigma_flat(I1))
        scale = min(1.0, self.noise_reference / sigma) if sigma > 0 else 1.0
        stats.update(noise_sigma=sigma, data_scale=scale)
        if scale == 1.0:
            return self
        return self.replace(data_weight=self.data_weight * scale,
                            gradient_weight=self.gradient_weight * scale)

    def sparse_active(self, shape: tuple[int, int]) -> bool:
        """Whether a pyramid level of size ``shape`` runs the sparse stage."""
        return self.sparse is not None and self.sparse.active(shape)

    def level_warps(self, shape: tuple[int, int]) -> int:
        """Warps at a pyramid level of size ``shape``: ``n_warps``, plus the sparse
        term's ``sparse_warps`` on levels large enough for its patches (the driver
        tells the solver which warp it is in ``state.warp``)."""
        return self.n_warps + (self.sparse.sparse_warps if self.sparse_active(shape) else 0)


_PLAIN = dict(data_weight=40.0, max_iterations=50, edge_weight=50.0, gradient_weight=0.0,
              huber=0.0, noise_reference=0.0, texture_alpha=0.65, sharpness_match=False,
              grey=False, weighted_median_radius=0, weighted_median_levels=0, n_warps=5)
_BASE = TVL1Params()
_FAST = TVL1Params(scale_factor=0.5, n_warps=3)
_PLAIN_P = TVL1Params(**_PLAIN)
_TENSOR_TVL1 = TensorTerm(tensor_a=FULL_ENERGY_TENSOR_A)
_SPARSE_LAYOUTS = {"dct": dict(dictionary="dct"), "1d": dict(layout="1D"),
                   "2x1d": dict(layout="2x1D"), "2d": dict(layout="2D")}

#: Named starting points of :class:`TVL1Params`: the energies (``tvl1`` — the
#: defaults —, ``plain`` — the book's energy: one L1 residual per colour channel,
#: edge-weighted TV, no gradient term, Huber-TV, sharpness match, noise rule or
#: weighted median, 5 warps per level —, ``fast`` — ``tvl1`` on fewer, coarser levels
#: —, ``multiframe`` — ``tvl1``'s data term and regulariser with 5 warps of 50
#: iterations, the weighted median on every level and no sharpness match, for whole
#: clips), and the parameters of every registered two-frame method under its name.
PRESETS: dict[str, TVL1Params] = {
    "tvl1": _BASE,
    "plain": _PLAIN_P,
    "fast": _FAST,
    "multiframe": TVL1Params(max_iterations=50, n_warps=5, weighted_median_levels=0,
                             sharpness_match=False),
    "tvl1-fast": _FAST,
    "tvl1-ld": TVL1Params(n_warps=3, weighted_median_levels=0, max_iterations=30,
                          matching=MatchingTerm()),
    "tensor": TVL1Params(**{**_PLAIN, "edge_weight": 0.0}, tensor=TensorTerm()),
    "tvl1-tensor": TVL1Params(edge_weight=0.0, tensor=_TENSOR_TVL1),
    **{f"sparse-{k}": TVL1Params(**_PLAIN, tensor=TensorTerm(), sparse=SparseTerm(**v))
       for k, v in _SPARSE_LAYOUTS.items()},
    **{f"tvl1-sparse-{k}": TVL1Params(tensor=_TENSOR_TVL1, sparse=SparseTerm(**v))
       for k, v in _SPARSE_LAYOUTS.items()},
}


def preset(name: str, **overrides: Any) -> TVL1Params:
    """The preset ``name`` of :data:`PRESETS` with ``overrides`` (flat names, routed to
    the terms that own them).

    Raises
    ------
    ValueError
        An unknown preset (``"preset: ..."``) or override.
    """
    _check(name in PRESETS, "preset",
           f"unknown preset {name!r}; available: {', '.join(sorted(PRESETS))}")
    return _route(PRESETS[name], **overrides) if overrides else PRESETS[name]


def deprecated_preset(name: str, preset_name: str) -> Callable[..., TVL1Params]:
    """A stand-in for a former parameter class ``name``: called with flat fields, it
    warns (:class:`DeprecationWarning`) and returns ``preset(preset_name, **fields)``.
    Kept for one version so that code written against the class keeps working."""

    def make(**overrides: Any) -> TVL1Params:
        warnings.warn(f"{name} is deprecated: use varflow.twoframe.params.preset("
                      f"{preset_name!r}, ...) or varflow.make_params", DeprecationWarning,
                      stacklevel=2)
        return preset(preset_name, **overrides)

    make.__name__ = make.__qualname__ = name
    make.__doc__ = (f"Deprecated: the ``{preset_name}`` preset of :class:`TVL1Params` "
                    f"(:func:`preset`) with the given fields.")
    return make
