"""Memory and time of RLR on a long, Sintel-sized clip (default 50 frames, 1024×436).

Usage::

    python benchmarks/bench_rlr_size.py [--frames 50] [--height 436] [--width 1024]
        [--method rlr] [--scene nonrigid] [--quick]

Generates a seeded synthetic clip of the requested size (:func:`make_sequence`, the
nonrigid scene by default, colour), runs a trajectory method with its default
parameters and prints: wall time (total, per non-reference frame, initialisation /
U-step / L-step split for RLR), the peak resident memory of the process (the frames
included) and the mean trajectory EPE against the exact trajectories.  ``--quick``
runs 8 frames of 128×96 as a smoke test.  Time it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time


def _peak_rss_gib() -> float:
    # ru_maxrss is in KiB on Linux
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=50)
    ap.add_argument("--height", type=int, default=436)
    ap.add_argument("--width", type=int, default=1024)
    ap.add_argument("--method", default="rlr")
    ap.add_argument("--scene", default="nonrigid")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        args.frames, args.height, args.width = 8, 96, 128

    import numpy as np

    from varflow.evaluation.trajectory_metrics import trajectory_errors
    from varflow.generators.sequences import make_sequence
    from varflow.multiframe.track import check_frames
    from varflow.registry import get_tracker, make_track_params

    t0 = time.perf_counter()
    seq = make_sequence(args.scene, n_frames=args.frames, shape=(args.height, args.width),
                        seed=0)
    frames = check_frames(seq.frames)
    t_gen = time.perf_counter() - t0
    rss_data = _peak_rss_gib()
    tracker = get_tracker(args.method)
    params = make_track_params(args.method)
    # warm up the JIT on a tiny clip so that compilation is not timed
    small = make_sequence(args.scene, n_frames=4, shape=(48, 64), seed=1)
    tracker.track(check_frames(small.frames), small.ref, params, None)

    stats: dict = {}
    t1 = time.perf_counter()
    kwargs = {"stats": stats} if args.method in ("rlr", "mfsf") else {}
    traj = tracker.track(frames, seq.ref, params, None, **kwargs)
    wall = time.perf_counter() - t1
    err = trajectory_errors(traj, seq.trajectories, seq.visibility, ref=seq.ref)
    n_other = args.frames - 1
    print(f"{args.method} on {args.scene}: {args.frames} frames {args.width}x{args.height}, "
          f"colour, reference {seq.ref}")
    print("| quantity | value |")
    print("|---|---:|")
    print(f"| wall time, s | {wall:.1f} |")
    print(f"| wall time per non-reference frame, s | {wall / n_other:.2f} |")
    keys = ["init_seconds", "visibility_seconds", "ustep_seconds"]
    keys.append("lstep_seconds" if "lstep_seconds" in stats else "coupling_seconds")
    for key in keys:
        if key in stats:
            print(f"| {key.replace('_', ' ')} | {stats[key]:.1f} |")
    if "ranks" in stats and stats["ranks"]:
        print(f"| L-step ranks (last) | {stats['ranks'][-1]} |")
    print(f"| peak RSS after generating the frames, GiB | {rss_data:.2f} |")
    print(f"| peak RSS of the whole run, GiB | {_peak_rss_gib():.2f} |")
    print(f"| frames array, GiB | {frames.nbytes / 2**30:.2f} |")
    print(f"| mean trajectory EPE, px | {err['epe']:.4f} |")
    print(f"| sequence generation, s | {t_gen:.1f} |")
    print(f"| result finite | {bool(np.isfinite(traj).all())} |")
    if stats.get("visible") is not None:
        from varflow.evaluation.trajectory_metrics import occlusion_accuracy

        occ = occlusion_accuracy(stats["visible"], seq.visibility, seq.ref)
        print(f"| occlusion accuracy | {occ['accuracy']:.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
