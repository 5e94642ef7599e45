"""Passes of real length: whole-process time, CPU time and peak memory of ``fly`` on long strips.

For every length (``--lengths``, km) one flat strip is synthesised (``synth --strip
--length-km --flat``, ``--density`` vents per 100 km, 256 px at 8 m), then flown once per
preset (``--presets``) the way a user flies it, from the shell::

    python -m dyntarget.cli fly --scene STRIP --truth --agility PRESET --out DIR --quiet

each in its own process, measured latency (no ``--compute-budget-s``). Recorded per pass:
the wall time of the whole process (start-up, world, every frame, the outputs), its CPU
time (user + system, from ``wait4``: what the wall time would be on an idle machine for
this single-threaded process), its peak resident memory, the frames, the median and
largest onboard loop time per frame (``loop_s`` of ``timeline.csv``), and the load average
before and after. Writes ``long_pass.json`` and ``long_pass.md`` into ``--out``.

    python benchmarks/long_pass.py --lengths 1000,3000 --presets fast,slow --out docs/benchmarks
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from dyntarget.evaluate.bench import machine
from dyntarget.io.atomic import write_text


def _run(cmd: list[str], env: dict[str, str]) -> tuple[float, float, float, int]:
    """Run ``cmd``; return (wall s, CPU s, peak RSS MB, exit code)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if proc.returncode:
        print(err, file=sys.stderr)
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, proc.returncode


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lengths", default="1000,3000", help="strip lengths, km (comma list)")
    ap.add_argument("--presets", default="fast,slow", help="agility presets (comma list)")
    ap.add_argument("--density", type=float, default=1.0, help="vents per 100 km")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--out", default="docs/benchmarks")
    ap.add_argument("--work", default=None, help="where strips and passes go (default: a temp dir)")
    args = ap.parse_args(argv)
    env = dict(os.environ)
    py = [sys.executable, "-m", "dyntarget.cli"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.work or tmp)
        for km in (float(v) for v in args.lengths.split(",")):
            strips = work / f"strip-{km:g}km"
            synth = [*py, "synth", "--strip", "--length-km", f"{km:g}", "--plumes-per-100km",
                     f"{args.density:g}", "--scenes", "1", "--seed", str(args.seed),
                     "--flat", "--out", str(strips), "--quiet"]  # fmt: skip
            s_wall, _, _, rc = _run(synth, env)
            if rc:
                return rc
            scene = strips / f"strip-{args.seed:04d}.tif"
            for preset in args.presets.split(","):
                out = work / f"pass-{km:g}km-{preset}"
                load0 = os.getloadavg()[0]
                cmd = [*py, "fly", "--scene", str(scene), "--truth", "--agility", preset,
                       "--out", str(out), "--quiet"]  # fmt: skip
                wall, cpu, rss, rc = _run(cmd, env)
                if rc:
                    return rc
                load1 = os.getloadavg()[0]
                with open(out / "timeline.csv", newline="") as fh:
                    loop = [float(r["loop_s"]) for r in csv.DictReader(fh) if r["loop_s"]]
                totals = json.loads((out / "summary.json").read_text())
                row = {
                    "length_km": km,
                    "preset": preset,
                    "vents": round(km / 100.0 * args.density),
                    "frames": len(loop),
                    "synth_wall_s": round(s_wall, 1),
                    "wall_s": round(wall, 1),
                    "cpu_s": round(cpu, 1),
                    "peak_rss_mb": round(rss),
                    "loop_median_s": round(statistics.median(loop), 4),
                    "loop_max_s": round(max(loop), 4),
                    "cpu_per_frame_s": round(cpu / max(len(loop), 1), 4),
                    "load_before": round(load0, 2),
                    "load_after": round(load1, 2),
                    "plumes_observed": totals.get("plumes_observed"),
                    "plumes_total": totals.get("plumes_total"),
                    "utility": totals.get("utility"),
                }
                rows.append(row)
                print(json.dumps(row), flush=True)
    cols = ["length_km", "preset", "frames", "wall_s", "cpu_s", "peak_rss_mb", "loop_median_s",
            "loop_max_s", "load_before", "load_after", "plumes_observed", "plumes_total"]  # fmt: skip
    table = "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"
    table += "".join("| " + " | ".join(str(r[c]) for c in cols) + " |\n" for r in rows)
    data = {"command": " ".join(sys.argv), "rows": rows, "machine": machine()}
    out = Path(args.out)
    write_text(out / "long_pass.json", json.dumps(data, indent=1) + "\n")
    write_text(out / "long_pass.md", table)
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
