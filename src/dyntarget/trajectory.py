"""Trajectory: the ordered NFOV pointings, with export to CSV and GeoJSON."""

from __future__ import annotations

import json
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
    """

    points: np.ndarray
    part: np.ndarray
    planner: str
    params: dict[str, Any] = field(default_factory=dict)
    times: np.ndarray | None = None
    """When each observation starts, seconds after the WFOV acquisition (set by
    :func:`dyntarget.schedule.schedule`; ``None`` for an untimed plan)."""

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
        return cls(np.zeros((0, 2)), np.zeros(0, np.int64), planner, params or {})

    def without(self, drop: np.ndarray) -> Trajectory:
        """The trajectory without the pointings where ``drop`` (bool per point) is true."""
        keep = ~np.asarray(drop, bool)
        times = self.times[keep] if self.times is not None else None
        return Trajectory(self.points[keep], self.part[keep], self.planner, self.params, times)

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
        """Points in the CRS of ``transform`` (pixel centres: ``transform @ (x + 0.5, y + 0.5)``)."""
        if transform is None:
            return self.points.copy()
        a, b, c, d, e, f = tuple(transform)[:6]
        x, y = self.points[:, 0] + 0.5, self.points[:, 1] + 0.5
        return np.column_stack([a * x + b * y + c, d * x + e * y + f])

    def to_csv(self, *, transform: Affine | None = None) -> str:
        lines = [
            "order,x,y,part"
            + (",X,Y" if transform is not None else "")
            + (",time_s" if self.times is not None else "")
        ]
        world = self.world_points(transform)
        for i, ((x, y), p) in enumerate(zip(self.points, self.part, strict=True)):
            row = f"{i},{x:.3f},{y:.3f},{p}"
            if transform is not None:
                row += f",{world[i, 0]:.3f},{world[i, 1]:.3f}"
            if self.times is not None:
                row += f",{self.times[i]:.3f}"
            lines.append(row)
        return "\n".join(lines) + "\n"

    def to_geojson(
        self, *, transform: Affine | None = None, crs: str | None = None
    ) -> dict[str, Any]:
        """A FeatureCollection: one LineString (the path) and one Point per pointing with its order.

        Coordinates are in ``crs`` when ``transform`` is given (georeferenced
        scene), else in WFOV pixel coordinates ``(column, row)``.
        """
        world = self.world_points(transform)
        coords = [[round(float(x), 6), round(float(y), 6)] for x, y in world]
        props = {"planner": self.planner, "params": self.params, "pointings": len(self)}
        feats: list[dict[str, Any]] = []
        if len(coords) >= 2:
            feats.append(
                {
                    "type": "Feature",
                    "geometry": {"type": "LineString", "coordinates": coords},
                    "properties": props,
                }
            )
        for i, (xy, p) in enumerate(zip(coords, self.part.tolist(), strict=True)):
            feats.append(
                {
                    "type": "Feature",
                    "geometry": {"type": "Point", "coordinates": xy},
                    "properties": {"order": i, "part": p}
                    | (
                        {"time_s": round(float(self.times[i]), 3)} if self.times is not None else {}
                    ),
                }
            )
        doc: dict[str, Any] = {"type": "FeatureCollection", "features": feats, "properties": props}
        if transform is not None and crs is not None:
            doc["crs"] = {"type": "name", "properties": {"name": crs}}
        else:
            doc["coordinate_system"] = "WFOV pixels (column, row)"
        return doc

    def save(
        self,
        path: str | os.PathLike[str],
        *,
        transform: Affine | None = None,
        crs: str | None = None,
    ) -> Path:
        """Write ``.geojson``/``.json`` (GeoJSON) or ``.csv``, atomically."""
        from dyntarget.io.atomic import write_text  # io: the one place files are written

        path = Path(path)
        suffix = path.suffix.lower()
        if suffix in (".geojson", ".json"):
            return write_text(
                path, json.dumps(self.to_geojson(transform=transform, crs=crs)) + "\n"
            )
        if suffix == ".csv":
            return write_text(path, self.to_csv(transform=transform))
        raise InvalidParameterError(f"{path}: trajectory files must end in .geojson, .json or .csv")
