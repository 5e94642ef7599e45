"""``dyntarget synth``: generate synthetic volcanic scenes."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dyntarget.cli._common import EXIT_OK, log, positive_float, positive_int


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
    log(
        f"wrote {args.scenes} scenes ({n_files} files) to {out} in {time.perf_counter() - t0:.1f} s"
    )
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add this module's command(s) to the ``dyntarget`` sub-commands."""
    p = sub.add_parser("synth", help="generate synthetic volcanic scenes (GeoTIFF + mask)")
    p.add_argument("--scenes", type=positive_int, default=38, help="number of scenes (default 38)")
    p.add_argument(
        "--size", type=positive_int, default=512, help="scene size in pixels (default 512)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--gsd", type=positive_float, default=8.0, help="metres per pixel (default 8)")
    p.add_argument("--out", required=True, help="output scene directory")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_synth)
