"""Accuracy measures for optical flow.

* AEE, average endpoint error: mean of ``||w_est - w_gt||`` (Otte & Nagel 1994;
  Baker et al. 2011).
* AAE, average angular error: mean angle between the space-time vectors
  ``(u, v, 1)`` and ``(u_gt, v_gt, 1)`` (Barron, Fleet & Beauchemin 1994;
  Baker et al. 2011), in degrees.
* RMS endpoint error, and outlier rates ``R_t`` = percentage of pixels with an
  endpoint error above ``t`` pixels (Middlebury R1/R3/R5-style statistics).
* Photometric residual: mean ``|I0(x) - I1(x + w(x))|`` for images with no ground
  truth.

Ground-truth pixels are valid where both components are finite and at most
``1e9`` in magnitude (``.flo`` stores unknown flow as ``1e10``), optionally
restricted further by a boolean mask.  Estimated pixels that are unknown (same
rule) where the ground truth is valid are left out of the averages;
:func:`evaluate` reports their share as ``"missing"`` so they are never
dropped silently.

References
----------
Baker, Scharstein, Lewis, Roth, Black & Szeliski, "A Database and Evaluation
Methodology for Optical Flow", IJCV 92(1):1-31, 2011.
Barron, Fleet & Beauchemin, "Performance of Optical Flow Techniques", IJCV
12(1):43-77, 1994.
"""

from __future__ import annotations

import logging

import numpy as np

from varflow._validate import check_pair
from varflow.ops.warp import warp_bicubic

__all__ = [
    "valid_mask",
    "endpoint_error_map",
    "endpoint_error",
    "angular_error_map",
    "angular_error",
    "rms_endpoint_error",
    "outlier_rate",
    "evaluate",
    "photometric_residual_map",
    "photometric_residual",
]

logger = logging.getLogger(__name__)

_UNKNOWN_THRESHOLD = 1e9


def _as_flow(flow: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(flow)
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise ValueError(f"{name}: expected a flow of shape (H, W, 2), got {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name}: expected a real-valued flow, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def _known(flow: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(flow) & (np.abs(flow) <= _UNKNOWN_THRESHOLD)
    return ok.all(axis=-1)


def _as_mask(mask: np.ndarray | None, shape: tuple[int, int], name: str) -> np.ndarray | None:
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {m.shape}")
    if m.dtype != np.bool_:
        raise ValueError(f"{name}: expected a boolean mask, got dtype {m.dtype}")
    return m


def valid_mask(gt: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Pixels where the ground truth is known (and the optional mask is true).

    Parameters
    ----------
    gt : ndarray, shape (H, W, 2)
        Ground-truth flow.
    mask : ndarray, shape (H, W), bool, optional
        Extra restriction, e.g. a non-occlusion mask.

    Returns
    -------
    ndarray, shape (H, W), bool
        True where both components are finite with ``|value| <= 1e9`` and ``mask``
        is true.
    """
    g = _as_flow(gt, "gt")
    valid = _known(g)
    m = _as_mask(mask, g.shape[:2], "mask")
    return valid if m is None else valid & m


def _prepare(
    est: np.ndarray, gt: np.ndarray, mask: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return (est, gt, pixels used, valid-gt pixels where est is unknown)."""
    e = _as_flow(est, "est")
    g = _as_flow(gt, "gt")
    if e.shape != g.shape:
        raise ValueError(f"est and gt differ in shape: {e.shape} vs {g.shape}")
    valid = valid_mask(g, mask)
    est_ok = _known(e)
    return e, g, valid & est_ok, valid & ~est_ok


def _mean(values: np.ndarray, what: str) -> float:
    if values.size == 0:
        logger.warning("%s: no valid pixels to average; returning NaN", what)
        return float("nan")
    return float(values.mean())


def _epe(e: np.ndarray, g: np.ndarray) -> np.ndarray:
    d = e - g
    return np.hypot(d[..., 0], d[..., 1])


def _ae_deg(e: np.ndarray, g: np.ndarray) -> np.ndarray:
    num = e[..., 0] * g[..., 0] + e[..., 1] * g[..., 1] + 1.0
    den = np.sqrt((e[..., 0] ** 2 + e[..., 1] ** 2 + 1.0) * (g[..., 0] ** 2 + g[..., 1] ** 2 + 1.0))
    return np.degrees(np.arccos(np.clip(num / den, -1.0, 1.0)))


def endpoint_error_map(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-pixel endpoint error ``||est - gt||``.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W, 2)

    Returns
    -------
    ndarray, shape (H, W), float32
        NaN where the ground truth or the estimate is unknown.
    """
    e, g, used, _ = _prepare(est, gt, None)
    with np.errstate(invalid="ignore", over="ignore"):
        out = _epe(e, g)
    out[~used] = np.nan
    return out.astype(np.float32)


def endpoint_error(est: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Average endpoint error (AEE) in pixels.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W, 2)
    mask : ndarray, shape (H, W), bool, optional
        Only pixels where the mask is true count.

    Returns
    -------
    float
        Mean of ``||est - gt||`` over pixels with known ground truth and estimate
        (and ``mask``); NaN, with a logged warning, if there are none.
    """
    e, g, used, _ = _prepare(est, gt, mask)
    return _mean(_epe(e[used], g[used]), "endpoint_error")


def rms_endpoint_error(est: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Root-mean-square endpoint error in pixels, over the same pixels as :func:`endpoint_error`."""
    e, g, used, _ = _prepare(est, gt, mask)
    return float(np.sqrt(_mean(_epe(e[used], g[used]) ** 2, "rms_endpoint_error")))


def angular_error_map(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-pixel angular error in degrees (see :func:`angular_error`).

    Returns
    -------
    ndarray, shape (H, W), float32
        NaN where the ground truth or the estimate is unknown.
    """
    e, g, used, _ = _prepare(est, gt, None)
    out = np.full(e.shape[:2], np.nan)
    out[used] = _ae_deg(e[used], g[used])
    return out.astype(np.float32)


def angular_error(est: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Average angular error (AAE) in degrees.

    The angle between the space-time direction vectors ``(u, v, 1)`` and
    ``(u_gt, v_gt, 1)``: ``arccos((u u_gt + v v_gt + 1) / sqrt((u² + v² + 1)(u_gt² + v_gt² + 1)))``
    with the cosine clipped to ``[-1, 1]`` (Barron et al. 1994; Baker et al. 2011).

    Parameters
    ----------
    est, gt : ndarray, shape (H, W, 2)
    mask : ndarray, shape (H, W), bool, optional

    Returns
    -------
    float
        Mean angle over the pixels used by :func:`endpoint_error`; NaN if none.
    """
    e, g, used, _ = _prepare(est, gt, mask)
    return _mean(_ae_deg(e[used], g[used]), "angular_error")


def outlier_rate(
    est: np.ndarray, gt: np.ndarray, threshold: float, mask: np.ndarray | None = None
) -> float:
    """Percentage of pixels whose endpoint error exceeds ``threshold`` pixels.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W, 2)
    threshold : float
        Non-negative, in pixels (strict inequality: ``EPE > threshold``).
    mask : ndarray, shape (H, W), bool, optional

    Returns
    -------
    float
        In ``[0, 100]`` over the pixels used by :func:`endpoint_error`; NaN if none.
    """
    threshold = float(threshold)
    if not (np.isfinite(threshold) and threshold >= 0):
        raise ValueError(f"outlier_rate: threshold must be finite and >= 0, got {threshold!r}")
    e, g, used, _ = _prepare(est, gt, mask)
    return 100.0 * _mean(_epe(e[used], g[used]) > threshold, "outlier_rate")


def evaluate(
    est: np.ndarray,
    gt: np.ndarray,
    mask: np.ndarray | None = None,
    occlusion: np.ndarray | None = None,
) -> dict[str, float]:
    """All the standard error measures of an estimate against ground truth.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W, 2)
    mask : ndarray, shape (H, W), bool, optional
        Restricts every measure to pixels where it is true.
    occlusion : ndarray, shape (H, W), bool, optional
        True where a pixel is occluded; adds ``"aee_noc"`` (non-occluded) and
        ``"aee_occ"`` (occluded).

    Returns
    -------
    dict
        ``"aee"`` (px), ``"aae"`` (degrees), ``"rms"`` (px), ``"r1"``, ``"r3"``,
        ``"r5"`` (percent of pixels with EPE above 1, 3, 5 px), ``"missing"``
        (percent of valid ground-truth pixels where the estimate is NaN or
        unknown; they are excluded from the other measures) and, with
        ``occlusion``, ``"aee_noc"`` and ``"aee_occ"``.  Every value is a plain
        Python ``float``, not a NumPy scalar (the dict prints as
        ``{'aee': 0.25, ...}``, not ``np.float64(0.25)``).  Averages over an empty set are NaN.
    """
    e, g, used, missing = _prepare(est, gt, mask)
    occ = _as_mask(occlusion, e.shape[:2], "occlusion")
    epe = _epe(e[used], g[used])
    n_valid = int(used.sum() + missing.sum())
    result = {
        "aee": _mean(epe, "evaluate: aee"),
        "aae": _mean(_ae_deg(e[used], g[used]), "evaluate: aae"),
        "rms": float(np.sqrt(_mean(epe**2, "evaluate: rms"))),
        "r1": 100.0 * _mean(epe > 1.0, "evaluate: r1"),
        "r3": 100.0 * _mean(epe > 3.0, "evaluate: r3"),
        "r5": 100.0 * _mean(epe > 5.0, "evaluate: r5"),
        "missing": 100.0 * float(missing.sum()) / n_valid if n_valid else float("nan"),
    }
    if result["missing"] > 0:
        logger.warning(
            "evaluate: %.3g%% of the valid ground-truth pixels have no estimate (excluded)",
            result["missing"],
        )
    if occ is not None:
        full = _epe(e, g)
        result["aee_noc"] = _mean(full[used & ~occ], "evaluate: aee_noc")
        result["aee_occ"] = _mean(full[used & occ], "evaluate: aee_occ")
    return {key: float(value) for key, value in result.items()}


def photometric_residual_map(
    frame0: np.ndarray,
    frame1: np.ndarray,
    flow: np.ndarray,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Per-pixel brightness-constancy residual ``mean_c |I0(x) - I1(x + w(x))|``.

    ``I1`` is warped backwards with bicubic interpolation
    (:func:`varflow.ops.warp.warp_bicubic`).  Intensities are scaled to ``[0, 1]``
    (``uint8`` / 255, ``uint16`` / 65535; float images must already be in
    ``[0, 1]``).

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        Same shape.
    flow : ndarray, shape (H, W, 2)
        Flow from ``frame0`` to ``frame1``.
    mask : ndarray, shape (H, W), bool, optional
        Pixels to evaluate.

    Returns
    -------
    ndarray, shape (H, W), float32
        Mean absolute difference over the channels; NaN where ``x + w(x)`` falls
        outside the image, the flow is NaN, or ``mask`` is false.
    """
    i0, i1 = check_pair(frame0, frame1)
    w = _as_flow(flow, "flow")
    if w.shape[:2] != i0.shape[:2]:
        raise ValueError(f"flow {w.shape} does not match the frames {i0.shape}")
    m = _as_mask(mask, i0.shape[:2], "mask")
    w32 = w.astype(np.float32)
    w32[~_known(w)] = np.nan  # treated as outside by the warp
    warped, inside = warp_bicubic(i1, w32)
    res = np.abs(i0 - warped).mean(axis=-1)
    keep = inside if m is None else inside & m
    res[~keep] = np.nan
    return res.astype(np.float32)


def photometric_residual(
    frame0: np.ndarray,
    frame1: np.ndarray,
    flow: np.ndarray,
    mask: np.ndarray | None = None,
) -> float:
    """Mean photometric residual over pixels whose target lies inside the image.

    See :func:`photometric_residual_map` for the parameters.

    Returns
    -------
    float
        Mean of the residual map over its finite entries (intensities in
        ``[0, 1]``); NaN, with a logged warning, if no pixel qualifies.
    """
    res = photometric_residual_map(frame0, frame1, flow, mask)
    return _mean(res[np.isfinite(res)].astype(np.float64), "photometric_residual")
