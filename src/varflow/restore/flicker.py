"""Deflicker of archival film: :func:`deflicker` and its :class:`DeflickerParams`.

Why: the exposure and the development of old film vary from frame to frame, so the
brightness of a shot pumps; the motion tells which changes belong to the picture.

Model, per frame ``t`` and channel: ``observed = g_t(x) * true + o_t(x)`` with a smooth
gain field ``g_t`` and offset field ``o_t``.  The method works in three stages.

1. **Motion.**  The flows between consecutive frames (both ways) are computed on
   intensity-normalised copies of the frames (the grey level's detail above a
   Gaussian of ``flow_highpass`` px divided by its local standard deviation, in which
   a smooth gain and offset field cancels, so that the flicker does not pull the
   flow) and checked forward-backward (:func:`varflow.consistency`).  Neighbours
   up to ``radius`` frames apart are reached by chaining the flows; a chain stops at
   the first inconsistent link.
2. **Consistent brightness.**  Every frame gets an affine correction
   ``J_t(x) = p_t(x) I_t(x) + q_t(x)`` whose gain ``p_t`` and offset ``q_t`` are
   polynomials in ``(x, y)`` (tensor Legendre terms of total degree at most
   ``degree`` and ``offset_degree``).  All the corrections are solved together by
   robust weighted least squares so that every pixel matches its motion-compensated
   neighbours, ``J_t(x) = J_s(x + w_ts(x))`` for ``0 < s - t <= radius``, with a weak
   pull of every ``J_t`` toward ``I_t`` that fixes the common gauge (the clip's average
   brightness).  Occluded pixels (failed forward-backward check, outside the frame)
   are left out; outliers (dirt, blotches, flow errors) are removed by iteratively
   reweighted least squares with Tukey's biweight on the residuals of each pair
   (cut-off ``trim`` robust standard deviations).
3. **Smoothed brightness path.**  The inverse maps ``I_t = a_t(x) J_t + b_t(x)``
   describe how each frame renders the consistent picture: the brightness path.  It
   is smoothed over time and each frame is rendered with the smoothed path,
   ``out_t = ã_t J_t + b̃_t``.  The smoothing keeps what lasts: the path is cut into
   segments at steps (a level change between the ``persist`` frames before and after
   a frame, ``step_threshold`` times larger than the flicker's noise level predicts:
   a light switched on and kept on), and within a segment each frame takes a local
   linear fit over ``window`` frames each side whose slope is kept as much as it is
   significant (shrunk by ``max(0, 1 - (trend / t)^2)`` with ``t`` its t-statistic
   against the flicker's noise level): a fade is kept, a random tilt of the flicker
   is not.  A clip without flicker has a constant path and comes back unchanged.

The whole clip is held in memory (frames, flows), as :func:`varflow.denoise` does.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.linalg import spsolve

from .._validate import check_field
from ..registry import REPAIR
from .denoise import _as_clip, _to_dtype

__all__ = ["DeflickerParams", "deflicker", "pair_flows"]

log = logging.getLogger(__name__)

Callback = Callable[[int, int], None]

#: Weight of the pull of every corrected frame toward its input, relative to one
#: pair's data term: small, it only fixes what the pairs leave free (the gauge).
_PRIOR = 1e-3
#: Ridge on the polynomial coefficients (unit-range intensities): conditioning only.
_RIDGE = 1e-9
#: Floor of the flicker's noise level on the brightness path (unit range), so that a
#: flicker-free clip does not see steps or trends in its estimation noise.
_SIGMA_FLOOR = 2e-3
#: Side of the coarse grid on which the brightness path is smoothed (at most).
_GRID = 33
#: Floor of the local contrast in the high-passed frames of the flows (unit range):
#: flat areas stay flat instead of having their noise amplified.
_HP_EPS = 0.008
#: A chained neighbour counts where the bilinear sample of the consistency masks is
#: at least this (all four taps consistent).
_OK = 0.999


@dataclass(frozen=True)
class DeflickerParams:
    """Parameters of :func:`deflicker` (motion-compensated gain/offset deflicker).

    Attributes
    ----------
    radius : int
        Temporal radius: each frame is matched to the frames up to ``radius`` after it
        (so to ``radius`` each side), along chained flows.  More neighbours average
        out flow errors.  In [1, 8], default 2.
    degree : int
        Total degree of the polynomial gain field ``p_t(x, y)`` of each frame and
        channel (0: one gain per frame; 4: fifteen Legendre terms, about one cycle
        of variation across the frame).  In [0, 6], default 4.
    offset_degree : int
        Total degree of the polynomial offset field ``q_t(x, y)``.  In [0, 6],
        default 2.
    stiffness : float
        Weight of the mean square of the spatial variation of each frame's gain and
        offset fields (unit-range intensities), against a pair's mean square
        residual: keeps the fields flat where a frame is poorly matched (parts
        entering the picture, occlusions) instead of extrapolating the polynomials.
        >= 0, default 0.01.
    window : int
        Half-width, in frames, of the temporal smoothing of the brightness path (a
        local linear fit over ``2 window + 1`` frames, clipped to the clip and to
        its steps); longer averages flicker better, shorter follows curved lighting
        changes.  >= 1, default 12.
    trend : float
        A local slope of the brightness path is kept in the proportion
        ``max(0, 1 - (trend / t)^2)``, ``t`` its t-statistic against the flicker's
        noise level: 0 keeps every slope (plain local linear fit), larger values
        flatten more (a random tilt of the flicker is then less often taken for a
        fade, a real fade more often damped).  >= 0, default 1.5.
    persist : int
        Frames a brightness step must last on each side to be kept (a segment
        boundary of the smoothing); 0 turns step detection off.  >= 0, default 4.
    step_threshold : float
        A step is kept where the mean brightness of the ``persist`` frames after a
        frame differs from that of the ``persist`` frames before by more than this
        many standard deviations of that difference under flicker alone (the
        flicker's level estimated robustly from frame-to-frame differences).  A fast
        fade may pass for a step (harmless: both are kept).  > 0, default 6.
    trim : float
        Cut-off of Tukey's biweight on the residuals of each pair of frames, in
        robust standard deviations (1.4826 MAD): dirt and flow errors beyond it get
        weight 0.  > 0, default 3.
    iterations : int
        Reweighted least-squares solves (the first one unweighted).  In [1, 20],
        default 4.
    samples : int
        Pixels of each frame used in the fits (a regular grid over the frame):
        bounds the time of the fits on big frames.  >= 64, default 40000.
    flow_method : str
        Two-frame method of the flows (a name of :data:`varflow.registry.FLOW`).
        Default ``"tvl1-fast"``.
    flow_params : dataclass or None
        Its parameters (None: its defaults).
    flow_max_pixels : int
        Frames of more pixels get their flows on a reduced copy
        (``varflow.flow(max_pixels=...)``); 0: never.  >= 0, default 0.
    flow_blur : float
        σ in pixels of the Gaussian applied to the normalised frames before the
        flows (grain and noise).  >= 0, default 1.
    flow_highpass : float
        σ in pixels of the Gaussian whose low-pass is taken off the frames of the
        flows, the detail being divided by its local standard deviation: a smooth
        gain and offset field (the flicker) then leaves the flow unchanged; 0 matches
        each frame's mean and std only.  >= 0, default 10.
    fb_tolerance : float
        α₂ of the forward-backward check in px² (:func:`varflow.consistency`).
        >= 0, default 0.5.
    """

    radius: int = 2
    degree: int = 4
    offset_degree: int = 2
    stiffness: float = 0.01
    window: int = 12
    trend: float = 1.5
    persist: int = 4
    step_threshold: float = 6.0
    trim: float = 3.0
    iterations: int = 4
    samples: int = 40000
    flow_method: str = "tvl1-fast"
    flow_params: Any = None
    flow_max_pixels: int = 0
    flow_blur: float = 1.0
    flow_highpass: float = 10.0
    fb_tolerance: float = 0.5

    def __post_init__(self) -> None:
        def integer(name: str, low: int, high: int | None = None) -> None:
            v = getattr(self, name)
            ok = isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= low \
                and (high is None or v <= high)
            rng = f">= {low}" if high is None else f"in [{low}, {high}]"
            check_field(ok, name, f"must be an integer {rng}, got {v!r}")

        def number(name: str, low: float, strict: bool = False) -> None:
            v = getattr(self, name)
            ok = isinstance(v, int | float | np.integer | np.floating) \
                and not isinstance(v, bool) and math.isfinite(v) \
                and (v > low if strict else v >= low)
            check_field(ok, name, f"must be a finite number {'>' if strict else '>='} "
                        f"{low:g}, got {v!r}")

        integer("radius", 1, 8)
        integer("degree", 0, 6)
        integer("offset_degree", 0, 6)
        integer("window", 1)
        integer("persist", 0)
        integer("iterations", 1, 20)
        integer("samples", 64)
        integer("flow_max_pixels", 0)
        number("trend", 0.0)
        number("step_threshold", 0.0, strict=True)
        number("trim", 0.0, strict=True)
        number("stiffness", 0.0)
        number("flow_blur", 0.0)
        number("flow_highpass", 0.0)
        number("fb_tolerance", 0.0)
        from ..registry import FLOW

        known = isinstance(self.flow_method, str) and FLOW.get(self.flow_method) is not None
        check_field(known, "flow_method", f"unknown two-frame method {self.flow_method!r}; "
                    f"available: {', '.join(FLOW.names())}")


# --------------------------------------------------------------------------- bases


def _terms(degree: int) -> list[tuple[int, int]]:
    """The (y order, x order) pairs of the tensor Legendre terms of total degree <= d."""
    return [(i, j) for i in range(degree + 1) for j in range(degree + 1 - i)]


def _legendre(z: np.ndarray, degree: int) -> np.ndarray:
    """Legendre polynomials ``P_0..P_d`` at ``z`` (on [-1, 1]): shape ``z.shape + (d+1,)``."""
    out = [np.ones_like(z), z]
    for k in range(2, degree + 1):
        out.append(((2 * k - 1) * z * out[k - 1] - (k - 1) * out[k - 2]) / k)
    return np.stack(out[:degree + 1], axis=-1)


def _basis(px: np.ndarray, py: np.ndarray, degree: int, h: int, w: int) -> np.ndarray:
    """Basis ``(N, n_terms)`` float64 at pixel positions ``(px, py)`` (columns, rows)."""
    lx = _legendre(2.0 * px / (w - 1) - 1.0, degree)
    ly = _legendre(2.0 * py / (h - 1) - 1.0, degree)
    return np.stack([ly[:, i] * lx[:, j] for i, j in _terms(degree)], axis=1)


def _field(coef: np.ndarray, ys: np.ndarray, xs: np.ndarray, degree: int, h: int,
           w: int) -> np.ndarray:
    """The polynomial of coefficients ``coef`` on the grid ``ys x xs``, float64."""
    ly = _legendre(2.0 * ys / (h - 1) - 1.0, degree)
    lx = _legendre(2.0 * xs / (w - 1) - 1.0, degree)
    c = np.zeros((degree + 1, degree + 1))
    for k, (i, j) in enumerate(_terms(degree)):
        c[i, j] = coef[k]
    return ly @ c @ lx.T


def _hat(n_out: int, n_grid: int) -> np.ndarray:
    """Linear-interpolation weights ``(n_out, n_grid)`` from ``n_grid`` evenly spaced
    points spanning ``[0, n_out - 1]`` (both ends included) to every pixel."""
    if n_grid == n_out:
        return np.eye(n_out)
    pos = np.arange(n_out) * (n_grid - 1) / (n_out - 1)
    lo = np.minimum(np.floor(pos).astype(np.int64), n_grid - 2)
    frac = pos - lo
    m = np.zeros((n_out, n_grid))
    m[np.arange(n_out), lo] = 1.0 - frac
    m[np.arange(n_out), lo + 1] += frac
    return m


# --------------------------------------------------------------------------- motion


def _flow_frames(clip: np.ndarray, lo: float, hi: float, blur: float,
                 highpass: float) -> np.ndarray:
    """The frames ``(F, H, W)`` in [0, 1] as the flows see them, the flicker taken out.

    The grey level (mean of the channels), smoothed by ``blur`` px; with ``highpass``
    > 0, its detail above a Gaussian of ``highpass`` px divided by the local standard
    deviation of that detail (so that a smooth gain and offset field, the flicker's
    form, cancels: ``g I + o`` gives the same frame as ``I``); with ``highpass`` 0,
    each frame matched in mean and std to the clip's averages (a global gain and
    offset only)."""
    grey = clip.mean(axis=3)
    grey = (grey - np.float32(lo)) * np.float32(1.0 / (hi - lo))
    if blur > 0:
        grey = ndimage.gaussian_filter(grey, (0, blur, blur), mode="nearest")
    if highpass > 0:
        low = ndimage.gaussian_filter(grey, (0, highpass, highpass), mode="nearest")
        detail = grey - low
        spread = np.sqrt(ndimage.gaussian_filter(detail * detail, (0, highpass, highpass),
                                                 mode="nearest"))
        out = 0.5 + detail / (spread + np.float32(_HP_EPS)) / np.float32(6.0)
    else:
        mean = grey.mean(axis=(1, 2), keepdims=True)
        std = grey.std(axis=(1, 2), keepdims=True)
        out = (grey - mean) * (std.mean() / np.maximum(std, 1e-12)) + mean.mean()
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _compute_flows(clip: np.ndarray, p: DeflickerParams, lo: float, hi: float,
                   tick: Callable[[], None]) -> tuple[np.ndarray, np.ndarray]:
    """Forward flows ``(F-1, H, W, 2)`` between consecutive frames and their
    forward-backward masks ``(F-1, H, W)``."""
    from .. import flow as _flow
    from ..compensate import consistency

    n, h, w, _ = clip.shape
    frames = _flow_frames(clip, lo, hi, p.flow_blur, p.flow_highpass)
    fwd = np.zeros((n - 1, h, w, 2), np.float32)
    ok = np.zeros((n - 1, h, w), np.bool_)
    kw: dict[str, Any] = dict(params=p.flow_params, max_pixels=p.flow_max_pixels)
    for s in range(n - 1):
        fwd[s] = _flow(frames[s], frames[s + 1], p.flow_method, **kw)
        bwd = _flow(frames[s + 1], frames[s], p.flow_method, **kw)
        ok[s] = consistency(fwd[s], bwd, alpha2=p.fb_tolerance)
        tick()
    return fwd, ok


def pair_flows(frame0: np.ndarray, frame1: np.ndarray, params: DeflickerParams
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, None]:
    """The flows of one pair of consecutive frames and the forward one's
    forward-backward mask, as :func:`deflicker` estimates them (on the pair's own
    intensity range, which the high-pass normalisation of the flow frames makes
    irrelevant), to be passed back, stacked, as its ``flows`` by a caller that sees
    each pair in several windows.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, C), float32
    params : DeflickerParams

    Returns
    -------
    (fwd, bwd, fwd_ok, None)
        ``fwd`` and ``bwd`` ``(H, W, 2)`` float32 (frame 0 to 1 and 1 to 0) and
        ``fwd_ok`` ``(H, W)`` bool, in the form of :func:`deflicker`'s ``flows``
        (which uses the forward ones; deflicker changes no positions, so the pair
        still serves a later stage, e.g. as the dirt stage's first flows).
    """
    from .. import flow as _flow
    from ..compensate import consistency

    pair = np.stack([frame0, frame1]).astype(np.float32)
    lo, hi = (float(v) for v in np.percentile(pair, [0.5, 99.5]))
    if not hi > lo:
        lo, hi = float(pair.min()), float(pair.max())
        if not hi > lo:
            hi = lo + 1.0
    a, b = _flow_frames(pair, lo, hi, params.flow_blur, params.flow_highpass)
    kw: dict[str, Any] = dict(params=params.flow_params, max_pixels=params.flow_max_pixels)
    fwd = _flow(a, b, params.flow_method, **kw)
    bwd = _flow(b, a, params.flow_method, **kw)
    return fwd, bwd, consistency(fwd, bwd, alpha2=params.fb_tolerance), None


def _given_flows(flows: Any, n: int, h: int, w: int,
                 fb_tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """The caller's ``(fwd, bwd)`` or ``(fwd, bwd, fwd_ok, bwd_ok)`` as forward flows
    and masks (the masks computed when not given; with the masks, ``bwd`` and
    ``bwd_ok`` may be None: only the forward ones are used)."""
    from ..compensate import consistency

    try:
        parts = [None if a is None else np.asarray(a) for a in flows]
    except TypeError:
        raise ValueError("flows: expected (fwd, bwd) or (fwd, bwd, fwd_ok, bwd_ok)") from None
    if len(parts) not in (2, 4):
        raise ValueError(f"flows: expected 2 or 4 arrays, got {len(parts)}")
    if parts[0] is None or parts[2 if len(parts) == 4 else 1] is None:
        raise ValueError("flows: fwd and fwd_ok (or bwd) must be given")
    for name, a in zip(("fwd", "bwd"), parts[:2], strict=True):
        if a is None:
            continue
        if a.shape != (n - 1, h, w, 2):
            raise ValueError(f"flows: {name} has shape {a.shape}, expected "
                             f"{(n - 1, h, w, 2)}")
    fwd = parts[0].astype(np.float32, copy=False)
    if len(parts) == 4:
        ok = np.asarray(parts[2], np.bool_)
        if ok.shape != (n - 1, h, w):
            raise ValueError(f"flows: fwd_ok has shape {ok.shape}, expected {(n - 1, h, w)}")
    else:
        bwd = parts[1].astype(np.float32, copy=False)
        ok = np.stack([consistency(fwd[s], bwd[s], alpha2=fb_tolerance)
                       for s in range(n - 1)]) if n > 1 else np.zeros((0, h, w), np.bool_)
    return fwd, ok & np.isfinite(fwd).all(axis=-1)


def _sample(image: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Bilinear samples ``(N, C)`` float64 of ``image`` ``(H, W, C)`` at ``(px, py)``
    (clamped to the frame)."""
    h, w = image.shape[:2]
    px = np.clip(px, 0.0, w - 1.0)
    py = np.clip(py, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(px).astype(np.int64), max(w - 2, 0))
    y0 = np.minimum(np.floor(py).astype(np.int64), max(h - 2, 0))
    fx = (px - x0)[:, None]
    fy = (py - y0)[:, None]
    top = image[y0, x0] * (1.0 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1.0 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1.0 - fy) + bottom * fy


@dataclass
class _Pair:
    """The samples of frame ``t`` matched in frame ``s``: grid indices, positions in
    ``s`` and the intensities of both frames there."""

    t: int
    s: int
    idx: np.ndarray   # (N,) indices into the sample grid
    px: np.ndarray    # (N,) x in frame s
    py: np.ndarray    # (N,) y in frame s
    it: np.ndarray    # (N, C) frame t at the samples
    js: np.ndarray    # (N, C) frame s at the matched positions


def _pairs(work: np.ndarray, fwd: np.ndarray, ok: np.ndarray, gx: np.ndarray,
           gy: np.ndarray, radius: int) -> list[_Pair]:
    """Every pair ``(t, s)``, ``0 < s - t <= radius``, along the chained flows."""
    n, h, w, _ = work.shape
    out = []
    okf = ok.astype(np.float32)
    for t in range(n - 1):
        px, py = gx.copy(), gy.copy()
        alive = np.ones(gx.shape, np.bool_)
        for s in range(t + 1, min(t + radius, n - 1) + 1):
            link = s - 1
            inside = (px >= 0) & (px <= w - 1) & (py >= 0) & (py <= h - 1)
            alive &= inside
            cx, cy = np.clip(px, 0, w - 1), np.clip(py, 0, h - 1)
            good = _sample(okf[link][..., None], cx, cy)[:, 0] >= _OK
            step = _sample(fwd[link], cx, cy)
            alive &= good & np.isfinite(step).all(axis=1)
            px = cx + np.nan_to_num(step[:, 0])
            py = cy + np.nan_to_num(step[:, 1])
            alive &= (px >= 0) & (px <= w - 1) & (py >= 0) & (py <= h - 1)
            idx = np.flatnonzero(alive)
            if idx.size < 16:
                break
            it = work[t][gy[idx].astype(np.int64), gx[idx].astype(np.int64)]
            js = _sample(work[s], px[idx], py[idx])
            out.append(_Pair(t, s, idx, px[idx].astype(np.float64),
                             py[idx].astype(np.float64), it.astype(np.float64),
                             js.astype(np.float64)))
    return out


# --------------------------------------------------------------------------- fit


def _tukey(r: np.ndarray, trim: float) -> np.ndarray:
    """Tukey's biweight of residuals ``r`` with cut-off ``trim`` robust std (MAD)."""
    scale = 1.4826 * float(np.median(np.abs(r))) * trim
    if not scale > 1e-9:
        return np.ones_like(r)
    z = r / scale
    return np.where(np.abs(z) < 1.0, (1.0 - z * z) ** 2, 0.0)


def _solve_channel(pairs: list[_Pair], grid_it: np.ndarray, bg: np.ndarray, bo: np.ndarray,
                   p: DeflickerParams, c: int, n: int, h: int, w: int,
                   tick: Callable[[], None]) -> np.ndarray:
    """Coefficients ``(F, ng + no)`` of the corrections of channel ``c``: gain terms
    then offset terms, solved jointly over the pairs by IRLS."""
    ng, no = bg.shape[1], bo.shape[1]
    m = ng + no
    size = n * m
    n_grid = bg.shape[0]
    # The prior: sum_x (p I + q - I)^2 per frame, and the ridge (constant over IRLS).
    prior_rows, prior_cols, prior_vals = [], [], []
    rhs = np.zeros(size)
    base_idx = np.arange(m)
    # Stiffness: the mean square over the frame of the non-constant part of each
    # field (Legendre terms are orthogonal, P_i(y) P_j(x) of mean square
    # 1 / ((2i+1)(2j+1))), so poorly matched parts of a frame are not extrapolated.
    stiff = np.concatenate([[0.0 if i + j == 0 else p.stiffness / ((2 * i + 1) * (2 * j + 1))
                             for i, j in _terms(d)] for d in (p.degree, p.offset_degree)])
    for t in range(n):
        v = np.concatenate([bg * grid_it[t, :, c:c + 1], bo], axis=1)
        block = (_PRIOR / n_grid) * (v.T @ v) + np.diag(_RIDGE + stiff)
        rr, cc = np.meshgrid(base_idx + t * m, base_idx + t * m, indexing="ij")
        prior_rows.append(rr.ravel())
        prior_cols.append(cc.ravel())
        prior_vals.append(block.ravel())
        rhs[t * m:(t + 1) * m] = (_PRIOR / n_grid) * (v.T @ grid_it[t, :, c])
    theta = np.zeros((n, m))
    theta[:, 0] = 1.0  # identity: P_0 = 1 gain, zero offset
    # The gauge, a hard constraint: the corrections average to the identity, term by
    # term (the pairs only fix the corrections relative to one another; a common field
    # is seen through the motion alone, and a pull toward "no correction" would let the
    # solution shrink toward J = 0, where the residuals of noise and flow errors vanish).
    gauge = sp.hstack([sp.identity(m, format="csr")] * n, format="csr") / n
    target = theta[0].copy()
    weights: list[np.ndarray | None] = [None] * len(pairs)
    for it in range(p.iterations):
        rows, cols, vals = list(prior_rows), list(prior_cols), list(prior_vals)
        for k, pr in enumerate(pairs):
            bgy = _basis(pr.px, pr.py, p.degree, h, w)
            boy = _basis(pr.px, pr.py, p.offset_degree, h, w)
            u = np.concatenate([bg[pr.idx] * pr.it[:, c:c + 1], bo[pr.idx],
                                -bgy * pr.js[:, c:c + 1], -boy], axis=1)
            if it > 0:
                r = u @ np.concatenate([theta[pr.t], theta[pr.s]])
                weights[k] = _tukey(r, p.trim)
            wk = weights[k]
            g = ((u * wk[:, None]).T @ u if wk is not None else u.T @ u) / n_grid
            where = np.concatenate([base_idx + pr.t * m, base_idx + pr.s * m])
            rr, cc = np.meshgrid(where, where, indexing="ij")
            rows.append(rr.ravel())
            cols.append(cc.ravel())
            vals.append(g.ravel())
        a = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(size, size))
        kkt = sp.bmat([[a, gauge.T], [gauge, None]], format="csc")
        theta = spsolve(kkt, np.concatenate([rhs, target]))[:size].reshape(n, m)
        tick()
    return theta


# --------------------------------------------------------------------------- path


def _noise_level(y: np.ndarray, segments: list[tuple[int, int]] | None = None) -> np.ndarray:
    """Robust std ``(K,)`` of the i.i.d. flicker on a path ``(F, K)``: 1.4826 MAD of the
    frame-to-frame differences (less their median: a steady fade) over sqrt(2)."""
    if segments is None:
        segments = [(0, y.shape[0])]
    d = np.concatenate([np.diff(y[a:b], axis=0) for a, b in segments if b - a > 1]
                       or [np.zeros((0, y.shape[1]))])
    if d.shape[0] < 2:
        return np.full(y.shape[1], _SIGMA_FLOOR)
    d = d - np.median(d, axis=0)
    sigma = 1.4826 * np.median(np.abs(d), axis=0) / math.sqrt(2.0)
    return np.maximum(sigma, _SIGMA_FLOOR)


def _breaks(y: np.ndarray, persist: int, threshold: float) -> list[int]:
    """Frames ``k`` where a lasting step starts: the mean of ``y[k:k+P]`` differs from
    that of ``y[k-P:k]`` by ``threshold`` std of that difference under flicker alone
    (the largest such statistic within ``P`` frames)."""
    n = y.shape[0]
    if persist < 1 or n < 2 * persist:
        return []
    sigma = _noise_level(y)
    z = np.zeros(n)
    for k in range(persist, n - persist + 1):
        diff = y[k:k + persist].mean(axis=0) - y[k - persist:k].mean(axis=0)
        z[k] = float(np.max(np.abs(diff) / (sigma * math.sqrt(2.0 / persist))))
    out: list[int] = []
    for k in np.argsort(-z):
        if z[k] <= threshold:
            break
        if all(abs(int(k) - b) >= persist for b in out):
            out.append(int(k))
    return sorted(out)


def _smoother(y: np.ndarray, p: DeflickerParams) -> tuple[np.ndarray, list[int]]:
    """The linear smoother ``S`` ``(F, F)`` of the brightness path (rows sum to 1 and
    reproduce a linear trend in proportion to its significance) and the steps kept."""
    n = y.shape[0]
    cuts = _breaks(y, p.persist, p.step_threshold)
    bounds = [0, *cuts, n]
    segments = list(zip(bounds[:-1], bounds[1:], strict=True))
    sigma = _noise_level(y, segments)
    s_mat = np.zeros((n, n))
    for a, b in segments:
        for t in range(a, b):
            lo, hi = max(a, t - p.window), min(b, t + p.window + 1)
            frames = np.arange(lo, hi, dtype=np.float64)
            count = hi - lo
            centred = frames - frames.mean()
            sxx = float(centred @ centred)
            s_mat[t, lo:hi] = 1.0 / count
            if count < 2 or sxx <= 0:
                continue
            slope = centred @ y[lo:hi] / sxx  # (K,)
            tstat = float(np.max(np.abs(slope) / (sigma / math.sqrt(sxx))))
            keep = 1.0 if p.trend == 0 else max(0.0, 1.0 - (p.trend / tstat) ** 2) \
                if tstat > 0 else 0.0
            s_mat[t, lo:hi] += keep * (t - frames.mean()) * centred / sxx
    return s_mat, cuts


# --------------------------------------------------------------------------- public


def deflicker(frames: Any, params: DeflickerParams | None = None, *, flows: Any = None,
              callback: Callback | None = None, stats: dict | None = None,
              **overrides: Any) -> np.ndarray:
    """Remove flicker (frame-to-frame brightness and contrast fluctuation) from a clip.

    Why: archival film pumps in brightness from frame to frame; matching every frame
    to its motion-compensated neighbours with smooth gain and offset fields, then
    rendering it with a temporally smoothed brightness, removes the pumping and keeps
    fades and lasting lighting changes (module notes give the method).

    Parameters
    ----------
    frames : ndarray or sequence of ndarray
        A clip ``(F, H, W, C)`` or ``(F, H, W)`` (grey), or a sequence of frames of one
        shape; uint8, uint16 or float (any range), finite, at least 8 × 8.  One frame
        comes back unchanged.
    params : DeflickerParams, optional
        The parameters (default :class:`DeflickerParams`).
    flows : tuple, optional
        The flows between consecutive frames when the caller has them:
        ``(fwd, bwd)`` each ``(F - 1, H, W, 2)`` (frame s to s + 1 and s + 1 to s, in
        pixels, as :func:`varflow.restore.denoise.clip_flows` gives), optionally with
        their forward-backward masks ``(fwd, bwd, fwd_ok, bwd_ok)``
        ``(F - 1, H, W)`` bool (then ``bwd`` and ``bwd_ok`` may be None, as
        :func:`pair_flows` gives them).  They should be computed on
        intensity-normalised frames.  Default: computed (``flow_method`` on
        normalised frames).
    callback : callable, optional
        ``callback(done, total)`` as the work progresses (flows, solves, output).
    stats : dict, optional
        Filled with ``seconds``, ``flow_seconds``, ``fit_seconds``, ``steps`` (the
        frames where a lasting brightness step starts), ``smoother`` (the ``(F, F)``
        temporal smoothing matrix), ``gain`` and ``offset`` ``(F, C)``: the mean gain
        and offset the correction applied to each frame and channel (input units,
        ``out ≈ gain * in + offset``).
    **overrides
        Fields of :class:`DeflickerParams` to change, e.g. ``radius=1``.

    Returns
    -------
    ndarray
        The deflickered clip, of the input's shape and dtype (integers rounded and
        clipped to their range; floats not clipped).

    Raises
    ------
    ValueError
        Bad frames (shape, dtype, NaN: the message names the frame), an unknown or
        invalid parameter (named), or flows of the wrong shape.

    Notes
    -----
    The brightness of a frame is corrected by polynomial fields: flicker that varies
    faster across the frame than ``degree`` allows stays.  Steps shorter than
    ``persist`` frames, or smaller than ``step_threshold`` times the flicker's level,
    are flattened as flicker; curved lighting changes faster than ``window`` frames
    are partly flattened.  Channels are corrected independently (colour flicker).

    Examples
    --------
    >>> import numpy as np
    >>> import varflow
    >>> from varflow.restore.flicker import deflicker
    >>> rng = np.random.default_rng(0)
    >>> scene = rng.uniform(20, 230, (40, 60)).astype(np.float32)
    >>> clean = np.stack([np.roll(scene, k, axis=1) for k in range(6)])
    >>> gains = np.array([1.0, 1.2, 0.8, 1.1, 0.9, 1.0], np.float32)
    >>> out = deflicker(clean * gains[:, None, None], radius=1, flow_blur=0)
    >>> bool(np.abs(out.mean(axis=(1, 2)) - clean.mean(axis=(1, 2))).max() < 1.0)
    True
    """
    p = REPAIR.make_params("deflicker", params, **overrides)
    clip, back = _as_clip(frames)
    dtype = clip.dtype
    t0 = time.perf_counter()
    work = clip.astype(np.float32)
    n, h, w, nc = work.shape
    if n < 2:
        if stats is not None:
            stats.update(seconds=0.0, flow_seconds=0.0, fit_seconds=0.0, steps=[],
                         smoother=np.ones((n, n)), gain=np.ones((n, nc)),
                         offset=np.zeros((n, nc)))
        return np.array(frames if isinstance(frames, np.ndarray) else back(clip), copy=True)
    lo, hi = (float(v) for v in np.percentile(work, [0.5, 99.5]))
    if not hi > lo:
        lo, hi = float(work.min()), float(work.max())
        if not hi > lo:
            hi = lo + 1.0
    unit = (work - np.float32(lo)) * np.float32(1.0 / (hi - lo))

    total = (n - 1) * (flows is None) + nc * p.iterations + 1
    done = [0]

    def tick() -> None:
        done[0] += 1
        if callback is not None:
            callback(done[0], total)

    if flows is None:
        fwd, ok = _compute_flows(work, p, lo, hi, tick)
    else:
        fwd, ok = _given_flows(flows, n, h, w, p.fb_tolerance)
    t1 = time.perf_counter()

    # The sample grid: a regular stride covering the frame.
    stride = max(1, int(math.ceil(math.sqrt(h * w / p.samples))))
    ys = np.arange((h - 1) % stride // 2, h, stride, dtype=np.float64)
    xs = np.arange((w - 1) % stride // 2, w, stride, dtype=np.float64)
    gy, gx = (a.ravel() for a in np.meshgrid(ys, xs, indexing="ij"))
    bg = _basis(gx, gy, p.degree, h, w)
    bo = _basis(gx, gy, p.offset_degree, h, w)
    grid_it = unit[:, gy.astype(np.int64), gx.astype(np.int64)].astype(np.float64)
    pairs = _pairs(unit, fwd, ok, gx, gy, p.radius)
    if not pairs:
        log.warning("deflicker: no frames could be matched along the flows; clip unchanged")
    thetas = [_solve_channel(pairs, grid_it, bg, bo, p, c, n, h, w, tick) for c in range(nc)]
    t2 = time.perf_counter()

    # The brightness path on a coarse grid: I = a J + b with a = 1 / p, b = -q / p.
    ng = bg.shape[1]
    gh, gw = min(h, _GRID), min(w, _GRID)
    cy = np.linspace(0.0, h - 1.0, gh)
    cx = np.linspace(0.0, w - 1.0, gw)
    gain = np.empty((n, gh, gw, nc))
    offs = np.empty((n, gh, gw, nc))
    for c, theta in enumerate(thetas):
        for t in range(n):
            gain[t, :, :, c] = _field(theta[t, :ng], cy, cx, p.degree, h, w)
            offs[t, :, :, c] = _field(theta[t, ng:], cy, cx, p.offset_degree, h, w)
    bad = gain <= 1e-3
    if bad.any():
        log.warning("deflicker: degenerate gain estimate on %d grid points; clamped",
                    int(bad.sum()))
        gain = np.maximum(gain, 1e-3)
    a_path, b_path = 1.0 / gain, -offs / gain
    levels = (0.25, 0.75)  # how a dark and a light tone render, per frame and channel
    summary = np.concatenate([(a_path * lv + b_path).mean(axis=(1, 2)) for lv in levels],
                             axis=1)
    s_mat, cuts = _smoother(summary, p)
    if cuts:
        log.info("deflicker: lasting brightness steps kept at frames %s", cuts)
    a_s = np.tensordot(s_mat, a_path, axes=1)
    b_s = np.tensordot(s_mat, b_path, axes=1)

    ry, rx = _hat(h, gh), _hat(w, gw)
    yy, xx = np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64)
    out = np.empty_like(work)
    mean_gain = np.empty((n, nc))
    mean_off = np.empty((n, nc))
    scale = np.float32(hi - lo)
    for c, theta in enumerate(thetas):
        for t in range(n):
            pf = _field(theta[t, :ng], yy, xx, p.degree, h, w)
            qf = _field(theta[t, ng:], yy, xx, p.offset_degree, h, w)
            af = ry @ a_s[t, :, :, c] @ rx.T
            bf = ry @ b_s[t, :, :, c] @ rx.T
            g_unit = af * pf  # out_unit = g_unit * in_unit + o_unit
            o_unit = af * qf + bf
            out[t, :, :, c] = (g_unit * unit[t, :, :, c] + o_unit) * scale + np.float32(lo)
            mean_gain[t, c] = float(g_unit.mean())
            mean_off[t, c] = float((o_unit * (hi - lo) + lo * (1.0 - g_unit)).mean())
    tick()
    if stats is not None:
        stats.update(seconds=time.perf_counter() - t0, flow_seconds=t1 - t0,
                     fit_seconds=t2 - t1, steps=cuts, smoother=s_mat, gain=mean_gain,
                     offset=mean_off)
    return back(_to_dtype(out, dtype))
