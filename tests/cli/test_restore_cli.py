"""``varflow restore``.

The clip: the moving texture of :mod:`test_denoise_cli` (8 frames of 48x64 RGB), with
a dark blotch on frame 3 and a bright one on frame 5, as a lossless video (FFV1) and
as a folder of PNG frames.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from test_denoise_cli import H, W, clean_clip, no_leftovers, one_line_error, run

from varflow.io.images import write_image
from varflow.io.sequences import read_frames
from varflow.io.video import write_video

pytestmark = pytest.mark.usefixtures("one_numba_thread")

BLOTCHES = {3: (slice(10, 17), slice(20, 27), 10), 5: (slice(30, 36), slice(40, 46), 245)}


def dirty_clip() -> tuple[np.ndarray, np.ndarray]:
    clean = clean_clip()
    dirty = np.clip(np.rint(clean), 0, 255).astype(np.uint8)
    mask = np.zeros(dirty.shape[:3], bool)
    for f, (ys, xs, v) in BLOTCHES.items():
        dirty[f, ys, xs] = v
        mask[f, ys, xs] = True
    return dirty, mask


@pytest.fixture(scope="module")
def sources(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("restore")
    dirty, _ = dirty_clip()
    video = root / "dirty.mkv"
    write_video(video, list(dirty), fps=25)
    folder = root / "frames"
    folder.mkdir()
    for k, f in enumerate(dirty):
        write_image(folder / f"f{k:03d}.png", f)
    return {"video": video, "folder": folder}


_HEAD = re.compile(r"^restore (?P<stages>[a-z +]+): (?P<n>\d+) frames of (?P<w>\d+)x(?P<h>\d+) "
                   r"RGB 8-bit at 25 fps, no scene cut, [\d.]+ s/frame \([\d.]+ s\) -> ")
_TAIL = re.compile(r"^seconds per frame: (?:[a-z-]+(?: [a-z-]+)? \d+\.\d\d(?:, |$))+")


def test_restore_dirt_with_mask_video(capsys, sources, tmp_path: Path) -> None:
    out, mask = tmp_path / "clean.mkv", tmp_path / "mask.mkv"
    rc, stdout, err = run(capsys, "restore", sources["video"], "-o", out, "--dirt",
                          "--mask-video", mask, "--set", "dirt.sensitivity=1.0", "-q")
    assert rc == 0, err
    head, tail = stdout.splitlines()
    m = _HEAD.match(head)
    assert m and m["stages"] == "dirt" and int(m["n"]) == 8, head
    assert (int(m["w"]), int(m["h"])) == (W, H)
    assert "dirt replaced" in head and f"mask -> {mask}" in head
    assert _TAIL.match(tail) and tail.startswith("seconds per frame: dirt "), tail
    dirty, truth = dirty_clip()
    restored = np.stack(read_frames(out))
    masks = np.stack(read_frames(mask))
    assert restored.shape == dirty.shape and masks.shape == dirty.shape[:3]
    found = masks > 127
    assert found[truth].mean() > 0.95
    assert (found & ~truth).sum() < 0.2 * truth.sum()
    assert np.array_equal(restored[~found], dirty[~found])
    clean = clean_clip()
    for f, (ys, xs, _) in BLOTCHES.items():
        assert np.abs(restored[f, ys, xs].astype(float) - clean[f, ys, xs]).mean() < 8
    no_leftovers(tmp_path)


def test_restore_folder_runs_stages_in_order(capsys, sources, tmp_path: Path) -> None:
    out = tmp_path / "out"
    rc, stdout, err = run(capsys, "restore", sources["folder"], "-o", out, "--dirt",
                          "--stabilise", "--set", "stabilise.smooth=4", "-q")
    assert rc == 0, err
    assert stdout.startswith("restore stabilise + dirt: 8 frames"), stdout
    assert "stabilise " in stdout.splitlines()[1] and ", dirt " in stdout.splitlines()[1]
    frames = sorted(p.name for p in out.iterdir())
    assert frames == [f"{k:06d}.png" for k in range(8)]


@pytest.mark.parametrize("extra, words", [
    (("--set", "dirt.bogus=1", "--dirt"), ("--set dirt.bogus", "not a parameter of dirt")),
    (("--set", "dirt.sensitivity=abc", "--dirt"), ("--set dirt.sensitivity", "a number")),
    (("--set", "deflicker.window=3", "--dirt"), ("deflicker", "not run")),
    (("--set", "sensitivity", "--dirt"), ("STAGE.FIELD=VALUE",)),
    (("--set", "dirt.sensitivity=-2", "--dirt"), ("sensitivity",)),
    (("--mask-video", "m.mkv", "--deflicker"), ("--mask-video", "--dirt")),
])
def test_bad_settings_one_line(capsys, sources, tmp_path: Path, extra, words) -> None:
    out = tmp_path / "o.mkv"
    rc, stdout, err = run(capsys, "restore", sources["video"], "-o", out, *extra, "-q")
    one_line_error(rc, stdout, err, *words)
    assert not out.exists()


def test_bad_inputs_one_line_and_no_output(capsys, tmp_path: Path) -> None:
    out = tmp_path / "o.mkv"
    rc, stdout, err = run(capsys, "restore", tmp_path / "missing.mkv", "-o", out, "--dirt")
    one_line_error(rc, stdout, err, "missing.mkv")
    corrupt = tmp_path / "corrupt.mkv"
    corrupt.write_bytes(b"\x1aE\xdf\xa3" + bytes(range(256)) * 8)
    rc, stdout, err = run(capsys, "restore", corrupt, "-o", out, "--dirt", "-q")
    one_line_error(rc, stdout, err, "corrupt.mkv")
    rc, stdout, err = run(capsys, "restore", corrupt, "-o", corrupt, "--dirt", "-q")
    one_line_error(rc, stdout, err)
    assert not out.exists()
    no_leftovers(tmp_path)


def test_batch_restore_writes_and_resumes(capsys, sources, tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    import sqlite3

    out = tmp_path / "out"
    args = ("batch", "restore", sources["video"], sources["folder"], "-o", out, "--dirt",
            "--set", "dirt.sensitivity=1.0", "--workers", "1", "-q")
    rc, stdout, err = run(capsys, *args)
    assert rc == 0, err
    assert "2 tasks: 2 done, 0 skipped, 0 failed" in stdout
    dirty, truth = dirty_clip()
    for name in ("dirty", "frames"):
        restored = np.stack(read_frames(out / f"{name}.mkv"))
        assert restored.shape == dirty.shape
        inside = np.abs(restored.astype(float) - dirty)[truth].mean()
        assert inside > 40, (name, inside)  # the blotches were replaced
    with sqlite3.connect(f"file:{out / 'manifest.sqlite'}?mode=ro", uri=True) as conn:
        rows = dict(conn.execute("SELECT task_id, method FROM tasks").fetchall())
    assert rows == {"dirty/dirty.mkv": "dirt", "frames/frames.mkv": "dirt"}
    rc, stdout, err = run(capsys, *args)  # a second run: nothing to do
    assert rc == 0 and "2 tasks: 0 done, 2 skipped, 0 failed" in stdout, err
    rc, stdout, err = run(capsys, *args[:-3], "--set", "dirt.sensitivity=2", "-q")
    one_line_error(rc, stdout, err, "--overwrite")  # other settings: refused
    one_line_error(*run(capsys, *args, "--zarr"), "--zarr")


def test_chain_params_identify_a_batch() -> None:
    from varflow.batch.plan import BatchConfig, plan_tasks
    from varflow.restore.chain import ChainParams

    chain = ChainParams.resolve(["dirt", "denoise"], {"dirt": {"sensitivity": 1.5}},
                                "nlbayes-fast")
    assert chain.label == "dirt+nlbayes-fast" and chain.stages == ("dirt", "denoise")
    kw = chain.as_kwargs()
    assert kw["stages"] == ["dirt", "denoise"] and kw["params"]["dirt"].sensitivity == 1.5
    cfg = BatchConfig("restore", chain.label, chain, fmt="mkv")
    assert [t.output for t in plan_tasks("a", 10, cfg)] == ["a.mkv"]
    other = BatchConfig("restore", chain.label, ChainParams.resolve(
        ["dirt", "denoise"], None, "nlbayes-fast"), fmt="mkv")
    assert cfg.fingerprint("1") != other.fingerprint("1")
    with pytest.raises(ValueError, match="--format"):
        BatchConfig("restore", chain.label, chain, fmt="gif")
