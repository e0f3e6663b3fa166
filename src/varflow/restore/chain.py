"""The restoration chain: the repair stages and the denoiser, in the order of practice.

:func:`iter_restore` streams frames through the stages a user names, always in the
order restoration practice uses them (each stage's ``order`` in
:data:`varflow.registry.REPAIR`): ``stabilise`` (the later stages compare aligned
frames), ``deflicker`` (the dirt test compares intensities), ``dirt``, then
``denoise`` (a method of :data:`varflow.registry.RESTORE`, fed the repaired frames).
:func:`restore_clip` runs it on a clip in memory.

Streaming: each repair stage works on windows of ``chunk`` frames with the frames
each side its result depends on (the stage's ``context``: the path smoother's reach
for ``stabilise``, the brightness smoothing for ``deflicker``, the two neighbours
each side for ``dirt``), so a frame comes out as the whole scene's run would give it
and memory holds a few windows.  A stage that takes its flows from outside
(``pair_flows`` of its entry: ``stabilise``, ``deflicker``) gets each consecutive
pair's flows estimated once and kept while the pair is in a window, so the overlap
costs no flow twice; ``deflicker`` changes no positions, so its flows go on with the
frames and the ``dirt`` stage starts from them (its first estimate; the final flows
it estimates again on the frames with the rough detection filled).  The denoiser is the streaming
:func:`~varflow.restore.denoise.iter_denoise`.  No stage looks across a scene cut.

Values: integer frames are repaired as float32 on the 0-255 scale (uint16 divided by
257) and rounded back to their dtype at the end; float frames are repaired in their
own units.  ``sigma`` is in the units of the input's values, as for
:func:`varflow.denoise`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from itertools import chain as chain_frames
from typing import Any

import numpy as np

from ..registry import REPAIR, RESTORE
from .denoise import _to_dtype, iter_denoise, mark_cuts

__all__ = ["DENOISE", "STAGES", "ChainParams", "iter_restore", "resolve_stages",
           "restore_clip"]

log = logging.getLogger(__name__)

#: The name of the denoising stage in a chain (its method: ``denoise_method``).
DENOISE = "denoise"

#: Every stage name, in the order of the chain.
STAGES = ("stabilise", "deflicker", "dirt", DENOISE)


@dataclass
class _Item:
    """A frame on its way through the chain."""

    frame: np.ndarray          # (H, W, C) float32, work scale
    cut: bool                  # a scene cut lies before it
    mask: np.ndarray | None    # (H, W) bool: the pixels the dirt stage replaced
    # (fwd, bwd) (H, W, 2) each to the next frame of the scene, estimated by a stage
    # that changes no positions (Repairer.shares_flows), for the next stage to start from
    pair: tuple[np.ndarray, np.ndarray] | None = None


def resolve_stages(stages: Iterable[str] | None = None, params: Mapping[str, Any] | None = None,
                   denoise_method: str | None = None) -> list[tuple[str, Any, Any]]:
    """The chain's ``(name, entry, params)`` in the order of practice.

    Parameters
    ----------
    stages : iterable of str, optional
        Names of :data:`STAGES` (any order, each once); default all of them.
    params : mapping, optional
        ``{stage: params}`` where ``params`` is the stage's parameter dataclass or a
        dict of its fields to change (``{"dirt": {"sensitivity": 1.5}}``).
    denoise_method : str, optional
        The method of :data:`~varflow.registry.RESTORE` of the ``denoise`` stage
        (default: its default).

    Raises
    ------
    ValueError
        ``stages: ...`` for an unknown, repeated or missing stage; ``params: ...``
        for parameters of a stage not in the chain; the field's name for a bad
        parameter.
    """
    names = list(STAGES if stages is None else stages)
    for name in names:
        if name not in STAGES:
            raise ValueError(f"stages: unknown stage {name!r}; available: {', '.join(STAGES)}")
    if len(set(names)) != len(names):
        raise ValueError(f"stages: each stage once, got {', '.join(names)}")
    if not names:
        raise ValueError(f"stages: name at least one of {', '.join(STAGES)}")
    params = dict(params or {})
    extra = sorted(set(params) - set(names))
    if extra:
        raise ValueError(f"params: {', '.join(extra)} not in the chain ({', '.join(names)})")
    out = []
    for name in sorted(names, key=STAGES.index):
        registry = RESTORE if name == DENOISE else REPAIR
        entry = registry.entry(denoise_method if name == DENOISE and denoise_method
                               else registry.default if name == DENOISE else name)
        given = params.get(name)
        if isinstance(given, Mapping):
            p = registry.make_params(entry, **given)
        else:
            p = registry.make_params(entry, given)
        out.append((name, entry, p))
    return out


@dataclass(frozen=True)
class ChainParams:
    """A whole chain's settings: what ``varflow batch restore`` records and runs.

    Attributes
    ----------
    stages : tuple of str
        The stages, in the order of the chain (:data:`STAGES`).
    denoise_method : str or None
        The denoiser of the ``denoise`` stage (None without it).
    params : tuple of (str, dataclass)
        ``(stage, parameters)`` of every stage, resolved (defaults filled in).
    """

    stages: tuple[str, ...]
    denoise_method: str | None = None
    params: tuple[tuple[str, Any], ...] = ()

    @classmethod
    def resolve(cls, stages: Iterable[str] | None = None,
                params: Mapping[str, Any] | None = None,
                denoise_method: str | None = None) -> ChainParams:
        """The settings of :func:`resolve_stages` (same arguments, same errors)."""
        chain = resolve_stages(stages, params, denoise_method)
        method = next((e.name for n, e, _ in chain if n == DENOISE), None)
        return cls(tuple(n for n, _, _ in chain), method, tuple((n, p) for n, _, p in chain))

    @property
    def label(self) -> str:
        """The stages joined by ``+`` (with the denoiser's name): ``"dirt+nlbayes"``."""
        return "+".join(self.denoise_method if n == DENOISE else n for n in self.stages)

    def as_kwargs(self) -> dict[str, Any]:
        """``stages``, ``params`` and ``denoise_method`` for :func:`iter_restore` and
        :func:`varflow.restore.video.restore_video`."""
        return {"stages": list(self.stages), "params": dict(self.params),
                "denoise_method": self.denoise_method}


def _scale_of(dtype: np.dtype) -> float:
    """Work values per input value: integers go to 0-255, floats stay."""
    return 255.0 / np.iinfo(dtype).max if dtype.kind in "ui" else 1.0


def _windowed(items: Iterator[_Item], name: str, entry: Any, params: Any, chunk: int,
              seconds: dict[str, float]) -> Iterator[_Item]:
    """Run one repair stage on a stream, window by window within each scene."""
    ctx = int(entry.context(params))
    step = max(chunk, min(ctx, 4 * chunk))  # frames given out per window
    buf: list[_Item] = []
    done = 0  # index in buf of the first frame not given out
    base = 0  # index in the scene of buf[0]
    cache: dict[int, Any] = {}  # the pair flows from scene frame k to k + 1

    def flows(lo: int, hi: int) -> Any:
        """The stage's flows of the window buf[lo:hi], each pair estimated once; for
        a stage without flows of its own, the (fwd, bwd) the frames carry, if all do."""
        if hi - lo < 2:
            return None
        if entry.pair_flows is None:
            carried = [buf[k].pair for k in range(lo, hi - 1)]
            if any(c is None for c in carried):
                return None
            return tuple(np.stack(parts) for parts in zip(*carried, strict=True))
        for k in range(lo, hi - 1):
            if base + k not in cache:
                cache[base + k] = entry.pair_flows(buf[k].frame, buf[k + 1].frame, params)
        pairs = [cache[base + k] for k in range(lo, hi - 1)]
        if isinstance(pairs[0], tuple):
            return tuple(None if parts[0] is None else np.stack(parts)
                         for parts in zip(*pairs, strict=True))
        return np.stack(pairs)

    def process(a: int, b: int) -> Iterator[_Item]:
        lo, hi = max(0, a - ctx), min(len(buf), b + ctx)
        clip = np.stack([it.frame for it in buf[lo:hi]])
        t0 = time.perf_counter()
        out, mask = entry.run(clip, params, flows=flows(lo, hi))
        seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - t0
        for k in range(a, b):
            it = buf[k]
            m = it.mask if mask is None else (mask[k - lo] if it.mask is None
                                             else mask[k - lo] | it.mask)
            pair = cache.get(base + k) if entry.shares_flows and k + 1 < hi else None
            yield _Item(np.asarray(out[k - lo], np.float32), it.cut, m,
                        None if pair is None else (pair[0], pair[1]))

    for it in items:
        if it.cut:
            if len(buf) > done:
                yield from process(done, len(buf))
            buf, done, base = [], 0, 0
            cache.clear()
        buf.append(it)
        if len(buf) - done >= step + ctx:
            yield from process(done, done + step)
            keep = max(0, done + step - ctx)
            buf, done, base = buf[keep:], done + step - keep, base + keep
            for k in [k for k in cache if k < base]:
                del cache[k]
    if len(buf) > done:
        yield from process(done, len(buf))


def iter_restore(frames: Iterable[Any], stages: Iterable[str] | None = None, *,
                 sigma: float | None = None, params: Mapping[str, Any] | None = None,
                 denoise_method: str | None = None, chunk: int = 24,
                 is_cut: Callable[..., bool] | None = None,
                 stats: dict | None = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Restore a stream of frames; yield ``(frame, mask)`` in order.

    Parameters
    ----------
    frames : iterable of ndarray
        Frames ``(H, W[, C])`` of one shape and dtype (uint8, uint16 or float),
        finite, at least 8 × 8.
    stages : iterable of str, optional
        The stages (:data:`STAGES`, any order: they run in the order of practice);
        default all of them.
    sigma : float, optional
        The noise's standard deviation in the units of the values, for ``denoise``;
        None: estimated on the repaired frames (``stats["sigma"]``).
    params : mapping, optional
        ``{stage: parameter dataclass or dict of fields}`` (:func:`resolve_stages`).
    denoise_method : str, optional
        The denoiser (:data:`varflow.registry.RESTORE`; default ``nlbayes``).
    chunk : int
        Frames given out per window of a repair stage (at least 1; a stage of long
        context takes windows of up to four times its context).  Default 24.
    is_cut : callable, optional
        ``is_cut(frame0, frame1, previous=..., following=...) -> bool`` (e.g.
        :func:`varflow.retime.stream.is_scene_cut`), tested on the input frames: no
        stage looks across a cut.  None: one scene.
    stats : dict, optional
        Gains ``seconds`` (``{stage: wall seconds}``), ``frames``, ``cuts``,
        ``sigma`` (with ``denoise``) and ``masked`` (pixels replaced by ``dirt``).

    Yields
    ------
    frame : ndarray
        The restored frame, of the input's shape and dtype (integers rounded and
        clipped).
    mask : ndarray, shape (H, W), bool
        The pixels the ``dirt`` stage replaced (all False without it).

    Raises
    ------
    ValueError
        A bad stage, parameter or ``chunk`` (named), a frame whose shape or dtype
        differs from the first one's, a non-finite frame.
    """
    stages_ = resolve_stages(stages, params, denoise_method)
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise ValueError(f"chunk: must be an integer >= 1, got {chunk!r}")
    stats = {} if stats is None else stats
    seconds: dict[str, float] = {name: 0.0 for name, _, _ in stages_}
    stats.update(seconds=seconds, frames=0, cuts=0, masked=0)
    src = iter(frames)
    head = next(src, None)
    if head is None:
        return
    a0 = np.asarray(head)
    if a0.ndim not in (2, 3) or a0.shape[0] < 8 or a0.shape[1] < 8 or a0.dtype.kind not in "uif":
        raise ValueError(f"frames: expected frames (H, W[, C]) of at least 8 x 8 of integers "
                         f"or floats, got {a0.shape} {a0.dtype}")
    shape, dtype = a0.shape, a0.dtype
    scale = np.float32(_scale_of(dtype))

    def checked() -> Iterator[np.ndarray]:
        for i, f in enumerate(chain_frames([a0], src)):
            a = np.asarray(f)
            if a.shape != shape or a.dtype != dtype:
                raise ValueError(f"frame {i}: shape {a.shape} {a.dtype} differs from frame "
                                 f"0's {shape} {dtype}")
            if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
                raise ValueError(f"frame {i}: contains NaN or infinite values")
            yield a

    def work(pairs: Iterator[tuple[np.ndarray, bool]]) -> Iterator[_Item]:
        for a, cut in pairs:
            x = a.astype(np.float32) * scale
            if cut:
                stats["cuts"] += 1
            yield _Item(x[..., None] if x.ndim == 2 else x, cut, None)

    items: Iterator[_Item] = work(mark_cuts(checked(), is_cut))
    for name, entry, p in stages_:
        if name != DENOISE:
            items = _windowed(items, name, entry, p, chunk, seconds)

    def out(frame: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        m = np.zeros(shape[:2], bool) if mask is None else mask
        stats["frames"] += 1
        stats["masked"] += int(m.sum())
        return _to_dtype(frame / scale, dtype).reshape(shape), m

    denoiser = next(((e, p) for name, e, p in stages_ if name == DENOISE), None)
    if denoiser is None:
        for it in items:
            yield out(it.frame, it.mask)
        return
    masks: list[np.ndarray | None] = []
    upstream = 0.0

    def feed() -> Iterator[tuple[np.ndarray, bool]]:
        nonlocal upstream
        while True:
            t0 = time.perf_counter()
            it = next(items, None)
            upstream += time.perf_counter() - t0
            if it is None:
                return
            masks.append(it.mask)
            yield it.frame, it.cut

    dn_stats: dict[str, Any] = {}
    t_start = time.perf_counter()
    stream = iter_denoise(feed(), None if sigma is None else float(sigma) * float(scale),
                          denoiser[0].name, params=denoiser[1], marked=True, stats=dn_stats)
    for frame in stream:
        seconds[DENOISE] = time.perf_counter() - t_start - upstream
        if "sigma" not in stats:
            stats["sigma"] = dn_stats["sigma"] / float(scale)
        yield out(frame, masks.pop(0))
    seconds[DENOISE] = time.perf_counter() - t_start - upstream


def restore_clip(frames: Any, stages: Iterable[str] | None = None, *, sigma: float | None = None,
                 params: Mapping[str, Any] | None = None, denoise_method: str | None = None,
                 return_mask: bool = False, is_cut: Callable[..., bool] | None = None,
                 stats: dict | None = None) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Restore a clip: the chosen stages in the order of practice (module notes).

    Why: archival footage has several defects at once, and each stage works best on
    the output of the one before (aligned frames, then steady brightness, then no
    dirt for the denoiser's patch matching).

    Parameters
    ----------
    frames : ndarray or sequence of ndarray
        A clip ``(F, H, W, C)`` or ``(F, H, W)`` (grey), or a sequence of frames of
        one shape; uint8, uint16 or float (any range), finite, at least 8 × 8.
    stages : iterable of str, optional
        Names of :data:`STAGES` (``"stabilise"``, ``"deflicker"``, ``"dirt"``,
        ``"denoise"``); default all of them.
    sigma : float, optional
        The noise's standard deviation in the units of the values (``denoise``);
        None: estimated.
    params : mapping, optional
        ``{stage: parameters}``: a stage's parameter dataclass or a dict of its
        fields, e.g. ``{"dirt": {"sensitivity": 1.5}, "denoise": {"grain": 0.2}}``.
    denoise_method : str, optional
        The denoiser (default ``nlbayes``; ``nlbayes-fast`` for previews).
    return_mask : bool
        Also return the ``(F, H, W)`` bool mask of the pixels ``dirt`` replaced.
    is_cut : callable, optional
        A scene-cut test (:func:`varflow.retime.stream.is_scene_cut`): no stage
        looks across a cut.  Default: one scene.
    stats : dict, optional
        As :func:`iter_restore`.

    Returns
    -------
    ndarray
        The restored clip, of the input's shape and dtype.
    mask : ndarray, shape (F, H, W), bool
        With ``return_mask``.

    Examples
    --------
    >>> import numpy as np
    >>> import varflow
    >>> clip = np.tile(np.linspace(60, 180, 32, dtype=np.float32), (6, 32, 1))
    >>> dirty = clip.copy()
    >>> dirty[3, 10:16, 10:16] = 5.0  # a dark blotch on frame 3 only
    >>> out, mask = varflow.restore_clip(dirty, ["dirt"], return_mask=True)
    >>> bool(mask[3, 10:16, 10:16].all()), float(np.abs(out - clip).max()) < 1
    (True, True)
    """
    if isinstance(frames, np.ndarray):
        seq: Sequence[Any] = list(frames)
    else:
        seq = list(frames)
    if not seq:
        raise ValueError("frames: empty clip")
    pairs = list(iter_restore(seq, stages, sigma=sigma, params=params,
                              denoise_method=denoise_method, chunk=max(len(seq), 1),
                              is_cut=is_cut, stats=stats))
    out = np.stack([f for f, _ in pairs])
    if return_mask:
        return out, np.stack([m for _, m in pairs])
    return out
