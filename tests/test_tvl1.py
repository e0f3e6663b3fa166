"""TV-L1 solver: exact synthetic motions, engine agreement, input handling."""

import dataclasses

import numpy as np
import pytest

import varflow
from varflow.generators.pairs import TextureField, synthetic_pair
from varflow.ops.primal_dual import NO_TENSOR, row_blocks
from varflow.ops.warp import warp_bicubic
from varflow.twoframe.coarse_to_fine import LevelState
from varflow.twoframe.params import preset
from varflow.twoframe.tvl1 import (
    TVL1Params,
    linearise,
    linearise_numpy,
    solve_warp,
    tvl1_iterations,
)


def aee(a, b):
    return float(np.linalg.norm(a - b, axis=-1).mean())


def test_identical_frames_give_zero_flow():
    f0, f1, _ = synthetic_pair("zero", shape=(64, 80), seed=3)
    flow = varflow.flow(f0, f1)
    assert flow.shape == (64, 80, 2) and flow.dtype == np.float32
    assert np.abs(flow).max() < 1e-6


# bounds: measured EPE (colour / grey) x ~1.5; 2026-12-01 defaults: 0.014, 0.017, 0.024,
# 0.088, 0.100, 0.189 (the last 0.162 without the weighted median)
@pytest.mark.parametrize(
    "motion, magnitude, channels, bound",
    [
        ("translation", 2.5, 3, 0.035),
        ("translation", 2.5, 1, 0.075),
        ("affine", 3.0, 3, 0.07),
        ("smooth", 3.0, 3, 0.12),
        ("smooth", 3.0, 1, 0.19),
        ("smooth", 6.0, 3, 0.27),
    ],
)
def test_synthetic_motion_recovered(motion, magnitude, channels, bound):
    f0, f1, gt = synthetic_pair(motion, shape=(96, 128), magnitude=magnitude,
                                channels=channels, seed=1)
    flow = varflow.flow(f0, f1)
    assert aee(flow, gt) < bound
    # sign convention: frame1 at x + flow(x) matches frame0 at x
    assert aee(-flow, gt) > 5 * bound


def test_grey_input_forms_agree():
    f0, f1, _ = synthetic_pair("smooth", shape=(64, 80), magnitude=2.0, channels=1, seed=2)
    a = varflow.flow(f0, f1)
    b = varflow.flow(f0[..., 0], f1[..., 0])
    c = varflow.flow((f0[..., 0] * 65535).round().astype(np.uint16),
                     (f1[..., 0] * 65535).round().astype(np.uint16))
    np.testing.assert_array_equal(a, b)
    assert aee(a, c) < 1e-3


def test_colour_with_equal_channels_matches_grey_with_tripled_weight():
    f0, f1, _ = synthetic_pair("smooth", shape=(64, 80), magnitude=2.0, channels=1, seed=4)
    plain = preset("plain")
    grey = varflow.flow(f0, f1, params=plain.replace(data_weight=3 * plain.data_weight))
    colour = varflow.flow(np.repeat(f0, 3, 2), np.repeat(f1, 3, 2), params=plain)
    assert aee(grey, colour) < 0.01


def test_grey_option_works_on_the_channel_mean():
    f0, f1, _ = synthetic_pair("smooth", shape=(64, 80), magnitude=2.0, channels=3, seed=4)
    assert TVL1Params().grey
    # the weighted median is guided by the colour frame, so it is left out here
    a = varflow.flow(f0, f1, weighted_median_radius=0)
    b = varflow.flow(np.mean(f0, axis=2, dtype=np.float32), np.mean(f1, axis=2, dtype=np.float32),
                     weighted_median_radius=0)
    np.testing.assert_array_equal(a, b)
    assert np.abs(varflow.flow(f0, f1, grey=False) - a).max() > 1e-3  # colour differs


def test_colour_term_uses_chroma_not_grey_conversion():
    """An isoluminant texture: its grey mean is constant, only colour carries motion.

    The colour term (``grey=False``) follows it; the default works on the channel
    mean and cannot (the price of its speed: a third of the data-term work).
    """
    h, w = 80, 96
    tex = TextureField(channels=1, seed=9)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    shift = np.array([1.5, -1.0])

    def render(x, y):
        s = tex(x, y, 96)[..., 0]
        return np.stack([s, 1.0 - s, np.full_like(s, 0.5)], -1).astype(np.float32)

    f0 = render(xx, yy)
    f1 = render(xx - shift[0], yy - shift[1])
    assert np.ptp(f0.mean(-1)) < 1e-6  # grey conversion loses everything
    flow = varflow.flow(f0, f1, params=preset("plain"))
    gt = np.broadcast_to(shift, (h, w, 2))
    assert aee(flow, gt) < 0.1
    assert aee(varflow.flow(f0, f1, grey=False), gt) < 0.1
    assert aee(varflow.flow(f0.mean(-1), f1.mean(-1)), gt) > 1.5
    assert aee(varflow.flow(f0, f1), gt) > 1.5


def test_numba_and_numpy_engines_agree():
    f0, f1, gt = synthetic_pair("smooth", shape=(48, 56), magnitude=1.5, channels=3, seed=5)
    from varflow.ops.differences import image_derivatives
    from varflow.ops.warp import warp_bicubic

    dx, dy = image_derivatives(f1)
    flow0 = (0.8 * gt).astype(np.float32)
    warped, inside = warp_bicubic(np.concatenate([f1, dx, dy], 2), flow0)
    params = TVL1Params(max_iterations=40, tolerance=0.0, edge_weight=5.0)
    outs = []
    for engine in ("numba", "numpy"):
        state = LevelState()
        outs.append(solve_warp(f0, warped[..., :3], warped[..., 3:6], warped[..., 6:], inside,
                               flow0, params, state, engine=engine))
    np.testing.assert_allclose(outs[0], outs[1], atol=2e-4)
    assert aee(outs[0], flow0) > 0.05  # the solver moved


def test_bad_inputs_raise_clear_errors():
    a = np.zeros((10, 12), np.uint8)
    with pytest.raises(ValueError, match="differ in shape"):
        varflow.flow(a, np.zeros((10, 13), np.uint8))
    with pytest.raises(ValueError, match="frame0"):
        varflow.flow(np.zeros((10, 12, 3, 2)), a)
    bad = np.zeros((10, 12), np.float32)
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        varflow.flow(bad, a)
    bad[0, 0] = np.inf
    with pytest.raises(ValueError, match="frame1: contains NaN or infinite"):
        varflow.flow(a, bad)
    # floats outside [0, 1] are scaled (jointly), no longer refused
    assert not varflow.flow(np.full((10, 12), 255.0), a).any()
    with pytest.raises(ValueError, match="method"):
        varflow.flow(a, a, method="nope")
    with pytest.raises(ValueError, match="no_such_field"):
        varflow.flow(a, a, no_such_field=1)


_BAD_VALUES = {
    "scale_factor": 1.0, "max_levels": 0, "min_size": 1, "n_warps": 0, "median_size": 4,
    "texture_alpha": 1.5, "rof_theta": 0.0, "rof_iterations": 0, "pyramid_sigma": -1.0,
    "data_weight": 0.0, "coupling": -0.1, "tv_step": 0.3, "max_iterations": 0,
    "tolerance": -1.0, "edge_weight": -1.0, "edge_weight_min": 0.0, "data_sweeps": 0,
    "gradient_weight": -1.0, "gradient_sigma": -1.0, "data_normalisation": -1.0,
    "huber": -0.1, "noise_reference": -0.01, "weighted_median_radius": -1,
    "weighted_median_sigma_space": 0.0, "weighted_median_sigma_colour": float("inf"),
    "weighted_median_threshold": -0.5, "weighted_median_sigma_divergence": float("nan"),
    "weighted_median_noise": -1.0, "weighted_median_levels": -1,
}


@pytest.mark.parametrize("field", sorted(_BAD_VALUES))
def test_invalid_parameter_names_the_field(field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        TVL1Params(**{field: _BAD_VALUES[field]})


def test_every_parameter_has_a_validity_test():
    # the booleans have no invalid value
    # (the optional terms are checked in tests/test_parameters.py and with their methods)
    assert {f.name for f in dataclasses.fields(TVL1Params)} <= set(_BAD_VALUES) | {
        "structure_texture", "sharpness_match", "gradient_grey", "grey",
        "weighted_median_every_warp", "tensor", "sparse", "matching",
    }


def test_registry_and_api():
    assert "tvl1" in varflow.methods()
    assert varflow.METHODS["tvl1"].params_type is TVL1Params
    p = varflow.make_params("tvl1", n_warps=3)
    assert p.n_warps == 3 and p.data_weight == TVL1Params().data_weight


def test_progress_callback_counts_every_warp():
    f0, f1, _ = synthetic_pair("translation", shape=(40, 48), magnitude=1.0, seed=6)
    calls = []
    varflow.flow(f0, f1, n_warps=2, callback=lambda d, t: calls.append((d, t)))
    total = calls[-1][1]
    assert [c[0] for c in calls] == list(range(1, total + 1)) and total % 2 == 0


@pytest.mark.parametrize("aniso", [False, True])
@pytest.mark.parametrize("h", [5, 9, 37])
def test_two_iterations_per_pass_equal_single_passes_bit_for_bit(h, aniso):
    # the kernel carries two iterations in one row wavefront (blocks of 1-9 rows here);
    # one call of n iterations must equal n calls of one (the single-iteration pass)
    rng = np.random.default_rng(h)
    w, nc = 29, 3
    ix, iy, a = (rng.normal(size=(nc, h, w)).astype(np.float32) * 0.1 for _ in range(3))
    g = rng.uniform(0.05, 1.0, (h, w)).astype(np.float32)
    tens = rng.uniform(0.2, 1.0, (3, h, w)).astype(np.float32) if aniso else NO_TENSOR
    if aniso:
        tens[1] *= 0.3
    runs = []
    for n_calls, n_iter in ((1, 7), (7, 1)):
        u = np.zeros((2, h, w), np.float32)
        p = np.zeros((4, h, w), np.float32)
        tp = np.zeros_like(p) if aniso else p
        q = np.zeros((nc, h, w), np.float32)
        for _ in range(n_calls):
            tvl1_iterations(ix, iy, a, g, tens, u, p, tp, q, np.float32(15), np.float32(0.3),
                            np.float32(0.25), n_iter, np.float32(0), 1, aniso, row_blocks(h),
                            np.float32(0.02))
        runs.append((u, p, q))
    assert np.abs(runs[0][0]).max() > 0.05  # it moved
    for x, y in zip(*runs, strict=True):
        np.testing.assert_array_equal(x, y)


def test_linearise_engines_agree_on_the_drivers_strided_views():
    # the driver hands the solver views into one (H, W, 3C) warped array
    rng = np.random.default_rng(11)
    h, w, c = 23, 31, 3
    i0 = rng.random((h, w, c), dtype=np.float32)
    planes = rng.random((h, w, 3 * c), dtype=np.float32)
    flow = (rng.normal(size=(h, w, 2)) * 4).astype(np.float32)
    warped, inside = warp_bicubic(planes, flow)
    assert 0 < inside.sum() < h * w
    views = (i0, warped[..., :c], warped[..., c:2 * c], warped[..., 2 * c:], inside, flow)
    got = linearise(*views)
    want = linearise_numpy(*views)
    for g, e in zip(got, want, strict=True):
        assert g.shape == (c, h, w) and g.dtype == np.float32 and g.flags.c_contiguous
        np.testing.assert_allclose(g, e, rtol=1e-6, atol=1e-6)
        assert not g[:, ~inside].any()


def test_fast_preset_does_less_work_and_stays_accurate():
    assert varflow.FLOW["tvl1-fast"].defaults() == preset("fast")
    f0, f1, gt = synthetic_pair("smooth", shape=(96, 128), magnitude=3.0, channels=3, seed=1)
    full: dict = {}
    fast: dict = {}
    e_full = aee(varflow.flow(f0, f1, stats=full), gt)
    e_fast = aee(varflow.flow(f0, f1, "tvl1-fast", stats=fast), gt)
    assert fast["warps"] * 3 < full["warps"] and fast["levels"] < full["levels"]
    assert e_fast < 0.1 and e_fast < 1.3 * e_full  # measured: 0.085 and 0.086


def test_noise_rule_weakens_the_data_term_on_noisy_frames_only():
    from varflow.generators.photo_pairs import make_photo_pair

    p = make_photo_pair("affine", 1)
    params = preset("plain", noise_reference=0.01)
    stats: dict = {}
    assert params.for_frames(p.frame0, p.frame1, stats) is params  # clean: unchanged
    assert stats["data_scale"] == 1.0 and stats["noise_sigma"] < 0.008
    rng = np.random.default_rng(3)
    noisy = [np.clip(f + rng.normal(0, 0.03, f.shape), 0, 1).astype(np.float32)
             for f in (p.frame0, p.frame1)]
    stats = {}
    q = preset("plain", noise_reference=0.01, gradient_weight=20.0).for_frames(*noisy, stats)
    assert 0.026 < stats["noise_sigma"] < 0.034  # the added noise, not the texture
    assert q.data_weight == pytest.approx(40.0 * stats["data_scale"])
    assert q.gradient_weight == pytest.approx(20.0 * stats["data_scale"])
    assert 0.28 < stats["data_scale"] < 0.39
    # the rule reaches the driver and helps there (measured 0.134 -> 0.062 px)
    errs = []
    for ref in (0.0, 0.01):
        st: dict = {}
        flow = varflow.flow(*noisy, params=preset("plain", noise_reference=ref), stats=st)
        errs.append(float(np.linalg.norm(flow - p.flow, axis=-1)[p.valid].mean()))
        assert ("data_scale" in st) == (ref > 0)
    assert errs[1] < 0.6 * errs[0]


def test_dual_projection_kernel_matches_the_numpy_projection():
    from varflow.ops.primal_dual import project_dual
    from varflow.ops.prox import project_l2_ball

    rng = np.random.default_rng(7)
    p = rng.normal(0, 1, (4, 23, 31)).astype(np.float32)
    g = rng.uniform(0.05, 1.0, (23, 31)).astype(np.float32)
    want = project_l2_ball(np.moveaxis(p, 0, -1).reshape(23, 31, 2, 2), g[..., None])
    got = p.copy()
    project_dual(got, g)
    np.testing.assert_allclose(np.moveaxis(got, 0, -1).reshape(23, 31, 2, 2), want, atol=1e-6)
    assert (np.abs(got - p) > 1e-3).any()  # some pairs were outside their ball
