from __future__ import annotations

import json

import pytest

from dyntarget.cli import main
from helpers import synth_dir


@pytest.fixture(scope="module")
def scenes_dir(tmp_path_factory):
    return synth_dir(tmp_path_factory, "agility-data", scenes=4, size=128, seed=6)


@pytest.mark.slow
def test_evaluate_agility_table(scenes_dir, tmp_path, capsys):
    code = main(
        ["evaluate", "agility", "--data", str(scenes_dir), "--out", str(tmp_path),
         "--classifier", "decision-tree", "--folds", "2", "--quiet"]
    )  # fmt: skip
    assert code == 0, capsys.readouterr().err
    result = json.loads((tmp_path / "agility.json").read_text())
    rows = {(r["agility"], r["planner"]): r for r in result["rows"]}
    planners = ["trace-outline", "track-center", "diagonal-transect", "lawnmower-transect"]
    assert set(rows) == {
        (a, p) for a in ("unlimited", "fast", "slow") for p in [*planners, "utility-max"]
    }
    for p in planners:
        assert rows[("unlimited", p)]["Feasible as planned"] == 1.0  # the paper's assumption
        # less agility never observes more
        assert (
            rows[("slow", p)]["Observed"]
            <= rows[("fast", p)]["Observed"]
            <= rows[("unlimited", p)]["Observed"]
        )
    for r in result["records"]:
        assert 0.0 <= r["feasible_as_planned"] <= 1.0
        assert r["total_gradient"] == pytest.approx(r["gradient"] * r["observed"])
    # equal budgets with unlimited agility: utility-max gets as many pointings as the most generous planner
    for scene in {r["scene"] for r in result["records"]}:
        sel = [r for r in result["records"] if r["scene"] == scene and r["agility"] == "unlimited"]
        um = next(r for r in sel if r["planner"] == "utility-max")
        assert um["planned"] <= max(r["planned"] for r in sel if r["planner"] != "utility-max")


def test_plan_with_agility_writes_times(scenes_dir, tmp_path, capsys):
    image = sorted(scenes_dir.glob("*[0-9].tif"))[0]
    mask = image.with_name(image.stem + "_mask.tif")
    code = main(
        ["plan", str(image), "--mask", str(mask), "--factor", "4", "--planner", "utility-max",
         "--agility", "fast", "--out", str(tmp_path / "u.geojson")]
    )  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "under 'fast' agility" in captured.err
    doc = json.loads((tmp_path / "u.geojson").read_text())
    times = [f["properties"]["time_s"] for f in doc["features"] if f["geometry"]["type"] == "Point"]
    assert times and times == sorted(times)
    code = main(
        ["plan", str(image), "--mask", str(mask), "--planner", "utility-max", "--out", str(tmp_path / "x.csv")]
    )  # fmt: skip
    assert code == 2 and "give --agility" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()
