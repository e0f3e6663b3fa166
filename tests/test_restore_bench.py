"""The film-restoration benchmark: its scores, peers, tables, and a tiny run on data.

The scores run on planted cases whose answers are exact (no data); the end-to-end run
is the dirt case on 4 frames of a 64x96 crop of carphone with the ``data_root``
fixture (skipped without the data, required when ``VARFLOW_REQUIRE_DATA=1``) with one
Numba thread.
"""

from __future__ import annotations

import math
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from varflow.evaluation import restoration as rs
from varflow.evaluation.defects import plant_weave, weave_residual


def _texture(frames: int = 4, shape: tuple[int, int] = (64, 80), seed: int = 0) -> np.ndarray:
    """A smooth random picture repeated: ``(frames, H, W, 3)`` float32 in 40-215."""
    rng = np.random.default_rng(seed)
    base = cv2.GaussianBlur(rng.uniform(0, 255, shape).astype(np.float32), (0, 0), 2.0)
    base = 40 + 175 * (base - base.min()) / (base.max() - base.min())
    rgb = np.stack([base, base * 0.8 + 20, 255 - base], axis=-1)
    return np.repeat(rgb[None], frames, axis=0).astype(np.float32)


# --------------------------------------------------------------------------- scores


def test_precision_recall_of_known_masks() -> None:
    truth = np.zeros((2, 10, 10), bool)
    truth[0, 2:4, 2:6] = True  # 8 pixels
    found = np.zeros_like(truth)
    found[0, 2:4, 4:6] = True  # 4 of them
    found[1, 0, 0:2] = True  # 2 false alarms
    assert rs.mask_precision_recall(found, truth) == (4 / 6, 4 / 8)
    p, r = rs.mask_precision_recall(np.zeros_like(truth), truth)
    assert math.isnan(p) and r == 0.0


def test_residual_flicker_of_a_known_offset_sequence() -> None:
    clean = _texture(4)
    offsets = np.array([1.0, -1.0, 1.0, -1.0], np.float32)
    assert rs.residual_flicker(clean + offsets[:, None, None, None], clean) == \
        pytest.approx(1.0, abs=1e-5)
    steps = np.array([0.0, 2.0, 4.0, 6.0], np.float32)  # std sqrt(5), ddof 0
    assert rs.residual_flicker(clean + steps[:, None, None, None], clean) == \
        pytest.approx(math.sqrt(5.0), abs=1e-5)
    assert rs.residual_flicker(clean + 7.0, clean) == pytest.approx(0.0, abs=1e-5)


def test_psnr_over_masked_subsets() -> None:
    clean = _texture(3)
    mask = np.zeros(clean.shape[:3], bool)
    mask[1, 10:20, 10:30] = True
    out = clean.copy()
    out[mask] += 5.0
    assert rs.masked_psnr(out, clean, mask) == pytest.approx(20 * math.log10(255 / 5), abs=1e-4)
    assert rs.masked_psnr(out, clean, ~mask) == math.inf
    assert math.isnan(rs.masked_psnr(out, clean, np.zeros_like(mask)))
    out[0, 0, 0] = 300.0  # clipped to 255 first, as clip_psnr
    out[0, 0, 1] = clean[0, 0, 1] + 10.0
    one = np.zeros_like(mask)
    one[0, 0, 1] = True
    assert rs.masked_psnr(out, clean, one) == pytest.approx(20 * math.log10(25.5), abs=1e-4)


def test_dirt_case_scores_against_the_planted_mask() -> None:
    clean = _texture(4, (64, 80))
    degraded, truth = rs.plant_case(clean, "dirt", rs.case_seed("synthetic", "dirt"))
    mask = truth["mask"]
    fixed = np.where(mask[..., None], clean, degraded)  # a perfect repair
    sc = rs.score_restoration(fixed, clean, "dirt", truth, found_mask=mask)
    assert sc["precision"] == sc["recall"] == 1.0
    assert sc["psnr_untouched"] > 45 and sc["psnr_blotched"] == math.inf  # rims < 8 levels
    none = rs.score_restoration(degraded, clean, "dirt", truth)
    assert none["psnr_blotched"] < 25 and none["precision"] is None
    assert none["psnr_centre"] is None and none["jitter"] is None


def test_case_seed_is_stable_and_per_case() -> None:
    assert rs.case_seed("bikes", "dirt") == zlib.crc32(b"bikes:dirt")
    assert rs.case_seed("bikes", "dirt", 5) == (zlib.crc32(b"bikes:dirt") + 5) % 2**32
    assert len({rs.case_seed(c, k) for c in ("bikes", "carphone") for k in rs.RESTORE_CASES}) \
        == 8
    a, _ = rs.plant_case(_texture(3), "all", 7)
    b, _ = rs.plant_case(_texture(3), "all", 7)
    assert np.array_equal(a, b)
    with pytest.raises(ValueError, match="case"):
        rs.plant_case(_texture(3), "scratches", 0)


def test_jitter_from_transforms_and_by_registration() -> None:
    clean = _texture(4, (96, 112))
    woven, weave = plant_weave(clean, seed=3)
    truth = {"mask": None, "weave": weave, "flicker": None}
    planted = weave_residual(None, weave)
    assert planted.mean() > 1.5
    # registration of the woven clip to the clean one finds the planted weave (OpenCV's
    # ECC on these small smooth frames: within 0.1-0.5 px, measured)
    assert np.allclose(rs.registration_jitter(woven, clean), planted, atol=0.6)
    assert rs.registration_jitter(clean, clean).max() < 0.02
    # the exact correction (the inverse of the weave) leaves no jitter
    exact = np.stack([cv2.invertAffineTransform(m) for m in weave.matrices])
    sc = rs.score_restoration(clean, clean, "weave", truth, transforms=exact)
    assert sc["jitter"] == pytest.approx(0.0, abs=1e-9)
    assert sc["jitter_registered"] < 0.02 and sc["psnr_centre"] == math.inf
    sc = rs.score_restoration(woven, clean, "weave", truth,
                              transforms=np.repeat(np.eye(2, 3)[None], 4, axis=0))
    assert sc["jitter"] == pytest.approx(planted.mean())


def _fourier_shifted(base: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """``base`` moved by each ``(dx, dy)`` exactly (circularly, by the shift theorem)."""
    from scipy import ndimage

    spectrum = np.fft.fft2(base)
    return np.stack([np.fft.ifft2(ndimage.fourier_shift(spectrum, (dy, dx))).real
                     for dx, dy in shifts])


def test_weave_agreement_of_known_shifts() -> None:
    rng = np.random.default_rng(4)
    base = cv2.GaussianBlur(rng.uniform(0, 255, (160, 192)), (0, 0), 1.0)
    clean = np.repeat(base[None], 8, axis=0)
    planted = rng.uniform(-4, 4, size=(8, 2))
    woven = _fourier_shifted(base, planted)
    # sub-pixel shifts found within 0.06 px (measured 0.022)
    assert np.abs(rs.frame_shifts(clean, woven) - planted).max() < 0.06
    second = planted[2:] - 2 * planted[1:-1] + planted[:-2]
    exact = math.sqrt(np.mean(np.sum(second ** 2, axis=1)))
    assert exact > 5.0  # ±4 px independent shifts: about 8 px
    assert rs.weave_agreement(woven, clean) == pytest.approx(exact, abs=0.15)  # -0.054
    # a smooth drift between the two clips is not jitter; identical clips agree
    drift = _fourier_shifted(base, np.array([[0.5 * t, 0.3 * t] for t in range(8)]))
    assert rs.weave_agreement(drift, clean) < 0.05  # measured 0.014
    assert rs.weave_agreement(clean, clean) == 0.0
    with pytest.raises(ValueError, match="3 frames"):
        rs.weave_agreement(woven[:2], clean[:2])
    with pytest.raises(ValueError, match="shape"):
        rs.weave_agreement(woven[:, :90], clean)


# --------------------------------------------------------------------------- peers


def test_tmedian_keeps_every_frame() -> None:
    clip = np.stack([np.full((16, 24, 3), 10.0 * t, np.float32) for t in range(5)])
    clip[2, 4:8, 4:8] = 250.0  # a blotch on one frame
    out = rs.ffmpeg_tmedian(clip, 1)
    # mirrored ends: median(10, 0, 10) = 10 for frame 0, median(30, 40, 30) for frame 4
    assert out.shape == clip.shape
    assert [float(out[t, 0, 0, 0]) for t in range(5)] == [10.0, 10.0, 20.0, 30.0, 30.0]
    assert float(out[2, 5, 5, 0]) == 30.0  # the blotch is gone
    assert rs.ffmpeg_tmedian(clip, 2).shape == clip.shape
    assert rs.ffmpeg_chain(clip).shape == clip.shape


def test_mean_std_match_undoes_a_global_gain_and_offset() -> None:
    clean = _texture(4)
    gains = np.array([1.1, 0.9, 1.2, 0.8], np.float32)
    offsets = np.array([5.0, -5.0, 0.0, 0.0], np.float32)
    flick = clean * gains[:, None, None, None] + offsets[:, None, None, None]
    out = rs.mean_std_match(flick)
    assert rs.residual_flicker(out, clean) < 1e-3  # every frame made the same
    assert np.abs(out - out[0]).max() < 1e-3


def test_tuning_refuses_reporting_clips() -> None:
    with pytest.raises(ValueError, match="tuning"):
        rs.tune_ffmpeg_chain(None, clips=("alley_1",))


def test_option_checks() -> None:
    assert rs.check_restore_cases("all,dirt") == ["dirt", "all"]
    assert rs.check_restore_kinds(None) == list(rs.RESTORE_KINDS)
    with pytest.raises(ValueError, match="cases"):
        rs.check_restore_cases("dust")
    with pytest.raises(ValueError, match="methods"):
        rs.check_restore_kinds("vbm3d")


# --------------------------------------------------------------------------- tables


def _row(clip: str, split: str, case: str, method: str, psnr: float,
         **kw: float | None) -> dict:
    r = dict.fromkeys(rs.RESTORE_CSV_FIELDS)
    r.update(clip=clip, split=split, case=case, method=method, kind="varflow", psnr=psnr)
    r.update(kw)
    return r


def _table_rows(text: str) -> list[list[str]]:
    lines = text.splitlines()
    return [[c.strip() for c in ln.strip().strip("|").split("|")]
            for ln, nxt in zip(lines, [*lines[1:], ""], strict=True)
            if ln.startswith("| ") and not nxt.startswith("|-")]


def test_format_restore_tables_on_synthetic_rows() -> None:
    rows = [_row("bikes", "tuning", "dirt", "remove_dirt", 40.0, precision=0.9),
            _row("alley_1", "reporting", "dirt", "remove_dirt", 30.0, precision=0.8,
                 seconds_per_frame=1.0),
            _row("sintel-demo", "reporting", "dirt", "remove_dirt", 34.0, precision=None,
                 seconds_per_frame=3.0),
            _row("alley_1", "reporting", "weave", "stabilise", 25.0, jitter=0.5,
                 psnr_centre=27.0)]
    text = rs.format_restore_tables(rows)
    body = _table_rows(text)
    assert len(body) == 4 + 2
    assert body[0][:4] == ["bikes", "tuning", "dirt", "remove_dirt"]
    assert body[0][4] == "40.00" and body[0][8] == "0.900" and body[0][5] == "-"
    assert "Means over the reporting clips (alley_1, sintel-demo)" in text
    dirt_mean = body[4]
    assert dirt_mean[:3] == ["dirt", "remove_dirt", "2"]
    assert dirt_mean[3] == "32.00"  # mean of 30 and 34; bikes (tuning) left out
    assert dirt_mean[7] == "0.800"  # a blank precision is left out of the mean
    assert dirt_mean[-1] == "2.000"
    assert body[5][:3] == ["weave", "stabilise", "1"] and body[5][10] == "0.50"
    only_tuning = rs.format_restore_tables(rows[:1])
    assert "none in this run" in only_tuning
    assert rs.format_restore_tables([]) == "(no results)"
    # rows read back from CSV: strings, empty cells
    csv_row = {k: ("" if v is None else str(v)) for k, v in rows[1].items()}
    assert _table_rows(rs.format_restore_tables([csv_row]))[0][4] == "30.00"


# --------------------------------------------------------------------------- data


def test_dirt_case_on_a_carphone_crop(data_root: Path, one_numba_thread) -> None:
    rows = rs.run_restore_benchmark(data_root, "carphone", "dirt", 4, crop=(64, 96))
    by = {r["method"]: r for r in rows}
    assert list(by) == ["degraded", "remove_dirt", "tmedian", "flow-median"]
    assert all(r["frames"] == 4 and (r["height"], r["width"]) == (64, 96) for r in rows)
    deg, rd, tm = by["degraded"], by["remove_dirt"], by["tmedian"]
    assert rd["precision"] > 0.8 and rd["recall"] > 0.9  # measured 0.85, 1.00
    assert tm["precision"] is None and rd["psnr_centre"] is None
    # measured (blotched / untouched / all, dB): degraded 13.6 / 68.2 / 36.8,
    # remove_dirt 26.4 / 49.4 / 54.1, tmedian 41.5 / 33.8 / 35.6.  remove_dirt repairs
    # the blotches and leaves the picture; on this nearly still crop FFmpeg's tmedian
    # is better on the blotched pixels (two of remove_dirt's fills at the frame's left
    # edge are 90 levels off and dominate the pooled error) but blurs everything else.
    assert rd["psnr_blotched"] > deg["psnr_blotched"] + 10
    assert rd["psnr_untouched"] > tm["psnr_untouched"] + 10
    assert rd["psnr"] > tm["psnr"] + 10
    assert rd["seconds_per_frame"] > 0


def test_weave_case_on_an_alley_crop(data_root: Path, one_numba_thread) -> None:
    rows = rs.run_restore_benchmark(data_root, "alley_1", "weave", 6, crop=(128, 192))
    by = {r["method"]: r for r in rows}
    assert list(by) == ["degraded", "stabilise", "deshake"]
    # the woven clip against the clean one: the weave itself (measured 7.1 px);
    # stabilise's outputs on both clips agree (measured 0.11 px on this small crop),
    # deshake's do not (4.5 px)
    assert by["degraded"]["weave_agreement"] > 5.0
    assert by["stabilise"]["weave_agreement"] < 0.3
    assert by["deshake"]["weave_agreement"] > 5 * by["stabilise"]["weave_agreement"]
    assert by["stabilise"]["jitter"] < by["degraded"]["jitter"]


def test_cli_bench_restore_prints_the_table(capsys, data_root: Path, tmp_path: Path,
                                            one_numba_thread) -> None:
    from varflow import cli

    csv = tmp_path / "restore.csv"
    rc = cli.main(["bench", "restore", "--data", str(data_root), "--clips", "carphone",
                   "--cases", "flicker", "--frames", "4", "--crop", "48x64",
                   "--methods", "varflow", "--csv", str(csv), "-q"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert out.startswith("Film-restoration protocol, first 4 frames, top-left 48x64")
    assert "deflicker" in out and f"wrote {csv}" in out
    lines = csv.read_text().splitlines()
    assert len(lines) == 3 and lines[0].startswith(",".join(rs.RESTORE_CSV_FIELDS[:2]))
    for bad, words in ((["--cases", "dust"], "--cases: unknown case 'dust'"),
                       (["--frames", "2"], "--frames: must be at least 3"),
                       (["--crop", "4x"], "--crop: expected HxW")):
        rc = cli.main(["bench", "restore", "--data", str(data_root), *bad, "-q"])
        out, err = capsys.readouterr()
        assert rc == 2 and not out and words in err and len(err.splitlines()) == 1, err


def test_format_chain_timing() -> None:
    result = {"clip": "bigbuckbunny", "frames": 24, "width": 960, "height": 540,
              "stages": ["stabilise", "dirt"], "chunk": 24, "flow_seconds": 2.0,
              "stage_seconds": {"stabilise": 0.5, "dirt": 3.0}, "chain_seconds": 3.5,
              "ratio": 1.75}
    text = rs.format_chain_timing(result)
    assert "one default varflow.flow on a pair: 2.00 s" in text
    assert "| stabilise | 0.50 | 0.25 |" in text and "| dirt | 3.00 | 1.50 |" in text
    assert text.splitlines()[-1] == "| chain (stabilise + dirt) | 3.50 | 1.75 |"
