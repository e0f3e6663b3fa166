"""Sharpness matching of two frames: blur the sharper one until both are equally sharp.

Brightness constancy assumes that the two frames see the scene through the same
optics.  When one frame is blurred and the other is not (motion blur in one frame,
a focus change, a different exposure time), every textured point violates it, in a
structured way, and the flow is biased wherever texture is.  Blurring the sharper
frame by a Gaussian until both have the same *sharpness* restores the constancy
for Gaussian blur (and approximately for other symmetric blurs); a pair whose
sharpness already agrees is left untouched.

Sharpness is measured as the mean squared image gradient over the variance of the
intensities, ``S = mean |∇I|² / var(I)`` (channels averaged): blur lowers the
gradient energy but hardly the variance, and a brightness gain or offset changes
neither the ratio nor the decision.  The Gaussian's σ is found by bisection so
that ``S(G_σ * I_sharp) = S(I_blurred)``.

Function
--------
* :func:`sharpness` — ``S`` of one image.
* :func:`match_sharpness` — the two frames, the sharper blurred when
  ``|log(S1/S0)|`` exceeds :data:`SHARPNESS_TOLERANCE`.
"""

from __future__ import annotations

import math

import numpy as np

from .differences import image_derivatives
from .pyramid import smooth_image

__all__ = ["SHARPNESS_TOLERANCE", "sharpness", "match_sharpness"]

#: |log(S1/S0)| at or below which the pair is left alone (dimensionless).  Default 0.15:
#: well above the values of pairs seen through the same optics (clean, noisy or relit)
#: and well below those of pairs with one frame blurred; see benchmarks/HISTORY.md.
SHARPNESS_TOLERANCE = 0.15

_MAX_SIGMA = 6.0
_BISECTIONS = 12


def sharpness(image: np.ndarray) -> float:
    """``mean |∇I|² / var(I)`` of an ``(H, W, C)`` float image (channels averaged).

    The gradient is that of :func:`varflow.ops.differences.image_derivatives`, in
    1/pixel² units once divided by the variance.  A constant image has sharpness 0.
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[..., None]
    dx, dy = image_derivatives(img)
    var = float(img.reshape(-1, img.shape[2]).var(axis=0).mean())
    if var <= 1e-12:
        return 0.0
    return float((dx * dx + dy * dy).mean()) / var


def match_sharpness(frame0: np.ndarray, frame1: np.ndarray,
                    tolerance: float = SHARPNESS_TOLERANCE
                    ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Blur the sharper of two frames until their sharpness agrees.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W, C), float32
    tolerance : float
        Leave the pair alone when ``|log(S1/S0)| <= tolerance``.

    Returns
    -------
    frame0, frame1 : ndarray, shape (H, W, C), float32
        The inputs, one of them blurred (the other is returned as is).
    sigma0, sigma1 : float
        σ of the Gaussian applied to each frame, pixels (0 for the untouched one;
        both 0 when the pair was left alone, or when either frame is flat).
    """
    s0, s1 = sharpness(frame0), sharpness(frame1)
    if s0 <= 0 or s1 <= 0 or abs(math.log(s1 / s0)) <= tolerance:
        return frame0, frame1, 0.0, 0.0
    sharp, target = (frame1, s0) if s1 > s0 else (frame0, s1)
    lo, hi = 0.0, _MAX_SIGMA
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if sharpness(smooth_image(sharp, mid)) > target:
            lo = mid
        else:
            hi = mid
    sigma = 0.5 * (lo + hi)
    if s1 > s0:
        return frame0, smooth_image(frame1, sigma), 0.0, sigma
    return smooth_image(frame0, sigma), frame1, sigma, 0.0
