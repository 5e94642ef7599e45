"""``dyntarget demo`` and ``dyntarget reproduce``: both tables, figures and a report."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from dyntarget import defaults
from dyntarget.cli._common import (
    EXIT_OK,
    SCHEDULER_HELP,
    load_labelled,
    positive_int,
    scheduler_address,
    writes,
)
from dyntarget.cli.synth import cmd_synth


@writes(dirs=("out",))
def cmd_demo(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.figures import scenes_figure
    from dyntarget.evaluate.options import RunOptions, TrainingConfig
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
    names = tuple(
        n for n in CLASSIFIERS.available() if args.unets or CLASSIFIERS.get(n).kind != "unet"
    )
    folds = min(5, len(scenes))
    table1, table2, figures = evaluate_all(
        scenes,
        out,
        classifiers=names,
        training=TrainingConfig(
            folds=folds, seed=args.seed, factor=args.factor, epochs=args.epochs
        ),
        options=RunOptions(models_dir=out / "models", progress=not args.quiet),
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


@writes(dirs=("out", "models"))
def cmd_reproduce(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.options import RunOptions, TrainingConfig
    from dyntarget.evaluate.report import evaluate_all, write_report
    from dyntarget.perceive import CLASSIFIERS

    t0 = time.perf_counter()
    out = Path(args.out)
    scenes = load_labelled(args.data)
    table1, table2, figures = evaluate_all(
        scenes,
        out,
        classifiers=tuple(CLASSIFIERS.available()),
        training=TrainingConfig(
            folds=args.folds, seed=args.seed, factor=args.factor, epochs=args.epochs
        ),
        options=RunOptions(
            models_dir=Path(args.models) if args.models else out / "models",
            progress=not args.quiet,
            scheduler=args.scheduler,
        ),
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


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
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
        "--folds",
        type=positive_int,
        default=defaults.FOLDS,
        help=f"number of folds (default {defaults.FOLDS}, as the paper)",
    )
    p.add_argument(
        "--epochs",
        type=positive_int,
        default=defaults.EPOCHS,
        help=f"U-Net epochs (default {defaults.EPOCHS}, as the paper)",
    )
    p.add_argument(
        "--factor",
        type=positive_int,
        default=defaults.FACTOR,
        help=f"high-res -> WFOV factor (default {defaults.FACTOR})",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--scheduler", type=scheduler_address, help=SCHEDULER_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_reproduce)

    p = sub.add_parser(
        "demo", help="the main job on built-in synthetic data: both tables, figures, report"
    )
    p.add_argument("--out", default="out", help="output folder (default ./out)")
    p.add_argument("--scenes", type=positive_int, default=38, help="number of scenes (default 38)")
    p.add_argument(
        "--size", type=positive_int, default=512, help="scene size in pixels (default 512)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--factor",
        type=positive_int,
        default=defaults.FACTOR,
        help=f"high-res -> WFOV factor (default {defaults.FACTOR})",
    )
    p.add_argument("--unets", action="store_true", help="also train the two U-Nets (slower)")
    p.add_argument(
        "--epochs", type=positive_int, default=5, help="U-Net epochs with --unets (default 5)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_demo)
