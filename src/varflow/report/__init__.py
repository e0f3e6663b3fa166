"""Self-contained static HTML reports (``varflow report``).

:func:`build_report` turns a batch output folder, a ``varflow bench --csv`` file, a
single flow (``.flo`` / KITTI ``.png``, optionally with ground truth) or a trajectory
``.npz`` into one HTML page: images inlined as PNG data URIs, inline CSS, no
JavaScript and no external request.

* :mod:`varflow.report.sources` loads the inputs,
* :mod:`varflow.report.figures` makes the images,
* :mod:`varflow.report.html` assembles the page,
* :mod:`varflow.report.batch`, :mod:`varflow.report.flows`,
  :mod:`varflow.report.trajectories` and :mod:`varflow.report.bench` decide the content
  of each kind of input (on the shared pieces of :mod:`varflow.report.common`),
* :mod:`varflow.report.build` is the entry point;

the ``varflow report`` sub-command is :mod:`varflow.cli.report`.
"""

from .build import DEFAULT_MAX_FRAMES, ReportInfo, build_report, render_report

__all__ = ["DEFAULT_MAX_FRAMES", "ReportInfo", "build_report", "render_report"]
