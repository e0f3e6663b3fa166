"""Tests of the two-frame photographic pairs (varflow.generators.photo_pairs)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter, map_coordinates

pytest.importorskip("skimage")

from scipy.spatial.transform import Rotation  # noqa: E402

from varflow.generators import photo_pairs  # noqa: E402
from varflow.generators.photo_pairs import (  # noqa: E402
    DEFAULT_SHAPE,
    FAMILIES,
    MAGNITUDE_RANGE,
    REPORTING_SEEDS,
    SPLITS,
    TUNING_SEEDS,
    PhotoPair,
    make_photo_pair,
    photo_pair_cases,
)

SHAPE = (96, 128)
H, W = SHAPE


@pytest.fixture(scope="module")
def pairs() -> dict[str, PhotoPair]:
    """One small pair per family (seed 1)."""
    return {fam: make_photo_pair(fam, seed=1, shape=SHAPE) for fam in FAMILIES}


def _grid(shape: tuple[int, int] = SHAPE) -> tuple[np.ndarray, np.ndarray]:
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return xx, yy


def _inside(flow: np.ndarray, margin: float = 0.0) -> np.ndarray:
    h, w = flow.shape[:2]
    xx, yy = _grid((h, w))
    tx, ty = xx + flow[..., 0], yy + flow[..., 1]
    return (tx >= margin) & (tx <= w - 1 - margin) & (ty >= margin) & (ty <= h - 1 - margin)


def _warp_residual(
    pair: PhotoPair, flow: np.ndarray, mask: np.ndarray, prefilter: float = 1.0
) -> float:
    """Mean |frame1(x + flow) - frame0(x)| (cubic, both clean frames pre-blurred) on ``mask``."""
    xx, yy = _grid(pair.shape)
    m = mask & _inside(flow, 4.0)
    m[:4] = m[-4:] = False
    m[:, :4] = m[:, -4:] = False
    f0, f1 = (gaussian_filter(f, (prefilter, prefilter, 0)) for f in pair.clean_frames)
    px, py = xx + flow[..., 0], yy + flow[..., 1]
    warped = np.stack(
        [map_coordinates(f1[..., c], [py, px], order=3) for c in range(f1.shape[-1])], -1
    )
    assert m.sum() > 30
    return float(np.abs(warped - f0)[m].mean())


# --------------------------------------------------------------------------- structure


@pytest.mark.parametrize("family", FAMILIES)
def test_shapes_dtypes_ranges(pairs, family):
    p = pairs[family]
    assert p.family == family and p.seed == 1 and p.name == f"{family}/1"
    for f in (p.frame0, p.frame1):
        assert f.shape == (H, W, 3) and f.dtype == np.float32
        assert f.min() >= 0.0 and f.max() <= 1.0
        assert f.std() > 0.03  # a photograph, not a flat image
    assert p.clean_frames.shape == (2, H, W, 3) and p.clean_frames.dtype == np.float32
    assert p.flow.shape == (H, W, 2) and p.flow.dtype == np.float32
    assert np.isfinite(p.flow).all()
    assert p.valid.shape == (H, W) and p.valid.dtype == bool
    assert p.layer.shape == (H, W) and p.layer.dtype == np.uint8
    assert np.array_equal(p.occlusion, ~p.valid)
    assert p.shape == SHAPE
    # small / medium motion, as calibrated
    assert 2.0 < p.params["max_displacement"] < 25.0
    assert MAGNITUDE_RANGE[0] <= p.params["magnitude"] <= MAGNITUDE_RANGE[1]
    assert 0.0 < p.params["mean_displacement"] <= p.params["max_displacement"]
    assert 0.5 < p.valid.mean() < 1.0
    assert p.params["occluded_fraction"] == pytest.approx(1.0 - p.valid.mean())
    geometric = family in ("affine", "homography", "nonrigid", "objects")
    same = np.array_equal(p.frame0, p.clean_frames[0]) and np.array_equal(
        p.frame1, p.clean_frames[1]
    )
    assert same == geometric


def test_determinism_and_seeds():
    a = make_photo_pair("objects", seed=2, shape=(64, 80))
    b = make_photo_pair("objects", seed=2, shape=(64, 80))
    for name in ("frame0", "frame1", "flow", "valid", "layer"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    c = make_photo_pair("objects", seed=3, shape=(64, 80))
    assert not np.array_equal(a.flow, c.flow)
    assert not np.array_equal(a.frame0, c.frame0)
    # noise comes from its own seeded stream: identical on a repeat call
    n1 = make_photo_pair("noise", seed=0, shape=(48, 64))
    n2 = make_photo_pair("noise", seed=0, shape=(48, 64))
    assert np.array_equal(n1.frame1, n2.frame1)


def test_channels_do_not_change_the_geometry():
    colour = make_photo_pair("objects", seed=1, shape=(64, 80))
    grey = make_photo_pair("objects", seed=1, shape=(64, 80), channels=1)
    assert grey.frame0.shape == (64, 80, 1)
    assert np.array_equal(colour.flow, grey.flow)
    assert np.array_equal(colour.valid, grey.valid)


def test_splits_disjoint_and_cases():
    assert TUNING_SEEDS == (0, 1, 2) and REPORTING_SEEDS == (100, 101, 102)
    assert not set(SPLITS["tuning"]) & set(SPLITS["reporting"])
    assert photo_pair_cases("tuning", ["affine", "blur"]) == [
        ("affine", 0), ("affine", 1), ("affine", 2), ("blur", 0), ("blur", 1), ("blur", 2)
    ]
    assert photo_pair_cases("reporting", ["noise"]) == [("noise", 100), ("noise", 101),
                                                        ("noise", 102)]
    assert len(photo_pair_cases("reporting")) == 3 * len(FAMILIES)
    # different seeds of a family are different scenes
    t0 = make_photo_pair("affine", 0, shape=(48, 64))
    r0 = make_photo_pair("affine", 100, shape=(48, 64))
    assert not np.array_equal(t0.flow, r0.flow)


def test_default_size_and_generation_time():
    assert DEFAULT_SHAPE == (256, 320)
    make_photo_pair("nonrigid", 0, shape=(48, 64))  # photos loaded and cached
    t0 = time.perf_counter()
    p = make_photo_pair("nonrigid", 0)
    seconds = time.perf_counter() - t0
    assert p.frame0.shape == (256, 320, 3)
    assert seconds < 4.0  # ~0.4 s on one core; a gross regression guard


def test_magnitude_argument():
    p = make_photo_pair("affine", 0, shape=SHAPE, magnitude=5.0)
    assert p.params["magnitude"] == 5.0
    # calibrated at the corners of frame 1 (mapped back); the flow of frame 0 is close
    assert p.params["max_displacement"] == pytest.approx(5.0, rel=0.1)
    z = make_photo_pair("affine", 0, shape=SHAPE, magnitude=0.0)
    assert np.abs(z.flow).max() < 1e-6
    assert np.array_equal(z.frame0, z.frame1)


# --------------------------------------------------------------------------- exact ground truth


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_affine_flow_is_the_camera_map(seed):
    """flow(x) = M_1(M_0^{-1}(x)) - x, from the stored M_n(p) = c + A_n (p - c) + b_n."""
    p = make_photo_pair("affine", seed, shape=SHAPE)
    m = p.params["motion"]
    a, b, c = m["A"], m["b"], m["centre"]
    rng = np.random.default_rng(seed)
    ys, xs = rng.integers(0, H, 50), rng.integers(0, W, 50)
    x = np.stack([xs, ys], -1).astype(np.float64)
    p0 = c + np.linalg.solve(a[0], (x - c - b[0]).T).T  # M_0^{-1}(x)
    x1 = c + (a[1] @ (p0 - c).T).T + b[1]
    np.testing.assert_allclose(p.flow[ys, xs], x1 - x, atol=2e-5)
    mat = p.params["camera"]["matrix"]
    assert p.params["camera"]["kind"] == "affine" and mat.shape == (2, 3)
    np.testing.assert_allclose(x @ mat[:, :2].T + mat[:, 2], x1, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_homography_flow_is_the_plane_reprojection(seed):
    """Back-project x onto the plane n . X = 1, move the camera (R, t), project again."""
    p = make_photo_pair("homography", seed, shape=SHAPE)
    m = p.params["motion"]
    k, normal = m["K"], m["plane_normal"]
    rot = Rotation.from_rotvec(m["rotation_vector"]).as_matrix()
    t = m["translation"]
    rng = np.random.default_rng(seed)
    ys, xs = rng.integers(0, H, 60), rng.integers(0, W, 60)
    rays = np.linalg.solve(k, np.stack([xs, ys, np.ones(60)]).astype(np.float64))
    points0 = rays / (normal @ rays)  # on the plane
    proj = k @ (rot @ points0 + t[:, None])
    x1 = proj[:2] / proj[2]
    np.testing.assert_allclose(p.flow[ys, xs], (x1 - np.stack([xs, ys])).T, atol=2e-5)
    # a real perspective motion: the map is not affine
    hom = p.params["camera"]["matrix"]
    assert p.params["camera"]["kind"] == "homography"
    assert np.abs(hom[2, :2]).max() > 1e-6
    design = np.stack([xs, ys, np.ones(60)], -1).astype(np.float64)
    target = x1.T
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    assert np.hypot(*(design @ coef - target).T).max() > 0.05 * p.params["magnitude"]


@pytest.mark.parametrize("family", ["affine", "homography", "nonrigid"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_warping_frame1_back_reproduces_frame0(family, seed):
    p = make_photo_pair(family, seed, shape=SHAPE)
    err = _warp_residual(p, p.flow, p.valid)
    assert err < 0.0025, err  # ~1e-4 to 1e-3 measured (interpolation only)
    shifted = _warp_residual(p, p.flow + np.float32([0.5, 0.0]), p.valid)
    scaled = _warp_residual(p, 0.9 * p.flow, p.valid)
    assert shifted > 4.0 * err, (err, shifted)
    assert scaled > 4.0 * err, (err, scaled)


# --------------------------------------------------------------------------- occlusion


@pytest.mark.parametrize("seed", TUNING_SEEDS)
def test_objects_occlusion_mask(seed):
    p = make_photo_pair("objects", seed, shape=SHAPE)
    n_obj = len(p.params["objects"])
    assert 1 <= n_obj <= 3
    assert set(np.unique(p.layer)) <= set(range(n_obj + 1))
    assert (p.layer > 0).mean() > 0.02  # the objects are seen
    inside = _inside(p.flow)
    assert not p.valid[~inside].any()  # leaving the frame is not valid
    front = p.layer == p.layer.max()
    assert p.valid[front & inside].all()  # nothing can hide the front-most layer
    hidden = ~p.valid & inside
    assert 20 < hidden.sum() < 0.2 * H * W
    assert not (hidden & front).any()
    # hidden pixels really show something else in frame 1: large warp residual there
    ok = _warp_residual(p, p.flow, p.valid, prefilter=0.0)
    bad = _warp_residual(p, p.flow, hidden, prefilter=0.0)
    assert ok < 0.015 and bad > 5.0 * ok, (ok, bad)
    # the objects move independently of the camera
    mat = p.params["camera"]["matrix"]
    xx, yy = _grid()
    cam = np.stack([mat[0, 0] * xx + mat[0, 1] * yy + mat[0, 2] - xx,
                    mat[1, 0] * xx + mat[1, 1] * yy + mat[1, 2] - yy], -1)
    dev = np.hypot(*np.moveaxis(p.flow - cam, -1, 0))
    assert dev[p.layer == 0].max() < 1e-4
    assert dev[p.layer > 0].mean() > 1.0


# --------------------------------------------------------------------------- photometry


def test_illumination_changes_the_light_between_the_frames(pairs):
    p = pairs["illumination"]
    info = p.params["illumination"]
    gain = info["gain"]
    assert abs(np.log(gain[1] / gain[0])) > 0.1
    # frame = clip(field * clean + offset): recover the field where nothing clips
    for n, frame in enumerate((p.frame0, p.frame1)):
        xx, yy = _grid()
        c = info["centre"]
        field = gain[n] * np.exp(info["gradient"][n, 0] * (xx - c[0])
                                 + info["gradient"][n, 1] * (yy - c[1]))
        expect = np.clip(field[..., None] * p.clean_frames[n] + info["offset"][n], 0, 1)
        np.testing.assert_allclose(frame, expect, atol=1e-5)
    # the brightness change is not a pure geometry: the two frames differ in mean level
    ratio = (p.frame1.mean() / p.clean_frames[1].mean()) / (p.frame0.mean()
                                                            / p.clean_frames[0].mean())
    assert abs(np.log(ratio)) > 0.05


def test_noise_level(pairs):
    p = pairs["noise"]
    sigma = p.params["noise"]["sigma"]
    lo, hi = photo_pairs.NOISE_SIGMA_RANGE
    assert lo <= sigma <= hi
    for n, frame in enumerate((p.frame0, p.frame1)):
        clean = p.clean_frames[n]
        mid = (clean > 0.2) & (clean < 0.8)  # away from the clipping
        z = (frame - clean)[mid] / (sigma * (0.6 + 0.8 * clean[mid]))
        assert abs(z.std() - 1.0) < 0.05 and abs(z.mean()) < 0.05
    assert not np.array_equal(p.frame0 - p.clean_frames[0], p.frame1 - p.clean_frames[1])


def _gradient_energy(img: np.ndarray) -> float:
    return float(np.mean(np.diff(img, axis=0) ** 2) + np.mean(np.diff(img, axis=1) ** 2))


@pytest.mark.parametrize("seed", [0, 100, 101])  # motion/second, gaussian/second, gaussian/both
def test_blur_frames(seed):
    p = make_photo_pair("blur", seed, shape=SHAPE)
    info = p.params["blur"]
    assert info["kind"] in ("gaussian", "motion") and info["frames"] in ("second", "both")
    blurred = (1,) if info["frames"] == "second" else (0, 1)
    for n, frame in enumerate((p.frame0, p.frame1)):
        if n in blurred:
            assert _gradient_energy(frame) < 0.8 * _gradient_energy(p.clean_frames[n])
        else:
            assert np.array_equal(frame, p.clean_frames[n])
    # the blur is centred: the flow of the sharp scene still aligns the blurred frames
    if info["frames"] == "both" and info["kind"] == "gaussian":
        err = _warp_residual(p, p.flow, p.valid)
        assert err < 0.0025


def test_blur_seeds_cover_both_kinds():
    kinds = {make_photo_pair("blur", s, shape=(48, 64)).params["blur"]["kind"]
             for s in TUNING_SEEDS + REPORTING_SEEDS}
    assert kinds == {"gaussian", "motion"}


def test_motion_blur_kernel():
    ker = photo_pairs._line_kernel(6.0, 0.0)
    assert ker.sum() == pytest.approx(1.0)
    r = ker.shape[0] // 2
    assert np.allclose(ker, ker[::-1, ::-1])  # centred: no shift
    assert ker[r].sum() == pytest.approx(1.0)  # horizontal line
    cols = np.nonzero(ker[r])[0]
    assert cols.max() - cols.min() == 6


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"family": "spiral"}, "family"),
        ({"family": "affine", "seed": -1}, "seed"),
        ({"family": "affine", "seed": 1.5}, "seed"),
        ({"family": "affine", "shape": (16, 64)}, "shape"),
        ({"family": "affine", "shape": (64,)}, "shape"),
        ({"family": "affine", "magnitude": -1.0}, "magnitude"),
        ({"family": "affine", "magnitude": 100.0}, "magnitude"),
        ({"family": "affine", "channels": 2}, "channels"),
        ({"family": "affine", "supersample": 0}, "supersample"),
    ],
)
def test_invalid_arguments(kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        make_photo_pair(**kwargs)


def test_invalid_split_and_families():
    with pytest.raises(ValueError, match="^split:"):
        photo_pair_cases("validation")
    with pytest.raises(ValueError, match="^families:"):
        photo_pair_cases("tuning", ["affine", "waves"])
    with pytest.raises(ValueError, match="^families:"):
        photo_pair_cases("tuning", "affine")
