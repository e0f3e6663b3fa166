"""Edge-aware photometric cost, candidate fusion and the boundary repair (ops/fusion.py)."""

import numpy as np
import pytest

from varflow.generators.pairs import TextureField
from varflow.ops import fusion
from varflow.ops.fusion import noise_sigma, repair_margin


def _two_layer_pair(shape=(48, 64), shift_bg=(1.0, 0.0), shift_fg=(-3.0, 2.0), seed=3):
    """Frame 0/1 of a textured disc moving over a textured background, and the exact flow."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    bg, fg = TextureField(3, seed), TextureField(3, seed + 7)
    cy, cx, r = h / 2, w / 2, min(h, w) / 4
    disc0 = (yy - cy) ** 2 + (xx - cx) ** 2 <= r * r
    f0 = np.where(disc0[..., None], fg(xx, yy, 64.0), bg(xx, yy, 64.0))
    # frame 1: background moved by shift_bg, disc by shift_fg
    bx, by = xx - shift_bg[0], yy - shift_bg[1]
    fx, fy = xx - shift_fg[0], yy - shift_fg[1]
    disc1 = (fy - cy) ** 2 + (fx - cx) ** 2 <= r * r
    f1 = np.where(disc1[..., None], fg(fx, fy, 64.0), bg(bx, by, 64.0))
    flow = np.empty((h, w, 2), np.float32)
    flow[...] = shift_bg
    flow[disc0] = shift_fg
    return f0.astype(np.float32), f1.astype(np.float32), flow, disc0


def test_support_weights_engines_agree_and_normalise() -> None:
    rng = np.random.default_rng(0)
    img = rng.random((20, 30, 3), dtype=np.float32)
    a = fusion.support_weights(img, 2, 0.1)
    b = fusion.support_weights(img, 2, 0.1, engine="numpy")
    assert a.shape == (25, 20, 30)
    np.testing.assert_allclose(a, b, atol=1e-6)
    np.testing.assert_allclose(a.sum(0), 1.0, atol=1e-5)
    # a neighbour of another colour weighs less than one of the same colour
    img2 = np.zeros((5, 5, 1), np.float32)
    img2[:, 3:] = 1.0
    wts = fusion.support_weights(img2, 1, 0.1)
    k_left, k_right = 3, 5  # offsets (0, -1) and (0, +1)
    assert wts[k_left, 2, 2] > 100 * wts[k_right, 2, 2]


def test_vectorised_exp_matches_libm() -> None:
    import numba as nb

    x = -np.linspace(0.0, 200.0, 200001).astype(np.float32)
    out = np.empty_like(x)
    bits = np.empty(x.size, np.int32)
    nb.njit(lambda a, b, c: fusion._exp_neg_row(a, b, c))(x, out, bits)
    ref = np.exp(x.astype(np.float64))
    normal = x > -80.0
    assert np.max(np.abs(out[normal] / ref[normal] - 1.0)) < 1e-7
    assert out[0] == 1.0
    assert np.all(out[~normal] < 2e-35) and np.all(out[~normal] >= 0)  # clamped, not NaN


def test_support_weights_engines_agree_on_grey_and_extreme_gamma() -> None:
    rng = np.random.default_rng(1)
    img = rng.random((9, 14, 1), dtype=np.float32)
    for gamma, radius in ((0.1, 2), (1e-3, 1), (5.0, 3)):
        a = fusion.support_weights(img, radius, gamma)
        b = fusion.support_weights(img, radius, gamma, engine="numpy")
        np.testing.assert_allclose(a, b, atol=1e-6)
        assert np.all(np.isfinite(a))


@pytest.mark.parametrize("channels", [1, 3])
def test_candidate_costs_equal_flow_cost_with_weight_planes(channels) -> None:
    f0, f1, flow, _ = _two_layer_pair()
    if channels == 1:
        f0, f1 = (x.mean(axis=2, keepdims=True) for x in (f0, f1))
    cands = [flow, flow + np.float32(1.5), flow * np.float32(-1.0)]
    cands[2][:3] = 40.0  # some targets outside the frame
    for radius, gamma in ((2, 0.1), (1, 0.05), (0, 0.1)):
        got = fusion.candidate_costs(f0, f1, cands, radius, gamma, 0.1)
        ref = fusion.candidate_costs(f0, f1, cands, radius, gamma, 0.1, engine="numpy")
        wts = fusion.support_weights(f0, radius, gamma)
        assert got.shape == (3,) + f0.shape[:2] and got.dtype == np.float32
        for k, c in enumerate(cands):
            np.testing.assert_allclose(got[k], fusion.flow_cost(f0, f1, c, wts, 0.1),
                                       atol=2e-6)
        np.testing.assert_allclose(got, ref, atol=2e-6)
    assert got[0].mean() < got[1].mean()
    with pytest.raises(ValueError, match="candidates"):
        fusion.candidate_costs(f0, f1, [])
    with pytest.raises(ValueError, match=r"candidates\[1\]"):
        fusion.candidate_costs(f0, f1, [flow, flow[:-1]])


def test_flow_cost_engines_agree_and_rank_the_true_flow_first() -> None:
    f0, f1, flow, _ = _two_layer_pair()
    wts = fusion.support_weights(f0)
    c_true = fusion.flow_cost(f0, f1, flow, wts)
    np.testing.assert_allclose(c_true, fusion.flow_cost(f0, f1, flow, wts, engine="numpy"),
                               atol=1e-5)
    wrong = flow + np.float32(1.5)
    c_wrong = fusion.flow_cost(f0, f1, wrong, wts)
    inner = (slice(6, -6), slice(6, -6))
    assert c_true[inner].mean() < 0.3 * c_wrong[inner].mean()
    # a target outside the frame costs the truncation
    far = np.full_like(flow, 500.0)
    np.testing.assert_allclose(fusion.flow_cost(f0, f1, far, wts, truncation=0.07), 0.07,
                               atol=1e-6)


def test_fuse_keeps_the_better_candidate_per_pixel() -> None:
    f0, f1, flow, disc = _two_layer_pair()
    wts = fusion.support_weights(f0)
    bg_only = np.empty_like(flow)
    bg_only[...] = flow[~disc][0]
    fg_only = np.empty_like(flow)
    fg_only[...] = flow[disc][0]
    fused, choice = fusion.fuse(f0, f1, [bg_only, fg_only], wts)
    err = np.hypot(*(fused - flow).transpose(2, 0, 1))
    assert (err < 1e-6).mean() > 0.97
    assert choice[disc].mean() > 0.95 and choice[~disc].mean() < 0.03
    # ties keep the first candidate
    same, ch = fusion.fuse(f0, f1, [flow, flow.copy()], wts)
    assert not ch.any() and np.array_equal(same, flow)


def test_census_planes_ignore_a_brightness_offset_and_rank_under_a_contrast_change() -> None:
    f0, f1, flow, disc = _two_layer_pair()
    c0 = fusion.census_planes(f0)
    assert c0.shape == f0.shape[:2] + (8,) and c0.dtype == np.float32
    assert np.abs(c0).max() <= 0.5
    # a brightness offset leaves the planes unchanged (to rounding)
    np.testing.assert_allclose(fusion.census_planes(f0 + 0.2), c0, atol=2e-5)
    # the right neighbour's plane is 1/2 tanh((I(x+1) - I(x)) / eps)
    g = f0.mean(axis=2)
    k = fusion.CENSUS_OFFSETS.index((0, 1))
    np.testing.assert_allclose(c0[:, :-1, k], 0.5 * np.tanh((g[:, 1:] - g[:, :-1]) / 0.02),
                               atol=1e-6)
    assert np.all(c0[:, -1, k] == 0)  # the replicated border
    # frame 1 darkened to 60 % and offset: the colour cost of the true flow is
    # truncated nearly everywhere, the census cost still ranks it far before a wrong one
    dark = (0.6 * f1 + 0.3).astype(np.float32)
    wts = fusion.support_weights(f0)
    wrong = flow.copy()
    wrong[..., 0] += 2.0
    inner = (slice(6, -6), slice(6, -6))
    colour = fusion.flow_cost(f0, dark, flow, wts)
    assert colour[inner].mean() > 0.08  # truncation 0.1: measured 0.089
    c1 = fusion.census_planes(dark)
    c_true = fusion.flow_cost(c0, c1, flow, wts, truncation=0.5)
    c_wrong = fusion.flow_cost(c0, c1, wrong, wts, truncation=0.5)
    # measured 0.086 against 0.334 (the colour cost: 0.089 against 0.092)
    assert c_true[inner].mean() < 0.5 * c_wrong[inner].mean()
    with pytest.raises(ValueError, match="eps"):
        fusion.census_planes(f0, eps=0.0)


def test_repair_removes_a_band_of_bled_motion() -> None:
    """A 3 px band of background motion inside the disc edge is put right."""
    from scipy import ndimage

    f0, f1, flow, disc = _two_layer_pair(shape=(64, 80))
    wts = fusion.support_weights(f0)
    inner = ndimage.binary_erosion(disc, iterations=3)
    bled = flow.copy()
    bled[disc & ~inner] = flow[~disc][0]
    err0 = np.hypot(*(bled - flow).transpose(2, 0, 1))
    st: dict = {}
    fixed = fusion.repair(f0, f1, bled, wts, distances=(2, 4, 8), stats=st)
    err1 = np.hypot(*(fixed - flow).transpose(2, 0, 1))
    band = disc & ~inner
    assert err0[band].mean() > 3.0
    assert err1[band].mean() < 0.1 * err0[band].mean()
    # nothing else broken, except background points hidden by the disc in frame 1
    h, w = disc.shape
    yy, xx = np.mgrid[0:h, 0:w]
    ty = np.clip(np.rint(yy + flow[..., 1]).astype(int), 0, h - 1)
    tx = np.clip(np.rint(xx + flow[..., 0]).astype(int), 0, w - 1)
    fy, fx = flow[disc][0][1], flow[disc][0][0]
    hidden = ~disc & ndimage.binary_dilation(
        disc[np.clip(ty - int(fy), 0, h - 1), np.clip(tx - int(fx), 0, w - 1)], iterations=1)
    rest = ~band & ~hidden
    assert err1[rest].mean() <= err0[rest].mean() + 1e-3
    assert 0 < st["changed"] < 0.2
    np.testing.assert_allclose(
        fixed, fusion.repair(f0, f1, bled, wts, distances=(2, 4, 8), engine="numpy"), atol=1e-6)


def test_repair_margin_keeps_a_smooth_field() -> None:
    """An exact smooth field is not swapped for its neighbours' vectors."""
    h, w = 48, 64
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    tex = TextureField(3, 1)
    a = np.array([[0.02, -0.01], [0.015, 0.01]])
    u = a[0, 0] * (xx - w / 2) + a[0, 1] * (yy - h / 2) + 1.0
    v = a[1, 0] * (xx - w / 2) + a[1, 1] * (yy - h / 2) - 0.5
    f0 = tex(xx, yy, 64.0).astype(np.float32)
    # frame 1 sampled at the inverse map (x + w(x) carries frame-0 content)
    m = np.eye(2) + a
    inv = np.linalg.inv(m)
    px = inv[0, 0] * (xx - w / 2 - 1.0) + inv[0, 1] * (yy - h / 2 + 0.5) + w / 2
    py = inv[1, 0] * (xx - w / 2 - 1.0) + inv[1, 1] * (yy - h / 2 + 0.5) + h / 2
    f1 = tex(px, py, 64.0).astype(np.float32)
    flow = np.stack([u, v], -1).astype(np.float32)
    wts = fusion.support_weights(f0)
    st: dict = {}
    fixed = fusion.repair(f0, f1, flow, wts, stats=st)
    # bilinear interpolation error lets a few pixels take a neighbour's vector (0.3 %,
    # 0.12 px here); without the margin 3 % change, by up to 0.27 px
    assert st["changed"] < 0.01
    assert np.abs(fixed - flow).max() < 0.15
    loose = fusion.repair(f0, f1, flow, wts, margin=0.0, stats=st)
    assert st["changed"] > 0.01 and np.abs(loose - flow).max() > 0.15


def test_argument_errors() -> None:
    img = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(ValueError, match="engine"):
        fusion.support_weights(img, engine="gpu")
    with pytest.raises(ValueError, match="gamma"):
        fusion.support_weights(img, gamma=0)
    wts = fusion.support_weights(img)
    with pytest.raises(ValueError, match="flow"):
        fusion.flow_cost(img, img, np.zeros((8, 7, 2), np.float32), wts)
    with pytest.raises(ValueError, match="candidates"):
        fusion.fuse(img, img, [], wts)


def test_noise_sigma_recovers_added_gaussian_noise() -> None:
    """Immerkær's estimate on a smooth image plus white noise of known σ."""
    yy, xx = np.mgrid[0:120, 0:160].astype(np.float32)
    smooth = 0.5 + 0.2 * np.sin(xx / 17.0) * np.cos(yy / 23.0)
    rng = np.random.default_rng(3)
    assert noise_sigma(smooth) < 0.002
    for sigma in (0.01, 0.04):
        noisy = smooth + rng.normal(0, sigma, smooth.shape).astype(np.float32)
        assert abs(noise_sigma(noisy) - sigma) < 0.05 * sigma
        colour = np.stack([noisy, noisy, noisy], -1)
        assert noise_sigma(colour) == pytest.approx(noise_sigma(noisy), rel=1e-5)
    with pytest.raises(ValueError, match="image"):
        noise_sigma(np.zeros((2, 5)))


def test_repair_margin_grows_with_the_noise() -> None:
    yy, xx = np.mgrid[0:64, 0:80].astype(np.float32)
    clean = 0.5 + 0.2 * np.sin(xx / 9.0)
    noisy = clean + np.random.default_rng(0).normal(0, 0.04, clean.shape).astype(np.float32)
    assert repair_margin(clean, clean) == 0.005  # the floor
    m = repair_margin(noisy, noisy)
    assert m == pytest.approx(0.5 * np.sqrt(2) * noise_sigma(noisy), rel=1e-6)
    assert 0.025 < m < 0.032


def _relit(img: np.ndarray, gain0: float, gx: float, gy: float, offset: float) -> np.ndarray:
    """``img`` under a gain varying linearly across the frame, plus an offset."""
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    xs, ys = 2.0 * xx / (w - 1) - 1.0, 2.0 * yy / (h - 1) - 1.0
    gain = (gain0 + gx * xs + gy * ys)[..., None]
    return np.clip(gain * img + offset, 0.0, 1.0).astype(np.float32)


def test_relight_recovers_a_planted_change_of_light() -> None:
    """A gain gradient and an offset along the exact flow are recovered to rounding;
    no change of light is the identity; occluded, wrongly matched pixels are trimmed."""
    f0, f1, flow, disc = _two_layer_pair(shape=(64, 80))
    f0 = 0.15 + 0.7 * f0  # away from the clipping at 0 and 1
    f1 = 0.15 + 0.7 * f1
    lit = _relit(f1, 1.08, 0.05, -0.04, -0.03)
    # what frame 0 looks like under frame 1's light, where the flow is right
    want = _relit(f0, 1.08, 0.05, -0.04, -0.03)
    got = fusion.relight(f0, lit, flow)
    assert np.abs(got - want).max() < 2e-3
    assert np.abs(fusion.relight(f0, f1, flow) - f0).max() < 1e-3
    # a wrong vector on the disc (a fifth of the pixels) does not pull the fit
    wrong = flow.copy()
    wrong[disc] = flow[~disc][0]
    assert np.abs(fusion.relight(f0, lit, wrong) - want)[~disc].max() < 5e-3


def test_relit_repair_keeps_the_true_field_under_a_change_of_light() -> None:
    """Under a gain gradient the colour repair swaps true vectors for wrong ones that
    land on a matching brightness; the relit and the census repairs put the bled band
    right and keep the rest."""
    from scipy import ndimage

    f0, f1, flow, disc = _two_layer_pair(shape=(64, 80))
    lit = _relit(0.15 + 0.7 * f1, 1.2, 0.15, 0.1, 0.0)
    f0 = 0.15 + 0.7 * f0
    wts = fusion.support_weights(f0)
    inner = ndimage.binary_erosion(disc, iterations=3)
    band = disc & ~inner
    bled = flow.copy()
    bled[band] = flow[~disc][0]
    errs = {}
    for cost in ("colour", "relit", "census"):
        fixed = fusion.repair_with(cost, f0, lit, bled, wts)
        err = np.hypot(*(fixed - flow).transpose(2, 0, 1))
        errs[cost] = (err[band].mean(), float((err[~band] > 0.5).mean()))
    # measured: band 3.09 / 0.0 / 0.09 px, elsewhere 3.1 / 0.4 / 2.1 % wrong by > 0.5 px
    assert errs["colour"][0] > 2.0
    assert errs["relit"][0] < 0.1 and errs["census"][0] < 0.5
    assert errs["relit"][1] < 0.015 < errs["colour"][1]
    # with no change of light the relit repair is the colour repair
    same = 0.15 + 0.7 * f1
    np.testing.assert_allclose(fusion.repair_with("relit", f0, same, bled, wts),
                               fusion.repair_with("colour", f0, same, bled, wts), atol=1e-5)
    with pytest.raises(ValueError, match="cost"):
        fusion.repair_with("gradient", f0, lit, bled, wts)
