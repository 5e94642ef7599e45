"""``dyntarget fly``: fly a pass over a strip, watch a directory live, or run a campaign."""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path
from typing import Any

from dyntarget import defaults
from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, log, plan_config, writes
from dyntarget.errors import DynTargetError, InvalidParameterError


def _classifier(args: argparse.Namespace):
    if args.model is None:
        return None
    if args.onnx or args.int8:
        from dyntarget.perceive.onnx import load_onnx

        return load_onnx(args.model, int8=args.int8)
    from dyntarget.perceive import load_classifier

    return load_classifier(args.model)


def _geo(args: argparse.Namespace):
    """The GEO settings of ``--geo`` (``None`` without it); bad values: one line, exit 2."""
    given = [
        o
        for o in (
            "geo_gsd_m",
            "geo_cadence_s",
            "geo_latency_s",
            "geo_reserve",
            "geo_detection",
            "geo_endmembers",
            "geo_no_stage",
        )
        if getattr(args, o) not in (None, False)
    ]
    modes = [f"--{m.replace('_', '-')}" for m in GEO_MODES if getattr(args, m)]
    if not modes:
        if given:
            raise InvalidParameterError(f"--{given[0].replace('_', '-')}: give --geo too")
        return None
    if len(modes) > 1:
        raise InvalidParameterError(f"{' and '.join(modes)} exclude each other; give one")
    ignored = [g for g in given if g not in GEO_MODE_OPTIONS.get(modes[0], given)]
    if ignored:
        raise InvalidParameterError(
            f"--{ignored[0].replace('_', '-')}: has no effect with {modes[0]} "
            f"({GEO_MODE_WHAT[modes[0]]}); leave it out or fly with --geo"
        )
    from dyntarget.passes.geo import GeoSettings

    kw = {
        k: getattr(args, f"geo_{k}")
        for k in ("gsd_m", "cadence_s", "latency_s", "reserve", "detection", "endmembers")
        if getattr(args, f"geo_{k}") is not None
    }
    if args.geo_no_stage:
        kw["stage"] = False
    if args.geo_prior and args.geo_prior != "vents":  # a bad catalog: one line, before the pass
        from dyntarget.geo.catalog import read_catalog

        read_catalog(args.geo_prior)
    return GeoSettings(
        **kw,
        omniscient=bool(args.geo_omniscient),
        blind=bool(args.geo_blind),
        prior=args.geo_prior,
    )


GEO_MODES = ("geo", "geo_omniscient", "geo_blind", "geo_prior")
GEO_MODE_OPTIONS = {
    "--geo-omniscient": ("geo_reserve", "geo_no_stage"),
    "--geo-blind": (),
    "--geo-prior": ("geo_reserve", "geo_no_stage"),
}
"""The ``--geo-*`` settings each GEO mode uses (``--geo`` uses them all): the omniscient
blueprint is planned on the true plumes (no GEO grid, cadence, latency or detection); the
blind ablation has no blueprint at all (nothing to reserve or stage)."""
GEO_MODE_WHAT = {
    "--geo-omniscient": "the blueprint is planned on the true plumes, not on GEO images",
    "--geo-blind": "there is no blueprint",
    "--geo-prior": "the blueprint is planned on the catalog's volcanoes, not on GEO images",
}


def _pass_config(args: argparse.Namespace, planner: str, agility: str):
    from dyntarget.fly import PassConfig
    from dyntarget.pipeline import PipelineConfig

    return PassConfig(
        planner=planner,
        agility=agility,
        factor=args.factor,
        frame_px=args.frame_px,
        overlap=args.overlap,
        altitude_m=args.altitude_km * 1e3,
        look_ahead_m=args.look_ahead_km * 1e3,
        compute_budget_s=args.compute_budget_s,
        deadline_s=args.deadline_s,
        footprint=args.footprint,
        denoise=not args.no_denoise,
        predict=args.predict,
        wind_mps=args.wind_mps,
        wind_from_deg=args.wind_from_deg,
        ground=args.ground,
        pipeline=PipelineConfig(plan=plan_config(args)),
        **_parallax_settings(args),
    )


def _parallax_settings(args: argparse.Namespace) -> dict[str, Any]:
    """``PassConfig`` parallax fields from ``--parallax``, ``--plume-height-km``,
    ``--no-parallax``, ``--relook-km``, ``--no-catch-up``, ``--max-rise-mps``,
    ``--relook-frames``, ``--relook-hold`` and ``--defer-cut-plumes`` (and their ``--no-``
    forms; none given: none set, the defaults)."""
    kw: dict[str, Any] = {}
    mode, choice = args.parallax, o.parallax_choice(args)
    if choice == "off":
        if mode not in (None, "off"):
            raise InvalidParameterError(f"--no-parallax and --parallax {mode} exclude each other")
        mode = "off"
    height = o.parallax_height_m(args)
    if height is not None:
        if mode in ("off", "true"):
            raise InvalidParameterError(
                f"--plume-height-km: has no effect with --parallax {mode} (no prior is used); "
                "leave it out or give --parallax prior or estimated"
            )
        kw["plume_height_m"] = height
    if mode is not None:
        kw["parallax"] = mode
    if args.relook_km is not None:
        kw["relook_km"] = args.relook_km
    if args.no_catch_up:
        kw["catch_up"] = False
    if args.max_rise_mps is not None:
        if args.max_rise_mps > 0 and len(args.relook_km or ()) < 2:  # the default: one
            raise InvalidParameterError(
                "--max-rise-mps: has no effect with one re-look distance (a rise is fitted "
                "with two or more: give e.g. --relook-km 400,300)"
            )
        if args.max_rise_mps > 0 and mode in ("off", "prior", "true"):
            raise InvalidParameterError(
                f"--max-rise-mps: has no effect with --parallax {mode} (no height is measured)"
            )
        kw["max_rise_mps"] = args.max_rise_mps
    if args.relook_frames is not None:
        _refuse_unmeasured("--relook-frames", mode, "no re-look is taken")
        kw["relook_frames"] = args.relook_frames
    if args.relook_hold is not None:
        flag = "--relook-hold" if args.relook_hold else "--no-relook-hold"
        _refuse_unmeasured(flag, mode, "no re-look is taken")
        kw["relook_hold"] = args.relook_hold
    if args.defer_cut is not None:
        flag = "--defer-cut-plumes" if args.defer_cut else "--no-defer-cut-plumes"
        _refuse_unmeasured(flag, mode, "no height is measured")
        if args.defer_cut and args.predict != "none":
            raise InvalidParameterError(
                f"--defer-cut-plumes: not with --predict {args.predict} (a frame that predicts "
                "plans the predicted plume, not the ground a later frame plans again)"
            )
        kw["defer_cut"] = args.defer_cut
    return kw


def _refuse_unmeasured(flag: str, mode: str | None, why: str) -> None:
    """A re-look option given with a ``--parallax`` mode that measures no height: one line."""
    if mode in ("off", "prior", "true"):
        raise InvalidParameterError(f"{flag}: has no effect with --parallax {mode} ({why})")


def _km_list(text: str) -> tuple[float, ...]:
    """``--relook-km A,B``: distances ahead of the nadir, km, finite and > 0."""
    import math

    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected distances in km, comma-separated (e.g. 400,300), got {text!r}"
        ) from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"expected finite distances in km > 0, got {text!r}")
    return values


@writes(dirs=("out",))
def cmd_fly(args: argparse.Namespace) -> int:
    from dyntarget.cli._common import check_orbit

    check_orbit(args)
    modes = [m for m in ("scene", "watch", "campaign") if getattr(args, m)]
    if len(modes) != 1:
        raise InvalidParameterError("fly: give exactly one of --scene, --watch, --campaign")
    if args.model is None and not args.truth:
        raise InvalidParameterError(
            "fly: give --model MODEL (a trained model directory) or --truth (plan on the true mask)"
        )
    if args.model is not None and args.truth:
        raise InvalidParameterError("fly: --model and --truth exclude each other")
    # campaigns: the strips' GSD is not known yet, so factors are compared. Not for --watch:
    # live look-ahead frames come at their own resolution (often already the WFOV grid, flown
    # at --factor 1), so a factor says nothing about the resolution there.
    if args.campaign:
        from dyntarget.cli._resolution import check_resolution

        check_resolution(args.model, factor=args.factor, gsd=None, force=args.force)
    if args.watch:
        return _watch(args)
    if args.campaign:
        return _campaign(args)
    return _fly(args)


def _fly(args: argparse.Namespace) -> int:
    from dyntarget.synth.strip_world import load_world

    if "," in args.planner or "," in args.agility:
        raise InvalidParameterError("--planner/--agility: lists are for --campaign; give one each")
    geo = _geo(args)  # bad GEO settings: one line before anything is read
    world = load_world(args.scene, truth_step_s=args.truth_step_s)
    from dyntarget.cli._resolution import check_resolution

    gsd = world.gsd * args.factor
    for opt in ("model", "fallback_model"):
        check_resolution(
            getattr(args, opt),
            factor=args.factor,
            gsd=gsd,
            force=args.force,
            what=f"--{opt.replace('_', '-')}",
        )
    config = _pass_config(args, args.planner, args.agility)
    if geo is not None:
        geo.check_against(world.gsd * args.factor)
        if world.spec is None and geo.prior is None:
            raise InvalidParameterError(
                f"--geo: {args.scene} has no world to render the GEO stream from "
                "(a 'dyntarget synth --strip' strip is needed)"
            )
    classifier = _classifier(args)
    fallback = None
    if args.fallback_model:
        from dyntarget.perceive import load_classifier

        fallback = load_classifier(args.fallback_model)
    return _fly_staged(args, world, classifier, fallback, config, geo)


def _fly_staged(args: argparse.Namespace, world, classifier, fallback, config, geo) -> int:
    """Fly the pass into a staging folder inside ``--out``; move it into place when written.

    A failure leaves ``--out`` as it was. A pass stopped by a signal is moved into place
    when ``--out`` holds no earlier pass; otherwise the earlier pass is kept and the
    stopped one stays in its staging folder, named on stderr.
    """
    from dyntarget.fly import fly_pass
    from dyntarget.fly.signals import stop_on_signals  # only when a pass flies
    from dyntarget.io.staging import discard, new_stage
    from dyntarget.view.pass_report import ViewCollector, commit_pass, write_progress

    out = Path(args.out)
    stage = new_stage(out)
    views = None if args.no_html and args.no_picture else ViewCollector(segments=not args.no_html)
    try:
        with stop_on_signals() as stop:
            try:
                result = fly_pass(
                    world,
                    classifier,
                    config,
                    fallback=fallback,
                    on_frame=_Progress(
                        lambda r: write_progress(r, world, stage, crs_mode=args.crs)
                    ),
                    should_stop=stop.is_set,
                    progress=not args.quiet,
                    frame_sink=views,
                    geo=geo,
                    # the true upper bound: every pass on the truth (a long strip on request)
                    upper_bound=bool(args.truth) and (args.upper_bound or not world.is_long),
                )
            except DynTargetError as exc:  # found after the first frame: nothing is kept
                raise type(exc)(
                    f"{exc} (the pass stopped; no partial timeline is left in {out}: "
                    "it holds what it held before)"
                ) from None
        written = _write_outputs(args, result, world, views, stage)
    except BaseException:
        discard(stage)
        raise
    t = result.totals()
    log(
        f"{t['frames']} frames, {t['pointings_flown']} pointings flown, "
        f"{t['plumes_observed']} of {t['plumes_total']} plumes observed, utility {t['utility']:.2f}"
        + (" (stopped)" if result.stopped else "")
    )
    if result.stopped and _holds_a_pass(out):
        log(
            f"stopped: {out} keeps its earlier pass; this pass's {t['frames']} frame(s) are in "
            f"{stage}"
        )
    else:
        commit_pass(stage, out)
        log("wrote " + ", ".join(str(out / p.relative_to(stage)) for p in written))
    if result.stopped and stop.caught:
        return 128 + stop.caught[0]
    return EXIT_OK


def _write_outputs(args: argparse.Namespace, result, world, views, stage: Path) -> list[Path]:
    """Every file of the pass into ``stage``, in the order the ``wrote`` line names them."""
    from dyntarget.view.pass_report import MEASURED, write_pass, write_times

    written = write_pass(
        result, world, stage, picture=not args.no_picture, views=views, crs_mode=args.crs
    )
    if (stage / MEASURED).is_file() and stage / MEASURED not in written:
        written.insert(2, stage / MEASURED)  # the measured stage times (a fixed-budget pass)
    if result.is_3d:  # the plume-top heights of a 3D strip (a flat strip: as before)
        from dyntarget.io.geojson import write_height_estimates

        written.append(
            write_height_estimates(
                stage / PLUMES_GEOJSON, result.heights, transform=world.transform, crs=world.crs
            )
        )
    times = write_times(result, stage)
    return written if times is None else [*written, times]


PLUMES_GEOJSON = "plumes.geojson"
"""Per-plume top heights of a pass over a 3D strip (:func:`dyntarget.io.geojson.write_height_estimates`)."""


def _holds_a_pass(out: Path) -> bool:
    from dyntarget.view.pass_report import SUMMARY_JSON

    return (out / SUMMARY_JSON).is_file()


class _Progress:
    """Rewrite the progress files after a frame, keeping the rewrites to a small share of the time.

    The files hold the whole pass so far, so rewriting them after every frame costs time
    growing with the pass (quadratic over a 3000 km pass). After a rewrite that took
    ``d`` seconds the next one waits for ``PROGRESS_TIME_FACTOR * d`` seconds: on a short
    pass (a rewrite of a millisecond) they are rewritten every few frames, on a long one
    every second or so. The last frame's are written by ``write_pass`` in any case.
    """

    def __init__(self, write) -> None:
        self.write, self.next_at = write, 0.0

    def __call__(self, result) -> None:
        import time

        now = time.monotonic()
        if now < self.next_at:
            return
        self.write(result)
        self.next_at = now + PROGRESS_TIME_FACTOR * (time.monotonic() - now)


PROGRESS_TIME_FACTOR = 20.0
"""After a rewrite of the progress files taking ``d`` s, the next waits ``20 d`` (<= 5 % of the time)."""


def _watch(args: argparse.Namespace) -> int:
    from dyntarget.fly.watch import WatchConfig, Watcher
    from dyntarget.pipeline import PipelineConfig

    if args.model is None:
        raise InvalidParameterError("fly --watch plans from a model: give --model MODEL")
    config = WatchConfig(
        planner=args.planner,
        factor=args.factor,
        agility=None if args.agility == "none" else args.agility,
        altitude_m=args.altitude_km * 1e3,
        look_ahead_m=args.look_ahead_km * 1e3,
        deadline_s=args.deadline_s,
        poll_s=args.poll_s,
        settle_s=args.settle_s,
        idle_exit_s=args.idle_exit_s,
        max_frames=args.max_frames,
        pipeline=PipelineConfig(plan=plan_config(args)),
    )
    watcher = Watcher(args.watch, args.out, _classifier(args), config, log=log)
    how = "inotify events and polling" if watcher._events is not None else "polling"
    log(f"watching {args.watch} with {how} (stop with Ctrl-C or SIGTERM)")
    from dyntarget.fly.signals import stop_on_signals  # only when a pass flies

    with stop_on_signals() as stop:
        n = watcher.run(stop.is_set)
    log(f"planned {n} frame(s) into {args.out}; stopped: {watcher.stop_reason or 'stop requested'}")
    return EXIT_OK


def _campaign(args: argparse.Namespace) -> int:
    from dyntarget.fly.campaign import COLUMNS, run_campaign, strips_in

    config = _pass_config(args, "lawnmower-transect", "fast")
    geo = _geo(args)  # checked against each strip's look-ahead GSD per pass
    rows = run_campaign(
        strips_in(args.campaign),
        tuple(args.planner.split(",")),
        tuple(args.agility.split(",")),
        args.out,
        config=config,
        model=args.model,
        onnx=args.onnx,
        int8=args.int8,
        scheduler=args.scheduler,
        truth_step_s=args.truth_step_s,
        progress=not args.quiet,
        geo=geo,
    )
    out = csv.writer(sys.stdout, lineterminator="\n")  # a strip name may hold a comma
    out.writerow(COLUMNS)
    out.writerows([["" if r[c] is None else r[c] for c in COLUMNS] for r in rows])
    log(f"wrote {Path(args.out) / 'campaign.csv'} ({len(rows)} passes)")
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser(
        "fly",
        help="fly a pass over a strip (the onboard loop), watch a directory live, or a campaign",
        description="Fly a pass: look-ahead frames cut along a strip at the frame cadence, each "
        "classified, denoised and planned, the pointings of one shared NFOV scheduled under the "
        "agility limits and scored against the truth at their own time (docs/onboard.md). "
        "Writes timeline.csv, pointings.geojson, summary.md, summary.json (the totals), pass.png "
        "(the picture) and pass.html (the interactive view, with a time slider) into --out; "
        "with a fixed --compute-budget-s also stage_times.csv (the measured times), with a GEO "
        "blueprint geo.timing.json, on a 3D strip plumes.geojson (per-plume top heights, "
        "--parallax). A rerun replaces the earlier pass only when it is complete.",
    )
    _add_sources(p)
    _add_pass_options(p)
    _add_prediction_options(p)
    _add_parallax_options(p)
    _add_geo_options(p)
    _add_output_options(p)
    _add_live_options(p)
    o.add_plan_options(p)
    p.set_defaults(func=cmd_fly)


def _add_sources(p: argparse.ArgumentParser) -> None:
    """What to fly (a strip, a watched folder, a campaign) and how frames are classified."""
    what = p.add_argument_group("what to fly (one of)")
    what.add_argument(
        "--scene", help="a strip: 'dyntarget synth --strip' output or a GeoTIFF with a label"
    )
    what.add_argument(
        "--watch", help="live mode: plan each complete frame appearing in this directory"
    )
    what.add_argument("--campaign", help="a directory of strips: every strip x planner x preset")
    src = p.add_argument_group("how frames are classified (one of)")
    o.MODEL.add(src, help="trained model directory ('dyntarget train')")
    src.add_argument("--truth", action="store_true", help="plan on the true mask (an oracle)")
    o.add_model_options(src, onnx_help="run the model's ONNX export (onnxruntime)")
    o.FALLBACK_MODEL.add(src, help="a cheaper model to fall back on under --deadline-s")


def _add_pass_options(p: argparse.ArgumentParser) -> None:
    """Planner, agility, resolution, frames, timing and orbit of the pass."""
    o.PLANNER.add(
        p,
        default="lawnmower-transect",
        help="planner (comma list with --campaign; default lawnmower-transect)",
    )
    o.AGILITY.add(
        p,
        default="fast",
        help="agility preset: unlimited, fast, slow (comma list with --campaign; "
        "'none' in --watch: no scheduling; default fast)",
    )
    o.OUT.add(p, help="output directory")
    o.FACTOR.add(p, default=4)
    o.FORCE.add(p)
    p.add_argument(
        "--frame-px",
        type=o.int_range(8, 65_536, "a frame height in WFOV px"),
        help="frame height in WFOV px (default: the strip's width)",
    )
    p.add_argument(
        "--overlap",
        type=o.float_range(0.0, 1.0, "a fraction of a frame", hi_open=True),
        default=0.5,
        help="fraction of a frame the next one sees again (default 0.5); sets the cadence",
    )
    p.add_argument(
        "--compute-budget-s",
        type=o.positive_seconds,
        help="fixed compute time per frame (and per height fit) instead of the measured one "
        "(deterministic)",
    )
    o.DEADLINE_S.add(
        p, help="seconds from acquisition to plan per frame; fallbacks apply, late frames drop"
    )
    p.add_argument(
        "--footprint",
        type=o.odd_footprint,
        default=1,
        help=f"NFOV footprint in WFOV px (odd, at most {o.MAX_FOOTPRINT} and the strip's "
        "width; default 1)",
    )
    o.add_orbit_options(p, look_ahead_positive=True)
    o.TRUTH_STEP_S.add(p)
    p.add_argument(
        "--upper-bound",
        action="store_true",
        help="with --truth on a long strip: also its true upper bound (summary.json "
        "upper_bound_utility; minutes per 1000 km; computed for every other --truth pass)",
    )
    o.NO_DENOISE.add(p)


def _add_parallax_options(p: argparse.ArgumentParser) -> None:
    """How the aim is corrected for the plumes' parallax on a 3D strip (a flat one has none)."""
    par = p.add_argument_group(
        "parallax (3D strips: plume tops seen displaced by the oblique look-ahead)"
    )
    o.add_parallax_options(
        par,
        height_help="a prior plume-top height, km above sea level (0 < H <= 25): the aim's "
        "height until (or where) the pass measures one; with --parallax prior, the only one",
    )
    par.add_argument(
        "--parallax",
        choices=("auto", "off", "prior", "true", "estimated"),
        help="auto (default): estimated on a 3D strip, off on a flat one; off: aim where the "
        "look-ahead saw the plume; prior: every plume at --plume-height-km; true: the strip's "
        "true heights (a benchmark's reference); estimated: heights measured from re-looks",
    )
    par.add_argument(
        "--relook-km",
        type=_km_list,
        metavar="A,B",
        help="how far ahead of the nadir the look-ahead re-looks at a new plume, km, nearest "
        "last (default 300: one re-look, with re-looks nearer in time added where a frame is "
        "too short for the search; two or more also fit a rising top, e.g. 400,300); each "
        "re-look costs look-ahead time (frames taken late, or lost)",
    )
    par.add_argument(
        "--max-rise-mps",
        type=float,
        metavar="V",
        help="with two or more --relook-km distances (a rise is fitted): the fastest rise of "
        "a plume top the re-looks allow for, m/s (default 0: a steady top; e.g. 100 for a "
        "young eruption column: its re-look windows then reach where a risen top would be, "
        "at the expense of where a taller steady one would)",
    )
    par.add_argument(
        "--relook-frames",
        type=o.int_range(1, defaults.MAX_RELOOK_FRAMES, "frames"),
        metavar="N",
        help="the most frames one re-look takes, a mosaic down the strip, where its search "
        f"asks more rows than a frame holds (default {defaults.RELOOK_FRAMES}: one frame, the "
        "search cut to it; e.g. 8 on frames of 2 km); each further frame costs a pitch step, "
        "a settle and an exposure",
    )
    par.add_argument(
        "--no-catch-up",
        action="store_true",
        help="lose the look-ahead frames due during a re-look instead of taking them late, "
        "pitching back to them once the re-look is over (the default catches up)",
    )
    hold = par.add_mutually_exclusive_group()
    hold.add_argument(
        "--relook-hold",
        action="store_const",
        const=True,
        default=None,
        help="after a re-look, keep the look-ahead at that re-look's pitch, where it can, and "
        "take the regular frames from there, later (a shorter lead, never shorter than the "
        "NFOV's field of regard allows), instead of going back and catching up or losing "
        "the frames due meanwhile (the default where the look-ahead cannot catch up, as "
        "--agility slow; this asks for it on any look-ahead)",
    )
    hold.add_argument(
        "--no-relook-hold",
        dest="relook_hold",
        action="store_const",
        const=False,
        help="always go back to the regular pitch after a re-look, catching up where the "
        "look-ahead can, else losing the frames due meanwhile",
    )
    defer = par.add_mutually_exclusive_group()
    defer.add_argument(
        "--defer-cut-plumes",
        dest="defer_cut",
        action="store_const",
        const=True,
        default=None,
        help="the pointings a look-ahead frame plans on a plume whose upwind end its top "
        "edge cuts wait for the first frame that sees that end, and fly aimed with the "
        "height measured there, not the cut view's (the default on frames shorter than "
        "4 km along track; this asks for it on any frame; measured in docs/plumes-3d.md)",
    )
    defer.add_argument(
        "--no-defer-cut-plumes",
        dest="defer_cut",
        action="store_const",
        const=False,
        help="fly the pointings on a cut plume when the cut frame's plan is ready, aimed "
        "with the cut view's height, on any frame",
    )


def _add_prediction_options(p: argparse.ArgumentParser) -> None:
    """``--predict`` and its wind prior."""
    pr = p.add_argument_group(
        "prediction (plan for the plume as it will be when the NFOV is there)"
    )
    pr.add_argument(
        "--predict",
        choices=["none", "wind", "two-looks"],
        default="none",
        help="none: plan on the look as it is (static, default); wind: carry the plume with a "
        "wind prior; two-looks: motion from this frame's overlap with the previous one, "
        "checked against the wind prior when there is one",
    )
    o.GROUND.add(
        pr,
        help="with two-looks: is the background a fixed ground (its shift is misregistration, "
        "removed) or moving itself (weather, a plume over moving cloud)? auto (default) "
        "decides from the frames and says so",
    )
    o.add_wind_options(
        pr,
        mps="wind prior speed, m/s (default: a synthetic strip's own wind, an ideal forecast)",
        from_deg="direction the wind blows from, degrees clockwise from north",
    )


def _add_geo_options(p: argparse.ArgumentParser) -> None:
    """Geostationary foresight: ``--geo`` (or its reference and ablation) and its settings."""
    geo = p.add_argument_group(
        "geostationary foresight (plan the whole pass from GEO images, refine with the look-ahead)"
    )
    geo.add_argument(
        "--geo",
        action="store_true",
        help="plan a blueprint over the pass from the GEO stream of the strip's world "
        "(computed on the ground before the pass; needs pysteps: the [geo] extra)",
    )
    geo.add_argument(
        "--geo-omniscient",
        action="store_true",
        help="the omniscient reference: the blueprint planned on the true plumes "
        "(no latency, no noise; takes --geo-reserve and --geo-no-stage only)",
    )
    geo.add_argument(
        "--geo-prior",
        metavar="CATALOG",
        help="the catalog baseline, no GEO image: the blueprint aims at the known volcanoes "
        "of CATALOG over the strip (a CSV with the Smithsonian GVP's columns), or 'vents' "
        "(a synthetic strip's own vents); takes --geo-reserve and --geo-no-stage only",
    )
    geo.add_argument(
        "--geo-blind",
        action="store_true",
        help="no blueprint: the onboard refinement alone (an ablation: what GEO adds to it; "
        "takes no other --geo-* setting)",
    )
    geo.add_argument(
        "--geo-gsd-m",
        type=o.float_range(1.0, 50_000.0, "metres"),
        help="GEO cell size, m (default 2000)",
    )
    geo.add_argument(
        "--geo-cadence-s",
        type=o.positive_seconds,
        help="seconds between GEO images (default 600)",
    )
    geo.add_argument(
        "--geo-latency-s",
        type=o.seconds,
        help="an image taken at t is usable from t + latency (default 300)",
    )
    geo.add_argument(
        "--geo-detection",
        choices=["unmix", "brightness"],
        help="how GEO cells are tested for plume: the plume fraction of a four-band "
        "unmixing into cloud, ash and steam (default), or brightness above the clear sky "
        "(takes meteorological clouds for plumes)",
    )
    geo.add_argument(
        "--geo-endmembers",
        choices=["simulator", "estimated"],
        help="the unmixing's end-members: the GEO imager's stated spectra (default; for a "
        "synthetic strip the simulator's own), or estimated from the GEO images used "
        "(N-FINDR, named by spectral shape: dyntarget.geo.endmembers)",
    )
    geo.add_argument(
        "--geo-no-stage",
        action="store_true",
        help="never send the idle sensor ahead to a blueprint target the look-ahead has "
        "not seen yet (an ablation)",
    )
    geo.add_argument(
        "--geo-reserve",
        type=o.float_range(0.0, 0.9, "a fraction"),
        help="fraction of sensor time kept for plumes the look-ahead finds (default 0.1)",
    )


def _add_output_options(p: argparse.ArgumentParser) -> None:
    """What is written besides the timeline, and how campaigns are run."""
    o.NO_PICTURE.add(p, help="skip pass.png")
    o.NO_HTML.add(p, help="skip pass.html (interactive view)")
    o.CRS.add(
        p,
        help="pointings.geojson in WGS 84 lon/lat (RFC 7946, default) or the strip's own CRS "
        "(legacy 'crs' member, for GIS)",
    )
    o.SCHEDULER.add(p)
    o.QUIET.add(p)


def _add_live_options(p: argparse.ArgumentParser) -> None:
    """``--watch``: polling, settling and when to stop."""
    live = p.add_argument_group("live mode (--watch)")
    live.add_argument("--poll-s", type=o.positive_seconds, default=0.2, help="default 0.2")
    live.add_argument(
        "--settle-s",
        type=o.seconds,
        default=1.0,
        help="a file unchanged this long may be read (default 1)",
    )
    live.add_argument(
        "--idle-exit-s",
        type=o.positive_seconds,
        help="stop after this long without a new frame (default: run until stopped)",
    )
    live.add_argument("--max-frames", type=o.positive_int, help="stop after this many frames")
