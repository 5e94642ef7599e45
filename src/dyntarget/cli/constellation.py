"""``dyntarget constellation``: many satellites, one shared picture of the world's volcanoes."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, log, writes

HOURS = o.float_range(0, 720, "a number of hours", lo_open=True)
"""``--hours``: a simulated period of (0, 720] hours (argparse type)."""


@writes(dirs=("out",))
def cmd_constellation(args: argparse.Namespace) -> int:
    from dyntarget.constellation.run import constellation, options_of, write_outputs
    from dyntarget.constellation.simulate import Settings, run_day
    from dyntarget.constellation.world import read_catalog

    settings = Settings(
        cueing=args.cueing,
        allocation=args.allocation,
        relay=args.relay,
        agility=args.agility,
        swath_km=args.swath_km,
        look_ahead_km=args.look_ahead_km,
        eruption_model=args.eruption_model,
        **model_options(args),
    )
    sats = constellation(
        tle=args.tle,
        walker_tpf=args.walker,
        altitude_km=args.altitude_km,
        inclination_deg=args.inclination_deg,
        start=args.start,
    )
    catalog = read_catalog(args.volcanoes)
    day = run_day(
        sats,
        catalog,
        start=args.start,
        hours=args.hours,
        seed=args.seed,
        settings=settings,
        scheduler=args.scheduler,
        parts=Path(args.out) / "parts",
        progress=not args.quiet,
    )
    files = write_outputs(
        day,
        args.out,
        start=args.start,
        options=options_of(args),
        picture=not args.no_picture,
        html=not args.no_html,
    )
    s = day.summary
    log(
        f"{s['satellites']} satellites, {s['eruptions']} eruptions: {s['eruptions_observed']} "
        f"observed ({s['observed_within_6h']} within 6 h of onset), {s['observations']} observations"
    )
    for f in files:
        print(f)
    return EXIT_OK


MODEL_OPTIONS = {
    "episodes": ("eruptions_per_day",),
    "eruptions": (
        "eruptions_in_progress",
        "eruption_onsets_per_year",
        "episodes_per_day",
        "episode_median_h",
    ),
}
"""The options of each ``--eruption-model`` (given with the other model: refused)."""


def model_options(args: argparse.Namespace) -> dict[str, Any]:
    """The eruption-model options given, refusing those of the model not chosen.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``dyntarget constellation`` arguments.

    Returns
    -------
    dict
        ``Settings`` field -> value, for the options given.

    Examples
    --------
    >>> ns = argparse.Namespace(eruption_model="eruptions", eruptions_per_day=None,
    ...     eruptions_in_progress=30.0, eruption_onsets_per_year=None, episodes_per_day=None,
    ...     episode_median_h=None)
    >>> model_options(ns)
    {'eruptions_in_progress': 30.0}
    """
    from dyntarget.errors import InvalidParameterError

    out: dict[str, Any] = {}
    for model, names in MODEL_OPTIONS.items():
        for name in names:
            value = getattr(args, name, None)
            if value is None:
                continue
            if model != args.eruption_model:
                raise InvalidParameterError(
                    f"--{name.replace('_', '-')} applies to --eruption-model {model}, "
                    f"not {args.eruption_model}"
                )
            out[name] = value
    return out


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    from dyntarget.constellation.simulate import ALLOCATIONS, CUEING, RELAYS
    from dyntarget.constellation.world import (
        EPISODES_PER_DAY,
        ERUPTIONS_IN_PROGRESS,
        MEDIAN_DURATION_S,
        MODELS,
        ONSETS_PER_YEAR,
    )

    p = sub.add_parser(
        "constellation",
        help="a constellation-day over the world's volcanoes: cueing, allocation, on Dask",
    )
    orbit = p.add_argument_group("the satellites (one of)")
    orbit.add_argument("--tle", help="a TLE file (two- or three-line sets)")
    orbit.add_argument(
        "--walker",
        metavar="T/P/F",
        help="a Walker-delta constellation: T satellites in P planes, phasing F (W<plane>-<slot>)",
    )
    o.ALTITUDE_KM.add(orbit, default=500.0, help="Walker altitude (default 500)")
    orbit.add_argument(
        "--inclination-deg",
        default="sso",
        help="Walker inclination, degrees, or sso (sun-synchronous; default)",
    )
    p.add_argument(
        "--start", default="2026-06-01T00:00:00Z", help="ISO 8601 start (default %(default)s)"
    )
    p.add_argument("--hours", type=HOURS, default=24.0, help="length (default 24)")
    p.add_argument("--volcanoes", required=True, help="GVP Holocene volcano list (CSV)")
    p.add_argument(
        "--cueing", choices=CUEING, default="cross", help="who tells whom (default cross)"
    )
    p.add_argument(
        "--allocation",
        choices=ALLOCATIONS,
        default="greedy",
        help="who points where (default greedy; bound: exact MILP, small instances)",
    )
    p.add_argument(
        "--relay",
        choices=RELAYS,
        default="crosslink",
        help="board delay: crosslink (30 s), ground (station contacts) or none",
    )
    o.SEED.add(p)
    o.AGILITY.add(p, default="fast", help="NFOV agility preset: fast or slow (default fast)")
    p.add_argument(
        "--swath-km",
        type=o.positive_float,
        default=30.0,
        help="look-ahead swath width (default 30)",
    )
    o.LOOK_AHEAD_KM.add(
        p,
        type=o.positive_float,
        default=500.0,
        help="look-ahead distance ahead of nadir (default 500)",
    )
    p.add_argument(
        "--eruption-model",
        choices=MODELS,
        default="eruptions",
        help="eruptions: GVP eruptions (in progress and new) holding plume episodes (default); "
        "episodes: independent plume episodes only (the earlier model)",
    )
    p.add_argument(
        "--eruptions-in-progress",
        type=o.float_range(0, 100_000, "a number of eruptions"),
        default=None,
        help=f"mean GVP eruptions in progress at the start (default {ERUPTIONS_IN_PROGRESS:g})",
    )
    p.add_argument(
        "--eruption-onsets-per-year",
        type=o.float_range(0, 1e6, "a number of onsets a year"),
        default=None,
        help=f"new GVP eruptions a year, world-wide (default {ONSETS_PER_YEAR:g})",
    )
    p.add_argument(
        "--episodes-per-day",
        type=o.positive_float,
        default=None,
        help=f"plume episodes a day within an eruption (default {EPISODES_PER_DAY:g})",
    )
    p.add_argument(
        "--episode-median-h",
        type=o.positive_float,
        default=None,
        help=f"median plume-episode duration, hours (default {MEDIAN_DURATION_S / 3600:g})",
    )
    p.add_argument(
        "--eruptions-per-day",
        type=o.positive_float,
        default=None,
        help="--eruption-model episodes: expected episodes per day, world-wide (default 40)",
    )
    o.SCHEDULER.add(p)
    o.OUT.add(p)
    o.QUIET.add(p)
    o.NO_PICTURE.add(p, help="skip constellation.png")
    o.NO_HTML.add(p, help="skip constellation.html")
    p.set_defaults(func=cmd_constellation)
