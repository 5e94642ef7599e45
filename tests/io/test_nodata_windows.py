"""Nodata is honoured end to end; large images are read in strips straight onto the WFOV grid."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from affine import Affine

import dyntarget.io.scenes as scene_io
from dyntarget import InvalidSceneError, Scene
from dyntarget.evaluate.metrics import Confusion
from dyntarget.io import read_scene, write_scene
from dyntarget.observe import UtilityMaps, observe
from dyntarget.perceive import make_classifier
from dyntarget.perceive.base import sample_pixels
from dyntarget.pipeline import plan_scene
from helpers import write_raw_tif


def _scene_with_nodata(h=40, w=36, seed=0):
    rng = np.random.default_rng(seed)
    image = rng.uniform(0.05, 0.6, (4, h, w)).astype(np.float32)
    label = np.zeros((h, w), bool)
    label[8:30, 6:26] = True
    image[:, label] += 0.3
    valid = np.ones((h, w), bool)
    valid[:, :5] = False  # a nodata stripe at the left edge, inside and outside the plume
    valid[20:24, 10:14] = False
    return Scene(
        image,
        label=label,
        valid=valid,
        gsd=5.0,
        crs="EPSG:32605",
        transform=Affine(5, 0, 2e5, 0, -5, 2e6),
        id="nd",
    )


def test_nodata_round_trip_as_nan(tmp_path):
    s = _scene_with_nodata()
    write_scene(s, tmp_path)
    with rasterio.open(tmp_path / "nd.tif") as src:
        assert np.isnan(src.nodata)
    back = read_scene(tmp_path / "nd.tif")
    np.testing.assert_array_equal(back.valid, s.valid)
    np.testing.assert_array_equal(back.image[:, s.valid], s.image[:, s.valid])
    assert (back.image[:, ~s.valid] == 0).all()  # placeholders


def test_integer_nodata_value(tmp_path):
    data = np.full((4, 6, 6), 3000, np.uint16)
    data[:, :, 3:] = 5000
    data[:, 0, 0] = 0
    write_raw_tif(tmp_path / "n.tif", data, nodata=0)
    s = read_scene(tmp_path / "n.tif")
    assert not s.valid[0, 0] and s.valid.sum() == 35
    data[:] = 0
    write_raw_tif(tmp_path / "n.tif", data, nodata=0)
    with pytest.raises(InvalidSceneError, match="no valid pixel"):
        read_scene(tmp_path / "n.tif")


def test_wfov_valid_only_where_whole_block_valid():
    w = _scene_with_nodata().to_wfov(4)
    assert not w.valid[:, 0].any()  # high-res columns 0-4 are nodata: WFOV columns 0 and 1
    assert w.valid[np.arange(10) != 5, 2].all()
    assert not w.valid[:, 1].any()
    assert not w.valid[5, 2] and not w.valid[5, 3]  # the 4x4 hole at rows 20-23, cols 10-13


@pytest.mark.parametrize("label_kind", ["mask", "geojson"])
def test_strip_reading_equals_read_then_downsample(tmp_path, monkeypatch, label_kind):
    s = _scene_with_nodata(h=64, w=48)
    write_scene(s, tmp_path)
    if label_kind == "geojson":
        (tmp_path / "nd_mask.tif").unlink()
        t = s.transform
        ring = [list(t @ (c, r)) for c, r in [(6, 8), (26, 8), (26, 30), (6, 30), (6, 8)]]
        (tmp_path / "nd.geojson").write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    whole = read_scene(tmp_path / "nd.tif").to_wfov(4)
    monkeypatch.setattr(scene_io, "STRIP_PIXELS", 48 * 8)  # 8 rows per strip: many strips
    strips = read_scene(tmp_path / "nd.tif", factor=4)
    np.testing.assert_allclose(strips.image, whole.image, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(strips.label, whole.label)
    np.testing.assert_array_equal(strips.valid, whole.valid)
    assert strips.transform == whole.transform and strips.gsd == whole.gsd == 20.0


def test_too_large_whole_but_fine_in_strips(tmp_path, monkeypatch):
    write_scene(_scene_with_nodata(h=64, w=48), tmp_path)
    monkeypatch.setattr(scene_io, "MAX_PIXELS", 64 * 48 // 4)
    with pytest.raises(InvalidSceneError, match="pass a WFOV factor"):
        read_scene(tmp_path / "nd.tif")
    assert read_scene(tmp_path / "nd.tif", factor=2).shape == (32, 24)


@pytest.mark.slow
def test_training_never_draws_nodata():
    s = _scene_with_nodata()
    image = s.image.copy()
    image[:, ~s.valid] = 0.987  # a marker value only nodata pixels hold
    marked = Scene(image, label=s.label, valid=s.valid)
    x, _ = sample_pixels([marked], max_per_class=10_000, rng=np.random.default_rng(0))
    assert not np.isclose(x, 0.987).all(axis=1).any()
    unet = make_classifier("unet-uavsar", epochs=2, tile=16, width=4).fit([marked])
    assert np.isfinite(unet.history).all()


def test_metrics_and_observation_skip_nodata():
    s = _scene_with_nodata()
    pred = s.label | ~s.valid  # wrong everywhere on nodata
    assert Confusion.from_masks(pred, s.label, s.valid).fp == 0
    assert Confusion.from_masks(pred, s.label).fp > 0
    r = plan_scene(s.image, None, "straight-nadir", mask=s.label, valid=s.valid)
    rows = np.floor(r.trajectory.points[:, 1] + 0.5).astype(int)
    cols = np.floor(r.trajectory.points[:, 0] + 0.5).astype(int)
    assert s.valid[rows, cols].all()  # never pointed at nodata
    wide = plan_scene(
        s.image, None, "naive-transect", mask=s.label
    )  # planned without knowing nodata
    m_valid = observe(wide.trajectory, UtilityMaps.from_scene(s), factor=1)
    m_all = observe(
        wide.trajectory, UtilityMaps.from_scene(Scene(s.image, label=s.label)), factor=1
    )
    assert m_valid.pixels_observed < m_all.pixels_observed


def test_scene_valid_validation():
    img = np.zeros((4, 3, 3), np.float32)
    with pytest.raises(InvalidSceneError, match="valid mask"):
        Scene(img, valid=np.ones((2, 2), bool))
    with pytest.raises(InvalidSceneError, match="no valid pixel"):
        Scene(img, valid=np.zeros((3, 3), bool))
    assert Scene(img, valid=np.ones((3, 3), bool)).valid is None  # all valid: stored as None
