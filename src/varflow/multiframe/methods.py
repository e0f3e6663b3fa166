"""The trajectory methods, registered in :data:`varflow.registry.TRACK`.

Each :class:`~varflow.registry.Tracker` names its parameter defaults, its
``track(frames, ref, params, callback, stats=None)`` function, a one-line
description, its memory model and the kernels its first run compiles.
"""

from __future__ import annotations

from ..registry import TRACK, MemoryFactors, Tracker
from . import mfsf as _mfsf
from . import rlr as _rlr
from . import track as _track

__all__ = ["TRACKERS"]

TRACKERS = TRACK

_TVL1 = ("varflow.twoframe.tvl1:tvl1_iterations",)
_USTEP = ("varflow.multiframe.ustep:ustep_iterations",)

# Memory factors: bytes per pixel measured as described in varflow._memory.
TRACK.register(Tracker(
    name="rlr",
    description="robust low-rank trajectories (data + TV_g + nuclear norm + L1 link)",
    defaults=_rlr.RLRParams,
    memory=MemoryFactors(base=45, per_frame=145, per_channel=32),
    kernels=_TVL1 + _USTEP + ("varflow.multiframe.lowrank:_l1_kernel",),
    compile_seconds=80,
    track=_rlr.track_rlr,
))
TRACK.register(Tracker(
    name="mfsf",
    description="multi-frame subspace flow (Garg et al.): soft constraint to a PCA/DCT "
    "trajectory basis",
    defaults=_mfsf.MFSFParams,
    memory=MemoryFactors(base=145, per_frame=135, per_channel=26),
    kernels=_TVL1 + _USTEP,
    compile_seconds=70,
    track=_mfsf.track_mfsf,
))
TRACK.register(Tracker(
    name="twoframe",
    description="independent two-frame flows (varflow.flow) from the reference to every "
    "frame",
    defaults=_track.FlowTrackParams,
    memory=MemoryFactors(base=110, per_frame=14, per_channel=20),
    kernels=_TVL1,
    compile_seconds=35,
    track=_track.track_twoframe,
))
TRACK.register(Tracker(
    name="chain",
    description="two-frame flows (varflow.flow) between consecutive frames, composed "
    "along the trajectory",
    defaults=_track.FlowTrackParams,
    memory=MemoryFactors(base=110, per_frame=14, per_channel=21),
    kernels=_TVL1,
    compile_seconds=40,
    track=_track.track_chain,
))
