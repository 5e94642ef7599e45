"""What the GEO stage needs of the pass, the GEO imager and the world: typed protocols.

The stage imports no other stage: the pass's frame plan (:class:`PassFrames`,
implemented by :class:`dyntarget.fly.loop.FramePlan`), the GEO images
(:class:`GeoImager`, implemented by :class:`dyntarget.synth.geoimager.GeoStream`), the
detection settings (:class:`DetectionSettings`, implemented by
:class:`dyntarget.fly.geo.GeoSettings`) and the true plumes of a synthetic world
(:class:`PlumeTruth`, implemented by the moving strips) and any strip on the map
(:class:`MappedStrip`, for the catalog prior) reach it through these protocols.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from affine import Affine

from dyntarget.schedule import OrbitGeometry

Window = tuple[int, int, int, int]
"""``(col0, row0, width, height)`` of a strip on its world's grid, pixels."""


class PassFrames(Protocol):
    """The look-ahead frames of a pass (:class:`dyntarget.fly.loop.FramePlan`)."""

    @property
    def wfov_shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the strip's WFOV grid."""
        ...

    @property
    def frame_px(self) -> int:
        """Rows of one look-ahead frame, WFOV pixels."""
        ...

    @property
    def step(self) -> int:
        """Rows between two frames' tops, WFOV pixels."""
        ...

    @property
    def cadence_s(self) -> float:
        """Seconds between two frames."""
        ...

    @property
    def tops(self) -> tuple[int, ...]:
        """Each frame's top strip WFOV row, in flight order."""
        ...

    @property
    def geometry(self) -> OrbitGeometry:
        """The orbit (time 0: the first frame's acquisition)."""
        ...

    @property
    def n_frames(self) -> int:
        """Frames in the pass."""
        ...

    def acquired_s(self, k: int) -> float:
        """When frame ``k`` is acquired, pass seconds."""
        ...


class DetectionSettings(Protocol):
    """How GEO images are taken and tested for plume (:class:`dyntarget.fly.geo.GeoSettings`)."""

    @property
    def gsd_m(self) -> float:
        """GEO cell size, m."""
        ...

    @property
    def cadence_s(self) -> float:
        """Seconds between GEO images."""
        ...

    @property
    def latency_s(self) -> float:
        """An image taken at ``t`` is usable from ``t + latency_s``."""
        ...

    @property
    def history_s(self) -> float:
        """How far before the pass the GEO archive goes, s."""
        ...

    @property
    def threshold(self) -> float:
        """Detection threshold above the background, reflectance."""
        ...

    @property
    def detection(self) -> str:
        """``"unmix"`` or ``"brightness"``."""
        ...


class GeoImager(Protocol):
    """The GEO images of a strip (:class:`dyntarget.synth.geoimager.GeoStream`)."""

    @property
    def cells(self) -> tuple[int, int]:
        """``(rows, cols)`` of the GEO grid (the strip and a margin)."""
        ...

    @property
    def cell0(self) -> tuple[int, int]:
        """GEO cell ``(x, y)`` of the grid's corner on the world's GEO grid."""
        ...

    @property
    def window(self) -> Window:
        """The strip's window on its world's high-resolution grid."""
        ...

    @property
    def strip_gsd(self) -> float:
        """The strip's high-resolution pixel size, m."""
        ...

    @property
    def members(self) -> np.ndarray:
        """``(3, bands)`` end-member spectra: meteorological cloud, ash, steam."""
        ...

    def background(self) -> np.ndarray:
        """``(bands, rows, cols)`` clear-sky reflectance of every GEO cell."""
        ...

    def image(self, t: float) -> np.ndarray:
        """``(bands, rows, cols)`` GEO image taken at ``t`` (pass seconds)."""
        ...

    def strip_rows(self, gy: np.ndarray) -> np.ndarray:
        """High-resolution strip rows of the centres of GEO rows ``gy``."""
        ...

    def strip_cols(self) -> tuple[int, int]:
        """GEO columns overlapping the strip, ``(first, last + 1)``."""
        ...


class TruthRenderer(Protocol):
    """A world that renders its true plumes (:meth:`dyntarget.synth.dynamic.World.truth`)."""

    def truth(self, t: float, window: Window | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(mask, tau)``: the true plume at ``t`` on ``window``."""
        ...


class PlumeTruth(Protocol):
    """The true plumes of a synthetic strip (the omniscient reference reads them)."""

    @property
    def window(self) -> Window:
        """The strip's window on its world's high-resolution grid."""
        ...

    @property
    def gsd(self) -> float:
        """Metres per high-resolution pixel."""
        ...

    def source_rows(self, t: float, factor: int) -> list[float]:
        """Strip WFOV rows of the plume sources at ``t``: vents, then volcanic clouds."""
        ...

    def wfov_renderer(self, factor: int) -> TruthRenderer:
        """The strip's world on a grid ``factor`` times coarser (the WFOV grid)."""
        ...


class MappedStrip(Protocol):
    """A strip on the map (the catalog prior locates volcanoes on it): any flown world."""

    @property
    def id(self) -> str:
        """The strip's name."""
        ...

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the strip, high resolution."""
        ...

    @property
    def crs(self) -> str | None:
        """The strip's CRS, ``None`` for pixel coordinates."""
        ...

    @property
    def transform(self) -> Affine | None:
        """The strip's pixel -> CRS geotransform, ``None`` for pixel coordinates."""
        ...

    def vent_pixels(self) -> np.ndarray | None:
        """``(n, 2)`` strip ``(col, row)`` of a synthetic strip's vents; ``None``: no world."""
        ...
