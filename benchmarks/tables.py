"""Print the tables of benchmarks/README.md that are generated from benchmark CSVs.

    python benchmarks/tables.py interpolation [benchmarks/results/interpolation.csv]

prints the frame-interpolation tables (reporting split, tuning split, seconds per
960×540 frame) from the CSV of ``varflow bench interpolation --split all --csv ...``;

    python benchmarks/tables.py twoframe [benchmarks/results/twoframe_middlebury.csv]

prints the table of every two-frame method and peer on Middlebury from the CSV of
``varflow bench twoframe --sets middlebury ... --csv ...``.  benchmarks/README.md holds
each output between the markers ``<!-- generated: AREA -->`` and
``<!-- end generated -->``, and tests/test_benchmark_tables.py checks that it is what
this script prints now.
"""

from __future__ import annotations

import argparse
import csv
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_CSV = HERE / "results" / "interpolation.csv"
TWOFRAME_CSV = HERE / "results" / "twoframe_middlebury.csv"

#: Sets, their labels, and the methods of the tables in order.
SETS = (("middlebury", "Middlebury"), ("ucf101", "UCF101"), ("sintel", "Sintel alley_1"))
METHODS = ("splat", "splat-fast", "naive", "minterpolate", "blend")
LABELS = {"splat": "`splat`", "splat-fast": "`splat-fast`", "naive": "`naive`",
          "minterpolate": "minterpolate", "blend": "blend"}


def read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _by_case(rows: list[dict[str, str]], set_name: str, split: str) -> dict[str, dict]:
    out: dict[str, dict] = {}
    for r in rows:
        if r["set"] == set_name and r["split"] == split:
            out.setdefault(r["method"], {})[r["case"]] = r
    return out


def _mean(cases: dict, key: str) -> float:
    return statistics.mean(float(r[key]) for r in cases.values())


def _gain(cases: dict, base: dict) -> float:
    return statistics.mean(float(cases[c]["psnr"]) - float(base[c]["psnr"]) for c in base)


def _wins(cases: dict, base: dict) -> str:
    won = sum(float(cases[c]["psnr"]) > float(base[c]["psnr"]) for c in base)
    return f"{won}/{len(base)}"


def reporting_table(rows: list[dict[str, str]]) -> str:
    head = ("| set | method | PSNR | SSIM | IE | NE | MAE | dPSNR vs minterpolate | "
            "dPSNR vs naive | wins vs minterpolate |\n"
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    lines = [head]
    for set_name, label in SETS:
        by = _by_case(rows, set_name, "reporting")
        best = max(METHODS, key=lambda m: _mean(by[m], "psnr"))
        for k, m in enumerate(METHODS):
            cases = by[m]
            p = f"{_mean(cases, 'psnr'):.2f}"
            first = f"{label} ({len(cases)})" if k == 0 else ""
            mi = "-" if m == "minterpolate" else f"{_gain(cases, by['minterpolate']):+.2f}"
            nv = "-" if m == "naive" else f"{_gain(cases, by['naive']):+.2f}"
            wins = "-" if m == "minterpolate" else _wins(cases, by["minterpolate"])
            lines.append(f"| {first} | {LABELS[m]} | {'**' + p + '**' if m == best else p} | "
                         f"{_mean(cases, 'ssim'):.4f} | {_mean(cases, 'ie'):.2f} | "
                         f"{_mean(cases, 'ne'):.3f} | {_mean(cases, 'mae'):.2f} | {mi} | {nv} | "
                         f"{wins} |")
    return "\n".join(lines)


def tuning_table(rows: list[dict[str, str]]) -> str:
    lines = ["| set | " + " | ".join(LABELS[m] for m in METHODS)
             + " | `splat` wins vs minterpolate |",
             "|---|" + "---:|" * (len(METHODS) + 1)]
    for set_name, label in SETS:
        by = _by_case(rows, set_name, "tuning")
        n = len(by["splat"])
        lines.append(f"| {label} ({n}) | " + " | ".join(
            f"{_mean(by[m], 'psnr'):.2f}" for m in METHODS)
            + f" | {_wins(by['splat'], by['minterpolate'])} |")
    return "\n".join(lines)


def timing_table(rows: list[dict[str, str]]) -> str:
    lines = ["| method | pair s/frame | × minterpolate | stream s/frame | × minterpolate |",
             "|---|---:|---:|---:|---:|"]
    timing = {r["method"]: r for r in rows if r["set"] == "timing"}
    for m in ("naive", "splat", "splat-fast", "minterpolate"):
        r = timing[m]
        lines.append(f"| {LABELS[m]} | {float(r['seconds']):.3f} | "
                     f"{float(r['ratio_minterpolate']):.2f} | "
                     f"{float(r['seconds_stream']):.3f} | "
                     f"{float(r['ratio_minterpolate_stream']):.2f} |")
    return "\n".join(lines)


def interpolation(path: Path = DEFAULT_CSV) -> str:
    """The generated block of the README's frame-interpolation section."""
    rows = read_rows(path)
    return "\n\n".join([
        "Reporting split:", reporting_table(rows),
        "Tuning split:", tuning_table(rows),
        "Seconds per in-between 960 × 540 frame (median of the timed runs):",
        timing_table(rows)])


#: Rows of the two-frame table: CSV method name and label, in order.
TWOFRAME_ROWS = (("tvl1", "`tvl1`"), ("tvl1-fast", "`tvl1-fast`"), ("tvl1-ld", "`tvl1-ld`"),
                 ("tvl1-tensor", "`tvl1-tensor`"), ("tensor", "`tensor` (the book's plain energy)"),
                 ("deepflow", "OpenCV DeepFlow"), ("dis", "OpenCV DIS"),
                 ("dualtvl1", "OpenCV DualTVL1"),
                 ("skimage", "scikit-image `optical_flow_tvl1`"))


def twoframe(path: Path = TWOFRAME_CSV) -> str:
    """The generated table of every two-frame method and peer on Middlebury: mean AEE,
    mean seconds per pair and the ratio of the total time to DeepFlow's; the lowest
    AEE in bold."""
    rows = [r for r in read_rows(path) if r["set"] == "middlebury"]
    by: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        by.setdefault(r["method"], []).append(r)
    present = [(m, lab) for m, lab in TWOFRAME_ROWS if m in by]
    aee = {m: statistics.mean(float(r["aee"]) for r in by[m]) for m, _ in present}
    secs = {m: statistics.mean(float(r["seconds"]) for r in by[m]) for m, _ in present}
    best = min(aee.values())
    lines = ["| method | mean AEE | s per pair | × DeepFlow's time |", "|---|---:|---:|---:|"]
    for m, lab in present:
        a = f"{aee[m]:.3f}"
        if a == f"{best:.3f}":
            a = f"**{a}**"
        ratio = f"{secs[m] / secs['deepflow']:.2f}" if "deepflow" in secs else "-"
        lines.append(f"| {lab} | {a} | {secs[m]:.3f} | {ratio} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("area", choices=["interpolation", "twoframe"])
    parser.add_argument("csv", nargs="?", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.area == "twoframe":
        print(twoframe(args.csv or TWOFRAME_CSV))
    else:
        print(interpolation(args.csv or DEFAULT_CSV))
    return 0


if __name__ == "__main__":
    sys.exit(main())
