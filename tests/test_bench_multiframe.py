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

from varflow import cli
from varflow.evaluation import bench_multiframe as bm
from varflow.generators.sequences import make_sequence
from varflow.io import write_flo, write_image

# The cheapest tracker settings: one warp, 5 iterations per level.
CHEAP = {"n_warps": 1, "max_iterations": 5}
CHEAP_FLAGS = ["--n-warps", "1", "--max-iterations", "5"]


def _u8(img: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(img, np.float64) * 255.0), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def fake_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data folder with an 8-frame "RubberWhale" and one 4-frame Sintel snippet."""
    root = tmp_path_factory.mktemp("data")
    seq = make_sequence("affine", n_frames=8, shape=(48, 64), ref=3, magnitude=3.0, seed=2)
    d = root / "middlebury" / "other-data" / "RubberWhale"
    d.mkdir(parents=True)
    for i, n in enumerate(range(7, 15)):
        write_image(d / f"frame{n:02d}.png", _u8(seq.frames[i]))
    gt = seq.trajectories[4] - seq.trajectories[3]
    gt[:4, :4] = 1e10  # unknown pixels, as in the real ground truth
    (root / "middlebury" / "other-gt-flow" / "RubberWhale").mkdir(parents=True)
    write_flo(root / "middlebury" / "other-gt-flow" / "RubberWhale" / "flow10.flo", gt)

    s = make_sequence("affine", n_frames=4, shape=(40, 56), ref=1, magnitude=2.0, seed=3)
    tr = root / "sintel" / "training"
    for sub in ("clean/fake_1", "flow/fake_1", "occlusions/fake_1", "invalid/fake_1"):
        (tr / sub).mkdir(parents=True)
    for i, n in enumerate(range(1, 5)):
        write_image(tr / "clean" / "fake_1" / f"frame_{n:04d}.png", _u8(s.frames[i]))
    write_flo(tr / "flow" / "fake_1" / "frame_0001.flo", s.trajectories[1] - s.trajectories[0])
    write_flo(tr / "flow" / "fake_1" / "frame_0002.flo", s.trajectories[2] - s.trajectories[1])
    occ = np.zeros((40, 56), np.uint8)
    occ[:, -6:] = 255
    write_image(tr / "occlusions" / "fake_1" / "frame_0002.png", occ)
    write_image(tr / "invalid" / "fake_1" / "frame_0002.png", np.zeros((40, 56), np.uint8))
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
    _one_line_error(rc, err, "link_weight")


@pytest.mark.data
def test_cli_on_real_rubberwhale(capsys: pytest.CaptureFixture[str], data_root: Path) -> None:
    rc, out, err = _run(capsys, "bench", "middlebury-multiframe", "--data", str(data_root),
                        "--methods", "twoframe", "--quiet", *CHEAP_FLAGS)
    assert rc == 0, err
    row = next(ln for ln in out.splitlines() if "| twoframe" in ln)
    aee = float(row.split("|")[6])
    assert 0 < aee < 0.5, row


@pytest.mark.data
def test_rlr_weak_link_beats_the_pair_on_rubberwhale(data_root: Path) -> None:
    """The issue's RubberWhale criterion, full resolution and full iterations.

    With τ = 0.02 the 8-frame RLR's frame-11 AEE is 0.0982 against 0.0994 for the
    TV-L1 pair (benchmarks/README.md); τ = 0 (the refinement alone) gives 0.0989, so
    the bound below also needs the link's share of the gain.
    """
    rows = bm.run_middlebury_multiframe(["rlr"], {"link_weight": 0.02}, progress=False,
                                        root=data_root, warm_up=False)
    rlr = next(r for r in rows if r["method"] == "rlr")
    pair = next(r for r in rows if r["method"] == bm.BASELINE_LABEL)
    assert 0.095 < pair["aee"] < 0.103, pair
    assert rlr["aee"] < pair["aee"] - 0.0008, (rlr["aee"], pair["aee"])
    assert rlr["aae"] < pair["aae"], (rlr["aae"], pair["aae"])
