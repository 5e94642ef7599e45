"""Benchmark of ``dyntarget constellation`` (issue 41): what cueing buys, the bound, scale.

Run from the repository root (the GVP catalog is read where the shared data lies)::

    nice python benchmarks/constellation.py --out docs/benchmarks/constellation.json \\
        --figure docs/img/constellation_curve.png --day-figure docs/img/constellation_day.png

Parts (``--parts`` picks some): ``curve`` (1..500 satellites x 4 cueing modes x seeds,
distributed allocation, plus greedy at 20 satellites), ``bound`` (greedy and distributed
against the exact MILP on <= 10 satellites, 6 h), ``scale`` (the whole CLI process from
the shell under ``/usr/bin/time -v`` at 50/100/200/500 satellites, 24 h, 1,250 volcanoes),
``sweep`` (24 configurations serially and on a ``dask.distributed`` LocalCluster of
processes: same summaries, byte for byte), ``day`` (the world map of a 20-satellite day).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GVP = ROOT.parent / "shared" / "data" / "gvp-holocene" / "volcanoes.csv"
START = "2026-06-01T00:00:00Z"
WALKERS = {
    1: "1/1/0",
    4: "4/2/1",
    7: "7/7/1",
    10: "10/5/1",
    20: "20/5/1",
    50: "50/10/1",
    60: "60/12/1",
    100: "100/10/1",
    200: "200/20/1",
    500: "500/25/1",
}
MODES = ("none", "self", "cross", "cross+geo")
SHIM = (
    "import sys, dyntarget.cli as c\n"
    "from dyntarget.cli import constellation as k\n"
    "c.COMMANDS = c.COMMANDS if k in c.COMMANDS else (*c.COMMANDS, k)\n"
    "sys.exit(c.main(sys.argv[1:]))\n"
)
"""Runs ``dyntarget ...`` whether or not the command is registered in this checkout yet."""


def config(n: int, cueing: str, allocation: str, seed: int, hours: float = 24.0) -> dict:
    return {
        "walker": WALKERS[n],
        "altitude_km": 500.0,
        "inclination_deg": "sso",
        "start": START,
        "hours": hours,
        "seed": seed,
        "cueing": cueing,
        "allocation": allocation,
    }


def run_curve(catalog, seeds: int) -> list[dict]:
    from dyntarget.constellation.run import sweep

    configs = [
        config(n, m, "distributed", s)
        for n in (1, 7, 20, 60, 200, 500)
        for m in MODES
        for s in range(seeds)
    ]
    configs += [config(20, m, "greedy", s) for m in MODES for s in range(seeds)]
    t = time.perf_counter()
    out = sweep(configs, catalog, progress=True)
    print(f"curve: {len(configs)} runs in {time.perf_counter() - t:.0f} s", file=sys.stderr)
    return out


def run_bound(catalog, seeds: int) -> list[dict]:
    from dyntarget.constellation.run import sweep

    configs = [
        config(n, m, a, s, hours=6.0)
        for n in (4, 7, 10)
        for m in ("cross", "cross+geo")
        for a in ("greedy", "distributed", "bound")
        for s in range(seeds)
    ]
    # a busy world (400 episodes a day) and body-pointing agility: contention to allocate
    busy = [{**c, "eruptions_per_day": 400.0, "agility": "slow"} for c in configs]
    return sweep(configs + busy, catalog, progress=True)


def time_cli(args: list[str]) -> dict:
    """The whole CLI process under /usr/bin/time -v: wall seconds and peak RSS."""
    cmd = ["/usr/bin/time", "-v", sys.executable, "-c", SHIM, *args]
    p = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if p.returncode:
        raise RuntimeError(p.stderr[-2000:])
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", p.stderr)
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr)
    assert wall and rss
    parts = [float(x) for x in wall.group(1).split(":")]
    secs = parts[-1] + 60 * parts[-2] + (3600 * parts[-3] if len(parts) > 2 else 0)
    return {"wall_s": round(secs, 2), "peak_rss_mb": round(int(rss.group(1)) / 1024, 1)}


def run_scale() -> list[dict]:
    rows = []
    for n in (50, 100, 200, 500):
        with tempfile.TemporaryDirectory() as d:
            args = [
                "constellation",
                "--walker",
                WALKERS[n],
                "--hours",
                "24",
                "--volcanoes",
                str(GVP),
                "--cueing",
                "cross+geo",
                "--allocation",
                "distributed",
                "--out",
                str(Path(d) / "o"),
                "--quiet",
                "--no-html",
                "--no-picture",
            ]
            r = {"satellites": n, **time_cli(args)}
            print(r, file=sys.stderr)
            rows.append(r)
    return rows


def run_sweep_check(catalog) -> dict:
    from dyntarget.constellation.run import sweep

    configs = [
        config(n, m, a, 0, hours=6.0)
        for n in (1, 7, 20)
        for m in MODES
        for a in ("greedy", "distributed")
    ]
    t = time.perf_counter()
    serial = sweep(configs, catalog)
    t1 = time.perf_counter()
    dask = sweep(configs, catalog, scheduler="processes")
    t2 = time.perf_counter()
    a = json.dumps(serial, sort_keys=True).encode()
    b = json.dumps(dask, sort_keys=True).encode()
    return {
        "configurations": len(configs),
        "identical_bytes": a == b,
        "serial_s": round(t1 - t, 1),
        "localcluster_processes_s": round(t2 - t1, 1),
    }


def day_figure(path: Path) -> dict:
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "o"
        args = [
            "constellation",
            "--walker",
            "20/5/1",
            "--volcanoes",
            str(GVP),
            "--cueing",
            "cross+geo",
            "--allocation",
            "distributed",
            "--out",
            str(out),
            "--quiet",
        ]
        r = time_cli(args)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes((out / "constellation.png").read_bytes())
        summary = json.loads((out / "summary.json").read_text())
    return {
        "command": "dyntarget " + " ".join(args[:-3]).replace(str(GVP), "VOLCANOES.csv"),
        **r,
        "summary": summary,
    }


def curve_figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    ns = (1, 7, 20, 60, 200, 500)
    for m in MODES:
        within, per6 = [], []
        for n in ns:
            sel = [
                r
                for r in rows
                if r["options"]["cueing"] == m
                and r["satellites"] == n
                and r["options"]["allocation"] == "distributed"
            ]
            within.append(np.mean([r["observed_within_6h"] / max(r["eruptions"], 1) for r in sel]))
            vals = [r["observations_per_eruption_6h"] for r in sel]
            vals = [v for v in vals if v is not None]  # None: nothing detected that day
            per6.append(np.mean(vals) if vals else np.nan)
        axes[0].plot(ns, 100 * np.array(within), marker="o", label=m)
        axes[1].plot(ns, per6, marker="o", label=m)
    for ax, label in zip(
        axes,
        (
            "eruptions observed within 6 h of onset (%)",
            "observations per eruption, 6 h after first detection",
        ),
        strict=True,
    ):
        ax.set_xscale("log")
        ax.set_xlabel("satellites (Walker, 500 km, sun-synchronous)")
        ax.set_ylabel(label)
        ax.grid(lw=0.3)
        ax.legend(title="cueing", fontsize=8)
    fig.suptitle("dyntarget constellation: 24 h, GVP Holocene volcanoes, distributed allocation")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, metadata={"Software": None})


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="docs/benchmarks/constellation.json")
    p.add_argument("--figure", default="docs/img/constellation_curve.png")
    p.add_argument("--day-figure", default="docs/img/constellation_day.png")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--parts", default="curve,bound,scale,sweep,day")
    args = p.parse_args()
    if not GVP.is_file():
        sys.exit(f"benchmark: the GVP catalog is not at {GVP}")
    from dyntarget.constellation.world import read_catalog

    catalog = read_catalog(GVP)
    out = Path(args.out)
    result = json.loads(out.read_text()) if out.is_file() else {}
    result["machine"] = {
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
    }
    parts = set(args.parts.split(","))
    if "curve" in parts:
        result["curve"] = run_curve(catalog, args.seeds)
        curve_figure(result["curve"], Path(args.figure))
    if "bound" in parts:
        result["bound"] = run_bound(catalog, 2 * args.seeds)
    if "scale" in parts:
        result["scale"] = run_scale()
    if "sweep" in parts:
        result["sweep"] = run_sweep_check(catalog)
    if "day" in parts:
        result["day"] = day_figure(Path(args.day_figure))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(out)


if __name__ == "__main__":
    main()
