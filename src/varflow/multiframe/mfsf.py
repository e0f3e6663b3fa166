"""Multi-Frame Subspace Flow (MFSF), the baseline of Garg, Roussos & Agapito (IJCV 2013).

Trajectories are kept near a subspace spanned by ``2R`` fixed basis trajectories
``P`` (shape ``(2F, 2R)``, rows in the order of the trajectory matrix of
:mod:`varflow.multiframe.lowrank`) through a soft constraint::

    E(U, Q) = Σ_n [ λ_D Σ_c |ρ_{n,c}(u_n)| + λ_TV TV_g(u_n) ] + β/2 ||U − P Q||²

with the same data and TV terms as RLR (:mod:`varflow.multiframe.rlr`).  It is
minimised by alternation in the same multi-frame driver
(:func:`varflow.multiframe.refine.refine_trajectories`): the Q-step is the least-squares
fit ``Q = P⁺ U`` over the frames other than the reference (whose displacement is
zero by definition), and the U-step is RLR's per-frame primal-dual iteration with
the quadratic folded into the point-wise prox.

Bases (``basis``):

* ``"dct"`` — the first R orthonormal DCT-II functions over the F frames, applied to
  u and to v (smooth motion in time).
* ``"pca"`` — the 2R leading left singular vectors of the initial trajectory matrix
  (the two-frame initialisation), computed once.

References
----------
R. Garg, A. Roussos, L. Agapito, "A variational approach to video registration with
subspace constraints", Int. J. Comput. Vis. 104(3), 2013.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import check_field as _check
from .lowrank import matrix_to_trajectories, trajectories_to_matrix
from .params import MultiFrameParams
from .refine import Coupling, refine_trajectories
from .track import TrackCallback

__all__ = ["MFSFParams", "dct_basis", "pca_basis", "track_mfsf"]


@dataclass(frozen=True)
class MFSFParams(MultiFrameParams):
    """Parameters of MFSF (and those of :class:`~varflow.multiframe.params.MultiFrameParams`).

    Attributes
    ----------
    basis : {"pca", "dct"}
        Basis trajectories: PCA of the initial estimate, or temporal DCT.
        Default "pca".
    n_basis : int
        R: basis functions per displacement component (``P`` has 2R columns).
        Default 6, the most accurate of 3, 4 and 6 on the synthetic suite (see
        benchmarks/HISTORY.md).
    subspace_weight : float
        β of the soft constraint ``β/2 ||U − P Q||²`` (1/pixel², relative to the TV
        weight); 0 decouples the frames.  Default 10: on the synthetic suite as
        accurate as 30 and more than 3 (see benchmarks/HISTORY.md).
    """

    basis: str = "pca"
    n_basis: int = 6
    subspace_weight: float = 10.0

    def __post_init__(self) -> None:
        super().__post_init__()
        _check(self.basis in ("pca", "dct"), "basis",
               f"must be 'pca' or 'dct', got {self.basis!r}")
        _check(self.n_basis >= 1, "n_basis", f"must be >= 1, got {self.n_basis}")
        _check(self.subspace_weight >= 0, "subspace_weight",
               f"must be >= 0, got {self.subspace_weight}")


def dct_basis(n_frames: int, n_basis: int) -> np.ndarray:
    """Temporal DCT basis trajectories.

    Parameters
    ----------
    n_frames : int
        F.
    n_basis : int
        R, DCT-II functions per component (clipped to F).

    Returns
    -------
    ndarray, shape (2F, 2R'), float64, R' = min(R, F)
        ``P[2n + k, 2r + k] = φ_r(n)`` with the orthonormal DCT-II functions
        ``φ_r(n) ∝ cos(π (n + 1/2) r / F)``; orthonormal columns.
    """
    r = min(int(n_basis), int(n_frames))
    n = np.arange(n_frames)[:, None]
    phi = np.cos(np.pi * (n + 0.5) * np.arange(r)[None, :] / n_frames)
    phi /= np.linalg.norm(phi, axis=0, keepdims=True)
    p = np.zeros((2 * n_frames, 2 * r))
    p[0::2, 0::2] = phi
    p[1::2, 1::2] = phi
    return p


def pca_basis(traj: np.ndarray, n_basis: int) -> np.ndarray:
    """The 2R leading left singular vectors of a trajectory matrix.

    Parameters
    ----------
    traj : ndarray, shape (F, H, W, 2)
    n_basis : int
        R (2R columns, clipped to 2F).

    Returns
    -------
    ndarray, shape (2F, 2R'), float64, orthonormal columns
    """
    u = trajectories_to_matrix(traj).astype(np.float64)
    left, _, _ = np.linalg.svd(u, full_matrices=False)
    return left[:, : min(2 * int(n_basis), u.shape[0])]


def track_mfsf(frames: np.ndarray, ref: int, params: MFSFParams,
               callback: TrackCallback | None = None, engine: str = "numba",
               stats: dict | None = None) -> np.ndarray:
    """MFSF trajectories (see the module docstring).

    Arguments as in :func:`varflow.multiframe.refine.refine_trajectories`.

    Returns
    -------
    ndarray, shape (F, H, W, 2), float32
    """
    n_frames = frames.shape[0]
    keep = np.ones(2 * n_frames, bool)
    keep[2 * ref: 2 * ref + 2] = False
    cache: dict = {}

    def project(traj: np.ndarray, visible: np.ndarray | None) -> np.ndarray:
        if "pinv" not in cache:
            if params.basis == "dct":
                p = dct_basis(n_frames, params.n_basis)
            else:
                p = pca_basis(traj, params.n_basis)
            cache["P"] = p
            cache["pinv"] = np.linalg.pinv(p[keep])
        u = trajectories_to_matrix(traj).astype(np.float64)
        fit = cache["P"] @ (cache["pinv"] @ u[keep])
        fit[~keep] = 0.0
        return matrix_to_trajectories(fit.astype(np.float32), traj.shape[1], traj.shape[2])

    coupling = Coupling("l2", float(params.subspace_weight), project)
    return refine_trajectories(frames, ref, params, coupling, callback, engine, stats)
