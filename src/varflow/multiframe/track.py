"""Dense trajectories from two-frame flows: the ``twoframe`` and ``chain`` baselines.

A trajectory array ``traj`` of shape ``(F, H, W, 2)`` holds, for every pixel ``x`` of
the reference frame ``ref``, its displacement in frame ``n``: the point seen at ``x``
in frame ``ref`` is at ``x + traj[n, x]`` in frame ``n`` (``traj[ref] = 0``).

* ``twoframe`` — independent two-frame flows from the reference to every frame:
  ``traj[n] = flow(I_ref, I_n)``.  Far frames need large displacements, which the
  coarse-to-fine pyramid handles up to a point.
* ``chain`` — flows between consecutive frames composed along the trajectory
  (Gibson & Marques 2016, ch. 4): ``traj[n] = traj[n−1] + f_{n−1→n}(x + traj[n−1])``
  for ``n > ref`` and symmetrically with ``f_{n+1→n}`` for ``n < ref``; each flow is
  sampled (bicubic) at the current position.  Errors accumulate (drift), but every
  flow is small.

Both run a registered two-frame method (``flow_method``; by default that of
:func:`varflow.flow`, :data:`~varflow.twoframe.methods.DEFAULT_METHOD`) with its
parameter object (``flow_params``) exactly as :func:`varflow.flow` does, so that
``twoframe`` is a loop of :func:`varflow.flow` and the baseline of every trajectory
table is the flow a user already has.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_float_frames, match_channels
from .._validate import check_field as _check
from ..ops.warp import warp_bicubic
from ..registry import DEFAULT_METHOD, FLOW
from ..twoframe.methods import FlowComposed, run_method
from ..twoframe.params import TVL1Params

__all__ = [
    "TrackCallback",
    "FlowTrackParams",
    "TwoFrameTrackParams",
    "ChainTrackParams",
    "check_frames",
    "default_ref",
    "track_twoframe",
    "track_chain",
    "compose",
]

log = logging.getLogger(__name__)

#: ``callback(done, total)`` after every unit of work (a flow, a level...).
TrackCallback = Callable[[int, int], None]


@dataclass(frozen=True)
class FlowTrackParams(FlowComposed):
    """Parameters of the trackers built on two-frame flows (``twoframe``, ``chain``).

    The two-frame method and its parameter object are fields, so any method of
    :data:`~varflow.registry.FLOW` serves, each with all its own fields; a flat
    override that is not a field here goes to ``flow_params``
    (:func:`varflow.parameters.replace`), and a new ``flow_method`` without
    ``flow_params`` starts from that method's defaults.

    Attributes
    ----------
    flow_method : str
        The two-frame method, a name of :data:`~varflow.registry.FLOW`.
        Default ``"tvl1"``, the default of :func:`varflow.flow`.
    flow_params : TVL1Params or None
        Its parameters (with the method's terms); None (default) gives
        :meth:`default_flow_params`, the method's defaults.
    """

    flow_method: str = DEFAULT_METHOD
    flow_params: TVL1Params | None = None



#: The former names of :class:`FlowTrackParams` for each tracker.
TwoFrameTrackParams = FlowTrackParams
ChainTrackParams = FlowTrackParams


def _flow(params: FlowTrackParams, frame0: np.ndarray, frame1: np.ndarray) -> np.ndarray:
    """The flow of ``params.flow_method`` from ``frame0`` to ``frame1``, as
    :func:`varflow.flow` computes it."""
    return run_method(FLOW[params.flow_method], frame0, frame1, params.flow_params)


def check_frames(frames: Any) -> np.ndarray:
    """Validate a frame sequence and convert it to ``(F, H, W, C)`` float32 in [0, 1].

    Float frames outside [0, 1] are scaled jointly from the common range of all
    the frames (:func:`varflow._validate.as_float_frames`).

    Parameters
    ----------
    frames : sequence of ndarray or ndarray, shape (F, H, W) or (F, H, W, C)
        uint8, uint16 or float (finite); all of one shape.

    Returns
    -------
    ndarray, shape (F, H, W, C), float32

    Raises
    ------
    ValueError
        Fewer than 2 frames, frames of different shapes, or a bad frame (named by index).
    """
    if isinstance(frames, np.ndarray):
        if frames.ndim not in (3, 4):
            raise ValueError(f"frames: expected shape (F, H, W[, C]), got {frames.shape}")
        seq: Sequence[Any] = list(frames)
    else:
        try:
            seq = list(frames)
        except TypeError:
            raise ValueError("frames: expected a sequence of images or an array") from None
    if len(seq) < 2:
        raise ValueError(f"frames: need at least 2 frames, got {len(seq)}")
    names = [f"frame {i}" for i in range(len(seq))]
    out = match_channels(as_float_frames(seq, names), [np.shape(f) for f in seq], names)
    return np.stack(out)


def default_ref(n_frames: int, ref: int | None) -> int:
    """The reference index: ``ref`` checked against ``n_frames``, or the centre frame."""
    if ref is None:
        return n_frames // 2
    if isinstance(ref, bool) or not isinstance(ref, int | np.integer):
        raise ValueError(f"ref: expected an integer frame index, got {ref!r}")
    if ref < 0:
        ref += n_frames
    _check(0 <= ref < n_frames, "ref", f"must index one of the {n_frames} frames, got {ref}")
    return int(ref)


def _progress(callback: TrackCallback | None, done: int, total: int) -> None:
    if callback is not None:
        callback(done, total)


def track_twoframe(
    frames: np.ndarray, ref: int, params: FlowTrackParams,
    callback: TrackCallback | None = None, stats: dict | None = None,
) -> np.ndarray:
    """Trajectories as independent two-frame flows from the reference to every frame.

    ``traj[n]`` is exactly ``varflow.flow(frames[ref], frames[n], params.flow_method,
    params=params.flow_params)``.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32
        From :func:`check_frames`.
    ref : int
    params : FlowTrackParams
    callback : callable, optional
        ``callback(done, total)`` after each flow.
    stats : dict, optional
        Gains ``seconds``.

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
    """
    t0 = time.perf_counter()
    f, h, w = frames.shape[:3]
    traj = np.zeros((f, h, w, 2), np.float32)
    todo = [n for n in range(f) if n != ref]
    for i, n in enumerate(todo):
        traj[n] = _flow(params, frames[ref], frames[n])
        _progress(callback, i + 1, len(todo))
    if stats is not None:
        stats["seconds"] = time.perf_counter() - t0
    return traj


def compose(traj_prev: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """One chaining step: ``traj_prev + flow(x + traj_prev)`` (bicubic sampling of ``flow``).

    Parameters
    ----------
    traj_prev : ndarray, shape (H, W, 2)
        Displacements of the reference pixels in frame ``m``.
    flow : ndarray, shape (H, W, 2)
        Flow from frame ``m`` to frame ``n``.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        Displacements in frame ``n``; positions outside frame ``m`` sample its border
        (replicated), so the trajectory continues with the nearest flow.
    """
    sampled, _ = warp_bicubic(np.ascontiguousarray(flow, np.float32), traj_prev)
    return (traj_prev + sampled).astype(np.float32)


def track_chain(
    frames: np.ndarray, ref: int, params: FlowTrackParams,
    callback: TrackCallback | None = None, stats: dict | None = None,
) -> np.ndarray:
    """Trajectories by composing consecutive two-frame flows outwards from the reference.

    Arguments and result as in :func:`track_twoframe`.
    """
    t0 = time.perf_counter()
    f, h, w = frames.shape[:3]
    traj = np.zeros((f, h, w, 2), np.float32)
    total = f - 1
    done = 0
    for n in range(ref + 1, f):
        traj[n] = compose(traj[n - 1], _flow(params, frames[n - 1], frames[n]))
        done += 1
        _progress(callback, done, total)
    for n in range(ref - 1, -1, -1):
        traj[n] = compose(traj[n + 1], _flow(params, frames[n + 1], frames[n]))
        done += 1
        _progress(callback, done, total)
    if stats is not None:
        stats["seconds"] = time.perf_counter() - t0
    return traj
