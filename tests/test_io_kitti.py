"""Tests of the KITTI flow PNG reader/writer and its 16-bit PNG codec."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from varflow.io import FlowFormatError, read_kitti_png, write_kitti_png
from varflow.io.kitti_png import decode_png16, read_png16

SIG = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _paeth(a: int, b: int, c: int) -> int:
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    if pa <= pb and pa <= pc:
        return a
    return b if pb <= pc else c


def _encode_with_filters(img: np.ndarray, filters: list[int], colour: int = 2) -> bytes:
    """Independent reference encoder: 16-bit PNG with a chosen filter type per row."""
    h, w = img.shape[:2]
    rows = img.astype(">u2").reshape(h, -1).view(np.uint8).astype(int)
    bpp = 2 * (img.shape[2] if img.ndim == 3 else 1)
    out = bytearray()
    for y in range(h):
        ft = filters[y]
        out.append(ft)
        for x in range(rows.shape[1]):
            a = rows[y, x - bpp] if x >= bpp else 0
            b = rows[y - 1, x] if y > 0 else 0
            c = rows[y - 1, x - bpp] if (y > 0 and x >= bpp) else 0
            pred = [0, a, b, (a + b) // 2, _paeth(a, b, c)][ft] if ft <= 4 else 0
            out.append((rows[y, x] - pred) % 256)
    ihdr = struct.pack(">IIBBBBB", w, h, 16, colour, 0, 0, 0)
    idat = zlib.compress(bytes(out), 9)
    # split the image data over two IDAT chunks and add an ancillary chunk
    return (
        SIG
        + _chunk(b"IHDR", ihdr)
        + _chunk(b"tEXt", b"Comment\0test")
        + _chunk(b"IDAT", idat[:10])
        + _chunk(b"IDAT", idat[10:])
        + _chunk(b"IEND", b"")
    )


def _grid_flow(h: int = 6, w: int = 9, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    f = (rng.integers(-20000, 20000, size=(h, w, 2)) / 64.0).astype(np.float32)
    f[1, 2] = np.nan
    f[h - 1, 0] = np.nan
    return f


def test_round_trip_exact_on_grid(tmp_path):
    f = _grid_flow()
    path = tmp_path / "f.png"
    write_kitti_png(path, f)
    g = read_kitti_png(path)
    assert g.dtype == np.float32 and g.shape == f.shape
    np.testing.assert_array_equal(g, f)  # exact, NaN at the same places
    assert np.isnan(g).sum() == 4


def test_encoded_channel_values(tmp_path):
    f = np.array([[[1.5, -2.0], [np.nan, 3.0], [0.0, 0.0]]], np.float32)
    path = tmp_path / "f.png"
    write_kitti_png(path, f)
    raw = read_png16(path)
    assert raw.dtype == np.uint16 and raw.shape == (1, 3, 3)
    assert raw[0, 0].tolist() == [32768 + 96, 32768 - 128, 1]
    assert raw[0, 1].tolist() == [0, 0, 0]  # invalid pixel: all zero
    assert raw[0, 2].tolist() == [32768, 32768, 1]


def test_rounding_and_clipping(tmp_path):
    f = np.array([[[1000.0, -1000.0], [0.3 / 64, 0.7 / 64]]], np.float32)
    path = tmp_path / "f.png"
    write_kitti_png(path, f)
    raw = read_png16(path)
    assert raw[0, 0].tolist() == [65535, 0, 1]
    assert raw[0, 1].tolist() == [32768, 32769, 1]
    g = read_kitti_png(path)
    assert g[0, 0].tolist() == [(65535 - 32768) / 64, -512.0]
    assert g[0, 1].tolist() == [0.0, 1 / 64]


def test_write_read_write_bytes_identical(tmp_path):
    rng = np.random.default_rng(3)
    f = rng.normal(scale=30, size=(8, 5, 2))  # off the 1/64 grid, float64
    f[3, 3, 1] = np.nan
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    write_kitti_png(a, f)
    g = read_kitti_png(a)
    np.testing.assert_allclose(g[np.isfinite(g)], f[np.isfinite(g)], atol=0.5 / 64 + 1e-6)
    write_kitti_png(b, g)
    assert a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize("filters", [[0] * 5, [1] * 5, [2] * 5, [3] * 5, [4] * 5, [4, 3, 2, 1, 0]])
def test_decoder_handles_all_filter_types(tmp_path, filters):
    rng = np.random.default_rng(4)
    img = rng.integers(0, 65536, size=(5, 4, 3)).astype(np.uint16)
    img[2] = 65535  # wrap-around in the filter arithmetic
    path = tmp_path / "filt.png"
    path.write_bytes(_encode_with_filters(img, filters))
    np.testing.assert_array_equal(read_png16(path), img)
    flow = read_kitti_png(path)
    valid = img[..., 2] > 0
    np.testing.assert_array_equal(flow[valid, 0], (img[valid, 0].astype(np.float32) - 32768) / 64)
    assert np.isnan(flow[~valid]).all()


def test_decoder_grey_and_rgba():
    rng = np.random.default_rng(5)
    grey = rng.integers(0, 65536, size=(3, 4, 1)).astype(np.uint16)
    rgba = rng.integers(0, 65536, size=(3, 4, 4)).astype(np.uint16)
    np.testing.assert_array_equal(decode_png16(_encode_with_filters(grey, [1, 4, 3], 0)), grey)
    np.testing.assert_array_equal(decode_png16(_encode_with_filters(rgba, [4, 2, 3], 6)), rgba)


def test_interop_with_opencv(tmp_path):
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(6)
    rgb = rng.integers(0, 65536, size=(13, 17, 3)).astype(np.uint16)
    rgb[..., 2] = rng.integers(0, 2, size=(13, 17))
    path = tmp_path / "cv.png"
    assert cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1]))  # OpenCV is BGR
    f = read_kitti_png(path)
    valid = rgb[..., 2] > 0
    expected = (rgb[..., :2].astype(np.float64) - 32768) / 64
    np.testing.assert_array_equal(f[valid], expected[valid])
    assert np.isnan(f[~valid]).all()
    # and OpenCV reads what we write
    ours = tmp_path / "ours.png"
    write_kitti_png(ours, _grid_flow(seed=7))
    back = cv2.imread(str(ours), cv2.IMREAD_UNCHANGED)
    assert back.dtype == np.uint16
    np.testing.assert_array_equal(back[..., ::-1], read_png16(ours))


def _good_png(tmp_path) -> bytes:
    path = tmp_path / "good.png"
    write_kitti_png(path, _grid_flow())
    return path.read_bytes()


def test_bad_crc(tmp_path):
    data = bytearray(_good_png(tmp_path))
    data[8 + 25 + 10] ^= 0xFF  # a byte inside the IDAT payload
    path = tmp_path / "crc.png"
    path.write_bytes(bytes(data))
    with pytest.raises(FlowFormatError, match=r"crc\.png: CRC mismatch in PNG chunk b'IDAT'"):
        read_kitti_png(path)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d[:-20], "truncated PNG"),
        (lambda d: d[:-12], "no IEND"),
        (lambda d: d + b"junk", "trailing bytes"),
        (lambda d: b"\x89PNX" + d[4:], "bad signature"),
        (lambda d: d[:8] + d[33:], "IHDR"),
    ],
)
def test_corrupted_png(tmp_path, mutate, message):
    path = tmp_path / "bad.png"
    path.write_bytes(mutate(_good_png(tmp_path)))
    with pytest.raises(FlowFormatError, match=message) as info:
        read_kitti_png(path)
    assert "bad.png" in str(info.value)


def test_bad_filter_type_and_bad_zlib(tmp_path):
    img = np.ones((3, 2, 3), np.uint16)
    path = tmp_path / "f.png"
    path.write_bytes(_encode_with_filters(img, [0, 7, 0]))
    with pytest.raises(FlowFormatError, match="filter type 7 in row 1"):
        read_kitti_png(path)
    ihdr = struct.pack(">IIBBBBB", 2, 3, 16, 2, 0, 0, 0)
    bad = SIG + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", b"not zlib") + _chunk(b"IEND", b"")
    path.write_bytes(bad)
    with pytest.raises(FlowFormatError, match="corrupt PNG image data"):
        read_kitti_png(path)
    short = zlib.compress(b"\0" * 10)
    path.write_bytes(SIG + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", short) + _chunk(b"IEND", b""))
    with pytest.raises(FlowFormatError, match="truncated"):
        read_kitti_png(path)


def test_wrong_png_kinds(tmp_path):
    path8 = tmp_path / "rgb8.png"
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(path8)
    with pytest.raises(FlowFormatError, match=r"not a KITTI flow PNG \(8-bit RGB, a picture\?\)"):
        read_kitti_png(path8)
    grey = tmp_path / "grey16.png"
    grey.write_bytes(_encode_with_filters(np.ones((2, 2, 1), np.uint16), [0, 0], colour=0))
    with pytest.raises(FlowFormatError, match=r"not a KITTI flow PNG \(16-bit grey"):
        read_kitti_png(grey)


def test_missing_and_invalid_input(tmp_path):
    with pytest.raises(FileNotFoundError, match="none.png"):
        read_kitti_png(tmp_path / "none.png")
    with pytest.raises(ValueError):
        write_kitti_png(tmp_path / "x.png", np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError):
        write_kitti_png(tmp_path / "x.png", np.zeros((3, 3, 2), np.int16))
    assert not (tmp_path / "x.png").exists()
