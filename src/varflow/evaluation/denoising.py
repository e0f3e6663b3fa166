"""The video-denoising protocol, its scores and the peers a user already has.

The protocol (Arias & Morel 2018, Tassone et al. 2020): additive white Gaussian noise
of standard deviation σ on 0-255 float RGB, not clipped, σ given to the method; the
output clipped to [0, 255]; PSNR per frame averaged over the clip, then over clips.
Here the noise is one draw of ``numpy.random.default_rng(seed).normal(0, σ, shape)``
for the whole ``(F, H, W, 3)`` stack (:func:`add_noise`), the clips are the first 20
frames of each restoration clip (:func:`protocol_clips`), and beside PSNR the
*temporal error* (:func:`temporal_error`) measures the flicker a denoiser adds.

The peers (:func:`opencv_nlm`, :func:`flow_average`) are what a user reaches for
without a dedicated denoiser: OpenCV's multi-frame non-local means and the simple
use of varflow, its neighbours warped onto each frame and averaged where the flows
agree.  V-BM3D cannot run here; its figures on the same noise and frames are
:data:`VBM3D_REFERENCE`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = [
    "PROTOCOL_SIGMAS",
    "REPORTING_CLIPS",
    "TUNING_CLIPS",
    "VBM3D_REFERENCE",
    "add_noise",
    "clip_psnr",
    "flow_average",
    "opencv_nlm",
    "protocol_clips",
    "temporal_error",
]

#: The noise levels of the protocol, on 0-255.
PROTOCOL_SIGMAS = (10, 20, 30, 40, 50)
#: Clips on which defaults are chosen.
TUNING_CLIPS = ("bikes", "carphone")
#: Clips on which results are reported (never used to choose a default).
REPORTING_CLIPS = ("bigbuckbunny", "sintel-demo", "alley_1")
#: V-BM3D (VapourSynth ``bm3d``, radius 3, basic + final, opponent colour) on the
#: protocol's noise and frames, from the benchmark data's README (2 cores):
#: ``{clip: ({σ: PSNR} for σ 10, 30, 50, temporal error at σ 30, s per frame)}``.
VBM3D_REFERENCE: dict[str, tuple[dict[int, float], float, float]] = {
    "bikes": ({10: 44.46, 30: 38.45, 50: 35.43}, 3.63, 0.25),
    "bigbuckbunny": ({10: 39.50, 30: 32.89, 50: 29.52}, 5.82, 0.94),
    "carphone": ({10: 38.15, 30: 32.41, 50: 29.44}, 6.94, 0.03),
    "sintel-demo": ({10: 38.06, 30: 32.05, 50: 29.41}, 8.40, 0.52),
    "alley_1": ({10: 41.18, 30: 34.54, 50: 31.54}, 6.05, 0.79),
}


def protocol_clips(root: str | Path, frames: int = 20,
                   names: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The clean clips of the protocol, ``(F, H, W, 3)`` float32 on 0-255.

    Parameters
    ----------
    root : str or path
        The benchmark data folder (:func:`varflow.evaluation.datasets.data_root`).
    frames : int
        Frames per clip from its start (frames 1.. of Sintel alley_1 final; the
        10 of sintel-demo at most).
    names : tuple of str, optional
        Which clips (default all, tuning then reporting).

    Returns
    -------
    dict
        ``{name: clip}``.

    Raises
    ------
    FileNotFoundError
        If a clip's folder holds no frames.
    """
    from ..io import read_image

    base = Path(root)
    where = {name: base / "restoration" / name
             for name in ("bikes", "bigbuckbunny", "carphone", "sintel-demo")}
    where["alley_1"] = base / "sintel" / "training" / "final" / "alley_1"
    out = {}
    for name in names or (*TUNING_CLIPS, *REPORTING_CLIPS):
        files = sorted(where[name].glob("*.png"))
        files = files[1:frames + 1] if name == "alley_1" else files[:frames]
        if not files:
            raise FileNotFoundError(2, "no frames of the clip", str(where[name]))
        out[name] = np.stack([read_image(f) for f in files]).astype(np.float32)
    return out


def add_noise(clean: np.ndarray, sigma: float, seed: int = 0) -> np.ndarray:
    """The protocol's noisy clip: ``clean + default_rng(seed).normal(0, σ, shape)``.

    Parameters
    ----------
    clean : ndarray, shape (F, H, W, C)
        On 0-255.
    sigma : float
        Standard deviation, 0-255 units.
    seed : int

    Returns
    -------
    ndarray, float32, not clipped
    """
    c = np.asarray(clean, np.float32)
    return c + np.random.default_rng(seed).normal(0, sigma, c.shape).astype(np.float32)


def _clip255(a: np.ndarray) -> np.ndarray:
    return np.clip(np.asarray(a, np.float64), 0.0, 255.0)


def clip_psnr(denoised: np.ndarray, clean: np.ndarray) -> float:
    """Mean over the frames of the PSNR of ``denoised`` clipped to [0, 255], in dB.

    Parameters
    ----------
    denoised, clean : ndarray, shape (F, H, W[, C])
        On 0-255.

    Returns
    -------
    float
    """
    d, c = _clip255(denoised), np.asarray(clean, np.float64)
    if d.shape != c.shape:
        raise ValueError(f"denoised: shape {d.shape} differs from clean {c.shape}")
    mse = ((d - c) ** 2).reshape(d.shape[0], -1).mean(axis=1)
    return float(np.mean([math.inf if m == 0 else 10 * math.log10(255.0**2 / m)
                          for m in mse]))


def temporal_error(denoised: np.ndarray, clean: np.ndarray) -> float:
    """RMS over the clip of ``(D_t − D_{t−1}) − (C_t − C_{t−1})``: the flicker added.

    ``D`` is ``denoised`` clipped to [0, 255], ``C`` the clean clip; 0 for a
    denoiser whose error does not change from frame to frame.

    Parameters
    ----------
    denoised, clean : ndarray, shape (F, H, W[, C]), F >= 2
        On 0-255.

    Returns
    -------
    float
    """
    d, c = _clip255(denoised), np.asarray(clean, np.float64)
    if d.shape != c.shape or d.shape[0] < 2:
        raise ValueError(f"denoised: need matching clips of 2 frames or more, got "
                         f"{d.shape} and {c.shape}")
    return float(np.sqrt(np.mean((np.diff(d, axis=0) - np.diff(c, axis=0)) ** 2)))


def opencv_nlm(noisy: np.ndarray, sigma: float, window: int = 5,
               h_factor: float = 0.5) -> np.ndarray:
    """OpenCV's multi-frame non-local means, ``fastNlMeansDenoisingColoredMulti``.

    Every frame is denoised with the ``window`` frames around it (mirrored at the
    clip's ends: OpenCV needs the frame in the middle), ``h = hColor = h_factor · σ``,
    7 × 7 patches searched in 21 × 21 windows (OpenCV's defaults).  OpenCV takes uint8 frames: the
    noisy clip is rounded and clipped first (part of what the peer costs).

    Parameters
    ----------
    noisy : ndarray, shape (F, H, W, 3)
        On 0-255.
    sigma : float
    window : int
        Odd, at most F.
    h_factor : float
        0.5: the best on the bikes clip at σ 30 (the issue's measurement).

    Returns
    -------
    ndarray, shape (F, H, W, 3), float32
    """
    import cv2

    n = noisy.shape[0]
    window = min(window, n if n % 2 else n - 1)
    frames = [np.ascontiguousarray(np.clip(np.rint(f), 0, 255).astype(np.uint8)[..., ::-1])
              for f in noisy]  # BGR
    h = float(h_factor * sigma)
    out = np.empty(noisy.shape, np.float32)
    r = window // 2
    for t in range(n):  # OpenCV wants the window centred: mirrored at the clip's ends
        idx = [abs(k) if k < n else 2 * (n - 1) - k for k in range(t - r, t + r + 1)]
        res = cv2.fastNlMeansDenoisingColoredMulti([frames[k] for k in idx], r, window, None,
                                                   h, h, 7, 21)
        out[t] = res[..., ::-1]
    return out


def flow_average(noisy: np.ndarray, radius: int = 2, method: str = "tvl1",
                 flow: Callable[..., np.ndarray] | None = None) -> np.ndarray:
    """The simple use of varflow: neighbours warped onto each frame, averaged.

    For every frame t, each frame s with ``0 < |s − t| <= radius`` is warped onto
    it by ``varflow.flow(noisy[t], noisy[s])``, and kept where
    :func:`varflow.consistency` confirms the flow with the backward one; the
    output is the mean of the frame and its kept neighbours per pixel.

    Parameters
    ----------
    noisy : ndarray, shape (F, H, W[, C])
        On 0-255.
    radius : int
    method : str
        The two-frame method.
    flow : callable, optional
        ``flow(frame0, frame1)`` instead of ``varflow.flow(..., method)``.

    Returns
    -------
    ndarray, shape of ``noisy``, float32
    """
    import varflow

    est = flow or (lambda a, b: varflow.flow(a, b, method))
    clip = np.asarray(noisy, np.float32)
    n = clip.shape[0]
    flows: dict[tuple[int, int], np.ndarray] = {}

    def get(t: int, s: int) -> np.ndarray:
        if (t, s) not in flows:
            flows[(t, s)] = est(clip[t], clip[s])
        return flows[(t, s)]

    planes = clip if clip.ndim == 4 else clip[..., None]  # (F, H, W, C)
    out = np.empty_like(planes)
    for t in range(n):
        total = planes[t].astype(np.float64)
        count = np.ones(planes.shape[1:3])
        for s in range(max(0, t - radius), min(n, t + radius + 1)):
            if s == t:
                continue
            fw = get(t, s)
            warped = varflow.warp(planes[s], fw)
            ok = varflow.consistency(fw, get(s, t)) & np.all(np.isfinite(warped), axis=-1)
            total[ok] += warped[ok]
            count += ok
        out[t] = total / count[..., None]
        for key in [k for k in flows if min(k) < t + 1 - radius]:  # keep the window only
            del flows[key]
    out = out if clip.ndim == 4 else out[..., 0]
    return out
