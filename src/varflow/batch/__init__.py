"""Flow, trajectories, retiming and denoising of many videos on Dask (``varflow batch``).

One task per frame pair (``varflow batch flow``), per window of frames
(``varflow batch track``) or per input (``varflow batch retime`` and ``varflow batch
denoise``); tasks run on a :class:`distributed.LocalCluster` or an
existing Dask scheduler, each reading only its own frames and writing its output
atomically.  The driver process records every task in a SQLite manifest
(``OUT/manifest.sqlite``) so that a killed run, started again with the same
command, redoes only the unfinished work.

Modules
-------
inputs
    Expanding the command-line inputs (videos, frame folders, globs, input lists)
    and probing them (frame count, fingerprint).
plan
    Pair and window arithmetic, output names, the task list of an input.
manifest
    The SQLite manifest (tasks, inputs, run settings).
worker
    The function that runs on the Dask workers.
runner
    The driver: resume rules, submission with bounded in-flight tasks.
zarrsink
    The optional Zarr mirror (``--zarr``).

The task of ``varflow batch denoise`` is :func:`varflow.restore.video.denoise_video`,
the work of ``varflow denoise``; that of ``varflow batch restore`` is
:func:`varflow.restore.video.restore_video`, the work of ``varflow restore``.

The ``varflow batch`` sub-command is :mod:`varflow.cli.batch`.  This package needs
the ``batch`` extra (dask, distributed, zarr: ``pip install "varflow[batch]"``); the
rest of varflow never imports them.  The names below are imported on first use, so
that importing a module of this package loads only what it needs.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .inputs import BatchInput, expand_inputs, probe_input
    from .plan import BatchConfig, Task, flow_pairs, plan_tasks, read_pairs_file, track_windows
    from .runner import BatchSummary, run_batch

__all__ = [
    "BatchConfig",
    "BatchInput",
    "BatchSummary",
    "Task",
    "expand_inputs",
    "flow_pairs",
    "plan_tasks",
    "probe_input",
    "read_pairs_file",
    "run_batch",
    "track_windows",
]

#: The public names and their modules, imported on first use (:func:`__getattr__`).
_LAZY = {
    "BatchInput": "inputs", "expand_inputs": "inputs", "probe_input": "inputs",
    "BatchConfig": "plan", "Task": "plan", "flow_pairs": "plan", "plan_tasks": "plan",
    "read_pairs_file": "plan", "track_windows": "plan",
    "BatchSummary": "runner", "run_batch": "runner",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
