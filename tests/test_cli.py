from __future__ import annotations

import importlib.util

import pytest
import rasterio

from dyntarget.cli import main


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_synth_writes_76_files_byte_identical(tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    for d in (a, b):
        code, _, err = run(
            capsys, "synth", "--scenes", 38, "--size", 32, "--seed", 0, "--out", d, "--quiet"
        )
        assert code == 0, err
    files = sorted(p.name for p in a.iterdir() if p.name != ".dyntarget-output")  # the marker
    assert len(files) == 76
    for name in files:
        assert (a / name).read_bytes() == (b / name).read_bytes()
        with rasterio.open(a / name) as src:
            assert src.count in (1, 4)


@pytest.mark.slow
def test_demo_writes_picture(tmp_path, capsys):
    code, out, err = run(capsys, "demo", "--out", tmp_path, "--scenes", 3, "--size", 48, "--quiet")
    assert code == 0, err
    assert (tmp_path / "scenes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "scenes.png" in out
    if importlib.util.find_spec("plotly") is not None:  # the interactive view beside report.md
        assert (tmp_path / "view.html").read_text().startswith("<!doctype html>")
        assert "[view.html](view.html)" in (tmp_path / "report.md").read_text()


def test_bad_argument_exit_2_no_traceback(tmp_path, capsys):
    code, _, err = run(capsys, "synth", "--scenes", 0, "--out", tmp_path)
    assert code == 2
    assert "positive integer" in err and "Traceback" not in err


def test_library_error_exit_2_one_line(tmp_path, capsys):
    args = ("synth", "--strip", "--scenes", 1, "--size", 16, "--out", tmp_path, "--quiet")
    code, _, err = run(capsys, *args)
    assert code == 2
    assert err.strip().splitlines() == [
        "dyntarget: error: width: expected an integer >= 32, got 16"
    ]


def test_option_error_exit_2_one_line_naming_the_option(tmp_path, capsys):
    code, _, err = run(capsys, "synth", "--scenes", 1, "--gsd", "nan", "--out", tmp_path)
    assert code == 2
    assert err.strip().splitlines() == [
        "dyntarget: error: argument --gsd: expected metres in (0, 10000] (a finite number), "
        "got 'nan' (see 'dyntarget synth --help')"
    ]


def test_classifiers_lists_eight(capsys):
    code, out, _ = run(capsys, "classifiers")
    assert code == 0
    names = [line.split()[0] for line in out.strip().splitlines()]
    assert names[0] == "band-threshold" and len(names) == 8 and "unet-xception" in names


def _tiny_dir(tmp_path, capsys, n=4):
    d = tmp_path / "scenes"
    assert run(capsys, "synth", "--scenes", n, "--size", 32, "--out", d, "--quiet")[0] == 0
    return d


def test_train_writes_model(tmp_path, capsys):
    d = _tiny_dir(tmp_path, capsys, n=2)
    code, out, err = run(
        capsys,
        "train",
        "--data",
        d,
        "--classifier",
        "naive-bayes",
        "--out",
        tmp_path / "nb",
        "--factor",
        2,
    )
    assert code == 0, err
    assert (tmp_path / "nb" / "metadata.json").exists() and "nb" in out


def test_train_unknown_classifier(tmp_path, capsys):
    d = _tiny_dir(tmp_path, capsys, n=1)
    code, _, err = run(capsys, "train", "--data", d, "--classifier", "svm", "--out", tmp_path / "m")
    assert code == 2 and "unknown classifier 'svm'; expected one of: band-threshold" in err
    assert not (tmp_path / "m").exists()


def test_train_missing_data(tmp_path, capsys):
    code, _, err = run(
        capsys, "train", "--data", tmp_path / "nope", "--classifier", "mlp", "--out", tmp_path / "m"
    )
    assert code == 2 and "not a directory" in err


def test_evaluate_classification_writes_table1(tmp_path, capsys):
    d = _tiny_dir(tmp_path, capsys, n=4)
    out_dir = tmp_path / "t1"
    code, out, err = run(
        capsys,
        "evaluate",
        "classification",
        "--data",
        d,
        "--folds",
        2,
        "--out",
        out_dir,
        "--classifiers",
        "band-threshold,logistic-regression",
        "--factor",
        2,
        "--quiet",
    )
    assert code == 0, err
    assert "| Band Threshold |" in out and "| + Denoising |" in out
    assert sorted(p.name for p in out_dir.iterdir()) == [
        ".dyntarget-output",  # marks the folder as dyntarget's (docs/reliability.md)
        "parts",  # finished tasks, for resuming
        "table1_classification.csv",
        "table1_classification.json",
        "table1_classification.md",
        "table1_classification.timing.json",
    ]


def test_planners_lists_the_paper_six_then_ours(capsys):
    code, out, _ = run(capsys, "planners")
    assert code == 0
    lines = out.strip().splitlines()
    assert len(lines) == 8 and lines[0].startswith("trace-outline")
    assert sum("(baseline)" in line for line in lines) == 2
    assert [ln.split()[0] for ln in lines[6:]] == ["track-centerline", "utility-max"]


def test_plan_with_mask_writes_rfc7946_geojson_and_figure(tmp_path, capsys):
    import json

    d = _tiny_dir(tmp_path, capsys, n=1)
    image = d / "synth-0000-0000.tif"
    code, _, err = run(
        capsys,
        "plan",
        image,
        "--mask",
        d / "synth-0000-0000_mask.tif",
        "--planner",
        "trace-outline",
        "--out",
        tmp_path / "t.geojson",
        "--figure",
        tmp_path / "t.png",
    )
    assert code == 0, err
    doc = json.loads((tmp_path / "t.geojson").read_text())
    assert "crs" not in doc  # RFC 7946: WGS 84 lon/lat, no crs member
    lon, lat = doc["features"][-1]["geometry"]["coordinates"]
    assert -156 < lon < -155 and 19 < lat < 20  # the synthetic scenes lie near Kilauea
    assert (tmp_path / "t.png").read_bytes()[:4] == b"\x89PNG"


def test_plan_with_model(tmp_path, capsys):
    d = _tiny_dir(tmp_path, capsys, n=2)
    assert (
        run(
            capsys, "train", "--data", d, "--classifier", "decision-tree", "--out", tmp_path / "dt"
        )[0]
        == 0
    )
    code, _, err = run(
        capsys,
        "plan",
        d / "synth-0000-0001.tif",
        "--model",
        tmp_path / "dt",
        "--planner",
        "lawnmower-transect",
        "--factor",
        "4",  # the model's: train's default
        "--out",
        tmp_path / "t.csv",
    )
    assert code == 0, err
    assert (tmp_path / "t.csv").read_text().startswith("order,x,y,part,lon,lat")


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--classifier", "mlp"], "needs --model PATH"),
        ([], "give --mask MASK or --model PATH"),
        (["--mask", "MISSING.tif"], "no such file"),
    ],
)
def test_plan_input_errors(tmp_path, capsys, extra, message):
    d = _tiny_dir(tmp_path, capsys, n=1)
    extra = [str(tmp_path / e) if e.endswith(".tif") else e for e in extra]
    code, _, err = run(
        capsys,
        "plan",
        d / "synth-0000-0000.tif",
        "--planner",
        "track-center",
        "--out",
        tmp_path / "t.geojson",
        *extra,
    )
    assert code == 2 and message in err and "Traceback" not in err
    assert not (tmp_path / "t.geojson").exists()


def test_evaluate_planning(tmp_path, capsys):
    d = _tiny_dir(tmp_path, capsys, n=2)
    code, out, err = run(
        capsys,
        "evaluate",
        "planning",
        "--data",
        d,
        "--out",
        tmp_path / "p",
        "--factor",
        2,
        "--quiet",
    )
    assert code == 0, err
    assert "| Straight Nadir |" in out and (tmp_path / "p" / "planning_true_masks.csv").exists()
