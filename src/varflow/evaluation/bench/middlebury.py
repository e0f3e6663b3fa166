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

import logging
import math
import os
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ...registry import get_method, make_params
from ..datasets import (
    BOOK_REFERENCE_AEE,
    BOOK_TV_AEE,
    MIDDLEBURY_SEQUENCES,
    data_root,
    load_middlebury_pair,
    middlebury_sequence,
)
from .common import CSV_FIELDS, _warm_up, markdown_table, split_overrides

__all__ = ["BASELINE_METHOD", "CSV_FIELDS", "run_middlebury", "format_table"]

log = logging.getLogger(__name__)

#: The method the "% improved" row compares against (the book's "TV-only").
BASELINE_METHOD = "tvl1"


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

    from ..metrics import evaluate

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
