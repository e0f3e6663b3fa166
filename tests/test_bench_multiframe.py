"""Trajectory methods on real sequences: `varflow bench middlebury-multiframe`.

Most tests run on a small fake data folder written from a synthetic sequence (same
layout as the benchmark data, exact ground truth), so they need no data and take a
few seconds; the tests on the real RubberWhale / Sintel files use the ``data_root``
fixture (skipped without data, failed when ``VARFLOW_REQUIRE_DATA=1`` as in CI) and
carry the ``data`` marker.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from _problems import to_u8, wave_texture

from varflow import cli
from varflow.evaluation.bench import multiframe as bm
from varflow.generators.sequences import make_sequence
from varflow.io import write_flo, write_image

# The cheapest tracker settings: one warp, 5 iterations per level.
CHEAP = {"n_warps": 1, "max_iterations": 5}
CHEAP_FLAGS = ["--n-warps", "1", "--max-iterations", "5"]


def _write_rubberwhale(root: Path) -> None:
    """An 8-frame "RubberWhale" (frame07-frame14) with flow10.flo, under ``root``."""
    seq = make_sequence("affine", n_frames=8, shape=(48, 64), ref=3, magnitude=3.0, seed=2)
    d = root / "middlebury" / "other-data" / "RubberWhale"
    d.mkdir(parents=True)
    for i, n in enumerate(range(7, 15)):
        write_image(d / f"frame{n:02d}.png", to_u8(seq.frames[i]))
    gt = seq.trajectories[4] - seq.trajectories[3]
    gt[:4, :4] = 1e10  # unknown pixels, as in the real ground truth
    (root / "middlebury" / "other-gt-flow" / "RubberWhale").mkdir(parents=True)
    write_flo(root / "middlebury" / "other-gt-flow" / "RubberWhale" / "flow10.flo", gt)


@pytest.fixture(scope="module")
def fake_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data folder with an 8-frame "RubberWhale" and one 4-frame Sintel snippet."""
    root = tmp_path_factory.mktemp("data")
    _write_rubberwhale(root)
    s = make_sequence("affine", n_frames=4, shape=(40, 56), ref=1, magnitude=2.0, seed=3)
    tr = root / "sintel" / "training"
    for sub in ("clean/fake_1", "flow/fake_1", "occlusions/fake_1", "invalid/fake_1"):
        (tr / sub).mkdir(parents=True)
    for i, n in enumerate(range(1, 5)):
        write_image(tr / "clean" / "fake_1" / f"frame_{n:04d}.png", to_u8(s.frames[i]))
    write_flo(tr / "flow" / "fake_1" / "frame_0001.flo", s.trajectories[1] - s.trajectories[0])
    write_flo(tr / "flow" / "fake_1" / "frame_0002.flo", s.trajectories[2] - s.trajectories[1])
    occ = np.zeros((40, 56), np.uint8)
    occ[:, -6:] = 255
    write_image(tr / "occlusions" / "fake_1" / "frame_0002.png", occ)
    write_image(tr / "invalid" / "fake_1" / "frame_0002.png", np.zeros((40, 56), np.uint8))
    return root


# The fake alley_1: 20 frames of a smooth texture translating by ALLEY_V px per frame, so
# the ground-truth flow of every frame is exactly ALLEY_V everywhere.
ALLEY_FRAMES, ALLEY_SHAPE, ALLEY_V = 20, (48, 64), (0.8, -0.5)
ALLEY_GT = range(1, 11)  # frame_0001.flo ... frame_0010.flo, as on the real clip
ALLEY_MASKED = 6  # the frame with occlusion and invalid masks


@pytest.fixture(scope="module")
def alley_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data folder with a fake 20-frame final/alley_1 and the fake RubberWhale."""
    root = tmp_path_factory.mktemp("alley")
    _write_rubberwhale(root)
    tr = root / "sintel" / "training"
    for sub in ("final", "flow", "occlusions", "invalid"):
        (tr / sub / "alley_1").mkdir(parents=True)
    for n in range(1, ALLEY_FRAMES + 1):
        shift = ((n - 1) * ALLEY_V[0], (n - 1) * ALLEY_V[1])
        write_image(tr / "final" / "alley_1" / f"frame_{n:04d}.png",
                    wave_texture(ALLEY_SHAPE, shift))
    gt = np.empty(ALLEY_SHAPE + (2,), np.float32)
    gt[...] = ALLEY_V
    gt[-3:, -3:] = 1e10  # unknown pixels
    for n in ALLEY_GT:
        write_flo(tr / "flow" / "alley_1" / f"frame_{n:04d}.flo", gt)
    occ = np.zeros(ALLEY_SHAPE, np.uint8)
    occ[:, -6:] = 255
    inv = np.zeros(ALLEY_SHAPE, np.uint8)
    inv[:4, :4] = 255
    write_image(tr / "occlusions" / "alley_1" / f"frame_{ALLEY_MASKED:04d}.png", occ)
    write_image(tr / "invalid" / "alley_1" / f"frame_{ALLEY_MASKED:04d}.png", inv)
    return root


# ----------------------------------------------------------------------------- loaders


def test_fake_clip_loads(fake_root: Path) -> None:
    frames, ref, gt = bm.load_rubberwhale_clip(fake_root)
    assert frames.shape == (8, 48, 64, 3) and frames.dtype == np.uint8
    assert ref == 3 and gt.shape == (48, 64, 2) and gt.dtype == np.float32
    assert np.isnan(gt[:4, :4]).all() and np.isfinite(gt[4:]).all()


def test_sintel_snippet_prefers_the_pair_with_occlusion_mask(fake_root: Path) -> None:
    (s,) = bm.sintel_snippets(fake_root)
    assert (s.clip, s.pass_, s.numbers, s.ref) == ("fake_1", "clean", (1, 2, 3, 4), 1)
    assert s.name == "fake_1 0001-0004" and s.pair == "0002->0003"
    assert bm.sintel_snippets(fake_root, passes=("final",)) == []


def test_missing_data_message(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="frame07.*VARFLOW_DATA"):
        bm.load_rubberwhale_clip(tmp_path)
    with pytest.raises(FileNotFoundError, match="Sintel.*VARFLOW_DATA"):
        bm.run_sintel_multiframe(["twoframe"], root=tmp_path, progress=False)


@pytest.mark.data
def test_load_rubberwhale_clip(data_root: Path) -> None:
    frames, ref, gt = bm.load_rubberwhale_clip(data_root)
    assert frames.shape == (8, 388, 584, 3) and frames.dtype == np.uint8
    assert ref == 3
    assert gt.shape == (388, 584, 2) and gt.dtype == np.float32
    assert np.isnan(gt).any() and np.isfinite(gt).mean() > 0.9
    assert not np.array_equal(frames[0], frames[-1])


@pytest.mark.data
def test_real_sintel_snippets(data_root: Path) -> None:
    snippets = bm.sintel_snippets(data_root)
    assert snippets, "no Sintel snippets found"
    for s in snippets:
        assert len(s.numbers) == 4 and s.ref == 1  # frame N with masks, one frame before
    assert ("alley_1", "clean", (1, 2, 3, 4)) in {(s.clip, s.pass_, s.numbers) for s in snippets}


# ----------------------------------------------------------------------------- runners


def test_runner_rows_on_fake_clip(fake_root: Path) -> None:
    rows = bm.run_middlebury_multiframe(["twoframe", "chain"], CHEAP, progress=False,
                                        root=fake_root)
    assert [r["method"] for r in rows] == ["twoframe", "chain", bm.BASELINE_LABEL]
    for r in rows:
        assert r["dataset"] == "middlebury" and r["sequence"] == "RubberWhale"
        assert r["ref"] == 3 and r["frames"] == 8 and r["aee_noc"] is None
        assert math.isfinite(r["aee"]) and math.isfinite(r["aae"]) and r["seconds"] >= 0
        assert r["aee"] < 0.5, r  # a smooth 3 px affine motion is easy
    # twoframe's frame11 is the tvl1 pair flow (cheap settings vs default: close)
    assert abs(rows[0]["aee"] - rows[2]["aee"]) < 0.2


def test_overrides_reach_the_methods(fake_root: Path) -> None:
    with pytest.raises(ValueError, match="bogus"):
        bm.run_middlebury_multiframe(["twoframe"], {"bogus": 1}, root=fake_root)
    with pytest.raises(ValueError, match="unknown trajectory method"):
        bm.run_middlebury_multiframe(["nope"], root=fake_root)
    zero = bm.run_middlebury_multiframe(["twoframe"], {"max_iterations": 1, "n_warps": 1,
                                                       "max_levels": 1}, progress=False,
                                        root=fake_root, baseline=False, warm_up=False)
    cheap = bm.run_middlebury_multiframe(["twoframe"], CHEAP, progress=False, root=fake_root,
                                         baseline=False, warm_up=False)
    assert len(zero) == len(cheap) == 1 and zero[0]["aee"] != cheap[0]["aee"]


def test_sintel_runner_on_fake_snippet(fake_root: Path) -> None:
    rows = bm.run_sintel_multiframe(["twoframe"], CHEAP, progress=False, root=fake_root)
    assert [r["method"] for r in rows] == ["twoframe", bm.BASELINE_LABEL]
    for r in rows:
        assert r["dataset"] == "sintel-clean" and r["pair"] == "0002->0003" and r["ref"] == 1
        assert math.isfinite(r["aee"]) and math.isfinite(r["aee_noc"])


@pytest.mark.data
def test_runner_on_cropped_rubberwhale(data_root: Path) -> None:
    rows = bm.run_middlebury_multiframe(["twoframe"], CHEAP, progress=False, root=data_root,
                                        crop=(100, 228, 200, 360))
    assert [r["method"] for r in rows] == ["twoframe", bm.BASELINE_LABEL]
    for r in rows:
        assert math.isfinite(r["aee"]) and 0 < r["aee"] < 1.0, r


# ----------------------------------------------------------------------------- Table 4.1 protocol


def test_protocol_window_centred_shifted_and_whole() -> None:
    w = bm.protocol_window(10, 9, 1, 50)  # centred: 4 frames either side
    assert (w.first, w.last, w.length, w.n_frames, w.ref_index) == (6, 14, 9, 9, 4)
    assert w.label == "9: 0006-0014" and w.numbers == tuple(range(6, 15))
    # even lengths keep one frame more after r: L = 2 is the pair r, r + 1
    assert (bm.protocol_window(10, 2, 1, 50).first, bm.protocol_window(10, 2, 1, 50).last) \
        == (10, 11)
    assert bm.protocol_window(10, 4, 1, 50).label == "4: 0009-0012"
    # shifted inward at the clip's start and end
    assert bm.protocol_window(2, 9, 1, 50).label == "9: 0001-0009"
    assert bm.protocol_window(1, 13, 1, 50).label == "13: 0001-0013"
    assert bm.protocol_window(48, 9, 1, 50).label == "9: 0042-0050"
    assert bm.protocol_window(49, 19, 1, 50).label == "19: 0032-0050"
    assert bm.protocol_window(9, 3, 8, 11).label == "3: 0008-0010"  # a clip not from 1
    whole = bm.protocol_window(5, None, 1, 50)
    assert (whole.first, whole.last, whole.length, whole.ref_index) == (1, 50, None, 4)
    assert whole.label == "whole: 0001-0050"
    # every placement: inside the clip, of the asked length, holding r and r + 1, and
    # exactly centred whenever the clip allows
    for n in (2, 5, 12):
        for r in range(1, n):
            for length in range(2, n + 1):
                w = bm.protocol_window(r, length, 1, n)
                assert 1 <= w.first and w.last <= n and w.n_frames == length
                assert w.first <= r and r + 1 <= w.last
                lo = r - (length - 1) // 2
                if lo >= 1 and lo + length - 1 <= n:
                    assert w.first == lo


def test_protocol_window_errors() -> None:
    with pytest.raises(ValueError, match="at least 2 frames"):
        bm.protocol_window(5, 1, 1, 50)
    with pytest.raises(ValueError, match="exceeds the 50 frames"):
        bm.protocol_window(5, 51, 1, 50)
    for r in (0, 50, 51):
        with pytest.raises(ValueError, match=r"refs: .*1\.\.49"):
            bm.protocol_window(r, 9, 1, 50)
    with pytest.raises(ValueError, match="integer"):
        bm.protocol_window(True, 9, 1, 50)


def test_protocol_windows_defaults() -> None:
    labels = [w.label for w in bm.protocol_windows(5, bm.PROTOCOL_WINDOWS, 1, 50)]
    assert labels == ["9: 0001-0009", "13: 0001-0013", "19: 0001-0019", "whole: 0001-0050"]
    labels = [w.label for w in bm.protocol_windows(10, bm.PROTOCOL_WINDOWS, 1, 50)]
    assert labels == ["9: 0006-0014", "13: 0004-0016", "19: 0001-0019", "whole: 0001-0050"]
    assert [w.label for w in bm.protocol_windows(5, (9, 9), 1, 50, include_whole=False)] \
        == ["9: 0001-0009"]
    with pytest.raises(ValueError, match="at least one window"):
        bm.protocol_windows(5, (), 1, 50, include_whole=False)


def test_plan_on_fake_alley(alley_root: Path, tmp_path: Path) -> None:
    assert bm.sintel_clip_numbers(alley_root) == tuple(range(1, 21))
    plan = bm.plan_sintel_protocol(alley_root, refs=(5, 6, 5), windows=(3, 5))
    assert list(plan) == [5, 6]
    assert [w.label for w in plan[5]] == ["3: 0004-0006", "5: 0003-0007", "whole: 0001-0020"]
    for r, match in ((0, "needs frames 0 and 1"), (20, "needs frames 20 and 21"),
                     (12, r"no ground truth for reference frame 12.*0001-0010")):
        with pytest.raises(ValueError, match=match):
            bm.plan_sintel_protocol(alley_root, refs=(5, r))
    with pytest.raises(ValueError, match="at least 2 frames"):
        bm.plan_sintel_protocol(alley_root, windows=(9, 1))
    with pytest.raises(ValueError, match="exceeds the 20 frames"):
        bm.plan_sintel_protocol(alley_root, windows=(21,))
    with pytest.raises(FileNotFoundError, match="alley_1 frames not found.*VARFLOW_DATA"):
        bm.plan_sintel_protocol(tmp_path)


def test_crop_outside_the_frames(alley_root: Path) -> None:
    with pytest.raises(ValueError, match="crop.*exceeds the 64x48 frames of Sintel"):
        bm.run_sintel_trajectories(["twoframe"], root=alley_root, crop=(0, 60, 0, 32),
                                   progress=False, warm_up=False)
    with pytest.raises(ValueError, match="crop.*exceeds the 64x48 frames of Middlebury"):
        bm.run_middlebury_multiframe(["twoframe"], root=alley_root, crop=(0, 32, 0, 70),
                                     progress=False, warm_up=False)


def test_sintel_trajectories_rows_on_fake_alley(alley_root: Path) -> None:
    methods = [m for m in ("twoframe", "mfsf", "rlr") if m in bm.default_methods()]
    rows = bm.run_sintel_trajectories(methods, CHEAP, progress=False, root=alley_root,
                                      refs=(5, ALLEY_MASKED), windows=(3,))
    windows = {5: [("3: 0004-0006", 3, 1), ("whole: 0001-0020", 20, 4)],
               6: [("3: 0005-0007", 3, 1), ("whole: 0001-0020", 20, 5)]}
    expected = [(r, w, m) for r in (5, 6) for w in windows[r] for m in methods]
    assert [(r["ref"], (r["window"], r["frames"], r["ref_index"]), r["method"]) for r in rows] \
        == expected
    for r in rows:
        assert set(r) == {"dataset", "sequence", "ref", "pair", "window", "frames", "ref_index",
                          "method", "aee", "aae", "aee_noc", "seconds", "shared"}
        assert r["dataset"] == "sintel-final" and r["sequence"] == "alley_1"
        assert r["pair"] == f"{r['ref']:04d}->{r['ref'] + 1:04d}"
        assert r["shared"] is (r["method"] == "twoframe")
        assert math.isfinite(r["aee"]) and math.isfinite(r["aae"]) and r["seconds"] >= 0
        assert r["aee"] < 0.3, r  # a smooth translation of 0.94 px per frame
        if r["ref"] == ALLEY_MASKED:
            assert math.isfinite(r["aee_noc"])
        else:
            assert r["aee_noc"] is None


def test_twoframe_runs_once_per_reference(alley_root: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    import varflow

    calls: list[tuple[str, int, int]] = []
    track = varflow.track

    def counting(frames, ref, method, **kw):  # noqa: ANN001, ANN202 - a test double
        calls.append((method, len(frames), ref))
        return track(frames, ref, method, **kw)

    monkeypatch.setattr(varflow, "track", counting)
    rows = bm.run_sintel_trajectories(["twoframe", "mfsf"], CHEAP, progress=False,
                                      root=alley_root, refs=(5, 6), windows=(3, 5),
                                      warm_up=False)
    # twoframe: once per reference on the pair (r, r + 1); mfsf: once per window
    assert [c for c in calls if c[0] == "twoframe"] == [("twoframe", 2, 0)] * 2
    assert [c for c in calls if c[0] == "mfsf"] == [("mfsf", n, i) for n, i in
                                                    ((3, 1), (5, 2), (20, 4),
                                                     (3, 1), (5, 2), (20, 5))]
    for ref in (5, 6):
        mine = [r for r in rows if r["method"] == "twoframe" and r["ref"] == ref]
        assert len(mine) == 3 and all(r["shared"] for r in mine)
        assert len({(r["aee"], r["aae"], r["seconds"]) for r in mine}) == 1
        assert len({r["window"] for r in mine}) == 3
    assert not any(r["shared"] for r in rows if r["method"] == "mfsf")
    # the premise: twoframe's frame r + 1 on a window is the flow of the pair r, r + 1
    monkeypatch.setattr(varflow, "track", track)
    from varflow.io import read_image

    d = alley_root / "sintel" / "training" / "final" / "alley_1"
    frames = np.stack([read_image(d / f"frame_{n:04d}.png") for n in range(4, 9)])
    window = varflow.track(frames, 2, "twoframe", **CHEAP)
    pair = varflow.track(frames[2:4], 0, "twoframe", **CHEAP)
    np.testing.assert_allclose(window[3], pair[1], atol=1e-5)


@pytest.mark.data
def test_sintel_trajectories_cropped_real_alley(data_root: Path) -> None:
    rows = bm.run_sintel_trajectories(["twoframe"], CHEAP, progress=False, root=data_root,
                                      refs=(2,), windows=(3,), include_whole=False,
                                      crop=(150, 246, 400, 528), warm_up=False)
    (row,) = rows
    assert (row["ref"], row["window"], row["frames"], row["ref_index"]) \
        == (2, "3: 0001-0003", 3, 1)
    assert row["shared"] and row["pair"] == "0002->0003"
    assert math.isfinite(row["aee"]) and 0 < row["aee"] < 2.0, row
    assert math.isfinite(row["aee_noc"])  # frame 2 has the occlusion mask


def _protocol_rows() -> list[dict]:
    aee = {  # (ref, window) -> (twoframe, mfsf, rlr)
        (5, "3: 0004-0006"): (1.0, 0.8, 0.5),
        (5, "whole: 0001-0020"): (1.0, 1.1, 0.9),
        (6, "3: 0005-0007"): (2.0, 2.5, 1.0),
        (6, "whole: 0001-0020"): (2.0, 2.1, 1.5),
    }
    rows = []
    for (ref, window), vals in aee.items():
        for m, v in zip(("twoframe", "mfsf", "rlr"), vals, strict=True):
            rows.append({"ref": ref, "window": window, "frames": 3 if window[0] == "3" else 20,
                         "method": m, "aee": v, "seconds": 1.0, "shared": m == "twoframe"})
    return rows


def test_protocol_table_format() -> None:
    text = bm.format_protocol_table(_protocol_rows())
    lines = text.splitlines()
    table = [ln for ln in lines if ln.startswith("|")]
    assert table[0].startswith("| ref") and "| window" in table[0]
    for h in ("twoframe AEE", "mfsf AEE", "mfsf / twoframe", "rlr AEE", "rlr / twoframe"):
        assert h in table[0], h
    assert "twoframe / twoframe" not in table[0]
    assert set(table[1]) <= {"|", "-", ":"}
    assert len(table) == 2 + 4 + 2 + 1  # header, rule, 4 lines, 2 reference means, overall
    assert len({len(ln) for ln in table}) == 1  # aligned
    assert "3: 0004-0006" in table[2] and "0.8000" in table[2] and "0.800" in table[2]
    ref5 = next(ln for ln in table if ln.startswith("| 5 ") and "mean of 2 windows" in ln)
    assert "0.9500" in ref5 and "0.7000" in ref5  # mfsf and rlr means over the windows
    assert table[-1].startswith("| all") and "mean of 4 lines" in table[-1]
    assert "mfsf beats twoframe at 1 of 2 references (5)" in text
    assert "rlr beats twoframe at 2 of 2 references (5, 6)" in text
    assert "twoframe: one run per reference" in text
    assert "twoframe 2.0 s in 2 runs" in text and "mfsf 4.0 s in 4 runs" in text
    # without the baseline: no ratios, and it says so
    text = bm.format_protocol_table([r for r in _protocol_rows() if r["method"] != "twoframe"])
    assert "/ twoframe" not in text and "no twoframe rows" in text
    assert bm.format_protocol_table([]) == "(no results)"


# ----------------------------------------------------------------------------- table


def test_table_format() -> None:
    def row(seq: str, method: str, aee: float, noc: float | None = None) -> dict:
        return {"dataset": "sintel-clean", "sequence": seq, "pair": "0002->0003", "ref": 1,
                "frames": 4, "method": method, "aee": aee, "aae": 10 * aee, "aee_noc": noc,
                "seconds": 1.5}

    rows = [row("a", "twoframe", 0.2, 0.1), row("a", bm.BASELINE_LABEL, 0.4, 0.2),
            row("b", "twoframe", 0.3), row("b", bm.BASELINE_LABEL, 0.3)]
    lines = bm.format_multiframe_table(rows).splitlines()
    assert lines[0].startswith("| dataset") and "AEE / tvl1 pair" in lines[0]
    assert set(lines[1]) <= {"|", "-", ":"}
    assert len(lines) == 2 + 4 + 2  # header, rule, rows, a mean line per method
    assert len({len(line) for line in lines}) == 1  # aligned
    assert "0.500" in lines[2] and "0.1000" in lines[2]  # ratio to the pair, AEE noc
    assert " - " in lines[4]  # no occlusion mask
    assert lines[-2].startswith("| mean") and "0.750" in lines[-2]  # mean of 0.5 and 1.0
    assert bm.format_multiframe_table([]) == "(no results)"


# ----------------------------------------------------------------------------- CLI


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    rc = cli.main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


def _one_line_error(rc: int, err: str, *needles: str) -> None:
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert err.startswith("varflow: error: ") and "Traceback" not in err
    for n in needles:
        assert n in err, (n, err)


def test_cli_prints_tables(capsys: pytest.CaptureFixture[str], fake_root: Path,
                           tmp_path: Path) -> None:
    csv = tmp_path / "rows.csv"
    rc, out, err = _run(capsys, "bench", "middlebury-multiframe", "--data", str(fake_root),
                        "--methods", "twoframe", "--sintel", "--quiet", "--csv", str(csv),
                        *CHEAP_FLAGS)
    assert rc == 0, err
    lines = out.splitlines()
    assert "RubberWhale" in lines[0] and "frame10" in lines[0]
    # the header names every changed parameter, so a table never hides its settings
    assert lines[0].endswith("parameters changed: max_iterations=5, n_warps=1"), lines[0]
    assert sum("parameters changed: max_iterations=5, n_warps=1" in ln for ln in lines) == 2
    tables = [ln for ln in lines if ln.startswith("| dataset")]
    assert len(tables) == 2  # Middlebury, then Sintel
    assert any("| twoframe" in ln and "RubberWhale" in ln for ln in lines)
    assert any(bm.BASELINE_LABEL in ln and "fake_1" in ln for ln in lines)
    assert csv.is_file() and len(csv.read_text().splitlines()) == 1 + 4


def test_cli_unknown_method_one_line(capsys: pytest.CaptureFixture[str], fake_root: Path) -> None:
    rc, _, err = _run(capsys, "bench", "middlebury-multiframe", "--data", str(fake_root),
                      "--methods", "twoframe,nope", "--quiet")
    _one_line_error(rc, err, "nope")


def test_cli_missing_data_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rc, _, err = _run(capsys, "bench", "middlebury-multiframe", "--data", str(tmp_path / "none"),
                      "--methods", "twoframe", "--quiet")
    _one_line_error(rc, err, "--data", "VARFLOW_DATA")
    rc, _, err = _run(capsys, "bench", "middlebury-multiframe", "--data", str(tmp_path),
                      "--methods", "twoframe", "--sintel", "--quiet")
    _one_line_error(rc, err, "Sintel", "VARFLOW_DATA")


def test_cli_parameter_of_no_method_one_line(capsys: pytest.CaptureFixture[str],
                                             fake_root: Path) -> None:
    if "rlr" not in bm.default_methods():
        pytest.skip("needs rlr registered")
    rc, _, err = _run(capsys, "bench", "middlebury-multiframe", "--data", str(fake_root),
                      "--methods", "twoframe", "--link-weight", "3", "--quiet")
    _one_line_error(rc, err, "--link-weight: not a parameter of method(s) twoframe")


@pytest.mark.data
def test_cli_on_real_rubberwhale(capsys: pytest.CaptureFixture[str], data_root: Path) -> None:
    rc, out, err = _run(capsys, "bench", "middlebury-multiframe", "--data", str(data_root),
                        "--methods", "twoframe", "--quiet", *CHEAP_FLAGS)
    assert rc == 0, err
    row = next(ln for ln in out.splitlines() if "| twoframe" in ln)
    aee = float(row.split("|")[6])
    assert 0 < aee < 0.5, row


@pytest.mark.slow
@pytest.mark.data
def test_rlr_defaults_on_rubberwhale(data_root: Path) -> None:
    """RubberWhale frame 11, full resolution and full iterations, default parameters.

    Measured (2026-12-04, version 0.7.1, benchmarks/README.md): RLR 0.0965 on the host
    build and 0.0962 with NUMBA_CPU_NAME=generic (cold and warm caches alike), the
    TV-L1 pair 0.0970 on both.  The builds move RLR by 0.0003 and the gap to the pair
    is 0.0005-0.0008, so "RLR beats the pair" stays a benchmark figure; this test
    bounds RLR within 2 % of the pair (0.995 and 0.992 measured), which the exact data
    term broke (0.0992, 2.3 % above, version 0.6.0) and the full link on the frames
    next to the reference breaks by far (0.1305 at ``adjacent_link_factor=1``,
    2026-11-30).
    """
    rows = bm.run_middlebury_multiframe(["rlr"], {}, progress=False, root=data_root,
                                        warm_up=False)
    rlr = next(r for r in rows if r["method"] == "rlr")
    pair = next(r for r in rows if r["method"] == bm.BASELINE_LABEL)
    assert 0.093 < pair["aee"] < 0.103, pair
    assert rlr["aee"] < 1.02 * pair["aee"], (rlr["aee"], pair["aee"])


def test_cli_sintel_trajectories(capsys: pytest.CaptureFixture[str], alley_root: Path,
                                 tmp_path: Path) -> None:
    csv = tmp_path / "rows.csv"
    rc, out, err = _run(capsys, "bench", "sintel-trajectories", "--data", str(alley_root),
                        "--methods", "twoframe,mfsf", "--refs", "5", "6", "--windows", "3",
                        "--no-whole", "--quiet", "--csv", str(csv), *CHEAP_FLAGS)
    assert rc == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("MPI-Sintel final/alley_1 frames 0001-0020"), lines[0]
    assert lines[0].endswith("parameters changed: max_iterations=5, n_warps=1"), lines[0]
    assert lines[1].startswith("| ref") and "mfsf / twoframe" in lines[1]
    assert any(ln.startswith("| 5 ") and "3: 0004-0006" in ln for ln in lines)
    assert any(ln.startswith("mfsf beats twoframe at ") for ln in lines)
    # then the RubberWhale table
    rw = next(i for i, ln in enumerate(lines) if ln.startswith("Middlebury RubberWhale"))
    assert lines[rw + 1].startswith("| dataset")
    assert any("RubberWhale" in ln and bm.BASELINE_LABEL in ln for ln in lines[rw:])
    assert csv.is_file() and len(csv.read_text().splitlines()) == 1 + 2 * 2 + 3

    rc, out, err = _run(capsys, "bench", "sintel-trajectories", "--data", str(alley_root),
                        "--methods", "twoframe", "--refs", "6", "--windows", "2",
                        "--crop", "0", "32", "8", "56", "--no-rubberwhale", "-q", *CHEAP_FLAGS)
    assert rc == 0, err
    assert "cropped to rows 0:32, columns 8:56" in out and "RubberWhale" not in out
    assert "| 6   | 2: 0006-0007" in out


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--refs", "0"], ["refs", "frames 0 and 1"]),
        (["--refs", "5", "20"], ["refs", "frames 20 and 21"]),
        (["--refs", "12"], ["refs", "no ground truth", "0001-0010"]),
        (["--windows", "1"], ["windows", "at least 2 frames"]),
        (["--windows", "21"], ["windows", "exceeds the 20 frames"]),
        (["--refs", "five"], ["--refs"]),
        (["--crop", "0", "99", "0", "10"], ["crop"]),
        (["--methods", "twoframe,nope"], ["nope"]),
    ],
)
def test_cli_sintel_trajectories_bad_args_one_line(
    capsys: pytest.CaptureFixture[str], alley_root: Path, args: list[str], needles: list[str]
) -> None:
    rc, out, err = _run(capsys, "bench", "sintel-trajectories", "--data", str(alley_root),
                        "--methods", "twoframe", "--quiet", *args)
    _one_line_error(rc, err, *needles)
    assert out == ""


def test_cli_sintel_trajectories_missing_data_one_line(
    capsys: pytest.CaptureFixture[str], alley_root: Path, tmp_path: Path
) -> None:
    rc, _, err = _run(capsys, "bench", "sintel-trajectories", "--data", str(tmp_path),
                      "--methods", "twoframe", "--quiet")
    _one_line_error(rc, err, "alley_1", "VARFLOW_DATA")
    # Sintel present, RubberWhale missing: fails before the Sintel run
    (tmp_path / "sintel").symlink_to(alley_root / "sintel", target_is_directory=True)
    rc, out, err = _run(capsys, "bench", "sintel-trajectories", "--data", str(tmp_path),
                        "--methods", "twoframe", "--quiet")
    _one_line_error(rc, err, "RubberWhale", "VARFLOW_DATA")
    assert out == ""
