"""Video denoising with motion: :func:`denoise` and the ``nlbayes`` methods' runner.

:func:`denoise` (re-exported as :func:`varflow.denoise`) checks a clip, estimates
the noise when σ is not given (:func:`varflow.estimate_noise`), runs a method of
:data:`varflow.registry.RESTORE` on it in float32 and gives the result back in the
input's dtype, shape and units.

:func:`run_nlbayes` is the runner of ``nlbayes`` and ``nlbayes-fast``: the flows
between consecutive frames (both ways, with their forward-backward check), one
NL-Bayes pass on the noisy clip and the final pass on its estimate, along the same
flows (:mod:`varflow.restore._nlbayes`).
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

import numpy as np
from scipy import ndimage

from ..registry import RESTORE
from ._nlbayes import accumulate_pass, denoise_pass, normalise

__all__ = ["OPPONENT", "clip_flows", "denoise", "iter_denoise", "mark_cuts", "run_nlbayes"]

log = logging.getLogger(__name__)

#: The orthonormal opponent colour transform (rows: luminance, red - blue, and
#: green against magenta): orthonormal, so white noise of σ in RGB stays white
#: noise of σ in each opponent channel.
OPPONENT = (np.array([[1.0, 1.0, 1.0], [1.0, 0.0, -1.0], [1.0, -2.0, 1.0]])
            / np.sqrt([[3.0], [2.0], [6.0]])).astype(np.float32)

Callback = Callable[[int, int], None]

#: The smallest group kept under the distance thresholds (``tau``, ``tau_final``).
_NMIN = 2


def _as_clip(frames: Any) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """``frames`` as an (F, H, W, C) array, and the function that gives an array of
    that shape back in the input's layout."""
    if isinstance(frames, np.ndarray):
        arr = frames
    else:
        try:
            seq = [np.asarray(f) for f in frames]
        except TypeError:
            raise ValueError("frames: expected an array or a sequence of images") from None
        if not seq:
            raise ValueError("frames: no frames")
        shapes = {f.shape for f in seq}
        if len(shapes) > 1:
            k = next(i for i, f in enumerate(seq) if f.shape != seq[0].shape)
            raise ValueError(f"frame {k}: shape {seq[k].shape} differs from frame 0's "
                             f"{seq[0].shape}")
        dtypes = {f.dtype for f in seq}
        if len(dtypes) > 1:
            raise ValueError(f"frames: mixed dtypes {sorted(map(str, dtypes))}")
        arr = np.stack(seq)
    shape = arr.shape
    if arr.ndim == 2:  # one grey image
        clip = arr[None, :, :, None]
    elif arr.ndim == 3 and shape[2] in (1, 3, 4) and isinstance(frames, np.ndarray):
        clip = arr[None]  # one colour image
    elif arr.ndim == 3:  # (F, H, W) grey clip
        clip = arr[..., None]
    elif arr.ndim == 4:
        clip = arr
    else:
        raise ValueError(f"frames: expected (H, W[, C]) or (F, H, W[, C]), got shape {shape}")
    if arr.dtype.kind not in "uif" or arr.dtype == np.bool_:
        raise ValueError(f"frames: unsupported dtype {arr.dtype} (expected uint8, uint16 "
                         "or float)")
    if clip.shape[1] < 8 or clip.shape[2] < 8:
        raise ValueError(f"frames: {clip.shape[2]}x{clip.shape[1]} frames are too small "
                         "(need at least 8x8)")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        bad = int(np.argmax(~np.isfinite(clip).reshape(clip.shape[0], -1).all(axis=1)))
        raise ValueError(f"frame {bad}: contains NaN or infinite values")

    def back(out: np.ndarray) -> np.ndarray:
        return out.reshape(shape)

    return clip, back


def _to_dtype(out: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Float32 values in the input's units to the input's dtype (integers rounded and
    clipped to their range)."""
    if dtype.kind in "ui":
        info = np.iinfo(dtype)
        return np.clip(np.rint(out), info.min, info.max).astype(dtype)
    return out.astype(dtype, copy=False)


def denoise(frames: Any, sigma: float | None = None, method: str | None = None, *,
            params: Any = None, callback: Callback | None = None,
            stats: dict | None = None, **overrides: Any) -> np.ndarray:
    """Remove white noise from a clip (or one image) with its motion.

    Parameters
    ----------
    frames : ndarray or sequence of ndarray
        A clip ``(F, H, W, C)`` or ``(F, H, W)`` (grey), a sequence of frames of one
        shape, or one image ``(H, W[, C])`` (an array of three dimensions is one
        colour image when its last axis is 1, 3 or 4 long, and a grey clip
        otherwise); uint8, uint16 or float (any range), finite, at least 8 × 8.
    sigma : float, optional
        Standard deviation of the noise, in the units of the values (0-255 for
        uint8 frames, 0-1 for float frames in [0, 1]); not rescaled from the
        clip's range.  None: estimated from the clip
        (:func:`varflow.estimate_noise`, the root mean square over the channels;
        logged and put in ``stats["sigma"]``).  0 returns a copy.
    method : str, optional
        A name of :data:`varflow.registry.RESTORE` (``varflow methods`` lists
        them); default ``"nlbayes"``.
    params : dataclass, optional
        The method's parameters (e.g. :class:`varflow.restore.methods.NLBayesParams`).
    callback : callable, optional
        ``callback(done, total)`` as the work progresses.
    stats : dict, optional
        Filled with ``sigma`` (the σ used), ``seconds`` and the method's timings.
    **overrides
        Parameter fields to change, e.g. ``radius=2`` or ``grain=0.2``.

    Returns
    -------
    ndarray
        The denoised clip, of the input's shape and dtype (integers rounded and
        clipped to their range; floats not clipped).

    Raises
    ------
    ValueError
        Bad frames (shape, dtype, NaN: the message names the frame), a negative or
        non-finite ``sigma``, an unknown method or parameter.

    Notes
    -----
    Colour (3-channel) clips are denoised in an orthonormal opponent space; other
    channel counts are grouped over all channels as they are.  The noise is taken
    as white, Gaussian and of one σ over the clip.

    References
    ----------
    P. Arias, J.-M. Morel, "Video denoising via empirical Bayesian estimation of
    space-time patches", J. Math. Imaging Vis. 60, 2018.  M. Lebrun, A. Buades,
    J.-M. Morel, "A nonlocal Bayesian image denoising algorithm", SIAM J. Imaging
    Sci. 6(3), 2013.

    Examples
    --------
    >>> import numpy as np
    >>> import varflow
    >>> rng = np.random.default_rng(0)
    >>> clean = np.full((3, 32, 32), 100.0, np.float32)
    >>> noisy = clean + rng.normal(0, 10, clean.shape).astype(np.float32)
    >>> out = varflow.denoise(noisy, sigma=10, radius=1)
    >>> out.shape, out.dtype
    ((3, 32, 32), dtype('float32'))
    >>> float(np.abs(out - clean).mean()) < 2
    True
    """
    entry = RESTORE.entry(method if method is not None else RESTORE.default)
    p = RESTORE.make_params(entry, params, **overrides)
    clip, back = _as_clip(frames)
    dtype = clip.dtype
    t0 = time.perf_counter()
    if sigma is None:
        from .noise import estimate_noise

        est = estimate_noise(clip)
        sigma = float(np.sqrt(np.mean(np.square(est.sigma))))
        log.info("estimated noise sigma %.4g (per channel %s)", sigma,
                 np.array2string(est.sigma, precision=4))
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.floating,
                                                          np.integer)) \
            or not math.isfinite(float(sigma)) or sigma < 0:
        raise ValueError(f"sigma: must be a finite number >= 0, got {sigma!r}")
    sigma = float(sigma)
    if stats is not None:
        stats["sigma"] = sigma
    if sigma == 0:
        return np.array(frames if isinstance(frames, np.ndarray) else back(clip), copy=True)
    work = clip.astype(np.float32)
    out = entry.run(work, sigma, p, callback=callback, stats=stats)
    grain = float(getattr(p, "grain", 0.0))
    if grain > 0:  # (1 - g) D + g I: exactly the input at g = 1
        out = np.float32(1 - grain) * out + np.float32(grain) * work
    if stats is not None:
        stats["seconds"] = time.perf_counter() - t0
    return back(_to_dtype(out, dtype))


# --------------------------------------------------------------------------- nlbayes


def clip_flows(clip: np.ndarray, params: Any, blur: float = 0.0,
               callback: Callable[[], None] | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Flows between consecutive frames both ways and their forward-backward checks.

    Parameters
    ----------
    clip : ndarray, shape (F, H, W, C), float32
    params : NLBayesParams
        ``flow_method``, ``flow_params``, ``flow_max_pixels`` and ``fb_tolerance``.
    blur : float
        σ (pixels) of a Gaussian applied to the frames first (0: none).
    callback : callable, optional
        Called after each pair.

    Returns
    -------
    fwd, bwd : ndarray, shape (F - 1, H, W, 2), float32
        Frame s to s + 1 and s + 1 to s, at index s.
    fwd_ok, bwd_ok : ndarray, shape (F - 1, H, W), bool
        Where each passed :func:`varflow.consistency`.
    """
    from .. import flow as _flow
    from ..compensate import consistency

    n, h, w, _ = clip.shape
    fwd = np.zeros((max(n - 1, 0), h, w, 2), np.float32)
    bwd = np.zeros_like(fwd)
    fwd_ok = np.zeros((max(n - 1, 0), h, w), np.bool_)
    bwd_ok = np.zeros_like(fwd_ok)
    lo, hi = _flow_range(clip[0]) if n else (0.0, 1.0)

    def prepared(k: int) -> np.ndarray:
        return _for_flow(clip[k], lo, hi, blur)

    nxt = prepared(0) if n else None
    for s in range(n - 1):
        a, nxt = nxt, prepared(s + 1)
        kw = dict(params=params.flow_params, max_pixels=params.flow_max_pixels)
        fwd[s] = _flow(a, nxt, params.flow_method, **kw)
        bwd[s] = _flow(nxt, a, params.flow_method, **kw)
        fwd_ok[s] = consistency(fwd[s], bwd[s], alpha2=params.fb_tolerance)
        bwd_ok[s] = consistency(bwd[s], fwd[s], alpha2=params.fb_tolerance)
        if callback is not None:
            callback()
    return fwd, bwd, fwd_ok, bwd_ok


def _flow_range(frame: np.ndarray) -> tuple[float, float]:
    """The intensities mapped to [0, 1] for the flows: the range of a scene's first
    frame (a stream knows no other)."""
    lo, hi = float(frame.min()), float(frame.max())
    return lo, (hi if hi > lo else lo + 1.0)


def _for_flow(frame: np.ndarray, lo: float, hi: float, blur: float) -> np.ndarray:
    """A frame as the flows see it: mapped from [lo, hi] to [0, 1], smoothed, clipped."""
    f = (frame - np.float32(lo)) * np.float32(1.0 / (hi - lo))
    if blur > 0:
        f = ndimage.gaussian_filter(f, (blur, blur, 0), mode="nearest")
    return np.clip(f, 0, 1).astype(np.float32)


def _opponent(clip: np.ndarray, inverse: bool = False) -> np.ndarray:
    if clip.shape[-1] != 3:
        return clip
    m = OPPONENT if inverse else OPPONENT.T
    return np.ascontiguousarray(clip @ m, dtype=np.float32)


def run_nlbayes(clip: np.ndarray, sigma: float, params: Any,
                callback: Callback | None = None, stats: dict | None = None,
                frames: Sequence[int] | None = None,
                flows: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Run ``nlbayes`` on a clip (the :class:`~varflow.registry.Restorer` runner).

    Parameters
    ----------
    clip : ndarray, shape (F, H, W, C), float32
        In the input's units.
    sigma : float
        Noise standard deviation, same units, > 0.
    params : NLBayesParams
    callback : callable, optional
        ``callback(done, total)``: one step per flow pair and per pass.
    stats : dict, optional
        Gains ``flow_seconds`` and ``pass_seconds``.
    frames : sequence of int, optional
        Estimate only these frames (the others give zeros); the clip around them
        is still used.
    flows : tuple, optional
        The clip's :func:`clip_flows` when the caller has them (a stream's cache).

    Returns
    -------
    ndarray, shape (F, H, W, C), float32
    """
    n, h, w, _ = clip.shape
    motion = params.radius > 0 and n > 1
    total = (n - 1) * (motion and flows is None) + params.passes
    done = [0]

    def tick() -> None:
        done[0] += 1
        if callback is not None:
            callback(done[0], total)

    kw = dict(sigma=sigma, radius=params.radius if motion else 0, search=params.search,
              search_t=params.search_t, stride=params.stride, beta=params.beta,
              flat=params.flat)
    t0 = time.perf_counter()
    if not motion:
        flows = (np.zeros((0, h, w, 2), np.float32), np.zeros((0, h, w, 2), np.float32),
                 np.zeros((0, h, w), np.bool_), np.zeros((0, h, w), np.bool_))
    elif flows is None:
        flows = clip_flows(clip, params, params.flow_blur, tick)
    t1 = time.perf_counter()
    refs_final = refs_first = None
    if frames is not None:  # a frame gathers the groups of the frames within radius
        r = kw["radius"]

        def around(ks: Sequence[int], d: int) -> list[int]:
            return sorted({min(max(k + j, 0), n - 1) for k in ks for j in range(-d, d + 1)})

        refs_final = around(frames, r)
        refs_first = around(frames, 3 * r if params.passes == 2 else r)
    noisy = _opponent(clip)
    out = denoise_pass(noisy, noisy, False, *flows, patch=params.patch,
                       n_similar=params.n_similar, frames=refs_first, dist_channels=1,
                       tau=params.tau, n_min=_NMIN, **kw)
    tick()
    if params.passes == 2:
        out = denoise_pass(noisy, out, True, *flows, patch=params.patch_final,
                           n_similar=params.n_similar_final, frames=refs_final,
                           dist_channels=1 if params.luma_final else 0,
                           tau=params.tau_final, n_min=_NMIN, **kw)
        tick()
    if frames is not None:
        out[np.setdiff1d(np.arange(n), np.asarray(frames, np.int64))] = 0
    if stats is not None:
        stats["flow_seconds"] = t1 - t0
        stats["pass_seconds"] = time.perf_counter() - t1
    return _opponent(out, inverse=True)


# --------------------------------------------------------------------------- streams


class _Sums:
    """The running sums of one pass in a stream: per frame the estimates' sum, their
    count and the covered reference positions, and the next reference frame."""

    def __init__(self) -> None:
        self.acc: dict[int, np.ndarray] = {}
        self.weight: dict[int, np.ndarray] = {}
        self.done: dict[int, np.ndarray] = {}
        self.next = 0

    def window(self, a: int, b: int, h: int, w: int, nc: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        for k in range(a, b + 1):
            if k not in self.acc:
                self.acc[k] = np.zeros((h, w, nc), np.float32)
                self.weight[k] = np.zeros((h, w), np.float32)
                self.done[k] = np.zeros((h, w), np.bool_)
        return tuple(np.stack([store[k] for k in range(a, b + 1)])  # type: ignore[return-value]
                     for store in (self.acc, self.weight, self.done))

    def store(self, a: int, acc: np.ndarray, weight: np.ndarray, done: np.ndarray) -> None:
        for i in range(len(acc)):
            self.acc[a + i], self.weight[a + i], self.done[a + i] = acc[i], weight[i], done[i]

    def take(self, k: int) -> np.ndarray:
        """Frame k's estimate (its sums are complete), forgetting its sums."""
        est = normalise(self.acc.pop(k), self.weight.pop(k))
        del self.done[k]
        return est


class _Segment:
    """The frames of one scene in a stream, with what is computed of them (indices
    within the scene): noisy frames (opponent space), flows of consecutive pairs,
    the running sums of both passes and the complete first estimates.

    The reference frames of each pass are taken in increasing order, as
    :func:`run_nlbayes` takes them, so each frame's sums and estimate are the same
    bytes.  First-pass reference ``t`` needs the frames to ``t + r``; a first
    estimate is complete once the references to ``r`` after it are taken; final
    reference ``t`` needs the first estimates to ``t + r``."""

    def __init__(self, params: Any, sigma: float) -> None:
        self.p = params
        self.sigma = sigma
        self.r = params.radius
        self.noisy: dict[int, np.ndarray] = {}   # opponent, float32
        self.prepared: dict[int, np.ndarray] = {}  # for the flows
        self.flows: dict[int, tuple[np.ndarray, ...]] = {}  # pair (k, k + 1)
        self.basic: dict[int, np.ndarray] = {}
        self.first = _Sums()
        self.final = _Sums()
        self.count = 0
        self.basic_next = 0   # the first estimates before it are complete
        self.out_next = 0     # the frames before it were given out
        self.range: tuple[float, float] | None = None

    def add(self, frame: np.ndarray) -> None:
        from .. import flow as _flow
        from ..compensate import consistency

        k = self.count
        self.count += 1
        self.noisy[k] = _opponent(frame[None])[0]
        if self.r == 0:
            return
        if self.range is None:
            self.range = _flow_range(frame)
        self.prepared[k] = _for_flow(frame, *self.range, self.p.flow_blur)
        if k > 0:
            a, b = self.prepared[k - 1], self.prepared[k]
            kw = dict(params=self.p.flow_params, max_pixels=self.p.flow_max_pixels)
            fw = _flow(a, b, self.p.flow_method, **kw)
            bw = _flow(b, a, self.p.flow_method, **kw)
            self.flows[k - 1] = (fw, bw, consistency(fw, bw, alpha2=self.p.fb_tolerance),
                                 consistency(bw, fw, alpha2=self.p.fb_tolerance))
            del self.prepared[k - 1]

    def _pass(self, sums: _Sums, t1: int, oracle: bool) -> None:
        """Take the references ``sums.next .. t1`` of a pass."""
        t0 = sums.next
        a, b = max(t0 - self.r, 0), min(t1 + self.r, self.count - 1)
        noisy = np.stack([self.noisy[k] for k in range(a, b + 1)])
        guide = np.stack([self.basic[k] for k in range(a, b + 1)]) if oracle else noisy
        h, w, nc = noisy.shape[1:]
        if b > a and self.r > 0:
            parts = [self.flows[k] for k in range(a, b)]
            flows = tuple(np.stack([q[i] for q in parts]) for i in range(4))
        else:
            flows = (np.zeros((0, h, w, 2), np.float32), np.zeros((0, h, w, 2), np.float32),
                     np.zeros((0, h, w), np.bool_), np.zeros((0, h, w), np.bool_))
        acc, weight, done = sums.window(a, b, h, w, nc)
        p = self.p
        accumulate_pass(
            noisy, guide, oracle, *flows, acc, weight, done, refs=range(t0 - a, t1 - a + 1),
            sigma=self.sigma, patch=p.patch_final if oracle else p.patch,
            n_similar=p.n_similar_final if oracle else p.n_similar,
            radius=self.r if b > a else 0, search=p.search, search_t=p.search_t,
            stride=p.stride, beta=p.beta, flat=p.flat, dist_channels=0 if oracle else 1,
            tau=p.tau_final if oracle else p.tau, n_min=_NMIN)
        sums.store(a, acc, weight, done)
        sums.next = t1 + 1

    def advance(self, chunk: int, end: bool) -> list[np.ndarray]:
        """Compute what the frames so far allow (all of it at the scene's end), in
        batches of at least ``chunk`` reference frames; return the finished frames
        (RGB)."""
        r, two, last = self.r, self.p.passes == 2, self.count - 1
        ready = last if end else last - r
        if ready >= self.first.next and (end or ready - self.first.next + 1 >= chunk):
            self._pass(self.first, ready, False)
        complete = last if end and self.first.next > last else self.first.next - 1 - r
        while self.basic_next <= complete:
            self.basic[self.basic_next] = self.first.take(self.basic_next)
            self.basic_next += 1
        out: list[np.ndarray] = []
        if not two:
            while self.out_next < self.basic_next:
                out.append(self.basic.pop(self.out_next))
                self.out_next += 1
            keep_from = self.first.next - r
        else:
            at_end = end and self.basic_next > last
            ready = last if at_end else self.basic_next - 1 - r
            if ready >= self.final.next and (at_end or ready - self.final.next + 1 >= chunk):
                self._pass(self.final, ready, True)
            complete = last if at_end and self.final.next > last else self.final.next - 1 - r
            while self.out_next <= complete:
                out.append(self.final.take(self.out_next))
                self.out_next += 1
            keep_from = min(self.first.next, self.final.next) - r
        # forget what no later reference reads
        for store in (self.noisy, self.basic, self.flows):
            for k in [k for k in store if k < keep_from]:
                del store[k]
        return [_opponent(f[None], inverse=True)[0] for f in out]


def mark_cuts(frames: Iterable[np.ndarray], is_cut: Callable[..., bool] | None
              ) -> Iterator[tuple[np.ndarray, bool]]:
    """``(frame, cut)`` for every frame of a stream, ``cut`` True when a scene cut lies
    between the previous frame and this one.

    A frame is given out once the next one is read: the test between frames ``j - 1``
    and ``j`` also looks at ``j - 2`` and ``j + 1``.

    Parameters
    ----------
    frames : iterable of ndarray
    is_cut : callable or None
        ``is_cut(frame0, frame1, previous=..., following=...) -> bool`` (e.g.
        :func:`varflow.retime.stream.is_scene_cut`); None: one scene (every ``cut``
        False).
    """
    window: list[np.ndarray] = []  # the last four frames
    held: np.ndarray | None = None
    for i, a in enumerate(frames):
        window.append(a)
        if len(window) > 4:
            window.pop(0)
        if held is not None:
            cut = is_cut is not None and i >= 2 and bool(is_cut(
                window[-3], window[-2], previous=window[-4] if len(window) == 4 else None,
                following=a))
            yield held, cut
        held = a
    if held is not None:
        n = len(window)
        cut = is_cut is not None and n >= 2 and bool(is_cut(
            window[-2], window[-1], previous=window[-3] if n >= 3 else None, following=None))
        yield held, cut


def _unmark(pairs: Iterable[tuple[np.ndarray, bool]], flags: deque[bool]
            ) -> Iterator[np.ndarray]:
    for a, cut in pairs:
        flags.append(bool(cut))
        yield a


def iter_denoise(frames: Any, sigma: float | None = None, method: str | None = None, *,
                 params: Any = None, chunk: int = 8,
                 is_cut: Callable[..., bool] | None = None, marked: bool = False,
                 stats: dict | None = None, **overrides: Any) -> Any:
    """Denoise a stream of frames with bounded memory; yield the frames in order.

    The same estimate as :func:`denoise` on each scene, computed as the frames
    arrive: a frame is given out once the ``4 · radius`` frames after it (one pass:
    ``2 · radius``) are read, and memory holds about ``chunk + 6 · radius`` frames.

    Parameters
    ----------
    frames : iterable of ndarray
        Frames ``(H, W[, C])`` of one shape and dtype (uint8, uint16 or float).
    sigma : float, optional
        Noise standard deviation in the units of the values; None: estimated on
        the first ``chunk + 2 · radius`` frames (:func:`varflow.estimate_noise`) and
        kept for the stream (``stats["sigma"]``).
    method : str, optional
        A ``nlbayes`` method of :data:`varflow.registry.RESTORE`.
    params : NLBayesParams, optional
    chunk : int
        Frames estimated per batch (>= 1): larger batches use the cores better.
    is_cut : callable, optional
        ``is_cut(frame0, frame1, previous=..., following=...) -> bool`` (e.g.
        :func:`varflow.retime.stream.is_scene_cut`): no patch is searched across
        a cut.  None: one scene.
    marked : bool
        ``frames`` yields ``(frame, cut)`` pairs whose ``cut`` says that a scene
        cut precedes the frame (as :func:`mark_cuts` gives them; ``is_cut`` is then
        not used).  Default False.
    stats : dict, optional
        Gains ``sigma``, ``frames`` and ``cuts``.
    **overrides
        Parameter fields, as in :func:`denoise`.

    Yields
    ------
    ndarray
        Each denoised frame, of the input frame's shape and dtype.

    Raises
    ------
    ValueError
        As :func:`denoise`, for a frame whose shape or dtype differs from the
        first one's (naming the frame), or ``chunk`` < 1.
    """
    entry = RESTORE.entry(method if method is not None else RESTORE.default)
    p = RESTORE.make_params(entry, params, **overrides)
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk: must be an integer >= 1, got {chunk!r}")
    stats = {} if stats is None else stats
    stats.update(frames=0, cuts=0)
    flags: deque[bool] = deque()  # the given cut marks (marked), in the frames' order
    if marked:
        frames = _unmark(frames, flags)
    it = iter(frames)
    head: list[np.ndarray] = []
    first = None
    for f in it:  # the first frames: checks, and σ if unknown
        a = np.asarray(f)
        if first is None:
            first = a
        elif a.shape != first.shape or a.dtype != first.dtype:
            raise ValueError(f"frame {len(head)}: shape {a.shape} {a.dtype} differs from "
                             f"frame 0's {first.shape} {first.dtype}")
        head.append(a)
        if sigma is not None or len(head) >= chunk + 2 * p.radius:
            break
    if first is None:
        return
    _as_clip(first)  # shape, dtype, finite
    if sigma is None:
        from .noise import estimate_noise

        est = estimate_noise(np.stack(head))
        sigma = float(np.sqrt(np.mean(np.square(est.sigma))))
        log.info("estimated noise sigma %.4g (per channel %s)", sigma,
                 np.array2string(est.sigma, precision=4))
    if isinstance(sigma, bool) or not math.isfinite(float(sigma)) or sigma < 0:
        raise ValueError(f"sigma: must be a finite number >= 0, got {sigma!r}")
    stats["sigma"] = float(sigma)
    shape, dtype = first.shape, first.dtype
    grain = np.float32(p.grain)

    def rest() -> Any:
        yield from head
        for i, f in enumerate(it, start=len(head)):
            a = np.asarray(f)
            if a.shape != shape or a.dtype != dtype:
                raise ValueError(f"frame {i}: shape {a.shape} {a.dtype} differs from "
                                 f"frame 0's {shape} {dtype}")
            yield a

    def prepared(a: np.ndarray, i: int) -> np.ndarray:
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ValueError(f"frame {i}: contains NaN or infinite values")
        x = a.astype(np.float32)
        return x[..., None] if x.ndim == 2 else x

    if float(sigma) == 0:
        for a in rest():
            stats["frames"] += 1
            yield a.copy()
        return
    seg = _Segment(p, float(sigma))
    pending: list[np.ndarray] = []  # the inputs not yet given out (for grain)

    def emit(outs: list[np.ndarray]) -> Any:
        for o in outs:
            x = pending.pop(0)
            if grain > 0:
                o = (1 - grain) * o + grain * x
            stats["frames"] += 1
            yield _to_dtype(o, dtype).reshape(shape)

    def place(x: np.ndarray, cut: bool) -> Any:
        nonlocal seg
        if cut:
            stats["cuts"] += 1
            yield from emit(seg.advance(chunk, end=True))
            seg = _Segment(p, float(sigma))
        pending.append(x)
        seg.add(x)
        yield from emit(seg.advance(chunk, end=False))

    marks = ((a, flags.popleft()) for a in rest()) if marked else mark_cuts(rest(), is_cut)
    for i, (a, cut) in enumerate(marks):
        yield from place(prepared(a, i), cut and i > 0)
    yield from emit(seg.advance(chunk, end=True))
