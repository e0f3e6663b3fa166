"""Tests of frame-sequence reading (varflow.io.video) and trajectory files
(varflow.io.trajectories)."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from varflow.io.images import write_image
from varflow.io.trajectories import TrajectoryFile, read_trajectories, write_trajectories
from varflow.io.video import list_frame_files, read_frames


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


def _smooth_frames(n, h, w):
    """RGB frames with smooth, channel-distinct content (JPEG-friendly), moving right."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    frames = []
    for k in range(n):
        r = 128 + 100 * np.sin((xx - 2 * k) / 9.0)
        g = 40 + 150 * yy / h
        b = 200 - 150 * xx / w
        frames.append(np.stack([r, g, b], axis=-1).round().astype(np.uint8))
    return np.stack(frames)


def _write_avi(path, frames, cv2):
    h, w = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (w, h))
    assert writer.isOpened(), "OpenCV cannot write MJPG/AVI here"
    for frame in frames:
        writer.write(np.ascontiguousarray(frame[..., ::-1]))  # RGB -> BGR
    writer.release()


def test_read_video(tmp_path):
    cv2 = pytest.importorskip("cv2", reason="OpenCV (varflow[bench]) not installed")
    frames = _smooth_frames(7, 48, 64)
    path = tmp_path / "clip.avi"
    _write_avi(path, frames, cv2)
    out = read_frames(path)
    assert out.shape == (7, 48, 64, 3) and out.dtype == np.uint8
    diff = np.abs(out.astype(np.int64) - frames.astype(np.int64))
    assert diff.mean() < 10  # lossy MJPG
    # RGB order: swapping R and B would give a large error on this content.
    swapped = np.abs(out[..., ::-1].astype(np.int64) - frames.astype(np.int64)).mean()
    assert swapped > 30

    sub = read_frames(path, start=1, step=2, max_frames=2)
    assert sub.shape == (2, 48, 64, 3)
    np.testing.assert_array_equal(sub, out[[1, 3]])
    np.testing.assert_array_equal(read_frames(path, start=5, stop=100), out[5:])


def test_video_errors(tmp_path, monkeypatch):
    pytest.importorskip("cv2", reason="OpenCV (varflow[bench]) not installed")
    bad = tmp_path / "broken.avi"
    bad.write_bytes(b"RIFF....AVI garbage" * 20)
    with pytest.raises(ValueError, match=r"broken\.avi"):
        read_frames(bad)


def test_video_without_opencv(tmp_path, monkeypatch):
    path = tmp_path / "clip.mp4"
    path.write_bytes(b"\x00" * 64)
    monkeypatch.setitem(sys.modules, "cv2", None)  # makes `import cv2` raise ImportError
    with pytest.raises(ValueError, match=r"varflow\[bench\]"):
        read_frames(path)


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
