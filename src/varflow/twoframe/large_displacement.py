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

The parameters are a :class:`~varflow.twoframe.params.TVL1Params` (every field keeps
its meaning) whose ``matching`` term, a :class:`~varflow.twoframe.params.MatchingTerm`,
holds the stages' own ``match_*``, ``interp_*`` and ``fusion_*`` fields.

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

import numpy as np
from scipy import ndimage

from .._validate import check_field, check_pair
from ..ops.fusion import candidate_costs
from ..ops.interpolation import interpolate
from ..ops.matching import match
from ..ops.pyramid import resize_bilinear, resize_flow, smooth_image_fast
from .coarse_to_fine import ProgressCallback, coarse_to_fine
from .params import PRESETS, MatchingTerm, TVL1Params, deprecated_preset
from .tvl1 import solve_warp

__all__ = ["MatchingTerm", "LargeDisplacementParams", "fusion_hook", "matching_flow", "tvl1_ld"]

log = logging.getLogger(__name__)


LargeDisplacementParams = deprecated_preset("LargeDisplacementParams", "tvl1-ld")


def _matching(params: MatchingTerm | TVL1Params | None) -> MatchingTerm:
    """The matching term of ``params`` (an energy with one, the term itself, or None:
    ``tvl1-ld``'s)."""
    if params is None:
        return PRESETS["tvl1-ld"].matching
    return params.matching if isinstance(params, TVL1Params) else params


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
                        params: MatchingTerm) -> np.ndarray:
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
    params: MatchingTerm | TVL1Params | None = None,
    stats: dict | None = None,
) -> np.ndarray | None:
    """The dense flow ``w_m`` of the matches (stages 1 and 2 of the module notes).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float (see :func:`varflow._validate.check_pair`).
    params : MatchingTerm or TVL1Params, optional
        The matching term (or an energy that has one); default ``tvl1-ld``'s.
    stats : dict, optional
        Filled with ``matches`` (kept), ``match_seconds`` and ``interp_seconds``.

    Returns
    -------
    ndarray, shape (H, W, 2), float32, or None
        NaN where the flow is not supported (the pixel's nearest seed lost its
        match; see the module notes); None when fewer than ``min_matches`` matches
        survive.
    """
    params = _matching(params)
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


def fusion_hook(candidate: np.ndarray, params: MatchingTerm | TVL1Params):
    """The level hook that fuses the carried flow with ``candidate`` (module notes, 3).

    ``candidate`` is NaN where it is not supported; there it never replaces the flow
    (NaN pixels take their nearest supported value before the candidate is resampled
    to a level, so that they do not pull the supported ones near them).
    """
    params = _matching(params)
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
    params: TVL1Params | None = None,
    init_flow: np.ndarray | None = None,
    callback: ProgressCallback | None = None,
    stats: dict | None = None,
) -> np.ndarray:
    """Large-displacement TV-L1 flow from ``frame0`` to ``frame1`` (module notes).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float.
    params : TVL1Params, optional
        An energy with a ``matching`` term; default the ``tvl1-ld`` preset.
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
    params = params or PRESETS["tvl1-ld"]
    check_field(params.matching is not None, "matching",
                "tvl1-ld needs a MatchingTerm (the 'tvl1-ld' preset has one)")
    stats = {} if stats is None else stats
    I0, I1 = check_pair(frame0, frame1)
    candidate = matching_flow(I0, I1, params.matching, stats)
    hook = None if candidate is None else fusion_hook(candidate, params.matching)
    return coarse_to_fine(I0, I1, solve_warp, params, init_flow=init_flow, callback=callback,
                          stats=stats, level_hook=hook)
