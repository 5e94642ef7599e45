"""``dyntarget synth --frames`` and ``evaluate dynamic``: layout, determinism, scoring, extension."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from dyntarget.cli import main
from dyntarget.denoise import denoise
from dyntarget.evaluate import dynamic as dyn
from dyntarget.evaluate.dynamic import DynamicConfig, ModeContext, evaluate_dynamic
from dyntarget.evaluate.options import RunOptions
from dyntarget.io import read_sequence_dir
from dyntarget.observe import observe
from dyntarget.plan import PlanConfig, Trajectory, plan
from dyntarget.sequence import FrameSequence
from dyntarget.synth import generate_sequences


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def seq_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("dyn")
    args = ["synth", "--scenes", "4", "--size", "64", "--frames", "2", "--frame-interval-s", "15"]
    assert main([*args, "--seed", "3", "--out", str(d), "--quiet"]) == 0
    return d


def test_synth_frames_layout_and_same_bytes_twice(tmp_path, seq_dir, capsys):
    code, _, err = run(
        capsys, "synth", "--scenes", 4, "--size", 64, "--frames", 2, "--frame-interval-s", 15,
        "--seed", 3, "--out", tmp_path, "--quiet",
    )  # fmt: skip
    assert code == 0, err
    names = sorted(p.name for p in (tmp_path / "dyn-0003-0000").iterdir())
    assert names == ["f000.tif", "f000_mask.tif", "f001.tif", "f001_mask.tif", "sequence.json"]
    for f in sorted(tmp_path.rglob("*")):
        if f.is_file():
            assert f.read_bytes() == (seq_dir / f.relative_to(tmp_path)).read_bytes(), f
    doc = json.loads((tmp_path / "dyn-0003-0000" / "sequence.json").read_text())
    assert [f["time_s"] for f in doc["frames"]] == [0.0, 15.0]
    assert doc["meta"]["world"]["wind"]["speed_mps"] >= 0


def test_synth_wind_options_fix_the_wind(tmp_path, capsys):
    code, _, err = run(
        capsys, "synth", "--scenes", 2, "--size", 32, "--frames", 1, "--wind-mps", 10,
        "--wind-from-deg", 45, "--out", tmp_path, "--quiet",
    )  # fmt: skip
    assert code == 0, err
    for seq in read_sequence_dir(tmp_path):
        assert seq.meta["world"]["wind"] == {"speed_mps": 10.0, "from_deg": 45.0}


def test_synth_without_frames_keeps_the_flat_layout(tmp_path, capsys):
    code, _, _ = run(capsys, "synth", "--scenes", 2, "--size", 32, "--out", tmp_path, "--quiet")
    assert code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        ".dyntarget-output",  # marks the folder as dyntarget's (docs/reliability.md)
        "synth-0000-0000.tif", "synth-0000-0000_mask.tif",
        "synth-0000-0001.tif", "synth-0000-0001_mask.tif",
    ]  # fmt: skip


@pytest.mark.slow
def test_evaluate_dynamic_writes_tidy_csv_and_resumes_identically(tmp_path, seq_dir, capsys):
    argv = [
        "evaluate", "dynamic", "--data", seq_dir, "--out", tmp_path, "--folds", 2,
        "--classifiers", "logistic-regression", "--latencies", "0,60", "--quiet",
    ]  # fmt: skip
    code, out, err = run(capsys, *argv)
    assert code == 0, err
    assert "Trace Outline" in out
    with open(tmp_path / "dynamic.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == dyn.DYNAMIC_COLUMNS
    assert {r["latency_s"] for r in rows} == {"0.0", "60.0"}
    assert {r["classifier"] for r in rows} == {"logistic-regression", "true-mask", "N/A"}
    assert {r["mode"] for r in rows} == {"static"}
    # every (classifier, planner, latency) covers the 4 scenes once over the wind bins
    per = {}
    for r in rows:
        k = (r["classifier"], r["planner"], r["latency_s"])
        per[k] = per.get(k, 0) + int(r["scenes"])
    assert set(per.values()) == {4}
    assert (tmp_path / "dynamic.png").read_bytes()[:4] == b"\x89PNG"
    first = (tmp_path / "dynamic.csv").read_bytes()
    code, _, err = run(capsys, *argv)  # resumed from parts/
    assert code == 0, err
    assert (tmp_path / "dynamic.csv").read_bytes() == first


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--latencies", "0,abc"], "comma-separated seconds"),
        (["--modes", "telepathic"], "unknown mode 'telepathic'"),
        (["--agility", "warp"], "invalid choice"),
    ],
)
def test_evaluate_dynamic_bad_input_exit_2_one_line(tmp_path, seq_dir, capsys, extra, needle):
    code, _, err = run(
        capsys, "evaluate", "dynamic", "--data", seq_dir, "--out", tmp_path, *extra, "--quiet"
    )
    assert code == 2
    assert needle in err and "Traceback" not in err


def test_evaluate_dynamic_on_a_folder_without_sequences_exit_2(tmp_path, capsys):
    code, _, err = run(capsys, "evaluate", "dynamic", "--data", tmp_path, "--out", tmp_path)
    assert code == 2 and "no sequences" in err


def _static_sequences(n=4):
    """Sequences whose truth never changes: the decision frame itself, at every time."""
    out = []
    for seq in generate_sequences(n, size=64, seed=9, frames=1):
        frame = seq.frames[-1]
        out.append(FrameSequence(seq.frames, seq.times, id=seq.id, truth=lambda t, f=frame: f))
    return out


def test_zero_latency_static_plume_equals_todays_observe():
    seqs = _static_sequences()
    config = DynamicConfig(
        folds=2, classifiers=(), latencies=(0.0, 90.0), planners=("track-center", "straight-nadir")
    )
    result = evaluate_dynamic(seqs, config, options=RunOptions(progress=False))
    for seq in seqs:
        wf = seq.frames[-1].to_wfov(config.factor)
        cleaned = denoise(wf.label)
        expected = observe(
            plan("track-center", cleaned.mask, cleaned.polygons, PlanConfig()),
            seq.frames[-1],
            factor=config.factor,
        )
        for lat in (0.0, 90.0):  # a static plume: latency changes nothing either
            (rec,) = [
                r for r in result["records"]
                if r["scene"] == seq.id and r["planner"] == "track-center" and r["latency_s"] == lat
            ]  # fmt: skip
            assert rec["ratio_plume"] == expected.ratio_plume
            assert rec["pixels_observed"] == expected.pixels_observed
            assert rec["intensity"] == expected.intensity


def test_a_new_mode_is_one_dict_entry(monkeypatch):
    seen = []

    def first_pixel_only(ctx: ModeContext) -> Trajectory:
        seen.append((ctx.planner, ctx.latency_s, ctx.mask.shape, len(ctx.frames)))
        return Trajectory(np.zeros((1, 2)), np.zeros(1), ctx.planner)

    monkeypatch.setitem(dyn.MODES, "corner", first_pixel_only)
    monkeypatch.setitem(dyn.MODES, "lazy-static", "dyntarget.evaluate.dynamic:static_mode")
    config = DynamicConfig(
        folds=2, classifiers=(), latencies=(30.0,), planners=("trace-outline",),
        modes=("corner", "lazy-static"),
    )  # fmt: skip
    result = evaluate_dynamic(_static_sequences(), config, options=RunOptions(progress=False))
    assert {r["mode"] for r in result["rows"]} == {"corner", "lazy-static"}
    assert seen and all(s[0] == "trace-outline" and s[1] == 30.0 for s in seen)
    corner = [r for r in result["records"] if r["mode"] == "corner"]
    assert all(r["pixels_observed"] == 1 for r in corner)


def test_wind_bins_from_the_world_spec_or_a_user_prior():
    seq = next(generate_sequences(1, size=32, frames=1, wind_mps=9.5))
    assert dyn.sequence_wind(seq) == 9.5 and dyn.wind_bin(9.5) == "8-12"
    user = FrameSequence(seq.frames, seq.times, id="u", meta={"wind": {"speed_mps": 1.0}})
    assert dyn.wind_bin(dyn.sequence_wind(user)) == "0-2"
    bare = FrameSequence(seq.frames, seq.times, id="b")
    assert dyn.sequence_wind(bare) is None and dyn.wind_bin(None) == "unknown"
    assert [dyn.wind_bin(v) for v in (1.99, 2.0, 15.99, 16.0, 40.0)] == [
        "0-2", "2-5", "12-16", "16+", "16+",
    ]  # fmt: skip


@pytest.mark.slow
def test_on_a_dask_cluster_the_records_equal_the_serial_run(cluster):
    seqs = list(generate_sequences(4, size=48, seed=2, frames=1))
    config = DynamicConfig(
        folds=2, classifiers=(), latencies=(0.0, 60.0), planners=("track-center", "naive-transect")
    )
    serial = evaluate_dynamic(seqs, config, options=RunOptions(progress=False))
    remote = evaluate_dynamic(seqs, config, options=RunOptions(progress=False, scheduler=cluster))
    assert remote["records"] == serial["records"]


def test_the_cli_defaults_name_the_evaluations_modes_and_bins():
    from dyntarget import defaults
    from dyntarget.evaluate.dynamic import MODES, WIND_BINS, wind_bin

    assert defaults.DYNAMIC_MODES == tuple(MODES)
    labels = [wind_bin(lo) for lo, _ in WIND_BINS]
    assert labels == ["0-2", "2-5", "5-8", "8-12", "12-16", "16+"]  # as the --help lists them
