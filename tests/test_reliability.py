"""Hostile inputs through the CLI: exit code 2, one line naming the file and the problem, no traceback.

Each case here is a row of docs/reliability.md.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from dyntarget import Scene
from dyntarget.cli import main
from dyntarget.io import write_scene
from helpers import ramp, write_raw_tif


def _good(tmp_path, name="img", h=16, w=16):
    image = np.random.default_rng(0).uniform(0.05, 0.6, (4, h, w)).astype(np.float32)
    label = np.zeros((h, w), bool)
    label[4:10, 3:12] = True
    write_scene(Scene(image, label=label, id=name), tmp_path)
    return tmp_path / f"{name}.tif"


def _bands(n):
    def make(tmp_path):
        return write_raw_tif(tmp_path / "img.tif", ramp(n, 8, 8))

    return make


def _values(fill):
    def make(tmp_path):
        data = ramp(4, 8, 8)
        if callable(fill):
            data = fill(data)
        else:
            data[1, 2, 3] = fill
        return write_raw_tif(tmp_path / "img.tif", data)

    return make


def _truncated(tmp_path):
    big = Scene(np.random.default_rng(0).uniform(size=(4, 512, 512)).astype(np.float32), id="img")
    write_scene(big, tmp_path)
    p = tmp_path / "img.tif"
    p.write_bytes(p.read_bytes()[:20000])
    return p


def _not_tiff(tmp_path):
    p = tmp_path / "img.tif"
    p.write_text("GIF89a definitely not a GeoTIFF")
    return p


def _empty_file(tmp_path):
    p = tmp_path / "img.tif"
    p.write_bytes(b"")
    return p


# (case id, how to make the image, extra CLI arguments, expected fragment of the error)
PLAN_CASES = [
    ("1-band image", _bands(1), [], "expected 4 bands (R, G, B, NIR), got 1 band"),
    ("3-band image", _bands(3), [], "got 3 band"),
    ("5-band image", _bands(5), [], "got 5 band"),
    ("NaN value", _values(np.nan), [], "1 value(s) are NaN or infinite"),
    ("infinite value", _values(np.inf), [], "NaN or infinite"),
    ("strongly negative values", _values(-3.0), [], "are not reflectance"),
    ("digital numbers stored as float", _values(lambda d: d * 20000), [], "pass a scale"),
    ("all-zero image", _values(lambda d: d * 0), [], "image is constant (every value 0)"),
    ("constant image", _values(lambda d: d * 0 + 0.3), [], "image is constant"),
    ("truncated GeoTIFF", _truncated, [], "img.tif"),
    ("not a TIFF", _not_tiff, [], "not a readable raster"),
    ("empty file", _empty_file, [], "not a readable raster"),
    ("missing file", lambda tmp_path: tmp_path / "absent.tif", [], "absent.tif: no such file"),
    ("factor larger than image", _good, ["--factor", "64"], "factor: 64 is larger than the image"),
    ("step below 0.1 px", _good, ["--step", "0.01"], "step: expected a number of pixels >= 0.1"),
    (
        "unknown planner",
        _good,
        ["--planner", "spiral"],
        "unknown planner 'spiral'; expected one of",
    ),
]


@pytest.mark.parametrize(
    ("case", "make", "extra", "message"), PLAN_CASES, ids=[c[0] for c in PLAN_CASES]
)
def test_plan_bad_image(tmp_path, capsys, case, make, extra, message):
    image = make(tmp_path)
    mask = _good(tmp_path, "ok").with_name("ok_mask.tif")
    planner = [] if "--planner" in extra else ["--planner", "track-center"]
    out = tmp_path / "t.geojson"
    code = main(["plan", str(image), "--mask", str(mask), "--out", str(out), *planner, *extra])
    err = capsys.readouterr().err
    assert code == 2, err
    assert message in err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 or err.startswith("usage")
    assert not out.exists()


def _label_cases():
    def wrong_shape(tmp_path):
        p = tmp_path / "m.tif"
        write_raw_tif(p, np.ones((1, 5, 5), np.uint8))
        return p, "does not match the image's (16, 16)"

    def nan_label(tmp_path):
        data = np.zeros((1, 16, 16), np.float32)
        data[0, 0, 0] = np.nan
        return write_raw_tif(tmp_path / "m.tif", data), "label holds NaN"

    def two_band_label(tmp_path):
        return write_raw_tif(
            tmp_path / "m.tif", np.zeros((2, 16, 16), np.uint8)
        ), "a label must have 1 band, got 2"

    def geojson_invalid(tmp_path):
        p = tmp_path / "m.geojson"
        p.write_text("{ nope")
        return p, "not valid JSON"

    def geojson_outside(tmp_path):
        p = tmp_path / "m.geojson"
        p.write_text(
            json.dumps(
                {
                    "type": "Polygon",
                    "coordinates": [[[100, 100], [120, 100], [120, 120], [100, 100]]],
                }
            )
        )
        return p, "no polygon overlaps the image"

    def geojson_point(tmp_path):
        p = tmp_path / "m.geojson"
        p.write_text(
            json.dumps({"type": "Feature", "geometry": {"type": "Point", "coordinates": [1, 1]}})
        )
        return p, "expected Polygon or MultiPolygon, got Point"

    return [wrong_shape, nan_label, two_band_label, geojson_invalid, geojson_outside, geojson_point]


@pytest.mark.parametrize("make", _label_cases(), ids=lambda f: f.__name__)
def test_plan_bad_label(tmp_path, capsys, make):
    image = _good(tmp_path)
    label, message = make(tmp_path)
    code = main(
        [
            "plan",
            str(image),
            "--mask",
            str(label),
            "--planner",
            "trace-outline",
            "--out",
            str(tmp_path / "t.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err, err
    assert str(label.name) in err


def test_geojson_empty_gives_empty_trajectory_with_note(tmp_path, capsys):
    image = _good(tmp_path)
    (tmp_path / "m.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    code = main(
        [
            "plan",
            str(image),
            "--mask",
            str(tmp_path / "m.geojson"),
            "--planner",
            "trace-outline",
            "--out",
            str(tmp_path / "t.geojson"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 0 and "no plume found" in err
    assert json.loads((tmp_path / "t.geojson").read_text())["features"] == []


def test_no_crs_writes_pixel_coordinates(tmp_path, capsys):
    image = _good(tmp_path)
    code = main(
        [
            "plan",
            str(image),
            "--mask",
            str(image.with_name("img_mask.tif")),
            "--planner",
            "track-center",
            "--out",
            str(tmp_path / "t.geojson"),
        ]
    )
    assert code == 0
    doc = json.loads((tmp_path / "t.geojson").read_text())
    assert doc["properties"]["coordinates"].startswith("WFOV pixels (column, row)")
    assert "crs" not in doc and "bbox" not in doc


def test_one_pixel_image(tmp_path, capsys):
    image = np.array([0.1, 0.2, 0.3, 0.4], np.float32).reshape(4, 1, 1)
    write_scene(Scene(image, label=np.ones((1, 1), bool), id="px"), tmp_path)
    for planner in ("trace-outline", "track-center", "lawnmower-transect", "straight-nadir"):
        code = main(
            [
                "plan",
                str(tmp_path / "px.tif"),
                "--mask",
                str(tmp_path / "px_mask.tif"),
                "--planner",
                planner,
                "--out",
                str(tmp_path / f"{planner}.csv"),
            ]
        )
        assert code == 0, capsys.readouterr().err
        rows = (tmp_path / f"{planner}.csv").read_text().splitlines()[1:]
        assert rows and all(r.split(",")[1:3] == ["0.000", "0.000"] for r in rows)


def test_very_large_image_refused_before_reading(tmp_path, capsys, monkeypatch):
    import dyntarget.io.scenes as scenes_io

    image = _good(tmp_path)
    monkeypatch.setattr(scenes_io, "MAX_PIXELS", 100)
    code = main(
        [
            "plan",
            str(image),
            "--mask",
            str(image.with_name("img_mask.tif")),
            "--planner",
            "track-center",
            "--out",
            str(tmp_path / "t.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "image is 16 x 16 px, more than the 100 px" in err


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        ("missing", "not a model directory"),
        ("foreign", "not a dyntarget model"),
    ],
)
def test_plan_bad_model(tmp_path, capsys, setup, message):
    image = _good(tmp_path)
    model = tmp_path / "model"
    if setup == "foreign":
        model.mkdir()
        (model / "metadata.json").write_text('{"format": "pickle"}')
    code = main(
        [
            "plan",
            str(image),
            "--model",
            str(model),
            "--planner",
            "track-center",
            "--out",
            str(tmp_path / "t.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err


def test_wrong_output_suffix(tmp_path, capsys):
    image = _good(tmp_path)
    code = main(
        [
            "plan",
            str(image),
            "--mask",
            str(image.with_name("img_mask.tif")),
            "--planner",
            "track-center",
            "--out",
            str(tmp_path / "t.txt"),
        ]
    )
    assert code == 2 and "must end in .geojson, .json or .csv" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["evaluate", "classification", "--folds", "1"], "folds: expected an integer >= 2"),
        (["evaluate", "classification", "--folds", "9"], "9 folds need at least 9 scenes, got 2"),
        (["evaluate", "classification", "--classifiers", "svm"], "unknown classifier 'svm'"),
        (["train", "--classifier", "mlp", "--factor", "0"], "expected a positive integer, got 0"),
    ],
)
def test_evaluation_bad_parameters(tmp_path, capsys, argv, message):
    _good(tmp_path / "data", "a")
    _good(tmp_path / "data", "b")
    argv = [*argv, "--data", str(tmp_path / "data"), "--out", str(tmp_path / "out"), "--quiet"]
    if argv[0] == "train":
        argv.remove("--quiet")
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err, err


def test_internal_error_exit_1_one_line_and_debug_traceback(tmp_path, capsys, monkeypatch):
    import dyntarget.plan.planners as planners

    image = _good(tmp_path)
    argv = [
        "plan",
        str(image),
        "--mask",
        str(image.with_name("img_mask.tif")),
        "--planner",
        "track-center",
        "--out",
        str(tmp_path / "t.csv"),
    ]

    def broken(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(planners, "major_axis", broken)
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert (
        err.strip()
        == "dyntarget: internal error: RuntimeError: boom (rerun with --debug for a traceback)"
    )
    with pytest.raises(RuntimeError, match="boom"):
        main(["--debug", *argv])
