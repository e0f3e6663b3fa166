"""Discrete gradient and divergence (an adjoint pair) and image derivatives.

Conventions (Chambolle 2004): the gradient uses forward differences with Neumann
boundary (the difference across the last column/row is zero); the divergence uses
backward differences and is defined so that ``<grad u, p> = -<u, div p>`` holds
exactly for every ``u`` and ``p``.

Arrays: a scalar field ``u`` has shape ``(H, W)``; a vector field ``p`` has shape
``(H, W, 2)`` with ``p[..., 0]`` the x (column) and ``p[..., 1]`` the y (row)
component.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .._jit import FASTMATH

__all__ = ["gradient", "divergence", "image_derivatives", "derivative_planes",
           "derivative_planes_numpy"]


def gradient(u: np.ndarray) -> np.ndarray:
    """Forward-difference gradient with Neumann boundary.

    Parameters
    ----------
    u : ndarray, shape (H, W)

    Returns
    -------
    ndarray, shape (H, W, 2)
        ``[..., 0] = u[i, j+1] - u[i, j]`` (zero in the last column),
        ``[..., 1] = u[i+1, j] - u[i, j]`` (zero in the last row).
    """
    u = np.asarray(u)
    g = np.zeros(u.shape + (2,), dtype=np.result_type(u.dtype, np.float32))
    g[:, :-1, 0] = u[:, 1:] - u[:, :-1]
    g[:-1, :, 1] = u[1:, :] - u[:-1, :]
    return g


def divergence(p: np.ndarray) -> np.ndarray:
    """Backward-difference divergence, the negative adjoint of :func:`gradient`.

    Parameters
    ----------
    p : ndarray, shape (H, W, 2)

    Returns
    -------
    ndarray, shape (H, W)
    """
    p = np.asarray(p)
    px, py = p[..., 0], p[..., 1]
    d = np.zeros(p.shape[:2], dtype=np.result_type(p.dtype, np.float32))
    d[:, 0] = px[:, 0]
    d[:, 1:-1] = px[:, 1:-1] - px[:, :-2]
    d[:, -1] = -px[:, -2]
    d[0, :] += py[0, :]
    d[1:-1, :] += py[1:-1, :] - py[:-2, :]
    d[-1, :] -= py[-2, :]
    return d


def image_derivatives(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spatial derivatives of an image with the 5-point stencil ``[1, -8, 0, 8, -1] / 12``.

    The stencil is the one used by Wedel et al. (2009) for the data term; borders are
    handled by replicating edge pixels.

    Parameters
    ----------
    image : ndarray, shape (H, W, C), float32

    Returns
    -------
    (ndarray, ndarray)
        ``dI/dx`` and ``dI/dy``, both ``(H, W, C)`` float32.
    """
    img = np.asarray(image, dtype=np.float32)
    pad = np.pad(img, ((2, 2), (2, 2), (0, 0)), mode="edge")
    c = np.float32(1.0 / 12.0)
    dx = (pad[2:-2, :-4] - 8 * pad[2:-2, 1:-3] + 8 * pad[2:-2, 3:-1] - pad[2:-2, 4:]) * c
    dy = (pad[:-4, 2:-2] - 8 * pad[1:-3, 2:-2] + 8 * pad[3:-1, 2:-2] - pad[4:, 2:-2]) * c
    return np.ascontiguousarray(dx, dtype=np.float32), np.ascontiguousarray(dy, dtype=np.float32)


def derivative_planes_numpy(image: np.ndarray) -> np.ndarray:
    """Reference NumPy implementation of :func:`derivative_planes`."""
    img = np.asarray(image, dtype=np.float32)
    return np.concatenate([img, *image_derivatives(img)], axis=2)


@nb.njit(cache=True, inline="always")
def stencil5_indices(i, n):
    """Indices ``i-2, i-1, i+1, i+2`` clamped to ``[0, n-1]`` (edge replication) for the
    5-point stencil of :func:`image_derivatives` in Numba kernels."""
    return max(i - 2, 0), max(i - 1, 0), min(i + 1, n - 1), min(i + 2, n - 1)


_C12 = np.float32(1.0 / 12.0)


@nb.njit(cache=True, inline="always")
def stencil5(m2, m1, p1, p2):
    """The 5-point derivative ``(f(-2) - 8 f(-1) + 8 f(1) - f(2)) / 12`` of
    :func:`image_derivatives`, from the samples at the :func:`stencil5_indices`."""
    return (m2 - 8 * m1 + 8 * p1 - p2) * _C12


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH)
def _derivative_planes_kernel(img, out):
    h, w, nc = img.shape
    for i in nb.prange(h):
        im2, im1, ip1, ip2 = stencil5_indices(i, h)
        for j in range(w):
            jm2, jm1, jp1, jp2 = stencil5_indices(j, w)
            for c in range(nc):
                out[i, j, c] = img[i, j, c]
                out[i, j, nc + c] = stencil5(img[i, jm2, c], img[i, jm1, c], img[i, jp1, c],
                                             img[i, jp2, c])
                out[i, j, 2 * nc + c] = stencil5(img[im2, j, c], img[im1, j, c],
                                                 img[ip1, j, c], img[ip2, j, c])


def derivative_planes(image: np.ndarray) -> np.ndarray:
    """The image and its :func:`image_derivatives` stacked: the planes a warp samples.

    One Numba pass (:func:`derivative_planes_numpy` is the reference).

    Parameters
    ----------
    image : ndarray, shape (H, W, C), float32

    Returns
    -------
    ndarray, shape (H, W, 3C), float32
        ``[I, dI/dx, dI/dy]`` along the last axis.
    """
    img = np.ascontiguousarray(image, dtype=np.float32)
    out = np.empty(img.shape[:2] + (3 * img.shape[2],), np.float32)
    _derivative_planes_kernel(img, out)
    return out
