"""Edge-preserving interpolation of sparse matches (ops/interpolation.py, EpicFlow)."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage, sparse
from scipy.interpolate import griddata
from scipy.sparse import csgraph

from varflow.ops import interpolation as it
from varflow.ops.interpolation import InterpParams, geodesic_voronoi, interpolate

log = logging.getLogger(__name__)


def _scene(h: int = 96, w: int = 128, seed: int = 0):
    """Three regions of different colour and texture, each with its own affine motion.

    Returns the image (H, W, 3), the exact flow (H, W, 2) and the region map.
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    region = np.zeros((h, w), np.int64)
    region[xx > 0.55 * w + 0.25 * (yy - h / 2)] = 1  # a slanted straight edge
    region[(yy - 0.45 * h) ** 2 + (xx - 0.3 * w) ** 2 < (0.22 * h) ** 2] = 2  # a disc
    colours = np.array([[0.2, 0.3, 0.7], [0.8, 0.6, 0.2], [0.3, 0.8, 0.35]])
    texture = ndimage.gaussian_filter(rng.standard_normal((h, w, 3)), (1.5, 1.5, 0)) * 0.1
    img = np.clip(colours[region] + texture, 0, 1).astype(np.float32)
    jac = np.array([[[0.01, 0.0], [0.0, 0.02]], [[0.0, -0.03], [0.03, 0.0]],
                    [[0.03, 0.0], [0.0, -0.02]]])
    shift = np.array([[1.0, -0.5], [4.0, 1.0], [-3.0, 2.0]])
    centred = np.stack([xx - w / 2, yy - h / 2], -1)
    flow = np.einsum("hwij,hwj->hwi", jac[region], centred) + shift[region]
    return img, flow.astype(np.float32), region


def _grid_samples(flow: np.ndarray, step: int):
    h, w = flow.shape[:2]
    yy, xx = np.mgrid[step // 2:h:step, step // 2:w:step]
    pts = np.stack([xx.ravel(), yy.ravel()], 1).astype(np.float32)
    return pts, flow[yy.ravel(), xx.ravel()].copy()


def _epe(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.hypot(a[..., 0] - b[..., 0], a[..., 1] - b[..., 1])


def _boundary_distance(region: np.ndarray) -> np.ndarray:
    edge = np.zeros(region.shape, bool)
    edge[:, 1:] |= region[:, 1:] != region[:, :-1]
    edge[1:] |= region[1:] != region[:-1]
    return ndimage.distance_transform_edt(~edge)


def _smooth_image(shape=(24, 31), seed=0) -> np.ndarray:
    """A smooth random colour image whose cost map has no exact ties."""
    rng = np.random.default_rng(seed)
    img = ndimage.gaussian_filter(rng.random(shape + (3,)), (3, 3, 0))
    return ((img - img.min()) / (img.max() - img.min())).astype(np.float32)


# --------------------------------------------------------------------- parameters
@pytest.mark.parametrize(
    "field, value",
    [("mode", "linear"), ("k", 0), ("k", 2.5), ("k", True), ("a", 0.0), ("a", np.inf),
     ("edge_sigma", -1.0), ("edge_scale", 0.0), ("edge_floor", 0.0), ("edge_floor", np.nan),
     ("fallback_cond", -0.1), ("fallback_cond", 1.0)],
)
def test_invalid_params_name_the_field(field: str, value) -> None:
    with pytest.raises(ValueError, match=field):
        InterpParams(**{field: value})


def test_invalid_inputs_raise() -> None:
    img = _smooth_image()
    pts = np.array([[3.0, 4.0], [10.0, 12.0]], np.float32)
    fl = np.zeros((2, 2), np.float32)
    with pytest.raises(ValueError, match="points"):
        interpolate(img, np.full((2, 2), np.nan, np.float32), fl)
    with pytest.raises(ValueError, match="points"):  # all outside the image
        interpolate(img, pts + 1000, fl)
    with pytest.raises(ValueError, match="points"):
        interpolate(img, np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32))
    with pytest.raises(ValueError, match="points"):
        interpolate(img, pts.ravel(), fl)
    with pytest.raises(ValueError, match="flow"):
        interpolate(img, pts, fl[:1])
    with pytest.raises(ValueError, match="engine"):
        interpolate(img, pts, fl, engine="cuda")
    bad = img.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="frame0"):
        interpolate(bad, pts, fl)
    with pytest.raises(ValueError, match="params"):
        interpolate(img, pts, fl, params={"k": 3})
    with pytest.raises(ValueError, match="cost"):
        geodesic_voronoi(np.zeros((5, 5)), np.array([[1, 1]]))
    with pytest.raises(ValueError, match="seeds_yx"):
        geodesic_voronoi(np.ones((5, 5)), np.array([[1, 7]]))


# ------------------------------------------------------------------ geodesic distance
def _scipy_grid_distance(cost: np.ndarray, seeds_yx: np.ndarray) -> np.ndarray:
    """Independent reference: 8-connected grid graph, weight (C(p) + C(q))/2 · |p − q|."""
    h, w = cost.shape
    rows, cols, wts = [], [], []
    for y in range(h):
        for x in range(w):
            for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
                qy, qx = y + dy, x + dx
                if 0 <= qy < h and 0 <= qx < w:
                    rows.append(y * w + x)
                    cols.append(qy * w + qx)
                    wts.append(0.5 * (cost[y, x] + cost[qy, qx]) * np.hypot(dy, dx))
    g = sparse.coo_matrix((wts, (rows, cols)), shape=(h * w, h * w)).tocsr()
    d = csgraph.dijkstra(g, directed=False, indices=seeds_yx[:, 0] * w + seeds_yx[:, 1])
    return d.reshape(len(seeds_yx), h, w)


def test_geodesic_distance_equals_scipy_dijkstra() -> None:
    rng = np.random.default_rng(4)
    cost = rng.uniform(0.05, 2.0, (13, 17))
    seeds = np.array([[0, 0], [6, 9], [12, 3], [2, 15]])
    per_seed = _scipy_grid_distance(cost, seeds)
    for engine in ("numba", "numpy"):
        labels, dist = geodesic_voronoi(cost, seeds, engine=engine)
        np.testing.assert_allclose(dist, per_seed.min(0), rtol=1e-12, atol=1e-12)
        assert labels.dtype == np.int32 and labels.shape == cost.shape
        # the label is a seed at that distance
        picked = np.take_along_axis(per_seed, labels[None].astype(np.int64), 0)[0]
        np.testing.assert_allclose(picked, dist, rtol=1e-12)
    # a wall of high cost: the distance goes around it
    cost = np.full((9, 9), 0.1)
    cost[:7, 4] = 50.0
    _, dist = geodesic_voronoi(cost, np.array([[0, 0]]))
    assert dist[0, 8] > 1.2 and dist[0, 3] < 0.31


def test_seed_graph_and_nearest_seeds_engines_agree() -> None:
    rng = np.random.default_rng(1)
    cost = it.edge_cost(_smooth_image((30, 40)), InterpParams(edge_scale=10.0))
    seeds = np.unique(np.stack([rng.integers(0, 30, 60), rng.integers(0, 40, 60)], 1), axis=0)
    labels, dist = geodesic_voronoi(cost, seeds)
    n = len(seeds)
    g_nb = it.seed_graph(labels, dist, cost, n)
    g_np = it.seed_graph(labels, dist, cost, n, engine="numpy")
    for a, b in zip(g_nb, g_np, strict=True):
        np.testing.assert_array_equal(a, b)
    # the graph distance from a seed equals scipy's on the same graph
    idx_nb, d_nb = it.nearest_seeds(*g_nb, 17)
    idx_np, d_np = it.nearest_seeds(*g_nb, 17, engine="numpy")
    np.testing.assert_array_equal(idx_nb, idx_np)
    np.testing.assert_allclose(d_nb, d_np, rtol=1e-12)
    assert np.all(idx_nb[:, 0] == np.arange(n)) and np.all(d_nb[:, 0] == 0)
    assert np.all(np.diff(d_nb, axis=1) >= 0)
    # k above the number of seeds pads with -1 / inf
    idx, d = it.nearest_seeds(*g_nb, n + 5)
    assert np.all(idx[:, n:] == -1) and np.all(np.isinf(d[:, n:]))


def test_fit_models_engines_agree() -> None:
    rng = np.random.default_rng(2)
    n, k = 40, 12
    pos = rng.uniform(0, 30, (n, 2))
    val = rng.normal(0, 2, (n, 2))
    idx = np.stack([rng.permutation(n)[:k] for _ in range(n)])
    d = np.sort(rng.uniform(0, 3, (n, k)), 1)
    idx[:5, 2:] = -1  # too few neighbours: fallback
    d[:5, 2:] = np.inf
    for mode in ("la", "nw"):
        p = InterpParams(mode=mode)
        a = it.fit_models(pos, val, idx, d, p)
        b = it.fit_models(pos, val, idx, d, p, engine="numpy")
        for x, y in zip(a, b, strict=True):
            np.testing.assert_allclose(x, y, atol=1e-10)
        assert np.all(a[2][:5] == 0)
        if mode == "nw":
            assert np.all(a[2] == 0)


def test_interpolate_engines_agree_and_are_deterministic() -> None:
    rng = np.random.default_rng(3)
    img = _smooth_image((28, 36), seed=5)
    pts = np.stack([rng.uniform(0, 35, 70), rng.uniform(0, 27, 70)], 1).astype(np.float32)
    fl = rng.normal(0, 3, (70, 2)).astype(np.float32)
    for mode in ("la", "nw"):
        p = InterpParams(mode=mode, k=20, edge_scale=0.5)
        a = interpolate(img, pts, fl, p)
        b = interpolate(img, pts, fl, p, engine="numpy")
        assert a.shape == (28, 36, 2) and a.dtype == np.float32
        np.testing.assert_allclose(a, b, atol=1e-4)
        np.testing.assert_array_equal(a, interpolate(img, pts, fl, p))


def test_nan_and_duplicate_seeds_are_dropped() -> None:
    img, flow, _ = _scene(48, 64)
    pts, fl = _grid_samples(flow, 4)
    ref = interpolate(img, pts, fl)
    extra_pts = np.r_[pts, pts[:7] + 0.2, [[np.nan, 3.0], [5.0, 5.0], [-40.0, 2.0]]]
    extra_fl = np.r_[fl, fl[:7] + 50.0, [[0.0, 0.0], [np.nan, 1.0], [0.0, 0.0]]]
    out = interpolate(img, extra_pts.astype(np.float32), extra_fl.astype(np.float32))
    np.testing.assert_array_equal(out, ref)


# ------------------------------------------------------------------ accuracy
def test_affine_field_is_reproduced_by_la() -> None:
    img, _, _ = _scene()
    h, w = img.shape[:2]
    rng = np.random.default_rng(7)
    pts = np.stack([rng.uniform(0, w - 1, 600), rng.uniform(0, h - 1, 600)], 1)
    jac = np.array([[0.02, -0.05], [0.04, 0.01]])
    shift = np.array([3.0, -1.5])
    fl = pts @ jac.T + shift
    out = interpolate(img, pts.astype(np.float32), fl.astype(np.float32))
    yy, xx = np.mgrid[0:h, 0:w]
    exact = np.stack([xx, yy], -1) @ jac.T + shift
    assert np.abs(out - exact).max() < 1e-3


@pytest.mark.parametrize("outliers", [False, True])
def test_piecewise_affine_field_respects_image_edges(outliers: bool) -> None:
    """Sparse samples (every 4th pixel) of three affine motions split by image edges.

    With ``outliers``, 5 % of the samples are corrupted and then marked NaN (as a
    consistency check would), which also exercises the NaN dropping.
    """
    img, flow, region = _scene()
    h, w = region.shape
    pts, fl = _grid_samples(flow, 4)
    if outliers:
        rng = np.random.default_rng(11)
        bad = rng.random(len(fl)) < 0.05
        fl[bad] += rng.uniform(-15, 15, (bad.sum(), 2)).astype(np.float32)
        fl[bad] = np.nan
    dist = _boundary_distance(region)
    far, near = dist > 4, dist <= 2
    la = _epe(interpolate(img, pts, fl), flow)
    nw = _epe(interpolate(img, pts, fl, InterpParams(mode="nw")), flow)
    ok = np.isfinite(fl).all(1)
    yy, xx = np.mgrid[0:h, 0:w]
    lin = griddata(pts[ok], fl[ok], (xx, yy), method="linear")
    lin = np.where(np.isnan(lin), griddata(pts[ok], fl[ok], (xx, yy), method="nearest"), lin)
    lin = _epe(lin, flow)
    log.info("far: LA %.4f NW %.4f linear %.4f; near: LA %.3f NW %.3f linear %.3f",
             la[far].mean(), nw[far].mean(), lin[far].mean(), la[near].mean(),
             nw[near].mean(), lin[near].mean())
    assert la[far].mean() < 0.01
    assert nw[far].mean() < 0.1
    assert la[near].mean() < 0.4
    # the edge-aware part: a plain linear interpolation smears the motion boundaries
    assert la[near].mean() < 0.4 * lin[near].mean()
    assert nw[near].mean() < 0.5 * lin[near].mean()


# ------------------------------------------------------------------ real data
@pytest.mark.data
def test_sintel_ground_truth_samples(data_root: Path) -> None:
    """market_5 final 9 -> 10: the ground truth sampled on a 3 px grid, interpolated.

    Bounds what a pipeline with perfect matches on that grid can reach.
    """
    from varflow.evaluation.datasets import load_sintel_pair

    try:
        f0, _, gt, _, _ = load_sintel_pair("market_5", 9, "final", root=data_root)
    except FileNotFoundError as exc:
        import os

        if os.environ.get("VARFLOW_REQUIRE_DATA", "").strip() == "1":
            raise
        pytest.skip(str(exc))
    pts, fl = _grid_samples(gt, 3)
    t0 = time.perf_counter()
    out = interpolate(f0, pts, fl)
    seconds = time.perf_counter() - t0
    ok = np.isfinite(gt).all(2)
    aee = float(_epe(out, gt)[ok].mean())
    log.info("Sintel market_5 final 9: %d seeds, AEE %.3f px, %.2f s", len(pts), aee, seconds)
    assert out.shape == gt.shape and np.isfinite(out).all()
    assert aee < 2.0
