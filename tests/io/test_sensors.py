from __future__ import annotations

import numpy as np
import pytest
from affine import Affine
from rasterio.crs import CRS

from dyntarget import DataFileError, InvalidParameterError, InvalidSceneError, UnknownNameError
from dyntarget.io.sensors import (
    PRESETS,
    parse_bands,
    read_any,
    read_band_files,
    read_multiband,
    read_npz,
)
from helpers import write_raw_tif


def _stack(n, h=6, w=5):
    """Band k (1-based) holds the value 1000 * k + pixel index, as uint16 digital numbers."""
    base = np.arange(h * w, dtype=np.uint16).reshape(h, w)
    return np.stack([(1000 * k + base).astype(np.uint16) for k in range(1, n + 1)])


def test_parse_bands():
    assert parse_bands("3,2,1,7") == (3, 2, 1, 7)
    assert parse_bands(["B4", "b3", "B2", "B8"], names=PRESETS["sentinel2-l1c"].band_names) == (
        4,
        3,
        2,
        8,
    )
    with pytest.raises(InvalidParameterError, match="expected 4 bands"):
        parse_bands("1,2,3")
    with pytest.raises(InvalidParameterError, match="'B13' is neither"):
        parse_bands("B4,B3,B2,B13", names=PRESETS["sentinel2-l1c"].band_names)
    with pytest.raises(InvalidParameterError, match="1-based"):
        parse_bands("0,1,2,3")


def test_sentinel2_preset_selects_b4_b3_b2_b8_and_scales(tmp_path):
    p = write_raw_tif(
        tmp_path / "s2.tif",
        _stack(13),
        crs=CRS.from_epsg(32632),
        transform=Affine(10, 0, 5e5, 0, -10, 5e6),
    )
    s = read_multiband(p, preset="sentinel2-l1c")
    np.testing.assert_allclose(s.image[:, 0, 0], [0.4, 0.3, 0.2, 0.8], rtol=1e-6)
    assert s.gsd == 10.0 and s.crs == "EPSG:32632"
    assert read_multiband(p, bands="B4,B3,B2,B8A", preset="sentinel2-l1c").image[
        3, 0, 0
    ] == pytest.approx(0.9)


def test_planetscope_preset_reorders_bgr(tmp_path):
    p = write_raw_tif(tmp_path / "ps.tif", _stack(4))
    np.testing.assert_allclose(
        read_multiband(p, preset="planetscope").image[:, 0, 0], [0.3, 0.2, 0.1, 0.4], rtol=1e-6
    )


def test_landsat_preset_offset(tmp_path):
    p = write_raw_tif(tmp_path / "l8.tif", _stack(7) * 5)
    img = read_multiband(p, preset="landsat8").image
    assert img[0, 0, 0] == pytest.approx(4 * 5000 * 2e-5 - 0.1)


def test_explicit_bands_and_errors(tmp_path):
    p = write_raw_tif(tmp_path / "m.tif", _stack(5))
    assert read_multiband(p, bands="5,4,3,2").image[0, 0, 0] == pytest.approx(0.5)
    with pytest.raises(InvalidSceneError, match="band 9 requested but the file has 5"):
        read_multiband(p, bands="9,4,3,2")
    with pytest.raises(InvalidSceneError, match="choose R, G, B, NIR with --bands or a --preset"):
        read_multiband(p)
    with pytest.raises(UnknownNameError, match="unknown preset 'modis'"):
        read_multiband(p, preset="modis")


def test_band_files(tmp_path):
    paths = [
        write_raw_tif(tmp_path / f"{c}.tif", _stack(1) + 100 * i) for i, c in enumerate("rgbn")
    ]
    s = read_band_files(paths, scale=1e-4)
    np.testing.assert_allclose(s.image[:, 0, 0], [0.1, 0.11, 0.12, 0.13], rtol=1e-5)
    bad = write_raw_tif(tmp_path / "small.tif", _stack(1, h=3))
    with pytest.raises(InvalidSceneError, match="differs from the first band"):
        read_band_files([*paths[:3], bad])
    with pytest.raises(InvalidParameterError, match="expected 4 files"):
        read_band_files(paths[:3])


def test_npz(tmp_path):
    rng = np.random.default_rng(0)
    image = rng.uniform(0, 0.5, (4, 5, 6)).astype(np.float32)
    np.savez(tmp_path / "a.npz", image=image, label=image[0] > 0.25)
    s = read_npz(tmp_path / "a.npz")
    np.testing.assert_array_equal(s.image, image)
    assert s.label.dtype == bool
    np.savez(tmp_path / "b.npz", red=image[0], green=image[1], blue=image[2], nir=image[3])
    np.testing.assert_array_equal(read_any([tmp_path / "b.npz"]).image, image)
    np.savez(tmp_path / "c.npz", other=image)
    with pytest.raises(InvalidSceneError, match="expected an 'image' array"):
        read_npz(tmp_path / "c.npz")
    (tmp_path / "d.npz").write_bytes(b"not a zip")
    with pytest.raises(DataFileError, match="not a readable .npz"):
        read_npz(tmp_path / "d.npz")
    np.savez(tmp_path / "e.npz", image=np.array([object()], dtype=object))
    with pytest.raises(DataFileError, match="not a readable .npz"):
        read_npz(tmp_path / "e.npz")  # pickled object arrays are refused, never loaded
