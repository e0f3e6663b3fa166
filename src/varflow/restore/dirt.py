"""Dirt and dust removal for archival film: :func:`remove_dirt` and :class:`DirtParams`.

Dust, dirt and hairs sit on one frame of the print only, so along the motion they are
temporal spikes: the frame disagrees with both of its motion-compensated neighbours,
which agree with each other (Kokaram, *Motion Picture Restoration*, 1998).  The
detector here is a signed rank-order test of that kind on the colour mean, cleaned by
hysteresis; the detected pixels are filled from the neighbours along the flows, with
spatial inpainting where neither neighbour sees them, and every other pixel of the
clip is returned untouched (bit-identical).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from scipy import ndimage

from .._validate import check_field
from ..registry import REPAIR
from ..twoframe.methods import FlowComposed
from ..twoframe.params import TVL1Params
from .denoise import _as_clip, _to_dtype

__all__ = ["DirtParams", "remove_dirt"]

log = logging.getLogger(__name__)

Callback = Callable[[int, int], None]
Flows = dict[tuple[int, int], np.ndarray]

#: Radius (pixels) of the box over which the neighbours' disagreement is averaged
#: for ``agree_local``.
_LOCAL = 3


@dataclass(frozen=True)
class DirtParams(FlowComposed):
    """Parameters of :func:`remove_dirt` (motion-compensated blotch detection and fill).

    Intensities are in grey levels on a 0-255 scale whatever the clip's dtype (see
    :func:`remove_dirt` for the scale of float clips).

    Attributes
    ----------
    sensitivity : float
        s, the trade of recall for precision: every threshold below is divided by it
        (above 1 finds fainter dirt and raises false alarms on badly compensated
        motion; below 1 the reverse).  Positive.  Default 1.
    threshold : float
        T, grey levels: a pixel seeds a blotch when it lies more than T / s outside
        the range of its two motion-compensated neighbours over the ``window``
        (darker than both or brighter than both, on the mean of the channels), less
        the disagreement penalties (``agree``, ``agree_local``).  Positive.
        Default 20 (chosen on the tuning clips: 30 missed dark dirt on dark
        clothes, 15 added false alarms).
    low : float
        The hysteresis ratio: pixels beyond ``low * T / s`` at the pixel itself (no
        window) are added when connected to a seed (the soft, ragged rims of a
        blotch, and blotches on fine texture).  In (0, 1].  Default 0.4.
    mixed : float
        m, the largest share of a detection's spike on its minority side: the sums
        over the detection of how far its pixels lie below and above the range of
        the neighbours over the ``window`` are taken, and a detection whose smaller
        sum exceeds ``m`` times their total is dropped.  A blotch is one tone laid
        over the picture (darker than both neighbours, or brighter); a moving object
        the flow has lost is the picture itself, its texture darker and brighter
        than what the neighbours show.  In [0, 0.5] (0.5: no test).  Default 0.1
        (chosen on the tuning clips: 0.02 dropped blotches).
    ends : float
        Seed and growth thresholds are multiplied by this on the first and last
        frame of a clip, whose two candidates are both on one side in time (new
        content entering the picture agrees with neither).  >= 1.  Default 1.5.
    agree : float
        a, weight of the neighbours' disagreement ``|P - N|`` (mean over channels)
        at the pixel, taken off the spike: where the two compensated neighbours
        disagree the motion is unreliable and no spike is trusted.  >= 0.
        Default 0.5.
    agree_local : float
        The same for the disagreement averaged over a 7 × 7 box: badly compensated
        regions (fast, blurred or non-rigid motion) need larger spikes.  >= 0.
        Default 1 (0 doubled the false alarms on the tuning clips).
    window : int
        Radius in pixels of the square window of compensated neighbour pixels whose
        range a seed is tested against (the rank-order test's tolerance of
        sub-pixel flow errors at edges); 0 tests the pixel alone.  In [0, 3].
        Default 1.
    occluded : float
        Seed and growth thresholds are multiplied by this where a neighbour is
        occluded or outside the frame (forward-backward check failed): only clear
        spikes are taken there.  >= 1.  Default 1.5.
    min_area : int
        Connected detections smaller than this many pixels are dropped (noise, not
        dirt).  >= 1.  Default 4.
    dilate : int
        Radius in pixels of the ring around the cleaned mask added to it where the
        frame is outside its neighbours' range by more than ``rim`` (the faint outer
        rim of a blotch).  In [0, 8].  Default 1.
    rim : float
        That margin, grey levels.  >= 0.  Default 2 (0: the whole ring).
    refine : int
        Times a rough detection (thresholds times 0.75, dilated 2 px more) fills the
        frames, the flows are estimated again on them and the detection repeated:
        the blotches pull the flows of the dirty frames (on the tuning clips one
        refinement raised the recall on carphone from 0.6 to 0.75 and the
        blotched-pixel PSNR by 4-6 dB, at twice the flow time).  In [0, 3].
        Default 1.
    flow_method : str
        The two-frame method of the flows.  Default ``"tvl1-fast"``.
    flow_params : TVL1Params or None
        Its parameters (None: its defaults).
    flow_max_pixels : int
        Frames of more pixels than this get their flows on a reduced copy; 0: never.
        Default 0.
    fb_tolerance : float
        α₂ of the forward-backward check, px² (:func:`varflow.consistency`).
        Default 0.5.
    """

    sensitivity: float = 1.0
    threshold: float = 20.0
    low: float = 0.4
    mixed: float = 0.1
    ends: float = 1.5
    agree: float = 0.5
    agree_local: float = 1.0
    window: int = 1
    occluded: float = 1.5
    min_area: int = 4
    dilate: int = 1
    rim: float = 2.0
    refine: int = 1
    flow_method: str = "tvl1-fast"
    flow_params: TVL1Params | None = None
    flow_max_pixels: int = 0
    fb_tolerance: float = 0.5

    def __post_init__(self) -> None:
        super().__post_init__()

        def integer(name: str, low: int, high: int | None = None) -> None:
            v = getattr(self, name)
            ok = isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= low \
                and (high is None or v <= high)
            rng = f">= {low}" if high is None else f"in [{low}, {high}]"
            check_field(ok, name, f"must be an integer {rng}, got {v!r}")

        def number(name: str, low: float, high: float | None = None,
                   open_low: bool = False) -> None:
            v = getattr(self, name)
            ok = isinstance(v, (int, float, np.integer, np.floating)) \
                and not isinstance(v, bool) and math.isfinite(v) \
                and (v > low if open_low else v >= low) and (high is None or v <= high)
            lo = f"> {low:g}" if open_low else f">= {low:g}"
            rng = lo if high is None else f"{lo} and <= {high:g}"
            check_field(ok, name, f"must be a finite number {rng}, got {v!r}")

        number("sensitivity", 0.0, open_low=True)
        number("threshold", 0.0, open_low=True)
        number("low", 0.0, 1.0, open_low=True)
        number("mixed", 0.0, 0.5)
        number("ends", 1.0)
        number("agree", 0.0)
        number("agree_local", 0.0)
        number("rim", 0.0)
        integer("window", 0, 3)
        number("occluded", 1.0)
        integer("min_area", 1)
        integer("dilate", 0, 8)
        integer("refine", 0, 3)
        integer("flow_max_pixels", 0)
        number("fb_tolerance", 0.0)


# --------------------------------------------------------------------------- helpers


def _scale(clip: np.ndarray) -> tuple[float, float]:
    """``(peak, base)``: the clip's values ``v`` are ``255 * (v - base) / peak`` grey
    levels on the 0-255 scale the thresholds are given in."""
    if clip.dtype.kind in "ui":
        return float(np.iinfo(clip.dtype).max), 0.0
    lo, hi = float(clip.min()), float(clip.max())
    if lo >= -0.05 and hi <= 1.05:
        return 1.0, 0.0
    if lo >= -45.0 and hi <= 300.0:
        return 255.0, 0.0
    return max(hi - lo, 1e-12), lo


def _candidates(t: int, n: int) -> tuple[int, ...]:
    """The two frames a frame is compared with: its neighbours, or at the ends of the
    clip the next (previous) frame and the one after (before) it."""
    if n < 3:
        return ()
    if t == 0:
        return (1, 2)
    if t == n - 1:
        return (n - 2, n - 3)
    return (t - 1, t + 1)


def _pairs(n: int) -> list[tuple[int, int]]:
    """The ordered frame pairs whose flows the detection needs."""
    return sorted({(t, c) for t in range(n) for c in _candidates(t, n)}
                  | {(c, t) for t in range(n) for c in _candidates(t, n)})


def _finite(x: np.ndarray) -> np.ndarray:
    """(H, W) True where every channel of ``x`` (H, W, C) is finite (the channels in
    turn: a reduction over the short last axis is several times slower)."""
    ok = np.isfinite(x[..., 0])
    for c in range(1, x.shape[-1]):
        ok &= np.isfinite(x[..., c])
    return ok


def _channel_mean(x: np.ndarray) -> np.ndarray:
    """(H, W) the mean of the channels of ``x`` (H, W, C), float32."""
    total = x[..., 0].astype(np.float32, copy=True)
    for c in range(1, x.shape[-1]):
        total += x[..., c]
    return total / np.float32(x.shape[-1])


def _warp(image: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) sampled bilinearly at ``x + flow(x)``; NaN outside."""
    from ..compensate import warp

    return warp(image, flow)


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The flow of ``a`` followed by ``b``: ``a(x) + b(x + a(x))`` (NaN outside)."""
    return a + _warp(b, a)


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _sides(t: int, n: int) -> list[tuple[int, int | None]]:
    """For each of a frame's two candidates, the frame it comes from and the frame
    that replaces it where it falls outside the picture (the next-but-one frame on
    the other side: content leaving the picture one way is still seen the other)."""
    if t == 0:
        return [(1, None), (2, 3 if n > 3 else None)]
    if t == n - 1:
        return [(n - 2, None), (n - 3, n - 4 if n > 3 else None)]
    return [(t - 1, t + 2 if t + 2 < n else None), (t + 1, t - 2 if t >= 2 else None)]


class _Frame:
    """One frame's two compensated candidates: values (H, W, C), NaN outside the
    picture, and usable (H, W): visible (forward-backward check) and, when the masks
    are given, not dirt themselves."""

    def __init__(self, values: list[np.ndarray], visible: list[np.ndarray],
                 spare: np.ndarray) -> None:
        self.values = values
        self.visible = visible
        self.spare = spare  # (H, W): a candidate is the next-but-one frame


def _flow(fl: Flows, t: int, c: int) -> np.ndarray:
    """The flow from frame ``t`` to frame ``c``: estimated, or composed through the
    frame between them."""
    if (t, c) not in fl:
        m = t + (1 if c > t else -1)
        fl[(t, c)] = _compose(fl[(t, m)], _flow(fl, m, c))
    return fl[(t, c)]


def _candidate(work: np.ndarray, t: int, c: int, fl: Flows, fb: float,
               mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    from ..compensate import consistency

    f = _flow(fl, t, c)
    value = _warp(work[c], f)
    ok = _finite(value) & consistency(f, _flow(fl, c, t), alpha2=fb)
    if mask is not None:
        dirt = np.nan_to_num(_warp(mask[c, :, :, None].astype(np.float32), f)[..., 0],
                             nan=1.0) >= 0.01
        value[dirt] = np.nan  # dirt itself: as if unseen, the spare frame replaces it
        ok &= ~dirt
    return value, ok


def _compensate(work: np.ndarray, t: int, fl: Flows, fb: float,
                mask: np.ndarray | None = None) -> _Frame:
    """Frame ``t``'s candidates (:class:`_Frame`); ``fl`` gains the composed flows."""
    values, visible = [], []
    used = np.zeros(work.shape[1:3], bool)
    for c, spare in _sides(t, work.shape[0]):
        value, ok = _candidate(work, t, c, fl, fb, mask)
        out = ~_finite(value)
        if spare is not None and out.any():
            v2, ok2 = _candidate(work, t, spare, fl, fb, mask)
            value[out], ok[out] = v2[out], ok2[out]
            used |= out & _finite(v2)
        values.append(value)
        visible.append(ok)
    return _Frame(values, visible, used)


def _score(frame: np.ndarray, cand: _Frame, p: DirtParams
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                      np.ndarray]:
    """The spike scores of a frame, grey levels (H, W) each: against the range of the
    compensated neighbours over the ``window`` less the disagreement penalties (the
    seeds' score; -inf where a neighbour falls outside the frame), the same at the
    pixel alone (the growth's score), the bare distance to the neighbours' range at
    the pixel (the rim's), how far the pixel lies below and how far above the range
    over the ``window`` (signed: positive on the side it is on; the ``mixed`` test);
    and the pixels (H, W) where a neighbour is occluded."""
    a, b = cand.values
    fa, fb = _finite(a), _finite(b)
    a = np.where(fa[..., None], a, np.where(fb[..., None], b, frame))
    b = np.where(fb[..., None], b, a)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    dis = _channel_mean(np.abs(a - b))
    side = 2 * _LOCAL + 1
    penalty = np.float32(p.agree) * dis + np.float32(p.agree_local) * cv2.blur(
        dis, (side, side), borderType=cv2.BORDER_REPLICATE)
    none = ~fa & ~fb

    def below_above(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dark = _channel_mean(lo - frame)  # > 0: darker than both candidates
        bright = _channel_mean(frame - hi)  # > 0: brighter than both
        dark[none] = 0.0
        bright[none] = 0.0
        return dark, bright

    dark, bright = below_above(lo, hi)
    rim = np.maximum(dark, bright)
    grow = rim - penalty
    if p.window > 0:  # the seeds' (and the mixed test's) range over the window
        k = np.ones((2 * p.window + 1, 2 * p.window + 1), np.uint8)
        lo = cv2.erode(lo, k, borderType=cv2.BORDER_REPLICATE).reshape(frame.shape)
        hi = cv2.dilate(hi, k, borderType=cv2.BORDER_REPLICATE).reshape(frame.shape)
        dark, bright = below_above(lo, hi)
        seed = np.maximum(dark, bright) - penalty
    else:
        seed = grow.copy()
    seed[fa != fb] = -np.inf  # one neighbour outside the picture: one-sided, no seed
    va, vb = cand.visible
    return seed, grow, rim, dark, bright, ~(va & vb) | cand.spare


def _clean(seed: np.ndarray, grow: np.ndarray, rim: np.ndarray, dark: np.ndarray,
           bright: np.ndarray, occluded: np.ndarray, p: DirtParams,
           scale: float = 1.0) -> np.ndarray:
    """Hysteresis (seeds grown into connected weaker spikes), small and two-toned
    detections dropped (``min_area``, ``mixed``), then dilated into the rim: the mask
    (H, W).  ``scale`` multiplies the thresholds (``ends``)."""
    thr = np.where(occluded, np.float32(p.occluded), np.float32(1.0)) \
        * np.float32(scale * p.threshold / p.sensitivity)
    strong = seed > thr
    weak = (grow > np.float32(p.low) * thr) | strong
    if not strong.any():
        return np.zeros_like(strong)
    labels, n = ndimage.label(weak, structure=np.ones((3, 3), bool))
    seeded = np.zeros(n + 1, bool)
    seeded[labels[strong]] = True
    area = np.bincount(labels.ravel(), minlength=n + 1)
    keep = seeded & (area >= p.min_area)
    keep[0] = False
    if p.mixed < 0.5 and keep.any():
        flat = labels.ravel()
        below = np.bincount(flat, np.maximum(dark, 0.0).ravel(), minlength=n + 1)
        above = np.bincount(flat, np.maximum(bright, 0.0).ravel(), minlength=n + 1)
        keep &= np.minimum(below, above) <= p.mixed * (below + above)
    mask = keep[labels]
    if p.dilate > 0 and mask.any():
        ring = cv2.dilate(mask.view(np.uint8), _disc(p.dilate)).view(bool)
        mask |= ring & (rim > np.float32(p.rim))
    return mask


def _fill(frame: np.ndarray, mask: np.ndarray, cand: _Frame) -> tuple[np.ndarray, int]:
    """The frame with its masked pixels replaced by the mean of its usable candidates,
    inpainted spatially where none is; and how many pixels were inpainted."""
    out = frame.copy()
    if not mask.any():
        return out, 0
    total = np.zeros(frame.shape, np.float32)
    count = np.zeros(frame.shape[:2], np.float32)
    for value, ok in zip(cand.values, cand.visible, strict=True):
        total += np.where(ok[..., None], value, np.float32(0.0))
        count += ok
    have = mask & (count > 0)
    out[have] = total[have] / count[have][:, None]
    hole = mask & (count == 0)
    n_hole = int(hole.sum())
    if n_hole:
        m8 = hole.view(np.uint8)
        for c in range(frame.shape[-1]):
            out[..., c] = cv2.inpaint(np.ascontiguousarray(out[..., c]), m8, 3,
                                      cv2.INPAINT_TELEA)
    return out, n_hole


#: The first (rough) detection, whose pixels are filled only for the flows to be
#: estimated again: thresholds times this, no raise where occluded, more dilation.
_ROUGH = 0.75
_ROUGH_DILATE = 2


def _detect(work: np.ndarray, fl: Flows, p: DirtParams, liberal: bool,
            prior: np.ndarray | None = None) -> np.ndarray:
    """The dirt mask (F, H, W) of every frame; candidates on the ``prior`` mask of
    their own frame are not used."""
    n = work.shape[0]
    fl = dict(fl)  # the composed flows stay here
    out = np.zeros(work.shape[:3], bool)
    if liberal:
        p = p.replace(threshold=p.threshold * _ROUGH, occluded=1.0,
                      dilate=min(p.dilate + _ROUGH_DILATE, 8))
    for t in range(n):
        cand = _compensate(work, t, fl, p.fb_tolerance, prior)
        out[t] = _clean(*_score(work[t], cand, p), p, p.ends if t in (0, n - 1) else 1.0)
    return out


def _inpaint_flow(f: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The flow (H, W, 2) inside ``mask`` interpolated from around it."""
    if not mask.any():
        return f
    m8 = cv2.dilate(mask.view(np.uint8), _disc(1))
    out = np.empty_like(f)
    for c in range(2):
        out[..., c] = cv2.inpaint(np.ascontiguousarray(np.nan_to_num(f[..., c])), m8, 5,
                                  cv2.INPAINT_TELEA)
    return out


def _repair_flows(fl: Flows, mask: np.ndarray) -> Flows:
    """The flows from every frame with their values on the frame's dirt interpolated
    from around it (the dirt pulls the flow)."""
    return {(a, b): _inpaint_flow(f, mask[a]) for (a, b), f in fl.items()}


def _fill_clip(work: np.ndarray, mask: np.ndarray, fl: Flows, p: DirtParams,
               visibility: bool) -> tuple[np.ndarray, int]:
    """Every frame with its masked pixels filled (:func:`_fill`; without
    ``visibility`` every candidate inside the picture is used), and the count of
    pixels inpainted spatially."""
    filled = np.empty_like(work)
    holes = 0
    fl = dict(fl)  # the composed flows stay here
    for t in range(work.shape[0]):
        cand = _compensate(work, t, fl, p.fb_tolerance, mask)
        if not visibility:
            cand.visible = [_finite(v) for v in cand.values]
        filled[t], k = _fill(work[t], mask[t], cand)
        holes += k
    return filled, holes


# --------------------------------------------------------------------------- public


def remove_dirt(frames: Any, params: DirtParams | None = None, *, return_mask: bool = False,
                flows: tuple[np.ndarray, np.ndarray] | None = None,
                initial_flows: tuple[np.ndarray, np.ndarray] | None = None,
                callback: Callback | None = None, stats: dict | None = None,
                **overrides: Any) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Remove dust, dirt and hairs (blotches present on one frame only) from a clip.

    Why: dirt on a film print is the most visible archival defect, and it is exactly
    what the motion tells apart from the picture: a spike in time along the flow.

    Every frame is compared with its two neighbours warped onto it along the flows
    (the first and last frames with the next two, or previous two; where a neighbour
    falls outside the picture, or is dirt itself, the next-but-one frame on the
    other side replaces it, along the composed flows): a pixel is dirt when it is
    darker than both or brighter than both by more than a threshold on the mean of
    its channels, while the two agree (a signed rank-order test, Kokaram 1998); on
    the first and last frames, whose candidates are both on one side in time, the
    thresholds are raised (``ends``).  Detections are grown by hysteresis into the
    soft rims, freed of specks and of two-toned detections (partly darker and partly
    brighter than the neighbours: lost motion, not a blotch; ``mixed``), dilated
    into the faint outer rim, and filled with the mean of the neighbours that see the
    pixel (forward-backward check) and are not dirt themselves, or inpainted
    spatially (:func:`cv2.inpaint`) where none does.  Before the final detection a
    rough one (lower thresholds) fills the frames and the flows are estimated again
    on them, since the dirt pulls the flow (``refine``).

    Parameters
    ----------
    frames : ndarray or sequence of ndarray
        A clip ``(F, H, W, C)`` or ``(F, H, W)`` (grey), or a sequence of frames of
        one shape; uint8, uint16 or float, at least 8 × 8.  The thresholds are in grey
        levels on 0-255: integer frames are scaled by their dtype's maximum, float
        frames within [0, 1] by 1 and within about [0, 255] by 255, other float
        frames by their range.  Fewer than 3 frames are returned unchanged.
    params : DirtParams, optional
        The parameters (default :class:`DirtParams`).
    return_mask : bool
        Also return the mask of the replaced pixels.  Default False.
    flows : (ndarray, ndarray), optional
        ``(fwd, bwd)``, each ``(F - 1, H, W, 2)`` float32: the flows from frame ``s``
        to ``s + 1`` and from ``s + 1`` to ``s`` at index ``s`` (as
        :func:`varflow.restore.denoise.clip_flows` gives them), used instead of
        estimating them (``refine`` then repeats the detection without estimating
        the flows again); the flows across two or three frames are composed from
        them.
    initial_flows : (ndarray, ndarray), optional
        The same form, in place of the first estimate only: the rough detection
        uses them and ``refine`` still estimates the flows again on the frames with
        the rough detection filled (the chain passes the flows of its deflicker
        stage, which changes no positions).  Not with ``flows``.
    callback : callable, optional
        ``callback(done, total)`` as the work progresses.
    stats : dict, optional
        Filled with ``seconds``, ``flow_seconds``, ``fraction`` (of the pixels
        replaced, per frame) and ``inpainted`` (pixels filled spatially).
    **overrides
        Fields of :class:`DirtParams` to change (or of its ``flow_params``), e.g.
        ``sensitivity=1.5``.

    Returns
    -------
    ndarray
        The cleaned clip, of the input's shape and dtype (integers rounded and
        clipped); the pixels outside the mask are the input's bytes.
    mask : ndarray, shape (F, H, W), bool
        With ``return_mask``: the pixels replaced.

    Raises
    ------
    ValueError
        Bad frames, flows of the wrong shape, or an unknown or invalid parameter
        (named in the message).

    References
    ----------
    A. C. Kokaram, *Motion Picture Restoration*, Springer, 1998.

    Examples
    --------
    >>> import numpy as np
    >>> import varflow.restore.dirt as dirt
    >>> clip = np.tile(np.linspace(60, 180, 32, dtype=np.float32), (5, 32, 1))
    >>> dirty = clip.copy()
    >>> dirty[2, 10:16, 10:16] = 5.0  # a dark blotch on frame 2 only
    >>> out, mask = dirt.remove_dirt(dirty, return_mask=True)
    >>> bool(mask[2, 10:16, 10:16].all()), int(mask[[0, 1, 3, 4]].sum())
    (True, 0)
    >>> float(np.abs(out - clip).max()) < 1
    True
    """
    p = REPAIR.make_params("dirt", params, **overrides)
    clip, back = _as_clip(frames)
    t0 = time.perf_counter()
    n, h, w, _ = clip.shape
    if flows is not None and initial_flows is not None:
        raise ValueError("initial_flows: not with flows (which replace every estimate)")
    given, given_name = (flows, "flows") if initial_flows is None else (initial_flows,
                                                                        "initial_flows")
    if given is not None:
        try:
            fwd, bwd = (np.asarray(f, np.float32) for f in given)
        except (TypeError, ValueError):
            raise ValueError(f"{given_name}: expected (fwd, bwd)") from None
        want = (max(n - 1, 0), h, w, 2)
        for name, f in (("fwd", fwd), ("bwd", bwd)):
            if f.shape != want:
                raise ValueError(f"{given_name}: {name} of shape {f.shape}, expected {want}")
    if n < 3:
        mask = np.zeros((n, h, w), bool)
        log.warning("remove_dirt: %d frame(s); at least 3 are needed, nothing done", n)
        out = np.array(frames if isinstance(frames, np.ndarray) else back(clip), copy=True)
        return (out, mask) if return_mask else out
    peak, base = _scale(clip)
    work = (clip.astype(np.float32) - np.float32(base)) * np.float32(255.0 / peak)

    pairs = _pairs(n)
    passes = 1 + p.refine
    estimated = 0 if flows is not None else passes - (initial_flows is not None)
    total = len(pairs) * estimated + n * passes
    done = [0]

    def tick() -> None:
        done[0] += 1
        if callback is not None:
            callback(done[0], total)

    def tick_n(k: int) -> None:
        for _ in range(k):
            tick()

    flow_seconds = 0.0

    def estimate(frames_: np.ndarray) -> Flows:
        from .. import flow as _flow

        nonlocal flow_seconds
        s0 = time.perf_counter()
        prepared = np.clip(frames_ * np.float32(1.0 / 255.0), 0.0, 1.0)
        out_: Flows = {}
        for a, b in pairs:
            out_[(a, b)] = _flow(prepared[a], prepared[b], p.flow_method,
                                 params=p.flow_params, max_pixels=p.flow_max_pixels)
            tick()
        flow_seconds += time.perf_counter() - s0
        return out_

    if given is None:
        fl = estimate(work)
    else:
        fl = {}
        for s in range(n - 1):
            fl[(s, s + 1)], fl[(s + 1, s)] = fwd[s], bwd[s]
        fl[(0, 2)] = _compose(fl[(0, 1)], fl[(1, 2)])
        fl[(2, 0)] = _compose(fl[(2, 1)], fl[(1, 0)])
        fl[(n - 1, n - 3)] = _compose(fl[(n - 1, n - 2)], fl[(n - 2, n - 3)])
        fl[(n - 3, n - 1)] = _compose(fl[(n - 3, n - 2)], fl[(n - 2, n - 1)])

    inpainted = 0
    rough = None
    for _ in range(p.refine):
        rough = _detect(work, fl, p, liberal=True, prior=rough)
        tick_n(n)
        if flows is None:  # the flows again, on the frames with the dirt filled
            fixed = _repair_flows(fl, rough)
            filled, _ = _fill_clip(work, rough, fixed, p, visibility=False)
            fl = estimate(filled)
    mask = _detect(work, fl, p, liberal=False, prior=rough)
    tick_n(n)
    filled, inpainted = _fill_clip(work, mask, fl, p, visibility=True)

    result = filled * np.float32(peak / 255.0) + np.float32(base)
    out = np.array(clip, copy=True)
    out[mask] = _to_dtype(result[mask], clip.dtype)
    if stats is not None:
        stats["seconds"] = time.perf_counter() - t0
        stats["flow_seconds"] = flow_seconds
        stats["fraction"] = mask.reshape(n, -1).mean(axis=1)
        stats["inpainted"] = inpainted
    log.info("remove_dirt: %.3g %% of the pixels replaced (%d inpainted)",
             100.0 * mask.mean(), inpainted)
    out = back(out)
    return (out, mask) if return_mask else out
