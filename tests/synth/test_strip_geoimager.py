"""The GEO imager over a synthetic strip, and a world on a coarser grid."""

from __future__ import annotations

import numpy as np

from dyntarget.synth.geoimager import GeoStream
from dyntarget.synth.strip import resampled_spec, strip_spec


def test_geo_grid_covers_the_strip_and_an_8_km_margin():
    # a 64 x 256 px strip of 8 m: 512 m x 2048 m; 1 km cells with 8 km around it:
    # x from -8000 to 8512 m: cells -8 .. 8 (17); y from -8000 to 10048 m: cells -8 .. 10 (19)
    spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    s = GeoStream(spec, window, 1000.0, 0.0)
    assert s.cell0 == (-8, -8) and s.cells == (19, 17)
    assert s.strip_cols() == (8, 9)  # the strip's 512 m lie in the cell from 0 to 1000 m
    # GEO row 8 is the cell from 0 to 1000 m: its centre, 500 m, is strip row 62.5
    assert s.strip_rows(np.array([8])).tolist() == [62.5]
    assert s.m == 8 and s.render_gsd == 125.0  # 8 render px of 125 m a GEO cell


def test_geo_images_are_noisy_but_the_same_for_the_same_seed():
    spec, window = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    a = GeoStream(spec, window, 1000.0, 0.01).image(-600.0)
    b = GeoStream(spec, window, 1000.0, 0.01).image(-600.0)
    clean = GeoStream(spec, window, 1000.0, 0.0).image(-600.0)
    assert np.array_equal(a, b)
    assert 0.005 < float(np.std(a - clean)) < 0.02  # the imager's own noise, std 0.01


def test_resampled_spec_moves_vents_and_clouds_with_the_grid():
    spec, _ = strip_spec(0, width=64, length=256, plumes=2, wind_mps=5.0)
    c = resampled_spec(spec, spec.gsd * 2, lambda v: v / 2, noise_sigma=0.0)
    assert c.gsd == 16.0 and c.noise_sigma == 0.0
    assert [(v.x, v.y) for v in c.vents] == [(v.x / 2, v.y / 2) for v in spec.vents]
