"""The forest on ONNX Runtime's tree ensemble against scikit-learn's own prediction.

The expected values are ``RandomForestClassifier.predict_proba`` rounded to float32: a
different implementation (scikit-learn walks its own node records in float64), never the
graph run again. Where the graph's form could go wrong, a test picks the case that tells:
pixels on a split's threshold (``BRANCH_LEQ`` against ``BRANCH_LT``, double against float
thresholds), many trees (a float sum instead of a double one drifts), more than 80 trees
on few rows (ONNX Runtime's tree-parallel sum, which adds in another order).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from dyntarget import InvalidParameterError
from dyntarget.errors import MissingExtraError
from dyntarget.perceive import compiled
from dyntarget.perceive.compiled import pack_forest
from dyntarget.perceive.ensemble import ensemble_graph, ensemble_predictor, forest_digest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")
pytest.importorskip("sklearn")


def _forest(x, y, **kw):
    from sklearn.ensemble import RandomForestClassifier

    return RandomForestClassifier(random_state=0, n_jobs=1, **kw).fit(x, y)


def _reference(est, x):
    return est.predict_proba(x)[:, 1].astype(np.float32)


def _reference_map(est, image):
    """scikit-learn's plume probability of every pixel of a ``(4, H, W)`` image."""
    return _reference(est, image.reshape(4, -1).T).reshape(image.shape[1:])


def test_project_forest_equals_scikit_learn_on_a_scene(project_forest, tiny_scenes, tmp_path):
    """A 50-tree, depth-14 forest on a held-out scene's pixels: bit-identical."""
    est = project_forest.estimator
    x = np.ascontiguousarray(tiny_scenes[3].image.reshape(4, -1).T)
    got = ensemble_predictor(pack_forest(est), directory=tmp_path)(x)
    np.testing.assert_array_equal(got, _reference(est, x))


def test_pixels_on_and_beside_every_threshold_go_where_scikit_learn_sends_them(
    project_forest, tmp_path
):
    """A pixel equal to a split's threshold goes left (``x <= t``); the next float32 up goes
    right. A graph with ``BRANCH_LT``, or thresholds rounded to nearest, sends some wrong."""
    est = project_forest.estimator
    rng = np.random.default_rng(1)
    rows = []
    for tree in est.estimators_[:10]:
        t = tree.tree_
        for k in np.flatnonzero(t.children_left != -1)[:40]:
            t32 = np.float32(t.threshold[k])
            for v in (t32, np.nextafter(t32, np.float32(np.inf)), np.nextafter(t32, np.float32(0))):
                row = rng.random(4, dtype=np.float32)
                row[t.feature[k]] = v
                rows.append(row)
    x = np.array(rows, np.float32)
    assert len(x) > 500
    got = ensemble_predictor(pack_forest(est), directory=tmp_path)(x)
    np.testing.assert_array_equal(got, _reference(est, x))


@pytest.mark.parametrize("trees, rows", [(120, 1), (120, 100), (120, 5000), (7, 3)])
def test_many_trees_on_few_and_many_rows_equal_scikit_learn(trees, rows, tmp_path):
    """120 trees on 1 to 5000 rows (where ONNX Runtime could split the trees between
    threads) and 7 trees on 3: bit-identical. It does not prove the order of the sum: after
    rounding to float32 another order would rarely show (docs/reliability.md)."""
    rng = np.random.default_rng(trees + rows)
    x = rng.normal(size=(5000, 4)).astype(np.float32)
    y = (x[:, 0] + 0.5 * x[:, 3] + 0.3 * rng.normal(size=5000) > 0.1).astype(int)
    est = _forest(x, y, n_estimators=trees, min_samples_leaf=2)
    predict = ensemble_predictor(pack_forest(est), directory=tmp_path)
    np.testing.assert_array_equal(predict(x[:rows]), _reference(est, x[:rows]))


def test_a_float32_sum_would_not_be_bit_identical(tmp_path):
    """The double graph is needed: the same forest summed in float32 (ONNX Runtime's
    float graph, what skl2onnx writes) differs from scikit-learn on some pixels."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(20000, 4)).astype(np.float32)
    y = (x[:, 0] * x[:, 1] + 0.4 * rng.normal(size=20000) > 0).astype(int)
    est = _forest(x, y, n_estimators=50, min_samples_leaf=3)
    ref = _reference(est, x)
    float_sum = np.zeros(len(x), np.float32)
    for tree in est.estimators_:  # what a float accumulator does, tree by tree
        float_sum += tree.predict_proba(x)[:, 1].astype(np.float32)
    assert ((float_sum / np.float32(50)) != ref).any()  # the case exists on this forest
    predict = ensemble_predictor(pack_forest(est), directory=tmp_path)
    np.testing.assert_array_equal(predict(x), ref)


def test_float64_pixels_are_rounded_to_float32_first_as_scikit_learn_does(project_forest, tmp_path):
    """scikit-learn (and the kernel) compare float32 pixels: a float64 pixel above a split's
    threshold whose float32 rounding is not goes left there, and must here too."""
    est = project_forest.estimator
    rows = []
    for tree in est.estimators_:
        t = tree.tree_
        for k in np.flatnonzero(t.children_left != -1):
            t64 = t.threshold[k]
            lo = np.float32(t64)
            lo = lo if lo <= t64 else np.nextafter(lo, np.float32(-np.inf))  # float32 below
            hi = np.nextafter(lo, np.float32(np.inf))
            if (t64 - lo) < 0.25 * (hi - lo):
                v = t64 + 0.125 * (np.float64(hi) - np.float64(lo))  # right in float64 ...
                assert v > t64 and np.float32(v) <= t64  # ... left once rounded to float32
                row = np.full(4, 0.3)
                row[t.feature[k]] = v
                rows.append(row)
    x = np.array(rows, np.float64)
    assert len(x) > 20
    predict = ensemble_predictor(pack_forest(est), directory=tmp_path)
    np.testing.assert_array_equal(predict(x), _reference(est, x))


def test_bad_pixels_are_refused_as_the_kernel_refuses_them(project_forest, tmp_path):
    """NaN or infinite pixels and a wrong number of features: one clear error each."""
    predict = ensemble_predictor(project_forest.packed(), directory=tmp_path)
    x = np.zeros((4, 4), np.float32)
    x[2, 1] = np.nan
    with pytest.raises(InvalidParameterError, match=r"^pixels: hold NaN or infinite values$"):
        predict(x)
    with pytest.raises(InvalidParameterError, match=r"expected shape \(n, 4\), got \(4, 3\)"):
        predict(np.zeros((4, 3), np.float32))
    empty = predict(np.zeros((0, 4), np.float32))
    assert empty.shape == (0,) and empty.dtype == np.float32
    assert predict.isa == "onnxruntime" and predict.vectorised is False and not predict.shipped


def test_the_graph_is_cached_by_forest_and_read_back_without_onnx(project_forest, tmp_path):
    """The first predictor writes ``ensemble-<digest>.onnx`` (owner-only folder); a fresh
    interpreter with ``onnx`` made unimportable predicts the same from it."""
    packed = project_forest.packed()
    ensemble_predictor(packed, directory=tmp_path)
    cached = tmp_path / f"ensemble-{forest_digest(packed)}.onnx"
    assert cached.read_bytes() == ensemble_graph(packed)
    np.save(tmp_path / "x.npy", np.linspace(0, 1, 400, dtype=np.float32).reshape(100, 4))
    probe = (
        "import sys, numpy as np\n"
        "sys.modules['onnx'] = None  # import onnx now fails\n"
        "from dyntarget.perceive.compiled import load_forest\n"
        "from dyntarget.perceive.ensemble import ensemble_predictor\n"
        f"packed = load_forest({str(tmp_path / 'forest.npz')!r})\n"
        f"p = ensemble_predictor(packed, directory={str(tmp_path)!r})\n"
        f"np.save({str(tmp_path / 'got.npy')!r}, p(np.load({str(tmp_path / 'x.npy')!r})))\n"
    )
    compiled.save_forest(packed, tmp_path / "forest.npz")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    x = np.load(tmp_path / "x.npy")
    np.testing.assert_array_equal(
        np.load(tmp_path / "got.npy"), _reference(project_forest.estimator, x)
    )


def test_a_second_predictor_reads_the_cached_graph_and_says_nothing(
    project_forest, tiny_scenes, tmp_path, monkeypatch, capsys
):
    """The first predictor builds the graph into a new owner-only cache folder; the next one
    reads it back with ``onnx`` unimportable (it could not build one), bit for bit, and
    nothing is said on stderr when no shipped graph was given."""
    cache = tmp_path / "a" / "b"
    monkeypatch.setattr(compiled, "_SAID", set())
    capsys.readouterr()
    ensemble_predictor(project_forest.packed(), directory=cache)
    assert oct(cache.stat().st_mode & 0o777) == "0o700"
    monkeypatch.setitem(sys.modules, "onnx", None)
    predict = ensemble_predictor(project_forest.packed(), directory=cache)
    x = np.ascontiguousarray(tiny_scenes[3].image.reshape(4, -1).T)
    np.testing.assert_array_equal(predict(x), _reference(project_forest.estimator, x))
    assert capsys.readouterr().err == ""


def test_without_onnx_and_no_cached_graph_it_says_what_to_install(
    project_forest, tmp_path, monkeypatch
):
    monkeypatch.setitem(sys.modules, "onnx", None)
    with pytest.raises(
        MissingExtraError,
        match=r"^onnx is not installed; the forest's ONNX Runtime graph is built with it: "
        r"pip install 'dyntarget\[full\]'$",
    ):
        ensemble_predictor(project_forest.packed(), directory=tmp_path)


def test_a_damaged_cached_graph_is_built_again(project_forest, tiny_scenes, tmp_path):
    packed = project_forest.packed()
    cached = tmp_path / f"ensemble-{forest_digest(packed)}.onnx"
    cached.write_bytes(b"\x08\x08not a model")
    x = np.ascontiguousarray(tiny_scenes[3].image.reshape(4, -1).T)
    got = ensemble_predictor(packed, directory=tmp_path)(x)
    np.testing.assert_array_equal(got, _reference(project_forest.estimator, x))
    assert cached.read_bytes() == ensemble_graph(packed)


def test_a_folder_others_may_write_gets_no_graph(project_forest, tmp_path):
    """A graph is data ONNX Runtime trusts: never left where another user could swap it
    (the folder's mode decides, for root too); the predictor still runs."""
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o777)
    predict = ensemble_predictor(project_forest.packed(), directory=shared)
    assert not list(shared.iterdir())
    assert predict(np.zeros((3, 4), np.float32)).shape == (3,)


def test_auto_falls_back_to_onnxruntime_then_to_scikit_learn(
    project_forest, tiny_scenes, monkeypatch, tmp_path
):
    """No kernel (no compiler, nothing cached): ``auto`` runs ONNX Runtime; without
    onnxruntime, scikit-learn. Same probabilities on all three; the path is recorded."""
    from dyntarget.evaluate.bench import forest_path

    image = tiny_scenes[3].image
    ref = _reference_map(project_forest.estimator, image)
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path))
    monkeypatch.delenv(compiled.ISA_ENV, raising=False)
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    np.testing.assert_array_equal(project_forest.set_backend("auto").predict_proba(image), ref)
    assert forest_path(project_forest) == "onnxruntime"
    forced = project_forest.set_backend("onnxruntime")
    np.testing.assert_array_equal(forced.predict_proba(image), ref)
    assert forest_path(forced) == "onnxruntime"
    monkeypatch.setitem(sys.modules, "onnxruntime", None)  # not installed
    np.testing.assert_array_equal(project_forest.set_backend("auto").predict_proba(image), ref)
    assert forest_path(project_forest) == "sklearn"
    with pytest.raises(
        MissingExtraError,
        match=r"^onnxruntime is not installed; pip install 'dyntarget\[onboard\]'$",
    ):
        project_forest.set_backend("onnxruntime").predict_proba(image)


def test_the_kernel_off_runs_onnxruntime(project_forest, tiny_scenes, monkeypatch, tmp_path):
    """``DYNTARGET_FOREST_ISA=off`` is a machine without the kernel: the portable path."""
    from dyntarget.evaluate.bench import forest_path

    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path))
    monkeypatch.setenv(compiled.ISA_ENV, "off")
    image = tiny_scenes[3].image
    ref = _reference_map(project_forest.estimator, image)
    np.testing.assert_array_equal(project_forest.set_backend("auto").predict_proba(image), ref)
    assert forest_path(project_forest) == "onnxruntime"


# -- the graph shipped in an exported model directory (forest.onnx) -----------------------


@pytest.fixture
def exported(project_forest, tiny_scenes, tmp_path):
    """The project forest saved and exported (model.onnx, forest.npz, forest.onnx)."""
    from dyntarget.perceive.onnx_export import export_checked

    model_dir = tmp_path / "rf"
    project_forest.save(model_dir)
    export_checked(project_forest, model_dir, tiny_scenes[3].image)
    return model_dir


def _no_cache(monkeypatch, tmp_path, isa="off"):
    """An empty cache, the kernel's path forced to ``isa`` (``None``: this CPU's), nothing
    said yet."""
    if isa is not None:
        monkeypatch.setenv(compiled.ISA_ENV, isa)
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path / "empty-cache"))
    monkeypatch.setattr(compiled, "_SAID", set())


def _as_lean(monkeypatch, tmp_path):
    """No kernel, no cached graph, no ``onnx``: what the onboard install has on aarch64."""
    _no_cache(monkeypatch, tmp_path)
    monkeypatch.setitem(sys.modules, "onnx", None)


def test_the_lean_install_runs_the_shipped_graph_bit_for_bit(
    exported, project_forest, tiny_scenes, monkeypatch, tmp_path
):
    from dyntarget.perceive.ensemble import GRAPH_FILE
    from dyntarget.perceive.onnx import SHIPPED_BACKEND, load_onnx

    assert (exported / GRAPH_FILE).is_file()
    _as_lean(monkeypatch, tmp_path)
    image = tiny_scenes[3].image
    twin = load_onnx(exported)
    got = twin.predict_proba(image)
    assert twin.backend == SHIPPED_BACKEND and twin._kernel.shipped
    ref = _reference_map(project_forest.estimator, image)
    np.testing.assert_array_equal(got, ref)
    assert not (tmp_path / "empty-cache").exists() or not list(
        (tmp_path / "empty-cache").rglob("*.onnx")
    )


def test_a_shipped_graph_of_another_forest_is_not_run(
    exported, tiny_scenes, monkeypatch, tmp_path, capsys
):
    """forest.onnx swapped for another forest's graph: said once, model.onnx runs instead."""
    from dyntarget.perceive import make_classifier
    from dyntarget.perceive.ensemble import GRAPH_FILE
    from dyntarget.perceive.onnx import load_onnx

    other = make_classifier("random-forest", seed=1, max_pixels_per_class=500).fit(tiny_scenes[:2])
    (exported / GRAPH_FILE).write_bytes(ensemble_graph(other.packed()))
    _as_lean(monkeypatch, tmp_path)
    capsys.readouterr()
    twin = load_onnx(exported)
    twin.predict_proba(tiny_scenes[3].image)
    twin.predict_proba(tiny_scenes[2].image)
    said = [line for line in capsys.readouterr().err.splitlines() if GRAPH_FILE in line]
    assert twin.backend == "onnxruntime"  # model.onnx
    assert said == [
        f"dyntarget: {exported / GRAPH_FILE}: its dyntarget_forest_sha256 names another "
        "forest, not this forest.npz's; not used"
    ], said


@pytest.mark.parametrize("what", ["no metadata", "not a model"])
def test_the_line_for_a_shipped_graph_says_why_it_is_not_run(
    exported, tiny_scenes, monkeypatch, tmp_path, capsys, what
):
    """A graph without the forest's digest in its metadata names no forest; an empty file
    passes the graph checks (no node at all) but ONNX Runtime does not open it."""
    import onnx

    from dyntarget.perceive.ensemble import GRAPH_FILE
    from dyntarget.perceive.onnx import load_onnx

    shipped = exported / GRAPH_FILE
    if what == "no metadata":
        model = onnx.load_from_string(shipped.read_bytes())
        del model.metadata_props[:]
        shipped.write_bytes(model.SerializeToString())
    else:
        shipped.write_bytes(b"")
    _as_lean(monkeypatch, tmp_path)
    capsys.readouterr()
    load_onnx(exported).predict_proba(tiny_scenes[3].image)
    (said,) = [line for line in capsys.readouterr().err.splitlines() if GRAPH_FILE in line]
    if what == "no metadata":
        assert said == (
            f"dyntarget: {shipped}: its dyntarget_forest_sha256 names no forest, "
            "not this forest.npz's; not used"
        )
    else:
        opened = f"dyntarget: {shipped}: ONNX Runtime does not open it ("
        assert said.startswith(opened) and "NoneType" not in said, said


def test_a_shipped_graph_with_control_flow_is_never_run(
    exported, project_forest, tiny_scenes, monkeypatch, tmp_path, capsys
):
    """forest.onnx is checked as model.onnx is, on the bytes that would run: a Loop operator
    is said once and the graph left; the forest still predicts, bit for bit."""
    from onnx import TensorProto, helper

    from dyntarget.perceive.ensemble import GRAPH_FILE
    from dyntarget.perceive.onnx import ENSEMBLE_BACKEND, load_onnx

    body = helper.make_graph([], "body", [], [])
    loop = helper.make_node("Loop", ["n", "c"], [], body=body)
    graph = helper.make_graph(
        [loop], "g",
        [helper.make_tensor_value_info("n", TensorProto.INT64, []),
         helper.make_tensor_value_info("c", TensorProto.BOOL, [])], [],
    )  # fmt: skip
    (exported / GRAPH_FILE).write_bytes(helper.make_model(graph).SerializeToString())
    _no_cache(monkeypatch, tmp_path)
    capsys.readouterr()
    twin = load_onnx(exported)
    image = tiny_scenes[3].image
    got = twin.predict_proba(image)
    said = [line for line in capsys.readouterr().err.splitlines() if GRAPH_FILE in line]
    assert len(said) == 1 and "holds a Loop node" in said[0] and said[0].endswith("not used")
    assert twin.forest_graph is None and twin.backend == ENSEMBLE_BACKEND  # built here
    ref = _reference_map(project_forest.estimator, image)
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("isa", ["off", None])
def test_a_damaged_shipped_graph_does_not_stop_the_model(
    exported, project_forest, tiny_scenes, monkeypatch, tmp_path, capsys, isa
):
    """A truncated forest.onnx: said once, not used; the model loads and predicts bit for
    bit, on the kernel where it runs, else on a graph built here."""
    from dyntarget.perceive.ensemble import GRAPH_FILE
    from dyntarget.perceive.onnx import load_onnx

    data = (exported / GRAPH_FILE).read_bytes()
    (exported / GRAPH_FILE).write_bytes(data[: len(data) // 2])
    _no_cache(monkeypatch, tmp_path, isa)
    capsys.readouterr()
    twin = load_onnx(exported)
    image = tiny_scenes[3].image
    got = twin.predict_proba(image)
    err = capsys.readouterr().err
    assert err.count(f"{exported / GRAPH_FILE}") == 1 and "not used" in err, err
    ref = _reference_map(project_forest.estimator, image)
    np.testing.assert_array_equal(got, ref)


def test_a_cached_graph_in_a_folder_others_may_write_is_not_read(
    project_forest, tmp_path, monkeypatch
):
    """The right graph, planted under its right name in a folder others may write: not
    read (it could have been swapped), so with no onnx to build one nothing runs."""
    from dyntarget.perceive.ensemble import ensemble_graph, forest_digest

    shared = tmp_path / "shared"
    shared.mkdir()
    packed = project_forest.packed()
    (shared / f"ensemble-{forest_digest(packed)}.onnx").write_bytes(ensemble_graph(packed))
    os.chmod(shared, 0o777)
    monkeypatch.setitem(sys.modules, "onnx", None)
    with pytest.raises(MissingExtraError, match="onnx is not installed"):
        ensemble_predictor(packed, directory=shared)
    os.chmod(shared, 0o700)  # the same folder, ours alone: read
    assert ensemble_predictor(packed, directory=shared)(np.zeros((2, 4), np.float32)).shape == (2,)


def test_the_cached_graph_is_ours_alone_whatever_the_umask(project_forest, tmp_path):
    old = os.umask(0)
    try:
        ensemble_predictor(project_forest.packed(), directory=tmp_path / "cache")
    finally:
        os.umask(old)
    (graph,) = (tmp_path / "cache").glob("ensemble-*.onnx")
    assert oct(graph.stat().st_mode & 0o777) == "0o600"


def test_a_forest_too_large_for_a_graph_runs_elsewhere(
    project_forest, tiny_scenes, tmp_path, monkeypatch
):
    """More nodes than MAX_GRAPH_NODES: no graph is built (its build would need gigabytes);
    ``auto`` without a kernel runs scikit-learn, and export ships no forest.onnx."""
    from dyntarget.evaluate.bench import forest_path
    from dyntarget.perceive import ensemble
    from dyntarget.perceive.ensemble import GRAPH_FILE
    from dyntarget.perceive.onnx_export import export_onnx

    nodes = len(project_forest.packed().value)
    monkeypatch.setattr(ensemble, "MAX_GRAPH_NODES", nodes)
    assert ensemble_graph(project_forest.packed())  # at the limit: built
    monkeypatch.setattr(ensemble, "MAX_GRAPH_NODES", nodes - 1)
    message = (
        f"^forest: {nodes:,} nodes, more than the {nodes - 1:,} built as an ONNX Runtime graph$"
    )
    with pytest.raises(InvalidParameterError, match=message):
        ensemble_graph(project_forest.packed())
    monkeypatch.setenv("DYNTARGET_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv(compiled.ISA_ENV, "off")
    project_forest.set_backend("auto").predict_proba(tiny_scenes[3].image)
    assert forest_path(project_forest) == "sklearn"
    model_dir = tmp_path / "rf"
    project_forest.save(model_dir)
    export_onnx(project_forest, model_dir)
    assert (model_dir / "forest.npz").is_file() and not (model_dir / GRAPH_FILE).exists()


def test_a_graph_too_large_for_load_onnx_is_not_shipped(project_forest, tmp_path, monkeypatch):
    """A graph over load_onnx's size limit is not written (it would only be refused there);
    forest.npz still is, and an earlier forest.onnx is not left behind."""
    from dyntarget.perceive import validate
    from dyntarget.perceive.ensemble import GRAPH_FILE
    from dyntarget.perceive.onnx_export import export_onnx

    model_dir = tmp_path / "rf"
    project_forest.save(model_dir)
    export_onnx(project_forest, model_dir)
    size = (model_dir / GRAPH_FILE).stat().st_size
    monkeypatch.setattr(validate, "MAX_ONNX_BYTES", size - 1)
    export_onnx(project_forest, model_dir)
    assert (model_dir / "forest.npz").is_file() and not (model_dir / GRAPH_FILE).exists()
    monkeypatch.setattr(validate, "MAX_ONNX_BYTES", size)
    export_onnx(project_forest, model_dir)
    assert (model_dir / GRAPH_FILE).stat().st_size == size
