"""varflow's film-restoration stages against FFmpeg's filters, on planted archival defects.

For every clip and case (dirt, flicker, weave, all: dirt + flicker + weave + noise σ 3,
planted by ``varflow.evaluation.defects`` with a seed per clip and case): PSNR over all
pixels, the 16 px-inset centre (weave, all), the blotched and the untouched pixels,
the precision and recall of remove_dirt's mask, the residual flicker, the residual
jitter (from stabilise's transforms, and by registering every output to the clean
frames) and seconds per frame of varflow's stage (remove_dirt, deflicker, stabilise;
for all: stabilise → deflicker → remove_dirt → denoise), FFmpeg's filter through PyAV
(tmedian, deflicker, deshake; for all the chain deshake,deflicker,tmedian,atadenoise)
and the simple use of varflow (a flow-compensated median; per-frame mean/deviation
matching); then the means over the reporting clips.  See
``varflow.evaluation.restoration``.

``--tune-ffmpeg`` first reruns the grid search of the FFmpeg chain on the tuning clips
(``tune_ffmpeg_chain``), prints its table and runs the chain with its choice.

Run::

    python benchmarks/bench_restore.py [--data DIR] [--clips bikes,carphone,...]
        [--cases dirt,flicker,weave,all] [--frames 12] [--crop HxW]
        [--methods varflow,ffmpeg,simple] [--csv OUT.csv] [--tune-ffmpeg]
"""

from __future__ import annotations

import argparse
import logging
import os
import sys

from tqdm import tqdm

from varflow.evaluation import restoration as rs
from varflow.evaluation.bench.common import write_csv
from varflow.evaluation.datasets import data_root
from varflow.evaluation.denoising import REPORTING_CLIPS, TUNING_CLIPS


def _crop(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    h, w = (int(v) for v in text.lower().split("x"))
    return h, w


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("VARFLOW_DATA"))
    ap.add_argument("--clips", default=",".join((*TUNING_CLIPS, *REPORTING_CLIPS)))
    ap.add_argument("--cases", default=",".join(rs.RESTORE_CASES))
    ap.add_argument("--frames", type=int, default=rs.RESTORE_FRAMES)
    ap.add_argument("--crop", default=None, metavar="HxW", help="top-left crop of the frames")
    ap.add_argument("--methods", default=",".join(rs.RESTORE_KINDS),
                    help="kinds (varflow, ffmpeg, simple) or method labels")
    ap.add_argument("--csv", default=None, help="also write the rows as CSV")
    ap.add_argument("--tune-ffmpeg", action="store_true",
                    help="rerun the FFmpeg chain's grid search on the tuning clips first")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    root = data_root(args.data)
    crop = _crop(args.crop)
    chain = None
    if args.tune_ffmpeg:
        with tqdm(total=None, desc="tune chain", unit="run", file=sys.stderr,
                  leave=False) as bar:

            def tuned(done: int, total: int) -> None:
                bar.total = total
                bar.update(done - bar.n)

            best, table = rs.tune_ffmpeg_chain(root, frames=args.frames, callback=tuned)
        print(rs.format_chain_tuning(table))
        print(f"\nchosen: {best}\n")
        chain = {k: best[k] for k in ("tmedian_radius", "atadenoise", "deflicker_size")}
    with tqdm(total=None, desc="restore", unit="run", file=sys.stderr, leave=False) as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        rows = rs.run_restore_benchmark(root, args.clips, args.cases, args.frames,
                                        args.methods, crop=crop, callback=progress,
                                        chain=chain)
    print(f"Film-restoration protocol, first {args.frames} frames"
          + (f", top-left {crop[0]}x{crop[1]}" if crop else "") + f"; data {root}")
    print()
    print(rs.format_restore_tables(rows), flush=True)
    if args.csv:
        write_csv(rows, args.csv, rs.RESTORE_CSV_FIELDS)
        print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
