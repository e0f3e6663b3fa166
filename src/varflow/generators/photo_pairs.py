"""Two-frame pairs of real photographs with exact ground-truth flow and occlusion mask.

The two-frame counterpart of :mod:`varflow.generators.photo`: the same
photographs (bundled with scikit-image), the same area-sampling renderer,
photographic layers, occluding objects and photometric models, reused from
that module, but rendered as *pairs* with small to medium motion (a few pixels
up to ~15 px) for the evaluation of two-frame methods.  Defaults are chosen on
the *tuning* split (:data:`TUNING_SEEDS`, seeds 0-2) and reported on the
disjoint *reporting* split (:data:`REPORTING_SEEDS`, seeds 100-102), as for the
clips.

Construction
------------
A pair is a two-frame scene of :mod:`varflow.generators.photo` at times
``t = 0, 1``: every layer is a photograph seen through texture coordinates ``p``
and moved by an invertible map ``M_n: p -> frame-n position`` (``n = 0, 1``,
float64).  The flow of pixel ``x`` of frame 0, owned by the front-most layer
covering it there, is::

    flow(x) = M_1(M_0^{-1}(x)) - x

evaluated in float64 from the analytic maps (closed form for the affine and
projective maps, Newton's method to 1e-9 px for the waves), then cast to
float32: there is no interpolation error in the ground truth.  ``valid(x)`` is
True when ``x + flow(x)`` is inside ``[0, W-1] x [0, H-1]`` and not covered in
frame 1 by a layer in front of the point's own layer (the renderer's coverage
predicate): False marks both occlusion and leaving the frame.  The frames are
area sampled (``supersample**2`` sub-samples per pixel, anti-aliased object
boundaries), float32 in ``[0, 1]``, shape ``(H, W, C)``; see
:mod:`varflow.generators.photo` for the renderer and the photographs.

``magnitude`` (px) is drawn per pair in :data:`MAGNITUDE_RANGE` (3-15 px) and
calibrated to the largest background displacement between the two frames (at
the frame corners for the camera motions, on a grid for the waves); the
objects move about as far.  ``params["max_displacement"]`` and
``params["mean_displacement"]`` report the flow actually generated.

Families
--------
``"affine"``
    Camera motion ``M_n(p) = c + A_n (p - c) + b_n`` (pan, roll, zoom and a slight
    shear, from :mod:`varflow.generators.photo`); ``params["camera"]["matrix"]`` is
    the 2 x 3 affine map ``x -> M_1(M_0^{-1}(x))`` of frame-0 pixels.
``"homography"``
    A perspective camera moving in front of a tilted photographic plane:
    ``M_0 = I`` and ``M_1 = K (R + t n^T) K^{-1}`` (focal length ``f`` of 0.7-1.4 x
    ``max(H, W)``, plane normal ``n`` tilted by 15-50 degrees, small rotation ``R``
    and translation ``t`` scaled to ``magnitude``; the map departs from its best
    affine fit by at least 15 % of the magnitude on a 9 x 9 grid, the motion
    being redrawn up to 20 times until it does).
    ``params["camera"]["matrix"]`` is the 3 x 3 homography of frame-0 pixels.
``"nonrigid"``
    A photographic sheet deformed by four travelling waves plus a drift
    (:mod:`varflow.generators.photo`, ``|grad s| <= 0.5``).
``"objects"``
    The affine camera and 1-3 objects cut from other photographs (smooth
    outlines, each with its own rotation, zoom and path, in a seeded depth
    order), occluding the background and each other; one of them straddles the
    frame border (partly outside the frame, sometimes moving further out).
    The object paths are calibrated to half the magnitude each way from
    mid-time, so that they move about as far as the background between the
    frames.
``"illumination"``
    The affine camera, then the light of :mod:`varflow.generators.photo` at
    ``t = 0, 1``: ``I'_n = clip(g_n exp(gamma_n . (x - c)) I_n + o_n, 0, 1)``, the
    gain changing by 16-24 % (and a sway) between the frames, an offset of a few
    percent and a turning spatial gain gradient.
``"noise"``
    The affine camera plus signal-dependent Gaussian noise of standard deviation
    ``sigma (0.6 + 0.8 I)`` on both frames, ``sigma`` in :data:`NOISE_SIGMA_RANGE`.
``"blur"``
    The affine camera, then either a Gaussian blur (sigma 0.8-2 px) or a centred
    linear motion blur along the mean flow (length 0.3-0.8 x the mean motion,
    within 2-10 px), of the second frame only or of both frames (independent
    strengths); the blur is symmetric, so it does not move the image and the
    flow is that of the sharp scene.

``clean_frames`` are the frames before the illumination change, the noise or
the blur.  Each ``(family, seed)`` draws its photos, crops, scales, shapes,
motion and photometry from local generators seeded by ``(seed,
crc32("pair/" + family))``; no global random state is used.

References
----------
S. van der Walt et al., "scikit-image: image processing in Python", PeerJ 2:e453,
2014 (the photographs).

R. Hartley, A. Zisserman, "Multiple View Geometry in Computer Vision", 2nd ed.,
Cambridge University Press, 2004, section 13.1 (the homography induced by a
plane, ``K (R + t n^T / d) K^{-1}``).
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.ndimage import convolve, gaussian_filter

from ..ops.warp import in_bounds
from .photo import REPORTING_SEEDS, SPLITS, TUNING_SEEDS, split_cases
from .photo_render import add_noise, illuminate, render
from .photo_scenes import (
    MAX_SPEED,
    PhotoLayer,
    affine_camera,
    background_extent,
    photo_objects,
    wave_sheet,
)
from .photo_textures import PhotoTexture, background_texture
from .sequences import _AffineMotion, _calibrate, _check_float, _check_int, _trajectories

__all__ = [
    "FAMILIES",
    "MAGNITUDE_RANGE",
    "NOISE_SIGMA_RANGE",
    "DEFAULT_SHAPE",
    "TUNING_SEEDS",
    "REPORTING_SEEDS",
    "SPLITS",
    "PhotoPair",
    "make_photo_pair",
    "photo_pair_cases",
]

FAMILIES = ("affine", "homography", "nonrigid", "objects", "illumination", "noise", "blur")
MAGNITUDE_RANGE = (3.0, 15.0)  # px: largest background displacement between the frames
NOISE_SIGMA_RANGE = (0.015, 0.04)  # noise std at mid-grey
DEFAULT_SHAPE = (256, 320)

_MIN_SIZE = 32
_MAX_MAGNITUDE = 40.0
_TIMES = np.array([0.0, 1.0])
_MIN_PERSPECTIVE = 0.15  # projective share of the homography motion (see _homography_camera)


@dataclass
class PhotoPair:
    """A two-frame pair of photographs with exact flow (see the module notes).

    Attributes
    ----------
    frame0, frame1 : ndarray, shape (H, W, C), float32 in [0, 1]
        The frames (after the illumination change, noise or blur of the family).
    flow : ndarray, shape (H, W, 2), float32
        Exact flow frame0 -> frame1: ``[..., 0]`` = u (x), ``[..., 1]`` = v (y); the
        point seen at pixel ``(x, y)`` of frame 0 is at ``(x + u, y + v)`` in frame 1.
        Defined (finite) everywhere, also where ``valid`` is False.
    valid : ndarray, shape (H, W), bool
        True where the frame-0 pixel's point is inside frame 1 and not occluded there.
    family : str
        One of :data:`FAMILIES`.
    seed : int
    clean_frames : ndarray, shape (2, H, W, C), float32
        The frames before the photometric change, noise or blur (the same values as
        ``frame0``, ``frame1`` for the purely geometric families).
    layer : ndarray, shape (H, W), uint8
        Layer of each frame-0 pixel's point: 0 background, 1.. objects back to front.
    params : dict
        Metadata: ``"magnitude"``, ``"max_displacement"``, ``"mean_displacement"``,
        ``"occluded_fraction"`` (share of pixels not valid), ``"out_of_frame_fraction"``,
        ``"photos"``, ``"photo_scale"``, ``"background"``, ``"motion"`` (the
        background motion's parameters), ``"camera"`` (``"kind"`` and ``"matrix"``
        of frame-0 pixels for the affine and projective cameras, else None),
        ``"objects"``, ``"illumination"``, ``"noise"``, ``"blur"``, ``"supersample"``.
    """

    frame0: np.ndarray
    frame1: np.ndarray
    flow: np.ndarray
    valid: np.ndarray
    family: str
    seed: int
    clean_frames: np.ndarray
    layer: np.ndarray
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """``"<family>/<seed>"``."""
        return f"{self.family}/{self.seed}"

    @property
    def occlusion(self) -> np.ndarray:
        """``~valid``: occluded in frame 1 or leaving the frame, shape (H, W) bool."""
        return ~self.valid

    @property
    def shape(self) -> tuple[int, int]:
        """Frame size ``(H, W)``."""
        return int(self.frame0.shape[0]), int(self.frame0.shape[1])


# --------------------------------------------------------------------------- projective camera


class _HomographyMotion:
    """``M_n(p) = H_n p`` in homogeneous coordinates, ``H_n`` of shape (F, 3, 3)."""

    def __init__(self, mats: np.ndarray) -> None:
        self.h = np.asarray(mats, np.float64)
        self.hinv = np.linalg.inv(self.h)

    @staticmethod
    def _apply(m: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        den = m[2, 0] * x + m[2, 1] * y + m[2, 2]
        return (m[0, 0] * x + m[0, 1] * y + m[0, 2]) / den, (
            m[1, 0] * x + m[1, 1] * y + m[1, 2]
        ) / den

    def forward(self, px: np.ndarray, py: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
        return self._apply(self.h[n], px, py)

    def inverse(
        self, qx: np.ndarray, qy: np.ndarray, n: int, guess: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        return self._apply(self.hinv[n], qx, qy)


class _ProjectiveTexture(PhotoTexture):
    """A :class:`~varflow.generators.photo_textures.PhotoTexture` for a projective background.

    The renderer of :mod:`varflow.generators.photo` asks the background texture for
    the photo coordinates of the sub-sample grid through ``affine_coords``; here they
    go through the (any) motion's ``inverse`` instead of the affine closed form.
    """

    def affine_coords(self, motion: Any, n: int, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        px, py = motion.inverse(xs[None, :], ys[:, None], n)
        return self.coords(px, py)


def _rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (axis * angle)."""
    theta = float(np.linalg.norm(rvec))
    if theta == 0.0:
        return np.eye(3)
    k = rvec / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * kx + (1.0 - np.cos(theta)) * (kx @ kx)


def _grid_points(shape: tuple[int, int], n: int = 9) -> tuple[np.ndarray, np.ndarray]:
    h, w = shape
    gy, gx = np.meshgrid(np.linspace(0, h - 1, n), np.linspace(0, w - 1, n), indexing="ij")
    return gx.ravel(), gy.ravel()


def _affine_fit_residual(
    mat: np.ndarray, xs: np.ndarray, ys: np.ndarray
) -> float:
    """Largest distance between the homography and its least-squares affine fit (px)."""
    qx, qy = _HomographyMotion._apply(mat, xs, ys)
    design = np.stack([xs, ys, np.ones_like(xs)], -1)
    coef, *_ = np.linalg.lstsq(design, np.stack([qx, qy], -1), rcond=None)
    fit = design @ coef
    return float(np.hypot(fit[:, 0] - qx, fit[:, 1] - qy).max())


def _homography_camera(
    rng: np.random.Generator, shape: tuple[int, int], magnitude: float
) -> tuple[_HomographyMotion, dict[str, Any]]:
    """A camera moving in front of a tilted plane: ``M_1 = K (R + t n^T) K^{-1}``, ``M_0 = I``."""
    h, w = shape
    xs, ys = _grid_points(shape)
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    best: tuple[float, Any] | None = None
    for _attempt in range(20):
        f = rng.uniform(0.7, 1.4) * max(h, w)
        k = np.array([[f, 0.0, centre[0]], [0.0, f, centre[1]], [0.0, 0.0, 1.0]])
        kinv = np.linalg.inv(k)
        tilt = rng.uniform(np.radians(15.0), np.radians(50.0))
        azimuth = rng.uniform(0, 2 * np.pi)
        # plane n . X = 1 in camera-0 coordinates (depth 1 / n_z on the optical axis)
        normal = np.array(
            [np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)]
        )
        rot_dir = rng.normal(size=3) * np.array([1.0, 1.0, 0.6])  # pitch, yaw, roll
        rot_dir /= np.linalg.norm(rot_dir)
        trans_dir = rng.normal(size=3) * np.array([1.0, 1.0, 0.7])
        trans_dir /= np.linalg.norm(trans_dir)
        mix = rng.uniform(0.3, 0.7)  # share of rotation against translation (unit scale)
        rot_unit = mix * 0.02  # rad per unit of the scale s
        trans_unit = (1.0 - mix) * 0.02

        def build(
            s: float,
            k: np.ndarray = k,
            kinv: np.ndarray = kinv,
            normal: np.ndarray = normal,
            rot: np.ndarray = rot_unit * rot_dir,
            trans: np.ndarray = trans_unit * trans_dir,
        ) -> _HomographyMotion:
            hom = k @ (_rodrigues(s * rot) + np.outer(s * trans, normal)) @ kinv
            return _HomographyMotion(np.stack([np.eye(3), hom / hom[2, 2]]))

        def measure(m: _HomographyMotion) -> float:
            qx, qy = m.forward(xs, ys, 1)
            return float(np.hypot(qx - xs, qy - ys).max())

        motion, s = _calibrate(build, measure, magnitude)
        persp = _affine_fit_residual(motion.h[1], xs, ys)
        info = {
            "type": "homography",
            "matrix": motion.h[1].copy(),
            "focal_length": f,
            "K": k,
            "plane_normal": normal,
            "rotation_vector": s * rot_unit * rot_dir,
            "translation": s * trans_unit * trans_dir,
            "scale": s,
            "perspective_px": persp,
        }
        if magnitude == 0.0 or persp >= _MIN_PERSPECTIVE * magnitude:
            return motion, info
        if best is None or persp > best[0]:
            best = (persp, (motion, info))
    assert best is not None
    return best[1]


# --------------------------------------------------------------------------- blur


def _line_kernel(length: float, angle: float) -> np.ndarray:
    """Normalised centred line kernel (bilinear splats of points along the segment)."""
    radius = int(np.ceil(length / 2.0)) + 1
    size = 2 * radius + 1
    ker = np.zeros((size, size), np.float64)
    t = np.linspace(-length / 2.0, length / 2.0, 8 * int(np.ceil(length)) + 1)
    px = radius + t * np.cos(angle)
    py = radius + t * np.sin(angle)
    x0 = np.floor(px).astype(int)
    y0 = np.floor(py).astype(int)
    fx, fy = px - x0, py - y0
    for dy, dx, wgt in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)),
                        (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(ker, (y0 + dy, x0 + dx), wgt)
    return ker / ker.sum()


def _blur(
    rng: np.random.Generator, clean: np.ndarray, flow: np.ndarray
) -> tuple[np.ndarray, dict[str, Any]]:
    """Gaussian or centred motion blur of the second frame or of both (see the notes)."""
    kind = "gaussian" if rng.random() < 0.5 else "motion"
    which = "second" if rng.random() < 0.5 else "both"
    frames = (1,) if which == "second" else (0, 1)
    out = clean.copy()
    info: dict[str, Any] = {"kind": kind, "frames": which}
    if kind == "gaussian":
        sigmas = [0.0, 0.0]
        for n in frames:
            sigmas[n] = float(rng.uniform(0.8, 2.0))
            out[n] = gaussian_filter(clean[n], sigma=(sigmas[n], sigmas[n], 0), mode="nearest")
        info["sigma"] = tuple(sigmas)
        return out, info
    mean = flow.reshape(-1, 2).astype(np.float64).mean(axis=0)
    speed = float(np.hypot(flow[..., 0], flow[..., 1]).mean())
    angle = float(np.arctan2(mean[1], mean[0])) if np.hypot(*mean) > 0.5 else rng.uniform(0, np.pi)
    lengths = [0.0, 0.0]
    for n in frames:
        lengths[n] = float(np.clip(rng.uniform(0.3, 0.8) * speed, 2.0, 10.0))
        ker = _line_kernel(lengths[n], angle).astype(np.float32)
        for c in range(clean.shape[-1]):
            out[n, ..., c] = convolve(clean[n, ..., c], ker, mode="nearest")
    np.clip(out, 0.0, 1.0, out=out)
    info.update(length=tuple(lengths), angle=angle)
    return out, info


# --------------------------------------------------------------------------- public API


def _pair_rng(family: str, seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    ss = np.random.SeedSequence([seed, zlib.crc32(("pair/" + family).encode())])
    scene, noise = ss.spawn(2)
    return np.random.default_rng(scene), np.random.default_rng(noise)


def _affine_matrix(motion: _AffineMotion) -> np.ndarray:
    """The 2 x 3 matrix of ``x -> M_1(M_0^{-1}(x))``."""
    lin = motion.a[1] @ motion.ainv[0]
    off = motion.c + motion.b[1] - lin @ (motion.c + motion.b[0])
    return np.concatenate([lin, off[:, None]], axis=1)


def make_photo_pair(
    family: str,
    seed: int = 0,
    shape: tuple[int, int] = DEFAULT_SHAPE,
    magnitude: float | None = None,
    channels: int = 3,
    supersample: int = 4,
) -> PhotoPair:
    """Generate a two-frame pair of photographs with exact flow and occlusion mask.

    Parameters
    ----------
    family : {"affine", "homography", "nonrigid", "objects", "illumination", "noise", "blur"}
        Pair family (see the module notes).
    seed : int
        Seeds the photos, crops, shapes, motion, light, noise and blur (local
        generators; see :data:`SPLITS` for the tuning and reporting seeds).
    shape : (int, int)
        Frame size ``(H, W)``, each at least 32; default 256 x 320.
    magnitude : float, optional
        Largest background displacement between the frames (px, in ``[0, 40]``);
        default drawn per pair in :data:`MAGNITUDE_RANGE`.
    channels : {1, 3}
        1 for grey (luminance), 3 for colour.
    supersample : int
        Sub-samples per pixel side for area sampling, in ``[1, 16]``.

    Returns
    -------
    PhotoPair
        ``frame0``, ``frame1`` (H, W, C) float32 in [0, 1], ``flow`` (H, W, 2)
        float32, ``valid`` (H, W) bool, ``clean_frames``, ``layer`` and ``params``.

    Raises
    ------
    ValueError
        On an unknown family or an out-of-range argument (the message starts with
        the argument's name).
    ImportError
        When scikit-image (the photographs) is not installed.

    Examples
    --------
    >>> pair = make_photo_pair("objects", seed=1, shape=(64, 96))
    >>> pair.frame0.shape, pair.flow.shape, pair.valid.shape
    ((64, 96, 3), (64, 96, 2), (64, 96))
    """
    if family not in FAMILIES:
        raise ValueError(f"family: expected one of {FAMILIES}, got {family!r}")
    seed = _check_int(seed, "seed", 0)
    try:
        dims = tuple(shape)
        if len(dims) != 2:
            raise TypeError
        h, w = (_check_int(v, "shape", _MIN_SIZE) for v in dims)
    except (TypeError, ValueError):
        raise ValueError(
            f"shape: expected (H, W) with integers H, W >= {_MIN_SIZE}, got {shape!r}"
        ) from None
    if channels not in (1, 3) or isinstance(channels, bool):
        raise ValueError(f"channels: expected 1 or 3, got {channels!r}")
    supersample = _check_int(supersample, "supersample", 1)
    if supersample > 16:
        raise ValueError(f"supersample: expected at most 16, got {supersample}")
    if magnitude is not None:
        magnitude = _check_float(magnitude, "magnitude", 0.0, _MAX_MAGNITUDE)

    rng, noise_rng = _pair_rng(family, seed)
    drawn = float(rng.uniform(*MAGNITUDE_RANGE))  # drawn always: the stream does not
    magnitude = drawn if magnitude is None else magnitude  # depend on the argument
    params: dict[str, Any] = {"magnitude": magnitude}
    motion: Any
    camera: dict[str, Any] | None = None
    if family == "nonrigid":
        motion, params["motion"] = wave_sheet(rng, (h, w), _TIMES, magnitude)
    elif family == "homography":
        motion, params["motion"] = _homography_camera(rng, (h, w), magnitude)
        camera = {"kind": "homography", "matrix": params["motion"]["matrix"]}
    else:
        motion, params["motion"] = affine_camera(rng, (h, w), _TIMES, magnitude)
        camera = {"kind": "affine", "matrix": _affine_matrix(motion)}
    params["camera"] = camera
    extent = background_extent(motion, (h, w), 2)
    texture, bg_info = background_texture(rng, extent, channels)
    if family == "homography":
        texture = _ProjectiveTexture(
            texture.name, channels, texture.origin, texture.scale, texture.tint
        )
    params["background"] = {**bg_info, "extent": extent}
    params["photo_scale"] = bg_info["photo_scale"]
    layers = [PhotoLayer(motion, texture)]
    params["objects"] = []
    if family == "objects":
        # the object paths are calibrated from mid-time: half the magnitude each way
        objs, infos = photo_objects(
            rng, (h, w), _TIMES, 0.5 * magnitude, MAX_SPEED, channels, [texture.name]
        )
        layers += objs
        params["objects"] = infos
    params["photos"] = [layer.texture.name for layer in layers]

    clean = render(layers, (h, w), 2, channels, supersample)
    params["supersample"] = supersample
    traj, vis, owner = _trajectories(layers, (h, w), 2, 0)
    flow = np.ascontiguousarray(traj[1])
    valid = np.ascontiguousarray(vis[1])

    frames = clean
    params["illumination"] = None
    params["noise"] = None
    params["blur"] = None
    if family == "illumination":
        frames, params["illumination"] = illuminate(rng, clean, _TIMES)
    elif family == "noise":
        sigma = float(rng.uniform(*NOISE_SIGMA_RANGE))
        frames, params["noise"] = add_noise(noise_rng, clean, sigma)
    elif family == "blur":
        frames, params["blur"] = _blur(rng, clean, flow)

    disp = np.hypot(flow[..., 0], flow[..., 1])
    params["max_displacement"] = float(disp.max())
    params["mean_displacement"] = float(disp.mean())
    params["occluded_fraction"] = float(1.0 - valid.mean())
    params["out_of_frame_fraction"] = float((~in_bounds(flow)).mean())
    return PhotoPair(
        frame0=np.ascontiguousarray(frames[0]),
        frame1=np.ascontiguousarray(frames[1]),
        flow=flow,
        valid=valid,
        family=family,
        seed=seed,
        clean_frames=clean,
        layer=owner,
        params=params,
    )


def photo_pair_cases(split: str, families: Sequence[str] = FAMILIES) -> list[tuple[str, int]]:
    """The ``(family, seed)`` pairs of a split, family-major.

    Parameters
    ----------
    split : {"tuning", "reporting"}
        Which seeds (:data:`SPLITS`: 0-2 and 100-102, disjoint).
    families : sequence of str
        Subset of :data:`FAMILIES`.

    Returns
    -------
    list of (str, int)

    Raises
    ------
    ValueError
        Unknown split (``split: ...``) or family (``families: ...``).
    """
    return split_cases(split, families, FAMILIES)
