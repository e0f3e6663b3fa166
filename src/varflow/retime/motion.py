"""What every interpolation method estimates once per pair: :class:`PairMotion`.

A method's ``prepare`` returns a :class:`PairMotion`; its ``render(t)`` synthesises
the frame at any ``t`` from it.  :func:`pair_flows` computes flows between frames
with a registered two-frame method, as :func:`varflow.flow` does, through an
optional :class:`FlowCache`: a retimed video asks for the flows of consecutive
pairs (and of their neighbours, for the four-frame methods) and each is estimated
once.
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from collections.abc import Sequence

import numpy as np

from ..twoframe.coarse_to_fine import ProgressCallback
from ..twoframe.methods import FlowChoice

__all__ = ["FlowCache", "PairMotion", "bidirectional_flows", "pair_flows", "reduced",
           "working_scale"]


class PairMotion:
    """The motion of one pair of frames, estimated once, from which frames are rendered.

    Subclasses implement :meth:`render`.

    Attributes
    ----------
    frame0, frame1 : ndarray, shape (H, W, C), float32
        The two frames (uint8 / uint16 inputs divided by 255 / 65535, float inputs
        as they are).
    """

    def __init__(self, frame0: np.ndarray, frame1: np.ndarray) -> None:
        self.frame0 = frame0
        self.frame1 = frame1

    def render(self, t: float) -> np.ndarray:
        """The frame at time ``t`` (0 < t < 1), shape (H, W, C), float32, the units of
        :attr:`frame0`."""
        raise NotImplementedError


def _digest(frame: np.ndarray) -> bytes:
    a = np.ascontiguousarray(frame)
    h = hashlib.blake2b(digest_size=16)
    h.update(repr((a.shape, a.dtype.str)).encode())
    h.update(a.data)
    return h.digest()


class FlowCache:
    """Flows between frames, kept by the frames' content: each estimated once.

    A key is the BLAKE2 digest of both frames' bytes (shape and dtype included)
    and the method's name and parameters, so a cached flow is never returned for
    other frames or settings.  The oldest entries are dropped beyond
    ``max_entries``.

    Parameters
    ----------
    max_entries : int
        Flows kept (default 8: a four-frame method in a stream needs the last six).

    Attributes
    ----------
    hits, misses : int
        Flows served from the cache and estimated.
    """

    def __init__(self, max_entries: int = 8) -> None:
        if isinstance(max_entries, bool) or not isinstance(max_entries, int) or max_entries < 1:
            raise ValueError(f"max_entries: expected an integer >= 1, got {max_entries!r}")
        self.max_entries = max_entries
        self._flows: OrderedDict[tuple, np.ndarray] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._flows)

    @staticmethod
    def key(frame_a: np.ndarray, frame_b: np.ndarray, params: FlowChoice,
            max_pixels: int = 0, digests: dict[int, bytes] | None = None) -> tuple:
        """The cache key of the flow from ``frame_a`` to ``frame_b``.

        ``digests`` memoises the frames' digests by ``id`` for the duration of one
        call that keys several pairs of the same frames (hashing a 960 × 540 frame
        takes milliseconds).
        """
        memo = {} if digests is None else digests
        for f in (frame_a, frame_b):
            if id(f) not in memo:
                memo[id(f)] = _digest(f)
        return (memo[id(frame_a)], memo[id(frame_b)], params.flow_method,
                repr(params.flow_params), max_pixels)

    def get(self, key: tuple) -> np.ndarray | None:
        flow = self._flows.get(key)
        if flow is not None:
            self._flows.move_to_end(key)
            self.hits += 1
        return flow

    def put(self, key: tuple, flow: np.ndarray) -> None:
        self.misses += 1
        self._flows[key] = flow
        self._flows.move_to_end(key)
        while len(self._flows) > self.max_entries:
            self._flows.popitem(last=False)


def working_scale(shape: tuple[int, ...], max_pixels: int) -> float:
    """The factor that brings ``shape``'s first two sides to at most ``max_pixels``
    pixels (1 when they are within it or ``max_pixels`` is 0)."""
    n = int(shape[0]) * int(shape[1])
    if max_pixels <= 0 or n <= max_pixels:
        return 1.0
    return math.sqrt(max_pixels / n)


def reduced(frame: np.ndarray, scale: float) -> np.ndarray:
    """``frame`` (H, W, C) float32 resized by ``scale`` < 1: Gaussian pre-smoothing
    σ = 0.6/scale − 0.6 against aliasing, then bilinear resampling."""
    from ..ops.pyramid import resize_bilinear, smooth_image_fast

    h, w = frame.shape[:2]
    shape = (max(8, round(h * scale)), max(8, round(w * scale)))
    return resize_bilinear(smooth_image_fast(frame, 0.6 / scale - 0.6), shape)


def pair_flows(pairs: Sequence[tuple[np.ndarray, np.ndarray]], params: FlowChoice,
               callback: ProgressCallback | None = None, stats: dict | None = None,
               cache: FlowCache | None = None, max_pixels: int = 0) -> list[np.ndarray]:
    """The flows of ``params.flow_method`` from ``a`` to ``b`` for every pair ``(a, b)``.

    Parameters
    ----------
    pairs : sequence of (ndarray, ndarray)
        Frames (H, W, C) float32, as :func:`varflow.flow` takes them.
    params : FlowChoice
        The two-frame method and its parameters.
    callback : callable, optional
        ``callback(done, total)``: one progress range over all the flows to
        estimate (the cached ones are not counted).
    stats : dict, optional
        ``flows`` (estimated) and ``cached_flows`` (served from ``cache``) are
        incremented.
    cache : FlowCache, optional
    max_pixels : int
        Frames of more pixels are resized to this many (:func:`reduced`) for the
        flow, which is resized back (:func:`varflow.ops.pyramid.resize_flow`:
        vectors scaled); 0 (default) never.

    Returns
    -------
    list of ndarray, each (H, W, 2) float32
        The cache's own arrays for cached flows: do not modify them.
    """
    from ..ops.pyramid import resize_flow
    from ..registry import FLOW
    from ..twoframe.methods import run_method

    m = FLOW[params.flow_method]
    digests: dict[int, bytes] = {}  # the frames are alive for the whole call
    keys = [None if cache is None else FlowCache.key(a, b, params, max_pixels, digests)
            for a, b in pairs]
    out: list[np.ndarray | None] = [None if k is None else cache.get(k) for k in keys]
    todo = [i for i, f in enumerate(out) if f is None]
    small: dict[int, np.ndarray] = {}  # each frame reduced once for all its flows

    def reduce_once(frame: np.ndarray, scale: float) -> np.ndarray:
        if id(frame) not in small:
            small[id(frame)] = reduced(frame, scale)
        return small[id(frame)]

    for n, i in enumerate(todo):
        a, b = pairs[i]

        def tick(k: int, total: int, n: int = n) -> None:  # one range for all the flows
            if callback is not None:
                callback(n * total + k, len(todo) * total)

        scale = working_scale(a.shape, max_pixels)
        if scale < 1:
            flow = resize_flow(run_method(m, reduce_once(a, scale), reduce_once(b, scale),
                                          params.flow_params, callback=tick), a.shape[:2])
        else:
            flow = run_method(m, a, b, params.flow_params, callback=tick)
        if cache is not None:
            cache.put(keys[i], flow)
        out[i] = flow
    if stats is not None:
        stats["flows"] = stats.get("flows", 0) + len(todo)
        stats["cached_flows"] = stats.get("cached_flows", 0) + len(pairs) - len(todo)
    return out  # type: ignore[return-value]


def bidirectional_flows(frame0: np.ndarray, frame1: np.ndarray, params: FlowChoice,
                        callback: ProgressCallback | None = None, stats: dict | None = None,
                        cache: FlowCache | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The flows 0→1 and 1→0 of ``params.flow_method`` (:func:`pair_flows`).

    Returns
    -------
    f01, f10 : ndarray, shape (H, W, 2), float32
    """
    f01, f10 = pair_flows([(frame0, frame1), (frame1, frame0)], params, callback, stats, cache)
    return f01, f10
