"""What runs on the Dask workers: one task = read its frames, compute, write, hash.

A task reads only the frames it needs (a video is opened with
``read_frames(path, start=..., stop=..., step=...)``, a frame folder by the task's
own frame files; a retime task streams its whole input through
:func:`varflow.retime.stream.retime_video`, a denoise task through
:func:`varflow.restore.video.denoise_video`, a restore task through
:func:`varflow.restore.video.restore_video`), writes its output with the atomic
writers of :mod:`varflow.io` and returns a small result dictionary; it never touches the manifest.

Threads: every task runs single-threaded (Numba, OpenCV); a worker runs as many
tasks at once as it has threads.  :func:`thread_environment` gives the variables
that limit the native thread pools of a worker process (set before the process
starts), :class:`PinThreads` applies the same limits to the workers of an existing
cluster.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from .._errors import error_line

__all__ = ["PinThreads", "WorkItem", "run_item", "sha256_file", "thread_environment"]

log = logging.getLogger(__name__)

_THREAD_VARS = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                "MKL_NUM_THREADS", "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
                "NUMEXPR_NUM_THREADS", "OPENCV_FOR_THREADS_NUM")


def thread_environment(threads: int) -> dict[str, str]:
    """Environment variables that size the native thread pools to ``threads``."""
    return {name: str(max(1, int(threads))) for name in _THREAD_VARS}


def _pin_task_threads(threads: int = 1) -> None:
    """Run this task's Numba and OpenCV code on ``threads`` threads."""
    try:
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    except (ImportError, ValueError):  # pragma: no cover
        pass
    cv2 = sys.modules.get("cv2")
    if cv2 is not None:
        cv2.setNumThreads(threads)


class PinThreads(WorkerPlugin):
    """Limit the native thread pools of the workers of an existing cluster.

    Sets the :func:`thread_environment` variables (they reach libraries loaded
    later and subprocesses), OpenCV's thread count and, when ``threadpoolctl`` is
    installed, the BLAS/OpenMP pools already loaded.  Numba's thread count is
    thread-local and is set by every task (:func:`run_item`).

    Parameters
    ----------
    threads : int
        Threads per native pool.
    """

    name = "varflow-pin-threads"

    def __init__(self, threads: int = 1) -> None:
        self.threads = max(1, int(threads))

    def setup(self, worker: Any) -> None:  # noqa: D102 - WorkerPlugin API
        os.environ.update(thread_environment(self.threads))
        try:
            import cv2

            cv2.setNumThreads(self.threads)
        except ImportError:  # pragma: no cover
            pass
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:
            return
        threadpool_limits(self.threads)  # pragma: no cover


@dataclass(frozen=True)
class WorkItem:
    """Everything a worker needs for one task (picklable).

    Attributes
    ----------
    task_id : str
    kind : str
        ``"flow"``, ``"track"``, ``"retime"``, ``"denoise"`` or ``"restore"``.
    method : str
    params : dataclass instance
    source : str or tuple of str
        The video path, or the frame files of ``frames`` (a frame folder).
    frames : tuple of int
        ``(i, j)`` for flow from frame i to frame j; the window's frames for track.
    output : str
        Absolute output path.
    fmt : str
        ``"flo"``, ``"png"`` or ``"npz"``.
    metadata : dict
        Extra metadata stored in ``.npz`` outputs (input path, name, version).
    threads : int
        Threads per task for Numba/OpenCV.
    retime : dict, optional
        ``fps``, ``slowmo``, ``input_fps``, ``codec`` of a retime task (``source``
        is then the video or the frame folder).
    denoise : dict, optional
        ``sigma``, ``input_fps``, ``codec``, ``scene_cuts`` of a denoise or restore task
        (``source`` is then the video or the frame folder).
    """

    task_id: str
    kind: str
    method: str
    params: Any
    source: str | tuple[str, ...]
    frames: tuple[int, ...]
    output: str
    fmt: str
    metadata: dict[str, Any] = field(default_factory=dict)
    threads: int = 1
    retime: dict[str, Any] | None = None
    denoise: dict[str, Any] | None = None


def sha256_file(path: str | os.PathLike[str]) -> str:
    """SHA-256 hex digest of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _read(item: WorkItem) -> Any:
    """The task's frames, in the order of ``item.frames``."""
    from varflow.io.sequences import read_frames

    if isinstance(item.source, tuple):  # frame folder: exactly the task's files
        frames = read_frames(list(item.source))
        expected = len(item.frames)
    elif item.kind == "flow":
        i, j = item.frames
        lo, hi = min(i, j), max(i, j)
        frames = read_frames(item.source, start=lo, stop=hi + 1, step=hi - lo)
        expected = 2
        if len(frames) == 2 and i > j:
            frames = frames[::-1]
    else:
        frames = read_frames(item.source, start=item.frames[0], stop=item.frames[-1] + 1)
        expected = len(item.frames)
    if len(frames) != expected:
        raise ValueError(
            f"{item.source}: decoded {len(frames)} of the {expected} frames "
            f"{item.frames[0]}..{item.frames[-1]} (truncated video?)"
        )
    return frames


def _compute(item: WorkItem) -> None:
    import varflow

    out = Path(item.output)
    if item.kind == "retime":
        from varflow.retime.stream import retime_video

        assert item.retime is not None and isinstance(item.source, str)
        out.parent.mkdir(parents=True, exist_ok=True)
        retime_video(item.source, out, method=item.method, params=item.params, **item.retime)
        return
    if item.kind == "denoise":
        from ..restore.video import denoise_video

        assert item.denoise is not None and isinstance(item.source, str)
        out.parent.mkdir(parents=True, exist_ok=True)
        denoise_video(item.source, out, method=item.method, params=item.params, **item.denoise)
        return
    if item.kind == "restore":
        from ..restore.video import restore_video

        assert item.denoise is not None and isinstance(item.source, str)
        out.parent.mkdir(parents=True, exist_ok=True)
        restore_video(item.source, out, **item.params.as_kwargs(), **item.denoise)
        return
    frames = _read(item)
    out.parent.mkdir(parents=True, exist_ok=True)
    if item.kind == "flow":
        flow = varflow.flow(frames[0], frames[1], item.method, params=item.params)
        if item.fmt == "png":
            from varflow.io.kitti_png import write_kitti_png

            write_kitti_png(out, flow)
        else:
            from varflow.io.flo import write_flo

            write_flo(out, flow)
        return
    from varflow.io.trajectories import write_trajectories
    from varflow.multiframe.track import default_ref

    ref = default_ref(len(frames), None)
    traj, visible = varflow.track(frames, ref, item.method, params=item.params,
                                  return_visibility=True)
    meta = dict(item.metadata)
    meta.update({
        "frames": list(item.frames),
        "ref_frame": item.frames[ref],
        "method": item.method,
        "params": dataclasses.asdict(item.params),
    })
    write_trajectories(out, traj, ref=ref, visibility=visible, metadata=meta)


def run_item(item: WorkItem) -> dict[str, Any]:
    """Run one task on a worker.

    Parameters
    ----------
    item : WorkItem

    Returns
    -------
    dict
        ``task_id``; ``checksum`` (SHA-256 of the written output) and ``seconds``
        on success, or ``error`` (one line) when the task failed -- exceptions are
        caught so that one bad input does not stop the run.
    """
    _pin_task_threads(item.threads)
    t0 = time.perf_counter()
    try:
        _compute(item)
        checksum = sha256_file(item.output)
    except Exception as exc:  # noqa: BLE001 - reported to the driver, recorded as failed
        log.debug("task %s failed", item.task_id, exc_info=exc)
        return {"task_id": item.task_id, "error": error_line(exc, with_type=True)}
    return {"task_id": item.task_id, "checksum": checksum,
            "seconds": time.perf_counter() - t0}
