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


def test_the_slider_shows_each_pointing_on_the_frame_whose_plan_it_came_from():
    # four pointings flown: two from frame 3's plan when it was ready, then (after frame 5)
    # frame 5's own one and one of frame 3's that was held (defer_cut) and flown with it.
    # Frame 3's view shows its three (frame pixels: y less its top 100), frame 5's its one
    from types import SimpleNamespace

    from dyntarget.passes.record import Flown, FrameView
    from dyntarget.view.pass_report import _pass_frames

    fl = Flown(
        x=[1.0, 2.0, 3.0, 4.0], y=[110.0, 111.0, 90.0, 112.0], t=[10.0, 11.0, 12.0, 13.0],
        frame=[3, 3, 5, 3], part=[0, 0, 1, 0], plume=[0.5, 0.25, 1.0, 0.75],
        intensity=[0.0] * 4, plume_id=[1, 1, 2, 1],
    )  # fmt: skip
    result = SimpleNamespace(
        flown=fl, config=SimpleNamespace(planner="demo"),
        frames=SimpleNamespace(acquired_s=lambda k: 0.5 * k),
    )  # fmt: skip
    plan = SimpleNamespace(probability=None, polygons=())
    image = np.zeros((4, 32, 8), np.float32)
    views = [FrameView(3, 100, image, plan, 0, 2), FrameView(5, 80, image, plan, 2, 4)]
    three, five = _pass_frames(result, views)
    assert three.trajectory.points.tolist() == [[1.0, 10.0], [2.0, 11.0], [4.0, 12.0]]
    assert three.trajectory.times.tolist() == [10.0, 11.0, 13.0]
    assert list(three.point_values["plume_fraction"]) == [0.5, 0.25, 0.75]
    assert three.label == "frame 3: 3 flown"
    assert five.trajectory.points.tolist() == [[3.0, 10.0]] and five.label == "frame 5: 1 flown"
