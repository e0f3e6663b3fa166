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

Modules
-------
This module holds the families, the splits and :func:`make_photo_clip`; the
pieces it builds on are shared with :mod:`varflow.generators.photo_pairs` and
:mod:`varflow.generators.large_pairs`:

* :mod:`varflow.generators.photo_textures` — the photographs and their sampling;
* :mod:`varflow.generators.photo_scenes` — layers, outlines and motions;
* :mod:`varflow.generators.photo_render` — rendering, change of light and noise.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter

from .photo_render import add_noise, illuminate, render
from .photo_scenes import (
    MAX_SPEED,
    PhotoLayer,
    affine_camera,
    background_extent,
    photo_objects,
    wave_sheet,
)
from .photo_textures import (
    COLOUR_PHOTOS,
    GREY_PHOTOS,
    PHOTO_SCALE_RANGE,
    PHOTOS,
    background_texture,
    load_photo,
)
from .sequences import SyntheticSequence, _check_float, _check_int, _trajectories

__all__ = [
    "FAMILIES",
    "COLOUR_PHOTOS",
    "GREY_PHOTOS",
    "PHOTOS",
    "PHOTO_SCALE_RANGE",
    "TUNING_SEEDS",
    "REPORTING_SEEDS",
    "SPLITS",
    "MAX_FRAMES",
    "MIN_SIZE",
    "load_photo",
    "make_photo_clip",
    "photo_cases",
    "split_cases",
    "photo_suite",
]


FAMILIES = ("affine", "nonrigid", "objects", "illumination", "noise")
TUNING_SEEDS = (0, 1, 2)
REPORTING_SEEDS = (100, 101, 102)
SPLITS = {"tuning": TUNING_SEEDS, "reporting": REPORTING_SEEDS}

#: Largest number of frames of a clip (:func:`make_photo_clip`).
MAX_FRAMES = 60
#: Smallest frame side in pixels (:func:`make_photo_clip`).
MIN_SIZE = 32


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
) -> tuple[list[PhotoLayer], dict[str, Any], np.random.Generator, np.random.Generator]:
    """Layers (back to front) and metadata of a clip; the generators for the rest."""
    rng, noise_rng = _family_rng(family, seed)
    drawn = float(rng.uniform(30.0, 50.0))
    magnitude = drawn if magnitude is None else magnitude
    times = np.arange(n_frames, dtype=np.float64) / (n_frames - 1)
    params: dict[str, Any] = {"magnitude": magnitude, "times": times}
    motion: Any
    if family == "nonrigid":
        motion, params["motion"] = wave_sheet(rng, shape, times, magnitude)
    else:
        motion, params["motion"] = affine_camera(rng, shape, times, magnitude)
    extent = background_extent(motion, shape, n_frames)
    texture, bg_info = background_texture(rng, extent, channels)
    params["background"] = {**bg_info, "extent": extent}
    params["photo_scale"] = bg_info["photo_scale"]
    layers = [PhotoLayer(motion, texture)]
    params["objects"] = []
    if family in ("objects", "illumination", "noise"):
        cap = max(MAX_SPEED, params["motion"]["peak_speed"])
        objs, infos = photo_objects(rng, shape, times, magnitude, cap, channels, [texture.name])
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
    if n_frames > MAX_FRAMES:
        raise ValueError(f"n_frames: expected at most {MAX_FRAMES}, got {n_frames}")
    try:
        dims = tuple(shape)
        if len(dims) != 2:
            raise TypeError
        h, w = (_check_int(v, "shape", MIN_SIZE) for v in dims)
    except (TypeError, ValueError):
        raise ValueError(
            f"shape: expected (H, W) with integers H, W >= {MIN_SIZE}, got {shape!r}"
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
    clean = render(layers, (h, w), n_frames, channels, supersample)
    if blur > 0:
        clean = gaussian_filter(clean, sigma=(0, blur, blur, 0), mode="nearest")
    params["supersample"] = supersample
    params["blur"] = blur
    traj, vis, owner = _trajectories(layers, (h, w), n_frames, ref)

    frames = clean
    params["illumination"] = None
    params["noise"] = None
    if family == "illumination":
        frames, params["illumination"] = illuminate(rng, clean, times)
    elif family == "noise":
        sigma = float(rng.uniform(0.01, 0.03))
        frames, params["noise"] = add_noise(noise_rng, clean, sigma)

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
