"""Orbit kinematics and agility against hand-computed cases; utility-max; the agility evaluation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.plan.utility import predicted_utility, utility_max
from dyntarget.schedule import (
    AGILITY,
    EARTH_RADIUS_M,
    Agility,
    OrbitGeometry,
    look_vectors,
    off_nadir_deg,
    schedule,
    visibility_windows,
)
from dyntarget.trajectory import Trajectory

FAST = AGILITY["fast"]
SLOW = AGILITY["slow"]


def test_ground_speed_at_500_km_by_hand():
    # v = sqrt(GM / (R + h)) = sqrt(3.986004418e14 / 6.871e6) = 7616.5 m/s in orbit;
    # the nadir point moves R / (R + h) as fast: 7616.5 * 6371 / 6871 = 7062.3 m/s
    assert OrbitGeometry(altitude_m=500e3).ground_speed == pytest.approx(7062.3, abs=0.1)


def test_slew_time_for_known_angles():
    a = Agility("t", max_rate_deg_s=1.0, max_accel_deg_s2=0.5)
    # 10 deg > rate^2 / accel = 2 deg: trapezoid, 10 / 1 + 1 / 0.5 = 12 s
    assert a.slew_time(10.0) == pytest.approx(12.0)
    # 1 deg < 2 deg: triangle, 2 * sqrt(1 / 0.5) = 2.828 s
    assert a.slew_time(1.0) == pytest.approx(2 * math.sqrt(2.0))
    # the two branches meet at 2 deg: 2 / 1 + 2 = 4 = 2 * sqrt(2 / 0.5)
    assert a.slew_time(2.0) == pytest.approx(4.0)
    assert Agility("r", max_rate_deg_s=2.0).slew_time(10.0) == pytest.approx(5.0)
    assert AGILITY["unlimited"].slew_time(45.0) == 0.0


@pytest.mark.parametrize("one", [False, True])
def test_a_change_of_direction_below_the_resolution_takes_no_slew(one):
    # 1e-5 deg (0.036 arcsec): below it no slew; just above, the triangle profile by hand,
    # 2 sqrt(2e-5 / 0.5) = 0.012649 s. 1.2e-6 deg is what the arc cosine of two unit vectors
    # of one direction, a few units in the last place apart, gives
    a = Agility("t", max_rate_deg_s=1.0, max_accel_deg_s2=0.5)
    slew = a.slew_time_one if one else a.slew_time
    assert float(slew(1.2e-6)) == 0.0 and float(slew(-9.9e-6)) == 0.0
    assert float(slew(2e-5)) == pytest.approx(0.0126491, rel=1e-5)


def test_two_pointings_at_one_top_are_timed_alike_with_and_without_avx512():
    # numpy dispatches its vector loops to AVX-512 where the CPU has it; the arc cosine of
    # two nearly parallel look vectors then came out about 1e-6 deg instead of 0, a slow
    # slew of 3 ms per pointing. The aim test's two pointings at one 10 km top, flown with
    # numpy's AVX-512 loops disabled and as this CPU runs them: the same times to the bit
    import json
    import os
    import subprocess
    import sys

    code = (
        "import sys; sys.path.insert(0, 'tests'); import numpy as np; import test_aim as T;"
        "from dyntarget.schedule import schedule_on_prediction, OrbitGeometry;"
        "from dyntarget.trajectory import Trajectory;"
        "g = OrbitGeometry(altitude_m=T.H_SC, look_ahead_m=500e3, wfov_gsd_m=T.GSD, start_s=40.0);"
        "b = np.array([T._pixel(500e3, 0.0), T._pixel(500e3, 0.0)]);"
        "s = schedule_on_prediction(Trajectory(b, np.zeros(2), 'demo'), T.SHAPE, g, 'slow',"
        " None, aim=T._aim()); import json; print(json.dumps(s.times.tolist()))"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

    def times(disabled: str) -> list[float]:
        env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": disabled}
        out = subprocess.run([sys.executable, "-c", code], env=env, cwd=root,
                             capture_output=True, text=True, check=True)  # fmt: skip
        return json.loads(out.stdout.strip().splitlines()[-1])  # floats round-trip exactly

    from numpy._core._multiarray_umath import __cpu_dispatch__

    avx512 = [f for f in __cpu_dispatch__ if f.startswith(("AVX512", "X86_V4"))]
    native, no512 = times(""), times(" ".join(avx512))
    assert native == no512
    assert native[1] - native[0] == pytest.approx(1.1, abs=1e-9)  # dwell 0.1 + settle 1.0


def test_off_nadir_angle_on_a_sphere_by_hand():
    g = OrbitGeometry(altitude_m=500e3)
    # straight below: 0 deg
    assert off_nadir_deg(look_vectors(g, 1000.0, 0.0, 1000.0 / g.ground_speed)) == pytest.approx(
        0.0, abs=1e-6
    )
    # 300 km across track: Earth-central angle phi = d / R; tan(theta) = R sin phi / (R + h - R cos phi)
    phi = 300e3 / EARTH_RADIUS_M
    expected = math.degrees(
        math.atan2(
            EARTH_RADIUS_M * math.sin(phi), EARTH_RADIUS_M + 500e3 - EARTH_RADIUS_M * math.cos(phi)
        )
    )
    got = off_nadir_deg(look_vectors(g, 0.0, 300e3, 0.0))
    assert got == pytest.approx(expected, abs=1e-9)
    assert 30.0 < got < math.degrees(math.atan(300 / 500))  # less than flat: the Earth curves away


def test_visibility_window_of_a_point_on_the_ground_track():
    g = OrbitGeometry()
    t_in, t_out = visibility_windows(g, FAST, np.array([500e3]), np.array([0.0]))
    # enters the 30 deg field of regard when the off-nadir angle is 30 deg, leaves at overhead
    at_entry = off_nadir_deg(look_vectors(g, 500e3, 0.0, t_in[0]))
    assert at_entry == pytest.approx(30.0, abs=1e-6)
    assert t_out[0] == pytest.approx(500e3 / g.ground_speed)
    # a sensor that may look 30 deg aft keeps it as long again
    aft = Agility("aft", field_of_regard_deg=30.0, aft_limit_deg=30.0)
    t_in2, t_out2 = visibility_windows(g, aft, np.array([500e3]), np.array([0.0]))
    assert t_in2[0] == pytest.approx(t_in[0])
    assert t_out2[0] - t_out[0] == pytest.approx(t_out[0] - t_in[0], rel=1e-6)
    # too far across track: never visible
    t_in3, t_out3 = visibility_windows(g, FAST, np.array([500e3]), np.array([400e3]))
    assert t_in3[0] > t_out3[0]


def _line(ys, x=63.5):
    pts = np.array([[x, y] for y in ys], float)
    return Trajectory(pts, np.zeros(len(pts), int), "line")


def test_straight_along_track_line_is_feasible():
    g = OrbitGeometry()
    line = _line(np.arange(127, -1, -4.0))  # bottom (reached first) to top, along track
    s = schedule(line, (128, 128), g, FAST)
    assert s.fraction_feasible == 1.0 and len(s.kept) == 32
    assert np.all(np.diff(s.times) > 0)  # taken in order, one after another
    assert s.time_left_s > 0
    assert schedule(line, (128, 128), g, "unlimited").fraction_feasible == 1.0
    # the slow preset needs about 1.3 s per pointing: a short line fits, a long one is trimmed
    assert schedule(_line([127.0, 120.0, 113.0]), (128, 128), g, SLOW).fraction_feasible == 1.0
    long_line = schedule(_line(np.arange(127, -1, -1.0)), (128, 128), g, SLOW)
    assert 0 < long_line.fraction_feasible < 1


def test_pointing_behind_the_spacecraft_is_not_feasible():
    # the plan starts 80 s after acquisition: nadir is then 565 km down-track, past the scene
    g = OrbitGeometry(start_s=80.0)
    s = schedule(_line([64.0]), (128, 128), g, FAST)
    assert s.fraction_feasible == 0.0 and len(s.trajectory) == 0
    # with unlimited agility (the paper's assumption) it would still be taken
    assert schedule(_line([64.0]), (128, 128), g, "unlimited").fraction_feasible == 1.0


def test_order_matters_and_reordering_recovers_points():
    # a 384 km long WFOV scene: its far edge enters the field of regard after the near edge left it
    g = OrbitGeometry(wfov_gsd_m=3000.0)
    near = [[64.0, y] for y in (127.0, 125.0, 123.0)]
    far_first = Trajectory(np.array([[64.0, 0.0], *near]), np.zeros(4, int), "far-first")
    as_planned = schedule(far_first, (128, 128), g, FAST)
    # waiting for the far point, the sensor lets the near ones pass under it
    assert list(as_planned.kept) == [0]
    reordered = schedule(far_first, (128, 128), g, FAST, reorder=True)
    assert list(reordered.kept) == [1, 2, 3, 0] and np.all(np.diff(reordered.times) > 0)


def test_budget_trims_and_times_are_exported(tmp_path):
    g = OrbitGeometry()
    line = _line(np.arange(127, -1, -4.0))
    full = schedule(line, (128, 128), g, FAST)
    budget = full.times[10] - g.start_s  # room for 10 observations and part of the 11th
    short = schedule(line, (128, 128), g, FAST, budget_s=budget)
    assert len(short.kept) == 10
    path = short.trajectory.save(tmp_path / "t.csv")
    header, first = path.read_text().splitlines()[:2]
    assert header.endswith(",time_s") and float(first.split(",")[-1]) == pytest.approx(
        short.times[0], abs=1e-3
    )


def test_bad_kinematic_parameters_are_refused():
    with pytest.raises(InvalidParameterError, match="altitude_m"):
        OrbitGeometry(altitude_m=50.0)
    with pytest.raises(InvalidParameterError, match="field_of_regard_deg"):
        Agility("x", field_of_regard_deg=95.0)
    with pytest.raises(InvalidParameterError, match="max_rate_deg_s"):
        Agility("x", max_rate_deg_s=-1.0)
    with pytest.raises(InvalidParameterError, match="unknown preset"):
        schedule(_line([1.0]), (128, 128), OrbitGeometry(), "nimble")


def _blob(h=64, w=64):
    yy, xx = np.mgrid[:h, :w]
    p = np.exp(-(((yy - 32) / 10.0) ** 2 + ((xx - 20) / 6.0) ** 2)).astype(np.float32)
    image = np.full((4, h, w), 0.2, np.float32)
    image[2] += p
    return p, image


def test_utility_max_picks_high_utility_and_respects_budgets():
    p, image = _blob()
    g = OrbitGeometry(wfov_gsd_m=32.0)
    traj = utility_max(p, image, g, "unlimited", step=1.0, objective="plume", max_pointings=5)
    assert len(traj) == 5
    # with unlimited agility the first pick is the most probable pixel
    assert tuple(traj.points[0]) == (20.0, 32.0)
    timed = utility_max(p, image, g, FAST, step=2.0, budget_s=35.0)
    s = schedule(timed, p.shape, g, FAST)
    assert s.fraction_feasible == 1.0 and s.end_s <= 35.0 + 1e-9
    u = predicted_utility(p, image, "gradient")
    assert u.max() == pytest.approx(1.0)
    assert (
        u[timed.points[:, 1].astype(int), timed.points[:, 0].astype(int)].mean() > u[p > 0.1].mean()
    )
    with pytest.raises(InvalidParameterError, match="max_pointings"):
        utility_max(p, image, g, "unlimited", step=1.0)
    with pytest.raises(InvalidParameterError, match="objective"):
        utility_max(p, image, g, FAST, step=1.0, objective="beauty")


def test_utility_max_empty_probability_gives_empty_plan():
    p = np.zeros((32, 32), np.float32)
    traj = utility_max(p, np.ones((4, 32, 32), np.float32), OrbitGeometry(), FAST, step=1.0)
    assert len(traj) == 0


def test_make_feasible_flies_the_better_order():
    from dyntarget.schedule import make_feasible

    g = OrbitGeometry(wfov_gsd_m=3000.0)
    near = [[64.0, y] for y in (127.0, 125.0, 123.0)]
    far_first = Trajectory(np.array([[64.0, 0.0], *near]), np.zeros(4, int), "far-first")
    assert list(make_feasible(far_first, (128, 128), g, FAST).kept) == [1, 2, 3, 0]
    # a cross-track transect: reordering by deadline would zig-zag; the plan's order is kept
    row = Trajectory(
        np.array([[x, 64.0] for x in range(0, 128, 4)], float), np.zeros(32, int), "row"
    )
    flown = make_feasible(row, (128, 128), OrbitGeometry(), SLOW)
    assert len(flown.kept) >= len(
        schedule(row, (128, 128), OrbitGeometry(), SLOW, reorder=True).kept
    )


def test_arrival_one_gives_the_vectorised_arrivals_floats_to_the_bit():
    """The scalar path (one pointing at a time) against the numpy path on random
    orbits, presets, custom kinematics and sensor states: the same floats."""
    from dyntarget.schedule import AGILITY, Agility, OrbitGeometry, Timer

    rng = np.random.default_rng(0)
    custom = Agility("custom", max_rate_deg_s=2.5, max_accel_deg_s2=0.7, settle_s=1.5,
                     dwell_s=0.5, field_of_regard_deg=30.0)  # fmt: skip
    rate_only = Agility("rate-only", max_rate_deg_s=3.0, field_of_regard_deg=30.0)
    kinds = [a for a in AGILITY.values() if not a.unlimited] + [custom, rate_only]
    compared = 0
    for k in range(60):
        geometry = OrbitGeometry(altitude_m=float(rng.uniform(300e3, 900e3)), start_s=5.0)
        timer = Timer(geometry, kinds[k % len(kinds)])
        for _ in range(3):
            along, cross = rng.uniform(-6e5, 6e5, 6), rng.uniform(-3e5, 3e5, 6)
            t_in = rng.uniform(-50, 150, 6)
            expected = timer.arrival(along, cross, t_in)
            for i in range(6):
                got = timer.arrival_one(float(along[i]), float(cross[i]), float(t_in[i]))
                assert got == expected[i]
                compared += 1
            timer.take(along[0], cross[0], float(expected[0]))
    assert compared == 60 * 3 * 6
    unlimited = Timer(OrbitGeometry(start_s=7.0), AGILITY["unlimited"])
    assert unlimited.arrival_one(1e5, 0.0, -3.0) == 7.0


def _one_by_one(points, shape, geometry, agility, free_s=None, target=None, budget_s=None):
    """Reference walk: every pointing timed alone with Timer.arrival_one, in order."""
    from dyntarget.schedule import Timer

    along, cross = geometry.ground(points, shape)
    t_in, t_out = visibility_windows(geometry, agility, along, cross)
    timer = Timer(geometry, agility)
    if free_s is not None:
        timer.t, timer.target = max(free_s, geometry.start_s), target
    limit = math.inf if budget_s is None else geometry.start_s + budget_s
    kept, times = [], []
    for j in range(len(points)):
        if t_in[j] > t_out[j]:
            continue
        start = timer.arrival_one(float(along[j]), float(cross[j]), float(t_in[j]))
        end = start + agility.dwell_s
        if end > t_out[j] or end > limit:
            continue
        timer.take(along[j], cross[j], start)
        kept.append(j)
        times.append(start)
    return kept, times, timer


@pytest.mark.parametrize("preset", ["fast", "slow"])
@pytest.mark.parametrize("seed", [0, 4])
def test_chunked_schedule_equals_the_pointing_by_pointing_walk(preset, seed):
    # schedule() screens CHUNK pointings at once; it must keep exactly what a walk that
    # times one pointing after the other keeps, at the same floats (also from a busy sensor
    # and under a budget)
    from dyntarget.schedule import SensorState

    rng = np.random.default_rng(seed)
    points = rng.uniform(0, 511, (300, 2))  # random order over 16 km: long slews, many dropped
    shape, agility = (512, 512), AGILITY[preset]
    g = OrbitGeometry(wfov_gsd_m=32.0, start_s=0.7)
    traj = Trajectory(points, np.zeros(len(points)), "demo")
    for free, target, budget in ((None, None, None), (3.5, (480e3, 2e3), None), (None, None, 45.0)):
        sensor = None if free is None else SensorState(free, target)
        s = schedule(traj, shape, g, agility, sensor=sensor, budget_s=budget)
        kept, times, timer = _one_by_one(points, shape, g, agility, free, target, budget)
        assert 0 < len(kept) < len(points)
        assert s.kept.tolist() == kept
        assert s.times.tolist() == times  # bit for bit
        assert s.end_s == timer.t and s.end_target == timer.target


def test_a_busy_sensor_starts_when_free_from_what_it_tracks():
    # the scene centre 500 km ahead enters the 30 deg field of regard after ~29 s and is
    # lost when passed (~71 s). Free at t = 40 s, tracking that very ground point: no slew,
    # so the observation starts after the settling alone, 40 + 0.05 = 40.05 s (fast preset)
    from dyntarget.schedule import SensorState

    g = OrbitGeometry(wfov_gsd_m=32.0)
    pt = np.array([[64.0, 64.0]])
    along, cross = g.ground(pt, (128, 128))
    traj = Trajectory(pt, np.zeros(1), "demo")
    busy = schedule(traj, (128, 128), g, FAST, sensor=SensorState(40.0, (along[0], cross[0])))
    assert busy.times.tolist() == [pytest.approx(40.05, abs=1e-9)]
    assert busy.end_s == pytest.approx(40.1, abs=1e-9)  # + dwell 0.05 s
    # tracking a point 3.2 km across track instead: a slew first, so later than 40.05 s
    aside = schedule(traj, (128, 128), g, FAST, sensor=SensorState(40.0, (along[0], 3.2e3)))
    assert aside.times[0] > 40.05 + 1e-3
    # a sensor "free" before the plan is ready waits for the plan (start_s)
    early = schedule(
        traj, (128, 128), OrbitGeometry(wfov_gsd_m=32.0, start_s=2.0), "unlimited",
        sensor=SensorState(1.0),
    )  # fmt: skip
    assert early.times.tolist() == [2.0]


def test_a_pass_sensor_is_seen_in_the_frame_time_and_ground():
    # issue 39: SensorState for one frame of a pass (was fly.loop._sensor)
    from dyntarget.schedule import sensor_in_frame

    g = OrbitGeometry()
    v = g.ground_speed
    # free at 12 s into the pass, tracking 1 km ahead of where nadir was at t = 0 + 10 s of flight;
    # frame acquired at 10 s, its plan ready at 11 s: free 2 s after the acquisition, the target
    # 1 km ahead of the frame's nadir
    s = sensor_in_frame(12.0, (v * 10.0 + 1000.0, -40.0), g, 10.0, 11.0)
    assert s.free_s == pytest.approx(2.0)
    assert s.target == (pytest.approx(1000.0), -40.0)
    # a plan ready after the sensor is free starts when it is ready; no target: nadir
    s = sensor_in_frame(3.0, None, g, 10.0, 14.5)
    assert s.free_s == pytest.approx(4.5) and s.target is None


def test_the_lead_is_when_the_frame_enters_the_field_of_regard_or_later():
    from dyntarget.schedule import get_agility, lead_s

    g, fast = OrbitGeometry(), get_agility("fast")
    # the frame centre enters the field of regard when its look angle drops to the limit:
    # ahead distance d with atan-geometry worked from the orbit (spherical Earth)
    R, h = 6_371_000.0, g.altitude_m
    fov = math.radians(fast.field_of_regard_deg)
    # off-nadir angle fov -> Earth central angle: asin((R + h) / R * sin(fov)) - fov
    central = math.asin((R + h) / R * math.sin(fov)) - fov
    enter = (g.look_ahead_m - R * central) / g.ground_speed
    assert lead_s(g, fast, 0.0, 0.0, 0.0) == pytest.approx(enter, abs=1e-3)
    # the sensor busy until 100 s into the pass on a frame acquired at 10 s: 90 s
    assert lead_s(g, fast, 10.0, 12.0, 100.0) == pytest.approx(90.0)
    # unlimited agility: no field of regard, the lead is when the loop or sensor is free
    assert lead_s(g, get_agility("unlimited"), 10.0, 12.5, 0.0) == pytest.approx(2.5)


def test_without_a_prediction_schedule_on_prediction_is_make_feasible():
    from dyntarget.schedule import make_feasible, schedule, schedule_on_prediction

    traj = Trajectory(np.array([[8.0, 2.0], [8.0, 14.0], [2.0, 8.0]]), np.zeros(3), "demo")
    g = OrbitGeometry(start_s=1.0)
    a = schedule_on_prediction(traj, (16, 16), g, "slow", None)
    b = make_feasible(traj, (16, 16), g, "slow")
    assert a.kept.tolist() == b.kept.tolist() and a.times.tolist() == b.times.tolist()
    planned = schedule(traj, (16, 16), g, "slow")
    c = schedule_on_prediction(traj, (16, 16), g, "slow", None, as_planned=planned)
    assert c.kept.tolist() == b.kept.tolist()
