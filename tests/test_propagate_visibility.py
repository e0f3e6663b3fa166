"""Outward propagation of the initial trajectories and the visibility estimate."""

import numpy as np
import pytest

from varflow.evaluation.trajectory_metrics import occlusion_accuracy, trajectory_errors
from varflow.generators.sequences import make_sequence
from varflow.multiframe.propagate import extrapolate, frame_pyramids, propagate_trajectories
from varflow.multiframe.track import TwoFrameTrackParams, track_twoframe
from varflow.multiframe.visibility import (
    VisibilityParams,
    estimate_visibility,
    fb_error,
    in_bounds,
    invert_flow,
)
from varflow.twoframe.tvl1 import TVL1Params


@pytest.fixture(scope="module")
def fast_disc():
    """A disc crossing 2 x 18 px over 13 frames in front of a slowly moving background."""
    return make_sequence("layers", n_frames=13, shape=(64, 80), magnitude=18.0, seed=5)


def _far_epe(traj, seq):
    e = trajectory_errors(traj, seq.trajectories, seq.visibility, ref=seq.ref)
    return float(np.nanmean(e["epe_per_frame"][[0, 1, -2, -1]])), e["epe"]


def test_extrapolate_is_constant_velocity() -> None:
    a = np.full((2, 3, 2), 1.0, np.float32)
    b = np.full((2, 3, 2), 3.0, np.float32)
    np.testing.assert_array_equal(extrapolate(b, a), 5.0)
    np.testing.assert_array_equal(extrapolate(b, None), 6.0)


def test_propagation_follows_a_fast_object_that_independent_flows_lose(fast_disc) -> None:
    """Measured (2026-11-29): far-frame EPE twoframe 4.3, propagated 0.2 px."""
    s = fast_disc
    p = TVL1Params()
    two = track_twoframe(s.frames, s.ref, TwoFrameTrackParams(flow_params=p))
    st: dict = {}
    prop = propagate_trajectories(s.frames, s.ref, p, stats=st)
    far_two, all_two = _far_epe(two, s)
    far_prop, all_prop = _far_epe(prop, s)
    assert np.all(prop[s.ref] == 0)
    assert far_prop < 0.25 * far_two, (far_prop, far_two)
    assert all_prop < 0.5 * all_two, (all_prop, all_two)
    assert st["flows"] == s.n_frames - 1 and 0 < st["repaired"] < 0.5


def test_propagation_repair_and_direct_candidates(fast_disc) -> None:
    s = fast_disc
    # the repair alone, without the weighted median (which narrows the band too): far
    # frames 0.561 px unrepaired; with the weighted median 0.425
    p = TVL1Params(weighted_median_radius=0)
    pyrs = frame_pyramids(s.frames, p)
    plain = propagate_trajectories(s.frames, s.ref, p, pyrs, repair_distances=())
    fixed = propagate_trajectories(s.frames, s.ref, p, pyrs)
    # the repair stops the disc's edge band from drifting with the background
    assert _far_epe(fixed, s)[0] < 0.5 * _far_epe(plain, s)[0]
    weighted = propagate_trajectories(s.frames, s.ref, TVL1Params(), pyrs, repair_distances=())
    assert _far_epe(weighted, s)[0] < 0.85 * _far_epe(plain, s)[0]
    # without repair_adjacent the frames ref +- 1 keep their pyramid flows untouched,
    # the others are repaired as before
    skip = propagate_trajectories(s.frames, s.ref, p, pyrs, repair_adjacent=False)
    for n in (s.ref - 1, s.ref + 1):
        np.testing.assert_array_equal(skip[n], plain[n])
        assert not np.array_equal(fixed[n], plain[n])
    for n in (0, s.ref + 2, s.n_frames - 1):
        assert not np.array_equal(skip[n], plain[n])
    st: dict = {}
    both = propagate_trajectories(s.frames, s.ref, p, pyrs, direct=True, stats=st)
    assert st["flows"] == 2 * (s.n_frames - 1) - 2  # r ± 1 have one candidate only
    assert 0.0 <= st["direct_share"] <= 1.0
    assert np.all(np.isfinite(both))


def test_invert_flow_and_fb_error_on_an_affine_field() -> None:
    h, w = 40, 50
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    a = np.array([[0.03, -0.02], [0.01, 0.02]])
    fwd = np.stack([a[0, 0] * xx + a[0, 1] * yy + 1.5, a[1, 0] * xx + a[1, 1] * yy - 0.7],
                   -1).astype(np.float32)
    back = invert_flow(fwd, iterations=8)
    err = fb_error(fwd, back)
    inner = in_bounds(fwd)
    # away from the bicubic stencil's clamped border (5 px: the target lands 1.5 px right)
    inner[:5] = inner[-5:] = False
    inner[:, :5] = inner[:, -5:] = False
    assert err[inner].max() < 1e-5
    assert fb_error(fwd, back + np.float32(2.0))[inner].min() > 2.0
    assert not in_bounds(np.full((h, w, 2), -100, np.float32)).any()


def test_visibility_finds_the_occluded_background(fast_disc) -> None:
    """Measured (2026-11-29): accuracy 0.96 / 0.97 with the estimated / exact trajectories."""
    s = fast_disc
    p = TVL1Params()
    pyrs = frame_pyramids(s.frames, p)
    traj = propagate_trajectories(s.frames, s.ref, p, pyrs)
    st: dict = {}
    vis = estimate_visibility(traj, s.ref, pyrs, p, stats=st)
    assert vis.shape == s.visibility.shape and vis.dtype == bool and vis[s.ref].all()
    acc = occlusion_accuracy(vis, s.visibility, s.ref)
    assert s.params["occluded_fraction"] > 0.05
    assert acc["accuracy"] > 0.93, acc
    assert acc["hidden_recall"] > 0.8, acc
    assert 0.5 * acc["hidden_true"] < acc["hidden_estimated"] < 1.5 * acc["hidden_true"]
    assert st["backward"].shape == traj.shape and st["hidden"] == pytest.approx(
        acc["hidden_estimated"])
    # a zero trajectory is wrong wherever the scene moves: most points look hidden
    zero = estimate_visibility(np.zeros_like(traj), s.ref, pyrs, p)
    assert occlusion_accuracy(zero, s.visibility, s.ref)["accuracy"] < acc["accuracy"] - 0.2


def test_occlusion_accuracy_counts_labels() -> None:
    truth = np.ones((3, 2, 2), bool)
    truth[0, 0, 0] = truth[2, 1, 1] = False
    est = truth.copy()
    est[2, 1, 1] = True  # a missed hidden point
    est[2, 0, 0] = False  # a false alarm
    r = occlusion_accuracy(est, truth, ref=1)
    assert r["accuracy"] == pytest.approx(6 / 8)
    assert r["hidden_recall"] == pytest.approx(0.5)
    assert r["hidden_precision"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="estimated"):
        occlusion_accuracy(est[:2], truth)


def test_visibility_params_name_the_field() -> None:
    with pytest.raises(ValueError, match="^fb_tolerance:"):
        VisibilityParams(fb_tolerance=0)
    with pytest.raises(ValueError, match="^photo_factor:"):
        VisibilityParams(photo_factor=-1)
