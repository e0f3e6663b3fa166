"""Fingerprints of every registered method's output: a refactoring must not move a bit.

Runs each registered method on a fixed small set of cases and prints, per case, a
SHA-256 of the output array (its float32 / uint8 bytes in C order, NaNs included):

* every two-frame method on two Middlebury pairs (frame10 -> frame11 of RubberWhale
  and Venus, a fixed 160 x 200 crop of each);
* every tracker on one short clip (RubberWhale frames 07-14, a 96 x 128 crop);
* every interpolator on two UCF101 triplets (frame1 from frame0 and frame2, t = 0.5);

each with its defaults, and a few with overrides routed the way users pass them: a
field of the method, a field of the composed two-frame energy, ``flow_method``,
a regulariser's field, a parameter object, and the same through a CLI flag (the
command run in this process, its output file read back).

The hashes depend on the CPU build of the Numba kernels (fast-math, instruction
set): compare two runs on one machine and one build only.  ``--save FILE`` writes
the table as JSON; ``--compare FILE`` prints it beside a saved one and exits 1 when
a hash differs.

::

    python benchmarks/bench_fingerprint.py [--data DIR] [--save FILE] [--compare FILE]
        [--only SUBSTRING]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

PAIRS = ("RubberWhale", "Venus")
PAIR_CROP = (slice(100, 260), slice(150, 350))  # 160 x 200 pixels
CLIP_CROP = (slice(140, 236), slice(200, 328))  # 96 x 128 pixels
TRIPLETS = ("01", "02")


def digest(a: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes (C order), first 16 hex digits."""
    a = np.ascontiguousarray(a)
    h = hashlib.sha256()
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())
    return h.hexdigest()[:16]


def _cases(root: Path, tmp: Path) -> list[tuple[str, Callable[[], np.ndarray]]]:
    import varflow
    from varflow.cli import main as cli
    from varflow.io import read_image
    from varflow.retime.methods import INTERPOLATORS

    cases: list[tuple[str, Callable[[], np.ndarray]]] = []
    mdb = root / "middlebury" / "other-data"
    pairs = {}
    for seq in PAIRS:
        f0 = read_image(mdb / seq / "frame10.png")[PAIR_CROP]
        f1 = read_image(mdb / seq / "frame11.png")[PAIR_CROP]
        pairs[seq] = (np.ascontiguousarray(f0), np.ascontiguousarray(f1))
    for name in sorted(varflow.METHODS):
        for seq, (f0, f1) in pairs.items():
            cases.append((f"flow {name} {seq}",
                          lambda f0=f0, f1=f1, name=name: varflow.flow(f0, f1, name)))
    f0, f1 = pairs["RubberWhale"]
    overrides = [
        ("tvl1", {"data_weight": 30.0}),             # a field of the energy
        ("tvl1", {"n_warps": 3, "grey": False}),     # pyramid + energy fields
        ("tvl1-ld", {"match_step": 6}),              # a field of the method
        ("tvl1-tensor", {"tensor_a": 1.0}),          # a field of the regulariser
        ("tensor", {"data_weight": 30.0}),
        ("sparse-1d", {"n_atoms": 200, "sparse_weight": 1.0}),
        ("tvl1-sparse-2d", {"patch_size": 8}),
    ]
    for name, kw in overrides:
        label = ",".join(f"{k}={v}" for k, v in kw.items())
        cases.append((f"flow {name} RubberWhale {label}",
                      lambda name=name, kw=kw: varflow.flow(f0, f1, name, **kw)))
    cases.append(("flow tvl1 RubberWhale params=make_params(n_warps=2)",
                  lambda: varflow.flow(f0, f1, params=varflow.make_params("tvl1", n_warps=2))))

    a, b = tmp / "a.png", tmp / "b.png"
    from varflow.io import write_image

    write_image(a, f0)
    write_image(b, f1)

    def cli_flow() -> np.ndarray:
        out = tmp / "cli.flo"
        code = cli(["flow", str(a), str(b), "-o", str(out), "--method", "tvl1",
                    "--data-weight", "30", "--no-grey", "-q"])
        assert code in (0, None), code
        return varflow.read_flo(out)

    cases.append(("cli flow --data-weight 30 --no-grey RubberWhale", cli_flow))

    seq = mdb / "RubberWhale"
    clip = np.stack([read_image(seq / f"frame{k:02d}.png")[CLIP_CROP] for k in range(7, 15)])
    clip = np.ascontiguousarray(clip)
    for name in sorted(varflow.TRACKERS):
        cases.append((f"track {name} RubberWhale8",
                      lambda name=name: varflow.track(clip, method=name)))
    tracks = [
        ("rlr", {"link_weight": 1.0}),            # a field of the tracker
        ("rlr", {"data_weight": 20.0}),           # a field of the composed energy
        ("mfsf", {"n_basis": 4, "huber": 0.0}),
        ("twoframe", {"flow_method": "tvl1-ld"}),
        ("chain", {"flow_method": "tvl1-fast", "data_weight": 20.0}),
    ]
    for name, kw in tracks:
        label = ",".join(f"{k}={v}" for k, v in kw.items())
        cases.append((f"track {name} RubberWhale8 {label}",
                      lambda name=name, kw=kw: varflow.track(clip, method=name, **kw)))
    cases.append(("track rlr visibility RubberWhale8",
                  lambda: varflow.track(clip, method="rlr", return_visibility=True)[1]))
    clipdir = tmp / "clip"
    clipdir.mkdir(exist_ok=True)
    for k, frame in enumerate(clip):
        write_image(clipdir / f"frame_{k:04d}.png", frame)

    def cli_track() -> np.ndarray:
        out = tmp / "cli.npz"
        code = cli(["track", str(clipdir), "-o", str(out), "--method", "twoframe",
                    "--flow-method", "tvl1-fast", "--data-weight", "20", "-q"])
        assert code in (0, None), code
        return varflow.read_trajectories(out)[0]

    cases.append(("cli track twoframe --flow-method tvl1-fast --data-weight 20", cli_track))

    ucf = root / "interpolation" / "ucf101"
    trip = {k: (read_image(ucf / k / "frame0.png"), read_image(ucf / k / "frame2.png"))
            for k in TRIPLETS}
    for name in sorted(INTERPOLATORS):
        for k, (i0, i2) in trip.items():
            cases.append((f"interpolate {name} ucf{k}",
                          lambda i0=i0, i2=i2, name=name: varflow.interpolate(i0, i2, 0.5, name)))
    i0, i2 = trip["01"]
    interps = [
        ("splat", {"data_weight": 30.0}),            # a field of the composed energy
        ("splat", {"flow_method": "tvl1"}),
        ("splat-fast", {"flow_method": "tvl1-ld", "match_scale": 1.0}),
        ("splat", {"splat_sharpness": 5.0}),         # a field of the method
        ("naive", {"flow_method": "tvl1-fast"}),
    ]
    for name, kw in interps:
        label = ",".join(f"{k}={v}" for k, v in kw.items())
        cases.append((f"interpolate {name} ucf01 {label}",
                      lambda name=name, kw=kw: varflow.interpolate(i0, i2, 0.5, name, **kw)))
    ia, ib = tmp / "i0.png", tmp / "i2.png"
    write_image(ia, i0)
    write_image(ib, i2)

    def cli_interp() -> np.ndarray:
        out = tmp / "mid.png"
        code = cli(["interpolate", str(ia), str(ib), "-o", str(out), "--method", "splat",
                    "--data-weight", "30", "-q"])
        assert code in (0, None), code
        return read_image(out)

    cases.append(("cli interpolate splat --data-weight 30 ucf01", cli_interp))
    return cases


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=None, help="benchmark data folder (default: VARFLOW_DATA "
                    "or ../shared/data)")
    ap.add_argument("--save", default=None, help="write the table as JSON")
    ap.add_argument("--compare", default=None, help="a saved JSON table to compare with")
    ap.add_argument("--only", default=None, help="run the cases whose label contains this")
    args = ap.parse_args(argv)

    from varflow.evaluation.datasets import data_root

    root = data_root(args.data)
    old = json.loads(Path(args.compare).read_text()) if args.compare else {}
    table: dict[str, str] = {}
    differ = 0
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        cases = _cases(root, Path(tmp))
        if args.only:
            cases = [c for c in cases if args.only in c[0]]
        width = max(len(label) for label, _ in cases)
        print(f"{'case':<{width}}  {'sha256[:16]':<16}  {'seconds':>7}"
              + ("  before            same" if old else ""))
        for label, run in cases:
            t = time.perf_counter()
            h = digest(np.asarray(run()))
            dt = time.perf_counter() - t
            table[label] = h
            line = f"{label:<{width}}  {h}  {dt:7.1f}"
            if old:
                before = old.get(label, "-")
                same = before == h
                differ += not same
                line += f"  {before:<16}  {'yes' if same else 'NO'}"
            print(line, flush=True)
    print(f"{len(table)} cases in {time.perf_counter() - t_all:.0f} s"
          + (f"; {differ} differ from {args.compare}" if old else ""))
    if args.save:
        Path(args.save).write_text(json.dumps(table, indent=1) + "\n")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
