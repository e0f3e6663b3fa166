"""Stabilisation against gate weave: :func:`stabilise` and :class:`StabiliseParams`.

Why: a film frame sits a little differently in the gate at every exposure (and again
at the scan), so the whole picture jitters by a few pixels and a fraction of a
degree from frame to frame; the camera's intended motion (a pan, a zoom) is slow.
Removing the fast part of the global motion and keeping the slow part gives a steady
picture without freezing the camera.

The method, per clip:

1. The dense flow between consecutive frames (:func:`varflow.flow`, on reduced frames,
   both ways for the forward-backward check :func:`varflow.consistency`).
2. A robust global motion per pair (translation, similarity or affine; RANSAC over a
   grid of flow samples, then iteratively reweighted least squares with Tukey's
   biweight), each sample weighted by its forward-backward consistency and by its
   texture (the smaller eigenvalue of the structure tensor: the flow of flat areas is
   only interpolated).  Independently moving objects are outliers of the fit.
3. The motions chained into an absolute camera path (frame 0's pixels to frame
   ``f``'s), written about the frame centre as translation, angle and log-scale
   (similarity; the matrix entries for an affine model).
4. The path smoothed by a Gaussian-weighted local polynomial regression (degree 1 by
   default: a constant-speed pan or zoom is kept exactly, up to the clip's ends, where
   a plain Gaussian blur of the path would bend it).
5. Each frame warped by its correction, the smoothed path times the inverse path, with
   bicubic interpolation (:func:`cv2.warpAffine`, float32).  The pixels the correction
   brings in from outside the frame are filled from the neighbouring frames, nearest in
   time first, each warped by the global motion onto the stabilised frame (with a
   per-channel level match on a band along the hole, against flicker); reflection of
   the frame itself is the last resort.  No black border, no crop.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from scipy import ndimage

from .._validate import check_field
from ..registry import REPAIR
from .denoise import _as_clip, _to_dtype

__all__ = ["MODELS", "StabiliseParams", "fit_global_motion", "pair_flows", "smooth_path",
           "stabilise"]

log = logging.getLogger(__name__)

Callback = Callable[[int, int], None]

#: The global motion models and their numbers of parameters.
MODELS = {"translation": 2, "similarity": 4, "affine": 6}
_INTERPOLATIONS = {"cubic": cv2.INTER_CUBIC, "linear": cv2.INTER_LINEAR}
#: Smallest summed sample weight (in samples of full weight) a pair's fit needs; below it
#: the pair's motion is taken as the identity (a flat or blank picture).
_MIN_WEIGHT = 12.0
#: Tukey's biweight constant, in multiples of ``inlier``.
_TUKEY = 2.0
#: Samples on which the RANSAC hypotheses are scored.
_SCORE_SAMPLES = 2000
#: Iterations of the reweighted least squares after RANSAC.
_IRLS_ITERATIONS = 8
#: Half-width (px) of the band along a hole on which a neighbour's levels are matched.
_BAND = 6
#: Fewest band pixels for a level match (otherwise the neighbour is used as it is).
_BAND_MIN = 20


@dataclass(frozen=True)
class StabiliseParams:
    """Parameters of :func:`stabilise`.

    Attributes
    ----------
    model : str
        The global motion between frames: ``"translation"`` (dx, dy), ``"similarity"``
        (translation, rotation, uniform scale; gate weave plus pans and zooms) or
        ``"affine"`` (six parameters: also shear and anisotropic scale, which weave
        does not have).  Default ``"similarity"``.
    smooth : float
        σ of the Gaussian weights of the path smoother, in frames: motion much faster
        than this is removed, motion much slower kept.  ``math.inf`` fits one
        polynomial of ``degree`` to the whole clip (degree 0: a locked-off camera);
        0 keeps the path (no correction).  Default 12.
    degree : int
        Degree of the local polynomial fitted to the path (0, 1 or 2).  1 keeps a
        constant-speed pan or zoom exactly, also at the clip's ends; 0 is the plain
        Gaussian average (bends a pan at the ends).  Default 1.
    shrink : bool
        Shrink the local slope (and curvature) of the path towards 0 by its
        significance (positive-part James-Stein factor ``max(0, 1 - var / slope²)``,
        ``var`` the slope's sampling variance from the path's scatter): a slope the
        weave alone could explain is dropped, so a still shot does not drift, while a
        real pan, many times its standard error, is kept.  Default True.
    flow_method : str
        The two-frame method of the flows between consecutive frames (a name of
        :func:`varflow.methods`).  Default ``"tvl1-fast"``.
    flow_max_pixels : int
        Frames of more pixels than this get their flows on a reduced copy (the global
        fit needs no detail); 0: never.  Default 100 000.
    flow_blur : float
        σ (px) of a Gaussian applied to the frames before their flows (against noise
        and grain).  Default 1.
    fb_check : bool
        Compute the backward flows too and drop the samples that fail the
        forward-backward check (occlusions, wrong flow); False halves the flow time.
        Default True.
    fb_tolerance : float
        α₂ of the forward-backward check, px² (:func:`varflow.consistency`).
        Default 1.
    samples : int
        Approximate number of flow samples per pair (a regular grid).  Default 6000.
    inlier : float
        Residual (px, full-resolution frame) under which a sample agrees with a RANSAC
        hypothesis; the biweight of the refinement reaches 0 at twice this.  Tight:
        the flow next to a moving object is dragged by it and biases a loose fit.
        Default 0.5.
    ransac_iterations : int
        Hypotheses drawn per pair (minimal sample sets, drawn with probability
        proportional to the samples' weights, scored on at most 2000 of them).
        Default 200.
    seed : int
        Seed of the local generator of the RANSAC draws.  Default 0.
    fill_radius : int
        Frames each side searched for the pixels brought in from outside the frame;
        0 fills them by reflection only.  Default 4.
    fill_match : bool
        Match a neighbour's levels (per-channel offset, median over a band along the
        hole) before filling from it: no seam under flicker.  Default True.
    interpolation : str
        ``"cubic"`` (bicubic, default) or ``"linear"`` resampling of the frames.
    """

    model: str = "similarity"
    smooth: float = 12.0
    degree: int = 1
    shrink: bool = True
    flow_method: str = "tvl1-fast"
    flow_max_pixels: int = 100_000
    flow_blur: float = 1.0
    fb_check: bool = True
    fb_tolerance: float = 1.0
    samples: int = 6000
    inlier: float = 0.5
    ransac_iterations: int = 200
    seed: int = 0
    fill_radius: int = 4
    fill_match: bool = True
    interpolation: str = "cubic"

    def __post_init__(self) -> None:
        from ..registry import FLOW

        def integer(name: str, low: int, high: int | None = None) -> None:
            v = getattr(self, name)
            ok = isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= low \
                and (high is None or v <= high)
            rng = f">= {low}" if high is None else f"in [{low}, {high}]"
            check_field(ok, name, f"must be an integer {rng}, got {v!r}")

        def number(name: str, low: float, allow_inf: bool = False, open_low: bool = False
                   ) -> None:
            v = getattr(self, name)
            ok = isinstance(v, int | float | np.integer | np.floating) \
                and not isinstance(v, bool) and not math.isnan(v) \
                and (allow_inf or math.isfinite(v)) and (v > low if open_low else v >= low)
            check_field(ok, name, f"must be a {'' if allow_inf else 'finite '}number "
                        f"{'>' if open_low else '>='} {low:g}, got {v!r}")

        check_field(self.model in MODELS, "model",
                    f"expected one of {', '.join(MODELS)}, got {self.model!r}")
        number("smooth", 0.0, allow_inf=True)
        integer("degree", 0, 2)
        check_field(isinstance(self.shrink, bool | np.bool_), "shrink",
                    f"must be True or False, got {self.shrink!r}")
        check_field(isinstance(self.flow_method, str) and FLOW.get(self.flow_method)
                    is not None, "flow_method",
                    f"unknown two-frame method {self.flow_method!r}; available: "
                    f"{', '.join(FLOW.names())}")
        integer("flow_max_pixels", 0)
        number("flow_blur", 0.0)
        check_field(isinstance(self.fb_check, bool | np.bool_), "fb_check",
                    f"must be True or False, got {self.fb_check!r}")
        number("fb_tolerance", 0.0)
        integer("samples", 16)
        number("inlier", 0.0, open_low=True)
        integer("ransac_iterations", 1)
        integer("seed", 0)
        integer("fill_radius", 0)
        check_field(isinstance(self.fill_match, bool | np.bool_), "fill_match",
                    f"must be True or False, got {self.fill_match!r}")
        check_field(self.interpolation in _INTERPOLATIONS, "interpolation",
                    f"expected one of {', '.join(_INTERPOLATIONS)}, got {self.interpolation!r}")


# --------------------------------------------------------------------------- global fit


def _design(x: np.ndarray, model: str) -> np.ndarray:
    """Design matrix ``(N, 2, k)`` of ``y = M(x)`` linear in the model's parameters.

    Parameters: translation ``(tx, ty)``; similarity ``(a, b, tx, ty)`` with
    ``A = [[a, -b], [b, a]]``; affine ``(a00, a01, a10, a11, tx, ty)``."""
    n = x.shape[0]
    one, zero = np.ones(n), np.zeros(n)
    px, py = x[:, 0], x[:, 1]
    if model == "translation":
        rows = [[one, zero], [zero, one]]
    elif model == "similarity":
        rows = [[px, -py, one, zero], [py, px, zero, one]]
    else:
        rows = [[px, py, zero, zero, one, zero], [zero, zero, px, py, zero, one]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=1)


def _offset(x: np.ndarray, model: str) -> np.ndarray:
    """The part of ``y`` not carried by a parameter: ``x`` for translation, else 0."""
    return x if model == "translation" else np.zeros_like(x)


def _to_matrix(theta: np.ndarray, model: str) -> np.ndarray:
    """Parameters ``(..., k)`` to affine matrices ``(..., 2, 3)``."""
    m = np.zeros(theta.shape[:-1] + (2, 3))
    if model == "translation":
        m[..., 0, 0] = m[..., 1, 1] = 1.0
        m[..., :, 2] = theta
    elif model == "similarity":
        a, b = theta[..., 0], theta[..., 1]
        m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1] = a, -b, b, a
        m[..., :, 2] = theta[..., 2:]
    else:
        m[..., 0, :2] = theta[..., 0:2]
        m[..., 1, :2] = theta[..., 2:4]
        m[..., :, 2] = theta[..., 4:]
    return m


def _weighted_lstsq(design: np.ndarray, target: np.ndarray, w: np.ndarray) -> np.ndarray | None:
    """Parameters minimising ``sum w |design @ p - target|²`` (None if degenerate)."""
    k = design.shape[-1]
    d = design.reshape(-1, k)
    t = target.reshape(-1)
    ww = np.repeat(w, 2)
    lhs = d.T @ (d * ww[:, None])
    rhs = d.T @ (t * ww)
    if not np.all(np.isfinite(lhs)) or np.linalg.cond(lhs) > 1e12:
        return None
    return np.linalg.solve(lhs, rhs)


def fit_global_motion(points: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                      model: str = "similarity", inlier: float = 1.0,
                      iterations: int = 200, seed: int = 0
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Robust global motion ``targets ≈ M(points)``: RANSAC, then reweighted least squares.

    Why: the flow of a frame pair is the camera's (or the gate's) global motion on the
    background and something else on moving objects, flat areas and occlusions; a
    robust fit recovers the former and ignores the rest.

    Parameters
    ----------
    points, targets : ndarray, shape (N, 2), float
        Sample positions ``(x, y)`` in the first frame and where the flow carries them
        in the second, in pixels.
    weights : ndarray, shape (N,), float
        Prior confidence of each sample, >= 0 (0 drops it).
    model : str
        ``"translation"``, ``"similarity"`` (default) or ``"affine"``.
    inlier : float
        RANSAC's inlier residual, px (default 1); Tukey's biweight of the refinement
        reaches 0 at twice this.
    iterations : int
        RANSAC hypotheses (default 200), drawn with probability proportional to
        ``weights`` and scored on at most 2000 samples.
    seed : int
        Seed of the local generator (default 0).

    Returns
    -------
    matrix : ndarray, shape (2, 3), float64
        ``[A | b]`` with ``targets ≈ A @ points + b``; the identity when the weights
        are too few (under 12 samples of full weight) or the fit is degenerate.
    inliers : ndarray, shape (N,), float64
        The final robust weight of each sample on [0, 1] (Tukey's biweight; 0 for an
        outlier or a dropped sample).
    """
    pts = np.asarray(points, dtype=np.float64)
    tgt = np.asarray(targets, dtype=np.float64)
    w = np.clip(np.asarray(weights, dtype=np.float64), 0.0, None)
    identity = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    n = pts.shape[0]
    k = MODELS[model]
    minimal = k // 2
    usable = np.flatnonzero(w > 0)
    if w.sum() < _MIN_WEIGHT or usable.size < max(minimal, 3):
        return identity, np.zeros(n)
    # Normalised coordinates (centre and scale of the samples) for conditioning.
    centre = pts[usable].mean(axis=0)
    scale = float(np.sqrt(((pts[usable] - centre) ** 2).sum(axis=1).mean())) or 1.0
    x = (pts - centre) / scale
    y = (tgt - centre) / scale
    design = _design(x, model)
    target = y - _offset(x, model)
    thr = inlier / scale

    rng = np.random.default_rng(seed)
    prob = w[usable] / w[usable].sum()
    draws = np.stack([rng.choice(usable, size=minimal, replace=False, p=prob)
                      if usable.size > minimal else usable[:minimal]
                      for _ in range(iterations)])  # (I, m)
    dm = design[draws].reshape(iterations, 2 * minimal, k)
    tm = target[draws].reshape(iterations, 2 * minimal)
    lhs = np.einsum("ink,inl->ikl", dm, dm) + 1e-12 * np.eye(k)
    rhs = np.einsum("ink,in->ik", dm, tm)
    with np.errstate(all="ignore"):
        try:
            hyp = np.linalg.solve(lhs, rhs[..., None])[..., 0]  # (I, k)
        except np.linalg.LinAlgError:
            hyp = np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(lhs, rhs,
                                                                               strict=True)])
    hyp = hyp[np.all(np.isfinite(hyp), axis=1)]
    if hyp.shape[0] == 0:
        return identity, np.zeros(n)
    # Hypotheses scored on a subset of the usable samples (the refinement sees all).
    sub = usable if usable.size <= _SCORE_SAMPLES else np.sort(
        rng.choice(usable, size=_SCORE_SAMPLES, replace=False))
    pred = np.einsum("njk,ik->inj", design[sub], hyp)  # (I, n, 2)
    r2 = ((pred - target[sub][None]) ** 2).sum(axis=-1)
    score = ((r2 < thr * thr) * w[sub][None]).sum(axis=1)
    theta = hyp[int(np.argmax(score))]

    c = _TUKEY * thr
    robust = np.zeros(n)
    for _ in range(_IRLS_ITERATIONS):
        r = np.sqrt(((design @ theta - target) ** 2).sum(axis=-1))
        robust = np.where(r < c, (1.0 - (r / c) ** 2) ** 2, 0.0)
        ww = w * robust
        if ww.sum() < _MIN_WEIGHT * 0.5:
            break
        new = _weighted_lstsq(design, target, ww)
        if new is None:
            break
        done = np.abs(new - theta).max() < 1e-9
        theta = new
        if done:
            break
    m = _to_matrix(theta, model)
    if model == "translation":
        m[:, 2] *= scale
    else:  # back from normalised coordinates: y = A (x - c) + c + s t
        a = m[:, :2]
        m[:, 2] = scale * m[:, 2] + centre - a @ centre
    if not np.all(np.isfinite(m)):
        return identity, np.zeros(n)
    return m, robust


# --------------------------------------------------------------------------- path


def _h(m: np.ndarray) -> np.ndarray:
    """``(..., 2, 3)`` affine matrices as ``(..., 3, 3)`` homogeneous ones."""
    out = np.zeros(m.shape[:-2] + (3, 3))
    out[..., :2, :] = m
    out[..., 2, 2] = 1.0
    return out


def _local_fit(y: np.ndarray, sigma: float, degree: int, shrink: bool) -> np.ndarray:
    """Gaussian-weighted local polynomial regression of the series ``y`` ``(F, k)``.

    At every frame ``f``, a polynomial of ``degree`` in ``(g - f)`` is fitted to the
    values at frames ``g`` by weighted least squares (weights ``exp(-(g - f)² / 2σ²)``,
    cut at ``4σ``; all 1 for ``σ = inf``) and its value at ``g = f`` kept.  With
    ``shrink``, each coefficient above the constant is shrunk towards 0 by the
    positive-part James-Stein factor ``max(0, 1 - var / coef²)`` (``var`` its sampling
    variance, from the weighted residuals), and the constant refitted to the rest: a
    slope the jitter alone could explain is dropped (no spurious drift on a still
    shot), a real pan (many times its standard error) is kept."""
    n, k = y.shape
    if n == 1 or sigma == 0:
        return y.copy()
    g = np.arange(n, dtype=np.float64)
    out = np.empty_like(y)
    for f in range(n):
        d = g - f
        if math.isinf(sigma):
            kern = np.ones(n)
        else:
            kern = np.exp(-0.5 * (d / sigma) ** 2)
            kern[np.abs(d) > 4 * sigma] = 0.0
        keep = kern > 0
        kf, df, yf = kern[keep], d[keep], y[keep]
        deg = min(degree, int(keep.sum()) - 1)
        v = np.vander(df / max(1.0, min(sigma, n)), deg + 1, increasing=True)  # (m, deg+1)
        gram = v.T @ (v * kf[:, None])
        coef = np.linalg.solve(gram, v.T @ (yf * kf[:, None]))  # (deg+1, k)
        if deg == 0:
            out[f] = coef[0]
            continue
        if shrink:
            resid = yf - v @ coef
            n_eff = kf.sum() ** 2 / (kf ** 2).sum()
            dof = max(n_eff - (deg + 1), 1.0)
            s2 = (kf[:, None] * resid ** 2).sum(axis=0) / kf.sum() * n_eff / dof  # (k,)
            ginv = np.linalg.inv(gram)
            sandwich = ginv @ (v.T @ (v * (kf ** 2)[:, None])) @ ginv
            var = np.diag(sandwich)[:, None] * s2[None, :]  # (deg+1, k)
            with np.errstate(divide="ignore", invalid="ignore"):
                factor = np.where(coef ** 2 > 0, 1.0 - var / coef ** 2, 0.0)
            coef[1:] *= np.clip(factor[1:], 0.0, 1.0)
        rest = yf - v[:, 1:] @ coef[1:]
        out[f] = (kf[:, None] * rest).sum(axis=0) / kf.sum()
    return out


def _decompose(path: np.ndarray, centre: np.ndarray, model: str) -> np.ndarray:
    """Absolute path ``(F, 3, 3)`` to smoothable parameters ``(F, k)`` about ``centre``:
    translation of the centre, then angle (rad, unwrapped) and log-scale (similarity),
    or the four entries of ``A`` (affine)."""
    a = path[:, :2, :2]
    t = path[:, :2, 2] + a @ centre - centre  # where the centre goes, minus the centre
    if model == "translation":
        return t
    if model == "similarity":
        angle = np.unwrap(np.arctan2(a[:, 1, 0] - a[:, 0, 1], a[:, 0, 0] + a[:, 1, 1]))
        logscale = 0.5 * np.log(np.abs(np.linalg.det(a)))
        return np.column_stack([t, angle, logscale])
    return np.column_stack([t, a.reshape(-1, 4)])


def _compose(values: np.ndarray, centre: np.ndarray, model: str) -> np.ndarray:
    """Inverse of :func:`_decompose`: ``(F, k)`` to ``(F, 3, 3)``."""
    n = values.shape[0]
    a = np.zeros((n, 2, 2))
    if model == "translation":
        a[:] = np.eye(2)
    elif model == "similarity":
        s = np.exp(values[:, 3])
        c, si = np.cos(values[:, 2]) * s, np.sin(values[:, 2]) * s
        a[:, 0, 0], a[:, 0, 1], a[:, 1, 0], a[:, 1, 1] = c, -si, si, c
    else:
        a = values[:, 2:6].reshape(n, 2, 2)
    out = np.zeros((n, 3, 3))
    out[:, :2, :2] = a
    out[:, :2, 2] = values[:, :2] + centre - a @ centre
    out[:, 2, 2] = 1.0
    return out


def smooth_path(path: np.ndarray, shape: tuple[int, int], model: str = "similarity",
                smooth: float = 12.0, degree: int = 1, shrink: bool = True) -> np.ndarray:
    """Smooth an absolute camera path: Gaussian-weighted local polynomial regression.

    Why: gate weave is fast, independent from frame to frame; the camera's intended
    motion is slow.  A local polynomial of degree 1 follows a constant-speed pan or zoom
    without lag or bending, also at the clip's ends.

    Parameters
    ----------
    path : ndarray, shape (F, 2, 3) or (F, 3, 3)
        Affine maps from the reference frame's pixels to each frame's.
    shape : (int, int)
        ``(H, W)`` of the frames: the path is written about the frame centre (angle and
        log-scale of a similarity smoothed as numbers, translation of the centre).
    model : str
        ``"translation"``, ``"similarity"`` (default) or ``"affine"``.
    smooth : float
        σ of the Gaussian weights in frames (default 8); ``inf`` fits one polynomial to
        the whole clip; 0 returns the path.
    degree : int
        Degree of the local polynomial, 0-2 (default 1).
    shrink : bool
        Shrink the polynomial's coefficients above the constant by their significance
        (default True; see :class:`StabiliseParams`).

    Returns
    -------
    ndarray, shape (F, 3, 3), float64
        The smoothed path.
    """
    p = np.asarray(path, dtype=np.float64)
    p = _h(p) if p.shape[-2] == 2 else p
    if smooth == 0 or p.shape[0] == 1:
        return p.copy()
    h, w = shape
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    values = _decompose(p, centre, model)
    smoothed = _local_fit(values, float(smooth), int(degree), bool(shrink))
    return _compose(smoothed, centre, model)


# --------------------------------------------------------------------------- flows


def _grey_for_flow(frame: np.ndarray, blur: float) -> np.ndarray:
    """A frame ``(H, W, C)`` as the flows see it: the channel mean, standardised (zero
    mean, unit deviation: a frame's gain and offset, i.e. flicker, drop out), mapped to
    [0, 1] by one fixed affine map, smoothed by ``blur``."""
    g = frame.mean(axis=-1, dtype=np.float32)
    std = float(g.std())
    z = (g - np.float32(g.mean())) / np.float32(std if std > 0 else 1.0)
    if blur > 0:
        z = cv2.GaussianBlur(z, (0, 0), sigmaX=blur, borderType=cv2.BORDER_REFLECT)
    return np.clip(np.float32(0.5) + np.float32(0.15) * z, 0.0, 1.0).astype(np.float32)


def pair_flows(frame0: np.ndarray, frame1: np.ndarray, params: StabiliseParams
               ) -> tuple[np.ndarray, np.ndarray] | np.ndarray:
    """The flows of one pair of consecutive frames as :func:`stabilise` estimates them
    (forward and backward, or forward only without ``fb_check``), to be passed back
    as its ``flows`` by a caller that sees each pair in several windows.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, C), float32
    params : StabiliseParams

    Returns
    -------
    ndarray or (ndarray, ndarray), shape (H', W', 2) each
        On the reduced grid of ``flow_max_pixels``.
    """
    from .. import flow as _flow

    a = _grey_for_flow(frame0, params.flow_blur)
    b = _grey_for_flow(frame1, params.flow_blur)
    fw = _flow(a, b, params.flow_method, max_pixels=params.flow_max_pixels)
    if not params.fb_check:
        return fw
    return fw, _flow(b, a, params.flow_method, max_pixels=params.flow_max_pixels)


def _texture(grey: np.ndarray) -> np.ndarray:
    """Texture weight ``(H, W)`` on [0, 1): ``λ / (λ + median λ)`` with ``λ`` the smaller
    eigenvalue of the structure tensor (5 × 5 window)."""
    lam = cv2.cornerMinEigenVal(grey, blockSize=5, ksize=3)
    ref = float(np.median(lam))
    ref = ref if ref > 0 else float(lam.mean()) or 1.0
    return lam / (lam + np.float32(ref))


def _check_flows(flows: Any, n: int) -> tuple[np.ndarray, np.ndarray | None]:
    """``flows`` as (forward, backward or None), each ``(F - 1, H', W', 2)``."""
    if isinstance(flows, tuple | list) and len(flows) == 2 and np.ndim(flows[0]) == 4:
        fwd, bwd = np.asarray(flows[0]), np.asarray(flows[1])
    else:
        fwd, bwd = np.asarray(flows), None
    for name, arr in (("flows", fwd), ("flows (backward)", bwd)):
        if arr is None:
            continue
        if arr.ndim != 4 or arr.shape[0] != n - 1 or arr.shape[-1] != 2:
            raise ValueError(f"{name}: expected shape ({n - 1}, H, W, 2), got {arr.shape}")
        if not np.issubdtype(arr.dtype, np.floating):
            raise ValueError(f"{name}: expected floats, got dtype {arr.dtype}")
    if bwd is not None and bwd.shape != fwd.shape:
        raise ValueError(f"flows: forward {fwd.shape} and backward {bwd.shape} differ")
    return fwd, bwd


def _pair_motion(grey: np.ndarray, fw: np.ndarray, bw: np.ndarray | None,
                 p: StabiliseParams, full: tuple[int, int], seed: int
                 ) -> tuple[np.ndarray, float]:
    """Global motion ``(2, 3)`` (full-resolution pixels) of one pair from its flows, and
    the fraction of the sample weight its inliers hold."""
    from ..compensate import consistency

    fh, fw_ = fw.shape[:2]
    h, w = full
    sx, sy = w / fw_, h / fh
    step = max(1, int(round(math.sqrt(fh * fw_ / p.samples))))
    ys, xs = np.mgrid[step // 2:fh:step, step // 2:fw_:step]
    ys, xs = ys.ravel(), xs.ravel()
    f = fw[ys, xs].astype(np.float64)
    weight = np.isfinite(f).all(axis=1).astype(np.float64)
    f = np.nan_to_num(f)
    if grey.shape != (fh, fw_):
        grey = cv2.resize(grey, (fw_, fh), interpolation=cv2.INTER_AREA)
    weight *= _texture(grey)[ys, xs]
    if bw is not None:
        weight *= consistency(np.nan_to_num(fw), np.nan_to_num(bw),
                              alpha2=p.fb_tolerance)[ys, xs]
    # Sample positions and targets in full-resolution pixel coordinates (pixel centres).
    px = np.column_stack([(xs + 0.5) * sx - 0.5, (ys + 0.5) * sy - 0.5])
    tx = np.column_stack([(xs + f[:, 0] + 0.5) * sx - 0.5, (ys + f[:, 1] + 0.5) * sy - 0.5])
    m, robust = fit_global_motion(px, tx, weight, p.model, p.inlier, p.ransac_iterations,
                                  seed)
    total = weight.sum()
    return m, float((weight * robust).sum() / total) if total > 0 else 0.0


# --------------------------------------------------------------------------- warping


def _warp(frame: np.ndarray, matrix: np.ndarray, flags: int, border: int) -> np.ndarray:
    """``frame`` ``(H, W, C)`` float32 warped forward by the affine ``matrix``."""
    h, w, c = frame.shape
    if c <= 4:
        out = cv2.warpAffine(frame if c > 1 else frame[..., 0], matrix, (w, h), flags=flags,
                             borderMode=border)
        return out.reshape(h, w, c)
    return np.stack([cv2.warpAffine(np.ascontiguousarray(frame[..., k]), matrix, (w, h),
                                    flags=flags, borderMode=border) for k in range(c)], axis=-1)


def _sample(frame: np.ndarray, pos: np.ndarray, flags: int) -> np.ndarray:
    """``frame`` ``(H, W, C)`` sampled at ``pos`` ``(N, 2)`` (x, y): ``(N, C)`` float32."""
    mx = np.ascontiguousarray(pos[None, :, 0], dtype=np.float32)
    my = np.ascontiguousarray(pos[None, :, 1], dtype=np.float32)
    c = frame.shape[2]
    if c <= 4:
        out = cv2.remap(frame if c > 1 else frame[..., 0], mx, my, flags,
                        borderMode=cv2.BORDER_REFLECT)
        return out.reshape(-1, c)
    return np.stack([cv2.remap(np.ascontiguousarray(frame[..., k]), mx, my, flags,
                               borderMode=cv2.BORDER_REFLECT)[0] for k in range(c)], axis=-1)


def _inside(pos: np.ndarray, h: int, w: int) -> np.ndarray:
    """Positions ``(N, 2)`` inside the frame's pixel centres ``[0, W-1] × [0, H-1]``."""
    eps = 1e-3
    return (pos[:, 0] >= -eps) & (pos[:, 0] <= w - 1 + eps) \
        & (pos[:, 1] >= -eps) & (pos[:, 1] <= h - 1 + eps)


def _apply(m: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Affine ``(3, 3)`` applied to positions ``(N, 2)``."""
    return pos @ m[:2, :2].T + m[:2, 2]


def _neighbour_order(f: int, n: int, radius: int) -> list[int]:
    """Frames within ``radius`` of ``f``, nearest first (earlier first on a tie)."""
    out = []
    for d in range(1, radius + 1):
        out += [g for g in (f - d, f + d) if 0 <= g < n]
    return out


def _fill_frame(clip: np.ndarray, f: int, out: np.ndarray, path: np.ndarray,
                smoothed: np.ndarray, correction: np.ndarray, p: StabiliseParams,
                flags: int) -> tuple[int, int]:
    """Fill, in place, the pixels of stabilised frame ``out`` ``(H, W, C)`` that the
    correction brought in from outside frame ``f``: from the neighbours (nearest in time
    first), warped by the global motion; reflection (already in ``out``) is left where
    none covers.  Returns (pixels uncovered, pixels filled from neighbours)."""
    n, h, w, _ = clip.shape
    yy, xx = np.mgrid[0:h, 0:w]
    grid = np.column_stack([xx.ravel(), yy.ravel()]).astype(np.float64)
    hole = ~_inside(_apply(np.linalg.inv(correction), grid), h, w)
    n_hole = int(hole.sum())
    if n_hole == 0 or p.fill_radius == 0:
        return n_hole, 0
    hole_img = hole.reshape(h, w)
    band = ndimage.binary_dilation(hole_img, iterations=_BAND) & ~hole_img
    band_idx = np.flatnonzero(band.ravel())
    todo = np.flatnonzero(hole)
    filled = 0
    flat = out.reshape(h * w, -1)
    to_ref = np.linalg.inv(smoothed[f])  # stabilised frame f -> reference coordinates
    for g in _neighbour_order(f, n, p.fill_radius):
        if todo.size == 0:
            break
        m = path[g] @ to_ref  # stabilised frame f -> frame g's pixels
        pos = _apply(m, grid[todo])
        ok = _inside(pos, h, w)
        if not ok.any():
            continue
        values = _sample(clip[g], pos[ok], flags)
        if p.fill_match and band_idx.size >= _BAND_MIN:
            bpos = _apply(m, grid[band_idx])
            bok = _inside(bpos, h, w)
            if bok.sum() >= _BAND_MIN:
                theirs = _sample(clip[g], bpos[bok], flags)
                values = values + np.median(flat[band_idx[bok]] - theirs, axis=0)
        flat[todo[ok]] = values
        filled += int(ok.sum())
        todo = todo[~ok]
    return n_hole, filled


# --------------------------------------------------------------------------- main


def stabilise(frames: Any, params: StabiliseParams | None = None, *,
              flows: Any = None, return_transforms: bool = False,
              callback: Callback | None = None, stats: dict | None = None,
              **overrides: Any) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Remove gate weave (fast global jitter) from a clip, keeping the camera's slow motion.

    Why: archival film jitters by a few pixels and a fraction of a degree from frame to
    frame; the dense flow gives each pair's global motion robustly (moving objects are
    outliers), and only its fast part is undone.  See the module docstring for the
    method.

    Parameters
    ----------
    frames : ndarray or sequence of ndarray
        A clip ``(F, H, W, C)`` or ``(F, H, W)`` (grey), or a sequence of frames of one
        shape; uint8, uint16 or float (any range), finite, at least 8 × 8.  One image
        is returned as it is.
    params : StabiliseParams, optional
        The parameters (default :class:`StabiliseParams`).
    flows : ndarray or (ndarray, ndarray), optional
        Precomputed flows between consecutive frames: forward ``(F - 1, H', W', 2)``
        (frame ``f`` to ``f + 1`` at index ``f``, :func:`varflow.flow`'s convention),
        or ``(forward, backward)`` with backward frame ``f + 1`` to ``f``; in pixels of
        an ``H' × W'`` grid (the frames' own or a reduced one).  Without a backward
        flow no forward-backward check is made.  Default: computed.
    return_transforms : bool
        Also return the corrections applied (default False).
    callback : callable, optional
        ``callback(done, total)`` as the work progresses: one step per pair, one per
        frame warped.
    stats : dict, optional
        Filled with ``seconds``, ``flow_seconds``, ``fit_seconds``, ``warp_seconds``,
        ``motions`` ``(F-1, 2, 3)`` (each pair's global motion, frame ``f`` to
        ``f + 1``), ``path`` and ``smoothed`` ``(F, 2, 3)`` (frame 0's pixels to frame
        ``f``'s, raw and smoothed), ``inlier_fraction`` ``(F-1,)`` (share of the sample
        weight in each pair's inliers), ``border_fraction`` ``(F,)`` (pixels brought in
        from outside the frame) and ``reflected_fraction`` ``(F,)`` (of those, the ones
        no neighbour covered, filled by reflection).
    **overrides
        Fields of :class:`StabiliseParams` to change, e.g. ``smooth=4`` or
        ``model="affine"``.

    Returns
    -------
    ndarray
        The stabilised clip, of the input's shape and dtype (integers rounded and
        clipped to their range; floats not clipped: bicubic may overshoot at edges).
    transforms : ndarray, shape (F, 2, 3), float64
        With ``return_transforms``: the correction ``[A | b]`` of each frame, the affine
        map from the input frame's pixels to the output's (the content at ``p`` in
        input frame ``f`` is at ``A @ p + b`` in output frame ``f``).  Its inverse
        (:func:`cv2.invertAffineTransform`) is the estimated weave, what
        :func:`varflow.evaluation.defects.weave_residual` scores.

    Raises
    ------
    ValueError
        Bad frames (shape, dtype, NaN: the message names the frame), bad flows, an
        invalid or unknown parameter (the message names it).

    Notes
    -----
    The reference of the path is the smoothed path itself: a stabiliser cannot know
    where the unwoven picture sat, so the output sits where the clip sits on average
    over the smoothing window (with random weave of ``±s`` px, about ``s / sqrt(3 N)``
    px away from the truth along each axis over ``N`` frames).

    Examples
    --------
    >>> import numpy as np
    >>> from varflow.restore.stabilise import stabilise
    >>> rng = np.random.default_rng(0)
    >>> import cv2
    >>> base = cv2.GaussianBlur(rng.uniform(0, 255, (64, 80)).astype(np.float32), (0, 0), 2)
    >>> clip = np.stack([np.roll(base, (k % 2, 0), axis=(0, 1)) for k in range(6)])
    >>> out, t = stabilise(clip, return_transforms=True, smooth=float("inf"), degree=0)
    >>> out.shape, t.shape
    ((6, 64, 80), (6, 2, 3))
    """
    p = REPAIR.make_params("stabilise", params, **overrides)
    clip, back = _as_clip(frames)
    dtype = clip.dtype
    n, h, w, _ = clip.shape
    t0 = time.perf_counter()
    work = clip.astype(np.float32, copy=False)
    flags = _INTERPOLATIONS[p.interpolation]
    total = 2 * n - 1
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if callback is not None:
            callback(done, total)

    identity = np.tile(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), (n, 1, 1))
    if n == 1:
        if stats is not None:
            stats.update(seconds=time.perf_counter() - t0, flow_seconds=0.0, fit_seconds=0.0,
                         warp_seconds=0.0, motions=np.zeros((0, 2, 3)), path=identity,
                         smoothed=identity, inlier_fraction=np.zeros(0),
                         border_fraction=np.zeros(1), reflected_fraction=np.zeros(1))
        out = np.array(frames if isinstance(frames, np.ndarray) else back(clip), copy=True)
        return (out, identity) if return_transforms else out

    given = _check_flows(flows, n) if flows is not None else None
    from .. import flow as _flow

    motions = np.zeros((n - 1, 2, 3))
    inliers = np.zeros(n - 1)
    flow_s = fit_s = 0.0
    nxt = _grey_for_flow(work[0], p.flow_blur)
    for s in range(n - 1):
        a, nxt = nxt, _grey_for_flow(work[s + 1], p.flow_blur)
        t1 = time.perf_counter()
        if given is not None:
            fw = given[0][s].astype(np.float32)
            bw = None if given[1] is None else given[1][s].astype(np.float32)
        else:
            fw = _flow(a, nxt, p.flow_method, max_pixels=p.flow_max_pixels)
            bw = _flow(nxt, a, p.flow_method, max_pixels=p.flow_max_pixels) \
                if p.fb_check else None
        t2 = time.perf_counter()
        motions[s], inliers[s] = _pair_motion(a, fw, bw, p, (h, w), p.seed + s)
        fit_s += time.perf_counter() - t2
        flow_s += t2 - t1
        if inliers[s] < 0.3:
            log.warning("pair %d-%d: only %.0f %% of the flow agrees with the global "
                        "motion", s, s + 1, 100 * inliers[s])
        tick()

    path = np.zeros((n, 3, 3))
    path[0] = np.eye(3)
    for s in range(n - 1):
        path[s + 1] = _h(motions[s]) @ path[s]
    smoothed = smooth_path(path, (h, w), p.model, p.smooth, p.degree, p.shrink)
    correction = smoothed @ np.linalg.inv(path)  # input frame f -> output frame f

    t3 = time.perf_counter()
    out = np.empty_like(work)
    border = np.zeros(n)
    reflected = np.zeros(n)
    for f in range(n):
        out[f] = _warp(work[f], correction[f, :2], flags, cv2.BORDER_REFLECT)
        n_hole, filled = _fill_frame(work, f, out[f], path, smoothed, correction[f], p, flags)
        border[f] = n_hole / (h * w)
        reflected[f] = (n_hole - filled) / (h * w)
        tick()
    warp_s = time.perf_counter() - t3
    log.info("stabilised %d frames: flows %.2f s, fits %.2f s, warps %.2f s; largest "
             "border %.2f %% (%.2f %% reflected)", n, flow_s, fit_s, warp_s,
             100 * border.max(), 100 * reflected.max())
    if stats is not None:
        stats.update(seconds=time.perf_counter() - t0, flow_seconds=flow_s,
                     fit_seconds=fit_s, warp_seconds=warp_s, motions=motions,
                     path=path[:, :2].copy(), smoothed=smoothed[:, :2].copy(),
                     inlier_fraction=inliers, border_fraction=border,
                     reflected_fraction=reflected)
    result = back(_to_dtype(out, dtype))
    if return_transforms:
        return result, correction[:, :2].copy()
    return result
