"""Seeded archival-film defects, planted in clean clips for restoration benchmarks.

A film-restoration benchmark needs degraded clips whose damage is known exactly: the
pixels dirt covers, the gains and offsets of the flicker, the motion of the gate weave.
This module plants those defects in a clean clip with a local seeded generator
(``numpy.random.default_rng(seed)``, never the global state) and returns them beside
the degraded clip, so that dirt removal, deflicker and stabilisation can each be scored
against the truth.

Conventions: a clip is ``(F, H, W)`` (grey) or ``(F, H, W, C)`` (colour), any real dtype
on 0-255; every function returns ``float32`` of the same shape, not clipped (the flicker
and the noise may leave 0-255).  The same arguments and seed give the same bytes.

* :func:`plant_dirt` -- dark and bright blotches (dust, dirt, hairs) with ragged, soft
  rims, 0.3-1 % of every frame, never where the previous frame was blotched; returns the
  exact mask of the pixels it changed.
* :func:`plant_flicker` -- per-frame gain and offset times a smooth spatial gain field.
* :func:`plant_weave` -- per-frame random translation and rotation (gate weave), with
  :func:`weave_residual` to score a stabiliser's estimate of it.
* :func:`plant_noise` -- mild white Gaussian noise (film grain stand-in).
* :func:`plant_defects` -- all of them in the physical order: weave, flicker, dirt,
  noise.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "BORDERS",
    "DefectResult",
    "FlickerParams",
    "WeaveParams",
    "plant_defects",
    "plant_dirt",
    "plant_flicker",
    "plant_noise",
    "plant_weave",
    "weave_residual",
]

log = logging.getLogger(__name__)

#: Border modes of :func:`plant_weave` (OpenCV's names): ``reflect`` mirrors with the
#: edge pixel repeated (``fedcba|abcdef``), ``reflect101`` without (``fedcb|abcdef``),
#: ``replicate`` repeats the edge pixel, ``constant`` fills with 0.
BORDERS = {
    "reflect": cv2.BORDER_REFLECT,
    "reflect101": cv2.BORDER_REFLECT_101,
    "replicate": cv2.BORDER_REPLICATE,
    "constant": cv2.BORDER_CONSTANT,
}
_INTERPOLATIONS = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}

#: A blotch of radius ``r`` never reaches beyond ``_EXTENT * r`` of its centre (the
#: ragged boundary stays inside that disc).
_EXTENT = 1.3
#: Fraction of blotches drawn as thin curved hairs rather than blobs.
_HAIR_FRACTION = 0.12
#: Blotches tried per frame before giving up on the coverage target (a safeguard for
#: pictures on which the blotches hardly change anything).
_MAX_BLOTCHES = 2000
#: Positions tried for one blotch before drawing another one.
_PLACE_TRIES = 50
#: Smaller redraws of a blotch whose footprint exceeds the frame's coverage budget.
_SHRINK_TRIES = 6
#: Grey levels of dark and bright blotches on 0-255 (the texture stays inside).
_DARK = (0.0, 60.0)
_BRIGHT = (200.0, 255.0)


# --------------------------------------------------------------------------- checks


def _as_clip(clip: ArrayLike, name: str = "clip") -> np.ndarray:
    """``clip`` as a new float32 ``(F, H, W, C)`` array (a grey clip gets ``C = 1``)."""
    arr = np.asarray(clip)
    if arr.ndim not in (3, 4):
        raise ValueError(f"{name}: expected shape (F, H, W) or (F, H, W, C), got {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_) \
            or np.issubdtype(arr.dtype, np.complexfloating):
        raise ValueError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    if arr.shape[0] < 1 or arr.shape[1] < 2 or arr.shape[2] < 2 \
            or (arr.ndim == 4 and arr.shape[3] < 1):
        raise ValueError(f"{name}: clip of shape {arr.shape} is too small "
                         "(need F >= 1, H >= 2, W >= 2)")
    out = np.array(arr, dtype=np.float32)
    if not np.isfinite(out).all():
        raise ValueError(f"{name}: contains NaN or infinite values")
    return out if out.ndim == 4 else out[..., None]


def _restore_shape(out: np.ndarray, like: np.ndarray) -> np.ndarray:
    """``out`` ``(F, H, W, C)`` back to the rank of the caller's clip."""
    return out[..., 0] if np.ndim(like) == 3 else out


def _number(value: Any, name: str, low: float | None = None, high: float | None = None,
            low_open: bool = False, high_open: bool = False) -> float:
    """``value`` as a finite float within the given bounds, else ``ValueError(name)``."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    if low is not None and (x < low or (low_open and x == low)):
        raise ValueError(f"{name}: must be {'>' if low_open else '>='} {low}, got {value!r}")
    if high is not None and (x > high or (high_open and x == high)):
        raise ValueError(f"{name}: must be {'<' if high_open else '<='} {high}, got {value!r}")
    return x


def _interval(value: Any, name: str, low: float, high: float | None = None,
              low_open: bool = False) -> tuple[float, float]:
    """``value`` as ``(a, b)`` with ``low <= a <= b <= high``, else ``ValueError(name)``."""
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a pair (low, high), got {value!r}") from None
    a = _number(a, name, low, high, low_open=low_open)
    b = _number(b, name, low, high, low_open=low_open)
    if a > b:
        raise ValueError(f"{name}: low {a} is above high {b}")
    return a, b


def _seed(seed: Any) -> int:
    """``seed`` as a non-negative int, else ``ValueError("seed")``."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    return int(seed)


# --------------------------------------------------------------------------- dirt


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int],
                  sigma: float) -> np.ndarray:
    """White noise blurred by a Gaussian of ``sigma`` px, zero mean and unit std."""
    z = rng.standard_normal(shape, dtype=np.float32)
    z = cv2.GaussianBlur(z, (0, 0), sigmaX=sigma, borderType=cv2.BORDER_REFLECT)
    z -= z.mean()
    std = float(z.std())
    return z / std if std > 0 else z


def _patch_grid(rng: np.random.Generator, r: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Pixel offsets ``(yy, xx)`` from a sub-pixel blotch centre on a square patch of
    half-size ``R`` (one pixel of margin past the blotch's extent), and ``R``."""
    half = int(math.ceil(_EXTENT * r)) + 1
    off = rng.uniform(-0.5, 0.5, 2).astype(np.float32)
    g = np.arange(-half, half + 1, dtype=np.float32)
    return g[:, None] - off[1], g[None, :] - off[0], half


def _blob(rng: np.random.Generator, r: float) -> np.ndarray:
    """Opacity ``(2R+1, 2R+1)`` on [0, 1] of a ragged blob of nominal radius ``r`` px.

    A disc whose radius follows a random sum of low harmonics (irregular, elongated or
    lobed outlines), roughened by smoothed noise and given a soft rim of 0.8-2 px."""
    yy, xx, half = _patch_grid(rng, r)
    rho = np.hypot(xx, yy)
    theta = np.arctan2(yy, xx)
    shape = np.ones_like(rho)
    for k in range(2, 7):
        shape += rng.uniform(0.0, 0.35) / k * np.cos(k * theta + rng.uniform(0.0, 2 * np.pi))
    boundary = r * np.clip(shape, 0.6, 1.2)
    n = 2 * half + 1
    rag = _smooth_noise(rng, (n, n), max(0.8, r / 8.0)) * (0.08 * r + 0.4)
    soft = rng.uniform(0.8, 2.0)
    alpha = np.clip((boundary + rag - rho) / soft + 0.5, 0.0, 1.0)
    alpha[rho > _EXTENT * r] = 0.0
    return alpha.astype(np.float32)


def _hair(rng: np.random.Generator, r: float) -> np.ndarray:
    """Opacity ``(2R+1, 2R+1)`` on [0, 1] of a thin curved hair of half-length about
    ``r`` px: a quadratic Bezier curve 1-2.2 px wide with a soft edge."""
    yy, xx, half = _patch_grid(rng, r)
    width = rng.uniform(1.0, 2.2)
    length = max(1.0, 0.9 * r - 1.0)
    phi = rng.uniform(0.0, np.pi)
    u = np.array([np.cos(phi), np.sin(phi)])
    v = np.array([-u[1], u[0]])
    bend = rng.uniform(-0.5, 0.5) * length
    t = np.linspace(0.0, 1.0, int(math.ceil(4 * length)) + 2)[:, None]
    pts = (1 - t) ** 2 * (-length * u) + 2 * (1 - t) * t * (bend * v) + t ** 2 * (length * u)
    pts = pts.astype(np.float32)
    n = 2 * half + 1
    px = np.broadcast_to(xx, (n, n)).reshape(-1, 1)
    py = np.broadcast_to(yy, (n, n)).reshape(-1, 1)
    dist = np.sqrt(((px - pts[:, 0]) ** 2 + (py - pts[:, 1]) ** 2).min(axis=1)).reshape(n, n)
    alpha = np.clip(width / 2 + 0.5 - dist, 0.0, 1.0)
    alpha[np.hypot(xx, yy) > _EXTENT * r] = 0.0
    return alpha.astype(np.float32)


def _blotch_value(rng: np.random.Generator, n: int, dark: bool) -> np.ndarray:
    """Grey level ``(n, n)`` of a blotch: a near-constant level with a faint texture."""
    lo, hi = _DARK if dark else _BRIGHT
    base = rng.uniform(lo + 8.0, 45.0) if dark else rng.uniform(210.0, hi - 7.0)
    texture = _smooth_noise(rng, (n, n), 1.2) * rng.uniform(2.0, 8.0)
    return np.clip(base + texture, lo, hi)


def _boxes(cy: int, cx: int, half: int, h: int,
           w: int) -> tuple[tuple[slice, slice], tuple[slice, slice]]:
    """Frame and patch slices of a ``(2*half+1)``-square patch centred on ``(cy, cx)``."""
    y0, x0 = cy - half, cx - half
    y1, x1 = cy + half + 1, cx + half + 1
    frame = (slice(max(y0, 0), min(y1, h)), slice(max(x0, 0), min(x1, w)))
    patch = (slice(max(y0, 0) - y0, min(y1, h) - y0), slice(max(x0, 0) - x0, min(x1, w) - x0))
    return frame, patch


def plant_dirt(clip: ArrayLike, seed: int = 0, coverage: tuple[float, float] = (0.003, 0.01),
               radius: tuple[float, float] = (3.0, 20.0), dark_fraction: float = 0.7,
               threshold: float = 8.0) -> tuple[np.ndarray, np.ndarray]:
    """Plant dirt and dust: dark and bright blotches with ragged, soft rims.

    Why: the known mask lets a dirt-removal benchmark score detection (precision, recall)
    and repair (error inside the mask) exactly.

    Every frame gets its own coverage target drawn uniformly in ``coverage``; blotches
    are added until the changed pixels reach it, a blotch whose footprint would take the
    frame past ``coverage[1]`` being redrawn smaller (no smaller than ``radius[0]``; the
    frame is then done).  A blotch's radius is log-uniform in
    ``radius`` (many specks, few large blotches); 88 % are irregular blobs (a disc whose
    outline follows random low harmonics, roughened by smoothed noise, with a soft rim
    0.8-2 px wide), 12 % thin curved hairs of half-length about the radius.  Nothing
    reaches beyond 1.3 times the radius from the blotch's centre.  A blotch is dark
    (grey 0-60) with probability ``dark_fraction``, else bright (200-255), a
    near-constant level with a faint texture, the same on every channel, 85-100 %
    opaque in its core and partially opaque on its rim.  Blotches of one frame do not
    touch each other, and no blotch touches a pixel of the previous frame's mask (its
    position is drawn again): dirt is never at the same place in consecutive frames.

    Parameters
    ----------
    clip : array_like, shape (F, H, W) or (F, H, W, C)
        The clean clip, 0-255.
    seed : int
        Seed of the local generator (default 0).
    coverage : (float, float)
        Range of the fraction of each frame's pixels in the mask (default 0.3-1 %),
        within [0, 1].
    radius : (float, float)
        Range of the blotch radii in pixels (default 3-20), positive.
    dark_fraction : float
        Probability of a dark blotch (default 0.7), within [0, 1].
    threshold : float
        A pixel is in the mask when some channel changed by at least this much, in grey
        levels (default 8), positive.

    Returns
    -------
    dirty : numpy.ndarray, float32, shape of ``clip``
        The clip with the blotches (not clipped; the blotch levels stay in 0-255).
    mask : numpy.ndarray, bool, shape (F, H, W)
        ``(abs(dirty - clean) >= threshold).any(channel)`` with ``clean`` the clip as
        float32: exactly the pixels the dirt changed by ``threshold`` or more.

    Raises
    ------
    ValueError
        On a clip that is not ``(F, H, W[, C])`` or not finite, or an argument out of
        range (the message names it).

    Notes
    -----
    On a frame too small for the smallest blotch to fit between the coverage bounds,
    or a picture that the blotches hardly change, a frame may stay under
    ``coverage[0]``; a warning is logged.
    """
    clean = _as_clip(clip)
    seed = _seed(seed)
    cov_lo, cov_hi = _interval(coverage, "coverage", 0.0, 1.0)
    r_lo, r_hi = _interval(radius, "radius", 0.0, low_open=True)
    dark_fraction = _number(dark_fraction, "dark_fraction", 0.0, 1.0)
    threshold = _number(threshold, "threshold", 0.0, low_open=True)

    rng = np.random.default_rng(seed)
    n_frames, h, w, _ = clean.shape
    dirty = clean.copy()
    mask = np.zeros((n_frames, h, w), dtype=bool)
    prev = np.zeros((h, w), dtype=bool)
    lo_px, hi_px = cov_lo * h * w, cov_hi * h * w
    kernel = np.ones((3, 3), dtype=np.uint8)
    for f in range(n_frames):
        target = rng.uniform(cov_lo, cov_hi) * h * w
        covered = 0
        taken = np.zeros((h, w), dtype=bool)  # this frame's blotches, grown by 1 px
        changed_so_far = np.zeros((h, w), dtype=bool)
        for _ in range(_MAX_BLOTCHES):
            if covered >= target:
                break
            budget = hi_px - covered
            r = math.exp(rng.uniform(math.log(r_lo), math.log(r_hi)))
            hair = rng.random() < _HAIR_FRACTION
            foot = None
            for _ in range(_SHRINK_TRIES):  # shrink until the footprint fits the budget
                alpha = _hair(rng, r) if hair else _blob(rng, r)
                area = int(np.count_nonzero(alpha))
                if area <= budget:
                    foot = alpha > 0
                    break
                if r <= r_lo:
                    break
                r = max(r_lo, r * 0.95 * math.sqrt(budget / area))
            if foot is None:
                break
            half = alpha.shape[0] // 2
            place = None
            for _ in range(_PLACE_TRIES):
                cy, cx = int(rng.integers(0, h)), int(rng.integers(0, w))
                fs, ps = _boxes(cy, cx, half, h, w)
                if not (foot[ps] & (prev[fs] | taken[fs])).any():
                    place = fs, ps
                    break
            if place is None:
                continue
            fs, ps = place
            value = _blotch_value(rng, alpha.shape[0], rng.random() < dark_fraction)
            a = alpha[ps] * np.float32(rng.uniform(0.85, 1.0))
            region = dirty[f][fs]
            region *= (1.0 - a)[..., None]
            region += (a * value[ps])[..., None]
            changed = (np.abs(region - clean[f][fs]) >= threshold).any(axis=-1)
            covered += int(np.count_nonzero(changed & ~changed_so_far[fs]))
            changed_so_far[fs] |= changed
            taken[fs] |= cv2.dilate(foot.astype(np.uint8), kernel)[ps].astype(bool)
        mask[f] = (np.abs(dirty[f] - clean[f]) >= threshold).any(axis=-1)
        if covered < lo_px:
            log.warning("plant_dirt: frame %d covered %d px, under coverage[0] (%.1f px)",
                        f, covered, lo_px)
        prev = mask[f]
    return _restore_shape(dirty, clip), mask


# --------------------------------------------------------------------------- flicker


@dataclass(frozen=True, eq=False)
class FlickerParams:
    """The flicker :func:`plant_flicker` planted: ``out = fields * gains * clip + offsets``.

    Attributes
    ----------
    gains : numpy.ndarray, float64, shape (F,)
        Global gain of each frame; their mean is 1.
    offsets : numpy.ndarray, float64, shape (F,)
        Offset of each frame in grey levels (0-255 units); their mean is 0.
    fields : numpy.ndarray, float32, shape (F, H, W)
        Smooth spatial gain field of each frame; mean 1, largest deviation from 1 equal
        to ``local``.
    """

    gains: np.ndarray
    offsets: np.ndarray
    fields: np.ndarray


def _low_frequency_field(rng: np.random.Generator, h: int, w: int, local: float,
                         terms: int = 4) -> np.ndarray:
    """A smooth field ``(H, W)`` of mean 1 and largest deviation ``local``: a random sum
    of ``terms`` separable 2D cosines of at most one cycle across the frame."""
    y = (np.arange(h) + 0.5) / h
    x = (np.arange(w) + 0.5) / w
    amp = rng.standard_normal(terms)
    fy, fx = rng.uniform(0.0, 1.0, terms), rng.uniform(0.0, 1.0, terms)
    py, px = rng.uniform(0.0, 2 * np.pi, terms), rng.uniform(0.0, 2 * np.pi, terms)
    cy = np.cos(2 * np.pi * y[:, None] * fy + py) * amp  # (H, terms)
    cx = np.cos(2 * np.pi * fx[:, None] * x + px[:, None])  # (terms, W)
    field = cy @ cx
    field -= field.mean()
    peak = np.abs(field).max()
    if peak <= 1e-12 or local == 0.0:
        return np.ones((h, w), dtype=np.float32)
    return (1.0 + local * field / peak).astype(np.float32)


def plant_flicker(clip: ArrayLike, seed: int = 0, gain: tuple[float, float] = (0.75, 1.25),
                  offset: float = 15.0,
                  local: float = 0.15) -> tuple[np.ndarray, FlickerParams]:
    """Plant flicker: per-frame gain and offset times a smooth random gain field.

    Why: a deflicker benchmark needs the true per-frame brightness changes to report the
    residual flicker of a method.

    ``out[f] = fields[f] * gains[f] * clip[f] + offsets[f]`` (the field on every
    channel).  Each frame draws a gain uniformly in ``gain`` and an offset uniformly in
    ``[-offset, offset]``, independently; the gains are then divided by their mean over
    the clip (so they average to 1 and may leave ``gain`` slightly) and the offsets
    shifted to average 0.  A one-frame clip thus gets gain 1 and offset 0.  Each
    frame's field is an independent random sum of four low-frequency separable
    cosines (at most one cycle across the frame), of mean 1 and largest deviation from
    1 exactly ``local``.

    Parameters
    ----------
    clip : array_like, shape (F, H, W) or (F, H, W, C)
        The clean clip, 0-255.
    seed : int
        Seed of the local generator (default 0).
    gain : (float, float)
        Range of the global gains before normalisation (default 0.75-1.25), positive.
    offset : float
        Largest offset before normalisation, grey levels (default 15), >= 0.
    local : float
        Largest relative deviation of the spatial gain field (default 0.15), in [0, 1).

    Returns
    -------
    flickered : numpy.ndarray, float32, shape of ``clip``
        The flickering clip (not clipped).
    params : FlickerParams
        The gains, offsets and fields.

    Raises
    ------
    ValueError
        On a bad clip or an argument out of range (the message names it).
    """
    src = _as_clip(clip)
    seed = _seed(seed)
    g_lo, g_hi = _interval(gain, "gain", 0.0, low_open=True)
    offset = _number(offset, "offset", 0.0)
    local = _number(local, "local", 0.0, 1.0, high_open=True)

    rng = np.random.default_rng(seed)
    n_frames, h, w, _ = src.shape
    gains = rng.uniform(g_lo, g_hi, n_frames)
    gains /= gains.mean()
    offsets = rng.uniform(-offset, offset, n_frames)
    offsets -= offsets.mean()
    fields = np.stack([_low_frequency_field(rng, h, w, local) for _ in range(n_frames)])
    scale = fields * gains[:, None, None].astype(np.float32)
    out = scale[..., None] * src + offsets[:, None, None, None].astype(np.float32)
    params = FlickerParams(gains=gains, offsets=offsets, fields=fields)
    return _restore_shape(out.astype(np.float32, copy=False), clip), params


# --------------------------------------------------------------------------- weave


@dataclass(frozen=True, eq=False)
class WeaveParams:
    """The gate weave :func:`plant_weave` planted.

    Attributes
    ----------
    dx, dy : numpy.ndarray, float64, shape (F,)
        Translation of each frame in pixels (x right, y down).
    angle : numpy.ndarray, float64, shape (F,)
        Rotation of each frame about the frame centre ``((W-1)/2, (H-1)/2)`` in degrees;
        positive turns the picture counter-clockwise on screen (OpenCV's convention).
    matrices : numpy.ndarray, float64, shape (F, 2, 3)
        Affine maps from clean to woven pixel coordinates: the content at ``p`` in the
        clean frame is at ``A @ p + b`` in the woven one, ``[A | b] = matrices[f]``.
    shape : (int, int)
        ``(H, W)`` of the frames, for :func:`weave_residual`.
    """

    dx: np.ndarray
    dy: np.ndarray
    angle: np.ndarray
    matrices: np.ndarray
    shape: tuple[int, int]


def _warp(frame: np.ndarray, matrix: np.ndarray, flags: int, border: int) -> np.ndarray:
    """``frame`` ``(H, W, C)`` float32 warped forward by ``matrix`` (clean -> woven)."""
    h, w, c = frame.shape
    if c <= 4:
        out = cv2.warpAffine(frame if c > 1 else frame[..., 0], matrix, (w, h), flags=flags,
                             borderMode=border, borderValue=0)
        return out.reshape(h, w, c)
    return np.stack([cv2.warpAffine(np.ascontiguousarray(frame[..., k]), matrix, (w, h),
                                    flags=flags, borderMode=border, borderValue=0)
                     for k in range(c)], axis=-1)


def plant_weave(clip: ArrayLike, seed: int = 0, shift: float = 4.0, angle: float = 0.5,
                border: str = "reflect",
                interpolation: str = "cubic") -> tuple[np.ndarray, WeaveParams]:
    """Plant gate weave: a random translation and rotation of every frame.

    Why: a stabilisation benchmark needs each frame's true displacement to measure the
    jitter a method leaves (:func:`weave_residual`).

    Each frame, independently, draws ``dx`` and ``dy`` uniformly in ``[-shift, shift]``
    px and a rotation uniformly in ``[-angle, angle]`` degrees about the frame centre,
    and is resampled with :func:`cv2.warpAffine` in float32 (which rounds source
    positions to 1/32 px: the picture sits within about 0.03 px of ``params``).

    Parameters
    ----------
    clip : array_like, shape (F, H, W) or (F, H, W, C)
        The clean clip, 0-255.
    seed : int
        Seed of the local generator (default 0).
    shift : float
        Largest translation in pixels along x and along y (default 4), >= 0.
    angle : float
        Largest rotation in degrees (default 0.5), >= 0.
    border : str
        How pixels brought in from outside the frame are filled (default ``"reflect"``,
        mirrored with the edge pixel repeated); one of :data:`BORDERS`.
    interpolation : str
        ``"cubic"`` (default, bicubic: sharper, may overshoot by a few levels at edges)
        or ``"linear"`` (bilinear).

    Returns
    -------
    woven : numpy.ndarray, float32, shape of ``clip``
        The woven clip.
    params : WeaveParams
        The per-frame translations, angles and clean-to-woven affine matrices.

    Raises
    ------
    ValueError
        On a bad clip or an argument out of range (the message names it).
    """
    src = _as_clip(clip)
    seed = _seed(seed)
    shift = _number(shift, "shift", 0.0)
    angle = _number(angle, "angle", 0.0)
    if border not in BORDERS:
        raise ValueError(f"border: expected one of {sorted(BORDERS)}, got {border!r}")
    if interpolation not in _INTERPOLATIONS:
        raise ValueError(f"interpolation: expected one of {sorted(_INTERPOLATIONS)}, "
                         f"got {interpolation!r}")

    rng = np.random.default_rng(seed)
    n_frames, h, w, _ = src.shape
    dx = rng.uniform(-shift, shift, n_frames)
    dy = rng.uniform(-shift, shift, n_frames)
    angles = rng.uniform(-angle, angle, n_frames)
    centre = ((w - 1) / 2.0, (h - 1) / 2.0)
    matrices = np.empty((n_frames, 2, 3))
    out = np.empty_like(src)
    for f in range(n_frames):
        m = cv2.getRotationMatrix2D(centre, float(angles[f]), 1.0)
        m[:, 2] += (dx[f], dy[f])
        matrices[f] = m
        out[f] = _warp(src[f], m, _INTERPOLATIONS[interpolation], BORDERS[border])
    params = WeaveParams(dx=dx, dy=dy, angle=angles, matrices=matrices, shape=(h, w))
    return _restore_shape(out, clip), params


def weave_residual(estimate: ArrayLike | None, params: WeaveParams) -> np.ndarray:
    """Residual jitter of a stabiliser: RMS pixel displacement left per frame.

    Why: one number per frame, in pixels, says how much of the planted weave an
    estimate missed, whatever the estimate's form (translation only or affine).

    For each frame, the root mean square over the frame's pixel centres ``p`` of
    ``|M_true p - M_est p|``, with ``M_true`` the planted clean-to-woven map
    (``params.matrices``) and ``M_est`` the estimate of it, computed in closed form.
    A stabiliser's correction ``C`` (woven to stabilised) is scored by passing its
    inverse (:func:`cv2.invertAffineTransform`).  The clean frame is the reference, so
    a constant offset of the estimate counts as residual.

    Parameters
    ----------
    estimate : array_like or None
        The estimated motion: ``(F, 2, 3)`` affine matrices (clean to woven), or
        ``(F, 2)`` translations ``(dx, dy)`` in pixels; None for no correction (the
        residual is then the planted weave itself).
    params : WeaveParams
        What :func:`plant_weave` returned.

    Returns
    -------
    numpy.ndarray, float64, shape (F,)
        RMS residual displacement of each frame in pixels.

    Raises
    ------
    ValueError
        If ``estimate`` has another shape.
    """
    true = np.asarray(params.matrices, dtype=np.float64)
    n_frames = true.shape[0]
    if estimate is None:
        est = np.zeros_like(true)
        est[:, 0, 0] = est[:, 1, 1] = 1.0
    else:
        arr = np.asarray(estimate, dtype=np.float64)
        if arr.shape == (n_frames, 2):
            est = np.zeros_like(true)
            est[:, 0, 0] = est[:, 1, 1] = 1.0
            est[:, :, 2] = arr
        elif arr.shape == (n_frames, 2, 3):
            est = arr
        else:
            raise ValueError(f"estimate: expected shape ({n_frames}, 2) or ({n_frames}, 2, 3), "
                             f"got {arr.shape}")
    d = true - est  # displacement d(p) = A p + b, per frame
    h, w = params.shape
    # Moments of the pixel centres x in 0..W-1, y in 0..H-1 (independent).
    ex, ey = (w - 1) / 2.0, (h - 1) / 2.0
    exx, eyy = (w - 1) * (2 * w - 1) / 6.0, (h - 1) * (2 * h - 1) / 6.0
    a, c, b = d[:, :, 0], d[:, :, 1], d[:, :, 2]  # (F, 2) each: x, y coefficients, constant
    mean_sq = (a ** 2 * exx + c ** 2 * eyy + b ** 2
               + 2 * a * c * ex * ey + 2 * a * b * ex + 2 * c * b * ey).sum(axis=1)
    return np.sqrt(np.maximum(mean_sq, 0.0))


# --------------------------------------------------------------------------- noise


def plant_noise(clip: ArrayLike, sigma: float = 3.0, seed: int = 0) -> np.ndarray:
    """Plant mild white Gaussian noise of standard deviation ``sigma`` grey levels.

    Why: a stand-in for film grain and scanner noise, so that restorations are not
    scored on an unrealistically clean picture.

    Parameters
    ----------
    clip : array_like, shape (F, H, W) or (F, H, W, C)
        The clip, 0-255.
    sigma : float
        Standard deviation in grey levels (default 3), >= 0; independent per pixel
        and channel.
    seed : int
        Seed of the local generator (default 0).

    Returns
    -------
    numpy.ndarray, float32, shape of ``clip``
        ``clip + noise``, not clipped.

    Raises
    ------
    ValueError
        On a bad clip, a negative ``sigma`` or seed.
    """
    src = _as_clip(clip)
    sigma = _number(sigma, "sigma", 0.0)
    seed = _seed(seed)
    noise = np.random.default_rng(seed).standard_normal(src.shape, dtype=np.float32)
    noise *= np.float32(sigma)
    src += noise
    return _restore_shape(src, clip)


# --------------------------------------------------------------------------- together


@dataclass(frozen=True, eq=False)
class DefectResult:
    """What :func:`plant_defects` planted.

    Attributes
    ----------
    dirt_mask : numpy.ndarray, bool, shape (F, H, W)
        The pixels the dirt step changed by ``threshold`` (8) levels or more, against
        the clip after weave and flicker (all False without dirt).
    before_dirt : numpy.ndarray, float32, shape of the clip
        The clip after weave and flicker, before dirt and noise: the target of a
        dirt-removal method.
    weave : WeaveParams or None
        The weave, None when off.
    flicker : FlickerParams or None
        The flicker, None when off.
    noise_sigma : float
        The noise's standard deviation in grey levels (0 when off).
    seeds : dict
        ``{"weave", "flicker", "dirt", "noise": int}``: the seed of each stage, derived
        from the clip's seed, so a stage can be replayed alone.
    """

    dirt_mask: np.ndarray
    before_dirt: np.ndarray
    weave: WeaveParams | None
    flicker: FlickerParams | None
    noise_sigma: float
    seeds: dict[str, int]


_STAGES = ("weave", "flicker", "dirt", "noise")


def _stage_kwargs(value: bool | Mapping[str, Any], name: str) -> dict[str, Any] | None:
    """``True`` -> defaults ``{}``, ``False`` -> None (off), a mapping -> its items."""
    if isinstance(value, bool | np.bool_):
        return {} if value else None
    if isinstance(value, Mapping):
        if "seed" in value:
            raise ValueError(f"{name}: the stage's seed is derived from seed; do not pass one")
        return dict(value)
    raise ValueError(f"{name}: expected a bool or a mapping of keyword arguments, "
                     f"got {value!r}")


def plant_defects(clip: ArrayLike, seed: int = 0, dirt: bool | Mapping[str, Any] = True,
                  flicker: bool | Mapping[str, Any] = True,
                  weave: bool | Mapping[str, Any] = True,
                  noise: float | None = 3.0) -> tuple[np.ndarray, DefectResult]:
    """Plant all the defects in their physical order: weave, flicker, dirt, noise.

    Why: one seeded call gives a benchmark a realistically degraded archival clip and
    the truth of each defect.

    The order follows the film's history: the frame moves in the gate (weave) when it
    is exposed, the exposure and development vary (flicker), dust and dirt settle on
    the print afterwards and so are not woven or flickered (dirt), and grain and
    scanner noise come with the scan (noise).  Each stage has its own seed derived
    from ``seed`` (:class:`numpy.random.SeedSequence`), so the stages are independent
    and each can be replayed alone with ``result.seeds[stage]``.

    Parameters
    ----------
    clip : array_like, shape (F, H, W) or (F, H, W, C)
        The clean clip, 0-255.
    seed : int
        Seed of the whole degradation (default 0).
    dirt, flicker, weave : bool or mapping
        True (default) for the stage with its defaults, False to skip it, or a mapping
        of keyword arguments of :func:`plant_dirt`, :func:`plant_flicker` or
        :func:`plant_weave` (without ``seed``).
    noise : float or None
        Standard deviation of the noise in grey levels (default 3); 0 or None skips it.

    Returns
    -------
    degraded : numpy.ndarray, float32, shape of ``clip``
        The degraded clip (not clipped).
    result : DefectResult
        The dirt mask, the clip before dirt, each stage's parameters and seeds.

    Raises
    ------
    ValueError
        On a bad clip, seed or stage argument (the message names it).
    """
    seed = _seed(seed)
    src = _as_clip(clip)
    stages = {name: _stage_kwargs(value, name)
              for name, value in (("weave", weave), ("flicker", flicker), ("dirt", dirt))}
    sigma = 0.0 if noise is None else _number(noise, "noise", 0.0)
    states = np.random.SeedSequence(seed).generate_state(len(_STAGES), dtype=np.uint32)
    seeds = {name: int(s) for name, s in zip(_STAGES, states, strict=True)}

    out = _restore_shape(src, clip)
    weave_params = flicker_params = None
    if stages["weave"] is not None:
        out, weave_params = plant_weave(out, seed=seeds["weave"], **stages["weave"])
    if stages["flicker"] is not None:
        out, flicker_params = plant_flicker(out, seed=seeds["flicker"], **stages["flicker"])
    before_dirt = out
    if stages["dirt"] is not None:
        out, mask = plant_dirt(out, seed=seeds["dirt"], **stages["dirt"])
    else:
        mask = np.zeros(src.shape[:3], dtype=bool)
    if sigma > 0:
        out = plant_noise(out, sigma=sigma, seed=seeds["noise"])
    result = DefectResult(dirt_mask=mask, before_dirt=before_dirt, weave=weave_params,
                          flicker=flicker_params, noise_sigma=sigma, seeds=seeds)
    return out, result
