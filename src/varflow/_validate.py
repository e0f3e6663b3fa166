"""Input checking and the fixed intensity convention.

Every solver in varflow works on ``float32`` images scaled to ``[0, 1]`` with the
channel axis last, ``(H, W, C)``.  Keeping the range fixed means a parameter such
as the data weight λ means the same thing for every input type.  Frames are
brought into that range as follows:

* ``uint8`` / ``uint16`` frames are divided by the maximum of their dtype (255,
  65535); ``bool`` frames become 0 / 1.
* Float frames that already lie in ``[0, 1]`` (up to a tolerance of ``1e-3``,
  clipped) are used as they are.
* Otherwise the float frames of **one call** -- the two frames of a pair, all the
  frames of a track -- are scaled *jointly* from their common range
  ``[min, max]`` to ``[0, 1]``: the same affine map ``(x - min) / (max - min)``
  for every frame, so that brightness constancy between the frames still holds.
  Integer frames of the same call keep their dtype scaling.  A constant input
  (``max == min``) becomes a constant image 0, which gives exactly zero flow.
* NaN or infinite values are a :class:`ValueError` naming the frame
  (``"frame1: contains NaN or infinite values"``).

Consequence: the flow of float frames outside ``[0, 1]`` does not depend on an
affine change of intensity ``a * I + b`` (``a > 0``) applied to all frames, up to
floating-point rounding of the scaled images.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "as_float_frames",
    "as_float_image",
    "check_field",
    "check_flow",
    "check_pair",
    "match_channels",
]

#: Float frames within ``[-_FLOAT_TOL, 1 + _FLOAT_TOL]`` are taken as already in [0, 1].
_FLOAT_TOL = 1e-3


def check_field(cond: bool, field: str, msg: str) -> None:
    """Raise ``ValueError("field: msg")`` unless ``cond`` (the parameter classes' checks)."""
    if not cond:
        raise ValueError(f"{field}: {msg}")


def _as_hwc(image: object, name: str) -> np.ndarray:
    """``image`` as an array of shape ``(H, W, C)`` (a view where possible), checked."""
    arr = np.asarray(image)
    if arr.ndim not in (2, 3):
        raise ValueError(f"{name}: expected shape (H, W) or (H, W, C), got {arr.shape}")
    if arr.ndim == 2:
        arr = arr[:, :, None]
    h, w, c = arr.shape
    if h < 2 or w < 2 or c < 1:
        raise ValueError(f"{name}: image of shape {arr.shape} is too small (need H, W >= 2)")
    return arr


def _convert_fixed(arr: np.ndarray, name: str) -> np.ndarray | None:
    """Integer and bool frames -> float32 in [0, 1]; ``None`` for float frames."""
    if arr.dtype == np.bool_:
        return arr.astype(np.float32)
    if np.issubdtype(arr.dtype, np.integer):
        if arr.dtype.itemsize > 2 or np.issubdtype(arr.dtype, np.signedinteger):
            raise ValueError(
                f"{name}: integer dtype {arr.dtype} is ambiguous; pass uint8, uint16 or float"
            )
        return arr.astype(np.float32) / np.float32(np.iinfo(arr.dtype).max)
    if np.issubdtype(arr.dtype, np.floating):
        return None
    raise ValueError(f"{name}: unsupported dtype {arr.dtype}")


def as_float_frames(frames: Sequence[object], names: Sequence[str]) -> list[np.ndarray]:
    """Convert the frames of one call to ``float32`` in ``[0, 1]``, float frames jointly.

    See the module docstring for the rule.  ``uint8``, ``uint16`` and ``bool`` frames
    and float frames in ``[0, 1]`` are converted on their own: their results do not
    depend on the other frames of the call.

    Parameters
    ----------
    frames : sequence of ndarray, each (H, W) or (H, W, C)
        ``uint8``, ``uint16``, ``bool`` or floating point, finite.
    names : sequence of str
        One name per frame, used in error messages (``"frame0"``, ``"frame 7"``).

    Returns
    -------
    list of ndarray, each (H, W, C) float32, C-contiguous
        Shapes are not compared here.

    Raises
    ------
    ValueError
        On a wrong number of dimensions, a too small image, an unsupported dtype or
        non-finite values; the message starts with the frame's name.
    """
    if len(frames) != len(names):
        raise ValueError(f"as_float_frames: {len(frames)} frames but {len(names)} names")
    arrays = [_as_hwc(f, n) for f, n in zip(frames, names, strict=True)]
    out: list[np.ndarray | None] = [
        _convert_fixed(a, n) for a, n in zip(arrays, names, strict=True)
    ]
    floats = [i for i, o in enumerate(out) if o is None]
    if not floats:
        return [np.ascontiguousarray(o) for o in out]  # type: ignore[arg-type]
    lo = hi = None
    in_range = True
    for i in floats:
        a = arrays[i]
        a_min, a_max = a.min(), a.max()  # NaN propagates to both
        if not (np.isfinite(a_min) and np.isfinite(a_max)):
            raise ValueError(f"{names[i]}: contains NaN or infinite values")
        lo = a_min if lo is None else min(lo, a_min)
        hi = a_max if hi is None else max(hi, a_max)
        # Range test on the float32 values: a frame is in [0, 1] when its float32 cast is.
        with np.errstate(over="ignore"):
            lo32, hi32 = np.float32(a_min), np.float32(a_max)
        if lo32 < -_FLOAT_TOL or hi32 > 1.0 + _FLOAT_TOL:
            in_range = False
    for i in floats:
        out[i] = _unit_range(arrays[i]) if in_range else _scale_jointly(arrays[i], lo, hi)
    return [np.ascontiguousarray(o) for o in out]  # type: ignore[arg-type]


def _unit_range(arr: np.ndarray) -> np.ndarray:
    """A float frame already in [0, 1] (within the tolerance): float32, clipped."""
    f = arr.astype(np.float32, copy=True)
    np.clip(f, 0.0, 1.0, out=f)
    return f


def _scale_jointly(arr: np.ndarray, lo: np.floating, hi: np.floating) -> np.ndarray:
    """``(arr - lo) / (hi - lo)`` as float32 in [0, 1]; 0 where ``hi == lo``.

    Computed in float64 (or the input's wider type) with both terms halved so that
    ``hi - lo`` cannot overflow for ranges near the largest float.
    """
    work = np.result_type(arr.dtype, np.float64)
    half_lo = work.type(lo) * work.type(0.5)
    span = work.type(hi) * work.type(0.5) - half_lo
    if not span > 0:
        return np.zeros(arr.shape, np.float32)
    scaled = arr.astype(work) * work.type(0.5)
    scaled -= half_lo
    scaled /= span
    out = scaled.astype(np.float32)
    np.clip(out, 0.0, 1.0, out=out)
    return out


def as_float_image(image: np.ndarray, name: str = "image") -> np.ndarray:
    """Convert one image to ``float32`` in ``[0, 1]`` with shape ``(H, W, C)``.

    The rule of the module docstring applied to a single frame: a float image
    outside ``[0, 1]`` is scaled from its own range ``[min, max]``.  Use
    :func:`as_float_frames` for frames that must share one intensity map.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        ``uint8``, ``uint16``, ``bool`` or floating point (finite).
    name : str
        Name used in error messages.

    Returns
    -------
    ndarray, shape (H, W, C), float32, C-contiguous

    Raises
    ------
    ValueError
        On a wrong number of dimensions, a too small image, an unsupported dtype
        or non-finite values.
    """
    return as_float_frames([image], [name])[0]


def check_pair(frame0: np.ndarray, frame1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate two frames and convert them jointly with :func:`as_float_frames`.

    Returns
    -------
    (ndarray, ndarray)
        Both ``(H, W, C)`` float32 in ``[0, 1]``.

    Raises
    ------
    ValueError
        If a frame is invalid (named ``frame0`` / ``frame1``) or the frames differ
        in shape.
    """
    a, b = match_channels(as_float_frames([frame0, frame1], ["frame0", "frame1"]),
                          [np.shape(frame0), np.shape(frame1)], ["frame0", "frame1"])
    return a, b


def match_channels(
    frames: Sequence[np.ndarray], shapes: Sequence[tuple[int, ...]], names: Sequence[str]
) -> list[np.ndarray]:
    """Give the grey frames of a call the channel count of its colour frames.

    A grey frame next to colour ones (a ``(H, W)`` scan beside an RGB photo) is
    repeated over the channels: ``(g, g, g)`` has the grey value ``g`` under every
    colour-to-grey weighting that sums to 1, so a grey data term sees the same
    image and a colour one sees a colourless frame.

    Parameters
    ----------
    frames : sequence of ndarray, each (H, W, C) float32
        From :func:`as_float_frames`.
    shapes : sequence of tuple
        The shapes the caller passed, named in the error message.
    names : sequence of str
        One name per frame.

    Returns
    -------
    list of ndarray, each (H, W, C) with one C

    Raises
    ------
    ValueError
        If the frames differ in height or width, or hold two different channel
        counts besides 1 (``"frame0 and frame1 differ in shape: (H, W, 3) vs (H, W, 4)"``,
        with the shapes as passed).
    """
    out = list(frames)
    for i, f in enumerate(out[1:], 1):
        if f.shape[:2] != out[0].shape[:2]:
            raise ValueError(f"{names[0]} and {names[i]} differ in shape: "
                             f"{tuple(shapes[0])} vs {tuple(shapes[i])}")
    colour = [i for i, f in enumerate(out) if f.shape[2] != 1]
    for i in colour[1:]:
        if out[i].shape[2] != out[colour[0]].shape[2]:
            k = colour[0]
            raise ValueError(f"{names[k]} and {names[i]} differ in shape: "
                             f"{tuple(shapes[k])} vs {tuple(shapes[i])}")
    if colour:
        c = out[colour[0]].shape[2]
        out = [np.ascontiguousarray(np.repeat(f, c, axis=2)) if f.shape[2] == 1 else f
               for f in out]
    return out


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
