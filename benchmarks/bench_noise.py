"""The noise estimate of :func:`varflow.estimate_noise` on the restoration clips.

The protocol of the denoising benchmark: the first 20 frames of each clip (frames
1-20 of Sintel alley_1 final, the 10 of sintel-demo), noise
``clean + numpy.random.default_rng(0).normal(0, σ, clean.shape)`` on float32 0-255
RGB, one draw for the whole stack, not clipped; and the same noise rounded and
clipped to uint8.  Prints the estimate (mean over the channels) against the true σ,
and the seconds per frame.

Run::

    python benchmarks/bench_noise.py [--data DIR] [--frames N]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from varflow.evaluation.datasets import data_root
from varflow.io import read_image
from varflow.restore import estimate_noise

SIGMAS = (10, 20, 30, 40, 50)


def clips(root, n: int) -> dict[str, np.ndarray]:
    """The clean clips, (F, H, W, 3) float32 on 0-255."""
    where = {name: root / "restoration" / name
             for name in ("bikes", "bigbuckbunny", "carphone", "sintel-demo")}
    where["alley_1"] = root / "sintel" / "training" / "final" / "alley_1"
    out = {}
    for name, path in where.items():
        files = sorted(path.glob("*.png"))
        files = files[1:n + 1] if name == "alley_1" else files[:n]
        out[name] = np.stack([read_image(f) for f in files]).astype(np.float32)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("VARFLOW_DATA"))
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args()
    head = " | ".join(f"σ {s}" for s in SIGMAS)
    print(f"| clip | noise | clean | {head} | worst error | s per frame |")
    print("|---|---|---:|" + "---:|" * len(SIGMAS) + "---:|---:|")
    for name, clean in clips(data_root(args.data), args.frames).items():
        base = estimate_noise(clean).sigma.mean()
        for kind in ("float", "uint8"):
            cells, worst, seconds = [], 0.0, []
            for s in SIGMAS:
                noisy = clean + np.random.default_rng(0).normal(0, s, clean.shape).astype(
                    np.float32)
                if kind == "uint8":
                    noisy = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
                t0 = time.perf_counter()
                est = float(estimate_noise(noisy).sigma.mean())
                seconds.append((time.perf_counter() - t0) / clean.shape[0])
                worst = max(worst, abs(est / s - 1))
                cells.append(f"{est:.2f}")
            print(f"| {name} {clean.shape[2]}×{clean.shape[1]} | {kind} | {base:.2f} | "
                  f"{' | '.join(cells)} | {100 * worst:.1f} % | {np.median(seconds):.3f} |")


if __name__ == "__main__":
    main()
