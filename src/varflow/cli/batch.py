"""``varflow batch``: flow, trajectories, retiming, denoising or restoration of many
inputs on Dask.

Synopsis::

    varflow batch flow INPUT... -o OUT [--method M] [--stride S | --pairs FILE]
                       [--format flo|png] [--workers N] [--threads-per-worker T]
                       [--scheduler ADDRESS] [--zarr] [--overwrite] [--quiet]
                       [--<parameter> VALUE ...]
    varflow batch track INPUT... -o OUT --window F --overlap K [--method M]
                        [--workers N] [--threads-per-worker T] [--scheduler ADDRESS]
                        [--zarr] [--overwrite] [--quiet] [--<parameter> VALUE ...]
    varflow batch retime INPUT... -o OUT (--fps F | --slowmo K) [--method M]
                         [--input-fps R] [--format mkv|mp4|...] [--codec C]
                         [--workers N] [--threads-per-worker T] [--scheduler ADDRESS]
                         [--overwrite] [--quiet] [--<parameter> VALUE ...]
    varflow batch denoise INPUT... -o OUT [--sigma S] [--method M] [--input-fps R]
                          [--format mkv|mp4|...] [--codec C] [--no-scene-cuts]
                          [--workers N] [--threads-per-worker T] [--scheduler ADDRESS]
                          [--overwrite] [--quiet] [--<parameter> VALUE ...]
    varflow batch restore INPUT... -o OUT [--stabilise] [--deflicker] [--dirt]
                          [--denoise] [--sigma S] [--denoise-method M]
                          [--set STAGE.FIELD=VALUE ...] [--input-fps R]
                          [--format mkv|mp4|...] [--codec C] [--no-scene-cuts]
                          [--workers N] [--threads-per-worker T] [--scheduler ADDRESS]
                          [--overwrite] [--quiet]

The work is done by :mod:`varflow.batch` (one task per input for ``retime``,
``denoise`` and ``restore``).  Needs the ``batch`` extra (dask, distributed, zarr: ``pip install
"varflow[batch]"``); without it the command stops with one line naming the extra.

Exit status: 0 when every task is done, 1 when some input or task failed (after
all the others finished; the failures are listed on stderr and in the manifest),
2 on an error that stops the run before it starts (one line on stderr).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..registry import (
    METHODS,
    RESTORE,
    TRACKERS,
    get_method,
    get_tracker,
    make_params,
    make_track_params,
)
from ..retime.methods import (
    DEFAULT_INTERPOLATOR,
    INTERPOLATORS,
    get_interpolator,
    make_interp_params,
)
from ._common import (
    MissingExtraError,
    _add_param_flags,
    _collect_params,
    _own_params,
    _Parser,
    _Progress,
    chosen_methods,
    int_at_least,
    methods_epilog,
    rate_arg,
)
from .denoise import SIGMA_HELP, sigma_arg
from .denoise import resolve as resolve_denoise

__all__ = ["add_parser", "require_batch_extra"]

#: The packages of the ``batch`` extra (``pip install "varflow[batch]"``).
BATCH_EXTRA = ("dask", "distributed", "zarr")

_DESCRIPTION = (
    "Compute flow between frame pairs (flow), trajectories over windows of frames "
    "(track), retimed videos (retime), denoised videos (denoise) or restored videos "
    "(restore) for many inputs on "
    "Dask: a local cluster of "
    "--workers processes by default, or an existing scheduler.  INPUT is a video, a "
    "folder of frames, a folder of videos, a glob pattern or "
    "an input list (.txt/.lst/.list/.jsonl: one path or {\"path\": ..., \"name\": ...} "
    "per line); results go to OUT/<name>/ (retime, denoise, restore: OUT/<name>.<format>) "
    "with <name> the "
    "video's file name without extension or the folder's name (two inputs with one name "
    "are an error).  Every "
    "task is recorded in OUT/manifest.sqlite; running the same command again after an "
    "interruption computes only the unfinished tasks.  A run into an OUT made with other "
    "settings is refused unless --overwrite."
)


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _non_negative(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _rate_text(rate: Any) -> str | None:
    """An exact rate as ``"num/den"`` (recorded in the manifest), None for None."""
    return None if rate is None else f"{rate.numerator}/{rate.denominator}"


def require_batch_extra() -> None:
    """Fail with one line naming the ``batch`` extra when its packages are missing.

    Raises
    ------
    MissingExtraError
        When dask, distributed or zarr cannot be imported.
    """
    import importlib

    for name in BATCH_EXTRA:
        try:
            importlib.import_module(name)
        except ImportError:
            raise MissingExtraError(
                'varflow batch needs dask, distributed and zarr: pip install "varflow[batch]"'
            ) from None


def add_parser(sub: Any, common: argparse.ArgumentParser, argv: Sequence[str] | None) -> None:
    """Register ``varflow batch flow``, ``track``, ``retime`` and ``denoise``.

    The ``add_parser`` protocol of :mod:`varflow.cli` (its notes say what ``sub``,
    ``common`` and ``argv`` are).
    """
    p = sub.add_parser("batch", help="flow, trajectories, retiming or denoising of many videos "
                       "on Dask",
                       description=_DESCRIPTION)
    bsub = p.add_subparsers(dest="batch_kind", metavar="KIND", required=True,
                            parser_class=_Parser)
    shared = _Parser(add_help=False)
    shared.add_argument("inputs", nargs="+", metavar="INPUT",
                        help="videos, frame folders, glob patterns or input lists")
    shared.add_argument("-o", "--output", required=True, metavar="OUT",
                        help="output folder (created; holds OUT/<name>/ and manifest.sqlite)")
    g = shared.add_argument_group("cluster")
    g.add_argument("--workers", type=_positive, metavar="N",
                   help="worker processes of the local cluster (default: number of cores)")
    g.add_argument("--threads-per-worker", type=_positive, metavar="T",
                   help="tasks run at once per worker; Numba/BLAS/OpenCV pools of each "
                   "worker are limited to T threads (default 1)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="use an existing Dask scheduler (tcp://host:port) instead of a local "
                   "cluster; its workers must see the inputs and OUT at the same paths")
    shared.add_argument("--zarr", action="store_true",
                        help="also write OUT/<name>.zarr (one chunk per pair or window)")
    shared.add_argument("--overwrite", action="store_true",
                        help="discard the results of an earlier run in OUT (also one with "
                        "other settings) and start again")
    shared.add_argument("-q", "--quiet", action="store_true", help="no progress bar")

    f = bsub.add_parser("flow", parents=[common, shared],
                        help="flow for frame pairs: OUT/<name>/NNNNNN.flo",
                        description="Flow from frame N to frame N+S of every input (N "
                        "zero-based): OUT/<name>/NNNNNN.flo (or .png, KITTI 16-bit).  With "
                        "--pairs FILE (lines 'I J'), the listed pairs of every input: "
                        "OUT/<name>/IIIIII_JJJJJJ.flo.")
    f.add_argument("--method", default="tvl1", metavar="NAME",
                   help=f"one of: {', '.join(METHODS)} (default tvl1)")
    x = f.add_mutually_exclusive_group()
    x.add_argument("--stride", type=_positive, metavar="S",
                   help="frame gap of the pairs (default 1)")
    x.add_argument("--pairs", metavar="FILE",
                   help="text file of pairs 'I J' (zero-based frame indices), one per line")
    f.add_argument("--format", choices=("flo", "png"), default="flo",
                   help="output format: Middlebury .flo or KITTI 16-bit .png (default flo)")
    _add_param_flags(f, _collect_params(), METHODS, chosen_methods(argv, METHODS))
    f.set_defaults(func=_cmd_batch_flow)

    t = bsub.add_parser("track", parents=[common, shared],
                        help="trajectories over windows: OUT/<name>/window_SSSSSS.npz",
                        description="Trajectories of the centre frame's pixels over windows "
                        "of F frames overlapping by K (a last window ends at the last "
                        "frame): OUT/<name>/window_SSSSSS.npz (S = first frame), with "
                        "visibility and metadata (frames, reference, input, parameters).")
    t.add_argument("--window", type=_positive, required=True, metavar="F",
                   help="frames per window (>= 2)")
    t.add_argument("--overlap", type=_non_negative, required=True, metavar="K",
                   help="frames shared by consecutive windows (< F)")
    t.add_argument("--method", default="rlr", metavar="NAME",
                   help=f"one of: {', '.join(TRACKERS)} (default rlr)")
    _add_param_flags(t, _collect_params(TRACKERS), TRACKERS, chosen_methods(argv, TRACKERS))
    t.set_defaults(func=_cmd_batch_track)

    r = bsub.add_parser("retime", parents=[common, shared],
                        help="retimed videos: OUT/<name>.<format>",
                        description="Retime every input (a video or a folder of frames) to "
                        "a new frame rate (--fps) or to slow motion (--slowmo): one task per "
                        "input, written to OUT/<name>.<format> (as 'varflow retime', audio "
                        "copied when the duration is kept).")
    x = r.add_mutually_exclusive_group(required=True)
    x.add_argument("--fps", type=rate_arg, metavar="F",
                   help="output frame rate, e.g. 60 or 24000/1001")
    x.add_argument("--slowmo", type=int_at_least(2), metavar="K",
                   help="slow motion: K-1 new frames between every two (K >= 2)")
    r.add_argument("--method", default=DEFAULT_INTERPOLATOR, metavar="NAME",
                   help=f"one of: {', '.join(INTERPOLATORS)} (default {DEFAULT_INTERPOLATOR})")
    r.add_argument("--input-fps", type=rate_arg, metavar="R",
                   help="source frame rate (default: the video's own; 25 for a folder)")
    r.add_argument("--format", default="mkv", metavar="EXT",
                   help="output container: mkv (lossless FFV1, default), mp4, mov, avi, "
                   "webm or m4v")
    r.add_argument("--codec", metavar="C", help="FFmpeg encoder (default after the format)")
    _add_param_flags(r, _collect_params(INTERPOLATORS), INTERPOLATORS,
                     chosen_methods(argv, INTERPOLATORS))
    r.set_defaults(func=_cmd_batch_retime)

    d = bsub.add_parser("denoise", parents=[common, shared],
                        help="denoised videos: OUT/<name>.<format>",
                        description="Denoise every input (a video or a folder of frames) "
                        "with its motion: one task per input, written to OUT/<name>.<format> "
                        "(as 'varflow denoise': lossless where the container allows it, "
                        "audio copied, scene cuts not crossed; sigma estimated per input "
                        "unless --sigma).",
                        epilog=methods_epilog(RESTORE))
    d.add_argument("--sigma", type=sigma_arg, metavar="S", help=SIGMA_HELP)
    d.add_argument("--method", default=RESTORE.default, metavar="NAME",
                   help=f"one of: {', '.join(RESTORE)} (default {RESTORE.default})")
    d.add_argument("--input-fps", type=rate_arg, metavar="R",
                   help="source frame rate (default: the video's own; 25 for a folder)")
    d.add_argument("--format", default="mkv", metavar="EXT",
                   help="output container: mkv (lossless FFV1, default), mp4, mov, avi, "
                   "webm or m4v")
    d.add_argument("--codec", metavar="C",
                   help="FFmpeg encoder (default: lossless, after the format)")
    d.add_argument("--no-scene-cuts", dest="scene_cuts", action="store_false",
                   help="search patches across scene cuts too (one scene)")
    _add_param_flags(d, _collect_params(RESTORE), RESTORE, chosen_methods(argv, RESTORE))
    d.set_defaults(func=_cmd_batch_denoise)

    from .restore import add_chain_flags

    s = bsub.add_parser("restore", parents=[common, shared],
                        help="restored videos: OUT/<name>.<format>",
                        description="Restore every input (a video or a folder of frames) "
                        "as 'varflow restore' does: the stages named (all when none is: "
                        "stabilise, deflicker, dirt, denoise) in that order, one task per "
                        "input, written to OUT/<name>.<format> (lossless where the container "
                        "allows it, audio copied, scene cuts respected).")
    add_chain_flags(s)
    s.add_argument("--input-fps", type=rate_arg, metavar="R",
                   help="source frame rate (default: the video's own; 25 for a folder)")
    s.add_argument("--format", default="mkv", metavar="EXT",
                   help="output container: mkv (lossless FFV1, default), mp4, mov, avi, "
                   "webm or m4v")
    s.add_argument("--codec", metavar="C",
                   help="FFmpeg encoder (default: lossless, after the format)")
    s.add_argument("--no-scene-cuts", dest="scene_cuts", action="store_false",
                   help="one scene: stages look across scene cuts too")
    s.set_defaults(func=_cmd_batch_restore)


def _cmd_batch_flow(args: argparse.Namespace) -> int:
    require_batch_extra()
    from ..batch.plan import BatchConfig, read_pairs_file

    method = get_method(args.method)
    params = make_params(method, **_own_params(args, method, "method"))
    pairs = read_pairs_file(args.pairs) if args.pairs else None
    config = BatchConfig("flow", method.name, params, fmt=args.format,
                         stride=args.stride or 1, pairs=pairs)
    return _run(args, config)


def _cmd_batch_track(args: argparse.Namespace) -> int:
    require_batch_extra()
    from ..batch.plan import BatchConfig

    tracker = get_tracker(args.method)
    params = make_track_params(tracker, **_own_params(args, tracker, "trajectory method"))
    config = BatchConfig("track", tracker.name, params, fmt="npz", window=args.window,
                         overlap=args.overlap)
    return _run(args, config)


def _cmd_batch_retime(args: argparse.Namespace) -> int:
    require_batch_extra()
    from ..batch.plan import BatchConfig

    if args.zarr:
        raise ValueError("--zarr: not available for batch retime (its outputs are videos)")
    interp = get_interpolator(args.method)
    params = make_interp_params(interp, **_own_params(args, interp, "interpolation method"))
    config = BatchConfig("retime", interp.name, params, fmt=args.format.lower().lstrip("."),
                         fps=_rate_text(args.fps), slowmo=args.slowmo,
                         input_fps=_rate_text(args.input_fps), codec=args.codec)
    return _run(args, config)


def _cmd_batch_denoise(args: argparse.Namespace) -> int:
    require_batch_extra()
    from ..batch.plan import BatchConfig

    if args.zarr:
        raise ValueError("--zarr: not available for batch denoise (its outputs are videos)")
    entry, params = resolve_denoise(args)
    config = BatchConfig("denoise", entry.name, params, fmt=args.format.lower().lstrip("."),
                         input_fps=_rate_text(args.input_fps), codec=args.codec,
                         sigma=args.sigma, scene_cuts=args.scene_cuts)
    return _run(args, config)


def _cmd_batch_restore(args: argparse.Namespace) -> int:
    require_batch_extra()
    from ..batch.plan import BatchConfig
    from .restore import resolve_chain

    if args.zarr:
        raise ValueError("--zarr: not available for batch restore (its outputs are videos)")
    chain = resolve_chain(args)
    config = BatchConfig("restore", chain.label, chain, fmt=args.format.lower().lstrip("."),
                         input_fps=_rate_text(args.input_fps), codec=args.codec,
                         sigma=args.sigma, scene_cuts=args.scene_cuts)
    return _run(args, config)


_MAX_LISTED = 20


def _run(args: argparse.Namespace, config: Any) -> int:
    from ..batch.inputs import expand_inputs
    from ..batch.runner import run_batch

    if args.scheduler and (args.workers is not None or args.threads_per_worker is not None):
        raise ValueError("--workers/--threads-per-worker set up a local cluster; leave them "
                         "out with --scheduler")
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(20, "-o/--output: not a directory", str(out))
    inputs = expand_inputs(args.inputs)
    command = {k: v for k, v in vars(args).items() if k != "func"}
    unit = {"flow": "pair", "track": "window"}.get(config.kind, "video")
    with _Progress(f"batch {config.kind}", args.quiet, unit=unit) as progress:
        summary = run_batch(
            inputs, out, config,
            workers=args.workers,
            threads=args.threads_per_worker or 1,
            scheduler=args.scheduler,
            overwrite=args.overwrite,
            zarr=args.zarr,
            progress=progress,
            command=command,
        )
    for task_id, error in summary.failures[:_MAX_LISTED]:
        print(f"varflow: failed: {task_id}: {error}", file=sys.stderr)
    if len(summary.failures) > _MAX_LISTED:
        print(f"varflow: ... and {len(summary.failures) - _MAX_LISTED} more failures (see "
              f"{out / 'manifest.sqlite'})", file=sys.stderr)
    print(f"batch {config.kind}: {summary.total} tasks: {summary.done} done, "
          f"{summary.skipped} skipped, {summary.failed} failed; {summary.done} "
          f"{summary.unit} in {summary.seconds:.2f} s ({summary.throughput:.2f} "
          f"{summary.unit}/s) -> {out}")
    return 0 if summary.ok else 1
