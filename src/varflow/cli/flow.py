"""``varflow flow``, ``show``, ``eval``, ``demo`` and ``methods``: one pair of frames.

Synopsis::

    varflow flow FRAME0 FRAME1 -o OUT.flo|OUT.npy|OUT.png [--png COLOUR.png] [--method NAME]
                 [--max-pixels N] [--max-radius R] [--quiet] [--<parameter> VALUE ...]
    varflow show FLOW -o OUT.png [--max-radius R] [--legend]
    varflow eval EST GT [--occlusions MASK.png] [--json]
    varflow demo [-o DIR] [--quiet]
    varflow methods [NAME] [--params] [--markdown]
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..registry import METHODS, TRACKERS, get_method, make_params
from ._common import (
    PROG,
    _add_param_flags,
    _check_output,
    _claim_inputs,
    _collect_params,
    _compile_notice,
    _magnitude,
    _max_radius,
    _own_params,
    _Progress,
    _to_uint8,
    chosen_methods,
    int_at_least,
    method_card,
    methods_epilog,
    parameter_table,
)

__all__ = ["DEMO_MAGNITUDE", "DEMO_SEED", "DEMO_SHAPE", "add_parser"]

log = logging.getLogger("varflow.cli")


def add_parser(sub: Any, common: argparse.ArgumentParser, argv: Sequence[str] | None) -> None:
    """Register ``flow``, ``show``, ``eval``, ``demo`` and ``methods``.

    The ``add_parser`` protocol of :mod:`varflow.cli` (its notes say what ``sub``,
    ``common`` and ``argv`` are).
    """
    params = _collect_params()
    p = sub.add_parser(
        "flow", parents=[common], help="estimate the flow between two frames",
        description="Estimate the flow from FRAME0 to FRAME1: FRAME1 at (x + u, y + v) "
        "matches FRAME0 at (x, y).  Grey and colour frames mix.",
        usage="%(prog)s FRAME0 FRAME1 -o OUT [--method NAME] [--PARAMETER VALUE ...] "
        "[options]",
        epilog=methods_epilog(METHODS))
    p.add_argument("frame0", metavar="FRAME0", help="first image (PNG, JPEG, TIFF, ...)")
    p.add_argument("frame1", metavar="FRAME1", help="second image, same size (grey or colour)")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="flow file: .flo (Middlebury), .npy (NumPy float32) or .png (KITTI "
                   "16-bit, for programs, not viewers: use --png for a picture)")
    p.add_argument("--png", metavar="COLOUR.png", help="also write the colour-coded flow")
    p.add_argument("--method", default=METHODS.default, metavar="NAME",
                   help=f"the method (default {METHODS.default}; list below)")
    p.add_argument("--max-pixels", type=int_at_least(0), default=0, metavar="N",
                   help="estimate on copies of the frames reduced to at most N pixels and "
                   "scale the flow back up: faster on large frames (default 0: full size)")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="flow magnitude of full colour saturation (default: the maximum)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    _add_param_flags(p, params, METHODS, chosen_methods(argv, METHODS))
    p.set_defaults(func=_cmd_flow)

    p = sub.add_parser("show", parents=[common], help="colour-code a flow file",
                       description="Write the Middlebury colour coding of a .flo/.png flow.")
    p.add_argument("flow", metavar="FLOW", help="flow file: .flo, KITTI .png or .npy")
    p.add_argument("-o", "--output", required=True, metavar="OUT.png")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="flow magnitude of full colour saturation (default: the maximum)")
    p.add_argument("--legend", action="store_true", help="paste a colour-wheel legend")
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser("eval", parents=[common], help="score a flow against ground truth",
                       description="Print AEE, AAE (degrees), RMS and R1/R3/R5 of EST vs GT.")
    p.add_argument("est", metavar="EST", help="estimated flow (.flo, KITTI .png or .npy)")
    p.add_argument("gt", metavar="GT", help="ground-truth flow (.flo, KITTI .png or .npy)")
    p.add_argument("--occlusions", metavar="MASK.png",
                   help="occlusion mask (white = occluded) for noc/occ scores")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("demo", parents=[common], help="run on a synthetic pair with known motion",
                       description="Synthetic pair with exact ground truth: writes frames, "
                       "flow and colour images, prints the error.")
    p.add_argument("-o", "--output", default="varflow-demo", metavar="DIR",
                   help="output folder (default ./varflow-demo)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    p.set_defaults(func=_cmd_demo)


    p = sub.add_parser("methods", parents=[common], help="list the methods, or one in full",
                       description="List the methods with when to use each; with NAME, "
                       "that method's parameters (flag, symbol, default, range, unit).")
    p.add_argument("name", nargs="?", metavar="NAME", help="one method, e.g. tvl1")
    p.add_argument("-p", "--params", action="store_true",
                   help="every method with its full parameter descriptions")
    p.add_argument("--markdown", action="store_true", help="parameter tables in Markdown")
    p.set_defaults(func=_cmd_methods)



def _cmd_flow(args: argparse.Namespace) -> int:
    import varflow
    from varflow._warm import beside
    from varflow.io import read_image, write_flow, write_image
    from varflow.io.images import FLOW_EXTENSIONS
    from varflow.viz import flow_to_color

    method = get_method(args.method)
    params = make_params(method, **_own_params(args, method, "method"))
    max_radius = _max_radius(args.max_radius)
    _claim_inputs((args.frame0, "FRAME0"), (args.frame1, "FRAME1"))
    out = _check_output(args.output, FLOW_EXTENSIONS, "-o/--output")
    png = _check_output(args.png, None, "--png") if args.png else None

    f0 = read_image(args.frame0)
    f1 = read_image(args.frame1)
    log.info("frames: %s %s, %s %s", f0.shape, f0.dtype, f1.shape, f1.dtype)
    log.info("parameters: %s", params)
    _compile_notice(method.name, args.quiet)
    t0 = time.perf_counter()
    # a cold cache: the last kernels compile in a helper process beside the run
    with beside(method.name), _Progress(f"{method.name}", args.quiet) as progress:
        flow = varflow.flow(f0, f1, method.name, params=params, callback=progress,
                            max_pixels=args.max_pixels)
    seconds = time.perf_counter() - t0
    write_flow(out, flow)
    if png is not None:
        write_image(png, flow_to_color(flow, max_radius=max_radius))
    mag = _magnitude(flow)
    h, w = flow.shape[:2]
    extra = f", colour {png}" if png is not None else ""
    print(
        f"{method.name}: {w}x{h} in {seconds:.2f} s, mean |w| {mag.mean():.3f} px, "
        f"max |w| {mag.max():.3f} px -> {out}{extra}"
    )
    if out.suffix.lower() == ".png" and png is None:
        print(f"{PROG}: note: {out} is a 16-bit KITTI flow PNG (u, v, valid), not a picture: "
              "image viewers show it as flat; use --png COLOUR.png or 'varflow show' for one",
              file=sys.stderr)
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from varflow.io import read_flow, write_image
    from varflow.viz import flow_to_color, flow_to_color_with_legend

    max_radius = _max_radius(args.max_radius)
    _claim_inputs((args.flow, "FLOW"))
    out = _check_output(args.output, None, "-o/--output")
    flow = read_flow(args.flow)
    if args.legend:
        img = flow_to_color_with_legend(flow, max_radius=max_radius)
    else:
        img = flow_to_color(flow, max_radius=max_radius)
    write_image(out, img)
    mag = _magnitude(flow)
    h, w = flow.shape[:2]
    peak = f"{mag.max():.3f}" if mag.size else "n/a"
    print(f"{args.flow}: {w}x{h}, max |w| {peak} px -> {out}")
    return 0


_EVAL_LABELS = {  # key of evaluate() -> (label, unit)
    "aee": ("AEE", "px"),
    "aae": ("AAE", "deg"),
    "rms": ("RMS", "px"),
    "r1": ("R1", "% EPE > 1 px"),
    "r3": ("R3", "% EPE > 3 px"),
    "r5": ("R5", "% EPE > 5 px"),
    "aee_noc": ("AEE noc", "px (non-occluded)"),
    "aee_occ": ("AEE occ", "px (occluded)"),
    "missing": ("missing", "% of valid pixels without estimate"),
}


def _read_mask(path: str) -> np.ndarray:
    from varflow.io import read_image

    m = read_image(path)
    if m.ndim == 3:
        m = m.max(axis=2)
    return m > np.iinfo(m.dtype).max // 2


def _cmd_eval(args: argparse.Namespace) -> int:
    from varflow.evaluation.metrics import evaluate
    from varflow.io import read_flow

    est = read_flow(args.est)
    gt = read_flow(args.gt)
    occ = _read_mask(args.occlusions) if args.occlusions else None
    scores = evaluate(est, gt, occlusion=occ)
    if args.json:
        print(json.dumps({k: (None if isinstance(v, float) and math.isnan(v) else v)
                          for k, v in scores.items()}, indent=2, sort_keys=False))
        return 0
    keys = [k for k in _EVAL_LABELS if k in scores] + [k for k in scores if k not in _EVAL_LABELS]
    labels = {k: _EVAL_LABELS.get(k, (k, "")) for k in keys}
    width = max(len(lab) for lab, _ in labels.values())
    for k in keys:
        label, unit = labels[k]
        print(f"{label:<{width}}  {float(scores[k]):.6f}  {unit}".rstrip())
    return 0


DEMO_SHAPE = (240, 320)
DEMO_MAGNITUDE = 3.0
DEMO_SEED = 4


def _cmd_demo(args: argparse.Namespace) -> int:
    import varflow
    from varflow._warm import beside
    from varflow.evaluation.metrics import evaluate
    from varflow.generators.pairs import synthetic_pair
    from varflow.io import write_flo, write_image
    from varflow.viz import flow_to_color_with_legend

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    f0, f1, gt = synthetic_pair("smooth", shape=DEMO_SHAPE, magnitude=DEMO_MAGNITUDE,
                                seed=DEMO_SEED)
    f0, f1 = _to_uint8(f0), _to_uint8(f1)  # exactly what frame0.png / frame1.png hold
    _compile_notice("tvl1", args.quiet)
    t0 = time.perf_counter()
    # a cold cache: the last kernels compile in a helper process beside the run
    with beside("tvl1"), _Progress("demo", args.quiet) as progress:
        flow = varflow.flow(f0, f1, "tvl1", callback=progress)
    seconds = time.perf_counter() - t0
    scores = evaluate(flow, gt)
    radius = float(_magnitude(gt).max())
    paths = {
        "frame0": out / "frame0.png",
        "frame1": out / "frame1.png",
        "flow": out / "flow.flo",
        "colour": out / "flow.png",
        "ground truth": out / "gt.flo",
        "gt colour": out / "gt.png",
    }
    write_image(paths["frame0"], f0)
    write_image(paths["frame1"], f1)
    write_flo(paths["flow"], flow)
    write_image(paths["colour"], flow_to_color_with_legend(flow, max_radius=radius))
    write_flo(paths["ground truth"], gt)
    write_image(paths["gt colour"], flow_to_color_with_legend(gt, max_radius=radius))
    h, w = DEMO_SHAPE
    print(f"synthetic smooth motion, {w}x{h}, up to {radius:.2f} px; tvl1 in {seconds:.2f} s")
    print(f"AEE {scores['aee']:.4f} px, AAE {scores['aae']:.3f} deg (exact ground truth)")
    for label, p in paths.items():
        print(f"  {label + ':':<14}{p}")
    print(f"next: varflow eval {paths['flow']} {paths['ground truth']}")
    return 0


def _cmd_methods(args: argparse.Namespace) -> int:
    from ..registry import REPAIR, RESTORE
    from ..retime.methods import INTERPOLATORS

    kinds = (("two-frame flow (varflow flow --method)", METHODS),
             ("trajectories (varflow track --method)", TRACKERS),
             ("frame interpolation (varflow interpolate / retime --method)", INTERPOLATORS),
             ("denoising (varflow denoise --method)", RESTORE),
             ("repair stages (varflow restore --STAGE)", REPAIR))
    if args.name is not None:
        if not any(args.name in registry for _, registry in kinds):
            names = ", ".join(n for _, registry in kinds for n in registry)
            raise ValueError(f"unknown method {args.name!r}; available: {names}")
        if args.markdown:
            print(parameter_table(args.name, markdown=True))
        else:
            print(method_card(args.name))
        return 0
    width = max(len(n) for _, registry in kinds for n in registry)
    for title, registry in kinds:
        print(f"# {title}")
        for name, m in registry.items():
            print(f"{name:<{width}}  {m.use if not args.params else m.description}")
            if args.params:
                if args.markdown:
                    print()
                print(parameter_table(name, markdown=args.markdown))
                if args.markdown:
                    print()
    return 0
