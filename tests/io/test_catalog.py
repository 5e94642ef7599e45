"""The one volcano catalog reader (dyntarget.io.catalog).

Expected values: the GVP catalog's README (1,250 volcanoes; 229 last erupted in 2000 CE
or later), Kilauea's row read by eye from the CSV, the astronomical year convention
(1 BCE is year 0) by hand.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from dyntarget.errors import DataFileError
from dyntarget.io.catalog import MAX_ROWS, eruption_year, parse_catalog, read_catalog
from helpers import shared_data

FULL = ("volcano_number", "elevation_m", "last_known_eruption")
HEAD = "volcano_number,volcano_name,latitude,longitude,elevation_m,last_known_eruption\n"


def test_reads_the_gvp_holocene_catalog_in_columns():
    root = shared_data()
    path = None if root is None else root / "gvp-holocene" / "volcanoes.csv"
    if path is None or not path.is_file():
        pytest.skip("the GVP Holocene catalog (../shared/data/gvp-holocene) is not here")
    cat = read_catalog(path, require=FULL)
    assert len(cat) == 1250 and len(set(cat.number.tolist())) == 1250
    assert int((cat.last_year >= 2000).sum()) == 229  # the README's count
    k = cat.name.index("Kilauea")
    assert (int(cat.number[k]), cat.lat[k], cat.lon[k]) == (332010, 19.421, -155.287)
    assert cat.elevation_m[k] == 1222.0 and cat.last_year[k] == 2025.0


def test_years_are_astronomical_and_unknown_is_nan():
    cat = parse_catalog(
        HEAD + "1,A,0,0,0,1 BCE\n2,B,0,0,0,8300 BCE\n3,C,0,0,0,Unknown\n4,D,0,0,0,1801 CE\n",
        require=FULL,
    )
    assert cat.last_year[:2].tolist() == [0.0, -8299.0]
    assert np.isnan(cat.last_year[2]) and cat.last_year[3] == 1801.0
    assert eruption_year(" 79 ce ") == 79


def test_optional_columns_absent():
    cat = parse_catalog("latitude,longitude\n10,20\n-5.5,179\n", source="v.csv")
    assert cat.number.tolist() == [-1, -1]
    assert cat.name == ("line 2", "line 3")
    assert np.isnan(cat.elevation_m).all() and np.isnan(cat.last_year).all()
    assert cat.lat.tolist() == [10.0, -5.5] and cat.lon.tolist() == [20.0, 179.0]


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ("1,A,,10,0,Unknown\n", "row at line 2 (A): latitude is missing"),
        ("1,A,10,180.5,0,Unknown\n", "row at line 2 (A): longitude 180.5 is outside [-180, 180]"),
        ("1,A,10,20,9500,Unknown\n", "row at line 2 (A): elevation_m 9500 is outside"),
        ("1,A,10,20,inf,Unknown\n", "row at line 2 (A): elevation_m inf is outside"),
        ("1,,10,20,0,Unknown\n2,,x,20,0,Unknown\n", "row at line 3: latitude 'x' is not a number"),
        ("-4,A,10,20,0,Unknown\n", "row at line 2 (A): volcano_number '-4' is not an integer"),
        ("1,A,10,20,0,soon\n", "row at line 2 (A): last_known_eruption: expected a year"),
        (
            "7,A,1,2,0,Unknown\n7,B,1,2,0,Unknown\n",
            "line 3 (B): volcano_number 7 repeats the row at line 2",
        ),
        ("", "catalog v.csv: no volcanoes"),
    ],
)
def test_a_bad_row_is_one_line_naming_row_and_field(rows, message):
    with pytest.raises(DataFileError, match=re.escape(message)) as err:
        parse_catalog(HEAD + rows, source="v.csv", require=FULL)
    assert "\n" not in str(err.value) and "v.csv" in str(err.value)


def test_missing_columns_and_files(tmp_path):
    with pytest.raises(DataFileError, match="no 'longitude' or 'elevation_m' column"):
        parse_catalog("latitude,volcano_number\n1,2\n", require=("elevation_m",))
    p = tmp_path / "v.csv"
    p.write_bytes(b"latitude,longitude\n\xff,1\n")
    with pytest.raises(DataFileError, match="not UTF-8"):
        read_catalog(p)
    with pytest.raises(DataFileError, match="--volcanoes .*missing.csv"):
        read_catalog(tmp_path / "missing.csv", what="--volcanoes")


def test_too_many_rows_is_refused_before_reading_them_all():
    rows = "latitude,longitude\n" + "0,0\n" * (MAX_ROWS + 1)
    with pytest.raises(DataFileError, match=f"more than {MAX_ROWS} volcanoes"):
        parse_catalog(rows)
