"""The CLI as a newcomer meets it: plain-text listings, one version, train's band inputs."""

from __future__ import annotations

import re
from importlib.metadata import version

import numpy as np
import pytest
import rasterio
from affine import Affine

from dyntarget.cli import main


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


RST = re.compile(r"``|:\w+:`")


@pytest.mark.parametrize("command", ["planners", "classifiers"])
def test_listings_carry_no_rest_markup(capsys, command):
    code, out, _ = run(capsys, command)
    assert code == 0
    assert not RST.search(out), out
    assert len(out.strip().splitlines()) == 8


def test_diagonal_transect_line_names_no_private_helper(capsys):
    _, out, _ = run(capsys, "planners")
    line = next(ln for ln in out.splitlines() if ln.startswith("diagonal-transect"))
    assert "_transects" not in line and line.endswith("major axis.")


def test_version_comes_from_the_installed_metadata(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"dyntarget {version('dyntarget')}\n"


GRID = dict(
    driver="GTiff", width=16, height=16, count=1, crs="EPSG:32605",
    transform=Affine(30, 0, 500000, 0, -30, 2200000),
)  # fmt: skip


def _band_files(tmp_path):
    """Four uint16 single-band files (the Landsat / 38-Cloud layout) and a label.

    The plume (rows 4-11, columns 4-11) is bright in every band; the rest is dark.
    """
    rows, cols = np.mgrid[0:16, 0:16]
    plume = (rows >= 4) & (rows < 12) & (cols >= 4) & (cols < 12)
    paths = []
    for name, bright in (("red", 9000), ("green", 9000), ("blue", 9000), ("nir", 8000)):
        data = np.where(plume, bright, 800 + (rows * 7 + cols * 3) % 50).astype("uint16")
        path = tmp_path / f"{name}.tif"
        with rasterio.open(path, "w", dtype="uint16", **GRID) as dst:
            dst.write(data, 1)
        paths.append(path)
    gt = tmp_path / "gt.tif"
    with rasterio.open(gt, "w", dtype="uint8", **GRID) as d:
        d.write((plume * 255).astype("uint8"), 1)
    return paths, gt


def test_train_takes_four_band_files_and_a_preset(tmp_path, capsys):
    bands, gt = _band_files(tmp_path)
    out = tmp_path / "model"
    code, _, err = run(
        capsys, "train", *bands, "--mask", gt, "--preset", "landsat8",
        "--classifier", "decision-tree", "--factor", 1, "--out", out,
    )  # fmt: skip
    assert code == 0, err
    assert "on 1 scenes" in err
    assert (out / "metadata.json").is_file()


def test_train_on_a_folder_of_band_files_points_at_the_preset(tmp_path, capsys):
    _band_files(tmp_path)
    code, _, err = run(
        capsys, "train", "--data", tmp_path, "--classifier", "decision-tree", "--out",
        tmp_path / "m",
    )  # fmt: skip
    assert code == 2
    assert "got 1 band(s)" in err and "--preset landsat8" in err
    assert len(err.strip().splitlines()) == 1


def test_train_on_an_image_needs_its_mask(tmp_path, capsys):
    bands, _ = _band_files(tmp_path)
    code, _, err = run(
        capsys, "train", *bands, "--classifier", "decision-tree", "--out", tmp_path / "m"
    )
    assert code == 2 and "--mask MASK" in err
    assert not (tmp_path / "m").exists()
