"""Frame sequences and video files: reading image sequences, reading and writing video.

Frame arrays are ``(F, H, W, 3)`` for colour (RGB) and ``(F, H, W)`` for grey, with
the dtype of the source (``uint8`` or ``uint16``); no intensity scaling is done here
(see :mod:`varflow._validate` for that).

Image sequences (:func:`read_frames`)
    * A list or tuple of image paths is read in the order given with
      :func:`varflow.io.images.read_image`.
    * A directory contributes every still-image file in it (see
      :data:`IMAGE_EXTENSIONS`; hidden files are ignored) in *natural* order, so that
      ``frame2.png`` comes before ``frame10.png`` (:func:`list_frame_files`).

Video (PyAV, i.e. FFmpeg)
    * :func:`video_info` describes a video; its frame count is exact (packets are
      counted, the container header is not trusted).
    * :class:`VideoReader` gives frame-accurate random access (``read(i)``) and
      streaming (``iter_frames``) with bounded memory.  Frames are RGB ``uint8``
      ``(H, W, 3)`` for 8-bit colour, RGB ``uint16`` for pixel formats with more than
      8 bits per component (``yuv420p10le``, ``rgb48le``, 16-bit FFV1, ...; values
      use the full 0..65535 range), and ``(H, W)`` for grey pixel formats.
    * :class:`VideoWriter` / :func:`write_video` encode ``uint8`` or ``uint16``
      frames atomically (temporary file in the target directory, then
      :func:`os.replace`); ``.mkv`` defaults to lossless FFV1.  With ``audio=PATH``
      the writer also copies the first audio stream of ``PATH`` (remuxed, or
      re-encoded when the container cannot hold its codec).
    * :func:`video_rate` gives a stream's exact rational frame rate and
      :func:`check_video_complete` detects a file cut short (its header promises
      more than is there).

A corrupt, truncated or non-video file raises a one-line :class:`ValueError` (a
missing path :class:`FileNotFoundError`); FFmpeg's own exceptions never escape.

Frame-accurate seeking
----------------------
Opening a video demuxes (without decoding) every packet of its video stream once and
records its presentation timestamp (pts), decode timestamp and keyframe flag; the
result is cached per file (path, size, modification time).  Frame ``i`` is the
packet with the ``i``-th smallest pts.  To read it, the reader picks the last
keyframe that precedes the frame's packet in decode order and is not displayed after
the frame, seeks there (verifying where the demuxer actually landed and falling back
to an earlier keyframe or to the start of the file), and decodes forward until the
decoder outputs the frame with the wanted pts.  This is exact with B-frames, open or
closed GOPs and streams whose first pts is not 0.  Streams without usable
timestamps (missing or repeated pts) are read sequentially from the start.

Modules
-------
This module is the public home of these names; each job lives in its own module:

* :mod:`varflow.io.sequences` — image sequences (frame folders, lists of image
  files) and :func:`read_frames`;
* :mod:`varflow.io.probe` — probing a video: :class:`VideoInfo`, the packet index,
  :func:`video_info`, :func:`video_rate`, :func:`check_video_complete`;
* :mod:`varflow.io.video_reader` — :class:`VideoReader`;
* :mod:`varflow.io.video_writer` — :class:`VideoWriter` and :func:`write_video`;
* :mod:`varflow.io.codecs` — codec tables: the extensions read and written, the
  default encoders (:func:`default_video_codec`), quality settings, pixel formats;
* :mod:`varflow.io.audio` — copying a source's audio into a written video;
* :mod:`varflow.io.checks` — the frame-selection and path checks and FFmpeg's
  errors as one-line messages, shared by all of them.
"""

from __future__ import annotations

from . import codecs as _codecs
from . import sequences as _sequences
from .codecs import default_video_codec
from .probe import VideoInfo, check_video_complete, video_info, video_rate
from .sequences import list_frame_files, read_frames
from .video_reader import VideoReader
from .video_writer import VideoWriter, write_video

# The tables are bound here with their doc comments, which the API reference shows.

#: Still-image formats picked up from a directory (lower case, with the dot): the usual
#: photo/scientific formats, restricted to those the installed Pillow can open.  Formats
#: Pillow registers but that are not frame images (MPEG, EPS, HDF5 stubs, ...) are excluded.
IMAGE_EXTENSIONS: frozenset[str] = _sequences.IMAGE_EXTENSIONS

#: File extensions :func:`read_frames` decodes as video (lower case, with the dot).
VIDEO_EXTENSIONS: frozenset[str] = _codecs.VIDEO_EXTENSIONS

#: Extensions :class:`VideoWriter` can write.
VIDEO_WRITE_EXTENSIONS: frozenset[str] = _codecs.VIDEO_WRITE_EXTENSIONS

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_EXTENSIONS",
    "VIDEO_WRITE_EXTENSIONS",
    "VideoInfo",
    "VideoReader",
    "VideoWriter",
    "default_video_codec",
    "check_video_complete",
    "list_frame_files",
    "read_frames",
    "video_info",
    "video_rate",
    "write_video",
]

