"""Tests of the flow error measures, with hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from varflow.evaluation import (
    angular_error,
    angular_error_map,
    endpoint_error,
    endpoint_error_map,
    evaluate,
    outlier_rate,
    photometric_residual,
    photometric_residual_map,
    rms_endpoint_error,
    valid_mask,
)

# Two pixels: EPE 1 and 5; angles 45 deg and arccos(1 / sqrt(26)).
EST = np.array([[[1.0, 0.0], [0.0, 0.0]]], np.float32)
GT = np.array([[[0.0, 0.0], [3.0, 4.0]]], np.float32)
AAE_2 = math.degrees(math.acos(1 / math.sqrt(26)))  # 78.690...


def test_hand_computed_basic_measures():
    assert endpoint_error(EST, GT) == pytest.approx(3.0)
    assert rms_endpoint_error(EST, GT) == pytest.approx(math.sqrt(13.0))
    assert angular_error(EST, GT) == pytest.approx((45.0 + AAE_2) / 2)
    np.testing.assert_allclose(endpoint_error_map(EST, GT), [[1.0, 5.0]])
    np.testing.assert_allclose(angular_error_map(EST, GT), [[45.0, AAE_2]], rtol=1e-6)
    assert AAE_2 == pytest.approx(78.69006752597979)


def test_unknown_ground_truth_and_mask_are_excluded():
    est = np.concatenate([EST, np.zeros((1, 3, 2), np.float32)], axis=1)
    gt = np.concatenate([GT, [[[1e10, 1e10], [np.nan, 0.0], [0.0, 2e9]]]], axis=1).astype(
        np.float32
    )
    assert valid_mask(gt).tolist() == [[True, True, False, False, False]]
    assert endpoint_error(est, gt) == pytest.approx(3.0)
    assert angular_error(est, gt) == pytest.approx((45.0 + AAE_2) / 2)
    mask = np.array([[False, True, True, True, True]])
    assert valid_mask(gt, mask).tolist() == [[False, True, False, False, False]]
    assert endpoint_error(est, gt, mask) == pytest.approx(5.0)
    assert rms_endpoint_error(est, gt, mask) == pytest.approx(5.0)
    assert angular_error(est, gt, mask) == pytest.approx(AAE_2)
    epe_map = endpoint_error_map(est, gt)
    assert np.isnan(epe_map[0, 2:]).all() and np.isfinite(epe_map[0, :2]).all()


def test_threshold_of_unknown_is_1e9():
    gt = np.array([[[1e9, 0.0], [-1.5e9, 0.0]]], np.float32)
    assert valid_mask(gt).tolist() == [[True, False]]


def test_angular_error_edge_cases():
    same = np.array([[[1e4, 3.3], [0.0, 0.0]]])
    aae = angular_error(same, same)
    assert np.isfinite(aae) and aae < 1e-3  # cosine clipped, no NaN from round-off
    est = np.array([[[1000.0, 0.0]]])
    gt = np.array([[[-1000.0, 0.0]]])
    assert angular_error(est, gt) == pytest.approx(180.0, abs=0.2)
    assert angular_error(np.zeros((1, 1, 2)), np.array([[[0.0, 1.0]]])) == pytest.approx(45.0)


def test_outlier_rates_are_strict_percentages():
    gt = np.zeros((1, 5, 2))
    est = np.zeros((1, 5, 2))
    est[0, :, 0] = [0.5, 1.0, 2.0, 4.0, 6.0]
    assert outlier_rate(est, gt, 1.0) == pytest.approx(60.0)
    assert outlier_rate(est, gt, 3.0) == pytest.approx(40.0)
    assert outlier_rate(est, gt, 5.0) == pytest.approx(20.0)
    assert outlier_rate(est, gt, 0.0) == pytest.approx(100.0)
    mask = np.array([[True, True, False, False, True]])
    assert outlier_rate(est, gt, 1.0, mask) == pytest.approx(100 / 3)
    with pytest.raises(ValueError):
        outlier_rate(est, gt, -1.0)


def test_evaluate_with_missing_estimates_and_occlusion():
    gt = np.zeros((2, 3, 2))
    est = np.zeros((2, 3, 2))
    est[0, :, 0] = [0.5, 2.0, 4.0]
    est[1, :, 1] = [6.0, np.nan, 0.0]  # one missing estimate
    gt[1, 2] = np.nan  # one unknown ground-truth pixel: not counted anywhere
    occ = np.array([[False, False, True], [True, True, False]])
    r = evaluate(est, gt, occlusion=occ)
    assert set(r) == {"aee", "aae", "rms", "r1", "r3", "r5", "missing", "aee_noc", "aee_occ"}
    # used EPEs: 0.5, 2, 4, 6 ; 5 valid gt pixels of which 1 has no estimate
    assert r["aee"] == pytest.approx(3.125)
    assert r["rms"] == pytest.approx(math.sqrt((0.25 + 4 + 16 + 36) / 4))
    assert r["r1"] == pytest.approx(75.0)
    assert r["r3"] == pytest.approx(50.0)
    assert r["r5"] == pytest.approx(25.0)
    assert r["missing"] == pytest.approx(20.0)
    assert r["aee_noc"] == pytest.approx(1.25)  # pixels (0,0), (0,1)
    assert r["aee_occ"] == pytest.approx(5.0)  # pixels (0,2), (1,0); (1,1) is missing
    expected_aae = np.mean([math.degrees(math.atan(e)) for e in (0.5, 2.0, 4.0, 6.0)])
    assert r["aae"] == pytest.approx(expected_aae)
    r_plain = evaluate(est, gt)
    assert "aee_noc" not in r_plain and r_plain["aee"] == r["aee"]
    assert evaluate(gt, gt)["missing"] == 0.0


def test_no_valid_pixels_gives_nan():
    gt = np.full((2, 2, 2), np.nan)
    assert math.isnan(endpoint_error(np.zeros((2, 2, 2)), gt))
    r = evaluate(np.zeros((2, 2, 2)), np.zeros((2, 2, 2)), occlusion=np.zeros((2, 2), bool))
    assert r["aee"] == 0.0 and math.isnan(r["aee_occ"])


def test_input_validation():
    with pytest.raises(ValueError, match="differ in shape"):
        endpoint_error(np.zeros((2, 3, 2)), np.zeros((3, 2, 2)))
    with pytest.raises(ValueError, match=r"\(H, W, 2\)"):
        endpoint_error(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="boolean"):
        endpoint_error(np.zeros((2, 3, 2)), np.zeros((2, 3, 2)), mask=np.ones((2, 3)))
    with pytest.raises(ValueError, match="mask"):
        valid_mask(np.zeros((2, 3, 2)), np.ones((3, 2), bool))
    with pytest.raises(ValueError, match="occlusion"):
        evaluate(np.zeros((2, 3, 2)), np.zeros((2, 3, 2)), occlusion=np.ones((2, 2), bool))


@pytest.fixture
def texture() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, size=(20, 24, 3)).astype(np.uint8)


def test_photometric_residual_zero_for_integer_shift(texture):
    dy, dx = 2, 3
    frame1 = np.roll(texture, shift=(dy, dx), axis=(0, 1))  # frame0(x) = frame1(x + d)
    flow = np.zeros((20, 24, 2), np.float32)
    flow[..., 0], flow[..., 1] = dx, dy
    res_map = photometric_residual_map(texture, frame1, flow)
    assert res_map.shape == (20, 24) and res_map.dtype == np.float32
    finite = np.isfinite(res_map)
    assert finite.sum() == (20 - dy) * (24 - dx)  # targets leaving the image are excluded
    assert not finite[-1, :].any() and not finite[:, -1].any()
    assert photometric_residual(texture, frame1, flow) < 1e-6
    # the wrong flow leaves a large residual
    assert photometric_residual(texture, frame1, np.zeros_like(flow)) > 0.2


def test_photometric_residual_scaling_and_masks():
    frame0 = np.full((6, 7), 100, np.uint8)
    frame1 = np.full((6, 7), 110, np.uint8)
    flow = np.zeros((6, 7, 2), np.float32)
    assert photometric_residual(frame0, frame1, flow) == pytest.approx(10 / 255, abs=1e-6)
    g0 = np.full((6, 7), 1000, np.uint16)
    g1 = np.full((6, 7), 1655, np.uint16)
    assert photometric_residual(g0, g1, flow) == pytest.approx(655 / 65535, abs=1e-6)
    # only the masked pixel counts, and NaN flow counts as outside
    frame1b = frame1.copy()
    frame1b[0, 0] = 200
    mask = np.zeros((6, 7), bool)
    mask[0, 0] = True
    assert photometric_residual(frame0, frame1b, flow, mask) == pytest.approx(100 / 255, abs=1e-6)
    flow_nan = flow.copy()
    flow_nan[0, 0] = np.nan
    res = photometric_residual_map(frame0, frame1b, flow_nan)
    assert np.isnan(res[0, 0]) and np.isfinite(res).sum() == 41
    assert photometric_residual(frame0, frame1b, flow_nan) == pytest.approx(10 / 255, abs=1e-6)
    # everything leaves the image: nothing to average
    out = np.zeros_like(flow)
    out[..., 0] = 100.0
    assert math.isnan(photometric_residual(frame0, frame1, out))
    with pytest.raises(ValueError):
        photometric_residual(frame0, frame1, np.zeros((5, 7, 2), np.float32))
