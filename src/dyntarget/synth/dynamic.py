"""A moving world: time-evolving synthetic volcanic scenes, rendered on any window at any time.

A :class:`WorldSpec` (a small, JSON-serialisable set of numbers) fixes one world;
:class:`World` renders it deterministically on any integer pixel window of its
grid at any time ``t`` (seconds after the look-ahead acquisition):

* a **fixed ground** (terrain, land cover, hillshade, haze) from periodic noise
  tiles, so any window, however far from the origin, is defined;
* **attached plumes**: each vent emits continuously since ``eruption_age_s``
  before ``t = 0`` (a negative age: an eruption that starts during the pass, nothing
  before it; ``end_s``: one that stops, its last puffs drifting on; :func:`with_onsets`
  draws them); the emission is a train of Gaussian puffs (the Gaussian puff
  model) that are carried downwind with the wind and spread (diffusion plus
  turbulent relative dispersion), and fade with age. The vent end stays put,
  the envelope stretches downwind;
* **detached clouds** (volcanic ash/steam clouds, part of the truth; and
  meteorological cumulus, not part of it) that drift with the wind as a whole;
* texture that moves with the flow: the plume's multiplicative texture is
  sampled at ``x - u t``, so motion is visible between frames.

The truth is the plume optical depth (attached plumes + volcanic clouds) and
the mask where it exceeds ``label_optical_depth``, like the static generator's
label. Physics, parameter ranges and sources: ``docs/synthetic-scenes.md``,
section "Moving scenes".

Conventions: ``x`` = column, ``y`` = row of the world grid (GSD ``gsd`` m,
north up); wind speed in m/s and the direction it blows *from*, degrees
clockwise from north (meteorological convention).

Examples
--------
>>> spec = sample_world(0, 0, size=64, wind_mps=10.0, wind_from_deg=270.0)
>>> world = World(spec)
>>> frame = world.render(30.0)
>>> frame.image.shape, frame.image.dtype, frame.mask.dtype
((4, 64, 64), dtype('float32'), dtype('bool'))
>>> world.render(30.0, window=(10, 20, 16, 8)).image.shape
(4, 8, 16)
"""

from __future__ import annotations

import functools
import json
import math
import zlib
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import cv2
import numpy as np
from affine import Affine

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.scene import Scene
from dyntarget.sequence import FrameSequence
from dyntarget.synth.noise import fractal_noise
from dyntarget.synth.volcano import (
    ASH_PLUME,
    CLOUD,
    HAZE,
    ORIGIN_EASTING,
    ORIGIN_NORTHING,
    STEAM,
    SURFACE_SPECTRA,
    UTM_5N,
)

SPEC_VERSION = 1
"""Version of the :class:`WorldSpec` JSON layout."""

EPOCH = "2026-01-01T00:00:00Z"
"""Default acquisition time (ISO-8601 UTC) of ``t = 0``."""

PAD = 8
"""Pixels rendered around a window and cropped, so neighbourhood operations
(blur, gradients) give the same values whatever the window."""

CONE_REACH = 24.0
"""Distance from a vent, in world sizes, beyond which its cone and lava bias are exactly
zero in float32 (``exp(-24 / 0.15)`` and ``exp(-24 / 0.2)`` underflow): not computed there."""

GROUND_BLOCK = 128
"""Rows of the bands the ground is computed (and kept) in."""
GROUND_CACHE_PX = 1 << 21
"""Most ground pixels kept in bands (32 MB of 4-band float32)."""

MAX_VENTS = 64
"""Most vents in one world (a strip of ``synth --strip --plumes`` has one per plume)."""
MAX_CLOUDS = 256
"""Most drifting clouds in one world."""
MAX_TILE = 2048
"""Largest period of the ground's noise tiles, pixels (7 float32 tiles: 117 MB at 2048)."""
MAX_SIZE = 8192
"""Largest side of a world's own tile, pixels."""
MAX_WINDOW_PIXELS = 1 << 23
"""Most pixels rendered in one window (8.4 Mpx, e.g. 2048 x 4096). Measured: a 2048 x 2048
window of a 4-vent strip renders in 2.8 s with a peak RSS of 706 MB (``docs/reliability.md``)."""
MAX_WINDOW_SIDE = 1 << 16
"""Longest side of a window, pixels."""
MAX_FRAMES = 10_000
"""Most frames of one synthetic sequence."""
MAX_SECONDS = 86_400.0
"""Longest time scale of a world (eruption age, fade times, periods): one day."""
MAX_COORD_PX = 1e7
"""Largest vent/cloud/window coordinate, pixels, in size."""
MAX_RADIUS_M = 100_000.0
"""Largest puff/cloud radius, metres (100 km)."""
MIN_GSD, MAX_GSD = 0.01, 10_000.0
"""Ground sampling distances accepted, metres per pixel."""
MAX_HEIGHT_M = 25_000.0
"""Highest plume or cloud top of a 3D world, metres (``synth --plume-height-km``: 0..25 km)."""
MAX_RISE_MPS = 1_000.0
"""Fastest column rise accepted, m/s."""
OPTIONAL_HEIGHTS = {"vents": ("top_height_m", "rise_mps", "end_s"), "clouds": ("height_m",)}
"""Optional fields (the heights of a 3D world, a vent's end time) left out of the JSON where
unset (so the specs written before them keep their bytes)."""


def _number(
    where: str, name: str, v: object, lo: float, hi: float, *, lo_open: bool = False
) -> float:
    """``v`` as a float in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``), or a one-line refusal."""
    ok = isinstance(v, int | float | np.integer | np.floating) and not isinstance(
        v, bool | np.bool_
    )
    f = float(v) if ok else math.nan  # type: ignore[arg-type]
    if ok and math.isfinite(f) and (f > lo if lo_open else f >= lo) and f <= hi:
        return f
    bound = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
    raise InvalidParameterError(f"{where}{name}: expected a number in {bound}, got {v!r}")


def _integer(where: str, name: str, v: object, lo: int, hi: int) -> int:
    if isinstance(v, bool | np.bool_) or not isinstance(v, int | np.integer) or not lo <= v <= hi:
        raise InvalidParameterError(
            f"{where}{name}: expected an integer in [{lo}, {hi}], got {v!r}"
        )
    return int(v)


Window = tuple[int, int, int, int]
"""``(col0, row0, width, height)`` on the world grid, integers."""


@dataclass(frozen=True)
class Wind:
    """Wind: speed in m/s and the direction it blows *from*, degrees clockwise from north.

    Parameters
    ----------
    speed_mps : float
        Wind speed, m/s.
    from_deg : float
        Direction the wind blows from, degrees clockwise from north.

    Examples
    --------
    >>> Wind(10.0, 0.0).velocity_px(8.0)  # from the north: moves south, down the image
    (-0.0, 1.25)
    """

    speed_mps: float
    from_deg: float

    def __post_init__(self) -> None:
        _number("wind ", "speed", self.speed_mps, 0.0, 60.0)
        _number("wind ", "direction", self.from_deg, -3600.0, 3600.0)

    def velocity_px(self, gsd: float) -> tuple[float, float]:
        """``(dx/dt, dy/dt)`` in pixels per second on a north-up grid of ``gsd`` m.

        Parameters
        ----------
        gsd : float
            Ground sample distance, metres per pixel.

        Returns
        -------
        tuple of float
            ``(vx, vy)``, x = column (east), y = row (south).
        """
        rad = math.radians(self.from_deg)
        east = -self.speed_mps * math.sin(rad)
        north = -self.speed_mps * math.cos(rad)
        return east / gsd, -north / gsd


@dataclass(frozen=True)
class VentSpec:
    """A vent emitting an attached plume (positions in world pixels, times in s).

    Parameters
    ----------
    x, y : float
        Vent position, world pixels.
    emission_optical_depth : float
        Centreline optical depth near the vent.
    source_sigma_m : float
        Puff radius at release, metres.
    eruption_age_s : float
        How long the vent has emitted at ``t = 0``, seconds: the onset is at
        ``-eruption_age_s`` on the pass clock. Negative: the eruption starts
        ``-eruption_age_s`` seconds *after* ``t = 0`` (an onset during the pass; before
        it the vent shows nothing, in any image or truth).
    fade_s : float
        E-folding time of a puff's optical depth (dilution, fallout), seconds.
    diffusivity_m2s : float
        Small-scale diffusion, m²/s.
    turbulence : float
        Relative dispersion: sigma grows by ``turbulence * wind * age``.
    gustiness : float
        Log-normal sigma of the puff masses.
    meander : float
        Std of each puff's crosswind velocity as a fraction of the wind.
    ash_fraction : float
        Ash share near the vent (steam downwind).
    ash_fade_s : float
        E-folding time of the ash share with puff age, seconds.
    pulsation : float
        Std of the log emission rate, a smooth random function of the release
        time (pulsing eruptions; 0: steady).
    pulse_period_s : float
        Typical period of the pulsation, seconds.
    top_height_m : float or None
        Neutral-buoyancy height of the column top (the umbrella), metres above sea level
        (the vent's datum; vents sit at sea level here); ``None``: a flat world's plume,
        on the ground (see ``docs/plumes-3d.md``).
    rise_mps : float or None
        Rise velocity of the column top, m/s: the top rises from the vent from the onset
        (``-eruption_age_s``) until it reaches ``top_height_m`` (``None``: already there).
    end_s : float or None
        When the vent stops emitting, pass clock, s (``None``: never). The puffs already
        released drift on and fade (``fade_s``); the column keeps its height.
    """

    x: float
    y: float
    emission_optical_depth: float = 3.0
    source_sigma_m: float = 60.0
    eruption_age_s: float = 600.0
    fade_s: float = 600.0
    diffusivity_m2s: float = 20.0
    turbulence: float = 0.1
    gustiness: float = 0.25
    meander: float = 0.05
    ash_fraction: float = 0.5
    ash_fade_s: float = 300.0
    pulsation: float = 0.0
    pulse_period_s: float = 120.0
    top_height_m: float | None = None
    rise_mps: float | None = None
    end_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("x", "y"):
            _number("vent ", name, getattr(self, name), -MAX_COORD_PX, MAX_COORD_PX)
        _number("vent ", "eruption_age_s", self.eruption_age_s, -MAX_SECONDS, MAX_SECONDS)
        if self.end_s is not None:
            _number("vent ", "end_s", self.end_s, -MAX_SECONDS, MAX_SECONDS)
            if self.end_s <= -self.eruption_age_s:
                raise InvalidParameterError(
                    f"vent end_s: {self.end_s!r} is not after the onset "
                    f"(-eruption_age_s = {-self.eruption_age_s!r})"
                )
        if self.top_height_m is not None:
            _number("vent ", "top_height_m", self.top_height_m, 0.0, MAX_HEIGHT_M)
        if self.rise_mps is not None:
            if self.top_height_m is None:
                raise InvalidParameterError("vent rise_mps: give top_height_m too")
            _number("vent ", "rise_mps", self.rise_mps, 0.0, MAX_RISE_MPS, lo_open=True)
        _number(
            "vent ", "emission_optical_depth", self.emission_optical_depth, 0.0, 100.0, lo_open=True
        )
        for name, lo, hi in (
            ("source_sigma_m", 0.1, MAX_RADIUS_M),
            ("fade_s", 0.1, MAX_SECONDS),
            ("ash_fade_s", 0.1, MAX_SECONDS),
            ("pulse_period_s", 0.1, MAX_SECONDS),
        ):
            _number("vent ", name, getattr(self, name), lo, hi)
        for name, hi in (
            ("diffusivity_m2s", 1e4),
            ("turbulence", 10.0),
            ("gustiness", 5.0),
            ("meander", 5.0),
            ("pulsation", 5.0),
            ("ash_fraction", 1.0),
        ):
            _number("vent ", name, getattr(self, name), 0.0, hi)


@dataclass(frozen=True)
class CloudSpec:
    """A cloud drifting with the wind as a whole; ``volcanic`` clouds are part of the truth.

    Parameters
    ----------
    x, y : float
        Centre at ``t = 0``, world pixels.
    radius_m : float
        Gaussian envelope radius, metres.
    optical_depth : float
        Peak optical depth before texture.
    volcanic : bool
        A volcanic ash/steam cloud (part of the truth) rather than a meteorological one.
    ash_fraction : float
        Colour between steam (0) and ash (1), for volcanic clouds.
    height_m : float or None
        Cloud-top height, metres above sea level (``None``: on the ground, a flat world).
    """

    x: float
    y: float
    radius_m: float = 300.0
    optical_depth: float = 2.0
    volcanic: bool = True
    ash_fraction: float = 0.5
    height_m: float | None = None

    def __post_init__(self) -> None:
        if self.height_m is not None:
            _number("cloud ", "height_m", self.height_m, 0.0, MAX_HEIGHT_M)
        for name in ("x", "y"):
            _number("cloud ", name, getattr(self, name), -MAX_COORD_PX, MAX_COORD_PX)
        _number("cloud ", "radius_m", self.radius_m, 1.0, MAX_RADIUS_M)
        _number("cloud ", "optical_depth", self.optical_depth, 0.0, 100.0, lo_open=True)
        _number("cloud ", "ash_fraction", self.ash_fraction, 0.0, 1.0)
        if not isinstance(self.volcanic, bool):
            raise InvalidParameterError(
                f"cloud volcanic: expected true or false, got {self.volcanic!r}"
            )


@dataclass(frozen=True)
class WorldSpec:
    """Everything that fixes one moving world; ``to_json``/``from_json`` round-trip exactly.

    Parameters
    ----------
    seed : int
        Seed of every random draw of the rendering (ground, texture, puffs).
    size : int
        Side of the world's own tile, pixels (the default window).
    gsd : float
        Ground sample distance, metres per pixel.
    wind : Wind
        The wind.
    vents : tuple of VentSpec
        The vents emitting attached plumes.
    clouds : tuple of CloudSpec
        Drifting clouds, volcanic or meteorological.
    label_optical_depth : float
        Optical depth above which a pixel is plume in the truth.
    plume_texture : float
        Amplitude of the plume's multiplicative texture (0: none).
    tile : int
        Period of the ground's noise tiles, pixels.
    water_fraction, lava_fraction, vegetation_fraction : float
        Land-cover shares, as in :class:`~dyntarget.synth.volcano.SceneParams`.
    sun_azimuth_deg, sun_elevation_deg : float
        Sun position for the hillshade, degrees.
    haze : float
        Strength of the haze (blend weight of the haze colour).
    noise_sigma : float
        Std of the Gaussian sensor noise, reflectance units.
    origin_easting, origin_northing : float
        CRS coordinates of the world grid's top-left corner, metres.
    crs : str
        The CRS (default UTM zone 5N, near Kilauea).
    epoch : str
        ISO-8601 UTC time of ``t = 0``.
    id : str
        World id, the prefix of its scenes' ids.
    version : int
        Version of the JSON layout (:data:`SPEC_VERSION`).
    """

    seed: int
    size: int
    gsd: float
    wind: Wind
    vents: tuple[VentSpec, ...]
    clouds: tuple[CloudSpec, ...] = ()
    label_optical_depth: float = 0.35
    plume_texture: float = 0.5
    tile: int = 512
    water_fraction: float = 0.0
    lava_fraction: float = 0.25
    vegetation_fraction: float = 0.4
    sun_azimuth_deg: float = 135.0
    sun_elevation_deg: float = 45.0
    haze: float = 0.05
    noise_sigma: float = 0.005
    origin_easting: float = ORIGIN_EASTING
    origin_northing: float = ORIGIN_NORTHING
    crs: str = UTM_5N
    epoch: str = EPOCH
    id: str = "world"
    version: int = SPEC_VERSION

    def __post_init__(self) -> None:
        _integer("", "seed", self.seed, 0, 2**63 - 1)
        _integer("", "size", self.size, 16, MAX_SIZE)
        _number("", "gsd", self.gsd, MIN_GSD, MAX_GSD)
        _integer("", "tile", self.tile, 64, MAX_TILE)
        if self.tile & (self.tile - 1):
            raise InvalidParameterError(
                f"tile: expected a power of two in [64, {MAX_TILE}], got {self.tile!r}"
            )
        _number("", "label_optical_depth", self.label_optical_depth, 0.0, 100.0, lo_open=True)
        for name in (
            "water_fraction",
            "lava_fraction",
            "vegetation_fraction",
            "haze",
            "plume_texture",
        ):
            v = getattr(self, name)
            _number("", name, v, 0.0, 1.0)
            if v == 1.0:
                raise InvalidParameterError(f"{name}: expected 0 <= value < 1, got {v!r}")
        _number("", "sun_azimuth_deg", self.sun_azimuth_deg, -360.0, 720.0)
        _number("", "sun_elevation_deg", self.sun_elevation_deg, 1.0, 90.0)
        _number("", "noise_sigma", self.noise_sigma, 0.0, 1.0)
        _number("", "origin_easting", self.origin_easting, -1e8, 1e8)
        _number("", "origin_northing", self.origin_northing, -1e8, 1e8)
        if self.version != SPEC_VERSION:
            raise InvalidParameterError(
                f"world spec version: expected {SPEC_VERSION}, got {self.version!r}"
            )
        if not isinstance(self.id, str) or not self.id or len(self.id) > 200:
            raise InvalidParameterError(
                f"id: expected a name of 1 to 200 characters, got {self.id!r}"
            )
        if not isinstance(self.wind, Wind):
            raise InvalidParameterError(f"wind: expected a Wind, got {type(self.wind).__name__}")
        for name, items, kind, most in (
            ("vents", self.vents, VentSpec, MAX_VENTS),
            ("clouds", self.clouds, CloudSpec, MAX_CLOUDS),
        ):
            if isinstance(items, str | bytes | dict) or not hasattr(items, "__len__"):
                raise InvalidParameterError(f"{name}: expected a list, got {type(items).__name__}")
            if len(items) > most:
                raise InvalidParameterError(
                    f"{name}: {len(items)} of them, more than the {most} a world may have"
                )
            if not all(isinstance(v, kind) for v in items):
                raise InvalidParameterError(f"{name}: expected {kind.__name__} entries")
            object.__setattr__(self, name, tuple(items))
        _check_crs(self.crs)
        _check_epoch(self.epoch)

    def to_dict(self) -> dict[str, Any]:
        """The spec as nested plain dicts and lists (``dataclasses.asdict``).

        The heights of a 3D world (:data:`OPTIONAL_HEIGHTS`) are written only where set,
        so a flat world's JSON is what it was before worlds had heights.

        Returns
        -------
        dict
            JSON-ready; :meth:`from_dict` reads it back.
        """
        d = asdict(self)
        for name, keys in OPTIONAL_HEIGHTS.items():
            for item in d[name]:
                for k in keys:
                    if item[k] is None:
                        del item[k]
        return d

    def plumes(self) -> list[dict[str, Any]]:
        """The per-vent truth of a 3D world: ``plume_id``, position and heights.

        Returns
        -------
        list of dict
            One per vent: ``plume_id`` (the vent's index), ``x_px``, ``y_px`` (world
            grid), ``top_height_m`` (metres above sea level), ``rise_mps`` (``None``: at
            its top from the start) and ``onset_s`` (``-eruption_age_s``, pass clock).

        Examples
        --------
        >>> spec = with_heights(sample_world(0, 0, size=32), seed=0)
        >>> sorted(spec.plumes()[0])
        ['onset_s', 'plume_id', 'rise_mps', 'top_height_m', 'x_px', 'y_px']
        """
        return [
            {
                "plume_id": i,
                "x_px": v.x,
                "y_px": v.y,
                "top_height_m": v.top_height_m,
                "rise_mps": v.rise_mps,
                "onset_s": -v.eruption_age_s,
            }
            for i, v in enumerate(self.vents)
        ]

    def grid_transform(self) -> Affine:
        """Pixel-corner transform of the world grid (pixel ``(0, 0)`` at the origin).

        Returns
        -------
        affine.Affine
            North up, ``gsd`` metre pixels, in :attr:`crs`.
        """
        return Affine.translation(self.origin_easting, self.origin_northing) @ Affine.scale(
            self.gsd, -self.gsd
        )

    @property
    def is_3d(self) -> bool:
        """Whether any vent or cloud has a height (else every feature lies on the ground)."""
        return any(v.top_height_m is not None for v in self.vents) or any(
            c.height_m is not None for c in self.clouds
        )

    def to_json(self) -> str:
        """Canonical JSON (sorted keys); floats round-trip exactly.

        Returns
        -------
        str
            The JSON text.
        """
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> WorldSpec:
        """Rebuild a spec from :meth:`to_dict` output; unknown keys are refused.

        Parameters
        ----------
        d : dict
            A spec as :meth:`to_dict` writes it.

        Returns
        -------
        WorldSpec
            The spec.

        Raises
        ------
        dyntarget.errors.InvalidParameterError
            For something else than a dict, unknown fields or a malformed spec.
        """
        if not isinstance(d, dict):
            raise InvalidParameterError(
                f"world spec: expected a JSON object, got {type(d).__name__}"
            )
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise InvalidParameterError(f"world spec: unknown field(s) {', '.join(unknown)}")
        try:
            d = dict(d)
            for name, most in (("vents", MAX_VENTS), ("clouds", MAX_CLOUDS)):
                items = d.get(name, ())
                if not isinstance(items, list | tuple):
                    raise InvalidParameterError(
                        f"world spec: {name}: expected a list, got {type(items).__name__}"
                    )
                if len(items) > most:  # before building thousands of entries
                    raise InvalidParameterError(
                        f"world spec: {name}: {len(items)} of them, more than the {most} a world may have"
                    )
                if not all(isinstance(v, dict) for v in items):
                    raise InvalidParameterError(f"world spec: {name}: expected a list of objects")
            if not isinstance(d.get("wind"), dict):
                raise InvalidParameterError("world spec: wind: expected an object")
            d["wind"] = Wind(**d["wind"])
            d["vents"] = tuple(VentSpec(**v) for v in d["vents"])
            d["clouds"] = tuple(CloudSpec(**c) for c in d.get("clouds", ()))
            return cls(**d)
        except (KeyError, TypeError) as exc:
            raise InvalidParameterError(f"world spec: malformed ({exc})") from None

    @classmethod
    def from_json(cls, text: str) -> WorldSpec:
        """Rebuild a spec from :meth:`to_json` output.

        Parameters
        ----------
        text : str
            The JSON text.

        Returns
        -------
        WorldSpec
            The spec.

        Raises
        ------
        dyntarget.errors.InvalidParameterError
            For text that is not JSON or not a spec (:meth:`from_dict`).
        """
        from dyntarget.io.safeopen import loads_json

        try:
            d = loads_json(text, where="world spec")
        except DataFileError as exc:
            raise InvalidParameterError(str(exc)) from None
        return cls.from_dict(d)


def sample_world(
    seed: int,
    index: int,
    *,
    size: int = 512,
    gsd: float = 8.0,
    wind_mps: float | None = None,
    wind_from_deg: float | None = None,
) -> WorldSpec:
    """Draw world ``index`` of the set with ``seed`` (ranges documented in the docs).

    Wind speed is drawn uniformly in 0..16 m/s (so every wind bin from calm to
    gale is covered evenly) and its direction uniformly, unless given.
    World ``i`` depends only on ``(seed, i)`` and the arguments.

    Parameters
    ----------
    seed : int
        The set's seed.
    index : int
        The world's index in the set.
    size : int
        Side of the world's tile, pixels (at least 16).
    gsd : float
        Ground sample distance, metres per pixel.
    wind_mps : float or None
        Wind speed, m/s (default: drawn).
    wind_from_deg : float or None
        Wind direction, degrees from north (default: drawn).

    Returns
    -------
    WorldSpec
        The world's spec.

    Examples
    --------
    >>> sample_world(0, 3, size=64, wind_mps=5.0).wind.speed_mps
    5.0
    """
    if isinstance(size, bool) or not isinstance(size, int) or size < 16:
        raise InvalidParameterError(f"size: expected an integer >= 16, got {size!r}")
    _integer("", "size", size, 16, MAX_SIZE)
    _integer("", "seed", seed, 0, 2**63 - 1)
    rng = np.random.default_rng([int(seed), int(index), 0xD1])
    u = rng.uniform
    speed = float(u(0.0, 16.0)) if wind_mps is None else float(wind_mps)
    direction = float(u(0.0, 360.0)) if wind_from_deg is None else float(wind_from_deg)
    wind = Wind(speed, direction)
    extent_m = size * gsd
    # upwind part of the scene for the vent, so the plume has room downwind
    vx, vy = wind.velocity_px(gsd)
    norm = math.hypot(vx, vy)
    back = 0.25 * size
    cx = 0.5 * size - (back * vx / norm if norm > 0 else 0.0)
    cy = 0.5 * size - (back * vy / norm if norm > 0 else 0.0)
    vent = VentSpec(
        x=float(cx + u(-0.1, 0.1) * size),
        y=float(cy + u(-0.1, 0.1) * size),
        emission_optical_depth=float(u(2.0, 5.0)),
        source_sigma_m=float(u(0.012, 0.025) * extent_m),
        # mostly a mature plume (front beyond the scene); one in five young, its
        # front still inside the scene; capped for calm air
        eruption_age_s=float(
            min(
                (u(0.3, 0.9) if u() < 0.2 else u(1.0, 2.0)) * extent_m / max(speed, 0.5),
                2400.0,
            )
        ),
        fade_s=float(u(300.0, 900.0)),
        diffusivity_m2s=float(u(5.0, 40.0)),
        turbulence=float(u(0.05, 0.15)),
        gustiness=float(u(0.1, 0.4)),
        meander=float(u(0.0, 0.08)),
        ash_fraction=float(u(0.0, 1.0)),
        ash_fade_s=float(u(120.0, 600.0)),
        pulsation=float(u(0.1, 0.5)),
        pulse_period_s=float(u(60.0, 300.0)),
    )
    clouds: list[CloudSpec] = []
    if u() < 0.5:  # a detached volcanic cloud (an earlier burst), downwind of the vent
        dist = u(0.2, 0.6) * size
        ang = math.atan2(vy, vx) if norm > 0 else u(0, 2 * math.pi)
        ang += u(-0.3, 0.3)
        clouds.append(
            CloudSpec(
                x=float(vent.x + dist * math.cos(ang)),
                y=float(vent.y + dist * math.sin(ang)),
                radius_m=float(u(0.04, 0.09) * extent_m),
                optical_depth=float(u(1.0, 3.0)),
                volcanic=True,
                ash_fraction=float(u(0.0, 1.0)),
            )
        )
    for _ in range(int(rng.integers(0, 4)) if u() < 0.6 else 0):  # meteorological cumulus
        clouds.append(
            CloudSpec(
                x=float(u(-0.1, 1.1) * size),
                y=float(u(-0.1, 1.1) * size),
                radius_m=float(u(0.03, 0.08) * extent_m),
                optical_depth=float(u(2.0, 6.0)),
                volcanic=False,
                ash_fraction=0.0,
            )
        )
    tile = min(1 << max(9, (size - 1).bit_length()), MAX_TILE)
    tile_m = size * gsd * 1.5
    return WorldSpec(
        seed=int(seed),
        size=size,
        gsd=float(gsd),
        wind=wind,
        vents=(vent,),
        clouds=tuple(clouds),
        label_optical_depth=float(u(0.25, 0.5)),
        tile=tile,
        water_fraction=float(u(0.0, 0.3)) if u() < 0.5 else 0.0,
        lava_fraction=float(u(0.1, 0.4)),
        vegetation_fraction=float(u(0.2, 0.7)),
        sun_azimuth_deg=float(u(0.0, 360.0)),
        sun_elevation_deg=float(u(25.0, 70.0)),
        haze=float(u(0.0, 0.12)),
        noise_sigma=float(u(0.002, 0.008)),
        origin_easting=ORIGIN_EASTING + (index % 20) * tile_m,
        origin_northing=ORIGIN_NORTHING - 200_000.0 - (index // 20) * tile_m,
        id=f"dyn-{int(seed):04d}-{int(index):04d}",
    )


@dataclass(frozen=True, eq=False)
class WorldFrame:
    """One rendering: ``image`` (4, H, W) float32, truth ``mask`` bool, plume optical depth ``tau``.

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` float32 reflectance.
    mask : numpy.ndarray
        Boolean ``(H, W)`` truth.
    tau : numpy.ndarray
        ``(H, W)`` optical depth of attached plumes and volcanic clouds.
    t : float
        Time rendered, seconds after the look-ahead acquisition.
    window : tuple of int
        ``(col0, row0, width, height)`` rendered.
    """

    image: np.ndarray
    mask: np.ndarray
    tau: np.ndarray
    t: float
    window: Window


def check_window(window: object, size: int) -> Window:
    """Validate ``(col0, row0, width, height)``; ``None`` is the world's own tile ``(0, 0, size, size)``.

    Parameters
    ----------
    window : object
        ``None`` or four integers.
    size : int
        The world's tile size, pixels.

    Returns
    -------
    tuple of int
        ``(col0, row0, width, height)``.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For anything else, or a width or height below 1.
    """
    if window is None:
        return (0, 0, size, size)
    try:
        vals: tuple[object, ...] = tuple(window)  # type: ignore[arg-type]
    except TypeError:
        vals = ()
    if len(vals) != 4 or not all(
        isinstance(v, int | np.integer) and not isinstance(v, bool) for v in vals
    ):
        raise InvalidParameterError(
            f"window: expected (col0, row0, width, height) integers, got {window!r}"
        )
    c0, r0, w, h = (int(v) for v in vals)  # type: ignore[call-overload]
    if w < 1 or h < 1:
        raise InvalidParameterError(f"window: expected a positive size, got {w} x {h}")
    if max(w, h) > MAX_WINDOW_SIDE or w * h > MAX_WINDOW_PIXELS:
        raise InvalidParameterError(
            f"window: {w} x {h} px, more than the {MAX_WINDOW_PIXELS:,} px "
            f"(sides up to {MAX_WINDOW_SIDE}) rendered at once"
        )
    if max(abs(c0), abs(r0)) > MAX_COORD_PX:
        raise InvalidParameterError(
            f"window: origin ({c0}, {r0}) farther than {MAX_COORD_PX:g} px from the world's"
        )
    return (c0, r0, w, h)


def _check_crs(crs: object) -> None:
    if not isinstance(crs, str) or not crs or len(crs) > 10_000:
        raise InvalidParameterError(
            f"crs: expected a CRS name such as 'EPSG:32605', got {crs!r:.80}"
        )
    _crs_known(crs)


@functools.lru_cache(maxsize=64)
def _crs_known(crs: str) -> None:
    import rasterio.crs
    import rasterio.errors

    try:
        rasterio.crs.CRS.from_user_input(crs)
    except (rasterio.errors.CRSError, ValueError, TypeError) as exc:
        raise InvalidParameterError(
            f"crs: {crs!r:.80} is not a known CRS ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
        ) from None


def _check_epoch(epoch: object) -> None:
    from dyntarget.sequence import parse_time

    if not isinstance(epoch, str):
        raise InvalidParameterError(f"epoch: expected an ISO-8601 UTC time, got {epoch!r:.80}")
    dt = parse_time(epoch)
    if not 1900 <= dt.year <= 2200:
        raise InvalidParameterError(f"epoch: expected a year in 1900..2200, got {epoch!r}")


def _check_time(t: object) -> float:
    if isinstance(t, bool) or not isinstance(t, int | float | np.integer | np.floating):
        raise InvalidParameterError(f"t: expected seconds (a number), got {t!r}")
    t = float(t)
    if not (math.isfinite(t) and abs(t) <= 86_400.0):
        raise InvalidParameterError(f"t: expected finite seconds within a day of t = 0, got {t!r}")
    return t


class World:
    """Renders a :class:`WorldSpec` on any window at any time (see the module docstring).

    Parameters
    ----------
    spec : WorldSpec
        The world; build one with :func:`sample_world` or by hand.

    Examples
    --------
    >>> w = World(sample_world(1, 0, size=32, wind_mps=0.0))
    >>> bool((w.render(0.0).mask == w.render(0.0).mask).all())
    True
    """

    PUFF_BLOCK = 1024

    def __init__(self, spec: WorldSpec) -> None:
        if not isinstance(spec, WorldSpec):
            raise InvalidParameterError(f"spec: expected a WorldSpec, got {type(spec).__name__}")
        self.spec = spec
        self._tiles: dict[str, np.ndarray] = {}
        self._thresholds: dict[str, float] = {}
        self._ground_cache: OrderedDict[Window, np.ndarray] = OrderedDict()
        self._ground_blocks: OrderedDict[tuple[int, int, int], np.ndarray] = OrderedDict()
        self._ground_block_px = 0
        self._puff_draws: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
        self._build_tiles()

    # ------------------------------------------------------------------ noise tiles
    def _build_tiles(self) -> None:
        s = self.spec
        rng = np.random.default_rng([s.seed, s.size, 0xD2])
        shape = (s.tile, s.tile)
        for name, beta in (
            ("elev", 3.6),
            ("lava", 2.6),
            ("basalt", 2.4),
            ("veg", 2.6),
            ("texture", 1.6),
            ("haze", 3.5),
            ("plume", 2.0),
            ("cloud", 2.8),
        ):
            self._tiles[name] = fractal_noise(rng, shape, beta=beta)
        self._tiles["white"] = rng.standard_normal(shape).astype(np.float32)
        t = self._tiles
        self._thresholds = {
            "water": float(np.quantile(t["elev"], s.water_fraction))
            if s.water_fraction
            else -np.inf,
            "lava": float(np.quantile(t["lava"], 1.0 - s.lava_fraction)),
            "veg": float(np.quantile(t["veg"], 1.0 - s.vegetation_fraction)),
        }

    def _sample(self, name: str, window: Window, pad: int = 0) -> np.ndarray:
        """Tile values at integer pixels of ``window`` (+ ``pad`` around), periodic."""
        c0, r0, w, h = window
        p = self.spec.tile
        tile = self._tiles[name]
        a, b = (r0 - pad) % p, (c0 - pad) % p
        n, m = h + 2 * pad, w + 2 * pad
        if a + n <= p and b + m <= p:  # no wrap: a (read-only) view, the same values
            view = tile[a : a + n, b : b + m]
            view.flags.writeable = False
            return view
        rows = np.arange(r0 - pad, r0 + h + pad) % p
        cols = np.arange(c0 - pad, c0 + w + pad) % p
        return tile[np.ix_(rows, cols)]

    def _sample_shifted(self, name: str, window: Window, dx: float, dy: float) -> np.ndarray:
        """Tile values at ``(x - dx, y - dy)`` for the pixels of ``window`` (bilinear, periodic)."""
        c0, r0, w, h = window
        p = self.spec.tile
        xs = np.mod(np.arange(c0, c0 + w, dtype=np.float64) - dx, p).astype(np.float32)
        ys = np.mod(np.arange(r0, r0 + h, dtype=np.float64) - dy, p).astype(np.float32)
        mx, my = np.meshgrid(xs, ys)
        return cv2.remap(
            self._tiles[name], mx, my, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP
        )

    # ------------------------------------------------------------------ ground
    def _ground(self, window: Window) -> np.ndarray:
        """Surface reflectance (4, h, w): fixed in time; cached for recent windows.

        Built from bands of :data:`GROUND_BLOCK` rows at multiples of it (as wide as the
        window, kept): a pixel's ground does not depend on the window it is rendered in
        (the :data:`PAD` margin), so overlapping frames of a pass compute each band once.
        """
        cached = self._ground_cache.get(window)
        if cached is not None:
            self._ground_cache.move_to_end(window)
            return cached
        c0, r0, w, h = window
        first, last = r0 // GROUND_BLOCK, (r0 + h - 1) // GROUND_BLOCK
        parts = []
        for blk in range(first, last + 1):
            key = (c0, w, blk)
            part = self._ground_blocks.get(key)
            if part is None:
                part = self._ground_window((c0, blk * GROUND_BLOCK, w, GROUND_BLOCK))
                self._ground_blocks[key] = part
                self._ground_block_px += w * GROUND_BLOCK
                while self._ground_block_px > GROUND_CACHE_PX and len(self._ground_blocks) > 1:
                    (_, bw, _), _ = self._ground_blocks.popitem(last=False)
                    self._ground_block_px -= bw * GROUND_BLOCK
            else:
                self._ground_blocks.move_to_end(key)
            parts.append(part)
        top = r0 - first * GROUND_BLOCK
        surface = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
        surface = np.ascontiguousarray(surface[:, top : top + h])
        self._ground_cache[window] = surface
        if len(self._ground_cache) > 4:
            self._ground_cache.popitem(last=False)
        return surface

    def _ground_window(self, window: Window) -> np.ndarray:
        """Surface reflectance (4, h, w) of ``window``, computed (see :meth:`_ground`)."""
        s = self.spec
        c0, r0, w, h = window
        pad = PAD
        yy, xx = np.mgrid[r0 - pad : r0 + h + pad, c0 - pad : c0 + w + pad].astype(np.float32)
        cone = np.zeros_like(xx)
        lava_bias = np.zeros_like(xx)
        for vent in s.vents:  # a volcanic cone under every vent
            # beyond CONE_REACH sizes both terms underflow to exactly 0 in float32: skip
            dx = max(c0 - pad - vent.x, 0.0, vent.x - (c0 + w + pad - 1))
            dy = max(r0 - pad - vent.y, 0.0, vent.y - (r0 + h + pad - 1))
            if math.hypot(dx, dy) > CONE_REACH * s.size:
                continue
            r_vent = np.hypot(xx - vent.x, yy - vent.y) / s.size
            cone = np.maximum(cone, 2.5 * np.exp(-r_vent / 0.2))
            lava_bias = np.maximum(lava_bias, 2.0 * np.exp(-r_vent / 0.15))
        elev_noise = self._sample("elev", window, pad)
        elev = elev_noise + cone
        water = elev_noise < self._thresholds["water"]
        water &= cone < 0.5  # the volcano's flank stays dry
        land = ~water
        lava = land & (self._sample("lava", window, pad) + lava_bias > self._thresholds["lava"])
        basalt = self._sample("basalt", window, pad) > 0.0
        rest = land & ~lava
        veg = rest & (self._sample("veg", window, pad) > self._thresholds["veg"])
        classes = {
            "water": water,
            "basalt": lava & basalt,
            "ash": lava & ~basalt,
            "vegetation": veg,
            "soil": rest & ~veg,
        }
        surface = np.zeros((4, *xx.shape), np.float32)
        for name, m in classes.items():
            wgt = cv2.GaussianBlur(m.astype(np.float32), (0, 0), 1.0)
            surface += np.asarray(SURFACE_SPECTRA[name], np.float32)[:, None, None] * wgt
        surface *= (1.0 + 0.12 * self._sample("texture", window, pad))[None]
        gy, gx = np.gradient(elev * (0.015 * s.size))
        az, el = math.radians(s.sun_azimuth_deg), math.radians(s.sun_elevation_deg)
        sx, sy, sz = math.cos(el) * math.sin(az), -math.cos(el) * math.cos(az), math.sin(el)
        shade = (-gx * sx - gy * sy + sz) / np.sqrt(1.0 + gx**2 + gy**2) / sz
        shade = np.where(water, 1.0, np.clip(shade, 0.15, 1.6)).astype(np.float32)
        surface = (surface * shade[None])[:, pad:-pad, pad:-pad]
        haze = s.haze * (0.6 + 0.4 * np.tanh(self._sample("haze", window)))
        surface = (
            surface * (1.0 - haze[None]) + np.asarray(HAZE, np.float32)[:, None, None] * haze[None]
        )
        return np.ascontiguousarray(surface, dtype=np.float32)

    # ------------------------------------------------------------------ plumes
    def _puffs(self, vi: int, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Per-puff random draws (mass factor, crosswind velocity) of puffs ``k0 .. k1 - 1``.

        Drawn in blocks of :attr:`PUFF_BLOCK` puffs, block ``b`` from its own seed (so a
        puff's draws do not depend on which puffs are asked for), kept per vent as one
        array. Also returns the largest ``|crosswind draw|`` of the vent's puffs drawn so
        far (a bound for culling).
        """
        gust, cross, top = self._puff_draws.get(vi, (np.empty(0), np.empty(0), 0.0))
        have = len(gust) // self.PUFF_BLOCK
        need = -(-k1 // self.PUFF_BLOCK)
        if need > have:
            g, c = [gust], [cross]
            for blk in range(have, need):
                rng = np.random.default_rng([self.spec.seed, self.spec.size, 0xD3, vi, blk])
                g.append(rng.standard_normal(self.PUFF_BLOCK))
                c.append(rng.standard_normal(self.PUFF_BLOCK))
            gust, cross = np.concatenate(g), np.concatenate(c)
            top = float(np.abs(cross).max())
            self._puff_draws[vi] = (gust, cross, top)
        return gust[k0:k1], cross[k0:k1], top

    def _pulse(self, vi: int, vent: VentSpec, release: np.ndarray) -> np.ndarray:
        """Smooth unit-variance random function of release time (8 random cosines)."""
        rng = np.random.default_rng([self.spec.seed, self.spec.size, 0xD5, vi])
        freq = rng.uniform(0.5, 2.0, 8) / vent.pulse_period_s
        phase = rng.uniform(0.0, 2.0 * math.pi, 8)
        return 0.5 * np.cos(2.0 * math.pi * np.outer(release, freq) + phase).sum(axis=1)

    def puff_step_s(self, vent: VentSpec) -> float:
        """Time between puff releases: spacing ``wind * step`` at most 0.4 source sigma.

        Parameters
        ----------
        vent : VentSpec
            The vent.

        Returns
        -------
        float
            Seconds between releases, clipped to 0.5..20 s.
        """
        return float(
            np.clip(0.4 * vent.source_sigma_m / max(self.spec.wind.speed_mps, 1e-6), 0.5, 20.0)
        )

    def _puff_train(
        self, vi: int, v: VentSpec, t: float, window: Window
    ) -> tuple[np.ndarray, ...] | None:
        """Vent ``vi``'s puffs at ``t`` that reach ``window``: ``(px, py, sig, mass, ash)``.

        ``None`` when none does. The train's bounding box is checked first (most vents
        of a long strip are far from any one window), then each puff's 4-sigma box; the
        pulsation and masses are computed only for the puffs left.
        """
        s = self.spec
        c0, r0, w, h = window
        ux, uy = s.wind.velocity_px(s.gsd)  # px/s
        speed_px = math.hypot(ux, uy)
        nx, ny = (-uy / speed_px, ux / speed_px) if speed_px > 0 else (0.0, 0.0)
        start = -v.eruption_age_s
        if t <= start:
            return None
        stop = t if v.end_s is None else min(t, v.end_s)  # emission ends at end_s
        step = self.puff_step_s(v)
        sigma0 = v.source_sigma_m / s.gsd
        # puff k carries the emission over [start + k step, start + (k+1) step), clipped at stop
        k_last = math.floor((stop - start) / step)
        k_first = max(0, math.floor((t - start - 8.0 * v.fade_s) / step))
        gust, cross_draw, top = self._puffs(vi, k_first, k_last + 1)
        age_max = max(t - start - k_first * step, 0.0)
        sig_max = math.sqrt(
            sigma0**2
            + 2.0 * (v.diffusivity_m2s / s.gsd**2) * age_max
            + (v.turbulence * speed_px * age_max) ** 2
        )
        drift = v.meander * speed_px * top * age_max  # largest crosswind offset
        sx = abs(nx) * drift + 4.0 * sig_max + 1.0
        sy = abs(ny) * drift + 4.0 * sig_max + 1.0
        if (
            v.x + max(ux * age_max, 0.0) + sx < c0
            or v.x + min(ux * age_max, 0.0) - sx > c0 + w - 1
            or v.y + max(uy * age_max, 0.0) + sy < r0
            or v.y + min(uy * age_max, 0.0) - sy > r0 + h - 1
        ):
            return None
        k = np.arange(k_first, k_last + 1)
        t0 = start + k * step
        t1 = np.minimum(t0 + step, stop)
        keep = t1 > t0
        t0, t1, gust, cross_draw = t0[keep], t1[keep], gust[keep], cross_draw[keep]
        age = t - 0.5 * (t0 + t1)  # age of the puff's centre of emission
        sig = np.sqrt(
            sigma0**2
            + 2.0 * (v.diffusivity_m2s / s.gsd**2) * age
            + (v.turbulence * speed_px * age) ** 2
        )
        cross = v.meander * speed_px * cross_draw * age
        px = v.x + ux * age + nx * cross
        py = v.y + uy * age + ny * cross
        reach = 4.0 * sig
        near = np.flatnonzero(
            (px + reach >= c0)
            & (px - reach <= c0 + w - 1)
            & (py + reach >= r0)
            & (py - reach <= r0 + h - 1)
        )
        if len(near) == 0:
            return None
        age, sig, px, py = age[near], sig[near], px[near], py[near]
        t0, t1, gust = t0[near], t1[near], gust[near]
        # line-source normalisation: a steady train of puffs has centreline
        # optical depth ~ emission_optical_depth near the vent
        u_norm = max(speed_px, 1.0 / s.gsd)  # px/s; at least 1 m/s so calm air stays finite
        q = v.emission_optical_depth * u_norm * math.sqrt(2.0 * math.pi) * sigma0  # per s
        log_rate = v.gustiness * gust - 0.5 * v.gustiness**2
        if v.pulsation > 0:
            log_rate = log_rate + v.pulsation * self._pulse(vi, v, 0.5 * (t0 + t1))
            log_rate -= 0.5 * v.pulsation**2
        mass = q * (t1 - t0) * np.exp(log_rate) * np.exp(-age / v.fade_s)
        ash = v.ash_fraction * np.exp(-age / v.ash_fade_s)
        drawn = np.flatnonzero(mass / (2 * math.pi * sig**2) > 1e-5)
        if len(drawn) == 0:
            return None
        return px[drawn], py[drawn], sig[drawn], mass[drawn], ash[drawn]

    def _plume_tau(
        self, t: float, window: Window, only: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Attached plumes: ``(tau, tau_ash)`` on ``window`` at time ``t`` (vent ``only``'s alone).

        Each vent's plume is drawn on its own box and textured from its own vent (the
        texture's amplitude grows with the distance downwind of that vent).
        """
        s = self.spec
        c0, r0, w, h = window
        tau = np.zeros((h, w), np.float64)
        tau_ash = np.zeros((h, w), np.float64)
        ux, uy = s.wind.velocity_px(s.gsd)  # px/s
        speed_px = math.hypot(ux, uy)
        xs = np.arange(c0, c0 + w, dtype=np.float64)
        ys = np.arange(r0, r0 + h, dtype=np.float64)
        tex = None  # the plume texture on the window (sampled once, when a plume is drawn)
        for vi, v in enumerate(s.vents):
            if only is not None and vi != only:
                continue
            train = self._puff_train(vi, v, t, window)
            if train is None:
                continue
            px, py, sig, mass, ash = train
            reach = 4.0 * sig
            # pixels within 4 sigma of each centre (the same ones in any window)
            ca0 = np.maximum(np.ceil(px - reach).astype(np.int64) - c0, 0)
            ca1 = np.minimum(np.floor(px + reach).astype(np.int64) - c0 + 1, w)
            cb0 = np.maximum(np.ceil(py - reach).astype(np.int64) - r0, 0)
            cb1 = np.minimum(np.floor(py + reach).astype(np.int64) - r0 + 1, h)
            x0, x1, y0, y1 = int(ca0.min()), int(ca1.max()), int(cb0.min()), int(cb1.max())
            if x1 <= x0 or y1 <= y0:
                continue
            vt = np.zeros((y1 - y0, x1 - x0), np.float64)  # this vent's plume on its box
            va = np.zeros_like(vt)
            for j, (a0, a1, b0, b1) in enumerate(zip(ca0, ca1, cb0, cb1, strict=True)):
                if a1 <= a0 or b1 <= b0:
                    continue
                inv = 0.5 / sig[j] ** 2
                gx = np.exp(-((xs[a0:a1] - px[j]) ** 2) * inv)
                gy = np.exp(-((ys[b0:b1] - py[j]) ** 2) * inv) * (mass[j] * inv / math.pi)
                blob = np.outer(gy, gx)
                vt[b0 - y0 : b1 - y0, a0 - x0 : a1 - x0] += blob
                va[b0 - y0 : b1 - y0, a0 - x0 : a1 - x0] += blob * ash[j]
            if s.plume_texture > 0 and vt.any():
                # texture that moves with the flow, developing away from this plume's vent:
                # the downwind distance from it (plain distance in calm air), none upwind
                if tex is None:
                    tex = self._sample_shifted("plume", window, ux * t, uy * t).astype(np.float64)
                rx, ry = xs[None, x0:x1] - v.x, ys[y0:y1, None] - v.y
                if speed_px > 0:
                    d = np.maximum((rx * ux + ry * uy) / speed_px, 0.0)
                else:
                    d = np.hypot(rx, ry)
                amp = s.plume_texture * (1.0 - np.exp(-d / (3.0 * v.source_sigma_m / s.gsd)))
                mult = np.exp(amp * tex[y0:y1, x0:x1] - 0.5 * amp**2)
                vt *= mult
                va *= mult
            tau[y0:y1, x0:x1] += vt
            tau_ash[y0:y1, x0:x1] += va
        return tau.astype(np.float32), tau_ash.astype(np.float32)

    def _cloud_tau(
        self,
        t: float,
        window: Window,
        *,
        volcanic: bool,
        shift: tuple[float, float] = (0.0, 0.0),
        only: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Drifting clouds of one kind (cloud ``only`` alone): ``(tau, tau_ash)``; rigid drift."""
        s = self.spec
        c0, r0, w, h = window
        tau = np.zeros((h, w), np.float32)
        tau_ash = np.zeros((h, w), np.float32)
        ux, uy = s.wind.velocity_px(s.gsd)
        dx, dy = ux * t + shift[0], uy * t + shift[1]
        xs = np.arange(c0, c0 + w, dtype=np.float64)
        ys = np.arange(r0, r0 + h, dtype=np.float64)
        for ci, c in enumerate(s.clouds):
            if c.volcanic != volcanic or (only is not None and ci != only):
                continue
            cx, cy, rad = c.x + dx, c.y + dy, c.radius_m / s.gsd
            if (
                cx + 4 * rad < c0
                or cx - 4 * rad > c0 + w
                or cy + 4 * rad < r0
                or cy - 4 * rad > r0 + h
            ):
                continue
            # each cloud its own texture: the tile seen through an offset per cloud
            tex = self._sample_shifted("cloud", window, dx + 37.0 * ci, dy + 53.0 * ci)
            env = np.exp(-0.5 * ((ys[:, None] - cy) ** 2 + (xs[None, :] - cx) ** 2) / rad**2)
            layer = c.optical_depth * np.maximum(env * np.exp(0.8 * tex - 0.32) - 0.25, 0.0)
            tau += layer.astype(np.float32)
            tau_ash += (layer * c.ash_fraction).astype(np.float32)
        return tau, tau_ash

    # ------------------------------------------------------------------ public
    def truth(self, t: float, window: Window | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(mask bool, tau float32)``: the true plume at time ``t`` on ``window``.

        ``tau`` is the optical depth of attached plumes and volcanic clouds; the
        mask is ``tau > label_optical_depth``.

        Parameters
        ----------
        t : float
            Seconds after the look-ahead acquisition.
        window : tuple of int or None
            ``(col0, row0, width, height)`` (``None``: the world's tile).

        Returns
        -------
        mask : numpy.ndarray
            Boolean ``(height, width)`` truth.
        tau : numpy.ndarray
            ``(height, width)`` optical depth of attached plumes and volcanic clouds.
        """
        t = _check_time(t)
        window = check_window(window, self.spec.size)
        tau, _ = self._plume_tau(t, window)
        vtau, _ = self._cloud_tau(t, window, volcanic=True)
        tau = tau + vtau
        return tau > self.spec.label_optical_depth, tau

    def render(self, t: float, window: Window | None = None, *, noise: bool = True) -> WorldFrame:
        """Render the world at time ``t`` (s after ``epoch``) on ``window``.

        Parameters
        ----------
        t : float
            Seconds after the look-ahead acquisition (``spec.epoch``).
        window : (col0, row0, width, height) or None
            Integer pixel window of the world grid; ``None``: ``(0, 0, size, size)``.
            Overlapping windows agree pixel for pixel.
        noise : bool
            Add sensor noise (deterministic in ``t`` and the pixel position).

        Returns
        -------
        WorldFrame
            ``image`` (4, H, W) float32 reflectance, ``mask`` bool truth, ``tau`` plume optical depth.

        Examples
        --------
        >>> w = World(sample_world(0, 1, size=32))
        >>> f = w.render(0.0, window=(-8, 4, 12, 10))
        >>> f.image.shape, f.mask.shape
        ((4, 10, 12), (10, 12))
        """
        t = _check_time(t)
        window = check_window(window, self.spec.size)
        s = self.spec
        image = self._ground(window).copy()
        tau, tau_ash = self._plume_tau(t, window)
        vtau, vash = self._cloud_tau(t, window, volcanic=True)
        mtau, _ = self._cloud_tau(t, window, volcanic=False)
        # cloud shadows: the same clouds seen offset away from the sun
        az = math.radians(s.sun_azimuth_deg)
        off = 0.05 * s.size / math.tan(math.radians(s.sun_elevation_deg))
        shift = (-off * math.sin(az), off * math.cos(az))
        shadow, _ = self._cloud_tau(t, window, volcanic=False, shift=shift)
        return self._composite(image, shadow, (tau, tau_ash), (vtau, vash), mtau, t, window, noise)

    def _composite(
        self,
        image: np.ndarray,
        shadow: np.ndarray,
        plume: tuple[np.ndarray, np.ndarray],
        volcanic: tuple[np.ndarray, np.ndarray],
        mtau: np.ndarray,
        t: float,
        window: Window,
        noise: bool,
    ) -> WorldFrame:
        """Lay the shadows, plumes and clouds over the ground ``image``; add the noise."""
        s = self.spec
        tau, tau_ash = plume
        vtau, vash = volcanic
        # each layer is skipped where it is zero everywhere (exactly a no-op: x * 1 + c * 0)
        if shadow.any():
            image *= np.exp(-0.6 * shadow)[None]
        ptau = tau + vtau
        if ptau.any():
            with np.errstate(invalid="ignore", divide="ignore"):
                ash = np.where(ptau > 1e-6, (tau_ash + vash) / np.maximum(ptau, 1e-6), 0.0)
            colour = np.asarray(ASH_PLUME, np.float32)[:, None, None] * ash[None] + np.asarray(
                STEAM, np.float32
            )[:, None, None] * (1.0 - ash[None])
            trans = np.exp(-ptau)[None]
            image = image * trans + colour * (1.0 - trans)
        if mtau.any():
            trans = np.exp(-mtau)[None]
            image = image * trans + np.asarray(CLOUD, np.float32)[:, None, None] * (1.0 - trans)
        if noise and s.noise_sigma > 0:
            frame_rng = np.random.default_rng([s.seed, 0xD4, round(t * 1000.0) & 0xFFFFFFFF])
            ox, oy = (int(v) for v in frame_rng.integers(0, s.tile, 2))
            for b in range(4):
                c0, r0, w, h = window
                image[b] += s.noise_sigma * self._sample(
                    "white", (c0 + ox + 97 * b, r0 + oy + 31 * b, w, h)
                )
        image = np.clip(image, 0.0, 1.0).astype(np.float32)
        return WorldFrame(image, ptau > s.label_optical_depth, ptau.astype(np.float32), t, window)

    # ------------------------------------------------------------------ 3D
    def column_height(self, vi: int, t: float) -> float:
        """Height of vent ``vi``'s column top at ``t``, metres (0 in a flat world).

        The top rises from the vent (sea level) at ``rise_mps`` from the onset
        (``-eruption_age_s``) until it reaches ``top_height_m``, then stays there.

        Parameters
        ----------
        vi : int
            Index of the vent in the spec.
        t : float
            Seconds on the pass clock.

        Returns
        -------
        float
            The height, metres (0 before the onset).

        Examples
        --------
        >>> v = VentSpec(10.0, 10.0, eruption_age_s=100.0, top_height_m=9000.0, rise_mps=30.0)
        >>> w = World(WorldSpec(0, 32, 8.0, Wind(5.0, 0.0), (v,)))
        >>> w.column_height(0, 0.0), w.column_height(0, 200.0), w.column_height(0, 400.0)
        (3000.0, 9000.0, 9000.0)
        """
        v = self.spec.vents[vi]
        if v.top_height_m is None:
            return 0.0
        if v.rise_mps is None:
            return float(v.top_height_m)
        return float(min(v.top_height_m, max(0.0, v.rise_mps * (t + v.eruption_age_s))))

    def _seen_from(
        self,
        layer: Any,
        window: Window,
        height_m: float,
        nadir_px: tuple[float, float],
        altitude_m: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """A layer ``window -> (tau, tau_ash)`` at ``height_m`` as seen on the ground ``window``.

        Each output pixel is an apparent ground point; the feature seen there lies where the
        line of sight to it crosses ``height_m`` (:func:`dyntarget.parallax.sight_at_height`,
        radial from the nadir), so the layer is rendered around those points and resampled
        there (bilinear, OpenCV ``remap``).
        """
        from dyntarget import parallax

        c0, r0, w, h = window
        gsd = self.spec.gsd
        nx, ny = nadir_px

        def source(xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """True (source) world px of the apparent points ``(xs, ys)`` (offsets from the nadir)."""
            d = np.hypot(xs, ys) * gsd
            # k(d) = true / apparent distance is smooth in d: exact on 2,049 distances
            # spanning the window, linear in between (differs from exact by < 1e-6 px)
            grid = np.linspace(float(d.min()), float(d.max()), 2049) if d.size > 4096 else d
            true_d = parallax.sight_at_height(altitude_m, grid, height_m)
            with np.errstate(invalid="ignore", divide="ignore"):
                k = np.where(grid > 0, true_d / np.where(grid > 0, grid, 1.0), 1.0)
            if not np.isfinite(k).all():
                raise InvalidParameterError(
                    "oblique view: part of the window is beyond the spacecraft's horizon"
                )
            if grid is not d:
                k = np.interp(d, grid, k)
            return nx + xs * k, ny + ys * k

        # the map is a radial bijection: the window's border bounds where its pixels come from
        cols = np.arange(c0, c0 + w, dtype=np.float64) - nx
        rows = np.arange(r0, r0 + h, dtype=np.float64) - ny
        bx = np.concatenate([cols, cols, np.full(h, cols[0]), np.full(h, cols[-1])])
        by = np.concatenate([np.full(w, rows[0]), np.full(w, rows[-1]), rows, rows])
        ex, ey = source(bx, by)
        if c0 <= nx <= c0 + w - 1 and r0 <= ny <= r0 + h - 1:  # the nadir inside: it maps to itself
            ex, ey = np.append(ex, nx), np.append(ey, ny)
        bx0, by0 = math.floor(float(ex.min())) - 2, math.floor(float(ey.min())) - 2
        bx1, by1 = math.ceil(float(ex.max())) + 3, math.ceil(float(ey.max())) + 3
        src = check_window((bx0, by0, bx1 - bx0, by1 - by0), self.spec.size)
        tau, tau_ash = layer(src)
        if not tau.any():
            return np.zeros((h, w), np.float32), np.zeros((h, w), np.float32)
        sx, sy = source(cols[None, :], rows[:, None])
        mx, my = (sx - bx0).astype(np.float32), (sy - by0).astype(np.float32)
        out = [
            cv2.remap(
                np.ascontiguousarray(a, np.float32),
                mx,
                my,
                cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=0.0,
            )
            for a in (tau, tau_ash)
        ]
        return out[0], out[1]

    def render_look(
        self,
        t: float,
        window: Window | None = None,
        *,
        nadir_px: tuple[float, float],
        altitude_m: float,
        noise: bool = True,
    ) -> WorldFrame:
        """Render a look-ahead frame at ``t`` as the spacecraft sees it from an oblique view.

        The spacecraft is at ``altitude_m`` above the world-grid point ``nadir_px``
        (``(x, y)`` world pixels; a look-ahead 500 km ahead at 8 m has it 62,500 px
        behind the window). Every plume at its column height (:meth:`column_height`) and
        every cloud at its height is displaced away from the nadir by its parallax
        (:mod:`dyntarget.parallax`, exact on the sphere; the displacement varies across
        the window); the ground, cloud shadows and the frame stay georeferenced to the
        ground, as an L1 product orthorectified to the terrain (whose height is taken as
        0 here). The mask and ``tau`` are those of the displaced plume, what the frame
        shows. Not modelled: the pixel footprint's stretch with the view angle (the frame
        keeps the ground GSD), the column's own side (each vent's plume is drawn as one
        layer at its top's height, the umbrella) and occlusion of one layer by another
        beyond the optical-depth blending. A flat world renders as :meth:`render`.

        Parameters
        ----------
        t : float
            Seconds after the look-ahead acquisition.
        window : tuple of int or None
            ``(col0, row0, width, height)`` on the ground (``None``: the world's tile).
        nadir_px : tuple of float
            The spacecraft's nadir on the world grid, pixels.
        altitude_m : float
            The spacecraft's altitude, metres.
        noise : bool
            Add sensor noise (as :meth:`render`).

        Returns
        -------
        WorldFrame
            The oblique view on the ground grid.

        Examples
        --------
        A 10 km umbrella 500 km ahead of a spacecraft 500 km up shifts 11.5 km (1438 px):

        >>> v = VentSpec(32.0, 32.0, top_height_m=10_000.0)
        >>> w = World(WorldSpec(0, 64, 8.0, Wind(0.0, 0.0), (v,), plume_texture=0.0))
        >>> f = w.render_look(0.0, (0, -1438, 64, 64), nadir_px=(32.0, 32.0 + 62_500.0),
        ...                   altitude_m=500e3)
        >>> [int(i) for i in np.unravel_index(f.tau.argmax(), f.tau.shape)]  # row, column
        [32, 32]
        """
        t = _check_time(t)
        window = check_window(window, self.spec.size)
        nadir = (
            _number("", "nadir x", nadir_px[0], -MAX_COORD_PX, MAX_COORD_PX),
            _number("", "nadir y", nadir_px[1], -MAX_COORD_PX, MAX_COORD_PX),
        )
        altitude = _number("", "altitude_m", altitude_m, 1.0, 1e8)
        if not self.spec.is_3d:
            return self.render(t, window, noise=noise)
        s = self.spec
        _, _, w, h = window
        image = self._ground(window).copy()
        az = math.radians(s.sun_azimuth_deg)
        off = 0.05 * s.size / math.tan(math.radians(s.sun_elevation_deg))
        shift = (-off * math.sin(az), off * math.cos(az))
        shadow, _ = self._cloud_tau(t, window, volcanic=False, shift=shift)
        layers = [np.zeros((h, w), np.float32) for _ in range(5)]  # tau, ash, vtau, vash, mtau
        for vi in range(len(s.vents)):
            hv = self.column_height(vi, t)

            def plume(win: Window, vi: int = vi) -> tuple[np.ndarray, np.ndarray]:
                return self._plume_tau(t, win, only=vi)

            a, b = self._seen_from(plume, window, hv, nadir, altitude) if hv > 0 else plume(window)
            layers[0] += a
            layers[1] += b
        for ci, c in enumerate(s.clouds):

            def cloud(win: Window, ci: int = ci, c: CloudSpec = c) -> tuple[np.ndarray, np.ndarray]:
                return self._cloud_tau(t, win, volcanic=c.volcanic, only=ci)

            hc = c.height_m or 0.0
            a, b = self._seen_from(cloud, window, hc, nadir, altitude) if hc > 0 else cloud(window)
            if c.volcanic:
                layers[2] += a
                layers[3] += b
            else:
                layers[4] += a
        tau, tau_ash, vtau, vash, mtau = layers
        return self._composite(image, shadow, (tau, tau_ash), (vtau, vash), mtau, t, window, noise)

    def transform(self, window: Window | None = None) -> Affine:
        """Pixel -> CRS transform of ``window`` (north up, ``gsd`` m pixels).

        Parameters
        ----------
        window : tuple of int or None
            ``(col0, row0, width, height)`` (``None``: the world's tile).

        Returns
        -------
        affine.Affine
            The window's geotransform in the spec's CRS.
        """
        c0, r0, _, _ = check_window(window, self.spec.size)
        s = self.spec
        return Affine.translation(
            s.origin_easting + c0 * s.gsd, s.origin_northing - r0 * s.gsd
        ) @ Affine.scale(s.gsd, -s.gsd)

    def scene(self, t: float, window: Window | None = None, *, id: str | None = None) -> Scene:
        """The rendering at ``t`` as a labelled, georeferenced :class:`~dyntarget.scene.Scene`.

        Parameters
        ----------
        t : float
            Seconds after the look-ahead acquisition.
        window : tuple of int or None
            ``(col0, row0, width, height)`` (``None``: the world's tile).
        id : str or None
            Scene id (default: the spec's id and the time).

        Returns
        -------
        dyntarget.scene.Scene
            The 4-band image with its truth label, GSD, CRS and transform.

        Examples
        --------
        >>> World(sample_world(0, 2, size=32)).scene(60.0).id
        'dyn-0000-0002-t0060.000'
        """
        f = self.render(t, window)
        return Scene(
            f.image,
            label=f.mask,
            gsd=self.spec.gsd,
            crs=self.spec.crs,
            transform=self.transform(window),
            id=id or f"{self.spec.id}-t{f.t:08.3f}".replace("-t-", "-tm"),
        )


@dataclass
class TruthCache:
    """A truth provider ``t -> Scene`` for a world, caching recent times (quantised).

    ``step_s`` rounds the requested times to a grid (0: exact times), so that
    pointings a few milliseconds apart share one rendering.

    Parameters
    ----------
    world : World
        The world to render.
    step_s : float
        Grid the requested times are rounded to, seconds (0: exact times).
    window : tuple of int or None
        ``(col0, row0, width, height)`` to render (``None``: the world's tile).
    capacity : int
        Most renderings kept (least recently used dropped first).

    Examples
    --------
    >>> truth = TruthCache(World(sample_world(0, 0, size=32)), step_s=1.0)
    >>> truth(0.4) is truth(0.0)
    True
    """

    world: World
    step_s: float = 1.0
    window: Window | None = None
    capacity: int = 16
    _cache: OrderedDict = field(default_factory=OrderedDict, repr=False)

    def __call__(self, t: float) -> Scene:
        t = _check_time(t)
        if self.step_s > 0:
            t = round(t / self.step_s) * self.step_s
        hit = self._cache.get(t)
        if hit is not None:
            self._cache.move_to_end(t)
            return hit
        scene = self.world.scene(t, self.window)
        self._cache[t] = scene
        if len(self._cache) > self.capacity:
            self._cache.popitem(last=False)
        return scene


def world_sequence(
    world: World,
    *,
    frames: int,
    interval_s: float,
    window: Window | None = None,
    truth_step_s: float = 1.0,
) -> FrameSequence:
    """Look-ahead frames at ``t = 0, S, 2S`` and on, with the world as truth provider.

    Parameters
    ----------
    world : World
    frames : int
        Number of frames (>= 1).
    interval_s : float
        Seconds between frames (> 0).
    window : (col0, row0, width, height) or None
        Where to render; ``None``: the world's own tile.
    truth_step_s : float
        Time quantum of the truth provider's cache (see :class:`TruthCache`).

    Returns
    -------
    FrameSequence
        With ``meta["world"]`` the spec (from which the truth is rebuilt) and ``meta["window"]``.

    Examples
    --------
    >>> seq = world_sequence(World(sample_world(0, 0, size=32)), frames=3, interval_s=10.0)
    >>> seq.times.tolist(), seq.truth_at(95.0).label.shape
    ([0.0, 10.0, 20.0], (32, 32))
    """
    if isinstance(frames, bool) or not isinstance(frames, int | np.integer) or frames < 1:
        raise InvalidParameterError(f"frames: expected an integer >= 1, got {frames!r}")
    if frames > MAX_FRAMES:
        raise InvalidParameterError(f"frames: {frames}, more than the {MAX_FRAMES} of one sequence")
    if not (isinstance(interval_s, int | float) and math.isfinite(interval_s) and interval_s > 0):
        raise InvalidParameterError(f"frame interval: expected seconds > 0, got {interval_s!r}")
    window = check_window(window, world.spec.size)
    times = [i * float(interval_s) for i in range(int(frames))]
    scenes = [world.scene(t, window, id=f"f{i:03d}") for i, t in enumerate(times)]
    return FrameSequence(
        scenes,
        times,
        epoch=world.spec.epoch,
        id=world.spec.id,
        truth=TruthCache(world, step_s=truth_step_s, window=window),
        meta={"world": world.spec.to_dict(), "window": list(window)},
    )


def truth_provider(meta: dict[str, Any], *, step_s: float = 1.0) -> TruthCache | None:
    """Rebuild the truth provider of a sequence from its stored ``meta`` (``None`` without a world).

    Parameters
    ----------
    meta : dict
        The sequence's metadata, with the world spec under ``"world"`` and the
        window under ``"window"``.
    step_s : float
        Time grid of the cache, seconds (see :class:`TruthCache`).

    Returns
    -------
    TruthCache or None
        The provider, or ``None`` when ``meta`` holds no world.

    Examples
    --------
    >>> seq = world_sequence(World(sample_world(0, 0, size=32)), frames=1, interval_s=1.0)
    >>> bool((truth_provider(seq.meta)(40.0).label == seq.truth_at(40.0).label).all())
    True
    """
    spec = meta.get("world") if isinstance(meta, dict) else None
    if spec is None:
        return None
    spec = WorldSpec.from_dict(spec)
    window = meta.get("window")
    window = None if window is None else check_window(window, spec.size)
    return TruthCache(World(spec), step_s=step_s, window=window)


def generate_sequences(
    n: int,
    *,
    size: int = 512,
    seed: int = 0,
    gsd: float = 8.0,
    frames: int = 2,
    interval_s: float = 10.0,
    wind_mps: float | None = None,
    wind_from_deg: float | None = None,
    heights_km: tuple[tuple[float, float], tuple[float, float]] | None = None,
) -> Iterator[FrameSequence]:
    """Yield sequences ``0`` to ``n - 1`` of the moving-world set with ``seed`` (see :func:`sample_world`).

    Parameters
    ----------
    n : int
        Number of sequences (at least 1).
    size : int
        Side of each world, pixels.
    seed : int
        The set's seed.
    gsd : float
        Ground sample distance, metres per pixel.
    frames : int
        Frames per sequence.
    interval_s : float
        Seconds between frames.
    wind_mps : float or None
        Wind speed for every world, m/s (default: drawn per world).
    wind_from_deg : float or None
        Wind direction for every world, degrees from north (default: drawn).
    heights_km : tuple or None
        ``((plume lo, hi), (cloud lo, hi))`` km: 3D worlds (:func:`with_heights`);
        ``None``: flat worlds. The frames are still rendered from straight above
        (:meth:`World.render_look` renders oblique looks).

    Yields
    ------
    dyntarget.sequence.FrameSequence
        Sequence ``i`` of world ``i``, with its truth provider.

    Examples
    --------
    >>> [s.id for s in generate_sequences(2, size=32, frames=1)]
    ['dyn-0000-0000', 'dyn-0000-0001']
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise InvalidParameterError(f"scenes: expected an integer >= 1, got {n!r}")
    for i in range(n):
        spec = sample_world(
            seed, i, size=size, gsd=gsd, wind_mps=wind_mps, wind_from_deg=wind_from_deg
        )
        if heights_km is not None:
            spec = with_heights(spec, plume_height_km=heights_km[0], cloud_height_km=heights_km[1])
        yield world_sequence(World(spec), frames=frames, interval_s=interval_s)


def sample_strip(
    seed: int,
    *,
    length: int,
    width: int = 512,
    plumes: int = 4,
    gsd: float = 8.0,
    wind_mps: float | None = None,
    wind_from_deg: float | None = None,
) -> tuple[WorldSpec, Window]:
    """A long world with several vents, for pass simulations; returns ``(spec, strip window)``.

    The strip runs along the image rows (row 0 at the top, ``length`` rows,
    ``width`` columns); vents are spread along it, one per ``length / plumes``
    rows, each with its own draws as in :func:`sample_world`. Render the whole
    strip with ``World(spec).render(t, window)`` or any sub-window of it.

    Parameters
    ----------
    seed : int
        Seed of the strip's draws.
    length : int
        Rows of the strip (at least ``width``).
    width : int
        Columns of the strip.
    plumes : int
        Number of vents (at least 1).
    gsd : float
        Ground sample distance, metres per pixel.
    wind_mps : float or None
        Wind speed, m/s (default: drawn).
    wind_from_deg : float or None
        Wind direction, degrees from north (default: drawn).

    Returns
    -------
    spec : WorldSpec
        The world.
    window : tuple of int
        ``(0, 0, width, length)``, the strip on the world grid.

    Examples
    --------
    >>> spec, window = sample_strip(0, length=256, width=64, plumes=2)
    >>> len(spec.vents), window
    (2, (0, 0, 64, 256))
    """
    if isinstance(plumes, bool) or not isinstance(plumes, int) or plumes < 1:
        raise InvalidParameterError(f"plumes: expected an integer >= 1, got {plumes!r}")
    if plumes > MAX_VENTS:
        raise InvalidParameterError(
            f"plumes: {plumes}, more than the {MAX_VENTS} vents a world may have"
        )
    check_window((0, 0, width, length), width)
    if isinstance(length, bool) or not isinstance(length, int) or length < width:
        raise InvalidParameterError(
            f"length: expected an integer >= width ({width}), got {length!r}"
        )
    base = sample_world(
        seed, 0, size=width, gsd=gsd, wind_mps=wind_mps, wind_from_deg=wind_from_deg
    )
    rng = np.random.default_rng([int(seed), 0xD6])
    vents, clouds = [], list(base.clouds)
    seg = length / plumes
    for k in range(plumes):
        v = sample_world(seed, k, size=width, gsd=gsd, wind_mps=base.wind.speed_mps,
                         wind_from_deg=base.wind.from_deg).vents[0]  # fmt: skip
        y = seg * (k + float(rng.uniform(0.3, 0.7)))
        x = width * float(rng.uniform(0.25, 0.75))
        vents.append(
            VentSpec(**{**asdict(v), "x": x, "y": y})  # same plume draws, placed along the strip
        )
    tile = 1 << max(9, (max(width, length) - 1).bit_length())
    spec = WorldSpec(
        **{
            **{f.name: getattr(base, f.name) for f in fields(WorldSpec)},
            "vents": tuple(vents),
            "clouds": tuple(clouds),
            "tile": min(tile, 2048),
            "id": f"strip-{int(seed):04d}",
        }
    )
    return spec, (0, 0, int(width), int(length))


PLUME_HEIGHT_KM = (2.0, 15.0)
"""Default range of a vent's column-top height, km (neutral buoyancy; issue 40)."""
CLOUD_HEIGHT_KM = (1.0, 12.0)
"""Default range of a cloud's top height, km."""
RISE_MPS = (10.0, 100.0)
"""Range of a column's rise velocity, m/s."""


def check_height_range(name: str, value: object) -> tuple[float, float]:
    """A ``(lo, hi)`` range of heights in km: finite, ``0 <= lo <= hi <= 25``, or a refusal.

    Parameters
    ----------
    name : str
        The option, for the message.
    value : object
        The range.

    Returns
    -------
    tuple of float
        ``(lo, hi)`` km.

    Examples
    --------
    >>> check_height_range("plume height", (2, 15))
    (2.0, 15.0)
    """
    try:
        lo, hi = (float(v) for v in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{name}: expected LO,HI km, got {value!r}") from None
    top = MAX_HEIGHT_M / 1e3
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo <= hi <= top):
        raise InvalidParameterError(
            f"{name}: expected LO,HI km with 0 <= LO <= HI <= {top:g}, got {lo:g},{hi:g}"
        )
    return lo, hi


def with_heights(
    spec: WorldSpec,
    *,
    plume_height_km: tuple[float, float] = PLUME_HEIGHT_KM,
    cloud_height_km: tuple[float, float] = CLOUD_HEIGHT_KM,
    rise_mps: tuple[float, float] = RISE_MPS,
    seed: int | None = None,
) -> WorldSpec:
    """The world made 3D: a column-top height and rise velocity per vent, a height per cloud.

    Drawn uniformly in the ranges from their own random stream (``seed`` and the spec's
    id, so each world of a set, and each strip, draws its own), so the flat world's
    other draws are untouched: the 3D world differs from the flat one only in its heights.

    Parameters
    ----------
    spec : WorldSpec
        The flat world.
    plume_height_km : tuple of float
        Range of the vents' top heights, km.
    cloud_height_km : tuple of float
        Range of the clouds' heights (volcanic and meteorological), km.
    rise_mps : tuple of float
        Range of the rise velocities, m/s.
    seed : int or None
        Seed of the height draws (default: the spec's).

    Returns
    -------
    WorldSpec
        The same world with heights.

    Examples
    --------
    >>> spec = with_heights(sample_world(0, 0, size=32), plume_height_km=(5, 5), seed=1)
    >>> spec.vents[0].top_height_m, spec.is_3d
    (5000.0, True)
    """
    p_lo, p_hi = check_height_range("plume height", plume_height_km)
    c_lo, c_hi = check_height_range("cloud height", cloud_height_km)
    r_lo, r_hi = (float(v) for v in rise_mps)
    if not (0.0 < r_lo <= r_hi <= MAX_RISE_MPS):
        raise InvalidParameterError(f"rise: expected 0 < LO <= HI <= {MAX_RISE_MPS:g} m/s")
    key = zlib.crc32(spec.id.encode())
    rng = np.random.default_rng([int(spec.seed if seed is None else seed), key, 0xD8])
    vents = tuple(
        replace(
            v,
            top_height_m=float(rng.uniform(p_lo, p_hi) * 1e3),
            rise_mps=float(rng.uniform(r_lo, r_hi)),
        )
        for v in spec.vents
    )
    clouds = tuple(replace(c, height_m=float(rng.uniform(c_lo, c_hi) * 1e3)) for c in spec.clouds)
    return replace(spec, vents=vents, clouds=clouds)


ONSET_WINDOW_S = (-3600.0, 0.0)
"""Default span of the drawn onsets, pass clock, s: the hour before the pass starts (the
GEO images a blueprint may use are from then: a latency decides which onsets they show)."""


def check_onset_window(name: str, value: object) -> tuple[float, float]:
    """A ``(lo, hi)`` span on the pass clock, s: finite, ``lo < hi``, within a day, or a refusal.

    Parameters
    ----------
    name : str
        The option, for the message.
    value : object
        The span.

    Returns
    -------
    tuple of float
        ``(lo, hi)`` s.

    Examples
    --------
    >>> check_onset_window("onset window", (-3600, 60))
    (-3600.0, 60.0)
    """
    try:
        lo, hi = (float(v) for v in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{name}: expected LO,HI seconds, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and -MAX_SECONDS <= lo < hi <= MAX_SECONDS):
        raise InvalidParameterError(
            f"{name}: expected LO < HI within ±{MAX_SECONDS:g} s, got {lo:g},{hi:g}"
        )
    return lo, hi


def with_onsets(
    spec: WorldSpec,
    fraction: float,
    *,
    window_s: tuple[float, float] = ONSET_WINDOW_S,
    duration_s: tuple[float, float] | None = None,
    seed: int | None = None,
) -> WorldSpec:
    """Eruptions that start (and optionally stop) around the pass: an onset for some vents.

    Each vent erupts, with probability ``fraction``, at an onset drawn uniformly in
    ``window_s`` on the pass clock (``eruption_age_s = -onset``: before it the vent shows
    nothing; after it the plume grows downwind from the vent at the wind's speed and, in a
    3D world, the column rises at ``rise_mps``); with ``duration_s`` it stops after a
    duration drawn uniformly in that range (``end_s``). The other vents keep their draws.
    Drawn from their own random stream (``seed`` and the spec's id), so every other draw
    of the world is untouched.

    Parameters
    ----------
    spec : WorldSpec
        The world.
    fraction : float
        Share of the vents given an onset, in ``[0, 1]`` (0: the world unchanged).
    window_s : tuple of float
        Span of the onsets, pass clock, s (default :data:`ONSET_WINDOW_S`).
    duration_s : tuple of float or None
        Span of the eruptions' durations, s (``None``: they do not stop).
    seed : int or None
        Seed of the onset draws (default: the spec's).

    Returns
    -------
    WorldSpec
        The same world with onsets.

    Examples
    --------
    >>> spec = with_onsets(sample_world(0, 0, size=32), 1.0, window_s=(-600, -300), seed=1)
    >>> -600 <= -spec.vents[0].eruption_age_s <= -300
    True
    """
    f = _number("", "onset fraction", fraction, 0.0, 1.0)
    lo, hi = check_onset_window("onset window", window_s)
    if duration_s is not None:
        d_lo, d_hi = (float(v) for v in duration_s)
        if not (math.isfinite(d_lo) and math.isfinite(d_hi) and 0.0 < d_lo <= d_hi <= MAX_SECONDS):
            raise InvalidParameterError(
                f"onset duration: expected 0 < LO <= HI <= {MAX_SECONDS:g} s, got {d_lo:g},{d_hi:g}"
            )
    if f == 0.0:
        return spec
    key = zlib.crc32(spec.id.encode())
    rng = np.random.default_rng([int(spec.seed if seed is None else seed), key, 0xD9])
    vents = []
    for v in spec.vents:
        hit, onset, dur = rng.uniform(), rng.uniform(lo, hi), rng.uniform()
        if hit >= f:
            vents.append(v)
            continue
        end = None
        if duration_s is not None:
            end = float(onset + d_lo + dur * (d_hi - d_lo))
        vents.append(replace(v, eruption_age_s=float(-onset), end_s=end))
    return replace(spec, vents=tuple(vents))
