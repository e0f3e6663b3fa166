"""The photographic generalisation suite of ``varflow bench trajectories``."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

import varflow
from varflow import cli
from varflow.evaluation.bench.trajectories import (
    end_frames,
    far_epe,
    format_photo_table,
    run_photo_trajectories,
    tracker_params,
)
from varflow.generators.photo import make_photo_clip

FAMILIES = ("affine", "objects")
N_FRAMES = 7
SHAPE = (48, 64)
CHEAP = {"max_iterations": 10, "n_warps": 1}
ROW_KEYS = {"split", "family", "seed", "method", "epe", "far_epe", "rms", "occ_accuracy",
            "hidden_recall", "seconds"}


@pytest.fixture(scope="module", autouse=True)
def one_numba_thread():
    """One numba thread: on 2 busy cores, parallel kernels of tiny clips spin for ages."""
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(old)


@pytest.fixture(scope="module")
def photo_rows():
    return run_photo_trajectories(["twoframe", "rlr"], splits=("tuning",), families=FAMILIES,
                                  n_frames=N_FRAMES, shape=SHAPE, overrides=CHEAP,
                                  progress=False)


def test_runner_rows(photo_rows):
    assert len(photo_rows) == len(FAMILIES) * 3 * 2
    assert [(r["family"], r["seed"], r["method"]) for r in photo_rows] == [
        (f, s, m) for f in FAMILIES for s in (0, 1, 2) for m in ("twoframe", "rlr")]
    for r in photo_rows:
        assert set(r) == ROW_KEYS and r["split"] == "tuning"
        assert math.isfinite(r["epe"]) and r["epe"] > 0
        assert r["rms"] >= r["epe"] - 1e-9
        assert math.isfinite(r["far_epe"]) and r["far_epe"] >= 0
        assert 0.0 <= r["occ_accuracy"] <= 1.0
        assert 0.0 <= r["hidden_recall"] <= 1.0  # these clips have hidden points
        assert r["seconds"] > 0


def test_far_epe_and_occlusion_accuracy_recomputed(photo_rows):
    """Score one clip again with plain numpy: EPE, far EPE, occlusion accuracy."""
    clip = make_photo_clip("objects", seed=1, n_frames=N_FRAMES, shape=SHAPE)
    _, params = tracker_params(["twoframe"], CHEAP)
    est, visible = varflow.track(clip.frames, clip.ref, "twoframe", params=params["twoframe"],
                                 return_visibility=True)
    err = np.hypot(*np.moveaxis(est.astype(np.float64) - clip.trajectories, -1, 0))
    others = [n for n in range(N_FRAMES) if n != clip.ref]
    vis = clip.visibility
    per_frame = {n: err[n][vis[n]].mean() for n in others}
    far = np.mean([per_frame[n] for n in (0, 1, N_FRAMES - 2, N_FRAMES - 1)])
    pooled = err[others][vis[others]].mean()
    occ = (visible[others] == vis[others]).mean()
    hidden = ~vis[others]
    recall = (~visible[others] & hidden).sum() / hidden.sum()
    row = next(r for r in photo_rows
               if (r["family"], r["seed"], r["method"]) == ("objects", 1, "twoframe"))
    assert row["far_epe"] == pytest.approx(far, rel=1e-4)
    assert row["epe"] == pytest.approx(pooled, rel=1e-4)
    assert row["occ_accuracy"] == pytest.approx(occ, abs=1e-6)
    assert row["hidden_recall"] == pytest.approx(recall, abs=1e-6)
    assert row["far_epe"] != pytest.approx(row["epe"], rel=1e-3)  # not the pooled EPE


def test_end_frames_and_far_epe():
    assert end_frames(7) == [0, 1, 5, 6]
    assert end_frames(3) == [0, 1, 2]
    assert end_frames(2) == [0, 1]
    nan = math.nan
    assert far_epe(np.array([1.0, 2.0, 9.0, nan, 9.0, 3.0, 4.0])) == pytest.approx(2.5)
    assert far_epe(np.array([nan, 2.0, 9.0, 1.0, 3.0])) == pytest.approx(2.0)  # ref 0
    assert math.isnan(far_epe(np.array([nan, nan, 1.0, nan, nan])))


def test_table_from_runner(photo_rows):
    table = format_photo_table(photo_rows)
    lines = table.splitlines()
    assert lines[0] == "tuning split (seeds 0, 1, 2)"
    assert lines[1].startswith("| family") and "twoframe far EPE" in lines[1]
    assert "rlr occ acc" in lines[1] and "rlr hidden rec" in lines[1]
    assert "---:|" in lines[2]
    assert any(line.startswith("| affine ") for line in lines)
    assert any(line.startswith("| objects ") for line in lines)
    assert any(line.startswith("| mean ") for line in lines)
    ratio = next(line for line in lines if "ratio to twoframe" in line)

    def mean(m: str, f: str) -> float:
        return np.mean([np.mean([r[f] for r in photo_rows
                                 if r["family"] == fam and r["method"] == m])
                        for fam in FAMILIES])

    cells = [c.strip() for c in ratio.strip("|").split("|")]
    assert cells[1:3] == ["1.000", "1.000"]
    assert cells[6] == f"{mean('rlr', 'epe') / mean('twoframe', 'epe'):.3f}"
    assert cells[7] == f"{mean('rlr', 'far_epe') / mean('twoframe', 'far_epe'):.3f}"


def test_table_layout_with_handmade_rows():
    def row(split, family, seed, m, epe, far, hid):
        return {"split": split, "family": family, "seed": seed, "method": m, "epe": epe,
                "far_epe": far, "rms": epe, "occ_accuracy": 0.5, "hidden_recall": hid,
                "seconds": 1.0}

    rows = [row("tuning", "affine", 0, "a", 1.0, 2.0, 0.25),
            row("tuning", "affine", 1, "a", 3.0, 4.0, math.nan),
            row("tuning", "affine", 0, "b", 1.0, 1.0, math.nan),
            row("tuning", "affine", 1, "b", 1.0, 1.5, math.nan),
            row("reporting", "noise", 100, "a", 4.0, 8.0, 0.5),
            row("reporting", "noise", 100, "b", 2.0, 2.0, 0.5)]
    table = format_photo_table(rows)
    tuning, reporting = table.split("\n\n")
    assert tuning.splitlines()[0] == "tuning split (seeds 0, 1)"
    assert reporting.splitlines()[0] == "reporting split (seeds 100)"
    affine = [c.strip() for c in tuning.splitlines()[3].strip("|").split("|")]
    # a: EPE mean(1, 3), far mean(2, 4), hidden recall 0.25 (NaN ignored); b: no value
    assert affine == ["affine", "2.0000", "3.0000", "0.5000", "0.2500", "1.00",
                      "1.0000", "1.2500", "0.5000", "-", "1.00"]
    ratio = [c.strip() for c in tuning.splitlines()[-1].strip("|").split("|")]
    assert ratio[0] == "EPE, far EPE ratio to a" and ratio[6:8] == ["0.500", "0.417"]
    ratio = [c.strip() for c in reporting.splitlines()[-1].strip("|").split("|")]
    assert ratio[6:8] == ["0.500", "0.250"]
    assert format_photo_table([]) == "(no results)"


def test_runner_rejects_bad_options():
    with pytest.raises(ValueError, match="families"):
        run_photo_trajectories(["twoframe"], families=("affine", "bogus"), progress=False)
    with pytest.raises(ValueError, match="splits"):
        run_photo_trajectories(["twoframe"], splits=("validation",), progress=False)
    with pytest.raises(ValueError, match="shape"):
        run_photo_trajectories(["twoframe"], shape=(16, 64), progress=False)
    with pytest.raises(ValueError, match="n_frames"):
        run_photo_trajectories(["twoframe"], n_frames=1, progress=False)


SMALL = ["--methods", "twoframe", "--max-iterations", "10", "--n-warps", "1", "-q"]


def test_cli_photo_suite(capsys, tmp_path):
    out_csv = tmp_path / "rows.csv"
    rc = cli.main(["bench", "trajectories", "--suite", "photo", "--splits", "reporting",
                   "--families", "affine", "--photo-frames", "5", "--photo-shape", "48x64",
                   "--csv", str(out_csv), *SMALL])
    out = capsys.readouterr().out
    assert rc == 0
    assert "photo suite" in out and "TAP-Vid" in out and "far EPE" in out
    assert "parameters changed: max_iterations=10, n_warps=1" in out
    assert "reporting split (seeds 100, 101, 102)" in out and "tuning split" not in out
    assert "\n| affine " in out and "ratio to twoframe" in out
    assert "| scene" not in out  # no procedural table
    with open(out_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["suite"], r["split"], r["family"], r["seed"]) for r in rows] == [
        ("photo", "reporting", "affine", str(s)) for s in (100, 101, 102)]
    assert all(0.0 <= float(r["occ_accuracy"]) <= 1.0 and float(r["far_epe"]) >= 0
               for r in rows)


def test_cli_both_suites_and_implied_suite(capsys, tmp_path):
    out_csv = tmp_path / "rows.csv"
    rc = cli.main(["bench", "trajectories", "--frames", "4", "--shape", "32x40", "--scenes",
                   "affine", "--variants", "clean", "--splits", "tuning", "--families",
                   "objects", "--photo-frames", "4", "--photo-shape", "40x48",
                   "--csv", str(out_csv), *SMALL])
    out = capsys.readouterr().out
    assert rc == 0
    assert "procedural suite" in out and "| scene" in out and "| affine " in out
    assert "photo suite" in out and "tuning split (seeds 0, 1, 2)" in out
    assert "\n| objects " in out
    with open(out_csv, newline="") as f:
        suites = [r["suite"] for r in csv.DictReader(f)]
    assert suites == ["procedural"] + ["photo"] * 3


@pytest.mark.parametrize("argv, flag", [
    (["--families", "affine,bogus"], "--families"),
    (["--suite", "photo", "--splits", "tuning,test"], "--splits"),
    (["--photo-shape", "16x64"], "--photo-shape"),
    (["--photo-shape", "big"], "--photo-shape"),
    (["--photo-frames", "1"], "--photo-frames"),
    (["--suite", "photo", "--scenes", "affine"], "--scenes"),
    (["--suite", "procedural", "--families", "affine"], "--families"),
])
def test_cli_errors_are_one_line(capsys, argv, flag):
    rc = cli.main(["bench", "trajectories", *argv, "-q"])
    captured = capsys.readouterr()
    assert rc == 2 and captured.out == ""
    assert len(captured.err.splitlines()) == 1
    assert captured.err.startswith("varflow: error: ") and flag in captured.err
    if "bogus" in argv[-1]:
        assert "'bogus'" in captured.err
