"""Whole-process ``dyntarget plan --model RF`` at 1024 px: the forest kernel's paths
against the portable path (no kernel), before and after, in one run on one machine.

The portable path is what a machine gets where no forest kernel runs (no C compiler and
none installed, e.g. an aarch64 flight computer): ``DYNTARGET_FOREST_ISA=off`` forces it
here. Before this round it was scikit-learn's ``predict_proba``; now it is ONNX Runtime's
tree ensemble on the forest's double-precision graph (``dyntarget.perceive.ensemble``,
bit-identical). The rows, each a fresh process from the shell, run round-robin (one run
of each row per round, so load hits every row alike) after one warm-up round:

* ``avx2``: the kernel forced to its AVX2 path (the issue's reference);
* ``avx512``: the kernel's AVX-512 path, where this CPU has it;
* ``portable, after``: no kernel, this checkout (ONNX Runtime's tree ensemble, its graph
  cached by an earlier run); ``portable, after, first run``: the same with an empty cache
  each run (the graph built with ``onnx`` in the run, as the first process on a machine);
* ``portable, before``: no kernel, the code given by ``--before-src`` (scikit-learn);
* ``--onnx, no kernel``, after and before: the onboard command. After, the packed forest
  runs as the same tree ensemble where its graph is cached (here: the full install builds
  it); before, ``model.onnx`` runs (ONNX Runtime, float), which is what the lean install
  still runs where no graph is cached.

The data are made here: four 128 px training scenes and one 1024 px scene (``synth``,
seeds 0 and 3, 8 m GSD), a random forest trained on them (``train --factor 1``: 50 trees,
depth <= 14) and its ONNX export. Each row records whether its plan equals the ``avx2``
row's byte for byte (the float ``model.onnx`` may differ; the other paths are
bit-identical).

    python benchmarks/portable_forest.py --before-src OLD/src [--runs 7]
        [--out docs/benchmarks/portable_forest.json]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from dyntarget.evaluate.bench import machine
from dyntarget.io.atomic import write_text

COLD = "portable, after, first run"
"""The row whose every run starts with an empty cache: the graph is built (``onnx``
imported) in the run, as in the first process on a machine."""

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"
sys.path.insert(0, str(HERE))
import plan_rf_process  # noqa: E402  (its run_once times one process)


def run_once(argv: list[str], env: dict[str, str]) -> dict:
    """Wall seconds, peak MiB, CPU seconds and the logged classify seconds of one process."""
    wall, peak, classify, cpu = plan_rf_process.run_once(argv, env)
    return {"wall_s": wall, "peak_mib": peak, "cpu_s": cpu, "classify_s": classify}


def dyntarget(args: list[str], *, src: Path, isa: str | None = None, cache: Path) -> tuple:
    env = {**os.environ, "PYTHONPATH": str(src), "DYNTARGET_CACHE": str(cache)}
    env.pop("DYNTARGET_FOREST_ISA", None)
    if isa is not None:
        env["DYNTARGET_FOREST_ISA"] = isa
    return [sys.executable, "-m", "dyntarget.cli", "--debug", *args], env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before-src", required=True, help="src/ of the code before")
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--out", default="docs/benchmarks/portable_forest.json")
    a = parser.parse_args()
    from dyntarget.perceive import compiled

    work = Path(tempfile.mkdtemp(prefix="portable-forest-"))
    cache = work / "cache"
    setup = [
        ["synth", "--scenes", "4", "--size", "128", "--seed", "0", "--out", str(work / "train"), "--quiet"],
        ["synth", "--scenes", "1", "--size", "1024", "--seed", "3", "--out", str(work / "scene"), "--quiet"],
        ["train", "--data", str(work / "train"), "--classifier", "random-forest", "--factor", "1",
         "--out", str(work / "rf")],
        ["export-onnx", str(work / "rf"), "--targets", "none"],
    ]  # fmt: skip
    for args in setup:
        argv, env = dyntarget(args, src=SRC, cache=cache)
        subprocess.run(argv, env=env, check=True, stdout=subprocess.DEVNULL)
    image = next((work / "scene").glob("*[0-9].tif"))
    rows = [("avx2", SRC, "avx2", []), ("avx512", SRC, "avx512", [])]
    rows = [r for r in rows if compiled.cpu_runs(r[2])]
    rows += [
        ("portable, after", SRC, "off", []),
        (COLD, SRC, "off", []),
        ("portable, before", Path(a.before_src).resolve(), "off", []),
        ("--onnx, no kernel, after", SRC, "off", ["--onnx"]),
        ("--onnx, no kernel, before", Path(a.before_src).resolve(), "off", ["--onnx"]),
    ]
    commands = {}
    for name, src, isa, extra in rows:
        out = work / f"{re.sub('[^a-z0-9]+', '-', name)}.geojson"
        args = ["plan", str(image), "--model", str(work / "rf"), *extra]
        args += ["--planner", "lawnmower-transect", "--out", str(out)]
        commands[name] = (*dyntarget(args, src=src, isa=isa, cache=cache), out, args, isa)
    load_start = round(os.getloadavg()[0], 2)
    for argv, env, *_ in commands.values():  # warm-up: file cache, kernel build, graph cache
        run_once(argv, env)
    runs: dict[str, list[dict]] = {name: [] for name in commands}
    for i in range(a.runs):
        for name, (argv, env, *_) in commands.items():
            if name == COLD:  # an empty cache of its own: the graph is built in this run
                env = {**env, "DYNTARGET_CACHE": str(work / f"cold-{i}")}
            runs[name].append(run_once(argv, env))
    reference = commands[rows[0][0]][2].read_bytes()
    result = []
    for name, (_, _, out, args, isa) in commands.items():
        walls = [r["wall_s"] for r in runs[name]]
        classify = [r["classify_s"] for r in runs[name] if r["classify_s"] is not None]
        result.append(
            {
                "row": name,
                "command": f"DYNTARGET_FOREST_ISA={isa} dyntarget " + " ".join(args),
                "wall_s": walls,
                "wall_median_s": statistics.median(walls),
                "classify_median_s": statistics.median(classify) if classify else None,
                "cpu_median_s": statistics.median(r["cpu_s"] for r in runs[name]),
                "peak_mib_median": statistics.median(r["peak_mib"] for r in runs[name]),
                "plan_equals_avx2": out.read_bytes() == reference,
            }
        )
    base = result[0]["wall_median_s"]
    for r in result:
        r["vs_avx2"] = r["wall_median_s"] / base
    record = {
        "runs": a.runs,
        "load_1min_start": load_start,
        "load_1min_end": round(os.getloadavg()[0], 2),
        "rows": result,
        "machine": machine(),
    }
    write_text(Path(a.out), json.dumps(record, indent=2) + "\n")
    shutil.rmtree(work)
    for r in result:
        print(
            f"{r['row']:<20} wall {r['wall_median_s']:.3f} s ({r['vs_avx2']:.2f}x avx2)  "
            f"classify {r['classify_median_s'] or 0:.3f} s  peak {r['peak_mib_median']:.0f} MiB  "
            f"same plan: {r['plan_equals_avx2']}"
        )


if __name__ == "__main__":
    main()
