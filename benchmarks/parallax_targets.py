"""Plumes in 3D, issue 40's targets: measured heights, targeting against the flat world, speed.

Every pass is ``dyntarget fly``'s loop (:func:`dyntarget.fly.loop.fly_pass`) at its
defaults (``lawnmower-transect``, factor 4, overlap 0.5, 500 km up, no prediction), with
the oracle classifier (``--truth``: each look-ahead frame's mask is what a perfect
classifier puts there, the parallax displacement included; never its heights), on
synthetic strips (:func:`dyntarget.synth.strip.strip_spec`, 8 m, ``--width`` px wide)
made 3D by :func:`dyntarget.synth.dynamic.with_heights` (tops 2-15 km, clouds 1-12 km,
rise 10-100 m/s). A 3D plume is seen up to ~17 km north of its vent, so each strip has
``MARGIN_PX`` rows north of its vents with no vent of its own: there the look-ahead sees
the displaced plumes of the vents further south (a flat world shows nothing there).

Parts (``--part``):

``heights``
    ``--strips`` strips, wind drawn 0-20 m/s, the look-ahead distance drawn so that its view
    zenith angle is 30-50 deg; ``fly``'s default parallax mode (``estimated``: one re-look
    at 60 % of the look-ahead distance, as ``fly``'s default 300 of 500 km),
    ``fast`` agility. Every plume whose height was estimated against its vent's true top
    (at the time of its last look): RMSE, bias, share measured.
``targeting``
    The same strips at the default geometry (500 km ahead), ``slow`` and ``fast``, flown
    flat (the same world without heights), and in 3D uncorrected (``off``), corrected with
    the true heights (``true``), with the estimated ones (``estimated``, re-looks and the
    frames they cost included: one re-look, ``fly``'s default; ``estimated-2``: two, at 80 %
    and 60 % of the distance, a steady top's search; ``estimated-2r``: the same allowing a
    top rising at up to 100 m/s; ``estimated-far``: one re-look, at 80 % of the distance,
    400 km: a shorter pitch, cheaper for ``slow``, a shorter baseline; ``estimated-mosaic``:
    ``estimated`` whose re-looks take up to 8 frames where one cannot hold the search,
    ``fly --relook-frames 8``; ``estimated-hold``: ``estimated`` whose look-ahead holds
    its re-looks' pitch where it can, ``fly --relook-hold``, as ``estimated`` does by
    default where it cannot catch up (``slow``); ``estimated-back``: going back to the
    regular pitch after every re-look, ``fly --no-relook-hold``) and with a fixed
    prior of 8.5 km (``prior``); ``--modes`` picks some. Utility is the loop's
    (line-of-sight scoring on the 3D worlds).
``long``
    What re-looks cost: ``--long-strips`` pass-length strips (``--long-km`` km,
    ``--long-width`` px wide at 8 m, 2 vents / 100 km:
    :func:`dyntarget.synth.strip.long_strip_spec`, 3D), long enough that a re-look falls
    while later frames are due: each mode's utility, re-looks, the look-ahead frames they
    cost and those taken late (catching up; ``estimated-nc``: without), ``slow`` and
    ``fast`` (``--long-modes``; ``--long-agilities`` picks one).
``rise``
    ``--rise-strips`` strips of one column rising through the looks (top 6-15 km, rise
    10-100 m/s, still rising 40 s after the pass starts; wind 0-20 m/s from any direction;
    no clouds), flown with re-looks at two distances (the rise is fitted only then), a steady
    top's search (``estimated-2``) and allowing a rising top (``estimated-2r``), ``fast``:
    the fitted rise against the true one (the issue's ±25 %), and the height at the first
    look.
``speed``
    The estimate's own time per frame (the ``heights`` stage) and the loop's time per frame
    (``loop_s``) of the ``estimated`` passes.

``--relook-wait W`` sets :data:`dyntarget.predict.relooks.RELOOK_WAIT` (the longest wait for
a busy look-ahead, in re-look durations) for the run: the study of that constant.

Usage::

    python benchmarks/parallax_targets.py --strips 12 --out docs/benchmarks
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from dyntarget import defaults, parallax
from dyntarget.evaluate.bench import machine
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.predict import relooks
from dyntarget.synth.dynamic import with_heights
from dyntarget.synth.strip import long_strip_spec, strip_spec
from dyntarget.synth.strip_world import LongStrip, MovingStrip

MARGIN_PX = 2400
"""Rows (8 m) north of the vents: the parallax of a 15 km top 560 km ahead, 20 km."""
MODES = ("flat", "off", "prior", "true", "estimated", "estimated-2")
"""``estimated``: ``fly``'s default, one re-look at 60 % of the look-ahead distance;
``estimated-2``: two, at 80 % and 60 % (they also measure a rise), searching for a steady
top (``fly``'s default ``--max-rise-mps 0``)."""
LONG_MODES = (*MODES, "estimated-nc")
"""The long part adds ``estimated-nc``: ``estimated`` without catching up (``--no-catch-up``:
the frames due during a re-look are lost)."""
EXTRA_MODES = (
    "estimated-nc",
    "estimated-2r",
    "estimated-far",
    "estimated-mosaic",
    "estimated-hold",
    "estimated-back",
    "estimated-defer",
    "estimated-nodefer",
)
"""Also accepted by ``--modes``: ``estimated-2r`` is ``estimated-2`` allowing for a top
rising at up to :data:`RISE_MPS` (``fly --max-rise-mps 100``); ``estimated-far`` is
``estimated`` with its one re-look at 80 % of the look-ahead distance instead of 60 %
(``fly --relook-km 400`` at the default geometry); ``estimated-mosaic`` is ``estimated``
whose re-looks take up to :data:`MOSAIC_FRAMES` frames where one cannot hold the search
(``fly --relook-frames 8``); ``estimated-hold`` is ``estimated`` whose look-ahead, after
a re-look, holds that re-look's pitch where it can and takes the regular frames from there
(``fly --relook-hold``; ``estimated`` does so by default where the look-ahead cannot catch
up, as ``slow``); ``estimated-back`` is ``estimated`` whose look-ahead always goes back to
its regular pitch (``fly --no-relook-hold``); ``estimated-defer`` is ``estimated`` whose
plumes cut by a frame's top edge are flown from the frame that sees them whole
(``fly --defer-cut-plumes``; ``estimated``'s default on frames shorter than 4 km, the 2 km
frames of ``--long-width 256`` and of the rise part); ``estimated-nodefer`` flies them from
the cut frame on any frame (``fly --no-defer-cut-plumes``; ``estimated`` before deferring
became its default on short frames)."""
MOSAIC_FRAMES = 8
"""The most frames an ``estimated-mosaic`` re-look takes."""
RISE_MPS = 100.0
"""The fastest rise ``estimated-2r`` allows for: the top of the rising columns' range."""
RISE_MODES = ("estimated-2", "estimated-2r")
"""The rise part flies each column both ways by default: a steady top's search, and the rise
allowed for (``--rise-modes`` picks; ``estimated-2rm`` is ``estimated-2r`` whose re-looks
take up to :data:`MOSAIC_FRAMES` frames where one cannot hold the search,
``fly --relook-km 400,300 --max-rise-mps 100 --relook-frames 8``)."""
RISE_EXTRA = ("estimated-2rm",)
PRIOR_M = 8500.0
AGILITIES = ("slow", "fast")
"""The agility presets flown (``--long-agilities`` picks some for the long part)."""


def look_ahead_for_zenith(zenith_deg: float, altitude_m: float = defaults.ALTITUDE_M) -> float:
    """The ground distance ahead at which the view zenith angle is ``zenith_deg`` (bisection)."""
    lo, hi = 0.0, 2.0e6
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if float(np.degrees(parallax.view_zenith(altitude_m, mid))) < zenith_deg:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def make_strip(seed: int, width: int, length: int, plumes: int, wind: float | None):
    """A 3D strip and its flat twin: vents only south of the northern margin."""
    spec, window = strip_spec(
        seed, width=width, length=length + MARGIN_PX, plumes=plumes, wind_mps=wind
    )
    _, r0, _, _ = window
    vents = tuple(v for v in spec.vents if v.y - r0 >= MARGIN_PX)
    flat = replace(spec, vents=vents)
    return (
        flat,
        with_heights(flat, plume_height_km=(2.0, 15.0), cloud_height_km=(1.0, 12.0)),
        window,
    )


def fly(spec, window, config: PassConfig, *, long: bool = False) -> dict:
    world = LongStrip(spec, window) if long else MovingStrip(spec, window)
    t0 = time.perf_counter()
    result = fly_pass(world, None, config)
    wall = time.perf_counter() - t0
    totals = result.totals()
    estimates = [e.as_dict() for e in getattr(result, "heights", ()) or ()]
    frames = [r for r in result.records if not r.dropped]
    return {
        "utility": totals["utility"],
        "plumes_observed": totals["plumes_observed"],
        "plumes_total": totals["plumes_total"],
        "pointings_flown": totals["pointings_flown"],
        "parallax": totals.get("parallax"),
        "relooks": totals.get("relooks"),
        "frames_lost_to_relooks": totals.get("frames_lost_to_relooks"),
        "frames_caught_up": totals.get("frames_caught_up"),
        **({"frames_held": totals["frames_held"]} if "frames_held" in totals else {}),
        "frames": len(result.records),
        "estimates": estimates,
        "heights_s": [float(r.stage_s.get("heights", 0.0)) for r in frames],
        "loop_s": [float(r.loop_s) for r in frames if r.loop_s is not None],
        "wall_s": round(wall, 2),
    }


def config_for(mode: str, agility: str, look_ahead_m: float) -> PassConfig:
    if mode == "estimated-nc":
        return replace(config_for("estimated", agility, look_ahead_m), catch_up=False)
    if mode == "estimated-far":
        far = (round(0.8 * look_ahead_m / 1e3, 3),)
        return replace(config_for("estimated", agility, look_ahead_m), relook_km=far)
    if mode == "estimated-2r":
        return replace(config_for("estimated-2", agility, look_ahead_m), max_rise_mps=RISE_MPS)
    if mode == "estimated-2rm":
        return replace(
            config_for("estimated-2r", agility, look_ahead_m), relook_frames=MOSAIC_FRAMES
        )
    if mode == "estimated-mosaic":
        return replace(config_for("estimated", agility, look_ahead_m), relook_frames=MOSAIC_FRAMES)
    if mode == "estimated-hold":
        return replace(config_for("estimated", agility, look_ahead_m), relook_hold=True)
    if mode == "estimated-back":
        return replace(config_for("estimated", agility, look_ahead_m), relook_hold=False)
    if mode in ("estimated-defer", "estimated-nodefer"):
        defer = mode == "estimated-defer"
        return replace(config_for("estimated", agility, look_ahead_m), defer_cut=defer)
    relook: tuple[float, ...] = (round(0.6 * look_ahead_m / 1e3, 3),)
    if mode == "estimated-2":
        mode, relook = "estimated", (round(0.8 * look_ahead_m / 1e3, 3), *relook)
    parallax_mode = "off" if mode == "flat" else mode
    return PassConfig(
        agility=agility,
        look_ahead_m=look_ahead_m,
        parallax=parallax_mode,
        plume_height_m=PRIOR_M if mode == "prior" else None,
        relook_km=relook,
    )


def part_heights(args) -> dict:
    rng = np.random.default_rng(args.seed)
    rows = []
    for i in range(args.strips):
        wind = float(rng.uniform(0.0, 20.0))
        zenith = float(rng.uniform(30.0, 50.0))
        ahead = look_ahead_for_zenith(zenith)
        _, spec3, window = make_strip(args.seed + i, args.width, args.length, args.plumes, wind)
        r = fly(spec3, window, config_for(args.height_mode, "fast", ahead))
        rows.append(
            {"strip": i, "wind_mps": wind, "zenith_deg": zenith, "look_ahead_m": ahead, **r}
        )
        print(
            json.dumps({k: v for k, v in rows[-1].items() if k not in ("heights_s", "loop_s")}),
            flush=True,
        )
    return {"rows": rows, "summary": height_summary(rows), "speed": speed_summary(rows)}


def height_summary(rows: list[dict]) -> dict:
    err, measured, total = [], 0, 0
    for r in rows:
        for e in r["estimates"]:
            total += 1
            if e.get("height_source") == "estimated" and e.get("true_height_m") is not None:
                measured += 1
                err.append(float(e["top_height_m"]) - float(e["true_height_m"]))
    a = np.asarray(err)
    return {
        "plumes": total,
        "estimated": measured,
        "rmse_m": None if not len(a) else round(float(np.sqrt(np.mean(a**2))), 1),
        "bias_m": None if not len(a) else round(float(a.mean()), 1),
        "median_abs_m": None if not len(a) else round(float(np.median(np.abs(a))), 1),
        "worst_abs_m": None if not len(a) else round(float(np.abs(a).max()), 1),
    }


def part_targeting(args) -> dict:
    rng = np.random.default_rng(args.seed + 1)
    rows = []
    for i in range(args.strips):
        wind = float(rng.uniform(0.0, 20.0))
        flat, spec3, window = make_strip(args.seed + i, args.width, args.length, args.plumes, wind)
        for agility in ("slow", "fast"):
            for mode in args.modes:
                spec = flat if mode == "flat" else spec3
                r = fly(spec, window, config_for(mode, agility, defaults.LOOK_AHEAD_M))
                rows.append({"strip": i, "agility": agility, "mode": mode, **r})
                say(rows[-1], "plumes_observed", "relooks", "frames_lost_to_relooks", "wall_s")
    summary = mode_summary(rows, "plumes_observed")
    est = [r for r in rows if r["mode"] == "estimated"]
    return {
        "rows": rows, "summary": summary, "speed": speed_summary(est),
        "heights": height_summary(est),
        "heights_2": height_summary([r for r in rows if r["mode"] == "estimated-2"]),
        **({"heights_mosaic": height_summary([r for r in rows if r["mode"] == "estimated-mosaic"])}
           if "estimated-mosaic" in args.modes else {}),
    }  # fmt: skip


RISE_VENT_XY = (200.0, 2100.0)
"""The rising column's vent on its strip (high-res px): seen by the pass's first frames."""


def rising_column(seed: int, rng: np.random.Generator):
    """One vent whose column rises through the looks, on a 2304-row strip without clouds.

    Top 6-15 km, rise 10-100 m/s, the top at the pass's start 2 km or more and still
    rising 40 s later (the looks span about 28 s); wind 0-20 m/s from any direction; a
    broad source (as ``tests/fly/test_pass_3d.py``). Returns the spec, window and the
    true rise."""
    top = float(rng.uniform(6e3, 15e3))
    rise = float(rng.uniform(10.0, 100.0))
    lo, hi = 2e3 / rise, (top - 40.0 * rise) / rise  # seconds since the onset at t = 0
    age = float(rng.uniform(lo, max(hi, lo)))
    wind, wind_from = float(rng.uniform(0.0, 20.0)), float(rng.uniform(0.0, 360.0))
    spec, window = strip_spec(
        seed, width=256, length=2304, plumes=1, wind_mps=wind, wind_from_deg=wind_from
    )
    vent = replace(
        spec.vents[0], x=RISE_VENT_XY[0], y=RISE_VENT_XY[1], top_height_m=top, rise_mps=rise,
        eruption_age_s=age, source_sigma_m=200.0, diffusivity_m2s=200.0,
    )  # fmt: skip
    return replace(spec, vents=(vent,), clouds=()), window, rise


def part_rise(args) -> dict:
    """Rise velocity from re-looks at two distances (80 % and 60 % of the look-ahead
    distance), ``fast``, one rising column per strip, flown both ways (:data:`RISE_MODES`;
    ``--rise-modes`` picks)."""
    rng = np.random.default_rng(args.seed + 2)
    rows = []
    for i in range(args.rise_strips):
        spec, window, rise = rising_column(args.seed + 500 + i, rng)
        for mode in args.rise_modes:
            r = fly(spec, window, config_for(mode, "fast", defaults.LOOK_AHEAD_M))
            est = [e for e in r["estimates"] if e.get("height_source") == "estimated"]
            got = est[0].get("rise_mps") if est else None
            rows.append({
                "strip": i, "agility": "fast", "mode": mode, "rise_true_mps": round(rise, 2),
                "rise_mps": got, "within_25": got is not None and abs(got - rise) <= 0.25 * rise,
                **r,
            })  # fmt: skip
            say(rows[-1], "rise_true_mps", "rise_mps", "within_25", "wall_s")
    summary = {}
    for mode in args.rise_modes:
        mine = [r for r in rows if r["mode"] == mode]
        fitted = [r for r in mine if r["rise_mps"] is not None]
        rel = np.array([(r["rise_mps"] - r["rise_true_mps"]) / r["rise_true_mps"] for r in fitted])
        summary[mode] = {
            "columns": len(mine),
            "rise_fitted": len(fitted),
            "within_25_percent": sum(r["within_25"] for r in mine),
            "median_abs_relative_error": round(float(np.median(np.abs(rel))), 3)
            if len(rel)
            else None,
            "heights": height_summary(mine),
        }
    return {"rows": rows, "summary": summary}


def say(row: dict, *keys: str) -> None:
    """One pass's line on stdout: strip, agility, mode, utility and ``keys``."""
    keys = ("strip", "agility", "mode", "utility", *keys)
    print(json.dumps({k: row[k] for k in keys}), flush=True)


def mode_summary(rows: list[dict], *sums: str) -> dict:
    """Per agility and mode: utility summed over the strips, as a fraction of the flat
    passes', and the sums of ``sums`` (``None`` counted 0; a key no row of a mode has, left
    out)."""
    summary: dict = {}
    for agility in ("slow", "fast"):
        sel = [r for r in rows if r["agility"] == agility]
        flat_u = sum(r["utility"] for r in sel if r["mode"] == "flat")
        summary[agility] = {}
        for mode in dict.fromkeys(r["mode"] for r in sel):  # the modes flown, in order
            mine = [r for r in sel if r["mode"] == mode]
            u = sum(r["utility"] for r in mine)
            summary[agility][mode] = {
                "utility": round(u, 2),
                "fraction_of_flat": None if flat_u <= 0 else round(u / flat_u, 4),
                **{k: sum(r.get(k) or 0 for r in mine) for k in sums if any(k in r for r in mine)},
            }
    return summary


def speed_summary(rows: list[dict]) -> dict:
    """The height estimate's time per frame and the loop's, over every frame of ``rows``."""
    heights = [s for r in rows for s in r["heights_s"]]
    loops = [s for r in rows for s in r["loop_s"]]
    return {
        "frames": len(heights),
        "heights_median_ms": round(1e3 * statistics.median(heights), 2) if heights else None,
        "heights_p95_ms": round(1e3 * float(np.percentile(heights, 95)), 2) if heights else None,
        "heights_max_ms": round(1e3 * max(heights), 2) if heights else None,
        "frames_over_50ms": sum(h > 0.05 for h in heights),
        "loop_median_s": round(statistics.median(loops), 4) if loops else None,
    }


def part_long(args) -> dict:
    rows = []
    for i in range(args.long_strips):
        spec, window = long_strip_spec(
            args.seed + 300 + i, args.long_km, width=args.long_width, plumes_per_100km=2.0,
            wind_mps=5.0,
        )  # fmt: skip
        spec3 = with_heights(spec, plume_height_km=(2.0, 15.0), cloud_height_km=(1.0, 12.0))
        for agility in args.long_agilities:
            for mode in args.long_modes:
                r = fly(spec if mode == "flat" else spec3, window,
                        config_for(mode, agility, defaults.LOOK_AHEAD_M), long=True)  # fmt: skip
                rows.append({"strip": i, "agility": agility, "mode": mode, **r})
                say(rows[-1], "plumes_observed", "plumes_total", "relooks",
                    "frames_lost_to_relooks", "frames_caught_up", "frames", "wall_s")  # fmt: skip
    summary = mode_summary(
        rows, "relooks", "frames_lost_to_relooks", "frames_caught_up", "frames_held", "frames"
    )
    return {"rows": rows, "summary": summary}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--strips", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--width", type=int, default=1024, help="strip width, px (8 m)")
    ap.add_argument("--length", type=int, default=4096, help="rows holding vents, px (8 m)")
    ap.add_argument("--plumes", type=int, default=4)
    ap.add_argument(
        "--part", choices=("heights", "targeting", "long", "rise", "all"), default="all"
    )
    ap.add_argument("--rise-strips", type=int, default=24)
    ap.add_argument(
        "--rise-modes", type=lambda s: tuple(s.split(",")), default=RISE_MODES,
        help=f"rise part, comma-separated, of {','.join((*RISE_MODES, *RISE_EXTRA))}",
    )  # fmt: skip
    ap.add_argument("--long-strips", type=int, default=2)
    ap.add_argument("--long-km", type=float, default=150.0)
    ap.add_argument("--long-width", type=int, default=256, help="long strips' width, px (8 m)")
    ap.add_argument(
        "--long-modes", type=lambda s: tuple(s.split(",")), default=LONG_MODES,
        help=f"comma-separated, of {','.join(LONG_MODES)}",
    )  # fmt: skip
    ap.add_argument(
        "--long-agilities", type=lambda s: tuple(s.split(",")), default=AGILITIES,
        help="long part, comma-separated, of slow,fast",
    )  # fmt: skip
    ap.add_argument(
        "--modes", type=lambda s: tuple(s.split(",")), default=MODES,
        help=f"targeting part, comma-separated, of {','.join((*MODES, *EXTRA_MODES[1:]))}",
    )  # fmt: skip
    ap.add_argument(
        "--height-mode",
        default="estimated",
        choices=("estimated", "estimated-mosaic"),
        help="heights part: fly's default re-looks, or re-looks taking a mosaic",
    )
    ap.add_argument(
        "--relook-wait", type=float, default=relooks.RELOOK_WAIT,
        help="longest wait for a busy look-ahead, in re-look durations (a study of "
        "dyntarget.predict.relooks.RELOOK_WAIT; default: its value)",
    )  # fmt: skip
    ap.add_argument("--record", help="the record's file name (default: by --part)")
    ap.add_argument("--out", type=Path, default=Path("docs/benchmarks"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    record: dict = {
        "command": "python benchmarks/parallax_targets.py "
        + " ".join(
            f"--{k} {v}"
            for k, v in (
                ("strips", args.strips),
                ("seed", args.seed),
                ("width", args.width),
                ("length", args.length),
                ("plumes", args.plumes),
                ("part", args.part),
                ("long-strips", args.long_strips),
                ("long-km", args.long_km),
                ("long-width", args.long_width),
                ("long-modes", ",".join(args.long_modes)),
                ("rise-strips", args.rise_strips),
            )
        )
        + ("" if args.modes == MODES else f" --modes {','.join(args.modes)}")
        + ("" if args.rise_modes == RISE_MODES else f" --rise-modes {','.join(args.rise_modes)}")
        + ("" if args.height_mode == "estimated" else f" --height-mode {args.height_mode}")
        + (
            ""
            if args.long_agilities == AGILITIES
            else f" --long-agilities {','.join(args.long_agilities)}"
        )
        + (
            ""
            if args.relook_wait == relooks.RELOOK_WAIT
            else f" --relook-wait {args.relook_wait:g}"
        )
    }
    if not args.relook_wait > 0.0:
        ap.error(f"--relook-wait must be positive, got {args.relook_wait:g}")
    relooks.RELOOK_WAIT = args.relook_wait  # the one study that changes it: this process only
    for a in args.long_agilities:
        if a not in AGILITIES:
            ap.error(f"unknown agility {a!r}: expected one of {', '.join(AGILITIES)}")
    for asked, known in (
        ((*args.modes, *args.long_modes), (*MODES, *EXTRA_MODES)),
        (args.rise_modes, (*RISE_MODES, *RISE_EXTRA)),
    ):
        for m in asked:
            if m not in known:
                ap.error(f"unknown mode {m!r}: expected one of {', '.join(known)}")
    t0 = time.perf_counter()
    if args.part in ("heights", "all"):
        record["heights"] = part_heights(args)
    if args.part in ("targeting", "all"):
        record["targeting"] = part_targeting(args)
    if args.part in ("long", "all"):
        record["long"] = part_long(args)
    if args.part in ("rise", "all"):
        record["rise"] = part_rise(args)
    record["wall_s"] = round(time.perf_counter() - t0, 1)
    record["machine"] = machine()
    name = "parallax_targets.json" if args.part == "all" else f"parallax_{args.part}.json"
    name = args.record or name
    (args.out / name).write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    print(args.out / name)
    for part in ("heights", "targeting", "long", "rise"):
        if part in record:
            print(
                part, json.dumps({k: v for k, v in record[part].items() if k != "rows"}, indent=1)
            )


if __name__ == "__main__":
    main()
