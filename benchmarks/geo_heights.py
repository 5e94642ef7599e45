"""Plume-top heights from a look-ahead look and GEO images (LEO+GEO parallax, issue 40).

For each of ``--n`` plumes (one vent per synthetic strip, :func:`dyntarget.synth.strip.strip_spec`
at 8 m, the vent moved to the strip's middle column; made 3D by
:func:`dyntarget.synth.dynamic.with_heights`: top 2-15 km, rise 10-100 m/s; clouds removed;
wind drawn 0-20 m/s; the eruption's onset drawn ``--age-s`` (default 1800-3600 s) before the
look, so that the plume is on the GEO images taken before it), at the pass time ``t = 0``:

* **The look-ahead look** (spacecraft 500 km up, flying north, the look-ahead distance drawn
  so that the view zenith is 30-50 deg, as ``benchmarks/parallax_targets.py --part
  heights``): the whole plume rendered obliquely by ``World.render_look`` at the
  look-ahead's 32 m pixels (one look of the whole plume: a pass sees it over a few frames,
  about a second apart; not the pass loop). Its field: the plume's opacity
  ``1 - exp(-tau)`` in that look (what a perfect unmixing of the look would give); its
  position: that field's centroid.
* **The GEO images** (:class:`dyntarget.synth.geoimager.GeoStream` with a
  :class:`~dyntarget.synth.geoimager.GeoView`, ``fly --geo``'s noise 0.005, over the vent
  +- ``GEO_HALF_M`` and the stream's 8 km margin): cells of ``--cells`` metres. Timing as
  ``fly --geo``'s defaults (an image every 600 s, usable 300 s after it is taken, the
  cadence's phase drawn per plume): the last two images usable at ``t = 0``, taken 300-900 s
  and 900-1500 s before the look; and, for comparison, an image taken at the look's own time
  (``simultaneous``). On each: the plume's unmixed cover fraction (ash plus steam,
  :func:`dyntarget.geo.unmix` with the world's end-members) over its connected cells
  brighter than the background by 0.01, dilated; the look's opacity field is matched onto it
  (:func:`dyntarget.geo.heights.match_offset`, sub-cell, from the difference of the two
  centroids): the GEO's sighting is the look's centroid moved by that offset.
* **Views:** ``north`` (:data:`~dyntarget.synth.geoimager.DEFAULT_VIEW`: 35 deg N under the
  GEO's longitude; the GEO due south, zenith 40.6 deg: it displaces a top north, as the
  north-flying look-ahead does) and ``south`` (35 deg S: the GEO due north, displacing the
  top south, against the look-ahead: the geometry of a southbound (descending) pass at
  35 deg N).

**Estimators** (:func:`dyntarget.geo.heights.fit_geo_height`): ``pair`` the look and the
last two GEO images, the drift measured from the GEO pair (no prior); ``pair+prior`` the same
with a zero-drift prior of ``PRIOR_SD`` m/s (an attached plume's envelope stays near its
vent); ``one+prior`` the look and the last GEO image with that prior; ``simultaneous`` the
look and the GEO image taken with it. Positions' sigma: the look ``SIGMA_LEO_M``; a GEO
sighting the match's noise and ``CELL_FLOOR`` of a cell, in quadrature (chosen before the
run, on a pilot of seeds 1000+). Errors against the column's true height at the look's time.
Speed only: the two worlds a GEO stream builds share their noise tiles (``_SharedTiles``:
the images are unchanged).

    python benchmarks/geo_heights.py --n 44 --json docs/benchmarks/geo_heights.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import ClassVar

import numpy as np
from scipy import ndimage

from dyntarget import defaults, parallax
from dyntarget.evaluate.bench import machine
from dyntarget.geo import unmix
from dyntarget.geo.heights import (
    GEO_ALTITUDE_M,
    Sighting,
    fit_geo_height,
    fraction_centroid,
    match_offset,
)
from dyntarget.synth import geoimager
from dyntarget.synth.dynamic import World, with_heights
from dyntarget.synth.geoimager import GeoStream, GeoView
from dyntarget.synth.strip import resampled_spec, strip_spec

sys.path.insert(0, str(Path(__file__).resolve().parent))
from parallax_targets import look_ahead_for_zenith

REPO = Path(__file__).resolve().parents[1]
GSD = 8.0
LEO_GSD = 32.0
"""The look-ahead's pixel, metres."""
CADENCE_S, LATENCY_S, GEO_NOISE = 600.0, 300.0, 0.005
"""``fly --geo``'s defaults."""
SIGMA_LEO_M = 50.0
CELL_FLOOR = 0.1
"""Share of a GEO cell added (in quadrature) to a GEO centroid's sigma."""
PRIOR_SD = 3.0
DETECT = 0.01
FIELD_DILATE = 4
"""Cells around the detected plume where the GEO fraction is unmixed (its thin edges)."""
GEO_HALF_M = (16_000.0, 24_000.0)
"""Half width and half height of the GEO images' window about the vent, metres."""
VIEWS = {"north": GeoView(35.0, 0.0), "south": GeoView(-35.0, 0.0)}
MODES = ("pair", "pair+prior", "one+prior", "simultaneous")


class _SharedTiles(World):
    """A world whose noise tiles are shared with every earlier world of the same seed,
    grid size, tile and land cover (a GEO stream builds two such worlds: the same tiles,
    computed once; the images are unchanged). Speed only."""

    _cache: ClassVar[dict[tuple, tuple[dict, dict]]] = {}

    def _build_tiles(self) -> None:
        s = self.spec
        key = (s.seed, s.size, s.tile, s.water_fraction, s.lava_fraction, s.vegetation_fraction)
        hit = self._cache.get(key)
        if hit is None:
            super()._build_tiles()
            self._cache.clear()  # one world's tiles at a time: they are large
            self._cache[key] = (self._tiles, self._thresholds)
        else:
            self._tiles, self._thresholds = dict(hit[0]), dict(hit[1])


geoimager.MovingWorld = _SharedTiles  # type: ignore[misc]


def make_world(seed: int, width: int, length: int, wind: float, age_s: float):
    """One vent at the middle column of a strip, erupting ``age_s`` before ``t = 0``, 3D,
    no clouds; and the GEO images' window, about the vent."""
    spec, window = strip_spec(seed, width=width, length=length, plumes=1, wind_mps=wind)
    v = spec.vents[0]
    v = replace(v, x=window[0] + window[2] / 2.0, eruption_age_s=age_s)
    spec = with_heights(replace(spec, vents=(v,)), plume_height_km=(2.0, 15.0))
    # the GEO images cover the vent +- GEO_HALF_M (and their own 8 km margin): the plume
    # drifts up to ~12 km downwind and its top is displaced up to 13 km from the GEO
    hx, hy = (round(m / GSD) for m in GEO_HALF_M)
    geo_window = (round(v.x) - hx, round(v.y) - hy, 2 * hx, 2 * hy)
    return replace(spec, clouds=()), geo_window


def azimuth_to(dx_east: float, dy_north: float) -> float:
    """Azimuth (deg clockwise from north) of the direction ``(east, north)``."""
    return math.degrees(math.atan2(dx_east, dy_north)) % 360.0


def leo_world(spec) -> World:
    """The world on the look-ahead's 32 m grid."""
    k = GSD / LEO_GSD
    return World(resampled_spec(spec, LEO_GSD, lambda c: c * k, noise_sigma=0.0))


def leo_look(world: World, zenith_deg: float, t: float) -> dict:
    """The look-ahead's look at the whole plume: its opacity centroid and view geometry."""
    v = world.spec.vents[0]
    half = 800
    win = (int(v.x) - half, int(v.y) - half, 2 * half, 2 * half)
    _, tau = world.truth(t, win)
    rows, cols = np.nonzero(tau > 1e-3)
    if not rows.size:
        return {"skipped": "no plume at the look's time"}
    x0, y0 = win[0] + cols.min(), win[1] + rows.min()
    x1, y1 = win[0] + cols.max() + 1, win[1] + rows.max() + 1
    ahead = look_ahead_for_zenith(zenith_deg)
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    nadir = (cx, cy + ahead / LEO_GSD)
    h = world.column_height(0, t)
    shift = float(parallax.parallax_shift(defaults.ALTITUDE_M, ahead, h)) / LEO_GSD
    pad = 24
    look_win = (
        int(x0) - pad,
        int(y0 - shift) - pad,
        int(x1 - x0) + 2 * pad,
        int(y1 - y0) + 2 * pad,
    )
    f = world.render_look(t, look_win, nadir_px=nadir, altitude_m=defaults.ALTITUDE_M, noise=False)
    alpha = 1.0 - np.exp(-f.tau.astype(np.float64))
    edge = max(alpha[0].max(), alpha[-1].max(), alpha[:, 0].max(), alpha[:, -1].max())
    c = fraction_centroid(
        alpha, cell_m=LEO_GSD, origin_m=(look_win[0] * LEO_GSD, -look_win[1] * LEO_GSD)
    )
    dx, dy = nadir[0] * LEO_GSD - c.x_m, -nadir[1] * LEO_GSD - c.y_m
    zen = math.degrees(float(parallax.view_zenith(defaults.ALTITUDE_M, math.hypot(dx, dy))))
    return {
        "alpha": alpha,
        "origin_m": (look_win[0] * LEO_GSD, -look_win[1] * LEO_GSD),
        "sighting": Sighting(
            t, c.x_m, c.y_m, zen, azimuth_to(dx, dy), defaults.ALTITUDE_M, SIGMA_LEO_M
        ),
        "edge_opacity": round(float(edge), 4),
        "look_ahead_m": round(ahead, 1),
    }


def geo_field(s: GeoStream, image: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The plume's unmixed cover fraction (ash plus steam) on a GEO image, over its
    connected cells brighter than the background by ``DETECT`` dilated by ``FIELD_DILATE``
    cells (0 elsewhere); the detected cells dilated by one; a cell's fraction noise."""
    bg = s.background()
    anomaly = (image - bg).mean(axis=0)
    labels, n = ndimage.label(anomaly > DETECT)
    if n == 0:
        return None
    sums = ndimage.sum(anomaly, labels, index=np.arange(1, n + 1))
    core = labels == 1 + int(np.argmax(sums))
    region = ndimage.binary_dilation(core)
    wide = ndimage.binary_dilation(core, iterations=FIELD_DILATE)
    rr, cc = np.nonzero(wide)
    frac = unmix(image[:, rr, cc][:, None], bg[:, rr, cc][:, None], s.members)[:, 0]
    f = np.zeros(anomaly.shape)
    f[rr, cc] = frac[1] + frac[2]  # ash + steam
    if not f[region].sum() > 0:
        return None
    steam = np.asarray(s.members[2]) - bg[:, rr, cc].mean(axis=1)
    return f, region, GEO_NOISE / float(np.linalg.norm(steam))


def geo_sighting(
    s: GeoStream, image: np.ndarray, t: float, leo: dict
) -> tuple[Sighting, dict] | str:
    """The GEO's sighting at ``t`` of the look-ahead's plume: the look's opacity matched on
    the GEO fraction (:func:`match_offset`, from the centroids' difference), the look's
    centroid moved by the offset; the GEO view at that point; its sigma."""
    field = geo_field(s, image)
    if field is None:
        return "no plume on a GEO image"
    f, region, noise = field
    g = s.gsd_m
    origin = (s.cell0[0] * g, -s.cell0[1] * g)
    c = fraction_centroid(f, cell_m=g, origin_m=origin, region=region, noise=noise)
    lo = leo["sighting"]
    b = max(1, int(g / 4 // LEO_GSD))  # the look's opacity on pixels of at most a 4th of a cell
    alpha = leo["alpha"]
    alpha = np.pad(alpha, ((0, -alpha.shape[0] % b), (0, -alpha.shape[1] % b)))
    alpha = alpha.reshape(alpha.shape[0] // b, b, alpha.shape[1] // b, b).mean(axis=(1, 3))
    o = match_offset(
        alpha,
        f,
        fine_cell_m=LEO_GSD * b,
        fine_origin_m=leo["origin_m"],
        coarse_cell_m=g,
        coarse_origin_m=origin,
        guess_m=(c.x_m - lo.x_m, c.y_m - lo.y_m),
        noise=noise,
    )
    if not math.isfinite(o.sigma_m):
        return "the match leaves the GEO offset undetermined"
    x, y = lo.x_m + o.dx_m, lo.y_m + o.dy_m
    assert s._nadir is not None  # a 3D world seen from a view
    nx, ny = s._nadir[0] * s.render_gsd, -s._nadir[1] * s.render_gsd
    dx, dy = nx - x, ny - y
    zen = math.degrees(float(parallax.view_zenith(GEO_ALTITUDE_M, math.hypot(dx, dy))))
    sigma = math.hypot(o.sigma_m, CELL_FLOOR * g)
    info = {
        "offset_m": [round(o.dx_m, 1), round(o.dy_m, 1)],
        "offset_sigma_m": round(o.sigma_m, 1),
        "scale": round(o.scale, 3),
        "rms": round(o.rms, 4),
        "centroid_offset_m": [round(c.x_m - lo.x_m, 1), round(c.y_m - lo.y_m, 1)],
    }
    return Sighting(t, x, y, zen, azimuth_to(dx, dy), GEO_ALTITUDE_M, sigma), info


def one_plume(i: int, args, rng: np.random.Generator) -> dict:
    wind = float(rng.uniform(0.0, 20.0))
    zenith = float(rng.uniform(30.0, 50.0))
    phase = float(rng.uniform(0.0, CADENCE_S))
    age = float(rng.uniform(*args.age_s))
    spec, window = make_world(args.seed + i, args.width, args.length, wind, age)
    t = 0.0
    t1 = t - LATENCY_S - phase
    t0 = t1 - CADENCE_S
    truth_w = leo_world(spec)
    h_true = truth_w.column_height(0, t)
    row: dict = {
        "plume": i,
        "seed": args.seed + i,
        "wind_mps": round(wind, 2),
        "zenith_deg": round(zenith, 2),
        "age_s": round(age, 1),
        "true_height_m": round(h_true, 1),
        "rising_over_geo": truth_w.column_height(0, t0) < h_true - 1.0,
        "geo_times_s": [round(t0, 1), round(t1, 1)],
        "results": [],
    }
    leo = leo_look(truth_w, zenith, t)
    if "skipped" in leo:
        return {**row, **leo}
    row["edge_opacity"], row["look_ahead_m"] = leo["edge_opacity"], leo["look_ahead_m"]
    for cell in args.cells:
        base = GeoStream(spec, window, cell, GEO_NOISE)
        for vname in args.views:
            s = base.seen_from(VIEWS[vname])
            seen = {tt: geo_sighting(s, s.image(tt), tt, leo) for tt in (t0, t1, t)}
            for mode in MODES:
                need = {
                    "pair": (t0, t1),
                    "pair+prior": (t0, t1),
                    "one+prior": (t1,),
                    "simultaneous": (t,),
                }[mode]
                res: dict = {"cell_m": cell, "view": vname, "mode": mode}
                got = [seen[tt] for tt in need]
                why = [x for x in got if isinstance(x, str)]
                if why:
                    row["results"].append({**res, "ok": False, "reason": why[0]})
                    continue
                sights = [leo["sighting"]] + [x[0] for x in got if not isinstance(x, str)]
                res["geo"] = [x[1] for x in got if not isinstance(x, str)]
                kw = {"wind_prior": (0.0, 0.0), "wind_prior_sigma_mps": PRIOR_SD}
                fit = fit_geo_height(sights, **(kw if mode.endswith("prior") else {}))
                res |= {"ok": fit.ok, "reason": fit.reason, "baseline": round(fit.baseline, 3)}
                if fit.ok:
                    res |= {
                        "height_m": round(fit.height_m, 1),
                        "sigma_m": round(fit.height_sigma_m, 1),
                        "error_m": round(fit.height_m - h_true, 1),
                        "wind_mps": [round(w, 2) for w in fit.wind_mps],
                    }
                row["results"].append(res)
    return row


def summarise(rows: list[dict], cells, views) -> list[dict]:
    out = []
    for cell in cells:
        for vname in views:
            for mode in MODES:
                for subset in ("all", "steady"):
                    sel = [
                        res
                        for r in rows
                        if subset == "all" or not r.get("rising_over_geo")
                        for res in r.get("results", [])
                        if res["cell_m"] == cell and res["view"] == vname and res["mode"] == mode
                    ]
                    err = np.array([res["error_m"] for res in sel if res["ok"]])
                    sd = np.array([res["sigma_m"] for res in sel if res["ok"]])
                    s: dict = {
                        "cell_m": cell,
                        "view": vname,
                        "mode": mode,
                        "plumes": subset,
                        "tried": len(sel),
                        "count": int(err.size),
                    }
                    if err.size:
                        s |= {
                            "rmse_m": round(float(np.sqrt(np.mean(err**2))), 1),
                            "bias_m": round(float(err.mean()), 1),
                            "median_abs_m": round(float(np.median(np.abs(err))), 1),
                            "worst_abs_m": round(float(np.abs(err).max()), 1),
                            "sigma_rms_m": round(float(np.sqrt(np.mean(sd**2))), 1),
                            "within_2sigma": round(float(np.mean(np.abs(err) <= 2 * sd)), 3),
                        }
                    out.append(s)
    return out


def _head() -> str | None:
    """``git rev-parse HEAD`` run in this repository."""
    out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True)
    return out.stdout.strip() or None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=44, help="plumes (one strip each)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--width", type=int, default=512, help="strip width, px (8 m)")
    ap.add_argument("--length", type=int, default=2048, help="rows holding the vent, px (8 m)")
    ap.add_argument("--cells", default="2000,1000", help="GEO cell sizes, m, comma-separated")
    ap.add_argument(
        "--age-s", default="1800,3600", help="eruption onset before the look, s: LO,HI (drawn)"
    )
    ap.add_argument("--views", default="north,south", help=f"of {sorted(VIEWS)}")
    ap.add_argument("--json", type=Path, default=None, help="write the record here")
    args = ap.parse_args()
    args.cells = [float(c) for c in args.cells.split(",")]
    args.views = [v for v in args.views.split(",") if v]
    args.age_s = tuple(float(a) for a in args.age_s.split(","))
    if any(v not in VIEWS for v in args.views) or args.n < 1:
        ap.error(f"--views: expected names of {sorted(VIEWS)}; --n >= 1")
    head = _head()
    where = machine()  # at the start: the commit whose code is loaded
    rng = np.random.default_rng(args.seed)
    t_start = time.perf_counter()
    rows = []
    for i in range(args.n):
        rows.append(one_plume(i, args, rng))
        r = rows[-1]
        brief = {(x["cell_m"], x["view"], x["mode"]): x.get("error_m") for x in r["results"]}
        print(
            i,
            r["true_height_m"],
            r.get("skipped", ""),
            json.dumps({str(k): v for k, v in brief.items()}),
            f"{time.perf_counter() - t_start:.0f}s",
            flush=True,
        )
    summary = summarise(rows, args.cells, args.views)
    record = {
        "command": "python benchmarks/geo_heights.py " + " ".join(sys.argv[1:]),
        "commit": head,
        "settings": {
            "n": args.n,
            "seed": args.seed,
            "width": args.width,
            "length": args.length,
            "cells_m": args.cells,
            "age_s": list(args.age_s),
            "views": {
                v: {
                    "lat_deg": VIEWS[v].lat_deg,
                    "dlon_deg": VIEWS[v].dlon_deg,
                    "zenith_deg": round(VIEWS[v].zenith_deg, 3),
                    "azimuth_deg": VIEWS[v].azimuth_deg,
                }
                for v in args.views
            },
            "cadence_s": CADENCE_S,
            "latency_s": LATENCY_S,
            "geo_noise": GEO_NOISE,
            "sigma_leo_m": SIGMA_LEO_M,
            "cell_floor": CELL_FLOOR,
            "prior_sd_mps": PRIOR_SD,
            "leo_gsd_m": LEO_GSD,
        },
        "summary": summary,
        "rows": rows,
        "wall_s": round(time.perf_counter() - t_start, 1),
        "machine": where,
        "load_1min_end": round(os.getloadavg()[0], 2),
    }
    if _head() != head:
        record["commit_at_end"] = _head()  # the checkout moved on during the run
    for s in summary:
        print(json.dumps(s))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
        print(args.json)


if __name__ == "__main__":
    main()
