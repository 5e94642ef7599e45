"""UNET-Xception's classify time against its one-pass FLOP bound, each run under its own load.

Issue 43: the bench set the classify time against a matmul rate measured once, at the
start of the process, before training; on a loaded machine the two were measured under
different loads (4.9x "under load", 2.4x quiet). Here every timed classification is
bracketed by the bound's own probe, the best of three 2048-square float32 matrix
products on 1 thread and on every core (the higher rate: the stricter bound), measured
right before and right after it, and each run's ratio is its time over the FLOPs of
one pass over the image (``torch.utils.flop_counter`` on the network prediction runs)
at the higher of the two rates. The 1-minute load average is kept with each run.

The probe and the FLOP count are written out here rather than imported from
``dyntarget.evaluate.bench`` so that the script runs unchanged on an older checkout
(``PYTHONPATH=OLD/src``): before and after are then measured by the same code, as
whole processes taking turns in one shell loop::

    python benchmarks/unet_bound.py train --model /tmp/xcep
    for i in 1 2 3; do
      PYTHONPATH=/tmp/before/src python benchmarks/unet_bound.py run --model /tmp/xcep \\
          --label before --out /tmp/ub/before-$i.json
      python benchmarks/unet_bound.py run --model /tmp/xcep --label after \\
          --out /tmp/ub/after-$i.json
    done
    python benchmarks/unet_bound.py merge /tmp/ub/*.json --out docs/benchmarks/unet_bound.json

The model is the bench's: UNET-Xception (width 16) trained 2 epochs on four 256 px
synthetic scenes (latency does not depend on how well it is trained); the image is the
bench's synthetic 1024 px scene (``generate_scene(0, 0, size=1024)``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np


def matmul_rate(n: int = 2048, repeats: int = 3) -> dict:
    """Best float32 matmul rate now, over 1 thread and every core (FLOP/s)."""
    import torch

    cores = len(os.sched_getaffinity(0))
    a, b = torch.randn(n, n), torch.randn(n, n)
    before = torch.get_num_threads()
    rates = {}
    try:
        for threads in sorted({1, cores}):
            torch.set_num_threads(threads)
            best = float("inf")
            for _ in range(repeats):
                t0 = time.perf_counter()
                torch.mm(a, b)
                best = min(best, time.perf_counter() - t0)
            rates[str(threads)] = 2 * n**3 / best
    finally:
        torch.set_num_threads(before)
    return {"flop_per_s": max(rates.values()), "by_threads": rates}


def one_pass_flops(model, size: int) -> float:
    """FLOPs of one pass of the prediction network over a ``size`` px square image."""
    import torch
    from torch.utils.flop_counter import FlopCounterMode

    tile = model.tile
    with FlopCounterMode(display=False) as counter, torch.inference_mode():
        model.inference_network()(torch.zeros(1, 4, tile, tile))
    return counter.get_total_flops() * size * size / tile**2


def cpu() -> dict:
    model, flags = platform.machine(), set()
    with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
        for line in fh:
            key, _, value = line.partition(":")
            if key.strip() == "model name":
                model = value.strip()
            elif key.strip() == "flags":
                flags.update(value.split())
    wanted = ("avx2", "avx512f", "avx512_bf16", "amx_tile", "amx_bf16")
    return {
        "model": model,
        "cores": len(os.sched_getaffinity(0)),
        "flags": [f for f in wanted if f in flags],
    }


def train(args: argparse.Namespace) -> None:
    from dyntarget.perceive import make_classifier
    from dyntarget.synth import generate_scene

    scenes = [generate_scene(1, i, size=256)[0] for i in range(4)]
    make_classifier("unet-xception", epochs=2).fit(scenes).save(args.model)
    print(f"wrote {args.model}")


LOAD_CODE = """
import numpy as np
a = np.random.default_rng(0).random((512, 512), dtype=np.float32)
big = np.ones(16 << 20, np.float32)  # 64 MiB
while True:  # one core's worth of other work: compute, then memory traffic
    a = (a @ a) / np.float32(512)
    big = big * np.float32(1.0)
"""
"""What each ``--load`` process runs: a 512-square float32 product and a 64 MiB stream in
turn, on one thread (a stand-in for another user's job, compute- and memory-bound)."""


def start_load(n: int) -> list:
    """``n`` single-threaded load processes (:data:`LOAD_CODE`), given 2 s to get going."""
    import subprocess

    env = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    procs = [subprocess.Popen([sys.executable, "-c", LOAD_CODE], env=env) for _ in range(n)]
    time.sleep(2.0 if procs else 0.0)
    return procs


def run(args: argparse.Namespace) -> None:
    load = start_load(args.load)
    try:
        _run(args)
    finally:
        for proc in load:
            proc.kill()
            proc.wait()


def _run(args: argparse.Namespace) -> None:
    from dyntarget.perceive import resources

    # as the dyntarget command does at start, before torch loads (absent before issue 43's
    # spin bound: an older checkout then runs as it did)
    getattr(resources, "bound_openmp_spin", lambda: False)()
    import torch

    if args.threads:  # the thread count fixed, whatever the load (the comparison's other arm)
        resources.inference_threads = lambda limit=None: args.threads

    import dyntarget
    from dyntarget.perceive.resources import keep_freed_memory
    from dyntarget.perceive.unet import XceptionUNetClassifier
    from dyntarget.synth import generate_scene

    keep_freed_memory()  # as the dyntarget command does at start
    model = XceptionUNetClassifier.load(args.model)
    image = generate_scene(0, 0, size=args.size)[0].image
    flops = one_pass_flops(model, args.size)
    windows = len(model.stitching().windows(model.stitching().padded_shape(image.shape[1:])))
    reference = model.predict_proba(image)  # warm-up
    runs = []
    for _ in range(args.runs):
        before = matmul_rate()
        t0 = time.perf_counter()
        prob = model.predict_proba(image)
        seconds = time.perf_counter() - t0
        after = matmul_rate()
        rate = max(before["flop_per_s"], after["flop_per_s"])
        runs.append(
            {
                "classify_s": round(seconds, 4),
                "rate_before": before["by_threads"],
                "rate_after": after["by_threads"],
                "bound_s": round(flops / rate, 4),
                "ratio": round(seconds * rate / flops, 3),
                "load_1min": round(os.getloadavg()[0], 2),
                "threads": getattr(model, "threads_used", torch.get_num_threads()),
            }
        )
        print(json.dumps(runs[-1]), flush=True)
        assert np.array_equal(prob, reference)
    out = {
        "label": args.label,
        "dyntarget": str(Path(dyntarget.__file__).parent),
        "size": args.size,
        "one_pass_gflop": flops / 1e9,
        "windows": windows,
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "cpu": cpu(),
        "nice": os.nice(0),
        "gomp_spincount": os.environ.get("GOMP_SPINCOUNT"),
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
        "load_processes": args.load,
        "threads_fixed": args.threads or None,
        "runs": runs,
        "ratio_median": float(np.median([r["ratio"] for r in runs])),
        "classify_median_s": float(np.median([r["classify_s"] for r in runs])),
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


def merge(args: argparse.Namespace) -> None:
    parts = [json.loads(Path(p).read_text()) for p in args.files]
    summary = {}
    for label in dict.fromkeys(p["label"] for p in parts):
        runs = [r for p in parts if p["label"] == label for r in p["runs"]]
        ratios = [r["ratio"] for r in runs]
        summary[label] = {
            "processes": sum(p["label"] == label for p in parts),
            "runs": len(runs),
            "ratio_median": float(np.median(ratios)),
            "ratio_min": min(ratios),
            "ratio_max": max(ratios),
            "classify_median_s": float(np.median([r["classify_s"] for r in runs])),
            "bound_median_s": float(np.median([r["bound_s"] for r in runs])),
            "load_1min_range": [
                min(r["load_1min"] for r in runs),
                max(r["load_1min"] for r in runs),
            ],
            "windows": sorted({p["windows"] for p in parts if p["label"] == label}),
            "load_processes": sorted(
                {p.get("load_processes", 0) for p in parts if p["label"] == label}
            ),
            "threads": sorted({r["threads"] for r in runs}),
        }
    bench = []
    for path in args.bench or []:
        result = json.loads(Path(path).read_text())
        for rec in result["records"]:
            if rec["stage"] == "classify" and rec["classifier"] == "unet-xception":
                size = str(rec["size"])
                start = result["bounds"]["sizes"][size]["unet-xception"]["one_pass_s"]
                bench.append(
                    {
                        "file": Path(path).name,
                        "size": rec["size"],
                        "median_s": rec["median_s"],
                        "ratio_rate_at_start": rec["median_s"] / start,
                        "ratios_per_run": rec.get("ratios"),
                        "ratio_median_per_run": rec.get("ratio_median"),
                        "runs": rec.get("runs"),
                        "load_1min_at_end": result["machine"]["load_1min"],
                        "matmul_flop_per_s_at_start": result["bounds"]["rates"][
                            "matmul_flop_per_s"
                        ],
                    }
                )
    from dyntarget.evaluate.bench import machine

    out = {
        "command": " ".join(sys.argv),
        "machine": machine(),  # the machine and code, as every benchmark record names them
        "summary": summary,
        "processes": parts,
        "bench": bench,
    }
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(json.dumps(summary, indent=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("train", help="train and save the bench's UNET-Xception")
    p.add_argument("--model", required=True)
    p.set_defaults(func=train)
    p = sub.add_parser("run", help="time classification, each run between two bound probes")
    p.add_argument("--model", required=True)
    p.add_argument("--label", required=True)
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--runs", type=int, default=5)
    p.add_argument(
        "--load", type=int, default=0,
        help="single-threaded load processes running beside it (LOAD_CODE), bound and "
        "classification alike: a load that is the same from run to run",
    )  # fmt: skip
    p.add_argument(
        "--threads", type=int, default=0,
        help="fix a pass's threads instead of inference_threads()'s choice (0: its choice)",
    )  # fmt: skip
    p.add_argument("--out", required=True)
    p.set_defaults(func=run)
    p = sub.add_parser("merge", help="combine run files into one JSON with a summary")
    p.add_argument("files", nargs="+")
    p.add_argument("--bench", nargs="*", help="bench.json files whose UNET-Xception rows to add")
    p.add_argument("--out", required=True)
    p.set_defaults(func=merge)
    args = parser.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
