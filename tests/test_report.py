"""``varflow report``: the three input kinds, errors, and rendering in a real browser.

The browser tests drive Debian's headless Chromium through the DevTools protocol
over ``--remote-debugging-pipe`` (standard library only): they load the report from
a ``file://`` URL, collect console messages, uncaught exceptions, log entries and
network requests, measure every ``<img>`` with ``getBoundingClientRect`` and compare
a full-page screenshot against the images' own pixels.  Without Chromium they skip,
unless ``VARFLOW_REQUIRE_BROWSER=1`` (as in CI), which makes them fail.
"""

from __future__ import annotations

import base64
import csv
import io
import json
import re
import sqlite3
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _browser import DevTools
from PIL import Image

import varflow
from varflow import cli
from varflow.batch.manifest import MANIFEST_NAME, Manifest
from varflow.evaluation.bench.common import write_csv
from varflow.io import write_flo, write_image, write_kitti_png
from varflow.io.trajectories import write_trajectories
from varflow.report.figures import HIDDEN_COLOUR, VISIBLE_COLOUR, error_map
from varflow.report.html import BAR_COLOUR
from varflow.viz.colorwheel import flow_to_color

# --------------------------------------------------------------------------- helpers


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


class _Doc(HTMLParser):
    """Images, tables (cell texts), headings, tags and text of a report.

    Each image also gets ``_row`` (number of its enclosing ``div.thumbs`` row, -1 for
    none) and ``_pair`` (number of its enclosing ``div.pair`` group, -1 for none).
    """

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.images: list[dict[str, str]] = []
        self.tables: list[dict[str, Any]] = []
        self.headings: list[str] = []
        self.tags: set[str] = set()
        self.text: list[str] = []
        self.svg_rects: list[dict[str, str]] = []
        self._cell: list[str] | None = None
        self._row: list[str] | None = None
        self._heading: list[str] | None = None
        self._bold = False
        self._divs: list[tuple[str, int]] = []  # (class, number) of the open divs
        self._n_divs = 0

    def _inside(self, cls: str) -> int:
        return next((n for c, n in reversed(self._divs) if cls in c.split()), -1)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = {k: v or "" for k, v in attrs}
        self.tags.add(tag)
        if tag == "div":
            self._n_divs += 1
            self._divs.append((a.get("class", ""), self._n_divs))
        if tag == "img":
            a["_row"] = str(self._inside("thumbs"))
            a["_pair"] = str(self._inside("pair"))
            self.images.append(a)
        elif tag == "rect":
            self.svg_rects.append(a)
        elif tag == "table":
            self.tables.append({"class": a.get("class", ""), "rows": [], "bold": []})
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = []
            self._bold = "best" in a.get("class", "")
        elif tag in ("h1", "h2", "h3", "h4"):
            self._heading = []

    def handle_endtag(self, tag: str) -> None:
        if tag == "div" and self._divs:
            self._divs.pop()
        if tag in ("td", "th") and self._cell is not None and self._row is not None:
            text = "".join(self._cell).strip()
            self._row.append(text)
            if self._bold:
                self.tables[-1]["bold"].append(text)
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[-1]["rows"].append(self._row)
            self._row = None
        elif tag in ("h1", "h2", "h3", "h4") and self._heading is not None:
            self.headings.append("".join(self._heading).strip())
            self._heading = None

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)
        if self._heading is not None:
            self._heading.append(data)

    def table(self, cls: str) -> dict[str, Any]:
        found = [t for t in self.tables if t["class"] == cls]
        assert found, f"no table of class {cls!r}"
        return found[0]

    def role(self, role: str) -> list[dict[str, str]]:
        return [i for i in self.images if i.get("data-role") == role]


def parse(path: Path) -> tuple[str, _Doc]:
    text = path.read_text(encoding="utf-8")
    doc = _Doc()
    doc.feed(text)
    doc.close()
    return text, doc


def decode(img: dict[str, str]) -> np.ndarray:
    prefix = "data:image/png;base64,"
    assert img["src"].startswith(prefix)
    with Image.open(io.BytesIO(base64.b64decode(img["src"][len(prefix):]))) as im:
        assert im.format == "PNG"
        return np.asarray(im.convert("RGB"))


def uniform(h: int, w: int, u: float, v: float) -> np.ndarray:
    f = np.empty((h, w, 2), np.float32)
    f[..., 0], f[..., 1] = u, v
    return f


def assert_self_contained(text: str, doc: _Doc) -> None:
    assert "<script" not in text.lower()
    assert "script" not in doc.tags and "link" not in doc.tags and "iframe" not in doc.tags
    assert all(i["src"].startswith("data:image/png;base64,") for i in doc.images)
    rest = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", text)
    # the only URL is the SVG namespace, which is not a request
    urls = set(re.findall(r"[a-z]+://[^\s\"'<>]*", rest))
    assert urls <= {"http://www.w3.org/2000/svg"}, urls
    assert "url(" not in rest and "href=" not in rest and "@import" not in rest


def assert_close_colour(actual: np.ndarray, expected: np.ndarray, tol: int = 1) -> None:
    diff = np.abs(actual.astype(int) - expected.astype(int)).max()
    assert diff <= tol, f"colour {actual.tolist()} != {expected.tolist()}"


# --------------------------------------------------------------------------- inputs

N_FLOWS = 20
FLOW_SHAPE = (48, 64)
BIG_SHAPE = (200, 400)
TRAJ_SHAPE = (40, 56)
ERROR_TEXT = "solver diverged <b>at</b> frame 20 & gave up"


def flow_u(n: int) -> float:
    """Horizontal motion of flow ``n`` of clipA: grows with n, so one scale matters."""
    return 0.5 + 0.25 * n


def make_trajectories(n_frames: int = 5, ref: int = 2) -> tuple[np.ndarray, np.ndarray]:
    h, w = TRAJ_SHAPE
    traj = np.zeros((n_frames, h, w, 2), np.float32)
    for n in range(n_frames):
        traj[n, ..., 0] = 1.5 * (n - ref)
        traj[n, ..., 1] = -0.5 * (n - ref)
    vis = np.ones((n_frames, h, w), bool)
    vis[-1, :, : w // 2] = False  # the left half is hidden in the last frame
    return traj, vis


def make_batch(root: Path, manifest: bool = True) -> Path:
    """A batch output folder: a flow video, a KITTI video, a big video and a track video."""
    root.mkdir(parents=True, exist_ok=True)
    tasks = []
    (root / "clipA").mkdir()
    for n in range(N_FLOWS):
        write_flo(root / "clipA" / f"{n:06d}.flo", uniform(*FLOW_SHAPE, flow_u(n), 0.0))
        tasks.append((f"clipA:{n}", "videos/clipA.mp4", "clipA", "flow", json.dumps([n, n + 1]),
                      "tvl1", json.dumps({"data_weight": 0.15, "n_warps": 5}), "0.1.0",
                      f"clipA/{n:06d}.flo", "sha256:x", "done", None, 0.5, 1, 0.0))
    tasks.append(("clipA:20", "videos/clipA.mp4", "clipA", "flow", json.dumps([20, 21]), "tvl1",
                  json.dumps({"data_weight": 0.15, "n_warps": 5}), "0.1.0", "clipA/000020.flo",
                  None, "failed", ERROR_TEXT, 3.0, 3, 0.0))
    tasks.append(("clipA:21", "videos/clipA.mp4", "clipA", "flow", json.dumps([21, 22]), "tvl1",
                  json.dumps({"data_weight": 0.15, "n_warps": 5}), "0.1.0", "clipA/000021.flo",
                  None, "pending", None, None, 0, 0.0))
    (root / "clipK").mkdir()
    for n in range(3):
        write_kitti_png(root / "clipK" / f"{n:06d}.png", uniform(*FLOW_SHAPE, 0.0, 2.0))
    (root / "big").mkdir()
    for n in range(2):
        write_flo(root / "big" / f"{n:06d}.flo", uniform(*BIG_SHAPE, -3.0, 0.0))
    (root / "clipB").mkdir()
    traj, vis = make_trajectories()
    write_trajectories(root / "clipB" / "window_000000.npz", traj, ref=2, visibility=vis,
                       metadata={"method": "rlr"})
    tasks.append(("clipB:0", "videos/clipB.mp4", "clipB", "track", json.dumps(list(range(5))),
                  "rlr", json.dumps({"rank": 4}), "0.1.0", "clipB/window_000000.npz", "x",
                  "done", None, 12.0, 1, 0.0))
    if manifest:
        write_manifest(root, tasks, [("stride", "1"), ("created_by", "varflow batch <test>")])
    return root


def write_manifest(root: Path, tasks: list[tuple], meta: list[tuple[str, str]]) -> None:
    """``root/manifest.sqlite`` with the batch runner's own schema, holding these rows."""
    with Manifest(root / MANIFEST_NAME) as man:
        man.conn.executemany("INSERT INTO tasks VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)", tasks)
        man.conn.executemany("INSERT INTO meta VALUES (?, ?)", meta)


@pytest.fixture
def batch(tmp_path: Path) -> Path:
    return make_batch(tmp_path / "out")


# --------------------------------------------------------------------------- batch folders


def test_batch_report(batch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report.html"
    rc, stdout, err = run(capsys, "report", batch, "-o", out, "--max-frames", 5)
    assert rc == 0, err
    assert "batch report" in stdout and str(out) in stdout
    text, doc = parse(out)
    assert_self_contained(text, doc)
    # header: version and source
    assert f"varflow {varflow.__version__}" in text
    assert str(batch.resolve()) in text
    # flows of clipA: 5 of 20, evenly spaced, one scale = the largest |w| shown
    flows = [i for i in doc.role("flow") if i["alt"].startswith("frames")]
    clip_a = [i for i in flows if float(i["data-scale"]) > 5]
    assert [int(i["data-frame"]) for i in clip_a] == [0, 5, 10, 14, 19]
    scale = float(clip_a[0]["data-scale"])
    assert scale == pytest.approx(flow_u(19), rel=1e-4)
    assert {i["data-scale"] for i in clip_a} == {clip_a[0]["data-scale"]}
    assert "full saturation at 5.25 px" in text
    for img in clip_a:
        pixels = decode(img)
        assert pixels.shape == FLOW_SHAPE + (3,)
        expected = flow_to_color(uniform(1, 1, flow_u(int(img["data-frame"])), 0.0),
                                 max_radius=scale)[0, 0]
        assert (pixels == pixels[0, 0]).all()
        assert_close_colour(pixels[0, 0], expected)
    # the colours differ: one scale, not one per frame
    assert len({tuple(decode(i)[0, 0]) for i in clip_a}) == 5
    # KITTI flows (downwards motion) and the big video, downscaled to 256 px
    kitti = [i for i in doc.role("flow") if i["data-scale"].startswith("2")]
    assert len(kitti) == 3
    assert_close_colour(decode(kitti[0])[5, 5],
                        flow_to_color(uniform(1, 1, 0.0, 2.0), max_radius=2.0 * (1 + 1e-5))[0, 0])
    big = [i for i in doc.role("flow") if i["data-scale"].startswith("3")]
    assert len(big) == 2 and decode(big[0]).shape == (128, 256, 3)
    assert "400×200 px shown at 256×128" in text
    # legend per video
    assert len(doc.role("legend")) == 4
    legend = decode(doc.role("legend")[0])
    assert legend.shape == (101, 101, 3) and (legend[50, 50] == 255).all()
    # parameters and settings from the manifest
    params = doc.table("params")
    assert ["data_weight", "0.15"] in params["rows"] and ["n_warps", "5"] in params["rows"]
    meta = doc.table("meta")
    assert ["created_by", "varflow batch <test>"] in meta["rows"]
    videos = doc.table("videos")["rows"]
    row_a = next(r for r in videos if r[0] == "clipA")
    assert row_a[1:7] == ["flow", "tvl1", "20", "20", "1", "1"]
    # failed tasks, escaped
    failed = doc.table("failed")["rows"]
    assert failed[1][0] == "clipA:20" and failed[1][-1] == ERROR_TEXT
    assert "&lt;b&gt;at&lt;/b&gt;" in text and "<b>at</b>" not in text
    # trajectory window: plot, displacement (one scale), visibility
    assert len(doc.role("trajectories")) == 1
    disp = doc.role("displacement")
    assert [int(i["data-frame"]) for i in disp] == [0, 1, 2, 3, 4]
    traj, vis = make_trajectories()
    tscale = float(disp[0]["data-scale"])
    assert tscale == pytest.approx(float(np.hypot(3.0, 1.0)), rel=1e-4)
    for i in disp:
        n = int(i["data-frame"])
        expected = flow_to_color(traj[n, :1, :1], max_radius=tscale)[0, 0]
        assert_close_colour(decode(i)[3, 3], expected)
    visibility = doc.role("visibility")
    last = decode(visibility[-1])
    assert last.shape == TRAJ_SHAPE + (3,)
    assert (last[:, : TRAJ_SHAPE[1] // 2] == HIDDEN_COLOUR).all()
    assert (last[:, TRAJ_SHAPE[1] // 2:] == VISIBLE_COLOUR).all()
    assert (decode(visibility[0]) == VISIBLE_COLOUR).all()


def test_batch_without_manifest(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = make_batch(tmp_path / "out", manifest=False)
    out = tmp_path / "r.html"
    rc, _, err = run(capsys, "report", root, "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    assert "No manifest.sqlite" in text
    videos = [r[0] for r in doc.table("videos")["rows"][1:]]
    assert videos == ["big", "clipA", "clipB", "clipK"]
    clip_a = [i for i in doc.role("flow") if float(i["data-scale"]) > 5]
    assert len(clip_a) == 12  # the default --max-frames
    assert [i["alt"] for i in clip_a[:2]] == ["frame 0", "frame 2"]
    assert not [t for t in doc.tables if t["class"] == "failed"]


def test_batch_unreadable_manifest_and_output(
    batch: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (batch / "manifest.sqlite").write_bytes(b"this is not a database" * 100)
    (batch / "clipK" / "000001.png").write_bytes(b"broken")
    out = tmp_path / "r.html"
    rc, _, err = run(capsys, "report", batch, "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    assert "manifest.sqlite: cannot be read" in text
    assert "Unreadable outputs: 000001.png" in text
    assert len([i for i in doc.role("flow") if i["data-scale"].startswith("2")]) == 2


def test_batch_only_failed_tasks(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "out"
    root.mkdir()
    con = sqlite3.connect(root / "manifest.sqlite")
    con.execute("CREATE TABLE tasks(task_id TEXT PRIMARY KEY, name TEXT, kind TEXT, "
                "status TEXT, error TEXT, output TEXT)")
    con.execute("INSERT INTO tasks VALUES ('v:0', 'v', 'flow', 'failed', 'no such file', "
                "'v/000000.flo')")
    con.commit()
    con.close()
    out = tmp_path / "r.html"
    rc, _, err = run(capsys, "report", root, "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    assert doc.table("failed")["rows"][1][-1] == "no such file"
    assert "No output file yet." in text and not doc.images


def test_batch_pairs_running_and_failed_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Explicit pairs (IIIIII_JJJJJJ.flo), running tasks, an input that failed as a whole."""
    root = tmp_path / "out"
    (root / "pairs").mkdir(parents=True)
    (root / "pairs.zarr" / "0").mkdir(parents=True)  # a Zarr store is not scanned
    (root / "pairs.zarr" / "0" / "000001.flo").write_bytes(b"not a flow")
    write_flo(root / "pairs" / "000000_000005.flo", uniform(8, 8, 1.0, 0.0))
    write_flo(root / "pairs" / "000002_000003.flo", uniform(8, 8, 0.5, 0.0))
    (root / "pairs" / ".000004_000009.flo.abc.tmp").write_bytes(b"partial")  # atomic write
    write_manifest(root, [
        ("pairs/000000_000005.flo", "a.mp4", "pairs", "flow", "[0, 5]", "tvl1", "{}", "0.1",
         "pairs/000000_000005.flo", "x", "done", None, 1.0, 1, 0.0),
        ("pairs/000004_000009.flo", "a.mp4", "pairs", "flow", "[4, 9]", "tvl1", "{}", "0.1",
         "pairs/000004_000009.flo", None, "running", None, None, 1, 0.0),
        ("broken/input", "b.mp4", "broken", "flow", "[]", "tvl1", "{}", "0.1", None, None,
         "failed", "cannot open b.mp4: invalid data", None, 0, 0.0),
    ], [("updated", "1764500000.0")])
    out = tmp_path / "r.html"
    rc, _, err = run(capsys, "report", root, "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    assert [i["alt"] for i in doc.role("flow")] == ["frames 0→5", "frames 2→3"]
    videos = {r[0]: r[1:] for r in doc.table("videos")["rows"][1:]}
    assert set(videos) == {"broken", "pairs"}
    assert videos["pairs"][2:6] == ["2", "1", "0", "1"]  # outputs, done, failed, pending/running
    failed = doc.table("failed")["rows"]
    assert failed[1][:3] == ["broken/input", "broken", "—"]
    assert failed[1][-1] == "cannot open b.mp4: invalid data"
    assert ["updated", "2025-11-30 10:53:20 UTC"] in doc.table("meta")["rows"]
    assert "Unreadable" not in text


def frame_value(k: int) -> int:
    """Grey level of frame k of the inputs of :func:`make_flow_batch`."""
    return 10 + 20 * k


def make_flow_batch(root: Path, source: Path, n_flows: int = 9, video: bool = False) -> Path:
    """A ``varflow batch flow`` folder of ``n_flows`` flows of the pairs (n, n + 1) of
    ``source``: a frame folder (PNG) or, with ``video``, a lossless FFV1 video whose
    frame k is the grey level :func:`frame_value` (k)."""
    from varflow.io.video import write_video

    frames = [np.full(FLOW_SHAPE + (3,), frame_value(k), np.uint8) for k in range(n_flows + 1)]
    if video:
        write_video(source, frames, 10, codec="ffv1", pix_fmt="bgr0")
    else:
        source.mkdir(parents=True)
        for k, f in enumerate(frames):
            write_image(source / f"img{k}.png", f)  # natural order: img2 before img10
    (root / "clip").mkdir(parents=True)
    tasks = []
    for n in range(n_flows):
        write_flo(root / "clip" / f"{n:06d}.flo", uniform(*FLOW_SHAPE, flow_u(n), 0.0))
        tasks.append((f"clip/{n:06d}.flo", str(source), "clip", "flow", json.dumps([n, n + 1]),
                      "tvl1", "{}", "0.1.0", f"clip/{n:06d}.flo", "x", "done", None, 1.0, 1,
                      0.0))
    write_manifest(root, tasks, [("stride", "1")])
    return root


@pytest.mark.parametrize("video", [False, True], ids=["frame folder", "video"])
def test_batch_flows_beside_their_frames(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch, video: bool) -> None:
    """Each flow thumbnail is paired with frame i of its pair (i, j), read from the input
    recorded in the manifest, each frame once (a video: the chosen frames only)."""
    from varflow.io.video import VideoReader

    calls: list[list[int]] = []
    original = VideoReader.read_indices

    def spy(self: VideoReader, indices: list[int]) -> np.ndarray:
        calls.append(list(indices))
        return original(self, indices)

    monkeypatch.setattr(VideoReader, "read_indices", spy)
    source = tmp_path / ("clip.mkv" if video else "frames")
    root = make_flow_batch(tmp_path / "out", source, video=video)
    out = tmp_path / "r.html"
    rc, _, err = run(capsys, "report", root, "-o", out, "--max-frames", 4)
    assert rc == 0, err
    text, doc = parse(out)
    assert_self_contained(text, doc)
    flows, frames = doc.role("flow"), doc.role("frame")
    assert [int(i["data-frame"]) for i in flows] == [0, 3, 5, 8]
    assert [int(i["data-frame"]) for i in frames] == [0, 3, 5, 8]
    for frame, flow in zip(frames, flows, strict=True):
        # frame | flow, in one group of the row, at the thumbnail size
        assert frame["_pair"] == flow["_pair"] != "-1" and frame["_row"] == flow["_row"]
        assert (frame["width"], frame["height"]) == (flow["width"], flow["height"])
        pixels = decode(frame)
        assert pixels.shape == FLOW_SHAPE + (3,)
        assert np.abs(pixels.astype(int) - frame_value(int(frame["data-frame"]))).max() <= 1
    assert len({i["_pair"] for i in flows}) == 4
    assert f"from the input {source}" in text
    assert calls == ([[0, 3, 5, 8]] if video else [])


def test_batch_flows_without_their_input(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """The input was deleted (a report made on another machine): the flows alone and one
    note saying why; a frame folder too short for the pairs likewise."""
    source = tmp_path / "frames"
    root = make_flow_batch(tmp_path / "out", source)
    for f in source.iterdir():
        f.unlink()
    source.rmdir()
    out = tmp_path / "r.html"
    rc, _, err = run(capsys, "report", root, "-o", out, "--max-frames", 4)
    assert rc == 0, err
    text, doc = parse(out)
    assert len(doc.role("flow")) == 4 and not doc.role("frame")
    assert all(i["_pair"] == "-1" for i in doc.role("flow"))
    notes = [t for t in doc.text if t.startswith("Input frames not shown")]
    assert notes == [f"Input frames not shown: input not found: {source}; the flows are shown "
                     f"alone."]
    # only 3 of the 10 frames left: frame 8 is missing
    root2 = make_flow_batch(tmp_path / "out2", tmp_path / "frames2")
    for k in range(3, 10):
        (tmp_path / "frames2" / f"img{k}.png").unlink()
    rc, _, err = run(capsys, "report", root2, "-o", out, "--max-frames", 4)
    assert rc == 0, err
    text, doc = parse(out)
    assert len(doc.role("flow")) == 4 and not doc.role("frame")
    assert "has 3 images, the flows need frame 8" in text


# --------------------------------------------------------------------------- bench CSV


def test_bench_csv_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rows = []
    aee = {"tvl1": [0.2, 0.4, 0.6], "sparse": [0.1, 0.5, 0.3]}
    for m, values in aee.items():
        for seq, v in zip(("Dimetrodon", "Grove2", "Venus"), values, strict=True):
            rows.append({"sequence": seq, "method": m, "aee": v, "aae": 10 * v,
                         "seconds": 2.0 if m == "tvl1" else 6.0, "book_tv_aee": None,
                         "book_aee": None})
    csv_path = tmp_path / "bench.csv"
    write_csv(rows, csv_path)
    out = tmp_path / "bench.html"
    rc, _, err = run(capsys, "report", csv_path, "-o", out, "--title", "Bench <1>")
    assert rc == 0, err
    text, doc = parse(out)
    assert_self_contained(text, doc)
    assert "<title>Bench &lt;1&gt;</title>" in text
    summary = doc.table("summary")
    assert summary["rows"][0][:4] == ["method", "rows", "mean aee px", "mean aae deg"]
    assert summary["rows"][1][:3] == ["tvl1", "3", "0.400"]
    assert summary["rows"][2][:3] == ["sparse", "3", "0.300"]
    assert summary["bold"] == ["0.300"]
    assert summary["rows"][1][-2:] == ["2.000", "6.000"]
    seqs = doc.table("sequences")
    assert seqs["rows"][0] == ["sequence", "tvl1", "sparse"]
    assert seqs["rows"][1] == ["Dimetrodon", "0.200", "0.100"]
    assert seqs["rows"][-1] == ["mean", "0.400", "0.300"]
    assert seqs["bold"] == ["0.100", "0.400", "0.300"]
    # bar charts: one bar per method, lengths proportional to the means
    bars = [r for r in doc.svg_rects if r.get("fill") == BAR_COLOUR]
    assert len(bars) == 4
    assert [float(b["data-value"]) for b in bars[:2]] == pytest.approx([0.4, 0.3])
    assert float(bars[1]["width"]) / float(bars[0]["width"]) == pytest.approx(0.75, rel=1e-2)


def test_bench_csv_groups_and_trajectory_rows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rows = [
        {"suite": "procedural", "scene": "affine", "variant": "clean", "method": "rlr",
         "epe": 0.5, "rms": 0.7, "seconds": 1.0},
        {"suite": "procedural", "scene": "affine", "variant": "clean", "method": "mfsf",
         "epe": 0.25, "rms": 0.4, "seconds": 2.0},
        {"suite": "photo", "split": "reporting", "family": "rotate", "seed": 100,
         "method": "rlr", "epe": 1.5, "far_epe": 2.0, "rms": 2.0, "occ_accuracy": 0.9,
         "hidden_recall": 0.5, "seconds": 3.0},
    ]
    csv_path = tmp_path / "traj.csv"
    write_csv(rows, csv_path)  # the leading Middlebury columns stay empty
    out = tmp_path / "traj.html"
    rc, _, err = run(capsys, "report", csv_path, "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    assert "main error measure: EPE" in text
    assert "suite procedural" in doc.headings and "suite photo" in doc.headings
    seq_tables = [t for t in doc.tables if t["class"] == "sequences"]
    assert seq_tables[0]["rows"][1] == ["affine / clean", "0.500", "0.250"]
    assert seq_tables[1]["rows"][1] == ["reporting / rotate / 100", "1.500"]


# --------------------------------------------------------------------------- single files


def test_flow_with_ground_truth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    est = uniform(30, 40, 2.0, 0.0)
    gt = uniform(30, 40, 2.0, 1.5)
    gt[:3] = np.nan  # unknown ground truth
    write_flo(tmp_path / "est.flo", est)
    write_flo(tmp_path / "gt.flo", gt)
    out = tmp_path / "f.html"
    rc, _, err = run(capsys, "report", tmp_path / "est.flo", "--gt", tmp_path / "gt.flo",
                     "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    assert_self_contained(text, doc)
    metrics = {r[0]: r[1] for r in doc.table("metrics")["rows"][1:]}
    assert metrics["AEE"] == "1.500" and metrics["RMS"] == "1.500"
    assert metrics["R1"] == "100.000" and metrics["R3"] == "0.000"
    assert float(metrics["AAE"]) > 0
    scale = float(doc.role("flow")[0]["data-scale"])
    assert scale == pytest.approx(2.5, rel=1e-4)  # the ground truth's largest |w|
    assert_close_colour(decode(doc.role("flow")[0])[10, 10],
                        flow_to_color(est[:1, :1], max_radius=scale)[0, 0])
    gimg = decode(doc.role("gt")[0])
    assert (gimg[:3] == 0).all()  # unknown: black
    assert_close_colour(gimg[10, 10], flow_to_color(gt[5:6, :1], max_radius=scale)[0, 0])
    emap = decode(doc.role("error")[0])
    vmax = float(doc.role("error")[0]["data-vmax"])
    assert vmax == pytest.approx(1.5, rel=1e-4)
    assert (emap[:3] == 128).all()
    assert_close_colour(emap[10, 10], error_map(np.full((1, 1), 1.5), vmax)[0, 0])
    assert decode(doc.role("colorbar")[0]).shape == (14, 256, 3)


def test_kitti_flow_without_ground_truth(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_kitti_png(tmp_path / "k.png", uniform(700, 900, 0.0, -4.0))
    out = tmp_path / "k.html"
    rc, _, err = run(capsys, "report", tmp_path / "k.png", "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    img = decode(doc.role("flow")[0])
    assert img.shape == (498, 640, 3)  # downscaled: longer side 640
    assert "900×700 px shown at 640×498" in text
    assert not doc.role("error") and "No ground truth given" in text


def texture(h: int, w: int, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
    """A smooth grey texture on 0..255 sampled at ``(x - dx, y - dy)``: the texture at
    ``(0, 0)`` translated by ``(dx, dy)``, so that ``texture(dx, dy)(x + d) =
    texture(0, 0)(x)``."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = xx - dx, yy - dy
    return 128 + 60 * np.sin(0.3 * x + 0.2 * y) + 40 * np.cos(0.25 * y - 0.15 * x)


def photometric(img: dict[str, str]) -> float:
    """The photometric error stated in the caption (alt text) of the warped image,
    checked against its ``data-photometric``."""
    stated = float(re.search(r"photometric error (\d+\.\d+) ", img["alt"]).group(1))
    assert stated == pytest.approx(float(img["data-photometric"]), abs=0.006)
    return stated


ROW_ROLES = ["frame0", "frame1", "warped", "flow", "gt", "legend", "error", "colorbar"]


def test_flow_with_frames_in_one_row(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--frames F0 F1: the frames, frame 1 warped back, the estimate, the truth and the
    error map in one row at one size; the warped frame's photometric error is small for
    the exact flow of a translated texture and large for a wrong one."""
    h, w = 90, 120
    u, v = 1.3, -0.7  # sub-pixel
    frame0 = np.rint(texture(h, w)).astype(np.uint8)
    write_image(tmp_path / "f0.png", frame0)
    write_image(tmp_path / "f1.png", np.rint(texture(h, w, u, v)).astype(np.uint8))
    write_flo(tmp_path / "est.flo", uniform(h, w, u, v))
    write_flo(tmp_path / "gt.flo", uniform(h, w, u, v + 0.5))
    write_flo(tmp_path / "zero.flo", uniform(h, w, 0.0, 0.0))
    out = tmp_path / "f.html"
    rc, _, err = run(capsys, "report", tmp_path / "est.flo", "--gt", tmp_path / "gt.flo",
                     "--frames", tmp_path / "f0.png", tmp_path / "f1.png", "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    assert_self_contained(text, doc)
    row = [i for i in doc.images if i["_row"] == doc.role("flow")[0]["_row"]]
    assert [i["data-role"] for i in row] == ROW_ROLES  # one row, in this order
    big = [i for i in row if i["data-role"] not in ("legend", "colorbar")]
    assert {(i["width"], i["height"]) for i in big} == {(str(w), str(h))}  # one shown size
    assert all(decode(i).shape == (h, w, 3) for i in big)
    # the frames are shown as they are (grey -> equal RGB channels)
    assert (decode(doc.role("frame0")[0]) == frame0[..., None]).all()
    assert "f1.png" in doc.role("frame1")[0]["alt"]
    # frame 1 warped back by the exact flow is frame 0, up to interpolation and rounding
    warped = doc.role("warped")[0]
    assert photometric(warped) < 2.0
    assert float(warped["data-inside"]) == pytest.approx(
        (w - 2) * (h - 1) / (w * h), abs=0.01)  # x + 1.3 > w - 1 and y - 0.7 < 0 leave
    inside = decode(warped)[5:-5, 5:-5].astype(int)
    assert np.abs(inside - frame0[5:-5, 5:-5, None]).mean() < 2.0
    assert "frames: " in text and str((tmp_path / "f1.png").resolve()) in text
    # a wrong flow: a large photometric error
    rc, _, err = run(capsys, "report", tmp_path / "zero.flo", "--frames", tmp_path / "f0.png",
                     tmp_path / "f1.png", "-o", out)
    assert rc == 0, err
    _, doc = parse(out)
    assert photometric(doc.role("warped")[0]) > 10.0
    assert float(doc.role("warped")[0]["data-inside"]) == 1.0
    row = [i for i in doc.images if i["_row"] == doc.role("flow")[0]["_row"]]
    assert [i["data-role"] for i in row] == ["frame0", "frame1", "warped", "flow", "legend"]


@pytest.mark.parametrize("kind", ["uint8 colour", "uint16 grey", "float32 grey"])
def test_flow_frames_of_any_type(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                 kind: str) -> None:
    """Grey or colour, 8-bit, 16-bit or float frames are shown as they look, box-filtered
    to the row's size with the flow; one frame alone gives no warped image."""
    h, w = 300, 800
    grad = np.linspace(0.0, 1.0, w)[None, :].repeat(h, axis=0)  # dark left, bright right
    expected = np.floor(255 * grad + 0.5)
    if kind == "uint8 colour":
        frame = np.zeros((h, w, 3), np.uint8)
        frame[..., 0] = np.rint(255 * grad)
        frame[..., 2] = 200
        write_image(tmp_path / "f0.png", frame)
        expected = np.stack([expected, np.zeros_like(expected), np.full_like(expected, 200)], -1)
        name = "f0.png"
    elif kind == "uint16 grey":
        write_image(tmp_path / "f0.png", np.rint(65535 * grad).astype(np.uint16))
        expected = np.repeat(expected[..., None], 3, axis=2)
        name = "f0.png"
    else:
        Image.fromarray(grad.astype(np.float32), mode="F").save(tmp_path / "f0.tif")
        expected = np.repeat(expected[..., None], 3, axis=2)
        name = "f0.tif"
    write_flo(tmp_path / "est.flo", uniform(h, w, 1.0, 0.0))
    out = tmp_path / "f.html"
    rc, _, err = run(capsys, "report", tmp_path / "est.flo", "--frames", tmp_path / name,
                     "-o", out)
    assert rc == 0, err
    text, doc = parse(out)
    frame, flow = doc.role("frame0")[0], doc.role("flow")[0]
    assert frame["_row"] == flow["_row"] and not doc.role("warped") and not doc.role("frame1")
    shown = decode(frame)
    assert shown.shape == decode(flow).shape == (240, 640, 3)  # 2 images: 640 px each
    assert (frame["width"], frame["height"]) == (flow["width"], flow["height"]) == ("640", "240")
    small = np.asarray(Image.fromarray(expected.astype(np.uint8)).resize(
        (640, 240), Image.Resampling.BOX)).astype(int)
    assert np.abs(shown.astype(int) - small).max() <= 2
    assert "800×300 px shown at 640×240" in text


def test_trajectory_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    traj, vis = make_trajectories(n_frames=9, ref=4)
    traj *= 0.25  # short tracks: the frame shows between them
    path = tmp_path / "t.npz"
    write_trajectories(path, traj, ref=4, visibility=vis,
                       metadata={"method": "rlr", "params": {"rank": 3}, "seconds": 1.25})
    frame = np.zeros(TRAJ_SHAPE, np.uint8)
    frame[:, TRAJ_SHAPE[1] // 2:] = 255
    write_image(tmp_path / "ref.png", frame)
    out = tmp_path / "t.html"
    rc, _, err = run(capsys, "report", path, "-o", out, "--frames", tmp_path / "ref.png",
                     "--max-frames", 3)
    assert rc == 0, err
    text, doc = parse(out)
    assert_self_contained(text, doc)
    assert "over reference frame ref.png" in text
    assert [int(i["data-frame"]) for i in doc.role("displacement")] == [0, 4, 8]
    assert [int(i["data-frame"]) for i in doc.role("visibility")] == [0, 4, 8]
    plot = decode(doc.role("trajectories")[0])
    assert plot.shape == (4 * TRAJ_SHAPE[0], 4 * TRAJ_SHAPE[1], 3)  # small: drawn enlarged
    assert "56×40 px shown at 224×160" in text
    assert ["rank", "3"] in doc.table("params")["rows"]
    assert ["method", "rlr"] in doc.table("info")["rows"]
    # the reference frame (dimmed to half) is under the tracks: black left, grey right
    half = plot.shape[1] // 2
    black, grey = (plot == 0).all(axis=2), (plot == 128).all(axis=2)
    assert black[:, :half].any() and not black[:, half:].any()
    assert grey[:, half:].any() and not grey[:, :half].any()
    rc, _, err = run(capsys, "report", path, "-o", out)  # neutral background
    assert rc == 0, err
    assert "on a neutral background" in out.read_text(encoding="utf-8")


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("missing", "report input not found"),
        ("txt", "cannot report on a .txt file"),
        ("empty_dir", "no flows"),
        ("csv_no_method", "no 'method' column"),
        ("bad_flo", ""),
        ("gt_with_folder", "--gt: only for a single flow file"),
        ("gt_shape", "--gt:"),
        ("bad_output", "must end in .html"),
        ("output_dir_missing", "directory does not exist"),
        ("max_frames", "--max-frames"),
        ("frames_with_batch", "--frames: only for a single flow or trajectory file"),
        ("frames_unreadable", "--frames: "),
        ("frames_three", "--frames: a flow takes its two input frames"),
    ],
)
def test_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str], case: str,
                message: str) -> None:
    out = tmp_path / "r.html"
    flo = tmp_path / "f.flo"
    write_flo(flo, uniform(8, 8, 1.0, 0.0))
    args: list[object] = {
        "missing": [tmp_path / "nope", "-o", out],
        "txt": [tmp_path / "a.txt", "-o", out],
        "empty_dir": [tmp_path / "empty", "-o", out],
        "csv_no_method": [tmp_path / "x.csv", "-o", out],
        "bad_flo": [tmp_path / "bad.flo", "-o", out],
        "gt_with_folder": [tmp_path / "empty", "--gt", flo, "-o", out],
        "gt_shape": [flo, "--gt", tmp_path / "g.flo", "-o", out],
        "bad_output": [flo, "-o", tmp_path / "r.txt"],
        "output_dir_missing": [flo, "-o", tmp_path / "no" / "r.html"],
        "max_frames": [flo, "-o", out, "--max-frames", "0"],
        "frames_with_batch": [tmp_path / "empty", "-o", out, "--frames", flo],
        "frames_unreadable": [flo, "-o", out, "--frames", flo],
        "frames_three": [flo, "-o", out, "--frames", flo, flo, flo],
    }[case]
    (tmp_path / "a.txt").write_text("hello")
    (tmp_path / "empty").mkdir()
    with open(tmp_path / "x.csv", "w", newline="") as f:
        csv.writer(f).writerows([["a", "b"], ["1", "2"]])
    (tmp_path / "bad.flo").write_bytes(b"PIEH" + b"\0" * 3)
    write_flo(tmp_path / "g.flo", uniform(4, 8, 1.0, 0.0))
    rc, stdout, err = run(capsys, "report", *args)
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("varflow: error: "), err
    assert message in lines[0]
    assert not out.exists() and not (tmp_path / "r.txt").exists()
    assert not list(tmp_path.glob(".r.html.*"))  # no temporary file left


def test_flow_frames_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A frame of another size than the flow, and two frames for a trajectory file."""
    write_flo(tmp_path / "f.flo", uniform(30, 40, 1.0, 0.0))
    write_image(tmp_path / "ok.png", np.zeros((30, 40), np.uint8))
    write_image(tmp_path / "small.png", np.zeros((20, 40, 3), np.uint8))
    out = tmp_path / "r.html"
    rc, _, err = run(capsys, "report", tmp_path / "f.flo", "--frames", tmp_path / "ok.png",
                     tmp_path / "small.png", "-o", out)
    assert rc == 2 and not out.exists()
    assert err.strip() == (f"varflow: error: --frames: {tmp_path / 'small.png'} is 40×20 px, "
                           f"the flow is 40×30 px")
    traj, vis = make_trajectories()
    write_trajectories(tmp_path / "t.npz", traj, ref=2, visibility=vis)
    rc, _, err = run(capsys, "report", tmp_path / "t.npz", "--frames", tmp_path / "ok.png",
                     tmp_path / "ok.png", "-o", out)
    assert rc == 2 and not out.exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0] == ("varflow: error: --frames: a trajectory file takes one reference frame "
                        "(an image or a folder of frames), got 2 paths")


# --------------------------------------------------------------------------- the browser


_IMAGES_JS = """JSON.stringify([...document.images].map(i => {
  const r = i.getBoundingClientRect();
  return {id: i.id, role: i.dataset.role, x: r.left + scrollX, y: r.top + scrollY,
          w: r.width, h: r.height, ok: i.complete && i.naturalWidth > 0,
          nw: i.naturalWidth, nh: i.naturalHeight};
}))"""


def rendered(shot: np.ndarray, box: dict[str, Any]) -> np.ndarray:
    """The screenshot pixels of an image, sampled at the centres of its image pixels."""
    zoom_x, zoom_y = box["w"] / box["nw"], box["h"] / box["nh"]
    xs = np.floor(box["x"] + (np.arange(box["nw"]) + 0.5) * zoom_x).astype(int)
    ys = np.floor(box["y"] + (np.arange(box["nh"]) + 0.5) * zoom_y).astype(int)
    assert xs.max() < shot.shape[1] and ys.max() < shot.shape[0], "image outside the screenshot"
    return shot[np.ix_(ys, xs)]


def test_browser_renders_batch_report(browser: DevTools, batch: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report.html"
    rc, _, err = run(capsys, "report", batch, "-o", out, "--max-frames", 5)
    assert rc == 0, err
    _, doc = parse(out)
    browser.load(out.as_uri())
    assert browser.problems() == []
    assert browser.evaluate("document.title").startswith("varflow report")
    boxes = json.loads(browser.evaluate(_IMAGES_JS))
    assert len(boxes) == len(doc.images) > 20
    shot = browser.screenshot()
    Image.fromarray(shot).save(tmp_path / "screenshot.png")
    by_id = {i["id"]: i for i in doc.images}
    page_bg = np.array([255, 255, 255])
    for box in boxes:
        assert box["ok"], f"{box['id']} ({box['role']}) did not decode"
        expected = decode(by_id[box["id"]])
        assert (box["nh"], box["nw"]) == expected.shape[:2]
        got = rendered(shot, box)
        diff = np.abs(got.astype(int) - expected.astype(int))
        # the rendered image is the image: every pixel within 2 levels, almost all exact
        assert np.mean(diff.max(axis=2) <= 2) > 0.97, f"{box['id']} ({box['role']}) differs"
        if (expected != page_bg).any():  # not blank where the image is not
            assert np.abs(got.astype(int) - page_bg).max() > 20, f"{box['id']} is blank"
    # a known colour at a known place: the first clipA flow (u = 0.5, scale 5.25 px)
    first = next(b for b in boxes if b["id"] == next(
        i["id"] for i in doc.role("flow") if i.get("data-frame") == "0"
        and float(i["data-scale"]) > 5))
    cx, cy = int(first["x"] + first["w"] / 2), int(first["y"] + first["h"] / 2)
    expected = flow_to_color(uniform(1, 1, flow_u(0), 0.0), max_radius=flow_u(19))[0, 0]
    assert_close_colour(shot[cy, cx], expected, tol=2)
    # hidden half of the last visibility map is dark on screen
    vis = [b for b in boxes if b["role"] == "visibility"][-1]
    left = shot[int(vis["y"] + 5), int(vis["x"] + 3)]
    right = shot[int(vis["y"] + 5), int(vis["x"] + vis["w"] - 3)]
    assert_close_colour(left, np.array(HIDDEN_COLOUR), tol=2)
    assert_close_colour(right, np.array(VISIBLE_COLOUR), tol=2)


def test_browser_renders_bench_chart(browser: DevTools, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    rows = [{"sequence": s, "method": m, "aee": v, "aae": 1.0, "seconds": 1.0}
            for m, v in (("tvl1", 0.4), ("sparse", 0.2)) for s in ("a", "b")]
    write_csv(rows, tmp_path / "b.csv")
    out = tmp_path / "b.html"
    rc, _, err = run(capsys, "report", tmp_path / "b.csv", "-o", out)
    assert rc == 0, err
    browser.load(out.as_uri())
    assert browser.problems() == []
    bars = json.loads(browser.evaluate("""JSON.stringify([...document.querySelectorAll(
        'svg.chart rect')].map(r => { const b = r.getBoundingClientRect();
        return {x: b.left + scrollX, y: b.top + scrollY, w: b.width, h: b.height}; }))"""))
    assert len(bars) == 4
    assert bars[1]["w"] == pytest.approx(bars[0]["w"] / 2, rel=0.02)
    shot = browser.screenshot()
    colour = np.array([int(BAR_COLOUR[i:i + 2], 16) for i in (1, 3, 5)])
    for b in bars:
        assert_close_colour(shot[int(b["y"] + b["h"] / 2), int(b["x"] + b["w"] / 2)], colour,
                            tol=2)


def test_browser_shows_flow_truth_and_error_side_by_side(
        browser: DevTools, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A flow with its ground truth and its input frames: frame 0, frame 1, frame 1
    warped back, the estimate, the truth and the error map in one row, their tops
    level, left to right and of one size, not stacked."""
    est = uniform(30, 40, 1.0, 1.5)
    write_flo(tmp_path / "est.flo", est)
    write_flo(tmp_path / "gt.flo", uniform(30, 40, 2.0, 1.5))
    write_image(tmp_path / "f0.png", np.rint(texture(30, 40)).astype(np.uint8))
    rgb = np.repeat(np.rint(texture(30, 40, 1.0, 1.5))[..., None], 3, axis=2)
    write_image(tmp_path / "f1.png", (257 * rgb).astype(np.uint16))  # 16-bit colour
    out = tmp_path / "f.html"
    rc, _, err = run(capsys, "report", tmp_path / "est.flo", "--gt", tmp_path / "gt.flo",
                     "--frames", tmp_path / "f0.png", tmp_path / "f1.png", "-o", out)
    assert rc == 0, err
    browser.load(out.as_uri())
    assert browser.problems() == []
    boxes = {b["role"]: b for b in json.loads(browser.evaluate(_IMAGES_JS))}
    row = [boxes[r] for r in ("frame0", "frame1", "warped", "flow", "gt", "error")]
    assert all(b["ok"] for b in row)
    for left, right in zip(row, row[1:], strict=False):
        assert right["y"] == pytest.approx(left["y"], abs=2), (left["role"], right["role"])
        assert left["x"] + left["w"] <= right["x"], (left["role"], right["role"])
        assert (right["w"], right["h"]) == (left["w"], left["h"])


def test_browser_detects_console_errors(browser: DevTools, tmp_path: Path) -> None:
    """The check above is meaningful: errors of a broken page are all reported."""
    bad = tmp_path / "bad.html"
    bad.write_text("<!DOCTYPE html><html><head><title>bad</title></head><body>"
                   "<script>console.error('deliberate error');</script>"
                   "<script>undefined_function_xyz();</script>"
                   '<img src="missing.png" alt="missing"></body></html>', encoding="utf-8")
    browser.load(bad.as_uri())
    problems = browser.problems()
    assert any("deliberate error" in p for p in problems), problems
    assert any("undefined_function_xyz" in p for p in problems), problems
    assert any("missing.png" in p or "ERR_FILE_NOT_FOUND" in p for p in problems), problems
    good = tmp_path / "good.html"
    good.write_text("<!DOCTYPE html><html><head><title>ok</title></head><body>"
                    "<script>console.log('fine');</script></body></html>", encoding="utf-8")
    browser.load(good.as_uri())
    assert browser.problems() == []
