"""Tests of the flow-video frame helpers (varflow.viz.video)."""

from __future__ import annotations

import numpy as np
import pytest

from varflow.io.video import read_frames, video_info
from varflow.viz import flow_to_color
from varflow.viz.video import (
    INVALID_GREY,
    flow_frame,
    flow_max_radius,
    grey_out_invalid,
    side_by_side,
    to_display_rgb,
    warp_next_frame,
    write_flow_video,
)


@pytest.fixture
def flows() -> np.ndarray:
    rng = np.random.default_rng(11)
    f = rng.normal(size=(3, 6, 8, 2)).astype(np.float32)
    f[1, 2, 3] = [3.0, 4.0]  # |w| = 5, the largest
    f[0, 0, 0, 0] = np.nan
    f[2, 1, 1, 1] = 1e10  # unknown (.flo convention), not the maximum
    return f


def test_flow_max_radius(flows):
    assert flow_max_radius(flows) == pytest.approx(5.0 * (1 + 1e-5))
    assert flow_max_radius(iter(list(flows))) == flow_max_radius(flows)  # streaming
    assert flow_max_radius(flows[1]) == flow_max_radius(flows)
    assert flow_max_radius(np.zeros((2, 3, 4, 2))) == 1.0
    assert flow_max_radius(np.full((3, 4, 2), np.nan)) == 1.0
    with pytest.raises(ValueError, match="flow 0"):
        flow_max_radius([np.zeros((3, 4, 3))])


def test_flow_frame_common_scale_and_invalid(flows):
    r = flow_max_radius(flows)
    img = flow_frame(flows[0], r)
    assert img.shape == (6, 8, 3) and img.dtype == np.uint8
    assert tuple(img[0, 0]) == INVALID_GREY
    expected = flow_to_color(flows[0], max_radius=r)
    np.testing.assert_array_equal(img[1:], expected[1:])
    # the same flow gets the same colours whatever the other frames contain
    np.testing.assert_array_equal(flow_frame(flows[2], r)[3:], flow_frame(flows[2], r)[3:])
    big = np.zeros((40, 48, 2), np.float32)
    with_legend = flow_frame(big, 1.0, legend=True)
    assert (with_legend[:10, -10:] != 255).any() and (with_legend[20:, :30] == 255).all()
    with pytest.raises(ValueError, match="max_radius"):
        flow_frame(flows[0], 0.0)


def test_to_display_rgb():
    grey16 = np.array([[0, 256, 65535]], np.uint16)
    np.testing.assert_array_equal(to_display_rgb(grey16)[..., 1], [[0, 1, 255]])
    assert to_display_rgb(np.ones((2, 3), np.float32)).max() == 255
    assert to_display_rgb(np.zeros((2, 3, 1), np.uint8)).shape == (2, 3, 3)
    with pytest.raises(ValueError):
        to_display_rgb(np.zeros((2, 3, 4), np.uint8))


def test_warp_and_grey_out():
    rng = np.random.default_rng(5)
    frame = rng.integers(0, 256, size=(10, 12, 3)).astype(np.uint8)
    warped, valid = warp_next_frame(frame, np.zeros((10, 12, 2), np.float32))
    np.testing.assert_array_equal(warped, frame)
    assert valid.all()
    flow = np.zeros((10, 12, 2), np.float32)
    flow[..., 0] = 2.0  # sample two pixels to the right
    flow[4, 4] = np.nan
    warped, valid = warp_next_frame(frame, flow)
    assert not valid[4, 4] and not valid[:, 10:].any() and valid[:, :10].sum() == 10 * 10 - 1
    np.testing.assert_array_equal(warped[:, :10][valid[:, :10]], frame[:, 2:][valid[:, :10]])
    out = grey_out_invalid(frame, valid)
    np.testing.assert_array_equal(out[valid], frame[valid])
    expected = np.rint(0.25 * frame[~valid].astype(np.float32) + 96).astype(np.uint8)
    np.testing.assert_array_equal(out[~valid], expected)


def test_side_by_side_layout():
    rng = np.random.default_rng(2)
    f0 = rng.integers(0, 256, size=(24, 20, 3)).astype(np.uint8)
    f1 = rng.integers(0, 256, size=(24, 20)).astype(np.uint8)  # grey works too
    flow = np.ones((24, 20, 2), np.float32)
    img = side_by_side(f0, flow, f1, 2.0, labels=False, gap=3, legend=False)
    assert img.shape == (24, 66, 3) and img.dtype == np.uint8
    np.testing.assert_array_equal(img[:, :20], f0)
    assert (img[:, 20:23] == 0).all()
    np.testing.assert_array_equal(img[:, 23:43], flow_frame(flow, 2.0))
    labelled = side_by_side(f0, flow, f1, 2.0)
    assert labelled.shape[1] == 3 * 20 + 2 * 4 and labelled.shape[0] == 24 + 12
    bar = labelled[:12]
    assert (bar > 128).any()  # white caption text on black
    with pytest.raises(ValueError, match="labels"):
        side_by_side(f0, flow, f1, 2.0, labels=["a"])
    with pytest.raises(ValueError, match="differ"):
        side_by_side(f0[:10], flow, f1, 2.0)


def test_write_flow_video(tmp_path, flows):
    flows = np.nan_to_num(flows, nan=0.0, posinf=0.0)
    flows[2, 1, 1, 1] = 0.0
    path = tmp_path / "flow.mkv"
    radius = write_flow_video(path, flows, fps=4, legend=False)
    assert radius == pytest.approx(5.0 * (1 + 1e-5))
    out = read_frames(path)
    assert out.shape == (3, 6, 8, 3)
    for k in range(3):  # lossless: exactly the colour coding on the common scale
        np.testing.assert_array_equal(out[k], flow_frame(flows[k], radius))
    frames = np.zeros((4, 6, 8), np.uint8)
    sbs = tmp_path / "sbs.mkv"
    write_flow_video(sbs, flows, frames=frames, layout="side-by-side", max_radius=2.0)
    info = video_info(sbs)
    assert info.n_frames == 3 and info.width == 3 * 8 + 8
    with pytest.raises(ValueError, match="frames"):
        write_flow_video(tmp_path / "x.mkv", flows, layout="side-by-side")
    with pytest.raises(ValueError, match="layout"):
        write_flow_video(tmp_path / "x.mkv", flows, layout="grid")
