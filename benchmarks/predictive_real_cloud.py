"""Predictive targeting on a real moving cloud: pointings that land on the future cloud.

The real 38-Cloud Landsat 8 patch (``../shared/data/38cloud-sample``, 384 x 384 px at
30 m; its human cloud mask) with the cloud layer drifting rigidly over its inpainted
ground (``benchmarks/motion_real.py``'s rendering): two looks 10 s apart, the plan drawn
on the second look for the cloud as it will be ``--lead-s`` (default 90) s later, every
look-ahead planner, the human mask as the classifier. Scored: the share of pointings whose
pixel is cloud at that time ("on the future cloud"): on the human mask itself, and on
that mask denoised as the pipeline denoises what it plans on (Algorithm 2: the fragments
and holes a planner is meant to ignore), for

* ``static``: the plan on the second look's mask, unmoved;
* ``predictive``: :func:`dyntarget.pipeline.two_look_motion` on the two looks (defaults),
  then :func:`dyntarget.pipeline.plan_scene` with that ``Prediction``;
* ``true motion``: the same with the motion that made the frames (the planner's own ceiling:
  an outline pointing on the cloud's very edge can miss by rounding alone).

Speeds 5, 10 and 20 m/s (0.17, 0.33, 0.67 px/s), each in 8 directions (every 45 deg from
east); the mean and the worst over the directions are reported.

    DYNTARGET_SHARED_DATA=../shared/data PYTHONPATH=src \\
        python benchmarks/predictive_real_cloud.py [--out docs/benchmarks/predictive_real_cloud.json]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from motion_real import CLOUD_INTERVAL, _read_cloud, cloud_frames

from dyntarget.evaluate.bench import machine
from dyntarget.evaluate.tables import markdown_table
from dyntarget.pipeline import PipelineConfig, clean, plan_scene, two_look_motion
from dyntarget.plan import BASELINES, PAPER_PLANNERS
from dyntarget.predict import Motion, Prediction

GSD_M = 30.0
SPEEDS_MPS = (5.0, 10.0, 20.0)
DIRECTIONS_DEG = tuple(range(0, 360, 45))


def on_cloud(points: np.ndarray, truth: np.ndarray) -> float:
    """Share of pointings ``(x, y)`` on a cloud pixel of ``truth`` (outside the image: a miss)."""
    if len(points) == 0:
        return float("nan")
    h, w = truth.shape
    x, y = np.rint(points[:, 0]).astype(int), np.rint(points[:, 1]).astype(int)
    inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
    hit = np.zeros(len(points), bool)
    hit[inside] = truth[y[inside], x[inside]]
    return float(hit.mean())


def run(lead_s: float) -> list[dict]:
    image, gt, ground = _read_cloud()
    planners = [p for p in PAPER_PLANNERS if p not in BASELINES]
    rows = []
    for speed in SPEEDS_MPS:
        for deg in DIRECTIONS_DEG:
            v = (
                speed / GSD_M * math.cos(math.radians(deg)),
                -speed / GSD_M * math.sin(math.radians(deg)),
            )  # towards deg counter-clockwise from east; rows grow southwards
            a, pm = cloud_frames(image, gt, ground, "drift", v, 0.0, 0.0)
            b, cm = cloud_frames(image, gt, ground, "drift", v, 0.0, CLOUD_INTERVAL)
            _, truth = cloud_frames(image, gt, ground, "drift", v, 0.0, CLOUD_INTERVAL + lead_s)
            truth_clean, _ = clean(truth, PipelineConfig())
            motion = two_look_motion(a, b, CLOUD_INTERVAL, previous_mask=pm, current_mask=cm)
            true_motion = Motion(v, regime="detached", source="two-looks", method="truth")
            for planner in planners:
                row = {"speed m/s": speed, "direction deg": deg, "planner": planner}
                for label, pred in (
                    ("static", None),
                    ("predictive", Prediction(motion, lead_s)),
                    ("true motion", Prediction(true_motion, lead_s)),
                ):
                    res = plan_scene(b, None, planner, mask=cm, prediction=pred)
                    row[label] = on_cloud(res.trajectory.points, truth)
                    row[f"{label} (denoised truth)"] = on_cloud(res.trajectory.points, truth_clean)
                    row[f"{label} pointings"] = len(res.trajectory)
                row["motion"] = motion.summary()
                rows.append(row)
            print(
                f"{speed:g} m/s {deg:3d} deg: "
                + ", ".join(
                    f"{r['planner']} {r['static']:.2f}/{r['predictive']:.2f}"
                    for r in rows[-len(planners) :]
                ),
                flush=True,
            )
    return rows


def _stats(row: dict, sel: list[dict]) -> None:
    for label in ("static", "predictive", "true motion"):
        for suffix in ("", " (denoised truth)"):
            vals = np.array([r[label + suffix] for r in sel])
            row[f"{label}{suffix} mean"] = round(float(np.nanmean(vals)), 3)
            row[f"{label}{suffix} worst"] = round(float(np.nanmin(vals)), 3)


def summarise(rows: list[dict]) -> list[dict]:
    out = []
    keys = sorted(
        {(r["speed m/s"], r["planner"]) for r in rows},
        key=lambda k: (k[0], PAPER_PLANNERS.index(k[1])),
    )
    for speed, planner in keys:
        sel = [r for r in rows if r["speed m/s"] == speed and r["planner"] == planner]
        row = {"speed m/s": speed, "planner": planner}
        _stats(row, sel)
        out.append(row)
    for speed in SPEEDS_MPS:
        sel = [r for r in rows if r["speed m/s"] == speed]
        row = {"speed m/s": speed, "planner": "all look-ahead planners"}
        _stats(row, sel)
        out.append(row)
    return out


COLUMNS = [
    "speed m/s",
    "planner",
    "static mean",
    "predictive mean",
    "predictive worst",
    "true motion mean",
    "static (denoised truth) mean",
    "predictive (denoised truth) mean",
    "predictive (denoised truth) worst",
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lead-s", type=float, default=90.0)
    ap.add_argument("--out", default="docs/benchmarks/predictive_real_cloud.json")
    args = ap.parse_args()
    rows = run(args.lead_s)
    summary = summarise(rows)
    doc = {
        "machine": machine(),
        "command": f"PYTHONPATH=src python benchmarks/predictive_real_cloud.py --lead-s {args.lead_s:g}",
        "lead_s": args.lead_s,
        "interval_s": CLOUD_INTERVAL,
        "summary": summary,
        "rows": rows,
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    md = markdown_table(summary, COLUMNS)
    out.with_suffix(".md").write_text(md + "\n")
    print(md)


if __name__ == "__main__":
    main()
