"""Large-displacement TV-L1: matching-guided candidates fused into the coarse-to-fine flow.

Coarse-to-fine warping loses a structure that moves farther than its own size:
it vanishes at the coarse levels, and the fine levels start from the motion of
what surrounds it.  The ``tvl1-ld`` method gives every level a second opinion from
feature matching, in three stages:

1. **Matching** (:func:`varflow.ops.matching.match`): coarse-to-fine PatchMatch of
   SIFT-like descriptors on a seed grid (CPM, Hu et al. 2016), checked forward
   and backward.  It follows motions of 150 px and more.
2. **Interpolation** (:func:`varflow.ops.interpolation.interpolate`): the surviving
   matches become a dense flow ``w_m`` by edge-aware, locally affine
   interpolation over geodesic distances (EpicFlow, Revaud et al. 2015).
3. **Fusion with the energy**: the one coarse-to-fine driver runs TV-L1 as usual,
   with a :data:`~varflow.twoframe.coarse_to_fine.LevelHook` at the start of every
   level.  Where the flow carried from the coarser level and ``w_m`` resampled to
   the level disagree by more than ``fusion_threshold`` pixels (of the level), and
   where ``w_m`` is *supported* (the match of the pixel's nearest seed survived
   the forward-backward check; in occluded regions ``w_m`` is only interpolated,
   and a wrong vector there can still fit the frames), the two compete: the pixel
   keeps the one with the lower edge-aware truncated photometric cost
   (:func:`varflow.ops.fusion.candidate_costs`, the data term aggregated over a
   small window with adaptive support weights).  The level's warps then refine the
   fused flow, so the matches bring back what the pyramid lost and the variational
   refinement removes their errors.  Where the motion is small the two candidates
   agree and the result is that of ``tvl1``.

Every field of :class:`TVL1Params` keeps its meaning; the ``match_*``,
``interp_*`` and ``fusion_*`` fields are the stages' own.

References
----------
T. Brox, J. Malik, "Large displacement optical flow: descriptor matching in
variational motion estimation", IEEE TPAMI 33(3), 2011.

J. Revaud, P. Weinzaepfel, Z. Harchaoui, C. Schmid, "EpicFlow: edge-preserving
interpolation of correspondences for optical flow", CVPR 2015.

Y. Hu, R. Song, Y. Li, "Efficient coarse-to-fine PatchMatch for large displacement
optical flow", CVPR 2016.

V. Lempitsky, S. Roth, C. Rother, "FusionFlow: discrete-continuous optimization
for optical flow estimation", CVPR 2008 (fusing flow proposals).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .._validate import check_pair
from ..ops.fusion import candidate_costs
from ..ops.interpolation import InterpParams, interpolate
from ..ops.matching import MatchParams, match
from ..ops.pyramid import resize_bilinear, resize_flow, smooth_image_fast
from .coarse_to_fine import ProgressCallback, _check, coarse_to_fine
from .tvl1 import TVL1Params, solve_warp

__all__ = ["LargeDisplacementParams", "fusion_hook", "matching_flow", "tvl1_ld"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LargeDisplacementParams(TVL1Params):
    """Parameters of ``tvl1-ld`` (every :class:`TVL1Params` field too).

    Defaults were chosen on the tuning split of the large-motion generator
    (:mod:`varflow.generators.large_pairs`, seeds 0-3) under the constraint that the
    Middlebury mean stays within 2 % of ``tvl1``'s (benchmarks/README.md).  Every
    :class:`TVL1Params` default (the ``tvl1`` model: grey channel, gradient term,
    Huber-TV) is kept except ``n_warps`` = 3 (the matching carries the large
    motion).  On that model: tuning split 2.07 px, Middlebury 0.2724 against
    ``tvl1``'s 0.2677 (with the interpolation on at most 2**17 pixels and K = 32,
    chosen for speed in session 5; before, 2.15 px and 0.2719); the stages were
    tuned on the plain energy (2.16 px, Middlebury 0.287 against its 0.284).
    Since ``tvl1`` took the weighted median (issue 11), ``tvl1-ld`` keeps it on
    every level and the 30 iterations per warp that ``tvl1`` dropped to 24: tuning
    split 1.81 px (1.98 with ``tvl1``'s 3 levels and 24 iterations, 1.88 with
    every level and 24).

    Attributes
    ----------
    weighted_median_levels : int
        As in :class:`varflow.twoframe.coarse_to_fine.CoarseToFineParams`.
        Default 0 (every level; ``tvl1`` 3).
    max_iterations : int
        As in :class:`TVL1Params`.  Default 30 (``tvl1`` 24).
    match_step : int
        d, spacing in pixels of the seed grid of the matching
        (:class:`varflow.ops.matching.MatchParams` ``step``).  Default 4 (3: tuning
        split 2.22 px against 2.16, and 1.3 x the matching and interpolation time).
    match_levels : int
        k, pyramid levels of the matching (factor 1/2 each).  Default 4.
    match_iterations : int
        n, PatchMatch sweeps per matching level (:class:`~varflow.ops.matching.MatchParams`
        ``iterations``).  Default 6 (4: tuning split 2.20 px against 2.09).
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
        their positions, scaled to that grid), and its flow is resized back.  The
        geodesic Voronoi partition, a sequential Dijkstra over every pixel, is the
        largest cost of the stage; the variational refinement restores the detail.
        Default 2**17 = 131072 (a 1024x436 frame is interpolated at 0.54 of its
        size, the 384x512 generator pairs at 0.82; with ``interp_k`` = 32 the
        tuning split went from 2.15 to 2.07 px and the stage's time from about
        0.75 s to 0.3 s per Sintel pair).
    interp_k : int
        K, geodesically nearest matches of each match in its locally affine model
        (:class:`varflow.ops.interpolation.InterpParams` ``k``).  Default 32 (the
        per-seed Dijkstra of the K nearest seeds costs in proportion; on the tuning
        split, interpolating at half size, 32 gave 2.09 px, 48 2.07 and 64 2.16).
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

    n_warps: int = 3
    weighted_median_levels: int = 0
    max_iterations: int = 30
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
        super().__post_init__()
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


def _support(grid_flow: np.ndarray, step: int, shape: tuple[int, int],
             radius: int = 0) -> np.ndarray:
    """Pixels with a kept match within ``radius`` seeds of their nearest seed, ``(H, W)`` bool."""
    h, w = shape
    gh, gw = grid_flow.shape[:2]
    kept = np.isfinite(grid_flow[..., 0])
    if radius > 0:
        kept = ndimage.binary_dilation(kept, np.ones((2 * radius + 1,) * 2, bool))
    off = step // 2
    gi = np.clip(np.rint((np.arange(h) - off) / step).astype(np.int64), 0, gh - 1)
    gj = np.clip(np.rint((np.arange(w) - off) / step).astype(np.int64), 0, gw - 1)
    return kept[gi[:, None], gj[None, :]]


def _downscale(image: np.ndarray, scale: float) -> np.ndarray:
    """``image`` resized by ``scale`` < 1 (each side at least 8 px), after a Gaussian of
    σ = 0.6/scale − 0.6 px against aliasing."""
    h, w = image.shape[:2]
    small = (max(8, round(h * scale)), max(8, round(w * scale)))
    return resize_bilinear(smooth_image_fast(image, 0.6 / scale - 0.6), small)


def _interpolate_scaled(image: np.ndarray, points: np.ndarray, flow: np.ndarray,
                        params: LargeDisplacementParams) -> np.ndarray:
    """The interpolation of ``(points, flow)`` over ``image``, on at most ``interp_max_pixels``.

    A larger image is reduced by :func:`_downscale` with ``s = sqrt(max_pixels / (H W))``,
    the matches are mapped to its pixel centres, and the dense flow is resized
    back to ``image``.
    """
    full = image.shape[:2]
    scale = math.sqrt(params.interp_max_pixels / (full[0] * full[1]))
    if scale >= 1.0:
        return interpolate(image, points, flow, params.interp_params())
    img = _downscale(image, scale)
    sy, sx = img.shape[0] / full[0], img.shape[1] / full[1]
    pts = ((points.astype(np.float64) + 0.5) * (sx, sy) - 0.5).astype(np.float32)
    fl = (flow.astype(np.float64) * (sx, sy)).astype(np.float32)
    return resize_flow(interpolate(img, pts, fl, params.interp_params()), full)


def matching_flow(
    frame0: np.ndarray,
    frame1: np.ndarray,
    params: LargeDisplacementParams | None = None,
    stats: dict | None = None,
) -> np.ndarray | None:
    """The dense flow ``w_m`` of the matches (stages 1 and 2 of the module notes).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float (see :func:`varflow._validate.check_pair`).
    params : LargeDisplacementParams, optional
    stats : dict, optional
        Filled with ``matches`` (kept), ``match_seconds`` and ``interp_seconds``.

    Returns
    -------
    ndarray, shape (H, W, 2), float32, or None
        NaN where the flow is not supported (the pixel's nearest seed lost its
        match; see the module notes); None when fewer than ``min_matches`` matches
        survive.
    """
    params = params or LargeDisplacementParams()
    stats = {} if stats is None else stats
    I0, I1 = check_pair(frame0, frame1)
    t0 = time.perf_counter()
    full = I0.shape[:2]
    if params.match_scale < 1.0:
        I0, I1 = (_downscale(x, params.match_scale) for x in (I0, I1))
    m = match(I0, I1, params.match_params())
    t1 = time.perf_counter()
    stats.update(matches=int(m.points.shape[0]), match_seconds=t1 - t0)
    if m.points.shape[0] < params.min_matches:
        log.info("tvl1-ld: %d matches (< %d): no matching candidate", m.points.shape[0],
                 params.min_matches)
        stats["interp_seconds"] = 0.0
        return None
    dense = _interpolate_scaled(I0, m.points, m.flow, params)
    dense[~_support(m.grid_flow, m.step, I0.shape[:2], int(params.support_radius))] = np.nan
    if dense.shape[:2] != full:
        known = resize_bilinear(np.isfinite(dense[..., :1]).astype(np.float32), full)
        dense = resize_flow(np.nan_to_num(dense, nan=0.0), full)
        dense[known[..., 0] < 0.999] = np.nan
    stats["interp_seconds"] = time.perf_counter() - t1
    return dense


def fusion_hook(candidate: np.ndarray, params: LargeDisplacementParams):
    """The level hook that fuses the carried flow with ``candidate`` (module notes, 3).

    ``candidate`` is NaN where it is not supported; there it never replaces the flow
    (NaN pixels take their nearest supported value before the candidate is resampled
    to a level, so that they do not pull the supported ones near them).
    """
    valid = np.isfinite(candidate[..., 0])
    known = valid[..., None].astype(np.float32)
    if valid.all() or not valid.any():
        filled = np.nan_to_num(candidate, nan=0.0).astype(np.float32)
    else:
        iy, ix = ndimage.distance_transform_edt(~valid, return_distances=False,
                                                return_indices=True)
        filled = np.ascontiguousarray(candidate[iy, ix], np.float32)

    def hook(level: int, i0: np.ndarray, i1: np.ndarray, flow: np.ndarray,
             stats: dict) -> np.ndarray:
        h, w = i0.shape[:2]
        if min(h, w) < params.fusion_min_size:
            return flow
        t0 = time.perf_counter()
        cand = resize_flow(filled, (h, w))
        supported = resize_bilinear(known, (h, w))[..., 0] > 0.5
        cost = candidate_costs(i0, i1, [flow, cand], int(params.fusion_radius),
                               float(params.fusion_gamma), float(params.fusion_truncation))
        differ = np.hypot(*(cand - flow).transpose(2, 0, 1)) > params.fusion_threshold
        take = (cost[1] < cost[0]) & differ & supported
        fused = np.where(take[..., None], cand, flow).astype(np.float32)
        stats.setdefault("fusion_share", []).append(float(take.mean()))
        stats["fusion_seconds"] = stats.get("fusion_seconds", 0.0) + time.perf_counter() - t0
        return fused

    return hook


def tvl1_ld(
    frame0: np.ndarray,
    frame1: np.ndarray,
    params: LargeDisplacementParams | None = None,
    init_flow: np.ndarray | None = None,
    callback: ProgressCallback | None = None,
    stats: dict | None = None,
) -> np.ndarray:
    """Large-displacement TV-L1 flow from ``frame0`` to ``frame1`` (module notes).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float.
    params : LargeDisplacementParams, optional
    init_flow : ndarray, shape (H, W, 2), optional
        Initial flow of the coarse-to-fine stage.
    callback : callable, optional
        ``callback(done, total)`` after every warp.
    stats : dict, optional
        Filled with the driver's counters and ``matches``, ``match_seconds``,
        ``interp_seconds``, ``fusion_seconds``, ``fusion_share`` (per level, the
        share of pixels that took the matching candidate).

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    params = params or LargeDisplacementParams()
    stats = {} if stats is None else stats
    I0, I1 = check_pair(frame0, frame1)
    candidate = matching_flow(I0, I1, params, stats)
    hook = None if candidate is None else fusion_hook(candidate, params)
    return coarse_to_fine(I0, I1, solve_warp, params, init_flow=init_flow, callback=callback,
                          stats=stats, level_hook=hook)
