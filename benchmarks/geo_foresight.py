"""Geostationary foresight: look-ahead only, the refinement alone, GEO blueprints, the omniscient one.

Pass-length strips (``long_strip_spec``: ``--length-km`` km, ``--passes`` sparse and as
many dense) are flown with the oracle classifier (the true mask at each frame's time, so
only the planning differs) and a fixed compute budget (deterministic), under each preset:

* ``lookahead``: today's loop (each frame's plan queued as it comes);
* ``blind``: the onboard refinement with no blueprint (``fly --geo-blind``: an ablation);
* ``geo@L``: a blueprint from the GEO stream (2 km, 600 s cadence, latency ``L`` s),
  refined onboard (``fly --geo``);
* ``geo@L no staging`` / ``geo@L brightness`` (``--ablate``): GEO without sending the
  idle sensor ahead, and GEO detected by brightness instead of unmixing;
* ``omniscient``: the blueprint planned on the true plumes at their overpass times
  (``fly --geo-omniscient``), refined by the same refinement;
* ``prior`` (``--prior [CATALOG]``): the catalog baseline, no GEO image at all
  (``fly --geo-prior``): one blueprint target per known volcano over the strip
  (:mod:`dyntarget.geo.catalog`; the synthetic strips' own vents unless a catalog CSV is
  given), refined by the same refinement;
* ``reference`` (added by ``--merge``): the better of ``lookahead`` and ``omniscient``
  on each pass (never below look-ahead only; not an upper bound).

``--upper-bound`` adds each pass's true upper bound (:mod:`dyntarget.observe.bound`: no
schedule the sensor can fly over that strip scores more; the same for every mode) as
``upper_bound`` and every mode's utility as a fraction of it (``fraction_of_bound``;
``vs_upper_bound`` in the summary). It renders the truth at every second of the pass over
the field of regard: minutes per 1000 km strip.

Strips are shared out over ``--shards`` processes (``--shard`` each); ``--merge`` writes
``geo_foresight.json`` (rows, summary, machine) and ``geo_foresight.png``.
``--timing-only`` times the blueprint alone on ``--blueprint-km`` (dense targets).
Commands: docs/results.md, "Geostationary foresight".
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np

from dyntarget import defaults
from dyntarget.evaluate.bench import machine
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.fly.geo import GeoSettings
from dyntarget.fly.strip import LongStrip, long_strip_spec
from dyntarget.geo import plan_blueprint
from dyntarget.io.atomic import write_text
from dyntarget.observe.bound import upper_bound_utility
from dyntarget.schedule import get_agility

DENSITIES = {"sparse": 0.2, "dense": 1.0}  # vents per 100 km: 1 / 500 km and 1 / 100 km


def _row(result, **kw):
    t = result.totals()
    geo = result.geo or {}
    times = result.geo_times or {}  # wall-clock times: kept out of result.geo (summary.json)
    return {
        **kw,
        **{k: t[k] for k in ("utility", "plumes_observed", "plumes_total", "pointings_flown")},
        "frames": t["frames"],
        "geo_targets": geo.get("targets"),
        "geo_chosen": geo.get("targets_chosen"),
        "blueprint_s": times.get("blueprint_s"),
        "targets_s": times.get("targets_s"),
        "degraded": geo.get("degraded"),
        **{
            k: geo.get(k)
            for k in (
                "blueprint_pointings",
                "targets_released",
                "targets_released_blueprint",
                "look_ahead_targets",
                "pointings_released",
                "releases_capped_by_blueprint",
            )
        },
    }


MODES_DOC = {
    "lookahead": "look-ahead only (today's loop)",
    "blind": "the onboard refinement alone (no blueprint)",
    "geo@L": "GEO blueprint (latency L s) + refinement",
    "omniscient": "blueprint on the truth + refinement",
    "prior": "catalog baseline: a target per known volcano, no GEO image + refinement",
    "reference": "the better of look-ahead only and omniscient, per pass",
}


def _geo_prior(source: str):
    """GeoSettings of the catalog baseline (``fly --geo-prior SOURCE``)."""
    if "prior" in GeoSettings.__dataclass_fields__:
        return GeoSettings(prior=source)
    return _PriorSettings(source)  # until fly.geo knows the prior: see _prior_prepare


class _PriorSettings(GeoSettings):
    """GeoSettings carrying a catalog prior, for a fly.geo without one (see _prior_prepare)."""

    def __init__(self, source: str) -> None:
        super().__init__(blind=True)
        object.__setattr__(self, "prior_source", source)


def _prior_prepare(original):
    """fly.geo.prepare, planning the blueprint on the catalog's targets for _PriorSettings."""
    import dataclasses

    from dyntarget.fly.geo import BlueprintGate
    from dyntarget.geo.catalog import prior_targets

    def prepare(world, frames, config, settings):
        out = original(world, frames, config, settings)
        source = getattr(settings, "prior_source", None)
        if source is None:
            return out
        t0 = time.perf_counter()
        targets, info = prior_targets(source, world, frames, config.factor)
        horizon = frames.n_frames * frames.cadence_s + frames.geometry.look_ahead_m / (
            frames.geometry.ground_speed
        )
        agility = get_agility(config.agility)
        bp = plan_blueprint(
            targets, dataclasses.replace(frames.geometry, start_s=0.0), agility,
            horizon_s=horizon, reserve=settings.reserve,
        )  # fmt: skip
        out = list(out)
        out[0] = BlueprintGate(bp, frames, agility, stage=settings.stage)
        out[1] = {
            **out[1], **info, "targets": len(bp.targets), "targets_chosen": len(bp.chosen),
            "blueprint_pointings": int(bp.budget.sum()),
            "blueprint_s": round(time.perf_counter() - t0, 4),
        }  # fmt: skip
        return tuple(out)

    return prepare


class _SparseValues:
    """The truth's utility per WFOV pixel at each time, kept sparse (shared by presets)."""

    def __init__(self, world, factor: int, frames) -> None:
        from dyntarget.fly.loop import _TruthCache
        from dyntarget.observe.bound import values_from_bands

        truth = _TruthCache(world, factor, 1, band=frames.frame_px)
        self.values = values_from_bands(truth.at, frames.wfov_shape[1])
        self.width = frames.wfov_shape[1]
        self.memo: dict[float, tuple[int, int, np.ndarray, np.ndarray, np.ndarray]] = {}

    def _sparse(self, t: float, a: int, b: int):
        v = self.values(t, a, b)
        rr, cc = np.nonzero(v > 0)
        return rr + a, cc, v[rr, cc].astype(np.float64)

    def __call__(self, t: float, r0: int, r1: int) -> np.ndarray:
        hit = self.memo.get(t)
        if hit is None:
            hit = self.memo[t] = (r0, r1, *self._sparse(t, r0, r1))
        elif hit[0] > r0 or hit[1] < r1:  # render only the rows not kept yet
            a, b, rr, cc, vv = hit
            parts = [(rr, cc, vv)]
            if r0 < a:
                parts.append(self._sparse(t, r0, a))
            if r1 > b:
                parts.append(self._sparse(t, b, r1))
            hit = self.memo[t] = (
                min(a, r0),
                max(b, r1),
                *(np.concatenate(x) for x in zip(*parts, strict=True)),
            )
        out = np.zeros((r1 - r0, self.width))
        a, b, rr, cc, vv = hit
        on = (rr >= r0) & (rr < r1)
        out[rr[on] - r0, cc[on]] = vv[on]
        return out


def upper_bounds(spec, window, presets, cfgs) -> dict[str, dict]:
    """Each preset's upper bound on the strip (a fresh world: its truth is not the passes')."""
    from dyntarget.fly.loop import frame_plan

    world = LongStrip(spec, window)  # small caches: the bound walks the whole pass
    frames = frame_plan(world, cfgs[presets[0]])
    values = _SparseValues(world, cfgs[presets[0]].factor, frames)
    out = {}
    for preset in presets:
        b = upper_bound_utility(
            values, frames.wfov_shape, frames.frame_px, frames.geometry, get_agility(preset),
            time_step_s=world.truth_step_s,
        )  # fmt: skip
        out[preset] = b.as_dict(timing=True)
        print(json.dumps({"strip": spec.id, "preset": preset, "upper_bound": out[preset]}))
    return out


def run(args) -> dict:
    import dyntarget.fly.geo as fly_geo

    if "prior" not in GeoSettings.__dataclass_fields__:
        fly_geo.prepare = _prior_prepare(fly_geo.prepare)
    rows = []
    jobs = [(p, d) for p in range(args.passes) for d in args.densities]  # they alternate
    for n, (p, density) in enumerate(jobs):
        if n % args.shards != args.shard:
            continue
        per100 = DENSITIES[density]
        seed = 100 * (1 + list(DENSITIES).index(density)) + p
        spec, window = long_strip_spec(
            seed, args.length_km, width=args.width, gsd=args.gsd, plumes_per_100km=per100
        )
        world = LongStrip(spec, window, capacity=4000, frame_capacity=4000)
        cfgs = {
            preset: PassConfig(
                agility=preset,
                compute_budget_s=args.budget_s,
                look_ahead_m=args.look_ahead_km * 1e3,
            )
            for preset in args.presets
        }
        bounds = upper_bounds(spec, window, args.presets, cfgs) if args.upper_bound else {}
        for preset in args.presets:
            cfg = cfgs[preset]
            modes = [("lookahead", None), ("blind", GeoSettings(blind=True))]
            modes += [(f"geo@{lat:g}", GeoSettings(latency_s=lat)) for lat in args.latencies]
            if args.ablate:  # GEO at the middle latency without staging, and by brightness
                lat = args.latencies[len(args.latencies) // 2]
                modes += [
                    (f"geo@{lat:g} no staging", GeoSettings(latency_s=lat, stage=False)),
                    (f"geo@{lat:g} brightness", GeoSettings(latency_s=lat, detection="brightness")),
                ]
            modes.append(("omniscient", GeoSettings(omniscient=True)))
            if args.prior:
                modes.append(("prior", _geo_prior(args.prior)))
            for mode, geo in modes:
                t0 = time.perf_counter()
                r = fly_pass(world, None, cfg, geo=geo)
                wall = time.perf_counter() - t0
                row = _row(
                    r, strip=spec.id, density=density, vents=len(spec.vents),
                    preset=preset, mode=mode, wall_s=round(wall, 2),
                )  # fmt: skip
                if preset in bounds:
                    ub = bounds[preset]["value"]
                    row["upper_bound"] = ub
                    row["upper_bound_exact"] = bounds[preset]["exact"]
                    row["fraction_of_bound"] = round(row["utility"] / ub, 4) if ub else None
                if mode == "prior":
                    row["prior"] = (r.geo or {}).get("catalog")
                rows.append(row)
                print(json.dumps(row), flush=True)
                write_text(
                    Path(args.out) / f"geo_foresight.part{args.shard}.json", json.dumps(rows)
                )
    return {"rows": rows}


def add_reference(rows: list[dict]) -> list[dict]:
    """Per pass and preset: the better of look-ahead only and the omniscient blueprint."""
    out = [r for r in rows if r["mode"] != "reference"]
    keys = dict.fromkeys((r["strip"], r["preset"]) for r in out)
    for strip, preset in keys:
        sub = {r["mode"]: r for r in out if r["strip"] == strip and r["preset"] == preset}
        if "lookahead" in sub and "omniscient" in sub:
            best = max(sub["lookahead"], sub["omniscient"], key=lambda r: r["utility"])
            out.append({**best, "mode": "reference", "from": best["mode"]})
    return out


def summarise(rows: list[dict]) -> list[dict]:
    """One line per density, preset and mode: sums, ratios and per-pass ranges."""
    out = []
    groups = dict.fromkeys((r["density"], r["preset"]) for r in rows)
    for density, preset in groups:
        sub = [r for r in rows if r["density"] == density and r["preset"] == preset]
        base = {r["strip"]: r for r in sub if r["mode"] == "lookahead"}
        ref = {r["strip"]: r for r in sub if r["mode"] == "reference"}
        for mode in dict.fromkeys(r["mode"] for r in sub):
            rs = [r for r in sub if r["mode"] == mode and r["strip"] in base]
            u = sum(r["utility"] for r in rs)
            ub = sum(base[r["strip"]]["utility"] for r in rs)
            uref = sum(ref[r["strip"]]["utility"] for r in rs if r["strip"] in ref)
            # per-pass ratios only where look-ahead only scored (0 / 0 says nothing)
            per = [r["utility"] / base[r["strip"]]["utility"] for r in rs
                   if base[r["strip"]]["utility"] > 0] or [float("nan")]  # fmt: skip
            fewer = sum(r["plumes_observed"] < base[r["strip"]]["plumes_observed"] for r in rs)
            bounded = [r for r in rs if r.get("upper_bound")]
            ubound = sum(r["upper_bound"] for r in bounded)
            out.append({
                "density": density, "preset": preset, "mode": mode, "passes": len(rs),
                "utility": round(u, 3), "vs_lookahead": round(u / max(ub, 1e-9), 3),
                "vs_reference": round(u / max(uref, 1e-9), 3) if uref else None,
                "per_pass_min": round(min(per), 3), "per_pass_max": round(max(per), 3),
                "plumes_observed": sum(r["plumes_observed"] for r in rs),
                "plumes_total": sum(r["plumes_total"] for r in rs),
                "passes_fewer_plumes": fewer,
                "vs_upper_bound": (
                    round(sum(r["utility"] for r in bounded) / ubound, 4) if ubound else None
                ),
            })  # fmt: skip
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

    groups = [(d, p) for d in DENSITIES for p in ("slow", "fast")
              if any(r["density"] == d and r["preset"] == p for r in rows)]  # fmt: skip
    fig, axes = plt.subplots(1, len(groups), figsize=(4.0 * len(groups), 4.0), sharey=False)
    axes = np.atleast_1d(axes)
    rng = np.random.default_rng(0)
    for ax, (density, preset) in zip(axes, groups, strict=True):
        sub = [r for r in rows if r["density"] == density and r["preset"] == preset]
        modes = [m for m in dict.fromkeys(r["mode"] for r in sub) if m != "lookahead"]
        base = {r["strip"]: r["utility"] for r in sub if r["mode"] == "lookahead"}
        for x, m in enumerate(modes):
            ys = [r["utility"] / base[r["strip"]] for r in sub
                  if r["mode"] == m and base.get(r["strip"], 0) > 0]  # fmt: skip
            ax.scatter(x + rng.uniform(-0.15, 0.15, len(ys)), ys, s=12, alpha=0.6)
            ax.hlines(np.median(ys), x - 0.3, x + 0.3, color="k", lw=2)
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set_xticks(range(len(modes)), modes, rotation=35, ha="right")
        scored = sum(v > 0 for v in base.values())
        ax.set_title(f"{density}, {preset} ({scored} passes)")
        ax.set_ylabel("utility / look-ahead only (per pass)")
    fig.suptitle("Geostationary foresight: utility of each pass relative to look-ahead only "
                 "(bar: median)", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def merge(out: Path) -> dict:
    """Combine the shards' rows (``geo_foresight.part*.json``) with the header."""
    doc = json.loads((out / "geo_foresight.json.head").read_text())
    rows = []
    for f in sorted(out.glob("geo_foresight.part*.json")):
        rows += json.loads(f.read_text())
    rows = add_reference(rows)
    doc["rows"] = rows
    doc["summary"] = summarise(rows)
    doc["modes"] = MODES_DOC
    write_text(out / "geo_foresight.json", json.dumps(doc, indent=1))
    figure(rows, out / "geo_foresight.png")
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", type=int, default=10, help="strips per density")
    ap.add_argument("--length-km", type=float, default=1000.0)
    ap.add_argument("--width", type=int, default=256, help="strip width, px")
    ap.add_argument("--gsd", type=float, default=32.0, help="strip GSD, m")
    ap.add_argument("--presets", default="slow,fast")
    ap.add_argument("--latencies", default="0,300,900")
    ap.add_argument("--budget-s", type=float, default=0.05)
    ap.add_argument("--densities", default="sparse,dense", help="of: " + ",".join(DENSITIES))
    ap.add_argument(
        "--look-ahead-km",
        type=float,
        default=defaults.LOOK_AHEAD_M / 1e3,
        help="how far ahead of nadir the look-ahead frames are (default: the project's)",
    )
    ap.add_argument(
        "--ablate",
        action="store_true",
        help="also GEO at the middle latency without staging, and with brightness detection",
    )
    ap.add_argument(
        "--prior",
        nargs="?",
        const="vents",
        default=None,
        help="also the catalog baseline (fly --geo-prior): a catalog CSV, or 'vents' (default: "
        "the synthetic strips' own vents)",
    )
    ap.add_argument(
        "--upper-bound",
        action="store_true",
        help="each pass's true upper bound and every mode as a fraction of it (minutes a strip)",
    )
    ap.add_argument("--shard", type=int, default=0, help="this process's share (0-based)")
    ap.add_argument("--shards", type=int, default=1, help="processes sharing the strips")
    ap.add_argument("--out", default="docs/benchmarks")
    ap.add_argument(
        "--merge",
        action="store_true",
        help="write geo_foresight.json and the figure from --out's shards (run after them)",
    )
    ap.add_argument(
        "--timing-only",
        action="store_true",
        help="only time the blueprint on --blueprint-km (dense: 1 target / 100 km)",
    )
    ap.add_argument("--blueprint-km", type=float, default=3000.0)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.timing_only:
        doc = {
            "command": f"python benchmarks/geo_foresight.py --timing-only --blueprint-km "
            f"{args.blueprint_km:g}",
            "machine": machine(),
            "timing": time_blueprint_synthetic(args.blueprint_km, round(args.blueprint_km / 100)),
        }
        print(json.dumps(doc["timing"]))
        write_text(out / "geo_blueprint_timing.json", json.dumps(doc, indent=1))
        return
    if args.merge:
        doc = merge(out)
        for line in doc["summary"]:
            print(json.dumps(line))
        return
    args.presets = args.presets.split(",")
    args.latencies = [float(v) for v in args.latencies.split(",")]
    args.densities = [d for d in args.densities.split(",") if d in DENSITIES]
    if args.shard == 0:
        head = {
            "command": "python benchmarks/geo_foresight.py "
            + f"--passes {args.passes} --length-km {args.length_km:g} --width {args.width} "
            + f"--gsd {args.gsd:g} --presets {','.join(args.presets)} "
            + f"--latencies {','.join(f'{v:g}' for v in args.latencies)} "
            + f"--densities {','.join(args.densities)} --look-ahead-km {args.look_ahead_km:g} "
            + ("--ablate " if args.ablate else "")
            + (f"--prior {args.prior} " if args.prior else "")
            + ("--upper-bound " if args.upper_bound else "")
            + f"--shards {args.shards} (each --shard), then --merge",
            "machine": machine(),
        }
        write_text(out / "geo_foresight.json.head", json.dumps(head))
    t0 = time.perf_counter()
    run(args)
    peak = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    print(json.dumps({"shard": args.shard, "wall_s": round(time.perf_counter() - t0, 1),
                      "peak_rss_mb": peak}))  # fmt: skip


if __name__ == "__main__":
    main()
