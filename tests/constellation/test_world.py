"""The volcano catalog reader and the eruption / cloud model."""

from __future__ import annotations

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
