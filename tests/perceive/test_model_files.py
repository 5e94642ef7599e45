"""Model files are data: foreign, tampered or mismatched files are refused, never unpickled."""

from __future__ import annotations

import json
import pickle

import pytest

from dyntarget import DataFileError, ModelFileError
from dyntarget.perceive import load_classifier, make_classifier
from helpers import FAST_KWARGS


@pytest.fixture(scope="module")
def saved(tmp_path_factory, tiny_scenes):
    root = tmp_path_factory.mktemp("models")
    paths = {}
    for name in ("decision-tree", "unet-uavsar", "band-threshold"):
        paths[name] = (
            make_classifier(name, **FAST_KWARGS.get(name, {}))
            .fit(tiny_scenes[:2])
            .save(root / name)
        )
    return paths


def _edit_meta(path, **changes):
    meta = json.loads((path / "metadata.json").read_text())
    meta.update(changes)
    (path / "metadata.json").write_text(json.dumps(meta))


def _copy(src, dst):
    import shutil

    shutil.copytree(src, dst)
    return dst


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"format": "other"}, "not a dyntarget model"),
        ({"format_version": 99}, "format version 99"),
        ({"bands": ["blue", "green", "red", "nir"]}, "band order"),
        ({"classifier": "svm"}, "unknown classifier 'svm'"),
        ({"config": {"seed": 0, "bogus": 1}}, "config does not fit"),
    ],
)
def test_tampered_metadata_refused(saved, tmp_path, changes, match):
    path = _copy(saved["decision-tree"], tmp_path / "m")
    _edit_meta(path, **changes)
    with pytest.raises(ModelFileError, match=match):
        load_classifier(path)


def test_not_a_model_directory(tmp_path):
    with pytest.raises(DataFileError, match="not a model directory"):
        load_classifier(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ModelFileError, match="no metadata.json"):
        load_classifier(tmp_path / "empty")


def test_pickle_in_place_of_skops_refused(saved, tmp_path):
    path = _copy(saved["decision-tree"], tmp_path / "m")
    (path / "model.skops").write_bytes(pickle.dumps({"evil": "payload"}))
    with pytest.raises(ModelFileError, match="not a readable skops file"):
        load_classifier(path)


def test_untrusted_type_in_skops_refused(saved, tmp_path):
    import skops.io as sio
    from sklearn.preprocessing import FunctionTransformer

    path = _copy(saved["decision-tree"], tmp_path / "m")
    sio.dump(FunctionTransformer(func=print), path / "model.skops")
    with pytest.raises(ModelFileError, match="untrusted types"):
        load_classifier(path)


def test_wrong_estimator_kind_refused(saved, tmp_path):
    import skops.io as sio
    from sklearn.naive_bayes import GaussianNB

    path = _copy(saved["decision-tree"], tmp_path / "m")
    sio.dump(GaussianNB(), path / "model.skops")
    with pytest.raises(ModelFileError, match="expected DecisionTreeClassifier"):
        load_classifier(path)


def test_corrupt_safetensors_refused(saved, tmp_path):
    path = _copy(saved["unet-uavsar"], tmp_path / "m")
    (path / "model.safetensors").write_bytes(b"\x00" * 64)
    with pytest.raises(ModelFileError, match="not a readable safetensors"):
        load_classifier(path)


def test_weights_of_other_shape_refused(saved, tmp_path):
    path = _copy(saved["unet-uavsar"], tmp_path / "m")
    meta = json.loads((path / "metadata.json").read_text())
    meta["config"]["width"] = 8
    (path / "metadata.json").write_text(json.dumps(meta))
    with pytest.raises(ModelFileError, match="do not match"):
        load_classifier(path)


def test_classifier_specific_load_checks_name(saved):
    from dyntarget.perceive.pixel import RandomForest

    with pytest.raises(ModelFileError, match="holds a 'decision-tree' model"):
        RandomForest.load(saved["decision-tree"])


def test_bad_threshold_params(saved, tmp_path):
    path = _copy(saved["band-threshold"], tmp_path / "m")
    (path / "params.json").write_text("{}")
    with pytest.raises(ModelFileError, match="bad params.json"):
        load_classifier(path)


def test_save_replaces_atomically(saved, tiny_scenes, tmp_path):
    path = _copy(saved["band-threshold"], tmp_path / "m")
    make_classifier("band-threshold", seed=3).fit(tiny_scenes[:1]).save(path)
    assert json.loads((path / "metadata.json").read_text())["config"]["seed"] == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]
