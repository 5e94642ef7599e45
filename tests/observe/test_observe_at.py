"""Scoring each pointing against the truth at its own time."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError, InvalidSceneError, Scene
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


ZERO = (0, 0.0, 0.0, 0.0)


def _maps(h, w, plume, valid=None):
    """Utility maps worked by hand: label = intensity = gradient = ``plume`` (0/1)."""
    from dyntarget.utility import UtilityMaps

    p = np.asarray(plume, np.float32)
    return UtilityMaps(p > 0, p.copy(), p.copy(), None if valid is None else np.asarray(valid))


def _metrics(m):
    return (m.pixels_observed, m.ratio_plume, m.intensity, m.gradient)


def test_nothing_observed_scores_exactly_zero():
    maps = _maps(8, 8, np.ones((8, 8)))
    empty = Trajectory(np.zeros((0, 2)), np.zeros(0), "t")
    assert _metrics(observe_at(empty, lambda t: maps, factor=FACTOR)) == ZERO
    # every pointing off the 2 x 2 WFOV grid: one column or row too far on each side
    off = np.array([[2.0, 0.0], [0.0, 2.0], [-1.0, 0.0], [0.0, -1.0], [2.0, 2.0]])
    traj = Trajectory(off, np.zeros(len(off)), "t", times=np.zeros(len(off)))
    assert _metrics(observe_at(traj, lambda t: maps, factor=FACTOR)) == ZERO
    # every pointing on nodata
    nodata = _maps(8, 8, np.ones((8, 8)), valid=np.zeros((8, 8), bool))
    on = Trajectory(np.array([[0.0, 0.0], [1.0, 1.0]]), np.zeros(2), "t")
    assert _metrics(observe_at(on, lambda t: nodata, factor=FACTOR)) == ZERO


def test_nodata_pointing_dropped_valid_one_kept_by_hand():
    valid = np.ones((8, 8), bool)
    valid[4:, 4:] = False  # WFOV pixel (1, 1) is nodata
    maps = _maps(8, 8, np.ones((8, 8)), valid=valid)
    traj = Trajectory(np.array([[0.0, 0.0], [1.0, 1.0]]), np.zeros(2), "t")
    assert _metrics(observe_at(traj, lambda t: maps, factor=FACTOR)) == (1, 1.0, 1.0, 1.0)


def test_distinct_pixels_of_a_tall_grid_counted_apart():
    # a 12 x 4 truth at factor 2: a 6 x 2 WFOV grid, taller than wide; WFOV (row 2, col 0) is
    # plume, (row 0, col 1) is not: two pixels, ratio 1/2
    plume = np.zeros((12, 4))
    plume[4:6, 0:2] = 1
    traj = Trajectory(np.array([[0.0, 2.0], [1.0, 0.0]]), np.zeros(2), "t")
    m = observe_at(traj, lambda t: _maps(12, 4, plume), factor=2)
    assert m.pixels_observed == 2 and m.ratio_plume == 0.5


def test_latency_delays_every_pointing():
    # one pointing at WFOV (1, 1) taken at t = 0: with 60 s latency it sees the plume that has
    # moved there by t = 60; without latency it sees none
    traj = Trajectory(np.array([[1.0, 1.0]]), np.zeros(1), "t", times=np.zeros(1))
    assert observe_at(traj, _moving_block(), factor=FACTOR, latency_s=60.0).ratio_plume == 1.0
    assert observe_at(traj, _moving_block(), factor=FACTOR).ratio_plume == 0.0


def test_truth_on_another_grid_refused_with_both_grids_and_times():
    small, tall = _maps(8, 8, np.ones((8, 8))), _maps(16, 8, np.ones((16, 8)))
    traj = Trajectory(np.array([[0.0, 0.0], [1.0, 1.0]]), np.zeros(2), "t", times=[0.0, 60.0])
    with pytest.raises(
        InvalidSceneError,
        match=r"^truth at t=60 s: WFOV grid \(4, 2\) differs from \(2, 2\) at t=0 s$",
    ):
        observe_at(traj, lambda t: small if t < 60 else tall, factor=FACTOR)


def test_provider_errors_name_the_problem():
    traj = Trajectory(np.zeros((1, 2)), np.zeros(1), "t")
    with pytest.raises(
        InvalidParameterError, match=r"^truth: expected a callable t -> Scene \(a truth provider\)$"
    ):
        observe_at(traj, "not callable", factor=FACTOR)
    with pytest.raises(InvalidParameterError, match="UtilityMaps, got ndarray$"):
        observe_at(traj, lambda t: np.zeros((8, 8)), factor=FACTOR)


@pytest.mark.parametrize("as_maps", [True, False])
def test_footprint_by_hand_from_maps_and_scenes(as_maps):
    # a 4 x 4 truth at factor 2 (2 x 2 WFOV grid) with plume only under WFOV (0, 0): footprint 1
    # sees it whole (ratio 1); footprint 3 centred there averages the four WFOV pixels that
    # exist (the other five are off the image): ratio 1/4. The same Scene object is asked
    # for both footprints, so a cache must keep them apart.
    plume = np.zeros((4, 4))
    plume[:2, :2] = 1
    truth = (
        _maps(4, 4, plume) if as_maps else Scene(np.ones((4, 4, 4), np.float32), label=plume > 0)
    )
    traj = Trajectory(np.zeros((1, 2)), np.zeros(1), "t")
    one = observe_at(traj, lambda t: truth, factor=2, footprint=1)
    three = observe_at(traj, lambda t: truth, factor=2, footprint=3)
    assert one.pixels_observed == three.pixels_observed == 1
    assert one.ratio_plume == 1.0 and three.ratio_plume == pytest.approx(0.25)
    if as_maps:  # intensity = gradient = the plume here
        assert three.intensity == pytest.approx(0.25) and three.gradient == pytest.approx(0.25)
