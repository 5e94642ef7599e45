"""Plume-top heights measured from rendered oblique look-ahead frames (issue 40, phase A).

For each of ``--n`` synthetic 3D worlds (``sample_world`` of ``--seed``, made 3D with
``with_heights``: top 2-15 km; the columns at their top, no rise during the looks;
wind 0-20 m/s drawn), the look-ahead looks three times at the plume from 500, 400 and
300 km ahead of a spacecraft 500 km up flying north (view zenith 48, 41 and 33 deg;
14 s apart). Each frame is rendered by ``World.render_look`` on a fixed ground window
(the parallax displacement included). The plume's apparent motion between the first
look and each later one is measured by ``plume_disparity`` (OpenCV Farneback inside the
first look's true mask, the ``--truth`` mask: where a perfect classifier puts it), after
moving the later frame back by what a prior height of 8.5 km and a wind prior predict.
``fit_height`` then solves for the height and the drift, with the wind prior (the truth
plus a random error, ``--prior-sd`` m/s per axis, default 2; stated sigma 3 m/s: a GEO-
or forecast-like prior). No NFOV, no planner: the pipeline does not use heights yet.

    python benchmarks/plumes_3d.py --n 40 [--prior-sd 2] [--figure docs/img/plumes-3d-looks.png]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace

import numpy as np

from dyntarget import parallax
from dyntarget.predict.height import Look, fit_height, plume_disparity
from dyntarget.synth.dynamic import World, sample_world, with_heights

ALTITUDE = 500e3
AHEAD_KM = (500.0, 400.0, 300.0)
GSD = 30.0
SIZE = 192
PRIOR_HEIGHT = 8500.0
SIGMA_M = 30.0  # position noise assumed per look, metres (about one 30 m pixel)


def one_plume(seed: int, i: int, rng: np.random.Generator, prior_sd: float) -> dict:
    wind = float(rng.uniform(0.0, 20.0))
    spec = sample_world(seed, i, size=SIZE, gsd=GSD, wind_mps=wind)
    spec = with_heights(spec, plume_height_km=(2.0, 15.0))
    spec = replace(
        spec,
        vents=tuple(replace(v, rise_mps=None) for v in spec.vents),  # at the top already
        clouds=tuple(c for c in spec.clouds if c.volcanic is False),  # the plume alone
    )
    world = World(spec)
    h_true = float(spec.vents[0].top_height_m)
    v_ground = parallax.ground_speed(ALTITUDE)
    times = [(AHEAD_KM[0] - a) * 1e3 / v_ground for a in AHEAD_KM]
    track_x = SIZE / 2.0
    nadirs = [(track_x, SIZE / 2.0 + a * 1e3 / GSD) for a in AHEAD_KM]
    top = int(parallax.parallax_shift(ALTITUDE, AHEAD_KM[0] * 1e3, 15e3) / GSD) + 48
    window = (0, -top, SIZE, SIZE + top + 48)
    frames = [
        world.render_look(t, window, nadir_px=n, altitude_m=ALTITUDE)
        for t, n in zip(times, nadirs, strict=True)
    ]
    m0 = frames[0].mask
    if m0.sum() < 50:
        return {"seed": seed, "index": i, "skipped": "plume too faint in the first look"}
    rows, cols = np.nonzero(m0)
    c0x, c0y = float(cols.mean()), float(rows.mean()) + window[1]  # world px
    ex = spec.wind.velocity_px(GSD)
    true_wind = (ex[0] * GSD, -ex[1] * GSD)  # east, north m/s
    err = np.random.default_rng([seed, i, 1]).normal(0.0, 1.0, 2) * prior_sd
    prior = (true_wind[0] + float(err[0]), true_wind[1] + float(err[1]))

    def apparent_px(h: float, t: float, n: tuple[float, float]) -> tuple[float, float]:
        """Where the prior model puts the feature seen in look 0 at time t (world px)."""
        # true ground point under the look-0 feature at the prior height, drifted by the prior
        ax, ay = parallax.unshift_xy(
            ALTITUDE, (c0x - nadirs[0][0]) * GSD, (c0y - nadirs[0][1]) * GSD, h
        )
        px = nadirs[0][0] + float(ax) / GSD + prior[0] * t / GSD
        py = nadirs[0][1] + float(ay) / GSD - prior[1] * t / GSD
        sx, sy = parallax.shift_xy(ALTITUDE, (px - n[0]) * GSD, (py - n[1]) * GSD, h)
        return px + float(sx) / GSD, py + float(sy) / GSD

    looks = [
        Look(
            times[0],
            c0x * GSD,
            -c0y * GSD,
            nadirs[0][0] * GSD,
            -nadirs[0][1] * GSD,
            ALTITUDE,
            SIGMA_M,
        )
    ]
    quality = []
    for k in (1, 2):
        gx, gy = apparent_px(PRIOR_HEIGHT, times[k], nadirs[k])
        d, why = plume_disparity(
            frames[0].image, frames[k].image, m0, guess_px=(gx - c0x, gy - c0y), search_px=128
        )
        if d is None:
            return {"seed": seed, "index": i, "skipped": why}
        quality.append(d.quality)
        x, y = c0x + d.dx_px, c0y + d.dy_px
        looks.append(
            Look(
                times[k],
                x * GSD,
                -y * GSD,
                nadirs[k][0] * GSD,
                -nadirs[k][1] * GSD,
                ALTITUDE,
                SIGMA_M,
            )
        )
    fit = fit_height(looks, wind_prior=prior, wind_prior_sigma_mps=3.0)
    return {
        "seed": seed,
        "index": i,
        "true_height_m": h_true,
        "height_m": fit.height_m,
        "height_sigma_m": fit.height_sigma_m,
        "wind_mps": round(wind, 2),
        "flow_quality": min(quality),
        "_frames": frames,
        "_window": window,
        "_looks": looks,
        "_vent": (spec.vents[0].x * GSD / 1e3, -spec.vents[0].y * GSD / 1e3),
        "_fit": fit,
    }


def figure(rec: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames, window = rec["_frames"], rec["_window"]
    fig, axes = plt.subplots(1, 4, figsize=(13, 4.6), gridspec_kw={"width_ratios": [1, 1, 1, 1.5]})
    ext = [0, window[2] * GSD / 1e3, -(window[1] + window[3]) * GSD / 1e3, -window[1] * GSD / 1e3]
    for ax, f, a, lk in zip(axes[:3], frames, AHEAD_KM, rec["_looks"], strict=True):
        rgb = np.clip(f.image[:3].transpose(1, 2, 0) * 2.5, 0, 1)
        ax.imshow(rgb, extent=ext, origin="upper")
        ax.contour(
            f.mask, levels=[0.5], colors="yellow", linewidths=0.8, extent=ext, origin="upper"
        )
        theta = math.degrees(float(parallax.view_zenith(ALTITUDE, a * 1e3)))
        ax.set_title(f"{a:g} km ahead, θ = {theta:.1f}°\nt = {lk.t_s:.1f} s", fontsize=9)
        ax.plot(lk.x_m / 1e3, lk.y_m / 1e3, "r+", ms=10, mew=2, label="plume, measured")
        ax.plot(*rec["_vent"], "c^", ms=7, label="vent (ground truth)")
        ax.set_xlabel("east, km")
    axes[0].set_ylabel("north, km (ground grid)")
    axes[0].legend(fontsize=7, loc="lower left")
    ax = axes[3]
    t = np.array([lk.t_s for lk in rec["_looks"]])
    y = np.array([lk.y_m for lk in rec["_looks"]]) / 1e3
    ax.plot(t, y, "ko", label="measured (flow)")
    fit = rec["_fit"]
    tt = np.linspace(t[0], t[-1], 50)
    for h, style, lab in ((fit.height_m, "r-", "fit"), (rec["true_height_m"], "b--", "truth")):
        x0, y0 = fit.position_m
        vx, vy = fit.wind_mps
        pts = []
        for ti in tt:
            ny = rec["_looks"][0].nadir_y_m + parallax.ground_speed(ALTITUDE) * ti
            px, py = x0 + vx * ti, y0 + vy * ti
            s = float(parallax.parallax_shift(ALTITUDE, math.hypot(px, py - ny), h))
            pts.append((py + s) / 1e3)
        ax.plot(tt, pts, style, label=f"{lab}: h = {h / 1e3:.2f} km")
    ax.set_xlabel("time, s")
    ax.set_ylabel("apparent north, km")
    ax.set_title(
        f"height {fit.height_m / 1e3:.2f} ± {fit.height_sigma_m / 1e3:.2f} km "
        f"(true {rec['true_height_m'] / 1e3:.2f} km)",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--seed", type=int, default=40)
    ap.add_argument("--prior-sd", type=float, default=2.0)
    ap.add_argument("--figure", default=None)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    recs, skipped = [], []
    for i in range(args.n):
        r = one_plume(args.seed, i, rng, args.prior_sd)
        if "skipped" in r:
            skipped.append(r)
            continue
        if args.figure and not recs:
            figure(r, args.figure)
        recs.append(r)
    err = np.array([r["height_m"] - r["true_height_m"] for r in recs])
    sig = np.array([r["height_sigma_m"] for r in recs])
    out = {
        "prior_sd_mps": args.prior_sd,
        "plumes": len(recs),
        "skipped": [(r["index"], r["skipped"].split(":")[0]) for r in skipped],
        "rmse_m": round(float(np.sqrt(np.mean(err**2))), 1),
        "bias_m": round(float(err.mean()), 1),
        "median_abs_m": round(float(np.median(np.abs(err))), 1),
        "worst_m": round(float(np.abs(err).max()), 1),
        "rms_reported_sigma_m": round(float(np.sqrt(np.mean(sig**2))), 1),
        "seconds": round(time.perf_counter() - t0, 1),
        "rows": [
            {
                k: (round(v, 1) if isinstance(v, float) else v)
                for k, v in r.items()
                if not k.startswith("_")
            }
            for r in recs
        ],
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
