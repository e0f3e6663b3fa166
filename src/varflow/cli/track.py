"""``varflow track``: dense trajectories through a sequence.

Synopsis::

    varflow track FRAME... -o OUT.npz [--ref K] [--method NAME] [--warped DIR] [--png DIR]
                  [--plot PLOT.png] [--animate TRACKS.mp4] [--plot-points N]
                  [--max-radius R] [--quiet]
                  [--<parameter> VALUE ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..registry import TRACKERS, get_tracker, make_track_params
from ._common import (
    _add_param_flags,
    _check_output,
    _claim,
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
    methods_epilog,
)

__all__ = ["add_parser"]

log = logging.getLogger("varflow.cli")


def add_parser(sub: Any, common: argparse.ArgumentParser, argv: Sequence[str] | None) -> None:
    """Register ``track``.

    The ``add_parser`` protocol of :mod:`varflow.cli` (its notes say what ``sub``,
    ``common`` and ``argv`` are).
    """
    p = sub.add_parser("track", parents=[common], help="dense trajectories through a sequence",
                       description="Track every pixel of a reference frame through a sequence "
                       "(frames as files, a directory or a video).",
                       epilog=methods_epilog(TRACKERS))
    p.add_argument("frames", nargs="+", metavar="FRAME",
                   help="image files in order, or one directory of images or video file")
    p.add_argument("-o", "--output", required=True, metavar="OUT.npz",
                   help="trajectories (F, H, W, 2), visibility (F, H, W), the reference "
                   "index and metadata")
    p.add_argument("--ref", type=int, default=None, metavar="K",
                   help="reference frame index (default: the centre frame)")
    p.add_argument("--method", default=TRACKERS.default, metavar="NAME",
                   help=f"the method (default {TRACKERS.default}; list below)")
    p.add_argument("--warped", metavar="DIR", help="write every frame warped back to the "
                   "reference (warped_NNNN.png; points hidden in that frame greyed out)")
    p.add_argument("--png", metavar="DIR", help="write the colour-coded displacement of every "
                   "frame (displacement_NNNN.png, one colour scale)")
    p.add_argument("--plot", metavar="PLOT.png",
                   help="draw the tracks of sampled points over the last frame, as TAP-Vid "
                   "does: coloured tails through every frame, dashed grey where hidden; a "
                   "legend under the picture names the reference frame")
    p.add_argument("--animate", metavar="TRACKS.mp4",
                   help="a video (.mp4, .mkv, ...) or animated .gif of the tracks: every "
                   "frame with the points' last 10 positions")
    p.add_argument("--plot-points", type=int_at_least(1), default=300, metavar="N",
                   help="about N points in --plot and --animate (default 300)")
    p.add_argument("--max-radius", type=float, metavar="R",
                   help="displacement of full colour saturation for --png (default: maximum)")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar, no compile notice")
    _add_param_flags(p, _collect_params(TRACKERS), TRACKERS, chosen_methods(argv, TRACKERS))
    p.set_defaults(func=_cmd_track)


def _cmd_track(args: argparse.Namespace) -> int:
    import varflow
    from varflow.io import write_image
    from varflow.io.trajectories import write_trajectories
    from varflow.io.video import read_frames
    from varflow.multiframe.track import check_frames, default_ref
    from varflow.ops.warp import warp_bicubic
    from varflow.viz import flow_to_color
    from varflow.viz.plots import draw_tracks, grey_out, track_animation

    tracker = get_tracker(args.method)
    params = make_track_params(tracker, **_own_params(args, tracker, "trajectory method"))
    _claim_inputs(*[(f, "FRAME") for f in args.frames])
    out = _check_output(args.output, (".npz",), "-o/--output")
    plot = _check_output(args.plot, None, "--plot") if args.plot else None
    animate = None
    if args.animate:
        from varflow.io.video import VIDEO_WRITE_EXTENSIONS

        animate = _check_output(args.animate, (".gif", *sorted(VIDEO_WRITE_EXTENSIONS)),
                                "--animate")
    dirs = {}
    for flag, value in (("--warped", args.warped), ("--png", args.png)):
        if value:
            d = Path(value)
            _claim(d, flag)
            d.mkdir(parents=True, exist_ok=True)
            dirs[flag] = d
    max_radius = _max_radius(args.max_radius)

    source = args.frames[0] if len(args.frames) == 1 else args.frames
    raw = read_frames(source)
    frames = check_frames(raw)
    ref = default_ref(frames.shape[0], args.ref)
    n_f, h, w = frames.shape[:3]
    log.info("%d frames %dx%d, reference %d, method %s", n_f, w, h, ref, tracker.name)
    _compile_notice(tracker.name, args.quiet)
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
        write_image(plot, draw_tracks(raw[-1], traj, ref, visibility=visible,
                                      points=args.plot_points, legend=True,
                                      title=_plot_title(args.frames, ref, n_f)))
    if animate is not None:
        pictures = track_animation(raw, traj, ref, visibility=visible, points=args.plot_points)
        _write_animation(animate, pictures)
    others = np.arange(n_f) != ref
    hidden = float(1.0 - visible[others].mean()) if others.any() else 0.0
    print(f"{tracker.name}: {n_f} frames {w}x{h}, reference {ref}, in {seconds:.2f} s, "
          f"max |displacement| {mag.max():.3f} px, {100 * hidden:.1f}% hidden -> {out}")
    for flag, d in dirs.items():
        print(f"  {flag[2:]}: {d}")
    if plot is not None:
        print(f"  plot: {plot}")
    if animate is not None:
        print(f"  animation: {animate}")
    return 0


def _plot_title(frames: Sequence[str], ref: int, n_frames: int) -> str:
    """``reference frame 2 of 5 (f2.png)`` and ``drawn on frame 4 (f4.png)``: the frames
    of the --plot picture, with their file names (or the video's name)."""
    from varflow.io.video import list_frame_files

    names: list[str] = []
    if len(frames) > 1:
        names = [Path(f).name for f in frames]
    elif Path(frames[0]).is_dir():
        names = [f.name for f in list_frame_files(frames[0])]
    if len(names) != n_frames:  # a video
        return (f"reference frame {ref} of {n_frames} in {Path(frames[0]).name}\n"
                f"drawn on frame {n_frames - 1}")
    return (f"reference frame {ref} of {n_frames} ({names[ref]})\n"
            f"drawn on frame {n_frames - 1} ({names[-1]})")


def _write_animation(path: Path, pictures: Any, fps: int = 10) -> None:
    """The pictures as a video (the writer's codec for the extension) or an animated GIF,
    atomically."""
    if path.suffix.lower() != ".gif":
        from varflow.io.video import write_video

        write_video(path, list(pictures), fps)
        return
    import os
    import tempfile

    from PIL import Image

    images = [Image.fromarray(p) for p in pictures]
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".gif", dir=path.parent)
    os.close(fd)
    try:
        images[0].save(tmp, save_all=True, append_images=images[1:], duration=1000 // fps,
                       loop=0)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
