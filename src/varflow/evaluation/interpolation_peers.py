"""Frame-interpolation peers run in the same process: FFmpeg's minterpolate, blend, repeat.

Every peer is ``peer(frame0, frame1, t) -> frame``, the frame at time ``t`` between
``frame0`` (t = 0) and ``frame1`` (t = 1); :data:`INTERPOLATION_PEERS` maps their
names to them.

:func:`minterpolate`
    FFmpeg's motion-compensated interpolation filter (block matching, overlapped
    block motion compensation) through PyAV's filter graph, with
    :data:`MINTERPOLATE_OPTIONS`.
:func:`blend`
    The cross-fade ``(1 − t)·frame0 + t·frame1``.
:func:`repeat`
    The nearer input frame (frame repetition, what a player without interpolation
    shows).

How minterpolate is driven
--------------------------
The graph is ``buffer (rgb24) → format=yuv444p → minterpolate → format=rgb24 →
buffersink``.  minterpolate works on planar YUV; the explicit 4:4:4 format keeps
the chroma at full resolution (a 4:2:0 round trip alone costs about 30 dB of PSNR
on a textured frame), works for odd widths and heights (no padding needed) and
costs only the rounding of the RGB ↔ YUV conversions (a frame passed through it
comes back with a PSNR of about 52 dB).  The filter refuses frames narrower or
lower than 32 pixels (:data:`MIN_SIDE`); smaller frames are padded by edge
replication to 32 and the output cropped back.  For ``t = k/n`` the two frames are fed
at rate r (:data:`INPUT_RATE`) and the filter asked for ``fps = n·r``; the output
with presentation time ``k/(n·r)`` is the frame at ``t``.  minterpolate holds
frames back: after ``frame0`` and ``frame1`` nothing comes out, and flushing with
``graph.push(None)`` does not release them either; it emits the frames of the
interval [frame0, frame1] only once a third frame has arrived.  :func:`minterpolate`
therefore pushes ``frame1`` a second time (the output between frame0 and frame1
does not depend on that third frame: replacing it with a real next frame gives
bit-identical output).  ``t = 0`` and ``t = 1`` return copies of the inputs.

References
----------
FFmpeg filters documentation, "minterpolate" (libavfilter/vf_minterpolate.c).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from fractions import Fraction

import numpy as np

__all__ = [
    "INPUT_RATE",
    "INTERPOLATION_PEERS",
    "MAX_DENOMINATOR",
    "MIN_SIDE",
    "MINTERPOLATE_OPTIONS",
    "blend",
    "minterpolate",
    "minterpolate_stream",
    "minterpolate_times",
    "repeat",
    "time_fraction",
]

#: The options of FFmpeg's minterpolate filter (``fps`` is added per call):
#: motion-compensated interpolation, adaptive overlapped block motion compensation,
#: bidirectional motion estimation, variable-size block motion compensation, no
#: scene-change detection (which would fall back to frame repetition).
MINTERPOLATE_OPTIONS = "mi_mode=mci:mc_mode=aobmc:me_mode=bidir:vsbmc=1:scd=none"

#: The frame rate at which the two input frames are fed (frames per second).
INPUT_RATE = 25

#: The smallest width and height minterpolate accepts; smaller frames are padded.
MIN_SIDE = 32

#: The largest denominator n of a time t = k/n that :func:`minterpolate` accepts.
MAX_DENOMINATOR = 120


def time_fraction(t: float) -> Fraction:
    """``t`` in [0, 1] as a fraction ``k/n`` with ``n ≤`` :data:`MAX_DENOMINATOR`.

    Raises
    ------
    ValueError
        ``t`` outside [0, 1] or not such a fraction (within 1e-9).
    """
    t = float(t)
    if not (math.isfinite(t) and 0.0 <= t <= 1.0):
        raise ValueError(f"t: must lie in [0, 1], got {t!r}")
    frac = Fraction(t).limit_denominator(MAX_DENOMINATOR)
    if abs(float(frac) - t) > 1e-9:
        raise ValueError(f"t: minterpolate needs a time k/n with n <= {MAX_DENOMINATOR}, "
                         f"got {t!r}")
    return frac


def _rgb_pair(frame0: np.ndarray, frame1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The frames as contiguous uint8 (H, W, 3) (floats in [0, 1] scaled and rounded)."""
    out = []
    for name, f in (("frame0", frame0), ("frame1", frame1)):
        a = np.asarray(f)
        if a.ndim != 3 or a.shape[2] != 3:
            raise ValueError(f"{name}: minterpolate needs RGB frames (H, W, 3), got {a.shape}")
        if np.issubdtype(a.dtype, np.floating):
            a = np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)
        elif a.dtype != np.uint8:
            raise ValueError(f"{name}: unsupported dtype {a.dtype} (uint8 or float in [0, 1])")
        out.append(np.ascontiguousarray(a))
    if out[0].shape != out[1].shape:
        raise ValueError(f"frame1: shape {out[1].shape} differs from frame0 {out[0].shape}")
    if min(out[0].shape[:2]) < 2:
        raise ValueError(f"frame0: image too small, shape {out[0].shape}")
    return out[0], out[1]


def _run_minterpolate(frames: Sequence[np.ndarray], n: int) -> dict[int, np.ndarray]:
    """minterpolate over uint8 RGB ``frames`` fed at :data:`INPUT_RATE` and output at
    ``fps = n·INPUT_RATE``: ``{k: frame}`` for the output at ``t = k/n`` frame
    intervals after the first frame (the last frame is pushed twice to release the
    last interval; sides below :data:`MIN_SIDE` are padded by edge replication and
    cropped back)."""
    import av

    h0, w0 = frames[0].shape[:2]
    pad = ((0, max(0, MIN_SIDE - h0)), (0, max(0, MIN_SIDE - w0)), (0, 0))
    if pad[0][1] or pad[1][1]:
        frames = [np.pad(f, pad, mode="edge") for f in frames]
    h, w = frames[0].shape[:2]
    base = Fraction(1, INPUT_RATE)
    graph = av.filter.Graph()
    chain = [
        graph.add_buffer(width=w, height=h, format="rgb24", time_base=base),
        graph.add("format", "yuv444p"),
        graph.add("minterpolate", f"fps={n * INPUT_RATE}:{MINTERPOLATE_OPTIONS}"),
        graph.add("format", "rgb24"),
        graph.add("buffersink"),
    ]
    for a, b in zip(chain, chain[1:], strict=False):
        a.link_to(b)
    graph.configure()
    outputs: dict[int, np.ndarray] = {}

    def drain() -> None:
        while True:
            try:
                frame = graph.pull()
            except (av.BlockingIOError, av.EOFError):
                return
            k = Fraction(frame.pts) * Fraction(frame.time_base) / base * n
            if k.denominator == 1 and 0 <= k <= (len(frames) - 1) * n:
                outputs[int(k)] = np.ascontiguousarray(
                    frame.to_ndarray(format="rgb24")[:h0, :w0])

    # the last frame again releases the frames of the last interval
    for i, f in enumerate([*frames, frames[-1]]):
        vf = av.VideoFrame.from_ndarray(f, format="rgb24")
        vf.pts = i
        vf.time_base = base
        graph.push(vf)
        drain()
    graph.push(None)
    drain()
    return outputs


def minterpolate_stream(frames: Sequence[np.ndarray], factor: int) -> list[np.ndarray]:
    """FFmpeg minterpolate run over a clip: ``factor − 1`` frames between every two.

    The clip is pushed through one filter graph at ``fps = factor·r``, as FFmpeg
    retimes a video (the motion of every pair is estimated once and frames are
    held back, so this measures its cost per frame in a stream).

    Parameters
    ----------
    frames : sequence of ndarray, each (H, W, 3)
        At least two uint8 RGB frames (floats in [0, 1] scaled and rounded), of
        one size (sides below :data:`MIN_SIDE` are padded).
    factor : int
        At least 2.

    Returns
    -------
    list of ndarray, each (H, W, 3), uint8
        The ``(len(frames) − 1) (factor − 1)`` in-between frames, in order.

    Raises
    ------
    ValueError
        Fewer than two frames, frames of other sizes, ``factor`` below 2.
    RuntimeError
        An in-between frame is missing from the filter's output.
    """
    if isinstance(factor, bool) or not isinstance(factor, int) or factor < 2:
        raise ValueError(f"factor: expected an integer >= 2, got {factor!r}")
    if len(frames) < 2:
        raise ValueError(f"frames: need at least 2, got {len(frames)}")
    rgb = [_rgb_pair(frames[0], f)[1] for f in frames]
    outputs = _run_minterpolate(rgb, factor)
    wanted = [k for k in range((len(rgb) - 1) * factor) if k % factor]
    missing = [k for k in wanted if k not in outputs]
    if missing:
        raise RuntimeError(f"minterpolate gave no frame at {missing[0]}/{factor}")
    return [outputs[k] for k in wanted]


def minterpolate_times(frame0: np.ndarray, frame1: np.ndarray,
                       times: Sequence[float]) -> np.ndarray:
    """FFmpeg minterpolate's frames at several times, from one run of the filter.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, 3)
        uint8 RGB (floats in [0, 1] are scaled by 255 and rounded).
    times : sequence of float
        Each in [0, 1] and of the form k/n with n ≤ :data:`MAX_DENOMINATOR`; the
        filter runs at the least common multiple of the denominators.

    Returns
    -------
    ndarray, shape (len(times), H, W, 3), uint8
        ``t = 0`` and ``t = 1`` give the inputs exactly.

    Raises
    ------
    ValueError
        Bad frames or times.
    RuntimeError
        minterpolate produced no frame at a requested time (should not happen).
    """
    f0, f1 = _rgb_pair(frame0, frame1)
    fracs = [time_fraction(t) for t in times]
    if not fracs:
        raise ValueError("times: give at least one time")
    inner = [fr for fr in fracs if 0 < fr < 1]
    outputs: dict[int, np.ndarray] = {}
    n = 1
    if inner:
        n = math.lcm(*(fr.denominator for fr in inner))
        outputs = _run_minterpolate([f0, f1], n)
    out = []
    for fr in fracs:
        if fr == 0:
            out.append(f0.copy())
        elif fr == 1:
            out.append(f1.copy())
        else:
            k = int(fr * n)
            if k not in outputs:
                raise RuntimeError(f"minterpolate gave no frame at t = {fr} (outputs at "
                                   f"{sorted(outputs)} of {n})")
            out.append(outputs[k])
    return np.stack(out)


def minterpolate(frame0: np.ndarray, frame1: np.ndarray, t: float = 0.5) -> np.ndarray:
    """FFmpeg minterpolate's frame at time ``t`` (see the module notes for how it runs).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, 3)
        uint8 RGB (floats in [0, 1] are scaled by 255 and rounded); any width and
        height (odd sizes work; sides below :data:`MIN_SIDE` are padded).
    t : float
        In [0, 1], of the form k/n with n ≤ :data:`MAX_DENOMINATOR` (0.5 by default).

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
    """
    return minterpolate_times(frame0, frame1, [t])[0]


def _check_blend_pair(frame0: np.ndarray, frame1: np.ndarray,
                      t: float) -> tuple[np.ndarray, np.ndarray, float]:
    a0, a1 = np.asarray(frame0), np.asarray(frame1)
    if a0.shape != a1.shape:
        raise ValueError(f"frame1: shape {a1.shape} differs from frame0 {a0.shape}")
    if a0.dtype != a1.dtype:
        raise ValueError(f"frame1: dtype {a1.dtype} differs from frame0 {a0.dtype}")
    t = float(t)
    if not (math.isfinite(t) and 0.0 <= t <= 1.0):
        raise ValueError(f"t: must lie in [0, 1], got {t!r}")
    return a0, a1, t


def blend(frame0: np.ndarray, frame1: np.ndarray, t: float = 0.5) -> np.ndarray:
    """The cross-fade ``(1 − t)·frame0 + t·frame1``.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        One shape and dtype.
    t : float
        In [0, 1].

    Returns
    -------
    ndarray
        The dtype of the inputs: integer frames rounded half to even
        (:func:`numpy.rint`) and clipped to the dtype's range; float frames as
        computed (in float32, or float64 for float64 inputs).
    """
    a0, a1, t = _check_blend_pair(frame0, frame1, t)
    work = np.float64 if a0.dtype == np.float64 else np.float32
    out = (1 - t) * a0.astype(work) + t * a1.astype(work)
    if np.issubdtype(a0.dtype, np.integer):
        info = np.iinfo(a0.dtype)
        return np.clip(np.rint(out), info.min, info.max).astype(a0.dtype)
    return out.astype(a0.dtype)


def repeat(frame0: np.ndarray, frame1: np.ndarray, t: float = 0.5) -> np.ndarray:
    """The nearer input frame: ``frame0`` for ``t ≤ 0.5``, ``frame1`` for ``t > 0.5``.

    The tie ``t = 0.5`` goes to the earlier frame, ``frame0`` (frame repetition
    holds the last shown frame).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        One shape and dtype.
    t : float
        In [0, 1].

    Returns
    -------
    ndarray
        A copy of ``frame0`` or ``frame1``.
    """
    a0, a1, t = _check_blend_pair(frame0, frame1, t)
    return (a0 if t <= 0.5 else a1).copy()


#: The peers by name: ``peer(frame0, frame1, t) -> frame``.
INTERPOLATION_PEERS: dict[str, Callable[[np.ndarray, np.ndarray, float], np.ndarray]] = {
    "minterpolate": minterpolate,
    "blend": blend,
    "repeat": repeat,
}
