"""Input checking and the fixed intensity convention.

Every solver in varflow works on ``float32`` images scaled to ``[0, 1]`` with the
channel axis last, ``(H, W, C)``.  Integer images are scaled by the maximum of
their dtype (``uint8`` by 255, ``uint16`` by 65535); float images must already lie
in ``[0, 1]``.  Keeping the range fixed means a parameter such as the data weight
λ means the same thing for every input type.
"""

from __future__ import annotations

import numpy as np

__all__ = ["as_float_image", "check_flow", "check_pair"]

_FLOAT_TOL = 1e-3


def as_float_image(image: np.ndarray, name: str = "image") -> np.ndarray:
    """Convert an image to ``float32`` in ``[0, 1]`` with shape ``(H, W, C)``.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        ``uint8``, ``uint16``, ``bool`` or floating point.  Float images must lie in
        ``[0, 1]`` and be finite.
    name : str
        Name used in error messages.

    Returns
    -------
    ndarray, shape (H, W, C), float32, C-contiguous

    Raises
    ------
    ValueError
        On a wrong number of dimensions, an empty image, an unsupported dtype,
        non-finite values or floats outside ``[0, 1]``.
    """
    arr = np.asarray(image)
    if arr.ndim not in (2, 3):
        raise ValueError(f"{name}: expected shape (H, W) or (H, W, C), got {arr.shape}")
    if arr.ndim == 2:
        arr = arr[:, :, None]
    h, w, c = arr.shape
    if h < 2 or w < 2 or c < 1:
        raise ValueError(f"{name}: image of shape {arr.shape} is too small (need H, W >= 2)")
    if arr.dtype == np.bool_:
        out = arr.astype(np.float32)
    elif np.issubdtype(arr.dtype, np.unsignedinteger) or np.issubdtype(arr.dtype, np.signedinteger):
        if arr.dtype.itemsize > 2 or np.issubdtype(arr.dtype, np.signedinteger):
            raise ValueError(
                f"{name}: integer dtype {arr.dtype} is ambiguous; pass uint8, uint16 or "
                "float in [0, 1]"
            )
        out = arr.astype(np.float32) / np.float32(np.iinfo(arr.dtype).max)
    elif np.issubdtype(arr.dtype, np.floating):
        out = arr.astype(np.float32, copy=True)
        if not np.all(np.isfinite(out)):
            raise ValueError(f"{name}: contains NaN or infinite values")
        lo, hi = float(out.min()), float(out.max())
        if lo < -_FLOAT_TOL or hi > 1.0 + _FLOAT_TOL:
            raise ValueError(
                f"{name}: float images must be scaled to [0, 1], got range "
                f"[{lo:.4g}, {hi:.4g}] (divide by 255 or pass the uint8 array)"
            )
        np.clip(out, 0.0, 1.0, out=out)
    else:
        raise ValueError(f"{name}: unsupported dtype {arr.dtype}")
    return np.ascontiguousarray(out)


def check_pair(frame0: np.ndarray, frame1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate two frames and convert both with :func:`as_float_image`.

    Returns
    -------
    (ndarray, ndarray)
        Both ``(H, W, C)`` float32 in ``[0, 1]``.

    Raises
    ------
    ValueError
        If the frames differ in shape.
    """
    a = as_float_image(frame0, "frame0")
    b = as_float_image(frame1, "frame1")
    if a.shape != b.shape:
        raise ValueError(f"frame0 and frame1 differ in shape: {a.shape} vs {b.shape}")
    return a, b


def check_flow(flow: np.ndarray, name: str = "flow", allow_nan: bool = True) -> np.ndarray:
    """Check the flow convention: ``(H, W, 2)`` with u = ``[..., 0]``, v = ``[..., 1]``.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    arr = np.asarray(flow)
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise ValueError(f"{name}: expected shape (H, W, 2), got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.floating):
        raise ValueError(f"{name}: expected a floating dtype, got {arr.dtype}")
    arr = arr.astype(np.float32, copy=False)
    if not allow_nan and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return arr
