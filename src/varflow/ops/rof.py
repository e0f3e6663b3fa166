"""ROF denoising and the structure-texture decomposition (Wedel et al. 2009).

The ROF model (Rudin, Osher & Fatemi 1992) with weight θ::

    min_u  TV(u) + 1/(2θ) ||u - f||²

is solved per channel by the accelerated primal-dual algorithm of Chambolle &
Pock (2011, Algorithm 2; the data term is 1/θ-strongly convex).  The structure
part ``S = ROF(I)`` holds the shading; the texture part ``I - α S`` keeps the
edges and fine detail and is far less sensitive to illumination changes, which is
why TV-L1 is run on it (Wedel, Pock, Zach, Bischof & Cremers, "An improved
algorithm for TV-L1 optical flow", 2009: α = 0.95).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .differences import divergence, gradient

__all__ = ["rof_denoise", "rof_denoise_numpy", "structure_texture"]


def _schedule(n_iter: int, theta: float):
    """Step sizes of Chambolle-Pock Algorithm 2: (tau, sigma, relax) per iteration."""
    tau, sigma, gamma = 0.25, 0.5, 1.0 / theta  # tau * sigma * L^2 = 1 with L^2 = 8
    out = []
    for _ in range(n_iter):
        rel = 1.0 / math.sqrt(1.0 + 2.0 * gamma * tau)
        out.append((tau, sigma, rel))
        tau *= rel
        sigma /= rel
    return np.array(out, dtype=np.float32).reshape(n_iter, 3)


def rof_denoise_numpy(f: np.ndarray, theta: float, n_iter: int) -> np.ndarray:
    """Reference NumPy ROF solver for an ``(H, W, C)`` image (channels independent)."""
    f = np.asarray(f, dtype=np.float32)
    out = np.empty_like(f)
    sched = _schedule(n_iter, theta)
    for c in range(f.shape[2]):
        fc = f[..., c]
        u = fc.copy()
        ubar = fc.copy()
        p = np.zeros(fc.shape + (2,), np.float32)
        for tau, sigma, rel in sched:
            p = p + sigma * gradient(ubar)
            p /= np.maximum(1.0, np.sqrt((p * p).sum(-1)))[..., None]
            u_old = u
            u = (u + tau * divergence(p) + (tau / theta) * fc) / (1.0 + tau / theta)
            ubar = u + rel * (u - u_old)
        out[..., c] = u
    return out


@nb.njit(cache=True, parallel=True, fastmath=True)
def _rof_kernel(f, theta, sched, u, ubar, p):
    h, w, k = f.shape
    for it in range(sched.shape[0]):
        tau = sched[it, 0]
        sigma = sched[it, 1]
        rel = sched[it, 2]
        for i in nb.prange(h):
            for j in range(w):
                for c in range(k):
                    gx = ubar[i, j + 1, c] - ubar[i, j, c] if j < w - 1 else 0.0
                    gy = ubar[i + 1, j, c] - ubar[i, j, c] if i < h - 1 else 0.0
                    px = p[i, j, c, 0] + sigma * gx
                    py = p[i, j, c, 1] + sigma * gy
                    nrm = math.sqrt(px * px + py * py)
                    if nrm > 1.0:
                        px /= nrm
                        py /= nrm
                    p[i, j, c, 0] = px
                    p[i, j, c, 1] = py
        a = tau / theta
        for i in nb.prange(h):
            for j in range(w):
                for c in range(k):
                    if j == 0:
                        d = p[i, j, c, 0]
                    elif j == w - 1:
                        d = -p[i, j - 1, c, 0]
                    else:
                        d = p[i, j, c, 0] - p[i, j - 1, c, 0]
                    if i == 0:
                        d += p[i, j, c, 1]
                    elif i == h - 1:
                        d -= p[i - 1, j, c, 1]
                    else:
                        d += p[i, j, c, 1] - p[i - 1, j, c, 1]
                    uo = u[i, j, c]
                    un = (uo + tau * d + a * f[i, j, c]) / (1.0 + a)
                    u[i, j, c] = un
                    ubar[i, j, c] = un + rel * (un - uo)


def rof_denoise(f: np.ndarray, theta: float = 0.125, n_iter: int = 50) -> np.ndarray:
    """ROF-denoise each channel of an image.

    Parameters
    ----------
    f : ndarray, shape (H, W, C), float32
    theta : float
        θ, the weight of the fidelity term ``1/(2θ)||u - f||²``; larger means smoother.
        Units: intensity (images in ``[0, 1]``).
    n_iter : int
        Number of primal-dual iterations.

    Returns
    -------
    ndarray, shape (H, W, C), float32
    """
    if theta <= 0:
        raise ValueError(f"rof theta must be > 0, got {theta}")
    f = np.ascontiguousarray(f, dtype=np.float32)
    u = f.copy()
    ubar = f.copy()
    p = np.zeros(f.shape + (2,), np.float32)
    _rof_kernel(f, np.float32(theta), _schedule(n_iter, theta), u, ubar, p)
    return u


def structure_texture(
    image: np.ndarray, alpha: float = 0.95, theta: float = 0.125, n_iter: int = 50
) -> np.ndarray:
    """Texture part ``I - α ROF(I)`` of an ``(H, W, C)`` image (Wedel et al. 2009).

    Returns
    -------
    ndarray, shape (H, W, C), float32
        Values roughly in ``[-α, 1]``; not rescaled, so intensity differences keep
        their units.
    """
    structure = rof_denoise(image, theta=theta, n_iter=n_iter)
    return (np.asarray(image, np.float32) - np.float32(alpha) * structure).astype(np.float32)
