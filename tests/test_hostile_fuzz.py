"""Property-based fuzzing of the hostile-input surfaces (issue 20): the GeoJSON label
reader, ``--bands``, ``--grid`` and the resume part files.

The property everywhere: any input either works (and then the result obeys the
documented contract) or is refused with a ``DynTargetError``; no other exception
type, no crash, no silently wrong result.
"""

from __future__ import annotations

import json
import math

import pytest
from affine import Affine
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dyntarget.errors import DynTargetError
from dyntarget.evaluate.distributed import run_tasks
from dyntarget.evaluate.sweep import GRID_PARAMETERS, check_grid, parse_grid
from dyntarget.io import read_geojson_label
from dyntarget.io.sensors import parse_bands

FUZZ = settings(max_examples=150, suppress_health_check=[HealthCheck.function_scoped_fixture])

# ---------------------------------------------------------------- GeoJSON reader

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**20), 10**20),
    st.floats(-50, 50),
)
coords = st.recursive(
    st.lists(numbers, max_size=3), lambda inner: st.lists(inner, max_size=4), max_leaves=40
)
json_values = st.recursive(
    st.none() | st.booleans() | numbers | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=20,
)
crs_members = st.one_of(
    st.none(),
    json_values,
    st.fixed_dictionaries(
        {
            "type": st.just("name"),
            "properties": st.one_of(
                json_values,
                st.fixed_dictionaries(
                    {"name": st.sampled_from(["EPSG:32605", "EPSG:4326", "EPSG:0", "urn:x", ""])}
                ),
            ),
        }
    ),
)
geometries = st.fixed_dictionaries(
    {
        "type": st.sampled_from(["Polygon", "MultiPolygon", "Point", "LineString", "Nope"]),
        "coordinates": coords,
    }
)
documents = st.one_of(
    geometries,
    st.fixed_dictionaries({"type": st.just("Feature"), "geometry": geometries | json_values}),
    st.fixed_dictionaries(
        {
            "type": st.just("FeatureCollection"),
            "features": st.lists(
                st.fixed_dictionaries({"type": st.just("Feature"), "geometry": geometries}),
                max_size=3,
            ),
            "crs": crs_members,
        }
    ),
    json_values,
)


@pytest.mark.slow
@FUZZ
@given(doc=documents, georef=st.booleans())
def test_geojson_reader_refuses_or_returns_a_mask(tmp_path, doc, georef):
    path = tmp_path / "label.geojson"
    path.write_text(json.dumps(doc))  # NaN/Infinity are written as JSON extensions
    kwargs = {"crs": "EPSG:32605", "transform": Affine(10, 0, 0, 0, -10, 160)} if georef else {}
    try:
        mask = read_geojson_label(path, shape=(16, 16), **kwargs)
    except DynTargetError:
        return
    assert mask.shape == (16, 16) and mask.dtype == bool


@FUZZ
@given(depth=st.integers(1, 50_000), opener=st.sampled_from(["[", '{"a":']))
def test_geojson_any_nesting_depth_is_refused_cleanly(tmp_path, depth, opener):
    closer = "]" if opener == "[" else "}"
    path = tmp_path / "deep.geojson"
    path.write_text(
        '{"type": "Polygon", "coordinates": '
        + opener * depth
        + "1" * (opener == '{"a":')
        + closer * depth
        + "}"
    )
    try:
        mask = read_geojson_label(path, shape=(8, 8))
    except DynTargetError:
        return
    assert not mask.any()  # only an empty polygon (no vertex at all) is accepted


# ---------------------------------------------------------------- --bands

band_tokens = st.one_of(
    st.integers(-3, 20).map(str),
    st.sampled_from(["", "", " ", "B4", "b8", "B99", "²", "٣", "1.5", "0x1", "NIR"]),
    st.text(max_size=4),
)


@FUZZ
@given(
    tokens=st.lists(band_tokens, min_size=4, max_size=4) | st.lists(band_tokens, max_size=6),
    named=st.booleans(),
)
def test_bands_parse_to_four_distinct_positive_indices_or_refuse(tokens, named):
    names = [f"B{i}" for i in range(1, 13)] if named else [""] * 12
    text = ",".join(tokens)
    try:
        sel = parse_bands(text, names=names)
    except DynTargetError:
        return
    assert len(sel) == 4 and len(set(sel)) == 4
    assert all(isinstance(i, int) and i >= 1 for i in sel)
    # accepted only when every token is a plain number or a known name
    assert all(t.strip() for t in tokens)


# ---------------------------------------------------------------- --grid

grid_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-5, 10).map(str),
    st.sampled_from(["", "unlimited", "fast", "warp", "1e-3", "0.5", "nan", "2.0"]),
)
grid_items = st.builds(
    lambda name, values: f"{name}={','.join(values)}",
    st.sampled_from([*GRID_PARAMETERS, "step-fraction", "bogus", ""]),
    st.lists(grid_values, max_size=4),
)


@FUZZ
@given(items=st.lists(grid_items, max_size=4))
def test_grid_parses_to_a_valid_grid_or_refuses(items):
    try:
        grid = parse_grid(items)
    except DynTargetError:
        return
    check_grid(grid)  # what parse_grid returns passes the full validation
    assert len(grid) == len(items)  # no parameter silently dropped
    for values in grid.values():
        assert len(set(values)) == len(values)
        for v in values:
            if isinstance(v, float):
                assert math.isfinite(v)


# ---------------------------------------------------------------- part files

CALLS: list[int] = []


def _task(x: int) -> dict:
    CALLS.append(x)
    return {"x": x, "n": [x, x + 1], "ok": True}


part_contents = st.one_of(
    json_values.map(json.dumps),
    st.builds(
        lambda result, sha, settings_: json.dumps(
            {
                "format": "dyntarget-part",
                "key": "3",
                "settings": settings_,
                "sha256": sha,
                "result": result,
            }
        ),
        json_values,
        st.text(max_size=64),
        st.sampled_from([{"torch_train_threads": 1}, {"torch_train_threads": 4}, {}, None]),
    ),
    st.binary(max_size=64).map(lambda b: b.decode("latin-1")),
)


@FUZZ
@given(content=part_contents)
def test_any_part_content_gives_the_right_result(tmp_path_factory, content):
    parts = tmp_path_factory.mktemp("parts")
    run_tasks(_task, [1, 3], key=str, parts=parts, progress=False)
    (parts / "3.json").write_text(content, encoding="latin-1")
    CALLS.clear()
    got = run_tasks(_task, [1, 3], key=str, parts=parts, progress=False)
    assert got == [_expected(1), _expected(3)]
    assert CALLS in ([], [3])


def _expected(x: int) -> dict:
    return {"x": x, "n": [x, x + 1], "ok": True}
