"""ONNX export: parity with the native models, refusals, corrupt files, the CLI."""

from __future__ import annotations

import numpy as np
import pytest

from dyntarget import InvalidParameterError, ModelFileError
from dyntarget.cli import main
from dyntarget.perceive import CLASSIFIERS, Predictor, make_classifier
from dyntarget.perceive.onnx import load_onnx
from dyntarget.perceive.onnx_export import TOLERANCE, export_onnx
from helpers import FAST_KWARGS

EXPORTED = [
    pytest.param(n, marks=pytest.mark.slow) if CLASSIFIERS.get(n).kind == "unet" else n
    for n in CLASSIFIERS.available()
    if n != "band-threshold"
]


@pytest.mark.parametrize("name", EXPORTED)
def test_onnx_matches_native(name, tiny_scenes, tmp_path):
    model = make_classifier(name, **FAST_KWARGS.get(name, {})).fit(tiny_scenes[:3])
    model.save(tmp_path / "m")
    path = export_onnx(model, tmp_path / "m")
    assert path.name == "model.onnx" and path.stat().st_size > 0
    twin = load_onnx(tmp_path / "m")
    for scene in tiny_scenes[3:]:
        image = scene.image
        native, onnx = model.predict_proba(image), twin.predict_proba(image)
        assert onnx.shape == native.shape and onnx.dtype == np.float32
        np.testing.assert_allclose(onnx, native, atol=TOLERANCE, rtol=0)
        # a non-square crop exercises the U-Nets' tiling and the pixel reshape
        crop = image[:, :40, :23]
        np.testing.assert_allclose(
            twin.predict_proba(crop), model.predict_proba(crop), atol=TOLERANCE, rtol=0
        )
    # the deadline logic scales a timed crop by work units: the twin counts as the native
    assert isinstance(twin, Predictor) and isinstance(model, Predictor)
    assert twin.work_units((40, 23)) == model.work_units((40, 23))
    if model.kind == "pixel":
        assert twin.work_units((40, 23)) == 40 * 23  # one row per pixel


def test_band_threshold_is_not_exported(tiny_scenes, tmp_path):
    model = make_classifier("band-threshold").fit(tiny_scenes[:3])
    with pytest.raises(InvalidParameterError, match="not exported"):
        export_onnx(model, tmp_path)
    assert not (tmp_path / "model.onnx").exists()


def test_missing_and_corrupt_onnx_files(tiny_scenes, tmp_path):
    model = make_classifier("decision-tree").fit(tiny_scenes[:3])
    model.save(tmp_path / "m")
    with pytest.raises(ModelFileError, match="no model.onnx"):
        load_onnx(tmp_path / "m")
    (tmp_path / "m" / "model.onnx").write_bytes(b"not a protobuf at all")
    with pytest.raises(ModelFileError, match="not a readable ONNX model"):
        load_onnx(tmp_path / "m")


def test_export_and_plan_with_onnx_cli(tiny_scenes, tmp_path, capsys):
    model = make_classifier("logistic-regression").fit(tiny_scenes[:3])
    model.save(tmp_path / "m")
    assert main(["export-onnx", str(tmp_path / "m"), "--check-size", "64"]) == 0
    assert "agree to" in capsys.readouterr().err
    from dyntarget.io import write_scene

    image = write_scene(tiny_scenes[3], tmp_path / "scene")[0]
    outs = {}
    for flag in ([], ["--onnx"]):
        out = tmp_path / f"t{len(flag)}.csv"
        args = ["plan", str(image), "--model", str(tmp_path / "m"), "--planner", "track-center"]
        assert main([*args, "--out", str(out), *flag]) == 0, capsys.readouterr().err
        outs[len(flag)] = out.read_text()
    assert outs[0] == outs[1]  # the same mask, so the same trajectory


@pytest.mark.parametrize("name", ["mlp", pytest.param("unet-xception", marks=pytest.mark.slow)])
def test_export_is_byte_identical(name, tiny_scenes, tmp_path):
    model = make_classifier(name, **FAST_KWARGS.get(name, {})).fit(tiny_scenes[:2])
    a = export_onnx(model, tmp_path / "a").read_bytes()
    b = export_onnx(model, tmp_path / "b").read_bytes()
    assert a == b


def test_export_failing_the_parity_check_is_bad_input_and_removed(
    tiny_scenes, tmp_path, capsys, monkeypatch
):
    from dyntarget.perceive import onnx_export

    model = make_classifier("decision-tree").fit(tiny_scenes[:3])
    model.save(tmp_path / "m")
    monkeypatch.setattr(onnx_export, "TOLERANCE", -1.0)  # no difference can pass
    assert main(["export-onnx", str(tmp_path / "m"), "--check-size", "64"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "export removed" in err[0] and "internal" not in err[0]
    assert not (tmp_path / "m" / "model.onnx").exists()
