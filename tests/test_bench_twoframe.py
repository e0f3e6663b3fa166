"""Tests of the two-frame benchmark (varflow.evaluation.bench.twoframe), its peers and CLI.

The runner is exercised on a few tiny photographic pairs and on a fake data folder
(small textured Middlebury / Sintel look-alikes written to a temporary directory),
so these tests take a few seconds; the tests on the real data use the ``data_root``
fixture (skipped without the data, required when ``VARFLOW_REQUIRE_DATA=1``).
"""

from __future__ import annotations

import csv
import importlib.util
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from _problems import to_u8, wave_texture

pytest.importorskip("skimage")

import varflow  # noqa: E402
from varflow import cli  # noqa: E402
from varflow.evaluation import peers as pe  # noqa: E402
from varflow.evaluation.bench import twoframe as bt  # noqa: E402
from varflow.evaluation.datasets import MIDDLEBURY_SEQUENCES  # noqa: E402
from varflow.evaluation.metrics import evaluate  # noqa: E402
from varflow.generators.photo_pairs import make_photo_pair  # noqa: E402
from varflow.io import write_flo, write_image  # noqa: E402

HAVE_CV2 = importlib.util.find_spec("cv2") is not None
TINY = (48, 64)
CHEAP = {"max_iterations": 20, "n_warps": 2}  # a quick tvl1 for the fake data folder


def _run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _one_line_error(rc: int, err: str, *needles: str) -> None:
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("varflow: error: ") and "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])


def _table_rows(text: str) -> dict[str, list[str]]:
    """First cell -> the other cells of every Markdown body row of ``text``."""
    out = {}
    for ln in text.splitlines():
        if ln.startswith("| ") and not ln.startswith("|-"):
            cells = [c.strip() for c in ln.strip("|").split("|")]
            out[cells[0]] = cells[1:]
    return out


# --------------------------------------------------------------------------- fake data folder


FAKE_SHAPE = (40, 56)
MB_SHIFT = (0.6, -0.4)
SMALL = ("alley_2", "clean", 2)  # translation by SMALL_SHIFT, with masks
SMALL_SHIFT = (0.8, 0.3)
LARGE = ("cave_2", "final", 2)  # "large": ground truth of 12 px (frames not matching)


@pytest.fixture(scope="module")
def fake_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Fake Middlebury (8 translating textures) and two of the Sintel pairs."""
    root = tmp_path_factory.mktemp("data")
    gt = np.empty(FAKE_SHAPE + (2,), np.float32)
    gt[...] = MB_SHIFT
    gt[:3, :3] = 1e10  # unknown
    for i, seq in enumerate(MIDDLEBURY_SEQUENCES):
        d = root / "middlebury" / "other-data" / seq
        d.mkdir(parents=True)
        write_image(d / "frame10.png", wave_texture(FAKE_SHAPE, (0, 0), seed=i))
        write_image(d / "frame11.png", wave_texture(FAKE_SHAPE, MB_SHIFT, seed=i))
        g = root / "middlebury" / "other-gt-flow" / seq
        g.mkdir(parents=True)
        write_flo(g / "flow10.flo", gt)
    tr = root / "sintel" / "training"
    for (clip, pass_, n), shift in ((SMALL, SMALL_SHIFT), (LARGE, (12.0, 0.0))):
        for sub in (pass_, "flow", "occlusions", "invalid"):
            (tr / sub / clip).mkdir(parents=True, exist_ok=True)
        write_image(tr / pass_ / clip / f"frame_{n:04d}.png", wave_texture(FAKE_SHAPE, (0, 0), 7))
        write_image(tr / pass_ / clip / f"frame_{n + 1:04d}.png",
                    wave_texture(FAKE_SHAPE, SMALL_SHIFT if clip == SMALL[0] else (0, 0), 7))
        flow = np.empty(FAKE_SHAPE + (2,), np.float32)
        flow[...] = shift
        inv = np.zeros(FAKE_SHAPE, np.uint8)
        if clip == SMALL[0]:
            flow[:, :8] = (40.0, 40.0)  # wrong values under the invalid mask
            inv[:, :8] = 255
        occ = np.zeros(FAKE_SHAPE, np.uint8)
        occ[-10:] = 255
        write_flo(tr / "flow" / clip / f"frame_{n:04d}.flo", flow)
        write_image(tr / "occlusions" / clip / f"frame_{n:04d}.png", occ)
        write_image(tr / "invalid" / clip / f"frame_{n:04d}.png", inv)
    return root


# --------------------------------------------------------------------------- peers


def test_to_grey_uint8():
    rgb = np.random.default_rng(0).random((5, 6, 3)).astype(np.float32)
    luma = rgb[..., 0] * 0.2125 + rgb[..., 1] * 0.7154 + rgb[..., 2] * 0.0721
    np.testing.assert_array_equal(pe.to_grey_uint8(rgb), np.rint(luma * 255).astype(np.uint8))
    u8 = to_u8(rgb)
    grey8 = pe.to_grey_uint8(u8)
    assert grey8.dtype == np.uint8
    assert np.abs(grey8.astype(int) - np.rint(luma * 255)).max() <= 1
    np.testing.assert_array_equal(pe.to_grey_uint8(u8[..., 1]), u8[..., 1])
    np.testing.assert_array_equal(pe.to_grey_uint8(u8[..., 1:2]), u8[..., 1])
    u16 = (u8.astype(np.uint16) * 257)[..., 0]
    np.testing.assert_array_equal(pe.to_grey_uint8(u16), u8[..., 0])
    with pytest.raises(ValueError, match="^frame:"):
        pe.to_grey_uint8(np.zeros((4, 4, 2), np.float32))
    with pytest.raises(ValueError, match="^frame:"):
        pe.to_grey_uint8(np.zeros((4, 4), bool))


@pytest.mark.parametrize("name", list(pe.PEERS))
def test_peer_convention_u_then_v(name):
    """Every available peer finds the exact flow of a photo pair, in (u, v) order."""
    if pe.peer_status()[name] is not None:
        pytest.skip(f"{name} unavailable: {pe.peer_status()[name]}")
    pair = make_photo_pair("affine", 0, shape=(96, 128))  # u ~ -5, v ~ -3 px
    est = pe.PEERS[name](pair.frame0, pair.frame1)
    assert est.shape == (96, 128, 2) and est.dtype == np.float32
    good = evaluate(est, pair.flow, mask=pair.valid)["aee"]
    swapped = evaluate(est[..., ::-1], pair.flow, mask=pair.valid)["aee"]
    assert good < 0.4 and swapped > 5.0, (good, swapped)


def test_peers_report_missing_opencv(monkeypatch):
    monkeypatch.setitem(sys.modules, "cv2", None)  # "import cv2" raises ImportError
    status = pe.peer_status()
    for name in ("deepflow", "dis", "dualtvl1"):
        assert "OpenCV is not installed" in status[name]
        assert "varflow[bench]" in status[name]
    assert set(pe.available_peers()) <= {"skimage"}
    assert pe.peer_threads() is None
    with pytest.raises(pe.PeerUnavailableError, match="OpenCV"):
        pe.dis(np.zeros((8, 8)), np.zeros((8, 8)))
    runnable, unavailable = bt.resolve_peers("all")
    assert set(unavailable) == {"deepflow", "dis", "dualtvl1"} and "dis" not in runnable


def test_peers_report_missing_contrib(monkeypatch):
    fake = types.ModuleType("cv2")
    fake.DISOpticalFlow_create = lambda preset: None  # type: ignore[attr-defined]
    fake.DISOPTICAL_FLOW_PRESET_MEDIUM = 1  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "cv2", fake)
    status = pe.peer_status()
    assert status["dis"] is None
    assert "contrib" in status["deepflow"] and "contrib" in status["dualtvl1"]
    with pytest.raises(pe.PeerUnavailableError, match="contrib"):
        pe.deepflow(np.zeros((8, 8)), np.zeros((8, 8)))


def test_peers_report_missing_skimage(monkeypatch):
    monkeypatch.setitem(sys.modules, "skimage.registration", None)
    assert "scikit-image is not installed" in pe.peer_status()["skimage"]
    assert "skimage" not in pe.available_peers()


# --------------------------------------------------------------------------- options


def test_check_options():
    sets, splits, fams, shape = bt.check_twoframe_options("sintel,photo", "both", "blur,affine",
                                                          (64, 80))
    assert sets == ["photo", "sintel"] and splits == ["tuning", "reporting"]
    assert fams == ["blur", "affine"] and shape == (64, 80)
    assert bt.check_twoframe_options(["photo"], "tuning")[1] == ["tuning"]
    for args, name in ((("photo,kitti",), "sets"), (("",), "sets"), (("photo", "test"), "split"),
                       (("photo", "tuning", "affine,zoom"), "families"),
                       (("photo", "tuning", "affine", (16, 64)), "photo_shape")):
        with pytest.raises(ValueError, match=f"^{name}:"):
            bt.check_twoframe_options(*args)
    assert bt.resolve_peers("none") == ([], {})
    assert bt.resolve_peers(None) == ([], {})
    with pytest.raises(ValueError, match="^peers:.*flownet"):
        bt.resolve_peers("dis,flownet")


# --------------------------------------------------------------------------- runner


@pytest.fixture(scope="module")
def photo_rows() -> list[dict]:
    peers = ["dis"] if HAVE_CV2 else None
    return bt.run_twoframe(["tvl1"], peers=peers, sets=["photo"], split="tuning",
                           families=["affine", "objects"], photo_shape=TINY, progress=False)


def test_runner_on_tiny_photo_pairs(photo_rows):
    methods = ["tvl1"] + (["dis"] if HAVE_CV2 else [])
    assert len(photo_rows) == 6 * len(methods)
    assert [r["method"] for r in photo_rows[: len(methods)]] == methods
    seqs = list(dict.fromkeys(r["sequence"] for r in photo_rows))
    assert seqs == ["affine/0", "affine/1", "affine/2", "objects/0", "objects/1", "objects/2"]
    for r in photo_rows:
        assert r["set"] == "photo" and r["split"] == "tuning"
        assert r["kind"] == ("varflow" if r["method"] == "tvl1" else "peer")
        assert math.isfinite(r["aee"]) and math.isfinite(r["aee_noc"])
        assert r["seconds"] > 0  # recorded (no bound: the first pair may include the JIT)
        assert r["motion"] == "small" and 0 < r["occluded"] < 0.5
    # the numbers are those of a direct run, scored on all pixels and on the visible ones
    r = next(r for r in photo_rows if r["sequence"] == "objects/1" and r["method"] == "tvl1")
    pair = make_photo_pair("objects", 1, shape=TINY)
    est = varflow.flow(pair.frame0, pair.frame1, "tvl1")
    scores = evaluate(est, pair.flow, occlusion=~pair.valid)
    assert r["aee"] == pytest.approx(scores["aee"], rel=1e-6)
    assert r["aee_noc"] == pytest.approx(scores["aee_noc"], rel=1e-6)
    assert r["mean_motion"] == pytest.approx(pair.params["mean_displacement"], rel=1e-6)
    assert r["occluded"] == pytest.approx(1 - pair.valid.mean())
    assert r["family"] == "objects" and r["seed"] == 1
    # tvl1 recovers the camera motion of the affine pairs
    aff = [r["aee"] for r in photo_rows if r["family"] == "affine" and r["method"] == "tvl1"]
    assert max(aff) < 0.6, aff


def test_runner_on_fake_middlebury_and_sintel(fake_root, caplog):
    with caplog.at_level("WARNING"):
        rows = bt.run_twoframe(["tvl1"], sets=["middlebury", "sintel"], root=fake_root,
                               overrides=CHEAP, progress=False)
    assert len(rows) == 8 + 2
    mb = [r for r in rows if r["set"] == "middlebury"]
    assert [r["sequence"] for r in mb] == list(MIDDLEBURY_SEQUENCES)
    for r in mb:
        assert r["aee_noc"] is None and r["occluded"] is None and r["split"] is None
        assert r["aee"] < 0.2, r  # a smooth texture translating by (0.6, -0.4)
        assert r["mean_motion"] == pytest.approx(math.hypot(*MB_SHIFT), rel=1e-5)
    small = next(r for r in rows if r["sequence"] == "alley_2 clean 2->3")
    large = next(r for r in rows if r["sequence"] == "cave_2 final 2->3")
    # the invalid columns (ground truth 40, 40) are not scored
    assert small["aee"] < 0.3 and small["max_motion"] < 1.0
    assert small["motion"] == "small" and large["motion"] == "large"
    assert large["mean_motion"] == pytest.approx(12.0)
    assert small["aee_noc"] is not None and small["occluded"] == pytest.approx(10 / 40)
    missing = [f"{c} {p} {n}->{n + 1}" for c, p, n in bt.SINTEL_PAIRS if (c, p, n)
               not in (SMALL, LARGE)]
    for label in missing:
        assert label in caplog.text


def test_runner_errors(fake_root, tmp_path):
    with pytest.raises(ValueError, match="^method:"):
        bt.run_twoframe(["tvl1", "nope"], sets="photo", progress=False)
    with pytest.raises(ValueError, match="^methods:"):
        bt.run_twoframe([], peers="none", sets="photo", progress=False)
    with pytest.raises(ValueError, match="^overrides:"):
        bt.run_twoframe([], peers="skimage", sets="photo", overrides={"n_warps": 1},
                        progress=False)
    with pytest.raises(ValueError, match="flux"):
        bt.run_twoframe(["tvl1"], sets="photo", overrides={"flux": 1}, progress=False)
    with pytest.raises(FileNotFoundError, match="Middlebury.*VARFLOW_DATA"):
        bt.run_twoframe(["tvl1"], sets="middlebury", root=tmp_path, progress=False)
    with pytest.raises(FileNotFoundError, match="Sintel.*VARFLOW_DATA"):
        bt.run_twoframe(["tvl1"], sets="sintel", root=tmp_path, progress=False)


def test_unavailable_peer_is_skipped_not_fatal(monkeypatch, caplog):
    monkeypatch.setitem(sys.modules, "cv2", None)
    with caplog.at_level("WARNING"):
        rows = bt.run_twoframe(["tvl1"], peers="dis", sets="photo", split="tuning",
                               families="affine", photo_shape=TINY, progress=False)
    assert {r["method"] for r in rows} == {"tvl1"} and len(rows) == 3
    assert "peer dis unavailable" in caplog.text


# --------------------------------------------------------------------------- tables and CSV


def _row(set_, seq, method, aee, noc, s, motion=1.0, family=None, split=None):
    return {"set": set_, "split": split, "sequence": seq, "family": family, "seed": None,
            "method": method, "kind": "peer", "aee": aee, "aee_noc": noc, "seconds": s,
            "mean_motion": motion, "motion": "large" if motion > 10 else "small"}


def test_format_table_numbers():
    rows = [
        _row("sintel", "a", "tvl1", 1.0, 0.5, 2.0, 2.0),
        _row("sintel", "a", "deepflow", 2.0, 1.0, 4.0, 2.0),
        _row("sintel", "b", "tvl1", 3.0, 1.5, 6.0, 20.0),
        _row("sintel", "b", "deepflow", 2.0, 2.0, 4.0, 20.0),
        _row("middlebury", "M", "tvl1", 0.2, None, 1.0),
    ]
    text = bt.format_twoframe_table(rows)
    assert text.index("Middlebury") < text.index("MPI-Sintel")  # sets in SETS order
    mb_text, sintel_text = text.split("MPI-Sintel")
    assert "noc" not in mb_text  # no occlusion mask: no noc column
    mb = _table_rows(mb_text)
    assert mb["M"] == ["1.00", "0.200", "1.000"] and "ratio to tvl1" not in mb
    t = _table_rows(sintel_text)
    assert t["sequence"] == ["mean gt px", "motion", "tvl1 AEE", "tvl1 noc", "tvl1 s",
                             "deepflow AEE", "deepflow noc", "deepflow s"]
    assert t["a"][:2] == ["2.00", "small"] and t["b"][1] == "large"
    assert t["mean"] == ["11.00", "", "2.000", "1.000", "4.000", "2.000", "1.500", "4.000"]
    assert t["mean small motion (1)"][2] == "1.000"
    assert t["mean large motion (1)"][2] == "3.000"
    assert t["total s"] == ["", "", "", "", "8.000", "", "", "8.000"]
    # deepflow is the baseline: tvl1's mean AEE 2.0 / 2.0, noc 1.0 / 1.5, seconds 4 / 4
    assert t["ratio to deepflow"] == ["", "", "1.00", "0.67", "1.00", "1.00", "1.00", "1.00"]
    t2 = _table_rows(bt.format_twoframe_table(rows[:4], baseline="tvl1"))
    assert t2["ratio to tvl1"][5:] == ["1.00", "1.50", "1.00"]
    assert bt.format_twoframe_table([]) == "(no results)"


def test_format_table_photo_groups():
    rows = [_row("photo", f"{f}/{s}", "tvl1", a, a / 2, 1.0, family=f, split=sp)
            for sp in ("tuning", "reporting") for f, a in (("affine", 0.1), ("blur", 0.3))
            for s in ((0, 1) if sp == "tuning" else (100, 101))]
    text = bt.format_twoframe_table(rows[::-1])
    assert text.index("tuning split") < text.index("reporting split")  # split order
    assert text.count("photo pairs, tuning split, seeds 0, 1, 2 (4 pairs)") == 1
    assert text.count("photo pairs, reporting split") == 1
    tuning = _table_rows(text.split("reporting split")[0])
    assert tuning["mean affine"][1] == "0.100" and tuning["mean blur"][1] == "0.300"
    assert tuning["mean"][1] == "0.200"


def test_csv_round_trip(photo_rows, tmp_path):
    path = tmp_path / "rows.csv"
    bt.write_twoframe_csv(photo_rows, path)
    with open(path, newline="") as f:
        back = list(csv.DictReader(f))
    assert len(back) == len(photo_rows)
    assert list(back[0])[: len(bt.TWOFRAME_CSV_FIELDS)] == list(bt.TWOFRAME_CSV_FIELDS)
    assert float(back[0]["aee"]) == pytest.approx(photo_rows[0]["aee"])
    assert bt.format_twoframe_table(back) == bt.format_twoframe_table(photo_rows)


# --------------------------------------------------------------------------- CLI


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--sets", "photo,kitti"], ["--sets", "kitti"]),
        (["--split", "validation"], ["--split", "validation"]),
        (["--families", "affine,zoom"], ["--families", "zoom"]),
        (["--peers", "flownet"], ["--peers", "flownet"]),
        (["--methods", "tvl1,nope"], ["nope"]),
        (["--photo-shape", "64by80"], ["--photo-shape"]),
        (["--photo-shape", "16x80"], ["--photo-shape"]),
        (["--sets", "middlebury", "--families", "affine"], ["--families", "photo"]),
        (["--sets", "middlebury", "--split", "tuning"], ["--split", "photo"]),
        (["--methods", "", "--peers", "none"], ["--methods"]),
        (["--csv", "out.txt"], ["--csv", ".csv"]),
        (["--flux", "3"], ["--flux"]),
    ],
)
def test_cli_option_errors(capsys, args, needles):
    rc, out, err = _run(capsys, "bench", "twoframe", "--quiet", *args)
    _one_line_error(rc, err, *needles)
    assert out == ""


def test_cli_missing_data_one_line(capsys, tmp_path):
    rc, _, err = _run(capsys, "bench", "twoframe", "--sets", "middlebury", "--data",
                      tmp_path / "none", "--quiet")
    _one_line_error(rc, err, "Middlebury", "--data", "VARFLOW_DATA")
    # checked before the photo pairs run
    rc, out, err = _run(capsys, "bench", "twoframe", "--sets", "photo,middlebury", "--data",
                        tmp_path / "none", "--quiet")
    _one_line_error(rc, err, "Middlebury")
    assert out == ""
    rc, _, err = _run(capsys, "bench", "twoframe", "--sets", "sintel", "--data", tmp_path,
                      "--quiet")
    _one_line_error(rc, err, "Sintel", "VARFLOW_DATA")


def test_cli_tiny_photo_run(capsys, tmp_path):
    peers = "dis" if HAVE_CV2 else "none"
    out_csv = tmp_path / "tf.csv"
    rc, out, err = _run(capsys, "bench", "twoframe", "--sets", "photo", "--split", "tuning",
                        "--families", "affine", "--photo-shape", "48x64", "--peers", peers,
                        "--csv", out_csv, "--quiet", "--max-iterations", "30")
    assert rc == 0, err
    assert out.splitlines()[0].startswith("Two-frame benchmark (photo)")
    assert "parameters changed: max_iterations=30" in out.splitlines()[0]
    t = _table_rows(out)
    assert {"affine/0", "affine/1", "affine/2", "mean", "total s"} <= set(t)
    assert ("ratio to tvl1" in t) == HAVE_CV2
    n_methods = 2 if HAVE_CV2 else 1
    assert len(out_csv.read_text().splitlines()) == 1 + 3 * n_methods
    assert f"wrote {out_csv}" in out


def test_cli_reports_unavailable_peer(capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "cv2", None)
    rc, out, err = _run(capsys, "bench", "twoframe", "--sets", "photo", "--split", "tuning",
                        "--families", "affine", "--photo-shape", "48x64", "--peers", "dis",
                        "--quiet")
    assert rc == 0, err
    assert "peer dis unavailable: OpenCV is not installed" in out
    assert "dis AEE" not in out and "tvl1 AEE" in out


def test_cli_on_fake_data_folder(capsys, fake_root):
    rc, out, err = _run(capsys, "bench", "twoframe", "--sets", "middlebury,sintel", "--data",
                        fake_root, "--quiet", "--max-iterations", "20", "--n-warps", "2")
    assert rc == 0, err
    assert f"data {fake_root}" in out.splitlines()[0]
    assert "Sintel alley_1 final 1->2 not found; skipped" in out
    t = _table_rows(out)
    assert t["cave_2 final 2->3"][1] == "large" and t["alley_2 clean 2->3"][1] == "small"
    assert "mean large motion (1)" in t and "Grove2" in t


# --------------------------------------------------------------------------- real data


@pytest.mark.data
def test_real_middlebury_set(data_root: Path) -> None:
    pairs = list(bt.middlebury_set(data_root))
    assert [p.sequence for p in pairs] == list(MIDDLEBURY_SEQUENCES)
    for p in pairs:
        assert p.frame0.dtype == np.uint8 and p.frame0.shape[:2] == p.gt.shape[:2]
        assert p.occlusion is None


@pytest.mark.data
def test_real_sintel_pairs_and_motion_classes(data_root: Path) -> None:
    present, missing = bt.sintel_pairs_present(data_root)
    assert missing == [] and present == list(bt.SINTEL_PAIRS)
    classes = {}
    for p in bt.sintel_set(data_root):
        assert p.frame0.shape == (436, 1024, 3) and p.gt.shape == (436, 1024, 2)
        classes[p.sequence] = bt._motion(p)["motion"]
        # alley_1 has its occlusion and invalid masks for frame 2 only
        assert (p.occlusion is None) == (p.sequence == "alley_1 final 1->2")
        assert (p.mask is None) == (p.sequence == "alley_1 final 1->2")
    assert classes == {
        "alley_1 final 1->2": "small",
        "alley_2 clean 2->3": "small",
        "bandage_1 final 35->36": "small",
        "cave_2 clean 2->3": "large",
        "cave_2 final 2->3": "large",
        "market_5 clean 2->3": "large",
        "market_5 final 9->10": "large",
    }
