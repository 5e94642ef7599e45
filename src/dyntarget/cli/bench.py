"""``dyntarget bench``: latency and peak memory of every stage."""

from __future__ import annotations

import argparse
from typing import Any

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, log, writes


@writes(files=("out", "markdown"))
def cmd_bench(args: argparse.Namespace) -> int:
    import json

    from dyntarget.evaluate.bench import parse_sizes, run_bench, summary_tables
    from dyntarget.io.atomic import write_text

    sizes: dict[str, Any] = {"sizes": parse_sizes(args.sizes)} if args.sizes is not None else {}
    result = run_bench(
        **sizes,
        classifiers=args.classifiers.split(",") if args.classifiers else None,
        planners=args.planners.split(",") if args.planners else None,
        repeats=args.repeats,
        progress=not args.quiet,
        variants=args.variants.split(",") if args.variants else (),
    )
    tables = summary_tables(result)
    write_text(args.out, json.dumps(result, indent=1) + "\n")
    if args.markdown:
        write_text(args.markdown, tables)
    print(tables)
    log(f"wrote {args.out}")
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser(
        "bench", help="latency and peak memory of every stage, classifier and planner"
    )
    p.add_argument("--sizes", help="comma-separated WFOV sizes in px (default 256,512,1024,2048)")
    o.CLASSIFIERS.add(p)
    o.PLANNERS.add(p)
    p.add_argument(
        "--repeats",
        type=o.int_range(1, 1000, "a number of runs"),
        default=5,
        help="timed runs after a warm-up (default 5)",
    )
    o.OUT.add(p, required=False, default="bench.json", help="JSON results (default bench.json)")
    p.add_argument("--markdown", help="also write the Markdown tables here")
    o.QUIET.add(p)
    p.add_argument(
        "--variants",
        help="extra rows: comma-separated unet-uavsar:blend, unet-xception:blend, "
        "random-forest:sklearn, random-forest:compiled",
    )
    p.set_defaults(func=cmd_bench)
