"""How denoising's two settings change each classifier's IoU (5-fold CV, held-out scenes).

Reuses the models of a classification evaluation (``--models``, trained when
missing) and scores every classifier's held-out predictions after denoising
with each (iterations, min_area_fraction) pair; ``iterations = 0`` and
``min_area_fraction = 0`` together are "no denoising".

    python benchmarks/denoise_sweep.py --data DIR --models DIR [--out docs/benchmarks/denoise_sweep.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dyntarget.denoise import denoise
from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.crossval import (
    DEFAULT_FACTOR,
    kfold_indices,
    train_or_load,
)
from dyntarget.evaluate.metrics import Confusion
from dyntarget.io import read_scene_dir
from dyntarget.perceive import CLASSIFIERS

ITERATIONS = (0, 1, 2, 3)
FRACTIONS = (0.0, 0.002, 0.01, 0.03)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--models", required=True)
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--epochs", type=int, default=50)
    ap.add_argument("--out", default="docs/benchmarks/denoise_sweep.json")
    args = ap.parse_args()
    scenes = [s.to_wfov(DEFAULT_FACTOR) for s in read_scene_dir(args.data, require_labels=True)]
    folds = kfold_indices(len(scenes), args.folds, 0)
    iou: dict[str, dict[str, float]] = {}
    for name in CLASSIFIERS.available():
        per_setting = {(i, f): [] for i in ITERATIONS for f in FRACTIONS}
        for k, test_idx in enumerate(folds):
            test = set(test_idx.tolist())
            train = [s for j, s in enumerate(scenes) if j not in test]
            model, _, _ = train_or_load(
                name,
                train,
                seed=0,
                epochs=args.epochs,
                model_dir=Path(args.models) / f"fold-{k}" / name,
            )
            preds = [(model.predict(scenes[j].image), scenes[j].label) for j in sorted(test)]
            for (i, f), values in per_setting.items():
                c = Confusion()
                for pred, truth in preds:
                    c = c + Confusion.from_masks(
                        denoise(pred, iterations=i, min_area_fraction=f).mask, truth
                    )
                values.append(c.metrics()["iou"])
        iou[name] = {f"{i}/{f}": float(np.mean(v)) for (i, f), v in per_setting.items()}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(
        json.dumps(
            {"machine": machine(), "iterations": ITERATIONS, "fractions": FRACTIONS, "iou": iou},
            indent=1,
        )
        + "\n"
    )
    head = " | ".join(f"{i} it, {100 * f:g} %" for i in ITERATIONS for f in FRACTIONS)
    print(f"| classifier | {head} |")
    print("|---|" + "---|" * (len(ITERATIONS) * len(FRACTIONS)))
    for name, row in iou.items():
        print(
            f"| {name} | "
            + " | ".join(f"{row[f'{i}/{f}']:.3f}" for i in ITERATIONS for f in FRACTIONS)
            + " |"
        )


if __name__ == "__main__":
    main()
