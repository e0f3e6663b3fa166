"""How far varflow's results move between two builds of its Numba kernels.

The kernels are compiled for the CPU they run on (``fastmath`` and the instruction
set decide the last bits of a sum).  This script computes a fixed set of results in
two child processes, one with the host build and one compiled for a generic x86-64
(``NUMBA_CPU_NAME=generic``), each with its own fresh ``NUMBA_CACHE_DIR`` warmed by a
process of its own first (so both load every kernel from the cache), and compares
them:

* every two-frame method on the 8 Middlebury pairs (frame10 -> frame11);
* ``rlr`` and ``mfsf`` (and the ``twoframe`` tracker) on photographic trajectory
  clips of the reporting split (one per family, 15 frames 128x160 by default) and on
  the fast-object clip of the tests;
* ``rlr`` on RubberWhale frames 7-14 (frame 10 the reference, frame 11 scored).

Per method it prints the mean score of each build (AEE against the ground truth),
the largest difference of that score over the cases, and the per-pixel difference
between the two builds' flows: its median over the cases of the 99th percentile and
its maximum, in pixels.

::

    python benchmarks/bench_reproducibility.py [--data DIR] [--methods tvl1,tensor,...]
        [--trackers rlr,mfsf,twoframe] [--frames 15] [--shape 128x160] [--no-middlebury]
        [--no-clips] [--keep DIR]

``--save FILE`` runs one build in this process (what each child does) and writes its
results to an ``.npz``; ``--compare A B`` compares two such files.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DEFAULT_METHODS = "tvl1,tvl1-fast,tvl1-ld,tensor,sparse-dct"
DEFAULT_TRACKERS = "rlr,mfsf,twoframe"


def _planes(traj: np.ndarray) -> np.ndarray:
    """A flow ``(H, W, 2)`` as it is, trajectories ``(F, H, W, 2)`` as ``(F·H, W, 2)``."""
    return traj.reshape(-1, *traj.shape[-2:])


def _child_args(args: argparse.Namespace) -> list[str]:
    """The options of this run that decide the result set, for the child processes."""
    out = ["--methods", args.methods, "--trackers", args.trackers,
           "--frames", str(args.frames), "--shape", args.shape]
    if args.data:
        out += ["--data", args.data]
    out += ["--no-middlebury"] * args.no_middlebury + ["--no-clips"] * args.no_clips
    return out


def warm(args: argparse.Namespace) -> None:
    """Compile every kernel of the set into the cache on small inputs.

    The process that compiles a kernel can differ in the last bits from the ones that
    load it from the cache, so each build is warmed in a process of its own first and
    the results come from a process that loads every kernel.
    """
    import varflow
    from varflow.generators.pairs import synthetic_pair

    f0, f1, _ = synthetic_pair("translation", shape=(48, 64), magnitude=1.0, seed=0)
    for m in args.methods.split(","):
        varflow.flow(f0, f1, m)
    frames = np.stack([f0, f1, f0, f1, f0])
    for m in args.trackers.split(","):
        varflow.track(frames, 2, m)
        varflow.track(frames, 2, m, **({"propagate_matching": True} if m == "rlr" else {}))


def save(path: str, args: argparse.Namespace) -> None:
    """Compute every result of the set in this process and write them to ``path``."""
    import varflow
    from varflow.evaluation.datasets import MIDDLEBURY_SEQUENCES, data_root, load_middlebury_pair

    out: dict[str, np.ndarray] = {}
    t0 = time.perf_counter()
    if not args.no_middlebury:
        root = data_root(args.data)
        for seq in MIDDLEBURY_SEQUENCES:
            f0, f1, out[f"gt/mdb/{seq}"] = load_middlebury_pair(seq, root)
            for m in args.methods.split(","):
                out[f"mdb/{m}/{seq}/flow"] = varflow.flow(f0, f1, m)
            print(f"  {seq} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    if not args.no_clips:
        from varflow.generators.photo import FAMILIES, make_photo_clip

        h, w = (int(v) for v in args.shape.split("x"))
        clips = []
        for fam in FAMILIES:
            c = make_photo_clip(fam, seed=100, n_frames=args.frames, shape=(h, w))
            clips.append((f"photo-{fam}", c.frames, c.trajectories, c.visibility, c.ref))
        from varflow.generators.large_pairs import fast_object_clip

        frames, traj, _, ref = fast_object_clip()
        clips.append(("fast-object", frames, traj, np.ones(traj.shape[:3], bool), ref))
        if not args.no_middlebury:
            from varflow.io import read_image

            seq = root / "middlebury" / "other-data" / "RubberWhale"
            frames = np.stack([read_image(seq / f"frame{k:02d}.png") for k in range(7, 15)])
            gt = load_middlebury_pair("RubberWhale", root)[2]
            traj = np.zeros(frames.shape[:3] + (2,), np.float32)
            traj[4] = gt  # frame10 (index 3) -> frame11: only this frame is scored
            vis = np.zeros(frames.shape[:3], bool)
            vis[4] = np.isfinite(gt[..., 0])
            clips.append(("rubberwhale", frames, traj, vis, 3))
        for name, frames, traj, vis, ref in clips:
            out[f"gt/clip/{name}"], out[f"mask/clip/{name}"] = traj, vis
            for m in args.trackers.split(","):
                if name == "rubberwhale" and m != "rlr":
                    continue
                out[f"clip/{m}/{name}/flow"] = varflow.track(frames, ref, m)
            print(f"  {name} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    tmp = path + ".tmp.npz"
    np.savez_compressed(tmp, **out)
    os.replace(tmp, path)


def compare(a_path: str, b_path: str, labels: tuple[str, str] = ("host", "generic")) -> str:
    """The table of differences between two ``--save`` files."""
    from varflow.evaluation.metrics import endpoint_error, endpoint_error_map

    a, b = np.load(a_path), np.load(b_path)
    groups: dict[tuple[str, str], list[str]] = {}
    for key in a.files:
        kind, method, case, what = (key.split("/") + [""])[:4]
        if what == "flow":
            groups.setdefault((kind, method), []).append(case)
    lines = [
        f"| set | method | cases | mean AEE {labels[0]} | mean AEE {labels[1]} "
        "| max abs. diff. of a case's AEE | median p99 px diff. | max px diff. |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for (kind, method), cases in groups.items():
        sa, sb, p99, pmax = [], [], [], []
        for case in cases:
            fa, fb = (_planes(f[f"{kind}/{method}/{case}/flow"]) for f in (a, b))
            gt = _planes(a[f"gt/{kind}/{case}"])
            mask = a[f"mask/{kind}/{case}"].reshape(gt.shape[:2]) if kind == "clip" else None
            sa.append(endpoint_error(fa, gt, mask))
            sb.append(endpoint_error(fb, gt, mask))
            d = endpoint_error_map(fa, fb)
            d = d[np.isfinite(d)]
            p99.append(float(np.percentile(d, 99)))
            pmax.append(float(d.max()))
        diff = max(abs(x - y) for x, y in zip(sa, sb, strict=True))
        lines.append(
            f"| {'Middlebury' if kind == 'mdb' else 'clips'} | {method} | {len(cases)} "
            f"| {np.mean(sa):.4f} | {np.mean(sb):.4f} | {diff:.4f} "
            f"| {np.median(p99):.4f} | {max(pmax):.3f} |"
        )
        if kind == "clip":
            for case, x, y, q in zip(cases, sa, sb, pmax, strict=True):
                lines.append(f"|  | {method}: {case} |  | {x:.4f} | {y:.4f} | {abs(x - y):.4f} "
                             f"|  | {q:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--methods", default=DEFAULT_METHODS)
    ap.add_argument("--trackers", default=DEFAULT_TRACKERS)
    ap.add_argument("--frames", type=int, default=15)
    ap.add_argument("--shape", default="128x160")
    ap.add_argument("--no-middlebury", action="store_true")
    ap.add_argument("--no-clips", action="store_true")
    ap.add_argument("--keep", default=None, help="folder for the two builds' .npz files")
    ap.add_argument("--save", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--warm", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--compare", nargs=2, default=None)
    args = ap.parse_args(argv)
    if args.warm:
        warm(args)
        return 0
    if args.save:
        save(args.save, args)
        return 0
    if args.compare:
        print(compare(*args.compare))
        return 0
    work = Path(args.keep or tempfile.mkdtemp(prefix="varflow-repro-"))
    work.mkdir(parents=True, exist_ok=True)
    passthrough = _child_args(args)
    files = {}
    for label, cpu in (("host", None), ("generic", "generic")):
        env = dict(os.environ)
        env.pop("NUMBA_CPU_NAME", None)
        if cpu:
            env["NUMBA_CPU_NAME"] = cpu
        env["NUMBA_CACHE_DIR"] = str(work / f"numba-{label}")
        files[label] = str(work / f"{label}.npz")
        t0 = time.perf_counter()
        print(f"{label} build ...", file=sys.stderr)
        subprocess.run([sys.executable, __file__, "--warm", *passthrough], env=env, check=True)
        subprocess.run([sys.executable, __file__, "--save", files[label], *passthrough],
                       env=env, check=True)
        print(f"{label} build: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    day = time.strftime("%Y-%m-%d")
    print(f"varflow results, host build against NUMBA_CPU_NAME=generic ({day})")
    print(compare(files["host"], files["generic"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
