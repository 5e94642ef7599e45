"""Orbit geometry against independent references: Vallado's published SGP4 ephemeris
and a circular Kepler orbit worked out by hand."""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from dyntarget.constellation.orbits import (
    ecef_to_geodetic,
    parse_tle,
    parse_walker,
    propagate,
    sso_inclination_deg,
    walker,
)
from dyntarget.errors import DataFileError, InvalidParameterError

# Vallado, Crawford, Hujsak & Kelso (2006), "Revisiting Spacetrack Report #3", test
# case 00005 (SGP4-VER.TLE) and its published TEME ephemeris (tcppver.out), km.
L1 = "1 00005U 58002B   00179.78495062  .00000023  00000-0  28098-4 0  4753"
L2 = "2 00005  34.2682 348.7242 1859667 331.7664  19.3264 10.82419157413667"
EPOCH = datetime(2000, 6, 27, tzinfo=UTC) + timedelta(days=0.78495062)
PUBLISHED = {  # minutes since epoch -> TEME position, km
    0.0: (7022.46529266, -1400.08296755, 0.03995155),
    360.0: (-7154.03120202, -3783.17682504, -3536.19412294),
}


def test_published_ephemeris_radius_and_polar_component():
    # TEME -> Earth-fixed is a rotation about z: it keeps |r| and z of the published values
    sats = parse_tle(f"{L1}\n{L2}\n", start=EPOCH)
    r, _ = propagate(sats, EPOCH, np.array([0.0, 360.0 * 60.0]))
    for k, minutes in enumerate(PUBLISHED):
        ref = np.array(PUBLISHED[minutes])
        # published with WGS 72 constants, we propagate with WGS 84: tens of metres apart
        assert np.linalg.norm(r[0, k]) / 1e3 == pytest.approx(np.linalg.norm(ref), abs=0.03)
        assert r[0, k, 2] / 1e3 == pytest.approx(ref[2], abs=0.03)


def _node_crossings(r: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times and Earth-fixed longitudes of ascending equator crossings (linear interpolation)."""
    z = r[:, 2]
    k = np.flatnonzero((z[:-1] < 0) & (z[1:] >= 0))
    f = -z[k] / (z[k + 1] - z[k])
    times = t[k] + f * (t[k + 1] - t[k])
    pos = r[k] + f[:, None] * (r[k + 1] - r[k])
    return times, np.degrees(np.arctan2(pos[:, 1], pos[:, 0]))


def test_walker_circular_orbit_matches_kepler_by_hand():
    start = datetime(2026, 6, 1, tzinfo=UTC)
    inc = sso_inclination_deg(500.0)
    sats = walker(1, 1, 0, altitude_km=500.0, inclination_deg=inc, epoch=start)
    t = np.arange(0.0, 6 * 3600.0, 5.0)
    r, v = propagate(sats, start, t)
    r, v = r[0], v[0]
    # Kepler by hand: a = 6378.137 + 500 km, T = 2 pi sqrt(a^3 / mu) = 5676.98 s
    times, lon = _node_crossings(r, t)
    period = np.diff(times)
    assert period.mean() == pytest.approx(5676.98, rel=3e-3)  # J2 shifts the nodal period ~0.1 %
    # the Earth turns under the orbit: each node falls west by (omega_E - node drift) * T
    shift = (lon[1:] - lon[:-1] + 540.0) % 360.0 - 180.0
    sidereal_deg_s = 360.0 / 86164.0905
    node_drift_deg_s = 360.0 / (365.2422 * 86400.0)  # sun-synchronous: one turn a year
    expected = -(sidereal_deg_s - node_drift_deg_s) * period
    np.testing.assert_allclose(shift, expected, atol=0.02)
    # radius ~ a, highest geocentric latitude = 180 - inclination (retrograde)
    assert np.linalg.norm(r, axis=1).mean() / 1e3 == pytest.approx(6878.137, abs=15.0)
    top = np.degrees(np.arcsin(r[:, 2] / np.linalg.norm(r, axis=1))).max()
    assert top == pytest.approx(180.0 - inc, abs=0.05)
    # the Earth-fixed velocity is the derivative of the Earth-fixed position
    fd = (r[2:] - r[:-2]) / 10.0
    np.testing.assert_allclose(fd, v[1:-1], atol=0.5)  # m/s, of 7600


def test_walker_names_and_phasing():
    sats = walker(
        6, 3, 1, altitude_km=550.0, inclination_deg=53.0, epoch=datetime(2026, 1, 1, tzinfo=UTC)
    )
    assert [s.name for s in sats] == ["W1-1", "W1-2", "W2-1", "W2-2", "W3-1", "W3-2"]
    # RAAN 360 p / P; mean anomaly 360 s / (T/P) + 360 F p / T
    assert [s.elements[2] for s in sats] == [0.0, 0.0, 120.0, 120.0, 240.0, 240.0]
    assert [s.elements[3] for s in sats] == [0.0, 180.0, 60.0, 240.0, 120.0, 300.0]


def test_sso_inclination_textbook():
    # Wertz, Space Mission Analysis and Design: 97.4 deg at 500 km, 98.2 at 800 km
    assert sso_inclination_deg(500.0) == pytest.approx(97.40, abs=0.02)
    assert sso_inclination_deg(800.0) == pytest.approx(98.60, abs=0.05)


def test_geodetic_round_trip_pole_and_equator():
    lat, _, h = ecef_to_geodetic(np.array([[0.0, 0.0, 6356752.314245 + 100.0]]))
    assert lat[0] == pytest.approx(90.0) and h[0] == pytest.approx(100.0, abs=1e-3)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (f"{L1[:-1]}5\n{L2}\n", "line 1: checksum '5' does not match the computed 3"),
        (f"SAT\n{L1}\n", "line 2: expected two element lines"),
        (f"{L1}\n{L1}\n", "line 2: expected TLE line 2"),
        ("", "no satellites (an empty constellation)"),
    ],
)
def test_malformed_tle_names_the_line(text, message):
    with pytest.raises(DataFileError, match=re_escape(message)):
        parse_tle(text, start=EPOCH)


def test_tle_epoch_decades_away_is_refused():
    with pytest.raises(DataFileError, match=r"line 1: epoch is 25\.9 years before --start"):
        parse_tle(f"{L1}\n{L2}\n", start=datetime(2026, 6, 1, tzinfo=UTC))


def test_three_line_names():
    sats = parse_tle(f"0 OLD SAT\n{L1}\n{L2}\n", start=EPOCH)
    assert sats[0].name == "OLD SAT"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("0/1/0", "empty constellation"),
        ("20/3/1", "P 3 must divide T 20"),
        ("20/5/5", "F 5 must be in 0..P-1"),
        ("a/b/c", "expected T/P/F"),
    ],
)
def test_bad_walker(text, message):
    with pytest.raises(InvalidParameterError, match=message):
        parse_walker(text)


def re_escape(s: str) -> str:
    import re

    return re.escape(s)


def test_math_constant_sanity():
    assert math.isclose(2 * math.pi * math.sqrt((6878.137) ** 3 / 398600.5), 5676.98, abs_tol=0.01)


def test_sun_at_the_march_equinox_by_hand():
    from dyntarget.constellation.orbits import sun_direction

    # 2026-03-20 12:00 UTC: the equinox is at 14:46 UTC (declination ~ -0.05 deg) and the
    # equation of time is -7.4 min, so the Sun is 7.4 min * 0.25 deg/min = 1.85 deg east
    d = sun_direction(datetime(2026, 3, 20, 12, tzinfo=UTC), np.array([0.0]))[0]
    assert np.degrees(np.arcsin(d[2])) == pytest.approx(-0.045, abs=0.02)
    assert np.degrees(np.arctan2(d[1], d[0])) == pytest.approx(1.85, abs=0.1)


def test_no_sun_synchronous_orbit_exists_above_about_5970_km():
    # J2 precession rate 3/2 n J2 (Re/a)^2 |cos i| must reach 360 deg/year: with cos i = 1 it
    # does up to a = 12,352 km (worked out from GM, J2 and Re), i.e. 5,974 km above Re.
    assert 170 < sso_inclination_deg(5950.0) < 180  # nearly retrograde-equatorial
    with pytest.raises(InvalidParameterError, match="no sun-synchronous orbit at 6000 km"):
        sso_inclination_deg(6000.0)
