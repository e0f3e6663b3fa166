"""Image formation of the photographic clips: rendering, change of light, camera noise.

:func:`render` area-samples the layers of a scene into frames (the way a camera
integrates light over a pixel); :func:`illuminate` and :func:`add_noise` apply the
slow change of light of the ``"illumination"`` family and the camera noise of the
``"noise"`` family.  See :mod:`varflow.generators.photo` for the model.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .photo_scenes import PhotoLayer, sway, sway_eval
from .sequences import _WaveMotion

__all__ = ["add_noise", "illuminate", "render"]


_CHUNK_SAMPLES = 1 << 18  # sub-samples per rendering chunk (bounds memory)


def _wave_inverse_fine(
    motion: _WaveMotion,
    n: int,
    centres: tuple[np.ndarray, np.ndarray],
    off: np.ndarray,
    guess: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """``M_n^{-1}`` at the sub-samples of a block of pixels, to ~1e-5 px.

    Newton's method (float64, to 1e-9 px) at the pixel centres ``centres`` (x, y
    of shape ``(rows, W)``, warm-started by ``guess``); from each centre solution
    ``p_c`` a first-order step to its sub-samples, ``dp = (I + grad s)^{-1} delta``
    (off by ~1e-3 px), then one chord step (Newton with the centre's Jacobian)
    on ``dp``.  That step works in float32 on small quantities: the residual
    ``dp - delta + s(p_c + dp) - s(p_c)`` with the wave phases ``theta(p_c) +
    kappa . dp``, which leaves ~1e-5 px: ample for rendering (the trajectories are
    computed separately, in float64).  Returns the sub-sample positions in the
    layout ``(rows * s, W * s)`` of the renderer and the centre solution.
    """
    cx, cy = centres
    rows, w = cx.shape
    s = off.size
    pcx, pcy = motion.inverse(cx, cy, n, guess)
    _, _, thetas = motion._eval(pcx, pcy, n)
    j = motion._jacobian(thetas)
    det = (1.0 + j[0]) * (1.0 + j[3]) - j[1] * j[2]
    f32 = np.float32
    dyx = off.astype(f32)
    dx = dyx[None, None, None, :]
    dy = dyx[None, :, None, None]

    def pix(v: np.ndarray) -> np.ndarray:  # (rows, W) -> (rows, 1, W, 1)
        return v.astype(f32)[:, None, :, None]

    ja, jb, jc, jd = (1.0 + j[3]) / det, -j[1] / det, -j[2] / det, (1.0 + j[0]) / det
    ia, ib, ic, id_ = pix(ja), pix(jb), pix(jc), pix(jd)
    dpx = ia * dx + ib * dy
    dpy = ic * dx + id_ * dy
    # residual p + s(p) - q = dp - delta + s(p_c + dp) - s(p_c)   (p_c + s(p_c) = centre)
    rx = dpx - dx
    ry = dpy - dy
    sc = np.zeros((2,) + cx.shape)
    for k, theta_c in enumerate(thetas):
        red = theta_c * (1.0 / (2 * np.pi))
        red -= np.rint(red)
        red *= 2 * np.pi
        tc = red.astype(f32)
        kx, ky = motion.kappa[k]
        ex, ey = motion.amp[k] * motion.direction[k]
        sin = np.sin(tc)
        sc[0] += ex * sin
        sc[1] += ey * sin
        # theta(p_c + dp) = theta_c + kappa . dp, and dp is linear in delta
        theta = pix(kx * jb + ky * jd) * dy + pix(tc)
        theta = theta + pix(kx * ja + ky * jc) * dx
        sin = np.sin(theta, out=theta)
        rx += f32(ex) * sin
        ry += f32(ey) * sin
    rx -= pix(sc[0])
    ry -= pix(sc[1])
    # one chord step with the centre Jacobian (its change over half a pixel is ~1e-2)
    dpx -= ia * rx + ib * ry
    dpy -= ic * rx + id_ * ry
    px = (pcx[:, None, :, None] + dpx).reshape(rows * s, w * s)
    py = (pcy[:, None, :, None] + dpy).reshape(rows * s, w * s)
    return px, py, (pcx, pcy)


def _box_mean(acc: np.ndarray, s: int) -> np.ndarray:
    """Mean of the ``s x s`` blocks of ``acc`` (rows * s, W * s, C) (strided sums: fast)."""
    hs, ws, c = acc.shape
    cols = acc.reshape(hs, ws // s, s, c)
    tot = cols[:, :, 0].copy()
    for k in range(1, s):
        tot += cols[:, :, k]
    rows = tot.reshape(hs // s, s, ws // s, c)
    out = rows[:, 0].copy()
    for k in range(1, s):
        out += rows[:, k]
    out *= np.float32(1.0 / (s * s))
    return out


def render(
    layers: Sequence[PhotoLayer],
    shape: tuple[int, int],
    n_frames: int,
    channels: int,
    supersample: int,
) -> np.ndarray:
    """Area-sampled frames ``(F, H, W, C)``: mean of ``s x s`` composited sub-samples per pixel."""
    h, w = shape
    s = supersample
    off = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(w)[:, None] + off).ravel()
    rows = max(1, min(h, _CHUNK_SAMPLES // (w * s * s)))
    frames = np.empty((n_frames, h, w, channels), np.float32)
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        ys = (np.arange(r0, r1)[:, None] + off).ravel()
        cy, cx = np.mgrid[r0:r1, 0:w].astype(np.float64)
        guess: tuple[np.ndarray, np.ndarray] | None = None
        for n in range(n_frames):
            back = layers[0]
            if isinstance(back.motion, _WaveMotion):
                px, py, guess = _wave_inverse_fine(back.motion, n, (cx, cy), off, guess)
                acc = back.texture(px, py)
            else:
                acc = back.texture.sample(back.texture.affine_coords(back.motion, n, xs, ys))
            for layer in layers[1:]:
                x0, x1, y0, y1 = layer.bounds(n)
                i0 = max(0, int(np.floor((y0 - ys[0]) * s)))
                i1 = min(ys.size, int(np.ceil((y1 - ys[0]) * s)) + 1)
                j0 = max(0, int(np.floor((x0 - xs[0]) * s)))
                j1 = min(xs.size, int(np.ceil((x1 - xs[0]) * s)) + 1)
                if i1 <= i0 or j1 <= j0:
                    continue
                ox, oy = layer.motion.inverse(xs[None, j0:j1], ys[i0:i1, None], n)
                cov = layer.covers(ox, oy)
                if cov is None or not cov.any():
                    continue
                vals = layer.texture(ox[cov], oy[cov])
                win = acc[i0:i1, j0:j1]
                win[cov] = vals
            frames[n, r0:r1] = _box_mean(acc, s)[..., :channels]
    return frames


def illuminate(
    rng: np.random.Generator, clean: np.ndarray, times: np.ndarray
) -> tuple[np.ndarray, dict[str, Any]]:
    """Slow global gain and offset and a turning spatial gain gradient (see the notes)."""
    n_frames, h, w, _ = clean.shape
    # log-gain: a ramp of 0.16-0.24 over the clip and a sway of up to +-0.06
    lg1 = rng.uniform(0.08, 0.12) * rng.choice([-1.0, 1.0])
    lg2 = sway(rng, 0.0, 0.03)
    gain = np.exp(2 * lg1 * (times - 0.5) + sway_eval(lg2, times))
    offset = rng.uniform(-0.04, 0.04) * 2 * (times - 0.5) + rng.uniform(-0.02, 0.02)
    half_diag = 0.5 * np.hypot(h, w)
    strength = rng.uniform(0.1, 0.2) / half_diag
    ang = rng.uniform(0, 2 * np.pi) + rng.uniform(0.5, 1.5) * rng.choice([-1, 1]) * times
    gradient = strength * np.stack([np.cos(ang), np.sin(ang)], -1)
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    out = np.empty_like(clean)
    for n in range(n_frames):
        field_n = gain[n] * np.exp(
            gradient[n, 0] * (xx - centre[0]) + gradient[n, 1] * (yy - centre[1])
        )
        out[n] = np.clip(field_n[..., None] * clean[n] + offset[n], 0.0, 1.0)
    info = {
        "model": "clip(gain[n] * exp(gradient[n] . (x - centre)) * I + offset[n], 0, 1)",
        "gain": gain,
        "offset": offset,
        "gradient": gradient,
        "centre": centre,
    }
    return out, info


def add_noise(
    rng: np.random.Generator, clean: np.ndarray, sigma: float
) -> tuple[np.ndarray, dict[str, Any]]:
    """Signal-dependent Gaussian noise ``sigma (0.6 + 0.8 I)`` per sample, clipped."""
    out = np.empty_like(clean)
    for n in range(clean.shape[0]):
        std = np.float32(sigma) * (np.float32(0.6) + np.float32(0.8) * clean[n])
        noise = rng.standard_normal(clean[n].shape, dtype=np.float32)
        out[n] = np.clip(clean[n] + std * noise, 0.0, 1.0)
    info = {"sigma": sigma, "model": "std = sigma * (0.6 + 0.8 * I), clipped to [0, 1]"}
    return out, info
