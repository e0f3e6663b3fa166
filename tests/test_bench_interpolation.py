"""The interpolation benchmark: peers, sets and splits, runner, tables and CLI.

Most tests run on a tiny fake data tree written to ``tmp_path`` (the layout of
``../shared/data``); the tests on the real data use the ``data_root`` fixture
(skipped without the data, required when ``VARFLOW_REQUIRE_DATA=1``).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.ndimage import gaussian_filter

from varflow import cli
from varflow.evaluation import interpolation_sets as isets
from varflow.evaluation.bench import interpolation as bi
from varflow.evaluation.frame_metrics import psnr
from varflow.evaluation.interpolation_peers import blend, minterpolate, minterpolate_times, repeat
from varflow.retime import methods as rm


def _run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def _texture(h: int, w: int, seed: int, pad: int = 16) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.random((h + 2 * pad, w + 2 * pad, 3))
    base = np.stack([gaussian_filter(base[..., c], 2.0) for c in range(3)], -1)
    return np.rint((base - base.min()) / (base.max() - base.min()) * 255).astype(np.uint8)


def _shifted(base: np.ndarray, h: int, w: int, dy: int, dx: int, pad: int = 16) -> np.ndarray:
    return np.ascontiguousarray(base[pad + dy:pad + dy + h, pad + dx:pad + dx + w])


# --------------------------------------------------------------------------- peers


def test_minterpolate_lands_halfway_on_a_translation() -> None:
    h, w = 72, 96
    base = _texture(h, w, seed=0)
    f0, f1, mid = _shifted(base, h, w, 0, 0), _shifted(base, h, w, 2, 8), _shifted(base, h, w,
                                                                                    1, 4)
    out = minterpolate(f0, f1, 0.5)
    assert out.dtype == np.uint8 and out.shape == f0.shape
    p_mid = psnr(out, mid)
    # measured: 24.3 dB to the true middle, 19.6 for blend, 19.2 / 19.1 to the inputs
    assert p_mid > psnr(blend(f0, f1, 0.5), mid) + 3.0
    assert p_mid > max(psnr(out, f0), psnr(out, f1)) + 3.0


def test_minterpolate_sizes_times_and_errors() -> None:
    rng = np.random.default_rng(1)
    for shape in ((37, 45, 3), (20, 24, 3)):  # odd sizes; sides below 32 are padded
        f0 = rng.integers(0, 256, shape).astype(np.uint8)
        f1 = np.roll(f0, 2, axis=1)
        out = minterpolate(f0, f1)
        assert out.shape == shape and out.dtype == np.uint8
        assert psnr(out, f0) < 60  # not a copy of an input
    stack = minterpolate_times(f0, f1, [0.0, 0.25, 1.0])
    assert stack.shape == (3, *f0.shape)
    assert np.array_equal(stack[0], f0) and np.array_equal(stack[2], f1)
    with pytest.raises(ValueError, match="k/n"):
        minterpolate(f0, f1, 0.123456789)
    with pytest.raises(ValueError, match="RGB"):
        minterpolate(f0[..., 0], f1[..., 0])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        minterpolate(f0, f1, 1.5)


def test_blend_and_repeat_values() -> None:
    f0 = np.full((2, 3, 3), 10, np.uint8)
    f1 = np.full((2, 3, 3), 21, np.uint8)
    assert np.all(blend(f0, f1, 0.5) == 16)  # 15.5 rounds half to even
    assert np.all(blend(f0, f1, 0.25) == 13)  # 12.75
    assert blend(f0, f1, 0.5).dtype == np.uint8
    g0, g1 = f0.astype(np.float32) / 255, f1.astype(np.float32) / 255
    b = blend(g0, g1, 0.5)
    assert b.dtype == np.float32 and np.allclose(b, 15.5 / 255)
    r = repeat(f0, f1, 0.5)  # tie: the earlier frame
    assert np.array_equal(r, f0) and r is not f0
    assert np.array_equal(repeat(f0, f1, 0.49), f0)
    assert np.array_equal(repeat(f0, f1, 0.51), f1)
    with pytest.raises(ValueError, match="dtype"):
        blend(f0, g1, 0.5)


# --------------------------------------------------------------------------- fake data


def _png(path: Path, rng: np.random.Generator, shape: tuple[int, int] = (36, 40)) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rng.integers(0, 256, (*shape, 3)).astype(np.uint8)).save(path)


@pytest.fixture(scope="module")
def fake_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("data")
    rng = np.random.default_rng(0)
    for seq in isets.MIDDLEBURY_INTERP_SEQUENCES:
        for f in ("frame10", "frame11", "frame10i11"):
            _png(root / "interpolation" / "middlebury" / seq / f"{f}.png", rng)
    for t in isets.UCF101_TRIPLETS:
        for f in ("frame0", "frame1", "frame2"):
            _png(root / "interpolation" / "ucf101" / t / f"{f}.png", rng)
    for n in range(1, 51):
        _png(root / "sintel" / "training" / "final" / "alley_1" / f"frame_{n:04d}.png", rng)
    return root


def test_split_rule_alternates_over_sorted_cases(fake_root: Path) -> None:
    counts = {"middlebury": (6, 6), "ucf101": (11, 10), "sintel": (12, 12),
              "sintel-x4": (18, 18)}
    for s in isets.INTERPOLATION_SETS:
        every = isets.interpolation_cases(s, "all", fake_root)
        names = [c.name for c in every]
        assert names == sorted(names)
        tuning = [c.name for c in isets.interpolation_cases(s, "tuning", fake_root)]
        reporting = [c.name for c in isets.interpolation_cases(s, "reporting", fake_root)]
        step = 3 if s == "sintel-x4" else 1  # x4: the groups of three times alternate
        groups = [names[i:i + step] for i in range(0, len(names), step)]
        assert tuning == sum(groups[0::2], []) and reporting == sum(groups[1::2], [])
        assert (len(tuning), len(reporting)) == counts[s]
        want = isets.X4_TIMES * 12 if s == "sintel-x4" else (0.5,) * len(every)
        assert tuple(c.t for c in every) == want
    assert [c.name for c in isets.interpolation_cases("middlebury", "tuning", fake_root)] == [
        "Beanbags", "DogDance", "Grove3", "MiniCooper", "Urban2", "Venus"]
    assert [isets.split_of(i) for i in range(4)] == ["tuning", "reporting"] * 2


def test_sintel_cases_and_context(fake_root: Path) -> None:
    cases = isets.interpolation_cases("sintel", "all", fake_root)
    assert [c.name for c in cases][:2] == ["frame_0003", "frame_0005"]
    assert cases[-1].name == "frame_0049"
    first, second, last = cases[0], cases[1], cases[-1]
    assert (first.frame0.name, first.gt.name, first.frame1.name) == (
        "frame_0002.png", "frame_0003.png", "frame_0004.png")
    assert first.previous is None and first.following.name == "frame_0006.png"
    assert second.previous.name == "frame_0002.png" and second.following.name == "frame_0008.png"
    assert last.following is None and last.previous.name == "frame_0046.png"
    frames = second.load()
    assert all(f.dtype == np.uint8 and f.shape == (36, 40, 3) for f in frames)
    assert first.load().previous is None
    ucf = isets.interpolation_cases("ucf101", "all", fake_root)[0]
    assert (ucf.frame0.name, ucf.frame1.name, ucf.gt.name) == ("frame0.png", "frame2.png",
                                                               "frame1.png")


def test_sintel_x4_cases(fake_root: Path) -> None:
    cases = isets.interpolation_cases("sintel-x4", "all", fake_root)
    assert len(cases) == 36 and cases[0].name == "frame_0002" and cases[-1].name == "frame_0048"
    # group c = 7: frames 5 and 9 give 6, 7, 8 at t = 1/4, 1/2, 3/4; context 1 and 13
    for case, (gt, t) in zip(cases[3:6], ((6, 0.25), (7, 0.5), (8, 0.75)), strict=True):
        assert (case.frame0.name, case.frame1.name, case.gt.name) == (
            "frame_0005.png", "frame_0009.png", f"frame_{gt:04d}.png")
        assert case.t == t and case.split == "reporting"
        assert (case.previous.name, case.following.name) == ("frame_0001.png", "frame_0013.png")
    assert cases[0].previous is None and cases[-1].following is None
    assert {c.split for c in cases[:3]} == {"tuning"}


def test_missing_data_names_the_path_and_the_variable(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as info:
        isets.interpolation_cases("middlebury", "reporting", tmp_path)
    text = str(info.value)
    assert "VARFLOW_DATA" in text and str(tmp_path / "interpolation" / "middlebury") in text
    with pytest.raises(ValueError, match="split"):
        isets.interpolation_cases("middlebury", "both", tmp_path)
    with pytest.raises(ValueError, match="sets"):
        isets.check_sets("middlebury,kitti")


@dataclass(frozen=True)
class _CtxParams:
    pass


class _BlendMotion(rm.PairMotion):
    def render(self, t: float) -> np.ndarray:
        return (1 - t) * self.frame0 + t * self.frame1


def test_context_methods_get_the_neighbours(fake_root: Path, monkeypatch) -> None:
    seen: list[tuple[bool, bool]] = []

    def prepare(frame0, frame1, params, previous=None, following=None, callback=None,
                stats=None, cache=None):
        seen.append((previous is not None, following is not None))
        return _BlendMotion(frame0, frame1)

    monkeypatch.setitem(rm.INTERPOLATORS, "fake-ctx",
                        rm.Interpolator(name="fake-ctx", description="test", defaults=_CtxParams,
                                        prepare=prepare, context=1))
    rows = bi.run_interpolation_bench(["sintel", "middlebury"], "all", ["fake-ctx"], ["blend"],
                                      root=fake_root, max_cases=2, progress=False,
                                      warm_up=False)
    assert [(r["set"], r["case"], r["method"]) for r in rows[:4]] == [
        ("middlebury", "Beanbags", "fake-ctx"), ("middlebury", "Beanbags", "blend"),
        ("middlebury", "Dimetrodon", "fake-ctx"), ("middlebury", "Dimetrodon", "blend")]
    ctx = {(r["case"], r["method"]): r["context"] for r in rows}
    assert ctx[("frame_0003", "fake-ctx")] == 1 and ctx[("frame_0005", "fake-ctx")] == 2
    assert ctx[("frame_0005", "blend")] == 0 and ctx[("Beanbags", "fake-ctx")] == 0
    assert seen == [(False, False), (False, False), (False, True), (True, True)]
    by = {(r["case"], r["method"]): r for r in rows}
    for case in ("Beanbags", "frame_0005"):  # the fake renders the cross-fade
        assert by[(case, "fake-ctx")]["psnr"] == pytest.approx(by[(case, "blend")]["psnr"],
                                                               abs=0.05)


def test_x4_groups_estimate_their_motion_once(fake_root: Path, monkeypatch) -> None:
    # the three times between one pair share the pair's flows (a FlowCache per method),
    # with the same frames as when every case estimates its own
    from varflow.twoframe import methods as tm

    calls: list[tuple[int, ...]] = []
    real = tm.run_method

    def counting(m, a, b, *args, **kwargs):
        calls.append(a.shape)
        return real(m, a, b, *args, **kwargs)

    monkeypatch.setattr(tm, "run_method", counting)

    def run() -> list[dict]:
        return bi.run_interpolation_bench(["sintel-x4"], "all", ["naive"], "none",
                                          root=fake_root, max_cases=3, progress=False,
                                          warm_up=False)

    shared = run()
    assert len(calls) == 2  # F01 and F10 of frames 1 -> 5, once for t = 1/4, 1/2, 3/4
    calls.clear()
    monkeypatch.setattr(bi, "SHARED_MOTION_SETS", frozenset())
    alone = run()
    assert len(calls) == 6
    assert [r["t"] for r in shared] == [0.25, 0.5, 0.75]
    assert [r["psnr"] for r in shared] == [r["psnr"] for r in alone]
    assert len({r["psnr"] for r in shared}) == 3  # three different frames


def test_format_tables_gains_and_wins() -> None:
    def row(case: str, method: str, p: float) -> dict:
        return {"set": "ucf101", "split": "reporting", "case": case, "method": method,
                "psnr": p, "ssim": 0.9, "ie": 5.0, "ne": 1.0, "mae": 2.0, "seconds": 0.5}

    rows = [row("a", "naive", 30.0), row("a", "minterpolate", 29.0), row("a", "blend", 25.0),
            row("b", "naive", 28.0), row("b", "minterpolate", 29.0), row("b", "blend", 27.0),
            row("c", "naive", 33.0), row("c", "minterpolate", 30.0), row("c", "blend", 26.0)]
    text = bi.format_tables(rows, per_case=False)
    lines = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[2:-1]]
             for ln in text.splitlines() if ln.startswith("| ") and "method" not in ln}
    # columns: n, PSNR, worst 10 %, SSIM, IE, NE, MAE, dPSNR vs minterpolate,
    # dPSNR vs naive, wins, s
    assert lines["naive"][0] == "3" and lines["naive"][1] == "30.33"
    assert lines["naive"][2] == "28.00" and lines["blend"][2] == "25.00"
    assert lines["naive"][7] == "1.00" and lines["naive"][8] == "-"
    assert lines["naive"][9] == "2/3"
    assert lines["blend"][7] == "-3.33" and lines["blend"][8] == "-4.33"
    assert lines["blend"][9] == "0/3"
    assert lines["minterpolate"][8] == "-1.00" and lines["minterpolate"][9] == "-"
    assert "3 cases, split reporting" in text
    assert "cases lost" not in text  # no varflow method among the rows
    rows = [dict(r, kind="varflow" if r["method"] == "naive" else "peer") for r in rows]
    text = bi.format_tables(rows, per_case=False)
    assert "- `naive`: b (28.00 / 29.00)" in text
    assert "means at t" not in text  # one time: no per-time tables


def test_worst_decile() -> None:
    assert bi.worst_decile([30.0, 20.0, 40.0]) == 20.0  # ceil(3 / 10) = 1 case
    values = [float(v) for v in range(11)] + [math.nan]
    assert bi.worst_decile(values) == 0.5  # ceil(11 / 10) = 2 cases, NaN left out
    assert math.isnan(bi.worst_decile([math.nan]))


def test_format_tables_per_time() -> None:
    def row(case: str, t: float, method: str, p: float) -> dict:
        return {"set": "sintel-x4", "split": "tuning", "case": case, "t": t, "method": method,
                "psnr": p, "ssim": 0.9, "ie": 5.0, "ne": 1.0, "mae": 2.0, "seconds": 0.5}

    rows = [row("frame_0002", 0.25, "splat", 36.0), row("frame_0002", 0.25, "minterpolate", 33.0),
            row("frame_0003", 0.5, "splat", 30.0), row("frame_0003", 0.5, "minterpolate", 31.0),
            row("frame_0004", 0.75, "splat", 34.0), row("frame_0004", 0.75, "minterpolate", 32.0)]
    text = bi.format_tables(rows, per_case=False)
    parts = text.split("\n\n")
    titles = [p for p in parts if p.startswith("MPI-Sintel")]
    assert [t.rsplit(", ", 1)[1] for t in titles] == [
        "means", "means at t = 0.25", "means at t = 0.5", "means at t = 0.75"]
    at_half = parts[parts.index(titles[2]) + 1]
    splat = next(ln for ln in at_half.splitlines() if ln.startswith("| splat"))
    cells = [c.strip() for c in splat.split("|")[1:-1]]
    assert cells[1:4] == ["1", "30.00", "30.00"] and cells[8] == "-1.00" and cells[10] == "0/1"


def test_timing_on_a_resized_pair(fake_root: Path) -> None:
    rows = bi.run_interpolation_timing([], "all", root=fake_root, repeats=2, shape=(54, 96),
                                       progress=False)
    assert [r["method"] for r in rows] == ["minterpolate", "blend", "repeat"]
    assert "Sintel final/alley_1 9 -> 11, resized to 96x54" in rows[0]["case"]
    by = {r["method"]: r for r in rows}
    assert by["minterpolate"]["ratio_minterpolate"] == pytest.approx(1.0)
    assert by["repeat"]["ratio_minterpolate"] < 1.0
    assert by["blend"]["seconds_min"] <= by["blend"]["seconds"]
    assert all(r["repeats"] == 2 for r in rows)
    assert "alley_1 frames 5, 7, ..., 15, resized to 96x54" in rows[0]["clip"]
    assert by["minterpolate"]["ratio_minterpolate_stream"] == pytest.approx(1.0)
    assert all(r["seconds_stream"] > 0 for r in rows)
    _, frames = bi.timing_pair(fake_root, (54, 96))
    # writable copies, like the frames of the sets (not read-only views of PIL images)
    assert all(f.shape == (54, 96, 3) and f.flags.writeable for f in frames)
    label, clip = bi.timing_clip(fake_root, (54, 96), n=4)
    assert len(clip) == 4 and all(f.shape == (54, 96, 3) for f in clip)
    text = bi.format_timing_table(rows)
    assert "stream s/frame" in text and "x2 slow motion" in text


def test_minterpolate_stream_matches_the_pairs() -> None:
    """A stream gives the in-between frames in order; its first pairs are the frames
    minterpolate gives for the pairs alone (the frame after a pair does not change
    them)."""
    from varflow.evaluation.interpolation_peers import minterpolate, minterpolate_stream

    rng = np.random.default_rng(3)
    frames = [np.clip(rng.normal(128, 40, (36, 44, 3)), 0, 255).astype(np.uint8)
              for _ in range(4)]
    out = minterpolate_stream(frames, 2)
    assert len(out) == 3
    for i in range(2):
        np.testing.assert_array_equal(out[i], minterpolate(frames[i], frames[i + 1], 0.5))
    assert len(minterpolate_stream(frames, 3)) == 6
    with pytest.raises(ValueError, match="factor"):
        minterpolate_stream(frames, 1)
    with pytest.raises(ValueError, match="frames"):
        minterpolate_stream(frames[:1], 2)


# --------------------------------------------------------------------------- CLI


@pytest.mark.parametrize("args, needle", [
    (["--sets", "middlebury,kitti"], "--sets: unknown set 'kitti'"),
    (["--methods", "nope"], "--methods: unknown interpolation method 'nope'"),
    (["--peers", "ffmpeg"], "--peers: unknown peer 'ffmpeg'"),
    (["--split", "both"], "invalid choice: 'both'"),
    (["--max-cases", "0"], "--max-cases: must be at least 1"),
    (["--timing-only", "--no-timing"], "--timing-only: contradicts --no-timing"),
    (["--methods", "", "--peers", "none"], "give at least one interpolation method or peer"),
])
def test_cli_bad_options(capsys, args, needle) -> None:
    rc, out, err = _run(capsys, "bench", "interpolation", "--quiet", *args)
    assert rc == 2
    assert needle in err
    assert len(err.strip().splitlines()) == 1
    assert out == ""


def test_cli_missing_data_one_line(capsys, tmp_path: Path) -> None:
    rc, out, err = _run(capsys, "bench", "interpolation", "--quiet", "--no-timing",
                        "--methods", "", "--data", tmp_path)
    assert rc == 2
    assert "VARFLOW_DATA" in err and str(tmp_path / "interpolation" / "middlebury") in err
    assert len(err.strip().splitlines()) == 1


def test_cli_peers_on_fake_data_with_csv(capsys, fake_root: Path, tmp_path: Path) -> None:
    out_csv = tmp_path / "rows.csv"
    rc, out, err = _run(capsys, "bench", "interpolation", "--quiet", "--methods", "",
                        "--peers", "blend,repeat", "--sets", "ucf101", "--max-cases", "2",
                        "--timing-repeats", "1", "--data", fake_root, "--csv", out_csv)
    assert rc == 0, err
    assert "UCF101 triplets (frame0, frame2 -> frame1): 2 cases, split reporting" in out
    assert "Timing:" in out
    with open(out_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["set"] for r in rows] == ["ucf101"] * 4 + ["timing"] * 2
    assert [r["case"] for r in rows[:4]] == ["02", "02", "04", "04"]
    assert list(rows[0])[:13] == list(bi.INTERPOLATION_CSV_FIELDS)
    assert [float(r["t"]) for r in rows[:4]] == [0.5] * 4
    assert all(math.isfinite(float(r["psnr"])) for r in rows)


# --------------------------------------------------------------------------- real data


@pytest.mark.data
def test_real_middlebury_bench(data_root: Path) -> None:
    rows = bi.run_interpolation_bench(["middlebury"], "reporting", ["naive", "splat"], "all",
                                      root=data_root, max_cases=1, progress=False)
    by = {r["method"]: r for r in rows}
    assert list(by) == ["naive", "splat", "minterpolate", "blend", "repeat"]
    assert {r["case"] for r in rows} == {"Dimetrodon"}
    # measured on Dimetrodon: splat 42.1 dB, naive 40.1, minterpolate 38.1, blend 32.5,
    # repeat 28.9
    assert by["splat"]["psnr"] > by["minterpolate"]["psnr"] + 2.5
    assert by["splat"]["psnr"] > by["naive"]["psnr"] + 1.0
    assert by["naive"]["psnr"] > by["blend"]["psnr"] + 4
    assert by["minterpolate"]["psnr"] > by["blend"]["psnr"] + 4
    assert by["blend"]["psnr"] > by["repeat"]["psnr"] + 2
    assert 36 < by["minterpolate"]["psnr"] < 41
    for r in rows:
        assert r["ne"] < r["ie"]
        assert 0.8 < r["ssim"] < 1.0


@pytest.mark.data
def test_real_cli_run(capsys, data_root: Path, tmp_path: Path) -> None:
    out_csv = tmp_path / "real.csv"
    rc, out, err = _run(capsys, "bench", "interpolation", "--quiet", "--no-timing",
                        "--sets", "sintel", "--max-cases", "1", "--methods", "naive,splat",
                        "--peers", "minterpolate,blend", "--data", data_root, "--csv", out_csv)
    assert rc == 0, err
    assert "frame_0005" in out and "Timing:" not in out
    with open(out_csv, newline="") as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    assert list(rows) == ["naive", "splat", "minterpolate", "blend"]
    psnr = {m: float(r["psnr"]) for m, r in rows.items()}
    assert psnr["naive"] > psnr["blend"]
    # measured on frame_0005 (frames 4, 6 with the context 2 and 8): splat 38.4 dB,
    # naive 36.6, minterpolate 35.8
    assert psnr["splat"] > psnr["minterpolate"] + 1.5
    assert psnr["splat"] > psnr["naive"] + 1.0
    assert rows["naive"]["context"] == "0" and rows["splat"]["context"] == "2"
