"""Tests of the trajectory pictures (varflow.viz.plots)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from varflow.viz.colorwheel import flow_to_color
from varflow.viz.plots import (
    HIDDEN_GREY,
    displacement_panels,
    draw_tracks,
    draw_trajectories,
    grey_out,
    sample_points,
    track_animation,
)

F, H, W, REF = 5, 32, 48, 2


def translation(du: float, dv: float, n_frames: int = F, ref: int = REF) -> np.ndarray:
    """Constant translation (du, dv) per frame, zero at the reference frame."""
    steps = (np.arange(n_frames) - ref).astype(np.float32)
    traj = np.zeros((n_frames, H, W, 2), np.float32)
    traj[..., 0] = steps[:, None, None] * du
    traj[..., 1] = steps[:, None, None] * dv
    return traj


def drawn(img: np.ndarray) -> np.ndarray:
    """Pixels that differ from the black background of a blank frame."""
    return img.any(axis=2)


BLANK = np.zeros((H, W), np.uint8)


# --------------------------------------------------------------------------- basics


@pytest.mark.parametrize(
    "frame",
    [
        np.zeros((H, W), np.uint8),
        np.zeros((H, W, 3), np.uint16),
        np.zeros((H, W, 1), np.float32),
        np.zeros((H, W, 4), np.uint8),
    ],
)
def test_shape_and_dtype(frame):
    img = draw_trajectories(frame, translation(1, 1), REF)
    assert img.shape == (H, W, 3) and img.dtype == np.uint8
    assert drawn(img).any()


def test_background_is_dimmed_grey():
    frame = np.zeros((H, W, 3), np.uint8)
    frame[..., 0] = 200  # pure red 200 -> luma 0.299 * 200 = 59.8 -> dimmed 29.9
    img = draw_trajectories(frame, np.full((F, H, W, 2), np.nan), REF)
    assert np.all(img == 30)
    grey16 = np.full((H, W), 65535, np.uint16)
    assert np.all(draw_trajectories(grey16, np.full((F, H, W, 2), np.nan), REF) == 128)
    grey_float = np.full((H, W), 0.5, np.float64)
    assert np.all(draw_trajectories(grey_float, np.full((F, H, W, 2), np.nan), REF) == 64)


def test_straight_horizontal_trajectory():
    # step 24 samples (x, y) = (12, 12) and (36, 12); positions x - 10 .. x + 10.
    img = draw_trajectories(BLANK, translation(5, 0), REF, step=24, show_points=False)
    expected = np.zeros((H, W), bool)
    expected[12, 2:23] = True
    expected[12, 26:47] = True
    np.testing.assert_array_equal(drawn(img), expected)
    assert np.all(img[expected] == flow_to_color(np.array([[[1.0, 0.0]]]))[0, 0])
    assert tuple(img[12, 5]) == (255, 0, 0)  # rightwards = red on the Middlebury wheel


def test_points_and_line_width_stay_near_the_line():
    img = draw_trajectories(BLANK, translation(5, 0), REF, step=24)
    ys, xs = np.nonzero(drawn(img))
    assert set(ys) == {10, 11, 12, 13, 14}  # dots of radius 2 around row 12
    assert set(np.flatnonzero(drawn(img)[11])) <= {10, 11, 12, 13, 14, 34, 35, 36, 37, 38}
    thick = draw_trajectories(
        BLANK, translation(5, 0), REF, step=24, line_width=3, show_points=False
    )
    rows = set(np.nonzero(drawn(thick))[0])
    assert rows == {11, 12, 13}
    assert drawn(thick)[11, 5] and drawn(thick)[13, 5]


def test_nan_breaks_the_line():
    traj = translation(5, 0)
    traj[3, 12, 12] = np.nan  # track at (12, 12): x = 2, 7, 12, NaN, 22
    traj[:, 12, 36] = np.nan  # track at (36, 12): entirely unknown -> not drawn
    img = draw_trajectories(BLANK, traj, REF, step=24, show_points=False)
    expected = np.zeros((H, W), bool)
    expected[12, 2:13] = True  # polyline through frames 0..2
    expected[12, 22] = True  # isolated known position of frame 4
    np.testing.assert_array_equal(drawn(img), expected)
    with_points = draw_trajectories(BLANK, traj, REF, step=24)
    assert not drawn(with_points)[:, 30:].any()  # no dot for the unknown track


def test_step_and_mask_reduce_tracks():
    still = np.zeros((F, H, W, 2), np.float32)

    def n_dots(img: np.ndarray) -> int:
        return ndimage.label(drawn(img))[1]

    for step in (6, 8, 16):
        expected = len(range(step // 2, H, step)) * len(range(step // 2, W, step))
        assert n_dots(draw_trajectories(BLANK, still, REF, step=step)) == expected
    assert n_dots(draw_trajectories(BLANK, still, REF, step=8)) == 4 * 6
    mask = np.zeros((H, W), bool)
    mask[:, :24] = True  # columns 4, 12, 20 of 4, 12, ..., 44
    assert n_dots(draw_trajectories(BLANK, still, REF, step=8, mask=mask)) == 4 * 3
    assert n_dots(draw_trajectories(BLANK, still, REF, step=8, mask=mask.astype(int))) == 12
    assert not drawn(draw_trajectories(BLANK, still, REF, step=8, mask=~np.ones_like(mask))).any()


# --------------------------------------------------------------------------- colours


@pytest.mark.parametrize(("du", "dv"), [(3.0, -4.0), (-2.0, 1.0), (0.0, 3.0), (-4.0, 0.0)])
def test_direction_colour(du, dv):
    img = draw_trajectories(BLANK, translation(du, dv), REF, step=64, show_points=False)
    # step > frame: a single track at the centre (23, 15); a point two frames after the ref
    x, y = int(round(23 + 2 * du)), int(round(15 + 2 * dv))
    expected = flow_to_color(np.array([[[du, dv]]]))[0, 0].astype(int)
    assert np.abs(img[y, x].astype(int) - expected).max() <= 1
    assert expected.max() == 255  # fully saturated wheel colour


def test_direction_colour_with_max_radius():
    # overall displacement (first -> last known frame) = 4 * (3, -4) = (12, -16), length 20
    img = draw_trajectories(
        BLANK, translation(3, -4), REF, step=64, show_points=False, max_radius=40.0
    )
    expected = flow_to_color(np.array([[[12.0, -16.0]]]), max_radius=40.0)[0, 0]
    np.testing.assert_array_equal(img[15 - 4, 23 + 3], expected)
    assert expected.min() > 100  # half the radius: a pale colour
    dark = draw_trajectories(BLANK, translation(3, -4), REF, step=64, max_radius=5.0)
    assert dark[15, 23].max() < 200  # beyond the radius: darkened


def test_direction_mixed_tracks():
    traj = np.zeros((F, H, W, 2), np.float32)
    steps = np.arange(F) - REF
    traj[:, :, :24, 0] = steps[:, None, None] * 2.0  # left half moves right
    traj[:, :, 24:, 0] = -steps[:, None, None] * 2.0  # right half moves left
    img = draw_trajectories(BLANK, traj, REF, step=24, show_points=False)
    right = flow_to_color(np.array([[[1.0, 0.0]]]))[0, 0]
    left = flow_to_color(np.array([[[-1.0, 0.0]]]))[0, 0]
    np.testing.assert_array_equal(img[12, 15], right)
    np.testing.assert_array_equal(img[12, 33], left)
    assert not np.array_equal(right, left)


def test_index_and_fixed_colours():
    still = translation(1, 0)
    img = draw_trajectories(BLANK, still, REF, step=8, colour_by="index")
    labels, n = ndimage.label(drawn(img))
    colours = {tuple(img[labels == k][0]) for k in range(1, n + 1)}
    assert n == 24 and len(colours) >= 20  # (nearly) one colour per track
    fixed = draw_trajectories(BLANK, still, REF, step=8, colour_by=(10, 200, 30))
    assert {tuple(c) for c in fixed[drawn(fixed)]} == {(10, 200, 30)}


# --------------------------------------------------------------------------- panels


def test_displacement_panels_layout_and_colours():
    rng = np.random.default_rng(3)
    traj = rng.normal(scale=3.0, size=(F, 10, 12, 2)).astype(np.float32)
    traj[REF] = 0.0
    traj[1, 0, 0] = np.nan
    out = displacement_panels(traj, REF, labels=False)
    cols, rows = 3, 2  # ceil(sqrt(5)) columns
    assert out.dtype == np.uint8 and out.shape == (rows * 10 + 2, cols * 12 + 4, 3)
    radius = float(np.nanmax(np.hypot(traj[..., 0], traj[..., 1]))) * (1 + 1e-5)
    for n in range(F):
        y0, x0 = (n // cols) * 12, (n % cols) * 14
        np.testing.assert_array_equal(
            out[y0 : y0 + 10, x0 : x0 + 12], flow_to_color(traj[n], max_radius=radius)
        )
    assert np.all(out[10:12] == 128) and np.all(out[:, 12:14] == 128)  # gaps
    assert np.all(out[12:, 28:] == 128)  # empty sixth cell
    assert np.all(out[0:10, 14:26][0, 0] == 0)  # NaN -> black
    assert np.all(out[0:10, 28:40] == 255)  # reference frame panel: zero motion is white


@pytest.mark.parametrize(
    ("n_frames", "columns", "gap", "shape"),
    [
        (5, None, 2, (22, 40)),
        (5, 5, 2, (10, 68)),
        (5, 2, 0, (30, 24)),
        (9, None, 1, (32, 38)),
        (2, 1, 3, (23, 12)),
    ],
)
def test_displacement_panels_sizes(n_frames, columns, gap, shape):
    traj = np.ones((n_frames, 10, 12, 2), np.float32)
    out = displacement_panels(traj, 0, columns=columns, gap=gap)
    rows = math.ceil(n_frames / (columns or math.ceil(math.sqrt(n_frames))))
    assert out.shape == (*shape, 3)
    assert out.shape[0] == rows * 10 + (rows - 1) * gap


def test_displacement_panels_labels_and_shared_radius():
    traj = translation(1, 0)  # frame n moves by (n - 2, 0): |max| = 2
    plain = displacement_panels(traj, REF, labels=False, gap=0, columns=F)
    labelled = displacement_panels(traj, REF, gap=0, columns=F)
    differs = (plain != labelled).any(axis=2)
    assert differs.any() and not differs[H // 2 :].any()  # labels only in the top rows
    assert not differs[:, 30:W].any()  # ... and only at the left of each panel
    # shared scale: frame 3 (|d| = 1) is paler than frame 4 (|d| = 2, saturated)
    assert plain[H - 1, 3 * W + W - 1].min() > plain[H - 1, 4 * W + W - 1].min()
    fixed = displacement_panels(traj, REF, labels=False, gap=0, columns=F, max_radius=4.0)
    np.testing.assert_array_equal(fixed[:, 4 * W :], flow_to_color(traj[4], max_radius=4.0))


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("args", "kwargs", "name"),
    [
        ((BLANK, np.zeros((F, H, W)), REF), {}, "traj"),
        ((BLANK, np.zeros((F, H, W, 3)), REF), {}, "traj"),
        ((BLANK, np.zeros((F, H, W, 2), bool), REF), {}, "traj"),
        ((BLANK, np.zeros((F, H, W, 2)), F), {}, "ref"),
        ((BLANK, np.zeros((F, H, W, 2)), -1), {}, "ref"),
        ((BLANK, np.zeros((F, H, W, 2)), 1.5), {}, "ref"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"step": 0}, "step"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"step": 2.5}, "step"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"line_width": 0}, "line_width"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"mask": np.ones((H, W + 1), bool)}, "mask"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"colour_by": "speed"}, "colour_by"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"colour_by": (1, 2)}, "colour_by"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"colour_by": (0, 0, 300)}, "colour_by"),
        ((BLANK, np.zeros((F, H, W, 2)), REF), {"max_radius": 0.0}, "max_radius"),
        ((np.zeros((H, W + 1)), np.zeros((F, H, W, 2)), REF), {}, "reference_frame"),
        # floats outside [0, 1] are scaled now (varflow._validate); non-finite is refused
        ((np.full((H, W), np.nan), np.zeros((F, H, W, 2)), REF), {}, "reference_frame"),
    ],
)
def test_draw_trajectories_invalid(args, kwargs, name):
    with pytest.raises(ValueError, match=name):
        draw_trajectories(*args, **kwargs)


@pytest.mark.parametrize(
    ("traj", "ref", "kwargs", "name"),
    [
        (np.zeros((F, H, W)), 0, {}, "traj"),
        (np.zeros((F, H, W, 2)), F, {}, "ref"),
        (np.zeros((F, H, W, 2)), 0, {"columns": 0}, "columns"),
        (np.zeros((F, H, W, 2)), 0, {"gap": -1}, "gap"),
        (np.zeros((F, H, W, 2)), 0, {"max_radius": -1.0}, "max_radius"),
    ],
)
def test_displacement_panels_invalid(traj, ref, kwargs, name):
    with pytest.raises(ValueError, match=name):
        displacement_panels(traj, ref, **kwargs)


# ------------------------------------------------------------------------- visibility


def test_hidden_segments_are_grey_and_visible_ones_keep_their_colour():
    traj = translation(5, 0)
    vis = np.ones((F, H, W), bool)
    vis[REF + 1:] = False  # hidden after the reference frame
    img = draw_trajectories(BLANK, traj, REF, step=24, show_points=False, visibility=vis)
    colour = flow_to_color(np.array([[[1.0, 0.0]]]))[0, 0]
    assert tuple(img[12, 14]) == HIDDEN_GREY  # x = 12 + 2: on the hidden (later) part
    assert np.all(img[12, 4] == colour)  # x = 12 - 8: before the reference, visible
    plain = draw_trajectories(BLANK, traj, REF, step=24, show_points=False)
    assert not np.any(np.all(plain == np.array(HIDDEN_GREY, np.uint8), axis=-1))
    with pytest.raises(ValueError, match="visibility"):
        draw_trajectories(BLANK, traj, REF, visibility=vis[:, :4])


def test_grey_out_changes_only_hidden_pixels():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    vis = rng.random((H, W)) > 0.3
    out = grey_out(img, vis)
    np.testing.assert_array_equal(out[vis], img[vis])
    expect = np.round(0.25 * img[~vis].astype(np.float32) + 96.0).astype(np.uint8)
    np.testing.assert_array_equal(out[~vis], expect)
    assert grey_out(img[..., 0], vis).shape == (H, W)
    with pytest.raises(ValueError, match="visible"):
        grey_out(img, vis[:5])


# --------------------------------------------------------------------------- TAP-Vid style


def test_sample_points_spread_and_repeat() -> None:
    ys, xs = sample_points((120, 160), 300, seed=3)
    assert 0.8 * 300 <= ys.size <= 1.2 * 300
    assert ys.min() >= 0 and ys.max() < 120 and xs.min() >= 0 and xs.max() < 160
    again = sample_points((120, 160), 300, seed=3)
    np.testing.assert_array_equal(ys, again[0])
    np.testing.assert_array_equal(xs, again[1])
    assert not np.array_equal(xs, sample_points((120, 160), 300, seed=4)[1])
    # one point per cell: every quarter of the frame gets about a quarter of them
    assert abs(int((xs < 80).sum()) - ys.size // 2) <= ys.size // 10
    mask = np.zeros((120, 160), bool)
    mask[:, :40] = True
    _, xm = sample_points((120, 160), 300, seed=3, mask=mask)
    assert xm.size > 0 and xm.max() < 40
    with pytest.raises(ValueError, match="n must be"):
        sample_points((10, 10), 0)


def test_draw_tracks_tails_dots_and_hidden_parts() -> None:
    """One point moving 6 px per frame to the right: its dot at its last position in
    its colour, its tail back along the row; hidden in the last two frames: a grey
    ring and dashed grey segments instead."""
    traj = translation(6, 0)
    img = draw_tracks(BLANK, traj, REF, points=1, line_width=1)
    ys, xs = sample_points((H, W), 1)
    y, x = int(ys[0]), int(xs[0])
    last = x + 6 * (F - 1 - REF)
    colour = img[y, min(last, W - 1)]
    assert colour.any() and tuple(colour) != HIDDEN_GREY
    row = drawn(img)[y]
    first = x - 6 * REF
    # the tail, frame 0 to the last (the dot's black outline aside)
    assert row[max(first, 0):last - 3].all()
    vis = np.ones((F, H, W), bool)
    vis[-2:] = False
    hidden = draw_tracks(BLANK, traj, REF, points=1, line_width=1, visibility=vis)
    seg = hidden[y, x + 6 * (F - 3 - REF) + 1:min(last - 3, W)]  # the last two segments
    assert (seg == HIDDEN_GREY).all(axis=1).any()
    assert not (seg == colour).all(axis=1).any()
    with pytest.raises(ValueError, match="frame_index"):
        draw_tracks(BLANK, traj, REF, frame_index=F)
    with pytest.raises(ValueError, match="tail"):
        draw_tracks(BLANK, traj, REF, tail=-1)
    with pytest.raises(ValueError, match="visibility"):
        draw_tracks(BLANK, traj, REF, visibility=vis[:2])


def test_track_animation_one_picture_per_frame() -> None:
    traj = translation(3, 1)
    frames = np.zeros((F, H, W, 3), np.uint8)
    pictures = list(track_animation(frames, traj, REF, points=20, tail=2))
    assert len(pictures) == F and all(p.shape == (H, W, 3) for p in pictures)
    # frame n draws the dots where the points are in frame n
    for n in (0, F - 1):
        expect = draw_tracks(frames[n], traj, REF, frame_index=n, points=20, tail=2)
        np.testing.assert_array_equal(pictures[n], expect)
    with pytest.raises(ValueError, match="frames"):
        list(track_animation(frames[:2], traj, REF))


def test_draw_tracks_legend_and_title() -> None:
    """The legend is a white band under the picture, which stays as it was: a dot, a
    tail and, with the visibility, a grey ring and grey dashes, each with its text."""
    from varflow.viz.plots import _LEGEND_COLOUR, _legend_entries

    traj = translation(3, 1)
    vis = np.ones((F, H, W), bool)
    vis[-1, :, : W // 2] = False
    plain = draw_tracks(BLANK, traj, REF, points=20, visibility=vis)
    assert plain.shape == (H, W, 3)
    img = draw_tracks(BLANK, traj, REF, points=20, visibility=vis, legend=True)
    assert img.shape[0] > H and img.shape[1] >= W
    np.testing.assert_array_equal(img[:H, :W], plain)
    band = img[H:]
    assert (band == 255).all(axis=2).mean() > 0.5  # white
    assert (band.max(axis=2) < 80).any()  # black text
    assert (band == _LEGEND_COLOUR).all(axis=2).any()  # the sample dot and tail
    # the ring and the dashes (the text's anti-aliasing has a few such greys too)
    greys = int((band == HIDDEN_GREY).all(axis=2).sum())
    # without the visibility nothing is hidden, and the legend says nothing about it
    seen = draw_tracks(BLANK, traj, REF, points=20, legend=True)
    assert int((seen[H:] == HIDDEN_GREY).all(axis=2).sum()) + 20 < greys
    assert seen.shape[0] < img.shape[0]
    texts = [t for _, t in _legend_entries(F - 1, 0, hidden=True)]
    assert texts == [f"point in frame {F - 1}", f"its path, frames 0-{F - 1}",
                     f"point hidden in frame {F - 1}", "path while hidden"]
    assert [s for s, _ in _legend_entries(F - 1, 0, hidden=False)] == ["dot", "tail"]
    # the title (the reference frame, by default) is drawn at the top of the band
    named = draw_tracks(BLANK, traj, REF, points=20, visibility=vis, legend=True,
                        title="the reference: f2.png\non f4.png")
    np.testing.assert_array_equal(named[:H, :W], plain)
    assert named.shape == img.shape
    rows = slice(H, H + 20)  # the first line of the title
    assert not np.array_equal(named[rows], img[rows])
    np.testing.assert_array_equal(named[-40:], img[-40:])  # the same legend under it
    only_title = draw_tracks(BLANK, traj, REF, points=20, title="reference frame 2")
    assert H < only_title.shape[0] < img.shape[0]
    with pytest.raises(ValueError, match="title"):
        draw_tracks(BLANK, traj, REF, title=3)  # type: ignore[arg-type]


def test_draw_tracks_legend_wraps_to_the_picture() -> None:
    """A wide picture keeps its width (the entries in columns); a long title is wrapped."""
    wide = np.zeros((H, 12 * W), np.uint8)
    traj = np.zeros((F, H, 12 * W, 2), np.float32)
    img = draw_tracks(wide, traj, REF, points=20, legend=True, title="reference " * 60)
    assert img.shape[1] == 12 * W
    one_line = draw_tracks(wide, traj, REF, points=20, legend=True, title="reference")
    assert img.shape[0] > one_line.shape[0]
