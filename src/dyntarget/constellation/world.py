"""The world's volcanoes, their eruptions and plumes, and the weather that hides them.

* :func:`read_catalog`: a GVP Holocene volcano list (CSV: ``volcano_number``,
  ``latitude``, ``longitude``, ``elevation_m``, ``last_known_eruption``; other columns
  ignored), read by :func:`dyntarget.io.catalog.read_catalog` with every one of these
  columns required. One line names the row and field of anything wrong.
* Two stochastic eruption models (:data:`MODELS`); both share volcanoes out by a weight
  that grows with how recently each last erupted (:data:`RECENCY_WEIGHTS`: 100 for a
  last eruption in 2020 CE or later, 20 in 2000-2019, 3 in 1900-1999, 1 before 1900 CE,
  0.1 BCE or unknown; an assumption of this simulator).

  ``eruptions`` (:func:`draw_gvp_eruptions`, the default): two levels.
  **Level 1, GVP eruptions** (an eruption as the Global Volcanism Program counts one:
  eruptive activity without a break of 3 months or more). Those in progress when the
  period starts: a Poisson number with mean :data:`ERUPTIONS_IN_PROGRESS` (45: the GVP's
  "Current Eruptions" list held 48 continuing eruptions on 17 March 2022 and 46 in
  November 2023), at distinct volcanoes drawn by the recency weight; new onsets: a
  Poisson process of :data:`ONSETS_PER_YEAR` (15) a year, at volcanoes not already in
  eruption. 15 is the difference between the ~60 volcanoes active in a typical year
  (Simkin 1994, "Volcanoes: their occurrence and geography", USGS Bulletin 2047,
  pp. 75-79) and the ~45 whose eruptions are in progress at any time. Durations are
  log-normal with the median of the GVP's dated eruptions, 7 weeks (Simkin & Siebert
  1994, *Volcanoes of the World*, 2nd ed., 3,211 durations; repeated in Siebert, Simkin &
  Kimberly 2010, 3rd ed.), and a log-sigma (3.04) that puts 10 % of them under one day
  (the GVP's FAQ "How long does an eruption last?": 10 % lasted no longer than a day,
  most end in less than 3 months, few last longer than 3 years; the fit gives 58 % under
  3 months and 15 % over 3 years), clipped to 20 min - 100 years. An eruption already in
  progress is drawn as a stationary process has it: its whole duration length-biased
  (log-normal with log-mean raised by sigma squared, clipped the same way), the start
  of the period uniform within it; its onset lies before the start (negative).
  **Level 2, plume episodes** inside each eruption (explosions, ash-emission pulses): a
  Poisson process of :data:`EPISODES_PER_DAY` (3) a day from the eruption's onset (or
  3 days before the period, for one in progress), the first at the onset of a new
  eruption; durations log-normal (median :data:`MEDIAN_DURATION_S`, 3 h; log-sigma 1;
  20 min to 3 days, cut at the eruption's end); overlapping episodes merge. A plume
  exists only during an episode and grows from the episode's onset. No published
  statistic gives the pulse rate and durations world-wide: they are assumptions, chosen
  so that the fraction of eruptions raising a plume at a given moment,
  ``1 - exp(-rate * mean duration)`` = ``1 - exp(-3 / 24 * 4.93)`` = 0.46, matches the
  GVP's "around 20 volcanoes actively erupting at any particular time" of ~45 in
  eruption (``docs/constellation.md`` shows the sensitivity to them).

  ``episodes`` (:func:`draw_eruptions`, the model of earlier versions, kept to reproduce
  their figures): one level. An *eruption* there is an eruptive episode that raises a
  plume, not a GVP eruption. Onsets are a Poisson process over the period,
  ``eruptions_per_day`` expected in all, shared out by the recency weight; durations
  log-normal (median 3 h, log-sigma 1, 20 min to 3 days); a volcano has one episode at
  a time (an onset during its current episode is dropped). Nothing cited supports it.
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
from statistics import NormalDist

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
MODELS = ("eruptions", "episodes")
"""``--eruption-model``: two levels (GVP eruptions holding plume episodes) or episodes only."""
DAY_S, YEAR_S = 86400.0, 365.25 * 86400.0
ERUPTIONS_IN_PROGRESS = 45.0
"""Mean number of GVP eruptions in progress at any time (the GVP's continuing eruptions)."""
ONSETS_PER_YEAR = 15.0
"""New GVP eruptions a year, world-wide (~60 volcanoes active a year less ~45 in progress)."""
GVP_MEDIAN_DURATION_S = 49 * DAY_S
"""Median duration of a GVP eruption: 7 weeks (Simkin & Siebert 1994)."""
GVP_LOG_SIGMA = math.log(49.0) / NormalDist().inv_cdf(0.9)
"""Log-sigma of GVP eruption durations: 10 % last no longer than a day (GVP FAQ)."""
GVP_MIN_DURATION_S, GVP_MAX_DURATION_S = 1200.0, 100 * YEAR_S
EPISODES_PER_DAY = 3.0
"""Plume episodes a day within a GVP eruption (an assumption; see the module docstring)."""
EPISODE_LEAD_S = MAX_DURATION_S
"""Episodes of an eruption in progress are drawn from this long before the period."""


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
    episode_eruption, episode_onset_s, episode_end_s : numpy.ndarray or None
        The plume episodes of the two-level model (sorted by eruption, then onset; not
        overlapping within an eruption): a plume exists only during one, and grows from
        its onset. ``None`` (the episode model): the plume exists from ``onset_s`` to
        ``end_s``.

    Examples
    --------
    >>> one = np.array
    >>> e = Eruptions(one([0]), one([0.0]), one([3600.0]), one([10.0]), one([90.0]), one([50.0]),
    ...     one([0.1]), one([600.0]), one([5000.0]), one([3.0]))
    >>> float(e.length_m(one([0]), one([100.0]))[0]), float(e.half_width_m(one([0]), one([100.0]))[0])
    (1050.0, 300.0)
    >>> e.active(one([0, 0]), one([-1.0, 10.0])).tolist()
    [False, True]
    >>> two = Eruptions(one([0]), one([-9e5]), one([9e5]), one([10.0]), one([90.0]), one([50.0]),
    ...     one([0.1]), one([600.0]), one([5000.0]), one([3.0]),
    ...     one([0, 0]), one([-100.0, 500.0]), one([200.0, 800.0]))
    >>> two.active(one([0, 0, 0]), one([100.0, 300.0, 600.0])).tolist()  # between episodes: no plume
    [True, False, True]
    >>> float(two.length_m(one([0]), one([600.0]))[0])  # 100 s into the second episode
    1050.0
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
    episode_eruption: np.ndarray | None = None
    episode_onset_s: np.ndarray | None = None
    episode_end_s: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.volcano)

    @property
    def episodic(self) -> bool:
        """Whether plumes come in episodes within each eruption (the two-level model)."""
        return self.episode_onset_s is not None

    def plume_onset_s(self, e: np.ndarray, t: np.ndarray) -> np.ndarray:
        """When the plume of eruptions ``e`` seen at times ``t`` started.

        The eruption's onset in the episode model; in the two-level model the onset of
        the latest episode started by ``t`` (``inf`` if none has).

        Parameters
        ----------
        e : numpy.ndarray
            Eruption indices.
        t : numpy.ndarray
            Times, seconds after the start (broadcast with ``e``).

        Returns
        -------
        numpy.ndarray
            Seconds.
        """
        return self._episode(e, t)[0]

    def _episode(self, e: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Onset and end of the latest plume episode of ``e`` started by ``t``."""
        e, t = np.broadcast_arrays(np.asarray(e, np.int64), np.asarray(t, np.float64))
        if not self.episodic:
            return self.onset_s[e], self.end_s[e]
        assert self.episode_eruption is not None and self.episode_end_s is not None
        ep_e, ep_on, ep_end = self.episode_eruption, self.episode_onset_s, self.episode_end_s
        assert ep_on is not None
        onset = np.full(e.shape, math.inf)
        end = np.full(e.shape, -math.inf)
        lo = np.searchsorted(ep_e, e, side="left")
        hi = np.searchsorted(ep_e, e, side="right")
        for k in np.unique(e).tolist():  # the episodes of each eruption are sorted by onset
            sel = e == k
            a, b = int(lo[sel][0]), int(hi[sel][0])
            if a == b:  # no episode in the period: no plume (ep_on[a] may not exist)
                continue
            j = np.searchsorted(ep_on[a:b], t[sel], side="right") - 1
            ok = j >= 0
            jj = a + np.maximum(j, 0)
            onset[sel] = np.where(ok, ep_on[jj], math.inf)
            end[sel] = np.where(ok, ep_end[jj], -math.inf)
        return onset, end

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
        age = np.clip(np.asarray(t, np.float64) - self._onset(e, t), 0.0, 3.0 * self.fade_s[e])
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
        age = np.clip(np.asarray(t, np.float64) - self._onset(e, t), 0.0, 3.0 * self.fade_s[e])
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
        active = (t >= self.onset_s[e]) & (t < self.end_s[e])
        if self.episodic:
            on, end = self._episode(e, t)
            active = active & (t >= on) & (t < end)
        return active

    def _onset(self, e: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The plume's onset for its age (the episode's; 0 age where no episode has begun)."""
        if not self.episodic:
            return self.onset_s[e]
        on = self.plume_onset_s(e, t)
        return np.where(np.isfinite(on), on, np.asarray(t, np.float64))

    def to_json(self) -> dict[str, list]:
        """The arrays as lists (task inputs: scattered to Dask workers, hashed for keys).

        Returns
        -------
        dict
            Field name -> list.
        """
        return {
            k: getattr(self, k).tolist()
            for k in self.__dataclass_fields__
            if getattr(self, k) is not None  # the episode model: as it always was
        }

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
                k: np.asarray(
                    doc[k], np.int64 if k in ("volcano", "episode_eruption") else np.float64
                )
                for k in cls.__dataclass_fields__
                if k in doc
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
    plume = _plumes(seed, n)
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


def _plumes(seed: int, n: int) -> np.ndarray:
    """Plume parameters of ``n`` eruptions from the synthetic-scene model (one row each)."""
    from dyntarget.synth.dynamic import sample_world

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
    return plume


def _check(name: str, value: float, lo: float, hi: float) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and lo <= value <= hi):
        raise InvalidParameterError(
            f"--{name}: expected a number in [{lo:g}, {hi:g}], got {value!r}"
        )
    return float(value)


def _lognormal(rng: np.random.Generator, median: float, sigma: float, n: int, lo: float, hi: float):
    return np.clip(median * np.exp(rng.normal(0.0, sigma, n)), lo, hi)


def draw_gvp_eruptions(
    catalog: Catalog,
    *,
    seconds: float,
    seed: int,
    in_progress: float = ERUPTIONS_IN_PROGRESS,
    onsets_per_year: float = ONSETS_PER_YEAR,
    episodes_per_day: float = EPISODES_PER_DAY,
    episode_median_s: float = MEDIAN_DURATION_S,
) -> Eruptions:
    """Draw the two-level world: GVP eruptions over ``[0, seconds)`` and their plume episodes.

    The module docstring states the model and its sources. Eruptions in progress at the
    start have a negative ``onset_s``; every eruption's ``end_s`` may lie past the period.
    Episodes that ended before the start are dropped.

    Parameters
    ----------
    catalog : Catalog
        The volcanoes.
    seconds : float
        Length of the period, s.
    seed : int
        Seed (same seed, same world).
    in_progress : float
        Mean number of eruptions in progress at the start (at most one per volcano: a
        small catalog holds fewer).
    onsets_per_year : float
        New eruptions a year, world-wide.
    episodes_per_day : float
        Plume episodes a day within an eruption.
    episode_median_s : float
        Median episode duration, s (log-sigma 1, 20 min to 3 days).

    Returns
    -------
    Eruptions
        Sorted by onset, then volcano, with their episodes.

    Examples
    --------
    >>> head = "volcano_number,latitude,longitude,elevation_m,last_known_eruption\\n"
    >>> cat = parse_catalog(head + "".join(f"{i},0,{i},0,2025 CE\\n" for i in range(1, 90)))
    >>> w = draw_gvp_eruptions(cat, seconds=86400.0, seed=1)
    >>> 20 < len(w) < 75, bool((w.onset_s < 0).any()), bool(w.episodic)
    (True, True, True)
    """
    in_progress = _check("eruptions-in-progress", in_progress, 0.0, 100_000.0)
    onsets_per_year = _check("eruption-onsets-per-year", onsets_per_year, 0.0, 1e6)
    episodes_per_day = _check("episodes-per-day", episodes_per_day, 1e-6, 10_000.0)
    episode_median_s = _check("episode-median-h", episode_median_s / 3600.0, 1 / 60, 72.0) * 3600.0
    rng = np.random.default_rng([int(seed), 0xE8])
    w = recency_weight(catalog.last_year)
    # level 1: in progress at the start (a stationary process: length-biased durations,
    # the start uniform within them), then new onsets at volcanoes not in eruption
    k = min(int(rng.poisson(in_progress)), len(catalog))
    vol = rng.choice(len(catalog), size=k, replace=False, p=w / w.sum()) if k else np.zeros(0, int)
    total = _lognormal(
        rng,
        GVP_MEDIAN_DURATION_S * math.exp(GVP_LOG_SIGMA**2),
        GVP_LOG_SIGMA,
        k,
        GVP_MIN_DURATION_S,
        GVP_MAX_DURATION_S,
    )
    elapsed = rng.uniform(0.0, 1.0, k) * total
    onset, end = list(-elapsed), list(total - elapsed)
    vols = [int(v) for v in vol]
    new = rng.uniform(0.0, seconds, int(rng.poisson(onsets_per_year * seconds / YEAR_S)))
    new_dur = _lognormal(
        rng, GVP_MEDIAN_DURATION_S, GVP_LOG_SIGMA, len(new), GVP_MIN_DURATION_S, GVP_MAX_DURATION_S
    )
    for t0, d in zip(np.sort(new).tolist(), new_dur.tolist(), strict=True):
        busy = {v for v, a, b in zip(vols, onset, end, strict=True) if a <= t0 < b}
        free = np.array([i not in busy for i in range(len(catalog))])
        if not free.any():
            continue
        p = np.where(free, w, 0.0)
        vols.append(int(rng.choice(len(catalog), p=p / p.sum())))
        onset.append(t0)
        end.append(t0 + d)
    volcano = np.asarray(vols, np.int64)
    on, off = np.asarray(onset, np.float64), np.asarray(end, np.float64)
    order = np.lexsort((volcano, on))
    volcano, on, off = volcano[order], on[order], off[order]
    n = len(volcano)
    # level 2: plume episodes, a Poisson process within each eruption; overlaps merge
    ep: list[tuple[int, float, float]] = []
    rate = episodes_per_day / DAY_S
    for e in range(n):
        a = max(float(on[e]), -EPISODE_LEAD_S)
        b = min(float(off[e]), seconds)
        starts = rng.uniform(a, b, int(rng.poisson(rate * max(b - a, 0.0))))
        if on[e] >= 0.0:  # a new eruption begins with an episode
            starts = np.append(starts, on[e])
        starts = np.sort(starts)
        ends = np.minimum(
            starts
            + _lognormal(rng, episode_median_s, 1.0, len(starts), MIN_DURATION_S, MAX_DURATION_S),
            off[e],
        )
        cur: list[float] | None = None
        for s0, s1 in zip(starts.tolist(), ends.tolist(), strict=True):
            if cur is not None and s0 <= cur[1]:
                cur[1] = max(cur[1], s1)
                continue
            if cur is not None and cur[1] > 0.0:
                ep.append((e, cur[0], cur[1]))
            cur = [s0, s1]
        if cur is not None and cur[1] > 0.0:
            ep.append((e, cur[0], cur[1]))
    plume = _plumes(seed, n)
    top = np.exp(rng.uniform(math.log(1000.0), math.log(15_000.0), n))
    eps = np.asarray(ep, np.float64).reshape(-1, 3)
    return Eruptions(
        volcano=volcano,
        onset_s=on,
        end_s=off,
        wind_mps=plume[:, 0],
        drift_deg=plume[:, 1],
        source_m=plume[:, 2],
        turbulence=plume[:, 3],
        fade_s=plume[:, 4],
        top_m=top,
        optical_depth=plume[:, 5],
        episode_eruption=eps[:, 0].astype(np.int64),
        episode_onset_s=eps[:, 1].copy(),
        episode_end_s=eps[:, 2].copy(),
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
