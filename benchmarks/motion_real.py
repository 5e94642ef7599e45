"""Motion on real evolving fields: persistence, dyntarget and pysteps LK on the same pixels.

Two groups of cases (issue 28), all scored by the IoU of the predicted mask with the truth:

* **radar**: a day of the FMI radar composite (``../shared/data/fmi-radar-20170509``,
  1024 x 1024 px at 250 m, one frame every 5 min). Two looks 5 min apart
  (frames ``k - 1`` and ``k``), the plume = echoes above 30 dBZ, the truth the
  real frame ``k + 1``, ``k + 3``, ``k + 6`` (5 / 15 / 30 min after the
  current look). ``--radar-cases`` current frames, evenly spaced over the day
  (default 11: ``k = 1, 4, ..., 31``).
* **clouds**: the real 38-Cloud Landsat patch (``../shared/data/38cloud-sample``,
  384 x 384 px): the cloud pixels are inpainted (``cv2.inpaint``, Telea) for a
  fixed ground, and the cloud layer (its own pixels, the human mask) is moved
  over it by a known field: a rigid drift, a drift of 0.25 px/s plus a rotation
  about the image centre, or a drift plus a shear (the x speed grows across the
  rows by ``k`` times the drift between the top and the bottom edge). Looks at
  0 and 10 s, the truth the moved mask 90 s after the second look. Cloud entering
  from beyond the border is clear sky (the mask is cut by the border, as real ones are).
  Also a **rigid-drift sweep**: 0.1, 0.25, 0.5 and 1 px/s, each in 8 directions, with
  the ``true motion`` ceiling (the current mask carried by the exact velocity: whole-pixel
  masks put even that a pixel off on some directions) and the velocity's error.

Methods: ``persistence`` (the current mask, unmoved), ``dyntarget``
(:func:`dyntarget.predict.estimate_motion` + :func:`dyntarget.predict.predict_mask`,
defaults; for the radar the dBZ is the brightness of all four bands; the radar is scored
twice: ``dyntarget`` carries the > 30 dBZ mask, ``dyntarget dBZ`` carries the dBZ field with
:func:`dyntarget.predict.predict_field` and thresholds it at 30 dBZ, as pysteps does) and
``pysteps LK`` (Lucas-Kanade on the two looks + semi-Lagrangian extrapolation,
pysteps defaults; the radar's dBZ field extrapolated and thresholded at 30 dBZ,
the clouds' mask extrapolated as a 0/1 field and thresholded at 0.5). Times are
wall seconds per call (the estimate plus every lead's prediction), median over the cases.

    DYNTARGET_SHARED_DATA=/work/shared/data PYTHONPATH=src \\
        python benchmarks/motion_real.py [--radar-cases 11] \\
        [--out docs/benchmarks/motion_real.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
import warnings
from pathlib import Path

import cv2
import numpy as np

from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.tables import markdown_table
from dyntarget.predict import estimate_motion, predict_field, predict_mask

DATA = Path(
    os.environ.get("DYNTARGET_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
RADAR = "fmi-radar-20170509/fmi_20170509.npz"
CLOUD = "38cloud-sample"
RADAR_LEADS = (1, 3, 6)
"""Frames (5 min each) after the current look: 5, 15, 30 min."""
THRESHOLD_CODE = 124
"""dBZ = 0.5 code - 32: code > 124 is above 30 dBZ."""
CLOUD_INTERVAL = 10.0
CLOUD_LEAD = 90.0
CLOUD_CASES = {
    "drift 0.1 px/s": ("drift", (0.08, 0.06), 0.0),
    "drift 0.5 px/s": ("drift", (0.4, -0.3), 0.0),
    "drift 1 px/s": ("drift", (-0.6, 0.8), 0.0),
    "drift + rotation 0.05 deg/s": ("rotation", (0.25, 0.0), 0.05),
    "drift + rotation 0.1 deg/s": ("rotation", (0.25, 0.0), 0.1),
    "drift + rotation 0.2 deg/s": ("rotation", (0.25, 0.0), 0.2),
    "drift + shear 0.5x": ("shear", (0.25, 0.0), 0.5),
    "drift + shear 1x": ("shear", (0.25, 0.0), 1.0),
}


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = int((a | b).sum())
    return 1.0 if union == 0 else int((a & b).sum()) / union


def _steps():
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from pysteps import extrapolation, motion
        return motion.get_method("LK"), extrapolation.get_method("semilagrangian")
    except ImportError:
        return None


def _lk(steps, stack):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return steps[0](stack, verbose=False)


def _extrapolate(steps, field, v, timesteps):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return steps[1](field, v, list(timesteps))


# ---------------------------------------------------------------- radar
def radar_cases(n: int) -> list[int]:
    last = 40 - 1 - max(RADAR_LEADS)
    return sorted({round(k) for k in np.linspace(1, last, n)})


def _dbz(code: np.ndarray) -> np.ndarray:
    d = 0.5 * code.astype(np.float32) - 32.0
    d[code == 255] = -32.0  # no data: no echo
    return d


def _radar_image(dbz: np.ndarray) -> np.ndarray:
    band = np.clip((dbz + 32.0) / 95.0, 0.0, 1.0).astype(np.float32)
    return np.repeat(band[None], 4, axis=0)


def run_radar(n_cases: int, steps, dyn_options: dict) -> list[dict]:
    data = np.load(DATA / RADAR)
    code = data["dbz_code"]
    dt = float(data["times_s"][1] - data["times_s"][0])
    rows = []
    for k in radar_cases(n_cases):
        pm, cm = code[k - 1] > THRESHOLD_CODE, code[k] > THRESHOLD_CODE
        pm &= code[k - 1] != 255
        cm &= code[k] != 255
        truths = [(code[k + s] > THRESHOLD_CODE) & (code[k + s] != 255) for s in RADAR_LEADS]
        row: dict = {"case": f"radar frame {k}", "group": "radar"}
        for s, t in zip(RADAR_LEADS, truths, strict=True):
            row[f"persistence {5 * s} min"] = iou(cm, t)
        a, b = _radar_image(_dbz(code[k - 1])), _radar_image(_dbz(code[k]))
        t0 = time.perf_counter()
        m = estimate_motion(a, b, dt, previous_mask=pm, current_mask=cm, **dyn_options)
        preds = [predict_mask(cm, m, s * dt) for s in RADAR_LEADS]
        row["dyntarget s"] = time.perf_counter() - t0
        # the same motion carrying what pysteps carries: the dBZ (floored at 0 dBZ, as
        # pysteps' input), thresholded at 30 dBZ after the advection
        echo = np.maximum(_dbz(code[k]), 0.0)
        fields = [predict_field(echo, m, s * dt) > 30.0 for s in RADAR_LEADS]
        for s, t, p, q in zip(RADAR_LEADS, truths, preds, fields, strict=True):
            row[f"dyntarget {5 * s} min"] = iou(p, t)
            row[f"dyntarget dBZ {5 * s} min"] = iou(q, t)
        row["dyntarget ground"] = m.ground
        row["dyntarget confidence"] = m.confidence
        row["dyntarget notes"] = m.summary()
        if steps is not None:
            d0, d1 = _dbz(code[k - 1]), _dbz(code[k])
            floor = 0.0  # below 0 dBZ: no echo, as pysteps' examples clip
            stack = np.maximum(np.stack([d0, d1]), floor).astype(np.float64)
            t0 = time.perf_counter()
            v = _lk(steps, stack)
            ext = _extrapolate(steps, stack[-1], v, RADAR_LEADS)
            row["pysteps LK s"] = time.perf_counter() - t0
            for i, (s, t) in enumerate(zip(RADAR_LEADS, truths, strict=True)):
                p = np.nan_to_num(ext[i], nan=floor) > 30.0
                row[f"pysteps LK {5 * s} min"] = iou(p, t)
        rows.append(row)
        print({k2: (round(v2, 3) if isinstance(v2, float) else v2) for k2, v2 in row.items()})
    return rows


# ---------------------------------------------------------------- clouds
def _read_cloud():
    import rasterio

    bands = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in ("red", "green", "blue", "nir"):
            with rasterio.open(DATA / CLOUD / f"{name}.tif") as f:
                bands.append(f.read(1).astype(np.float32) / 65535.0)
        with rasterio.open(DATA / CLOUD / "gt.tif") as f:
            gt = f.read(1) > 0
    image = np.stack(bands)
    hole = cv2.dilate(gt.astype(np.uint8), np.ones((5, 5), np.uint8))
    ground = np.stack([cv2.inpaint(b, hole, 5, cv2.INPAINT_TELEA) for b in image])
    return image, gt, ground


def _inverse_map(kind: str, v: tuple[float, float], p: float, t: float, shape):
    """Where the pixel at (x, y) at time t was at time 0 (float32 maps for cv2.remap)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    if kind == "drift":
        return (xx - v[0] * t).astype(np.float32), (yy - v[1] * t).astype(np.float32)
    if kind == "rotation":  # p deg/s about the centre, then the drift
        a = -math.radians(p * t)
        x, y = xx - cx - v[0] * t, yy - cy - v[1] * t
        return (
            (cx + math.cos(a) * x - math.sin(a) * y).astype(np.float32),
            (cy + math.sin(a) * x + math.cos(a) * y).astype(np.float32),
        )
    # shear: vx(y0) = v0 (1 + p (y0 - cy) / (h / 2)), rows drift by v[1]
    y0 = yy - v[1] * t
    vx = v[0] * (1 + p * (y0 - cy) / (h / 2))
    return (xx - vx * t).astype(np.float32), y0.astype(np.float32)


def cloud_frames(image, gt, ground, kind, v, p, t):
    mx, my = _inverse_map(kind, v, p, t, gt.shape)
    layer = np.stack([cv2.remap(b, mx, my, cv2.INTER_LINEAR) for b in image])
    mask = (
        cv2.remap(
            gt.astype(np.uint8),
            mx,
            my,
            cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )
        > 0
    )
    return np.where(mask[None], layer, ground).astype(np.float32), mask


def run_clouds(steps, dyn_options: dict) -> list[dict]:
    image, gt, ground = _read_cloud()
    rows = []
    for name, (kind, v, p) in CLOUD_CASES.items():
        a, pm = cloud_frames(image, gt, ground, kind, v, p, 0.0)
        b, cm = cloud_frames(image, gt, ground, kind, v, p, CLOUD_INTERVAL)
        _, truth = cloud_frames(image, gt, ground, kind, v, p, CLOUD_INTERVAL + CLOUD_LEAD)
        row: dict = {"case": name, "group": "clouds", "persistence 90 s": iou(cm, truth)}
        t0 = time.perf_counter()
        m = estimate_motion(a, b, CLOUD_INTERVAL, previous_mask=pm, current_mask=cm, **dyn_options)
        pred = predict_mask(cm, m, CLOUD_LEAD)
        row["dyntarget s"] = time.perf_counter() - t0
        row["dyntarget 90 s"] = iou(pred, truth)
        row["dyntarget notes"] = m.summary()
        if steps is not None:
            t0 = time.perf_counter()
            row["pysteps LK 90 s"] = _lk_mask(steps, a, b, cm, truth)
            row["pysteps LK s"] = time.perf_counter() - t0
        rows.append(row)
        print({k2: (round(v2, 3) if isinstance(v2, float) else v2) for k2, v2 in row.items()})
    return rows


DRIFT_SPEEDS = (0.1, 0.25, 0.5, 1.0)
"""px/s of the rigid-drift sweep, each in 8 directions (every 45 deg from east)."""


def run_drift_directions(steps, dyn_options: dict) -> list[dict]:
    """Rigid drift of the real cloud layer at each of :data:`DRIFT_SPEEDS` in 8 directions.

    One direction alone is a lottery at these speeds: the masks are whole pixels, so a
    velocity right within a few per cent can still put the 90 s mask a pixel off (e.g.
    0.1 px/s towards (0.8, 0.6): the estimate must read vy within -17 % / +2 %). The
    ``true motion`` column is that rounding's ceiling: the current mask carried by the
    velocity that made the frames."""
    from dyntarget.predict import Motion

    image, gt, ground = _read_cloud()
    rows = []
    for speed in DRIFT_SPEEDS:
        for deg in range(0, 360, 45):
            v = (speed * math.cos(math.radians(deg)), -speed * math.sin(math.radians(deg)))
            a, pm = cloud_frames(image, gt, ground, "drift", v, 0.0, 0.0)
            b, cm = cloud_frames(image, gt, ground, "drift", v, 0.0, CLOUD_INTERVAL)
            _, truth = cloud_frames(image, gt, ground, "drift", v, 0.0, CLOUD_INTERVAL + CLOUD_LEAD)
            m = estimate_motion(
                a, b, CLOUD_INTERVAL, previous_mask=pm, current_mask=cm, **dyn_options
            )
            row = {
                "speed px/s": speed,
                "direction deg": deg,
                "persistence 90 s": iou(cm, truth),
                "dyntarget 90 s": iou(predict_mask(cm, m, CLOUD_LEAD), truth),
                "true motion 90 s": iou(predict_mask(cm, Motion(v), CLOUD_LEAD), truth),
                "velocity error %": 100
                * math.hypot(m.velocity[0] - v[0], m.velocity[1] - v[1])
                / speed,
            }
            if steps is not None:
                row["pysteps LK 90 s"] = _lk_mask(steps, a, b, cm, truth)
            rows.append(row)
        print(
            {
                "speed px/s": speed,
                **{k: round(_mean([r for r in rows if r["speed px/s"] == speed], k) or 0, 3)
                   for k in ("dyntarget 90 s", "true motion 90 s", "velocity error %")},
            },
            flush=True,
        )  # fmt: skip
    return rows


def _lk_mask(steps, a, b, cm, truth) -> float:
    ba, bb = a.mean(axis=0), b.mean(axis=0)
    lo, hi = np.percentile(np.concatenate([ba.ravel(), bb.ravel()]), [1, 99])
    stack = np.clip((np.stack([ba, bb]) - lo) / (hi - lo), 0, 1).astype(np.float64)
    vel = _lk(steps, stack)
    ext = _extrapolate(steps, cm.astype(np.float64), vel, [CLOUD_LEAD / CLOUD_INTERVAL])
    return iou(np.nan_to_num(ext[0], nan=0.0) >= 0.5, truth)


def summarise_drift(rows: list[dict]) -> list[dict]:
    out = []
    for speed in DRIFT_SPEEDS:
        sel = [r for r in rows if r["speed px/s"] == speed]
        if not sel:
            continue
        row: dict = {"speed px/s": speed}
        for key in ("persistence 90 s", "dyntarget 90 s", "true motion 90 s", "pysteps LK 90 s"):
            vals = [r[key] for r in sel if key in r]
            row[f"{key.removesuffix(' 90 s')} mean"] = (
                round(float(np.mean(vals)), 3) if vals else None
            )
        row["dyntarget worst"] = round(min(r["dyntarget 90 s"] for r in sel), 3)
        row["velocity error % (max)"] = round(max(r["velocity error %"] for r in sel), 2)
        out.append(row)
    return out


# ---------------------------------------------------------------- timing
def run_timing(repeats: int = 5) -> list[dict]:
    """Whole call (estimate_motion + predict_mask 90 s ahead) at 1024 px, 10 s looks:
    the test worlds' rigid cloud (``tests/motion_worlds.py``, radius 150 px) and a
    1024-px radar window (5-min looks, the whole field moving); median of ``repeats``."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from motion_worlds import RigidCloud

    world = RigidCloud(size=1024, velocity=(0.3, -0.16), centre=(400, 500), radius=150)
    a, b = world.frame(0.0), world.frame(10.0)
    pm, cm = world.mask(0.0), world.mask(10.0)
    data = np.load(DATA / RADAR)
    code = data["dbz_code"]
    ra, rb = _radar_image(_dbz(code[10])), _radar_image(_dbz(code[11]))
    rpm, rcm = code[10] > THRESHOLD_CODE, code[11] > THRESHOLD_CODE
    cases = [
        ("rigid cloud 1024 px, 10 s looks", (a, b, pm, cm, 10.0)),
        ("radar 1024 px, 5 min looks", (ra, rb, rpm, rcm, 300.0)),
    ]
    variants = {"default (dense Farneback)": {}, "field=uniform": {"field": "uniform"}}
    if _steps() is not None:
        variants["flow=lk (pysteps, nowcast extra)"] = {"flow": "lk"}
    rows = []
    for case, (p, c, m0, m1, dt) in cases:
        for name, opts in variants.items():
            times, cpu = [], []
            for _ in range(repeats if "lk" not in name else 1):
                t0, c0 = time.perf_counter(), time.process_time()
                mo = estimate_motion(p, c, dt, previous_mask=m0, current_mask=m1, **opts)
                predict_mask(m1, mo, 9 * dt)
                times.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            rows.append(
                {
                    "case": case,
                    "variant": name,
                    "s per call": round(float(np.median(times)), 3),
                    # CPU seconds of this process (all its threads), which a loaded machine
                    # inflates far less than the wall time; on free cores the wall time is
                    # about this or less (OpenCV's two threads)
                    "cpu s per call": round(float(np.median(cpu)), 3),
                    "grid": mo.method,
                }
            )
            print(rows[-1], flush=True)
    return rows


# ---------------------------------------------------------------- tables
def _mean(rows, key):
    vals = [r[key] for r in rows if key in r]
    return float(np.mean(vals)) if vals else None


def _median(rows, key):
    vals = [r[key] for r in rows if key in r]
    return float(np.median(vals)) if vals else None


def _radar_per_case(radar: list[dict]) -> list[dict]:
    """Per case: the ground decision, the confidence, and both dyntarget advections
    against pysteps LK at each lead (ratios of the IoUs)."""
    out = []
    for r in radar:
        row = {
            "case": r["case"],
            "ground": r.get("dyntarget ground"),
            "confidence": round(r.get("dyntarget confidence", float("nan")), 2),
        }
        for s in RADAR_LEADS:
            lk = r.get(f"pysteps LK {5 * s} min")
            for key, name in (("dyntarget", "mask"), ("dyntarget dBZ", "dBZ")):
                v = r[f"{key} {5 * s} min"]
                row[f"{name} {5 * s} min"] = round(v, 3)
                row[f"{name} / LK {5 * s} min"] = round(v / lk, 3) if lk else None
            row[f"LK {5 * s} min"] = None if lk is None else round(lk, 3)
        out.append(row)
    return out


def summarise(radar: list[dict], clouds: list[dict]) -> dict:
    out: dict = {"radar": [], "clouds": []}
    for method in ("persistence", "dyntarget", "dyntarget dBZ", "pysteps LK"):
        row = {"method": method}
        for s in RADAR_LEADS:
            m = _mean(radar, f"{method} {5 * s} min")
            row[f"{5 * s} min"] = None if m is None else round(m, 3)
        t = _median(radar, f"{method.removesuffix(' dBZ')} s")
        row["s per call"] = None if t is None else round(t, 2)
        out["radar"].append(row)
    out["radar per case"] = _radar_per_case(radar)
    for r in clouds:
        row = {"case": r["case"]}
        for method in ("persistence", "dyntarget", "pysteps LK"):
            v = r.get(f"{method} 90 s")
            row[method] = None if v is None else round(v, 3)
        ref = r.get("pysteps LK 90 s")
        row["dyntarget / LK"] = None if not ref else round(r["dyntarget 90 s"] / ref, 3)
        out["clouds"].append(row)
    out["clouds s per call"] = {
        m: (None if _median(clouds, f"{m} s") is None else round(_median(clouds, f"{m} s"), 3))
        for m in ("dyntarget", "pysteps LK")
    }
    return out


RADAR_CASE_COLUMNS = [
    "case",
    "ground",
    "confidence",
    *(f"{n} {5 * s} min" for s in RADAR_LEADS for n in ("mask", "dBZ", "LK")),
    *(f"dBZ / LK {5 * s} min" for s in RADAR_LEADS),
]

DRIFT_COLUMNS = [
    "speed px/s",
    "persistence mean",
    "dyntarget mean",
    "dyntarget worst",
    "true motion mean",
    "pysteps LK mean",
    "velocity error % (max)",
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radar-cases", type=int, default=11)
    ap.add_argument("--no-radar", action="store_true")
    ap.add_argument("--no-clouds", action="store_true")
    ap.add_argument("--no-pysteps", action="store_true")
    ap.add_argument("--no-timing", action="store_true")
    ap.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="passed on to estimate_motion (e.g. ground=fixed)",
    )
    ap.add_argument("--out", default="docs/benchmarks/motion_real.json")
    args = ap.parse_args()
    dyn_options = dict(o.split("=", 1) for o in args.option)
    steps = None if args.no_pysteps else _steps()
    cv2.setNumThreads(2)
    radar = [] if args.no_radar else run_radar(args.radar_cases, steps, dyn_options)
    clouds = [] if args.no_clouds else run_clouds(steps, dyn_options)
    drift = [] if args.no_clouds else run_drift_directions(steps, dyn_options)
    timing = [] if args.no_timing else run_timing()
    summary = summarise(radar, clouds)
    summary["drift directions"] = summarise_drift(drift)
    doc = {
        "machine": machine(),
        "command": "PYTHONPATH=src python benchmarks/motion_real.py "
        + f"--radar-cases {args.radar_cases}"
        + "".join(f" --option {o}" for o in args.option),
        "estimate_motion options": dyn_options,
        "radar frames (current look)": radar_cases(args.radar_cases),
        "summary": summary,
        "radar": radar,
        "clouds": clouds,
        "drift directions": drift,
        "timing": timing,
        "pysteps": steps is not None,
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    md = (
        "## Radar day (mean IoU of the > 30 dBZ mask)\n\n"
        + markdown_table(summary["radar"], ["method", "5 min", "15 min", "30 min", "s per call"])
        + "\n\n(dyntarget: the > 30 dBZ mask carried by `predict_mask`; dyntarget dBZ: the same"
        + " motion carrying the dBZ by `predict_field`, thresholded at 30 dBZ, as pysteps'"
        + " extrapolation is)\n\n### Per case\n\n"
        + markdown_table(summary["radar per case"], RADAR_CASE_COLUMNS)
        + "\n\n## Real cloud layer moved over its inpainted ground (IoU at 90 s)\n\n"
        + markdown_table(
            summary["clouds"], ["case", "persistence", "dyntarget", "pysteps LK", "dyntarget / LK"]
        )
        + f"\n\nseconds per call (median): {summary['clouds s per call']}\n"
        + "\n## Rigid drift of the real cloud layer, 8 directions per speed (IoU at 90 s)\n\n"
        + markdown_table(summary["drift directions"], DRIFT_COLUMNS)
        + "\n"
        + "\n## Whole call (estimate + predict 90 s / 9 intervals ahead), median of 5\n\n"
        + markdown_table(timing, ["case", "variant", "s per call", "cpu s per call", "grid"])
        + "\n"
    )
    out.with_suffix(".md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
