"""One constellation-day at target level: detections, the shared board, cueing, allocation.

**Detections.** A satellite's look-ahead detects an eruption when it passes over the
plume while the plume is there and not hidden by cloud
(:mod:`dyntarget.constellation.geometry`). In ``cross+geo`` the geostationary imagers
(:data:`GEO_IMAGERS`: real sub-satellite longitudes and full-disk cadences) detect too,
with the detection model of ``fly --geo`` (:mod:`dyntarget.passes.geo`): a GEO cell's
anomaly is :data:`dyntarget.geo.targets.CONTRAST` times the fraction of the cell the plume
covers (the cell grows as ``1 / cos`` of the viewing zenith angle) times its opacity
``1 - exp(-optical depth)``, plus Gaussian noise (``GeoSettings.noise``); above
``GeoSettings.threshold`` it counts; the image is usable ``GeoSettings.latency_s``
after it is taken. A volcano beyond :data:`GEO_MAX_ZENITH_DEG` of every imager's view
is not seen from GEO; cloud hides a plume below its top from GEO too.

**The board** holds every detection; what a satellite knows depends on the cueing mode
(``none``: its own look-ahead on this overflight only; ``self``: its own detections of
the last ``memory_s``; ``cross``: every satellite's; ``cross+geo``: and the GEO
imagers') and on the relay (``crosslink``: ``crosslink_s`` after the detection;
``ground``: at the detecting satellite's next ground-station contact, then at the
receiving satellite's next one; ``none``: at once). An overflight is an opportunity
when the satellite knows the eruption :data:`PLAN_S` before the observation and the Sun
is up over the volcano (optical sensors; the look-ahead detects by day only too). The
GEO imagers detect day and night (the split-window thermal-infrared ash products do).
"""

from __future__ import annotations

import itertools
import math
import statistics
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.constellation.allocate import (
    CLUSTER_S,
    Opportunities,
    bound,
    distributed,
    greedy,
)
from dyntarget.constellation.geometry import ENC_FIELDS, MIN_SUN_DEG, PLAN_S, overflights
from dyntarget.constellation.orbits import Satellite, geodetic_to_ecef
from dyntarget.constellation.world import (
    EPISODES_PER_DAY,
    ERUPTIONS_IN_PROGRESS,
    MEDIAN_DURATION_S,
    MODELS,
    ONSETS_PER_YEAR,
    Catalog,
    Eruptions,
    cloud_state,
    hidden,
)
from dyntarget.errors import InvalidParameterError

CUEING = ("none", "self", "cross", "cross+geo")
ALLOCATIONS = ("greedy", "distributed", "bound")
RELAYS = ("crosslink", "ground", "none")
GEO_IMAGERS: tuple[tuple[str, float, float], ...] = (
    ("GOES-East", -75.2, 600.0),
    ("GOES-West", -137.0, 600.0),
    ("Meteosat", 0.0, 900.0),
    ("Himawari", 140.7, 600.0),
)
"""Name, sub-satellite longitude (degrees) and full-disk cadence (seconds): GOES-19 and
GOES-18 (ABI full disk every 10 min), Meteosat-11 at 0° (SEVIRI every 15 min),
Himawari-9 (AHI every 10 min)."""
GEO_RADIUS_M = 42_164_000.0
GEO_MAX_ZENITH_DEG = 65.0
"""Largest viewing zenith angle a GEO detection is trusted at (beyond: blind)."""
HOUR6 = 6 * 3600.0


@dataclass(frozen=True)
class Settings:
    """Everything besides the orbits, catalog and seed that fixes a constellation-day.

    Parameters
    ----------
    cueing, allocation, relay : str
        Modes (:data:`CUEING`, :data:`ALLOCATIONS`, :data:`RELAYS`).
    agility : str
        NFOV agility preset (:data:`dyntarget.schedule.AGILITY`; it needs a field of regard).
    swath_km, look_ahead_km : float
        Look-ahead swath width and distance ahead of nadir, km.
    step_s : float
        Propagation grid, seconds.
    crosslink_s : float
        Board delay over crosslinks, seconds.
    dup_window_s : float
        Two observations of one eruption closer than this: the later is a duplicate.
    memory_s : float
        How long a detection stays on the board (and in a satellite's memory).
    eruptions_per_day : float
        Expected eruptive-episode onsets per day, world-wide (``eruption_model``
        ``episodes`` only).
    eruption_model : str
        :data:`dyntarget.constellation.world.MODELS`: ``eruptions`` (GVP eruptions holding
        plume episodes) or ``episodes`` (episodes only, the earlier model).
    eruptions_in_progress, eruption_onsets_per_year, episodes_per_day, episode_median_h : float
        The two-level model's parameters
        (:func:`dyntarget.constellation.world.draw_gvp_eruptions`; ``eruptions`` only).
    geo : dict
        Overrides of :class:`dyntarget.passes.geo.GeoSettings` fields (GEO detection).
    """

    cueing: str = "cross"
    allocation: str = "greedy"
    relay: str = "crosslink"
    agility: str = "fast"
    swath_km: float = 30.0
    look_ahead_km: float = 500.0
    step_s: float = 20.0
    crosslink_s: float = 30.0
    dup_window_s: float = 600.0
    memory_s: float = 12 * 3600.0
    eruptions_per_day: float = 40.0
    eruption_model: str = "eruptions"
    eruptions_in_progress: float = ERUPTIONS_IN_PROGRESS
    eruption_onsets_per_year: float = ONSETS_PER_YEAR
    episodes_per_day: float = EPISODES_PER_DAY
    episode_median_h: float = MEDIAN_DURATION_S / 3600.0
    geo: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from dyntarget.schedule import get_agility

        for name, allowed in (
            ("cueing", CUEING),
            ("allocation", ALLOCATIONS),
            ("relay", RELAYS),
            ("eruption_model", MODELS),
        ):
            if getattr(self, name) not in allowed:
                raise InvalidParameterError(
                    f"--{name.replace('_', '-')}: expected one of {', '.join(allowed)}, "
                    f"got {getattr(self, name)!r}"
                )
        if get_agility(self.agility).field_of_regard_deg is None:
            raise InvalidParameterError(
                f"--agility {self.agility}: a constellation needs a field of regard "
                "(choose fast or slow)"
            )
        for name, lo, hi in (
            ("swath_km", 0.01, 3000.0),
            ("look_ahead_km", 0.0, 3000.0),
            ("step_s", 1.0, 120.0),
            ("crosslink_s", 0.0, 86400.0),
            ("dup_window_s", 0.0, 86400.0),
            ("memory_s", 0.0, 30 * 86400.0),
            ("eruptions_per_day", 1e-6, 10_000.0),
            ("eruptions_in_progress", 0.0, 100_000.0),
            ("eruption_onsets_per_year", 0.0, 1e6),
            ("episodes_per_day", 1e-6, 10_000.0),
            ("episode_median_h", 1 / 60, 72.0),
        ):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and lo <= v <= hi):
                raise InvalidParameterError(
                    f"--{name.replace('_', '-')}: expected a number in [{lo:g}, {hi:g}], got {v!r}"
                )

    def task_settings(self) -> dict[str, Any]:
        """What the overflight tasks need (part of their keys).

        Returns
        -------
        dict
            JSON-able settings.

        Examples
        --------
        >>> Settings().task_settings()["swath_m"]
        30000.0
        """
        return {
            "step_s": self.step_s,
            "agility": self.agility,
            "look_ahead_m": self.look_ahead_km * 1e3,
            "swath_m": self.swath_km * 1e3,
        }


def geo_detections(
    eruptions: Eruptions,
    lat: np.ndarray,
    lon: np.ndarray,
    cloud_top: np.ndarray,
    *,
    seconds: float,
    seed: int,
    geo: dict[str, float] | None = None,
) -> list[tuple[int, float, float, int]]:
    """GEO detections: ``(eruption, image time, usable time, imager)``, the first per imager.

    Parameters
    ----------
    eruptions : Eruptions
        The eruptions.
    lat, lon : numpy.ndarray
        Each eruption's volcano, degrees.
    cloud_top : numpy.ndarray
        Cloud tops per eruption and block (:func:`dyntarget.constellation.world.hidden`).
    seconds : float
        Length of the period.
    seed : int
        Seed of the noise.
    geo : dict or None
        Overrides of :class:`dyntarget.passes.geo.GeoSettings` fields.

    Returns
    -------
    list of tuple
        Sorted by usable time.

    Examples
    --------
    >>> from dyntarget.constellation.world import Eruptions
    >>> one = np.array
    >>> e = Eruptions(one([0]), one([0.0]), one([7200.0]), one([8.0]), one([0.0]), one([60.0]),
    ...     one([0.1]), one([600.0]), one([5000.0]), one([3.0]))
    >>> geo_detections(e, one([0.0]), one([-75.2]), np.zeros((1, 2)), seconds=7200.0, seed=0)
    [(0, 600.0, 900.0, 0)]
    """
    from dyntarget.geo.targets import CONTRAST
    from dyntarget.passes.geo import GeoSettings

    gs = GeoSettings(**(geo or {}))  # type: ignore[arg-type]
    ground = geodetic_to_ecef(lat, lon, 0.0)
    up = ground / np.linalg.norm(ground, axis=1, keepdims=True)
    out = []
    for g, (_, glon, cadence) in enumerate(GEO_IMAGERS):
        sat = (
            np.array([math.cos(math.radians(glon)), math.sin(math.radians(glon)), 0.0])
            * GEO_RADIUS_M
        )
        los = sat[None, :] - ground
        cos_z = np.sum(los * up, 1) / np.linalg.norm(los, axis=1)
        for e in range(len(eruptions)):
            if cos_z[e] < math.cos(math.radians(GEO_MAX_ZENITH_DEG)):
                continue
            first = math.ceil(max(eruptions.onset_s[e], 0.0) / cadence)
            last = min(eruptions.end_s[e], seconds)
            t = np.arange(first, math.floor(last / cadence) + 1) * cadence
            if not len(t):
                continue
            idx = np.full(len(t), e)
            cell = gs.gsd_m / float(cos_z[e])
            fill = np.minimum(1.0, 2.0 * eruptions.half_width_m(idx, t) / cell) * np.minimum(
                1.0, eruptions.length_m(idx, t) / cell
            )
            anomaly = CONTRAST * fill * (1.0 - math.exp(-eruptions.optical_depth[e]))
            rng = np.random.default_rng([int(seed), int(e), g, 0x6E0])
            seen = (anomaly + rng.normal(0.0, gs.noise, len(t)) > gs.threshold) & ~hidden(
                eruptions, cloud_top, idx, t
            )
            if eruptions.episodic:  # no plume between episodes (noise alone detects nothing)
                seen &= eruptions.active(idx, t)
            if seen.any():
                t0 = float(t[int(np.argmax(seen))])
                out.append((e, t0, t0 + gs.latency_s, g))
    return sorted(out, key=lambda d: (d[2], d[0], d[3]))


class Board:
    """When news posted by a satellite (or the ground) reaches another satellite.

    Parameters
    ----------
    relay : str
        ``crosslink``, ``ground`` or ``none``.
    crosslink_s : float
        Crosslink delay, seconds.
    contacts : list of numpy.ndarray
        Per satellite, sorted times in contact with a ground station.
    """

    def __init__(self, relay: str, crosslink_s: float, contacts: list[np.ndarray]) -> None:
        self.relay, self.crosslink_s, self.contacts = relay, crosslink_s, contacts
        allc = np.unique(np.concatenate(contacts)) if contacts else np.zeros(0)
        self.any_contact = allc

    @staticmethod
    def _next(times: np.ndarray, t: float) -> float:
        k = int(np.searchsorted(times, t, side="left"))
        return float(times[k]) if k < len(times) else math.inf

    def heard(self, src: int, t: float, dst: int) -> float:
        """When ``dst`` hears what ``src`` posted at ``t`` (``src < 0``: the ground).

        Parameters
        ----------
        src : int
            Satellite index, or -1 for a post on the ground (GEO detections).
        t : float
            Posting time, seconds.
        dst : int
            Receiving satellite.

        Returns
        -------
        float
            Seconds (``inf``: never within the period).

        Examples
        --------
        >>> Board("ground", 30.0, [np.array([100.0]), np.array([50.0, 400.0])]).heard(0, 10.0, 1)
        400.0
        """
        if src == dst:
            return t
        if self.relay == "none":
            return t
        if self.relay == "crosslink":
            if src < 0:  # up through the first satellite in contact, then across
                return self._next(self.any_contact, t) + self.crosslink_s
            return t + self.crosslink_s
        down = t if src < 0 else self._next(self.contacts[src], t)
        return self._next(self.contacts[dst], down) if math.isfinite(down) else math.inf


@dataclass
class Day:
    """The result of :func:`run_day` (everything the outputs are written from).

    Parameters
    ----------
    names : list of str
        Satellite names, in constellation order.
    catalog : Catalog
        The volcanoes.
    eruptions : Eruptions
        The eruptions drawn.
    observations : list of dict
        Observations (visible pointings), in time order.
    table : list of dict
        One row per eruption (``eruptions.csv``).
    summary : dict
        The metrics (``summary.json`` without the options).
    tracks : list of list
        Per satellite, ``[lon, lat]`` every minute (empty when not kept).
    cues : list of dict
        Detections on the board: eruption, time, source.
    """

    names: list[str]
    catalog: Catalog
    eruptions: Eruptions
    observations: list[dict[str, Any]]
    table: list[dict[str, Any]]
    summary: dict[str, Any]
    tracks: list[list[list[float]]]
    cues: list[dict[str, Any]]


def run_day(
    sats: list[Satellite],
    catalog: Catalog,
    *,
    start: str,
    hours: float,
    seed: int,
    settings: Settings,
    scheduler: str | None = None,
    parts: Path | None = None,
    progress: bool = False,
    chunk: int = 10,
    tracks: bool = True,
) -> Day:
    """Simulate one constellation period at target level.

    Parameters
    ----------
    sats : list of Satellite
        The constellation.
    catalog : Catalog
        The volcanoes.
    start : str
        ISO 8601 start.
    hours : float
        Length, hours (> 0).
    seed : int
        Seed of eruptions, plumes, clouds and GEO noise.
    settings : Settings
        Modes and geometry.
    scheduler : str or None
        Where the per-satellite overflight tasks run (``None``: here, one by one).
    parts : pathlib.Path or None
        Folder of finished tasks (resume).
    progress : bool
        Progress bar.
    chunk : int
        Satellites per task.
    tracks : bool
        Keep ground tracks (for the figures).

    Returns
    -------
    Day
        Observations, the eruptions table, the summary and what the figures draw.

    Examples
    --------
    >>> from dyntarget.constellation.orbits import utc, walker
    >>> from dyntarget.constellation.world import parse_catalog
    >>> cat = parse_catalog("volcano_number,latitude,longitude,elevation_m,last_known_eruption\\n"
    ...                     "1,19.4,-155.3,1222,2025 CE\\n")
    >>> sats = walker(2, 1, 0, altitude_km=500, inclination_deg=53, epoch=utc("2026-06-01"))
    >>> day = run_day(sats, cat, start="2026-06-01T00:00:00Z", hours=1, seed=0, settings=Settings())
    >>> day.summary["satellites"], day.names
    (2, ['W1-1', 'W1-2'])
    """
    from dyntarget.evaluate.distributed import run_tasks, task_key

    if not (isinstance(hours, int | float) and math.isfinite(hours) and 0 < hours <= 24 * 30):
        raise InvalidParameterError(
            f"--hours: expected a number of hours in (0, 720], got {hours!r}"
        )
    if not sats:
        raise InvalidParameterError("constellation: no satellites (an empty constellation)")
    seconds = float(hours) * 3600.0
    eruptions = _draw(catalog, seconds, seed, settings)
    vol = (
        np.stack(
            [
                catalog.lat[eruptions.volcano],
                catalog.lon[eruptions.volcano],
                catalog.elevation_m[eruptions.volcano],
            ],
            axis=1,
        )
        if len(eruptions)
        else np.zeros((0, 3))
    )
    shared = {
        "start": start,
        "seconds": seconds,
        "settings": settings.task_settings(),
        "eruptions": eruptions.to_json(),
        "volcano": vol.tolist(),
        "tracks": bool(tracks),
    }
    chunks = [
        {"satellites": [[s.name, s.line1, s.line2, list(s.elements)] for s in sats[i : i + chunk]]}
        for i in range(0, len(sats), chunk)
    ]
    results = run_tasks(
        overflights,
        chunks,
        key=lambda t: task_key("constellation-overflights", 1, t, shared),
        parts=parts,
        scheduler=scheduler,
        shared=shared,
        progress=progress,
        desc="satellites",
    )
    per_sat = [s for r in results for s in r]
    names = [s["name"] for s in per_sat]
    cloud, _ = cloud_state(catalog.number[eruptions.volcano], seconds=seconds, seed=seed)
    rows = [(i, row) for i, s in enumerate(per_sat) for row in s["rows"]]
    enc = np.array(
        [[i] + [math.nan if x is None else x for x in row] for i, row in rows], np.float64
    ).reshape(-1, 1 + len(ENC_FIELDS))
    col = {f: enc[:, k + 1] for k, f in enumerate(ENC_FIELDS)}
    sat_of = enc[:, 0].astype(np.int64)
    e_of = col["eruption"].astype(np.int64)
    # detections: (eruption, time, source satellite or -1 - imager, usable time, encounter)
    t_look = col["t_look"]
    look = (col["look_hit"] > 0) & (t_look >= 0) & (t_look <= seconds)
    look &= col["sun_look_deg"] >= MIN_SUN_DEG  # optical: daylight only
    if len(enc):
        look &= ~hidden(eruptions, cloud, e_of, t_look)
    dets: list[tuple[int, float, int, float, int]] = [
        (int(e_of[k]), float(t_look[k]), int(sat_of[k]), float(t_look[k]), int(k))
        for k in np.flatnonzero(look).tolist()
    ]
    if settings.cueing == "cross+geo":
        for e, t_img, t_use, g in geo_detections(
            eruptions, vol[:, 0], vol[:, 1], cloud, seconds=seconds, seed=seed, geo=settings.geo
        ):
            dets.append((e, t_img, -1 - g, t_use, -1))
    board = Board(
        settings.relay,
        settings.crosslink_s,
        [np.asarray(s["contacts"], np.float64) for s in per_sat],
    )
    opp, enc_of = _opportunities(
        enc, col, sat_of, e_of, dets, board, eruptions, cloud, seconds, settings
    )
    conflict = _Conflict(opp, enc_of, col, settings.agility)
    if settings.allocation == "greedy":
        chosen = greedy(opp, dup_window_s=settings.dup_window_s, conflict=conflict)
    elif settings.allocation == "distributed":
        heard = board.heard if settings.cueing in ("cross", "cross+geo") else _never

        def cued(j: int, sat: int, t: float) -> bool:
            assert opp.cue_src is not None and opp.cue_t is not None
            return heard(int(opp.cue_src[j]), float(opp.cue_t[j]), sat) <= t

        predicted = None
        if settings.cueing in ("none", "self"):  # no board: the others' looks, predicted
            predicted = _predicted_looks(col, e_of, sat_of, seconds, settings.swath_km * 500.0)
        chosen = distributed(
            opp,
            dup_window_s=settings.dup_window_s,
            conflict=conflict,
            heard=heard,
            cued=cued,
            predicted=predicted,
        )
    else:
        chosen, _ = bound(opp, dup_window_s=settings.dup_window_s, conflict=conflict)
    first_det: dict[int, float] = {}
    for e, t, *_ in dets:
        first_det[e] = min(first_det.get(e, math.inf), t)
    observations, wasted, dups = _realize(
        opp, chosen, enc_of, col, names, catalog, eruptions, settings
    )
    table = _table(eruptions, catalog, first_det, observations)
    summary = _summary(len(sats), eruptions, first_det, observations, table, seconds)
    summary.update(duplicates=dups, wasted_pointings=wasted, opportunities=len(opp))
    cues = [
        {"eruption": e, "time_s": t, "source": names[src] if src >= 0 else GEO_IMAGERS[-1 - src][0]}
        for e, t, src, _, _ in sorted(dets, key=lambda d: (d[1], d[0], d[2]))
    ]
    return Day(
        names, catalog, eruptions, observations, table, summary, [s["track"] for s in per_sat], cues
    )


def _predicted_looks(col, e_of, sat_of, seconds: float, half_swath_m: float):
    """Per eruption, the overflights ``(t_obs, sat)`` whose look-ahead passes over its vent by day.

    What a satellite without a board can know of the others from the constellation's
    ephemerides (every satellite carries them): who flies over the vent with the vent in
    its look-ahead's swath, by day, in time to plan the observation. Not whether that
    look-ahead will see a plume (the plume's extent, whether it is there, the cloud).
    """
    t_look, t_obs = col["t_look"], col["t_obs"]
    ok = (np.abs(col["cross"]) <= half_swath_m) & (t_look >= 0) & (t_look <= seconds)
    ok &= np.isfinite(t_obs) & (t_obs >= 0) & (t_obs <= seconds) & (t_look <= t_obs - PLAN_S)
    ok &= (col["sun_look_deg"] >= MIN_SUN_DEG) & (col["sun_obs_deg"] >= MIN_SUN_DEG)
    out: dict[int, list[tuple[float, int]]] = {}
    for k in np.flatnonzero(ok).tolist():
        out.setdefault(int(e_of[k]), []).append((float(t_obs[k]), int(sat_of[k])))
    return out


def _never(src: int, t: float, dst: int) -> float:
    return t if src == dst else math.inf


def _draw(catalog: Catalog, seconds: float, seed: int, settings: Settings) -> Eruptions:
    from dyntarget.constellation.world import draw_eruptions, draw_gvp_eruptions

    if settings.eruption_model == "eruptions":
        return draw_gvp_eruptions(
            catalog,
            seconds=seconds,
            seed=seed,
            in_progress=settings.eruptions_in_progress,
            onsets_per_year=settings.eruption_onsets_per_year,
            episodes_per_day=settings.episodes_per_day,
            episode_median_s=settings.episode_median_h * 3600.0,
        )
    return draw_eruptions(
        catalog, seconds=seconds, seed=seed, eruptions_per_day=settings.eruptions_per_day
    )


def _opportunities(enc, col, sat_of, e_of, dets, board, eruptions, cloud, seconds, settings):
    """The overflights each satellite knows about in time, with planned and realized value."""
    by_e: dict[int, list[tuple[int, float, int, float, int]]] = {}
    for d in dets:
        by_e.setdefault(d[0], []).append(d)
    keep, t_dec, cues = [], [], []
    t_obs = col["t_obs"]
    for k in range(len(enc)):
        t = t_obs[k]
        if not (math.isfinite(t) and 0.0 <= t <= seconds) or col["sun_obs_deg"][k] < MIN_SUN_DEG:
            continue  # outside the period, or at night (an optical NFOV sees nothing)
        s, e = int(sat_of[k]), int(e_of[k])
        known, cue = math.inf, (s, math.inf)
        for _e, td, src, t_use, from_enc in by_e.get(e, []):
            if settings.cueing == "none":
                ok = from_enc == k
            elif settings.cueing == "self":
                ok = src == s
            elif settings.cueing == "cross":
                ok = src >= 0
            else:
                ok = True
            if not ok or td < t - settings.memory_s:
                continue
            when = board.heard(src if src >= 0 else -1, t_use, s)
            if when < known:
                known, cue = when, (src if src >= 0 else -1, t_use)
        if known <= t - PLAN_S:
            keep.append(k)
            t_dec.append(max(known, t - 5700.0))  # a satellite plans about one orbit ahead
            cues.append(cue)
    idx = np.asarray(keep, np.int64)
    planned = np.cos(np.radians(col["off_nadir"][idx]))
    e_idx = e_of[idx]
    visible = eruptions.active(e_idx, t_obs[idx]) & ~hidden(eruptions, cloud, e_idx, t_obs[idx])
    opp = Opportunities(
        sat_of[idx],
        e_idx,
        t_obs[idx],
        np.asarray(t_dec, np.float64).reshape(-1),
        planned,
        np.where(visible, planned, 0.0),
        np.asarray([c[0] for c in cues], np.int64),
        np.asarray([c[1] for c in cues], np.float64),
    )
    return opp, idx


class _Conflict:
    """Sensor conflict between two opportunities of one satellite, by the schedule stage
    (:func:`dyntarget.pipeline.schedule_feasible`)."""

    def __init__(self, opp: Opportunities, enc_of: np.ndarray, col: dict, agility: str) -> None:
        self.opp, self.enc_of, self.col, self.agility = opp, enc_of, col, agility
        self.cache: dict[tuple[int, int], bool] = {}

    def __call__(self, a: int, b: int) -> bool:
        key = (min(a, b), max(a, b))
        if key not in self.cache:
            self.cache[key] = not _both_fit(
                [int(self.enc_of[a]), int(self.enc_of[b])], self.col, self.agility
            )
        return self.cache[key]


def _both_fit(ks: list[int], col: dict, agility: str) -> bool:
    """Whether one satellite can take all of the overflights ``ks`` (one pass, one frame)."""
    from dyntarget.pipeline import Kinematics, schedule_feasible
    from dyntarget.schedule import OrbitGeometry
    from dyntarget.trajectory import Trajectory

    ref = min(ks, key=lambda k: col["t_ref"][k])
    geom = OrbitGeometry(
        altitude_m=float(col["altitude"][ref]),
        look_ahead_m=0.0,
        wfov_gsd_m=1.0,
        start_s=float(min(col["t_in"][k] + col["t_ref"][k] for k in ks) - col["t_ref"][ref]),
    )
    v = geom.ground_speed
    pts = []
    for k in ks:
        along = col["along"][k] + v * (col["t_ref"][k] - col["t_ref"][ref])
        pts.append([col["cross"][k], -along])
    traj = Trajectory(np.asarray(pts, np.float64), np.arange(len(ks)), "constellation")
    flown = schedule_feasible(traj, (1, 1), Kinematics(geom, agility))
    return len(flown.kept) == len(ks)


def _realize(opp, chosen, enc_of, col, names, catalog, eruptions, settings):
    """Observations of the chosen pointings: visible ones, duplicates worth nothing."""
    last: dict[int, float] = {}
    out, wasted, dups = [], 0, 0
    for i in chosen:
        if opp.value[i] <= 0:
            wasted += 1
            continue
        e, t = int(opp.eruption[i]), float(opp.t_obs[i])
        dup = t - last.get(e, -math.inf) < settings.dup_window_s
        if dup:
            dups += 1
        else:
            last[e] = t
        out.append(
            {
                "satellite": names[int(opp.sat[i])],
                "eruption": e,
                "volcano_number": int(catalog.number[eruptions.volcano[e]]),
                "time_s": t,
                "off_nadir_deg": float(col["off_nadir"][enc_of[i]]),
                "utility": 0.0 if dup else float(opp.value[i]),
                "duplicate": bool(dup),
            }
        )
    return out, wasted, dups


def _table(eruptions, catalog, first_det, observations) -> list[dict[str, Any]]:
    rows = []
    for e in range(len(eruptions)):
        obs = [o["time_s"] for o in observations if o["eruption"] == e and not o["duplicate"]]
        rows.append(
            {
                "eruption": e,
                "volcano_number": int(catalog.number[eruptions.volcano[e]]),
                "onset_s": float(eruptions.onset_s[e]),
                "end_s": float(eruptions.end_s[e]),
                "first_detection_s": first_det.get(e),
                "first_observation_s": min(obs) if obs else None,
                "observations": len(obs),
                "obs_times": sorted(obs),
            }
        )
    return rows


def _quantile(values: list[float], q: float) -> float | None:
    if not values:
        return None
    return round(float(np.quantile(np.asarray(values, np.float64), q)), 3)


def observations_after_detection(table: list[dict[str, Any]]) -> list[int]:
    """Each detected eruption's observations in the 6 h after its first detection.

    Parameters
    ----------
    table : list of dict
        :attr:`Day.table`: per eruption, ``first_detection_s`` (``None``: never detected)
        and ``obs_times`` (sorted seconds).

    Returns
    -------
    list of int
        One count per detected eruption, in table order (``summary.json``'s
        ``observations_per_eruption_6h`` is their mean).

    Examples
    --------
    >>> observations_after_detection([
    ...     {"first_detection_s": 100.0, "obs_times": [50.0, 200.0, 21700.0, 30000.0]},
    ...     {"first_detection_s": None, "obs_times": []}])
    [2]
    """
    return [
        sum(1 for t in r["obs_times"] if d <= t <= d + HOUR6)
        for r in table
        if (d := r["first_detection_s"]) is not None
    ]


def revisit_gaps(table: list[dict[str, Any]]) -> list[float]:
    """Every gap between successive observations of one eruption, seconds.

    Parameters
    ----------
    table : list of dict
        :attr:`Day.table`: per eruption, ``obs_times`` (sorted seconds).

    Returns
    -------
    list of float
        The gaps, eruption by eruption (``summary.json``'s ``median_revisit_s`` is their
        median).

    Examples
    --------
    >>> revisit_gaps([{"obs_times": [0.0, 600.0, 4200.0]}, {"obs_times": [10.0]}])
    [600.0, 3600.0]
    """
    return [b - a for r in table for a, b in itertools.pairwise(r["obs_times"])]


def _summary(n_sats, eruptions, first_det, observations, table, seconds) -> dict[str, Any]:
    # onset-based figures: eruptions that start in the period (one in progress at the
    # start has an onset before it, unknown to any sensor: excluded)
    delays = [
        r["first_observation_s"] - r["onset_s"]
        for r in table
        if r["first_observation_s"] is not None and r["onset_s"] >= 0.0
    ]
    per6 = observations_after_detection(table)
    gaps = revisit_gaps(table)
    out = {
        "satellites": n_sats,
        "eruptions": len(eruptions),
        "eruptions_observed": sum(1 for r in table if r["observations"]),
        "eruptions_detected": len(first_det),
        "observed_within_6h": sum(1 for d in delays if d <= HOUR6),
        "median_onset_to_first_obs_s": _quantile(delays, 0.5),
        "p90_onset_to_first_obs_s": _quantile(delays, 0.9),
        "observations_per_eruption_6h": round(statistics.fmean(per6), 6) if per6 else None,
        "median_revisit_s": _quantile(gaps, 0.5),
        "utility": round(math.fsum(o["utility"] for o in observations), 6),
        "observations": len(observations),
    }
    if eruptions.episodic:
        out.update(_episode_summary(eruptions, table, seconds))
    return out


def _episode_summary(eruptions: Eruptions, table, seconds: float) -> dict[str, Any]:
    """Figures of the two-level model: eruptions started in the period, and per episode
    (:func:`episode_delays`)."""
    started, ep_delays = episode_delays(eruptions, table, seconds)
    return {
        "eruptions_in_progress_at_start": int((eruptions.onset_s < 0.0).sum()),
        "eruptions_started": int((eruptions.onset_s >= 0.0).sum()),
        "episodes_started": started,
        "episodes_observed": len(ep_delays),
        "episodes_observed_within_6h": sum(1 for d in ep_delays if d <= HOUR6),
        "median_episode_onset_to_first_obs_s": _quantile(ep_delays, 0.5),
    }


def episode_delays(
    eruptions: Eruptions, table: list[dict[str, Any]], seconds: float
) -> tuple[int, list[float]]:
    """The plume episodes that start in the period, and the delay to each observed one.

    An episode's delay is from its onset to the first observation of its eruption at or
    after that onset and before the episode's end (an observation is taken only while a
    plume is there); only episodes that start in the period (``0 <= onset < seconds``) count.

    Parameters
    ----------
    eruptions : Eruptions
        The two-level model's eruptions (with their episodes).
    table : list of dict
        :attr:`Day.table`: per eruption, ``obs_times`` (sorted seconds).
    seconds : float
        The period's length, seconds.

    Returns
    -------
    (int, list of float)
        The episodes started, and the delays (seconds) of those observed, in episode order.

    Examples
    --------
    Two episodes of one eruption, the first begun before the period: the second is seen
    100 s after its onset.

    >>> one = np.array
    >>> e = Eruptions(one([0]), one([-9e5]), one([9e5]), one([10.0]), one([90.0]), one([50.0]),
    ...     one([0.1]), one([600.0]), one([5000.0]), one([3.0]),
    ...     one([0, 0]), one([-100.0, 500.0]), one([200.0, 800.0]))
    >>> episode_delays(e, [{"obs_times": [150.0, 600.0]}], 3600.0)
    (1, [100.0])
    """
    assert eruptions.episode_onset_s is not None and eruptions.episode_end_s is not None
    assert eruptions.episode_eruption is not None
    delays = []
    started = 0
    for e, t0, t1 in zip(
        eruptions.episode_eruption.tolist(),
        eruptions.episode_onset_s.tolist(),
        eruptions.episode_end_s.tolist(),
        strict=True,
    ):
        if not 0.0 <= t0 < seconds:
            continue
        started += 1
        seen = [t for t in table[e]["obs_times"] if t0 <= t < t1]
        if seen:
            delays.append(seen[0] - t0)
    return started, delays


def settings_dict(settings: Settings) -> dict[str, Any]:
    """The settings as a JSON-able dict (recorded in ``summary.json``).

    Parameters
    ----------
    settings : Settings
        The settings.

    Returns
    -------
    dict
        Field -> value.

    Examples
    --------
    >>> settings_dict(Settings(cueing="none"))["cueing"]
    'none'
    """
    return asdict(settings)


__all__ = [
    "ALLOCATIONS",
    "CLUSTER_S",
    "CUEING",
    "GEO_IMAGERS",
    "RELAYS",
    "Day",
    "Settings",
    "episode_delays",
    "observations_after_detection",
    "revisit_gaps",
    "run_day",
]
