"""``varflow interpolate`` and ``varflow retime`` (issue 28, part 3)."""

from __future__ import annotations

import os
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from varflow import cli
from varflow.io.images import read_image, write_image
from varflow.io.video import read_frames, video_info, video_rate, write_video

H, W = 48, 64


#: Small frames: one Numba thread is faster, and steady on a loaded machine.
pytestmark = pytest.mark.usefixtures("one_numba_thread")


def frames(n: int = 4, speed: int = 2) -> list[np.ndarray]:
    from varflow.generators.photo import load_photo

    photo = load_photo("astronaut")
    return [(255 * photo[100:100 + 2 * H:2, 2 * speed * k:2 * speed * k + 2 * W:2])
            .round().astype(np.uint8) for k in range(n)]


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def one_line_error(rc: int, out: str, err: str, *words: str) -> None:
    assert rc == 2 and not out, (rc, out, err)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("varflow: error: "), err
    assert "Traceback" not in err
    for w in words:
        assert w in err, (w, err)


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    f = frames(2)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    write_image(a, f[0])
    write_image(b, f[1])
    return a, b


def test_interpolate_one_frame(tmp_path: Path, pair: tuple[Path, Path],
                               capsys: pytest.CaptureFixture[str]) -> None:
    import varflow

    a, b = pair
    out = tmp_path / "mid.png"
    rc, stdout, err = run(capsys, "interpolate", a, b, "-o", out, "-q")
    assert rc == 0, err
    assert "splat: 1 frame(s) at t = 0.5 of 64x48" in stdout
    mid = read_image(out)
    want = varflow.interpolate(read_image(a), read_image(b), 0.5)  # the default, splat
    assert mid.dtype == np.uint8 and mid.shape == (H, W, 3)
    assert np.array_equal(mid, want)
    rc, _, err = run(capsys, "interpolate", a, b, "-o", out, "--t", "0", "-q")
    assert rc == 0, err
    assert np.array_equal(read_image(out), read_image(a))  # t = 0 is frame A exactly


def test_interpolate_n_frames_names(tmp_path: Path, pair: tuple[Path, Path],
                                    capsys: pytest.CaptureFixture[str]) -> None:
    import varflow

    a, b = pair
    rc, stdout, err = run(capsys, "interpolate", a, b, "-o", tmp_path / "m_%03d.png", "-n",
                          "3", "-q")
    assert rc == 0, err
    assert "t = 0.25, 0.5, 0.75" in stdout
    want = varflow.interpolate(read_image(a), read_image(b), [0.25, 0.5, 0.75])
    for k in range(3):
        assert np.array_equal(read_image(tmp_path / f"m_{k + 1:03d}.png"), want[k])
    rc, _, err = run(capsys, "interpolate", a, b, "-o", tmp_path / "mid.png", "-n", "2", "-q")
    assert rc == 0, err
    assert (tmp_path / "mid_01.png").is_file() and (tmp_path / "mid_02.png").is_file()
    rc, _, err = run(capsys, "interpolate", a, b, "-o", f"{tmp_path / 'dd'}/", "-n", "2", "-q")
    assert rc == 0, err
    assert sorted(p.name for p in (tmp_path / "dd").iterdir()) == ["01.png", "02.png"]
    third = varflow.interpolate(read_image(a), read_image(b), [1 / 3, 2 / 3])
    assert np.array_equal(read_image(tmp_path / "dd" / "02.png"), third[1])


def test_interpolate_bad_inputs(tmp_path: Path, pair: tuple[Path, Path],
                                capsys: pytest.CaptureFixture[str]) -> None:
    a, b = pair
    out = tmp_path / "x.png"
    small = tmp_path / "small.png"
    write_image(small, frames(1)[0][:40])
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n broken")
    one_line_error(*run(capsys, "interpolate", a, tmp_path / "nope.png", "-o", out),
                   "nope.png")
    one_line_error(*run(capsys, "interpolate", a, corrupt, "-o", out), "corrupt.png")
    one_line_error(*run(capsys, "interpolate", a, small, "-o", out), "64x40", "64x48")
    for t in ("1.5", "-0.1", "nan", "x"):
        one_line_error(*run(capsys, "interpolate", a, b, "-o", out, "--t", t), "--t")
    one_line_error(*run(capsys, "interpolate", a, b, "-o", out, "-n", "0"), "-n")
    one_line_error(*run(capsys, "interpolate", a, b, "-o", out, "-n", "2", "--t", "0.5"),
                   "not allowed")
    one_line_error(*run(capsys, "interpolate", a, b, "-o", out, "--method", "nope"), "nope")
    one_line_error(*run(capsys, "interpolate", a, b, "-o", tmp_path / "no" / "x.png"), "no")
    assert not out.exists()


def test_retime_video(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    clip = frames(5)
    src = tmp_path / "in.mkv"
    write_video(src, clip, Fraction(24000, 1001), codec="ffv1")
    out = tmp_path / "out.mkv"
    rc, stdout, err = run(capsys, "retime", src, "-o", out, "--fps", "30000/1001", "-q")
    assert rc == 0, err
    # round(5 * 30000 / 24000) = round(6.25) = 6 frames at s = 0, 0.8, 1.6, 2.4, 3.2, 4
    assert "5 frames at 24000/1001 (23.976) fps -> 6 frames at 30000/1001 (29.97) fps" in stdout
    assert "(2 source frames passed through, 4 interpolated)" in stdout
    assert video_info(out).n_frames == 6 and video_rate(out) == Fraction(30000, 1001)
    got = read_frames(out)
    assert np.array_equal(got[0], clip[0]) and np.array_equal(got[5], clip[4])
    rc, stdout, err = run(capsys, "retime", src, "-o", tmp_path / "slow", "--slowmo", "3",
                          "--flow-method", "tvl1-fast", "--n-warps", "2", "-q")
    assert rc == 0, err
    assert len(list((tmp_path / "slow").iterdir())) == 13  # (5 - 1) * 3 + 1


_MADE_OF = re.compile(
    r"^retime (?P<method>\S+): (?P<n_source>\d+) frames at .* fps -> (?P<n_output>\d+) frames "
    r"at .* fps \((?P<passed>\d+) source frames? passed through, (?P<interpolated>\d+) "
    r"interpolated(?:, (?P<cut_frames>\d+) repeated at (?P<cuts>\d+) scene cuts?)?"
    r"(?:, last frame held for (?P<held>\d+) extra frames?)?\) in "
)


def _summary_counts(stdout: str) -> dict[str, int]:
    match = _MADE_OF.match(stdout)
    assert match, stdout
    return {k: int(v or 0) for k, v in match.groupdict().items() if k != "method"}


@pytest.mark.parametrize(
    ("fps", "counts"),
    [
        # 5 frames at 24 fps -> 10 at 48: s = 0, 0.5, .., 4, 4.5; s = 4.5 holds frame 4
        ("48", {"passed": 5, "interpolated": 4, "held": 1}),
        # -> 6 at 30: s = 0, 0.8, 1.6, 2.4, 3.2, 4
        ("30", {"passed": 2, "interpolated": 4, "held": 0}),
        # -> 3 at 12: s = 0, 2, 4
        ("12", {"passed": 3, "interpolated": 0, "held": 0}),
        # -> 6 at 27 (round(5.625)): s = 0, 0.89, .., 3.56, 4.44: frame 4 shown once
        ("27", {"passed": 2, "interpolated": 4, "held": 0}),
    ],
)
def test_retime_summary_adds_up(tmp_path: Path, capsys: pytest.CaptureFixture[str], fps: str,
                                counts: dict[str, int]) -> None:
    """The summary counts every output frame once and no source frame twice: a last
    frame repeated to reach the duration is said to be held, not passed through again."""
    src = tmp_path / "in"
    src.mkdir()
    for k, f in enumerate(frames(5)):
        write_image(src / f"{k:02d}.png", f)
    out = tmp_path / "out"
    rc, stdout, err = run(capsys, "retime", src, "-o", out, "--input-fps", "24", "--fps", fps,
                          "--method", "naive", "--flow-method", "tvl1-fast", "-q")
    assert rc == 0, err
    got = _summary_counts(stdout)
    assert {k: got[k] for k in counts} == counts
    assert got["n_source"] == 5 and got["passed"] <= got["n_source"]
    assert (got["passed"] + got["interpolated"] + got["cut_frames"] + got["held"]
            == got["n_output"] == len(list(out.iterdir())))
    assert ("held" in stdout) == (counts["held"] > 0)


def test_retime_summary_with_a_scene_cut(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    from varflow.generators.photo import load_photo

    other = load_photo("coffee")
    src = tmp_path / "in"
    src.mkdir()
    shot = frames(2) + [(255 * other[k:k + 2 * H:2, 2 * k:2 * k + 2 * W:2]).round()
                        .astype(np.uint8) for k in (0, 2)]
    for k, f in enumerate(shot):
        write_image(src / f"{k:02d}.png", f)
    rc, stdout, err = run(capsys, "retime", src, "-o", tmp_path / "out", "--slowmo", "2",
                          "--method", "naive", "--flow-method", "tvl1-fast", "-q")
    assert rc == 0, err
    # 4 frames -> 7: s = 0, 0.5, .., 3; the pair (1, 2) is a cut
    assert "(4 source frames passed through, 2 interpolated, 1 repeated at 1 scene cut)" in stdout
    got = _summary_counts(stdout)
    assert got["passed"] + got["interpolated"] + got["cut_frames"] == got["n_output"] == 7


def test_retime_bad_inputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "in.mkv"
    write_video(src, frames(4), 25, codec="ffv1")
    corrupt = tmp_path / "corrupt.mkv"
    corrupt.write_bytes(os.urandom(3000))
    data = src.read_bytes()
    truncated = tmp_path / "truncated.mkv"
    truncated.write_bytes(data[: len(data) // 2])
    out = tmp_path / "out.mkv"
    one_line_error(*run(capsys, "retime", tmp_path / "nope.mkv", "-o", out, "--fps", "50"),
                   "nope.mkv")
    one_line_error(*run(capsys, "retime", corrupt, "-o", out, "--fps", "50"), "corrupt.mkv")
    one_line_error(*run(capsys, "retime", truncated, "-o", out, "--fps", "50"), "truncated")
    one_line_error(*run(capsys, "retime", src, "-o", out, "--fps", "50", "--slowmo", "2"),
                   "not allowed")
    one_line_error(*run(capsys, "retime", src, "-o", out), "--fps", "--slowmo")
    one_line_error(*run(capsys, "retime", src, "-o", out, "--slowmo", "1"), "--slowmo", ">= 2")
    one_line_error(*run(capsys, "retime", src, "-o", out, "--fps", "0"), "--fps")
    one_line_error(*run(capsys, "retime", src, "-o", out, "--fps", "abc"), "--fps")
    one_line_error(*run(capsys, "retime", src, "-o", tmp_path / "o.txt", "--fps", "50"),
                   "must be a video")
    one_line_error(*run(capsys, "retime", src, "-o", out, "--fps", "50", "--grey", "--bogus"),
                   "unrecognized")
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_help_lists_the_interpolation_parameters(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(capsys, "retime", "--help")
    assert rc == 0
    text = " ".join(out.split())
    assert "--flow-method STR" in text and "(default tvl1-ld)" in text  # splat's knob
    assert "--data-weight" not in text  # not a knob: 'varflow methods splat' lists it
    for name in ("naive", "splat", "splat-fast"):  # every method with when to use it
        assert f" {name} " in text.split("methods (--method NAME;")[1]
    rc, out, _ = run(capsys, "retime", "--method", "naive", "--help")
    assert rc == 0 and "(default tvl1)" in " ".join(out.split())
    rc, out, _ = run(capsys, "--help")
    assert rc == 0 and "interpolate" in out and "retime" in out
