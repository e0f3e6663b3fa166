"""Occlusions from a pair of flows (the forward-backward check) and the photometric error.

A pixel ``x`` of the first frame is *hidden in the second* when its flow leaves the
image or comes back elsewhere through the backward flow (Sundaram, Brox & Keutzer
2010)::

    |F(x) + B(x + F(x))| > τ + κ |F(x)|

with ``B`` sampled bilinearly.  :func:`hidden_mask` is a fused Numba kernel, and
:func:`hidden_mask_numpy` its NumPy reference (bilinear warping, then the test).
:func:`photometric_error` is the brightness-constancy error of a flow, the mean over
the channels of ``|I0(x) − I1(x + F(x))|`` (``I1`` sampled bilinearly, the border
replicated), likewise with :func:`photometric_error_numpy` as its reference.

References
----------
N. Sundaram, T. Brox, K. Keutzer, "Dense point trajectories by GPU-accelerated large
displacement optical flow", ECCV 2010.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .warp import bilinear_at, bilinear_cell, warp_bilinear_numpy

__all__ = ["hidden_mask", "hidden_mask_numpy", "photometric_error", "photometric_error_numpy"]


def _check(forward: np.ndarray, backward: np.ndarray, tolerance: float,
           relative: float) -> tuple[np.ndarray, np.ndarray]:
    forward = np.asarray(forward, np.float32)
    backward = np.asarray(backward, np.float32)
    if forward.ndim != 3 or forward.shape[2] != 2 or backward.shape != forward.shape:
        raise ValueError(f"hidden_mask: flows {forward.shape} and {backward.shape} must both "
                         "be (H, W, 2)")
    if not (np.isfinite(tolerance) and np.isfinite(relative)):
        raise ValueError("hidden_mask: tolerance and relative must be finite")
    return forward, backward


def hidden_mask_numpy(forward: np.ndarray, backward: np.ndarray, tolerance: float,
                      relative: float) -> np.ndarray:
    """Reference engine of :func:`hidden_mask`."""
    forward, backward = _check(forward, backward, tolerance, relative)
    sampled, inside = warp_bilinear_numpy(backward, forward)
    err = np.hypot(forward[..., 0] + sampled[..., 0], forward[..., 1] + sampled[..., 1])
    limit = np.float32(tolerance) + np.float32(relative) * np.hypot(forward[..., 0],
                                                                    forward[..., 1])
    return ~inside | ~(err <= limit)


@nb.njit(cache=True, parallel=True)
def _hidden_kernel(forward, backward, tolerance, relative, out):
    h, w = out.shape
    xmax = np.float32(w - 1.0)
    ymax = np.float32(h - 1.0)
    for i in nb.prange(h):
        for j in range(w):
            u = forward[i, j, 0]
            v = forward[i, j, 1]
            x = np.float32(j) + u
            y = np.float32(i) + v
            if not (x >= 0 and x <= xmax and y >= 0 and y <= ymax):  # also NaN
                out[i, j] = True
                continue
            x0, x1, y0, y1, fx, fy = bilinear_cell(x, y, h, w)
            bu = bilinear_at(backward, 0, x0, x1, y0, y1, fx, fy)
            bv = bilinear_at(backward, 1, x0, x1, y0, y1, fx, fy)
            err = np.hypot(u + bu, v + bv)
            out[i, j] = not (err <= tolerance + relative * np.hypot(u, v))


def hidden_mask(forward: np.ndarray, backward: np.ndarray, tolerance: float,
                relative: float) -> np.ndarray:
    """Pixels of the first frame hidden in the second: bounds and forward-backward check.

    Parameters
    ----------
    forward, backward : ndarray, shape (H, W, 2)
        The flows first → second and second → first.
    tolerance, relative : float
        τ (pixels) and κ: a pixel passes when
        ``|F(x) + B(x + F(x))| <= τ + κ |F(x)|``.

    Returns
    -------
    ndarray, shape (H, W), bool
        True where the pixel leaves the image (or its flow is NaN) or fails the
        check.
    """
    forward, backward = _check(forward, backward, tolerance, relative)
    out = np.empty(forward.shape[:2], np.bool_)
    _hidden_kernel(np.ascontiguousarray(forward), np.ascontiguousarray(backward),
                   np.float32(tolerance), np.float32(relative), out)
    return out


def _check_photo(frame0: np.ndarray, frame1: np.ndarray,
                 flow: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    frame0 = np.asarray(frame0, np.float32)
    frame1 = np.asarray(frame1, np.float32)
    flow = np.asarray(flow, np.float32)
    if frame0.ndim != 3 or frame1.shape != frame0.shape or flow.shape != frame0.shape[:2] + (2,):
        raise ValueError(f"photometric_error: frames {frame0.shape}, {frame1.shape} and flow "
                         f"{flow.shape} do not match")
    return frame0, frame1, flow


def photometric_error_numpy(frame0: np.ndarray, frame1: np.ndarray,
                            flow: np.ndarray) -> np.ndarray:
    """Reference engine of :func:`photometric_error`."""
    frame0, frame1, flow = _check_photo(frame0, frame1, flow)
    warped, _ = warp_bilinear_numpy(frame1, flow)
    return np.abs(frame0 - warped).mean(axis=2).astype(np.float32)


@nb.njit(cache=True, parallel=True)
def _photo_kernel(frame0, frame1, flow, out):
    h, w, k = frame0.shape
    for i in nb.prange(h):
        for j in range(w):
            x0, x1, y0, y1, fx, fy = bilinear_cell(np.float32(j) + flow[i, j, 0],
                                                   np.float32(i) + flow[i, j, 1], h, w)
            acc = np.float32(0.0)
            for c in range(k):
                acc += abs(frame0[i, j, c] - bilinear_at(frame1, c, x0, x1, y0, y1, fx, fy))
            out[i, j] = acc / np.float32(k)


def photometric_error(frame0: np.ndarray, frame1: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """The brightness-constancy error of ``flow``: ``mean_c |I0(x) − I1(x + F(x))|``.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, C)
    flow : ndarray, shape (H, W, 2)
        From ``frame0`` to ``frame1``; outside the image ``frame1``'s border is
        replicated, a NaN flow samples its top-left pixel (as
        :func:`varflow.ops.warp.warp_bilinear`).

    Returns
    -------
    ndarray, shape (H, W), float32
        In the units of the frames.
    """
    frame0, frame1, flow = _check_photo(frame0, frame1, flow)
    out = np.empty(frame0.shape[:2], np.float32)
    _photo_kernel(np.ascontiguousarray(frame0), np.ascontiguousarray(frame1),
                  np.ascontiguousarray(flow), out)
    return out
