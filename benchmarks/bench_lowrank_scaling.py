"""Scaling of the RLR low-rank step: linear-time PCP (l1 filtering) against exact PCP.

Usage::

    python benchmarks/bench_lowrank_scaling.py [--quick] [--repeats 3] [--frames 30]
        [--exact-budget 120] [--blas-threads K]

For N = 64², 128², 256², 512² pixels and F = 30 frames (``U`` of shape (60, N)) a
planted trajectory matrix is built: rank-4 trajectories (four smooth temporal curves
in ``t = (n − F//2) / F`` that vanish at the centre reference frame, each along a
random direction, mixed per pixel by smooth random coefficient fields of amplitude
up to 10) plus gross errors of ±[5, 15] px on 5 % of the entries outside the
reference frame's two rows.  Smooth temporal curves make the column space fairly
coherent: at the standard λ the PCP minimiser of the full matrix is then not exactly
the planted L0 (errors ~1e-3), while the seed PCP of the linear method, on a less
wide matrix, usually is — the error columns show it.  Then, with the standard λ = 1/sqrt(N):

* ``rpca_linear`` (default sample ``min(N, 20·2F)`` = 1200 columns) — median wall
  time over ``--repeats`` runs, microseconds per column, the ratio of that to the
  first size's per-column time, and the per-column time of the l1 filtering alone
  (warm start with the basis, median of the same number of runs);
* ``rpca_exact`` (full SVD per iteration) — one run, skipped ("skipped") when the
  time predicted from the smaller sizes exceeds ``--exact-budget`` seconds;
* the recovery error ``||L − L0||_F / ||L0||_F`` of each.

One warm-up call (Numba JIT compilation / cache loading) is excluded.  The last lines
state the goals: linear per-column time within 1.5x from the first to the last size,
and the exact solver's growth exponent ``log(t2/t1) / log(N2/N1)`` (> 1: super-linear).
``--quick`` runs 32² and 64² once each as a smoke test.  ``--blas-threads`` sets the
OpenBLAS/MKL/OpenMP thread counts before NumPy is imported (useful on a loaded machine
where multi-threaded BLAS can be far slower than one thread).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time


def _planted(side: int, frames: int, seed: int, rank: int = 4, frac: float = 0.05):
    """Planted ``(U, L0)`` float32 of shape (2F, side²); see the module docstring."""
    import numpy as np

    rng = np.random.default_rng(seed)
    ref = frames // 2
    t = (np.arange(frames) - ref) / frames
    curves = [t, np.sin(np.pi * t), 1.0 - np.cos(2 * np.pi * t), np.sin(3 * np.pi * t)]
    temporal = np.zeros((2 * frames, rank))
    for k, c in enumerate(curves[:rank]):  # each curve moves along a random direction
        ang = rng.uniform(0, 2 * np.pi)
        temporal[0::2, k] = np.cos(ang) * c
        temporal[1::2, k] = np.sin(ang) * c
    temporal /= np.linalg.norm(temporal, axis=0)
    yy, xx = np.mgrid[0:side, 0:side] / side
    coef = np.empty((rank, side * side))
    for k in range(rank):  # smooth random fields: three low-frequency plane waves
        field = np.zeros((side, side))
        for _ in range(3):
            fx, fy = rng.uniform(0.5, 3.0, 2)
            field += rng.normal() * np.cos(2 * np.pi * (fx * xx + fy * yy) + rng.uniform(0, 6.3))
        coef[k] = (10.0 * field / np.abs(field).max()).ravel()
    l0 = (temporal @ coef).astype(np.float32)
    mask = rng.random(l0.shape) < frac
    mask[2 * ref : 2 * ref + 2] = False  # the reference frame's displacement is exactly 0
    k = int(mask.sum())
    u = l0.copy()
    u[mask] += (rng.uniform(5, 15, k) * rng.choice([-1.0, 1.0], k)).astype(np.float32)
    return u, l0


def _median_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main(argv: list[str] | None = None) -> int:
    """Run the scaling benchmark and print the table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke run: 32², 64², 1 repeat")
    parser.add_argument("--repeats", type=int, default=3, help="runs of the linear solver")
    parser.add_argument("--frames", type=int, default=30, help="F (U has 2F rows)")
    parser.add_argument("--exact-budget", type=float, default=120.0,
                        help="skip rpca_exact when its predicted time exceeds this (s)")
    parser.add_argument("--blas-threads", type=int, default=None,
                        help="BLAS/OpenMP threads (set before NumPy is imported)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.blas_threads is not None:
        for var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
            os.environ[var] = str(args.blas_threads)

    import numba
    import numpy as np

    from varflow.multiframe.lowrank import rpca_exact, rpca_linear

    sides = [32, 64] if args.quick else [64, 128, 256, 512]
    repeats = 1 if args.quick else args.repeats
    rows = 2 * args.frames
    print(f"low-rank step scaling: U is ({rows}, N), planted rank 4 + 5% gross errors, "
          f"lambda = 1/sqrt(N)")
    print(f"numba threads: {numba.get_num_threads()}, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}, "
          f"linear: median of {repeats} run(s)")

    u_w, _ = _planted(32, args.frames, args.seed + 99)  # warm-up (JIT), not timed
    rpca_linear(u_w)

    header = (f"{'N':>9} {'linear s':>9} {'us/col':>8} {'ratio':>6} {'filter us/col':>13} "
              f"{'rank':>4} {'lin err':>9} {'exact s':>9} {'exact it':>8} {'exact err':>9}")
    print(header)
    print("-" * len(header))
    first_per_col = None
    exact_times: list[tuple[int, float]] = []
    per_cols: list[float] = []
    skip_exact = False
    for side in sides:
        n = side * side
        u, l0 = _planted(side, args.frames, args.seed + side)
        nrm = float(np.linalg.norm(l0))
        t_lin, (L, _, info) = _median_time(lambda u=u: rpca_linear(u, seed=args.seed), repeats)
        basis = info["basis"]
        t_fil, _ = _median_time(lambda u=u, b=basis: rpca_linear(u, basis=b), repeats)
        per_col = t_lin / n * 1e6
        per_cols.append(per_col)
        first_per_col = first_per_col or per_col
        lin_err = float(np.linalg.norm(L - l0)) / nrm
        del L
        if not skip_exact and exact_times:
            n2, t2 = exact_times[-1]
            p = 1.0  # growth exponent: from the last two sizes, at least linear
            if len(exact_times) >= 2:
                n1, t1 = exact_times[-2]
                p = max(1.0, math.log(t2 / t1) / math.log(n2 / n1))
            skip_exact = t2 * (n / n2) ** p > args.exact_budget
        if skip_exact:
            ex = f"{'skipped':>9} {'':>8} {'':>9}"
        else:
            t0 = time.perf_counter()
            Le, _, einfo = rpca_exact(u)
            t_ex = time.perf_counter() - t0
            exact_times.append((n, t_ex))
            ex_err = float(np.linalg.norm(Le - l0)) / nrm
            del Le
            ex = f"{t_ex:9.2f} {einfo['iterations']:8d} {ex_err:9.2e}"
        print(f"{f'{side}^2':>9} {t_lin:9.3f} {per_col:8.2f} {per_col / first_per_col:6.2f} "
              f"{t_fil / n * 1e6:13.2f} {info['rank']:4d} {lin_err:9.2e} {ex}", flush=True)

    ratio = per_cols[-1] / per_cols[0]
    print(f"\nlinear per-column time, {sides[-1]}^2 vs {sides[0]}^2: {ratio:.2f}x "
          f"(goal <= 1.5x: {'met' if ratio <= 1.5 else 'NOT met'})")
    if len(exact_times) >= 2:
        (n1, t1), (n2, t2) = exact_times[0], exact_times[-1]
        p = math.log(t2 / t1) / math.log(n2 / n1)
        kind = "super-linear" if p > 1.05 else "not super-linear"
        print(f"exact time growth exponent, N={n1} -> {n2}: {p:.2f} ({kind})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
