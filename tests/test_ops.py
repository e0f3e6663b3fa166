"""Operators come in tested pairs: adjoints, Moreau identities, engine agreement."""

import numpy as np
import pytest

from varflow.ops.differences import (
    derivative_planes,
    derivative_planes_numpy,
    divergence,
    gradient,
    image_derivatives,
)
from varflow.ops.median import median_filter_flow, median_filter_flow_numpy
from varflow.ops.prox import (
    clip_unit,
    linear_l1_energy,
    project_l2_ball,
    prox_huber_conjugate,
    prox_huber_norm,
    prox_l2_norm,
    prox_linear_l1,
    prox_linear_l1_exact,
    soft_threshold,
)
from varflow.ops.pyramid import (
    build_pyramid,
    pyramid_shapes,
    resize_bilinear,
    resize_flow,
    smooth_image,
    smooth_image_fast,
    smooth_planes,
)
from varflow.ops.rof import rof_denoise, rof_denoise_numpy, structure_texture
from varflow.ops.warp import warp_bicubic, warp_bicubic_numpy


@pytest.mark.parametrize("shape", [(2, 2), (7, 11), (64, 48)])
def test_gradient_divergence_adjoint(shape):
    rng = np.random.default_rng(0)
    u = rng.normal(size=shape)
    p = rng.normal(size=shape + (2,))
    lhs = float((gradient(u) * p).sum())
    rhs = -float((u * divergence(p)).sum())
    assert abs(lhs - rhs) <= 1e-10 * max(1.0, abs(lhs))


def test_gradient_of_ramp_and_neumann_border():
    u = np.tile(np.arange(5.0), (4, 1)) * 2.0
    g = gradient(u)
    np.testing.assert_array_equal(g[:, :-1, 0], 2.0)
    np.testing.assert_array_equal(g[:, -1, 0], 0.0)
    np.testing.assert_array_equal(g[..., 1], 0.0)


def test_image_derivatives_exact_on_quadratic():
    yy, xx = np.mgrid[0:20, 0:30].astype(np.float64)
    img = (0.001 * xx**2 + 0.002 * yy * xx)[..., None].astype(np.float32)
    dx, dy = image_derivatives(img)
    inner = (slice(2, -2), slice(2, -2), 0)
    np.testing.assert_allclose(dx[inner], (0.002 * xx + 0.002 * yy)[2:-2, 2:-2], atol=1e-5)
    np.testing.assert_allclose(dy[inner], (0.002 * xx)[2:-2, 2:-2], atol=1e-5)


@pytest.mark.parametrize("shape", [(1, 1, 1), (3, 2, 3), (29, 37, 3)])
def test_derivative_planes_engines_agree(shape):
    img = np.random.default_rng(8).random(shape, dtype=np.float32)
    got = derivative_planes(img)
    assert got.shape == shape[:2] + (3 * shape[2],) and got.dtype == np.float32
    np.testing.assert_allclose(got, derivative_planes_numpy(img), atol=1e-6)


def test_moreau_soft_threshold_and_l2():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(50, 2)) * 3
    for t in (0.1, 1.0, 4.0):
        np.testing.assert_allclose(soft_threshold(x, t) + t * clip_unit(x / t), x, atol=1e-12)
        np.testing.assert_allclose(prox_l2_norm(x, t) + t * project_l2_ball(x / t), x, atol=1e-12)


@pytest.mark.parametrize("eps", [0.0, 0.05, 0.5])
def test_moreau_huber_pair(eps):
    rng = np.random.default_rng(21)
    x = rng.normal(size=(200, 2)) * rng.choice([0.01, 0.3, 3.0], size=(200, 1))
    r = rng.uniform(0.05, 1.0, size=200)
    t = 0.7
    left = prox_huber_norm(x, t, eps, r) + t * prox_huber_conjugate(x / t, 1 / t, eps, r)
    np.testing.assert_allclose(left, x, atol=1e-10)
    # the prox minimises its energy: better than random perturbations
    y = prox_huber_norm(x, t, eps, r)

    def energy(z):
        n = np.sqrt((z * z).sum(-1))
        hub = np.where(n <= eps, n * n / (2 * eps) if eps else 0 * n, n - eps / 2)
        return t * r * hub + ((z - x) ** 2).sum(-1) / 2

    for _ in range(5):
        z = y + rng.normal(size=y.shape) * 0.01
        assert np.all(energy(z) >= energy(y) - 1e-12)
    if eps == 0:
        np.testing.assert_allclose(y, prox_l2_norm(x, t * r[:, None]), atol=1e-12)


def test_project_l2_ball_radius_map():
    p = np.array([[[3.0, 4.0], [0.3, 0.4]]])
    out = project_l2_ball(p, np.array([[2.0, 1.0]]))
    np.testing.assert_allclose(out, [[[1.2, 1.6], [0.3, 0.4]]])


def _data_problem(n, c, seed):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 2)).astype(np.float32)
    a = rng.normal(size=(n, c)).astype(np.float32) * 0.3
    gx = rng.normal(size=(n, c)).astype(np.float32)
    gy = rng.normal(size=(n, c)).astype(np.float32)
    return u, a, gx, gy


def test_grey_data_prox_is_exact_in_one_sweep():
    u, a, gx, gy = _data_problem(500, 1, 2)
    t = 0.4
    d, _ = prox_linear_l1(u, a, gx, gy, t, n_sweeps=1)
    exact = prox_linear_l1_exact(u, a, gx, gy, t)
    np.testing.assert_allclose(d, exact, atol=1e-5)


def test_colour_data_prox_converges_to_exact():
    u, a, gx, gy = _data_problem(400, 3, 3)
    t = 0.5
    exact = prox_linear_l1_exact(u, a, gx, gy, t)
    d, _ = prox_linear_l1(u, a, gx, gy, t, n_sweeps=300)
    e_cd = linear_l1_energy(d, u, a, gx, gy, t)
    e_ex = linear_l1_energy(exact, u, a, gx, gy, t)
    assert np.all(e_ex <= e_cd + 1e-4)
    assert np.median(np.abs(d - exact)) < 1e-3
    # the exact solution beats random perturbations
    rng = np.random.default_rng(4)
    for _ in range(5):
        pert = exact + rng.normal(size=exact.shape) * 0.05
        assert np.all(linear_l1_energy(pert, u, a, gx, gy, t) >= e_ex - 1e-9)


def test_warp_engines_agree_and_integer_shift_is_exact():
    rng = np.random.default_rng(5)
    planes = rng.random((40, 50, 3)).astype(np.float32)
    flow = (rng.normal(size=(40, 50, 2)) * 3).astype(np.float32)
    a, ia = warp_bicubic(planes, flow)
    b, ib = warp_bicubic_numpy(planes, flow)
    np.testing.assert_allclose(a, b, atol=2e-5)
    np.testing.assert_array_equal(ia, ib)
    shift = np.zeros((40, 50, 2), np.float32)
    shift[..., 0] = 2.0
    shift[..., 1] = -1.0
    w, inside = warp_bicubic(planes, shift)
    np.testing.assert_allclose(w[1:, :-2], planes[:-1, 2:], atol=1e-6)
    assert not inside[0].any() and not inside[:, -2:].any() and inside[1:, :-2].all()


def test_warp_engines_agree_on_many_planes():
    # the driver warps 3C planes (colour, x and y derivatives) in one call
    rng = np.random.default_rng(15)
    planes = rng.random((27, 35, 9)).astype(np.float32)
    flow = (rng.normal(size=(27, 35, 2)) * 2 + 0.5).astype(np.float32)
    a, ia = warp_bicubic(planes, flow)
    b, ib = warp_bicubic_numpy(planes, flow)
    np.testing.assert_allclose(a, b, atol=2e-5)
    np.testing.assert_array_equal(ia, ib)


def test_warp_nan_flow_is_outside():
    planes = np.ones((8, 8, 1), np.float32)
    flow = np.zeros((8, 8, 2), np.float32)
    flow[3, 3] = np.nan
    w, inside = warp_bicubic(planes, flow)
    assert not inside[3, 3] and inside.sum() == 63 and np.isfinite(w).all()


@pytest.mark.parametrize("size", [3, 5, 7])
def test_median_engines_agree(size):
    rng = np.random.default_rng(6)
    f = rng.normal(size=(33, 41, 2)).astype(np.float32)
    f[:10, :10] = 0.5  # ties
    np.testing.assert_array_equal(median_filter_flow(f, size), median_filter_flow_numpy(f, size))


def test_median_network_is_generated_from_tool():
    import subprocess
    import sys
    from pathlib import Path

    tool = Path(__file__).resolve().parents[1] / "tools" / "gen_median_network.py"
    assert subprocess.run([sys.executable, str(tool), "--check"]).returncode == 0


def test_rof_engines_agree_and_reduce_tv():
    rng = np.random.default_rng(7)
    f = rng.random((30, 40, 2)).astype(np.float32)
    a = rof_denoise(f, 0.1, 30)
    b = rof_denoise_numpy(f, 0.1, 30)
    np.testing.assert_allclose(a, b, atol=1e-4)

    def tv(x):
        return np.sqrt((gradient(x[..., 0]) ** 2).sum(-1)).sum()

    assert tv(a) < 0.5 * tv(f)
    # constant images are fixed points; texture of a constant is (1 - alpha) * const
    const = np.full((16, 16, 1), 0.4, np.float32)
    np.testing.assert_allclose(rof_denoise(const, 0.2, 20), const, atol=1e-6)
    np.testing.assert_allclose(structure_texture(const, 0.95), 0.02, atol=1e-6)


@pytest.mark.parametrize("shape", [(23, 31, 5), (5, 3, 3), (1, 1, 2)])
@pytest.mark.parametrize("sigma", [0.0, 0.4, 1.0, 2.5])
def test_planar_smoothing_of_a_strided_view(sigma, shape):
    stack = np.random.default_rng(13).random(shape, dtype=np.float32)
    view = stack[..., 1:]  # not contiguous: read as it is
    out = np.full((shape[2],) + shape[:2], np.nan, np.float32)
    got = smooth_planes(view, sigma, out=out[1:])
    assert got.shape == (shape[2] - 1,) + shape[:2] and np.isnan(out[0]).all()
    want = np.moveaxis(smooth_image_fast(view, sigma), -1, 0)
    np.testing.assert_allclose(out[1:], want, atol=2e-7)
    np.testing.assert_allclose(got, np.moveaxis(smooth_image(view, sigma), -1, 0), atol=2e-6)


@pytest.mark.parametrize("shape", [(23, 31, 4), (5, 3, 2), (1, 1, 1)])
@pytest.mark.parametrize("sigma", [0.0, 0.4, 1.0, 2.5])
def test_smoothing_engines_agree(sigma, shape):
    img = np.random.default_rng(12).random(shape, dtype=np.float32)
    fast = smooth_image_fast(img, sigma)
    ref = smooth_image(img, sigma)
    assert fast.shape == img.shape and fast.dtype == np.float32 and ref.dtype == np.float32
    np.testing.assert_allclose(fast, ref, atol=2e-6)
    if sigma == 0:
        assert ref is img
        np.testing.assert_array_equal(fast, img)
    elif img.size > 1:  # a smoothing: the variance drops
        assert fast.var() < 0.9 * img.var()


def test_pyramid_shapes_and_resize_flow():
    shapes = pyramid_shapes((100, 200), 40, 0.5, 16)
    assert shapes == [(100, 200), (50, 100), (25, 50)]
    img = np.full((100, 200, 3), 0.3, np.float32)
    pyr = build_pyramid(img, shapes, 0.5)
    assert [p.shape[:2] for p in pyr] == shapes
    np.testing.assert_allclose(pyr[-1], 0.3, atol=1e-6)
    flow = np.ones((50, 100, 2), np.float32)
    up = resize_flow(flow, (100, 200))
    np.testing.assert_allclose(up, 2.0, atol=1e-6)
    ramp = np.tile(np.arange(8, dtype=np.float32), (4, 1))[..., None]
    np.testing.assert_allclose(resize_bilinear(ramp, (4, 8)), ramp)
