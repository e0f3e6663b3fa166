"""Trajectory methods scored on real sequences: Middlebury RubberWhale and Sintel snippets.

There is no public dense *trajectory* ground truth on real images, so the
multi-frame methods are scored the way the book does it: on the one pair of the
sequence that has two-frame ground truth.

* :func:`run_middlebury_multiframe` — every trajectory method of
  :data:`varflow.registry.TRACKERS` runs on the 8 frames ``frame07 … frame14`` of
  RubberWhale with the reference ``frame10`` (index 3); the displacement it gives
  frame11 (index 4) is compared with ``flow10.flo`` (frame10 → frame11) over the
  pixels with known ground truth: AEE and AAE.  A row ``tvl1 (two-frame)``
  (``varflow.flow(frame10, frame11, "tvl1")`` with default parameters) is the pair
  baseline.
* :func:`run_sintel_multiframe` — the same on every MPI-Sintel snippet found on disk
  (runs of consecutive frames, 4 per clip and pass here); a report, without bounds.
  The reference of a snippet is the frame N whose ground truth ``frame_N.flo``
  (N → N + 1) exists with frame N + 1 in the snippet, preferring one that has an
  occlusion mask (so the non-occluded AEE can be given): frame_0002 of a
  0001–0004 snippet, i.e. index 1, with one frame before and two after.  AEE over
  all valid pixels (the ``invalid`` mask removed when present) and over the
  non-occluded ones.

:func:`format_multiframe_table` prints the rows as a Markdown table, one line per
(sequence, method), with each method's AEE relative to the ``tvl1`` pair baseline of
the same sequence.

The book's Table 4.1 protocol on real footage (Gibson & Marques 2016) runs on the
whole 50-frame MPI-Sintel clip ``final/alley_1``:

* :func:`run_sintel_trajectories` — for every reference frame r (5 … 10 by default)
  and every window of the clip around r (9, 13 and 19 frames placed by
  :func:`protocol_window`, plus the whole clip), every trajectory method tracks r's
  pixels through the window; its displacement in frame r + 1 is scored against
  ``flow/alley_1/frame_r.flo``.  :func:`plan_sintel_protocol` checks the
  arguments against the data on disk before any work, and
  :func:`format_protocol_table` prints one line per (reference, window) with each
  method's AEE and its ratio to ``twoframe``, the means, and at how many references
  each method beats ``twoframe``.

Modules
-------
This module is the public home of these names; each job lives in its own module:

* :mod:`varflow.evaluation.bench.multiframe_data` — loading RubberWhale and the
  Sintel snippets, crops;
* :mod:`varflow.evaluation.bench.multiframe_run` — the runs on RubberWhale and the
  snippets, with the ``tvl1`` pair baseline;
* :mod:`varflow.evaluation.bench.multiframe_tables` — the Markdown tables;
* :mod:`varflow.evaluation.bench.sintel_protocol` — the Table 4.1 protocol.
"""

from __future__ import annotations

from .multiframe_data import (
    RUBBERWHALE_FRAMES,
    RUBBERWHALE_REF,
    SintelSnippet,
    load_rubberwhale_clip,
    sintel_snippets,
)
from .multiframe_data import Crop as Crop
from .multiframe_run import (
    BASELINE_LABEL,
    DEFAULT_METHODS,
    default_methods,
    run_middlebury_multiframe,
    run_sintel_multiframe,
)
from .multiframe_tables import format_multiframe_table, format_protocol_table
from .sintel_protocol import (
    PROTOCOL_BASELINE,
    PROTOCOL_CLIP,
    PROTOCOL_METHODS,
    PROTOCOL_PASS,
    PROTOCOL_REFS,
    PROTOCOL_WINDOWS,
    SHARED_METHODS,
    ProtocolWindow,
    plan_sintel_protocol,
    protocol_window,
    protocol_windows,
    run_sintel_trajectories,
    sintel_clip_numbers,
)

__all__ = [
    "BASELINE_LABEL",
    "DEFAULT_METHODS",
    "RUBBERWHALE_FRAMES",
    "RUBBERWHALE_REF",
    "SintelSnippet",
    "default_methods",
    "load_rubberwhale_clip",
    "sintel_snippets",
    "run_middlebury_multiframe",
    "run_sintel_multiframe",
    "format_multiframe_table",
    "PROTOCOL_CLIP",
    "PROTOCOL_PASS",
    "PROTOCOL_METHODS",
    "PROTOCOL_REFS",
    "PROTOCOL_WINDOWS",
    "PROTOCOL_BASELINE",
    "SHARED_METHODS",
    "ProtocolWindow",
    "protocol_window",
    "protocol_windows",
    "sintel_clip_numbers",
    "plan_sintel_protocol",
    "run_sintel_trajectories",
    "format_protocol_table",
]
