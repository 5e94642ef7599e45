"""``dyntarget constellation``: many satellites, one shared picture of the world's volcanoes."""

from __future__ import annotations

import argparse
from pathlib import Path

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
        eruptions_per_day=args.eruptions_per_day,
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


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    from dyntarget.constellation.simulate import ALLOCATIONS, CUEING, RELAYS

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
        "--eruptions-per-day",
        type=o.positive_float,
        default=40.0,
        help="expected eruptive episodes per day, world-wide (default 40)",
    )
    o.SCHEDULER.add(p)
    o.OUT.add(p)
    o.QUIET.add(p)
    o.NO_PICTURE.add(p, help="skip constellation.png")
    o.NO_HTML.add(p, help="skip constellation.html")
    p.set_defaults(func=cmd_constellation)
