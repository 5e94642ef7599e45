"""Planning latency per planner on 512 x 512 WFOV masks (issue: < 50 ms per scene).

Masks: the 38 synthetic scenes of seed 0 at 512 px used directly as WFOV grids
(factor 1, the hardest case for planning), (a) their true labels and (b) the
masks a decision tree predicts (messier: many fragments), both denoised as in
the pipeline. Reports the median and the maximum over scenes of 5 repeats'
median, after one warm-up run per scene.

Also (c) a raw mask of 2000 isolated one-pixel specks at 512 px (what an undenoised,
speckled prediction gives): the nearest-next polygon ordering alone (target <= 50 ms) and
every planner on it.

    python benchmarks/plan_speed.py [--scenes 38] [--out docs/benchmarks/plan_speed.json]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from dyntarget.denoise import denoise
from dyntarget.evaluate.bench import machine
from dyntarget.masks import mask_to_polygons
from dyntarget.perceive import make_classifier
from dyntarget.plan import geometric_planners, plan
from dyntarget.plan.planners import _NearestNext, start_point
from dyntarget.synth import generate_scene


def median_ms(fn, repeats: int = 5) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1000 * float(np.median(times))


def cpu_ms(fn) -> float:
    """CPU time of one run in ms (less sensitive than wall time to other jobs on the machine)."""
    t0 = time.process_time()
    fn()
    return 1000 * (time.process_time() - t0)


def specks(n: int = 2000, size: int = 512, seed: int = 0) -> np.ndarray:
    """``n`` isolated one-pixel specks on a ``size`` grid (3 px apart at least: never 8-connected)."""
    rng = np.random.default_rng(seed)
    cells = size // 3
    sites = rng.choice(cells * cells, n, replace=False)
    m = np.zeros((size, size), bool)
    m[(sites // cells) * 3 + 1, (sites % cells) * 3 + 1] = True
    return m


def order_only(polygons, shape) -> list[int]:
    """The nearest-next order alone, each polygon left at its first exterior vertex."""
    ends = [np.asarray(p.exterior.coords[0]) for p in polygons]
    walk, position, order = _NearestNext(polygons), start_point(shape), []
    while walk.remaining:
        j = walk.take(position)
        order.append(j)
        position = ends[j]
    return order


def speck_case(repeats: int = 3) -> dict:
    mask = specks()
    polygons = mask_to_polygons(mask)
    out = {
        "polygons": len(polygons),
        "ordering_ms": median_ms(lambda: order_only(polygons, mask.shape), repeats),
        "ordering_cpu_ms": cpu_ms(lambda: order_only(polygons, mask.shape)),
        "planners_ms": {},
    }
    for name in geometric_planners():
        out["planners_ms"][name] = median_ms(lambda name=name: plan(name, mask, polygons), repeats)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=38)
    ap.add_argument("--out", default="docs/benchmarks/plan_speed.json")
    args = ap.parse_args()
    scenes = [generate_scene(0, i, size=512)[0] for i in range(args.scenes)]
    tree = make_classifier("decision-tree").fit(scenes[:5])
    masks = {
        "true": [denoise(s.label) for s in scenes],
        "decision-tree": [denoise(tree.predict(s.image)) for s in scenes],
    }
    results = {}
    for kind, cleaned in masks.items():
        polys = [len(c.polygons) for c in cleaned]
        results[kind] = {
            "polygons_median": float(np.median(polys)),
            "polygons_max": int(max(polys)),
            "planners": {},
        }
        for name in geometric_planners():
            ms = [median_ms(lambda c=c, name=name: plan(name, c.mask, c.polygons)) for c in cleaned]
            results[kind]["planners"][name] = {
                "median_ms": float(np.median(ms)),
                "max_ms": float(max(ms)),
            }
    results["specks-2000"] = speck_case()
    record = {
        "machine": machine(),
        "size_px": 512,
        "scenes": args.scenes,
        "results": results,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(record, indent=2) + "\n")
    print(
        "| planner | true mask median (ms) | true mask max (ms) | DT mask median (ms) | DT mask max (ms) |"
    )
    print("|---|---|---|---|---|")
    for name in geometric_planners():
        t, d = results["true"]["planners"][name], results["decision-tree"]["planners"][name]
        print(
            f"| {name} | {t['median_ms']:.1f} | {t['max_ms']:.1f} | {d['median_ms']:.1f} | {d['max_ms']:.1f} |"
        )
    sp = results["specks-2000"]
    print(
        f"\n2000 specks at 512 px: nearest-next ordering {sp['ordering_ms']:.1f} ms wall, "
        f"{sp['ordering_cpu_ms']:.1f} ms CPU (target <= 50 ms)"
    )
    for name, ms in sp["planners_ms"].items():
        print(f"| {name} on 2000 specks | {ms:.1f} ms |")
    for kind in masks:
        print(
            f"{kind} masks: polygons per scene median {results[kind]['polygons_median']}, max {results[kind]['polygons_max']}"
        )


if __name__ == "__main__":
    main()
