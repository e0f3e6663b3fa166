"""The ``varflow`` command line.

Synopsis::

    varflow flow FRAME0 FRAME1 -o OUT.flo|OUT.png [--png COLOUR.png] [--method NAME]
                 [--max-radius R] [--quiet] [--<parameter> VALUE ...]
    varflow show FLOW -o OUT.png [--max-radius R] [--legend]
    varflow eval EST GT [--occlusions MASK.png] [--json]
    varflow demo [-o DIR] [--quiet]
    varflow methods [--params] [--markdown]
    varflow bench middlebury [--data DIR] [--methods tvl1,...] [--sequences ...]
                             [--csv OUT.csv] [--quiet] [--<parameter> VALUE ...]
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
    varflow video VIDEO -o OUT.mp4|.mkv|.avi [--method NAME] [--start N] [--stop N]
                  [--stride S] [--layout flow|side-by-side|warped] [--max-radius R]
    varflow batch flow INPUT... -o OUT [--method NAME] [--stride S | --pairs FILE]
                  [--workers N] [--threads-per-worker T] [--scheduler ADDRESS]
                  [--format flo|png] [--zarr] [--overwrite] [--<parameter> VALUE ...]
    varflow batch track INPUT... -o OUT --window F --overlap K [--method NAME] ...
    varflow report PATH -o REPORT.html [--gt GT.flo] [--title T] [--max-frames N]

Method parameters become flags automatically: every field of the parameter
dataclass of every registered method is offered as ``--field-name`` (booleans as
``--name/--no-name``); only the flags given on the command line are passed on.

Every error ends the program with one line ``varflow: error: ...`` on stderr and
exit status 2 (130 on Ctrl-C).  Results go to stdout; ``-v`` turns on the library's
INFO logging on stderr.  Files are written atomically.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import os
import re
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from . import __version__
from .registry import METHODS, TRACKERS, get_method, get_tracker, make_params, make_track_params

__all__ = ["main", "parameter_table"]

log = logging.getLogger(__name__)

PROG = "varflow"
_PARAM_PREFIX = "param__"


class _UsageError(Exception):
    """Raised by the parser instead of printing usage and exiting."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line instead of usage + message
        raise _UsageError(f"{message} (see '{self.prog} --help')")


# --------------------------------------------------------------------------- parameters


@dataclasses.dataclass(frozen=True)
class _FieldDoc:
    name: str
    symbol: str
    meaning: str


_SYMBOL = re.compile(
    r"^(?P<sym>(?:[^\W\d_]{1,2}|[^\x00-\x7f]{1,2})(?:_[A-Za-z]{1,4})?)"
    r"(?:,\s+|\s+(?=of\b))(?P<rest>.*)$",
    re.S,
)


def _is_header(lines: list[str], i: int) -> bool:
    """True if ``lines[i]`` is a numpydoc section title (the next line is dashes)."""
    return i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}


def _field_docs(cls: type) -> dict[str, _FieldDoc]:
    """Parse the numpydoc ``Attributes`` sections of a dataclass and its bases.

    Returns ``{field: _FieldDoc(name, symbol, meaning)}``; ``symbol`` is the paper
    symbol when the description starts with one (``"λ, weight of ..."`` or
    ``"c of the ..."``), and ``meaning`` drops "Default ..." sentences (the default
    is taken from the dataclass itself).
    """
    out: dict[str, _FieldDoc] = {}
    for klass in reversed(cls.__mro__):
        doc = klass.__dict__.get("__doc__") or ""
        lines = doc.expandtabs().splitlines()
        in_attrs = False
        current: str | None = None
        buf: dict[str, list[str]] = {}
        for i, line in enumerate(lines):
            stripped = line.strip()
            if stripped == "Attributes" and _is_header(lines, i):
                in_attrs = True
                continue
            if not in_attrs or set(stripped) == {"-"}:
                continue
            indent = len(line) - len(line.lstrip())
            m = re.match(r"^(\w+)\s*:", stripped)
            if m and indent <= 4 and stripped:
                current = m.group(1)
                buf[current] = []
            elif stripped and indent <= 4 and _is_header(lines, i):
                in_attrs = False  # next section
                current = None
            elif current is not None and stripped:
                buf[current].append(stripped)
        for name, parts in buf.items():
            sentences = re.split(r"(?<=\.)\s+", " ".join(parts))
            text = " ".join(t for t in sentences if t and not t.startswith("Default")).strip()
            sym = ""
            m = _SYMBOL.match(text)
            if m:
                sym = m.group("sym")
                if text[len(sym)] == ",":  # "λ, weight of ..." -> "Weight of ..."
                    text = m.group("rest").strip()
                    text = text[:1].upper() + text[1:]
            out[name] = _FieldDoc(name, sym, text)
    return out


@dataclasses.dataclass
class _Param:
    name: str
    type: type
    default: Any
    owners: list[str]
    doc: _FieldDoc | None

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")


def _collect_params(registry: Mapping[str, Any] = METHODS) -> dict[str, _Param]:
    """All scalar fields of all registered methods' parameter classes, in registry order."""
    params: dict[str, _Param] = {}
    for mname, method in registry.items():
        docs = _field_docs(method.params)
        defaults = method.params()
        for f in dataclasses.fields(method.params):
            default = getattr(defaults, f.name)
            if f.name in params:
                params[f.name].owners.append(mname)
                continue
            kind = type(default)
            if kind not in (bool, int, float, str):
                log.debug("no CLI flag for %s.%s (type %s)", mname, f.name, kind.__name__)
                continue
            params[f.name] = _Param(f.name, kind, default, [mname], docs.get(f.name))
    return params


def _add_param_flags(
    parser: argparse.ArgumentParser, params: dict[str, _Param], n_methods: int = len(METHODS)
) -> None:
    group = parser.add_argument_group(
        "method parameters",
        "Fields of the methods' parameter dataclasses; only the flags you give are changed.",
    )
    for p in params.values():
        meaning = p.doc.meaning if p.doc else ""
        sym = f" [{p.doc.symbol}]" if p.doc and p.doc.symbol else ""
        owners = "" if len(p.owners) == n_methods else f"; methods: {', '.join(p.owners)}"
        text = f"{meaning}{sym} (default {p.default}{owners})".replace("%", "%%")
        kwargs: dict[str, Any] = {"dest": _PARAM_PREFIX + p.name, "default": argparse.SUPPRESS,
                                  "help": text}
        if p.type is bool:
            group.add_argument(p.flag, action=argparse.BooleanOptionalAction, **kwargs)
        else:
            group.add_argument(p.flag, type=p.type, metavar=p.type.__name__.upper(), **kwargs)


def _given_params(args: argparse.Namespace) -> dict[str, Any]:
    return {k[len(_PARAM_PREFIX):]: v for k, v in vars(args).items() if k.startswith(_PARAM_PREFIX)}


def _params_note(overrides: Mapping[str, Any]) -> str:
    """``"; parameters changed: a=1, b=2"`` for a benchmark header ("" when none)."""
    if not overrides:
        return ""
    return "; parameters changed: " + ", ".join(f"{k}={v}" for k, v in sorted(overrides.items()))


def _own_params(args: argparse.Namespace, entry: Any, kind: str) -> dict[str, Any]:
    """The parameter flags given on the command line; each must be a field of ``entry``."""
    given = _given_params(args)
    own = {f.name for f in dataclasses.fields(entry.params)}
    for name in given:
        if name not in own:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{flag} is not a parameter of {kind} {entry.name!r}")
    return given


def parameter_table(method: str, markdown: bool = False) -> str:
    """Table of a method's parameters: name, CLI flag, paper symbol, default, meaning.

    Parameters
    ----------
    method : str
        A registered method name.
    markdown : bool
        Markdown table (as in the README) instead of aligned text.

    Returns
    -------
    str
    """
    m = TRACKERS[method] if method in TRACKERS else get_method(method)
    docs = _field_docs(m.params)
    defaults = m.params()
    rows = []
    for f in dataclasses.fields(m.params):
        d = docs.get(f.name)
        rows.append((f.name, d.symbol if d and d.symbol else "", repr(getattr(defaults, f.name)),
                     d.meaning if d else ""))
    if markdown:
        lines = ["| parameter (`--flag`) | symbol | default | meaning |", "|---|---|---|---|"]
        for name, sym, default, meaning in rows:
            flag = "--" + name.replace("_", "-")
            meaning = meaning.replace("|", "\\|")
            lines.append(f"| `{name}` (`{flag}`) | {sym or '—'} | `{default}` | {meaning} |")
        return "\n".join(lines)
    wn = max(len(r[0]) for r in rows)
    ws = max(len(r[1]) for r in rows)
    wd = max(len(r[2]) for r in rows)
    return "\n".join(
        f"  {n:<{wn}}  {s or '-':<{ws}}  {d:>{wd}}  {t}" for n, s, d, t in rows
    )


# --------------------------------------------------------------------------- helpers


class _Progress:
    """A tqdm bar on stderr fed by ``callback(done, total)``; off with --quiet or no TTY."""

    def __init__(self, desc: str, quiet: bool, unit: str = "warp") -> None:
        from tqdm import tqdm

        enabled = not quiet and sys.stderr.isatty()
        self.bar = tqdm(total=None, desc=desc, unit=unit, file=sys.stderr, disable=not enabled,
                        leave=False)

    def __call__(self, done: int, total: int) -> None:
        if self.bar.total != total:
            self.bar.total = total
        self.bar.update(done - self.bar.n)

    def __enter__(self) -> _Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()


def _check_output(path: str, suffixes: Sequence[str] | None, what: str) -> Path:
    """Fail before any work when an output cannot be written."""
    p = Path(path)
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise ValueError(f"{what}: {p} must end in {' or '.join(suffixes)}")
    if suffixes is None:
        from PIL import Image

        if p.suffix.lower() not in Image.registered_extensions():
            raise ValueError(f"{what}: {p} has no known image extension (use .png)")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(2, f"{what}: directory does not exist", str(parent))
    if p.is_dir():
        raise IsADirectoryError(21, f"{what}: is a directory", str(p))
    return p


def _max_radius(value: float | None) -> float | None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ValueError(f"--max-radius: must be positive, got {value}")
    return value


def _magnitude(flow: np.ndarray) -> np.ndarray:
    mag = np.hypot(flow[..., 0], flow[..., 1])
    return mag[np.isfinite(mag)]


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(image, np.float64) * 255.0), 0, 255).astype(np.uint8)


def _split_list(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


# --------------------------------------------------------------------------- commands


def _cmd_flow(args: argparse.Namespace) -> int:
    import varflow
    from varflow.io import read_image, write_flow, write_image
    from varflow.viz import flow_to_color

    method = get_method(args.method)
    params = make_params(method, **_own_params(args, method, "method"))
    max_radius = _max_radius(args.max_radius)
    out = _check_output(args.output, (".flo", ".png"), "-o/--output")
    png = _check_output(args.png, None, "--png") if args.png else None

    f0 = read_image(args.frame0)
    f1 = read_image(args.frame1)
    log.info("frames: %s %s, %s %s", f0.shape, f0.dtype, f1.shape, f1.dtype)
    log.info("parameters: %s", params)
    t0 = time.perf_counter()
    with _Progress(f"{method.name}", args.quiet) as progress:
        flow = varflow.flow(f0, f1, method.name, params=params, callback=progress)
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
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from varflow.io import read_flow, write_image
    from varflow.viz import flow_to_color, flow_to_color_with_legend

    max_radius = _max_radius(args.max_radius)
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
    from varflow.evaluation.metrics import evaluate
    from varflow.generators.pairs import synthetic_pair
    from varflow.io import write_flo, write_image
    from varflow.viz import flow_to_color_with_legend

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    f0, f1, gt = synthetic_pair("smooth", shape=DEMO_SHAPE, magnitude=DEMO_MAGNITUDE,
                                seed=DEMO_SEED)
    f0, f1 = _to_uint8(f0), _to_uint8(f1)  # exactly what frame0.png / frame1.png hold
    t0 = time.perf_counter()
    with _Progress("demo", args.quiet) as progress:
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


def _cmd_track(args: argparse.Namespace) -> int:
    import varflow
    from varflow.io import write_image
    from varflow.io.trajectories import write_trajectories
    from varflow.io.video import read_frames
    from varflow.multiframe.track import check_frames, default_ref
    from varflow.ops.warp import warp_bicubic
    from varflow.viz import flow_to_color
    from varflow.viz.plots import draw_trajectories, grey_out

    tracker = get_tracker(args.method)
    params = make_track_params(tracker, **_own_params(args, tracker, "trajectory method"))
    out = _check_output(args.output, (".npz",), "-o/--output")
    plot = _check_output(args.plot, None, "--plot") if args.plot else None
    dirs = {}
    for flag, value in (("--warped", args.warped), ("--png", args.png)):
        if value:
            d = Path(value)
            d.mkdir(parents=True, exist_ok=True)
            dirs[flag] = d
    max_radius = _max_radius(args.max_radius)

    source = args.frames[0] if len(args.frames) == 1 else args.frames
    raw = read_frames(source)
    frames = check_frames(raw)
    ref = default_ref(frames.shape[0], args.ref)
    n_f, h, w = frames.shape[:3]
    log.info("%d frames %dx%d, reference %d, method %s", n_f, w, h, ref, tracker.name)
    t0 = time.perf_counter()
    with _Progress(tracker.name, args.quiet, unit="step") as progress:
        traj, visible = varflow.track(frames, ref, tracker.name, params=params,
                                      callback=progress, return_visibility=True)
    seconds = time.perf_counter() - t0
    meta = {"method": tracker.name, "params": dataclasses.asdict(params),
            "frames": [str(f) for f in args.frames], "seconds": seconds}
    write_trajectories(out, traj, ref=ref, visibility=visible, metadata=meta)
    if "--warped" in dirs:
        for n in range(n_f):
            warped, _ = warp_bicubic(frames[n], traj[n])
            write_image(dirs["--warped"] / f"warped_{n:04d}.png",
                        grey_out(_to_uint8(np.squeeze(warped)), visible[n]))
    mag = _magnitude(traj.reshape(-1, 1, 2))
    if "--png" in dirs:
        radius = max_radius or float(mag.max() or 1.0)
        for n in range(n_f):
            write_image(dirs["--png"] / f"displacement_{n:04d}.png",
                        flow_to_color(traj[n], max_radius=radius))
    if plot is not None:
        write_image(plot, draw_trajectories(raw[ref], traj, ref, step=args.plot_step,
                                            visibility=visible))
    others = np.arange(n_f) != ref
    hidden = float(1.0 - visible[others].mean()) if others.any() else 0.0
    print(f"{tracker.name}: {n_f} frames {w}x{h}, reference {ref}, in {seconds:.2f} s, "
          f"max |displacement| {mag.max():.3f} px, {100 * hidden:.1f}% hidden -> {out}")
    for flag, d in dirs.items():
        print(f"  {flag[2:]}: {d}")
    if plot is not None:
        print(f"  plot: {plot}")
    return 0


def _cmd_methods(args: argparse.Namespace) -> int:
    width = max(len(n) for n in (*METHODS, *TRACKERS))
    for title, registry in (("two-frame flow (varflow flow --method)", METHODS),
                            ("trajectories (varflow track --method)", TRACKERS)):
        print(f"# {title}")
        for name, m in registry.items():
            print(f"{name:<{width}}  {m.description}")
            if args.params:
                if args.markdown:
                    print()
                print(parameter_table(name, markdown=args.markdown))
                if args.markdown:
                    print()
    return 0


def _checked_methods(value: str, lookup, what: str) -> list[str]:
    """The ``--methods`` list, each name checked by ``lookup`` (one-line errors)."""
    methods = _split_list(value)
    if not methods:
        raise ValueError(f"--methods: give at least one {what} name")
    for m in methods:
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
    from varflow.evaluation.bench.multiframe import (
        format_multiframe_table,
        run_middlebury_multiframe,
        run_sintel_multiframe,
        sintel_snippets,
    )
    from varflow.evaluation.datasets import _HINT, data_root

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
                f"{_HINT}"
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
    from varflow.evaluation.bench.multiframe import (
        PROTOCOL_CLIP,
        PROTOCOL_PASS,
        format_multiframe_table,
        format_protocol_table,
        load_rubberwhale_clip,
        plan_sintel_protocol,
        run_middlebury_multiframe,
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


# --------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (parameter flags generated from the registry)."""
    params = _collect_params()
    common = _Parser(add_help=False)
    common.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                        help="log to stderr: -v INFO, -vv DEBUG")

    parser = _Parser(
        prog=PROG,
        description="Classical variational optical flow (TV-L1 and friends).",
        epilog="Run 'varflow demo' for a first look; 'varflow COMMAND --help' for details.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log to stderr: -v INFO, -vv DEBUG")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                parser_class=_Parser)

    p = sub.add_parser("flow", parents=[common], help="estimate the flow between two frames",
                       description="Estimate the flow from FRAME0 to FRAME1.")
    p.add_argument("frame0", metavar="FRAME0", help="first image (PNG, JPEG, ...)")
    p.add_argument("frame1", metavar="FRAME1", help="second image, same size")
    p.add_argument("-o", "--output", required=True, metavar="OUT",
                   help="flow file: .flo (Middlebury) or .png (KITTI 16-bit)")
    p.add_argument("--png", metavar="COLOUR.png", help="also write the colour-coded flow")
    p.add_argument("--method", default="tvl1", metavar="NAME",
                   help=f"one of: {', '.join(METHODS)} (default tvl1)")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="flow magnitude of full colour saturation (default: the maximum)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    _add_param_flags(p, params)
    p.set_defaults(func=_cmd_flow)

    p = sub.add_parser("show", parents=[common], help="colour-code a flow file",
                       description="Write the Middlebury colour coding of a .flo/.png flow.")
    p.add_argument("flow", metavar="FLOW", help=".flo or KITTI .png flow file")
    p.add_argument("-o", "--output", required=True, metavar="OUT.png")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="flow magnitude of full colour saturation (default: the maximum)")
    p.add_argument("--legend", action="store_true", help="paste a colour-wheel legend")
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser("eval", parents=[common], help="score a flow against ground truth",
                       description="Print AEE, AAE (degrees), RMS and R1/R3/R5 of EST vs GT.")
    p.add_argument("est", metavar="EST", help="estimated flow (.flo or .png)")
    p.add_argument("gt", metavar="GT", help="ground-truth flow (.flo or .png)")
    p.add_argument("--occlusions", metavar="MASK.png",
                   help="occlusion mask (white = occluded) for noc/occ scores")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("demo", parents=[common], help="run on a synthetic pair with known motion",
                       description="Synthetic pair with exact ground truth: writes frames, "
                       "flow and colour images, prints the error.")
    p.add_argument("-o", "--output", default="varflow-demo", metavar="DIR",
                   help="output folder (default ./varflow-demo)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_demo)

    tparams = _collect_params(TRACKERS)
    p = sub.add_parser("track", parents=[common], help="dense trajectories through a sequence",
                       description="Track every pixel of a reference frame through a sequence "
                       "(frames as files, a directory or a video).")
    p.add_argument("frames", nargs="+", metavar="FRAME",
                   help="image files in order, or one directory of images or video file")
    p.add_argument("-o", "--output", required=True, metavar="OUT.npz",
                   help="trajectories (F, H, W, 2), visibility (F, H, W), the reference "
                   "index and metadata")
    p.add_argument("--ref", type=int, default=None, metavar="K",
                   help="reference frame index (default: the centre frame)")
    p.add_argument("--method", default="rlr", metavar="NAME",
                   help=f"one of: {', '.join(TRACKERS)} (default rlr)")
    p.add_argument("--warped", metavar="DIR", help="write every frame warped back to the "
                   "reference (warped_NNNN.png; points hidden in that frame greyed out)")
    p.add_argument("--png", metavar="DIR", help="write the colour-coded displacement of every "
                   "frame (displacement_NNNN.png, one colour scale)")
    p.add_argument("--plot", metavar="PLOT.png",
                   help="draw sampled trajectories over the reference frame (grey where "
                   "hidden)")
    p.add_argument("--plot-step", type=int, default=16, metavar="PX",
                   help="grid step of the plotted trajectories (default 16)")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="displacement of full colour saturation for --png (default: maximum)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    _add_param_flags(p, tparams, n_methods=len(TRACKERS))
    p.set_defaults(func=_cmd_track)

    p = sub.add_parser("methods", parents=[common], help="list the methods",
                       description="List the registered methods.")
    p.add_argument("-p", "--params", action="store_true", help="with their parameters")
    p.add_argument("--markdown", action="store_true", help="parameter tables in Markdown")
    p.set_defaults(func=_cmd_methods)

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
    _add_param_flags(b, params)
    b.set_defaults(func=_cmd_bench_middlebury)

    from .generators.photo import FAMILIES as PHOTO_FAMILIES

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
    b.add_argument("--methods", default=",".join(TRACKERS), metavar="NAMES",
                   help=f"comma-separated, from: {', '.join(TRACKERS)} (default all)")
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
    _add_param_flags(b, tparams, n_methods=len(TRACKERS))
    b.set_defaults(func=_cmd_bench_trajectories)

    from .evaluation.bench.twoframe import DEFAULT_SETS as DEFAULT_SETS_TWOFRAME
    from .evaluation.bench.twoframe import SETS as SETS_TWOFRAME
    from .evaluation.peers import PEERS
    from .generators.photo_pairs import FAMILIES as PAIR_FAMILIES

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
    _add_param_flags(b, params)
    b.set_defaults(func=_cmd_bench_twoframe)

    from .evaluation.bench.multiframe import default_methods

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
                   help=f"comma-separated, from: {', '.join(TRACKERS)} (default {mf_default})")
    b.add_argument("--sintel", action="store_true",
                   help="also report on the MPI-Sintel snippets found under the data folder")
    _add_param_flags(b, tparams, n_methods=len(TRACKERS))
    b.set_defaults(func=_cmd_bench_middlebury_multiframe)

    from .evaluation.bench.multiframe import PROTOCOL_METHODS, PROTOCOL_REFS, PROTOCOL_WINDOWS

    st_default = ",".join(m for m in PROTOCOL_METHODS if m in TRACKERS)
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
                   help=f"comma-separated, from: {', '.join(TRACKERS)} (default {st_default})")
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
    _add_param_flags(b, tparams, n_methods=len(TRACKERS))
    b.set_defaults(func=_cmd_bench_sintel_trajectories)

    # commands that live with their stage: each module's add_parser(sub, common)
    from .batch import command as batch_command
    from .io import video_command
    from .report import command as report_command

    for module in (video_command, batch_command, report_command):
        module.add_parser(sub, common)
    return parser


# --------------------------------------------------------------------------- main


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror and exc.filename is not None:
        msg = f"{exc.strerror}: {exc.filename}"
        if exc.filename2 is not None:
            msg += f" -> {exc.filename2}"
    else:
        msg = str(exc) or type(exc).__name__
    if not isinstance(exc, ValueError | OSError | _UsageError):
        msg = f"{type(exc).__name__}: {msg}"
    return " ".join(msg.split())


def _fail(message: str) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return 2


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name; ``sys.argv[1:]`` by default.

    Returns
    -------
    int
        0 on success, 2 on any error (one line on stderr), 130 on Ctrl-C, 141 when
        stdout is a closed pipe.
    """
    handler: logging.Handler | None = None
    pkg_log = logging.getLogger("varflow")
    old_level = pkg_log.level
    try:
        try:
            args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
        except SystemExit as exc:  # --help, --version
            return int(exc.code or 0) if not isinstance(exc.code, str) else _fail(exc.code)
        if getattr(args, "verbose", 0):
            handler = logging.StreamHandler(sys.stderr)
            handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
            pkg_log.addHandler(handler)
            pkg_log.setLevel(logging.INFO if args.verbose == 1 else logging.DEBUG)
        func: Callable[[argparse.Namespace], int] = args.func
        return func(args)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `varflow methods | head -1`: stop quietly
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes
        except (OSError, ValueError):
            pass
        return 141
    except Exception as exc:  # noqa: BLE001 - the CLI turns every error into one line
        if handler is not None:
            log.info("details", exc_info=exc)
        return _fail(_one_line(exc))
    finally:
        if handler is not None:
            pkg_log.removeHandler(handler)
            pkg_log.setLevel(old_level)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
