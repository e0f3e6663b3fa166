"""Sparse-coding blocks: patch grid (adjoint, exact averaging, apron), DCT, layouts, OMP, MOD."""

import numpy as np
import pytest

from varflow.sparse import (
    LAYOUTS,
    PatchGrid,
    check_layout,
    dct_dictionary,
    dictionary_from_data,
    layout_atom_dim,
    layout_dct,
    learn_mod,
    merge_problems,
    normalize_columns,
    omp,
    omp_numpy,
    reconstruct,
    residual_energy,
    split_problems,
)

# (H, W, m, n, k): includes k that does not divide H - m or W - n, and patch == image
GRIDS = [
    (23, 31, 10, 10, 1),
    (23, 31, 10, 10, 3),
    (23, 31, 10, 10, 4),
    (17, 26, 7, 5, 2),
    (16, 19, 6, 8, 5),
    (10, 12, 10, 12, 7),
]


def _planted(seed, dim=64, n_atoms=128, n_signals=2000, sparsity=3, noise=0.01):
    """Random unit dictionary and signals that are 3-sparse combinations + noise."""
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((dim, n_atoms))
    d /= np.linalg.norm(d, axis=0)
    a = np.zeros((n_atoms, n_signals))
    for p in range(n_signals):
        sup = rng.choice(n_atoms, sparsity, replace=False)
        a[sup, p] = rng.uniform(0.5, 1.5, sparsity) * rng.choice([-1.0, 1.0], sparsity)
    y = d @ a + noise * rng.standard_normal((dim, n_signals))
    return d.astype(np.float32), a, y.astype(np.float32)


def _supports(codes):
    return [
        set(codes.indices[codes.indptr[p] : codes.indptr[p + 1]]) for p in range(codes.shape[1])
    ]


def _recovered(d_true, d_learned, thr=0.99):
    corr = np.abs(d_true.T.astype(np.float64) @ d_learned.astype(np.float64))
    return float(np.mean(corr.max(axis=1) > thr))


# --------------------------------------------------------------------------- patch grid
@pytest.mark.parametrize("h, w, m, n, k", GRIDS)
def test_grid_geometry_and_apron_mask(h, w, m, n, k):
    g = PatchGrid(h, w, (m, n), k)
    hp, wp = g.padded_shape
    assert (hp - m) % k == 0 and (wp - n) % k == 0
    assert h <= hp < h + k and w <= wp < w + k
    ph, pw = g.grid_shape
    assert (ph, pw) == ((hp - m) // k + 1, (wp - n) // k + 1)
    assert g.n_patches == ph * pw
    expected = np.ones((hp, wp), bool)
    expected[:h, :w] = False
    np.testing.assert_array_equal(g.apron_mask, expected)
    assert g.has_apron == bool(expected.any())


@pytest.mark.parametrize("h, w, m, n, k", GRIDS)
def test_extract_order_and_patch_mask_brute_force(h, w, m, n, k):
    """Entry (c, a, b) of patch (i, j) is padded[i·k + a, j·k + b, c]; mask = real pixel."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(h, w, 2)).astype(np.float32)
    g = PatchGrid(h, w, (m, n), k)
    y = g.extract(x)
    msk = g.patch_mask(2)
    padded = np.pad(x, ((0, g.padded_shape[0] - h), (0, g.padded_shape[1] - w), (0, 0)), "edge")
    ph, pw = g.grid_shape
    assert y.shape == msk.shape == (2 * m * n, ph * pw) and y.dtype == np.float32
    for i in range(ph):
        for j in range(pw):
            p = i * pw + j
            block = padded[i * k : i * k + m, j * k : j * k + n]  # (m, n, 2)
            np.testing.assert_array_equal(y[:, p], np.moveaxis(block, 2, 0).ravel())
            real = np.zeros((g.padded_shape), bool)
            real[:h, :w] = True
            np.testing.assert_array_equal(
                msk[:, p], np.tile(real[i * k : i * k + m, j * k : j * k + n].ravel(), 2)
            )
    interior = g.interior_patches()
    np.testing.assert_array_equal(interior, msk.all(axis=0))


@pytest.mark.parametrize("h, w, m, n, k", GRIDS)
@pytest.mark.parametrize("channels", [1, 2])
def test_extract_adjoint_pair(h, w, m, n, k, channels):
    rng = np.random.default_rng(1)
    shape = (h, w) if channels == 1 else (h, w, channels)
    g = PatchGrid(h, w, (m, n), k)
    x = rng.normal(size=shape).astype(np.float32)
    z = rng.normal(size=(channels * m * n, g.n_patches)).astype(np.float32)
    lhs = float((g.extract(x).astype(np.float64) * z).sum())
    adj = g.extract_adjoint(z)
    assert adj.shape == shape
    rhs = float((x.astype(np.float64) * adj).sum())
    assert abs(lhs - rhs) <= 1e-5 * max(1.0, abs(lhs))


@pytest.mark.parametrize("h, w, m, n, k", GRIDS)
def test_average_of_extract_is_exact(h, w, m, n, k):
    rng = np.random.default_rng(2)
    x = (rng.normal(size=(h, w, 2)) * 7).astype(np.float32)
    g = PatchGrid(h, w, (m, n), k)
    np.testing.assert_array_equal(g.average(g.extract(x)), x)
    x1 = x[..., 0]
    np.testing.assert_array_equal(g.average(g.extract(x1)), x1)


def test_count_map_and_masked_adjoint():
    g = PatchGrid(23, 31, (10, 10), 4)
    msk = g.patch_mask(1).astype(np.float32)
    np.testing.assert_array_equal(g.extract_adjoint(msk), g.count)
    assert g.count.min() >= 1
    g1 = PatchGrid(23, 31, (10, 10), 1)
    assert g1.count[0, 0] == 1 and g1.count[11, 11] == 100 and not g1.has_apron


def test_average_ignores_apron_entries():
    rng = np.random.default_rng(3)
    g = PatchGrid(23, 31, (10, 10), 4)
    assert g.has_apron
    x = rng.normal(size=(23, 31, 2)).astype(np.float32)
    y = g.extract(x)
    y[~g.patch_mask(2)] = 1e6
    np.testing.assert_array_equal(g.average(y), x)


def test_grid_validation():
    with pytest.raises(ValueError, match="offset"):
        PatchGrid(20, 20, (10, 10), 0)
    with pytest.raises(ValueError, match="offset"):
        PatchGrid(20, 20, (10, 10), 11)
    with pytest.raises(ValueError, match="patch_size"):
        PatchGrid(8, 20, (10, 10), 1)
    with pytest.raises(ValueError, match="patch_size"):
        PatchGrid(20, 20, (0, 10), 1)
    g = PatchGrid(20, 20, (10, 10), 2)
    with pytest.raises(ValueError, match="field"):
        g.extract(np.zeros((20, 21), np.float32))
    with pytest.raises(ValueError, match="patches"):
        g.average(np.zeros((99, g.n_patches), np.float32))
    with pytest.raises(ValueError, match="channels"):
        g.patch_mask(0)


# --------------------------------------------------------------------------- dictionaries
@pytest.mark.parametrize(
    "m, n, k", [(10, 10, 400), (10, 10, 800), (8, 6, 100), (10, 10, 50), (1, 7, 12), (5, 5, 25)]
)
def test_dct_dictionary_unit_norm_and_dc(m, n, k):
    d = dct_dictionary(m, n, k)
    assert d.shape == (m * n, k) and d.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(d.astype(np.float64), axis=0), 1.0, atol=1e-6)
    np.testing.assert_allclose(d[:, 0], 1.0 / np.sqrt(m * n), atol=1e-7)
    gram = np.abs(d.T.astype(np.float64) @ d)
    np.fill_diagonal(gram, 0.0)
    assert gram.max() < 1 - 1e-4  # no duplicated atom
    if k >= m * n:
        assert np.linalg.matrix_rank(d.astype(np.float64)) == m * n


def test_dct_dictionary_is_separable_cosines():
    d = dct_dictionary(10, 10, 400).reshape(10, 10, 400)
    # every atom is an outer product (rank 1) of a vertical and a horizontal cosine
    svals = np.linalg.svd(np.moveaxis(d, 2, 0).astype(np.float64), compute_uv=False)
    assert np.all(svals[:, 1] < 1e-5 * svals[:, 0])


def test_dct_validation():
    with pytest.raises(ValueError, match="n_atoms"):
        dct_dictionary(10, 10, 0)
    with pytest.raises(ValueError, match="m"):
        dct_dictionary(0, 10, 100)
    with pytest.raises(ValueError, match="n_atoms"):
        dct_dictionary(1, 1, 2)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_layouts_split_merge_roundtrip(layout):
    rng = np.random.default_rng(4)
    g = PatchGrid(20, 27, (6, 5), 3)
    flow = rng.normal(size=(20, 27, 2)).astype(np.float32)
    y, msk = g.extract(flow), g.patch_mask(2)
    probs = split_problems(layout, y, msk)
    dicts = layout_dct(layout, (6, 5), 60)
    assert len(probs) == len(dicts) == (2 if layout == "2x1D" else 1)
    for (ys, ms), d in zip(probs, dicts, strict=True):
        assert ys.shape[0] == d.shape[0] == layout_atom_dim(layout, (6, 5))
        assert ms.shape == ys.shape
    if layout == "1D":
        assert probs[0][0].shape[1] == 2 * g.n_patches
        np.testing.assert_array_equal(probs[0][0][:, g.n_patches :], y[30:])
    np.testing.assert_array_equal(merge_problems(layout, [p[0] for p in probs]), y)
    np.testing.assert_array_equal(merge_problems(layout, [p[1] for p in probs]), msk)


def test_layout_2d_dct_is_block_diagonal_and_validation():
    (d,) = layout_dct("2D", (4, 4), 33)
    assert d.shape == (32, 33)
    assert np.all(d[:16, 17:] == 0) and np.all(d[16:, :17] == 0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, atol=1e-6)
    with pytest.raises(ValueError, match="layout"):
        check_layout("3D")
    with pytest.raises(ValueError, match="parts"):
        merge_problems("2x1D", [np.zeros((4, 3))])


def test_dictionary_from_data_uses_only_real_signals():
    rng = np.random.default_rng(5)
    y = rng.normal(size=(16, 200)).astype(np.float32)
    msk = np.ones_like(y, bool)
    msk[3, ::2] = False  # even columns are partly masked
    for method in ("random", "largest"):
        d = dictionary_from_data(y, 40, msk, method=method, seed=7)
        np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, atol=1e-6)
        yn = normalize_columns(y)[0]
        match = np.abs(yn.T @ d).argmax(axis=0)
        assert np.all(match % 2 == 1)
        np.testing.assert_allclose(np.abs(yn[:, match] * d).sum(axis=0), 1.0, atol=1e-5)
    np.testing.assert_array_equal(
        dictionary_from_data(y, 40, seed=3), dictionary_from_data(y, 40, seed=3)
    )
    # too few candidates: the rest are random unit atoms
    d = dictionary_from_data(y[:, :5], 12, seed=0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, atol=1e-6)


# --------------------------------------------------------------------------- OMP
def _omp_problem(seed):
    d, _, y = _planted(seed, n_signals=150)
    rng = np.random.default_rng(seed + 10)
    y[:, 140:145] = rng.normal(size=(64, 5)).astype(np.float32)  # dense signals
    y[:, 145] = 0.0  # empty code
    y[:, 146] = 3 * d[:, 5]  # exactly one atom
    msk = np.ones_like(y, bool)
    msk[rng.random(y.shape) < 0.3] = False
    msk[:, :100] = True  # 50 partly masked signals
    return d, y, msk


@pytest.mark.parametrize(
    "tol, max_atoms, masked",
    [(0.05, 8, False), (0.05, 8, True), (None, 5, True), (0.3, None, False)],
)
def test_omp_numba_matches_numpy(tol, max_atoms, masked):
    d, y, msk = _omp_problem(6)
    msk = msk if masked else None
    a_nb = omp(d, y, tol=tol, max_atoms=max_atoms, mask=msk)
    a_np = omp_numpy(d, y, tol=tol, max_atoms=max_atoms, mask=msk)
    assert a_nb.shape == a_np.shape == (128, y.shape[1]) and a_nb.dtype == np.float32
    assert _supports(a_nb) == _supports(a_np)
    np.testing.assert_allclose(a_nb.toarray(), a_np.toarray(), atol=2e-4, rtol=1e-4)
    assert a_nb[:, [145]].nnz == 0
    assert _supports(a_nb)[146] == {5}
    np.testing.assert_allclose(a_nb[5, 146], 3.0, rtol=1e-5)
    via_engine = omp(d, y, tol=tol, max_atoms=max_atoms, mask=msk, engine="numpy")
    np.testing.assert_array_equal(via_engine.toarray(), a_np.toarray())


def test_omp_stopping_rule_is_rms_per_real_entry():
    d, y, msk = _omp_problem(7)
    tol, big_l = 0.05, 6
    for mask in (None, msk):
        codes = omp(d, y, tol=tol, max_atoms=big_l, mask=mask)
        n_real = y.shape[0] if mask is None else mask.sum(axis=0)
        energy = residual_energy(d, codes, y, mask)
        nnz = np.diff(codes.indptr)
        ok = (energy <= tol**2 * n_real * (1 + 1e-4)) | (nnz == big_l)
        assert ok.all()
        # and one atom fewer would not have met the threshold (greedy stops at the first hit)
        assert np.all(nnz <= big_l)
    # 3-sparse + noise 0.01: tol 0.05 stops after the 3 planted atoms in most signals
    codes = omp(d, y[:, :140], tol=tol, max_atoms=big_l)
    assert np.mean(np.diff(codes.indptr) == 3) > 0.95


def test_omp_recovers_planted_supports():
    d, a, y = _planted(8)
    codes = omp(d, y, tol=0.02, max_atoms=6)
    truth = [set(np.flatnonzero(a[:, p])) for p in range(a.shape[1])]
    assert np.mean([s == t for s, t in zip(_supports(codes), truth, strict=True)]) == 1.0
    err = np.abs(codes.toarray() - a)[a != 0]
    assert err.max() < 0.1 and err.mean() < 0.01  # noise-level coefficient errors


def test_omp_ignores_masked_entries():
    d, y, msk = _omp_problem(9)
    garbage = y.copy()
    garbage[~msk] = np.random.default_rng(0).normal(size=(~msk).sum()) * 1e3
    a1 = omp(d, y, tol=0.05, max_atoms=8, mask=msk)
    a2 = omp(d, garbage, tol=0.05, max_atoms=8, mask=msk)
    np.testing.assert_array_equal(a1.indptr, a2.indptr)
    np.testing.assert_array_equal(a1.indices, a2.indices)
    np.testing.assert_array_equal(a1.data, a2.data)


def test_omp_on_patch_grid_apron_garbage_and_dct_approximation():
    rng = np.random.default_rng(10)
    h, w = 33, 46
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    flow = np.stack([2 * np.sin(xx / 9) + yy / 20, np.cos((xx + yy) / 13)], -1).astype(np.float32)
    g = PatchGrid(h, w, (8, 8), 3)
    assert g.has_apron
    y, msk = g.extract(flow), g.patch_mask(2)
    ((ys, ms),) = split_problems("1D", y, msk)
    d = dct_dictionary(8, 8, 100)
    tol = 0.05
    a1 = omp(d, ys, tol=tol, mask=ms)
    ys_bad = ys.copy()
    ys_bad[~ms] = rng.normal(size=(~ms).sum()).astype(np.float32) * 50
    a2 = omp(d, ys_bad, tol=tol, mask=ms)
    np.testing.assert_array_equal(a1.toarray(), a2.toarray())
    approx = g.average(merge_problems("1D", [reconstruct(d, a1)]))
    rms = float(np.sqrt(np.mean((approx - flow) ** 2)))
    assert rms <= tol
    assert np.diff(a1.indptr).mean() < 8  # smooth flow: few atoms per patch


def test_reconstruct_and_residual_energy():
    d, y, msk = _omp_problem(11)
    codes = omp(d, y, tol=0.05, max_atoms=4)
    dense = codes.toarray().astype(np.float64)
    rec = reconstruct(d, codes)
    np.testing.assert_allclose(rec, d.astype(np.float64) @ dense, atol=1e-5)
    r = (y - d.astype(np.float64) @ dense) * msk
    np.testing.assert_allclose(residual_energy(d, codes, y, msk), (r * r).sum(0), rtol=1e-5)


def test_omp_validation():
    d, y, msk = _omp_problem(12)
    with pytest.raises(ValueError, match="tol"):
        omp(d, y, tol=None, max_atoms=None)
    with pytest.raises(ValueError, match="tol"):
        omp(d, y, tol=-1.0)
    with pytest.raises(ValueError, match="max_atoms"):
        omp(d, y, max_atoms=0)
    with pytest.raises(ValueError, match="signals"):
        omp(d, y[:10])
    with pytest.raises(ValueError, match="mask"):
        omp(d, y, mask=msk[:, :3])
    with pytest.raises(ValueError, match="engine"):
        omp(d, y, engine="cuda")
    with pytest.raises(ValueError, match="dictionary"):
        omp(d[0], y)


# --------------------------------------------------------------------------- MOD
def test_mod_recovers_planted_dictionary_from_perturbed_init():
    d_true, _, y = _planted(13)
    rng = np.random.default_rng(14)
    d0 = normalize_columns(d_true + 0.5 * rng.standard_normal(d_true.shape) / 8)[0]
    assert _recovered(d_true, d0) == 0.0  # median |<d, d0>| ≈ 0.9
    res = learn_mod(y, d0, tol=None, max_atoms=3, n_iterations=10, seed=0)
    assert _recovered(d_true, res.dictionary) >= 0.9
    assert res.errors[-1] < 0.05 * res.errors[0]
    assert res.dictionary.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(res.dictionary, axis=0), 1.0, atol=1e-5)
    # with the learned dictionary OMP finds the planted supports again
    assert res.n_updates >= 1 and res.n_signals == y.shape[1]


def test_mod_from_data_init_improves_and_replaces_unused_atoms():
    d_true, _, y = _planted(15, n_signals=1500)
    d0 = dictionary_from_data(y, 128, seed=1)
    d0[:, 1:4] = d0[:, [0]]  # duplicates of atom 0 are never selected -> replaced
    res = learn_mod(y, d0, tol=None, max_atoms=3, n_iterations=30, rel_tol=1e-4, seed=0)
    assert res.n_replaced >= 3
    assert res.errors[-1] < 0.25 * res.errors[0]
    assert _recovered(d_true, res.dictionary) >= 0.75


def test_mod_keeps_apron_out_of_training():
    rng = np.random.default_rng(16)
    h, w = 30, 41
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    flow = np.stack([np.sin(xx / 5) * (yy > 12) + 0.5, np.cos(yy / 4) + (xx > 20)], -1)
    flow = (flow + 0.01 * rng.standard_normal(flow.shape)).astype(np.float32)
    g = PatchGrid(h, w, (6, 6), 4)
    y, msk = g.extract(flow), g.patch_mask(2)
    ((ys, ms),) = split_problems("1D", y, msk)
    assert not ms.all()
    d0 = dct_dictionary(6, 6, 64)
    runs = []
    for scale in (0.0, 1e3):
        bad = ys.copy()
        bad[~ms] = scale * rng.standard_normal((~ms).sum()).astype(np.float32)
        runs.append(
            learn_mod(bad, d0, ms, tol=0.02, max_atoms=6, n_iterations=4, min_valid_fraction=0.5)
        )
    np.testing.assert_allclose(runs[0].dictionary, runs[1].dictionary, atol=1e-5)
    np.testing.assert_allclose(runs[0].errors, runs[1].errors, rtol=1e-5)
    assert runs[0].n_signals == 2 * g.n_patches  # partial patches used
    assert runs[0].errors[-1] < runs[0].errors[0]
    # default: only patches entirely inside the image
    res = learn_mod(ys, d0, ms, tol=0.02, max_atoms=6, n_iterations=2)
    assert res.n_signals == 2 * int(g.interior_patches().sum()) < 2 * g.n_patches


def test_mod_seeded_subset_and_validation():
    d_true, _, y = _planted(17, n_signals=600)
    d0 = dictionary_from_data(y, 128, seed=2)
    r1 = learn_mod(y, d0, tol=None, max_atoms=3, n_iterations=2, max_signals=300, seed=5)
    r2 = learn_mod(y, d0, tol=None, max_atoms=3, n_iterations=2, max_signals=300, seed=5)
    assert r1.n_signals == 300
    np.testing.assert_array_equal(r1.dictionary, r2.dictionary)
    with pytest.raises(ValueError, match="ridge"):
        learn_mod(y, d0, ridge=0.0)
    with pytest.raises(ValueError, match="n_iterations"):
        learn_mod(y, d0, n_iterations=0)
    with pytest.raises(ValueError, match="min_valid_fraction"):
        learn_mod(y, d0, min_valid_fraction=0.0)
    with pytest.raises(ValueError, match="max_signals"):
        learn_mod(y, d0, max_signals=0)
    with pytest.raises(ValueError, match="signals"):
        learn_mod(y[:5], d0)
    # nothing above the threshold: dictionary returned unchanged (normalised)
    res = learn_mod(np.zeros_like(y), d0, tol=0.05)
    assert res.n_signals == 0 and res.n_updates == 0
    np.testing.assert_allclose(res.dictionary, d0, atol=1e-6)
