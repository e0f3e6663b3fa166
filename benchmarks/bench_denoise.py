"""varflow's denoisers against the peers a user has, on the denoising protocol.

For every clip and σ: PSNR (mean over frames, output clipped to 0-255), SSIM
(scikit-image, 7x7 window), the temporal error (flicker) and seconds per frame of
varflow's restoration methods (``varflow.denoise``; the first of them, ``nlbayes``
when listed, also with σ estimated), of its per-frame variant (``radius=0``: no
motion), OpenCV's ``fastNlMeansDenoisingColoredMulti``, the flow average, and FFmpeg's
``atadenoise`` and ``fftdnoiz`` through PyAV, beside the noisy input and V-BM3D's
reference figures (``varflow.evaluation.denoising.VBM3D_REFERENCE``; on the
protocol's 20 uncropped frames only); then the means over the reporting clips.  The
same run as ``varflow bench denoise`` (``run_denoise_benchmark``).

``--cli-case`` adds the 8-bit case: the clean clip plus the same noise, rounded and
clipped to uint8, written to a lossless FFV1 .mkv, denoised by the command
``varflow denoise IN -o OUT.mkv --sigma 20`` in a subprocess and scored against the
clean frames (``run_cli_case``); ``--cli-only`` runs only that case.

Run::

    python benchmarks/bench_denoise.py [--data DIR] [--clips bikes,carphone,...]
        [--sigmas 10,30,50] [--frames 20] [--methods nlbayes,nlbayes-fast]
        [--peers opencv-nlm,flow-average,atadenoise,fftdnoiz,per-frame|all|none]
        [--crop HxW] [--no-estimated] [--csv OUT.csv] [--cli-case [--cli-clip carphone]
        [--cli-sigma 20] [--cli-method M] | --cli-only]
"""

from __future__ import annotations

import argparse
import os
import sys

from tqdm import tqdm

from varflow.evaluation.bench.common import write_csv
from varflow.evaluation.datasets import data_root
from varflow.evaluation.denoising import (
    DENOISE_CSV_FIELDS,
    DENOISE_PEERS,
    PROTOCOL_FRAMES,
    REPORTING_CLIPS,
    TUNING_CLIPS,
    format_cli_case,
    format_denoise_tables,
    run_cli_case,
    run_denoise_benchmark,
)


def _crop(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    h, w = (int(v) for v in text.lower().split("x"))
    return h, w


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("VARFLOW_DATA"))
    ap.add_argument("--clips", default=",".join((*TUNING_CLIPS, *REPORTING_CLIPS)))
    ap.add_argument("--sigmas", default="10,30,50")
    ap.add_argument("--frames", type=int, default=PROTOCOL_FRAMES)
    ap.add_argument("--methods", default=None, help="restoration methods (default all)")
    ap.add_argument("--peers", default="all", help=f"of {','.join(DENOISE_PEERS)}, all, none")
    ap.add_argument("--no-estimated", action="store_true",
                    help="skip the run of the first method with sigma estimated")
    ap.add_argument("--crop", default=None, metavar="HxW", help="top-left crop of the frames")
    ap.add_argument("--csv", default=None, help="also write the rows as CSV")
    ap.add_argument("--cli-case", action="store_true",
                    help="also run the 8-bit case through `varflow denoise`")
    ap.add_argument("--cli-only", action="store_true", help="only the 8-bit case")
    ap.add_argument("--cli-clip", default="carphone")
    ap.add_argument("--cli-sigma", type=float, default=20.0)
    ap.add_argument("--cli-method", default=None, help="--method of the command")
    args = ap.parse_args()
    root = data_root(args.data)
    crop = _crop(args.crop)
    if not args.cli_only:
        sigmas = [float(s) for s in args.sigmas.split(",")]
        with tqdm(total=None, desc="denoise", unit="run", file=sys.stderr,
                  leave=False) as bar:

            def progress(done: int, total: int) -> None:
                bar.total = total
                bar.update(done - bar.n)

            rows = run_denoise_benchmark(root, args.clips, sigmas, args.frames,
                                         args.methods, args.peers, crop=crop,
                                         estimated=not args.no_estimated,
                                         callback=progress)
        print(f"Denoising protocol, first {args.frames} frames"
              + (f", top-left {crop[0]}x{crop[1]}" if crop else "") + f"; data {root}")
        print()
        print(format_denoise_tables(rows), flush=True)
        if args.csv:
            write_csv(rows, args.csv, DENOISE_CSV_FIELDS)
            print(f"wrote {args.csv}")
    if args.cli_case or args.cli_only:
        case = run_cli_case(root, args.cli_clip, args.cli_sigma, args.frames, crop,
                            method=args.cli_method)
        print()
        print(format_cli_case(case))


if __name__ == "__main__":
    main()
