"""Tests of ``varflow batch``: planning, inputs, manifest, resume, SIGKILL, Dask clusters."""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import varflow
from varflow import cli
from varflow.batch import (
    BatchConfig,
    expand_inputs,
    flow_pairs,
    plan_tasks,
    read_pairs_file,
    track_windows,
)
from varflow.batch.manifest import Manifest
from varflow.io.flo import write_flo
from varflow.io.trajectories import read_trajectories
from varflow.io.video import read_frames, write_video
from varflow.registry import get_method, make_params

H, W = 32, 48
FAST = ["--method", "tvl1-fast"]
TASK_COLUMNS = ["task_id", "input", "name", "kind", "frames", "method", "params", "version",
                "output", "checksum", "status", "error", "seconds", "attempts", "updated"]


# --------------------------------------------------------------------------- helpers


def make_video(path: Path, n_frames: int = 5, seed: int = 0) -> Path:
    """A lossless FFV1 video of a smooth random texture moving right by 1 px per frame."""
    rng = np.random.default_rng(seed)
    big = rng.random((H // 4 + 3, (W + n_frames) // 4 + 3, 3))
    texture = np.kron(big, np.ones((4, 4, 1)))  # blocky, then blurred below
    from scipy.ndimage import uniform_filter

    texture = (255 * uniform_filter(texture, size=(3, 3, 1))).astype(np.uint8)
    write_video(path, (texture[2:2 + H, k:k + W] for k in range(n_frames)), 10,
                codec="ffv1", pix_fmt="bgr0")
    return path


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def rows(out: Path) -> dict[str, dict]:
    with sqlite3.connect(f"file:{out / 'manifest.sqlite'}?mode=ro", uri=True) as conn:
        conn.row_factory = sqlite3.Row
        return {r["task_id"]: dict(r) for r in conn.execute("SELECT * FROM tasks")}


def outputs(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.glob("*/*"))
            if p.is_file() and not p.name.startswith(".")}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(procs: list[subprocess.Popen]) -> None:
    """Terminate the processes one by one (workers before the scheduler); kill on timeout."""
    for p in reversed(procs):
        if p.poll() is None:
            p.terminate()
        try:
            p.wait(timeout=8)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=10)


@pytest.fixture(scope="module")
def videos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("videos")
    for k in range(3):
        make_video(d / f"clip{k}.mkv", n_frames=5, seed=k)
    return d


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """An external cluster: a ``dask scheduler`` and two ``dask worker`` processes."""
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    log_dir = tmp_path_factory.mktemp("dask")
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    procs: list[subprocess.Popen] = []
    logs = []
    try:
        def spawn(args: list[str], tag: str) -> None:
            f = open(log_dir / f"{tag}.log", "wb")  # noqa: SIM115 - closed below
            logs.append(f)
            procs.append(subprocess.Popen([shutil.which("dask") or "dask", *args], env=env,
                                          stdout=f, stderr=subprocess.STDOUT,
                                          start_new_session=True))

        spawn(["scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
              "scheduler")
        for k in range(2):
            spawn(["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
                   "--host", "127.0.0.1", "--local-directory", str(log_dir / f"w{k}")],
                  f"worker{k}")
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        stop(procs)
        for f in logs:
            f.close()


# --------------------------------------------------------------------------- planning


def test_pairs_and_windows_arithmetic() -> None:
    assert flow_pairs(5) == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert flow_pairs(5, 2) == [(0, 2), (1, 3), (2, 4)]
    assert flow_pairs(2, 2) == []
    assert track_windows(10, 4, 1) == [(0, 4), (3, 7), (6, 10)]
    assert track_windows(11, 4, 1) == [(0, 4), (3, 7), (6, 10), (7, 11)]
    assert track_windows(6, 4, 0) == [(0, 4), (2, 6)]
    assert track_windows(3, 5, 2) == [(0, 3)]
    assert track_windows(1, 5, 2) == []
    for n in range(2, 30):
        for window in range(2, 8):
            for overlap in range(window):
                ws = track_windows(n, window, overlap)
                covered = set().union(*(range(s, e) for s, e in ws))
                assert covered == set(range(n))
                assert all(e - s == min(n, window) for s, e in ws)
                starts = [s for s, _ in ws]
                assert all(0 < d <= window - overlap for d in np.diff(starts))
    with pytest.raises(ValueError):
        track_windows(10, 4, 4)


def test_plan_names_and_config(tmp_path: Path) -> None:
    params = make_params(get_method("tvl1-fast"))
    cfg = BatchConfig("flow", "tvl1-fast", params, stride=2)
    tasks = plan_tasks("a", 5, cfg)
    assert [t.task_id for t in tasks] == ["a/000000.flo", "a/000001.flo", "a/000002.flo"]
    assert [t.frames for t in tasks] == [(0, 2), (1, 3), (2, 4)]
    with pytest.raises(ValueError, match="stride 2 needs at least 3"):
        plan_tasks("a", 2, cfg)
    pf = tmp_path / "pairs.txt"
    pf.write_text("# pairs\n0 3\n4,1\n\n7 8\n")
    pairs = read_pairs_file(pf)
    assert pairs == ((0, 3), (4, 1), (7, 8))
    cfg = BatchConfig("flow", "tvl1-fast", params, pairs=pairs, fmt="png")
    tasks = plan_tasks("b", 6, cfg)
    assert [t.output for t in tasks] == ["b/000000_000003.png", "b/000004_000001.png",
                                        "b/000007_000008.png"]
    assert [t.problem is None for t in tasks] == [True, True, False]
    for bad, msg in (("0 0\n", "different"), ("1 2 3\n", "two frame"), ("1 x\n", "integers"),
                     ("1 2\n1 2\n", "twice"), ("# nothing\n", "no pairs")):
        pf.write_text(bad)
        with pytest.raises(ValueError, match=msg):
            read_pairs_file(pf)
    track = BatchConfig("track", "chain", params, fmt="npz", window=4, overlap=1)
    assert [t.output for t in plan_tasks("c", 11, track)] == [
        "c/window_000000.npz", "c/window_000003.npz", "c/window_000006.npz",
        "c/window_000007.npz"]
    assert cfg.identity_hash("1") != BatchConfig("flow", "tvl1-fast", params).identity_hash("1")
    with pytest.raises(ValueError, match="--overlap"):
        BatchConfig("track", "chain", params, fmt="npz", window=4, overlap=4)


def test_expand_inputs(tmp_path: Path, videos: Path) -> None:
    from PIL import Image

    frames = tmp_path / "shot"
    frames.mkdir()
    for k in range(3):
        Image.fromarray(np.full((H, W), 10 * k, np.uint8)).save(frames / f"f{k}.png")
    got = expand_inputs([str(videos)])  # a folder of videos
    assert [(i.name, i.kind) for i in got] == [("clip0", "video"), ("clip1", "video"),
                                              ("clip2", "video")]
    got = expand_inputs([str(videos / "clip*.mkv"), str(videos / "clip1.mkv"), str(frames)])
    assert [i.name for i in got] == ["clip0", "clip1", "clip2", "shot"]
    assert got[-1].kind == "folder"
    lst = tmp_path / "inputs.jsonl"
    lst.write_text(f"# a list\n{videos / 'clip0.mkv'}\n"
                   + json.dumps({"path": "shot", "name": "renamed"}) + "\n")
    assert [i.name for i in expand_inputs([str(lst)])] == ["clip0", "renamed"]
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(videos / "clip0.mkv", other / "clip0.avi")
    with pytest.raises(ValueError, match="two inputs are named 'clip0'"):
        expand_inputs([str(videos / "clip0.mkv"), str(other / "clip0.avi")])
    with pytest.raises(FileNotFoundError):
        expand_inputs([str(tmp_path / "missing.mp4")])
    with pytest.raises(FileNotFoundError):
        expand_inputs([str(tmp_path / "nothing*.mp4")])
    with pytest.raises(ValueError, match="single image"):
        expand_inputs([str(frames / "f0.png")])


def test_manifest_schema_and_settings(tmp_path: Path) -> None:
    params = make_params(get_method("tvl1-fast"))
    cfg = BatchConfig("flow", "tvl1-fast", params)
    with Manifest(tmp_path / "m.sqlite") as m:
        ident = cfg.identity("0")
        assert m.check_settings(ident, cfg.identity_hash("0")) is None
        m.record_settings(ident, cfg.identity_hash("0"), {"x": 1})
        tasks = plan_tasks("a", 3, cfg)
        m.add_tasks(tasks, "/a.mkv", "flow", "tvl1-fast", cfg.params_json, "0")
        m.mark_running(["a/000000.flo"])
        m.finish("a/000000.flo", "done", checksum="ab", seconds=1.5)
        other = BatchConfig("flow", "tvl1-fast", make_params(get_method("tvl1-fast"),
                                                             n_warps=4), stride=2)
        diff = m.check_settings(other.identity("0"), other.identity_hash("0"))
        assert "n_warps 3 -> 4" in diff and "stride" in diff
    conn = sqlite3.connect(tmp_path / "m.sqlite")
    assert [c[1] for c in conn.execute("PRAGMA table_info(tasks)")] == TASK_COLUMNS
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    row = conn.execute("SELECT status, attempts, checksum, frames FROM tasks "
                       "WHERE task_id = 'a/000000.flo'").fetchone()
    assert row == ("done", 1, "ab", "[0, 1]")
    meta = dict(conn.execute("SELECT key, value FROM meta"))
    assert meta["method"] == "tvl1-fast" and json.loads(meta["params"])["n_warps"] == 3
    conn.close()


def test_output_folder_lock(tmp_path: Path, videos: Path) -> None:
    import fcntl

    from varflow.batch import run_batch

    out = tmp_path / "out"
    out.mkdir()
    cfg = BatchConfig("flow", "tvl1-fast", make_params(get_method("tvl1-fast")))
    with open(out / "manifest.lock", "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        with pytest.raises(ValueError, match="another varflow batch run"):
            run_batch(expand_inputs([str(videos / "clip0.mkv")]), out, cfg)


# --------------------------------------------------------------------------- runs


def test_flow_resume_and_settings(tmp_path: Path, videos: Path, scheduler: str,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    """External cluster: outputs equal varflow.flow; resume recomputes nothing done."""
    out = tmp_path / "out"
    args = ["batch", "flow", videos, "-o", out, *FAST, "--scheduler", scheduler, "-q"]
    rc, stdout, err = run(capsys, *args)
    assert rc == 0, err
    assert "12 tasks: 12 done, 0 skipped, 0 failed" in stdout and "pairs/s" in stdout
    first = rows(out)
    assert {r["status"] for r in first.values()} == {"done"}
    assert {r["attempts"] for r in first.values()} == {1}
    # bit-identical to varflow.flow run here
    for k in range(3):
        frames = read_frames(videos / f"clip{k}.mkv")
        for n in range(4):
            direct = tmp_path / "direct.flo"
            write_flo(direct, varflow.flow(frames[n], frames[n + 1], "tvl1-fast"))
            produced = out / f"clip{k}" / f"{n:06d}.flo"
            assert produced.read_bytes() == direct.read_bytes(), produced
            assert first[f"clip{k}/{n:06d}.flo"]["checksum"] is not None
    # a rerun skips everything; a damaged output and a stale temp file are handled
    (out / "clip1" / "000002.flo").write_bytes(b"garbage")
    (out / "clip1" / ".000003.flo.abc123.tmp").write_bytes(b"partial")
    rc, stdout, err = run(capsys, *args)
    assert rc == 0, err
    assert "1 done, 11 skipped, 0 failed" in stdout
    again = rows(out)
    assert {t: r["attempts"] for t, r in again.items()} == {
        t: 1 + (t == "clip1/000002.flo") for t in first}
    assert again["clip1/000002.flo"]["checksum"] == first["clip1/000002.flo"]["checksum"]
    assert not list(out.glob("*/.*.tmp"))
    # other settings: refused (one line), then --overwrite starts again
    rc, _, err = run(capsys, *args, "--n-warps", "2")
    assert rc == 2 and len(err.splitlines()) == 1 and "--overwrite" in err
    assert "n_warps 3 -> 2" in err
    rc, stdout, err = run(capsys, *args, "--stride", "2", "--overwrite")
    assert rc == 0, err
    assert "9 tasks: 9 done" in stdout
    assert not (out / "clip0" / "000003.flo").exists()
    # --scheduler excludes the local-cluster options
    rc, _, err = run(capsys, *args, "--workers", "2")
    assert rc == 2 and "--scheduler" in err


def test_adopt_running_output(tmp_path: Path, videos: Path, scheduler: str,
                              capsys: pytest.CaptureFixture[str]) -> None:
    """An output written after its 'running' record is adopted, an older one is not."""
    out = tmp_path / "out"
    args = ["batch", "flow", videos / "clip0.mkv", "-o", out, *FAST, "--scheduler", scheduler,
            "-q"]
    assert run(capsys, *args)[0] == 0
    conn = sqlite3.connect(out / "manifest.sqlite")
    written = (out / "clip0" / "000000.flo").stat().st_mtime
    with conn:  # as if the driver died after the renames, before recording the results
        conn.execute("UPDATE tasks SET status = 'running', checksum = NULL, updated = ? "
                     "WHERE task_id = 'clip0/000000.flo'", (written - 1,))
        # submitted (per the manifest) long after its file was written: not adopted
        conn.execute("UPDATE tasks SET status = 'running', checksum = NULL, updated = ? "
                     "WHERE task_id = 'clip0/000001.flo'", (written + 60,))
    conn.close()
    rc, stdout, err = run(capsys, *args)
    assert rc == 0, err
    assert "1 done, 3 skipped" in stdout
    r = rows(out)
    assert r["clip0/000000.flo"]["attempts"] == 1 and r["clip0/000000.flo"]["status"] == "done"
    assert r["clip0/000001.flo"]["attempts"] == 2


def test_fingerprint_of_the_numbers() -> None:
    """The fingerprint covers method, every resolved parameter and the version only."""
    params = make_params(get_method("tvl1-fast"))
    cfg = BatchConfig("flow", "tvl1-fast", params)
    fp = cfg.fingerprint("0.2.0")
    assert len(fp) == 64 and fp == BatchConfig("flow", "tvl1-fast", params).fingerprint("0.2.0")
    assert BatchConfig("flow", "tvl1-fast", params, stride=2).fingerprint("0.2.0") == fp
    assert cfg.fingerprint("0.2.1") != fp
    other = make_params(get_method("tvl1-fast"), n_warps=4)
    assert BatchConfig("flow", "tvl1-fast", other).fingerprint("0.2.0") != fp
    with Manifest(Path(":memory:")) as m:  # a recorded fingerprint is compared as well
        ident = cfg.identity("0.2.0")
        m.record_settings(ident, cfg.identity_hash("0.2.0"), None, fp)
        assert m.meta()["fingerprint"] == fp
        assert m.check_settings(ident, cfg.identity_hash("0.2.0"), fp) is None
        assert m.check_settings(ident, cfg.identity_hash("0.2.0"), "0" * 64) is not None
        diff = m.check_settings(cfg.identity("0.3.0"), cfg.identity_hash("0.3.0"),
                                cfg.fingerprint("0.3.0"))
        assert diff == "varflow version 0.2.0 -> 0.3.0"


def test_resume_refused_after_version_or_parameter_change(
    tmp_path: Path, videos: Path, scheduler: str, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An upgrade (another version) or other parameters: refused, one line; --overwrite runs."""
    import varflow._version

    out = tmp_path / "out"
    args = ["batch", "flow", videos / "clip0.mkv", "-o", out, *FAST, "--scheduler", scheduler,
            "-q"]
    rc, _, err = run(capsys, *args)
    assert rc == 0, err
    before = outputs(out)
    with Manifest(out / "manifest.sqlite") as m:
        meta = m.meta()
    assert meta["version"] == varflow.__version__ and len(meta["fingerprint"]) == 64
    old = varflow.__version__
    monkeypatch.setattr(varflow._version, "__version__", "99.0.0")
    rc, stdout, err = run(capsys, *args)
    assert rc == 2 and not stdout and len(err.splitlines()) == 1, err
    assert err.startswith("varflow: error: ")
    assert f"varflow version {old} -> 99.0.0" in err and "--overwrite" in err
    assert outputs(out) == before and rows(out)["clip0/000000.flo"]["version"] == old
    rc, _, err = run(capsys, *args, "--n-warps", "2")  # parameters and version differ
    assert rc == 2 and "n_warps 3 -> 2" in err and "99.0.0" in err and "--overwrite" in err
    monkeypatch.setattr(varflow._version, "__version__", old)
    rc, _, err = run(capsys, *args, "--n-warps", "2")  # parameters only
    assert rc == 2 and "n_warps 3 -> 2" in err and "version" not in err
    monkeypatch.setattr(varflow._version, "__version__", "99.0.0")
    rc, stdout, err = run(capsys, *args, "--overwrite")
    assert rc == 0, err
    assert "4 tasks: 4 done, 0 skipped" in stdout
    assert {r["version"] for r in rows(out).values()} == {"99.0.0"}
    with Manifest(out / "manifest.sqlite") as m:
        meta_new = m.meta()
    assert meta_new["version"] == "99.0.0" and meta_new["fingerprint"] != meta["fingerprint"]
    assert outputs(out) == before  # same code, same numbers
    rc, stdout, err = run(capsys, *args)  # and now it resumes
    assert rc == 0 and "0 done, 4 skipped" in stdout, err


def test_failing_inputs(tmp_path: Path, videos: Path, scheduler: str,
                        capsys: pytest.CaptureFixture[str]) -> None:
    from PIL import Image

    bad = tmp_path / "in"
    bad.mkdir()
    (bad / "corrupt.mkv").write_bytes(os.urandom(5000))
    data = (videos / "clip2.mkv").read_bytes()
    (bad / "truncated.mkv").write_bytes(data[: len(data) * 2 // 3])
    shot = tmp_path / "shot"
    shot.mkdir()
    frames = read_frames(videos / "clip0.mkv")
    for k in range(4):
        Image.fromarray(frames[k]).save(shot / f"{k:03d}.png")
    (shot / "002.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    out = tmp_path / "out"
    rc, stdout, err = run(capsys, "batch", "flow", bad, videos / "clip1.mkv", shot, "-o", out,
                          *FAST, "--scheduler", scheduler, "-q")
    assert rc == 1
    r = rows(out)
    assert r["corrupt/input"]["status"] == "failed" and r["corrupt/input"]["error"]
    assert "varflow: failed: corrupt/input" in err
    assert {r[f"clip1/{n:06d}.flo"]["status"] for n in range(4)} == {"done"}
    assert r["shot/000000.flo"]["status"] == "done"
    assert r["shot/000001.flo"]["status"] == "failed" and "002.png" in r["shot/000001.flo"][
        "error"]
    assert r["shot/000002.flo"]["status"] == "failed"
    truncated = [v for k, v in r.items() if k.startswith("truncated/")]
    assert truncated and all(v["status"] in ("done", "failed") for v in truncated)
    assert all(v["error"] for v in truncated if v["status"] == "failed")
    assert not (out / "shot" / "000001.flo").exists()
    n_failed = sum(v["status"] == "failed" for v in r.values())
    assert f"{n_failed} failed" in stdout
    # a missing input is an error before any work
    rc, _, err = run(capsys, "batch", "flow", tmp_path / "nope.mkv", "-o", tmp_path / "o2")
    assert rc == 2 and "nope.mkv" in err and not (tmp_path / "o2").exists()


def test_track_windows_and_zarr(tmp_path: Path, videos: Path, scheduler: str,
                                capsys: pytest.CaptureFixture[str]) -> None:
    import zarr

    out = tmp_path / "out"
    tparams = ["--scale-factor", "0.5", "--n-warps", "2", "--max-iterations", "20"]
    rc, stdout, err = run(capsys, "batch", "track", videos / "clip0.mkv", "-o", out,
                          "--window", "4", "--overlap", "2", "--method", "chain", *tparams,
                          "--scheduler", scheduler, "--zarr", "-q")
    assert rc == 0, err
    assert "windows/s" in stdout
    files = sorted(p.name for p in (out / "clip0").iterdir())
    assert files == ["window_000000.npz", "window_000001.npz"]  # [0, 4), [1, 5)
    frames = read_frames(videos / "clip0.mkv")
    tf = read_trajectories(out / "clip0" / "window_000001.npz")
    assert tf.ref == 2 and tf.metadata["frames"] == [1, 2, 3, 4]
    assert tf.metadata["ref_frame"] == 3 and tf.metadata["method"] == "chain"
    assert tf.metadata["params"]["flow_params"]["n_warps"] == 2  # chain composes its flow
    traj, vis = varflow.track(frames[1:5], None, "chain", scale_factor=0.5, n_warps=2,
                              max_iterations=20, return_visibility=True)
    np.testing.assert_array_equal(tf.trajectories, traj)
    np.testing.assert_array_equal(tf.visibility, vis)
    group = zarr.open_group(str(out / "clip0.zarr"), mode="r")
    assert group["trajectories"].shape == (2, 4, H, W, 2)
    np.testing.assert_array_equal(group["trajectories"][1], traj)
    np.testing.assert_array_equal(group["visibility"][1], vis)
    assert group.attrs["windows"] == [[0, 4], [1, 5]]
    assert group["written"][:].all()


def test_flow_zarr_png(tmp_path: Path, videos: Path, scheduler: str,
                       capsys: pytest.CaptureFixture[str]) -> None:
    import zarr

    from varflow.io.kitti_png import read_kitti_png

    out = tmp_path / "out"
    rc, _, err = run(capsys, "batch", "flow", videos / "clip2.mkv", "-o", out, *FAST,
                     "--stride", "2", "--format", "png", "--zarr", "--scheduler", scheduler,
                     "-q")
    assert rc == 0, err
    group = zarr.open_group(str(out / "clip2.zarr"), mode="r")
    assert group["flow"].shape == (3, H, W, 2) and group.attrs["pairs"] == [[0, 2], [1, 3],
                                                                           [2, 4]]
    for n in range(3):
        np.testing.assert_array_equal(group["flow"][n],
                                      read_kitti_png(out / "clip2" / f"{n:06d}.png"))


# --------------------------------------------------------------------------- SIGKILL


def _descendants(pid: int) -> set[int]:
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            children.setdefault(int(fields[1]), []).append(int(d.name))
    out: set[int] = set()
    todo = [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            if c not in out:
                out.add(c)
                todo.append(c)
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _done_count(out: Path) -> int:
    db = out / "manifest.sqlite"
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1) as conn:
            return conn.execute("SELECT COUNT(*) FROM tasks WHERE status = 'done'").fetchone()[0]
    except sqlite3.Error:
        return 0


@pytest.mark.slow
def test_sigkill_resume(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Kill the driver twice mid-run; the rerun completes with identical outputs."""
    vids = tmp_path / "vids"
    vids.mkdir()
    for k in range(20):
        make_video(vids / f"v{k:02d}.mkv", n_frames=4, seed=10 + k)
    total = 20 * 3
    ref = tmp_path / "ref"  # uninterrupted, one worker
    rc, _, err = run(capsys, "batch", "flow", vids, "-o", ref, *FAST, "--workers", "1", "-q")
    assert rc == 0, err
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "varflow.cli", "batch", "flow", str(vids), "-o", str(out),
           *FAST, "--workers", "2", "-q"]
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    rng = random.Random(20261130)
    done_before: dict[str, tuple[int, str]] = {}
    for kill in range(2):
        log = open(tmp_path / f"run{kill}.log", "wb")  # noqa: SIM115
        proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        try:
            target = _done_count(out) + rng.randint(4, 20)
            deadline = time.monotonic() + 90
            while (proc.poll() is None and _done_count(out) < target
                   and time.monotonic() < deadline):
                time.sleep(0.02)
            time.sleep(rng.uniform(0.0, 0.15))
            assert proc.poll() is None, "the run finished before it could be killed"
            family = _descendants(proc.pid)
            assert family, "no worker processes"
            if kill == 0:  # the driver alone: its LocalCluster workers must go too
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
                deadline = time.monotonic() + 20
                while any(map(_alive, family)) and time.monotonic() < deadline:
                    time.sleep(0.05)
                survivors = [p for p in family if _alive(p)]
                assert not survivors, f"worker processes outlived the driver: {survivors}"
            else:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
        finally:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait(timeout=10)
            log.close()
        assert proc.returncode == -signal.SIGKILL
        for task_id, r in rows(out).items():
            if r["status"] == "done":
                done_before[task_id] = (r["attempts"], r["checksum"])
    assert 0 < len(done_before) < total
    final = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=180)
    assert final.returncode == 0, final.stderr
    assert f"{total} tasks" in final.stdout and "0 failed" in final.stdout
    got, want = outputs(out), outputs(ref)
    assert len(want) == total and got.keys() == want.keys()
    assert all(got[k] == want[k] for k in want)
    assert not list(out.glob("*/.*.tmp"))
    r = rows(out)
    assert all(v["status"] == "done" for v in r.values())
    for task_id, (attempts, checksum) in done_before.items():  # nothing done was redone
        assert (r[task_id]["attempts"], r[task_id]["checksum"]) == (attempts, checksum)
    # each kill can interrupt at most the tasks in flight (2 workers x 2)
    assert sum(v["attempts"] for v in r.values()) <= total + 2 * 4
