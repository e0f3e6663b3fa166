"""Stabilisation against gate weave (:func:`varflow.restore.stabilise.stabilise`), scored
with the weave the defect generator planted."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from varflow.evaluation.defects import (
    WeaveParams,
    plant_flicker,
    plant_noise,
    plant_weave,
    weave_residual,
)
from varflow.restore.stabilise import (
    StabiliseParams,
    fit_global_motion,
    smooth_path,
    stabilise,
)

IDENTITY = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _h(m: np.ndarray) -> np.ndarray:
    out = np.zeros(m.shape[:-2] + (3, 3))
    out[..., :2, :] = m
    out[..., 2, 2] = 1.0
    return out


def _rms(d: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Per-frame RMS over the pixels of ``|D p - p|``."""
    params = WeaveParams(None, None, None, np.asarray(d)[:, :2], shape)
    return weave_residual(np.broadcast_to(IDENTITY, np.asarray(d)[:, :2].shape), params)


def _net(correction: np.ndarray, weave: WeaveParams) -> np.ndarray:
    """Clean to stabilised maps ``(F, 3, 3)``: the correction after the weave."""
    return _h(correction) @ _h(weave.matrices)


def _jitter(correction: np.ndarray, weave: WeaveParams) -> float:
    """Mean RMS displacement left once the clip's constant offset is taken out."""
    d = _net(correction, weave)
    return float(_rms(d @ np.linalg.inv(d.mean(axis=0)), weave.shape).mean())


def _texture(shape: tuple[int, int], seed: int = 0) -> np.ndarray:
    """A grey picture with detail at several scales, on 28-228, float32."""
    rng = np.random.default_rng(seed)
    h, w = shape
    out = np.zeros(shape, np.float32)
    for sigma, amp in ((1.0, 40.0), (3.0, 60.0), (8.0, 80.0)):
        z = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0), sigma)
        out += amp * z / z.std()
    return (128 + 100 * np.tanh(out / 100)).astype(np.float32)


def _static_clip(frames: int = 12, shape=(96, 128)) -> np.ndarray:
    return np.repeat(_texture(shape)[None], frames, axis=0)


# --------------------------------------------------------------------------- fit, path


@pytest.mark.parametrize("model", ["translation", "similarity", "affine"])
def test_fit_recovers_the_motion_among_outliers(model: str) -> None:
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 200, (2000, 2))
    m = {"translation": np.array([[1, 0, 2.5], [0, 1, -1.25]]),
         "similarity": cv2.getRotationMatrix2D((100, 80), 0.7, 1.01) + [[0, 0, 3], [0, 0, -2]],
         "affine": np.array([[1.01, 0.02, 3.0], [-0.015, 0.99, -2.0]])}[model]
    tgt = pts @ m[:, :2].T + m[:, 2]
    out = rng.random(2000) < 0.35  # 35 % outliers moving 5-15 px their own way
    tgt[out] += rng.uniform(5, 15, (out.sum(), 2))
    est, robust = fit_global_motion(pts, tgt, np.ones(2000), model)
    np.testing.assert_allclose(est, m, atol=1e-6)
    assert robust[out].max() == 0.0 and robust[~out].min() > 0.99


def test_fit_without_weight_is_the_identity() -> None:
    pts = np.zeros((50, 2))
    est, robust = fit_global_motion(pts, pts + 1.0, np.zeros(50))
    np.testing.assert_array_equal(est, IDENTITY)
    assert not robust.any()


def test_smooth_path_keeps_a_pan_and_averages_jitter() -> None:
    n = 15
    pan = np.tile(IDENTITY, (n, 1, 1))
    pan[:, 0, 2] = 1.5 * np.arange(n)  # a constant-speed pan: kept exactly
    pan[:, 1, 2] = -0.5 * np.arange(n)
    np.testing.assert_allclose(smooth_path(pan, (60, 80))[:, :2], pan, atol=1e-9)
    rng = np.random.default_rng(0)
    still = np.tile(IDENTITY, (n, 1, 1))
    still[:, :, 2] = rng.uniform(-4, 4, (n, 2))  # pure jitter, no slope
    locked = smooth_path(still, (60, 80), smooth=np.inf, degree=0)
    np.testing.assert_allclose(locked[:, :2, 2], np.broadcast_to(still[:, :, 2].mean(0),
                                                                  (n, 2)), atol=1e-9)
    np.testing.assert_array_equal(smooth_path(still, (60, 80), smooth=0)[:, :2], still)


# --------------------------------------------------------------------------- stabilise


def test_static_weave_is_removed_to_the_oracle() -> None:
    """A still shot, weave of ±4 px and ±0.5°, locked-off path (σ = inf, degree 0): the
    transforms match those of the true path smoothed the same way within 0.05 px, and
    the jitter left is under 0.06 px (the weave's is over 2.5 px)."""
    clean = _static_clip()
    woven, weave = plant_weave(clean, seed=4)
    out, corr = stabilise(woven, return_transforms=True, smooth=np.inf, degree=0)
    true_path = _h(weave.matrices) @ np.linalg.inv(_h(weave.matrices[0]))
    oracle = smooth_path(true_path, weave.shape, smooth=np.inf, degree=0) \
        @ np.linalg.inv(true_path)
    est = np.stack([cv2.invertAffineTransform(c) for c in corr])
    orc = np.stack([cv2.invertAffineTransform(c) for c in oracle[:, :2]])
    assert _rms(_h(est) @ np.linalg.inv(_h(orc)), weave.shape).max() < 0.08
    assert _jitter(corr, weave) < 0.06
    assert _jitter(np.broadcast_to(IDENTITY, corr.shape), weave) > 2.5
    # The planted-weave score: the offset left is the clip's mean weave (exact oracle).
    assert weave_residual(est, weave).mean() == pytest.approx(
        weave_residual(orc, weave).mean(), abs=0.05)


def test_slow_pan_is_kept_and_weave_removed() -> None:
    """A pan of 1 px/frame to the right and 0.5 px/frame down, cut from a larger
    picture, then woven: the smoothed path is the true path smoothed the same way
    within 0.1 px RMS, keeps the pan (slope within 0.2 px/frame: the weave's own slope
    over 16 frames has a standard error of 0.13), and the jitter left is under a
    quarter of the weave's."""
    n, h, w = 16, 80, 112
    big = _texture((h + 20, w + 30), seed=5)
    clean = np.stack([cv2.warpAffine(big, np.array([[1.0, 0, -k], [0, 1.0, -10 - k / 2]]),
                                     (w, h), flags=cv2.INTER_CUBIC) for k in range(n)])
    woven, weave = plant_weave(clean, seed=7)
    st: dict = {}
    _, corr = stabilise(woven, return_transforms=True, stats=st)
    # Content at q in clean frame 0 is at q - (k, k/2) in clean frame k.
    pan = np.tile(np.eye(3), (n, 1, 1))
    pan[:, 0, 2], pan[:, 1, 2] = -np.arange(n), -np.arange(n) / 2
    true_path = _h(weave.matrices) @ pan @ np.linalg.inv(_h(weave.matrices[0]))
    oracle = smooth_path(true_path, (h, w))
    assert _rms(_h(st["smoothed"]) @ np.linalg.inv(oracle), (h, w)).max() < 0.1
    centre = np.array([(w - 1) / 2, (h - 1) / 2, 1.0])
    slope = np.diff((_h(st["smoothed"]) @ centre)[:, :2], axis=0).mean(axis=0)
    np.testing.assert_allclose(slope, [-1.0, -0.5], atol=0.2)
    net = _h(corr) @ _h(weave.matrices)  # clean panned frame -> stabilised frame
    jitter = _rms(net @ np.linalg.inv(net.mean(axis=0)), (h, w)).mean()
    assert jitter < 0.25 * _jitter(np.broadcast_to(IDENTITY, corr.shape), weave)


def test_moving_object_flicker_and_noise_are_outliers() -> None:
    """A textured square covering a fifth of the frame moves 3 px/frame across a still
    background; flicker and noise on top of the weave: each pair's global motion is the
    weave's within 0.12 px RMS."""
    n, h, w = 8, 96, 128
    bg = _texture((h, w), seed=1)
    obj = _texture((44, 56), seed=2)
    clean = np.repeat(bg[None], n, axis=0)
    for k in range(n):
        clean[k, 20:64, 10 + 3 * k:66 + 3 * k] = obj
    woven, weave = plant_weave(clean, seed=3)
    degraded, _ = plant_flicker(woven, seed=3)
    degraded = plant_noise(degraded, sigma=3, seed=3)
    st: dict = {}
    stabilise(degraded, stats=st, model="similarity")
    true_rel = _h(weave.matrices[1:]) @ np.linalg.inv(_h(weave.matrices[:-1]))
    err = _rms(_h(st["motions"]) @ np.linalg.inv(true_rel), (h, w))
    assert err.max() < 0.12, err
    assert st["inlier_fraction"].min() < 0.95  # the square was rejected


def test_border_filled_from_neighbours_beats_reflection() -> None:
    """The pixels a correction brings in from outside the frame are real picture from
    the neighbours: on a still shot their error against the clean picture (aligned by
    the clip's net map) is under a third of reflection's, and no pixel is black."""
    clean = _static_clip(10, (96, 128))
    woven, weave = plant_weave(clean, seed=11, angle=0.0)
    st: dict = {}
    out, corr = stabilise(woven, return_transforms=True, stats=st, smooth=np.inf, degree=0)
    ref = stabilise(woven, smooth=np.inf, degree=0, fill_radius=0)
    net = _net(corr, weave)
    h, w = weave.shape
    err_fill, err_ref = [], []
    for f in range(len(clean)):
        truth = cv2.warpAffine(clean[f], net[f, :2], (w, h), flags=cv2.INTER_CUBIC,
                               borderMode=cv2.BORDER_REFLECT)
        src = cv2.transform(np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1)
                            .reshape(-1, 1, 2).astype(np.float64),
                            cv2.invertAffineTransform(corr[f])).reshape(h, w, 2)
        hole = (src[..., 0] < 0) | (src[..., 0] > w - 1) | (src[..., 1] < 0) \
            | (src[..., 1] > h - 1)
        inner = hole.copy()
        inner[:3], inner[-3:], inner[:, :3], inner[:, -3:] = False, False, False, False
        err_fill.append(np.abs(out[f] - truth)[inner])
        err_ref.append(np.abs(ref[f] - truth)[inner])
    fill, refl = np.concatenate(err_fill).mean(), np.concatenate(err_ref).mean()
    assert st["border_fraction"].max() > 0.03
    assert fill < refl / 3, (fill, refl)
    assert out.min() > 10  # the picture is above 28 everywhere: no black border


def test_shapes_dtypes_and_zero_flows() -> None:
    clean = _static_clip(5, (40, 48))
    grey8 = np.clip(clean, 0, 255).astype(np.uint8)
    out = stabilise(grey8)
    assert out.shape == grey8.shape and out.dtype == np.uint8
    colour16 = np.repeat((clean * 257).astype(np.uint16)[..., None], 3, axis=-1)
    out16, t = stabilise(colour16, return_transforms=True)
    assert out16.shape == colour16.shape and out16.dtype == np.uint16 and t.shape == (5, 2, 3)
    unit = clean / 255.0
    zero = np.zeros((4, 40, 48, 2), np.float32)
    same, t0 = stabilise(unit, flows=zero, return_transforms=True)
    np.testing.assert_allclose(t0, np.broadcast_to(IDENTITY, (5, 2, 3)), atol=1e-12)
    np.testing.assert_allclose(same, unit, atol=1e-5)  # identity warp, up to rounding
    single = stabilise(grey8[0])
    np.testing.assert_array_equal(single, grey8[0])


def test_callback_stats_and_flows_check() -> None:
    clip = _static_clip(4, (40, 48))
    calls: list[tuple[int, int]] = []
    st: dict = {}
    stabilise(clip, callback=lambda d, t: calls.append((d, t)), stats=st, fb_check=False)
    assert calls == [(k, 7) for k in range(1, 8)]
    for key in ("seconds", "flow_seconds", "motions", "path", "smoothed", "inlier_fraction",
                "border_fraction", "reflected_fraction"):
        assert key in st
    assert st["motions"].shape == (3, 2, 3) and st["path"].shape == (4, 2, 3)
    with pytest.raises(ValueError, match="flows"):
        stabilise(clip, flows=np.zeros((4, 40, 48, 2), np.float32))


@pytest.mark.parametrize(("override", "field"), [
    ({"model": "projective"}, "model"), ({"smooth": -1.0}, "smooth"),
    ({"degree": 3}, "degree"), ({"inlier": 0.0}, "inlier"),
    ({"flow_method": "nope"}, "flow_method"), ({"fill_radius": -1}, "fill_radius"),
    ({"interpolation": "nearest"}, "interpolation"), ({"samples": 2.5}, "samples"),
])
def test_invalid_parameters_name_the_field(override: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}:"):
        stabilise(_static_clip(2, (16, 16)), **override)


def test_unknown_override_is_named() -> None:
    with pytest.raises(ValueError, match="smoothing"):
        stabilise(_static_clip(2, (16, 16)), smoothing=3)
    p = StabiliseParams(smooth=4.0)
    assert stabilise(_static_clip(2, (16, 16)), params=p, degree=0).shape == (2, 16, 16)


# --------------------------------------------------------------------------- real data


def test_carphone_crop_weave(data_root) -> None:
    """Real footage (carphone, 12 frames of 144 x 176; the person moves), planted
    weave: the jitter left is under a third of the weave's and the PSNR of the centre
    against the clean clip rises by over 4 dB."""
    from varflow.evaluation.denoising import protocol_clips

    clean = protocol_clips(data_root, 12, ("carphone",))["carphone"]
    woven, weave = plant_weave(clean, seed=0)
    out, corr = stabilise(woven, return_transforms=True)

    def psnr(a: np.ndarray) -> float:
        d = (np.clip(a, 0, 255) - clean)[:, 12:-12, 12:-12]
        return float(10 * np.log10(255.0 ** 2 / np.mean(d.astype(np.float64) ** 2)))

    none = np.broadcast_to(IDENTITY, corr.shape)
    assert _jitter(corr, weave) < _jitter(none, weave) / 3
    assert psnr(out) > psnr(woven) + 4
