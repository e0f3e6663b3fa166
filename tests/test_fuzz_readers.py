"""Property-based tests of the file readers (everything but video).

Two kinds of property, for ``.flo``, KITTI PNG, trajectory ``.npz``, image files and
:func:`varflow.read_flow`:

* **round trip** -- a file written by the package's own writer from a random array
  reads back exactly, and writing what was read reproduces the file byte for byte
  where the format is deterministic;
* **robustness** -- a mutated file (byte flips, truncation, appended junk, a wrong
  magic, a huge declared size, zip-level damage, pure junk) either reads as a valid
  array of the documented shape and dtype or raises :class:`ValueError` with a
  one-line message; never another exception type, never a hang.

Each reader gets a few hundred derandomised examples; a per-example alarm turns a
hang into a failure.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import struct
import subprocess
import sys
import zipfile
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import varflow
from varflow.io.flo import encode_flo, read_flo, write_flo
from varflow.io.images import encode_image, read_image, write_image
from varflow.io.kitti_png import encode_kitti_png, read_kitti_png
from varflow.io.trajectories import read_trajectories, write_trajectories

# Pillow warns about the damaged metadata it skips (corrupt EXIF, truncated tags).
pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

FUZZ = settings(
    max_examples=300,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
ROUND_TRIP = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
#: Seconds one read may take before it counts as a hang.
HANG_SECONDS = 10


# --------------------------------------------------------------------------- helpers


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


@contextlib.contextmanager
def _no_hang(seconds: int = HANG_SECONDS) -> Iterator[None]:
    def _alarm(signum, frame):  # noqa: ARG001
        raise TimeoutError(f"reader did not finish within {seconds} s")

    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _read_or_value_error(reader: Callable[[Path], object], path: Path) -> object | None:
    """Run ``reader(path)``; return its result, or None after a clean ValueError.

    Any other exception type, a multi-line or empty message, or a hang fails.
    """
    try:
        with _no_hang():
            return reader(path)
    except ValueError as exc:
        msg = str(exc)
        assert msg.strip(), f"empty ValueError message from {reader.__name__}"
        assert "\n" not in msg and "\r" not in msg, f"multi-line message: {msg!r}"
        return None


def _assert_flow(flow: object) -> None:
    assert isinstance(flow, np.ndarray)
    assert flow.ndim == 3 and flow.shape[2] == 2 and min(flow.shape[:2]) >= 1
    assert flow.dtype == np.float32
    assert not np.isinf(flow).any()


def _assert_image(img: object) -> None:
    assert isinstance(img, np.ndarray)
    assert img.ndim in (2, 3) and min(img.shape[:2]) >= 1
    if img.ndim == 3:
        assert img.shape[2] == 3
    assert img.dtype in (np.uint8, np.uint16, np.float32)
    assert img.flags.c_contiguous or img.flags.f_contiguous


@st.composite
def mutated(draw: st.DrawFn, data: bytes, header: int = 16) -> bytes:
    """A damaged copy of ``data``: flips, truncation, junk, wrong magic, splices."""
    kind = draw(
        st.sampled_from(["flip", "truncate", "append", "magic", "splice", "junk", "header"])
    )
    buf = bytearray(data)
    n = len(buf)
    if kind == "flip":
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, n - 1))
            buf[i] ^= draw(st.integers(1, 255))
    elif kind == "truncate":
        del buf[draw(st.integers(0, n - 1)) :]
    elif kind == "append":
        buf += draw(st.binary(min_size=1, max_size=64))
    elif kind == "magic":
        k = draw(st.integers(1, min(8, n)))
        buf[:k] = draw(st.binary(min_size=k, max_size=k))
    elif kind == "splice":
        i = draw(st.integers(0, n))
        j = draw(st.integers(i, min(n, i + 64)))
        buf[i:j] = draw(st.binary(max_size=64))
    elif kind == "header":  # flips confined to the header, where sizes live
        for _ in range(draw(st.integers(1, 4))):
            i = draw(st.integers(0, min(header, n) - 1))
            buf[i] ^= draw(st.integers(1, 255))
    else:
        buf = bytearray(draw(st.binary(max_size=256)))
    return bytes(buf)


def _flows(max_side: int = 9) -> st.SearchStrategy[np.ndarray]:
    shape = st.tuples(st.integers(1, max_side), st.integers(1, max_side), st.just(2))
    return hnp.arrays(np.float32, shape, elements=st.floats(width=32, allow_subnormal=False))


# --------------------------------------------------------------------------- .flo


@ROUND_TRIP
@given(flow=_flows())
def test_flo_round_trip(workdir: Path, flow: np.ndarray) -> None:
    path = workdir / "rt.flo"
    write_flo(path, flow)
    back = read_flo(path)
    _assert_flow(back)
    unknown = ~np.isfinite(flow).all(-1) | (np.abs(flow) > 1e9).any(-1)
    expected = flow.copy()
    expected[unknown] = np.nan
    np.testing.assert_array_equal(back, expected)
    assert encode_flo(back) == path.read_bytes()


_FLO_SAMPLE = encode_flo(np.arange(5 * 7 * 2, dtype=np.float32).reshape(5, 7, 2) / 8)


@FUZZ
@given(data=mutated(_FLO_SAMPLE, header=12))
def test_flo_mutated(workdir: Path, data: bytes) -> None:
    path = workdir / "m.flo"
    path.write_bytes(data)
    out = _read_or_value_error(read_flo, path)
    if out is not None:
        _assert_flow(out)
        assert out.size * 4 + 12 == len(data)


@pytest.mark.parametrize(
    ("width", "height"),
    [(10**9, 10**9), (100_000, 100_000), (2**31 - 1, 1), (-1, 5), (0, 0), (46341, 46341)],
)
def test_flo_huge_declared_size(workdir: Path, width: int, height: int) -> None:
    path = workdir / "huge.flo"
    w32, h32 = (np.array([v], "<i8").astype("<i4")[0] for v in (width, height))
    path.write_bytes(b"PIEH" + struct.pack("<ii", w32, h32) + bytes(64))
    with pytest.raises(ValueError, match="huge.flo"):
        with _no_hang(5):
            read_flo(path)


# --------------------------------------------------------------------------- KITTI PNG


def _kitti_flows() -> st.SearchStrategy[np.ndarray]:
    shape = st.tuples(st.integers(1, 8), st.integers(1, 8), st.just(2))
    ints = hnp.arrays(np.int32, shape, elements=st.integers(-(2**15), 2**15 - 1))
    return ints.map(lambda a: (a / 64.0).astype(np.float32))


@ROUND_TRIP
@given(flow=_kitti_flows(), holes=st.data())
def test_kitti_round_trip(workdir: Path, flow: np.ndarray, holes: st.DataObject) -> None:
    mask = holes.draw(hnp.arrays(np.bool_, flow.shape[:2]))
    flow[mask] = np.nan
    path = workdir / "rt_kitti.png"
    path.write_bytes(encode_kitti_png(flow))
    back = read_kitti_png(path)
    _assert_flow(back)
    np.testing.assert_array_equal(back, flow)
    assert encode_kitti_png(back) == path.read_bytes()
    np.testing.assert_array_equal(varflow.read_flow(path), flow)


_KITTI_SAMPLE = encode_kitti_png(
    (np.arange(6 * 5 * 2, dtype=np.float32).reshape(6, 5, 2) - 30) / 4
)


@FUZZ
@given(data=mutated(_KITTI_SAMPLE, header=33))
def test_kitti_mutated(workdir: Path, data: bytes) -> None:
    path = workdir / "m_kitti.png"
    path.write_bytes(data)
    out = _read_or_value_error(read_kitti_png, path)
    if out is not None:
        _assert_flow(out)


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


@pytest.mark.parametrize("side", [100_000, 2**31 - 1, 2**32 - 1, 0])
@pytest.mark.parametrize("reader", [read_kitti_png, read_image, varflow.read_flow])
def test_png16_huge_declared_size(workdir: Path, side: int, reader) -> None:
    """A valid-CRC 16-bit PNG header declaring an absurd size must not allocate it."""
    ihdr = struct.pack(">IIBBBBB", side, side, 16, 2, 0, 0, 0)
    idat = zlib.compress(bytes(1000))
    data = (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", idat)
            + _png_chunk(b"IEND", b""))
    path = workdir / "huge16.png"
    path.write_bytes(data)
    with pytest.raises(ValueError):
        with _no_hang(5):
            reader(path)


# --------------------------------------------------------------------------- trajectories


@st.composite
def _trajectory_files(draw: st.DrawFn) -> tuple[np.ndarray, int, np.ndarray | None, dict]:
    shape = draw(st.tuples(st.integers(1, 4), st.integers(1, 5), st.integers(1, 5)))
    traj = draw(hnp.arrays(np.float32, shape + (2,),
                           elements=st.floats(width=32, allow_subnormal=False)))
    ref = draw(st.integers(0, shape[0] - 1))
    vis = draw(st.none() | hnp.arrays(np.bool_, shape))
    json_values = st.recursive(
        st.none() | st.booleans() | st.integers(-(2**53), 2**53) | st.text(max_size=8)
        | st.floats(allow_nan=False, allow_infinity=False),
        lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner,
                                                                     max_size=3),
        max_leaves=6,
    )
    meta = draw(st.dictionaries(st.text(max_size=6), json_values, max_size=4))
    return traj, ref, vis, meta


@ROUND_TRIP
@given(content=_trajectory_files())
def test_trajectories_round_trip(workdir: Path, content) -> None:
    traj, ref, vis, meta = content
    path = workdir / "rt.npz"
    write_trajectories(path, traj, ref=ref, visibility=vis, metadata=meta)
    got = read_trajectories(path)
    assert got.trajectories.dtype == np.float32
    np.testing.assert_array_equal(got.trajectories, traj)
    assert got.trajectories.tobytes() == traj.tobytes()  # NaN payloads and -0.0 too
    assert got.ref == ref
    if vis is None:
        assert got.visibility is None
    else:
        np.testing.assert_array_equal(got.visibility, vis)
    assert got.metadata == meta


def _npz_sample() -> bytes:
    buf = io.BytesIO()
    traj = (np.arange(3 * 4 * 5 * 2, dtype=np.float32).reshape(3, 4, 5, 2) - 7) / 3
    vis = (np.arange(3 * 4 * 5).reshape(3, 4, 5) % 3) > 0
    np.savez_compressed(buf, trajectories=traj, ref=np.array(1, np.int64), visibility=vis,
                        metadata=np.array('{"method": "rlr"}'))
    return buf.getvalue()


_NPZ_SAMPLE = _npz_sample()


def _assert_trajectory_file(got) -> None:
    traj, ref, vis, meta = got
    assert isinstance(traj, np.ndarray) and traj.dtype == np.float32
    assert traj.ndim == 4 and traj.shape[3] == 2 and min(traj.shape) >= 1
    assert isinstance(ref, int) and 0 <= ref < traj.shape[0]
    assert vis is None or (vis.dtype == np.bool_ and vis.shape == traj.shape[:3])
    assert isinstance(meta, dict)


@FUZZ
@given(data=mutated(_NPZ_SAMPLE, header=64))
def test_trajectories_mutated(workdir: Path, data: bytes) -> None:
    path = workdir / "m.npz"
    path.write_bytes(data)
    out = _read_or_value_error(read_trajectories, path)
    if out is not None:
        _assert_trajectory_file(out)


def _zip_offsets(data: bytes) -> list[int]:
    """Offsets of the zip structures: local headers, central directory, end record."""
    offsets = []
    for sig in (b"PK\x03\x04", b"PK\x01\x02", b"PK\x05\x06"):
        start = 0
        while (i := data.find(sig, start)) >= 0:
            offsets.append(i)
            start = i + 1
    return offsets


_NPZ_STRUCT = _zip_offsets(_NPZ_SAMPLE)


@FUZZ
@given(
    base=st.sampled_from(_NPZ_STRUCT),
    flips=st.lists(st.tuples(st.integers(0, 45), st.integers(1, 255)), min_size=1, max_size=4),
)
def test_trajectories_zip_structure_damaged(workdir: Path, base: int,
                                           flips: list[tuple[int, int]]) -> None:
    """Flips inside the zip headers: sizes, offsets, methods, flags, names."""
    buf = bytearray(_NPZ_SAMPLE)
    for off, x in flips:
        if base + off < len(buf):
            buf[base + off] ^= x
    path = workdir / "z.npz"
    path.write_bytes(bytes(buf))
    out = _read_or_value_error(read_trajectories, path)
    if out is not None:
        _assert_trajectory_file(out)


@pytest.mark.parametrize("compress", [zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED])
@pytest.mark.parametrize("shape", [(10**9, 10**9, 1, 2), (10**5, 10**5, 10, 2), (2**40, 2)])
def test_trajectories_huge_declared_shape(workdir: Path, shape, compress) -> None:
    """An .npy member whose header declares an absurd shape is refused before allocating."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f4", "fortran_order": False, "shape": shape}
    )
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=compress) as zf:
        zf.writestr("trajectories.npy", header.getvalue() + bytes(4096))
        ref = io.BytesIO()
        np.save(ref, np.array(0, np.int64))
        zf.writestr("ref.npy", ref.getvalue())
    path = workdir / "huge.npz"
    path.write_bytes(buf.getvalue())
    with pytest.raises(ValueError, match="huge.npz"):
        with _no_hang(5):
            read_trajectories(path)


def test_trajectories_deeply_nested_metadata(workdir: Path) -> None:
    buf = io.BytesIO()
    np.savez_compressed(buf, trajectories=np.zeros((2, 2, 2, 2), np.float32),
                        ref=np.array(0, np.int64), metadata=np.array("[" * 100_000))
    path = workdir / "deep.npz"
    path.write_bytes(buf.getvalue())
    with pytest.raises(ValueError, match="metadata"):
        read_trajectories(path)


@pytest.mark.parametrize(
    "payload",
    [b"", b"PK\x05\x06" + bytes(18), b"\x93NUMPY", np.lib.format.MAGIC_PREFIX + b"\x01\x00"],
)
def test_trajectories_junk(workdir: Path, payload: bytes) -> None:
    path = workdir / "junk.npz"
    path.write_bytes(payload)
    assert _read_or_value_error(read_trajectories, path) is None


# --------------------------------------------------------------------------- images

_LOSSLESS = [".png", ".bmp", ".ppm", ".tif", ".tga"]


@st.composite
def _images(draw: st.DrawFn) -> tuple[np.ndarray, str]:
    ext = draw(st.sampled_from(_LOSSLESS + [".pgm", ".jpg"]))
    h, w = draw(st.integers(1, 9)), draw(st.integers(1, 9))
    grey = ext == ".pgm" or draw(st.booleans())
    shape = (h, w) if grey else (h, w, 3)
    deep = ext in (".png", ".tif") and draw(st.booleans()) and (grey or ext == ".png")
    dtype = np.uint16 if deep else np.uint8
    if ext == ".ppm" and grey:
        ext = ".pgm"
    if ext == ".pgm" and not grey:
        ext = ".ppm"
    return draw(hnp.arrays(dtype, shape)), ext


@ROUND_TRIP
@given(case=_images())
def test_image_round_trip(workdir: Path, case: tuple[np.ndarray, str]) -> None:
    img, ext = case
    path = workdir / f"rt{ext}"
    write_image(path, img)
    back = read_image(path)
    _assert_image(back)
    assert back.shape == img.shape and back.dtype == img.dtype
    if ext != ".jpg":
        np.testing.assert_array_equal(back, img)
        assert encode_image(back, path) == path.read_bytes()


def _image_sample(ext: str, dtype=np.uint8, colour: bool = True) -> bytes:
    rng = np.random.default_rng(1)
    shape = (7, 9, 3) if colour else (7, 9)
    img = rng.integers(0, np.iinfo(dtype).max, size=shape, endpoint=True).astype(dtype)
    return encode_image(img, f"x{ext}")


_IMAGE_SAMPLES = {
    "png8": (".png", _image_sample(".png")),
    "png16": (".png", _image_sample(".png", np.uint16)),
    "png16grey": (".png", _image_sample(".png", np.uint16, colour=False)),
    "jpg": (".jpg", _image_sample(".jpg")),
    "tif": (".tif", _image_sample(".tif")),
    "tif16": (".tif", _image_sample(".tif", np.uint16, colour=False)),
    "bmp": (".bmp", _image_sample(".bmp")),
    "ppm": (".ppm", _image_sample(".ppm")),
    "pgm": (".pgm", _image_sample(".pgm", colour=False)),
    "gif": (".gif", _image_sample(".gif")),
}


@FUZZ
@given(data=st.data(), key=st.sampled_from(sorted(_IMAGE_SAMPLES)))
def test_image_mutated(workdir: Path, data: st.DataObject, key: str) -> None:
    ext, sample = _IMAGE_SAMPLES[key]
    payload = data.draw(mutated(sample, header=40))
    path = workdir / f"m{ext}"
    path.write_bytes(payload)
    out = _read_or_value_error(read_image, path)
    if out is not None:
        _assert_image(out)


@pytest.mark.parametrize(
    "payload",
    [
        b"P6\n100000 100000\n255\n" + bytes(64),
        b"P5\n13000 13000\n255\n" + bytes(64),
        b"P5\n9000 9000\n65535\n" + bytes(64),
        b"BM" + bytes(16) + struct.pack("<ii", 40000, 40000) + bytes(64),
        b"\x89PNG\r\n\x1a\n"
        + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", 60000, 60000, 8, 2, 0, 0, 0))
        + _png_chunk(b"IDAT", zlib.compress(bytes(4000)))
        + _png_chunk(b"IEND", b""),
    ],
)
def test_image_huge_declared_size(workdir: Path, payload: bytes) -> None:
    path = workdir / ("huge.png" if payload.startswith(b"\x89PNG") else "huge.ppm")
    path.write_bytes(payload)
    with pytest.raises(ValueError):
        with _no_hang(5):
            read_image(path)


def test_float_tiff_is_read_as_float32(workdir: Path) -> None:
    from PIL import Image

    arr = np.linspace(-2.0, 300.0, 35, dtype=np.float32).reshape(5, 7)
    path = workdir / "f.tif"
    Image.fromarray(arr, mode="F").save(path)
    back = read_image(path)
    assert back.dtype == np.float32 and back.shape == (5, 7)
    np.testing.assert_array_equal(back, arr)


# --------------------------------------------------------------------------- read_flow


_FLOW_SAMPLES = {".flo": _FLO_SAMPLE, ".png": _KITTI_SAMPLE}


@FUZZ
@given(data=st.data(), ext=st.sampled_from([".flo", ".png", ".FLO", ".txt"]))
def test_read_flow_mutated(workdir: Path, data: st.DataObject, ext: str) -> None:
    sample = _FLOW_SAMPLES.get(ext.lower(), _FLO_SAMPLE)
    payload = data.draw(mutated(sample, header=33))
    path = workdir / f"rf{ext}"
    path.write_bytes(payload)
    out = _read_or_value_error(varflow.read_flow, path)
    if out is not None:
        assert ext.lower() in _FLOW_SAMPLES
        _assert_flow(out)


@ROUND_TRIP
@given(flow=_kitti_flows(), ext=st.sampled_from([".flo", ".png"]))
def test_read_flow_round_trip(workdir: Path, flow: np.ndarray, ext: str) -> None:
    path = workdir / f"rtf{ext}"
    varflow.write_flow(path, flow)
    np.testing.assert_array_equal(varflow.read_flow(path), flow)


# --------------------------------------------------------------------------- CLI


_BAD_FLO = [
    _FLO_SAMPLE[:30],
    b"PIEH" + struct.pack("<ii", 10**9, 10**9),
    b"junk\n\x00\xff",
    _FLO_SAMPLE + b"x",
    b"",
]


@pytest.mark.parametrize("payload", _BAD_FLO)
def test_cli_show_bad_flo(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                          payload: bytes) -> None:
    from varflow.cli import main

    bad = tmp_path / "BAD.flo"
    bad.write_bytes(payload)
    out = tmp_path / "out.png"
    assert main(["show", str(bad), "-o", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("varflow: error: ") and "BAD.flo" in lines[0]
    assert "Traceback" not in captured.err
    assert captured.out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["BAD.flo"]  # no out.png, no temp


def test_cli_show_bad_flo_process(tmp_path: Path) -> None:
    """The real command: exit status 2, one stderr line, no traceback, no output file."""
    bad = tmp_path / "BAD.flo"
    bad.write_bytes(b"PIEH" + struct.pack("<ii", 10**9, 10**9))
    out = tmp_path / "out.png"
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    proc = subprocess.run(
        [sys.executable, "-m", "varflow.cli", "show", str(bad), "-o", str(out)],
        capture_output=True, text=True, timeout=120, env=env,
    )
    assert proc.returncode == 2
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("varflow: error: ") and "BAD.flo" in lines[0]
    assert not out.exists()
