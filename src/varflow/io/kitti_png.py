"""KITTI optical-flow PNG files, with a minimal 16-bit PNG codec.

KITTI (Geiger, Lenz & Urtasun, CVPR 2012; Menze & Geiger, CVPR 2015) stores flow
as a 16-bit, 3-channel PNG:

* R = u, G = v, with ``value = (uint16 - 2**15) / 64``;
* B = validity flag (valid where ``B > 0``).

Pillow silently reduces 16-bit RGB PNGs to 8 bits and cannot write them, so this
module carries a small PNG codec (ISO/IEC 15948, "PNG Specification, 2nd ed."):
it writes 16-bit, non-interlaced images with filter type 0 in a single ``IDAT``
chunk, and reads 16-bit non-interlaced grey / grey+alpha / RGB / RGBA images with
any of the five filter types, verifying every chunk CRC.
"""

from __future__ import annotations

import logging
import os
import struct
import zlib
from pathlib import Path

import numba as nb
import numpy as np

from ._atomic import atomic_write
from .flo import MAX_SIDE, FlowFormatError, flow_to_write, unknown_pixels

__all__ = ["read_kitti_png", "write_kitti_png", "encode_kitti_png"]

logger = logging.getLogger(__name__)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: PNG colour type -> number of channels (16-bit depth only).
_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}
_COLOUR_TYPE = {c: t for t, c in _CHANNELS.items()}
_ZLIB_LEVEL = 6
#: Largest expansion of a deflate stream (about 1032:1); a header declaring more
#: image data than the compressed bytes can hold is refused before inflating.
_ZLIB_MAX_RATIO = 1032
_KITTI_OFFSET = 2.0**15
_KITTI_SCALE = 64.0


# ----------------------------------------------------------------------------- PNG codec


def _chunk(kind: bytes, body: bytes) -> bytes:
    crc = zlib.crc32(kind + body) & 0xFFFFFFFF
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)


def encode_png16(image: np.ndarray) -> bytes:
    """Encode a ``uint16`` image as a 16-bit, non-interlaced PNG (filter type 0).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C) with C in {1, 2, 3, 4}, uint16
        Grey, grey+alpha, RGB or RGBA.

    Returns
    -------
    bytes
        The complete PNG file; the output is a deterministic function of the input.
    """
    arr = np.asarray(image)
    if arr.dtype != np.uint16:
        raise ValueError(f"encode_png16: expected dtype uint16, got {arr.dtype}")
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3 or arr.shape[2] not in _COLOUR_TYPE:
        raise ValueError(f"encode_png16: expected shape (H, W) or (H, W, 1..4), got {arr.shape}")
    height, width, channels = arr.shape
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise ValueError(f"encode_png16: image size {width} x {height} out of range")
    stride = width * channels * 2
    raw = np.zeros((height, stride + 1), dtype=np.uint8)  # column 0: filter type 0
    raw[:, 1:] = arr.astype(">u2").view(np.uint8).reshape(height, stride)
    ihdr = struct.pack(">IIBBBBB", width, height, 16, _COLOUR_TYPE[channels], 0, 0, 0)
    return b"".join(
        [
            PNG_SIGNATURE,
            _chunk(b"IHDR", ihdr),
            _chunk(b"IDAT", zlib.compress(raw.tobytes(), _ZLIB_LEVEL)),
            _chunk(b"IEND", b""),
        ]
    )


@nb.njit(cache=True)
def _unfilter(raw, height, stride, bpp, out):  # pragma: no cover - compiled
    """Undo PNG scanline filters in place; returns -1 or the row with a bad filter type."""
    for y in range(height):
        base = y * (stride + 1)
        ftype = raw[base]
        if ftype > 4:
            return y
        for x in range(stride):
            cur = np.int32(raw[base + 1 + x])
            a = np.int32(out[y, x - bpp]) if x >= bpp else np.int32(0)
            b = np.int32(out[y - 1, x]) if y > 0 else np.int32(0)
            if ftype == 0:
                val = cur
            elif ftype == 1:
                val = cur + a
            elif ftype == 2:
                val = cur + b
            elif ftype == 3:
                val = cur + (a + b) // 2
            else:
                c = np.int32(out[y - 1, x - bpp]) if (y > 0 and x >= bpp) else np.int32(0)
                p = a + b - c
                pa = abs(p - a)
                pb = abs(p - b)
                pc = abs(p - c)
                if pa <= pb and pa <= pc:
                    pred = a
                elif pb <= pc:
                    pred = b
                else:
                    pred = c
                val = cur + pred
            out[y, x] = np.uint8(val & 0xFF)
    return -1


def decode_png16(data: bytes, path: str | os.PathLike[str] = "<bytes>") -> np.ndarray:
    """Decode a 16-bit, non-interlaced PNG.

    Parameters
    ----------
    data : bytes
        The whole file.
    path : str or path-like
        Used in error messages only.

    Returns
    -------
    ndarray, shape (H, W, C), uint16
        C = 1 (grey), 2 (grey+alpha), 3 (RGB) or 4 (RGBA).

    Raises
    ------
    FlowFormatError
        On a bad signature, a truncated file, a CRC mismatch, a missing or malformed
        ``IHDR``/``IDAT``/``IEND``, an unknown critical chunk, trailing bytes after
        ``IEND``, a corrupt zlib stream, a bad filter type, or an unsupported format
        (bit depth other than 16, palette, interlacing).
    """
    if data[:8] != PNG_SIGNATURE:
        raise FlowFormatError(f"{path}: not a PNG file (bad signature)")
    pos = 8
    n = len(data)
    ihdr: tuple[int, ...] | None = None
    idat: list[bytes] = []
    seen_iend = False
    while pos < n:
        if pos + 8 > n:
            raise FlowFormatError(f"{path}: truncated PNG (incomplete chunk header at {pos})")
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        end = pos + 12 + length
        if length > 0x7FFFFFFF or end > n:
            raise FlowFormatError(f"{path}: truncated PNG (chunk {kind!r} at byte {pos})")
        body = data[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack(">I", data[end - 4 : end])
        if zlib.crc32(kind + body) & 0xFFFFFFFF != crc:
            raise FlowFormatError(f"{path}: CRC mismatch in PNG chunk {kind!r} at byte {pos}")
        if ihdr is None and kind != b"IHDR":
            raise FlowFormatError(f"{path}: PNG does not start with an IHDR chunk")
        pos = end
        if kind == b"IHDR":
            if ihdr is not None or length != 13:
                raise FlowFormatError(f"{path}: malformed or repeated IHDR chunk")
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            seen_iend = True
            break
        elif kind == b"PLTE":
            pass  # optional suggested palette of truecolour images; irrelevant here
        elif not kind[0] & 0x20:  # upper-case first letter: critical chunk
            raise FlowFormatError(f"{path}: unsupported critical PNG chunk {kind!r}")
    if ihdr is None:
        raise FlowFormatError(f"{path}: PNG has no IHDR chunk")
    if not seen_iend:
        raise FlowFormatError(f"{path}: truncated PNG (no IEND chunk)")
    if pos != n:
        raise FlowFormatError(f"{path}: {n - pos} unexpected trailing bytes after PNG IEND")
    width, height, depth, colour, compression, filter_method, interlace = ihdr
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise FlowFormatError(f"{path}: invalid PNG size {width} x {height}")
    if depth != 16 or colour not in _CHANNELS:
        raise FlowFormatError(
            f"{path}: unsupported PNG (bit depth {depth}, colour type {colour}); "
            "need 16-bit grey, grey+alpha, RGB or RGBA"
        )
    if compression != 0 or filter_method != 0:
        raise FlowFormatError(f"{path}: invalid PNG compression/filter method in IHDR")
    if interlace != 0:
        raise FlowFormatError(f"{path}: interlaced PNGs are not supported")
    if not idat:
        raise FlowFormatError(f"{path}: PNG has no IDAT chunk")
    channels = _CHANNELS[colour]
    bpp = 2 * channels
    stride = width * bpp
    expected = height * (stride + 1)
    compressed = b"".join(idat)
    if expected > len(compressed) * _ZLIB_MAX_RATIO + 1024:  # cannot be there: no inflating
        raise FlowFormatError(
            f"{path}: PNG image data truncated ({len(compressed)} compressed bytes cannot hold "
            f"the {expected} bytes of {width} x {height} x {channels} at 16 bits)"
        )
    decomp = zlib.decompressobj()
    try:
        raw = decomp.decompress(compressed, expected + 1)
    except zlib.error as exc:
        raise FlowFormatError(f"{path}: corrupt PNG image data ({exc})") from exc
    if len(raw) != expected or not decomp.eof:
        what = "too long" if len(raw) > expected else "truncated"
        raise FlowFormatError(
            f"{path}: PNG image data {what} (expected {expected} bytes for "
            f"{width} x {height} x {channels} at 16 bits)"
        )
    out = np.empty((height, stride), dtype=np.uint8)
    bad_row = _unfilter(np.frombuffer(raw, dtype=np.uint8), height, stride, bpp, out)
    if bad_row >= 0:
        ftype = raw[bad_row * (stride + 1)]
        raise FlowFormatError(f"{path}: invalid PNG filter type {ftype} in row {bad_row}")
    return out.view(">u2").astype(np.uint16).reshape(height, width, channels)


def _read_bytes(path: Path) -> bytes:
    if not path.exists():
        raise FileNotFoundError(2, "flow file not found", str(path))
    if path.is_dir():
        raise IsADirectoryError(21, "is a folder, not a flow file", str(path))
    return path.read_bytes()


def _png_kind(data: bytes) -> tuple[int, int] | None:
    """``(bit depth, colour type)`` from a PNG's IHDR; None if the bytes are not one."""
    if len(data) < 33 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
        return None
    return data[24], data[25]


def read_png16(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a 16-bit PNG file with :func:`decode_png16`.

    Returns
    -------
    ndarray, shape (H, W, C), uint16

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    FlowFormatError
        See :func:`decode_png16`.
    """
    path = Path(os.fspath(path))
    if not path.exists():
        raise FileNotFoundError(2, "PNG file not found", str(path))
    return decode_png16(path.read_bytes(), path)


# ----------------------------------------------------------------------------- KITTI flow


def read_kitti_png(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a KITTI flow PNG.

    Parameters
    ----------
    path : str or path-like
        16-bit RGB PNG: R = u, G = v as ``(uint16 - 2**15) / 64``, B = valid flag.

    Returns
    -------
    flow : ndarray, shape (H, W, 2), float32
        NaN in both components where ``B == 0``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    FlowFormatError
        If the PNG is corrupted or not a 16-bit RGB image.

    References
    ----------
    Menze & Geiger, "Object Scene Flow for Autonomous Vehicles", CVPR 2015
    (KITTI 2015 development kit).
    """
    path = Path(os.fspath(path))
    data = _read_bytes(path)
    kind = _png_kind(data)
    if kind is not None and kind != (16, 2):
        depth, colour = kind
        channels = {0: "grey", 2: "RGB", 3: "palette", 4: "grey+alpha", 6: "RGBA"}.get(
            colour, f"colour type {colour}")
        raise FlowFormatError(
            f"{path}: not a KITTI flow PNG ({depth}-bit {channels}, a picture?); a KITTI flow "
            "PNG is 16-bit RGB with R = u, G = v, B = valid"
        )
    rgb = decode_png16(data, path)
    flow = (rgb[..., :2].astype(np.float32) - np.float32(_KITTI_OFFSET)) / np.float32(_KITTI_SCALE)
    flow[rgb[..., 2] == 0] = np.nan
    logger.debug("read %s: %d x %d KITTI flow", path, rgb.shape[1], rgb.shape[0])
    return flow


def encode_kitti_png(flow: np.ndarray) -> bytes:
    """Encode a flow field as the bytes of a KITTI flow PNG (see :func:`write_kitti_png`)."""
    arr = flow_to_write(flow, "write_kitti_png")
    invalid = unknown_pixels(arr)
    scaled = np.where(invalid[..., None], 0.0, arr.astype(np.float64))
    coded = np.clip(np.rint(scaled * _KITTI_SCALE + _KITTI_OFFSET), 0, 65535)
    rgb = np.empty(arr.shape[:2] + (3,), dtype=np.uint16)
    rgb[..., :2] = coded
    rgb[..., :2][invalid] = 0
    rgb[..., 2] = ~invalid
    return encode_png16(rgb)


def write_kitti_png(path: str | os.PathLike[str], flow: np.ndarray) -> None:
    """Write a flow field as a KITTI flow PNG, atomically.

    Parameters
    ----------
    path : str or path-like
    flow : ndarray, shape (H, W, 2), floating dtype
        Stored as ``rint(value * 64 + 2**15)`` clipped to ``[0, 65535]`` (values
        outside about ±512 px saturate).  Unknown pixels (any component NaN,
        infinite or ``|value| > 1e9``) get ``R = G = B = 0``; the rest ``B = 1``.

    Raises
    ------
    ValueError
        On a wrong shape or a non-floating dtype.

    Notes
    -----
    Flows on the 1/64-pixel grid within range round-trip exactly, and
    write -> read -> write reproduces the file byte for byte.
    """
    payload = encode_kitti_png(flow)
    with atomic_write(path, "wb") as f:
        f.write(payload)
    logger.debug("wrote %s", path)
