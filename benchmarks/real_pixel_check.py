"""Real-pixel sanity check on a 38-Cloud Landsat 8 patch (clouds, not plumes).

Trains every classifier on the left 45 % of the patch's columns, leaves a 32 px
gap, tests on the rest, with and without denoising, and plans on the test
part's denoised prediction.

    python benchmarks/real_pixel_check.py --data ../shared/data/38cloud-sample [--epochs 50]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dyntarget.datasets.cloud38 import read_patch
from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.crossval import TABLE1_COLUMNS
from dyntarget.evaluate.realpixels import real_pixel_check
from dyntarget.evaluate.tables import markdown_table

PLAN_COLUMNS = [
    "Trajectory Algorithm",
    "Classifier",
    "Pixels Observed",
    "Ratio Plume",
    "Intensity",
    "Gradient",
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--data", required=True, help="38-Cloud patch folder (red/green/blue/nir.tif, gt.tif)"
    )
    ap.add_argument("--epochs", type=int, default=50)
    ap.add_argument("--out", default="docs/benchmarks/real_pixel_check.json")
    args = ap.parse_args()
    scene = read_patch(args.data)
    result = real_pixel_check(scene, epochs=args.epochs)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"machine": machine(), **result}, indent=1) + "\n")
    print(f"split: {result['split']}; cloud fraction: {result['plume_fraction']}\n")
    print(markdown_table(result["segmentation"], TABLE1_COLUMNS))
    print(markdown_table(result["planning"], PLAN_COLUMNS))


if __name__ == "__main__":
    main()
