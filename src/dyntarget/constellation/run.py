"""Run a constellation-day end to end and write its outputs; sweeps of many days on Dask.

Outputs of :func:`write_outputs` (``--out DIR``): ``observations.csv``, ``eruptions.csv``,
``summary.json`` (the metrics and the options that produced them, the scheduler aside),
``constellation.png`` and ``constellation.html``. The per-satellite tasks' results are
kept in ``DIR/parts/`` (a rerun resumes). Every file is written atomically, after the
whole simulation has run.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.constellation.orbits import (
    Satellite,
    parse_walker,
    read_tle,
    sso_inclination_deg,
    utc,
    walker,
)
from dyntarget.constellation.simulate import Day, Settings, run_day, settings_dict
from dyntarget.constellation.world import Catalog
from dyntarget.errors import InvalidParameterError
from dyntarget.io.atomic import write_text

OBS_COLUMNS = ("satellite", "volcano_number", "time_utc", "off_nadir_deg", "utility", "duplicate")
ERUPTION_COLUMNS = (
    "volcano_number",
    "onset_utc",
    "end_utc",
    "first_detection_utc",
    "first_observation_utc",
    "observations",
)


def inclination(text: str | float, altitude_km: float) -> float:
    """``--inclination-deg``: a number of degrees, or ``sso`` (sun-synchronous at the altitude).

    Parameters
    ----------
    text : str or float
        Degrees or ``"sso"``.
    altitude_km : float
        Altitude, km.

    Returns
    -------
    float
        Degrees.

    Examples
    --------
    >>> inclination("53", 550.0), round(inclination("sso", 500.0), 2)
    (53.0, 97.4)
    """
    if isinstance(text, str) and text.strip().lower() == "sso":
        return sso_inclination_deg(altitude_km)
    try:
        return float(text)
    except ValueError:
        raise InvalidParameterError(
            f"--inclination-deg: expected degrees or sso, got {text!r}"
        ) from None


def constellation(
    *,
    tle: str | None,
    walker_tpf: str | None,
    altitude_km: float,
    inclination_deg: str | float,
    start: str,
) -> list[Satellite]:
    """The satellites of ``--tle FILE`` or ``--walker T/P/F``.

    Parameters
    ----------
    tle : str or None
        TLE file.
    walker_tpf : str or None
        ``T/P/F``.
    altitude_km : float
        Walker altitude, km.
    inclination_deg : str or float
        Walker inclination (degrees or ``sso``).
    start : str
        ISO start (TLE epochs are checked against it; Walker elements are set at it).

    Returns
    -------
    list of Satellite
        The constellation.

    Examples
    --------
    >>> sats = constellation(tle=None, walker_tpf="4/2/1", altitude_km=500, inclination_deg="sso",
    ...                      start="2026-06-01T00:00:00Z")
    >>> [s.name for s in sats]
    ['W1-1', 'W1-2', 'W2-1', 'W2-2']
    """
    when = utc(start)
    if (tle is None) == (walker_tpf is None):
        raise InvalidParameterError(
            "constellation: give exactly one of --tle FILE and --walker T/P/F"
        )
    if tle is not None:
        return read_tle(tle, start=when)
    assert walker_tpf is not None
    t, p, f = parse_walker(walker_tpf)
    return walker(
        t,
        p,
        f,
        altitude_km=altitude_km,
        inclination_deg=inclination(inclination_deg, altitude_km),
        epoch=when,
    )


def _csv(rows: list[list[Any]], header: tuple[str, ...]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def write_outputs(
    day: Day,
    out: str | Path,
    *,
    start: str,
    options: dict[str, Any],
    picture: bool = True,
    html: bool = True,
) -> list[Path]:
    """Write the day's files into ``out``.

    Parameters
    ----------
    day : Day
        The simulated day.
    out : str or pathlib.Path
        Output folder (exists).
    start : str
        ISO start.
    options : dict
        The options that produced it (recorded in ``summary.json``).
    picture, html : bool
        Write ``constellation.png`` / ``constellation.html``.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    from dyntarget.io.acquisition import iso_utc

    t0 = utc(start)
    out = Path(out)

    def when(s: float | None) -> str:
        return "" if s is None else iso_utc(t0, s)

    obs = [
        [
            o["satellite"],
            o["volcano_number"],
            when(o["time_s"]),
            f"{o['off_nadir_deg']:.3f}",
            f"{o['utility']:.6f}",
            int(o["duplicate"]),
        ]
        for o in day.observations
    ]
    er = [
        [
            r["volcano_number"],
            when(r["onset_s"]),
            when(r["end_s"]),
            when(r["first_detection_s"]),
            when(r["first_observation_s"]),
            r["observations"],
        ]
        for r in day.table
    ]
    summary = {**day.summary, "options": options}
    written = [
        write_text(out / "observations.csv", _csv(obs, OBS_COLUMNS)),
        write_text(out / "eruptions.csv", _csv(er, ERUPTION_COLUMNS)),
        write_text(out / "summary.json", json.dumps(summary, indent=2, sort_keys=True) + "\n"),
    ]
    if picture:
        from dyntarget.constellation.draw import world_map

        written.append(world_map(day, out / "constellation.png"))
    if html:
        from dyntarget.constellation.draw import html_view

        written.append(html_view(day, out / "constellation.html", start=start))
    return written


def catalog_json(catalog: Catalog) -> dict[str, Any]:
    """A catalog as JSON-able lists (a sweep's shared input).

    Parameters
    ----------
    catalog : Catalog
        The catalog.

    Returns
    -------
    dict
        Field -> list.

    Examples
    --------
    >>> from dyntarget.constellation.world import parse_catalog
    >>> cat = parse_catalog("volcano_number,latitude,longitude,elevation_m,last_known_eruption\\n1,0,0,0,Unknown\\n")
    >>> catalog_json(cat)["last_year"]
    [None]
    """
    return {
        "number": catalog.number.tolist(),
        "name": list(catalog.name),
        "lat": catalog.lat.tolist(),
        "lon": catalog.lon.tolist(),
        "elevation_m": catalog.elevation_m.tolist(),
        "last_year": [None if not np.isfinite(y) else y for y in catalog.last_year.tolist()],
    }


def _catalog_from(doc: dict[str, Any]) -> Catalog:
    return Catalog(
        np.asarray(doc["number"], np.int64),
        tuple(doc["name"]),
        np.asarray(doc["lat"]),
        np.asarray(doc["lon"]),
        np.asarray(doc["elevation_m"]),
        np.asarray([np.nan if y is None else y for y in doc["last_year"]], np.float64),
    )


def config_day(config: dict[str, Any], catalog: Catalog) -> tuple[Day, Settings]:
    """The constellation-day one sweep configuration names, run here.

    Parameters
    ----------
    config : dict
        ``walker``, ``altitude_km``, ``inclination_deg``, ``start``, ``hours``, ``seed`` and
        :class:`~dyntarget.constellation.simulate.Settings` fields.
    catalog : Catalog
        The volcanoes.

    Returns
    -------
    (Day, Settings)
        The day (no ground tracks kept) and the settings it ran with.
    """
    cfg = dict(config)
    sats = constellation(
        tle=None,
        walker_tpf=cfg.pop("walker"),
        altitude_km=cfg.pop("altitude_km"),
        inclination_deg=cfg.pop("inclination_deg"),
        start=cfg["start"],
    )
    start, hours, seed = cfg.pop("start"), cfg.pop("hours"), cfg.pop("seed")
    settings = Settings(**cfg)
    day = run_day(
        sats, catalog, start=start, hours=hours, seed=seed, settings=settings, tracks=False
    )
    return day, settings


def sweep_point(config: dict[str, Any], *, catalog: dict[str, Any]) -> dict[str, Any]:
    """One configuration of a sweep, run serially here: its ``summary.json`` content.

    Parameters
    ----------
    config : dict
        As :func:`config_day`'s.
    catalog : dict
        :func:`catalog_json` of the volcanoes.

    Returns
    -------
    dict
        The summary, with the configuration under ``options``.
    """
    day, settings = config_day(config, _catalog_from(catalog))
    return {**day.summary, "options": {**config, **settings_dict(settings)}}


def sweep(
    configs: list[dict[str, Any]],
    catalog: Catalog,
    *,
    scheduler: str | None = None,
    parts: Path | None = None,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Many constellation-days (per-run fan-out), resumable, here or on Dask.

    Parameters
    ----------
    configs : list of dict
        Configurations (:func:`sweep_point`).
    catalog : Catalog
        The volcanoes.
    scheduler : str or None
        ``None``, ``local``, ``processes`` or a scheduler address.
    parts : pathlib.Path or None
        Folder of finished runs.
    progress : bool
        Progress bar.

    Returns
    -------
    list of dict
        Summaries, in ``configs`` order.
    """
    from dyntarget.evaluate.distributed import run_tasks, task_key

    doc = catalog_json(catalog)
    return run_tasks(
        sweep_point,
        configs,
        key=lambda c: task_key("constellation-sweep", 1, c, doc),
        parts=parts,
        scheduler=scheduler,
        shared={"catalog": doc},
        progress=progress,
        desc="constellations",
    )


def options_of(args: Any) -> dict[str, Any]:
    """The options recorded in ``summary.json`` (everything but the scheduler and outputs).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``dyntarget constellation`` arguments.

    Returns
    -------
    dict
        Option -> value.

    Examples
    --------
    >>> import argparse
    >>> options_of(argparse.Namespace(seed=1, scheduler="local", out="o"))
    {'seed': 1}
    """
    skip = {"scheduler", "out", "func", "debug", "command", "quiet", "no_picture", "no_html"}
    return {k: v for k, v in sorted(vars(args).items()) if k not in skip}
