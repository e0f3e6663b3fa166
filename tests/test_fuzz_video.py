"""Property-based robustness of video reading against damaged files (hypothesis).

Small valid videos (FFV1/Matroska, MPEG-4 with B-frames in MP4, MPEG-4/AVI) are
damaged (random byte flips, truncation at a random offset, inserted junk, pure junk)
and must either decode to frames of the shape and dtype :func:`video_info` reports,
or raise a one-line ``ValueError`` -- never another exception, never a hang or a
crash.

FFmpeg runs inside a separate worker process: a C-level hang or crash cannot be
caught in-process (a signal-based alarm only fires between Python bytecodes), so the
worker is killed after a per-example wall-clock limit, and its death (e.g. a
segfault) is reported as a failure instead of killing the test run.
"""

from __future__ import annotations

import json
import select
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from varflow.io.video import write_video

#: Per-example wall-clock limit of the worker (s); a valid 10-frame clip takes ~10 ms.
TIME_LIMIT = 20.0

_WORKER = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    from varflow.io.video import VideoReader, read_frames, video_info

    def check(path):
        info = video_info(path)
        shape = info.frame_shape
        assert info.n_frames >= 1 and info.dtype in (np.uint8, np.uint16), info
        with VideoReader(path) as video:
            last = video.read(len(video) - 1)
            assert last.shape == shape and last.dtype == info.dtype, (last.shape, info)
            for frame in video.iter_frames(0, None, 3):
                assert frame.shape == shape and frame.dtype == info.dtype
        if info.n_frames >= 2:
            frames = read_frames(path, start=info.n_frames // 2 - 1)
            assert frames.shape[1:] == shape and frames.dtype == info.dtype
        return info.n_frames

    print("ready", flush=True)
    for line in sys.stdin:
        path = line.rstrip("\\n")
        try:
            res = {"kind": "ok", "n": check(path)}
        except ValueError as exc:
            res = {"kind": "ValueError", "msg": str(exc)}
        except BaseException as exc:  # reported to the test, which fails
            res = {"kind": type(exc).__name__, "msg": repr(exc)}
        print(json.dumps(res), flush=True)
    """
)


class _Worker:
    """A persistent Python process that checks one file per request."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen[str] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", _WORKER],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        assert self._readline(60.0) == "ready"

    def _readline(self, timeout: float) -> str | None:
        assert self.proc is not None and self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            return None
        return self.proc.stdout.readline().strip()

    def check(self, path: Path) -> dict:
        if self.proc is None or self.proc.poll() is not None:
            self.start()
        assert self.proc is not None and self.proc.stdin is not None
        self.proc.stdin.write(f"{path}\n")
        self.proc.stdin.flush()
        line = self._readline(TIME_LIMIT)
        if line is None:  # hang: kill it, restart for the next example
            self.stop()
            return {"kind": "timeout", "msg": f"no answer within {TIME_LIMIT} s"}
        if not line:  # EOF: the worker died (e.g. a segfault in FFmpeg)
            code = self.proc.wait()
            self.proc = None
            return {"kind": "crash", "msg": f"worker exit status {code}"}
        return json.loads(line)

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            self.proc = None


@pytest.fixture(scope="module")
def worker():
    w = _Worker()
    w.start()
    yield w
    w.stop()


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> dict[str, bytes]:
    """Valid 10-frame 32x48 videos: FFV1/MKV, MPEG-4 with B-frames/MP4, MPEG-4/AVI."""
    rng = np.random.default_rng(2024)
    directory = tmp_path_factory.mktemp("seeds")
    yy, xx = np.mgrid[0:32, 0:48]
    frames = np.stack(
        [np.stack([(xx * 5 + 9 * k) % 256, (yy * 7 + 4 * k) % 256,
                   rng.integers(0, 256, size=(32, 48))], axis=-1).astype(np.uint8)
         for k in range(10)]
    )  # fmt: skip
    out = {}
    for name, kwargs in [
        ("clip.mkv", {}),
        ("clip.mp4", {"codec": "mpeg4", "options": {"g": "4", "bf": "2"}}),
        ("clip.avi", {"options": {"g": "3"}}),
    ]:
        path = directory / name
        write_video(path, frames, fps=10, **kwargs)
        out[name] = path.read_bytes()
    grey16 = (rng.integers(0, 65536, size=(4, 16, 24))).astype(np.uint16)
    write_video(directory / "grey16.mkv", grey16)
    out["grey16.mkv"] = (directory / "grey16.mkv").read_bytes()
    return out


def test_worker_accepts_valid_seeds(worker, seeds, tmp_path):
    for name, data in seeds.items():
        path = tmp_path / name
        path.write_bytes(data)
        res = worker.check(path)
        assert res == {"kind": "ok", "n": 4 if name == "grey16.mkv" else 10}, name


@st.composite
def damaged(draw, seeds: dict[str, bytes]) -> tuple[str, bytes]:
    name = draw(st.sampled_from(sorted(seeds)))
    data = bytearray(seeds[name])
    kind = draw(st.sampled_from(["flip", "truncate", "junk", "only-junk"]))
    if kind == "flip":
        for _ in range(draw(st.integers(1, 24))):
            pos = draw(st.integers(0, len(data) - 1))
            data[pos] = draw(st.integers(0, 255))
    elif kind == "truncate":
        data = data[: draw(st.integers(0, len(data) - 1))]
    elif kind == "junk":
        pos = draw(st.integers(0, len(data)))
        size = draw(st.integers(0, 64))
        data[pos : pos + size] = draw(st.binary(min_size=1, max_size=512))
    else:
        data = bytearray(draw(st.binary(min_size=0, max_size=2048)))
    return name, bytes(data)


_counter = iter(range(10**9))


def test_damaged_videos_give_frames_or_valueerror(worker, seeds, tmp_path):
    directory = tmp_path / "fuzz"
    directory.mkdir()

    @settings(max_examples=300, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(case=damaged(seeds))
    def check(case: tuple[str, bytes]) -> None:
        name, data = case
        path = directory / f"{next(_counter)}_{name}"  # new name: no stale cache entry
        path.write_bytes(data)
        try:
            res = worker.check(path)
        finally:
            path.unlink()
        assert res["kind"] in ("ok", "ValueError"), res
        if res["kind"] == "ValueError":
            assert "\n" not in res["msg"] and res["msg"], res

    check()
