"""dyntarget.parallax against values worked out by hand and by plain 3D vector algebra.

The module uses closed-form angles (the sine rule in the triangle centre-feature-ground);
the reference here intersects rays with spheres as vectors, a different method.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dyntarget import parallax as px
from dyntarget.errors import InvalidParameterError

R = 6_371_008.7714  # WGS 84 mean radius R1 = (2a + b) / 3 = (2 * 6378137 + 6356752.3142) / 3


def _ray_hits_sphere(s: np.ndarray, through: np.ndarray, radius: float) -> np.ndarray:
    """First point where the ray from ``s`` through ``through`` meets the sphere ``radius``.

    |s + t d|^2 = r^2 with |d| = 1: t^2 + 2 (s.d) t + |s|^2 - r^2 = 0, the smaller root.
    """
    d = (through - s) / np.linalg.norm(through - s)
    b = float(s @ d)
    c = float(s @ s) - radius**2
    t = -b - math.sqrt(b * b - c)
    return s + t * d


def _arc_from_nadir(p: np.ndarray) -> float:
    """Arc distance on the sphere R from the nadir (the +z axis) to the point's foot."""
    return R * math.atan2(math.hypot(p[0], p[1]), p[2])


def _ground(gamma: float, radius: float = R) -> np.ndarray:
    return radius * np.array([math.sin(gamma), 0.0, math.cos(gamma)])


def _distance_for_zenith(h_sc: float, zenith_deg: float) -> float:
    """Arc distance at which the view zenith is ``zenith_deg`` (sine rule, by hand).

    Triangle centre O, ground point P, spacecraft S: the angle at P is 180 - zenith, so
    sin(angle at S) = R sin(180 - zenith) / (R + H), and the angle at O is
    gamma = zenith - angle at S.
    """
    eta = math.asin(R * math.sin(math.radians(zenith_deg)) / (R + h_sc))
    return R * (math.radians(zenith_deg) - eta)


def test_radius_is_wgs84_mean_radius():
    assert px.EARTH_RADIUS_M == pytest.approx((2 * 6378137.0 + 6356752.314245) / 3, abs=1e-3)


def test_issue_figures_500km_ahead_from_500km_up_and_300km_28s_later():
    # 500 km ahead: gamma = 500/6371.0088 = 0.078480 rad; (R+H) sin g = 538,690 m;
    # (R+H) cos g - R = 6,849,862 - 6,371,009 = 478,853 m; atan(538690/478853) = 48.37 deg.
    theta_500 = math.degrees(float(px.view_zenith(500e3, 500e3)))
    assert theta_500 == pytest.approx(48.37, abs=0.01)
    # 300 km ahead: (R+H) sin g = 323,424; (R+H) cos g - R = 492,385; tan = 0.6569.
    # tan(48.37) = 1.1250, so tan falls by 0.468.
    d_tan = math.tan(math.radians(theta_500)) - math.tan(float(px.view_zenith(500e3, 300e3)))
    assert d_tan == pytest.approx(0.468, abs=0.002)
    # 200 km in 28 s: the ground speed at 500 km, sqrt(GM/(R+H)) R/(R+H) = 7616 * 0.92723
    assert 200e3 / px.ground_speed(500e3) == pytest.approx(28.3, abs=0.1)


def test_view_zenith_against_vectors():
    h_sc, d = 500e3, 448.2e3
    s = np.array([0.0, 0.0, R + h_sc])
    p = _ground(d / R)
    los = (s - p) / np.linalg.norm(s - p)
    zen = math.degrees(math.acos(float(los @ (p / R))))
    assert math.degrees(float(px.view_zenith(h_sc, d))) == pytest.approx(zen, abs=1e-9)


def test_10km_feature_at_45deg_exact_on_the_sphere():
    h_sc, h = 500e3, 10e3
    # by hand: eta = asin(6371.009 sin 45 / 6871.009) = asin(0.65565) = 40.969 deg, gamma = 4.031 deg,
    # D = 448.5 km
    d = _distance_for_zenith(h_sc, 45.0)
    assert d == pytest.approx(448.2e3, abs=0.1e3)
    assert math.degrees(float(px.view_zenith(h_sc, d))) == pytest.approx(45.0, abs=1e-9)
    # the exact apparent ground point: the ray from S through the feature top meets the sphere
    s = np.array([0.0, 0.0, R + h_sc])
    top = _ground(d / R, R + h)
    a = _ray_hits_sphere(s, top, R)
    expected = _arc_from_nadir(a) - d
    got = float(px.parallax_shift(h_sc, d, h))
    assert got == pytest.approx(expected, abs=1e-3)
    # first order h tan 45 = 10 km; the curvature adds about 2 % here (the ray at the top is
    # steeper than at the ground and the ground curves away): 10.0 to 10.3 km
    assert 10.0e3 < got < 10.3e3


def test_nadir_gives_no_shift():
    assert float(px.parallax_shift(500e3, 0.0, 10e3)) == 0.0
    da, dc = px.shift_xy(500e3, 0.0, 0.0, 10e3)
    assert (float(da), float(dc)) == (0.0, 0.0)


def test_first_order_limit_small_angles():
    # 20 km from nadir, 500 km up: for small gamma = D/R, tan(theta) ~ (R + H) gamma / H
    # = (6871.009 / 6371.009) (20 / 500) = 0.043139 (a flat Earth would give 0.04), so a
    # 1 km top shifts h tan(theta) = 43.14 m (plus h/H = 0.2 %: the ray is steeper above)
    assert float(px.parallax_shift(500e3, 20e3, 1e3)) == pytest.approx(43.14, rel=0.005)


def test_inverse_and_terrain_against_vectors():
    h_sc, h, z = 500e3, 8e3, 1.5e3
    d_app = 400e3
    # the line of sight to the apparent point on the terrain sphere R + z, crossing R + h
    s = np.array([0.0, 0.0, R + h_sc])
    g = _ground(d_app / R)  # foot of the apparent point on the map sphere
    g = g / R * (R + z)
    hit = _ray_hits_sphere(s, g, R + h)
    expected = _arc_from_nadir(hit)
    assert float(px.sight_at_height(h_sc, d_app, h, ground_m=z)) == pytest.approx(
        expected, abs=1e-3
    )
    # and forward again
    back = float(px.parallax_shift(h_sc, expected, h, ground_m=z))
    assert expected + back == pytest.approx(d_app, abs=1e-3)


def test_shift_xy_is_radial_from_the_nadir():
    # a point 300 km ahead and 400 km to the right (500 km away): the shift points 3:4
    da, dc = px.shift_xy(500e3, 300e3, 400e3, 5e3)
    s = float(px.parallax_shift(500e3, 500e3, 5e3))
    assert (float(da), float(dc)) == pytest.approx((0.6 * s, 0.8 * s), rel=1e-12)
    a, c = px.unshift_xy(500e3, 300e3 + float(da), 400e3 + float(dc), 5e3)
    assert (float(a), float(c)) == pytest.approx((300e3, 400e3), abs=1e-3)


def test_view_azimuth_points_back_to_the_nadir():
    assert float(px.view_azimuth(500e3, 0.0)) == pytest.approx(math.pi)
    assert float(px.view_azimuth(-100e3, 0.0)) == pytest.approx(0.0)
    assert float(px.view_azimuth(0.0, -50e3)) == pytest.approx(math.pi / 2)


@pytest.mark.parametrize(
    "call",
    [
        lambda: px.view_zenith(float("nan"), 1e3),
        lambda: px.view_zenith(-5.0, 1e3),
        lambda: px.parallax_shift(500e3, 1e3, float("inf")),
        lambda: px.parallax_shift(5e3, 1e3, 10e3),
        lambda: px.sight_at_height(500e3, "x", 1e3),
    ],
)
def test_bad_input_is_refused(call):
    with pytest.raises(InvalidParameterError):
        call()


def test_beyond_the_horizon_is_nan():
    # 500 km up the horizon is R acos(R/(R+H)) = 2,500 km away
    assert np.isnan(px.view_zenith(500e3, 2_600e3))
    assert not np.isnan(px.view_zenith(500e3, 2_400e3))
