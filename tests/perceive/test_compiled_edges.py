"""The compiled forest's edges: where the kernel is built and cached, which compiler is
used, and the limits of the packed-forest file. Expected values are worked out by hand
(paths, counts, messages) or come from scikit-learn; mutation testing found each case
missing (docs/reliability.md)."""

from __future__ import annotations

import dataclasses
import shutil
import stat
from pathlib import Path

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.errors import MissingExtraError, ModelFileError
from dyntarget.perceive import compiled
from dyntarget.perceive.compiled import (
    MAX_DEPTH,
    PAD,
    build_library,
    compile_forest,
    forest_predictor,
    load_forest,
    pack_forest,
    save_forest,
)

if compiled.compiler() is None:
    pytest.skip("no C compiler", allow_module_level=True)

AVX512 = "avx512f" in Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else False


def _forest(x, y, **kw):
    from sklearn.ensemble import RandomForestClassifier

    return RandomForestClassifier(random_state=0, n_jobs=1, **kw).fit(x, y)


@pytest.fixture(scope="module")
def small():
    rng = np.random.default_rng(0)
    x = rng.random((400, 4), dtype=np.float32)
    return _forest(x, (x[:, 0] + x[:, 3] > 1).astype(int), n_estimators=3, max_depth=5), x


# -- where the kernel lives, and with which compiler -------------------------------------


def test_the_default_cache_is_under_the_home_directory(monkeypatch, tmp_path):
    monkeypatch.delenv("DYNTARGET_CACHE", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    assert compiled.cache_dir() == tmp_path / ".cache" / "dyntarget" / "forests"
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path / "elsewhere"))
    assert compiled.cache_dir() == tmp_path / "elsewhere" / "forests"


def test_the_compiler_is_cc_then_gcc_unless_cc_is_set(monkeypatch):
    paths = {"cc": "/opt/bin/cc", "gcc": "/opt/bin/gcc", "clang": "/opt/bin/clang"}
    monkeypatch.setattr(shutil, "which", lambda name: paths.get(name))
    monkeypatch.delenv("CC", raising=False)
    assert compiled.compiler() == "/opt/bin/cc"
    del paths["cc"]
    assert compiled.compiler() == "/opt/bin/gcc"
    monkeypatch.setenv("CC", "clang")
    assert compiled.compiler() == "/opt/bin/clang"
    monkeypatch.setenv("CC", "")  # empty: as if unset
    assert compiled.compiler() == "/opt/bin/gcc"
    del paths["gcc"]
    assert compiled.compiler() is None


def test_the_cpu_key_holds_the_model_and_feature_lines(monkeypatch):
    real = Path("/proc/cpuinfo")
    if real.exists():
        key = compiled._cpu()
        assert "model name" in key and "flags" in key
    fake = "processor\t: 0\nFeatures\t: fp asimd\nmodel name\t: X\nflags\t: sse\nother\t: 1\n"
    monkeypatch.setattr("builtins.open", lambda *a, **k: __import__("io").StringIO(fake))
    assert compiled._cpu() == "Features\t: fp asimd\nflags\t: sse\nmodel name\t: X\n"


def test_a_library_goes_where_it_is_asked_and_parents_are_made(small, tmp_path, monkeypatch):
    est, x = small
    lib = build_library(tmp_path / "d")
    assert lib.parent == tmp_path / "d" and lib.is_file()
    predict = compile_forest(est, directory=tmp_path / "e")
    assert len(list((tmp_path / "e").glob("forest-kernel-*.so"))) == 1
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path / "a" / "b"))  # a fresh machine
    assert build_library().parent == tmp_path / "a" / "b" / "forests"
    np.testing.assert_array_equal(predict(x), est.predict_proba(x)[:, 1].astype(np.float32))


@pytest.mark.skipif(not AVX512, reason="the CPU has no AVX-512")
def test_the_native_build_is_vectorised_and_the_portable_one_is_not(small, tmp_path):
    est, _ = small
    portable = compile_forest(est, directory=tmp_path, portable=True)
    native = compile_forest(est, directory=tmp_path)  # asked after the portable one
    assert (native.vectorised, portable.vectorised) == (True, False)
    assert forest_predictor(pack_forest(est), directory=tmp_path).vectorised is True


def _fake_compiler(tmp_path, body: str) -> str:
    script = tmp_path / "fake-cc"
    script.write_text(f"#!/bin/sh\n{body}\n")
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return str(script)


def test_a_compiler_that_refuses_native_code_gets_the_portable_build(tmp_path, monkeypatch):
    """A compiler that knows neither -march=native nor the x86-64-v3/v4 levels (e.g. gcc < 11)."""
    real = shutil.which("gcc") or shutil.which("cc")
    cc = _fake_compiler(
        tmp_path,
        'for a in "$@"; do case "$a" in -march=native|-march=x86-64-v*) echo "no $a" >&2; exit 1;;'
        " esac; done\n"
        f'exec {real} "$@"',
    )
    monkeypatch.setenv("CC", cc)
    lib = build_library(tmp_path / "cache")
    assert compiled._load(lib).dt_forest_isa() in (0, 1, 2)  # the baseline build
    monkeypatch.setattr(compiled, "compiler", lambda: None)  # and then it serves alone
    assert build_library(tmp_path / "cache") == lib


def test_a_failed_compile_names_its_last_error_line(tmp_path, monkeypatch):
    cc = _fake_compiler(tmp_path, "printf 'line one\\nline two\\nerror: boom\\n' >&2; exit 1")
    monkeypatch.setenv("CC", cc)
    with pytest.raises(MissingExtraError, match=r"does not compile with .*: \['error: boom'\]$"):
        build_library(tmp_path / "cache")
    cc = _fake_compiler(tmp_path, "printf 'caf\\351 \\377\\n' >&2; exit 1")  # not UTF-8
    monkeypatch.setenv("CC", cc)
    with pytest.raises(MissingExtraError, match="does not compile"):
        build_library(tmp_path / "cache")
    broken = tmp_path / "not-a-program"
    broken.write_bytes(b"\x7fELF garbage")
    broken.chmod(broken.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("CC", str(broken))
    with pytest.raises(MissingExtraError, match="does not run"):
        build_library(tmp_path / "cache")
    assert not [p for p in (tmp_path / "cache").iterdir() if p.is_dir()]  # no leftovers


# -- pixels and forests the predictor refuses ---------------------------------------------


def test_pixels_of_another_dtype_are_converted_and_bad_shapes_named(small):
    est, x = small
    predict = compile_forest(est)
    np.testing.assert_array_equal(predict(x.astype(np.float64)), predict(x))
    with pytest.raises(InvalidParameterError, match=r"expected shape \(n, 4\), got \(5, 3\)"):
        predict(np.zeros((5, 3), np.float32))
    broken = forest_predictor(dataclasses.replace(pack_forest(est), depth=-1))
    with pytest.raises(InvalidParameterError, match=r"refused the forest \(code -1\)"):
        broken(x)


def test_forests_beyond_the_kernel_are_refused_by_pack_forest(small, monkeypatch):
    rng = np.random.default_rng(1)
    x9 = rng.random((200, 9), dtype=np.float32)
    with pytest.raises(InvalidParameterError, match="1 to 8 features, not 9"):
        pack_forest(_forest(x9, (x9[:, 0] > 0.5).astype(int), n_estimators=2, max_depth=3))
    est, _ = small
    huge = dataclasses.make_dataclass("T", [("node_count", int), ("max_depth", int)])
    stub = type("Tree", (), {"tree_": huge(2**27 + 1, 3)})
    monkeypatch.setattr(est, "estimators_", [stub])
    with pytest.raises(InvalidParameterError, match="too many for the kernel"):
        pack_forest(est)


# -- the packed-forest file: what loads and what is refused -------------------------------


def _write(path, **arrays):
    fields = dict(model_sha256=np.zeros(0, np.uint8))
    fields.update(arrays)
    with open(path, "wb") as fh:
        np.savez(fh, **fields)
    return path


def _chain(depth: int, features: int = 1):
    """One tree: a chain of ``depth`` splits down the right, breadth-first (by hand)."""
    fshift = (features - 1).bit_length()
    total = 2 * depth + 1
    child = np.arange(total)
    inner = 2 * np.arange(depth)  # 0, 2, 4, ...: each internal node's right child splits
    child[inner] = inner + 1
    threshold = np.full(total, np.inf, np.float32)
    threshold[inner] = np.arange(depth, dtype=np.float32)
    return dict(
        threshold=np.concatenate([threshold, np.zeros(PAD, np.float32)]),
        code=np.concatenate([child << fshift, np.zeros(PAD, int)]).astype(np.int32),
        value=np.linspace(0, 1, total),
        roots=np.array([0], np.int32),
        depth=np.int64(depth),
        features=np.int64(features),
        fshift=np.int64(fshift),
    )


def test_forests_at_the_limits_load(tmp_path):
    """A single leaf (depth 0, one node), a chain exactly 64 deep, 1 to 8 features, one
    tree, and a one-leaf tree that is not the last: all valid, all loaded."""
    leaf = _chain(0)
    assert load_forest(_write(tmp_path / "leaf.npz", **leaf)).depth == 0
    assert load_forest(_write(tmp_path / "deep.npz", **_chain(MAX_DEPTH))).depth == MAX_DEPTH
    for features in (1, 3, 5, 8):
        back = load_forest(_write(tmp_path / f"f{features}.npz", **_chain(3, features)))
        assert (back.features, back.fshift) == (features, (features - 1).bit_length())
    two = _chain(2)
    both = dict(two)  # a one-leaf tree first, then the chain: roots 0 and 1
    both["threshold"] = np.concatenate([[np.inf], two["threshold"]]).astype(np.float32)
    shifted = two["code"][:5] + 1
    both["code"] = np.concatenate([[0], shifted, np.zeros(PAD, np.int32)]).astype(np.int32)
    both["value"] = np.concatenate([[0.5], two["value"]])
    both["roots"] = np.array([0, 1], np.int32)
    assert len(load_forest(_write(tmp_path / "two.npz", **both)).roots) == 2


@pytest.mark.parametrize(
    ("name", "change", "words"),
    [
        ("deeper than 64", lambda f: _chain(MAX_DEPTH + 1) | {"depth": np.int64(64)},
         "declared depth 64, the trees are 65 deep"),
        ("depth 65", lambda f: f | {"depth": np.int64(65)}, "out of the kernel's range"),
        ("depth -1", lambda f: f | {"depth": np.int64(-1)}, "out of the kernel's range"),
        ("2-d roots", lambda f: f | {"roots": f["roots"].reshape(1, 1)}, "one-dimensional"),
        ("fshift 3 for 1 feature", lambda f: f | {"fshift": np.int64(3)},
         "features 1 with fshift 3"),
        ("9 features", lambda f: f | {"features": np.int64(9), "fshift": np.int64(4)},
         "features 9 with fshift 4"),
        ("code one short", lambda f: f | {"code": f["code"][:-1]}, "lengths disagree"),
        ("threshold one short", lambda f: f | {"threshold": f["threshold"][:-1]},
         "lengths disagree"),
        ("a root past the nodes", lambda f: f | {"roots": np.array([0, 7], np.int32)},
         "tree roots are not increasing"),
        ("first root not 0", lambda f: f | {"roots": np.array([1], np.int32)},
         "tree roots are not increasing"),
        ("no roots", lambda f: f | {"roots": np.zeros(0, np.int32)},
         "tree roots are not increasing"),
        ("leaf values above 1", lambda f: f | {"value": f["value"] * 2}, "leaf values must lie"),
    ],
)  # fmt: skip
def test_broken_forests_are_refused(tmp_path, name, change, words):
    path = _write(tmp_path / "f.npz", **change(_chain(3)))  # the file name names nothing
    with pytest.raises(ModelFileError, match=words):
        load_forest(path)


def test_a_saved_forest_of_each_feature_count_round_trips(tmp_path):
    rng = np.random.default_rng(2)
    for features in (1, 3, 8):
        x = rng.random((300, features), dtype=np.float32)
        est = _forest(x, (x[:, -1] > 0.5).astype(int), n_estimators=2, max_depth=4)
        back = load_forest(save_forest(pack_forest(est), tmp_path / f"{features}.npz"))
        np.testing.assert_array_equal(
            forest_predictor(back)(x), est.predict_proba(x)[:, 1].astype(np.float32)
        )


def test_a_compiler_that_hangs_is_stopped(tmp_path, monkeypatch):
    monkeypatch.setattr(compiled, "COMPILE_TIMEOUT_S", 0.5)
    monkeypatch.setenv("CC", _fake_compiler(tmp_path, "sleep 5"))
    with pytest.raises(MissingExtraError, match="does not run .*timed out"):
        build_library(tmp_path / "cache")


def test_the_compile_happens_in_the_cache_not_in_the_temporary_directory(tmp_path, monkeypatch):
    """The half-built library sits beside its final name (one atomic rename), so a
    temporary directory elsewhere, or none at all, does not matter."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "no-such-directory"))
    assert build_library(tmp_path / "cache").is_file()


def test_a_forest_exactly_as_deep_as_the_kernel_takes_is_packed(tmp_path):
    x = np.arange(600, dtype=np.float32).reshape(-1, 1)
    y = (np.arange(600) // 2) % 2
    est = _forest(x, y, n_estimators=1, bootstrap=False, max_depth=MAX_DEPTH)
    assert est.estimators_[0].tree_.max_depth == MAX_DEPTH
    packed = pack_forest(est)
    assert packed.depth == MAX_DEPTH
    np.testing.assert_array_equal(
        forest_predictor(packed)(x), est.predict_proba(x)[:, 1].astype(np.float32)
    )


def test_a_nan_split_threshold_is_refused(small):
    import copy

    est = copy.deepcopy(small[0])
    est.estimators_[0].tree_.threshold[0] = np.nan  # a split no training makes
    with pytest.raises(InvalidParameterError, match="estimator: a split threshold is NaN"):
        pack_forest(est)


def test_a_forest_trained_with_missing_values_round_trips_through_its_file(tmp_path):
    """Missing-value splits carry +inf thresholds; packed as FLT_MAX they stay internal
    nodes, so the file loads (a +inf would read as a broken leaf) and predicts alike."""
    rng = np.random.default_rng(5)
    x = rng.random((2000, 4)).astype(np.float32)
    y = (x[:, 0] > 0.5).astype(int)
    x[rng.random(2000) < 0.2, 1] = np.nan
    y[np.isnan(x[:, 1])] = 1
    est = _forest(x, y, n_estimators=5, max_depth=6)
    assert any(np.isposinf(t.tree_.threshold).any() for t in est.estimators_)
    back = load_forest(save_forest(pack_forest(est), tmp_path / "forest.npz"))
    finite = rng.random((3000, 4)).astype(np.float32)
    np.testing.assert_array_equal(
        forest_predictor(back)(finite), est.predict_proba(finite)[:, 1].astype(np.float32)
    )


def test_cpu_runs_reads_cpuid_through_numpy_before_proc_cpuinfo(monkeypatch):
    """A Haswell as CPUID reports it (AVX2, no AVX-512), whatever /proc/cpuinfo says (under
    qemu-user it is the host's); with an older numpy lacking the names, /proc/cpuinfo."""
    monkeypatch.setattr(compiled.platform, "machine", lambda: "x86_64")
    haswell = {"AVX2": True, "FMA3": True, "BMI": True, "BMI2": True, "F16C": True,
               "MOVBE": True, "LZCNT": True, "AVX512F": False, "AVX512BW": False,
               "AVX512CD": False, "AVX512DQ": False, "AVX512VL": False}  # fmt: skip
    monkeypatch.setattr(compiled, "_cpuid_features", lambda: haswell)
    monkeypatch.setattr(compiled, "_cpu", lambda: "flags\t: avx2 avx512f avx512bw\n")
    assert (compiled.cpu_runs("avx2"), compiled.cpu_runs("avx512")) == (True, False)
    assert compiled._best_isa() == "avx2"
    monkeypatch.setattr(compiled, "_cpuid_features", lambda: {"AVX2": True})  # names missing
    flags = (
        "flags\t: fma bmi1 bmi2 f16c movbe abm avx2 avx512f avx512bw avx512cd avx512dq avx512vl\n"
    )
    monkeypatch.setattr(compiled, "_cpu", lambda: flags)
    assert (compiled.cpu_runs("avx2"), compiled.cpu_runs("avx512")) == (True, True)
    monkeypatch.setattr(compiled.platform, "machine", lambda: "aarch64")
    assert compiled._best_isa() is None and not compiled.cpu_runs("avx2")
