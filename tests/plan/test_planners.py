"""Planner contract (every registered planner) and hand-checked geometry."""

from __future__ import annotations

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
    # most steps run perpendicular to the axis (the joins along the boundary are the rest)
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


def test_diagonal_is_a_zigzag_advancing_along_the_axis():
    m = rect_mask()
    t = plan("diagonal-transect", m, config=PlanConfig(step=1.0, width=4.0))
    # x (the axis) advances monotonically; y alternates between the two long sides
    assert np.all(np.diff(t.points[:, 0]) * np.sign(t.points[-1, 0] - t.points[0, 0]) >= -1e-9)
    assert len(t) < len(plan("lawnmower-transect", m, config=PlanConfig(step=1.0, width=4.0)))


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
        ({"naive_fraction": 0}, "naive_fraction"),
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
    transform = Affine(8.0, 0, 240000.0, 0, -8.0, 2160000.0)
    geo = t.to_geojson(transform=transform, crs="EPSG:32605")
    assert geo["crs"]["properties"]["name"] == "EPSG:32605"
    x, y = geo["features"][1]["geometry"]["coordinates"]
    assert (x, y) == (240000.0 + 8 * 10.5, 2160000.0 - 8 * 50.0)
    csv = t.save(tmp_path / "t.csv", transform=transform).read_text().splitlines()
    assert csv[0] == "order,x,y,part,X,Y" and len(csv) == len(t) + 1
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
