"""Visibility of the reference pixels in every frame of a trajectory estimate.

``visible[n, x]`` answers: is the point seen at pixel ``x`` of the reference
frame ``r`` also seen in frame ``n``?  Three tests, all of which a visible point
must pass:

1. **Image bounds**: ``x + T_n(x)`` lies inside ``[0, W−1] × [0, H−1]``.
2. **Forward-backward consistency** (Sundaram, Brox & Keutzer 2010): with the
   backward flow ``B_n`` from frame ``n`` to the reference, a visible point comes
   back where it started, ``|T_n(x) + B_n(x + T_n(x))| ≤ fb_tolerance`` (pixels).
   A point hidden in frame ``n`` has no correspondence there: the backward flow at
   its position belongs to the surface in front and points elsewhere.  ``B_n`` is
   the inverse of ``T_n`` refined by the two-frame solver on the finest pyramid
   levels; the inverse is the fixed-point inversion (exact where ``T_n`` is
   smooth) or, with ``splat=True`` (for trajectories from matching, see
   :attr:`varflow.multiframe.params.MultiFrameParams.propagate_matching`), per pixel
   the better fit to the frames of it and the splatted one (every reference pixel
   sends ``−T_n`` to where it lands, which follows a small object moving farther
   than its size, where the fixed point takes the motion of the surroundings).
3. **Photometric residual**: the edge-aware photometric cost of ``T_n``
   (:func:`varflow.ops.fusion.flow_cost` on the pre-processed frames) is at most
   ``photo_factor`` times its median over the frame's in-bound pixels (at least
   ``photo_floor``): the scale of a good match is read from the footage itself
   (noise, blur and lighting set it), not fixed.

The mask is then cleaned: isolated hidden pixels are dropped and small holes in
hidden regions closed (a 3×3 opening and closing).  The reference frame is
visible everywhere.

References
----------
N. Sundaram, T. Brox, K. Keutzer, "Dense point trajectories by GPU-accelerated
large displacement optical flow", ECCV 2010.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .._validate import check_field as _check
from ..ops.fusion import flow_cost, fuse, support_weights
from ..ops.warp import in_bounds, warp_bicubic
from ..twoframe.coarse_to_fine import coarse_to_fine_pyramids
from ..twoframe.tvl1 import TVL1Params, solve_warp

__all__ = [
    "VisibilityParams",
    "invert_flow",
    "splat_inverse",
    "in_bounds",
    "fb_error",
    "backward_flows",
    "visibility_from",
    "estimate_visibility",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VisibilityParams:
    """Thresholds of :func:`estimate_visibility`.

    Attributes
    ----------
    fb_tolerance : float
        Largest forward-backward error of a visible point, pixels.  Default 1.5.
    photo_factor : float
        A visible point's photometric cost is at most this many times the frame's
        median cost.  Default 4.
    photo_floor : float
        Lower bound of the photometric threshold (intensity units, images in
        [0, 1]).  Default 0.02.
    backward_levels : int
        Pyramid levels of the refinement of the inverted trajectories into the
        backward flow.  Default 3.
    clean : bool
        3×3 opening and closing of the hidden mask.  Default True.
    """

    fb_tolerance: float = 1.5
    photo_factor: float = 4.0
    photo_floor: float = 0.02
    backward_levels: int = 3
    clean: bool = True

    def __post_init__(self) -> None:
        _check(self.fb_tolerance > 0, "fb_tolerance", f"must be > 0, got {self.fb_tolerance}")
        _check(self.photo_factor > 0, "photo_factor", f"must be > 0, got {self.photo_factor}")
        _check(self.photo_floor >= 0, "photo_floor", f"must be >= 0, got {self.photo_floor}")
        _check(self.backward_levels >= 1, "backward_levels",
               f"must be >= 1, got {self.backward_levels}")


def invert_flow(flow: np.ndarray, iterations: int = 5) -> np.ndarray:
    """Approximate inverse ``b`` of a flow ``w``: ``b(y) = −w(y + b(y))`` by fixed point.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
        Forward flow from frame A to frame B.
    iterations : int

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        Flow from B to A, exact where ``w`` is smooth; at occlusions it takes one
        of the surfaces that land on ``y``.
    """
    w = np.ascontiguousarray(flow, np.float32)
    b = -w
    for _ in range(iterations):
        sampled, _ = warp_bicubic(w, b)
        b = -sampled
    return b.astype(np.float32)


def splat_inverse(flow: np.ndarray) -> np.ndarray:
    """Inverse of a flow by forward splatting: ``b(round(x + w(x))) = −w(x)``.

    Where several pixels land on one target, the one with the largest ``|w|`` wins
    (a moving object is more often in front of the slower background); targets
    that nothing lands on are NaN.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)
        Forward flow from frame A to frame B.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        Flow from B to A, NaN where no pixel of A lands.
    """
    w = np.asarray(flow, np.float32)
    h, wd = w.shape[:2]
    yy, xx = np.mgrid[0:h, 0:wd]
    tx = np.rint(xx + w[..., 0])
    ty = np.rint(yy + w[..., 1])
    ok = np.isfinite(tx) & np.isfinite(ty) & (tx >= 0) & (tx <= wd - 1) & (ty >= 0) & (ty <= h - 1)
    src = np.flatnonzero(ok)
    dst = ty[ok].astype(np.int64) * wd + tx[ok].astype(np.int64)
    mag = np.hypot(w[..., 0], w[..., 1]).ravel()[src]
    order = np.lexsort((src, mag))  # by |w|, then by index: ties resolved the same way
    best = np.full(h * wd, -1, np.int64)
    best[dst[order]] = src[order]  # sorted ascending: the last write is the largest |w|
    out = np.full((h * wd, 2), np.nan, np.float32)
    hit = best >= 0
    out[hit] = -w.reshape(-1, 2)[best[hit]]
    return out.reshape(h, wd, 2)


def fb_error(forward: np.ndarray, backward: np.ndarray) -> np.ndarray:
    """Forward-backward error ``|w(x) + b(x + w(x))|``: ``(H, W)`` float32, pixels."""
    sampled, _ = warp_bicubic(np.ascontiguousarray(backward, np.float32), forward)
    return np.hypot(forward[..., 0] + sampled[..., 0], forward[..., 1] + sampled[..., 1])


def _clean(hidden: np.ndarray) -> np.ndarray:
    st = np.ones((3, 3), bool)
    out = ndimage.binary_opening(hidden, st)
    return ndimage.binary_closing(out, st, border_value=0) | (out & hidden)


def backward_flows(
    traj: np.ndarray,
    ref: int,
    pyramids: list[list[np.ndarray]],
    flow_params: TVL1Params,
    levels: int = 3,
    callback: Callable[[], None] | None = None,
    splat: bool = False,
) -> np.ndarray:
    """Flows from every frame back to the reference, from the inverted trajectories.

    ``B_n`` = :func:`invert_flow` of ``T_n`` (with ``splat``: per pixel the better
    fit, by :func:`varflow.ops.fusion.fuse` on the pre-processed frames, of it and
    :func:`splat_inverse`), refined by TV-L1 from frame ``n`` to the reference on
    the finest ``levels`` pyramid levels.

    Parameters
    ----------
    traj : ndarray, shape (F, H, W, 2)
    ref : int
    pyramids : list
        :func:`varflow.multiframe.propagate.frame_pyramids` of the frames.
    flow_params : TVL1Params
    levels : int
    callback : callable, optional
        Called without arguments after each flow.
    splat : bool
        Offer the splatted inverse as a second initial candidate.

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
        ``B[ref] = 0``.
    """
    back = np.zeros_like(traj, dtype=np.float32)
    for n in range(traj.shape[0]):
        if n != ref:
            init = invert_flow(traj[n])
            if splat:
                splatted = splat_inverse(traj[n])
                splatted = np.where(np.isnan(splatted), init, splatted)
                tex_n, tex_r = pyramids[n][0], pyramids[ref][0]
                init, _ = fuse(tex_n, tex_r, [init, splatted], support_weights(tex_n))
            back[n] = coarse_to_fine_pyramids(pyramids[n], pyramids[ref], solve_warp,
                                              flow_params, init_flow=init, levels=levels)
            if callback is not None:
                callback()
    return back


def visibility_from(
    traj: np.ndarray,
    back: np.ndarray,
    ref: int,
    textures: list[np.ndarray],
    params: VisibilityParams | None = None,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """The three tests of the module notes, given the backward flows.

    Parameters
    ----------
    traj : ndarray, shape (F, H, W, 2)
    back : ndarray, shape (F, H, W, 2)
        :func:`backward_flows`.
    ref : int
    textures : list of ndarray, each (H, W, C)
        The frames as the solver sees them (pre-processed, finest pyramid level).
    params : VisibilityParams, optional
    weights : ndarray, optional
        :func:`varflow.ops.fusion.support_weights` of ``textures[ref]``.

    Returns
    -------
    ndarray, shape (F, H, W), bool
    """
    params = params or VisibilityParams()
    n_frames, h, w = traj.shape[:3]
    if weights is None:
        weights = support_weights(textures[ref])
    visible = np.ones((n_frames, h, w), bool)
    for n in range(n_frames):
        if n == ref:
            continue
        fwd = traj[n]
        inside = in_bounds(fwd)
        fb_ok = fb_error(fwd, back[n]) <= params.fb_tolerance
        cost = flow_cost(textures[ref], textures[n], fwd, weights)
        scale = float(np.median(cost[inside])) if inside.any() else 0.0
        photo_ok = cost <= max(params.photo_factor * scale, params.photo_floor)
        hidden = ~(fb_ok & photo_ok)
        if params.clean:
            hidden = _clean(hidden)
        visible[n] = inside & ~hidden
    return visible


def estimate_visibility(
    traj: np.ndarray,
    ref: int,
    pyramids: list[list[np.ndarray]],
    flow_params: TVL1Params,
    params: VisibilityParams | None = None,
    stats: dict | None = None,
    splat: bool = False,
) -> np.ndarray:
    """Visibility of every reference pixel in every frame (see the module notes).

    :func:`backward_flows` then :func:`visibility_from`.

    Parameters
    ----------
    traj : ndarray, shape (F, H, W, 2), float32
        Trajectories of the reference pixels.
    ref : int
    pyramids : list
        :func:`varflow.multiframe.propagate.frame_pyramids` of the frames.
    flow_params : TVL1Params
        Of the backward flows.
    params : VisibilityParams, optional
    stats : dict, optional
        Gains ``seconds``, ``hidden`` (share of hidden (frame ≠ ref, pixel) pairs)
        and ``backward`` (the backward flows, for :func:`visibility_from`).
    splat : bool
        See :func:`backward_flows`.

    Returns
    -------
    ndarray, shape (F, H, W), bool
    """
    params = params or VisibilityParams()
    t0 = time.perf_counter()
    back = backward_flows(traj, ref, pyramids, flow_params, params.backward_levels,
                          splat=splat)
    visible = visibility_from(traj, back, ref, [p[0] for p in pyramids], params)
    if stats is not None:
        others = np.arange(traj.shape[0]) != ref
        stats.update(seconds=time.perf_counter() - t0, backward=back,
                     hidden=float(1.0 - visible[others].mean()) if others.any() else 0.0)
    return visible
