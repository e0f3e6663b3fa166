"""Video denoising (issue 48): varflow.denoise, its kernels and its stream.

Ground truth is exact here: clean synthetic clips with seeded noise; PSNR on the
clean values.
"""

from __future__ import annotations

import numpy as np
import pytest

import varflow
from varflow.evaluation.denoising import clip_psnr
from varflow.restore import _nlbayes as nb
from varflow.restore.denoise import iter_denoise
from varflow.restore.methods import NLBayesParams


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((np.clip(a, 0, 255).astype(np.float64) - b) ** 2))
    return 10 * np.log10(255.0 ** 2 / mse)


def _smooth_texture(shape, seed, blur=1.5) -> np.ndarray:
    """Band-limited noise on 0-255 (periodic, so it can be shifted by any amount)."""
    rng = np.random.default_rng(seed)
    spec = np.fft.fft2(rng.normal(size=shape))
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.fftfreq(shape[1])[None, :]
    spec *= np.exp(-2 * (np.pi * blur) ** 2 * (fy ** 2 + fx ** 2))
    tex = np.real(np.fft.ifft2(spec))
    return (128 + 60 * tex / tex.std()).astype(np.float64), spec


def _shifted(spec, dx, dy) -> np.ndarray:
    """The texture of ``spec`` moved by (dx, dy) pixels (Fourier phase)."""
    h, w = spec.shape
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.fftfreq(w)[None, :]
    return np.real(np.fft.ifft2(spec * np.exp(-2j * np.pi * (fx * dx + fy * dy))))


# --------------------------------------------------------------------------- kernels


@pytest.mark.parametrize("m", [60, 12])
@pytest.mark.parametrize("oracle", [False, True])
def test_group_estimate_matches_numpy_reference(m: int, oracle: bool) -> None:
    rng = np.random.default_rng(m)
    d, nc, sigma2 = 25, 3, 400.0
    signal = rng.normal(0, 30, (nc, d, 4)) @ rng.normal(0, 1, (4, m))  # rank 4
    group = (signal + rng.normal(0, 20, (nc, d, m))).astype(np.float32)
    pilot = (signal + rng.normal(0, 5, (nc, d, m))).astype(np.float32)
    keep = np.ones(m, bool)
    out = np.zeros_like(group)
    ws = nb.group_workspace(d, m)
    p = pilot if oracle else group[:, :, :0]
    nb.estimate_group(group, p, sigma2, 1.0, 0.0, keep, out, *ws)
    ref = nb.estimate_group_reference(group, pilot if oracle else None, sigma2, 1.0, 0.0)
    np.testing.assert_allclose(out, ref, atol=2e-3 * 255)
    # and it denoises: closer to the signal than the noisy group (the first pass's
    # statistics are the noisy group's own, so it keeps more of the noise)
    gain = 0.5 if oracle else 0.85
    assert np.mean((out - signal) ** 2) < gain * np.mean((group - signal) ** 2)
    # only the kept patches are written
    keep[::2] = False
    out2 = np.full_like(group, -7.0)
    nb.estimate_group(group, p, sigma2, 1.0, 0.0, keep, out2, *ws)
    assert np.all(out2[:, :, ::2] == -7.0)
    np.testing.assert_allclose(out2[:, :, 1::2], out[:, :, 1::2], atol=1e-3)


def test_homogeneous_group_becomes_its_mean() -> None:
    rng = np.random.default_rng(0)
    group = (50 + rng.normal(0, 10, (1, 25, 40))).astype(np.float32)
    out = np.zeros_like(group)
    ws = nb.group_workspace(25, 40)
    nb.estimate_group(group, group[:, :, :0], 100.0, 1.0, 1.05, np.ones(40, bool), out, *ws)
    np.testing.assert_allclose(out, group.mean(), rtol=1e-5)
    ref = nb.estimate_group_reference(group, None, 100.0, 1.0, 1.05)
    np.testing.assert_allclose(out, ref, rtol=1e-5)


def test_band_height_keeps_phases_apart() -> None:
    for search in (1, 7, 20):
        for patch in (3, 5, 7):
            band = nb.band_height(search, patch)
            # a band writes search rows above and search + patch - 1 below its own;
            # the next band of its phase starts two bands later
            assert band >= 2 * search + patch - 1


@pytest.mark.parametrize("count, n", [(1, 60), (60, 60), (61, 60), (415, 60), (415, 90),
                                      (415, 2), (300, 299)])
def test_nearest_candidates_match_a_stable_sort(count: int, n: int) -> None:
    """The group is the first n candidates in (distance, order found): NumPy's
    lexicographic sort of the same keys, ties included."""
    rng = np.random.default_rng(count + n)
    cd = rng.integers(0, 40, count).astype(np.float64)  # many ties
    cd[0] = -1.0
    idx = np.empty(count, np.int64)
    order = np.full(n, -1, np.int64)
    got = nb._nearest(cd, idx, count, n, order)
    want = np.lexsort((np.arange(count), cd))[:n]
    assert got == len(want)
    np.testing.assert_array_equal(order[:got], want)
    # the quickselect alone: the k-th in place, every one before it comes first
    for k in (0, count // 2, count - 1):
        idx[:count] = np.arange(count)
        nb._select(cd, idx, count, k)
        assert idx[k] == np.lexsort((np.arange(count), cd))[k]
        assert set(idx[:k]) == set(np.lexsort((np.arange(count), cd))[:k])


# --------------------------------------------------------------------------- motion


def test_static_white_noise_texture_gains_the_window() -> None:
    """F = 2r + 1 frames of one white-noise texture: the middle frame gains at least
    10 log10(F) - 1 dB (the temporal average of its copies, nothing spatial helps)."""
    r = 3
    f = 2 * r + 1
    rng = np.random.default_rng(1)
    tex = rng.uniform(0, 255, (48, 64))
    clean = np.repeat(tex[None], f, 0)
    noisy = clean + rng.normal(0, 20, clean.shape)
    out = varflow.denoise(noisy, 20.0, radius=r)
    gain = _psnr(out[r], clean[r]) - _psnr(noisy[r], clean[r])
    assert gain >= 10 * np.log10(f) - 1, gain


def test_moving_texture_within_1_db_of_static(one_numba_thread) -> None:
    """The same band-limited texture, still and moving by sub-pixel steps: motion
    compensation brings the moving clip within 1 dB of the still one."""
    r = 2
    shape = (64, 80)
    base, spec = _smooth_texture(shape, seed=4, blur=2.5)
    rng = np.random.default_rng(5)
    still = np.repeat(base[None], 2 * r + 1, 0)
    moving = np.stack([_shifted(spec, 0.6 * k, 0.35 * k) for k in range(2 * r + 1)])
    moving = 128 + 60 * (moving - np.real(np.fft.ifft2(spec)).mean()) / np.real(
        np.fft.ifft2(spec)).std()
    scores = {}
    for name, clean in (("still", still), ("moving", moving)):
        noisy = clean + rng.normal(0, 25, clean.shape)
        out = varflow.denoise(noisy, 25.0, radius=r)
        scores[name] = _psnr(out[r], clean[r])
        assert scores[name] > _psnr(noisy[r], clean[r]) + 6
    assert scores["moving"] >= scores["still"] - 1.0, scores


def test_luma_final_matches_the_colour_search(one_numba_thread) -> None:
    """The final pass's patch search on the first estimate's luminance only
    (``luma_final``) stays within 0.5 dB of the search on all channels on a moving
    colour texture, and both gain more than 6 dB."""
    shape = (56, 72)
    base, spec = _smooth_texture(shape, seed=8, blur=2.0)
    frames = np.stack([_shifted(spec, 0.5 * k, 0.3 * k) for k in range(5)])
    frames = (frames - frames.mean()) / frames.std()
    clean = 128 + 50 * np.stack([frames, np.roll(frames, 3, axis=1),
                                 np.roll(frames, 5, axis=2)], axis=-1)
    noisy = clean + np.random.default_rng(9).normal(0, 20, clean.shape)
    scores = {}
    for luma in (False, True):
        out = varflow.denoise(noisy, 20.0, radius=2, luma_final=luma)
        scores[luma] = _psnr(out[2], clean[2])
    assert min(scores.values()) > _psnr(noisy[2], clean[2]) + 6, scores
    assert abs(scores[True] - scores[False]) < 0.5, scores


def test_occluding_object_leaves_no_ghost(one_numba_thread) -> None:
    """A square slides over a still background: where it uncovers the background the
    error is within 1 dB of the rest of the frame (no ghost of the square)."""
    r = 2
    f = 2 * r + 1
    h, w = 64, 96
    bg, _ = _smooth_texture((h, w), seed=7, blur=2.0)
    sq, _ = _smooth_texture((24, 24), seed=8, blur=1.0)
    sq = 255 - 0.5 * sq  # bright, unlike the background
    clean = np.repeat(bg[None], f, 0)
    x0 = [6 + 8 * k for k in range(f)]
    for k in range(f):
        clean[k, 20:44, x0[k]:x0[k] + 24] = sq
    noisy = clean + np.random.default_rng(9).normal(0, 20, clean.shape)
    out = varflow.denoise(noisy, 20.0, radius=r)
    t = r
    uncovered = np.zeros((h, w), bool)  # covered in the frames before t, not in t
    for k in range(t):
        uncovered[20:44, x0[k]:x0[k] + 24] = True
    uncovered[20:44, x0[t]:x0[t] + 24] = False
    rest = ~uncovered
    rest[20:44, x0[t]:x0[t] + 24] = False
    err = (np.clip(out[t], 0, 255) - clean[t]) ** 2
    psnr_uncovered = 10 * np.log10(255 ** 2 / err[uncovered].mean())
    psnr_rest = 10 * np.log10(255 ** 2 / err[rest].mean())
    assert uncovered.sum() > 300
    assert psnr_uncovered >= psnr_rest - 1.0, (psnr_uncovered, psnr_rest)


# --------------------------------------------------------------------------- API


def test_grain_endpoints_and_between() -> None:
    rng = np.random.default_rng(2)
    clean, _ = _smooth_texture((40, 48), seed=2, blur=3.0)
    noisy = (clean[None] + rng.normal(0, 15, (3, 40, 48))).astype(np.float32)
    full = varflow.denoise(noisy, 15.0, radius=1)
    assert np.array_equal(varflow.denoise(noisy, 15.0, radius=1, grain=1.0), noisy)
    assert np.array_equal(varflow.denoise(noisy, 15.0, radius=1, grain=0.0), full)
    half = varflow.denoise(noisy, 15.0, radius=1, grain=0.5)
    np.testing.assert_allclose(half, 0.5 * (full + noisy), atol=1e-3)


@pytest.mark.parametrize("dtype, top", [(np.uint8, 255), (np.uint16, 65535),
                                        (np.float32, 1.0), (np.float64, 1000.0)])
def test_dtype_shape_and_units(dtype, top) -> None:
    rng = np.random.default_rng(3)
    tex, _ = _smooth_texture((40, 48), seed=3, blur=3.0)
    clean = np.stack([tex] * 3)[..., None].repeat(3, -1) / 255 * top  # (3, H, W, 3)
    sigma = 0.06 * top
    noisy = clean + rng.normal(0, sigma, clean.shape)
    if dtype in (np.uint8, np.uint16):
        noisy = np.clip(np.rint(noisy), 0, top)
    noisy = noisy.astype(dtype)
    out = varflow.denoise(noisy, sigma, radius=1)
    assert out.dtype == noisy.dtype and out.shape == noisy.shape
    err_in = np.mean((noisy.astype(np.float64) - clean) ** 2)
    err_out = np.mean((out.astype(np.float64) - clean) ** 2)
    assert err_out < 0.3 * err_in  # sigma in the input's units, not rescaled
    # grey clip, one grey image, one colour image, a list of frames
    assert varflow.denoise(noisy[..., 0], sigma, radius=1).shape == noisy.shape[:3]
    assert varflow.denoise(noisy[0, ..., 0], sigma).shape == noisy.shape[1:3]
    assert varflow.denoise(noisy[0], sigma).shape == noisy.shape[1:]
    assert varflow.denoise(list(noisy), sigma, radius=1).shape == noisy.shape


def test_sigma_zero_copies_and_bad_inputs() -> None:
    a = np.random.default_rng(0).uniform(0, 1, (2, 16, 16)).astype(np.float32)
    out = varflow.denoise(a, 0)
    assert np.array_equal(out, a) and out is not a
    bad = a.copy()
    bad[1, 3, 3] = np.nan
    with pytest.raises(ValueError, match="frame 1: contains NaN"):
        varflow.denoise(bad, 0.1)
    with pytest.raises(ValueError, match="sigma"):
        varflow.denoise(a, -1.0)
    with pytest.raises(ValueError, match="too small"):
        varflow.denoise(a[:, :4, :4], 0.1)
    with pytest.raises(ValueError, match="dtype"):
        varflow.denoise(a.astype(bool), 0.1)
    with pytest.raises(ValueError, match="frame 1: shape"):
        varflow.denoise([a[0], a[1, :8]], 0.1)
    with pytest.raises(ValueError, match="method: unknown restoration method"):
        varflow.denoise(a, 0.1, method="bm3d")
    with pytest.raises(ValueError, match="radius"):
        varflow.denoise(a, 0.1, radius=-1)
    with pytest.raises(ValueError, match="grain"):
        varflow.denoise(a, 0.1, grain=1.5)
    with pytest.raises(ValueError, match="stride"):
        NLBayesParams(stride=9)
    with pytest.raises(ValueError, match="^luma_final:"):
        NLBayesParams(luma_final=1)


def test_unknown_sigma_is_estimated() -> None:
    rng = np.random.default_rng(4)
    tex, _ = _smooth_texture((64, 80), seed=6, blur=3.0)
    clean = np.repeat(tex[None], 3, 0)
    noisy = clean + rng.normal(0, 12, clean.shape)
    st: dict = {}
    out = varflow.denoise(noisy, radius=1, stats=st)
    assert abs(st["sigma"] / 12 - 1) < 0.1, st["sigma"]
    known = varflow.denoise(noisy, 12.0, radius=1)
    assert abs(_psnr(out[1], clean[1]) - _psnr(known[1], clean[1])) < 0.3


def test_stream_equals_whole_clip_and_respects_cuts() -> None:
    rng = np.random.default_rng(6)
    a, _ = _smooth_texture((32, 40), seed=1)
    b, _ = _smooth_texture((32, 40), seed=2)
    clean = np.stack([a] * 5 + [b] * 4)
    noisy = (clean + rng.normal(0, 15, clean.shape)).astype(np.float32)
    whole = varflow.denoise(noisy[:5], 15.0, radius=2)
    st: dict = {}
    streamed = list(iter_denoise(iter(noisy[:5]), 15.0, radius=2, chunk=2, stats=st))
    assert st["frames"] == 5
    np.testing.assert_array_equal(np.stack(streamed), whole)
    # a cut between the two scenes: each scene as if alone
    from varflow.retime.stream import is_scene_cut

    st = {}
    out = np.stack(list(iter_denoise(iter(noisy), 15.0, radius=2, chunk=3,
                                     is_cut=is_scene_cut, stats=st)))
    assert st["cuts"] == 1
    np.testing.assert_array_equal(out[:5], whole)
    np.testing.assert_array_equal(out[5:], varflow.denoise(noisy[5:], 15.0, radius=2))


def test_registry_and_presets() -> None:
    assert varflow.restoration_methods() == ["nlbayes", "nlbayes-fast"]
    assert varflow.RESTORE.default == "nlbayes"
    fast = varflow.RESTORE["nlbayes-fast"].defaults()
    assert fast.radius < NLBayesParams().radius and fast.stride > NLBayesParams().stride
    p = varflow.RESTORE.make_params("nlbayes", radius=2, data_weight=40.0)
    assert p.radius == 2 and p.flow_params.data_weight == 40.0


def test_protocol_clip_beats_per_frame(data_root) -> None:
    """Real footage (a crop of carphone, 7 frames, σ 30): the motion-compensated
    estimate beats the same method frame by frame by over 1.5 dB."""
    from varflow.evaluation.denoising import add_noise, protocol_clips

    clean = protocol_clips(data_root, 7, ("carphone",))["carphone"][:, :96, :128]
    noisy = add_noise(clean, 30)
    motion = varflow.denoise(noisy, 30.0, radius=3)
    alone = varflow.denoise(noisy, 30.0, radius=0)
    assert clip_psnr(motion, clean) > clip_psnr(alone, clean) + 1.5
    assert clip_psnr(motion, clean) > clip_psnr(noisy, clean) + 10


@pytest.mark.parametrize(("radius", "chunk", "passes"), [(2, 1, 2), (2, 3, 2), (1, 2, 1)])
def test_stream_equals_whole_clip_long(radius: int, chunk: int, passes: int) -> None:
    """A clip much longer than the window: each frame gathers the groups of the
    frames around it, and the stream takes them in the same order."""
    rng = np.random.default_rng(1)
    base = rng.normal(128, 30, (40, 60, 3)).astype(np.float32)
    clean = np.stack([np.roll(base, k, axis=1) for k in range(14)])
    noisy = (clean + rng.normal(0, 15, clean.shape)).astype(np.float32)
    whole = varflow.denoise(noisy, 15.0, radius=radius, passes=passes)
    streamed = np.stack(list(iter_denoise(iter(noisy), 15.0, radius=radius, chunk=chunk,
                                          passes=passes)))
    np.testing.assert_array_equal(streamed, whole)
