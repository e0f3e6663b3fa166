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

_FLOW_KNOB = ("flow_method",
              "the two-frame method of the initial flows: tvl1-fast for speed, tvl1-ld for "
              "large motion")

# Memory factors: bytes per pixel measured as described in varflow._memory.
TRACK.register(Tracker(
    name="rlr",
    description="robust low-rank trajectories (data + TV_g + nuclear norm + L1 link)",
    defaults=_rlr.RLRParams,
    memory=MemoryFactors(base=45, per_frame=145, per_channel=32),
    kernels=_TVL1 + _USTEP + ("varflow.multiframe.lowrank:_l1_kernel",),
    compile_seconds=80,
    use="dense trajectories over a clip: the most accurate, and it knows which points are "
    "hidden in which frame",
    knobs=(("link_weight", "τ: how closely each frame follows the low-rank model; lower "
            "for non-rigid or erratic motion"),
           ("data_weight", "λ: higher follows the images more closely, lower gives smoother "
            "trajectories"),
           ("visibility", "--no-visibility skips the occlusion estimate (faster; for clips "
            "without occlusions)")),
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
    use="the published multi-frame baseline, for comparisons; rlr is more accurate",
    knobs=(("n_basis", "basis trajectories per component: more for complex motion"),
           ("subspace_weight", "β: how strongly trajectories keep to the basis")),
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
    use="quick trajectories for short clips: one flow from the reference to each frame",
    knobs=(_FLOW_KNOB,),
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
    use="long clips with small motion between frames; errors add up along the chain",
    knobs=(_FLOW_KNOB,),
    track=_track.track_chain,
))
