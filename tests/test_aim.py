"""Parallax-corrected aiming (dyntarget.schedule.aim) against ray-sphere vector algebra.

The module composes dyntarget.parallax's closed-form angles; the reference here builds the
spacecraft, the plume top and the lines of sight as 3D vectors and intersects rays with
spheres (the method of tests/test_parallax.py), then reads the aim off the ground.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dyntarget.errors import InvalidParameterError
from dyntarget.predict import Motion, Prediction
from dyntarget.schedule import (
    OrbitGeometry,
    ParallaxAim,
    SensorState,
    iterate_on_prediction,
    make_feasible,
    nadir_xy,
    schedule,
    schedule_on_prediction,
)
from dyntarget.trajectory import Trajectory

R = 6_371_008.7714  # the sphere of dyntarget.parallax: WGS 84 mean radius (2a + b) / 3
H_SC = 500e3
H_TOP = 10e3
GSD = 30.0
G = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD)
SHAPE = (101, 201)  # rows, columns: the frame's centre pixel is (100, 50)


def _ray_hits_sphere(s: np.ndarray, through: np.ndarray, radius: float) -> np.ndarray:
    """First point where the ray from ``s`` through ``through`` meets the sphere ``radius``."""
    d = (through - s) / np.linalg.norm(through - s)
    b = float(s @ d)
    c = float(s @ s) - radius**2
    t = -b - math.sqrt(b * b - c)
    return s + t * d


def _unit(along: float, cross: float) -> np.ndarray:
    """Direction from the Earth's centre of the map point (along, cross): azimuthal
    equidistant about the nadir at t = 0 (+z), the track along +x, cross-track along +y."""
    d = math.hypot(along, cross)
    if d == 0:
        return np.array([0.0, 0.0, 1.0])
    g = d / R
    return np.array(
        [math.sin(g) * along / d, math.sin(g) * cross / d, math.cos(g)],
    )


def _map(p: np.ndarray) -> tuple[float, float]:
    """The map point (along, cross) of the ground point under ``p``."""
    u = p / np.linalg.norm(p)
    d = R * math.atan2(math.hypot(u[0], u[1]), u[2])
    az = math.atan2(u[1], u[0])
    return d * math.cos(az), d * math.sin(az)


def _vector_aim(along: float, cross: float, t_s: float, look_s: float = 0.0) -> tuple[float, float]:
    """The ground point an NFOV flown at ``t_s`` must aim at to meet the top the look-ahead
    saw at (along, cross): the top is where the ray from the spacecraft at ``look_s``
    (0: the acquisition) through the apparent ground point crosses R + h; the aim is where
    the ray from the spacecraft at t through that top meets the ground."""
    gl = G.ground_speed * look_s / R
    s0 = (R + H_SC) * np.array([math.sin(gl), 0.0, math.cos(gl)])
    top = _ray_hits_sphere(s0, R * _unit(along, cross), R + H_TOP)
    g = G.ground_speed * t_s / R  # the nadir's central angle along the track at t
    s_t = (R + H_SC) * np.array([math.sin(g), 0.0, math.cos(g)])
    return _map(_ray_hits_sphere(s_t, top, R))


def _pixel(along: float, cross: float) -> np.ndarray:
    """The frame pixel of a map point (OrbitGeometry.ground, inverted by hand)."""
    h, w = SHAPE
    return np.array([(w - 1) / 2 + cross / GSD, (h - 1) / 2 - (along - G.look_ahead_m) / GSD])


def _aim(height_m: float = H_TOP) -> ParallaxAim:
    return ParallaxAim.constant(G, SHAPE, height_m)


def test_top_at_nadir_when_flown_moves_back_by_its_whole_parallax():
    # A 10 km top whose true ground point lies 500 km ahead at the acquisition: the
    # look-ahead (500 km up) saw it D_app - 500 km further ahead, about 11.5 km. Flown
    # when the nadir is under it, the NFOV looks straight down at the true point.
    s0 = np.array([0.0, 0.0, R + H_SC])
    top = (R + H_TOP) * _unit(500e3, 0.0)
    d_app, _ = _map(_ray_hits_sphere(s0, top, R))
    assert 11.4e3 < d_app - 500e3 < 11.6e3
    t = 500e3 / G.ground_speed
    shift = _aim().shift(_pixel(d_app, 0.0)[None], t)[0]
    # back towards the spacecraft = down the frame (+rows), 383 px at 30 m; no cross move
    assert shift[1] == pytest.approx((d_app - 500e3) / GSD, abs=1e-4)
    assert 380 < shift[1] < 387
    assert shift[0] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("t_s", [5.0, 28.0, 60.0, 80.0])
@pytest.mark.parametrize("along", [380e3, 500e3, 620e3])
def test_on_track_aims_match_the_vector_method(along, t_s):
    want_a, want_c = _vector_aim(along, 0.0, t_s)
    got = _aim().shift(_pixel(along, 0.0)[None], t_s)[0]
    assert got[1] == pytest.approx(-(want_a - along) / GSD, abs=1e-4)  # 3 mm
    assert got[0] == pytest.approx(want_c / GSD, abs=1e-9)


@pytest.mark.parametrize("look_s", [2.0, 4.0, 20.0])
@pytest.mark.parametrize("t_s", [28.0, 60.0, 80.0])
def test_a_frame_taken_late_aims_from_where_the_look_ahead_then_was(look_s, t_s):
    # the frame's pixels are the same ground; the look-ahead saw it from a nadir
    # v * look_s further along (catching up after a re-look): the vectors from there
    along = 500e3
    want_a, _ = _vector_aim(along, 0.0, t_s, look_s)
    late = ParallaxAim(G, SHAPE, _aim().heights_m, look_s=look_s)
    got = late.shift(_pixel(along, 0.0)[None], t_s)[0]
    assert got[1] == pytest.approx(-(want_a - along) / GSD, abs=1e-4)
    # seen from nearer, the top was displaced less: the on-time frame's aim would be off
    on_time = _aim().shift(_pixel(along, 0.0)[None], t_s)[0]
    assert abs(on_time[1] - got[1]) > 10.0  # > 300 m even for 2 s late
    # flown at the look's own time and place: nothing moves
    assert np.abs(late.shift(_pixel(along, 0.0)[None], look_s)).max() < 1e-6


@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf])
def test_a_bad_look_time_is_refused(bad):
    with pytest.raises(InvalidParameterError) as err:
        ParallaxAim(G, SHAPE, _aim().heights_m, look_s=bad)
    assert str(err.value) == f"look_s: expected seconds >= 0 after the acquisition, got {bad!r}"


def test_flown_at_the_look_aheads_own_time_and_position_nothing_moves():
    pts = np.array([_pixel(500e3, 0.0), _pixel(480e3, 2e3), _pixel(510e3, -3e3), [0.0, 0.0]])
    assert np.abs(_aim().shift(pts, 0.0)).max() < 1e-6


@pytest.mark.parametrize(
    ("along", "cross", "t_s"),
    [
        (500e3, 3e3, 500e3 / 7062.3),  # the nadir abeam, just right of the track
        (500e3, 50e3, 500e3 / 7062.3),
        (500e3, 300e3, 10.0),  # far out to the right, early
        (500e3, 300e3, 70.0),
        (400e3, -200e3, 30.0),  # to the left
    ],
)
def test_cross_track_sign_and_size_against_vectors(along, cross, t_s):
    # On a flat Earth the two views differ by h / (H - h) times the nadir's move, along the
    # track only; the cross-track move is the sphere's: the NFOV, nearer, sees the top less
    # far out across the track than the look-ahead did, so the aim moves towards the track
    # (-x right of it, +x left of it), and back (+rows) as on the track.
    want_a, want_c = _vector_aim(along, cross, t_s)
    want = np.array([(want_c - cross) / GSD, -(want_a - along) / GSD])
    aim = _aim()
    got = aim.shift(_pixel(along, cross)[None], t_s)[0]
    assert np.sign(got).tolist() == [-np.sign(cross), 1.0] == np.sign(want).tolist()
    # the design's frame at t is the map shifted along the track (not re-centred on the
    # sphere): at most 8 m (0.3 px) from the vectors here, 300 km off the track
    assert got == pytest.approx(want, abs=0.3)
    mirror = aim.shift(_pixel(along, -cross)[None], t_s)[0]
    assert mirror == pytest.approx([-got[0], got[1]], abs=1e-9)


def test_nan_and_zero_heights_do_not_move_their_pointing():
    pts = np.array([_pixel(500e3, 0.0)] * 3)
    aim = ParallaxAim(G, SHAPE, lambda p, t: np.array([np.nan, 0.0, H_TOP]))
    got = aim.shift(pts, 30.0)
    assert got[:2].tolist() == [[0.0, 0.0], [0.0, 0.0]]
    assert got[2, 1] > 100


def test_a_pointing_without_a_height_takes_its_nearest_neighbours_within_fill_px():
    # three pointings 500 km ahead on the track: the first has a 10 km top, the second
    # (2 px away: a plan's neighbour just off the plume's mask) none, the third (40 px
    # away) none. With fill_px 5 the second aims at the 10 km top as the vector method
    # puts it (from its own pixel); the third, further than 5 px from any height, stays.
    pts = np.array(
        [_pixel(500e3, 0.0), _pixel(500e3 + 2 * GSD, 0.0), _pixel(500e3 + 40 * GSD, 0.0)]
    )
    field = lambda p, t: np.array([H_TOP, np.nan, 0.0])  # noqa: E731
    t_s = 40.0
    got = ParallaxAim(G, SHAPE, field, fill_px=5.0).shift(pts, t_s)
    want_a, _ = _vector_aim(500e3 + 2 * GSD, 0.0, t_s)
    assert got[1, 1] == pytest.approx(-(want_a - (500e3 + 2 * GSD)) / GSD, abs=1e-4)
    assert got[1, 1] > 100  # hundreds of pixels: what the pointing would otherwise miss by
    assert got[2].tolist() == [0.0, 0.0]
    # the default takes no neighbour's height: the second does not move
    assert ParallaxAim(G, SHAPE, field).shift(pts, t_s)[1].tolist() == [0.0, 0.0]
    # a radius under a pixel still fills a neighbour nearer than it (half a pixel away),
    # and only strictly nearer: one exactly fill_px away is not filled
    half = np.array([pts[0], pts[0] + [0.0, 0.5]])
    two = lambda p, t: np.array([H_TOP, np.nan])  # noqa: E731
    assert ParallaxAim(G, SHAPE, two, fill_px=0.75).shift(half, t_s)[1, 1] > 100
    assert ParallaxAim(G, SHAPE, two, fill_px=0.5).shift(half, t_s)[1].tolist() == [0.0, 0.0]
    # a look height is taken from the same neighbour as the height now (a rising top)
    rising = ParallaxAim(
        G, SHAPE, lambda p, t: np.array([8e3, np.nan, np.nan]),
        lambda p, t: np.array([6e3, np.nan, np.nan]), fill_px=5.0,
    )  # fmt: skip
    want_a = _vector_aim_rising(500e3 + 2 * GSD, t_s, 6e3, 8e3)
    got = rising.shift(pts, t_s)
    assert got[1, 1] == pytest.approx(-(want_a - (500e3 + 2 * GSD)) / GSD, abs=1e-4)


def test_heights_are_asked_per_pointing_with_its_time():
    seen = {}

    def heights(points, t_s):
        seen["points"], seen["t"] = points.copy(), t_s.copy()
        return np.full(len(points), H_TOP)

    pts = np.array([_pixel(500e3, 0.0), _pixel(505e3, 0.0)])
    ParallaxAim(G, SHAPE, heights).shift(pts, [10.0, 20.0])
    assert seen["points"].tolist() == pts.tolist() and seen["t"].tolist() == [10.0, 20.0]


def _vector_aim_rising(along: float, t_s: float, h_look: float, h_now: float) -> float:
    """The vector method for a rising top: the look-ahead (t = 0) saw the top at
    ``h_look``; the NFOV at ``t_s`` meets it at ``h_now`` above the same ground point."""
    s0 = np.array([0.0, 0.0, R + H_SC])
    top = _ray_hits_sphere(s0, R * _unit(along, 0.0), R + h_look)
    g = G.ground_speed * t_s / R
    s_t = (R + H_SC) * np.array([math.sin(g), 0.0, math.cos(g)])
    raised = top / np.linalg.norm(top) * (R + h_now)  # straight up from the same ground point
    return _map(_ray_hits_sphere(s_t, raised, R))[0]


@pytest.mark.parametrize("t_s", [20.0, 60.0])
def test_a_rising_top_is_placed_by_its_height_at_the_look_and_aimed_at_its_height_now(t_s):
    # the look-ahead saw a 6 km top; when the NFOV flies it, it has risen to 8 km
    along = 500e3
    aim = ParallaxAim(  # the fields are asked with each pointing's time
        G, SHAPE, lambda p, t: np.full(len(p), 8e3) + 0 * t, lambda p, t: 6e3 + 0 * t
    )
    got = aim.shift(_pixel(along, 0.0)[None], t_s)[0]
    want_a = _vector_aim_rising(along, t_s, 6e3, 8e3)
    assert got[1] == pytest.approx(-(want_a - along) / GSD, abs=1e-4)
    # using the later height for both views misplaces it by about the rise x tan(theta)
    same = ParallaxAim.constant(G, SHAPE, 8e3).shift(_pixel(along, 0.0)[None], t_s)[0]
    assert abs(same[1] - got[1]) > 1.5e3 / GSD


@pytest.mark.parametrize("look", [np.nan, 0.0])
def test_no_height_when_seen_means_no_move(look):
    aim = ParallaxAim(
        G, SHAPE, lambda p, t: np.full(len(p), H_TOP), lambda p, t: np.full(len(p), look)
    )
    assert aim.shift(np.array([_pixel(500e3, 0.0)]), 30.0).tolist() == [[0.0, 0.0]]


def test_a_half_metre_top_still_moves_its_pointing():
    # heights above 0 are corrected, however low: 0.5 m seen 500 km ahead is ~0.6 m
    aim = ParallaxAim.constant(G, SHAPE, 0.5)
    d = aim.shift(np.array([_pixel(500e3, 0.0)]), 500e3 / G.ground_speed)[0]
    assert 0.5 / GSD < d[1] < 0.7 / GSD
    look = ParallaxAim(
        G, SHAPE, lambda p, t: np.full(len(p), H_TOP), lambda p, t: np.full(len(p), 0.5)
    )
    assert look.shift(np.array([_pixel(500e3, 0.0)]), 30.0)[0, 1] != 0.0


def test_a_top_beyond_the_horizon_is_not_moved_and_its_neighbours_are():
    # 3,000 km ahead the look-ahead's line of sight misses a 10 km top's sphere around the
    # horizon: nothing to correct there; the pointing on the track 500 km ahead moves
    pts = np.array([_pixel(3000e3, 0.0), _pixel(500e3, 0.0)])
    got = _aim().shift(pts, 30.0)
    assert got[0].tolist() == [0.0, 0.0]
    assert np.isfinite(got).all() and got[1, 1] > 100
    # and the NFOV is not told to track a top there (height 0: the ground it aims at)
    moved, heights = _aim().move(pts, 30.0)
    assert moved.tolist() == got.tolist() and heights.tolist() == [0.0, H_TOP]


def test_the_height_limit_and_the_smallest_frame_are_accepted():
    from dyntarget import parallax

    assert ParallaxAim.constant(G, SHAPE, parallax.MAX_HEIGHT_M).heights_m(
        np.zeros((1, 2)), np.zeros(1)
    ).tolist() == [parallax.MAX_HEIGHT_M]
    one = ParallaxAim(G, [1, 1], lambda p, t: np.full(len(p), H_TOP))  # a list: kept a tuple
    assert one.frame_shape == (1, 1) and one.shift(np.zeros((1, 2)), 0.0).shape == (1, 2)


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda: nadir_xy(G, SHAPE, float("nan")), "t_s: expected a finite number"),
        (lambda: ParallaxAim(G, "ab", lambda p, t: p[:, 0]), "frame_shape: expected (rows"),
        (lambda: ParallaxAim(G, (0, 5), lambda p, t: p[:, 0]), "frame_shape: expected two"),
        (lambda: ParallaxAim(G, (5, 0), lambda p, t: p[:, 0]), "frame_shape: expected two"),
        (lambda: ParallaxAim(G, (2.5, 5), lambda p, t: p[:, 0]), "frame_shape: expected two"),
        (lambda: ParallaxAim(object(), SHAPE, lambda p, t: p[:, 0]), "got object"),
        (lambda: ParallaxAim(G, SHAPE, 5.0), "heights_m: expected a callable (points, t_s) -> heights, got float"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: p[:, 0], 3.0), "look_heights_m: expected a"),
        (lambda: ParallaxAim.constant(G, SHAPE, "high"), "height_m: expected metres, got"),
        (lambda: ParallaxAim.constant(G, SHAPE, 0.0), "expected metres > 0"),
        (lambda: ParallaxAim.constant(G, SHAPE, 2e5), "up to 100000"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: np.zeros(3)).shift([[1.0, 1.0]], 1.0),
         "heights_m: expected 1 heights"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: np.full(len(p), np.inf)).shift(
            [[1.0, 1.0]], 1.0), "heights_m: expected metres >= 0 (or NaN), got inf"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: np.array([0.0, -2.0])).shift(
            [[1.0, 1.0], [2.0, 2.0]], 1.0), "got -2.0"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: np.array([0.5, -2.0])).shift(
            [[1.0, 1.0], [2.0, 2.0]], 1.0), "got -2.0"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: np.ones(len(p)),
                             lambda p, t: np.full(len(p), -1.0)).shift([[1.0, 1.0]], 1.0),
         "look_heights_m: expected metres >= 0"),
        (lambda: _aim().shift([1.0, 1.0], 1.0), "points: expected an (N, 2) array"),
        (lambda: _aim().shift([[1.0, 1.0]], [1.0, 2.0]), "t_s: expected one time or 1 times"),
        (lambda: _aim().shift([[1.0, 1.0]], np.nan), "points, t_s: expected finite"),
        (lambda: _aim().shift([[np.inf, 1.0]], 1.0), "points, t_s: expected finite"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: p[:, 0], fill_px=-1.0),
         "fill_px: expected WFOV pixels >= 0, got -1.0"),
        (lambda: ParallaxAim(G, SHAPE, lambda p, t: p[:, 0], fill_px=math.nan),
         "fill_px: expected WFOV pixels >= 0"),
    ],
)  # fmt: skip
def test_bad_input_is_refused_in_one_line_naming_it(call, needle):
    with pytest.raises(InvalidParameterError) as err:
        call()
    assert needle in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "call",
    [
        lambda: ParallaxAim.constant(G, SHAPE, -1.0),
        lambda: ParallaxAim.constant(G, SHAPE, float("nan")),
        lambda: ParallaxAim.constant(G, SHAPE, 0.0),
        lambda: ParallaxAim.constant(G, SHAPE, float("inf")),
        lambda: ParallaxAim(G, (0, 5), lambda p, t: np.zeros(len(p))),
        lambda: ParallaxAim(G, SHAPE, 5.0),  # not callable
        lambda: ParallaxAim(G, SHAPE, lambda p, t: np.full(len(p), -5.0)).shift([[1.0, 1.0]], 1.0),
        lambda: ParallaxAim(G, SHAPE, lambda p, t: np.zeros(3)).shift([[1.0, 1.0]], 1.0),
        lambda: _aim().shift([[1.0, 1.0]], [1.0, 2.0]),
        lambda: _aim().shift([[np.nan, 1.0]], 1.0),
        lambda: _aim().shift([1.0, 1.0], 1.0),
        lambda: nadir_xy(G, SHAPE, float("inf")),
    ],
)
def test_bad_input_is_refused(call):
    with pytest.raises(InvalidParameterError):
        call()


def test_nadir_xy_by_hand():
    # at the acquisition the nadir is 500 km = 16,666.67 rows of 30 m behind the centre row 50
    x, y = nadir_xy(G, SHAPE, 0.0)
    assert (x, y) == pytest.approx((100.0, 50.0 + 500e3 / 30.0))
    # 500 km / 7062.3 m/s = 70.8 s later it is under the centre
    assert nadir_xy(G, SHAPE, 500e3 / G.ground_speed) == pytest.approx((100.0, 50.0))


# -- the schedule: each pointing moved for its own time --------------------------------------


def test_schedule_with_an_aim_moves_every_pointing_for_its_time():
    # unlimited agility flies every pointing when the plan starts: start_s = 70.8 s, the
    # nadir under the frame's centre, where a 10 km top seen at the centre truly lies
    # ~11.5 km behind
    t = 500e3 / G.ground_speed
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=t)
    along = [500e3, 490e3, 515e3]
    base = np.array([_pixel(a, 0.0) for a in along])
    traj = Trajectory(base, np.zeros(3), "demo")
    s = schedule_on_prediction(traj, SHAPE, g, "unlimited", None, aim=_aim())
    assert s.times.tolist() == [t, t, t]
    for j, i in enumerate(s.kept):
        want_a, _ = _vector_aim(along[i], 0.0, t)
        assert s.trajectory.points[j, 1] == pytest.approx(
            base[i, 1] - (want_a - along[i]) / GSD, abs=1e-4
        )
        assert s.trajectory.points[j, 0] == pytest.approx(base[i, 0], abs=1e-9)
    # the first round flies the plan as seen (the acquisition's time: no move), the second
    # at the times it found, which no longer change
    assert s.trajectory.params["parallax_iterations"] == 2
    assert s.trajectory.params["parallax_residual_px"] < 1e-9


def test_no_aim_is_the_old_path_exactly():
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=3.0)
    traj = Trajectory(np.array([[10.0, 10.0], [150.0, 80.0], [60.0, 5.0]]), np.zeros(3), "demo")
    a = schedule_on_prediction(traj, SHAPE, g, "slow", None, aim=None)
    b = make_feasible(traj, SHAPE, g, "slow")
    assert a.trajectory.points.tobytes() == b.trajectory.points.tobytes()
    assert a.times.tobytes() == b.times.tobytes() and a.trajectory.params == b.trajectory.params
    p = Prediction(Motion((0.5, 0.0)), 0.0)
    c = schedule_on_prediction(traj, SHAPE, g, "slow", p)
    d = schedule_on_prediction(traj, SHAPE, g, "slow", p, aim=None)
    assert c.trajectory.points.tobytes() == d.trajectory.points.tobytes()
    assert "parallax_iterations" not in d.trajectory.params


def test_prediction_and_aim_moves_add():
    t = 40.0
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=t)
    base = np.array([_pixel(500e3, 0.0), _pixel(505e3, 900.0)])
    traj = Trajectory(base, np.zeros(2), "demo")
    p = Prediction(Motion((0.0, -0.5)), 0.0)  # 0.5 px/s up the frame
    s = schedule_on_prediction(traj, SHAPE, g, "unlimited", p, aim=_aim())
    seen = base + np.array([0.0, -0.5 * t])  # where the plume is at t, as the look-ahead sees
    want = seen + _aim().shift(seen, t)
    assert s.trajectory.points == pytest.approx(want[s.kept], abs=1e-9)
    assert {"prediction_iterations", "parallax_iterations"} <= set(s.trajectory.params)


def test_kept_and_dropped_pointings_keep_their_own_times():
    # slow agility drops some pointings, and moving them (4.8 px/s here: a 10 km top seen
    # from 500 km up slides back at 10/490 of the ground speed) changes which fit and in
    # which order: the schedule still flies every kept pointing aimed for its own time
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=2.0)
    rng = np.random.default_rng(0)
    base = np.column_stack([rng.uniform(0, 200, 40), rng.uniform(0, 100, 40)])
    traj = Trajectory(base, np.zeros(40), "demo")

    def fly(t: Trajectory):
        return make_feasible(t, SHAPE, g, "slow")

    def in_order(t: Trajectory):
        return schedule(t, SHAPE, g, "slow")

    moved, s = iterate_on_prediction(traj, None, fly, aim=_aim(), in_order=in_order)
    assert len(moved) == 40 and 0 < len(s.kept) < 40 and s.planned == 40
    assert len(set(s.kept.tolist())) == len(s.kept)
    assert s.trajectory.points == pytest.approx(moved.points[s.kept], abs=0)
    want = base[s.kept] + _aim().shift(base[s.kept], s.times)
    gap = np.hypot(*(want - s.trajectory.points).T).max()
    assert gap == pytest.approx(s.trajectory.params["parallax_residual_px"], abs=1e-9)
    assert gap < 0.5  # within half a pixel of where the top is seen from there
    # the same through schedule_on_prediction (which knows how to fly in order)
    s2 = schedule_on_prediction(traj, SHAPE, g, "slow", None, aim=_aim())
    assert s2.trajectory.params["parallax_residual_px"] < 0.5
    with pytest.raises(InvalidParameterError, match="prediction"):
        iterate_on_prediction(traj, None, fly)


# -- the NFOV tracks the top it observed -------------------------------------------------
R_K = 6_371_000.0  # the sphere of dyntarget.schedule.kinematics


def _kin_point(along: float, cross: float, radius: float) -> np.ndarray:
    """The point of kinematics' map coordinates (along-track and cross-track central
    angles times the radius) on the sphere ``radius``, in the frame of the spacecraft at
    nadir at t = 0 (x along the track, z up)."""
    a, c = along / R_K, cross / R_K
    return radius * np.array([math.sin(a) * math.cos(c), math.sin(c), math.cos(a) * math.cos(c)])


def _kin_map(p: np.ndarray) -> tuple[float, float]:
    u = p / np.linalg.norm(p)
    return R_K * math.atan2(u[0], u[2]), R_K * math.asin(u[1])


def _kin_top(along: float, cross: float, t: float, height: float) -> np.ndarray:
    """The point ``height`` up on the ray from the spacecraft at ``t`` to a ground point."""
    g = G.ground_speed * t / R_K
    s = (R_K + H_SC) * np.array([math.sin(g), 0.0, math.cos(g)])
    return _ray_hits_sphere(s, _kin_point(along, 0.0, R_K) if cross == 0 else
                            _kin_point(along, cross, R_K), R_K + height)  # fmt: skip


def _kin_aim(top: np.ndarray, t: float) -> tuple[float, float]:
    """The ground point on the ray from the spacecraft at ``t`` through ``top``."""
    g = G.ground_speed * t / R_K
    s = (R_K + H_SC) * np.array([math.sin(g), 0.0, math.cos(g)])
    return _kin_map(_ray_hits_sphere(s, top, R_K))


@pytest.mark.parametrize(
    ("along", "cross", "t", "height"),
    [(500e3, 0.0, 0.0, 10e3), (300e3, 40e3, 12.0, 15e3), (60e3, -5e3, 30.0, 2e3)],
)
def test_under_sight_is_where_the_ray_meets_the_tops_sphere(along, cross, t, height):
    from dyntarget.schedule.kinematics import under_sight

    # by vectors: the ray from the spacecraft at t to the ground point, met at R + height
    want = _kin_map(_kin_top(along, cross, t, height))
    got = under_sight(G, along, cross, t, height)
    assert got == pytest.approx(want, abs=1e-3)  # millimetres
    # 10 km up, 500 km ahead, from 500 km: 11.2 km nearer (the 2D vector sum in the docstring)
    if height == 10e3:
        assert (along - got[0]) / 1e3 == pytest.approx(11.22, abs=0.01)


def _one_top_twice(t1: float, t2: float) -> tuple[Trajectory, float, float]:
    """A 10 km top whose line of sight at ``t1`` meets the ground 450 km ahead of the
    nadir at t = 0: two pointings at it, aimed for ``t1`` and ``t2`` (the ground points
    those lines of sight meet, by vectors), and the two aims' along-track distances."""
    top = _kin_top(450e3, 0.0, t1, H_TOP)
    (a1, c1), (a2, c2) = _kin_aim(top, t1), _kin_aim(top, t2)
    pts = np.array([_pixel(a1, c1), _pixel(a2, c2)])
    heights = np.array([H_TOP, H_TOP])
    return Trajectory(pts, np.zeros(2), "demo", {}, np.array([t1, t2]), heights), a1, a2


def test_a_sensor_tracks_the_top_it_observed_not_the_ground_behind_it():
    # Two pointings at one 10 km top, aimed for 40 s and 41.1 s: their lines of sight meet
    # the ground ~170 m apart (the aim moves back as the spacecraft comes nearer). The
    # NFOV tracks the top it observed, so the second needs no slew: it follows the first
    # after the dwell and the settling alone (slow: 0.1 + 1.0 s). Tracking the ground
    # point behind the top instead, it must slew by the angle between the two aims.
    t1, t2 = 40.0, 41.1
    traj, a1, a2 = _one_top_twice(t1, t2)
    assert a1 == pytest.approx(450e3, abs=1e-3) and 150.0 < a1 - a2 < 200.0
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=t1)
    s = schedule(traj, SHAPE, g, "slow")
    # (the two tops, each from its pixel and time, agree to about a centimetre; a slew
    # that small takes milliseconds, 2 sqrt(phi / a))
    assert len(s.kept) == 2 and s.times[1] - s.times[0] == pytest.approx(1.1, abs=5e-3)
    assert s.trajectory.heights.tolist() == [H_TOP, H_TOP] and s.end_height_m == H_TOP
    # the same pointings as ground points: a slew of ~0.016 deg, 2 sqrt(phi / 0.5) ~ 0.36 s
    ground = schedule(Trajectory(traj.points, traj.part, "demo"), SHAPE, g, "slow")
    assert ground.times[1] - ground.times[0] > 1.1 + 0.15 and ground.end_height_m == 0.0


def test_a_sensor_handed_over_between_frames_keeps_tracking_the_top():
    # SensorState's height_m: a pass's next frame starts from the top the last one
    # observed (the sensor free at 41.1 s, tracking it): aimed at that top again, the
    # observation starts after the settling alone
    from dyntarget.schedule.kinematics import under_sight

    t1, t2 = 40.0, 41.1
    traj, a1, _ = _one_top_twice(t1, t2)
    under = under_sight(G, a1, 0.0, t1, H_TOP)  # the top's ground position
    assert under == pytest.approx(_kin_map(_kin_top(450e3, 0.0, t1, H_TOP)), abs=1e-3)
    second = traj.without(np.array([True, False]))
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=t2)
    s = schedule(second, SHAPE, g, "slow", sensor=SensorState(t2, under, H_TOP))
    assert s.times.tolist() == [pytest.approx(t2 + 1.0, abs=1e-6)]  # the settling alone
    ground = schedule(second, SHAPE, g, "slow", sensor=SensorState(t2, under))
    assert ground.times[0] > t2 + 1.0 + 0.1  # from the ground under the top: a slew


def test_heights_without_the_times_they_were_aimed_for_are_refused():
    with pytest.raises(InvalidParameterError, match="heights: expected the times"):
        Trajectory(np.zeros((1, 2)), np.zeros(1), "demo", heights=np.array([1e3]))
    with pytest.raises(InvalidParameterError, match="heights: expected 1 finite"):
        Trajectory(np.zeros((1, 2)), np.zeros(1), "demo", {}, np.zeros(1), np.array([-1.0]))


def test_a_schedule_with_an_aim_flies_its_pointings_at_their_tops_height():
    # two pointings planned on one 10 km top (ParallaxAim.constant), flown one after the
    # other: each aimed for its own time, at the same top, so the second follows the
    # first after the dwell and the settling alone (slow: 1.1 s)
    t = 40.0
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=t)
    base = np.array([_pixel(500e3, 0.0), _pixel(500e3, 0.0)])
    s = schedule_on_prediction(Trajectory(base, np.zeros(2), "demo"), SHAPE, g, "slow", None,
                               aim=_aim())  # fmt: skip
    assert s.trajectory.heights.tolist() == [H_TOP, H_TOP]
    assert s.times[1] - s.times[0] == pytest.approx(1.1, abs=1e-6)


# -- windows: a pointing flown only while the height it is aimed with is known ------------


def _known(windows: list[list[float]]):
    """``known_s`` giving each pointing its own row of ``windows``."""

    def known_s(points: np.ndarray) -> np.ndarray:
        return np.array(windows, np.float64)[: len(points)]

    return known_s


def test_a_pointing_waits_for_its_window_to_open_even_without_limits():
    # unlimited agility: every pointing when the sensor is free (3 s), unless its window
    # opens later (5 s); the one after it is taken then too (no dwell without limits)
    traj = Trajectory(np.array([[8.0, 8.0], [9.0, 8.0]]), np.zeros(2), "demo", {}, None, None,
                      np.array([[5.0, np.inf], [-np.inf, np.inf]]))  # fmt: skip
    s = schedule(traj, (16, 16), OrbitGeometry(), "unlimited", sensor=SensorState(3.0))
    assert s.times.tolist() == [5.0, 5.0]
    assert s.trajectory.windows.tolist() == [[5.0, math.inf], [-math.inf, math.inf]]


@pytest.mark.parametrize("agility", ["unlimited", "slow", "fast"])
def test_a_pointing_whose_window_never_opens_is_not_flown(agility):
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=40.0)
    base = np.array([_pixel(500e3, 0.0), _pixel(500e3, 3e3)])
    traj = Trajectory(
        base, np.zeros(2), "demo", windows=np.array([[np.inf, np.inf], [0.0, np.inf]])
    )
    s = schedule(traj, SHAPE, g, agility)
    assert s.kept.tolist() == [1]


def test_a_slow_sensor_waits_for_the_window_tracking_its_last_target():
    # slow agility: the first pointing is taken on arrival from nadir (about 50 s); the
    # second, at the same ground point, would follow 1.1 s later (dwell and settle) but
    # its window opens at 60 s: it starts exactly then
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=40.0)
    base = np.array([_pixel(500e3, 0.0), _pixel(500e3, 0.0)])
    free = schedule(Trajectory(base, np.zeros(2), "demo"), SHAPE, g, "slow")
    assert free.times[0] < 55.0 and free.times[1] - free.times[0] == pytest.approx(1.1, abs=1e-6)
    held = schedule(
        Trajectory(base, np.zeros(2), "demo", windows=np.array([[-np.inf, np.inf], [60.0, np.inf]])),
        SHAPE, g, "slow",
    )  # fmt: skip
    assert held.times[0] == free.times[0] and held.times[1] == 60.0


def test_a_pointing_that_cannot_end_before_its_window_closes_is_dropped():
    # slow: a pointing dwells 0.1 s; a window closing 0.05 s after the sensor could
    # start leaves too little time, one closing 0.2 s after enough
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=40.0)
    base = np.array([_pixel(500e3, 0.0)])
    start = schedule(Trajectory(base, np.zeros(1), "demo"), SHAPE, g, "slow").times[0]
    for until, kept in ((start + 0.05, []), (start + 0.2, [0])):
        traj = Trajectory(base, np.zeros(1), "demo", windows=np.array([[-np.inf, until]]))
        assert schedule(traj, SHAPE, g, "slow").kept.tolist() == kept


def test_bad_windows_are_refused_in_one_line():
    with pytest.raises(InvalidParameterError, match=r"windows: expected \(1, 2\)"):
        Trajectory(np.zeros((1, 2)), np.zeros(1), "demo", windows=np.zeros((1, 3)))
    with pytest.raises(InvalidParameterError, match="windows: .* not NaN"):
        Trajectory(np.zeros((1, 2)), np.zeros(1), "demo", windows=np.array([[np.nan, 1.0]]))
    aim = ParallaxAim(G, SHAPE, _aim().heights_m, known_s=_known([[5.0, 4.0]]))
    with pytest.raises(InvalidParameterError, match="known_s: a window ends before it starts"):
        aim.windows(np.zeros((1, 2)))
    aim = ParallaxAim(G, SHAPE, _aim().heights_m, known_s=_known([[5.0, 6.0, 7.0]]))
    with pytest.raises(InvalidParameterError, match=r"known_s: expected \(1, 2\) windows"):
        aim.windows(np.zeros((1, 2)))
    with pytest.raises(InvalidParameterError, match="known_s: expected a callable"):
        ParallaxAim(G, SHAPE, _aim().heights_m, known_s=3.0)


def test_a_pointing_on_no_plume_waits_with_its_neighbour_within_fill_px_only():
    aim = ParallaxAim(G, SHAPE, _aim().heights_m, fill_px=2.0,
                      known_s=_known([[20.0, 30.0], [np.nan, np.nan], [np.nan, np.nan]]))  # fmt: skip
    w = aim.windows(np.array([[10.0, 10.0], [11.5, 10.0], [12.0, 10.0]]))
    # 1.5 px away: its neighbour's window; 2 px: not strictly nearer than fill_px, any time
    assert w.tolist() == [[20.0, 30.0], [20.0, 30.0], [-math.inf, math.inf]]
    assert ParallaxAim(G, SHAPE, _aim().heights_m).windows(np.zeros((1, 2))) is None


def test_a_held_pointing_is_aimed_for_the_time_its_window_opens():
    # the plan is ready at 40 s, but the 10 km top's height is known only from 70.8 s,
    # when the nadir is under its true position: the NFOV (no limits) waits, and then
    # looks straight down at it, ~11.5 km behind where the look-ahead saw it (the vector
    # method), not where it would have aimed at 40 s
    t = 500e3 / G.ground_speed
    g = OrbitGeometry(altitude_m=H_SC, look_ahead_m=500e3, wfov_gsd_m=GSD, start_s=40.0)
    base = np.array([_pixel(500e3, 0.0), _pixel(500e3, 3e3)])
    aim = ParallaxAim(G, SHAPE, _aim().heights_m, known_s=_known([[t, np.inf], [np.inf, np.inf]]))
    s = schedule_on_prediction(Trajectory(base, np.zeros(2), "demo"), SHAPE, g, "unlimited",
                               None, aim=aim)  # fmt: skip
    assert s.kept.tolist() == [0] and s.times.tolist() == [t]
    want_a, _ = _vector_aim(500e3, 0.0, t)
    assert s.trajectory.points[0, 1] == pytest.approx(base[0, 1] - (want_a - 500e3) / GSD, abs=1e-4)
    assert 380 < s.trajectory.points[0, 1] - base[0, 1] < 387
    assert s.trajectory.params["parallax_residual_px"] < 1e-9


def test_windows_refuse_bad_points_and_name_the_bad_window():
    aim = ParallaxAim(G, SHAPE, _aim().heights_m, known_s=_known([[3.0, 3.0], [5.0, 4.0]]))
    for bad in (np.array([[np.nan, 1.0]]), np.zeros((1, 3)), np.zeros(2)):
        with pytest.raises(InvalidParameterError, match=r"points: expected an \(N, 2\) array"):
            aim.windows(bad)
    # a window of no length is allowed; the one ending before it starts is named
    with pytest.raises(InvalidParameterError, match=r"starts: \[5\.0, 4\.0\]"):
        aim.windows(np.zeros((2, 2)))
    with pytest.raises(InvalidParameterError, match="heights_m: expected a callable"):
        ParallaxAim(G, SHAPE, None)


def test_windows_are_seconds_even_from_whole_numbers():
    aim = ParallaxAim(G, SHAPE, _aim().heights_m, known_s=lambda p: [[5, 10]] * len(p))
    w = aim.windows([[1, 2]])
    assert w.dtype == np.float64 and w.tolist() == [[5.0, 10.0]]


def test_a_pointing_on_no_plume_takes_the_window_of_its_nearest_plume_pointing():
    # two plumes' pointings, known from 20 s and from 40 s; a pointing on neither, 0.5 px
    # from the second (fill_px 0.9: strictly nearer), waits with the second
    aim = ParallaxAim(G, SHAPE, _aim().heights_m, fill_px=0.9,
                      known_s=_known([[20.0, np.inf], [40.0, np.inf], [np.nan, np.nan]]))  # fmt: skip
    w = aim.windows(np.array([[10.0, 10.0], [12.0, 10.0], [12.5, 10.0]]))
    assert w.tolist() == [[20.0, math.inf], [40.0, math.inf], [40.0, math.inf]]


def test_a_pointing_off_every_plume_belongs_to_its_nearest_neighbours_plume_within_fill_px():
    # plume_of, by hand. Pointings at x = 0, 0.6, 3, 5 and 9 (one row): plume 1 under the
    # first (index 0), plume 7 under the fourth, none under the others. Within 1 px the
    # second (0.6 px from the first) joins plume 1; the third (3 px from the first, 2 px
    # from the fourth) and the fifth (4 px from the fourth) join none. Within 2.5 px the
    # third joins plume 7 (2 px, nearer than plume 1's 3 px); the fifth still none
    from dyntarget.schedule.aim import plume_of

    pts = np.array([[0.0, 4.0], [0.6, 4.0], [3.0, 4.0], [5.0, 4.0], [9.0, 4.0]])
    ids = np.array([1, 0, 0, 7, 0], np.int32)  # a frame's plume-id map is int32
    got = plume_of(pts, ids, 1.0)
    assert got.tolist() == [1, 1, 0, 7, 0] and got.dtype == np.int64
    assert plume_of(pts, ids, 2.5).tolist() == [1, 1, 7, 7, 0]
    assert plume_of(pts, ids, 2.0).tolist() == [1, 1, 0, 7, 0]  # 2 px: not strictly nearer
    assert plume_of(pts, ids, 0.0).tolist() == [1, 0, 0, 7, 0]  # 0: none takes another's
    assert plume_of(pts, np.zeros(5, np.int32), 9.0).tolist() == [0] * 5  # no plume at all
    assert plume_of(pts, np.ones(5, np.int32), 9.0).tolist() == [1] * 5
