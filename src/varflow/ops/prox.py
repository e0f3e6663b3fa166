"""Proximal operators used by the solvers: NumPy references and Numba kernels.

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

Every variant of this linear-L1 prox lives here, once (one place to test and to fix),
each with its NumPy reference; the solvers of :mod:`varflow.twoframe` and
:mod:`varflow.multiframe` import them:

* :func:`prox_linear_l1` (NumPy; channels last, one step) and
  :func:`prox_linear_l1_pixel_step` (NumPy; planar, a step per pixel): dual
  coordinate descent, the references of the two Numba rows;
* :func:`data_prox_row` (one step for the row; TV-L1's iterations through
  :func:`~varflow.ops.primal_dual.prox_primal_row`, the U-step of the multi-frame
  methods, :func:`prox_certified`) and :func:`data_prox_row_pixel_step` (a step per
  pixel; the primal-dual solver of :mod:`varflow.twoframe.sparse`): the same descent
  as Numba row kernels, in float32 with :data:`varflow._jit.FASTMATH`;
* :func:`shrink_towards`: the prox of one term in one dimension,
  ``thr |x − l|`` (the link of the relaxed U-step);
* the exact prox, in float64 without fast-math: :func:`prox_faces` (the enumeration
  of :func:`prox_linear_l1_exact` in Numba), :func:`prox_certified` (dual descent
  proposes the active set, an optimality certificate accepts it, else more sweeps,
  else the enumeration) and its row :func:`certify_prox_row` (inside the U-step's
  kernels).

Two that compute the same thing stay two where one would change the last bits of a
solver: a row with one step and a row with a step per pixel compile to different
code, the NumPy references differ in layout and in the test of a zero gradient, and
the exact family runs in float64 without fast-math.  Each says in its docstring
how it differs and who uses it.  The module stays one (under 1,000 lines); the exact
family would be the one to split off, into ``prox_exact.py``.
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
    "shrink_towards",
    "certify_prox_row",
    "prox_certified",
    "prox_faces",
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

    Used by :func:`~varflow.ops.primal_dual.prox_primal_row` (TV-L1's iterations), the
    U-step rows of :mod:`varflow.multiframe.ustep` and :func:`prox_certified`.  Kept
    apart from :func:`data_prox_row_pixel_step`, which reads the step from an array:
    one scalar step compiles to other code.  NumPy reference: :func:`prox_linear_l1`.
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
    """:func:`data_prox_row` with a per-pixel step ``tr[j]``.

    In place on ``d1, d2`` (on entry the prox centre, on exit
    ``d - t Σ_c q_c ∇I_c``) and on the row ``i`` of ``q``.

    Used by :func:`~varflow.twoframe.sparse.sparse_pd_iterations` (the step of the
    sparse term's point-wise quadratic varies per pixel); kept apart from
    :func:`data_prox_row` (whose scalar step compiles to other code).  NumPy
    reference: :func:`prox_linear_l1_pixel_step`.
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


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def shrink_towards(c, lk, thr):
    """``argmin_x (x − c)²/2 + thr |x − lk|``: ``c`` moved towards ``lk`` by at most ``thr``.

    Scalar (Numba, :data:`varflow._jit.FASTMATH`), for the link terms of the relaxed
    U-step (:mod:`varflow.multiframe.ustep`).  NumPy reference:
    ``lk + soft_threshold(c − lk, thr)`` (:func:`soft_threshold`), equal up to rounding.
    """
    d = c - lk
    if d > thr:
        return c - thr
    if d < -thr:
        return c + thr
    return lk


# ------------------------------------------ Numba: the exact prox (faces, certificate)
@nb.njit(cache=True, fastmath=False, error_model="numpy")
def _faces_energy(v1, v2, z1, z2, bx, by, cc, inv2t):
    """The energy at one pixel in float64, ``inv2t = 1/(2t)`` (the scalar of
    :func:`linear_l1_energy`, for the enumeration of :func:`_prox_faces_pixel`)."""
    e = ((v1 - z1) ** 2 + (v2 - z2) ** 2) * inv2t
    for k in range(bx.shape[0]):
        e += abs(cc[k] + bx[k] * v1 + by[k] * v2)
    return e


@nb.njit(cache=True, fastmath=False, error_model="numpy")
def _prox_faces_pixel(z1, z2, bx, by, cc, t):
    """Exact ``argmin_v |v − z|²/(2t) + Σ_k |cc_k + b_k·v|`` by face enumeration (float64)."""
    nk = bx.shape[0]
    inv2t = 0.5 / t
    best = _faces_energy(z1, z2, z1, z2, bx, by, cc, inv2t)
    b1 = z1
    b2 = z2
    # interior of a region: every sign fixed
    for mask in range(1 << nk):
        v1 = z1
        v2 = z2
        for k in range(nk):
            s = t if (mask >> k) & 1 else -t
            v1 -= s * bx[k]
            v2 -= s * by[k]
        e = _faces_energy(v1, v2, z1, z2, bx, by, cc, inv2t)
        if e < best:
            best, b1, b2 = e, v1, v2
    # on the line of term k, the other signs fixed
    for k in range(nk):
        nn = bx[k] * bx[k] + by[k] * by[k]
        if nn < 1e-24:
            continue
        for mask in range(1 << nk):
            if (mask >> k) & 1:
                continue
            v1 = z1
            v2 = z2
            for j in range(nk):
                if j != k:
                    s = t if (mask >> j) & 1 else -t
                    v1 -= s * bx[j]
                    v2 -= s * by[j]
            r = (cc[k] + bx[k] * v1 + by[k] * v2) / nn
            v1 -= r * bx[k]
            v2 -= r * by[k]
            e = _faces_energy(v1, v2, z1, z2, bx, by, cc, inv2t)
            if e < best:
                best, b1, b2 = e, v1, v2
    # crossing of two lines
    for k in range(nk):
        for j in range(k + 1, nk):
            det = bx[k] * by[j] - by[k] * bx[j]
            if abs(det) < 1e-18:
                continue
            v1 = (-cc[k] * by[j] + by[k] * cc[j]) / det
            v2 = (-bx[k] * cc[j] + cc[k] * bx[j]) / det
            e = _faces_energy(v1, v2, z1, z2, bx, by, cc, inv2t)
            if e < best:
                best, b1, b2 = e, v1, v2
    return b1, b2


_KKT_TOL = 1e-6  # relative tolerance of the optimality certificate


@nb.njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _gram_solve(bx, by, j0, j1, r0, r1):
    """Solve ``G (y0, y1) = (r0, r1)``, G the Gram matrix of ``b_j0``, ``b_j1``.

    Returns ``(ok, y0, y1)``; ``ok`` is False for (nearly) parallel vectors."""
    g00 = bx[j0] * bx[j0] + by[j0] * by[j0]
    g11 = bx[j1] * bx[j1] + by[j1] * by[j1]
    g01 = bx[j0] * bx[j1] + by[j0] * by[j1]
    det = g00 * g11 - g01 * g01
    if det <= 1e-9 * g00 * g11:
        return False, 0.0, 0.0
    return True, (g11 * r0 - g01 * r1) / det, (g00 * r1 - g01 * r0) / det


@nb.njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _prox_from_duals(z1, z2, bx, by, cc, t, y):
    """Certify the active set read from the duals ``y`` (in/out); float64.

    Terms with ``|y_k| = 1`` are taken as sign terms, the others (at most two) as
    sitting on their line ``cc_k + b_k·v = 0``; their duals and ``v`` follow from
    ``(v − z)/t + Σ_k y_k b_k = 0``.  The point is returned with ``ok = True`` only
    when it satisfies the optimality conditions of
    ``|v − z|²/(2t) + Σ_k |cc_k + b_k·v|`` (every sign term's residual has the
    sign of its dual, every line dual lies in [−1, 1], up to a relative
    :data:`_KKT_TOL`), so then it *is* the minimiser; ``y`` is updated.
    """
    nk = bx.shape[0]
    one = 1.0 - _KKT_TOL
    w1 = z1
    w2 = z2
    j0 = -1
    j1 = -1
    nz = 0
    for k in range(nk):
        if bx[k] * bx[k] + by[k] * by[k] < 1e-24:  # constant term: no effect on v
            continue
        if abs(y[k]) >= one:
            sk = 1.0 if y[k] > 0 else -1.0
            w1 -= t * sk * bx[k]
            w2 -= t * sk * by[k]
        else:
            if nz == 0:
                j0 = k
            elif nz == 1:
                j1 = k
            nz += 1
    if nz > 2:
        return False, w1, w2
    v1 = w1
    v2 = w2
    y0 = 0.0
    y1 = 0.0
    if nz == 1:
        y0 = (cc[j0] + bx[j0] * w1 + by[j0] * w2) / (t * (bx[j0] * bx[j0] + by[j0] * by[j0]))
        if abs(y0) > 1.0 + _KKT_TOL:
            return False, w1, w2
        v1 = w1 - t * y0 * bx[j0]
        v2 = w2 - t * y0 * by[j0]
    elif nz == 2:
        ok, y0, y1 = _gram_solve(bx, by, j0, j1, (cc[j0] + bx[j0] * w1 + by[j0] * w2) / t,
                                 (cc[j1] + bx[j1] * w1 + by[j1] * w2) / t)
        if not ok or abs(y0) > 1.0 + _KKT_TOL or abs(y1) > 1.0 + _KKT_TOL:
            return False, w1, w2
        v1 = w1 - t * (y0 * bx[j0] + y1 * bx[j1])
        v2 = w2 - t * (y0 * by[j0] + y1 * by[j1])
    for k in range(nk):
        if bx[k] * bx[k] + by[k] * by[k] < 1e-24 or abs(y[k]) < one:
            continue
        r = cc[k] + bx[k] * v1 + by[k] * v2
        scale = abs(cc[k]) + abs(bx[k] * v1) + abs(by[k] * v2) + 1e-30
        if y[k] * r < -_KKT_TOL * scale:
            return False, w1, w2
    if nz >= 1:
        y[j0] = min(max(y0, -1.0), 1.0)
    if nz == 2:
        y[j1] = min(max(y1, -1.0), 1.0)
    return True, v1, v2


@nb.njit(cache=True, fastmath=False, error_model="numpy")
def _duals_of(v1, v2, z1, z2, bx, by, cc, t, y):
    """Duals ``y`` (out) of the minimiser ``v``: signs of the residuals, and for the
    terms on their line the solution of ``(v − z)/t + Σ_k y_k b_k = 0`` (clipped)."""
    nk = bx.shape[0]
    rr1 = (z1 - v1) / t
    rr2 = (z2 - v2) / t
    j0 = -1
    j1 = -1
    nz = 0
    for k in range(nk):
        nn = bx[k] * bx[k] + by[k] * by[k]
        r = cc[k] + bx[k] * v1 + by[k] * v2
        scale = abs(cc[k]) + abs(bx[k] * v1) + abs(by[k] * v2) + 1e-30
        if nn < 1e-24:
            y[k] = 0.0
        elif abs(r) > _KKT_TOL * scale:
            y[k] = 1.0 if r > 0 else -1.0
            rr1 -= y[k] * bx[k]
            rr2 -= y[k] * by[k]
        else:
            y[k] = 0.0
            if nz == 0:
                j0 = k
            elif nz == 1:
                j1 = k
            nz += 1
    if nz == 1:
        nn = bx[j0] * bx[j0] + by[j0] * by[j0]
        y[j0] = min(max((rr1 * bx[j0] + rr2 * by[j0]) / nn, -1.0), 1.0)
    elif nz == 2:
        ok, y0, y1 = _gram_solve(bx, by, j0, j1, rr1 * bx[j0] + rr2 * by[j0],
                                 rr1 * bx[j1] + rr2 * by[j1])
        if ok:
            y[j0] = min(max(y0, -1.0), 1.0)
            y[j1] = min(max(y1, -1.0), 1.0)


_EXTRA_SWEEPS = 16  # dual descent sweeps a pixel may take before the enumeration


@nb.njit(cache=True, fastmath=False, error_model="numpy")
def _prox_fallback(z1, z2, bx, by, cc, t, y):
    """More dual descent sweeps on this pixel, each followed by the certificate; the
    enumeration (then the duals of its result) if none certifies.  Out of line:
    rarely taken.

    Its sweeps are :func:`data_prox_row`'s descent on one pixel, kept apart: float64
    without fast-math, and ``v`` recomputed from all the duals before each sweep."""
    nk = bx.shape[0]
    for _s in range(_EXTRA_SWEEPS):
        v1 = z1
        v2 = z2
        for k in range(nk):
            v1 -= t * y[k] * bx[k]
            v2 -= t * y[k] * by[k]
        for k in range(nk):
            nn = bx[k] * bx[k] + by[k] * by[k]
            if nn < 1e-24:
                continue
            e1 = v1 + t * y[k] * bx[k]
            e2 = v2 + t * y[k] * by[k]
            yk = (cc[k] + bx[k] * e1 + by[k] * e2) / (t * nn)
            yk = min(max(yk, -1.0), 1.0)
            y[k] = yk
            v1 = e1 - t * yk * bx[k]
            v2 = e2 - t * yk * by[k]
        ok, w1, w2 = _prox_from_duals(z1, z2, bx, by, cc, t, y)
        if ok:
            return w1, w2
    v1, v2 = _prox_faces_pixel(z1, z2, bx, by, cc, t)
    _duals_of(v1, v2, z1, z2, bx, by, cc, t, y)
    return v1, v2


@nb.njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _prox_exact_pixel(z1, z2, bx, by, cc, t, y):
    """Exact prox at one pixel: the certified active set of ``y``, else enumeration.

    Returns ``(v1, v2, fell_back)``; ``y`` holds the duals of the result.
    """
    ok, v1, v2 = _prox_from_duals(z1, z2, bx, by, cc, t, y)
    if ok:
        return v1, v2, False
    v1, v2 = _prox_fallback(z1, z2, bx, by, cc, t, y)
    return v1, v2, True


@nb.njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def certify_prox_row(ix, iy, a, q, i, z1, z2, d1, d2, t, sc):
    """Exact prox of row ``i`` from the duals ``q`` the descent left (in place on d, q).

    ``z1, z2``: the prox argument of the row; ``sc``: (4, K) float64 scratch.
    Returns the number of pixels whose first active set failed the certificate.
    Used by :func:`prox_certified` and inside the U-step's kernels
    (:mod:`varflow.multiframe.ustep`), after :func:`data_prox_row`.
    """
    nk = a.shape[0]
    bx = sc[0]
    by = sc[1]
    cc = sc[2]
    y = sc[3]
    t64 = np.float64(t)
    nf = 0
    for j in range(a.shape[2]):
        for k in range(nk):
            bx[k] = ix[k, i, j]
            by[k] = iy[k, i, j]
            cc[k] = a[k, i, j]
            y[k] = q[k, i, j]
        v1, v2, fell = _prox_exact_pixel(np.float64(z1[j]), np.float64(z2[j]), bx, by, cc,
                                         t64, y)
        nf += fell
        for k in range(nk):
            q[k, i, j] = y[k]
        d1[j] = v1
        d2[j] = v2
    return nf


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _prox_certified_kernel(u, a, ix, iy, q, t, n_sweeps, out, fallbacks):
    nk, h, w = a.shape
    for i in nb.prange(h):
        d1 = out[0, i]
        d2 = out[1, i]
        d1[:] = u[0, i]
        d2[:] = u[1, i]
        data_prox_row(ix, iy, a, q, i, d1, d2, np.float32(t), n_sweeps)
        fallbacks[i] = certify_prox_row(ix, iy, a, q, i, u[0, i], u[1, i], d1, d2, t,
                                    np.empty((4, nk), np.float64))


def prox_certified(u: np.ndarray, a: np.ndarray, ix: np.ndarray, iy: np.ndarray, t: float,
                   q: np.ndarray | None = None, n_sweeps: int = 1
                   ) -> tuple[np.ndarray, np.ndarray, int]:
    """Exact point-wise prox, fast: warm-started dual descent, then a certificate.

    The same problem and result as :func:`prox_faces`.  ``n_sweeps`` sweeps of the
    dual coordinate descent (started from ``q``) give a guess of the active set —
    which terms sit on their line ``a_k + b_k·v = 0`` (at most two in the plane) and
    the signs of the others; the point this guess defines is kept only when it
    satisfies the optimality conditions (then it is the exact minimiser), otherwise
    the pixel falls back to :func:`prox_faces`' enumeration.  Near convergence of a
    primal-dual loop the active sets hardly change, so few pixels fall back.

    Parameters
    ----------
    u : ndarray, shape (2, H, W)
        Point to project (the prox argument).
    a, ix, iy : ndarray, shape (K, H, W)
        Terms ``a_k + ix_k v_1 + iy_k v_2``.
    t : float
        Step.
    q : ndarray, shape (K, H, W), optional
        Dual variables in [−1, 1] to start from (zeros by default).
    n_sweeps : int
        Coordinate-descent sweeps before the certificate.

    Returns
    -------
    v : ndarray, shape (2, H, W), float32
        The minimiser.
    q : ndarray, shape (K, H, W), float32
        Its duals (a warm start for the next call).
    fallbacks : int
        Pixels whose first active set failed the certificate (they took more
        descent sweeps, and the enumeration if none of those certified).
    """
    a = np.ascontiguousarray(a, np.float32)
    q = np.zeros_like(a) if q is None else np.array(q, np.float32, order="C")
    out = np.empty((2,) + a.shape[1:], np.float32)
    fallbacks = np.zeros(a.shape[1], np.int64)
    _prox_certified_kernel(np.ascontiguousarray(u, np.float32), a,
                           np.ascontiguousarray(ix, np.float32),
                           np.ascontiguousarray(iy, np.float32), q, float(t), int(n_sweeps),
                           out, fallbacks)
    return out, q, int(fallbacks.sum())


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _prox_faces_kernel(u, a, ix, iy, t, out):
    nk, h, w = a.shape
    for i in nb.prange(h):
        bx = np.empty(nk, np.float64)
        by = np.empty(nk, np.float64)
        cc = np.empty(nk, np.float64)
        for j in range(w):
            for k in range(nk):
                bx[k] = ix[k, i, j]
                by[k] = iy[k, i, j]
                cc[k] = a[k, i, j]
            v1, v2 = _prox_faces_pixel(np.float64(u[0, i, j]), np.float64(u[1, i, j]),
                                       bx, by, cc, t)
            out[0, i, j] = v1
            out[1, i, j] = v2


def prox_faces(u: np.ndarray, a: np.ndarray, ix: np.ndarray, iy: np.ndarray,
               t: float) -> np.ndarray:
    """Exact point-wise prox of ``t Σ_k |a_k + (ix_k, iy_k)·v|`` (Numba, planar arrays).

    Same problem as :func:`varflow.ops.prox.prox_linear_l1_exact` (its NumPy
    reference) with planar ``(K, H, W)`` terms: evaluates the energy at the
    minimiser of every region (2^K), of every line with the other signs fixed
    (K·2^(K−1)) and at every crossing of two lines (K(K−1)/2) — 23 candidates for
    K = 3 (grey + two link terms), 122 for K = 5 — and keeps the lowest.  Kept apart
    from its reference: scalar float64 loops, another order of the candidates and
    other thresholds of a degenerate line or crossing.

    Parameters
    ----------
    u : ndarray, shape (2, H, W)
        Point to project (the prox argument).
    a, ix, iy : ndarray, shape (K, H, W)
        Terms ``a_k + ix_k v_1 + iy_k v_2``.
    t : float
        Step.

    Returns
    -------
    ndarray, shape (2, H, W), float32
    """
    out = np.empty((2,) + a.shape[1:], np.float32)
    _prox_faces_kernel(np.ascontiguousarray(u, np.float32), np.ascontiguousarray(a, np.float32),
                       np.ascontiguousarray(ix, np.float32), np.ascontiguousarray(iy, np.float32),
                       float(t), out)
    return out
