"""Noise estimation (issue 48): σ per channel and the noise curve, in input units."""

from __future__ import annotations

import numpy as np
import pytest

from varflow.restore import estimate_noise


def _texture(shape=(128, 160), seed=3) -> np.ndarray:
    """A grey photograph (0-255 float, flat and textured parts): a crop that moves
    with ``seed``, as the frames of a pan."""
    from varflow.generators.photo import load_photo

    photo = load_photo(("rocket", "astronaut")[seed % 2]).mean(axis=2) * 255.0
    y, x = 40 + 7 * seed, 60 + 11 * seed
    return photo[y:y + shape[0], x:x + shape[1]].astype(np.float64)


@pytest.mark.parametrize("sigma", [2.0, 10.0, 30.0, 50.0])
def test_planted_noise_within_5_percent(sigma: float) -> None:
    clean = np.stack([_texture(seed=s) for s in range(4)])  # (F, H, W), grey clip
    noisy = clean + np.random.default_rng(0).normal(0, sigma, clean.shape)
    est = estimate_noise(noisy)
    assert est.sigma.shape == (1,)
    assert abs(est.sigma[0] / sigma - 1) < 0.05, est.sigma


def test_colour_channels_and_units() -> None:
    """σ per channel, in the input's units: the same noise on 0-1 is σ/255."""
    clean = np.stack([np.stack([_texture(seed=s)] * 3, axis=-1) for s in range(3)])
    rng = np.random.default_rng(1)
    noisy = clean + rng.normal(0, 1, clean.shape) * np.array([5.0, 10.0, 20.0])
    est = estimate_noise(noisy)
    np.testing.assert_allclose(est.sigma, [5.0, 10.0, 20.0], rtol=0.05)
    unit = estimate_noise(noisy / 255.0)
    np.testing.assert_allclose(unit.sigma, est.sigma / 255.0, rtol=1e-9)
    one = estimate_noise(noisy[0])  # one image (H, W, 3)
    assert one.sigma.shape == (3,) and abs(one.sigma[1] / 10 - 1) < 0.1


def test_uint8_clipped_noise_and_saturated_blocks_left_out() -> None:
    clean = np.stack([_texture(seed=s) for s in range(4)])
    clean[:, :32] = 255.0  # a burnt-out band: its noise is clipped away
    noisy = np.clip(np.rint(clean + np.random.default_rng(2).normal(0, 12, clean.shape)),
                    0, 255).astype(np.uint8)
    est = estimate_noise(noisy)
    assert abs(est.sigma[0] / 12 - 1) < 0.05, est.sigma


def test_noise_curve_follows_signal_dependent_noise() -> None:
    clean = np.stack([_texture(seed=s) for s in range(6)])
    std = np.sqrt(4.0 + 0.4 * clean)  # photon-like: the variance grows with the signal
    noisy = clean + np.random.default_rng(3).normal(0, 1, clean.shape) * std
    est = estimate_noise(noisy, bins=4)
    assert est.curve.shape == (4, 1) and est.intensity.shape == (4, 1)
    assert np.all(np.diff(est.intensity[:, 0]) > 0)
    truth = np.sqrt(4.0 + 0.4 * est.intensity[:, 0])
    np.testing.assert_allclose(est.curve[:, 0], truth, rtol=0.08)
    assert est.curve[-1, 0] > 1.5 * est.curve[0, 0]


def test_clean_picture_has_little_noise() -> None:
    clean = np.stack([_texture(seed=s) for s in range(3)])
    assert estimate_noise(clean).sigma[0] < 0.5


@pytest.mark.parametrize("bad, message", [
    (np.zeros((4, 4)), "smaller than one 8x8 block"),
    (np.zeros((2, 3, 4, 5, 6)), "expected"),
    (np.full((16, 16), np.nan), "NaN"),
    (np.zeros((16, 16), complex), "unsupported dtype"),
    ([], "no frames"),
])
def test_bad_inputs(bad, message) -> None:
    with pytest.raises(ValueError, match=message):
        estimate_noise(bad)
    with pytest.raises(ValueError, match="^bins: must be an integer >= 1"):
        estimate_noise(np.zeros((16, 16)), bins=0)


def test_real_clips_within_2_percent(data_root) -> None:
    """The protocol's noise on two restoration clips (5 frames, σ 10 and 50)."""
    from varflow.io import read_image

    for clip in ("carphone", "bikes"):
        files = sorted((data_root / "restoration" / clip).glob("*.png"))[:5]
        clean = np.stack([read_image(f) for f in files]).astype(np.float32)
        for sigma in (10, 50):
            noisy = clean + np.random.default_rng(0).normal(0, sigma, clean.shape)
            est = estimate_noise(noisy.astype(np.float32))
            assert np.all(np.abs(est.sigma / sigma - 1) < 0.02), (clip, sigma, est.sigma)
