"""Running trajectory methods on RubberWhale and the Sintel snippets, scored on one pair.

:func:`run_middlebury_multiframe` and :func:`run_sintel_multiframe` track the
reference frame's pixels through each clip with every method and score the
displacement of the next frame against its two-frame ground truth
(:func:`score_estimate`), after an untimed warm-up (:func:`warm_up_methods`); a
``tvl1`` pair baseline row is added.  See :mod:`varflow.evaluation.bench.multiframe`.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...registry import TRACKERS
from ..datasets import DATA_HINT, SINTEL_PASSES, data_root
from .common import spec_name
from .multiframe_data import (
    Crop,
    SintelSnippet,
    apply_crop,
    check_crop,
    check_crop_fits,
    load_rubberwhale_clip,
    load_snippet,
    sintel_snippets,
)
from .trajectories import tracker_params

__all__ = [
    "BASELINE_LABEL",
    "DEFAULT_METHODS",
    "default_methods",
    "run_middlebury_multiframe",
    "run_sintel_multiframe",
    "score_estimate",
    "warm_up_methods",
]

log = logging.getLogger(__name__)


#: Method label of the two-frame baseline rows.
BASELINE_LABEL = "tvl1 (two-frame)"

#: Preferred trajectory method specs, in table order (:func:`~varflow.evaluation.bench.
#: common.method_spec`): rlr, rlr decoupled (τ = 0), mfsf, the library's two-frame flow
#: from the reference (default method and ``tvl1-ld``) and chained;
#: :func:`default_methods` keeps the registered ones.
DEFAULT_METHODS: tuple[str, ...] = ("rlr", "rlr:link_weight=0", "mfsf", "twoframe",
                                    "twoframe:tvl1-ld", "chain")


def default_methods() -> list[str]:
    """The registered ones of :data:`DEFAULT_METHODS`, in that order."""
    return [m for m in DEFAULT_METHODS if spec_name(m) in TRACKERS]


def warm_up_methods(methods: Sequence[str], params: Mapping[str, Any], baseline: bool) -> None:
    """Run every method once on a tiny synthetic clip so JIT compilation is not timed."""
    import varflow

    from ...generators.pairs import synthetic_pair

    f0, f1, _ = synthetic_pair("translation", shape=(48, 64), magnitude=1.0, seed=0)
    if baseline:
        varflow.flow(f0, f1, "tvl1")
    for m in methods:
        try:
            varflow.track(np.stack([f0, f1, f0]), 1, spec_name(m), params=params[m])
        except Exception as exc:  # noqa: BLE001 - a warm-up only; the real run reports
            log.warning("warm-up of %s failed (%s); its time includes compilation", m, exc)


def score_estimate(est: np.ndarray, gt: np.ndarray, valid: np.ndarray | None,
                   occ: np.ndarray | None) -> dict[str, float]:
    """AEE and AAE of ``est`` against ``gt`` over ``valid``, and the AEE over the
    non-occluded valid pixels (``aee_noc``, None without ``occ``)."""
    from ..metrics import endpoint_error, evaluate

    s = evaluate(est, gt, mask=valid)
    noc = None
    if occ is not None:
        noc = float(endpoint_error(est, gt, mask=~occ if valid is None else valid & ~occ))
    return {"aee": float(s["aee"]), "aae": float(s["aae"]), "aee_noc": noc}


def _run_clip(
    rows: list[dict[str, Any]],
    base: Mapping[str, Any],
    frames: np.ndarray,
    ref: int,
    gt: np.ndarray,
    valid: np.ndarray | None,
    occ: np.ndarray | None,
    methods: Sequence[str],
    params: Mapping[str, Any],
    baseline: bool,
    bar: Any,
) -> None:
    import varflow

    label = f"{base['dataset']} {base['sequence']}"
    for m in methods:
        bar.set_postfix_str(f"{label} {m}")
        t0 = time.perf_counter()
        traj = varflow.track(frames, ref, spec_name(m), params=params[m])
        seconds = time.perf_counter() - t0
        row = {**base, "method": m, **score_estimate(traj[ref + 1], gt, valid, occ),
               "seconds": seconds}
        log.info("%s %s: AEE %.4f AAE %.3f in %.2fs", label, m, row["aee"], row["aae"], seconds)
        rows.append(row)
        bar.update(1)
    if baseline:
        bar.set_postfix_str(f"{label} tvl1")
        t0 = time.perf_counter()
        est = varflow.flow(frames[ref], frames[ref + 1], "tvl1")
        seconds = time.perf_counter() - t0
        row = {**base, "method": BASELINE_LABEL, **score_estimate(est, gt, valid, occ),
               "seconds": seconds}
        log.info("%s tvl1 pair: AEE %.4f AAE %.3f in %.2fs", label, row["aee"], row["aae"],
                 seconds)
        rows.append(row)
        bar.update(1)


def run_middlebury_multiframe(
    methods: Sequence[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    *,
    root: str | os.PathLike[str] | None = None,
    baseline: bool = True,
    crop: Crop | None = None,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Trajectory methods on the 8-frame RubberWhale clip, scored on frame10 → frame11.

    Every method tracks the pixels of frame10 (reference, index 3) through
    ``frame07 … frame14``; its displacement in frame11 is compared with
    ``flow10.flo`` over the pixels with known ground truth (AEE, AAE).  Each method
    first runs once on a tiny synthetic clip (not timed) so ``seconds`` — the wall
    time of :func:`varflow.track` alone — excludes Numba compilation.

    Parameters
    ----------
    methods : sequence of str, optional
        Names from :data:`varflow.registry.TRACKERS`; :func:`default_methods` when None.
    overrides : mapping, optional
        ``{field: value}`` applied to every method that has the field, or
        ``{method: {field: value}}``; see :func:`varflow.evaluation.bench.common.split_overrides`.
        The baseline always uses the default ``tvl1`` parameters.
    progress : bool
        A tqdm bar on stderr (only on a terminal).
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.
    baseline : bool
        Add the row ``tvl1 (two-frame)``: ``varflow.flow(frame10, frame11, "tvl1")``.
    crop : (y0, y1, x0, x1), optional
        Score a window of the clip only (frames and ground truth cropped before
        running; for quick tests); it must lie inside the frames.
    warm_up : bool
        Do the untimed warm-up run.

    Returns
    -------
    list of dict
        One row per method, then the baseline: ``dataset`` ("middlebury"),
        ``sequence`` ("RubberWhale"), ``pair`` ("frame10->frame11"), ``ref`` (3),
        ``frames`` (8), ``method``, ``aee`` (px), ``aae`` (degrees), ``aee_noc``
        (None: Middlebury has no occlusion masks), ``seconds``.

    Raises
    ------
    ValueError
        Unknown method or parameter, invalid parameter value or crop.
    FileNotFoundError
        When the data are missing.
    """
    from tqdm import tqdm

    methods, params = tracker_params(default_methods() if methods is None else methods,
                                       overrides)
    crop = check_crop(crop)
    frames, ref, gt = load_rubberwhale_clip(root)
    check_crop_fits(crop, frames.shape[1:3], "Middlebury RubberWhale")
    frames, gt = apply_crop(frames, crop, lead=1), apply_crop(gt, crop)
    if warm_up:
        warm_up_methods(methods, params, baseline)
    rows: list[dict[str, Any]] = []
    base = {"dataset": "middlebury", "sequence": "RubberWhale", "pair": "frame10->frame11",
            "ref": ref, "frames": int(frames.shape[0])}
    bar = tqdm(total=len(methods) + int(baseline), desc="middlebury-multiframe", unit="run",
               file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        _run_clip(rows, base, frames, ref, gt, None, None, methods, params, baseline, bar)
    finally:
        bar.close()
    return rows


def run_sintel_multiframe(
    methods: Sequence[str] | None = None,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    *,
    root: str | os.PathLike[str] | None = None,
    snippets: Sequence[SintelSnippet] | None = None,
    passes: Sequence[str] = SINTEL_PASSES,
    clips: Sequence[str] | None = None,
    baseline: bool = True,
    crop: Crop | None = None,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Trajectory methods on the MPI-Sintel snippets, scored on their reference pair.

    A report, without bounds.  For every snippet of :func:`sintel_snippets` each
    method tracks the reference frame's pixels through the snippet's frames; its
    displacement in the next frame is compared with ``frame_N.flo``: AEE and AAE over
    the valid pixels (pixels of the ``invalid`` mask removed when there is one) and
    the AEE over the non-occluded ones when there is an occlusion mask.

    Parameters
    ----------
    methods, overrides, progress, root, baseline, crop, warm_up
        As in :func:`run_middlebury_multiframe` (the baseline is ``tvl1`` from the
        reference to the next frame).
    snippets : sequence of SintelSnippet, optional
        What to run; by default ``sintel_snippets(root, passes, clips)``.
    passes, clips
        Selection passed to :func:`sintel_snippets`.

    Returns
    -------
    list of dict
        Rows as in :func:`run_middlebury_multiframe` with ``dataset``
        ``"sintel-<pass>"``, ``sequence`` ``"<clip> NNNN-MMMM"``, ``pair``
        ``"NNNN->NNNN+1"`` and ``aee_noc`` (None without an occlusion mask).

    Raises
    ------
    ValueError
        Unknown method, parameter or pass.
    FileNotFoundError
        When no snippet with ground truth is found (or a file is missing).
    """
    from tqdm import tqdm

    methods, params = tracker_params(default_methods() if methods is None else methods,
                                       overrides)
    crop = check_crop(crop)
    base_dir = data_root(root)
    if snippets is None:
        snippets = sintel_snippets(base_dir, passes=passes, clips=clips)
    snippets = list(snippets)
    if not snippets:
        raise FileNotFoundError(
            f"no Sintel snippet with ground truth under {base_dir / 'sintel' / 'training'}; "
            f"{DATA_HINT}"
        )
    if warm_up:
        warm_up_methods(methods, params, baseline)
    rows: list[dict[str, Any]] = []
    bar = tqdm(total=len(snippets) * (len(methods) + int(baseline)), desc="sintel-multiframe",
               unit="run", file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        for s in snippets:
            frames, gt, occ, inv = load_snippet(s, base_dir)
            frames, gt = apply_crop(frames, crop, lead=1), apply_crop(gt, crop)
            occ, inv = apply_crop(occ, crop), apply_crop(inv, crop)
            base = {"dataset": f"sintel-{s.pass_}", "sequence": s.name, "pair": s.pair,
                    "ref": s.ref, "frames": len(s.numbers)}
            valid = None if inv is None else ~inv
            _run_clip(rows, base, frames, s.ref, gt, valid, occ, methods, params, baseline, bar)
    finally:
        bar.close()
    return rows
