"""Deflicker (:func:`varflow.restore.flicker.deflicker`) against planted flicker."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from varflow.evaluation.defects import plant_dirt, plant_flicker
from varflow.evaluation.denoising import clip_psnr
from varflow.restore.flicker import DeflickerParams, deflicker


def _panning_clip(frames: int = 8, shape=(72, 96)) -> np.ndarray:
    """A photo crop panning 2 px right and 1 px down per frame, float32 0-255."""
    from varflow.generators.photo import load_photo

    photo = load_photo("astronaut") * 255.0
    h, w = shape
    return np.stack([photo[40 + k:40 + k + h, 160 + 2 * k:160 + 2 * k + w]
                     for k in range(frames)]).astype(np.float32)


def _residual_flicker(out: np.ndarray, clean: np.ndarray) -> float:
    """Std over frames of the per-frame mean error (output clipped to 0-255)."""
    err = np.clip(out, 0, 255).astype(np.float64) - clean
    return float(err.reshape(len(err), -1).mean(axis=1).std())


def _mean_std_matching(clip: np.ndarray) -> np.ndarray:
    m = clip.mean(axis=(1, 2), keepdims=True)
    s = clip.std(axis=(1, 2), keepdims=True)
    return (clip - m) / s * s.mean(axis=0, keepdims=True) + m.mean(axis=0, keepdims=True)


@pytest.fixture(scope="module")
def panning() -> np.ndarray:
    return _panning_clip()


def test_planted_flicker_is_removed(panning: np.ndarray) -> None:
    flickered, _ = plant_flicker(panning, seed=3)
    stats: dict = {}
    out = deflicker(flickered, stats=stats)
    assert out.shape == panning.shape and out.dtype == np.float32
    before, after = clip_psnr(flickered, panning), clip_psnr(out, panning)
    assert before < 24.0
    assert after > 34.0
    assert after > clip_psnr(_mean_std_matching(flickered), panning) + 6.0
    assert _residual_flicker(out, panning) < 1.5 < 10.0 < _residual_flicker(flickered, panning)
    assert stats["gain"].shape == (8, 3) and stats["smoother"].shape == (8, 8)
    np.testing.assert_allclose(stats["smoother"].sum(axis=1), 1.0, atol=1e-9)


def test_steady_clip_comes_back_unchanged(panning: np.ndarray) -> None:
    out = deflicker(panning)
    assert clip_psnr(out, panning) >= 45.0


def test_fade_is_kept(panning: np.ndarray) -> None:
    n = len(panning)
    ramp = np.linspace(1.0, 0.6, n, dtype=np.float32)
    faded = panning * ramp[:, None, None, None]
    flickered, _ = plant_flicker(faded, seed=5, gain=(0.9, 1.1), offset=5.0)
    out = deflicker(flickered)
    m_out = np.clip(out, 0, 255).mean(axis=(1, 2, 3))
    m_true = faded.mean(axis=(1, 2, 3))
    slope = np.polyfit(m_true, m_out, 1)[0]
    assert 0.85 < slope < 1.15  # follows the fade, not a constant (slope 0)
    # Within what 8 frames of flicker allow (the flicker's own tilt is indistinguishable
    # from a fade): a constant at the clip's mean would be 24 levels off at the ends.
    assert np.abs(m_out - m_true).max() < 10.0
    assert np.abs(m_true - m_true.mean()).max() > 20.0
    assert clip_psnr(out, faded) > clip_psnr(flickered, faded) + 3.0


def test_lasting_step_is_kept(panning: np.ndarray) -> None:
    n = len(panning)
    level = np.where(np.arange(n) >= 4, 0.5, 1.0).astype(np.float32)
    dimmed = panning * level[:, None, None, None]
    flickered, _ = plant_flicker(dimmed, seed=2, gain=(0.95, 1.05), offset=3.0)
    stats: dict = {}
    out = deflicker(flickered, stats=stats)
    assert stats["steps"] == [4]
    m_out = np.clip(out, 0, 255).mean(axis=(1, 2, 3))
    assert np.abs(m_out - dimmed.mean(axis=(1, 2, 3))).max() < 3.0


def test_dirt_does_not_pull_the_estimate(panning: np.ndarray) -> None:
    flickered, _ = plant_flicker(panning, seed=3)
    dirty, mask = plant_dirt(flickered, seed=1, coverage=(0.01, 0.02))
    out = deflicker(dirty)
    keep = ~mask[..., None].repeat(3, axis=-1)
    err = (np.clip(out, 0, 255) - panning)[keep]
    psnr_clean_pixels = 10 * np.log10(255.0**2 / np.mean(err.astype(np.float64) ** 2))
    assert psnr_clean_pixels > 33.0


def test_dtype_and_shape_are_kept() -> None:
    clip = _panning_clip(6, (48, 64))
    flickered, _ = plant_flicker(clip.mean(axis=3), seed=1)
    grey8 = np.clip(np.rint(flickered), 0, 255).astype(np.uint8)
    out = deflicker(grey8)
    assert out.shape == grey8.shape and out.dtype == np.uint8
    unit = (np.clip(flickered, 0, 255) / 255.0).astype(np.float64)
    out_unit = deflicker(list(unit))
    assert out_unit.shape == unit.shape and out_unit.dtype == np.float64
    truth = clip.mean(axis=3) / 255.0
    assert np.sqrt(np.mean((out_unit - truth) ** 2)) < 0.5 * np.sqrt(np.mean((unit - truth) ** 2))
    one = grey8[:1]
    np.testing.assert_array_equal(deflicker(one), one)


def test_given_flows_are_used() -> None:
    scene = np.random.default_rng(0).uniform(20, 230, (40, 56)).astype(np.float32)
    clean = np.repeat(scene[None], 6, axis=0)
    gains = np.array([1.0, 1.2, 0.85, 1.1, 0.9, 0.95], np.float32)
    flickered = clean * gains[:, None, None] + np.float32(4.0)
    zero = np.zeros((5, 40, 56, 2), np.float32)
    out = deflicker(flickered, flows=(zero, zero), degree=0, offset_degree=0)
    # A static scene: every frame becomes the same picture, the clip's mean rendering.
    target = clean * gains.mean() + 4.0
    assert np.abs(out - target).max() < 0.05
    with pytest.raises(ValueError, match="flows"):
        deflicker(flickered, flows=(zero[:3], zero[:3]))


def test_parameters_are_checked() -> None:
    clip = np.zeros((3, 16, 16), np.float32)
    with pytest.raises(ValueError, match="degree"):
        DeflickerParams(degree=9)
    with pytest.raises(ValueError, match="trim"):
        deflicker(clip, trim=0)
    with pytest.raises(ValueError, match="bogus"):
        deflicker(clip, bogus=1)
    with pytest.raises(ValueError, match="flow_method"):
        DeflickerParams(flow_method="nope")
    with pytest.raises(ValueError, match="frame 1"):
        deflicker(np.stack([np.zeros((16, 16)), np.full((16, 16), np.nan)]))


def test_real_clip_beats_the_baseline(data_root: Path) -> None:
    from varflow.evaluation.denoising import protocol_clips

    clean = protocol_clips(data_root, 12, ("carphone",))["carphone"]
    flickered, _ = plant_flicker(clean, seed=0)
    out = deflicker(flickered)
    assert clip_psnr(flickered, clean) < 24.0
    assert clip_psnr(out, clean) > 36.0
    assert clip_psnr(out, clean) > clip_psnr(_mean_std_matching(flickered), clean) + 4.0
    assert _residual_flicker(out, clean) < 1.5
