"""Loading the inputs of ``varflow report``.

Three kinds of input are recognised by :func:`detect_kind`:

* ``"batch"``: a batch output folder ``OUT/`` with ``OUT/<name>/NNNNNN.flo`` (or KITTI
  ``NNNNNN.png``) flows, flow from frame ``N`` to ``N + stride`` (``IIIIII_JJJJJJ.flo``:
  an explicit pair, frame ``I`` to ``J``), and
  ``OUT/<name>/window_SSSSSS.npz`` trajectory windows, optionally described by
  ``OUT/manifest.sqlite`` (tables ``tasks`` and ``meta``).  The folder is always
  scanned; the manifest adds methods, parameters, timings and failed tasks.  A
  manifest that cannot be read is reported, not fatal.
* ``"bench"``: a CSV written by ``varflow bench ... --csv`` (a ``method`` column and
  metric columns such as ``aee`` or ``epe``).
* ``"flow"`` (a ``.flo`` or KITTI ``.png`` file) and ``"trajectories"`` (a ``.npz``
  file written by :func:`varflow.io.trajectories.write_trajectories`).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import math
import os
import re
import sqlite3
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "Task",
    "Video",
    "BatchFolder",
    "BenchTable",
    "detect_kind",
    "load_batch",
    "load_bench_csv",
    "evenly_spaced",
    "MANIFEST_NAME",
]

logger = logging.getLogger(__name__)

#: File name of the batch manifest inside the output folder.
MANIFEST_NAME = "manifest.sqlite"
_FLOW_FILE = re.compile(r"^(\d+)(?:_(\d+))?\.(flo|png)$", re.IGNORECASE)
_WINDOW_FILE = re.compile(r"^window_(\d+)\.npz$", re.IGNORECASE)
_TASK_COLUMNS = ("task_id", "input", "name", "kind", "frames", "method", "params", "version",
                 "output", "checksum", "status", "error", "seconds", "attempts", "updated")


@dataclasses.dataclass
class Task:
    """One row of the manifest's ``tasks`` table (missing columns are None)."""

    task_id: str
    input: str | None = None
    name: str | None = None
    kind: str | None = None
    frames: list[int] | None = None
    method: str | None = None
    params: dict[str, Any] | None = None
    version: str | None = None
    output: str | None = None
    checksum: str | None = None
    status: str | None = None
    error: str | None = None
    seconds: float | None = None
    attempts: int | None = None
    updated: float | None = None


@dataclasses.dataclass
class Video:
    """The outputs of one input video (one sub-folder of the batch folder).

    Attributes
    ----------
    name : str
        Sub-folder name, relative to the batch folder (POSIX separators).
    kind : str
        ``"flow"`` or ``"track"``.
    files : list of Path
        Output files present on disk, in frame order.
    numbers : list of int
        Frame (flows) or window start (trajectories) number of each file.
    labels : list of str
        Caption of each file (``"frames 3→4"`` from the manifest, else ``"frame 3"``).
    tasks : list of Task
        Manifest rows of this video (empty without a manifest).
    pairs : list of (int, int) or None
        Per file, the frames ``(i, j)`` of its flow as the manifest records them
        (None when the manifest has no row or no frames for the file, and for
        trajectory windows).
    input : str or None
        The input (video file or frame folder) as the manifest records it; None
        without a manifest.
    """

    name: str
    kind: str
    files: list[Path] = dataclasses.field(default_factory=list)
    numbers: list[int] = dataclasses.field(default_factory=list)
    labels: list[str] = dataclasses.field(default_factory=list)
    tasks: list[Task] = dataclasses.field(default_factory=list)
    pairs: list[tuple[int, int] | None] = dataclasses.field(default_factory=list)
    input: str | None = None


@dataclasses.dataclass
class BatchFolder:
    """A scanned batch output folder."""

    root: Path
    manifest: Path | None
    manifest_error: str | None
    meta: dict[str, str]
    tasks: list[Task]
    videos: list[Video]


@dataclasses.dataclass
class BenchTable:
    """Rows of a benchmark CSV: strings for text cells, floats (or None) for numbers."""

    path: Path
    columns: list[str]
    rows: list[dict[str, Any]]


def detect_kind(path: str | os.PathLike[str]) -> str:
    """Classify a report input.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    str
        ``"batch"``, ``"bench"``, ``"flow"`` or ``"trajectories"``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file type is not one of the supported ones.
    """
    p = Path(os.fspath(path))
    if not p.exists():
        raise FileNotFoundError(2, "report input not found", str(p))
    if p.is_dir():
        return "batch"
    suffix = p.suffix.lower()
    kinds = {".csv": "bench", ".flo": "flow", ".png": "flow", ".npz": "trajectories"}
    if suffix not in kinds:
        raise ValueError(f"{p}: cannot report on a {suffix or 'extension-less'} file; give a "
                         f"batch output folder, a bench .csv, a .flo/.png flow or a "
                         f"trajectory .npz")
    return kinds[suffix]


def evenly_spaced(n: int, k: int) -> list[int]:
    """At most ``k`` indices of ``range(n)``, evenly spaced, first and last included.

    Parameters
    ----------
    n : int
        Number of items.
    k : int
        Largest number of indices, ``>= 1``.

    Returns
    -------
    list of int
        Increasing, without duplicates.
    """
    if n <= 0:
        return []
    if n <= k:
        return list(range(n))
    if k == 1:
        return [0]
    return sorted({int(round(i)) for i in np.linspace(0, n - 1, k)})


# --------------------------------------------------------------------------- batch folders


def _json_or_none(text: Any, what: str) -> Any:
    if text is None or text == "":
        return None
    if not isinstance(text, str):
        return text
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        logger.warning("manifest: %s is not JSON: %.60s", what, text)
        return None


def _task_from_row(row: dict[str, Any]) -> Task:
    values: dict[str, Any] = {c: row.get(c) for c in _TASK_COLUMNS}
    frames = _json_or_none(values["frames"], "frames")
    if isinstance(frames, list) and all(isinstance(f, int) for f in frames):
        values["frames"] = frames
    else:
        values["frames"] = None
    params = _json_or_none(values["params"], "params")
    values["params"] = params if isinstance(params, dict) else None
    for key in ("task_id", "input", "name", "kind", "method", "version", "output", "checksum",
                "status", "error"):
        if values[key] is not None:
            values[key] = str(values[key])
    for key in ("seconds", "updated"):
        try:
            values[key] = None if values[key] is None else float(values[key])
        except (TypeError, ValueError):
            values[key] = None
    try:
        values["attempts"] = None if values["attempts"] is None else int(values["attempts"])
    except (TypeError, ValueError):
        values["attempts"] = None
    values["task_id"] = values["task_id"] or ""
    return Task(**values)


def read_manifest(path: Path) -> tuple[dict[str, str], list[Task]]:
    """Read the ``meta`` and ``tasks`` tables of a batch manifest (read-only).

    Parameters
    ----------
    path : Path

    Returns
    -------
    meta : dict of str to str
        Empty if there is no ``meta`` table.
    tasks : list of Task

    Raises
    ------
    sqlite3.Error
        If the file is not an SQLite database or has no ``tasks`` table.
    """
    uri = path.resolve().as_uri() + "?mode=ro"
    con = sqlite3.connect(uri, uri=True, timeout=5.0)
    try:
        con.row_factory = sqlite3.Row
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if "tasks" not in tables:
            raise sqlite3.DatabaseError("no 'tasks' table")
        meta: dict[str, str] = {}
        if "meta" in tables:
            for r in con.execute("SELECT * FROM meta"):
                d = dict(r)
                if "key" in d:
                    meta[str(d["key"])] = "" if d.get("value") is None else str(d.get("value"))
        tasks = [_task_from_row(dict(r)) for r in con.execute("SELECT * FROM tasks")]
    finally:
        con.close()
    return meta, tasks


def _scan(root: Path) -> dict[str, dict[str, list[tuple[int, int | None, Path]]]]:
    """``{video name: {"flow": [(n, m, path)], "track": [(n, None, path)]}}`` from the
    file names (``m``: second frame of an explicit pair ``NNNNNN_MMMMMM.flo``)."""
    found: dict[str, dict[str, list[tuple[int, int | None, Path]]]] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        # hidden folders and Zarr stores hold no flow files
        dirnames[:] = sorted(d for d in dirnames
                             if not d.startswith(".") and not d.endswith(".zarr"))
        here = Path(dirpath)
        if here == root:
            continue  # outputs live in OUT/<name>/
        name = here.relative_to(root).as_posix()
        for fname in filenames:
            if fname.startswith("."):
                continue  # temporary files of atomic writes
            m = _FLOW_FILE.match(fname)
            kind = "flow"
            second = None
            if m is None:
                m = _WINDOW_FILE.match(fname)
                kind = "track"
            elif m.group(2) is not None:
                second = int(m.group(2))
            if m is None:
                continue
            found.setdefault(name, {}).setdefault(kind, []).append(
                (int(m.group(1)), second, here / fname))
    return found


def _frames_label(kind: str, number: int, second: int | None, task: Task | None) -> str:
    frames = task.frames if task is not None else None
    if kind == "flow":
        if frames and len(frames) >= 2:
            return f"frames {frames[0]}→{frames[1]}"
        return f"frame {number}" if second is None else f"frames {number}→{second}"
    if frames:
        return f"window {number}: frames {frames[0]}–{frames[-1]}"
    return f"window {number}"


def load_batch(root: str | os.PathLike[str]) -> BatchFolder:
    """Scan a batch output folder and read its manifest when there is one.

    Parameters
    ----------
    root : str or path-like
        The folder.

    Returns
    -------
    BatchFolder

    Raises
    ------
    ValueError
        If the folder holds neither outputs nor a readable manifest.
    """
    root = Path(os.fspath(root))
    manifest = root / MANIFEST_NAME
    meta: dict[str, str] = {}
    tasks: list[Task] = []
    error = None
    if manifest.is_file():
        try:
            meta, tasks = read_manifest(manifest)
        except sqlite3.Error as exc:
            error = f"{manifest.name}: cannot be read ({exc})"
            logger.warning("%s", error)
    else:
        manifest = None  # type: ignore[assignment]

    scanned = _scan(root)
    by_output: dict[Path, Task] = {}
    keys: set[tuple[str, str]] = set()  # (video name, kind)
    for t in tasks:
        if t.output:
            by_output[(root / t.output).resolve()] = t
        if t.name:
            keys.add((t.name, t.kind if t.kind in ("flow", "track") else "flow"))
    for name, kinds in scanned.items():
        keys.update((name, kind) for kind in kinds)

    videos = []
    for name, kind in sorted(keys):
        video = Video(name=name, kind=kind, tasks=[
            t for t in tasks
            if t.name == name and (t.kind if t.kind in ("flow", "track") else "flow") == kind])
        video.input = next((t.input for t in video.tasks if t.input), None)
        files: dict[Path, tuple[int, int]] = {}  # path -> (number, second frame or -1)
        for n, second, p in scanned.get(name, {}).get(kind, []):
            files[p.resolve()] = (n, -1 if second is None else second)
        for t in video.tasks:  # done outputs that do not follow the naming scheme
            if t.status == "done" and t.output:
                p = (root / t.output).resolve()
                if p.is_file() and p not in files:
                    files[p] = (t.frames[0] if t.frames else len(files), -1)
        for p, (n, second) in sorted(files.items(), key=lambda item: (item[1], str(item[0]))):
            video.files.append(p)
            video.numbers.append(n)
            task = by_output.get(p)
            video.pairs.append((task.frames[0], task.frames[1]) if kind == "flow" and task
                               is not None and task.frames and len(task.frames) >= 2 else None)
            video.labels.append(_frames_label(kind, n, None if second < 0 else second,
                                              by_output.get(p)))
        videos.append(video)
    if not videos and not tasks and error is None:
        raise ValueError(f"{root}: no flows (NAME/NNNNNN.flo|.png), trajectory windows "
                         f"(NAME/window_NNNNNN.npz) or {MANIFEST_NAME} found")
    logger.info("batch folder %s: %d videos, %d tasks", root, len(videos), len(tasks))
    return BatchFolder(root, manifest, error, meta, tasks, videos)


# --------------------------------------------------------------------------- bench CSV


def _cell(text: str) -> Any:
    text = text.strip()
    if text == "":
        return None
    try:
        return float(text)
    except ValueError:
        return text


def load_bench_csv(path: str | os.PathLike[str]) -> BenchTable:
    """Read a CSV written by ``varflow bench ... --csv``.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    BenchTable
        Empty cells become None, numeric cells float (``nan`` included), others str.

    Raises
    ------
    ValueError
        If the file is not a CSV with a ``method`` column, a metric column
        (``aee`` or ``epe``) and at least one row.
    """
    path = Path(os.fspath(path))
    try:
        with open(path, encoding="utf-8", newline="") as f:
            reader = csv.DictReader(f)
            columns = list(reader.fieldnames or [])
            raw = list(reader)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise ValueError(f"{path}: not a readable CSV file ({exc})") from exc
    if "method" not in columns:
        raise ValueError(f"{path}: not a varflow bench CSV (no 'method' column; found "
                         f"{', '.join(columns[:8]) or 'none'})")
    rows = [{c: _cell(r.get(c) or "") for c in columns} for r in raw]
    if not rows:
        raise ValueError(f"{path}: the bench CSV has no rows")
    if not any(isinstance(r.get(m), float) for r in rows for m in ("aee", "epe")):
        raise ValueError(f"{path}: the bench CSV has no 'aee' or 'epe' values")
    return BenchTable(path, columns, rows)


def finite(values: Sequence[Any]) -> list[float]:
    """The finite floats among ``values``."""
    return [v for v in values if isinstance(v, float) and math.isfinite(v)]
