"""Tests of the photographic trajectory clips (varflow.generators.photo)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

pytest.importorskip("skimage")

from varflow.generators import photo, photo_render, photo_scenes, photo_textures  # noqa: E402
from varflow.generators.photo import (  # noqa: E402
    FAMILIES,
    PHOTOS,
    REPORTING_SEEDS,
    SPLITS,
    TUNING_SEEDS,
    make_photo_clip,
    photo_cases,
    photo_suite,
)
from varflow.generators.sequences import SyntheticSequence  # noqa: E402

F, SHAPE = 9, (64, 96)
H, W = SHAPE


@pytest.fixture(scope="module")
def clips() -> dict[str, SyntheticSequence]:
    """One small clip per family (seed 1)."""
    return {fam: make_photo_clip(fam, seed=1, n_frames=F, shape=SHAPE) for fam in FAMILIES}


def _grid(shape: tuple[int, int] = SHAPE) -> tuple[np.ndarray, np.ndarray]:
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return xx, yy


def _warp_error(clip: SyntheticSequence, n: int, delta=(0.0, 0.0)) -> tuple[float, float]:
    """Mean |I_n(x + traj[n, x]) - I_ref(x)| (bilinear) over visible interior points."""
    h, w = clip.shape
    xx, yy = _grid((h, w))
    px = xx + clip.trajectories[n, ..., 0] + delta[0]
    py = yy + clip.trajectories[n, ..., 1] + delta[1]
    m = clip.visibility[n] & (px >= 1) & (px <= w - 2) & (py >= 1) & (py <= h - 2)
    m[:2] = m[-2:] = False
    m[:, :2] = m[:, -2:] = False
    img = clip.clean_frames[n]
    warped = np.stack(
        [map_coordinates(img[..., c], [py, px], order=1) for c in range(img.shape[-1])], -1
    )
    return float(np.abs(warped - clip.clean_frames[clip.ref])[m].mean()), float(m.mean())


# --------------------------------------------------------------------------- structure


@pytest.mark.parametrize("family", FAMILIES)
def test_shapes_dtypes_ranges(clips, family):
    clip = clips[family]
    assert isinstance(clip, SyntheticSequence)
    assert clip.name == family and clip.variant == "photo" and clip.seed == 1
    assert clip.ref == F // 2
    assert clip.frames.shape == (F, H, W, 3) and clip.frames.dtype == np.float32
    assert clip.clean_frames.shape == (F, H, W, 3) and clip.clean_frames.dtype == np.float32
    assert clip.trajectories.shape == (F, H, W, 2) and clip.trajectories.dtype == np.float32
    assert clip.visibility.shape == (F, H, W) and clip.visibility.dtype == bool
    assert clip.layer.shape == (H, W) and clip.layer.dtype == np.uint8
    for arr in (clip.frames, clip.clean_frames):
        assert np.isfinite(arr).all() and arr.min() >= 0.0 and arr.max() <= 1.0
    assert np.all(clip.trajectories[clip.ref] == 0.0)
    assert clip.visibility[clip.ref].all()
    assert np.isfinite(clip.trajectories).all()
    # a photograph, not a flat image: plenty of grey levels and contrast
    assert clip.clean_frames[clip.ref].std() > 0.05
    assert np.unique(np.round(clip.clean_frames[clip.ref] * 255)).size > 100
    p = clip.params
    for key in ("magnitude", "max_displacement", "occluded_fraction", "photos", "times"):
        assert key in p
    assert 30.0 <= p["magnitude"] <= 50.0  # default drawn per seed
    assert all(name in PHOTOS for name in p["photos"])
    assert p["times"].shape == (F,)
    assert 0.0 < p["occluded_fraction"] < 1.0
    assert p["max_displacement"] == pytest.approx(
        float(np.hypot(*np.moveaxis(clip.trajectories, -1, 0)).max())
    )
    n_layers = 1 + len(p["objects"])
    assert set(np.unique(clip.layer)) <= set(range(n_layers))
    if family in ("affine", "nonrigid", "objects"):
        assert clip.frames is clip.clean_frames


def _affine_expected(clip: SyntheticSequence) -> np.ndarray:
    """Trajectories recomputed from the stored camera motion ``A``, ``b``, ``centre``."""
    m = clip.params["motion"]
    a, b, c = m["A"], m["b"], m["centre"]
    xx, yy = _grid(clip.shape)
    x = np.stack([xx, yy], -1)
    r = clip.ref
    p = (x - c - b[r]) @ np.linalg.inv(a[r]).T + c  # M_ref^{-1}(x)
    return np.stack([(p - c) @ a[n].T + c + b[n] - x for n in range(clip.n_frames)])


def test_grey_channel_and_ref_independence():
    grey = make_photo_clip("affine", seed=2, n_frames=5, shape=(48, 64), channels=1)
    assert grey.frames.shape == (5, 48, 64, 1)
    colour = make_photo_clip("affine", seed=2, n_frames=5, shape=(48, 64))
    luma = colour.frames @ np.array([0.2125, 0.7154, 0.0721], np.float32)
    if grey.params["photos"][0] in photo.COLOUR_PHOTOS:
        assert np.abs(grey.frames[..., 0] - luma).max() < 1e-5
    first = make_photo_clip("affine", seed=2, n_frames=5, shape=(48, 64), ref=0)
    np.testing.assert_array_equal(first.frames, colour.frames)  # frames do not depend on ref
    assert first.ref == 0 and np.all(first.trajectories[0] == 0) and first.visibility[0].all()
    assert np.abs(first.trajectories - _affine_expected(first)).max() < 1e-4
    assert np.abs(colour.trajectories - _affine_expected(colour)).max() < 1e-4


def test_determinism():
    a = make_photo_clip("objects", seed=5, n_frames=5, shape=(48, 64))
    b = make_photo_clip("objects", seed=5, n_frames=5, shape=(48, 64))
    c = make_photo_clip("objects", seed=6, n_frames=5, shape=(48, 64))
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.trajectories, b.trajectories)
    np.testing.assert_array_equal(a.visibility, b.visibility)
    np.testing.assert_array_equal(a.layer, b.layer)
    assert a.params["photos"] == b.params["photos"]
    assert np.abs(a.frames - c.frames).mean() > 0.05
    # noise is seeded too
    na = make_photo_clip("noise", seed=5, n_frames=3, shape=(32, 48))
    nb = make_photo_clip("noise", seed=5, n_frames=3, shape=(32, 48))
    np.testing.assert_array_equal(na.frames, nb.frames)


def test_splits_and_suite():
    assert set(TUNING_SEEDS).isdisjoint(REPORTING_SEEDS)
    assert SPLITS == {"tuning": TUNING_SEEDS, "reporting": REPORTING_SEEDS}
    cases = photo_cases("reporting")
    assert cases == [(f, s) for f in FAMILIES for s in REPORTING_SEEDS]
    assert photo_cases("tuning", ["noise"]) == [("noise", s) for s in TUNING_SEEDS]
    suite = photo_suite("tuning", families=("affine", "noise"), n_frames=3, shape=(32, 48))
    assert not isinstance(suite, list)  # lazy
    got = [(clip.name, clip.seed, clip.frames.shape) for clip in suite]
    assert got == [(f, s, (3, 32, 48, 3)) for f in ("affine", "noise") for s in TUNING_SEEDS]
    # the photos of a split differ between seeds (the background at least once)
    backs = {
        make_photo_clip("affine", seed=s, n_frames=2, shape=(32, 48)).params["photos"][0]
        for s in TUNING_SEEDS + REPORTING_SEEDS
    }
    assert len(backs) >= 3


# --------------------------------------------------------------------------- exact ground truth


def test_affine_trajectories_from_stored_motion(clips):
    clip = clips["affine"]
    m = clip.params["motion"]
    a, b, c = m["A"], m["b"], m["centre"]
    assert a.shape == (F, 2, 2) and b.shape == (F, 2)
    assert np.abs(clip.trajectories - _affine_expected(clip)).max() < 1e-4
    # A_n = exp(z) R(theta) [[1, h], [0, 1]] from the stored rotation / zoom / shear
    th, z, sh = m["rotation"], m["log_zoom"], m["shear"]
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]).transpose(2, 0, 1)
    shear = np.tile(np.eye(2), (F, 1, 1))
    shear[:, 0, 1] = sh
    np.testing.assert_allclose(np.exp(z)[:, None, None] * rot @ shear, a, atol=1e-12)
    # not constant velocity: the steps of the image centre change along the clip
    centre = (np.array([W / 2, H / 2]) - c) @ a.transpose(0, 2, 1) + c + b
    steps = np.linalg.norm(np.diff(centre, axis=0), axis=-1)
    assert steps.max() > 1.2 * steps.min()


def test_nonrigid_trajectories_from_stored_waves(clips):
    clip = clips["nonrigid"]
    m = clip.params["motion"]
    assert m["strain_bound"] <= 0.5
    kappa, e, amp = m["kappa"], m["direction"], m["amplitude"]
    omega, phase, drift, t = m["omega"], m["phase"], m["drift"], m["times"]

    def s(px, py, n):
        sx = np.full_like(px, drift[n, 0])
        sy = np.full_like(py, drift[n, 1])
        for k in range(amp.size):
            sin = np.sin(kappa[k, 0] * px + kappa[k, 1] * py - omega[k] * t[n] + phase[k])
            sx += amp[k] * e[k, 0] * sin
            sy += amp[k] * e[k, 1] * sin
        return sx, sy

    xx, yy = _grid()
    r = clip.ref
    px, py = xx.copy(), yy.copy()
    for _ in range(80):  # p = x - s_ref(p) is a contraction (|grad s| <= 0.5)
        sx, sy = s(px, py, r)
        px, py = xx - sx, yy - sy
    sx, sy = s(px, py, r)
    assert max(np.abs(px + sx - xx).max(), np.abs(py + sy - yy).max()) < 1e-9
    for n in range(F):
        sx, sy = s(px, py, n)
        assert np.abs(clip.trajectories[n, ..., 0] - (px + sx - xx)).max() < 1e-4
        assert np.abs(clip.trajectories[n, ..., 1] - (py + sy - yy)).max() < 1e-4


def _covers(shape_info: dict, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """The object outline predicate, re-implemented from the stored parameters."""
    if shape_info["kind"] == "superellipse":
        ang, (a, b), e = shape_info["angle"], shape_info["axes"], shape_info["exponent"]
        u = np.cos(ang) * px + np.sin(ang) * py
        v = -np.sin(ang) * px + np.cos(ang) * py
        return np.abs(u / a) ** e + np.abs(v / b) ** e <= 1.0
    phi = np.arctan2(py, px)
    r = 1.0 + sum(amp * np.cos(m * phi + ph) for m, amp, ph in shape_info["harmonics"])
    return np.hypot(px, py) <= shape_info["base"] * r


def test_objects_layers_and_visibility_from_stored_parameters(clips):
    clip = clips["objects"]
    p = clip.params
    objs = p["objects"]
    assert 1 <= len(objs) <= 3
    bg = p["motion"]
    xx, yy = _grid()
    x = np.stack([xx, yy], -1)
    r = clip.ref
    # texture coordinates of every pixel in every layer, ownership = front-most cover
    owner = np.zeros((H, W), np.uint8)
    tex = []
    for i, o in enumerate(objs, start=1):
        assert 0.08 * min(SHAPE) <= o["radius"] <= 0.25 * min(SHAPE)
        assert o["depth"] == i - 1
        q = (x - o["b"][r]) @ np.linalg.inv(o["A"][r]).T
        tex.append(q)
        owner[_covers(o["shape"], q[..., 0], q[..., 1])] = i
    np.testing.assert_array_equal(owner, clip.layer)
    # positions of every point in every frame, and visibility
    pb = (x - bg["centre"] - bg["b"][r]) @ np.linalg.inv(bg["A"][r]).T + bg["centre"]
    for n in range(F):
        pos = (pb - bg["centre"]) @ bg["A"][n].T + bg["centre"] + bg["b"][n]
        for i, o in enumerate(objs, start=1):
            sel = owner == i
            pos[sel] = tex[i - 1][sel] @ o["A"][n].T + o["b"][n]
        assert np.abs(x + clip.trajectories[n] - pos).max() < 1e-4
        vis = (pos[..., 0] >= 0) & (pos[..., 0] <= W - 1) & (pos[..., 1] >= 0)
        vis &= pos[..., 1] <= H - 1
        for i, o in enumerate(objs, start=1):
            q = (pos - o["b"][n]) @ np.linalg.inv(o["A"][n]).T
            covered = _covers(o["shape"], q[..., 0], q[..., 1])
            vis &= ~(covered & (owner < i))
        assert np.mean(vis != clip.visibility[n]) < 1e-3  # float32 vs float64 at edges


def test_objects_occlude_and_leave(clips):
    for family in ("objects", "illumination", "noise"):
        clip = clips[family]
        p = clip.params
        xx, yy = _grid()
        px = xx + clip.trajectories[..., 0]
        py = yy + clip.trajectories[..., 1]
        inside = (px >= 0) & (px <= W - 1) & (py >= 0) & (py <= H - 1)
        hidden = inside & ~clip.visibility  # occluded, not merely out of the frame
        assert hidden.sum() > 0 and p["occluded_fraction"] > 0.0
        assert hidden[:, clip.layer == 0].any()  # the background is occluded by objects
        leaving = []
        for i, o in enumerate(p["objects"], start=1):
            sel = clip.layer == i
            assert sel.sum() == o["ref_pixels"]
            out = ~inside[:, sel]
            leaving.append(bool(out.any()))
            assert leaving[-1] == o["leaves_frame"]
            if o["leaves_frame"]:
                # visibility follows the image bound: inside at ref, outside later/earlier
                assert not out[clip.ref].any()
                assert (~clip.visibility[:, sel][out]).all()
        assert any(leaving), family
        assert any(o["planned_crossing"] and o["leaves_frame"] for o in p["objects"])
        # background and objects come from different photographs
        sources = [photo_textures.photo_source(n) for n in p["photos"]]
        assert len(set(sources)) == len(sources)


# --------------------------------------------------------------------------- rendering


@pytest.mark.parametrize("family", ["affine", "nonrigid"])
def test_trajectories_match_the_rendering(clips, family):
    clip = clips[family]
    for n in (0, F // 4, F - 1):
        err, coverage = _warp_error(clip, n)
        assert coverage > 0.3
        assert err < 0.02, (n, err)
        for delta in ((1.0, 0.0), (0.0, -1.0)):
            wrong, _ = _warp_error(clip, n, delta)
            assert wrong > 2.5 * err, (n, err, wrong)


def test_sampler_equals_map_coordinates():
    rng = np.random.default_rng(0)
    for name, tint in (("coffee", None), ("camera", np.array([1.05, 0.98, 0.97]))):
        tex = photo_textures.PhotoTexture(name, 3, (10.0, 20.0), 1.5, tint)
        h, w = tex.shape
        coords = np.stack([rng.uniform(0, h - 1, 500), rng.uniform(0, w - 1, 500)])
        got = tex.sample(coords)[..., :3]
        img = photo.load_photo(name)
        planes = [img[..., c] for c in range(3)] if img.ndim == 3 else [img] * 3
        ref = np.stack([map_coordinates(pl, coords, order=1, mode="reflect") for pl in planes], -1)
        if tint is not None:
            ref = np.clip(ref * tint, 0, 1)
        assert np.abs(got - ref).max() < 1e-6


def _flat_render(layers, s: int) -> np.ndarray:
    """Render with the background black and every object white: the coverage fraction."""

    class Flat:
        def __init__(self, value, depth):
            self.value, self.depth = value, depth

        def __call__(self, px, py):
            return np.full(np.shape(px) + (self.depth,), self.value, np.float32)

        def affine_coords(self, motion, n, xs, ys):
            return np.zeros((2, ys.size, xs.size))

        def sample(self, coords):
            return self(coords[0], coords[1])

    flat = [
        photo_scenes.PhotoLayer(layer.motion, Flat(float(i > 0), 4), layer.shape)
        for i, layer in enumerate(layers)
    ]
    return photo_render.render(flat, SHAPE, F, 3, s)[..., 0]


def test_antialiased_object_boundaries():
    layers, params, *_ = photo._scene("objects", 1, F, SHAPE, None, 3)
    cov4 = _flat_render(layers, 4)
    cov1 = _flat_render(layers, 1)
    # point sampling: every pixel is one surface; area sampling: mixed pixels at edges
    assert np.all((cov1 == 0) | (cov1 == 1))
    mixed = (cov4 > 0.01) & (cov4 < 0.99)
    assert mixed.sum() > 50
    # mixed pixels sit on the outline: a neighbour differs in the point-sampled render
    pad = np.pad(cov1, ((0, 0), (1, 1), (1, 1)), mode="edge")
    edge = np.zeros_like(cov1, bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            edge |= pad[:, 1 + dy : 1 + dy + H, 1 + dx : 1 + dx + W] != cov1
    assert mixed[~edge].sum() <= 0.02 * mixed.sum()  # (a corner may graze a pixel)
    # where point sampling jumps between neighbours, area sampling mixes one of them
    jump_x = cov1[:, :, 1:] != cov1[:, :, :-1]
    jump_y = cov1[:, 1:] != cov1[:, :-1]
    either_x = (mixed[:, :, 1:] | mixed[:, :, :-1])[jump_x]
    either_y = (mixed[:, 1:] | mixed[:, :-1])[jump_y]
    assert np.concatenate([either_x, either_y]).mean() > 0.9
    # the same object area (to within the boundary pixels)
    assert abs(cov4.sum() - cov1.sum()) < 0.5 * edge.sum()
    # real rendering: at mixed pixels the value lies between the two layers' own renderings
    frames = photo_render.render(layers, SHAPE, F, 3, 4)
    back = photo_render.render(layers[:1], SHAPE, F, 3, 4)
    obj_only = []
    for i in range(1, len(layers)):
        full = photo_scenes.PhotoLayer(layers[i].motion, layers[i].texture, None)
        obj_only.append(photo_render.render([full], SHAPE, F, 3, 4))
    # pixels mixing the background and exactly one object (no other object nearby)
    between = []
    for i, obj in enumerate(obj_only, start=1):
        one = _flat_render([layers[0], layers[i]], 4)
        others = np.zeros_like(one)
        for j in range(1, len(layers)):
            if j != i:
                others += _flat_render([layers[0], layers[j]], 4)
        sel = (one > 0.2) & (one < 0.8) & (others == 0)
        contrast = np.abs(obj - back) > 0.15  # per channel
        sel = sel[..., None] & contrast
        lo, hi = np.minimum(obj, back), np.maximum(obj, back)
        margin = 0.1 * (hi - lo)
        between.append(((frames > lo + margin) & (frames < hi - margin))[sel])
    between = np.concatenate(between)
    assert between.size > 30
    assert between.mean() > 0.8


def test_illumination_is_a_smooth_gain(clips):
    clip = clips["illumination"]
    ill = clip.params["illumination"]
    gain, offset, grad, c = ill["gain"], ill["offset"], ill["gradient"], ill["centre"]
    assert 0.8 <= gain.min() and gain.max() <= 1.25
    assert gain.max() / gain.min() > 1.08  # the light changes over the clip
    xx, yy = _grid()
    for n in range(F):
        field = gain[n] * np.exp(grad[n, 0] * (xx - c[0]) + grad[n, 1] * (yy - c[1]))
        expected = np.clip(field[..., None] * clip.clean_frames[n] + offset[n], 0, 1)
        assert np.abs(clip.frames[n] - expected).max() < 1e-5
        # from the data alone: the log-ratio is a plane in x (smooth gain), off the clipped
        ok = (clip.clean_frames[n] > 0.15) & (clip.frames[n] < 0.99) & (clip.frames[n] > 0.01)
        ratio = (clip.frames[n] - offset[n]) / clip.clean_frames[n]
        lr = np.log(ratio[ok])
        xs = np.broadcast_to(xx[..., None], ok.shape)[ok]
        ys = np.broadcast_to(yy[..., None], ok.shape)[ok]
        design = np.stack([np.ones_like(xs), xs, ys], -1)
        coef, *_ = np.linalg.lstsq(design, lr, rcond=None)
        assert np.abs(design @ coef - lr).max() < 1e-3
        np.testing.assert_allclose(coef[1:], grad[n], atol=1e-4)
    assert np.abs(clip.frames - clip.clean_frames).mean() > 0.01
    # the gain gradient turns over the clip
    ang = np.arctan2(grad[:, 1], grad[:, 0])
    assert np.abs(np.angle(np.exp(1j * (ang[-1] - ang[0])))) > 0.3


def test_noise_level(clips):
    clip = clips["noise"]
    sigma = clip.params["noise"]["sigma"]
    assert 0.01 <= sigma <= 0.03
    clean = clip.clean_frames
    ok = (clean > 0.1) & (clean < 0.9)
    resid = (clip.frames - clean)[ok]
    scaled = resid / (0.6 + 0.8 * clean[ok])
    assert scaled.std() == pytest.approx(sigma, rel=0.05)
    assert abs(scaled.mean()) < 0.1 * sigma
    # noise on the reference frame too, and it grows with the intensity
    assert np.abs(clip.frames[clip.ref] - clean[clip.ref]).mean() > 0.5 * sigma
    dark = (clean > 0.1) & (clean < 0.3)
    bright = (clean > 0.7) & (clean < 0.9)
    assert (clip.frames - clean)[bright].std() > 1.3 * (clip.frames - clean)[dark].std()


# --------------------------------------------------------------------------- motion


def test_default_size_magnitude_and_steps():
    """One clip at the default size, rendered; the motion of every suite clip."""
    clip = make_photo_clip("objects", seed=REPORTING_SEEDS[0])
    assert clip.frames.shape == (31, 192, 256, 3)
    p = clip.params
    assert 30.0 <= p["magnitude"] <= 50.0
    bg = clip.layer == 0
    disp = np.hypot(clip.trajectories[..., 0], clip.trajectories[..., 1])
    assert disp[:, bg].max() == pytest.approx(p["magnitude"], rel=1e-3)
    assert p["max_displacement"] >= 30.0
    steps = np.hypot(*np.moveaxis(np.diff(clip.trajectories, axis=0), -1, 0))
    assert steps.max() <= 6.0
    # not constant velocity: the per-frame steps of the background vary along the clip
    bg_steps = steps[:, bg].mean(axis=1)
    assert bg_steps.max() > 1.2 * bg_steps.min()


def test_suite_motion_bounds(monkeypatch):
    """Every clip of both splits at the default size: >= 30 px of motion, steps <= 6 px."""

    def no_render(layers, shape, n_frames, channels, s):  # the motion only
        return np.zeros((n_frames, *shape, channels), np.float32)

    monkeypatch.setattr(photo, "render", no_render)
    for split in SPLITS:
        for family, seed in photo_cases(split):
            p = make_photo_clip(family, seed=seed).params
            assert p["max_displacement"] >= 30.0, (family, seed)
            assert p["max_step"] <= 6.0, (family, seed)
            assert p["photo_scale"] >= 1.2, (family, seed)
            assert p["occluded_fraction"] > 0.0


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"family": "flag"}, "family"),
        ({"shape": (16, 64)}, "shape"),
        ({"shape": (64,)}, "shape"),
        ({"shape": (64.5, 96)}, "shape"),
        ({"n_frames": 1}, "n_frames"),
        ({"n_frames": 61}, "n_frames"),
        ({"ref": 9}, "ref"),
        ({"channels": 2}, "channels"),
        ({"magnitude": -1.0}, "magnitude"),
        ({"supersample": 0}, "supersample"),
        ({"blur": -0.5}, "blur"),
        ({"seed": -1}, "seed"),
    ],
)
def test_invalid_arguments(kwargs, name):
    args = {"family": "affine", "n_frames": F, "shape": SHAPE, **kwargs}
    with pytest.raises(ValueError, match=rf"^{name}:"):
        make_photo_clip(**args)


def test_invalid_split_and_families():
    with pytest.raises(ValueError, match=r"^split:"):
        photo_cases("test")
    with pytest.raises(ValueError, match=r"^families:"):
        photo_cases("tuning", ["affine", "flag"])
    with pytest.raises(ValueError, match=r"^split:"):
        photo_suite("validation")  # checked at the call, before any clip is made
    with pytest.raises(ValueError, match=r"^families:"):
        photo_suite("tuning", families="affine")
    with pytest.raises(ValueError, match=r"^name:"):
        photo.load_photo("colorwheel")


def test_missing_scikit_image(monkeypatch):
    monkeypatch.setattr(photo_textures, "_PHOTO_CACHE", {})
    monkeypatch.setitem(sys.modules, "skimage", None)
    with pytest.raises(ImportError, match="pip install"):
        photo.load_photo("astronaut")
