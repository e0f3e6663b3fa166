"""``varflow bench``: the accuracy benchmarks (runners in :mod:`varflow.evaluation.bench`).

Synopsis::

    varflow bench middlebury [--data DIR] [--methods tvl1,...] [--sequences ...]
                             [--csv OUT.csv] [--quiet] [--<parameter> VALUE ...]
    varflow bench trajectories [--suite procedural|photo|both] [--methods ...] ...
    varflow bench middlebury-multiframe [--data DIR] [--methods rlr,twoframe,...]
                             [--sintel] [--csv OUT.csv] [--quiet] [--<parameter> VALUE ...]
    varflow bench twoframe [--sets photo,middlebury,sintel] [--split tuning|reporting|both]
                           [--families ...] [--methods tvl1,...]
                           [--peers deepflow,dis,dualtvl1,skimage|all|none]
                           [--photo-shape HxW] [--data DIR] [--csv OUT.csv] [--quiet]
                           [--<parameter> VALUE ...]
    varflow bench sintel-trajectories [--data DIR] [--methods twoframe,mfsf,rlr]
                             [--refs 5 6 ...] [--windows 9 13 19] [--no-whole]
                             [--crop Y0 Y1 X0 X1] [--no-rubberwhale] [--csv OUT.csv]
                             [--quiet] [--<parameter> VALUE ...]
    varflow bench interpolation [--sets middlebury,ucf101,sintel,sintel-x4]
                             [--split tuning|reporting|all] [--methods naive,...]
                             [--peers minterpolate,blend,repeat|all|none] [--max-cases N]
                             [--timing|--no-timing] [--timing-only] [--timing-repeats N]
                             [--no-per-case] [--data DIR] [--csv OUT.csv] [--quiet]
    varflow bench denoise [--data DIR] [--clips bikes,carphone,...] [--sigmas 10,30,50]
                          [--frames 20] [--methods nlbayes,nlbayes-fast]
                          [--peers opencv-nlm,flow-average,atadenoise,fftdnoiz,per-frame|all|none]
                          [--crop HxW] [--csv OUT.csv] [--quiet]
    varflow bench restore [--data DIR] [--clips bikes,carphone,...]
                          [--cases dirt,flicker,weave,all] [--frames 12] [--crop HxW]
                          [--methods varflow,ffmpeg,simple] [--tune-ffmpeg]
                          [--timing | --timing-only] [--csv OUT.csv] [--quiet]
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import Any

from ..registry import METHODS, TRACKERS, get_method, get_tracker
from ._common import (
    _add_param_flags,
    _check_output,
    _collect_params,
    _given_params,
    _params_note,
    _Parser,
    _Progress,
    _split_list,
    chosen_methods,
)

__all__ = ["add_parser"]


def add_parser(sub: Any, common: argparse.ArgumentParser, argv: Sequence[str] | None) -> None:
    """Register ``bench`` and its benchmarks.

    The ``add_parser`` protocol of :mod:`varflow.cli` (its notes say what ``sub``,
    ``common`` and ``argv`` are).
    """
    from ..evaluation.bench.multiframe_run import default_methods

    params = _collect_params()
    tparams = _collect_params(TRACKERS)
    p = sub.add_parser("bench", help="accuracy benchmarks", description="Accuracy benchmarks.")
    bsub = p.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True,
                            parser_class=_Parser)
    bench_common = _Parser(add_help=False)  # the options every benchmark has
    bench_common.add_argument("--csv", metavar="OUT.csv", help="also write the rows as CSV")
    bench_common.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    b = bsub.add_parser("middlebury", parents=[common, bench_common],
                        help="the 8 Middlebury sequences with public ground truth",
                        description="AEE/AAE/time per sequence and method (book Table 3.3 "
                        "layout).")
    b.add_argument("--data", metavar="DIR",
                   help="data folder (default $VARFLOW_DATA or ../shared/data)")
    b.add_argument("--methods", default="tvl1", metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(METHODS)} (default tvl1)")
    b.add_argument("--sequences", nargs="+", metavar="SEQ",
                   help="subset of the sequences (names, space or comma separated)")
    _add_param_flags(b, params, METHODS, chosen_methods(argv, METHODS))
    b.set_defaults(func=_cmd_bench_middlebury)

    from ..generators.photo import FAMILIES as PHOTO_FAMILIES

    b = bsub.add_parser("trajectories", parents=[common, bench_common],
                        help="trajectory methods on the procedural and photographic "
                        "synthetic clips",
                        description="Trajectory methods on clips with exact ground truth.  "
                        "The procedural suite: EPE / RMS per scene and variant (book Table "
                        "4.2 layout).  The photo suite (varflow.generators.photo, real "
                        "photographs under known motions): per split (tuning seeds 0-2, "
                        "reporting seeds 100-102) a line per family with EPE, far EPE (the "
                        "two frames at each end), TAP-Vid occlusion accuracy and hidden "
                        "recall of the estimated visibility, and seconds.  Without --suite, "
                        "the options given choose it: only procedural options (--frames, "
                        "--shape, --scenes, --variants) run the procedural suite, only photo "
                        "options (--splits, --families, --photo-frames, --photo-shape) the "
                        "photo suite, otherwise both.  --csv writes the rows of both with a "
                        "'suite' column (procedural rows: scene, variant, epe, rms, seconds; "
                        "photo rows: split, family, seed, epe, far_epe, rms, occ_accuracy, "
                        "hidden_recall, seconds).")
    b.add_argument("--suite", choices=("procedural", "photo", "both"), default=None,
                   help="which suite to run (default: both, unless only one suite's options "
                   "are given)")
    b.add_argument("--methods", default=",".join(default_methods()), metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(TRACKERS)}, each optionally "
                   "NAME:FIELD=VALUE (default %(default)s)")
    g = b.add_argument_group("procedural suite")
    g.add_argument("--frames", type=int, default=None, metavar="F", help="frames (default 30)")
    g.add_argument("--shape", default=None, metavar="HxW", help="frame size (default 96x128)")
    g.add_argument("--scenes", metavar="NAMES", help="subset: affine,nonrigid,layers")
    g.add_argument("--variants", metavar="NAMES",
                   help="subset: clean,gaussian,saltpepper,occluder")
    g = b.add_argument_group("photo suite")
    g.add_argument("--splits", metavar="NAMES",
                   help="comma-separated, from: tuning,reporting (default both)")
    g.add_argument("--families", metavar="NAMES",
                   help=f"comma-separated subset of: {','.join(PHOTO_FAMILIES)} (default all)")
    g.add_argument("--photo-frames", type=int, default=None, metavar="F",
                   help="frames per photo clip (default 31)")
    g.add_argument("--photo-shape", default=None, metavar="HxW",
                   help="photo clip size (default 192x256)")
    _add_param_flags(b, tparams, TRACKERS, chosen_methods(argv, TRACKERS))
    b.set_defaults(func=_cmd_bench_trajectories)

    from ..evaluation.bench.twoframe import DEFAULT_SETS as DEFAULT_SETS_TWOFRAME
    from ..evaluation.bench.twoframe import SETS as SETS_TWOFRAME
    from ..evaluation.peers import PEERS
    from ..generators.photo_pairs import FAMILIES as PAIR_FAMILIES

    b = bsub.add_parser("twoframe", parents=[common, bench_common],
                        help="two-frame methods and peers on photographic pairs, Middlebury "
                        "and MPI-Sintel",
                        description="Two-frame methods (and optional peers: OpenCV DeepFlow, "
                        "DIS, DualTVL1, scikit-image TV-L1) on three sets: the photographic "
                        "pairs of varflow.generators.photo_pairs (real photographs under "
                        "known motions of 3-15 px, exact flow and occlusion mask; tuning "
                        "seeds 0-2, reporting seeds 100-102), the 8 Middlebury pairs and the "
                        "MPI-Sintel pairs with ground truth under the data folder (marked "
                        "small / large motion).  Per pair and method: AEE over all pixels "
                        "with ground truth, AEE over the non-occluded ones and seconds; a "
                        "table per set with means, total seconds and ratios to DeepFlow "
                        "(when it runs, else the first method).  Peers whose library is "
                        "missing are reported as unavailable and skipped.")
    b.add_argument("--sets", default=",".join(DEFAULT_SETS_TWOFRAME), metavar="NAMES",
                   help=f"comma-separated, from: {','.join(SETS_TWOFRAME)} (default "
                   f"{','.join(DEFAULT_SETS_TWOFRAME)})")
    b.add_argument("--split", choices=("tuning", "reporting", "both"), default=None,
                   help="seeds of the photo pairs and the large-motion pairs (default "
                   "reporting)")
    b.add_argument("--families", metavar="NAMES",
                   help=f"photo pair families, comma-separated subset of: "
                   f"{','.join(PAIR_FAMILIES)} (default all)")
    b.add_argument("--photo-shape", default=None, metavar="HxW",
                   help="size of the photo pairs (default 256x320)")
    b.add_argument("--methods", default="tvl1", metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(METHODS)} (default tvl1; "
                   "empty to run peers only)")
    b.add_argument("--peers", default="none", metavar="NAMES",
                   help=f"comma-separated, from: {','.join(PEERS)}; or all, or none "
                   "(default none)")
    b.add_argument("--data", metavar="DIR",
                   help="data folder (default $VARFLOW_DATA or ../shared/data)")
    _add_param_flags(b, params, METHODS, chosen_methods(argv, METHODS))
    b.set_defaults(func=_cmd_bench_twoframe)

    from ..evaluation.bench.multiframe_run import default_methods

    mf_default = ",".join(default_methods())
    b = bsub.add_parser("middlebury-multiframe", parents=[common, bench_common],
                        help="trajectory methods on RubberWhale (8 frames), scored on "
                        "frame10 -> frame11",
                        description="Trajectory methods on Middlebury RubberWhale frame07-"
                        "frame14 with reference frame10: AEE/AAE of the frame11 displacement "
                        "against flow10.flo, next to the TV-L1 pair baseline; --sintel adds "
                        "the same report on the MPI-Sintel snippets.")
    b.add_argument("--data", metavar="DIR",
                   help="data folder (default $VARFLOW_DATA or ../shared/data)")
    b.add_argument("--methods", default=mf_default, metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(TRACKERS)}, each optionally "
                   f"NAME:FIELD=VALUE (default {mf_default})")
    b.add_argument("--sintel", action="store_true",
                   help="also report on the MPI-Sintel snippets found under the data folder")
    _add_param_flags(b, tparams, TRACKERS, chosen_methods(argv, TRACKERS))
    b.set_defaults(func=_cmd_bench_middlebury_multiframe)

    from ..evaluation.bench.sintel_protocol import (
        PROTOCOL_METHODS,
        PROTOCOL_REFS,
        PROTOCOL_WINDOWS,
    )

    st_default = ",".join(m for m in PROTOCOL_METHODS if m.split(":")[0] in TRACKERS)
    b = bsub.add_parser("sintel-trajectories", parents=[common, bench_common],
                        help="book Table 4.1 protocol on MPI-Sintel alley_1 (50 frames), "
                        "plus RubberWhale frame 11",
                        description="For every reference frame r and every window of the "
                        "50-frame MPI-Sintel final/alley_1 clip around r (centred as far as "
                        "the clip allows, plus the whole clip), every trajectory method "
                        "tracks r's pixels through the window; its frame r+1 displacement "
                        "is scored against flow/alley_1/frame_r.flo.  twoframe (TV-L1 r -> "
                        "r+1, independent of the window) runs once per reference.  Then "
                        "the RubberWhale frame-11 table.  At full resolution the default "
                        "run takes about an hour of 2 cores.")
    b.add_argument("--data", metavar="DIR",
                   help="data folder (default $VARFLOW_DATA or ../shared/data)")
    b.add_argument("--methods", default=st_default, metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(TRACKERS)}, each optionally "
                   f"NAME:FIELD=VALUE (default {st_default})")
    b.add_argument("--refs", nargs="+", type=int, default=list(PROTOCOL_REFS), metavar="R",
                   help="reference frame numbers, 1-based; each needs frame R+1 and "
                   "flow/alley_1/frame_R.flo (default "
                   f"{' '.join(map(str, PROTOCOL_REFS))})")
    b.add_argument("--windows", nargs="+", type=int, default=list(PROTOCOL_WINDOWS),
                   metavar="L", help="window lengths in frames, each >= 2 (default "
                   f"{' '.join(map(str, PROTOCOL_WINDOWS))})")
    b.add_argument("--no-whole", action="store_true",
                   help="skip the whole-clip window")
    b.add_argument("--crop", nargs=4, type=int, metavar=("Y0", "Y1", "X0", "X1"),
                   help="run on rows Y0:Y1, columns X0:X1 of the frames only (quick runs; "
                   "also applied to RubberWhale)")
    b.add_argument("--no-rubberwhale", action="store_true",
                   help="skip the RubberWhale frame-11 table")
    _add_param_flags(b, tparams, TRACKERS, chosen_methods(argv, TRACKERS))
    b.set_defaults(func=_cmd_bench_sintel_trajectories)

    from ..evaluation.interpolation_peers import INTERPOLATION_PEERS
    from ..evaluation.interpolation_sets import INTERPOLATION_SETS
    from ..retime.methods import INTERPOLATORS

    b = bsub.add_parser("interpolation", parents=[common, bench_common],
                        help="frame interpolation against the true in-between frame "
                        "(Middlebury, UCF101, MPI-Sintel), with FFmpeg minterpolate",
                        description="Interpolation methods (varflow.interpolate) and peers "
                        "(FFmpeg minterpolate via PyAV, blend, repeat) synthesise the frame "
                        "between two frames at the time of a true one and are scored against "
                        "it: "
                        "PSNR and SSIM, Baker et al.'s IE and NE, and MAE (the mean "
                        "absolute difference learned methods call 'IE'), all on 0-255.  Sets: "
                        "the 12 Middlebury interpolation sequences, 21 UCF101 triplets and "
                        "MPI-Sintel final/alley_1 (odd frames from their neighbours; methods "
                        "that use context get frames i-3 and i+3) and its x4 slow motion "
                        "(sintel-x4: frames c-2 and c+2 give c-1, c, c+1 at t = 1/4, 1/2, "
                        "3/4).  In each set the sorted cases (sintel-x4: groups) alternate "
                        "tuning (even positions) / reporting (odd).  Per set (and per t): "
                        "a per-case table and the means, the PSNR gain over minterpolate and "
                        "over naive, the cases won against minterpolate and median seconds; "
                        "then the seconds per 960x540 frame of every method and peer.")
    b.add_argument("--sets", default=",".join(INTERPOLATION_SETS), metavar="NAMES",
                   help=f"comma-separated, from: {','.join(INTERPOLATION_SETS)} (default all)")
    b.add_argument("--split", choices=("tuning", "reporting", "all"), default="reporting",
                   help="which cases of each set (default reporting)")
    b.add_argument("--methods", default=None, metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(INTERPOLATORS)} (default all "
                   "registered; empty to run peers only)")
    b.add_argument("--peers", default=",".join(INTERPOLATION_PEERS), metavar="NAMES",
                   help=f"comma-separated, from: {','.join(INTERPOLATION_PEERS)}; or all, or "
                   "none (default all)")
    b.add_argument("--max-cases", type=int, default=None, metavar="N",
                   help="only the first N cases of each set (quick runs)")
    b.add_argument("--timing", action=argparse.BooleanOptionalAction, default=True,
                   help="also time every method and peer on one pair at 960x540 (default on)")
    b.add_argument("--timing-only", action="store_true",
                   help="only the timing section, no cases")
    b.add_argument("--timing-repeats", type=int, default=3, metavar="N",
                   help="timed runs per method, after an untimed one; the median is "
                   "reported (default 3)")
    b.add_argument("--per-case", action=argparse.BooleanOptionalAction, default=True,
                   help="print the per-case tables (default on)")
    b.add_argument("--data", metavar="DIR",
                   help="data folder (default $VARFLOW_DATA or ../shared/data)")
    b.set_defaults(func=_cmd_bench_interpolation)

    from ..evaluation.denoising import (
        DENOISE_PEERS,
        PROTOCOL_FRAMES,
        REPORTING_CLIPS,
        TUNING_CLIPS,
    )
    from ..registry import RESTORE

    b = bsub.add_parser("denoise", parents=[common, bench_common],
                        help="video denoising on the restoration clips against OpenCV NLM, "
                        "FFmpeg's atadenoise and fftdnoiz, and V-BM3D's figures",
                        description="The denoising protocol: white Gaussian noise of "
                        "standard deviation sigma (0-255, seed 0, not clipped) on the first "
                        "frames of each clip, sigma given to every denoiser.  Runs the "
                        "restoration methods (varflow.denoise), the first of them (nlbayes "
                        "when listed) once more with sigma estimated, and the peers: OpenCV's "
                        "multi-frame NL-means, the flow average (neighbours warped by tvl1 "
                        "flows and averaged), FFmpeg's atadenoise and fftdnoiz through PyAV "
                        "(8-bit input) and per-frame (that method with radius 0: no motion). "
                        "Per clip, sigma and method: PSNR (dB, output clipped to 0-255), "
                        "SSIM, temporal error (the flicker added), seconds per frame and "
                        "their ratio to OpenCV NLM's, beside V-BM3D's reference PSNR (runs "
                        "of the protocol's frames only); then the means over the reporting "
                        f"clips.  Tuning clips: {', '.join(TUNING_CLIPS)}; reporting clips: "
                        f"{', '.join(REPORTING_CLIPS)}.")
    b.add_argument("--clips", default=",".join((*TUNING_CLIPS, *REPORTING_CLIPS)),
                   metavar="NAMES", help="comma-separated, from: "
                   f"{','.join((*TUNING_CLIPS, *REPORTING_CLIPS))} (default all)")
    b.add_argument("--sigmas", default="10,30,50", metavar="S,...",
                   help="noise levels on 0-255, comma-separated (default 10,30,50: those of "
                   "V-BM3D's reference)")
    b.add_argument("--frames", type=int, default=PROTOCOL_FRAMES, metavar="F",
                   help=f"frames from the start of each clip, at least 2 (default "
                   f"{PROTOCOL_FRAMES}; sintel-demo has 10)")
    b.add_argument("--methods", default=None, metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(RESTORE.names())} (default all; "
                   "empty to run peers only)")
    b.add_argument("--peers", default="all", metavar="NAMES",
                   help=f"comma-separated, from: {','.join(DENOISE_PEERS)}; or all, or none "
                   "(default all)")
    b.add_argument("--crop", default=None, metavar="HxW",
                   help="keep the top-left HxW of every frame (quick runs)")
    b.add_argument("--data", metavar="DIR",
                   help="data folder (default $VARFLOW_DATA or ../shared/data)")
    b.set_defaults(func=_cmd_bench_denoise)

    from ..evaluation.restoration import RESTORE_CASES, RESTORE_FRAMES, RESTORE_KINDS

    b = bsub.add_parser("restore", parents=[common, bench_common],
                        help="archival defects (dirt, flicker, weave, all) planted in the "
                        "restoration clips, against FFmpeg's tmedian, deflicker, deshake "
                        "and a tuned FFmpeg chain",
                        description="The film-restoration protocol: seeded defects "
                        "(varflow.evaluation.defects) planted in the first frames of each "
                        "clean clip; varflow's stage for each case (remove_dirt, deflicker, "
                        "stabilise; for all: the whole chain with denoising), FFmpeg's "
                        "filters through PyAV and the simple uses of varflow, each scored "
                        "against the clean clip: PSNR over all, blotched and untouched "
                        "pixels, mask precision and recall, residual flicker and jitter, "
                        "seconds per frame; then the means over the reporting clips.  "
                        f"Tuning clips: {', '.join(TUNING_CLIPS)}; reporting clips: "
                        f"{', '.join(REPORTING_CLIPS)}.")
    b.add_argument("--clips", default=",".join((*TUNING_CLIPS, *REPORTING_CLIPS)),
                   metavar="NAMES", help="comma-separated, from: "
                   f"{','.join((*TUNING_CLIPS, *REPORTING_CLIPS))} (default all)")
    b.add_argument("--cases", default=",".join(RESTORE_CASES), metavar="NAMES",
                   help=f"comma-separated, from: {','.join(RESTORE_CASES)} (default all)")
    b.add_argument("--frames", type=int, default=RESTORE_FRAMES, metavar="F",
                   help=f"frames from the start of each clip, at least 3 (default "
                   f"{RESTORE_FRAMES})")
    b.add_argument("--methods", default=",".join(RESTORE_KINDS), metavar="NAMES",
                   help=f"kinds ({','.join(RESTORE_KINDS)}) or method labels (default all)")
    b.add_argument("--crop", default=None, metavar="HxW",
                   help="keep the top-left HxW of every frame (quick runs)")
    b.add_argument("--tune-ffmpeg", action="store_true",
                   help="first rerun the FFmpeg chain's grid search on the tuning clips and "
                   "use its choice")
    b.add_argument("--timing", action="store_true",
                   help="also time the streamed chain stabilise + deflicker + dirt on the "
                   "first 24 frames of bigbuckbunny (960x540) against one default "
                   "varflow.flow on a pair of them")
    b.add_argument("--timing-only", action="store_true",
                   help="only that timing")
    b.add_argument("--data", metavar="DIR",
                   help="data folder (default $VARFLOW_DATA or ../shared/data)")
    b.set_defaults(func=_cmd_bench_restore)


def _checked_methods(value: str, lookup, what: str) -> list[str]:
    """The ``--methods`` list, each name checked by ``lookup`` (one-line errors).

    Trajectory methods may be specs, ``NAME:FIELD=VALUE`` (e.g. ``rlr:link_weight=0``,
    ``twoframe:tvl1-ld``; :func:`varflow.evaluation.bench.common.method_spec`).
    """
    from varflow.evaluation.bench.common import method_spec

    methods = _split_list(value)
    if not methods:
        raise ValueError(f"--methods: give at least one {what} name")
    for m in methods:
        if lookup is get_tracker:
            method_spec(m, TRACKERS)
        elif ":" in m:
            raise ValueError(f"--methods: {m!r}: NAME:FIELD=VALUE specs are for trajectory "
                             "methods; give the fields as --<parameter> flags")
        else:
            lookup(m)
    return methods


def _write_rows(rows: list, csv_path) -> None:
    """Write benchmark rows to ``--csv`` when one was given."""
    from varflow.evaluation.bench.common import write_csv

    if csv_path is not None:
        write_csv(rows, csv_path)
        print(f"wrote {csv_path}")


def _cmd_bench_middlebury(args: argparse.Namespace) -> int:
    from varflow.evaluation.bench.middlebury import format_table, run_middlebury
    from varflow.evaluation.datasets import data_root

    methods = _checked_methods(args.methods, get_method, "method")
    sequences = None
    if args.sequences:
        sequences = [s for item in args.sequences for s in _split_list(item)]
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    root = data_root(args.data)
    overrides = _given_params(args)
    rows = run_middlebury(methods, root=root, sequences=sequences,
                          overrides=overrides, progress=not args.quiet)
    print(f"Middlebury frame10 -> frame11, data {root}; seconds exclude JIT warm-up"
          f"{_params_note(overrides)}")
    print(format_table(rows))
    _write_rows(rows, csv_path)
    return 0


def _cmd_bench_trajectories(args: argparse.Namespace) -> int:
    from varflow.evaluation.bench.trajectories import (
        PHOTO_SPLITS,
        check_photo_options,
        format_photo_table,
        format_trajectory_table,
        run_photo_trajectories,
        run_trajectories,
    )
    from varflow.generators.photo import FAMILIES

    procedural_options = ("frames", "shape", "scenes", "variants")
    photo_options = ("splits", "families", "photo_frames", "photo_shape")

    def flag(name: str) -> str:
        return "--" + name.replace("_", "-")

    def parse_hw(text: str, option: str, example: str) -> tuple[int, int]:
        try:
            h, w = (int(v) for v in text.lower().split("x"))
        except ValueError:
            raise ValueError(f"{option}: expected HxW, e.g. {example}, got {text!r}") from None
        return h, w

    given = {name for name in (*procedural_options, *photo_options)
             if getattr(args, name) is not None}
    suite = args.suite
    if suite is None:  # implied by the suite-specific options given, else both
        proc = any(n in given for n in procedural_options)
        photo = any(n in given for n in photo_options)
        suite = "procedural" if proc and not photo else "photo" if photo and not proc else "both"
    for names, wanted in ((procedural_options, "procedural"), (photo_options, "photo")):
        for n in names:
            if n in given and suite not in (wanted, "both"):
                raise ValueError(f"{flag(n)}: an option of the {wanted} suite, which "
                                 f"--suite {suite} does not run")
    run_proc = suite in ("procedural", "both")
    run_photo = suite in ("photo", "both")

    methods = _checked_methods(args.methods, get_tracker, "trajectory method")
    frames = 30 if args.frames is None else args.frames
    h, w = parse_hw("96x128" if args.shape is None else args.shape, "--shape", "96x128")
    kw = {}
    if args.scenes:
        kw["scenes"] = _split_list(args.scenes)
    if args.variants:
        kw["variants"] = _split_list(args.variants)
    photo_frames = 31 if args.photo_frames is None else args.photo_frames
    photo_shape = parse_hw("192x256" if args.photo_shape is None else args.photo_shape,
                           "--photo-shape", "192x256")
    splits = list(PHOTO_SPLITS) if args.splits is None else _split_list(args.splits)
    families = list(FAMILIES) if args.families is None else _split_list(args.families)
    if run_photo:  # fail before any run
        try:
            splits, families, photo_frames, photo_shape = check_photo_options(
                splits, families, photo_frames, photo_shape)
        except ValueError as exc:
            arg, _, rest = str(exc).partition(":")
            names = {"splits": "--splits", "families": "--families",
                     "n_frames": "--photo-frames", "shape": "--photo-shape"}
            raise ValueError(f"{names.get(arg, arg)}:{rest}") from None
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    overrides = _given_params(args)
    rows: list[dict[str, Any]] = []
    if run_proc:
        prows = run_trajectories(methods, n_frames=frames, shape=(h, w),
                                 overrides=overrides, progress=not args.quiet, **kw)
        print(f"procedural suite: synthetic sequences, {frames} frames {w}x{h}, reference = "
              f"centre; EPE / RMS in pixels over visible points of all frames but the "
              f"reference{_params_note(overrides)}")
        print(format_trajectory_table(prows))
        rows += [{"suite": "procedural", **r} for r in prows]
    if run_photo:
        qrows = run_photo_trajectories(methods, splits=splits, families=families,
                                       n_frames=photo_frames, shape=photo_shape,
                                       overrides=overrides, progress=not args.quiet)
        if run_proc:
            print()
        ph, pw = photo_shape
        print(f"photo suite: clips of real photographs (varflow.generators.photo), "
              f"{photo_frames} frames {pw}x{ph}, reference = centre; per family the mean over "
              f"the split's seeds.  EPE in pixels over visible points of all frames but the "
              f"reference; far EPE: mean per-frame EPE of the two frames at each end (0, 1, "
              f"F-2, F-1); occ acc: TAP-Vid occlusion accuracy (share of (pixel, frame) pairs, "
              f"reference excluded, with the right visible/hidden label); hidden rec: share of "
              f"the hidden pairs labelled hidden; s: seconds per clip with the visibility "
              f"estimate, JIT warm-up excluded{_params_note(overrides)}")
        print(format_photo_table(qrows))
        rows += [{"suite": "photo", **r} for r in qrows]
    _write_rows(rows, csv_path)
    return 0


def _cmd_bench_twoframe(args: argparse.Namespace) -> int:
    from varflow.evaluation.bench.twoframe import (
        PHOTO_FAMILIES,
        SETS,
        check_twoframe_data,
        check_twoframe_options,
        format_twoframe_table,
        resolve_peers,
        run_twoframe,
        write_twoframe_csv,
    )
    from varflow.evaluation.datasets import data_root
    from varflow.evaluation.peers import peer_threads

    def option(exc: ValueError) -> ValueError:  # "sets: ..." -> "--sets: ..."
        arg, _, rest = str(exc).partition(":")
        names = {"sets": "--sets", "split": "--split", "families": "--families",
                 "photo_shape": "--photo-shape", "peers": "--peers", "methods": "--methods"}
        return ValueError(f"{names.get(arg, arg)}:{rest}")

    shape = (256, 320)
    if args.photo_shape is not None:
        try:
            shape = tuple(int(v) for v in args.photo_shape.lower().split("x"))
            if len(shape) != 2:
                raise ValueError
        except ValueError:
            raise ValueError(f"--photo-shape: expected HxW, e.g. 256x320, got "
                             f"{args.photo_shape!r}") from None
    try:
        sets, _, families, shape = check_twoframe_options(
            args.sets, args.split or "reporting", args.families or list(PHOTO_FAMILIES), shape)
        peers, unavailable = resolve_peers(args.peers)
    except ValueError as exc:
        raise option(exc) from None
    if "photo" not in sets:
        for name in ("split", "families", "photo_shape"):
            if name == "split" and "large" in sets:
                continue
            if getattr(args, name) is not None:
                flag = "--" + name.replace("_", "-")
                raise ValueError(f"{flag}: only used by the photo (and large) sets, which --sets "
                                 f"{','.join(sets)} does not include")
    methods = _split_list(args.methods)
    for m in methods:
        get_method(m)
    if not methods and not peers:
        raise ValueError("--methods: give at least one method or an available peer")
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    root = data_root(args.data)
    overrides = _given_params(args)
    if overrides and not methods:
        raise ValueError("method parameters given but no --methods to apply them to")
    missing_sintel = check_twoframe_data(sets, root)  # before any run

    try:
        import numba

        numba_threads: Any = numba.get_num_threads()
    except ImportError:  # pragma: no cover - numba is a dependency
        numba_threads = "?"
    cv_threads = peer_threads()
    print(f"Two-frame benchmark ({', '.join(s for s in SETS if s in sets)}): AEE in px over "
          f"all pixels with ground truth, noc over the non-occluded ones (photo pairs: "
          f"visible in frame 1; Sintel: its occlusion mask), s: seconds per pair, JIT "
          f"warm-up excluded; Numba threads {numba_threads}"
          + (f", OpenCV threads {cv_threads}" if peers and cv_threads is not None else "")
          + (f"; data {root}" if {"middlebury", "sintel", "sintel-large"} & set(sets) else "")
          + _params_note(overrides))
    for p, reason in unavailable.items():
        print(f"peer {p} unavailable: {reason}")
    for clip, pass_, n in missing_sintel:
        print(f"Sintel {clip} {pass_} {n}->{n + 1} not found; skipped")
    rows: list[dict[str, Any]] = []
    first = True
    for s in sets:  # one table per set as soon as it is done
        srows = run_twoframe(methods, peers=peers, sets=[s], split=args.split or "reporting",
                             families=families, root=root, photo_shape=shape,
                             overrides=overrides, progress=not args.quiet, warm_up=first)
        first = False
        print()
        print(format_twoframe_table(srows))
        rows += srows
    if csv_path is not None:
        write_twoframe_csv(rows, csv_path)
        print(f"wrote {csv_path}")
    return 0


def _cmd_bench_middlebury_multiframe(args: argparse.Namespace) -> int:
    from varflow.evaluation.bench.multiframe_data import sintel_snippets
    from varflow.evaluation.bench.multiframe_run import (
        run_middlebury_multiframe,
        run_sintel_multiframe,
    )
    from varflow.evaluation.bench.multiframe_tables import format_multiframe_table
    from varflow.evaluation.datasets import DATA_HINT, data_root

    methods = _checked_methods(args.methods, get_tracker, "trajectory method")
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    root = data_root(args.data)
    overrides = _given_params(args)
    snippets = None
    if args.sintel:  # fail before the Middlebury runs when Sintel is missing
        snippets = sintel_snippets(root)
        if not snippets:
            raise FileNotFoundError(
                f"no Sintel snippet with ground truth under {root / 'sintel' / 'training'}; "
                f"{DATA_HINT}"
            )
    rows = run_middlebury_multiframe(methods, overrides, progress=not args.quiet, root=root)
    print(f"Middlebury RubberWhale frame07-frame14, reference frame10, scored on frame10 -> "
          f"frame11 (known pixels), data {root}; seconds exclude JIT warm-up"
          f"{_params_note(overrides)}")
    print(format_multiframe_table(rows))
    if snippets is not None:
        srows = run_sintel_multiframe(methods, overrides, progress=not args.quiet, root=root,
                                      snippets=snippets, warm_up=False)
        print()
        print("MPI-Sintel snippets, reference = the frame with ground truth (and occlusion "
              "mask), scored on reference -> next frame; AEE over valid pixels, AEE noc "
              f"over non-occluded ones (report only){_params_note(overrides)}")
        print(format_multiframe_table(srows))
        rows = rows + srows
    _write_rows(rows, csv_path)
    return 0


def _cmd_bench_sintel_trajectories(args: argparse.Namespace) -> int:
    from varflow.evaluation.bench.multiframe_data import load_rubberwhale_clip
    from varflow.evaluation.bench.multiframe_run import run_middlebury_multiframe
    from varflow.evaluation.bench.multiframe_tables import (
        format_multiframe_table,
        format_protocol_table,
    )
    from varflow.evaluation.bench.sintel_protocol import (
        PROTOCOL_CLIP,
        PROTOCOL_PASS,
        plan_sintel_protocol,
        run_sintel_trajectories,
        sintel_clip_numbers,
    )
    from varflow.evaluation.datasets import data_root

    methods = _checked_methods(args.methods, get_tracker, "trajectory method")
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    root = data_root(args.data)
    overrides = _given_params(args)
    crop = tuple(args.crop) if args.crop else None
    # fail before the long run: bad references or windows, missing data
    plan = plan_sintel_protocol(root, refs=args.refs, windows=args.windows,
                                include_whole=not args.no_whole)
    numbers = sintel_clip_numbers(root)
    if not args.no_rubberwhale:
        h, w = load_rubberwhale_clip(root)[0].shape[1:3]
        if crop is not None and (crop[1] > h or crop[3] > w):
            raise ValueError(f"--crop: {' '.join(map(str, crop))} exceeds the {w}x{h} "
                             f"RubberWhale frames (give --no-rubberwhale to skip them)")
    rows = run_sintel_trajectories(methods, overrides, progress=not args.quiet, root=root,
                                   refs=list(plan), windows=args.windows,
                                   include_whole=not args.no_whole, crop=crop)
    crop_note = ""
    if crop is not None:
        crop_note = f", cropped to rows {crop[0]}:{crop[1]}, columns {crop[2]}:{crop[3]}"
    print(f"MPI-Sintel {PROTOCOL_PASS}/{PROTOCOL_CLIP} frames {numbers[0]:04d}-{numbers[-1]:04d}"
          f"{crop_note} (book Table 4.1 protocol): from reference r every method tracks "
          f"through the window; AEE (px, valid pixels) of its frame r+1 displacement against "
          f"flow r -> r+1, ratio to twoframe (< 1: better); data {root}; seconds exclude JIT "
          f"warm-up{_params_note(overrides)}")
    print(format_protocol_table(rows))
    if not args.no_rubberwhale:
        mrows = run_middlebury_multiframe(methods, overrides, progress=not args.quiet,
                                          root=root, crop=crop, warm_up=False)
        print()
        print(f"Middlebury RubberWhale frame07-frame14{crop_note}, reference frame10, scored "
              f"on frame10 -> frame11 (known pixels){_params_note(overrides)}")
        print(format_multiframe_table(mrows))
        rows = rows + mrows
    _write_rows(rows, csv_path)
    return 0


def _cmd_bench_interpolation(args: argparse.Namespace) -> int:
    from varflow.evaluation.bench.interpolation import (
        check_methods,
        check_peers,
        format_tables,
        format_timing_table,
        run_interpolation_bench,
        run_interpolation_timing,
    )
    from varflow.evaluation.datasets import data_root
    from varflow.evaluation.interpolation_sets import check_sets, interpolation_cases

    def option(exc: ValueError) -> ValueError:  # "sets: ..." -> "--sets: ..."
        arg, _, rest = str(exc).partition(":")
        names = {"sets": "--sets", "split": "--split", "peers": "--peers",
                 "methods": "--methods", "max_cases": "--max-cases",
                 "repeats": "--timing-repeats"}
        return ValueError(f"{names.get(arg, arg)}:{rest}")

    try:
        sets = check_sets(args.sets)
        methods = check_methods(args.methods)
        peers = check_peers(args.peers)
    except ValueError as exc:
        raise option(exc) from None
    if not methods and not peers:
        raise ValueError("--methods: give at least one interpolation method or peer")
    if args.max_cases is not None and args.max_cases < 1:
        raise ValueError(f"--max-cases: must be at least 1, got {args.max_cases}")
    if args.timing_repeats < 1:
        raise ValueError(f"--timing-repeats: must be at least 1, got {args.timing_repeats}")
    if args.timing_only and not args.timing:
        raise ValueError("--timing-only: contradicts --no-timing")
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    root = data_root(args.data)
    if not args.timing_only:
        for s in sets:  # fail on missing data before any run
            interpolation_cases(s, args.split, root)
    names = ", ".join(methods + peers)
    rows: list[dict[str, Any]] = []
    if not args.timing_only:
        times = "t = 0.5" + (", sintel-x4 1/4, 1/2, 3/4" if "sintel-x4" in sets else "")
        print(f"Frame interpolation ({', '.join(sets)}; {args.split} split; {times}"
              + (f", first {args.max_cases} cases per set" if args.max_cases else "")
              + f"): {names}.  PSNR (dB, RGB) and SSIM (Gaussian 11x11, sigma 1.5, mean "
              f"over channels) on 0-255; IE: Baker et al. RMS colour error, NE: IE with "
              f"each pixel divided by |grad I_gt|^2 + 1, MAE: mean absolute error (the "
              f"'IE' of learned methods); s: seconds per frame, JIT warm-up excluded; "
              f"data {root}")
        try:
            rows = run_interpolation_bench(sets, args.split, methods, peers, root=root,
                                           max_cases=args.max_cases,
                                           progress=not args.quiet)
        except ValueError as exc:
            raise option(exc) from None
        print()
        print(format_tables(rows, per_case=args.per_case))
    timing: list[dict[str, Any]] = []
    if args.timing:
        timing = run_interpolation_timing(methods, peers, root=root,
                                          repeats=args.timing_repeats,
                                          progress=not args.quiet)
        if rows:
            print()
        print(format_timing_table(timing))
    if csv_path is not None:
        from varflow.evaluation.bench.common import write_csv
        from varflow.evaluation.bench.interpolation import INTERPOLATION_CSV_FIELDS

        write_csv(rows + timing, csv_path, INTERPOLATION_CSV_FIELDS)
        print(f"wrote {csv_path}")
    return 0


def _cmd_bench_denoise(args: argparse.Namespace) -> int:
    from varflow.evaluation.bench.common import write_csv
    from varflow.evaluation.datasets import data_root
    from varflow.evaluation.denoising import (
        DENOISE_CSV_FIELDS,
        ESTIMATED_SUFFIX,
        PROTOCOL_FRAMES,
        check_denoise_clips,
        check_denoise_peers,
        check_restore_methods,
        format_denoise_tables,
        reference_method,
        run_denoise_benchmark,
        unavailable_peers,
    )

    def option(exc: ValueError) -> ValueError:  # "peers: ..." -> "--peers: ..."
        arg, _, rest = str(exc).partition(":")
        names = {"clips": "--clips", "sigmas": "--sigmas", "frames": "--frames",
                 "methods": "--methods", "peers": "--peers", "crop": "--crop"}
        return ValueError(f"{names.get(arg, arg)}:{rest}")

    try:
        sigmas = [float(v) for v in _split_list(args.sigmas)]
    except ValueError:
        raise ValueError(f"--sigmas: expected comma-separated noise levels, e.g. 10,30,50, "
                         f"got {args.sigmas!r}") from None
    if not sigmas or not all(math.isfinite(v) and v > 0 for v in sigmas):
        raise ValueError(f"--sigmas: every noise level must be positive, got {args.sigmas!r}")
    if args.frames < 2:
        raise ValueError(f"--frames: must be at least 2, got {args.frames}")
    crop = _crop_arg(args.crop)
    try:
        methods = check_restore_methods(args.methods)
        peers = check_denoise_peers(args.peers)
    except ValueError as exc:
        raise option(exc) from None
    missing = unavailable_peers(peers)
    peers = [p for p in peers if p not in missing]
    if not methods and not peers:
        raise ValueError("--methods: give at least one restoration method or available peer")
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    root = data_root(args.data)
    try:
        clips = check_denoise_clips(root, args.clips, crop)  # before any output
    except ValueError as exc:
        raise option(exc) from None
    sigma_text = ", ".join(f"{v:g}" for v in sigmas)
    crop_note = f", top-left {crop[0]}x{crop[1]} (HxW)" if crop else ""
    ref = reference_method(methods)
    notes = []
    if methods:
        notes.append(f"'{ref}{ESTIMATED_SUFFIX}': {ref} given no sigma")
    if "per-frame" in peers:
        notes.append(f"per-frame: {ref} with radius 0")
    protocol = crop is None and args.frames == PROTOCOL_FRAMES
    print(f"Video denoising ({', '.join(clips)}; sigma {sigma_text}; first {args.frames} "
          f"frames{crop_note}): white Gaussian noise on 0-255 RGB, seed 0, not clipped.  "
          f"PSNR (dB) of the output clipped to 0-255, mean over frames; SSIM (scikit-image, "
          f"7x7 window, data range 255); temp. err: RMS of the frame-to-frame change of "
          f"the error (0-255); s/frame: wall time per frame, JIT warm-up excluded; x NLM: "
          f"time over OpenCV NLM's; V-BM3D PSNR: reference figures"
          + ("" if protocol else " (only on the protocol's 20 uncropped frames)")
          + (f"; {'; '.join(notes)}" if notes else "") + f"; data {root}")
    for p, reason in missing.items():
        print(f"peer {p} unavailable: {reason}")
    with _Progress("denoise", args.quiet, unit="run") as bar:
        try:
            rows = run_denoise_benchmark(root, clips, sigmas, args.frames, methods, peers,
                                         crop=crop, callback=bar)
        except ValueError as exc:
            raise option(exc) from None
    print()
    print(format_denoise_tables(rows))
    if csv_path is not None:
        write_csv(rows, csv_path, DENOISE_CSV_FIELDS)
        print(f"wrote {csv_path}")
    return 0


def _crop_arg(text: str | None) -> tuple[int, int] | None:
    """``--crop HxW`` as ``(H, W)`` (None when not given)."""
    if text is None:
        return None
    try:
        crop = tuple(int(v) for v in text.lower().split("x"))
        if len(crop) != 2 or min(crop) < 1:
            raise ValueError
    except ValueError:
        raise ValueError(f"--crop: expected HxW, e.g. 96x128, got {text!r}") from None
    return crop[0], crop[1]


def _cmd_bench_restore(args: argparse.Namespace) -> int:
    from varflow.evaluation import restoration as rs
    from varflow.evaluation.bench.common import write_csv
    from varflow.evaluation.datasets import data_root

    if args.frames < 3:
        raise ValueError(f"--frames: must be at least 3, got {args.frames}")
    crop = _crop_arg(args.crop)
    try:
        rs.check_restore_cases(args.cases)
        rs.check_restore_kinds(args.methods)
    except ValueError as exc:
        arg, _, rest = str(exc).partition(":")
        raise ValueError(f"--{arg}:{rest}") from None
    csv_path = _check_output(args.csv, (".csv",), "--csv") if args.csv else None
    root = data_root(args.data)
    chain = None
    if args.tune_ffmpeg:
        with _Progress("tune chain", args.quiet, unit="run") as bar:
            best, table = rs.tune_ffmpeg_chain(root, frames=args.frames, callback=bar)
        print(rs.format_chain_tuning(table))
        print(f"\nchosen: {best}\n")
        chain = {k: best[k] for k in ("tmedian_radius", "atadenoise", "deflicker_size")}
    if not args.timing_only:
        with _Progress("restore", args.quiet, unit="run") as bar:
            rows = rs.run_restore_benchmark(root, args.clips, args.cases, args.frames,
                                            args.methods, crop=crop, callback=bar,
                                            chain=chain)
        print(f"Film-restoration protocol, first {args.frames} frames"
              + (f", top-left {crop[0]}x{crop[1]}" if crop else "") + f"; data {root}")
        print()
        print(rs.format_restore_tables(rows), flush=True)
        if csv_path is not None:
            write_csv(rows, csv_path, rs.RESTORE_CSV_FIELDS)
            print(f"wrote {csv_path}")
    if args.timing or args.timing_only:
        print()
        print(rs.format_chain_timing(rs.chain_timing(root)))
    return 0
