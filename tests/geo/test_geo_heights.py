"""Plume-top heights from a look-ahead look and GEO images (dyntarget.geo.heights).

The geometry is checked against values worked out here: the flat-Earth ``h tan(theta)``
and an independent ray-sphere intersection in 2-D vectors (the line of sight from the
apparent ground point, at its zenith angle, meets the sphere of radius ``R + h``; the
true ground point is under that crossing). Synthetic sightings are made with that
intersection, not with the module's formula.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError
from dyntarget.geo.heights import (
    GEO_ALTITUDE_M,
    Sighting,
    fit_geo_height,
    fraction_centroid,
    ground_distance_for_zenith,
    match_offset,
    parallax_offset,
)

R = 6_371_008.7714  # WGS 84 mean radius, typed in


def ray_sphere_offset(zenith_deg: float, height_m: float) -> float:
    """Arc distance from the apparent ground point to the true one under a feature at
    ``height_m`` seen at ``zenith_deg`` there: 2-D vectors, the apparent point at
    ``(0, R)``, the line of sight leaving towards ``-x`` at the zenith angle."""
    th = math.radians(zenith_deg)
    p = np.array([0.0, R])
    d = np.array([-math.sin(th), math.cos(th)])
    # |p + s d| = R + h: s^2 + 2 s (p.d) + |p|^2 - (R + h)^2 = 0, the positive root
    b = float(p @ d)
    s = -b + math.sqrt(b * b - (R * R - (R + height_m) ** 2))
    f = p + s * d
    return R * math.atan2(-f[0], f[1])  # angle at the centre between p and f


def test_a_10_km_top_at_50_deg_is_11_9_km_away_flat_and_the_sphere_differs_slightly():
    flat = 10e3 * math.tan(math.radians(50.0))  # 11,917.5 m
    sphere = ray_sphere_offset(50.0, 10e3)
    for altitude in (500e3, GEO_ALTITUDE_M):  # the zenith at the point fixes the line
        dx, dy = parallax_offset(50.0, 180.0, altitude, 10e3)  # imager due south: north
        assert abs(dx) < 1e-9 and dy == pytest.approx(sphere, abs=1e-3)
    # on the sphere the top appears 0.26 % nearer than on flat ground (32 m)
    assert (sphere - flat) / flat == pytest.approx(-0.0026, abs=0.0002)
    assert round(flat) == 11918 and round(sphere) == 11886
    # the direction: away from the imager along its azimuth
    dx, dy = parallax_offset(50.0, 90.0, GEO_ALTITUDE_M, 10e3)  # imager due east: west
    assert dx == pytest.approx(-sphere, abs=1e-3) and abs(dy) < 1e-9


def test_the_ground_distance_for_a_zenith_inverts_view_zenith():
    # 35 deg N under the GEO's longitude: 35 deg of arc, 3,891.8 km; zenith 40.65 deg
    d = R * math.radians(35.0)
    rs = R + GEO_ALTITUDE_M
    g = math.radians(35.0)
    zen = math.degrees(math.atan2(rs * math.sin(g), rs * math.cos(g) - R))  # by hand
    assert zen == pytest.approx(40.6498, abs=1e-4)
    assert ground_distance_for_zenith(GEO_ALTITUDE_M, zen) == pytest.approx(d, abs=0.01)
    for z in (0.0, 30.0, 48.37, 70.0):
        d = ground_distance_for_zenith(500e3, z)
        assert math.degrees(float(parallax.view_zenith(500e3, d))) == pytest.approx(z, abs=1e-9)


def _sightings(h, wind, times_geo, *, z_leo=45.0, z_geo=40.65, az_geo=0.0, noise=(0.0, 0.0),
               rng=None, sigma=(50.0, 200.0)):  # fmt: skip
    """A north-flying look-ahead (spacecraft south: azimuth 180) at t = 0 and GEO images at
    ``times_geo``; positions from the ray-sphere offsets, ground truth (1000, 2000) at t = 0."""
    p0 = np.array([1000.0, 2000.0])
    v = np.asarray(wind, float)
    out = []
    for t, z, az, alt, n, sd in [(0.0, z_leo, 180.0, 500e3, noise[0], sigma[0])] + [
        (t, z_geo, az_geo, GEO_ALTITUDE_M, noise[1], sigma[1]) for t in times_geo
    ]:
        a = math.radians(az)
        pos = p0 + v * t - ray_sphere_offset(z, h) * np.array([math.sin(a), math.cos(a)])
        if rng is not None:
            pos = pos + rng.normal(0.0, n, 2)
        out.append(Sighting(t, float(pos[0]), float(pos[1]), z, az, alt, sd))
    return out


def test_a_simultaneous_pair_recovers_the_height_and_its_sigma_is_honest():
    rng = np.random.default_rng(7)
    z = []
    for _ in range(300):
        h = float(rng.uniform(2e3, 15e3))
        s = _sightings(h, (3.0, -4.0), [0.0], noise=(50.0, 200.0), rng=rng)
        fit = fit_geo_height(s)
        assert fit.ok
        z.append((fit.height_m - h) / fit.height_sigma_m)
    z = np.asarray(z)
    # sigma by hand: the disparity's noise (50 and 200 m) over tan 45 + tan 40.65 = 1.859
    assert fit.height_sigma_m == pytest.approx(math.hypot(50.0, 200.0) / 1.859, rel=0.03)
    assert abs(z.mean()) < 0.15 and 0.85 < z.std() < 1.15
    assert np.mean(np.abs(z) < 2.0) > 0.92


def test_a_drift_ignored_biases_the_height_by_the_hand_amount_and_the_geo_pair_removes_it():
    h, north = 9000.0, 10.0  # the plume moves 10 m/s north; the GEO image is 600 s older
    s = _sightings(h, (0.0, north), [-600.0])
    fit = fit_geo_height(s, wind_prior=(0.0, 0.0), wind_prior_sigma_mps=0.001)
    # the 6 km of drift is read as disparity: 6000 / (tan 45 + tan 40.65) = 3,228 m too high
    by_hand = north * 600.0 / (1.0 + math.tan(math.radians(40.65)))
    assert fit.ok and fit.height_m - h == pytest.approx(by_hand, rel=0.01)
    # with a second GEO image the drift is measured and carried to the look
    pair = fit_geo_height(_sightings(h, (0.0, north), [-1200.0, -600.0]))
    assert pair.ok and pair.height_m == pytest.approx(h, abs=1.0)
    assert pair.wind_mps == pytest.approx((0.0, north), abs=1e-3)
    # its sigma carries the extrapolation: the GEO position at t = 0 from images at -1200
    # and -600 s is 2 a(-600) - a(-1200): sqrt(5) x 200 m; with the look's 50 m, over 1.859
    assert pair.height_sigma_m == pytest.approx(math.hypot(50.0, math.sqrt(5) * 200.0) / 1.859,
                                                rel=0.03)  # fmt: skip


def test_a_geo_on_the_same_side_as_the_look_ahead_measures_little_or_nothing():
    # the GEO due south, like the north-flying look-ahead: both displace the top north
    same = _sightings(8000.0, (0.0, 0.0), [0.0], z_leo=40.65, az_geo=180.0)
    fit = fit_geo_height(same)
    assert not fit.ok and "degenerate" in fit.reason and fit.baseline < 1e-6
    near = _sightings(8000.0, (0.0, 0.0), [0.0], z_leo=45.0, az_geo=180.0)
    fit = fit_geo_height(near)
    # the baseline is tan 45 - tan 40.65 = 0.141: the sigma 1.859 / 0.141 = 13 times larger
    assert fit.ok and fit.baseline == pytest.approx(1.0 - math.tan(math.radians(40.65)), abs=1e-3)
    assert fit.height_sigma_m == pytest.approx(math.hypot(50.0, 200.0) / fit.baseline, rel=0.03)


def test_sightings_at_two_times_without_a_prior_are_refused_with_the_reason():
    fit = fit_geo_height(_sightings(8000.0, (0.0, 5.0), [-600.0]))
    assert not fit.ok and "drift unconstrained" in fit.reason and math.isnan(fit.height_m)


def test_the_centroid_and_its_noise_by_hand():
    f = np.zeros((3, 4))
    f[1, 1], f[1, 2] = 0.5, 0.5  # two half-covered cells side by side
    c = fraction_centroid(f, cell_m=1000.0, origin_m=(0.0, 3000.0), noise=0.1,
                          region=f > 0)  # fmt: skip
    assert (c.x_m, c.y_m, c.cover, c.cells) == (2000.0, 1500.0, 1.0, 2)
    # x: 0.1 sqrt(500^2 + 500^2) / 1 = 70.7 m; y: 0 (both cells on the same row)
    assert c.sigma_m == pytest.approx(70.71, abs=0.01)


def test_a_fine_plume_is_matched_on_coarse_cells_to_a_fraction_of_a_cell():
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:160, 0:160] * 32.0 + 16.0
    blob = lambda cx, cy, x, y: np.exp(-(((x - cx) / 900.0) ** 2 + ((y - cy) / 500.0) ** 2))  # noqa: E731
    fine = blob(2560.0, 2560.0, xx, yy)
    # the coarse image: the same plume 3,210 m east and 1,470 m north on 1 km cells,
    # each cell the mean of 25 x 25 samples, plus noise 0.01
    true = (3210.0, 1470.0)
    sub = (np.arange(25) + 0.5) * 40.0
    coarse = np.zeros((12, 12))
    for r in range(12):
        for c in range(12):
            x, y = np.meshgrid(c * 1000.0 + sub, r * 1000.0 + sub)
            coarse[r, c] = blob(2560.0 + true[0], 2560.0 - true[1], x, y).mean()
    coarse += rng.normal(0.0, 0.01, coarse.shape)
    o = match_offset(fine, coarse, fine_cell_m=32.0, fine_origin_m=(0.0, 0.0),
                     coarse_cell_m=1000.0, coarse_origin_m=(0.0, 0.0), guess_m=(2500.0, 2000.0),
                     noise=0.01)  # fmt: skip
    assert abs(o.dx_m - true[0]) < 40.0 and abs(o.dy_m - true[1]) < 40.0
    assert 5.0 < o.sigma_m < 40.0 and o.scale == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: Sighting(0.0, 0.0, 0.0, float("nan"), 180.0, 500e3, 30.0), "zenith_deg"),
        (lambda: Sighting(0.0, 0.0, 0.0, 95.0, 180.0, 500e3, 30.0), "zenith_deg"),
        (lambda: Sighting(0.0, 0.0, 0.0, 45.0, 180.0, 500e3, 0.0), "sigma_m"),
        (lambda: Sighting(0.0, 0.0, 0.0, 45.0, 180.0, -1.0, 30.0), "altitude_m"),
        (lambda: fit_geo_height([Sighting(0.0, 0.0, 0.0, 45.0, 180.0, 500e3, 30.0)]), "two or more"),
        (lambda: fit_geo_height(["a", "b"]), "two or more"),
        (lambda: fit_geo_height(_sightings(5e3, (0, 0), [0.0]), wind_prior=(0.0, 0.0)), "both"),
        (lambda: fit_geo_height(_sightings(5e3, (0, 0), [0.0]), wind_prior=(0.0, 0.0),
                                wind_prior_sigma_mps=-1.0), "wind_prior_sigma_mps"),
        (lambda: fit_geo_height(_sightings(5e3, (0, 0), [0.0]), wind_prior=(float("inf"), 0.0),
                                wind_prior_sigma_mps=1.0), "wind_prior"),
        (lambda: parallax_offset(45.0, 0.0, 500e3, -10.0), "height_m"),
        (lambda: ground_distance_for_zenith(500e3, 90.0), "zenith_deg"),
        (lambda: fraction_centroid(np.zeros((3, 3)), cell_m=1000.0), "no plume"),
        (lambda: fraction_centroid(np.ones(3), cell_m=1000.0), "2-D"),
        (lambda: fraction_centroid(np.ones((3, 3)), cell_m=0.0), "cell_m"),
        (lambda: fraction_centroid(np.ones((3, 3)), cell_m=1.0, region=np.ones((2, 2))), "region"),
        (lambda: match_offset(np.zeros((4, 4)), np.ones((4, 4)), fine_cell_m=1.0,
                              fine_origin_m=(0, 0), coarse_cell_m=2.0, coarse_origin_m=(0, 0),
                              guess_m=(0, 0)), "no plume"),
        (lambda: match_offset(np.ones((4, 4)), np.ones((4, 4)), fine_cell_m=4.0,
                              fine_origin_m=(0, 0), coarse_cell_m=2.0, coarse_origin_m=(0, 0),
                              guess_m=(0, 0)), "coarser"),
    ],
)  # fmt: skip
def test_bad_input_is_refused_in_one_line(call, match):
    with pytest.raises(InvalidParameterError, match=match) as e:
        call()
    assert "\n" not in str(e.value)
