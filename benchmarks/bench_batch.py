"""Throughput of ``varflow batch flow``: plain loop vs Dask clusters (pairs per second).

Usage::

    python benchmarks/bench_batch.py [--videos 20] [--frames 10] [--shape 240x320]
        [--method tvl1] [--workers 1,2,4] [--no-external] [--keep DIR] [--quick]

Generates ``--videos`` seeded lossless FFV1 videos (a blurred random texture moving
by one pixel per frame), then computes the flow of every consecutive pair with

* **loop** -- a plain Python loop in this process: for each pair, read its two
  frames (``read_frames(path, start, stop, step)``, as a batch task does), compute
  ``varflow.flow`` and write the ``.flo`` file; Numba limited to ``--loop-threads``
  threads (default 1); after one warm-up pair (JIT);
* **LocalCluster** -- :func:`varflow.batch.run_batch` with N single-threaded worker
  processes for every N in ``--workers`` (the time includes starting the cluster
  and the workers' JIT loading: what ``varflow batch flow`` costs end to end);
* **external** -- a ``dask scheduler`` and two ``dask worker --nthreads 1``
  processes on 127.0.0.1 started by this script (the time excludes starting them,
  includes the workers' first-task JIT loading).

Prints a Markdown table (setup, workers, pairs, seconds, pairs/s, speed-up vs the
loop) and checks that every setup wrote byte-identical files.  ``--quick`` runs a
tiny configuration (smoke test).  Measure on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def make_video(path: Path, n_frames: int, shape: tuple[int, int], seed: int) -> None:
    """A lossless FFV1 video: blurred random texture moving right by 1 px per frame."""
    from scipy.ndimage import uniform_filter

    from varflow.io.video import write_video

    h, w = shape
    rng = np.random.default_rng(seed)
    coarse = rng.random((h // 4 + 3, (w + n_frames) // 4 + 3, 3))
    texture = np.kron(coarse, np.ones((4, 4, 1)))
    texture = (255 * uniform_filter(texture, size=(5, 5, 1))).astype(np.uint8)
    write_video(path, (texture[2:2 + h, k:k + w] for k in range(n_frames)), 25,
                codec="ffv1", pix_fmt="bgr0")


def run_loop(videos: list[Path], out: Path, method: str, threads: int) -> tuple[int, float]:
    """The plain loop; returns (pairs, seconds)."""
    import numba

    import varflow
    from varflow.io.flo import write_flo
    from varflow.io.video import read_frames, video_info

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    warm = read_frames(videos[0], start=0, stop=2)
    varflow.flow(warm[0], warm[1], method)
    pairs = 0
    t0 = time.perf_counter()
    for v in videos:
        d = out / v.stem
        d.mkdir(parents=True, exist_ok=True)
        for n in range(video_info(v).n_frames - 1):
            f = read_frames(v, start=n, stop=n + 2)
            write_flo(d / f"{n:06d}.flo", varflow.flow(f[0], f[1], method))
            pairs += 1
    return pairs, time.perf_counter() - t0


def run_cluster(videos: list[Path], out: Path, method: str, workers: int | None,
                scheduler: str | None) -> tuple[int, float]:
    """``run_batch`` on a local cluster or an external scheduler; returns (pairs, seconds)."""
    from varflow.batch import BatchConfig, expand_inputs, run_batch
    from varflow.registry import get_method, make_params

    config = BatchConfig("flow", method, make_params(get_method(method)))
    inputs = expand_inputs([str(v) for v in videos])
    t0 = time.perf_counter()
    summary = run_batch(inputs, out, config, workers=workers, threads=1, scheduler=scheduler)
    seconds = time.perf_counter() - t0
    if not summary.ok or summary.done != summary.total:
        raise RuntimeError(f"batch run failed: {summary.failures[:3]}")
    return summary.done, seconds


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_external(n_workers: int, tmp: Path) -> tuple[str, list[subprocess.Popen]]:
    """Start a ``dask scheduler`` and ``n_workers`` single-threaded ``dask worker``."""
    from distributed import Client

    dask = shutil.which("dask") or "dask"
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env,
             "start_new_session": True}
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], **quiet)]
    for k in range(n_workers):
        procs.append(subprocess.Popen(
            [dask, "worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
             "--host", "127.0.0.1", "--local-directory", str(tmp / f"worker{k}")], **quiet))
    try:
        with Client(address, timeout="60s") as client:
            client.wait_for_workers(n_workers, timeout=120)
    except BaseException:
        stop_external(procs)
        raise
    return address, procs


def stop_external(procs: list[subprocess.Popen]) -> None:
    """Terminate the processes one by one, workers first (kill after 10 s)."""
    for p in reversed(procs):
        if p.poll() is None:
            p.terminate()
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=10)


def _files(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.glob("*/*.flo"))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--videos", type=int, default=20, help="number of videos (default 20)")
    ap.add_argument("--frames", type=int, default=10, help="frames per video (default 10)")
    ap.add_argument("--shape", default="240x320", help="frame size HxW (default 240x320)")
    ap.add_argument("--method", default="tvl1", help="two-frame method (default tvl1)")
    ap.add_argument("--workers", default="1,2,4",
                    help="LocalCluster sizes, comma-separated (default 1,2,4)")
    ap.add_argument("--loop-threads", type=int, default=1,
                    help="Numba threads of the plain loop (default 1)")
    ap.add_argument("--no-external", action="store_true",
                    help="skip the dask scheduler + 2 workers setup")
    ap.add_argument("--keep", metavar="DIR", help="work in DIR and keep the files")
    ap.add_argument("--quick", action="store_true",
                    help="tiny smoke configuration: 2 videos of 3 frames, 48x64, tvl1-fast, "
                    "workers 1,2")
    args = ap.parse_args(argv)
    if args.quick:
        args.videos, args.frames, args.shape = 2, 3, "48x64"
        args.method, args.workers = "tvl1-fast", "1,2"
    h, w = (int(x) for x in args.shape.lower().split("x"))
    sizes = [int(x) for x in args.workers.split(",") if x.strip()]

    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_batch_"))
    root.mkdir(parents=True, exist_ok=True)
    try:
        vdir = root / "videos"
        vdir.mkdir(exist_ok=True)
        videos = []
        for k in range(args.videos):
            v = vdir / f"video{k:03d}.mkv"
            if not v.exists():
                make_video(v, args.frames, (h, w), seed=k)
            videos.append(v)
        results: list[tuple[str, str, int, float]] = []
        outs: dict[str, Path] = {}

        out = root / "out_loop"
        shutil.rmtree(out, ignore_errors=True)
        pairs, seconds = run_loop(videos, out, args.method, args.loop_threads)
        results.append(("plain loop", f"1 process, {args.loop_threads} thread(s)", pairs,
                        seconds))
        outs["loop"] = out
        for n in sizes:
            out = root / f"out_local{n}"
            shutil.rmtree(out, ignore_errors=True)
            pairs, seconds = run_cluster(videos, out, args.method, n, None)
            results.append(("LocalCluster", f"{n} x 1 thread", pairs, seconds))
            outs[f"local{n}"] = out
        if not args.no_external:
            address, procs = start_external(2, root)
            try:
                out = root / "out_external"
                shutil.rmtree(out, ignore_errors=True)
                pairs, seconds = run_cluster(videos, out, args.method, None, address)
            finally:
                stop_external(procs)
            results.append(("dask scheduler + workers", "2 x 1 thread", pairs, seconds))
            outs["external"] = out

        reference = _files(outs["loop"])
        identical = all(_files(o) == reference for o in outs.values())
        base = results[0][2] / results[0][3]
        print(f"varflow batch flow: {args.videos} videos x {args.frames} frames, {w}x{h}, "
              f"method {args.method}, {os.cpu_count()} cores; outputs identical across "
              f"setups: {'yes' if identical else 'NO'}")
        print()
        print("| setup | workers | pairs | seconds | pairs/s | speed-up vs loop |")
        print("|---|---|---:|---:|---:|---:|")
        for setup, workers, pairs, seconds in results:
            rate = pairs / seconds
            print(f"| {setup} | {workers} | {pairs} | {seconds:.2f} | {rate:.2f} | "
                  f"{rate / base:.2f} |")
        return 0 if identical else 1
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
