"""Reading and writing images and flow files.

Images are returned as NumPy arrays with the bit depth of the file: ``uint8`` or
``uint16`` (``float32`` for 32-bit floating-point TIFFs), shape ``(H, W)`` for grey
and ``(H, W, 3)`` for colour.  Alpha channels are dropped and palettes expanded to
RGB.  Corrupted files raise a one-line :class:`ValueError`; a header declaring a
size the file cannot hold is refused before anything is allocated.  Most formats
are handled by Pillow; 16-bit PNGs go through the PNG codec of :mod:`varflow.io.kitti_png`
because Pillow reduces 16-bit colour PNGs to 8 bits.
"""

from __future__ import annotations

import io
import logging
import os
import struct
import warnings
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from ._atomic import atomic_write
from .flo import read_flo, write_flo
from .kitti_png import PNG_SIGNATURE, decode_png16, encode_png16, read_kitti_png, write_kitti_png
from .npy import read_npy_flow, write_npy_flow

__all__ = ["read_image", "write_image", "read_flow", "write_flow"]

logger = logging.getLogger(__name__)

_16BIT_MODES = ("I;16", "I;16L", "I;16B", "I;16N")
_TO_RGB_MODES = ("P", "PA", "RGBA", "RGBa", "RGBX", "CMYK", "YCbCr", "LAB", "HSV")
_TO_GREY_MODES = ("1", "LA", "La")


def _require_file(path: Path, what: str) -> None:
    if not path.exists():
        raise FileNotFoundError(2, f"{what} not found", str(path))


def _png16_header(head: bytes) -> bool:
    """True if ``head`` starts a non-interlaced 16-bit grey/GA/RGB/RGBA PNG."""
    if len(head) < 33 or head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        return False
    depth, colour, _, _, interlace = struct.unpack(">BBBBB", head[24:29])
    return depth == 16 and colour in (0, 2, 4, 6) and interlace == 0


def _from_pillow(img: Image.Image, path: Path) -> np.ndarray:
    mode = img.mode
    if mode in _TO_RGB_MODES:
        img = img.convert("RGBA" if mode in ("P", "PA") else "RGB").convert("RGB")
    elif mode in _TO_GREY_MODES:
        img = img.convert("L")
    elif mode not in ("L", "RGB", "I", "F", *_16BIT_MODES):
        raise ValueError(f"{path}: unsupported image mode {mode!r}")
    arr = np.array(img)
    if img.mode == "F":  # 32-bit float (TIFF): kept as it is, range and all
        return np.ascontiguousarray(arr, dtype=np.float32)
    if img.mode in _16BIT_MODES:
        return arr.astype(np.uint16)
    if img.mode == "I":  # 32-bit integer: accept if it fits 16 bits
        if arr.size and (arr.min() < 0 or arr.max() > 65535):
            raise ValueError(f"{path}: integer image values outside 0..65535")
        return arr.astype(np.uint16)
    return arr.astype(np.uint8, copy=False)


#: Largest ratio of decoded pixel bytes to file bytes accepted from a header.  No
#: lossless or lossy codec Pillow reads gets near it on real data (deflate stops at
#: about 1032:1, LZW at a few thousand); a header declaring more than this is damaged
#: or hostile and is refused before Pillow allocates the image.
_MAX_EXPANSION = 8192
#: Images below this many decoded bytes are never refused by the expansion test.
_SMALL_IMAGE_BYTES = 64 * 2**20


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _check_declared_size(img: Image.Image, path: Path, file_size: int) -> None:
    """Refuse a header whose declared size the file cannot possibly encode."""
    width, height = img.size
    if width < 1 or height < 1:
        raise ValueError(f"{path}: invalid image size {width} x {height}")
    bands = len(img.getbands())
    declared = width * height * bands * (2 if img.mode in _16BIT_MODES else 1)
    if declared > max(_SMALL_IMAGE_BYTES, file_size * _MAX_EXPANSION):
        raise ValueError(
            f"{path}: header declares a {width} x {height} {img.mode} image, far more "
            f"than a {file_size}-byte file can hold (damaged file?)"
        )


def read_image(path: str | os.PathLike[str]) -> np.ndarray:
    """Read an image file (PNG, JPEG, PPM/PGM, TIFF, BMP, ... via Pillow).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    ndarray
        ``(H, W)`` for grey images (no channel axis), ``(H, W, 3)`` for colour in
        **RGB** channel order (as Pillow, scikit-image and matplotlib; OpenCV's
        ``cv2.imread`` gives BGR).  The dtype of the file is kept, values are not
        rescaled: ``uint8`` for 8-bit files and ``uint16`` for 16-bit files
        (16-bit PNGs, grey or colour, are decoded at full precision); ``float32``
        for 32-bit floating-point grey files (TIFF mode ``F``; any range, NaN kept
        -- see :mod:`varflow._validate` for how flow scales them).  RGBA drops
        alpha, palette images are expanded to RGB, LA drops alpha to L, 1-bit
        images become ``uint8`` 0/255.

    Notes
    -----
    To hand a colour image to OpenCV functions that expect BGR (``cv2.imwrite``,
    ``cv2.imshow``, colour conversions), convert it:
    ``cv2.cvtColor(img, cv2.COLOR_RGB2BGR)`` (and ``cv2.COLOR_BGR2RGB`` for the way
    back, e.g. from ``cv2.imread`` to :func:`varflow.flow`).  Grey ``(H, W)`` arrays
    need no conversion.  The flow itself does not depend on the channel order
    (the default ``tvl1`` averages the channels), but mixing an RGB and a BGR frame
    in one call does.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file cannot be decoded as an image (unknown format, truncated or
        corrupted data, a header declaring a size the file cannot hold) or has an
        unsupported mode.  The message is one line and names the file.
    """
    path = Path(os.fspath(path))
    _require_file(path, "image file")
    with open(path, "rb") as f:
        head = f.read(33)
        file_size = os.fstat(f.fileno()).st_size
    if _png16_header(head):
        try:
            arr = decode_png16(path.read_bytes(), path)
        except ValueError as exc:
            raise ValueError(f"cannot read image: {_one_line(exc)}") from exc
        arr = arr[..., :3] if arr.shape[2] >= 3 else arr[..., 0]
        return np.ascontiguousarray(arr)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as img:
                _check_declared_size(img, path, file_size)
                img.load()
                arr = _from_pillow(img, path)
    except FileNotFoundError:
        raise
    except ValueError as exc:
        if str(path) in str(exc):  # our own message
            raise ValueError(_one_line(exc)) from exc
        raise ValueError(f"{path}: cannot read image ({_one_line(exc)})") from exc
    except Exception as exc:  # noqa: BLE001 - Pillow decoders fail in many ways on bad bytes
        reason = _one_line(exc) or type(exc).__name__
        if not isinstance(exc, UnidentifiedImageError | OSError | SyntaxError):
            reason = f"{type(exc).__name__}: {reason}"
        raise ValueError(f"{path}: cannot read image ({reason})") from exc
    logger.debug("read %s: %s %s", path, arr.shape, arr.dtype)
    return arr


def _pillow_format(path: Path) -> str:
    fmt = Image.registered_extensions().get(path.suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: unknown image extension {path.suffix!r}")
    return fmt


def encode_image(array: np.ndarray, path: str | os.PathLike[str]) -> bytes:
    """Encode an image in the format given by the extension of ``path`` (no file is written)."""
    path = Path(os.fspath(path))
    fmt = _pillow_format(path)
    arr = np.asarray(array)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if arr.ndim not in (2, 3) or arr.size == 0:
        raise ValueError(f"{path}: expected an image of shape (H, W) or (H, W, 3), got {arr.shape}")
    if arr.ndim == 3 and arr.shape[2] not in (3, 4):
        raise ValueError(f"{path}: expected 1, 3 or 4 channels, got {arr.shape[2]}")
    if arr.dtype == np.uint8:
        mode = "L" if arr.ndim == 2 else ("RGB" if arr.shape[2] == 3 else "RGBA")
    elif arr.dtype == np.uint16:
        if arr.ndim == 3:
            if fmt != "PNG":
                raise ValueError(f"{path}: 16-bit colour images can only be written as PNG")
            return encode_png16(arr)
        mode = "I;16"
    else:
        raise ValueError(f"{path}: expected a uint8 or uint16 image, got dtype {arr.dtype}")
    buf = io.BytesIO()
    try:
        raw = arr.astype(arr.dtype.newbyteorder("<")).tobytes()  # I;16 is little-endian
        img = Image.frombytes(mode, (arr.shape[1], arr.shape[0]), raw)
        options = {"quality": 95} if fmt == "JPEG" else {}
        img.save(buf, format=fmt, **options)
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(
            f"{path}: cannot write a {arr.dtype} {mode} image as {fmt} ({exc})"
        ) from exc
    return buf.getvalue()


def write_image(path: str | os.PathLike[str], array: np.ndarray) -> None:
    """Write an image atomically; the format follows the file extension.

    Parameters
    ----------
    path : str or path-like
        ``.png``, ``.jpg``, ``.ppm``, ``.pgm``, ``.tif``, ``.bmp``, ... (any
        extension Pillow can write).
    array : ndarray
        ``uint8`` of shape ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)``, or ``uint16``
        of shape ``(H, W)`` (PNG, TIFF, ...) or ``(H, W, 3|4)`` (PNG only).

    Raises
    ------
    ValueError
        On an unknown extension, an unsupported dtype or shape, or a combination
        the format cannot store (e.g. 16-bit JPEG).
    """
    payload = encode_image(array, path)
    with atomic_write(path, "wb") as f:
        f.write(payload)
    logger.debug("wrote %s", path)


_FLOW_READERS = {".flo": read_flo, ".png": read_kitti_png, ".npy": read_npy_flow}
_FLOW_WRITERS = {".flo": write_flo, ".png": write_kitti_png, ".npy": write_npy_flow}
#: The flow file extensions read and written, as error messages list them.
FLOW_EXTENSIONS = tuple(_FLOW_READERS)


def read_flow(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a flow file, choosing the format from the extension.

    ``.flo`` -> :func:`~varflow.io.flo.read_flo` (Middlebury),
    ``.png`` -> :func:`~varflow.io.kitti_png.read_kitti_png` (KITTI 16-bit PNG),
    ``.npy`` -> :func:`~varflow.io.npy.read_npy_flow` (the NumPy array).

    Returns
    -------
    flow : ndarray, shape (H, W, 2), float32
        NaN where unknown.

    Raises
    ------
    ValueError
        On an unknown extension.
    FileNotFoundError, FlowFormatError
        From the format reader.
    """
    path = Path(os.fspath(path))
    reader = _FLOW_READERS.get(path.suffix.lower())
    if reader is None:
        raise ValueError(f"{path}: unknown flow file extension {path.suffix!r} "
                         "(use .flo, .png or .npy)")
    return reader(path)


def write_flow(path: str | os.PathLike[str], flow: np.ndarray) -> None:
    """Write a flow file atomically, choosing the format from the extension.

    ``.flo`` -> :func:`~varflow.io.flo.write_flo`,
    ``.png`` -> :func:`~varflow.io.kitti_png.write_kitti_png` (a 16-bit PNG that
    image viewers show as a nearly flat picture: use
    :func:`~varflow.viz.flow_to_color` for a picture),
    ``.npy`` -> :func:`~varflow.io.npy.write_npy_flow`.

    Raises
    ------
    ValueError
        On an unknown extension or an invalid flow array.
    """
    path = Path(os.fspath(path))
    writer = _FLOW_WRITERS.get(path.suffix.lower())
    if writer is None:
        raise ValueError(f"{path}: unknown flow file extension {path.suffix!r} "
                         "(use .flo, .png or .npy)")
    writer(path, flow)
