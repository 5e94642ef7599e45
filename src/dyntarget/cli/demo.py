"""``dyntarget demo`` and ``dyntarget reproduce``: both tables, figures and a report."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, load_labelled, writes
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
    o.DATA.add(p, help="scene directory with labels (e.g. from 'dyntarget synth')")
    o.OUT.add(p, help="output folder (tables, figures, report.md)")
    o.MODELS.add(p, help="folder for trained models (default OUT/models); reused when present")
    o.FOLDS.add(p, help="number of folds (default %(default)s, as the paper)")
    o.EPOCHS.add(p, help="U-Net epochs (default %(default)s, as the paper)")
    o.FACTOR.add(p)
    o.SEED.add(p)
    o.SCHEDULER.add(p)
    o.QUIET.add(p, help="no progress bars")
    p.set_defaults(func=cmd_reproduce)

    p = sub.add_parser(
        "demo", help="the main job on built-in synthetic data: both tables, figures, report"
    )
    o.OUT.add(p, required=False, default="out", help="output folder (default ./out)")
    o.SCENES.add(p)
    o.SIZE.add(p)
    o.SEED.add(p)
    o.FACTOR.add(p)
    p.add_argument("--unets", action="store_true", help="also train the two U-Nets (slower)")
    o.EPOCHS.add(p, default=5, help="U-Net epochs with --unets (default 5)")
    o.QUIET.add(p, help="no progress bars")
    p.set_defaults(func=cmd_demo)
