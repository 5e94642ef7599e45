"""Make the README's picture of the interactive view: plan a synthetic scene, open it in Chromium.

    PYTHONPATH=src python scripts/view_screenshot.py            # -> docs/img/view.png
    PYTHONPATH=src python scripts/view_screenshot.py --out DIR  # also keeps view.html, plan.geojson

Steps (all seeded): scene 1 of the synthetic set (seed 0, 256 px, 8 m, UTM 5N),
a random-forest classifier trained on scenes 2-5, WFOV = 2x downsampled,
classify + denoise + lawnmower-transect plan, timed under the 'fast' agility preset,
acquired 2024-05-01T10:00:00Z. Writes the RFC 7946 GeoJSON of the plan and of the
polygons, the HTML view, and a headless-Chromium screenshot of the view with the
hover label of one pointing shown. Needs the 'view' extra, selenium and Debian's
chromium + chromium-driver. Takes about a minute.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from dyntarget.io.geojson import write_polygons, write_trajectory
from dyntarget.observe import pointing_truth
from dyntarget.perceive import make_classifier
from dyntarget.pipeline import plan_scene
from dyntarget.schedule import OrbitGeometry, get_agility, make_feasible
from dyntarget.synth import generate_scene
from dyntarget.view import write_scene_view

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from view_browser import render  # the Selenium harness lives with the tests

ACQUIRED = "2024-05-01T10:00:00Z"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="keep view.html, plan.geojson, plumes.geojson here")
    parser.add_argument("--png", default="docs/img/view.png", help="screenshot path")
    args = parser.parse_args(argv)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="dyntarget-view-"))
    factor = 2
    scene = generate_scene(0, 1, size=256)[0]
    train = [generate_scene(0, i, size=256)[0].to_wfov(factor) for i in range(2, 6)]
    model = make_classifier("random-forest", seed=0).fit(train)
    wfov = scene.to_wfov(factor)
    result = plan_scene(wfov.image, model, "lawnmower-transect")
    geometry = OrbitGeometry(altitude_m=500e3, look_ahead_m=500e3, wfov_gsd_m=wfov.gsd)
    sched = make_feasible(result.trajectory, wfov.shape, geometry, get_agility("fast"))
    traj = sched.trajectory
    georef = {"transform": wfov.transform, "crs": wfov.crs, "acquired": ACQUIRED}
    print(write_trajectory(out / "plan.geojson", traj, **georef))
    print(write_polygons(out / "plumes.geojson", result.polygons, **georef))
    view = write_scene_view(
        out / "view.html",
        wfov.image,
        probability=result.probability,
        polygons=result.polygons,
        trajectory=traj,
        point_values=pointing_truth(traj, scene.image, scene.label, factor=factor),  # hover
        title=f"{wfov.id}: random-forest, lawnmower-transect, 'fast' agility "
        f"({len(traj)} of {len(result.trajectory)} pointings feasible)",
        **georef,
    )
    print(view)
    png = Path(args.png)
    png.parent.mkdir(parents=True, exist_ok=True)
    truth = pointing_truth(traj, scene.image, scene.label, factor=factor)
    shown = render(
        view, screenshot=png, window=(1000, 960), hover=int(np.nanargmax(truth["gradient"]))
    )
    if shown.errors:
        raise SystemExit(f"browser console errors: {shown.errors}")
    print(f"{png}: {len(shown.drawn)} pointings drawn, {len(shown.console)} console entries")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
