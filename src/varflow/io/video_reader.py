"""Frame-accurate reading of a video: :class:`VideoReader`.

Random access (``read(i)``) seeks to the keyframe before the wanted frame and decodes
forward; streaming (``iter_frames``) decodes each packet at most once.  The method is
described in :mod:`varflow.io.video` (Frame-accurate seeking); the packet index comes
from :mod:`varflow.io.probe`.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import operator
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from .checks import AV_ERRORS, PathLike, av_errors, check_selection, check_video_path, select
from .codecs import output_format
from .probe import PacketIndex, VideoInfo, open_input, probe

__all__ = ["VideoReader"]

logger = logging.getLogger(__name__)


class _Session:
    """An open input container positioned for decoding selected frames."""

    def __init__(self, path: Path, index: PacketIndex, info: VideoInfo) -> None:
        self.path = path
        self.index = index
        self.info = info
        self.out_format = output_format(info.pix_fmt)[0]
        self.container: Any = None
        self.stream: Any = None

    def close(self) -> None:
        if self.container is not None:
            with contextlib.suppress(*AV_ERRORS):
                self.container.close()
        self.container = self.stream = None

    def reopen(self) -> Iterator[Any]:
        """Reopen the file and return its packet iterator from the first packet."""
        self.close()
        self.container, self.stream = open_input(self.path)
        return self.container.demux(self.stream)

    def convert(self, frame: Any, i: int) -> np.ndarray:
        arr = frame.to_ndarray(format=self.out_format)
        if arr.shape != self.info.frame_shape:
            raise ValueError(
                f"{self.path}: frame {i} decodes to shape {arr.shape}, but the video stream "
                f"has frames of shape {self.info.frame_shape}"
            )
        return np.ascontiguousarray(arr, dtype=self.info.dtype)

    def _seek(self, kpos: int | None) -> Iterator[Any]:
        """Packet iterator starting at a keyframe at or before decode position ``kpos``."""
        idx = self.index
        if kpos is None or kpos == 0:
            return self.reopen()
        if self.container is None:
            self.reopen()
        candidates = [int(q) for q in idx.keypos[idx.keypos <= kpos][::-1][:3]]
        for q in candidates:
            ts = idx.dts[q] if idx.dts[q] is not None else idx.pts[q]
            if ts is None or q == 0:
                break
            self.container.seek(int(ts), stream=self.stream, backward=True, any_frame=False)
            self.stream.codec_context.flush_buffers()
            packets = self.container.demux(self.stream)
            first = next((p for p in packets if p.size > 0), None)
            if first is None or first.pts is None:
                continue
            landed = idx.dec_of_pts.get(first.pts)
            if landed is not None and landed <= kpos and idx.key[landed]:
                return itertools.chain([first], packets)
            logger.debug("%s: seek for packet %d landed on packet %s", self.path, kpos, landed)
        return self.reopen()

    def frames(self, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        """Decode the frames ``wanted`` (ascending presentation indices), in order."""
        if not wanted:
            return
        if not self.index.seekable:
            yield from self._sequential(wanted)
            return
        idx = self.index
        w = 0
        target = wanted[0]
        sought = idx.start_packet(target)
        packets = self._seek(sought)
        last_pos = -1
        while True:
            reseek = False
            for packet in packets:
                if packet.pts is not None:
                    last_pos = max(last_pos, idx.dec_of_pts.get(packet.pts, last_pos))
                for frame in packet.decode():
                    f = idx.frame_of_pts.get(frame.pts) if frame.pts is not None else None
                    if f is None or f < target:
                        continue
                    if f > target:
                        raise ValueError(f"{self.path}: frame {target} could not be decoded")
                    yield self.convert(frame, f)
                    w += 1
                    if w == len(wanted):
                        return
                    target = wanted[w]
                kpos = idx.start_packet(target)
                if kpos is not None and kpos > last_pos + 1 and kpos > (sought or 0):
                    sought = kpos  # the next selected frame is GOPs ahead: seek there
                    packets = self._seek(kpos)
                    reseek = True
                    break
            if not reseek:
                raise ValueError(
                    f"{self.path}: frame {target} could not be decoded (the data ends early "
                    "or is damaged)"
                )

    def _sequential(self, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        """Decode from the start and count frames (no usable timestamps)."""
        w = 0
        count = 0
        for packet in self.reopen():
            for frame in packet.decode():
                if count == wanted[w]:
                    yield self.convert(frame, count)
                    w += 1
                    if w == len(wanted):
                        return
                count += 1
        raise ValueError(
            f"{self.path}: frame {wanted[w]} could not be decoded (only {count} frames decode)"
        )


class VideoReader:
    """Frame-accurate reader of the first video stream of a file.

    Parameters
    ----------
    path : str or path-like
        Any file FFmpeg can read.

    Attributes
    ----------
    path : Path
    info : VideoInfo

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If it is not a readable video.  Reading a damaged frame later also raises
        ValueError.

    Notes
    -----
    Frames are RGB ``(H, W, 3)`` ``uint8`` (8-bit colour), RGB ``uint16``
    (higher bit depths, full 0..65535 range) or ``(H, W)`` for grey pixel formats;
    see :attr:`VideoInfo.frame_shape`.  Opening indexes the packets of the file once
    (cached); :meth:`read` then seeks to the keyframe before the wanted frame and
    decodes forward, so random access costs at most one GOP of decoding.  Use
    :meth:`iter_frames` or :meth:`read_range` for sequences: they decode each
    packet at most once.  The reader is not thread-safe.

    Examples
    --------
    >>> with VideoReader("clip.mp4") as video:  # doctest: +SKIP
    ...     last = video.read(len(video) - 1)
    ...     for frame in video.iter_frames(step=5):
    ...         pass
    """

    def __init__(self, path: PathLike) -> None:
        self.path = check_video_path(path)
        self._index, self.info = probe(self.path)
        self._session = _Session(self.path, self._index, self.info)

    def __len__(self) -> int:
        return self.info.n_frames

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        i = self.info
        return (
            f"VideoReader({str(self.path)!r}, {i.n_frames} frames {i.width}x{i.height} "
            f"{i.pix_fmt} {i.codec})"
        )

    def close(self) -> None:
        """Release the decoder (the reader can still be used; it reopens the file)."""
        self._session.close()

    def _selection(self, start: int, stop: int | None, step: int, who: str) -> range:
        check_selection(start, stop, step, None, who=who)
        return select(len(self), start, stop, step, None)

    def _decode(self, session: _Session, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        gen = session.frames(wanted)
        while True:
            with av_errors(self.path, "decode the video"):
                try:
                    frame = next(gen)
                except StopIteration:
                    return
            yield frame

    def read(self, index: int) -> np.ndarray:
        """Decode one frame exactly.

        Parameters
        ----------
        index : int
            Frame index in presentation order; negative values count from the end.

        Returns
        -------
        ndarray, shape (H, W, 3) or (H, W)
            ``uint8`` or ``uint16``.

        Raises
        ------
        IndexError
            If ``index`` is out of range.
        ValueError
            If the frame cannot be decoded (damaged file).
        """
        i = operator.index(index)
        n = len(self)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(f"{self.path}: frame index {index} out of range for {n} frames")
        for frame in self._decode(self._session, [i]):
            return frame
        raise ValueError(f"{self.path}: frame {i} could not be decoded")  # pragma: no cover

    def read_indices(self, indices: Sequence[int]) -> np.ndarray:
        """Decode the frames ``indices`` (ascending, in range) into one array.

        Parameters
        ----------
        indices : sequence of int
            Strictly increasing frame indices.

        Returns
        -------
        ndarray, shape (len(indices), H, W[, 3])
        """
        idx = [operator.index(i) for i in indices]
        if any(b <= a for a, b in zip(idx, idx[1:], strict=False)) or (
            idx and not (0 <= idx[0] and idx[-1] < len(self))
        ):
            raise ValueError(
                f"{self.path}: frame indices must increase strictly within 0..{len(self) - 1}"
            )
        out = np.empty((len(idx), *self.info.frame_shape), dtype=self.info.dtype)
        k = 0
        for k, frame in enumerate(self._decode(self._session, idx), start=1):
            out[k - 1] = frame
        if k != len(idx):  # pragma: no cover - frames() raises first
            raise ValueError(f"{self.path}: only {k} of {len(idx)} frames could be decoded")
        return out

    def read_range(self, start: int, stop: int | None, step: int = 1) -> np.ndarray:
        """Decode the frames ``start:stop:step`` (slice semantics, clipped to the video).

        Parameters
        ----------
        start : int
            First frame (``>= 0``).
        stop : int or None
            End (exclusive); None for the end of the video.
        step : int, default 1

        Returns
        -------
        ndarray, shape (F, H, W, 3) or (F, H, W)
            ``F`` may be 0.
        """
        return self.read_indices(self._selection(start, stop, step, "read_range"))

    def iter_frames(
        self, start: int = 0, stop: int | None = None, step: int = 1
    ) -> Iterator[np.ndarray]:
        """Stream the frames ``start:stop:step`` one by one (bounded memory).

        Parameters
        ----------
        start, stop, step : int
            As in :meth:`read_range`.

        Yields
        ------
        ndarray, shape (H, W, 3) or (H, W)

        Notes
        -----
        The iterator has its own decoder, so :meth:`read` may be called while it is
        in use.  It seeks past GOPs that contain no selected frame.
        """
        wanted = self._selection(start, stop, step, "iter_frames")  # checked before iterating
        return self._stream(wanted)

    def _stream(self, wanted: Sequence[int]) -> Iterator[np.ndarray]:
        session = _Session(self.path, self._index, self.info)
        try:
            yield from self._decode(session, wanted)
        finally:
            session.close()
