"""``dyntarget plan`` outputs: RFC 7946 by default, --crs native, time, --polygons, --html."""

from __future__ import annotations

import json

import numpy as np
import pytest
from affine import Affine

from dyntarget.cli import main
from dyntarget.io import write_scene
from dyntarget.scene import Scene

pyogrio = pytest.importorskip("pyogrio", reason="pyogrio (GDAL's OGR) is in the test extra")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _scene(tmp_path, crs, transform, *, size=48, name="s"):
    """A square plume on dark ground, written as <name>.tif + <name>_mask.tif in ``crs``."""
    image = np.full((4, size, size), 0.05, np.float32)
    image += np.linspace(0, 0.02, size, dtype=np.float32)[None, None, :]
    label = np.zeros((size, size), bool)
    label[10:38, 8:40] = True
    image[:, label] = 0.7
    scene = Scene(image, label=label, gsd=30.0, crs=crs, transform=transform, id=name)
    write_scene(scene, tmp_path)
    return tmp_path / f"{name}.tif", tmp_path / f"{name}_mask.tif"


def _plan(capsys, image, mask, out, *extra):
    code, stdout, err = run(
        capsys, "plan", image, "--mask", mask, "--planner", "lawnmower-transect", "--out", out,
        *extra,
    )  # fmt: skip
    assert code == 0, err
    return stdout


def _points(path):
    import shapely

    meta, _, geoms, fields = pyogrio.raw.read(path, where="kind = 'pointing'")
    order = fields[list(meta["fields"]).index("order")]
    return shapely.get_coordinates(shapely.from_wkb(geoms))[np.argsort(order)], meta["crs"]


GRIDS = {
    "utm32n": ("EPSG:32632", Affine(30.0, 0.0, 653000.0, 0.0, -30.0, 5120000.0)),
    "utm33s": ("EPSG:32733", Affine(30.0, 0.0, 418000.0, 0.0, -30.0, 8410000.0)),
}


@pytest.mark.parametrize("zone", list(GRIDS))
def test_plan_geojson_round_trips_through_gdal_within_a_tenth_of_a_pixel(tmp_path, capsys, zone):
    from rasterio.warp import transform as warp

    crs, transform = GRIDS[zone]
    image, mask = _scene(tmp_path, crs, transform)
    _plan(capsys, image, mask, tmp_path / "rfc.geojson")
    _plan(capsys, image, mask, tmp_path / "native.geojson", "--crs", "native")
    lonlat, rfc_crs = _points(tmp_path / "rfc.geojson")
    native, native_crs = _points(tmp_path / "native.geojson")
    assert rfc_crs == "EPSG:4326" and native_crs == crs
    assert "crs" not in json.loads((tmp_path / "rfc.geojson").read_text())
    xs, ys = warp("EPSG:4326", crs, lonlat[:, 0], lonlat[:, 1])
    # metres -> pixels: 30 m per pixel on both axes
    err_px = np.hypot(np.asarray(xs) - native[:, 0], np.asarray(ys) - native[:, 1]) / 30.0
    assert len(native) > 10 and err_px.max() < 0.1, err_px.max()
    if zone == "utm33s":
        assert (lonlat[:, 1] < 0).all()  # southern hemisphere: negative latitudes


@pytest.mark.slow
def test_agility_and_acquired_put_time_on_every_pointing_in_geojson_and_csv(tmp_path, capsys):
    crs, transform = GRIDS["utm32n"]
    image, mask = _scene(tmp_path, crs, transform)
    extra = ("--agility", "fast", "--acquired", "2024-05-01T12:00:00+02:00")
    _plan(capsys, image, mask, tmp_path / "t.geojson", *extra)
    _plan(capsys, image, mask, tmp_path / "t.csv", *extra)
    doc = json.loads((tmp_path / "t.geojson").read_text())
    assert doc["properties"]["acquired"] == "2024-05-01T10:00:00.000Z"
    pts = [f["properties"] for f in doc["features"] if f["properties"]["kind"] == "pointing"]
    rows = (tmp_path / "t.csv").read_text().splitlines()
    assert rows[0] == "order,x,y,part,lon,lat,time_s,time"
    assert len(rows) - 1 == len(pts) > 0
    for p, row in zip(pts, rows[1:], strict=True):
        cells = row.split(",")
        assert float(cells[6]) == p["time_s"] and cells[7] == p["time"]
        # the ISO time is the acquisition plus time_s (to the millisecond)
        from datetime import datetime

        t = datetime.fromisoformat(p["time"].replace("Z", "+00:00"))
        start = datetime.fromisoformat("2024-05-01T10:00:00+00:00")
        assert abs((t - start).total_seconds() - p["time_s"]) < 1e-3
    # GDAL reads `time` as a DateTime field (what QGIS's temporal controller needs)
    meta, _, _, fields = pyogrio.raw.read(tmp_path / "t.geojson", where="kind = 'pointing'")
    k = list(meta["fields"]).index("time")
    assert str(meta["dtypes"][k]).startswith("datetime64")
    assert [str(v) for v in fields[k]] == [p["time"].rstrip("Z") for p in pts]


@pytest.mark.slow
def test_acquisition_time_is_read_from_the_tiff_tag(tmp_path, capsys):
    import rasterio

    crs, transform = GRIDS["utm33s"]
    image, mask = _scene(tmp_path, crs, transform)
    with rasterio.open(image, "r+") as dst:
        dst.update_tags(TIFFTAG_DATETIME="2023:07:14 23:59:59")
    _plan(capsys, image, mask, tmp_path / "t.csv", "--agility", "fast")
    first = (tmp_path / "t.csv").read_text().splitlines()[1].split(",")
    assert first[7].startswith("2023-07-1")  # 23:59:59 + time_s (tens of seconds): next day
    assert first[7] > "2023-07-14T23:59:59"


def test_polygons_are_written_in_the_same_form_and_read_by_gdal(tmp_path, capsys):
    import shapely

    crs, transform = GRIDS["utm32n"]
    image, mask = _scene(tmp_path, crs, transform)
    _plan(capsys, image, mask, tmp_path / "t.geojson", "--polygons", tmp_path / "p.geojson")
    meta, _, geoms, _ = pyogrio.raw.read(tmp_path / "p.geojson")
    assert meta["crs"] == "EPSG:4326" and len(geoms) == 1
    poly = shapely.from_wkb(geoms[0])
    assert poly.exterior.is_ccw
    # the plume is the 32 x 28 px rectangle: its polygon (through pixel centres) is 31 x 27 px
    doc = json.loads((tmp_path / "p.geojson").read_text())
    assert doc["features"][0]["properties"]["area_px"] == 31 * 27
    assert doc["features"][0]["properties"]["area_m2"] == 31 * 27 * 900


def test_image_without_crs_keeps_pixels_and_says_so(tmp_path, capsys):
    image, mask = _scene(tmp_path, None, None)
    _plan(capsys, image, mask, tmp_path / "t.geojson", "--crs", "native")
    doc = json.loads((tmp_path / "t.geojson").read_text())
    assert "no CRS" in doc["properties"]["coordinates"] and "crs" not in doc
    pt = next(f for f in doc["features"] if f["properties"]["kind"] == "pointing")
    assert pt["geometry"]["coordinates"] == [pt["properties"]["x_px"], pt["properties"]["y_px"]]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--polygons", "p.csv"], "--polygons: expected a .geojson path"),
        (["--html", "v.png"], "--html: expected a .html path"),
        (["--acquired", "noon"], "--acquired: expected an ISO-8601"),
        (["--crs", "utm"], "invalid choice: 'utm'"),
        (["--polygons", "out/t.geojson"], "the same path as --out"),
        (["--polygons", "out/d.geojson"], "a directory, not written by dyntarget"),
    ],
)
def test_bad_output_options_exit_2_and_write_nothing(tmp_path, capsys, extra, message):
    crs, transform = GRIDS["utm32n"]
    image, mask = _scene(tmp_path, crs, transform)
    extra = [str(tmp_path / e) if "." in e and not e.startswith("-") else e for e in extra]
    out = tmp_path / "out"
    if "d.geojson" in " ".join(extra):
        (out / "d.geojson").mkdir(parents=True)
    code, _, err = run(
        capsys, "plan", image, "--mask", mask, "--planner", "track-center",
        "--out", out / "t.geojson", *extra,
    )  # fmt: skip
    assert code == 2 and message in err and "Traceback" not in err
    assert not out.exists() or [p.name for p in out.iterdir()] in ([], ["d.geojson"])


@pytest.mark.slow
def test_plan_html_view_holds_the_geojson_pointings_in_chromium(tmp_path, capsys):
    pytest.importorskip("plotly")
    from view_browser import find_chromium, render

    if find_chromium() is None:
        pytest.skip("headless Chromium not installed (apt-get install -y chromium chromium-driver)")
    crs, transform = GRIDS["utm33s"]
    image, mask = _scene(tmp_path, crs, transform)
    stdout = _plan(
        capsys, image, mask, tmp_path / "t.geojson", "--html", tmp_path / "v.html",
        "--agility", "fast", "--acquired", "2024-05-01T10:00:00Z",
    )  # fmt: skip
    assert str(tmp_path / "v.html") in stdout
    doc = json.loads((tmp_path / "t.geojson").read_text())
    px = [
        [f["properties"]["x_px"], f["properties"]["y_px"]]
        for f in doc["features"]
        if f["properties"]["kind"] == "pointing"
    ]
    shown = render(tmp_path / "v.html")
    assert shown.errors == [], shown.console
    np.testing.assert_allclose(shown.drawn, px, atol=0.5 / shown.px_per_unit + 1e-3)


def test_html_without_plotly_names_the_extra_and_writes_nothing(tmp_path, capsys, monkeypatch):
    import sys

    crs, transform = GRIDS["utm32n"]
    image, mask = _scene(tmp_path, crs, transform)
    monkeypatch.setitem(sys.modules, "plotly", None)  # as if the 'view' extra were absent
    monkeypatch.setitem(sys.modules, "plotly.graph_objects", None)
    out = tmp_path / "out"
    code, _, err = run(
        capsys, "plan", image, "--mask", mask, "--planner", "track-center",
        "--out", out / "t.geojson", "--html", out / "v.html",
    )  # fmt: skip
    assert code == 2
    assert err.strip().splitlines()[-1] == (
        'dyntarget: error: plotly is not installed: pip install "dyntarget[view]"'
    )
    assert not out.exists() or list(out.iterdir()) == []


def test_html_view_is_replaced_on_rerun_but_a_foreign_page_is_left_alone(tmp_path, capsys):
    pytest.importorskip("plotly")
    crs, transform = GRIDS["utm32n"]
    image, mask = _scene(tmp_path, crs, transform)
    view = tmp_path / "view.html"
    argv = ["plan", image, "--mask", mask, "--planner", "track-center", "--html", view]
    code, _, err = run(capsys, *argv, "--out", tmp_path / "a.geojson")
    assert code == 0, err
    code, _, err = run(capsys, *argv, "--out", tmp_path / "b.geojson")  # ours: replaced
    assert code == 0, err
    foreign = tmp_path / "notes.html"
    foreign.write_text("<!doctype html><html><body>my notes</body></html>")
    argv[-1] = foreign
    code, _, err = run(capsys, *argv, "--out", tmp_path / "c.geojson")
    assert code == 2 and "--html" in err and "not written by dyntarget" in err
    assert foreign.read_text() == "<!doctype html><html><body>my notes</body></html>"
    assert not (tmp_path / "c.geojson").exists()


# --- the model's training resolution (metadata.json) against the run's ---------------------


@pytest.fixture(scope="module")
def threshold_model(tmp_path_factory):
    """A band-threshold model directory trained by 'dyntarget train' at factor 2 on 30 m scenes."""
    d = tmp_path_factory.mktemp("res")
    crs, transform = GRIDS["utm32n"]
    for k in range(2):
        _scene(d / "scenes", crs, transform, name=f"s{k}")
    assert main(["train", "--data", str(d / "scenes"), "--classifier", "band-threshold",
                 "--factor", "2", "--out", str(d / "model")]) == 0  # fmt: skip
    return d


def _with_training(src, dst, **fields):
    """A copy of the model directory whose metadata.json holds these training fields only."""
    import shutil

    shutil.copytree(src, dst)
    meta = json.loads((dst / "metadata.json").read_text())
    meta["training"] = {k: v for k, v in fields.items() if v is not None}
    (dst / "metadata.json").write_text(json.dumps(meta))
    return dst


def test_train_records_the_factor_and_wfov_gsd(threshold_model):
    meta = json.loads((threshold_model / "model" / "metadata.json").read_text())
    assert meta["training"]["factor"] == 2
    assert meta["training"]["wfov_gsd_m"] == 60.0  # 30 m scenes, 2 x 2 blocks


@pytest.mark.parametrize(
    ("factor", "expected"),
    [("2", "none"), ("1", "warn"), ("4", "warn"), ("8", "refuse")],
)
def test_plan_at_another_resolution_warns_once_and_refuses_beyond_twice(
    threshold_model, tmp_path, capsys, factor, expected
):
    image = threshold_model / "scenes" / "s0.tif"
    out = tmp_path / "p.geojson"
    code, _, err = run(capsys, "plan", image, "--model", threshold_model / "model",
                       "--planner", "lawnmower-transect", "--factor", factor, "--out", out)  # fmt: skip
    gsd = 30 * int(factor)
    said = f"trained at WFOV factor 2, 60 m GSD; this run is at WFOV factor {factor}, {gsd} m GSD"
    if expected == "none":
        assert code == 0 and "trained at" not in err
    elif expected == "warn":
        assert code == 0 and err.count(said) == 1 and "warning:" in err
    else:  # 60 m -> 240 m: 4 times apart
        assert code == 2 and err.count(said) == 1 and "--force" in err
        assert not out.exists()
        code, _, err = run(capsys, "plan", image, "--model", threshold_model / "model", "--force",
                           "--planner", "lawnmower-transect", "--factor", factor, "--out", out)  # fmt: skip
        assert code == 0 and err.count(said) == 1 and out.exists()


def test_a_model_without_training_resolution_is_said_unknown_and_runs(
    threshold_model, tmp_path, capsys
):
    old = _with_training(threshold_model / "model", tmp_path / "old")
    code, _, err = run(capsys, "plan", threshold_model / "scenes" / "s0.tif", "--model", old,
                       "--planner", "lawnmower-transect", "--factor", "8",
                       "--out", tmp_path / "p.geojson")  # fmt: skip
    assert code == 0 and err.count("training resolution unknown") == 1


def test_the_factor_is_compared_when_the_gsd_is_not_recorded(threshold_model, tmp_path, capsys):
    hand = _with_training(threshold_model / "model", tmp_path / "hand", factor=1)
    code, _, err = run(capsys, "plan", threshold_model / "scenes" / "s0.tif", "--model", hand,
                       "--planner", "lawnmower-transect", "--factor", "3",
                       "--out", tmp_path / "p.geojson")  # fmt: skip
    assert code == 2 and "trained at WFOV factor 1; this run is at WFOV factor 3, 90 m GSD" in err


def test_fly_refuses_a_model_trained_four_times_finer(threshold_model, tmp_path, capsys):
    strip = tmp_path / "strip"
    assert main(["synth", "--strip", "--scenes", "1", "--size", "32", "--length", "96",
                 "--out", str(strip), "--quiet"]) == 0  # fmt: skip
    fine = _with_training(threshold_model / "model", tmp_path / "fine", factor=1, wfov_gsd_m=2.0)
    scene = next(p for p in strip.glob("*.tif") if not p.stem.endswith("_mask"))
    capsys.readouterr()
    code, _, err = run(capsys, "fly", "--scene", scene, "--model", fine, "--factor", "1",
                       "--out", tmp_path / "out", "--compute-budget-s", "0.5", "--quiet")  # fmt: skip
    # the strip is 8 m per pixel: 8 m against 2 m
    assert (
        code == 2
        and "trained at WFOV factor 1, 2 m GSD; this run is at WFOV factor 1, 8 m GSD" in err
    )
    assert not (tmp_path / "out").exists()


def test_plan_on_a_scene_across_180_writes_split_polygons_and_path(tmp_path, capsys):
    import shapely

    pyproj = pytest.importorskip("pyproj")
    # a 48 px, 30 m scene centred on 180°E at 52°N (the Aleutians), in UTM 60N
    x, y = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32660", always_xy=True).transform(
        180.0, 52.0
    )
    transform = Affine(30.0, 0.0, x - 24 * 30.0, 0.0, -30.0, y + 24 * 30.0)
    image, mask = _scene(tmp_path, "EPSG:32660", transform)
    out, polygons = tmp_path / "t.geojson", tmp_path / "p.geojson"
    _plan(capsys, image, mask, out, "--polygons", polygons, "--step", "3")
    for path, kind in ((polygons, "MultiPolygon"), (out, "MultiLineString")):
        doc = json.loads(path.read_text())
        west, _, east, _ = doc["bbox"]
        assert 179.9 < west <= 180.0 and -180.0 <= east < -179.9  # west > east across 180°
        _, _, wkb, _ = pyogrio.raw.read(path, where="kind <> 'pointing'")
        assert shapely.from_wkb(wkb[0]).geom_type == kind
