"""Scoring each pointing against the truth at its own time."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError, Scene
from dyntarget.denoise import denoise
from dyntarget.observe import observe, observe_at
from dyntarget.plan import PAPER_PLANNERS, PlanConfig, Trajectory, plan
from dyntarget.schedule import OrbitGeometry, make_feasible
from dyntarget.synth import generate_scene
from dyntarget.synth.dynamic import TruthCache, World, sample_world

FACTOR = 4


@pytest.mark.parametrize("planner", PAPER_PLANNERS)
@pytest.mark.parametrize("footprint", [1, 3])
def test_zero_latency_static_truth_equals_todays_numbers_exactly(planner, footprint):
    scene, _ = generate_scene(0, 1, size=96)
    wfov = scene.to_wfov(FACTOR)
    cleaned = denoise(wfov.label)
    traj = plan(planner, cleaned.mask, cleaned.polygons, PlanConfig())
    geometry = OrbitGeometry(wfov_gsd_m=scene.gsd * FACTOR)
    timed = make_feasible(traj, wfov.shape, geometry, "fast").trajectory  # varied times
    for t in (traj, timed):
        expected = observe(t, scene, factor=FACTOR, footprint=footprint)
        got = observe_at(t, lambda _t: scene, factor=FACTOR, footprint=footprint)
        assert got == expected  # exact equality of every float


def test_zero_latency_on_a_moving_world_equals_observing_its_first_frame():
    world = World(sample_world(0, 4, size=64, wind_mps=12.0))
    truth = TruthCache(world, step_s=0.0)
    wfov = truth(0.0).to_wfov(FACTOR)
    cleaned = denoise(wfov.label)
    traj = plan("trace-outline", cleaned.mask, cleaned.polygons, PlanConfig())
    assert observe_at(traj, truth, factor=FACTOR) == observe(traj, truth(0.0), factor=FACTOR)


def _moving_block():
    """Plume = WFOV pixel (0, 0) at t = 0, WFOV pixel (1, 1) from t = 60 s (factor 4)."""
    image = np.full((4, 8, 8), 0.5, np.float32)
    before = np.zeros((8, 8), bool)
    before[:4, :4] = True
    after = np.zeros((8, 8), bool)
    after[4:, 4:] = True
    s0, s1 = Scene(image, label=before), Scene(image, label=after)
    return lambda t: s0 if t < 60.0 else s1


def test_each_pointing_scored_at_its_own_time_by_hand():
    truth = _moving_block()
    pts = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    # pointing 1 at t=0 sees the plume at (0,0); pointing 2 at t=70 sees it at (1,1);
    # pointing 3 at t=70 sees nothing: ratio plume = (1 + 1 + 0) / 3
    traj = Trajectory(pts, np.zeros(3), "t", times=np.array([0.0, 70.0, 70.0]))
    m = observe_at(traj, truth, factor=FACTOR)
    assert m.pixels_observed == 3 and m.ratio_plume == pytest.approx(2 / 3)
    # with 60 s latency every pointing is late: only (1, 1) is plume
    m = observe_at(traj, truth, factor=FACTOR, latency_s=60.0)
    assert m.ratio_plume == pytest.approx(1 / 3)
    # untimed: all at latency_s
    untimed = Trajectory(pts, np.zeros(3), "t")
    assert observe_at(untimed, truth, factor=FACTOR).ratio_plume == pytest.approx(1 / 3)


def test_repeat_visit_counts_once_at_its_first_time():
    truth = _moving_block()
    traj = Trajectory(np.array([[0.0, 0.0], [0.0, 0.0]]), np.zeros(2), "t", times=[0.0, 90.0])
    m = observe_at(traj, truth, factor=FACTOR)
    assert m.pixels_observed == 1 and m.ratio_plume == 1.0


def test_bad_latency_and_provider_are_refused():
    traj = Trajectory(np.zeros((1, 2)), np.zeros(1), "t")
    with pytest.raises(InvalidParameterError, match="latency_s"):
        observe_at(traj, _moving_block(), factor=FACTOR, latency_s=float("nan"))
    with pytest.raises(InvalidParameterError, match="truth"):
        observe_at(traj, "not callable", factor=FACTOR)
    with pytest.raises(InvalidParameterError, match="truth provider"):
        observe_at(traj, lambda t: np.zeros((8, 8)), factor=FACTOR)
