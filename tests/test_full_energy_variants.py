"""The tensor-directed and sparse regularisers on ``tvl1``'s energy.

``tvl1-tensor`` and ``tvl1-sparse-*`` compose a
:class:`~varflow.twoframe.params.TensorTerm` / :class:`~varflow.twoframe.params.SparseTerm`
with :class:`~varflow.twoframe.params.TVL1Params`' defaults (grey channel, gradient constancy,
Huber-TV, noise rule, weighted median, sharpness match).  The reductions: without the
tensor (a = 0) the tensor variant is ``tvl1``; without the sparse term (λ_SP = 0, the
exact primal-dual combined step) the sparse warps are the base energy's warps.
"""

import dataclasses

import numpy as np
import pytest
from _problems import linearised_sparse_problem

import varflow
from varflow.generators.pairs import synthetic_pair
from varflow.ops.primal_dual import row_blocks
from varflow.twoframe import sparse as sp
from varflow.twoframe import tensor, tvl1
from varflow.twoframe.coarse_to_fine import coarse_to_fine
from varflow.twoframe.methods import METHODS
from varflow.twoframe.params import PRESETS, preset
from varflow.twoframe.tvl1 import TVL1Params

FULL = ("tvl1-tensor", "tvl1-sparse-dct", "tvl1-sparse-1d", "tvl1-sparse-2x1d",
        "tvl1-sparse-2d")


def aee(a, b):
    return float(np.linalg.norm(a - b, axis=-1).mean())


@pytest.fixture(scope="module")
def smooth_pair():
    """A smooth 2 px colour flow, 64 x 80 (the finest levels run the sparse stage)."""
    return synthetic_pair("smooth", shape=(64, 80), magnitude=2.0, channels=3, seed=3)


@pytest.fixture(scope="module")
def noisy_pair(smooth_pair):
    """The smooth pair with Gaussian noise σ = 0.03: the noise rule scales λ and γ."""
    f0, f1, gt = smooth_pair
    rng = np.random.default_rng(0)
    noisy = [np.clip(f + rng.normal(0, 0.03, f.shape), 0, 1).astype(np.float32)
             for f in (f0, f1)]
    return noisy[0], noisy[1], gt


# ------------------------------------------------------------------ registry and params


def test_registry_lists_the_full_energy_variants():
    assert set(FULL) <= set(varflow.methods())
    for name in FULL:
        assert METHODS[name].defaults() is PRESETS[name]
        assert PRESETS[name].data_weight == PRESETS["tvl1"].data_weight
    assert METHODS["tvl1-tensor"].solve_warp is tensor.solve_warp
    assert all(METHODS[n].solve_warp is sp.solve_warp for n in FULL if "sparse" in n)
    assert varflow.make_params("tvl1-sparse-dct").dictionary == "dct"
    assert varflow.make_params("tvl1-sparse-1d").layout == "1D"
    assert varflow.make_params("tvl1-sparse-2x1d").layout == "2x1D"
    assert varflow.make_params("tvl1-sparse-2d").layout == "2D"
    # the plain-energy methods keep the book's energy (their tables were measured on it)
    assert varflow.make_params("tensor").data_weight == 40.0
    assert varflow.make_params("sparse-1d").gradient_weight == 0.0


@pytest.mark.parametrize("name", sorted(FULL))
def test_full_energy_defaults_are_tvl1s(name):
    """Every field of TVL1Params keeps tvl1's default (the edge weight aside for the
    tensor, which carries the edge information itself); the regulariser fields keep
    those of the plain-energy method."""
    p, ref = varflow.make_params(name), TVL1Params()
    differ = {f.name for f in dataclasses.fields(TVL1Params)
              if getattr(p, f.name) != getattr(ref, f.name)}
    terms = {"tensor"} | ({"sparse"} if "sparse" in name else set())
    assert differ == ({"edge_weight"} if name == "tvl1-tensor" else set()) | terms
    assert (p.data_weight, p.gradient_weight, p.huber, p.noise_reference) == (15.0, 140.0,
                                                                            0.02, 0.01)
    assert p.grey and p.sharpness_match and p.weighted_median_radius == 3
    # the regulariser's fields keep the plain-energy method's defaults but the tensor's
    # a (0.5 against 3, benchmarks/HISTORY.md)
    plain = METHODS[name.removeprefix("tvl1-")].defaults()
    assert p.sparse == plain.sparse
    assert p.tensor == dataclasses.replace(plain.tensor, tensor_a=0.5)
    assert (p.tensor_a, plain.tensor_a) == (0.5, 3.0)


_BAD = {
    "tensor_a": -1.0, "tensor_b": 0.0, "tensor_sigma": -0.5,  # the tensor's
    "huber": -0.01, "gradient_weight": float("nan"), "noise_reference": -1.0,  # the energy's
}
_BAD_SPARSE = {
    "layout": "3D", "dictionary": "ksvd", "patch_offset": 11, "sparse_weight": -1.0,
    "combined_solver": "admm", "sparse_min_size": 5, "regulariser": "huber",
}


@pytest.mark.parametrize("field", sorted(_BAD))
def test_tensor_params_name_the_field(field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        preset("tvl1-tensor", **{field: _BAD[field]})


@pytest.mark.parametrize("field", sorted({**_BAD, **_BAD_SPARSE}))
def test_sparse_params_name_the_field(field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        preset("tvl1-sparse-2d", **{field: {**_BAD, **_BAD_SPARSE}[field]})


def test_sparse_stage_accepts_the_robust_terms():
    # refused before the sparse stage handled them (issue 27, part 6)
    p = preset("sparse-1d", gradient_weight=40.0, huber=0.02, data_normalisation=0.05)
    assert (p.gradient_weight, p.huber, p.data_normalisation) == (40.0, 0.02, 0.05)


# ------------------------------------------------------------------ reductions


@pytest.mark.parametrize("which", ["smooth_pair", "noisy_pair"])
def test_tensor_a_zero_is_tvl1(which, request):
    f0, f1, gt = request.getfixturevalue(which)
    s_ref, s_ten = {}, {}
    ref = varflow.flow(f0, f1, "tvl1", edge_weight=10.0, stats=s_ref)
    ident = varflow.flow(f0, f1, "tvl1-tensor", tensor_a=0.0, edge_weight=10.0, stats=s_ten)
    # the same iterations through the anisotropic branch of the kernel: rounding only
    # (measured 4e-5 px clean, 1.3e-5 px noisy)
    assert np.abs(ref - ident).max() < 1e-3
    assert s_ref.get("data_scale", 1.0) == s_ten.get("data_scale", 1.0)
    if which == "noisy_pair":  # the noise rule was on (measured scale 0.62)
        assert s_ten["data_scale"] < 0.8
    # and the tensor does change the flow (measured max 0.35 / 0.51 px)
    assert np.abs(varflow.flow(f0, f1, "tvl1-tensor") - ref).max() > 0.05


@pytest.mark.parametrize("regulariser, base", [("tv", tvl1.solve_warp),
                                               ("tensor", tensor.solve_warp)])
@pytest.mark.parametrize("which", ["smooth_pair", "noisy_pair"])
def test_sparse_weight_zero_is_the_base_energy(regulariser, base, which, request):
    """λ_SP = 0 with the exact primal-dual step and tvl1's θ, iterations and ε: the
    sparse warps are warps of the base solver (the same schedule of warps per level),
    gradient-constancy channels, Huber-TV and the noise rule included."""
    f0, f1, _ = request.getfixturevalue(which)
    p = preset("tvl1-sparse-dct",
        regulariser=regulariser, sparse_weight=0.0, combined_solver="primal-dual",
        combined_coupling=0.3, combined_iterations=24, combined_tolerance=0.0, tolerance=0.0)
    stats = {}
    u = coarse_to_fine(f0, f1, sp.solve_warp, p, stats=stats)
    v = coarse_to_fine(f0, f1, base, p)
    assert stats["sparse_warps"] == 6  # 2 per level on the 3 levels of side >= 40
    assert np.abs(u - v).max() < 1e-3  # measured 1.5e-5 / 8.5e-6 px


def test_sparse_pd_kernel_engines_agree_with_huber():
    terms, ubar, rng, u0 = linearised_sparse_problem(seed=5, aniso=True)
    wsp = (0.5 * rng.uniform(0.5, 1.5, u0.shape[1:])).astype(np.float32)
    outs = []
    for fn in (sp.sparse_pd_iterations, sp.sparse_pd_iterations_numpy):
        h, w = u0.shape[1:]
        u, p = u0.copy(), np.zeros((4, h, w), np.float32)
        tp, q = np.zeros_like(p), np.zeros((terms["a"].shape[0], h, w), np.float32)
        args = (*terms.values(), u, p, tp, q, ubar, wsp, np.float32(40.0), np.float32(1.0),
                np.float32(0.3), np.float32(0.25), 30, np.float32(0.0), 1, True)
        blocks = row_blocks(h) if fn is sp.sparse_pd_iterations else None
        assert fn(*args, blocks, 0.05) == 30
        outs.append(u)
    np.testing.assert_allclose(outs[0], outs[1], atol=1e-4)
    # Huber-TV changes the result (it is read)
    h, w = u0.shape[1:]
    u = u0.copy()
    p = np.zeros((4, h, w), np.float32)
    sp.sparse_pd_iterations_numpy(*terms.values(), u, p, np.zeros_like(p),
                                  np.zeros((terms["a"].shape[0], h, w), np.float32), ubar, wsp,
                                  40.0, 1.0, 0.3, 0.25, 30, 0.0, 1, True)
    assert np.abs(u - outs[1]).max() > 1e-3


# ------------------------------------------------------------------ accuracy


@pytest.fixture(scope="module")
def translation():
    """A planted 2.5 px translation of a procedural colour texture, 96 x 128."""
    return synthetic_pair("translation", shape=(96, 128), magnitude=2.5, channels=3, seed=1)


# measured (2026-12-02): tvl1 0.0145, tvl1-tensor 0.0149, tvl1-sparse-dct 0.0157,
# tvl1-sparse-1d 0.0164 px
@pytest.mark.parametrize("name, bound", [("tvl1-tensor", 0.025), ("tvl1-sparse-dct", 0.025),
                                         ("tvl1-sparse-1d", 0.025)])
def test_planted_translation(translation, name, bound):
    f0, f1, gt = translation
    stats = {}
    err = aee(varflow.flow(f0, f1, name, stats=stats), gt)
    assert err < bound, err
    assert ("sparse_warps" in stats) == ("sparse" in name)
