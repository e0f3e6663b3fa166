"""Tests of the synthetic trajectory sequences and the trajectory error measures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from varflow.evaluation.trajectory_metrics import frame11_flow, trajectory_errors
from varflow.generators.pairs import TextureField
from varflow.generators.sequences import (
    SCENES,
    VARIANTS,
    SyntheticSequence,
    _TextureSampler,
    benchmark_cases,
    benchmark_suite,
    make_sequence,
)
from varflow.ops.warp import warp_bicubic

F, SHAPE = 20, (64, 80)
H, W = SHAPE


@pytest.fixture(scope="module")
def clean() -> dict[str, SyntheticSequence]:
    return {name: make_sequence(name, n_frames=F, shape=SHAPE, seed=3) for name in SCENES}


def _grid() -> tuple[np.ndarray, np.ndarray]:
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    return xx, yy


def _safe_mask(seq: SyntheticSequence, n: int, margin: float = 3.0) -> np.ndarray:
    """Visible points whose bicubic stencil in frame n stays inside the frame and one layer."""
    xx, yy = _grid()
    px = xx + seq.trajectories[n, ..., 0]
    py = yy + seq.trajectories[n, ..., 1]
    m = seq.visibility[n] & (px >= 2) & (px <= W - 3) & (py >= 2) & (py <= H - 3)
    if "foreground" in seq.params:
        c = seq.params["foreground"]["centre"][n]
        r = seq.params["foreground"]["radius"][n]
        m &= np.abs(np.hypot(px - c[0], py - c[1]) - r) > margin
    return m


def _warp_error(seq: SyntheticSequence, n: int, delta=(0.0, 0.0)) -> float:
    traj = seq.trajectories[n] + np.asarray(delta, np.float32)
    warped, _ = warp_bicubic(seq.clean_frames[n], traj)
    m = _safe_mask(seq, n)
    assert m.mean() > 0.5
    return float(np.abs(warped - seq.clean_frames[seq.ref])[m].mean())


# --------------------------------------------------------------------------- sequences


@pytest.mark.parametrize("name", SCENES)
def test_shapes_ranges_and_reference(clean, name):
    seq = clean[name]
    assert seq.ref == F // 2 and seq.name == name and seq.variant == "clean"
    assert seq.frames.shape == (F, H, W, 3) and seq.frames.dtype == np.float32
    assert seq.trajectories.shape == (F, H, W, 2) and seq.trajectories.dtype == np.float32
    assert seq.visibility.shape == (F, H, W) and seq.visibility.dtype == np.bool_
    assert seq.layer.shape == SHAPE
    assert seq.n_frames == F and seq.shape == SHAPE
    assert 0.0 <= seq.frames.min() and seq.frames.max() <= 1.0
    assert np.all(seq.trajectories[seq.ref] == 0.0)
    assert seq.visibility[seq.ref].all()
    assert seq.clean_frames is seq.frames
    # motion a few to ~10 px, smooth in time (steps well below the total range)
    assert 5.0 < seq.params["max_displacement"] < 14.0
    steps = np.abs(np.diff(seq.trajectories, axis=0)).max()
    assert steps < 0.25 * seq.params["max_displacement"]


@pytest.mark.parametrize("name", SCENES)
def test_trajectories_register_frames_to_reference(clean, name):
    """Warping frame n back with the exact trajectories reproduces the reference frame."""
    seq = clean[name]
    for n in (0, 4, seq.ref + 1, F - 1):
        exact = _warp_error(seq, n)
        assert exact < 0.01  # bicubic interpolation of the texture only
        assert _warp_error(seq, n, (0.5, 0.0)) > 3 * exact
        assert _warp_error(seq, n, (0.0, -0.5)) > 3 * exact
        # the exact trajectory beats small perturbations in every direction
        for d in [(0.2, 0.0), (-0.2, 0.0), (0.0, 0.2), (0.0, -0.2)]:
            assert _warp_error(seq, n, d) > 1.1 * exact


def test_affine_trajectories_match_the_motion_matrices(clean):
    seq = clean["affine"]
    info = seq.params["motion"]
    a, b, c = info["A"], info["b"], info["centre"]
    xx, yy = _grid()
    x = np.stack([xx - c[0] - b[seq.ref, 0], yy - c[1] - b[seq.ref, 1]], -1)
    p = x @ np.linalg.inv(a[seq.ref]).T  # M_ref^{-1}(x) - c
    for n in range(F):
        pos = p @ a[n].T + c + b[n]
        expect = pos - np.stack([xx, yy], -1)
        np.testing.assert_allclose(seq.trajectories[n], expect, atol=2e-5)
    # magnitude is the exact maximum displacement of the centre frame's pixels
    assert seq.params["max_displacement"] == pytest.approx(8.0, rel=1e-3)


@pytest.mark.parametrize("name", ["affine", "nonrigid"])
def test_trajectories_compose_across_reference_frames(name):
    """traj_a[n](x) = traj_a[b](x) + traj_b[n](x + traj_a[b](x)) (frames do not depend on ref)."""
    sa = make_sequence(name, n_frames=F, shape=SHAPE, seed=3, ref=4)
    sb = make_sequence(name, n_frames=F, shape=SHAPE, seed=3, ref=14)
    np.testing.assert_array_equal(sa.frames, sb.frames)
    hop = sa.trajectories[14]
    for n in (0, 9, 19):
        onward, inside = warp_bicubic(sb.trajectories[n], hop)
        m = inside & _safe_mask(sa, 14)
        err = np.abs(hop + onward - sa.trajectories[n])[m]
        assert err.max() < 2e-3  # bicubic interpolation of a smooth field


def test_layers_visibility_is_analytic(clean):
    seq = clean["layers"]
    fg = seq.params["foreground"]
    xx, yy = _grid()
    # the layer map is the disc of the reference frame
    c, r = fg["centre"][seq.ref], fg["radius"][seq.ref]
    dist = np.hypot(xx - c[0], yy - c[1])
    clear = np.abs(dist - r) > 1e-3
    np.testing.assert_array_equal((seq.layer == 1)[clear], (dist <= r)[clear])
    assert 0.1 < (seq.layer == 1).mean() < 0.4
    # foreground points are always visible
    assert seq.visibility[:, seq.layer == 1].all()
    bg = seq.layer == 0
    n_occluded = 0
    for n in range(F):
        px = xx + seq.trajectories[n, ..., 0]
        py = yy + seq.trajectories[n, ..., 1]
        d = np.hypot(px - fg["centre"][n, 0], py - fg["centre"][n, 1])
        inside = (px >= 0) & (px <= W - 1) & (py >= 0) & (py <= H - 1)
        expect = inside & (d > fg["radius"][n])
        sure = bg & (np.abs(d - fg["radius"][n]) > 1e-3)
        np.testing.assert_array_equal(seq.visibility[n][sure], expect[sure])
        n_occluded += int((bg & ~seq.visibility[n] & (d <= fg["radius"][n] - 1)).sum())
        # deep inside the disc: hidden, and the nearest pixel of frame n is a disc pixel
        hidden = np.argwhere(bg & (d < fg["radius"][n] - 2))
        for y, x in hidden[:: max(1, len(hidden) // 5)]:
            assert not seq.visibility[n, y, x]
            iy, ix = round(py[y, x]), round(px[y, x])
            assert np.hypot(ix - fg["centre"][n, 0], iy - fg["centre"][n, 1]) < fg["radius"][n]
    assert n_occluded > 100
    assert seq.params["occluded_fraction"] > 0.02


def test_gaussian_noise_statistics(clean):
    for sigma in (0.02, 0.05):
        seq = make_sequence(
            "affine", n_frames=F, shape=SHAPE, seed=3, variant="gaussian", noise_sigma=sigma
        )
        np.testing.assert_array_equal(seq.clean_frames, clean["affine"].frames)
        diff = (seq.frames - seq.clean_frames).astype(np.float64)
        assert diff.std() == pytest.approx(sigma, rel=0.1)
        assert abs(diff.mean()) < 0.1 * sigma
        assert np.abs(diff[seq.ref]).mean() > 0.5 * sigma  # the reference is noisy too
        assert 0.0 <= seq.frames.min() and seq.frames.max() <= 1.0
        np.testing.assert_array_equal(seq.trajectories, clean["affine"].trajectories)
        np.testing.assert_array_equal(seq.visibility, clean["affine"].visibility)


def test_salt_and_pepper_statistics(clean):
    seq = make_sequence(
        "nonrigid", n_frames=F, shape=SHAPE, seed=3, variant="saltpepper", sp_fraction=0.05
    )
    np.testing.assert_array_equal(seq.clean_frames, clean["nonrigid"].frames)
    hit = np.any(seq.frames != seq.clean_frames, axis=-1)
    assert hit.mean() == pytest.approx(0.05, abs=0.004)
    vals = seq.frames[hit]
    assert np.all((vals == 0.0) | (vals == 1.0))
    assert np.all(vals == vals[:, :1])  # all channels of a hit pixel alike
    assert (vals[:, 0] == 1.0).mean() == pytest.approx(0.5, abs=0.03)
    assert hit[seq.ref].mean() > 0.03  # the reference frame is corrupted too


def test_occluder_sweeps_and_hides_points(clean):
    base = clean["layers"]
    seq = make_sequence("layers", n_frames=F, shape=SHAPE, seed=3, variant="occluder")
    occ = seq.params["occluder"]
    np.testing.assert_array_equal(seq.frames[seq.ref], base.frames[seq.ref])
    np.testing.assert_array_equal(seq.trajectories, base.trajectories)
    assert np.all(seq.visibility <= base.visibility)
    assert seq.params["occluded_fraction"] > base.params["occluded_fraction"] + 0.03
    cols = np.arange(W)
    swept = np.zeros(W, bool)
    for n in range(F):
        lo = occ["left"][n]
        if np.isnan(lo):
            np.testing.assert_array_equal(seq.frames[n], base.frames[n])
            continue
        bar = (cols >= lo) & (cols < lo + occ["width"])
        swept |= bar
        assert np.all(seq.frames[n][:, bar] == np.float32(occ["value"]))
        np.testing.assert_array_equal(seq.frames[n][:, ~bar], base.frames[n][:, ~bar])
        px = cols[None, :] + seq.trajectories[n, ..., 0]
        under = (px >= lo + 1e-3) & (px < lo + occ["width"] - 1e-3)
        assert not seq.visibility[n][under].any()
        away = (px < lo - 1e-3) | (px >= lo + occ["width"] + 1e-3)
        np.testing.assert_array_equal(seq.visibility[n][away], base.visibility[n][away])
    assert swept.all()  # the bar crosses the whole frame


@pytest.mark.parametrize("channels", [1, 3])
def test_fast_texture_sampler_matches_texture_field(channels):
    tex = TextureField(channels, seed=11)
    sampler = _TextureSampler(tex)
    assert sampler.fast
    x, y = np.random.default_rng(0).uniform(-200.0, 900.0, (2, 37, 53))
    np.testing.assert_allclose(sampler(x, y, 320.0), tex(x, y, 320.0), rtol=0, atol=1e-6)

    class Opaque:  # no TextureField internals: falls back to calling the field
        def __call__(self, x, y, scale=256.0):
            return tex(x, y, scale)

    slow = _TextureSampler(Opaque())
    assert not slow.fast
    np.testing.assert_array_equal(slow(x, y, 320.0), tex(x, y, 320.0))


def test_determinism_and_seed():
    a = make_sequence("nonrigid", n_frames=8, shape=(32, 40), seed=5, variant="gaussian")
    b = make_sequence("nonrigid", n_frames=8, shape=(32, 40), seed=5, variant="gaussian")
    c = make_sequence("nonrigid", n_frames=8, shape=(32, 40), seed=6, variant="gaussian")
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.trajectories, b.trajectories)
    assert not np.array_equal(a.frames, c.frames)
    assert not np.array_equal(a.trajectories, c.trajectories)


def test_grey_frames_and_magnitude():
    seq = make_sequence("nonrigid", n_frames=12, shape=(48, 64), channels=1, magnitude=4.0)
    assert seq.frames.shape == (12, 48, 64, 1)
    assert seq.params["max_displacement"] == pytest.approx(4.0, rel=0.1)
    still = make_sequence("affine", n_frames=6, shape=(32, 32), magnitude=0.0)
    assert np.all(still.trajectories == 0) and still.visibility.all()
    np.testing.assert_array_equal(
        still.frames, np.broadcast_to(still.frames[0], still.frames.shape)
    )


def test_benchmark_cases_and_suite():
    cases = benchmark_cases()
    assert len(cases) == len(SCENES) * len(VARIANTS) == 12
    assert cases[0] == ("affine", "clean") and ("layers", "occluder") in cases
    seqs = list(benchmark_suite(n_frames=6, shape=(32, 40), scenes=["layers"]))
    assert [(s.name, s.variant) for s in seqs] == [("layers", v) for v in VARIANTS]
    with pytest.raises(ValueError, match="scenes"):
        benchmark_cases(scenes=["flag"])
    with pytest.raises(ValueError, match="variants"):
        benchmark_cases(variants=["blur"])


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"name": "flag"}, "name"),
        ({"variant": "blur"}, "variant"),
        ({"n_frames": 1}, "n_frames"),
        ({"n_frames": 2.5}, "n_frames"),
        ({"shape": (8, 64)}, "shape"),
        ({"shape": (32,)}, "shape"),
        ({"ref": 10}, "ref"),
        ({"ref": -1}, "ref"),
        ({"channels": 0}, "channels"),
        ({"magnitude": -1.0}, "magnitude"),
        ({"magnitude": float("nan")}, "magnitude"),
        ({"noise_sigma": -0.1}, "noise_sigma"),
        ({"sp_fraction": 1.5}, "sp_fraction"),
        ({"seed": -3}, "seed"),
    ],
)
def test_make_sequence_rejects_bad_arguments(kwargs, word):
    args = {"name": "affine", "n_frames": 10, "shape": (32, 32)} | kwargs
    with pytest.raises(ValueError, match=word):
        make_sequence(**args)


# --------------------------------------------------------------------------- metrics


def test_constant_error_gives_exact_values(clean):
    seq = clean["layers"]
    gt = seq.trajectories
    est = gt.astype(np.float64) + np.array([0.3, 0.4])
    r = trajectory_errors(est, gt, seq.visibility)
    assert r["epe"] == pytest.approx(0.5, abs=1e-12)
    assert r["rms"] == pytest.approx(0.5, abs=1e-12)
    assert r["max"] == pytest.approx(0.5, abs=1e-12)
    assert r["ref"] == seq.ref and r["missing"] == 0.0
    others = np.arange(F) != seq.ref
    assert r["n_points"] == int(seq.visibility[others].sum())
    assert np.isnan(r["epe_per_frame"][seq.ref]) and np.isnan(r["rms_per_frame"][seq.ref])
    np.testing.assert_allclose(r["epe_per_frame"][others], 0.5, atol=1e-12)
    # with the reference frame included (est is 0.5 off there too) only the count changes
    r2 = trajectory_errors(est, gt, seq.visibility, exclude_ref=False)
    assert r2["n_points"] == int(seq.visibility.sum()) and r2["ref"] is None
    assert r2["epe"] == pytest.approx(0.5, abs=1e-12)


def test_hand_computed_errors_visibility_and_missing():
    gt = np.zeros((3, 1, 3, 2))
    gt[0] = 2.0
    gt[2] = -1.0
    est = gt.copy()
    est[0, 0, 0] += [1.0, 0.0]  # EPE 1
    est[2, 0, 0] += [3.0, 4.0]  # EPE 5
    est[2, 0, 1] += [100.0, 0.0]  # hidden below
    est[0, 0, 2] = np.nan  # missing
    vis = np.ones((3, 1, 3), bool)
    vis[2, 0, 1] = False
    r = trajectory_errors(est, gt, vis)
    # used: frame 0 -> (1, 0), frame 2 -> (5, 0); 4 points; one missing of 5
    assert r["ref"] == 1 and r["n_points"] == 4
    assert r["epe"] == pytest.approx(6.0 / 4)
    assert r["rms"] == pytest.approx(math.sqrt(26.0 / 4))
    assert r["max"] == pytest.approx(5.0)
    assert r["missing"] == pytest.approx(20.0)
    np.testing.assert_allclose(r["epe_per_frame"], [0.5, np.nan, 2.5])
    np.testing.assert_allclose(r["rms_per_frame"], [math.sqrt(0.5), np.nan, math.sqrt(12.5)])
    # without visibility the hidden outlier counts
    assert trajectory_errors(est, gt)["max"] == pytest.approx(100.0)
    # nothing to average -> NaN
    empty = trajectory_errors(est, gt, np.zeros((3, 1, 3), bool))
    assert math.isnan(empty["epe"]) and empty["n_points"] == 0


def test_metric_arguments_are_validated():
    gt = np.zeros((4, 5, 6, 2), np.float32)
    gt[0] = 1.0
    with pytest.raises(ValueError, match="est"):
        trajectory_errors(np.zeros((5, 6, 2)), gt)
    with pytest.raises(ValueError, match="gt"):
        trajectory_errors(gt, np.zeros((4, 5, 6, 3)))
    with pytest.raises(ValueError, match="differ in shape"):
        trajectory_errors(gt[:3], gt)
    with pytest.raises(ValueError, match="visibility"):
        trajectory_errors(gt, gt, np.ones((4, 5, 6)))
    with pytest.raises(ValueError, match="visibility"):
        trajectory_errors(gt, gt, np.ones((4, 5, 5), bool))
    with pytest.raises(ValueError, match="ref"):
        trajectory_errors(gt, gt)  # frames 1, 2, 3 are all zero: ambiguous
    with pytest.raises(ValueError, match="ref"):
        trajectory_errors(gt, gt, ref=4)
    assert trajectory_errors(gt, gt, ref=2)["n_points"] == 90


def test_frame11_flow(clean):
    seq = clean["nonrigid"]
    flow = frame11_flow(seq.trajectories, seq.ref)
    assert flow.shape == (H, W, 2) and flow.dtype == np.float32
    np.testing.assert_array_equal(flow, seq.trajectories[seq.ref + 1])
    flow[:] = 0
    assert np.any(seq.trajectories[seq.ref + 1] != 0)  # a copy
    np.testing.assert_array_equal(
        frame11_flow(seq.trajectories, seq.ref, step=-2), seq.trajectories[seq.ref - 2]
    )
    with pytest.raises(ValueError, match="step"):
        frame11_flow(seq.trajectories, F - 1)
    with pytest.raises(ValueError, match="ref"):
        frame11_flow(seq.trajectories, F)
    with pytest.raises(ValueError, match="traj"):
        frame11_flow(seq.trajectories[0], 0)
