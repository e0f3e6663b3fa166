"""Shared test problems (imported by the test modules; not collected by pytest)."""

import numpy as np

from varflow.generators.pairs import synthetic_pair
from varflow.ops.differences import image_derivatives
from varflow.ops.warp import warp_bicubic
from varflow.twoframe.tvl1 import linearise, planar


def linearised_sparse_problem(seed=5, shape=(40, 48), aniso=False):
    """One warp of a smooth synthetic pair, linearised at 0.8 × the true flow.

    Returns ``terms`` (ix, iy, a, g, tens for the kernels), a noisy sparse target
    ``ubar`` (2, H, W), the generator used (for further draws) and ``u0`` (2, H, W).
    """
    f0, f1, gt = synthetic_pair("smooth", shape=shape, magnitude=1.5, channels=3, seed=seed)
    dx, dy = image_derivatives(f1)
    flow0 = (0.8 * gt).astype(np.float32)
    warped, inside = warp_bicubic(np.concatenate([f1, dx, dy], 2), flow0)
    ix, iy, a = linearise(f0, warped[..., :3], warped[..., 3:6], warped[..., 6:], inside, flow0)
    h, w = shape
    rng = np.random.default_rng(seed)
    g = rng.uniform(0.3, 1.0, (h, w)).astype(np.float32)
    if aniso:
        ang = rng.uniform(0, np.pi, (h, w))
        k = rng.uniform(0, 0.8, (h, w))
        tens = np.stack([1 - k * np.cos(ang) ** 2, -k * np.cos(ang) * np.sin(ang),
                         1 - k * np.sin(ang) ** 2]).astype(np.float32)
    else:
        tens = np.zeros((3, 1, 1), np.float32)
    ubar = planar(gt + rng.normal(0, 0.05, gt.shape).astype(np.float32))
    return dict(ix=ix, iy=iy, a=a, g=g, tens=tens), ubar, rng, planar(flow0)
