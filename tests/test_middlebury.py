"""Middlebury accuracy regression, the data loaders and the benchmark runner/table.

Tests that read the benchmark data use the ``data_root`` fixture (skipped without
data, failed when ``VARFLOW_REQUIRE_DATA=1`` as in CI) and carry the ``data`` marker;
nothing deselects them, so they run in CI.
"""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np
import pytest

import varflow
from varflow import cli
from varflow.evaluation import datasets
from varflow.evaluation.bench import common, middlebury
from varflow.evaluation.metrics import evaluate
from varflow.twoframe.params import preset

# TV-L1 with the book's plain energy (PlainTVL1Params) on the colour frames, all 8
# pairs: the foundation's acceptance figures.  Measured (2026-11-23): mean 0.284,
# worst ratio to the book's TV-only figure 1.04 (Hydrangea); the bounds are the
# issue's: mean <= 0.30 and no pair above 1.05 x the book (Gibson & Marques 2016,
# Table 3.3).
MEAN_AEE_LIMIT = 0.30
BOOK_RATIO_LIMIT = 1.05
# The tvl1 default (issue 11: gradient term, Huber-TV, grey channel): mean <= 0.27
# and below OpenCV DeepFlow's 0.295; measured 0.268 (2026-11-30).
DEFAULT_MEAN_LIMIT = 0.27


def _middlebury_aee(data_root: Path, params) -> dict[str, float]:
    out = {}
    for seq in datasets.MIDDLEBURY_SEQUENCES:
        f0, f1, gt = datasets.load_middlebury_pair(seq, data_root)
        out[seq] = evaluate(varflow.flow(f0, f1, "tvl1", params=params), gt)["aee"]
    return out


@pytest.fixture(scope="module")
def tvl1_middlebury_aee(data_root: Path) -> dict[str, float]:
    return _middlebury_aee(data_root, preset("plain"))


@pytest.mark.data
def test_tvl1_default_middlebury_mean(data_root: Path) -> None:
    aees = _middlebury_aee(data_root, None)
    mean = float(np.mean(list(aees.values())))
    assert mean <= DEFAULT_MEAN_LIMIT, f"mean AEE {mean:.4f} > {DEFAULT_MEAN_LIMIT}"


@pytest.mark.data
@pytest.mark.parametrize("seq", datasets.MIDDLEBURY_SEQUENCES)
def test_plain_tvl1_accuracy_per_sequence(tvl1_middlebury_aee: dict[str, float],
                                            seq: str) -> None:
    aee = tvl1_middlebury_aee[seq]
    limit = BOOK_RATIO_LIMIT * datasets.BOOK_TV_AEE[seq]
    assert aee <= limit, f"{seq}: AEE {aee:.4f} > {limit:.4f} (1.05 x book TV-only)"


@pytest.mark.data
def test_plain_tvl1_mean_accuracy(tvl1_middlebury_aee: dict[str, float]) -> None:
    mean = float(np.mean(list(tvl1_middlebury_aee.values())))
    assert mean <= MEAN_AEE_LIMIT, f"mean AEE {mean:.4f} > {MEAN_AEE_LIMIT}"


# ----------------------------------------------------------------------------- loaders


@pytest.mark.data
def test_load_middlebury_pair(data_root: Path) -> None:
    f0, f1, gt = datasets.load_middlebury_pair("rubberwhale", data_root)  # any case
    assert f0.shape == f1.shape == (388, 584, 3) and f0.dtype == np.uint8
    assert gt.shape == (388, 584, 2) and gt.dtype == np.float32
    unknown = np.isnan(gt)
    assert unknown.any()  # RubberWhale has pixels without ground truth
    np.testing.assert_array_equal(unknown[..., 0], unknown[..., 1])
    assert np.abs(gt[~unknown]).max() < 100
    assert not np.array_equal(f0, f1)


@pytest.mark.data
def test_load_sintel_pair(data_root: Path) -> None:
    f0, f1, gt, occ, inv = datasets.load_sintel_pair("alley_1", 2, "clean", data_root)
    assert f0.shape == f1.shape == (436, 1024, 3) and f0.dtype == np.uint8
    assert gt.shape == (436, 1024, 2)
    assert occ is not None and occ.dtype == bool and occ.shape == (436, 1024)
    assert 0 < occ.mean() < 0.5
    assert inv is not None and inv.shape == (436, 1024)
    _, _, _, occ1, inv1 = datasets.load_sintel_pair("alley_1", 1, "clean", data_root)
    assert occ1 is None and inv1 is None  # no masks shipped for frame 1
    assert ("alley_1", 2, "clean") in datasets.sintel_pairs(data_root)


def test_data_root_precedence(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(datasets.ENV_VAR, str(tmp_path / "env"))
    assert datasets.data_root(tmp_path / "explicit") == tmp_path / "explicit"
    assert datasets.data_root() == tmp_path / "env"
    monkeypatch.delenv(datasets.ENV_VAR)
    (tmp_path / "repo").mkdir()
    (tmp_path / "shared" / "data").mkdir(parents=True)
    monkeypatch.chdir(tmp_path / "repo")
    assert datasets.data_root() == (tmp_path / "shared" / "data").resolve()


def test_missing_data_message(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="VARFLOW_DATA"):
        datasets.load_middlebury_pair("Venus", tmp_path)
    with pytest.raises(ValueError, match="Atlantis"):
        datasets.load_middlebury_pair("Atlantis", tmp_path)


def test_bench_cli_without_data_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    rc = cli.main(["bench", "middlebury", "--data", str(tmp_path / "none"), "--quiet"])
    _, err = capsys.readouterr()
    assert rc == 2
    assert len(err.splitlines()) == 1 and err.startswith("varflow: error: ")
    assert "--data" in err and "VARFLOW_DATA" in err and "Traceback" not in err


# ----------------------------------------------------------------------------- table


def _row(seq: str, method: str, aee: float) -> dict:
    return {"sequence": seq, "method": method, "aee": aee, "aae": 10 * aee, "seconds": 1.0,
            "book_tv_aee": datasets.BOOK_TV_AEE[seq], "book_aee": None}


def _cells(table: str, label: str) -> list[str]:
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == label:
            return cells
    raise AssertionError(f"no row {label!r} in\n{table}")


def test_format_table_single_method() -> None:
    rows = [_row("Venus", "tvl1", 0.30), _row("RubberWhale", "tvl1", 0.10)]
    table = middlebury.format_table(rows)
    header = _cells(table, "sequence")
    assert header == ["sequence", "tvl1 AEE", "tvl1 AAE", "tvl1 s", "book TV AEE"]
    assert _cells(table, "Venus")[1:] == ["0.3000", "3.000", "1.00", "0.2977"]
    mean = _cells(table, "mean")
    assert float(mean[1]) == pytest.approx(0.2) and float(mean[4]) == pytest.approx(
        (0.2977 + 0.1118) / 2, abs=1e-4)
    ratio = float(_cells(table, "ratio to book TV-only")[1])
    assert ratio == pytest.approx(0.2 / ((0.2977 + 0.1118) / 2), abs=1e-3)
    assert "% improved" not in table  # only with a baseline and another method
    assert _cells(table, "total s")[3] == "2.00"  # the seconds column summed


def test_format_table_adds_columns_and_improvement_row() -> None:
    rows = [_row("Venus", "tvl1", 0.30), _row("Venus", "other", 0.24),
            _row("Grove2", "tvl1", 0.20), _row("Grove2", "other", 0.22)]
    table = middlebury.format_table(rows)
    header = _cells(table, "sequence")
    assert header[1:7] == ["tvl1 AEE", "tvl1 AAE", "tvl1 s", "other AEE", "other AAE", "other s"]
    assert [c for c in _cells(table, "mean")[1:7:3]] == ["0.2500", "0.2300"]
    improved = _cells(table, "% improved vs TV-only")
    assert float(improved[4]) == pytest.approx(100 * (0.25 - 0.23) / 0.25, abs=0.05)
    assert float(improved[1]) == 0.0
    widths = {len(line) for line in table.splitlines()}
    assert len(widths) == 1  # aligned


def test_format_table_baseline_is_first_method_without_tvl1() -> None:
    rows = [_row("Venus", "tensor", 0.20), _row("Venus", "other", 0.19)]
    improved = _cells(middlebury.format_table(rows), "% improved vs tensor")
    assert float(improved[4]) == pytest.approx(5.0, abs=0.05) and float(improved[1]) == 0.0
    explicit = _cells(middlebury.format_table(rows, baseline="other"), "% improved vs other")
    assert float(explicit[1]) == pytest.approx(100 * (0.19 - 0.20) / 0.19, abs=0.05)


# ----------------------------------------------------------------------------- runner + CLI


@pytest.mark.data
def test_bench_runner_and_cli(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], data_root: Path,
    tmp_path: Path
) -> None:
    """Plumbing of run_middlebury / `varflow bench` with a fake method output.

    The flow is replaced by the ground truth plus (0.3, 0.4), so the AEE is exactly
    0.5 on every valid pixel; this checks loading, scoring, rows, table and CSV
    without spending solver time (the accuracy tests above cover the solver).
    """
    _, _, gt = datasets.load_middlebury_pair("Venus", data_root)
    calls = []

    def fake_flow(f0, f1, method="tvl1", *, params=None, **kwargs):
        calls.append((f0.shape, method, params))
        if f0.shape[:2] != gt.shape[:2]:  # warm-up pair
            return np.zeros(f0.shape[:2] + (2,), np.float32)
        return np.nan_to_num(gt) + np.float32([0.3, 0.4])

    monkeypatch.setattr(varflow, "flow", fake_flow)
    rows = middlebury.run_middlebury(["tvl1"], data_root, sequences=["venus"],
                                overrides={"n_warps": 3}, progress=False)
    assert len(rows) == 1
    r = rows[0]
    assert (r["sequence"], r["method"]) == ("Venus", "tvl1")
    assert r["aee"] == pytest.approx(0.5, abs=1e-6)
    shifted = np.nan_to_num(gt) + np.float32([0.3, 0.4])
    assert r["aae"] == pytest.approx(evaluate(shifted, gt)["aae"])
    assert r["book_tv_aee"] == r["book_aee"] == 0.2977
    assert all(c[2].n_warps == 3 for c in calls)  # overrides reach every call
    assert len(calls) == 2  # warm-up + Venus

    out_csv = tmp_path / "venus.csv"
    rc = cli.main(["bench", "middlebury", "--data", str(data_root), "--sequences", "Venus",
                   "--csv", str(out_csv), "--n-warps", "2", "--quiet"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert re.search(r"\| Venus\s+\|\s+0\.5000 \|", out)
    assert "mean" in out and "ratio to book TV-only" in out
    with open(out_csv, newline="") as f:
        got = list(csv.DictReader(f))
    assert [(g["sequence"], g["method"]) for g in got] == [("Venus", "tvl1")]
    assert math.isclose(float(got[0]["aee"]), 0.5, abs_tol=1e-6)
    assert list(got[0])[: len(middlebury.CSV_FIELDS)] == list(middlebury.CSV_FIELDS)
    assert calls[-1][2].n_warps == 2


def test_split_overrides() -> None:
    assert common.split_overrides(["tvl1"], {"data_weight": 3.0, "tvl1": {"n_warps": 2}}) == {
        "tvl1": {"data_weight": 3.0, "n_warps": 2}}
    with pytest.raises(ValueError, match="bogus"):
        common.split_overrides(["tvl1"], {"bogus": 1})
