"""Row kernels of the first-order primal-dual TV-L1 iterations (Numba).

The building blocks that every solver of the TV-L1 family composes into its
iteration kernel: :func:`varflow.twoframe.tvl1.tvl1_iterations` (two-frame TV-L1
and its tensor-directed variant), :mod:`varflow.twoframe.sparse` (the combined
sparse energy) and :func:`varflow.multiframe.ustep.ustep_iterations` (the U-step of
the multi-frame methods).  Each works on one image row of planar ``(K, H, W)``
float32 arrays, in place, so that a solver sweeps rows in parallel blocks
(:func:`row_blocks`) and keeps the data of a row in cache for several updates.

* :func:`~varflow.ops.prox.data_prox_row`: the prox of the linearised multi-channel
  L1 data term ``λ Σ_c |a_c + ∇I_c · u|`` by dual coordinate descent (the row version
  of :func:`varflow.ops.prox.prox_linear_l1`), which lives in :mod:`varflow.ops.prox`
  with the other variants of that prox and is imported here;
* :func:`primal_row`: ``u ← d + θ div p`` with the Neumann divergence of
  :func:`varflow.ops.differences.divergence`;
* :func:`dual_row`: the dual TV step ``p ← Π_{|p| ≤ g}(p + step · T∇u)``, with the
  Huber-TV shrinkage (:func:`varflow.ops.prox.prox_huber_conjugate`) and an
  optional tensor ``T``;
* :func:`prox_primal_row`: both of the first for one row;
* :func:`project_dual`: the projection of a whole dual field onto its balls;
* :func:`ordered_sum`: a sum whose result does not depend on the thread count.

The NumPy references are the operators of :mod:`varflow.ops.prox` and
:mod:`varflow.ops.differences`; the tests compare every iteration kernel built
from these rows with its NumPy reference.

References
----------
A. Chambolle, T. Pock, "A first-order primal-dual algorithm for convex problems with
applications to imaging", JMIV 2011.  C. Zach, T. Pock, H. Bischof, "A duality based
approach for realtime TV-L1 optical flow", DAGM 2007.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .._jit import FASTMATH
from .prox import EPS_GRAD, data_prox_row

__all__ = [
    "F0",
    "F1",
    "EPS_GRAD",
    "NO_TENSOR",
    "ordered_sum",
    "row_blocks",
    "data_prox_row",
    "primal_row",
    "shrink_project",
    "dual_row",
    "prox_primal_row",
    "project_dual",
]

# float32 constants: Python float literals would make Numba compute in float64
F0 = np.float32(0.0)
F1 = np.float32(1.0)


@nb.njit(cache=True, inline="always")
def ordered_sum(x):
    """Sum of a 1-D array in index order (a plain loop: the same float result for any
    thread count, where a reduction inside a parallel kernel may split it)."""
    total = 0.0
    for i in range(x.shape[0]):
        total += x[i]
    return total


def row_blocks(h: int) -> np.ndarray:
    """Split ``h`` rows into contiguous blocks, a few per thread (bounds, length n+1)."""
    n = max(1, min(h // 4, 4 * nb.get_num_threads()))
    return np.linspace(0, h, n + 1).astype(np.int64)


# The row kernels below index 1-D row views with plain loop variables only (no
# ``j - 1``): Numba then knows every index is non-negative, drops its wrap-around
# checks and LLVM vectorises the loops.


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def primal_row(u, tp, i, k, d, theta):
    """``u_k[i] = d + θ div(tp_k)[i]``; returns the squared change of the row.

    The divergence is the negative adjoint of the forward-difference gradient with
    Neumann boundary (:func:`varflow.ops.differences.divergence`): it ignores the x
    component in the last column and the y component in the last row.
    """
    h = u.shape[1]
    w = u.shape[2]
    px = tp[2 * k, i]
    pyc = tp[2 * k + 1, i]
    pym = tp[2 * k + 1, max(i - 1, 0)]
    cy = F1 if i < h - 1 else F0  # weight of py[i]
    cm = F1 if i > 0 else F0  # weight of py[i - 1]
    ur = u[k, i]
    err = F0
    # dv_x = px[j] - px[j-1] with px[-1] := 0 and px[w-1] := 0
    dv = px[0] + cy * pyc[0] - cm * pym[0]
    new = d[0] + theta * dv
    err += (new - ur[0]) ** 2
    ur[0] = new
    pxl = px[: w - 2]  # px[j - 1] for j = 1 .. w-2
    pxc = px[1 : w - 1]
    pyc1 = pyc[1 : w - 1]
    pym1 = pym[1 : w - 1]
    d1 = d[1 : w - 1]
    ur1 = ur[1 : w - 1]
    for jj in range(w - 2):
        dv = pxc[jj] - pxl[jj] + cy * pyc1[jj] - cm * pym1[jj]
        new = d1[jj] + theta * dv
        err += (new - ur1[jj]) ** 2
        ur1[jj] = new
    dv = -px[w - 2] + cy * pyc[w - 1] - cm * pym[w - 1]
    new = d[w - 1] + theta * dv
    err += (new - ur[w - 1]) ** 2
    ur[w - 1] = new
    return err


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy", inline="always")
def shrink_project(zx, zy, lim, se):
    """``Π_{|p| ≤ lim}(z / (1 + se / lim))`` as ``z · lim / max(lim + se, |z|)``.

    One division and one square root: scaling ``z`` by ``h = lim / (lim + se)`` and
    then projecting onto the ball of radius ``lim`` multiplies it by
    ``min(h, lim / |z|)``.  With ``se = 0`` the projection onto the ball.
    """
    s = lim / max(lim + se, math.sqrt(zx * zx + zy * zy))
    return zx * s, zy * s


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def dual_row(u, p, tp, g, tens, i, step, aniso, huber=0.0):
    """Dual TV step for row ``i``: ``p ← Π_{|p| ≤ g}(p + step · T ∇u)``; ``tp = T p``.

    With ``huber`` = ε_H > 0 the Huber-TV step
    ``Π_{|p| ≤ g}((p + step T∇u) / (1 + step ε_H / g))``
    (:func:`varflow.ops.prox.prox_huber_conjugate`).
    """
    h = u.shape[1]
    w = u.shape[2]
    cy = step if i < h - 1 else F0
    ip = min(i + 1, h - 1)
    gr = g[i]
    se = step * huber
    for k in range(2):
        uc = u[k, i]
        un = u[k, ip]
        ucr = uc[1:]  # u[j + 1]; the last column has a zero x difference
        pxr = p[2 * k, i]
        pyr = p[2 * k + 1, i]
        if not aniso:
            for j in range(w - 1):
                px, py = shrink_project(pxr[j] + step * (ucr[j] - uc[j]),
                                         pyr[j] + cy * (un[j] - uc[j]), gr[j], se)
                pxr[j] = px
                pyr[j] = py
            j = w - 1
            px, py = shrink_project(pxr[j], pyr[j] + cy * (un[j] - uc[j]), gr[j], se)
            pxr[j] = px
            pyr[j] = py
        else:
            t11r = tens[0, i]
            t12r = tens[1, i]
            t22r = tens[2, i]
            tpxr = tp[2 * k, i]
            tpyr = tp[2 * k + 1, i]
            for j in range(w):
                gx = step * (ucr[j] - uc[j]) if j < w - 1 else F0
                gy = cy * (un[j] - uc[j])
                t11 = t11r[j]
                t12 = t12r[j]
                t22 = t22r[j]
                px, py = shrink_project(pxr[j] + t11 * gx + t12 * gy,
                                         pyr[j] + t12 * gx + t22 * gy, gr[j], se)
                pxr[j] = px
                pyr[j] = py
                tpxr[j] = t11 * px + t12 * py
                tpyr[j] = t12 * px + t22 * py


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def prox_primal_row(ix, iy, a, q, u, tp, i, d1, d2, t, theta, n_sweeps):
    """Data prox and primal update of row ``i`` (``d1``, ``d2``: row buffers); returns
    the squared change of the flow on the row."""
    w = u.shape[2]
    for j in range(w):
        d1[j] = u[0, i, j]
        d2[j] = u[1, i, j]
    data_prox_row(ix, iy, a, q, i, d1, d2, t, n_sweeps)
    return primal_row(u, tp, i, 0, d1, theta) + primal_row(u, tp, i, 1, d2, theta)


@nb.njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def project_dual(p, g):
    """Project the dual TV pairs ``(p[2k], p[2k+1])`` of planar ``(4, H, W)`` ``p`` onto
    the balls of radius ``g`` (H, W), in place (the dual step's projection)."""
    _, h, w = p.shape
    for i in nb.prange(h):
        for k in range(2):
            pxr = p[2 * k, i]
            pyr = p[2 * k + 1, i]
            gr = g[i]
            for j in range(w):
                px, py = shrink_project(pxr[j], pyr[j], gr[j], F0)
                pxr[j] = px
                pyr[j] = py


#: The tensor argument of the kernels for isotropic TV: a (3, 1, 1) placeholder that
#: they never read.
NO_TENSOR = np.zeros((3, 1, 1), np.float32)
