"""Forest kernels built ahead of time into the model directory: shipped, installed, never
loaded from the model directory itself (issue 42: a model directory is data, never code).

The expected probabilities are scikit-learn's own ``predict_proba`` (a different
implementation); the ELF check reads the header bytes by hand (``e_machine`` at offset 18).
No test here needs a compiler at run time: each run-time load happens with the compiler
hidden and an empty cache, as on a flight computer.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from dyntarget.perceive import compiled, load_classifier, make_classifier

if compiled.compiler() is None:
    pytest.skip("no C compiler to build the artefacts with", allow_module_level=True)

X86 = [t for t, (_, arch, _) in compiled.TARGETS.items() if arch == "x86_64"]


@pytest.fixture(scope="module")
def trained(tiny_scenes, tmp_path_factory):
    """A saved project forest with a kernel for every target this machine can build."""
    model_dir = tmp_path_factory.mktemp("art") / "rf"
    model = make_classifier("random-forest", max_pixels_per_class=2000).fit(tiny_scenes[:3])
    model.save(model_dir)
    targets = [t for t in compiled.TARGETS if compiled.target_compiler(t) is not None]
    compiled.write_manifest(model_dir, compiled.build_kernels(model_dir, targets))
    return model, model_dir, targets


@pytest.fixture
def flight(monkeypatch, tmp_path):
    """As on a flight computer: no compiler, nothing cached, nothing said yet."""
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv(compiled.ISA_ENV, raising=False)
    monkeypatch.setattr(compiled, "_SAID", set())


def _pixels(tiny_scenes):
    return np.concatenate([s.image.reshape(4, -1).T for s in tiny_scenes]).astype(np.float32)


def _packed(model_dir):
    return compiled.load_forest(model_dir / compiled.FOREST_FILE)


def test_the_manifest_binds_each_artefact_to_its_bytes_and_its_forest(trained):
    _, model_dir, targets = trained
    manifest = json.loads((model_dir / compiled.MANIFEST_FILE).read_text())
    assert [k["target"] for k in manifest["kernels"]] == targets
    import hashlib

    forest_sha = hashlib.sha256((model_dir / "forest.npz").read_bytes()).hexdigest()
    assert manifest["forest"]["sha256"] == forest_sha
    for k in manifest["kernels"]:
        data = (model_dir / k["file"]).read_bytes()
        assert k["sha256"] == hashlib.sha256(data).hexdigest()
        assert k["forest_sha256"] == forest_sha


def test_a_shipped_kernel_is_never_loaded_from_the_model_directory(
    trained, flight, monkeypatch, capsys
):
    """A model directory is data: its libraries are named on stderr (once), never dlopened."""
    _, model_dir, targets = trained
    before = set(compiled._LOADED)
    assert compiled.fast_predictor(_packed(model_dir)) is None  # no compiler, nothing installed
    assert compiled.fast_predictor(_packed(model_dir)) is None
    assert set(compiled._LOADED) == before
    with open("/proc/self/maps") as maps:
        assert str(model_dir) not in maps.read()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "not loaded from a model directory" in err[0] and compiled.cpu_class() in err[0]
    assert all(f"forest-kernel-{t}.so" in err[0] for t in targets)
    if "aarch64" in targets and compiled._arch() != "aarch64":  # the other architecture, said
        assert f"forest-kernel-aarch64.so (for aarch64, this CPU is {compiled._arch()})" in err[0]


@pytest.mark.parametrize("target", X86)
def test_every_installed_x86_kernel_equals_scikit_learn_bit_for_bit(
    trained, tiny_scenes, target, flight, monkeypatch
):
    model, model_dir, targets = trained
    isa = compiled.TARGETS[target][0]
    if target not in targets or not compiled.cpu_runs(isa):
        pytest.skip(f"this CPU does not run {target} ({isa})")
    installed = compiled.install_kernel(model_dir / f"forest-kernel-{target}.so")
    assert installed.parent == compiled.cache_dir() and installed.name.endswith("-installed.so")
    monkeypatch.setenv(compiled.ISA_ENV, isa)
    predict = compiled.fast_predictor(_packed(model_dir))
    assert predict.source == installed  # the installed copy, no build
    assert predict.isa == isa
    x = _pixels(tiny_scenes)
    expected = model.estimator.predict_proba(x)[:, 1].astype(np.float32)
    np.testing.assert_array_equal(predict(x), expected)
    # the same through the classifier loaded from the directory (the packed forest)
    loaded = load_classifier(model_dir)
    image = tiny_scenes[3].image
    np.testing.assert_array_equal(
        loaded.predict_proba(image), model.set_backend("sklearn").predict_proba(image)
    )


def test_the_installed_kernel_follows_the_forced_path(trained, flight, monkeypatch):
    _, model_dir, targets = trained
    runnable = [t for t in targets if compiled.cpu_runs(compiled.TARGETS[t][0])]
    if not runnable:
        pytest.skip("no artefact for this CPU")
    libs = {t: compiled.install_kernel(model_dir / f"forest-kernel-{t}.so") for t in runnable}
    best = next(t for t in ("x86-64-v4", "x86-64-v3", "aarch64") if t in runnable)
    assert compiled.fast_predictor(_packed(model_dir)).source == libs[best]
    for target in runnable:
        monkeypatch.setenv(compiled.ISA_ENV, compiled.TARGETS[target][0])
        assert compiled.fast_predictor(_packed(model_dir)).source == libs[target]
    monkeypatch.setenv(compiled.ISA_ENV, "off")
    assert compiled.fast_predictor(_packed(model_dir)) is None


def test_a_tampered_installed_kernel_is_refused_and_the_fallback_said_once(
    trained, flight, monkeypatch, capsys
):
    _, model_dir, targets = trained
    runnable = [t for t in targets if compiled.cpu_runs(compiled.TARGETS[t][0])]
    if not runnable:
        pytest.skip("no artefact for this CPU")
    for target in runnable:
        lib = compiled.install_kernel(model_dir / f"forest-kernel-{target}.so")
        data = bytearray(lib.read_bytes())
        data[len(data) // 2] ^= 1  # one bit, after the install
        lib.write_bytes(bytes(data))
    packed = _packed(model_dir)
    assert compiled.fast_predictor(packed) is None  # no compiler either: scikit-learn predicts
    assert compiled.fast_predictor(packed) is None
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert compiled.cpu_class() in err[0] and "C compiler" in err[0]


def test_a_kernel_for_another_architecture_is_not_installed(trained, flight, tmp_path):
    from dyntarget.errors import InvalidParameterError

    _, model_dir, targets = trained
    foreign = [t for t in targets if compiled.TARGETS[t][1] != compiled._arch()]
    if not foreign:
        pytest.skip("no cross-compiled artefact here")
    lib = model_dir / f"forest-kernel-{foreign[0]}.so"
    with pytest.raises(InvalidParameterError, match=f"built for {compiled.TARGETS[foreign[0]][1]}"):
        compiled.install_kernel(lib)
    assert not compiled.cache_dir().exists() or not list(compiled.cache_dir().glob("*.so"))
    junk = tmp_path / "forest-kernel-x86-64.so"
    junk.write_bytes(b"#!/bin/sh\necho not a library\n")
    with pytest.raises(InvalidParameterError, match="not an ELF shared library"):
        compiled.install_kernel(junk)


def test_the_cross_compiled_aarch64_artefact_is_an_aarch64_elf(trained):
    _, model_dir, targets = trained
    if "aarch64" not in targets:
        pytest.skip("no aarch64 compiler here (Debian: gcc-aarch64-linux-gnu)")
    head = (model_dir / "forest-kernel-aarch64.so").read_bytes()[:20]
    assert head[:4] == b"\x7fELF" and head[4] == 2 and head[5] == 1  # 64-bit, little-endian
    assert int.from_bytes(head[16:18], "little") == 3  # ET_DYN: a shared object
    assert int.from_bytes(head[18:20], "little") == 183  # EM_AARCH64


def test_a_target_without_its_compiler_is_refused_in_one_line(
    trained, tmp_path, monkeypatch, capsys
):
    from dyntarget.cli import main

    _, model_dir, _ = trained
    foreign = next(t for t, (_, arch, _) in compiled.TARGETS.items() if arch != compiled._arch())
    arch = compiled.TARGETS[foreign][1]
    monkeypatch.setitem(compiled.CROSS_COMPILERS, arch, "no-such-cross-gcc")
    before = sorted(p.name for p in model_dir.iterdir())
    assert main(["export-onnx", str(model_dir), "--targets", f"host,{foreign}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--targets {foreign}: no C compiler for {arch}" in err[0], err
    assert sorted(p.name for p in model_dir.iterdir()) == before  # nothing written
    assert main(["export-onnx", str(model_dir), "--targets", "pentium"]) == 2
    assert "unknown target 'pentium'" in capsys.readouterr().err


@pytest.mark.slow
def test_export_onnx_builds_the_named_targets(tiny_scenes, tmp_path, flight, monkeypatch):
    pytest.importorskip("skl2onnx")
    import shutil

    from dyntarget.cli import main

    monkeypatch.undo()  # the export needs the compiler
    model_dir = tmp_path / "rf"
    make_classifier("random-forest", max_pixels_per_class=500).fit(tiny_scenes[:2]).save(model_dir)
    targets = [t for t in ("x86-64-v3", "aarch64") if compiled.target_compiler(t)]
    assert main(["export-onnx", str(model_dir), "--targets", ",".join(targets)]) == 0
    manifest = json.loads((model_dir / compiled.MANIFEST_FILE).read_text())
    assert [k["target"] for k in manifest["kernels"]] == targets
    assert main(["export-onnx", str(model_dir), "--targets", "none"]) == 0  # the old ones removed
    assert compiled.kernel_files(model_dir) == []
    assert json.loads((model_dir / compiled.MANIFEST_FILE).read_text())["kernels"] == []
    assert shutil.which("cc")


@pytest.mark.slow
def test_export_onnx_by_default_builds_every_class_it_has_a_compiler_for(
    tiny_scenes, tmp_path, monkeypatch, capsys
):
    """Default --targets auto: every x86-64 level where the host is x86-64 (or aarch64 where it
    is aarch64); the other architecture's target, its cross compiler hidden, is said once."""
    pytest.importorskip("skl2onnx")
    from dyntarget.cli import main

    host = compiled._arch()
    foreign = "aarch64" if host == "x86_64" else "x86_64"
    monkeypatch.setitem(compiled.CROSS_COMPILERS, foreign, "no-such-cross-gcc")
    model_dir = tmp_path / "rf"
    make_classifier("random-forest", max_pixels_per_class=500).fit(tiny_scenes[:2]).save(model_dir)
    capsys.readouterr()
    assert main(["export-onnx", str(model_dir)]) == 0
    built = {"x86_64": ["x86-64-v4", "x86-64-v3", "x86-64"], "aarch64": ["aarch64"]}[host]
    manifest = json.loads((model_dir / compiled.MANIFEST_FILE).read_text())
    assert [k["target"] for k in manifest["kernels"]] == built
    assert sorted(p.name for p in compiled.kernel_files(model_dir)) == sorted(
        f"forest-kernel-{t}.so" for t in built
    )
    said = [line for line in capsys.readouterr().err.splitlines() if "no forest kernel" in line]
    assert len(said) == 1 and "no-such-cross-gcc" in said[0] and "ONNX Runtime" in said[0]


def test_an_installed_kernel_runs_even_on_a_path_not_measured_faster(trained, tiny_scenes, flight):
    # A kernel built here runs only on a path measured faster than scikit-learn (AVX2,
    # AVX-512); one the user installed on purpose (the flight computer's NEON kernel,
    # here the x86-64 SSE2 baseline) runs whatever its path, as .ci/aarch64 needs.
    model, model_dir, targets = trained
    if "x86-64" not in targets or not compiled.cpu_runs("sse2"):
        pytest.skip("no x86-64 baseline artefact for this CPU")
    assert "sse2" not in compiled.FAST_ISAS
    installed = compiled.install_kernel(model_dir / "forest-kernel-x86-64.so")
    predict = compiled.fast_predictor(_packed(model_dir), against="scikit-learn")
    assert predict is not None and predict.source == installed and predict.isa == "sse2"
    x = _pixels(tiny_scenes)
    expected = model.estimator.predict_proba(x)[:, 1].astype(np.float32)
    np.testing.assert_array_equal(predict(x), expected)
