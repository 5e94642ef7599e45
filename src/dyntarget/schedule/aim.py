"""Aiming corrected for parallax: where the NFOV must point to meet a plume top at its own time.

The look-ahead (WFOV) frame is taken from the spacecraft over the nadir at the
acquisition (``t = 0``), looking ``look_ahead_m`` ahead: a plume top at height ``h``
shows in it displaced away from that nadir by its parallax. The NFOV flies a pointing
``t`` seconds later from a nadir ``ground_speed * t`` further along, and meets the same
top along its own line of sight, which crosses the ground elsewhere. A pointing planned
on the frame at pixel ``p`` (what the look-ahead saw) must therefore be moved:

* the true position under the top: ``true = unshift(p, h)`` in the look-ahead's view
  (:func:`dyntarget.parallax.unshift_xy` about the nadir at ``t = 0``);
* the ground point the NFOV aims at: ``aim = true + shift(true, h)`` in the NFOV's view
  at ``t`` (:func:`dyntarget.parallax.shift_xy` about the nadir at ``t``).

:class:`ParallaxAim` gives ``aim - p`` in WFOV pixels; the schedule adds it to every
pointing at its scheduled time (:func:`dyntarget.schedule.schedule_on_prediction`).
Exact on the sphere of :mod:`dyntarget.parallax`; positions follow the frame geometry of
:class:`~dyntarget.schedule.OrbitGeometry` (``along - ground_speed * t`` from the nadir
at ``t``). A pointing flown at ``t = 0`` sees what the look-ahead saw: it does not move.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError
from dyntarget.schedule.kinematics import OrbitGeometry

HeightField = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``heights_m(points, t_s) -> (N,)`` metres: the top height each pointing aims at."""


def nadir_xy(
    geometry: OrbitGeometry, frame_shape: tuple[int, int], t_s: float
) -> tuple[float, float]:
    """The nadir ``t_s`` seconds after a frame's acquisition, in that frame's WFOV pixels.

    ``x = (W - 1) / 2`` (the ground track runs down the frame's middle) and ``y`` is the
    row whose along-track distance ``look_ahead_m + ((H - 1) / 2 - y) * gsd`` equals
    ``ground_speed * t_s`` (rows below the frame, ``y > H - 1``, while the spacecraft
    has not reached it).

    Parameters
    ----------
    geometry : OrbitGeometry
        The frame's view geometry.
    frame_shape : tuple of int
        The frame's ``(H, W)``, WFOV pixels.
    t_s : float
        Seconds after the acquisition.

    Returns
    -------
    tuple of float
        ``(x, y)``, WFOV pixels of the frame (column, row).

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For a non-finite ``t_s`` or a bad ``frame_shape``.

    Examples
    --------
    >>> g = OrbitGeometry(altitude_m=500e3, look_ahead_m=500e3, wfov_gsd_m=100.0)
    >>> nadir_xy(g, (101, 11), 0.0)  # at the acquisition: 500 km = 5000 rows behind the centre
    (5.0, 5050.0)
    >>> x, y = nadir_xy(g, (101, 11), 500e3 / g.ground_speed)  # over the frame's centre
    >>> x, round(y, 9)
    (5.0, 50.0)
    """
    h, w = _shape(frame_shape)
    t = float(t_s)
    if not math.isfinite(t):
        raise InvalidParameterError(f"t_s: expected a finite number of seconds, got {t_s!r}")
    gsd = geometry.wfov_gsd_m
    y = (h - 1) / 2.0 + (geometry.look_ahead_m - geometry.ground_speed * t) / gsd
    return (w - 1) / 2.0, y


def _shape(frame_shape: tuple[int, int]) -> tuple[int, int]:
    try:
        h, w = (int(v) for v in frame_shape)
    except (TypeError, ValueError):
        raise InvalidParameterError(
            f"frame_shape: expected (rows, columns), got {frame_shape!r:.60}"
        ) from None
    if h < 1 or w < 1 or (h, w) != tuple(frame_shape):
        raise InvalidParameterError(
            f"frame_shape: expected two positive integers (rows, columns), got {frame_shape!r:.60}"
        )
    return h, w


def _heights(name: str, field: HeightField, pts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``field(pts, t)`` as ``(N,)`` float64 metres >= 0 (or NaN), or a refusal naming it."""
    h = np.asarray(field(pts, t), np.float64)
    if h.shape != (len(pts),):
        raise InvalidParameterError(
            f"{name}: expected {len(pts)} heights (one per pointing), got shape {h.shape}"
        )
    if np.any(np.isinf(h)) or np.any(h < 0):
        bad = h[np.isinf(h) | (h < 0)][0]
        raise InvalidParameterError(f"{name}: expected metres >= 0 (or NaN), got {float(bad)!r}")
    return h


@dataclass(frozen=True)
class ParallaxAim:
    """Parallax correction of pointings planned on a look-ahead frame (see the module).

    Parameters
    ----------
    geometry : OrbitGeometry
        The frame's view geometry: the spacecraft's altitude, the look-ahead distance at
        the acquisition, the WFOV GSD and the ground speed (``start_s`` is not used).
    frame_shape : tuple of int
        The frame's ``(H, W)``, WFOV pixels.
    heights_m : callable
        ``heights_m(points, t_s) -> (N,)``: the plume-top height, metres above the
        sphere, that each pointing (``(N, 2)`` frame pixels as planned, flown at
        ``t_s``, ``(N,)`` seconds after the acquisition) aims at. NaN or 0: no
        correction for that pointing. Negative or infinite heights are refused.
    look_heights_m : callable or None
        ``look_heights_m(points, t_s) -> (N,)``: the height the same tops had when the
        look-ahead saw them (at the acquisition), as known to a pointing flown at
        ``t_s``; it places each top's true position under what the look-ahead saw, and
        ``heights_m`` then aims the NFOV at it. ``None``: the same as ``heights_m`` (a
        top that does not rise between the look and the pointing). A rising column
        needs it: using its later height for both views misplaces it by the rise times
        the look-ahead's ``tan`` of its view zenith angle.
    look_s : float
        When the look-ahead took the frame, seconds after the acquisition that
        ``geometry`` and ``t_s`` refer to (>= 0): a frame taken late, catching up after
        a re-look (:class:`dyntarget.predict.relooks.HeightTracker`), was seen from a
        nadir ``ground_speed * look_s`` further along, at a smaller view angle. 0: on time.
    fill_px : float
        A pointing without a height of its own (NaN or 0: e.g. planned on the edge of a
        plume's mask, just off the plume its neighbours aim at) takes both heights of the
        nearest pointing shifted with it that has them, if that one lies strictly nearer
        than ``fill_px`` WFOV pixels (``fly`` uses twice the plan's transect spacing: one
        plume's pointings lie that close); further away it is not corrected. 0 (default):
        none takes another's. Without it, such a pointing stays where the look-ahead saw
        the plume, kilometres from its corrected neighbours, and the NFOV slews there and
        back.
    known_s : callable or None
        ``known_s(points) -> (N, 2)``: when the height each pointing (frame pixels as
        planned) is aimed with is known, ``(from, until)`` seconds after the acquisition
        (``inf``, ``inf``: never; NaN: the pointing is on no plume of its own, and takes
        the window of the nearest pointing within ``fill_px`` that has one, else any
        time). The schedule flies each pointing only inside its window
        (:meth:`windows`): not before its plume's height is measured, so that no pointing
        flies uncorrected, kilometres from the top, while the estimate is on its way.
        ``None`` (default): any time.

    Examples
    --------
    A 10 km top planned in a frame 500 km ahead of a spacecraft 500 km up (100 m pixels),
    flown when the spacecraft is straight above it: the NFOV looks straight down at the
    top's true position, which the look-ahead saw about 11.5 km (115 px) further ahead.

    >>> g = OrbitGeometry(altitude_m=500e3, look_ahead_m=500e3, wfov_gsd_m=100.0)
    >>> aim = ParallaxAim.constant(g, (101, 101), 10e3)
    >>> t = 500e3 / g.ground_speed  # when the nadir is under the true top
    >>> d = aim.shift(np.array([[50.0, 50.0 - 115.01447]]), t)
    >>> np.round(d, 2).tolist()  # back towards the spacecraft (down the frame), no cross-track move
    [[0.0, 115.01]]
    >>> bool(np.abs(aim.shift(np.array([[50.0, 50.0]]), 0.0)).max() < 1e-6)  # flown at t = 0: no move
    True

    The same frame taken 4 s late (the look-ahead catching up after a re-look) saw the
    top from 28 km nearer, less displaced: a pointing flown at that moment does not move
    either, and one flown over the top moves less than the on-time frame's 115 px.

    >>> late = ParallaxAim(g, (101, 101), aim.heights_m, look_s=4.0)
    >>> bool(np.abs(late.shift(np.array([[50.0, 50.0]]), 4.0)).max() < 1e-6)
    True
    >>> 0 < float(late.shift(np.array([[50.0, 50.0]]), t)[0, 1]) < 115.0
    True
    """

    geometry: OrbitGeometry
    frame_shape: tuple[int, int]
    heights_m: HeightField
    look_heights_m: HeightField | None = None
    look_s: float = 0.0
    fill_px: float = 0.0
    known_s: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        for name, what in (("fill_px", "WFOV pixels >= 0"),
                           ("look_s", "seconds >= 0 after the acquisition")):  # fmt: skip
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InvalidParameterError(f"{name}: expected {what}, got {v!r}")
        if not isinstance(self.geometry, OrbitGeometry):
            raise InvalidParameterError(
                f"geometry: expected an OrbitGeometry, got {type(self.geometry).__name__}"
            )
        object.__setattr__(self, "frame_shape", _shape(self.frame_shape))
        for name in ("heights_m", "look_heights_m", "known_s"):
            f = getattr(self, name)
            if not callable(f) and not (name != "heights_m" and f is None):
                raise InvalidParameterError(
                    f"{name}: expected a callable (points, t_s) -> heights, got {type(f).__name__}"
                )

    @classmethod
    def constant(
        cls, geometry: OrbitGeometry, frame_shape: tuple[int, int], height_m: float
    ) -> ParallaxAim:
        """An aim at one height for every pointing (a prior, e.g. a volcanic ash advisory's).

        Parameters
        ----------
        geometry : OrbitGeometry
            The frame's view geometry.
        frame_shape : tuple of int
            The frame's ``(H, W)``.
        height_m : float
            The plume-top height, metres above the sphere, finite and > 0 (at most
            :data:`dyntarget.parallax.MAX_HEIGHT_M`).

        Returns
        -------
        ParallaxAim

        Raises
        ------
        dyntarget.errors.InvalidParameterError
            For a height that is not finite, not positive or above the limit.

        Examples
        --------
        >>> ParallaxAim.constant(OrbitGeometry(), (8, 8), 5e3).heights_m(np.zeros((2, 2)), np.zeros(2))
        array([5000., 5000.])
        """
        h = _height(height_m)
        if not h > 0:
            raise InvalidParameterError(f"height_m: expected metres > 0, got {height_m!r}")

        def heights(points: np.ndarray, t_s: np.ndarray) -> np.ndarray:
            return np.full(len(points), h)

        return cls(geometry, frame_shape, heights)

    def shift(self, points: npt.ArrayLike, t_s: npt.ArrayLike) -> np.ndarray:
        """WFOV-pixel moves to add to pointings planned at ``points`` and flown at ``t_s``.

        Parameters
        ----------
        points : array_like
            ``(N, 2)`` pointings ``(x, y)``, pixels of the frame as the look-ahead saw
            it (column, row).
        t_s : float or array_like
            When each pointing is flown, seconds after the frame's acquisition: one
            value for all or ``(N,)``.

        Returns
        -------
        numpy.ndarray
            ``(N, 2)`` float64 ``(dx, dy)``, WFOV pixels: zero where the height is NaN
            or 0, and where the top or its aim lies beyond the horizon.

        Raises
        ------
        dyntarget.errors.InvalidParameterError
            For non-finite points or times, a times array of another length, or heights
            that are negative, infinite, above the spacecraft or of the wrong length.

        Examples
        --------
        A 10 km top 500 km ahead and 300 km to the right, flown 10 s after the
        acquisition: the look-ahead saw it further out than the NFOV will, so the aim
        moves back towards the spacecraft and towards the track.

        >>> g = OrbitGeometry(altitude_m=500e3, look_ahead_m=500e3, wfov_gsd_m=100.0)
        >>> aim = ParallaxAim.constant(g, (101, 6001), 10e3)
        >>> dx, dy = aim.shift(np.array([[6000.0, 50.0]]), 10.0)[0]
        >>> bool(dx < 0 and dy > 0)
        True
        """
        return self.move(points, t_s)[0]

    def windows(self, points: npt.ArrayLike) -> np.ndarray | None:
        """When each pointing may be flown: while the height it is aimed with is known.

        Parameters
        ----------
        points : array_like
            ``(N, 2)`` pointings ``(x, y)``, frame pixels as planned.

        Returns
        -------
        numpy.ndarray or None
            ``(N, 2)`` float64 ``(from, until)``, seconds after the acquisition
            (:attr:`dyntarget.trajectory.Trajectory.windows`); ``None`` without
            ``known_s``.

        Raises
        ------
        dyntarget.errors.InvalidParameterError
            For non-finite points, or ``known_s`` giving the wrong shape or a window that
            ends before it starts.

        Examples
        --------
        Two pointings on a plume whose height is known from 20 s, and one on no plume of
        its own: 1 px from the first (it waits with it), or 10 px away (any time).

        >>> g = OrbitGeometry()
        >>> def known(p):
        ...     return np.where(p[:, :1] < 5, [[20.0, np.inf]], np.nan)
        >>> aim = ParallaxAim(g, (32, 32), lambda p, t: np.full(len(p), 5e3), fill_px=4.0,
        ...                   known_s=known)
        >>> aim.windows(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [11.0, 0.0]])).tolist()
        [[20.0, inf], [20.0, inf], [20.0, inf], [-inf, inf]]
        """
        if self.known_s is None:
            return None
        pts = np.asarray(points, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all():
            raise InvalidParameterError(
                f"points: expected an (N, 2) array of finite (x, y) pixels, got shape {pts.shape}"
            )
        w = np.array(self.known_s(pts), np.float64)
        if w.shape != (len(pts), 2):
            raise InvalidParameterError(
                f"known_s: expected ({len(pts)}, 2) windows (one per pointing), got shape {w.shape}"
            )
        own = np.asarray(~np.isnan(w).any(axis=1))
        if np.any(w[own, 1] < w[own, 0]):
            bad = w[own][w[own, 1] < w[own, 0]][0].tolist()
            raise InvalidParameterError(f"known_s: a window ends before it starts: {bad}")
        if self.fill_px > 0 and own.any() and not own.all():
            src = _nearest(pts, own, self.fill_px)
            got = src >= 0
            w[np.flatnonzero(~own)[got]] = w[src[got]]
            own[np.flatnonzero(~own)[got]] = True
        w[~own] = (-np.inf, np.inf)
        return w

    def move(self, points: npt.ArrayLike, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`shift`, and the height each moved pointing is aimed at.

        Parameters
        ----------
        points, t_s : array_like
            As for :meth:`shift`.

        Returns
        -------
        shift : numpy.ndarray
            ``(N, 2)`` float64 ``(dx, dy)``, WFOV pixels (:meth:`shift`).
        heights : numpy.ndarray
            ``(N,)`` float64 metres: the top height the moved line of sight meets (the
            one corrected for, a neighbour's where it took one); 0 where not corrected.
            The NFOV tracks that top after observing it
            (:attr:`dyntarget.trajectory.Trajectory.heights`).

        Examples
        --------
        >>> g = OrbitGeometry(altitude_m=500e3, look_ahead_m=500e3, wfov_gsd_m=100.0)
        >>> d, h = ParallaxAim.constant(g, (101, 101), 10e3).move(np.array([[50.0, 50.0]]), 30.0)
        >>> h.tolist(), bool(d[0, 1] > 0)
        ([10000.0], True)
        """
        pts = np.asarray(points, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise InvalidParameterError(
                f"points: expected an (N, 2) array of (x, y) pixels, got shape {pts.shape}"
            )
        n = len(pts)
        t = np.asarray(t_s, np.float64)
        if t.ndim == 0:
            t = np.full(n, float(t))
        if t.shape != (n,):
            raise InvalidParameterError(
                f"t_s: expected one time or {n} times (one per pointing), got shape {t.shape}"
            )
        if not (np.isfinite(pts).all() and np.isfinite(t).all()):
            raise InvalidParameterError("points, t_s: expected finite pixels and seconds")
        out, aimed = np.zeros((n, 2)), np.zeros(n)
        if n == 0:
            return out, aimed
        h = _heights("heights_m", self.heights_m, pts, t)
        h_look = h if self.look_heights_m is None else _heights(
            "look_heights_m", self.look_heights_m, pts, t
        )  # fmt: skip
        on = np.isfinite(h) & (h > 0) & np.isfinite(h_look) & (h_look > 0)
        if not on.any():
            return out, aimed
        if self.fill_px > 0 and not on.all():
            h, h_look, on = _fill(pts, h, h_look, on, self.fill_px)
        g = self.geometry
        along, cross = g.ground(pts[on], self.frame_shape)
        alt = g.altitude_m
        seen = g.ground_speed * self.look_s  # the look-ahead's nadir when it took the frame
        true_a, true_c = parallax.unshift_xy(alt, along - seen, cross, h_look[on])
        true_a = true_a + seen
        moved = g.ground_speed * t[on]  # the NFOV's nadir at t, along the track
        rel_a = true_a - moved
        finite = np.isfinite(true_a) & np.isfinite(true_c)
        da, dc = parallax.shift_xy(
            alt, np.where(finite, rel_a, 0.0), np.where(finite, true_c, 0.0), h[on]
        )
        aim_a, aim_c = true_a + da, true_c + dc
        gsd = g.wfov_gsd_m
        d = np.stack([(aim_c - cross) / gsd, -(aim_a - along) / gsd], axis=1)
        beyond = ~np.isfinite(d).all(axis=1)  # beyond the horizon: nothing to correct for
        d[beyond] = 0.0
        out[on] = d
        aimed[on] = np.where(beyond, 0.0, h[on])
        return out, aimed


def _fill(
    pts: np.ndarray, h: np.ndarray, h_look: np.ndarray, on: np.ndarray, radius: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heights with each pointing off ``on`` given its nearest ``on`` neighbour's within ``radius``."""
    off = np.flatnonzero(~on)
    src = _nearest(pts, on, radius)
    got = src >= 0
    h, h_look, on = h.copy(), h_look.copy(), on.copy()
    h[off[got]], h_look[off[got]], on[off[got]] = h[src[got]], h_look[src[got]], True
    return h, h_look, on


def plume_of(points: npt.ArrayLike, ids: npt.ArrayLike, fill_px: float) -> np.ndarray:
    """Each pointing's plume as :class:`ParallaxAim` aims it: its own, or, off every plume,
    that of its nearest pointing on one strictly within ``fill_px`` pixels (the one whose
    heights it takes), else none.

    Parameters
    ----------
    points : array_like
        ``(N, 2)`` pointings, ``(x, y)`` pixels.
    ids : array_like
        ``(N,)`` plume ids under them (0: on none).
    fill_px : float
        :attr:`ParallaxAim.fill_px` (0: none takes another's).

    Returns
    -------
    numpy.ndarray
        ``(N,)`` int64 plume ids.

    Examples
    --------
    Two pointings on plume 3 and, off it, one 1.5 px from the second and one 5 px away:

    >>> pts = np.array([[0.0, 0.0], [2.0, 0.0], [3.5, 0.0], [7.0, 0.0]])
    >>> plume_of(pts, [3, 3, 0, 0], 4.0).tolist()
    [3, 3, 3, 0]
    """
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    out = np.array(ids, np.int64).reshape(-1)
    on = out > 0
    if fill_px > 0 and on.any() and not on.all():
        src = _nearest(pts, on, fill_px)
        out[np.flatnonzero(~on)[src >= 0]] = out[src[src >= 0]]
    return out


def _nearest(pts: np.ndarray, on: np.ndarray, radius: float) -> np.ndarray:
    """For each pointing off ``on``, the index of its nearest ``on`` pointing strictly
    within ``radius`` pixels (-1: none)."""
    from scipy.spatial import cKDTree

    have = np.flatnonzero(on)
    dist, near = cKDTree(pts[have]).query(pts[~on], distance_upper_bound=radius)
    return np.where(np.isfinite(dist), have[np.minimum(near, len(have) - 1)], -1)


def _height(value: float) -> float:
    try:
        h = float(value)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"height_m: expected metres, got {value!r:.60}") from None
    if not (math.isfinite(h) and h <= parallax.MAX_HEIGHT_M):
        raise InvalidParameterError(
            f"height_m: expected finite metres up to {parallax.MAX_HEIGHT_M:g}, got {value!r}"
        )
    return h
