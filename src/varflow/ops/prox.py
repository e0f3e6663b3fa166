"""Proximal operators used by the solvers (NumPy references).

``prox_{t f}(x) = argmin_y f(y) + ||y - x||² / (2 t)``.  Every operator here has a
Moreau partner so that ``x = prox_{t f}(x) + t prox_{f*/t}(x / t)`` can be tested.

The data-term prox of TV-L1 is the point-wise problem (per pixel, d in R²)::

    min_d  ||d - u||² / (2 t) + Σ_c |a_c + g_c · d|

with one term per colour channel (Rakêt et al. 2011; grey images have C = 1).  Its
dual is a box-constrained quadratic problem in q ∈ [-1, 1]^C with
``d = u - t Σ_c q_c g_c``; :func:`prox_linear_l1` solves that dual by exact
coordinate descent (one sweep is exact for C = 1, where it reduces to the classic
three-case thresholding of Zach, Pock & Bischof 2007), and
:func:`prox_linear_l1_exact` enumerates the faces of the piecewise-quadratic energy
(for tests and small problems).
"""

from __future__ import annotations

import itertools

import numba as nb
import numpy as np

from .._jit import FASTMATH

__all__ = [
    "soft_threshold",
    "clip_unit",
    "prox_l2_norm",
    "project_l2_ball",
    "prox_huber_norm",
    "prox_huber_conjugate",
    "prox_linear_l1",
    "prox_linear_l1_pixel_step",
    "prox_linear_l1_exact",
    "linear_l1_energy",
    "EPS_GRAD",
    "data_prox_row",
    "data_prox_row_pixel_step",
]

# float32 constants: Python float literals would make Numba compute in float64
_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
#: Squared gradient norm below which a linear-L1 term has no gradient (its dual is 0).
EPS_GRAD = np.float32(1e-12)


def soft_threshold(x: np.ndarray, t: float | np.ndarray) -> np.ndarray:
    """Prox of ``t |x|`` (element-wise shrinkage)."""
    return np.sign(x) * np.maximum(np.abs(x) - t, 0.0)


def clip_unit(x: np.ndarray) -> np.ndarray:
    """Projection onto [-1, 1]: the prox of the conjugate of ``|x|`` (Moreau partner of
    :func:`soft_threshold`: ``x = soft_threshold(x, t) + t clip_unit(x / t)``)."""
    return np.clip(x, -1.0, 1.0)


def prox_l2_norm(x: np.ndarray, t: float | np.ndarray) -> np.ndarray:
    """Prox of ``t ||x||_2`` over the last axis (group shrinkage).

    Moreau partner of :func:`project_l2_ball`:
    ``x = prox_l2_norm(x, t) + t project_l2_ball(x / t)``.
    """
    nrm = np.sqrt((x * x).sum(-1, keepdims=True))
    return x * np.maximum(0.0, 1.0 - t / np.maximum(nrm, 1e-30))


def project_l2_ball(p: np.ndarray, radius: float | np.ndarray = 1.0) -> np.ndarray:
    """Project vectors along the last axis onto the L2 ball of the given radius.

    This is the prox of the conjugate of ``radius * ||.||_2`` (any step), i.e. the
    dual step of (weighted) isotropic TV with ``radius = g(x)``.
    """
    nrm = np.sqrt((p * p).sum(-1, keepdims=True))
    r = np.asarray(radius, dtype=p.dtype)
    if r.ndim:
        r = r[..., None]
    return p / np.maximum(1.0, nrm / np.maximum(r, 1e-30))


def prox_huber_norm(x: np.ndarray, t: float, eps: float,
                    radius: float | np.ndarray = 1.0) -> np.ndarray:
    """Prox of ``t r h_ε(x)``, ``h_ε`` the Huber function of the L2 norm (last axis).

    ``h_ε(x) = |x|²/(2ε)`` for ``|x| ≤ ε``, ``|x| - ε/2`` beyond; ``r = radius``
    (e.g. the edge weight g).  Quadratic near zero, so a regulariser built on it does
    not staircase smooth ramps (Huber-TV; Werlberger, Trobin, Pock et al. 2009).
    Moreau partner of :func:`prox_huber_conjugate`:
    ``x = prox_huber_norm(x, t, ε, r) + t prox_huber_conjugate(x / t, 1 / t, ε, r)``.
    ``ε = 0`` gives :func:`prox_l2_norm` with ``t r``.
    """
    r = np.asarray(radius, dtype=x.dtype)
    if r.ndim:
        r = r[..., None]
    nrm = np.sqrt((x * x).sum(-1, keepdims=True))
    tr = t * r
    small = x * (eps / np.maximum(eps + tr, 1e-30))
    shrink = x * np.maximum(0.0, 1.0 - tr / np.maximum(nrm, 1e-30))
    return np.where(nrm <= eps + tr, small, shrink)


def prox_huber_conjugate(p: np.ndarray, s: float, eps: float,
                         radius: float | np.ndarray = 1.0) -> np.ndarray:
    """Prox of ``s (r h_ε)*``: ``Π_{|p| ≤ r}(p / (1 + s ε / r))`` over the last axis.

    ``(r h_ε)*(p) = ε |p|² / (2 r) + δ(|p| ≤ r)``: the dual step of Huber-TV, the
    dual step of TV (:func:`project_l2_ball`) after a shrinkage by ``1 + s ε / r``.
    """
    r = np.asarray(radius, dtype=p.dtype)
    rb = r[..., None] if r.ndim else r
    return project_l2_ball(p / (1.0 + s * eps / np.maximum(rb, 1e-30)), r)


def linear_l1_energy(d, u, a, gx, gy, t):
    """Energy ``||d - u||²/(2t) + Σ_c |a_c + gx_c d_0 + gy_c d_1|`` per pixel.

    Shapes: d, u ``(..., 2)``; a, gx, gy ``(..., C)``.
    """
    r = a + gx * d[..., :1] + gy * d[..., 1:2]
    return ((d - u) ** 2).sum(-1) / (2 * t) + np.abs(r).sum(-1)


def prox_linear_l1(u, a, gx, gy, t, n_sweeps=1, q0=None):
    """Point-wise prox of the linearised multi-channel L1 data term.

    Parameters
    ----------
    u : ndarray, shape (..., 2)
        Point at which the prox is evaluated (the current flow).
    a, gx, gy : ndarray, shape (..., C)
        Residual at zero displacement and its gradients: term ``|a + gx d0 + gy d1|``.
    t : float
        Step ``t = λ θ``.
    n_sweeps : int
        Coordinate-descent sweeps over the channels of the dual box QP.
    q0 : ndarray, shape (..., C), optional
        Warm start of the dual variable (values in [-1, 1]).

    Returns
    -------
    d : ndarray, shape (..., 2)
    q : ndarray, shape (..., C)
        The dual variable, for the next warm start.
    """
    u = np.asarray(u, np.float32)
    q = np.zeros_like(a, dtype=np.float32) if q0 is None else np.array(q0, np.float32)
    nn = gx * gx + gy * gy
    safe = nn > 1e-12
    inv = np.where(safe, 1.0 / (t * np.where(safe, nn, 1.0)), 0.0).astype(np.float32)
    d0 = u[..., 0] - t * (q * gx).sum(-1)
    d1 = u[..., 1] - t * (q * gy).sum(-1)
    for _ in range(n_sweeps):
        for c in range(a.shape[-1]):
            e0 = d0 + t * q[..., c] * gx[..., c]
            e1 = d1 + t * q[..., c] * gy[..., c]
            r = a[..., c] + gx[..., c] * e0 + gy[..., c] * e1
            qn = np.clip(r * inv[..., c], -1.0, 1.0)
            q[..., c] = qn
            d0 = e0 - t * qn * gx[..., c]
            d1 = e1 - t * qn * gy[..., c]
    return np.stack([d0, d1], -1).astype(np.float32), q


def prox_linear_l1_pixel_step(z, a, gx, gy, t, q, n_sweeps=1):
    """:func:`prox_linear_l1` on planar arrays, with a step per pixel and the duals in place.

    The NumPy reference of :func:`data_prox_row_pixel_step` (and so of
    :func:`~varflow.twoframe.sparse.sparse_pd_iterations`' point-wise step, whose
    reference :func:`~varflow.twoframe.sparse.sparse_pd_iterations_numpy` calls it).
    Apart from :func:`prox_linear_l1` because it differs in the last bits: the terms
    are planar ``(C, H, W)`` (sums over the first axis), a term counts as having a
    gradient when ``|g_c|² ≥ 1e-12`` (as in the Numba kernels; :func:`prox_linear_l1`
    asks for ``> 1e-12``) and ``q`` is updated in place.

    Parameters
    ----------
    z : sequence of two ndarray, shape (H, W), float32
        The prox centre ``(z_1, z_2)``.
    a, gx, gy : ndarray, shape (C, H, W), float32
        Terms ``|a_c + gx_c d_1 + gy_c d_2|``.
    t : float or ndarray, shape (H, W), float32
        Step, per pixel.
    q : ndarray, shape (C, H, W), float32
        Warm start of the duals in [-1, 1], updated in place.
    n_sweeps : int
        Coordinate-descent sweeps over the channels.

    Returns
    -------
    d0, d1 : ndarray, shape (H, W), float32
        The two components of the prox.
    """
    nn = gx * gx + gy * gy
    safe = nn >= 1e-12
    inv = np.where(safe, 1.0 / (t * np.where(safe, nn, 1.0)), 0.0).astype(np.float32)
    d0 = z[0] - t * (q * gx).sum(0)
    d1 = z[1] - t * (q * gy).sum(0)
    for _ in range(n_sweeps):
        for c in range(a.shape[0]):
            e0 = d0 + t * q[c] * gx[c]
            e1 = d1 + t * q[c] * gy[c]
            qn = np.clip((a[c] + gx[c] * e0 + gy[c] * e1) * inv[c], -1.0, 1.0)
            q[c] = qn
            d0 = e0 - t * qn * gx[c]
            d1 = e1 - t * qn * gy[c]
    return d0, d1


def prox_linear_l1_exact(u, a, gx, gy, t):
    """Exact prox of the linearised L1 data term by enumerating faces (for tests).

    The energy is strictly convex and piecewise quadratic over the arrangement of
    the lines ``a_c + g_c·d = 0``; its minimiser lies inside a region (all signs
    fixed), on one line (one residual zero) or at the crossing of two lines.  Every
    candidate of each kind is evaluated and the lowest energy kept.

    Shapes as in :func:`prox_linear_l1`; float64 internally.
    """
    u = np.asarray(u, np.float64)
    a, gx, gy = (np.asarray(z, np.float64) for z in (a, gx, gy))
    n_ch = a.shape[-1]
    g = np.stack([gx, gy], -1)  # (..., C, 2)
    cands = []
    signs = list(itertools.product((-1.0, 1.0), repeat=n_ch))
    for s in signs:  # interior of a region
        s = np.array(s)
        cands.append(u - t * (s[:, None] * g).sum(-2))
    for c in range(n_ch):  # on the line of channel c
        others = [k for k in range(n_ch) if k != c]
        gc = g[..., c, :]
        nn = np.maximum((gc * gc).sum(-1, keepdims=True), 1e-300)
        for s in itertools.product((-1.0, 1.0), repeat=len(others)):
            z = u.copy()
            for sk, k in zip(s, others, strict=True):
                z = z - t * sk * g[..., k, :]
            r = a[..., c : c + 1] + (gc * z).sum(-1, keepdims=True)
            cands.append(z - r * gc / nn)
    for c1, c2 in itertools.combinations(range(n_ch), 2):  # crossing of two lines
        m = np.stack([g[..., c1, :], g[..., c2, :]], -2)
        det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
        ok = np.abs(det) > 1e-12
        det = np.where(ok, det, 1.0)
        b0, b1 = -a[..., c1], -a[..., c2]
        x0 = (b0 * m[..., 1, 1] - m[..., 0, 1] * b1) / det
        x1 = (m[..., 0, 0] * b1 - b0 * m[..., 1, 0]) / det
        z = np.stack([x0, x1], -1)
        cands.append(np.where(ok[..., None], z, u))
    cands = np.stack(cands, 0)
    energies = linear_l1_energy(cands, u[None], a[None], gx[None], gy[None], t)
    best = np.argmin(energies, axis=0)
    return np.take_along_axis(cands, best[None, ..., None], 0)[0]


# ------------------------------------------------- Numba row kernels (dual descent)
@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def data_prox_row(ix, iy, a, q, i, d1, d2, t, n_sweeps):
    """Prox of the linearised colour L1 term for row ``i`` (in place on d1, d2, q).

    Dual coordinate descent over the channels (see :func:`varflow.ops.prox.prox_linear_l1`);
    on entry ``d = u``; on exit ``d = u - t Σ_c q_c ∇I_c``.
    """
    nc = a.shape[0]
    w = a.shape[2]
    for c in range(nc):
        gxr = ix[c, i]
        gyr = iy[c, i]
        qr = q[c, i]
        for j in range(w):
            qv = t * qr[j]
            d1[j] -= qv * gxr[j]
            d2[j] -= qv * gyr[j]
    for _s in range(n_sweeps):
        for c in range(nc):
            gxr = ix[c, i]
            gyr = iy[c, i]
            ar = a[c, i]
            qr = q[c, i]
            for j in range(w):
                gx = gxr[j]
                gy = gyr[j]
                qo = t * qr[j]
                e1 = d1[j] + qo * gx
                e2 = d2[j] + qo * gy
                nn = gx * gx + gy * gy
                r = ar[j] + gx * e1 + gy * e2
                qn = r / (t * nn) if nn >= EPS_GRAD else _F0
                qn = min(max(qn, -_F1), _F1)
                qr[j] = qn
                d1[j] = e1 - t * qn * gx
                d2[j] = e2 - t * qn * gy


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def data_prox_row_pixel_step(ix, iy, a, q, i, d1, d2, tr, n_sweeps):
    """:func:`varflow.ops.primal_dual.data_prox_row` with a per-pixel step ``tr[j]``.

    In place on ``d1, d2`` (on entry the prox centre, on exit
    ``d - t Σ_c q_c ∇I_c``) and on the row ``i`` of ``q``.
    """
    nc = a.shape[0]
    w = a.shape[2]
    for c in range(nc):
        gxr = ix[c, i]
        gyr = iy[c, i]
        qr = q[c, i]
        for j in range(w):
            qv = tr[j] * qr[j]
            d1[j] -= qv * gxr[j]
            d2[j] -= qv * gyr[j]
    for _s in range(n_sweeps):
        for c in range(nc):
            gxr = ix[c, i]
            gyr = iy[c, i]
            ar = a[c, i]
            qr = q[c, i]
            for j in range(w):
                gx = gxr[j]
                gy = gyr[j]
                t = tr[j]
                qo = t * qr[j]
                e1 = d1[j] + qo * gx
                e2 = d2[j] + qo * gy
                nn = gx * gx + gy * gy
                r = ar[j] + gx * e1 + gy * e2
                qn = r / (t * nn) if nn >= EPS_GRAD else _F0
                qn = min(max(qn, -_F1), _F1)
                qr[j] = qn
                d1[j] = e1 - t * qn * gx
                d2[j] = e2 - t * qn * gy
