"""Accuracy benchmark on the Middlebury sequences with public ground truth.

:func:`run_middlebury` runs registered methods on frame10 -> frame11 of each
sequence and returns one row per (sequence, method); :func:`format_table` lays the
rows out like Table 3.3 of Gibson & Marques (2016): one line per sequence, one
group of columns per method, a mean line, the ratio to the book's TV-only figures
and, when ``tvl1`` and another method are both present, the improvement of each
other method over ``tvl1``.  Method names always come from
:data:`varflow.registry.METHODS`.
"""

from __future__ import annotations

import csv
import logging
import math
import os
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ..registry import METHODS, get_method, make_params
from .datasets import (
    BOOK_REFERENCE_AEE,
    BOOK_TV_AEE,
    MIDDLEBURY_SEQUENCES,
    data_root,
    load_middlebury_pair,
    middlebury_sequence,
)

__all__ = [
    "BASELINE_METHOD",
    "CSV_FIELDS",
    "run_middlebury",
    "split_overrides",
    "format_table",
    "write_csv",
    "markdown_table",
]

log = logging.getLogger(__name__)

#: The method the "% improved" row compares against (the book's "TV-only").
BASELINE_METHOD = "tvl1"

#: Columns of :func:`write_csv`, in order.
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

    from ..generators.pairs import synthetic_pair

    f0, f1, _ = synthetic_pair("translation", shape=(32, 40), magnitude=1.0, seed=0)
    varflow.flow(f0, f1, method, params=params)


def run_middlebury(
    methods: Sequence[str],
    root: str | os.PathLike[str] | None = None,
    sequences: Iterable[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Run methods on the Middlebury pairs and score them against the ground truth.

    Each method first runs once on a tiny synthetic pair (warm-up, not timed) so that
    the reported seconds exclude Numba compilation.  ``seconds`` is the wall time of
    :func:`varflow.flow` alone (loading and scoring excluded).

    Parameters
    ----------
    methods : sequence of str
        Names from :data:`varflow.registry.METHODS`.
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.
    sequences : iterable of str, optional
        Subset of :data:`~varflow.evaluation.datasets.MIDDLEBURY_SEQUENCES`
        (case-insensitive); all eight by default.
    overrides : mapping, optional
        Parameter overrides; see :func:`split_overrides`.
    progress : bool
        Show a tqdm bar over sequences x methods on stderr (only when stderr is a
        terminal).

    Returns
    -------
    list of dict
        One row per (sequence, method), sequences outer: ``sequence``, ``method``,
        ``aee``, ``aae`` (degrees), ``seconds``, ``book_tv_aee`` (the book's TV-only
        figure for the sequence) and ``book_aee`` (the book's figure for this method,
        or None when the book has none).

    Raises
    ------
    ValueError
        Unknown method, sequence or parameter, or an invalid parameter value.
    FileNotFoundError
        When the data are missing.
    """
    from tqdm import tqdm

    import varflow

    from .metrics import evaluate

    methods = list(methods)
    if not methods:
        raise ValueError("methods: need at least one method")
    for m in methods:
        get_method(m)
    seqs = [middlebury_sequence(s) for s in (sequences or MIDDLEBURY_SEQUENCES)]
    if not seqs:
        raise ValueError("sequences: need at least one sequence")
    per_method = split_overrides(methods, overrides)
    params = {m: make_params(m, **per_method[m]) for m in methods}  # validate before any work
    root_path = data_root(root)
    if not (root_path / "middlebury").is_dir():
        raise FileNotFoundError(
            f"Middlebury data not found under {root_path}; pass --data DIR or set "
            "VARFLOW_DATA to the folder holding middlebury/"
        )
    for m in methods:
        _warm_up(m, params[m])

    rows: list[dict[str, Any]] = []
    bar = tqdm(
        total=len(seqs) * len(methods),
        desc="middlebury",
        unit="run",
        file=sys.stderr,
        disable=None if progress else True,
        leave=False,
    )
    try:
        for seq in seqs:
            f0, f1, gt = load_middlebury_pair(seq, root_path)
            for m in methods:
                bar.set_postfix_str(f"{seq} {m}")
                t0 = time.perf_counter()
                est = varflow.flow(f0, f1, m, params=params[m])
                seconds = time.perf_counter() - t0
                scores = evaluate(est, gt)
                row = {
                    "sequence": seq,
                    "method": m,
                    "aee": float(scores["aee"]),
                    "aae": float(scores["aae"]),
                    "seconds": seconds,
                    "book_tv_aee": BOOK_TV_AEE.get(seq),
                    "book_aee": BOOK_REFERENCE_AEE.get(m, {}).get(seq),
                }
                log.info("%s %s: AEE %.4f AAE %.3f in %.2fs", seq, m, row["aee"], row["aae"],
                         seconds)
                rows.append(row)
                bar.update(1)
    finally:
        bar.close()
    return rows


def _mean(values: Iterable[float | None]) -> float:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    return float(np.mean(vals)) if vals else math.nan


def _fmt(value: float | None, digits: int) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.{digits}f}"


def format_table(rows: Sequence[Mapping[str, Any]], baseline: str | None = None) -> str:
    """Lay benchmark rows out as a Markdown table, one line per sequence.

    Columns: the sequence, then ``AEE``, ``AAE`` and seconds for every method (in
    order of first appearance), then the book's TV-only AEE.  Under the sequences:

    * ``mean`` — mean of each column over the sequences;
    * ``ratio to book TV-only`` — mean AEE of each method divided by the mean of the
      book's TV-only AEE over the same sequences (1.00 = on par);
    * ``total s`` — the summed seconds of each method over the sequences;
    * ``% improved vs B`` — when the baseline method ``B`` and another method are
      both present: ``100 (mean_B - mean_m) / mean_B`` for every other method m,
      over the sequences both methods ran on (positive = better than the baseline).

    Parameters
    ----------
    rows : sequence of mapping
        As returned by :func:`run_middlebury` (or read back from its CSV).
    baseline : str, optional
        Method the improvement row compares against: ``tvl1`` (the book's
        "TV-only") when present, else the first method.

    Returns
    -------
    str
        The table, without a trailing newline.
    """
    if not rows:
        return "(no results)"
    methods: list[str] = []
    seqs: list[str] = []
    cell: dict[tuple[str, str], Mapping[str, Any]] = {}
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
        if r["sequence"] not in seqs:
            seqs.append(r["sequence"])
        cell[(r["sequence"], r["method"])] = r

    def get(seq: str, m: str, key: str) -> float | None:
        r = cell.get((seq, m))
        v = None if r is None else r.get(key)
        return None if v is None or v == "" else float(v)

    header = ["sequence"]
    for m in methods:
        header += [f"{m} AEE", f"{m} AAE", f"{m} s"]
    header.append("book TV AEE")
    body: list[list[str]] = []
    for s in seqs:
        line = [s]
        for m in methods:
            line += [_fmt(get(s, m, "aee"), 4), _fmt(get(s, m, "aae"), 3),
                     _fmt(get(s, m, "seconds"), 2)]
        line.append(_fmt(BOOK_TV_AEE.get(s), 4))
        body.append(line)

    mean_line = ["mean"]
    total_line = ["total s"]
    ratio_line = ["ratio to book TV-only"]
    for m in methods:
        ran = [s for s in seqs if get(s, m, "aee") is not None]
        mean_aee = _mean(get(s, m, "aee") for s in ran)
        mean_line += [_fmt(mean_aee, 4), _fmt(_mean(get(s, m, "aae") for s in ran), 3),
                      _fmt(_mean(get(s, m, "seconds") for s in ran), 2)]
        secs = [get(s, m, "seconds") for s in ran]
        total_line += ["", "", _fmt(sum(v for v in secs if v is not None), 2)]
        book = _mean(BOOK_TV_AEE.get(s) for s in ran)
        ratio_line += [_fmt(mean_aee / book if book > 0 else math.nan, 3), "", ""]
    mean_line.append(_fmt(_mean(BOOK_TV_AEE.get(s) for s in seqs), 4))
    ratio_line.append("1.000")
    total_line.append("")
    body += [mean_line, total_line, ratio_line]

    if baseline is None:
        baseline = BASELINE_METHOD if BASELINE_METHOD in methods else methods[0]
    others = [m for m in methods if m != baseline]
    if baseline in methods and others:
        label = "TV-only" if baseline == BASELINE_METHOD else baseline
        line = [f"% improved vs {label}"]
        for m in methods:
            if m == baseline:
                line += ["0.0", "", ""]
                continue
            both = [s for s in seqs
                    if get(s, m, "aee") is not None and get(s, baseline, "aee") is not None]
            base = _mean(get(s, baseline, "aee") for s in both)
            mine = _mean(get(s, m, "aee") for s in both)
            line += [_fmt(100.0 * (base - mine) / base if base > 0 else math.nan, 1), "", ""]
        line.append("")
        body.append(line)

    return markdown_table(header, body)


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
    from ..io._atomic import atomic_write

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
