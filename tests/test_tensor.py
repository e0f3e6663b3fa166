"""Tensor-directed TV-L1: the tensor, the identity case, the engines, the registry."""

import numpy as np
import pytest

import varflow
from varflow.generators.pairs import synthetic_pair
from varflow.ops.differences import image_derivatives
from varflow.ops.warp import warp_bicubic
from varflow.twoframe import tensor as tensor_mod
from varflow.twoframe.coarse_to_fine import LevelState
from varflow.twoframe.params import TensorTerm, preset
from varflow.twoframe.tensor import diffusion_tensor
from varflow.twoframe.tvl1 import TVL1Params


def aee(a, b):
    return float(np.linalg.norm(a - b, axis=-1).mean())


def _as_matrices(d):
    return np.stack([np.stack([d[0], d[1]], -1), np.stack([d[1], d[2]], -1)], -2)


def test_tensor_eigen_structure():
    """D = g n nᵀ + n⊥ n⊥ᵀ: eigenvalues g <= 1 (across the edge) and 1 (along it)."""
    h, w = 40, 50
    yy, xx = np.mgrid[0:h, 0:w]
    # vertical step edge: gradient along x, so n = ±e_x at the edge
    img = (xx >= 25).astype(np.float32)[..., None]
    d = diffusion_tensor(img, a=5.0, b=0.5, sigma=0.0, g_min=0.05)
    ev = np.linalg.eigvalsh(_as_matrices(d))
    assert np.allclose(ev[..., 1], 1.0, atol=1e-5)
    assert ev[..., 0].min() >= 0.05 - 1e-6 and ev[..., 0].max() <= 1.0 + 1e-6
    edge = d[:, 20, 24]  # next to the edge: weak across (x), full along (y)
    assert edge[0] < 0.5 and abs(edge[1]) < 1e-6 and edge[2] == pytest.approx(1.0, abs=1e-6)
    flat = d[:, 20, 5]
    np.testing.assert_allclose(flat, [1.0, 0.0, 1.0], atol=1e-6)


def test_tensor_with_a_zero_is_exactly_identity():
    f0, _, _ = synthetic_pair("smooth", shape=(32, 40), seed=2)
    d = diffusion_tensor(f0, a=0.0, b=0.5)
    np.testing.assert_array_equal(d[0], 1.0)
    np.testing.assert_array_equal(d[1], 0.0)
    np.testing.assert_array_equal(d[2], 1.0)


def test_identity_tensor_gives_the_isotropic_flow():
    f0, f1, _ = synthetic_pair("smooth", shape=(96, 128), magnitude=3.0, channels=3, seed=1)
    iso = varflow.flow(f0, f1, "tvl1", params=preset("plain", edge_weight=10.0))
    ident = varflow.flow(f0, f1, "tensor", tensor_a=0.0, edge_weight=10.0)
    # same iterations through the anisotropic branch of the kernel: rounding only
    assert np.abs(iso - ident).max() < 1e-3


def test_tensor_engines_agree():
    f0, f1, gt = synthetic_pair("smooth", shape=(48, 56), magnitude=1.5, channels=3, seed=5)
    dx, dy = image_derivatives(f1)
    flow0 = (0.8 * gt).astype(np.float32)
    warped, inside = warp_bicubic(np.concatenate([f1, dx, dy], 2), flow0)
    params = preset("tensor", max_iterations=40, tolerance=0.0, tensor_a=5.0)
    outs = []
    for engine in ("numba", "numpy"):
        outs.append(tensor_mod.solve_warp(f0, warped[..., :3], warped[..., 3:6], warped[..., 6:],
                                          inside, flow0, params, LevelState(), engine=engine))
    np.testing.assert_allclose(outs[0], outs[1], atol=2e-4)
    assert aee(outs[0], flow0) > 0.05


@pytest.mark.parametrize(
    "motion, magnitude, bound",  # measured 0.021 / 0.064; bound x ~1.5-2.5
    [("translation", 2.5, 0.035), ("smooth", 3.0, 0.10)],
)
def test_tensor_recovers_synthetic_motion(motion, magnitude, bound):
    f0, f1, gt = synthetic_pair(motion, shape=(96, 128), magnitude=magnitude, seed=1)
    assert aee(varflow.flow(f0, f1, "tensor"), gt) < bound


@pytest.mark.parametrize("field, value", [("tensor_a", -1.0), ("tensor_b", 0.0),
                                          ("tensor_sigma", -0.5)])
def test_invalid_tensor_parameters_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"^{field}:"):
        preset("tensor", **{field: value})


def test_registered_with_its_own_defaults():
    assert "tensor" in varflow.methods()
    p = varflow.make_params("tensor")
    assert isinstance(p, TVL1Params) and p.tensor == TensorTerm()
    assert p.edge_weight == 0.0 and p.tensor_a > 0
