"""Hostile input that used to get exit 1 or a silently wrong answer (issue 20, items 4-15).

Each test states the issue item it covers. Expected values are worked out by
hand from the fixtures (pixel shifts, counts, scales).
"""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest
import rasterio
from affine import Affine

from dyntarget import Scene
from dyntarget.cli import main
from dyntarget.errors import DataFileError, InvalidParameterError, InvalidSceneError
from dyntarget.evaluate.distributed import run_tasks
from dyntarget.io import read_scene, read_scene_dir, write_scene
from dyntarget.io.sensors import parse_bands
from helpers import write_raw_tif

UTM = "EPSG:32605"
GRID = Affine(10.0, 0.0, 250000.0, 0.0, -10.0, 2150000.0)


def _run(capsys, *args):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return code, captured.err


def _image(path, h=16, w=16, crs=UTM, transform=GRID, bands=4, dtype="float32"):
    rng = np.random.default_rng(1)
    data = rng.uniform(0.05, 0.6, (bands, h, w)).astype(dtype)
    profile = {"crs": crs, "transform": transform} if crs else {}
    return write_raw_tif(path, data, **profile)


def _mask(path, mask, crs=UTM, transform=GRID):
    profile = {"crs": crs, "transform": transform} if crs else {}
    return write_raw_tif(path, mask[None].astype(np.uint8), **profile)


# ---------------------------------------------------------------- item 4: --bands


@pytest.mark.parametrize("text", [",,,", "3,2,1,", ",2,3,4", "1,2, ,4"])
def test_empty_band_selector_refused_even_when_bands_have_no_names(text):
    with pytest.raises(InvalidParameterError, match="is empty"):
        parse_bands(text, names=["", "", "", "", ""])  # files without band descriptions


@pytest.mark.parametrize("text", ["1,1,2,3", "B4,B3,B4,B8"])
def test_repeated_band_selector_refused(text):
    with pytest.raises(InvalidParameterError, match="selected twice"):
        parse_bands(text, names=[f"B{i}" for i in range(1, 9)])


def test_cli_bands_commas_only_exits_2(tmp_path, capsys):
    img = _image(tmp_path / "five.tif", bands=5)
    mask = _mask(tmp_path / "m.tif", np.ones((16, 16), bool))
    code, err = _run(
        capsys, "plan", img, "--bands", ",,,", "--mask", mask, "--planner", "trace-outline",
        "--out", tmp_path / "t.csv",
    )  # fmt: skip
    assert code == 2 and "bands: selector 1 of ',,,' is empty" in err
    assert not (tmp_path / "t.csv").exists()


# ---------------------------------------------------------------- item 5: mask georeference


def test_mask_on_a_shifted_grid_is_reprojected_onto_the_image(tmp_path):
    img = _image(tmp_path / "img.tif")
    mask = np.zeros((16, 16), bool)
    mask[4:10, 2:6] = True
    # the mask's grid starts 3 px east and 2 px south of the image's (10 m pixels)
    shifted = Affine(10.0, 0.0, 250030.0, 0.0, -10.0, 2149980.0)
    lab = _mask(tmp_path / "m.tif", mask, transform=shifted)
    expected = np.zeros((16, 16), bool)
    expected[6:12, 5:9] = True  # by hand: rows + 2, columns + 3
    got = read_scene(img, label=lab).label
    assert np.array_equal(got, expected)


def test_mask_in_another_crs_is_reprojected(tmp_path):
    img = _image(tmp_path / "img.tif")
    # an all-plume mask in WGS 84 covering the image with a margin: every pixel is plume;
    # the same mask in the other half of the globe would cover none
    from rasterio.warp import transform_bounds

    w, s, e, n = transform_bounds(UTM, "EPSG:4326", 250000.0, 2149840.0, 250160.0, 2150000.0)
    pad = 0.01
    wgs = Affine((e - w + 2 * pad) / 8, 0, w - pad, 0, -(n - s + 2 * pad) / 8, n + pad)
    lab = _mask(tmp_path / "m.tif", np.ones((8, 8), bool), crs="EPSG:4326", transform=wgs)
    assert read_scene(img, label=lab).label.all()


def test_mask_not_overlapping_the_image_is_refused(tmp_path, capsys):
    img = _image(tmp_path / "img.tif")
    far = Affine(10.0, 0.0, 260000.0, 0.0, -10.0, 2150000.0)  # 10 km east
    lab = _mask(tmp_path / "m.tif", np.ones((16, 16), bool), transform=far)
    with pytest.raises(InvalidSceneError, match="does not overlap the image"):
        read_scene(img, label=lab)
    code, err = _run(
        capsys, "plan", img, "--mask", lab, "--planner", "trace-outline", "--out",
        tmp_path / "t.csv",
    )  # fmt: skip
    assert code == 2 and "does not overlap" in err


def test_mask_on_a_shifted_grid_read_in_strips_matches(tmp_path):
    img = _image(tmp_path / "img.tif")
    mask = np.zeros((16, 16), bool)
    mask[4:10, 2:6] = True
    shifted = Affine(10.0, 0.0, 250030.0, 0.0, -10.0, 2149980.0)
    lab = _mask(tmp_path / "m.tif", mask, transform=shifted)
    whole = read_scene(img, label=lab)
    strips = read_scene(img, label=lab, factor=2)
    assert np.array_equal(strips.label, whole.to_wfov(2).label)


# ---------------------------------------------------------------- item 6: GeoJSON crs, nesting


def _polygon_doc(**extra):
    ring = [[250020.0, 2149980.0], [250100.0, 2149980.0], [250100.0, 2149900.0]]
    ring += [[250020.0, 2149900.0], [250020.0, 2149980.0]]
    return {"type": "Polygon", "coordinates": [ring], **extra}


@pytest.mark.parametrize(
    ("doc", "fragment"),
    [
        (_polygon_doc(crs={"type": "name", "properties": {"name": "EPSG:999999"}}), "unknown CRS"),
        (_polygon_doc(crs={"type": "name", "properties": "EPSG:4326"}), "malformed 'crs'"),
        (_polygon_doc(crs="EPSG:4326"), "malformed 'crs'"),
        (_polygon_doc(crs={"type": "name", "properties": {"name": ["EPSG:4326"]}}), "malformed"),
    ],
    ids=["unknown code", "properties not an object", "crs a string", "name a list"],
)
def test_geojson_bad_crs_member_exits_2(tmp_path, capsys, doc, fragment):
    img = _image(tmp_path / "img.tif")
    lab = tmp_path / "label.geojson"
    lab.write_text(json.dumps(doc))
    with pytest.raises(DataFileError, match=fragment):
        read_scene(img, label=lab)
    code, err = _run(
        capsys, "plan", img, "--mask", lab, "--planner", "trace-outline", "--out",
        tmp_path / "t.csv",
    )  # fmt: skip
    assert code == 2 and fragment in err and len(err.strip().splitlines()) == 1


def test_geojson_nested_100000_levels_exits_2(tmp_path, capsys):
    img = _image(tmp_path / "img.tif")
    lab = tmp_path / "deep.geojson"
    lab.write_text('{"type": "Polygon", "coordinates": ' + "[" * 100_000 + "]" * 100_000 + "}")
    code, err = _run(
        capsys, "plan", img, "--mask", lab, "--planner", "trace-outline", "--out",
        tmp_path / "t.csv",
    )  # fmt: skip
    assert code == 2 and "nested too deeply" in err


def test_geojson_nan_vertex_refused(tmp_path):
    img = _image(tmp_path / "img.tif")
    doc = _polygon_doc()
    doc["coordinates"][0][1][0] = float("nan")
    lab = tmp_path / "nan.geojson"
    lab.write_text(json.dumps(doc))
    with pytest.raises(DataFileError, match="NaN or infinite vertex"):
        read_scene(img, label=lab)


# ---------------------------------------------------------------- item 8: synth / bench


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (
            ["synth", "--seed", "-5", "--scenes", "1", "--size", "32"],
            "seed: expected an integer >= 0",
        ),
        (["synth", "--size", "2000000", "--scenes", "1"], "GB of memory"),
        (["bench", "--sizes", "10000000"], "GB of memory"),
        (["bench", "--sizes", "a,b"], "'a' is not an integer"),
        (["bench", "--sizes", ","], "'' is not an integer"),
        (["bench", "--sizes", "64,64"], "listed twice"),
    ],
)
def test_synth_and_bench_parameters_refused_before_allocating(tmp_path, capsys, args, fragment):
    out = tmp_path / ("out.json" if args[0] == "bench" else "scenes")
    code, err = _run(capsys, *args, "--quiet", "--out", out)
    assert code == 2 and fragment in err
    assert not out.exists()


def test_memory_estimate_states_the_numbers():
    from dyntarget.synth.volcano import SYNTH_BYTES_PER_PIXEL, check_memory

    # 2,000,000^2 px x 320 B = 1.28e15 B = 1,280,000 GB (by hand)
    with pytest.raises(InvalidParameterError, match=r"about 1280000\.0 GB"):
        check_memory("size", 2_000_000, bytes_per_pixel=SYNTH_BYTES_PER_PIXEL)


# ---------------------------------------------------------------- item 9: duplicate classifiers


def test_duplicate_classifiers_refused(tmp_path, capsys):
    d = tmp_path / "data"
    rng = np.random.default_rng(0)
    for i in range(2):
        image = rng.uniform(0.05, 0.6, (4, 16, 16)).astype(np.float32)
        write_scene(Scene(image, label=np.eye(16, dtype=bool), id=f"s{i}"), d)
    code, err = _run(
        capsys, "evaluate", "classification", "--data", d, "--folds", "2", "--factor", "1",
        "--classifiers", "naive-bayes,naive-bayes", "--quiet", "--out", tmp_path / "out",
    )  # fmt: skip
    assert code == 2 and "'naive-bayes' is listed twice" in err
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- item 11: a huge header


@pytest.mark.slow
def test_header_claiming_200000_squared_refused_up_front(tmp_path):
    path = tmp_path / "huge.tif"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(
            path, "w", driver="GTiff", width=200_000, height=200_000, count=4,
            dtype="uint16", tiled=True, compress="deflate", sparse_ok=True,
        ):  # fmt: skip
            pass  # nothing written: a small file whose header claims 4e10 px
    assert path.stat().st_size < 50_000_000
    for factor in ("1", "64"):
        proc = subprocess.run(
            [
                sys.executable, "-m", "dyntarget", "plan", str(path), "--factor", factor,
                "--mask", str(path), "--planner", "trace-outline", "--out",
                str(tmp_path / "t.csv"),
            ],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert proc.returncode == 2, proc.stderr[-400:]
        assert "65536 x 65536" in proc.stderr
        assert "--factor" not in proc.stderr  # no suggestion of a flag that then hangs


# ---------------------------------------------------------------- item 12: resume parts

CALLS: list[int] = []


def _double(x: int) -> dict:
    CALLS.append(x)
    return {"x": x, "count": 2 * x}


@pytest.mark.parametrize(
    "content",
    ["{}", "[]", '{"x": 2, "count": "4"}', '{"x": 2, "count": NaN}', "null", '"text"', "DIR"],
)
def test_part_with_wrong_structure_is_run_again(tmp_path, content):
    run_tasks(_double, [1, 2, 3], key=str, parts=tmp_path, progress=False)
    part = tmp_path / "2.json"
    part.unlink()
    if content == "DIR":
        part.mkdir()  # a directory where the part belongs
    else:
        part.write_text(content)
    CALLS.clear()
    results = run_tasks(_double, [1, 2, 3], key=str, parts=tmp_path, progress=False)
    assert results == [{"x": 1, "count": 2}, {"x": 2, "count": 4}, {"x": 3, "count": 6}]
    assert CALLS == [2]  # only the bad part's task ran again
    assert part.is_file()


def test_part_of_the_right_shape_but_edited_is_run_again(tmp_path):
    run_tasks(_double, [5], key=str, parts=tmp_path, progress=False)
    doc = json.loads((tmp_path / "5.json").read_text())
    doc["result"]["count"] = 11  # a plausible but wrong count: the checksum no longer matches
    (tmp_path / "5.json").write_text(json.dumps(doc))
    CALLS.clear()
    assert run_tasks(_double, [5], key=str, parts=tmp_path, progress=False) == [
        {"x": 5, "count": 10}
    ]
    assert CALLS == [5]


def test_part_folder_holding_files_is_refused(tmp_path):
    (tmp_path / "7.json").mkdir()
    (tmp_path / "7.json" / "keep.txt").write_text("user data")
    with pytest.raises(DataFileError, match="a directory holding files"):
        run_tasks(_double, [7], key=str, parts=tmp_path, progress=False)
    assert (tmp_path / "7.json" / "keep.txt").read_text() == "user data"


# ---------------------------------------------------------------- item 13: sweep grid


@pytest.mark.parametrize(
    ("grid", "fragment"),
    [
        (["step_fraction=-1"], "step_fraction=-1.0 is out of range"),
        (["factor=2", "factor=4"], "factor is given twice"),
        (["factor=0"], "factor=0 is out of range"),
        (["min_area_fraction=nan"], "is not a finite float"),
        (["denoise_iterations=2,2"], "lists a value twice"),
    ],
)
def test_sweep_grid_validated_before_any_work(tmp_path, capsys, grid, fragment):
    d = tmp_path / "data"
    rng = np.random.default_rng(0)
    for i in range(2):
        image = rng.uniform(0.05, 0.6, (4, 16, 16)).astype(np.float32)
        write_scene(Scene(image, label=np.eye(16, dtype=bool), id=f"s{i}"), d)
    out = tmp_path / "out"
    code, err = _run(
        capsys, "sweep", "--data", d, "--classifiers", "naive-bayes", "--folds", "2",
        "--quiet", "--out", out, "--grid", *grid,
    )  # fmt: skip
    assert code == 2 and fragment in err
    assert not out.exists()  # no model trained, nothing left behind


# ---------------------------------------------------------------- item 14: datasets prepare


def _smoke_source(tmp_path, names, nan_label=False):
    """An extracted Industrial Smoke Plumes layout with one positive image per name."""
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent / "datasets"))
    from test_industrial_smoke import _s2_tif

    src = tmp_path / "download"
    (src / "images" / "positive").mkdir(parents=True)
    (src / "segmentation_labels").mkdir(parents=True)
    for i, name in enumerate(names):
        (src / "images" / "positive" / f"{name}.tif").write_bytes(_s2_tif(i, size=40))
        points = [[10, 10], [50, 10], [50, 50], [10, 50]]
        if nan_label and i == len(names) - 1:
            points[2][0] = float("nan")
        label = {
            "data": {"image": f"/data/upload/{i}-{name}.png"},
            "completions": [{"result": [{"value": {"points": points}}]}],
        }
        (src / "segmentation_labels" / f"{i}.json").write_text(json.dumps(label))
    return src


def test_prepare_ids_unique_visible_and_count_true(tmp_path, capsys):
    names = [
        "site_2019-05-09T10:26:31", "site_2019-05-09T10-26-31", ".hidden", "...", "a_mask",
        "plain",
    ]  # fmt: skip
    src = _smoke_source(tmp_path, names)
    out = tmp_path / "scenes"
    code, err = _run(
        capsys, "datasets", "prepare", "industrial-smoke", "--from", src, "--out", out, "--quiet"
    )
    assert code == 0, err
    scenes = read_scene_dir(out, require_labels=True)
    assert len(scenes) == len(names) == 6  # every image is a readable scene
    assert f"wrote {len(names)} scenes" in err
    assert all(not s.id.startswith(".") for s in scenes)


def test_prepare_nan_label_vertex_refused_before_writing(tmp_path, capsys):
    src = _smoke_source(tmp_path, ["a", "b", "c"], nan_label=True)
    out = tmp_path / "scenes"
    code, err = _run(
        capsys, "datasets", "prepare", "industrial-smoke", "--from", src, "--out", out, "--quiet"
    )
    assert code == 2 and "NaN or infinite vertex" in err
    assert not out.exists()  # nothing written


# ---------------------------------------------------------------- item 15: uint8, --budget-s


def test_uint8_image_scaled_by_255(tmp_path):
    data = np.zeros((4, 8, 8), np.uint8)
    data[:, :4] = 51  # 51 / 255 = 0.2
    data[:, 4:] = 204  # 0.8
    path = write_raw_tif(tmp_path / "u8.tif", data)
    image = read_scene(path).image
    assert np.allclose(image[:, :4], 0.2) and np.allclose(image[:, 4:], 0.8)  # rows


def test_uint16_still_scaled_by_10000(tmp_path):
    data = np.full((4, 8, 8), 2500, np.uint16)
    data[:, 0] = 5000
    image = read_scene(write_raw_tif(tmp_path / "u16.tif", data)).image
    assert np.isclose(image.min(), 0.25) and np.isclose(image.max(), 0.5)


def test_budget_without_agility_refused(tmp_path, capsys):
    img = _image(tmp_path / "img.tif")
    mask = _mask(tmp_path / "m.tif", np.ones((16, 16), bool))
    code, err = _run(
        capsys, "plan", img, "--mask", mask, "--planner", "trace-outline", "--budget-s", "30",
        "--out", tmp_path / "t.csv",
    )  # fmt: skip
    assert code == 2 and "--budget-s 30" in err and "--agility" in err
    assert not (tmp_path / "t.csv").exists()
