"""The denoising benchmark: FFmpeg's peers, SSIM, the runner, its tables and CLI.

The peers, SSIM, the tables and the option errors run on tiny synthetic clips (no
data); the runner, ``varflow bench denoise`` and the 8-bit case through ``varflow
denoise`` run on a 48x64 crop of 3 frames of carphone with the ``data_root`` fixture
(skipped without the data, required when ``VARFLOW_REQUIRE_DATA=1``) with one Numba
thread (on frames this small parallel kernels only add overhead, and a great deal of
it on a loaded machine).
"""

from __future__ import annotations

import csv
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skimage")

from varflow import cli  # noqa: E402
from varflow.evaluation import denoising as dn  # noqa: E402

HAVE_CV2 = importlib.util.find_spec("cv2") is not None
HAVE_DENOISE_CLI = importlib.util.find_spec("varflow.cli.denoise") is not None
QUICK = ("--clips", "carphone", "--sigmas", "20", "--frames", "3", "--crop", "48x64")


def _static_clip(frames: int = 4, shape: tuple[int, int] = (48, 64)) -> np.ndarray:
    """A still photograph repeated: ``(frames, H, W, 3)`` float32 on 0-255."""
    from varflow.generators.photo import load_photo

    photo = load_photo("astronaut")[100:100 + shape[0], 200:200 + shape[1]] * 255.0
    return np.repeat(photo[None].astype(np.float32), frames, axis=0)


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


def _table_rows(text: str) -> list[list[str]]:
    """The cells of every Markdown body row of ``text`` (header rows left out)."""
    lines = text.splitlines()
    return [[c.strip() for c in ln.strip().strip("|").split("|")]
            for ln, nxt in zip(lines, [*lines[1:], ""], strict=True)
            if ln.startswith("| ") and not nxt.startswith("|-")]


# --------------------------------------------------------------------------- FFmpeg


@pytest.mark.parametrize("peer", [dn.ffmpeg_atadenoise, dn.ffmpeg_fftdnoiz])
def test_ffmpeg_peers_denoise_a_small_clip(peer) -> None:
    clean = _static_clip()
    noisy = dn.add_noise(clean, 20)
    out = peer(noisy, 20)
    assert out.shape == clean.shape and out.dtype == np.float32
    assert np.array_equal(out, np.rint(out)) and out.min() >= 0 and out.max() <= 255
    # measured: noisy 22.3 dB, atadenoise 25.7, fftdnoiz 27.9
    assert dn.clip_psnr(out, clean) > dn.clip_psnr(noisy, clean) + 1.0
    assert np.array_equal(peer(noisy.astype(np.float64), 20), out)  # any float dtype


def test_ffmpeg_filter_clip_is_exact_and_keeps_every_frame() -> None:
    rng = np.random.default_rng(0)
    clip8 = rng.integers(0, 256, (5, 20, 30, 3)).astype(np.uint8)
    same = dn.ffmpeg_filter_clip(clip8, "null", "")
    assert same.dtype == np.uint8 and np.array_equal(same, clip8)  # gbrp: no loss
    clip16 = rng.integers(0, 65536, (3, 20, 30, 3)).astype(np.uint16)
    assert np.array_equal(dn.ffmpeg_filter_clip(clip16, "null", ""), clip16)
    # temporal filters hold frames back: the flush gives them all out
    assert dn.ffmpeg_filter_clip(clip8, "fftdnoiz", "sigma=5:prev=1:next=1").shape == clip8.shape
    assert dn.ffmpeg_filter_clip(clip8, "atadenoise", "s=9").shape == clip8.shape
    with pytest.raises(ValueError, match="refuses"):
        dn.ffmpeg_filter_clip(clip8, "atadenoise", "s=3")  # below FFmpeg's 5
    with pytest.raises(ValueError, match="RGB"):
        dn.ffmpeg_filter_clip(clip8[..., 0], "null", "")


def test_ffmpeg_options_follow_sigma() -> None:
    ata = dict(kv.split("=") for kv in dn.atadenoise_options(20).split(":"))
    scale = dn.FFMPEG_DOWNSCALE * 255
    assert float(ata["0a"]) == pytest.approx(dn.ATADENOISE_A * 20 / scale, rel=1e-5)
    assert float(ata["2b"]) == pytest.approx(dn.ATADENOISE_B * 20 / scale, rel=1e-5)
    assert ata["s"] == "9" and ata["a"] == "s"
    fft = dict(kv.split("=") for kv in dn.fftdnoiz_options(40).split(":"))
    assert float(fft["sigma"]) == pytest.approx(dn.FFTDNOIZ_POWER * 25)
    assert fft["prev"] == fft["next"] == "1"
    assert "sigma=100:" in dn.fftdnoiz_options(500)  # FFmpeg's bound


# --------------------------------------------------------------------------- SSIM


def test_ssim_clip() -> None:
    clean = _static_clip(3)
    assert dn.ssim_clip(clean, clean) == pytest.approx(1.0)
    noisy = dn.add_noise(clean, 20)
    low = dn.ssim_clip(noisy, clean)
    assert 0.2 < low < 0.9
    assert dn.ssim_clip(dn.add_noise(clean, 5), clean) > low
    # clipped to [0, 255] first, as clip_psnr
    assert dn.ssim_clip(np.clip(clean + 300, 0, None), np.full_like(clean, 255.0)) == \
        pytest.approx(1.0)
    assert dn.ssim_clip(clean[..., 0], clean[..., 0]) == pytest.approx(1.0)  # grey
    with pytest.raises(ValueError, match="differs"):
        dn.ssim_clip(clean[:2], clean)


# --------------------------------------------------------------------------- names, tables


def test_peer_and_method_names() -> None:
    assert dn.check_denoise_peers(None) == list(dn.DENOISE_PEERS)
    assert dn.check_denoise_peers("all") == list(dn.DENOISE_PEERS)
    assert dn.check_denoise_peers("none") == []
    assert dn.check_denoise_peers("per-frame,atadenoise") == ["atadenoise", "per-frame"]
    with pytest.raises(ValueError, match="^peers: unknown peer 'vbm3d'"):
        dn.check_denoise_peers("vbm3d")
    assert set(dn.check_restore_methods(None)) >= {"nlbayes", "nlbayes-fast"}
    assert dn.check_restore_methods("") == []
    with pytest.raises(ValueError, match="^methods: unknown restoration method"):
        dn.check_restore_methods("nlmeans")
    assert dn.reference_method(["nlbayes-fast", "nlbayes"]) == "nlbayes"
    assert dn.reference_method(["nlbayes-fast"]) == "nlbayes-fast"
    assert [dn.split_of(c) for c in ("bikes", "alley_1")] == ["tuning", "reporting"]


def _fake_rows() -> list[dict]:
    rows = []
    for clip, psnr in (("carphone", 30.0), ("alley_1", 32.0), ("sintel-demo", 34.0)):
        for method, kind, sec in (("noisy", "input", None), ("nlbayes", "varflow", 2.0),
                                  ("opencv-nlm", "peer", 0.5)):
            rows.append({"clip": clip, "split": dn.split_of(clip), "sigma": 30,
                         "method": method, "kind": kind,
                         "sigma_used": None if sec is None else 30.0, "frames": 20,
                         "height": 48, "width": 64,
                         "psnr": psnr - (8 if sec is None else 0) - (sec or 0),
                         "ssim": 0.9, "temporal_error": 3.0, "seconds_per_frame": sec,
                         "ratio_opencv_nlm": None if sec is None else sec / 0.5,
                         **dn._vbm3d(clip, 30, True)})
    return rows


def test_tables_list_every_row_and_the_reporting_means(tmp_path: Path) -> None:
    rows = _fake_rows()
    text = dn.format_denoise_tables(rows)
    body = _table_rows(text)
    assert len(body) == len(rows) + 3  # the rows, then a line per method of the means
    head, means = text.split("Means over the reporting clips")
    assert "(alley_1, sintel-demo)" in means
    line = {r[1]: r for r in _table_rows(means)}["nlbayes"]
    # σ, method, clips, PSNR (mean of 30 and 32), SSIM, temp. err, s/frame, x NLM, V-BM3D
    assert line == ["30", "nlbayes", "2", "31.00", "0.9000", "3.00", "2.000", "4.00",
                    f"{(34.54 + 32.05) / 2:.2f}"]
    assert {r[1] for r in _table_rows(head)} == {"tuning", "reporting"}
    # read back from CSV (strings, empty cells): the same tables
    from varflow.evaluation.bench.common import write_csv

    write_csv(rows, tmp_path / "rows.csv", dn.DENOISE_CSV_FIELDS)
    with open(tmp_path / "rows.csv", newline="") as f:
        assert dn.format_denoise_tables(list(csv.DictReader(f))) == text
    tuning_only = dn.format_denoise_tables([r for r in rows if r["split"] == "tuning"])
    assert "none in this run" in tuning_only


# --------------------------------------------------------------------------- CLI errors


@pytest.mark.parametrize(("args", "needles"), [
    (("--crop", "48by64"), ("--crop", "HxW")),
    (("--sigmas", "10,x"), ("--sigmas",)),
    (("--sigmas", "0"), ("--sigmas", "positive")),
    (("--frames", "1"), ("--frames", "at least 2")),
    (("--peers", "vbm3d"), ("--peers", "vbm3d")),
    (("--methods", "nlmeans"), ("--methods", "nlmeans")),
    (("--methods", "", "--peers", "none"), ("--methods",)),
    (("--clips", "foreman", "--peers", "atadenoise", "--methods", ""), ("--clips", "foreman")),
    (("--crop", "4x4"), ("--crop", "too small")),
    # tmp_path holds no data: the error says where it looked and how to point elsewhere
    (("--peers", "atadenoise", "--methods", ""), ("no frames of the clip bikes",
                                                  "VARFLOW_DATA")),
])
def test_bad_options_are_one_line_errors(capsys, tmp_path: Path, args, needles) -> None:
    rc, out, err = _run(capsys, "bench", "denoise", "--data", tmp_path, *args)
    _one_line_error(rc, err, *needles)
    assert out == ""  # checked before the title


# --------------------------------------------------------------------------- real data


@pytest.mark.data
def test_run_denoise_benchmark_on_a_crop(data_root: Path, one_numba_thread) -> None:
    peers = "per-frame,atadenoise,fftdnoiz" + (",opencv-nlm" if HAVE_CV2 else "")
    seen: list[tuple[int, int]] = []
    rows = dn.run_denoise_benchmark(data_root, "carphone", [20], 3, "nlbayes-fast", peers,
                                    crop=(48, 64), callback=lambda d, t: seen.append((d, t)))
    labels = [r["method"] for r in rows]
    runs = ["nlbayes-fast", "nlbayes-fast" + dn.ESTIMATED_SUFFIX]
    runs += (["opencv-nlm"] if HAVE_CV2 else []) + ["atadenoise", "fftdnoiz", "per-frame"]
    assert labels == ["noisy", *runs]
    assert seen == [(k + 1, len(runs)) for k in range(len(runs))]
    for r in rows:
        assert list(r)[:len(dn.DENOISE_CSV_FIELDS)] == list(dn.DENOISE_CSV_FIELDS)
        assert (r["clip"], r["split"], r["sigma"]) == ("carphone", "tuning", 20)
        assert (r["frames"], r["height"], r["width"]) == (3, 48, 64)
        assert all(math.isfinite(r[k]) for k in ("psnr", "ssim", "temporal_error"))
        assert r["vbm3d_psnr"] is None  # not the protocol's frames
        if r["kind"] != "input":
            assert math.isfinite(r["seconds_per_frame"]) and r["seconds_per_frame"] > 0
            assert (r["ratio_opencv_nlm"] is not None) == HAVE_CV2
    by = {r["method"]: r for r in rows}
    assert by["noisy"]["seconds_per_frame"] is None and by["noisy"]["sigma_used"] is None
    assert by["per-frame"]["base_method"] == "nlbayes-fast"
    assert abs(by["nlbayes-fast" + dn.ESTIMATED_SUFFIX]["sigma_used"] - 20) < 2
    for label in runs:  # every denoiser gains on the noisy input
        assert by[label]["psnr"] > by["noisy"]["psnr"] + 1.0, label
        assert by[label]["ssim"] > by["noisy"]["ssim"], label


@pytest.mark.data
def test_cli_bench_denoise_prints_the_table(capsys, data_root: Path, tmp_path: Path,
                                            one_numba_thread) -> None:
    out_csv = tmp_path / "denoise.csv"
    rc, out, err = _run(capsys, "bench", "denoise", *QUICK, "--methods", "nlbayes-fast",
                        "--peers", "per-frame,atadenoise", "--data", data_root, "-q",
                        "--csv", out_csv)
    assert rc == 0, err
    body = _table_rows(out)
    assert [r[3] for r in body] == ["noisy", "nlbayes-fast",
                                    "nlbayes-fast" + dn.ESTIMATED_SUFFIX, "atadenoise",
                                    "per-frame"]
    assert all(r[:3] == ["carphone", "tuning", "20"] for r in body)
    assert "none in this run" in out and f"wrote {out_csv}" in out
    rc, _, err = _run(capsys, "bench", "denoise", "--clips", "carphone", "--crop", "200x64",
                      "--data", data_root)
    _one_line_error(rc, err, "--crop: 200x64 (HxW) exceeds the 144x176 frames of carphone")
    with open(out_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[:len(dn.DENOISE_CSV_FIELDS)] == list(dn.DENOISE_CSV_FIELDS)
    assert all(math.isfinite(float(r["psnr"])) for r in rows)


@pytest.mark.data
@pytest.mark.skipif(not HAVE_DENOISE_CLI, reason="varflow denoise CLI not present")
def test_cli_case_through_varflow_denoise(data_root: Path, monkeypatch) -> None:
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")  # the command's process: tiny frames
    case = dn.run_cli_case(data_root, "carphone", 20, frames=3, crop=(48, 64), timeout=300)
    assert (case["frames"], case["height"], case["width"]) == (3, 48, 64)
    assert case["command"] == "varflow denoise IN.mkv -o OUT.mkv --sigma 20"
    assert case["psnr"] > case["noisy_psnr"] + 5 and case["ssim"] > case["noisy_ssim"]
    assert case["temporal_error"] < case["noisy_temporal_error"]
    assert case["seconds_per_frame"] > 0
    table = dn.format_cli_case(case)
    assert [r[0] for r in _table_rows(table)] == ["noisy (uint8)", "varflow denoise"]
