"""dyntarget's compiled forest kernel against scikit-learn's own prediction.

The expected values are always ``RandomForestClassifier.predict_proba``: a different
implementation (scikit-learn walks its node records one pixel at a time, in float64
comparisons), so every test here checks the packing and the kernel, never a formula
against itself. Both builds of the kernel are checked: the AVX-512 one (where this CPU
has it) and the portable one.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.errors import MissingExtraError
from dyntarget.perceive import compiled, load_classifier, make_classifier
from dyntarget.perceive.compiled import build_library, compile_forest, pack_forest

if compiled.compiler() is None:
    pytest.skip("no C compiler", allow_module_level=True)

BUILDS = [pytest.param(False, id="native"), pytest.param(True, id="portable")]


def _forest(x, y, **kw):
    from sklearn.ensemble import RandomForestClassifier

    return RandomForestClassifier(random_state=0, n_jobs=1, **kw).fit(x, y)


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def _reference(est, x):
    return est.predict_proba(x)[:, 1].astype(np.float32)


@pytest.mark.parametrize("portable", BUILDS)
def test_project_forest_equals_scikit_learn_on_a_scene(project_forest, tiny_scenes, portable):
    """A 50-tree, depth-14 forest on a held-out scene's pixels: bit-identical."""
    est = project_forest.estimator
    x = np.ascontiguousarray(tiny_scenes[3].image.reshape(4, -1).T)
    np.testing.assert_array_equal(compile_forest(est, portable=portable)(x), _reference(est, x))


@pytest.mark.parametrize("portable", BUILDS)
def test_pixels_on_and_beside_every_threshold_go_where_scikit_learn_sends_them(
    project_forest, portable
):
    """Pixels whose value equals a split's threshold rounded to float32, or is the next
    float32 up or down: the rounding of float64 thresholds must match ``x <= t``."""
    est = project_forest.estimator
    rng = np.random.default_rng(1)
    rows = []
    for tree in est.estimators_[:10]:
        t = tree.tree_
        inner = np.flatnonzero(t.children_left != -1)
        for k in inner[:40]:
            t32 = np.float32(t.threshold[k])
            for v in (t32, np.nextafter(t32, np.float32(np.inf)), np.nextafter(t32, np.float32(0))):
                row = rng.random(4, dtype=np.float32)
                row[t.feature[k]] = v
                rows.append(row)
    x = np.array(rows, np.float32)
    assert len(x) > 500
    np.testing.assert_array_equal(compile_forest(est, portable=portable)(x), _reference(est, x))


@pytest.mark.parametrize("portable", BUILDS)
@pytest.mark.parametrize("features", [1, 3, 5, 8])
def test_feature_counts_and_shallow_trees(features, portable):
    """1 to 8 features (1 to 4 bits of feature in the node code), trees shallower than the
    register-table levels, and pixel counts that leave partial groups and blocks."""
    rng = np.random.default_rng(features)
    x = rng.normal(size=(3000, features)).astype(np.float32)
    y = (x[:, 0] + 0.5 * x[:, -1] > 0.2).astype(int)
    for depth in (1, 3, 6, None):
        est = _forest(x, y, n_estimators=7, max_depth=depth, min_samples_leaf=3)
        predict = compile_forest(est, portable=portable)
        for n in (1, 17, 1025, 3000):
            np.testing.assert_array_equal(predict(x[:n]), _reference(est, x[:n]))


def test_a_tree_that_is_a_single_leaf():
    """A bootstrap sample with one class gives a tree with no split: its value is constant."""
    x = np.arange(40, dtype=np.float32).reshape(-1, 1)
    y = (x[:, 0] > 37).astype(int)  # two positives: some bootstrap samples miss both
    est = _forest(x, y, n_estimators=20)
    assert min(t.tree_.node_count for t in est.estimators_) == 1
    np.testing.assert_array_equal(compile_forest(est)(x), _reference(est, x))


def test_packing_by_hand():
    """A stump on one feature, packed by hand: breadth-first, children side by side,
    the float64 threshold rounded down to float32, leaves pointing to themselves."""
    x = np.array([[0.0], [0.1], [0.9], [1.0]], np.float32)
    est = _forest(x, [0, 0, 1, 1], n_estimators=1, bootstrap=False)
    t = est.estimators_[0].tree_
    packed = pack_forest(est)
    assert packed.fshift == 0 and packed.depth == 1 and list(packed.roots) == [0]
    # midpoint of 0.1 and 0.9 in float64, below the float32 nearest to it
    assert packed.threshold[0] <= t.threshold[0] < np.nextafter(packed.threshold[0], np.inf)
    assert list(packed.code[:3]) == [1, 1, 2]  # root -> node 1 (left) / 2 (right); leaves self
    assert np.isinf(packed.threshold[1:3]).all()
    assert list(packed.value[:3]) == [0.0, 0.0, 1.0]
    assert packed.node[0] == (1 << 32) | int(packed.threshold[:1].view(np.uint32)[0])


def test_the_kernel_is_built_once_per_build_and_cached(tmp_path, monkeypatch, project_forest):
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path))
    lib = build_library()
    assert lib.parent == tmp_path / "forests" and lib.is_file()
    stamp = lib.stat().st_mtime_ns
    assert build_library() == lib and lib.stat().st_mtime_ns == stamp
    assert build_library(portable=True) != lib
    assert len(list((tmp_path / "forests").glob("forest-kernel-*.so"))) == 2
    assert not [p for p in (tmp_path / "forests").iterdir() if p.is_dir()]  # no leftovers


def test_a_cached_build_serves_without_a_compiler(tmp_path, monkeypatch, project_forest):
    """A flight computer may get the cache built on the ground: no compiler needed then,
    and without either the refusal names the compiler."""
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path))
    lib = build_library()
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    assert build_library() == lib
    x = np.random.default_rng(4).uniform(0, 0.6, (300, 4)).astype(np.float32)
    np.testing.assert_array_equal(
        compile_forest(project_forest.estimator)(x), _reference(project_forest.estimator, x)
    )
    lib.unlink()
    with pytest.raises(MissingExtraError, match="C compiler"):
        build_library()


def test_bad_pixels_and_bad_forests_are_refused(project_forest):
    predict = compile_forest(project_forest.estimator)
    with pytest.raises(InvalidParameterError, match=r"expected shape \(n, 4\)"):
        predict(np.zeros((5, 3), np.float32))
    bad = np.zeros((5, 4), np.float32)
    bad[2, 1] = np.nan
    with pytest.raises(InvalidParameterError, match="NaN"):
        predict(bad)
    with pytest.raises(InvalidParameterError, match="RandomForestClassifier"):
        compile_forest(object())


def test_backends_through_the_classifier(project_forest, tiny_scenes, monkeypatch, tmp_path):
    """``auto`` (default), ``compiled`` and ``sklearn`` give the same probability maps;
    ``auto`` falls back to ONNX Runtime (else scikit-learn) without a compiler, ``compiled``
    says why (the fallback's own tests: test_ensemble.py)."""
    image = tiny_scenes[3].image
    ref = project_forest.estimator.predict_proba(image.reshape(4, -1).T)[:, 1]
    ref = ref.astype(np.float32).reshape(image.shape[1:])
    assert project_forest.backend == "auto"
    for backend in ("auto", "compiled", "sklearn"):
        got = project_forest.set_backend(backend).predict_proba(image)
        np.testing.assert_array_equal(got, ref)
    clone = pickle.loads(pickle.dumps(project_forest.set_backend("compiled")))
    np.testing.assert_array_equal(clone.predict_proba(image), ref)  # the kernel reloads

    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path))  # no cached build either
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    np.testing.assert_array_equal(project_forest.set_backend("auto").predict_proba(image), ref)
    fallback = project_forest._compiled[1]
    assert getattr(fallback, "isa", None) == ("onnxruntime" if _has("onnxruntime") else None)
    with pytest.raises(MissingExtraError, match="C compiler"):
        project_forest.set_backend("compiled").predict_proba(image)
    with pytest.raises(InvalidParameterError, match="backend: expected 'auto', 'sklearn', 'co"):
        project_forest.set_backend("gpu")


# -- the packed forest in an exported model directory (forest.npz) ----------------------


def _saved(project_forest, tmp_path):
    from dyntarget.perceive.compiled import save_forest

    return save_forest(pack_forest(project_forest.estimator), tmp_path / "forest.npz")


def _rewrite(path, **changes):
    with np.load(path) as npz:
        data = {k: npz[k] for k in npz.files}
    data.update(changes)
    with open(path, "wb") as fh:
        np.savez(fh, **data)
    return path


def test_a_saved_forest_loads_to_the_same_arrays_and_probabilities(project_forest, tmp_path):
    from dyntarget.perceive.compiled import forest_predictor, load_forest

    packed = pack_forest(project_forest.estimator)
    back = load_forest(_saved(project_forest, tmp_path))
    for name in ("threshold", "code", "node", "value", "roots"):
        np.testing.assert_array_equal(getattr(back, name), getattr(packed, name))
    assert (back.depth, back.features, back.fshift) == (packed.depth, 4, 2)
    x = np.random.default_rng(3).uniform(0, 0.6, (5000, 4)).astype(np.float32)
    np.testing.assert_array_equal(
        forest_predictor(back)(x), _reference(project_forest.estimator, x)
    )


def _hostile_cases(path):
    """(name, how to break the file, words the refusal must name)."""
    with np.load(path) as npz:
        code, thr, roots = npz["code"].copy(), npz["threshold"].copy(), npz["roots"]
    inner = int(np.flatnonzero(np.isfinite(thr[: len(thr) - 32]))[3])
    leaf = int(np.flatnonzero(np.isposinf(thr))[0])
    out_of_range, cycle, bad_leaf, bad_feature = code.copy(), code.copy(), code.copy(), code.copy()
    out_of_range[inner] = (10**6 << 2) | (code[inner] & 3)  # a child far past the nodes
    cycle[inner] = code[0] & ~3  # back to the root: a loop, not breadth-first
    bad_leaf[leaf] = (leaf + 1) << 2  # a leaf that walks on
    bad_feature[inner] = (code[inner] & ~3) | 3
    nan_thr = thr.copy()
    nan_thr[inner] = np.nan
    return [
        ("child out of range", dict(code=out_of_range), "breadth-first"),
        ("a cycle", dict(code=cycle), "breadth-first"),
        ("a leaf that moves", dict(code=bad_leaf), "leaf does not point to itself"),
        ("feature 3 of 3", dict(code=bad_feature, features=np.int64(3)), "features 3"),
        ("NaN threshold", dict(threshold=nan_thr), "NaN threshold"),
        ("deeper than declared", dict(depth=np.int64(13)), "declared depth 13"),
        ("declared too deep", dict(depth=np.int64(40)), "declared depth 40"),
        ("float64 codes", dict(code=code.astype(np.float64)), "code is not int32"),
        ("roots out of order", dict(roots=roots[::-1].copy()), "roots"),
        ("value above 1", dict(value=np.full(len(thr) - 32, 2.0)), "0..1"),
        ("depth as an array", dict(depth=np.array([14, 14])), "single numbers"),
        # int32 differences that wrap around: every step looks positive
        ("roots that overflow", dict(roots=np.array([0, 5, -(2**31) + 3, 1], np.int32)), "roots"),
        ("an extra member", dict(junk=np.zeros(10)), "members"),
        ("bound to another model", dict(model_sha256=np.ones(32, np.uint8)), "another model"),
    ]


def test_hostile_packed_forests_are_refused_naming_the_problem(project_forest, tmp_path):
    """Node indices are memory addresses to the kernel: every broken rule is refused with
    one line before any pixel reaches it."""
    from dyntarget.errors import ModelFileError
    from dyntarget.perceive.compiled import load_forest

    good = _saved(project_forest, tmp_path)
    for name, changes, words in _hostile_cases(good):
        bad = _rewrite(_copy(good, tmp_path / f"{name.replace(' ', '-')}.npz"), **changes)
        with pytest.raises(ModelFileError, match=words) as info:
            load_forest(bad, model_sha256="")  # saved unbound: "" is its binding
        assert "\n" not in str(info.value), name
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ModelFileError, match="unreadable"):
        load_forest(junk)
    pickled = _rewrite(_copy(good, tmp_path / "pickled.npz"), threshold=np.array([object()]))
    with pytest.raises(ModelFileError, match="threshold is not float32"):  # from its header
        load_forest(pickled)


def test_an_unreachable_cycle_is_refused(tmp_path):
    """A tree whose internal node 3 points to itself, with nodes 3 and 4 out of reach:
    breadth-first in its layout, but not a tree. Built by hand."""
    from dyntarget.errors import ModelFileError
    from dyntarget.perceive.compiled import PAD, load_forest

    inf = np.inf
    threshold = np.array([0.5, inf, inf, 0.5, inf] + [0.0] * PAD, np.float32)
    code = np.array([1, 1, 2, 3, 4] + [0] * PAD, np.int32)  # fshift 0: code = child
    path = tmp_path / "cycle.npz"
    with open(path, "wb") as fh:
        np.savez(fh, threshold=threshold, code=code, value=np.array([0, 0.2, 0.9, 0, 1.0]),
                 roots=np.array([0], np.int32), depth=np.int64(1), features=np.int64(1),
                 fshift=np.int64(0), model_sha256=np.zeros(0, np.uint8))  # fmt: skip
    with pytest.raises(ModelFileError, match="not reached from its tree's root"):
        load_forest(path)
    code[3] = 0  # a plain leaf at 3 (pointing at 0 is not itself): the leaf rule
    threshold[3] = inf
    _rewrite(path, code=code, threshold=threshold)
    with pytest.raises(ModelFileError, match="leaf does not point to itself"):
        load_forest(path)


def test_forests_beyond_the_kernel_fall_back_to_scikit_learn(tmp_path, monkeypatch):
    """Trees deeper than the kernel takes and multi-output forests are refused by
    pack_forest; the default backend then predicts with scikit-learn, and the ONNX
    export holds no forest.npz. A forest trained with missing values (+inf split
    thresholds) is packed, and agrees with scikit-learn on finite pixels."""
    from sklearn.ensemble import RandomForestClassifier

    from dyntarget.perceive.compiled import MAX_DEPTH

    x = np.arange(600, dtype=np.float32).reshape(-1, 1)
    y = (np.arange(600) // 2) % 2  # alternating pairs: a chain of splits
    deep = _forest(x, y, n_estimators=1, bootstrap=False)
    assert deep.estimators_[0].tree_.max_depth > MAX_DEPTH
    with pytest.raises(InvalidParameterError, match="deep"):
        pack_forest(deep)
    with pytest.raises(InvalidParameterError, match="single-output"):
        pack_forest(_forest(x, np.column_stack([y, 1 - y]), n_estimators=2))

    model = make_classifier("random-forest")
    model.estimator, model.fitted = deep, True
    px = np.zeros((4, 10, 60), np.float32)
    px[0] = (np.arange(600, dtype=np.float32) / 1000).reshape(10, 60)
    model.estimator = RandomForestClassifier(n_estimators=1, bootstrap=False, random_state=0)
    model.estimator.fit(np.column_stack([x[:, 0] / 1000] * 4), y)
    assert model.estimator.estimators_[0].tree_.max_depth > MAX_DEPTH
    ref = model.estimator.predict_proba(px.reshape(4, -1).T)[:, 1].astype(np.float32)
    np.testing.assert_array_equal(model.predict_proba(px).ravel(), ref)  # auto: scikit-learn
    assert model._compiled[1] is None

    rng = np.random.default_rng(5)
    xm = rng.random((2000, 2)).astype(np.float32)
    ym = (xm[:, 0] > 0.5).astype(int)
    xm[rng.random(2000) < 0.2, 1] = np.nan
    ym[np.isnan(xm[:, 1])] = 1
    with_nan = _forest(xm, ym, n_estimators=5, max_depth=6)
    assert any(np.isposinf(t.tree_.threshold).any() for t in with_nan.estimators_)
    finite = rng.random((3000, 2)).astype(np.float32)
    np.testing.assert_array_equal(compile_forest(with_nan)(finite), _reference(with_nan, finite))


def test_a_compiler_named_with_arguments(monkeypatch, tmp_path):
    """$CC as "gcc -O0" (a launcher or flags before the compiler) is found and used."""
    import shutil

    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("no gcc")
    monkeypatch.setenv("CC", "gcc -O0")
    assert compiled.compiler() == f"{gcc} -O0"
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path))
    assert build_library().is_file()
    monkeypatch.setenv("CC", "no-such-compiler-here")
    assert compiled.compiler() is None


def _copy(src, dst):
    dst.write_bytes(src.read_bytes())
    return dst


@pytest.mark.slow
def test_the_onnx_twin_of_a_forest_runs_the_kernel_from_its_export(
    project_forest, tiny_scenes, tmp_path
):
    """export-onnx writes forest.npz beside model.onnx; the twin runs it on the kernel,
    bit-identical to scikit-learn, ``kernel=False`` runs ONNX Runtime, and ``plan --onnx``
    refuses a broken forest.npz with one line and exit code 2."""
    pytest.importorskip("onnxruntime")
    from dyntarget.cli import main
    from dyntarget.io import write_scene
    from dyntarget.perceive.onnx import ENSEMBLE_BACKEND, SHIPPED_BACKEND, load_onnx
    from dyntarget.perceive.onnx_export import export_checked

    model_dir = tmp_path / "rf"
    project_forest.save(model_dir)
    image = tiny_scenes[3].image
    _, diff = export_checked(project_forest, model_dir, image)
    assert (model_dir / "forest.npz").is_file() and diff < 1e-4
    twin = load_onnx(model_dir)
    reference = project_forest.set_backend("sklearn").predict_proba(image)
    if twin.forest is not None:  # the kernel, or the double tree ensemble: bit-identical
        np.testing.assert_array_equal(twin.predict_proba(image), reference)
        assert twin.backend in ("forest kernel", ENSEMBLE_BACKEND, SHIPPED_BACKEND)
    else:  # neither (the lean install without a kernel): model.onnx's float32 sums
        np.testing.assert_allclose(twin.predict_proba(image), reference, rtol=0, atol=1e-6)
        assert twin.backend == "onnxruntime"
    ort = load_onnx(model_dir, kernel=False)
    assert ort.forest is None
    ort.predict_proba(image)
    assert ort.backend == "onnxruntime"

    # a model.onnx that is not the one the forest was exported with: refused, not mixed
    other = tmp_path / "other"
    make_classifier("random-forest", seed=1, max_pixels_per_class=500).fit(tiny_scenes[:2]).save(
        other
    )
    from dyntarget.errors import ModelFileError
    from dyntarget.perceive.onnx_export import export_onnx

    export_onnx(load_classifier(other), other)
    saved = (model_dir / "model.onnx").read_bytes()
    (model_dir / "model.onnx").write_bytes((other / "model.onnx").read_bytes())
    with pytest.raises(ModelFileError, match="another model.onnx"):
        load_onnx(model_dir)
    assert load_onnx(model_dir, kernel=False).forest is None  # ONNX Runtime on its own file
    (model_dir / "model.onnx").write_bytes(saved)

    scene = write_scene(tiny_scenes[3], tmp_path / "scene")[0]
    _rewrite(model_dir / "forest.npz", depth=np.int64(40))
    args = ["plan", str(scene), "--model", str(model_dir), "--onnx", "--planner", "track-center"]
    assert main([*args, "--out", str(tmp_path / "t.csv")]) == 2
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("isa", list(compiled.ISA_FLAGS))
def test_every_forced_path_equals_scikit_learn_bit_for_bit(
    project_forest, tiny_scenes, isa, tmp_path
):
    """Each code path of the kernel, forced by name; bit-identical where the CPU runs it."""
    if not compiled.cpu_runs(isa):
        pytest.skip(f"this CPU does not run the {isa} path")
    est = project_forest.estimator
    x = np.concatenate([s.image.reshape(4, -1).T for s in tiny_scenes]).astype(np.float32)
    predict = compile_forest(est, directory=tmp_path, isa=isa)
    assert predict.isa == ("sse2" if isa == "sse2" else isa)
    np.testing.assert_array_equal(predict(x), _reference(est, x))


@pytest.mark.slow
def test_a_forest_twin_left_to_onnx_runtime_says_so_once(
    project_forest, tiny_scenes, tmp_path, capsys, monkeypatch
):
    """No forest.npz beside model.onnx: ONNX Runtime's tree ensemble predicts, slower than
    the kernel, and one line on stderr says so however many frames are classified."""
    pytest.importorskip("onnxruntime")
    from dyntarget.perceive.onnx import load_onnx
    from dyntarget.perceive.onnx_export import export_checked

    model_dir = tmp_path / "rf"
    project_forest.save(model_dir)
    export_checked(project_forest, model_dir, tiny_scenes[3].image)
    (model_dir / "forest.npz").unlink()
    monkeypatch.setattr(compiled, "_SAID", set())
    capsys.readouterr()
    twin = load_onnx(model_dir)
    for scene in tiny_scenes[:3]:
        twin.predict_proba(scene.image)
    said = capsys.readouterr().err.strip().splitlines()
    assert twin.backend == "onnxruntime"
    assert len(said) == 1 and "ONNX Runtime's tree ensemble predicts" in said[0], said
    assert "slower than the kernel" in said[0]
    quiet = load_onnx(model_dir, kernel=False)  # asked for: nothing said
    monkeypatch.setattr(compiled, "_SAID", set())
    quiet.predict_proba(tiny_scenes[0].image)
    assert capsys.readouterr().err == ""
