"""Accuracy measures for dense multi-frame trajectories.

Trajectories are ``(F, H, W, 2)`` arrays of displacements relative to the
reference frame: reference pixel ``x`` is at ``x + traj[n, x]`` in frame ``n``
(``[..., 0]`` = u, ``[..., 1]`` = v).  The measures pool the endpoint error
``||est[n, x] - gt[n, x]||`` over all frames (except, by default, the
reference frame, where both are zero by definition) and all *visible* points,
as trajectory benchmarks do (Garg, Roussos & Agapito 2013; Gibson & Marques
2016, ch. 4 report the RMS endpoint error over all frames).

Unknown values follow :mod:`varflow.evaluation.metrics`: a ground-truth vector
is valid where both components are finite with ``|value| <= 1e9``.  An
estimated vector that is NaN, infinite or ``> 1e9`` where the ground truth is
valid and visible counts as *missing*: it is left out of every average and its
share is reported as ``"missing"`` (percent, with a logged warning) so that it is
never dropped silently.  Averages over an empty set are NaN.

References
----------
R. Garg, A. Roussos, L. Agapito, "A variational approach to video registration
with subspace constraints", IJCV 104(3), 286-314, 2013.

J. Gibson, O. Marques, "Optical Flow and Trajectory Estimation Methods",
SpringerBriefs in Computer Science, Springer 2016, ch. 4.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

__all__ = ["trajectory_errors", "frame11_flow", "occlusion_accuracy"]

logger = logging.getLogger(__name__)

_UNKNOWN_THRESHOLD = 1e9


def _as_traj(traj: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(traj)
    if arr.ndim != 4 or arr.shape[3] != 2:
        raise ValueError(f"{name}: expected trajectories of shape (F, H, W, 2), got {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name}: expected real-valued trajectories, got dtype {arr.dtype}")
    if arr.shape[0] < 1 or arr.shape[1] < 1 or arr.shape[2] < 1:
        raise ValueError(f"{name}: empty trajectories of shape {arr.shape}")
    return arr


def _known(arr: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(arr) & (np.abs(arr) <= _UNKNOWN_THRESHOLD)
    return ok.all(axis=-1)


def _check_index(value: Any, name: str, n: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    if not 0 <= value < n:
        raise ValueError(f"{name}: expected an index in [0, {n}), got {value}")
    return int(value)


def _infer_ref(gt: np.ndarray, known: np.ndarray) -> int:
    zero = np.all(known, axis=(1, 2)) & np.all(gt == 0, axis=(1, 2, 3))
    idx = np.flatnonzero(zero)
    if idx.size != 1:
        raise ValueError(
            "ref: cannot infer the reference frame from gt "
            f"({idx.size} frames are identically zero); pass ref explicitly"
        )
    return int(idx[0])


def trajectory_errors(
    est: np.ndarray,
    gt: np.ndarray,
    visibility: np.ndarray | None = None,
    exclude_ref: bool = True,
    ref: int | None = None,
) -> dict[str, Any]:
    """Endpoint-error statistics of estimated trajectories over frames and visible points.

    Parameters
    ----------
    est, gt : ndarray, shape (F, H, W, 2)
        Estimated and ground-truth displacements relative to the reference frame.
    visibility : ndarray, shape (F, H, W), bool, optional
        Only points where it is True count (e.g.
        :attr:`~varflow.generators.sequences.SyntheticSequence.visibility`);
        default all.
    exclude_ref : bool
        Leave the reference frame out (its ground truth is zero by definition,
        so including it only dilutes the averages).
    ref : int, optional
        The reference frame; if omitted and ``exclude_ref`` is True it is the
        unique frame where ``gt`` is identically zero (ValueError if there is
        not exactly one).

    Returns
    -------
    dict
        ``"epe"`` : mean endpoint error (px) over the pooled (frame, point) set;
        ``"rms"`` : root-mean-square endpoint error over the same set;
        ``"max"`` : largest endpoint error;
        ``"epe_per_frame"``, ``"rms_per_frame"`` : ndarray, shape (F,), float64,
        the same per frame (NaN for the excluded reference frame and frames
        without points);
        ``"n_points"`` : int, number of (frame, point) pairs averaged;
        ``"missing"`` : percent of the valid visible pairs whose estimate is
        NaN / unknown (excluded from the averages);
        ``"ref"`` : the excluded reference frame, or None.

    Raises
    ------
    ValueError
        On arrays of the wrong shape or dtype (naming the argument) or an
        invalid / non-inferable ``ref``.

    Examples
    --------
    >>> gt = np.zeros((3, 2, 2, 2), np.float32); gt[0] = 1.0; gt[2] = -1.0
    >>> r = trajectory_errors(gt + np.array([0.3, 0.4], np.float32), gt)
    >>> round(r["epe"], 6), round(r["rms"], 6), r["ref"], r["n_points"]
    (0.5, 0.5, 1, 8)
    """
    e = _as_traj(est, "est")
    g = _as_traj(gt, "gt")
    if e.shape != g.shape:
        raise ValueError(f"est and gt differ in shape: {e.shape} vs {g.shape}")
    n_frames = g.shape[0]
    g = g.astype(np.float64)
    gt_ok = _known(g)
    if visibility is not None:
        vis = np.asarray(visibility)
        if vis.shape != g.shape[:3]:
            raise ValueError(f"visibility: expected shape {g.shape[:3]}, got {vis.shape}")
        if vis.dtype != np.bool_:
            raise ValueError(f"visibility: expected a boolean array, got dtype {vis.dtype}")
        gt_ok &= vis
    used_ref: int | None = None
    if exclude_ref:
        used_ref = _infer_ref(g, _known(g)) if ref is None else _check_index(ref, "ref", n_frames)
        gt_ok[used_ref] = False
    elif ref is not None:
        _check_index(ref, "ref", n_frames)

    e = e.astype(np.float64)
    est_ok = _known(e)
    used = gt_ok & est_ok
    n_missing = int(np.count_nonzero(gt_ok & ~est_ok))
    with np.errstate(invalid="ignore", over="ignore"):
        d = e - g
        err = np.hypot(d[..., 0], d[..., 1])
    err = np.where(used, err, 0.0)

    counts = used.sum(axis=(1, 2))
    sums = err.sum(axis=(1, 2))
    sq = (err**2).sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        epe_f = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
        rms_f = np.where(counts > 0, np.sqrt(sq / np.maximum(counts, 1)), np.nan)
    n_points = int(counts.sum())
    n_valid = n_points + n_missing
    if n_points == 0:
        logger.warning("trajectory_errors: no valid visible points to average; returning NaN")
        epe = rms = emax = float("nan")
    else:
        epe = float(sums.sum() / n_points)
        rms = float(np.sqrt(sq.sum() / n_points))
        emax = float(err.max())
    missing = 100.0 * n_missing / n_valid if n_valid else float("nan")
    if n_missing:
        logger.warning(
            "trajectory_errors: %.3g%% of the valid visible points have no estimate (excluded)",
            missing,
        )
    return {
        "epe": epe,
        "rms": rms,
        "max": emax,
        "epe_per_frame": epe_f,
        "rms_per_frame": rms_f,
        "n_points": n_points,
        "missing": missing,
        "ref": used_ref,
    }


def frame11_flow(traj: np.ndarray, ref: int, step: int = 1) -> np.ndarray:
    """The two-frame flow from the reference frame to frame ``ref + step``.

    For comparing a trajectory estimate with a two-frame ground truth (or a
    two-frame method) between the reference frame and its neighbour, the
    protocol of Gibson & Marques (2016, ch. 4) on the flag benchmark.

    Parameters
    ----------
    traj : ndarray, shape (F, H, W, 2)
        Trajectories relative to frame ``ref``.
    ref : int
        Reference frame index in ``[0, F)``.
    step : int
        Frame offset (default 1, the next frame; negative for earlier frames).

    Returns
    -------
    ndarray, shape (H, W, 2), float32
        ``traj[ref + step]`` (a copy): the flow from frame ``ref`` to frame
        ``ref + step``.

    Raises
    ------
    ValueError
        If ``traj`` is not ``(F, H, W, 2)`` or ``ref`` / ``ref + step`` is out of
        range.
    """
    t = _as_traj(traj, "traj")
    n_frames = t.shape[0]
    ref = _check_index(ref, "ref", n_frames)
    if isinstance(step, bool) or not isinstance(step, int | np.integer):
        raise ValueError(f"step: expected an integer, got {step!r}")
    target = ref + int(step)
    if not 0 <= target < n_frames:
        raise ValueError(f"step: frame ref + step = {target} is outside [0, {n_frames})")
    return np.array(t[target], dtype=np.float32, copy=True)


def occlusion_accuracy(estimated: np.ndarray, truth: np.ndarray, ref: int | None = None
                       ) -> dict[str, float]:
    """TAP-Vid's occlusion accuracy and the share of hidden points detected.

    Doersch et al., "TAP-Vid: a benchmark for tracking any point in a video",
    NeurIPS 2022: the fraction of (point, frame) pairs whose visible / hidden
    label is right.

    Parameters
    ----------
    estimated, truth : ndarray, shape (F, H, W), bool
        Visibility (True = visible).
    ref : int, optional
        Reference frame, left out (visible by definition in both).

    Returns
    -------
    dict
        ``accuracy``: fraction of (frame, pixel) pairs whose label is right;
        ``hidden_recall``: fraction of the truly hidden pairs labelled hidden
        (NaN if none); ``hidden_precision``: fraction of the pairs labelled hidden
        that are (NaN if none); ``hidden_true``, ``hidden_estimated``: shares.
    """
    e = np.asarray(estimated, bool)
    t = np.asarray(truth, bool)
    if e.shape != t.shape or e.ndim != 3:
        raise ValueError(f"estimated: expected the shape of truth (F, H, W), got {e.shape} "
                         f"and {t.shape}")
    keep = np.ones(e.shape[0], bool)
    if ref is not None:
        keep[ref] = False
    e, t = e[keep], t[keep]
    hid_t, hid_e = ~t, ~e
    n_t, n_e = int(hid_t.sum()), int(hid_e.sum())
    both = int((hid_t & hid_e).sum())
    return {
        "accuracy": float((e == t).mean()) if e.size else float("nan"),
        "hidden_recall": both / n_t if n_t else float("nan"),
        "hidden_precision": both / n_e if n_e else float("nan"),
        "hidden_true": float(hid_t.mean()) if e.size else float("nan"),
        "hidden_estimated": float(hid_e.mean()) if e.size else float("nan"),
    }
