"""The helpers an OpenCV / scikit-image user expects: ``varflow.warp`` (backward
warping, the ``cv2.remap`` of a flow), ``varflow.consistency`` (forward-backward
check), ``dir(varflow)`` with the lazily loaded names, and ``evaluate``'s plain floats.
"""

from __future__ import annotations

import numpy as np
import pytest

import varflow


def _smooth(rng: np.random.Generator, shape: tuple[int, ...], cells: int = 4) -> np.ndarray:
    """A smooth random field in [-1, 1]: a coarse random grid, bilinearly upsampled."""
    h, w = shape[:2]
    coarse = rng.uniform(-1, 1, (cells + 1, cells + 1) + shape[2:])
    gy = np.linspace(0, cells, h)
    gx = np.linspace(0, cells, w)
    y0 = np.minimum(gy.astype(int), cells - 1)
    x0 = np.minimum(gx.astype(int), cells - 1)
    fy = (gy - y0)[:, None]
    fx = (gx - x0)[None, :]
    if coarse.ndim == 3:
        fy, fx = fy[..., None], fx[..., None]
    c = coarse
    top = c[y0][:, x0] * (1 - fx) + c[y0][:, x0 + 1] * fx
    bottom = c[y0 + 1][:, x0] * (1 - fx) + c[y0 + 1][:, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def _constant_flow(shape: tuple[int, int], u: float, v: float) -> np.ndarray:
    flow = np.empty(shape + (2,), np.float32)
    flow[..., 0] = u
    flow[..., 1] = v
    return flow


# --------------------------------------------------------------------------- warp


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32, np.float64])
def test_warp_by_integer_flow_is_the_shifted_image(dtype) -> None:
    rng = np.random.default_rng(1)
    image = (rng.random((24, 31, 3)) * 200).astype(dtype)
    u, v = 3, -2
    out = varflow.warp(image, _constant_flow((24, 31), u, v))
    assert out.dtype == np.float32 and out.shape == image.shape
    # out[y, x] = image[y + v, x + u] where that exists, exactly
    expected = np.full(image.shape, np.nan, np.float32)
    expected[2:, :-3] = image[:-2, 3:]
    np.testing.assert_array_equal(out, expected)  # NaN where expected is NaN
    assert np.isnan(out[:2]).all() and np.isnan(out[:, -3:]).all()
    assert np.isfinite(out[2:, :-3]).all()


def test_warp_grey_image_keeps_its_shape() -> None:
    image = np.arange(20, dtype=np.uint8).reshape(4, 5)
    out = varflow.warp(image, _constant_flow((4, 5), 0, 1))
    assert out.shape == (4, 5) and out.dtype == np.float32
    np.testing.assert_array_equal(out[:3], image[1:].astype(np.float32))
    assert np.isnan(out[3]).all()


def test_warp_sub_pixel_is_the_hand_bilinear_interpolation() -> None:
    rng = np.random.default_rng(2)
    image = rng.random((16, 20, 2)).astype(np.float32)
    u, v = 0.3, 0.7
    out = varflow.warp(image, _constant_flow((16, 20), u, v))
    i = image.astype(np.float64)
    hand = ((1 - u) * (1 - v) * i[:-1, :-1] + u * (1 - v) * i[:-1, 1:]
            + (1 - u) * v * i[1:, :-1] + u * v * i[1:, 1:])
    np.testing.assert_allclose(out[:-1, :-1], hand, atol=1e-6, rtol=0)
    # the last row and column sample beyond the border: NaN
    assert np.isnan(out[-1]).all() and np.isnan(out[:, -1]).all()
    # one pixel by hand: (x, y) = (5, 7) samples (5.3, 7.7)
    p = 0.7 * 0.3 * i[7, 5] + 0.3 * 0.3 * i[7, 6] + 0.7 * 0.7 * i[8, 5] + 0.3 * 0.7 * i[8, 6]
    np.testing.assert_allclose(out[7, 5], p, atol=1e-6)


def test_warp_nan_flow_gives_nan_and_uint8_equals_float() -> None:
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (12, 14, 3), dtype=np.uint8)
    flow = (_smooth(rng, (12, 14, 2)) * 2).astype(np.float32)
    flow[4, 5] = (np.nan, 0.0)
    flow[6, 7] = (0.0, np.nan)
    out = varflow.warp(image, flow)
    assert np.isnan(out[4, 5]).all() and np.isnan(out[6, 7]).all()
    # the values are not rescaled: a uint8 image warps like its float32 copy
    np.testing.assert_array_equal(out, varflow.warp(image.astype(np.float32), flow))
    assert np.nanmax(out) > 1.5  # 0..255 units, not 0..1


def test_warp_agrees_with_cv2_remap() -> None:
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(4)
    h, w = 48, 64
    image = (_smooth(rng, (h, w, 3), cells=8) * 100 + 120).astype(np.float32)
    flow = (_smooth(rng, (h, w, 2), cells=3) * 6).astype(np.float32)
    if int(cv2.__version__.split(".")[0]) < 5:
        flow = np.round(flow * 32) / 32  # OpenCV 4 rounds the positions to 1/32 px
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    map_x = xx + flow[..., 0]
    map_y = yy + flow[..., 1]
    ref = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=(np.nan,) * 4)
    out = varflow.warp(image, flow)
    # interior: the 4 taps strictly inside (OpenCV's zero-weight tap at x = W-1 is NaN)
    interior = (map_x >= 0) & (map_x < w - 1) & (map_y >= 0) & (map_y < h - 1)
    outside = (map_x < 0) | (map_x > w - 1) | (map_y < 0) | (map_y > h - 1)
    assert interior.mean() > 0.7 and outside.sum() > 50
    assert np.isfinite(out[interior]).all() and np.isfinite(ref[interior]).all()
    assert np.abs(out[interior] - ref[interior]).max() < 1e-4
    assert np.isnan(out[outside]).all() and np.isnan(ref[outside]).all()


@pytest.mark.parametrize(
    ("image", "flow", "name"),
    [
        (np.zeros(5), np.zeros((1, 5, 2)), "image"),
        (np.zeros((2, 3, 4, 5)), np.zeros((2, 3, 2)), "image"),
        (np.zeros((0, 3)), np.zeros((0, 3, 2)), "image"),
        (np.zeros((4, 5), complex), np.zeros((4, 5, 2)), "image"),
        (np.array([["a"]]), np.zeros((1, 1, 2)), "image"),
        (np.zeros((4, 5)), np.zeros((4, 6, 2)), "flow"),
        (np.zeros((4, 5)), np.zeros((4, 5)), "flow"),
        (np.zeros((4, 5)), np.zeros((4, 5, 3)), "flow"),
        (np.zeros((4, 5)), np.zeros((4, 5, 2), bool), "flow"),
        (np.zeros((4, 5)), np.zeros((4, 5, 2), complex), "flow"),
    ],
)
def test_warp_rejects_bad_inputs_naming_the_argument(image, flow, name) -> None:
    with pytest.raises(ValueError, match=rf"^{name}: ") as info:
        varflow.warp(image, flow)
    assert "\n" not in str(info.value)


# --------------------------------------------------------------------------- consistency


def test_consistency_of_a_translation_and_its_inverse() -> None:
    h, w = 20, 30
    fw = _constant_flow((h, w), 3.0, -2.0)
    mask = varflow.consistency(fw, -fw)
    assert mask.dtype == np.bool_ and mask.shape == (h, w)
    yy, xx = np.mgrid[0:h, 0:w]
    inside = (xx + 3 <= w - 1) & (yy - 2 >= 0)
    np.testing.assert_array_equal(mask, inside)
    assert mask[2:, :-3].all() and not mask[:2].any() and not mask[:, -3:].any()
    assert mask.sum() == (h - 2) * (w - 3)


def test_consistency_of_an_affine_flow_and_its_exact_inverse() -> None:
    """A sub-pixel affine motion x' = M x + b (rotation and zoom) and the backward flow of
    its inverse map, which bilinear sampling reproduces exactly: consistent wherever
    x + w_f stays inside the frame, inconsistent where it leaves."""
    h, w = 32, 40
    t = np.deg2rad(4.0)
    m = 1.03 * np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    b = np.array([0.7, -1.3])
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    pts = np.stack([xx, yy], axis=-1)
    fw = (pts @ m.T + b - pts).astype(np.float32)
    bw = ((pts - b) @ np.linalg.inv(m).T - pts).astype(np.float32)
    mask = varflow.consistency(fw, bw)
    tx, ty = xx + fw[..., 0], yy + fw[..., 1]
    inside = (tx >= 0) & (tx <= w - 1) & (ty >= 0) & (ty <= h - 1)
    assert 0.5 < inside.mean() < 0.95
    np.testing.assert_array_equal(mask, inside)
    # far from the threshold: the round trip comes back to within float32 rounding
    back = varflow.warp(bw, fw)
    assert np.nanmax(np.abs(fw + back)) < 1e-4


def test_consistency_threshold_is_the_sundaram_criterion() -> None:
    """fw = (1, 0) and bw = (-1 + d, 0): |fw + bw|² = d² against
    0.01 (1 + (1 - d)²) + 0.5, i.e. consistent for d = 0.70 (0.49 < 0.5109) and not
    for d = 0.72 (0.5184 > 0.5108); the relative term lets d = -0.73 pass
    (0.5329 < 0.5399) but not d = -0.74 (0.5476 > 0.5403)."""
    shape = (6, 8)
    fw = _constant_flow(shape, 1.0, 0.0)
    for d, expected in ((0.70, True), (0.72, False), (-0.73, True), (-0.74, False)):
        mask = varflow.consistency(fw, _constant_flow(shape, -1.0 + d, 0.0))
        assert (mask[:, :-1] == expected).all(), d
        assert not mask[:, -1].any()
    # alpha2 moves the threshold: d = 0.72 passes with alpha2 = 0.6
    bw = _constant_flow(shape, -1.0 + 0.72, 0.0)
    assert varflow.consistency(fw, bw, alpha2=0.6)[:, :-1].all()
    # alpha1 scales with the motion: d = 1 passes with alpha1 = 0.6 (1 < 0.6 * 1 + 0.5)
    bw = _constant_flow(shape, 0.0, 0.0)
    assert not varflow.consistency(fw, bw)[:, :-1].any()
    assert varflow.consistency(fw, bw, alpha1=0.6)[:, :-1].all()


def test_consistency_marks_the_occluded_band() -> None:
    """A square moving 4 px right over a still background: the background just right of
    the square in frame 0 (columns 20..23 of its rows) is covered in frame 1."""
    h, w = 32, 40
    fw = np.zeros((h, w, 2), np.float32)
    bw = np.zeros((h, w, 2), np.float32)
    fw[8:18, 10:20, 0] = 4.0  # the square in frame 0
    bw[8:18, 14:24, 0] = -4.0  # the square in frame 1
    mask = varflow.consistency(fw, bw)
    occluded = np.zeros((h, w), bool)
    occluded[8:18, 20:24] = True
    np.testing.assert_array_equal(~mask, occluded)
    assert (~mask).sum() == 40


def test_consistency_nan_and_outside_are_inconsistent() -> None:
    h, w = 10, 12
    fw = _constant_flow((h, w), 0.5, 0.0)
    bw = -fw
    fw[3, 4] = (np.nan, 0.0)
    # a NaN backward flow at (6, 6) is a tap of the bilinear cells of the points
    # (5.5, 6), (6.5, 6) (weight 1/2) and, with weight 0, (5.5, 5) and (6.5, 5): all four
    # pixels sampling it are inconsistent
    bw[6, 6] = (np.nan, np.nan)
    fw[1, 1] = (-5.0, 0.0)  # leaves the frame
    mask = varflow.consistency(fw, bw)
    assert not mask[3, 4] and not mask[1, 1]
    assert not mask[6, 5] and not mask[6, 6]
    assert not mask[:, -1].any()
    expected = np.ones((h, w), bool)
    expected[:, -1] = False
    expected[3, 4] = expected[1, 1] = False
    expected[5:7, 5:7] = False
    np.testing.assert_array_equal(mask, expected)


@pytest.mark.parametrize(
    ("args", "kwargs", "name"),
    [
        ((np.zeros((4, 5)), np.zeros((4, 5, 2))), {}, "flow_fw"),
        ((np.zeros((4, 5, 2)), np.zeros((4, 6, 2))), {}, "flow_bw"),
        ((np.zeros((4, 5, 2), complex), np.zeros((4, 5, 2))), {}, "flow_fw"),
        ((np.zeros((4, 5, 2)), np.zeros((4, 5, 3))), {}, "flow_bw"),
        ((np.zeros((4, 5, 2)), np.zeros((4, 5, 2))), {"alpha1": -0.1}, "alpha1"),
        ((np.zeros((4, 5, 2)), np.zeros((4, 5, 2))), {"alpha1": float("nan")}, "alpha1"),
        ((np.zeros((4, 5, 2)), np.zeros((4, 5, 2))), {"alpha2": float("inf")}, "alpha2"),
        ((np.zeros((4, 5, 2)), np.zeros((4, 5, 2))), {"alpha2": "big"}, "alpha2"),
        ((np.zeros((4, 5, 2)), np.zeros((4, 5, 2))), {"alpha2": True}, "alpha2"),
    ],
)
def test_consistency_rejects_bad_inputs_naming_the_argument(args, kwargs, name) -> None:
    with pytest.raises(ValueError, match=rf"^{name}: ") as info:
        varflow.consistency(*args, **kwargs)
    assert "\n" not in str(info.value)


# --------------------------------------------------------------------------- top level


LAZY = ["read_image", "read_flo", "write_flo", "read_kitti_png", "write_kitti_png",
        "read_frames", "read_trajectories", "write_trajectories", "draw_trajectories",
        "read_flow", "write_flow", "flow_to_color", "endpoint_error", "angular_error",
        "rms_endpoint_error", "evaluate"]


def test_dir_lists_every_public_name_including_the_lazy_ones() -> None:
    names = dir(varflow)
    assert names == sorted(names)
    for name in LAZY + ["warp", "consistency", "flow", "track", "interpolate"]:
        assert name in names, name
        assert name in varflow.__all__, name
    assert set(varflow.__all__) <= set(names)
    for name in varflow.__all__:  # every exported name resolves
        assert getattr(varflow, name) is not None, name
    # every public function defined in varflow/__init__.py is exported
    own = [n for n, v in vars(varflow).items()
           if callable(v) and getattr(v, "__module__", "") == "varflow" and not n.startswith("_")]
    assert own and set(own) <= set(varflow.__all__), set(own) - set(varflow.__all__)
    assert len(set(varflow.__all__)) == len(varflow.__all__)


def test_evaluate_returns_plain_floats() -> None:
    rng = np.random.default_rng(5)
    gt = rng.normal(size=(10, 12, 2)).astype(np.float32)
    est = gt + np.float32(0.5)
    est[0, :3] = np.nan  # 3 of 120 missing: 2.5 %
    occ = np.zeros((10, 12), bool)
    occ[5:] = True
    result = varflow.evaluate(est, gt, occlusion=occ)
    assert set(result) == {"aee", "aae", "rms", "r1", "r3", "r5", "missing",
                           "aee_noc", "aee_occ"}
    for key, value in result.items():
        assert type(value) is float, (key, type(value))
    assert result["missing"] == pytest.approx(2.5)
    assert result["aee"] == pytest.approx(np.sqrt(0.5), abs=1e-6)
    assert result["r1"] == 0.0
    # also with nothing missing and with no valid pixel at all
    assert all(type(v) is float for v in varflow.evaluate(gt, gt).values())
    empty = varflow.evaluate(gt, np.full_like(gt, np.nan))
    assert all(type(v) is float for v in empty.values())
    assert np.isnan(empty["missing"])
