"""The seeded archival-film defects of :mod:`varflow.evaluation.defects`.

Small synthetic clips (smooth gradients plus seeded texture, 96 x 128): determinism,
the dirt's coverage, dark/bright balance, exact mask, radii and no overlap between
consecutive frames; the flicker's normalised gains, offsets and smooth fields; the
weave's translations (recovered by phase correlation), matrices and residual; the
noise level; the order and seeds of :func:`plant_defects`; argument checking.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from varflow.evaluation.defects import (
    DefectResult,
    plant_defects,
    plant_dirt,
    plant_flicker,
    plant_noise,
    plant_weave,
    weave_residual,
)

F, H, W = 12, 96, 128


def _texture(rng: np.random.Generator, frames: int, h: int, w: int,
             sigma: float = 1.5) -> np.ndarray:
    """Seeded smooth noise ``(frames, h, w)`` of unit standard deviation."""
    tex = np.stack([cv2.GaussianBlur(rng.standard_normal((h, w)).astype(np.float32), (0, 0),
                                     sigma) for _ in range(frames)])
    return tex / tex.std()


def _clip(frames: int = F, h: int = H, w: int = W, colour: bool = True,
          seed: int = 0) -> np.ndarray:
    """A clean clip on 0-255: a gradient 70-190 plus texture (std 12); in colour the
    channels are the grey, the grey + 30 and the grey - 30."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    grey = 70 + 80 * x / w + 40 * y / h + 12 * _texture(rng, frames, h, w)
    if colour:
        grey = np.stack([grey, grey + 30, grey - 30], axis=-1)
    return grey.astype(np.float32)


def _components(mask: np.ndarray) -> list[np.ndarray]:
    """Boolean masks of the 8-connected components of a 2D mask."""
    n, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    return [labels == k for k in range(1, n)]


# --------------------------------------------------------------------------- determinism


STAGES = {
    "dirt": lambda c, s: plant_dirt(c, seed=s)[0],
    "flicker": lambda c, s: plant_flicker(c, seed=s)[0],
    "weave": lambda c, s: plant_weave(c, seed=s)[0],
    "noise": lambda c, s: plant_noise(c, seed=s),
    "all": lambda c, s: plant_defects(c, seed=s)[0],
}


@pytest.mark.parametrize("name", sorted(STAGES))
def test_same_seed_same_bytes_other_seed_other_bytes(name: str) -> None:
    clip = _clip()
    run = STAGES[name]
    first, again, other = run(clip, 3), run(clip, 3), run(clip, 4)
    assert first.tobytes() == again.tobytes()
    assert first.tobytes() != other.tobytes()
    assert np.abs(first - other).max() > 1.0


def test_plant_defects_is_deterministic_in_all_its_outputs() -> None:
    clip = _clip()
    (a, ra), (b, rb) = plant_defects(clip, seed=7), plant_defects(clip, seed=7)
    assert a.tobytes() == b.tobytes()
    assert ra.dirt_mask.tobytes() == rb.dirt_mask.tobytes()
    assert ra.weave.matrices.tobytes() == rb.weave.matrices.tobytes()
    assert ra.flicker.fields.tobytes() == rb.flicker.fields.tobytes()
    assert ra.seeds == rb.seeds
    _, rc = plant_defects(clip, seed=8)
    assert rc.seeds != ra.seeds
    assert not np.array_equal(rc.dirt_mask, ra.dirt_mask)


def test_the_input_is_not_modified() -> None:
    clip = _clip()
    before = clip.copy()
    for name in STAGES:
        STAGES[name](clip, 0)
    assert np.array_equal(clip, before)


@pytest.mark.parametrize("colour", [False, True])
@pytest.mark.parametrize("name", sorted(STAGES))
def test_shape_and_dtype_are_kept(name: str, colour: bool) -> None:
    clip = _clip(frames=3, colour=colour)
    out = STAGES[name](clip, 0)
    assert out.shape == clip.shape and out.dtype == np.float32
    out8 = STAGES[name](np.clip(clip, 0, 255).astype(np.uint8), 0)
    assert out8.shape == clip.shape and out8.dtype == np.float32


def test_a_clip_of_many_channels_is_woven_channel_by_channel() -> None:
    grey = _clip(frames=2, colour=False)
    clip = np.repeat(grey[..., None], 6, axis=-1)
    woven, _ = plant_weave(clip, seed=1)
    woven_grey, _ = plant_weave(grey, seed=1)
    assert woven.shape == clip.shape
    for k in range(6):
        assert np.array_equal(woven[..., k], woven_grey)


# --------------------------------------------------------------------------- dirt


@pytest.mark.parametrize("coverage", [(0.003, 0.01), (0.02, 0.03)])
def test_dirt_covers_each_frame_within_the_range(coverage: tuple[float, float]) -> None:
    _, mask = plant_dirt(_clip(), seed=1, coverage=coverage)
    per_frame = mask.mean(axis=(1, 2))
    assert per_frame.min() >= coverage[0] and per_frame.max() <= coverage[1], per_frame
    # The targets are drawn in the range, not all at one end of it.
    assert per_frame.max() - per_frame.min() > 0.2 * (coverage[1] - coverage[0])


@pytest.mark.parametrize("colour", [False, True])
def test_the_mask_is_exactly_the_pixels_changed_by_8_levels(colour: bool) -> None:
    clip = _clip(colour=colour)
    dirty, mask = plant_dirt(clip, seed=2)
    assert mask.shape == (F, H, W) and mask.dtype == bool
    diff = np.abs(dirty - clip)
    changed = (diff >= 8.0) if not colour else (diff >= 8.0).any(axis=-1)
    assert np.array_equal(mask, changed)
    assert mask.any(axis=(1, 2)).all()
    # Outside the mask the picture moved by less than the threshold (soft rims only).
    assert diff[~mask].max() < 8.0
    # A coarser threshold gives the mask of that threshold.
    dirty20, mask20 = plant_dirt(clip, seed=2, threshold=20.0)
    diff20 = np.abs(dirty20 - clip)
    assert np.array_equal(mask20, (diff20 >= 20.0) if not colour
                          else (diff20 >= 20.0).any(axis=-1))


def test_dirt_is_never_where_the_previous_frame_had_dirt() -> None:
    # At 5-8 % coverage, independent placement would overlap in most frame pairs.
    _, mask = plant_dirt(_clip(), seed=3, coverage=(0.05, 0.08))
    overlap = (mask[1:] & mask[:-1]).sum(axis=(1, 2))
    assert overlap.tolist() == [0] * (F - 1)
    _, mask = plant_dirt(_clip(), seed=3)
    assert not (mask[1:] & mask[:-1]).any()


def _blotch_signs(dirty: np.ndarray, clean: np.ndarray, mask: np.ndarray) -> list[bool]:
    """For each component of each frame's mask, whether the dirt darkened it."""
    return [bool((dirty[f][comp] - clean[f][comp]).mean() < 0)
            for f in range(mask.shape[0]) for comp in _components(mask[f])]


def test_about_70_percent_of_the_blotches_are_dark() -> None:
    clip = _clip(frames=60, colour=False, seed=4)
    dirty, mask = plant_dirt(clip, seed=5)
    dark = _blotch_signs(dirty, clip, mask)
    assert len(dark) >= 80
    assert 0.55 <= np.mean(dark) <= 0.85, (np.mean(dark), len(dark))


@pytest.mark.parametrize("fraction", [0.0, 1.0])
def test_dark_fraction_0_and_1_give_only_bright_or_only_dark_blotches(fraction: float) -> None:
    clip = _clip(frames=6, colour=False)
    dirty, mask = plant_dirt(clip, seed=6, dark_fraction=fraction)
    dark = _blotch_signs(dirty, clip, mask)
    assert dark and all(d == bool(fraction) for d in dark)
    # Dark blotches reach levels at most 60, bright ones at least 200.
    for f in range(6):
        for comp in _components(mask[f]):
            if fraction:
                assert dirty[f][comp].min() <= 60.0 + 0.15 * 255
            else:
                assert dirty[f][comp].max() >= 200.0 - 0.15 * 255
    levels = dirty[mask]
    if fraction:
        assert np.median(levels) < 75.0
    else:
        assert np.median(levels) > 185.0


def test_a_blotch_is_the_same_grey_on_every_channel() -> None:
    clip = _clip(colour=True)  # channels 30 levels apart
    dirty, mask = plant_dirt(clip, seed=7)
    spread_clean = (clip[..., 1] - clip[..., 2])[mask]  # 60 everywhere
    spread_dirty = (dirty[..., 1] - dirty[..., 2])[mask]
    ratio = spread_dirty / spread_clean
    # out = (1 - a) clean + a grey: the channel spread shrinks by the opacity a.
    assert ratio.min() >= -1e-4 and ratio.max() <= 1.0 + 1e-4
    assert np.median(ratio) <= 0.3


@pytest.mark.parametrize("radius", [(3.0, 20.0), (3.0, 4.0)])
def test_blotch_radii_stay_in_the_range(radius: tuple[float, float]) -> None:
    clip = _clip(frames=30, colour=False, seed=8)
    _, mask = plant_dirt(clip, seed=9, radius=radius, coverage=(0.05, 0.08))
    radii = np.array([np.sqrt(comp.sum() / np.pi)
                      for f in range(mask.shape[0]) for comp in _components(mask[f])])
    assert radii.max() <= 1.3 * radius[1], radii.max()
    if radius[1] >= 20:
        assert radii.max() >= 12.0  # not only specks
    extent = [max(np.ptp(np.nonzero(comp)[0]), np.ptp(np.nonzero(comp)[1])) + 1
              for f in range(mask.shape[0]) for comp in _components(mask[f])]
    assert max(extent) <= 2 * 1.3 * radius[1] + 1


# --------------------------------------------------------------------------- flicker


def test_flicker_gains_offsets_and_fields() -> None:
    clip = _clip()
    out, p = plant_flicker(clip, seed=1)
    assert p.gains.shape == (F,) and p.offsets.shape == (F,) and p.fields.shape == (F, H, W)
    assert abs(p.gains.mean() - 1.0) < 1e-6
    assert abs(p.offsets.mean()) < 1e-6
    # Drawn in 0.75-1.25 then divided by their mean (itself in 0.75-1.25).
    assert p.gains.min() >= 0.75 / 1.25 and p.gains.max() <= 1.25 / 0.75
    assert p.gains.std() > 0.05
    assert np.abs(p.offsets).max() <= 30.0 and np.abs(p.offsets).max() > 3.0
    deviation = np.abs(p.fields - 1.0).max(axis=(1, 2))
    assert deviation.max() <= 0.15 + 1e-6 and deviation.min() >= 0.15 - 1e-4
    assert np.abs(p.fields.mean(axis=(1, 2)) - 1.0).max() < 1e-4
    # Smooth: neighbouring pixels differ by at most 2 % (white noise would be ~30 %).
    step = max(np.abs(np.diff(p.fields, axis=1)).max(), np.abs(np.diff(p.fields, axis=2)).max())
    assert step < 0.02
    # Independent between frames.
    a, b = p.fields[0].ravel() - 1, p.fields[1].ravel() - 1
    assert abs(np.dot(a, b)) / (np.linalg.norm(a) * np.linalg.norm(b)) < 0.999
    expected = (p.fields[..., None] * p.gains[:, None, None, None] * clip
                + p.offsets[:, None, None, None])
    assert np.abs(out - expected).max() < 1e-3


def test_flicker_without_gain_range_offset_or_field_is_the_identity() -> None:
    clip = _clip(frames=4, colour=False)
    out, p = plant_flicker(clip, seed=2, gain=(1.0, 1.0), offset=0.0, local=0.0)
    assert np.all(p.gains == 1.0) and np.all(p.offsets == 0.0) and np.all(p.fields == 1.0)
    assert np.array_equal(out, clip)


def test_one_frame_flicker_keeps_only_the_field() -> None:
    _, p = plant_flicker(_clip(frames=1), seed=3)
    assert p.gains.tolist() == [1.0] and p.offsets.tolist() == [0.0]


# --------------------------------------------------------------------------- weave


def _phase_shift(a: np.ndarray, b: np.ndarray, iterations: int = 2) -> np.ndarray:
    """Translation ``(dx, dy)`` of ``b`` relative to ``a`` by phase correlation, refined
    by correlating again after undoing the estimate (the sub-pixel peak of
    cv2.phaseCorrelate is biased by up to ~0.4 px; the bias vanishes as the shift does)."""
    h, w = a.shape
    win = cv2.createHanningWindow((w, h), cv2.CV_64F)
    a, b = a.astype(np.float64), b.astype(np.float64)
    d = np.array(cv2.phaseCorrelate(a, b, win)[0])
    for _ in range(iterations):
        back = cv2.warpAffine(b, np.float64([[1, 0, -d[0]], [0, 1, -d[1]]]), (w, h),
                              flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
        d = d + np.array(cv2.phaseCorrelate(a, back, win)[0])
    return d


def test_phase_correlation_recovers_the_drawn_translation() -> None:
    clip = _clip(colour=False)
    woven, p = plant_weave(clip, seed=1, angle=0.0)
    assert np.all(p.angle == 0.0)
    assert np.abs(p.dx).max() <= 4.0 and np.abs(p.dy).max() <= 4.0
    assert np.abs(p.dx).max() > 2.0 and np.abs(p.dy).max() > 2.0
    found = np.array([_phase_shift(clip[f], woven[f]) for f in range(F)])
    assert np.abs(found - np.stack([p.dx, p.dy], axis=1)).max() < 0.3
    # The residual of that estimate is small; of no correction, the weave itself.
    assert weave_residual(found, p).max() < 0.3
    assert np.allclose(weave_residual(None, p), np.hypot(p.dx, p.dy))
    assert np.allclose(weave_residual(p.matrices, p), 0.0)


def test_the_matrices_map_clean_points_to_their_woven_place() -> None:
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    points = [(20.3, 15.7), (100.0, 80.2), (64.0, 48.0), (10.0, 85.0)]
    frame = sum(np.exp(-((x - px) ** 2 + (y - py) ** 2) / 8.0) for px, py in points) * 200
    clip = np.repeat(frame[None].astype(np.float32), 4, axis=0)
    woven, p = plant_weave(clip, seed=2, shift=4.0, angle=3.0, border="constant")
    assert np.abs(p.angle).max() <= 3.0 and np.abs(p.angle).max() > 1.0
    for f in range(4):
        for px, py in points:
            qx, qy = p.matrices[f] @ np.array([px, py, 1.0])
            near = np.hypot(x - qx, y - qy) < 8
            img = woven[f] * near
            assert abs((img * x).sum() / img.sum() - qx) < 0.1
            assert abs((img * y).sum() / img.sum() - qy) < 0.1
        # The centre only moves by the translation; a positive angle turns the picture
        # counter-clockwise on screen (y down): a point right of the centre goes up.
        centre = np.array([(W - 1) / 2, (H - 1) / 2, 1.0])
        cx, cy = p.matrices[f] @ centre
        assert np.allclose([cx - centre[0], cy - centre[1]], [p.dx[f], p.dy[f]])
        rx, ry = p.matrices[f] @ (centre + [10.0, 0.0, 0.0]) - [cx, cy]
        theta = np.deg2rad(p.angle[f])
        assert np.allclose([rx, ry], [10 * np.cos(theta), -10 * np.sin(theta)])


def test_weave_residual_is_the_rms_displacement_over_the_pixels() -> None:
    _, p = plant_weave(_clip(frames=3), seed=3)
    rng = np.random.default_rng(0)
    est = p.matrices + rng.normal(0, [[1e-3, 1e-3, 0.5]], (3, 2, 3))
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    pts = np.stack([x.ravel(), y.ravel(), np.ones(H * W)])
    brute = [np.sqrt((((p.matrices[f] - est[f]) @ pts) ** 2).sum(axis=0).mean())
             for f in range(3)]
    assert np.allclose(weave_residual(est, p), brute, rtol=1e-9)
    with pytest.raises(ValueError, match="estimate"):
        weave_residual(np.zeros((2, 2)), p)


def test_no_weave_is_the_identity() -> None:
    clip = _clip(frames=3)
    out, p = plant_weave(clip, seed=0, shift=0.0, angle=0.0)
    assert np.array_equal(out, clip)
    assert np.allclose(weave_residual(None, p), 0.0)


# --------------------------------------------------------------------------- noise


def test_noise_has_the_requested_level() -> None:
    clip = _clip()
    noisy = plant_noise(clip, sigma=3.0, seed=1)
    diff = (noisy - clip).astype(np.float64)
    assert abs(diff.std() - 3.0) < 0.05 and abs(diff.mean()) < 0.05
    assert np.array_equal(plant_noise(clip, sigma=0.0), clip)


# --------------------------------------------------------------------------- together


def test_plant_defects_is_weave_then_flicker_then_dirt_then_noise() -> None:
    clip = _clip()
    out, r = plant_defects(clip, seed=11)
    assert isinstance(r, DefectResult)
    assert set(r.seeds) == {"weave", "flicker", "dirt", "noise"}
    assert len(set(r.seeds.values())) == 4
    woven, pw = plant_weave(clip, seed=r.seeds["weave"])
    flick, pf = plant_flicker(woven, seed=r.seeds["flicker"])
    dirty, mask = plant_dirt(flick, seed=r.seeds["dirt"])
    noisy = plant_noise(dirty, sigma=3.0, seed=r.seeds["noise"])
    assert out.tobytes() == noisy.tobytes()
    assert r.before_dirt.tobytes() == flick.tobytes()
    assert np.array_equal(r.dirt_mask, mask)
    assert np.array_equal(r.weave.matrices, pw.matrices)
    assert np.array_equal(r.flicker.gains, pf.gains)
    assert r.noise_sigma == 3.0


def test_plant_defects_mask_is_against_the_clip_after_weave_and_flicker() -> None:
    clip = _clip()
    out, r = plant_defects(clip, seed=12, noise=0.0)
    assert np.array_equal(r.dirt_mask, (np.abs(out - r.before_dirt) >= 8.0).any(axis=-1))
    frac = r.dirt_mask.mean(axis=(1, 2))
    assert frac.min() >= 0.003 and frac.max() <= 0.01


def test_plant_defects_stages_can_be_switched_off_or_configured() -> None:
    clip = _clip(frames=4, colour=False)
    out, r = plant_defects(clip, seed=1, dirt=False, flicker=False, weave=False, noise=None)
    assert np.array_equal(out, clip)
    assert r.weave is None and r.flicker is None and r.noise_sigma == 0.0
    assert r.dirt_mask.shape == (4, H, W) and not r.dirt_mask.any()
    _, r = plant_defects(clip, seed=1, dirt={"coverage": (0.02, 0.03)}, flicker=False,
                         weave={"shift": 1.0, "angle": 0.0}, noise=0.0)
    frac = r.dirt_mask.mean(axis=(1, 2))
    assert frac.min() >= 0.02 and frac.max() <= 0.03
    assert np.abs(r.weave.dx).max() <= 1.0 and np.all(r.weave.angle == 0.0)


# --------------------------------------------------------------------------- arguments


BAD = [
    (lambda c: plant_dirt(c, coverage=(-0.01, 0.01)), "coverage"),
    (lambda c: plant_dirt(c, coverage=(0.5, 1.5)), "coverage"),
    (lambda c: plant_dirt(c, coverage=(0.02, 0.01)), "coverage"),
    (lambda c: plant_dirt(c, coverage=0.01), "coverage"),
    (lambda c: plant_dirt(c, radius=(-3, 20)), "radius"),
    (lambda c: plant_dirt(c, radius=(0, 20)), "radius"),
    (lambda c: plant_dirt(c, dark_fraction=1.2), "dark_fraction"),
    (lambda c: plant_dirt(c, threshold=0.0), "threshold"),
    (lambda c: plant_dirt(c, seed=-1), "seed"),
    (lambda c: plant_dirt(c, seed=1.5), "seed"),
    (lambda c: plant_dirt(c[None]), "clip"),
    (lambda c: plant_dirt(c[0, ..., 0]), "clip"),
    (lambda c: plant_dirt(np.where(c > 100, np.nan, c)), "clip"),
    (lambda c: plant_flicker(c, gain=(0.0, 1.2)), "gain"),
    (lambda c: plant_flicker(c, gain=(1.2, 0.8)), "gain"),
    (lambda c: plant_flicker(c, offset=-1.0), "offset"),
    (lambda c: plant_flicker(c, local=1.0), "local"),
    (lambda c: plant_flicker(c, local=-0.1), "local"),
    (lambda c: plant_flicker(c[0, 0]), "clip"),
    (lambda c: plant_weave(c, shift=-1.0), "shift"),
    (lambda c: plant_weave(c, angle=float("nan")), "angle"),
    (lambda c: plant_weave(c, border="wrap"), "border"),
    (lambda c: plant_weave(c, interpolation="nearest"), "interpolation"),
    (lambda c: plant_noise(c, sigma=-1.0), "sigma"),
    (lambda c: plant_noise(c[..., 0, 0]), "clip"),
    (lambda c: plant_defects(c, noise=-3.0), "noise"),
    (lambda c: plant_defects(c, dirt="yes"), "dirt"),
    (lambda c: plant_defects(c, weave={"seed": 3}), "weave"),
    (lambda c: plant_defects(c, dirt={"coverage": (0.1, 2.0)}), "coverage"),
    (lambda c: plant_defects(c, seed=-2), "seed"),
]


@pytest.mark.parametrize("call,name", BAD)
def test_bad_arguments_raise_value_error_naming_them(call, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        call(_clip(frames=2))
