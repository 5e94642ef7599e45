"""Per-plume heights in GeoJSON: polygon feature properties and a pass's height estimates."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest
from affine import Affine
from rasterio.warp import transform as warp
from shapely.geometry import box

from dyntarget.errors import InvalidParameterError
from dyntarget.io.geojson import (
    height_estimates_geojson,
    plumes_geojson,
    polygons_geojson,
    write_height_estimates,
    write_polygons,
)

TRANSFORM = Affine(30.0, 0.0, 653000.0, 0.0, -30.0, 5120000.0)
CRS = "EPSG:32632"
HEIGHTS = {"top_height_m": 9000.0, "top_height_sigma_m": None, "rise_mps": None}


def test_feature_properties_one_for_all_or_one_per_polygon():
    polys = [box(0, 0, 4, 2), box(10, 10, 12, 11)]
    doc = polygons_geojson(polys, feature_properties={**HEIGHTS, "height_source": "prior"})
    props = [f["properties"] for f in doc["features"]]
    assert [p["index"] for p in props] == [0, 1] and [p["area_px"] for p in props] == [8.0, 2.0]
    assert all(p["top_height_m"] == 9000.0 and p["rise_mps"] is None for p in props)
    per = [
        {"top_height_m": 8000.0, "top_height_sigma_m": 250.0, "rise_mps": 12.5,
         "height_source": "estimated"},
        {"top_height_m": float("nan"), "top_height_sigma_m": None, "rise_mps": None,
         "height_source": "none"},
    ]  # fmt: skip
    doc = polygons_geojson(polys, feature_properties=per)
    a, b = (f["properties"] for f in doc["features"])
    assert (a["top_height_m"], a["top_height_sigma_m"], a["rise_mps"]) == (8000.0, 250.0, 12.5)
    assert b["top_height_m"] is None and b["height_source"] == "none"  # NaN: null
    # the key order: the standard properties, then the extra ones as given
    assert list(a) == ["kind", "index", "area_px", *per[0]]


def test_without_feature_properties_the_bytes_are_unchanged(tmp_path):
    polys = [box(0, 0, 4, 2)]
    a = write_polygons(tmp_path / "a.geojson", polys, transform=TRANSFORM, crs=CRS)
    b = write_polygons(
        tmp_path / "b.geojson", polys, transform=TRANSFORM, crs=CRS, feature_properties=None
    )
    assert a.read_bytes() == b.read_bytes()
    c = write_polygons(
        tmp_path / "c.geojson", polys, transform=TRANSFORM, crs=CRS, feature_properties=HEIGHTS
    )
    doc_a, doc_c = json.loads(a.read_text()), json.loads(c.read_text())
    assert doc_c["features"][0]["geometry"] == doc_a["features"][0]["geometry"]
    assert doc_c["features"][0]["properties"]["top_height_m"] == 9000.0


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([HEIGHTS], "expected 2 mappings"),
        ({"area_px": 1.0}, "'area_px' is a standard polygon property"),
        ([HEIGHTS, 5], r"feature_properties\[1\]: expected a mapping"),
        ("top_height_m", "expected a mapping or one per polygon"),
    ],
)
def test_bad_feature_properties_are_refused(extra, message):
    with pytest.raises(InvalidParameterError, match=message):
        polygons_geojson([box(0, 0, 1, 1), box(2, 2, 3, 3)], feature_properties=extra)


@dataclass
class Estimate:
    plume_id: int
    x_px: float
    y_px: float
    top_height_m: float | None
    top_height_sigma_m: float | None
    rise_mps: float | None
    height_source: str


def test_height_estimates_at_their_ground_position_in_wgs84():
    est = [
        Estimate(1, 20.0, 30.0, 9120.5, 310.0, 14.0, "estimated"),
        {"plume_id": 2, "x_px": 0.0, "y_px": 0.0, "top_height_m": 6000.0,
         "top_height_sigma_m": None, "rise_mps": float("nan"), "height_source": "prior"},
        Estimate(3, 5.5, 7.25, None, None, None, "none"),
    ]  # fmt: skip
    doc = height_estimates_geojson(est, transform=TRANSFORM, crs=CRS)
    f1, f2, f3 = doc["features"]
    # the pixel centre (20.5, 30.5) of the 30 m grid, reprojected by PROJ directly
    x, y = 653000.0 + 30.0 * 20.5, 5120000.0 - 30.0 * 30.5
    lon, lat = warp(CRS, "EPSG:4326", [x], [y])
    assert f1["geometry"]["type"] == "Point"
    assert f1["geometry"]["coordinates"] == pytest.approx([lon[0], lat[0]], abs=1e-7)
    assert f1["properties"] == {
        "plume_id": 1, "top_height_m": 9120.5, "top_height_sigma_m": 310.0, "rise_mps": 14.0,
        "height_source": "estimated", "x_px": 20.0, "y_px": 30.0,
    }  # fmt: skip
    assert f2["properties"]["rise_mps"] is None and f2["properties"]["top_height_sigma_m"] is None
    assert f3["properties"]["top_height_m"] is None and f3["properties"]["height_source"] == "none"
    # the same position as the truth file writes for a vent there
    truth = plumes_geojson(
        [{"plume_id": 1, "x_px": 20.0, "y_px": 30.0, "top_height_m": 9000.0, "rise_mps": None,
          "onset_s": 0.0}], transform=TRANSFORM, crs=CRS,
    )  # fmt: skip
    assert f1["geometry"] == truth["features"][0]["geometry"]
    assert "crs" not in doc and len(doc["bbox"]) == 4


def test_height_estimates_without_georeferencing_stay_in_pixels_and_write(tmp_path):
    doc = height_estimates_geojson(
        [Estimate(1, 20.0, 30.0, 9000.0, None, None, "prior")], transform=None, crs=None
    )
    assert doc["features"][0]["geometry"]["coordinates"] == [20.0, 30.0]
    assert "pixels" in doc["properties"]["coordinates"]
    out = write_height_estimates(
        tmp_path / "plumes.geojson",
        [Estimate(1, 20.0, 30.0, 9000.0, None, None, "prior")],
        transform=TRANSFORM,
        crs=CRS,
    )
    back = json.loads(out.read_text())
    assert back["features"][0]["properties"]["top_height_m"] == 9000.0
    assert json.dumps(back, allow_nan=False)  # strict JSON: no NaN anywhere
    with pytest.raises(InvalidParameterError, match="must end in .geojson"):
        write_height_estimates(tmp_path / "p.csv", [], transform=TRANSFORM, crs=CRS)


@pytest.mark.parametrize(
    ("estimate", "message"),
    [
        (Estimate(1, 0.0, 0.0, 9000.0, None, None, "guessed"), "height_source: expected one of"),
        (Estimate(1, np.nan, 0.0, 9000.0, None, None, "prior"), "expected finite pixels"),
        (
            Estimate(1, 0.0, 0.0, float("inf"), None, None, "prior"),
            "top_height_m: expected a finite",
        ),
        (Estimate(1, 0.0, 0.0, "high", None, None, "prior"), "top_height_m: expected a number"),  # type: ignore[arg-type]
        ({"plume_id": 1, "height_source": "prior"}, "expected numbers x_px and y_px"),
    ],
)
def test_bad_estimates_are_refused(estimate, message):
    with pytest.raises(InvalidParameterError, match=message):
        height_estimates_geojson([estimate], transform=TRANSFORM, crs=CRS)
