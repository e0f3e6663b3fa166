"""Sparse-regularised TV-L1: the primal-dual solver of the combined energy."""

import numpy as np
import pytest
from _problems import linearised_sparse_problem

import varflow
from varflow.generators.pairs import synthetic_pair
from varflow.ops.primal_dual import row_blocks
from varflow.twoframe import sparse as sp
from varflow.twoframe.params import preset
from varflow.twoframe.tvl1 import tvl1_iterations

LAM, THETA, TAU, TOL = 40.0, 0.3, 0.25, 0.0


def _problem(seed=5, shape=(40, 48), aniso=False, wsp=0.5):
    terms, ubar, rng, u0 = linearised_sparse_problem(seed, shape, aniso)
    w_sp = (wsp * rng.uniform(0.5, 1.5, shape)).astype(np.float32)
    return terms, ubar, w_sp, u0


def _state(u0, nc, aniso, tens):
    h, w = u0.shape[1:]
    p = np.zeros((4, h, w), np.float32)
    tp = np.zeros_like(p) if aniso else p
    return dict(u=u0.copy(), p=p, tp=tp, q=np.zeros((nc, h, w), np.float32))


def _run_pd(fn, prob, ubar, wsp, u0, aniso, n_iter, lam_tv=1.0, n_sweeps=1):
    st = _state(u0, prob["a"].shape[0], aniso, prob["tens"])
    args = (*prob.values(), st["u"], st["p"], st["tp"], st["q"], ubar, wsp, np.float32(LAM),
            np.float32(lam_tv), np.float32(THETA), np.float32(TAU), n_iter, np.float32(TOL),
            n_sweeps, aniso)
    if fn is sp.sparse_pd_iterations:
        n = fn(*args, row_blocks(u0.shape[1]))
    else:
        n = fn(*args)
    assert n == n_iter
    return st


@pytest.mark.parametrize("aniso", [False, True])
@pytest.mark.parametrize("lam_tv", [1.0, 0.6])
def test_pd_engines_agree(aniso, lam_tv):
    prob, ubar, wsp, u0 = _problem(aniso=aniso)
    outs = [_run_pd(fn, prob, ubar, wsp, u0, aniso, 30, lam_tv=lam_tv, n_sweeps=2)
            for fn in (sp.sparse_pd_iterations, sp.sparse_pd_iterations_numpy)]
    for key in ("u", "p", "tp", "q"):
        np.testing.assert_allclose(outs[0][key], outs[1][key], atol=1e-4)
    assert np.abs(outs[0]["u"] - u0).max() > 0.05  # it moved


@pytest.mark.parametrize("aniso", [False, True])
def test_pd_without_sparse_weight_is_tvl1(aniso):
    prob, ubar, _, u0 = _problem(seed=7, aniso=aniso)
    pd = _run_pd(sp.sparse_pd_iterations, prob, ubar, np.zeros(u0.shape[1:], np.float32), u0,
                 aniso, 40)
    ref = _state(u0, prob["a"].shape[0], aniso, prob["tens"])
    tvl1_iterations(prob["ix"], prob["iy"], prob["a"], prob["g"], prob["tens"], ref["u"],
                    ref["p"], ref["tp"], ref["q"], np.float32(LAM), np.float32(THETA),
                    np.float32(TAU), 40, np.float32(TOL), 1, aniso, row_blocks(u0.shape[1]))
    # The two kernels are compiled separately with fastmath, so the rounding may differ:
    # measured up to 3e-6 after 40 iterations when one comes from Numba's cache and the
    # other is freshly compiled (0 when both come from the same state).  A sparse weight
    # of only w = 1e-3 already moves them apart by 5e-4, so 2e-5 still tests w = 0.
    for key in ("u", "p", "q"):
        np.testing.assert_allclose(pd[key], ref[key], atol=2e-5)


def test_pd_with_a_huge_sparse_weight_returns_ubar():
    """w → ∞ pins the auxiliary flow v to ū, so u = ROF_θ(ū) whatever the data.

    With the TV (nearly) off that is ū itself; with TV it is the result of the same
    iterations without data term.
    """
    prob, ubar, _, u0 = _problem(seed=9)
    far = np.abs(u0 - ubar).max()
    assert far > 0.3
    huge = np.full(u0.shape[1:], 1e6, np.float32)
    st = _run_pd(sp.sparse_pd_iterations, prob, ubar, huge, u0, False, 60, lam_tv=1e-4)
    assert np.abs(st["u"] - ubar).max() < 1e-3
    no_data = dict(prob, ix=0 * prob["ix"], iy=0 * prob["iy"], a=0 * prob["a"])
    st = _run_pd(sp.sparse_pd_iterations, prob, ubar, huge, u0, False, 100)
    ref = _run_pd(sp.sparse_pd_iterations, no_data, ubar, huge, u0, False, 100)
    np.testing.assert_allclose(st["u"], ref["u"], atol=1e-4)
    # and the pull grows with w
    errs = [np.abs(_run_pd(sp.sparse_pd_iterations, prob, ubar, np.full_like(huge, w), u0, False,
                           100)["u"] - ref["u"]).mean() for w in (0.0, 1.0, 10.0, 100.0)]
    assert all(e1 < e0 for e0, e1 in zip(errs, errs[1:], strict=False)) and errs[-1] < 0.01


def test_pd_lowers_the_combined_energy():
    """Its result has a lower exact (unsmoothed) energy than the start and than tvl1's."""
    prob, ubar, wsp, u0 = _problem(seed=11)

    def energy(u):
        return sp.smoothed_energy(u, *prob.values(), False, ubar, wsp, LAM, 1.0, 1e-9, 1e-9)

    st = _run_pd(sp.sparse_pd_iterations, prob, ubar, wsp, u0, False, 300)
    tv = _run_pd(sp.sparse_pd_iterations, prob, ubar, np.zeros_like(wsp), u0, False, 300)
    assert energy(st["u"]) < energy(u0) and energy(st["u"]) < energy(tv["u"])


def test_pd_solver_in_the_method():
    f0, f1, gt = synthetic_pair("smooth", shape=(96, 128), magnitude=3.0, seed=1)
    stats: dict = {}
    flow = varflow.flow(f0, f1, "sparse-1d", combined_solver="primal-dual", stats=stats)
    assert float(np.linalg.norm(flow - gt, axis=-1).mean()) < 0.10
    assert stats["sparse_warps"] > 0
    # w ≡ 0 with TV-L1's θ: the sparse warps are TV-L1 warps (7 per level); no early
    # stop, as TV-L1's kernel tests it after every second iteration, this one after each
    a = varflow.flow(f0, f1, "tvl1", params=preset("plain", n_warps=7, tolerance=0.0))
    b = varflow.flow(f0, f1, "sparse-1d", n_warps=5, sparse_warps=2, sparse_min_size=10,
                     combined_solver="primal-dual", sparse_weight=0.0, combined_coupling=0.3,
                     tolerance=0.0, combined_tolerance=0.0, combined_iterations=50)
    assert float(np.abs(a - b).max()) < 1e-4


def test_combined_solver_is_validated():
    with pytest.raises(ValueError, match="^combined_solver:"):
        preset("sparse-1d", combined_solver="admm")
    with pytest.raises(ValueError, match="^combined_iterations:"):
        preset("sparse-1d", combined_iterations=0)
    with pytest.raises(ValueError, match="^combined_coupling:"):
        preset("sparse-1d", combined_coupling=0.0)
    with pytest.raises(ValueError, match="^combined_tolerance:"):
        preset("sparse-1d", combined_tolerance=-1.0)
