"""Plume-top height and wind from looks at different view angles; column rise; plume disparity.

A tracked plume-top feature, looked at ``n`` times from orbit, appears at

    a(t_i) = p0 + v t_i + s(h; geometry_i)

on the ground map: ``p0`` its true ground position at ``t = 0``, ``v`` the wind that
carries it, ``s`` the parallax of its height ``h`` (:mod:`dyntarget.parallax`: radial
from the nadir, ``h tan(theta)`` to first order, exact on the sphere). :func:`fit_height`
solves for ``(p0, v, h)`` by least squares (``scipy.optimize.least_squares``, weighted
by each look's position noise) with the covariance of the estimate.

Assumptions and limits (``docs/plumes-3d.md``):

* the wind is constant over the looks and the feature keeps its height between them
  (a rising column breaks both: fit the rise from a longer sequence with :func:`fit_rise`);
* with **two looks** there are four equations and five unknowns: the drift along the
  parallax direction is indistinguishable from a height. A Gaussian **wind prior**
  (e.g. from the two-look motion, a GEO motion or a forecast; ``wind_prior``) makes it
  solvable, and the height's uncertainty then carries the prior's;
* with **three or more** looks whose ``tan(theta)`` changes non-linearly in time the
  linear drift separates from the parallax in principle; along a straight approach it
  changes almost linearly (500, 400, 300 km ahead from 500 km up: the height's standard
  deviation is 19 km for 30 m position noise without a prior, 170 m with a 3 m/s wind
  prior), so in practice the along-track wind comes from a prior; the cross-track drift
  is measured by the looks themselves. Where the looks leave the problem singular
  :func:`fit_height` says so (``HeightFit.ok`` False, with the reason) instead of
  returning a number; where they leave it weak the standard deviation says so.

:func:`plume_disparity` measures the apparent displacement of a plume between two
look-ahead frames with the dense optical flow of :mod:`dyntarget.predict.motion`
(OpenCV Farneback), restricted to the plume's interior.

Examples
--------
A 10 km top drifting north (along track) at 10 m/s, seen about 500, 400 and 300 km
ahead from 500 km up, without noise, with a forecast wind (north 10 m/s, +-3 m/s) as prior:

>>> from dyntarget import parallax
>>> t = np.array([0.0, 14.16, 28.32])
>>> nadir_y = -500e3 + parallax.ground_speed(500e3) * t  # flying north towards the plume
>>> y = 10.0 * t + parallax.parallax_shift(500e3, 10.0 * t - nadir_y, 10e3)
>>> looks = [Look(float(ti), 0.0, float(yi), 0.0, float(ny), 500e3, 30.0)
...          for ti, yi, ny in zip(t, y, nadir_y)]
>>> fit = fit_height(looks, wind_prior=(0.0, 10.0))
>>> fit.ok, round(fit.height_m), [round(v, 3) + 0.0 for v in fit.wind_mps], round(fit.height_sigma_m, -1)
(True, 10000, [0.0, 10.0], 200.0)

Without the prior the same looks give the same height, but with a standard deviation
of 19 km: along a straight approach ``tan(theta)`` is nearly linear in time, so an
along-track drift and a height are almost interchangeable.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError

MAX_CONDITION = 1e8
"""Whitened Jacobian condition number above which the fit is reported degenerate."""
MIN_DISPARITY_PX = 50
"""Fewest plume-interior pixels :func:`plume_disparity` measures on."""
MIN_TEXTURE = 0.004
"""Least brightness standard deviation (reflectance) inside the plume for the flow to hold."""


@dataclass(frozen=True)
class Look:
    """One look at a plume-top feature: where it appeared, when, and from where.

    Positions are on a projected ground map (``x`` east, ``y`` north, metres; e.g. UTM).

    Parameters
    ----------
    t_s : float
        Time of the look, seconds on the pass clock.
    x_m, y_m : float
        Apparent ground position of the feature (where the line of sight meets the ground).
    nadir_x_m, nadir_y_m : float
        The spacecraft's nadir at the time of the look, on the same map.
    altitude_m : float
        The spacecraft's altitude, metres.
    sigma_m : float
        Standard deviation of the measured position, metres (each axis).
    ground_m : float
        Terrain height under the apparent position, metres.
    """

    t_s: float
    x_m: float
    y_m: float
    nadir_x_m: float
    nadir_y_m: float
    altitude_m: float
    sigma_m: float = 30.0
    ground_m: float = 0.0

    def __post_init__(self) -> None:
        for name in ("t_s", "x_m", "y_m", "nadir_x_m", "nadir_y_m", "ground_m"):
            v = getattr(self, name)
            if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
                raise InvalidParameterError(f"look {name}: expected a finite number, got {v!r}")
        if not (isinstance(self.sigma_m, int | float) and math.isfinite(self.sigma_m)):
            raise InvalidParameterError(f"look sigma_m: expected metres, got {self.sigma_m!r}")
        if self.sigma_m <= 0:
            raise InvalidParameterError(f"look sigma_m: expected metres > 0, got {self.sigma_m!r}")
        parallax.view_zenith(self.altitude_m, 0.0)  # refuses a bad altitude


@dataclass(frozen=True)
class HeightFit:
    """Height and wind of one plume top from its looks (:func:`fit_height`).

    Parameters
    ----------
    ok : bool
        Whether the height is determined; False with ``reason`` when degenerate.
    height_m, height_sigma_m : float
        Top height above the sphere (sea level) and its standard deviation, metres
        (NaN when not ``ok``).
    wind_mps, wind_sigma_mps : tuple of float
        ``(east, north)`` drift of the feature and its standard deviation, m/s.
    position_m : tuple of float
        True ground position (under the feature) at ``t = 0``, metres.
    rms_residual_m : float
        Root mean square of the position residuals, metres.
    looks : int
        Number of looks used.
    wind_prior : bool
        Whether a wind prior entered the fit.
    reason : str
        Why the fit is not ``ok`` (empty otherwise).
    rise_mps, rise_sigma_mps : float or None
        The top's rise and its standard deviation, m/s (``None``: not fitted).
    """

    ok: bool
    height_m: float
    height_sigma_m: float
    wind_mps: tuple[float, float]
    wind_sigma_mps: tuple[float, float]
    position_m: tuple[float, float]
    rms_residual_m: float
    looks: int
    wind_prior: bool
    reason: str = ""
    rise_mps: float | None = None
    rise_sigma_mps: float | None = None


def _apparent(params: np.ndarray, looks: Sequence[Look]) -> np.ndarray:
    """Model positions ``(n, 2)`` for ``params = (x0, y0, vx, vy, h[, w])`` (``w``: the
    rise, the height at look ``i`` being ``h + w (t_i - t_0)``)."""
    x0, y0, vx, vy, h0 = params[:5]
    w = float(params[5]) if len(params) > 5 else 0.0
    out = np.empty((len(looks), 2))
    for i, lk in enumerate(looks):
        h = h0 + w * (lk.t_s - looks[0].t_s)
        px = x0 + vx * lk.t_s
        py = y0 + vy * lk.t_s
        rx, ry = px - lk.nadir_x_m, py - lk.nadir_y_m
        d = math.hypot(rx, ry)
        hh = max(h, lk.ground_m)  # below the ground the line of sight meets the ground first
        s = float(parallax.parallax_shift(lk.altitude_m, d, hh, ground_m=lk.ground_m))
        out[i] = (px + s * rx / d, py + s * ry / d) if d > 0 else (px, py)
    return out


def _parallax_rate(lk: Look) -> tuple[float, float]:
    """First-order shift per metre of height, ``tan(theta) u``, at the apparent position."""
    rx, ry = lk.x_m - lk.nadir_x_m, lk.y_m - lk.nadir_y_m
    d = math.hypot(rx, ry)
    if d == 0:
        return 0.0, 0.0
    k = math.tan(float(parallax.view_zenith(lk.altitude_m, d, ground_m=lk.ground_m)))
    return k * rx / d, k * ry / d


def fit_height(
    looks: Sequence[Look],
    *,
    wind_prior: tuple[float, float] | None = None,
    wind_prior_sigma_mps: float = 3.0,
    rise: bool = False,
) -> HeightFit:
    """Solve a plume top's height jointly with its drift from two or more looks.

    Least squares on ``a_i = p0 + v t_i + s(h)`` (the module docstring), started from
    the first-order linear solution, residuals weighted by each look's ``sigma_m``; a
    wind prior adds ``(v - prior) / sigma`` per axis. The covariance is ``(J^T J)^-1`` of
    the whitened Jacobian, scaled by the reduced chi-square when it exceeds 1 (noise
    larger than stated) and there are more equations than unknowns.

    Parameters
    ----------
    looks : sequence of Look
        At least two looks of the same feature.
    wind_prior : tuple of float or None
        ``(east, north)`` wind, m/s, as a Gaussian prior (needed with two looks).
    wind_prior_sigma_mps : float
        Its standard deviation per axis, m/s.
    rise : bool
        Also fit a linear rise of the top, ``h + w (t - t_0)`` (``t_0`` the first look's
        time; ``height_m`` is then the height at ``t_0``): needs three or more looks;
        the rise shows as the curvature of the apparent track.

    Returns
    -------
    HeightFit
        ``ok`` False (height NaN) with the reason when the looks cannot separate the
        height from the drift.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For fewer than two looks, or a bad prior.

    Examples
    --------
    Two looks without a prior cannot separate drift and height:

    >>> a = Look(0.0, 0.0, 11_500.0, 0.0, -500e3, 500e3)
    >>> b = Look(28.3, 0.0, 6_700.0, 0.0, -300e3, 500e3)
    >>> fit_height([a, b]).reason.split(":")[0]
    'degenerate'
    """
    from scipy.optimize import least_squares

    looks = list(looks)
    if len(looks) < 2 or not all(isinstance(lk, Look) for lk in looks):
        raise InvalidParameterError(f"looks: expected two or more Look, got {len(looks)}")
    if wind_prior is not None:
        wp = np.asarray(wind_prior, np.float64)
        if wp.shape != (2,) or not np.isfinite(wp).all():
            raise InvalidParameterError(
                f"wind prior: expected (east, north) m/s, got {wind_prior!r}"
            )
    if not (math.isfinite(wind_prior_sigma_mps) and wind_prior_sigma_mps > 0):
        raise InvalidParameterError(
            f"wind prior sigma: expected m/s > 0, got {wind_prior_sigma_mps!r}"
        )
    obs = np.array([(lk.x_m, lk.y_m) for lk in looks])
    sig = np.array([lk.sigma_m for lk in looks])
    t = np.array([lk.t_s for lk in looks])
    # first-order linear system in (x0, y0, vx, vy, h), whitened
    rows, rhs = [], []
    for i, lk in enumerate(looks):
        kx, ky = _parallax_rate(lk)
        dt = t[i] - t[0]
        rows += [[1, 0, t[i], 0, kx, kx * dt], [0, 1, 0, t[i], ky, ky * dt]]
        rhs += [obs[i, 0], obs[i, 1]]
    n_par = 6 if rise else 5
    a = np.array(rows, np.float64)[:, :n_par] / np.repeat(sig, 2)[:, None]
    b = np.array(rhs) / np.repeat(sig, 2)
    if wind_prior is not None:
        a = np.vstack(
            [
                a,
                np.array(
                    [
                        [0, 0, 1 / wind_prior_sigma_mps, 0, 0, 0],
                        [0, 0, 0, 1 / wind_prior_sigma_mps, 0, 0],
                    ]
                )[:, :n_par],
            ]
        )
        b = np.concatenate([b, np.asarray(wind_prior) / wind_prior_sigma_mps])
    nan2 = (math.nan, math.nan)
    cond = np.linalg.cond(a * _column_scale(t)[:n_par])
    if (
        a.shape[0] < n_par
        or (rise and len(looks) < 3)
        or not math.isfinite(cond)
        or cond > MAX_CONDITION
    ):
        why = (
            "degenerate: two looks give four equations for five unknowns (position, drift, "
            "height): give a wind prior"
            if len(looks) == 2 and wind_prior is None
            else "degenerate: the parallax changes linearly (or not at all) in time over "
            "these looks, so drift and height cannot be told apart: give a wind prior or a "
            "look from another angle"
        )
        return HeightFit(
            False,
            math.nan,
            math.nan,
            nan2,
            nan2,
            nan2,
            math.nan,
            len(looks),
            wind_prior is not None,
            why,
        )
    x_lin = np.linalg.lstsq(a, b, rcond=None)[0]

    def residuals(p: np.ndarray) -> np.ndarray:
        r = ((_apparent(p, looks) - obs) / sig[:, None]).ravel()
        if wind_prior is not None:
            r = np.concatenate([r, (p[2:4] - np.asarray(wind_prior)) / wind_prior_sigma_mps])
        return r

    try:
        sol = least_squares(
            residuals,
            x_lin,
            method="lm",
            x_scale=_column_scale(t)[:n_par] ** -1,
            xtol=1e-12,
            ftol=1e-12,
        )
    except InvalidParameterError as exc:  # the search left the geometry (a height > 100 km)
        return HeightFit(
            False, math.nan, math.nan, nan2, nan2, nan2, math.nan, len(looks),
            wind_prior is not None, f"the fit diverged: {exc}",
        )  # fmt: skip
    jac = _jacobian(residuals, sol.x, 1.0 / _column_scale(t)[:n_par], sol.jac)
    cov = np.linalg.pinv(jac.T @ jac)
    dof = jac.shape[0] - n_par
    if dof > 0:
        chi2 = float(sol.fun @ sol.fun) / dof
        cov *= max(chi2, 1.0)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    res = _apparent(sol.x, looks) - obs
    return HeightFit(
        ok=True,
        height_m=float(sol.x[4]),
        height_sigma_m=float(sd[4]),
        wind_mps=(float(sol.x[2]), float(sol.x[3])),
        wind_sigma_mps=(float(sd[2]), float(sd[3])),
        position_m=(float(sol.x[0]), float(sol.x[1])),
        rms_residual_m=float(np.sqrt(np.mean(np.sum(res**2, axis=1)))),
        looks=len(looks),
        wind_prior=wind_prior is not None,
        rise_mps=float(sol.x[5]) if rise else None,
        rise_sigma_mps=float(sd[5]) if rise else None,
    )


def _jacobian(
    residuals: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    steps: np.ndarray,
    fallback: np.ndarray,
) -> np.ndarray:
    """The residuals' Jacobian at ``x`` by central differences of fixed ``steps`` (about a
    metre of effect per unknown), for the covariance.

    MINPACK's own (``sol.jac``) steps each unknown by a fraction of its value, so an
    unknown at (about) zero, as a drift fitted with a zero-drift prior is, gets a step of
    ~1e-17 and a column of rounding noise: the reported sigma then changed with the CPU's
    floating-point kernels (170 m on an AVX-512 machine, 190 m on an AVX2 one in the
    module's example). ``fallback`` where a step leaves the geometry (a height near 0).
    """
    cols = []
    for i, h in enumerate(steps):
        e = np.zeros(len(x))
        e[i] = h
        try:
            cols.append((residuals(x + e) - residuals(x - e)) / (2.0 * h))
        except InvalidParameterError:
            return fallback
    return np.column_stack(cols)


def _column_scale(t: np.ndarray) -> np.ndarray:
    """Typical sizes of the unknowns' effects (so the condition number means something)."""
    span = max(float(np.ptp(t)), 1.0)
    return np.array([1.0, 1.0, span, span, 1.0, span])


@dataclass(frozen=True)
class RiseFit:
    """A column top that rises linearly, then levels (:func:`fit_rise`).

    Parameters
    ----------
    rise_mps, rise_sigma_mps : float
        Rise velocity and its standard deviation, m/s.
    top_height_m : float
        Level height reached, metres (the last height when it has not levelled yet).
    reach_s : float
        When the top reached it (the last time when not levelled).
    levelled : bool
        Whether the sequence shows the top levelling.
    rms_residual_m : float
        Root mean square residual, metres.
    """

    rise_mps: float
    rise_sigma_mps: float
    top_height_m: float
    reach_s: float
    levelled: bool
    rms_residual_m: float


def fit_rise(times_s: Sequence[float], heights_m: Sequence[float]) -> RiseFit:
    """Fit ``h(t) = top - w max(reach - t, 0)``: a linear rise at ``w`` until ``reach``, then flat.

    For each candidate ``reach`` (each sample time, the midpoints between them, and
    "beyond the last sample": never levelled) the model is linear in ``(top, w)``; the
    candidate with the least squared residual wins (no local minima to fall into).

    Parameters
    ----------
    times_s : sequence of float
        Times of the height estimates (at least three, not all equal).
    heights_m : sequence of float
        Estimated top heights, metres.

    Returns
    -------
    RiseFit

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For fewer than three points or non-finite values.

    Examples
    --------
    >>> t = [0, 60, 120, 180, 240, 300]
    >>> f = fit_rise(t, [2000, 4400, 6800, 8000, 8000, 8000])
    >>> round(f.rise_mps, 3), round(f.top_height_m), round(f.reach_s), f.levelled
    (40.0, 8000, 150, True)
    """
    t = np.asarray(times_s, np.float64)
    h = np.asarray(heights_m, np.float64)
    if t.shape != h.shape or t.ndim != 1 or len(t) < 3:
        raise InvalidParameterError("rise: expected three or more (time, height) pairs")
    if not (np.isfinite(t).all() and np.isfinite(h).all()) or np.ptp(t) <= 0:
        raise InvalidParameterError("rise: expected finite heights at distinct times")
    order = np.argsort(t)
    t, h = t[order], h[order]
    cands = np.unique(np.concatenate([t, 0.5 * (t[1:] + t[:-1])]))
    best: tuple[float, float, float, float] | None = None  # sse, top, w, reach
    for reach in cands:
        before = t < reach
        if before.sum() < 2:  # a rise needs two points on it
            continue
        a = np.column_stack([np.ones_like(t), -np.maximum(reach - t, 0.0)])
        coef, *_ = np.linalg.lstsq(a, h, rcond=None)
        sse = float(np.sum((a @ coef - h) ** 2))
        if best is None or sse < best[0] - 1e-9:
            best = (sse, float(coef[0]), float(coef[1]), float(reach))
    assert best is not None  # the last sample time always has two points before it
    sse, top, w, reach = best
    levelled = reach < t[-1]
    a = np.column_stack([np.ones_like(t), -np.maximum(reach - t, 0.0)])
    dof = max(len(t) - 3, 1)
    cov = np.linalg.pinv(a.T @ a) * sse / dof
    return RiseFit(
        rise_mps=w,
        rise_sigma_mps=float(math.sqrt(max(cov[1, 1], 0.0))),
        top_height_m=top,
        reach_s=reach,
        levelled=bool(levelled),
        rms_residual_m=math.sqrt(sse / len(t)),
    )


@dataclass(frozen=True)
class Disparity:
    """The apparent displacement of a plume between two frames (:func:`plume_disparity`).

    Parameters
    ----------
    dx_px, dy_px : float
        Displacement, pixels (column, row), of the plume from the first frame to the second.
    quality : float
        Share of the interior's flow votes within 1 px of the median (0..1).
    pixels : int
        Interior pixels voting.
    """

    dx_px: float
    dy_px: float
    quality: float
    pixels: int


def plume_disparity(
    first: np.ndarray,
    second: np.ndarray,
    mask: np.ndarray,
    *,
    guess_px: tuple[float, float] = (0.0, 0.0),
    search_px: int = 0,
    flow: str = "farneback",
) -> tuple[Disparity | None, str]:
    """Measure how far a plume moved between two co-registered frames (dense flow, OpenCV).

    The second frame is first moved back by ``guess_px`` (the displacement a prior
    height and wind predict: parallax disparities of re-looks reach a hundred pixels,
    more than the flow's pyramid reaches) and, with ``search_px``, by the best match of
    the plume within ``search_px`` of it (OpenCV ``matchTemplate``, normalised
    correlation of the plume's pixels alone, so the still ground does not vote); the
    flow from the first frame to it
    (:func:`dyntarget.predict.motion.dense_flow`, on the band mean) is read inside the
    plume's interior (the mask eroded by half the flow's window, so no vote straddles the
    edge) and its median added to the guess.

    Parameters
    ----------
    first, second : numpy.ndarray
        ``(4, H, W)`` frames on the same ground grid.
    mask : numpy.ndarray
        ``(H, W)`` bool plume mask of the first frame.
    guess_px : tuple of float
        Predicted displacement ``(dx, dy)``, pixels.
    search_px : int
        Half-width of the coarse search around the guess, pixels (0: none).
    flow : str
        ``"farneback"`` or ``"dis"``.

    Returns
    -------
    (Disparity or None, str)
        The measurement and ``""``; or ``None`` and the reason (a plume too small or too
        thin for an interior of :data:`MIN_DISPARITY_PX` pixels, or without texture).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> import cv2
    >>> base = cv2.GaussianBlur(rng.random((96, 96)).astype(np.float32), (0, 0), 1.5)
    >>> a = np.repeat(base[None], 4, axis=0)
    >>> b = np.roll(a, (3, 5), axis=(1, 2))  # 5 px right, 3 px down
    >>> m = np.zeros((96, 96), bool); m[24:72, 24:72] = True
    >>> d, why = plume_disparity(a, b, m)
    >>> round(d.dx_px), round(d.dy_px), why
    (5, 3, '')
    >>> plume_disparity(a, b, np.eye(96, dtype=bool))[1].split(":")[0]
    'plume too small or thin'
    """
    import cv2

    from dyntarget.predict.motion import FARNEBACK_WINDOW, _to_u8, brightness, dense_flow

    a, b = np.asarray(first, np.float32), np.asarray(second, np.float32)
    m = np.asarray(mask)
    if a.ndim != 3 or a.shape != b.shape or m.shape != a.shape[1:] or m.dtype != bool:
        raise InvalidParameterError(
            "plume_disparity: expected two (4, H, W) frames of one shape and a (H, W) bool mask"
        )
    k = FARNEBACK_WINDOW
    interior = cv2.erode(m.astype(np.uint8), np.ones((k, k), np.uint8)) > 0
    n = int(interior.sum())
    if n < MIN_DISPARITY_PX:
        return None, (
            f"plume too small or thin: {n} px inside the mask {k // 2} px from its edge, "
            f"fewer than {MIN_DISPARITY_PX}; no height is measured (the prior is used)"
        )
    ba, bb = brightness(a), brightness(b)
    gx, gy = float(guess_px[0]), float(guess_px[1])
    if search_px > 0:
        gx, gy = _coarse_match(ba, bb, m, (gx, gy), int(search_px))
    if gx or gy:
        # the second frame moved back by the guess: b'(x) = b(x + g)
        shift = np.array([[1.0, 0.0, gx], [0.0, 1.0, gy]], np.float32)
        bb = cv2.warpAffine(
            bb,
            shift,
            bb.shape[::-1],
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=cv2.BORDER_REPLICATE,
        )
    if float(ba[interior].std()) < MIN_TEXTURE:
        return None, "plume without texture: the flow cannot follow it; no height is measured"
    lo, hi = np.percentile(np.concatenate([ba[m], bb[m]]), [1, 99])
    field = dense_flow(_to_u8(ba, lo, hi), _to_u8(bb, lo, hi), flow)
    votes = field[interior]
    med = np.median(votes, axis=0)
    quality = float(np.mean(np.hypot(*(votes - med).T) <= 1.0))
    return Disparity(float(med[0]) + gx, float(med[1]) + gy, quality, n), ""


def _coarse_match(
    a: np.ndarray, b: np.ndarray, mask: np.ndarray, guess: tuple[float, float], r: int
) -> tuple[float, float]:
    """Whole-pixel shift of the plume (``mask`` of ``a``) into ``b`` within ``r`` px of
    ``guess``: masked normalised cross-correlation (``cv2.matchTemplate``)."""
    import cv2

    rows, cols = np.nonzero(mask)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    tpl = a[r0:r1, c0:c1]
    tmask = mask[r0:r1, c0:c1].astype(np.float32)
    gx, gy = round(guess[0]), round(guess[1])
    h, w = b.shape
    # the search area in b, clipped to the frame
    y0, x0 = max(r0 + gy - r, 0), max(c0 + gx - r, 0)
    y1, x1 = min(r1 + gy + r, h), min(c1 + gx + r, w)
    if y1 - y0 < tpl.shape[0] or x1 - x0 < tpl.shape[1]:
        return guess
    score = cv2.matchTemplate(
        np.ascontiguousarray(b[y0:y1, x0:x1]),
        np.ascontiguousarray(tpl),
        cv2.TM_CCORR_NORMED,
        mask=tmask,
    )
    score = np.nan_to_num(score, nan=-1.0)
    iy, ix = np.unravel_index(int(np.argmax(score)), score.shape)
    return float(x0 + ix - c0), float(y0 + iy - r0)


MIN_ENVELOPE_PX = 4
"""Fewest mask pixels :func:`envelope_disparity` measures on (a few WFOV pixels)."""
MIN_ENVELOPE_NCC = 0.5
"""Least normalised correlation of the envelopes at the best shift."""

EDGE_MATCH = "the envelope's best match lies on the search's edge"
"""Why :func:`envelope_disparity` gives no displacement when its best match lies on the
edge of its search (the envelope most likely lies beyond it)."""


def envelope_disparity(
    first: np.ndarray,
    second: np.ndarray,
    *,
    weight: np.ndarray | None = None,
    guess_px: tuple[float, float] = (0.0, 0.0),
    search_px: tuple[int, int] = (8, 8),
    blur_px: float = 1.0,
) -> tuple[Disparity | None, str]:
    """How far a plume's envelope (its mask) moved between two frames: masked NCC, sub-pixel.

    Unlike :func:`plume_disparity`, which follows the plume's texture (carried by the
    wind through an attached plume), this follows the envelope: the shape of the mask,
    which for a plume attached to its vent stays at the vent while the wind blows
    through it. Both masks are blurred (Gaussian, ``blur_px``) so their edges carry
    sub-pixel information; the normalised cross-correlation is computed over the
    overlap of ``weight`` (where the first frame is compared: the plume and a margin
    around it, other plumes left out) and the second frame, for every shift within
    ``search_px`` (``(dx, dy)``) of ``guess_px`` (masked NCC, Padfield 2012, by FFT);
    the peak is refined by a parabola through its neighbours in each axis.

    Parameters
    ----------
    first, second : numpy.ndarray
        ``(H, W)`` plume masks (bool or a plume fraction 0..1) of the two frames, on
        the same grid (the second frame's window may be anywhere: give the offset of its
        origin from the first's in ``guess_px``).
    weight : numpy.ndarray or None
        ``(H, W)`` bool: the first frame's pixels compared (``None``: all).
    guess_px : tuple of float
        Predicted displacement ``(dx, dy)``, pixels (searched around).
    search_px : tuple of int
        Half-widths of the search, pixels, ``(x, y)``.
    blur_px : float
        Standard deviation of the blur, pixels (0: none).

    Returns
    -------
    (Disparity or None, str)
        The displacement (``quality``: the correlation at the peak; ``pixels``: mask
        pixels of the first frame inside ``weight``) and ``""``; or ``None`` and the
        reason (fewer than :data:`MIN_ENVELOPE_PX` mask pixels, no overlap, a peak on
        the search's edge or a correlation below :data:`MIN_ENVELOPE_NCC`).

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For masks of different shapes or a bad search.

    Examples
    --------
    A 6 x 3 px blob moved 2.5 px right and 1 px down (its edges anti-aliased):

    >>> a = np.zeros((40, 40)); a[10:16, 10:13] = 1.0
    >>> b = np.zeros((40, 40)); b[11:17, 13:15] = 1.0; b[11:17, 12] = 0.5; b[11:17, 15] = 0.5
    >>> d, why = envelope_disparity(a, b, search_px=(6, 6))
    >>> round(d.dx_px, 1), round(d.dy_px, 1), why
    (2.5, 1.0, '')
    """
    import cv2

    a = np.asarray(first, np.float32)
    b = np.asarray(second, np.float32)
    if a.ndim != 2 or a.shape != b.shape:
        raise InvalidParameterError("envelope_disparity: expected two (H, W) masks of one shape")
    wa = np.ones(a.shape, bool) if weight is None else np.asarray(weight, bool)
    if wa.shape != a.shape:
        raise InvalidParameterError("envelope_disparity: weight must have the masks' shape")
    sx, sy = int(search_px[0]), int(search_px[1])
    if sx < 1 or sy < 1:
        raise InvalidParameterError(f"envelope_disparity: search_px must be >= 1, got {search_px}")
    n = int(np.count_nonzero((a > 0.5) & wa))
    if n < MIN_ENVELOPE_PX:
        return None, (
            f"plume too small: {n} mask px, fewer than {MIN_ENVELOPE_PX}; no height is measured"
        )
    if blur_px > 0:
        a = np.asarray(cv2.GaussianBlur(a, (0, 0), blur_px), np.float32)
        b = np.asarray(cv2.GaussianBlur(b, (0, 0), blur_px), np.float32)
    gx, gy = round(float(guess_px[0])), round(float(guess_px[1]))
    # template: the first frame's weighted box; image: the second around the guess
    rows, cols = np.nonzero(wa)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    h, w = a.shape
    tpl, tm = a[r0:r1, c0:c1], wa[r0:r1, c0:c1].astype(np.float32)
    pad = ((sy + h, sy + h), (sx + w, sx + w))
    bp = np.pad(b, pad)
    bm = np.pad(np.ones_like(b), pad)
    y0, x0 = r0 + gy - sy + pad[0][0], c0 + gx - sx + pad[1][0]
    y0, x0 = (
        min(max(y0, 0), bp.shape[0] - tpl.shape[0] - 2 * sy),
        min(max(x0, 0), bp.shape[1] - tpl.shape[1] - 2 * sx),
    )
    win = bp[y0 : y0 + tpl.shape[0] + 2 * sy, x0 : x0 + tpl.shape[1] + 2 * sx]
    wm = bm[y0 : y0 + tpl.shape[0] + 2 * sy, x0 : x0 + tpl.shape[1] + 2 * sx]
    score = _masked_ncc(tpl, tm, win, wm, min_overlap=0.5 * float(tm.sum()))
    iy, ix = np.unravel_index(int(np.argmax(score)), score.shape)
    best = float(score[iy, ix])
    if not best > MIN_ENVELOPE_NCC:
        return None, f"envelopes do not match (correlation {best:.2f}); no height is measured"
    if iy in (0, score.shape[0] - 1) or ix in (0, score.shape[1] - 1):
        return None, f"{EDGE_MATCH}; no height is measured"

    def vertex(m: float, c: float, p: float) -> float:
        den = m - 2.0 * c + p
        return 0.0 if den >= 0 else float(np.clip(0.5 * (m - p) / den, -0.5, 0.5))

    fy = vertex(score[iy - 1, ix], best, score[iy + 1, ix])
    fx = vertex(score[iy, ix - 1], best, score[iy, ix + 1])
    dx = x0 - pad[1][0] + ix - c0 + fx
    dy = y0 - pad[0][0] + iy - r0 + fy
    return Disparity(float(dx), float(dy), best, n), ""


def _masked_ncc(
    tpl: np.ndarray, tm: np.ndarray, img: np.ndarray, im: np.ndarray, *, min_overlap: float
) -> np.ndarray:
    """Normalised cross-correlation of ``tpl`` (weights ``tm``) at every position inside
    ``img`` (weights ``im``), over each overlap only (Padfield 2012); -1 where the overlap
    is below ``min_overlap`` or flat."""
    import cv2

    def corr(x: np.ndarray, k: np.ndarray) -> np.ndarray:
        return cv2.matchTemplate(
            np.ascontiguousarray(x, np.float32), np.ascontiguousarray(k, np.float32), cv2.TM_CCORR
        ).astype(np.float64)

    t = tpl * tm
    overlap = corr(im, tm)
    s_i = corr(img * im, tm)
    s_ii = corr(img * img * im, tm)
    s_t = corr(im, t)
    s_tt = corr(im, t * tpl)
    s_it = corr(img * im, t)
    with np.errstate(invalid="ignore", divide="ignore"):
        nn = np.maximum(overlap, 1e-9)
        num = s_it - s_i * s_t / nn
        var_i = s_ii - s_i**2 / nn
        var_t = s_tt - s_t**2 / nn
        ncc = num / np.sqrt(np.maximum(var_i, 0.0) * np.maximum(var_t, 0.0))
    bad = (overlap < min_overlap) | ~np.isfinite(ncc) | (var_i <= 1e-9) | (var_t <= 1e-9)
    return np.where(bad, -1.0, ncc)
