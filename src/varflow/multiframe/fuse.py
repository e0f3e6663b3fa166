"""RLR's decoupled fusion: per pixel and frame, the linked or the decoupled refinement.

:func:`fuse_decoupled` compares the soft-census cost of the trajectories refined
with the low-rank link and without it, and keeps (or blends towards) the decoupled
displacement where the data say it fits better; :func:`regional_evidence` on
:func:`texture_mask` lets a flat region follow its textured surroundings.  Used by
:func:`varflow.multiframe.rlr.track_rlr` (``decoupled_fusion``).
"""

from __future__ import annotations

import numpy as np
from scipy.special import expit

from ..ops.fusion import census_planes, flow_cost, fuse, support_weights
from ..ops.pyramid import smooth_image

__all__ = ["texture_mask", "regional_evidence", "fuse_decoupled"]


def texture_mask(image: np.ndarray) -> np.ndarray:
    """The textured half of an image: gradient magnitude of its channel mean above the median.

    Parameters
    ----------
    image : ndarray, shape (H, W[, C]), float

    Returns
    -------
    ndarray, shape (H, W), float32, 0 or 1 (all 0 on a flat image)
    """
    grey = np.asarray(image, np.float32)
    if grey.ndim == 3:
        grey = grey.mean(axis=-1)
    gy, gx = np.gradient(grey)
    mag = np.hypot(gx, gy)
    return (mag > np.median(mag)).astype(np.float32)


def regional_evidence(diff: np.ndarray, texture: np.ndarray, radius: float,
                      support: np.ndarray | None = None) -> np.ndarray:
    """The Gaussian-weighted mean of ``diff`` over the textured pixels around each pixel.

    ``E = G_σ * (diff · t) / G_σ * t`` (:func:`varflow.ops.pyramid.smooth_image`,
    σ = ``radius``), 0 where no textured pixel is near (``G_σ * t`` < 1e-6).

    Parameters
    ----------
    diff : ndarray, shape (H, W), float32
    texture : ndarray, shape (H, W), float32
        :func:`texture_mask` of the reference.
    radius : float
        σ in pixels.
    support : ndarray, shape (H, W), float32, optional
        ``G_σ * t``, when the caller smooths one texture for many ``diff``
        (computed here when omitted).

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    num = smooth_image((diff * texture)[..., None], radius)[..., 0]
    den = smooth_image(texture[..., None], radius)[..., 0] if support is None else support
    out = np.zeros_like(num)
    np.divide(num, den, out=out, where=den >= 1e-6)
    return out


def fuse_decoupled(frames: np.ndarray, ref: int, coupled: np.ndarray, decoupled: np.ndarray,
                   margin: float, softness: float = 0.0, evidence: float = 0.0,
                   radius: float = 8.0) -> tuple[np.ndarray, float]:
    """Per pixel and frame, the coupled or the decoupled trajectory, by the data.

    For every frame ``n ≠ ref`` the edge-aware soft-census cost of both
    displacement fields (:func:`varflow.ops.fusion.flow_cost` on
    :func:`~varflow.ops.fusion.census_planes`, truncation 0.5, the support weights
    of the reference) is compared.  With ``softness`` 0 the decoupled displacement
    is kept where its cost ``C_d`` is lower than the coupled one's ``C_c`` by more
    than ``margin`` (as :func:`varflow.ops.fusion.fuse` with that margin).  With
    ``softness`` κ > 0 the two are blended,

    ``w = 1 / (1 + exp(−(C_c − C_d − m) / (κ m)))``,  ``u = u_c + w (u_d − u_c)``,

    a logistic step of width κ·m centred on the margin: where the cost tells the two
    apart clearly the result is the better one, and where it hardly does (a flat
    region, a change of light) it is a mixture, which lies between the two and is
    closer than either where their errors point different ways.  The low-rank link
    thus stays where the frames do not say otherwise, and a region whose motion the
    link has pulled off the data gets the decoupled refinement back.

    With ``evidence`` γ > 0 the cost difference of a pixel is joined by that of its
    region: ``C_c − C_d`` is replaced by ``C_c − C_d + γ E``, E the mean of
    ``C_c − C_d`` over the textured pixels within about ``radius`` pixels
    (:func:`regional_evidence` on :func:`texture_mask` of the reference).  Where
    the two runs fit equally (a flat sky, a smooth wall) the textured surroundings,
    whose costs do tell them apart, decide: if the link has pulled the textured
    part of a region off its data in frame n, it is not trusted over the flat part
    either.

    Parameters
    ----------
    frames : ndarray, shape (F, H, W, C), float32
    ref : int
    coupled, decoupled : ndarray, shape (F, H, W, 2), float32
        Trajectories refined with the link and without it (``link_weight = 0``).
    margin : float
        m, the cost advantage the decoupled displacement needs (the centre of the
        blend when ``softness`` > 0).
    softness : float
        κ, the width of the blend as a fraction of ``margin``; 0 (or ``margin`` 0)
        is the hard choice.
    evidence : float
        γ, the weight of the regional cost difference; 0 compares each pixel alone.
    radius : float
        σ of the region, pixels.

    Returns
    -------
    traj : ndarray, shape (F, H, W, 2), float32
    share : float
        Mean weight of the decoupled displacement over the (pixel, frame) pairs,
        reference excluded (with the hard choice, the share that took it).
    """
    out = np.array(coupled, np.float32, copy=True)
    planes = census_planes(frames[ref])
    weights = support_weights(frames[ref])
    width = float(softness) * float(margin)
    texture = texture_mask(frames[ref]) if evidence > 0 else None
    support = None  # G_σ * texture: the same for every frame
    if texture is not None:
        support = smooth_image(texture[..., None], radius)[..., 0]
    taken = 0.0
    others = [n for n in range(frames.shape[0]) if n != ref]
    for n in others:
        planes_n = census_planes(frames[n])
        if width > 0 or texture is not None:
            cost_c = flow_cost(planes, planes_n, coupled[n], weights, truncation=0.5)
            cost_d = flow_cost(planes, planes_n, decoupled[n], weights, truncation=0.5)
            diff = cost_c - cost_d
            if texture is not None:
                diff = diff + np.float32(evidence) * regional_evidence(diff, texture, radius,
                                                                       support)
            if width > 0:
                w = expit((diff - np.float32(margin)) / np.float32(width))
                out[n] += w[..., None] * (np.asarray(decoupled[n], np.float32) - out[n])
                taken += float(w.sum(dtype=np.float64))
            else:  # the hard choice keeps either displacement bit for bit
                choice = diff > np.float32(margin)
                out[n][choice] = np.asarray(decoupled[n], np.float32)[choice]
                taken += int(choice.sum())
        else:
            out[n], choice = fuse(planes, planes_n, [coupled[n], decoupled[n]], weights,
                                  truncation=0.5, margin=margin)
            taken += int(choice.sum())
    share = taken / max(1, len(others) * frames.shape[1] * frames.shape[2])
    return out, float(share)
