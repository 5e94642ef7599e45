"""``dyntarget datasets list|fetch|prepare``: public datasets."""

from __future__ import annotations

import argparse

from dyntarget.cli import options as o
from dyntarget.cli._common import EXIT_OK, Parser, log, writes


def cmd_datasets_list(args: argparse.Namespace) -> int:
    from dyntarget.datasets import DATASETS

    for name, dataset in DATASETS.items():
        print(f"{name:20s} {dataset.summary}")
    return EXIT_OK


def cmd_datasets_fetch(args: argparse.Namespace) -> int:
    from dyntarget.datasets import get_dataset

    adapter = get_dataset(args.name).adapter()
    paths = adapter.fetch(args.to, api_url=args.url or adapter.RECORD_API, progress=not args.quiet)
    for p in paths:
        print(p)
    return EXIT_OK


@writes(dirs=("out",))
def cmd_datasets_prepare(args: argparse.Namespace) -> int:
    """Prepare the scene directory as a whole: staged, then moved in place of the previous one.

    The scenes are written into a staging folder inside ``--out``
    (:mod:`dyntarget.io.staging`); when all are written, they replace every scene file
    of the previous preparation at once (hidden entries, such as dyntarget's marker, stay).
    A failing or interrupted run leaves the previous scene directory as it was.
    """
    from pathlib import Path

    from dyntarget.datasets import get_dataset
    from dyntarget.io.staging import staged

    adapter = get_dataset(args.name).adapter()
    out = Path(args.out)
    previous = [p.name for p in out.iterdir() if not p.name.startswith(".")]  # claimed: exists
    with staged(out, stale=previous) as stage:
        ids = adapter.prepare(args.source, stage, negatives=args.negatives, progress=not args.quiet)
    log(f"wrote {len(ids)} scenes to {args.out}")
    print(args.out)
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser(
        "datasets", help="public datasets: list, fetch, prepare as a scene directory"
    )
    ds = p.add_subparsers(dest="action", required=True, metavar="ACTION", parser_class=Parser)
    q = ds.add_parser("list", help="the datasets dyntarget can fetch and convert")
    q.set_defaults(func=cmd_datasets_list)
    q = ds.add_parser("fetch", help="download a dataset (checksummed, resumable)")
    q.add_argument("name", help="dataset name (see 'dyntarget datasets list')")
    q.add_argument("--to", required=True, help="download folder")
    q.add_argument("--url", help="record API address (default: the Zenodo record)")
    o.QUIET.add(q, help="no progress bars")
    q.set_defaults(func=cmd_datasets_fetch)
    q = ds.add_parser("prepare", help="convert a downloaded dataset into a scene directory")
    q.add_argument("name", help="dataset name")
    q.add_argument(
        "--from", dest="source", required=True, help="folder with the downloaded archives"
    )
    o.OUT.add(q, help="scene directory to write")
    q.add_argument(
        "--negatives", action="store_true", help="add as many plume-free images as labelled ones"
    )
    o.QUIET.add(q)
    q.set_defaults(func=cmd_datasets_prepare)
