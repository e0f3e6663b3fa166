"""``varflow batch retime``: one task per input on Dask, manifest and resume (issue 28)."""

from __future__ import annotations

import os
import sqlite3
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from varflow import cli
from varflow.batch import BatchConfig, plan_tasks
from varflow.io.images import write_image
from varflow.io.video import read_frames, video_info, video_rate, write_video
from varflow.retime.methods import make_interp_params

H, W = 32, 48
ARGS = ["--workers", "1", "-q", "--flow-method", "tvl1-fast"]


def clip(n: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    from scipy.ndimage import uniform_filter

    tex = uniform_filter(rng.random((H, W + 2 * n, 3)), size=(5, 5, 1))
    tex = (255 * (tex - tex.min()) / np.ptp(tex)).astype(np.uint8)
    return [np.ascontiguousarray(tex[:, 2 * k:2 * k + W]) for k in range(n)]


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def rows(out: Path) -> dict[str, dict]:
    with sqlite3.connect(f"file:{out / 'manifest.sqlite'}?mode=ro", uri=True) as conn:
        conn.row_factory = sqlite3.Row
        return {r["task_id"]: dict(r) for r in conn.execute("SELECT * FROM tasks")}


def test_plan_and_config() -> None:
    params = make_interp_params("naive")
    cfg = BatchConfig("retime", "naive", params, fmt="mkv", fps="60/1")
    tasks = plan_tasks("a", 10, cfg)
    assert [(t.task_id, t.output, t.frames) for t in tasks] == [("a/a.mkv", "a.mkv", (0, 9))]
    with pytest.raises(ValueError, match="at least 2"):
        plan_tasks("a", 1, cfg)
    with pytest.raises(ValueError, match="exactly one"):
        BatchConfig("retime", "naive", params, fmt="mkv", fps="60/1", slowmo=2)
    with pytest.raises(ValueError, match="--format"):
        BatchConfig("retime", "naive", params, fmt="gif", fps="60/1")
    other = BatchConfig("retime", "naive", params, fmt="mkv", fps="50/1")
    assert cfg.identity_hash("1") != other.identity_hash("1")
    assert cfg.fingerprint("1") == other.fingerprint("1")  # same method and parameters


def test_batch_retime_resume_and_settings(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    vids = tmp_path / "in"
    vids.mkdir()
    for k in range(2):
        write_video(vids / f"v{k}.mkv", clip(4, k), 25, codec="ffv1")
    shot = tmp_path / "shot"
    shot.mkdir()
    frames = clip(3, 7)
    for k, f in enumerate(frames):
        write_image(shot / f"{k:03d}.png", f)
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "broken.mkv").write_bytes(os.urandom(3000))
    out = tmp_path / "out"
    inputs = [vids, shot]
    rc, stdout, err = run(capsys, "batch", "retime", *inputs, "-o", out, "--fps", "50", *ARGS)
    assert rc == 0, err
    assert "3 tasks: 3 done, 0 skipped, 0 failed" in stdout and "videos/s" in stdout
    for k in range(2):
        v = out / f"v{k}.mkv"
        assert video_info(v).n_frames == 8 and video_rate(v) == Fraction(50)
        got, src = read_frames(v), clip(4, k)
        assert all(np.array_equal(got[2 * i], src[i]) for i in range(4))  # bit-exact
    assert video_info(out / "shot.mkv").n_frames == 6  # a folder: 25 fps by default
    r = rows(out)
    assert set(r) == {"v0/v0.mkv", "v1/v1.mkv", "shot/shot.mkv"}
    assert {v["status"] for v in r.values()} == {"done"} and {v["attempts"] for v in
                                                                r.values()} == {1}
    assert all(v["checksum"] and v["kind"] == "retime" for v in r.values())
    # resume: nothing to do; a damaged output and a stale temporary file are handled
    first_v1 = read_frames(out / "v1.mkv")
    (out / "v1.mkv").write_bytes(b"garbage")
    (out / ".v0.abc123.mkv").write_bytes(b"partial")
    rc, stdout, err = run(capsys, "batch", "retime", *inputs, "-o", out, "--fps", "50", *ARGS)
    assert rc == 0, err
    assert "3 tasks: 1 done, 2 skipped, 0 failed" in stdout
    again = rows(out)
    assert {t: v["attempts"] for t, v in again.items()} == {
        "v0/v0.mkv": 1, "v1/v1.mkv": 2, "shot/shot.mkv": 1}
    # the same frames (the Matroska muxer writes random UIDs: the bytes differ)
    assert np.array_equal(read_frames(out / "v1.mkv"), first_v1)
    assert again["v0/v0.mkv"]["checksum"] == r["v0/v0.mkv"]["checksum"]
    assert not (out / ".v0.abc123.mkv").exists()
    # another rate or parameter: refused in one line, then --overwrite
    rc, stdout, err = run(capsys, "batch", "retime", *inputs, "-o", out, "--fps", "60", *ARGS)
    assert rc == 2 and not stdout and len(err.splitlines()) == 1
    assert "fps" in err and "--overwrite" in err
    rc, _, err = run(capsys, "batch", "retime", *inputs, "-o", out, "--fps", "50", *ARGS,
                     "--n-warps", "2")
    assert rc == 2 and "n_warps" in err
    rc, stdout, err = run(capsys, "batch", "retime", *inputs, "-o", out, "--slowmo", "3",
                          *ARGS, "--overwrite")
    assert rc == 0, err
    assert "3 tasks: 3 done" in stdout
    assert video_info(out / "v0.mkv").n_frames == 10 and video_rate(out / "v0.mkv") == 25
    # a broken input fails alone
    rc, stdout, err = run(capsys, "batch", "retime", tmp_path / "bad", vids, "-o", out,
                          "--slowmo", "3", *ARGS)
    assert rc == 1 and "varflow: failed: broken/input" in err
    assert "0 done, 2 skipped, 1 failed" in stdout
    rc, _, err = run(capsys, "batch", "retime", vids, "-o", out, "--slowmo", "3", *ARGS,
                     "--zarr")
    assert rc == 2 and "--zarr" in err
