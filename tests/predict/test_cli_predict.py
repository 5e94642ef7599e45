"""``dyntarget plan`` with a prediction: two looks or a wind prior; bad inputs exit 2."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine

from dyntarget.cli import main
from motion_worlds import RigidCloud

GSD = 30.0
TRANSFORM = Affine(GSD, 0.0, 240_000.0, 0.0, -GSD, 2_160_000.0)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _write(path, data, crs="EPSG:32605"):
    data = np.asarray(data)
    if data.ndim == 2:
        data = data[None].astype(np.uint8)
    with rasterio.open(
        path, "w", driver="GTiff", height=data.shape[1], width=data.shape[2],
        count=data.shape[0], dtype=data.dtype.name, crs=crs, transform=TRANSFORM,
    ) as dst:  # fmt: skip
        dst.write(data)
    return path


@pytest.fixture(scope="module")
def looks(tmp_path_factory):
    """Two looks 4 s apart of a cloud drifting (1.5, -0.8) px/s, their masks, as GeoTIFFs
    (made once per module: the tests only read them)."""
    tmp_path = tmp_path_factory.mktemp("looks")
    world = RigidCloud(velocity=(1.5, -0.8))
    return {
        "prev": _write(tmp_path / "prev.tif", world.frame(0.0)),
        "cur": _write(tmp_path / "cur.tif", world.frame(4.0)),
        "prev_mask": _write(tmp_path / "prev_mask.tif", world.mask(0.0)),
        "cur_mask": _write(tmp_path / "cur_mask.tif", world.mask(4.0)),
        "world": world,
    }


def _points(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return np.array([[float(r["X"]), float(r["Y"])] for r in rows])


def _plan(capsys, looks, out, *extra):
    code, _, err = run(
        capsys,
        "plan",
        looks["cur"],
        "--mask",
        looks["cur_mask"],
        "--planner",
        "lawnmower-transect",
        "--crs",
        "native",
        "--out",
        out,
        *extra,
    )  # fmt: skip  (native: the shifts below are checked in the image's metres)
    return code, err


def test_two_looks_move_the_plan_by_velocity_times_lead(tmp_path, capsys, looks):
    code, err = _plan(capsys, looks, tmp_path / "still.csv")
    assert code == 0, err
    lead = 40.0
    code, err = _plan(
        capsys, looks, tmp_path / "moved.csv", "--previous", looks["prev"],
        "--previous-mask", looks["prev_mask"], "--interval-s", 4, "--lead-s", lead,
    )  # fmt: skip
    assert code == 0, err
    assert "motion: detached plume" in err
    shift = _points(tmp_path / "moved.csv").mean(0) - _points(tmp_path / "still.csv").mean(0)
    # (1.5, -0.8) px/s for 40 s = (60, -32) px = 1800 m east, 960 m north (rows go south)
    assert shift[0] == pytest.approx(1800.0, abs=0.1 * 1800 + GSD)
    assert shift[1] == pytest.approx(960.0, abs=0.1 * 960 + GSD)


def test_wind_prior_alone_in_the_image_crs(tmp_path, capsys, looks):
    code, err = _plan(capsys, looks, tmp_path / "still.geojson")
    assert code == 0, err
    code, err = _plan(
        capsys, looks, tmp_path / "wind.geojson", "--wind-mps", 10, "--wind-from-deg", 270,
        "--lead-s", 30,
    )  # fmt: skip
    assert code == 0, err

    def centre(p):
        doc = json.loads(p.read_text())
        # --crs native: the legacy member names the image's CRS the way GDAL reads it
        assert doc["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32605"
        pts = [
            f["geometry"]["coordinates"]
            for f in doc["features"]
            if f["geometry"]["type"] == "Point"
        ]
        return np.mean(pts, axis=0)

    # from the west at 10 m/s for 30 s: 300 m east, none north
    shift = centre(tmp_path / "wind.geojson") - centre(tmp_path / "still.geojson")
    assert shift == pytest.approx([300.0, 0.0], abs=GSD / 2)


def test_two_looks_checked_against_the_wind(tmp_path, capsys, looks):
    # truth: 1.5 px/s east = 45 m/s east... give a wind from the north instead: disagreement noted
    code, err = _plan(
        capsys, looks, tmp_path / "t.csv", "--previous", looks["prev"], "--previous-mask",
        looks["prev_mask"], "--interval-s", 4, "--lead-s", 10, "--wind-mps", 20,
        "--wind-from-deg", 0,
    )  # fmt: skip
    assert code == 0, err
    assert "DISAGREES with the wind prior" in err


@pytest.mark.slow
def test_agility_places_each_pointing_at_its_own_time(tmp_path, capsys, looks):
    code, err = _plan(
        capsys, looks, tmp_path / "t.csv", "--wind-mps", 10, "--wind-from-deg", 270,
        "--lead-s", 60, "--agility", "slow", "--start-s", 60, "--look-ahead-km", 800,
    )  # fmt: skip
    assert code == 0, err
    assert "time_s" in (tmp_path / "t.csv").read_text().splitlines()[0]


@pytest.fixture(scope="module")
def bad_looks(tmp_path_factory, looks):
    """Frames that do not fit ``looks``: smaller, and in another CRS."""
    d, world = tmp_path_factory.mktemp("bad-looks"), looks["world"]
    return {
        "small": _write(d / "small.tif", world.frame(0.0)[:, :100, :120]),
        "small_mask": _write(d / "small_mask.tif", world.mask(0.0)[:100, :120]),
        "geo4326": _write(d / "geo4326.tif", world.frame(0.0), crs="EPSG:32606"),
        "nodata": _write_nodata(d / "nodata.tif", world.frame(0.0).shape),
        "late": _with_time(_write(d / "late.tif", world.frame(0.0)), "2024-05-01T10:00:09Z"),
    }


def _write_nodata(path, shape):
    """A frame of the right grid in which every pixel is the nodata value."""
    with rasterio.open(
        path, "w", driver="GTiff", height=shape[1], width=shape[2], count=shape[0],
        dtype="float32", crs="EPSG:32605", transform=TRANSFORM, nodata=-9999.0,
    ) as dst:  # fmt: skip
        dst.write(np.full(shape, -9999.0, np.float32))
    return path


def _with_time(path, when):
    path.with_name(path.stem + ".meta.json").write_text(json.dumps({"acquired": when}))
    return path


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--previous", "small", "--previous-mask", "small_mask", "--interval-s", "2", "--lead-s", "5"], "does not match the image"),
        (["--previous", "geo4326", "--previous-mask", "prev_mask", "--interval-s", "2", "--lead-s", "5"], "CRS"),
        (["--previous", "prev", "--previous-mask", "prev_mask", "--interval-s", "0", "--lead-s", "5"], "--interval-s: expected seconds in 0.001..86400"),
        (["--previous", "prev", "--previous-mask", "prev_mask", "--interval-s", "-3", "--lead-s", "5"], "--interval-s: expected seconds in 0.001..86400"),
        (["--previous", "prev", "--previous-mask", "prev_mask", "--interval-s", "2", "--lead-s", "-1"], "--lead-s: expected seconds in 0..86400"),
        (["--interval-s", "2", "--lead-s", "5"], "--previous: missing"),
        (["--previous", "MISSING", "--previous-mask", "prev_mask", "--interval-s", "2", "--lead-s", "5"], "MISSING"),
        (["--previous", "prev", "--interval-s", "2", "--lead-s", "5"], "--previous-mask: missing"),
        (["--previous", "prev", "--previous-mask", "prev_mask", "--lead-s", "5"], "--interval-s: missing"),
        (["--previous", "prev", "--previous-mask", "prev_mask", "--interval-s", "2"], "--lead-s: missing"),
        (["--wind-mps", "5", "--lead-s", "5"], "--wind-from-deg"),
        (["--wind-mps", "-5", "--wind-from-deg", "90", "--lead-s", "5"], "--wind-mps: expected a wind speed, m/s in 0..60"),
        (["--lead-s", "5"], "a prediction needs"),
        # issue 28: a lead beyond what two looks support names the limit (30 intervals)
        (["--previous", "prev", "--previous-mask", "prev_mask", "--interval-s", "2", "--lead-s", "61"], "at most 30 intervals (60 s)"),
        (["--previous", "nodata", "--previous-mask", "prev_mask", "--interval-s", "2", "--lead-s", "5"], "nodata"),
    ],
)  # fmt: skip
def test_bad_prediction_inputs_exit_2_with_one_line(
    tmp_path, capsys, looks, bad_looks, extra, message
):
    files = {**bad_looks, "prev": looks["prev"], "prev_mask": looks["prev_mask"]}
    files["MISSING"] = tmp_path / "MISSING.tif"
    extra = [str(files[e]) if e in files else e for e in extra]
    code, err = _plan(capsys, looks, tmp_path / "t.geojson", *extra)
    assert code == 2, err
    assert message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "t.geojson").exists()


def test_frames_at_other_times_than_the_interval_exit_2(tmp_path, capsys, looks, bad_looks):
    """--previous acquired 1 s before the image, --interval-s 4: one line naming both."""
    import shutil

    cur = _with_time(Path(shutil.copy(looks["cur"], tmp_path / "cur.tif")), "2024-05-01T10:00:10Z")
    code, _, err = run(
        capsys, "plan", cur, "--mask", looks["cur_mask"], "--planner", "lawnmower-transect",
        "--previous", bad_looks["late"],
        "--previous-mask", looks["prev_mask"], "--interval-s", 4, "--lead-s", 10,
        "--out", tmp_path / "t.csv",
    )  # fmt: skip
    assert code == 2, err
    assert "times are 1 s apart" in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize("ground", ["fixed", "moving", "auto"])
def test_ground_option_reaches_the_estimate(tmp_path, capsys, looks, ground):
    """A rigid cloud over a still ground: every --ground gives its velocity; the log says
    which ground was used."""
    code, err = _plan(
        capsys, looks, tmp_path / "g.csv", "--previous", looks["prev"],
        "--previous-mask", looks["prev_mask"], "--interval-s", 4, "--lead-s", 8,
        "--ground", ground,
    )  # fmt: skip
    assert code == 0, err
    assert "motion: detached plume, velocity (+1.5" in err, err
    if ground == "auto":
        assert "ground auto -> fixed" in err, err


def test_utility_max_plans_on_the_prediction(tmp_path, capsys, looks):
    code, _, err = run(
        capsys, "plan", looks["cur"], "--mask", looks["cur_mask"], "--planner", "utility-max",
        "--agility", "fast", "--start-s", 30, "--look-ahead-km", 700, "--wind-mps", 10,
        "--wind-from-deg", 270, "--lead-s", 30, "--out", tmp_path / "u.csv",
    )  # fmt: skip
    assert code == 0, err
    assert "predict" in err and (tmp_path / "u.csv").read_text().count("\n") > 1


@pytest.fixture(scope="module")
def flat_looks(tmp_path_factory):
    """Two looks of a cloud with no texture inside (the flow cannot be trusted)."""
    d = tmp_path_factory.mktemp("flat-looks")
    world = RigidCloud(velocity=(1.5, -0.8), textured=False)
    return {
        "prev": _write(d / "prev.tif", world.frame(0.0)),
        "cur": _write(d / "cur.tif", world.frame(4.0)),
        "prev_mask": _write(d / "prev_mask.tif", world.mask(0.0)),
        "cur_mask": _write(d / "cur_mask.tif", world.mask(4.0)),
    }


def test_a_fallback_is_said_on_stderr_and_in_the_geojson(tmp_path, capsys, flat_looks):
    """Issue 28: an estimate too unsure to use falls back to persistence; the plan is the
    one drawn without prediction, stderr says FALLBACK, and the GeoJSON's properties
    carry the fallback."""
    code, err = _plan(capsys, flat_looks, tmp_path / "still.geojson")
    assert code == 0, err
    code, err = _plan(
        capsys, flat_looks, tmp_path / "fb.geojson", "--previous", flat_looks["prev"],
        "--previous-mask", flat_looks["prev_mask"], "--interval-s", 4, "--lead-s", 40,
    )  # fmt: skip
    assert code == 0, err
    assert "motion: FALLBACK to persistence" in err, err
    doc = json.loads((tmp_path / "fb.geojson").read_text())
    pred = doc["properties"]["prediction"]
    assert pred["fallback"] == "persistence" and pred["velocity_px_s"] == [0.0, 0.0]
    assert pred["lead_s"] == 40.0 and "fallback to persistence" in pred["summary"]
    still = json.loads((tmp_path / "still.geojson").read_text())
    assert "prediction" not in still["properties"]
    assert [f["geometry"] for f in doc["features"]] == [f["geometry"] for f in still["features"]]


def test_a_used_prediction_is_recorded_in_the_geojson(tmp_path, capsys, looks):
    code, err = _plan(
        capsys, looks, tmp_path / "p.geojson", "--previous", looks["prev"],
        "--previous-mask", looks["prev_mask"], "--interval-s", 4, "--lead-s", 12,
        "--polygons", tmp_path / "poly.geojson",
    )  # fmt: skip
    assert code == 0, err
    for name in ("p.geojson", "poly.geojson"):
        pred = json.loads((tmp_path / name).read_text())["properties"]["prediction"]
        assert pred["fallback"] == "" and pred["lead_s"] == 12.0
        # the world drifts (1.5, -0.8) px/s
        assert pred["velocity_px_s"] == pytest.approx([1.5, -0.8], abs=0.15)


def test_an_all_nodata_current_image_exits_2(tmp_path, capsys, looks, bad_looks):
    code, _, err = run(
        capsys, "plan", bad_looks["nodata"], "--mask", looks["cur_mask"],
        "--planner", "lawnmower-transect", "--previous", looks["prev"],
        "--previous-mask", looks["prev_mask"], "--interval-s", 4, "--lead-s", 10,
        "--out", tmp_path / "t.csv",
    )  # fmt: skip
    assert code == 2, err
    assert "nodata" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "t.csv").exists()
