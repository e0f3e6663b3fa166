"""What a user already has for a noisy clip, on the denoising protocol.

For every clip and σ: PSNR (mean over frames, output clipped to 0-255), the
temporal error (flicker) and seconds per frame of OpenCV's
``fastNlMeansDenoisingColoredMulti`` (5 frames, h = 0.5 σ) and of the simple use of
varflow (neighbours within ±2 frames warped by ``varflow.flow`` and averaged where
the forward-backward check agrees), beside the noisy input and V-BM3D's reference
figures (same noise, same frames; ``varflow.evaluation.denoising.VBM3D_REFERENCE``).

Run::

    python benchmarks/bench_denoise_peers.py [--data DIR] [--frames 20] [--sigmas 10,30,50]
        [--clips bikes,carphone,...] [--method tvl1]
"""

from __future__ import annotations

import argparse
import os
import time

from varflow.evaluation.datasets import data_root
from varflow.evaluation.denoising import (
    REPORTING_CLIPS,
    TUNING_CLIPS,
    VBM3D_REFERENCE,
    add_noise,
    clip_psnr,
    flow_average,
    opencv_nlm,
    protocol_clips,
    temporal_error,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("VARFLOW_DATA"))
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--sigmas", default="10,30,50")
    ap.add_argument("--clips", default=",".join((*TUNING_CLIPS, *REPORTING_CLIPS)))
    ap.add_argument("--method", default="tvl1", help="two-frame method of the flow average")
    args = ap.parse_args()
    sigmas = [int(s) for s in args.sigmas.split(",")]
    names = tuple(args.clips.split(","))
    clips = protocol_clips(data_root(args.data), args.frames, names)
    print("| clip | σ | noisy | OpenCV NLM | s/frame | flow average | s/frame | V-BM3D |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, clean in clips.items():
        for sigma in sigmas:
            noisy = add_noise(clean, sigma)
            t0 = time.perf_counter()
            nlm = opencv_nlm(noisy, sigma)
            t1 = time.perf_counter()
            avg = flow_average(noisy, radius=2, method=args.method)
            t2 = time.perf_counter()
            n = clean.shape[0]
            ref = VBM3D_REFERENCE[name][0].get(sigma)
            ref_text = f"{ref:.2f}" if ref is not None else "-"
            print(f"| {name} {clean.shape[2]}×{clean.shape[1]}, {n} frames | {sigma} | "
                  f"{clip_psnr(noisy, clean):.2f} | {clip_psnr(nlm, clean):.2f} "
                  f"(flicker {temporal_error(nlm, clean):.2f}) | {(t1 - t0) / n:.2f} | "
                  f"{clip_psnr(avg, clean):.2f} (flicker {temporal_error(avg, clean):.2f}) | "
                  f"{(t2 - t1) / n:.2f} | {ref_text} |", flush=True)


if __name__ == "__main__":
    main()
