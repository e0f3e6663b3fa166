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

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..ops.differences import image_derivatives
from .coarse_to_fine import LevelState, _check
from .tvl1 import PlainTVL1Params, TVL1Params, edge_weight, init_level_state, run_warp

__all__ = [
    "TensorFields",
    "TensorParams",
    "TVL1TensorParams",
    "FULL_ENERGY_TENSOR_A",
    "diffusion_tensor",
    "init_tensor_level",
    "solve_warp",
]


#: a of the tensor on ``tvl1``'s energy (:class:`TVL1TensorParams`, and the
#: ``tvl1-sparse-*`` methods' tensor regulariser): tuned on the photographic tuning split.
FULL_ENERGY_TENSOR_A = 0.5


@dataclass(frozen=True)
class TensorFields:
    """The fields of the tensor-directed regulariser, to compose onto a TV-L1 energy.

    A mixin: put it before a :class:`~varflow.twoframe.tvl1.TVL1Params` subclass in
    the bases (``class P(TensorFields, TVL1Params)``); its checks run after those
    of the energy.  :class:`TensorParams` composes it with the book's plain energy,
    :class:`TVL1TensorParams` with ``tvl1``'s.

    Attributes
    ----------
    tensor_a : float
        a of g(s) = exp(-a s^b), the weight across edges (``s = |∇I|`` in intensity/pixel,
        images in [0, 1]); 0 gives D = identity (isotropic TV).  Default 3.
    tensor_b : float
        b of g(s) = exp(-a s^b), > 0.  Default 0.5.
    tensor_sigma : float
        σ of the Gaussian that smooths the structure tensor, pixels; 0 uses the
        gradient itself.  Default 1.
    """

    tensor_a: float = 3.0
    tensor_b: float = 0.5
    tensor_sigma: float = 1.0

    def __post_init__(self) -> None:
        super().__post_init__()  # the energy's checks (the next class in the MRO)
        _check(self.tensor_a >= 0, "tensor_a", f"must be >= 0, got {self.tensor_a}")
        _check(self.tensor_b > 0, "tensor_b", f"must be > 0, got {self.tensor_b}")
        _check(self.tensor_sigma >= 0, "tensor_sigma", f"must be >= 0, got {self.tensor_sigma}")


@dataclass(frozen=True)
class TensorParams(TensorFields, PlainTVL1Params):
    """Parameters of tensor-directed TV-L1 on the book's plain energy (method ``tensor``).

    The fields of :class:`~varflow.twoframe.tvl1.PlainTVL1Params` and of
    :class:`TensorFields`.

    Attributes
    ----------
    edge_weight : float
        c of the isotropic edge weight ``exp(-c |∇I0|²)`` (the radius of the dual ball);
        the tensor already carries the edge information, so it is off here.  Default 0.
    """

    edge_weight: float = 0.0


@dataclass(frozen=True)
class TVL1TensorParams(TensorFields, TVL1Params):
    """Tensor-directed TV-L1 on ``tvl1``'s energy (method ``tvl1-tensor``).

    The fields of :class:`~varflow.twoframe.tvl1.TVL1Params` (grey channel,
    gradient constancy, Huber-TV, noise rule, weighted median, sharpness match, with
    their defaults) and of :class:`TensorFields`; the tensor replaces the isotropic
    TV of every warp.  With ``tensor_a = 0`` it is ``tvl1`` with the same
    ``edge_weight``.

    Attributes
    ----------
    edge_weight : float
        c of the isotropic edge weight ``exp(-c |∇I0|²)`` beside the tensor (the radius of
        the dual ball); 0 leaves the edges to the tensor alone.  Default 0 (better
        than 30 at every a on the photographic tuning split).
    tensor_a : float
        a of g(s) = exp(-a s^b), the weight across edges (``s = |∇I|`` in intensity/pixel,
        images in [0, 1]); 0 gives D = identity (isotropic TV).  Default 0.5: on the
        photographic tuning split (21 pairs) mean AEE 0.076 / 0.076 / 0.077 / 0.078 /
        0.080 / 0.085 for a = 0 / 0.25 / 0.5 / 1 / 1.5 / 3 (edge weight 0; tvl1
        0.080), the largest a within 0.001 of the best (benchmarks/README.md, issue
        27 part 6); the plain energy's 3 costs 0.009 here.
    """

    edge_weight: float = 0.0
    tensor_a: float = FULL_ENERGY_TENSOR_A


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


def init_tensor_level(I0: np.ndarray, params: TensorFields, state: LevelState) -> None:
    """Per-level state of tensor-directed TV-L1: edge weight, tensor ``D`` and duals.

    ``params`` is any TV-L1 parameter class with the :class:`TensorFields`.
    """
    g = edge_weight(I0, params.edge_weight, params.edge_weight_min)
    tens = diffusion_tensor(I0, params.tensor_a, params.tensor_b, params.tensor_sigma,
                            params.edge_weight_min)
    init_level_state(state, I0.shape, g, tens)


def solve_warp(
    I0, I1w, I1w_dx, I1w_dy, inside, flow0, params: TensorFields, state: LevelState,
    engine: str = "numba",
):
    """Single-level, single-warp tensor-directed TV-L1 solver (plug-in to the driver).

    Arguments as in :func:`varflow.twoframe.tvl1.solve_warp`; the tensor is computed
    from ``I0`` once per level and kept in ``state.tensor``.

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    if state.g is None:
        init_tensor_level(I0, params, state)
    return run_warp(I0, I1w, I1w_dx, I1w_dy, inside, flow0, params, state, engine)
