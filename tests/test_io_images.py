"""Tests of image reading/writing and the flow-format dispatchers."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PIL import Image

from varflow.io import read_flow, read_image, write_flow, write_image


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


@pytest.mark.parametrize("ext", [".png", ".ppm", ".bmp", ".tif"])
def test_uint8_rgb_round_trip(tmp_path, rng, ext):
    img = rng.integers(0, 256, size=(9, 13, 3)).astype(np.uint8)
    path = tmp_path / f"rgb{ext}"
    write_image(path, img)
    back = read_image(path)
    assert back.dtype == np.uint8 and back.shape == (9, 13, 3)
    np.testing.assert_array_equal(back, img)


@pytest.mark.parametrize("ext", [".png", ".pgm"])
def test_uint8_grey_round_trip(tmp_path, rng, ext):
    img = rng.integers(0, 256, size=(6, 5)).astype(np.uint8)
    path = tmp_path / f"g{ext}"
    write_image(path, img)
    back = read_image(path)
    assert back.dtype == np.uint8 and back.shape == (6, 5)
    np.testing.assert_array_equal(back, img)


def test_uint16_grey_png_round_trip(tmp_path, rng):
    img = rng.integers(0, 65536, size=(7, 8)).astype(np.uint16)
    img[0, 0] = 65535
    img[0, 1] = 256  # would be lost by an 8-bit path
    path = tmp_path / "g16.png"
    write_image(path, img)
    back = read_image(path)
    assert back.dtype == np.uint16 and back.shape == (7, 8)
    np.testing.assert_array_equal(back, img)
    with Image.open(path) as im:  # a standard 16-bit grey PNG that Pillow understands
        assert im.mode.startswith("I")
        np.testing.assert_array_equal(np.asarray(im).astype(np.uint16), img)


def test_uint16_rgb_png_round_trip(tmp_path, rng):
    img = rng.integers(0, 65536, size=(5, 6, 3)).astype(np.uint16)
    path = tmp_path / "c16.png"
    write_image(path, img)
    back = read_image(path)
    assert back.dtype == np.uint16 and back.shape == (5, 6, 3)
    np.testing.assert_array_equal(back, img)


def test_uint16_rgb_written_by_opencv(tmp_path, rng):
    cv2 = pytest.importorskip("cv2")
    rgb = rng.integers(0, 65536, size=(4, 7, 3)).astype(np.uint16)
    path = tmp_path / "cv16.png"
    assert cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1]))
    np.testing.assert_array_equal(read_image(path), rgb)


def test_rgba_drops_alpha(tmp_path, rng):
    rgba = rng.integers(0, 256, size=(4, 5, 4)).astype(np.uint8)
    path = tmp_path / "a.png"
    Image.fromarray(rgba, "RGBA").save(path)
    back = read_image(path)
    assert back.shape == (4, 5, 3)
    np.testing.assert_array_equal(back, rgba[..., :3])  # not premultiplied


def test_palette_expands_to_rgb(tmp_path):
    pal = Image.new("P", (3, 2))
    pal.putpalette([10, 20, 30, 200, 100, 50] + [0] * (256 * 3 - 6))
    pal.putdata([0, 1, 0, 1, 1, 0])
    path = tmp_path / "p.png"
    pal.save(path)
    back = read_image(path)
    assert back.dtype == np.uint8 and back.shape == (2, 3, 3)
    assert back[0, 0].tolist() == [10, 20, 30]
    assert back[0, 1].tolist() == [200, 100, 50]
    assert back[1, 2].tolist() == [10, 20, 30]


def test_la_becomes_grey_and_bilevel_is_0_255(tmp_path):
    la = np.stack([np.array([[0, 100], [200, 255]], np.uint8), np.full((2, 2), 7, np.uint8)], -1)
    path = tmp_path / "la.png"
    Image.fromarray(la, "LA").save(path)
    back = read_image(path)
    assert back.shape == (2, 2) and back.dtype == np.uint8
    assert back.tolist() == [[0, 100], [200, 255]]
    bilevel = Image.new("1", (2, 1))
    bilevel.putpixel((1, 0), 1)
    path1 = tmp_path / "b.png"
    bilevel.save(path1)
    assert read_image(path1).tolist() == [[0, 255]]


def test_jpeg_round_trip_is_close(tmp_path):
    yy, xx = np.mgrid[0:32, 0:32]
    img = np.stack([xx * 8, yy * 8, (xx + yy) * 4], -1).astype(np.uint8)
    path = tmp_path / "x.jpg"
    write_image(path, img)
    back = read_image(path)
    assert back.shape == img.shape and back.dtype == np.uint8
    assert np.abs(back.astype(int) - img).mean() < 3.0


def test_read_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.png"):
        read_image(tmp_path / "missing.png")
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"this is not an image")
    with pytest.raises(ValueError, match="junk.png"):
        read_image(junk)
    # a corrupted 16-bit PNG goes through our decoder and still gives a ValueError
    good = tmp_path / "g.png"
    write_image(good, np.ones((3, 3, 3), np.uint16))
    data = bytearray(good.read_bytes())
    data[45] ^= 0x55
    bad = tmp_path / "bad16.png"
    bad.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="bad16.png"):
        read_image(bad)


@pytest.mark.parametrize(
    ("name", "array"),
    [
        ("f.png", np.zeros((4, 4), np.float32)),
        ("f.xyz", np.zeros((4, 4), np.uint8)),
        ("f.jpg", np.zeros((4, 4), np.uint16)),
        ("f.tif", np.zeros((4, 4, 3), np.uint16)),
        ("f.png", np.zeros((4, 4, 2), np.uint8)),
        ("f.png", np.zeros((0, 4), np.uint8)),
    ],
)
def test_write_errors_leave_nothing(tmp_path, name, array):
    with pytest.raises(ValueError):
        write_image(tmp_path / name, array)
    assert os.listdir(tmp_path) == []


def test_write_image_replaces_atomically(tmp_path):
    path = tmp_path / "x.png"
    write_image(path, np.zeros((2, 2), np.uint8))
    write_image(path, np.full((3, 3), 9, np.uint8))
    assert read_image(path).tolist() == [[9] * 3] * 3
    assert os.listdir(tmp_path) == ["x.png"]


def test_flow_dispatch(tmp_path):
    f = (np.arange(24, dtype=np.float32).reshape(3, 4, 2) - 10) / 64
    f[1, 1] = np.nan
    for name, magic in [("a.flo", b"PIEH"), ("b.png", b"\x89PNG"), ("c.FLO", b"PIEH")]:
        path = tmp_path / name
        write_flow(path, f)
        assert path.read_bytes()[:4] == magic
        np.testing.assert_array_equal(read_flow(path), f)
    with pytest.raises(ValueError, match=r"unknown flow file extension '\.npz' \(use \.flo, "):
        write_flow(tmp_path / "d.npz", f)
    with pytest.raises(ValueError, match="unknown flow file extension"):
        read_flow(tmp_path / "a.txt")
    assert not (tmp_path / "d.npz").exists()


def test_npy_flow_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(3)
    f = rng.normal(0, 5, (5, 7, 2)).astype(np.float32)
    f[2, 3] = np.nan
    path = tmp_path / "f.npy"
    write_flow(path, f)
    back = read_flow(path)
    assert back.dtype == np.float32 and back.shape == f.shape
    assert back.tobytes() == f.tobytes()  # NaN included, bit for bit
    np.testing.assert_array_equal(np.load(path), f)  # plain NumPy reads it
    np.save(tmp_path / "f64.npy", f.astype(np.float64))
    np.testing.assert_array_equal(read_flow(tmp_path / "f64.npy"), f)


@pytest.mark.parametrize("bad, message", [
    (np.zeros((4, 5), np.float32), r"shape \(H, W, 2\)"),
    (np.zeros((4, 5, 2), np.int16), "floating point"),
    (np.array([{"a": 1}], dtype=object), "not a NumPy .npy array"),
])
def test_npy_flow_bad_arrays(tmp_path, bad, message):
    from varflow.io.flo import FlowFormatError

    path = tmp_path / "bad.npy"
    np.save(path, bad, allow_pickle=True)
    with pytest.raises(FlowFormatError, match=message):
        read_flow(path)
    (tmp_path / "junk.npy").write_bytes(b"not numpy at all")
    with pytest.raises(FlowFormatError, match="not a NumPy .npy array"):
        read_flow(tmp_path / "junk.npy")
    with pytest.raises(ValueError, match="floating-point"):
        write_flow(tmp_path / "out.npy", np.zeros((3, 3, 2), np.int32))
    assert not (tmp_path / "out.npy").exists()
