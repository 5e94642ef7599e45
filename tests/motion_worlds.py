"""Analytic moving-plume fixtures for the prediction tests.

Everything is evaluated in closed form at sub-pixel shifted coordinates (sums
of random sinusoids for texture, an implicit bumpy ellipse or a swept disc for
the plume), so the truth at any time does not come from the code under test
(no warping, no dilation).
"""

from __future__ import annotations

import numpy as np


def _texture(rng: np.random.Generator, n: int, kmin: float, kmax: float):
    k = rng.uniform(kmin, kmax, n)
    th = rng.uniform(0, 2 * np.pi, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    kx, ky = k * np.cos(th), k * np.sin(th)

    def f(x, y):
        out = np.zeros(np.shape(x), np.float64)
        for i in range(n):
            out += np.cos(kx[i] * x + ky[i] * y + ph[i])
        return out / np.sqrt(n / 2.0)  # roughly unit variance

    return f


class RigidCloud:
    """A textured cloud translating at ``velocity`` px/s over a fixed textured ground."""

    def __init__(self, size=192, velocity=(1.5, -0.8), seed=0, textured=True, noise=0.004,
                 centre=(70.0, 110.0), radius=32.0):  # fmt: skip
        rng = np.random.default_rng(seed)
        self.size, self.v, self.noise = size, np.asarray(velocity, float), noise
        self.c, self.r = np.asarray(centre, float), radius
        self.ground = _texture(rng, 24, 0.15, 0.9)
        self.cloud = _texture(rng, 24, 0.2, 0.9)
        self.bump = rng.uniform(0, 2 * np.pi)
        self.textured = textured
        self.rng = np.random.default_rng(seed + 1000)
        yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
        self.xx, self.yy = xx, yy

    def _rho(self, t):
        cx, cy = self.c + self.v * t
        dx, dy = self.xx - cx, self.yy - cy
        th = np.arctan2(dy, dx)
        rad = self.r * (1 + 0.15 * np.sin(3 * th + self.bump)) * np.array([1.0])
        return np.hypot(dx / 1.3, dy) / rad  # <= 1 inside

    def mask(self, t: float) -> np.ndarray:
        return self._rho(t) <= 1.0

    def frame(self, t: float) -> np.ndarray:
        rho = self._rho(t)
        alpha = np.clip((1.15 - rho) / 0.3, 0, 1) * 0.9  # soft edge, 0.9 opaque inside
        g = 0.12 + 0.04 * self.ground(self.xx, self.yy)
        sx, sy = self.xx - self.v[0] * t, self.yy - self.v[1] * t  # texture moves with the cloud
        c = 0.7 + (0.12 * self.cloud(sx, sy) if self.textured else 0.0)
        img = g * (1 - alpha) + c * alpha
        bands = np.stack([img * 1.0, img * 0.98, img * 1.02, img * 0.95])
        bands += self.rng.normal(0, self.noise, bands.shape)
        return bands.astype(np.float32)


class AttachedPlume:
    """A plume from a fixed vent: puffs leave the vent at ``velocity`` and widen downwind.

    At time ``t`` the plume is every point within ``w0 + k s`` of ``vent + v s`` for
    puffs of age ``s`` in ``[0, t0 + t]``; its texture moves with the wind.
    """

    def __init__(self, size=192, velocity=(2.0, 1.0), vent=(40.0, 50.0), t0=30.0, seed=3,
                 w0=5.0, k=0.15, noise=0.004):  # fmt: skip
        rng = np.random.default_rng(seed)
        self.size, self.v = size, np.asarray(velocity, float)
        self.vent, self.t0, self.w0, self.k, self.noise = np.asarray(vent, float), t0, w0, k, noise
        self.ground = _texture(rng, 24, 0.15, 0.9)
        self.puff = _texture(rng, 24, 0.2, 0.9)
        self.rng = np.random.default_rng(seed + 1000)
        yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
        self.xx, self.yy = xx, yy

    def _dist(self, t):
        """Distance to the swept axis minus the local half-width (<= 0 inside)."""
        speed = np.hypot(*self.v)
        u = self.v / speed
        px, py = self.xx - self.vent[0], self.yy - self.vent[1]
        s = np.clip((px * u[0] + py * u[1]) / speed, 0, self.t0 + t)  # age of the nearest puff
        d = np.hypot(px - self.v[0] * s, py - self.v[1] * s)
        return d - (self.w0 + self.k * s * speed)

    def mask(self, t: float) -> np.ndarray:
        return self._dist(t) <= 0

    def upwind_end(self) -> np.ndarray:
        """Where the plume's upwind edge lies: the vent minus w0 along the wind."""
        return self.vent - self.w0 * self.v / np.hypot(*self.v)

    def frame(self, t: float) -> np.ndarray:
        alpha = np.clip((1.5 - self._dist(t)) / 3.0, 0, 1) * 0.9
        g = 0.12 + 0.04 * self.ground(self.xx, self.yy)
        c = 0.6 + 0.12 * self.puff(self.xx - self.v[0] * t, self.yy - self.v[1] * t)
        img = g * (1 - alpha) + c * alpha
        bands = np.stack([img, img * 0.97, img * 0.95, img * 1.05])
        bands += self.rng.normal(0, self.noise, bands.shape)
        return bands.astype(np.float32)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))
