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

from .._jit import FASTMATH
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


_F1 = np.float32(1.0)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def _rof_kernel(f, theta, sched, u, ubar, px, py):
    """Chambolle-Pock iterations on planar ``(C, H, W)`` arrays, in place.

    Rows are processed through 1-D views with plain loop indices so that the
    loops vectorise; the divergence treats the last column/row as in
    :func:`varflow.ops.differences.divergence` (``px[:, -1]`` and ``py[-1]`` are
    kept at zero, so a uniform backward difference is exact).
    """
    k, h, w = f.shape
    for it in range(sched.shape[0]):
        tau = sched[it, 0]
        sigma = sched[it, 1]
        rel = sched[it, 2]
        a = tau / theta
        inv = _F1 / (_F1 + a)
        # phase 0 the dual step, phase 1 the primal step (one parallel loop, one
        # gufunc to compile; the phases are separated by the loop's barrier)
        for phase in range(2):
            for r in nb.prange(k * h):
                c = r // h
                i = r - c * h
                if phase == 0:
                    ub = ubar[c, i]
                    ubn = ubar[c, min(i + 1, h - 1)]
                    cy = sigma if i < h - 1 else np.float32(0.0)
                    pxr = px[c, i]
                    pyr = py[c, i]
                    ub1 = ub[1:]
                    for j in range(w - 1):
                        qx = pxr[j] + sigma * (ub1[j] - ub[j])
                        qy = pyr[j] + cy * (ubn[j] - ub[j])
                        s = _F1 / max(_F1, math.sqrt(qx * qx + qy * qy))
                        pxr[j] = qx * s
                        pyr[j] = qy * s
                    qy = pyr[w - 1] + cy * (ubn[w - 1] - ub[w - 1])
                    pyr[w - 1] = qy / max(_F1, abs(qy))
                else:
                    pxr = px[c, i]
                    pyc = py[c, i]
                    pym = py[c, max(i - 1, 0)]
                    cm = _F1 if i > 0 else np.float32(0.0)
                    ur = u[c, i]
                    ubr = ubar[c, i]
                    fr = f[c, i]
                    # j = 0: no left neighbour
                    d = pxr[0] + pyc[0] - cm * pym[0]
                    uo = ur[0]
                    un = (uo + tau * d + a * fr[0]) * inv
                    ur[0] = un
                    ubr[0] = un + rel * (un - uo)
                    pxl = pxr[: w - 1]
                    pxc = pxr[1:]
                    pyc1 = pyc[1:]
                    pym1 = pym[1:]
                    ur1 = ur[1:]
                    ubr1 = ubr[1:]
                    fr1 = fr[1:]
                    for jj in range(w - 1):
                        d = pxc[jj] - pxl[jj] + pyc1[jj] - cm * pym1[jj]
                        uo = ur1[jj]
                        un = (uo + tau * d + a * fr1[jj]) * inv
                        ur1[jj] = un
                        ubr1[jj] = un + rel * (un - uo)


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
    fp = np.ascontiguousarray(np.moveaxis(np.asarray(f, np.float32), -1, 0))
    u = fp.copy()
    ubar = fp.copy()
    px = np.zeros_like(fp)
    py = np.zeros_like(fp)
    _rof_kernel(fp, np.float32(theta), _schedule(n_iter, theta), u, ubar, px, py)
    return np.ascontiguousarray(np.moveaxis(u, 0, -1))


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
