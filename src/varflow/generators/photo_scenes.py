"""The layers of a photographic scene and how they move.

Object outlines (superellipses and rounded polygons), :class:`PhotoLayer`, the smooth
paths and sways of the motions, the camera motion (:func:`affine_camera`), the
non-rigid sheet (:func:`wave_sheet`), the extent of the background that a clip sees
(:func:`background_extent`) and the moving photographic objects
(:func:`photo_objects`); see :mod:`varflow.generators.photo` for the model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .photo_textures import PHOTOS, PhotoTexture, object_texture, photo_source
from .sequences import _AffineMotion, _calibrate, _max_disp, _rotation, _WaveMotion

__all__ = [
    "MAX_SPEED",
    "PhotoLayer",
    "affine_camera",
    "background_extent",
    "photo_objects",
    "sway",
    "sway_eval",
    "wave_sheet",
]

#: Cap on the speed of the objects in px per clip (t in [0, 1]).
MAX_SPEED = 174.0  # px per clip (t in [0, 1]): steps <= 5.8 px for F >= 31

_MAX_STRAIN = 0.5  # bound on |grad s| of the waves (keeps M_n invertible)
_SPEED_RATIO = 3.4  # peak speed / maximum displacement of the camera motion
_FINE_TIMES = np.linspace(0.0, 1.0, 241)  # for speed checks, independent of F


@dataclass
class _Shape:
    """A smooth object outline in texture coordinates centred at 0, circumradius ``radius``.

    ``"superellipse"``: ``|u / a|^e + |v / b|^e <= 1`` in axes turned by ``angle``;
    ``"polygon"``: a rounded polygon ``|p| <= r0 (1 + sum_j a_j cos(m_j phi + phi_j))``.
    """

    kind: str
    radius: float
    angle: float = 0.0
    axes: tuple[float, float] = (1.0, 1.0)
    exponent: float = 2.0
    harmonics: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    base: float = 1.0

    @classmethod
    def draw(cls, rng: np.random.Generator, radius: float) -> _Shape:
        if rng.random() < 0.5:
            e = rng.uniform(2.0, 4.0)
            aspect = rng.uniform(0.65, 1.0)
            a = radius * 2.0 ** (1.0 / e - 0.5)  # circumradius of the e-ball with a = b
            return cls("superellipse", radius, rng.uniform(0, np.pi), (a, a * aspect), e)
        order = rng.integers(3, 7)
        harm = np.array(
            [
                [order, rng.uniform(0.05, 0.12), rng.uniform(0, 2 * np.pi)],
                [2, rng.uniform(0.0, 0.08), rng.uniform(0, 2 * np.pi)],
            ]
        )
        base = radius / (1.0 + harm[:, 1].sum())
        return cls("polygon", radius, harmonics=harm, base=base)

    def __call__(self, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        if self.kind == "superellipse":
            c, s = np.cos(self.angle), np.sin(self.angle)
            u = np.abs(c * px + s * py) / self.axes[0]
            v = np.abs(c * py - s * px) / self.axes[1]
            return u**self.exponent + v**self.exponent <= 1.0
        phi = np.arctan2(py, px)
        r = np.ones_like(phi)
        for m, amp, ph in self.harmonics:
            r += amp * np.cos(m * phi + ph)
        r *= self.base
        return px * px + py * py <= r * r

    def info(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "radius": self.radius}
        if self.kind == "superellipse":
            out.update(angle=self.angle, axes=self.axes, exponent=self.exponent)
        else:
            out.update(base=self.base, harmonics=self.harmonics)
        return out


@dataclass
class PhotoLayer:
    """A photographic layer; ``shape`` limits it to an object outline (None: whole plane)."""

    motion: Any
    texture: PhotoTexture
    shape: _Shape | None = None

    def covers(self, px: np.ndarray, py: np.ndarray) -> np.ndarray | None:
        return None if self.shape is None else self.shape(px, py)

    def bounds(self, n: int) -> tuple[float, float, float, float]:
        """Frame-n box ``(x0, x1, y0, y1)`` holding the object (objects are affine, centre 0)."""
        assert self.shape is not None
        cx, cy = self.motion.forward(np.zeros(1), np.zeros(1), n)
        r = self.shape.radius * float(np.linalg.norm(self.motion.a[n], 2)) + 1.0
        return float(cx[0]) - r, float(cx[0]) + r, float(cy[0]) - r, float(cy[0]) + r


# --------------------------------------------------------------------------- motions


@dataclass
class _Path:
    """Unit path ``u P(t) + u_perp Q(t)`` with ``P(1/2) = Q(1/2) = 0``.

    ``P' = 1 + beta sin(w t + phi)`` (speed varies within ``1 +- beta``) and
    ``Q = gamma (sin(w2 t + phi2) - sin(w2 / 2 + phi2))`` (a sideways sway).
    """

    angle: float
    beta: float
    w: float
    phi: float
    gamma: float
    w2: float
    phi2: float

    @classmethod
    def draw(cls, rng: np.random.Generator, angle: float | None = None) -> _Path:
        ang = rng.uniform(0, 2 * np.pi) if angle is None else float(angle)
        return cls(
            ang,
            rng.uniform(0.25, 0.5),
            2 * np.pi * rng.uniform(0.5, 1.2),
            rng.uniform(0, 2 * np.pi),
            rng.uniform(0.03, 0.12),
            2 * np.pi * rng.uniform(0.6, 1.6),
            rng.uniform(0, 2 * np.pi),
        )

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, np.float64)
        p = (t - 0.5) - self.beta / self.w * (
            np.cos(self.w * t + self.phi) - np.cos(0.5 * self.w + self.phi)
        )
        q = self.gamma * (np.sin(self.w2 * t + self.phi2) - np.sin(0.5 * self.w2 + self.phi2))
        u = np.array([np.cos(self.angle), np.sin(self.angle)])
        return p[:, None] * u + q[:, None] * np.array([-u[1], u[0]])

    def info(self) -> dict[str, float]:
        return dict(self.__dict__)


def sway(rng: np.random.Generator, lo: float, hi: float) -> tuple[float, float, float]:
    """Amplitude, angular frequency and phase of ``amp (sin(w t + phi) - sin(w / 2 + phi))``."""
    return (
        rng.uniform(lo, hi) * rng.choice([-1.0, 1.0]),
        2 * np.pi * rng.uniform(0.4, 1.0),
        rng.uniform(0, 2 * np.pi),
    )


def sway_eval(p: tuple[float, float, float], t: np.ndarray) -> np.ndarray:
    """The sway ``p`` of :func:`sway` at the times ``t`` (0 at mid-clip)."""
    amp, w, ph = p
    return amp * (np.sin(w * t + ph) - np.sin(0.5 * w + ph))


def _speed_and_reach(motion: Any, xs: np.ndarray, ys: np.ndarray) -> tuple[float, float]:
    """Peak speed (px per clip) and maximum displacement from mid-clip of the given points.

    ``motion`` must be built on :data:`_FINE_TIMES` (241 times, mid-clip = index 120).
    """
    px, py = motion.inverse(xs, ys, 120)
    pos = np.stack([np.stack(motion.forward(px, py, n), -1) for n in range(_FINE_TIMES.size)])
    speed = np.hypot(*np.moveaxis(np.diff(pos, axis=0), -1, 0)).max() * (_FINE_TIMES.size - 1)
    reach = np.hypot(*np.moveaxis(pos - pos[120], -1, 0)).max()
    return float(speed), float(reach)


def affine_camera(
    rng: np.random.Generator, shape: tuple[int, int], times: np.ndarray, magnitude: float
) -> tuple[_AffineMotion, dict[str, Any]]:
    """Pan, roll, zoom and slight shear of the camera, calibrated to ``magnitude``."""
    h, w = shape
    n_frames = times.size
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    r = 0.5 * np.hypot(h, w)
    cx = np.array([0.0, w - 1.0, 0.0, w - 1.0])
    cy = np.array([0.0, 0.0, h - 1.0, h - 1.0])
    speed = 0.0
    for _attempt in range(20):
        path = _Path.draw(rng)
        rot = sway(rng, 0.05 / r, 0.2 / r)
        zoom1, zoom2 = rng.uniform(-0.3, 0.3, 2) / r
        shear = sway(rng, 0.0, 0.06 / r)

        def build(s: float, t: np.ndarray = times) -> _AffineMotion:
            tc = t - 0.5
            theta = s * sway_eval(rot, t)  # noqa: B023 - used within the iteration
            zoom = s * (zoom1 * tc + zoom2 * tc**2)  # noqa: B023
            sh = np.zeros((t.size, 2, 2))
            sh[:, 0, 0] = sh[:, 1, 1] = 1.0
            sh[:, 0, 1] = s * sway_eval(shear, t)  # noqa: B023
            a = np.exp(zoom)[:, None, None] * (_rotation(theta) @ sh)
            return _AffineMotion(a, s * path(t), centre)  # noqa: B023

        motion, s = _calibrate(
            build, lambda m: _max_disp(m, cx, cy, n_frames // 2, n_frames), magnitude
        )
        if s == 0.0:
            break
        speed, reach = _speed_and_reach(build(s, _FINE_TIMES), cx, cy)
        if speed <= _SPEED_RATIO * reach:
            break
    info = {
        "type": "affine",
        "A": motion.a,
        "b": motion.b,
        "centre": centre,
        "scale": s,
        "peak_speed": speed,
        "path": path.info(),
        "rotation": s * sway_eval(rot, times),
        "log_zoom": s * (zoom1 * (times - 0.5) + zoom2 * (times - 0.5) ** 2),
        "shear": s * sway_eval(shear, times),
    }
    return motion, info


def wave_sheet(
    rng: np.random.Generator, shape: tuple[int, int], times: np.ndarray, magnitude: float
) -> tuple[_WaveMotion, dict[str, Any]]:
    """Travelling waves plus a smooth drift, calibrated to ``magnitude``."""
    h, w = shape
    n_frames = times.size
    size = max(h, w)
    n_waves = 4
    wavelength = rng.uniform(0.6, 1.3, n_waves) * size
    k_ang = rng.uniform(0, np.pi, n_waves)
    d_ang = rng.uniform(0, 2 * np.pi, n_waves)
    k_ang[0] = rng.uniform(-0.35, 0.35)  # the first wave: transverse, along x (a flag)
    d_ang[0] = np.pi / 2 + rng.uniform(-0.35, 0.35)
    kappa = (2 * np.pi / wavelength)[:, None] * np.stack([np.cos(k_ang), np.sin(k_ang)], -1)
    direction = np.stack([np.cos(d_ang), np.sin(d_ang)], -1)
    weight = np.array([1.0, 0.6, 0.5, 0.4]) / 2.5
    omega = 2 * np.pi * rng.uniform(0.4, 0.9, n_waves) * rng.choice([-1, 1], n_waves)
    phase = rng.uniform(0, 2 * np.pi, n_waves)
    path = _Path.draw(rng)
    share = rng.uniform(0.35, 0.6)
    strain_unit = float(np.sum(weight * np.hypot(*kappa.T)))
    wave_speed_unit = float(np.sum(weight * np.abs(omega)))

    def build(a: float, s: float, t: np.ndarray = times) -> _WaveMotion:
        return _WaveMotion(kappa, direction, a * weight, omega, phase, s * path(t), t)

    gy, gx = np.meshgrid(np.linspace(0, h - 1, 25), np.linspace(0, w - 1, 25), indexing="ij")
    gx, gy = gx.ravel(), gy.ravel()

    def measure(m: _WaveMotion) -> float:
        return _max_disp(m, gx, gy, n_frames // 2, n_frames)

    a = 0.0
    if magnitude > 0:
        reach1 = measure(build(1.0, 0.0))
        a = min(
            share * magnitude / reach1,
            0.95 * _MAX_STRAIN / strain_unit,
            0.4 * _SPEED_RATIO * magnitude / wave_speed_unit,
        )
    motion, s = _calibrate(lambda s: build(a, s), measure, magnitude)
    info = {
        "type": "travelling_waves",
        "kappa": kappa,
        "direction": direction,
        "amplitude": motion.amp,
        "omega": omega,
        "phase": phase,
        "drift": motion.drift,
        "times": times,
        "strain_bound": motion.strain_bound,
        "scale": s,
        "path": path.info(),
    }
    return motion, info


def _border_points(shape: tuple[int, int], per_side: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Points on the border of the area covered by the sub-samples, ``[-0.5, W-0.5] x ...``."""
    h, w = shape
    tx = np.linspace(-0.5, w - 0.5, per_side)
    ty = np.linspace(-0.5, h - 0.5, per_side)
    xs = np.concatenate([tx, tx, np.full(per_side, -0.5), np.full(per_side, w - 0.5)])
    ys = np.concatenate([np.full(per_side, -0.5), np.full(per_side, h - 0.5), ty, ty])
    return xs, ys


def background_extent(motion: Any, shape: tuple[int, int], n_frames: int) -> np.ndarray:
    """Box ``[x0, x1, y0, y1]`` (texture coords) seen by any sub-sample of any frame."""
    xs, ys = _border_points(shape, 4 if isinstance(motion, _AffineMotion) else 96)
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    for n in range(n_frames):
        px, py = motion.inverse(xs, ys, n)
        lo = np.minimum(lo, [px.min(), py.min()])
        hi = np.maximum(hi, [px.max(), py.max()])
    margin = 0.0 if isinstance(motion, _AffineMotion) else 1.0
    return np.array([lo[0] - margin, hi[0] + margin, lo[1] - margin, hi[1] + margin])


def photo_objects(
    rng: np.random.Generator,
    shape: tuple[int, int],
    times: np.ndarray,
    magnitude: float,
    speed_cap: float,
    channels: int,
    used: list[str],
) -> tuple[list[PhotoLayer], list[dict[str, Any]]]:
    """1-3 photographic objects in depth order (back to front); one leaves the frame."""
    h, w = shape
    n_obj = int(rng.integers(1, 4))
    crossing = int(rng.integers(n_obj))
    depth = rng.permutation(n_obj)  # depth[i] = depth rank of object i (0 = backmost)
    objects: list[tuple[int, PhotoLayer, dict[str, Any]]] = []
    rim = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    gentle = min(1.0, magnitude / 30.0)  # rotation and zoom shrink with small magnitudes
    for i in range(n_obj):
        radius = rng.uniform(0.08, 0.25) * min(h, w)
        outline = _Shape.draw(rng, radius)
        sides = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
        side = int(rng.integers(4))
        t_out = float(rng.choice([0.0, 1.0]))
        if i == crossing:
            normal = sides[side] * (1.0 if t_out == 1.0 else -1.0)
            angle = np.arctan2(normal[1], normal[0]) + rng.uniform(-0.4, 0.4)
            path = _Path.draw(rng, angle)
        else:
            path = _Path.draw(rng)
        rot = sway(rng, 0.05, 0.2)
        zoom = sway(rng, 0.02, 0.05)
        share = rng.uniform(0.7, 1.3)
        extra = rng.uniform(0.3, 1.2)
        mid_rel = rng.uniform(0.15, 0.85, 2)

        def build(
            d: float, rot_scale: float, centre_mid: np.ndarray, t: np.ndarray = times
        ) -> _AffineMotion:
            psi = rot_scale * sway_eval(rot, t)  # noqa: B023 - used within the iteration
            rho = np.exp(gentle * sway_eval(zoom, t))  # noqa: B023
            a = rho[:, None, None] * _rotation(psi)
            return _AffineMotion(a, centre_mid + d * path(t), np.zeros(2))  # noqa: B023

        reach_unit = float(np.hypot(*path(times).T).max())
        d = share * magnitude / reach_unit if reach_unit > 0 else 0.0
        rot_scale = gentle
        rx, ry = radius * np.cos(rim), radius * np.sin(rim)
        for _ in range(4):  # limit the speed (translation and rotation alike)
            fine = build(d, rot_scale, np.zeros(2), _FINE_TIMES)
            speed, _ = _speed_and_reach(fine, *fine.forward(rx, ry, 120))
            if speed <= speed_cap:
                break
            d *= 0.98 * speed_cap / speed
            rot_scale *= 0.98 * speed_cap / speed
        if i == crossing:
            # beyond the border by `extra` radii at t_out, inside by 0.3 radii at mid-clip
            end = d * path(np.array([t_out]))[0]
            axis = 0 if side < 2 else 1
            lim = (w - 1.0, h - 1.0)[axis]
            target = -extra * radius if side % 2 == 0 else lim + extra * radius
            mid = np.array([mid_rel[0] * (w - 1), mid_rel[1] * (h - 1)])
            mid[axis] = np.clip(target - end[axis], 0.3 * radius, lim - 0.3 * radius)
        else:
            mid = np.array([mid_rel[0] * (w - 1), mid_rel[1] * (h - 1)])
        motion = build(d, rot_scale, mid)
        candidates = [n for n in PHOTOS if photo_source(n) not in {photo_source(u) for u in used}]
        name = candidates[int(rng.integers(len(candidates)))] if candidates else PHOTOS[i]
        used.append(name)
        texture, tex_info = object_texture(rng, name, radius, channels)
        info = {
            **tex_info,
            "shape": outline.info(),
            "radius": radius,
            "depth": int(depth[i]),
            "planned_crossing": i == crossing,
            "crossing_side": ("left", "right", "top", "bottom")[side] if i == crossing else None,
            "outside_at_time": t_out if i == crossing else None,
            "centre": motion.b.copy(),
            "rotation": rot_scale * sway_eval(rot, times),
            "zoom": np.exp(gentle * sway_eval(zoom, times)),
            "A": motion.a,
            "b": motion.b,
            "path": path.info(),
            "path_scale": d,
        }
        objects.append((int(depth[i]), PhotoLayer(motion, texture, outline), info))
    objects.sort(key=lambda item: item[0])
    return [o[1] for o in objects], [o[2] for o in objects]
