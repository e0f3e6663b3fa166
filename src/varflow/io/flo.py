"""Middlebury ``.flo`` optical-flow files.

Layout (Baker et al., "A Database and Evaluation Methodology for Optical Flow",
IJCV 92(1), 2011; format notes of the Middlebury flow page), all little-endian:

=========  =======  =================================================
offset     type     content
=========  =======  =================================================
0          float32  tag ``202021.25`` (the ASCII bytes ``b"PIEH"``)
4          int32    width ``W``
8          int32    height ``H``
12         float32  ``H * W * 2`` values, row-major, ``(u, v)`` interleaved
=========  =======  =================================================

Unknown flow is stored as ``1e10``; any component with ``|value| > 1e9`` marks the
whole pixel as unknown, which :func:`read_flo` returns as NaN in both components.
:func:`write_flo` writes every unknown pixel (any component NaN, infinite or
``|value| > 1e9``) as ``1e10`` in both components, so that write -> read -> write
reproduces the file byte for byte.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from ._atomic import atomic_write

__all__ = ["FlowFormatError", "read_flo", "write_flo", "FLO_TAG", "UNKNOWN_FLOW", "MAX_SIDE",
           "flow_to_write"]

logger = logging.getLogger(__name__)

#: The 4-byte tag that starts every ``.flo`` file (float32 202021.25, little-endian).
FLO_TAG = np.array([202021.25], dtype="<f4").tobytes()
#: Value written for unknown flow.
UNKNOWN_FLOW = 1e10
#: Components with a magnitude above this are read as unknown.
UNKNOWN_THRESHOLD = 1e9
#: Largest width or height accepted by the readers (guards against garbage headers).
MAX_SIDE = 100_000

_HEADER = 12


class FlowFormatError(ValueError):
    """A flow file is corrupted or not in the expected format."""


def unknown_pixels(flow: np.ndarray) -> np.ndarray:
    """Pixels whose flow is unknown: any component NaN, infinite or ``|value| > 1e9``.

    Parameters
    ----------
    flow : ndarray, shape (H, W, 2)

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(flow) | (np.abs(flow) > UNKNOWN_THRESHOLD)
    return bad.any(axis=-1)


def _check_size(path: Path | str, width: int, height: int) -> None:
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise FlowFormatError(
            f"{path}: invalid size {width} x {height} in header "
            f"(width and height must be in 1..{MAX_SIDE})"
        )


def read_flo(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a Middlebury ``.flo`` file.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    flow : ndarray, shape (H, W, 2), float32
        ``[..., 0]`` = u (horizontal), ``[..., 1]`` = v (vertical); NaN in both
        components where the file marks the flow as unknown (``|value| > 1e9``).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    FlowFormatError
        On a wrong tag, a non-positive or absurd size (> 100000 on a side), a
        truncated file or trailing bytes after the data.

    References
    ----------
    Baker, Scharstein, Lewis, Roth, Black & Szeliski, "A Database and Evaluation
    Methodology for Optical Flow", IJCV 92(1):1-31, 2011.
    """
    path = Path(os.fspath(path))
    if not path.exists():
        raise FileNotFoundError(2, "flow file not found", str(path))
    with open(path, "rb") as f:
        file_size = os.fstat(f.fileno()).st_size
        header = f.read(_HEADER)
        if len(header) < _HEADER:
            raise FlowFormatError(
                f"{path}: truncated .flo header ({len(header)} of {_HEADER} bytes)"
            )
        if header[:4] != FLO_TAG:
            tag = float(np.frombuffer(header[:4], dtype="<f4")[0])
            raise FlowFormatError(
                f"{path}: not a .flo file (tag {header[:4]!r} = {tag!r}, expected 202021.25)"
            )
        width, height = (int(x) for x in np.frombuffer(header[4:12], dtype="<i4"))
        _check_size(path, width, height)
        expected = _HEADER + width * height * 2 * 4
        if file_size < expected:
            raise FlowFormatError(
                f"{path}: truncated .flo data ({file_size} bytes, expected {expected} "
                f"for {width} x {height})"
            )
        if file_size > expected:
            raise FlowFormatError(
                f"{path}: {file_size - expected} unexpected trailing bytes after the "
                f"{width} x {height} flow data"
            )
        payload = f.read(expected - _HEADER)
    if len(payload) != expected - _HEADER:  # file changed while reading
        raise FlowFormatError(f"{path}: truncated .flo data")
    flow = np.frombuffer(payload, dtype="<f4").reshape(height, width, 2).astype(np.float32)
    flow[unknown_pixels(flow)] = np.nan
    logger.debug("read %s: %d x %d flow", path, width, height)
    return flow


def flow_to_write(flow: np.ndarray, writer: str) -> np.ndarray:
    """``flow`` as an array the flow writers take: ``(H, W, 2)`` floating point.

    Parameters
    ----------
    flow : array_like
    writer : str
        The writer's name, at the start of the message.

    Raises
    ------
    ValueError
        ``"<writer>: expected a flow of shape (H, W, 2), got ..."`` or ``"...:
        expected a floating-point flow, got dtype ..."``.
    """
    arr = np.asarray(flow)
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise ValueError(f"{writer}: expected a flow of shape (H, W, 2), got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating):
        raise ValueError(f"{writer}: expected a floating-point flow, got dtype {arr.dtype}")
    return arr


def encode_flo(flow: np.ndarray) -> bytes:
    """Encode a flow field as the bytes of a ``.flo`` file (see :func:`write_flo`)."""
    arr = flow_to_write(flow, "write_flo")
    height, width = arr.shape[:2]
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise ValueError(
            f"write_flo: flow size {width} x {height} out of range (1..{MAX_SIDE} per side)"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        data = arr.astype("<f4")  # float64 beyond float32 range -> inf -> unknown
    data[unknown_pixels(data)] = UNKNOWN_FLOW
    header = FLO_TAG + np.array([width, height], dtype="<i4").tobytes()
    return header + np.ascontiguousarray(data).tobytes()


def write_flo(path: str | os.PathLike[str], flow: np.ndarray) -> None:
    """Write a flow field as a Middlebury ``.flo`` file, atomically.

    Parameters
    ----------
    path : str or path-like
    flow : ndarray, shape (H, W, 2), floating dtype
        ``[..., 0]`` = u, ``[..., 1]`` = v; stored as float32.  Pixels with any
        component NaN, infinite or ``|value| > 1e9`` are written as unknown
        (``1e10`` in both components).

    Raises
    ------
    ValueError
        If the shape is not ``(H, W, 2)`` with ``1 <= H, W <= 100000`` or the dtype
        is not floating point.
    """
    payload = encode_flo(flow)
    with atomic_write(path, "wb") as f:
        f.write(payload)
    logger.debug("wrote %s", path)
