"""Tests of the Middlebury colour coding."""

from __future__ import annotations

import numpy as np
import pytest

from varflow.viz import color_wheel, color_wheel_legend, flow_to_color, flow_to_color_with_legend


def _one(u: float, v: float, **kw) -> list[int]:
    return flow_to_color(np.array([[[u, v]]], np.float32), **kw)[0, 0].tolist()


def test_wheel_segments():
    wheel = color_wheel()
    assert wheel.shape == (55, 3) and wheel.dtype == np.uint8
    # primary / secondary colours start each segment: RY=15, YG=6, GC=4, CB=11, BM=13, MR=6
    starts = {0: (255, 0, 0), 15: (255, 255, 0), 21: (0, 255, 0), 25: (0, 255, 255),
              36: (0, 0, 255), 49: (255, 0, 255)}  # fmt: skip
    for k, rgb in starts.items():
        assert tuple(wheel[k]) == rgb
    assert wheel[14].tolist() == [255, 238, 0]  # floor(255 * 14 / 15)
    assert wheel[27].tolist() == [0, 209, 255]  # 255 - floor(255 * 2 / 11)
    assert wheel[54].tolist() == [255, 0, 43]  # 255 - floor(255 * 5 / 6)


def test_known_directions_at_full_saturation():
    assert _one(1, 0, max_radius=1) == [255, 0, 0]  # right: red
    assert _one(-1, 0, max_radius=1) == [0, 209, 255]  # left: wheel entry 27 (cyan-blue)
    # down: halfway between entries 13 and 14 -> G = (221 + 238) / 2
    assert _one(0, 1, max_radius=1) == [255, 229, 0]
    # up: halfway between entries 40 and 41 -> R = (78 + 98) / 2
    assert _one(0, -1, max_radius=1) == [88, 0, 255]
    # down-right at 45 deg: entry 6.75 -> G = 0.25 * 102 + 0.75 * 119
    s = 2**-0.5
    r, g, b = _one(s, s, max_radius=1)
    assert (r, b) == (255, 0) and abs(g - 114.75) <= 1
    assert _one(1, 0, max_radius=1) != _one(-1, 0, max_radius=1)


def test_negative_zero_does_not_flip_hue():
    assert _one(1.0, -0.0, max_radius=1) == _one(1.0, 0.0, max_radius=1) == [255, 0, 0]


def test_magnitude_controls_saturation():
    assert _one(0, 0, max_radius=1) == [255, 255, 255]
    assert _one(0.5, 0, max_radius=1) == [255, 127, 127]  # half length: lighter
    assert _one(2.0, 0, max_radius=1) == [191, 0, 0]  # beyond the scale: darkened x0.75
    assert _one(-0.5, 0, max_radius=1) == [127, 232, 255]


def test_automatic_scale_uses_largest_vector():
    f = np.array([[[4.0, 0.0], [2.0, 0.0], [0.0, 0.0]]], np.float32)
    img = flow_to_color(f)
    assert img[0, 0].tolist() == [255, 0, 0]
    assert img[0, 1].tolist() == [255, 127, 127]
    assert img[0, 2].tolist() == [255, 255, 255]
    np.testing.assert_array_equal(flow_to_color(f * 10), img)  # scale invariant
    np.testing.assert_array_equal(flow_to_color(f, max_radius=4.0), img)
    # shared scale: the same field coded against a larger radius is lighter
    shared = flow_to_color(f, max_radius=8.0)
    assert shared[0, 0].tolist() == [255, 127, 127]


def test_all_zero_flow_is_white():
    img = flow_to_color(np.zeros((3, 4, 2), np.float32))
    assert img.dtype == np.uint8 and img.shape == (3, 4, 3)
    assert (img == 255).all()


def test_unknown_pixels():
    f = np.array([[[np.nan, 0.0], [1.0, np.nan], [1e10, 0.0], [np.inf, 1.0], [1.0, 0.0]]])
    img = flow_to_color(f)
    assert (img[0, :4] == 0).all()
    assert img[0, 4].tolist() == [255, 0, 0]  # scale from the known pixels only
    img = flow_to_color(f, unknown_color=(10, 20, 30))
    assert img[0, 0].tolist() == [10, 20, 30]
    all_nan = flow_to_color(np.full((2, 2, 2), np.nan), unknown_color=(1, 2, 3))
    assert (all_nan == [1, 2, 3]).all()


@pytest.mark.parametrize(
    "kwargs",
    [{"max_radius": 0.0}, {"max_radius": -1.0}, {"max_radius": np.nan}, {"unknown_color": (0, 0)}],
)
def test_bad_arguments(kwargs):
    with pytest.raises(ValueError):
        flow_to_color(np.zeros((2, 2, 2)), **kwargs)


def test_bad_shape():
    with pytest.raises(ValueError, match=r"\(H, W, 2\)"):
        flow_to_color(np.zeros((2, 2, 3)))


def test_legend():
    leg = color_wheel_legend()
    assert leg.shape == (151, 151, 3) and leg.dtype == np.uint8
    assert leg[75, 75].tolist() == [255, 255, 255]  # centre: zero flow
    for y, x in [(0, 0), (0, 150), (150, 0), (150, 150)]:  # outside the disc
        assert leg[y, x].tolist() == [255, 255, 255]
    assert leg[75, 150].tolist() == [255, 0, 0]  # right edge = rightwards flow
    assert leg[75, 0].tolist() == [0, 209, 255]  # left edge
    assert leg[150, 75].tolist() == [255, 229, 0]  # bottom edge = downwards flow
    assert leg[0, 75].tolist() == [88, 0, 255]  # top edge = upwards flow
    np.testing.assert_array_equal(color_wheel_legend(31, max_radius=7.0), color_wheel_legend(31))
    with pytest.raises(ValueError):
        color_wheel_legend(2)


def test_flow_with_legend():
    rng = np.random.default_rng(0)
    f = rng.normal(size=(40, 60, 2)).astype(np.float32)
    plain = flow_to_color(f)
    img = flow_to_color_with_legend(f)
    assert img.shape == (40, 60, 3) and img.dtype == np.uint8
    np.testing.assert_array_equal(img[:10, 50:], color_wheel_legend(10))  # min(H, W) // 4
    np.testing.assert_array_equal(img[10:], plain[10:])
    np.testing.assert_array_equal(img[:, :50], plain[:, :50])
    img = flow_to_color_with_legend(f, max_radius=2.0, legend_size=21)
    np.testing.assert_array_equal(img[:21, 39:], color_wheel_legend(21))
    np.testing.assert_array_equal(img[21:], flow_to_color(f, max_radius=2.0)[21:])
    with pytest.raises(ValueError):
        flow_to_color_with_legend(f, legend_size=41)
    tiny = np.zeros((5, 5, 2), np.float32)
    np.testing.assert_array_equal(flow_to_color_with_legend(tiny), flow_to_color(tiny))
