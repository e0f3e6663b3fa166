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
   the inverse of ``T_n`` (fixed-point inversion) refined by the two-frame solver
   on the finest pyramid levels.
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

from ..ops.fusion import flow_cost, support_weights
from ..ops.warp import in_bounds, warp_bicubic
from ..twoframe.coarse_to_fine import _check, coarse_to_fine_pyramids
from ..twoframe.tvl1 import TVL1Params, solve_warp

__all__ = [
    "VisibilityParams",
    "invert_flow",
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
) -> np.ndarray:
    """Flows from every frame back to the reference, from the inverted trajectories.

    ``B_n`` = :func:`invert_flow` of ``T_n`` refined by TV-L1 from frame ``n`` to the
    reference on the finest ``levels`` pyramid levels.

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

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
        ``B[ref] = 0``.
    """
    back = np.zeros_like(traj, dtype=np.float32)
    for n in range(traj.shape[0]):
        if n != ref:
            back[n] = coarse_to_fine_pyramids(pyramids[n], pyramids[ref], solve_warp,
                                              flow_params, init_flow=invert_flow(traj[n]),
                                              levels=levels)
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

    Returns
    -------
    ndarray, shape (F, H, W), bool
    """
    params = params or VisibilityParams()
    t0 = time.perf_counter()
    back = backward_flows(traj, ref, pyramids, flow_params, params.backward_levels)
    visible = visibility_from(traj, back, ref, [p[0] for p in pyramids], params)
    if stats is not None:
        others = np.arange(traj.shape[0]) != ref
        stats.update(seconds=time.perf_counter() - t0, backward=back,
                     hidden=float(1.0 - visible[others].mean()) if others.any() else 0.0)
    return visible
