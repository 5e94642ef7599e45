"""The output-path rule (issue 20, items 2, 10 and the tcp leftover of 15).

A path the user gave is never moved, replaced or deleted unless dyntarget wrote
it; anything else gets exit 2 and stays byte for byte as it was, checked before
any work. ``plan`` checks all of its outputs before writing any.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from dyntarget import Scene
from dyntarget.cli import main
from dyntarget.io import write_scene
from dyntarget.io.outputs import MARKER, OutputPathError, check_output_file, is_ours

USER_BYTES = b"my thesis, the only copy\n"


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Three labelled 32x32 scenes (a scene directory)."""
    d = tmp_path_factory.mktemp("data")
    rng = np.random.default_rng(0)
    for i in range(3):
        image = rng.uniform(0.05, 0.3, (4, 32, 32)).astype(np.float32)
        label = np.zeros((32, 32), bool)
        label[8 + i : 20, 6:22] = True
        image[:, label] += 0.4
        write_scene(Scene(image, label=label, id=f"s{i}"), d)
    return d


def _user_file(path):
    path.write_bytes(USER_BYTES)
    return path


def _snapshot(root):
    """Every path under ``root`` with its bytes (None for folders)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames:
            out[os.path.join(dirpath, name)] = None
        for name in filenames:
            p = os.path.join(dirpath, name)
            with open(p, "rb") as fh:
                out[p] = fh.read()
    return out


def _run(capsys, *args):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.err


def test_train_out_existing_file_is_refused_and_untouched(tmp_path, data, capsys):
    target = _user_file(tmp_path / "thesis.txt")
    before = _snapshot(tmp_path)
    code, err = _run(
        capsys, "train", "--data", data, "--classifier", "naive-bayes", "--out", target
    )
    assert code == 2, err
    assert "thesis.txt: an existing file, not written by dyntarget" in err
    assert _snapshot(tmp_path) == before  # no hidden .old-PID copy, nothing new
    assert len(err.strip().splitlines()) == 1


def test_train_out_foreign_directory_refused(tmp_path, data, capsys):
    folder = tmp_path / "photos"
    folder.mkdir()
    _user_file(folder / "a.jpg")
    before = _snapshot(tmp_path)
    code, err = _run(
        capsys, "train", "--data", data, "--classifier", "naive-bayes", "--out", folder
    )
    assert code == 2 and "a directory holding other files" in err
    assert _snapshot(tmp_path) == before


def test_train_out_replaces_our_own_model_directory(tmp_path, data, capsys):
    out = tmp_path / "model"
    for _ in range(2):
        code, err = _run(
            capsys, "train", "--data", data, "--classifier", "naive-bayes", "--out", out
        )
        assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["metadata.json", "model.skops"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no leftovers


def test_classifier_save_refuses_a_foreign_file(tmp_path):
    from dyntarget.perceive import make_classifier

    model = make_classifier("band-threshold")
    model.fitted = True
    target = _user_file(tmp_path / "notes.txt")
    with pytest.raises(OutputPathError):
        model.save(target)
    assert target.read_bytes() == USER_BYTES


@pytest.mark.parametrize(
    "command",
    [
        ["synth", "--scenes", "1", "--size", "32", "--quiet"],
        ["evaluate", "planning", "--data", "{data}", "--factor", "2", "--quiet"],
        ["evaluate", "classification", "--data", "{data}", "--folds", "2", "--quiet"],
        ["reproduce", "--data", "{data}", "--folds", "2", "--quiet"],
        ["sweep", "--data", "{data}", "--classifiers", "band-threshold", "--folds", "2"],
        ["datasets", "prepare", "industrial-smoke", "--from", "{data}"],
    ],
    ids=["synth", "evaluate-planning", "evaluate-classification", "reproduce", "sweep", "prepare"],
)
@pytest.mark.parametrize("taken_by", ["file", "foreign-folder"])
def test_writing_commands_refuse_foreign_out_before_work(tmp_path, data, capsys, command, taken_by):
    if taken_by == "file":
        out = _user_file(tmp_path / "out")
    else:
        out = tmp_path / "out"
        out.mkdir()
        _user_file(out / "keep.txt")
    before = _snapshot(tmp_path)
    args = [a.replace("{data}", str(data)) for a in command]
    code, err = _run(capsys, *args, "--out", out)
    assert code == 2, err
    assert "not written by dyntarget" in err and "Traceback" not in err
    assert _snapshot(tmp_path) == before


def test_plan_checks_every_output_before_writing_any(tmp_path, data, capsys):
    traj = tmp_path / "t.geojson"
    figure_dir = tmp_path / "fig.png"
    figure_dir.mkdir()  # a folder where the figure should go
    code, err = _run(
        capsys,
        "plan",
        data / "s0.tif",
        "--mask",
        data / "s0_mask.tif",
        "--planner",
        "lawnmower-transect",
        "--out",
        traj,
        "--figure",
        figure_dir,
    )
    assert code == 2 and "--figure" in err and "a directory" in err
    assert not traj.exists()  # nothing written when any output cannot be


def test_plan_refuses_a_foreign_trajectory_file_and_reruns_over_its_own(tmp_path, data, capsys):
    args = ["plan", data / "s0.tif", "--mask", data / "s0_mask.tif", "--planner", "trace-outline"]
    for suffix in (".geojson", ".csv"):
        foreign = _user_file(tmp_path / f"foreign{suffix}")
        code, err = _run(capsys, *args, "--out", foreign)
        assert code == 2 and "an existing file" in err
        assert foreign.read_bytes() == USER_BYTES
        ours = tmp_path / f"ours{suffix}"
        for _ in range(2):  # the second run replaces the first one's file
            code, err = _run(capsys, *args, "--out", ours, "--figure", tmp_path / "f.png")
            assert code == 0, err
        assert is_ours(ours) and is_ours(tmp_path / "f.png")


def test_plan_same_path_for_two_outputs_refused(tmp_path, data, capsys):
    out = tmp_path / "same.png"
    code, err = _run(
        capsys,
        "plan",
        data / "s0.tif",
        "--mask",
        data / "s0_mask.tif",
        "--planner",
        "trace-outline",
        "--out",
        out,
        "--figure",
        out,
    )
    assert code == 2 and "the same path" in err and not out.exists()


def test_evaluate_reruns_into_its_own_folder(tmp_path, data, capsys):
    out = tmp_path / "eval"
    args = ["evaluate", "planning", "--data", data, "--factor", "2", "--quiet", "--out", out]
    for _ in range(2):
        code, err = _run(capsys, *args)
        assert code == 0, err
    assert (out / MARKER).is_file()


@pytest.mark.slow
def test_unreachable_scheduler_leaves_nothing_behind(tmp_path, data, capsys):
    out = tmp_path / "out"
    code, err = _run(
        capsys,
        "evaluate",
        "planning",
        "--data",
        data,
        "--factor",
        "2",
        "--quiet",
        "--scheduler",
        "tcp://127.0.0.1:1",
        "--out",
        out,
    )
    assert code == 2 and "cannot reach" in err
    assert not out.exists()


@pytest.mark.slow
def test_unreachable_scheduler_leaves_no_parts_folder_in_an_existing_output(tmp_path, data, capsys):
    out = tmp_path / "out"
    ok = ["evaluate", "planning", "--data", data, "--factor", "2", "--quiet", "--out", out]
    assert _run(capsys, *ok)[0] == 0
    before = _snapshot(tmp_path)
    code, err = _run(
        capsys,
        "evaluate",
        "classification",
        "--data",
        data,
        "--folds",
        "2",
        "--classifiers",
        "band-threshold",
        "--quiet",
        "--scheduler",
        "tcp://127.0.0.1:1",
        "--out",
        out,
    )
    assert code == 2, err
    assert _snapshot(tmp_path) == before  # no empty parts/classification


def test_bench_out_foreign_file_refused_before_work(tmp_path, capsys):
    target = _user_file(tmp_path / "results.json")
    code, err = _run(capsys, "bench", "--sizes", "32", "--repeats", "1", "--out", target)
    assert code == 2 and "an existing file" in err
    assert target.read_bytes() == USER_BYTES


def test_export_onnx_refuses_a_folder_in_place_of_model_onnx(tmp_path, data, capsys):
    model = tmp_path / "model"
    assert (
        _run(capsys, "train", "--data", data, "--classifier", "naive-bayes", "--out", model)[0] == 0
    )
    (model / "model.onnx").mkdir()
    code, err = _run(capsys, "export-onnx", str(model))
    assert code == 2 and "not a regular file" in err
    assert (model / "model.onnx").is_dir()


def test_check_output_file_accepts_empty_and_refuses_symlink_to_foreign(tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_bytes(b"")
    assert check_output_file(empty) == empty  # nothing to lose
    target = _user_file(tmp_path / "target.txt")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    with pytest.raises(OutputPathError):
        check_output_file(link)


def test_committed_bench_outputs_are_recognised_as_ours():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "docs" / "benchmarks"
    for name in ("bench.json", "bench.md"):  # the lead reruns bench over these
        if (root / name).exists():
            assert is_ours(root / name), name


def test_folder_inside_an_output_folder_of_ours_is_ours(tmp_path):
    from dyntarget.io.outputs import check_output_dir, claim_output_dir

    out = claim_output_dir(tmp_path / "demo")
    (out / "models" / "fold-0").mkdir(parents=True)
    (out / "models" / "fold-0" / "x.txt").write_text("written by an earlier run")
    assert check_output_dir(out / "models") == out / "models"
    foreign = tmp_path / "elsewhere"
    foreign.mkdir()
    (foreign / "x.txt").write_text("not ours")
    with pytest.raises(OutputPathError):
        check_output_dir(foreign)
