"""The Markdown tables of the multi-frame benchmarks.

:func:`format_multiframe_table` for the rows of :func:`~varflow.evaluation.bench.
multiframe_run.run_middlebury_multiframe` and :func:`~varflow.evaluation.bench.
multiframe_run.run_sintel_multiframe`; :func:`format_protocol_table` for those of the
Table 4.1 protocol (:func:`~varflow.evaluation.bench.sintel_protocol.
run_sintel_trajectories`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .common import markdown_table
from .multiframe_run import BASELINE_LABEL
from .sintel_protocol import PROTOCOL_BASELINE

__all__ = ["format_multiframe_table", "format_protocol_table"]


def _fmt(value: Any, digits: int) -> str:
    if value is None or value == "":
        return "-"
    v = float(value)
    return "-" if math.isnan(v) else f"{v:.{digits}f}"


def format_multiframe_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table, one line per (dataset, sequence, method).

    Columns: dataset, sequence, scored pair, reference index / number of frames,
    method, AEE, AAE (degrees), AEE over non-occluded pixels ("-" without occlusion
    mask), seconds, and the ratio of the AEE to the ``tvl1 (two-frame)`` baseline of
    the same sequence (< 1: the trajectory method beats the pair flow).  When several
    sequences are present, a ``mean`` line per method follows (over the sequences
    where it ran).

    Parameters
    ----------
    rows : sequence of mapping
        As returned by :func:`run_middlebury_multiframe` / :func:`run_sintel_multiframe`.

    Returns
    -------
    str
        The table, without a trailing newline.
    """
    if not rows:
        return "(no results)"
    base_aee = {(r["dataset"], r["sequence"]): r["aee"] for r in rows
                if r["method"] == BASELINE_LABEL}

    def ratio(r: Mapping[str, Any]) -> float | None:
        b = base_aee.get((r["dataset"], r["sequence"]))
        if b is None or r.get("aee") is None:
            return None
        b = float(b)
        return float(r["aee"]) / b if b > 0 else None

    header = ["dataset", "sequence", "pair", "ref/F", "method", "AEE", "AAE", "AEE noc", "s",
              "AEE / tvl1 pair"]
    body = []
    for r in rows:
        ref_f = f"{r['ref']}/{r['frames']}" if "ref" in r and "frames" in r else "-"
        body.append([str(r["dataset"]), str(r["sequence"]), str(r.get("pair", "-")), ref_f,
                     str(r["method"]), _fmt(r.get("aee"), 4), _fmt(r.get("aae"), 3),
                     _fmt(r.get("aee_noc"), 4), _fmt(r.get("seconds"), 2),
                     _fmt(ratio(r), 3)])
    n_left = 5
    seqs = {(r["dataset"], r["sequence"]) for r in rows}
    if len(seqs) > 1:
        methods: list[str] = []
        for r in rows:
            if r["method"] not in methods:
                methods.append(r["method"])

        def mean(vals: list[Any]) -> float | None:
            v = [float(x) for x in vals if x is not None and x != ""
                 and not math.isnan(float(x))]
            return float(np.mean(v)) if v else None

        for m in methods:
            mine = [r for r in rows if r["method"] == m]
            body.append(["mean", f"{len(mine)} sequences", "", "", m,
                         _fmt(mean([r.get("aee") for r in mine]), 4),
                         _fmt(mean([r.get("aae") for r in mine]), 3),
                         _fmt(mean([r.get("aee_noc") for r in mine]), 4),
                         _fmt(mean([r.get("seconds") for r in mine]), 2),
                         _fmt(mean([ratio(r) for r in mine]), 3)])
    return markdown_table(header, body, n_left)


def _mean_of(values: Sequence[Any]) -> float | None:
    v = [float(x) for x in values if x is not None and x != "" and not math.isnan(float(x))]
    return float(np.mean(v)) if v else None


def format_protocol_table(
    rows: Sequence[Mapping[str, Any]], baseline: str = PROTOCOL_BASELINE
) -> str:
    """Markdown table of the Table 4.1 protocol, then a verdict line per method.

    One line per (reference, window) with each method's AEE and, for the others, its
    ratio to ``baseline`` (< 1: the method beats it); then per reference the mean
    over its windows (when it has several) and the mean over all lines.  Below the
    table: for every other method, at how many references its mean AEE over the
    windows is below the baseline's; which methods' rows are shared between the
    windows; and the total seconds per method (a shared run counted once).

    Parameters
    ----------
    rows : sequence of mapping
        As returned by :func:`run_sintel_trajectories` (``ref``, ``window``,
        ``frames``, ``method``, ``aee``, optional ``seconds`` and ``shared``).
    baseline : str
        The method the others are compared with.

    Returns
    -------
    str
        Without a trailing newline; ``"(no results)"`` for no rows.
    """
    if not rows:
        return "(no results)"
    methods = list(dict.fromkeys(str(r["method"]) for r in rows))
    keys = list(dict.fromkeys((r["ref"], str(r["window"])) for r in rows))
    refs = list(dict.fromkeys(k[0] for k in keys))
    aee = {(r["ref"], str(r["window"]), str(r["method"])): r.get("aee") for r in rows}
    n_frames = {(r["ref"], str(r["window"])): r.get("frames") for r in rows}
    has_base = baseline in methods
    others = [m for m in methods if m != baseline]

    header = ["ref", "window", "F"]
    for m in methods:
        header.append(f"{m} AEE")
        if has_base and m != baseline:
            header.append(f"{m} / {baseline}")

    def cells(vals: Mapping[str, Any]) -> list[str]:
        out = []
        b = _mean_of([vals.get(baseline)]) if has_base else None
        for m in methods:
            v = _mean_of([vals.get(m)])
            out.append(_fmt(v, 4))
            if has_base and m != baseline:
                out.append(_fmt(v / b if v is not None and b else None, 3))
        return out

    body = [[str(ref), w, str(n_frames.get((ref, w), "") or "")]
            + cells({m: aee.get((ref, w, m)) for m in methods}) for ref, w in keys]
    ref_means = {}
    for ref in refs:
        wins = [w for x, w in keys if x == ref]
        ref_means[ref] = {m: _mean_of([aee.get((ref, w, m)) for w in wins]) for m in methods}
        if len(wins) > 1:
            body.append([str(ref), f"mean of {len(wins)} windows", ""] + cells(ref_means[ref]))
    if len(keys) > 1:
        overall = {m: _mean_of([aee.get((ref, w, m)) for ref, w in keys]) for m in methods}
        body.append(["all", f"mean of {len(keys)} lines", ""] + cells(overall))
    lines = [markdown_table(header, body, 2), ""]

    if not has_base:
        lines.append(f"no {baseline} rows: nothing to compare with")
    for m in others if has_base else []:
        both = [ref for ref in refs
                if ref_means[ref][m] is not None and ref_means[ref][baseline] is not None]
        wins = [ref for ref in both if ref_means[ref][m] < ref_means[ref][baseline]]
        where = f" ({', '.join(str(ref) for ref in wins)})" if wins else ""
        lines.append(f"{m} beats {baseline} at {len(wins)} of {len(both)} references{where} "
                     f"(mean AEE over each reference's windows)")
    for m in methods:
        if any(r.get("shared") for r in rows if r["method"] == m):
            lines.append(f"{m}: one run per reference on frames r, r+1, reused for every "
                         f"window (its estimate of frame r+1 does not depend on the window)")
    runs: dict[str, dict[tuple[Any, ...], float]] = {m: {} for m in methods}
    for r in rows:
        if r.get("seconds") is None:
            continue
        key = (r["ref"],) if r.get("shared") else (r["ref"], str(r["window"]))
        runs[str(r["method"])][key] = float(r["seconds"])
    timed = [f"{m} {sum(runs[m].values()):.1f} s in {len(runs[m])} runs" for m in methods
             if runs[m]]
    if timed:
        lines.append("seconds: " + ", ".join(timed))
    return "\n".join(lines)
