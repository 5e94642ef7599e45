"""GeoJSON/CSV writers: RFC 7946 by default, legacy native CRS on request, read back by GDAL."""

from __future__ import annotations

import json

import numpy as np
import pytest
from affine import Affine
from shapely.geometry import Polygon, box

from dyntarget.errors import DataFileError, InvalidParameterError
from dyntarget.io.acquisition import parse_acquired, read_acquired
from dyntarget.io.geojson import (
    polygons_geojson,
    trajectory_csv,
    trajectory_geojson,
    write_polygons,
    write_trajectory,
)
from dyntarget.trajectory import Trajectory

pyogrio = pytest.importorskip("pyogrio", reason="pyogrio (GDAL's OGR) is in the test extra")

# A 30 m grid whose pixel (0, 0) centre sits exactly on the zone's central meridian
# at the equator: UTM 32N (9°E, false northing 0) and UTM 33S (15°E, false
# northing 10 000 km). Those centres are, by the definition of UTM, lon = the
# central meridian, lat = 0.
UTM32N = ("EPSG:32632", Affine(30.0, 0.0, 500000.0 - 15.0, 0.0, -30.0, 15.0), 9.0)
UTM33S = ("EPSG:32733", Affine(30.0, 0.0, 500000.0 - 15.0, 0.0, -30.0, 10_000_015.0), 15.0)
# A realistic scene far from the meridian: Etna's area (UTM 33N) and Villarrica (UTM 19S).
ETNA = ("EPSG:32633", Affine(30.0, 0.0, 490000.0, 0.0, -30.0, 4185000.0), None)
VILLARRICA = ("EPSG:32719", Affine(30.0, 0.0, 745000.0, 0.0, -30.0, 5644000.0), None)


def _traj(times: bool = True) -> Trajectory:
    rng = np.random.default_rng(7)
    pts = np.vstack([[0.0, 0.0], rng.uniform(0, 500, (40, 2)), [499.37, 3.21]])
    part = np.repeat([0, 1], [20, 22])
    t = np.linspace(0.0, 41.0, len(pts)) if times else None
    return Trajectory(pts, part, "test", {"step": 5}, times=t)


def _read_points(path):
    """(xy, crs) of the Point features as GDAL's OGR reads them (pyogrio)."""
    import shapely

    meta, _, geoms, fields = pyogrio.raw.read(path, where="kind = 'pointing'")
    names = list(meta["fields"])
    order = fields[names.index("order")]
    xy = shapely.get_coordinates(shapely.from_wkb(geoms))
    return xy[np.argsort(order)], meta["crs"]


def _to_pixels(xy, src_crs, dst_crs, transform):
    from rasterio.warp import transform as warp

    if src_crs != dst_crs:
        xs, ys = warp(src_crs, dst_crs, xy[:, 0], xy[:, 1])
        xy = np.column_stack([xs, ys])
    a, b, c, d, e, f = tuple(~transform)[:6]
    col = a * xy[:, 0] + b * xy[:, 1] + c
    row = d * xy[:, 0] + e * xy[:, 1] + f
    return np.column_stack([col, row]) - 0.5


@pytest.mark.parametrize("grid", [UTM32N, UTM33S, ETNA, VILLARRICA], ids=lambda g: g[0])
def test_rfc7946_points_read_by_gdal_reproject_back_within_a_tenth_of_a_pixel(tmp_path, grid):
    crs, transform, _ = grid
    traj = _traj()
    out = write_trajectory(tmp_path / "t.geojson", traj, transform=transform, crs=crs)
    xy, read_crs = _read_points(out)
    assert read_crs == "EPSG:4326"  # GDAL takes RFC 7946 GeoJSON as WGS 84
    back = _to_pixels(xy, "EPSG:4326", crs, transform)
    err = np.abs(back - traj.points)
    assert err.max() < 0.1, err.max()


@pytest.mark.parametrize("grid", [UTM32N, UTM33S], ids=lambda g: g[0])
def test_pixel_on_the_central_meridian_at_the_equator_is_lon_meridian_lat_zero(tmp_path, grid):
    crs, transform, meridian = grid
    doc = trajectory_geojson(_traj(), transform=transform, crs=crs)
    first = next(f for f in doc["features"] if f["properties"].get("order") == 0)
    assert first["geometry"]["coordinates"] == [meridian, 0.0]
    assert "crs" not in doc
    # UTM 33S: rows grow southward, so every other point has a negative latitude
    if crs == "EPSG:32733":
        lats = [f["geometry"]["coordinates"][1] for f in doc["features"][1:]]
        assert max(lats) == 0.0 and min(lats) < 0


def test_native_form_carries_the_crs_gdal_reads_and_round_trips_exactly(tmp_path):
    crs, transform, _ = UTM32N
    traj = _traj()
    out = write_trajectory(
        tmp_path / "t.geojson", traj, transform=transform, crs=crs, crs_mode="native"
    )
    doc = json.loads(out.read_text())
    assert doc["crs"] == {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32632"}}
    xy, read_crs = _read_points(out)
    assert read_crs == "EPSG:32632"
    # metres rounded to the millimetre: 1 mm / 30 m per pixel
    assert np.abs(_to_pixels(xy, crs, crs, transform) - traj.points).max() < 1e-3 / 30 + 1e-9


def test_coordinates_are_rounded_to_seven_decimals(tmp_path):
    crs, transform, _ = ETNA
    text = write_trajectory(tmp_path / "t.geojson", _traj(), transform=transform, crs=crs)
    doc = json.loads(text.read_text())
    for f in doc["features"][1:]:
        for v in f["geometry"]["coordinates"]:
            assert round(v, 7) == v
            # Etna is at about 15°E, 37.8°N
            assert 14.5 < f["geometry"]["coordinates"][0] < 15.5
            assert 37.5 < f["geometry"]["coordinates"][1] < 38.0


def test_scene_without_crs_keeps_pixels_and_says_so():
    traj = _traj(times=False)
    doc = trajectory_geojson(traj, transform=Affine.identity(), crs=None)
    assert "pixel" in doc["properties"]["coordinates"]
    assert "crs" not in doc and "bbox" not in doc
    pts = [
        f["geometry"]["coordinates"] for f in doc["features"] if f["geometry"]["type"] == "Point"
    ]
    np.testing.assert_allclose(pts, traj.points, atol=5e-4)
    assert doc["features"][0]["geometry"]["type"] == "LineString"
    assert "time_s" not in doc["features"][1]["properties"]


def test_every_pointing_carries_time_s_and_iso_time_when_acquired():
    crs, transform, _ = UTM32N
    t = Trajectory(
        np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]),
        np.zeros(3, np.int64),
        "t",
        times=np.array([3.0, 61.5, 3600.0 + 0.25]),
    )
    doc = trajectory_geojson(t, transform=transform, crs=crs, acquired="2024-05-01T23:59:00+02:00")
    pts = doc["features"][1:]
    assert [p["properties"]["time_s"] for p in pts] == [3.0, 61.5, 3600.25]
    # 21:59:00 UTC + 3 s, + 61.5 s, + 1 h 0.25 s
    assert [p["properties"]["time"] for p in pts] == [
        "2024-05-01T21:59:03.000Z",
        "2024-05-01T22:00:01.500Z",
        "2024-05-01T22:59:00.250Z",
    ]
    assert doc["properties"]["acquired"] == "2024-05-01T21:59:00.000Z"
    csv = trajectory_csv(t, transform=transform, crs=crs, acquired="2024-05-01T21:59:00Z")
    lines = csv.splitlines()
    assert lines[0] == "order,x,y,part,lon,lat,time_s,time"
    assert lines[1].split(",")[4:] == [
        "9.0000000",
        "0.0000000",
        "3.000",
        "2024-05-01T21:59:03.000Z",
    ]
    assert lines[3].endswith(",3600.250,2024-05-01T22:59:00.250Z")


def test_time_without_acquisition_is_relative_only():
    t = Trajectory(np.array([[0.0, 0.0]]), np.zeros(1, np.int64), "t", times=np.array([2.0]))
    props = trajectory_geojson(t)["features"][0]["properties"]
    assert props["time_s"] == 2.0 and "time" not in props
    assert trajectory_csv(t).splitlines()[0] == "order,x,y,part,time_s"


def test_native_csv_has_metres():
    crs, transform, _ = UTM32N
    t = Trajectory(np.array([[2.0, 1.0]]), np.zeros(1, np.int64), "t")
    lines = trajectory_csv(t, transform=transform, crs=crs, crs_mode="native").splitlines()
    # pixel centre (2.5, 1.5) * 30 m from the corner (499985, 15)
    assert lines == ["order,x,y,part,X,Y", "0,2.000,1.000,0,500060.000,-30.000"]


def test_point_properties_are_written_per_pointing_in_geojson_and_csv():
    t = Trajectory(np.array([[0.0, 0.0], [1.0, 0.0]]), np.zeros(2, np.int64), "t")
    extra = {"utility": np.array([0.5, np.nan])}
    doc = trajectory_geojson(t, point_properties=extra)
    assert [f["properties"]["utility"] for f in doc["features"][1:]] == [0.5, None]
    assert trajectory_csv(t, point_properties=extra).splitlines()[1:] == [
        "0,0.000,0.000,0,0.5",
        "1,1.000,0.000,0,",
    ]
    with pytest.raises(InvalidParameterError, match=r"point_properties\['utility'\].*2 values"):
        trajectory_geojson(t, point_properties={"utility": [1.0]})


def test_polygons_follow_the_right_hand_rule_and_read_back_through_gdal(tmp_path):
    crs, transform, _ = UTM33S
    # a square with a square hole, given clockwise-in-the-image (as OpenCV might)
    outer = [(10, 10), (10, 40), (40, 40), (40, 10)]
    hole = [(20, 20), (30, 20), (30, 30), (20, 30)]
    poly = Polygon(outer, [hole])
    out = write_polygons(tmp_path / "p.geojson", [poly], transform=transform, crs=crs)
    doc = json.loads(out.read_text())
    rings = doc["features"][0]["geometry"]["coordinates"]
    assert Polygon(rings[0]).exterior.is_ccw  # exterior counter-clockwise in lon/lat
    assert not Polygon(rings[1]).exterior.is_ccw  # holes clockwise
    props = doc["features"][0]["properties"]
    assert props["area_px"] == 900 - 100
    assert props["area_m2"] == 800 * 30 * 30
    import shapely

    meta, _, geoms, _ = pyogrio.raw.read(out)
    assert meta["crs"] == "EPSG:4326"
    back = shapely.from_wkb(geoms[0])
    ext = _to_pixels(shapely.get_coordinates(back.exterior), "EPSG:4326", crs, transform)
    assert Polygon(ext).symmetric_difference(Polygon(outer)).area < 0.1


def test_polygons_without_crs_stay_in_pixels_and_bad_input_is_refused(tmp_path):
    doc = polygons_geojson([box(0, 0, 2, 1)])
    assert "pixel" in doc["properties"]["coordinates"]
    with pytest.raises(InvalidParameterError, match=r"polygons\[0\].*Polygon"):
        polygons_geojson(["not a polygon"])
    with pytest.raises(InvalidParameterError, match=r"polygons\[0\].*empty"):
        polygons_geojson([Polygon()])
    with pytest.raises(InvalidParameterError, match="must end in .geojson"):
        write_polygons(tmp_path / "p.csv", [box(0, 0, 1, 1)])
    assert not (tmp_path / "p.csv").exists()


def test_bad_mode_and_suffix_name_the_argument(tmp_path):
    with pytest.raises(InvalidParameterError, match="crs_mode: expected one of rfc7946, native"):
        trajectory_geojson(_traj(), crs_mode="utm")
    with pytest.raises(InvalidParameterError, match="must end in .geojson, .json or .csv"):
        write_trajectory(tmp_path / "t.kml", _traj())
    assert list(tmp_path.iterdir()) == []


def test_same_input_same_bytes(tmp_path):
    crs, transform, _ = ETNA
    a = write_trajectory(tmp_path / "a.geojson", _traj(), transform=transform, crs=crs)
    b = write_trajectory(tmp_path / "b.geojson", _traj(), transform=transform, crs=crs)
    assert a.read_bytes() == b.read_bytes()


def _tag(tif, value):
    import rasterio

    with rasterio.open(tif, "r+") as dst:
        dst.update_tags(TIFFTAG_DATETIME=value)


def test_acquisition_time_from_tiff_tag_sidecar_and_bad_values(tmp_path):
    from helpers import ramp, write_raw_tif

    tif = write_raw_tif(tmp_path / "s.tif", ramp(4, 8, 8), crs="EPSG:32632", transform=UTM32N[1])
    assert read_acquired(tif) is None
    _tag(tif, "2023:11:05 08:30:15")
    assert read_acquired(tif).isoformat() == "2023-11-05T08:30:15+00:00"
    sidecar = tmp_path / "s.meta.json"
    sidecar.write_text(json.dumps({"acquired": "2023-11-05T10:30:15+02:00"}))
    assert read_acquired(tif).isoformat() == "2023-11-05T08:30:15+00:00"
    sidecar.write_text("{not json")
    with pytest.raises(DataFileError, match=r"s\.meta\.json"):
        read_acquired(tif)
    sidecar.write_text(json.dumps({"acquired": "yesterday"}))
    with pytest.raises(DataFileError, match="ISO-8601"):
        read_acquired(tif)
    sidecar.unlink()
    _tag(tif, "2023:13:05 08:30:15")
    with pytest.raises(DataFileError, match="TIFFTAG_DATETIME"):
        read_acquired(tif)


def test_parse_acquired_refuses_what_is_not_iso_8601():
    with pytest.raises(InvalidParameterError, match="acquired: expected an ISO-8601"):
        parse_acquired("5 May 2024")
    assert parse_acquired("2024-05-05").isoformat() == "2024-05-05T00:00:00+00:00"


def test_our_rfc7946_polygons_read_back_as_a_label_on_the_image_grid(tmp_path):
    from dyntarget.io import read_label

    crs, transform, _ = ETNA
    # pixel-centre coordinates 10.3..29.7 x 12.3..39.7 = grid-corner coordinates
    # 10.8..30.2 x 12.8..40.2: the pixels whose centre (i + 0.5) is inside are
    # columns 11..29 and rows 13..39 (no centre near the boundary, so no ties)
    square = box(10.3, 12.3, 29.7, 39.7)
    expected = np.zeros((64, 64), bool)
    expected[13:40, 11:30] = True
    for mode in ("rfc7946", "native"):
        path = write_polygons(
            tmp_path / f"{mode}.geojson", [square], transform=transform, crs=crs, crs_mode=mode
        )
        label = read_label(path, shape=(64, 64), crs=crs, transform=transform)
        np.testing.assert_array_equal(label, expected, err_msg=mode)


def test_a_legacy_label_in_the_image_crs_without_crs_member_is_still_read_as_such(tmp_path):
    from dyntarget.io import read_label

    crs, transform, _ = ETNA
    # metres in the image's CRS, no crs member: the old convention keeps working
    x0, y0 = transform @ (5, 5)
    x1, y1 = transform @ (20, 20)
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {
                    "type": "Polygon",
                    "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]],
                },
            }
        ],
    }
    path = tmp_path / "legacy.geojson"
    path.write_text(json.dumps(doc))
    label = read_label(path, shape=(32, 32), crs=crs, transform=transform)
    assert label.sum() == 15 * 15 and label[5:20, 5:20].all()


# --- the antimeridian (RFC 7946 §3.1.9, §5.2) and the poles -------------------------------
# A 6 km plume centred on the 180° meridian, in the CRS an image there would have:
# the Aleutians (UTM 60N, 52°N), Tonga-Kermadec (UTM 1S, 30°S, west of 180° in its zone),
# the UTM system's limits (84°N, 80°S) and Antarctic polar stereographic (EPSG:3031) at 80°S.
ANTIMERIDIAN = {
    "aleutians-utm60n": ("EPSG:32660", 52.0),
    "kermadec-utm1s": ("EPSG:32701", -30.0),
    "utm60n-84N": ("EPSG:32660", 83.9),
    "utm1s-80S": ("EPSG:32701", -79.9),
    "polar-stereo-80S": ("EPSG:3031", -80.0),
}
PX = 30.0  # metres per pixel; 200 px = 6 km


def _grid_at(crs: str, lon: float, lat: float, n: int = 200) -> Affine:
    """A north-up grid of n x n 30 m pixels centred on (lon, lat), placed with PROJ (pyproj)."""
    pyproj = pytest.importorskip("pyproj")
    x, y = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(lon, lat)
    return Affine(PX, 0.0, x - PX * n / 2, 0.0, -PX, y + PX * n / 2)


def _centres(px: np.ndarray, transform: Affine) -> np.ndarray:
    """Pixel (column, row) -> the CRS position of that pixel's centre (north-up grid)."""
    px = np.asarray(px, np.float64)
    return np.column_stack(
        [transform.c + (px[:, 0] + 0.5) * transform.a, transform.f + (px[:, 1] + 0.5) * transform.e]
    )


def _lonlat_of_pixels(px: np.ndarray, crs: str, transform: Affine) -> np.ndarray:
    """Pixel centres to lon/lat with pyproj (PROJ directly, not through GDAL as the writer)."""
    import pyproj

    world = _centres(px, transform)
    t = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    return np.column_stack(t.transform(world[:, 0], world[:, 1]))


def _cut_lat(a: np.ndarray, b: np.ndarray) -> float:
    """Latitude where the straight lon/lat line a -> b (across 180°) meets the meridian, by hand."""
    lon_a, lon_b = a[0] % 360.0, b[0] % 360.0  # unwrap: 180° becomes a plain crossing
    return float(a[1] + (180.0 - lon_a) / (lon_b - lon_a) * (b[1] - a[1]))


def _back_to_crs(geom, crs: str):
    import pyproj
    import shapely

    t = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    return shapely.transform(geom, lambda c: np.column_stack(t.transform(c[:, 0], c[:, 1])))


@pytest.mark.parametrize("place", list(ANTIMERIDIAN), ids=str)
def test_a_plume_across_180_is_a_split_multipolygon_with_a_bbox_west_greater_than_east(
    tmp_path, place
):
    import shapely

    crs, lat = ANTIMERIDIAN[place]
    transform = _grid_at(crs, 180.0, lat)
    corners_px = np.array([[20.0, 20.0], [180.0, 20.0], [180.0, 180.0], [20.0, 180.0]])
    out = write_polygons(
        tmp_path / "p.geojson", [Polygon(corners_px)], transform=transform, crs=crs
    )
    doc = json.loads(out.read_text())
    geom = doc["features"][0]["geometry"]
    assert geom["type"] == "MultiPolygon" and len(geom["coordinates"]) == 2
    # expected by hand: each corner where PROJ puts it; where an edge crosses 180°, a vertex at
    # +180 and one at -180 on the straight lon/lat line between its two corners
    corners = _lonlat_of_pixels(corners_px, crs, transform)
    assert (corners[:, 0] > 0).sum() == 2  # two corners east of 180° in longitude, two west
    cuts = sorted(
        _cut_lat(corners[i], corners[(i + 1) % 4])
        for i in range(4)
        if (corners[i, 0] > 0) != (corners[(i + 1) % 4, 0] > 0)
    )
    east = np.vstack([corners[corners[:, 0] > 0], [[180.0, c] for c in cuts]])
    west = np.vstack([corners[corners[:, 0] < 0], [[-180.0, c] for c in cuts]])
    for part, expected in zip(
        sorted(geom["coordinates"], key=lambda p: -p[0][0][0]), (east, west), strict=True
    ):
        ring = np.array(part[0][:-1])
        assert len(ring) == 4 and len(part) == 1
        got = ring[np.lexsort(ring.T[::-1])]
        np.testing.assert_allclose(got, expected[np.lexsort(expected.T[::-1])], atol=1.5e-7)
        assert Polygon(part[0]).exterior.is_ccw  # right-hand rule on each side
    # RFC 7946 §5.2: west edge is the eastern-hemisphere side, east edge past 180°
    lats = np.concatenate([corners[:, 1], cuts])
    assert doc["bbox"] == pytest.approx(
        [east[:, 0].min(), lats.min(), west[:, 0].max(), lats.max()], abs=1e-7
    )
    assert doc["bbox"][0] > doc["bbox"][2]
    # GDAL reads it as one MultiPolygon whose parts, back in the image CRS, are the plume
    meta, _, wkb, _ = pyogrio.raw.read(out)
    back = shapely.from_wkb(wkb[0])
    assert meta["crs"] == "EPSG:4326" and back.geom_type == "MultiPolygon"
    dense = shapely.segmentize(Polygon(corners_px), 1.0)  # 1 px edges: straight in either CRS
    doc = polygons_geojson([dense], transform=transform, crs=crs)
    world = shapely.transform(dense, lambda c: _centres(c, transform))
    parts = _back_to_crs(shapely.geometry.shape(doc["features"][0]["geometry"]), crs)
    assert shapely.union_all(parts.geoms).symmetric_difference(world).area < 1e-5 * world.area


@pytest.mark.parametrize("place", ["aleutians-utm60n", "kermadec-utm1s", "utm60n-84N"], ids=str)
def test_a_path_across_180_is_a_split_multilinestring_and_its_points_and_csv_stay_put(
    tmp_path, place
):
    import csv

    import shapely

    crs, lat = ANTIMERIDIAN[place]
    transform = _grid_at(crs, 180.0, lat)
    pts = np.column_stack([np.linspace(10.0, 190.0, 10), np.full(10, 100.0)])  # a transect
    traj = Trajectory(pts, np.zeros(10, np.int64), "test")
    out = write_trajectory(tmp_path / "t.geojson", traj, transform=transform, crs=crs)
    doc = json.loads(out.read_text())
    expected = _lonlat_of_pixels(pts, crs, transform)
    k = int(np.flatnonzero(np.sign(expected[:-1, 0]) != np.sign(expected[1:, 0]))[0])
    cut = _cut_lat(expected[k], expected[k + 1])
    path = doc["features"][0]["geometry"]
    assert path["type"] == "MultiLineString"
    first, second = (np.array(p) for p in path["coordinates"])
    np.testing.assert_allclose(first, np.vstack([expected[: k + 1], [180.0, cut]]), atol=1.5e-7)
    np.testing.assert_allclose(second, np.vstack([[-180.0, cut], expected[k + 1 :]]), atol=1.5e-7)
    points = np.array([f["geometry"]["coordinates"] for f in doc["features"][1:]])
    np.testing.assert_allclose(points, expected, atol=1.5e-7)  # every point in [-180, 180]
    lats = np.concatenate([expected[:, 1], [cut]])
    assert doc["bbox"] == pytest.approx(
        [expected[: k + 1, 0].min(), lats.min(), expected[k + 1 :, 0].max(), lats.max()],
        abs=1e-7,
    )
    _, _, wkb, _ = pyogrio.raw.read(out, where="kind = 'path'")
    assert shapely.from_wkb(wkb[0]).geom_type == "MultiLineString"
    rows = list(csv.DictReader(trajectory_csv(traj, transform=transform, crs=crs).splitlines()))
    lonlat = np.array([[float(r["lon"]), float(r["lat"])] for r in rows])
    np.testing.assert_allclose(lonlat, expected, atol=1.5e-7)
    assert (lonlat[: k + 1, 0] > 179.0).all() and (lonlat[k + 1 :, 0] < -179.0).all()


@pytest.mark.parametrize(("crs", "pole"), [("EPSG:3413", 90.0), ("EPSG:3031", -90.0)])
def test_a_plume_over_a_pole_runs_along_the_pole_and_its_bbox_spans_every_longitude(crs, pole):
    import shapely

    transform = _grid_at(crs, 0.0, pole)
    square = shapely.segmentize(box(40.0, 40.0, 160.0, 160.0), 1.0)  # the pole at its centre
    doc = polygons_geojson([square], transform=transform, crs=crs)
    geom = shapely.geometry.shape(doc["features"][0]["geometry"])
    assert geom.geom_type == "Polygon" and geom.is_valid and geom.exterior.is_ccw
    ring = shapely.get_coordinates(geom.exterior)
    assert [180.0, pole] in ring.tolist() and [-180.0, pole] in ring.tolist()
    # 1.8 km from the pole to the square's nearest edge: 90° - 1.8 km / 111.7 km per degree
    edge_lat = 90.0 - 60 * PX / 111_700.0
    assert doc["bbox"][0::2] == [-180.0, 180.0]
    if pole > 0:
        assert doc["bbox"][3] == 90.0 and doc["bbox"][1] < edge_lat
    else:
        assert doc["bbox"][1] == -90.0 and doc["bbox"][3] > -edge_lat
    world = shapely.transform(square, lambda c: _centres(c, transform))
    assert _back_to_crs(geom, crs).symmetric_difference(world).area < 1e-5 * world.area


def test_a_plume_beside_180_but_not_across_keeps_its_polygon_and_plain_bbox():
    crs, transform = "EPSG:32660", _grid_at("EPSG:32660", 179.9, 52.0)
    doc = polygons_geojson([box(20.0, 20.0, 180.0, 180.0)], transform=transform, crs=crs)
    assert doc["features"][0]["geometry"]["type"] == "Polygon"
    west, _, east, _ = doc["bbox"]
    assert 179.8 < west < east < 180.0


def test_a_comma_or_quote_in_a_csv_value_stays_one_field(tmp_path):
    import csv

    crs, transform, _ = ETNA
    t = Trajectory(np.array([[0.0, 0.0], [1.0, 0.0]]), np.zeros(2, np.int64), "t")
    notes = ["a,b", 'said "ash", then gas']
    text = trajectory_csv(t, transform=transform, crs=crs, point_properties={"note": notes})
    rows = list(csv.reader(text.splitlines()))
    assert rows[0] == ["order", "x", "y", "part", "lon", "lat", "note"]
    assert [len(r) for r in rows] == [7, 7, 7] and [r[-1] for r in rows[1:]] == notes
    assert text.splitlines()[1].endswith(',"a,b"')  # RFC 4180 quoting
    path = tmp_path / "t.csv"
    write_trajectory(path, t, transform=transform, crs=crs, point_properties={"note": notes})
    _, _, _, fields = pyogrio.raw.read(path)  # GDAL's CSV driver agrees
    assert list(fields[-1]) == notes
