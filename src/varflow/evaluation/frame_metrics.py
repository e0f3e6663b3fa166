"""Error measures of an interpolated frame against the true in-between frame.

All measures compare frames on the **0-255 scale**: ``uint8`` frames are taken as
they are, ``uint16`` frames are multiplied by 255 / 65535, and floating-point frames
are taken to lie in [0, 1] and multiplied by 255 (they are not clipped).  The two
frames may have different dtypes (e.g. a float estimate against a uint8 ground
truth) but must have one shape, ``(H, W)`` (grey, one channel) or ``(H, W, C)``.
The arithmetic is float64.

:func:`psnr`
    Peak signal-to-noise ratio, data range 255, over all pixels and channels.
:func:`ssim`
    Structural similarity (Wang et al. 2004) with a Gaussian window, the mean over
    the channels, as :func:`skimage.metrics.structural_similarity`.
:func:`interpolation_error`
    Baker et al.'s IE: the RMS over pixels of the L2 colour difference.
:func:`normalized_interpolation_error`
    Baker et al.'s NE: IE with every pixel's squared difference divided by
    ``|∇I_GT|² + 1``.
:func:`mean_absolute_error`
    The mean absolute difference, which learned interpolation methods quote as
    "IE" on Middlebury.
:func:`frame_scores`
    All five in one dictionary.

References
----------
Baker, Scharstein, Lewis, Roth, Black & Szeliski (2011), "A Database and Evaluation
Methodology for Optical Flow", IJCV 92(1), pp. 1-31, section 4.1 (interpolation
error and normalised interpolation error).

Wang, Bovik, Sheikh & Simoncelli (2004), "Image quality assessment: from error
visibility to structural similarity", IEEE TIP 13(4), pp. 600-612.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "DATA_RANGE",
    "NE_EPSILON",
    "frame_scores",
    "interpolation_error",
    "mean_absolute_error",
    "normalized_interpolation_error",
    "psnr",
    "ssim",
    "to_255",
]

#: The data range of every measure (frames on the 0-255 scale).
DATA_RANGE = 255.0

#: Baker et al.'s ε in the denominator of NE: ``|∇I_GT|² + ε``.
NE_EPSILON = 1.0


def to_255(frame: np.ndarray, name: str = "frame") -> np.ndarray:
    """A frame on the 0-255 scale as float64, shape (H, W, C).

    Parameters
    ----------
    frame : ndarray, shape (H, W) or (H, W, C)
        ``uint8`` (taken as is), ``uint16`` (times 255 / 65535) or float in [0, 1]
        (times 255, not clipped).
    name : str
        For error messages.

    Returns
    -------
    ndarray, shape (H, W, C), float64
        A grey frame gets one channel.

    Raises
    ------
    ValueError
        Another dtype or number of dimensions.
    """
    a = np.asarray(frame)
    if a.ndim not in (2, 3):
        raise ValueError(f"{name}: expected shape (H, W) or (H, W, C), got {a.shape}")
    if a.dtype == np.uint8:
        out = a.astype(np.float64)
    elif a.dtype == np.uint16:
        out = a.astype(np.float64) * (DATA_RANGE / 65535.0)
    elif np.issubdtype(a.dtype, np.floating):
        out = a.astype(np.float64) * DATA_RANGE
    else:
        raise ValueError(f"{name}: unsupported dtype {a.dtype} (uint8, uint16 or float)")
    return out if out.ndim == 3 else out[..., None]


def _pair(est: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e, g = to_255(est, "est"), to_255(gt, "gt")
    if e.shape != g.shape:
        raise ValueError(f"est: shape {np.shape(est)} differs from gt {np.shape(gt)}")
    return e, g


def psnr(est: np.ndarray, gt: np.ndarray) -> float:
    """Peak signal-to-noise ratio in dB, data range 255.

    ``10 log10(255² / MSE)`` with the mean squared difference over all pixels and
    channels (RGB PSNR, as frame-interpolation papers report it).

    Parameters
    ----------
    est, gt : ndarray, shape (H, W) or (H, W, C)
        See the module notes for the units.

    Returns
    -------
    float
        ``inf`` for identical frames.
    """
    e, g = _pair(est, gt)
    mse = float(np.mean((e - g) ** 2))
    if mse == 0.0:
        return math.inf
    return 10.0 * math.log10(DATA_RANGE**2 / mse)


def _gaussian_filter(plane: np.ndarray, sigma: float, truncate: float) -> np.ndarray:
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(plane, sigma=sigma, truncate=truncate, mode="reflect")


def ssim(est: np.ndarray, gt: np.ndarray, *, sigma: float = 1.5, truncate: float = 3.5,
         k1: float = 0.01, k2: float = 0.03) -> float:
    """Structural similarity (Wang et al. 2004), Gaussian window, mean over channels.

    Per channel the local means, variances and covariance are Gaussian-weighted
    (σ = 1.5 truncated at 3.5 σ: an 11 × 11 window; reflected borders), the
    population (not sample) covariance is used, ``C1 = (K1·255)²`` and
    ``C2 = (K2·255)²``, and the SSIM map is averaged over the pixels at least the
    window radius (5) away from the border; the result is the mean over the
    channels.  This is :func:`skimage.metrics.structural_similarity` with
    ``gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
    data_range=255, channel_axis=-1``.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W) or (H, W, C)
        See the module notes for the units; each side at least 11.
    sigma, truncate : float
        Of the Gaussian window.
    k1, k2 : float
        The stabilising constants ``K1``, ``K2``.

    Returns
    -------
    float
        1 for identical frames.

    Raises
    ------
    ValueError
        Frames smaller than the window.
    """
    e, g = _pair(est, gt)
    radius = int(truncate * sigma + 0.5)
    if min(e.shape[:2]) < 2 * radius + 1:
        raise ValueError(f"est: frames of {e.shape[1]}x{e.shape[0]} are smaller than the "
                         f"{2 * radius + 1}x{2 * radius + 1} SSIM window")
    c1 = (k1 * DATA_RANGE) ** 2
    c2 = (k2 * DATA_RANGE) ** 2
    inner = (slice(radius, e.shape[0] - radius), slice(radius, e.shape[1] - radius))
    means = []
    for c in range(e.shape[2]):
        x, y = e[..., c], g[..., c]
        mx = _gaussian_filter(x, sigma, truncate)
        my = _gaussian_filter(y, sigma, truncate)
        vx = _gaussian_filter(x * x, sigma, truncate) - mx * mx
        vy = _gaussian_filter(y * y, sigma, truncate) - my * my
        cxy = _gaussian_filter(x * y, sigma, truncate) - mx * my
        s = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
        means.append(float(s[inner].mean()))
    return float(np.mean(means))


def interpolation_error(est: np.ndarray, gt: np.ndarray) -> float:
    """Baker et al.'s interpolation error IE (0-255 units).

    ``IE = sqrt(1/N Σ_x ‖I(x) − I_GT(x)‖²)``: the RMS over the N pixels of the L2
    norm of the colour difference (Baker et al. 2011, eq. 3).  For one channel it
    is the RMS difference; for C channels it is ``sqrt(C)`` times the per-value RMS.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W) or (H, W, C)

    Returns
    -------
    float
    """
    e, g = _pair(est, gt)
    return float(np.sqrt(np.mean(np.sum((e - g) ** 2, axis=2))))


def gradient_magnitude_sq(frame: np.ndarray) -> np.ndarray:
    """``|∇I|²`` of NE: per channel central differences, summed over the channels.

    Each channel's ``∂I/∂x`` and ``∂I/∂y`` are central differences
    ``(I(x+1) − I(x−1)) / 2`` (one-sided differences at the border, as
    :func:`numpy.gradient`); ``|∇I|² = Σ_c (∂I_c/∂x)² + (∂I_c/∂y)²``.

    Parameters
    ----------
    frame : ndarray, shape (H, W) or (H, W, C)
        See the module notes for the units.

    Returns
    -------
    ndarray, shape (H, W), float64
    """
    f = to_255(frame, "gt")
    gy, gx = np.gradient(f, axis=(0, 1))
    return np.sum(gx * gx + gy * gy, axis=2)


def normalized_interpolation_error(est: np.ndarray, gt: np.ndarray,
                                   epsilon: float = NE_EPSILON) -> float:
    """Baker et al.'s normalised interpolation error NE.

    ``NE = sqrt(1/N Σ_x ‖I(x) − I_GT(x)‖² / (|∇I_GT(x)|² + ε))`` with ε = 1
    (Baker et al. 2011, eq. 4): differences at edges and in texture, where a small
    misalignment gives a large error, count less.  For colour frames, as Baker et
    al. do, the numerator is the squared L2 norm of the RGB difference and the
    gradient is taken per colour band: here ``|∇I_GT|²`` is the sum over the
    channels of the squared central differences in x and y (see
    :func:`gradient_magnitude_sq`), on the 0-255 scale.  On a flat ground truth NE
    equals IE.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W) or (H, W, C)
    epsilon : float
        ε of the denominator (Baker et al.: 1.0).

    Returns
    -------
    float
    """
    e, g = _pair(est, gt)
    num = np.sum((e - g) ** 2, axis=2)
    return float(np.sqrt(np.mean(num / (gradient_magnitude_sq(gt) + epsilon))))


def mean_absolute_error(est: np.ndarray, gt: np.ndarray) -> float:
    """The mean absolute difference over all pixels and channels (0-255 units).

    What learned frame-interpolation methods (e.g. Super SloMo, DAIN) report as
    "IE" on the Middlebury interpolation set; it is not Baker et al.'s IE
    (:func:`interpolation_error`).

    Parameters
    ----------
    est, gt : ndarray, shape (H, W) or (H, W, C)

    Returns
    -------
    float
    """
    e, g = _pair(est, gt)
    return float(np.mean(np.abs(e - g)))


def frame_scores(est: np.ndarray, gt: np.ndarray) -> dict[str, float]:
    """All the measures of this module.

    Parameters
    ----------
    est, gt : ndarray, shape (H, W) or (H, W, C)

    Returns
    -------
    dict
        ``psnr`` (dB), ``ssim``, ``ie``, ``ne``, ``mae`` (0-255 units).
    """
    return {
        "psnr": psnr(est, gt),
        "ssim": ssim(est, gt),
        "ie": interpolation_error(est, gt),
        "ne": normalized_interpolation_error(est, gt),
        "mae": mean_absolute_error(est, gt),
    }
