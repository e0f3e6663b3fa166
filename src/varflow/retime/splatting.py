"""``splat``: frame interpolation by the flow splatted to time t, with occlusion reasoning.

The Middlebury interpolation algorithm (Baker et al. 2011, section 3.3) made
bidirectional, with softmax splatting (Niklaus & Liu 2020) as its z-buffer:

1. **Flows both ways**, ``F01`` and ``F10``, with a registered two-frame method
   (:attr:`SplatParams.flow_method`, computed as :func:`varflow.flow` computes
   them).
2. **Occlusions of each frame**: a pixel of frame 0 is *hidden in frame 1*
   (``O0 = 1``) when its flow leaves the image or fails the forward-backward
   check ``|F01(x) + F10(x + F01(x))| > τ_fb + κ |F01(x)|``; ``O1`` likewise
   (:func:`varflow.ops.occlusion.hidden_mask`).
3. **Where every pixel is at time t**: a pixel ``x`` of frame 0 moves by
   ``d0 = t F01(x)``, a pixel ``y`` of frame 1 by ``d1 = (1 − t) F10(y)`` (back in
   time); each carries the vectors from where it lands to its places in both
   frames (``−d0`` and ``F01 − d0``; ``F10 − d1`` and ``−d1``).  Both frames'
   pixels are splatted into one field with the importance ``exp(−α Z)``, ``Z`` the
   pixel's photometric error ``mean_c |I0(x) − I1(x + F01(x))|`` (intensity
   units) plus ``ζ`` where it is hidden in the other frame
   (:func:`varflow.ops.splat.splat_trajectories`).  Where a moving surface and
   the background land on one pixel, the surface seen in both frames wins; frame
   1's pixels supply what is uncovered, which frame 0 does not see.  Holes are
   filled outside in (:func:`varflow.ops.splat.fill_holes`).  With the frames
   before and after the pair, the motion is quadratic (Xu et al. 2019):
   ``d0 = t F01 + a0 (t² − t) / 2`` with the acceleration ``a0 = F01 + F0,−1``,
   likewise for frame 1 (:func:`accelerations`): it pays where the motion
   accelerates (Sintel; benchmarks/HISTORY.md).
4. **The frame**: with ``v0``, ``v1`` the splatted vectors of step 3 (for linear
   motion ``−t u_t`` and ``(1 − t) u_t``, ``u_t`` the motion at time t),
   ``x0 = p + v0(p)`` and ``x1 = p + v1(p)``;
   ``I_t(p) = (w0 I0(x0) + w1 I1(x1)) / (w0 + w1)``
   with ``w0 = (1 − t)(1 − O1(x1))`` and ``w1 = t (1 − O0(x0))`` (a sample from a
   frame in which the point is hidden, or outside the frame, is left out; where
   both are, the plain ``(1 − t, t)`` blend).  The frames are sampled bicubically
   (bilinear sampling blurs: 1.0, 0.1 and 0.1 dB less on Middlebury, UCF101 and
   Sintel) and the result is clipped to the range of the two frames.
5. **Where the motion is not known**: where both samples come from points hidden
   in the other frame (``O0(x0) O1(x1)``, smoothed), the flows failed (fast
   non-rigid motion, motion blur) and the two samples show different things; the
   frame is softened there by a Gaussian of σ = :attr:`SplatParams.fallback_blur`
   rather than showing two sharp, misplaced copies (a gain on every set;
   benchmarks/HISTORY.md).
6. **Where the motion is not known anywhere**: when the flows explain neither frame
   (two unrelated pictures: a scene cut, a flash, a failure of the flow on the whole
   frame), splatting shows torn, misplaced pieces.  A pixel's flow is *lost* where its
   photometric error ``Z``, averaged by a Gaussian of σ 4 px, exceeds
   :attr:`SplatParams.lost_error`; with ``m`` the share of lost pixels of both
   frames and ``f`` = :attr:`SplatParams.lost_fraction`, the frame fades toward the
   plain blend ``(1 − t) I0 + t I1`` with the weight ``clip(2 m / f − 1, 0, 1)``:
   untouched while a quarter of the pixels or fewer are lost at the default, the
   blend where half are.  (On every pair of the interpolation sets at most 7 % of
   the pixels are lost; on two unrelated textures all are.)

The motion (steps 1-2, the accelerations and the lost share) is estimated once per
pair; steps 3-6 run for every ``t``.

References
----------
S. Baker, D. Scharstein, J. P. Lewis, S. Roth, M. J. Black, R. Szeliski, "A Database
and Evaluation Methodology for Optical Flow", IJCV 92(1), 2011.
S. Niklaus, F. Liu, "Softmax Splatting for Video Frame Interpolation", CVPR 2020.
X. Xu, L. Siyao, W. Sun, Q. Yin, M.-H. Yang, "Quadratic Video Interpolation",
NeurIPS 2019.
N. Sundaram, T. Brox, K. Keutzer, "Dense point trajectories by GPU-accelerated large
displacement optical flow", ECCV 2010 (the forward-backward check).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .._validate import check_field
from ..ops.occlusion import hidden_mask, photometric_error
from ..ops.pyramid import smooth_image_fast
from ..ops.splat import fill_holes, splat_trajectories
from ..ops.warp import warp_bicubic, warp_bilinear
from ..registry import FLOW
from ..twoframe.coarse_to_fine import ProgressCallback
from ..twoframe.methods import FlowComposed
from ..twoframe.params import TVL1Params
from .motion import FlowCache, PairMotion, pair_flows

__all__ = ["SAMPLINGS", "SplatFastParams", "SplatMotion", "SplatParams", "accelerations",
           "splat_fast_defaults",
           "prepare_splat"]

#: Values of :attr:`SplatParams.sampling`.
SAMPLINGS = ("bicubic", "bilinear")


@dataclass(frozen=True)
class SplatParams(FlowComposed):
    """Parameters of ``splat`` (see :mod:`varflow.retime.splatting`).

    Attributes
    ----------
    flow_method : str
        The two-frame method of ``F01`` and ``F10`` (default ``"tvl1-ld"``:
        interpolated footage is often fast).
    flow_params : TVL1Params or None
        Its parameters; None gives :meth:`default_flow_params`: the method's
        defaults, for ``tvl1-ld`` with the matching on frames of half the size
        (``match_scale`` 0.5), the weighted median on the finest 3 levels and 24
        iterations per warp (as ``tvl1``): about 0.6 of the time for at most a
        fifth of a dB (benchmarks/HISTORY.md).
    flow_max_pixels : int
        Frames of more pixels than this are resized to this many for the flows
        (anti-aliased; the flows are resized back), which bounds their cost on
        large frames; the frames themselves are rendered at full size.  0: never.
        Default 300 000: 960 × 540 frames are reduced to 0.76 of their size, at
        no measured loss.
    splat_sharpness : float
        α of the splatting importance ``exp(−α Z)``, 1/intensity units (frames in
        [0, 1]); 0 averages whatever lands on a pixel, large values keep the
        lowest cost only (a z-buffer).  Default 50.
    occlusion_cost : float
        ζ, the cost added to ``Z`` of a pixel hidden in the other frame, intensity
        units: such a pixel wins a target pixel only where no visible one lands.
        Default 1.
    fb_tolerance : float
        τ_fb of the forward-backward check, pixels.  Default 3.
    fb_relative : float
        κ, the growth of the check's tolerance with the flow's length (pixels per
        pixel of flow).  Default 0.05.
    sampling : {"bicubic", "bilinear"}
        How the frames are sampled.  Default ``"bicubic"``.
    visibility_blend : bool
        Leave out a sample from a frame in which the point is hidden (step 4);
        False blends both with ``(1 − t, t)`` everywhere.  Default True.
    fallback_blur : float
        σ (pixels) of the Gaussian that softens the frame where both samples
        come from points hidden in the other frame (step 5 of the module notes);
        0 leaves it sharp.  Default 2.
    quadratic : bool
        With the frames before and after the pair (``previous`` / ``following``,
        as a video has them), move the pixels along quadratic trajectories (step
        3 of the module notes); without them, or False, linear motion.  Default
        True.
    lost_error : float
        τ_L of step 6: a pixel's flow is lost where its photometric error,
        averaged over a Gaussian of σ 4 px, exceeds it (intensity units, frames in
        [0, 1]).  Default 0.1 (at most 0.021 on average over a pair of the
        interpolation sets; 0.25 between unrelated textures).
    lost_fraction : float
        f of step 6: the share of lost pixels at which the frame is the plain
        blend (half of it starts the fade), in [0, 1]; 0 turns step 6 off.
        Default 0.5.
    """

    flow_method: str = "tvl1-ld"
    flow_params: TVL1Params | None = None
    flow_max_pixels: int = 300_000
    splat_sharpness: float = 50.0
    occlusion_cost: float = 1.0
    fb_tolerance: float = 3.0
    fb_relative: float = 0.05
    sampling: str = "bicubic"
    visibility_blend: bool = True
    fallback_blur: float = 2.0
    quadratic: bool = True
    lost_error: float = 0.1
    lost_fraction: float = 0.5

    @classmethod
    def default_flow_params(cls, flow_method: str) -> TVL1Params:
        """The method's defaults; for ``tvl1-ld`` with ``match_scale`` 0.5,
        ``weighted_median_levels`` 3 and ``max_iterations`` 24."""
        defaults = FLOW[flow_method].defaults()
        if flow_method == "tvl1-ld":
            return defaults.replace(match_scale=0.5, weighted_median_levels=3,
                                    max_iterations=24)
        return defaults

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("splat_sharpness", "occlusion_cost", "fb_tolerance", "fb_relative",
                     "fallback_blur", "lost_error"):
            v = getattr(self, name)
            check_field(isinstance(v, (int, float)) and not isinstance(v, bool)
                        and np.isfinite(v) and v >= 0, name,
                        f"must be a finite number >= 0, got {v!r}")
        check_field(isinstance(self.flow_max_pixels, int) and not isinstance(
            self.flow_max_pixels, bool) and self.flow_max_pixels >= 0, "flow_max_pixels",
            f"must be an integer >= 0, got {self.flow_max_pixels!r}")
        check_field(isinstance(self.lost_fraction, (int, float))
                    and not isinstance(self.lost_fraction, bool)
                    and 0.0 <= self.lost_fraction <= 1.0, "lost_fraction",
                    f"must be a number in [0, 1], got {self.lost_fraction!r}")
        check_field(self.sampling in SAMPLINGS, "sampling",
                    f"expected one of {', '.join(SAMPLINGS)}, got {self.sampling!r}")
        for name in ("visibility_blend", "quadratic"):
            check_field(isinstance(getattr(self, name), bool), name,
                        f"expected a bool, got {getattr(self, name)!r}")


def splat_fast_defaults() -> SplatParams:
    """The defaults of ``splat-fast``: ``splat`` on the ``tvl1-fast`` preset's flows,
    estimated on frames of at most 150 000 pixels (``flow_max_pixels``): within 3× of
    FFmpeg minterpolate's time per 960 × 540 frame (benchmarks/README.md)."""
    return SplatParams(flow_method="tvl1-fast", flow_max_pixels=150_000)


def SplatFastParams(**fields: object) -> SplatParams:
    """Deprecated: :func:`splat_fast_defaults` with ``fields`` (routed as
    :meth:`SplatParams.replace` does)."""
    warnings.warn("SplatFastParams is deprecated: use varflow.make_interp_params("
                  "'splat-fast', ...)", DeprecationWarning, stacklevel=2)
    return splat_fast_defaults().replace(**fields) if fields else splat_fast_defaults()


class SplatMotion(PairMotion):
    """The motion of a pair for ``splat``: both flows, occlusions, splatting weights and
    the pixels' accelerations.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, C), float32
    f01, f10 : ndarray, shape (H, W, 2)
        The flows both ways.
    params : SplatParams
    accel0, accel1 : ndarray, shape (H, W, 2), optional
        The acceleration ``a`` of every pixel of frame 0 and of frame 1 (pixels
        per frame interval², zero: linear motion); see :func:`accelerations`.

    Attributes
    ----------
    f01, f10, accel0, accel1 : ndarray, shape (H, W, 2), float32
    hidden0, hidden1 : ndarray, shape (H, W), bool
        ``O0`` and ``O1``.
    importance0, importance1 : ndarray, shape (H, W), float64
        ``exp(−α Z)`` of the pixels of each frame.
    lost : float
        The share of the pixels of both frames whose flow is lost (step 6 of the
        module notes), in [0, 1].
    """

    def __init__(self, frame0: np.ndarray, frame1: np.ndarray, f01: np.ndarray,
                 f10: np.ndarray, params: SplatParams, accel0: np.ndarray | None = None,
                 accel1: np.ndarray | None = None) -> None:
        super().__init__(frame0, frame1)
        self.params = params
        self.f01 = np.ascontiguousarray(f01, np.float32)
        self.f10 = np.ascontiguousarray(f10, np.float32)
        zero = np.zeros_like(self.f01)
        self.accel0 = zero if accel0 is None else np.ascontiguousarray(accel0, np.float32)
        self.accel1 = zero if accel1 is None else np.ascontiguousarray(accel1, np.float32)
        p = params
        self._lo = np.float32(min(frame0.min(), frame1.min()))
        self._hi = np.float32(max(frame0.max(), frame1.max()))
        # α and ζ are in the units of frames in [0, 1]; float frames of another range
        # (e.g. 0..255) have their photometric errors scaled by the joint range
        inside = self._lo >= 0 and self._hi <= 1
        self._unit = 1.0 if inside else 1.0 / max(float(self._hi - self._lo), 1e-12)
        self.hidden0 = hidden_mask(self.f01, self.f10, p.fb_tolerance, p.fb_relative)
        self.hidden1 = hidden_mask(self.f10, self.f01, p.fb_tolerance, p.fb_relative)
        z0 = photometric_error(frame0, frame1, self.f01).astype(np.float64) * self._unit
        z1 = photometric_error(frame1, frame0, self.f10).astype(np.float64) * self._unit
        self.importance0 = self._importance(z0, self.hidden0)
        self.importance1 = self._importance(z1, self.hidden1)
        self.lost = lost_share((z0, z1), p.lost_error)

    def _importance(self, error: np.ndarray, hidden: np.ndarray) -> np.ndarray:
        cost = error + self.params.occlusion_cost * hidden
        # float64: exp(-alpha Z) stays positive for any cost of interest (a landing
        # pixel counts as covered however costly; float32 underflows near exp(-103))
        return np.exp(-np.minimum(self.params.splat_sharpness * cost, 700.0))

    def vectors_at(self, t: float) -> np.ndarray:
        """Where the point at each pixel of the frame at ``t`` is in frame 0 and in frame 1.

        Frame 0's pixels move by ``d0(t) = t F01 + a0 (t² − t) / 2`` and frame 1's
        by ``d1(s) = s F10 + a1 (s² − s) / 2`` (``s = 1 − t``: back in time); each
        carries the vectors from its position at ``t`` to its positions in both
        frames, ``(−d0, F01 − d0)`` and ``(F10 − d1, −d1)``, splatted as in step 3
        of the module notes and filled outside in.  With zero accelerations the
        two vectors are ``−t u_t`` and ``(1 − t) u_t``.

        Returns
        -------
        ndarray, shape (H, W, 4), float32
            ``[..., :2]`` the vector to frame 0, ``[..., 2:]`` to frame 1.
        """
        acc, tot = splat_trajectories(self.f01, self.accel0, self.importance0, t, True)
        acc, tot = splat_trajectories(self.f10, self.accel1, self.importance1, 1.0 - t, False,
                                      acc, tot)
        known = tot > 0
        field = np.zeros(acc.shape, np.float32)
        np.divide(acc, tot[..., None], out=field, where=known[..., None], casting="unsafe")
        return fill_holes(field, known)

    def flow_at(self, t: float) -> np.ndarray:
        """``u_t``: the motion 0 → 1 of the point at each pixel of the frame at ``t``
        (the difference of the two vectors of :meth:`vectors_at`).

        Returns
        -------
        ndarray, shape (H, W, 2), float32
        """
        v = self.vectors_at(t)
        return np.ascontiguousarray(v[..., 2:] - v[..., :2])

    def render(self, t: float) -> np.ndarray:
        p = self.params
        t32 = np.float32(t)
        v = self.vectors_at(t)
        back0 = np.ascontiguousarray(v[..., :2])
        back1 = np.ascontiguousarray(v[..., 2:])
        sample = warp_bicubic if p.sampling == "bicubic" else warp_bilinear
        s0, in0 = sample(self.frame0, back0)
        s1, in1 = sample(self.frame1, back1)
        if p.visibility_blend:
            h0, _ = warp_bilinear(self.hidden0.astype(np.float32)[..., None], back0)
            h1, _ = warp_bilinear(self.hidden1.astype(np.float32)[..., None], back1)
            w0 = (1 - t32) * (1 - h1[..., 0]) * in0
            w1 = t32 * (1 - h0[..., 0]) * in1
            none = (w0 + w1) < 1e-3
            w0 = np.where(none, 1 - t32, w0)
            w1 = np.where(none, t32, w1)
            out = (w0[..., None] * s0 + w1[..., None] * s1) / (w0 + w1)[..., None]
            if p.fallback_blur > 0:
                sigma = p.fallback_blur
                both = smooth_image_fast((h0 * h1).astype(np.float32), sigma)
                if both.max() > 0:
                    out += both * (smooth_image_fast(out, sigma) - out)
        else:
            out = (1 - t32) * s0 + t32 * s1
        fade = lost_weight(self.lost, p.lost_fraction)
        if fade > 0:  # step 6: the flows explain nothing; toward the plain blend
            blend = (1 - t32) * self.frame0 + t32 * self.frame1
            out = out + np.float32(fade) * (blend - out)
        return np.clip(out, self._lo, self._hi).astype(np.float32)


#: σ (px) of the Gaussian that averages the photometric error in :func:`lost_share`.
LOST_SIGMA = 4.0


def lost_share(errors: tuple[np.ndarray, ...], threshold: float) -> float:
    """The share of pixels whose flow is lost: their photometric error, averaged by
    a Gaussian of σ :data:`LOST_SIGMA` px, above ``threshold``.

    Parameters
    ----------
    errors : tuple of ndarray, each (H, W)
        The photometric errors ``Z`` of each frame's flow (intensity units).
    threshold : float
        τ_L (:attr:`SplatParams.lost_error`).

    Returns
    -------
    float
        In [0, 1]: lost pixels over all pixels of all the frames.
    """
    lost = total = 0
    for z in errors:
        r = smooth_image_fast(np.ascontiguousarray(z, np.float32)[..., None], LOST_SIGMA)
        lost += int(np.count_nonzero(r > np.float32(threshold)))
        total += z.size
    return lost / max(total, 1)


def lost_weight(share: float, fraction: float) -> float:
    """The weight of the plain blend in step 6: ``clip(2 share / fraction − 1, 0, 1)``
    (0 when ``fraction`` is 0)."""
    if fraction <= 0:
        return 0.0
    return float(min(max(2.0 * share / fraction - 1.0, 0.0), 1.0))


def accelerations(f01: np.ndarray, f10: np.ndarray, f0m: np.ndarray | None,
                  fm0: np.ndarray | None, f12: np.ndarray | None, f21: np.ndarray | None,
                  hidden0: np.ndarray, hidden1: np.ndarray,
                  params: SplatParams) -> tuple[np.ndarray, np.ndarray]:
    """The accelerations of the pixels of frames 0 and 1 from their neighbours' flows.

    A frame-0 pixel on a quadratic trajectory ``x(τ) = x + v τ + a τ²/2`` through
    frames −1, 0, 1 has ``F01 = v + a/2`` and ``F0,−1 = −v + a/2``, so
    ``a0 = F01 + F0,−1`` (Xu et al. 2019); likewise ``a1 = F10 + F12`` for frame 1
    (``τ`` back in time).  ``a`` is set to zero (linear motion) where the pixel is
    hidden in the other frame of the pair or its flow to the neighbour fails that
    pair's forward-backward check (:func:`hidden_mask`), and everywhere when the
    neighbour is missing.

    Parameters
    ----------
    f01, f10 : ndarray, shape (H, W, 2)
    f0m, fm0 : ndarray or None
        Flows frame 0 → previous frame and back.
    f12, f21 : ndarray or None
        Flows frame 1 → following frame and back.
    hidden0, hidden1 : ndarray, shape (H, W), bool
        :func:`varflow.ops.occlusion.hidden_mask` of the pair's flows.
    params : SplatParams
        The forward-backward tolerances.

    Returns
    -------
    accel0, accel1 : ndarray, shape (H, W, 2), float32
    """
    out = []
    for flow, ctx, back, hidden in ((f01, f0m, fm0, hidden0), (f10, f12, f21, hidden1)):
        if ctx is None or back is None:
            out.append(np.zeros(np.shape(flow), np.float32))
            continue
        lost = hidden | hidden_mask(ctx, back, params.fb_tolerance, params.fb_relative)
        out.append(np.where(lost[..., None], np.float32(0), flow + ctx).astype(np.float32))
    return out[0], out[1]


def prepare_splat(frame0: np.ndarray, frame1: np.ndarray, params: SplatParams,
                  previous: np.ndarray | None = None, following: np.ndarray | None = None,
                  callback: ProgressCallback | None = None, stats: dict | None = None,
                  cache: FlowCache | None = None) -> SplatMotion:
    """The ``prepare`` of ``splat``: the flows both ways, occlusions and, with
    :attr:`SplatParams.quadratic` and context frames, the accelerations (each context
    frame costs two more flows, which a stream with a :class:`FlowCache` has
    already estimated for the neighbouring pair)."""
    if not params.quadratic:
        previous = following = None
    pairs = [(frame0, frame1), (frame1, frame0)]
    if previous is not None:
        pairs += [(frame0, previous), (previous, frame0)]
    if following is not None:
        pairs += [(frame1, following), (following, frame1)]
    flows = pair_flows(pairs, params, callback, stats, cache, params.flow_max_pixels)
    f01, f10 = flows[0], flows[1]
    ctx = flows[2:]
    f0m, fm0 = (ctx.pop(0), ctx.pop(0)) if previous is not None else (None, None)
    f12, f21 = (ctx.pop(0), ctx.pop(0)) if following is not None else (None, None)
    motion = SplatMotion(frame0, frame1, f01, f10, params)
    if f0m is not None or f12 is not None:
        motion.accel0, motion.accel1 = accelerations(
            f01, f10, f0m, fm0, f12, f21, motion.hidden0, motion.hidden1, params)
    return motion
