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

The benchmark (:func:`run_denoise_benchmark`, ``varflow bench denoise``,
``benchmarks/bench_denoise.py``) runs varflow's restoration methods
(:data:`varflow.registry.RESTORE`) beside those peers, FFmpeg's temporal denoisers
through PyAV's filter graph (:func:`ffmpeg_atadenoise`, :func:`ffmpeg_fftdnoiz`)
and the per-frame variant of varflow's method, and scores PSNR, SSIM
(:func:`ssim_clip`), temporal error and seconds per frame
(:func:`format_denoise_tables`).  :func:`run_cli_case` is the 8-bit case: the
``varflow denoise`` command on a lossless video of a noisy clip.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ATADENOISE_A",
    "ATADENOISE_ALGORITHM",
    "ATADENOISE_B",
    "ATADENOISE_FRAMES",
    "DENOISE_CSV_FIELDS",
    "DENOISE_PEERS",
    "ESTIMATED_SUFFIX",
    "FFMPEG_DOWNSCALE",
    "FFTDNOIZ_BLOCK",
    "FFTDNOIZ_POWER",
    "PROTOCOL_FRAMES",
    "PROTOCOL_SIGMAS",
    "REPORTING_CLIPS",
    "TUNING_CLIPS",
    "VBM3D_REFERENCE",
    "add_noise",
    "atadenoise_options",
    "check_denoise_clips",
    "check_denoise_peers",
    "check_restore_methods",
    "clip_psnr",
    "ffmpeg_atadenoise",
    "ffmpeg_fftdnoiz",
    "ffmpeg_filter_clip",
    "fftdnoiz_options",
    "flow_average",
    "format_cli_case",
    "format_denoise_tables",
    "opencv_nlm",
    "protocol_clips",
    "reference_method",
    "run_cli_case",
    "run_denoise_benchmark",
    "split_of",
    "ssim_clip",
    "temporal_error",
    "unavailable_peers",
]

log = logging.getLogger(__name__)

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
        Frames per clip from its start (``frame_0001.png`` on for Sintel alley_1
        final; the 10 of sintel-demo at most).
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
        files = files[:frames]
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



# --------------------------------------------------------------------------- FFmpeg


def _uint8_clip(noisy: np.ndarray) -> np.ndarray:
    """``noisy`` as contiguous uint8 ``(F, H, W, 3)``: other dtypes taken as 0-255,
    rounded and clipped."""
    a = np.asarray(noisy)
    if a.ndim != 4 or a.shape[-1] != 3:
        raise ValueError(f"noisy: expected an RGB clip (F, H, W, 3), got shape {a.shape}")
    if a.dtype != np.uint8:
        a = np.clip(np.rint(np.asarray(a, np.float64)), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(a)


def ffmpeg_filter_clip(frames: np.ndarray, name: str, options: str,
                       pix_fmt: str | None = None) -> np.ndarray:
    """Run an FFmpeg video filter over a clip through PyAV's filter graph.

    The graph is ``buffer (rgb24; rgb48le for uint16 frames) → format=pix_fmt →
    name=options → format=rgb24 (rgb48le) → buffersink``; the frames are pushed in
    order at 25 frames per second and the graph is flushed at the end (temporal
    filters hold frames back): one frame comes out per frame in.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, 3)
        uint8 or uint16 RGB (other dtypes are taken as 0-255, rounded and clipped
        to uint8).
    name : str
        The filter, e.g. ``"atadenoise"``.
    options : str
        Its options in FFmpeg's ``key=value:key=value`` syntax.
    pix_fmt : str, optional
        The planar format the filter runs on; default ``gbrp`` (``gbrp16le`` for
        uint16 frames): planar RGB, to and from which packed RGB converts exactly.

    Returns
    -------
    ndarray, shape (F, H, W, 3)
        uint16 for uint16 frames, else uint8.

    Raises
    ------
    ValueError
        Not an RGB clip, options the filter refuses, or a frame count out of the
        filter other than the count in.
    """

    a = np.asarray(frames)
    deep = a.dtype == np.uint16
    clip = np.ascontiguousarray(a) if deep else _uint8_clip(a)
    if clip.ndim != 4 or clip.shape[-1] != 3:
        raise ValueError(f"frames: expected an RGB clip (F, H, W, 3), got shape {clip.shape}")
    packed = "rgb48le" if deep else "rgb24"
    pix_fmt = pix_fmt or ("gbrp16le" if deep else "gbrp")
    n = clip.shape[0]
    out = _filter_graph(clip, packed, pix_fmt, [(name, options)],
                        f"options: FFmpeg's {name} refuses {options!r}")
    if len(out) != n:
        raise ValueError(f"{name}: {len(out)} frames out of the filter for {n} in")
    return np.stack(out)


def _filter_graph(clip: np.ndarray, packed: str, pix_fmt: str,
                  filters: Sequence[tuple[str, str]], refused: str) -> list[np.ndarray]:
    """The frames out of ``buffer (packed) → format=pix_fmt → filters → format=packed →
    buffersink`` for ``clip`` pushed in order at 25 frames per second, the graph
    flushed at the end; ``refused`` starts the ``ValueError`` of a graph FFmpeg
    refuses."""
    import av

    _, h, w, _ = clip.shape
    base = Fraction(1, 25)
    graph = av.filter.Graph()
    try:
        chain = [graph.add_buffer(width=w, height=h, format=packed, time_base=base),
                 graph.add("format", pix_fmt)]
        chain += [graph.add(name, options) for name, options in filters]
        chain += [graph.add("format", packed), graph.add("buffersink")]
        for up, down in zip(chain, chain[1:], strict=False):
            up.link_to(down)
        graph.configure()
    except (av.FFmpegError, ValueError) as exc:
        raise ValueError(f"{refused}: {exc}") from None
    out: list[np.ndarray] = []

    def drain() -> None:
        while True:
            try:
                frame = graph.pull()
            except (av.BlockingIOError, av.EOFError):
                return
            out.append(frame.to_ndarray(format=packed))

    for i, f in enumerate(clip):
        vf = av.VideoFrame.from_ndarray(f, format=packed)
        vf.pts = i
        vf.time_base = base
        graph.push(vf)
        drain()
    graph.push(None)
    drain()
    return out


#: The FFmpeg peers' 8-bit frames enter their filter as 16-bit planar RGB
#: (``gbrp16le``) holding ``v · 256 / FFMPEG_DOWNSCALE`` for an 8-bit value ``v``:
#: the data use an eighth of the 16-bit range, which stretches the filters' capped
#: thresholds eight times (noise power 64 times) relative to the noise; the output is
#: scaled back and rounded to 8 bits.
FFMPEG_DOWNSCALE = 8

#: atadenoise's threshold A (one frame's difference to the frame filtered, every
#: plane) in multiples of σ: ``0a = 1a = 2a = ATADENOISE_A · σ``.
ATADENOISE_A = 5.0
#: atadenoise's threshold B (the sum of the differences on one side) in multiples of σ.
ATADENOISE_B = 8.0
#: atadenoise's frames averaged (``s``; odd), FFmpeg's default.
ATADENOISE_FRAMES = 9
#: atadenoise's variant (``a``): ``"s"``, serial (each side until its thresholds break).
ATADENOISE_ALGORITHM = "s"
#: fftdnoiz's ``sigma`` (a threshold on the power of its windowed Fourier
#: coefficients, not a standard deviation) in multiples of the noise variance on
#: its input: ``sigma = FFTDNOIZ_POWER · (σ / FFMPEG_DOWNSCALE)²``.
FFTDNOIZ_POWER = 0.7
#: fftdnoiz's block side (pixels), FFmpeg's default.
FFTDNOIZ_BLOCK = 32


def atadenoise_options(sigma: float, a: float = ATADENOISE_A, b: float = ATADENOISE_B,
                       frames: int = ATADENOISE_FRAMES,
                       algorithm: str = ATADENOISE_ALGORITHM) -> str:
    """FFmpeg atadenoise's options for noise of σ (0-255) on :data:`FFMPEG_DOWNSCALE` data.

    The thresholds are fractions of the 16-bit range: ``a · σ / (255 ·
    FFMPEG_DOWNSCALE)`` (A, at most 0.3) and ``b · σ / (255 · FFMPEG_DOWNSCALE)``
    (B, at most 5), the same on the three planes.

    Parameters
    ----------
    sigma : float
        Noise standard deviation on 0-255.
    a, b : float
        Thresholds A and B in multiples of σ.
    frames : int
        Frames averaged (odd, 5-129).
    algorithm : {"s", "p"}
        Serial or parallel.

    Returns
    -------
    str
    """
    scale = float(sigma) / (255.0 * FFMPEG_DOWNSCALE)
    ta, tb = min(0.3, a * scale), min(5.0, b * scale)
    planes = ":".join(f"{p}a={ta:.6g}:{p}b={tb:.6g}" for p in range(3))
    return f"{planes}:s={int(frames)}:a={algorithm}"


def fftdnoiz_options(sigma: float, power: float = FFTDNOIZ_POWER,
                     block: int = FFTDNOIZ_BLOCK) -> str:
    """FFmpeg fftdnoiz's options for noise of σ (0-255) on :data:`FFMPEG_DOWNSCALE` data.

    Temporal mode (``prev=1:next=1``: a 3-frame Fourier transform), Wiener
    shrinkage, ``sigma = power · (σ / FFMPEG_DOWNSCALE)²`` (at most 100, FFmpeg's
    bound), half-overlapping Hann-windowed blocks of ``block`` pixels.

    Parameters
    ----------
    sigma : float
        Noise standard deviation on 0-255.
    power : float
        The threshold in multiples of the noise variance on the filter's input.
    block : int
        Block side, pixels (8-256).

    Returns
    -------
    str
    """
    value = min(100.0, power * (float(sigma) / FFMPEG_DOWNSCALE) ** 2)
    return f"sigma={value:.6g}:block={int(block)}:prev=1:next=1"


def _ffmpeg_peer(noisy: np.ndarray, name: str, options: str) -> np.ndarray:
    """The 8-bit noisy clip through a filter at :data:`FFMPEG_DOWNSCALE`, as float32
    0-255 values rounded to 8 bits."""
    k = 256.0 / FFMPEG_DOWNSCALE
    deep = (_uint8_clip(noisy).astype(np.float64) * k).round().astype(np.uint16)
    out = ffmpeg_filter_clip(deep, name, options)
    return np.clip(np.rint(out / k), 0, 255).astype(np.float32)


def ffmpeg_atadenoise(noisy: np.ndarray, sigma: float, **options: Any) -> np.ndarray:
    """FFmpeg's adaptive temporal averaging denoiser (``atadenoise``) through PyAV.

    Every pixel is the mean of itself and the same pixel in the frames around it,
    taken outwards on each side while each frame's difference stays below threshold
    A and their summed difference below threshold B (Bartovčak & Vrankić); no motion
    compensation.  The noisy clip is rounded and clipped to uint8 first (part of what
    the peer costs), run at :data:`FFMPEG_DOWNSCALE` in ``gbrp16le`` (FFmpeg caps A
    at 0.3 of the range: 76 of 255, below what σ 30 needs on 8-bit data) and rounded
    back to 8 bits.  Parameters (:func:`atadenoise_options`): ``A = 5 σ``, ``B = 8 σ``,
    9 frames, serial, chosen by a grid search on the tuning clips (bikes, carphone;
    σ 10, 30, 50) over A in {2, ..., 8} σ, B in {4, 8, 16, 32} σ, 5, 9 or 15 frames
    and both variants, for the mean PSNR; a few settings tie within 0.05 dB.

    Parameters
    ----------
    noisy : ndarray, shape (F, H, W, 3)
        On 0-255 (uint8 or float).
    sigma : float
        Noise standard deviation on 0-255.
    **options
        ``a``, ``b``, ``frames``, ``algorithm`` of :func:`atadenoise_options`.

    Returns
    -------
    ndarray, shape (F, H, W, 3), float32
        Values on 0-255, integers.
    """
    return _ffmpeg_peer(noisy, "atadenoise", atadenoise_options(sigma, **options))


def ffmpeg_fftdnoiz(noisy: np.ndarray, sigma: float, **options: Any) -> np.ndarray:
    """FFmpeg's 3D Fourier denoiser (``fftdnoiz``) through PyAV, in temporal mode.

    Each block and the same block in the previous and next frames are transformed
    (2D FFT per frame, then over the 3 frames) and shrunk by a Wiener factor
    ``max(0, (P − t) / P)`` of their power P.  fftdnoiz's ``sigma`` option is that
    threshold t, a power (for white noise of σ on 8-bit data about 0.14 σ²), bounded
    by 100, which 8-bit noise of σ above about 20 needs more than: the noisy clip is
    rounded and clipped to uint8 (part of what the peer costs), run at
    :data:`FFMPEG_DOWNSCALE` in ``gbrp16le`` and rounded back to 8 bits.  Parameters
    (:func:`fftdnoiz_options`): ``sigma = 0.7 (σ / 8)²``, blocks of 32 with FFmpeg's
    overlap 0.5 and Hann window, chosen by a grid search on the tuning clips (bikes,
    carphone; σ 10, 30, 50) over the factor 0.125-2, blocks of 16, 32 and 64 and
    hard thresholding, for the mean PSNR.

    Parameters
    ----------
    noisy : ndarray, shape (F, H, W, 3)
        On 0-255 (uint8 or float).
    sigma : float
        Noise standard deviation on 0-255.
    **options
        ``power``, ``block`` of :func:`fftdnoiz_options`.

    Returns
    -------
    ndarray, shape (F, H, W, 3), float32
        Values on 0-255, integers.
    """
    return _ffmpeg_peer(noisy, "fftdnoiz", fftdnoiz_options(sigma, **options))


# --------------------------------------------------------------------------- SSIM


def ssim_clip(denoised: np.ndarray, clean: np.ndarray) -> float:
    """Mean over the frames of the SSIM of ``denoised`` clipped to [0, 255].

    :func:`skimage.metrics.structural_similarity` with its defaults (7 × 7 uniform
    window), ``data_range=255`` and, for colour, ``channel_axis=-1`` (the mean over
    the channels).

    Parameters
    ----------
    denoised, clean : ndarray, shape (F, H, W[, C])
        On 0-255; frames of at least 7 × 7.

    Returns
    -------
    float
        1 for identical clips.

    Raises
    ------
    ValueError
        Shapes that differ.
    ModuleNotFoundError
        scikit-image is missing (``pip install 'varflow[bench]'``).
    """
    try:
        from skimage.metrics import structural_similarity
    except ImportError as exc:
        raise ModuleNotFoundError("ssim_clip: needs scikit-image (pip install "
                                  "'varflow[bench]')") from exc
    d, c = _clip255(denoised), np.asarray(clean, np.float64)
    if d.shape != c.shape:
        raise ValueError(f"denoised: shape {d.shape} differs from clean {c.shape}")
    axis = -1 if d.ndim == 4 else None
    return float(np.mean([structural_similarity(a, b, data_range=255.0, channel_axis=axis)
                          for a, b in zip(d, c, strict=True)]))


# --------------------------------------------------------------------------- benchmark

#: Frames per clip of the protocol (V-BM3D's reference figures are on these).
PROTOCOL_FRAMES = 20

#: The peers of :func:`run_denoise_benchmark`, in table order: OpenCV's multi-frame
#: NL-means, the flow average, FFmpeg's atadenoise and fftdnoiz, and the per-frame
#: variant of the reference varflow method (``radius=0``: no motion).
DENOISE_PEERS: tuple[str, ...] = ("opencv-nlm", "flow-average", "atadenoise", "fftdnoiz",
                                  "per-frame")

#: The leading columns of the benchmark's rows (and CSV).
DENOISE_CSV_FIELDS: tuple[str, ...] = (
    "clip", "split", "sigma", "method", "kind", "sigma_used", "frames", "height", "width",
    "psnr", "ssim", "temporal_error", "seconds_per_frame", "ratio_opencv_nlm",
    "vbm3d_psnr", "vbm3d_temporal_error", "vbm3d_seconds_per_frame",
)

#: The label of the σ-estimated run of the reference method: ``f"{method}{...}"``.
ESTIMATED_SUFFIX = ", σ estimated"


def _names(value: str | Sequence[str] | None) -> list[str]:
    if value is None:
        return []
    items = value.split(",") if isinstance(value, str) else list(value)
    return list(dict.fromkeys(str(v).strip() for v in items if str(v).strip()))


def check_restore_methods(methods: str | Sequence[str] | None) -> list[str]:
    """Validate restoration method names.

    Parameters
    ----------
    methods : str, sequence of str or None
        Names of :data:`varflow.registry.RESTORE` (a comma-separated string is
        split); None: all of them.

    Returns
    -------
    list of str

    Raises
    ------
    ValueError
        ``methods: ...`` for an unknown name.
    """
    from ..registry import RESTORE

    if methods is None:
        return RESTORE.names()
    names = _names(methods)
    for m in names:
        if m not in RESTORE:
            raise ValueError(f"methods: unknown restoration method {m!r}; available: "
                             f"{', '.join(RESTORE.names())}")
    return names


def check_denoise_peers(peers: str | Sequence[str] | None) -> list[str]:
    """Validate peer names.

    Parameters
    ----------
    peers : str, sequence of str or None
        Names of :data:`DENOISE_PEERS`, ``"all"`` or ``"none"`` (a comma-separated
        string is split); None: all.

    Returns
    -------
    list of str
        In :data:`DENOISE_PEERS` order.

    Raises
    ------
    ValueError
        ``peers: ...`` for an unknown name.
    """
    if peers is None:
        return list(DENOISE_PEERS)
    names = _names(peers)
    if names in ([], ["none"]):
        return []
    if names == ["all"]:
        return list(DENOISE_PEERS)
    for p in names:
        if p not in DENOISE_PEERS:
            raise ValueError(f"peers: unknown peer {p!r}; expected some of "
                             f"{', '.join(DENOISE_PEERS)}, all or none")
    return [p for p in DENOISE_PEERS if p in names]


def unavailable_peers(peers: Sequence[str]) -> dict[str, str]:
    """``{peer: reason}`` of the peers whose library is missing (OpenCV)."""
    import importlib.util

    out = {}
    if "opencv-nlm" in peers and importlib.util.find_spec("cv2") is None:
        out["opencv-nlm"] = "OpenCV is not installed (pip install 'varflow[bench]')"
    return out


def reference_method(methods: Sequence[str]) -> str:
    """The varflow method of the per-frame and σ-estimated runs: the default
    restoration method when it is among ``methods`` (or ``methods`` is empty), else
    the first of ``methods``."""
    from ..registry import RESTORE

    return RESTORE.default if not methods or RESTORE.default in methods else methods[0]


def split_of(clip: str) -> str:
    """``"tuning"`` for a clip of :data:`TUNING_CLIPS`, else ``"reporting"``."""
    return "tuning" if clip in TUNING_CLIPS else "reporting"


def _vbm3d(clip: str, sigma: float, protocol: bool) -> dict[str, float | None]:
    """The V-BM3D reference figures of a clip and σ (None where the table has none, and
    for runs on other frames than the protocol's)."""
    ref = VBM3D_REFERENCE.get(clip) if protocol else None
    key = int(sigma) if float(sigma).is_integer() else None
    return {
        "vbm3d_psnr": ref[0].get(key) if ref and key is not None else None,
        "vbm3d_temporal_error": ref[1] if ref and key == 30 else None,
        "vbm3d_seconds_per_frame": ref[2] if ref else None,
    }


def check_denoise_clips(root: str | Path | None, clips: str | Sequence[str] | None = None,
                        crop: tuple[int, int] | None = None) -> list[str]:
    """Check the clips of a run before it starts: known, on disk, larger than ``crop``.

    Reads the first frame of each clip.

    Parameters
    ----------
    root : str or path, optional
        The data folder (:func:`varflow.evaluation.datasets.data_root`).
    clips : str or sequence of str, optional
        Clips of the protocol (a comma-separated string is split); default all,
        :data:`TUNING_CLIPS` then :data:`REPORTING_CLIPS`.
    crop : (int, int), optional
        The top-left ``(H, W)`` the run keeps.

    Returns
    -------
    list of str
        The clips, without repeats.

    Raises
    ------
    ValueError
        ``clips: ...`` for an unknown clip, ``crop: ...`` for a crop below 8 × 8 or
        larger than a clip's frames.
    FileNotFoundError
        A clip has no frames under the data folder (the message says how to point
        to the data).
    """
    from .datasets import DATA_HINT, data_root

    every = (*TUNING_CLIPS, *REPORTING_CLIPS)
    names = list(dict.fromkeys(_names(clips) or every))
    for c in names:
        if c not in every:
            raise ValueError(f"clips: unknown clip {c!r}; expected some of {', '.join(every)}")
    if crop is not None and min(crop) < 8:
        raise ValueError(f"crop: {crop[0]}x{crop[1]} is too small (at least 8x8)")
    base = data_root(root)
    for name in names:
        try:
            first = protocol_clips(base, 1, (name,))[name]
        except FileNotFoundError as exc:
            raise FileNotFoundError(f"no frames of the clip {name} in {exc.filename} (data "
                                    f"root {base}); {DATA_HINT}") from None
        h, w = first.shape[1:3]
        if crop is not None and (crop[0] > h or crop[1] > w):
            raise ValueError(f"crop: {crop[0]}x{crop[1]} (HxW) exceeds the {h}x{w} frames "
                             f"of {name}")
    return names


def _warm_up(methods: Sequence[str], reference: str, peers: Sequence[str],
             estimated: bool) -> None:
    """Run every varflow method once on a tiny clip, so that no JIT compilation is timed."""
    import varflow

    rng = np.random.default_rng(0)
    tiny = (rng.random((3, 32, 32, 3)) * 255).astype(np.float32)
    for m in methods:
        varflow.denoise(tiny, 10.0, m)
    if "per-frame" in peers:
        varflow.denoise(tiny, 10.0, reference, radius=0)
    if estimated:
        varflow.denoise(tiny, None, reference)
    if "flow-average" in peers:
        varflow.flow(tiny[0], tiny[1], "tvl1")


def run_denoise_benchmark(
    root: str | Path | None = None,
    clips: str | Sequence[str] | None = None,
    sigmas: Sequence[float] = (10, 30, 50),
    frames: int = PROTOCOL_FRAMES,
    methods: str | Sequence[str] | None = None,
    peers: str | Sequence[str] | None = None,
    crop: tuple[int, int] | None = None,
    callback: Callable[[int, int], None] | None = None,
    *,
    estimated: bool = True,
    seed: int = 0,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Run varflow's restoration methods and the peers on the denoising protocol.

    For every clip and σ the noise is :func:`add_noise` (drawn on the whole
    frames, then cropped: a crop sees the pixels of the full run), and every
    denoiser gets the noisy float clip and σ: each varflow method of ``methods``
    (:func:`varflow.denoise`), the :func:`reference_method` once more with σ
    estimated (``sigma=None``; ``estimated``), and the ``peers``: ``opencv-nlm``
    (:func:`opencv_nlm`), ``flow-average`` (:func:`flow_average`, radius 2,
    ``tvl1``), ``atadenoise`` (:func:`ffmpeg_atadenoise`), ``fftdnoiz``
    (:func:`ffmpeg_fftdnoiz`) and ``per-frame`` (the reference method with
    ``radius=0``).  Each output is scored against the clean clip (:func:`clip_psnr`,
    :func:`ssim_clip`, :func:`temporal_error`) and each call timed
    (``time.perf_counter``); a row for the noisy input comes first.

    Parameters
    ----------
    root : str or path, optional
        The data folder (:func:`varflow.evaluation.datasets.data_root`).
    clips : str or sequence of str, optional
        Clips of the protocol (default all: :data:`TUNING_CLIPS` then
        :data:`REPORTING_CLIPS`).
    sigmas : sequence of float
        Noise levels on 0-255.
    frames : int
        Frames from the start of each clip (at least 2; sintel-demo has 10).
    methods : str, sequence of str or None
        Restoration methods (None: all of :data:`varflow.registry.RESTORE`; empty:
        peers only).
    peers : str, sequence of str or None
        Of :data:`DENOISE_PEERS`, ``"all"`` or ``"none"`` (None: all).
    crop : (int, int), optional
        Keep the top-left ``(H, W)`` of every frame (quick runs).
    callback : callable, optional
        ``callback(done, total)`` after each run.
    estimated : bool
        Also run the reference method with σ estimated (when ``methods`` is not empty).
    seed : int
        Of the noise (:func:`add_noise`).
    warm_up : bool
        First run every varflow method once, untimed, on a tiny clip.

    Returns
    -------
    list of dict
        Per clip and σ, in clip, σ order: the noisy input, the methods, the
        σ-estimated run, the peers.  Keys :data:`DENOISE_CSV_FIELDS`: ``clip``,
        ``split`` (``"tuning"`` or ``"reporting"``), ``sigma``, ``method``, ``kind``
        (``"input"``, ``"varflow"`` or ``"peer"``), ``sigma_used`` (the σ the
        denoiser was given, or estimated; None for the input and the flow
        average), ``frames``, ``height``, ``width``, ``psnr`` (dB), ``ssim``,
        ``temporal_error`` (0-255), ``seconds_per_frame`` (wall time of the call
        over the frames; None for the input), ``ratio_opencv_nlm`` (that time over
        OpenCV NLM's on the same clip and σ; None without it), and V-BM3D's
        reference ``vbm3d_psnr``, ``vbm3d_temporal_error`` (σ 30 only) and
        ``vbm3d_seconds_per_frame`` (:data:`VBM3D_REFERENCE`; None where it has
        no figure, and unless the run is the protocol's: :data:`PROTOCOL_FRAMES`
        frames, no crop).  The per-frame row carries ``base_method``.

    Raises
    ------
    ValueError
        Unknown clip, method or peer; nothing to run; ``frames`` < 2; no σ or a
        σ <= 0; a crop larger than a clip's frames.
    FileNotFoundError
        A clip is missing under the data folder (checked before any run).
    """
    from .datasets import data_root

    sigma_list = [float(s) for s in sigmas]
    if not sigma_list or not all(math.isfinite(s) and s > 0 for s in sigma_list):
        raise ValueError(f"sigmas: expected positive noise levels, got {list(sigmas)}")
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 2:
        raise ValueError(f"frames: must be an integer >= 2, got {frames!r}")
    method_list = check_restore_methods(methods)
    peer_list = check_denoise_peers(peers)
    if not method_list and not peer_list:
        raise ValueError("methods: give at least one restoration method or peer")
    reference = reference_method(method_list)
    estimated = estimated and bool(method_list)
    base = data_root(root)
    crop = None if crop is None else (int(crop[0]), int(crop[1]))
    names = check_denoise_clips(base, clips, crop)  # before any run
    protocol = crop is None and frames == PROTOCOL_FRAMES
    if warm_up and (method_list or "per-frame" in peer_list or "flow-average" in peer_list):
        _warm_up(method_list, reference, peer_list, estimated)

    runs: list[tuple[str, str]] = [(m, "varflow") for m in method_list]
    if estimated:
        runs.append((reference + ESTIMATED_SUFFIX, "varflow"))
    runs += [(p, "peer") for p in peer_list]
    total = len(names) * len(sigma_list) * len(runs)
    done = 0
    rows: list[dict[str, Any]] = []
    for name in names:
        clean_full = protocol_clips(base, frames, (name,))[name]
        clean = clean_full if crop is None else clean_full[:, :crop[0], :crop[1]]
        for sigma in sigma_list:
            noisy = add_noise(clean_full, sigma, seed)
            noisy = noisy if crop is None else np.ascontiguousarray(noisy[:, :crop[0], :crop[1]])
            common = {"clip": name, "split": split_of(name),
                      "sigma": int(sigma) if sigma.is_integer() else sigma,
                      **_vbm3d(name, sigma, protocol)}
            group = [_score(common, "noisy", "input", noisy, clean, None, None)]
            for label, kind in runs:
                t0 = time.perf_counter()
                out, used = _run_denoiser(label, noisy, sigma, method_list, reference)
                seconds = time.perf_counter() - t0
                r = _score(common, label, kind, out, clean, used, seconds)
                if label == "per-frame":
                    r["base_method"] = reference
                group.append(r)
                done += 1
                if callback is not None:
                    callback(done, total)
            nlm = next((r for r in group if r["method"] == "opencv-nlm"), None)
            if nlm is not None and nlm["seconds_per_frame"]:
                for r in group:
                    if r["seconds_per_frame"] is not None:
                        r["ratio_opencv_nlm"] = r["seconds_per_frame"] / nlm["seconds_per_frame"]
            rows += group
    return rows


def _run_denoiser(label: str, noisy: np.ndarray, sigma: float, methods: Sequence[str],
                  reference: str) -> tuple[np.ndarray, float | None]:
    """One run of :func:`run_denoise_benchmark`: the output and the σ it used."""
    import varflow

    if label in methods:
        return varflow.denoise(noisy, sigma, label), sigma
    if label == "opencv-nlm":
        return opencv_nlm(noisy, sigma), sigma
    if label == "flow-average":
        return flow_average(noisy, radius=2, method="tvl1"), None
    if label == "atadenoise":
        return ffmpeg_atadenoise(noisy, sigma), sigma
    if label == "fftdnoiz":
        return ffmpeg_fftdnoiz(noisy, sigma), sigma
    if label == "per-frame":
        return varflow.denoise(noisy, sigma, reference, radius=0), sigma
    if label == reference + ESTIMATED_SUFFIX:
        stats: dict[str, Any] = {}
        out = varflow.denoise(noisy, None, reference, stats=stats)
        return out, stats.get("sigma")
    raise ValueError(f"method: unknown run {label!r}")  # pragma: no cover


def _score(common: dict[str, Any], label: str, kind: str, out: np.ndarray,
           clean: np.ndarray, sigma_used: float | None,
           seconds: float | None) -> dict[str, Any]:
    """A row of :func:`run_denoise_benchmark` (``ratio_opencv_nlm`` filled later)."""
    n, h, w = clean.shape[:3]
    r = {**common, "method": label, "kind": kind, "sigma_used": sigma_used,
         "frames": n, "height": h, "width": w, "psnr": clip_psnr(out, clean),
         "ssim": ssim_clip(out, clean), "temporal_error": temporal_error(out, clean),
         "seconds_per_frame": None if seconds is None else seconds / n,
         "ratio_opencv_nlm": None}
    log.info("%s sigma %g %s: PSNR %.2f SSIM %.4f temporal error %.2f%s", common["clip"],
             common["sigma"], label, r["psnr"], r["ssim"], r["temporal_error"],
             "" if seconds is None else f" in {seconds / n:.3f} s per frame")
    return {k: r.get(k, common.get(k)) for k in DENOISE_CSV_FIELDS}


# --------------------------------------------------------------------------- tables


def _val(row: dict[str, Any] | None, key: str) -> float:
    """A number of a row (also read back from CSV), NaN when absent or empty."""
    v = None if row is None else row.get(key)
    if v is None or v == "":
        return math.nan
    return float(v)


def _num(value: float, digits: int) -> str:
    return f"{value:.{digits}f}" if math.isfinite(value) else "-"


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


_COLUMNS = (("psnr", "PSNR", 2), ("ssim", "SSIM", 4), ("temporal_error", "temp. err", 2),
            ("seconds_per_frame", "s/frame", 3), ("ratio_opencv_nlm", "x NLM", 2),
            ("vbm3d_psnr", "V-BM3D PSNR", 2))


def format_denoise_tables(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown tables of :func:`run_denoise_benchmark` rows (or rows read back from its CSV).

    The first table has a line per clip, σ and method: the clip's split (tuning or
    reporting), σ, the method, the σ it used (the estimate for the σ-estimated run),
    PSNR (dB), SSIM, temporal error (0-255), seconds per frame, the ratio of that
    time to OpenCV NLM's on the same clip and σ, and V-BM3D's PSNR (reference, on
    the protocol's frames only).  The second has, per σ and method, the means of
    the same columns over the reporting clips of the rows (a note when there are
    none).

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
    header = ["clip", "split", "σ", "method", "σ used"] + [h for _, h, _ in _COLUMNS]
    body = [[str(r["clip"]), str(r["split"]), _num(_val(r, "sigma"), 0), str(r["method"]),
             _num(_val(r, "sigma_used"), 2)] + [_num(_val(r, k), d) for k, _, d in _COLUMNS]
            for r in rows]
    parts = ["Per clip, σ and method\n\n" + markdown_table(header, body, n_left=4)]
    reporting = [r for r in rows if r.get("split") == "reporting"]
    clips = list(dict.fromkeys(str(r["clip"]) for r in reporting))
    if not reporting:
        parts.append("Means over the reporting clips: none in this run (tuning clips only)")
        return "\n\n".join(parts)
    groups: dict[tuple[float, str], list[dict[str, Any]]] = {}
    for r in reporting:
        groups.setdefault((_val(r, "sigma"), str(r["method"])), []).append(r)
    body = []
    for (sigma, method), group in sorted(groups.items(), key=lambda kv: kv[0][0]):
        cells = [_num(sigma, 0), method, str(len(group))]
        for key, _, digits in _COLUMNS:
            values = [_val(r, key) for r in group]
            whole = key != "vbm3d_psnr" or all(math.isfinite(v) for v in values)
            cells.append(_num(_mean(values) if whole else math.nan, digits))
        body.append(cells)
    header = ["σ", "method", "clips"] + [h for _, h, _ in _COLUMNS]
    parts.append(f"Means over the reporting clips ({', '.join(clips)})\n\n"
                 + markdown_table(header, body, n_left=2))
    return "\n\n".join(parts)


# --------------------------------------------------------------------------- the CLI


def run_cli_case(root: str | Path | None = None, clip: str = "carphone", sigma: float = 20,
                 frames: int = PROTOCOL_FRAMES, crop: tuple[int, int] | None = None,
                 method: str | None = None, seed: int = 0,
                 timeout: float | None = None) -> dict[str, Any]:
    """The 8-bit case: ``varflow denoise`` on a lossless video of a noisy clip.

    The clean clip (:func:`protocol_clips`, top-left ``crop``) plus the protocol's
    noise (:func:`add_noise`, drawn on the whole frames), rounded and clipped to
    uint8, is written to an FFV1 ``.mkv`` (lossless RGB,
    :func:`varflow.io.video_writer.write_video`) in a temporary folder;
    ``python -m varflow.cli denoise IN -o OUT.mkv --sigma S
    [--method M]`` runs in a subprocess (of this interpreter, with this varflow
    first on ``PYTHONPATH``), and its output is read back and scored against the
    clean frames.

    Parameters
    ----------
    root : str or path, optional
        The data folder.
    clip : str
        A clip of the protocol.
    sigma : float
        Noise standard deviation on 0-255, also given to the command.
    frames : int
        Frames from the clip's start (at least 2).
    crop : (int, int), optional
        Top-left ``(H, W)``.
    method : str, optional
        ``--method``; default the command's.
    seed : int
        Of the noise.
    timeout : float, optional
        Seconds before the command is stopped.

    Returns
    -------
    dict
        ``clip``, ``sigma``, ``method`` (None: the command's default), ``frames``,
        ``height``, ``width``; ``noisy_psnr``, ``noisy_ssim``, ``noisy_temporal_error``
        of the 8-bit noisy input; ``psnr``, ``ssim``, ``temporal_error`` of the
        command's output; ``seconds_per_frame`` (the command's wall time over the
        frames: start-up, decoding and encoding included) and ``command``.

    Raises
    ------
    ValueError
        An unknown clip, ``frames`` < 2, a crop larger than the frames.
    FileNotFoundError
        The clip is not under the data folder.
    RuntimeError
        The command failed (its last line of stderr in the message; for a varflow
        without the command: ``varflow denoise CLI not present``), or its output
        does not have the input's frames.
    """
    import os
    import subprocess
    import sys
    import tempfile

    import varflow

    from ..io.video_reader import VideoReader
    from ..io.video_writer import write_video
    from .datasets import data_root

    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 2:
        raise ValueError(f"frames: must be an integer >= 2, got {frames!r}")
    crop = None if crop is None else (int(crop[0]), int(crop[1]))
    check_denoise_clips(root, (clip,), crop)
    clean_full = protocol_clips(data_root(root), frames, (clip,))[clip]
    noisy = _uint8_clip(add_noise(clean_full, sigma, seed))
    clean = clean_full
    if crop is not None:
        noisy = np.ascontiguousarray(noisy[:, :crop[0], :crop[1]])
        clean = clean_full[:, :crop[0], :crop[1]]
    n, h, w = clean.shape[:3]
    env = dict(os.environ)
    src = str(Path(varflow.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH")) if p)
    with tempfile.TemporaryDirectory(prefix="varflow-denoise-") as tmp:
        src_video, out_video = Path(tmp) / "noisy.mkv", Path(tmp) / "denoised.mkv"
        write_video(src_video, noisy, 25.0, codec="ffv1")
        command = [sys.executable, "-m", "varflow.cli", "denoise", str(src_video), "-o",
                   str(out_video), "--sigma", f"{sigma:g}"]
        if method is not None:
            command += ["--method", method]
        t0 = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, env=env,
                              timeout=timeout, check=False)
        seconds = time.perf_counter() - t0
        if done.returncode != 0:
            err = done.stderr.strip().splitlines()
            last = err[-1] if err else f"exit status {done.returncode}"
            if "invalid choice: 'denoise'" in done.stderr:
                last = "varflow denoise CLI not present"
            raise RuntimeError(f"varflow denoise: {last}")
        with VideoReader(out_video) as video:
            out = video.read_range(0, None)
    if out.shape != clean.shape:
        raise RuntimeError(f"varflow denoise: output of shape {out.shape}, expected "
                           f"{clean.shape}")
    shown = ["varflow", "denoise", "IN.mkv", "-o", "OUT.mkv", *command[7:]]
    return {"clip": clip, "sigma": sigma, "method": method, "frames": n, "height": h,
            "width": w, "noisy_psnr": clip_psnr(noisy, clean),
            "noisy_ssim": ssim_clip(noisy, clean),
            "noisy_temporal_error": temporal_error(noisy, clean),
            "psnr": clip_psnr(out, clean), "ssim": ssim_clip(out, clean),
            "temporal_error": temporal_error(out, clean), "seconds_per_frame": seconds / n,
            "command": " ".join(shown)}


def format_cli_case(row: dict[str, Any]) -> str:
    """A titled Markdown table of a :func:`run_cli_case` result (the 8-bit input and
    the command's output)."""
    from .bench.common import markdown_table

    title = (f"8-bit case: {row['clip']} {row['width']}x{row['height']}, {row['frames']} "
             f"frames, noise σ {row['sigma']:g} rounded and clipped to uint8, FFV1 .mkv in and "
             f"out; `{row['command']}` (s/frame: the whole command, start-up included)")
    body = [["noisy (uint8)", _num(row["noisy_psnr"], 2), _num(row["noisy_ssim"], 4),
             _num(row["noisy_temporal_error"], 2), "-"],
            [row["method"] or "varflow denoise", _num(row["psnr"], 2), _num(row["ssim"], 4),
             _num(row["temporal_error"], 2), _num(row["seconds_per_frame"], 3)]]
    return title + "\n\n" + markdown_table(["output", "PSNR", "SSIM", "temp. err", "s/frame"],
                                            body)
