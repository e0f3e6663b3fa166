"""Scene-cut detection of ``varflow retime`` and ``varflow video`` on real clips.

Two counts per rule and split, from the real clips of the benchmark data:

* **false cuts**: pairs of consecutive frames of one shot (with both neighbour pairs
  known) that the rule calls a cut;
* **cuts found**: joins of the last two frames of one clip to the first two of
  another (the second cropped to the first's size when larger; pairs that cannot be
  cropped are left out), the cut pair scored with both neighbours.

The tuning split is Sintel (clean and final), Middlebury (the 8-frame RubberWhale
and the interpolation triples) and the UCF101 triples; the report split the
restoration clips (``bikes`` holds a real cut after frame 29 and counts as two
shots).  The rules: ``max`` (until 2026-12-05: the score at least twice the larger
neighbour's) and ``spike`` (today's: twice the smaller neighbour's and
:data:`~varflow.retime.stream.CUT_MARGIN` above the larger).

Run::

    python benchmarks/bench_scene_cuts.py [--data DIR]
"""

from __future__ import annotations

import argparse
import itertools
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from varflow.evaluation.datasets import data_root
from varflow.io import read_image
from varflow.retime.stream import CUT_MARGIN, CUT_RATIO, CUT_THRESHOLD, _score, _thumb

Rule = Callable[[float, float, float], bool]


def rule_max(s: float, p: float, f: float) -> bool:
    return s >= CUT_THRESHOLD and s >= CUT_RATIO * max(p, f)


def rule_spike(s: float, p: float, f: float) -> bool:
    return s >= CUT_THRESHOLD and s >= CUT_RATIO * min(p, f) and s >= max(p, f) + CUT_MARGIN


def _runs(files: list[Path]) -> list[list[Path]]:
    """Split ``frame_NNNN.png`` files at gaps in their numbering."""
    out: list[list[Path]] = []
    prev = None
    for f in files:
        digits = "".join(c for c in f.stem if c.isdigit())
        n = int(digits) if digits else None
        if not out or prev is None or n is None or n != prev + 1:
            out.append([])
        out[-1].append(f)
        prev = n
    return [r for r in out if len(r) >= 3]


def clips(root: Path) -> tuple[dict[str, list[Path]], set[str]]:
    """The shots of the data, by name, and the names of the report split."""
    out: dict[str, list[Path]] = {}
    images = (".png", ".jpg")
    for kind in ("final", "clean"):
        for c in sorted((root / "sintel" / "training" / kind).glob("*")):
            for k, run in enumerate(_runs(sorted(c.glob("*.png")))):
                out[f"sintel-{kind}-{c.name}-{k}"] = run
    rw = sorted((root / "middlebury" / "other-data" / "RubberWhale").glob("frame*.png"))
    out["middlebury-RubberWhale"] = rw
    for group in ("ucf101", "middlebury"):
        for c in sorted((root / "interpolation" / group).glob("*")):
            fs = sorted(f for f in c.glob("*") if f.suffix in images)
            if len(fs) >= 3:
                out[f"interp-{group}-{c.name}"] = fs
    report = set()
    for c in sorted((root / "restoration").glob("*")):
        fs = sorted(c.glob("*.png"))[:40]
        parts = [fs[:30], fs[30:]] if c.name == "bikes" else [fs]  # a real cut at 29|30
        for k, part in enumerate(parts):
            name = f"restoration-{c.name}-{k}"
            out[name] = part
            report.add(name)
    return {k: v for k, v in out.items() if len(v) >= 3}, report


class _Frames:
    def __init__(self) -> None:
        self.cache: dict[Path, np.ndarray] = {}

    def __call__(self, f: Path) -> np.ndarray:
        if f not in self.cache:
            self.cache[f] = read_image(f)
        return self.cache[f]


def triples(shots: dict[str, list[Path]], names: list[str], frames: _Frames
            ) -> tuple[list[tuple[float, float, float]], list[tuple[float, float, float]]]:
    """``(score, previous, following)`` within shots, and at the joins of two shots."""
    within = []
    for n in names:
        t = [_thumb(frames(f)) for f in shots[n]]
        s = [_score(a, b) for a, b in zip(t, t[1:], strict=False)]
        within += [(s[i], s[i - 1], s[i + 1]) for i in range(1, len(s) - 1)]
    joins = []
    for a, b in itertools.permutations(names, 2):
        sa, sb = frames(shots[a][-1]).shape, frames(shots[b][0]).shape
        if len(sa) != len(sb) or sb[0] < sa[0] or sb[1] < sa[1]:
            continue
        y, x = (sb[0] - sa[0]) // 2, (sb[1] - sa[1]) // 2
        ta = [_thumb(frames(f)) for f in shots[a][-2:]]
        tb = [_thumb(frames(f)[y:y + sa[0], x:x + sa[1]]) for f in shots[b][:2]]
        joins.append((_score(ta[1], tb[0]), _score(ta[0], ta[1]), _score(tb[0], tb[1])))
    return within, joins


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("VARFLOW_DATA"))
    args = ap.parse_args()
    shots, report = clips(data_root(args.data))
    frames = _Frames()
    print("| split | shots | rule | false cuts (within shots) | cuts found (joins) |")
    print("|---|---:|---|---:|---:|")
    for split in ("tuning", "report"):
        names = sorted(n for n in shots if (n in report) == (split == "report"))
        within, joins = triples(shots, names, frames)
        for label, rule in (("max", rule_max), ("spike", rule_spike)):
            fp = sum(rule(*t) for t in within)
            tp = sum(rule(*t) for t in joins)
            print(f"| {split} | {len(names)} | {label} | {fp} / {len(within)} | "
                  f"{tp} / {len(joins)} |")


if __name__ == "__main__":
    main()
