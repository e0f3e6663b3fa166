"""The denoising protocol's noise, scores and peers (issue 48)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from varflow.evaluation.denoising import (
    VBM3D_REFERENCE,
    add_noise,
    clip_psnr,
    flow_average,
    opencv_nlm,
    temporal_error,
)


def _static_clip(frames: int = 5, shape=(48, 64)) -> np.ndarray:
    from varflow.generators.photo import load_photo

    photo = load_photo("astronaut")[100:100 + shape[0], 200:200 + shape[1]] * 255.0
    return np.repeat(photo[None].astype(np.float32), frames, axis=0)


def test_add_noise_is_the_protocol_draw() -> None:
    clean = _static_clip(3)
    noisy = add_noise(clean, 30)
    expected = clean + np.random.default_rng(0).normal(0, 30, clean.shape).astype(np.float32)
    np.testing.assert_array_equal(noisy, expected)
    assert noisy.dtype == np.float32 and noisy.min() < 0  # not clipped


def test_clip_psnr_and_temporal_error_on_planted_errors() -> None:
    clean = _static_clip(4)
    d = clean + 5.0  # a constant error: 5 on every pixel, the same in every frame
    d = np.minimum(d, 255.0)
    err = np.sqrt(np.mean((d - clean) ** 2))
    assert clip_psnr(d, clean) == pytest.approx(20 * math.log10(255 / err), abs=1e-5)
    assert temporal_error(d, clean) == pytest.approx(0.0, abs=1e-12)  # no flicker
    flicker = clean.copy()
    flicker[1::2] = np.clip(flicker[1::2] + 3.0, 0, 255)  # +3 on every other frame
    mask = clean[1::2] < 252  # where the +3 was not clipped
    assert 0.9 * 3 < temporal_error(flicker, clean) <= 3.0 + 1e-9
    assert mask.mean() > 0.9
    assert clip_psnr(np.full_like(clean, 300.0), np.full_like(clean, 255.0)) == math.inf
    with pytest.raises(ValueError, match="differs"):
        clip_psnr(clean[:2], clean)


def test_opencv_peer_denoises() -> None:
    clean = _static_clip(5)
    noisy = add_noise(clean, 20)
    out = opencv_nlm(noisy, 20)
    assert out.shape == clean.shape and out.dtype == np.float32
    assert clip_psnr(out, clean) > clip_psnr(noisy, clean) + 4


def test_flow_average_of_a_static_clip_gains_nearly_the_frame_count() -> None:
    clean = _static_clip(5)
    noisy = add_noise(clean, 20, seed=1)
    out = flow_average(noisy, radius=2, method="tvl1-fast")
    gain = clip_psnr(out[2:3], clean[2:3]) - clip_psnr(noisy[2:3], clean[2:3])
    assert gain > 10 * math.log10(5) - 2.0, gain  # the middle frame averages 5 frames
    assert out.shape == noisy.shape and out.dtype == np.float32


def test_vbm3d_reference_has_every_clip() -> None:
    assert set(VBM3D_REFERENCE) == {"bikes", "bigbuckbunny", "carphone", "sintel-demo",
                                    "alley_1"}
    assert all(set(psnr) == {10, 30, 50} for psnr, _, _ in VBM3D_REFERENCE.values())
