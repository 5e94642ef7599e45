"""Render time of the moving world (``dyntarget.synth.dynamic``) by window size and wind.

For each window size and wind speed, a world is built (noise tiles: the
one-off cost) and rendered at 5 times; the table gives the build time and the
median time per render (full image) and per truth-only call (mask + optical
depth, what scoring needs besides the image). Writes JSON and a Markdown table.

    python benchmarks/world_render.py [--sizes 256,512,1024] [--out docs/benchmarks/world_render.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.tables import markdown_table
from dyntarget.io import write_text
from dyntarget.synth.dynamic import World, sample_world

TIMES = (0.0, 30.0, 60.0, 90.0, 180.0)
COLUMNS = ["size (px)", "wind (m/s)", "build (s)", "render (s)", "truth (s)", "puffs"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="256,512,1024")
    ap.add_argument("--winds", default="0,5,15")
    ap.add_argument("--out", default="docs/benchmarks/world_render.json")
    args = ap.parse_args()
    rows = []
    for size in (int(v) for v in args.sizes.split(",")):
        for wind in (float(v) for v in args.winds.split(",")):
            t0 = time.perf_counter()
            world = World(sample_world(0, 0, size=size, wind_mps=wind))
            build = time.perf_counter() - t0
            render, truth = [], []
            for t in TIMES:
                t0 = time.perf_counter()
                world.render(t)
                render.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                world.truth(t + 0.5)
                truth.append(time.perf_counter() - t0)
            vent = world.spec.vents[0]
            puffs = int(min(vent.eruption_age_s, 8 * vent.fade_s) / world.puff_step_s(vent))
            rows.append(
                {
                    "size (px)": size,
                    "wind (m/s)": wind,
                    "build (s)": build,
                    "render (s)": statistics.median(render),
                    "truth (s)": statistics.median(truth),
                    "puffs": puffs,
                }
            )
            print(rows[-1], flush=True)
    out = Path(args.out)
    write_text(
        out, json.dumps({"machine": machine(), "columns": COLUMNS, "rows": rows}, indent=1) + "\n"
    )
    write_text(out.with_suffix(".md"), markdown_table(rows, COLUMNS))
    print(markdown_table(rows, COLUMNS))


if __name__ == "__main__":
    main()
