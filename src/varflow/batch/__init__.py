"""Batch optical flow and trajectories over many videos on Dask (``varflow batch``).

One task per frame pair (``varflow batch flow``) or per window of frames
(``varflow batch track``); tasks run on a :class:`distributed.LocalCluster` or an
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

The ``varflow batch`` sub-command is :mod:`varflow.cli.batch`.  This package needs
the ``batch`` extra (dask, distributed, zarr: ``pip install "varflow[batch]"``); the
rest of varflow never imports them.
"""

from __future__ import annotations

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
