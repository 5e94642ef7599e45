"""The lean core: heavy libraries are imported only by the code paths that use them.

Each check runs in a fresh interpreter (this test process has imported everything
already) and reads ``sys.modules`` at the end.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

HEAVY = ("torch", "sklearn", "skops", "dask", "distributed", "matplotlib", "onnxruntime", "pytest")
NATIVE_ML = ("torch", "sklearn", "skops")


def _loaded_after(code: str) -> tuple[list[str], str]:
    """Run ``code`` in a fresh interpreter; the heavy modules it left loaded, and its stdout."""
    probe = (
        f"{code}\nimport json, sys\n"
        f"print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr
    *out, last = done.stdout.strip().splitlines()
    return json.loads(last), "\n".join(out)


@pytest.mark.slow
def test_importing_the_core_and_stages_loads_nothing_heavy():
    loaded, _ = _loaded_after(
        "import dyntarget, dyntarget.pipeline, dyntarget.plan, dyntarget.observe, dyntarget.io\n"
        "import dyntarget.denoise, dyntarget.schedule, dyntarget.masks, dyntarget.trajectory\n"
        "import dyntarget.perceive, dyntarget.synth, dyntarget.cli"
    )
    assert loaded == []


@pytest.mark.slow
def test_listing_classifiers_and_planners_loads_nothing_heavy():
    loaded, out = _loaded_after(
        "from dyntarget.cli import main\n"
        "assert main(['classifiers']) == 0\n"
        "assert main(['planners']) == 0\n"
        "assert main(['agility']) == 0"
    )
    assert loaded == []
    assert "random-forest" in out and "unet-uavsar" in out and "lawnmower-transect" in out


@pytest.mark.slow
def test_planning_from_the_onnx_export_of_a_sklearn_model_imports_no_native_ml(
    tiny_scenes, tmp_path
):
    pytest.importorskip("onnxruntime")
    pytest.importorskip("skl2onnx")
    from dyntarget.cli import main
    from dyntarget.io import write_scene
    from dyntarget.perceive import make_classifier
    from dyntarget.perceive.onnx_export import export_onnx

    model_dir = tmp_path / "rf"
    model = make_classifier("decision-tree").fit(tiny_scenes[:3])
    model.save(model_dir)
    export_onnx(model, model_dir)
    image = write_scene(tiny_scenes[3], tmp_path / "scene")[0]
    native_out = tmp_path / "native.csv"
    args = ["plan", str(image), "--model", str(model_dir), "--planner", "track-center"]
    assert main([*args, "--out", str(native_out)]) == 0

    onnx_out = tmp_path / "onnx.csv"
    loaded, _ = _loaded_after(
        "from dyntarget.cli import main\n"
        f"assert main({[*args, '--onnx', '--out', str(onnx_out)]!r}) == 0"
    )
    assert not set(loaded) & set(NATIVE_ML), loaded
    assert "onnxruntime" in loaded  # the ONNX path really ran
    assert onnx_out.read_text() == native_out.read_text()  # the same mask, the same plan


@pytest.mark.slow
@pytest.mark.skipif(
    os.environ.get("DYNTARGET_FOREST_ISA") == "off",
    reason="DYNTARGET_FOREST_ISA=off switches the forest kernel off: nothing plans on it",
)
def test_the_onnx_export_of_a_random_forest_plans_on_the_kernel_without_native_ml(
    tiny_scenes, tmp_path
):
    """forest.npz beside model.onnx: the lean path loads neither scikit-learn nor torch,
    maps the forest kernel where it builds on x86-64 (every x86-64 path was measured faster
    than ONNX Runtime's tree ensemble; NEON was not measured) or where
    ``DYNTARGET_FOREST_ISA`` forces a path (a forced path is never replaced silently), and
    plans what the native model plans (bit-identical probabilities, so the same mask)."""
    pytest.importorskip("onnxruntime")
    pytest.importorskip("skl2onnx")
    from dyntarget.cli import main
    from dyntarget.io import write_scene
    from dyntarget.perceive import compiled, make_classifier
    from dyntarget.perceive.onnx_export import export_onnx

    model_dir = tmp_path / "rf"
    model = make_classifier("random-forest", max_pixels_per_class=2000).fit(tiny_scenes[:3])
    model.save(model_dir)
    export_onnx(model, model_dir)
    image = write_scene(tiny_scenes[3], tmp_path / "scene")[0]
    native_out = tmp_path / "native.csv"
    args = ["plan", str(image), "--model", str(model_dir), "--planner", "track-center"]
    assert main([*args, "--out", str(native_out)]) == 0

    onnx_out = tmp_path / "onnx.csv"
    loaded, out = _loaded_after(
        "from dyntarget.cli import main\n"
        f"assert main({[*args, '--onnx', '--out', str(onnx_out)]!r}) == 0\n"
        "print(any('forest-kernel' in line for line in open('/proc/self/maps')))"
    )
    assert not set(loaded) & set(NATIVE_ML), loaded
    if compiled.forced_isa() is not None:  # e.g. portable or sse2: run because it was asked for
        expected = True
    else:  # auto: the kernel built here on any x86-64
        expected = compiled.compiler() is not None and platform.machine() in ("x86_64", "AMD64")
    assert out.strip().splitlines()[-1] == str(expected)  # the kernel ran where it should
    assert onnx_out.read_text() == native_out.read_text()


def _plan_args(model_dir, image, out):
    return ["plan", str(image), "--model", str(model_dir), "--planner", "track-center",
            "--out", str(out)]  # fmt: skip


@pytest.mark.slow
@pytest.mark.skipif(
    os.environ.get("DYNTARGET_FOREST_ISA") == "off",
    reason="DYNTARGET_FOREST_ISA=off switches the forest kernel off: nothing plans on it",
)
def test_native_random_forest_plans_from_its_packed_forest_without_native_ml(tiny_scenes, tmp_path):
    """``train`` writes forest.npz bound to model.skops (forest.json); ``plan --model RF``
    (native, not --onnx) predicts from it and imports neither torch nor scikit-learn nor
    skops, and plans what scikit-learn's probabilities plan. An older model directory
    (model.skops alone) is planned with scikit-learn once, gets its packed forest written,
    and the next run is lean again."""
    from dyntarget.cli import main
    from dyntarget.io import write_scene
    from dyntarget.perceive import make_classifier

    model_dir = tmp_path / "rf"
    model = make_classifier("random-forest", max_pixels_per_class=2000).fit(tiny_scenes[:3])
    model.save(model_dir)
    assert {p.name for p in model_dir.iterdir()} >= {"model.skops", "forest.npz", "forest.json"}
    image = write_scene(tiny_scenes[3], tmp_path / "scene")[0]
    reference = tmp_path / "sklearn.csv"
    model.set_backend("sklearn")
    from dyntarget.perceive import pixel

    # the reference plan: scikit-learn's own probabilities (a different implementation)
    original = pixel.RandomForest.chunk_predictor
    try:
        pixel.RandomForest.chunk_predictor = pixel.PixelClassifier.chunk_predictor
        assert main(_plan_args(model_dir, image, reference)) == 0
    finally:
        pixel.RandomForest.chunk_predictor = original

    out = tmp_path / "lean.csv"
    loaded, _ = _loaded_after(
        f"from dyntarget.cli import main\nassert main({_plan_args(model_dir, image, out)!r}) == 0"
    )
    assert not set(loaded) & set(NATIVE_ML), loaded
    assert out.read_text() == reference.read_text()

    for name in ("forest.npz", "forest.json"):  # as trained before the packed forest
        (model_dir / name).unlink()
    again = tmp_path / "again.csv"
    probe = (
        f"from dyntarget.cli import main\nassert main({_plan_args(model_dir, image, again)!r}) == 0"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("bound the packed forest to model.skops") == 1
    assert (model_dir / "forest.npz").is_file() and (model_dir / "forest.json").is_file()
    loaded, _ = _loaded_after(probe)
    assert not set(loaded) & set(NATIVE_ML), loaded
    assert again.read_text() == reference.read_text()

    (model_dir / "model.skops").write_bytes(  # another model's file: the forest is not its own
        _retrained(tiny_scenes, tmp_path).joinpath("model.skops").read_bytes()
    )
    loaded, _ = _loaded_after(probe)
    assert "sklearn" in loaded  # not the forest of this model.skops: scikit-learn predicts


def _retrained(tiny_scenes, tmp_path):
    from dyntarget.perceive import make_classifier

    other = tmp_path / "other"
    make_classifier("random-forest", seed=1, max_pixels_per_class=500).fit(tiny_scenes[:2]).save(
        other
    )
    return other


@pytest.mark.slow
def test_a_unet_loads_its_safetensors_without_scikit_learn(tiny_scenes, tmp_path):
    pytest.importorskip("torch")
    from dyntarget.perceive import make_classifier

    model_dir = tmp_path / "unet"
    make_classifier("unet-uavsar", epochs=1, width=4).fit(tiny_scenes[:2]).save(model_dir)
    loaded, _ = _loaded_after(
        "import numpy as np\nfrom dyntarget.perceive import load_classifier\n"
        f"load_classifier({str(model_dir)!r}).predict_proba(np.zeros((4, 32, 32), np.float32))"
    )
    assert "torch" in loaded and not {"sklearn", "skops"} & set(loaded), loaded


def test_a_missing_optional_dependency_names_its_extra(tiny_scenes, tmp_path, monkeypatch, capsys):
    from dyntarget.cli import main
    from dyntarget.io import write_scene

    data = tmp_path / "data"
    for scene in tiny_scenes[:2]:
        write_scene(scene, data)
    # as if scikit-learn were not installed (the lean install without the "full" extra)
    monkeypatch.setitem(sys.modules, "sklearn", None)
    monkeypatch.setitem(sys.modules, "sklearn.naive_bayes", None)
    args = [
        "train",
        "--data",
        str(data),
        "--classifier",
        "naive-bayes",
        "--out",
        str(tmp_path / "m"),
    ]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['dyntarget: error: sklearn is not installed: pip install "dyntarget[full]"']
    assert not (tmp_path / "m").exists()
