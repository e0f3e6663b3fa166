"""The linear-L1 point-wise prox, every variant of :mod:`varflow.ops.prox`.

``prox(z) = argmin_v |v − z|²/(2t) + Σ_k |c_k + b_k·v|``: the Moreau identity with an
independent prox of the conjugate, agreement with brute force and with the exact
enumeration of faces on small random problems, and every Numba kernel against its
NumPy reference.
"""

import numpy as np
import pytest
from scipy.optimize import minimize

from varflow.multiframe.ustep import link_channels
from varflow.ops.prox import (
    certify_prox_row,
    clip_unit,
    data_prox_row,
    data_prox_row_pixel_step,
    linear_l1_energy,
    prox_certified,
    prox_faces,
    prox_linear_l1,
    prox_linear_l1_exact,
    prox_linear_l1_pixel_step,
    shrink_towards,
    soft_threshold,
)

RNG = np.random.default_rng(7)


def hw(x):
    """Planar ``(K, H, W)`` to channels last ``(H, W, K)`` (a view)."""
    return np.moveaxis(x, 0, -1)


def _terms(h, w, c, link=True, seed=0):
    rng = np.random.default_rng(seed)
    ix = (0.2 * rng.normal(size=(c, h, w))).astype(np.float32)
    iy = (0.2 * rng.normal(size=(c, h, w))).astype(np.float32)
    a = (0.1 * rng.normal(size=(c, h, w))).astype(np.float32)
    lk = rng.normal(size=(2, h, w)).astype(np.float32) if link else None
    return link_channels(ix, iy, a, lk, 0.05)


def _small_problems(n, k, seed):
    """``n`` random problems of ``k`` terms, planar ``(k, 1, n)`` float32, and centres
    ``(2, 1, n)`` spread over the regions, lines and crossings of the arrangement."""
    rng = np.random.default_rng(seed)
    ix = rng.normal(size=(k, 1, n)).astype(np.float32)
    iy = rng.normal(size=(k, 1, n)).astype(np.float32)
    a = (0.5 * rng.normal(size=(k, 1, n))).astype(np.float32)
    z = (rng.normal(size=(2, 1, n)) * rng.choice([0.1, 1.0, 3.0], size=(1, 1, n)))
    return z.astype(np.float32), a, ix, iy


def _conjugate_prox(x, a, ix, iy):
    """``prox_{f*}(x)`` for unit step, ``f(v) = Σ_k |a_k + b_k·v|``, solved on its own.

    ``f*(y) = min {−aᵀq : Bᵀq = y, |q|_∞ ≤ 1}``, so ``prox_{f*}(x) = Bᵀq*`` with ``q*``
    the minimiser of the box QP ``½|Bᵀq − x|² − aᵀq`` (float64; the better of SLSQP
    and L-BFGS-B, either of which can stop short on a rank-2 Hessian).
    """
    b = np.stack([ix, iy], -1).astype(np.float64)  # (K, 2)
    a = a.astype(np.float64)
    x = x.astype(np.float64)

    def fun(q):
        r = b.T @ q - x
        return 0.5 * r @ r - a @ q, b @ r - a

    options = {"SLSQP": {"ftol": 1e-15, "maxiter": 1000},
               "L-BFGS-B": {"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10000}}
    res = min((minimize(fun, np.zeros(len(a)), jac=True, method=m,
                        bounds=[(-1.0, 1.0)] * len(a), options=o)
               for m, o in options.items()), key=lambda r: r.fun)
    return b.T @ res.x


@pytest.mark.parametrize("k", [1, 2, 3, 5])
def test_moreau_identity_of_the_linear_l1_prox(k):
    # unit step: prox_f(x) + prox_{f*}(x) = x, the conjugate's prox found by a QP solver
    z, a, ix, iy = _small_problems(40, k, seed=k)
    exact = prox_linear_l1_exact(hw(z), hw(a), hw(ix), hw(iy), 1.0)[0]
    faces = hw(prox_faces(z, a, ix, iy, 1.0))[0]
    cert = hw(prox_certified(z, a, ix, iy, 1.0)[0])[0]
    cd = prox_linear_l1(hw(z), hw(a), hw(ix), hw(iy), 1.0, n_sweeps=2000)[0][0]
    for j in range(z.shape[2]):
        x = z[:, 0, j]
        dual = _conjugate_prox(x, a[:, 0, j], ix[:, 0, j], iy[:, 0, j])
        np.testing.assert_allclose(exact[j] + dual, x, atol=2e-5)
        np.testing.assert_allclose(faces[j] + dual, x, atol=2e-5)
        np.testing.assert_allclose(cert[j] + dual, x, atol=2e-5)
        np.testing.assert_allclose(cd[j] + dual, x, atol=1e-3)


def test_moreau_identity_of_shrink_towards():
    # f(x) = thr |x − l|: f*(y) = l y + δ(|y| ≤ thr), prox_{f*}(c) = clip(c − l, ±thr)
    rng = np.random.default_rng(2)
    for _ in range(200):
        c, lk = rng.normal(size=2) * 2
        thr = rng.uniform(0.01, 2.0)
        got = shrink_towards(c, lk, thr)
        assert abs(got + thr * clip_unit((c - lk) / thr) - c) < 1e-12
        assert abs(got - (lk + soft_threshold(c - lk, thr))) < 1e-12  # its NumPy reference


@pytest.mark.parametrize("k", [1, 2, 3, 4])
@pytest.mark.parametrize("t", [0.1, 1.0, 4.0])
def test_the_exact_prox_agrees_with_brute_force(k, t):
    # the energy is 1/t-strongly convex: E(v) − E(v*) ≥ |v − v*|²/(2t) bounds the
    # distance of a brute-force minimiser (Nelder-Mead from three starts) to v*
    z, a, ix, iy = _small_problems(12, k, seed=10 * k)
    exact = prox_linear_l1_exact(hw(z), hw(a), hw(ix), hw(iy), t)[0]
    faces = hw(prox_faces(z, a, ix, iy, t))[0].astype(np.float64)
    for j in range(z.shape[2]):
        args = tuple(np.float64(v[:, 0, j]) for v in (z, a, ix, iy))

        def energy(v, args=args):
            zz, aa, gx, gy = args
            return linear_l1_energy(np.asarray(v)[None], zz[None], aa[None], gx[None],
                                    gy[None], t)[0]

        best = min((minimize(energy, s, method="Nelder-Mead",
                             options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 20000})
                    for s in (args[0], exact[j] + 0.3, exact[j] - 0.2)),
                   key=lambda r: r.fun)
        e_exact = energy(exact[j])
        assert e_exact <= best.fun + 1e-12
        gap = max(best.fun - e_exact, 0.0)
        assert np.sum((best.x - exact[j]) ** 2) <= 2 * t * gap + 1e-10
        np.testing.assert_allclose(faces[j], exact[j], atol=2e-5 * max(1.0, t))


@pytest.mark.parametrize("c", [1, 3])
def test_prox_faces_matches_numpy_enumeration(c):
    h, w = 6, 7
    ix, iy, a = _terms(h, w, c, seed=c)
    u = RNG.normal(size=(2, h, w)).astype(np.float32)
    t = 0.7
    got = prox_faces(u, a, ix, iy, t)
    ref = prox_linear_l1_exact(hw(u), hw(a), hw(ix), hw(iy), t)
    np.testing.assert_allclose(hw(got), ref, atol=2e-5)
    # and it is the minimiser: random perturbations never lower the energy
    e0 = linear_l1_energy(ref, hw(u), hw(a), hw(ix), hw(iy), t)
    for _ in range(20):
        d = ref + 1e-3 * RNG.normal(size=ref.shape)
        assert np.all(linear_l1_energy(d, hw(u), hw(a), hw(ix), hw(iy), t) >= e0 - 1e-9)


def _degenerate_terms(h, w, seed):
    """Colour-like terms with the hard cases mixed in: a channel without gradient,
    two channels with parallel gradients, and three lines through one point."""
    ix, iy, a = _terms(h, w, 3, seed=seed)
    ix, iy, a = ix.copy(), iy.copy(), a.copy()
    ix[0, ::3], iy[0, ::3] = 0.0, 0.0  # constant term
    ix[1, 1::3], iy[1, 1::3] = 2 * ix[2, 1::3], 2 * iy[2, 1::3]  # parallel lines
    a[1, 1::3] = 2 * a[2, 1::3]  # ... and coincident
    # lines of channels 0 and 1 through the crossing of the two link lines
    for c in (0, 1):
        sl = (c, slice(2, None, 3))
        a[sl] = -(ix[sl] * (-a[3, 2::3] / ix[3, 2::3]) + iy[sl] * (-a[4, 2::3] / iy[4, 2::3]))
    return ix, iy, a


@pytest.mark.parametrize("c", [1, 3])
@pytest.mark.parametrize("t", [0.05, 0.7, 5.0])
def test_certified_prox_equals_the_enumeration(c, t):
    h, w = 24, 30
    rng = np.random.default_rng(20 + c)
    ix, iy, a = _terms(h, w, c, seed=10 + c)
    u = rng.normal(size=(2, h, w)).astype(np.float32)
    ref = prox_faces(u, a, ix, iy, t)
    v, q, _ = prox_certified(u, a, ix, iy, t)  # cold start
    np.testing.assert_allclose(v, ref, atol=1e-5)
    assert np.all(np.abs(q) <= 1)
    # from its own duals every pixel certifies at once, with the same point
    v2, _, n_warm = prox_certified(u, a, ix, iy, t, q=q, n_sweeps=0)
    assert n_warm == 0
    np.testing.assert_allclose(v2, ref, atol=1e-5)
    # wrong duals never give a wrong point: they fall back or certify the true one
    bad = np.sign(rng.uniform(-1, 1, size=q.shape)).astype(np.float32)
    v3, _, n_bad = prox_certified(u, a, ix, iy, t, q=bad, n_sweeps=0)
    assert n_bad > 0
    np.testing.assert_allclose(v3, ref, atol=1e-5)


def test_certified_prox_on_degenerate_terms():
    h, w = 18, 21
    ix, iy, a = _degenerate_terms(h, w, seed=3)
    rng = np.random.default_rng(5)
    for t in (0.1, 1.0):
        u = rng.normal(size=(2, h, w)).astype(np.float32)
        ref = prox_faces(u, a, ix, iy, t)
        v, _, n_fall = prox_certified(u, a, ix, iy, t, n_sweeps=3)
        assert n_fall > 0  # the hard pixels do reach the enumeration
        # the energy is strongly convex: one minimiser, whatever the degeneracy
        np.testing.assert_allclose(v, ref, atol=1e-5)
        e_ref = linear_l1_energy(hw(ref), hw(u), hw(a), hw(ix), hw(iy), t)
        e_v = linear_l1_energy(hw(v), hw(u), hw(a), hw(ix), hw(iy), t)
        assert np.all(e_v <= e_ref + 1e-6)


@pytest.mark.parametrize("n_sweeps", [1, 3])
def test_data_prox_row_matches_its_numpy_reference(n_sweeps):
    h, w, c = 5, 33, 3
    ix, iy, a = _terms(h, w, c, link=False, seed=4)
    u = RNG.normal(size=(2, h, w)).astype(np.float32)
    q0 = RNG.uniform(-1, 1, size=(c, h, w)).astype(np.float32)
    q0[:, 0, :5] = 0.0
    ix[1, 1, :4] = 0.0  # terms without gradient
    iy[1, 1, :4] = 0.0
    t = np.float32(0.6)
    q = q0.copy()
    d = np.empty_like(u)
    for i in range(h):
        d1, d2 = u[0, i].copy(), u[1, i].copy()
        data_prox_row(ix, iy, a, q, i, d1, d2, t, n_sweeps)
        d[0, i], d[1, i] = d1, d2
    ref, q_ref = prox_linear_l1(hw(u), hw(a), hw(ix), hw(iy), t, n_sweeps=n_sweeps,
                                q0=hw(q0))
    np.testing.assert_allclose(hw(d), ref, atol=1e-5)
    np.testing.assert_allclose(hw(q), q_ref, atol=1e-5)


@pytest.mark.parametrize("n_sweeps", [1, 3])
def test_data_prox_row_pixel_step_matches_its_numpy_reference(n_sweeps):
    h, w, c = 5, 33, 3
    ix, iy, a = _terms(h, w, c, link=False, seed=6)
    z = RNG.normal(size=(2, h, w)).astype(np.float32)
    t = RNG.uniform(0.05, 2.0, size=(h, w)).astype(np.float32)
    q0 = RNG.uniform(-1, 1, size=(c, h, w)).astype(np.float32)
    q = q0.copy()
    d = np.empty_like(z)
    for i in range(h):
        d1, d2 = z[0, i].copy(), z[1, i].copy()
        data_prox_row_pixel_step(ix, iy, a, q, i, d1, d2, t[i], n_sweeps)
        d[0, i], d[1, i] = d1, d2
    q_ref = q0.copy()
    ref = prox_linear_l1_pixel_step((z[0], z[1]), a, ix, iy, t, q_ref, n_sweeps)
    np.testing.assert_allclose(d, np.stack(ref), atol=1e-5)
    np.testing.assert_allclose(q, q_ref, atol=1e-5)
    # with the same step everywhere it is the prox of one step
    q_one = q0.copy()
    one = prox_linear_l1_pixel_step((z[0], z[1]), a, ix, iy, np.float32(0.6), q_one, n_sweeps)
    two, q_two = prox_linear_l1(hw(z), hw(a), hw(ix), hw(iy), np.float32(0.6),
                                n_sweeps=n_sweeps, q0=hw(q0))
    np.testing.assert_allclose(hw(np.stack(one)), two, atol=1e-6)
    np.testing.assert_allclose(hw(q_one), q_two, atol=1e-6)


def test_certify_prox_row_makes_the_descent_exact():
    # the row kernel inside the U-step: after a sweep of data_prox_row, the certified
    # row is the exact prox (prox_faces), whatever the descent left
    h, w = 6, 25
    ix, iy, a = _terms(h, w, 3, seed=8)
    u = RNG.normal(size=(2, h, w)).astype(np.float32)
    t = np.float32(0.7)
    ref = prox_faces(u, a, ix, iy, float(t))
    q = np.zeros_like(a)
    sc = np.empty((4, a.shape[0]), np.float64)
    for i in range(h):
        d1, d2 = u[0, i].copy(), u[1, i].copy()
        data_prox_row(ix, iy, a, q, i, d1, d2, t, 1)
        certify_prox_row(ix, iy, a, q, i, u[0, i], u[1, i], d1, d2, t, sc)
        np.testing.assert_allclose(d1, ref[0, i], atol=1e-5)
        np.testing.assert_allclose(d2, ref[1, i], atol=1e-5)
    assert np.all(np.abs(q) <= 1)
