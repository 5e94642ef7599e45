"""Plane geometry of the planners (``plan/geometry.py``) against hand-worked values.

Where a value is not worked out by hand, it comes from a different method: line
intersections by shapely instead of the vectorised :func:`chords`, and least-squares
polynomial fits (``np.polyfit``) instead of the Savitzky-Golay filter.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import LineString, Point, Polygon

from dyntarget.plan.geometry import (
    _to_boundary,
    centerline,
    chords,
    major_axis,
    sample_polyline,
)

SQUARE = Polygon([(0, 0), (10, 0), (10, 10), (0, 10)])


@pytest.mark.parametrize("x", [0.0, 10.0])
def test_chord_along_an_edge_reaches_both_corners_without_warnings(x):
    # the vertical line x = 0 (or 10) runs along the square's left (right) edge: it enters at one
    # corner and leaves at the other, t = -5 and +5 from (x, 5); the edge itself is parallel to
    # the line (0 / 0 there), which must not warn
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = chords(SQUARE, np.array([[x, 5.0]]), np.array([0.0, 1.0]))
    np.testing.assert_allclose(out, [[-5.0, 5.0]])
    assert np.isnan(chords(SQUARE, np.array([[-1.0, 5.0]]), np.array([0.0, 1.0]))).all()


@pytest.mark.parametrize(
    ("point", "direction", "expected"),
    [
        ((5.0, 5.0), (2.0, 0.0), (10.0, 5.0)),  # from inside: the far edge (direction not unit)
        ((9.5, 5.0), (1.0, 0.0), (10.0, 5.0)),  # half a pixel from the edge: still moved there
        ((12.0, 5.0), (1.0, 0.0), (12.0, 5.0)),  # beyond the square, facing away: stays
        ((5.0, 20.0), (1.0, 0.0), (5.0, 20.0)),  # the line misses the square: stays
    ],
)
def test_to_boundary_by_hand(point, direction, expected):
    got = _to_boundary(SQUARE, np.array(point), np.array(direction))
    np.testing.assert_allclose(got, expected, atol=1e-12)


@pytest.mark.parametrize("angle", [30.0, 150.0])
def test_major_axis_sign_makes_the_larger_component_positive(angle):
    # a 60 x 6 rectangle turned by `angle`: its axis is (cos, sin) of the angle up to sign; the
    # sign is chosen so the larger component is positive: (0.866, 0.5) and (0.866, -0.5)
    bar = affinity.rotate(Polygon([(-30, -3), (30, -3), (30, 3), (-30, 3)]), angle, origin=(0, 0))
    centre, u = major_axis(bar)
    t = np.radians(angle)
    np.testing.assert_allclose(u, np.sign(np.cos(t)) * np.array([np.cos(t), np.sin(t)]), atol=1e-6)
    np.testing.assert_allclose(centre, [0.0, 0.0], atol=1e-6)


@pytest.mark.parametrize(
    ("vertices", "step", "expected_x"),
    [
        ([[0, 0], [1, 0]], 0.5, [0.0, 0.5, 1.0]),  # 1 px long: sampled, not one point
        ([[0, 0], [2.7, 0]], 1.0, [0.0, 1.0, 2.0, 2.7]),  # 0.7 step left over: end added
        ([[0, 0], [2.5, 0]], 1.0, [0.0, 1.0, 2.0]),  # exactly half a step left: not added
        ([[0, 0], [2.4, 0]], 1.0, [0.0, 1.0, 2.0]),  # 0.4 step left: not added
        ([[1, 1], [1, 1]], 1.0, [1.0]),  # no length: the vertex once
    ],
)
def test_sample_polyline_end_rule_by_hand(vertices, step, expected_x):
    pts = sample_polyline(np.array(vertices, float), step)
    np.testing.assert_allclose(pts[:, 0], expected_x, atol=1e-12)
    np.testing.assert_allclose(pts[:, 1], vertices[0][1])


def test_centerline_of_a_plume_shorter_than_the_spacing():
    # the rectangle x 0..10, y 0..4 with spacing 20: one station, at the centre (5, 2); the tips
    # are where the axis leaves the rectangle, (0, 2) and (10, 2)
    rect = Polygon([(0, 0), (10, 0), (10, 4), (0, 4)])
    np.testing.assert_allclose(centerline(rect, 20.0), [[0, 2], [5, 2], [10, 2]], atol=1e-9)


def _wavy_band(length):
    """A band 10 px wide along a wavy centre line, turned by 30 degrees."""
    x = np.linspace(0, length, 4 * int(length) + 1)
    c = 3 * np.sin(x / 5)
    band = Polygon(
        np.vstack([np.column_stack([x, c - 5]), np.column_stack([x[::-1], c[::-1] + 5])])
    )
    return affinity.rotate(band, 30, origin=(0, 0))


def _quadratic_fit(s, mid):
    return np.polyval(np.polyfit(s, mid, 2), s)


@pytest.mark.parametrize("count", [2, 4, 5, 6, 7, 9])
def test_centerline_stations_smoothed_like_quadratic_fits(count):
    spacing = 10.0
    band = _wavy_band(spacing * count + 5)
    centre, u = major_axis(band)
    n = np.array([-u[1], u[0]])  # the normal of the axis
    proj = (np.asarray(band.exterior.coords) - centre) @ u
    lo, hi = proj.min(), proj.max()
    assert int((hi - lo) // spacing) == count
    s = lo + (np.arange(count) + 0.5) * (hi - lo) / count
    # chord midpoints along the normal through each station, by shapely line intersection
    mid = []
    for sk in s:
        p = centre + sk * u
        cut = band.intersection(LineString([p - 100 * n, p + 100 * n]))
        t = (shapely.get_coordinates(cut) - p) @ n
        mid.append((t.min() + t.max()) / 2)
    mid = np.array(mid)
    # the Savitzky-Golay filter (window 7, order 2, "interp" ends) is: nothing below 5 stations;
    # one quadratic fit over all stations for 5 and 7; for 6, a window of 5: the first three from
    # the fit over stations 0..4, the last three from the fit over 1..5; for 9, a window of 7:
    # the first four from stations 0..6, the middle one from 1..7, the last four from 2..8
    if count < 5:
        smooth = mid
    elif count in (5, 7):
        smooth = _quadratic_fit(s, mid)
    elif count == 6:
        smooth = np.r_[_quadratic_fit(s[:5], mid[:5])[:3], _quadratic_fit(s[1:], mid[1:])[2:]]
    else:
        smooth = np.r_[
            _quadratic_fit(s[:7], mid[:7])[:4],
            _quadratic_fit(s[1:8], mid[1:8])[3],
            _quadratic_fit(s[2:], mid[2:])[3:],
        ]
    assert np.ptp(smooth - mid) > 0.05 or count < 5  # the smoothing does change something
    line = centerline(band, spacing)
    assert len(line) == count + 2
    expected = centre + s[:, None] * u + smooth[:, None] * n
    np.testing.assert_allclose(line[1:-1], expected, atol=1e-6)
    # each tip: on the boundary, on the line through the two stations next to it, beyond them
    ring = band.exterior
    for tip, a, b in ((line[0], line[1], line[2]), (line[-1], line[-2], line[-3])):
        assert ring.distance(Point(tip)) < 1e-6
        d, e = tip - a, a - b
        assert abs(d[0] * e[1] - d[1] * e[0]) < 1e-6 * np.hypot(*d) * np.hypot(*e)
        assert d @ e > 0
