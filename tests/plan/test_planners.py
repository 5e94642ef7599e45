"""Planner contract (every registered planner) and hand-checked geometry."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from affine import Affine
from shapely.geometry import Point, Polygon

from dyntarget import InvalidParameterError, UnknownNameError
from dyntarget.denoise import denoise
from dyntarget.masks import mask_to_polygons
from dyntarget.plan import (
    BASELINES,
    PAPER_PLANNERS,
    PlanConfig,
    Trajectory,
    geometric_planners,
    plan,
)
from dyntarget.plan.geometry import chord, major_axis, sample_polyline

NAMES = geometric_planners()
LOOKAHEAD = [n for n in NAMES if n not in BASELINES]


def rect_mask(h=100, w=100, rows=(40, 60), cols=(10, 90)):
    m = np.zeros((h, w), bool)
    m[rows[0] : rows[1], cols[0] : cols[1]] = True
    return m


def ellipse_mask(angle_deg, h=200, w=200, a=70, b=18):
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    t = np.radians(angle_deg)
    x, y = xx - w / 2, yy - h / 2
    u = x * np.cos(t) + y * np.sin(t)
    v = -x * np.sin(t) + y * np.cos(t)
    return (u / a) ** 2 + (v / b) ** 2 <= 1


def test_registry_names():
    paper = [
        "trace-outline",
        "track-center",
        "diagonal-transect",
        "lawnmower-transect",
        "straight-nadir",
        "naive-transect",
    ]
    assert list(PAPER_PLANNERS) == paper
    assert NAMES == [*paper, "track-centerline"]  # the paper's first, then ours
    with pytest.raises(UnknownNameError, match="expected one of: trace-outline"):
        plan("spiral", rect_mask())


@pytest.mark.parametrize("name", NAMES)
def test_contract_empty_mask(name):
    t = plan(name, np.zeros((50, 60), bool))
    assert isinstance(t, Trajectory) and t.planner == name
    if name in BASELINES:
        assert len(t) > 0
    else:
        assert len(t) == 0


@pytest.mark.parametrize("name", NAMES)
def test_contract_rectangle(name):
    m = rect_mask()
    t = plan(name, m)
    assert len(t) > 0
    assert t.points.dtype == np.float64 and t.points.shape[1] == 2
    assert np.isfinite(t.points).all()
    h, w = m.shape
    assert (t.points[:, 0] >= 0).all() and (t.points[:, 0] <= w - 1).all()
    assert (t.points[:, 1] >= 0).all() and (t.points[:, 1] <= h - 1).all()
    if name not in BASELINES:  # look-ahead points lie inside the plume or on its boundary
        poly = Polygon([(10, 40), (89, 40), (89, 59), (10, 59)])
        assert all(poly.buffer(1e-6).covers(Point(p)) for p in t.points)
    # ordered: consecutive points within a part are at most one step apart (plus rounding)
    step = t.params["step"]
    gaps = np.hypot(*np.diff(t.points, axis=0).T)[np.diff(t.part) == 0]
    assert gaps.max() <= step + 1e-6
    # deterministic
    again = plan(name, m)
    np.testing.assert_array_equal(again.points, t.points)


def test_rectangle_major_axis_by_hand():
    (poly,) = mask_to_polygons(rect_mask())
    centre, u = major_axis(poly)
    np.testing.assert_allclose(centre, [49.5, 49.5], atol=1e-6)
    np.testing.assert_allclose(u, [1.0, 0.0], atol=1e-9)
    t = plan("track-center", rect_mask())
    np.testing.assert_allclose(t.points[:, 1], 49.5)
    assert t.points[0, 0] == pytest.approx(10.0) and t.points[-1, 0] == pytest.approx(89.0)


@pytest.mark.parametrize("angle", [0, 30, 67, 120])
def test_rotated_ellipse_lawnmower_perpendicular_within_1_degree(angle):
    m = ellipse_mask(angle)
    (poly,) = mask_to_polygons(m)
    _, u = major_axis(poly)
    axis_deg = np.degrees(np.arctan2(u[1], u[0])) % 180
    assert min(abs(axis_deg - angle % 180), 180 - abs(axis_deg - angle % 180)) < 1.0
    t = plan("lawnmower-transect", m, config=PlanConfig(step=2.0))
    d = np.diff(t.points, axis=0)
    d = d[np.hypot(*d.T) > 1.9]  # steps along transects (not the short joins)
    cosang = np.abs(d @ u) / np.hypot(*d.T)
    # most steps run perpendicular to the axis (the straight joins between transects are the rest)
    perpendicular = np.degrees(np.arccos(np.clip(cosang, 0, 1))) > 89.0
    assert perpendicular.mean() > 0.85


def test_lawnmower_transects_spaced_by_width():
    m = rect_mask()
    t = plan("lawnmower-transect", m, config=PlanConfig(step=1.0, width=4.0))
    xs = np.unique(np.round(t.points[:, 0], 6))
    # transect positions: x where many points share the same x (the transects run along y)
    counts = np.array([(np.abs(t.points[:, 0] - x) < 1e-6).sum() for x in xs])
    positions = xs[counts >= 10]
    np.testing.assert_allclose(np.diff(positions), 4.0, atol=1.0)


def test_outline_points_spaced_by_step():
    m = rect_mask()
    t = plan("trace-outline", m, config=PlanConfig(step=3.0))
    (poly,) = mask_to_polygons(m)
    ring = poly.exterior
    s = np.array([ring.project(Point(p)) for p in t.points])
    gaps = np.diff(s) % ring.length
    np.testing.assert_allclose(gaps, 3.0, atol=1e-6)
    assert all(ring.distance(Point(p)) < 1e-6 for p in t.points)


def test_diagonal_is_a_zigzag_alternating_sides():
    # rect_mask: the polygon through the pixel centres spans x 10..89 (axis) and y 40..59 (sides)
    m = rect_mask()
    t = plan("diagonal-transect", m, config=PlanConfig(step=1.0, width=4.0))
    x, y = t.points[:, 0], t.points[:, 1]
    # x (the axis) advances monotonically
    assert np.all(np.diff(x) * np.sign(x[-1] - x[0]) >= -1e-9)
    # y runs from one long side to the other and back: its turning points alternate between
    # y = 40 and y = 59 (within a step, as the path is sampled every step)
    dy = np.diff(y)
    turns = np.flatnonzero(np.sign(dy[1:]) != np.sign(dy[:-1])) + 1
    corners = [0, *turns, len(y) - 1]
    sides = [59 if y[i] > 49.5 else 40 for i in corners]
    assert all(abs(y[i] - side) <= 1.0 for i, side in zip(corners, sides, strict=True))
    assert all(a != b for a, b in itertools.pairwise(sides))  # never the same side twice
    # by hand: the 79 px extent holds ceil(79 / 4) = 20 stations, so 19 diagonal legs
    assert len(sides) == 20
    # each leg advances one station spacing (79 / 20 px) along the axis
    legs = np.diff(x[corners])
    np.testing.assert_allclose(np.abs(legs), 79 / 20, atol=1.0)


def test_transect_stations_centred_with_count_rounded_up():
    # rect_mask's axis extent is x = 10..89 (79 px): with width 4, ceil(79 / 4) = 20 stations
    # spaced 79 / 20 = 3.95 px, the first and the last 3.95 / 2 px in from the ends
    m = rect_mask()
    t = plan("lawnmower-transect", m, config=PlanConfig(step=1.0, width=4.0))
    xs = np.unique(np.round(t.points[:, 0], 6))
    counts = np.array([(np.abs(t.points[:, 0] - x) < 1e-6).sum() for x in xs])
    positions = xs[counts >= 10]  # the transects run along y
    np.testing.assert_allclose(positions, 10 + 3.95 * (np.arange(20) + 0.5), atol=1e-9)


def test_trace_outline_skips_the_image_frame():
    # a band along the top edge: rows 0..9, columns 20..79 of a 100 x 100 image; its polygon
    # runs along the frame (y = 0) for 59 px, which is the image's edge, not the plume's
    m = np.zeros((100, 100), bool)
    m[0:10, 20:80] = True
    t = plan("trace-outline", m, config=PlanConfig(step=1.0))
    assert (t.points[:, 1] > 0).all()  # nothing on the frame
    # by hand: the ring is 2 * (59 + 9) = 136 px long; the 59 px on the frame are skipped
    assert len(t) == 136 - 59
    # the two sides and the bottom are all still traced (x = 20 and x = 79, y = 9)
    assert np.isclose(t.points[:, 0], 20).sum() >= 8 and np.isclose(t.points[:, 0], 79).sum() >= 8
    assert np.isclose(t.points[:, 1], 9).sum() >= 59
    # a plume clear of the frame is traced whole, in one part
    inner = plan("trace-outline", rect_mask(), config=PlanConfig(step=1.0))
    assert len(inner) == 2 * (79 + 19) and set(inner.part.tolist()) == {0}


def _nearest_next_by_brute_force(polygons, start, ends):
    """The plain loop: every unvisited exterior's distance at each step (the reference)."""
    remaining, position, order = list(range(len(polygons))), start, []
    while remaining:
        d = [polygons[i].exterior.distance(Point(*position)) for i in remaining]
        j = remaining.pop(int(np.argmin(d)))
        order.append(j)
        position = ends[j]
    return order


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nearest_next_order_equals_brute_force(seed):
    from dyntarget.plan.planners import _NearestNext, start_point

    rng = np.random.default_rng(seed)
    m = np.zeros((120, 120), bool)
    for _ in range(60):  # specks, bars and blocks of several sizes, some overlapping
        r, c = rng.integers(0, 118, 2)
        h, w = rng.integers(1, 12, 2)
        m[r : r + h, c : c + w] = True
    polygons = mask_to_polygons(m)
    assert len(polygons) > 20
    ends = [np.array(p.exterior.coords[0]) for p in polygons]
    order, position = [], start_point(m.shape)
    walk = _NearestNext(polygons)
    while walk.remaining:
        j = walk.take(position)
        order.append(j)
        position = ends[j]
    assert order == _nearest_next_by_brute_force(polygons, start_point(m.shape), ends)


def test_nearest_next_ties_go_to_the_largest():
    from dyntarget.plan.planners import _NearestNext

    # two squares at the same distance (1 px) from (50, 50): the larger one (index 0) first
    big = Polygon([(51, 40), (70, 40), (70, 60), (51, 60)])
    small = Polygon([(45, 49), (49, 49), (49, 51), (45, 51)])
    walk = _NearestNext([big, small])
    assert walk.take(np.array([50.0, 50.0])) == 0 and walk.take(np.array([50.0, 50.0])) == 1
    assert walk.remaining == 0


def test_several_polygons_nearest_next_with_travel():
    m = np.zeros((100, 100), bool)
    m[80:90, 40:60] = True  # near the start (bottom centre)
    m[5:15, 5:25] = True  # far top-left
    m[5:15, 75:95] = True  # far top-right
    t = plan("track-center", m)
    parts = [t.points[t.part == p] for p in np.unique(t.part)]
    assert len(parts) == 3
    assert parts[0][:, 1].mean() > 50  # the bottom plume first
    assert t.travel_length > 0
    # travel hops are not sampled: a hop is longer than a step
    hops = np.hypot(*np.diff(t.points, axis=0).T)[np.diff(t.part) != 0]
    assert (hops > t.params["step"]).all()


def test_step_default_is_one_percent_of_width_and_width_twice_step():
    t = plan("lawnmower-transect", rect_mask(w=200))
    assert t.params["step"] == pytest.approx(2.0) and t.params["width"] == pytest.approx(4.0)


def test_baselines_ignore_the_plume():
    a = plan("naive-transect", rect_mask())
    b = plan("naive-transect", np.zeros((100, 100), bool))
    np.testing.assert_array_equal(a.points, b.points)
    nadir = plan("straight-nadir", rect_mask())
    np.testing.assert_allclose(nadir.points[:, 0], 49.5)
    assert nadir.points[0, 1] == 99 and nadir.points[-1, 1] == 0 and len(nadir) == 100


@pytest.mark.slow
def test_curved_plume_behaviour_recorded():
    """A banana-shaped plume: the straight major axis cuts across the bend.

    Recorded behaviour: track-center's straight chord leaves the plume in the
    middle of the bend (a good share of its points fall outside), while the
    outline stays on the boundary and the transects still cross plume pixels
    because they run to the farthest boundary points on each line.
    """
    yy, xx = np.mgrid[0:200, 0:200].astype(float)
    r = np.hypot(xx - 100, yy - 180)
    m = (np.abs(r - 120) < 12) & (yy < 150)  # an arc of a ring
    (poly,) = mask_to_polygons(m)
    inside = {}
    for name in LOOKAHEAD:
        t = plan(name, m, config=PlanConfig(step=2.0))
        inside[name] = np.mean([poly.buffer(0.5).covers(Point(p)) for p in t.points])
    assert inside["trace-outline"] == 1.0
    assert inside["track-center"] < 0.6  # the straight axis misses the bend
    assert inside["lawnmower-transect"] > inside["track-center"]


def test_chord_concave_takes_first_entry_last_exit():
    u_shape = Polygon([(0, 0), (10, 0), (10, 10), (7, 10), (7, 3), (3, 3), (3, 10), (0, 10)])
    lo, hi = chord(u_shape, np.array([5.0, 8.0]), np.array([1.0, 0.0]))
    assert (lo, hi) == (-5.0, 5.0)
    assert chord(u_shape, np.array([5.0, 20.0]), np.array([1.0, 0.0])) is None


def test_sample_polyline_by_hand():
    pts = sample_polyline(np.array([[0, 0], [3, 0], [3, 2]]), 1.0)
    np.testing.assert_allclose(pts, [[0, 0], [1, 0], [2, 0], [3, 0], [3, 1], [3, 2]])
    np.testing.assert_allclose(sample_polyline(np.array([[1, 1]]), 1.0), [[1, 1]])


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"step": 0}, "step"),
        ({"step": -1.0}, "step"),
        ({"width": float("nan")}, "width"),
        ({"step_fraction": 2}, "step_fraction"),
        ({"step_fraction": 0}, "step_fraction"),
        ({"naive_fraction": 0}, "naive_fraction"),
        ({"naive_fraction": 1.5}, "naive_fraction"),
    ],
)
def test_config_validation(kw, match):
    with pytest.raises(InvalidParameterError, match=match):
        PlanConfig(**kw)


def test_trajectory_export_pixel_and_crs(tmp_path):
    t = plan("track-center", rect_mask())
    doc = json.loads(t.save(tmp_path / "t.geojson").read_text())
    assert doc["features"][0]["geometry"]["type"] == "LineString"
    points = [f for f in doc["features"] if f["geometry"]["type"] == "Point"]
    assert [f["properties"]["order"] for f in points] == list(range(len(t)))
    assert points[0]["geometry"]["coordinates"] == [10.0, 49.5]
    assert "pixel" in doc["properties"]["coordinates"]
    transform = Affine(8.0, 0, 240000.0, 0, -8.0, 2160000.0)
    geo = t.to_geojson(transform=transform, crs="EPSG:32605", crs_mode="native")
    assert geo["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32605"
    x, y = geo["features"][1]["geometry"]["coordinates"]
    assert (x, y) == (240000.0 + 8 * 10.5, 2160000.0 - 8 * 50.0)
    rfc = t.to_geojson(transform=transform, crs="EPSG:32605")  # the default: WGS 84 lon/lat
    assert "crs" not in rfc
    lon, lat = rfc["features"][1]["geometry"]["coordinates"]
    assert -156.0 < lon < -155.0 and 19.0 < lat < 20.0  # UTM 5N, near Kilauea
    csv = t.save(tmp_path / "t.csv", transform=transform, crs="EPSG:32605").read_text()
    csv = csv.splitlines()
    assert csv[0] == "order,x,y,part,lon,lat" and len(csv) == len(t) + 1
    with pytest.raises(InvalidParameterError, match="must end in"):
        t.save(tmp_path / "t.txt")


def test_trajectory_rejects_nan():
    with pytest.raises(InvalidParameterError, match="NaN"):
        Trajectory(np.array([[np.nan, 1.0]]), np.array([0]), "x")


def _shapely_chord(poly, origin, direction):
    """The straightforward implementation: intersect a long line with the polygon in shapely."""
    import shapely
    from shapely.geometry import LineString

    minx, miny, maxx, maxy = poly.bounds
    reach = np.hypot(maxx - minx, maxy - miny) + np.hypot(*(origin - [minx, miny])) + 1.0
    inter = poly.intersection(LineString([origin - reach * direction, origin + reach * direction]))
    coords = shapely.get_coordinates(inter)
    if inter.is_empty or len(coords) == 0:
        return (np.nan, np.nan)
    t = (coords - origin) @ direction
    return (t.min(), t.max())


def test_vectorised_chords_equal_shapely_intersection():
    from dyntarget.denoise import denoise
    from dyntarget.plan.geometry import chords
    from dyntarget.synth import generate_scene

    polygons = [Polygon([(0, 0), (10, 0), (10, 10), (7, 10), (7, 3), (3, 3), (3, 10), (0, 10)])]
    for i in range(4):
        polygons += denoise(generate_scene(0, i, size=128)[0].label).polygons
    for poly in polygons:
        centre, u = major_axis(poly)
        v = np.array([-u[1], u[0]])
        origins = centre + np.linspace(-80, 80, 41)[:, None] * u
        ours = chords(poly, origins, v)
        ref = np.array([_shapely_chord(poly, o, v) for o in origins])
        np.testing.assert_array_equal(np.isnan(ours[:, 0]), np.isnan(ref[:, 0]))
        np.testing.assert_allclose(ours, ref, atol=1e-9)


def test_ring_interpolation_equals_shapely():
    import shapely

    from dyntarget.denoise import denoise
    from dyntarget.plan.geometry import interpolate_ring
    from dyntarget.synth import generate_scene

    for poly in denoise(generate_scene(0, 5, size=128)[0].label).polygons:
        ring = poly.exterior
        s = np.linspace(0, ring.length, 97, endpoint=False)
        ref = shapely.get_coordinates(shapely.line_interpolate_point(ring, s))
        np.testing.assert_allclose(interpolate_ring(np.asarray(ring.coords), s), ref, atol=1e-9)


def _band(centre_y):
    """A plume band 10 px wide whose centreline is ``centre_y(x)`` for x in 10..117."""
    yy, xx = np.mgrid[:128, :128]
    return (np.abs(yy - centre_y(xx)) < 5) & (xx > 10) & (xx < 118)


def test_centerline_of_a_straight_plume_is_its_axis():
    mask = _band(lambda x: 64.5 + 0 * x)
    cleaned = denoise(mask)
    straight = plan("track-center", cleaned.mask, cleaned.polygons).points
    curved = plan("track-centerline", cleaned.mask, cleaned.polygons).points
    assert np.abs(curved[:, 1] - 64.5).max() < 0.05
    np.testing.assert_allclose(curved[[0, -1]], straight[[0, -1]], atol=0.05)


@pytest.mark.parametrize("amplitude", [10, 20])
def test_centerline_follows_a_curved_plume(amplitude):
    mask = _band(lambda x: 64 + amplitude * np.sin(2 * np.pi * (x - 10) / 160))
    cleaned = denoise(mask)
    inside = {}
    for name in ("track-center", "track-centerline"):
        traj = plan(name, cleaned.mask, cleaned.polygons)
        rows = np.round(traj.points[:, 1]).astype(int)
        cols = np.round(traj.points[:, 0]).astype(int)
        inside[name] = mask[rows, cols].mean()
    assert inside["track-centerline"] == 1.0  # every pointing on the plume
    assert inside["track-center"] < 0.85  # the straight axis cuts across the bend


def test_major_axis_orientation_and_degenerate_by_hand():
    # a thin rectangle along the direction (-1, 2): its axis is +-(-1, 2) / sqrt(5); the sign is
    # chosen so the larger component (y) is positive
    d = np.array([-1.0, 2.0]) / np.sqrt(5.0)
    n = np.array([d[1], -d[0]])
    corners = [
        c + s * 30 * d + t * 3 * n
        for c in [np.zeros(2)]
        for s, t in ((-1, -1), (1, -1), (1, 1), (-1, 1))
    ]
    centre, u = major_axis(Polygon(corners))
    np.testing.assert_allclose(u, d, atol=1e-9)
    np.testing.assert_allclose(centre, [0.0, 0.0], atol=1e-9)
    # a square has no preferred axis: x by convention
    _, u = major_axis(Polygon([(0, 0), (10, 0), (10, 10), (0, 10)]))
    np.testing.assert_array_equal(u, [1.0, 0.0])


def test_centerline_stations_of_a_rectangle_by_hand():
    from dyntarget.plan.geometry import centerline

    # rect_mask's polygon spans x 10..89 at y 40..59; spacing 4: floor(79 / 4) = 19 stations at
    # 10 + (k + 0.5) * 79 / 19 on the axis y = 49.5, plus the two tips on the boundary
    (poly,) = mask_to_polygons(rect_mask())
    line = centerline(poly, spacing=4.0)
    expected_x = [10.0, *(10 + (np.arange(19) + 0.5) * 79 / 19), 89.0]
    np.testing.assert_allclose(line[:, 0], expected_x, atol=1e-9)
    np.testing.assert_allclose(line[:, 1], 49.5, atol=1e-9)


def test_centerline_keeps_a_parabolic_bend():
    from dyntarget.plan.geometry import centerline

    # a band 10 px wide whose centre is the parabola y = 50 + 0.01 (x - 50)^2 for x in 0..100;
    # the chord midpoints lie on the parabola and a quadratic Savitzky-Golay fit keeps it
    x = np.linspace(0, 100, 401)
    c = 50 + 0.01 * (x - 50) ** 2
    band = Polygon(
        np.vstack([np.column_stack([x, c - 5]), np.column_stack([x[::-1], c[::-1] + 5])])
    )
    line = centerline(band, spacing=5.0)[1:-1]  # the stations (the tips are on the boundary)
    np.testing.assert_allclose(line[:, 1], 50 + 0.01 * (line[:, 0] - 50) ** 2, atol=0.05)
    assert len(line) == 20  # floor(100 / 5) stations


def test_stations_by_hand():
    from dyntarget.plan.planners import stations

    np.testing.assert_allclose(stations(0.0, 8.0, 4.0), [2.0, 6.0])  # an exact multiple: 2 cells
    np.testing.assert_allclose(stations(0.0, 10.0, 4.0), [10 / 6, 5.0, 50 / 6])  # ceil(2.5) = 3
    np.testing.assert_allclose(stations(3.0, 3.5, 4.0), [3.25])  # shorter than a width: one


@pytest.mark.parametrize(("cols", "frame_x"), [((0, 10), 0), ((90, 100), 99)])
def test_trace_outline_skips_the_left_and_right_frame(cols, frame_x):
    m = np.zeros((100, 100), bool)
    m[20:80, cols[0] : cols[1]] = True  # a band 10 px wide along the left or right edge
    t = plan("trace-outline", m, config=PlanConfig(step=1.0))
    assert not np.isclose(t.points[:, 0], frame_x).any()
    # by hand: the walk starts at the band's corner nearest the sensor, (9, 79) or (90, 79), so
    # the samples fall on pixel centres; the 136 px ring has 60 of them on the frame
    # (y = 20..79 at the frame column), corners included
    assert len(t) == 2 * (9 + 59) - 60


@pytest.mark.parametrize("name", ["lawnmower-transect", "diagonal-transect"])
def test_transects_start_at_the_end_nearest_the_sensor(name):
    # plume x 50..95, y 40..59 in a 100 x 100 image; the sensor starts at (49.5, 99). By hand:
    # ceil(45 / 4) = 12 stations 3.75 px apart, the first at x = 51.875; its end nearest the
    # sensor is the bottom one (y = 59), so the walk starts there and goes up first
    m = rect_mask(rows=(40, 60), cols=(50, 96))
    t = plan(name, m, config=PlanConfig(step=1.0, width=4.0))
    np.testing.assert_allclose(t.points[0], [51.875, 59.0], atol=1e-9)
    assert t.points[1, 1] < 59.0 and t.points[-1, 0] > 90  # up first, ends at the far side
    if name == "lawnmower-transect":
        np.testing.assert_allclose(t.points[1], [51.875, 58.0], atol=1e-9)


@pytest.mark.parametrize(
    ("cols", "first"),
    [
        # x 50..95: 12 stations 45 / 12 = 3.75 px apart; the sensor at (49.5, 99) is nearest
        # the bottom end of the first, at x = 50 + 3.75 / 2
        ((50, 96), [51.875, 59.0]),
        # x 4..50: 12 stations 46 / 12 px apart; nearest is the bottom end of the last one,
        # at x = 50 - 46 / 24 (the walk runs along the axis backwards)
        ((4, 51), [50 - 46 / 24, 59.0]),
    ],
)
def test_transect_walk_starts_from_either_end_of_the_axis(cols, first):
    m = rect_mask(rows=(40, 60), cols=cols)
    t = plan("lawnmower-transect", m, config=PlanConfig(step=1.0, width=4.0))
    np.testing.assert_allclose(t.points[0], first, atol=1e-9)


@pytest.mark.parametrize(("cols", "start_x"), [((50, 96), 50.0), ((4, 51), 50.0)])
def test_track_center_starts_at_the_end_nearest_the_sensor(cols, start_x):
    # the axis runs from x = cols[0] to cols[1] - 1 at y = 49.5; the sensor starts at (49.5, 99)
    t = plan("track-center", rect_mask(rows=(40, 60), cols=cols), config=PlanConfig(step=1.0))
    assert t.points[0, 0] == pytest.approx(start_x)
    assert t.points[-1, 0] == pytest.approx(95.0 if cols[0] == 50 else 4.0)
    assert len(t) == 46 if cols[0] == 50 else len(t) == 47


@pytest.mark.parametrize("edge", ["top", "bottom", "left", "right"])
def test_points_clipped_onto_the_pixel_grid_at_each_edge(edge):
    # chords across a one-pixel line along an image edge reach half a pixel beyond the grid
    # (its polygon is the union of pixel squares): the pointings are clipped onto the edge
    m = np.zeros((60, 80), bool)
    line = {"top": (0, slice(10, 70)), "bottom": (59, slice(10, 70))}
    line |= {"left": (slice(10, 50), 0), "right": (slice(10, 50), 79)}
    m[line[edge]] = True
    t = plan("lawnmower-transect", m, config=PlanConfig(step=0.5))
    x, y = t.points[:, 0], t.points[:, 1]
    assert x.min() >= 0 and x.max() <= 79 and y.min() >= 0 and y.max() <= 59
    value = {"top": y.min(), "bottom": y.max(), "left": x.min(), "right": x.max()}[edge]
    assert value == {"top": 0, "bottom": 59, "left": 0, "right": 79}[edge]


def test_trace_outline_skips_the_bottom_frame_and_keeps_a_speck():
    m = np.zeros((100, 100), bool)
    m[90:100, 20:80] = True  # a band along the bottom edge
    t = plan("trace-outline", m, config=PlanConfig(step=1.0))
    assert (t.points[:, 1] < 99).all() and np.isclose(t.points[:, 1], 98.5).sum() == 2
    speck = np.zeros((50, 50), bool)
    speck[20, 30] = True  # one pixel: its 4 px ring gives one pointing at the default step
    assert len(plan("trace-outline", speck, config=PlanConfig(step=5.0))) == 1


def test_parts_numbered_in_visiting_order_and_params_kept():
    m = np.zeros((100, 100), bool)
    m[80:90, 40:60] = True
    m[5:15, 5:25] = True
    m[5:15, 75:95] = True
    t = plan("track-center", m)
    assert sorted(set(t.part.tolist())) == [0, 1, 2] and (np.diff(t.part) >= 0).all()
    assert t.planner == "track-center" and t.params["step"] == pytest.approx(1.0)
    empty = plan("track-center", np.zeros((10, 10), bool))
    assert empty.planner == "track-center" and empty.params["step"] == pytest.approx(1.0)
    from dyntarget.plan import geometric_planners

    assert geometric_planners() == [*PAPER_PLANNERS, "track-centerline"]


def test_transect_stations_cover_an_off_centre_plume():
    # the rectangle x 10..89 with a thick left end (rows 30..69 at x 10..20): the contour's
    # mean moves left of the extent's middle, the axis stays horizontal (symmetric in y);
    # the stations still cover the extent: ceil(79 / 4) = 20 of them, 3.95 px apart from 11.975
    m = rect_mask()
    m[30:70, 10:21] = True
    t = plan("lawnmower-transect", m, config=PlanConfig(step=1.0, width=4.0))
    x = np.round(t.points[:, 0], 2)  # the fitted axis tilts by ~3e-5: x varies by < 0.005
    xs, counts = np.unique(x, return_counts=True)
    np.testing.assert_allclose(xs[counts >= 10], 10 + 3.95 * (np.arange(20) + 0.5), atol=0.01)


def test_start_point_and_config_bounds_by_hand():
    from dyntarget.plan.planners import MIN_STEP, start_point

    np.testing.assert_array_equal(start_point((100, 60)), [29.5, 99.0])  # bottom centre
    # the documented bounds are inclusive: the smallest step and a naive square of full size
    assert PlanConfig(step=MIN_STEP, width=MIN_STEP).resolved((10, 10)) == (MIN_STEP, MIN_STEP)
    assert PlanConfig(naive_fraction=1.0).naive_fraction == 1.0
    assert PlanConfig(step_fraction=1.0).resolved((10, 20)) == (20.0, 40.0)  # one step: W px


def test_trace_outline_flies_the_frame_of_a_plume_that_fills_the_image():
    # Every boundary point is on the frame: skipping them would leave the plume unobserved.
    mask = np.ones((12, 12), bool)
    t = plan("trace-outline", mask, config=PlanConfig(step=1.0))
    assert len(t) > 0
    on_frame = (
        np.isclose(t.points[:, 0], 0)
        | np.isclose(t.points[:, 0], 11)
        | np.isclose(t.points[:, 1], 0)
        | np.isclose(t.points[:, 1], 11)
    )
    assert on_frame.all()


def test_oriented_reverses_only_when_the_last_point_is_nearer():
    from dyntarget.plan.planners import _oriented

    line = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    # from (1.2, 5): the last point is 0.8 px off in x, the first 1.2 px: reversed, although the
    # middle point (0.2 px off) is nearer still
    np.testing.assert_array_equal(_oriented(line, np.array([1.2, 5.0])), line[::-1])
    np.testing.assert_array_equal(_oriented(line, np.array([0.8, 5.0])), line)  # first nearer
    pair = np.array([[0.0, 0.0], [2.0, 0.0]])  # a two-point path is oriented too
    np.testing.assert_array_equal(_oriented(pair, np.array([1.5, 0.0])), pair[::-1])
    one = np.array([[3.0, 4.0]])
    np.testing.assert_array_equal(_oriented(one, np.array([0.0, 0.0])), one)


@pytest.mark.parametrize(("cols", "near_x", "next_x"), [((10, 30), 29, 28), ((70, 90), 70, 71)])
def test_transects_start_on_the_side_nearer_the_sensor(cols, near_x, next_x):
    # a vertical plume x cols[0]..cols[1]-1, y 20..89 beside the sensor at (49.5, 99): its axis
    # is vertical, the transects run along x. By hand: ceil(69 / 4) = 18 stations 69 / 18 px
    # apart, the last at y = 89 - 69 / 36; the walk starts at that station's end on the side
    # facing the sensor (x = 29 for the left plume, x = 70 for the right one) and crosses away
    m = rect_mask(rows=(20, 90), cols=cols)
    t = plan("lawnmower-transect", m, config=PlanConfig(step=1.0, width=4.0))
    np.testing.assert_allclose(t.points[0], [near_x, 89 - 69 / 36], atol=1e-9)
    np.testing.assert_allclose(t.points[1], [next_x, 89 - 69 / 36], atol=1e-9)


def _box(x0, y0, x1, y1):
    return Polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])


@pytest.mark.parametrize(
    ("bar", "decoy", "position", "d_decoy"),
    [
        # a bar along x whose left end is 2 px from the position; a 1 px square 4.03 px away
        (_box(29, 28, 89, 29), _box(24, 24, 25, 25), (27.0, 28.5), np.hypot(2, 3.5)),
        # the same from the bar's right end, the square below-left of the position
        (_box(29, 88, 89, 89), _box(92, 93, 93, 94), (91.0, 88.5), np.hypot(1, 4.5)),
        # a bar along y whose bottom end is 2 px from the position
        (_box(88, 29, 89, 89), _box(92, 92, 93, 93), (88.5, 91.0), np.hypot(3.5, 1)),
    ],
)
def test_nearest_next_takes_a_long_bar_whose_end_is_nearest(bar, decoy, position, d_decoy):
    from dyntarget.plan.planners import _NearestNext

    # The bar's bounding box is centred ~32 px away, the square's ~5 px: only the exact
    # distances (2 px to the bar's end, d_decoy to the square) put the bar first.
    p = np.array(position)
    assert bar.exterior.distance(Point(p)) == pytest.approx(2.0)
    assert decoy.exterior.distance(Point(p)) == pytest.approx(d_decoy)
    walk = _NearestNext([decoy, bar])
    assert walk.take(p) == 1 and walk.take(p) == 0


def test_plan_hands_a_planner_that_needs_context_its_arguments(monkeypatch):
    from dyntarget.plan import planners

    seen = []

    def stub(mask, polygons, config, context):
        seen.append((mask, polygons, config, context))
        return Trajectory.empty("stub", {})

    stub.needs_context = True
    monkeypatch.setattr(planners.PLANNERS, "get", lambda name: stub)
    m = rect_mask()
    context = planners.PlanContext(agility="fast")
    config = PlanConfig(step=3.0)
    plan("stub", m, config=config, context=context)
    mask, polygons, got_config, got_context = seen[-1]
    np.testing.assert_array_equal(mask, m)
    assert isinstance(polygons, list) and len(polygons) == 1
    assert polygons[0].equals(_box(10, 40, 89, 59))  # the rectangle's pixel-centre outline
    assert got_config is config and got_context is context
    plan("stub", m)  # no config: the defaults; no context: None
    assert seen[-1][2] == PlanConfig() and seen[-1][3] is None
