"""summary.json: the pass totals, machine-readable, checked against counts of the other files."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from dyntarget.fly import PassConfig, fly_pass
from dyntarget.scene import Scene
from dyntarget.synth.worlds import StaticWorld
from dyntarget.view.pass_report import SUMMARY_KEYS, write_pass

PLUMES = [(600, 680, 20, 80), (200, 260, 40, 100)]  # (row0, row1, col0, col1), high-res px


def _strip() -> StaticWorld:
    image = np.full((4, 1024, 128), 0.05, np.float32)
    label = np.zeros((1024, 128), bool)
    for r0, r1, c0, c1 in PLUMES:
        label[r0:r1, c0:c1] = True
    image[:, label] = 0.8
    return StaticWorld(Scene(image, label=label, gsd=8.0, id="strip"))


def test_summary_json_matches_an_independent_count(tmp_path):
    world = _strip()
    result = fly_pass(world, None, PassConfig(agility="unlimited", compute_budget_s=0.01))
    write_pass(result, world, tmp_path, picture=False)
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert set(SUMMARY_KEYS) <= set(doc)
    assert doc["geo"] is None
    with (tmp_path / "timeline.csv").open() as f:
        rows = list(csv.DictReader(f))
    features = json.loads((tmp_path / "pointings.geojson").read_text())["features"]
    points = [f for f in features if f["geometry"]["type"] == "Point"]
    assert doc["frames"] == len(rows)
    assert doc["pointings_flown"] == len(points) == sum(int(r["pointings_flown"]) for r in rows)
    assert doc["utility"] == pytest.approx(sum(float(r["utility_gained"]) for r in rows), abs=1e-3)
    # which rectangle each flown pointing lies in, from its WFOV pixel (factor 4)
    hit = set()
    plume = 0.0
    for f in points:
        x, y = f["geometry"]["coordinates"][:2]
        plume += f["properties"]["plume_fraction"]
        for i, (r0, r1, c0, c1) in enumerate(PLUMES):
            if r0 <= 4 * y + 2 < r1 and c0 <= 4 * x + 2 < c1:
                hit.add(i)
    assert doc["plumes_observed"] == len(hit) == 2 and doc["plumes_total"] == 2
    assert doc["ratio_plume"] == pytest.approx(plume / len(points), abs=1e-3)
