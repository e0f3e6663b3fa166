"""Self-contained static HTML reports (``varflow report``).

:func:`build_report` turns a batch output folder, a ``varflow bench --csv`` file, a
single flow (``.flo`` / KITTI ``.png``, optionally with ground truth) or a trajectory
``.npz`` into one HTML page: images inlined as PNG data URIs, inline CSS, no
JavaScript and no external request.

* :mod:`varflow.report.sources` loads the inputs,
* :mod:`varflow.report.figures` makes the images,
* :mod:`varflow.report.html` assembles the page,
* :mod:`varflow.report.build` decides the content;

the ``varflow report`` sub-command is :mod:`varflow.cli.report`.
"""

from .build import DEFAULT_MAX_FRAMES, ReportInfo, build_report, render_report

__all__ = ["DEFAULT_MAX_FRAMES", "ReportInfo", "build_report", "render_report"]
