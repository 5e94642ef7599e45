"""Hostile model files (issue 20, items 1 and 7): crafted but allow-listed content is refused.

Every model is built from a small hand-made fit, then tampered with in one way a
hostile file could be; loading must raise ``ModelFileError`` (the CLI: exit 2, one
line). The crafted tree runs in a subprocess: before validation it crashed the
process with a segfault.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import torch

from dyntarget.cli import main
from dyntarget.errors import ModelFileError
from dyntarget.perceive import load_classifier, make_classifier
from dyntarget.perceive.validate import check_estimator, check_state_dict, check_tree
from helpers import FAST_KWARGS, write_raw_tif

RNG = np.random.default_rng(0)
X = RNG.uniform(0.0, 1.0, (400, 4))
Y = (X[:, 0] + X[:, 3] > 1.0).astype(np.int64)


def _fitted(name: str, x=X, y=Y):
    """A dyntarget classifier wrapping a scikit-learn estimator fitted on (x, y)."""
    model = make_classifier(name)
    est = model.make_estimator()
    est.fit(x, y)
    model.estimator, model.fitted = est, True
    return model


def _crafted_tree(edit):
    """A fitted decision tree whose node array went through ``edit(nodes, values)``."""
    from sklearn.tree._tree import Tree

    model = _fitted("decision-tree")
    state = model.estimator.tree_.__getstate__()
    nodes, values = state["nodes"].copy(), state["values"].copy()
    edit(nodes, values)
    tree = Tree(4, np.array([2], dtype=np.intp), 1)
    tree.__setstate__({**state, "nodes": nodes, "values": values})
    model.estimator.tree_ = tree
    return model


def _save(model, tmp_path, name="model"):
    return model.save(tmp_path / name)


def _image(tmp_path):
    data = RNG.uniform(0.05, 0.6, (4, 16, 16)).astype(np.float32)
    return write_raw_tif(tmp_path / "img.tif", data)


@pytest.mark.slow
def test_crafted_tree_child_index_out_of_range_exits_2_in_subprocess(tmp_path):
    def far_child(nodes, values):
        nodes["left_child"][0] = 10**8

    model_dir = _save(_crafted_tree(far_child), tmp_path)
    image = _image(tmp_path)
    for args in (
        [
            "plan",
            str(image),
            "--planner",
            "lawnmower-transect",
            "--model",
            str(model_dir),
            "--out",
            str(tmp_path / "t.geojson"),
        ],
        ["export-onnx", str(model_dir)],
    ):
        proc = subprocess.run(
            [sys.executable, "-m", "dyntarget", *args],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert proc.returncode == 2, (args[0], proc.returncode, proc.stderr[-500:])
        assert "children_left 100000000" in proc.stderr
        assert "Traceback" not in proc.stderr
    assert not (tmp_path / "t.geojson").exists()
    assert not (model_dir / "model.onnx").exists()


def _cycle(nodes, values):
    inner = np.flatnonzero(nodes["left_child"] != -1)
    nodes["right_child"][inner[-1]] = 0  # back to the root


def _negative_child(nodes, values):
    nodes["left_child"][0] = -5


def _one_child(nodes, values):
    leaf = np.flatnonzero(nodes["left_child"] == -1)[0]
    nodes["left_child"][leaf] = 1


def _shared_child(nodes, values):
    nodes["right_child"][0] = nodes["left_child"][0] + 0  # both children the same node


def _feature_7(nodes, values):
    nodes["feature"][0] = 7


def _nan_threshold(nodes, values):
    nodes["threshold"][0] = np.nan


def _negative_value(nodes, values):
    values[0, 0, 0] = -1.0


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        (_cycle, "expected a later node"),
        (_negative_child, "children_left -5"),
        (_one_child, "exactly one child"),
        (_shared_child, "several parents"),
        (_feature_7, "feature outside 0..3"),
        (_nan_threshold, "NaN or infinite threshold"),
        (_negative_value, "negative, NaN or infinite"),
    ],
)
def test_crafted_tree_refused_on_load(tmp_path, edit, fragment):
    model_dir = _save(_crafted_tree(edit), tmp_path)
    with pytest.raises(ModelFileError, match=fragment):
        load_classifier(model_dir)


def test_forest_with_one_crafted_tree_refused(tmp_path):
    model = _fitted("random-forest")
    bad = _crafted_tree(lambda nodes, values: nodes["feature"].__setitem__(0, 9))
    model.estimator.estimators_[3] = bad.estimator
    saved = _save(model, tmp_path)
    # not packed for the kernel: feature 9 of 4 would have spilled into the child index bits
    assert not (saved / "forest.npz").exists()
    with pytest.raises(ModelFileError, match=r"tree 3\): tree splits on a feature outside"):
        load_classifier(saved)


@pytest.mark.parametrize(
    "name", ["naive-bayes", "logistic-regression", "decision-tree", "random-forest", "mlp"]
)
def test_sound_models_of_every_kind_load(tmp_path, name):
    # the validation must not refuse what dyntarget itself writes
    model = _fitted(name)
    loaded = load_classifier(_save(model, tmp_path))
    probe = RNG.uniform(0, 1, (4, 3, 3)).astype(np.float32)
    assert np.array_equal(loaded.predict_proba(probe), model.predict_proba(probe))


def test_three_class_estimator_refused_not_used_as_binary(tmp_path):
    y3 = np.arange(len(X)) % 3
    model = _fitted("naive-bayes", y=y3)
    with pytest.raises(ModelFileError, match=r"classes_ is array\(\[0, 1, 2\]\)"):
        load_classifier(_save(model, tmp_path))


def test_five_feature_estimator_refused(tmp_path):
    model = _fitted("logistic-regression", x=RNG.uniform(size=(400, 5)))
    with pytest.raises(ModelFileError, match="n_features_in_ is 5, expected 4"):
        load_classifier(_save(model, tmp_path))


def test_one_class_estimator_refused(tmp_path):
    from sklearn.tree import DecisionTreeClassifier

    est = DecisionTreeClassifier().fit(X, np.zeros(len(X), int))
    with pytest.raises(ModelFileError, match=r"classes_ is array\(\[0\]\)"):
        check_estimator(est, "one-class.skops")


def test_mlp_with_wrong_layer_shapes_refused():
    model = _fitted("mlp")
    mlp = model.estimator.steps[1][1]
    mlp.coefs_[1] = np.zeros((5, 32))  # does not chain onto the 32 units before it
    with pytest.raises(
        ModelFileError, match=r"coefs_\[1\] has shape \(5, 32\), expected \(32, n\)"
    ):
        check_estimator(model.estimator, "mlp.skops")


def test_nan_coefficients_refused():
    model = _fitted("logistic-regression")
    model.estimator.steps[1][1].coef_[0, 2] = np.nan
    with pytest.raises(ModelFileError, match="coef_ holds NaN"):
        check_estimator(model.estimator, "lr.skops")


def test_check_tree_accepts_a_hand_built_stump():
    from sklearn.tree import DecisionTreeClassifier

    x = np.array([[0, 0, 0, 0], [0, 0, 0, 1]] * 4, float)
    est = DecisionTreeClassifier().fit(x, [0, 1] * 4)
    # worked by hand: one split on NIR (feature 3) at 0.5, two leaves
    assert est.tree_.node_count == 3 and est.tree_.feature[0] == 3
    check_tree(est.tree_, "stump")


@pytest.mark.parametrize(
    ("meta_edit", "fragment"),
    [
        ({"classifier": ["naive-bayes"]}, "unknown classifier"),
        ({"classifier": {"a": 1}}, "unknown classifier"),
    ],
)
def test_metadata_with_a_list_where_a_name_belongs_exits_2(tmp_path, capsys, meta_edit, fragment):
    model_dir = _save(_fitted("naive-bayes"), tmp_path)
    meta_path = model_dir / "metadata.json"
    meta = json.loads(meta_path.read_text())
    meta.update(meta_edit)
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ModelFileError, match=fragment):
        load_classifier(model_dir)
    code = main(
        [
            "plan",
            str(_image(tmp_path)),
            "--planner",
            "lawnmower-transect",
            "--model",
            str(model_dir),
            "--out",
            str(tmp_path / "t.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and fragment in err


def _unet(tmp_path):
    model = make_classifier("unet-uavsar", **FAST_KWARGS["unet-uavsar"])
    model.fitted = True
    return model, model.save(tmp_path / "unet")


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        (lambda s: s.update({"head.bias": s["head.bias"].double()}), "dtype torch.float64"),
        (lambda s: s["head.weight"].fill_(float("nan")), "head.weight holds NaN"),
        (lambda s: s.update({"extra.weight": torch.zeros(1)}), "unexpected tensors"),
        (
            lambda s: s.update(
                {"enc.0.1.num_batches_tracked": torch.zeros((), dtype=torch.float32)}
            ),
            "dtype torch.float32, expected torch.int64",
        ),
        (lambda s: s["norm.std"].fill_(0.0), "norm.std holds a value <= 0"),
    ],
)
def test_unet_weights_checked_tensor_by_tensor(tmp_path, edit, fragment):
    from safetensors.torch import load_file, save_file

    _, model_dir = _unet(tmp_path)
    path = model_dir / "model.safetensors"
    state = dict(load_file(str(path)))
    edit(state)
    save_file({k: v.contiguous() for k, v in state.items()}, str(path))
    with pytest.raises(ModelFileError, match=fragment):
        load_classifier(model_dir)


def test_check_state_dict_names_the_missing_tensor():
    net = torch.nn.Conv2d(4, 2, 1)
    with pytest.raises(ModelFileError, match=r"tensors missing: \['bias'\]"):
        check_state_dict({"weight": net.weight.detach()}, net.state_dict(), "w")


def _onnx_graph(path, inputs, outputs):
    """A graph of Identity/ReduceSum nodes with the given (name, dtype, shape) inputs/outputs."""
    pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    types = {"float": TensorProto.FLOAT, "int64": TensorProto.INT64}
    ins = [helper.make_tensor_value_info(n, types[t], s) for n, t, s in inputs]
    outs = [helper.make_tensor_value_info(n, types[t], s) for n, t, s in outputs]
    nodes = [helper.make_node("Identity", [inputs[0][0]], [outputs[0][0]])]
    for name, _, _ in outputs[1:]:
        nodes.append(helper.make_node("Identity", [inputs[0][0]], [name]))
    graph = helper.make_graph(nodes, "hostile", ins, outs)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    model.ir_version = 9
    path.write_bytes(model.SerializeToString())


@pytest.mark.parametrize(
    ("inputs", "outputs"),
    [
        ([("pixels", "float", [None, 5])], [("probabilities", "float", [None, 5])]),
        ([("pixels", "float", [None, 4])], [("probabilities", "float", [None])]),
        ([("x", "float", [None, 4])], [("probabilities", "float", [None, 4])]),
    ],
    ids=["5-feature input", "1-D output", "other names"],
)
def test_onnx_graph_with_other_signature_exits_2(tmp_path, capsys, inputs, outputs):
    pytest.importorskip("onnxruntime")
    model_dir = _save(_fitted("naive-bayes"), tmp_path)
    _onnx_graph(model_dir / "model.onnx", inputs, outputs)
    from dyntarget.perceive.onnx import load_onnx

    with pytest.raises(ModelFileError, match="ONNX (inputs|outputs) are"):
        load_onnx(model_dir)
    code = main(
        [
            "plan",
            str(_image(tmp_path)),
            "--planner",
            "lawnmower-transect",
            "--model",
            str(model_dir),
            "--onnx",
            "--out",
            str(tmp_path / "t.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2, err
    assert "ONNX" in err and "Traceback" not in err
