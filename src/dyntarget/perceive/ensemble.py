"""A packed random forest on ONNX Runtime's tree ensemble, bit-identical to the kernel.

Where dyntarget's forest kernel (:mod:`dyntarget.perceive.compiled`) cannot run (no C
compiler and no installed kernel, e.g. an aarch64 computer; or a path measured slower
than the alternatives), the forest would otherwise fall back to scikit-learn's
``predict_proba``, which walks one pixel at a time through 64-byte node records and is
imported whole (docs/performance.md: 3-9× the kernel's whole-process time). This module
gives the forest a third path: one ``TreeEnsembleRegressor`` node (``ai.onnx.ml`` opset 3)
that ONNX Runtime walks in C++ for any CPU it ships wheels for.

Bit for bit. The graph holds the forest in double precision (``nodes_values_as_tensor``,
``target_weights_as_tensor``) and takes the pixels as ``float64``: every float32 pixel
and every threshold is exact in double, so each split goes the way scikit-learn's
(float32 pixel against a float64 threshold) goes; with ``aggregate_function="AVERAGE"``
ONNX Runtime adds the leaves' plume fractions in double, in tree order, from zero, divides
by the number of trees and rounds to float32 once -- what the kernel and
``RandomForestClassifier.predict_proba`` (rounded to float32) do. ONNX Runtime may split
the *trees* of a forest between its threads and merge their partial sums (its kernel does
so for many trees and few rows), which would add in another order; every session here
runs one intra-op thread, and the pixel classifiers' chunk pool runs chunks in parallel
instead, as it does the kernel (bit-identity tested up to 120 trees, 1 to 5000 rows).

The graph is built with ``onnx`` (the full install) and kept in this user's private cache
(:func:`dyntarget.perceive.compiled.cache_dir`) under the SHA-256 of the forest's arrays,
so a later process reads it without importing ``onnx`` (about half a second of start-up).
``export-onnx`` also writes it into the model directory (:data:`GRAPH_FILE`) for the lean
install, which has no ``onnx`` to build it. Every graph carries the digest of its forest in
its metadata (:data:`DIGEST_KEY`) and runs only for that forest (against mixing two models'
files; like ``forest.npz``, its contents are trusted data).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError, MissingExtraError
from dyntarget.perceive.compiled import PackedForest

GRAPH_FORMAT = 2
"""Version of the graph's form (part of :func:`forest_digest`: a new form is built anew)."""

GRAPH_FILE = "forest.onnx"
"""The graph in an exported model directory, beside ``forest.npz`` (``export-onnx``): the
lean install, which cannot build it (no ``onnx``), runs the forest bit for bit from it."""

DIGEST_KEY = "dyntarget_forest_sha256"
"""The graph's metadata entry holding :func:`forest_digest` of the forest it was built from:
a graph is used only for the forest it names (checked on the session ONNX Runtime opened)."""

MAX_GRAPH_NODES = 4_000_000
"""Most nodes a forest may have to be built as a graph (about 150 MB serialized, 37 B a
node; building it through ``onnx``'s helpers peaks near 700 B a node, 2.8 GB here). A
larger forest runs on the kernel or scikit-learn."""

MAX_GRAPH_BYTES = 1 << 28
"""Largest cached graph read back (one of :data:`MAX_GRAPH_NODES` nodes is below it)."""


def forest_digest(packed: PackedForest) -> str:
    """Hex SHA-256 of a packed forest's arrays and numbers: its name in the cache.

    Parameters
    ----------
    packed : PackedForest
        The forest.

    Returns
    -------
    str
        64 hex digits; equal for equal forests wherever they came from.

    Examples
    --------
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> from dyntarget.perceive.compiled import pack_forest
    >>> x = np.array([[0.0], [1.0], [2.0], [3.0]], np.float32)
    >>> est = RandomForestClassifier(n_estimators=2, random_state=0).fit(x, [0, 0, 1, 1])
    >>> forest_digest(pack_forest(est)) == forest_digest(pack_forest(est))
    True
    """
    h = hashlib.sha256(f"dyntarget-ensemble-{GRAPH_FORMAT}".encode())
    for name in ("threshold", "code", "value", "roots"):
        array = np.ascontiguousarray(getattr(packed, name))
        h.update(f"{name}:{array.dtype.str}:{array.shape}".encode())
        h.update(array.tobytes())
    h.update(f"{packed.depth}:{packed.features}:{packed.fshift}".encode())
    return h.hexdigest()


def ensemble_graph(packed: PackedForest) -> bytes:
    """The forest as one double-precision ``TreeEnsembleRegressor`` (serialized ONNX).

    Parameters
    ----------
    packed : PackedForest
        The forest (:func:`~dyntarget.perceive.compiled.pack_forest` or
        :func:`~dyntarget.perceive.compiled.load_forest`).

    Returns
    -------
    bytes
        A model with input ``pixels`` ``(n, features) float64`` and output ``plume``
        ``(n, 1) float32``, the plume probability (see the module); its metadata
        :data:`DIGEST_KEY` names the forest.

    Raises
    ------
    MissingExtraError
        ``onnx`` is not installed (``pip install 'dyntarget[full]'``).
    InvalidParameterError
        The forest has more than :data:`MAX_GRAPH_NODES` nodes.

    Examples
    --------
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> from dyntarget.perceive.compiled import pack_forest
    >>> x = np.array([[0.0], [1.0], [2.0], [3.0]], np.float32)
    >>> est = RandomForestClassifier(n_estimators=2, random_state=0).fit(x, [0, 0, 1, 1])
    >>> ensemble_graph(pack_forest(est))[:2]  # a protobuf: field 1 (ir_version), a varint
    b'\\x08\\x08'
    """
    if len(packed.value) > MAX_GRAPH_NODES:
        raise InvalidParameterError(
            f"forest: {len(packed.value):,} nodes, more than the {MAX_GRAPH_NODES:,} "
            "built as an ONNX Runtime graph"
        )
    try:
        from onnx import TensorProto, helper
    except ImportError:
        raise MissingExtraError(
            "onnx is not installed; the forest's ONNX Runtime graph is built with it: "
            "pip install 'dyntarget[full]'"
        ) from None
    total, ntrees = len(packed.value), len(packed.roots)
    starts = np.asarray(packed.roots, np.int64)
    tree = np.repeat(np.arange(ntrees), np.diff([*starts.tolist(), total]))
    local = np.arange(total) - starts[tree]  # node ids within their tree
    leaf = np.isposinf(packed.threshold[:total])  # a leaf points to itself with +inf
    child = (packed.code[:total] >> packed.fshift) - starts[tree]  # left; right is next to it
    feature = packed.code[:total] & ((1 << packed.fshift) - 1)
    threshold = np.where(leaf, 0.0, packed.threshold[:total].astype(np.float64))
    weights = packed.value[leaf].astype(np.float64)
    node = helper.make_node(
        "TreeEnsembleRegressor", ["pixels"], ["plume"], domain="ai.onnx.ml",
        nodes_treeids=tree.tolist(), nodes_nodeids=local.tolist(),
        nodes_featureids=np.where(leaf, 0, feature).tolist(),
        nodes_values_as_tensor=helper.make_tensor(
            "nodes_values", TensorProto.DOUBLE, [total], threshold.tolist()
        ),
        nodes_modes=["LEAF" if is_leaf else "BRANCH_LEQ" for is_leaf in leaf.tolist()],
        nodes_truenodeids=np.where(leaf, 0, child).tolist(),
        nodes_falsenodeids=np.where(leaf, 0, child + 1).tolist(),
        target_treeids=tree[leaf].tolist(), target_nodeids=local[leaf].tolist(),
        target_ids=[0] * len(weights),
        target_weights_as_tensor=helper.make_tensor(
            "target_weights", TensorProto.DOUBLE, [len(weights)], weights.tolist()
        ),
        n_targets=1, aggregate_function="AVERAGE", post_transform="NONE",
    )  # fmt: skip
    graph = helper.make_graph(
        [node],
        "plume-probability",
        [helper.make_tensor_value_info("pixels", TensorProto.DOUBLE, [None, packed.features])],
        [helper.make_tensor_value_info("plume", TensorProto.FLOAT, [None, 1])],
    )
    model = helper.make_model(
        graph,
        opset_imports=[helper.make_opsetid("", 17), helper.make_opsetid("ai.onnx.ml", 3)],
        producer_name="dyntarget",
    )
    model.ir_version = 8  # what every ONNX Runtime since 1.10 reads
    helper.set_model_props(model, {DIGEST_KEY: forest_digest(packed)})
    return model.SerializeToString()


def _cached_graph(
    packed: PackedForest, directory: Path | None, digest: str, *, fresh: bool = False
) -> bytes:
    """The forest's graph from this user's cache, else built and put there (where it can be).

    ``digest`` is the forest's :func:`forest_digest` (the graph's name); ``fresh`` builds it
    anew whatever the cache holds (the cached one did not load).
    """
    from dyntarget.io.atomic import write_bytes
    from dyntarget.io.safeopen import read_bytes
    from dyntarget.perceive.compiled import _private, cache_dir

    where = Path(directory) if directory is not None else cache_dir()
    path = where / f"ensemble-{digest}.onnx"
    ours = os.path.isdir(where) and _private(where) is None  # no one else can swap a file in it
    if not fresh and ours and os.path.lexists(path) and _private(path) is None and path.is_file():
        try:
            return read_bytes(path, max_bytes=MAX_GRAPH_BYTES)
        except (OSError, ValueError):
            pass  # unreadable: built again below
    graph = ensemble_graph(packed)
    try:
        where.mkdir(mode=0o700, parents=True, exist_ok=True)
        if _private(where) is None:  # never leave a graph where others could swap it
            write_bytes(path, graph)
            os.chmod(path, 0o600)  # ours alone whatever the umask (else never read back)
    except OSError:
        pass  # a read-only home: the graph is built in every process instead
    return graph


def _session(ort, graph: bytes, digest: str) -> tuple[Any, str]:
    """An ONNX Runtime session of ``graph`` if it opens and names this forest, else ``None``
    and why."""
    options = ort.SessionOptions()
    options.log_severity_level = 3
    options.intra_op_num_threads = 1  # trees summed in their order (see the module)
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    try:
        session = ort.InferenceSession(graph, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # a damaged graph (onnxruntime raises its own types)
        return None, f"ONNX Runtime does not open it ({type(exc).__name__})"
    named = session.get_modelmeta().custom_metadata_map.get(DIGEST_KEY)
    if named != digest:
        return None, f"its {DIGEST_KEY} names {'no forest' if named is None else 'another forest'}"
    return session, ""


def ensemble_predictor(
    packed: PackedForest,
    *,
    directory: str | os.PathLike[str] | None = None,
    graph: bytes | None = None,
    where: str | os.PathLike[str] | None = None,
) -> Callable[[np.ndarray], np.ndarray]:
    """The forest's predictor on ONNX Runtime's tree ensemble (see the module).

    Parameters
    ----------
    packed : PackedForest
        The forest.
    directory : path, optional
        Where the graph is cached (default :func:`~dyntarget.perceive.compiled.cache_dir`).
    graph : bytes, optional
        A graph shipped with the model (:data:`GRAPH_FILE`), tried first; used only if
        ONNX Runtime opens it and it names this forest (:data:`DIGEST_KEY`), else said
        once on stderr and left.
    where : path, optional
        Where ``graph`` was read from (for that line).

    Returns
    -------
    callable
        ``(n, features) float32 -> (n,) float32`` plume probability, bit-identical to the
        kernel's and to ``predict_proba(x)[:, 1]`` rounded to float32; one ONNX Runtime
        thread, free of the GIL while it runs. Its attribute ``isa`` is
        ``"onnxruntime"``, ``vectorised`` is ``False``, ``shipped`` says whether the
        shipped ``graph`` runs.

    Raises
    ------
    MissingExtraError
        onnxruntime is not installed, or no usable graph was given and none is cached or
        can be built (no ``onnx``).
    InvalidParameterError
        A graph is to be built for a forest of more than :data:`MAX_GRAPH_NODES` nodes.

    Examples
    --------
    >>> import tempfile
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> from dyntarget.perceive.compiled import pack_forest
    >>> x = np.random.default_rng(0).random((200, 4), dtype=np.float32)
    >>> est = RandomForestClassifier(n_estimators=3, random_state=0).fit(x, x[:, 0] > 0.5)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     predict = ensemble_predictor(pack_forest(est), directory=tmp)
    ...     same = predict(x) == est.predict_proba(x)[:, 1].astype(np.float32)
    >>> bool(same.all()), predict.isa
    (True, 'onnxruntime')
    """
    try:
        import onnxruntime as ort
    except ImportError:
        raise MissingExtraError(
            "onnxruntime is not installed; pip install 'dyntarget[onboard]'"
        ) from None
    cache = None if directory is None else Path(directory)
    digest = forest_digest(packed)
    session, why = (None, "") if graph is None else _session(ort, graph, digest)
    shipped = session is not None
    if graph is not None and session is None:
        from dyntarget.perceive.compiled import _say_once

        _say_once(f"dyntarget: {where or GRAPH_FILE}: {why}, not this forest.npz's; not used")
    if session is None:
        session, why = _session(ort, _cached_graph(packed, cache, digest), digest)
    if session is None:  # a damaged or stale cached graph: built anew
        session, why = _session(ort, _cached_graph(packed, cache, digest, fresh=True), digest)
    if session is None:
        raise MissingExtraError(f"the forest's graph built here: {why}")
    features = packed.features

    def predict(part: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(part, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != features:
            raise InvalidParameterError(
                f"pixels: expected shape (n, {features}), got {np.shape(part)}"
            )
        if not np.isfinite(x).all():
            raise InvalidParameterError("pixels: hold NaN or infinite values")
        if not len(x):
            return np.empty(0, np.float32)
        out = session.run(["plume"], {"pixels": x.astype(np.float64)})[0]
        return np.ascontiguousarray(out[:, 0], dtype=np.float32)

    predict.isa = "onnxruntime"  # type: ignore[attr-defined]
    predict.vectorised = False  # type: ignore[attr-defined]
    predict.shipped = shipped  # type: ignore[attr-defined]
    return predict
