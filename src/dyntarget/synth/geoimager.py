"""A geostationary imager over a synthetic strip: the GEO images ``fly --geo`` plans on.

The strip's world (:class:`~dyntarget.synth.dynamic.WorldSpec`) seen by a
geostationary imager: rendered at ``gsd_m / 8`` (area-averaged: narrow plumes count
by the fraction of the cell they cover) over the strip and an 8 km margin around it,
averaged onto ``gsd_m`` cells, plus the imager's own Gaussian noise (``noise``,
reflectance). :class:`GeoStream` implements :class:`dyntarget.geo.seams.GeoImager`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dyntarget.scene import block_mean
from dyntarget.synth.dynamic import World as MovingWorld
from dyntarget.synth.dynamic import WorldSpec
from dyntarget.synth.strip import resampled_spec
from dyntarget.synth.volcano import ASH_PLUME, CLOUD, STEAM

MARGIN_M = 8_000.0
"""GEO coverage beyond the strip on every side, metres (context for the motion)."""
SUBSAMPLE = 8
"""Render pixels per GEO cell side."""
MAX_RENDER_ROWS = 8192
"""Most render rows in one call (a long strip's GEO grid is rendered band by band)."""


class GeoStream:
    """The GEO images of a synthetic strip's world (see the module docstring).

    Parameters
    ----------
    spec : WorldSpec
        The strip's world.
    window : tuple of int
        ``(col0, row0, width, height)`` of the strip on the world's grid.
    gsd_m : float
        GEO cell size, m.
    noise : float
        Std of the GEO brightness noise, reflectance.

    Examples
    --------
    >>> from dyntarget.synth.strip import strip_spec
    >>> spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    >>> s = GeoStream(spec, window, 1000.0, 0.0)
    >>> s.image(0.0).shape == (4, *s.cells), s.m
    (True, 8)
    """

    def __init__(
        self, spec: WorldSpec, window: tuple[int, int, int, int], gsd_m: float, noise: float
    ) -> None:
        self.spec, self.window, self.gsd_m, self.noise = spec, window, gsd_m, noise
        g = gsd_m / SUBSAMPLE
        g = max(g, spec.gsd)
        self.m = max(1, round(gsd_m / g))  # render px per GEO cell
        g = gsd_m / self.m
        scale = spec.gsd / g
        self.render_gsd = g
        coarse = resampled_spec(spec, g, lambda c: c * scale, noise_sigma=0.0)
        self.coarse = MovingWorld(coarse)
        # the clear-sky background: the same ground, no plume, no cloud
        self._clear = MovingWorld(
            replace(
                coarse,
                vents=tuple(replace(v, emission_optical_depth=1e-9) for v in coarse.vents),
                clouds=(),
            )
        )
        self._background: np.ndarray | None = None
        c0, r0, w, h = window
        G = gsd_m
        x0, x1 = c0 * spec.gsd - MARGIN_M, (c0 + w) * spec.gsd + MARGIN_M
        y0, y1 = r0 * spec.gsd - MARGIN_M, (r0 + h) * spec.gsd + MARGIN_M
        self.cell0 = (math.floor(x0 / G), math.floor(y0 / G))  # GEO cell of the grid's corner
        self.cells = (math.ceil(y1 / G) - self.cell0[1], math.ceil(x1 / G) - self.cell0[0])
        self._images: dict[float, np.ndarray] = {}

    @property
    def strip_gsd(self) -> float:
        """The strip's high-resolution pixel size, m."""
        return self.spec.gsd

    @property
    def members(self) -> np.ndarray:
        """``(3, bands)`` end-member spectra of the world: meteorological cloud, ash, steam."""
        return np.array([CLOUD, ASH_PLUME, STEAM], np.float64)

    def background(self) -> np.ndarray:
        """The clear-sky reflectance of every GEO cell (no plume, no cloud, no noise).

        Returns
        -------
        numpy.ndarray
            ``(bands, rows, cols)`` reflectance.
        """
        if self._background is None:
            self._background = self._render(self._clear, 0.0)
        return self._background

    def _render(self, world: MovingWorld, t: float) -> np.ndarray:
        m = self.m
        nrow, ncol = self.cells
        cx, cy = self.cell0
        out: np.ndarray | None = None
        step = max(1, MAX_RENDER_ROWS // m)
        for a in range(0, nrow, step):
            b = min(nrow, a + step)
            f = world.render(t, (cx * m, (cy + a) * m, ncol * m, (b - a) * m), noise=False)
            if out is None:
                out = np.empty((f.image.shape[0], nrow, ncol), np.float32)
            out[:, a:b] = block_mean(f.image, m)
        assert out is not None  # at least one GEO row
        return out

    def image(self, t: float) -> np.ndarray:
        """The GEO image taken at ``t`` (pass seconds), noise included (every band).

        Parameters
        ----------
        t : float
            Acquisition time.

        Returns
        -------
        numpy.ndarray
            ``(bands, rows, cols)`` reflectance on GEO cells (row 0: the strip's top, as
            the strip).
        """
        hit = self._images.get(t)
        if hit is not None:
            return hit
        out = self._render(self.coarse, t)
        if self.noise > 0:
            rng = np.random.default_rng([self.spec.seed, 0x6E0, round(t * 1000) & 0xFFFFFFFF])
            out += rng.normal(0.0, self.noise, out.shape).astype(np.float32)
        self._images[t] = out
        return out

    def strip_rows(self, gy: np.ndarray) -> np.ndarray:
        """High-resolution strip rows of the centres of GEO rows ``gy``.

        Parameters
        ----------
        gy : numpy.ndarray
            GEO rows.

        Returns
        -------
        numpy.ndarray
            Strip rows (high resolution, may lie outside the strip).
        """
        s = self.spec
        return (self.cell0[1] + np.asarray(gy) + 0.5) * self.gsd_m / s.gsd - (self.window[1])

    def strip_cols(self) -> tuple[int, int]:
        """GEO columns overlapping the strip.

        Returns
        -------
        tuple of int
            ``(first, last + 1)``.
        """
        s, G = self.spec, self.gsd_m
        c0, _, w, _ = self.window
        a = math.floor(c0 * s.gsd / G) - self.cell0[0]
        b = math.ceil((c0 + w) * s.gsd / G) - self.cell0[0]
        return a, b
