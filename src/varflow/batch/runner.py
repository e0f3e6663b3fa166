"""The driver of a batch run: plan, resume, submit to Dask, record.

Resume rules (every run, in this order)
---------------------------------------
1. **Settings.**  The run's settings (kind, method, parameters, varflow version,
   output format, stride/pairs or window/overlap; not the worker set-up nor
   ``--zarr``) are hashed and kept in the manifest's ``meta`` table, with the
   fingerprint of what decides the numbers (method, all its resolved parameters,
   varflow version: :meth:`~varflow.batch.plan.BatchConfig.fingerprint`).  A run
   into an output folder whose manifest records other settings -- after an upgrade
   of varflow too, since the version is bumped whenever default results change --
   stops with an error naming the difference before any work, unless
   ``overwrite``: then every output and Zarr store the manifest lists is deleted
   and the manifest is emptied first.
2. **Inputs.**  An input name whose recorded path or fingerprint (sizes and
   modification times of its files) differs from the current one while it has done
   tasks is an error too (same remedy).
3. **Stale files.**  Temporary files of killed writers (``OUT/<name>/.*.tmp`` from
   the atomic writers, ``*.partial`` chunks in Zarr stores) are deleted.
4. **Per task**, from its manifest row and its output file:

   * ``done`` with the output present and its SHA-256 equal to the recorded
     checksum: skipped;
   * ``running`` (submitted by a run that was killed before recording the
     result) with the output present and written no earlier than 2 s before the
     submission was committed: *adopted* -- its checksum is recorded and it is
     counted as skipped.  This is sound because the manifest row (and the
     settings hash in ``meta``) was committed before the task was submitted, only
     tasks of these settings write this path, and outputs appear only by atomic
     rename of a complete file;
   * anything else (pending, failed, running without output, done with a missing
     or different output): the output, if any, is deleted and the task runs again.

   ``attempts`` counts the submissions of a task, so a resumed run that skips done
   work leaves their ``attempts`` unchanged.

A task's output appears by atomic rename; the driver records it (after copying it
into the Zarr store with ``--zarr``) and commits.  Killing the driver (SIGKILL)
also ends the workers of its :class:`~distributed.LocalCluster` (they exit when
their parent process goes away).  Tasks still running on an *external* cluster
finish on their own; since outputs are deterministic and renamed atomically, a
late rename cannot corrupt an output.
"""

from __future__ import annotations

import contextlib
import fcntl
import glob
import logging
import os
import shutil
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any

from .._errors import error_line
from .inputs import BatchInput, InputProbe, probe_input
from .manifest import INPUT_TASK, MANIFEST_NAME, Manifest
from .plan import VIDEO_KINDS, BatchConfig, Task, plan_tasks
from .worker import PinThreads, WorkItem, run_item, sha256_file, thread_environment

__all__ = ["BatchSummary", "run_batch"]

log = logging.getLogger(__name__)

#: A ``running`` task's output may be adopted if written at most this long before the
#: submission was recorded (file-system timestamp granularity).
ADOPT_SLACK = 2.0

ProgressCallback = Callable[[int, int], None]


@dataclass
class BatchSummary:
    """Outcome of :func:`run_batch`.

    Attributes
    ----------
    total : int
        Tasks of the given inputs (plus one per input that failed as a whole).
    done : int
        Tasks computed successfully by this run.
    skipped : int
        Tasks already done before (including ``adopted``).
    adopted : int
        Outputs of a killed run recorded by this one without recomputing.
    failed : int
        Failed tasks and inputs.
    seconds : float
        Wall time of the computing phase.
    unit : str
        ``"pairs"``, ``"windows"`` or ``"videos"`` (retime, denoise, restore).
    failures : list of (str, str)
        ``(task_id, error)`` of every failure.
    """

    total: int = 0
    done: int = 0
    skipped: int = 0
    adopted: int = 0
    failed: int = 0
    seconds: float = 0.0
    unit: str = "pairs"
    failures: list[tuple[str, str]] = field(default_factory=list)

    @property
    def throughput(self) -> float:
        """Computed tasks per second (0 when nothing was computed)."""
        return self.done / self.seconds if self.done and self.seconds > 0 else 0.0

    @property
    def ok(self) -> bool:
        """True when nothing failed."""
        return self.failed == 0


@contextlib.contextmanager
def _locked(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on the output folder (released when the process dies)."""
    fd = os.open(out / "manifest.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ValueError(f"{out}: another varflow batch run is writing this folder") from None
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def _environ(values: dict[str, str]) -> Iterator[None]:
    """Set environment variables for the block (worker processes inherit them)."""
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _inside(out: Path, rel: str) -> Path | None:
    """``out / rel`` if it stays inside ``out`` (manifest entries are not trusted blindly)."""
    p = (out / rel).resolve()
    root = out.resolve()
    return p if p != root and root in p.parents else None


def _discard(out: Path, entries: list[str]) -> None:
    """Delete outputs and Zarr stores listed by an old manifest (``--overwrite``)."""
    for rel in entries:
        p = _inside(out, rel)
        if p is None:
            continue
        if p.is_dir() and p.suffix == ".zarr":
            shutil.rmtree(p, ignore_errors=True)
        elif p.is_file():
            p.unlink()
    for d in sorted({(out / rel).parent for rel in entries}, reverse=True):
        with contextlib.suppress(OSError):
            if d != out and d.is_dir() and not any(d.iterdir()):
                d.rmdir()


def _clean_stale(out: Path, names: Sequence[str], kind: str = "flow") -> int:
    """Delete temporary files of killed writers; returns how many."""
    count = 0
    for name in names:
        if kind in VIDEO_KINDS:  # OUT/.<name>.XXXX.<ext> of the video writer
            for p in out.glob(f".{glob.escape(name)}.*"):
                if p.is_file():
                    p.unlink(missing_ok=True)
                    count += 1
        d = out / name
        if d.is_dir():
            for p in d.iterdir():
                if p.name.startswith(".") and p.name.endswith(".tmp") and p.is_file():
                    p.unlink(missing_ok=True)
                    count += 1
        z = out / f"{name}.zarr"
        if z.is_dir():
            for p in z.rglob("*.partial"):
                p.unlink(missing_ok=True)
                count += 1
    if count:
        log.info("removed %d stale temporary file(s)", count)
    return count


@dataclass
class _Planned:
    inp: BatchInput
    probe: InputProbe
    tasks: list[Task]


def _plan(inputs: Sequence[BatchInput], config: BatchConfig, manifest: Manifest, out: Path,
          version: str, summary: BatchSummary, overwrite: bool) -> list[_Planned]:
    planned: list[_Planned] = []
    params = config.params_json
    for inp in inputs:
        try:
            probe = probe_input(inp)
            tasks = plan_tasks(inp.name, probe.n_frames, config)
        except Exception as exc:  # noqa: BLE001 - any unreadable input is recorded, not fatal
            error = error_line(exc)
            log.warning("input %s failed: %s", inp.path, error)
            manifest.fail_input(inp.name, str(inp.path), inp.kind, config.kind, config.method,
                                params, version, error)
            summary.total += 1
            summary.failed += 1
            summary.failures.append((f"{inp.name}/{INPUT_TASK}", error))
            continue
        old = manifest.input_row(inp.name)
        if (
            not overwrite
            and old is not None
            and old["status"] == "ok"
            and (old["input"] != str(inp.path) or old["fingerprint"] != probe.fingerprint)
            and manifest.done_count(inp.name) > 0
        ):
            what = ("was made from " + old["input"]) if old["input"] != str(inp.path) else (
                f"was made from an earlier version of {inp.path}")
            raise ValueError(
                f"{out / inp.name} {what}; use another -o folder or --overwrite"
            )
        manifest.set_input(inp.name, str(inp.path), inp.kind, probe.n_frames,
                           probe.fingerprint, "ok", None)
        manifest.prune(inp.name, (t.task_id for t in tasks))  # e.g. a frame count changed
        manifest.add_tasks(tasks, str(inp.path), config.kind, config.method, params, version)
        planned.append(_Planned(inp, probe, tasks))
    return planned


def _triage(planned: list[_Planned], manifest: Manifest, out: Path, summary: BatchSummary,
            sink: Any) -> list[tuple[_Planned, Task]]:
    """Apply the per-task resume rules; returns the tasks to compute."""
    to_run: list[tuple[_Planned, Task]] = []
    for pl in planned:
        rows = manifest.rows([t.task_id for t in pl.tasks])
        for task in pl.tasks:
            summary.total += 1
            if task.problem is not None:
                manifest.finish(task.task_id, "failed", error=task.problem)
                summary.failed += 1
                summary.failures.append((task.task_id, task.problem))
                continue
            row = rows[task.task_id]
            path = out / task.output
            status = row["status"]
            if status == "done" and path.is_file() and sha256_file(path) == row["checksum"]:
                if sink is not None and sink.needs(task) and not _sink_write(
                    sink, task, manifest, summary
                ):
                    continue
                summary.skipped += 1
                continue
            if (
                status == "running"
                and path.is_file()
                and path.stat().st_mtime >= (row["updated"] or 0.0) - ADOPT_SLACK
            ):
                log.info("adopting %s (finished before the previous run was killed)", task.output)
                if sink is not None and not _sink_write(sink, task, manifest, summary):
                    continue
                manifest.adopt(task.task_id, sha256_file(path))
                summary.skipped += 1
                summary.adopted += 1
                continue
            if status == "done":
                log.warning("%s is missing or differs from the manifest; computing it again",
                            task.output)
            if path.exists():
                path.unlink()
            if status in ("done", "running"):
                manifest.reset_task(task.task_id)
            to_run.append((pl, task))
    return to_run


def _sink_write(sink: Any, task: Task, manifest: Manifest, summary: BatchSummary) -> bool:
    """Copy an output into its Zarr store; a failure fails the task.  True on success."""
    try:
        sink.write(task)
    except (ValueError, OSError) as exc:
        error = f"zarr: {error_line(exc)}"
        manifest.finish(task.task_id, "failed", error=error)
        summary.failed += 1
        summary.failures.append((task.task_id, error))
        return False
    return True


def _work_item(pl: _Planned, task: Task, config: BatchConfig, out: Path,
               version: str) -> WorkItem:
    source: str | tuple[str, ...]
    if pl.probe.files is not None and config.kind not in VIDEO_KINDS:
        source = tuple(pl.probe.files[i] for i in task.frames)
    else:
        source = str(pl.inp.path)
    return WorkItem(
        task_id=task.task_id,
        kind=config.kind,
        method=config.method,
        params=config.params,
        source=source,
        frames=task.frames,
        output=str(out / task.output),
        fmt=config.fmt,
        metadata={"input": str(pl.inp.path), "name": pl.inp.name, "version": version},
        retime=None if config.kind != "retime" else {
            "fps": config.fps, "slowmo": config.slowmo, "input_fps": config.input_fps,
            "codec": config.codec},
        denoise=None if config.kind not in ("denoise", "restore") else {
            "sigma": config.sigma, "input_fps": config.input_fps, "codec": config.codec,
            "scene_cuts": config.scene_cuts},
    )


@contextlib.contextmanager
def _client(workers: int | None, threads: int, scheduler: str | None) -> Iterator[Any]:
    """A Dask client on a new LocalCluster or on an existing scheduler."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        client = Client(scheduler, timeout="30s", set_as_default=False)
        try:
            client.register_plugin(PinThreads(1))
            yield client
        finally:
            client.close()
        return
    n = workers if workers is not None else (os.cpu_count() or 1)
    env = thread_environment(threads)
    with _environ(env):  # inherited by the worker processes at spawn
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=threads,
            processes=True,
            dashboard_address=None,  # no dashboard; its plain HTTP server on a free port:
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
            silence_logs=logging.ERROR,
            env=env,
        )
    try:
        client = Client(cluster, set_as_default=False)
        try:
            client.register_plugin(PinThreads(threads))
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def _compute(to_run: list[tuple[_Planned, Task]], config: BatchConfig, out: Path, version: str,
             manifest: Manifest, summary: BatchSummary, sink: Any,
             progress: ProgressCallback | None, workers: int | None, threads: int,
             scheduler: str | None, max_in_flight: int | None) -> None:
    from distributed import as_completed

    total = summary.total
    finished = summary.total - len(to_run)

    def report() -> None:
        if progress is not None:
            progress(finished, total)

    report()
    with _client(workers, threads, scheduler) as client:
        slots = sum(client.nthreads().values()) or 1
        window = max_in_flight or max(2, 2 * slots)
        log.info("computing %d task(s) on %d worker thread(s), at most %d in flight",
                 len(to_run), slots, window)
        token = uuid.uuid4().hex[:12]
        pending = iter(to_run)
        in_flight: dict[str, Task] = {}

        def submit(k: int) -> list[Any]:
            batch = list(islice(pending, k))
            if not batch:
                return []
            manifest.mark_running([task.task_id for _, task in batch])
            futures = []
            for pl, task in batch:
                key = f"varflow-batch-{token}-{task.task_id}"
                fut = client.submit(run_item, _work_item(pl, task, config, out, version),
                                    key=key, pure=False, retries=0)
                in_flight[fut.key] = task
                futures.append(fut)
            return futures

        ac = as_completed(submit(window), loop=client.loop)
        for fut in ac:
            task = in_flight.pop(fut.key)
            try:
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - worker died, cancelled, ...
                result = {"task_id": task.task_id, "error": f"{type(exc).__name__}: "
                          f"{error_line(exc)}"}
            fut.release()
            error = result.get("error")
            if error is None:
                if sink is None or _sink_write(sink, task, manifest, summary):
                    manifest.finish(task.task_id, "done", checksum=result["checksum"],
                                    seconds=result["seconds"])
                    summary.done += 1
            else:
                log.warning("%s failed: %s", task.task_id, error)
                manifest.finish(task.task_id, "failed", error=error,
                                seconds=result.get("seconds"))
                summary.failed += 1
                summary.failures.append((task.task_id, error))
            finished += 1
            report()
            for new in submit(1):
                ac.add(new)


def run_batch(
    inputs: Sequence[BatchInput],
    out: str | os.PathLike[str],
    config: BatchConfig,
    *,
    workers: int | None = None,
    threads: int = 1,
    scheduler: str | None = None,
    overwrite: bool = False,
    zarr: bool = False,
    progress: ProgressCallback | None = None,
    command: Any = None,
    max_in_flight: int | None = None,
) -> BatchSummary:
    """Run (or resume) a batch of flow, trajectory, retime, denoise or restore tasks.

    Parameters
    ----------
    inputs : sequence of BatchInput
        From :func:`varflow.batch.inputs.expand_inputs`.
    out : str or path-like
        Output folder (created if needed).
    config : BatchConfig
        What to compute.
    workers : int, optional
        Worker processes of the local cluster (default: the number of cores).
    threads : int
        Threads per worker process (tasks run at once per worker); every task is
        single-threaded and the worker's Numba/BLAS/OpenCV pools are limited to this.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:port``) instead of a
        local cluster.
    overwrite : bool
        Discard the results a previous run left in ``out`` (see the resume rules).
    zarr : bool
        Also copy the results into ``OUT/<name>.zarr``.
    progress : callable, optional
        ``progress(finished, total)`` as tasks finish.
    command : JSON-serialisable, optional
        The command (e.g. its parsed options), stored in the manifest.
    max_in_flight : int, optional
        Tasks submitted at once (default: twice the cluster's threads).

    Returns
    -------
    BatchSummary

    Raises
    ------
    ValueError
        Settings that differ from those of an earlier run into ``out``, a changed
        input, or ``out`` in use by another run.
    """
    from .._version import __version__ as version

    out = Path(os.fspath(out))
    out.mkdir(parents=True, exist_ok=True)
    summary = BatchSummary(unit={"flow": "pairs", "track": "windows"}.get(config.kind,
                                                                          "videos"))
    identity = config.identity(version)
    params_hash = config.identity_hash(version)
    fingerprint = config.fingerprint(version)
    with _locked(out), Manifest(out / MANIFEST_NAME) as manifest:
        diff = manifest.check_settings(identity, params_hash, fingerprint)
        if diff is not None and not overwrite:
            raise ValueError(
                f"{out} holds results made with other settings ({diff}); use another -o "
                "folder or --overwrite (discards them)"
            )
        if overwrite:  # files first: a run killed in between can still --overwrite
            _discard(out, manifest.listed())
            manifest.reset()
        manifest.record_settings(identity, params_hash, command, fingerprint)
        planned = _plan(inputs, config, manifest, out, version, summary, overwrite)
        _clean_stale(out, [pl.inp.name for pl in planned], config.kind)
        sink = None
        if zarr:
            from .zarrsink import ZarrSink

            sink = ZarrSink(out, config, {"kind": config.kind, "method": config.method,
                                          "params": identity["params"], "version": version})
            for pl in planned:
                sink.register(pl.inp.name, str(pl.inp.path), pl.tasks)
        to_run = _triage(planned, manifest, out, summary, sink)
        log.info("%d task(s): %d to compute, %d already done, %d failed", summary.total,
                 len(to_run), summary.skipped, summary.failed)
        t0 = time.perf_counter()
        if to_run:
            _compute(to_run, config, out, version, manifest, summary, sink, progress, workers,
                     threads, scheduler, max_in_flight)
        elif progress is not None:
            progress(summary.total, summary.total)
        summary.seconds = time.perf_counter() - t0
        manifest.set_meta({"updated": repr(time.time())})
    return summary
