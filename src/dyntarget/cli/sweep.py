"""``dyntarget sweep``: a parameter grid over held-out scenes, on Dask."""

from __future__ import annotations

import argparse
from pathlib import Path

from dyntarget import defaults
from dyntarget.cli._common import EXIT_OK, positive_int, writes


@writes(dirs=("out", "models"))
def cmd_sweep(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.options import RunOptions
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
        options=RunOptions(
            models_dir=args.models, progress=not args.quiet, scheduler=args.scheduler
        ),
    )
    figure = summary_figure(table, Path(args.out) / "sweep.png")
    print(table)
    if figure:
        print(figure)
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
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
    p.add_argument(
        "--folds",
        type=positive_int,
        default=defaults.FOLDS,
        help=f"number of folds (default {defaults.FOLDS})",
    )
    p.add_argument(
        "--epochs",
        type=positive_int,
        default=defaults.EPOCHS,
        help=f"U-Net epochs (default {defaults.EPOCHS})",
    )
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
