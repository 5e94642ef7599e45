"""Latency and peak memory of each classifier per WFOV scene, native and through ONNX Runtime.

Every classifier that exports to ONNX is trained on four 256 px synthetic scenes
(U-Nets for 2 epochs: latency does not depend on how well a model is trained),
saved, exported with ``dyntarget.perceive.onnx_export.export_onnx`` and timed on one
synthetic scene per WFOV size: median of the repeats after a warm-up, and the
peak resident memory above the start (see ``dyntarget.evaluate.bench.measure``).
The largest difference between the two outputs is reported too. A second table puts
the static INT8 models (``quantize_int8``, calibrated on the training scenes) beside
FP32 ONNX: latency and peak memory at each size, file size, largest probability
difference (their IoU on held-out scenes: ``benchmarks/infer_iou.py``).

    python benchmarks/onnx_latency.py [--sizes 128,512,1024] [--repeats 5]
        [--out docs/benchmarks/onnx_latency.json] [--markdown docs/benchmarks/onnx_latency.md]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from dyntarget.evaluate.bench import machine, measure
from dyntarget.evaluate.tables import markdown_table
from dyntarget.perceive import CLASSIFIERS, make_classifier
from dyntarget.perceive.int8 import INT8_SUPPORTED, quantize_int8
from dyntarget.perceive.onnx import load_onnx
from dyntarget.perceive.onnx_export import export_onnx
from dyntarget.perceive.resources import keep_freed_memory
from dyntarget.synth import generate_scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="128,512,1024")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default="docs/benchmarks/onnx_latency.json")
    ap.add_argument("--markdown", default="docs/benchmarks/onnx_latency.md")
    args = ap.parse_args()
    keep_freed_memory()  # as the dyntarget command does
    sizes = [int(s) for s in args.sizes.split(",")]
    train = [generate_scene(1, i, size=256)[0] for i in range(4)]
    images = {s: generate_scene(0, 0, size=s)[0].image for s in sizes}
    rows, records, int8_rows = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name in CLASSIFIERS.available():
            if name == "band-threshold":
                continue
            kw = {"epochs": 2} if CLASSIFIERS.get(name).kind == "unet" else {}
            native = make_classifier(name, **kw).fit(train)
            native.save(Path(tmp) / name)
            export_onnx(native, Path(tmp) / name)
            twin = load_onnx(Path(tmp) / name)
            row = {"classifier": name}
            for size in sizes:
                img = images[size]
                a = measure(lambda m=native, i=img: m.predict_proba(i), repeats=args.repeats)
                b = measure(lambda m=twin, i=img: m.predict_proba(i), repeats=args.repeats)
                diff = float(np.abs(native.predict_proba(img) - twin.predict_proba(img)).max())
                records.append(
                    {"classifier": name, "size": size, "native": a, "onnx": b, "max_abs_diff": diff}
                )
                row[f"{size} px native / ONNX (ms)"] = (
                    f"{1000 * a['median_s']:.1f} / {1000 * b['median_s']:.1f}"
                )
                row[f"{size} px peak MiB native / ONNX"] = (
                    f"{a['peak_mib']:.0f} / {b['peak_mib']:.0f}"
                    if a["peak_mib"] is not None
                    else "n/a"
                )
            row["max abs diff"] = max(r["max_abs_diff"] for r in records if r["classifier"] == name)
            rows.append(row)
            print(row, flush=True)
            if name in INT8_SUPPORTED:
                int8_rows.append(_int8_row(name, Path(tmp) / name, twin, train, images, args))
                print(int8_rows[-1], flush=True)
    result = {
        "machine": machine(),
        "repeats": args.repeats,
        "sizes": sizes,
        "records": records,
        "int8": int8_rows,
    }
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    table = markdown_table(rows, list(rows[0]), digits=7)
    table += "\nINT8 against FP32 (ONNX Runtime):\n\n" + markdown_table(
        int8_rows, list(int8_rows[0]), digits=4
    )
    Path(args.markdown).write_text(table)
    print(table)


def _int8_row(name, mdir, fp32, train, images, args) -> dict:
    quantize_int8(mdir, [s.image for s in train])
    int8 = load_onnx(mdir, int8=True)
    row = {"classifier": name}
    diff = 0.0
    for size, img in images.items():
        a = measure(lambda m=fp32, i=img: m.predict_proba(i), repeats=args.repeats)
        b = measure(lambda m=int8, i=img: m.predict_proba(i), repeats=args.repeats)
        row[f"{size} px FP32 / INT8 (ms)"] = (
            f"{1000 * a['median_s']:.1f} / {1000 * b['median_s']:.1f}"
        )
        if a["peak_mib"] is not None:
            row[f"{size} px peak MiB FP32 / INT8"] = f"{a['peak_mib']:.0f} / {b['peak_mib']:.0f}"
        diff = max(diff, float(np.abs(fp32.predict_proba(img) - int8.predict_proba(img)).max()))
    kib = [(mdir / f).stat().st_size / 1024 for f in ("model.onnx", "model.int8.onnx")]
    row["file KiB FP32 / INT8"] = f"{kib[0]:.0f} / {kib[1]:.0f}"
    row["max abs diff"] = diff
    return row


if __name__ == "__main__":
    main()
