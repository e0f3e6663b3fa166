"""Tests of varflow.ops.matching: large-displacement CPM matches."""

from __future__ import annotations

import dataclasses

import numba as nb
import numpy as np
import pytest
from skimage import data

from varflow.ops import matching as m


def _photo(name: str) -> np.ndarray:
    return getattr(data, name)().astype(np.float32) / np.float32(255.0)


def _shift_pair(img: np.ndarray, shape: tuple[int, int], origin: tuple[int, int],
                shift: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Crops with ``frame1(x + shift) = frame0(x)`` (shift = (u, v))."""
    h, w = shape
    y0, x0 = origin
    u, v = shift
    f0 = img[y0:y0 + h, x0:x0 + w]
    f1 = img[y0 - v:y0 - v + h, x0 - u:x0 - u + w]
    assert f0.shape[:2] == shape and f1.shape[:2] == shape
    return np.ascontiguousarray(f0), np.ascontiguousarray(f1)


def _errors(res: m.Matches, gt_uv: np.ndarray) -> np.ndarray:
    return np.hypot(res.flow[:, 0] - gt_uv[:, 0], res.flow[:, 1] - gt_uv[:, 1])


def _inside(res: m.Matches, shape: tuple[int, int], uv: tuple[float, float]) -> np.ndarray:
    """Grid seeds whose true target ``x + uv`` lies inside the frame (gh, gw) bool."""
    h, w = shape
    gh, gw = res.grid_flow.shape[:2]
    xs, ys = m.seed_grid(shape, res.step)
    tx = xs[None, :] + uv[0]
    ty = ys[:, None] + uv[1]
    return np.broadcast_to((tx >= 0) & (tx <= w - 1) & (ty >= 0) & (ty <= h - 1), (gh, gw))


# ----------------------------------------------------------------------- accuracy
def test_translation_47_31():
    shape, shift = (300, 400), (47, -31)
    f0, f1 = _shift_pair(_photo("astronaut"), shape, (100, 60), shift)
    res = m.match(f0, f1)
    assert res.points.shape == res.flow.shape == (len(res.cost), 2)
    assert res.points.dtype == res.flow.dtype == res.cost.dtype == np.float32
    err = _errors(res, np.broadcast_to(np.float32(shift), res.flow.shape))
    assert np.median(err) < 0.5
    assert np.mean(err < 1.0) >= 0.9
    # most seeds with a visible target are kept, few with the target outside the frame
    inside = _inside(res, shape, shift)
    kept = np.isfinite(res.grid_flow[..., 0])
    assert kept[inside].mean() > 0.8
    assert kept[~inside].mean() < 0.2


def _object_pair():
    """Background moving by 120 px, a 70 x 90 object moving by (-35, 22)."""
    bg = _photo("coffee")  # 400 x 600
    obj = _photo("astronaut")[40:110, 180:270]
    shape, bg_shift, obj_shift = (260, 360), (120, -8), (-35, 22)
    f0, f1 = _shift_pair(bg, shape, (60, 180), bg_shift)
    f0, f1 = f0.copy(), f1.copy()
    oy, ox = 100, 150
    f0[oy:oy + 70, ox:ox + 90] = obj
    f1[oy + obj_shift[1]:oy + obj_shift[1] + 70, ox + obj_shift[0]:ox + obj_shift[0] + 90] = obj
    return f0, f1, shape, bg_shift, obj_shift, (oy, ox, 70, 90)


def test_translation_120_with_independent_object():
    f0, f1, shape, bg_shift, obj_shift, (oy, ox, oh, ow) = _object_pair()
    res = m.match(f0, f1)
    h, w = shape
    px, py = res.points[:, 0], res.points[:, 1]
    on_obj = (px >= ox) & (px < ox + ow) & (py >= oy) & (py < oy + oh)
    gt = np.where(on_obj[:, None], np.float32(obj_shift), np.float32(bg_shift))
    # background seeds whose target is covered by the object in frame 1 or leaves the
    # frame have no true match: left out of the error statistics
    tx, ty = px + gt[:, 0], py + gt[:, 1]
    oy1, ox1 = oy + obj_shift[1], ox + obj_shift[0]
    covered = ~on_obj & (tx >= ox1 - 2) & (tx < ox1 + ow + 2) & (ty >= oy1 - 2) \
        & (ty < oy1 + oh + 2)
    visible = (tx >= 0) & (tx <= w - 1) & (ty >= 0) & (ty <= h - 1) & ~covered
    err = _errors(res, gt)[visible]
    assert np.median(err) < 0.5
    assert np.mean(err < 1.0) >= 0.9
    assert np.mean(err[on_obj[visible]] < 1.0) >= 0.85
    assert on_obj[visible].sum() >= 0.5 * (oh * ow) / res.step**2  # the object is found
    assert visible.mean() > 0.85  # few kept seeds lack a true match


def test_forward_backward_rejects_occluded_region():
    shape, shift = (240, 320), (40, 25)
    f0, f1 = _shift_pair(_photo("astronaut"), shape, (150, 80), shift)
    f1 = f1.copy()
    patch = _photo("coffee")[100:180, 200:300]
    cy, cx = 80, 120  # covered region in frame 1
    f1[cy:cy + 80, cx:cx + 100] = patch
    res = m.match(f0, f1)
    xs, ys = m.seed_grid(shape, res.step)
    tx = xs[None, :] + shift[0]
    ty = ys[:, None] + shift[1]
    covered = (tx >= cx + 4) & (tx < cx + 96) & (ty >= cy + 4) & (ty < cy + 76)
    inside = _inside(res, shape, shift)
    rejected = ~np.isfinite(res.grid_flow[..., 0])
    rate_occ = rejected[covered].mean()
    rate_vis = rejected[inside & ~covered].mean()
    assert rate_occ > 0.8
    assert rate_vis < 0.15


# --------------------------------------------------------------- engines, determinism
def _small_pair():
    return _shift_pair(_photo("astronaut"), (72, 96), (200, 200), (13, -9))


def test_descriptors_engines_agree():
    f0, _ = _small_pair()
    p = m.MatchParams()
    a = m.descriptors(f0, p, engine="numba")
    b = m.descriptors(f0, p, engine="numpy")
    assert a.shape == (72, 96, 128) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)
    # unit norm after quantisation, except where rounding or the 255 cap bites
    norms = np.linalg.norm(a.astype(np.float64) / 512.0, axis=2)
    assert np.mean(np.abs(norms - 1.0) < 0.02) > 0.95


@pytest.mark.parametrize("shape", [(1, 1), (3, 2), (9, 31), (33, 70)])
def test_describe_kernel_is_bit_identical_across_block_edges(shape):
    rng = np.random.default_rng(3)
    p = m.MatchParams(cell_size=2)
    planes = m._orientation_planes(rng.random(shape).astype(np.float32), p)
    planes[0, 0] = 0.0  # a flat pixel: the small-norm guard
    a = m._describe_planes(planes, p, "numba")
    b = m._describe_planes(planes, p, "numpy")
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("shape", [(1, 1), (2, 3), (5, 4), (3, 9), (40, 57)])
@pytest.mark.parametrize("cell_size", [1, 2, 3, 5])
def test_orientation_planes_kernel_is_bit_identical(shape, cell_size):
    rng = np.random.default_rng(7)
    lum = rng.random(shape).astype(np.float32)
    p = m.MatchParams(cell_size=cell_size)
    ref = m._orientation_planes(lum, p, engine="numpy")
    out = m._orientation_planes(lum, p, engine="numba")
    assert out.shape == shape + (p.orientations,) and out.dtype == np.float32
    np.testing.assert_array_equal(out, ref)
    assert ref.sum() > 0 or shape == (1, 1)  # a single pixel has no gradient


@pytest.mark.parametrize("subpixel", [True, False])
def test_match_engines_agree(subpixel):
    f0, f1 = _small_pair()
    p = m.MatchParams(levels=3, iterations=4, subpixel=subpixel)
    a = m.match(f0, f1, p, engine="numba")
    b = m.match(f0, f1, p, engine="numpy")
    np.testing.assert_array_equal(np.isnan(a.grid_flow), np.isnan(b.grid_flow))
    np.testing.assert_allclose(a.grid_flow, b.grid_flow, atol=1e-5, equal_nan=True)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.cost, b.cost)
    assert len(a.flow) > 0.5 * a.grid_flow[..., 0].size
    if not subpixel:
        assert np.all(a.flow == np.rint(a.flow))


def test_random_numbers_agree():
    key = m._level_key(7, 2, 1)
    for a, b in [(0, 0), (64, 5), (65, 123456), (1000, 2**31 + 3)]:
        assert int(m._rand_nb(np.uint64(key), a, b)) == m._rand_py(key, a, b)


def test_deterministic_across_runs_and_threads():
    f0, f1, *_ = _object_pair()
    a = m.match(f0, f1)
    b = m.match(f0, f1)
    old = nb.get_num_threads()
    try:
        nb.set_num_threads(1)
        c = m.match(f0, f1)
    finally:
        nb.set_num_threads(old)
    for r in (b, c):
        np.testing.assert_array_equal(a.grid_flow, r.grid_flow)
        np.testing.assert_array_equal(a.cost, r.cost)
    d = m.match(f0, f1, m.MatchParams(seed=1))
    assert d.grid_flow.shape == a.grid_flow.shape  # another seed: still valid


def test_grid_layout_and_nan_for_rejected():
    f0, f1 = _small_pair()
    res = m.match(f0, f1, m.MatchParams(step=4, levels=3))
    xs, ys = m.seed_grid((72, 96), 4)
    assert res.step == 4
    assert res.grid_flow.shape == (len(ys), len(xs), 2)
    kept = np.isfinite(res.grid_flow[..., 0])
    iy, ix = np.nonzero(kept)
    np.testing.assert_array_equal(res.points, np.stack([xs[ix], ys[iy]], 1))
    np.testing.assert_array_equal(res.flow, res.grid_flow[kept])
    strict = m.match(f0, f1, m.MatchParams(step=4, levels=3, max_cost=0.0))
    assert len(strict.flow) < len(res.flow)


# ------------------------------------------------------------------ validation
@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("step", 0),
        ("step", 2.5),
        ("levels", 0),
        ("max_displacement", -1.0),
        ("max_displacement", float("nan")),
        ("iterations", 0),
        ("search_radius", -1),
        ("fb_threshold", -0.5),
        ("max_cost", -1.0),
        ("cells", 0),
        ("cell_size", 0),
        ("orientations", 1),
        ("gradient_sigma", -1.0),
        ("clip", 0.0),
        ("clip", 1.5),
        ("subpixel", "yes"),
        ("min_level_size", 1),
        ("seed", -1),
        ("levels", True),
    ],
)
def test_invalid_params_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        m.MatchParams(**{field: value})


def test_params_frozen_and_bad_inputs():
    p = m.MatchParams()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.step = 4  # type: ignore[misc]
    img = np.zeros((40, 50), np.float32)
    with pytest.raises(ValueError, match="engine"):
        m.match(img, img, engine="cuda")
    with pytest.raises(ValueError, match="frame1"):
        m.match(img, np.zeros((40, 51), np.float32))
    with pytest.raises(ValueError, match="params"):
        m.match(img, img, params={"step": 3})  # type: ignore[arg-type]


# ------------------------------------------------------------------ real data
@pytest.mark.data
def test_sintel_market5_large_motion(data_root):
    import varflow
    from varflow.io.flo import unknown_pixels

    seq = data_root / "sintel" / "training"
    f0 = varflow.read_image(seq / "final" / "market_5" / "frame_0009.png")
    f1 = varflow.read_image(seq / "final" / "market_5" / "frame_0010.png")
    gt = varflow.read_flo(seq / "flow" / "market_5" / "frame_0009.flo")
    res = m.match(f0, f1)
    xi = res.points[:, 0].astype(int)
    yi = res.points[:, 1].astype(int)
    g = gt[yi, xi]
    ok = ~unknown_pixels(gt)[yi, xi]
    err = np.hypot(*(res.flow[ok] - g[ok]).T)
    assert len(res.flow) > 0.3 * res.grid_flow[..., 0].size
    assert np.median(err) < 2.0
    assert np.max(np.hypot(*g[ok].T)) > 60  # the pair does contain large motion
