"""Pieces shared by the benchmark runners: parameter overrides, tables, CSV, warm-up.

:func:`split_overrides` distributes ``--<parameter>`` overrides over the methods of a
run, :func:`markdown_table` is the one renderer of the runners' tables and
:func:`write_csv` writes their rows atomically.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...registry import METHODS

__all__ = ["CSV_FIELDS", "markdown_table", "split_overrides", "write_csv"]

#: Default leading columns of :func:`write_csv` (those of the Middlebury runner's rows).
CSV_FIELDS = ("sequence", "method", "aee", "aae", "seconds", "book_tv_aee", "book_aee")


def split_overrides(
    methods: Sequence[str],
    overrides: Mapping[str, Any] | None,
    registry: Mapping[str, Any] = METHODS,
) -> dict[str, dict[str, Any]]:
    """Distribute parameter overrides over methods.

    Parameters
    ----------
    methods : sequence of str
        Registered method names.
    overrides : mapping, optional
        Either ``{field: value}``, applied to every listed method that has the field,
        or ``{method: {field: value}}`` per method (the two forms can be mixed).
    registry : mapping
        Where the methods are registered: :data:`~varflow.registry.METHODS` (default)
        or :data:`~varflow.registry.TRACKERS`.

    Returns
    -------
    dict
        ``{method: {field: value}}`` for every method in ``methods``.

    Raises
    ------
    ValueError
        For a field that none of the listed methods has, or a per-method entry for a
        method not listed.
    """
    import dataclasses

    for m in methods:
        if m not in registry:
            raise ValueError(f"method: unknown method {m!r}; available: {', '.join(registry)}")
    out: dict[str, dict[str, Any]] = {m: {} for m in methods}
    fields = {m: {f.name for f in dataclasses.fields(registry[m].params)} for m in methods}
    for key, value in (overrides or {}).items():
        if key in registry and isinstance(value, Mapping):
            if key not in out:
                raise ValueError(f"overrides: method {key!r} is not among {', '.join(methods)}")
            out[key].update(value)
            continue
        owners = [m for m in methods if key in fields[m]]
        if not owners:
            raise ValueError(f"{key}: not a parameter of method(s) {', '.join(methods)}")
        for m in owners:
            out[m][key] = value
    return out


def _warm_up(method: str, params: Any) -> None:
    """Run a method once on a tiny synthetic pair so JIT compilation is not timed."""
    import varflow

    from ...generators.pairs import synthetic_pair

    f0, f1, _ = synthetic_pair("translation", shape=(32, 40), magnitude=1.0, seed=0)
    varflow.flow(f0, f1, method, params=params)




def _nanmean(values: Sequence[float]) -> float:
    """Mean of the finite values (NaN if none)."""
    arr = np.asarray(values, np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.mean()) if arr.size else math.nan


def _num(value: float, digits: int) -> str:
    """``value`` with ``digits`` decimals, "-" if it is not finite."""
    return f"{value:.{digits}f}" if math.isfinite(value) else "-"


def markdown_table(header: Sequence[str], body: Sequence[Sequence[str]], n_left: int = 1) -> str:
    """Aligned Markdown table: the first ``n_left`` columns left-aligned, the rest right.

    The one renderer of the benchmark runners' tables.
    """
    widths = [max(len(header[i]), *(len(b[i]) for b in body)) for i in range(len(header))]

    def render(cells: Sequence[str]) -> str:
        left = [c.ljust(w) for c, w in zip(cells[:n_left], widths[:n_left], strict=True)]
        right = [c.rjust(w) for c, w in zip(cells[n_left:], widths[n_left:], strict=True)]
        return "| " + " | ".join(left + right) + " |"

    sep = "|" + "|".join(("-" * (w + 2)) if i < n_left else ("-" * (w + 1) + ":")
                         for i, w in enumerate(widths)) + "|"
    return "\n".join([render(header), sep] + [render(b) for b in body])


def write_csv(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike[str],
              fields: Sequence[str] = CSV_FIELDS) -> None:
    """Write benchmark rows to a CSV file atomically.

    Columns are ``fields`` (default :data:`CSV_FIELDS`, the Middlebury runner's)
    followed by any other keys of the rows (in order of first appearance); missing
    values and None are written as empty cells.

    Parameters
    ----------
    rows : sequence of mapping
    path : path-like
        Target file; its directory must exist.
    fields : sequence of str
        The leading columns, in order.
    """
    from ...io._atomic import atomic_write

    fields = list(fields)
    for r in rows:
        for k in r:
            if k not in fields:
                fields.append(k)
    with atomic_write(path, "w") as f:
        w = csv.DictWriter(f, fieldnames=fields, restval="", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})
