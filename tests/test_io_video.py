"""Tests of frame sequences and video (varflow.io.video, ``varflow video``) and trajectory
files (varflow.io.trajectories)."""

from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest

from varflow.io.images import write_image
from varflow.io.trajectories import TrajectoryFile, read_trajectories, write_trajectories
from varflow.io.video import (
    VideoInfo,
    VideoReader,
    VideoWriter,
    default_video_codec,
    list_frame_files,
    read_frames,
    video_info,
    write_video,
)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(7)


def _write_sequence(directory, frames, stem="frame", ext=".png", first=1):
    paths = []
    for k, frame in enumerate(frames):
        path = directory / f"{stem}{k + first}{ext}"
        write_image(path, frame)
        paths.append(path)
    return paths


@pytest.fixture
def sequence(tmp_path, rng):
    """frame1.png .. frame12.png, RGB uint8, random content (frame k+1 = frames[k])."""
    frames = rng.integers(0, 256, size=(12, 9, 11, 3)).astype(np.uint8)
    paths = _write_sequence(tmp_path, frames)
    return tmp_path, frames, paths


# --------------------------------------------------------------------------- listing


def test_list_frame_files_natural_sort_and_filter(sequence):
    directory, _, paths = sequence
    (directory / "notes.txt").write_text("not a frame")
    (directory / ".hidden.png").write_bytes(b"junk")
    (directory / "sub.png").mkdir()
    listed = list_frame_files(directory)
    assert [p.name for p in listed] == [f"frame{k}.png" for k in range(1, 13)]
    assert listed == paths


def test_list_frame_files_missing_and_not_dir(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope"):
        list_frame_files(tmp_path / "nope")
    f = tmp_path / "a.png"
    f.write_bytes(b"")
    with pytest.raises(NotADirectoryError):
        list_frame_files(f)


# --------------------------------------------------------------------------- image sequences


def test_read_directory_exact_and_natural_order(sequence):
    directory, frames, _ = sequence
    out = read_frames(directory)
    assert out.shape == (12, 9, 11, 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(out, frames)  # frame10 after frame9, not after frame1


def test_read_list_in_given_order(sequence):
    _, frames, paths = sequence
    order = [3, 0, 11, 5]
    out = read_frames([str(paths[i]) for i in order])
    np.testing.assert_array_equal(out, frames[order])
    np.testing.assert_array_equal(read_frames(tuple(paths[:2])), frames[:2])


def test_read_grey_uint16(tmp_path, rng):
    frames = rng.integers(0, 65536, size=(3, 5, 7)).astype(np.uint16)
    _write_sequence(tmp_path, frames)
    out = read_frames(tmp_path)
    assert out.dtype == np.uint16 and out.shape == (3, 5, 7)
    np.testing.assert_array_equal(out, frames)


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"start": 2}, list(range(2, 12))),
        ({"stop": 4}, [0, 1, 2, 3]),
        ({"step": 3}, [0, 3, 6, 9]),
        ({"start": 1, "stop": 10, "step": 4}, [1, 5, 9]),
        ({"step": 2, "max_frames": 3}, [0, 2, 4]),
        ({"start": 10, "stop": 100}, [10, 11]),
    ],
)
def test_frame_selection(sequence, kwargs, expected):
    directory, frames, _ = sequence
    np.testing.assert_array_equal(read_frames(directory, **kwargs), frames[expected])


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"start": -1}, "start"),
        ({"stop": -2}, "stop"),
        ({"step": 0}, "step"),
        ({"step": 1.5}, "step"),
        ({"max_frames": 0}, "max_frames"),
    ],
)
def test_invalid_selection(sequence, kwargs, name):
    with pytest.raises(ValueError, match=name):
        read_frames(sequence[0], **kwargs)


def test_too_few_selected_frames(sequence):
    directory, _, paths = sequence
    with pytest.raises(ValueError, match="at least 2"):
        read_frames(directory, start=11)
    with pytest.raises(ValueError, match="at least 2"):
        read_frames(directory, max_frames=1)
    with pytest.raises(ValueError, match="at least 2"):
        read_frames([paths[0]])


def test_size_mismatch_names_file(tmp_path, rng):
    frames = [rng.integers(0, 256, size=(6, 8, 3)).astype(np.uint8) for _ in range(3)]
    frames[2] = rng.integers(0, 256, size=(6, 9, 3)).astype(np.uint8)
    _write_sequence(tmp_path, frames)
    with pytest.raises(ValueError, match=r"frame3\.png.*\(6, 9, 3\).*\(6, 8, 3\)"):
        read_frames(tmp_path)


def test_dtype_and_channel_mismatch_names_file(tmp_path, rng):
    a = rng.integers(0, 256, size=(4, 4)).astype(np.uint8)
    b = rng.integers(0, 65536, size=(4, 4)).astype(np.uint16)
    c = rng.integers(0, 256, size=(4, 4, 3)).astype(np.uint8)
    write_image(tmp_path / "a.png", a)
    write_image(tmp_path / "b.png", b)
    write_image(tmp_path / "c.png", c)
    with pytest.raises(ValueError, match=r"b\.png.*uint16"):
        read_frames([tmp_path / "a.png", tmp_path / "b.png"])
    with pytest.raises(ValueError, match=r"c\.png"):
        read_frames([tmp_path / "a.png", tmp_path / "c.png"])


def test_corrupted_file_names_file(sequence):
    directory, _, paths = sequence
    data = paths[4].read_bytes()
    paths[4].write_bytes(data[: len(data) // 2])  # truncated PNG
    with pytest.raises(ValueError, match=r"frame5\.png"):
        read_frames(directory)
    paths[4].write_bytes(b"this is not an image at all")
    with pytest.raises(ValueError, match=r"frame5\.png"):
        read_frames(directory)
    # frames outside the selection are not decoded
    assert read_frames(directory, stop=4).shape[0] == 4


def test_missing_and_empty_sources(tmp_path, sequence):
    _, _, paths = sequence
    with pytest.raises(FileNotFoundError, match="missing_dir"):
        read_frames(tmp_path / "missing_dir")
    with pytest.raises(FileNotFoundError, match="ghost"):
        read_frames([paths[0], tmp_path / "ghost.png"])
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "readme.txt").write_text("no frames here")
    with pytest.raises(ValueError, match="no image files"):
        read_frames(empty)
    with pytest.raises(ValueError, match="empty"):
        read_frames([])


def test_bad_source_kinds(sequence, tmp_path):
    _, _, paths = sequence
    with pytest.raises(ValueError, match="single image"):
        read_frames(paths[0])
    other = tmp_path / "data.xyz"
    other.write_bytes(b"123")
    with pytest.raises(ValueError, match="unknown extension"):
        read_frames(other)
    with pytest.raises(TypeError):
        read_frames(42)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- video

H, W = 48, 64


def _index_frames(n: int, h: int = H, w: int = W) -> np.ndarray:
    """RGB frames that carry their index: 16 bits as a 4x4 grid of dark/bright blocks.

    Channels differ (R full, G 3/4, B 1/2 of the block value) so RGB order is checked.
    """
    bh, bw = h // 4, w // 4
    frames = np.empty((n, h, w, 3), np.uint8)
    for k in range(n):
        bits = [(k >> b) & 1 for b in range(16)]
        level = np.kron(np.array(bits).reshape(4, 4), np.ones((bh, bw)))
        value = 40 + 180 * level
        frames[k] = np.stack([value, 0.75 * value, 0.5 * value], axis=-1).round()
    return frames


def _decode_index(frame: np.ndarray) -> int:
    """Inverse of :func:`_index_frames` for a (lossy) decoded frame."""
    h, w = frame.shape[:2]
    red = frame[..., 0].astype(np.float64)
    means = red.reshape(4, h // 4, 4, w // 4).mean(axis=(1, 3)).ravel()
    return int(sum(1 << b for b in range(16) if means[b] > 130))


def _packets(path):
    """(pts, dts, keyframe) of the video packets in decode order, read with plain PyAV."""
    import av

    with av.open(str(path)) as container:
        return [(p.pts, p.dts, p.is_keyframe) for p in container.demux(video=0) if p.size]


def _has_encoder(name: str) -> bool:
    import av

    try:
        av.codec.Codec(name, "w")
    except Exception:  # noqa: BLE001
        return False
    return True


@pytest.mark.parametrize(
    ("shape", "dtype", "pix_fmt"),
    [
        ((H, W, 3), np.uint8, "bgr0"),
        ((H - 1, W - 1, 3), np.uint8, "bgr0"),  # odd sizes
        ((H, W), np.uint8, "gray"),
        ((H - 1, W + 1, 3), np.uint16, "gbrp16le"),
        ((H, W - 3), np.uint16, "gray16le"),
    ],
)
def test_ffv1_lossless_round_trip(tmp_path, rng, shape, dtype, pix_fmt):
    top = np.iinfo(dtype).max + 1
    frames = rng.integers(0, top, size=(7, *shape)).astype(dtype)
    frames[0].flat[:2] = [0, top - 1]  # extremes survive
    path = tmp_path / "clip.mkv"
    assert write_video(path, frames, fps=12.5) == 7
    info = video_info(path)
    assert info == VideoInfo(7, 12.5, shape[0], shape[1], 3 if len(shape) == 3 else 1,
                             np.dtype(dtype), "ffv1", pix_fmt)
    assert info.frame_shape == shape
    out = read_frames(path)
    assert out.dtype == dtype and out.shape == frames.shape
    np.testing.assert_array_equal(out, frames)
    with VideoReader(path) as video:
        assert len(video) == 7
        np.testing.assert_array_equal(video.read(4), frames[4])
        np.testing.assert_array_equal(video.read(-1), frames[6])
    # an iterable of frames (generator) gives the same file content
    gen_path = tmp_path / "gen.mkv"
    write_video(gen_path, (f for f in frames), fps=12.5)
    np.testing.assert_array_equal(read_frames(gen_path), frames)


def _lossy_cases():
    cases = [("clip.mp4", "mpeg4", {"g": "5", "bf": "2"})]
    if _has_encoder("libx264"):
        cases.append(("clip.mp4", "libx264", {"g": "5", "bf": "2"}))
        cases.append(("clip.mkv", "libx264", {"g": "7", "bf": "3", "x264-params": "open-gop=1"}))
    cases.append(("clip.avi", "mpeg4", {"g": "4"}))
    return cases


@pytest.mark.parametrize(("name", "codec", "options"), _lossy_cases())
def test_frame_accurate_seeking_with_b_frames(tmp_path, name, codec, options):
    n = 23
    frames = _index_frames(n)
    path = tmp_path / name
    write_video(path, frames, fps=25, codec=codec, options=options, quality=4 if
                codec == "mpeg4" else 20)
    packets = _packets(path)
    assert len(packets) == n
    assert sum(k for _, _, k in packets) >= 4  # several GOPs
    if "bf" in options:  # B-frames: decode order differs from presentation order
        pts = [p for p, _, _ in packets]
        assert pts != sorted(pts)

    info = video_info(path)
    assert (info.n_frames, info.height, info.width, info.dtype) == (n, H, W, np.uint8)
    with VideoReader(path) as video:
        seq = video.read_range(0, None)
        assert seq.shape == (n, H, W, 3)
        assert [_decode_index(f) for f in seq] == list(range(n))
        assert np.abs(seq.astype(int) - frames).mean() < 6
        order = np.random.default_rng(3).permutation(n).tolist() + [n - 1, 0, n - 1, 5, 5]
        for i in order:
            np.testing.assert_array_equal(video.read(i), seq[i], err_msg=f"frame {i}")
        for start, stop, step in [(0, None, 1), (3, 19, 4), (11, None, 6), (22, 40, 1)]:
            streamed = list(video.iter_frames(start, stop, step))
            ranged = video.read_range(start, stop, step)
            assert len(streamed) == len(ranged) == len(range(n)[start:stop:step])
            np.testing.assert_array_equal(np.stack(streamed), seq[start:stop:step])
            np.testing.assert_array_equal(ranged, seq[start:stop:step])
    np.testing.assert_array_equal(read_frames(path, start=7, stop=13), seq[7:13])
    np.testing.assert_array_equal(read_frames(path, start=2, step=5, max_frames=3),
                                  seq[[2, 7, 12]])


@pytest.mark.parametrize("codec", ["mpeg4", "libx264"])
def test_seeking_when_first_pts_is_not_zero(tmp_path, codec):
    if not _has_encoder(codec):
        pytest.skip(f"{codec} not in this FFmpeg build")
    import av

    n, offset = 18, 37
    frames = _index_frames(n)
    path = tmp_path / "offset.mkv"
    with av.open(str(path), "w") as container:
        stream = container.add_stream(codec, rate=25, options={"g": "4", "bf": "2"})
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        for k, frame in enumerate(frames):
            vf = av.VideoFrame.from_ndarray(frame, format="rgb24")
            vf.pts, vf.time_base = k + offset, Fraction(1, 25)
            container.mux(stream.encode(vf))
        container.mux(stream.encode(None))
    assert min(p for p, _, _ in _packets(path)) > 0
    with VideoReader(path) as video:
        assert len(video) == n
        for i in [n - 1, 9, 0, 4, 13, 1]:
            assert _decode_index(video.read(i)) == i
        assert [_decode_index(f) for f in video.iter_frames(5, None, 3)] == [5, 8, 11, 14, 17]


def test_default_codecs_and_odd_sizes(tmp_path, rng):
    frames = _index_frames(6, 48, 64)[:, :47, :63]  # odd size
    for ext in (".mp4", ".avi", ".mkv", ".webm"):
        try:
            codec = default_video_codec(f"x{ext}")
        except ValueError:
            continue  # no encoder for .webm in this build
        path = tmp_path / f"odd{ext}"
        write_video(path, frames, fps=10)
        info = video_info(path)
        assert info.n_frames == 6 and info.fps == 10.0
        if codec in ("libx264", "libx265"):  # padded to even sizes
            assert (info.height, info.width) == (48, 64)
        else:
            assert (info.height, info.width) == (47, 63)
        out = read_frames(path)
        assert out.shape == (6, *info.frame_shape) and out.dtype == np.uint8
        diff = np.abs(out[:, :47, :63].astype(int) - frames)
        assert diff.mean() < (1e-9 if codec == "ffv1" else 8), (ext, codec)
    assert default_video_codec("a.MKV") == "ffv1"
    with pytest.raises(ValueError, match=r"\.flo"):
        default_video_codec("a.flo")


def test_high_bit_depth_lossy(tmp_path):
    if not _has_encoder("libx264"):
        pytest.skip("libx264 not in this FFmpeg build")
    yy, xx = np.mgrid[0:H, 0:W]
    frame = np.stack([xx * 1000, yy * 1300, (xx + yy) * 500], axis=-1).astype(np.uint16)
    path = tmp_path / "deep.mp4"
    write_video(path, [frame, frame, frame], fps=5)
    info = video_info(path)
    assert info.pix_fmt == "yuv420p10le" and info.dtype == np.uint16 and info.channels == 3
    out = read_frames(path)
    assert out.dtype == np.uint16 and out.shape == (3, H, W, 3)
    assert np.abs(out.astype(float) - frame).mean() < 1500  # 10-bit, chroma subsampled


def test_write_is_atomic(tmp_path):
    frames = _index_frames(6)
    path = tmp_path / "out.mkv"

    def failing(n_ok: int, exc: BaseException):
        yield from frames[:n_ok]
        raise exc

    with pytest.raises(RuntimeError, match="camera unplugged"):
        write_video(path, failing(3, RuntimeError("camera unplugged")))
    assert list(tmp_path.iterdir()) == []  # no target, no temporary file

    write_video(path, frames[:2], fps=5)
    before = path.read_bytes()
    with pytest.raises(KeyboardInterrupt):
        write_video(path, failing(4, KeyboardInterrupt()))
    assert path.read_bytes() == before
    with pytest.raises(ValueError, match="shape"):
        write_video(path, [frames[0], frames[1][:40]])
    with pytest.raises(ValueError, match="no frames"):
        write_video(path, [])
    assert [p.name for p in tmp_path.iterdir()] == ["out.mkv"]
    assert path.read_bytes() == before

    # while writing, only a hidden temporary file with the same extension exists
    with VideoWriter(path, fps=5) as writer:
        writer.write(frames[0])
        temps = [p for p in tmp_path.iterdir() if p.name != "out.mkv"]
        assert len(temps) == 1 and temps[0].name.startswith(".") and temps[0].suffix == ".mkv"
        writer.write(frames[1])
        writer.write(frames[2])
    assert [p.name for p in tmp_path.iterdir()] == ["out.mkv"]
    assert video_info(path).n_frames == 3


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"path": "x.flo"}, "extension"),
        ({"fps": 0}, "fps"),
        ({"fps": float("nan")}, "fps"),
        ({"codec": "no-such-codec"}, "no-such-codec"),
        ({"codec": "mpeg4", "pix_fmt": "rgb48le"}, "pix_fmt"),
        ({"quality": -1}, "quality"),
    ],
)
def test_writer_arguments(tmp_path, kwargs, match):
    args = {"fps": 25.0, **kwargs}
    path = tmp_path / args.pop("path", "x.mp4")
    with pytest.raises(ValueError, match=match):
        VideoWriter(path, **args)
    assert list(tmp_path.iterdir()) == []


def test_writer_frame_checks(tmp_path):
    path = tmp_path / "x.mkv"
    for bad in (np.zeros((8, 8, 3), np.float32), np.zeros((8, 8, 4), np.uint8),
                np.zeros((2, 8, 8, 3), np.uint8)):
        with pytest.raises(ValueError, match="frame"):
            write_video(path, [bad])
    with pytest.raises(ValueError, match="shape"):
        write_video(path, np.zeros((8, 8), np.uint8))
    with pytest.raises(FileNotFoundError):
        VideoWriter(tmp_path / "missing" / "x.mkv")
    assert list(tmp_path.iterdir()) == []


def test_corrupt_truncated_and_missing(tmp_path):
    frames = _index_frames(12)
    good = tmp_path / "good.mp4"
    write_video(good, frames, fps=25, codec="mpeg4", options={"g": "3"})
    data = good.read_bytes()
    bad = tmp_path / "bad.mp4"
    for payload in (b"", b"\x00" * 64, b"not a video at all " * 30, data[:300], data[:40]):
        bad.write_bytes(payload)
        for call in (video_info, read_frames, VideoReader):
            with pytest.raises(ValueError, match=r"bad\.mp4") as exc_info:
                call(bad)
            assert "\n" not in str(exc_info.value)
    for name in ("missing.mp4", "missing.mkv"):
        with pytest.raises(FileNotFoundError, match="missing"):
            video_info(tmp_path / name)
        with pytest.raises(FileNotFoundError, match="missing"):
            read_frames(tmp_path / name)
    with pytest.raises(ValueError, match="directory"):
        video_info(tmp_path)
    # a damaged middle: frames of the right shape or a one-line ValueError, nothing else
    damaged = bytearray(data)
    damaged[len(data) // 3 : len(data) // 3 + 400] = bytes(400)
    bad.write_bytes(bytes(damaged))
    try:
        out = read_frames(bad)
    except ValueError as exc:
        assert "\n" not in str(exc)
    else:
        assert out.shape[1:] == (H, W, 3) and out.dtype == np.uint8


def test_truncated_mkv_keeps_complete_frames(tmp_path, rng):
    frames = rng.integers(0, 256, size=(10, H, W, 3)).astype(np.uint8)
    path = tmp_path / "clip.mkv"
    write_video(path, frames)
    data = path.read_bytes()
    cut = tmp_path / "cut.mkv"
    cut.write_bytes(data[: len(data) * 6 // 10])
    n = video_info(cut).n_frames
    assert 2 <= n < 10
    try:
        out = read_frames(cut)
    except ValueError as exc:  # the last, incomplete frame is damaged
        assert "cut.mkv" in str(exc)
        out = read_frames(cut, stop=n - 1)
    np.testing.assert_array_equal(out, frames[: len(out)])


def test_video_selection_errors(tmp_path):
    path = tmp_path / "clip.mkv"
    write_video(path, _index_frames(5))
    with pytest.raises(ValueError, match="at least 2"):
        read_frames(path, start=4)
    with pytest.raises(ValueError, match="step"):
        read_frames(path, step=0)
    with VideoReader(path) as video:
        with pytest.raises(IndexError):
            video.read(5)
        with pytest.raises(ValueError, match="start"):
            video.read_range(-1, None)
        assert video.read_range(9, None).shape == (0, H, W, 3)
        assert list(video.iter_frames(5)) == []
        with pytest.raises(ValueError, match="step"):
            video.iter_frames(0, None, 0)  # checked when called, not when iterated
        assert "5 frames" in repr(video)


# --------------------------------------------------------------------------- varflow video


def _moving_frames(n: int, h: int = 32, w: int = 40) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([
        np.stack([128 + 80 * np.sin((xx - 1.2 * k) / 4.0), 128 + 70 * np.cos((yy + 0.6 * k) / 5.0),
                  90 + 60 * np.sin((xx + yy - 0.6 * k) / 7.0)], axis=-1).round().astype(np.uint8)
        for k in range(n)
    ])


def run_cli(capsys, *args):
    from varflow.cli import main

    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_video(tmp_path, capsys):
    src = tmp_path / "in.mkv"
    write_video(src, _moving_frames(8), fps=20)
    out = tmp_path / "flow.mp4"
    rc, stdout, err = run_cli(capsys, "video", src, "-o", out, "--method", "tvl1-fast",
                              "--start", 1, "--stride", 2, "-q")
    assert rc == 0, err
    assert err == ""
    info = video_info(out)
    assert info.n_frames == 3  # frames 1, 3, 5, 7 -> 3 pairs
    assert info.fps == 10.0 and (info.height, info.width) == (32, 40)
    assert "3 flows" in stdout and str(out) in stdout and stdout.count("\n") == 1

    sbs = tmp_path / "sbs.mkv"
    rc, stdout, err = run_cli(capsys, "video", src, "-o", sbs, "--method", "tvl1-fast",
                              "--stop", 4, "--layout", "side-by-side", "--max-radius", 2, "-q")
    assert rc == 0, err
    info = video_info(sbs)
    assert info.n_frames == 3 and info.width == 3 * 40 + 2 * 4 and info.height > 32
    panels = read_frames(sbs)
    assert panels.dtype == np.uint8
    assert "colour scale 2.000 px" in stdout

    # the next frame warped back by the flow looks like the frame itself (lossless ffv1)
    warped = tmp_path / "warped.mkv"
    rc, stdout, err = run_cli(capsys, "video", src, "-o", warped, "--method", "tvl1",
                              "--stop", 3, "--layout", "warped", "-q")
    assert rc == 0, err
    back = read_frames(warped).astype(np.float32)
    frames = _moving_frames(8)
    assert back.shape[0] == 2 and back.shape[1:3] == frames.shape[1:3]
    interior = (slice(None), slice(6, -6), slice(6, -6))
    ref = frames[:2].astype(np.float32)
    if ref.ndim == 3:
        ref = np.repeat(ref[..., None], 3, axis=-1)
    aligned = np.abs(back - ref)[interior].mean()
    unaligned = np.abs(read_frames(src)[1:3].astype(np.float32) - frames[:2])[interior].mean()
    assert aligned < 0.5 * unaligned


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["{missing}", "-o", "{out}"], "missing.mp4"),
        (["{junk}", "-o", "{out}"], "junk.mp4"),
        (["{src}", "-o", "{tmp}/flow.gif"], "must end in"),
        (["{src}", "-o", "{out}", "--stride", "0"], "--stride"),
        (["{src}", "-o", "{out}", "--start", "7"], "at least 2"),
        (["{src}", "-o", "{out}", "--method", "nope"], "nope"),
        (["{src}", "-o", "{out}", "--max-radius", "-1"], "--max-radius"),
        (["{src}", "-o", "{out}", "--codec", "no-such-codec"], "no-such-codec"),
    ],
)
def test_cli_video_errors(tmp_path, capsys, args, match):
    src = tmp_path / "in.mkv"
    write_video(src, _moving_frames(8), fps=20)
    (tmp_path / "junk.mp4").write_bytes(b"\x00\x01junk" * 50)
    names = {"missing": tmp_path / "missing.mp4", "junk": tmp_path / "junk.mp4", "src": src,
             "out": tmp_path / "out.mp4", "tmp": tmp_path}
    rc, stdout, err = run_cli(capsys, "video", *[a.format(**names) for a in args], "-q")
    assert rc == 2
    assert stdout == ""
    assert err.startswith("varflow: error: ") and err.count("\n") == 1
    assert "Traceback" not in err
    assert match in err
    assert not (tmp_path / "out.mp4").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.mkv", "junk.mp4"]


# --------------------------------------------------------------------------- trajectories


@pytest.fixture
def traj(rng) -> np.ndarray:
    t = rng.normal(scale=4.0, size=(5, 6, 7, 2)).astype(np.float32)
    t[2] = 0.0
    t[0, 1, 2, :] = np.nan
    t[4, 5, 6, 1] = np.nan
    return t


def test_trajectories_round_trip(tmp_path, traj, rng):
    vis = rng.random((5, 6, 7)) > 0.3
    meta = {
        "method": "rlr",
        "params": {"data_weight": 0.15, "rank": 3, "scale": np.float32(0.5)},
        "frames": [tmp_path / "frame1.png", "frame2.png"],
        "nested": [1, [2, None], True],
    }
    path = tmp_path / "t.npz"
    write_trajectories(path, traj, ref=2, visibility=vis, metadata=meta)
    result = read_trajectories(path)
    assert isinstance(result, TrajectoryFile)
    t, ref, v, m = result
    assert t.dtype == np.float32 and t.shape == (5, 6, 7, 2)
    assert np.array_equal(t, traj, equal_nan=True)
    assert np.array_equal(np.isnan(t), np.isnan(traj))
    assert ref == 2 and isinstance(ref, int)
    assert v.dtype == np.bool_ and np.array_equal(v, vis)
    assert m == {
        "method": "rlr",
        "params": {"data_weight": 0.15, "rank": 3, "scale": 0.5},
        "frames": [str(tmp_path / "frame1.png"), "frame2.png"],
        "nested": [1, [2, None], True],
    }
    # plain NumPy can read it, without pickle
    with np.load(path, allow_pickle=False) as npz:
        assert set(npz.files) == {"trajectories", "ref", "visibility", "metadata"}
        assert json.loads(str(npz["metadata"]))["method"] == "rlr"


def test_trajectories_defaults_and_float64(tmp_path, traj):
    path = tmp_path / "t.npz"
    write_trajectories(path, traj.astype(np.float64), ref=0)
    t, ref, vis, meta = read_trajectories(path)
    assert t.dtype == np.float32 and np.array_equal(t, traj, equal_nan=True)
    assert ref == 0 and vis is None and meta == {}


def test_trajectories_write_is_atomic(tmp_path, traj, monkeypatch):
    path = tmp_path / "t.npz"

    def failing_savez(file, **arrays):
        file.write(b"PK\x03\x04 partial archive")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", failing_savez)
    with pytest.raises(OSError, match="disk full"):
        write_trajectories(path, traj, ref=1)
    assert not path.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary file left behind

    monkeypatch.undo()
    write_trajectories(path, traj, ref=1)
    before = path.read_bytes()
    monkeypatch.setattr(np, "savez_compressed", failing_savez)
    with pytest.raises(OSError, match="disk full"):
        write_trajectories(path, traj * 2, ref=3)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]
    monkeypatch.undo()
    t, ref, _, _ = read_trajectories(path)
    assert ref == 1 and np.array_equal(t, traj, equal_nan=True)


def test_trajectories_truncated_and_corrupted(tmp_path, traj):
    path = tmp_path / "t.npz"
    write_trajectories(path, traj, ref=1, metadata={"a": 1})
    data = path.read_bytes()
    bad = tmp_path / "bad.npz"
    for payload in (data[: len(data) // 2], data[:10], b"", b"not a numpy file" * 8):
        bad.write_bytes(payload)
        with pytest.raises(ValueError, match=r"bad\.npz"):
            read_trajectories(bad)
    corrupted = bytearray(data)
    corrupted[200] ^= 0x5A  # inside the compressed trajectories
    bad.write_bytes(bytes(corrupted))
    with pytest.raises(ValueError, match=r"bad\.npz"):
        read_trajectories(bad)
    with pytest.raises(FileNotFoundError, match="missing"):
        read_trajectories(tmp_path / "missing.npz")


def test_trajectories_wrong_content(tmp_path, traj):
    cases = {
        "flow_only.npz": {"flow": traj},
        "no_ref.npz": {"trajectories": traj},
        "bad_shape.npz": {"trajectories": traj[..., 0], "ref": np.array(0)},
        "int_traj.npz": {"trajectories": np.nan_to_num(traj).astype(np.int32), "ref": np.array(0)},
        "ref_range.npz": {"trajectories": traj, "ref": np.array(5)},
        "ref_float.npz": {"trajectories": traj, "ref": np.array(1.0)},
        "bad_vis.npz": {"trajectories": traj, "ref": np.array(0), "visibility": np.ones(3)},
        "bad_meta.npz": {"trajectories": traj, "ref": np.array(0), "metadata": np.array("{")},
        "meta_list.npz": {"trajectories": traj, "ref": np.array(0), "metadata": np.array("[1]")},
        "pickled.npz": {"trajectories": np.array([{"a": 1}], dtype=object), "ref": np.array(0)},
    }
    for name, arrays in cases.items():
        np.savez(tmp_path / name, **arrays)
        with pytest.raises(ValueError, match=name.replace(".", r"\.")):
            read_trajectories(tmp_path / name)
    np.save(tmp_path / "single.npy", traj)
    with pytest.raises(ValueError, match=r"single\.npy.*npz"):
        read_trajectories(tmp_path / "single.npy")


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"traj": np.zeros((5, 6, 7))}, "traj"),
        ({"traj": np.zeros((5, 6, 7, 3))}, "traj"),
        ({"traj": np.zeros((0, 6, 7, 2))}, "traj"),
        ({"traj": np.zeros((5, 6, 7, 2), dtype=bool)}, "traj"),
        ({"traj": np.zeros((5, 6, 7, 2), dtype=complex)}, "traj"),
        ({"ref": 5}, "ref"),
        ({"ref": -1}, "ref"),
        ({"ref": 1.0}, "ref"),
        ({"visibility": np.ones((5, 6, 6), bool)}, "visibility"),
        ({"visibility": np.full((5, 6, 7), 0.5)}, "visibility"),
        ({"metadata": ["not", "a", "dict"]}, "metadata"),
        ({"metadata": {"f": object()}}, "metadata"),
    ],
)
def test_write_trajectories_validation(tmp_path, traj, kwargs, name):
    args = {"traj": traj, "ref": 2, **kwargs}
    path = tmp_path / "t.npz"
    with pytest.raises(ValueError, match=name):
        write_trajectories(path, args.pop("traj"), **args)
    assert not path.exists()


def test_write_trajectories_extension(tmp_path, traj):
    with pytest.raises(ValueError, match=r"\.npz"):
        write_trajectories(tmp_path / "t.npy", traj, ref=0)
    write_trajectories(tmp_path / "T.NPZ", traj, ref=0)
    assert read_trajectories(tmp_path / "T.NPZ").ref == 0
