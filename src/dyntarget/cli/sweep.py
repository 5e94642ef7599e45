"""``dyntarget sweep``: a parameter grid over held-out scenes, on Dask."""

from __future__ import annotations

import argparse
from pathlib import Path

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, writes


@writes(dirs=("out", "models"))
def cmd_sweep(args: argparse.Namespace) -> int:
    """Run (or resume) the sweep; its table and figure move into ``--out`` together.

    ``parts/`` and ``models/`` (the resume state) are written in ``--out`` as they finish;
    ``sweep.csv`` and ``sweep.png`` are staged (:mod:`dyntarget.io.staging`), so a failing
    or interrupted rerun leaves the previous table and figure as they were, and a rerun
    that draws no figure removes the earlier one.
    """
    from dyntarget.evaluate.options import RunOptions
    from dyntarget.evaluate.sweep import RESULT_FILES, parse_grid, summary_figure, sweep
    from dyntarget.io.staging import staged

    grid = parse_grid(args.grid or [])
    out = Path(args.out)
    with staged(out, stale=RESULT_FILES) as stage:
        table = sweep(
            args.data,
            out,
            classifiers=args.classifiers.split(","),
            planners=args.planners.split(",") if args.planners else None,
            grid=grid,
            folds=args.folds,
            seed=args.seed,
            epochs=args.epochs,
            options=RunOptions(
                models_dir=args.models, progress=not args.quiet, scheduler=args.scheduler
            ),
            into=stage,
        )
        figure = summary_figure(table, stage / "sweep.png")
    print(out / table.name)
    if figure:
        print(out / figure.name)
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser(
        "sweep", help="a parameter grid over held-out scenes x classifiers x planners, on Dask"
    )
    o.DATA.add(p)
    o.OUT.add(p, help="output folder (sweep.csv, parts/, models/, sweep.png)")
    o.CLASSIFIERS.add(p, required=True, help="comma-separated classifier names")
    o.PLANNERS.add(p)
    p.add_argument(
        "--grid",
        nargs="*",
        metavar="NAME=V1,V2",
        help="parameters to sweep: step_fraction, denoise_iterations, min_area_fraction, factor, "
        "agility (presets: unlimited, fast, slow)",
    )
    o.FOLDS.add(p)
    o.EPOCHS.add(p)
    o.SEED.add(p)
    o.MODELS.add(p, help="folder for trained models (default OUT/models)")
    o.SCHEDULER.add(
        p,
        default="local",
        help="dask.distributed: local (threads, default), processes (one worker process per "
        "core) or a scheduler address tcp://HOST:PORT",
    )
    o.QUIET.add(p)
    p.set_defaults(func=cmd_sweep)
