"""The coarse-to-fine level and warp loop shared by the two-frame and multi-frame methods."""

import numpy as np

from varflow.generators.pairs import synthetic_pair
from varflow.ops.differences import derivative_planes
from varflow.ops.pyramid import pyramid_shapes
from varflow.ops.warp import warp_bicubic
from varflow.twoframe.coarse_to_fine import (
    LevelState,
    coarse_to_fine_pyramids,
    prepare_pyramid,
    run_levels,
)
from varflow.twoframe.tvl1 import TVL1Params, solve_warp

PARAMS = TVL1Params(max_iterations=30)


def _pyramids(frames):
    shapes = pyramid_shapes(frames[0].shape[:2], PARAMS.max_levels, PARAMS.scale_factor,
                            PARAMS.min_size)
    return [prepare_pyramid(f, PARAMS, shapes) for f in frames]


def test_a_stack_of_flows_is_a_set_of_independent_two_frame_runs():
    """run_levels on K flows, each warp solving every flow with its own level state,
    gives byte for byte the K flows of the two-frame driver (K = 2: the frames after
    the reference have different motions)."""
    f0, f1, _ = synthetic_pair("smooth", shape=(64, 80), magnitude=3.0, channels=3, seed=2)
    _, f2, _ = synthetic_pair("affine", shape=(64, 80), magnitude=2.0, channels=3, seed=2)
    pyrs = _pyramids([f0, f1, f2])
    shapes = [p.shape[:2] for p in pyrs[0]]
    want = [coarse_to_fine_pyramids(pyrs[0], pyrs[n], solve_warp, PARAMS) for n in (1, 2)]
    n_ch = pyrs[0][0].shape[2]
    ticks = []

    def start(level, flows, previous):
        prev = [None, None] if previous is None else previous
        return [LevelState(level=level, previous=prev[k]) for k in range(2)]

    def warp(states, flows, k):
        for i, st in enumerate(states):
            st.warp = k
            w, inside = warp_bicubic(derivative_planes(pyrs[i + 1][st.level]), flows[i])
            flows[i] = solve_warp(pyrs[0][st.level], w[..., :n_ch], w[..., n_ch:2 * n_ch],
                                  w[..., 2 * n_ch:], inside, flows[i], PARAMS, st)
        return flows

    got = run_levels(np.zeros((2,) + shapes[-1] + (2,), np.float32), shapes, PARAMS, start,
                     warp, guide=pyrs[0], tick=lambda: ticks.append(1))
    assert got.shape == (2, 64, 80, 2) and got.dtype == np.float32
    for k in range(2):
        np.testing.assert_array_equal(got[k], want[k])
    assert len(ticks) == len(shapes) * PARAMS.n_warps
    assert np.abs(want[0] - want[1]).max() > 1.0  # two different problems


def test_the_level_state_is_typed_and_keeps_one_coarser_level():
    f0, f1, gt = synthetic_pair("smooth", shape=(64, 80), magnitude=3.0, channels=3, seed=4)
    pyrs = _pyramids([f0, f1])
    seen = []

    def recording(I0, I1w, dx, dy, inside, flow0, params, state):
        assert isinstance(state, LevelState)
        seen.append((state.level, state.warp, None if state.previous is None
                     else (state.previous.level, state.previous.previous)))
        return solve_warp(I0, I1w, dx, dy, inside, flow0, params, state)

    stats: dict = {}
    flow = coarse_to_fine_pyramids(pyrs[0], pyrs[1], recording, PARAMS, stats=stats)
    n_levels = len(pyrs[0])
    assert [s[:2] for s in seen] == [(lv, k) for lv in range(n_levels - 1, -1, -1)
                                     for k in range(PARAMS.n_warps)]
    for level, _, prev in seen:
        assert prev == (None if level == n_levels - 1 else (level + 1, None))
    assert stats["levels"] == n_levels and stats["warps"] == n_levels * PARAMS.n_warps
    err = float(np.linalg.norm(flow - gt, axis=-1).mean())
    assert err < 0.25  # measured 0.140; the zero flow scores 1.13


def test_the_driver_does_not_write_into_the_initial_flow():
    f0, f1, gt = synthetic_pair("smooth", shape=(48, 56), magnitude=2.0, channels=1, seed=1)
    pyrs = _pyramids([f0, f1])
    init = (0.5 * gt).astype(np.float32)
    keep = init.copy()
    out = coarse_to_fine_pyramids(pyrs[0], pyrs[1], solve_warp, PARAMS, init_flow=init,
                                  levels=1)  # the finest level only: no resizing
    np.testing.assert_array_equal(init, keep)
    assert float(np.abs(out - init).max()) > 0.1
