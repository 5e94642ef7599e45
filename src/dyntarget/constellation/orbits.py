"""Satellites on real orbits over a rotating WGS 84 Earth (SGP4 through ``sgp4``).

Why ``sgp4`` (Brandon Rhodes' package, the Vallado reference implementation in C++)
rather than ``skyfield``: it is the propagator TLEs are defined for, it propagates a
whole constellation over a whole time grid in one vectorised call
(:class:`sgp4.api.SatrecArray`), it builds generated orbits from mean elements
(:meth:`sgp4.api.Satrec.sgp4init`), and it has no data files to download (skyfield
fetches ephemerides and leap-second tables). Its output frame is TEME; this module
rotates TEME into the Earth-fixed frame by the Greenwich mean sidereal time (IAU-82,
:func:`sgp4.propagation.gstime`), neglecting polar motion (metres).

* :func:`read_tle` reads a two- or three-line-element file, checking line numbers,
  checksums, matching catalogue numbers and an epoch close to the simulation's start.
* :func:`walker` makes a Walker-delta ``T/P/F`` constellation of circular orbits at an
  altitude and inclination (``"sso"``: the sun-synchronous inclination from J2),
  satellites named ``W<plane>-<slot>``.
* :func:`propagate` gives Earth-fixed positions and velocities on a time grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from dyntarget.errors import DataFileError, InvalidParameterError

WGS84_A_M = 6_378_137.0
"""WGS 84 semi-major axis, metres."""
WGS84_F = 1.0 / 298.257223563
"""WGS 84 flattening."""
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
"""WGS 84 first eccentricity squared."""
GM_KM3_S2 = 398_600.5
"""Earth's gravitational parameter of the WGS 84 SGP4 constants, km³/s²."""
J2 = 0.00108262998905
"""Earth's J2 (WGS 84 SGP4 constants)."""
OMEGA_EARTH = 7.292115e-5
"""Earth's rotation rate, rad/s (WGS 84)."""
MAX_EPOCH_DAYS = 365.0
"""A TLE whose epoch is further than this from the start is refused (SGP4 errors grow
by kilometres per day away from the epoch; decades away is a wrong file)."""
MAX_SATELLITES = 5000


@dataclass(frozen=True)
class Satellite:
    """One satellite: its name and the two TLE lines (or generated mean elements).

    Parameters
    ----------
    name : str
        The TLE's name line, or ``W<plane>-<slot>`` for a Walker satellite.
    line1, line2 : str
        The element lines (empty for a generated satellite).
    elements : tuple of float
        Generated satellites: ``(epoch_jd, inclination_deg, raan_deg, mean_anomaly_deg,
        mean_motion_rad_min)``; empty for a TLE.
    """

    name: str
    line1: str = ""
    line2: str = ""
    elements: tuple[float, ...] = ()

    def satrec(self):  # -> sgp4.api.Satrec
        """The ``sgp4`` record of this satellite.

        Returns
        -------
        sgp4.api.Satrec
            Ready to propagate.

        Examples
        --------
        >>> from datetime import UTC, datetime
        >>> s = walker(1, 1, 0, altitude_km=500, inclination_deg=53, epoch=datetime(2026, 1, 1, tzinfo=UTC))
        >>> round(s[0].satrec().no_kozai, 4)  # mean motion, rad/min
        0.0664
        """
        from sgp4.api import WGS84, Satrec

        if self.line1:
            return Satrec.twoline2rv(self.line1, self.line2, WGS84)
        epoch_jd, inc, raan, ma, n = self.elements
        rec = Satrec()
        rec.sgp4init(
            WGS84,
            "i",
            0,
            epoch_jd - 2433281.5,  # days since 1949 December 31 00:00 UT
            0.0,  # bstar: no drag (generated orbits stay circular)
            0.0,
            0.0,
            0.0,  # circular
            0.0,
            math.radians(inc),
            math.radians(ma),
            n,
            math.radians(raan),
        )
        return rec


def julian(when: datetime) -> tuple[float, float]:
    """``(jd, fraction)`` of a UTC instant, as ``sgp4`` takes times.

    Parameters
    ----------
    when : datetime.datetime
        An aware UTC instant.

    Returns
    -------
    tuple of float
        Julian day (at midnight) and its fraction.

    Examples
    --------
    >>> julian(datetime(2000, 1, 1, 12, tzinfo=UTC))
    (2451544.5, 0.5)
    """
    from sgp4.api import jday

    jd, fr = jday(when.year, when.month, when.day, when.hour, when.minute, 0.0)
    return float(jd), float(fr + (when.second + when.microsecond * 1e-6) / 86400.0)


def _checksum(line: str) -> int:
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def parse_tle(text: str, *, start: datetime, source: str = "TLE") -> list[Satellite]:
    """Satellites from TLE text (two- or three-line sets), each checked.

    Parameters
    ----------
    text : str
        The file's text.
    start : datetime.datetime
        Start of the simulation; an epoch more than :data:`MAX_EPOCH_DAYS` away is refused.
    source : str
        Name of the file, for error messages.

    Returns
    -------
    list of Satellite
        In file order.

    Raises
    ------
    dyntarget.errors.DataFileError
        Naming the line: a wrong line number, checksum, catalogue number, an epoch far
        from the start, or elements sgp4 cannot use.

    Examples
    --------
    >>> l1 = "1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927"
    >>> l2 = "2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537"
    >>> parse_tle(f"ISS\\n{l1}\\n{l2}\\n", start=datetime(2008, 9, 21, tzinfo=UTC))[0].name
    'ISS'
    """
    from sgp4.api import WGS84, Satrec

    lines = [(i + 1, ln.rstrip("\r\n").rstrip()) for i, ln in enumerate(text.splitlines())]
    lines = [(i, ln) for i, ln in lines if ln.strip()]
    sats: list[Satellite] = []
    k = 0
    start_jd = sum(julian(start))
    while k < len(lines):
        name = ""
        no, line = lines[k]
        if not line.startswith("1 "):
            name = line[2:].strip() if line.startswith("0 ") else line.strip()
            k += 1
            if k >= len(lines):
                raise DataFileError(f"{source} line {no}: a name line with no elements after it")
        if k + 1 >= len(lines):
            raise DataFileError(f"{source} line {lines[k][0]}: expected two element lines")
        (n1, l1), (n2, l2) = lines[k], lines[k + 1]
        k += 2
        for n, ln, digit in ((n1, l1, "1"), (n2, l2, "2")):
            if len(ln) != 69 or not ln.startswith(digit + " "):
                raise DataFileError(
                    f"{source} line {n}: expected TLE line {digit} (69 characters starting "
                    f"'{digit} '), got {ln[:20]!r}..."
                )
            if not ln[68].isdigit() or int(ln[68]) != _checksum(ln):
                raise DataFileError(
                    f"{source} line {n}: checksum {ln[68]!r} does not match "
                    f"the computed {_checksum(ln)} (corrupt TLE line)"
                )
        if l1[2:7] != l2[2:7]:
            raise DataFileError(
                f"{source} line {n2}: catalogue number {l2[2:7].strip()} differs from "
                f"line {n1}'s {l1[2:7].strip()}"
            )
        try:
            rec = Satrec.twoline2rv(l1, l2, WGS84)
        except ValueError as exc:
            raise DataFileError(f"{source} line {n1}: unreadable elements ({exc})") from None
        days = rec.jdsatepoch + rec.jdsatepochF - start_jd
        if abs(days) > MAX_EPOCH_DAYS:
            raise DataFileError(
                f"{source} line {n1}: epoch is {abs(days) / 365.25:.1f} years "
                f"{'before' if days < 0 else 'after'} --start (at most {MAX_EPOCH_DAYS:g} days)"
            )
        if rec.error:
            raise DataFileError(f"{source} line {n1}: sgp4 refuses the elements (code {rec.error})")
        sats.append(Satellite(name or l1[2:7].strip(), l1, l2))
    if not sats:
        raise DataFileError(f"{source}: no satellites (an empty constellation)")
    if len(sats) > MAX_SATELLITES:
        raise DataFileError(f"{source}: {len(sats)} satellites, at most {MAX_SATELLITES}")
    names = [s.name for s in sats]
    for i, nm in enumerate(names):
        if nm in names[:i]:
            raise DataFileError(f"{source}: satellite name {nm!r} appears twice")
    return sats


def read_tle(path: str | Path, *, start: datetime) -> list[Satellite]:
    """:func:`parse_tle` of a file.

    Parameters
    ----------
    path : str or pathlib.Path
        The TLE file.
    start : datetime.datetime
        Start of the simulation.

    Returns
    -------
    list of Satellite
        The satellites.

    Examples
    --------
    >>> import tempfile
    >>> l1 = "1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927"
    >>> l2 = "2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537"
    >>> p = Path(tempfile.mkdtemp()) / "iss.tle"; _ = p.write_text(f"ISS\\n{l1}\\n{l2}\\n")
    >>> [s.name for s in read_tle(p, start=datetime(2008, 9, 21, tzinfo=UTC))]
    ['ISS']
    """
    from dyntarget.io.safeopen import read_text

    try:
        text = read_text(path, max_bytes=64 << 20)
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(f"--tle {path}: cannot read ({exc})") from None
    return parse_tle(text, start=start, source=str(path))


def sso_inclination_deg(altitude_km: float) -> float:
    """Sun-synchronous inclination of a circular orbit (J2 nodal precession = 360°/year).

    Parameters
    ----------
    altitude_km : float
        Altitude above the equatorial radius, km.

    Returns
    -------
    float
        Inclination, degrees.

    Examples
    --------
    >>> round(sso_inclination_deg(500.0), 1)  # the textbook 97.4 degrees at 500 km
    97.4
    """
    a = WGS84_A_M / 1e3 + altitude_km
    rate = 2 * math.pi / (365.2422 * 86400.0)
    cos_i = -rate * 2.0 * a**3.5 / (3.0 * J2 * (WGS84_A_M / 1e3) ** 2 * math.sqrt(GM_KM3_S2))
    if not -1.0 <= cos_i <= 1.0:  # J2 precesses too slowly that high (above about 5,970 km)
        raise InvalidParameterError(
            f"--altitude-km: no sun-synchronous orbit at {altitude_km:g} km (J2 is too weak "
            "there); give --inclination-deg"
        )
    return math.degrees(math.acos(cos_i))


def parse_walker(text: str) -> tuple[int, int, int]:
    """``T/P/F`` as integers, checked (``P`` divides ``T``, ``0 <= F < P``).

    Parameters
    ----------
    text : str
        E.g. ``"20/5/1"``.

    Returns
    -------
    tuple of int
        ``(T, P, F)``.

    Examples
    --------
    >>> parse_walker("20/5/1")
    (20, 5, 1)
    """
    parts = text.split("/")
    try:
        t, p, f = (int(x) for x in parts)
    except ValueError:
        raise InvalidParameterError(f"--walker: expected T/P/F integers, got {text!r}") from None
    if t < 1:
        raise InvalidParameterError(
            f"--walker: T must be at least 1 (an empty constellation), got {t}"
        )
    if t > MAX_SATELLITES:
        raise InvalidParameterError(f"--walker: T {t} is more than {MAX_SATELLITES} satellites")
    if p < 1 or t % p:
        raise InvalidParameterError(f"--walker: P {p} must divide T {t}")
    if not 0 <= f < p:
        raise InvalidParameterError(f"--walker: F {f} must be in 0..P-1 ({p - 1})")
    return t, p, f


def walker(
    total: int,
    planes: int,
    phasing: int,
    *,
    altitude_km: float,
    inclination_deg: float,
    epoch: datetime,
) -> list[Satellite]:
    """A Walker-delta ``T/P/F`` constellation of circular orbits.

    Plane ``p`` (1-based) has its ascending node at ``360 (p-1) / P`` degrees; slot ``s``
    (1-based) of plane ``p`` has mean anomaly ``360 (s-1) P / T + 360 F (p-1) / T``.

    Parameters
    ----------
    total, planes, phasing : int
        ``T``, ``P``, ``F``.
    altitude_km : float
        Altitude above the equatorial radius, km (100-2000).
    inclination_deg : float
        Inclination, degrees (0-180).
    epoch : datetime.datetime
        Epoch of the elements (the simulation's start).

    Returns
    -------
    list of Satellite
        Named ``W<plane>-<slot>``.

    Examples
    --------
    >>> sats = walker(4, 2, 1, altitude_km=500, inclination_deg=53, epoch=datetime(2026, 1, 1, tzinfo=UTC))
    >>> [s.name for s in sats], [round(s.elements[3]) for s in sats]
    (['W1-1', 'W1-2', 'W2-1', 'W2-2'], [0, 180, 90, 270])
    """
    if not (math.isfinite(altitude_km) and 100.0 <= altitude_km <= 2000.0):
        raise InvalidParameterError(
            f"--altitude-km: expected a low Earth orbit altitude in 100-2000 km, got {altitude_km!r}"
        )
    if not (math.isfinite(inclination_deg) and 0.0 <= inclination_deg <= 180.0):
        raise InvalidParameterError(
            f"--inclination-deg: expected 0-180 degrees, got {inclination_deg!r}"
        )
    a = WGS84_A_M / 1e3 + altitude_km
    n = math.sqrt(GM_KM3_S2 / a**3) * 60.0  # rad/min
    jd = sum(julian(epoch))
    per = total // planes
    sats = []
    for p in range(planes):
        for s in range(per):
            ma = (360.0 * s / per + 360.0 * phasing * p / total) % 360.0
            sats.append(
                Satellite(
                    f"W{p + 1}-{s + 1}", elements=(jd, inclination_deg, 360.0 * p / planes, ma, n)
                )
            )
    return sats


def gmst_rad(jd: np.ndarray, fr: np.ndarray) -> np.ndarray:
    """Greenwich mean sidereal angle (IAU-82, as SGP4's TEME frame defines it), radians.

    Parameters
    ----------
    jd, fr : numpy.ndarray
        Julian days and fractions (UT1 taken as UTC).

    Returns
    -------
    numpy.ndarray
        Angles in [0, 2π).

    Examples
    --------
    >>> round(float(np.degrees(gmst_rad(np.array([2451545.0]), np.array([0.0]))[0])), 4)  # J2000.0
    280.4606
    """
    from sgp4.propagation import gstime

    return np.array([gstime(float(a) + float(b)) for a, b in zip(jd, fr, strict=True)])


def propagate(
    sats: list[Satellite], start: datetime, seconds: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Earth-fixed positions and velocities of every satellite at ``start + seconds``.

    Parameters
    ----------
    sats : list of Satellite
        The satellites.
    start : datetime.datetime
        Time zero.
    seconds : numpy.ndarray
        ``(n,)`` seconds after ``start``.

    Returns
    -------
    r : numpy.ndarray
        ``(len(sats), n, 3)`` positions, metres, Earth-fixed (ITRF, polar motion neglected).
    v : numpy.ndarray
        ``(len(sats), n, 3)`` velocities in the rotating frame, m/s.

    Raises
    ------
    dyntarget.errors.DataFileError
        When sgp4 fails for a satellite (decayed, eccentricity out of range).

    Examples
    --------
    >>> sats = walker(2, 1, 0, altitude_km=500, inclination_deg=97.4, epoch=datetime(2026, 1, 1, tzinfo=UTC))
    >>> r, v = propagate(sats, datetime(2026, 1, 1, tzinfo=UTC), np.array([0.0, 60.0]))
    >>> r.shape, round(float(np.linalg.norm(v[0, 0])) / 1e3, 1)  # km/s, Earth-fixed frame (retrograde)
    ((2, 2, 3), 7.7)
    """
    from sgp4.api import SatrecArray

    jd0, fr0 = julian(start)
    secs = np.asarray(seconds, np.float64)
    jd = np.full(secs.shape, jd0)
    fr = fr0 + secs / 86400.0
    arr = SatrecArray([s.satrec() for s in sats])
    err, r, v = arr.sgp4(jd, fr)
    bad = np.argwhere(err != 0)
    if len(bad):
        i, j = bad[0]
        raise DataFileError(
            f"satellite {sats[i].name}: sgp4 error code {int(err[i, j])} at "
            f"{secs[j]:g} s after --start (decayed or invalid orbit)"
        )
    theta = gmst_rad(jd, fr)
    c, s = np.cos(theta)[None, :], np.sin(theta)[None, :]
    x = c * r[..., 0] + s * r[..., 1]
    y = -s * r[..., 0] + c * r[..., 1]
    vx = c * v[..., 0] + s * v[..., 1] + OMEGA_EARTH * y
    vy = -s * v[..., 0] + c * v[..., 1] - OMEGA_EARTH * x
    pos = np.stack([x, y, r[..., 2]], axis=-1) * 1e3
    vel = np.stack([vx, vy, v[..., 2]], axis=-1) * 1e3
    return pos, vel


def geodetic_to_ecef(lat_deg, lon_deg, h_m) -> np.ndarray:
    """WGS 84 geodetic coordinates to Earth-fixed Cartesian, metres.

    Parameters
    ----------
    lat_deg, lon_deg, h_m : array-like
        Latitude, longitude (degrees) and height above the ellipsoid (metres).

    Returns
    -------
    numpy.ndarray
        ``(..., 3)`` positions, metres.

    Examples
    --------
    >>> geodetic_to_ecef(0.0, 90.0, 0.0).round(3).tolist()
    [0.0, 6378137.0, 0.0]
    """
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    h = np.asarray(h_m, np.float64)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack(
        np.broadcast_arrays(
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - WGS84_E2) + h) * np.sin(lat),
        ),
        axis=-1,
    )


def ecef_to_geodetic(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Earth-fixed Cartesian (metres) to WGS 84 latitude, longitude (degrees) and height (m).

    Parameters
    ----------
    r : numpy.ndarray
        ``(..., 3)`` positions, metres.

    Returns
    -------
    tuple of numpy.ndarray
        Latitude, longitude, height.

    Examples
    --------
    >>> lat, lon, h = ecef_to_geodetic(geodetic_to_ecef(45.0, -120.0, 500e3))
    >>> round(float(lat), 9), round(float(lon), 9), round(float(h), 3)
    (45.0, -120.0, 500000.0)
    """
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(6):  # fixed point: converges to 1e-12 rad in a few steps in LEO
        h = _height(p, z, lat)
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    h = _height(p, z, lat)
    return np.degrees(lat), np.degrees(lon), h


def _height(p: np.ndarray, z: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Height above the ellipsoid at geodetic latitude ``lat`` (well defined at the poles)."""
    s, c = np.sin(lat), np.cos(lat)
    return p * c + z * s - WGS84_A_M * np.sqrt(1.0 - WGS84_E2 * s * s)


def geodetic_up(lat_deg, lon_deg) -> np.ndarray:
    """Unit ellipsoid normals (geodetic "up") at the given latitudes and longitudes.

    Parameters
    ----------
    lat_deg, lon_deg : array-like
        Degrees.

    Returns
    -------
    numpy.ndarray
        ``(..., 3)`` unit vectors.

    Examples
    --------
    >>> geodetic_up(90.0, 0.0).round(12).tolist()
    [0.0, 0.0, 1.0]
    """
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    return np.stack(
        np.broadcast_arrays(np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)),
        axis=-1,
    )


def off_nadir_deg(sat_r: np.ndarray, target_r: np.ndarray) -> np.ndarray:
    """Angle between the satellite's geodetic nadir and the line of sight to a target, degrees.

    Parameters
    ----------
    sat_r, target_r : numpy.ndarray
        ``(..., 3)`` Earth-fixed positions, metres (broadcast together).

    Returns
    -------
    numpy.ndarray
        Off-nadir angles, degrees.

    Examples
    --------
    >>> sat = geodetic_to_ecef(0.0, 0.0, 500e3)
    >>> round(float(off_nadir_deg(sat, geodetic_to_ecef(0.0, 0.0, 0.0))), 9)
    0.0
    """
    lat, lon, _ = ecef_to_geodetic(np.asarray(sat_r, np.float64))
    down = -geodetic_up(lat, lon)
    los = np.asarray(target_r, np.float64) - sat_r
    los = los / np.linalg.norm(los, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(los * down, axis=-1), -1.0, 1.0)))


def sun_direction(start: datetime, seconds: np.ndarray) -> np.ndarray:
    """Unit vectors to the Sun in the Earth-fixed frame (low-precision almanac formula).

    The Astronomical Almanac's low-precision solar coordinates (good to 0.01° from 1950
    to 2050): mean longitude and anomaly, ecliptic longitude, obliquity; then right
    ascension and declination rotated by the Greenwich sidereal angle.

    Parameters
    ----------
    start : datetime.datetime
        Time zero (UTC).
    seconds : numpy.ndarray
        Seconds after ``start``.

    Returns
    -------
    numpy.ndarray
        ``(n, 3)`` unit vectors.

    Examples
    --------
    >>> d = sun_direction(datetime(2026, 6, 21, 12, tzinfo=UTC), np.array([0.0]))[0]
    >>> round(float(np.degrees(np.arcsin(d[2]))), 1)  # declination at the June solstice
    23.4
    """
    jd0, fr0 = julian(start)
    secs = np.asarray(seconds, np.float64)
    fr = fr0 + secs / 86400.0
    n = jd0 - 2451545.0 + fr
    mean_lon = np.radians((280.460 + 0.9856474 * n) % 360.0)
    g = np.radians((357.528 + 0.9856003 * n) % 360.0)
    lam = mean_lon + np.radians(1.915) * np.sin(g) + np.radians(0.020) * np.sin(2 * g)
    eps = np.radians(23.439 - 4e-7 * n)
    eci = np.stack([np.cos(lam), np.cos(eps) * np.sin(lam), np.sin(eps) * np.sin(lam)], axis=-1)
    theta = gmst_rad(np.full(secs.shape, jd0), fr)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack(
        [c * eci[:, 0] + s * eci[:, 1], -s * eci[:, 0] + c * eci[:, 1], eci[:, 2]], axis=-1
    )


def utc(text: str) -> datetime:
    """An ISO 8601 instant as aware UTC (no zone: UTC), for ``--start``.

    Parameters
    ----------
    text : str
        E.g. ``2026-06-01T00:00:00Z``.

    Returns
    -------
    datetime.datetime
        The instant.

    Examples
    --------
    >>> utc("2026-06-01T00:00:00Z").isoformat()
    '2026-06-01T00:00:00+00:00'
    """
    try:
        when = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise InvalidParameterError(
            f"--start: expected an ISO 8601 instant, got {text!r}"
        ) from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    when = when.astimezone(UTC)
    if not 1957 <= when.year <= 2056:  # the TLE two-digit year covers 1957-2056
        raise InvalidParameterError(f"--start: expected a year in 1957-2056, got {when.year}")
    return when
