"""``dyntarget fly`` through the command line: outputs, errors, signals, campaigns."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from dyntarget.cli import main
from dyntarget.io import write_scene
from dyntarget.scene import Scene


def _static_strip(directory, *, rows=1024, cols=128, plumes=((600, 680, 20, 80),)):
    image = np.full((4, rows, cols), 0.05, np.float32)
    label = np.zeros((rows, cols), bool)
    for r0, r1, c0, c1 in plumes:
        label[r0:r1, c0:c1] = True
    image[:, label] = 0.8
    write_scene(Scene(image, label=label, gsd=8.0, id="strip"), directory)
    return directory / "strip.tif"


def test_fly_writes_every_output(tmp_path):
    strip = _static_strip(tmp_path / "in")
    out = tmp_path / "out"
    args = ["fly", "--scene", str(strip), "--truth", "--agility", "unlimited"]
    assert main([*args, "--compute-budget-s", "0.05", "--out", str(out), "--quiet"]) == 0
    rows = list(csv.DictReader((out / "timeline.csv").read_text().splitlines()))
    assert [int(r["frame"]) for r in rows] == list(range(15))
    doc = json.loads((out / "pointings.geojson").read_text())
    points = [f for f in doc["features"] if f["geometry"]["type"] == "Point"]
    assert len(points) == sum(int(r["pointings_flown"]) for r in rows) > 0
    assert "1 of 1" in (out / "summary.md").read_text()
    assert (out / "pass.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_synthetic_strip_flies_from_the_cli(tmp_path):
    data, out = tmp_path / "strips", tmp_path / "out"
    args = ["synth", "--strip", "--scenes", "1", "--size", "64", "--plumes", "2", "--seed", "3"]
    assert main([*args, "--out", str(data), "--quiet"]) == 0
    assert sorted(p.name for p in data.iterdir()) == [
        ".dyntarget-output",  # marks the folder as dyntarget's (docs/reliability.md)
        "strip-0003.plumes.geojson",  # moving worlds are 3D by default: the per-vent truth
        "strip-0003.tif",
        "strip-0003.world.json",
        "strip-0003_mask.tif",
    ]
    fly = ["fly", "--scene", str(data / "strip-0003.tif"), "--truth", "--no-picture"]
    assert main([*fly, "--compute-budget-s", "0.1", "--out", str(out), "--quiet"]) == 0
    # 4.5 frames long (288 rows), plus the northern margin a 3D strip gains for its displaced
    # plumes (its rows read back from the strip); frames of 16 WFOV rows, 8 apart
    import rasterio

    with rasterio.open(data / "strip-0003.tif") as src:
        rows = src.height // 4
    assert rows > 288 // 4
    assert len((out / "timeline.csv").read_text().splitlines()) == 1 + (rows - 16) // 8 + 1


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--overlap", "1.5"], "overlap"),
        (["--agility", "warp"], "agility"),
        (["--planner", "nope"], "nope"),
        (["--agility", "fast,slow"], "--campaign"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, extra, word):
    strip = _static_strip(tmp_path / "in")
    args = ["fly", "--scene", str(strip), "--truth", "--out", str(tmp_path / "o"), "--quiet"]
    assert main([*args, *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0]


def test_fly_needs_a_model_or_the_truth(tmp_path, capsys):
    strip = _static_strip(tmp_path / "in")
    assert main(["fly", "--scene", str(strip), "--out", str(tmp_path / "o")]) == 2
    assert "--model" in capsys.readouterr().err


def test_campaign_writes_one_tidy_table_and_resumes(tmp_path):
    data = tmp_path / "strips"
    _static_strip(data)
    out = tmp_path / "out"
    args = [
        "fly",
        "--campaign",
        str(data),
        "--truth",
        "--planner",
        "lawnmower-transect,track-center",
    ]
    args += ["--agility", "unlimited,slow", "--compute-budget-s", "0.05", "--out", str(out)]
    assert main([*args, "--quiet"]) == 0
    rows = list(csv.DictReader((out / "campaign.csv").read_text().splitlines()))
    assert [(r["planner"], r["agility"]) for r in rows] == [
        ("lawnmower-transect", "unlimited"),
        ("lawnmower-transect", "slow"),
        ("track-center", "unlimited"),
        ("track-center", "slow"),
    ]
    assert all(r["plumes_total"] == "1" for r in rows)
    assert len(list((out / "parts").glob("*.json"))) == 4
    first = (out / "campaign.csv").read_bytes()
    for p in (out / "passes").rglob("timeline.csv"):
        p.unlink()
    assert main([*args, "--quiet"]) == 0  # resumed from parts: the passes are not flown again
    assert (out / "campaign.csv").read_bytes() == first
    assert not list((out / "passes").rglob("timeline.csv"))


@pytest.mark.slow
def test_sigterm_mid_pass_leaves_complete_outputs(tmp_path):
    strip = _static_strip(
        tmp_path / "in", rows=16384, plumes=[(r, r + 60, 30, 90) for r in range(400, 16000, 900)]
    )
    out = tmp_path / "out"
    env = {**os.environ, "MPLBACKEND": "Agg"}
    cmd = [sys.executable, "-m", "dyntarget", "fly", "--scene", str(strip), "--truth"]
    cmd += ["--compute-budget-s", "0.01", "--out", str(out), "--quiet", "--agility", "fast"]
    proc = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    timeline = out / "timeline.csv"
    while time.monotonic() < deadline:
        staged = list(out.glob(".partial-*/timeline.csv"))  # the pass is staged until written
        if staged and len(staged[0].read_text().splitlines()) >= 4:
            break
        if proc.poll() is not None:
            pytest.fail(f"fly ended before it was stopped: {proc.stderr.read()}")
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err
    rows = list(csv.DictReader(timeline.read_text().splitlines()))
    n = len(rows)
    assert 3 <= n < 255  # stopped mid-pass (the strip has 255 frames)
    assert [int(r["frame"]) for r in rows] == list(range(n))
    doc = json.loads((out / "pointings.geojson").read_text())
    frames = {f["properties"]["frame"] for f in doc["features"] if "frame" in f["properties"]}
    assert frames <= set(range(n))
    assert f"stopped** after {n} of 255 frames" in (out / "summary.md").read_text()
    # no temporary file left (the folder's marker is not one: docs/reliability.md)
    assert not [
        p.name for p in out.iterdir() if p.name.startswith(".") and p.name != ".dyntarget-output"
    ]


@pytest.mark.slow
def test_watch_plans_frames_until_sigint(tmp_path, tiny_scenes):
    from dyntarget.perceive import make_classifier

    model = tmp_path / "model"
    make_classifier("band-threshold").fit([s.to_wfov(4) for s in tiny_scenes]).save(model)
    watched, out = tmp_path / "in", tmp_path / "out"
    watched.mkdir()
    env = {**os.environ, "MPLBACKEND": "Agg"}
    cmd = [sys.executable, "-m", "dyntarget", "fly", "--watch", str(watched), "--model", str(model)]
    cmd += ["--out", str(out), "--settle-s", "0.2", "--poll-s", "0.05", "--agility", "fast"]
    proc = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True)
    frame = write_scene(tiny_scenes[0], tmp_path / "src")[0]
    part = watched / f"{frame.name}.part"
    part.write_bytes(frame.read_bytes())
    part.rename(watched / frame.name)  # the writer's convention: .part, then rename
    plan = out / f"{frame.stem}.geojson"
    deadline = time.monotonic() + 120
    while not plan.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert plan.exists()
    rows = (out / "frames.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith(frame.name + ",")
    assert "planned 1 frame(s)" in err
