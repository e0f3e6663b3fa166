"""The photographs of the photographic clips, sampled as textures, and their crops.

:func:`load_photo` loads the photographs bundled with scikit-image (see
:mod:`varflow.generators.photo` for the list and their sources); a
:class:`PhotoTexture` samples one through texture coordinates (bilinear, packed RGBA
texels); :func:`background_texture` and :func:`object_texture` choose a photo, its
scale and its crop for the background and for an object of a scene.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.ndimage import map_coordinates

from .sequences import _AffineMotion

__all__ = [
    "COLOUR_PHOTOS",
    "GREY_PHOTOS",
    "PHOTOS",
    "PHOTO_SCALE_RANGE",
    "PhotoTexture",
    "background_texture",
    "load_photo",
    "object_texture",
    "photo_source",
]


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
_PAD = 2.0  # photo pixels kept between a crop and the photo border
_LUMA = np.array([0.2125, 0.7154, 0.0721], np.float32)  # as skimage.color.rgb2gray

_PHOTO_CACHE: dict[str, np.ndarray] = {}


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


def photo_source(name: str) -> str:
    """The scene a photo shows (the two motorcycle views are one scene)."""
    return "motorcycle" if name.startswith("motorcycle_") else name


class PhotoTexture:
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


def background_texture(
    rng: np.random.Generator, extent: np.ndarray, channels: int
) -> tuple[PhotoTexture, dict[str, Any]]:
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
    tex = PhotoTexture(name, channels, (ox, oy), k, tint)
    info = {"photo": name, "photo_scale": k, "origin": (ox, oy), "tint": tex.tint}
    return tex, info


def _uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    """Uniform in ``[lo, hi]``, or the midpoint when the interval is empty."""
    u = rng.random()
    return lo + u * (hi - lo) if hi >= lo else 0.5 * (lo + hi)


def object_texture(
    rng: np.random.Generator, name: str, radius: float, channels: int
) -> tuple[PhotoTexture, dict[str, Any]]:
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
    tex = PhotoTexture(name, channels, best, k, tint)
    return tex, {"photo": name, "photo_scale": k, "origin": best, "tint": tex.tint}
