"""track-center (straight major axis) against track-centerline (smoothed centreline) on
straight and curved synthetic plumes.

The synthetic generator bends about a third of its plumes along a circular arc
(wind shear; ``SceneParams.curvature``). For every scene of the set, its WFOV
label (and, with ``--models``, the held-out prediction of a classifier trained
by ``dyntarget reproduce``) is denoised and both planners plan on it; the NFOV
simulator scores them on the high-resolution truth. Rows: means over the
straight and the curved scenes.

    python benchmarks/curved_plumes.py --data scenes/ [--models reproduce/models
        --classifier unet-uavsar] [--out docs/benchmarks/curved_plumes.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dyntarget.denoise import denoise
from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.crossval import kfold_indices
from dyntarget.evaluate.tables import markdown_table
from dyntarget.io import read_scene_dir
from dyntarget.observe import UtilityMaps, observe
from dyntarget.perceive import load_classifier
from dyntarget.plan import plan
from dyntarget.synth import generate_scene

PLANNERS = ("track-center", "track-centerline")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="a scene directory made by 'dyntarget synth'")
    ap.add_argument("--models", help="models of 'dyntarget reproduce' (fold-k/<classifier>)")
    ap.add_argument("--classifier", default="unet-uavsar")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--factor", type=int, default=4)
    ap.add_argument("--out", default="docs/benchmarks/curved_plumes.json")
    args = ap.parse_args()
    scenes = read_scene_dir(args.data, require_labels=True)
    fold_of = {}
    for k, test in enumerate(kfold_indices(len(scenes), args.folds, args.seed)):
        fold_of.update({int(i): k for i in test})
    records = []
    for i, scene in enumerate(scenes):
        _, seed, index = scene.id.split("-")  # synth-SSSS-IIII
        params = generate_scene(int(seed), int(index), size=16)[1]
        curved = bool(params.curvature != 0.0)
        wfov = scene.to_wfov(args.factor)
        maps = UtilityMaps.from_scene(scene)
        masks = {"true mask": wfov.label}
        if args.models:
            model = load_classifier(Path(args.models) / f"fold-{fold_of[i]}" / args.classifier)
            masks[args.classifier] = model.predict(wfov.image) & wfov.valid_mask
        for source, mask in masks.items():
            cleaned = denoise(mask)
            for name in PLANNERS:
                traj = plan(name, cleaned.mask, cleaned.polygons)
                m = observe(traj, maps, factor=args.factor)
                records.append(
                    {"scene": scene.id, "curved": curved, "mask": source, "planner": name}
                    | m.as_dict()
                )
    rows = []
    for source in dict.fromkeys(r["mask"] for r in records):
        for curved in (False, True):
            for name in PLANNERS:
                sel = [
                    r
                    for r in records
                    if r["mask"] == source and r["curved"] == curved and r["planner"] == name
                ]
                rows.append(
                    {
                        "mask": source,
                        "plumes": f"{'curved' if curved else 'straight'} ({len(sel)})",
                        "planner": name,
                        **{
                            k: float(np.mean([r[k] for r in sel]))
                            for k in ("pixels_observed", "ratio_plume", "intensity", "gradient")
                        },
                    }
                )
    Path(args.out).write_text(
        json.dumps({"machine": machine(), "rows": rows, "records": records}, indent=1) + "\n"
    )
    print(markdown_table(rows, list(rows[0])))


if __name__ == "__main__":
    main()
