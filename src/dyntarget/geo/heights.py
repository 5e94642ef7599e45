"""Plume-top height from a look-ahead look and geostationary images (LEO+GEO parallax).

A plume top at height ``h`` is seen by each imager displaced on the ground, away from the
imager, by its parallax (:mod:`dyntarget.parallax`, exact on the sphere; ``h tan(theta)``
to first order). The low-orbit look-ahead and a geostationary (GEO) imager see it from
different directions, so the difference of the two apparent positions measures ``h``
(Zaksek et al. 2013: 0.6 km from SEVIRI and MODIS). Each sighting ``i`` (time ``t_i``,
view zenith ``theta_i`` and azimuth ``phi_i`` of the line of sight towards the imager at
the apparent position, imager altitude ``H_i``) of the same plume feature gives

    a_i = p0 + v (t_i - t_ref) + s_i(h) u_i

on a local ground map (``x`` east, ``y`` north, metres): ``p0`` the feature's true
ground position at ``t_ref`` (the first sighting's time, the look-ahead's by
convention), ``v`` its ground velocity, ``u_i = -(sin phi_i, cos phi_i)`` the unit
vector away from the imager and ``s_i(h) = D_i - sight_at_height(H_i, D_i, h)`` the
parallax seen at the apparent point, ``D_i`` its ground distance from the imager's
nadir (:func:`ground_distance_for_zenith`). :func:`fit_geo_height` solves for
``(p0, v, h)`` by weighted least squares (``scipy.optimize.least_squares``) with the
covariance of the estimate.

**The drift between the looks.** A GEO image usable at the look-ahead's time was taken
minutes before it (``fly --geo``'s defaults: every 600 s, usable 300 s after): the
feature moves meanwhile, and a drift along the parallax baseline is indistinguishable
from a height. It is handled by measuring the motion: with **two GEO images or more**
(taken at different times: the last two usable) the velocity ``v`` is solved from the
GEO track itself (a feature at a constant height moves on the GEO image as on the
ground) and the GEO position is carried to the look's time with it; the height's
standard deviation then carries the extrapolation's. With **one** GEO image a Gaussian
**wind prior** (``wind_prior``, ``wind_prior_sigma_mps``: a forecast, or zero drift for
the envelope of an attached plume) closes the system; with a **simultaneous** GEO image
(same ``t``) the drift does not enter. Assumed: the feature keeps its height and its
velocity over the sightings (a column still rising breaks both: it biases the height
by the rise's parallax on the GEO track).

**Measuring the GEO position.** The same feature must be measured in both: the GEO's
cells are tens of look-ahead pixels wide, and a plume's thin edges, which the look-ahead
sees, fall below a GEO detection. :func:`match_offset` (used by
``benchmarks/geo_heights.py``) moves the look-ahead's plume field (its opacity
``1 - exp(-tau)``, or its mask) and averages it onto the GEO grid until it best matches the
plume's unmixed cover fraction on the GEO image (:func:`dyntarget.geo.unmix`: per cell,
the share the plume covers), to a fraction of a cell, with the offset's standard
deviation from the GEO noise; the GEO sighting is then the look-ahead's centroid moved by
that offset. :func:`fraction_centroid` (the centroid of the unmixed fraction, with its
noise) is the simpler measure and the match's starting point; alone it is biased wherever
the two imagers see different parts of the plume (the centroid of a plume whose thin tail
the GEO misses lies upwind of the look-ahead's). A plume cut by a frame's edge has another
centroid: the look must hold the whole plume.

**Degenerate geometry.** When the look-ahead looks from nearly the GEO's direction at
nearly its zenith angle, both displace the top alike and the pair measures nothing:
``tan(theta_L) u_L - tan(theta_G) u_G``, the height's baseline (``baseline`` in the
result, metres of disparity per metre of height), is small and the standard deviation
large; :func:`fit_geo_height` reports ``ok=False`` with the reason below
:data:`MIN_BASELINE`.

Examples
--------
A 10 km top seen by a look-ahead 45 deg from the south (the spacecraft behind it,
azimuth 180 deg) and by a GEO 40 deg from the north at the same time: the look-ahead
sees it 9.98 km north of its ground point, the GEO 8.37 km south (the zenith angles
are those at the apparent points).

>>> top = 10e3
>>> dl = parallax_offset(45.0, 180.0, 500e3, top)
>>> dg = parallax_offset(40.0, 0.0, GEO_ALTITUDE_M, top)
>>> [round(float(v)) + 0 for v in dl], [round(float(v)) + 0 for v in dg]
([0, 9977], [0, -8373])
>>> leo = Sighting(0.0, 0.0 + dl[0], 5000.0 + dl[1], 45.0, 180.0, 500e3, 30.0)
>>> geo = Sighting(0.0, 0.0 + dg[0], 5000.0 + dg[1], 40.0, 0.0, GEO_ALTITUDE_M, 200.0)
>>> fit = fit_geo_height([leo, geo], wind_prior=(0.0, 0.0), wind_prior_sigma_mps=5.0)
>>> fit.ok, round(fit.height_m), round(fit.height_sigma_m), round(fit.baseline, 2)
(True, 10000, 110, 1.84)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError

GEO_ALTITUDE_M = 35_786_000.0
"""Altitude of a geostationary satellite above the sphere, metres."""
MIN_BASELINE = 0.05
"""Least disparity per metre of height (``|tan(theta_1) u_1 - tan(theta_2) u_2|`` over
the best pair of sightings) for which :func:`fit_geo_height` gives a height: below it a
100 m position error is more than 2 km of height."""
MAX_CONDITION = 1e9
"""Whitened Jacobian condition number above which the fit is reported degenerate."""
MAX_HEIGHT_M = 30_000.0
"""Largest height the fit accepts as a result, metres (a feature above it is no plume top)."""


def _finite(name: str, v: object, lo: float, hi: float) -> float:
    """``v`` as a float in ``[lo, hi]``, or one line naming the problem."""
    try:
        f = float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{name}: expected a number, got {v!r:.60}") from None
    if not (math.isfinite(f) and lo <= f <= hi):
        raise InvalidParameterError(
            f"{name}: expected a finite value in [{lo:g}, {hi:g}], got {v!r}"
        )
    return f


def ground_distance_for_zenith(altitude_m: float, zenith_deg: float) -> float:
    """Ground (arc) distance from an imager's nadir at which its view zenith is ``zenith_deg``.

    The inverse of :func:`dyntarget.parallax.view_zenith` (terrain at sea level): in the
    triangle centre-ground point-imager the sine rule gives the angle at the imager,
    ``asin(R sin(theta) / (R + H))``, and the central angle is ``theta`` less it.

    Parameters
    ----------
    altitude_m : float
        Imager altitude, metres.
    zenith_deg : float
        View zenith angle at the ground point, degrees, in ``[0, 89]``.

    Returns
    -------
    float
        Arc distance, metres.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For a NaN, infinite or out-of-range value.

    Examples
    --------
    >>> d = ground_distance_for_zenith(500e3, 48.37)
    >>> round(d / 1e3, 1), round(float(np.degrees(parallax.view_zenith(500e3, d))), 6)
    (500.1, 48.37)
    """
    h = _finite("altitude_m", altitude_m, 1.0, parallax.MAX_ALTITUDE_M)
    theta = math.radians(_finite("zenith_deg", zenith_deg, 0.0, 89.0))
    r = parallax.EARTH_RADIUS_M
    return r * (theta - math.asin(r * math.sin(theta) / (r + h)))


def parallax_offset(
    zenith_deg: float, azimuth_deg: float, altitude_m: float, height_m: float
) -> np.ndarray:
    """Ground offset ``(east, north)`` of a feature's apparent position from its true one.

    The feature at ``height_m`` is seen at an apparent ground point where the view zenith
    is ``zenith_deg`` and the line of sight leaves towards the imager at ``azimuth_deg``;
    its true ground point lies ``D - sight_at_height(H, D, h)`` nearer the imager
    (:func:`dyntarget.parallax.sight_at_height`, exact on the sphere), so the apparent
    point is that far along ``-(sin(az), cos(az))``.

    Parameters
    ----------
    zenith_deg : float
        View zenith at the apparent point, degrees (``[0, 89]``).
    azimuth_deg : float
        Azimuth of the line of sight towards the imager, degrees clockwise from north.
    altitude_m : float
        Imager altitude, metres.
    height_m : float
        Feature height, metres (``[0, 30,000]``).

    Returns
    -------
    numpy.ndarray
        ``(2,)`` offset east and north, metres.

    Examples
    --------
    10 km at 50 deg, the imager due south: 10 km x tan(50 deg) = 11.92 km north on flat
    ground; 0.3 % less on the sphere from 500 km up (from the apparent point the line of
    sight meets the height where the local vertical has turned towards it).

    >>> dx, dy = parallax_offset(50.0, 180.0, 500e3, 10e3)
    >>> round(float(dx), 6) + 0.0, round(float(dy) / 1e3, 2)
    (0.0, 11.89)
    """
    h = _finite("height_m", height_m, 0.0, MAX_HEIGHT_M)
    az = math.radians(_finite("azimuth_deg", azimuth_deg, -360.0, 360.0))
    alt = _finite("altitude_m", altitude_m, 1.0, parallax.MAX_ALTITUDE_M)
    d = ground_distance_for_zenith(alt, zenith_deg)
    s = d - float(parallax.sight_at_height(alt, d, h))
    return np.array([-s * math.sin(az), -s * math.cos(az)])


@dataclass(frozen=True)
class Sighting:
    """One imager's sighting of a plume feature: where it appeared, when, from where.

    Parameters
    ----------
    t_s : float
        Time of the sighting, seconds (any clock shared by the sightings).
    x_m, y_m : float
        Apparent ground position, metres east and north on a local map.
    zenith_deg : float
        View zenith angle at the apparent position, degrees (``[0, 89]``).
    azimuth_deg : float
        Azimuth of the line of sight towards the imager at the apparent position,
        degrees clockwise from north (a look-ahead flying north looks back at 180).
    altitude_m : float
        Imager altitude, metres (:data:`GEO_ALTITUDE_M` for a GEO).
    sigma_m : float
        Standard deviation of the position per axis, metres (> 0).

    Examples
    --------
    >>> Sighting(0.0, 1.0, 2.0, 45.0, 180.0, 500e3, 30.0).sigma_m
    30.0
    """

    t_s: float
    x_m: float
    y_m: float
    zenith_deg: float
    azimuth_deg: float
    altitude_m: float
    sigma_m: float

    def __post_init__(self) -> None:
        _finite("Sighting t_s", self.t_s, -1e9, 1e9)
        _finite("Sighting x_m", self.x_m, -2e7, 2e7)
        _finite("Sighting y_m", self.y_m, -2e7, 2e7)
        _finite("Sighting zenith_deg", self.zenith_deg, 0.0, 89.0)
        _finite("Sighting azimuth_deg", self.azimuth_deg, -360.0, 360.0)
        _finite("Sighting altitude_m", self.altitude_m, 1.0, parallax.MAX_ALTITUDE_M)
        if not _finite("Sighting sigma_m", self.sigma_m, 0.0, 1e6) > 0:
            raise InvalidParameterError(f"Sighting sigma_m: expected > 0, got {self.sigma_m!r}")


@dataclass(frozen=True)
class GeoHeightFit:
    """A height solved from sightings by :func:`fit_geo_height`.

    Parameters
    ----------
    ok : bool
        Whether a height was solved (``False``: see ``reason``; the numbers are NaN).
    height_m, height_sigma_m : float
        Top height and its standard deviation, metres.
    wind_mps : tuple of float
        The feature's ground velocity ``(east, north)``, m/s.
    wind_sigma_mps : tuple of float
        Its standard deviations.
    ground_m : tuple of float
        The top's true ground position at ``t_ref_s``, metres (east, north).
    t_ref_s : float
        The time of ``ground_m`` (the first sighting's).
    baseline : float
        Largest ``|tan(theta_i) u_i - tan(theta_j) u_j|`` over pairs of sightings:
        metres of disparity per metre of height.
    chi2 : float
        Sum of squared whitened residuals.
    reason : str
        Why not solved, or ``""``.
    """

    ok: bool
    height_m: float
    height_sigma_m: float
    wind_mps: tuple[float, float]
    wind_sigma_mps: tuple[float, float]
    ground_m: tuple[float, float]
    t_ref_s: float
    baseline: float
    chi2: float
    reason: str = ""


def _unit_away(s: Sighting) -> np.ndarray:
    a = math.radians(s.azimuth_deg)
    return np.array([-math.sin(a), -math.cos(a)])


def _failed(reason: str, t_ref: float, baseline: float) -> GeoHeightFit:
    nan = math.nan
    return GeoHeightFit(
        False, nan, nan, (nan, nan), (nan, nan), (nan, nan), t_ref, baseline, nan, reason
    )


def _check_sightings(sightings: Sequence[Sighting]) -> None:
    """Two or more :class:`Sighting`, or one line naming the problem."""
    if isinstance(sightings, Sighting) or not isinstance(sightings, Sequence):
        raise InvalidParameterError("sightings: expected a sequence of Sighting")
    if len(sightings) < 2 or not all(isinstance(s, Sighting) for s in sightings):
        raise InvalidParameterError(
            f"sightings: expected two or more Sighting, got {len(sightings)} items"
        )


def _check_prior(
    wind_prior: tuple[float, float] | None, wind_prior_sigma_mps: float | None
) -> tuple[np.ndarray | None, float]:
    """The wind prior as an array and its standard deviation (``None, inf`` without one)."""
    if (wind_prior is None) != (wind_prior_sigma_mps is None):
        raise InvalidParameterError("wind_prior and wind_prior_sigma_mps: give both or neither")
    prior: np.ndarray | None = None
    prior_sd = math.inf
    if wind_prior is not None:
        if len(wind_prior) != 2:
            raise InvalidParameterError(
                f"wind_prior: expected (east, north) m/s, got {wind_prior!r}"
            )
        prior = np.array([_finite("wind_prior", w, -200.0, 200.0) for w in wind_prior])
        prior_sd = _finite("wind_prior_sigma_mps", wind_prior_sigma_mps, 0.0, 1e3)
        if not prior_sd > 0:
            raise InvalidParameterError("wind_prior_sigma_mps: expected > 0, got 0")
    return prior, prior_sd


def _first_order(
    tan_u: list[np.ndarray],
    dt: np.ndarray,
    w_obs: np.ndarray,
    obs: np.ndarray,
    prior: np.ndarray | None,
    prior_sd: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The whitened linear system of the first-order model (``s_i = h tan(theta_i)``):
    design matrix over ``(p0, v, h)`` and right-hand side, prior rows included."""
    a = np.zeros((2 * len(tan_u), 5))
    for i, tu in enumerate(tan_u):
        a[2 * i : 2 * i + 2, 0:2] = np.eye(2)
        a[2 * i : 2 * i + 2, 2:4] = dt[i] * np.eye(2)
        a[2 * i : 2 * i + 2, 4] = tu
    aw, bw = a * w_obs[:, None], obs * w_obs
    if prior is not None:
        aw = np.vstack([aw, np.hstack([np.zeros((2, 2)), np.eye(2) / prior_sd, np.zeros((2, 1))])])
        bw = np.concatenate([bw, prior / prior_sd])
    return aw, bw


def fit_geo_height(
    sightings: Sequence[Sighting],
    *,
    wind_prior: tuple[float, float] | None = None,
    wind_prior_sigma_mps: float | None = None,
) -> GeoHeightFit:
    """Solve a plume top's height, ground position and drift from two or more sightings.

    Least squares on the model of the module docstring, each sighting's position
    weighted by its ``sigma_m``, the wind prior (if given) as two more observations.
    Started from the first-order solution (``s_i = h tan(theta_i)``, linear), then
    refined on the exact parallax (``scipy.optimize.least_squares``, Levenberg-Marquardt).
    The covariance is ``(J^T J)^-1`` of the whitened Jacobian, scaled by the reduced
    chi-square where it exceeds 1 (when there are more observations than unknowns).

    Parameters
    ----------
    sightings : sequence of Sighting
        The look-ahead's and the GEO's sightings of the same feature (two or more; the
        first one's time is ``t_ref``).
    wind_prior : tuple of float or None
        Prior ground velocity ``(east, north)``, m/s.
    wind_prior_sigma_mps : float or None
        Its standard deviation per axis (> 0), given with ``wind_prior``.

    Returns
    -------
    GeoHeightFit
        ``ok=False`` with the reason where the sightings do not determine the height
        (too few, the drift unconstrained, a baseline under :data:`MIN_BASELINE`,
        a singular system, or a height outside ``[-1 km, 30 km]``).

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        Fewer than two sightings, something not a :class:`Sighting`, or a bad prior.

    Examples
    --------
    The GEO image 600 s older than the look, with another 600 s before it: the GEO pair
    measures the drift (10 m/s north) and carries it to the look.

    >>> top, v = 8000.0, np.array([0.0, 10.0])
    >>> def seen(t, zen, az, alt, sigma):
    ...     x, y = np.array([1000.0, 2000.0]) + v * t + parallax_offset(zen, az, alt, top)
    ...     return Sighting(t, float(x), float(y), zen, az, alt, sigma)
    >>> s = [seen(0.0, 40.0, 180.0, 500e3, 30.0), seen(-600.0, 40.0, 0.0, GEO_ALTITUDE_M, 100.0),
    ...      seen(-1200.0, 40.0, 0.0, GEO_ALTITUDE_M, 100.0)]
    >>> fit = fit_geo_height(s)
    >>> fit.ok, round(fit.height_m), [round(w, 3) + 0.0 for w in fit.wind_mps]
    (True, 8000, [0.0, 10.0])
    >>> round(fit.height_sigma_m)  # the drift's extrapolation over 600 s dominates
    135
    """
    from scipy.optimize import least_squares

    _check_sightings(sightings)
    prior, prior_sd = _check_prior(wind_prior, wind_prior_sigma_mps)
    t_ref = float(sightings[0].t_s)
    tan_u = [math.tan(math.radians(s.zenith_deg)) * _unit_away(s) for s in sightings]
    baseline = max(
        float(np.linalg.norm(a - b)) for i, a in enumerate(tan_u) for b in tan_u[i + 1 :]
    )
    if baseline < MIN_BASELINE:
        return _failed(
            f"degenerate: the sightings displace the top alike ({baseline:.3f} m of disparity "
            f"per m of height, less than {MIN_BASELINE:g})",
            t_ref,
            baseline,
        )
    times = {float(s.t_s) for s in sightings}
    if prior is None and len(times) > 1 and len(times) < 3:
        # two times: the drift along the baseline is free
        return _failed(
            "drift unconstrained: sightings at two times need a third (a second GEO image) "
            "or a wind prior",
            t_ref,
            baseline,
        )
    obs = np.array([[s.x_m, s.y_m] for s in sightings]).ravel()
    w_obs = np.repeat([1.0 / s.sigma_m for s in sightings], 2)
    dt = np.array([s.t_s - t_ref for s in sightings])
    units = np.array([_unit_away(s) for s in sightings])
    dists = [ground_distance_for_zenith(s.altitude_m, s.zenith_deg) for s in sightings]
    only_one_time = len(times) == 1

    def shifts(h: float) -> np.ndarray:
        return np.array(
            [
                d - float(parallax.sight_at_height(s.altitude_m, d, min(max(h, -10e3), 90e3)))
                for s, d in zip(sightings, dists, strict=True)
            ]
        )

    def residuals(p: np.ndarray) -> np.ndarray:
        model = p[None, 0:2] + dt[:, None] * p[None, 2:4] + shifts(float(p[4]))[:, None] * units
        r: np.ndarray = (model.ravel() - obs) * w_obs
        if prior is not None:
            r = np.concatenate([r, (p[2:4] - prior) / prior_sd])
        return r

    aw, bw = _first_order(tan_u, dt, w_obs, obs, prior, prior_sd)
    # at one time the velocity does not enter (its columns are zero): fixed unless a prior
    keep = [0, 1, 4] if only_one_time and prior is None else [0, 1, 2, 3, 4]
    sub = aw[:, keep]
    if np.linalg.cond(sub) > MAX_CONDITION:
        return _failed("degenerate: the sightings leave the height undetermined", t_ref, baseline)
    start = np.zeros(5)
    start[keep] = np.linalg.lstsq(sub, bw, rcond=None)[0]

    def res_kept(q: np.ndarray) -> np.ndarray:
        p = start.copy()
        p[keep] = q
        return residuals(p)

    sol = least_squares(res_kept, start[keep], method="lm", x_scale=[1e3] * len(keep))
    p = start.copy()
    p[keep] = sol.x
    j = sol.jac
    n_obs, n_par = j.shape
    try:
        cov = np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        return _failed("degenerate: singular normal equations", t_ref, baseline)
    chi2 = float(np.sum(sol.fun**2))
    dof = n_obs - n_par
    if dof > 0 and chi2 / dof > 1.0:
        cov = cov * (chi2 / dof)
    sd = np.full(5, math.nan)
    sd[keep] = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    h = float(p[4])
    if not -1000.0 <= h <= MAX_HEIGHT_M:
        return _failed(f"no plume top: the fit puts it at {h:.0f} m", t_ref, baseline)
    return GeoHeightFit(
        True,
        h,
        float(sd[4]),
        (float(p[2]), float(p[3])),
        (float(sd[2]), float(sd[3])),
        (float(p[0]), float(p[1])),
        t_ref,
        baseline,
        chi2,
    )


@dataclass(frozen=True)
class Centroid:
    """A plume's sub-cell position on a GEO grid (:func:`fraction_centroid`).

    Parameters
    ----------
    x_m, y_m : float
        Centroid, metres east and north on the map.
    sigma_m : float
        Standard deviation per axis from the fraction's noise (the larger axis), metres.
    cover : float
        Sum of the fractions (cells' worth of plume).
    cells : int
        Cells summed.
    """

    x_m: float
    y_m: float
    sigma_m: float
    cover: float
    cells: int


def fraction_centroid(
    fraction: np.ndarray,
    *,
    cell_m: float,
    origin_m: tuple[float, float] = (0.0, 0.0),
    region: np.ndarray | None = None,
    noise: float = 0.0,
) -> Centroid:
    """The centroid of a plume's cover fraction on a north-up grid, with its noise.

    ``x = sum(f x_c) / sum(f)`` over the cells of ``region`` (cell centres ``x_c``); the
    fraction of a cell is the share of it the plume covers, so the centroid is that of
    the plume's opacity at sub-cell precision. With independent noise of standard
    deviation ``noise`` on each cell's fraction, the centroid's standard deviation is
    ``noise sqrt(sum (x_c - x)^2) / sum(f)`` per axis.

    Parameters
    ----------
    fraction : numpy.ndarray
        ``(rows, cols)`` plume cover fraction (e.g. ash plus steam from
        :func:`dyntarget.geo.unmix`), finite, ``>= 0``.
    cell_m : float
        Cell size, metres.
    origin_m : tuple of float
        Map position of the grid's top-left corner ``(east, north)``, metres.
    region : numpy.ndarray or None
        Boolean ``(rows, cols)``: the plume's cells (``None``: every cell).
    noise : float
        Standard deviation of each cell's fraction (``>= 0``).

    Returns
    -------
    Centroid

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        A fraction that is not a finite 2-D array, a region of another shape, a bad cell
        size, or no plume in the region.

    Examples
    --------
    Half a cell's cover in cell (1, 2), a quarter in (1, 3), 2 km cells:

    >>> f = np.zeros((3, 5)); f[1, 2], f[1, 3] = 0.5, 0.25
    >>> c = fraction_centroid(f, cell_m=2000.0, origin_m=(0.0, 6000.0))
    >>> round(c.x_m, 1), c.y_m, c.cover, c.cells
    (5666.7, 3000.0, 0.75, 15)
    """
    f = np.asarray(fraction, np.float64)
    if f.ndim != 2 or f.size == 0 or not np.isfinite(f).all():
        raise InvalidParameterError(f"fraction: expected a finite 2-D array, got shape {f.shape}")
    g = _finite("cell_m", cell_m, 1e-3, 1e6)
    if not g > 0:
        raise InvalidParameterError("cell_m: expected > 0")
    x0 = _finite("origin east", origin_m[0], -2e7, 2e7)
    y0 = _finite("origin north", origin_m[1], -2e7, 2e7)
    sd = _finite("noise", noise, 0.0, 10.0)
    m = np.ones(f.shape, bool) if region is None else np.asarray(region, bool)
    if m.shape != f.shape:
        raise InvalidParameterError(
            f"region: shape {m.shape} does not match the fraction's {f.shape}"
        )
    rows, cols = np.nonzero(m)
    w = np.clip(f[rows, cols], 0.0, None)
    total = float(w.sum())
    if not total > 0:
        raise InvalidParameterError("fraction: no plume cover in the region")
    xc = x0 + (cols + 0.5) * g
    yc = y0 - (rows + 0.5) * g
    x = float((w * xc).sum() / total)
    y = float((w * yc).sum() / total)
    sx = sd * math.sqrt(float(((xc - x) ** 2).sum())) / total
    sy = sd * math.sqrt(float(((yc - y) ** 2).sum())) / total
    return Centroid(x, y, max(sx, sy), total, int(rows.size))


@dataclass(frozen=True)
class Offset:
    """Where a fine image's plume lies on a coarse (GEO) image: :func:`match_offset`.

    Parameters
    ----------
    dx_m, dy_m : float
        Offset east and north, metres: the coarse image shows the fine plume moved by it.
    sigma_m : float
        Standard deviation per axis from the coarse image's noise (the larger axis), metres;
        ``inf`` where the match does not determine the offset (a plume within one cell).
    scale : float
        Least-squares scale of the fine field matching the coarse one (about 1 where both
        are cover fractions of the same plume).
    rms : float
        Root-mean-square residual over the cells compared (fraction).
    """

    dx_m: float
    dy_m: float
    sigma_m: float
    scale: float
    rms: float


def _axis_split(u: np.ndarray, pix: float, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Cells holding the pixel ``[u - pix/2, u + pix/2]`` (``u`` from the grid's edge, in
    its direction) and the share of it in the first (the rest is in the next; ``pix <= cell``)."""
    lo = u - 0.5 * pix
    k = np.floor(lo / cell)
    share = np.clip(((k + 1.0) * cell - lo) / pix, 0.0, 1.0)
    return k.astype(np.int64), share


def match_offset(
    fine: np.ndarray,
    coarse: np.ndarray,
    *,
    fine_cell_m: float,
    fine_origin_m: tuple[float, float],
    coarse_cell_m: float,
    coarse_origin_m: tuple[float, float],
    guess_m: tuple[float, float],
    noise: float = 0.0,
) -> Offset:
    """The offset that moves a fine image's plume onto a coarse image's (sub-cell).

    The fine field (e.g. the look-ahead's plume opacity ``1 - exp(-tau)`` at 32 m) moved
    by ``(dx, dy)`` and averaged onto the coarse grid (each fine pixel split between the
    cells it overlaps, by area: continuous in the offset) predicts the coarse field
    (e.g. the plume's unmixed cover fraction on a GEO image) up to a scale. The offset
    minimising the squared difference over the cells either field covers (the scale
    solved in closed form at each offset) is found by Nelder-Mead from ``guess_m`` (e.g.
    the difference of the two fields' centroids, :func:`fraction_centroid`). Using the
    whole field rather than its centroid, the fine field is seen as the coarse imager
    sees it: the thin edges the coarse detection misses weigh alike in both.

    Its standard deviation is ``noise sqrt(diag((J^T J)^-1))``, ``J`` the derivative of
    the predicted cells with respect to the offset (central differences of a tenth of a
    cell): the coarse noise only. The plume's change between the two images' times is not
    in it: it is what the offset measures (drift) or its error (change of shape).

    Parameters
    ----------
    fine : numpy.ndarray
        ``(rows, cols)`` fine field, finite, ``>= 0``, on a north-up grid.
    coarse : numpy.ndarray
        ``(rows, cols)`` coarse field, finite, on a north-up grid.
    fine_cell_m, coarse_cell_m : float
        Pixel sizes, metres (the fine one at most the coarse one).
    fine_origin_m, coarse_origin_m : tuple of float
        Map positions ``(east, north)`` of the grids' top-left corners, metres.
    guess_m : tuple of float
        Starting offset ``(east, north)``, metres.
    noise : float
        Standard deviation of a coarse cell's value (``>= 0``).

    Returns
    -------
    Offset

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        Fields that are not finite 2-D arrays, a fine field without plume, or bad cell
        sizes.

    Examples
    --------
    A 1 km disc on a 32 m grid, seen on 500 m cells 1,234 m east and 2,345 m south:

    >>> yy, xx = np.mgrid[0:128, 0:128] * 32.0 + 16.0
    >>> disc = lambda cx, cy: (np.hypot(xx - cx, yy - cy) < 1000.0).astype(float)
    >>> fine = disc(2048.0, 2048.0)
    >>> cy, cx = np.mgrid[0:24, 0:24] * 500.0 + 250.0  # coarse centres from the same corner
    >>> sub = np.mgrid[0:16, 0:16].reshape(2, -1).T * 31.25 + 15.625
    >>> coarse = np.zeros((24, 24))
    >>> for r in range(24):
    ...     for c in range(24):
    ...         px = c * 500.0 + sub[:, 1]; py = r * 500.0 + sub[:, 0]
    ...         coarse[r, c] = np.mean(np.hypot(px - 2048 - 1234, py - 2048 - 2345) < 1000.0)
    >>> o = match_offset(fine, coarse, fine_cell_m=32.0, fine_origin_m=(0.0, 0.0),
    ...                  coarse_cell_m=500.0, coarse_origin_m=(0.0, 0.0),
    ...                  guess_m=(1000.0, -2000.0))
    >>> abs(o.dx_m - 1234.0) < 20, abs(o.dy_m + 2345.0) < 20, round(o.scale, 2)
    (True, True, 1.0)
    """
    from scipy.optimize import minimize

    f = np.asarray(fine, np.float64)
    g = np.asarray(coarse, np.float64)
    for name, a in (("fine", f), ("coarse", g)):
        if a.ndim != 2 or a.size == 0 or not np.isfinite(a).all():
            raise InvalidParameterError(f"{name}: expected a finite 2-D array, got shape {a.shape}")
    p = _finite("fine_cell_m", fine_cell_m, 1e-3, 1e6)
    big = _finite("coarse_cell_m", coarse_cell_m, 1e-3, 1e6)
    if p > big:
        raise InvalidParameterError(
            f"fine_cell_m: {p:g} m is coarser than the coarse grid's {big:g} m"
        )
    fx0, fy0 = (_finite("fine origin", v, -2e7, 2e7) for v in fine_origin_m)
    cx0, cy0 = (_finite("coarse origin", v, -2e7, 2e7) for v in coarse_origin_m)
    gx, gy = (_finite("guess_m", v, -2e7, 2e7) for v in guess_m)
    sd = _finite("noise", noise, 0.0, 10.0)
    rows, cols = np.nonzero(f > 0)
    if not rows.size:
        raise InvalidParameterError("fine: no plume (every value is 0)")
    weight = f[rows, cols] * (p / big) ** 2
    east = fx0 + (cols + 0.5) * p  # pixel centres, map metres
    north = fy0 - (rows + 0.5) * p
    nr, nc = g.shape

    def predict(dx: float, dy: float) -> np.ndarray:
        kc, sc = _axis_split(east + dx - cx0, p, big)
        kr, sr = _axis_split(cy0 - (north + dy), p, big)
        out = np.zeros((nr + 2) * (nc + 2))
        for dr, wr in ((0, sr), (1, 1.0 - sr)):
            for dc, wc in ((0, sc), (1, 1.0 - sc)):
                r = np.clip(kr + dr, -1, nr) + 1
                c = np.clip(kc + dc, -1, nc) + 1
                out += np.bincount(r * (nc + 2) + c, weight * wr * wc, out.size)
        return out.reshape(nr + 2, nc + 2)[1:-1, 1:-1]  # what falls outside is dropped

    def misfit(d: np.ndarray) -> float:
        q = predict(float(d[0]), float(d[1]))
        qq = float((q * q).sum())
        k = float((q * g).sum()) / qq if qq > 0 else 0.0
        return float(((k * q - g) ** 2).sum()) + (1e6 if qq <= 0 else 0.0)

    start = np.array([gx, gy])
    simplex = start + np.array([[0.0, 0.0], [0.5 * big, 0.0], [0.0, 0.5 * big]])
    best = minimize(
        misfit,
        start,
        method="Nelder-Mead",
        options={"initial_simplex": simplex, "xatol": 0.002 * big, "fatol": 1e-12, "maxiter": 400},
    )
    dx, dy = (float(v) for v in best.x)
    q = predict(dx, dy)
    qq = float((q * q).sum())
    k = float((q * g).sum()) / qq if qq > 0 else 0.0
    step = 0.1 * big
    jx = k * (predict(dx + step, dy) - predict(dx - step, dy)).ravel() / (2 * step)
    jy = k * (predict(dx, dy + step) - predict(dx, dy - step)).ravel() / (2 * step)
    jac = np.stack([jx, jy], axis=1)
    try:
        cov = np.linalg.inv(jac.T @ jac) * sd**2
        sigma = float(np.sqrt(max(cov[0, 0], cov[1, 1], 0.0)))
    except np.linalg.LinAlgError:
        sigma = math.inf
    support = (q > 0) | (g > 0)
    rms = float(np.sqrt(np.mean((k * q - g)[support] ** 2))) if support.any() else 0.0
    return Offset(dx, dy, sigma, k, rms)
