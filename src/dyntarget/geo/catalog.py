"""The catalog baseline: aim at the known volcanoes of a catalog, no GEO image at all.

What GEO adds over knowing where volcanoes are is measured against this
prior (``fly --geo-prior CATALOG``): the blueprint is planned on one target
per catalogued volcano over the strip, and refined onboard exactly as a GEO
blueprint is (:class:`dyntarget.geo.refine.BlueprintGate`).

* **Catalog.** A CSV with the Smithsonian Global Volcanism Program's columns
  (Volcanoes of the World: ``volcano_number``, ``volcano_name``,
  ``last_known_eruption`` such as ``2025 CE`` / ``8300 BCE`` / ``Unknown``,
  ``latitude``, ``longitude`` in WGS 84 degrees; other columns ignored),
  :func:`read_catalog` (through :func:`dyntarget.io.catalog.read_catalog`, the one
  catalog reader); ``active_since`` keeps the volcanoes that erupted in
  or after a year. A row with a missing or out-of-range coordinate (or an
  unreadable eruption year) is refused with one line naming the row and the field.
* **Synthetic strips** lie wherever their world's spec puts them (UTM 5N by
  default, with no real volcano under most of a long strip), so a real
  catalog says nothing about them: their own vents are the catalog there
  (:func:`strip_vents`, ``--geo-prior vents``): every vent, erupting or not,
  is a known volcano, as a perfect catalog of that world would list it.
* **Targets** (:func:`catalog_targets`): each volcano within ``radius_m`` of the
  strip's georeferenced footprint (the strip's CRS and transform,
  :func:`locate`) is one :class:`~dyntarget.geo.Target` at the vent, its span
  ``radius_m`` along track each way (where its plume may be: the catalog
  does not say which way the wind blows), worth :data:`PRIOR_VALUE` a
  pointing for ``need`` pointings (a plume of :data:`PRIOR_AREA_M2`): one
  number for every volcano, since the catalog does not say which erupts.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.geo.blueprint import Target
from dyntarget.geo.seams import MappedStrip, PassFrames
from dyntarget.io.catalog import eruption_year as eruption_year  # re-exported
from dyntarget.io.catalog import read_catalog as _read_catalog
from dyntarget.schedule import OrbitGeometry

if TYPE_CHECKING:
    from affine import Affine

PRIOR_VALUE = 0.1
"""Expected utility of one pointing on a catalogued volcano (the same for all)."""
PRIOR_AREA_M2 = 4e6
"""Expected plume area of a catalogued volcano, m² (about 10 km x 400 m)."""
PRIOR_RADIUS_M = 6_000.0
"""How far from its vent a volcano's plume is looked for, m (either way along track): as far
as a GEO target reaches beyond its cells (3 cells of 2 km, :data:`dyntarget.geo.targets.SPAN_CELLS`)."""
NEED_MAX = 400
"""Most pointings one target asks for (as the GEO targets)."""
VENTS = "vents"
"""``--geo-prior vents``: a synthetic strip's own vents are the catalog."""


@dataclass(frozen=True)
class Volcano:
    """One catalogued volcano.

    Parameters
    ----------
    name : str
        Its name.
    lat, lon : float
        WGS 84 degrees.
    number : int or None
        Its catalog number (GVP volcano number).
    last_eruption : int or None
        Year of its last known eruption (astronomical: 1 BCE is 0, 8300 BCE is -8299;
        ``None``: unknown).
    """

    name: str
    lat: float
    lon: float
    number: int | None = None
    last_eruption: int | None = None


def read_catalog(path: str | os.PathLike[str], *, active_since: int | None = None) -> list[Volcano]:
    """The volcanoes of a catalog CSV (module docstring), optionally only the recently active.

    Read by :func:`dyntarget.io.catalog.read_catalog` (the one catalog reader).

    Parameters
    ----------
    path : the CSV (GVP columns; ``latitude`` and ``longitude`` required).
    active_since : keep only volcanoes whose last known eruption is in or after this
        year (CE); ``None``: all.

    Returns
    -------
    list of Volcano
        In the file's order.

    Raises
    ------
    dyntarget.errors.DataFileError
        One line naming the file, the row (its line number) and the field.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "v.csv"
    >>> _ = p.write_text("volcano_name,latitude,longitude,last_known_eruption\\n"
    ...                  "Kilauea,19.421,-155.287,2025 CE\\nOld,10,10,8300 BCE\\n")
    >>> [v.name for v in read_catalog(p)], [v.name for v in read_catalog(p, active_since=2000)]
    (['Kilauea', 'Old'], ['Kilauea'])
    """
    cat = _read_catalog(path)
    out: list[Volcano] = []
    for k in range(len(cat)):
        year = None if math.isnan(cat.last_year[k]) else int(cat.last_year[k])
        if active_since is not None and (year is None or year < active_since):
            continue
        number = int(cat.number[k])
        out.append(
            Volcano(
                cat.name[k],
                float(cat.lat[k]),
                float(cat.lon[k]),
                None if number < 0 else number,
                year,
            )
        )
    return out


def locate(
    volcanoes: list[Volcano],
    crs: str | None,
    transform: Affine | None,
    shape: tuple[int, int] | None = None,
    margin_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Strip pixel ``(row, col)`` (high resolution, fractional) of each volcano.

    With ``shape``, only volcanoes within the strip's longitude/latitude bounds
    (widened by ``margin_m``) are projected, the others are ``nan``: a projection
    such as UTM is not defined (or not meaningful) on the other side of the Earth.

    Parameters
    ----------
    volcanoes : from :func:`read_catalog`.
    crs : the strip's CRS (anything :mod:`rasterio.crs` reads).
    transform : its pixel -> CRS :class:`affine.Affine`.
    shape : the strip's ``(rows, cols)``, high resolution (``None``: project all).
    margin_m : how far beyond the strip a volcano is still projected, metres.

    Returns
    -------
    (rows, cols) : numpy.ndarray
        Pixel coordinates (pixel ``i`` spans ``[i, i + 1)``), may lie outside the strip.

    Examples
    --------
    >>> from affine import Affine
    >>> t = Affine(1000.0, 0, 500_000.0, 0, -1000.0, 2_200_000.0)   # UTM 5N, 1 km pixels
    >>> r, c = locate([Volcano("Kilauea", 19.421, -155.287)], "EPSG:32605", t)
    >>> round(float(r[0]), 1), round(float(c[0]), 1)
    (51.0, -240.1)
    """
    from rasterio.warp import transform as warp

    if crs is None or transform is None:
        raise InvalidSceneError(
            "the catalog prior needs a georeferenced strip (a CRS and a geotransform)"
        )
    lons = np.array([v.lon for v in volcanoes], np.float64)
    lats = np.array([v.lat for v in volcanoes], np.float64)
    near = np.ones(len(volcanoes), bool)
    if shape is not None:
        near = _near_footprint(lons, lats, crs, transform, shape, margin_m)
    rows = np.full(len(volcanoes), np.nan)
    cols = np.full(len(volcanoes), np.nan)
    if near.any():
        xs, ys = warp("EPSG:4326", crs, lons[near].tolist(), lats[near].tolist())
        c, r = _apply(~transform, np.asarray(xs, np.float64), np.asarray(ys, np.float64))
        rows[near], cols[near] = r, c
    return rows, cols


def _near_footprint(
    lons: np.ndarray,
    lats: np.ndarray,
    crs: str,
    transform: Affine,
    shape: tuple[int, int],
    margin_m: float,
) -> np.ndarray:
    """Volcanoes within the strip's lon/lat bounds widened by ``margin_m`` (and 0.05 degrees)."""
    from rasterio.transform import array_bounds
    from rasterio.warp import transform_bounds

    h, w = shape
    west, south, east, north = transform_bounds(
        crs, "EPSG:4326", *array_bounds(h, w, transform), densify_pts=21
    )
    dlat = margin_m / 111_000.0 + 0.05
    coslat = max(math.cos(math.radians(min(89.0, max(abs(south), abs(north)) + dlat))), 0.01)
    dlon = min(180.0, margin_m / 111_000.0 / coslat + 0.05)
    ok = (lats >= south - dlat) & (lats <= north + dlat)
    west, east = west - dlon, east + dlon
    if west > east or west < -180.0 or east > 180.0:  # across the antimeridian
        lo, hi = ((west + 180.0) % 360.0) - 180.0, ((east + 180.0) % 360.0) - 180.0
        near: np.ndarray = ok & ((lons >= lo) | (lons <= hi))
    else:
        near = ok & (lons >= west) & (lons <= east)
    return near


def _apply(t: Affine, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An affine transform applied to arrays of points."""
    return t.a * x + t.b * y + t.c, t.d * x + t.e * y + t.f


def strip_vents(world: MappedStrip) -> list[Volcano]:
    """A synthetic strip's own vents as a catalog (their lon/lat through the strip's CRS).

    Parameters
    ----------
    world : MappedStrip
        A synthetic strip (its ``vent_pixels``, ``crs``, ``transform``).

    Returns
    -------
    list of Volcano
        ``vent 1``, ``vent 2``, ... in the spec's order.

    Examples
    --------
    >>> from dyntarget.synth.strip_world import MovingStrip
    >>> from dyntarget.synth.strip import strip_spec
    >>> w = MovingStrip(*strip_spec(0, width=64, length=256, plumes=2))
    >>> [v.name for v in strip_vents(w)]
    ['vent 1', 'vent 2']
    """
    from rasterio.warp import transform as warp

    px = world.vent_pixels()
    if px is None:
        raise InvalidSceneError(
            f"strip {world.id!r}: --geo-prior {VENTS} needs a synthetic "
            "strip (its vents are the catalog); give a catalog CSV"
        )
    if not len(px):
        return []
    if world.crs is None or world.transform is None:
        raise InvalidSceneError(
            "the catalog prior needs a georeferenced strip (a CRS and a geotransform)"
        )
    cols, rows = px[:, 0], px[:, 1]
    xs, ys = _apply(world.transform, cols, rows)
    lons, lats = warp(world.crs, "EPSG:4326", list(np.atleast_1d(xs)), list(np.atleast_1d(ys)))
    return [
        Volcano(f"vent {i + 1}", float(la), float(lo))
        for i, (lo, la) in enumerate(zip(lons, lats, strict=True))
    ]


def catalog_targets(
    rows: np.ndarray,
    cols: np.ndarray,
    wfov_shape: tuple[int, int],
    frame_px: int,
    geometry: OrbitGeometry,
    factor: int,
    *,
    radius_m: float = PRIOR_RADIUS_M,
    value: float = PRIOR_VALUE,
    area_m2: float = PRIOR_AREA_M2,
) -> tuple[list[Target], np.ndarray]:
    """One blueprint target per volcano within ``radius_m`` of the strip (module docstring).

    Pass coordinates as the loop's: frame 0 (the strip's bottom ``frame_px`` WFOV
    rows) is acquired at pass time 0 with its centre ``look_ahead_m`` ahead of
    nadir; targets' ``span`` is in strip WFOV rows (what the gate matches).

    Parameters
    ----------
    rows, cols : the volcanoes' strip pixels, high resolution (:func:`locate`).
    wfov_shape : the strip's WFOV grid ``(H, W)``.
    frame_px : rows per look-ahead frame.
    geometry : the pass's :class:`~dyntarget.schedule.OrbitGeometry` (look-ahead, WFOV GSD).
    factor : high-res -> WFOV factor.
    radius_m : how far from the vent its plume is looked for.
    value : expected utility of one pointing.
    area_m2 : expected plume area (``need`` = its WFOV pixels, at most :data:`NEED_MAX`).

    Returns
    -------
    (targets, index) : the targets (along-track order) and which volcano each is.

    Examples
    --------
    >>> from dyntarget.schedule import OrbitGeometry
    >>> g = OrbitGeometry(look_ahead_m=500e3, wfov_gsd_m=100.0)
    >>> ts, i = catalog_targets(np.array([400.0, 9e9]), np.array([200.0, 0.0]), (200, 100),
    ...                         50, g, 4, radius_m=1000.0)
    >>> i.tolist(), ts[0].along_m, ts[0].cross_m, ts[0].span, ts[0].need
    ([0], 507500.0, 0.0, (89.5, 109.5), 400)
    """
    for name, v in (("radius_m", radius_m), ("value", value), ("area_m2", area_m2)):
        if not (math.isfinite(v) and v >= 0):
            raise InvalidParameterError(f"catalog prior {name}: expected a number >= 0, got {v!r}")
    h, w = wfov_shape
    g = geometry.wfov_gsd_m
    reach = radius_m / g
    r = np.asarray(rows, np.float64) / factor - 0.5  # WFOV pixel coordinates (centres on integers)
    c = np.asarray(cols, np.float64) / factor - 0.5
    near = (
        (r >= -0.5 - reach) & (r <= h - 0.5 + reach) & (c >= -0.5 - reach) & (c <= w - 0.5 + reach)
    )
    index = np.flatnonzero(near)
    need = int(np.clip(round(area_m2 / g**2), 1, NEED_MAX))
    targets = []
    for i in index:
        row = float(np.clip(r[i], 0.0, h - 1.0))
        col = float(np.clip(c[i], 0.0, w - 1.0))
        along = geometry.look_ahead_m + ((frame_px - 1) / 2.0 - (row - (h - frame_px))) * g
        targets.append(
            Target(
                float(along),
                (col - (w - 1) / 2.0) * g,
                float(value),
                need,
                (max(0.0, row - reach), min(h - 1.0, row + reach)),
            )
        )
    order = np.argsort([t.along_m for t in targets], kind="stable")
    return [targets[k] for k in order], index[order]


def prior_targets(
    source: str | os.PathLike[str],
    world: MappedStrip,
    frames: PassFrames,
    factor: int,
    *,
    active_since: int | None = None,
) -> tuple[list[Target], dict[str, Any]]:
    """The catalog baseline's targets for a pass (what ``fly --geo-prior`` plans on).

    Parameters
    ----------
    source : a catalog CSV, or ``"vents"`` (a synthetic strip's own vents).
    world : MappedStrip
        The strip (``crs``, ``transform``; ``vent_pixels`` for ``"vents"``).
    frames : PassFrames
        The pass's frame plan (``wfov_shape``, ``frame_px``, ``geometry``).
    factor : high-res -> WFOV factor.
    active_since : only volcanoes that erupted in or after this year (CE).

    Returns
    -------
    (targets, info) : the targets, and what summary.json records (catalog, counts, names).

    Examples
    --------
    >>> from dyntarget.fly import PassConfig
    >>> from dyntarget.passes.record import frame_plan
    >>> from dyntarget.synth.strip_world import MovingStrip
    >>> from dyntarget.synth.strip import strip_spec
    >>> w = MovingStrip(*strip_spec(0, width=64, length=256, plumes=2))
    >>> ts, info = prior_targets("vents", w, frame_plan(w, PassConfig()), 4)
    >>> len(ts), info["volcanoes"], info["in_footprint"]
    (2, 2, 2)
    """
    if str(source) == VENTS:
        volcanoes = strip_vents(world)
    else:
        volcanoes = read_catalog(source, active_since=active_since)
    rows, cols = locate(volcanoes, world.crs, world.transform, world.shape, PRIOR_RADIUS_M)
    targets, index = catalog_targets(
        rows, cols, frames.wfov_shape, frames.frame_px, frames.geometry, factor
    )
    info = {
        "images": "none: the catalog prior (no GEO image)",
        "catalog": str(source),
        "volcanoes": len(volcanoes),
        "in_footprint": len(targets),
        "names": [volcanoes[i].name for i in index][:50],
    }
    return targets, info
