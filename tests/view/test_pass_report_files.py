"""The files a pass writes are the ones a rerun replaces (issue 39: the report moved to view)."""

from __future__ import annotations

import numpy as np

from dyntarget.fly import PassConfig, fly_pass
from dyntarget.scene import Scene
from dyntarget.synth.worlds import StaticWorld
from dyntarget.view.pass_report import ViewCollector, pass_files, write_pass, write_times


def test_every_file_a_pass_writes_is_one_a_rerun_replaces(tmp_path):
    img = np.full((4, 256, 64), 0.05, np.float32)
    lab = np.zeros((256, 64), bool)
    lab[100:120, 20:40] = True
    img[:, lab] = 0.8
    world = StaticWorld(Scene(img, label=lab, gsd=8.0))
    views = ViewCollector()
    result = fly_pass(
        world, None, PassConfig(agility="unlimited", compute_budget_s=0.01), frame_sink=views
    )
    written = write_pass(result, world, tmp_path, views=views)
    assert write_times(result, tmp_path) is None  # no GEO, no GEO times
    names = {p.name for p in written}
    assert {"timeline.csv", "pointings.geojson", "summary.md", "summary.json"} <= names
    assert names <= set(pass_files())
    assert {p.name for p in tmp_path.iterdir()} <= set(pass_files())
