"""TV-L1 optical flow: L1 (colour) constancy + (edge-weighted) total variation.

Energy at one warp, linearised around ``u0`` (Zach, Pock & Bischof 2007; Wedel et
al. 2009; Sánchez, Meinhardt-Llopis & Facciolo, IPOL 2013)::

    E(u) = Σ_x g(x) |∇u_1| + g(x) |∇u_2| + λ Σ_c |ρ_c(u)|,
    ρ_c(u) = I1w_c + ∇I1w_c · (u - u0) - I0_c

The scheme introduces an auxiliary flow v coupled to u by ||u - v||²/(2θ) and
alternates

1. ``v = prox_{λθ Σ|ρ_c|}(u)`` — point-wise; for colour images the vector-valued
   data term of Rakêt et al. (2011) is solved through its box-constrained dual by
   coordinate descent over the channels (exact for grey images);
2. ``u = v + θ div p`` and ``p ← Π_{|p| ≤ g}(p + (τ/θ) ∇u)`` — Chambolle's dual
   step for the (weighted) ROF problem of each flow component.

until the mean squared update falls below ε² or ``max_iterations`` is reached.

Symbol map: λ = ``data_weight``, θ = ``coupling``, τ = ``tv_step``,
ε = ``tolerance``, c of g(x) = exp(-c |∇I|²) = ``edge_weight``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..ops.differences import divergence, gradient, image_derivatives
from ..ops.prox import project_l2_ball, prox_linear_l1
from ..ops.pyramid import resize_bilinear
from .coarse_to_fine import CoarseToFineParams, _check, coarse_to_fine

__all__ = [
    "TVL1Params",
    "solve_warp",
    "tvl1",
    "tvl1_iterations",
    "tvl1_iterations_numpy",
    "edge_weight",
]


@dataclass(frozen=True)
class TVL1Params(CoarseToFineParams):
    """Parameters of TV-L1 (all pyramid fields of :class:`CoarseToFineParams` too).

    Intensities are in [0, 1]; flows in pixels.

    Attributes
    ----------
    data_weight : float
        λ, weight of the L1 data term per channel (1/intensity units).  Default 0.6·255/…
        tuned on Middlebury (see README).
    coupling : float
        θ, coupling between the data and TV sub-problems (pixels²·…); small values
        tie u and v closely.  Default 0.3.
    tv_step : float
        τ, step of the dual TV update; stable for τ ≤ 1/4.  Default 0.25.
    max_iterations : int
        Maximum iterations per warp.  Default 50.
    tolerance : float
        ε, stop when the root-mean-square update of the flow is below ε pixels.
        Default 0.01.
    edge_weight : float
        c of the TV edge weight g(x) = exp(-c |∇I0|²) (|∇I0|² in intensity²/pixel²,
        averaged over channels); 0 gives g ≡ 1 (plain TV).  Default 0.
    edge_weight_min : float
        Lower bound of g, in (0, 1].  Default 0.05.
    data_sweeps : int
        Coordinate-descent sweeps of the colour data prox per iteration (warm
        started, so 1–2 suffice; grey images are exact with 1).  Default 2.
    """

    data_weight: float = 40.0
    coupling: float = 0.3
    tv_step: float = 0.25
    max_iterations: int = 50
    tolerance: float = 0.01
    edge_weight: float = 0.0
    edge_weight_min: float = 0.05
    data_sweeps: int = 2

    def __post_init__(self) -> None:
        super().__post_init__()
        _check(self.data_weight > 0, "data_weight", f"must be > 0, got {self.data_weight}")
        _check(self.coupling > 0, "coupling", f"must be > 0, got {self.coupling}")
        _check(0 < self.tv_step <= 0.25, "tv_step", f"must be in (0, 0.25], got {self.tv_step}")
        _check(
            self.max_iterations >= 1, "max_iterations", f"must be >= 1, got {self.max_iterations}"
        )
        _check(self.tolerance >= 0, "tolerance", f"must be >= 0, got {self.tolerance}")
        _check(self.edge_weight >= 0, "edge_weight", f"must be >= 0, got {self.edge_weight}")
        _check(
            0 < self.edge_weight_min <= 1,
            "edge_weight_min",
            f"must be in (0, 1], got {self.edge_weight_min}",
        )
        _check(self.data_sweeps >= 1, "data_sweeps", f"must be >= 1, got {self.data_sweeps}")


def edge_weight(image: np.ndarray, c: float, g_min: float = 0.05) -> np.ndarray:
    """Edge weight g(x) = max(exp(-c |∇I|²), g_min) of an ``(H, W, C)`` image.

    ``|∇I|²`` is the squared gradient magnitude averaged over channels.

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    if c <= 0:
        return np.ones(image.shape[:2], np.float32)
    dx, dy = image_derivatives(image)
    mag2 = (dx * dx + dy * dy).mean(axis=2)
    return np.maximum(np.exp(-c * mag2), g_min).astype(np.float32)


@nb.njit(cache=True, parallel=True, fastmath=True)
def tvl1_iterations(ix, iy, a, g, u, p, q, lam, theta, tau, max_iter, tol, n_sweeps):
    """Numba TV-L1 iterations at one warp; updates ``u``, ``p``, ``q`` in place.

    Channels whose gradient vanishes (``|∇I1w_c|² < 1e-12``) take no part in the
    data prox.

    Parameters
    ----------
    ix, iy : (H, W, C) float32
        Derivatives of the warped second frame (zero where the data term is off).
    a : (H, W, C) float32
        Residual at zero flow, ``I1w - I0 - ix*u0_1 - iy*u0_2`` (zero where off).
    g : (H, W) float32
        TV edge weight.
    u : (H, W, 2) float32
        Flow, updated in place.
    p : (H, W, 2, 2) float32
        Dual TV variable per flow component, ``p[..., k, :]`` for component k.
    q : (H, W, C) float32
        Dual variable of the data prox (warm start).

    Returns
    -------
    int
        Iterations performed.
    """
    h, w, nc = a.shape
    t = lam * theta
    step = tau / theta
    errs = np.zeros(h, np.float64)
    tol2 = tol * tol
    inv = np.empty_like(a)  # 1 / (t |g_c|^2), 0 where the gradient vanishes
    for i in nb.prange(h):
        for j in range(w):
            for c in range(nc):
                nn = ix[i, j, c] * ix[i, j, c] + iy[i, j, c] * iy[i, j, c]
                inv[i, j, c] = 1.0 / (t * nn) if nn >= 1e-12 else 0.0
    it = 0
    while it < max_iter:
        it += 1
        for i in nb.prange(h):
            err = 0.0
            for j in range(w):
                u1 = u[i, j, 0]
                u2 = u[i, j, 1]
                d1 = u1
                d2 = u2
                for c in range(nc):
                    d1 -= t * q[i, j, c] * ix[i, j, c]
                    d2 -= t * q[i, j, c] * iy[i, j, c]
                for _s in range(n_sweeps):
                    for c in range(nc):
                        gx = ix[i, j, c]
                        gy = iy[i, j, c]
                        qo = q[i, j, c]
                        e1 = d1 + t * qo * gx
                        e2 = d2 + t * qo * gy
                        qn = (a[i, j, c] + gx * e1 + gy * e2) * inv[i, j, c]
                        qn = min(max(qn, -1.0), 1.0)
                        q[i, j, c] = qn
                        d1 = e1 - t * qn * gx
                        d2 = e2 - t * qn * gy
                for k in range(2):
                    if j == 0:
                        dv = p[i, j, k, 0]
                    elif j == w - 1:
                        dv = -p[i, j - 1, k, 0]
                    else:
                        dv = p[i, j, k, 0] - p[i, j - 1, k, 0]
                    if i == 0:
                        dv += p[i, j, k, 1]
                    elif i == h - 1:
                        dv -= p[i - 1, j, k, 1]
                    else:
                        dv += p[i, j, k, 1] - p[i - 1, j, k, 1]
                    if k == 0:
                        n1 = d1 + theta * dv
                        err += (n1 - u1) * (n1 - u1)
                        u[i, j, 0] = n1
                    else:
                        n2 = d2 + theta * dv
                        err += (n2 - u2) * (n2 - u2)
                        u[i, j, 1] = n2
            errs[i] = err
        for i in nb.prange(h):
            for j in range(w):
                lim = g[i, j]
                for k in range(2):
                    gx = u[i, j + 1, k] - u[i, j, k] if j < w - 1 else 0.0
                    gy = u[i + 1, j, k] - u[i, j, k] if i < h - 1 else 0.0
                    px = p[i, j, k, 0] + step * gx
                    py = p[i, j, k, 1] + step * gy
                    nrm = math.sqrt(px * px + py * py)
                    if nrm > lim:
                        s = lim / nrm
                        px *= s
                        py *= s
                    p[i, j, k, 0] = px
                    p[i, j, k, 1] = py
        if errs.sum() / (h * w) < tol2:
            break
    return it


def tvl1_iterations_numpy(ix, iy, a, g, u, p, q, lam, theta, tau, max_iter, tol, n_sweeps):
    """NumPy reference of :func:`tvl1_iterations` (same arguments, same in-place updates)."""
    h, w, _ = a.shape
    t = lam * theta
    it = 0
    while it < max_iter:
        it += 1
        d, qn = prox_linear_l1(u, a, ix, iy, t, n_sweeps=n_sweeps, q0=q)
        q[...] = qn
        new = np.stack([d[..., k] + theta * divergence(p[..., k, :]) for k in range(2)], -1)
        err = float(((new - u) ** 2).sum()) / (h * w)
        u[...] = new
        for k in range(2):
            p[..., k, :] = project_l2_ball(p[..., k, :] + (tau / theta) * gradient(u[..., k]), g)
        if err < tol * tol:
            break
    return it


def solve_warp(
    I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TVL1Params, state: dict, engine: str = "numba"
):
    """Single-level, single-warp TV-L1 solver (the method's plug-in to the driver).

    Parameters
    ----------
    I0, I1w, I1w_dx, I1w_dy : ndarray, shape (H, W, C), float32
        Reference frame, warped second frame and its warped derivatives.
    inside : ndarray, shape (H, W), bool
        Pixels whose warped position lies inside the second frame; the data term is
        switched off elsewhere.
    flow0 : ndarray, shape (H, W, 2), float32
        Linearisation point (and initial value).
    params : TVL1Params
    state : dict
        Per-level state: dual variables ``p`` and ``q`` and the edge weight ``g``.
    engine : {"numba", "numpy"}

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    h, w, nc = I0.shape
    if "g" not in state:
        state["g"] = edge_weight(I0, params.edge_weight, params.edge_weight_min)
        prev = state.get("previous") or {}
        if "p" in prev:  # warm start the TV dual from the coarser level
            p = resize_bilinear(prev["p"].reshape(prev["p"].shape[:2] + (4,)), (h, w))
            p = project_l2_ball(p.reshape(h, w, 2, 2), state["g"][..., None])
            state["p"] = np.ascontiguousarray(p, dtype=np.float32)
        else:
            state["p"] = np.zeros((h, w, 2, 2), np.float32)
        state["q"] = np.zeros((h, w, nc), np.float32)
    m = inside[..., None].astype(np.float32)
    ix = np.ascontiguousarray(I1w_dx * m, dtype=np.float32)
    iy = np.ascontiguousarray(I1w_dy * m, dtype=np.float32)
    a = (I1w - I0 - ix * flow0[..., :1] - iy * flow0[..., 1:2]) * m
    a = np.ascontiguousarray(a, dtype=np.float32)
    u = np.array(flow0, dtype=np.float32, order="C")
    fn = tvl1_iterations if engine == "numba" else tvl1_iterations_numpy
    n = fn(
        ix,
        iy,
        a,
        state["g"],
        u,
        state["p"],
        state["q"],
        np.float32(params.data_weight),
        np.float32(params.coupling),
        np.float32(params.tv_step),
        params.max_iterations,
        np.float32(params.tolerance),
        params.data_sweeps,
    )
    state["iterations"] = state.get("iterations", 0) + n
    return u


def tvl1(frame0, frame1, params: TVL1Params | None = None, init_flow=None, callback=None):
    """TV-L1 optical flow from ``frame0`` to ``frame1``.

    Parameters
    ----------
    frame0, frame1 : ndarray, shape (H, W) or (H, W, C)
        uint8, uint16 or float in [0, 1].  Colour images use the vector-valued data
        term (one L1 residual per channel).
    params : TVL1Params, optional
    init_flow : ndarray, shape (H, W, 2), optional
    callback : callable, optional
        ``callback(done, total)`` after every warp.

    Returns
    -------
    ndarray, shape (H, W, 2), float32

    References
    ----------
    C. Zach, T. Pock, H. Bischof, "A duality based approach for realtime TV-L1
    optical flow", DAGM 2007.  A. Wedel et al., "An improved algorithm for TV-L1
    optical flow", 2009.  L. Rakêt et al., "TV-L1 optical flow for vector valued
    images", EMMCVPR 2011.  D. Sun, S. Roth, M. Black, "Secrets of optical flow
    estimation and their principles", CVPR 2010.
    """
    return coarse_to_fine(
        frame0, frame1, solve_warp, params or TVL1Params(), init_flow=init_flow, callback=callback
    )
