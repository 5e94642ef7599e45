"""The ``dyntarget`` command line: a thin layer over the library.

Exit codes: 0 success, 2 bad usage or bad input (any :class:`DynTargetError`),
1 internal error. No traceback is printed unless ``--debug`` is given.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from dyntarget import __version__
from dyntarget.errors import DynTargetError

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # argparse exits 2 as well; keep its one line
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f"dyntarget: error: {message}\n")


SCHEDULER_HELP = (
    "run the tasks on dask.distributed: local (threads), processes (one worker process per "
    "core) or a scheduler address tcp://HOST:PORT (default: one by one in this process)"
)


def _scheduler(text: str) -> str:
    if text in ("local", "processes") or "://" in text:
        return text
    raise argparse.ArgumentTypeError(
        f"expected local, processes or a scheduler address like tcp://HOST:PORT, got {text!r}"
    )


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text!r}")
    return value


def _preset_names() -> list[str]:
    from dyntarget.io.sensors import PRESETS

    return list(PRESETS)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- commands


def cmd_synth(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from dyntarget.io import write_scene
    from dyntarget.synth import generate_scenes

    out = Path(args.out)
    t0 = time.perf_counter()
    n_files = 0
    gen = generate_scenes(args.scenes, size=args.size, seed=args.seed, gsd=args.gsd)
    for scene, _params in tqdm(
        gen, total=args.scenes, desc="synth", unit="scene", disable=args.quiet
    ):
        n_files += len(write_scene(scene, out))
    _log(
        f"wrote {args.scenes} scenes ({n_files} files) to {out} in {time.perf_counter() - t0:.1f} s"
    )
    return EXIT_OK


def cmd_classifiers(args: argparse.Namespace) -> int:
    from dyntarget.perceive import CLASSIFIERS

    for name in CLASSIFIERS.available():
        print(f"{name:20s} {CLASSIFIERS.get(name).summary}")
    return EXIT_OK


def _load_labelled(data: str) -> list:
    from dyntarget.io import read_scene_dir

    return read_scene_dir(data, require_labels=True)


def cmd_train(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.crossval import classifier_kwargs
    from dyntarget.perceive import make_classifier

    scenes = [s.to_wfov(args.factor) for s in _load_labelled(args.data)]
    model = make_classifier(
        args.classifier, **classifier_kwargs(args.classifier, seed=args.seed, epochs=args.epochs)
    )
    t0 = time.perf_counter()
    model.fit(scenes)
    path = model.save(args.out)
    _log(f"trained {args.classifier} on {len(scenes)} scenes in {time.perf_counter() - t0:.1f} s")
    print(path)
    return EXIT_OK


def _show_result(out: str, name: str, result: dict, columns: list[str]) -> None:
    """Write an evaluation's table (md, csv, json), print it, say where it went."""
    from dyntarget.evaluate.tables import markdown_table, write_result

    paths = write_result(out, name, result, columns)
    print(markdown_table(result["rows"], columns))
    _log("wrote " + ", ".join(str(p) for p in paths.values()))


def cmd_evaluate_classification(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.crossval import TABLE1_COLUMNS, CVConfig, cross_validate
    from dyntarget.evaluate.tables import markdown_table, write_result

    config = CVConfig(
        folds=args.folds,
        seed=args.seed,
        factor=args.factor,
        epochs=args.epochs,
        **_names(classifiers=args.classifiers),
    )
    scenes = _load_labelled(args.data)
    t0 = time.perf_counter()
    result = cross_validate(
        scenes,
        config,
        models_dir=args.models,
        progress=not args.quiet,
        scheduler=args.scheduler,
        parts=Path(args.out) / "parts" / "classification",
    )
    seconds = time.perf_counter() - t0
    result["timing"]["seconds"] = seconds
    paths = write_result(args.out, "table1_classification", result, TABLE1_COLUMNS)
    print(markdown_table(result["rows"], TABLE1_COLUMNS))
    _log(
        f"cross-validation of {len(config.classifiers)} classifiers on {len(scenes)} scenes took {seconds:.0f} s"
    )
    _log("wrote " + ", ".join(str(p) for p in paths.values()))
    return EXIT_OK


def cmd_planners(args: argparse.Namespace) -> int:
    from dyntarget.plan import BASELINES, PAPER_PLANNERS, PLANNERS

    for name in PLANNERS.available():
        doc = (PLANNERS.get(name).__doc__ or "").strip().splitlines()[0]
        tag = " (baseline)" if name in BASELINES else ""
        tag += "" if name in PAPER_PLANNERS else " (beyond the paper)"
        print(f"{name:20s} {doc}{tag}")
    print(
        f"{'utility-max':20s} Pointings chosen for the highest expected utility per second "
        "under orbit kinematics; needs plan --agility PRESET (beyond the paper)"
    )
    return EXIT_OK


def _plan_config(args: argparse.Namespace):
    from dyntarget.plan import PlanConfig

    return PlanConfig(step=args.step, width=args.width)


def cmd_plan(args: argparse.Namespace) -> int:

    from dyntarget.errors import InvalidParameterError
    from dyntarget.io.sensors import read_any
    from dyntarget.perceive import load_classifier
    from dyntarget.pipeline import PipelineConfig, plan_scene

    if args.mask is None and args.model is None:
        if args.classifier:
            raise InvalidParameterError(
                f"--classifier {args.classifier} needs --model PATH (train one with 'dyntarget train')"
            )
        raise InvalidParameterError("give --mask MASK or --model PATH")
    wfov = read_any(
        args.image,
        label=args.mask,
        bands=args.bands,
        preset=args.preset,
        scale=args.scale,
        offset=args.offset,
        factor=args.factor,
    )
    classifier = None
    if args.onnx and args.model is None:
        raise InvalidParameterError("--onnx runs a model's ONNX export: give --model PATH")
    if args.model is not None:
        if args.onnx:
            from dyntarget.perceive.onnx import load_onnx

            classifier = load_onnx(args.model)
        else:
            classifier = load_classifier(args.model)
        if args.classifier and args.classifier != classifier.name:
            raise InvalidParameterError(
                f"--classifier {args.classifier} does not match the model in {args.model} ({classifier.name})"
            )
    config = PipelineConfig(plan=_plan_config(args))
    if args.planner == "utility-max":
        return _plan_utility_max(args, wfov, classifier, config)
    fallback = load_classifier(args.fallback_model) if args.fallback_model else None
    result = plan_scene(
        wfov.image,
        classifier,
        args.planner,
        mask=wfov.label,
        valid=wfov.valid,
        denoise=not args.no_denoise,
        config=config,
        deadline_s=args.deadline_s,
        fallback=fallback,
    )
    if args.deadline_s is not None:
        met = "met" if result.deadline_met else "MISSED"
        _log(
            f"deadline {args.deadline_s:g} s {met} ({result.runtime:.3f} s): "
            + "; ".join(result.path)
        )
    traj = result.trajectory
    if len(traj) == 0:
        _log(f"{args.planner}: no plume found in {args.image[0]}; the trajectory is empty")
    times = ", ".join(f"{k} {1000 * v:.1f} ms" for k, v in result.timings.items())
    _log(
        f"{args.planner}: {len(traj)} pointings over {len(result.polygons)} plume polygon(s); {times}"
    )
    if args.agility:  # fly what the kinematics allow: re-timed, trimmed, maybe reordered
        from dyntarget.plan.kinematics import get_agility, make_feasible

        sched = make_feasible(
            traj, wfov.shape, _geometry(args, wfov), get_agility(args.agility),
            budget_s=args.budget_s,
        )  # fmt: skip
        _log_schedule(args.planner, sched)
        traj = sched.trajectory
    out = traj.save(args.out, transform=wfov.transform, crs=wfov.crs)
    print(out)
    if args.figure:
        from dyntarget.evaluate.figures import trajectories_figure

        print(trajectories_figure(wfov.image, [traj], args.figure, mask=result.mask, title=wfov.id))
    return EXIT_OK


def _geometry(args: argparse.Namespace, wfov):
    """The observation geometry of ``plan``'s kinematics options for this WFOV image."""
    from dyntarget.errors import InvalidParameterError
    from dyntarget.plan.kinematics import Geometry

    gsd = args.wfov_gsd or wfov.gsd
    if gsd is None:
        raise InvalidParameterError(
            f"{args.image[0]}: no ground sampling distance known; give --wfov-gsd METRES"
        )
    return Geometry(
        altitude_m=args.altitude_km * 1e3,
        look_ahead_m=args.look_ahead_km * 1e3,
        wfov_gsd_m=gsd,
        start_s=args.start_s,
    )


def _log_schedule(planner: str, sched) -> None:
    _log(
        f"{planner} under '{sched.agility}' agility: {len(sched.kept)} of {sched.planned} "
        f"planned pointings feasible ({100 * sched.fraction_feasible:.0f} %), "
        f"done {sched.total_s:.1f} s after the start, {sched.time_left_s:.1f} s left in the window"
    )


def _plan_utility_max(args, wfov, classifier, config) -> int:
    """``plan --planner utility-max``: plan under an agility preset, write the timed pointings."""
    import numpy as np

    from dyntarget.errors import InvalidParameterError
    from dyntarget.plan.kinematics import get_agility, schedule
    from dyntarget.plan.utility import utility_max

    if not args.agility:
        raise InvalidParameterError("utility-max plans under an agility preset: give --agility")
    agility = get_agility(args.agility)
    geometry = _geometry(args, wfov)
    if classifier is not None:
        proba = classifier.predict_proba(wfov.image)
    else:
        proba = wfov.label.astype(np.float32)
    proba = np.where(wfov.valid_mask, proba, 0.0).astype(np.float32)
    step, _ = config.plan.resolved(wfov.shape)
    traj = utility_max(
        proba,
        wfov.image,
        geometry,
        agility,
        step=max(step, 1.0),
        objective=args.objective,
        budget_s=args.budget_s,
        max_pointings=args.max_pointings,
    )
    sched = schedule(traj, wfov.shape, geometry, agility)
    _log_schedule("utility-max", sched)
    print(sched.trajectory.save(args.out, transform=wfov.transform, crs=wfov.crs))
    return EXIT_OK


def cmd_evaluate_planning(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.planning import PLANNING_COLUMNS, evaluate_planners_on_truth

    scenes = _load_labelled(args.data)
    result = evaluate_planners_on_truth(
        scenes,
        factor=args.factor,
        config=_plan_config(args),
        progress=not args.quiet,
        scheduler=args.scheduler,
        parts=Path(args.out) / "parts" / "planning",
    )
    _show_result(args.out, "planning_true_masks", result, PLANNING_COLUMNS)
    return EXIT_OK


def cmd_evaluate_agility(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.agility import AGILITY_COLUMNS, AgilityConfig, evaluate_agility

    config = AgilityConfig(
        folds=args.folds,
        seed=args.seed,
        factor=args.factor,
        epochs=args.epochs,
        classifier=args.classifier,
        objective=args.objective,
        altitude_m=args.altitude_km * 1e3,
        look_ahead_m=args.look_ahead_km * 1e3,
        plan=_plan_config(args),
        **_names(planners=args.planners, presets=args.agility),
    )
    scenes = _load_labelled(args.data)
    result = evaluate_agility(
        scenes,
        config,
        models_dir=args.models,
        progress=not args.quiet,
        scheduler=args.scheduler,
        parts=Path(args.out) / "parts" / "agility",
    )
    _show_result(args.out, "agility", result, AGILITY_COLUMNS)
    return EXIT_OK


def cmd_export_onnx(args: argparse.Namespace) -> int:
    import numpy as np

    from dyntarget.perceive import load_classifier
    from dyntarget.perceive.onnx import TOLERANCE, export_onnx, load_onnx
    from dyntarget.synth import generate_scene

    native = load_classifier(args.model)
    path = export_onnx(native, args.model)
    check = generate_scene(args.seed, 0, size=args.check_size)[0].image
    diff = float(
        np.abs(load_onnx(args.model).predict_proba(check) - native.predict_proba(check)).max()
    )
    if diff > TOLERANCE:
        path.unlink()
        raise RuntimeError(
            f"{native.name}: ONNX output differs from the native model by {diff:.2e} "
            f"(> {TOLERANCE:g}); export removed"
        )
    _log(f"{native.name}: ONNX and native plume probabilities agree to {diff:.1e} on a check scene")
    print(path)
    return EXIT_OK


def cmd_agility(args: argparse.Namespace) -> int:
    from dyntarget.plan.kinematics import AGILITY

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


def cmd_bench(args: argparse.Namespace) -> int:
    import json

    from dyntarget.errors import InvalidParameterError
    from dyntarget.evaluate.bench import run_bench, summary_tables
    from dyntarget.io.atomic import write_text

    sizes = [int(x) for x in args.sizes.split(",")] if args.sizes else None
    for size in sizes or []:
        if size < 32:
            raise InvalidParameterError(f"sizes: each WFOV size must be at least 32 px, got {size}")
    result = run_bench(
        **({"sizes": sizes} if sizes else {}),
        classifiers=args.classifiers.split(",") if args.classifiers else None,
        planners=args.planners.split(",") if args.planners else None,
        repeats=args.repeats,
        progress=not args.quiet,
    )
    tables = summary_tables(result)
    write_text(args.out, json.dumps(result, indent=1) + "\n")
    if args.markdown:
        write_text(args.markdown, tables)
    print(tables)
    _log(f"wrote {args.out}")
    return EXIT_OK


def cmd_sweep(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.sweep import parse_grid, summary_figure, sweep

    grid = parse_grid(args.grid or [])
    table = sweep(
        args.data,
        args.out,
        classifiers=args.classifiers.split(","),
        planners=args.planners.split(",") if args.planners else None,
        grid=grid,
        folds=args.folds,
        seed=args.seed,
        epochs=args.epochs,
        scheduler=args.scheduler,
        models_dir=args.models,
        progress=not args.quiet,
    )
    figure = summary_figure(table, Path(args.out) / "sweep.png")
    print(table)
    if figure:
        print(figure)
    return EXIT_OK


DATASETS = {
    "industrial-smoke": "Mommert et al. 2020, Sentinel-2 industrial smoke plumes (Zenodo 4250706)"
}


def _check_dataset(name: str) -> None:
    from dyntarget.errors import UnknownNameError

    if name not in DATASETS:
        raise UnknownNameError(f"unknown dataset {name!r}; expected one of: {', '.join(DATASETS)}")


def cmd_datasets_list(args: argparse.Namespace) -> int:
    for name, text in DATASETS.items():
        print(f"{name:20s} {text}")
    return EXIT_OK


def cmd_datasets_fetch(args: argparse.Namespace) -> int:
    from dyntarget.datasets import industrial_smoke

    _check_dataset(args.name)
    paths = industrial_smoke.fetch(
        args.to, api_url=args.url or industrial_smoke.RECORD_API, progress=not args.quiet
    )
    for p in paths:
        print(p)
    return EXIT_OK


def cmd_datasets_prepare(args: argparse.Namespace) -> int:
    from dyntarget.datasets import industrial_smoke

    _check_dataset(args.name)
    ids = industrial_smoke.prepare(
        args.source, args.out, negatives=args.negatives, progress=not args.quiet
    )
    _log(f"wrote {len(ids)} scenes to {args.out}")
    print(args.out)
    return EXIT_OK


def _add_evaluation_options(q: argparse.ArgumentParser, *, trains: bool = True) -> None:
    """Options the evaluations share; with ``trains``, those of training classifiers too."""
    q.add_argument("--data", required=True, help="scene directory with labels")
    q.add_argument("--out", required=True, help="output folder for the table (md, csv, json)")
    q.add_argument(
        "--factor", type=_positive_int, default=4, help="high-res -> WFOV factor (default 4)"
    )
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    q.add_argument("--scheduler", type=_scheduler, help=SCHEDULER_HELP)
    if trains:
        q.add_argument("--models", help="folder to keep trained models in and reuse them from")
        q.add_argument("--folds", type=_positive_int, default=5, help="number of folds (default 5)")
        q.add_argument("--epochs", type=_positive_int, default=50, help="U-Net epochs (default 50)")
        q.add_argument("--seed", type=int, default=0, help="random seed (default 0)")


def _names(**lists: str | None) -> dict[str, tuple[str, ...]]:
    """Comma-separated CLI lists that were given, as keyword arguments of a config."""
    return {key: tuple(text.split(",")) for key, text in lists.items() if text}


def _add_plan_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--step", type=_positive_float, help="pixels between pointings (default 1%% of the width)"
    )
    p.add_argument(
        "--width", type=_positive_float, help="pixels between transects (default 2 x step)"
    )


def cmd_demo(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.figures import scenes_figure
    from dyntarget.evaluate.report import evaluate_all, write_report
    from dyntarget.io import read_scene_dir
    from dyntarget.perceive import CLASSIFIERS

    t0 = time.perf_counter()
    out = Path(args.out)
    data = out / "scenes"
    cmd_synth(
        argparse.Namespace(
            scenes=args.scenes, size=args.size, seed=args.seed, gsd=8.0, out=data, quiet=args.quiet
        )
    )
    scenes = read_scene_dir(data, require_labels=True)
    scenes_fig = scenes_figure(scenes, out / "scenes.png", max_scenes=4)
    names = tuple(n for n in CLASSIFIERS.available() if args.unets or not n.startswith("unet-"))
    folds = min(5, len(scenes))
    table1, table2, figures = evaluate_all(
        scenes,
        out,
        models_dir=out / "models",
        classifiers=names,
        folds=folds,
        epochs=args.epochs,
        factor=args.factor,
        seed=args.seed,
        progress=not args.quiet,
    )
    figures["scenes"] = scenes_fig
    unet_note = (
        f" U-Nets trained for {args.epochs} epochs."
        if args.unets
        else " U-Nets skipped (add --unets)."
    )
    report = write_report(
        out,
        title="dyntarget demo: dynamic targeting of synthetic volcanic plumes",
        command="dyntarget " + " ".join(sys.argv[1:]) if sys.argv[1:] else "dyntarget demo",
        table1=table1,
        table2=table2,
        figures=figures,
        seconds=time.perf_counter() - t0,
        data_note=f"Data: {len(scenes)} synthetic scenes of {args.size} px (seed {args.seed}), "
        f"WFOV = {args.factor}x downsampled; {folds}-fold cross-validation by scene.{unet_note} "
        f"Sample scenes: ![scenes]({scenes_fig.name})",
        compare_with_paper=False,
    )
    print(f"report:  {report}")
    print(f"tables:  {out / 'table1_classification.md'}, {out / 'table2_end_to_end.md'}")
    print(f"figures: {', '.join(str(p) for p in figures.values())}")
    print(f"models:  {out / 'models'}")
    print(f"scenes:  {data}")
    return EXIT_OK


def cmd_evaluate_end_to_end(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.endtoend import TABLE2_COLUMNS, E2EConfig, evaluate_end_to_end
    from dyntarget.pipeline import PipelineConfig

    config = E2EConfig(
        folds=args.folds,
        seed=args.seed,
        factor=args.factor,
        epochs=args.epochs,
        pipeline=PipelineConfig(plan=_plan_config(args)),
        **_names(classifiers=args.classifiers, planners=args.planners),
    )
    scenes = _load_labelled(args.data)
    t0 = time.perf_counter()
    result = evaluate_end_to_end(
        scenes,
        config,
        models_dir=args.models,
        progress=not args.quiet,
        scheduler=args.scheduler,
        parts=Path(args.out) / "parts" / "end-to-end",
    )
    result["timing"] = {"seconds": time.perf_counter() - t0}
    _show_result(args.out, "table2_end_to_end", result, TABLE2_COLUMNS)
    return EXIT_OK


def cmd_reproduce(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.report import evaluate_all, write_report
    from dyntarget.perceive import CLASSIFIERS

    t0 = time.perf_counter()
    out = Path(args.out)
    scenes = _load_labelled(args.data)
    table1, table2, figures = evaluate_all(
        scenes,
        out,
        models_dir=Path(args.models) if args.models else out / "models",
        classifiers=tuple(CLASSIFIERS.available()),
        folds=args.folds,
        epochs=args.epochs,
        factor=args.factor,
        seed=args.seed,
        progress=not args.quiet,
        scheduler=args.scheduler,
    )
    report = write_report(
        out,
        title="dyntarget reproduce: the paper's Tables 1 and 2",
        command="dyntarget " + " ".join(sys.argv[1:]) if sys.argv[1:] else "dyntarget reproduce",
        table1=table1,
        table2=table2,
        figures=figures,
        seconds=time.perf_counter() - t0,
        data_note=f"Data: {len(scenes)} scenes from {args.data}; WFOV = {args.factor}x downsampled; "
        f"{args.folds}-fold cross-validation by scene; U-Nets {args.epochs} epochs.",
    )
    print(report)
    return EXIT_OK


# --------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="dyntarget",
        description="Dynamic targeting of plumes: classify look-ahead imagery, denoise, plan NFOV trajectories.",
    )
    parser.add_argument("--version", action="version", version=f"dyntarget {__version__}")
    parser.add_argument("--debug", action="store_true", help="print full tracebacks on errors")
    sub = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=_Parser
    )

    p = sub.add_parser("synth", help="generate synthetic volcanic scenes (GeoTIFF + mask)")
    p.add_argument("--scenes", type=_positive_int, default=38, help="number of scenes (default 38)")
    p.add_argument(
        "--size", type=_positive_int, default=512, help="scene size in pixels (default 512)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--gsd", type=_positive_float, default=8.0, help="metres per pixel (default 8)")
    p.add_argument("--out", required=True, help="output scene directory")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_synth)

    p = sub.add_parser("classifiers", help="list the plume classifiers")
    p.set_defaults(func=cmd_classifiers)

    p = sub.add_parser("train", help="train a classifier on a scene directory and save the model")
    p.add_argument("--data", required=True, help="scene directory with labels")
    p.add_argument(
        "--classifier", required=True, help="classifier name (see 'dyntarget classifiers')"
    )
    p.add_argument("--out", required=True, help="model directory to write")
    p.add_argument(
        "--epochs", type=_positive_int, default=50, help="U-Net epochs (default 50, as the paper)"
    )
    p.add_argument(
        "--factor", type=_positive_int, default=4, help="high-res -> WFOV factor (default 4)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("evaluate", help="evaluations that reproduce the paper's tables")
    ev = p.add_subparsers(
        dest="evaluation", required=True, metavar="EVALUATION", parser_class=_Parser
    )
    q = ev.add_parser("classification", help="k-fold cross-validation of the classifiers (Table 1)")
    _add_evaluation_options(q)
    q.add_argument("--classifiers", help="comma-separated subset (default: all)")
    q.set_defaults(func=cmd_evaluate_classification)
    q = ev.add_parser("planning", help="the six planners on the true masks")
    _add_evaluation_options(q, trains=False)
    _add_plan_options(q)
    q.set_defaults(func=cmd_evaluate_planning)
    q = ev.add_parser(
        "agility", help="planners and utility-max under orbit kinematics and agility presets"
    )
    _add_evaluation_options(q)
    q.add_argument(
        "--classifier", default="unet-uavsar", help="classifier to plan on (default unet-uavsar)"
    )
    q.add_argument("--planners", help="comma-separated geometric planners (default: the four)")
    q.add_argument("--agility", help="comma-separated presets (default: all; 'dyntarget agility')")
    q.add_argument(
        "--objective",
        default="gradient",
        choices=["gradient", "intensity", "plume"],
        help="what utility-max maximises (default gradient)",
    )
    q.add_argument("--altitude-km", type=_positive_float, default=500.0, help="default 500")
    q.add_argument(
        "--look-ahead-km",
        type=float,
        default=500.0,
        help="ground distance from nadir to the WFOV scene centre at acquisition (default 500)",
    )
    _add_plan_options(q)
    q.set_defaults(func=cmd_evaluate_agility)

    p = sub.add_parser("planners", help="list the trajectory planners")
    p.set_defaults(func=cmd_planners)

    p = sub.add_parser(
        "export-onnx", help="export a trained model to ONNX (model.onnx beside it), checked"
    )
    p.add_argument("model", help="trained model directory (from 'dyntarget train')")
    p.add_argument(
        "--check-size", type=_positive_int, default=128, help="check scene size (default 128)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the check scene (default 0)")
    p.set_defaults(func=cmd_export_onnx)

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
    src = p.add_mutually_exclusive_group()
    src.add_argument("--mask", help="plume mask to plan on (.tif, non-zero = plume, or .geojson)")
    src.add_argument("--model", help="trained model directory (from 'dyntarget train')")
    p.add_argument("--classifier", help="classifier name; must match --model")
    p.add_argument(
        "--onnx", action="store_true", help="run the model's ONNX export with onnxruntime"
    )
    p.add_argument(
        "--deadline-s",
        type=_positive_float,
        help="seconds allowed for classify + denoise + plan; cheaper paths are taken to meet it",
    )
    p.add_argument(
        "--fallback-model", help="a cheaper trained model to fall back on under --deadline-s"
    )
    p.add_argument(
        "--planner",
        required=True,
        help="planner name (see 'dyntarget planners'), or utility-max (with --agility)",
    )
    p.add_argument("--out", required=True, help="trajectory file: .geojson or .csv")
    p.add_argument("--figure", help="also draw the trajectory over the image (PNG)")
    p.add_argument(
        "--factor",
        type=_positive_int,
        default=1,
        help="downsample the image to WFOV first (default 1)",
    )
    p.add_argument(
        "--scale", type=_positive_float, help="reflectance per digital number for integer images"
    )
    p.add_argument("--preset", help="sensor preset: " + ", ".join(_preset_names()))
    p.add_argument(
        "--bands", help="R,G,B,NIR band numbers (1-based) or names, e.g. 3,2,1,7 or B4,B3,B2,B8"
    )
    p.add_argument(
        "--offset", type=float, help="reflectance offset added after scaling (e.g. -0.1)"
    )
    p.add_argument("--no-denoise", action="store_true", help="plan on the raw mask")
    _add_plan_options(p)
    k = p.add_argument_group("kinematics (with --agility: time the pointings, keep the feasible)")
    k.add_argument("--agility", help="agility preset: unlimited, fast, slow ('dyntarget agility')")
    k.add_argument("--altitude-km", type=_positive_float, default=500.0, help="default 500")
    k.add_argument(
        "--look-ahead-km",
        type=float,
        default=500.0,
        help="ground distance from nadir to the scene centre at acquisition (default 500)",
    )
    k.add_argument(
        "--start-s",
        type=float,
        default=0.0,
        help="seconds after acquisition when the plan starts (onboard latency; default 0)",
    )
    k.add_argument(
        "--wfov-gsd", type=_positive_float, help="metres per WFOV pixel (default: the image's)"
    )
    k.add_argument("--budget-s", type=float, help="time budget in seconds from the start")
    k.add_argument(
        "--max-pointings",
        type=_positive_int,
        help="pointing budget (utility-max; needed when unlimited)",
    )
    k.add_argument(
        "--objective",
        default="gradient",
        choices=["gradient", "intensity", "plume"],
        help="what utility-max maximises (default gradient)",
    )
    p.set_defaults(func=cmd_plan)

    q = ev.add_parser(
        "end-to-end", help="classify, denoise, plan and observe on held-out scenes (Table 2)"
    )
    _add_evaluation_options(q)
    q.add_argument("--classifiers", help="comma-separated subset (default: all)")
    q.add_argument("--planners", help="comma-separated subset (default: all)")
    _add_plan_options(q)
    q.set_defaults(func=cmd_evaluate_end_to_end)

    p = sub.add_parser(
        "sweep", help="a parameter grid over held-out scenes x classifiers x planners, on Dask"
    )
    p.add_argument("--data", required=True, help="scene directory with labels")
    p.add_argument(
        "--out", required=True, help="output folder (sweep.csv, parts/, models/, sweep.png)"
    )
    p.add_argument("--classifiers", required=True, help="comma-separated classifier names")
    p.add_argument("--planners", help="comma-separated subset (default: all)")
    p.add_argument(
        "--grid",
        nargs="*",
        metavar="NAME=V1,V2",
        help="parameters to sweep: step_fraction, denoise_iterations, min_area_fraction, factor, "
        "agility (presets: unlimited, fast, slow)",
    )
    p.add_argument("--folds", type=_positive_int, default=5, help="number of folds (default 5)")
    p.add_argument("--epochs", type=_positive_int, default=50, help="U-Net epochs (default 50)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--models", help="folder for trained models (default OUT/models)")
    p.add_argument(
        "--scheduler",
        default="local",
        help="dask.distributed: local (threads, default), processes (one worker process per "
        "core) or a scheduler address tcp://HOST:PORT",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser(
        "bench", help="latency and peak memory of every stage, classifier and planner"
    )
    p.add_argument("--sizes", help="comma-separated WFOV sizes in px (default 256,512,1024,2048)")
    p.add_argument("--classifiers", help="comma-separated subset (default: all)")
    p.add_argument("--planners", help="comma-separated subset (default: all)")
    p.add_argument(
        "--repeats", type=_positive_int, default=5, help="timed runs after a warm-up (default 5)"
    )
    p.add_argument("--out", default="bench.json", help="JSON results (default bench.json)")
    p.add_argument("--markdown", help="also write the Markdown tables here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser(
        "datasets", help="public datasets: list, fetch, prepare as a scene directory"
    )
    ds = p.add_subparsers(dest="action", required=True, metavar="ACTION", parser_class=_Parser)
    q = ds.add_parser("list", help="the datasets dyntarget can fetch and convert")
    q.set_defaults(func=cmd_datasets_list)
    q = ds.add_parser("fetch", help="download a dataset (checksummed, resumable)")
    q.add_argument("name", help="dataset name (see 'dyntarget datasets list')")
    q.add_argument("--to", required=True, help="download folder")
    q.add_argument("--url", help="record API address (default: the Zenodo record)")
    q.add_argument("--quiet", action="store_true", help="no progress bars")
    q.set_defaults(func=cmd_datasets_fetch)
    q = ds.add_parser("prepare", help="convert a downloaded dataset into a scene directory")
    q.add_argument("name", help="dataset name")
    q.add_argument(
        "--from", dest="source", required=True, help="folder with the downloaded archives"
    )
    q.add_argument("--out", required=True, help="scene directory to write")
    q.add_argument(
        "--negatives", action="store_true", help="add as many plume-free images as labelled ones"
    )
    q.add_argument("--quiet", action="store_true", help="no progress bar")
    q.set_defaults(func=cmd_datasets_prepare)

    p = sub.add_parser(
        "reproduce", help="both of the paper's tables at its settings, beside its numbers"
    )
    p.add_argument(
        "--data", required=True, help="scene directory with labels (e.g. from 'dyntarget synth')"
    )
    p.add_argument("--out", required=True, help="output folder (tables, figures, report.md)")
    p.add_argument(
        "--models", help="folder for trained models (default OUT/models); reused when present"
    )
    p.add_argument(
        "--folds", type=_positive_int, default=5, help="number of folds (default 5, as the paper)"
    )
    p.add_argument(
        "--epochs", type=_positive_int, default=50, help="U-Net epochs (default 50, as the paper)"
    )
    p.add_argument(
        "--factor", type=_positive_int, default=4, help="high-res -> WFOV factor (default 4)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--scheduler", type=_scheduler, help=SCHEDULER_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_reproduce)

    p = sub.add_parser(
        "demo", help="the main job on built-in synthetic data: both tables, figures, report"
    )
    p.add_argument("--out", default="out", help="output folder (default ./out)")
    p.add_argument("--scenes", type=_positive_int, default=38, help="number of scenes (default 38)")
    p.add_argument(
        "--size", type=_positive_int, default=512, help="scene size in pixels (default 512)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--factor", type=_positive_int, default=4, help="high-res -> WFOV factor (default 4)"
    )
    p.add_argument("--unets", action="store_true", help="also train the two U-Nets (slower)")
    p.add_argument(
        "--epochs", type=_positive_int, default=5, help="U-Net epochs with --unets (default 5)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dyntarget`` console script; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and usage errors
        return int(exc.code or 0)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except DynTargetError as exc:
        if args.debug:
            raise
        print(f"dyntarget: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("dyntarget: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # an internal error: one line unless --debug
        if args.debug:
            raise
        first = str(exc).splitlines()[0] if str(exc) else ""
        print(
            f"dyntarget: internal error: {type(exc).__name__}: {first} (rerun with --debug for a traceback)",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
