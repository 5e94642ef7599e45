"""Benchmark of ``dyntarget constellation`` (issue 41): what cueing buys, the bound, scale.

Run from the repository root (the GVP catalog is read where the shared data lies)::

    nice python benchmarks/constellation.py --out docs/benchmarks/constellation.json \\
        --figure docs/img/constellation_curve.png --day-figure docs/img/constellation_day.png

The curve runs on the two-level eruption model (``--eruption-model eruptions``, the
default); ``--eruption-model episodes --parts curve --figure OTHER.png`` reruns the
earlier episode-only table (kept as ``curve_episodes``).

Parts (``--parts`` picks some): ``curve`` (1..500 satellites x 4 cueing modes x seeds,
``--seeds-20`` of them at 20 satellites, distributed allocation, plus greedy at 20
satellites), ``sensitivity`` (``none``, ``cross`` and ``cross+geo`` at 20 satellites under
other plume-episode parameters), ``bound`` (greedy and distributed
against the exact MILP on <= 10 satellites, 6 h), ``scale`` (the whole CLI process from
the shell under ``/usr/bin/time -v`` at 50/100/200/500 satellites, 24 h, 1,250 volcanoes),
``sweep`` (24 configurations serially and on a ``dask.distributed`` LocalCluster of
processes: same summaries, byte for byte), ``day`` (the world map of a 20-satellite day),
``fidelity`` (the target level against the pixel-level pass loop, ``fly``, on 36 sampled
overflights of a 20-satellite day: :func:`fly_overflight`), ``revisit`` (not in the default
set: ``none``, ``cross`` and ``cross+geo`` at 20 satellites on ``--revisit-seeds`` seeds,
the 20-satellite targets with every day's eruptions, gaps and episodes pooled per mode,
:func:`run_revisit`), ``regard`` (not in the default set either: the same with ``fast``
agility's field of regard widened to 40, 50 and 60 deg, :func:`run_regard`).
"""

from __future__ import annotations

import argparse
import functools
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from dyntarget.synth.worlds import WorldBase

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


def config(
    n: int, cueing: str, allocation: str, seed: int, hours: float = 24.0, model: str = "eruptions"
) -> dict:
    return {
        "eruption_model": model,
        "walker": WALKERS[n],
        "altitude_km": 500.0,
        "inclination_deg": "sso",
        "start": START,
        "hours": hours,
        "seed": seed,
        "cueing": cueing,
        "allocation": allocation,
    }


def run_curve(catalog, seeds: int, seeds20: int, model: str) -> list[dict]:
    from dyntarget.constellation.run import sweep

    configs = [
        config(n, m, "distributed", s, model=model)
        for n in (1, 7, 20, 60, 200, 500)
        for m in MODES
        for s in range(seeds20 if n == 20 else seeds)
    ]
    configs += [config(20, m, "greedy", s, model=model) for m in MODES for s in range(seeds20)]
    t = time.perf_counter()
    out = sweep(configs, catalog, progress=True)
    print(f"curve: {len(configs)} runs in {time.perf_counter() - t:.0f} s", file=sys.stderr)
    return out


SENSITIVITY = (
    {"episodes_per_day": 3.0, "episode_median_h": 3.0},
    {"episodes_per_day": 1.5, "episode_median_h": 3.0},
    {"episodes_per_day": 6.0, "episode_median_h": 3.0},
    {"episodes_per_day": 3.0, "episode_median_h": 1.0},
    {"episodes_per_day": 3.0, "episode_median_h": 9.0},
    {"episodes_per_day": 1.0, "episode_median_h": 24.0},
)
"""Plume-episode parameters (assumptions of the two-level model) the 20-satellite targets
are re-measured under."""


def run_sensitivity(catalog, seeds: int) -> list[dict]:
    """``none``, ``cross`` and ``cross+geo`` at 20 satellites under other episode parameters."""
    from dyntarget.constellation.run import sweep

    configs = [
        {**config(20, m, "distributed", s), **p}
        for p in SENSITIVITY
        for m in ("none", "cross", "cross+geo")
        for s in range(seeds)
    ]
    return sweep(configs, catalog, progress=True)


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
    busy = [
        {**c, "eruption_model": "episodes", "eruptions_per_day": 400.0, "agility": "slow"}
        for c in configs
    ]
    return sweep(configs + busy, catalog, progress=True)


@functools.cache
def _gvp():
    """The GVP catalog, read once per process (each worker of :func:`run_revisit`)."""
    from dyntarget.constellation.world import read_catalog

    return read_catalog(GVP)


def _revisit_gaps(cfg: dict) -> dict:
    """One constellation-day: its gaps, observations after detection and episode delays."""
    from dyntarget.constellation.run import config_day
    from dyntarget.constellation.simulate import (
        episode_delays,
        observations_after_detection,
        revisit_gaps,
    )

    _regard_preset(cfg.get("agility", "fast"))  # in this worker too
    day, _ = config_day(cfg, _gvp())
    started, delays = episode_delays(day.eruptions, day.table, cfg["hours"] * 3600.0)
    return {"cueing": cfg["cueing"], "seed": cfg["seed"], "gaps_s": revisit_gaps(day.table),
            "per6": observations_after_detection(day.table),
            "episodes_started": started, "episode_delays_s": delays,
            "median_revisit_s": day.summary["median_revisit_s"],
            "observations_per_eruption_6h": day.summary["observations_per_eruption_6h"]}  # fmt: skip


def _regard_preset(name: str) -> None:
    """Register ``fast-regard-DEG`` (``fast`` with another field of regard) in this process."""
    import dataclasses

    from dyntarget.schedule import AGILITY

    if name.startswith("fast-regard-") and name not in AGILITY:
        deg = float(name.removeprefix("fast-regard-"))
        AGILITY[name] = dataclasses.replace(AGILITY["fast"], name=name, field_of_regard_deg=deg)


def run_regard(seeds: int, degrees: tuple[float, ...] = (30.0, 40.0, 50.0, 60.0)) -> list[dict]:
    """The 20-satellite targets of :func:`run_revisit` with wider fields of regard.

    ``fast`` agility with the field of regard (largest off-nadir angle) replaced: what a
    mission designer would have to fly for the targets the default (30 deg) misses. Each
    row is :func:`run_revisit`'s ratios on ``seeds`` days; 30 deg is the default itself.
    """
    rows = []
    for deg in degrees:
        agility = "fast" if deg == 30.0 else f"fast-regard-{deg:g}"
        out = run_revisit(seeds, agility=agility)
        keep = (
            "per6_cross_over_none", "per6_cross_over_none_bootstrap_95", "cross_over_none",
            "cross_over_none_bootstrap_95", "episodes_6h_geo_over_none",
            "episode_delay_geo_over_none", "episode_delay_geo_over_none_bootstrap_95", "wall_s",
        )  # fmt: skip
        row = {"field_of_regard_deg": deg, "agility": agility, "seeds": seeds}
        row.update({k: out.get(k) for k in keep})
        row["modes"] = {
            m: {
                k: v[k]
                for k in (
                    "observations_per_eruption_6h",
                    "pooled_median_revisit_s",
                    "gaps",
                    "pooled_median_episode_delay_s",
                    "episodes_started",
                    "episodes_observed_within_6h",
                    "detected_eruptions",
                )
            }
            for m, v in out["modes"].items()
        }
        rows.append(row)
    return rows


def run_revisit(seeds: int, agility: str = "fast") -> dict:
    """The 20-satellite targets over ``seeds`` days, enough for ``none`` to have gaps: per
    mode (``none``, ``cross``, ``cross+geo``), every gap between successive observations of
    an eruption, every detected eruption's observations in the 6 h after its detection and
    every plume episode's delay to its first observation, pooled over the days (a day's
    own median exists only where it has a gap); the ratios the targets name, with
    bootstrap intervals (2,000 resamples, seeded)."""
    from concurrent.futures import ProcessPoolExecutor

    modes = ("none", "cross", "cross+geo")
    configs = [config(20, m, "distributed", s) for m in modes for s in range(seeds)]
    if agility != "fast":
        configs = [{**c, "agility": agility} for c in configs]
    t = time.perf_counter()
    with ProcessPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(_revisit_gaps, configs))
    out: dict = {"seeds": seeds, "wall_s": round(time.perf_counter() - t, 1), "modes": {}}
    for m in modes:
        mine = [r for r in runs if r["cueing"] == m]
        delays = sorted(d for r in mine for d in r["episode_delays_s"])
        gaps = sorted(g for r in mine for g in r["gaps_s"])
        out["modes"][m] = {
            "gaps": len(gaps),
            "seeds_with_a_gap": sum(1 for r in mine if r["gaps_s"]),
            "pooled_median_revisit_s": float(statistics.median(gaps)) if gaps else None,
            "gaps_s": [round(g, 3) for g in gaps],
            "per_seed_median_s": [r["median_revisit_s"] for r in mine],
            "detected_eruptions": sum(len(r["per6"]) for r in mine),
            "observations_per_eruption_6h": statistics.fmean(p for r in mine for p in r["per6"]),
            "per6": [p for r in mine for p in r["per6"]],
            "episodes_started": sum(r["episodes_started"] for r in mine),
            "episodes_observed_within_6h": sum(d <= 6 * 3600.0 for d in delays),
            "pooled_median_episode_delay_s": float(statistics.median(delays)) if delays else None,
            "episode_delays_s": [round(d, 3) for d in delays],
        }
    a, b = (out["modes"][m]["pooled_median_revisit_s"] for m in ("cross", "none"))
    out["cross_over_none"] = None if a is None or not b else round(a / b, 4)
    if a is not None and b:  # how sure: the ratio of medians over gaps resampled (seeded)
        import numpy as np

        rng = np.random.default_rng(0)
        g = {m: np.asarray(out["modes"][m]["gaps_s"]) for m in ("cross", "none")}
        ratios = [
            np.median(rng.choice(g["cross"], g["cross"].size))
            / np.median(rng.choice(g["none"], g["none"].size))
            for _ in range(2000)
        ]
        lo, hi = np.percentile(ratios, [2.5, 97.5])
        out["cross_over_none_bootstrap_95"] = [round(float(lo), 4), round(float(hi), 4)]
    # the other 20-satellite target: observations per eruption in the 6 h after its first
    # detection, cross over none, pooled over every detected eruption of every day
    import numpy as np

    rng = np.random.default_rng(1)
    p = {m: np.asarray(out["modes"][m]["per6"], float) for m in ("cross", "none")}
    out["per6_cross_over_none"] = round(float(p["cross"].mean() / p["none"].mean()), 4)
    boot = [
        rng.choice(p["cross"], p["cross"].size).mean()
        / rng.choice(p["none"], p["none"].size).mean()
        for _ in range(2000)
    ]
    out["per6_cross_over_none_bootstrap_95"] = [
        round(float(v), 4) for v in np.percentile(boot, [2.5, 97.5])
    ]
    # cross+geo against none, per plume episode: the share observed within 6 h of its onset
    # (the days' episodes pooled) and the median delay to the first observation
    g, n = out["modes"]["cross+geo"], out["modes"]["none"]
    share = {k: v["episodes_observed_within_6h"] / v["episodes_started"] for k, v in
             (("cross+geo", g), ("none", n))}  # fmt: skip
    out["episodes_6h_geo_over_none"] = round(share["cross+geo"] / share["none"], 4)
    dg, dn = np.asarray(g["episode_delays_s"]), np.asarray(n["episode_delays_s"])
    out["episode_delay_geo_over_none"] = round(float(np.median(dg) / np.median(dn)), 4)
    boot = [
        np.median(rng.choice(dg, dg.size)) / np.median(rng.choice(dn, dn.size)) for _ in range(2000)
    ]
    out["episode_delay_geo_over_none_bootstrap_95"] = [
        round(float(v), 4) for v in np.percentile(boot, [2.5, 97.5])
    ]
    print(f"revisit: {len(configs)} runs in {out['wall_s']:.0f} s", file=sys.stderr)
    return out


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


def _cell(rows: list[dict], m: str, n: int) -> list[dict]:
    return [
        r
        for r in rows
        if r["options"]["cueing"] == m
        and r["satellites"] == n
        and r["options"]["allocation"] == "distributed"
    ]


def curve_figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    two = rows[0]["options"].get("eruption_model", "episodes") == "eruptions"
    panels = (
        (
            ("eruptions_observed", "eruptions", "GVP eruptions observed in the day (%)"),
            (
                "episodes_observed_within_6h",
                "episodes_started",
                "plume episodes observed within 6 h of their onset (%)",
            ),
        )
        if two
        else (("observed_within_6h", "eruptions", "eruptions observed within 6 h of onset (%)"),)
    )
    fig, axes = plt.subplots(1, len(panels) + 1, figsize=(5.5 * (len(panels) + 1), 4.2))
    ns = (1, 7, 20, 60, 200, 500)
    for m in MODES:
        for ax, (num, den, _) in zip(axes, panels, strict=False):
            y = [np.mean([r[num] / max(r[den], 1) for r in _cell(rows, m, n)]) for n in ns]
            ax.plot(ns, 100 * np.array(y), marker="o", label=m)
        per6 = []
        for n in ns:
            vals = [r["observations_per_eruption_6h"] for r in _cell(rows, m, n)]
            vals = [v for v in vals if v is not None]  # None: nothing detected that day
            per6.append(np.mean(vals) if vals else np.nan)
        axes[-1].plot(ns, per6, marker="o", label=m)
    labels = [p[2] for p in panels] + ["observations per eruption, 6 h after first detection"]
    for ax, label in zip(axes, labels, strict=True):
        ax.set_xscale("log")
        ax.set_xlabel("satellites (Walker, 500 km, sun-synchronous)")
        ax.set_ylabel(label)
        ax.grid(lw=0.3)
        ax.legend(title="cueing", fontsize=8)
    world = "GVP eruptions holding plume episodes" if two else "independent plume episodes"
    fig.suptitle(
        f"dyntarget constellation: 24 h, GVP Holocene volcanoes, {world}, distributed allocation"
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, metadata={"Software": None})


# -- two fidelities, one physics: the target level against fly on sampled overflights --

FIDELITY_GSD_M = 100.0
"""High-resolution GSD of the pixel-level worlds (WFOV: x FIDELITY_FACTOR)."""
FIDELITY_FACTOR = 2
FIDELITY_INNER_PX = 1024
"""Side of the window rendered around the vent, high-resolution pixels (102 km)."""
FIDELITY_TOLERANCE = 0.02
"""Largest |pixel-level - target-level| utility per overflight accepted (cos of off-nadir;
0.02 is 2.3 % of cos 30 deg, about 2.3 deg of off-nadir angle at the field of regard's edge)."""


class OffsetStrip(WorldBase):
    """A wide strip centred on the ground track holding a narrow rendered strip off track.

    The pass loop (``fly``) puts the ground track down the middle of its strip; a volcano
    ``cross_m`` across track needs a strip twice as wide. Only the window around the vent
    is rendered (a :class:`dyntarget.synth.strip_world.MovingStrip`); the rest is plume-free ground
    (the inner window's median radiance), so its truth is empty there.
    """

    def __init__(self, inner, width: int, col0: int) -> None:
        self.inner, self.col0 = inner, col0
        self.shape = (inner.shape[0], width)
        self.gsd, self.crs, self.transform, self.valid = inner.gsd, None, None, None
        self.id, self.wind = inner.id, inner.wind
        self.truth_step_s = inner.truth_step_s
        self._key, self._truth = None, None

    def _pad(self, a, fill=0):
        import numpy as np

        out = np.full((*a.shape[:-1], self.shape[1]), fill, a.dtype)
        out[..., self.col0 : self.col0 + a.shape[-1]] = a
        return out

    def image_at(self, t: float, top: int, bottom: int):
        import numpy as np

        im = self.inner.image_at(t, top, bottom)
        out = self._pad(im)
        out[..., : self.col0] = np.median(im, axis=(1, 2))[:, None, None]
        out[..., self.col0 + im.shape[-1] :] = np.median(im, axis=(1, 2))[:, None, None]
        return out

    def truth_at(self, t: float):
        from dyntarget.synth.worlds import Truth
        from dyntarget.utility import UtilityMaps

        tr = self.inner.truth_at(t)
        if self._key is not tr:
            m = tr.maps
            valid = None if m.valid is None else self._pad(m.valid, True)
            maps = UtilityMaps(
                self._pad(m.label), self._pad(m.intensity), self._pad(m.gradient), valid
            )
            self._key, self._truth = tr, Truth(maps, self._pad(tr.ids))
        return self._truth


def fly_overflight(case: dict, *, agility: str = "fast", index: int = 0) -> dict:
    """Fly one overflight of :func:`dyntarget.constellation.fidelity.overflight_cases` at pixel level.

    The world: :func:`dyntarget.synth.dynamic.sample_world`'s ground and one vent with the
    eruption's plume parameters (wind, drift relative to the flight direction, source
    radius, turbulence, fade time, optical depth) and age (capped at 6 fade times: older
    puffs have faded below any label, exp(-6)), ``case["cross_m"]`` across the track.
    The pass: the truth as classifier (``--truth``), no denoising (a 1-2 km plume at a
    200 m WFOV GSD is a few pixels), a fixed 0.5 s compute budget per frame, 32-row frames.
    The pixel level's utility: ``cos`` of the off-nadir angle of its first pointing on the
    plume (the pinpoint observation), in the pass's own (spherical) geometry.
    """
    import math
    from dataclasses import replace

    import numpy as np

    from dyntarget.fly import PassConfig, fly_pass
    from dyntarget.schedule import get_agility, look_vectors, off_nadir_deg, visibility_windows
    from dyntarget.synth.dynamic import Wind, sample_world
    from dyntarget.synth.strip_world import MovingStrip

    gsd, f, inner_px = FIDELITY_GSD_M, FIDELITY_FACTOR, FIDELITY_INNER_PX
    base = sample_world(0, index, size=inner_px, gsd=gsd)
    age = min(case["age_s"], 6.0 * case["fade_s"])
    vent = replace(
        base.vents[0],
        x=inner_px / 2.0,
        y=inner_px / 2.0,
        emission_optical_depth=case["optical_depth"],
        source_sigma_m=case["source_m"],
        turbulence=case["turbulence"],
        fade_s=case["fade_s"],
        eruption_age_s=age,
    )
    wind = Wind(case["wind_mps"], (case["drift_rel_deg"] + 180.0) % 360.0)
    spec = replace(base, wind=wind, vents=(vent,), clouds=(), id=f"overflight-{index:03d}")
    inner = MovingStrip(spec, (0, 0, inner_px, inner_px), truth_step_s=5.0)
    half = math.ceil((abs(case["cross_m"]) / gsd + inner_px / 2 + 64) / 32.0) * 32
    width = 2 * half  # the track down the middle; a multiple of the factor
    col0 = half + round(case["cross_m"] / gsd) - inner_px // 2
    world = OffsetStrip(inner, width, col0)
    config = PassConfig(
        agility=agility,
        factor=f,
        frame_px=32,
        compute_budget_s=0.5,
        denoise=False,
        altitude_m=case["altitude_m"],
        look_ahead_m=500e3,
    )
    t0 = time.perf_counter()
    r = fly_pass(world, None, config)
    wall = time.perf_counter() - t0
    fr = r.frames
    g, gw = fr.geometry, fr.geometry.wfov_gsd_m

    def ground(x, y):  # strip WFOV pixel -> (along at t = 0, cross), the loop's geometry
        along = g.look_ahead_m + (fr.tops[0] + (fr.frame_px - 1) / 2.0 - np.asarray(y)) * gw
        return along, (np.asarray(x) - (fr.wfov_shape[1] - 1) / 2.0) * gw

    va, vc = ground([(col0 + vent.x) / f - 0.5], [vent.y / f - 0.5])
    v_in, v_out = visibility_windows(g, get_agility(agility), va, vc)
    plume = np.asarray(r.flown.plume) > 0
    out = {
        "cross_m": case["cross_m"],
        "strip_width_km": width * gsd / 1e3,
        "pointings": len(r.flown.x),
        "plume_pointings": int(plume.sum()),
        "observed": bool(plume.any()),
        "vent_window_s": round(float(v_out[0] - v_in[0]), 3),
        "wall_s": round(wall, 2),
    }
    if plume.any():
        k = int(np.flatnonzero(plume)[np.argmin(np.asarray(r.flown.t)[plume])])
        a, c = ground([r.flown.x[k]], [r.flown.y[k]])
        t = r.flown.t[k]
        deg = float(off_nadir_deg(look_vectors(g, a, c, np.array([t])))[0])
        out.update(
            off_nadir_deg=round(deg, 4),
            utility=round(math.cos(math.radians(deg)), 6),
            after_vent_enters_s=round(float(t - v_in[0]), 3),
        )
    return out


def run_fidelity(catalog, n: int = 36) -> dict:
    """The target level against fly on ``n`` overflights of a 20-satellite day (seed 0)."""
    import math

    from dyntarget.constellation.fidelity import overflight_cases

    cases = overflight_cases(catalog, n)
    rows = []
    t = time.perf_counter()
    for i, case in enumerate(cases):
        px = fly_overflight(case, index=i)
        row = {
            "target": {k: (round(v, 6) if isinstance(v, float) else v) for k, v in case.items()},
            "pixel": px,
        }
        if px["observed"]:
            row["utility_diff"] = round(px["utility"] - case["utility"], 6)
            old = math.cos(math.radians(case["off_nadir_window_end_deg"]))
            row["utility_diff_window_end"] = round(px["utility"] - old, 6)
        rows.append(row)
        print(f"fidelity {i + 1}/{len(cases)}: {row.get('utility_diff')}", file=sys.stderr)
    diffs = [abs(r["utility_diff"]) for r in rows if "utility_diff" in r]
    old = [abs(r["utility_diff_window_end"]) for r in rows if "utility_diff_window_end" in r]
    return {
        "overflights": len(rows),
        "observed_by_both": len(diffs),
        "tolerance": FIDELITY_TOLERANCE,
        "within_tolerance": sum(d <= FIDELITY_TOLERANCE for d in diffs),
        "max_abs_utility_diff": max(diffs, default=None),
        "mean_abs_utility_diff": (sum(diffs) / len(diffs)) if diffs else None,
        "max_abs_utility_diff_window_end": max(old, default=None),
        "wall_s": round(time.perf_counter() - t, 1),
        "rows": rows,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="docs/benchmarks/constellation.json")
    p.add_argument("--figure", default="docs/img/constellation_curve.png")
    p.add_argument("--day-figure", default="docs/img/constellation_day.png")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--seeds-20", type=int, default=5, help="seeds at 20 satellites")
    p.add_argument(
        "--eruption-model",
        choices=("eruptions", "episodes"),
        default="eruptions",
        help="the curve's world (episodes: the earlier table, kept as curve_episodes)",
    )
    p.add_argument("--parts", default="curve,sensitivity,bound,scale,sweep,day,fidelity")
    p.add_argument(
        "--revisit-seeds", type=int, default=40, help="seeds of the revisit part (20 satellites)"
    )
    args = p.parse_args()
    if not GVP.is_file():
        sys.exit(f"benchmark: the GVP catalog is not at {GVP}")
    from dyntarget.constellation.world import read_catalog

    catalog = read_catalog(GVP)
    out = Path(args.out)
    result = json.loads(out.read_text()) if out.is_file() else {}
    from dyntarget.evaluate.bench import machine

    result["machine"] = machine()  # the machine and code, as every benchmark record names them
    parts = set(args.parts.split(","))
    out.parent.mkdir(parents=True, exist_ok=True)

    def save() -> None:  # after every part: a later part's failure loses nothing
        out.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")

    if "curve" in parts:
        key = "curve" if args.eruption_model == "eruptions" else "curve_episodes"
        result[key] = run_curve(catalog, args.seeds, args.seeds_20, args.eruption_model)
        curve_figure(result[key], Path(args.figure))
        save()
    if "sensitivity" in parts:
        result["sensitivity"] = run_sensitivity(catalog, args.seeds_20)
        save()
    if "bound" in parts:
        result["bound"] = run_bound(catalog, 2 * args.seeds)
        save()
    if "scale" in parts:
        result["scale"] = run_scale()
        save()
    if "sweep" in parts:
        result["sweep"] = run_sweep_check(catalog)
        save()
    if "day" in parts:
        result["day"] = day_figure(Path(args.day_figure))
        save()
    if "fidelity" in parts:
        result["fidelity"] = run_fidelity(catalog)
    if "revisit" in parts:
        result["revisit"] = run_revisit(args.revisit_seeds)
    if "regard" in parts:
        result["regard"] = run_regard(args.revisit_seeds)
    save()
    print(out)


if __name__ == "__main__":
    main()
