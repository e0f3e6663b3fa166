"""Copying the audio of a source file into a video being written: :class:`AudioCopy`.

The first audio stream of the source is remuxed when the output container can hold
its codec, else decoded and re-encoded; :class:`~varflow.io.video_writer.VideoWriter`
interleaves it with the video by time (``audio=PATH``).
"""

from __future__ import annotations

import contextlib
import logging
from fractions import Fraction
from pathlib import Path
from typing import Any

import av

from .checks import AV_ERRORS, av_errors

__all__ = ["AudioCopy"]

logger = logging.getLogger(__name__)


#: Audio encoders tried, in order, when a container cannot hold the source's codec
#: (after the container's own default).
_AUDIO_ENCODERS = ("aac", "libopus", "libvorbis", "libmp3lame", "flac")


class AudioCopy:
    """The first audio stream of a file, copied into an output container by time."""

    def __init__(self, source: Path, container: Any, target: Path) -> None:
        self.source = source
        self.mode: str | None = None
        self.codec: str | None = None
        self._src: Any = None
        self._pending: Any = None
        self._container = container
        with av_errors(source, "read the audio"):
            self._src = av.open(str(source), "r", metadata_errors="replace")
            if not self._src.streams.audio:
                logger.info("%s: no audio stream; %s gets none", source, target)
                self.close()
                return
            ain = self._src.streams.audio[0]
            offset = 0.0
            if self._src.streams.video:
                v = self._src.streams.video[0]
                if v.start_time is not None and v.time_base is not None:
                    offset = float(v.start_time * v.time_base)
            self._offset = offset
            self._in = ain
            name = ain.codec_context.name
            supported = container.supported_codecs
            if name in supported:
                self.out = container.add_stream_from_template(ain)
                self.mode, self.codec = "copy", name
            else:
                encoder = self._encoder(container, supported)
                if encoder is None:
                    self.close()
                    raise ValueError(
                        f"{target}: the container cannot hold the {name} audio of {source}, "
                        "and no encoder for an audio codec it accepts is installed; write "
                        "a .mkv, or leave the audio out"
                    )
                layout = {1: "mono", 2: "stereo"}.get(ain.channels, ain.layout.name)
                self.out = container.add_stream(encoder, rate=ain.sample_rate, layout=layout)
                self.mode, self.codec = "encode", encoder
                logger.info("%s: %s audio re-encoded as %s (the container cannot hold %s)",
                            target, name, encoder, name)
            self._packets = self._src.demux(ain)

    @staticmethod
    def _encoder(container: Any, supported: Any) -> str | None:
        for name in (container.default_audio_codec, *_AUDIO_ENCODERS):
            if not name or name not in supported:
                continue
            try:
                codec = av.codec.Codec(name, "w")
            except Exception:  # noqa: BLE001 - unknown codec names raise various errors
                continue
            if codec.type == "audio" and not codec.experimental:
                return name
        return None

    def _time(self, packet: Any) -> float | None:
        ts = packet.pts if packet.pts is not None else packet.dts
        if ts is None or packet.time_base is None:
            return None
        return float(ts * packet.time_base) - self._offset

    def _emit(self, packet: Any, container: Any) -> None:
        if self.mode == "copy":
            if packet.size == 0:
                return
            if self._offset:
                shift = round(self._offset / packet.time_base)
                if packet.pts is not None:
                    packet.pts -= shift
                if packet.dts is not None:
                    packet.dts -= shift
            packet.stream = self.out
            container.mux(packet)
            return
        for frame in packet.decode():
            t = float(frame.pts * frame.time_base) - self._offset if frame.pts is not None else None
            if t is not None:
                frame.pts = round(t * frame.sample_rate)
                frame.time_base = Fraction(1, frame.sample_rate)
            for out in self.out.encode(frame):
                container.mux(out)

    def mux_until(self, seconds: float | None) -> None:
        """Mux the source's audio packets that start before ``seconds`` (None: all)."""
        if self._src is None:
            return
        container = self._container
        with av_errors(self.source, "copy the audio"):
            while True:
                packet = self._pending
                self._pending = None
                if packet is None:
                    packet = next(self._packets, None)
                    if packet is None:
                        return
                t = self._time(packet)
                if seconds is not None and t is not None and t >= seconds and packet.size:
                    self._pending = packet
                    return
                self._emit(packet, container)

    def finish(self) -> None:
        """Mux the rest of the audio and flush the encoder, then close the source."""
        if self._src is None:
            return
        self.mux_until(None)
        if self.mode == "encode":
            with av_errors(self.source, "copy the audio"):
                for out in self.out.encode(None):
                    self._container.mux(out)
        self.close()

    def close(self) -> None:
        if self._src is not None:
            with contextlib.suppress(*AV_ERRORS):
                self._src.close()
        self._src = None
