from __future__ import annotations

import json

import numpy as np
import pytest

from dyntarget import InvalidParameterError, UnknownNameError
from dyntarget.evaluate.crossval import CVConfig, cross_validate, kfold_indices
from dyntarget.evaluate.options import RunOptions


def test_kfold_partitions_scenes():
    folds = kfold_indices(38, 5, seed=0)
    allidx = np.concatenate(folds)
    assert sorted(allidx.tolist()) == list(range(38))
    assert [len(f) for f in folds] == [8, 8, 8, 7, 7]
    assert [f.tolist() for f in kfold_indices(38, 5, seed=0)] == [f.tolist() for f in folds]


def test_kfold_too_many_folds():
    with pytest.raises(InvalidParameterError, match="at least 5 scenes"):
        kfold_indices(4, 5, seed=0)


def test_config_validation():
    with pytest.raises(InvalidParameterError, match="folds"):
        CVConfig(folds=1)
    with pytest.raises(UnknownNameError, match="svm"):
        CVConfig(classifiers=("svm",))


@pytest.mark.slow
def test_small_cross_validation_and_model_reuse(tiny_scenes, tmp_path):
    config = CVConfig(folds=2, factor=2, classifiers=("band-threshold", "decision-tree"))
    first = cross_validate(
        tiny_scenes, config, options=RunOptions(models_dir=tmp_path, progress=False)
    )
    rows = first["rows"]
    assert [r["Classifier"] for r in rows] == [
        "Band Threshold",
        "+ Denoising",
        "Decision Tree",
        "+ Denoising",
    ]
    for r in rows:
        for col in ("Accuracy", "Precision", "Recall", "IoU"):
            assert 0.0 <= r[col] <= 1.0
    assert first["wfov_shape"] == [32, 32]
    saved = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.glob("fold-*/*"))
    assert saved == [
        "fold-0/band-threshold",
        "fold-0/decision-tree",
        "fold-1/band-threshold",
        "fold-1/decision-tree",
    ]
    meta = json.loads((tmp_path / "fold-0/decision-tree/metadata.json").read_text())
    assert set(meta["training"]["scenes"]).isdisjoint(first["folds"][0])
    mtime = (tmp_path / "fold-0/decision-tree/model.skops").stat().st_mtime_ns
    second = cross_validate(
        tiny_scenes, config, options=RunOptions(models_dir=tmp_path, progress=False)
    )
    assert (
        tmp_path / "fold-0/decision-tree/model.skops"
    ).stat().st_mtime_ns == mtime  # reused, not retrained
    assert [r["IoU"] for r in second["rows"]] == [r["IoU"] for r in rows]
