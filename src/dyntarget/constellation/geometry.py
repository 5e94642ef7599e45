"""Overflights: when each satellite can see each erupting volcano, and what its look-ahead sees.

Per satellite (one Dask task per chunk of satellites, :func:`overflights`), on a time
grid of ``step_s``: every local minimum of the satellite's angular distance to a
volcano within reach of its field of regard is an *overflight*. At that grid time
``t_ref`` the volcano's along- and cross-track ground distances from nadir are taken
in the ground track's frame (Earth-fixed positions: Earth rotation included) and
:func:`dyntarget.schedule.visibility_windows` gives the window ``[t_in, t_out]`` the
NFOV field of regard holds it, from the same kinematics and agility preset the pass
scheduler uses. The observation is timed through the pipeline's scheduler
(:func:`dyntarget.pipeline.schedule_on_prediction` without a prediction, which is
:func:`dyntarget.schedule.make_feasible`; :func:`first_pointing_s`) as the pass loop (``fly``) times its pointings: the sensor
starts at nadir when the plan is ready (:data:`PLAN_S` after the look-ahead passes over
the volcano, or earlier when cued) and takes the pointing as soon as the kinematics
allow, which is when the volcano enters the field of regard (its forward edge, about
30° off nadir with the default presets); its off-nadir angle is recomputed exactly
there (SGP4 position, WGS 84 geodetic nadir, the summit at its catalog elevation) and
its utility is ``cos(off-nadir)``. (Until the pixel-level comparison,
``benchmarks/constellation.py --parts fidelity``, showed that ``fly`` takes its first
pointing on a plume there, the observation was placed at the end of the window, nadir's
along-track crossing, with the smallest off-nadir angle.)

Both sensors are optical: each row carries the Sun's elevation over the volcano when
the look-ahead passes and at the observation (the simulation uses neither below
:data:`MIN_SUN_DEG`).

The look-ahead images a swath ``swath_m`` wide centred ``look_ahead_m`` ahead of nadir:
it passes over the volcano's along-track position at ``t_ref + (along - look_ahead) / v``
and sees the plume if the plume (a segment from the vent downwind, of the model's length
and half-width at that time) reaches into the swath.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dyntarget.constellation.orbits import (
    WGS84_A_M,
    Satellite,
    geodetic_to_ecef,
    off_nadir_deg,
    propagate,
    utc,
)
from dyntarget.constellation.world import Eruptions
from dyntarget.schedule import (
    EARTH_RADIUS_M,
    Agility,
    OrbitGeometry,
    get_agility,
    visibility_windows,
)

STATIONS: tuple[tuple[str, float, float], ...] = (
    ("Svalbard", 78.23, 15.39),
    ("Kiruna", 67.86, 20.96),
    ("Fairbanks", 64.86, -147.85),
    ("Wallops", 37.94, -75.46),
    ("Hawaii", 19.01, -155.66),
    ("Santiago", -33.15, -70.67),
    ("Hartebeesthoek", -25.89, 27.69),
    ("McMurdo", -77.85, 166.67),
)
"""Ground stations of the ``ground`` relay: name, latitude, longitude (degrees)."""
MIN_ELEVATION_DEG = 5.0
"""A satellite is in contact with a station above this elevation."""
PLAN_S = 20.0
"""Seconds from a detection to a plan the NFOV can fly (the observation needs the eruption
known this long before it)."""
MIN_SUN_DEG = 5.0
"""Lowest Sun elevation over a volcano at which the look-ahead detects and the NFOV observes."""
ENC_FIELDS = (
    "eruption",
    "t_ref",
    "t_in",
    "t_out",
    "along",
    "cross",
    "t_look",
    "look_hit",
    "t_obs",
    "off_nadir",
    "altitude",
    "sun_look_deg",
    "sun_obs_deg",
)
"""Columns of an overflight row (:func:`overflights`)."""


def reach_angle_rad(altitude_m: float, field_of_regard_deg: float) -> float:
    """Earth central angle from nadir to the edge of the field of regard (spherical Earth).

    Parameters
    ----------
    altitude_m : float
        Altitude, metres.
    field_of_regard_deg : float
        Largest off-nadir angle, degrees.

    Returns
    -------
    float
        Radians.

    Examples
    --------
    >>> round(reach_angle_rad(500e3, 30.0) * 6371.0, 0)  # ground range, km
    293.0
    """
    eta = math.radians(field_of_regard_deg)
    r = EARTH_RADIUS_M
    return math.asin(min(1.0, (r + altitude_m) / r * math.sin(eta))) - eta


def first_pointing_s(
    altitude_m: float, agility: Agility, along_m: float, cross_m: float, ready_s: float
) -> float:
    """When the NFOV takes one pointing at a ground point, by the pipeline's scheduler.

    The point lies ``along_m`` ahead of nadir and ``cross_m`` across track at ``t = 0``;
    the sensor starts at nadir at ``ready_s`` (the plan is ready) and takes the pointing
    as soon as the kinematics allow, as the pass loop does.

    Parameters
    ----------
    altitude_m : float
        Orbit altitude, metres.
    agility : dyntarget.schedule.Agility
        The NFOV's agility preset.
    along_m, cross_m : float
        Ground distances from nadir at ``t = 0``, metres.
    ready_s : float
        When the plan is ready, seconds.

    Returns
    -------
    float
        When the observation starts, seconds (NaN: it cannot be taken).

    Examples
    --------
    >>> from dyntarget.schedule import get_agility
    >>> fast = get_agility("fast")  # a point under the track 500 km ahead, plan ready at once:
    >>> # it enters the 30 deg field of regard 292 km ahead of nadir: (500 - 292) / 7.06 km/s
    >>> round(first_pointing_s(500e3, fast, 500e3, 0.0, 0.0), 1)
    29.4
    >>> first_pointing_s(500e3, fast, 500e3, 400e3, 0.0)  # beyond the field of regard
    nan
    """
    from dyntarget.pipeline import schedule_on_prediction
    from dyntarget.trajectory import Trajectory

    geometry = OrbitGeometry(
        altitude_m=altitude_m, look_ahead_m=0.0, wfov_gsd_m=1.0, start_s=ready_s
    )
    # a 1 x 1 px "image" with 1 m pixels: pixel (x, y) lies -y m ahead, x m across
    traj = Trajectory(np.array([[cross_m, -along_m]]), np.zeros(1), "constellation")
    flown = schedule_on_prediction(traj, (1, 1), geometry, agility, None)  # no prediction
    return float(flown.times[0]) if len(flown.kept) else math.nan


def overflights(task: dict[str, Any], **shared: Any) -> list[dict[str, Any]]:
    """Every overflight of every erupting volcano by the task's satellites (a Dask task).

    Parameters
    ----------
    task : dict
        ``satellites``: list of ``[name, line1, line2, elements]``.
    **shared
        ``start`` (ISO), ``seconds`` (period), ``settings`` (dict), ``eruptions``
        (:meth:`Eruptions.to_json`), ``volcano`` (``[lat, lon, elevation]`` per eruption),
        ``tracks`` (bool: return ground tracks).

    Returns
    -------
    list of dict
        Per satellite: ``name``, ``rows`` (lists in :data:`ENC_FIELDS` order),
        ``contacts`` (grid times in contact with a ground station), ``track``
        (``[lon, lat]`` every minute, or empty).
    """
    settings = shared["settings"]
    start = utc(shared["start"])
    seconds = float(shared["seconds"])
    step = float(settings["step_s"])
    grid = np.arange(0.0, seconds + step, step)
    sats = [Satellite(n, l1, l2, tuple(el)) for n, l1, l2, el in task["satellites"]]
    r, v = propagate(sats, start, grid)
    erupt = Eruptions.from_json(shared["eruptions"])
    vol = np.asarray(shared["volcano"], np.float64).reshape(-1, 3)
    summit = geodetic_to_ecef(vol[:, 0], vol[:, 1], vol[:, 2])
    unit = summit / np.linalg.norm(summit, axis=1, keepdims=True)
    agility = get_agility(settings["agility"])
    stations = geodetic_to_ecef(
        np.array([s[1] for s in STATIONS]), np.array([s[2] for s in STATIONS]), 0.0
    )
    st_up = stations / np.linalg.norm(stations, axis=1, keepdims=True)
    out = []
    for i, sat in enumerate(sats):
        rows = _rows(sat, start, grid, r[i], v[i], erupt, summit, unit, vol, agility, settings)
        rel = r[i][:, None, :] - stations[None, :, :]
        sin_el = np.sum(rel * st_up[None], axis=-1) / np.linalg.norm(rel, axis=-1)
        contact = grid[(sin_el >= math.sin(math.radians(MIN_ELEVATION_DEG))).any(axis=1)]
        track: list[list[float]] = []
        if shared.get("tracks"):
            from dyntarget.constellation.orbits import ecef_to_geodetic

            every = max(1, round(60.0 / step))
            lat, lon, _ = ecef_to_geodetic(r[i][::every])
            track = np.round(np.stack([lon, lat], axis=1), 3).tolist()
        out.append({"name": sat.name, "rows": rows, "contacts": contact.tolist(), "track": track})
    return out


def _sun_elevation_deg(start, t: np.ndarray, vol: np.ndarray) -> np.ndarray:
    """Sun elevation over each volcano (geodetic horizon) at times ``t``, degrees."""
    from dyntarget.constellation.orbits import geodetic_up, sun_direction

    up = geodetic_up(vol[:, 0], vol[:, 1])
    sin_el = np.sum(sun_direction(start, t) * up, axis=1)
    return np.round(np.degrees(np.arcsin(np.clip(sin_el, -1.0, 1.0))), 6)


def _rows(
    sat, start, grid, r, v, erupt, summit, unit, vol, agility, settings
) -> list[list[float | None]]:
    """Overflight rows of one satellite (see :func:`overflights`)."""
    if not len(erupt):
        return []
    radius = np.linalg.norm(r, axis=1)
    nadir = r / radius[:, None]
    alt = float(np.round(np.median(radius) - WGS84_A_M, -3))
    alt = min(max(alt, 100e3), 2000e3)
    fov = float(agility.field_of_regard_deg)
    step = float(grid[1] - grid[0]) if len(grid) > 1 else 1.0
    speed = float(np.median(np.linalg.norm(v, axis=1)))
    reach = reach_angle_rad(alt, fov) + speed * step / EARTH_RADIUS_M
    # the volcanoes of erupting episodes only (by position; an episode row per eruption)
    cosd = nadir @ unit.T  # (n_t, n_e)
    near = cosd >= math.cos(reach)
    prev = np.vstack([np.full((1, cosd.shape[1]), -2.0), cosd[:-1]])
    nxt = np.vstack([cosd[1:], np.full((1, cosd.shape[1]), -2.0)])
    k_idx, e_idx = np.nonzero(near & (cosd >= prev) & (cosd > nxt))
    keep = grid[k_idx] >= erupt.onset_s[e_idx] - 600.0
    k_idx, e_idx = k_idx[keep], e_idx[keep]
    if not len(k_idx):
        return []
    n = nadir[k_idx]
    vel = v[k_idx]
    a_hat = vel - np.sum(vel * n, axis=1, keepdims=True) * n
    a_hat /= np.linalg.norm(a_hat, axis=1, keepdims=True)
    c_hat = np.cross(n, a_hat)
    p = unit[e_idx]
    along = EARTH_RADIUS_M * np.arctan2(np.sum(p * a_hat, 1), np.sum(p * n, 1))
    cross = EARTH_RADIUS_M * np.arcsin(np.clip(np.sum(p * c_hat, 1), -1.0, 1.0))
    geometry = OrbitGeometry(altitude_m=alt, look_ahead_m=0.0)
    t_in, t_out = visibility_windows(geometry, agility, along, cross)
    gs = geometry.ground_speed
    t_ref = grid[k_idx]
    t_look = t_ref + (along - float(settings["look_ahead_m"])) / gs
    # the plume in the swath at t_look: a segment from the vent along the drift
    lat, lon = np.radians(vol[e_idx, 0]), np.radians(vol[e_idx, 1])
    east = np.stack([-np.sin(lon), np.cos(lon), np.zeros_like(lon)], 1)
    north = np.stack([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)], 1)
    az = np.radians(erupt.drift_deg[e_idx])
    drift = np.sin(az)[:, None] * east + np.cos(az)[:, None] * north
    length = erupt.length_m(e_idx, t_look)
    half = erupt.half_width_m(e_idx, t_look)
    far = cross + length * np.sum(drift * c_hat, 1)
    lo, hi = np.minimum(cross, far) - half, np.maximum(cross, far) + half
    sw = float(settings["swath_m"]) / 2.0
    look_hit = (lo <= sw) & (hi >= -sw) & erupt.active(e_idx, t_look)
    visible = t_in <= t_out
    t_first = np.full(len(e_idx), np.nan)
    for j in np.flatnonzero(visible).tolist():  # scheduled as fly schedules its pointings
        t_first[j] = first_pointing_s(
            alt, agility, float(along[j]), float(cross[j]), float(t_look[j] - t_ref[j]) + PLAN_S
        )
    visible &= np.isfinite(t_first)
    t_obs = t_ref + t_first
    t_obs_eval = np.where(visible, t_obs, t_ref)
    rr, _ = propagate([sat], start, t_obs_eval)
    off = off_nadir_deg(rr[0], summit[e_idx])
    rows = np.stack(
        [
            e_idx.astype(np.float64),
            t_ref,
            np.where(visible, t_in, np.nan),
            np.where(visible, t_out, np.nan),
            along,
            cross,
            t_look,
            look_hit.astype(np.float64),
            np.where(visible, t_obs, np.nan),
            off,
            np.full(len(e_idx), alt),
            _sun_elevation_deg(start, t_look, vol[e_idx]),
            _sun_elevation_deg(start, t_obs_eval, vol[e_idx]),
        ],
        axis=1,
    )
    order = np.lexsort((e_idx, t_ref))
    return [[None if not math.isfinite(x) else x for x in row] for row in rows[order].tolist()]
