"""The report of a ``varflow bench --csv`` file: :func:`report_bench`.

Bar charts of the primary metric per method and, per group of rows (set, suite or
dataset), a table per sequence and method with the best marked.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .html import Page, bar_chart_svg, table
from .sources import BenchTable, finite

__all__ = ["report_bench"]


#: Columns that name a group of rows (one table per value).
_GROUP_COLUMNS = ("set", "suite", "dataset")
#: Columns that identify a sequence within a group, in label order.
_ID_COLUMNS = ("sequence", "scene", "variant", "split", "family", "seed", "pair", "window")
#: Descriptive columns left out of labels and summaries (shown in the full rows).
_DESCRIPTIVE = frozenset({"method", "kind", "motion", "shared", "frames", "ref", "ref_index",
                          "book_tv_aee", "book_aee", "mean_motion", "max_motion", "occluded",
                          "seconds"})
#: Metric columns in display order, with units (others numeric columns follow).
_METRICS = {"aee": "px", "aee_noc": "px", "aae": "deg", "epe": "px", "far_epe": "px",
            "rms": "px", "r1": "%", "r3": "%", "occ_accuracy": "", "hidden_recall": ""}


def _numeric(rows: Sequence[dict[str, Any]], column: str) -> bool:
    values = [r.get(column) for r in rows if r.get(column) is not None]
    return bool(values) and all(isinstance(v, float) for v in values)


def _label(row: dict[str, Any], id_cols: Sequence[str]) -> str:
    parts = []
    for c in id_cols:
        v = row.get(c)
        if v is None:
            continue
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        parts.append(str(v))
    return " / ".join(parts) or "(all)"


def report_bench(page: Page, src: BenchTable) -> None:
    """Add the report of a bench CSV table to ``page``."""
    rows = src.rows
    cols = src.columns
    primary = "aee" if finite([r.get("aee") for r in rows]) else "epe"
    group_col = next((c for c in _GROUP_COLUMNS if any(r.get(c) is not None for r in rows)), None)
    id_cols = [c for c in _ID_COLUMNS if c in cols and any(r.get(c) is not None for r in rows)]
    id_cols += [c for c in cols if c not in id_cols and c not in _DESCRIPTIVE
                and c not in _METRICS and c not in _GROUP_COLUMNS and not _numeric(rows, c)
                and any(r.get(c) is not None for r in rows)]
    metrics = [m for m in _METRICS if m in cols and finite([r.get(m) for r in rows])]
    metrics += [c for c in cols if c not in metrics and c not in _DESCRIPTIVE
                and c not in id_cols and c not in _GROUP_COLUMNS and _numeric(rows, c)
                and finite([r.get(c) for r in rows])]
    methods = list(dict.fromkeys(str(r["method"]) for r in rows if r.get("method") is not None))
    unit = _METRICS.get(primary, "")
    page.para(f"{len(rows)} rows, {len(methods)} methods; main error measure: "
              f"{primary.upper()} ({unit}), lower is better; best per row in bold.")

    # per-method summary
    page.heading("Summary per method", level=2, anchor="summary")
    srows = []
    means: dict[str, float] = {}
    secs: dict[str, float] = {}
    for m in methods:
        mine = [r for r in rows if r.get("method") == m]
        vals = {k: finite([r.get(k) for r in mine]) for k in metrics}
        s = finite([r.get("seconds") for r in mine])
        means[m] = float(np.mean(vals[primary])) if vals.get(primary) else math.nan
        secs[m] = float(np.mean(s)) if s else math.nan
        srows.append([m, len(mine)] + [float(np.mean(vals[k])) if vals[k] else None
                                       for k in metrics]
                     + [secs[m] if s else None, float(sum(s)) if s else None])
    header = ["method", "rows"] + [f"mean {k} {_METRICS.get(k, '')}".strip() for k in metrics]
    header += ["mean s", "total s"]
    best_col = 2 + metrics.index(primary) if primary in metrics else None
    best = None
    if best_col is not None:
        good = finite(list(means.values()))
        best = [{best_col} if good and math.isfinite(means[m]) and means[m] == min(good)
                else set() for m in methods]
    page.add(table(header, srows, best=best, cls="summary"))
    page.add('<div class="thumbs"><figure>'
             + bar_chart_svg(methods, [means[m] for m in methods], unit=unit,
                             title=f"mean {primary.upper()} per method")
             + "</figure><figure>"
             + bar_chart_svg(methods, [secs[m] for m in methods], unit="s",
                             title="mean seconds per row")
             + "</figure></div>")

    # per-sequence tables, one per group
    groups: dict[Any, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(r.get(group_col) if group_col else None, []).append(r)
    for g, grows in groups.items():
        title = f"{group_col} {g}" if group_col and g is not None else "Per sequence"
        page.heading(title if group_col else "Per sequence", level=2)
        gmetric = primary if finite([r.get(primary) for r in grows]) else next(
            (m for m in metrics if finite([r.get(m) for r in grows])), primary)
        gid = [c for c in id_cols if any(r.get(c) is not None for r in grows)]
        gmethods = list(dict.fromkeys(str(r["method"]) for r in grows
                                      if r.get("method") is not None))
        cells: dict[str, dict[str, list[float]]] = {}
        for r in grows:
            cells.setdefault(_label(r, gid), {}).setdefault(str(r.get("method")), []).extend(
                finite([r.get(gmetric)]))
        trows = []
        best_sets = []
        for lab, per in cells.items():
            vals = [float(np.mean(per[m])) if per.get(m) else None for m in gmethods]
            trows.append([lab, *vals])
            good = [v for v in vals if v is not None]
            best_sets.append({1 + j for j, v in enumerate(vals) if good and v == min(good)}
                             if len(good) > 1 else set())
        mean_row: list[Any] = ["mean"]
        for j in range(len(gmethods)):
            col = [r[1 + j] for r in trows if r[1 + j] is not None]
            mean_row.append(float(np.mean(col)) if col else None)
        trows.append(mean_row)
        best_sets.append(set())
        page.para(f"{gmetric.upper()} ({_METRICS.get(gmetric, '')}) per "
                  f"{' / '.join(gid) or 'row'} and method.")
        page.add(table([" / ".join(gid) or "row", *gmethods], trows, best=best_sets,
                       summary_rows=1, cls="sequences"))
        shown = [c for c in cols if any(r.get(c) is not None for r in grows)]
        page.add(f"<details><summary>all {len(grows)} rows</summary>")
        page.add(table(shown, ([r.get(c) for c in shown] for r in grows), n_text=0,
                       cls="rows"))
        page.add("</details>")
