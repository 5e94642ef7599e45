"""Scoring timed pointings against a truth that changes: each at its own time, over its footprint.

A pass (:mod:`dyntarget.fly.loop`) flies pointings over a strip whose plumes
move; each pointing observes the truth *at its own time*. The truth comes from
``truth_at(t, row) -> (maps, first_row)``: maps of the NFOV footprint's mean plume
fraction, intensity and gradient utility, plume ids and validity on the strip's
WFOV grid (:class:`FootprintMaps`), holding WFOV row ``row`` and starting at
``first_row`` (a long strip is scored band by band).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np


class FootprintMaps(Protocol):
    """The truth on NFOV footprints centred on WFOV pixels (e.g. ``fly.world.WfovTruth``)."""

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


def score_pointings(
    points: np.ndarray,
    times_s: Sequence[float] | np.ndarray,
    top: int,
    shape: tuple[int, int],
    truth_at: TruthAt,
) -> PointingScores:
    """Score pointings against the truth at each one's own time.

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

    Returns
    -------
    PointingScores
        Per pointing; pointings off the grid or on nodata observe nothing.

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
    """
    hw, ww = shape
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    n = len(pts)
    rows = np.floor(pts[:, 1] + 0.5).astype(np.int64) + top
    cols = np.floor(pts[:, 0] + 0.5).astype(np.int64)
    inside = (rows >= 0) & (rows < hw) & (cols >= 0) & (cols < ww)
    plume, intensity, gradient = [0.0] * n, [0.0] * n, [0.0] * n
    ids = [0] * n
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
