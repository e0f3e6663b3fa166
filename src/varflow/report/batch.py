"""The report of a ``varflow batch`` output folder.

:func:`report_batch` summarises the tasks of the manifest, lists the videos and the
failed tasks, and shows every video with its settings: flows through
:func:`varflow.report.flows.flow_thumbnails`, trajectory windows through
:func:`varflow.report.trajectories.track_video`.
"""

from __future__ import annotations

import datetime
import json
from collections import Counter
from typing import Any

from .common import params_block
from .flows import flow_thumbnails
from .html import Page, esc, key_value_table, table
from .sources import BatchFolder, Video, finite
from .trajectories import track_video

__all__ = ["MAX_FAILED_ROWS", "report_batch"]


#: Rows shown in the table of failed tasks.
MAX_FAILED_ROWS = 500


def _video_params(page: Page, video: Video) -> None:
    if not video.tasks:
        page.para("No manifest entry for this video (outputs found by scanning the folder).")
        return
    groups: Counter[str] = Counter()
    done = [t for t in video.tasks if t.status == "done"]
    for t in done or video.tasks:  # the settings of the outputs shown
        groups[json.dumps([t.method, t.version, t.params], sort_keys=True, default=str)] += 1
    inputs = sorted({t.input for t in video.tasks if t.input})
    for key, count in groups.items():
        method, version, params = json.loads(key)
        extra: dict[str, Any] = {}
        if inputs:
            extra["input"] = inputs[0] if len(inputs) == 1 else f"{len(inputs)} inputs"
        if version:
            extra["varflow version"] = version
        if len(groups) > 1:
            extra["tasks"] = count
        params_block(page, method, params, extra)


def report_batch(page: Page, src: BatchFolder, max_frames: int) -> None:
    """Add the report of a batch output folder to ``page`` (``max_frames`` per video)."""
    tasks = src.tasks
    status = Counter(t.status or "unknown" for t in tasks)
    if src.manifest_error:
        page.add(f'<p class="warn">{esc(src.manifest_error)}; the folder was scanned '
                 f"instead.</p>")
    elif src.manifest is None:
        page.para("No manifest.sqlite: outputs found by scanning the folder; no parameters "
                  "or task states.")
    kinds = Counter(v.kind for v in src.videos)
    summary = (f"{len(src.videos)} videos ({kinds.get('flow', 0)} flow, "
               f"{kinds.get('track', 0)} trajectory)")
    if tasks:
        summary += "; tasks: " + ", ".join(f"{n} {s}" for s, n in sorted(status.items()))
        secs = finite([t.seconds for t in tasks])
        if secs:
            summary += f"; {sum(secs):.1f} s of computation"
    page.para(summary + ".")
    if src.meta:
        page.heading("Batch settings", level=3)
        page.add(key_value_table({k: _meta_value(k, v) for k, v in src.meta.items()},
                                 cls="meta"))

    page.heading("Videos", level=2, anchor="videos")
    rows = []
    for v in src.videos:
        c = Counter(t.status for t in v.tasks)
        methods = sorted({t.method for t in v.tasks if t.method})
        rows.append((v.name, v.kind, ", ".join(methods) or "—", len(v.files),
                     c.get("done", 0) if v.tasks else "—", c.get("failed", 0) if v.tasks else "—",
                     c.get("pending", 0) + c.get("running", 0) if v.tasks else "—",
                     sum(finite([t.seconds for t in v.tasks])) if v.tasks else None))
    page.add(table(("video", "kind", "method", "outputs", "done", "failed",
                    "pending/running", "seconds"), rows, n_text=3, cls="videos"))

    failed = [t for t in tasks if t.status == "failed"]
    if failed:
        page.heading(f"Failed tasks ({len(failed)})", level=2, anchor="failed")
        frows = [(t.task_id, t.name or "—", _frames_text(t.frames), t.attempts, t.error or "")
                 for t in failed[:MAX_FAILED_ROWS]]
        page.add(table(("task", "video", "frames", "attempts", "error"), frows, n_text=5,
                       cls="failed"))
        if len(failed) > MAX_FAILED_ROWS:
            page.para(f"… and {len(failed) - MAX_FAILED_ROWS} more failed tasks.")
    missing = [t for t in tasks if t.status == "done" and t.output
               and not (src.root / t.output).is_file()]
    if missing:
        page.add(f'<p class="warn">{len(missing)} tasks are marked done but their output is '
                 f"missing, e.g. {esc(missing[0].output)}.</p>")

    for v in src.videos:
        page.heading(f"{v.name} ({'flow' if v.kind == 'flow' else 'trajectories'})", level=2)
        _video_params(page, v)
        if not v.files:
            page.para("No output file yet.")
            continue
        if v.kind == "flow":
            problems = flow_thumbnails(page, v, max_frames)
        else:
            problems = track_video(page, v, max_frames)
        if problems:
            page.add('<p class="warn">Unreadable outputs: '
                     + "; ".join(esc(p) for p in problems) + "</p>")


def _meta_value(key: str, value: str) -> str:
    """A ``meta`` value for display: POSIX times of time-like keys as UTC dates."""
    if key in ("created", "updated", "started", "finished"):
        try:
            t = float(value)
        except ValueError:
            return value
        if 1e9 < t < 1e10:
            stamp = datetime.datetime.fromtimestamp(t, datetime.UTC)
            return stamp.strftime("%Y-%m-%d %H:%M:%S UTC")
    return value


def _frames_text(frames: list[int] | None) -> str:
    if not frames:
        return "—"
    if len(frames) <= 3:
        return ", ".join(map(str, frames))
    return f"{frames[0]}–{frames[-1]} ({len(frames)})"
