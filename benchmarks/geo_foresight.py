"""Geostationary foresight: look-ahead only, GEO blueprint + look-ahead, and the omniscient bound.

Pass-length strips (``long_strip_spec``: ``--length-km`` km, sparse and dense
vents) are flown with the oracle classifier (``--truth``: the true mask at
each frame's time, so only the planning differs) and a fixed compute budget
(deterministic), under each preset, in three ways:

* ``lookahead``: today's loop (each frame planned greedily from the look-ahead);
* ``geo@L``: a blueprint from the GEO stream (2 km, 600 s cadence, latency
  ``L`` s), refined by the look-ahead (``fly --geo``);
* ``omniscient``: the blueprint planned on the true plumes at their overpass
  times (``fly --geo-omniscient``), refined by the same oracle look-ahead.

Also times the blueprint alone on a 3000 km dense pass (``--blueprint-km``).
Writes ``geo_foresight.json`` (rows + machine) and ``geo_foresight.png``.

Command (recorded in docs/results.md, "Geostationary foresight")::

    python benchmarks/geo_foresight.py --passes 3 --length-km 1000 --out docs/benchmarks

Equivalent single pass on the command line::

    dyntarget synth --strip --length-km 1000 --plumes-per-100km 0.2 --scenes 1 --out strips
    dyntarget fly --scene strips/strip-0000.tif --truth --agility slow --compute-budget-s 0.05 \\
        --geo --geo-latency-s 300 --out pass
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np

from dyntarget.evaluate.bench import machine
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.fly.geo import GeoSettings, omniscient_targets
from dyntarget.fly.loop import frame_plan
from dyntarget.fly.strip import LongStrip, long_strip_spec
from dyntarget.geo import plan_blueprint
from dyntarget.io.atomic import write_text
from dyntarget.schedule import get_agility

DENSITIES = {"sparse": 0.2, "dense": 1.0}  # vents per 100 km: 1 / 500 km and 1 / 100 km


def _row(result, **kw):
    t = result.totals()
    geo = result.geo or {}
    return {
        **kw,
        **{k: t[k] for k in ("utility", "plumes_observed", "plumes_total", "pointings_flown")},
        "frames": t["frames"],
        "geo_targets": geo.get("targets"),
        "geo_chosen": geo.get("targets_chosen"),
        "blueprint_s": geo.get("blueprint_s"),
        "targets_s": geo.get("targets_s"),
        "degraded": geo.get("degraded"),
        **{
            k: geo.get(k)
            for k in (
                "blueprint_pointings",
                "pointings_dropped_given_up",
                "pointings_dropped_over_budget",
                "pointings_from_reserve",
            )
        },
    }


def run(args) -> dict:
    rows = []
    for p in range(args.passes):  # sparse and dense alternate: a stopped run has both
        for density, per100 in DENSITIES.items():
            seed = 100 * (1 + list(DENSITIES).index(density)) + p
            spec, window = long_strip_spec(
                seed, args.length_km, width=args.width, gsd=args.gsd, plumes_per_100km=per100
            )
            world = LongStrip(spec, window, capacity=4000, frame_capacity=4000)
            for preset in args.presets:
                cfg = PassConfig(agility=preset, compute_budget_s=args.budget_s)
                modes = [("lookahead", None)]
                lats = args.latencies if preset == "slow" else args.latencies[1:2]
                modes += [(f"geo@{lat:g}", GeoSettings(latency_s=lat)) for lat in lats]
                modes.append(("omniscient", GeoSettings(omniscient=True)))
                for mode, geo in modes:
                    t0 = time.perf_counter()
                    r = fly_pass(world, None, cfg, geo=geo)
                    wall = time.perf_counter() - t0
                    row = _row(
                        r, strip=spec.id, density=density, vents=len(spec.vents),
                        preset=preset, mode=mode, wall_s=round(wall, 2),
                    )  # fmt: skip
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    Path(args.out, "geo_foresight.partial.json").write_text(json.dumps(rows))
    return {"rows": rows}


def time_blueprint(km: float, width: int, gsd: float) -> dict:
    spec, window = long_strip_spec(7, km, width=width, gsd=gsd, plumes_per_100km=1.0)
    world = LongStrip(spec, window)
    cfg = PassConfig(agility="slow")
    frames = frame_plan(world, cfg)
    targets = omniscient_targets(world, frames, cfg.factor)
    horizon = frames.n_frames * frames.cadence_s + frames.geometry.look_ahead_m / (
        frames.geometry.ground_speed
    )
    out = {"length_km": km, "targets": len(targets)}
    for preset in ("slow", "fast"):
        best = []
        for _ in range(3):
            t0 = time.perf_counter()
            bp = plan_blueprint(targets, frames.geometry, get_agility(preset), horizon_s=horizon)
            best.append(time.perf_counter() - t0)
        out[preset] = {"blueprint_s_min": round(min(best), 4), "slots": bp.info["slots"]}
    return out


def time_blueprint_synthetic(km: float, n: int, seed: int = 0) -> dict:
    """The DP alone on ``n`` targets spread over ``km`` (its cost depends on n and T only)."""
    from dyntarget.geo import Target
    from dyntarget.schedule import OrbitGeometry

    g = OrbitGeometry(wfov_gsd_m=64.0)
    rng = np.random.default_rng(seed)
    v = g.ground_speed
    horizon = km * 1e3 / v + g.look_ahead_m / v
    along = np.sort(rng.uniform(g.look_ahead_m, g.look_ahead_m + km * 1e3, n))
    ts = [
        Target(float(a), float(rng.uniform(-900, 900)), float(rng.uniform(0.02, 0.2)),
               int(rng.integers(50, 400)))
        for a in along
    ]  # fmt: skip
    out = {"length_km": km, "targets": n, "horizon_s": round(horizon, 1)}
    for preset in ("slow", "fast"):
        tt = []
        for _ in range(5):
            t0 = time.perf_counter()
            bp = plan_blueprint(ts, g, get_agility(preset), horizon_s=horizon)
            tt.append(time.perf_counter() - t0)
        out[preset] = {
            "blueprint_s_min": round(min(tt), 4),
            "blueprint_s_median": round(float(np.median(tt)), 4),
            "slots": bp.info["slots"],
            "chosen": len(bp.chosen),
        }
    return out


def figure(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = sorted({(r["density"], r["preset"]) for r in rows}, reverse=True)
    fig, axes = plt.subplots(1, len(groups), figsize=(4.2 * len(groups), 3.8), sharey=False)
    axes = np.atleast_1d(axes)
    for ax, (density, preset) in zip(axes, groups, strict=True):
        sub = [r for r in rows if r["density"] == density and r["preset"] == preset]
        modes = list(dict.fromkeys(r["mode"] for r in sub))
        strips = list(dict.fromkeys(r["strip"] for r in sub))
        base = {r["strip"]: r["utility"] for r in sub if r["mode"] == "lookahead"}
        for j, s in enumerate(strips):
            ys = [
                next(r["utility"] for r in sub if r["strip"] == s and r["mode"] == m)
                / max(base[s], 1e-9)
                for m in modes
            ]
            ax.plot(range(len(modes)), ys, "o-", alpha=0.7, label=s if j < 6 else None)
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set_xticks(range(len(modes)), modes, rotation=30, ha="right")
        ax.set_title(f"{density}, {preset}")
        ax.set_ylabel("utility / look-ahead only")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", type=int, default=3, help="strips per density")
    ap.add_argument("--length-km", type=float, default=1000.0)
    ap.add_argument("--width", type=int, default=128, help="strip width, px")
    ap.add_argument("--gsd", type=float, default=16.0, help="strip GSD, m")
    ap.add_argument("--presets", default="slow,fast")
    ap.add_argument("--latencies", default="0,300,900")
    ap.add_argument("--budget-s", type=float, default=0.05)
    ap.add_argument("--blueprint-km", type=float, default=3000.0, help="0: skip the timing")
    ap.add_argument("--out", default="docs/benchmarks")
    ap.add_argument(
        "--from-partial",
        action="store_true",
        help="write the JSON and figure from --out's partial rows (a run stopped early)",
    )
    ap.add_argument(
        "--timing-only",
        action="store_true",
        help="only time the blueprint DP on 31 targets over --blueprint-km (dense: 1 / 100 km)",
    )
    args = ap.parse_args()
    if args.timing_only:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        doc = {
            "command": f"python benchmarks/geo_foresight.py --timing-only --blueprint-km "
            f"{args.blueprint_km:g}",
            "machine": machine(),
            "timing": time_blueprint_synthetic(args.blueprint_km, round(args.blueprint_km / 100)),
        }
        print(json.dumps(doc["timing"]))
        write_text(Path(args.out) / "geo_blueprint_timing.json", json.dumps(doc, indent=1))
        return
    if args.from_partial:
        doc = json.loads((Path(args.out) / "geo_foresight.json.head").read_text())
        doc["rows"] = json.loads((Path(args.out) / "geo_foresight.partial.json").read_text())
        doc["stopped_early"] = True
        write_text(Path(args.out) / "geo_foresight.json", json.dumps(doc, indent=1))
        figure(doc["rows"], Path(args.out) / "geo_foresight.png")
        return
    args.presets = args.presets.split(",")
    args.latencies = [float(v) for v in args.latencies.split(",")]
    Path(args.out).mkdir(parents=True, exist_ok=True)
    doc = {
        "command": "python benchmarks/geo_foresight.py "
        + f"--passes {args.passes} --length-km {args.length_km:g} --width {args.width} "
        + f"--gsd {args.gsd:g} --presets {','.join(args.presets)}",
        "machine": machine(),
        "blueprint_timing": time_blueprint(args.blueprint_km, args.width, args.gsd)
        if args.blueprint_km
        else None,
    }
    print(json.dumps(doc["blueprint_timing"]), flush=True)
    write_text(Path(args.out) / "geo_foresight.json.head", json.dumps(doc))
    doc |= run(args)
    doc["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    write_text(Path(args.out) / "geo_foresight.json", json.dumps(doc, indent=1))
    figure(doc["rows"], Path(args.out) / "geo_foresight.png")


if __name__ == "__main__":
    main()
