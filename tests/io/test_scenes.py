from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from affine import Affine

from dyntarget import DataFileError, InvalidSceneError, Scene
from dyntarget.io import read_scene, read_scene_dir, scene_ids, write_scene
from helpers import ramp, write_raw_tif


def test_round_trip_georeferenced(georef_scene, tmp_path):
    paths = write_scene(georef_scene, tmp_path)
    assert [p.name for p in paths] == ["geo.tif", "geo_mask.tif"]
    back = read_scene(tmp_path / "geo.tif")
    np.testing.assert_allclose(back.image, georef_scene.image, rtol=0, atol=1e-7)
    np.testing.assert_array_equal(back.label, georef_scene.label)
    assert back.crs == "EPSG:32605"
    assert back.transform == georef_scene.transform
    assert back.gsd == georef_scene.gsd
    assert back.id == "geo"


def test_round_trip_plain(plain_scene, tmp_path):
    write_scene(plain_scene, tmp_path)
    back = read_scene(tmp_path / "plain.tif")
    np.testing.assert_array_equal(back.image, plain_scene.image)
    np.testing.assert_array_equal(back.label, plain_scene.label)
    assert back.crs is None and back.transform is None and back.gsd == 2.0


def test_unlabelled_scene(tmp_path):
    write_scene(Scene(ramp(4, 4, 4), id="u"), tmp_path)
    assert read_scene(tmp_path / "u.tif").label is None


def test_uint16_scaled_to_reflectance(tmp_path):
    dn = np.full((4, 3, 3), 2500, np.uint16)
    dn[0, 2, 2] = 5000
    write_raw_tif(tmp_path / "dn.tif", dn)
    assert read_scene(tmp_path / "dn.tif").image[0, 0, 0] == pytest.approx(0.25)
    assert read_scene(tmp_path / "dn.tif", scale=2e-5).image[0, 0, 0] == pytest.approx(0.05)


def test_gsd_from_projected_transform(tmp_path):
    from rasterio.crs import CRS

    write_raw_tif(
        tmp_path / "p.tif",
        ramp(4, 2, 2),
        crs=CRS.from_epsg(32605),
        transform=Affine(30.0, 0, 0, 0, -30.0, 0),
    )
    assert read_scene(tmp_path / "p.tif").gsd == 30.0


def test_geojson_label_pixel_coordinates(tmp_path):
    write_scene(Scene(ramp(4, 10, 10), id="g"), tmp_path)
    poly = {"type": "Polygon", "coordinates": [[[2, 3], [6, 3], [6, 7], [2, 7], [2, 3]]]}
    (tmp_path / "g.geojson").write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "features": [{"type": "Feature", "geometry": poly, "properties": {}}],
            }
        )
    )
    label = read_scene(tmp_path / "g.tif").label
    expected = np.zeros((10, 10), bool)
    expected[3:7, 2:6] = True  # pixel centres inside columns 2..5, rows 3..6
    np.testing.assert_array_equal(label, expected)


def test_geojson_label_in_crs(georef_scene, tmp_path):
    s = Scene(
        georef_scene.image,
        gsd=10.0,
        crs=georef_scene.crs,
        transform=georef_scene.transform,
        id="geo",
    )
    write_scene(s, tmp_path)
    t = s.transform
    ring = [list(t @ (c, r)) for c, r in [(1, 1), (5, 1), (5, 4), (1, 4), (1, 1)]]
    (tmp_path / "geo.geojson").write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    label = read_scene(tmp_path / "geo.tif").label
    assert label.sum() == 12 and label[1:4, 1:5].all()


def test_geojson_empty_collection_gives_empty_label(tmp_path):
    write_scene(Scene(ramp(4, 4, 4), id="e"), tmp_path)
    (tmp_path / "e.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    assert not read_scene(tmp_path / "e.tif").label.any()


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("{not json", "not valid JSON"),
        ('{"a": 1}', "not a GeoJSON object"),
        ('{"type": "Point", "coordinates": [1, 2]}', "unsupported GeoJSON type"),
        (
            '{"type": "Polygon", "coordinates": [[[100, 100], [120, 100], [120, 120], [100, 100]]]}',
            "no polygon overlaps",
        ),
        ('{"type": "Polygon", "coordinates": "x"}', "invalid geometry"),
    ],
)
def test_bad_geojson(tmp_path, text, match):
    write_scene(Scene(ramp(4, 4, 4), id="b"), tmp_path)
    (tmp_path / "b.geojson").write_text(text)
    with pytest.raises((DataFileError, InvalidSceneError), match=match):
        read_scene(tmp_path / "b.tif")


def test_missing_file(tmp_path):
    with pytest.raises(DataFileError, match="no such file"):
        read_scene(tmp_path / "nope.tif")


def test_not_a_tiff(tmp_path):
    (tmp_path / "x.tif").write_bytes(b"this is not a tiff at all")
    with pytest.raises(DataFileError, match="not a readable raster"):
        read_scene(tmp_path / "x.tif")


def test_truncated_tiff(georef_scene, tmp_path):
    big = Scene(np.random.default_rng(0).uniform(size=(4, 600, 600)).astype(np.float32), id="t")
    write_scene(big, tmp_path)
    data = (tmp_path / "t.tif").read_bytes()
    (tmp_path / "t.tif").write_bytes(data[: len(data) // 2])
    with pytest.raises(DataFileError, match="t.tif"):
        read_scene(tmp_path / "t.tif")


def test_wrong_band_count_file(tmp_path):
    write_raw_tif(tmp_path / "three.tif", np.zeros((3, 2, 2), np.float32))
    with pytest.raises(InvalidSceneError, match="three.tif: expected 4 bands.*got 3"):
        read_scene(tmp_path / "three.tif")


def test_nan_in_file(tmp_path):
    data = ramp(4, 2, 2)
    data[1, 0, 0] = np.nan
    write_raw_tif(tmp_path / "nan.tif", data)
    with pytest.raises(InvalidSceneError, match="nan.tif.*NaN"):
        read_scene(tmp_path / "nan.tif")


def test_label_shape_mismatch_file(tmp_path):
    write_scene(Scene(ramp(4, 4, 4), id="m"), tmp_path)
    write_raw_tif(tmp_path / "m_mask.tif", np.zeros((1, 3, 4), np.uint8))
    with pytest.raises(InvalidSceneError, match="m_mask.tif.*does not match"):
        read_scene(tmp_path / "m.tif")


def test_scene_dir_sorted_and_skips_masks(tmp_path):
    for name in ["b", "a", "c"]:
        write_scene(Scene(ramp(4, 2, 2), label=np.ones((2, 2), bool), id=name), tmp_path)
    assert scene_ids(tmp_path) == ["a", "b", "c"]
    assert [s.id for s in read_scene_dir(tmp_path, require_labels=True)] == ["a", "b", "c"]


def test_scene_dir_errors(tmp_path):
    with pytest.raises(DataFileError, match="not a directory"):
        scene_ids(tmp_path / "missing")
    with pytest.raises(DataFileError, match="no scenes"):
        read_scene_dir(tmp_path)
    write_scene(Scene(ramp(4, 2, 2), id="nolabel"), tmp_path)
    with pytest.raises(InvalidSceneError, match="no label"):
        read_scene_dir(tmp_path, require_labels=True)


def test_write_is_atomic_on_failure(tmp_path, monkeypatch):
    s = Scene(ramp(4, 2, 2), id="atomic")
    write_scene(s, tmp_path)
    before = (tmp_path / "atomic.tif").read_bytes()

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(rasterio.io.DatasetWriter, "write", boom)
    with pytest.raises(RuntimeError):
        write_scene(Scene(ramp(4, 2, 2) + 0.1, id="atomic"), tmp_path)
    assert (tmp_path / "atomic.tif").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["atomic.tif"]
