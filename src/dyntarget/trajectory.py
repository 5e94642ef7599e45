"""Trajectory: the ordered NFOV pointings (written by :mod:`dyntarget.io.geojson`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from affine import Affine

from dyntarget.errors import InvalidParameterError


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Ordered NFOV pointings ``(x, y)`` in WFOV pixel coordinates.

    ``points[i]`` is the i-th pointing, ``(column, row)`` with pixel centres at
    integer coordinates. ``part[i]`` numbers the polygon (or baseline leg) the
    pointing belongs to: consecutive pointings with different ``part`` are
    joined by a *travel* hop that observes nothing on the way.

    Parameters
    ----------
    points : numpy.ndarray
        ``(n, 2)`` pointings ``(x, y)``, WFOV pixels; must be finite.
    part : numpy.ndarray
        ``(n,)`` integer part of each pointing.
    planner : str
        Name of the planner that made it.
    params : dict
        The planner's settings, recorded with the plan.
    times : numpy.ndarray or None
        ``(n,)`` observation start times, seconds after the WFOV acquisition, or
        ``None`` for an untimed plan.
    heights : numpy.ndarray or None
        ``(n,)`` height, metres above the ground, of what each pointing's line of sight
        is aimed at, at its time (``times``, required with them): a plume top, the aim
        corrected for parallax (:class:`~dyntarget.schedule.ParallaxAim`). The NFOV slews
        to that top and tracks it after observing it, not the ground behind it
        (:func:`~dyntarget.schedule.schedule`). ``None`` or 0: the ground.
    windows : numpy.ndarray or None
        ``(n, 2)`` seconds after the WFOV acquisition: each pointing may start no earlier
        than its first value and must end by its second (``inf``, ``inf``: never), on top
        of its visibility window; e.g. only once the plume-top height it is aimed with is
        known (:class:`~dyntarget.schedule.ParallaxAim` ``known_s``). ``None``: any time.
    """

    points: np.ndarray
    part: np.ndarray
    planner: str
    params: dict[str, Any] = field(default_factory=dict)
    times: np.ndarray | None = None
    """When each observation starts, seconds after the WFOV acquisition (set by
    :func:`dyntarget.schedule.schedule`; ``None`` for an untimed plan)."""
    heights: np.ndarray | None = None
    """Height of what each pointing is aimed at, metres (``None``: the ground)."""
    windows: np.ndarray | None = None
    """When each pointing may be observed, seconds (``None``: any time)."""

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=np.float64).reshape(-1, 2)
        part = np.asarray(self.part, dtype=np.int64).reshape(-1)
        if len(part) != len(pts):
            raise InvalidParameterError(f"part: {len(part)} entries for {len(pts)} points")
        if self.times is not None:
            times = np.asarray(self.times, dtype=np.float64).reshape(-1)
            if len(times) != len(pts) or not np.isfinite(times).all():
                raise InvalidParameterError(
                    f"times: expected {len(pts)} finite times, got {len(times)}"
                )
            times.setflags(write=False)
            object.__setattr__(self, "times", times)
        if self.heights is not None:
            if self.times is None:
                raise InvalidParameterError(
                    "heights: expected the times the pointings were aimed for with them"
                )
            heights = np.asarray(self.heights, dtype=np.float64).reshape(-1)
            if len(heights) != len(pts) or not (np.isfinite(heights) & (heights >= 0)).all():
                raise InvalidParameterError(
                    f"heights: expected {len(pts)} finite heights >= 0, got {len(heights)}"
                )
            heights.setflags(write=False)
            object.__setattr__(self, "heights", heights)
        if self.windows is not None:
            windows = np.asarray(self.windows, dtype=np.float64)
            if windows.shape != (len(pts), 2) or np.isnan(windows).any():
                raise InvalidParameterError(
                    f"windows: expected ({len(pts)}, 2) seconds (from, until), not NaN, "
                    f"got shape {windows.shape}"
                )
            windows.setflags(write=False)
            object.__setattr__(self, "windows", windows)
        if not np.isfinite(pts).all():
            raise InvalidParameterError("points: trajectory holds NaN or infinite coordinates")
        pts.setflags(write=False)
        part.setflags(write=False)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "part", part)

    def __len__(self) -> int:
        return len(self.points)

    @classmethod
    def empty(cls, planner: str, params: dict[str, Any] | None = None) -> Trajectory:
        """A trajectory with no pointings.

        Parameters
        ----------
        planner : str
            Name of the planner.
        params : dict or None
            The planner's settings (default: none).

        Returns
        -------
        Trajectory
            ``(0, 2)`` points, no parts, untimed.
        """
        return cls(np.zeros((0, 2)), np.zeros(0, np.int64), planner, params or {})

    def without(self, drop: np.ndarray) -> Trajectory:
        """The trajectory without the pointings where ``drop`` (bool per point) is true.

        Parameters
        ----------
        drop : numpy.ndarray
            ``(n,)`` boolean, true for the pointings to drop.

        Returns
        -------
        Trajectory
            A new trajectory with the kept points, parts, times, heights and windows
            (planner and params unchanged).
        """
        keep = ~np.asarray(drop, bool)
        times = self.times[keep] if self.times is not None else None
        heights = self.heights[keep] if self.heights is not None else None
        windows = self.windows[keep] if self.windows is not None else None
        return Trajectory(
            self.points[keep],
            self.part[keep],
            self.planner,
            self.params,
            times,
            heights,
            windows,
        )

    @property
    def path_length(self) -> float:
        """Length of the whole path in WFOV pixels, travel hops included."""
        if len(self) < 2:
            return 0.0
        return float(np.hypot(*np.diff(self.points, axis=0).T).sum())

    @property
    def travel_length(self) -> float:
        """Length of the hops between parts (observing nothing) in WFOV pixels."""
        if len(self) < 2:
            return 0.0
        hops = np.diff(self.part) != 0
        return float(np.hypot(*np.diff(self.points, axis=0)[hops].T).sum())

    def world_points(self, transform: Affine | None) -> np.ndarray:
        """Points in the CRS of ``transform`` (pixel centres: ``transform @ (x + 0.5, y + 0.5)``).

        Parameters
        ----------
        transform : affine.Affine or None
            The WFOV grid's geotransform; ``None`` returns the pixel coordinates.

        Returns
        -------
        numpy.ndarray
            ``(n, 2)`` coordinates ``(X, Y)`` (a copy of ``points`` without a transform).
        """
        if transform is None:
            return self.points.copy()
        a, b, c, d, e, f = tuple(transform)[:6]
        x, y = self.points[:, 0] + 0.5, self.points[:, 1] + 0.5
        return np.column_stack([a * x + b * y + c, d * x + e * y + f])

    def to_csv(
        self,
        *,
        transform: Affine | None = None,
        crs: str | None = None,
        crs_mode: str = "rfc7946",
        acquired: Any = None,
    ) -> str:
        """CSV, one row per pointing (see :func:`dyntarget.io.geojson.trajectory_csv`).

        Columns ``order,x,y,part`` in pixels, then ``lon,lat`` (WGS 84, default)
        or ``X,Y`` (``crs_mode="native"``) when ``transform`` and ``crs`` are
        given, ``time_s`` when timed and ``time`` (ISO-8601 UTC) when ``acquired``
        is known too.

        Parameters
        ----------
        transform : affine.Affine or None
            The WFOV grid's geotransform.
        crs : str or None
            The image's CRS (e.g. ``"EPSG:32633"``).
        crs_mode : {"rfc7946", "native"}
            Write WGS 84 ``lon,lat`` or the image CRS's ``X,Y``.
        acquired : datetime.datetime or str or None
            When the WFOV image was taken, for the ``time`` column.

        Returns
        -------
        str
            The CSV text, header first.
        """
        from dyntarget.io.geojson import trajectory_csv

        return trajectory_csv(
            self, transform=transform, crs=crs, crs_mode=crs_mode, acquired=acquired
        )

    def to_geojson(
        self,
        *,
        transform: Affine | None = None,
        crs: str | None = None,
        crs_mode: str = "rfc7946",
        acquired: Any = None,
    ) -> dict[str, Any]:
        """RFC 7946 GeoJSON: the path and one Point per pointing (see
        :func:`dyntarget.io.geojson.trajectory_geojson`).

        WGS 84 lon/lat when ``transform`` and ``crs`` are given (the image's CRS
        with the legacy ``crs`` member when ``crs_mode="native"``), else WFOV
        pixel coordinates ``(column, row)``, said in ``properties.coordinates``.

        Parameters
        ----------
        transform : affine.Affine or None
            The WFOV grid's geotransform.
        crs : str or None
            The image's CRS (e.g. ``"EPSG:32633"``).
        crs_mode : {"rfc7946", "native"}
            WGS 84 coordinates, or the image's CRS with a legacy ``crs`` member.
        acquired : datetime.datetime or str or None
            When the WFOV image was taken, for the pointings' times.

        Returns
        -------
        dict
            The GeoJSON ``FeatureCollection``.
        """
        from dyntarget.io.geojson import trajectory_geojson

        return trajectory_geojson(
            self, transform=transform, crs=crs, crs_mode=crs_mode, acquired=acquired
        )

    def save(
        self,
        path: str | os.PathLike[str],
        *,
        transform: Affine | None = None,
        crs: str | None = None,
        crs_mode: str = "rfc7946",
        acquired: Any = None,
    ) -> Path:
        """Write ``.geojson``/``.json`` (GeoJSON) or ``.csv``, atomically
        (see :func:`dyntarget.io.geojson.write_trajectory`).

        Parameters
        ----------
        path : str or os.PathLike
            Output file; its suffix chooses the format.
        transform : affine.Affine or None
            The WFOV grid's geotransform.
        crs : str or None
            The image's CRS.
        crs_mode : {"rfc7946", "native"}
            As for :meth:`to_geojson` and :meth:`to_csv`.
        acquired : datetime.datetime or str or None
            When the WFOV image was taken.

        Returns
        -------
        pathlib.Path
            The file written.
        """
        from dyntarget.io.geojson import write_trajectory

        return write_trajectory(
            path, self, transform=transform, crs=crs, crs_mode=crs_mode, acquired=acquired
        )
