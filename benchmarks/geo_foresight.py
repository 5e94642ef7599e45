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

``--curve`` (the latency curve, issue 43): each pass is flown look-ahead only, with GEO at
every ``--latencies`` value (in seconds, e.g. ``0,300,600,1200,1800,2700,3600``) for
each ``--endmembers`` source (``simulator``: the imager's stated spectra; ``estimated``:
N-FINDR on the GEO images), blind and omniscient; with the archive long enough that every
latency has three images (``history_s = max(3600, L + 2 cadence)``). ``--worlds
steady,onsets`` flies each strip as drawn (steady plumes) and with onsets
(``synth --onset-fraction``: ``--onset-fraction`` of the vents start erupting at a time
drawn in ``--onset-window-min``, pass clock). ``--tag`` names the output files
(``<tag>.json``, ``<tag>.png``; default ``geo_foresight``).

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
import dataclasses
import json
import resource
import time
from pathlib import Path

import numpy as np

from dyntarget import defaults
from dyntarget.evaluate.bench import machine
from dyntarget.fly import PassConfig, fly_pass
from dyntarget.geo import plan_blueprint
from dyntarget.io.atomic import write_text
from dyntarget.observe.bound import upper_bound_utility
from dyntarget.passes.geo import GeoSettings
from dyntarget.schedule import get_agility
from dyntarget.synth.dynamic import with_onsets
from dyntarget.synth.strip import long_strip_spec
from dyntarget.synth.strip_world import LongStrip

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
    return _PriorSettings(source)  # until passes.geo knows the prior: see _prior_prepare


class _PriorSettings(GeoSettings):
    """GeoSettings carrying a catalog prior, for a passes.geo without one (see _prior_prepare)."""

    def __init__(self, source: str) -> None:
        super().__init__(blind=True)
        object.__setattr__(self, "prior_source", source)


def _prior_prepare(original):
    """passes.geo.prepare, planning the blueprint on the catalog's targets for _PriorSettings."""
    import dataclasses

    from dyntarget.geo.catalog import prior_targets
    from dyntarget.geo.refine import BlueprintGate

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
        from dyntarget.observe.bound import values_from_bands
        from dyntarget.synth.worlds import TruthBands

        truth = TruthBands(world, factor, 1, band=frames.frame_px)
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
    from dyntarget.passes.record import frame_plan

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
    import dyntarget.passes.geo as fly_geo

    if "prior" not in GeoSettings.__dataclass_fields__:
        fly_geo.prepare = _prior_prepare(fly_geo.prepare)
    rows = []
    jobs = [(p, d, w) for p in range(args.passes) for d in args.densities for w in args.worlds]
    for n, (p, density, kind) in enumerate(jobs):  # they alternate
        if n % args.shards != args.shard:
            continue
        per100 = DENSITIES[density]
        seed = 100 * (1 + list(DENSITIES).index(density)) + p
        spec, window = long_strip_spec(
            seed, args.length_km, width=args.width, gsd=args.gsd, plumes_per_100km=per100
        )
        if kind == "onsets":  # the draws of synth --strip --onset-fraction, a distinct id
            lo, hi = args.onset_window_min
            spec = with_onsets(spec, args.onset_fraction, window_s=(lo * 60.0, hi * 60.0))
            spec = dataclasses.replace(spec, id=f"{spec.id}-onsets")
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
            if args.curve:
                modes += [
                    (f"geo@{lat:g}" + ("" if em == "simulator" else " estimated"),
                     GeoSettings(latency_s=lat, endmembers=em,
                                 history_s=max(3600.0, lat + 2 * GeoSettings.cadence_s)))
                    for em in args.endmembers for lat in args.latencies
                ]  # fmt: skip
                if args.no_persistence:  # the ablation: every detection at full weight
                    modes += [
                        (f"geo@{lat:g} no persistence",
                         GeoSettings(latency_s=lat, persistence=False,
                                     history_s=max(3600.0, lat + 2 * GeoSettings.cadence_s)))
                        for lat in args.latencies
                    ]  # fmt: skip
            else:
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
                if len(args.worlds) > 1 or kind != "steady":
                    row["world"] = kind
                    row["onsets_s"] = [round(-v.eruption_age_s, 1) for v in spec.vents
                                       if v.eruption_age_s < 0 or kind == "onsets"]  # fmt: skip
                if args.curve and mode.startswith("geo@"):
                    row["latency_s"] = geo.latency_s
                    row["endmembers"] = geo.endmembers + (
                        "" if geo.persistence else "/no-persistence"
                    )
                    found = (r.geo or {}).get("endmembers")
                    if found is not None:
                        row["endmembers_found"] = found
                if preset in bounds:
                    ub = bounds[preset]["value"]
                    row["upper_bound"] = ub
                    row["upper_bound_exact"] = bounds[preset]["exact"]
                    row["fraction_of_bound"] = round(row["utility"] / ub, 4) if ub else None
                if mode == "prior":
                    row["prior"] = (r.geo or {}).get("catalog")
                rows.append(row)
                print(json.dumps(row), flush=True)
                write_text(Path(args.out) / f"{args.tag}.part{args.shard}.json", json.dumps(rows))
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
    groups = dict.fromkeys((r.get("world"), r["density"], r["preset"]) for r in rows)
    for world, density, preset in groups:
        sub = [r for r in rows if r["density"] == density and r["preset"] == preset
               and r.get("world") == world]  # fmt: skip
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
                **({"world": world} if world else {}),
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


def curve(rows: list[dict]) -> list[dict]:
    """The latency curve: per world, preset, end-members and latency, sums over the passes."""
    out = []
    geo = [r for r in rows if "latency_s" in r]
    keys = dict.fromkeys((r.get("world", "steady"), r["preset"], r["endmembers"]) for r in geo)
    for world, preset, em in keys:
        sub = [r for r in rows if r.get("world", "steady") == world and r["preset"] == preset]
        base = {r["strip"]: r["utility"] for r in sub if r["mode"] == "lookahead"}
        omni = {r["strip"]: r["utility"] for r in sub if r["mode"] == "omniscient"}
        blind = {r["strip"]: r["utility"] for r in sub if r["mode"] == "blind"}
        bound = {r["strip"]: r.get("upper_bound") for r in sub if r["mode"] == "lookahead"}
        lats = sorted({r["latency_s"] for r in sub if "latency_s" in r})
        for lat in lats:
            rs = [r for r in sub if r.get("latency_s") == lat and r.get("endmembers") == em]
            u = sum(r["utility"] for r in rs)
            b = sum(base[r["strip"]] for r in rs)
            o = sum(omni.get(r["strip"], 0.0) for r in rs)
            bl = sum(blind.get(r["strip"], 0.0) for r in rs)
            ub = [bound[r["strip"]] for r in rs if bound.get(r["strip"])]
            per = [r["utility"] / base[r["strip"]] for r in rs if base[r["strip"]] > 0]
            out.append({
                "world": world, "preset": preset, "endmembers": em,
                "latency_min": round(lat / 60.0, 2), "passes": len(rs),
                "utility": round(u, 3), "lookahead": round(b, 3), "omniscient": round(o, 3),
                "blind": round(bl, 3),
                "geo_targets": sum(r["geo_targets"] or 0 for r in rs),
                "geo_chosen": sum(r["geo_chosen"] or 0 for r in rs),
                "vs_lookahead": round(u / max(b, 1e-9), 4),
                "vs_omniscient": round(u / max(o, 1e-9), 4) if o else None,
                "fraction_of_bound": round(u / sum(ub), 4) if len(ub) == len(rs) and ub else None,
                "upper_bound": round(sum(ub), 3) if len(ub) == len(rs) and ub else None,
                "per_pass_min": round(min(per), 3) if per else None,
                "per_pass_max": round(max(per), 3) if per else None,
                "plumes_observed": sum(r["plumes_observed"] for r in rs),
                "plumes_total": sum(r["plumes_total"] for r in rs),
            })  # fmt: skip
    return out


def curve_figure(points: list[dict], path: Path) -> None:
    """Utility against GEO latency (per world and end-members): vs look-ahead, and vs the bound."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bounded = all(p["fraction_of_bound"] is not None for p in points)
    fig, axes = plt.subplots(1, 2 if bounded else 1, figsize=(10 if bounded else 5.5, 4.0))
    axes = np.atleast_1d(axes)
    styles = {"steady": "tab:blue", "onsets": "tab:red"}
    keys = dict.fromkeys((p["world"], p["preset"], p["endmembers"]) for p in points)
    for world, preset, em in keys:
        pts = [
            p for p in points if (p["world"], p["preset"], p["endmembers"]) == (world, preset, em)
        ]
        x = [p["latency_min"] for p in pts]
        ls = {"simulator": "-", "estimated": "--"}.get(em, "-.")
        label = f"{world} plumes, {em} end-members ({preset})"
        mk = {"simulator": "o", "estimated": "s"}.get(em, "^")
        axes[0].plot(x, [p["vs_lookahead"] for p in pts], ls, marker=mk, ms=4,
                     color=styles.get(world), label=label, alpha=1.0 if mk == "o" else 0.6)  # fmt: skip
        if em == "simulator":
            o = pts[0]["omniscient"] / max(pts[0]["lookahead"], 1e-9)
            axes[0].axhline(o, color=styles.get(world), lw=0.8, ls=":")
            bl = pts[0]["blind"] / max(pts[0]["lookahead"], 1e-9)
            axes[0].axhline(bl, color=styles.get(world), lw=2.0, alpha=0.3)
        if bounded:
            axes[1].plot(x, [p["fraction_of_bound"] for p in pts], ls, marker=mk, ms=4,
                         color=styles.get(world), label=label, alpha=1.0 if mk == "o" else 0.6)  # fmt: skip
    axes[0].axhline(1.0, color="k", lw=0.8)
    axes[0].set_ylabel("utility / look-ahead only (sum over passes)")
    axes[0].set_title(
        "GEO blueprint vs look-ahead only\n(dotted: omniscient blueprint)", fontsize=9
    )
    if bounded:
        axes[1].set_ylabel("utility / true upper bound")
        axes[1].set_title("fraction of the pass's upper bound", fontsize=9)
    for ax in axes:
        ax.set_xlabel("GEO latency (min)")
        ax.set_xticks(sorted({p["latency_min"] for p in points}))
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def combined_figure(docs: list[tuple[str, dict]], path: Path) -> None:
    """One panel per run (``(title, merged doc)``): utility / upper bound against latency.

    Lines: GEO per world (steady blue, onsets red) and end-members (simulator solid,
    estimated dashed); horizontal: look-ahead only (thin), the refinement alone with no
    blueprint (wide, pale) and the omniscient blueprint (dotted), in the world's colour.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(docs), figsize=(5.6 * len(docs), 5.0), sharey=False)
    axes = np.atleast_1d(axes)
    colour = {"steady": "tab:blue", "onsets": "tab:red"}
    for ax, (title, doc) in zip(axes, docs, strict=True):
        pts = doc["latency_curve"]
        for world in dict.fromkeys(p["world"] for p in pts):
            c = colour.get(world, "k")
            for em, ls, mk in (("simulator", "-", "o"), ("estimated", "--", "s")):
                sub = [p for p in pts if p["world"] == world and p["endmembers"] == em]
                if not sub:
                    continue
                ax.plot([p["latency_min"] for p in sub], [p["fraction_of_bound"] for p in sub],
                        ls, marker=mk, ms=4, color=c, alpha=1.0 if em == "simulator" else 0.6,
                        label=f"{world}: GEO, {em} end-members")  # fmt: skip
            p0 = next(p for p in pts if p["world"] == world)
            ub = p0["upper_bound"]
            ax.axhline(p0["lookahead"] / ub, color=c, lw=0.8, label=f"{world}: look-ahead only")
            ax.axhline(p0["blind"] / ub, color=c, lw=4.0, alpha=0.25,
                       label=f"{world}: refinement alone (no blueprint)")  # fmt: skip
            ax.axhline(p0["omniscient"] / ub, color=c, lw=1.0, ls=":",
                       label=f"{world}: omniscient blueprint")  # fmt: skip
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("GEO latency (min)")
        ax.set_xticks(sorted({p["latency_min"] for p in pts}))
        ax.set_ylabel("utility / true upper bound (sum over passes)")
        ax.grid(alpha=0.3)
    handles, labels = axes[-1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0.0, 0.15, 1.0, 1.0))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def merge(out: Path, tag: str = "geo_foresight", figure_path: Path | None = None) -> dict:
    """Combine the shards' rows (``<tag>.part*.json``) with the header."""
    doc = json.loads((out / f"{tag}.json.head").read_text())
    rows = []
    for f in sorted(out.glob(f"{tag}.part*.json")):
        rows += json.loads(f.read_text())
    rows = add_reference(rows)
    doc["rows"] = rows
    doc["summary"] = summarise(rows)
    doc["modes"] = MODES_DOC
    if any("latency_s" in r and "endmembers" in r for r in rows) and doc.get("curve"):
        doc["latency_curve"] = curve(rows)
        curve_figure(doc["latency_curve"], figure_path or out / f"{tag}.png")
    else:
        figure(rows, figure_path or out / f"{tag}.png")
    write_text(out / f"{tag}.json", json.dumps(doc, indent=1))
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
    ap.add_argument(
        "--curve",
        action="store_true",
        help="the latency curve: look-ahead only, GEO at each latency and --endmembers, omniscient",
    )
    ap.add_argument("--endmembers", default="simulator", help="with --curve: simulator,estimated")
    ap.add_argument(
        "--no-persistence",
        action="store_true",
        help="with --curve: also GEO (simulator end-members) without the persistence weight",
    )
    ap.add_argument("--worlds", default="steady", help="steady and/or onsets (comma-separated)")
    ap.add_argument("--onset-fraction", type=float, default=1.0, help="of the onsets worlds")
    ap.add_argument(
        "--onset-window-min", default="-60,0", help="onsets drawn in LO,HI minutes (pass clock)"
    )
    ap.add_argument("--tag", default="geo_foresight", help="output file stem")
    ap.add_argument(
        "--combine",
        default=None,
        help="merged --curve JSONs (comma-separated): their curves side by side in --figure",
    )
    ap.add_argument("--figure", default=None, help="the figure's path (default OUT/<tag>.png)")
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
    if args.combine:  # the latency curves of merged runs side by side
        docs = [json.loads(Path(p).read_text()) for p in args.combine.split(",")]
        titles = [
            f"look-ahead {d['command'].split('--look-ahead-km ')[1].split()[0]} km ahead: "
            f"{d['latency_curve'][0]['passes']} passes of each world"
            for d in docs
        ]
        combined_figure(list(zip(titles, docs, strict=True)), Path(args.figure))
        return
    if args.merge:
        doc = merge(out, args.tag, Path(args.figure) if args.figure else None)
        for line in doc.get("latency_curve") or doc["summary"]:
            print(json.dumps(line))
        return
    args.presets = args.presets.split(",")
    args.latencies = [float(v) for v in args.latencies.split(",")]
    args.densities = [d for d in args.densities.split(",") if d in DENSITIES]
    args.endmembers = args.endmembers.split(",")
    args.worlds = [w for w in args.worlds.split(",") if w in ("steady", "onsets")]
    args.onset_window_min = tuple(float(v) for v in args.onset_window_min.split(","))
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
            + (
                f"--curve --endmembers {','.join(args.endmembers)} "
                + ("--no-persistence " if args.no_persistence else "")
                + f"--worlds {','.join(args.worlds)} --onset-fraction {args.onset_fraction:g} "
                f"--onset-window-min={args.onset_window_min[0]:g},{args.onset_window_min[1]:g} "
                if args.curve
                else ""
            )
            + (f"--tag {args.tag} " if args.tag != "geo_foresight" else "")
            + f"--shards {args.shards} (each --shard), then --merge",
            "machine": machine(),
            "curve": bool(args.curve),
        }
        write_text(out / f"{args.tag}.json.head", json.dumps(head))
    t0 = time.perf_counter()
    run(args)
    peak = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    print(json.dumps({"shard": args.shard, "wall_s": round(time.perf_counter() - t0, 1),
                      "peak_rss_mb": peak}))  # fmt: skip


if __name__ == "__main__":
    main()
