"""``dyntarget evaluate dynamic``: the paper's metrics against latency and wind on moving scenes."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, log, name_lists, plan_config, writes


def _latencies(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated seconds such as 0,30,60,90,180, got {text!r}"
        ) from None
    if not values or any(not 0 <= v <= 3600 for v in values):
        raise argparse.ArgumentTypeError(f"expected seconds in 0..3600, got {text!r}")
    return values


@writes(dirs=("out", "models"))
def cmd_evaluate_dynamic(args: argparse.Namespace) -> int:
    from dyntarget.evaluate.dynamic import (
        DYNAMIC_COLUMNS,
        DynamicConfig,
        evaluate_dynamic,
        latency_figure,
        latency_table,
    )
    from dyntarget.evaluate.options import RunOptions
    from dyntarget.evaluate.tables import csv_text, markdown_table
    from dyntarget.io import read_sequence_dir, write_text
    from dyntarget.pipeline import PipelineConfig

    lists = name_lists(classifiers=args.classifiers, planners=args.planners, modes=args.modes)
    config = DynamicConfig(
        folds=args.folds,
        seed=args.seed,
        factor=args.factor,
        epochs=args.epochs,
        true_mask=not args.no_true_mask,
        latencies=args.latencies,
        agility=args.agility,
        altitude_m=args.altitude_km * 1e3,
        look_ahead_m=args.look_ahead_km * 1e3,
        truth_step_s=args.truth_step_s,
        pipeline=PipelineConfig(plan=plan_config(args)),
        **lists,
    )
    sequences = read_sequence_dir(args.data)
    t0 = time.perf_counter()
    result = evaluate_dynamic(
        sequences,
        config,
        options=RunOptions(
            models_dir=args.models,
            progress=not args.quiet,
            scheduler=args.scheduler,
            parts=Path(args.out) / "parts" / "dynamic",
        ),
    )
    seconds = time.perf_counter() - t0
    out = Path(args.out)
    records = result["records"]
    sections = [
        f"# Dynamic evaluation: {len(sequences)} sequences, agility {config.agility}\n",
        "Ratio plume by latency (s after the decision frame), mode static, all winds:\n",
        markdown_table(*latency_table(records)),
    ]
    bins = list(dict.fromkeys(r["wind_bin"] for r in result["rows"]))
    for wbin in bins:
        sections += [
            f"\nWind {wbin} m/s:\n",
            markdown_table(*latency_table(records, wind=wbin)),
        ]
    for mode in config.modes:
        if mode != "static":
            sections += [
                f"\nMode {mode}, all winds:\n",
                markdown_table(*latency_table(records, mode=mode)),
            ]
    from dyntarget.defaults import DYNAMIC_MODES
    from dyntarget.io.staging import staged

    figures = ["dynamic.png", *(f"dynamic-{m}.png" for m in DYNAMIC_MODES if m != "static")]
    stale = ("dynamic.csv", "dynamic.md", "dynamic.json", "dynamic.timing.json", *figures)
    with staged(out, stale=stale) as stage:  # the tables and figures move in together
        paths = [
            write_text(stage / "dynamic.csv", csv_text(result["rows"], DYNAMIC_COLUMNS)),
            write_text(stage / "dynamic.md", "".join(sections)),
            write_text(stage / "dynamic.json", json.dumps(result, indent=1) + "\n"),
            write_text(stage / "dynamic.timing.json", json.dumps({"seconds": seconds}) + "\n"),
        ]
        winds = [None, "8-12"] if "8-12" in bins and len(bins) > 1 else [None]
        for mode in config.modes:
            name = "dynamic.png" if mode == "static" else f"dynamic-{mode}.png"
            paths.append(latency_figure(records, stage / name, winds=winds, mode=mode))
    print("".join(sections[1:3]))
    log(f"dynamic evaluation of {len(sequences)} sequences took {seconds:.0f} s")
    log("wrote " + ", ".join(str(out / p.name) for p in paths if p is not None))
    return EXIT_OK


def register_evaluation(ev: argparse._SubParsersAction) -> None:
    """Add ``evaluate dynamic`` to the ``evaluate`` sub-commands."""
    from dyntarget.defaults import DYNAMIC_LATENCIES_S as DEFAULT_LATENCIES
    from dyntarget.defaults import DYNAMIC_MODES as MODES
    from dyntarget.defaults import DYNAMIC_WIND_BINS_MPS as WIND_BINS
    from dyntarget.schedule import AGILITY

    # (the parser needs only the defaults: the evaluation itself is imported when it runs)
    bins = ", ".join(f"{lo:g}+" if hi == float("inf") else f"{lo:g}-{hi:g}" for lo, hi in WIND_BINS)
    q = ev.add_parser(
        "dynamic",
        help="metrics vs latency and wind on moving scenes (pointings scored at their own time)",
        description=(
            "Look-ahead planners and baselines on held-out moving sequences (from "
            "'dyntarget synth --frames N' or your own sequence folders): each plan is timed "
            "from the decision frame (the last look-ahead frame) plus the latency, and every "
            "pointing is scored against the true plume at its own time. Axes of the tidy "
            f"dynamic.csv: mode x classifier x planner x latency x wind bin ({bins} m/s). "
            "Writes dynamic.csv, dynamic.md (ratio plume per latency, all winds and per "
            "wind bin), dynamic.json (per-scene records) and dynamic.png (ratio plume vs latency)."
        ),
    )
    o.DATA.add(q, help="sequence directory (sub-folders with sequence.json)")
    o.OUT.add(q)
    o.FACTOR.add(q, default=4)
    o.QUIET.add(q)
    o.SCHEDULER.add(q)
    o.MODELS.add(q)
    o.FOLDS.add(q, default=5)
    o.EPOCHS.add(q, default=50)
    o.SEED.add(q)
    o.CLASSIFIERS.add(
        q,
        help="axis: comma-separated classifiers trained per fold (default mlp, a good "
        "per-pixel classifier; unet-uavsar is better and slower)",
    )
    q.add_argument(
        "--no-true-mask",
        action="store_true",
        help="leave out planning on the decision frame's true mask (classifier 'true-mask')",
    )
    o.PLANNERS.add(q, help="axis: comma-separated planners (default: all six)")
    q.add_argument(
        "--modes",
        help=f"axis: comma-separated modes (default static; available: {', '.join(MODES)})",
    )
    q.add_argument(
        "--latencies",
        type=_latencies,
        default=DEFAULT_LATENCIES,
        help="axis: seconds from the decision frame to pointing (default "
        + ",".join(f"{v:g}" for v in DEFAULT_LATENCIES)
        + ")",
    )
    o.AGILITY.add(
        q,
        default="unlimited",
        choices=list(AGILITY),
        help="NFOV agility preset for timing the pointings (default unlimited: all at the latency)",
    )
    o.add_orbit_options(q)
    o.TRUTH_STEP_S.add(
        q, help="pointing times are rounded to this step to share truth renderings (default 1 s)"
    )
    o.add_plan_options(q)
    q.set_defaults(func=cmd_evaluate_dynamic)
