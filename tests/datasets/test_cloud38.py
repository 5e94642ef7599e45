"""The real 38-Cloud Landsat 8 patch in ../shared/data (skipped where that folder is absent)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from dyntarget.cli import main
from dyntarget.denoise import denoise
from dyntarget.plan import BASELINES, geometric_planners, plan
from helpers import shared_data

DATA = shared_data()
PATCH = DATA / "38cloud-sample" if DATA else None
pytestmark = pytest.mark.skipif(
    PATCH is None or not PATCH.is_dir(),
    reason="../shared/data/38cloud-sample is not present (a user's checkout)",
)


@pytest.fixture(scope="module")
def patch():
    from dyntarget.datasets.cloud38 import read_patch

    return read_patch(PATCH)


def test_patch_reads_as_landsat8_toa(patch):
    assert patch.image.shape == (4, 384, 384) and patch.gsd == 30.0
    assert 0.25 < patch.label.mean() < 0.35  # README: 30.7 % cloud
    # clouds are brighter than clear pixels in every band
    assert all(
        patch.image[b][patch.label].mean() > patch.image[b][~patch.label].mean() for b in range(4)
    )


def test_plan_cli_on_band_files_with_preset(tmp_path, capsys):
    files = [str(PATCH / f) for f in ("red.tif", "green.tif", "blue.tif", "nir.tif")]
    code = main(
        [
            "plan",
            *files,
            "--preset",
            "landsat8",
            "--mask",
            str(PATCH / "gt.tif"),
            "--planner",
            "trace-outline",
            "--out",
            str(tmp_path / "t.geojson"),
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert (tmp_path / "t.geojson").stat().st_size > 100


@pytest.mark.slow
def test_messy_real_mask_denoise_and_every_planner(patch):
    """The human cloud mask is fragmented (many blobs, holes, border cuts): everything stays correct."""
    import cv2

    n_raw = cv2.connectedComponents(patch.label.astype(np.uint8), connectivity=8)[0] - 1
    assert n_raw > 20  # a realistically messy mask
    t0 = time.perf_counter()
    cleaned = denoise(patch.label)
    assert time.perf_counter() - t0 < 5.0  # generous: guards against pathological slow-downs only
    assert 0 < len(cleaned.polygons) < n_raw
    assert all(p.is_valid for p in cleaned.polygons)
    h, w = patch.shape
    union = (
        cleaned.polygons[0].union(cleaned.polygons[1])
        if len(cleaned.polygons) > 1
        else cleaned.polygons[0]
    )
    for name in geometric_planners():
        t = plan(name, cleaned.mask, cleaned.polygons)
        assert len(t) > 0 and np.isfinite(t.points).all()
        assert (t.points[:, 0] >= 0).all() and (t.points[:, 0] <= w - 1).all()
        assert (t.points[:, 1] >= 0).all() and (t.points[:, 1] <= h - 1).all()
        if name == "trace-outline":  # outline points lie on the polygons' boundaries
            assert all(
                any(
                    p.exterior.distance(__import__("shapely").Point(xy)) < 1e-6
                    for p in cleaned.polygons
                )
                for xy in t.points[:50]
            )
        if name not in BASELINES:
            assert t.part.max() + 1 <= len(cleaned.polygons)
    assert union.area > 0


@pytest.mark.slow
def test_real_pixel_check_small(patch):
    from dyntarget.evaluate.realpixels import real_pixel_check, split_columns

    train, test = split_columns(patch)
    assert train.shape == (384, 173) and test.shape == (384, 179)
    result = real_pixel_check(patch, classifiers=["band-threshold", "random-forest"])
    seg = {(r["classifier"], r["denoised"]): r for r in result["segmentation"]}
    assert (
        seg[("random-forest", False)]["IoU"] > 0.5
    )  # clouds are learnable from 4 bands on real pixels
    ratios = {
        (r["Trajectory Algorithm"], r["Classifier"]): r["Ratio Plume"] for r in result["planning"]
    }
    assert ratios[("Lawnmower Transect", "Random Forest")] > ratios[("Straight Nadir", "N/A")]
