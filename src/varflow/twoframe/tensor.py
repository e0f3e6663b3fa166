"""Tensor-directed (anisotropic) TV-L1: the regulariser follows the image structure.

The isotropic term ``Σ_k |∇u_k|`` of TV-L1 is replaced by ``Σ_k |D ∇u_k|`` with the
per-pixel tensor (Werlberger, Trobin, Pock, Wedel, Cremers & Bischof, "Anisotropic
Huber-L1 optical flow", BMVC 2009; Gibson & Marques 2016, ch. 3)::

    D(x) = g(|∇I|) n nᵀ + n⊥ n⊥ᵀ = I − (1 − g) n nᵀ,     g(s) = exp(−a s^b),

where ``n`` is the dominant direction of the image gradient.  Across an edge (along
``n``) the flow may jump at a cost reduced by ``g``; along the edge (``n⊥``)
smoothing is full.  In flat regions ``g ≈ 1`` and ``D ≈ I``; with ``a = 0``, ``D = I``
exactly and the method is isotropic TV-L1.

For colour images ``n`` and ``|∇I|`` come from the channel-averaged structure
tensor ``J = G_σ * (1/C) Σ_c ∇I_c ∇I_cᵀ``: ``n`` is its principal eigenvector and
``|∇I|`` the square root of the principal eigenvalue.

The primal-dual iterations are those of :mod:`varflow.twoframe.tvl1` (the dual step
becomes ``p ← Π(p + (τ/θ) D ∇u)`` and the primal step uses ``div(D p)``); ``D`` has
spectral norm ≤ 1, so the step bound τ ≤ 1/4 still holds.

Symbol map: a = ``tensor_a``, b = ``tensor_b``, σ = ``tensor_sigma``; the rest as in
:class:`~varflow.twoframe.tvl1.TVL1Params`.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..ops.differences import image_derivatives
from .coarse_to_fine import LevelState
from .params import FULL_ENERGY_TENSOR_A, TensorTerm, TVL1Params, deprecated_preset
from .tvl1 import TVL1State, edge_weight, init_level_state, level_state, run_warp

__all__ = [
    "TensorTerm",
    "TensorFields",
    "TensorParams",
    "TVL1TensorParams",
    "FULL_ENERGY_TENSOR_A",
    "diffusion_tensor",
    "init_tensor_level",
    "solve_warp",
]


TensorFields = TensorTerm  # the former mixin's name
TensorParams = deprecated_preset("TensorParams", "tensor")
TVL1TensorParams = deprecated_preset("TVL1TensorParams", "tvl1-tensor")


def diffusion_tensor(
    image: np.ndarray, a: float, b: float, sigma: float = 1.0, g_min: float = 0.05
) -> np.ndarray:
    """The tensor ``D = I − (1 − g) n nᵀ`` of an ``(H, W, C)`` image.

    Parameters
    ----------
    image : ndarray, shape (H, W, C), float32
    a, b : float
        ``g(s) = max(exp(-a s^b), g_min)`` with ``s = |∇I|`` (square root of the principal
        eigenvalue of the channel-averaged structure tensor).
    sigma : float
        Gaussian smoothing of the structure tensor, pixels (0: none).
    g_min : float
        Lower bound of g, in (0, 1].

    Returns
    -------
    ndarray, shape (3, H, W), float32
        (D11, D12, D22).  Symmetric, eigenvalues g (along n) and 1 (along n⊥).
    """
    h, w = image.shape[:2]
    out = np.empty((3, h, w), np.float32)
    if a == 0:
        out[0] = 1.0
        out[1] = 0.0
        out[2] = 1.0
        return out
    dx, dy = image_derivatives(image)
    j11 = (dx * dx).mean(axis=2)
    j12 = (dx * dy).mean(axis=2)
    j22 = (dy * dy).mean(axis=2)
    if sigma > 0:
        j11, j12, j22 = (ndimage.gaussian_filter(j, sigma, mode="nearest") for j in (j11, j12, j22))
    # principal eigenpair of [[j11, j12], [j12, j22]]
    half_tr = 0.5 * (j11 + j22)
    disc = np.sqrt(np.maximum(0.25 * (j11 - j22) ** 2 + j12 * j12, 0.0))
    lam1 = half_tr + disc
    # eigenvector (lam1 - j22, j12), or (j12, lam1 - j11): pick the better conditioned
    vx1, vy1 = lam1 - j22, j12
    vx2, vy2 = j12, lam1 - j11
    use1 = vx1 * vx1 + vy1 * vy1 >= vx2 * vx2 + vy2 * vy2
    vx = np.where(use1, vx1, vx2)
    vy = np.where(use1, vy1, vy2)
    nrm = np.sqrt(vx * vx + vy * vy)
    flat = nrm < 1e-12
    nrm = np.where(flat, 1.0, nrm)
    nx, ny = vx / nrm, vy / nrm
    s = np.sqrt(np.maximum(lam1, 0.0))
    g = np.maximum(np.exp(-a * s**b), g_min)
    k = np.where(flat, 0.0, 1.0 - g)
    out[0] = 1.0 - k * nx * nx
    out[1] = -k * nx * ny
    out[2] = 1.0 - k * ny * ny
    return out


def init_tensor_level(I0: np.ndarray, params: TVL1Params, state: TVL1State) -> None:
    """Per-level state of tensor-directed TV-L1: edge weight, tensor ``D`` and duals.

    ``params`` is a TV-L1 energy with a :class:`~varflow.twoframe.params.TensorTerm`.
    """
    g = edge_weight(I0, params.edge_weight, params.edge_weight_min)
    t = params.tensor
    tens = diffusion_tensor(I0, t.tensor_a, t.tensor_b, t.tensor_sigma, params.edge_weight_min)
    init_level_state(state, I0.shape, g, tens)


def solve_warp(
    I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TVL1Params, state: LevelState,
    engine: str = "numba",
):
    """Single-level, single-warp tensor-directed TV-L1 solver (plug-in to the driver).

    Arguments as in :func:`varflow.twoframe.tvl1.solve_warp`; ``params.tensor`` is the
    :class:`~varflow.twoframe.params.TensorTerm`.  The tensor is computed from ``I0``
    once per level and kept in the solver's state (``state.data.tensor``).

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    st = level_state(state)
    if st.g is None:
        init_tensor_level(I0, params, st)
    return run_warp(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params, st, engine)


solve_warp.planar_flow = True  # type: ignore[attr-defined]  # as tvl1's
