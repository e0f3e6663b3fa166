"""The frame-interpolation error measures (varflow.evaluation.frame_metrics) on exact cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from varflow.evaluation import frame_metrics as fm


def _noise(shape: tuple[int, ...], seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, shape).astype(np.uint8)


def test_psnr_of_a_constant_offset() -> None:
    gt = np.full((20, 30, 3), 100, np.uint8)
    est = gt + np.uint8(5)
    assert fm.psnr(est, gt) == pytest.approx(20 * math.log10(255 / 5), abs=1e-12)
    assert fm.psnr(gt, gt) == math.inf
    # one channel off by 6, the others exact: MSE = 36 / 3 = 12
    est = gt.copy()
    est[..., 1] += 6
    assert fm.psnr(est, gt) == pytest.approx(10 * math.log10(255**2 / 12), abs=1e-12)


def test_float_frames_are_scaled_by_255() -> None:
    a, b = _noise((16, 16, 3), 0), _noise((16, 16, 3), 1)
    fa, fb = a.astype(np.float32) / 255, b.astype(np.float32) / 255
    assert fm.psnr(fa, fb) == pytest.approx(fm.psnr(a, b), abs=1e-5)
    assert fm.interpolation_error(fa, b) == pytest.approx(fm.interpolation_error(a, b),
                                                          abs=1e-4)
    assert fm.mean_absolute_error(a, fb) == pytest.approx(fm.mean_absolute_error(a, b),
                                                          abs=1e-4)
    with pytest.raises(ValueError, match="dtype"):
        fm.psnr(a.astype(np.int32), b)
    with pytest.raises(ValueError, match="shape"):
        fm.psnr(a, b[:, :8])


def test_ie_and_mae_of_a_known_difference() -> None:
    gt = np.full((10, 12, 3), 50, np.uint8)
    est = gt.copy()
    est[..., 0] += 3
    est[..., 1] += 4  # colour difference (3, 4, 0) everywhere: L2 norm 5
    assert fm.interpolation_error(est, gt) == pytest.approx(5.0, abs=1e-12)
    assert fm.mean_absolute_error(est, gt) == pytest.approx(7 / 3, abs=1e-12)
    one = gt.copy()
    one[2, 3] = (53, 54, 50)  # one pixel of 120 differs by (3, 4, 0)
    assert fm.interpolation_error(one, gt) == pytest.approx(math.sqrt(25 / 120), abs=1e-12)
    assert fm.mean_absolute_error(one, gt) == pytest.approx(7 / 360, abs=1e-12)
    # grey frames: one channel
    assert fm.interpolation_error(np.full((4, 4), 9, np.uint8),
                                  np.full((4, 4), 2, np.uint8)) == pytest.approx(7.0)


def test_ne_is_ie_on_a_flat_ground_truth() -> None:
    gt = np.full((15, 17, 3), 80, np.uint8)
    est = _noise((15, 17, 3), 3)
    ie = fm.interpolation_error(est, gt)
    assert ie > 10
    assert fm.normalized_interpolation_error(est, gt) == pytest.approx(ie, rel=1e-12)


def test_ne_gradient_is_central_differences_summed_over_channels() -> None:
    # each channel a ramp of slope 2 along x: |grad|^2 = 3 channels * 2^2 = 12
    x = np.arange(20, dtype=np.uint8) * 2
    gt = np.repeat(np.broadcast_to(x, (9, 20))[..., None], 3, axis=2).copy()
    assert np.allclose(fm.gradient_magnitude_sq(gt), 12.0)
    est = gt.copy()
    est[..., 2] += 10
    ie = fm.interpolation_error(est, gt)
    assert ie == pytest.approx(10.0)
    assert fm.normalized_interpolation_error(est, gt) == pytest.approx(10 / math.sqrt(13),
                                                                       rel=1e-12)
    # a ramp along y of slope 4 in one channel only: |grad|^2 = 16
    gt2 = np.zeros((12, 8, 3), np.uint8)
    gt2[..., 0] = (np.arange(12, dtype=np.uint8) * 4)[:, None]
    assert np.allclose(fm.gradient_magnitude_sq(gt2), 16.0)


def test_ssim_of_identical_frames_is_one() -> None:
    a = _noise((32, 40, 3), 4)
    assert fm.ssim(a, a) == pytest.approx(1.0, abs=1e-12)
    b = np.clip(a.astype(int) + 40, 0, 255).astype(np.uint8)
    assert fm.ssim(b, a) < 0.99
    with pytest.raises(ValueError, match="window"):
        fm.ssim(a[:10], a[:10])


@pytest.mark.parametrize("seed", [0, 1])
def test_ssim_agrees_with_skimage(seed: int) -> None:
    skm = pytest.importorskip("skimage.metrics")
    rng = np.random.default_rng(seed)
    gt = _noise((48, 61, 3), seed)
    est = np.clip(gt.astype(int) + rng.integers(-40, 41, gt.shape), 0, 255).astype(np.uint8)
    ref = skm.structural_similarity(est.astype(np.float64), gt.astype(np.float64),
                                    gaussian_weights=True, sigma=1.5,
                                    use_sample_covariance=False, data_range=255,
                                    channel_axis=-1)
    got = fm.ssim(est, gt)
    assert 0.5 < got < 0.99  # not trivially 1
    assert got == pytest.approx(ref, abs=1e-4)
    ref_grey = skm.structural_similarity(est[..., 0].astype(np.float64),
                                         gt[..., 0].astype(np.float64),
                                         gaussian_weights=True, sigma=1.5,
                                         use_sample_covariance=False, data_range=255)
    assert fm.ssim(est[..., 0], gt[..., 0]) == pytest.approx(ref_grey, abs=1e-4)


def test_frame_scores_has_every_measure() -> None:
    gt = np.full((16, 16, 3), 100, np.uint8)
    est = gt + np.uint8(5)
    s = fm.frame_scores(est, gt)
    assert set(s) == {"psnr", "ssim", "ie", "ne", "mae"}
    assert s["ie"] == pytest.approx(5 * math.sqrt(3))
    assert s["ne"] == pytest.approx(5 * math.sqrt(3))
    assert s["mae"] == pytest.approx(5.0)
