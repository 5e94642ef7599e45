"""GeoJSON and CSV writers for pointings and plume polygons (RFC 7946 by default).

Three coordinate forms, chosen by the scene's georeferencing and ``crs_mode``:

``rfc7946`` (default, georeferenced scene)
    WGS 84 longitude, latitude in degrees (RFC 7946), reprojected from the
    image's CRS with PROJ (``rasterio.warp.transform``); no ``crs`` member;
    polygons follow the right-hand rule (exterior counter-clockwise); a
    ``bbox``. A polygon or path that crosses the antimeridian is split there
    (RFC 7946 §3.1.9: a MultiPolygon or MultiLineString with parts on either
    side of 180°, by the ``antimeridian`` package) and the ``bbox`` then runs
    from its western edge east across 180°, west > east (§5.2); one that
    encloses a pole runs its ring along the pole's parallel. Coordinates are rounded to :data:`LONLAT_DECIMALS` = 7 decimals:
    1e-7 degree is 1.1 cm of latitude (less of longitude), so rounding moves a
    point by at most about 6 mm per axis, 1/80 of the 0.5 m NFOV pixel the paper
    simulates and far below a tenth of any WFOV pixel. (RFC 7946's suggested 6
    decimals, 11 cm, would be a fifth of that NFOV pixel.)
``native`` (``--crs native``, georeferenced scene)
    The image's own CRS (e.g. UTM metres), with the legacy (2008 draft)
    ``crs`` member that GDAL, and so QGIS, reads; rounded to :data:`METRE_DECIMALS`
    (millimetres). Web maps and RFC 7946 readers will misplace it.
pixels (no CRS known)
    WFOV pixel coordinates ``(column, row)``, pixel centres at integers, rounded
    to :data:`PIXEL_DECIMALS`; the collection's ``properties.coordinates`` says so.

Pixel ``(x, y)`` maps to the CRS as the pixel centre ``transform * (x + 0.5, y + 0.5)``.
Every feature also carries its pixel position (``x_px``, ``y_px``), so the WFOV
grid position survives any reprojection. Fields and units: ``docs/outputs.md``.
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from affine import Affine

from dyntarget.errors import InvalidParameterError
from dyntarget.io.acquisition import iso_utc, parse_acquired
from dyntarget.io.atomic import write_text

CRS_MODES = ("rfc7946", "native")
"""``crs_mode`` values: WGS 84 lon/lat (RFC 7946) or the image's own CRS (legacy ``crs`` member)."""
LONLAT_DECIMALS = 7
"""Decimals of longitude/latitude: 1e-7 degree <= 1.1 cm (see the module docstring)."""
METRE_DECIMALS = 3
"""Decimals of native (projected) coordinates: millimetres."""
PIXEL_DECIMALS = 3
"""Decimals of pixel coordinates: a thousandth of a WFOV pixel."""
TIME_DECIMALS = 3
"""Decimals of ``time_s``: milliseconds."""
WGS84 = "EPSG:4326"


class Pointings(Protocol):
    """What the writers read from a trajectory (``dyntarget`` ``Trajectory`` has it)."""

    @property
    def points(self) -> np.ndarray:
        """``(n, 2)`` pointings, WFOV pixel ``(x, y)``."""
        ...

    @property
    def part(self) -> np.ndarray:
        """``(n,)`` index of the part (polygon or pass) each pointing belongs to."""
        ...

    @property
    def planner(self) -> str:
        """The planner's registered name."""
        ...

    @property
    def params(self) -> dict[str, Any]:
        """The planner's settings."""
        ...

    @property
    def times(self) -> np.ndarray | None:
        """``(n,)`` seconds of each pointing, ``None`` for an untimed plan."""
        ...


def _check_mode(crs_mode: str) -> str:
    if crs_mode not in CRS_MODES:
        raise InvalidParameterError(
            f"crs_mode: expected one of {', '.join(CRS_MODES)}, got {crs_mode!r}"
        )
    return crs_mode


def coordinate_form(transform: Affine | None, crs: object | None, crs_mode: str) -> str:
    """Which coordinates the writers will use: ``"lonlat"``, ``"native"`` or ``"pixels"``.

    Parameters
    ----------
    transform : affine.Affine or None
        Pixel -> CRS transform of the WFOV grid.
    crs : str, rasterio CRS or None
        The grid's CRS.
    crs_mode : {"rfc7946", "native"}

    Returns
    -------
    str

    Examples
    --------
    >>> coordinate_form(None, None, "rfc7946")
    'pixels'
    >>> coordinate_form(Affine.translation(0, 0), "EPSG:32632", "native")
    'native'
    """
    _check_mode(crs_mode)
    if transform is None or crs is None:
        return "pixels"
    return "lonlat" if crs_mode == "rfc7946" else "native"


def pixels_to_crs(points: np.ndarray, transform: Affine) -> np.ndarray:
    """Pixel ``(x, y)`` (pixel centres at integers) to the transform's CRS.

    Parameters
    ----------
    points : array (N, 2)
        Pixel ``(column, row)``.
    transform : affine.Affine
        Pixel-corner transform (GDAL convention).

    Returns
    -------
    ndarray (N, 2)

    Examples
    --------
    >>> pixels_to_crs(np.array([[0.0, 0.0]]), Affine(10, 0, 500000, 0, -10, 4000000)).tolist()
    [[500005.0, 3999995.0]]
    """
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    a, b, c, d, e, f = tuple(transform)[:6]
    x, y = pts[:, 0] + 0.5, pts[:, 1] + 0.5
    return np.column_stack([a * x + b * y + c, d * x + e * y + f])


def crs_to_lonlat(xy: np.ndarray, crs: object) -> np.ndarray:
    """Coordinates in ``crs`` to WGS 84 ``(longitude, latitude)`` in degrees (PROJ).

    Parameters
    ----------
    xy : array (N, 2)
    crs : str or rasterio CRS

    Returns
    -------
    ndarray (N, 2)
        Longitude, latitude (always in that order, whatever the CRS's axis order).

    Examples
    --------
    >>> crs_to_lonlat(np.array([[500000.0, 0.0]]), "EPSG:32632").round(9).tolist()
    [[9.0, 0.0]]
    """
    from rasterio.crs import CRS
    from rasterio.warp import transform as warp

    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return xy.copy()
    lon, lat = warp(CRS.from_user_input(crs), CRS.from_user_input(WGS84), xy[:, 0], xy[:, 1])
    out = np.column_stack([lon, lat])
    if not np.isfinite(out).all():
        raise InvalidParameterError(
            f"crs: some coordinates do not reproject from {crs} to WGS 84 (outside the CRS's area)"
        )
    return out


def rfc7946_source_crs(geometries: Sequence[Mapping[str, Any]], crs: object | None) -> str | None:
    """``"EPSG:4326"`` when GeoJSON geometries without a ``crs`` member are RFC 7946 lon/lat.

    A GeoJSON file without a ``crs`` member is, by RFC 7946, WGS 84; older label
    files wrote the image's own CRS without saying so. The two are told apart for
    a projected image CRS: projected coordinates (metres from a false origin) do
    not all fall inside ``[-180, 180] x [-90, 90]``, degrees always do.

    Parameters
    ----------
    geometries : sequence of GeoJSON geometry mappings
    crs : the image's CRS, or None

    Returns
    -------
    str or None
        ``"EPSG:4326"`` to reproject from, or ``None`` (take the coordinates as they are).

    Examples
    --------
    >>> poly = {"type": "Polygon", "coordinates": [[[9.0, 45.0], [9.1, 45.0], [9.0, 45.1]]]}
    >>> rfc7946_source_crs([poly], "EPSG:32632")
    'EPSG:4326'
    >>> rfc7946_source_crs([poly], "EPSG:4326") is None  # already degrees: nothing to do
    True
    """
    if crs is None or not geometries:
        return None
    from rasterio.crs import CRS

    if not CRS.from_user_input(crs).is_projected:
        return None
    points: list[tuple[float, float]] = []
    stack: list[Any] = [g.get("coordinates") for g in geometries]
    while stack:
        item = stack.pop()
        if isinstance(item, (list, tuple)):
            if len(item) >= 2 and all(isinstance(v, (int, float)) for v in item[:2]):
                points.append((float(item[0]), float(item[1])))
            else:
                stack.extend(item)
    if not points:
        return None
    xy = np.asarray(points)
    degrees = (np.abs(xy[:, 0]) <= 180.0) & (np.abs(xy[:, 1]) <= 90.0)
    return WGS84 if bool(degrees.all()) else None


def _project(points_px: np.ndarray, transform, crs, form: str) -> np.ndarray:
    pts = np.asarray(points_px, np.float64).reshape(-1, 2)
    if form == "pixels":
        return pts.round(PIXEL_DECIMALS)
    world = pixels_to_crs(pts, transform)
    if form == "native":
        return world.round(METRE_DECIMALS)
    return crs_to_lonlat(world, crs).round(LONLAT_DECIMALS)


def _crs_name(crs: object) -> str:
    """The legacy ``crs`` member's name: an OGC URN when the CRS has an EPSG code, else WKT."""
    from rasterio.crs import CRS

    c = CRS.from_user_input(crs)
    epsg = c.to_epsg()
    return f"urn:ogc:def:crs:EPSG::{epsg}" if epsg else c.to_wkt()


def _collection_properties(transform, crs, form: str, acquired) -> dict[str, Any]:
    from rasterio.crs import CRS

    props: dict[str, Any] = {}
    if form == "lonlat":
        props["coordinates"] = "WGS 84 longitude, latitude in degrees (RFC 7946)"
    elif form == "native":
        props["coordinates"] = f"{CRS.from_user_input(crs).to_string()} (the image's CRS)"
    else:
        props["coordinates"] = (
            "WFOV pixels (column, row), pixel centres at integers; no CRS known for the image"
        )
    if form != "pixels":
        props["source_crs"] = CRS.from_user_input(crs).to_string()
        props["pixel_transform"] = [float(v) for v in tuple(transform)[:6]]
    if acquired is not None:
        props["acquired"] = iso_utc(acquired, 0.0)
    return props


def lonlat_bbox(coords: np.ndarray) -> list[float]:
    """RFC 7946 ``bbox`` of longitude/latitude positions, west > east across the antimeridian.

    Positions that span more than 180° of longitude are taken to straddle 180°
    when the widest empty stretch of longitude lies between them (no scene is
    half the globe wide): the box then runs from the east side of that stretch
    eastward across 180° to its west side (RFC 7946 §5.2). Positions on a pole
    (latitude ±90, a polygon enclosing it) span every longitude: -180 to 180 (§5.3).

    Parameters
    ----------
    coords : array (N, 2)
        Longitude, latitude in degrees, longitudes in [-180, 180]; N >= 1.

    Returns
    -------
    list of float
        ``[west, south, east, north]``.

    Examples
    --------
    >>> lonlat_bbox(np.array([[9.0, 45.0], [9.5, 45.2]]))
    [9.0, 45.0, 9.5, 45.2]
    >>> lonlat_bbox(np.array([[179.9, -30.1], [180.0, -30.0], [-180.0, -30.0], [-179.8, -29.9]]))
    [179.9, -30.1, -179.8, -29.9]
    """
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    west, east = float(lo[0]), float(hi[0])
    if east - west > 180.0 and not (np.abs(coords[:, 1]) == 90.0).any():
        lons = np.unique(np.where(coords[:, 0] == 180.0, -180.0, coords[:, 0]))  # one meridian
        gaps = np.diff(lons)
        i = int(np.argmax(gaps))
        if gaps[i] > lons[0] + 360.0 - lons[-1]:  # the widest gap is not the one across 180°
            west, east = float(lons[i + 1]), float(lons[i])
            east = 180.0 if east == -180.0 else east
    return [west, float(lo[1]), east, float(hi[1])]


def _finish(doc: dict[str, Any], coords: np.ndarray, form: str, crs) -> dict[str, Any]:
    if form == "native":
        doc["crs"] = {"type": "name", "properties": {"name": _crs_name(crs)}}
    if form == "lonlat" and len(coords):
        doc["bbox"] = lonlat_bbox(coords)
    return doc


def _crosses_antimeridian(geom: Any) -> bool:
    """Whether a lon/lat line or polygon has an edge that jumps more than 180° of longitude."""
    import shapely

    parts = getattr(geom, "geoms", [geom])
    rings = [
        r for p in parts for r in ([p.exterior, *p.interiors] if hasattr(p, "exterior") else [p])
    ]
    return any(
        bool((np.abs(np.diff(shapely.get_coordinates(r)[:, 0])) > 180.0).any()) for r in rings
    )


def _poles_inside(world: Any, crs: object) -> tuple[bool, bool]:
    """Whether the geometry, in the image's CRS, encloses the north and the south pole."""
    import shapely
    from rasterio.crs import CRS
    from rasterio.warp import transform as warp

    xs, ys = warp(CRS.from_user_input(WGS84), CRS.from_user_input(crs), [0.0, 0.0], [90.0, -90.0])
    inside = []
    for x, y in zip(xs, ys, strict=True):
        pole = shapely.Point(x, y)
        inside.append(bool(np.isfinite([x, y]).all() and world.contains(pole)))
    return inside[0], inside[1]


def _split_at_antimeridian(lonlat: Any, world: Any, crs: object) -> Any:
    """Split a lon/lat polygon or line crossing 180° into parts on either side (RFC 7946 §3.1.9).

    ``lonlat`` (rounded to :data:`LONLAT_DECIMALS`) is returned as it is when no
    edge crosses; else the ``antimeridian`` package cuts it at ±180° (straight
    lines in lon/lat, as RFC 7946 reads them), a polygon enclosing a pole (found
    in the image CRS, ``world``) closed along the pole's parallel. New vertices
    are rounded like the others.
    """
    import shapely

    if not _crosses_antimeridian(lonlat):
        return lonlat
    import antimeridian

    fixed: Any
    if lonlat.geom_type == "LineString":
        fixed = antimeridian.fix_line_string(lonlat, great_circle=False)
    else:
        north, south = _poles_inside(world, crs)
        fixed = antimeridian.fix_polygon(
            lonlat,
            force_north_pole=north,
            force_south_pole=south,
            fix_winding=False,
            great_circle=False,
        )
    fixed = shapely.transform(fixed, lambda c: c.round(LONLAT_DECIMALS))
    return shapely.remove_repeated_points(fixed)


def _point_extras(point_properties: Mapping[str, Sequence[Any]] | None, n: int) -> dict:
    extras = dict(point_properties or {})
    for key, values in extras.items():
        if len(values) != n:
            raise InvalidParameterError(
                f"point_properties[{key!r}]: expected {n} values (one per pointing), got {len(values)}"
            )
    return extras


def _json_value(v: Any) -> Any:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float):
        return round(v, 6) if np.isfinite(v) else None
    return v


def trajectory_geojson(
    traj: Pointings,
    *,
    transform: Affine | None = None,
    crs: object | None = None,
    crs_mode: str = "rfc7946",
    acquired: datetime | str | None = None,
    point_properties: Mapping[str, Sequence[Any]] | None = None,
    properties: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """A trajectory as a GeoJSON FeatureCollection: the path, then one Point per pointing.

    Parameters
    ----------
    traj : Trajectory
        The ordered pointings (``points`` in WFOV pixels, ``part``, optional ``times``).
    transform, crs : affine.Affine, CRS-like or None
        The WFOV grid's georeferencing; without both, coordinates stay in pixels.
    crs_mode : {"rfc7946", "native"}
        WGS 84 lon/lat without a ``crs`` member (default) or the image's CRS with one.
    acquired : datetime, ISO-8601 str or None
        Acquisition instant; with ``traj.times`` each pointing gets an ISO-8601 ``time``.
    point_properties : mapping of name -> sequence, optional
        Extra per-pointing values (e.g. ``{"utility": [...]}``), one per pointing.
    properties : mapping, optional
        Extra collection properties (e.g. ``{"scene": "etna"}``).

    Returns
    -------
    dict
        ``{"type": "FeatureCollection", "features": [...], "properties": {...}}``.
        The path is a ``LineString`` feature (``kind="path"``, only with two or
        more pointings); each pointing is a ``Point`` with ``kind="pointing"``,
        ``order``, ``part``, ``x_px``, ``y_px`` and, when timed, ``time_s`` (and ``time``).

    Examples
    --------
    >>> from dyntarget.trajectory import Trajectory
    >>> t = Trajectory(np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([0, 0]), "demo",
    ...                times=np.array([0.0, 1.5]))
    >>> doc = trajectory_geojson(t, transform=Affine(10, 0, 500000, 0, -10, 0),
    ...                          crs="EPSG:32632", acquired="2024-05-01T10:00:00Z")
    >>> doc["features"][2]["geometry"]["coordinates"]
    [9.0001348, -4.52e-05]
    >>> doc["features"][2]["properties"]["time"], "crs" in doc
    ('2024-05-01T10:00:01.500Z', False)
    """
    form = coordinate_form(transform, crs, crs_mode)
    when = None if acquired is None else parse_acquired(acquired)
    n = len(traj.points)
    coords = _project(traj.points, transform, crs, form)
    extras = _point_extras(point_properties, n)
    props = _collection_properties(transform, crs, form, when)
    props |= {"planner": traj.planner, "params": traj.params, "pointings": n}
    props |= dict(properties or {})
    times = traj.times
    feats: list[dict[str, Any]] = []
    if n >= 2:
        path_props: dict[str, Any] = {"kind": "path", "planner": traj.planner, "pointings": n}
        if times is not None:
            path_props |= {"time_s_start": round(float(times[0]), TIME_DECIMALS)}
            path_props |= {"time_s_end": round(float(times[-1]), TIME_DECIMALS)}
        feats.append(
            {
                "type": "Feature",
                "geometry": _path_geometry(traj.points, coords, transform, crs, form),
                "properties": path_props,
            }
        )
    px = np.asarray(traj.points, np.float64).reshape(-1, 2).round(PIXEL_DECIMALS)
    for i in range(n):
        p: dict[str, Any] = {
            "kind": "pointing",
            "order": i,
            "part": int(traj.part[i]),
            "x_px": float(px[i, 0]),
            "y_px": float(px[i, 1]),
        }
        if times is not None:
            p["time_s"] = round(float(times[i]), TIME_DECIMALS)
            if when is not None:
                p["time"] = iso_utc(when, float(times[i]))
        for key, values in extras.items():
            p[key] = _json_value(values[i])
        feats.append(
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": coords[i].tolist()},
                "properties": p,
            }
        )
    doc = {"type": "FeatureCollection", "features": feats, "properties": props}
    if n >= 2 and feats[0]["geometry"]["type"] == "MultiLineString":  # split at 180°
        coords = np.concatenate([coords, *map(np.asarray, feats[0]["geometry"]["coordinates"])])
    return _finish(doc, coords, form, crs)


def polygons_geojson(
    polygons: Sequence[Any],
    *,
    transform: Affine | None = None,
    crs: object | None = None,
    crs_mode: str = "rfc7946",
    acquired: datetime | str | None = None,
    properties: Mapping[str, Any] | None = None,
    feature_properties: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None = None,
) -> dict[str, Any]:
    """Plume polygons (shapely, in WFOV pixel coordinates) as a GeoJSON FeatureCollection.

    Parameters
    ----------
    polygons : sequence of shapely Polygon or MultiPolygon
        In pixel coordinates ``(column, row)``, pixel centres at integers (as
        :func:`dyntarget.denoise.denoise` returns them).
    transform, crs, crs_mode, acquired, properties
        As for :func:`trajectory_geojson`.
    feature_properties : mapping, sequence of mapping, or None
        Extra properties of each polygon, after the standard ones: one mapping for
        every polygon, or one per polygon (e.g. ``top_height_m``, ``top_height_sigma_m``,
        ``rise_mps``, ``height_source``); a NaN is written as null. ``None``: none (the
        document is exactly as without the argument).

    Returns
    -------
    dict
        One feature per polygon with ``kind="plume"``, ``index`` (largest first as
        given), ``area_px`` (WFOV pixels) and, when the CRS is projected in metres,
        ``area_m2``, then any ``feature_properties``. Rings follow the right-hand rule
        in the output coordinates.

    Raises
    ------
    InvalidParameterError
        For something that is not a polygon, an empty one, or ``feature_properties``
        of another length than ``polygons`` or overriding a standard property.

    Examples
    --------
    >>> from shapely.geometry import box
    >>> doc = polygons_geojson([box(0, 0, 2, 1)])
    >>> doc["features"][0]["geometry"]["coordinates"][0]
    [[2.0, 0.0], [2.0, 1.0], [0.0, 1.0], [0.0, 0.0], [2.0, 0.0]]
    >>> doc["features"][0]["properties"]["area_px"]
    2.0
    >>> doc = polygons_geojson([box(0, 0, 2, 1)], feature_properties={"top_height_m": 9000.0,
    ...                        "rise_mps": None, "height_source": "prior"})
    >>> doc["features"][0]["properties"]["top_height_m"], doc["features"][0]["properties"]["rise_mps"]
    (9000.0, None)
    """
    import shapely
    from rasterio.crs import CRS
    from shapely.geometry import mapping
    from shapely.geometry.polygon import orient

    form = coordinate_form(transform, crs, crs_mode)
    when = None if acquired is None else parse_acquired(acquired)
    per_feature = _feature_extras(feature_properties, len(polygons))
    metres = None
    if form != "pixels":
        c = CRS.from_user_input(crs)
        if c.is_projected and c.linear_units in ("metre", "meter"):
            assert transform is not None  # coordinate_form: only "pixels" has none
            metres = abs(transform.determinant)

    def project(coords: np.ndarray) -> np.ndarray:
        return _project(coords, transform, crs, form)

    def to_world(coords: np.ndarray) -> np.ndarray:
        assert transform is not None  # coordinate_form: only "pixels" has none
        return pixels_to_crs(coords, transform)

    def to_lonlat(coords: np.ndarray) -> np.ndarray:
        return crs_to_lonlat(coords, crs).round(LONLAT_DECIMALS)

    feats: list[dict[str, Any]] = []
    everything: list[np.ndarray] = []
    for i, poly in enumerate(polygons):
        if not isinstance(poly, shapely.Geometry) or poly.geom_type not in (
            "Polygon",
            "MultiPolygon",
        ):
            raise InvalidParameterError(
                f"polygons[{i}]: expected a shapely Polygon or MultiPolygon, got {type(poly).__name__}"
            )
        if poly.is_empty:
            raise InvalidParameterError(f"polygons[{i}]: the polygon is empty")
        out = shapely.transform(poly, project)
        parts = list(out.geoms) if out.geom_type == "MultiPolygon" else [out]
        if form == "lonlat" and _crosses_antimeridian(out):
            # orientation is taken in the image CRS (x east, y north), where it is well defined
            world = shapely.transform(poly, to_world)
            split = [
                _split_at_antimeridian(shapely.transform(g, to_lonlat), g, crs)
                for g in (orient(g, sign=1.0) for g in getattr(world, "geoms", [world]))
            ]
            parts = [q for p in split for q in getattr(p, "geoms", [p])]
        parts = [orient(p, sign=1.0) for p in parts]
        out = parts[0] if len(parts) == 1 else shapely.MultiPolygon(parts)
        everything.append(shapely.get_coordinates(out))
        p: dict[str, Any] = {"kind": "plume", "index": i, "area_px": round(float(poly.area), 3)}
        if metres is not None:
            p["area_m2"] = round(float(poly.area) * metres, 3)
        if per_feature is not None:
            p |= per_feature[i]
        feats.append({"type": "Feature", "geometry": _lists(mapping(out)), "properties": p})
    props = _collection_properties(transform, crs, form, when)
    props |= {"polygons": len(feats)} | dict(properties or {})
    doc = {"type": "FeatureCollection", "features": feats, "properties": props}
    coords = np.concatenate(everything) if everything else np.zeros((0, 2))
    return _finish(doc, coords, form, crs)


_POLYGON_FIELDS = ("kind", "index", "area_px", "area_m2")


def _feature_extras(
    extras: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None, n: int
) -> list[dict[str, Any]] | None:
    """``feature_properties`` as one JSON-ready dict per polygon (``None``: none given)."""
    if extras is None:
        return None
    if isinstance(extras, Mapping):
        rows: list[Any] = [extras] * n
    elif isinstance(extras, Sequence) and not isinstance(extras, str):
        rows = list(extras)
        if len(rows) != n:
            raise InvalidParameterError(
                f"feature_properties: expected {n} mappings (one per polygon), got {len(rows)}"
            )
    else:
        raise InvalidParameterError(
            f"feature_properties: expected a mapping or one per polygon, got {type(extras).__name__}"
        )
    out = []
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise InvalidParameterError(
                f"feature_properties[{i}]: expected a mapping, got {type(row).__name__}"
            )
        clash = [k for k in row if k in _POLYGON_FIELDS]
        if clash:
            raise InvalidParameterError(
                f"feature_properties: {clash[0]!r} is a standard polygon property; expected "
                "other names"
            )
        out.append({str(k): _json_value(v) for k, v in row.items()})
    return out


def _path_geometry(points_px, coords: np.ndarray, transform, crs, form: str) -> dict[str, Any]:
    """The path's GeoJSON geometry: a LineString, or a MultiLineString split at 180°."""
    if form != "lonlat" or not (np.abs(np.diff(coords[:, 0])) > 180.0).any():
        return {"type": "LineString", "coordinates": coords.tolist()}
    import shapely
    from shapely.geometry import mapping

    world = shapely.LineString(pixels_to_crs(points_px, transform))
    line = _split_at_antimeridian(shapely.LineString(coords), world, crs)
    return _lists(mapping(line))


def _lists(obj: Any) -> Any:
    """shapely's ``mapping`` gives tuples; JSON wants lists (and plain floats)."""
    if isinstance(obj, dict):
        return {k: _lists(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_lists(v) for v in obj]
    return float(obj) if isinstance(obj, (float, np.floating)) else obj


def trajectory_csv(
    traj: Pointings,
    *,
    transform: Affine | None = None,
    crs: object | None = None,
    crs_mode: str = "rfc7946",
    acquired: datetime | str | None = None,
    point_properties: Mapping[str, Sequence[Any]] | None = None,
) -> str:
    """A trajectory as CSV: one row per pointing, the same fields as the GeoJSON points.

    Columns: ``order,x,y,part`` (pixels), then ``lon,lat`` (RFC 7946 form) or
    ``X,Y`` (native form) when georeferenced, ``time_s`` when timed, ``time``
    when the acquisition instant is known too, then any ``point_properties``.
    Written by the :mod:`csv` module (RFC 4180 quoting: a value holding a
    comma, a quote or a line break is quoted, so it stays one field).

    Parameters
    ----------
    traj, transform, crs, crs_mode, acquired, point_properties
        As for :func:`trajectory_geojson`.

    Returns
    -------
    str

    Examples
    --------
    >>> from dyntarget.trajectory import Trajectory
    >>> t = Trajectory(np.array([[1.0, 2.0]]), np.array([0]), "demo", times=np.array([2.0]))
    >>> print(trajectory_csv(t, acquired="2024-05-01T10:00:00Z"), end="")
    order,x,y,part,time_s,time
    0,1.000,2.000,0,2.000,2024-05-01T10:00:02.000Z
    >>> print(trajectory_csv(t, point_properties={"note": ["ash, then gas"]}), end="")
    order,x,y,part,time_s,note
    0,1.000,2.000,0,2.000,"ash, then gas"
    """
    form = coordinate_form(transform, crs, crs_mode)
    when = None if acquired is None else parse_acquired(acquired)
    n = len(traj.points)
    extras = _point_extras(point_properties, n)
    times = traj.times
    header = ["order", "x", "y", "part"]
    if form == "lonlat":
        header += ["lon", "lat"]
    elif form == "native":
        header += ["X", "Y"]
    if times is not None:
        header.append("time_s")
        if when is not None:
            header.append("time")
    header += list(extras)
    world = _project(traj.points, transform, crs, form) if form != "pixels" else None
    fmt = "{:.7f}" if form == "lonlat" else "{:.3f}"
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")  # quotes a field holding a comma or quote
    writer.writerow(header)
    for i, (x, y) in enumerate(np.asarray(traj.points, np.float64).reshape(-1, 2)):
        row = [str(i), f"{x:.3f}", f"{y:.3f}", str(int(traj.part[i]))]
        if world is not None:
            row += [fmt.format(world[i, 0]), fmt.format(world[i, 1])]
        if times is not None:
            row.append(f"{float(times[i]):.3f}")
            if when is not None:
                row.append(iso_utc(when, float(times[i])))
        for values in extras.values():
            v = _json_value(values[i])
            row.append("" if v is None else str(v))
        writer.writerow(row)
    return buf.getvalue()


def write_geojson(path: str | os.PathLike[str], doc: Mapping[str, Any]) -> Path:
    """Write a GeoJSON document atomically (compact, UTF-8, trailing newline).

    Parameters
    ----------
    path : path-like
    doc : mapping

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = write_geojson(pathlib.Path(tempfile.mkdtemp()) / "e.geojson",
    ...                     {"type": "FeatureCollection", "features": []})
    >>> print(out.read_text(), end="")
    {"type":"FeatureCollection","features":[]}
    """
    return write_text(path, json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n")


def write_trajectory(
    path: str | os.PathLike[str],
    traj: Pointings,
    *,
    transform: Affine | None = None,
    crs: object | None = None,
    crs_mode: str = "rfc7946",
    acquired: datetime | str | None = None,
    point_properties: Mapping[str, Sequence[Any]] | None = None,
    properties: Mapping[str, Any] | None = None,
) -> Path:
    """Write a trajectory as ``.geojson``/``.json`` (GeoJSON) or ``.csv``, atomically.

    Parameters
    ----------
    path : path-like
        The suffix picks the format.
    traj, transform, crs, crs_mode, acquired, point_properties, properties
        As for :func:`trajectory_geojson` (``properties`` is GeoJSON only).

    Returns
    -------
    Path

    Raises
    ------
    InvalidParameterError
        For another suffix or a bad ``crs_mode``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from dyntarget.trajectory import Trajectory
    >>> t = Trajectory(np.array([[0.0, 0.0], [3.0, 4.0]]), np.array([0, 0]), "demo")
    >>> out = write_trajectory(pathlib.Path(tempfile.mkdtemp()) / "t.geojson", t)
    >>> json.loads(out.read_text())["properties"]["coordinates"][:11]
    'WFOV pixels'
    """
    path = Path(path)
    suffix = path.suffix.lower()
    kw: dict[str, Any] = dict(
        transform=transform,
        crs=crs,
        crs_mode=crs_mode,
        acquired=acquired,
        point_properties=point_properties,
    )
    if suffix in (".geojson", ".json"):
        return write_geojson(path, trajectory_geojson(traj, properties=properties, **kw))
    if suffix == ".csv":
        return write_text(path, trajectory_csv(traj, **kw))
    raise InvalidParameterError(
        f"{path}: trajectory files must end in .geojson, .json or .csv, got {suffix or 'no suffix'!r}"
    )


def write_polygons(
    path: str | os.PathLike[str],
    polygons: Sequence[Any],
    *,
    transform: Affine | None = None,
    crs: object | None = None,
    crs_mode: str = "rfc7946",
    acquired: datetime | str | None = None,
    properties: Mapping[str, Any] | None = None,
    feature_properties: Mapping[str, Any] | Sequence[Mapping[str, Any]] | None = None,
) -> Path:
    """Write plume polygons as GeoJSON (``.geojson``/``.json``), atomically.

    Parameters
    ----------
    path : path-like
    polygons, transform, crs, crs_mode, acquired, properties, feature_properties
        As for :func:`polygons_geojson`.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from shapely.geometry import box
    >>> out = write_polygons(pathlib.Path(tempfile.mkdtemp()) / "p.geojson", [box(0, 0, 1, 1)])
    >>> json.loads(out.read_text())["features"][0]["properties"]["kind"]
    'plume'
    """
    path = Path(path)
    if path.suffix.lower() not in (".geojson", ".json"):
        raise InvalidParameterError(
            f"{path}: polygon files must end in .geojson or .json, got {path.suffix or 'no suffix'!r}"
        )
    doc = polygons_geojson(
        polygons,
        transform=transform,
        crs=crs,
        crs_mode=crs_mode,
        acquired=acquired,
        properties=properties,
        feature_properties=feature_properties,
    )
    return write_geojson(path, doc)


PLUME_TRUTH_FIELDS = ("plume_id", "top_height_m", "rise_mps", "onset_s")
"""Properties of each Point of a ``<id>.plumes.geojson`` truth file, in order."""


def plumes_geojson(
    plumes: Sequence[Mapping[str, Any]], *, transform: Affine, crs: object
) -> dict[str, Any]:
    """The per-plume truth of a 3D world as an RFC 7946 FeatureCollection.

    One Point Feature per vent at its WGS 84 ``(longitude, latitude)``, with
    :data:`PLUME_TRUTH_FIELDS` (``top_height_m`` metres above sea level, ``rise_mps``
    m/s or null, ``onset_s`` seconds on the pass clock) and its world-grid position
    ``x_px``, ``y_px``.

    Parameters
    ----------
    plumes : sequence of mapping
        As :meth:`dyntarget.synth.dynamic.World.plumes` gives them (``x_px``, ``y_px``
        on the grid of ``transform``, pixel centres at integers, and the truth fields).
    transform : affine.Affine
        Pixel-corner transform of the world grid.
    crs : str or rasterio CRS
        The grid's CRS.

    Returns
    -------
    dict
        The FeatureCollection (with a ``bbox`` when there are plumes).

    Examples
    --------
    >>> doc = plumes_geojson(
    ...     [{"plume_id": 0, "x_px": 0.0, "y_px": 0.0, "top_height_m": 9000.0,
    ...       "rise_mps": 20.0, "onset_s": -600.0}],
    ...     transform=Affine(10, 0, 500000, 0, -10, 0), crs="EPSG:32632")
    >>> doc["features"][0]["geometry"]["coordinates"], doc["features"][0]["properties"]["top_height_m"]
    ([9.0000449, -4.52e-05], 9000.0)
    """
    pts = np.array([[float(p["x_px"]), float(p["y_px"])] for p in plumes], np.float64)
    rows = []
    for p in plumes:
        props = {k: _json_value(p.get(k)) for k in PLUME_TRUTH_FIELDS}
        props["x_px"] = round(float(p["x_px"]), PIXEL_DECIMALS)
        props["y_px"] = round(float(p["y_px"]), PIXEL_DECIMALS)
        rows.append(props)
    return _point_collection(pts.reshape(-1, 2), rows, transform, crs)


def _point_collection(
    pts: np.ndarray, rows: list[dict[str, Any]], transform: Affine | None, crs: object | None
) -> dict[str, Any]:
    """Point Features at grid pixels ``pts`` with ``rows`` as properties: WGS 84 lon/lat and
    a ``bbox`` where georeferenced, else pixels and a collection property saying so."""
    georef = transform is not None and crs is not None
    if georef and len(pts):
        assert transform is not None
        coords = np.round(crs_to_lonlat(pixels_to_crs(pts, transform), crs), LONLAT_DECIMALS)
    else:
        coords = pts.round(PIXEL_DECIMALS)
    features = [
        {
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [float(c[0]), float(c[1])]},
            "properties": props,
        }
        for props, c in zip(rows, coords, strict=True)
    ]
    doc: dict[str, Any] = {"type": "FeatureCollection", "features": features}
    if not georef:
        doc["properties"] = {
            "coordinates": "pixels (column, row) of the grid, pixel centres at integers; "
            "no CRS known"
        }
    elif len(pts):
        doc["bbox"] = lonlat_bbox(coords)
    return doc


def write_plumes(
    path: str | os.PathLike[str],
    plumes: Sequence[Mapping[str, Any]],
    *,
    transform: Affine,
    crs: object,
) -> Path:
    """Write :func:`plumes_geojson` to ``path`` (``.geojson``), atomically.

    Parameters
    ----------
    path : path-like
    plumes, transform, crs
        As for :func:`plumes_geojson`.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = write_plumes(pathlib.Path(tempfile.mkdtemp()) / "w.plumes.geojson", [],
    ...                    transform=Affine.identity(), crs="EPSG:32632")
    >>> json.loads(out.read_text())["features"]
    []
    """
    path = Path(path)
    if path.suffix.lower() not in (".geojson", ".json"):
        raise InvalidParameterError(f"{path}: plume files must end in .geojson or .json")
    return write_geojson(path, plumes_geojson(plumes, transform=transform, crs=crs))


HEIGHT_FIELDS = ("plume_id", "top_height_m", "top_height_sigma_m", "rise_mps", "height_source")
"""Properties of each Point of a pass's ``plumes.geojson`` (height estimates), in order."""
HEIGHT_SOURCES = ("estimated", "prior", "none")
"""``height_source`` values: measured from the look-ahead frames, a prior, or no height."""


def _field(estimate: Any, name: str) -> Any:
    if isinstance(estimate, Mapping):
        return estimate.get(name)
    return getattr(estimate, name, None)


def _optional_metres(i: int, name: str, v: Any) -> float | None:
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InvalidParameterError(
            f"estimates[{i}].{name}: expected a number or None, got {v!r:.40}"
        ) from None
    if np.isnan(f):
        return None
    if not np.isfinite(f):
        raise InvalidParameterError(f"estimates[{i}].{name}: expected a finite number, got {v!r}")
    return round(f, 6)


def height_estimates_geojson(
    estimates: Sequence[Any], *, transform: Affine | None, crs: object | None
) -> dict[str, Any]:
    """Per-plume top heights measured on a pass, as a GeoJSON FeatureCollection.

    One Point Feature per estimate at the ground position of the plume top it measured
    (parallax-corrected), in WGS 84 ``(longitude, latitude)`` (RFC 7946, as
    :func:`plumes_geojson`), with :data:`HEIGHT_FIELDS` (``top_height_m`` metres above
    sea level, ``top_height_sigma_m`` its one-sigma uncertainty, ``rise_mps`` m/s; null
    where not measured; ``height_source`` one of :data:`HEIGHT_SOURCES`) and the grid
    position ``x_px``, ``y_px``. Without ``transform`` and ``crs`` the coordinates stay in
    pixels of the grid and the collection's ``properties.coordinates`` says so.

    Parameters
    ----------
    estimates : sequence of mapping or object
        Each with ``plume_id``, ``x_px``, ``y_px`` (on the grid of ``transform``, pixel
        centres at integers), ``top_height_m``, ``top_height_sigma_m``, ``rise_mps``
        (``None`` or NaN: not measured) and ``height_source``, as keys or attributes.
    transform : affine.Affine or None
        Pixel-corner transform of the grid.
    crs : str, rasterio CRS or None
        The grid's CRS.

    Returns
    -------
    dict
        The FeatureCollection (with a ``bbox`` when georeferenced and not empty).

    Raises
    ------
    InvalidParameterError
        For a missing or non-finite position, a non-finite height, or an unknown
        ``height_source``.

    Examples
    --------
    >>> doc = height_estimates_geojson(
    ...     [{"plume_id": 1, "x_px": 0.0, "y_px": 0.0, "top_height_m": 9120.5,
    ...       "top_height_sigma_m": 310.0, "rise_mps": None, "height_source": "estimated"}],
    ...     transform=Affine(10, 0, 500000, 0, -10, 0), crs="EPSG:32632")
    >>> doc["features"][0]["geometry"]["coordinates"]
    [9.0000449, -4.52e-05]
    >>> p = doc["features"][0]["properties"]
    >>> p["top_height_m"], p["rise_mps"], p["height_source"]
    (9120.5, None, 'estimated')
    """
    rows: list[dict[str, Any]] = []
    pts = np.zeros((len(estimates), 2))
    for i, e in enumerate(estimates):
        try:
            pts[i] = [float(_field(e, "x_px")), float(_field(e, "y_px"))]
        except (TypeError, ValueError):
            raise InvalidParameterError(
                f"estimates[{i}]: expected numbers x_px and y_px, got "
                f"{_field(e, 'x_px')!r:.30}, {_field(e, 'y_px')!r:.30}"
            ) from None
        if not np.isfinite(pts[i]).all():
            raise InvalidParameterError(f"estimates[{i}]: x_px, y_px: expected finite pixels")
        source = _field(e, "height_source")
        if source not in HEIGHT_SOURCES:
            raise InvalidParameterError(
                f"estimates[{i}].height_source: expected one of {', '.join(HEIGHT_SOURCES)}, "
                f"got {source!r:.40}"
            )
        pid = _field(e, "plume_id")
        props: dict[str, Any] = {"plume_id": _json_value(pid)}
        for name in ("top_height_m", "top_height_sigma_m", "rise_mps"):
            props[name] = _optional_metres(i, name, _field(e, name))
        props["height_source"] = source
        props["x_px"] = round(float(pts[i, 0]), PIXEL_DECIMALS)
        props["y_px"] = round(float(pts[i, 1]), PIXEL_DECIMALS)
        rows.append(props)
    return _point_collection(pts, rows, transform, crs)


def write_height_estimates(
    path: str | os.PathLike[str],
    estimates: Sequence[Any],
    *,
    transform: Affine | None,
    crs: object | None,
) -> Path:
    """Write :func:`height_estimates_geojson` to ``path`` (``.geojson``), atomically.

    Parameters
    ----------
    path : path-like
    estimates, transform, crs
        As for :func:`height_estimates_geojson`.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = write_height_estimates(pathlib.Path(tempfile.mkdtemp()) / "plumes.geojson", [],
    ...                              transform=Affine.identity(), crs="EPSG:32632")
    >>> json.loads(out.read_text())["features"]
    []
    """
    path = Path(path)
    if path.suffix.lower() not in (".geojson", ".json"):
        raise InvalidParameterError(
            f"{path}: height estimate files must end in .geojson or .json, got "
            f"{path.suffix or 'no suffix'!r}"
        )
    return write_geojson(path, height_estimates_geojson(estimates, transform=transform, crs=crs))
