"""The method registries: plain dicts that the API, the CLI and the benchmarks read.

:data:`METHODS` (defined in :mod:`varflow.twoframe.methods`, re-exported here) maps a
two-frame method name to a :class:`Method`: its frozen parameter dataclass, its
single-level warp solver, a one-line description and, for a method with stages
around the driver (``tvl1-ld``), the function that runs it.
:data:`TRACKERS` maps a multi-frame (trajectory) method name to a :class:`Tracker`:
its parameter dataclass and its ``track(frames, ref, params, callback)`` function.

A tracker built on a two-frame method (``twoframe``, ``chain``) composes that
method's parameter object (its field ``flow_params``); :func:`make_track_params`
routes an override that is not one of the tracker's own fields to it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from .multiframe import mfsf as _mfsf
from .multiframe import rlr as _rlr
from .multiframe import track as _track
from .twoframe.coarse_to_fine import CoarseToFineParams
from .twoframe.methods import DEFAULT_METHOD, METHODS, Method, get_method

__all__ = [
    "DEFAULT_METHOD",
    "Method",
    "METHODS",
    "Tracker",
    "TRACKERS",
    "get_method",
    "get_tracker",
    "make_params",
    "make_track_params",
    "parameter_fields",
]


@dataclass(frozen=True)
class Tracker:
    """A registered multi-frame (trajectory) method.

    Attributes
    ----------
    name : str
    params : type
        Frozen dataclass of its parameters.
    track : callable
        ``track(frames, ref, params, callback, stats=None) -> (F, H, W, 2)`` with
        ``frames`` as returned by :func:`varflow.multiframe.track.check_frames`;
        ``stats`` (a dict) may gain ``visible``, the ``(F, H, W)`` bool visibility
        when the method estimates it.
    description : str
    """

    name: str
    params: type
    track: Any
    description: str


TRACKERS: dict[str, Tracker] = {
    "rlr": Tracker(
        name="rlr",
        params=_rlr.RLRParams,
        track=_rlr.track_rlr,
        description="robust low-rank trajectories (data + TV_g + nuclear norm + L1 link)",
    ),
    "mfsf": Tracker(
        name="mfsf",
        params=_mfsf.MFSFParams,
        track=_mfsf.track_mfsf,
        description="multi-frame subspace flow (Garg et al.): soft constraint to a PCA/DCT "
        "trajectory basis",
    ),
    "twoframe": Tracker(
        name="twoframe",
        params=_track.TwoFrameTrackParams,
        track=_track.track_twoframe,
        description="independent two-frame flows (varflow.flow) from the reference to every "
        "frame",
    ),
    "chain": Tracker(
        name="chain",
        params=_track.ChainTrackParams,
        track=_track.track_chain,
        description="two-frame flows (varflow.flow) between consecutive frames, composed "
        "along the trajectory",
    ),
}


def get_tracker(name: str) -> Tracker:
    """Look a trajectory method up by name; unknown names raise ``ValueError``."""
    try:
        return TRACKERS[name]
    except KeyError:
        raise ValueError(
            f"method: unknown trajectory method {name!r}; available: {', '.join(TRACKERS)}"
        ) from None


def make_params(method: str | Method, params: Any = None, **overrides: Any) -> CoarseToFineParams:
    """Build a method's parameter object from defaults, an existing object and overrides.

    Raises
    ------
    ValueError
        For an unknown field name (named in the message) or an invalid value.
    """
    m = get_method(method) if isinstance(method, str) else method
    return _make(m, params, **overrides)


def make_track_params(method: str | Tracker, params: Any = None, **overrides: Any) -> Any:
    """:func:`make_params` for a trajectory method of :data:`TRACKERS`.

    For a tracker that composes a two-frame method (a ``flow_params`` field), an
    override that is not one of the tracker's own fields goes to ``flow_params``
    (checked against the fields of ``flow_method``'s parameters, after a change of
    ``flow_method``, which starts from that method's defaults unless
    ``flow_params`` is given too).
    """
    m = get_tracker(method) if isinstance(method, str) else method
    if "flow_params" not in {f.name for f in dataclasses.fields(m.params)}:
        return _make(m, params, **overrides)
    base = params if params is not None else m.params()
    if not isinstance(base, m.params):
        raise ValueError(f"params: expected {m.params.__name__}, got {type(base).__name__}")
    return base.replace(**overrides) if overrides else base


def parameter_fields(entry: Method | Tracker, flow_method: str | None = None
                     ) -> list[tuple[str, Any, type]]:
    """``(name, default, class documenting it)`` of every parameter an entry accepts.

    A method's fields; a tracker's own fields and, for a tracker composing a
    two-frame method, then the fields of ``flow_method``'s parameters (default: the
    tracker's default method), which :func:`make_track_params` routes to
    ``flow_params``.  The CLI builds its flags and help from it.
    """
    defaults = entry.params()
    out = [(f.name, getattr(defaults, f.name), entry.params)
           for f in dataclasses.fields(entry.params) if f.name != "flow_params"]
    inner = getattr(defaults, "flow_params", None)
    if inner is not None and dataclasses.is_dataclass(inner):
        if flow_method is not None and flow_method != defaults.flow_method:
            if flow_method not in METHODS:
                raise ValueError(f"flow_method: unknown two-frame method {flow_method!r}; "
                                 f"available: {', '.join(sorted(METHODS))}")
            inner = entry.params.default_flow_params(flow_method)
        own = {name for name, _, _ in out}
        out += [(f.name, getattr(inner, f.name), type(inner))
                for f in dataclasses.fields(inner) if f.name not in own]
    return out


def _make(m: Method | Tracker, params: Any, **overrides: Any) -> Any:
    base = params if params is not None else m.params()
    if not isinstance(base, m.params):
        raise ValueError(f"params: expected {m.params.__name__}, got {type(base).__name__}")
    names = {f.name for f in dataclasses.fields(m.params)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ValueError(
            f"{unknown[0]}: not a parameter of method {m.name!r} "
            f"(valid: {', '.join(sorted(names))})"
        )
    return dataclasses.replace(base, **overrides) if overrides else base
