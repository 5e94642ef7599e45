"""``dyntarget demo`` and ``dyntarget reproduce``: both tables, figures and a report."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, load_labelled, log, writes


@writes(dirs=("out",))
def cmd_demo(args: argparse.Namespace) -> int:
    """Scenes, both tables, figures and report, staged; models and parts resume in ``--out``.

    The result (``scenes/``, ``scenes.png``, the tables, figures and ``report.md``) is
    written into a staging folder inside ``--out`` and moved into place when complete
    (:mod:`dyntarget.io.staging`): a failing or interrupted rerun leaves the previous
    result as it was. ``models/`` and ``parts/`` are written in ``--out`` as they finish,
    so a rerun resumes from them.
    """
    from tqdm import tqdm

    from dyntarget.evaluate.figures import scenes_figure
    from dyntarget.evaluate.options import RunOptions, TrainingConfig
    from dyntarget.evaluate.report import RESULT_FILES, evaluate_all, write_report
    from dyntarget.io import read_scene_dir, write_scene
    from dyntarget.io.staging import staged
    from dyntarget.perceive import CLASSIFIERS
    from dyntarget.synth import generate_scenes

    t0 = time.perf_counter()
    out = Path(args.out)
    with staged(out, stale=(SCENES, SCENES_FIGURE, *RESULT_FILES)) as stage:
        data, n_files = stage / SCENES, 0
        for scene, _params in tqdm(
            generate_scenes(args.scenes, size=args.size, seed=args.seed, gsd=8.0),
            total=args.scenes,
            desc="synth",
            unit="scene",
            disable=args.quiet,
        ):
            n_files += len(write_scene(scene, data))  # as 'dyntarget synth' writes them
        synth_s = time.perf_counter() - t0
        scenes = read_scene_dir(data, require_labels=True)
        scenes_fig = scenes_figure(scenes, stage / SCENES_FIGURE, max_scenes=4)
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
            into=stage,
        )
        figures["scenes"] = scenes_fig
        unet_note = (
            f" U-Nets trained for {args.epochs} epochs."
            if args.unets
            else " U-Nets skipped (add --unets)."
        )
        report = write_report(
            stage,
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
    log(f"wrote {args.scenes} scenes ({n_files} files) to {out / SCENES} in {synth_s:.1f} s")
    print(f"report:  {out / report.name}")
    print(f"tables:  {out / 'table1_classification.md'}, {out / 'table2_end_to_end.md'}")
    print(f"figures: {', '.join(str(out / p.name) for p in figures.values())}")
    print(f"models:  {out / 'models'}")
    print(f"scenes:  {out / SCENES}")
    return EXIT_OK


SCENES = "scenes"
"""The demo's scene directory inside ``--out`` (part of its staged result)."""
SCENES_FIGURE = "scenes.png"


@writes(dirs=("out", "models"))
def cmd_reproduce(args: argparse.Namespace) -> int:
    """Both tables, figures and report, staged as in :func:`cmd_demo`; models and parts resume."""
    from dyntarget.evaluate.options import RunOptions, TrainingConfig
    from dyntarget.evaluate.report import RESULT_FILES, evaluate_all, write_report
    from dyntarget.io.staging import staged
    from dyntarget.perceive import CLASSIFIERS

    t0 = time.perf_counter()
    out = Path(args.out)
    scenes = load_labelled(args.data)
    with staged(out, stale=RESULT_FILES) as stage:
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
            into=stage,
        )
        report = write_report(
            stage,
            title="dyntarget reproduce: the paper's Tables 1 and 2",
            command="dyntarget " + " ".join(sys.argv[1:])
            if sys.argv[1:]
            else "dyntarget reproduce",
            table1=table1,
            table2=table2,
            figures=figures,
            seconds=time.perf_counter() - t0,
            data_note=f"Data: {len(scenes)} scenes from {args.data}; WFOV = {args.factor}x "
            f"downsampled; {args.folds}-fold cross-validation by scene; U-Nets {args.epochs} epochs.",
        )
    print(out / report.name)
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
