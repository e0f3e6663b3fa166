"""varflow: classical variational optical flow and dense trajectory estimation.

Public API
----------
flow(frame0, frame1, method="tvl1", **params)
    Dense flow ``(H, W, 2)`` float32 from ``frame0`` to ``frame1``.
track(frames, ref=None, method="rlr", **params)
    Dense trajectories ``(F, H, W, 2)`` of the reference frame's pixels.
interpolate(frame0, frame1, t=0.5, method=None, **params)
    The frame (or a stack of frames) at time ``t`` between two frames.
methods() / track_methods() / interpolation_methods()
    Names of the registered two-frame / trajectory / interpolation methods.
read_flo / write_flo / read_kitti_png / write_kitti_png / read_image / read_frames /
read_trajectories / write_trajectories
    File I/O.
flow_to_color / draw_trajectories
    Middlebury colour coding; trajectories drawn over the reference frame.
endpoint_error / angular_error / rms_endpoint_error / evaluate
    Metrics.
warp(image, flow) / consistency(flow_fw, flow_bw)
    Backward warping (the ``cv2.remap`` of a flow) and the forward-backward
    consistency mask.
estimate_noise(frames)
    The noise level of a clip, per channel and over intensity.
denoise(frames, sigma=None, method="nlbayes", **params) / restoration_methods()
    The clip without its noise (motion-compensated NL-Bayes), in the input's dtype.
deflicker(frames) / remove_dirt(frames, return_mask=False) / stabilise(frames)
    Archival defects: frame-to-frame exposure flicker, dirt and dust on one frame,
    gate weave; each keeps the input's shape and dtype.
restore_clip(frames, stages=None, sigma=None, return_mask=False)
    The repair stages and the denoiser chained in the order of practice.

Conventions: images are uint8, uint16 or float, ``(H, W)`` or ``(H, W, C)``;
flows are ``(H, W, 2)`` float32 with ``[..., 0]`` the horizontal component u and
``[..., 1]`` the vertical component v; unknown flow is NaN.

Intensities (:mod:`varflow._validate`): uint8 / uint16 frames are divided by 255 /
65535; float frames inside [0, 1] are used as they are; float frames of one call
that go outside [0, 1] are scaled *jointly* (one affine map for all the frames of
the call) from their common range [min, max] to [0, 1]; a constant frame gives
zero flow; NaN or inf is an error naming the frame.  Before running, the memory
the call needs is estimated and compared with the memory available
(:mod:`varflow._memory`; ``VARFLOW_MEMORY_LIMIT`` overrides the latter).

Layout: every method is an entry of one of the registries of :mod:`varflow.registry`
(``FLOW``, ``TRACK``, ``INTERPOLATE``, ``RESTORE``), registered by the ``methods`` module of its
package (:mod:`varflow.twoframe`, :mod:`varflow.multiframe`, :mod:`varflow.retime`);
parameters are frozen dataclasses composed of smaller ones (:mod:`varflow.parameters`,
:mod:`varflow.twoframe.params`); the two-frame solvers plug into the one coarse-to-fine
driver (:mod:`varflow.twoframe.coarse_to_fine`); kernels live in :mod:`varflow.ops`.
The documentation's developer page (``docs/guide/architecture.md``) draws it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._version import __version__
from .registry import (
    FLOW,
    INTERPOLATE,
    METHODS,
    RESTORE,
    TRACK,
    TRACKERS,
    get_method,
    get_tracker,
    make_params,
    make_track_params,
)
from .twoframe.coarse_to_fine import ProgressCallback
from .twoframe.methods import DEFAULT_METHOD, run_method

__all__ = [
    "__version__",
    "flow",
    "track",
    "methods",
    "track_methods",
    "make_track_params",
    "TRACKERS",
    "make_params",
    "METHODS",
    "FLOW",
    "TRACK",
    "INTERPOLATE",
    "read_flo",
    "write_flo",
    "read_kitti_png",
    "write_kitti_png",
    "read_image",
    "read_frames",
    "read_trajectories",
    "write_trajectories",
    "draw_trajectories",
    "read_flow",
    "write_flow",
    "flow_to_color",
    "endpoint_error",
    "angular_error",
    "rms_endpoint_error",
    "evaluate",
    "interpolate",
    "interpolation_methods",
    "warp",
    "consistency",
    "estimate_noise",
    "denoise",
    "deflicker",
    "remove_dirt",
    "stabilise",
    "restore_clip",
    "restoration_methods",
    "RESTORE",
]

#: Public names imported on first use (``name: (module, attribute)``), to keep
#: ``import varflow`` light; :func:`__getattr__` loads them and :func:`__dir__` lists them.
_LAZY = {
    "estimate_noise": ("restore.noise", "estimate_noise"),
    "denoise": ("restore.denoise", "denoise"),
    "deflicker": ("restore.flicker", "deflicker"),
    "remove_dirt": ("restore.dirt", "remove_dirt"),
    "stabilise": ("restore.stabilise", "stabilise"),
    "restore_clip": ("restore.chain", "restore_clip"),
    "warp": ("compensate", "warp"),
    "consistency": ("compensate", "consistency"),
    "read_flo": ("io.flo", "read_flo"),
    "write_flo": ("io.flo", "write_flo"),
    "read_kitti_png": ("io.kitti_png", "read_kitti_png"),
    "write_kitti_png": ("io.kitti_png", "write_kitti_png"),
    "read_image": ("io.images", "read_image"),
    "read_frames": ("io.video", "read_frames"),
    "read_trajectories": ("io.trajectories", "read_trajectories"),
    "write_trajectories": ("io.trajectories", "write_trajectories"),
    "draw_trajectories": ("viz.plots", "draw_trajectories"),
    "read_flow": ("io.images", "read_flow"),
    "write_flow": ("io.images", "write_flow"),
    "flow_to_color": ("viz.colorwheel", "flow_to_color"),
    "endpoint_error": ("evaluation.metrics", "endpoint_error"),
    "angular_error": ("evaluation.metrics", "angular_error"),
    "rms_endpoint_error": ("evaluation.metrics", "rms_endpoint_error"),
    "evaluate": ("evaluation.metrics", "evaluate"),
}


def methods() -> list[str]:
    """Names of the registered two-frame methods (see :data:`varflow.registry.FLOW`)."""
    return FLOW.names()


def track_methods() -> list[str]:
    """Names of the registered trajectory methods (see :data:`varflow.registry.TRACK`)."""
    return TRACK.names()


def track(
    frames: Any,
    ref: int | None = None,
    method: str = "rlr",
    *,
    params: Any = None,
    callback: ProgressCallback | None = None,
    return_visibility: bool = False,
    **overrides: Any,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Dense trajectories of the reference frame's pixels through a sequence.

    Parameters
    ----------
    frames : sequence of ndarray or ndarray, shape (F, H, W) or (F, H, W, C)
        uint8, uint16 or float; F >= 2, all of one shape.  Float frames inside
        [0, 1] are used as they are; if any float frame goes outside [0, 1], all
        the float frames are scaled jointly, with one affine map, from their
        common range [min, max] to [0, 1] (brightness constancy is kept).  NaN
        or inf raises a ValueError naming the frame (``"frame 7: ..."``).
    ref : int, optional
        Index of the reference frame (negative counts from the end); the centre
        frame ``F // 2`` by default.
    method : str
        A name from :func:`track_methods`.
    params : dataclass, optional
        A parameter object of the method.
    callback : callable, optional
        ``callback(done, total)`` as the work proceeds.
    return_visibility : bool
        Also return the visibility of every reference pixel in every frame
        (:mod:`varflow.multiframe.visibility`: image bounds, forward-backward
        consistency and photometric residual).  ``rlr`` and ``mfsf`` estimate it
        anyway (``visibility=True``, the default); for the other methods it costs
        one backward flow per frame.
    **overrides
        Parameter fields to change.

    Returns
    -------
    traj : ndarray, shape (F, H, W, 2), float32
        ``traj[n, y, x]`` = displacement (u, v) of reference pixel ``(x, y)`` in frame
        ``n``; ``traj[ref] == 0``.
    visible : ndarray, shape (F, H, W), bool
        Only with ``return_visibility``: is the point of reference pixel ``(x, y)``
        seen in frame ``n``?  All True in the reference frame.

    Raises
    ------
    ValueError
        Unknown method or parameter, invalid value, bad frames or ``ref``, or
        frames too large for the available memory
        (:class:`varflow._memory.InsufficientMemoryError`, raised before the run).
    """
    from ._memory import check_memory
    from .multiframe.track import check_frames, default_ref

    m = get_tracker(method)
    p = make_track_params(m, params, **overrides)
    if isinstance(frames, np.ndarray) and frames.ndim in (3, 4):  # before converting
        check_memory(m.name, frames.shape[1:], frames.shape[0], p)
    arr = check_frames(frames)
    check_memory(m.name, arr.shape[1:], arr.shape[0], p)
    r = default_ref(arr.shape[0], ref)
    stats: dict = {}
    traj = m.track(arr, r, p, callback, stats=stats)
    if not return_visibility:
        return traj
    visible = stats.get("visible")
    if visible is None:
        from .multiframe.propagate import frame_pyramids
        from .multiframe.visibility import estimate_visibility
        from .twoframe.params import PRESETS, TVL1Params

        # the backward flows are TV-L1 with the tracker's two-frame parameters when
        # those are TV-L1's (every registered method's derive from them)
        fp = getattr(p, "flow_params", p)
        fp = fp if isinstance(fp, TVL1Params) else PRESETS["tvl1"]
        visible = estimate_visibility(traj, r, frame_pyramids(arr, fp), fp)
    return traj, visible


def interpolation_methods() -> list[str]:
    """Names of the registered frame-interpolation methods
    (see :data:`varflow.registry.INTERPOLATE`)."""
    return INTERPOLATE.names()


def restoration_methods() -> list[str]:
    """Names of the registered restoration methods (see :data:`varflow.registry.RESTORE`)."""
    return RESTORE.names()


def interpolate(frame0: np.ndarray, frame1: np.ndarray, t: Any = 0.5, method: str | None = None,
                **kwargs: Any) -> np.ndarray:
    """The frame at time ``t`` between ``frame0`` and ``frame1``; see
    :func:`varflow.retime.methods.interpolate` for the parameters.

    Returns
    -------
    ndarray
        Shape and dtype of ``frame0`` (a stack of them for a sequence ``t``).
    """
    from .retime.methods import interpolate as _interpolate

    return _interpolate(frame0, frame1, t, method, **kwargs)


def flow(
    frame0: np.ndarray,
    frame1: np.ndarray,
    method: str = DEFAULT_METHOD,
    *,
    params: Any = None,
    init_flow: np.ndarray | None = None,
    callback: ProgressCallback | None = None,
    stats: dict | None = None,
    max_pixels: int = 0,
    **overrides: Any,
) -> np.ndarray:
    """Estimate dense optical flow from ``frame0`` to ``frame1``.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8 (divided by 255), uint16 (by 65535) or float.  Float frames inside
        [0, 1] are used as they are; if either goes outside [0, 1], both are
        scaled jointly, with one affine map, from their common range [min, max]
        to [0, 1], so the flow does not change under ``a * I + b`` applied to
        both frames; constant frames give zero flow.  NaN or inf raises a
        ValueError naming the frame (``"frame1: ..."``).  ``tvl1`` works on the
        mean of the colour channels by default (``grey``); with ``grey=False``,
        and in the methods built on the plain energy, colour frames use a
        vector-valued data term (one residual per channel).
    method : str
        A name from :func:`methods`.
    params : dataclass, optional
        A parameter object of the method (e.g. :class:`varflow.twoframe.tvl1.TVL1Params`).
    init_flow : ndarray, shape (H, W, 2), optional
        Initial estimate.
    callback : callable, optional
        ``callback(done, total)`` after every warp (for progress bars).
    stats : dict, optional
        Filled with timings and counters of the run (levels, warps, seconds and
        method-specific entries such as ``sparse_seconds``).
    max_pixels : int
        Frames of more pixels than this are estimated on copies reduced to this
        many (Gaussian anti-aliasing, bilinear resampling) and the flow is resized
        back, its vectors scaled to full-size pixels: a faster, coarser flow for
        large frames (about ``pixels / max_pixels`` times less work).  0 (default)
        works at full size.
    **overrides
        Parameter fields to change, e.g. ``data_weight=30.0``.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        ``[..., 0]`` = u (x, columns), ``[..., 1]`` = v (y, rows): ``frame1`` at
        ``(x + u, y + v)`` matches ``frame0`` at ``(x, y)``.

    Raises
    ------
    ValueError
        Unknown method or parameter, invalid parameter value, bad input arrays, or
        frames too large for the available memory
        (:class:`varflow._memory.InsufficientMemoryError`, raised before the run).
    """
    from ._memory import check_memory

    m = get_method(method)
    p = make_params(m, params, **overrides)
    if isinstance(max_pixels, bool) or not isinstance(max_pixels, int | np.integer) \
            or max_pixels < 0:
        raise ValueError(f"max_pixels: must be an integer >= 0, got {max_pixels!r}")
    shape = np.shape(frame0)
    if len(shape) in (2, 3):  # anything else is reported by the input checks
        from .retime.motion import working_scale

        scale = working_scale(shape, int(max_pixels))
        if scale < 1:
            return _reduced_flow(m, p, frame0, frame1, scale, init_flow, callback, stats)
        check_memory(m.name, shape, 2, p)
    return run_method(m, frame0, frame1, p, init_flow=init_flow, callback=callback, stats=stats)


def _reduced_flow(m: Any, p: Any, frame0: np.ndarray, frame1: np.ndarray, scale: float,
                  init_flow: np.ndarray | None, callback: ProgressCallback | None,
                  stats: dict | None) -> np.ndarray:
    """:func:`flow` on copies of the frames reduced by ``scale`` < 1, resized back."""
    from ._memory import check_memory
    from ._validate import check_flow, check_pair
    from .ops.pyramid import resize_flow
    from .retime.motion import reduced

    a, b = check_pair(frame0, frame1)
    small0, small1 = reduced(a, scale), reduced(b, scale)
    init = None
    if init_flow is not None:
        init = check_flow(init_flow, "init_flow")
        if init.shape[:2] != a.shape[:2]:
            raise ValueError(f"init_flow: expected shape {a.shape[:2] + (2,)}, got {init.shape}")
        init = resize_flow(init, small0.shape[:2])
    check_memory(m.name, small0.shape, 2, p)
    small = run_method(m, small0, small1, p, init_flow=init, callback=callback, stats=stats)
    return resize_flow(small, a.shape[:2])


def __dir__() -> list[str]:
    # the module's attributes and the lazily loaded public names, so that dir() and
    # tab completion show every name of __all__
    return sorted(set(globals()) | set(__all__))


def __getattr__(name: str) -> Any:
    # I/O, visualisation and metrics are imported on first use to keep start-up light.
    if name in _LAZY:
        import importlib

        mod, attr = _LAZY[name]
        return getattr(importlib.import_module(f".{mod}", __name__), attr)
    raise AttributeError(f"module 'varflow' has no attribute {name!r}")
