"""Two fidelities, one physics: overflights of a constellation-day, ready to fly at pixel level.

The target level (:mod:`dyntarget.constellation.geometry`) turns an overflight into a
visibility window (:func:`dyntarget.schedule.visibility_windows`) and one pinpoint
observation timed by :func:`dyntarget.schedule.make_feasible`, worth ``cos(off-nadir)``.
The pixel level (``fly``) flies a strip of look-ahead frames and schedules its NFOV
pointings on the plume's pixels with the same kinematics. :func:`overflight_cases` draws
overflights of a simulated day and returns, for each, what the target level says
(observation time, off-nadir angle, utility) and what a pixel-level world of the same
overflight needs: the vent's place in the ground track's frame (along and across track,
``fly``'s sign: positive to the right of the flight direction), the plume's drift
relative to the flight direction and its parameters (those
:func:`dyntarget.synth.dynamic.sample_world` gave the eruption) and age.
``benchmarks/constellation.py --parts fidelity`` builds each world with ``synth``, flies
it with the truth as classifier and compares (``tests/constellation/test_fidelity.py``).
This module imports nothing of ``fly`` (a sibling layer).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dyntarget.constellation.geometry import ENC_FIELDS, overflights
from dyntarget.constellation.orbits import geodetic_to_ecef, propagate, utc, walker
from dyntarget.constellation.world import Catalog, draw_eruptions

START = "2026-06-01T00:00:00Z"


def overflight_cases(
    catalog: Catalog,
    n: int,
    *,
    walker_tpf: tuple[int, int, int] = (20, 5, 1),
    altitude_km: float = 500.0,
    inclination_deg: float = 97.4,
    hours: float = 24.0,
    seed: int = 0,
    agility: str = "fast",
    eruptions_per_day: float = 40.0,
) -> list[dict[str, Any]]:
    """``n`` overflights of erupting volcanoes in one simulated day, spread over cross-track offsets.

    Every overflight whose summit comes inside the field of regard while its plume is
    active is a candidate (day or night, cloud or not: the comparison is of the
    kinematics); ``n`` of them are taken at evenly spaced ranks of ``|cross|``.

    Parameters
    ----------
    catalog : Catalog
        The volcanoes.
    n : int
        Overflights wanted (fewer if the day has fewer).
    walker_tpf : tuple of int
        The Walker ``T/P/F`` constellation.
    altitude_km, inclination_deg : float
        Its orbits.
    hours : float
        Length of the day simulated.
    seed : int
        Seed of the eruptions.
    agility : str
        NFOV agility preset.
    eruptions_per_day : float
        Eruption rate.

    Returns
    -------
    list of dict
        Per overflight: ``volcano_number``, ``altitude_m``, ``along_m`` and ``cross_m``
        (the summit from nadir at ``t_ref``, ``fly``'s sign), ``t_in``, ``t_out`` and
        ``t_obs`` (seconds after ``t_ref``), ``off_nadir_deg`` and ``utility`` (the target
        level's), ``off_nadir_window_end_deg`` (at the end of the window, where the target
        level placed the observation before), ``drift_rel_deg`` (where the plume drifts
        to, clockwise from the flight direction), ``wind_mps``, ``source_m``,
        ``turbulence``, ``fade_s``, ``optical_depth`` and ``age_s`` (at ``t_obs``).

    Examples
    --------
    >>> from dyntarget.constellation.world import parse_catalog
    >>> cat = parse_catalog("volcano_number,latitude,longitude,elevation_m,last_known_eruption\\n"
    ...                     "1,19.4,-155.3,1222,2025 CE\\n")
    >>> cases = overflight_cases(cat, 3, eruptions_per_day=20.0)
    >>> len(cases), all(abs(c["cross_m"]) < 300e3 for c in cases)
    (3, True)
    """
    start = utc(START)
    sats = walker(
        *walker_tpf, altitude_km=altitude_km, inclination_deg=inclination_deg, epoch=start
    )
    seconds = hours * 3600.0
    er = draw_eruptions(catalog, seconds=seconds, seed=seed, eruptions_per_day=eruptions_per_day)
    vol = np.stack(
        [catalog.lat[er.volcano], catalog.lon[er.volcano], catalog.elevation_m[er.volcano]], 1
    )
    settings = {"step_s": 20.0, "agility": agility, "look_ahead_m": 500e3, "swath_m": 30e3}
    res = overflights(
        {"satellites": [[s.name, s.line1, s.line2, list(s.elements)] for s in sats]},
        start=START,
        seconds=seconds,
        eruptions=er.to_json(),
        volcano=vol.tolist(),
        settings=settings,
        tracks=False,
    )
    found = []
    for i, sat_rows in enumerate(res):
        for raw in sat_rows["rows"]:
            row = dict(zip(ENC_FIELDS, raw, strict=True))
            e = int(row["eruption"])
            if row["t_obs"] is None or not er.active(np.array([e]), np.array([row["t_obs"]]))[0]:
                continue
            found.append((abs(row["cross"]), i, row))
    found.sort(key=lambda x: (x[0], x[1], x[2]["t_ref"]))
    if not found or n <= 0:
        return []
    picks = sorted({round(k * (len(found) - 1) / max(1, n - 1)) for k in range(n)})
    return [_case(sats[found[k][1]], start, found[k][2], er, vol, catalog) for k in picks]


def _case(sat, start, row, er, vol, catalog) -> dict[str, Any]:
    e = int(row["eruption"])
    t_ref, t_obs = float(row["t_ref"]), float(row["t_obs"])
    r, v = propagate([sat], start, np.array([t_ref, t_ref + row["t_out"]]))
    lat, lon = math.radians(vol[e, 0]), math.radians(vol[e, 1])
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    north = np.array(
        [-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)]
    )
    heading = math.degrees(math.atan2(float(v[0, 0] @ east), float(v[0, 0] @ north)))
    summit = geodetic_to_ecef(vol[e : e + 1, 0], vol[e : e + 1, 1], vol[e : e + 1, 2])
    from dyntarget.constellation.orbits import off_nadir_deg

    end_deg = float(off_nadir_deg(r[0, 1:], summit)[0])
    return {
        "volcano_number": int(catalog.number[er.volcano[e]]),
        "altitude_m": float(row["altitude"]),
        "along_m": float(row["along"]),
        "cross_m": -float(row["cross"]),  # geometry's cross is positive to the left
        "t_in": float(row["t_in"]),
        "t_out": float(row["t_out"]),
        "t_obs": t_obs - t_ref,
        "off_nadir_deg": float(row["off_nadir"]),
        "utility": math.cos(math.radians(float(row["off_nadir"]))),
        "off_nadir_window_end_deg": end_deg,
        "drift_rel_deg": (float(er.drift_deg[e]) - heading) % 360.0,
        "wind_mps": float(er.wind_mps[e]),
        "source_m": float(er.source_m[e]),
        "turbulence": float(er.turbulence[e]),
        "fade_s": float(er.fade_s[e]),
        "optical_depth": float(er.optical_depth[e]),
        "age_s": t_obs - float(er.onset_s[e]),
    }
