"""The SQLite manifest of a batch run (``OUT/manifest.sqlite``).

Only the driver process writes it.  It uses write-ahead logging and commits after
every state change of a task, so that killing the driver at any moment leaves a
consistent database (readers, e.g. the HTML report, may open it while a run goes
on).

Tables
------
``tasks``
    One row per task: ``task_id`` (``"<name>/<output file name>"``), ``input``
    (path), ``name``, ``kind`` (``flow``/``track``/``retime``/``denoise``/``restore``), ``frames``
    (JSON list of frame indices), ``method``, ``params`` (JSON of the parameter
    dataclass), ``version`` (varflow's), ``output`` (path relative to OUT),
    ``checksum`` (SHA-256 hex of the output once done), ``status``, ``error``,
    ``seconds`` (compute time), ``attempts`` (times submitted to a worker),
    ``updated`` (Unix time).

    ``status`` is ``pending`` (planned), ``running`` (submitted, result not yet
    recorded), ``done`` or ``failed``.  An input that could not be opened at all
    gets one row ``"<name>/input"`` with status ``failed``, empty ``frames`` and no
    ``output``.
``inputs``
    One row per input name: path, kind, frame count, fingerprint (size and
    modification times), status (``ok``/``failed``) and error.
``meta``
    ``key``/``value`` pairs: the run settings (``kind``, ``method``, ``params``,
    ``version``, ``format``, ``stride``/``pairs`` or ``window``/``overlap``), their
    hash ``params_hash``, the ``fingerprint`` of what decides the numbers (SHA-256 of
    the method, all its resolved parameters and the varflow version), the last
    ``command`` line, ``created`` and ``updated``.
"""

from __future__ import annotations

import json
import sqlite3
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from .plan import Task

__all__ = ["INPUT_TASK", "Manifest", "MANIFEST_NAME"]

#: File name of the manifest inside the output folder.
MANIFEST_NAME = "manifest.sqlite"
#: Output-file part of the task id of an input that failed as a whole.
INPUT_TASK = "input"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS tasks (
    task_id TEXT PRIMARY KEY,
    input TEXT,
    name TEXT,
    kind TEXT,
    frames TEXT,
    method TEXT,
    params TEXT,
    version TEXT,
    output TEXT,
    checksum TEXT,
    status TEXT,
    error TEXT,
    seconds REAL,
    attempts INTEGER,
    updated REAL
);
CREATE INDEX IF NOT EXISTS tasks_name ON tasks(name);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT);
CREATE TABLE IF NOT EXISTS inputs (
    name TEXT PRIMARY KEY,
    input TEXT,
    kind TEXT,
    n_frames INTEGER,
    fingerprint TEXT,
    status TEXT,
    error TEXT,
    updated REAL
);
"""


class Manifest:
    """Read and update a batch manifest.

    Parameters
    ----------
    path : Path
        The SQLite file (created if missing).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.conn = sqlite3.connect(str(path), timeout=30.0, isolation_level=None)
        self.conn.row_factory = sqlite3.Row
        self.conn.execute("PRAGMA journal_mode=WAL")
        # NORMAL in WAL mode: a committed transaction survives a killed process; an OS
        # crash may lose the last commits, which the resume rules tolerate.
        self.conn.execute("PRAGMA synchronous=NORMAL")
        self.conn.executescript(_SCHEMA)

    # ------------------------------------------------------------------ basics

    def _tx(self) -> _Transaction:
        return _Transaction(self.conn)

    def close(self) -> None:
        """Checkpoint and close the database."""
        try:
            self.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        except sqlite3.Error:
            pass
        self.conn.close()

    def __enter__(self) -> Manifest:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ meta

    def meta(self) -> dict[str, str]:
        """All ``meta`` entries."""
        return {r["key"]: r["value"] for r in self.conn.execute("SELECT key, value FROM meta")}

    def set_meta(self, values: dict[str, Any]) -> None:
        """Insert or replace ``meta`` entries (non-strings stored as JSON)."""
        with self._tx():
            self.conn.executemany(
                "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)",
                [(k, v if isinstance(v, str) else json.dumps(v, sort_keys=True))
                 for k, v in values.items()],
            )

    def check_settings(self, identity: dict[str, Any], params_hash: str,
                       fingerprint: str | None = None) -> str | None:
        """Compare the run settings with those recorded.

        Parameters
        ----------
        identity : dict
            :meth:`varflow.batch.plan.BatchConfig.identity` of this run.
        params_hash : str
            Its hash (:meth:`~varflow.batch.plan.BatchConfig.identity_hash`).
        fingerprint : str, optional
            :meth:`~varflow.batch.plan.BatchConfig.fingerprint` of this run (method,
            resolved parameters, varflow version), compared when one is recorded.

        Returns
        -------
        str or None
            None when the manifest is new or was written with the same settings,
            else a short description of the differences (e.g. ``varflow version
            1.2 -> 1.3``, ``params: n_warps 3 -> 2``).
        """
        meta = self.meta()
        old_hash = meta.get("params_hash")
        old_fingerprint = meta.get("fingerprint")
        same_fingerprint = (fingerprint is None or old_fingerprint is None
                            or old_fingerprint == fingerprint)
        if old_hash is None or (old_hash == params_hash and same_fingerprint):
            return None
        diffs = []
        for key, value in identity.items():
            new = value if isinstance(value, str) else json.dumps(value, sort_keys=True)
            old = meta.get(key)
            if old != new:
                if key == "version":
                    diffs.append(f"varflow version {old} -> {new}")
                elif key == "params" and old is not None:
                    a, b = json.loads(old), value
                    keys = sorted(set(a) | set(b))
                    changed = [f"{k} {a.get(k)} -> {b.get(k)}" for k in keys
                               if a.get(k) != b.get(k)]
                    diffs.append("params: " + ", ".join(changed[:4])
                                 + (", ..." if len(changed) > 4 else ""))
                else:
                    diffs.append(f"{key}: {old} -> {new}")
        return "; ".join(diffs) or "settings differ"

    def record_settings(self, identity: dict[str, Any], params_hash: str,
                        command: Any, fingerprint: str | None = None) -> None:
        """Store the run settings, their hash, the fingerprint and the command."""
        now = time.time()
        values: dict[str, Any] = dict(identity)
        values["params_hash"] = params_hash
        if fingerprint is not None:
            values["fingerprint"] = fingerprint
        values["command"] = json.dumps(command, sort_keys=True, default=str)
        values["updated"] = repr(now)
        if "created" not in self.meta():
            values["created"] = repr(now)
        self.set_meta(values)

    def listed(self) -> list[str]:
        """Every output and Zarr store (relative paths) the manifest knows of."""
        outputs = [r[0] for r in self.conn.execute(
            "SELECT output FROM tasks WHERE output IS NOT NULL")]
        names = [r[0] for r in self.conn.execute(
            "SELECT name FROM inputs UNION SELECT name FROM tasks")]
        return outputs + [f"{n}.zarr" for n in names if n]

    def reset(self) -> None:
        """Forget every task, input and setting (commits)."""
        with self._tx():
            self.conn.execute("DELETE FROM tasks")
            self.conn.execute("DELETE FROM inputs")
            self.conn.execute("DELETE FROM meta")

    # ------------------------------------------------------------------ inputs

    def input_row(self, name: str) -> sqlite3.Row | None:
        """The ``inputs`` row of a name."""
        return self.conn.execute("SELECT * FROM inputs WHERE name = ?", (name,)).fetchone()

    def done_count(self, name: str) -> int:
        """Number of done tasks of an input name."""
        row = self.conn.execute(
            "SELECT COUNT(*) FROM tasks WHERE name = ? AND status = 'done'", (name,)).fetchone()
        return int(row[0])

    def set_input(self, name: str, path: str, kind: str, n_frames: int | None,
                  fingerprint: str | None, status: str, error: str | None) -> None:
        """Insert or replace an ``inputs`` row (commits)."""
        with self._tx():
            self.conn.execute(
                "INSERT OR REPLACE INTO inputs VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (name, path, kind, n_frames, fingerprint, status, error, time.time()),
            )
            self.conn.execute("UPDATE tasks SET input = ? WHERE name = ?", (path, name))

    def fail_input(self, name: str, path: str, input_kind: str, kind: str, method: str,
                   params: str, version: str, error: str) -> None:
        """Record an input that cannot be opened (row ``"<name>/input"``, commits)."""
        now = time.time()
        with self._tx():
            self.conn.execute(
                "INSERT OR REPLACE INTO inputs VALUES (?, ?, ?, NULL, NULL, 'failed', ?, ?)",
                (name, path, input_kind, error, now),
            )
            self.conn.execute(
                "INSERT OR REPLACE INTO tasks VALUES (?, ?, ?, ?, '[]', ?, ?, ?, NULL, NULL, "
                "'failed', ?, NULL, 0, ?)",
                (f"{name}/{INPUT_TASK}", path, name, kind, method, params, version, error, now),
            )

    def prune(self, name: str, keep: Iterable[str]) -> int:
        """Delete the task rows of an input that are not in ``keep`` (commits).

        Removes the ``"<name>/input"`` failure row of an input that now opens, and
        the rows of pairs or windows an input no longer has.

        Returns
        -------
        int
            Rows deleted.
        """
        keep_set = set(keep)
        stale = [r[0] for r in self.conn.execute("SELECT task_id FROM tasks WHERE name = ?",
                                                 (name,)) if r[0] not in keep_set]
        if stale:
            with self._tx():
                self.conn.executemany("DELETE FROM tasks WHERE task_id = ?",
                                      [(t,) for t in stale])
        return len(stale)

    # ------------------------------------------------------------------ tasks

    def add_tasks(self, tasks: Iterable[Task], path: str, kind: str, method: str, params: str,
                  version: str) -> None:
        """Insert planned tasks as ``pending`` (existing rows are kept; commits)."""
        now = time.time()
        with self._tx():
            self.conn.executemany(
                "INSERT OR IGNORE INTO tasks VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, NULL, "
                "'pending', NULL, NULL, 0, ?)",
                [(t.task_id, path, t.name, kind, json.dumps(list(t.frames)), method, params,
                  version, t.output, now) for t in tasks],
            )

    def rows(self, task_ids: Sequence[str]) -> dict[str, sqlite3.Row]:
        """The rows of the given tasks."""
        out: dict[str, sqlite3.Row] = {}
        for k in range(0, len(task_ids), 500):
            chunk = list(task_ids[k:k + 500])
            marks = ",".join("?" * len(chunk))
            for r in self.conn.execute(f"SELECT * FROM tasks WHERE task_id IN ({marks})", chunk):
                out[r["task_id"]] = r
        return out

    def mark_running(self, task_ids: Sequence[str]) -> float:
        """Mark tasks as submitted: status ``running``, one more attempt (commits).

        Returns
        -------
        float
            The time recorded in ``updated``.
        """
        now = time.time()
        with self._tx():
            self.conn.executemany(
                "UPDATE tasks SET status = 'running', attempts = attempts + 1, error = NULL, "
                "checksum = NULL, updated = ? WHERE task_id = ?",
                [(now, t) for t in task_ids],
            )
        return now

    def finish(self, task_id: str, status: str, *, checksum: str | None = None,
               error: str | None = None, seconds: float | None = None) -> None:
        """Record the outcome of a task (commits)."""
        with self._tx():
            self.conn.execute(
                "UPDATE tasks SET status = ?, checksum = ?, error = ?, seconds = ?, updated = ? "
                "WHERE task_id = ?",
                (status, checksum, error, seconds, time.time(), task_id),
            )

    def adopt(self, task_id: str, checksum: str) -> None:
        """Mark a ``running`` task done from its existing output (commits)."""
        with self._tx():
            self.conn.execute(
                "UPDATE tasks SET status = 'done', checksum = ?, error = NULL, updated = ? "
                "WHERE task_id = ?",
                (checksum, time.time(), task_id),
            )

    def reset_task(self, task_id: str, status: str = "pending") -> None:
        """Forget the result of a task whose output is gone or damaged (commits)."""
        with self._tx():
            self.conn.execute(
                "UPDATE tasks SET status = ?, checksum = NULL, updated = ? WHERE task_id = ?",
                (status, time.time(), task_id),
            )


class _Transaction:
    """``with`` block around ``BEGIN IMMEDIATE`` ... ``COMMIT`` (rollback on error)."""

    def __init__(self, conn: sqlite3.Connection) -> None:
        self.conn = conn

    def __enter__(self) -> sqlite3.Connection:
        self.conn.execute("BEGIN IMMEDIATE")
        return self.conn

    def __exit__(self, exc_type: object, *rest: object) -> None:
        if exc_type is None:
            self.conn.execute("COMMIT")
        else:
            self.conn.execute("ROLLBACK")
