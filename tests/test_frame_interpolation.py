"""Frame interpolation (issue 28, part 1): varflow.interpolate, the splat method and its
kernels (forward splatting, outside-in hole filling, bilinear warping)."""

from __future__ import annotations

import numpy as np
import pytest

import varflow
from varflow.evaluation.frame_metrics import psnr
from varflow.ops.occlusion import (
    hidden_mask,
    hidden_mask_numpy,
    photometric_error,
    photometric_error_numpy,
)
from varflow.ops.splat import (
    fill_holes,
    fill_holes_numpy,
    splat,
    splat_numpy,
    splat_trajectories,
    splat_trajectories_numpy,
)
from varflow.ops.warp import warp_bilinear, warp_bilinear_numpy
from varflow.retime.methods import make_interp_params
from varflow.retime.motion import FlowCache, pair_flows, reduced, working_scale
from varflow.retime.schedule import slowmo_schedule
from varflow.retime.splatting import (
    SplatMotion,
    SplatParams,
    accelerations,
    prepare_splat,
)
from varflow.retime.stream import retime_frames

#: Small frames: one Numba thread is faster, and steady on a loaded machine.
pytestmark = pytest.mark.usefixtures("one_numba_thread")


def texture(h: int, w: int, shift: tuple[float, float] = (0.0, 0.0),
            seed: int = 0) -> np.ndarray:
    """A band-limited colour texture (a sum of 24 sinusoids below 0.2 cycles/px),
    translated by ``shift`` = (dx, dy) exactly: ``texture(.., s)(x) = texture(x - s)``."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = xx - shift[0], yy - shift[1]
    img = np.zeros((h, w, 3))
    for _ in range(24):
        fx, fy = rng.uniform(-0.2, 0.2, 2)
        phase = rng.uniform(0, 2 * np.pi)
        amp = rng.uniform(0.02, 0.06, 3)
        img += amp * np.sin(2 * np.pi * (fx * x + fy * y) + phase)[..., None]
    return np.clip(0.5 + img, 0, 1).astype(np.float32)


def square_scene(x0: int, move: int = 12, size: int = 32, h: int = 96, w: int = 128):
    """A textured red square at column ``x0`` over a grey texture; frame, square mask."""
    frame = texture(h, w, seed=1)
    yy, xx = np.mgrid[0:h, 0:w]
    sq = (xx >= x0) & (xx < x0 + size) & (yy >= 32) & (yy < 32 + size)
    col = np.clip(np.array([0.8, 0.25, 0.15]) + 0.6 * (texture(size, size, seed=7) - 0.5), 0, 1)
    frame[sq] = col.reshape(-1, 3)
    return frame, sq


def redness(img: np.ndarray) -> np.ndarray:
    return img[..., 0] - 0.5 * (img[..., 1] + img[..., 2])


# --------------------------------------------------------------------------- kernels


def test_warp_bilinear_engines_agree() -> None:
    rng = np.random.default_rng(0)
    planes = rng.random((23, 31, 3)).astype(np.float32)
    flow = rng.normal(scale=4, size=(23, 31, 2)).astype(np.float32)
    flow[3, 4] = np.nan
    a, ia = warp_bilinear(planes, flow)
    b, ib = warp_bilinear_numpy(planes, flow)
    np.testing.assert_allclose(a, b, atol=2e-6)
    np.testing.assert_array_equal(ia, ib)
    assert not ia[3, 4]


def test_hidden_mask_engines_agree_and_find_the_occlusion() -> None:
    rng = np.random.default_rng(4)
    fwd = rng.normal(scale=3, size=(30, 40, 2)).astype(np.float32)
    bwd = rng.normal(scale=3, size=(30, 40, 2)).astype(np.float32)
    fwd[2, 3] = np.nan
    for tol, rel in ((1.0, 0.05), (3.0, 0.0), (0.0, 0.5)):
        np.testing.assert_array_equal(hidden_mask(fwd, bwd, tol, rel),
                                      hidden_mask_numpy(fwd, bwd, tol, rel))
    # a block moving 6 px right over a still background: the background it covers is
    # hidden in the second frame, nothing else (bar the block's flow at the border)
    f = np.zeros((20, 30, 2), np.float32)
    f[5:15, 5:15, 0] = 6.0
    b = np.zeros_like(f)
    b[5:15, 11:21, 0] = -6.0
    hid = hidden_mask(f, b, 1.0, 0.0)
    expected = np.zeros((20, 30), bool)
    expected[5:15, 15:21] = True
    np.testing.assert_array_equal(hid, expected)
    with pytest.raises(ValueError, match="hidden_mask"):
        hidden_mask(f, b[:5], 1.0, 0.0)


def test_photometric_error_engines_agree() -> None:
    rng = np.random.default_rng(6)
    a, b = rng.random((2, 25, 33, 3)).astype(np.float32)
    flow = rng.normal(scale=5, size=(25, 33, 2)).astype(np.float32)
    flow[4, 4] = np.nan
    np.testing.assert_allclose(photometric_error(a, b, flow),
                               photometric_error_numpy(a, b, flow), atol=2e-6)
    zero = np.zeros((25, 33, 2), np.float32)
    np.testing.assert_allclose(photometric_error(a, b, zero), np.abs(a - b).mean(axis=2),
                               atol=1e-6)
    with pytest.raises(ValueError, match="photometric_error"):
        photometric_error(a, b[:5], flow)


def test_splat_engines_agree_and_conserve_the_weights() -> None:
    rng = np.random.default_rng(1)
    h, w = 40, 52
    vals = rng.normal(size=(h, w, 4)).astype(np.float32)
    flow = rng.normal(scale=5, size=(h, w, 2)).astype(np.float32)
    flow[2, 2] = np.nan
    weights = np.exp(-rng.uniform(0, 600, size=(h, w)))  # far below float32's range
    weights[5, 5] = 0.0
    a_acc, a_tot = splat(vals, flow, weights, 0.7)
    b_acc, b_tot = splat_numpy(vals, flow, weights, 0.7)
    np.testing.assert_allclose(a_acc, b_acc, rtol=1e-5, atol=1e-300)
    np.testing.assert_allclose(a_tot, b_tot, rtol=1e-5, atol=1e-300)
    # an integer translation inside the frame lands whole: the weight and value sums
    # are kept, and every pixel that lands gets its own value back
    shift = np.zeros((h, w, 2), np.float32)
    shift[..., 0] = 3.0
    shift[..., 1] = -2.0
    z = rng.uniform(0.5, 1.0, size=(h, w))
    acc, tot = splat(vals, shift, z)
    inside = np.zeros((h, w), bool)
    inside[2:, : w - 3] = True
    assert tot.sum() == pytest.approx(z[inside].sum(), rel=1e-12)
    np.testing.assert_allclose(acc[:-2, 3:] / tot[:-2, 3:, None], vals[2:, :-3], atol=1e-6)
    assert np.all(tot[-2:] == 0) and np.all(tot[:, :3] == 0)


def test_trajectory_splat_engines_agree() -> None:
    rng = np.random.default_rng(5)
    h, w = 33, 47
    flow = rng.normal(scale=4, size=(h, w, 2)).astype(np.float32)
    accel = rng.normal(scale=1, size=(h, w, 2)).astype(np.float32)
    flow[1, 1] = np.nan
    weights = np.exp(-rng.uniform(0, 100, size=(h, w)))
    for time, own_first in ((0.3, True), (0.8, False), (0.0, True), (1.0, False)):
        a, ta = splat_trajectories(flow, accel, weights, time, own_first)
        b, tb = splat_trajectories_numpy(flow, accel, weights, time, own_first)
        np.testing.assert_allclose(ta, tb, rtol=1e-5, atol=1e-300)
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6 * np.abs(b).max())
    # no acceleration: a pixel carries -s f to its own frame and (1 - s) f to the other
    acc, tot = splat_trajectories(np.full((5, 6, 2), 2.0, np.float32),
                                  np.zeros((5, 6, 2), np.float32), np.ones((5, 6)), 0.5, True)
    np.testing.assert_allclose(acc[2:, 2:] / tot[2:, 2:, None],
                               np.broadcast_to([-1.0, -1.0, 1.0, 1.0], (3, 4, 4)))
    with pytest.raises(ValueError, match="time"):
        splat_trajectories(flow, accel, weights, 1.5, True)


def test_splat_accumulates_two_sources() -> None:
    vals = np.ones((6, 7, 1), np.float32)
    zero = np.zeros((6, 7, 2), np.float32)
    acc, tot = splat(vals, zero, np.ones((6, 7)))
    acc, tot = splat(2 * vals, zero, np.full((6, 7), 3.0), 1.0, acc, tot)
    np.testing.assert_allclose(acc[..., 0] / tot, (1 + 6) / 4)
    with pytest.raises(ValueError, match="splat"):
        splat(vals, zero[:5], np.ones((6, 7)))
    with pytest.raises(ValueError, match="acc and tot"):
        splat(vals, zero, np.ones((6, 7)), 1.0, acc.astype(np.float32), tot)


def test_fill_holes_engines_agree_and_keep_known_values() -> None:
    rng = np.random.default_rng(2)
    field = rng.normal(size=(30, 41, 3)).astype(np.float32)
    known = rng.random((30, 41)) > 0.85
    known[:, :12] = False  # a wide hole: many rings
    a = fill_holes(field, known)
    b = fill_holes_numpy(field, known)
    np.testing.assert_allclose(a, b, atol=1e-6)
    np.testing.assert_array_equal(a[known], field[known])
    one = np.zeros((9, 11), bool)
    one[4, 5] = True
    np.testing.assert_array_equal(fill_holes(field[:9, :11, :1], one), np.broadcast_to(
        field[4, 5, :1], (9, 11, 1)))
    assert not fill_holes(field, np.zeros((30, 41), bool)).any()
    with pytest.raises(ValueError, match="fill_holes"):
        fill_holes(field, known[:, :5])


# --------------------------------------------------------------------------- splat


@pytest.mark.parametrize(("field", "value"), [
    ("splat_sharpness", -1.0), ("occlusion_cost", np.nan), ("fb_tolerance", "3"),
    ("fb_relative", True), ("sampling", "nearest"), ("visibility_blend", 1),
    ("quadratic", "yes"), ("flow_method", "nope"), ("flow_max_pixels", -1),
    ("flow_max_pixels", 2.5), ("fallback_blur", -0.5), ("lost_error", -0.1),
    ("lost_fraction", 1.5), ("lost_fraction", True)])
def test_splat_params_name_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        SplatParams(**{field: value})
    with pytest.raises(ValueError, match=field):
        varflow.interpolate(np.zeros((8, 8)), np.zeros((8, 8)), 0.5, "splat", **{field: value})


def blotchy(seed: int, h: int = 96, w: int = 128) -> np.ndarray:
    """A colour texture of blobs about 4 px across (uniform noise on a grid 4 times
    coarser, upsampled bicubically), uint8."""
    import cv2

    coarse = np.random.default_rng(seed).uniform(0, 255, (h // 4, w // 4, 3)).astype(np.float32)
    return np.clip(cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC), 0, 255).astype(
        np.uint8)


@pytest.mark.parametrize("method", ["splat", "splat-fast"])
def test_a_flow_that_explains_nothing_gives_the_blend(method: str) -> None:
    """Two unrelated textures (a cut, or a flow lost everywhere): the true frame between
    them is their blend, and the flows can only tear it; the frame is the blend (57 dB:
    the rounding to uint8), not the torn splat (15 dB with step 6 off)."""
    def db(x: np.ndarray, y: np.ndarray) -> float:  # PSNR on 0-255, float truth
        return float(10 * np.log10(255.0 ** 2 / np.mean((x.astype(np.float64) - y) ** 2)))

    a, b = blotchy(1), blotchy(2)
    for t in (0.5, 0.25):
        truth = (1 - t) * a.astype(np.float64) + t * b
        out = varflow.interpolate(a, b, t, method)
        assert db(out, truth) > db(np.round(truth), truth) - 0.5, t
    torn = varflow.interpolate(a, b, 0.5, method, lost_fraction=0.0)
    assert db(torn, 0.5 * a.astype(np.float64) + 0.5 * b) < 25


def test_lost_share_and_weight() -> None:
    from varflow.retime.splatting import lost_share, lost_weight

    z = np.zeros((40, 60), np.float32)
    z[:, :30] = 0.3  # the left half lost (and the 1.7 px the blur spreads it by)
    assert lost_share((z, np.zeros_like(z)), 0.1) == pytest.approx(31.7 / 120, abs=0.01)
    assert lost_share((z, z), 0.1) == pytest.approx(31.7 / 60, abs=0.02)
    assert lost_share((z,), 0.5) == 0.0
    assert [lost_weight(m, 0.5) for m in (0.0, 0.25, 0.375, 0.5, 0.9)] == [0, 0, 0.5, 1, 1]
    assert lost_weight(1.0, 0.0) == 0.0


def test_occlusions_with_exact_flows_leave_no_ghost() -> None:
    """The renderer alone: with the true flows, the square moves and what it uncovers
    and covers is the background, exactly, at every t."""
    move = 12
    f0, s0 = square_scene(40)
    f1, s1 = square_scene(40 + move)
    f01 = np.zeros(f0.shape[:2] + (2,), np.float32)
    f01[s0, 0] = move
    f10 = np.zeros_like(f01)
    f10[s1, 0] = -move
    motion = SplatMotion(f0, f1, f01, f10, SplatParams())
    for k, t in enumerate((0.25, 0.5, 0.75)):
        truth, _ = square_scene(40 + 3 * (k + 1))
        out = motion.render(t)
        assert np.abs(out - truth).max() < 1e-5, t


def test_moving_square_end_to_end() -> None:
    """Estimated flows: the area the square uncovers shows the background, not a
    ghost of the square (a blend and the naive scheme leave a red trace there)."""
    f0, s0 = square_scene(40)
    f1, _ = square_scene(52)
    ft, st = square_scene(46)
    uncovered = s0 & ~st
    middle = np.zeros_like(uncovered)
    middle[38:58] = True  # away from the corners, which TV-L1 rounds
    truth = redness(ft)[uncovered & middle].mean()
    ghost = {}
    for m in ("naive", "splat"):
        out = varflow.interpolate(f0, f1, 0.5, m)
        ghost[m] = redness(out)[uncovered & middle].mean() - truth
    blend = redness(0.5 * (f0 + f1))[uncovered & middle].mean() - truth
    # measured: splat 0.025, naive 0.120, blend 0.26
    assert ghost["splat"] < 0.06
    assert ghost["splat"] < 0.5 * ghost["naive"]
    assert ghost["splat"] < 0.25 * blend
    out = varflow.interpolate(f0, f1, 0.5, "splat")
    # measured: 28.5 against 27.5 dB
    assert psnr(out, ft) > psnr(varflow.interpolate(f0, f1, 0.5, "naive"), ft) + 0.5


def test_planted_translation_at_several_times() -> None:
    h, w, d = 64, 80, (3.2, -1.6)
    f0 = texture(h, w)
    f1 = texture(h, w, d)
    times = [0.25, 0.5, 0.75]
    outs = varflow.interpolate(f0, f1, times, "splat")
    naive = varflow.interpolate(f0, f1, times, "naive")
    inner = (slice(8, -8), slice(8, -8))
    for k, t in enumerate(times):
        truth = texture(h, w, (t * d[0], t * d[1]))
        # measured: splat 49-51 dB, naive 35 dB (bilinear sampling blurs), blend 18-21
        assert psnr(outs[k][inner], truth[inner]) > 44.0, t
        assert psnr(outs[k][inner], truth[inner]) > psnr(naive[k][inner], truth[inner]) + 6
        assert psnr(((1 - t) * f0 + t * f1)[inner], truth[inner]) < 22.0
    motion = prepare_splat(f0, f1, SplatParams())
    ut = motion.flow_at(0.5)[inner]
    assert np.abs(ut[..., 0] - d[0]).mean() < 0.05 and np.abs(ut[..., 1] - d[1]).mean() < 0.05


def test_quadratic_motion_from_the_neighbouring_frames() -> None:
    """An accelerating pan, x(τ) = 4τ + 1.5τ²: with the frames before and after, the
    middle frame is on the parabola; with the pair only, it is where linear motion
    puts it (0.375 px off)."""
    h, w = 64, 96

    def at(tau: float) -> np.ndarray:
        return texture(h, w, (4.0 * tau + 1.5 * tau * tau, 0.0), seed=3)

    inner = (slice(8, -8), slice(12, -12))
    truth = at(0.5)[inner]
    linear = varflow.interpolate(at(0), at(1), 0.5, "splat")
    quad = varflow.interpolate(at(0), at(1), 0.5, "splat", previous=at(-1), following=at(2))
    off = varflow.interpolate(at(0), at(1), 0.5, "splat", previous=at(-1), following=at(2),
                              quadratic=False)
    # measured: 59 dB with the neighbours, 29 dB without
    assert psnr(quad[inner], truth) > 45.0
    assert psnr(linear[inner], truth) < 35.0
    np.testing.assert_array_equal(off, linear)


def test_accelerations_from_exact_flows() -> None:
    h, w = 20, 30
    v, a = np.float32(2.0), np.float32(1.0)
    full = np.zeros((h, w, 2), np.float32)

    def flow(dx: float) -> np.ndarray:
        f = full.copy()
        f[..., 0] = dx
        return f

    # frame 0 at τ = 0: to τ = 1 moves v + a/2, to τ = -1 moves -v + a/2
    f01, f0m = flow(v + a / 2), flow(-v + a / 2)
    # frame 1 at τ = 1: back to τ = 0 is -(v + a/2); on to τ = 2 is v + 3a/2
    f10, f12 = flow(-(v + a / 2)), flow(v + 1.5 * a)
    hidden = np.zeros((h, w), bool)
    hidden[:, -4:] = True
    a0, a1 = accelerations(f01, f10, f0m, -f0m, f12, -f12, hidden, hidden, SplatParams())
    # the flow to the previous frame leaves the image in columns 0 and 1
    assert np.all(a0[:, 2:-4, 0] == a) and np.all(a1[:, :-4, 0] == a)
    assert not a0[:, -4:].any() and not a0[:, :2].any() and not a0[..., 1].any()


# --------------------------------------------------------------------------- the API


@pytest.mark.parametrize("method", ["naive", "splat"])
def test_dtype_shape_and_the_end_times(method: str) -> None:
    f0 = texture(40, 48)
    f1 = texture(40, 48, (1.5, 0.5))
    for a, b in ((f0, f1), ((f0 * 255).round().astype(np.uint8), (f1 * 255).round().astype(
            np.uint8)), ((f0 * 65535).astype(np.uint16), (f1 * 65535).astype(np.uint16)),
            (f0.mean(axis=2), f1.mean(axis=2)), (f0.astype(np.float64), f1.astype(np.float64))):
        out = varflow.interpolate(a, b, [0.0, 0.5, 1.0], method)
        assert out.shape == (3,) + a.shape and out.dtype == a.dtype
        np.testing.assert_array_equal(out[0], a)
        np.testing.assert_array_equal(out[2], b)
        one = varflow.interpolate(a, b, 0.5, method)
        assert one.shape == a.shape and one.dtype == a.dtype
        np.testing.assert_array_equal(one, out[1])


def test_float_frames_of_another_range() -> None:
    """Frames in 0..255 as floats give the frame of the same frames in [0, 1], scaled:
    the photometric costs are read in the frames' own range (the flows see the frames
    scaled jointly by their range, as varflow.flow does, hence not bit for bit)."""
    f0 = texture(40, 48)
    f1 = texture(40, 48, (2.5, -1.0))
    truth = texture(40, 48, (1.25, -0.5))
    unit = varflow.interpolate(f0, f1, 0.5)
    wide = varflow.interpolate(f0 * 255, f1 * 255, 0.5)
    assert wide.dtype == np.float32 and wide.max() > 1.5
    # measured: 65 dB apart; each 45 dB from the truth (the borders enter)
    assert psnr(wide / 255, unit) > 45.0
    assert abs(psnr(wide / 255, truth) - psnr(unit, truth)) < 0.5


def test_bad_inputs_name_what_is_wrong() -> None:
    f0 = texture(16, 20)
    with pytest.raises(ValueError, match="t:"):
        varflow.interpolate(f0, f0, 1.5)
    with pytest.raises(ValueError, match="t:"):
        varflow.interpolate(f0, f0, [])
    with pytest.raises(ValueError, match="frame1"):
        varflow.interpolate(f0, f0[:8])
    with pytest.raises(ValueError, match="frame1"):
        varflow.interpolate(f0, f0.astype(np.float64))
    bad = f0.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="frame0"):
        varflow.interpolate(bad, f0)
    with pytest.raises(ValueError, match="following"):
        varflow.interpolate(f0, f0, 0.5, "splat", following=f0[:8])
    with pytest.raises(ValueError, match="frame0: image too small"):
        varflow.interpolate(f0[:2, :2], f0[:2, :2])
    with pytest.raises(ValueError, match="method"):
        varflow.interpolate(f0, f0, 0.5, "magic")
    with pytest.raises(ValueError, match="no_such_field"):
        varflow.interpolate(f0, f0, 0.5, "splat", no_such_field=1)


def test_the_presets() -> None:
    p, fast = SplatParams(), make_interp_params("splat-fast")
    assert (p.flow_method, p.flow_params.match_scale, p.flow_max_pixels) == ("tvl1-ld", 0.5,
                                                                             300_000)
    assert (p.flow_params.weighted_median_levels, p.flow_params.max_iterations) == (3, 24)
    assert (fast.flow_method, fast.flow_max_pixels) == ("tvl1-fast", 150_000)
    assert p.replace(flow_method="tvl1").flow_params == varflow.make_params("tvl1")
    assert varflow.retime.DEFAULT_INTERPOLATOR == "splat"


def test_flows_on_reduced_frames_are_resized_back() -> None:
    """A 1.6 x 0.8 px translation of a 96 x 128 frame, its flows estimated on frames
    of a quarter of the pixels (half the size): the vectors come back at full scale."""
    assert working_scale((96, 128, 3), 0) == 1.0
    assert working_scale((96, 128, 3), 96 * 128) == 1.0
    assert working_scale((96, 128, 3), 96 * 128 // 4) == pytest.approx(0.5)
    f0 = texture(96, 128)
    f1 = texture(96, 128, (1.6, 0.8))
    assert reduced(f0, 0.5).shape == (48, 64, 3)
    f01, f10 = pair_flows([(f0, f1), (f1, f0)], SplatParams(), max_pixels=96 * 128 // 4)
    inner = (slice(10, -10), slice(10, -10))
    assert f01.shape == (96, 128, 2)
    assert np.abs(f01[inner] - [1.6, 0.8]).mean() < 0.1
    assert np.abs(f10[inner] + [1.6, 0.8]).mean() < 0.1


# --------------------------------------------------------------------------- flows shared


def test_flow_cache_is_keyed_by_content() -> None:
    cache = FlowCache(max_entries=2)
    a, b = texture(8, 8), texture(8, 8, seed=2)
    p = SplatParams()
    k = FlowCache.key(a, b, p)
    assert FlowCache.key(a.copy(), b.copy(), p) == k
    assert FlowCache.key(b, a, p) != k
    assert FlowCache.key(a, b, p.replace(data_weight=30.0)) != k
    cache.put(k, np.zeros((8, 8, 2), np.float32))
    assert cache.get(k) is not None and cache.hits == 1
    cache.put(FlowCache.key(b, a, p), np.ones((8, 8, 2), np.float32))
    cache.put(FlowCache.key(a, a, p), np.ones((8, 8, 2), np.float32))
    assert len(cache) == 2 and cache.get(k) is None
    with pytest.raises(ValueError, match="max_entries"):
        FlowCache(0)


def test_a_stream_estimates_two_flows_per_pair() -> None:
    """Slow motion of n frames with the four-frame method: every flow is estimated
    once, 2 (n - 1) in all, and the frames equal those of separate calls."""
    n = 5
    frames = [(texture(32, 40, (1.5 * k, 0.25 * k), seed=4) * 255).round().astype(np.uint8)
              for k in range(n)]
    stats: dict = {}
    out = list(retime_frames(frames, slowmo_schedule(n, 2), "splat", stats=stats,
                             scene_cuts=False))
    assert len(out) == 2 * n - 1
    assert stats["flows"] == 2 * (n - 1)
    # asked for: 4 flows by the first and last pairs, 6 by the others
    assert stats["cached_flows"] == (4 + 6 * (n - 3) + 4) - 2 * (n - 1)
    for i in range(n - 1):
        np.testing.assert_array_equal(out[2 * i], frames[i])
        ctx = {"previous": frames[i - 1] if i >= 1 else None,
               "following": frames[i + 2] if i + 2 < n else None}
        np.testing.assert_array_equal(
            out[2 * i + 1], varflow.interpolate(frames[i], frames[i + 1], 0.5, "splat", **ctx))
