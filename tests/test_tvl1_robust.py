"""TV-L1 robust data terms: gradient constancy (γ, σ_g) and normalisation (ζ)."""

import math

import numpy as np
import pytest

import varflow
from varflow.generators.pairs import synthetic_pair
from varflow.ops.differences import image_derivatives
from varflow.ops.warp import warp_bicubic
from varflow.twoframe.coarse_to_fine import LevelState
from varflow.twoframe.params import preset
from varflow.twoframe.tvl1 import (
    TVL1Params,
    TVL1State,
    data_channels,
    data_channels_numpy,
    linearise,
    solve_warp,
    tvl1,
)

ROBUST = {"data_weight": 5.0, "gradient_weight": 40.0}


def aee(a, b):
    return float(np.linalg.norm(a - b, axis=-1).mean())


def warped_inputs(f0, f1, flow0):
    nc = f1.shape[2]
    dx, dy = image_derivatives(f1)
    warped, inside = warp_bicubic(np.concatenate([f1, dx, dy], 2), flow0)
    return f0, warped[..., :nc], warped[..., nc:2 * nc], warped[..., 2 * nc:], inside, flow0


@pytest.fixture(scope="module")
def gain_pair():
    """A 2.5 px colour translation whose second frame has a brightness gain of 1.2."""
    f0, f1, gt = synthetic_pair("translation", shape=(96, 128), magnitude=2.5, channels=3,
                                seed=1)
    return f0, np.clip(1.2 * f1, 0, 1).astype(np.float32), gt


# ------------------------------------------------------------------ defaults


def test_plain_energy_has_the_robust_terms_off():
    p = preset("plain")
    assert p.gradient_weight == 0.0 and p.data_normalisation == 0.0 and p.huber == 0.0
    assert p.noise_reference == 0.0 and not p.sharpness_match and not p.grey
    assert p.gradient_sigma == 1.0  # read only when gradient_weight > 0


def test_tvl1_defaults_use_the_gradient_term_and_huber_tv():
    p = TVL1Params()
    assert (p.data_weight, p.gradient_weight, p.huber, p.edge_weight) == (15.0, 140.0, 0.02, 30.0)
    assert p.grey and p.sharpness_match and p.noise_reference == 0.01
    assert p.texture_alpha == 0.3 and p.max_iterations == 24


def test_zero_weights_reduce_exactly_to_plain_tvl1(gain_pair):
    f0, f1, _ = gain_pair
    plain = tvl1(f0, f1, preset("plain"))
    # σ_g alone changes nothing while γ = 0
    same = tvl1(f0, f1, preset("plain", gradient_weight=0.0, gradient_sigma=2.5,
                                   data_normalisation=0.0))
    np.testing.assert_array_equal(plain, same)
    args = warped_inputs(f0, f1, np.zeros(f0.shape[:2] + (2,), np.float32))
    state = TVL1State()
    for got, want in zip(data_channels(*args, preset("plain"), state), linearise(*args),
                         strict=True):
        np.testing.assert_array_equal(got, want)
    assert state == TVL1State()  # nothing cached, no extra dual variables


# ------------------------------------------------------------------ the channels


def test_gradient_channels_are_the_linearised_gradient_constancy():
    f0, f1, gt = synthetic_pair("smooth", shape=(40, 48), magnitude=1.5, channels=3, seed=2)
    flow0 = (0.5 * gt).astype(np.float32)
    args = warped_inputs(f0, f1, flow0)
    p = preset("plain", data_weight=8.0, gradient_weight=20.0, gradient_sigma=0.0)
    ix, iy, a = data_channels(*args, p, TVL1State())
    assert ix.shape == iy.shape == a.shape == (9, 40, 48)
    _, _, i1x, i1y, inside, _ = args
    i0x, i0y = image_derivatives(f0)
    hxx, hxy = image_derivatives(i1x)
    hyx, hyy = image_derivatives(i1y)
    hxy = 0.5 * (hxy + hyx)
    w, m = 20.0 / 8.0, inside[..., None]
    u, v = flow0[..., :1], flow0[..., 1:]
    want_ax = w * m * (i1x - i0x - hxx * u - hxy * v)
    want_ay = w * m * (i1y - i0y - hxy * u - hyy * v)
    np.testing.assert_allclose(np.moveaxis(a[3:6], 0, -1), want_ax, atol=1e-6)
    np.testing.assert_allclose(np.moveaxis(a[6:9], 0, -1), want_ay, atol=1e-6)
    np.testing.assert_allclose(np.moveaxis(ix[3:6], 0, -1), w * m * hxx, atol=1e-6)
    np.testing.assert_allclose(np.moveaxis(iy[6:9], 0, -1), w * m * hyy, atol=1e-6)
    # the colour channels are those of the plain term
    np.testing.assert_array_equal(a[:3], linearise(*args)[2])


def test_gradient_term_ignores_an_additive_brightness_offset():
    f0, f1, gt = synthetic_pair("translation", shape=(48, 56), magnitude=1.5, channels=1, seed=3)
    brighter = (f1 + 0.05).astype(np.float32)  # not clipped: the channels take any values
    p = preset("plain", gradient_weight=40.0, gradient_sigma=0.0)
    gt = gt.astype(np.float32)
    _, _, a = data_channels(*warped_inputs(f0, f1, gt), p, TVL1State())
    _, _, b = data_channels(*warped_inputs(f0, brighter, gt), p, TVL1State())
    np.testing.assert_allclose(a[1:], b[1:], atol=1e-5)  # gradient channels: unchanged
    assert np.abs(b[0] - a[0]).mean() > 0.04  # the colour channel sees the offset


def test_normalised_channels_have_gradients_below_one():
    f0, f1, gt = synthetic_pair("smooth", shape=(40, 48), magnitude=1.5, channels=3, seed=2)
    args = warped_inputs(f0, f1, np.zeros_like(gt))
    p = preset("plain", data_weight=2.0, gradient_weight=6.0, data_normalisation=0.05)
    ix, iy, a = data_channels(*args, p, TVL1State())
    plain = data_channels(*args, p.replace(data_normalisation=0.0), TVL1State())
    w = np.array([1.0] * 3 + [3.0] * 6)[:, None, None]  # channel weights γ/λ
    nrm = np.sqrt(ix**2 + iy**2) / w
    assert nrm.max() < 1.0 and nrm.max() > 0.9  # |∇ρ| / sqrt(|∇ρ|² + ζ²)
    # the scale is the same for the residual and its gradient of a channel
    scale = a / np.where(plain[2] == 0, 1, plain[2])
    ok = np.abs(plain[2]) > 1e-3
    want = 1 / np.sqrt((plain[0] ** 2 + plain[1] ** 2) / w**2 + 0.05**2)
    np.testing.assert_allclose(scale[ok], want[ok], rtol=1e-4)


def test_gradient_sigma_follows_the_pyramid_level():
    f0, f1, gt = synthetic_pair("smooth", shape=(40, 48), magnitude=1.5, channels=1, seed=2)
    args = warped_inputs(f0, f1, np.zeros_like(gt))
    p = preset("plain", gradient_weight=10.0, gradient_sigma=2.0, scale_factor=0.5)
    at_level_1 = data_channels(*args, p, TVL1State(level=1))
    sigma_1 = data_channels(*args, p.replace(gradient_sigma=1.0), TVL1State(level=0))
    for x, y in zip(at_level_1, sigma_1, strict=True):
        np.testing.assert_array_equal(x, y)


# ------------------------------------------------------------------ engines


@pytest.mark.parametrize("extra", [
    {},
    {"gradient_weight": 30.0},
    {"gradient_weight": 30.0, "gradient_grey": True},
    {"gradient_weight": 30.0, "gradient_grey": True, "data_normalisation": 0.05},
    {"gradient_weight": 30.0, "gradient_sigma": 0.0},
    {"gradient_weight": 30.0, "data_normalisation": 0.05, "data_weight": 1.0},
    {"data_normalisation": 0.05, "data_weight": 1.0},
])
@pytest.mark.parametrize("level", [0, 3])
def test_data_channel_engines_agree(extra, level):
    f0, f1, gt = synthetic_pair("smooth", shape=(41, 53), magnitude=2.5, channels=3, seed=9)
    args = warped_inputs(f0, f1, (0.7 * gt).astype(np.float32))
    assert 0 < args[4].sum() < args[4].size  # some points leave the frame
    params = preset("plain", **extra)
    s_fast = TVL1State(level=level)
    s_ref = TVL1State(level=level)
    got = data_channels(*args, params, s_fast)
    want = data_channels_numpy(*args, params, s_ref)
    scale = max(float(np.abs(w).max()) for w in want)
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape and g.dtype == np.float32 and g.flags.c_contiguous
        np.testing.assert_allclose(g, w, atol=1e-6 * scale)
    assert (s_fast.grad0 is None) == (s_ref.grad0 is None)


@pytest.mark.parametrize("extra", [
    {"gradient_weight": 30.0},
    {"gradient_weight": 30.0, "data_normalisation": 0.05, "data_weight": 1.0},
    {"data_normalisation": 0.05, "data_weight": 1.0},
    {"huber": 0.05},
    {"huber": 0.2, "gradient_weight": 30.0},
])
def test_numba_and_numpy_engines_agree(extra):
    f0, f1, gt = synthetic_pair("smooth", shape=(48, 56), magnitude=1.5, channels=3, seed=5)
    flow0 = (0.8 * gt).astype(np.float32)
    args = warped_inputs(f0, f1, flow0)
    params = preset("plain", max_iterations=40, tolerance=0.0, edge_weight=5.0, **extra)
    outs, states = [], []
    for engine in ("numba", "numpy"):
        state = LevelState()
        for _ in range(2):  # the second warp warm starts every dual variable
            out = solve_warp(*args, params, state, engine=engine)
        outs.append(out)
        states.append(state.data)
    # 80 iterations amplify float32 rounding differences of the two engines' operators
    np.testing.assert_allclose(outs[0], outs[1], atol=3e-4)
    assert aee(outs[0], flow0) > 0.05  # the solver moved
    n_extra = 6 if extra.get("gradient_weight") else 0
    for s in states:
        assert s.q.shape == (3, 48, 56)
        assert (s.q_all is None) == (n_extra == 0)
        if n_extra:  # one array for every channel's dual; state.q is a view of it
            assert s.q_all.shape == (3 + n_extra, 48, 56)
            assert np.shares_memory(s.q, s.q_all)
            assert np.abs(s.q_all[3:]).max() > 0
    if n_extra:
        np.testing.assert_allclose(states[0].q_all, states[1].q_all, atol=2e-3)


# ------------------------------------------------------------------ accuracy


def test_gradient_term_recovers_a_shift_under_a_brightness_gain(gain_pair):
    f0, f1, gt = gain_pair
    today = aee(tvl1(f0, f1, preset("plain")), gt)
    robust = aee(tvl1(f0, f1, preset("plain", **ROBUST)), gt)
    normalised = aee(tvl1(f0, f1, preset("plain", data_weight=0.5, gradient_weight=2.0,
                                            data_normalisation=0.05)), gt)
    # measured: today 0.32, robust 0.018, normalised 0.018
    assert today > 0.25
    assert robust < 0.03 and normalised < 0.03
    assert robust < today / 10


def test_gradient_term_on_a_photograph_with_a_gain_and_zero_motion():
    skdata = pytest.importorskip("skimage.data")
    img = skdata.astronaut()[::4, ::4].astype(np.float32) / 255
    brighter = np.clip(1.2 * img, 0, 1)
    today = np.linalg.norm(varflow.flow(img, brighter, params=preset("plain")),
                           axis=-1).mean()
    robust = np.linalg.norm(varflow.flow(img, brighter, params=preset("plain", **ROBUST)),
                            axis=-1).mean()
    default = np.linalg.norm(varflow.flow(img, brighter), axis=-1).mean()
    # measured (128 x 128): today 1.37 px, robust 0.042 px; the true flow is zero
    assert today > 1.0
    assert robust < 0.1 and default < 0.1  # the default has the gradient term


def test_gradient_term_keeps_clean_motion_accurate():
    f0, f1, gt = synthetic_pair("smooth", shape=(96, 128), magnitude=3.0, channels=3, seed=1)
    # measured: plain 0.062, robust 0.068; 0.12 is test_tvl1's bound for the plain term
    assert aee(tvl1(f0, f1, preset("plain", **ROBUST)), gt) < 0.1


def test_tensor_method_accepts_the_robust_terms(gain_pair):
    f0, f1, gt = gain_pair
    plain = aee(varflow.flow(f0, f1, "tensor"), gt)
    robust = aee(varflow.flow(f0, f1, "tensor", params=preset("tensor", **ROBUST)), gt)
    assert plain > 0.25 and robust < 0.05  # measured 0.34 and 0.025


# ------------------------------------------------------------------ validation


_BAD = {
    "gradient_weight": [-1.0, math.nan, math.inf],
    "gradient_sigma": [-0.5, math.nan, math.inf],
    "data_normalisation": [-0.01, math.nan, math.inf],
    "huber": [-0.01, math.nan, math.inf],
}


@pytest.mark.parametrize("field, value", [(f, v) for f, vs in _BAD.items() for v in vs])
def test_invalid_values_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"^{field}:"):
        preset("plain", **{field: value})


def test_new_fields_reach_the_api_and_registry():
    p = varflow.make_params("tvl1", gradient_weight=40.0, data_normalisation=0.1)
    assert p.gradient_weight == 40.0 and p.data_normalisation == 0.1
    with pytest.raises(ValueError, match="^gradient_weight:"):
        varflow.make_params("tvl1", gradient_weight=-1.0)


# ------------------------------------------------------------------ Huber-TV


def test_huber_tv_does_not_staircase_an_affine_motion():
    # TV favours piecewise-constant flow; on an affine field Huber-TV (quadratic
    # below ε_H) is closer to the truth (measured: 0.0368 -> 0.0312 px)
    f0, f1, gt = synthetic_pair("affine", shape=(96, 128), magnitude=3.0, channels=3, seed=1)
    e_tv = aee(tvl1(f0, f1, preset("plain")), gt)
    e_hub = aee(tvl1(f0, f1, preset("plain", huber=0.02)), gt)
    assert e_hub < 0.9 * e_tv and e_hub < 0.034


def test_huber_reaches_the_api():
    p = varflow.make_params("tvl1", huber=0.05)
    assert p.huber == 0.05 and preset("plain").huber == 0.0 and TVL1Params().huber == 0.02
    with pytest.raises(ValueError, match="^huber:"):
        varflow.make_params("tvl1", huber=-1.0)


def test_grey_gradient_term_is_two_channels_of_the_channel_mean():
    f0, f1, gt = synthetic_pair("smooth", shape=(41, 53), magnitude=2.5, channels=3, seed=9)
    args = warped_inputs(f0, f1, (0.7 * gt).astype(np.float32))
    grey = preset("plain", gradient_weight=30.0, gradient_grey=True)
    ix, iy, a = data_channels(*args, grey, TVL1State())
    assert ix.shape[0] == 3 + 2
    # the same as the colour term's gradient channels of the mean image, weighted 3x
    mean = [np.repeat(x.mean(2, keepdims=True), 1, 2) for x in args[:4]]
    one = data_channels(*mean, *args[4:], preset("plain", gradient_weight=90.0), TVL1State())
    for got, want in zip((ix, iy, a), one, strict=True):
        np.testing.assert_allclose(got[3:], want[1:], atol=1e-6)
    # on a grey image the option changes nothing
    g = [x[..., :1] for x in args[:4]]
    for got, want in zip(data_channels(*g, *args[4:], grey, TVL1State()),
                         data_channels(*g, *args[4:], preset("plain", gradient_weight=30.0),
                                       TVL1State()),
                         strict=True):
        np.testing.assert_array_equal(got, want)
