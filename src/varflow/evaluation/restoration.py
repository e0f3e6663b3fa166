"""The film-restoration protocol: planted archival defects, varflow's stages and peers.

Why: dirt removal, deflicker and stabilisation can only be compared with what a user
already has on clips whose damage is known exactly; the seeded defect generator
(:mod:`varflow.evaluation.defects`) plants it, and this module scores every method
against the clean clip and the generator's truth.

The protocol.  The clean clips are the restoration clips and Sintel alley_1
(:func:`~varflow.evaluation.denoising.protocol_clips`), the first
:data:`RESTORE_FRAMES` frames, optionally a top-left crop (the defects are then
planted on the crop: a crop is a smaller clip, with its own blotches and a weave about
its own centre).  Four cases (:data:`RESTORE_CASES`) per clip, each with the seed
:func:`case_seed` (CRC-32 of ``"clip:case"``, so every clip and case has its own,
stable across runs and machines):

* ``dirt`` -- :func:`~varflow.evaluation.defects.plant_dirt` alone;
* ``flicker`` -- :func:`~varflow.evaluation.defects.plant_flicker` alone;
* ``weave`` -- :func:`~varflow.evaluation.defects.plant_weave` alone;
* ``all`` -- :func:`~varflow.evaluation.defects.plant_defects`: weave, flicker,
  dirt and white noise of σ :data:`NOISE_SIGMA`.

The methods (:data:`CASE_METHODS`; kinds ``varflow``, ``ffmpeg``, ``simple``):
varflow's stage for the case (:func:`varflow.remove_dirt`, :func:`varflow.deflicker`,
:func:`varflow.stabilise`; for ``all`` :func:`varflow_chain`: stabilise, deflicker,
remove_dirt, denoise, the order of restoration practice: geometry first so that the
later temporal stages see aligned frames, brightness before the dirt test, noise last
since the other stages would take grain for signal); FFmpeg's filter for the defect
through PyAV (:func:`ffmpeg_tmedian`, :func:`ffmpeg_deflicker`, :func:`ffmpeg_deshake`;
for ``all`` the fixed chain :func:`ffmpeg_chain` tuned by :func:`tune_ffmpeg_chain`);
and the simple use of varflow where there is one (:func:`flow_median` for dirt,
:func:`mean_std_match` for flicker).  A row for the degraded input comes first.

The scores (:func:`score_restoration`): PSNR over all pixels, over the 16 px-inset
centre (weave and all), over the blotched and the untouched pixels
(:func:`masked_psnr`), the precision and recall of a returned dirt mask
(:func:`mask_precision_recall`), the residual flicker (:func:`residual_flicker`), the
residual jitter (stabilise's transforms through
:func:`~varflow.evaluation.defects.weave_residual`, and for every output of the weave
and all cases by registration to the clean frames, :func:`registration_jitter`), the
agreement of a stabiliser's outputs on the woven and the clean clip (weave case,
:func:`weave_agreement`), and seconds per frame.  :func:`run_restore_benchmark` runs it all,
:func:`format_restore_tables` prints it (``benchmarks/bench_restore.py``).
"""

from __future__ import annotations

import logging
import math
import time
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .denoising import (
    TUNING_CLIPS,
    _filter_graph,
    check_denoise_clips,
    clip_psnr,
    ffmpeg_filter_clip,
    protocol_clips,
    split_of,
)

__all__ = [
    "CASE_METHODS",
    "CENTRE_BORDER",
    "CHAIN_ATADENOISE",
    "CHAIN_DEFLICKER_SIZE",
    "CHAIN_GRID",
    "CHAIN_TMEDIAN_RADIUS",
    "NOISE_SIGMA",
    "RESTORE_CASES",
    "RESTORE_CSV_FIELDS",
    "RESTORE_FRAMES",
    "RESTORE_KINDS",
    "TIMED_STAGES",
    "case_seed",
    "chain_timing",
    "check_restore_cases",
    "check_restore_kinds",
    "ffmpeg_chain",
    "ffmpeg_deflicker",
    "ffmpeg_deshake",
    "ffmpeg_graph_clip",
    "ffmpeg_tmedian",
    "flow_median",
    "format_chain_timing",
    "format_chain_tuning",
    "format_restore_tables",
    "frame_shifts",
    "mask_precision_recall",
    "masked_psnr",
    "mean_std_match",
    "plant_case",
    "registration_jitter",
    "residual_flicker",
    "run_restore_benchmark",
    "score_restoration",
    "tune_ffmpeg_chain",
    "varflow_chain",
    "weave_agreement",
]

log = logging.getLogger(__name__)

#: The cases of the protocol, in table order.
RESTORE_CASES: tuple[str, ...] = ("dirt", "flicker", "weave", "all")
#: Frames per clip of the protocol, from each clip's start.
RESTORE_FRAMES = 12
#: Standard deviation (grey levels on 0-255) of the white noise of the ``all`` case:
#: visible film grain, also the σ given to
#: :func:`varflow.denoise` in :func:`varflow_chain`.
NOISE_SIGMA = 8.0
#: Border (px) left out of the centre PSNR and of the registration: the stabilised
#: frames' edges are brought in from outside the frame and cannot match the clean ones.
CENTRE_BORDER = 16
#: Kinds of method: varflow's stage, FFmpeg's filter, the simple use of varflow.
RESTORE_KINDS: tuple[str, ...] = ("varflow", "ffmpeg", "simple")
#: ``{case: ((label, kind), ...)}``: the methods run on each case, in table order.
CASE_METHODS: dict[str, tuple[tuple[str, str], ...]] = {
    "dirt": (("remove_dirt", "varflow"), ("tmedian", "ffmpeg"), ("flow-median", "simple")),
    "flicker": (("deflicker", "varflow"), ("ffmpeg-deflicker", "ffmpeg"),
                ("mean-std", "simple")),
    "weave": (("stabilise", "varflow"), ("deshake", "ffmpeg")),
    "all": (("varflow-chain", "varflow"), ("ffmpeg-chain", "ffmpeg")),
}

#: tmedian's radius (frames each side) in :func:`ffmpeg_chain`: the best mean centre
#: PSNR of the ``all`` case over :data:`CHAIN_GRID` on the clips of
#: :data:`~varflow.evaluation.denoising.TUNING_CLIPS` (:func:`tune_ffmpeg_chain`).
CHAIN_TMEDIAN_RADIUS = 2
#: atadenoise's thresholds ``(A, B)`` (fractions of the range, every plane) in
#: :func:`ffmpeg_chain`; from :func:`tune_ffmpeg_chain` as :data:`CHAIN_TMEDIAN_RADIUS`.
CHAIN_ATADENOISE = (0.04, 0.08)
#: deflicker's window (frames) in :func:`ffmpeg_chain`; from :func:`tune_ffmpeg_chain`
#: as :data:`CHAIN_TMEDIAN_RADIUS`.
CHAIN_DEFLICKER_SIZE = 9
#: The grid of :func:`tune_ffmpeg_chain`: tmedian radius, atadenoise ``(A, B)``
#: (FFmpeg's default and twice it) and deflicker size.
CHAIN_GRID: dict[str, tuple[Any, ...]] = {
    "tmedian_radius": (1, 2),
    "atadenoise": ((0.02, 0.04), (0.04, 0.08)),
    "deflicker_size": (5, 9),
}

#: The columns of the benchmark's rows (and CSV).
RESTORE_CSV_FIELDS: tuple[str, ...] = (
    "clip", "split", "case", "method", "kind", "seed", "frames", "height", "width",
    "psnr", "psnr_centre", "psnr_blotched", "psnr_untouched", "precision", "recall",
    "residual_flicker", "jitter", "jitter_registered", "weave_agreement",
    "seconds_per_frame",
)


# --------------------------------------------------------------------------- the cases


def case_seed(clip: str, case: str, seed: int = 0) -> int:
    """The seed of a clip's case: ``(crc32(f"{clip}:{case}") + seed) mod 2**32``.

    Why: every clip and case gets its own defects, the same on every run and machine
    (Python's ``hash`` of a string changes between processes; CRC-32 does not).

    Parameters
    ----------
    clip, case : str
    seed : int
        Added to the CRC (default 0: the protocol's draws).

    Returns
    -------
    int
        In ``[0, 2**32)``.
    """
    return (zlib.crc32(f"{clip}:{case}".encode()) + int(seed)) % 2**32


def plant_case(clean: np.ndarray, case: str, seed: int) -> tuple[np.ndarray, dict[str, Any]]:
    """The degraded clip of a case and its truth.

    Parameters
    ----------
    clean : ndarray, shape (F, H, W, C)
        The clean clip on 0-255.
    case : str
        One of :data:`RESTORE_CASES`.
    seed : int
        The generator's seed (:func:`case_seed`).

    Returns
    -------
    degraded : ndarray, float32, shape of ``clean``
        Not clipped.
    truth : dict
        ``mask`` (the dirt mask ``(F, H, W)`` bool in the degraded frames' geometry,
        None without dirt), ``weave``
        (:class:`~varflow.evaluation.defects.WeaveParams` or None), ``flicker``
        (:class:`~varflow.evaluation.defects.FlickerParams` or None).

    Raises
    ------
    ValueError
        An unknown case.
    """
    from .defects import plant_defects, plant_dirt, plant_flicker, plant_weave

    truth: dict[str, Any] = {"mask": None, "weave": None, "flicker": None}
    if case == "dirt":
        out, truth["mask"] = plant_dirt(clean, seed)
    elif case == "flicker":
        out, truth["flicker"] = plant_flicker(clean, seed)
    elif case == "weave":
        out, truth["weave"] = plant_weave(clean, seed)
    elif case == "all":
        out, res = plant_defects(clean, seed, noise=NOISE_SIGMA)
        truth.update(mask=res.dirt_mask, weave=res.weave, flicker=res.flicker)
    else:
        raise ValueError(f"case: unknown case {case!r}; expected one of "
                         f"{', '.join(RESTORE_CASES)}")
    return out, truth


# --------------------------------------------------------------------------- scores


def _clip255(a: np.ndarray) -> np.ndarray:
    return np.clip(np.asarray(a, np.float64), 0.0, 255.0)


def masked_psnr(restored: np.ndarray, clean: np.ndarray, mask: np.ndarray) -> float:
    """PSNR (dB) of ``restored`` clipped to [0, 255] over the pixels of ``mask``.

    The squared errors of every channel of the masked pixels of the whole clip are
    pooled (one mean, not a mean over frames: a frame may hold a handful of blotched
    pixels).

    Parameters
    ----------
    restored, clean : ndarray, shape (F, H, W[, C])
        On 0-255.
    mask : ndarray, bool, shape (F, H, W)

    Returns
    -------
    float
        NaN for an empty mask, inf for no error.
    """
    d, c = _clip255(restored), np.asarray(clean, np.float64)
    m = np.asarray(mask, bool)
    if d.shape != c.shape or m.shape != d.shape[:3]:
        raise ValueError(f"mask: shapes {d.shape}, {c.shape} and mask {m.shape} differ")
    if not m.any():
        return math.nan
    mse = float(np.mean((d[m] - c[m]) ** 2))
    return math.inf if mse == 0 else 10 * math.log10(255.0**2 / mse)


def mask_precision_recall(found: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Pixel precision and recall of a detected dirt mask against the planted one.

    Parameters
    ----------
    found, truth : ndarray, bool, shape (F, H, W)

    Returns
    -------
    (float, float)
        ``|found ∩ truth| / |found|`` and ``|found ∩ truth| / |truth|``; NaN where the
        denominator is 0.
    """
    f, t = np.asarray(found, bool), np.asarray(truth, bool)
    if f.shape != t.shape:
        raise ValueError(f"found: shape {f.shape} differs from truth {t.shape}")
    hit = float(np.count_nonzero(f & t))
    nf, nt = np.count_nonzero(f), np.count_nonzero(t)
    return (hit / nf if nf else math.nan), (hit / nt if nt else math.nan)


def residual_flicker(restored: np.ndarray, clean: np.ndarray) -> float:
    """Standard deviation over frames of the per-frame mean error, grey levels.

    Why: flicker is a brightness that changes from frame to frame; a constant offset
    is not flicker and scores 0.

    ``e_t = mean over pixels and channels of (clip(restored_t) − clean_t)``; the
    result is ``std(e)`` with ``ddof=0``.

    Parameters
    ----------
    restored, clean : ndarray, shape (F, H, W[, C])
        On 0-255.

    Returns
    -------
    float
    """
    d, c = _clip255(restored), np.asarray(clean, np.float64)
    if d.shape != c.shape:
        raise ValueError(f"restored: shape {d.shape} differs from clean {c.shape}")
    return float(np.std((d - c).reshape(d.shape[0], -1).mean(axis=1)))


def _grey(frame: np.ndarray) -> np.ndarray:
    f = np.asarray(frame, np.float32)
    return f.mean(axis=-1) if f.ndim == 3 else f


def _identity_params(n: int, h: int, w: int) -> Any:
    from .defects import WeaveParams

    eye = np.zeros((n, 2, 3))
    eye[:, 0, 0] = eye[:, 1, 1] = 1.0
    z = np.zeros(n)
    return WeaveParams(dx=z, dy=z, angle=z, matrices=eye, shape=(h, w))


def registration_jitter(restored: np.ndarray, clean: np.ndarray,
                        border: int = CENTRE_BORDER) -> np.ndarray:
    """Residual jitter of a clip by registration to the clean frames, px per frame.

    Why: FFmpeg's deshake and the chains return no transforms; registering their
    output to the clean frames measures what weave is left for any method alike.

    Per frame, the Euclidean map (rotation and translation) ``M`` taking a clean
    pixel to where its content is in the output is found by
    :func:`cv2.findTransformECC` on grey frames (insensitive to a global gain and
    offset, so flicker does not bias it), over the frame less ``border`` px, started
    from :func:`cv2.phaseCorrelate`'s translation (Hann-windowed) and from the
    identity, the better correlation kept; the residual is the RMS over the
    pixel centres of ``|M p − p|`` (:func:`~varflow.evaluation.defects.weave_residual`
    against the identity).  A frame where ECC fails keeps the phase correlation.
    Accuracy: on small smooth synthetic frames (96 x 112) ECC is off by 0.1-0.5 px
    per frame (measured against the planted weave); the column is a cross-check,
    the transforms' ``jitter`` the exact score where a method returns them.

    Parameters
    ----------
    restored, clean : ndarray, shape (F, H, W[, C])
        On 0-255.
    border : int
        Pixels left out on each side (default :data:`CENTRE_BORDER`).

    Returns
    -------
    ndarray, float64, shape (F,)
    """
    import cv2

    from .defects import weave_residual

    d, c = np.asarray(restored), np.asarray(clean)
    if d.shape != c.shape:
        raise ValueError(f"restored: shape {d.shape} differs from clean {c.shape}")
    n, h, w = c.shape[:3]
    mask = np.zeros((h, w), np.uint8)
    b = int(border) if min(h, w) > 4 * border else 0
    mask[b:h - b, b:w - b] = 1
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-5)
    window = cv2.createHanningWindow((w, h), cv2.CV_64F)
    est = np.zeros((n, 2, 3))
    for t in range(n):
        ref = np.ascontiguousarray(_grey(c[t]))
        out = np.ascontiguousarray(np.clip(_grey(d[t]), 0, 255).astype(np.float32))
        (sx, sy), _ = cv2.phaseCorrelate(ref.astype(np.float64), out.astype(np.float64),
                                         window)
        best, best_cc = np.array([[1, 0, sx], [0, 1, sy]]), -np.inf
        for start in (best.copy(), np.eye(2, 3)):
            try:
                cc, m = cv2.findTransformECC(ref, out, start.astype(np.float32),
                                             cv2.MOTION_EUCLIDEAN, criteria, mask, 5)
            except cv2.error:
                continue
            if cc > best_cc:
                best, best_cc = m, cc
        if not math.isfinite(best_cc):
            log.info("registration of frame %d: ECC did not converge; phase correlation "
                     "kept", t)
        est[t] = best
    return weave_residual(est, _identity_params(n, h, w))


#: Fraction of each side kept by :func:`weave_agreement`: the central 70 % of the frame,
#: away from the edges a stabiliser brings in from outside it.
AGREEMENT_CENTRE = 0.7
#: f₀ of the spectral weight ``exp(−|f|² / 2 f₀²)`` (f in cycles per pixel) of
#: :func:`frame_shifts`' phase correlation.
AGREEMENT_BAND = 0.1


def frame_shifts(a: np.ndarray, b: np.ndarray, centre: float = AGREEMENT_CENTRE,
                 band: float = AGREEMENT_BAND) -> np.ndarray:
    """Per frame, the translation of ``b`` against ``a`` by band-limited phase correlation, px.

    Grey frames, the central ``centre`` of each side, Hann-windowed; the normalised
    cross-power spectrum (unit magnitude: phase correlation) weighted by
    ``exp(−|f|² / 2 f₀²)``, and its peak refined to 1/50 px by the upsampled
    cross-correlation of :func:`skimage.registration.phase_cross_correlation`.
    Why the weight (Takita et al. 2003): every resampling of a frame (the planted
    weave, the stabiliser's warp) alters the phase of its highest frequencies, and
    plain phase correlation gives them the weight of the rest: on real frames
    resampled twice by bicubic warps whose net motion is a known translation it is
    off by 0.1-0.3 px, where the band-limited one is within about 0.05 px.

    Parameters
    ----------
    a, b : ndarray, shape (F, H, W[, C])
        Two clips of the same shape, on 0-255.
    centre : float
        Fraction of each side kept, in (0, 1] (default :data:`AGREEMENT_CENTRE`).
    band : float
        f₀, cycles per pixel, > 0 (default :data:`AGREEMENT_BAND`).

    Returns
    -------
    ndarray, float64, shape (F, 2)
        ``(dx, dy)`` per frame: the content of ``a`` at ``p`` is at ``p + (dx, dy)``
        in ``b``.

    References
    ----------
    K. Takita, T. Aoki, Y. Sasaki, T. Higuchi, K. Kobayashi, "High-accuracy subpixel
    image registration based on phase-only correlation", IEICE Trans. Fundamentals
    E86-A(8), 2003.
    """
    import cv2
    from skimage.registration import phase_cross_correlation

    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"b: shape {b.shape} differs from a {a.shape}")
    if not 0.0 < centre <= 1.0:
        raise ValueError(f"centre: must be in (0, 1], got {centre!r}")
    if not band > 0.0:
        raise ValueError(f"band: must be positive, got {band!r}")
    n, h, w = a.shape[:3]
    ch, cw = max(int(round(h * centre)), 8), max(int(round(w * centre)), 8)
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    window = cv2.createHanningWindow((cw, ch), cv2.CV_64F)
    fy, fx = np.fft.fftfreq(ch)[:, None], np.fft.fftfreq(cw)[None, :]
    root = np.exp(-0.25 * (fx * fx + fy * fy) / (band * band))  # its square is the weight
    out = np.zeros((n, 2))
    for t in range(n):
        spectra = []
        for clip in (a, b):
            f = np.fft.fft2(_grey(clip[t])[y0:y0 + ch, x0:x0 + cw].astype(np.float64)
                            * window)
            spectra.append(f / np.maximum(np.abs(f), 1e-12) * root)
        # the shift that registers b onto a, (row, col): minus the content's motion
        s, _, _ = phase_cross_correlation(spectra[0], spectra[1], space="fourier",
                                          upsample_factor=50, normalization=None)
        out[t] = -s[1], -s[0]
    return out


def weave_agreement(from_woven: np.ndarray, from_clean: np.ndarray,
                    centre: float = AGREEMENT_CENTRE, band: float = AGREEMENT_BAND) -> float:
    """How far a stabiliser's output on a woven clip jitters against its output on the clean one.

    Why: a stabiliser keeps a smoothed camera path, so its outputs on the woven and the
    clean clip may differ by a slowly varying shift, but not by a jerky one.  The
    score is the RMS over frames of the length of the second difference over time of
    the per-frame shift between the two outputs (:func:`frame_shifts` on the central
    ``centre`` of the frames); a smooth drift scores 0.  Given the woven clip and the
    clean clip themselves it measures the weave: about 8 px for independent shifts
    uniform in ±4 px (each component's second difference has 6 times the variance,
    16/3 px²).

    Parameters
    ----------
    from_woven, from_clean : ndarray, shape (F, H, W[, C])
        On 0-255, F >= 3.
    centre, band : float
        As :func:`frame_shifts`.

    Returns
    -------
    float
        px.
    """
    shifts = frame_shifts(from_clean, from_woven, centre, band)
    if len(shifts) < 3:
        raise ValueError(f"from_woven: needs at least 3 frames, got {len(shifts)}")
    second = shifts[2:] - 2.0 * shifts[1:-1] + shifts[:-2]
    return float(np.sqrt(np.mean(np.sum(second ** 2, axis=1))))


def _identity_transforms(n: int) -> np.ndarray:
    """``(n, 2, 3)`` identity corrections: the degraded input's, for its jitter."""
    eye = np.zeros((n, 2, 3))
    eye[:, 0, 0] = eye[:, 1, 1] = 1.0
    return eye


def _map_mask(mask: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """``mask`` ``(F, H, W)`` of one geometry in another: ``out_t(q) = mask_t(M_t q)``,
    the pixel ``q`` of the new geometry being at ``M_t q`` in the mask's; any overlap
    of a blotched pixel counts (bilinear weight above 0)."""
    import cv2

    n, h, w = mask.shape
    out = np.empty_like(mask, dtype=bool)
    for t in range(n):
        m = cv2.warpAffine(mask[t].astype(np.float32), np.asarray(matrices[t], np.float64),
                           (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                           borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        out[t] = m > 1e-3
    return out


def _centre(a: np.ndarray, border: int) -> np.ndarray:
    h, w = a.shape[1:3]
    b = border if min(h, w) > 4 * border else 0
    return a[:, b:h - b, b:w - b]


def score_restoration(restored: np.ndarray, clean: np.ndarray, case: str,
                      truth: dict[str, Any], found_mask: np.ndarray | None = None,
                      transforms: np.ndarray | None = None,
                      border: int = CENTRE_BORDER) -> dict[str, float | None]:
    """The scores of one output of a case.

    Parameters
    ----------
    restored, clean : ndarray, shape (F, H, W, C)
        The method's output and the clean clip, on 0-255.  The clean clip is the
        reference in every case, weave included (the weave is to be removed).
    case : str
        One of :data:`RESTORE_CASES`.
    truth : dict
        As :func:`plant_case` returns.
    found_mask : ndarray, bool, shape (F, H, W), optional
        The dirt mask the method returned (in its output's geometry).
    transforms : ndarray, shape (F, 2, 3), optional
        The corrections the method applied (input to output pixels, as
        :func:`varflow.stabilise` returns them).
    border : int
        Of the centre PSNR and the registration.

    Returns
    -------
    dict
        ``psnr`` (:func:`~varflow.evaluation.denoising.clip_psnr`), ``psnr_centre``
        (the same without ``border`` px; weave and all), ``psnr_blotched``,
        ``psnr_untouched`` (:func:`masked_psnr` over the dirt mask and its
        complement; dirt and all: in the all case the mask is carried from the woven
        frames to the clean geometry by the planted weave), ``precision``,
        ``recall`` (:func:`mask_precision_recall` of ``found_mask`` against the
        planted mask, carried in the all case to the output's geometry by
        ``transforms``), ``residual_flicker`` (:func:`residual_flicker`),
        ``jitter`` (mean over frames of
        :func:`~varflow.evaluation.defects.weave_residual` of the inverse of
        ``transforms``, or of no correction for the input), ``jitter_registered``
        (mean of :func:`registration_jitter`); None where a score does not apply.
    """
    import cv2

    from .defects import weave_residual

    r: dict[str, float | None] = dict.fromkeys(
        ("psnr", "psnr_centre", "psnr_blotched", "psnr_untouched", "precision", "recall",
         "residual_flicker", "jitter", "jitter_registered"))
    r["psnr"] = clip_psnr(restored, clean)
    r["residual_flicker"] = residual_flicker(restored, clean)
    weave = truth.get("weave")
    if case in ("weave", "all"):
        r["psnr_centre"] = clip_psnr(_centre(np.asarray(restored), border),
                                     _centre(np.asarray(clean), border))
        r["jitter_registered"] = float(np.mean(registration_jitter(restored, clean, border)))
        if weave is not None and transforms is not None:
            est = np.stack([cv2.invertAffineTransform(np.asarray(m, np.float64))
                            for m in transforms])
            r["jitter"] = float(np.mean(weave_residual(est, weave)))
    mask = truth.get("mask")
    if mask is not None:
        in_clean = mask if weave is None else _map_mask(mask, weave.matrices)
        r["psnr_blotched"] = masked_psnr(restored, clean, in_clean)
        r["psnr_untouched"] = masked_psnr(restored, clean, ~in_clean)
        if found_mask is not None:
            target = mask
            if transforms is not None:  # the planted mask in the output's geometry
                target = _map_mask(mask, np.stack(
                    [cv2.invertAffineTransform(np.asarray(m, np.float64))
                     for m in transforms]))
            r["precision"], r["recall"] = mask_precision_recall(found_mask, target)
    return r


# --------------------------------------------------------------------------- peers


def ffmpeg_graph_clip(frames: np.ndarray, filters: Sequence[tuple[str, str]],
                      pix_fmt: str = "gbrp") -> np.ndarray:
    """Run a chain of FFmpeg filters over an 8-bit RGB clip; every frame that comes out.

    Why: :func:`~varflow.evaluation.denoising.ffmpeg_filter_clip` runs one filter and
    wants a frame out per frame in; FFmpeg's ``tmedian`` gives none for the first and
    last ``radius`` frames, and a user's chain is one graph.

    The graph is ``buffer (rgb24) → format=pix_fmt → filters… → format=rgb24 →
    buffersink`` at 25 frames per second, flushed at the end.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, 3)
        On 0-255 (rounded and clipped to uint8).
    filters : sequence of (str, str)
        ``(name, options)`` in order.
    pix_fmt : str
        The format the filters run on (default ``gbrp``, planar RGB: exact).

    Returns
    -------
    ndarray, uint8, shape (F', H, W, 3)
        The frames out, in order (F' may be below F).

    Raises
    ------
    ValueError
        A filter or options FFmpeg refuses, or a clip that is not RGB.
    """
    clip = np.asarray(frames)
    if clip.ndim != 4 or clip.shape[-1] != 3:
        raise ValueError(f"frames: expected an RGB clip (F, H, W, 3), got shape {clip.shape}")
    clip = np.ascontiguousarray(np.clip(np.rint(np.asarray(clip, np.float64)), 0, 255)
                                .astype(np.uint8))
    _, h, w, _ = clip.shape
    out = _filter_graph(clip, "rgb24", pix_fmt, filters,
                        f"filters: FFmpeg refuses {list(filters)!r}")
    return np.stack(out) if out else np.empty((0, h, w, 3), np.uint8)


def _mirror(n: int, pad: int) -> list[int]:
    """Frame indices of a clip of ``n`` frames mirrored by ``pad`` at each end
    (``2 1 | 0 1 2 … n-1 | n-2 n-3``)."""
    idx = [abs(k) for k in range(-pad, 0)] + list(range(n))
    idx += [2 * (n - 1) - k for k in range(n, n + pad)]
    return [min(max(i, 0), n - 1) for i in idx]


def ffmpeg_tmedian(degraded: np.ndarray, radius: int = 1) -> np.ndarray:
    """FFmpeg's temporal median (``tmedian``) of ``2 radius + 1`` frames, no motion.

    FFmpeg outputs nothing for the first and last ``radius`` frames: the clip is
    mirrored by ``radius`` frames at each end first, so every frame has a median.

    Parameters
    ----------
    degraded : ndarray, shape (F, H, W, 3)
        On 0-255 (rounded and clipped to uint8: part of what the peer costs).
    radius : int
        Frames each side (default 1).

    Returns
    -------
    ndarray, float32, shape of ``degraded``
    """
    n = len(degraded)
    out = ffmpeg_graph_clip(np.asarray(degraded)[_mirror(n, radius)],
                            [("tmedian", f"radius={int(radius)}")])
    return out[:n].astype(np.float32)


def ffmpeg_deflicker(degraded: np.ndarray, size: int = 5, mode: str = "am") -> np.ndarray:
    """FFmpeg's ``deflicker``: each frame's mean brightness scaled to the mean
    (``mode``, arithmetic by default) of the ``size`` frames around it.

    Parameters
    ----------
    degraded : ndarray, shape (F, H, W, 3)
        On 0-255 (rounded and clipped to uint8).
    size : int
        Window, frames (default 5).
    mode : str
        FFmpeg's averaging mode.

    Returns
    -------
    ndarray, float32, shape of ``degraded``
    """
    return ffmpeg_filter_clip(degraded, "deflicker",
                              f"size={int(size)}:mode={mode}").astype(np.float32)


def ffmpeg_deshake(degraded: np.ndarray) -> np.ndarray:
    """FFmpeg's ``deshake`` with its defaults, on ``yuv444p`` (deshake's formats are YUV).

    Parameters
    ----------
    degraded : ndarray, shape (F, H, W, 3)
        On 0-255 (rounded and clipped to uint8).

    Returns
    -------
    ndarray, float32, shape of ``degraded``
    """
    return ffmpeg_filter_clip(degraded, "deshake", "", pix_fmt="yuv444p").astype(np.float32)


def _chain_rest(deshaken: np.ndarray, tmedian_radius: int, atadenoise: tuple[float, float],
                deflicker_size: int) -> np.ndarray:
    n = len(deshaken)
    a, b = atadenoise
    ata = ":".join(f"{p}a={a:g}:{p}b={b:g}" for p in range(3))
    out = ffmpeg_graph_clip(deshaken[_mirror(n, tmedian_radius)],
                            [("deflicker", f"size={int(deflicker_size)}:mode=am"),
                             ("tmedian", f"radius={int(tmedian_radius)}"),
                             ("atadenoise", ata)])
    return out[:n].astype(np.float32)


def ffmpeg_chain(degraded: np.ndarray, tmedian_radius: int = CHAIN_TMEDIAN_RADIUS,
                 atadenoise: tuple[float, float] = CHAIN_ATADENOISE,
                 deflicker_size: int = CHAIN_DEFLICKER_SIZE) -> np.ndarray:
    """The fixed FFmpeg chain of the ``all`` case: ``deshake,deflicker,tmedian,atadenoise``.

    ``deshake`` (defaults) runs on ``yuv444p`` (:func:`ffmpeg_deshake`); the rest
    in one graph on ``gbrp``: ``deflicker=size=S:mode=am``, ``tmedian=radius=R`` (the
    clip mirrored by R frames at each end, as :func:`ffmpeg_tmedian`) and
    ``atadenoise`` with thresholds A, B on every plane (9 frames).  Defaults from
    :func:`tune_ffmpeg_chain` on the tuning clips.

    Parameters
    ----------
    degraded : ndarray, shape (F, H, W, 3)
        On 0-255 (rounded and clipped to uint8).
    tmedian_radius : int
    atadenoise : (float, float)
        Thresholds A and B, fractions of the range.
    deflicker_size : int

    Returns
    -------
    ndarray, float32, shape of ``degraded``
    """
    deshaken = ffmpeg_deshake(degraded)
    return _chain_rest(deshaken, tmedian_radius, atadenoise, deflicker_size)


def flow_median(degraded: np.ndarray, method: str = "tvl1-fast") -> np.ndarray:
    """The simple use of varflow against dirt: a motion-compensated temporal median.

    Every frame ``t`` is replaced by the per-pixel, per-channel median of itself and
    two neighbours warped onto it by ``varflow.flow(frame_t, neighbour, method)``
    (:func:`varflow.warp`): ``t − 1`` and ``t + 1``, the two next at the first frame,
    the two previous at the last.  Where a neighbour falls outside the frame it is left
    out (median of two: their mean).

    Parameters
    ----------
    degraded : ndarray, shape (F, H, W[, C]), F >= 3
        On 0-255.
    method : str
        The two-frame flow method (default ``tvl1-fast``).

    Returns
    -------
    ndarray, float32, shape of ``degraded``
    """
    import varflow

    clip = np.asarray(degraded, np.float32)
    n = clip.shape[0]
    if n < 3:
        raise ValueError(f"degraded: need at least 3 frames, got {n}")
    out = np.empty_like(clip)
    for t in range(n):
        pair = (1, 2) if t == 0 else (n - 2, n - 3) if t == n - 1 else (t - 1, t + 1)
        stack = [clip[t]] + [varflow.warp(clip[s], varflow.flow(clip[t], clip[s], method))
                             for s in pair]
        out[t] = np.nanmedian(np.stack(stack), axis=0)
    return out


def mean_std_match(degraded: np.ndarray) -> np.ndarray:
    """The simple deflicker: every frame's mean and deviation matched, per channel,
    to the clip's averages.

    ``out_t = (x_t − μ_t) · σ̄ / σ_t + μ̄`` with ``μ_t``, ``σ_t`` the mean and standard
    deviation of frame ``t``'s channel over its pixels and ``μ̄``, ``σ̄`` their means over
    the frames.

    Parameters
    ----------
    degraded : ndarray, shape (F, H, W[, C])
        On 0-255.

    Returns
    -------
    ndarray, float32, shape of ``degraded``
    """
    clip = np.asarray(degraded, np.float64)
    axes = (1, 2)
    mu = clip.mean(axis=axes, keepdims=True)
    sd = np.maximum(clip.std(axis=axes, keepdims=True), 1e-6)
    return ((clip - mu) * (sd.mean(axis=0) / sd) + mu.mean(axis=0)).astype(np.float32)


def varflow_chain(degraded: np.ndarray, sigma: float | None = NOISE_SIGMA
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """varflow's stages in the order of restoration practice: stabilise, deflicker,
    remove_dirt, denoise; the last three as ``varflow restore`` runs them
    (:func:`varflow.restore_clip`: the dirt stage starts from deflicker's flows).

    Parameters
    ----------
    degraded : ndarray, shape (F, H, W, C)
        On 0-255.
    sigma : float or None
        Of :func:`varflow.denoise` (default :data:`NOISE_SIGMA`, the noise planted;
        None: estimated).

    Returns
    -------
    restored : ndarray, float32
    mask : ndarray, bool, shape (F, H, W)
        :func:`varflow.remove_dirt`'s mask, in the stabilised geometry.
    transforms : ndarray, shape (F, 2, 3)
        :func:`varflow.stabilise`'s corrections.
    """
    import varflow

    steady, transforms = varflow.stabilise(degraded, return_transforms=True)
    out, mask = varflow.restore_clip(steady, ["deflicker", "dirt", "denoise"], sigma=sigma,
                                     return_mask=True)
    return np.asarray(out, np.float32), mask, transforms


# --------------------------------------------------------------------------- timing

#: The stages whose time :func:`chain_timing` compares with one flow: the repair chain
#: without denoising.
TIMED_STAGES: tuple[str, ...] = ("stabilise", "deflicker", "dirt")


def chain_timing(root: str | Path | None = None, clip: str = "bigbuckbunny",
                 frames: int = 24, stages: Sequence[str] = TIMED_STAGES,
                 chunk: int = 24, repeats: int = 3) -> dict[str, Any]:
    """Seconds per frame of each stage of the streamed chain, against one default flow.

    The first ``frames`` frames of ``clip`` get the ``all`` case's defects (8-bit, as a
    user's file holds them) and go through :func:`varflow.restore.chain.iter_restore`
    with ``stages`` (in memory: no decoding or encoding is timed); in the same run,
    :func:`varflow.flow` with its default method on the first two degraded frames
    (median of ``repeats`` runs).  JIT compilation is done before either is timed.

    Returns
    -------
    dict
        ``clip``, ``frames``, ``width``, ``height``, ``stages``, ``chunk``,
        ``flow_seconds`` (one flow), ``stage_seconds`` (``{stage: s per frame}``),
        ``chain_seconds`` (all the stages, per frame) and ``ratio``
        (``chain_seconds / flow_seconds``).
    """
    import varflow
    from varflow.restore.chain import iter_restore

    from .datasets import data_root
    from .defects import plant_defects

    clean = protocol_clips(data_root(root), frames, (clip,))[clip]
    degraded, _ = plant_defects(clean, case_seed(clip, "all"), noise=NOISE_SIGMA)
    u8 = np.clip(np.rint(degraded), 0, 255).astype(np.uint8)
    tiny = u8[:4, :48, :64]
    varflow.flow(tiny[0], tiny[1])
    list(iter_restore(iter(list(tiny)), stages))
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        varflow.flow(u8[0], u8[1])
        times.append(time.perf_counter() - t0)
    flow_s = float(np.median(times))
    stats: dict[str, Any] = {}
    for _ in iter_restore(iter(list(u8)), stages, chunk=chunk, stats=stats):
        pass
    n = len(u8)
    per_stage = {k: v / n for k, v in stats["seconds"].items()}
    total = float(sum(per_stage.values()))
    return {"clip": clip, "frames": n, "width": u8.shape[2], "height": u8.shape[1],
            "stages": list(stages), "chunk": chunk, "flow_seconds": flow_s,
            "stage_seconds": per_stage, "chain_seconds": total, "ratio": total / flow_s}


def format_chain_timing(result: dict[str, Any]) -> str:
    """A table of :func:`chain_timing`'s result."""
    lines = [f"Chain timing: {result['clip']}, {result['frames']} frames of "
             f"{result['width']}x{result['height']}, windows of {result['chunk']} frames; "
             f"one default varflow.flow on a pair: {result['flow_seconds']:.2f} s", "",
             "| stage | s per frame | x one flow |", "|---|---:|---:|"]
    for name, sec in result["stage_seconds"].items():
        lines.append(f"| {name} | {sec:.2f} | {sec / result['flow_seconds']:.2f} |")
    lines.append(f"| chain ({' + '.join(result['stages'])}) | {result['chain_seconds']:.2f} | "
                 f"{result['ratio']:.2f} |")
    return "\n".join(lines)


# --------------------------------------------------------------------------- tuning


def tune_ffmpeg_chain(root: str | Path | None = None,
                      clips: Sequence[str] = TUNING_CLIPS, frames: int = RESTORE_FRAMES,
                      crop: tuple[int, int] | None = (272, 320),
                      grid: dict[str, Sequence[Any]] | None = None,
                      border: int = CENTRE_BORDER,
                      callback: Callable[[int, int], None] | None = None
                      ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Choose the parameters of :func:`ffmpeg_chain` on the tuning clips.

    Why: the peer chain deserves its best settings, chosen on clips the reported
    means never use.

    For every clip, the ``all`` case (:func:`plant_case`, :func:`case_seed`) is
    deshaken once and every combination of ``grid`` runs the rest of the chain; the
    choice is the best mean over the clips of the centre PSNR (``border`` px left
    out).  The module's ``CHAIN_*`` constants are this function's choice with its
    defaults.

    Parameters
    ----------
    root : str or path, optional
        The data folder.
    clips : sequence of str
        Tuning clips only (default :data:`TUNING_CLIPS`).
    frames : int
        Frames from each clip's start.
    crop : (int, int) or None
        Top-left ``(H, W)`` (default 272 x 320, at most the frames: carphone's 144 x
        176 stay whole; None: whole frames).
    grid : dict, optional
        ``tmedian_radius``, ``atadenoise``, ``deflicker_size`` values (default
        :data:`CHAIN_GRID`).
    border : int
    callback : callable, optional
        ``callback(done, total)``.

    Returns
    -------
    best : dict
        ``tmedian_radius``, ``atadenoise``, ``deflicker_size`` and ``psnr_centre``.
    rows : list of dict
        Per combination: its values, ``psnr_centre`` per clip (``psnr_centre_<clip>``)
        and their mean ``psnr_centre``.

    Raises
    ------
    ValueError
        A reporting clip among ``clips`` (tuning on them would bias the report).
    """
    import itertools

    from .datasets import data_root

    bad = [c for c in clips if c not in TUNING_CLIPS]
    if bad:
        raise ValueError(f"clips: {', '.join(bad)} not of the tuning split "
                         f"({', '.join(TUNING_CLIPS)})")
    g = {**CHAIN_GRID, **(grid or {})}
    combos = list(itertools.product(g["tmedian_radius"], g["atadenoise"],
                                    g["deflicker_size"]))
    base = data_root(root)
    names = check_denoise_clips(base, list(clips))  # a crop larger than a clip: whole
    scores = {c: [] for c in combos}
    done, total = 0, len(names) * len(combos)
    per_clip: dict[tuple[Any, ...], dict[str, float]] = {c: {} for c in combos}
    for name in names:
        clean = protocol_clips(base, frames, (name,))[name]
        if crop is not None:
            clean = np.ascontiguousarray(clean[:, :crop[0], :crop[1]])
        degraded, _ = plant_case(clean, "all", case_seed(name, "all"))
        deshaken = ffmpeg_deshake(degraded)
        for combo in combos:
            out = _chain_rest(deshaken, *combo)
            p = clip_psnr(_centre(out, border), _centre(clean, border))
            scores[combo].append(p)
            per_clip[combo][name] = p
            done += 1
            if callback is not None:
                callback(done, total)
    rows = []
    for combo in combos:
        row = {"tmedian_radius": combo[0], "atadenoise": combo[1],
               "deflicker_size": combo[2], "psnr_centre": float(np.mean(scores[combo]))}
        row.update({f"psnr_centre_{k}": v for k, v in per_clip[combo].items()})
        rows.append(row)
    best = max(rows, key=lambda r: r["psnr_centre"])
    log.info("FFmpeg chain: best %s", best)
    return {k: best[k] for k in ("tmedian_radius", "atadenoise", "deflicker_size",
                                 "psnr_centre")}, rows


def format_chain_tuning(rows: Sequence[dict[str, Any]]) -> str:
    """A Markdown table of :func:`tune_ffmpeg_chain`'s rows, best first."""
    from .bench.common import markdown_table

    if not rows:
        return "(no results)"
    clips = [k[len("psnr_centre_"):] for k in rows[0] if k.startswith("psnr_centre_")]
    body = [[str(r["tmedian_radius"]), f"A {r['atadenoise'][0]:g} B {r['atadenoise'][1]:g}",
             str(r["deflicker_size"])]
            + [_num(r[f"psnr_centre_{c}"], 2) for c in clips] + [_num(r["psnr_centre"], 2)]
            for r in sorted(rows, key=lambda r: -r["psnr_centre"])]
    header = ["tmedian radius", "atadenoise", "deflicker size", *clips, "mean"]
    return ("FFmpeg chain tuning (all case, centre PSNR dB)\n\n"
            + markdown_table(header, body, n_left=3))


# --------------------------------------------------------------------------- benchmark


def _names(value: str | Sequence[str] | None) -> list[str]:
    if value is None:
        return []
    items = value.split(",") if isinstance(value, str) else list(value)
    return list(dict.fromkeys(str(v).strip() for v in items if str(v).strip()))


def check_restore_cases(cases: str | Sequence[str] | None) -> list[str]:
    """Validate case names (None: all of :data:`RESTORE_CASES`), in table order."""
    names = _names(cases) or list(RESTORE_CASES)
    for c in names:
        if c not in RESTORE_CASES:
            raise ValueError(f"cases: unknown case {c!r}; expected some of "
                             f"{', '.join(RESTORE_CASES)}")
    return [c for c in RESTORE_CASES if c in names]


def check_restore_kinds(methods: str | Sequence[str] | None) -> list[str]:
    """Validate method kinds or labels (None: every kind).

    Parameters
    ----------
    methods : str, sequence of str or None
        Kinds of :data:`RESTORE_KINDS` or labels of :data:`CASE_METHODS` (a
        comma-separated string is split).

    Returns
    -------
    list of str

    Raises
    ------
    ValueError
        ``methods: ...`` for an unknown name.
    """
    labels = {label for runs in CASE_METHODS.values() for label, _ in runs}
    names = _names(methods) or list(RESTORE_KINDS)
    for m in names:
        if m not in RESTORE_KINDS and m not in labels:
            raise ValueError(f"methods: unknown method {m!r}; expected kinds "
                             f"{', '.join(RESTORE_KINDS)} or labels {', '.join(sorted(labels))}")
    return names


def _warm_up(cases: Sequence[str]) -> None:
    """Run varflow's stages once on a tiny clip, so that no JIT compilation is timed."""
    from scipy import ndimage

    import varflow

    # a smooth texture moving a pixel a frame: white noise would only make the stages
    # warn about motion and gains they cannot find
    rng = np.random.default_rng(0)
    tex = ndimage.gaussian_filter(rng.random((40, 56, 3)), (2.0, 2.0, 0))
    tex = (tex - tex.min()) / max(float(np.ptp(tex)), 1e-6) * 160 + 40
    tiny = np.stack([tex[:, k:k + 48] for k in range(4)]).astype(np.float32)
    varflow.flow(tiny[0], tiny[1], "tvl1-fast")
    if "dirt" in cases or "all" in cases:
        varflow.remove_dirt(tiny)
    if "flicker" in cases or "all" in cases:
        varflow.deflicker(tiny)
    if "weave" in cases or "all" in cases:
        varflow.stabilise(tiny)
    if "all" in cases:
        varflow.denoise(tiny, NOISE_SIGMA)


def _run_method(label: str, degraded: np.ndarray, chain: dict[str, Any] | None = None
                ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """One run: the output, the dirt mask it returned, the transforms it returned."""
    import varflow

    if label == "remove_dirt":
        out, mask = varflow.remove_dirt(degraded, return_mask=True)
        return out, mask, None
    if label == "deflicker":
        return varflow.deflicker(degraded), None, None
    if label == "stabilise":
        out, transforms = varflow.stabilise(degraded, return_transforms=True)
        return out, None, transforms
    if label == "varflow-chain":
        return varflow_chain(degraded)
    if label == "ffmpeg-chain":
        return ffmpeg_chain(degraded, **(chain or {})), None, None
    peers: dict[str, Callable[[np.ndarray], np.ndarray]] = {
        "tmedian": ffmpeg_tmedian, "ffmpeg-deflicker": ffmpeg_deflicker,
        "deshake": ffmpeg_deshake,
        "flow-median": flow_median, "mean-std": mean_std_match}
    if label in peers:
        return peers[label](degraded), None, None
    raise ValueError(f"method: unknown run {label!r}")  # pragma: no cover


def run_restore_benchmark(
    root: str | Path | None = None,
    clips: str | Sequence[str] | None = None,
    cases: str | Sequence[str] | None = None,
    frames: int = RESTORE_FRAMES,
    methods: str | Sequence[str] | None = None,
    crop: tuple[int, int] | None = None,
    callback: Callable[[int, int], None] | None = None,
    *,
    seed: int = 0,
    warm_up: bool = True,
    chain: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Run varflow's restoration stages and the peers on the film-defect protocol.

    For every clip and case, the clean clip (top-left ``crop``) gets the case's
    defects (:func:`plant_case` with :func:`case_seed`), every method of the case
    (:data:`CASE_METHODS`, filtered by ``methods``) restores it, timed
    (``time.perf_counter``), and the output is scored against the clean clip
    (:func:`score_restoration`); a row for the degraded input comes first.  In the
    weave case every method also runs, untimed, on the clean clip, for
    :func:`weave_agreement` (the input's row: the woven clip against the clean one).

    Parameters
    ----------
    root : str or path, optional
        The data folder (:func:`varflow.evaluation.datasets.data_root`).
    clips : str or sequence of str, optional
        Default all: :data:`TUNING_CLIPS` then :data:`REPORTING_CLIPS`.
    cases : str or sequence of str, optional
        Of :data:`RESTORE_CASES` (default all).
    frames : int
        Frames from each clip's start (at least 3; sintel-demo has 10).
    methods : str or sequence of str, optional
        Kinds (``varflow``, ``ffmpeg``, ``simple``) or labels of
        :data:`CASE_METHODS` (default all).
    crop : (int, int), optional
        Top-left ``(H, W)`` of every frame (quick runs).
    callback : callable, optional
        ``callback(done, total)`` after each run.
    seed : int
        Added to every :func:`case_seed` (default 0: the protocol's defects).
    warm_up : bool
        First run varflow's stages once, untimed, on a tiny clip.
    chain : dict, optional
        ``tmedian_radius``, ``atadenoise``, ``deflicker_size`` of :func:`ffmpeg_chain`
        (default the module's ``CHAIN_*``; e.g. :func:`tune_ffmpeg_chain`'s choice).

    Returns
    -------
    list of dict
        Keys :data:`RESTORE_CSV_FIELDS`: ``clip``, ``split``, ``case``, ``method``,
        ``kind`` (``input``, ``varflow``, ``ffmpeg``, ``simple``), ``seed``, ``frames``,
        ``height``, ``width``, the scores of :func:`score_restoration` (None where
        they do not apply), ``weave_agreement`` (px; weave case only) and
        ``seconds_per_frame`` (None for the input).

    Raises
    ------
    ValueError
        Unknown clip, case or method; ``frames`` < 3; a crop larger than a clip.
    FileNotFoundError
        A clip missing under the data folder (checked before any run).
    """
    from .datasets import data_root

    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 3:
        raise ValueError(f"frames: must be an integer >= 3, got {frames!r}")
    case_list = check_restore_cases(cases)
    wanted = check_restore_kinds(methods)
    base = data_root(root)
    crop = None if crop is None else (int(crop[0]), int(crop[1]))
    names = check_denoise_clips(base, clips, crop)
    runs = {case: [(label, kind) for label, kind in CASE_METHODS[case]
                   if kind in wanted or label in wanted] for case in case_list}
    if warm_up and any(kind in ("varflow", "simple") for r in runs.values() for _, kind in r):
        _warm_up(case_list)
    total = len(names) * sum(len(r) for r in runs.values())
    done = 0
    rows: list[dict[str, Any]] = []
    for name in names:
        clean = protocol_clips(base, frames, (name,))[name]
        if crop is not None:
            clean = np.ascontiguousarray(clean[:, :crop[0], :crop[1]])
        n, h, w = clean.shape[:3]
        for case in case_list:
            s = case_seed(name, case, seed)
            degraded, truth = plant_case(clean, case, s)
            common = {"clip": name, "split": split_of(name), "case": case, "seed": s,
                      "frames": n, "height": h, "width": w}
            found = score_restoration(degraded, clean, case, truth,
                                      transforms=_identity_transforms(n))
            if case == "weave":
                found["weave_agreement"] = weave_agreement(degraded, clean)
            rows.append({**common, "method": "degraded", "kind": "input", **found,
                         "seconds_per_frame": None})
            for label, kind in runs[case]:
                t0 = time.perf_counter()
                out, mask, transforms = _run_method(label, degraded, chain)
                seconds = time.perf_counter() - t0
                sc = score_restoration(out, clean, case, truth, mask, transforms)
                if case == "weave":  # the same stabiliser on the clean clip, untimed
                    sc["weave_agreement"] = weave_agreement(
                        out, _run_method(label, clean, chain)[0])
                rows.append({**common, "method": label, "kind": kind, **sc,
                             "seconds_per_frame": seconds / n})
                log.info("%s %s %s: PSNR %.2f in %.3f s per frame", name, case, label,
                         sc["psnr"], seconds / n)
                done += 1
                if callback is not None:
                    callback(done, total)
    return [{k: r.get(k) for k in RESTORE_CSV_FIELDS} for r in rows]


# --------------------------------------------------------------------------- tables


def _val(row: dict[str, Any] | None, key: str) -> float:
    """A number of a row (also read back from CSV), NaN when absent or empty."""
    v = None if row is None else row.get(key)
    if v is None or v == "":
        return math.nan
    return float(v)


def _num(value: float, digits: int) -> str:
    if math.isinf(value):
        return "inf"
    return f"{value:.{digits}f}" if math.isfinite(value) else "-"


_COLUMNS = (("psnr", "PSNR", 2), ("psnr_centre", "PSNR centre", 2),
            ("psnr_blotched", "PSNR blotched", 2), ("psnr_untouched", "PSNR untouched", 2),
            ("precision", "precision", 3), ("recall", "recall", 3),
            ("residual_flicker", "flicker", 2), ("jitter", "jitter px", 2),
            ("jitter_registered", "jitter reg. px", 2), ("weave_agreement", "agreement px", 2),
            ("seconds_per_frame", "s/frame", 3))


def format_restore_tables(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown tables of :func:`run_restore_benchmark` rows (or rows read back from CSV).

    The first table has a line per clip, case and method: the split, PSNR (dB) over
    all pixels, over the centre (weave and all), over the blotched and the untouched
    pixels (dirt and all), the precision and recall of the returned dirt mask, the
    residual flicker (grey levels), the residual jitter from the returned transforms
    and by registration (px), the weave agreement (px), and seconds per frame; ``-``
    where a score does not apply.  The second has, per case and method, the means over
    the reporting clips of the rows (a note when there are none).

    Parameters
    ----------
    rows : sequence of dict

    Returns
    -------
    str
        The tables separated by a blank line, without a trailing newline.
    """
    from .bench.common import markdown_table

    if not rows:
        return "(no results)"
    header = ["clip", "split", "case", "method"] + [h for _, h, _ in _COLUMNS]
    body = [[str(r["clip"]), str(r["split"]), str(r["case"]), str(r["method"])]
            + [_num(_val(r, k), d) for k, _, d in _COLUMNS] for r in rows]
    parts = ["Per clip, case and method\n\n" + markdown_table(header, body, n_left=4)]
    reporting = [r for r in rows if r.get("split") == "reporting"]
    if not reporting:
        parts.append("Means over the reporting clips: none in this run (tuning clips only)")
        return "\n\n".join(parts)
    clips = list(dict.fromkeys(str(r["clip"]) for r in reporting))
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in reporting:
        groups.setdefault((str(r["case"]), str(r["method"])), []).append(r)
    order = {c: i for i, c in enumerate(RESTORE_CASES)}
    body = []
    for (case, method), group in sorted(groups.items(),
                                        key=lambda kv: order.get(kv[0][0], len(order))):
        cells = [case, method, str(len(group))]
        for key, _, digits in _COLUMNS:
            values = [_val(r, key) for r in group]
            finite = [v for v in values if not math.isnan(v)]
            cells.append(_num(float(np.mean(finite)) if finite else math.nan, digits))
        body.append(cells)
    header = ["case", "method", "clips"] + [h for _, h, _ in _COLUMNS]
    parts.append(f"Means over the reporting clips ({', '.join(clips)})\n\n"
                 + markdown_table(header, body, n_left=2))
    return "\n\n".join(parts)


