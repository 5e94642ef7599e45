"""Whole-process time of ``dyntarget plan --model RF`` (native) and what it imports.

Runs the command ``--runs`` times as a fresh process (after one untimed warm-up run)
and records, per run, the wall time start to exit, the peak resident memory
(``ru_maxrss``), the CPU time (user + system) and the classify time the command logs
(``classify N ms``), then once
more in a probe interpreter that prints which heavy packages were left in
``sys.modules`` (torch, sklearn, skops, scipy, onnxruntime).

    python benchmarks/plan_rf_process.py --image IMG.tif --model RF [--runs 5]
        [--label after] [--out docs/benchmarks/plan_rf_native.json]

The JSON keeps one entry per ``--label`` (re-running with another label adds to the file),
so a before/after pair sits side by side.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

from dyntarget.evaluate.bench import machine
from dyntarget.io.atomic import write_text

HEAVY = ("torch", "sklearn", "skops", "scipy", "onnxruntime")


def run_once(
    argv: list[str], env: dict[str, str] | None = None
) -> tuple[float, float, float | None, float]:
    """Wall seconds, peak MiB, the logged classify seconds and the CPU seconds (user + system,
    all threads) of one process (its environment ``env``, default this one's); the CPU
    seconds move less with other processes' load."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{argv} failed: {err}")
    found = re.search(r"classify ([0-9.]+) ms", err)
    cpu = usage.ru_utime + usage.ru_stime
    return seconds, usage.ru_maxrss / 1024, float(found.group(1)) / 1000 if found else None, cpu


def imported(args: list[str]) -> list[str]:
    """The heavy top-level packages left in ``sys.modules`` after ``main(args)``."""
    probe = (
        "import sys\nfrom dyntarget.cli import main\n"
        f"assert main({args!r}) == 0\n"
        f"print(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r})))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1].replace("'", '"'))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--image", required=True)
    parser.add_argument("--model", required=True)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--label", default="after")
    parser.add_argument("--out", default="docs/benchmarks/plan_rf_native.json")
    a = parser.parse_args()
    load_start = round(os.getloadavg()[0], 2)
    out = Path(a.out)
    args = ["plan", a.image, "--model", a.model, "--planner", "lawnmower-transect"]
    args += ["--out", str(Path(os.environ.get("TMPDIR", "/tmp")) / "plan_rf_process.geojson")]
    script = Path(sys.executable).with_name("dyntarget")
    argv = [str(script) if script.is_file() else "dyntarget", *args]
    run_once(argv)  # warm-up: file cache, the kernel's build cache
    runs = [run_once(argv) for _ in range(a.runs)]
    walls = [r[0] for r in runs]
    classify = [r[2] for r in runs if r[2] is not None]
    entry = {
        "command": " ".join(["dyntarget", *args]),
        "runs": a.runs,
        "wall_s": walls,
        "wall_median_s": statistics.median(walls),
        "classify_s": classify,
        "classify_median_s": statistics.median(classify) if classify else None,
        "rest_median_s": statistics.median(r[0] - (r[2] or 0.0) for r in runs),
        "peak_mib_median": statistics.median(r[1] for r in runs),
        "cpu_s": [r[3] for r in runs],
        "cpu_median_s": statistics.median(r[3] for r in runs),
        "load_1min_start": load_start,
        "heavy_imports": imported(args),
        "machine": machine(),
    }
    data = json.loads(out.read_text()) if out.is_file() else {}
    data[a.label] = entry
    write_text(out, json.dumps(data, indent=2) + "\n")
    print(json.dumps({k: v for k, v in entry.items() if k != "machine"}, indent=2))


if __name__ == "__main__":
    main()
