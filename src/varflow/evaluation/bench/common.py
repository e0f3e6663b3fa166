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

__all__ = ["CSV_FIELDS", "markdown_table", "method_spec", "parse_value", "spec_name",
           "split_overrides", "write_csv"]

#: Default leading columns of :func:`write_csv` (those of the Middlebury runner's rows).
CSV_FIELDS = ("sequence", "method", "aee", "aae", "seconds", "book_tv_aee", "book_aee")


def parse_value(text: str, default: Any, field: str) -> Any:
    """A field value written as text (a method spec, ``--set``), of the type of the
    field's default; ``ValueError`` naming ``field`` otherwise."""
    if isinstance(default, bool):
        low = text.strip().lower()
        if low in ("1", "true", "yes", "on"):
            return True
        if low in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"{field}: expected true or false, got {text!r}")
    for kind, what in ((int, "an integer"), (float, "a number")):
        if isinstance(default, kind):
            try:
                return kind(text)
            except ValueError:
                raise ValueError(f"{field}: expected {what}, got {text!r}") from None
    return text


def method_spec(spec: str, registry: Mapping[str, Any] = METHODS) -> tuple[str, dict[str, Any]]:
    """Split a method spec ``NAME[:FIELD=VALUE[:...]]`` into the name and its overrides.

    A benchmark runs a method with other parameters beside its defaults this way:
    ``rlr:link_weight=0`` is rlr decoupled.  For a tracker that composes a two-frame
    method, a bare method name stands for ``flow_method=NAME``: ``twoframe:tvl1-ld``.
    Values take the type of the field's default.  The spec is the row's label.

    Raises
    ------
    ValueError
        An unknown method or field, or a value of the wrong type.
    """
    from ...registry import parameter_fields

    name, *parts = spec.split(":")
    if name not in registry:
        raise ValueError(f"method: unknown method {name!r}; available: {', '.join(registry)}")
    entry = registry[name]
    given: dict[str, str] = {}
    for part in parts:
        key, eq, value = part.partition("=")
        if not eq:
            key, value = "flow_method", key
        given[key.strip()] = value.strip()
    defaults = {n: d for n, d, _ in parameter_fields(entry, given.get("flow_method"))}
    out: dict[str, Any] = {}
    for key, value in given.items():
        if key not in defaults:
            raise ValueError(f"{key}: not a parameter of method {name!r} (in {spec!r})")
        out[key] = parse_value(value, defaults[key], key)
    return name, out


def spec_name(spec: str) -> str:
    """The registered name of a method spec (:func:`method_spec`): the part before ``:``."""
    return spec.split(":", 1)[0]


def split_overrides(
    methods: Sequence[str],
    overrides: Mapping[str, Any] | None,
    registry: Mapping[str, Any] = METHODS,
) -> dict[str, dict[str, Any]]:
    """Distribute parameter overrides over methods.

    Parameters
    ----------
    methods : sequence of str
        Method specs (:func:`method_spec`): registered names, optionally with
        ``:field=value`` parts, which override everything else for that entry.
    overrides : mapping, optional
        Either ``{field: value}``, applied to every listed method that has the field,
        or ``{method: {field: value}}`` per method (the two forms can be mixed; the
        key is a spec of ``methods`` or a registered name, which then applies to
        every spec of that method).
    registry : mapping
        Where the methods are registered: :data:`~varflow.registry.METHODS` (default)
        or :data:`~varflow.registry.TRACKERS`.

    Returns
    -------
    dict
        ``{spec: {field: value}}`` for every spec in ``methods``.

    Raises
    ------
    ValueError
        For a field that none of the listed methods has, or a per-method entry for a
        method not listed.
    """
    from ...registry import parameter_fields

    specs = {m: method_spec(m, registry) for m in methods}
    out: dict[str, dict[str, Any]] = {m: {} for m in methods}
    fields = {m: {n for n, _, _ in parameter_fields(registry[name], own.get("flow_method"))}
              for m, (name, own) in specs.items()}
    for key, value in (overrides or {}).items():
        if (key in registry or key in specs) and isinstance(value, Mapping):
            targets = [m for m in methods if m == key or specs[m][0] == key]
            if not targets:
                raise ValueError(f"overrides: method {key!r} is not among {', '.join(methods)}")
            for m in targets:
                out[m].update(value)
            continue
        owners = [m for m in methods if key in fields[m]]
        if not owners:
            raise ValueError(f"{key}: not a parameter of method(s) {', '.join(methods)}")
        for m in owners:
            out[m][key] = value
    for m, (_, own) in specs.items():
        out[m].update(own)
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
