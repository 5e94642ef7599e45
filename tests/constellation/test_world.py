"""The volcano catalog reader and the eruption / cloud model."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from dyntarget.constellation.world import (
    draw_eruptions,
    parse_catalog,
    read_catalog,
    recency_weight,
)
from dyntarget.errors import DataFileError

HEAD = "volcano_number,volcano_name,latitude,longitude,elevation_m,last_known_eruption\n"


def test_real_catalog_reads_1250_volcanoes(gvp):
    cat = read_catalog(gvp)
    assert len(cat) == 1250
    # the README: 229 volcanoes last erupted in 2000 CE or later
    assert int((cat.last_year >= 2000).sum()) == 229
    k = int(np.flatnonzero(cat.number == 332010)[0]) if (cat.number == 332010).any() else None
    if k is not None:  # Kilauea, 19.421 N 155.287 W
        assert cat.lat[k] == pytest.approx(19.421, abs=0.01)


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ("1,A,,10,0,Unknown\n", "line 2 (A): latitude is missing"),
        ("1,A,10,200,0,Unknown\n", "line 2 (A): longitude 200 is outside [-180, 180]"),
        ("1,A,10,20,0,2020 CE\n2,B,x,20,0,2020 CE\n", "line 3 (B): latitude 'x' is not a number"),
        ("1,A,10,20,,2020 CE\n", "line 2 (A): elevation_m is missing"),
        (
            "1,A,10,20,0,2020 CE\n1,B,10,20,0,2020 CE\n",
            "line 3 (B): volcano_number 1 repeats the row at line 2",
        ),
        ("", "no volcanoes"),
    ],
)
def test_bad_catalog_names_row_and_field(rows, message):
    with pytest.raises(DataFileError, match=re.escape(message)) as err:
        parse_catalog(HEAD + rows, source="v.csv")
    assert "\n" not in str(err.value) and "v.csv" in str(err.value)


def test_missing_column():
    with pytest.raises(DataFileError, match="no 'elevation_m' or 'last_known_eruption' column"):
        parse_catalog("volcano_number,latitude,longitude\n1,2,3\n")


def test_rate_is_higher_for_recently_active_volcanoes():
    # two volcanoes, weights 100 (2025 CE) and 0.1 (BCE): expected share 100/100.1 of onsets
    cat = parse_catalog(HEAD + "1,A,0,0,0,2025 CE\n2,B,0,90,0,800 BCE\n")
    er = draw_eruptions(cat, seconds=86400.0 * 200, seed=3, eruptions_per_day=1.0)
    n = len(er)
    # 200 expected onsets; those during an ongoing episode are dropped: the mean episode
    # lasts 3 h * exp(1/2) = 4.95 h, so about 200 / (1 + 4.95 / 24) = 166 remain
    assert 125 < n < 210
    assert (er.volcano == 0).mean() > 0.97
    assert recency_weight(np.array([2020.0, 2019.0, 1900.0, 5.0, -5.0])).tolist() == [
        100.0,
        20.0,
        3.0,
        1.0,
        0.1,
    ]


def test_eruptions_are_seeded_and_within_the_period(gvp):
    cat = read_catalog(gvp)
    a = draw_eruptions(cat, seconds=86400.0, seed=5)
    b = draw_eruptions(cat, seconds=86400.0, seed=5)
    assert a.to_json() == b.to_json()
    assert ((a.onset_s >= 0) & (a.onset_s < 86400.0)).all() and (a.end_s > a.onset_s).all()
    # Poisson with mean 40 a day (minus overlaps): within 4 sigma
    assert 15 <= len(a) <= 66
    # one episode at a time per volcano
    for v in np.unique(a.volcano):
        k = np.flatnonzero(a.volcano == v)
        assert (a.onset_s[k][1:] >= a.end_s[k][:-1]).all()
    # plumes drift downwind: the drift direction is the wind's "from" + 180
    assert ((a.drift_deg >= 0) & (a.drift_deg < 360)).all()
    assert ((a.top_m >= 1000) & (a.top_m <= 15000)).all()


# -- the two-level model: GVP eruptions holding plume episodes --------------------------


def _recent(n: int, bce: int = 0):
    rows = "".join(f"{i},V{i},{i % 60},{i * 3 % 360 - 180},0,2025 CE\n" for i in range(1, n + 1))
    rows += "".join(
        f"{i},V{i},{i % 60},{i * 3 % 360 - 180},0,800 BCE\n" for i in range(n + 1, n + bce + 1)
    )
    return parse_catalog(HEAD + rows)


def test_in_progress_count_is_poisson_with_the_given_mean():
    from dyntarget.constellation.world import draw_gvp_eruptions

    cat = _recent(200)
    counts = []
    for seed in range(300):
        w = draw_gvp_eruptions(cat, seconds=3600.0, seed=seed, in_progress=10.0, onsets_per_year=0)
        assert (w.onset_s < 0).all() and (w.end_s > 0).all()  # all in progress at the start
        assert len(np.unique(w.volcano)) == len(w)  # one eruption per volcano
        counts.append(len(w))
    # Poisson(10): mean 10 (standard error sqrt(10/300) = 0.18), variance 10
    assert np.mean(counts) == pytest.approx(10.0, abs=0.75)
    assert 7.0 < np.var(counts) < 13.5


def test_new_onsets_follow_the_yearly_rate_and_open_with_an_episode():
    from dyntarget.constellation.world import draw_gvp_eruptions

    cat = _recent(300)
    counts = []
    for seed in range(100):
        # 3652.5 a year = 10 a day: Poisson(10) onsets in one day
        w = draw_gvp_eruptions(
            cat, seconds=86400.0, seed=seed, in_progress=0.0, onsets_per_year=3652.5
        )
        assert ((w.onset_s >= 0) & (w.onset_s < 86400.0)).all()
        counts.append(len(w))
        for e in range(len(w)):  # the first episode of a new eruption starts at its onset
            k = np.flatnonzero(w.episode_eruption == e)
            assert w.episode_onset_s[k[0]] == w.onset_s[e]
    assert np.mean(counts) == pytest.approx(10.0, abs=1.3)  # 4 standard errors


def test_episodes_cover_the_fraction_and_start_at_the_rate_worked_out_by_hand():
    """M/G/infinity by hand: Poisson starts (rate L) of episodes of mean length D.

    D: log-normal, median 3 h, log-sigma 1: 3 h * exp(1/2) = 4.946 h; clipping to
    20 min - 72 h moves it by under 0.02 h: D = 4.93 h. With L = 3 a day, L D = 0.616:
    the plume is there a fraction 1 - exp(-0.616) = 0.460 of the time, and merged
    episodes start at L exp(-L D) = 3 * 0.540 = 1.62 a day (a start that finds none
    under way opens one).
    """
    from dyntarget.constellation.world import draw_gvp_eruptions

    cat = _recent(1)
    days = 30.0
    grid = np.arange(0.0, days * 86400.0, 600.0)
    cover, starts = [], []
    for seed in range(40):
        w = draw_gvp_eruptions(cat, seconds=days * 86400.0, seed=seed, in_progress=50.0)
        assert len(w) == 1 and w.end_s[0] > days * 86400.0  # one long eruption in progress
        on, end = w.episode_onset_s, w.episode_end_s
        assert (on[1:] > end[:-1]).all()  # merged: no overlaps
        cover.append(w.active(np.zeros(len(grid), np.int64), grid).mean())
        starts.append(((on >= 0) & (on < days * 86400.0)).sum() / days)
    assert np.mean(cover) == pytest.approx(0.460, abs=0.03)
    assert np.mean(starts) == pytest.approx(1.62, abs=0.12)


def test_in_progress_eruptions_prefer_recently_active_volcanoes():
    from dyntarget.constellation.world import draw_gvp_eruptions

    cat = _recent(50, bce=50)  # weights 100 and 0.1
    vols = np.concatenate(
        [draw_gvp_eruptions(cat, seconds=3600.0, seed=s, in_progress=10).volcano for s in range(30)]
    )
    # a BCE volcano's share of each draw is at most 50 * 0.1 / (40 * 100 + 50 * 0.1) = 0.12 %
    assert (vols >= 50).mean() < 0.01


def test_two_level_world_is_seeded_and_round_trips(gvp):
    from dyntarget.constellation.world import Eruptions, draw_gvp_eruptions

    cat = read_catalog(gvp)
    a = draw_gvp_eruptions(cat, seconds=86400.0, seed=5)
    b = draw_gvp_eruptions(cat, seconds=86400.0, seed=5)
    c = draw_gvp_eruptions(cat, seconds=86400.0, seed=6)
    assert a.to_json() == b.to_json() != c.to_json()
    back = Eruptions.from_json(a.to_json())
    assert back.to_json() == a.to_json() and back.episodic
    # the episode model's JSON has no episode fields (task keys unchanged)
    assert "episode_onset_s" not in draw_eruptions(cat, seconds=3600.0, seed=5).to_json()
    # every episode lies inside its eruption and overlaps the period
    e = a.episode_eruption
    assert (a.episode_onset_s >= a.onset_s[e]).all() and (a.episode_end_s <= a.end_s[e]).all()
    assert (a.episode_end_s > 0).all()


def test_plume_exists_only_during_an_episode_and_grows_from_its_onset():
    from dyntarget.constellation.world import Eruptions

    one = np.array
    w = Eruptions(
        one([0]), one([-1e6]), one([1e6]), one([10.0]), one([90.0]), one([50.0]),
        one([0.1]), one([600.0]), one([5000.0]), one([3.0]),
        one([0, 0]), one([-50.0, 1000.0]), one([100.0, 4000.0]),
    )  # fmt: skip
    t = one([-60.0, 0.0, 500.0, 1000.0, 1100.0, 4000.0])
    assert w.active(np.zeros(6, np.int64), t).tolist() == [False, True, False, True, True, False]
    # length = source + wind * age: 50 m at the episode's onset, +10 m/s
    assert w.length_m(np.zeros(2, np.int64), one([0.0, 1100.0])).tolist() == [550.0, 1050.0]


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"in_progress": -1.0}, "--eruptions-in-progress: expected a number in [0, 100000]"),
        ({"onsets_per_year": math.nan}, "--eruption-onsets-per-year"),
        ({"episodes_per_day": 0.0}, "--episodes-per-day"),
        ({"episode_median_s": 1e9}, "--episode-median-h"),
    ],
)
def test_two_level_bad_parameters(kw, message):
    from dyntarget.constellation.world import draw_gvp_eruptions
    from dyntarget.errors import InvalidParameterError

    with pytest.raises(InvalidParameterError, match=re.escape(message)):
        draw_gvp_eruptions(_recent(3), seconds=3600.0, seed=0, **kw)


def test_settings_refuses_an_unknown_model():
    from dyntarget.constellation.simulate import Settings
    from dyntarget.errors import InvalidParameterError

    with pytest.raises(InvalidParameterError, match="--eruption-model: expected one of eruptions"):
        Settings(eruption_model="weeks")
