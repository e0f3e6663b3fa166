"""varflow's film-restoration stages against FFmpeg's filters, on planted archival defects.

For every clip and case (dirt, flicker, weave, all: dirt + flicker + weave + noise σ 8,
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

Run (the same as ``varflow bench restore``, which this script calls)::

    python benchmarks/bench_restore.py [--data DIR] [--clips bikes,carphone,...]
        [--cases dirt,flicker,weave,all] [--frames 12] [--crop HxW]
        [--methods varflow,ffmpeg,simple] [--csv OUT.csv] [--tune-ffmpeg] [-q]
"""

from __future__ import annotations

import sys

from varflow.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "restore", *sys.argv[1:]]))
