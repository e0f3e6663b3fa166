"""Synthetic image pairs with exact ground-truth motion, generated in code.

The texture is an analytic function ``T(x, y)`` (a seeded sum of oriented cosine
gratings with a 1/f amplitude spectrum plus soft blobs, passed through ``tanh``),
so it can be sampled at any real-valued position.  A second frame is rendered as
``I1(y) = T(M^{-1}(y))`` for a known invertible motion ``M``, which makes the flow
``w(x) = M(x) - x`` exact: no interpolation error enters the ground truth.

For smooth non-rigid motion the backward displacement ``s`` is given, and the
forward flow solves ``w(x) = s(x + w(x))``, computed by fixed-point iteration to
float precision (``s`` is a contraction by construction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["TextureField", "procedural_texture", "synthetic_pair", "MOTIONS"]

MOTIONS = ("translation", "affine", "smooth", "zero")


@dataclass
class TextureField:
    """An analytic colour texture ``T(x, y) -> (..., C)`` in [0, 1].

    Parameters
    ----------
    channels : int
        Number of channels C.
    seed : int
        Seed of the local random generator.
    n_waves : int
        Number of cosine gratings per channel.
    """

    channels: int = 3
    seed: int = 0
    n_waves: int = 48

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        n = self.n_waves
        freq = np.exp(rng.uniform(np.log(0.015), np.log(0.35), n))  # cycles / pixel
        ang = rng.uniform(0, np.pi, n)
        self._kx = (2 * np.pi * freq * np.cos(ang)).astype(np.float64)
        self._ky = (2 * np.pi * freq * np.sin(ang)).astype(np.float64)
        self._phase = rng.uniform(0, 2 * np.pi, n)
        amp = 1.0 / np.sqrt(freq / 0.015)
        self._mix = rng.normal(size=(n, self.channels)) * amp[:, None]
        self._mix /= np.sqrt((self._mix**2).sum(0, keepdims=True) / 2.0)
        nb = 12
        self._bc = rng.uniform(0, 1, (nb, 2))
        self._br = rng.uniform(0.05, 0.2, nb)
        self._bw = rng.normal(size=(nb, self.channels)) * 0.8

    def __call__(self, x: np.ndarray, y: np.ndarray, scale: float = 256.0) -> np.ndarray:
        """Evaluate at real-valued positions (pixels).

        Parameters
        ----------
        x, y : ndarray, same shape S
        scale : float
            Size (pixels) over which blob positions are spread.

        Returns
        -------
        ndarray, shape S + (C,), float32 in [0, 1]
        """
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        acc = np.zeros(x.shape + (self.channels,), np.float64)
        for k in range(self._kx.size):
            wave = np.cos(self._kx[k] * x + self._ky[k] * y + self._phase[k])
            acc += wave[..., None] * self._mix[k]
        for b in range(self._br.size):
            cx, cy = self._bc[b] * scale
            r2 = ((x - cx) ** 2 + (y - cy) ** 2) / (self._br[b] * scale) ** 2
            acc += np.exp(-r2)[..., None] * self._bw[b]
        return (0.5 + 0.5 * np.tanh(0.6 * acc)).astype(np.float32)


def procedural_texture(shape: tuple[int, int], channels: int = 3, seed: int = 0) -> np.ndarray:
    """A textured ``(H, W, C)`` float32 image in [0, 1] (see :class:`TextureField`)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    return TextureField(channels, seed)(xx, yy, scale=max(h, w))


def _smooth_field(shape: tuple[int, int], seed: int, magnitude: float):
    """A smooth displacement function ``s(x, y) -> (..., 2)`` of amplitude ``magnitude``.

    Four sinusoids per component with wavelengths of at least 2/3 of the image
    size, so that ``|∇s|`` stays well below 1 for the magnitudes used here.
    """
    rng = np.random.default_rng(seed + 1000)
    base = 2 * np.pi / max(shape) * 1.5
    k = rng.uniform(-1, 1, (2, 4, 2)) * base
    phase = rng.uniform(0, 2 * np.pi, (2, 4))

    def s(x, y):
        out = np.zeros(np.shape(x) + (2,))
        for c in range(2):
            for n in range(4):
                out[..., c] += np.sin(k[c, n, 0] * x + k[c, n, 1] * y + phase[c, n])
        return out * (magnitude / 4.0)

    return s


def synthetic_pair(
    motion: str = "affine",
    shape: tuple[int, int] = (128, 160),
    magnitude: float = 2.0,
    channels: int = 3,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two frames of a procedural texture and the exact flow between them.

    Parameters
    ----------
    motion : {"translation", "affine", "smooth", "zero"}
        ``translation``: constant sub-pixel shift of length ``magnitude``;
        ``affine``: rotation + zoom + shift with displacements up to about
        ``magnitude`` pixels; ``smooth``: non-rigid sinusoidal field of amplitude
        ``magnitude``; ``zero``: identical frames.
    shape : (int, int)
        ``(H, W)``.
    magnitude : float
        Motion size in pixels.
    channels : int
        1 for grey, 3 for colour.
    seed : int

    Returns
    -------
    frame0, frame1 : ndarray, shape (H, W, C), float32 in [0, 1]
    flow : ndarray, shape (H, W, 2), float32
        Exact flow from frame0 to frame1.
    """
    if motion not in MOTIONS:
        raise ValueError(f"motion: expected one of {MOTIONS}, got {motion!r}")
    h, w = shape
    tex = TextureField(channels, seed)
    scale = max(h, w)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    frame0 = tex(xx, yy, scale)
    if motion == "zero":
        return frame0, frame0.copy(), np.zeros((h, w, 2), np.float32)
    if motion == "translation":
        rng = np.random.default_rng(seed)
        ang = rng.uniform(0, 2 * np.pi)
        d = magnitude * np.array([np.cos(ang), np.sin(ang)])
        frame1 = tex(xx - d[0], yy - d[1], scale)
        flow = np.broadcast_to(d, (h, w, 2)).astype(np.float32)
        return frame0, frame1, flow
    if motion == "affine":
        rng = np.random.default_rng(seed)
        cx, cy = (w - 1) / 2, (h - 1) / 2
        r = max(h, w) / 2
        rot = rng.uniform(-1, 1) * 0.5 * magnitude / r
        zoom = 1 + rng.uniform(-1, 1) * 0.3 * magnitude / r
        shift = rng.uniform(-1, 1, 2) * 0.4 * magnitude
        a = zoom * np.array([[np.cos(rot), -np.sin(rot)], [np.sin(rot), np.cos(rot)]])
        # M(p) = a (p - c) + c + shift ; render I1(q) = T(M^-1(q))
        ainv = np.linalg.inv(a)
        qx, qy = xx - cx - shift[0], yy - cy - shift[1]
        px = ainv[0, 0] * qx + ainv[0, 1] * qy + cx
        py = ainv[1, 0] * qx + ainv[1, 1] * qy + cy
        frame1 = tex(px, py, scale)
        mx = a[0, 0] * (xx - cx) + a[0, 1] * (yy - cy) + cx + shift[0]
        my = a[1, 0] * (xx - cx) + a[1, 1] * (yy - cy) + cy + shift[1]
        flow = np.stack([mx - xx, my - yy], -1).astype(np.float32)
        return frame0, frame1, flow
    # smooth: I1(q) = T(q - s(q)); forward flow w solves w(x) = s(x + w(x))
    s = _smooth_field(shape, seed, magnitude)
    disp = s(xx, yy)
    frame1 = tex(xx - disp[..., 0], yy - disp[..., 1], scale)
    wf = np.zeros((h, w, 2))
    for _ in range(200):
        new = s(xx + wf[..., 0], yy + wf[..., 1])
        if np.max(np.abs(new - wf)) < 1e-10:
            wf = new
            break
        wf = new
    return frame0, frame1, wf.astype(np.float32)
