"""Figure: one plume seen from three look-ahead angles, its measured and true top height, and
the NFOV pointings with and without the parallax correction over the truth.

A synthetic strip (:func:`dyntarget.synth.strip.strip_spec`, 512 px wide at 8 m, one vent)
made 3D with its column at ``--height-km`` (no rise), flown three times by ``fly``'s loop
(:func:`dyntarget.fly.loop.fly_pass`, the oracle classifier, ``fast`` agility, 500 km up,
500 km ahead): uncorrected (``off``), with the height measured from the look-ahead's
re-looks (``estimated``) and with the true height (``true``). The first three panels are the
look-ahead frame in which the plume was first seen and the two re-looks (rendered by
``World.look_at`` from the nadir at the middle of each re-look's window), the plume outline
(what each frame shows) and the vent; the last panel is the plume on the ground at the
middle of the NFOV's pointings, with the pointings of each run.

    python benchmarks/parallax_figure.py --out docs/img/plumes-3d-aim.png
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from dyntarget import parallax
from dyntarget.fly import PassConfig, fly_pass, frame_plan
from dyntarget.predict.relooks import Geometry3D
from dyntarget.synth.dynamic import with_heights
from dyntarget.synth.strip import strip_spec
from dyntarget.synth.strip_world import MovingStrip


def build(seed: int, height_m: float, wind_mps: float):
    spec, window = strip_spec(seed, width=512, length=4448, plumes=1, wind_mps=wind_mps)
    spec = with_heights(spec, plume_height_km=(2.0, 15.0), cloud_height_km=(1.0, 12.0))
    vents = tuple(replace(v, top_height_m=height_m, rise_mps=None) for v in spec.vents)
    clouds = tuple(c for c in spec.clouds if not c.volcanic)
    return replace(spec, vents=vents, clouds=clouds), window


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--height-km", type=float, default=10.0)
    ap.add_argument("--wind-mps", type=float, default=5.0)
    ap.add_argument("--out", type=Path, default=Path("docs/img/plumes-3d-aim.png"))
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spec, window = build(args.seed, args.height_km * 1e3, args.wind_mps)
    world = MovingStrip(spec, window)
    runs = {}
    for mode in ("off", "estimated", "true"):
        config = PassConfig(agility="fast", parallax=mode)
        runs[mode] = (config, fly_pass(world, None, config))
    config, est = runs["estimated"]
    frames = frame_plan(world, config)
    f = config.factor
    geo = Geometry3D(frames.geometry, frames.wfov_shape, frames.frame_px, frames.tops[0], f)
    if not est.heights:
        raise SystemExit("no plume was seen: try another --seed")
    h = est.heights[0]
    t_looks = [frames.acquired_s(h.frame), *est.relook_times[:2]]
    vent = spec.vents[0]
    vx, vy = vent.x - window[0], vent.y - window[1]  # strip hr px
    top = int(max(0, vy - 1900))
    bottom = int(min(world.shape[0], vy + 400))
    fig, axes = plt.subplots(1, 4, figsize=(11, 7.2))
    ext = (0, world.shape[1], bottom, top)
    for ax, t in zip(axes[:3], t_looks, strict=False):
        nadir = geo.nadir_hr(t)
        image, mask = world.look_at(t, top, bottom, nadir_xy=nadir, altitude_m=config.altitude_m)
        rgb = np.clip(image[:3].transpose(1, 2, 0) * 2.5, 0, 1)
        ax.imshow(rgb, extent=ext, origin="upper")
        if mask.any():
            ax.contour(np.arange(mask.shape[1]), np.arange(top, bottom), mask, levels=[0.5],
                       colors="yellow", linewidths=1.0)  # fmt: skip
        ax.plot([vx], [vy], marker="^", color="cyan", ms=9, mec="k")
        ahead_km = (nadir[1] - vy) * spec.gsd / 1e3
        zen = float(np.degrees(parallax.view_zenith(config.altitude_m, max(ahead_km, 0) * 1e3)))
        ax.set_title(f"look at t = {t:.1f} s\nvent {ahead_km:.0f} km ahead, θ = {zen:.0f}°",
                     fontsize=9)  # fmt: skip
        ax.set_xticks([])
        ax.set_ylabel("strip row (8 m px)") if ax is axes[0] else ax.set_yticks([])
    ax = axes[3]
    flown = {m: r.flown for m, (_, r) in runs.items()}
    ts = [t for t in flown["estimated"].t] or [0.0]
    t_mid = float(np.median(ts))
    truth = world.truth_at(t_mid)
    ground = truth.maps.label[top:bottom]
    ax.imshow(ground, extent=ext, origin="upper", cmap="Greys", vmin=0, vmax=2.5)
    # what the NFOV's lines of sight meet at that time: the plume top seen from its nadir
    _, seen = world.look_at(t_mid, top, bottom, nadir_xy=geo.nadir_hr(t_mid),
                            altitude_m=config.altitude_m)  # fmt: skip
    if seen.any():
        ax.contour(np.arange(seen.shape[1]), np.arange(top, bottom), seen, levels=[0.5],
                   colors="orange", linewidths=1.0)  # fmt: skip
    ax.plot([vx], [vy], marker="^", color="cyan", ms=9, mec="k", label="vent")
    styles = {"off": ("tab:red", "x", "uncorrected (--no-parallax)"),
              "estimated": ("tab:green", ".", "corrected, measured height"),
              "true": ("tab:blue", "+", "corrected, true height")}  # fmt: skip
    score = {}
    for mode, fl in flown.items():
        x = np.asarray(fl.x) * f + (f - 1) / 2.0
        y = np.asarray(fl.y) * f + (f - 1) / 2.0
        c, m, label = styles[mode]
        util = runs[mode][1].totals()["utility"]
        score[mode] = util
        ax.plot(x, y, m, color=c, ms=4, alpha=0.8, label=f"{label} (utility {util:.0f})")
    ax.set_ylim(bottom, top)
    ax.set_xlim(0, world.shape[1])
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"NFOV pointings, t ≈ {t_mid:.0f} s\ngrey: plume on the ground;\norange: its top seen from the NFOV",
                 fontsize=9)  # fmt: skip
    ax.legend(loc="upper center", bbox_to_anchor=(-1.3, -0.02), ncol=2, fontsize=8)
    est_txt = (
        "(not measured)" if h.top_height_m is None
        else f"{h.top_height_m / 1e3:.2f} ± {(h.top_height_sigma_m or 0) / 1e3:.2f} km"
    )  # fmt: skip
    fig.suptitle(
        f"One plume, true top {args.height_km:.2f} km, measured {est_txt} from the look-ahead\n"
        f"and two re-looks (yellow: the plume each look shows; cyan: its vent)", fontsize=10,
    )  # fmt: skip
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(args.out)
    print(json.dumps({"true_m": args.height_km * 1e3, "estimate": h.as_dict(), "utility": score,
                      "looks_s": t_looks}, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
