"""``dyntarget plan``: one image -> an NFOV trajectory; ``planners`` and ``agility`` list the choices."""

from __future__ import annotations

import argparse

from dyntarget.cli import options as o
from dyntarget.cli._common import (
    EXIT_NOTHING_FEASIBLE,
    EXIT_OK,
    log,
    plain_text,
    plan_config,
    writes,
)
from dyntarget.cli._outputs import add_output_options, write_outputs
from dyntarget.cli._predict import (
    add_predict_options,
    prediction_for,
    prediction_record,
    wants_prediction,
)


def cmd_planners(args: argparse.Namespace) -> int:
    from dyntarget.plan import BASELINES, PAPER_PLANNERS, PLANNERS

    for name in PLANNERS.available():
        doc = plain_text((PLANNERS.get(name).__doc__ or "").strip().splitlines()[0])
        tag = " (baseline)" if name in BASELINES else ""
        tag += "" if name in PAPER_PLANNERS else " (beyond the paper)"
        print(f"{name:20s} {doc}{tag}")
    return EXIT_OK


@writes(files=("out", "figure", "polygons", "html"))
def cmd_plan(args: argparse.Namespace) -> int:

    from dyntarget.cli._common import check_orbit
    from dyntarget.cli._outputs import acquisition
    from dyntarget.errors import InvalidParameterError
    from dyntarget.io.sensors import read_any
    from dyntarget.perceive import Predictor, load_classifier
    from dyntarget.pipeline import Kinematics, PipelineConfig, plan_scene

    check_orbit(args)
    _check_size(args)
    acquisition(args, args.image[0])  # a bad time is refused now, not after the work
    if args.figure:  # before anything is written
        from dyntarget.errors import require

        require("matplotlib")
    if args.mask is None and args.model is None:
        if args.classifier:
            raise InvalidParameterError(
                f"--classifier {args.classifier} needs --model PATH (train one with 'dyntarget train')"
            )
        raise InvalidParameterError("give --mask MASK or --model PATH")
    height_m = _check_needs_agility(args)
    wfov = read_any(
        args.image,
        label=args.mask,
        bands=args.bands,
        preset=args.preset,
        scale=args.scale,
        offset=args.offset,
        factor=args.factor,
    )
    from dyntarget.cli._resolution import check_resolution

    check_resolution(args.model, factor=args.factor, gsd=wfov.gsd, force=args.force)
    check_resolution(
        args.fallback_model,
        factor=args.factor,
        gsd=wfov.gsd,
        force=args.force,
        what="--fallback-model",
    )
    classifier: Predictor | None = None
    if (args.onnx or args.int8) and args.model is None:
        flag = "--int8" if args.int8 else "--onnx"
        raise InvalidParameterError(f"{flag} runs a model's ONNX export: give --model PATH")
    if args.model is not None:
        if args.onnx or args.int8:
            from dyntarget.perceive.onnx import load_onnx

            classifier = load_onnx(args.model, int8=args.int8)
        else:
            classifier = load_classifier(args.model)
        if args.classifier and args.classifier != classifier.name:
            raise InvalidParameterError(
                f"--classifier {args.classifier} does not match the model in {args.model} ({classifier.name})"
            )
    config = PipelineConfig(plan=plan_config(args))
    kinematics = None
    if args.agility:  # fly what the kinematics allow: re-timed, trimmed, maybe reordered
        from dyntarget.schedule import get_agility

        kinematics = Kinematics(
            geometry=_geometry(args, wfov),
            agility=get_agility(args.agility),
            budget_s=args.budget_s,
            objective=args.objective,
            max_pointings=args.max_pointings,
        )
    prediction, mask = None, wfov.label
    if wants_prediction(args):  # two looks or a wind prior: plan for the plume as it will be
        prediction, raw = prediction_for(args, wfov, classifier, config.threshold)
        mask = mask if raw is None else raw
    fallback = load_classifier(args.fallback_model) if args.fallback_model else None
    result = plan_scene(
        wfov.image,
        classifier,
        args.planner,
        mask=mask,
        valid=wfov.valid,
        denoise=not args.no_denoise,
        config=config,
        deadline_s=args.deadline_s,
        fallback=fallback,
        kinematics=kinematics,
        prediction=prediction,
        aim_height_m=height_m,
    )
    _log_parallax(args, height_m)
    if args.deadline_s is not None:
        met = "met" if result.deadline_met else "MISSED"
        log(
            f"deadline {args.deadline_s:g} s {met} ({result.runtime:.3f} s): "
            + "; ".join(result.path)
        )
    traj = result.trajectory
    if len(traj) == 0:
        log(f"{args.planner}: no plume found in {args.image[0]}; the trajectory is empty")
    times = ", ".join(f"{k} {1000 * v:.1f} ms" for k, v in result.timings.items())
    log(
        f"{args.planner}: {len(traj)} pointings over {len(result.polygons)} plume polygon(s); {times}"
    )
    infeasible = False
    if result.schedule is not None:
        _log_schedule(result.planner, result.schedule)
        traj = result.schedule.trajectory
        infeasible = len(traj) == 0 and result.schedule.planned > 0
    properties = None if prediction is None else {"prediction": prediction_record(prediction)}
    write_outputs(
        args, wfov, traj, polygons=result.polygons, probability=result.probability,
        title=f"{wfov.id}: {result.planner}" + (f", '{args.agility}' agility" if args.agility else ""),
        properties=properties, polygon_properties=_height_properties(args, height_m),
    )  # fmt: skip
    if args.figure:
        from dyntarget.evaluate.figures import trajectories_figure

        shown = result.mask if result.predicted_mask is None else result.predicted_mask
        print(
            trajectories_figure(
                wfov.image, [traj], args.figure, mask=shown, title=wfov.id, gsd=wfov.gsd
            )
        )
    if infeasible:
        sched = result.schedule
        why = (
            f"the observation window has closed {-sched.time_left_s:.1f} s before the plan "
            "can be flown"
            if sched.time_left_s < 0
            else "no pointing fits the agility limits and the window"
        )
        log(
            f"dyntarget: no feasible pointing: 0 of {sched.planned} planned pointings can be "
            f"flown under '{args.agility}' agility ({why}; try a smaller --start-s or another "
            f"preset); {args.out} holds no pointing; exit {EXIT_NOTHING_FEASIBLE}"
        )
        return EXIT_NOTHING_FEASIBLE
    return EXIT_OK


def _check_needs_agility(args: argparse.Namespace) -> float | None:
    """Refuse ``--budget-s`` or ``--plume-height-km`` without ``--agility``; the prior height, m."""
    from dyntarget.errors import InvalidParameterError

    if args.budget_s is not None and not args.agility:
        raise InvalidParameterError(
            f"--budget-s {args.budget_s:g} limits the time under an agility preset: "
            "give --agility PRESET as well (without it the budget would be ignored)"
        )
    height_m = o.parallax_height_m(args)
    if height_m is not None and not args.agility:
        raise InvalidParameterError(
            f"--plume-height-km {args.plume_height_km:g} corrects the scheduled pointings for "
            "parallax: give --agility PRESET as well (without it nothing would be corrected)"
        )
    return height_m


def _log_parallax(args: argparse.Namespace, height_m: float | None) -> None:
    if height_m is not None:
        log(
            f"parallax: every pointing aimed at a plume top {height_m / 1e3:g} km above sea level "
            f"(prior) as the NFOV sees it at its time, from a look-ahead {args.look_ahead_km:g} km "
            "ahead at acquisition"
        )


def _height_properties(args: argparse.Namespace, height_m: float | None) -> dict | None:
    """Every plume polygon's top height (``--plume-height-km``/``--no-parallax``), else ``None``.

    A frame carries no height of its own: every polygon gets the prior (``height_source``
    ``prior``) or none (``none``); ``top_height_sigma_m`` and ``rise_mps`` are not measured.
    """
    if o.parallax_choice(args) is None:
        return None
    return {
        "top_height_m": height_m,
        "top_height_sigma_m": None,
        "rise_mps": None,
        "height_source": "none" if height_m is None else "prior",
    }


PLAN_BYTES_PER_PIXEL = 160
"""Estimated peak memory of ``plan`` per WFOV pixel (image, probability, masks, polygons;
an estimate, not a measurement), checked against the memory available before reading."""
HTML_MAX_PIXELS = 4096 * 4096
"""Largest WFOV image ``plan --html`` draws (the view embeds it)."""


def _check_size(args: argparse.Namespace) -> None:
    """Refuse, from the GeoTIFF header alone, a plan that would not fit in memory or in a view."""
    from dyntarget.errors import InvalidParameterError

    if len(args.image) != 1 or not args.image[0].lower().endswith((".tif", ".tiff")):
        return
    from dyntarget.io.safeopen import raster_size
    from dyntarget.io.scenes import MAX_STRIP_PIXELS
    from dyntarget.synth.volcano import available_memory

    size = raster_size(args.image[0])
    if size is None or size[0] * size[1] > MAX_STRIP_PIXELS:
        return  # the reader says what is wrong with it (too large at any factor, say)
    h, w = size[0] // args.factor, size[1] // args.factor
    if args.html and h * w > HTML_MAX_PIXELS:
        raise InvalidParameterError(
            f"--html {args.html}: the image is {w} x {h} px at factor {args.factor}, more than "
            f"the {HTML_MAX_PIXELS:,} px the view draws; use a larger --factor or leave out --html"
        )
    need, have = h * w * PLAN_BYTES_PER_PIXEL, available_memory()
    if need > have:
        raise InvalidParameterError(
            f"{args.image[0]}: {w} x {h} px at factor {args.factor} needs about "
            f"{need / 1e9:.1f} GB, more than the {have / 1e9:.1f} GB available; "
            "use a larger --factor, or crop or tile it"
        )


def _geometry(args: argparse.Namespace, wfov):
    """The observation geometry of ``plan``'s kinematics options for this WFOV image."""
    from dyntarget.errors import InvalidParameterError
    from dyntarget.schedule import OrbitGeometry

    gsd = args.wfov_gsd or wfov.gsd
    if gsd is None:
        raise InvalidParameterError(
            f"{args.image[0]}: no ground sampling distance known; give --wfov-gsd METRES"
        )
    return OrbitGeometry(
        altitude_m=args.altitude_km * 1e3,
        look_ahead_m=args.look_ahead_km * 1e3,
        wfov_gsd_m=gsd,
        start_s=args.start_s,
    )


def _log_schedule(planner: str, sched) -> None:
    log(
        f"{planner} under '{sched.agility}' agility: {len(sched.kept)} of {sched.planned} "
        f"planned pointings feasible ({100 * sched.fraction_feasible:.0f} %), "
        f"done {sched.total_s:.1f} s after the start, {sched.time_left_s:.1f} s left in the window"
    )


def cmd_agility(args: argparse.Namespace) -> int:
    from dyntarget.schedule import AGILITY

    print(
        f"{'preset':10s} {'rate °/s':>9s} {'accel °/s²':>10s} {'settle s':>9s} {'dwell s':>8s} {'FOR °':>6s}"
    )
    for a in AGILITY.values():
        fov = "-" if a.field_of_regard_deg is None else f"{a.field_of_regard_deg:g}"
        print(
            f"{a.name:10s} {a.max_rate_deg_s:9g} {a.max_accel_deg_s2:10g} {a.settle_s:9g} "
            f"{a.dwell_s:8g} {fov:>6s}"
        )
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser("planners", help="list the trajectory planners")
    p.set_defaults(func=cmd_planners)

    p = sub.add_parser("agility", help="list the NFOV agility presets")
    p.set_defaults(func=cmd_agility)

    p = sub.add_parser(
        "plan", help="plan an NFOV trajectory for one image (classify, denoise, plan)"
    )
    p.add_argument(
        "image",
        nargs="+",
        help="a 4-band GeoTIFF (R, G, B, NIR), a multi-band product with --preset/--bands, a .npz, "
        "or four single-band files in the order R G B NIR",
    )
    _add_plan_sources(p)
    o.PLANNER.add(
        p,
        required=True,
        help="planner name (see 'dyntarget planners'), or utility-max (with --agility)",
    )
    o.OUT.add(p, help="trajectory file: .geojson (RFC 7946 unless --crs native) or .csv")
    p.add_argument("--figure", help="also draw the trajectory over the image (PNG)")
    o.FACTOR.add(p, default=1, help="downsample the image to WFOV first (default 1)")
    o.FORCE.add(p)
    o.add_sensor_options(p)
    o.NO_DENOISE.add(p)
    o.add_plan_options(p)
    add_predict_options(p)
    add_output_options(p)
    _add_kinematics(p)
    p.set_defaults(func=cmd_plan)


def _add_plan_sources(p: argparse.ArgumentParser) -> None:
    """What the plan is drawn on: a mask or a model (and how the model runs)."""
    src = p.add_mutually_exclusive_group()
    o.MASK.add(src)
    o.MODEL.add(src)
    o.CLASSIFIER.add(p, help="classifier name; must match --model")
    o.add_model_options(p)
    o.DEADLINE_S.add(p)
    o.FALLBACK_MODEL.add(p)


def _add_kinematics(p: argparse.ArgumentParser) -> None:
    """``--agility`` and the orbit, start, budgets and objective that time the pointings."""
    k = p.add_argument_group("kinematics (with --agility: time the pointings, keep the feasible)")
    o.AGILITY.add(k)
    o.add_orbit_options(k)
    k.add_argument(
        "--start-s",
        type=o.float_range(-o.MAX_SECONDS, o.MAX_SECONDS, "seconds"),
        default=0.0,
        help="seconds after acquisition when the plan starts (onboard latency; default 0)",
    )
    k.add_argument(
        "--wfov-gsd",
        type=o.float_range(0.0, 100_000.0, "metres", lo_open=True),
        help="metres per WFOV pixel (default: the image's)",
    )
    k.add_argument(
        "--budget-s",
        type=o.float_range(-o.MAX_SECONDS, o.MAX_SECONDS, "seconds"),
        help="time budget in seconds from the start",
    )
    k.add_argument(
        "--max-pointings",
        type=o.int_range(1, 1_000_000, "a number of pointings"),
        help="pointing budget (utility-max; needed when unlimited)",
    )
    o.OBJECTIVE.add(k)
    o.add_parallax_options(
        k,
        height_help="correct the scheduled pointings for the parallax of a plume top H km above "
        "sea level, seen by the look-ahead --look-ahead-km ahead (a prior, e.g. from a volcanic "
        "ash advisory; 0 < H <= 25; needs --agility); the polygons get top_height_m",
        no_parallax_help="no parallax correction (the default for plan: one frame carries no "
        "heights); the polygons get height_source none",
    )
