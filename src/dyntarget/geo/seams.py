"""What the GEO stage needs of the pass, the GEO imager and the world: typed protocols.

The stage imports no other stage: the pass's frame plan (:class:`PassFrames`,
implemented by :class:`dyntarget.passes.record.FramePlan`), the GEO images
(:class:`GeoImager`, implemented by :class:`dyntarget.synth.geoimager.GeoStream`), the
detection settings (:class:`DetectionSettings`, implemented by
:class:`dyntarget.passes.geo.GeoSettings`) and the true plumes of a synthetic world
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
    """The look-ahead frames of a pass (:class:`dyntarget.passes.record.FramePlan`)."""

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
        """When frame ``k`` is acquired.

        Parameters
        ----------
        k : int
            The frame's index, in flight order.

        Returns
        -------
        float
            Its acquisition time, seconds on the pass clock.
        """
        ...


class DetectionSettings(Protocol):
    """How GEO images are taken and tested for plume (:class:`dyntarget.passes.geo.GeoSettings`)."""

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
        """The clear-sky reflectance of every GEO cell.

        Returns
        -------
        numpy.ndarray
            ``(bands, rows, cols)`` float reflectance.
        """
        ...

    def image(self, t: float) -> np.ndarray:
        """The GEO image taken at ``t``.

        Parameters
        ----------
        t : float
            Acquisition time, seconds on the pass clock.

        Returns
        -------
        numpy.ndarray
            ``(bands, rows, cols)`` float reflectance.
        """
        ...

    def strip_rows(self, gy: np.ndarray) -> np.ndarray:
        """Where GEO rows lie on the strip.

        Parameters
        ----------
        gy : numpy.ndarray
            GEO row indices of this grid.

        Returns
        -------
        numpy.ndarray
            The high-resolution strip rows of their centres (float, same shape).
        """
        ...

    def strip_cols(self) -> tuple[int, int]:
        """The GEO columns overlapping the strip.

        Returns
        -------
        tuple of int
            ``(first, last + 1)``.
        """
        ...


class TruthRenderer(Protocol):
    """A world that renders its true plumes (:meth:`dyntarget.synth.dynamic.World.truth`)."""

    def truth(self, t: float, window: Window | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The true plume at ``t``.

        Parameters
        ----------
        t : float
            Seconds on the pass clock.
        window : tuple of int, optional
            ``(col0, row0, width, height)`` on the world's grid; default the whole world.

        Returns
        -------
        tuple of numpy.ndarray
            ``(mask, tau)``: the bool plume mask and its optical depth, ``(height, width)``.
        """
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
        """Where the plume sources are at ``t``.

        Parameters
        ----------
        t : float
            Seconds on the pass clock.
        factor : int
            High-resolution pixels per WFOV pixel.

        Returns
        -------
        list of float
            Strip WFOV rows of the vents, then of the volcanic clouds.
        """
        ...

    def wfov_renderer(self, factor: int) -> TruthRenderer:
        """The strip's world on the WFOV grid.

        Parameters
        ----------
        factor : int
            High-resolution pixels per WFOV pixel.

        Returns
        -------
        TruthRenderer
            The same world on a grid ``factor`` times coarser.
        """
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
        """The vents of a synthetic strip.

        Returns
        -------
        numpy.ndarray or None
            ``(n, 2)`` float ``(col, row)`` on the strip's high-resolution grid; ``None`` when
            no synthetic world is behind the strip.
        """
        ...
