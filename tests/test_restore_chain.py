"""The restoration chain (:mod:`varflow.restore.chain`) and the repair registry.

The clip: a smooth random texture translating by (1, 0.5) px per frame, 10 frames of
56 x 72 RGB, with dark and bright blotches planted on single frames.  The dirt stage
finds them with a wide margin here (recall 1 in the tests of :mod:`test_dirt`), so the
bounds below test the chain's plumbing: order, windows, scene cuts, dtypes.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import varflow
from varflow.registry import REPAIR, RESTORE
from varflow.restore.chain import STAGES, iter_restore, resolve_stages

H, W, N = 56, 72, 10

pytestmark = pytest.mark.usefixtures("one_numba_thread")


def _clip(seed: int = 0, n: int = N) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tex = ndimage.gaussian_filter(rng.random((H + 2 * n, W + 2 * n, 3)), (2.5, 2.5, 0))
    tex = (tex - tex.min()) / np.ptp(tex) * 180 + 40
    frames = [ndimage.shift(tex, (0.5 * k, 1.0 * k, 0), order=3, mode="reflect")
              for k in range(n)]
    return np.stack([f[n:n + H, n:n + W] for f in frames]).astype(np.float32)


def _blotches(clip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dirty, mask = clip.copy(), np.zeros(clip.shape[:3], bool)
    for f, (y, x, r, v) in {2: (20, 30, 4, 8.0), 5: (35, 50, 3, 250.0),
                            7: (12, 15, 5, 10.0)}.items():
        yy, xx = np.mgrid[:H, :W]
        disc = (yy - y) ** 2 + (xx - x) ** 2 <= r * r
        dirty[f][disc] = v
        mask[f] = disc
    return dirty, mask


def test_registry_lists_the_repair_stages_in_chain_order() -> None:
    assert list(REPAIR) == ["stabilise", "deflicker", "dirt"]
    assert [REPAIR[n].order for n in REPAIR] == [0, 1, 2]
    for name in REPAIR:
        entry = REPAIR[name]
        assert entry.context(entry.defaults()) >= 2
        assert REPAIR.make_params(name) == entry.defaults()
    with pytest.raises(ValueError, match="^bogus: not a parameter of repair stage 'dirt'"):
        REPAIR.make_params("dirt", bogus=1)
    with pytest.raises(ValueError, match="^window:"):
        REPAIR.make_params("deflicker", window=0)


def test_resolve_stages_orders_and_checks() -> None:
    chain = resolve_stages(["denoise", "dirt", "stabilise"], {"dirt": {"sensitivity": 2.0}},
                           denoise_method="nlbayes-fast")
    assert [n for n, _, _ in chain] == ["stabilise", "dirt", "denoise"]
    assert chain[1][2].sensitivity == 2.0
    assert chain[2][1] is RESTORE["nlbayes-fast"]
    assert [n for n, _, _ in resolve_stages()] == list(STAGES)
    with pytest.raises(ValueError, match="^stages: unknown stage 'dust'"):
        resolve_stages(["dust"])
    with pytest.raises(ValueError, match="^stages: each stage once"):
        resolve_stages(["dirt", "dirt"])
    with pytest.raises(ValueError, match="^stages: name at least one"):
        resolve_stages([])
    with pytest.raises(ValueError, match="^params: deflicker not in the chain"):
        resolve_stages(["dirt"], {"deflicker": {}})
    with pytest.raises(ValueError, match="^sensitivity:"):
        resolve_stages(["dirt"], {"dirt": {"sensitivity": -1.0}})


def test_dirt_through_the_chain_finds_and_fills_the_blotches() -> None:
    clean = _clip()
    dirty, truth = _blotches(clean)
    u8 = np.clip(np.rint(dirty), 0, 255).astype(np.uint8)
    out, mask = varflow.restore_clip(u8, ["dirt"], return_mask=True)
    assert out.dtype == np.uint8 and out.shape == u8.shape and mask.shape == truth.shape
    inner = ndimage.binary_erosion(truth, np.ones((1, 3, 3), bool))
    assert mask[inner].all()
    assert (mask & ~ndimage.binary_dilation(truth, np.ones((1, 7, 7), bool))).sum() == 0
    assert np.array_equal(out[~mask], u8[~mask])  # the rest is the input's bytes
    err = np.abs(out.astype(np.float64) - clean)[truth]
    assert err.mean() < 6.0, err.mean()


def test_streamed_windows_match_the_whole_clip() -> None:
    clean = _clip(n=14)
    dirty, _ = _blotches(clean)
    whole = varflow.restore_clip(dirty, ["dirt"])
    st: dict = {}
    streamed = np.stack([f for f, _ in iter_restore(iter(list(dirty)), ["dirt"], chunk=2,
                                                    stats=st)])
    # windows of 2 frames with the stage's 3 frames of context each side
    assert st["frames"] == 14 and st["seconds"]["dirt"] > 0
    differ = np.abs(streamed - whole) > 0.5
    assert differ.mean() < 1e-3, differ.mean()


def test_grey_uint16_keeps_dtype_and_shape() -> None:
    clean = _clip().mean(axis=-1)
    dirty = (clean * 257).astype(np.uint16)
    dirty[4, 20:26, 20:26] = 300
    out, mask = varflow.restore_clip(dirty, ["dirt", "deflicker"], return_mask=True)
    assert out.dtype == np.uint16 and out.shape == dirty.shape
    assert mask[4, 21:25, 21:25].all()
    assert np.abs(out[4, 21:25, 21:25].astype(float) / 257 - clean[4, 21:25, 21:25]).max() < 12


def test_no_stage_looks_across_a_scene_cut() -> None:
    a, b = _clip(seed=1, n=6), _clip(seed=2, n=6) * 0.4 + 20  # means about 130 and 72
    clip = np.concatenate([a, b])
    clip[6, 20:28, 30:38] = 5.0  # dirt on the first frame after the cut
    calls: list[int] = []

    def is_cut(f0: np.ndarray, f1: np.ndarray, **_: object) -> bool:
        calls.append(1)
        return abs(float(f0.mean()) - float(f1.mean())) > 15

    st: dict = {}
    out, mask = varflow.restore_clip(clip, ["dirt"], return_mask=True, is_cut=is_cut, stats=st)
    assert st["cuts"] == 1 and calls
    assert mask[6, 21:27, 31:37].all()
    # filled from its own scene (frames 7, 8 of b), not from a's frame 5
    assert np.abs(out[6, 21:27, 31:37] - b[0, 21:27, 31:37]).mean() < 6


def test_denoise_stage_is_varflow_denoise() -> None:
    clean = _clip(n=6)
    noisy = clean + np.random.default_rng(3).normal(0, 12, clean.shape).astype(np.float32)
    st: dict = {}
    out = varflow.restore_clip(noisy, ["denoise"], sigma=12.0,
                               params={"denoise": {"radius": 1}}, stats=st)
    ref = varflow.denoise(noisy, 12.0, radius=1)
    np.testing.assert_allclose(out, ref, atol=1e-3)
    assert st["sigma"] == pytest.approx(12.0)


def test_bad_frames_raise_named_errors() -> None:
    clip = _clip(n=4)
    with pytest.raises(ValueError, match="^frame 2: contains NaN"):
        bad = clip.copy()
        bad[2, 0, 0, 0] = np.nan
        varflow.restore_clip(bad, ["dirt"])
    with pytest.raises(ValueError, match="^frame 1: shape"):
        varflow.restore_clip([clip[0], clip[1, :10]], ["dirt"])
    with pytest.raises(ValueError, match="^frames: expected frames"):
        varflow.restore_clip(np.zeros((3, 4, 4), np.float32), ["dirt"])
    with pytest.raises(ValueError, match="^chunk:"):
        list(iter_restore(iter(list(clip)), ["dirt"], chunk=0))


def test_pair_flows_are_estimated_once_per_pair() -> None:
    """A stream in overlapping windows asks the stage for each consecutive pair's flows
    once, and deflicker's result stays close to the whole clip's run."""
    from varflow.evaluation.defects import plant_flicker

    clean = _clip(n=40)[:, :40, :48]
    flickered, _ = plant_flicker(clean, seed=5)
    entry = REPAIR["deflicker"]
    calls: list[int] = []
    original = entry.pair_flows

    def counted(a: np.ndarray, b: np.ndarray, p: object) -> object:
        calls.append(1)
        return original(a, b, p)

    object.__setattr__(entry, "pair_flows", counted)  # the entry is a frozen dataclass
    try:
        st: dict = {}
        # window 4: a context of 14 frames, so 40 frames make overlapping windows
        streamed = np.stack([f for f, _ in iter_restore(
            iter(list(flickered)), ["deflicker"], params={"deflicker": {"window": 4}},
            chunk=4, stats=st)])
    finally:
        object.__setattr__(entry, "pair_flows", original)
    assert len(calls) == 39  # 40 frames, one scene: 39 pairs
    whole = varflow.restore_clip(flickered, ["deflicker"], params={"deflicker": {"window": 4}})
    diff = np.abs(streamed - whole)
    # the windows' own flicker-noise estimates move the smoothed brightness a little:
    # measured mean 0.13 grey levels (2.6 on the first frame, 0.05 in the middle)
    assert diff.mean() < 0.4, diff.mean()


def test_dirt_starts_from_the_deflicker_flows(flow_calls: list[int]) -> None:
    """After deflicker (which moves no pixel) the dirt stage takes its first flows
    from the frames: each consecutive pair is estimated twice by deflicker (both ways)
    and the dirt stage estimates only its refined flows; the blotches are found."""
    clean = _clip()
    dirty, truth = _blotches(clean)
    calls = flow_calls
    out, mask = varflow.restore_clip(dirty, ["deflicker", "dirt"], return_mask=True)
    # deflicker: 9 pairs both ways; dirt: its refined flows of 18 + 4 pairs
    assert len(calls) == 18 + 22, len(calls)
    inner = ndimage.binary_erosion(truth, np.ones((1, 3, 3), bool))
    assert mask[inner].all()
    assert (mask & ~ndimage.binary_dilation(truth, np.ones((1, 7, 7), bool))).sum() == 0
    calls.clear()
    varflow.restore_clip(dirty, ["stabilise", "dirt"])  # stabilise moves pixels: its
    n_stab = len(calls)                                  # flows are not passed on
    calls.clear()
    varflow.restore_clip(dirty, ["stabilise"])
    assert n_stab - len(calls) == 44
