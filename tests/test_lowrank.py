"""The L-step of RLR: PCP (exact and linear-time), l1 filtering, the trajectory matrix view."""

import numpy as np
import pytest
from scipy.optimize import linprog

from varflow.multiframe.lowrank import (
    estimate_basis,
    l1_regression,
    l1_regression_numpy,
    lowrank_step,
    matrix_to_trajectories,
    noise_rank,
    rpca_exact,
    rpca_linear,
    sample_columns,
    trajectories_to_matrix,
)

M, N, RANK = 60, 4000, 3


def _planted(m=M, n=N, rank=RANK, frac=0.05, mag=10.0, seed=0):
    """Low-rank L0 (Gaussian factors) plus sparse gross errors S0 (uniform in ±[mag/2, mag])."""
    rng = np.random.default_rng(seed)
    l0 = (rng.normal(size=(m, rank)) @ rng.normal(size=(rank, n))).astype(np.float32)
    mask = rng.random((m, n)) < frac
    s0 = np.zeros((m, n), np.float32)
    k = int(mask.sum())
    s0[mask] = rng.uniform(mag / 2, mag, k) * rng.choice([-1.0, 1.0], k)
    return l0 + s0, l0, s0


def _rel(a, b):
    return float(np.linalg.norm(np.asarray(a, np.float64) - b) / np.linalg.norm(b))


@pytest.fixture(scope="module", params=[0, 1])
def solved(request):
    u, l0, s0 = _planted(seed=request.param)
    exact = rpca_exact(u)
    linear = rpca_linear(u, n_samples=1200, seed=request.param)  # a sample of 20 M
    return u, l0, s0, exact, linear


# ------------------------------------------------------------------ matrix view
def test_trajectory_matrix_row_order_and_roundtrip():
    rng = np.random.default_rng(3)
    traj = rng.normal(size=(4, 5, 7, 2)).astype(np.float32)
    u = trajectories_to_matrix(traj)
    assert u.shape == (8, 35) and u.dtype == np.float32
    for n, y, x in [(0, 0, 0), (2, 3, 4), (3, 4, 6)]:
        assert u[2 * n, y * 7 + x] == traj[n, y, x, 0]
        assert u[2 * n + 1, y * 7 + x] == traj[n, y, x, 1]
    np.testing.assert_array_equal(matrix_to_trajectories(u, 5, 7), traj)
    with pytest.raises(ValueError, match="traj"):
        trajectories_to_matrix(traj[..., 0])
    with pytest.raises(ValueError, match="U"):
        matrix_to_trajectories(u, 5, 6)


# ------------------------------------------------------------------ exact PCP
def test_rpca_exact_recovers_planted(solved):
    u, l0, s0, (L, S, info), _ = solved
    assert info["lam"] == pytest.approx(1 / np.sqrt(N))
    assert info["converged"] and info["relative_residual"] < 1e-7
    assert info["rank"] == RANK
    assert L.dtype == np.float32 and S.dtype == np.float32
    assert _rel(L, l0) < 1e-3
    assert _rel(S, s0) < 1e-3
    np.testing.assert_allclose(L + S, u, atol=1e-4)


def test_rpca_exact_objective_not_above_planted(solved):
    u, l0, s0, (_, _, info), _ = solved
    lam = info["lam"]
    planted = np.linalg.svd(l0.astype(np.float64), compute_uv=False).sum() + lam * np.abs(
        s0.astype(np.float64)
    ).sum()
    assert info["objective"] <= planted * (1 + 1e-6)
    assert info["objective"] >= planted * (1 - 1e-6)  # planted pair is optimal here


def test_rpca_exact_float64_and_zero_matrix():
    u, l0, _ = _planted(n=800, seed=5)
    L, S, info = rpca_exact(u.astype(np.float64), lam=1 / np.sqrt(800))
    assert L.dtype == np.float64 and S.dtype == np.float64
    assert _rel(L, l0) < 1e-3
    Lz, Sz, iz = rpca_exact(np.zeros((6, 10), np.float32))
    assert not Lz.any() and not Sz.any() and iz["iterations"] == 0


# ------------------------------------------------------------------ linear-time PCP
def test_default_sample_is_20_per_row_and_at_least_the_floor():
    from varflow.multiframe.lowrank import DEFAULT_MIN_SAMPLES

    rng = np.random.default_rng(0)
    for m, n in ((10, 9000), (10, 3000), (240, 6000)):
        u = rng.normal(size=(m, n)).astype(np.float32)
        _, _, info = rpca_linear(u, max_iter=2, l1_max_iter=2)
        assert info["n_samples"] == min(n, max(20 * m, DEFAULT_MIN_SAMPLES)), (m, n)
    assert DEFAULT_MIN_SAMPLES == 4000


def test_rpca_linear_agrees_with_exact_and_recovers(solved):
    _, l0, s0, (L, _, _), (Ll, Sl, info) = solved
    assert Ll.dtype == np.float32
    assert _rel(Ll, L) < 1e-2
    assert _rel(Ll, l0) < 1e-3
    assert _rel(Sl, s0) < 1e-3
    assert info["rank"] == RANK
    assert info["n_samples"] == 1200
    assert info["columns"].shape == (1200,) and np.unique(info["columns"]).size == 1200
    assert info["lam_sample"] == pytest.approx(info["lam"] * np.sqrt(N / 1200))
    assert info["l1_unconverged"] == 0
    b = info["basis"]
    assert b.shape == (M, RANK)
    np.testing.assert_allclose(b.T @ b, np.eye(RANK), atol=1e-10)


def test_rpca_linear_numpy_engine_matches_numba():
    u, l0, _ = _planted(n=2500, seed=7)
    Ln, _, inn = rpca_linear(u, engine="numba")
    Lp, _, inp = rpca_linear(u, engine="numpy")
    assert inn["rank"] == inp["rank"] == RANK
    assert _rel(Ln, Lp) < 1e-6
    assert _rel(Ln, l0) < 1e-3


@pytest.mark.parametrize("rank", [1, 3, 5])
def test_rank_estimate_equals_planted_rank(rank):
    u, l0, _ = _planted(n=3000, rank=rank, frac=0.03, seed=10 + rank)
    assert estimate_basis(l0).shape == (M, rank)
    L, _, info = rpca_linear(u, seed=rank)
    assert info["rank"] == rank
    assert info["seed_info"]["rank"] == rank
    assert _rel(L, l0) < 1e-3
    assert estimate_basis(l0, max_rank=1).shape == (M, 1)


def test_rpca_linear_seeding_and_warm_start():
    u, l0, _ = _planted(n=3000, seed=11)
    L1, _, i1 = rpca_linear(u, n_samples=400, seed=4)
    L2, _, i2 = rpca_linear(u, n_samples=400, seed=4)
    L3, _, i3 = rpca_linear(u, n_samples=400, seed=5)
    np.testing.assert_array_equal(i1["columns"], i2["columns"])
    np.testing.assert_array_equal(L1, L2)
    assert not np.array_equal(i1["columns"], i3["columns"])
    assert _rel(L3, l0) < 1e-3 and _rel(L1, l0) < 1e-3
    # warm start with the previous basis, and with another basis of the same span
    Lw, _, iw = rpca_linear(u, basis=i1["basis"])
    assert iw["warm_start"] and iw["columns"] is None and iw["seed_info"] is None
    assert _rel(Lw, L1) < 1e-6
    mix = np.random.default_rng(0).normal(size=(RANK, RANK))
    Lm, _, im = rpca_linear(u, basis=3.0 * i1["basis"] @ mix)
    assert im["rank"] == RANK and _rel(Lm, L1) < 1e-5
    # more samples than columns are clipped; a tiny problem equals seed PCP + refit
    _, _, ic = rpca_linear(u[:, :500], n_samples=10_000)
    assert ic["n_samples"] == 500


def test_rpca_linear_without_the_residual_returns_the_same_low_rank_part():
    u, l0, _ = _planted(n=2000, seed=12)
    L, S, _ = rpca_linear(u, seed=3)
    Ln, none, info = rpca_linear(u, seed=3, residual=False)
    assert none is None and info["rank"] == RANK
    np.testing.assert_array_equal(L, Ln)
    np.testing.assert_array_equal(S, u - L)
    assert _rel(Ln, l0) < 1e-3


def test_rpca_linear_zero_matrix():
    L, S, info = rpca_linear(np.zeros((8, 50)))
    assert L.dtype == np.float64 and not L.any() and not S.any() and info["rank"] == 0


# ------------------------------------------------------------------ l1 filtering
def _regression_problem(n=1500, m=M, r=4, seed=20, noise=0.05):
    rng = np.random.default_rng(seed)
    basis = rng.normal(size=(m, r))  # deliberately not orthonormal
    clean = basis @ rng.normal(size=(r, n)) * 2
    u = clean + noise * rng.normal(size=(m, n))
    mask = rng.random((m, n)) < 0.08
    u[mask] += rng.uniform(-20, 20, int(mask.sum()))
    return u, basis, clean


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_l1_regression_numba_matches_numpy(dtype):
    u, basis, _ = _regression_problem()
    u = u.astype(dtype)
    a, ia = l1_regression(u, basis)
    b, ib = l1_regression_numpy(u, basis)
    assert a.dtype == b.dtype == dtype
    scale = np.abs(u).max()
    np.testing.assert_allclose(a, b, atol=1e-5 * scale, rtol=0)
    assert np.mean(ia["iterations"] == ib["iterations"]) > 0.95
    assert ia["unconverged"] == ib["unconverged"] == 0
    assert 5 < ia["iterations_mean"] < 60


def test_l1_regression_fits_clean_column_despite_gross_outliers():
    rng = np.random.default_rng(21)
    basis = rng.normal(size=(M, 4))
    clean = basis @ rng.normal(size=(4, 3))
    u = clean.copy()
    u[[3, 17, 40, 52, 58], 0] += [50.0, -35.0, 80.0, 20.0, -60.0]
    u[[0, 1, 2], 1] += 100.0  # adjacent outliers
    for fit in (l1_regression(u, basis)[0], l1_regression_numpy(u, basis)[0]):
        np.testing.assert_allclose(fit, clean, atol=1e-5)
    ls = basis @ np.linalg.lstsq(basis, u, rcond=None)[0]
    assert np.abs(ls[:, :2] - clean[:, :2]).max() > 1.0  # least squares is not robust


def test_l1_regression_is_near_the_lp_optimum():
    u, basis, _ = _regression_problem(n=30, seed=22, noise=0.2)
    fit, _ = l1_regression(u, basis)
    q, _ = np.linalg.qr(basis)
    m, r = q.shape
    a_ub = np.block([[-q, -np.eye(m)], [q, -np.eye(m)]])
    bounds = [(None, None)] * r + [(0, None)] * m
    gaps = []
    for j in range(u.shape[1]):
        res = linprog(np.r_[np.zeros(r), np.ones(m)], A_ub=a_ub, b_ub=np.r_[-u[:, j], u[:, j]],
                      bounds=bounds, method="highs")
        assert res.status == 0
        ours = np.abs(u[:, j] - fit[:, j]).sum()
        gaps.append((ours - res.fun) / res.fun)
    gaps = np.array(gaps)
    assert gaps.min() > -1e-7  # never better than the optimum (sanity of the comparison)
    assert gaps.max() < 2e-3
    # a slower μ schedule gets closer
    fit2, _ = l1_regression(u, basis, rho=1.1)
    obj2 = np.abs(u - fit2).sum(0)
    obj1 = np.abs(u - fit).sum(0)
    assert obj2.sum() <= obj1.sum()


def test_l1_regression_zero_columns():
    u = np.zeros((M, 5), np.float32)
    u[:, 2] = 1.0
    fit, info = l1_regression(u, np.ones((M, 1)))
    np.testing.assert_allclose(fit[:, 2], 1.0, atol=1e-6)
    assert not fit[:, [0, 1, 3, 4]].any() and info["iterations"][0] == 0


def test_weighted_l1_regression_ignores_zero_weight_entries():
    """A zero weight removes an entry from the fit: more than half of a column may be junk."""
    rng = np.random.default_rng(23)
    basis = rng.normal(size=(M, 3))
    clean = basis @ rng.normal(size=(3, 40))
    u = clean.copy()
    junk = rng.random(u.shape) < 0.6  # too many gross errors for the plain L1 fit
    u[junk] += rng.uniform(5, 30, int(junk.sum())) * rng.choice([-1, 1], int(junk.sum()))
    wts = (~junk).astype(np.float32)
    for solver in (l1_regression, l1_regression_numpy):
        # the stopping rule sees no residual on free entries, so with 60 % of them free
        # the iteration stops a little short (measured max error 0.011 on values ~10)
        fit, _ = solver(u, basis, weights=wts)
        np.testing.assert_allclose(fit, clean, atol=0.03)
        plain, _ = solver(u, basis)
        assert np.abs(plain - clean).max() > 1.0
    a, _ = l1_regression(u.astype(np.float32), basis, weights=wts)
    b, _ = l1_regression_numpy(u.astype(np.float32), basis, weights=wts)
    np.testing.assert_allclose(a, b, atol=1e-4)
    with pytest.raises(ValueError, match="weights"):
        l1_regression(u, basis, weights=-wts)
    with pytest.raises(ValueError, match="weights"):
        l1_regression(u, basis, weights=wts[:, :3])


def _small_object_trajectories(f=20, n=6000, share=0.02, seed=4):
    """Trajectory matrix: a background translating along a curve, a small object otherwise."""
    rng = np.random.default_rng(seed)
    t = np.linspace(-1, 1, f)
    bg = np.stack([3 * t + np.sin(2 * t), 2 * t**2], 1).reshape(-1)  # (2F,)
    obj = np.stack([-6 * t, 4 * np.sin(3 * t)], 1).reshape(-1)
    u = np.repeat(bg[:, None], n, 1) * rng.uniform(0.9, 1.1, n)  # mild zoom per pixel
    is_obj = np.zeros(n, bool)
    is_obj[rng.choice(n, int(share * n), replace=False)] = True
    u[:, is_obj] = obj[:, None] * rng.uniform(0.95, 1.05, is_obj.sum())
    return u.astype(np.float32), is_obj


def test_stratified_sample_represents_every_motion_layer():
    u, is_obj = _small_object_trajectories()
    rng = np.random.default_rng(0)
    uni = sample_columns(u, 100, rng)
    strat = sample_columns(u, 100, rng, strata=4)
    assert len(strat) == 100 == len(np.unique(strat)) and np.all(np.diff(strat) > 0)
    assert is_obj[uni].sum() <= 6  # ~2 expected
    assert is_obj[strat].sum() >= 20  # an equal share of its cluster
    # reliable columns come first within a cluster
    reliable = np.ones(u.shape[1], bool)
    reliable[::2] = False
    pick = sample_columns(u, 100, np.random.default_rng(1), strata=4, reliable=reliable)
    assert reliable[pick].all()


def test_a_planted_small_object_survives_the_lowrank_step():
    """Its motion gets a basis vector only when the sample is stratified (2 % of columns)."""
    u, is_obj = _small_object_trajectories()
    lam = 1.0 / np.sqrt(u.shape[1])
    errs = {}
    for strata in (0, 4):
        low, _, info = rpca_linear(u, lam, n_samples=100, seed=3, strata=strata,
                                   rank_tol=0.03)
        errs[strata] = float(np.abs(low - u)[:, is_obj].mean())
    assert errs[0] > 1.0, errs  # the object's columns are fitted to the background
    assert errs[4] < 0.1 * errs[0], errs


@pytest.mark.parametrize("rank", [2, 5, 9])
def test_noise_rank_finds_the_planted_rank_under_white_noise(rank):
    rng = np.random.default_rng(rank)
    m, n = 40, 2000
    sig = rng.normal(size=(m, rank)) @ rng.normal(size=(rank, n)) * np.linspace(3, 1, rank)[0]
    data = sig + 0.05 * rng.normal(size=(m, n))
    r, thr = noise_rank(data)
    assert r == rank and thr > 0
    assert noise_rank(np.zeros((5, 7))) == (0, 0.0)


# ------------------------------------------------------------------ the L-step
def test_lowrank_step_maps_alpha_tau_to_lambda():
    u, l0, _ = _planted(n=1000, seed=30)
    lam = 1 / np.sqrt(1000)
    L, S, info = lowrank_step(u, alpha=2.0, tau=2.0 * lam, method="exact")
    Lr, _, _ = rpca_exact(u, lam)
    assert info["lam"] == pytest.approx(lam)
    np.testing.assert_array_equal(L, Lr)
    np.testing.assert_allclose(S, u - L, atol=1e-4)

    def energy(x):  # α ||L||_* + τ ||U − L||_1 of the L-step, α = 2
        x = x.astype(np.float64)
        return 2.0 * np.linalg.svd(x, compute_uv=False).sum() + 2.0 * lam * np.abs(u - x).sum()

    assert energy(L) <= energy(l0) * (1 + 1e-6)
    assert energy(L) < energy(u.astype(np.float64)) and energy(L) < energy(0 * u)
    Ll, _, il = lowrank_step(u, alpha=2.0, tau=2.0 * lam)
    assert il["lam"] == pytest.approx(lam) and _rel(Ll, l0) < 1e-3
    Lw, _, iw = lowrank_step(u, 1.0, lam, basis=il["basis"])
    assert iw["warm_start"] and _rel(Lw, Ll) < 1e-6


# ------------------------------------------------------------------ validation
@pytest.mark.parametrize("solver", [rpca_exact, rpca_linear])
def test_input_validation_names_the_argument(solver):
    u, _, _ = _planted(n=100, seed=40)
    bad = u.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="U: contains NaN"):
        solver(bad)
    bad[3, 4] = np.inf
    with pytest.raises(ValueError, match="U: contains NaN"):
        solver(bad)
    for wrong in (u[0], u[None]):
        with pytest.raises(ValueError, match="U: expected a 2-D"):
            solver(wrong)
    for lam in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="lam"):
            solver(u, lam)
    with pytest.raises(ValueError, match="rho"):
        solver(u, rho=1.0)
    with pytest.raises(ValueError, match="max_iter"):
        solver(u, max_iter=0)


def test_validation_of_linear_and_step_arguments():
    u, _, _ = _planted(n=100, seed=41)
    with pytest.raises(ValueError, match="n_samples"):
        rpca_linear(u, n_samples=0)
    with pytest.raises(ValueError, match="basis"):
        rpca_linear(u, basis=np.ones((M - 1, 2)))
    with pytest.raises(ValueError, match="basis"):
        rpca_linear(u, basis=np.ones((M, 2)))  # rank deficient
    with pytest.raises(ValueError, match="l1_rho"):
        rpca_linear(u, l1_rho=0.5)
    with pytest.raises(ValueError, match="engine"):
        rpca_linear(u, engine="cuda")
    with pytest.raises(ValueError, match="rank_tol"):
        rpca_linear(u, rank_tol=1.5)
    with pytest.raises(ValueError, match="alpha"):
        lowrank_step(u, 0.0, 1.0)
    with pytest.raises(ValueError, match="tau"):
        lowrank_step(u, 1.0, -1.0)
    with pytest.raises(ValueError, match="method"):
        lowrank_step(u, 1.0, 1.0, method="svd")
    with pytest.raises(ValueError, match="U: contains NaN"):
        l1_regression(np.full((4, 3), np.nan), np.eye(4)[:, :2])
    with pytest.raises(ValueError, match="basis"):
        l1_regression_numpy(np.ones((4, 3)), np.eye(5)[:, :2])
