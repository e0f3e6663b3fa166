"""Flow fields as NumPy ``.npy`` files: the array itself, for Python users.

A ``.npy`` flow holds exactly the in-memory convention, shape ``(H, W, 2)``
float32 with u = ``[..., 0]``, v = ``[..., 1]`` and NaN where unknown, so a round
trip is byte-exact (NaN included) and ``numpy.load`` reads it without varflow.
Pickled objects are never loaded.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from ._atomic import atomic_write
from .flo import MAX_SIDE, FlowFormatError, flow_to_write

__all__ = ["read_npy_flow", "write_npy_flow"]

logger = logging.getLogger(__name__)


def read_npy_flow(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a flow saved as ``.npy``.

    Parameters
    ----------
    path : str or path-like
        A ``.npy`` file of shape ``(H, W, 2)`` and a floating dtype (float16, 32 or
        64; converted to float32).

    Returns
    -------
    flow : ndarray, shape (H, W, 2), float32
        NaN where unknown (infinite values are taken as unknown too).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    FlowFormatError
        If the file is not a ``.npy`` array, holds pickled objects, or the array is
        not ``(H, W, 2)`` floating point.
    """
    path = Path(os.fspath(path))
    if not path.exists():
        raise FileNotFoundError(2, "flow file not found", str(path))
    try:
        arr = np.load(path, allow_pickle=False, mmap_mode=None)
    except (ValueError, OSError, EOFError) as exc:
        detail = " ".join(str(exc).split()) or type(exc).__name__
        raise FlowFormatError(f"{path}: not a NumPy .npy array ({detail})") from None
    if not isinstance(arr, np.ndarray):
        raise FlowFormatError(f"{path}: not a NumPy .npy array")
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise FlowFormatError(f"{path}: a flow array has shape (H, W, 2), got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating):
        raise FlowFormatError(f"{path}: a flow array is floating point, got dtype {arr.dtype}")
    h, w = arr.shape[:2]
    if not (0 < h <= MAX_SIDE and 0 < w <= MAX_SIDE):
        raise FlowFormatError(f"{path}: invalid flow size {w} x {h}")
    flow = np.ascontiguousarray(arr, dtype=np.float32)
    flow[~np.isfinite(flow)] = np.nan
    logger.debug("read %s: %d x %d .npy flow", path, w, h)
    return flow


def write_npy_flow(path: str | os.PathLike[str], flow: np.ndarray) -> None:
    """Write a flow as a ``.npy`` file (float32), atomically.

    Parameters
    ----------
    path : str or path-like
        Target; its directory must exist.
    flow : ndarray, shape (H, W, 2)
        Floating point; NaN where unknown is kept as NaN.

    Raises
    ------
    ValueError
        If ``flow`` is not ``(H, W, 2)`` floating point.
    """
    arr = np.ascontiguousarray(flow_to_write(flow, "write_npy_flow"), dtype=np.float32)
    with atomic_write(path) as fh:
        np.save(fh, arr, allow_pickle=False)
