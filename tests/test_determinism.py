"""Same command, same seed: byte-identical outputs (synth, plan, a small evaluation)."""

from __future__ import annotations

import json

import pytest

from dyntarget.cli import main


def _run(*argv):
    assert main([str(a) for a in argv]) == 0


def _files(d):
    return {
        p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()
    }


@pytest.mark.slow
def test_plan_and_evaluate_byte_identical(tmp_path, capsys):
    data = tmp_path / "data"
    _run("synth", "--scenes", 4, "--size", 48, "--seed", 3, "--out", data, "--quiet")
    outputs = []
    for run in ("a", "b"):
        out = tmp_path / run
        _run(
            "train",
            "--data",
            data,
            "--classifier",
            "random-forest",
            "--out",
            out / "rf",
            "--factor",
            2,
        )
        _run(
            "plan",
            data / "synth-0003-0001.tif",
            "--model",
            out / "rf",
            "--factor",
            2,
            "--planner",
            "diagonal-transect",
            "--out",
            out / "t.geojson",
        )
        _run(
            "plan",
            data / "synth-0003-0001.tif",
            "--mask",
            data / "synth-0003-0001_mask.tif",
            "--planner",
            "trace-outline",
            "--out",
            out / "t.csv",
        )
        _run(
            "evaluate",
            "classification",
            "--data",
            data,
            "--folds",
            2,
            "--factor",
            2,
            "--classifiers",
            "band-threshold,mlp,unet-uavsar",
            "--epochs",
            1,
            "--out",
            out / "eval",
            "--quiet",
        )
        files = _files(out)
        files.pop("eval/table1_classification.timing.json")  # wall-clock measurements, by design
        for name in [n for n in files if n.startswith("eval/parts/")]:  # resume cache: same
            part = json.loads(files[name])  # results, but it keeps each task's timings too
            part.pop("predict_seconds")
            files[name] = json.dumps(part, sort_keys=True).encode()
        outputs.append(files)
    capsys.readouterr()
    assert outputs[0].keys() == outputs[1].keys()
    different = [name for name in outputs[0] if outputs[0][name] != outputs[1][name]]
    assert different == []
