"""``dyntarget evaluate ...``: the evaluations behind the paper's tables."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dyntarget import defaults
from dyntarget.cli import dynamic
from dyntarget.cli import options as o
from dyntarget.cli._common import (
    EXIT_OK,
    Parser,
    add_evaluation_options,
    load_labelled,
    log,
    name_lists,
    plan_config,
    show_result,
    writes,
)

EVALUATIONS: tuple = (dynamic,)
"""Further command modules adding an evaluation: each has ``register_evaluation(ev)``
(``ev`` the ``evaluate`` sub-commands); import the module here and list it."""


@writes(dirs=("out", "models"))
def cmd_evaluate_classification(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.crossval import TABLE1_COLUMNS, CVConfig, cross_validate
    from dyntarget.evaluate.options import RunOptions

    config = CVConfig(
        folds=args.folds,
        seed=args.seed,
        factor=args.factor,
        epochs=args.epochs,
        **name_lists(classifiers=args.classifiers),
    )
    scenes = load_labelled(args.data)
    t0 = time.perf_counter()
    result = cross_validate(
        scenes,
        config,
        options=RunOptions(
            models_dir=args.models,
            progress=not args.quiet,
            scheduler=args.scheduler,
            parts=Path(args.out) / "parts" / "classification",
        ),
    )
    seconds = time.perf_counter() - t0
    result["timing"]["seconds"] = seconds
    log(
        f"cross-validation of {len(config.classifiers)} classifiers on {len(scenes)} scenes took {seconds:.0f} s"
    )
    show_result(args.out, "table1_classification", result, TABLE1_COLUMNS)
    return EXIT_OK


@writes(dirs=("out",))
def cmd_evaluate_planning(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.options import RunOptions
    from dyntarget.evaluate.planning import PLANNING_COLUMNS, evaluate_planners_on_truth

    scenes = load_labelled(args.data)
    result = evaluate_planners_on_truth(
        scenes,
        factor=args.factor,
        config=plan_config(args),
        options=RunOptions(
            progress=not args.quiet,
            scheduler=args.scheduler,
            parts=Path(args.out) / "parts" / "planning",
        ),
    )
    show_result(args.out, "planning_true_masks", result, PLANNING_COLUMNS)
    return EXIT_OK


@writes(dirs=("out", "models"))
def cmd_evaluate_agility(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.agility import AGILITY_COLUMNS, AgilityConfig, evaluate_agility
    from dyntarget.evaluate.options import RunOptions

    config = AgilityConfig(
        folds=args.folds,
        seed=args.seed,
        factor=args.factor,
        epochs=args.epochs,
        classifier=args.classifier,
        objective=args.objective,
        altitude_m=args.altitude_km * 1e3,
        look_ahead_m=args.look_ahead_km * 1e3,
        plan=plan_config(args),
        **name_lists(planners=args.planners, presets=args.agility),
    )
    scenes = load_labelled(args.data)
    result = evaluate_agility(
        scenes,
        config,
        options=RunOptions(
            models_dir=args.models,
            progress=not args.quiet,
            scheduler=args.scheduler,
            parts=Path(args.out) / "parts" / "agility",
        ),
    )
    show_result(args.out, "agility", result, AGILITY_COLUMNS)
    return EXIT_OK


@writes(dirs=("out", "models"))
def cmd_evaluate_end_to_end(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.endtoend import TABLE2_COLUMNS, E2EConfig, evaluate_end_to_end
    from dyntarget.evaluate.options import RunOptions
    from dyntarget.pipeline import PipelineConfig

    config = E2EConfig(
        folds=args.folds,
        seed=args.seed,
        factor=args.factor,
        epochs=args.epochs,
        pipeline=PipelineConfig(plan=plan_config(args)),
        **name_lists(classifiers=args.classifiers, planners=args.planners),
    )
    scenes = load_labelled(args.data)
    t0 = time.perf_counter()
    result = evaluate_end_to_end(
        scenes,
        config,
        options=RunOptions(
            models_dir=args.models,
            progress=not args.quiet,
            scheduler=args.scheduler,
            parts=Path(args.out) / "parts" / "end-to-end",
        ),
    )
    result["timing"] = {"seconds": time.perf_counter() - t0}
    show_result(args.out, "table2_end_to_end", result, TABLE2_COLUMNS)
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser("evaluate", help="evaluations that reproduce the paper's tables")
    ev = p.add_subparsers(
        dest="evaluation", required=True, metavar="EVALUATION", parser_class=Parser
    )
    q = ev.add_parser("classification", help="k-fold cross-validation of the classifiers (Table 1)")
    add_evaluation_options(q)
    o.CLASSIFIERS.add(q)
    q.set_defaults(func=cmd_evaluate_classification)
    q = ev.add_parser("planning", help="the six planners on the true masks")
    add_evaluation_options(q, trains=False)
    o.add_plan_options(q)
    q.set_defaults(func=cmd_evaluate_planning)
    q = ev.add_parser(
        "agility", help="planners and utility-max under orbit kinematics and agility presets"
    )
    add_evaluation_options(q)
    o.CLASSIFIER.add(
        q,
        default=defaults.AGILITY_CLASSIFIER,
        help=f"classifier to plan on (default {defaults.AGILITY_CLASSIFIER})",
    )
    o.PLANNERS.add(q, help="comma-separated geometric planners (default: the four)")
    o.AGILITY.add(q, help="comma-separated presets (default: all; 'dyntarget agility')")
    o.OBJECTIVE.add(q)
    o.add_orbit_options(q)
    o.add_plan_options(q)
    q.set_defaults(func=cmd_evaluate_agility)

    q = ev.add_parser(
        "end-to-end", help="classify, denoise, plan and observe on held-out scenes (Table 2)"
    )
    add_evaluation_options(q)
    o.CLASSIFIERS.add(q)
    o.PLANNERS.add(q)
    o.add_plan_options(q)
    q.set_defaults(func=cmd_evaluate_end_to_end)
    for module in EVALUATIONS:
        module.register_evaluation(ev)
