"""The world's volcanoes, their eruptions and plumes, and the weather that hides them.

* :func:`read_catalog`: a GVP Holocene volcano list (CSV: ``volcano_number``,
  ``latitude``, ``longitude``, ``elevation_m``, ``last_known_eruption``; other columns
  ignored), read by :func:`dyntarget.io.catalog.read_catalog` with every one of these
  columns required. One line names the row and field of anything wrong.
* :func:`draw_eruptions`: the stochastic eruption model. An *eruption* here is an
  eruptive episode that raises a plume (an explosion, an ash-emission pulse), not a
  GVP eruption (which may last years and hold thousands of episodes). Onsets are a
  Poisson process over the period, ``eruptions_per_day`` expected in all, shared out
  between volcanoes by a weight that grows with how recently each last erupted
  (:data:`RECENCY_WEIGHTS`: 100 for a last eruption in 2020 CE or later, 20 in
  2000-2019, 3 in 1900-1999, 1 before 1900 CE, 0.1 BCE or unknown). Durations are
  log-normal (median :data:`MEDIAN_DURATION_S`, 3 h; log-sigma 1; 20 min to 3 days);
  a volcano has one episode at a time (an onset during its current episode is dropped).
* Each plume's drift and size follow dyntarget's plume model
  (:func:`dyntarget.synth.dynamic.sample_world`: wind speed and direction, the vent's
  source radius, turbulence and fade time); its length at age ``a`` is
  ``wind * min(a, 3 fade)`` (plus the source radius), its half-width
  ``2 (source radius + turbulence * wind * min(a, 3 fade))``. Its top height is not
  in the synthetic-scene model: it is drawn log-uniform in 1-15 km above the vent.
* Cloud cover (:func:`cloud_state`): per volcano and 3-hour block, overcast with
  probability :data:`CLOUD_FRACTION` (0.5) with a cloud top uniform in 1-12 km; a
  plume under the cloud top is hidden from every sensor, one above it is seen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.io.catalog import Catalog
from dyntarget.io.catalog import parse_catalog as _parse
from dyntarget.io.catalog import read_catalog as _read

RECENCY_WEIGHTS = ((2020, 100.0), (2000, 20.0), (1900, 3.0), (-10_000, 1.0))
"""``(since year CE, weight)``: the first row whose year the last eruption reaches."""
OLD_WEIGHT = 0.1
"""Weight of a volcano last active BCE or at an unknown date."""
MEDIAN_DURATION_S = 3 * 3600.0
MIN_DURATION_S, MAX_DURATION_S = 1200.0, 3 * 86400.0
CLOUD_BLOCK_S = 3 * 3600.0
CLOUD_FRACTION = 0.5


REQUIRED = ("volcano_number", "elevation_m", "last_known_eruption")
"""Columns ``--volcanoes`` needs besides latitude and longitude (:mod:`dyntarget.io.catalog`)."""


def parse_catalog(text: str, *, source: str = "volcanoes") -> Catalog:
    """A GVP volcano list from CSV text, every column the constellation needs required.

    :func:`dyntarget.io.catalog.parse_catalog` with :data:`REQUIRED`.

    Parameters
    ----------
    text : str
        The CSV text.
    source : str
        File name for messages.

    Returns
    -------
    Catalog
        The volcanoes.

    Examples
    --------
    >>> head = "volcano_number,latitude,longitude,elevation_m,last_known_eruption\\n"
    >>> c = parse_catalog(head + "1,19.4,-155.3,1222,2025 CE\\n")
    >>> c.number.tolist(), float(c.last_year[0])
    ([1], 2025.0)
    """
    return _parse(text, source=source, require=REQUIRED)


def read_catalog(path: str | Path) -> Catalog:
    """The ``--volcanoes`` file (:func:`dyntarget.io.catalog.read_catalog`, :data:`REQUIRED`).

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV file.

    Returns
    -------
    Catalog
        The volcanoes.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "v.csv"
    >>> _ = p.write_text("volcano_number,latitude,longitude,elevation_m,last_known_eruption\\n1,0,0,0,Unknown\\n")
    >>> len(read_catalog(p))
    1
    """
    return _read(path, require=REQUIRED, what="--volcanoes")


def recency_weight(last_year: np.ndarray) -> np.ndarray:
    """Eruption-rate weight per volcano from its last eruption year (:data:`RECENCY_WEIGHTS`).

    Parameters
    ----------
    last_year : numpy.ndarray
        Astronomical years (CE positive, 1 BCE is 0, earlier negative), NaN if unknown.

    Returns
    -------
    numpy.ndarray
        Weights.

    Examples
    --------
    >>> recency_weight(np.array([2025.0, 2010.0, 1950.0, 1500.0, -800.0, np.nan])).tolist()
    [100.0, 20.0, 3.0, 1.0, 0.1, 0.1]
    """
    y = np.asarray(last_year, np.float64)
    w = np.full(y.shape, OLD_WEIGHT)
    ce = np.isfinite(y) & (y > 0)
    for since, weight in reversed(RECENCY_WEIGHTS):
        w = np.where(ce & (y >= since), weight, w)
    return w


@dataclass(frozen=True)
class Eruptions:
    """Eruptive episodes with their plumes, as arrays (sorted by onset, then volcano).

    Parameters
    ----------
    volcano : numpy.ndarray
        Catalog index of each eruption's volcano.
    onset_s, end_s : numpy.ndarray
        Start and end, seconds after the simulation's start.
    wind_mps : numpy.ndarray
        Wind speed, m/s.
    drift_deg : numpy.ndarray
        Direction the plume drifts *to*, degrees clockwise from north.
    source_m, turbulence, fade_s : numpy.ndarray
        Source radius (m), relative dispersion and fade time (s) of the synthetic plume model.
    top_m : numpy.ndarray
        Plume top above the vent, metres.
    optical_depth : numpy.ndarray
        Plume optical depth near the vent.

    Examples
    --------
    >>> one = np.array
    >>> e = Eruptions(one([0]), one([0.0]), one([3600.0]), one([10.0]), one([90.0]), one([50.0]),
    ...     one([0.1]), one([600.0]), one([5000.0]), one([3.0]))
    >>> float(e.length_m(one([0]), one([100.0]))[0]), float(e.half_width_m(one([0]), one([100.0]))[0])
    (1050.0, 300.0)
    >>> e.active(one([0, 0]), one([-1.0, 10.0])).tolist()
    [False, True]
    """

    volcano: np.ndarray
    onset_s: np.ndarray
    end_s: np.ndarray
    wind_mps: np.ndarray
    drift_deg: np.ndarray
    source_m: np.ndarray
    turbulence: np.ndarray
    fade_s: np.ndarray
    top_m: np.ndarray
    optical_depth: np.ndarray

    def __len__(self) -> int:
        return len(self.volcano)

    def length_m(self, e: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Plume length (vent to front), metres, of eruptions ``e`` at times ``t``.

        Parameters
        ----------
        e : numpy.ndarray
            Eruption indices.
        t : numpy.ndarray
            Times, seconds after the start (broadcast with ``e``).

        Returns
        -------
        numpy.ndarray
            Lengths; 0 before onset.
        """
        age = np.clip(np.asarray(t, np.float64) - self.onset_s[e], 0.0, 3.0 * self.fade_s[e])
        return self.source_m[e] + self.wind_mps[e] * age

    def half_width_m(self, e: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Plume half-width (two sigmas of the puffs), metres.

        Parameters
        ----------
        e : numpy.ndarray
            Eruption indices.
        t : numpy.ndarray
            Times, seconds after the start.

        Returns
        -------
        numpy.ndarray
            Half-widths.
        """
        age = np.clip(np.asarray(t, np.float64) - self.onset_s[e], 0.0, 3.0 * self.fade_s[e])
        return 2.0 * (self.source_m[e] + self.turbulence[e] * self.wind_mps[e] * age)

    def active(self, e: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Whether eruptions ``e`` are under way at times ``t``.

        Parameters
        ----------
        e : numpy.ndarray
            Eruption indices.
        t : numpy.ndarray
            Times, seconds after the start.

        Returns
        -------
        numpy.ndarray
            Booleans.
        """
        t = np.asarray(t, np.float64)
        return (t >= self.onset_s[e]) & (t < self.end_s[e])

    def to_json(self) -> dict[str, list]:
        """The arrays as lists (task inputs: scattered to Dask workers, hashed for keys).

        Returns
        -------
        dict
            Field name -> list.
        """
        return {k: getattr(self, k).tolist() for k in self.__dataclass_fields__}

    @classmethod
    def from_json(cls, doc: dict[str, list]) -> Eruptions:
        """Inverse of :meth:`to_json`.

        Parameters
        ----------
        doc : dict
            As written by :meth:`to_json`.

        Returns
        -------
        Eruptions
            The eruptions.
        """
        return cls(
            **{
                k: np.asarray(doc[k], np.int64 if k == "volcano" else np.float64)
                for k in cls.__dataclass_fields__
            }
        )


def draw_eruptions(
    catalog: Catalog, *, seconds: float, seed: int, eruptions_per_day: float = 40.0
) -> Eruptions:
    """Draw the eruptive episodes that start during ``[0, seconds)`` (the module's model).

    Parameters
    ----------
    catalog : Catalog
        The volcanoes.
    seconds : float
        Length of the period, s.
    seed : int
        Seed (same seed, same eruptions).
    eruptions_per_day : float
        Expected onsets per day, world-wide.

    Returns
    -------
    Eruptions
        Sorted by onset.

    Examples
    --------
    >>> head = "volcano_number,latitude,longitude,elevation_m,last_known_eruption\\n"
    >>> cat = parse_catalog(head + "1,19.4,-155.3,1222,2025 CE\\n2,0,0,0,Unknown\\n")
    >>> e = draw_eruptions(cat, seconds=86400.0, seed=1, eruptions_per_day=20)
    >>> bool((cat.number[e.volcano] == 1).mean() > 0.5)  # the recently active one dominates
    True
    """
    from dyntarget.synth.dynamic import sample_world

    if not (math.isfinite(eruptions_per_day) and 0 < eruptions_per_day <= 10_000):
        raise InvalidParameterError(
            f"--eruptions-per-day: expected a number in (0, 10000], got {eruptions_per_day!r}"
        )
    rng = np.random.default_rng([int(seed), 0xE7])
    w = recency_weight(catalog.last_year)
    rate = eruptions_per_day * w / w.sum() / 86400.0  # per volcano, per second
    counts = rng.poisson(rate * seconds)
    vol = np.repeat(np.arange(len(catalog)), counts)
    onset = rng.uniform(0.0, seconds, len(vol))
    dur = np.clip(
        MEDIAN_DURATION_S * np.exp(rng.normal(0.0, 1.0, len(vol))), MIN_DURATION_S, MAX_DURATION_S
    )
    order = np.lexsort((vol, onset))
    vol, onset, dur = vol[order], onset[order], dur[order]
    keep = np.ones(len(vol), bool)
    busy: dict[int, float] = {}
    for i, (v, t0, d) in enumerate(zip(vol.tolist(), onset.tolist(), dur.tolist(), strict=True)):
        if busy.get(v, -math.inf) > t0:
            keep[i] = False
        else:
            busy[v] = t0 + d
    vol, onset, dur = vol[keep], onset[keep], dur[keep]
    n = len(vol)
    plume = np.zeros((n, 6))
    for i in range(n):
        spec = sample_world(int(seed), i, size=512, gsd=8.0)
        vent = spec.vents[0]
        plume[i] = (
            spec.wind.speed_mps,
            (spec.wind.from_deg + 180.0) % 360.0,
            vent.source_sigma_m,
            vent.turbulence,
            vent.fade_s,
            vent.emission_optical_depth,
        )
    top = np.exp(rng.uniform(math.log(1000.0), math.log(15_000.0), n))
    return Eruptions(
        volcano=vol.astype(np.int64),
        onset_s=onset,
        end_s=onset + dur,
        wind_mps=plume[:, 0],
        drift_deg=plume[:, 1],
        source_m=plume[:, 2],
        turbulence=plume[:, 3],
        fade_s=plume[:, 4],
        top_m=top,
        optical_depth=plume[:, 5],
    )


def cloud_state(
    volcano_numbers: np.ndarray, *, seconds: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Cloud top height (0: clear) per volcano and 3-hour block.

    Each volcano's blocks come from its own generator (seed and volcano number), so a
    volcano's weather does not depend on which other volcanoes are simulated.

    Parameters
    ----------
    volcano_numbers : numpy.ndarray
        GVP numbers of the volcanoes.
    seconds : float
        Length of the period, s.
    seed : int
        Seed.

    Returns
    -------
    top_m : numpy.ndarray
        ``(n_volcanoes, n_blocks)`` cloud top height above the vent, metres; 0 where clear.
    block_s : numpy.ndarray
        Start of each block, seconds.

    Examples
    --------
    >>> top, start = cloud_state(np.array([1, 2]), seconds=86400.0, seed=0)
    >>> top.shape, start[:3].tolist()  # 3-hour blocks
    ((2, 9), [0.0, 10800.0, 21600.0])
    """
    blocks = math.ceil(seconds / CLOUD_BLOCK_S) + 1
    top = np.zeros((len(volcano_numbers), blocks))
    for i, num in enumerate(np.asarray(volcano_numbers).tolist()):
        g = np.random.default_rng([int(seed), int(num), 0xC1])
        cloudy = g.uniform(size=blocks) < CLOUD_FRACTION
        top[i] = np.where(cloudy, g.uniform(1000.0, 12_000.0, blocks), 0.0)
    return top, np.arange(blocks) * CLOUD_BLOCK_S


def hidden(eruptions: Eruptions, cloud_top: np.ndarray, e: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Whether meteorological cloud hides eruption ``e``'s plume at time ``t``.

    Parameters
    ----------
    eruptions : Eruptions
        The eruptions.
    cloud_top : numpy.ndarray
        ``(n_eruptions, n_blocks)`` cloud top over each eruption's volcano (rows of
        :func:`cloud_state` taken per eruption).
    e : numpy.ndarray
        Eruption indices.
    t : numpy.ndarray
        Times, seconds.

    Returns
    -------
    numpy.ndarray
        True where the plume top is below the cloud top.

    Examples
    --------
    >>> one = np.array
    >>> e = Eruptions(one([0]), one([0.0]), one([1e4]), one([5.0]), one([0.0]), one([50.0]),
    ...     one([0.1]), one([600.0]), one([5000.0]), one([3.0]))
    >>> hidden(e, np.array([[8000.0, 0.0]]), one([0, 0]), one([100.0, 12000.0])).tolist()
    [True, False]
    """
    e = np.asarray(e, np.int64)
    b = np.clip(
        (np.asarray(t, np.float64) // CLOUD_BLOCK_S).astype(np.int64), 0, cloud_top.shape[1] - 1
    )
    top = cloud_top[e, b]
    return (top > 0) & (eruptions.top_m[e] < top)
