"""Multi-frame clips of real photographs with exact dense trajectories and visibility.

The *generalisation suite* for trajectory methods: the procedural clips of
:mod:`varflow.generators.sequences` are built from analytic textures, which a
method can over-fit; the clips here are made of real photographs, rendered
the way a camera integrates light, under known smooth motions, so that the
ground truth is still exact.  Defaults of trajectory methods are chosen on the
*tuning* split (:data:`TUNING_SEEDS`) and reported on the disjoint *reporting*
split (:data:`REPORTING_SEEDS`).

Photographs
-----------
All images are photographs bundled with scikit-image (no download at run
time; imported lazily, see :func:`load_photo`), public domain or CC0 according
to the ``skimage.data`` docstrings:

* colour: ``astronaut`` (Eileen Collins, NASA), ``coffee`` (Rachel Michetti),
  ``chelsea`` (the cat, Stefan van der Walt), ``rocket`` (Falcon 9 launch,
  SpaceX), ``immunohistochemistry`` (stained colonic glands, microscope, CMMI),
  ``motorcycle_left`` and ``motorcycle_right`` (the two views of
  ``skimage.data.stereo_motorcycle``, Middlebury 2014 stereo benchmark);
* grey (replicated to three channels with a light seeded tint): ``camera``
  (photographer with a camera, Lav Varshney), ``brick`` (a brick wall,
  CC0Textures), ``grass`` (DeviantArt, CC0), ``gravel`` (CC0Textures), ``moon``
  (the lunar surface), ``coins`` (Greek coins, Brooklyn Museum), ``clock`` (a
  wall clock shot with a moving camera, Stefan van der Walt).

Synthetic images of scikit-image (colorwheel, logo, checkerboard, binary blobs,
phantom, text, horse) are not used.  Photos are converted to float32 in
``[0, 1]`` and cached in memory.  Backgrounds need large photos (see below);
objects are cut from the other photos, around the most textured of a few
candidate spots.

Construction
------------
Every layer ``L`` of a scene is a photograph seen through *texture
coordinates* ``p`` (output pixels at zoom 1): the photo value at ``p`` is the
photo interpolated at ``o_L + k_L p``, where the seeded scale ``k_L`` (photo
pixels per output pixel, :data:`PHOTO_SCALE_RANGE` = 1.2-2) *down-samples* the
photo, and the seeded offset ``o_L`` picks the crop.  For every frame ``n`` an
invertible map ``M_n: p -> frame-n position`` (float64) moves the layer.  The
point seen at pixel ``x`` of the reference frame ``ref`` is ``p = M_ref^{-1}(x)``
of the front-most layer that covers ``x`` there, and its trajectory is::

    traj[n, x] = M_n(M_ref^{-1}(x)) - x,          traj[ref] = 0 exactly,

evaluated in float64 from the analytic maps (the affine maps are inverted in
closed form, the non-rigid one by Newton's method to 1e-9 px), then cast to
float32.  The maps do not depend on ``ref``, so neither do the frames.

Visibility ``vis[n, x]`` is True when ``x + traj[n, x]`` is inside
``[0, W-1] x [0, H-1]`` and not covered in frame ``n`` by a layer in front of the
point's own layer (the coverage predicate of the renderer, at that position).

Rendering
---------
A camera pixel integrates the light over its area.  Frame ``n`` is rendered by
area sampling: every output pixel averages ``s x s`` sub-samples (default
``s = 4``, offsets ``(k + 0.5) / s - 0.5`` px from the pixel centre).  Each
sub-sample is mapped back into every layer by ``M_n^{-1}``; layers are
composited back to front with a coverage test per sub-sample, so object
boundaries are anti-aliased (mixed pixels) and the photos are pre-filtered by
the pixel footprint.  The photos are interpolated bilinearly: the values of
``scipy.ndimage.map_coordinates(order=1, mode="reflect")`` (the crops are chosen
inside the photo, so the boundary rule is never reached), computed by four
gathers of packed RGBA texels, which is about twice as fast.  On one core, a
31-frame 192 x 256 clip takes 1-2.5 s (the non-rigid family 4-5 s) and a
41-frame 384 x 512 clip 10-25 s.  An optional Gaussian blur
(``blur`` px, default 0) models the optics.  Trajectories and ownership use
the coverage predicate at the pixel centre, so at a mixed boundary pixel the
trajectory is the one of the layer covering its centre.

The crop of the background must contain the back-projection of the frame in
every frame of the clip.  Only the photos that fit it at 1.2 photo pixels per
output pixel or more are candidates; when none does (frames larger than about
384 x 512), the best-fitting ones are used at the scale that fits, which may
magnify the photo mildly (``k < 1``); ``params["photo_scale"]`` reports it.
For the non-rigid sheet, the back-projections of the sub-samples are computed
to ~1e-5 px (Newton's method at the pixel centres, then one chord step per
sub-sample); the trajectories are exact all the same.

Motion
------
Time is ``t_n = n / (F - 1)``.  Every motion is smooth in time and not of
constant velocity: translations follow ``P(t) = (t - 1/2) - beta / w (cos(w t +
phi) - cos(w / 2 + phi))`` (speed oscillating within ``1 +- beta``) plus a
sideways sinusoid, and rotations, zooms and shears are sinusoids or
quadratics in time.  ``magnitude`` (px, default drawn per seed in ``[30, 50]``)
is the maximum displacement over the clip of the background pixels of the
centre frame ``F // 2`` (the default reference), to which the amplitudes are
calibrated (exactly for affine motion, on a 25 x 25 grid for the non-rigid one).
The peak speed is limited so that the step between frames stays below
about 6 px for ``F >= 31`` at the default magnitudes (longer clips have
smaller steps); ``params["max_step"]`` reports the largest step.

Families
--------
``"affine"``
    A photograph under a camera motion ``M_n(p) = c + A_n (p - c) + b_n`` with
    ``A_n = exp(z_n) R(theta_n) [[1, h_n], [0, 1]]``: pan (``b_n``), roll
    (``theta_n``), zoom (``z_n``) and a slight shear (``h_n``).
``"nonrigid"``
    A photographic sheet deformed by four travelling waves
    ``M_n(p) = p + d_n + sum_k a_k e_k sin(kappa_k . p - omega_k t_n + phi_k)``
    (wavelengths 0.6-1.3 x ``max(H, W)``, ``|grad s| <= 0.5`` so that ``M_n`` is
    invertible) plus a drift ``d_n`` along a smooth path; the waves make
    35-60 % of the magnitude when the strain bound allows.
``"objects"``
    The affine background and 1-3 objects cut from other photographs, with
    smooth outlines (superellipses or rounded polygons of circumradius 8-25 %
    of ``min(H, W)``), each under its own motion ``M_n(p) = c_n + rho_n
    R(psi_n) p`` (a smooth path, rotation and a zoom of a few percent), in a
    seeded depth order, occluding the background and each other.  One of them
    is placed so that it leaves the frame towards the first or the last frame
    (it enters or leaves during the clip).  The paths of the objects reach
    0.7-1.3 x the magnitude (less if the speed would exceed ~174 px per clip);
    they turn by up to 0.4 rad and zoom by up to 10 % (in proportion to the
    magnitude below 30 px).
``"illumination"``
    As ``"objects"``, then the light changes slowly: ``I'_n(x) = clip(g_n
    exp(gamma_n . (x - c)) I_n(x) + o_n, 0, 1)`` with a global gain ``g_n`` within
    ``[0.83, 1.2]`` that changes by 10-30 % over the clip, an offset ``o_n`` of a
    few percent and a spatial gain gradient ``gamma_n`` (10-20 % across the
    half-diagonal) whose direction turns over the clip.  Trajectories are
    unaffected; ``clean_frames`` are the frames before the change of light.
``"noise"``
    As ``"objects"``, plus signal-dependent Gaussian camera noise of standard
    deviation ``sigma (0.6 + 0.8 I)`` (``sigma`` in ``[0.01, 0.03]`` per seed, the
    std at mid-grey), independent per sample, on every frame including the
    reference, clipped to ``[0, 1]``; ``clean_frames`` are noise-free.

Splits
------
:data:`SPLITS` maps ``"tuning"`` to :data:`TUNING_SEEDS` and ``"reporting"``
to :data:`REPORTING_SEEDS` (disjoint).  Each ``(family, seed)`` draws its
photos, crops, scales, shapes and motions from a local generator seeded by
``(seed, crc32(family))``; no global random state is used.

References
----------
S. van der Walt et al., "scikit-image: image processing in Python", PeerJ 2:e453,
2014 (the photographs; their sources and licences are in the docstrings of
``skimage.data``).

R. Garg, A. Roussos, L. Agapito, "A variational approach to video registration
with subspace constraints", International Journal of Computer Vision 104(3),
286-314, 2013 (the procedural counterpart, :mod:`varflow.generators.sequences`).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates

from .sequences import (
    SyntheticSequence,
    _AffineMotion,
    _calibrate,
    _check_float,
    _check_int,
    _max_disp,
    _rotation,
    _trajectories,
    _WaveMotion,
)

__all__ = [
    "FAMILIES",
    "COLOUR_PHOTOS",
    "GREY_PHOTOS",
    "PHOTOS",
    "PHOTO_SCALE_RANGE",
    "TUNING_SEEDS",
    "REPORTING_SEEDS",
    "SPLITS",
    "load_photo",
    "make_photo_clip",
    "photo_cases",
    "split_cases",
    "photo_suite",
]

FAMILIES = ("affine", "nonrigid", "objects", "illumination", "noise")
COLOUR_PHOTOS = (
    "astronaut",
    "coffee",
    "chelsea",
    "rocket",
    "immunohistochemistry",
    "motorcycle_left",
    "motorcycle_right",
)
GREY_PHOTOS = ("camera", "brick", "grass", "gravel", "moon", "coins", "clock")
PHOTOS = COLOUR_PHOTOS + GREY_PHOTOS
PHOTO_SCALE_RANGE = (1.2, 2.0)  # photo pixels per output pixel
TUNING_SEEDS = (0, 1, 2)
REPORTING_SEEDS = (100, 101, 102)
SPLITS = {"tuning": TUNING_SEEDS, "reporting": REPORTING_SEEDS}

_MAX_FRAMES = 60
_MIN_SIZE = 32
_MAX_STRAIN = 0.5  # bound on |grad s| of the waves (keeps M_n invertible)
_MAX_SPEED = 174.0  # px per clip (t in [0, 1]): steps <= 5.8 px for F >= 31
_SPEED_RATIO = 3.4  # peak speed / maximum displacement of the camera motion
_FINE_TIMES = np.linspace(0.0, 1.0, 241)  # for speed checks, independent of F
_CHUNK_SAMPLES = 1 << 18  # sub-samples per rendering chunk (bounds memory)
_PAD = 2.0  # photo pixels kept between a crop and the photo border
_LUMA = np.array([0.2125, 0.7154, 0.0721], np.float32)  # as skimage.color.rgb2gray

_PHOTO_CACHE: dict[str, np.ndarray] = {}


# --------------------------------------------------------------------------- photographs


def load_photo(name: str) -> np.ndarray:
    """Load one bundled photograph as float32 in ``[0, 1]`` (cached, read-only).

    Parameters
    ----------
    name : str
        One of :data:`PHOTOS`.

    Returns
    -------
    ndarray
        ``(h, w, 3)`` for the colour photos, ``(h, w)`` for the grey ones.

    Raises
    ------
    ValueError
        On an unknown name.
    ImportError
        When scikit-image is not installed.
    """
    if name not in PHOTOS:
        raise ValueError(f"name: expected one of {PHOTOS}, got {name!r}")
    cached = _PHOTO_CACHE.get(name)
    if cached is not None:
        return cached
    try:
        from skimage import data
    except ImportError as exc:
        raise ImportError(
            "varflow.generators.photo needs the photographs of scikit-image: "
            "pip install 'varflow[test]' or scikit-image"
        ) from exc
    if name.startswith("motorcycle_"):
        left, right, _ = data.stereo_motorcycle()
        img = left if name == "motorcycle_left" else right
    else:
        img = getattr(data, name)()
    img = np.asarray(img)
    if np.issubdtype(img.dtype, np.integer):
        arr = img.astype(np.float32) / np.float32(np.iinfo(img.dtype).max)
    else:
        arr = np.clip(img.astype(np.float32), 0.0, 1.0)
    if arr.ndim == 3:
        arr = arr[..., :3]
    arr = np.ascontiguousarray(arr)
    arr.flags.writeable = False
    _PHOTO_CACHE[name] = arr
    return arr


def _luma(img: np.ndarray) -> np.ndarray:
    """Luminance of an RGB photo (float32), as ``skimage.color.rgb2gray``."""
    return img[..., 0] * _LUMA[0] + img[..., 1] * _LUMA[1] + img[..., 2] * _LUMA[2]


def _source(name: str) -> str:
    """The scene a photo shows (the two motorcycle views are one scene)."""
    return "motorcycle" if name.startswith("motorcycle_") else name


class _PhotoTexture:
    """A photo seen through texture coordinates: value at ``p`` = photo at ``origin + scale p``.

    Bilinear interpolation, the same values as ``scipy.ndimage.map_coordinates(order=1,
    mode="reflect")`` at every point inside the photo (the crops keep all samples
    at least :data:`_PAD` photo pixels inside), computed as four gathers of
    packed RGBA texels (16-byte items), about twice as fast as three
    ``map_coordinates`` calls.  Values stay in ``[0, 1]``.  Grey photos are
    sampled once and tinted.  Samples come out channel-last with ``depth``
    channels: 4 (RGB and a spare one) for colour output, 1 for grey output.
    """

    def __init__(
        self,
        name: str,
        channels: int,
        origin: tuple[float, float],
        scale: float,
        tint: np.ndarray | None = None,
    ) -> None:
        img = load_photo(name)
        self.name = name
        self.channels = channels
        self.origin = (float(origin[0]), float(origin[1]))
        self.scale = float(scale)
        self.shape = (int(img.shape[0]), int(img.shape[1]))
        self.depth = 4 if channels == 3 else 1
        self.tint: np.ndarray | None = None
        if img.ndim == 3 and channels == 3:
            rgba = np.zeros(self.shape + (4,), np.float32)
            rgba[..., :3] = img
            self._table = rgba.reshape(-1).view(np.complex128)  # one RGBA texel per item
        else:
            grey = img if img.ndim == 2 else _luma(img)
            self._table = np.ascontiguousarray(grey, np.float32).reshape(-1)
            if channels == 3:
                self.tint = np.ones(3) if tint is None else np.asarray(tint, np.float64)

    def coords(self, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """Photo (row, column) coordinates of texture points, shape ``(2,) + px.shape``."""
        out = np.empty((2,) + np.shape(px))
        np.multiply(py, self.scale, out=out[0])
        out[0] += self.origin[1]
        np.multiply(px, self.scale, out=out[1])
        out[1] += self.origin[0]
        return out

    def affine_coords(
        self, motion: _AffineMotion, n: int, xs: np.ndarray, ys: np.ndarray
    ) -> np.ndarray:
        """Photo coordinates of ``M_n^{-1}`` on the grid ``xs`` x ``ys`` (columns, rows)."""
        ai, (cx, cy), (bx, by) = motion.ainv[n], motion.c, motion.b[n]
        k, (ox, oy) = self.scale, self.origin
        dx, dy = xs - cx - bx, ys - cy - by
        out = np.empty((2, ys.size, xs.size))
        np.add((k * ai[1, 1] * dy + oy + k * cy)[:, None], (k * ai[1, 0] * dx)[None, :], out=out[0])
        np.add((k * ai[0, 1] * dy + ox + k * cx)[:, None], (k * ai[0, 0] * dx)[None, :], out=out[1])
        return out

    def __call__(self, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """Values at texture points: shape S -> ``S + (depth,)`` float32."""
        return self.sample(self.coords(px, py))

    def sample(self, coords: np.ndarray) -> np.ndarray:
        """Values at photo (row, column) coordinates ``(2,) + S`` -> ``S + (depth,)`` float32."""
        h, w = self.shape
        shape = coords.shape[1:]
        r, c = coords[0], coords[1]
        if not (r.min() >= 0 and r.max() <= h - 1 and c.min() >= 0 and c.max() <= w - 1):
            # never reached by the generated scenes (the crops keep inside the photo)
            r, c = np.clip(r, 0.0, h - 1.0), np.clip(c, 0.0, w - 1.0)
        r0 = r.astype(np.intp)
        np.minimum(r0, h - 2, out=r0)
        c0 = c.astype(np.intp)
        np.minimum(c0, w - 2, out=c0)
        fy = np.subtract(r, r0).astype(np.float32)
        fx = np.subtract(c, c0).astype(np.float32)
        idx = r0
        idx *= w
        idx += c0
        table = self._table
        width = 4 if table.dtype == np.complex128 else 1

        def tap(offset: int) -> np.ndarray:
            v = table[idx + offset] if offset else table[idx]
            return v.view(np.float32).reshape(shape + (width,))

        fx, fy = fx[..., None], fy[..., None]
        top, right = tap(0), tap(1)
        right -= top
        right *= fx
        top += right
        bottom, corner = tap(w), tap(w + 1)
        corner -= bottom
        corner *= fx
        bottom += corner
        bottom -= top
        bottom *= fy
        top += bottom
        if self.tint is None:
            return top
        out = np.empty(shape + (4,), np.float32)
        for ch in range(3):
            np.multiply(top[..., 0], np.float32(self.tint[ch]), out=out[..., ch])
        out[..., 3] = 0.0
        np.clip(out, 0.0, 1.0, out=out)
        return out


def _tint(rng: np.random.Generator) -> np.ndarray:
    t = 1.0 + rng.uniform(-0.06, 0.06, 3)
    return t / t.mean()


def _photo_size(name: str) -> tuple[int, int]:
    img = load_photo(name)
    return int(img.shape[0]), int(img.shape[1])


# --------------------------------------------------------------------------- shapes, layers


@dataclass
class _Shape:
    """A smooth object outline in texture coordinates centred at 0, circumradius ``radius``.

    ``"superellipse"``: ``|u / a|^e + |v / b|^e <= 1`` in axes turned by ``angle``;
    ``"polygon"``: a rounded polygon ``|p| <= r0 (1 + sum_j a_j cos(m_j phi + phi_j))``.
    """

    kind: str
    radius: float
    angle: float = 0.0
    axes: tuple[float, float] = (1.0, 1.0)
    exponent: float = 2.0
    harmonics: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    base: float = 1.0

    @classmethod
    def draw(cls, rng: np.random.Generator, radius: float) -> _Shape:
        if rng.random() < 0.5:
            e = rng.uniform(2.0, 4.0)
            aspect = rng.uniform(0.65, 1.0)
            a = radius * 2.0 ** (1.0 / e - 0.5)  # circumradius of the e-ball with a = b
            return cls("superellipse", radius, rng.uniform(0, np.pi), (a, a * aspect), e)
        order = rng.integers(3, 7)
        harm = np.array(
            [
                [order, rng.uniform(0.05, 0.12), rng.uniform(0, 2 * np.pi)],
                [2, rng.uniform(0.0, 0.08), rng.uniform(0, 2 * np.pi)],
            ]
        )
        base = radius / (1.0 + harm[:, 1].sum())
        return cls("polygon", radius, harmonics=harm, base=base)

    def __call__(self, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        if self.kind == "superellipse":
            c, s = np.cos(self.angle), np.sin(self.angle)
            u = np.abs(c * px + s * py) / self.axes[0]
            v = np.abs(c * py - s * px) / self.axes[1]
            return u**self.exponent + v**self.exponent <= 1.0
        phi = np.arctan2(py, px)
        r = np.ones_like(phi)
        for m, amp, ph in self.harmonics:
            r += amp * np.cos(m * phi + ph)
        r *= self.base
        return px * px + py * py <= r * r

    def info(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "radius": self.radius}
        if self.kind == "superellipse":
            out.update(angle=self.angle, axes=self.axes, exponent=self.exponent)
        else:
            out.update(base=self.base, harmonics=self.harmonics)
        return out


@dataclass
class _PhotoLayer:
    """A photographic layer; ``shape`` limits it to an object outline (None: whole plane)."""

    motion: Any
    texture: _PhotoTexture
    shape: _Shape | None = None

    def covers(self, px: np.ndarray, py: np.ndarray) -> np.ndarray | None:
        return None if self.shape is None else self.shape(px, py)

    def bounds(self, n: int) -> tuple[float, float, float, float]:
        """Frame-n box ``(x0, x1, y0, y1)`` holding the object (objects are affine, centre 0)."""
        assert self.shape is not None
        cx, cy = self.motion.forward(np.zeros(1), np.zeros(1), n)
        r = self.shape.radius * float(np.linalg.norm(self.motion.a[n], 2)) + 1.0
        return float(cx[0]) - r, float(cx[0]) + r, float(cy[0]) - r, float(cy[0]) + r


# --------------------------------------------------------------------------- motions


@dataclass
class _Path:
    """Unit path ``u P(t) + u_perp Q(t)`` with ``P(1/2) = Q(1/2) = 0``.

    ``P' = 1 + beta sin(w t + phi)`` (speed varies within ``1 +- beta``) and
    ``Q = gamma (sin(w2 t + phi2) - sin(w2 / 2 + phi2))`` (a sideways sway).
    """

    angle: float
    beta: float
    w: float
    phi: float
    gamma: float
    w2: float
    phi2: float

    @classmethod
    def draw(cls, rng: np.random.Generator, angle: float | None = None) -> _Path:
        ang = rng.uniform(0, 2 * np.pi) if angle is None else float(angle)
        return cls(
            ang,
            rng.uniform(0.25, 0.5),
            2 * np.pi * rng.uniform(0.5, 1.2),
            rng.uniform(0, 2 * np.pi),
            rng.uniform(0.03, 0.12),
            2 * np.pi * rng.uniform(0.6, 1.6),
            rng.uniform(0, 2 * np.pi),
        )

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, np.float64)
        p = (t - 0.5) - self.beta / self.w * (
            np.cos(self.w * t + self.phi) - np.cos(0.5 * self.w + self.phi)
        )
        q = self.gamma * (np.sin(self.w2 * t + self.phi2) - np.sin(0.5 * self.w2 + self.phi2))
        u = np.array([np.cos(self.angle), np.sin(self.angle)])
        return p[:, None] * u + q[:, None] * np.array([-u[1], u[0]])

    def info(self) -> dict[str, float]:
        return dict(self.__dict__)


def _sway(rng: np.random.Generator, lo: float, hi: float) -> tuple[float, float, float]:
    """Amplitude, angular frequency and phase of ``amp (sin(w t + phi) - sin(w / 2 + phi))``."""
    return (
        rng.uniform(lo, hi) * rng.choice([-1.0, 1.0]),
        2 * np.pi * rng.uniform(0.4, 1.0),
        rng.uniform(0, 2 * np.pi),
    )


def _sway_eval(p: tuple[float, float, float], t: np.ndarray) -> np.ndarray:
    amp, w, ph = p
    return amp * (np.sin(w * t + ph) - np.sin(0.5 * w + ph))


def _speed_and_reach(motion: Any, xs: np.ndarray, ys: np.ndarray) -> tuple[float, float]:
    """Peak speed (px per clip) and maximum displacement from mid-clip of the given points.

    ``motion`` must be built on :data:`_FINE_TIMES` (241 times, mid-clip = index 120).
    """
    px, py = motion.inverse(xs, ys, 120)
    pos = np.stack([np.stack(motion.forward(px, py, n), -1) for n in range(_FINE_TIMES.size)])
    speed = np.hypot(*np.moveaxis(np.diff(pos, axis=0), -1, 0)).max() * (_FINE_TIMES.size - 1)
    reach = np.hypot(*np.moveaxis(pos - pos[120], -1, 0)).max()
    return float(speed), float(reach)


def _affine_camera(
    rng: np.random.Generator, shape: tuple[int, int], times: np.ndarray, magnitude: float
) -> tuple[_AffineMotion, dict[str, Any]]:
    """Pan, roll, zoom and slight shear of the camera, calibrated to ``magnitude``."""
    h, w = shape
    n_frames = times.size
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    r = 0.5 * np.hypot(h, w)
    cx = np.array([0.0, w - 1.0, 0.0, w - 1.0])
    cy = np.array([0.0, 0.0, h - 1.0, h - 1.0])
    speed = 0.0
    for _attempt in range(20):
        path = _Path.draw(rng)
        rot = _sway(rng, 0.05 / r, 0.2 / r)
        zoom1, zoom2 = rng.uniform(-0.3, 0.3, 2) / r
        shear = _sway(rng, 0.0, 0.06 / r)

        def build(s: float, t: np.ndarray = times) -> _AffineMotion:
            tc = t - 0.5
            theta = s * _sway_eval(rot, t)  # noqa: B023 - used within the iteration
            zoom = s * (zoom1 * tc + zoom2 * tc**2)  # noqa: B023
            sh = np.zeros((t.size, 2, 2))
            sh[:, 0, 0] = sh[:, 1, 1] = 1.0
            sh[:, 0, 1] = s * _sway_eval(shear, t)  # noqa: B023
            a = np.exp(zoom)[:, None, None] * (_rotation(theta) @ sh)
            return _AffineMotion(a, s * path(t), centre)  # noqa: B023

        motion, s = _calibrate(
            build, lambda m: _max_disp(m, cx, cy, n_frames // 2, n_frames), magnitude
        )
        if s == 0.0:
            break
        speed, reach = _speed_and_reach(build(s, _FINE_TIMES), cx, cy)
        if speed <= _SPEED_RATIO * reach:
            break
    info = {
        "type": "affine",
        "A": motion.a,
        "b": motion.b,
        "centre": centre,
        "scale": s,
        "peak_speed": speed,
        "path": path.info(),
        "rotation": s * _sway_eval(rot, times),
        "log_zoom": s * (zoom1 * (times - 0.5) + zoom2 * (times - 0.5) ** 2),
        "shear": s * _sway_eval(shear, times),
    }
    return motion, info


def _wave_sheet(
    rng: np.random.Generator, shape: tuple[int, int], times: np.ndarray, magnitude: float
) -> tuple[_WaveMotion, dict[str, Any]]:
    """Travelling waves plus a smooth drift, calibrated to ``magnitude``."""
    h, w = shape
    n_frames = times.size
    size = max(h, w)
    n_waves = 4
    wavelength = rng.uniform(0.6, 1.3, n_waves) * size
    k_ang = rng.uniform(0, np.pi, n_waves)
    d_ang = rng.uniform(0, 2 * np.pi, n_waves)
    k_ang[0] = rng.uniform(-0.35, 0.35)  # the first wave: transverse, along x (a flag)
    d_ang[0] = np.pi / 2 + rng.uniform(-0.35, 0.35)
    kappa = (2 * np.pi / wavelength)[:, None] * np.stack([np.cos(k_ang), np.sin(k_ang)], -1)
    direction = np.stack([np.cos(d_ang), np.sin(d_ang)], -1)
    weight = np.array([1.0, 0.6, 0.5, 0.4]) / 2.5
    omega = 2 * np.pi * rng.uniform(0.4, 0.9, n_waves) * rng.choice([-1, 1], n_waves)
    phase = rng.uniform(0, 2 * np.pi, n_waves)
    path = _Path.draw(rng)
    share = rng.uniform(0.35, 0.6)
    strain_unit = float(np.sum(weight * np.hypot(*kappa.T)))
    wave_speed_unit = float(np.sum(weight * np.abs(omega)))

    def build(a: float, s: float, t: np.ndarray = times) -> _WaveMotion:
        return _WaveMotion(kappa, direction, a * weight, omega, phase, s * path(t), t)

    gy, gx = np.meshgrid(np.linspace(0, h - 1, 25), np.linspace(0, w - 1, 25), indexing="ij")
    gx, gy = gx.ravel(), gy.ravel()

    def measure(m: _WaveMotion) -> float:
        return _max_disp(m, gx, gy, n_frames // 2, n_frames)

    a = 0.0
    if magnitude > 0:
        reach1 = measure(build(1.0, 0.0))
        a = min(
            share * magnitude / reach1,
            0.95 * _MAX_STRAIN / strain_unit,
            0.4 * _SPEED_RATIO * magnitude / wave_speed_unit,
        )
    motion, s = _calibrate(lambda s: build(a, s), measure, magnitude)
    info = {
        "type": "travelling_waves",
        "kappa": kappa,
        "direction": direction,
        "amplitude": motion.amp,
        "omega": omega,
        "phase": phase,
        "drift": motion.drift,
        "times": times,
        "strain_bound": motion.strain_bound,
        "scale": s,
        "path": path.info(),
    }
    return motion, info


def _border_points(shape: tuple[int, int], per_side: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Points on the border of the area covered by the sub-samples, ``[-0.5, W-0.5] x ...``."""
    h, w = shape
    tx = np.linspace(-0.5, w - 0.5, per_side)
    ty = np.linspace(-0.5, h - 0.5, per_side)
    xs = np.concatenate([tx, tx, np.full(per_side, -0.5), np.full(per_side, w - 0.5)])
    ys = np.concatenate([np.full(per_side, -0.5), np.full(per_side, h - 0.5), ty, ty])
    return xs, ys


def _background_extent(motion: Any, shape: tuple[int, int], n_frames: int) -> np.ndarray:
    """Box ``[x0, x1, y0, y1]`` (texture coords) seen by any sub-sample of any frame."""
    xs, ys = _border_points(shape, 4 if isinstance(motion, _AffineMotion) else 96)
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    for n in range(n_frames):
        px, py = motion.inverse(xs, ys, n)
        lo = np.minimum(lo, [px.min(), py.min()])
        hi = np.maximum(hi, [px.max(), py.max()])
    margin = 0.0 if isinstance(motion, _AffineMotion) else 1.0
    return np.array([lo[0] - margin, hi[0] + margin, lo[1] - margin, hi[1] + margin])


def _background_texture(
    rng: np.random.Generator, extent: np.ndarray, channels: int
) -> tuple[_PhotoTexture, dict[str, Any]]:
    """Pick the photo, scale and crop of the background so that ``extent`` fits inside."""
    span_x, span_y = extent[1] - extent[0], extent[3] - extent[2]
    fits = {}
    for name in PHOTOS:
        ph, pw = _photo_size(name)
        fits[name] = min((pw - 1 - 2 * _PAD) / span_x, (ph - 1 - 2 * _PAD) / span_y)
    want = rng.uniform(*PHOTO_SCALE_RANGE)
    eligible = [n for n in PHOTOS if fits[n] >= PHOTO_SCALE_RANGE[0]]
    if not eligible:  # large frames: the photos that fit best (mild magnification)
        best = max(fits.values())
        eligible = [n for n in PHOTOS if fits[n] >= 0.9 * best]
    name = eligible[int(rng.integers(len(eligible)))]
    k = min(want, fits[name])
    ph, pw = _photo_size(name)
    ox = _uniform(rng, _PAD - k * extent[0], pw - 1 - _PAD - k * extent[1])
    oy = _uniform(rng, _PAD - k * extent[2], ph - 1 - _PAD - k * extent[3])
    tint = _tint(rng)
    tex = _PhotoTexture(name, channels, (ox, oy), k, tint)
    info = {"photo": name, "photo_scale": k, "origin": (ox, oy), "tint": tex.tint}
    return tex, info


def _uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """Uniform in ``[lo, hi]``, or the midpoint when the interval is empty."""
    u = rng.random()
    return lo + u * (hi - lo) if hi >= lo else 0.5 * (lo + hi)


def _object_texture(
    rng: np.random.Generator, name: str, radius: float, channels: int
) -> tuple[_PhotoTexture, dict[str, Any]]:
    """A crop of ``name`` around a textured spot (best of 6 candidates by grey-level std)."""
    ph, pw = _photo_size(name)
    want = rng.uniform(*PHOTO_SCALE_RANGE)
    k = min(want, (0.5 * min(ph, pw) - 1 - _PAD) / radius)
    reach = k * radius + _PAD
    img = load_photo(name)
    grey = _luma(img) if img.ndim == 3 else img
    gy, gx = np.mgrid[-1:1:12j, -1:1:12j]
    disc = gx**2 + gy**2 <= 1.0
    best, best_score = (0.5 * (pw - 1), 0.5 * (ph - 1)), -1.0
    for _ in range(6):
        cx = _uniform(rng, reach, pw - 1 - reach)
        cy = _uniform(rng, reach, ph - 1 - reach)
        vals = map_coordinates(
            grey, [cy + reach * gy[disc], cx + reach * gx[disc]], order=1, mode="reflect"
        )
        score = float(vals.std())
        if score > best_score:
            best, best_score = (cx, cy), score
    tint = _tint(rng)
    tex = _PhotoTexture(name, channels, best, k, tint)
    return tex, {"photo": name, "photo_scale": k, "origin": best, "tint": tex.tint}


def _objects(
    rng: np.random.Generator,
    shape: tuple[int, int],
    times: np.ndarray,
    magnitude: float,
    speed_cap: float,
    channels: int,
    used: list[str],
) -> tuple[list[_PhotoLayer], list[dict[str, Any]]]:
    """1-3 photographic objects in depth order (back to front); one leaves the frame."""
    h, w = shape
    n_obj = int(rng.integers(1, 4))
    crossing = int(rng.integers(n_obj))
    depth = rng.permutation(n_obj)  # depth[i] = depth rank of object i (0 = backmost)
    objects: list[tuple[int, _PhotoLayer, dict[str, Any]]] = []
    rim = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    gentle = min(1.0, magnitude / 30.0)  # rotation and zoom shrink with small magnitudes
    for i in range(n_obj):
        radius = rng.uniform(0.08, 0.25) * min(h, w)
        outline = _Shape.draw(rng, radius)
        sides = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
        side = int(rng.integers(4))
        t_out = float(rng.choice([0.0, 1.0]))
        if i == crossing:
            normal = sides[side] * (1.0 if t_out == 1.0 else -1.0)
            angle = np.arctan2(normal[1], normal[0]) + rng.uniform(-0.4, 0.4)
            path = _Path.draw(rng, angle)
        else:
            path = _Path.draw(rng)
        rot = _sway(rng, 0.05, 0.2)
        zoom = _sway(rng, 0.02, 0.05)
        share = rng.uniform(0.7, 1.3)
        extra = rng.uniform(0.3, 1.2)
        mid_rel = rng.uniform(0.15, 0.85, 2)

        def build(
            d: float, rot_scale: float, centre_mid: np.ndarray, t: np.ndarray = times
        ) -> _AffineMotion:
            psi = rot_scale * _sway_eval(rot, t)  # noqa: B023 - used within the iteration
            rho = np.exp(gentle * _sway_eval(zoom, t))  # noqa: B023
            a = rho[:, None, None] * _rotation(psi)
            return _AffineMotion(a, centre_mid + d * path(t), np.zeros(2))  # noqa: B023

        reach_unit = float(np.hypot(*path(times).T).max())
        d = share * magnitude / reach_unit if reach_unit > 0 else 0.0
        rot_scale = gentle
        rx, ry = radius * np.cos(rim), radius * np.sin(rim)
        for _ in range(4):  # limit the speed (translation and rotation alike)
            fine = build(d, rot_scale, np.zeros(2), _FINE_TIMES)
            speed, _ = _speed_and_reach(fine, *fine.forward(rx, ry, 120))
            if speed <= speed_cap:
                break
            d *= 0.98 * speed_cap / speed
            rot_scale *= 0.98 * speed_cap / speed
        if i == crossing:
            # beyond the border by `extra` radii at t_out, inside by 0.3 radii at mid-clip
            end = d * path(np.array([t_out]))[0]
            axis = 0 if side < 2 else 1
            lim = (w - 1.0, h - 1.0)[axis]
            target = -extra * radius if side % 2 == 0 else lim + extra * radius
            mid = np.array([mid_rel[0] * (w - 1), mid_rel[1] * (h - 1)])
            mid[axis] = np.clip(target - end[axis], 0.3 * radius, lim - 0.3 * radius)
        else:
            mid = np.array([mid_rel[0] * (w - 1), mid_rel[1] * (h - 1)])
        motion = build(d, rot_scale, mid)
        candidates = [n for n in PHOTOS if _source(n) not in {_source(u) for u in used}]
        name = candidates[int(rng.integers(len(candidates)))] if candidates else PHOTOS[i]
        used.append(name)
        texture, tex_info = _object_texture(rng, name, radius, channels)
        info = {
            **tex_info,
            "shape": outline.info(),
            "radius": radius,
            "depth": int(depth[i]),
            "planned_crossing": i == crossing,
            "crossing_side": ("left", "right", "top", "bottom")[side] if i == crossing else None,
            "outside_at_time": t_out if i == crossing else None,
            "centre": motion.b.copy(),
            "rotation": rot_scale * _sway_eval(rot, times),
            "zoom": np.exp(gentle * _sway_eval(zoom, times)),
            "A": motion.a,
            "b": motion.b,
            "path": path.info(),
            "path_scale": d,
        }
        objects.append((int(depth[i]), _PhotoLayer(motion, texture, outline), info))
    objects.sort(key=lambda item: item[0])
    return [o[1] for o in objects], [o[2] for o in objects]


# --------------------------------------------------------------------------- rendering


def _wave_inverse_fine(
    motion: _WaveMotion,
    n: int,
    centres: tuple[np.ndarray, np.ndarray],
    off: np.ndarray,
    guess: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """``M_n^{-1}`` at the sub-samples of a block of pixels, to ~1e-5 px.

    Newton's method (float64, to 1e-9 px) at the pixel centres ``centres`` (x, y
    of shape ``(rows, W)``, warm-started by ``guess``); from each centre solution
    ``p_c`` a first-order step to its sub-samples, ``dp = (I + grad s)^{-1} delta``
    (off by ~1e-3 px), then one chord step (Newton with the centre's Jacobian)
    on ``dp``.  That step works in float32 on small quantities: the residual
    ``dp - delta + s(p_c + dp) - s(p_c)`` with the wave phases ``theta(p_c) +
    kappa . dp``, which leaves ~1e-5 px: ample for rendering (the trajectories are
    computed separately, in float64).  Returns the sub-sample positions in the
    layout ``(rows * s, W * s)`` of the renderer and the centre solution.
    """
    cx, cy = centres
    rows, w = cx.shape
    s = off.size
    pcx, pcy = motion.inverse(cx, cy, n, guess)
    _, _, thetas = motion._eval(pcx, pcy, n)
    j = motion._jacobian(thetas)
    det = (1.0 + j[0]) * (1.0 + j[3]) - j[1] * j[2]
    f32 = np.float32
    dyx = off.astype(f32)
    dx = dyx[None, None, None, :]
    dy = dyx[None, :, None, None]

    def pix(v: np.ndarray) -> np.ndarray:  # (rows, W) -> (rows, 1, W, 1)
        return v.astype(f32)[:, None, :, None]

    ja, jb, jc, jd = (1.0 + j[3]) / det, -j[1] / det, -j[2] / det, (1.0 + j[0]) / det
    ia, ib, ic, id_ = pix(ja), pix(jb), pix(jc), pix(jd)
    dpx = ia * dx + ib * dy
    dpy = ic * dx + id_ * dy
    # residual p + s(p) - q = dp - delta + s(p_c + dp) - s(p_c)   (p_c + s(p_c) = centre)
    rx = dpx - dx
    ry = dpy - dy
    sc = np.zeros((2,) + cx.shape)
    for k, theta_c in enumerate(thetas):
        red = theta_c * (1.0 / (2 * np.pi))
        red -= np.rint(red)
        red *= 2 * np.pi
        tc = red.astype(f32)
        kx, ky = motion.kappa[k]
        ex, ey = motion.amp[k] * motion.direction[k]
        sin = np.sin(tc)
        sc[0] += ex * sin
        sc[1] += ey * sin
        # theta(p_c + dp) = theta_c + kappa . dp, and dp is linear in delta
        theta = pix(kx * jb + ky * jd) * dy + pix(tc)
        theta = theta + pix(kx * ja + ky * jc) * dx
        sin = np.sin(theta, out=theta)
        rx += f32(ex) * sin
        ry += f32(ey) * sin
    rx -= pix(sc[0])
    ry -= pix(sc[1])
    # one chord step with the centre Jacobian (its change over half a pixel is ~1e-2)
    dpx -= ia * rx + ib * ry
    dpy -= ic * rx + id_ * ry
    px = (pcx[:, None, :, None] + dpx).reshape(rows * s, w * s)
    py = (pcy[:, None, :, None] + dpy).reshape(rows * s, w * s)
    return px, py, (pcx, pcy)


def _box_mean(acc: np.ndarray, s: int) -> np.ndarray:
    """Mean of the ``s x s`` blocks of ``acc`` (rows * s, W * s, C) (strided sums: fast)."""
    hs, ws, c = acc.shape
    cols = acc.reshape(hs, ws // s, s, c)
    tot = cols[:, :, 0].copy()
    for k in range(1, s):
        tot += cols[:, :, k]
    rows = tot.reshape(hs // s, s, ws // s, c)
    out = rows[:, 0].copy()
    for k in range(1, s):
        out += rows[:, k]
    out *= np.float32(1.0 / (s * s))
    return out


def _render(
    layers: Sequence[_PhotoLayer],
    shape: tuple[int, int],
    n_frames: int,
    channels: int,
    supersample: int,
) -> np.ndarray:
    """Area-sampled frames ``(F, H, W, C)``: mean of ``s x s`` composited sub-samples per pixel."""
    h, w = shape
    s = supersample
    off = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(w)[:, None] + off).ravel()
    rows = max(1, min(h, _CHUNK_SAMPLES // (w * s * s)))
    frames = np.empty((n_frames, h, w, channels), np.float32)
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        ys = (np.arange(r0, r1)[:, None] + off).ravel()
        cy, cx = np.mgrid[r0:r1, 0:w].astype(np.float64)
        guess: tuple[np.ndarray, np.ndarray] | None = None
        for n in range(n_frames):
            back = layers[0]
            if isinstance(back.motion, _WaveMotion):
                px, py, guess = _wave_inverse_fine(back.motion, n, (cx, cy), off, guess)
                acc = back.texture(px, py)
            else:
                acc = back.texture.sample(back.texture.affine_coords(back.motion, n, xs, ys))
            for layer in layers[1:]:
                x0, x1, y0, y1 = layer.bounds(n)
                i0 = max(0, int(np.floor((y0 - ys[0]) * s)))
                i1 = min(ys.size, int(np.ceil((y1 - ys[0]) * s)) + 1)
                j0 = max(0, int(np.floor((x0 - xs[0]) * s)))
                j1 = min(xs.size, int(np.ceil((x1 - xs[0]) * s)) + 1)
                if i1 <= i0 or j1 <= j0:
                    continue
                ox, oy = layer.motion.inverse(xs[None, j0:j1], ys[i0:i1, None], n)
                cov = layer.covers(ox, oy)
                if cov is None or not cov.any():
                    continue
                vals = layer.texture(ox[cov], oy[cov])
                win = acc[i0:i1, j0:j1]
                win[cov] = vals
            frames[n, r0:r1] = _box_mean(acc, s)[..., :channels]
    return frames


# --------------------------------------------------------------------------- photometry


def _illuminate(
    rng: np.random.Generator, clean: np.ndarray, times: np.ndarray
) -> tuple[np.ndarray, dict[str, Any]]:
    """Slow global gain and offset and a turning spatial gain gradient (see the notes)."""
    n_frames, h, w, _ = clean.shape
    # log-gain: a ramp of 0.16-0.24 over the clip and a sway of up to +-0.06
    lg1 = rng.uniform(0.08, 0.12) * rng.choice([-1.0, 1.0])
    lg2 = _sway(rng, 0.0, 0.03)
    gain = np.exp(2 * lg1 * (times - 0.5) + _sway_eval(lg2, times))
    offset = rng.uniform(-0.04, 0.04) * 2 * (times - 0.5) + rng.uniform(-0.02, 0.02)
    half_diag = 0.5 * np.hypot(h, w)
    strength = rng.uniform(0.1, 0.2) / half_diag
    ang = rng.uniform(0, 2 * np.pi) + rng.uniform(0.5, 1.5) * rng.choice([-1, 1]) * times
    gradient = strength * np.stack([np.cos(ang), np.sin(ang)], -1)
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    out = np.empty_like(clean)
    for n in range(n_frames):
        field_n = gain[n] * np.exp(
            gradient[n, 0] * (xx - centre[0]) + gradient[n, 1] * (yy - centre[1])
        )
        out[n] = np.clip(field_n[..., None] * clean[n] + offset[n], 0.0, 1.0)
    info = {
        "model": "clip(gain[n] * exp(gradient[n] . (x - centre)) * I + offset[n], 0, 1)",
        "gain": gain,
        "offset": offset,
        "gradient": gradient,
        "centre": centre,
    }
    return out, info


def _add_noise(
    rng: np.random.Generator, clean: np.ndarray, sigma: float
) -> tuple[np.ndarray, dict[str, Any]]:
    """Signal-dependent Gaussian noise ``sigma (0.6 + 0.8 I)`` per sample, clipped."""
    out = np.empty_like(clean)
    for n in range(clean.shape[0]):
        std = np.float32(sigma) * (np.float32(0.6) + np.float32(0.8) * clean[n])
        noise = rng.standard_normal(clean[n].shape, dtype=np.float32)
        out[n] = np.clip(clean[n] + std * noise, 0.0, 1.0)
    info = {"sigma": sigma, "model": "std = sigma * (0.6 + 0.8 * I), clipped to [0, 1]"}
    return out, info


# --------------------------------------------------------------------------- public API


def _family_rng(family: str, seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    ss = np.random.SeedSequence([seed, zlib.crc32(family.encode())])
    scene, noise = ss.spawn(2)
    return np.random.default_rng(scene), np.random.default_rng(noise)


def _scene(
    family: str,
    seed: int,
    n_frames: int,
    shape: tuple[int, int],
    magnitude: float | None,
    channels: int,
) -> tuple[list[_PhotoLayer], dict[str, Any], np.random.Generator, np.random.Generator]:
    """Layers (back to front) and metadata of a clip; the generators for the rest."""
    rng, noise_rng = _family_rng(family, seed)
    drawn = float(rng.uniform(30.0, 50.0))
    magnitude = drawn if magnitude is None else magnitude
    times = np.arange(n_frames, dtype=np.float64) / (n_frames - 1)
    params: dict[str, Any] = {"magnitude": magnitude, "times": times}
    motion: Any
    if family == "nonrigid":
        motion, params["motion"] = _wave_sheet(rng, shape, times, magnitude)
    else:
        motion, params["motion"] = _affine_camera(rng, shape, times, magnitude)
    extent = _background_extent(motion, shape, n_frames)
    texture, bg_info = _background_texture(rng, extent, channels)
    params["background"] = {**bg_info, "extent": extent}
    params["photo_scale"] = bg_info["photo_scale"]
    layers = [_PhotoLayer(motion, texture)]
    params["objects"] = []
    if family in ("objects", "illumination", "noise"):
        cap = max(_MAX_SPEED, params["motion"]["peak_speed"])
        objs, infos = _objects(rng, shape, times, magnitude, cap, channels, [texture.name])
        layers += objs
        params["objects"] = infos
    params["photos"] = [layer.texture.name for layer in layers]
    return layers, params, rng, noise_rng


def make_photo_clip(
    family: str,
    seed: int = 0,
    n_frames: int = 31,
    shape: tuple[int, int] = (192, 256),
    ref: int | None = None,
    magnitude: float | None = None,
    channels: int = 3,
    supersample: int = 4,
    blur: float = 0.0,
) -> SyntheticSequence:
    """Generate a clip of real photographs with exact trajectories and visibility.

    Parameters
    ----------
    family : {"affine", "nonrigid", "objects", "illumination", "noise"}
        Scene family (see the module notes).
    seed : int
        Seeds the photos, crops, shapes, motions, light and noise (local generators).
    n_frames : int
        Number of frames F in ``[2, 60]``.
    shape : (int, int)
        Frame size ``(H, W)``, each at least 32.
    ref : int, optional
        Reference frame in ``[0, F)``; default the centre ``F // 2``.  The frames
        do not depend on it.
    magnitude : float, optional
        Maximum displacement (px) over the clip of the background pixels of the
        centre frame; default drawn per seed in ``[30, 50]``.  Objects move
        0.7-1.3 times as far (less if their speed would exceed ~174 px per clip).
        The waves of ``"nonrigid"`` are limited by ``|grad s| <= 0.5``; the drift
        makes up the rest.
    channels : {1, 3}
        1 for grey (luminance), 3 for colour.
    supersample : int
        Sub-samples per pixel side for area sampling (``s``, in ``[1, 16]``);
        1 is point sampling.
    blur : float
        Standard deviation (px) of an optional Gaussian optical blur of the
        rendered frames, in ``[0, 5]``; default 0 (off).

    Returns
    -------
    SyntheticSequence
        ``frames`` (F, H, W, C) float32 in [0, 1], ``trajectories`` (F, H, W, 2)
        float32, ``visibility`` (F, H, W) bool, ``ref``, ``name`` = family,
        ``variant`` = ``"photo"``, ``clean_frames`` (before the illumination change
        or the noise), ``layer`` (0 background, 1.. objects back to front),
        ``seed`` and ``params`` with ``"magnitude"``, ``"max_displacement"`` (over all
        reference pixels and frames, objects included),
        ``"background_max_displacement"``, ``"max_step"`` (largest motion between
        consecutive frames), ``"occluded_fraction"`` (share of the (frame != ref,
        pixel) pairs not visible), ``"photos"`` (background first, then the
        objects back to front), ``"photo_scale"`` (photo pixels per output pixel
        of the background), ``"background"`` (its photo, scale, crop origin,
        tint and texture extent), ``"times"``, ``"motion"`` (the background
        motion: ``"A"``, ``"b"``, ``"centre"`` and its profiles for the affine
        camera; the wave parameters and ``"drift"`` for ``"nonrigid"``),
        ``"objects"`` (one dict per object, back to front: photo, crop, outline
        ``"shape"``, ``"radius"``, ``"depth"``, ``"A"``, ``"b"`` (``M_n(p) = A_n p +
        b_n``), ``"centre"``, ``"rotation"``, ``"zoom"``, ``"planned_crossing"``,
        ``"leaves_frame"``, ``"ref_pixels"``, ``"outside_fraction"`` per frame),
        ``"illumination"`` (gain, offset, gradient, centre) or None, ``"noise"``
        (sigma and model) or None, ``"supersample"``, ``"blur"``.  The
        displacements are measured from ``ref``; the calibration of
        ``magnitude`` uses the centre frame.

    Raises
    ------
    ValueError
        On an unknown family or an out-of-range argument (the message starts with
        the argument's name).
    ImportError
        When scikit-image (the photographs) is not installed.

    Examples
    --------
    >>> clip = make_photo_clip("objects", seed=1, n_frames=9, shape=(64, 96))
    >>> clip.frames.shape, clip.trajectories.shape, clip.visibility.shape
    ((9, 64, 96, 3), (9, 64, 96, 2), (9, 64, 96))
    """
    if family not in FAMILIES:
        raise ValueError(f"family: expected one of {FAMILIES}, got {family!r}")
    seed = _check_int(seed, "seed", 0)
    n_frames = _check_int(n_frames, "n_frames", 2)
    if n_frames > _MAX_FRAMES:
        raise ValueError(f"n_frames: expected at most {_MAX_FRAMES}, got {n_frames}")
    try:
        dims = tuple(shape)
        if len(dims) != 2:
            raise TypeError
        h, w = (_check_int(v, "shape", _MIN_SIZE) for v in dims)
    except (TypeError, ValueError):
        raise ValueError(
            f"shape: expected (H, W) with integers H, W >= {_MIN_SIZE}, got {shape!r}"
        ) from None
    ref = n_frames // 2 if ref is None else _check_int(ref, "ref", 0)
    if ref >= n_frames:
        raise ValueError(f"ref: expected an index in [0, {n_frames}), got {ref}")
    if channels not in (1, 3) or isinstance(channels, bool):
        raise ValueError(f"channels: expected 1 or 3, got {channels!r}")
    supersample = _check_int(supersample, "supersample", 1)
    if supersample > 16:
        raise ValueError(f"supersample: expected at most 16, got {supersample}")
    blur = _check_float(blur, "blur", 0.0, 5.0)
    if magnitude is not None:
        magnitude = _check_float(magnitude, "magnitude", 0.0)

    layers, params, rng, noise_rng = _scene(family, seed, n_frames, (h, w), magnitude, channels)
    times = params["times"]
    clean = _render(layers, (h, w), n_frames, channels, supersample)
    if blur > 0:
        clean = gaussian_filter(clean, sigma=(0, blur, blur, 0), mode="nearest")
    params["supersample"] = supersample
    params["blur"] = blur
    traj, vis, owner = _trajectories(layers, (h, w), n_frames, ref)

    frames = clean
    params["illumination"] = None
    params["noise"] = None
    if family == "illumination":
        frames, params["illumination"] = _illuminate(rng, clean, times)
    elif family == "noise":
        sigma = float(rng.uniform(0.01, 0.03))
        frames, params["noise"] = _add_noise(noise_rng, clean, sigma)

    disp = np.hypot(traj[..., 0], traj[..., 1])
    params["max_displacement"] = float(disp.max())
    params["background_max_displacement"] = float(disp[:, owner == 0].max(initial=0.0))
    step = np.diff(traj, axis=0)
    params["max_step"] = float(np.hypot(step[..., 0], step[..., 1]).max())
    others = np.arange(n_frames) != ref
    params["occluded_fraction"] = float(1.0 - vis[others].mean())
    for i, info in enumerate(params["objects"], start=1):
        sel = owner == i
        info["ref_pixels"] = int(sel.sum())
        if sel.any():
            pos_x = traj[..., 0][:, sel] + np.nonzero(sel)[1]
            pos_y = traj[..., 1][:, sel] + np.nonzero(sel)[0]
            out = (pos_x < 0) | (pos_x > w - 1) | (pos_y < 0) | (pos_y > h - 1)
            info["leaves_frame"] = bool(out.any())
            info["outside_fraction"] = out.mean(axis=1)
        else:
            info["leaves_frame"] = False
            info["outside_fraction"] = np.zeros(n_frames)
    return SyntheticSequence(
        frames=frames,
        trajectories=traj,
        visibility=vis,
        ref=ref,
        name=family,
        variant="photo",
        clean_frames=clean,
        layer=owner,
        seed=seed,
        params=params,
    )


def photo_cases(split: str, families: Sequence[str] = FAMILIES) -> list[tuple[str, int]]:
    """The ``(family, seed)`` cases of a split, family-major.

    Parameters
    ----------
    split : {"tuning", "reporting"}
        Which seeds (:data:`SPLITS`).
    families : sequence of str
        Subset of :data:`FAMILIES`.

    Returns
    -------
    list of (str, int)
    """
    return split_cases(split, families, FAMILIES)


def split_cases(split: str, families: Sequence[str], known: Sequence[str],
                splits: Mapping[str, Sequence[int]] | None = None) -> list[tuple[str, int]]:
    """The ``(family, seed)`` cases of a split for any family list, family-major.

    Shared by :func:`photo_cases`, :func:`varflow.generators.photo_pairs.photo_pair_cases`
    and :func:`varflow.generators.large_pairs.large_pair_cases`.

    Parameters
    ----------
    split : {"tuning", "reporting"}
    families : sequence of str
        Checked against ``known``.
    known : sequence of str
        The generator's family names.
    splits : mapping, optional
        Split name -> seeds (default :data:`SPLITS`).

    Returns
    -------
    list of (str, int)
    """
    splits = SPLITS if splits is None else splits
    if split not in splits:
        raise ValueError(f"split: expected one of {tuple(splits)}, got {split!r}")
    if isinstance(families, str):
        raise ValueError(f"families: expected a sequence of names, got the string {families!r}")
    for f in families:
        if f not in known:
            raise ValueError(f"families: expected names from {known}, got {f!r}")
    return [(f, s) for f in families for s in splits[split]]


def photo_suite(
    split: str = "reporting",
    families: Sequence[str] = FAMILIES,
    n_frames: int = 31,
    shape: tuple[int, int] = (192, 256),
    **kwargs: Any,
) -> Iterator[SyntheticSequence]:
    """Generate the clips of a split lazily, one per :func:`photo_cases` row.

    Parameters
    ----------
    split : {"tuning", "reporting"}
        Which seeds (:data:`SPLITS`).
    families : sequence of str
        Subset of :data:`FAMILIES` (family-major order).
    n_frames, shape
        Passed to :func:`make_photo_clip`.
    **kwargs
        Further :func:`make_photo_clip` arguments (``ref``, ``magnitude``,
        ``channels``, ``supersample``, ``blur``).

    Returns
    -------
    iterator of SyntheticSequence
        Clips generated one at a time as the iterator is consumed (the split and
        families are checked at the call).
    """
    cases = photo_cases(split, families)
    return (
        make_photo_clip(family, seed=seed, n_frames=n_frames, shape=shape, **kwargs)
        for family, seed in cases
    )
