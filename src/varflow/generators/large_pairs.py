"""Two-frame pairs with large motion (30-150 px) of photographs, with exact flow.

The large-displacement counterpart of :mod:`varflow.generators.photo_pairs`: the
same photographs (bundled with scikit-image), the same area-sampling renderer and
the same layered scenes, but the moving objects travel 30-150 px between the two
frames, often farther than their own size, which is what coarse-to-fine warping
loses.  Defaults of the large-displacement mode are chosen on the
*tuning* split (:data:`TUNING_SEEDS`, seeds 0-3) and reported on the disjoint
*reporting* split (:data:`REPORTING_SEEDS`, seeds 100-103).

Families
--------
``"objects"``
    A gentle affine camera (largest background displacement 2-15 px) and 1-3
    photographic objects (radius 8-25 % of the smaller frame side, smooth
    outlines, each with its own rotation, zoom and path) that move
    :data:`OBJECT_MOTION_RANGE` = 30-150 px between the frames, occluding the
    background and each other; one of them straddles the frame border.
``"camera"``
    A fast camera (pan, roll, zoom and a slight shear; largest background
    displacement 30-80 px, :data:`CAMERA_MOTION_RANGE`) plus 1-3 objects moving
    30-150 px on their own.

The construction (maps, exact flow ``M_1(M_0^{-1}(x)) - x`` evaluated from the
analytic maps, validity = inside frame 1 and not covered there by a layer in
front) is that of :mod:`varflow.generators.photo_pairs`; see its notes.  Every
``(family, seed)`` draws from local generators seeded by ``(seed,
crc32("large/" + family))``.

References
----------
T. Brox, J. Malik, "Large displacement optical flow: descriptor matching in
variational motion estimation", IEEE TPAMI 33(3), 2011 (why such pairs matter).
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence

import numpy as np

from ..ops.warp import in_bounds
from .photo import split_cases
from .photo_pairs import PhotoPair, _affine_matrix
from .photo_render import render
from .photo_scenes import PhotoLayer, affine_camera, background_extent, photo_objects
from .photo_textures import background_texture
from .sequences import _check_int, _trajectories

__all__ = [
    "FAMILIES",
    "OBJECT_MOTION_RANGE",
    "CAMERA_MOTION_RANGE",
    "BACKGROUND_MOTION_RANGE",
    "DEFAULT_SHAPE",
    "TUNING_SEEDS",
    "REPORTING_SEEDS",
    "SPLITS",
    "make_large_pair",
    "large_pair_cases",
    "fast_object_clip",
]

FAMILIES: tuple[str, ...] = ("objects", "camera")
#: px: displacement of each moving object between the frames (drawn per pair).
OBJECT_MOTION_RANGE = (30.0, 150.0)
#: px: largest background displacement of the ``"camera"`` family.
CAMERA_MOTION_RANGE = (30.0, 80.0)
#: px: largest background displacement of the ``"objects"`` family.
BACKGROUND_MOTION_RANGE = (2.0, 15.0)
DEFAULT_SHAPE = (384, 512)
TUNING_SEEDS: tuple[int, ...] = (0, 1, 2, 3)
REPORTING_SEEDS: tuple[int, ...] = (100, 101, 102, 103)
SPLITS = {"tuning": TUNING_SEEDS, "reporting": REPORTING_SEEDS}

_MIN_SIZE = 64
_TIMES = np.array([0.0, 1.0])


def _rng(family: str, seed: int) -> np.random.Generator:
    ss = np.random.SeedSequence([seed, zlib.crc32(("large/" + family).encode())])
    return np.random.default_rng(ss)


def make_large_pair(
    family: str,
    seed: int = 0,
    shape: tuple[int, int] = DEFAULT_SHAPE,
    channels: int = 3,
    supersample: int = 3,
) -> PhotoPair:
    """Generate a pair of photographs whose objects move 30-150 px, with exact flow.

    Parameters
    ----------
    family : {"objects", "camera"}
        See the module notes.
    seed : int
        Seeds the photos, crops, shapes and motions (:data:`SPLITS` lists the tuning
        and reporting seeds).
    shape : (int, int)
        Frame size ``(H, W)``, each at least 64; default 384 x 512.
    channels : {1, 3}
        Grey (luminance) or colour.
    supersample : int
        Sub-samples per pixel side for area sampling, in ``[1, 16]``.

    Returns
    -------
    PhotoPair
        ``frame0``, ``frame1`` (H, W, C) float32 in [0, 1], ``flow`` (H, W, 2)
        float32 (exact), ``valid`` (H, W) bool (False: occluded in frame 1 or
        leaving it), ``layer`` and ``params`` (``"object_motion"``,
        ``"background_motion"``, ``"max_displacement"``, ``"mean_displacement"``,
        ``"object_displacement"`` = mean displacement over object pixels, ...).

    Raises
    ------
    ValueError
        Unknown family or out-of-range argument (the message names it).
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

    rng = _rng(family, seed)
    bg_range = CAMERA_MOTION_RANGE if family == "camera" else BACKGROUND_MOTION_RANGE
    bg_motion = float(rng.uniform(*bg_range))
    obj_motion = float(rng.uniform(*OBJECT_MOTION_RANGE))
    motion, motion_info = affine_camera(rng, (h, w), _TIMES, bg_motion)
    extent = background_extent(motion, (h, w), 2)
    texture, bg_info = background_texture(rng, extent, channels)
    # object paths are calibrated from mid-time: half the displacement each way; the
    # speed cap is lifted (two frames: only the displacement matters)
    objs, infos = photo_objects(rng, (h, w), _TIMES, 0.5 * obj_motion, 1e9, channels,
                                [texture.name])
    layers = [PhotoLayer(motion, texture), *objs]
    clean = render(layers, (h, w), 2, channels, supersample)
    traj, vis, owner = _trajectories(layers, (h, w), 2, 0)
    flow = np.ascontiguousarray(traj[1])
    valid = np.ascontiguousarray(vis[1])
    disp = np.hypot(flow[..., 0], flow[..., 1])
    on_objects = owner > 0
    params = {
        "object_motion": obj_motion,
        "background_motion": bg_motion,
        "motion": motion_info,
        "camera": {"kind": "affine", "matrix": _affine_matrix(motion)},
        "background": {**bg_info, "extent": extent},
        "objects": infos,
        "photos": [layer.texture.name for layer in layers],
        "supersample": supersample,
        "max_displacement": float(disp.max()),
        "mean_displacement": float(disp.mean()),
        "object_displacement": float(disp[on_objects].mean()) if on_objects.any() else 0.0,
        "object_fraction": float(on_objects.mean()),
        "occluded_fraction": float(1.0 - valid.mean()),
        "out_of_frame_fraction": float((~in_bounds(flow)).mean()),
    }
    return PhotoPair(
        frame0=np.ascontiguousarray(clean[0]),
        frame1=np.ascontiguousarray(clean[1]),
        flow=flow,
        valid=valid,
        family=family,
        seed=seed,
        clean_frames=clean,
        layer=owner,
        params=params,
    )


def large_pair_cases(split: str, families: Sequence[str] = FAMILIES) -> list[tuple[str, int]]:
    """The ``(family, seed)`` pairs of a split, family-major.

    Parameters
    ----------
    split : {"tuning", "reporting"}
    families : sequence of str
        Subset of :data:`FAMILIES`.

    Returns
    -------
    list of (str, int)
    """
    return split_cases(split, families, FAMILIES, SPLITS)


def fast_object_clip(
    n_frames: int = 5,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A disc moving 25 px per frame over a photograph moving 1.4 px per frame.

    The clip of the large-motion tracker tests and of
    ``benchmarks/bench_reproducibility.py``: scikit-image's ``coffee`` shifted by
    ``(k, k)`` px in frame ``ref + k``, and a disc of radius 20 cut from
    ``astronaut`` that moves by ``(24 k, −8 k)`` px, farther than its own size
    between the reference and the far frames (pasted, so it has no blur edge).

    Parameters
    ----------
    n_frames : int
        Number of frames F in ``[2, 7]``; the reference is ``F // 2``.

    Returns
    -------
    frames : ndarray, shape (F, 128, 192, 3), uint8
    trajectories : ndarray, shape (F, 128, 192, 2), float32
        Exact displacements of the reference frame's pixels.
    disc : ndarray, shape (128, 192), bool
        The disc's pixels in the reference frame.
    ref : int
    """
    n_frames = _check_int(n_frames, "n_frames", 2)
    if n_frames > 7:
        raise ValueError(f"n_frames: must be <= 7 (the disc leaves the frame), got {n_frames}")
    from .photo_textures import load_photo

    def as_uint8(img: np.ndarray) -> np.ndarray:
        return np.round(img * np.float32(255)).astype(np.uint8)

    bg, obj = as_uint8(load_photo("coffee")), as_uint8(load_photo("astronaut"))
    h, w, r = 128, 192, 20
    ref = n_frames // 2
    yy, xx = np.mgrid[0:h, 0:w]
    cx, cy = 96, 64
    disc_ref = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    frames, traj = [], np.zeros((n_frames, h, w, 2), np.float32)
    for n in range(n_frames):
        k = n - ref
        du, dv, ou, ov = k, k, 24 * k, -8 * k
        f = bg[60 - dv: 60 - dv + h, 80 - du: 80 - du + w].copy()
        disc = (xx - cx - ou) ** 2 + (yy - cy - ov) ** 2 <= r * r
        f[disc] = obj[yy[disc] - ov + 100, xx[disc] - ou + 180]
        frames.append(f)
        traj[n, ..., 0], traj[n, ..., 1] = du, dv
        traj[n][disc_ref] = (ou, ov)
    return np.stack(frames), traj, disc_ref, ref
