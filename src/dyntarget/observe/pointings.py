"""Scoring timed pointings against a truth that changes: each at its own time, over its footprint.

A pass (:mod:`dyntarget.fly.loop`) flies pointings over a strip whose plumes
move; each pointing observes the truth *at its own time*. The truth comes from
``truth_at(t, row) -> (maps, first_row)``: maps of the NFOV footprint's mean plume
fraction, intensity and gradient utility, plume ids and validity on the strip's
WFOV grid (:class:`FootprintMaps`), holding WFOV row ``row`` and starting at
``first_row`` (a long strip is scored band by band).

In a 3D world (plumes with heights) a pointing is a line of sight (:class:`Sight`): it
observes the highest plume layer it meets, not the truth on the ground under its aim.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from dyntarget import parallax
from dyntarget.errors import InvalidParameterError


class FootprintMaps(Protocol):
    """The truth on NFOV footprints centred on WFOV pixels (e.g. ``synth.worlds.WfovTruth``)."""

    @property
    def plume(self) -> np.ndarray:
        """``(H, W)`` mean plume fraction over the footprint."""
        ...

    @property
    def intensity(self) -> np.ndarray:
        """``(H, W)`` mean intensity utility."""
        ...

    @property
    def gradient(self) -> np.ndarray:
        """``(H, W)`` mean gradient utility."""
        ...

    @property
    def ids(self) -> np.ndarray:
        """``(H, W)`` largest plume id under each pixel."""
        ...

    @property
    def valid(self) -> np.ndarray:
        """Boolean ``(H, W)``: no nodata under the pixel."""
        ...


TruthAt = Callable[[float, int], tuple[FootprintMaps, int]]
"""``truth_at(t, row) -> (maps, first_row)``: the maps at time ``t`` holding WFOV row ``row``."""


@dataclass(frozen=True)
class PointingScores:
    """What each pointing observed: per pointing, in the order given.

    Parameters
    ----------
    rows, cols : numpy.ndarray
        The WFOV pixel each pointing is on (strip rows).
    inside : numpy.ndarray
        Boolean: the pixel lies on the strip's grid (else nothing is observed).
    plume, intensity, gradient : list of float
        Mean plume fraction, intensity and gradient utility over the footprint.
    plume_id : list of int
        The true plume observed (0: none).
    """

    rows: np.ndarray
    cols: np.ndarray
    inside: np.ndarray
    plume: list[float]
    intensity: list[float]
    gradient: list[float]
    plume_id: list[int]

    def totals(self) -> tuple[float, float, float]:
        """Plume fraction, intensity and gradient summed in order (one float each).

        Returns
        -------
        tuple of float
            ``(plume, intensity, gradient)``.
        """
        p = i = g = 0.0
        for a, b, c in zip(self.plume, self.intensity, self.gradient, strict=True):
            p, i, g = p + a, i + b, g + c
        return p, i, g


@dataclass(frozen=True)
class Sight:
    """How the NFOV's lines of sight cross a 3D world's plumes (:func:`score_pointings`).

    The spacecraft flies at ``altitude_m`` over the strip; at pass time ``T`` its nadir
    is ``nadir(T)`` in the strip's WFOV pixels (``(x, y)``, the spacecraft flying
    towards row 0), and the truth's plume ``i`` has its top ``heights(T)[i]`` metres
    above sea level (0: on the ground). Positions on the WFOV grid are taken as a
    map of the track frame about the nadir: a pixel ``(x, y)`` lies
    ``along = (y_n - y) * gsd_m``, ``cross = (x - x_n) * gsd_m`` from it.

    Parameters
    ----------
    nadir : callable
        ``nadir(T) -> (x, y)``: the nadir at pass time ``T``, strip WFOV pixels.
    gsd_m : float
        Metres per WFOV pixel.
    altitude_m : float
        The spacecraft's altitude, metres.
    heights : callable
        ``heights(T) -> array``: top height per truth plume id, metres (index 0 unused),
        as :meth:`dyntarget.synth.worlds.World.heights_at` gives it.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For a GSD or altitude that is not a positive finite number, or a non-callable.

    Examples
    --------
    >>> s = Sight(lambda t: (2.0, 514.0), 1000.0, 500e3, lambda t: np.array([0.0, 10e3]))
    >>> s.nadir(0.0), s.heights(0.0).tolist()
    ((2.0, 514.0), [0.0, 10000.0])
    """

    nadir: Callable[[float], tuple[float, float]]
    gsd_m: float
    altitude_m: float
    heights: Callable[[float], np.ndarray]

    def __post_init__(self) -> None:
        for name in ("gsd_m", "altitude_m"):
            v = getattr(self, name)
            if (
                isinstance(v, bool)
                or not isinstance(v, int | float)
                or not math.isfinite(v)
                or v <= 0
            ):
                raise InvalidParameterError(f"sight {name}: expected metres > 0, got {v!r:.40}")
        if not self.altitude_m <= parallax.MAX_ALTITUDE_M:
            raise InvalidParameterError(
                f"sight altitude_m: expected at most {parallax.MAX_ALTITUDE_M:g} m, "
                f"got {self.altitude_m!r}"
            )
        for name in ("nadir", "heights"):
            if not callable(getattr(self, name)):
                raise InvalidParameterError(f"sight {name}: expected a callable of the pass time")

    def nadir_at(self, t: float) -> tuple[float, float]:
        """The nadir at ``t``, checked finite.

        Parameters
        ----------
        t : float
            Pass time, seconds.

        Returns
        -------
        tuple of float
            ``(x, y)``, strip WFOV pixels.

        Examples
        --------
        >>> Sight(lambda t: (1.0, 10.0 - t), 8.0, 500e3, lambda t: np.zeros(1)).nadir_at(2.0)
        (1.0, 8.0)
        """
        try:
            x, y = (float(v) for v in self.nadir(t))
        except (TypeError, ValueError):
            raise InvalidParameterError(f"sight nadir at t={t:g} s: expected (x, y)") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise InvalidParameterError(f"sight nadir at t={t:g} s: not finite: ({x}, {y})")
        return x, y

    def heights_at(self, t: float) -> np.ndarray:
        """The plume heights at ``t``, checked (1-D, finite, >= 0).

        Parameters
        ----------
        t : float
            Pass time, seconds.

        Returns
        -------
        numpy.ndarray
            float64 metres per plume id.

        Examples
        --------
        >>> Sight(lambda t: (0.0, 0.0), 8.0, 500e3, lambda t: [0, 5e3]).heights_at(0.0).tolist()
        [0.0, 5000.0]
        """
        try:
            h = np.asarray(self.heights(t), np.float64)
        except (TypeError, ValueError):
            raise InvalidParameterError(f"sight heights at t={t:g} s: expected numbers") from None
        if h.ndim != 1 or not (np.isfinite(h).all() and (h >= 0).all()):
            raise InvalidParameterError(
                f"sight heights at t={t:g} s: expected a 1-D array of finite metres >= 0"
            )
        if (h > parallax.MAX_HEIGHT_M).any() or (h >= self.altitude_m).any():
            raise InvalidParameterError(
                f"sight heights at t={t:g} s: a plume top above {parallax.MAX_HEIGHT_M:g} m "
                "or the spacecraft"
            )
        return h


def score_pointings(
    points: np.ndarray,
    times_s: Sequence[float] | np.ndarray,
    top: int,
    shape: tuple[int, int],
    truth_at: TruthAt,
    sight: Sight | None = None,
) -> PointingScores:
    """Score pointings against the truth at each one's own time.

    Without a ``sight`` (a flat world) a pointing observes the truth's footprint maps
    on the WFOV pixel it rounds to. With a ``sight`` (a 3D world) it is the line of sight
    from the spacecraft at its time through its ground point (the aimed point, strip
    WFOV pixels): for each truth plume ``i`` raised at that time (``h_i > 0``), the
    line crosses height ``h_i`` above the ground point
    :func:`dyntarget.parallax.unshift_xy` gives (nearer the nadir); the layer is met
    when the truth there (the pixel that point rounds to) has id ``i``. The highest
    layer met is observed: its footprint values there, plume id ``i``. A line that
    meets no layer observes the ground at the pointing: today's values, unless the
    truth there is a raised plume (the line passes beneath it: nothing observed).
    Each layer is thin (the column's umbrella at its top height, as
    :meth:`dyntarget.synth.dynamic.World.render_look` draws it); the footprint values
    read at the crossing are the truth's, so a ground plume overlapping it counts too.
    Meteorological clouds are not modelled here: they neither hide a plume nor count.

    Parameters
    ----------
    points : numpy.ndarray
        ``(N, 2)`` pointings ``(x, y)`` in a frame's WFOV pixels (pixel centres at
        integers; a pointing is on the pixel it rounds to, halves up).
    times_s : sequence of float
        When each observed, in the time ``truth_at`` takes.
    top : int
        The frame's top row on the strip's WFOV grid (``y + top`` is the strip row).
    shape : tuple of int
        The strip's WFOV grid ``(H, W)``.
    truth_at : callable
        ``truth_at(t, row) -> (maps, first_row)`` (:data:`TruthAt`).
    sight : Sight or None
        The lines of sight in a 3D world; ``None``: each pointing observes the truth
        under its pixel.

    Returns
    -------
    PointingScores
        Per pointing; pointings off the grid or on nodata observe nothing. ``rows`` and
        ``cols`` are the pixels aimed at, also with a sight.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        With a sight: a nadir or height that is not finite, or a truth plume id without
        a height.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> z = np.zeros((4, 4))
    >>> plume = z.copy(); plume[2, 1] = 0.5
    >>> maps = SimpleNamespace(plume=plume, intensity=plume * 2, gradient=z, ids=(plume > 0) * 7,
    ...                        valid=np.ones((4, 4), bool))
    >>> s = score_pointings(np.array([[1.0, 0.6], [9.0, 0.0]]), [3.0, 4.0], 1, (4, 4),
    ...                     lambda t, r: (maps, 0))
    >>> s.plume, s.plume_id, s.inside.tolist(), s.totals()
    ([0.5, 0.0], [7, 0], [True, False], (0.5, 1.0, 0.0))

    A 10 km plume top (id 1) truly over strip pixel (row 14, col 2), the nadir 500 km
    (500 px of 1 km) behind it: aimed at its ground position the line of sight passes
    under it; aimed 11.5 px farther from the nadir (its parallax) it meets the top.

    >>> plume = np.zeros((20, 5)); plume[14, 2] = 1.0
    >>> maps = SimpleNamespace(plume=plume, intensity=plume, gradient=plume,
    ...                        ids=(plume > 0) * 1, valid=np.ones((20, 5), bool))
    >>> sight = Sight(lambda t: (2.0, 514.0), 1000.0, 500e3, lambda t: np.array([0.0, 10e3]))
    >>> s = score_pointings(np.array([[2.0, 14.0], [2.0, 2.5]]), [0.0, 0.0], 0, (20, 5),
    ...                     lambda t, r: (maps, 0), sight=sight)
    >>> s.plume_id, s.plume
    ([0, 1], [0.0, 1.0])
    """
    hw, ww = shape
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    n = len(pts)
    rows = np.floor(pts[:, 1] + 0.5).astype(np.int64) + top
    cols = np.floor(pts[:, 0] + 0.5).astype(np.int64)
    inside = (rows >= 0) & (rows < hw) & (cols >= 0) & (cols < ww)
    plume, intensity, gradient = [0.0] * n, [0.0] * n, [0.0] * n
    ids = [0] * n
    if sight is not None:
        _score_sight(pts, times_s, top, shape, truth_at, sight, rows, cols, inside,
                     (plume, intensity, gradient, ids))  # fmt: skip
        return PointingScores(rows, cols, inside, plume, intensity, gradient, ids)
    for j in np.flatnonzero(inside):
        r, c = int(rows[j]), int(cols[j])
        maps, first = truth_at(float(times_s[int(j)]), r)
        rb = r - first
        if maps.valid[rb, c]:
            plume[j] = float(maps.plume[rb, c])
            intensity[j] = float(maps.intensity[rb, c])
            gradient[j] = float(maps.gradient[rb, c])
            ids[j] = int(maps.ids[rb, c]) if plume[j] > 0 else 0
    return PointingScores(rows, cols, inside, plume, intensity, gradient, ids)


class _Maps:
    """The footprint maps holding a row at a time, fetched once per band (one scoring call)."""

    def __init__(self, truth_at: TruthAt) -> None:
        self.truth_at = truth_at
        self.got: dict[float, list[tuple[FootprintMaps, int]]] = {}

    def at(self, t: float, r: int) -> tuple[FootprintMaps, int]:
        for maps, first in self.got.get(t, []):
            if first <= r < first + maps.plume.shape[0]:
                return maps, first
        maps, first = self.truth_at(t, r)
        self.got.setdefault(t, []).append((maps, first))
        return maps, first


def _score_sight(
    pts: np.ndarray,
    times_s: Sequence[float] | np.ndarray,
    top: int,
    shape: tuple[int, int],
    truth_at: TruthAt,
    sight: Sight,
    rows: np.ndarray,
    cols: np.ndarray,
    inside: np.ndarray,
    out: tuple[list[float], list[float], list[float], list[int]],
) -> None:
    """:func:`score_pointings` along lines of sight: fill ``out`` for the pointings inside."""
    plume, intensity, gradient, ids = out
    hw, ww = shape
    idx = np.flatnonzero(inside)
    if len(idx) == 0:
        return
    times = np.array([float(times_s[int(j)]) for j in idx], np.float64)
    uniq, inv = np.unique(times, return_inverse=True)
    nadirs = np.array([sight.nadir_at(float(t)) for t in uniq], np.float64).reshape(-1, 2)
    per_time = [sight.heights_at(float(t)) for t in uniq]
    m = max(len(h) for h in per_time)
    heights = np.zeros((len(uniq), max(m, 1)), np.float64)
    for k, h in enumerate(per_time):
        heights[k, : len(h)] = h
    heights[:, 0] = 0.0  # id 0 is no plume
    hj = heights[inv]  # (n_in, ids): each pointing's heights at its time
    xn, yn = nadirs[inv, 0], nadirs[inv, 1]
    g = float(sight.gsd_m)
    along = (yn - (pts[idx, 1] + top)) * g
    cross = (pts[idx, 0] - xn) * g
    # every (pointing, raised plume) pair: where the line of sight crosses that plume's top
    jj, ii = np.nonzero(hj > 0)
    ta, tc = parallax.unshift_xy(sight.altitude_m, along[jj], cross[jj], hj[jj, ii])
    ty, tx = yn[jj] - ta / g, xn[jj] + tc / g
    ok = np.isfinite(tx) & np.isfinite(ty)
    tr = np.where(ok, np.floor(np.where(ok, ty, 0.0) + 0.5), -1).astype(np.int64)
    tcl = np.where(ok, np.floor(np.where(ok, tx, 0.0) + 0.5), -1).astype(np.int64)
    on = ok & (tr >= 0) & (tr < hw) & (tcl >= 0) & (tcl < ww)
    # per pointing, its layers from the highest down (equal heights: the lower id first)
    order = np.lexsort((ii, -hj[jj, ii], jj))
    starts = np.searchsorted(jj[order], np.arange(len(idx) + 1))
    maps_at = _Maps(truth_at)
    for q, j in enumerate(idx):
        t = float(times[q])
        hit = False
        for p in order[starts[q] : starts[q + 1]]:
            if not on[p]:
                continue
            r, c, i = int(tr[p]), int(tcl[p]), int(ii[p])
            maps, first = maps_at.at(t, r)
            rb = r - first
            if maps.valid[rb, c] and int(maps.ids[rb, c]) == i:
                plume[j] = float(maps.plume[rb, c])
                intensity[j] = float(maps.intensity[rb, c])
                gradient[j] = float(maps.gradient[rb, c])
                ids[j] = i
                hit = True
                break
        if hit:
            continue
        r, c = int(rows[j]), int(cols[j])
        maps, first = maps_at.at(t, r)
        rb = r - first
        if not maps.valid[rb, c]:
            continue
        pid = int(maps.ids[rb, c])
        if pid >= len(per_time[inv[q]]) and pid > 0:
            raise InvalidParameterError(
                f"sight heights at t={t:g} s: {len(per_time[inv[q]])} values, "
                f"but the truth has plume id {pid}"
            )
        if pid > 0 and hj[q, pid] > 0:
            continue  # the line of sight passes beneath this raised plume: the ground
        plume[j] = float(maps.plume[rb, c])
        intensity[j] = float(maps.intensity[rb, c])
        gradient[j] = float(maps.gradient[rb, c])
        ids[j] = pid if plume[j] > 0 else 0
