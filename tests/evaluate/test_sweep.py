"""Sweeps on a dask LocalCluster (loopback): resumable after a kill, identical results, no duplicates."""

from __future__ import annotations

import csv
import subprocess
import sys
import time

import pytest

from dyntarget import InvalidParameterError
from dyntarget.cli import main
from dyntarget.evaluate.options import RunOptions
from dyntarget.evaluate.sweep import SweepInterrupted, expand, parse_grid, summary_figure, sweep
from helpers import synth_dir

# distributed leaves a listening socket to the garbage collector at cluster teardown (its own
# internals, not ours); with warnings as errors that would fail unrelated tests.
pytestmark = [
    pytest.mark.filterwarnings("ignore::ResourceWarning"),
    pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning"),
]

METRIC_COLUMNS = (
    "task",
    "scene",
    "classifier",
    "planner",
    "step_fraction",
    "denoise_iterations",
    "pixels_observed",
    "ratio_plume",
    "intensity",
    "gradient",
    "pointings",
)


def _rows(path):
    with open(path) as fh:
        return [{k: r[k] for k in METRIC_COLUMNS} for r in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def data38(tmp_path_factory):
    return synth_dir(tmp_path_factory, "sweep-data38", scenes=38, size=64, seed=4)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return synth_dir(tmp_path_factory, "sweep-data", scenes=6, size=64, seed=2)


def test_parse_and_expand_grid():
    grid = parse_grid(["step_fraction=0.01,0.02", "denoise-iterations=0,1"])
    assert grid == {"step_fraction": [0.01, 0.02], "denoise_iterations": [0, 1]}
    points = expand(grid)
    assert len(points) == 4 and all(
        p["factor"] == 4 and p["min_area_fraction"] == 0.01 for p in points
    )
    with pytest.raises(InvalidParameterError, match="NAME one of"):
        parse_grid(["speed=1"])
    with pytest.raises(InvalidParameterError, match="not a int"):
        parse_grid(["factor=two"])


KW38 = dict(classifiers=["band-threshold", "decision-tree", "naive-bayes"], folds=2)


def _run(cluster, **kw):
    return RunOptions(scheduler=cluster, progress=False, **kw)


@pytest.fixture(scope="module")
def ref38(data38, cluster, tmp_path_factory):
    """The uninterrupted sweep of 38 scenes x 3 classifiers x 6 planners."""
    rows = _rows(sweep(data38, tmp_path_factory.mktemp("ref"), options=_run(cluster), **KW38))
    assert len(rows) == 38 * 3 * 6  # scenes x classifiers x planners
    return rows


def _parts(out):
    return [p for p in (out / "parts").glob("*.json") if not p.name.startswith(".")]


@pytest.mark.slow
def test_killed_sweep_resumes_with_identical_results(data38, ref38, cluster, tmp_path):
    """38 scenes x 3 classifiers x 6 planners on a 2-worker LocalCluster, stopped halfway."""
    out = tmp_path / "resumed"
    with pytest.raises(SweepInterrupted):
        sweep(data38, out, stop_after=57, options=_run(cluster), **KW38)
    finished = _parts(out)
    assert 57 <= len(finished) < 114 and not (out / "sweep.csv").exists()
    mtimes = {p.name: p.stat().st_mtime_ns for p in finished}
    table = sweep(data38, out, options=_run(cluster, models_dir=out / "models"), **KW38)
    rows = _rows(table)
    assert rows == ref38  # identical, in the same order
    keys = [(r["task"], r["planner"]) for r in rows]
    assert len(keys) == len(set(keys))  # no duplicated rows
    # finished tasks were not redone
    assert all((out / "parts" / n).stat().st_mtime_ns == t for n, t in mtimes.items())


@pytest.mark.slow
def test_sweep_process_killed_with_sigkill_resumes(data38, ref38, cluster, tmp_path):
    """The real thing: the sweep command's process is killed (SIGKILL) mid-run, then rerun."""
    out = tmp_path / "killed"
    command = [
        sys.executable, "-m", "dyntarget.cli", "sweep", "--data", str(data38), "--out", str(out),
        "--classifiers", ",".join(KW38["classifiers"]), "--folds", "2",
        "--scheduler", cluster, "--quiet",
    ]  # fmt: skip
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    give_up = time.monotonic() + 180
    try:
        while proc.poll() is None and time.monotonic() < give_up:
            if (out / "parts").is_dir() and len(_parts(out)) >= 20:
                break
            time.sleep(0.02)
    finally:
        proc.kill()
        proc.wait()
    assert 20 <= len(_parts(out)) < 114 and not (out / "sweep.csv").exists()
    rows = _rows(sweep(data38, out, options=_run(cluster), **KW38))
    assert rows == ref38
    assert len({(r["task"], r["planner"]) for r in rows}) == len(rows)


def test_sweep_grid_points(data, cluster, tmp_path):
    table = sweep(
        data,
        tmp_path / "g",
        classifiers=["band-threshold"],
        planners=["track-center", "lawnmower-transect"],
        grid={"step_fraction": [0.01, 0.03], "denoise_iterations": [0, 1]},
        folds=2,
        options=_run(cluster),
    )
    rows = _rows(table)
    assert len(rows) == 6 * 4 * 2
    assert {(r["step_fraction"], r["denoise_iterations"]) for r in rows} == {
        ("0.01", "0"), ("0.01", "1"), ("0.03", "0"), ("0.03", "1")
    }  # fmt: skip
    # a coarser step gives fewer pointings on the same masks
    by = {}
    for r in rows:
        if r["planner"] == "lawnmower-transect" and r["denoise_iterations"] == "1":
            by.setdefault(r["scene"], {})[r["step_fraction"]] = int(r["pointings"])
    assert all(v["0.03"] <= v["0.01"] for v in by.values())


def test_sweep_cli_local_scheduler(data, tmp_path, capsys):
    code = main(
        [
            "sweep",
            "--data",
            str(data),
            "--out",
            str(tmp_path / "s"),
            "--classifiers",
            "band-threshold",
            "--planners",
            "track-center,straight-nadir",
            "--grid",
            "denoise_iterations=0,2",
            "--folds",
            "2",
            "--scheduler",
            "local",
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert len(_rows(tmp_path / "s" / "sweep.csv")) == 6 * 2 * 2
    assert (tmp_path / "s" / "sweep.png").read_bytes()[:4] == b"\x89PNG"


def test_bad_scheduler(data, tmp_path, capsys):
    code = main(
        [
            "sweep",
            "--data",
            str(data),
            "--out",
            str(tmp_path / "s"),
            "--classifiers",
            "band-threshold",
            "--folds",
            "2",
            "--scheduler",
            "somewhere",
            "--quiet",
        ]
    )
    assert (
        code == 2
        and "scheduler: expected local, processes or a scheduler address" in capsys.readouterr().err
    )


@pytest.mark.slow
def test_sweep_over_agility_presets(data, cluster, tmp_path):
    table = sweep(
        data,
        tmp_path / "a",
        classifiers=["band-threshold"],
        planners=["lawnmower-transect", "track-center"],
        grid=parse_grid(["agility=unlimited,slow"]),
        folds=2,
        options=_run(cluster),
    )
    with open(table) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 * 2 * 2
    by = {(r["scene"], r["planner"], r["agility"]): r for r in rows}
    for (scene, planner, agility), r in by.items():
        if agility == "unlimited":
            assert float(r["feasible_fraction"]) == 1.0  # the paper's assumption: all taken
        else:  # a slow sensor never takes more than the plan holds
            assert int(r["pointings"]) <= int(by[(scene, planner, "unlimited")]["pointings"])
    figure = summary_figure(table, tmp_path / "a.png")  # a categorical axis
    assert figure.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(InvalidParameterError, match="unknown preset"):
        parse_grid(["agility=nimble"])
