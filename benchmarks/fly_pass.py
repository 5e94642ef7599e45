"""Fly passes: loop latency at 1024 px, pass results per planner mode and preset, lean memory.

Three parts (each writes JSON and a Markdown table into ``--out``, default
``docs/benchmarks``):

``latency``
    One long-lived process flies a moving strip with 1024 x 1024 px WFOV frames
    (factor 1, 32 m), every frame classified by the given model (``--onnx``: its
    ONNX export), measured latency. Per frame: ``loop_s`` (all onboard work on
    the frame: classify, denoise, predict, plan, de-duplicate, schedule) and the
    in-process stage sum; median and worst over the frames, and their ratio.
``passes``
    Dynamic strips (``--strips`` of them, 8 frames, 4 vents each, 256 px wide at
    factor 4) flown by one planner with static planning (``none``) and
    predictive planning (``wind``: the strip's own wind as prior; ``two-looks``),
    under ``fast`` and ``slow`` agility; compute latency fixed at
    ``--budget-s`` so the table is deterministic. Utility, plume px, ratio plume,
    plumes observed, summed over the strips.
``memory``
    The live mode (``fly --watch``) of ``--python`` (e.g. the lean onboard
    venv's interpreter) plans 1024 px frames from the ONNX model in a child
    process; its peak resident memory (``ru_maxrss``) and per-frame times. With
    ``--venv``, the venv's installed size.

Commands the lead re-runs on a quiet machine (see docs/onboard.md, "Flying a pass")::

    python benchmarks/fly_pass.py latency --model MODEL --onnx
    python benchmarks/fly_pass.py passes --model MODEL --onnx
    python benchmarks/fly_pass.py memory --model MODEL --python VENV/bin/python --venv VENV
"""

from __future__ import annotations

import argparse
import csv
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dyntarget.evaluate.bench import machine
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.io.atomic import write_text
from dyntarget.synth.strip import strip_spec
from dyntarget.synth.strip_world import MovingStrip


def _classifier(model: str | None, onnx: bool):
    if model is None:
        return None
    if onnx:
        from dyntarget.perceive.onnx import load_onnx

        return load_onnx(model)
    from dyntarget.perceive import load_classifier

    return load_classifier(model)


def _save(out: Path, name: str, data: dict, table: str) -> None:
    data = {**data, "machine": machine()}
    write_text(out / f"{name}.json", json.dumps(data, indent=1) + "\n")
    write_text(out / f"{name}.md", table)
    print(table)


def latency(args) -> None:
    size = args.size
    spec, window = strip_spec(
        args.seed, width=size, length=size * 9 // 2, plumes=4, gsd=32.0, wind_mps=10.0
    )
    world = MovingStrip(spec, window, truth_step_s=5.0)
    classifier = _classifier(args.model, args.onnx)
    config = PassConfig(
        planner=args.planner, agility="fast", factor=1, predict=args.predict, overlap=0.5
    )
    # calibrate once (as onboard, before the first frame)
    classifier.predict_proba(world.image_at(0.0, 0, 64)[:, :, :64])
    result = fly_pass(world, classifier, config)
    recs = [r for r in result.records if not r.dropped]
    loop = np.array([r.loop_s for r in recs])
    stages = np.array([sum(r.stage_s.values()) for r in recs])
    cls = np.array([r.stage_s.get("classify", 0.0) for r in recs])
    data = {
        "frame_px": size,
        "frames": len(recs),
        "classifier": f"{getattr(classifier, 'name', '?')}{' (ONNX)' if args.onnx else ''}",
        "planner": args.planner,
        "predict": args.predict,
        "loop_median_s": float(np.median(loop)),
        "loop_worst_s": float(loop.max()),
        "stage_sum_median_s": float(np.median(stages)),
        "stage_sum_worst_s": float(stages.max()),
        "classify_median_s": float(np.median(cls)),
        "ratio_median": float(np.median(loop) / np.median(stages)),
        "stage_median_s": {
            k: float(np.median([r.stage_s.get(k, 0.0) for r in recs]))
            for k in ("classify", "denoise", "predict", "plan", "schedule")
        },
        "per_frame_loop_s": loop.round(4).tolist(),
        "per_frame_stage_sum_s": stages.round(4).tolist(),
        "per_frame_stage_s": [{k: round(v, 4) for k, v in r.stage_s.items()} for r in recs],
    }
    table = (
        f"Per-frame loop latency, {size} x {size} px WFOV frames, {data['classifier']}, "
        f"{args.planner}, predict {args.predict}, {len(recs)} frames in one process\n\n"
        "| | median (s) | worst (s) |\n|---|---|---|\n"
        f"| loop (all onboard work on a frame) | {data['loop_median_s']:.3f} | {data['loop_worst_s']:.3f} |\n"
        f"| in-process stage sum | {data['stage_sum_median_s']:.3f} | {data['stage_sum_worst_s']:.3f} |\n"
        + "".join(f"| of which {k} | {v:.3f} | |\n" for k, v in data["stage_median_s"].items())
        + "\n"
        f"loop / stage sum (medians): {data['ratio_median']:.2f}\n"
    )
    _save(Path(args.out), "fly_latency", data, table)


def passes(args) -> None:
    classifier = _classifier(args.model, args.onnx)
    rows = []
    worlds = []
    for i in range(args.strips):
        spec, window = strip_spec(args.seed + i, width=256, length=1152, plumes=4, gsd=8.0)
        worlds.append(MovingStrip(spec, window, truth_step_s=1.0))
    for agility in ("fast", "slow"):
        for mode in ("none", "wind", "two-looks"):
            tot = {"utility": 0.0, "plume_px": 0.0, "flown": 0, "observed": 0, "total": 0}
            for w in worlds:
                cfg = PassConfig(
                    planner=args.planner,
                    agility=agility,
                    predict=mode,
                    compute_budget_s=args.budget_s,
                )
                t = fly_pass(w, classifier, cfg).totals()
                tot["utility"] += t["utility"]
                tot["plume_px"] += t["plume_px"]
                tot["flown"] += t["pointings_flown"]
                tot["observed"] += t["plumes_observed"]
                tot["total"] += t["plumes_total"]
            ratio = tot["plume_px"] / tot["flown"] if tot["flown"] else 0.0
            rows.append({"agility": agility, "predict": mode, **tot, "ratio_plume": ratio})
    n = args.strips
    table = (
        f"{n} dynamic strips (8 frames, 4 vents, 256 x 1152 px at 8 m, WFOV factor 4), "
        f"{args.planner}, classifier "
        f"{'truth mask' if classifier is None else classifier.name + (' (ONNX)' if args.onnx else '')}, "
        f"compute latency fixed at {args.budget_s:g} s per frame; sums over the strips\n\n"
        "| agility | planning | utility | plume px | pointings flown | ratio plume "
        "| plumes observed |\n|---|---|---|---|---|---|---|\n"
    )
    for r in rows:
        table += (
            f"| {r['agility']} | {'static' if r['predict'] == 'none' else 'predictive: ' + r['predict']} "
            f"| {r['utility']:.1f} | {r['plume_px']:.1f} | {r['flown']} | {r['ratio_plume']:.3f} "
            f"| {r['observed']} of {r['total']} |\n"
        )
    _save(Path(args.out), "fly_passes", {"rows": rows, "strips": n}, table)


WATCH_CHILD = """
import resource, subprocess, sys, json
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"rc": done.returncode, "peak_kb": peak, "err": done.stderr[-2000:]}))
"""


def memory(args) -> None:
    tmp = Path(tempfile.mkdtemp(prefix="fly-memory-"))
    size = args.size
    spec, window = strip_spec(args.seed, width=size, length=size, plumes=1, gsd=32.0)
    frames = tmp / "frames"
    frames.mkdir()
    world = MovingStrip(spec, window)
    from dyntarget.io import write_scene

    for k in range(args.frames):
        scene = world.world.scene(k * 2.3, window, id=f"f{k:03d}")
        write_scene(scene.__class__(scene.image, gsd=scene.gsd, id=scene.id), frames)
    cmd = [args.python, "-m", "dyntarget", "fly", "--watch", str(frames), "--model", args.model]
    cmd += ["--onnx", "--factor", "1", "--out", str(tmp / "plans"), "--settle-s", "0"]
    cmd += ["--max-frames", str(args.frames), "--agility", "fast", "--planner", args.planner]
    t0 = time.perf_counter()
    probe = subprocess.run(
        [sys.executable, "-c", WATCH_CHILD, *cmd], capture_output=True, text=True, check=True
    )
    wall = time.perf_counter() - t0
    res = json.loads(probe.stdout.strip().splitlines()[-1])
    if res["rc"] != 0:
        raise SystemExit(f"fly --watch failed: {res['err']}")
    with open(tmp / "plans" / "frames.csv", newline="") as f:
        per = np.array([float(r["planned_s"]) for r in csv.DictReader(f)])
    data = {
        "python": args.python,
        "frame_px": size,
        "frames": len(per),
        "peak_rss_mb": res["peak_kb"] / 1024,
        "wall_s": wall,
        "per_frame_median_s": float(np.median(per)),
        "per_frame_worst_s": float(per.max()),
    }
    if args.venv:
        site = subprocess.run(
            ["du", "-sm", args.venv], capture_output=True, text=True, check=True
        ).stdout.split()[0]
        data["venv_mb"] = int(site)
    table = (
        f"Live mode (fly --watch, {args.python}): {len(per)} frames of {size} x {size} px from the "
        "ONNX model\n\n| peak memory (MB) | per frame median / worst (s) | installed size (MB) |\n"
        "|---|---|---|\n"
        f"| {data['peak_rss_mb']:.0f} | {data['per_frame_median_s']:.3f} / "
        f"{data['per_frame_worst_s']:.3f} | {data.get('venv_mb', '-')} |\n"
    )
    _save(Path(args.out), "fly_memory", data, table)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("part", choices=["latency", "passes", "memory"])
    p.add_argument("--model", help="trained model directory (with model.onnx for --onnx)")
    p.add_argument("--onnx", action="store_true", help="run the model's ONNX export")
    p.add_argument("--planner", default="lawnmower-transect")
    p.add_argument("--predict", default="wind", help="latency: planning mode (default wind)")
    p.add_argument("--size", type=int, default=1024, help="WFOV frame px (latency, memory)")
    p.add_argument("--strips", type=int, default=5, help="passes: number of strips")
    p.add_argument("--budget-s", type=float, default=0.25, help="passes: compute per frame")
    p.add_argument("--frames", type=int, default=8, help="memory: frames to plan")
    p.add_argument("--python", default=sys.executable, help="memory: interpreter to run")
    p.add_argument("--venv", help="memory: venv whose size to report")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="docs/benchmarks")
    args = p.parse_args()
    if args.part in ("latency", "memory") and not args.model:
        p.error(f"{args.part} needs --model")
    {"latency": latency, "passes": passes, "memory": memory}[args.part](args)
    print(
        f"peak memory of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB",
        file=sys.stderr,
    )


if __name__ == "__main__":
    main()
