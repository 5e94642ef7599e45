"""The pass loop's time per frame, before and after a change, as whole processes side by side.

Each run is a fresh ``python`` process with one checkout's ``src`` first on
``PYTHONPATH`` that flies one strip (``dyntarget synth --strip --flat``, 256 px wide,
``--length`` px long, factor 4: 15 frames at the default 2048) and prints every frame's ``loop_s`` (all onboard work on a frame:
classify, denoise, predict, plan, de-duplicate, schedule; :class:`dyntarget.passes.record.FrameRecord`).
The two checkouts alternate, ``--repeats`` times, on the same machine in one run;
the table gives, per case, the median over the runs of each run's median per frame.

Cases: the truth (oracle) and a logistic-regression model, static (``none``) and
predictive (``two-looks``) planning, under ``fast`` agility, with a fixed compute
budget (one schedule per frame) and measured (no budget).

Usage::

    python benchmarks/loop_frame.py --before /tmp/39b-before --after . --repeats 5
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import json, sys
from dyntarget.fly import PassConfig, fly_pass
try:
    from dyntarget.synth.strip_world import load_world
except ImportError:  # a checkout from before issue 39
    from dyntarget.fly.strip import load_world
strip, model, predict, budget = sys.argv[1:5]
world = load_world(strip)
classifier = None
if model != "-":
    from dyntarget.perceive import load_classifier
    classifier = load_classifier(model)
config = PassConfig(
    planner="lawnmower-transect", agility="fast", predict=predict,
    compute_budget_s=None if budget == "-" else float(budget),
)
result = fly_pass(world, classifier, config)
print(json.dumps([r.loop_s for r in result.records if not r.dropped]))
"""

CASES = [
    (model, predict, budget)
    for model in ("truth", "lr")
    for predict in ("none", "two-looks")
    for budget in ("0.05", "-")
]


def _run(src: Path, strip: Path, model: str, predict: str, budget: str) -> float:
    env = {**os.environ, "PYTHONPATH": str(src / "src")}
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(strip), model, predict, budget],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return statistics.median(json.loads(out.stdout.strip().splitlines()[-1]))


def main() -> None:
    """Run the cases on both checkouts, alternating, and print the table (and ``--json``)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, type=Path, help="checkout before the change")
    ap.add_argument("--after", default=Path("."), type=Path, help="checkout after (default .)")
    ap.add_argument("--repeats", type=int, default=5, help="runs per case and checkout")
    ap.add_argument("--length", type=int, default=2048, help="strip length, px (default 2048)")
    ap.add_argument("--json", type=Path, help="also write the numbers here")
    args = ap.parse_args()
    before, after = args.before.resolve(), args.after.resolve()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        env = {**os.environ, "PYTHONPATH": str(after / "src")}
        synth = [sys.executable, "-m", "dyntarget.cli", "synth", "--quiet", "--seed", "0"]
        subprocess.run([*synth, "--strip", "--scenes", "1", "--size", "256", "--plumes", "4",
                        "--length", str(args.length), "--flat", "--out", str(work / "strips")],
                       env=env, check=True)  # fmt: skip
        subprocess.run([*synth, "--scenes", "2", "--size", "256", "--out", str(work / "sc")],
                       env=env, check=True)  # fmt: skip
        subprocess.run([sys.executable, "-m", "dyntarget.cli", "train", "--data", str(work / "sc"),
                        "--classifier", "logistic-regression", "--out", str(work / "lr")],
                       env=env, check=True, capture_output=True)  # fmt: skip
        strip = work / "strips" / "strip-0000.tif"
        rows = []
        for model, predict, budget in CASES:
            m = "-" if model == "truth" else str(work / "lr")
            times: dict[str, list[float]] = {"before": [], "after": []}
            for _ in range(args.repeats):
                for name, src in (("before", before), ("after", after)):
                    times[name].append(_run(src, strip, m, predict, budget))
            b, a = statistics.median(times["before"]), statistics.median(times["after"])
            rows.append({
                "model": model, "predict": predict,
                "budget_s": None if budget == "-" else float(budget),
                "before_ms": round(1e3 * b, 3), "after_ms": round(1e3 * a, 3),
                "after_over_before": round(a / b, 3),
                "runs_before_ms": [round(1e3 * t, 3) for t in times["before"]],
                "runs_after_ms": [round(1e3 * t, 3) for t in times["after"]],
            })  # fmt: skip
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"median over {args.repeats} runs of each run's median loop_s per frame")  # fmt: skip
    print("| model | predict | budget | before ms | after ms | after/before |")
    print("|---|---|---|---:|---:|---:|")
    for r in rows:
        budget = "measured" if r["budget_s"] is None else f"{r['budget_s']:g} s"
        print(f"| {r['model']} | {r['predict']} | {budget} | {r['before_ms']:.2f} | "
              f"{r['after_ms']:.2f} | {r['after_over_before']:.2f} |")  # fmt: skip
    if args.json:  # the rows with the command and the machine (this checkout's commit)
        from dyntarget.evaluate.bench import machine

        command = f"python benchmarks/loop_frame.py --before BEFORE_CHECKOUT --after {args.after} "
        command += f"--repeats {args.repeats} --length {args.length} --json {args.json}"
        record = {"command": command, "machine": machine(), "result": rows}
        args.json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
