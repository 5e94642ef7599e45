"""Table 1 IoU of the inference paths on held-out scenes: halo vs blend, INT8 vs FP32.

The cross-validation of Table 1 (``CVConfig``: 5 folds, seed 0, WFOV factor 4, U-Nets
50 epochs): for each fold the U-Nets and the MLP are trained on the other folds (or
reused from ``--models DIR/fold-K/NAME``, e.g. ``reproduce/models``) and predict the
held-out scenes with

* ``blend``: the former stitching (64 px tiles at stride 32, blended);
* ``halo``: the default (whole image / large windows with a receptive-field halo);
* ``onnx-fp32`` and ``onnx-int8``: ONNX Runtime, halo stitching, FP32 and static INT8
  (calibrated on the fold's training tiles).

Raw (not denoised) pixel counts are summed per fold; IoU is the mean over folds, as in
Table 1. The largest per-pixel probability difference to ``halo`` is reported too.

    python benchmarks/infer_iou.py --data scenes/ [--models reproduce/models]
        [--out docs/benchmarks/infer_iou.json] [--markdown docs/benchmarks/infer_iou.md]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.crossval import CVConfig, kfold_indices, train_or_load
from dyntarget.evaluate.metrics import Confusion
from dyntarget.evaluate.tables import markdown_table
from dyntarget.io import read_scene_dir
from dyntarget.perceive.int8 import quantize_int8
from dyntarget.perceive.onnx import load_onnx
from dyntarget.perceive.onnx_export import export_onnx

PATHS = ("blend", "halo", "onnx-fp32", "onnx-int8")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="labelled scene directory (as for reproduce)")
    ap.add_argument("--models", help="reuse/keep trained models here (DIR/fold-K/NAME)")
    ap.add_argument("--classifiers", default="unet-xception,unet-uavsar,mlp")
    ap.add_argument("--epochs", type=int, default=50)
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--out", default="docs/benchmarks/infer_iou.json")
    ap.add_argument("--markdown", default="docs/benchmarks/infer_iou.md")
    args = ap.parse_args()
    config = CVConfig(folds=args.folds, epochs=args.epochs)
    wfov = [s.to_wfov(config.factor) for s in read_scene_dir(args.data, require_labels=True)]
    folds = kfold_indices(len(wfov), config.folds, config.seed)
    names = args.classifiers.split(",")
    counts = {(n, p): [] for n in names for p in PATHS}
    diffs = {(n, p): 0.0 for n in names for p in PATHS}
    with tempfile.TemporaryDirectory() as tmp:
        for k, test in enumerate(folds):
            held = set(test.tolist())
            train = [s for i, s in enumerate(wfov) if i not in held]
            for name in names:
                where = Path(args.models) / f"fold-{k}" / name if args.models else None
                model, _, _ = train_or_load(
                    name, train, seed=config.seed, epochs=config.epochs, model_dir=where
                )
                mdir = Path(tmp) / f"{k}-{name}"
                model.save(mdir)
                export_onnx(model, mdir)
                quantize_int8(mdir, [s.image for s in train], seed=config.seed)
                runners = {"onnx-fp32": load_onnx(mdir), "onnx-int8": load_onnx(mdir, int8=True)}
                per_path = {p: Confusion() for p in PATHS}
                for i in test:
                    s = wfov[i]
                    probs = {}
                    if hasattr(model, "set_stitching"):
                        probs["blend"] = model.set_stitching("blend").predict_proba(s.image)
                        probs["halo"] = model.set_stitching("halo").predict_proba(s.image)
                    else:  # pixel classifiers have no stitching
                        probs["blend"] = probs["halo"] = model.predict_proba(s.image)
                    for p, runner in runners.items():
                        probs[p] = runner.predict_proba(s.image)
                    for p, prob in probs.items():
                        pred = (prob >= 0.5) & s.valid_mask
                        per_path[p] = per_path[p] + Confusion.from_masks(pred, s.label, s.valid)
                        diffs[name, p] = max(
                            diffs[name, p], float(np.abs(prob - probs["halo"]).max())
                        )
                for p in PATHS:
                    counts[name, p].append(per_path[p].metrics()["iou"])
                print(
                    f"fold {k} {name}: "
                    + ", ".join(f"{p} {counts[name, p][-1]:.4f}" for p in PATHS),
                    flush=True,
                )
    rows = []
    for name in names:
        row = {"classifier": name}
        for p in PATHS:
            row[f"IoU {p}"] = float(np.mean(counts[name, p]))
        row["halo - blend"] = row["IoU halo"] - row["IoU blend"]
        row["int8 - fp32"] = row["IoU onnx-int8"] - row["IoU onnx-fp32"]
        row["max abs diff to halo: blend / int8"] = (
            f"{diffs[name, 'blend']:.4f} / {diffs[name, 'onnx-int8']:.4f}"
        )
        rows.append(row)
    result = {
        "machine": machine(),
        "config": {"folds": config.folds, "epochs": config.epochs, "seed": config.seed},
        "per_fold_iou": {f"{n}|{p}": v for (n, p), v in counts.items()},
        "rows": rows,
    }
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    table = markdown_table(rows, list(rows[0]), digits=4)
    Path(args.markdown).write_text(table)
    print(table)


if __name__ == "__main__":
    main()
