"""Reference two-frame flow methods of other libraries ("peers"), for comparison.

Every peer is a callable ``peer(frame0, frame1) -> flow`` with the conventions of
:func:`varflow.flow`: frames ``(H, W)`` or ``(H, W, C)``, uint8, uint16 or float
in ``[0, 1]``; the result is ``(H, W, 2)`` float32 with ``[..., 0]`` = u
(horizontal) and ``[..., 1]`` = v (vertical), ``frame1(x + w(x)) ~ frame0(x)``.
The peers work on grey images: colour frames are converted with the luminance
weights of ``skimage.color.rgb2gray`` (0.2125, 0.7154, 0.0721) and quantised to
uint8; :data:`PEERS` maps a name to its callable:

``"deepflow"``
    OpenCV contrib DeepFlow (``cv2.optflow.createOptFlow_DeepFlow()``, default
    parameters), Weinzaepfel et al., ICCV 2013.
``"dis"``
    OpenCV Dense Inverse Search, ``cv2.DISOpticalFlow_create(
    cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)``, Kroeger et al., ECCV 2016.
``"dualtvl1"``
    OpenCV contrib dual TV-L1 (``cv2.optflow.DualTVL1OpticalFlow_create()``,
    default parameters), Zach, Pock & Bischof 2007 / Wedel et al. 2009.
``"skimage"``
    scikit-image TV-L1, ``skimage.registration.optical_flow_tvl1`` (default
    parameters) on the same grey image scaled to ``[0, 1]``; its ``(v, u)``
    output is reordered to ``(u, v)``.

OpenCV (``opencv-contrib-python-headless``) and scikit-image are optional (the
``bench`` extra).  A missing backend makes its peers unavailable, not an error at
import: :func:`available_peers` lists the usable ones, :func:`peer_status` gives
the reason for the others, and calling an unavailable peer raises
:class:`PeerUnavailableError` (an ``ImportError``) with that reason.  OpenCV may
use several threads (``cv2.getNumThreads()``, see :func:`peer_threads`).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = [
    "PEERS",
    "PEER_DESCRIPTIONS",
    "PeerUnavailableError",
    "available_peers",
    "peer_status",
    "peer_threads",
    "to_grey_uint8",
    "deepflow",
    "dis",
    "dualtvl1",
    "skimage_tvl1",
]

_LUMA = np.array([0.2125, 0.7154, 0.0721])
_INSTALL = "pip install 'varflow[bench]'"


class PeerUnavailableError(ImportError):
    """A peer's backend (OpenCV contrib or scikit-image) is not installed or incomplete."""


def _import_cv2() -> Any:
    try:
        cv2 = importlib.import_module("cv2")
    except ImportError as exc:
        raise PeerUnavailableError(
            f"OpenCV is not installed ({exc}); {_INSTALL} or opencv-contrib-python-headless"
        ) from exc
    return cv2


def _require_contrib(cv2: Any) -> Any:
    if not hasattr(cv2, "optflow"):
        raise PeerUnavailableError(
            "OpenCV has no contrib module cv2.optflow (opencv-python without contrib?); "
            "install opencv-contrib-python-headless instead"
        )
    return cv2.optflow


def _import_skimage_tvl1() -> Any:
    try:
        registration = importlib.import_module("skimage.registration")
    except ImportError as exc:
        raise PeerUnavailableError(
            f"scikit-image is not installed ({exc}); {_INSTALL} or scikit-image"
        ) from exc
    return registration.optical_flow_tvl1


def to_grey_uint8(frame: np.ndarray) -> np.ndarray:
    """Grey uint8 image of a frame, as the OpenCV peers take it.

    Parameters
    ----------
    frame : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float in ``[0, 1]``; C = 3 or 4 is RGB(A) (luminance of
        ``skimage.color.rgb2gray``), C = 1 is grey.

    Returns
    -------
    ndarray, shape (H, W), uint8

    Raises
    ------
    ValueError
        On another shape (``frame: ...``).
    """
    arr = np.asarray(frame)
    dtype = arr.dtype
    if dtype == np.uint8:
        scale = 1.0
    elif dtype == np.uint16:
        scale = 1.0 / 257.0
    elif np.issubdtype(dtype, np.floating):
        scale = 255.0
    else:
        raise ValueError(f"frame: expected uint8, uint16 or float values, got {dtype}")
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    elif arr.ndim == 3 and arr.shape[2] in (3, 4):
        arr = arr[..., :3].astype(np.float64) @ _LUMA
    if arr.ndim != 2:
        raise ValueError(
            f"frame: expected (H, W) or (H, W, C) with C in 1, 3, 4, got {np.shape(frame)}"
        )
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr)
    return np.clip(np.rint(arr * scale), 0, 255).astype(np.uint8)


def _check_pair(frame0: np.ndarray, frame1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    g0, g1 = to_grey_uint8(frame0), to_grey_uint8(frame1)
    if g0.shape != g1.shape:
        raise ValueError(f"frame1: shape {g1.shape} differs from frame0's {g0.shape}")
    return g0, g1


def _as_flow(flow: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    out = np.ascontiguousarray(flow, dtype=np.float32)
    if out.shape != shape + (2,):
        raise RuntimeError(f"peer returned a flow of shape {out.shape}, expected {shape + (2,)}")
    return out


def deepflow(frame0: np.ndarray, frame1: np.ndarray) -> np.ndarray:
    """OpenCV contrib DeepFlow on grey uint8 frames.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        Flow frame0 -> frame1, ``[..., 0]`` = u, ``[..., 1]`` = v.

    Raises
    ------
    PeerUnavailableError
        Without OpenCV contrib.
    """
    optflow = _require_contrib(_import_cv2())
    g0, g1 = _check_pair(frame0, frame1)
    return _as_flow(optflow.createOptFlow_DeepFlow().calc(g0, g1, None), g0.shape)


def dis(frame0: np.ndarray, frame1: np.ndarray) -> np.ndarray:
    """OpenCV DIS optical flow, preset MEDIUM, on grey uint8 frames (see :func:`deepflow`)."""
    cv2 = _import_cv2()
    g0, g1 = _check_pair(frame0, frame1)
    est = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return _as_flow(est.calc(g0, g1, None), g0.shape)


def dualtvl1(frame0: np.ndarray, frame1: np.ndarray) -> np.ndarray:
    """OpenCV contrib dual TV-L1, defaults, on grey uint8 frames (see :func:`deepflow`)."""
    optflow = _require_contrib(_import_cv2())
    g0, g1 = _check_pair(frame0, frame1)
    return _as_flow(optflow.DualTVL1OpticalFlow_create().calc(g0, g1, None), g0.shape)


def skimage_tvl1(frame0: np.ndarray, frame1: np.ndarray) -> np.ndarray:
    """scikit-image ``optical_flow_tvl1`` on the grey frames in ``[0, 1]`` (see :func:`deepflow`).

    scikit-image returns ``(v, u)`` stacked first (rows, then columns) with the same
    meaning as here (``frame1(x + w) ~ frame0(x)``); it is reordered to ``(u, v)``
    last.
    """
    tvl1 = _import_skimage_tvl1()
    g0, g1 = _check_pair(frame0, frame1)
    vu = tvl1(g0.astype(np.float32) / 255.0, g1.astype(np.float32) / 255.0)
    return _as_flow(np.stack([vu[1], vu[0]], axis=-1), g0.shape)


#: Peer name -> ``peer(frame0, frame1) -> (H, W, 2) float32`` flow.
PEERS: dict[str, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    "deepflow": deepflow,
    "dis": dis,
    "dualtvl1": dualtvl1,
    "skimage": skimage_tvl1,
}

#: Peer name -> one-line description (for tables and ``--help``).
PEER_DESCRIPTIONS: dict[str, str] = {
    "deepflow": "OpenCV contrib DeepFlow (grey uint8)",
    "dis": "OpenCV DIS, preset MEDIUM (grey uint8)",
    "dualtvl1": "OpenCV contrib DualTVL1, defaults (grey uint8)",
    "skimage": "scikit-image optical_flow_tvl1, defaults (grey)",
}

_CHECKS: dict[str, Callable[[], Any]] = {
    "deepflow": lambda: _require_contrib(_import_cv2()).createOptFlow_DeepFlow,
    "dis": lambda: _import_cv2().DISOpticalFlow_create,
    "dualtvl1": lambda: _require_contrib(_import_cv2()).DualTVL1OpticalFlow_create,
    "skimage": _import_skimage_tvl1,
}


def peer_status() -> dict[str, str | None]:
    """Whether each peer of :data:`PEERS` can run.

    Returns
    -------
    dict
        Peer name -> None when available, else the reason (one line, with the
        install hint).
    """
    status: dict[str, str | None] = {}
    for name in PEERS:
        try:
            _CHECKS[name]()
        except (ImportError, AttributeError) as exc:
            status[name] = str(exc) or type(exc).__name__
        else:
            status[name] = None
    return status


def available_peers() -> list[str]:
    """Names of the peers whose backend is installed, in :data:`PEERS` order."""
    return [name for name, reason in peer_status().items() if reason is None]


def peer_threads() -> int | None:
    """``cv2.getNumThreads()`` (the OpenCV peers' threads), None without OpenCV."""
    try:
        return int(_import_cv2().getNumThreads())
    except PeerUnavailableError:
        return None
