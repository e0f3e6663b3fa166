"""Tests of the Middlebury .flo reader/writer and the atomic-write helper."""

from __future__ import annotations

import os

import numpy as np
import pytest

from varflow.io import FlowFormatError, read_flo, write_flo
from varflow.io._atomic import atomic_write


def _raw_flo(u_v: np.ndarray, tag: bytes = b"PIEH", size: tuple[int, int] | None = None) -> bytes:
    """Build .flo bytes by hand, independently of the writer."""
    h, w = u_v.shape[:2]
    if size is not None:
        w, h = size
    return tag + np.array([w, h], "<i4").tobytes() + u_v.astype("<f4").tobytes()


@pytest.fixture
def flow() -> np.ndarray:
    rng = np.random.default_rng(0)
    f = rng.normal(scale=5.0, size=(7, 11, 2)).astype(np.float32)
    f[2, 3] = np.nan
    f[6, 10] = np.nan
    return f


def test_header_and_layout(tmp_path, flow):
    path = tmp_path / "a.flo"
    write_flo(path, flow)
    data = path.read_bytes()
    assert len(data) == 12 + 7 * 11 * 2 * 4
    assert data[:4] == b"PIEH"
    assert np.frombuffer(data[:4], "<f4")[0] == np.float32(202021.25)
    assert np.frombuffer(data[4:12], "<i4").tolist() == [11, 7]
    values = np.frombuffer(data[12:], "<f4").reshape(7, 11, 2)
    # interleaved (u, v), row-major
    assert values[0, 1, 0] == flow[0, 1, 0] and values[0, 1, 1] == flow[0, 1, 1]
    assert values[1, 0, 1] == flow[1, 0, 1]
    # NaN is stored as 1e10 in both components
    assert values[2, 3].tolist() == [np.float32(1e10)] * 2


def test_round_trip_values(tmp_path, flow):
    path = tmp_path / "a.flo"
    write_flo(path, flow)
    back = read_flo(path)
    assert back.dtype == np.float32 and back.shape == (7, 11, 2)
    np.testing.assert_array_equal(back, flow)  # NaN positions compared too
    assert np.isnan(back[2, 3]).all() and np.isnan(back[6, 10]).all()


def test_read_write_read_bytes_identical(tmp_path):
    rng = np.random.default_rng(1)
    vals = rng.normal(size=(4, 5, 2)).astype(np.float32)
    vals[1, 2] = 1e10
    vals[0, 0] = [-0.0, 0.0]
    original = _raw_flo(vals)
    src = tmp_path / "src.flo"
    src.write_bytes(original)
    dst = tmp_path / "dst.flo"
    write_flo(dst, read_flo(src))
    assert dst.read_bytes() == original


def test_write_read_write_bytes_identical(tmp_path):
    rng = np.random.default_rng(2)
    f = rng.normal(size=(5, 6, 2))  # float64 input
    f[0, 0, 0] = np.nan  # only one component unknown
    f[1, 1, 1] = np.inf
    f[2, 2, 0] = -3e9  # beyond the unknown threshold
    a, b = tmp_path / "a.flo", tmp_path / "b.flo"
    write_flo(a, f)
    g = read_flo(a)
    assert np.isnan(g[0, 0]).all() and np.isnan(g[1, 1]).all() and np.isnan(g[2, 2]).all()
    assert np.isfinite(g).sum() == 2 * (30 - 3)
    write_flo(b, g)
    assert a.read_bytes() == b.read_bytes()


def test_large_component_marks_pixel_unknown(tmp_path):
    vals = np.zeros((2, 2, 2), np.float32)
    vals[0, 1] = [5e9, 1.0]
    vals[1, 0] = [2.0, -1e9]  # exactly at the threshold: still known
    path = tmp_path / "u.flo"
    path.write_bytes(_raw_flo(vals))
    f = read_flo(path)
    assert np.isnan(f[0, 1]).all()
    assert f[1, 0].tolist() == [2.0, -1e9]
    assert np.isnan(f).sum() == 2


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d[:8], "truncated .flo header"),
        (lambda d: d[:-1], "truncated .flo data"),
        (lambda d: d[:12], "truncated .flo data"),
        (lambda d: d + b"\0", "trailing"),
        (lambda d: b"PIEX" + d[4:], "not a .flo file"),
        (lambda d: _raw_flo(np.zeros((0, 3, 2))), "invalid size"),
        (lambda d: _raw_flo(np.zeros((2, 3, 2)), size=(3, -2)), "invalid size"),
        (lambda d: _raw_flo(np.zeros((1, 1, 2)), size=(200_000, 1)), "invalid size"),
    ],
)
def test_corrupted_files_raise(tmp_path, mutate, message):
    good = _raw_flo(np.ones((3, 4, 2), np.float32))
    path = tmp_path / "bad.flo"
    path.write_bytes(mutate(good))
    with pytest.raises(FlowFormatError, match=message) as info:
        read_flo(path)
    assert "bad.flo" in str(info.value)
    assert isinstance(info.value, ValueError)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.flo"):
        read_flo(tmp_path / "nope.flo")


@pytest.mark.parametrize(
    "bad",
    [np.zeros((4, 4, 3), np.float32), np.zeros((4, 4), np.float32), np.zeros((4, 4, 2), np.int32)],
)
def test_writer_validates(tmp_path, bad):
    path = tmp_path / "x.flo"
    with pytest.raises(ValueError):
        write_flo(path, bad)
    assert not path.exists()


def test_atomic_write_failure_keeps_target(tmp_path):
    target = tmp_path / "t.bin"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic_write(target) as f:
        f.write(b"partial new content")
        raise RuntimeError("boom")
    assert target.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["t.bin"]  # temp file removed


def test_atomic_write_replaces_and_keeps_mode(tmp_path):
    target = tmp_path / "t.txt"
    target.write_text("old")
    target.chmod(0o600)
    with atomic_write(target, "w") as f:
        f.write("new\n")
    assert target.read_text() == "new\n"
    assert target.stat().st_mode & 0o777 == 0o600
    assert os.listdir(tmp_path) == ["t.txt"]


def test_atomic_write_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        with atomic_write(tmp_path / "missing_dir" / "x.flo"):
            pass
    with pytest.raises(ValueError):
        with atomic_write(tmp_path / "x", "ab"):
            pass


def test_failed_flo_write_keeps_existing_file(tmp_path):
    path = tmp_path / "keep.flo"
    write_flo(path, np.ones((2, 2, 2), np.float32))
    before = path.read_bytes()
    with pytest.raises(ValueError):
        write_flo(path, np.ones((2, 2, 3), np.float32))
    assert path.read_bytes() == before
