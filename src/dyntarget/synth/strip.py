"""Synthetic strips to fly over: the moving worlds of ``synth --strip`` and their files.

A synthetic strip is one :class:`dyntarget.synth.dynamic.World` (the moving
world of ``synth --frames``) with several vents placed along a long window,
``width`` pixels across and ``length`` along the flight direction (north, up).
On disk (``dyntarget synth --strip``)::

    <id>.tif             the strip at t = 0 (4-band GeoTIFF, to look at or fly as static)
    <id>_mask.tif        its truth at t = 0
    <id>.world.json      {"format": "dyntarget-strip", "version": 1,
                          "world": <WorldSpec>, "window": [col0, row0, width, length]}

:func:`strip_spec` and :func:`long_strip_spec` make the worlds, :func:`write_strip`
and :func:`write_long_strip` write them, :func:`resampled_spec` puts a world on a
coarser grid (the GEO imager's, the WFOV's). ``fly`` reads the sidecar and renders
every look-ahead frame and the truth at the time it is needed
(:func:`dyntarget.synth.strip_world.load_world`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError
from dyntarget.io.atomic import write_text
from dyntarget.synth.dynamic import World as MovingWorld
from dyntarget.synth.dynamic import WorldSpec, sample_strip

STRIP_FORMAT = "dyntarget-strip"
SIDECAR = ".world.json"
LONG_VERSION = 2
"""Sidecar version of a long strip (rendered lazily, :class:`LongStrip`)."""
MIN_LENGTH_KM, MAX_LENGTH_KM = 10.0, 10_000.0
MAX_LONG_ROWS = 2_000_000
"""Most rows of a long strip's window (10,000 km at 5 m; the default 8 m gives 1,250,000)."""
PREVIEW_ROWS = 1152
"""Rows of a long strip written as its ``<id>.tif`` preview (the start of the pass)."""
LONG_ERUPTION_AGE_S = 7200.0
"""Vents of a long strip have erupted this long at t = 0 (steady plumes in every GEO image)."""


def strip_spec(
    seed: int,
    *,
    width: int = 256,
    length: int = 1152,
    plumes: int = 4,
    gsd: float = 8.0,
    wind_mps: float | None = None,
    wind_from_deg: float | None = None,
) -> tuple[WorldSpec, tuple[int, int, int, int]]:
    """A moving world with ``plumes`` vents along a ``width`` x ``length`` px strip.

    The world is :func:`dyntarget.synth.dynamic.sample_strip`'s (one wind for
    the whole strip, one vent per ``length / plumes`` rows), named ``strip-<seed>``.

    Parameters
    ----------
    seed : the strip's seed (same seed, same strip).
    width, length : strip size in high-resolution pixels.
    plumes : number of vents (>= 1).
    gsd : high-resolution ground sampling distance, m.
    wind_mps, wind_from_deg : the wind (meteorological convention); drawn if not given.

    Returns
    -------
    (WorldSpec, window): the world and the strip's window ``(col0, row0, width, length)``.

    Examples
    --------
    >>> spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    >>> len(spec.vents), window, spec.id
    (2, (0, 0, 64, 256), 'strip-0000')
    """
    for name, v, lo in (("width", width, 32), ("length", length, 64), ("plumes", plumes, 1)):
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise InvalidParameterError(f"{name}: expected an integer >= {lo}, got {v!r}")
    spec, window = sample_strip(
        seed,
        length=length,
        width=width,
        plumes=plumes,
        gsd=gsd,
        wind_mps=wind_mps,
        wind_from_deg=wind_from_deg,
    )
    return replace(spec, id=f"strip-{seed:04d}"), window


def with_parallax_margin(
    spec: WorldSpec,
    window: tuple[int, int, int, int],
    *,
    altitude_m: float = defaults.ALTITUDE_M,
    look_ahead_m: float = defaults.LOOK_AHEAD_M,
) -> tuple[WorldSpec, tuple[int, int, int, int]]:
    """A 3D strip lengthened to the north by the parallax of its highest plume top.

    A look-ahead ``look_ahead_m`` ahead sees a plume top at height ``h`` displaced away
    from the spacecraft (north, towards row 0) by its parallax (17.3 km for a 15 km top at
    the default geometry): on a short strip the plumes of its northern vents would be seen
    beyond its end. The strip gains that many rows at its top, with no vent of its own
    (every vent moves down by the same rows; the ground, clouds and wind are the world's
    as before). A flat spec is returned unchanged.

    Parameters
    ----------
    spec : WorldSpec
        A strip's world (:func:`strip_spec`), 3D (``spec.is_3d``) or flat.
    window : tuple of int
        Its window ``(col0, row0, width, length)``, ``row0 == 0``.
    altitude_m, look_ahead_m : float
        The geometry the margin is sized for (the project's defaults).

    Returns
    -------
    (WorldSpec, window)
        The spec with its vents moved south by the margin, and the longer window.

    Examples
    --------
    >>> from dyntarget.synth.dynamic import with_heights
    >>> spec, window = strip_spec(0, width=64, length=256, plumes=1, wind_mps=5.0)
    >>> spec3 = with_heights(spec, plume_height_km=(10.0, 10.0))
    >>> _, longer = with_parallax_margin(spec3, window)
    >>> longer  # 11.50 km of parallax at 8 m: 1438 rows more
    (0, 0, 64, 1694)
    >>> with_parallax_margin(spec, window) == (spec, window)
    True
    """
    if not spec.is_3d:
        return spec, window
    from dyntarget import parallax

    top = max((float(v.top_height_m or 0.0) for v in spec.vents), default=0.0)
    top = max([top, *(float(c.height_m or 0.0) for c in spec.clouds if c.volcanic)])
    shift = float(parallax.parallax_shift(altitude_m, look_ahead_m, top))
    margin = math.ceil(shift / spec.gsd)
    if margin <= 0:
        return spec, window
    c0, r0, w, length = window
    vents = tuple(replace(v, y=v.y + margin) for v in spec.vents)
    clouds = tuple(replace(c, y=c.y + margin) if c.volcanic else c for c in spec.clouds)
    return replace(spec, vents=vents, clouds=clouds), (c0, r0, w, length + margin)


def long_strip_spec(
    seed: int,
    length_km: float,
    *,
    width: int = 256,
    gsd: float = 8.0,
    plumes: int | None = None,
    plumes_per_100km: float | None = None,
    clouds_per_100km: float = 2.0,
    wind_mps: float | None = None,
    wind_from_deg: float | None = None,
) -> tuple[WorldSpec, tuple[int, int, int, int]]:
    """A pass-length moving world: vents and drifting clouds spread along ``length_km``.

    ``plumes`` vents (or ``plumes_per_100km`` per 100 km, at least one), one per
    equal segment of the strip at a random place inside it (30-70 % of the
    segment, 25-75 % across); each vent has the plume draws of
    :func:`dyntarget.synth.dynamic.sample_world` (world ``k`` of ``seed``) and has
    erupted :data:`LONG_ERUPTION_AGE_S` at t = 0, so its plume is steady in every
    geostationary image before the pass. Meteorological clouds (not plume: they
    hide the ground and the plumes from both sensors) are placed uniformly,
    ``clouds_per_100km`` per 100 km, 0.3-1.5 km in radius.

    Parameters
    ----------
    seed : the strip's seed.
    length_km : strip length along track, km (10 .. 10 000).
    width : strip width, high-resolution pixels.
    gsd : high-resolution ground sampling distance, m.
    plumes, plumes_per_100km : the vents: a count, or a density (one of them; default 1 / 100 km).
    clouds_per_100km : meteorological cloud density (the clouds drawn must not exceed
        :data:`~dyntarget.synth.dynamic.MAX_CLOUDS`; more are refused, not capped).
    wind_mps, wind_from_deg : the wind (drawn if not given).

    Returns
    -------
    (WorldSpec, window): the world and the strip's window ``(0, 0, width, rows)``.

    Examples
    --------
    >>> spec, window = long_strip_spec(0, 500.0, plumes_per_100km=0.4)
    >>> len(spec.vents), window, spec.id
    (2, (0, 0, 256, 62500), 'strip-0000')
    """
    from dyntarget.synth.dynamic import MAX_CLOUDS, MAX_VENTS, CloudSpec, VentSpec, sample_world

    if not (isinstance(length_km, int | float) and MIN_LENGTH_KM <= length_km <= MAX_LENGTH_KM):
        raise InvalidParameterError(
            f"length_km: expected {MIN_LENGTH_KM:g} to {MAX_LENGTH_KM:g} km, got {length_km!r}"
        )
    if isinstance(width, bool) or not isinstance(width, int) or not 32 <= width <= 4096:
        raise InvalidParameterError(f"width: expected an integer in 32..4096, got {width!r}")
    if plumes is not None and plumes_per_100km is not None:
        raise InvalidParameterError("give plumes or plumes_per_100km, not both")
    if plumes_per_100km is not None and not (
        math.isfinite(plumes_per_100km) and plumes_per_100km > 0
    ):
        raise InvalidParameterError(
            f"plumes_per_100km: expected a density > 0, got {plumes_per_100km!r}"
        )
    if not (math.isfinite(clouds_per_100km) and clouds_per_100km >= 0):
        raise InvalidParameterError(
            f"clouds_per_100km: expected a density >= 0, got {clouds_per_100km!r}"
        )
    rows = round(length_km * 1e3 / gsd)
    if rows < 4 * width:
        raise InvalidParameterError(
            f"length_km: {length_km:g} km is {rows} px at {gsd:g} m, shorter than 4 x the width"
        )
    n = (
        plumes
        if plumes is not None
        else max(1, round(length_km / 100.0 * (plumes_per_100km or 1.0)))
    )
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_VENTS:
        raise InvalidParameterError(
            f"plumes: expected 1 to {MAX_VENTS} vents along the strip, got {n!r}"
        )
    base = sample_world(
        seed, 0, size=width, gsd=gsd, wind_mps=wind_mps, wind_from_deg=wind_from_deg
    )
    rng = np.random.default_rng([int(seed), 0xD7])
    seg = rows / n
    vents = []
    for k in range(n):
        v = sample_world(
            seed, k, size=width, gsd=gsd, wind_mps=base.wind.speed_mps,
            wind_from_deg=base.wind.from_deg,
        ).vents[0]  # fmt: skip
        y = seg * (k + float(rng.uniform(0.3, 0.7)))
        x = width * float(rng.uniform(0.25, 0.75))
        vents.append(
            VentSpec(**{**v.__dict__, "x": x, "y": y, "eruption_age_s": LONG_ERUPTION_AGE_S})
        )
    n_clouds = int(rng.poisson(length_km / 100.0 * clouds_per_100km))
    if n_clouds > MAX_CLOUDS:  # refused, not silently capped
        raise InvalidParameterError(
            f"clouds_per_100km: {n_clouds} clouds drawn over {length_km:g} km, more than the "
            f"{MAX_CLOUDS} a strip may hold (--clouds-per-100km); give a lower density"
        )
    clouds = [
        CloudSpec(
            x=float(rng.uniform(-0.2, 1.2) * width),
            y=float(rng.uniform(0.0, rows)),
            radius_m=float(rng.uniform(300.0, 1500.0)),
            optical_depth=float(rng.uniform(2.0, 6.0)),
            volcanic=False,
            ash_fraction=0.0,
        )
        for _ in range(n_clouds)
    ]
    spec = replace(
        base, vents=tuple(vents), clouds=tuple(clouds), tile=2048, id=f"strip-{int(seed):04d}"
    )
    return spec, (0, 0, int(width), rows)


def write_long_strip(
    spec: WorldSpec, window: tuple[int, int, int, int], directory: str | os.PathLike[str]
) -> list[Path]:
    """Write a long strip: its world sidecar (version 2) and a preview of its start.

    ``<id>.tif`` / ``<id>_mask.tif`` hold only the first :data:`PREVIEW_ROWS`
    rows flown (the bottom of the strip) at t = 0; ``fly`` renders the whole
    strip from ``<id>.world.json``, frame by frame.

    Parameters
    ----------
    spec, window : from :func:`long_strip_spec`.
    directory : output directory (created).

    Returns
    -------
    list of the paths written (each atomically).
    """
    from dyntarget.io import write_scene

    directory = Path(directory)
    c0, r0, w, h = window
    n = min(PREVIEW_ROWS, h)
    scene = MovingWorld(spec).scene(0.0, (c0, r0 + h - n, w, n), id=spec.id)
    written: list[Path] = write_scene(scene, directory)
    doc = {
        "format": STRIP_FORMAT,
        "version": LONG_VERSION,
        "world": spec.to_dict(),
        "window": list(window),
        "length_km": h * spec.gsd / 1e3,
        "preview_rows": n,
    }
    written.append(write_text(directory / f"{spec.id}{SIDECAR}", json.dumps(doc, sort_keys=True)))
    return written


def write_strip(
    spec: WorldSpec, window: tuple[int, int, int, int], directory: str | os.PathLike[str]
) -> list[Path]:
    """Write a synthetic strip (image and truth at t = 0, and the world sidecar).

    Parameters
    ----------
    spec, window : from :func:`strip_spec`.
    directory : output directory (created).

    Returns
    -------
    list of the paths written (each atomically).
    """
    from dyntarget.io import write_scene

    directory = Path(directory)
    scene = MovingWorld(spec).scene(0.0, window, id=spec.id)
    written: list[Path] = write_scene(scene, directory)
    doc = {"format": STRIP_FORMAT, "version": 1, "world": spec.to_dict(), "window": list(window)}
    written.append(write_text(directory / f"{spec.id}{SIDECAR}", json.dumps(doc, sort_keys=True)))
    return written


def resampled_spec(
    spec: WorldSpec, gsd: float, to: Callable[[float], float], **changes: Any
) -> WorldSpec:
    """The same world on another grid: ``gsd`` metres a pixel, every position mapped by ``to``.

    The grid's size is ``to(size)`` (at least 16 pixels); vents and clouds move with it.

    Parameters
    ----------
    spec : WorldSpec
        The world.
    gsd : float
        The new grid's pixel size, m.
    to : callable
        Old grid coordinate -> new one (``lambda c: c / 8`` for a grid 8 times coarser).
    **changes
        Other fields to replace (``noise_sigma=0.0``).

    Returns
    -------
    WorldSpec

    Examples
    --------
    >>> spec, _ = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    >>> c = resampled_spec(spec, spec.gsd * 4, lambda v: v / 4)
    >>> c.gsd, c.size == max(16, round(spec.size / 4)), c.vents[0].y == spec.vents[0].y / 4
    (32.0, True, True)
    """
    return replace(
        spec,
        gsd=gsd,
        size=max(16, round(to(spec.size))),
        vents=tuple(replace(v, x=to(v.x), y=to(v.y)) for v in spec.vents),
        clouds=tuple(replace(c, x=to(c.x), y=to(c.y)) for c in spec.clouds),
        **changes,
    )
