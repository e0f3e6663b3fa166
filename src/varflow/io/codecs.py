"""Codec tables: which files are video, which encoder writes them, with what settings.

The extensions read as video (:data:`VIDEO_EXTENSIONS`) and written
(:data:`VIDEO_WRITE_EXTENSIONS`), the default encoder per extension
(:func:`default_video_codec`), the encoder options that give a quality
(:func:`codec_options`), the pixel formats of the stream and of the NumPy frames on
both sides (:func:`output_format` for decoding; :func:`input_format` and
:func:`default_pix_fmt` for encoding).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path

import av
import numpy as np

from .checks import PathLike

__all__ = [
    "EVEN_SIZE_CODECS",
    "VIDEO_EXTENSIONS",
    "VIDEO_WRITE_EXTENSIONS",
    "chroma_subsampled",
    "codec_options",
    "default_pix_fmt",
    "default_video_codec",
    "has_encoder",
    "input_format",
    "output_format",
]

logger = logging.getLogger(__name__)


#: File extensions :func:`read_frames` decodes as video (lower case, with the dot).
VIDEO_EXTENSIONS: frozenset[str] = frozenset(
    {
        ".mp4", ".m4v", ".avi", ".mov", ".mkv", ".webm", ".mpg", ".mpeg", ".wmv",
        ".flv", ".ogv", ".3gp", ".mts", ".m2ts", ".ts", ".mjpeg", ".mjpg",
    }
)  # fmt: skip

#: Default encoders per output extension, in order of preference (the first one the
#: installed FFmpeg offers is used).
_DEFAULT_CODECS: dict[str, tuple[str, ...]] = {
    ".mp4": ("libx264", "mpeg4"),
    ".m4v": ("libx264", "mpeg4"),
    ".mov": ("libx264", "mpeg4"),
    ".mkv": ("ffv1",),
    ".avi": ("mpeg4", "ffv1"),
    ".webm": ("libvpx-vp9", "libvpx"),
}

#: Extensions :class:`VideoWriter` can write.
VIDEO_WRITE_EXTENSIONS: frozenset[str] = frozenset(_DEFAULT_CODECS)


def output_format(pix_fmt: str) -> tuple[str, int, np.dtype]:
    """``(format passed to to_ndarray, channels, dtype)`` for a stream pixel format."""
    fmt = av.VideoFormat(pix_fmt)
    comps = fmt.components
    bits = max((c.bits for c in comps), default=8)
    grey = not fmt.has_palette and (
        len(comps) == 1 or (len(comps) == 2 and pix_fmt.startswith("ya"))
    )
    deep = bits > 8 and not fmt.has_palette
    if grey:
        return ("gray16le" if deep else "gray"), 1, np.dtype(np.uint16 if deep else np.uint8)
    return ("rgb48le" if deep else "rgb24"), 3, np.dtype(np.uint16 if deep else np.uint8)


def has_encoder(name: str) -> bool:
    """True when the installed FFmpeg has a video encoder called ``name``."""
    try:
        codec = av.codec.Codec(name, "w")
    except Exception:  # noqa: BLE001 - unknown codec names raise various errors
        return False
    return codec.type == "video"


def default_video_codec(path: PathLike) -> str:
    """The encoder :class:`VideoWriter` uses for a file name when none is given.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    str
        ``.mp4``/``.m4v``/``.mov``: ``libx264`` (``mpeg4`` if the installed FFmpeg
        lacks it); ``.mkv``: ``ffv1`` (lossless); ``.avi``: ``mpeg4``; ``.webm``:
        ``libvpx-vp9`` (or ``libvpx``).

    Raises
    ------
    ValueError
        For another extension, or if no encoder for it is installed.
    """
    ext = Path(os.fspath(path)).suffix.lower()
    if ext not in _DEFAULT_CODECS:
        raise ValueError(
            f"{path}: cannot write video with extension {ext!r}; use one of "
            f"{', '.join(sorted(VIDEO_WRITE_EXTENSIONS))}"
        )
    for name in _DEFAULT_CODECS[ext]:
        if has_encoder(name):
            return name
    raise ValueError(
        f"{path}: none of the encoders {', '.join(_DEFAULT_CODECS[ext])} is available in "
        "this FFmpeg build"
    )


_LOSSLESS = frozenset({"ffv1", "ffvhuff", "huffyuv", "utvideo", "png", "rawvideo"})
_CRF_CODECS = frozenset({"libx264", "libx264rgb", "libx265", "libvpx-vp9", "libvpx",
                         "libaom-av1", "libsvtav1"})  # fmt: skip
_QSCALE_CODECS = frozenset({"mpeg4", "mpeg2video", "mpeg1video", "mjpeg", "msmpeg4",
                            "msmpeg4v2"})  # fmt: skip
_DEFAULT_QUALITY = {"libx264": 18, "libx265": 20, "libvpx-vp9": 30, "libvpx": 10}
_DEFAULT_QSCALE = 2
#: Encoders that need even frame sizes with chroma subsampling (odd frames are padded).
EVEN_SIZE_CODECS = frozenset({"libx264", "libx265", "h264_nvenc", "hevc_nvenc"})
#: FFmpeg's FF_QP2LAMBDA: global_quality is a quantiser scale times this.
_QP2LAMBDA = 118


def input_format(grey: bool, deep: bool) -> str:
    """Pixel format of the NumPy frames handed to PyAV."""
    if grey:
        return "gray16le" if deep else "gray"
    return "rgb48le" if deep else "rgb24"


def default_pix_fmt(codec: str, supported: Sequence[str], grey: bool, deep: bool) -> str:
    """The stream pixel format :class:`VideoWriter` picks when none is given.

    Lossless formats for FFV1/FFVHuff (after the input's type), ``yuv420p10le`` for
    deep (``uint16``) input where ``supported`` offers it, else ``yuv420p``, else the
    encoder's first format.
    """
    if codec in ("ffv1", "ffvhuff"):  # lossless: keep every bit and the RGB values
        lossless = {
            (False, False): "bgr0" if codec == "ffv1" else "rgb24",
            (True, False): "gray",
            (False, True): "gbrp16le",
            (True, True): "gray16le",
        }[(grey, deep)]
        if lossless in supported:
            return lossless
    preferred = ["yuv420p10le", "yuv420p"] if deep else ["yuv420p"]
    for fmt in preferred:
        if not supported or fmt in supported:
            return fmt
    return supported[0]


def chroma_subsampled(pix_fmt: str) -> bool:
    """True for a YUV pixel format with subsampled chroma (4:2:0, 4:2:2, NV12, ...)."""
    f = av.VideoFormat(pix_fmt)
    return (
        not f.is_rgb
        and len(f.components) >= 3
        and ("420" in pix_fmt or "422" in pix_fmt or pix_fmt.startswith("nv"))
    )


def codec_options(name: str, quality: int | None) -> dict[str, str]:
    """The encoder options of ``name`` for a ``quality`` (see :class:`VideoWriter`).

    Parameters
    ----------
    name : str
        FFmpeg encoder.
    quality : int or None
        CRF or quantiser scale; None for the encoder's default here.  Ignored (with a
        log message) by lossless encoders and encoders without a quality mapping.

    Returns
    -------
    dict of str to str
    """
    if name in _LOSSLESS:
        if quality is not None:
            logger.info("%s is lossless; quality=%s ignored", name, quality)
        return {"level": "3", "slicecrc": "1"} if name == "ffv1" else {}
    if name in _CRF_CODECS:
        crf = _DEFAULT_QUALITY.get(name, 23) if quality is None else int(quality)
        opts = {"crf": str(crf)}
        if name.startswith("libvpx"):
            opts["b"] = "0"  # constant quality without a bit-rate cap
        return opts
    if name in _QSCALE_CODECS:
        q = _DEFAULT_QSCALE if quality is None else int(quality)
        return {"flags": "+qscale", "global_quality": str(max(1, q) * _QP2LAMBDA)}
    if quality is not None:
        logger.info("quality is not mapped for encoder %s; ignored", name)
    return {}
