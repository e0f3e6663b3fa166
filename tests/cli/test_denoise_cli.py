"""``varflow denoise`` and ``varflow batch denoise``.

The clip: a smooth random texture (values 28..228) seen through a window moving by
(1, 1) px per frame, 8 frames of 48x64 RGB, plus seeded Gaussian noise of σ = 20,
written as a lossless video (FFV1) and as folders of 8- and 16-bit PNG frames.  The
denoiser runs with ``--radius 1`` (one frame each side): it still gains about 10 dB
here, so the 4 dB the tests ask for is a wide margin.
"""

from __future__ import annotations

import os
import re
import sqlite3
from pathlib import Path

import av
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from varflow import cli
from varflow.io.images import write_image
from varflow.io.sequences import read_frames
from varflow.io.video import video_info, write_video
from varflow.registry import RESTORE

H, W, N = 48, 64, 8
SIGMA = 20.0
FAST = ("--radius", "1", "-q")  # one frame each side: seconds, and still ~10 dB better

#: Small frames: one Numba thread is faster, and steady on a loaded machine.
pytestmark = pytest.mark.usefixtures("one_numba_thread")


def texture(seed: int, shape: tuple[int, int] = (H + N, W + N)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tex = gaussian_filter(rng.random((*shape, 3)), (2.0, 2.0, 0))
    return (tex - tex.min()) / np.ptp(tex) * 200 + 28


def clean_clip(seed: int = 0, n: int = N) -> np.ndarray:
    """``n`` float frames of one moving texture, (n, H, W, 3) in 0..255."""
    tex = texture(seed)
    return np.stack([tex[k:k + H, k:k + W] for k in range(n)])


def noisy(clean: np.ndarray, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.clip(np.rint(clean + rng.normal(0, SIGMA, clean.shape)), 0, 255).astype(np.uint8)


def psnr(x: np.ndarray, clean: np.ndarray, peak: float = 255.0) -> float:
    return float(10 * np.log10(peak**2 / np.mean((x.astype(np.float64) - clean) ** 2)))


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


def no_leftovers(folder: Path) -> None:
    """No temporary file or folder of an atomic writer is left in ``folder``."""
    hidden = [p.name for p in folder.iterdir() if p.name.startswith(".")]
    assert not hidden, hidden


_SUMMARY = re.compile(
    r"^denoise (?P<method>\S+): (?P<frames>\d+) frames?(?: \(frames \d+\.\.\d+ of \d+\))? of "
    r"(?P<w>\d+)x(?P<h>\d+) (?P<colour>\S+) (?P<bits>\d+)-bit at \S+ fps, "
    r"σ (?P<sigma>[0-9.e+-]+) \((?P<how>estimated|given)[^)]*\), (?P<cuts>[^,]+), "
    r"(?P<spf>[0-9.]+) s/frame \([0-9.]+ s\) -> (?P<where>.*)$")


def summary(stdout: str) -> dict[str, str]:
    lines = stdout.splitlines()
    assert len(lines) == 1, stdout
    m = _SUMMARY.match(lines[0])
    assert m, stdout
    return m.groupdict()


def sine_video(path: Path, frames: np.ndarray, fps: int = 25) -> Path:
    """An FFV1 video with a 440 Hz mono FLAC audio stream as long as the video."""
    rate = 48000
    t = np.arange(int(rate * len(frames) / fps)) / rate
    sig = (0.3 * np.sin(2 * np.pi * 440 * t) * 32767).astype(np.int16)
    with av.open(str(path), "w") as c:
        v = c.add_stream("ffv1", rate=fps)
        v.width, v.height, v.pix_fmt = frames.shape[2], frames.shape[1], "bgr0"
        a = c.add_stream("flac", rate=rate, layout="mono")
        for k, f in enumerate(frames):
            vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(f), format="rgb24")
            vf.pts = k
            for p in v.encode(vf):
                c.mux(p)
        for s in range(0, len(sig), 1024):
            af = av.AudioFrame.from_ndarray(sig[None, s:s + 1024], format="s16", layout="mono")
            af.sample_rate, af.pts = rate, s
            for p in a.encode(af):
                c.mux(p)
        for stream in (v, a):
            for p in stream.encode(None):
                c.mux(p)
    return path


def stream_types(path: Path) -> list[str]:
    with av.open(str(path)) as c:
        return [s.type for s in c.streams]


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("clip")
    clean = clean_clip()
    frames = noisy(clean)
    video = root / "noisy.mkv"
    write_video(video, frames, 25)  # FFV1: lossless
    folder16 = root / "noisy16"
    folder16.mkdir()
    for k, f in enumerate(frames):
        write_image(folder16 / f"frame{k + 1}.png", f.astype(np.uint16) * 257)
    return {"clean": clean, "noisy": frames, "video": video, "folder16": folder16,
            "root": root}


# --------------------------------------------------------------------------- results


@pytest.mark.parametrize("ext", ["mkv", "mp4"])
def test_denoised_video_gains_psnr_and_is_lossless(clip: dict, tmp_path: Path, ext: str,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / f"out.{ext}"
    rc, stdout, err = run(capsys, "denoise", clip["video"], "-o", out, *FAST)
    assert rc == 0, err
    s = summary(stdout)
    assert s["method"] == RESTORE.default and s["frames"] == str(N)
    assert (s["w"], s["h"], s["colour"], s["bits"]) == (str(W), str(H), "RGB", "8")
    assert s["how"] == "estimated" and abs(float(s["sigma"]) - SIGMA) < 0.1 * SIGMA
    assert s["cuts"] == "no scene cut" and float(s["spf"]) > 0
    assert s["where"].endswith(", lossless)")
    got = read_frames(out)
    assert got.shape == clip["noisy"].shape and got.dtype == np.uint8
    before, after = psnr(clip["noisy"], clip["clean"]), psnr(got, clip["clean"])
    assert after >= before + 4.0, (before, after)
    assert video_info(out).n_frames == N
    no_leftovers(tmp_path)


def test_lossless_output_is_what_was_computed(clip: dict, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Same frames in every container and in PNG frames: the video keeps every bit."""
    outs = [tmp_path / "frames", tmp_path / "out.webm"]
    for out in outs:
        rc, _, err = run(capsys, "denoise", clip["video"], "-o", out, "--sigma", SIGMA, *FAST)
        assert rc == 0, err
    frames, webm = read_frames(outs[0]), read_frames(outs[1])
    assert sorted(p.name for p in outs[0].iterdir()) == [f"{k:06d}.png" for k in range(N)]
    assert np.array_equal(frames, webm)


def test_16_bit_folder_stays_16_bit(clip: dict, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A 16-bit PNG folder gives 16-bit PNG frames; σ is on the 0-255 scale."""
    out = tmp_path / "out"
    rc, stdout, err = run(capsys, "denoise", clip["folder16"], "-o", out, "--sigma", SIGMA,
                          *FAST)
    assert rc == 0, err
    s = summary(stdout)
    assert s["bits"] == "16" and s["how"] == "given" and float(s["sigma"]) == SIGMA
    assert "0-255 scale" in stdout and s["where"] == f"{out} ({N} PNG frames)"
    got = read_frames(out)
    assert got.dtype == np.uint16 and got.shape == clip["noisy"].shape
    clean16 = clip["clean"] * 257.0
    before = psnr(clip["noisy"].astype(np.uint16) * 257, clean16, 65535.0)
    after = psnr(got, clean16, 65535.0)
    assert after >= before + 4.0, (before, after)
    # the same σ estimated on the 16-bit values is reported on the 0-255 scale too
    rc, stdout, err = run(capsys, "denoise", clip["folder16"], "-o", tmp_path / "est",
                          "--stop", "4", *FAST)
    assert rc == 0, err
    s = summary(stdout)
    assert s["how"] == "estimated" and abs(float(s["sigma"]) - SIGMA) < 0.15 * SIGMA
    assert "(frames 0..3 of 8)" in stdout and len(os.listdir(tmp_path / "est")) == 4


def test_audio_is_copied(clip: dict, tmp_path: Path,
                         capsys: pytest.CaptureFixture[str]) -> None:
    src = sine_video(tmp_path / "sound.mkv", clip["noisy"])
    quick = ("--radius", "0", "--sigma", SIGMA, "-q")  # this test is about the audio
    out = tmp_path / "out.mkv"
    rc, stdout, err = run(capsys, "denoise", src, "-o", out, *quick)
    assert rc == 0, err
    assert stdout.rstrip().endswith("; audio copied (flac)")
    assert stream_types(out) == ["video", "audio"]
    m4v = tmp_path / "out.m4v"  # .m4v cannot hold FLAC
    rc, stdout, err = run(capsys, "denoise", src, "-o", m4v, *quick)
    assert rc == 0 and "audio re-encoded (aac)" in stdout, err
    assert stream_types(m4v) == ["video", "audio"]
    for extra, note in ((("--no-audio",), None), (("--start", "2"), "left out (a section")):
        rc, stdout, err = run(capsys, "denoise", src, "-o", out, *quick, *extra)
        assert rc == 0, err
        assert stream_types(out) == ["video"]
        assert ("; audio" in stdout) == (note is not None) and (note is None or note in stdout)


def photo_shot(name: str, top: int, left: int, n: int = 4) -> np.ndarray:
    """``n`` frames of a photo at half resolution, panning by (1, 1) px per frame."""
    from varflow.generators.photo import load_photo

    photo = 255.0 * load_photo(name)
    return np.stack([photo[top + 2 * k:top + 2 * k + 2 * H:2, left + 2 * k:left + 2 * k + 2 * W:2]
                     for k in range(n)])


def test_scene_cut_is_counted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two shots of four frames (two photos: the cut stands out from the noise, which
    the random textures' does not): one cut; none looked for with --no-scene-cuts."""
    clean = np.concatenate([photo_shot("astronaut", 100, 100), photo_shot("coffee", 50, 100)])
    src = tmp_path / "cut"
    src.mkdir()
    for k, f in enumerate(noisy(clean)):
        write_image(src / f"{k:02d}.png", f)
    rc, stdout, err = run(capsys, "denoise", src, "-o", tmp_path / "out.mkv", "--sigma",
                          SIGMA, *FAST)
    assert rc == 0, err
    assert summary(stdout)["cuts"] == "1 scene cut"
    got = read_frames(tmp_path / "out.mkv")
    assert psnr(got, clean) >= psnr(noisy(clean), clean) + 4.0
    rc, stdout, err = run(capsys, "denoise", src, "-o", tmp_path / "one.mkv", "--sigma",
                          SIGMA, "--no-scene-cuts", *FAST)
    assert rc == 0, err
    assert summary(stdout)["cuts"] == "scene cuts not detected"


# --------------------------------------------------------------------------- errors


def test_bad_inputs_and_options(clip: dict, tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    data = clip["video"].read_bytes()
    truncated = tmp_path / "truncated.mkv"
    truncated.write_bytes(data[: len(data) // 2])
    corrupt = tmp_path / "corrupt.mkv"
    corrupt.write_bytes(os.urandom(3000))
    empty = tmp_path / "empty"
    empty.mkdir()
    out = tmp_path / "out.mkv"
    src = clip["video"]
    for args, words in [
        ((tmp_path / "nope.mkv",), ("input not found", "nope.mkv")),
        ((empty,), ("no image files",)),
        ((corrupt,), ("corrupt.mkv",)),
        ((truncated,), ("truncated.mkv", "truncated")),
        ((src, "--sigma", "-1"), ("--sigma", ">= 0")),
        ((src, "--sigma", "abc"), ("--sigma",)),
        ((src, "--method", "nope"), ("nope", "nlbayes")),
        ((src, "--radius", "99"), ("--radius",)),
        ((src, "--grain", "2"), ("--grain",)),
        ((src, "--start", "99"), ("no frame selected",)),
        ((src, "--chunk", "0"), ("--chunk",)),
        ((src, "--data-weight", "-1"), ("--data-weight",)),
    ]:
        one_line_error(*run(capsys, "denoise", *args, "-o", out, "-q"), *words)
    one_line_error(*run(capsys, "denoise", src, "-o", tmp_path / "o.txt"), "must be a video")
    one_line_error(*run(capsys, "denoise", src, "-o", tmp_path / "no" / "o.mkv"), "no")
    one_line_error(*run(capsys, "denoise", src, "-o", tmp_path / "frames", "--codec", "ffv1"),
                   "folder of PNG frames")
    assert not out.exists() and not (tmp_path / "frames").exists()
    no_leftovers(tmp_path)


def test_output_may_not_replace_an_input(clip: dict, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    video = tmp_path / "in.mkv"
    video.write_bytes(clip["video"].read_bytes())
    before = video.read_bytes()
    one_line_error(*run(capsys, "denoise", video, "-o", video), "input IN")
    assert video.read_bytes() == before
    folder = clip["folder16"]
    names = sorted(os.listdir(folder))
    one_line_error(*run(capsys, "denoise", folder, "-o", folder), "input IN")
    assert sorted(os.listdir(folder)) == names


def test_failure_mid_stream_leaves_the_old_output(clip: dict, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A frame that cannot be read after the work began: one line, and neither a half
    video nor a half folder; an output of an earlier run stays as it was."""
    src = tmp_path / "shot"
    src.mkdir()
    for k, f in enumerate(clip["noisy"]):
        write_image(src / f"{k:02d}.png", f)
    out, frames = tmp_path / "out.mkv", tmp_path / "frames"
    out.write_bytes(b"an earlier result")
    (src / "05.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    for target in (out, frames):
        one_line_error(*run(capsys, "denoise", src, "-o", target, *FAST), "05.png")
    assert out.read_bytes() == b"an earlier result" and not frames.exists()
    no_leftovers(tmp_path)


# --------------------------------------------------------------------------- help


_HISTORY = re.compile(r"benchmarks/|HISTORY|\bmeasured\b|\btuned\b|varflow\.[a-z_]+\.[a-z_]")


def test_help_is_short_and_reads_the_registry(capsys: pytest.CaptureFixture[str]) -> None:
    rc, raw, _ = run(capsys, "denoise", "--help")
    assert rc == 0 and len(raw.splitlines()) <= 70, len(raw.splitlines())
    assert not _HISTORY.search(raw) and not re.search(r":\w+:`|``", raw)
    text = " ".join(raw.split())
    for flag in ("--sigma S", "--method NAME", "--start N", "--stop N", "--input-fps R",
                 "--codec C", "--no-scene-cuts", "--chunk K", "-q"):
        assert flag in text, flag
    for method in ("nlbayes", "nlbayes-fast"):
        entry = RESTORE[method]
        defaults = entry.defaults()
        rc, raw, _ = run(capsys, "denoise", "--method", method, "--help")
        text = " ".join(raw.split())
        assert rc == 0 and f"knobs of {method}:" in text
        for name, _ in entry.knobs:
            assert f"--{name.replace('_', '-')} " in text, name
            assert f"(default {getattr(defaults, name)})" in text, name
        assert f" {method} {' '.join(entry.use.split())}" in text  # the list of methods
        assert "--patch-final" not in text  # not a knob: 'varflow methods nlbayes' has it
    rc, raw, _ = run(capsys, "--help")
    assert rc == 0 and "denoise" in raw
    rc, raw, _ = run(capsys, "batch", "denoise", "--help")
    assert rc == 0 and "--sigma S" in raw and not _HISTORY.search(raw)


def test_methods_lists_the_restoration_methods(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(capsys, "methods")
    assert rc == 0 and "# denoising (varflow denoise --method)" in out
    for name in RESTORE:
        assert re.search(rf"^{re.escape(name)}\s+{re.escape(RESTORE[name].use)}$", out, re.M)
    rc, out, _ = run(capsys, "methods", "nlbayes-fast")
    lines = out.splitlines()
    assert rc == 0 and lines[0] == f"nlbayes-fast: {RESTORE['nlbayes-fast'].use}"
    assert len(lines) <= 60 and not _HISTORY.search(out)
    radius = next(ln for ln in lines if " --radius " in ln).split()
    assert radius[:4] == ["*", "--radius", "-", str(RESTORE["nlbayes-fast"].defaults().radius)]
    assert "parameters of its flow method (--flow-method" in out


# --------------------------------------------------------------------------- batch


def test_batch_denoise_writes_and_resumes(clip: dict, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed")
    inputs = tmp_path / "in"
    inputs.mkdir()
    (inputs / "a.mkv").write_bytes(clip["video"].read_bytes())
    shot = tmp_path / "shot"
    shot.mkdir()
    for k, f in enumerate(clip["noisy"][:4]):
        write_image(shot / f"{k:02d}.png", f)
    out = tmp_path / "out"
    args = ("batch", "denoise", inputs, shot, "-o", out, "--workers", "1", "--sigma", SIGMA,
            *FAST)
    rc, stdout, err = run(capsys, *args)
    assert rc == 0, err
    assert "2 tasks: 2 done, 0 skipped, 0 failed" in stdout
    a, b = read_frames(out / "a.mkv"), read_frames(out / "shot.mkv")
    assert a.shape == clip["noisy"].shape and b.shape == clip["noisy"][:4].shape
    assert psnr(a, clip["clean"]) >= psnr(clip["noisy"], clip["clean"]) + 4.0
    assert video_info(out / "a.mkv").n_frames == N
    with sqlite3.connect(f"file:{out / 'manifest.sqlite'}?mode=ro", uri=True) as conn:
        rows = dict(conn.execute("SELECT task_id, kind FROM tasks").fetchall())
    assert rows == {"a/a.mkv": "denoise", "shot/shot.mkv": "denoise"}
    rc, stdout, err = run(capsys, *args)  # a second run: nothing to do
    assert rc == 0 and "2 tasks: 0 done, 2 skipped, 0 failed" in stdout, err
    assert np.array_equal(read_frames(out / "a.mkv"), a)
    rc, stdout, err = run(capsys, *args[:-3], "-q")  # other settings: σ estimated
    assert rc == 2 and not stdout and len(err.splitlines()) == 1 and "--overwrite" in err
    one_line_error(*run(capsys, *args, "--zarr"), "--zarr")
    one_line_error(*run(capsys, *args, "--format", "gif"), "--format")


def test_batch_config_of_denoise() -> None:
    from varflow.batch.plan import BatchConfig, plan_tasks

    params = RESTORE.make_params(RESTORE.default)
    cfg = BatchConfig("denoise", RESTORE.default, params, fmt="mkv", sigma=SIGMA)
    tasks = plan_tasks("a", 10, cfg)
    assert [(t.task_id, t.output, t.frames) for t in tasks] == [("a/a.mkv", "a.mkv", (0, 9))]
    other = BatchConfig("denoise", RESTORE.default, params, fmt="mkv", sigma=None)
    assert cfg.identity_hash("1") != other.identity_hash("1")
    assert cfg.fingerprint("1") == other.fingerprint("1")
    with pytest.raises(ValueError, match="--sigma"):
        BatchConfig("denoise", RESTORE.default, params, fmt="mkv", sigma=-1.0)
    with pytest.raises(ValueError, match="--format"):
        BatchConfig("denoise", RESTORE.default, params, fmt="gif")
