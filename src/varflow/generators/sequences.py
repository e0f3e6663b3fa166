"""Synthetic image sequences with exact dense trajectories and visibility.

Multi-frame counterpart of :mod:`varflow.generators.pairs`: clips of ``F``
frames (typically 20-60) of analytic textures
(:class:`~varflow.generators.pairs.TextureField`) under known motions, with
the exact trajectory of every pixel of a reference frame and whether it is
visible in each frame.  They follow the idea of the flag
benchmark of Garg, Roussos & Agapito (a deforming textured surface with ground
truth trajectories, plus noisy and occluded variants) with images the package
can produce itself.

Construction
------------
Every layer ``L`` of a scene carries an analytic texture ``T_L`` defined on
*texture coordinates* ``p`` and, for every frame ``n``, an invertible map
``M_n: p -> frame-n position``.  Frame ``n`` is rendered by point sampling,
back to front::

    I_n(q) = T_L(M_n^{-1}(q))      (front-most layer L whose region contains M_n^{-1}(q))

so each pixel centre ``q`` looks up the exact *backward* position in the texture;
the inverse is analytic for affine maps and computed by Newton iteration to
about 1e-9 px for the non-rigid one.  The point seen at pixel ``x`` of the
reference frame ``ref`` has texture coordinates ``p = M_ref^{-1}(x)`` and is at
``M_n(p)`` in frame ``n``, so its trajectory is::

    traj[n, x] = M_n(M_ref^{-1}(x)) - x,          traj[ref] = 0 exactly,

evaluated in float64 from the analytic maps: there is no interpolation error in
the ground truth (only the final cast to float32).  The maps ``M_n`` do not
depend on ``ref``, so the frames are the same for every choice of reference.
(The texture is evaluated by a faster routine that agrees with
``TextureField.__call__`` to ~3e-7, i.e. float32 rounding.)

Layer and occluder boundaries are point sampled without anti-aliasing, so every
pixel shows exactly one surface point; near those boundaries any interpolating
method sees a step, which is part of the difficulty.

Visibility ``vis[n, x]`` is True when ``x + traj[n, x]`` lies inside
``[0, W-1] x [0, H-1]`` and is not covered in frame ``n`` by a layer in front of
the point's own layer (tested with the same predicate that renders that layer)
nor by the passing occluder.

Scenes
------
Time is ``t_n = n / (F - 1)`` in ``[0, 1]``, so the motion over the clip does
not depend on ``F`` (longer clips have smaller steps).  ``magnitude`` (px) is
the maximum displacement, over the sequence, of the pixels of the centre frame
``F // 2`` (the default reference); the motion amplitudes are calibrated to it
(exactly for affine motion, on a 17 x 17 grid of points for the non-rigid one).
The achieved maximum relative to the chosen ``ref`` is
``params["max_displacement"]``.

``"affine"``
    One textured plane under ``M_n(p) = c + A_n (p - c) + b_n`` with
    ``A_n = exp(z_n) R(theta_n) [[1, h_n], [0, 1]]``: a sinusoidal rotation
    ``theta``, a quadratic log-zoom ``z``, a sinusoidal shear ``h`` and a
    translation ``b`` that is linear plus a sinusoid in time.
``"nonrigid"``
    A waving textured sheet: ``M_n(p) = p + d_n + sum_k a_k e_k sin(kappa_k . p -
    omega_k t_n + phi_k)`` with four travelling waves of wavelength 0.6-1.3 x
    ``max(H, W)`` (the first one transverse and travelling along x, like a
    flag), a slow drift ``d_n``, and ``|grad s| <= 0.5`` so that ``M_n`` is
    invertible.
``"layers"``
    The affine background (calibrated to ``0.6 * magnitude``) and, in front, a
    textured disc of radius ``0.25 * min(H, W)`` that translates by
    ``2 * magnitude`` across the clip (plus a sideways wobble of
    ``0.2 * magnitude``), rotates by up to ``0.25 * magnitude / radius`` rad
    and zooms by up to 5 %.  Background points are occluded where
    the disc covers them; disc points stay visible (the disc stays in the image
    for the default settings).

Variants
--------
``"clean"``
    The rendered frames.
``"gaussian"``
    Additive white Gaussian noise of standard deviation ``noise_sigma``
    (default 0.04) on every sample of every frame, clipped to ``[0, 1]``.
``"saltpepper"``
    A fraction ``sp_fraction`` (default 5 %) of the pixels of every frame set to
    0 or 1 (all channels of a pixel alike, 0 and 1 equally likely).
``"occluder"``
    A flat dark vertical bar (value 0.1, width ``max(3, round(W / 8))`` px)
    sweeping from left to right at constant speed, entering at the reference
    frame and leaving at the last frame (or, when fewer frames follow the
    reference than precede it, entering at frame 0 and leaving at the
    reference), so that it never appears in the reference frame.  Points under
    it are not visible.

Noise is added to *all* frames, the reference included (a real reference frame
is noisy too); ``clean_frames`` keeps the noise-free frames.  Noise comes from a
local generator seeded by ``seed`` and independent of the motion, so the clean
frames of every variant with the same seed coincide.

References
----------
R. Garg, A. Roussos, L. Agapito, "A variational approach to video registration
with subspace constraints", International Journal of Computer Vision 104(3),
286-314, 2013 (the flag benchmark).

J. Gibson, O. Marques, "Optical Flow and Trajectory Estimation Methods",
SpringerBriefs in Computer Science, Springer 2016, ch. 4 (Table 4.2).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .pairs import TextureField

__all__ = [
    "SCENES",
    "VARIANTS",
    "SyntheticSequence",
    "make_sequence",
    "benchmark_cases",
    "benchmark_suite",
]

SCENES = ("affine", "nonrigid", "layers")
VARIANTS = ("clean", "gaussian", "saltpepper", "occluder")

_OCCLUDER_VALUE = 0.1
_MAX_STRAIN = 0.5  # bound on |grad s| for the non-rigid motion (keeps M_n invertible)
_NEWTON_TOL = 1e-9  # px
_NEWTON_MAX_ITER = 50


@dataclass
class SyntheticSequence:
    """A synthetic clip with exact trajectories (see the module notes).

    Attributes
    ----------
    frames : ndarray, shape (F, H, W, C), float32 in [0, 1]
        The frames of the variant (noisy for the noise variants).
    trajectories : ndarray, shape (F, H, W, 2), float32
        ``traj[n, y, x]`` = displacement of reference pixel ``(x, y)`` in frame
        ``n``: the point is at ``(x, y) + traj[n, y, x]``; ``[..., 0]`` = u
        (horizontal), ``[..., 1]`` = v (vertical); ``traj[ref] == 0``.
    visibility : ndarray, shape (F, H, W), bool
        True where the reference pixel's point is inside frame ``n`` and not
        occluded there; all True in the reference frame.
    ref : int
        Index of the reference frame.
    name : str
        Scene, one of :data:`SCENES`.
    variant : str
        One of :data:`VARIANTS`.
    clean_frames : ndarray, shape (F, H, W, C), float32
        The frames before noise is added (with the occluder, for that variant);
        the same object as ``frames`` for the noise-free variants.
    layer : ndarray, shape (H, W), uint8
        Layer of each reference pixel's point: 0 background, 1 foreground disc.
    seed : int
    params : dict
        Metadata: ``"magnitude"``, ``"max_displacement"`` (px, over all
        reference pixels and frames), ``"occluded_fraction"`` (share of the
        (frame != ref, pixel) pairs that are not visible: occluded or out of
        the frame), ``"times"``, the
        motion parameters, and per scene / variant ``"foreground"`` (centre
        ``(F, 2)`` and radius ``(F,)`` of the disc in each frame),
        ``"occluder"`` (bar width, left edge per frame, value),
        ``"noise_sigma"``, ``"sp_fraction"``.
    """

    frames: np.ndarray
    trajectories: np.ndarray
    visibility: np.ndarray
    ref: int
    name: str
    variant: str
    clean_frames: np.ndarray
    layer: np.ndarray
    seed: int = 0
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        """Number of frames F."""
        return int(self.frames.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        """Frame size ``(H, W)``."""
        return int(self.frames.shape[1]), int(self.frames.shape[2])


# --------------------------------------------------------------------------- motions


class _AffineMotion:
    """``M_n(p) = c + A_n (p - c) + b_n`` with ``A_n`` (F, 2, 2), ``b_n`` (F, 2)."""

    def __init__(self, a: np.ndarray, b: np.ndarray, centre: np.ndarray) -> None:
        self.a = np.asarray(a, np.float64)
        self.b = np.asarray(b, np.float64)
        self.c = np.asarray(centre, np.float64)
        self.ainv = np.linalg.inv(self.a)

    def forward(self, px: np.ndarray, py: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
        a, (cx, cy), (bx, by) = self.a[n], self.c, self.b[n]
        dx, dy = px - cx, py - cy
        return (
            a[0, 0] * dx + a[0, 1] * dy + cx + bx,
            a[1, 0] * dx + a[1, 1] * dy + cy + by,
        )

    def inverse(
        self, qx: np.ndarray, qy: np.ndarray, n: int, guess: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        ai, (cx, cy), (bx, by) = self.ainv[n], self.c, self.b[n]
        dx, dy = qx - cx - bx, qy - cy - by
        return ai[0, 0] * dx + ai[0, 1] * dy + cx, ai[1, 0] * dx + ai[1, 1] * dy + cy


class _WaveMotion:
    """``M_n(p) = p + d_n + sum_k amp_k e_k sin(kappa_k . p - omega_k t_n + phi_k)``."""

    def __init__(
        self,
        kappa: np.ndarray,
        direction: np.ndarray,
        amp: np.ndarray,
        omega: np.ndarray,
        phase: np.ndarray,
        drift: np.ndarray,
        times: np.ndarray,
    ) -> None:
        self.kappa = np.asarray(kappa, np.float64)  # (K, 2)
        self.direction = np.asarray(direction, np.float64)  # (K, 2) unit vectors
        self.amp = np.asarray(amp, np.float64)  # (K,)
        self.omega = np.asarray(omega, np.float64)  # (K,)
        self.phase = np.asarray(phase, np.float64)  # (K,)
        self.drift = np.asarray(drift, np.float64)  # (F, 2)
        self.times = np.asarray(times, np.float64)  # (F,)

    @property
    def strain_bound(self) -> float:
        """Upper bound of the spectral norm of ``grad s`` over space and time."""
        return float(np.sum(np.abs(self.amp) * np.hypot(*self.kappa.T)))

    def _eval(
        self, px: np.ndarray, py: np.ndarray, n: int
    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """``s_n(p)`` (float64) and the wave phases ``theta_k(p)``."""
        sx = np.full_like(px, self.drift[n, 0])
        sy = np.full_like(py, self.drift[n, 1])
        thetas = []
        t = self.times[n]
        for k in range(self.amp.size):
            theta = self.kappa[k, 0] * px
            theta += self.kappa[k, 1] * py
            theta += self.phase[k] - self.omega[k] * t
            sin = np.sin(theta)
            ex, ey = self.amp[k] * self.direction[k]
            sx += ex * sin
            sy += ey * sin
            thetas.append(theta)
        return sx, sy, thetas

    def _jacobian(self, thetas: list[np.ndarray]) -> list[np.ndarray]:
        """Entries ``[ds_x/dx, ds_x/dy, ds_y/dx, ds_y/dy]`` of ``grad s``.

        Only steers the Newton steps (the residual is float64), so the cosines
        are taken in float32 (SIMD, phases reduced to one period first).
        """
        j = [np.zeros(thetas[0].shape, np.float32) for _ in range(4)]
        for k, theta in enumerate(thetas):
            red = theta * (1.0 / (2 * np.pi))
            red -= np.rint(red)
            red *= 2 * np.pi
            cos = np.cos(red.astype(np.float32))
            ex, ey = self.amp[k] * self.direction[k]
            kx, ky = self.kappa[k]
            j[0] += np.float32(ex * kx) * cos
            j[1] += np.float32(ex * ky) * cos
            j[2] += np.float32(ey * kx) * cos
            j[3] += np.float32(ey * ky) * cos
        return j

    def forward(self, px: np.ndarray, py: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
        sx, sy, _ = self._eval(px, py, n)
        return px + sx, py + sy

    def inverse(
        self,
        qx: np.ndarray,
        qy: np.ndarray,
        n: int,
        guess: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Solve ``p + s_n(p) = q`` by Newton's method (``I + grad s`` is invertible).

        Iterates until the float64 residual ``|p + s_n(p) - q|`` is below 1e-9 px
        (usually 2 steps from the previous frame's solution ``guess``).
        """
        if guess is None:
            sx, sy, _ = self._eval(qx, qy, n)
            px, py = qx - sx, qy - sy
        else:
            px, py = guess[0].copy(), guess[1].copy()
        for _ in range(_NEWTON_MAX_ITER):
            sx, sy, thetas = self._eval(px, py, n)
            rx = px + sx - qx
            ry = py + sy - qy
            err = max(
                float(np.max(np.abs(rx), initial=0.0)), float(np.max(np.abs(ry), initial=0.0))
            )
            if err < _NEWTON_TOL:
                return px, py
            j = self._jacobian(thetas)
            a, b, c, d = 1.0 + j[0], j[1], j[2], 1.0 + j[3]
            det = a * d - b * c
            px = px - (d * rx - b * ry) / det
            py = py - (a * ry - c * rx) / det
        raise RuntimeError("non-rigid motion: the Newton inversion did not converge")


class _TextureSampler:
    """Evaluate a :class:`TextureField` faster, with the same values up to float32 rounding.

    ``TextureField.__call__`` takes float64 cosines of arguments of up to ~10^3 rad,
    one grating at a time.  Here the phase of every grating is reduced to one
    period in float64 (``t - rint(t)`` in cycles), the cosine is taken in float32
    (SIMD) and the gratings are mixed into the channels by a small matrix
    product, in cache-sized chunks of pixels: about 6x faster, within ~3e-7 of
    ``TextureField.__call__``.  If the field's internals are not as expected, or
    a probe evaluation differs by more than 1e-5, it falls back to calling the
    field itself.
    """

    _CHUNK = 1024

    def __init__(self, texture: TextureField) -> None:
        self.texture = texture
        self.fast = False
        try:
            self._cycles = np.stack([texture._kx, texture._ky, texture._phase]) / (2 * np.pi)
            self._mix = np.asarray(texture._mix, np.float32)
            self._blobs = (np.asarray(texture._bc), np.asarray(texture._br), texture._bw)
            rng = np.random.default_rng(0)
            px, py = rng.uniform(-50.0, 500.0, (2, 64))
            self.fast = True
            ok = np.allclose(self(px, py, 300.0), texture(px, py, 300.0), rtol=0.0, atol=1e-5)
        except (AttributeError, TypeError, ValueError):
            ok = False
        self.fast = bool(ok)

    def __call__(self, x: np.ndarray, y: np.ndarray, scale: float) -> np.ndarray:
        """Texture values at real positions: ``x, y`` shape S -> shape S + (C,), float32."""
        if not self.fast:
            return self.texture(x, y, scale)
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        shape = x.shape
        xf, yf = x.ravel(), y.ravel()
        kx, ky, ph = self._cycles
        centres, radii, weights = self._blobs
        centres = centres * scale
        inv_r2 = 1.0 / (radii * scale) ** 2
        out = np.empty((xf.size, self._mix.shape[1]), np.float32)
        for s in range(0, xf.size, self._CHUNK):
            xs = xf[s : s + self._CHUNK, None]
            ys = yf[s : s + self._CHUNK, None]
            t = xs * kx
            t += ys * ky
            t += ph
            t -= np.rint(t)
            t *= 2 * np.pi
            waves = t.astype(np.float32)
            np.cos(waves, out=waves)
            acc = (waves @ self._mix).astype(np.float64)
            r2 = ((xs - centres[:, 0]) ** 2 + (ys - centres[:, 1]) ** 2) * inv_r2
            acc += np.exp(-r2) @ weights
            out[s : s + self._CHUNK] = 0.5 + 0.5 * np.tanh(0.6 * acc)
        return out.reshape(shape + (out.shape[1],))


@dataclass
class _Layer:
    """A textured layer; ``radius`` limits it to ``|p - centre| <= radius`` (texture coords)."""

    motion: Any
    texture: _TextureSampler
    radius: float | None = None
    centre: tuple[float, float] = (0.0, 0.0)

    def covers(self, px: np.ndarray, py: np.ndarray) -> np.ndarray | None:
        if self.radius is None:
            return None
        return (px - self.centre[0]) ** 2 + (py - self.centre[1]) ** 2 <= self.radius**2


def _rotation(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _calibrate(build, measure, target: float, s_max: float = np.inf) -> tuple[Any, float]:
    """Find the amplitude scale ``s`` with ``measure(build(s)) == target`` (fixed point)."""
    if target == 0.0:
        return build(0.0), 0.0
    s = min(1.0, s_max)
    motion = build(s)
    for _ in range(30):
        got = measure(motion)
        if got <= 0.0 or abs(got - target) <= 1e-4 * target:
            break
        s_new = min(s * target / got, s_max)
        if s_new == s:
            break
        s = s_new
        motion = build(s)
    return motion, s


def _max_disp(motion: Any, xs: np.ndarray, ys: np.ndarray, ref: int, n_frames: int) -> float:
    """Maximum over frames of ``|M_n(M_ref^{-1}(x)) - x|`` at the given points."""
    px, py = motion.inverse(xs, ys, ref)
    best = 0.0
    for n in range(n_frames):
        fx, fy = motion.forward(px, py, n)
        best = max(best, float(np.max(np.hypot(fx - xs, fy - ys))))
    return best


def _affine_background(
    rng: np.random.Generator, shape: tuple[int, int], times: np.ndarray, magnitude: float
) -> tuple[_AffineMotion, dict[str, Any]]:
    h, w = shape
    n_frames = times.size
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    r = 0.5 * np.hypot(h, w)
    tc = times - 0.5
    # unit profiles (scale 1 gives displacements of order 1 px), then calibrated
    rot_amp = rng.uniform(0.5, 1.0) * rng.choice([-1, 1]) / r
    rot_f, rot_ph = rng.uniform(0.5, 1.0), rng.uniform(0, 2 * np.pi)
    zoom1, zoom2 = rng.uniform(-1, 1) * 0.8 / r, rng.uniform(-1, 1) * 0.8 / r
    shear_amp, shear_ph = rng.uniform(-1, 1) * 0.3 / r, rng.uniform(0, 2 * np.pi)
    ang = rng.uniform(0, 2 * np.pi)
    t_lin = 1.2 * np.array([np.cos(ang), np.sin(ang)])
    t_sin = rng.normal(size=2) * 0.4
    t_f, t_ph = rng.uniform(0.5, 1.5), rng.uniform(0, 2 * np.pi)

    def build(s: float) -> _AffineMotion:
        theta = s * rot_amp * (np.sin(2 * np.pi * rot_f * times + rot_ph) - np.sin(rot_ph))
        zoom = s * (zoom1 * tc + zoom2 * tc**2)
        shear = s * shear_amp * (np.sin(2 * np.pi * times + shear_ph) - np.sin(shear_ph))
        shear_m = np.zeros((n_frames, 2, 2))
        shear_m[:, 0, 0] = shear_m[:, 1, 1] = 1.0
        shear_m[:, 0, 1] = shear
        a = np.exp(zoom)[:, None, None] * (_rotation(theta) @ shear_m)
        b = s * (tc[:, None] * t_lin + np.sin(2 * np.pi * t_f * times + t_ph)[:, None] * t_sin)
        return _AffineMotion(a, b, centre)

    corners_x = np.array([0.0, w - 1.0, 0.0, w - 1.0])
    corners_y = np.array([0.0, 0.0, h - 1.0, h - 1.0])
    centre_ref = n_frames // 2
    motion, s = _calibrate(
        build, lambda m: _max_disp(m, corners_x, corners_y, centre_ref, n_frames), magnitude
    )
    info = {"type": "affine", "centre": centre, "A": motion.a, "b": motion.b, "scale": s}
    return motion, info


def _wave_motion(
    rng: np.random.Generator, shape: tuple[int, int], times: np.ndarray, magnitude: float
) -> tuple[_WaveMotion, dict[str, Any]]:
    h, w = shape
    n_frames = times.size
    size = max(h, w)
    n_waves = 4
    wavelength = rng.uniform(0.6, 1.3, n_waves) * size
    k_ang = rng.uniform(0, np.pi, n_waves)
    d_ang = rng.uniform(0, 2 * np.pi, n_waves)
    # the first wave: transverse, travelling along x (a waving flag)
    k_ang[0] = rng.uniform(-0.35, 0.35)
    d_ang[0] = np.pi / 2 + rng.uniform(-0.35, 0.35)
    kappa = (2 * np.pi / wavelength)[:, None] * np.stack([np.cos(k_ang), np.sin(k_ang)], -1)
    direction = np.stack([np.cos(d_ang), np.sin(d_ang)], -1)
    weight = np.array([1.0, 0.6, 0.5, 0.4]) / 2.5
    omega = 2 * np.pi * rng.uniform(0.5, 1.25, n_waves) * rng.choice([-1, 1], n_waves)
    phase = rng.uniform(0, 2 * np.pi, n_waves)
    dr_ang = rng.uniform(0, 2 * np.pi)
    drift_unit = 0.25 * (times - 0.5)[:, None] * np.array([np.cos(dr_ang), np.sin(dr_ang)])
    strain_unit = float(np.sum(weight * np.hypot(*kappa.T)))

    def build(s: float) -> _WaveMotion:
        return _WaveMotion(kappa, direction, s * weight, omega, phase, s * drift_unit, times)

    gy, gx = np.meshgrid(np.linspace(0, h - 1, 17), np.linspace(0, w - 1, 17), indexing="ij")
    gx, gy = gx.ravel(), gy.ravel()
    motion, s = _calibrate(
        build,
        lambda m: _max_disp(m, gx, gy, n_frames // 2, n_frames),
        magnitude,
        s_max=_MAX_STRAIN / strain_unit,
    )
    info = {
        "type": "travelling_waves",
        "kappa": kappa,
        "direction": direction,
        "amplitude": motion.amp,
        "omega": omega,
        "phase": phase,
        "drift": motion.drift,
        "strain_bound": motion.strain_bound,
        "scale": s,
    }
    return motion, info


def _disc_foreground(
    rng: np.random.Generator, shape: tuple[int, int], times: np.ndarray, magnitude: float
) -> tuple[_AffineMotion, float, np.ndarray, dict[str, Any]]:
    h, w = shape
    radius = 0.25 * min(h, w)
    tex_centre = np.array([0.5 * max(h, w), 0.5 * max(h, w)])
    mid = np.array([(w - 1) / 2, (h - 1) / 2]) + rng.uniform(-0.08, 0.08, 2) * np.array([w, h])
    ang = rng.uniform(0, 2 * np.pi)
    u = np.array([np.cos(ang), np.sin(ang)])
    u_perp = np.array([-u[1], u[0]])
    tc = times - 0.5
    wobble = np.sin(2 * np.pi * times + rng.uniform(0, 2 * np.pi))
    centres = mid + 2.0 * magnitude * tc[:, None] * u + 0.2 * magnitude * wobble[:, None] * u_perp
    psi = (0.25 * magnitude / radius) * rng.choice([-1, 1]) * 2 * tc
    rho = 1.0 + 0.05 * rng.choice([-1, 1]) * np.sin(np.pi * times)
    a = rho[:, None, None] * _rotation(psi)
    # M_n(p) = centres_n + rho_n R(psi_n) (p - tex_centre)
    motion = _AffineMotion(a, centres - tex_centre, tex_centre)
    info = {"centre": centres, "radius": radius * rho, "rotation": psi, "zoom": rho}
    return motion, radius, tex_centre, info


# --------------------------------------------------------------------------- rendering


def _render(
    layers: Sequence[_Layer], shape: tuple[int, int], n_frames: int, channels: int
) -> np.ndarray:
    h, w = shape
    scale = float(max(h, w))
    qy, qx = np.mgrid[0:h, 0:w].astype(np.float64)
    frames = np.empty((n_frames, h, w, channels), np.float32)
    guesses: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(layers)
    for n in range(n_frames):
        for i, layer in enumerate(layers):
            px, py = layer.motion.inverse(qx, qy, n, guesses[i])
            guesses[i] = (px, py)
            inside = layer.covers(px, py)
            if inside is None:
                frames[n] = layer.texture(px, py, scale)
            elif inside.any():
                frames[n][inside] = layer.texture(px[inside], py[inside], scale)
    return frames


def _trajectories(
    layers: Sequence[_Layer], shape: tuple[int, int], n_frames: int, ref: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact trajectories, in-front visibility and the layer of each reference pixel."""
    h, w = shape
    qy, qx = np.mgrid[0:h, 0:w].astype(np.float64)
    owner = np.zeros((h, w), np.uint8)
    for i, layer in enumerate(layers):
        px, py = layer.motion.inverse(qx, qy, ref)
        inside = layer.covers(px, py)
        owner[np.ones((h, w), bool) if inside is None else inside] = i
    traj = np.zeros((n_frames, h, w, 2), np.float32)
    vis = np.ones((n_frames, h, w), bool)
    for i, layer in enumerate(layers):
        sel = owner == i
        if not sel.any():
            continue
        xs, ys = qx[sel], qy[sel]
        px, py = layer.motion.inverse(xs, ys, ref)
        for n in range(n_frames):
            if n == ref:
                continue  # exactly zero by definition
            fx, fy = layer.motion.forward(px, py, n)
            traj[n][sel] = np.stack([fx - xs, fy - ys], -1)
            ok = (fx >= 0) & (fx <= w - 1) & (fy >= 0) & (fy <= h - 1)
            for front in layers[i + 1 :]:
                bx, by = front.motion.inverse(fx, fy, n)
                cov = front.covers(bx, by)
                ok &= np.zeros_like(ok) if cov is None else ~cov
            vis[n][sel] = ok
    return traj, vis, owner


# --------------------------------------------------------------------------- variants


def _add_occluder(
    frames: np.ndarray, traj: np.ndarray, vis: np.ndarray, ref: int
) -> dict[str, Any]:
    """Draw the sweeping bar into ``frames`` and clear ``vis`` under it (in place)."""
    n_frames, h, w, _ = frames.shape
    width = max(3, round(w / 8))
    if n_frames - 1 - ref >= ref:
        n0, n1 = ref, n_frames - 1
    else:
        n0, n1 = 0, ref
    left = np.full(n_frames, np.nan)
    xs = np.arange(w, dtype=np.float64)
    if n1 > n0:
        for n in range(n0, n1 + 1):
            lo = -width + (w + width) * (n - n0) / (n1 - n0)
            left[n] = lo
            cols = (xs >= lo) & (xs < lo + width)
            frames[n][:, cols] = _OCCLUDER_VALUE
            pos_x = xs[None, :] + traj[n, ..., 0].astype(np.float64)
            vis[n] &= ~((pos_x >= lo) & (pos_x < lo + width))
    return {"width": width, "left": left, "frames": (n0, n1), "value": _OCCLUDER_VALUE}


def _check_int(value: Any, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {value}")
    return int(value)


def _check_float(value: Any, name: str, lo: float, hi: float = np.inf) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not (np.isfinite(v) and lo <= v <= hi):
        raise ValueError(f"{name}: expected a finite value in [{lo}, {hi}], got {value!r}")
    return v


def make_sequence(
    name: str,
    n_frames: int = 30,
    shape: tuple[int, int] = (96, 128),
    ref: int | None = None,
    variant: str = "clean",
    seed: int = 0,
    channels: int = 3,
    magnitude: float = 8.0,
    noise_sigma: float = 0.04,
    sp_fraction: float = 0.05,
) -> SyntheticSequence:
    """Generate a synthetic clip with exact trajectories and visibility.

    Parameters
    ----------
    name : {"affine", "nonrigid", "layers"}
        Scene (see the module notes).
    n_frames : int
        Number of frames F >= 2 (benchmarks use 20-60).
    shape : (int, int)
        Frame size ``(H, W)``, each at least 16.
    ref : int, optional
        Reference frame in ``[0, F)``; default the centre ``F // 2``.  The frames
        do not depend on it.
    variant : {"clean", "gaussian", "saltpepper", "occluder"}
        Degradation (see the module notes).
    seed : int
        Seeds the textures, the motion and the noise (local generators only).
    channels : int
        1 for grey, 3 for colour.
    magnitude : float
        Maximum displacement (px) over the clip of the centre frame's pixels;
        the background of ``"layers"`` uses 0.6 of it.  The non-rigid motion is
        capped at ``|grad s| <= 0.5``, which may keep it below ``magnitude`` on
        small frames.
    noise_sigma : float
        Standard deviation of the ``"gaussian"`` noise, intensities in [0, 1].
    sp_fraction : float
        Fraction of pixels hit by ``"saltpepper"`` noise, in ``[0, 1]``.

    Returns
    -------
    SyntheticSequence
        ``frames`` (F, H, W, C) float32, ``trajectories`` (F, H, W, 2) float32,
        ``visibility`` (F, H, W) bool, ``ref``, metadata.

    Raises
    ------
    ValueError
        On an unknown scene or variant or an out-of-range argument (the message
        names the argument).

    Examples
    --------
    >>> seq = make_sequence("nonrigid", n_frames=20, shape=(48, 64), variant="gaussian")
    >>> seq.frames.shape, seq.trajectories.shape, seq.visibility.shape
    ((20, 48, 64, 3), (20, 48, 64, 2), (20, 48, 64))
    """
    if name not in SCENES:
        raise ValueError(f"name: expected one of {SCENES}, got {name!r}")
    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {VARIANTS}, got {variant!r}")
    n_frames = _check_int(n_frames, "n_frames", 2)
    try:
        h, w = (int(v) for v in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape: expected (H, W), got {shape!r}") from None
    if len(tuple(shape)) != 2 or h < 16 or w < 16:
        raise ValueError(f"shape: expected (H, W) with H, W >= 16, got {shape!r}")
    ref = n_frames // 2 if ref is None else _check_int(ref, "ref", 0)
    if ref >= n_frames:
        raise ValueError(f"ref: expected an index in [0, {n_frames}), got {ref}")
    seed = _check_int(seed, "seed", 0)
    channels = _check_int(channels, "channels", 1)
    magnitude = _check_float(magnitude, "magnitude", 0.0)
    noise_sigma = _check_float(noise_sigma, "noise_sigma", 0.0)
    sp_fraction = _check_float(sp_fraction, "sp_fraction", 0.0, 1.0)

    motion_ss, noise_ss = np.random.SeedSequence(seed).spawn(2)
    rng = np.random.default_rng(motion_ss)
    times = np.arange(n_frames, dtype=np.float64) / (n_frames - 1)
    texture = _TextureSampler(TextureField(channels, seed))
    params: dict[str, Any] = {"magnitude": magnitude, "times": times}

    if name == "nonrigid":
        motion, info = _wave_motion(rng, (h, w), times, magnitude)
        layers = [_Layer(motion, texture)]
        params["motion"] = info
    else:
        bg_mag = magnitude if name == "affine" else 0.6 * magnitude
        motion, info = _affine_background(rng, (h, w), times, bg_mag)
        layers = [_Layer(motion, texture)]
        params["motion"] = info
        if name == "layers":
            fg_motion, radius, tex_centre, fg_info = _disc_foreground(rng, (h, w), times, magnitude)
            fg_texture = _TextureSampler(TextureField(channels, seed + 1))
            layers.append(_Layer(fg_motion, fg_texture, radius, tuple(tex_centre)))
            params["foreground"] = fg_info

    frames = _render(layers, (h, w), n_frames, channels)
    traj, vis, owner = _trajectories(layers, (h, w), n_frames, ref)

    if variant == "occluder":
        params["occluder"] = _add_occluder(frames, traj, vis, ref)
    clean = frames
    noise_rng = np.random.default_rng(noise_ss)
    if variant == "gaussian":
        noise = noise_rng.standard_normal(frames.shape, dtype=np.float32)
        frames = np.clip(clean + np.float32(noise_sigma) * noise, 0.0, 1.0)
        params["noise_sigma"] = noise_sigma
    elif variant == "saltpepper":
        hit = noise_rng.random(frames.shape[:3]) < sp_fraction
        salt = noise_rng.random(frames.shape[:3]) < 0.5
        frames = clean.copy()
        frames[hit] = salt[hit].astype(np.float32)[:, None]
        params["sp_fraction"] = sp_fraction

    disp = np.hypot(traj[..., 0], traj[..., 1])
    params["max_displacement"] = float(disp.max())
    others = np.arange(n_frames) != ref
    params["occluded_fraction"] = float(1.0 - vis[others].mean()) if others.any() else 0.0
    return SyntheticSequence(
        frames=frames,
        trajectories=traj,
        visibility=vis,
        ref=ref,
        name=name,
        variant=variant,
        clean_frames=clean,
        layer=owner,
        seed=seed,
        params=params,
    )


def benchmark_cases(
    scenes: Sequence[str] = SCENES, variants: Sequence[str] = VARIANTS
) -> list[tuple[str, str]]:
    """The ``(name, variant)`` rows of the trajectory benchmark table.

    One row per scene and variant, scene-major (the layout of Gibson & Marques
    2016, Table 4.2: original, occlusion, Gaussian and salt & pepper noise).

    Parameters
    ----------
    scenes : sequence of str
        Subset of :data:`SCENES`.
    variants : sequence of str
        Subset of :data:`VARIANTS`.

    Returns
    -------
    list of (str, str)
    """
    for s in scenes:
        if s not in SCENES:
            raise ValueError(f"scenes: expected names from {SCENES}, got {s!r}")
    for v in variants:
        if v not in VARIANTS:
            raise ValueError(f"variants: expected names from {VARIANTS}, got {v!r}")
    return [(s, v) for s in scenes for v in variants]


def benchmark_suite(
    n_frames: int = 30,
    shape: tuple[int, int] = (96, 128),
    seed: int = 0,
    scenes: Sequence[str] = SCENES,
    variants: Sequence[str] = VARIANTS,
    **kwargs: Any,
) -> Iterator[SyntheticSequence]:
    """Generate the benchmark sequences lazily, one per :func:`benchmark_cases` row.

    Parameters
    ----------
    n_frames, shape, seed
        Passed to :func:`make_sequence` (the same seed for every row, so the
        variants of a scene share texture and motion).
    scenes, variants : sequence of str
        Restrict the table (see :func:`benchmark_cases`).
    **kwargs
        Further :func:`make_sequence` arguments (``ref``, ``magnitude``,
        ``noise_sigma``, ...).

    Yields
    ------
    SyntheticSequence
    """
    for name, variant in benchmark_cases(scenes, variants):
        yield make_sequence(
            name, n_frames=n_frames, shape=shape, variant=variant, seed=seed, **kwargs
        )
