"""The noise level of a clip, from the high frequencies of its flattest blocks.

Additive noise that is white in space puts the same variance σ² into every
coefficient of an orthonormal block DCT, while the picture puts its energy into the
low frequencies.  So, per channel (after Ponomarenko et al. 2007 and Colom & Buades
2013):

1. every 8 × 8 block of every frame (stride 4) is transformed by the orthonormal 2-D
   DCT;
2. its *texture* is the energy of its lowest non-constant frequencies (``1 <= k + l <=
   3``), its *noise sample* the squares of its highest ones (``k + l >= 7``, 36 of 64);
3. the blocks are sorted by texture and the flattest :data:`FLAT_FRACTION` of them
   kept: there the high frequencies hold the noise alone;
4. every kept block's σ² is the mean of its 36 noise samples, and σ² the median of
   those over the blocks divided by the median of χ²₃₆ / 36 (0.9815): the median
   shrugs off the few flat blocks that still hold an edge, and where σ grows with
   the intensity it is the σ of the median block's intensity.

The texture and the noise samples of a block are independent for white noise (other
coefficients), so choosing blocks by texture does not bias σ.  The *noise curve*
repeats steps 3-4 within bins of the blocks' mean intensity, for noise that grows
with the signal (photon noise, film grain).  Blocks holding a clipped value
(0 or the largest value of an integer dtype) are left out: clipping shrinks the
noise there, and so, for integer frames, are the blocks whose mean lies within
:data:`CLIP_MARGIN` σ of those ends (only the draws that missed the clip survive
there).  σ is in the units of the input's values: 0-255 for uint8 and for
float frames on that scale, 0-1 for frames in [0, 1]; nothing is rescaled.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["FLAT_FRACTION", "NoiseEstimate", "estimate_noise"]

log = logging.getLogger(__name__)

#: Side of the DCT blocks, pixels.
BLOCK = 8
#: Step between blocks, pixels.
STRIDE = 4
#: Share of the blocks, the flattest, whose high frequencies give σ.
FLAT_FRACTION = 0.05
#: The fewest blocks σ is taken from (more than ``FLAT_FRACTION`` on small clips).
MIN_BLOCKS = 64
#: Integer frames: blocks whose mean is within this many σ of 0 or of the dtype's
#: largest value are left out (a second pass), as clipping there shrinks the noise.
CLIP_MARGIN = 3.0
#: Median of χ²₃₆ / 36, the mean of a block's 36 high-frequency squares over σ².
_CHI2_MEDIAN = 0.9815436898771362  # scipy.stats.chi2.median(36) / 36


def _dct_matrix(n: int) -> np.ndarray:
    """The orthonormal DCT-II matrix ``D`` (``D @ x`` transforms a column ``x``)."""
    k = np.arange(n)[:, None]
    i = np.arange(n)[None, :]
    d = np.sqrt(2.0 / n) * np.cos(np.pi * (2 * i + 1) * k / (2 * n))
    d[0] /= np.sqrt(2.0)
    return d


_D = _dct_matrix(BLOCK)
_ORDER = np.add.outer(np.arange(BLOCK), np.arange(BLOCK))
_LOW = (_ORDER >= 1) & (_ORDER <= 3)
_HIGH = _ORDER >= 7


@dataclass(frozen=True)
class NoiseEstimate:
    """The noise level of a clip.

    Attributes
    ----------
    sigma : ndarray, shape (C,), float64
        Standard deviation of the noise per channel, in the units of the input's
        values.
    intensity : ndarray, shape (B, C), float64
        Median intensity of the blocks each point of the noise curve was taken from
        (input units); the bins split the blocks by intensity into equal shares.
    curve : ndarray, shape (B, C), float64
        σ within each bin: the noise as a function of the intensity (flat for
        additive noise).
    blocks : int
        Blocks σ was taken from, per channel.
    """

    sigma: np.ndarray
    intensity: np.ndarray
    curve: np.ndarray
    blocks: int

    def __repr__(self) -> str:
        return (f"NoiseEstimate(sigma={np.array2string(self.sigma, precision=4)}, "
                f"bins={self.curve.shape[0]}, blocks={self.blocks})")


def _frames(frames: object) -> tuple[list[np.ndarray], bool, float | None]:
    """``frames`` as a list of (H, W, C) arrays; whether they are integers; their top."""
    if isinstance(frames, np.ndarray):
        arr = frames
        if arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] in (1, 3, 4)):
            seq: Sequence[np.ndarray] = [arr]  # one image
        elif arr.ndim in (3, 4):  # (F, H, W) grey or (F, H, W, C)
            seq = list(arr)
        else:
            raise ValueError(f"frames: expected (H, W[, C]) or (F, H, W[, C]), got {arr.shape}")
    else:
        try:
            seq = [np.asarray(f) for f in frames]  # type: ignore[union-attr]
        except TypeError:
            raise ValueError("frames: expected an array or a sequence of images") from None
    if not seq:
        raise ValueError("frames: no frames")
    out = []
    for k, f in enumerate(seq):
        a = np.asarray(f)
        if a.ndim == 2:
            a = a[:, :, None]
        if a.ndim != 3:
            raise ValueError(f"frame {k}: expected (H, W) or (H, W, C), got {a.shape}")
        if a.dtype.kind not in "uif":
            raise ValueError(f"frame {k}: unsupported dtype {a.dtype}")
        if a.shape[0] < BLOCK or a.shape[1] < BLOCK:
            raise ValueError(f"frame {k}: {a.shape[1]}x{a.shape[0]} is smaller than one "
                             f"{BLOCK}x{BLOCK} block")
        if out and a.shape[2] != out[0].shape[2]:
            raise ValueError(f"frame {k}: {a.shape[2]} channels, frame 0 has "
                             f"{out[0].shape[2]}")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            raise ValueError(f"frame {k}: contains NaN or infinite values")
        out.append(a)
    integer = out[0].dtype.kind in "ui"
    top = float(np.iinfo(out[0].dtype).max) if integer else None
    return out, integer, top


def _block_stats(plane: np.ndarray, integer: bool, top: float | None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per block of one channel: texture, the 36 high-frequency squares, the mean."""
    p = plane.astype(np.float64)
    win = np.lib.stride_tricks.sliding_window_view(p, (BLOCK, BLOCK))[::STRIDE, ::STRIDE]
    blocks = win.reshape(-1, BLOCK, BLOCK)
    if integer:
        wq = np.lib.stride_tricks.sliding_window_view(plane, (BLOCK, BLOCK))[::STRIDE, ::STRIDE]
        wq = wq.reshape(-1, BLOCK * BLOCK)
        keep = (wq.min(axis=1) > 0) & (wq.max(axis=1) < top)
        blocks = blocks[keep]
    coef = np.einsum("ki,bij,lj->bkl", _D, blocks, _D, optimize=True)
    texture = np.square(coef[:, _LOW]).sum(axis=1)
    high = np.square(coef[:, _HIGH])
    mean = coef[:, 0, 0] / BLOCK
    return texture, high, mean


def _sigma(texture: np.ndarray, high: np.ndarray) -> tuple[float, np.ndarray]:
    """σ from the flattest blocks (steps 3-4 of the module notes) and their indices;
    NaN without blocks."""
    n = texture.shape[0]
    if n == 0:
        return float("nan"), np.zeros(0, np.intp)
    k = min(n, max(MIN_BLOCKS, int(round(FLAT_FRACTION * n))))
    flat = np.argpartition(texture, k - 1)[:k] if k < n else np.arange(n)
    per_block = high[flat].mean(axis=1)  # each block's own estimate of σ²
    return float(np.sqrt(np.median(per_block) / _CHI2_MEDIAN)), flat


def estimate_noise(frames: object, bins: int = 8) -> NoiseEstimate:
    """Estimate the standard deviation of white noise in a clip, per channel.

    Parameters
    ----------
    frames : ndarray or sequence of ndarray
        One image ``(H, W)`` / ``(H, W, C)`` with C in 1, 3, 4, a clip
        ``(F, H, W, C)`` or ``(F, H, W)`` (grey; an array of three dimensions is a
        colour image when its last axis is 1, 3 or 4 long), or a sequence of images
        of one channel count; uint8, uint16 or float, finite.  The noise is taken as
        the same in every frame.
    bins : int
        Intensity bins of the noise curve (>= 1).  Default 8: enough to show noise
        that grows with the signal, each bin still holding thousands of blocks on a
        few frames.

    Returns
    -------
    NoiseEstimate
        ``sigma`` per channel in the units of the input's values (0-255 for uint8,
        what the float values are otherwise), and the noise curve.

    Raises
    ------
    ValueError
        On bad shapes, dtypes, non-finite values, frames smaller than a block, or a
        non-positive ``bins``.

    Notes
    -----
    Accurate when some part of the picture is flat at the scale of 8 pixels (sky,
    walls, skin, out-of-focus background): on a clip that is texture everywhere
    the texture adds to σ.  Noise that is correlated in space (compressed video,
    resampled frames) has less energy in the high frequencies and is
    underestimated.

    References
    ----------
    N. Ponomarenko et al., "An automatic approach to lossy compression of AVIRIS
    images", IGARSS 2007.  M. Colom, A. Buades, "Analysis and extension of the
    Ponomarenko et al. method, estimating a noise curve from a single image",
    IPOL 3 (2013).
    """
    if isinstance(bins, bool) or not isinstance(bins, int | np.integer) or bins < 1:
        raise ValueError(f"bins: must be an integer >= 1, got {bins!r}")
    seq, integer, top = _frames(frames)
    n_ch = seq[0].shape[2]
    sigma = np.empty(n_ch)
    intensity = np.full((bins, n_ch), np.nan)
    curve = np.full((bins, n_ch), np.nan)
    used = 0
    for c in range(n_ch):
        stats = [_block_stats(f[:, :, c], integer, top) for f in seq]
        texture = np.concatenate([s[0] for s in stats])
        high = np.concatenate([s[1] for s in stats])
        mean = np.concatenate([s[2] for s in stats])
        sigma[c], flat = _sigma(texture, high)
        if integer and np.isfinite(sigma[c]):
            # blocks near the ends keep only their draws that missed the clip: smaller
            margin = CLIP_MARGIN * sigma[c]
            inner = np.flatnonzero((mean > margin) & (mean < top - margin))
            if inner.size >= MIN_BLOCKS:
                texture, high, mean = texture[inner], high[inner], mean[inner]
                sigma[c], flat = _sigma(texture, high)
        used = flat.size
        if texture.size:
            edges = np.quantile(mean, np.linspace(0.0, 1.0, bins + 1))
            which = np.clip(np.searchsorted(edges, mean, side="right") - 1, 0, bins - 1)
            for b in range(bins):
                sel = np.flatnonzero(which == b)
                if sel.size:
                    curve[b, c], flat = _sigma(texture[sel], high[sel])
                    intensity[b, c] = float(np.median(mean[sel[flat]]))  # as σ is taken
    log.info("noise: sigma %s from %d blocks per channel", np.round(sigma, 4), used)
    return NoiseEstimate(sigma=sigma, intensity=intensity, curve=curve, blocks=used)
