"""Whole-process start-up: ``dyntarget`` commands timed from the shell, start to exit.

Each command runs ``--runs`` times (after one untimed warm-up run that fills the
file cache) as a fresh process; the table gives the median and the worst wall
time and the median peak resident memory of the process (``ru_maxrss`` from
``os.wait4``, the child's own high-water mark). The inputs are made first with
the CLI itself: one synthetic 1024 px scene (image + mask) and a random forest
trained on four 256 px scenes, exported to ONNX.

    python benchmarks/startup.py [--runs 7] [--work DIR]
        [--out docs/benchmarks/startup.json] [--markdown docs/benchmarks/startup.md]

``--dyntarget V/bin/dyntarget`` times another install's console script (e.g. the lean
``pip install "dyntarget[onboard]"`` venv), the inputs still being made by this
interpreter's; ``--skip-native`` leaves out the native random forest (an onboard install
has no scikit-learn).

The targets are those of issue 13 (a 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.tables import markdown_table
from dyntarget.io.atomic import write_text

PLANNER = "lawnmower-transect"


def dyntarget_command() -> list[str]:
    """The console script (what a user runs), else ``python -m dyntarget``.

    The script beside this interpreter comes first: a version manager's shim on PATH (pyenv)
    would add its own start-up to every measurement.
    """
    beside = Path(sys.executable).with_name("dyntarget")
    script = str(beside) if beside.is_file() else shutil.which("dyntarget")
    return [script] if script else [sys.executable, "-m", "dyntarget"]


def run_once(argv: list[str]) -> tuple[float, float]:
    """Wall seconds and peak resident MiB of one process running ``argv``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} exited {proc.returncode}: {err.strip()}")
    return seconds, usage.ru_maxrss / 1024  # Linux: KiB


def prepare(work: Path, cli: list[str]) -> dict[str, Path]:
    """The inputs: a 1024 px scene with its mask, and a random forest with its ONNX export."""
    scene_dir, train_dir, model = work / "scene", work / "train", work / "rf"
    if not scene_dir.exists():
        subprocess.run(
            [*cli, "synth", "--scenes", "1", "--size", "1024", "--seed", "3", "--out", str(scene_dir), "--quiet"],
            check=True,
        )  # fmt: skip
    if not model.exists():
        subprocess.run(
            [*cli, "synth", "--scenes", "4", "--size", "256", "--seed", "1", "--out", str(train_dir), "--quiet"],
            check=True,
        )  # fmt: skip
        subprocess.run(
            [*cli, "train", "--data", str(train_dir), "--classifier", "random-forest", "--factor", "1", "--out", str(model)],
            check=True, stdout=subprocess.DEVNULL,
        )  # fmt: skip
        subprocess.run([*cli, "export-onnx", str(model)], check=True, stdout=subprocess.DEVNULL)
    image = next(p for p in sorted(scene_dir.glob("*.tif")) if not p.stem.endswith("_mask"))
    mask = image.with_name(f"{image.stem}_mask.tif")
    return {"image": image, "mask": mask, "model": model, "out": work / "trajectory.geojson"}


def commands(
    paths: dict[str, Path], native: bool = True
) -> list[tuple[str, list[str], float | None, float | None]]:
    """``(label, arguments, target seconds, target MiB)`` for each timed command."""
    plan = ["plan", str(paths["image"]), "--planner", PLANNER, "--out", str(paths["out"])]
    timed = [
        ("dyntarget --help", ["--help"], 0.5, None),
        ("dyntarget planners", ["planners"], 0.5, None),
        ("plan 1024 px --mask", [*plan, "--mask", str(paths["mask"])], 1.0, None),
        ("plan 1024 px --model rf --onnx", [*plan, "--model", str(paths["model"]), "--onnx"], 1.5, 250.0),
    ]  # fmt: skip
    if native:
        timed.append(
            (
                "plan 1024 px --model rf (native)",
                [*plan, "--model", str(paths["model"])],
                None,
                None,
            )
        )
    return timed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7, help="timed runs per command (default 7)")
    ap.add_argument("--work", help="folder for the inputs (default: a temporary folder)")
    ap.add_argument("--out", default="docs/benchmarks/startup.json")
    ap.add_argument("--markdown", default="docs/benchmarks/startup.md")
    ap.add_argument("--dyntarget", help="console script to time (default: this interpreter's)")
    ap.add_argument("--skip-native", action="store_true", help="leave out the native forest")
    args = ap.parse_args()
    cli = dyntarget_command()
    timed = [args.dyntarget] if args.dyntarget else cli
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.work or tmp)
        work.mkdir(parents=True, exist_ok=True)
        paths = prepare(work, cli)
        rows, records = [], []
        for label, argv, target_s, target_mib in commands(paths, native=not args.skip_native):
            run_once([*timed, *argv])  # warm-up: file cache, bytecode
            runs = [run_once([*timed, *argv]) for _ in range(args.runs)]
            seconds = [s for s, _ in runs]
            mib = [m for _, m in runs]
            median_s, rss = statistics.median(seconds), statistics.median(mib)
            met = (target_s is None or median_s <= target_s) and (
                target_mib is None or rss <= target_mib
            )
            records.append(
                {"command": label, "argv": argv[:1], "seconds": seconds, "peak_mib": mib}
            )
            target = " and ".join(
                t
                for t in (
                    f"≤ {target_s:g} s" if target_s else "",
                    f"≤ {target_mib:g} MB" if target_mib else "",
                )
                if t
            )
            rows.append(
                {
                    "Command": label,
                    "Median (s)": median_s,
                    "Worst (s)": max(seconds),
                    "Peak RSS (MiB)": rss,
                    "Target": target or "reported",
                    "Met": ("yes" if met else "NO") if target else "-",
                }
            )
            print(f"{label}: median {median_s:.3f} s, peak {rss:.0f} MiB", file=sys.stderr)
    columns = ["Command", "Median (s)", "Worst (s)", "Peak RSS (MiB)", "Target", "Met"]
    result = {
        "runs": args.runs,
        "command": [*timed[-1:]],
        "machine": machine(),
        "records": records,
        "rows": rows,
    }
    write_text(args.out, json.dumps(result, indent=1) + "\n")
    table = markdown_table(rows, columns)
    write_text(
        args.markdown,
        f"Whole processes from the shell, median of {args.runs} runs after a warm-up "
        f"(`python benchmarks/startup.py`; timed: `{args.dyntarget or 'dyntarget'}`).\n\n{table}\n",
    )
    print(table)


if __name__ == "__main__":
    main()
