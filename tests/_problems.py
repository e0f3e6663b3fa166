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


def to_u8(img):
    """Float image in [0, 1] -> uint8 (rounded, clipped)."""
    return np.clip(np.rint(np.asarray(img, np.float64) * 255.0), 0, 255).astype(np.uint8)


def wave_texture(shape, shift, seed=0):
    """A smooth colour texture (sum of plane waves) translated by ``shift`` = (x, y), uint8."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    x, y = x - shift[0], y - shift[1]
    img = np.full(tuple(shape) + (3,), 0.5)
    for c in range(3):
        for _ in range(6):
            a, f, ph = rng.uniform(0, np.pi), rng.uniform(0.15, 0.45), rng.uniform(0, 2 * np.pi)
            img[..., c] += 0.075 * np.sin(f * (np.cos(a) * x + np.sin(a) * y) + ph)
    return to_u8(img)
