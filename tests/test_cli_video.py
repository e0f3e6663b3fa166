"""``varflow video`` on frame folders and on clips with a scene cut (issue 47).

The clip: two unrelated smooth textures, each translated by (2, 1) px per frame
(``|w| = sqrt(5) = 2.24`` px), four frames of each, 64x96 RGB; the pair (3, 4) is
the cut.  It is written as a folder of PNG frames and as a lossless video.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from varflow.cli import main
from varflow.io.images import write_image
from varflow.io.video import read_frames, video_info, write_video
from varflow.viz.video import INVALID_GREY, flow_percentile_radius

H, W = 64, 96
N_FRAMES, CUT = 8, 4  # frames 0..3 show scene A, 4..7 scene B
SHIFT = (2, 1)  # (dx, dy) per frame
TRUE_MOTION = math.hypot(*SHIFT)
PAD = 16


def _scene(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tex = gaussian_filter(rng.random((H + 2 * PAD, W + 2 * PAD, 3)), (2.5, 2.5, 0))
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    return np.rint(255 * tex).astype(np.uint8)


def _clip() -> np.ndarray:
    scenes = (_scene(1), _scene(2))
    frames = []
    for k in range(N_FRAMES):
        src, j = (scenes[0], k) if k < CUT else (scenes[1], k - CUT)
        y, x = PAD + SHIFT[1] * j, PAD + SHIFT[0] * j  # the window moves: content moves back
        frames.append(src[y : y + H, x : x + W])
    return np.stack(frames)


@pytest.fixture(scope="module")
def clip_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("clip")
    frames = _clip()
    folder = root / "frames"
    folder.mkdir()
    for k, frame in enumerate(frames):
        write_image(folder / f"frame{k + 1}.png", frame)  # natural order: frame10 after frame9
    video = root / "clip.mkv"
    write_video(video, frames, fps=20)
    empty = root / "empty"
    empty.mkdir()
    return {"folder": folder, "video": video, "empty": empty}


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def colour_scale(stdout: str) -> float:
    m = re.search(r"colour scale ([0-9.]+) px", stdout)
    assert m, stdout
    return float(m.group(1))


@pytest.mark.parametrize("kind", ["folder", "video"])
def test_cut_is_skipped_and_the_scale_follows_the_true_motion(
    clip_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str,
) -> None:
    out = tmp_path / "flow.mkv"  # lossless: the grey frame stays exactly grey
    rc, stdout, err = run(capsys, "video", clip_files[kind], "-o", out, "--method", "tvl1-fast",
                          "--no-legend", "-q")
    assert rc == 0, err
    assert err == ""
    assert stdout.count("\n") == 1
    assert "(99th percentile of |w|, 1 scene cut skipped)" in stdout
    assert f"{N_FRAMES - 2} flows of {W}x{H}" in stdout  # 7 pairs, one across the cut
    scale = colour_scale(stdout)
    assert 0.5 * TRUE_MOTION < scale < 3.0, stdout
    info = video_info(out)
    assert info.n_frames == N_FRAMES - 1  # one frame per pair, the cut included
    assert info.fps == (25.0 if kind == "folder" else 20.0)
    assert (info.height, info.width) == (H, W)
    rendered = read_frames(out)
    assert (rendered[CUT - 1] == INVALID_GREY).all()  # the pair across the cut: no flow
    others = np.delete(rendered, CUT - 1, axis=0).astype(np.int16)
    assert (np.abs(others - 128).max(axis=(1, 2, 3)) > 50).all()  # coloured, not washed out


def test_max_radius_side_by_side_on_a_folder(
    clip_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "sbs.mp4"
    rc, stdout, err = run(capsys, "video", clip_files["folder"], "-o", out, "--method",
                          "tvl1-fast", "--layout", "side-by-side", "--max-radius", "2",
                          "--start", "2", "--stride", "2", "--input-fps", "30", "-q")
    assert rc == 0, err
    assert "colour scale 2.000 px (--max-radius, 1 scene cut skipped)" in stdout
    assert "frames 2..6, stride 2" in stdout and "15 fps" in stdout
    info = video_info(out)
    assert info.n_frames == 2 and info.fps == 15.0  # frames 2, 4, 6: pairs (2, 4), (4, 6)
    assert info.width == 3 * W + 2 * 4


def test_no_scene_cuts_computes_every_flow(
    clip_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "flow.mp4"
    rc, stdout, err = run(capsys, "video", clip_files["folder"], "-o", out, "--method",
                          "tvl1-fast", "--stop", "6", "--no-scene-cuts", "-q")
    assert rc == 0, err
    assert "5 flows" in stdout and "scene cuts not detected" in stdout
    assert video_info(out).n_frames == 5


def test_clip_without_cut(
    clip_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "flow.mp4"
    rc, stdout, err = run(capsys, "video", clip_files["video"], "-o", out, "--method",
                          "tvl1-fast", "--stop", str(CUT), "-q")
    assert rc == 0, err
    assert "3 flows" in stdout and "(99th percentile of |w|, no scene cut)" in stdout
    assert colour_scale(stdout) < 3.0


@pytest.mark.parametrize("which", ["empty", "missing", "image"])
def test_input_errors_are_worded_as_retime_and_track_word_them(
    clip_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], which: str,
) -> None:
    source = {"empty": clip_files["empty"], "missing": tmp_path / "nowhere",
              "image": clip_files["folder"] / "frame1.png"}[which]
    out = tmp_path / "out"
    out.mkdir()
    rc, stdout, err = run(capsys, "video", source, "-o", out / "flow.mp4", "-q")
    assert rc == 2 and stdout == ""
    assert err.startswith("varflow: error: ") and err.count("\n") == 1
    assert str(source) in err
    if which == "empty":
        assert "no image files in the folder" in err
    rc, _, retime_err = run(capsys, "retime", source, "-o", out / "r.mkv", "--fps", "30", "-q")
    assert rc == 2 and retime_err == err  # one wording for the commands that read clips
    rc, _, track_err = run(capsys, "track", source, "-o", out / "t.npz", "-q")
    assert rc == 2 and track_err == err
    assert list(out.iterdir()) == []


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--start", "7"], "need at least 2 frames, 1 of 8 selected with --start 7"),
        (["--input-fps", "0"], "--input-fps"),
        (["--stride", "0"], "--stride"),
    ],
)
def test_folder_errors(
    clip_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str],
    args: list[str], match: str,
) -> None:
    rc, stdout, err = run(capsys, "video", clip_files["folder"], "-o", tmp_path / "flow.mp4",
                          *args, "-q")
    assert rc == 2 and stdout == ""
    assert err.startswith("varflow: error: ") and err.count("\n") == 1
    assert match in err
    assert list(tmp_path.iterdir()) == []


def test_folder_with_frames_of_different_sizes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    folder = tmp_path / "frames"
    folder.mkdir()
    frames = _clip()
    write_image(folder / "a1.png", frames[0])
    write_image(folder / "a2.png", frames[1][:-2])
    rc, stdout, err = run(capsys, "video", folder, "-o", tmp_path / "flow.mp4", "--method",
                          "tvl1-fast", "-q")
    assert rc == 2 and stdout == ""
    assert "frame 1 (a2.png) has shape (62, 96, 3)" in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames"]


def test_flow_percentile_radius_ignores_outliers_and_unknown() -> None:
    rng = np.random.default_rng(3)
    flows = rng.normal(scale=2.0, size=(4, 30, 40, 2)).astype(np.float32)
    flows[1, :3, :3] = 500.0  # a few wrong vectors: not the scale
    flows[2, 5, 5] = np.nan  # unknown: ignored
    exact = np.nanpercentile(np.hypot(flows[..., 0], flows[..., 1]), 99)
    assert exact < 10
    got = flow_percentile_radius(flows)
    assert got == pytest.approx(exact, rel=0.01)
    assert flow_percentile_radius(flows, 100) == pytest.approx(500 * math.sqrt(2) * (1 + 1e-5))
    assert flow_percentile_radius(np.full((2, 3, 4, 2), np.nan)) == 1.0
    still = np.zeros((20, 20, 2))
    still[0, 0] = (3.0, 4.0)  # 99 % do not move: the maximum
    assert flow_percentile_radius(still) == pytest.approx(5.0 * (1 + 1e-5))
    with pytest.raises(ValueError, match="percentile"):
        flow_percentile_radius(flows, 0)


def test_video_output_may_not_replace_its_input(tmp_path, capsys) -> None:
    """Issue 47: ``varflow video a.mkv -o a.mkv`` is refused before any work."""
    src = tmp_path / "clip.mkv"
    src.write_bytes(b"not read: refused before")
    rc = main(["video", str(src), "-o", str(src)])
    err = capsys.readouterr().err
    assert rc == 2 and err.strip() == (f"varflow: error: -o/--output: {src} is also the input "
                                       "IN; give each output a file of its own")
    assert src.read_bytes() == b"not read: refused before"
