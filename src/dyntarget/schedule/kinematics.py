"""Kinematics of the NFOV: orbit geometry, agility presets, look vectors, visibility windows.

The model below is the scheduling model as a whole; this module holds its geometry
(:class:`OrbitGeometry`), the agility presets (:class:`Agility`) and the field of
regard (:func:`visibility_windows`); :mod:`dyntarget.schedule.feasibility` times the
pointings.


The paper plans in the image plane as if the NFOV sensor could take every
pointing at once. Here the spacecraft moves and the sensor has finite agility.

Model (documented in ``docs/onboard.md``):

* **Orbit**: circular, altitude ``h`` over a spherical, non-rotating Earth
  (mean radius 6371 km; GM = 3.986004418e14 m³/s², WGS 84). The orbital speed is
  ``sqrt(GM / (R + h))`` and the nadir point moves over the ground at
  ``sqrt(GM / (R + h)) * R / (R + h)`` — 7.06 km/s at 500 km.
* **Scene placement**: time ``t = 0`` is the WFOV acquisition. The WFOV footprint
  centre lies ``look_ahead_m`` ahead of nadir along the ground track. WFOV
  image "up" (decreasing row) is the flight direction, as for the planners;
  pixel ``(x, y)`` lies ``look_ahead_m + ((H - 1) / 2 - y) * gsd`` ahead of
  the nadir point at ``t = 0`` and ``(x - (W - 1) / 2) * gsd`` across track.
  Earth rotation (at most 0.46 km/s) is ignored.
* **Field of regard**: a target can be observed while its off-nadir angle is at
  most ``field_of_regard_deg`` and its along-track look angle is no more than
  ``aft_limit_deg`` behind nadir (default 0: the sensor looks forward and down,
  never back, so a target the spacecraft has passed is lost).
* **Agility**: a slew between two look directions of angle ``φ`` takes the
  time of a rest-to-rest trapezoidal rate profile (acceleration ``α`` up to the
  rate ``ω``): ``2 sqrt(φ / α)`` when ``φ <= ω² / α``, else ``φ / ω + ω / α``;
  none below :data:`SLEW_RESOLUTION_DEG` (the same direction, up to rounding); then
  ``settle_s``; then the pointing is held for ``dwell_s`` (the sensor
  tracks the ground point meanwhile). The sensor starts at nadir at ``start_s``
  (the time the plan is ready: onboard classification and planning latency).

:func:`schedule` walks a trajectory in order, times every pointing and drops
those that cannot be taken inside their visibility window (or the budget);
with ``reorder=True`` it first sorts the pointings by the time they leave the
field of regard (earliest deadline first; the planner's order on ties), since
points the spacecraft passes first must be taken first. :func:`make_feasible`
flies whichever of the two keeps more pointings.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError

SLEW_RESOLUTION_DEG = 1e-5
"""A change of direction smaller than this (0.036 arcsec, 9 cm at 500 km) takes no slew.

Far below any attitude control's resolution, and far above the rounding of the angle between
two unit vectors of one direction computed two ways (the arc cosine of their dot product
turns a few units in the last place into about 1e-6 degrees, and with it a slew of
milliseconds for ``slow``: which one depended on the CPU's vector instructions, with
AVX-512 or without)."""

EARTH_RADIUS_M = 6_371_000.0
"""Mean Earth radius (IUGG)."""
GM_EARTH = 3.986004418e14
"""Earth's gravitational parameter, m³/s² (WGS 84)."""


@dataclass(frozen=True)
class OrbitGeometry:
    """Where the scene lies relative to the spacecraft, and when the plan starts.

    Parameters
    ----------
    altitude_m : float
        Orbit altitude, metres.
    look_ahead_m : float
        Along-track ground distance from nadir to the WFOV footprint centre at the
        acquisition (``t = 0``), metres.
    wfov_gsd_m : float
        WFOV ground sample distance, metres per pixel.
    start_s : float
        When the plan is ready and the sensor starts at nadir, seconds after the
        WFOV acquisition.
    """

    altitude_m: float = defaults.ALTITUDE_M
    look_ahead_m: float = defaults.LOOK_AHEAD_M
    wfov_gsd_m: float = 32.0
    start_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("altitude_m", "wfov_gsd_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InvalidParameterError(f"{name}: expected a positive number, got {v!r}")
        if not 100e3 <= self.altitude_m <= 2000e3:
            raise InvalidParameterError(
                f"altitude_m: expected a low Earth orbit (100-2000 km), got {self.altitude_m!r}"
            )
        for name in ("look_ahead_m", "start_s"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise InvalidParameterError(f"{name}: expected a finite number, got {v!r}")

    @property
    def ground_speed(self) -> float:
        """Speed of the nadir point over the ground, m/s."""
        r = EARTH_RADIUS_M + self.altitude_m
        return math.sqrt(GM_EARTH / r) * EARTH_RADIUS_M / r

    def ground(self, points: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """WFOV pixel ``(x, y)`` -> (along-track, cross-track) ground distance from nadir at t=0, m.

        Parameters
        ----------
        points : numpy.ndarray
            ``(n, 2)`` WFOV pixel coordinates ``(x, y)``.
        shape : tuple of int
            The WFOV image's ``(H, W)``.

        Returns
        -------
        along : numpy.ndarray
            ``(n,)`` distance ahead of nadir along the ground track, metres.
        cross : numpy.ndarray
            ``(n,)`` distance across track (positive towards increasing ``x``), metres.
        """
        h, w = shape
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        along = self.look_ahead_m + ((h - 1) / 2.0 - pts[:, 1]) * self.wfov_gsd_m
        cross = (pts[:, 0] - (w - 1) / 2.0) * self.wfov_gsd_m
        return along, cross


@dataclass(frozen=True)
class Agility:
    """How fast the NFOV line of sight can move. ``inf`` rate/acceleration: instantaneous.

    Parameters
    ----------
    name : str
        Preset name, recorded in schedules.
    max_rate_deg_s : float
        Largest slew rate, degrees per second.
    max_accel_deg_s2 : float
        Largest slew acceleration, degrees per second squared.
    settle_s : float
        Time to settle after each slew, seconds.
    dwell_s : float
        Time each pointing is held, seconds.
    field_of_regard_deg : float or None
        Largest off-nadir angle a target can be observed at, degrees; ``None``: no
        limit (unlimited agility).
    aft_limit_deg : float
        How far behind nadir (along-track look angle) the sensor may look, degrees.
    """

    name: str
    max_rate_deg_s: float = math.inf
    max_accel_deg_s2: float = math.inf
    settle_s: float = 0.0
    dwell_s: float = 0.0
    field_of_regard_deg: float | None = None
    aft_limit_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("max_rate_deg_s", "max_accel_deg_s2"):
            v = getattr(self, name)
            if not v > 0 or math.isnan(v):
                raise InvalidParameterError(f"{name}: expected a positive number, got {v!r}")
        for name in ("settle_s", "dwell_s", "aft_limit_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InvalidParameterError(f"{name}: expected a number >= 0, got {v!r}")
        f = self.field_of_regard_deg
        if f is not None and not 0 < f < 70:
            raise InvalidParameterError(
                f"field_of_regard_deg: expected an off-nadir angle in (0, 70) degrees, got {f!r}"
            )

    @property
    def unlimited(self) -> bool:
        """Whether there is no field of regard (``field_of_regard_deg is None``): every pointing is feasible at once."""
        return self.field_of_regard_deg is None

    def slew_time(self, angle_deg: np.ndarray | float) -> np.ndarray:
        """Rest-to-rest slew time (s) for angles in degrees (trapezoidal rate profile).

        Parameters
        ----------
        angle_deg : numpy.ndarray or float
            Slew angles, degrees (the sign is ignored).

        Returns
        -------
        numpy.ndarray
            Slew times, seconds, of the same shape (settling not included; 0 below
            :data:`SLEW_RESOLUTION_DEG`).
        """
        phi = np.abs(np.asarray(angle_deg, np.float64))
        phi = np.where(phi < SLEW_RESOLUTION_DEG, 0.0, phi)
        w, a = self.max_rate_deg_s, self.max_accel_deg_s2
        if math.isinf(a):
            return phi / w if math.isfinite(w) else np.zeros_like(phi)
        if math.isinf(w):
            return 2.0 * np.sqrt(phi / a)
        return np.where(phi <= w * w / a, 2.0 * np.sqrt(phi / a), phi / w + w / a)

    def slew_time_one(self, angle_deg: float) -> float:
        """:meth:`slew_time` of one angle, in float arithmetic (the same result, faster).

        Parameters
        ----------
        angle_deg : float
            Slew angle, degrees (the sign is ignored).

        Returns
        -------
        float
            Slew time, seconds (settling not included).
        """
        phi = abs(angle_deg)
        if phi < SLEW_RESOLUTION_DEG:
            phi = 0.0
        w, a = self.max_rate_deg_s, self.max_accel_deg_s2
        if math.isinf(a):
            return phi / w if math.isfinite(w) else 0.0
        if math.isinf(w) or phi <= w * w / a:
            return 2.0 * math.sqrt(phi / a)
        return phi / w + w / a


AGILITY: dict[str, Agility] = {
    "unlimited": Agility("unlimited"),
    "fast": Agility(
        "fast",
        max_rate_deg_s=10.0,
        max_accel_deg_s2=20.0,
        settle_s=0.05,
        dwell_s=0.05,
        field_of_regard_deg=30.0,
    ),
    "slow": Agility(
        "slow",
        max_rate_deg_s=1.0,
        max_accel_deg_s2=0.5,
        settle_s=1.0,
        dwell_s=0.1,
        field_of_regard_deg=30.0,
    ),
}
"""Agility presets (see ``docs/onboard.md`` for where the numbers come from).

* ``unlimited``: the paper's assumption — every pointing, no time, no limits.
* ``fast``: a steerable-mirror NFOV sensor (degrees per second slews, tens of
  milliseconds to settle and expose).
* ``slow``: a small satellite that points its whole body with reaction wheels
  (about 1 °/s, a second to settle).
"""


def get_agility(name: str) -> Agility:
    """The agility preset called ``name`` (:data:`AGILITY`).

    Parameters
    ----------
    name : str
        A preset name (``unlimited``, ``fast``, ``slow``...).

    Returns
    -------
    Agility
        The preset.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For an unknown name.
    """
    try:
        return AGILITY[name]
    except KeyError:
        raise InvalidParameterError(
            f"agility: unknown preset {name!r}; choose one of: {', '.join(AGILITY)}"
        ) from None


def look_vectors(
    geometry: OrbitGeometry,
    along: np.ndarray,
    cross: np.ndarray,
    t: float | np.ndarray,
    height_m: float | np.ndarray = 0.0,
) -> np.ndarray:
    """Unit line-of-sight vectors ``(n, 3)`` from the spacecraft to ground points at time(s) ``t``
    (or to the points ``height_m`` above them, e.g. a plume top over its ground position).

    Frame: x along the velocity, y across track, z up (away from Earth's centre).

    Parameters
    ----------
    geometry : OrbitGeometry
        The orbit (altitude and ground speed).
    along : numpy.ndarray
        Along-track ground distances from nadir at ``t = 0``, metres.
    cross : numpy.ndarray
        Cross-track ground distances, metres.
    t : float or numpy.ndarray
        Times, seconds after the WFOV acquisition (broadcast with ``along``).
    height_m : float or numpy.ndarray
        Height of the points above the sphere, metres (0: the ground points; broadcast
        with ``along``).

    Returns
    -------
    numpy.ndarray
        ``(..., 3)`` unit vectors.

    Examples
    --------
    Straight down at the nadir, whatever the height; 500 km ahead of a spacecraft 500 km
    up, a top 10 km up is seen 0.6 deg higher than the ground under it:

    >>> g = OrbitGeometry(altitude_m=500e3)
    >>> look_vectors(g, np.array([0.0]), np.array([0.0]), 0.0, 10e3).round(12).tolist()
    [[0.0, 0.0, -1.0]]
    >>> ground, top = (look_vectors(g, np.array([500e3]), np.array([0.0]), 0.0, h) for h in (0.0, 10e3))
    >>> round(float(angle_between_deg(ground, top)[0]), 2)
    0.6
    """
    r = EARTH_RADIUS_M
    rel = (np.asarray(along, np.float64) - geometry.ground_speed * np.asarray(t, np.float64)) / r
    c = np.asarray(cross, np.float64) / r
    rh = r + np.asarray(height_m, np.float64)  # the ground's radius exactly when height_m is 0
    target = np.stack(
        np.broadcast_arrays(
            rh * np.sin(rel) * np.cos(c), rh * np.sin(c), rh * np.cos(rel) * np.cos(c)
        ),
        axis=-1,
    )
    los = target - np.array([0.0, 0.0, r + geometry.altitude_m])
    unit: np.ndarray = los / np.linalg.norm(los, axis=-1, keepdims=True)
    return unit


def _look_one(
    geometry: OrbitGeometry, along: float, cross: float, t: float, height_m: float = 0.0
) -> tuple[float, ...]:
    """:func:`look_vectors` of one point, in float arithmetic (the same floats)."""
    r = EARTH_RADIUS_M
    rel = (float(along) - geometry.ground_speed * t) / r
    c = float(cross) / r
    rh = r + height_m
    x = rh * math.sin(rel) * math.cos(c) - 0.0
    y = rh * math.sin(c) - 0.0
    z = rh * math.cos(rel) * math.cos(c) - (r + geometry.altitude_m)
    norm = math.sqrt(0.0 + x * x + y * y + z * z)
    return (x / norm, y / norm, z / norm)


def under_sight(
    geometry: OrbitGeometry,
    along: npt.ArrayLike,
    cross: npt.ArrayLike,
    t: npt.ArrayLike,
    height_m: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """The ground position under the point ``height_m`` up on the line of sight, at ``t``,
    to the ground point ``(along, cross)``: where a top at that height lies, seen there.

    The line of sight meets the sphere of radius ``R + height_m`` first (on the
    spacecraft's side) at that point; its ground position is the same direction from
    Earth's centre. The inverse of :func:`look_vectors` ``height_m=``: the line of sight
    to the returned position, ``height_m`` up, at ``t`` is the one to the ground point.
    :func:`dyntarget.parallax.unshift_xy` is the same closed form on the parallax
    module's sphere and map (radius 6,371,008.8 m, azimuthal about the nadir); this one
    keeps the schedule's own (6,371,000 m, along- and cross-track angles), so that the
    sensor's line of sight to the top is exactly the aimed one: slews of a few
    thousandths of a degree, whose time grows as its square root, are measured in it.

    Parameters
    ----------
    geometry : OrbitGeometry
        The orbit (altitude and ground speed).
    along, cross : array_like
        The ground points the lines of sight meet, metres from the nadir at ``t = 0``.
    t : array_like
        When, seconds after the WFOV acquisition (broadcast with ``along``).
    height_m : array_like
        The heights, metres above the sphere (>= 0, below the spacecraft).

    Returns
    -------
    tuple of numpy.ndarray
        ``(along, cross)`` of the ground positions under those points, metres.

    Examples
    --------
    Looking straight down, the top is over the ground point; a top 10 km up whose line
    of sight meets the ground 500 km ahead of a spacecraft 500 km up lies 11.2 km nearer
    the spacecraft:

    >>> g = OrbitGeometry(altitude_m=500e3)
    >>> a, c = under_sight(g, [0.0, 500e3], [0.0, 0.0], 0.0, 10e3)
    >>> a[0], round(float(500e3 - a[1]) / 1e3, 2), c.tolist()
    (np.float64(0.0), 11.22, [0.0, 0.0])
    """
    r = EARTH_RADIUS_M
    a, c0, ts = np.broadcast_arrays(
        np.asarray(along, np.float64), np.asarray(cross, np.float64), np.asarray(t, np.float64)
    )
    u = look_vectors(geometry, a, c0, ts)
    sz = r + geometry.altitude_m  # the spacecraft at (0, 0, sz)
    b = sz * u[..., 2]  # S . u
    rh = r + np.asarray(height_m, np.float64)
    s = -b - np.sqrt(np.maximum(b * b - sz * sz + rh * rh, 0.0))  # the nearer crossing
    p = s[..., None] * u
    p[..., 2] += sz
    rel = np.arctan2(p[..., 0], p[..., 2])
    c = np.arcsin(np.clip(p[..., 1] / np.linalg.norm(p, axis=-1), -1.0, 1.0))
    return rel * r + geometry.ground_speed * ts, c * r


def off_nadir_deg(los: np.ndarray) -> np.ndarray:
    """Angle between the line of sight and nadir, degrees.

    Parameters
    ----------
    los : numpy.ndarray
        ``(..., 3)`` unit line-of-sight vectors (z up).

    Returns
    -------
    numpy.ndarray
        Off-nadir angles, degrees.
    """
    deg: np.ndarray = np.degrees(np.arccos(np.clip(-los[..., 2], -1.0, 1.0)))
    return deg


def pitch_deg(los: np.ndarray) -> np.ndarray:
    """Along-track look angle, degrees: positive ahead of nadir, negative behind.

    Parameters
    ----------
    los : numpy.ndarray
        ``(..., 3)`` unit line-of-sight vectors (x along the velocity, z up).

    Returns
    -------
    numpy.ndarray
        Along-track look angles, degrees.
    """
    deg: np.ndarray = np.degrees(np.arctan2(los[..., 0], -los[..., 2]))
    return deg


def angle_between_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between unit vectors, degrees (along the last axis).

    Parameters
    ----------
    a, b : numpy.ndarray
        Unit vectors ``(..., 3)``, broadcast together.

    Returns
    -------
    numpy.ndarray
        Angles in degrees, 0..180.
    """
    deg: np.ndarray = np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))
    return deg


def _angle_deg(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """:func:`angle_between_deg` of two unit 3-vectors given as tuples (same floats)."""
    dot = 0.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    return float(np.degrees(np.arccos(min(max(dot, -1.0), 1.0))))


def visibility_windows(
    geometry: OrbitGeometry, agility: Agility, along: np.ndarray, cross: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(t_in, t_out)`` per ground point: when it is inside the field of regard.

    ``t_in > t_out`` marks a point that is never inside (too far across track).
    Unlimited agility: ``(-inf, inf)``.

    How far ahead of and behind nadir a point can be seen depends only on its
    cross-track distance (and the orbit's altitude and the field of regard), so
    those distances are found once per cross-track value and kept (a pass asks
    for the same few WFOV columns frame after frame); the times follow from the
    along-track distance.

    Parameters
    ----------
    geometry : OrbitGeometry
        The orbit.
    agility : Agility
        Its field of regard and aft limit decide the windows.
    along : numpy.ndarray
        Along-track ground distances from nadir at ``t = 0``, metres.
    cross : numpy.ndarray
        Cross-track ground distances, metres.

    Returns
    -------
    t_in : numpy.ndarray
        When each point enters the field of regard, seconds.
    t_out : numpy.ndarray
        When it leaves, seconds.

    Examples
    --------
    >>> g = OrbitGeometry(altitude_m=500e3, look_ahead_m=0.0)
    >>> t_in, t_out = visibility_windows(g, AGILITY["fast"], np.array([0.0]), np.array([0.0]))
    >>> round(float(t_in[0]), 1), round(float(t_out[0]), 6)  # seen from 41 s before nadir to nadir
    (-41.4, 0.0)
    """
    along, cross = np.asarray(along, np.float64), np.asarray(cross, np.float64)
    if agility.unlimited:
        return np.full(along.shape, -np.inf), np.full(along.shape, np.inf)
    v = geometry.ground_speed
    visible_now, ahead, behind = _reach(geometry, agility, cross)
    t_in = np.where(visible_now, (along - ahead) / v, np.inf)
    t_out = np.where(visible_now, (along - behind) / v, -np.inf)
    return t_in, t_out


_REACH: dict[tuple[float, float, float], dict[float, tuple[bool, float, float]]] = {}
"""Per (altitude, field of regard, aft limit): cross-track distance -> (seen, ahead, behind)."""
REACH_CACHE_SIZE = 100_000
"""Most cross-track distances kept per geometry (a speed setting; results do not depend on it)."""


def _reach(
    geometry: OrbitGeometry, agility: Agility, cross: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(visible_now, ahead, behind)`` of :func:`_reach_compute`, looked up per distinct ``cross``."""
    if cross.size == 0:
        return np.zeros(cross.shape, bool), np.zeros(cross.shape), np.zeros(cross.shape)
    if not np.isfinite(cross).all():
        return _reach_compute(geometry, agility, cross)
    key = (
        float(geometry.altitude_m),
        float(agility.field_of_regard_deg),  # type: ignore[arg-type]
        float(agility.aft_limit_deg),
    )
    table = _REACH.setdefault(key, {})
    uniq, inverse = np.unique(cross, return_inverse=True)
    values = uniq.tolist()
    known = [table.get(c) for c in values]
    missing = [c for c, hit in zip(values, known, strict=True) if hit is None]
    if missing:
        seen, ahead, behind = _reach_compute(geometry, agility, np.asarray(missing, np.float64))
        found = dict(
            zip(
                missing,
                zip(seen.tolist(), ahead.tolist(), behind.tolist(), strict=True),
                strict=True,
            )
        )
        if len(table) + len(found) > REACH_CACHE_SIZE:
            table.clear()
        table.update(found)
        known = [hit if hit is not None else found[c] for c, hit in zip(values, known, strict=True)]
    arr = np.asarray(known, np.float64).reshape(-1, 3)[inverse.reshape(cross.shape)]
    return arr[..., 0] > 0.5, arr[..., 1], arr[..., 2]


def _reach_compute(
    geometry: OrbitGeometry, agility: Agility, cross: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visible at nadir's along-track position, and how far ahead / behind nadir (m), by bisection."""
    fov = agility.field_of_regard_deg
    assert fov is not None  # limited agility

    def los_at(delta: np.ndarray) -> np.ndarray:  # the target ``delta`` metres ahead of nadir
        return look_vectors(geometry, delta, cross, 0.0)

    def bisect(
        pred: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray
    ) -> np.ndarray:  # largest delta in [lo, hi] with pred true (pred true at lo)
        for _ in range(60):
            mid = (lo + hi) / 2
            ok = pred(mid)
            lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
        return lo

    reach = geometry.altitude_m * 10.0  # far beyond any field of regard below 70 degrees
    zero = np.zeros_like(cross)
    visible_now = off_nadir_deg(los_at(zero)) <= fov
    ahead = bisect(lambda d: off_nadir_deg(los_at(d)) <= fov, zero, zero + reach)
    behind = -bisect(
        lambda d: (
            (off_nadir_deg(los_at(-d)) <= fov)
            & (pitch_deg(los_at(-d)) >= -agility.aft_limit_deg - 1e-9)
        ),
        zero,
        zero + reach,
    )
    return visible_now, ahead, behind
