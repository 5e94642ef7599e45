"""Integration: the pipeline and both evaluations end to end on 4 tiny scenes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dyntarget import InvalidParameterError, InvalidSceneError
from dyntarget.evaluate.claims import check_claims, paper_results
from dyntarget.evaluate.endtoend import E2EConfig, evaluate_end_to_end
from dyntarget.perceive import make_classifier
from dyntarget.pipeline import plan_scene
from dyntarget.plan import PAPER_PLANNERS


def test_plan_scene_stages_and_timings(tiny_scenes):
    model = make_classifier("decision-tree").fit(tiny_scenes[:3])
    image = tiny_scenes[3].image
    r = plan_scene(image, model, "lawnmower-transect")
    assert set(r.timings) == {"classify", "denoise", "plan"}
    assert r.runtime == pytest.approx(sum(r.timings.values()))
    assert r.probability.shape == image.shape[1:] and r.raw_mask.dtype == bool
    np.testing.assert_array_equal(r.raw_mask, r.probability >= 0.5)
    assert (
        not (r.mask & ~r.raw_mask).any() or r.mask.sum() >= 1
    )  # closing may add pixels between blobs
    assert r.trajectory.planner == "lawnmower-transect"
    raw = plan_scene(image, model, "trace-outline", denoise=False)
    np.testing.assert_array_equal(raw.mask, raw.raw_mask)


def test_plan_scene_with_mask_and_errors(tiny_scenes):
    image = tiny_scenes[0].image
    r = plan_scene(image, None, "track-center", mask=tiny_scenes[0].label)
    assert r.probability is None and len(r.trajectory) > 0
    with pytest.raises(InvalidParameterError, match="classifier or a mask"):
        plan_scene(image, None, "track-center")
    with pytest.raises(InvalidSceneError, match="does not match"):
        plan_scene(image, None, "track-center", mask=np.zeros((3, 3), bool))


def test_end_to_end_rows_and_model_sharing(tiny_scenes, tmp_path):
    config = E2EConfig(folds=2, factor=2, classifiers=("band-threshold", "decision-tree"))
    result = evaluate_end_to_end(tiny_scenes, config, models_dir=tmp_path, progress=False)
    rows = result["rows"]
    assert [(r["planner"], r["classifier"]) for r in rows[:2]] == [
        ("straight-nadir", "N/A"),
        ("naive-transect", "N/A"),
    ]
    assert len(rows) == 2 + 4 * 2
    assert all(r["scenes"] == 4 for r in rows)
    for r in rows:
        assert 0 <= r["Ratio Plume"] <= 1 and 0 <= r["Intensity"] <= 1 and r["Runtime (s)"] >= 0
    assert len(result["records"]) == 4 * (2 + 4 * 2)
    assert (tmp_path / "fold-1" / "decision-tree" / "metadata.json").exists()


def test_end_to_end_config_validation():
    with pytest.raises(InvalidParameterError, match="folds"):
        E2EConfig(folds=1)


def test_claim_rules_on_the_papers_numbers():
    paper = paper_results()
    assert len(paper["table1"]) == 16 and len(paper["table2"]) == 2 + 4 * 8
    verdicts = check_claims(paper["table1"], paper["table2"])
    assert [v.get("holds") for v in verdicts[:3]] == [True, True, True]
    assert "6 of 8 improve" in verdicts[1]["detail"]
    assert verdicts[3]["verdict"] == "holds for windows longer than 13 s"


@pytest.mark.slow
def test_demo_and_reproduce_cli(tmp_path, capsys):
    from dyntarget.cli import main

    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--scenes", "4", "--size", "96", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "report.md" in printed
    report = (out / "report.md").read_text()
    assert "## Table 1" in report and "## Table 2" in report and "fig3_trajectories.png" in report
    for name in (
        "fig3_trajectories.png",
        "fig4_classification.png",
        "fig_utilities.png",
        "scenes.png",
    ):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"
    t2 = json.loads((out / "table2_end_to_end.json").read_text())
    assert {r["planner"] for r in t2["rows"]} == set(PAPER_PLANNERS)
    # reproduce on the same scenes, reusing the demo's models for the pixel classifiers
    rep = tmp_path / "rep"
    code = main(
        [
            "reproduce",
            "--data",
            str(out / "scenes"),
            "--out",
            str(rep),
            "--models",
            str(out / "models"),
            "--folds",
            "2",
            "--epochs",
            "1",
            "--quiet",
        ]
    )
    assert code == 0
    text = (rep / "report.md").read_text()
    assert "## The paper's claims on this data" in text and "| UNET-Uavsar |" in text
