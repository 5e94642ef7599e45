"""Model files are data: check every loaded model's structure before it runs.

A model file that holds only allow-listed types can still be hostile: a
decision tree whose child indices point outside its node array makes
scikit-learn's compiled code read memory it does not own (a segfault), an
estimator with five features or three classes gives wrong answers or odd
errors deep inside a prediction. Each loader calls one function of this module
right after deserialising and before the model is used:

* :func:`check_estimator` — scikit-learn models (``pixel.py``): trees (node
  count, children in range and acyclic, feature indices < 4, finite thresholds,
  values shaped for two classes), forests (every tree), naive Bayes, logistic
  regression, MLP and the standard scaler (coefficient shapes, finite values),
  ``classes_`` equal to ``[0, 1]`` or ``[False, True]``, ``n_features_in_ == 4``;
* :func:`check_state_dict` — U-Net weights (``unet.py``): every tensor's name,
  shape and dtype as the architecture expects, and finite values;
* :func:`check_onnx_session` — ONNX graphs (``onnx.py``): input/output names,
  shapes and element types as :mod:`dyntarget.perceive.onnx` documents them.

Anything else raises :class:`~dyntarget.errors.ModelFileError` naming the
file and the first thing that is wrong (the CLI exits 2).

Heavy libraries are imported inside the functions.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError, ModelFileError

N_FEATURES = 4
"""Band values per pixel (R, G, B, NIR)."""

TREE_LEAF = -1
"""scikit-learn's child index of a leaf."""


def _fail(where: Any, what: str) -> ModelFileError:
    return ModelFileError(f"{where}: {what}")


def _array(where: Any, name: str, value: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    """``value`` as a finite float array of ``shape`` (``None`` matches any length)."""
    try:
        arr = np.asarray(value)
    except Exception:
        raise _fail(where, f"{name} is not an array") from None
    if arr.dtype.kind not in "fiub":
        raise _fail(where, f"{name} has dtype {arr.dtype}, expected numbers")
    if arr.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(arr.shape, shape, strict=True)
    ):
        want_text = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
        raise _fail(where, f"{name} has shape {arr.shape}, expected {want_text}")
    if not np.isfinite(arr.astype(np.float64, copy=False)).all():
        raise _fail(where, f"{name} holds NaN or infinite values")
    return arr


def _check_classes(where: Any, est: Any) -> None:
    classes = getattr(est, "classes_", None)
    try:
        ok = classes is not None and np.asarray(classes).tolist() in ([0, 1], [False, True])
    except Exception:
        ok = False
    if not ok:
        raise _fail(
            where,
            f"classes_ is {_short(classes)}, expected [0, 1] or [False, True] "
            "(a two-class plume / background model)",
        )


def _check_n_features(where: Any, est: Any) -> None:
    n = getattr(est, "n_features_in_", None)
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or int(n) != N_FEATURES:
        raise _fail(where, f"n_features_in_ is {_short(n)}, expected {N_FEATURES} (R, G, B, NIR)")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_tree(tree: Any, where: Any = "tree") -> None:
    """Refuse a fitted ``sklearn.tree._tree.Tree`` that is not a sound two-class tree.

    Checks: one output, two classes, four features; node count equal to the
    length of every node array; every internal node's children are later nodes
    (so they are in range and the tree is acyclic) and every node but the root
    has exactly one parent; leaves have no children; feature indices in 0..3 and
    finite thresholds on internal nodes; ``value`` shaped ``(nodes, 1, 2)``,
    finite and non-negative.

    Parameters
    ----------
    tree : sklearn.tree._tree.Tree
        The ``tree_`` attribute of a fitted decision tree.
    where : str or path
        Named in the error (the model file).

    Raises
    ------
    ModelFileError
        On the first defect found.

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.tree import DecisionTreeClassifier
    >>> x = np.array([[0, 0, 0, 0], [1, 1, 1, 1]] * 5, float)
    >>> est = DecisionTreeClassifier().fit(x, [0, 1] * 5)
    >>> check_tree(est.tree_)  # a sound tree passes silently
    """
    try:
        n = int(tree.node_count)
        n_outputs = int(tree.n_outputs)
        n_features = int(tree.n_features)
        n_classes = np.asarray(tree.n_classes).tolist()
        left = np.asarray(tree.children_left)
        right = np.asarray(tree.children_right)
        feature = np.asarray(tree.feature)
        threshold = np.asarray(tree.threshold)
        value = np.asarray(tree.value)
    except Exception as exc:
        raise _fail(where, f"not a readable decision tree ({type(exc).__name__})") from None
    if n_outputs != 1 or n_classes != [2]:
        raise _fail(
            where, f"tree has {n_outputs} output(s) of {n_classes} classes, expected 1 of [2]"
        )
    if n_features != N_FEATURES:
        raise _fail(where, f"tree uses {n_features} features, expected {N_FEATURES}")
    if n < 1:
        raise _fail(where, f"tree has {n} nodes, expected at least 1")
    for name, arr in (
        ("children_left", left),
        ("children_right", right),
        ("feature", feature),
        ("threshold", threshold),
    ):
        if arr.shape != (n,):
            raise _fail(where, f"tree {name} has shape {arr.shape}, expected ({n},)")
    if value.shape != (n, 1, 2):
        raise _fail(where, f"tree value has shape {value.shape}, expected ({n}, 1, 2)")
    if not np.isfinite(value).all() or (value < 0).any():
        raise _fail(where, "tree value holds negative, NaN or infinite entries")
    leaf = left == TREE_LEAF
    if not np.array_equal(leaf, right == TREE_LEAF):
        raise _fail(where, "tree has a node with exactly one child")
    idx = np.arange(n)
    inner = ~leaf
    for name, child in (("children_left", left), ("children_right", right)):
        bad = inner & ((child <= idx) | (child >= n))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise _fail(
                where,
                f"tree node {i} has {name} {int(child[i])}, expected a later node in "
                f"{i + 1}..{n - 1}",
            )
    parents = np.bincount(np.concatenate([left[inner], right[inner]]), minlength=n)
    if parents[0] != 0 or (parents[1:] != 1).any():
        raise _fail(where, "tree nodes do not form a tree (a node with no or several parents)")
    if ((feature[inner] < 0) | (feature[inner] >= N_FEATURES)).any():
        raise _fail(where, f"tree splits on a feature outside 0..{N_FEATURES - 1}")
    if not np.isfinite(threshold[inner]).all():
        raise _fail(where, "tree holds a NaN or infinite threshold")


def _tree_depth(tree: Any) -> int:
    """The depth of a tree :func:`check_tree` passed, from its child arrays (not its claim):
    each node's distance to the root by pointer jumping (a few passes, even for a chain)."""
    left = np.asarray(tree.children_left, np.int64)
    right = np.asarray(tree.children_right, np.int64)
    inner = np.flatnonzero(left != TREE_LEAF)
    parent = np.full(len(left), -1, np.int64)
    parent[left[inner]] = inner
    parent[right[inner]] = inner
    dist, jump = (parent >= 0).astype(np.int64), parent
    while (jump >= 0).any():
        live = np.flatnonzero(jump >= 0)
        dist, jump = dist.copy(), jump.copy()
        hop = jump[live]
        dist[live] += dist[hop]
        jump[live] = jump[hop]
    return int(dist.max())


def _check_forest_size(where: Any, trees: list[Any]) -> None:
    """Refuse a forest beyond :data:`~dyntarget.perceive.compiled.MAX_TREES` trees,
    ``MAX_NODES`` nodes or ``MAX_STEPS`` levels in all (the work per pixel)."""
    from dyntarget.perceive.compiled import MAX_NODES, MAX_STEPS, MAX_TREES

    if len(trees) > MAX_TREES:
        raise _fail(where, f"{len(trees):,} trees, more than the {MAX_TREES:,} a model may hold")
    nodes = steps = 0
    for i, tree in enumerate(trees):
        t = getattr(tree, "tree_", tree)
        nodes += int(t.node_count)
        if nodes > MAX_NODES:
            raise _fail(where, f"more than the {MAX_NODES:,} nodes a model may hold (tree {i})")
        steps += _tree_depth(t)
        if steps > MAX_STEPS:
            raise _fail(
                where,
                f"trees more than {MAX_STEPS:,} levels deep in all (tree {i}): more work per "
                "pixel than a model may ask",
            )


def _check_tree_estimator(est: Any, where: Any) -> None:
    _check_classes(where, est)
    _check_n_features(where, est)
    if getattr(est, "n_outputs_", None) != 1:
        raise _fail(where, f"n_outputs_ is {_short(getattr(est, 'n_outputs_', None))}, expected 1")
    check_tree(getattr(est, "tree_", None), where)


def check_estimator(est: Any, where: Any = "model") -> None:
    """Refuse a scikit-learn estimator that is not a sound 4-feature, two-class model.

    Handles the estimators of :mod:`dyntarget.perceive.pixel` (also inside a
    ``Pipeline`` after a ``StandardScaler``): decision trees and random forests
    (:func:`check_tree` on every tree), Gaussian naive Bayes (``theta_``,
    ``var_`` > 0, ``class_prior_``), logistic regression (``coef_ (1, 4)``,
    ``intercept_ (1,)``), MLP (layer shapes chained from 4 inputs to 1 logistic
    output); every classifier must have ``classes_`` ``[0, 1]`` or
    ``[False, True]`` and ``n_features_in_ == 4``; all numbers finite.

    Parameters
    ----------
    est : sklearn estimator
        What a model file deserialised to.
    where : str or path
        Named in the error (the model file).

    Raises
    ------
    ModelFileError
        On the first defect found, or for an estimator type not listed above.

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.naive_bayes import GaussianNB
    >>> rng = np.random.default_rng(0)
    >>> est = GaussianNB().fit(rng.uniform(size=(20, 4)), [0, 1] * 10)
    >>> check_estimator(est)
    >>> est.fit(rng.uniform(size=(20, 5)), [0, 1] * 10)  # five features
    GaussianNB()
    >>> check_estimator(est, "m.skops")
    Traceback (most recent call last):
    ...
    dyntarget.errors.ModelFileError: m.skops: n_features_in_ is 5, expected 4 (R, G, B, NIR)
    """
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.linear_model import LogisticRegression
    from sklearn.naive_bayes import GaussianNB
    from sklearn.neural_network import MLPClassifier
    from sklearn.neural_network._base import ACTIVATIONS
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.tree import DecisionTreeClassifier

    kind = type(est)
    if kind is Pipeline:
        steps = getattr(est, "steps", None)
        if (
            not isinstance(steps, list)
            or len(steps) != 2
            or not all(isinstance(s, tuple) and len(s) == 2 for s in steps)
        ):
            raise _fail(where, "pipeline is not (StandardScaler, classifier)")
        scaler, final = steps[0][1], steps[1][1]
        if type(scaler) is not StandardScaler:
            raise _fail(where, f"pipeline starts with {type(scaler).__name__}, not StandardScaler")
        _check_n_features(where, scaler)
        _array(where, "StandardScaler.mean_", getattr(scaler, "mean_", None), (N_FEATURES,))
        scale = _array(
            where, "StandardScaler.scale_", getattr(scaler, "scale_", None), (N_FEATURES,)
        )
        if (scale <= 0).any():
            raise _fail(where, "StandardScaler.scale_ holds a value <= 0")
        if type(final) not in (LogisticRegression, MLPClassifier):
            raise _fail(where, f"pipeline ends with {type(final).__name__}, not a classifier")
        check_estimator(final, where)
        return
    if kind is DecisionTreeClassifier:
        _check_tree_estimator(est, where)
        _check_forest_size(where, [est])
        return
    if kind is RandomForestClassifier:
        _check_classes(where, est)
        _check_n_features(where, est)
        trees = getattr(est, "estimators_", None)
        if not isinstance(trees, list) or not trees:
            raise _fail(where, "random forest holds no trees")
        from dyntarget.perceive.compiled import MAX_TREES

        if len(trees) > MAX_TREES:  # before any tree is looked at
            raise _fail(
                where, f"{len(trees):,} trees, more than the {MAX_TREES:,} a model may hold"
            )
        for i, tree in enumerate(trees):
            if type(tree) is not DecisionTreeClassifier:
                raise _fail(where, f"random forest member {i} is a {type(tree).__name__}")
            _check_tree_estimator(tree, f"{where} (tree {i})")
        _check_forest_size(where, trees)
        return
    _check_classes(where, est)
    _check_n_features(where, est)
    if kind is GaussianNB:
        _array(where, "theta_", getattr(est, "theta_", None), (2, N_FEATURES))
        var = _array(where, "var_", getattr(est, "var_", None), (2, N_FEATURES))
        if (var <= 0).any():
            raise _fail(where, "var_ holds a variance <= 0")
        prior = _array(where, "class_prior_", getattr(est, "class_prior_", None), (2,))
        if (prior < 0).any() or not np.isclose(prior.sum(), 1.0):
            raise _fail(where, f"class_prior_ {prior.tolist()} is not a probability vector")
        return
    if kind is LogisticRegression:
        _array(where, "coef_", getattr(est, "coef_", None), (1, N_FEATURES))
        _array(where, "intercept_", getattr(est, "intercept_", None), (1,))
        return
    if kind is MLPClassifier:
        coefs, intercepts = getattr(est, "coefs_", None), getattr(est, "intercepts_", None)
        if not isinstance(coefs, list) or not isinstance(intercepts, list) or not coefs:
            raise _fail(where, "MLP coefs_/intercepts_ are not lists of arrays")
        if len(coefs) != len(intercepts) or getattr(est, "n_layers_", None) != len(coefs) + 1:
            raise _fail(where, "MLP layer counts disagree (coefs_, intercepts_, n_layers_)")
        width = N_FEATURES
        for i, (w, b) in enumerate(zip(coefs, intercepts, strict=True)):
            w = _array(where, f"MLP coefs_[{i}]", w, (width, None))
            width = w.shape[1]
            if width < 1:
                raise _fail(where, f"MLP layer {i} has no units")
            _array(where, f"MLP intercepts_[{i}]", b, (width,))
        if width != 1 or getattr(est, "n_outputs_", None) != 1:
            raise _fail(where, f"MLP ends in {width} output unit(s), expected 1 (two classes)")
        if getattr(est, "out_activation_", None) != "logistic":
            raise _fail(
                where,
                f"MLP out_activation_ is {_short(getattr(est, 'out_activation_', None))}, "
                "expected 'logistic'",
            )
        if getattr(est, "activation", None) not in ACTIVATIONS:
            raise _fail(
                where,
                f"MLP activation is {_short(getattr(est, 'activation', None))}, "
                f"expected one of {sorted(ACTIVATIONS)}",
            )
        return
    raise _fail(where, f"holds a {kind.__name__}, which dyntarget does not load")


def check_state_dict(
    state: Mapping[str, Any], expected: Mapping[str, Any], where: Any = "weights"
) -> None:
    """Refuse U-Net weights whose tensors differ from the architecture's.

    Every tensor of ``expected`` (a freshly built network's ``state_dict()``)
    must be present in ``state`` with the same shape and dtype, no other
    tensor may be present, and floating-point tensors must be finite (a
    normalisation ``std`` must be positive).

    Parameters
    ----------
    state : mapping of str to torch.Tensor
        The loaded weights.
    expected : mapping of str to torch.Tensor
        ``network(width=...).state_dict()`` of the architecture the metadata names.
    where : str or path
        Named in the error (the weights file).

    Raises
    ------
    ModelFileError
        On the first missing, extra or mismatched tensor.

    Examples
    --------
    >>> import torch
    >>> net = torch.nn.Linear(4, 2)
    >>> check_state_dict(net.state_dict(), net.state_dict())
    >>> check_state_dict({"weight": torch.zeros(2, 4)}, net.state_dict(), "w.st")
    Traceback (most recent call last):
    ...
    dyntarget.errors.ModelFileError: w.st: weights do not match the architecture (tensors missing: ['bias'])
    """
    import torch

    if not isinstance(state, Mapping):
        raise _weights(where, f"weights are a {type(state).__name__}, expected named tensors")
    missing = sorted(set(expected) - set(state))
    extra = sorted(set(state) - set(expected))
    if missing:
        raise _weights(where, f"tensors missing: {missing[:3]}")
    if extra:
        raise _weights(where, f"unexpected tensors: {extra[:3]}")
    for name, want in expected.items():
        got = state[name]
        if not isinstance(got, torch.Tensor):
            raise _weights(where, f"{name} is a {type(got).__name__}, expected a tensor")
        if tuple(got.shape) != tuple(want.shape):
            raise _weights(
                where, f"{name} has shape {tuple(got.shape)}, expected {tuple(want.shape)}"
            )
        if got.dtype != want.dtype:
            raise _weights(where, f"{name} has dtype {got.dtype}, expected {want.dtype}")
        if got.is_floating_point() and not bool(torch.isfinite(got).all()):
            raise _weights(where, f"{name} holds NaN or infinite values")
        if name.endswith(("norm.std", "running_var")) and bool((got <= 0).any()):
            raise _weights(where, f"{name} holds a value <= 0")


def _weights(where: Any, what: str) -> ModelFileError:
    return _fail(where, f"weights do not match the architecture ({what})")


# ONNX element types as onnxruntime names them
_FLOAT, _INT64 = "tensor(float)", "tensor(int64)"


def _dims_match(got: Any, want: tuple[int | None, ...]) -> bool:
    got = list(got or [])
    if len(got) != len(want):
        return False
    for g, w in zip(got, want, strict=True):
        if w is None:  # dynamic: a symbolic name (or a positive size) is acceptable
            if isinstance(g, int) and g < 1:
                return False
        elif isinstance(w, TileSide):  # a U-Net's height/width: the tile, or symbolic
            if isinstance(g, int) and g != w:
                return False
        elif g != w:
            return False
    return True


class TileSide(int):
    """A U-Net's height or width in an ONNX signature: exports before halo stitching fix it
    to the tile size; later ones leave it symbolic (any size a multiple of the network's
    downsampling). A fixed size other than the tile is refused."""


def onnx_signature(kind: str, tile: int | None = None) -> dict[str, list]:
    """The documented inputs and outputs ``{"inputs": [...], "outputs": [...]}``.

    Each entry is ``(name, element type, shape)`` with ``None`` for a dynamic
    dimension. ``kind`` is ``"unet"`` (needs ``tile``) or ``"pixel"``.

    Parameters
    ----------
    kind : {"unet", "pixel"}
        The model family.
    tile : int or None
        The U-Net's tile side, px.

    Returns
    -------
    dict of str to list
        ``(name, element type, shape)`` entries under ``"inputs"`` and ``"outputs"``.

    Examples
    --------
    >>> onnx_signature("unet", 32)["inputs"]
    [('image', 'tensor(float)', (None, 4, 32, 32))]
    """
    if kind == "unet":
        if tile is None:
            raise InvalidParameterError("onnx_signature: a U-Net's signature needs its tile")
        side = TileSide(tile)
        return {
            "inputs": [("image", _FLOAT, (None, 4, side, side))],
            "outputs": [("logits", _FLOAT, (None, 2, side, side))],
        }
    return {
        "inputs": [("pixels", _FLOAT, (None, N_FEATURES))],
        "outputs": [("label", _INT64, (None,)), ("probabilities", _FLOAT, (None, 2))],
    }


def check_onnx_session(
    session: Any, kind: str, *, tile: int | None = None, where: Any = "model.onnx"
) -> None:
    """Refuse an ONNX graph whose inputs or outputs differ from the documented ones.

    Parameters
    ----------
    session : onnxruntime.InferenceSession
        The loaded graph.
    kind : {"unet", "pixel"}
        Which signature applies (:func:`onnx_signature`).
    tile : int, optional
        The U-Net's tile size (from the model's metadata).
    where : str or path
        Named in the error.

    Raises
    ------
    ModelFileError
        When names, element types or shapes differ.

    Examples
    --------
    >>> class _Arg:
    ...     def __init__(self, name, type, shape):
    ...         self.name, self.type, self.shape = name, type, shape
    >>> class _Session:
    ...     def get_inputs(self):
    ...         return [_Arg("pixels", "tensor(float)", [None, 4])]
    ...     def get_outputs(self):
    ...         return [_Arg("label", "tensor(int64)", [None])]
    >>> check_onnx_session(_Session(), "pixel", where="m.onnx")
    Traceback (most recent call last):
    ...
    dyntarget.errors.ModelFileError: m.onnx: ONNX outputs are [('label', 'tensor(int64)', [None])], expected [('label', 'tensor(int64)', (n,)), ('probabilities', 'tensor(float)', (n, 2))]
    """
    sig = onnx_signature(kind, tile)
    for side, args in (("inputs", session.get_inputs()), ("outputs", session.get_outputs())):
        got = [(a.name, a.type, list(a.shape or [])) for a in args]
        want = sig[side]
        ok = len(got) == len(want) and all(
            g[0] == w[0] and g[1] == w[1] and _dims_match(g[2], w[2])
            for g, w in zip(got, want, strict=True)
        )
        if not ok:
            shown = [(n, t, tuple("n" if d is None else d for d in s)) for n, t, s in want]
            raise _fail(
                where,
                f"ONNX {side} are {_short_list(got)}, expected {shown}".replace("'n'", "n"),
            )


def _short_list(items: list) -> str:
    text = repr(items)
    return text if len(text) <= 200 else text[:197] + "..."


MAX_ONNX_BYTES = 512 * 1024 * 1024
"""Largest ``model.onnx`` loaded (512 MiB), checked before a byte of it is read."""

MAX_ONNX_NODES = 200_000
"""Most nodes in an ONNX graph (subgraphs included)."""

ONNX_RUN_LIMIT_S = 300.0
"""Longest one ONNX Runtime call may take (one chunk of pixels or one batch of tiles)
before it is stopped and the model refused."""

CONTROL_FLOW_OPS = ("Loop", "Scan", "If")
"""ONNX operators refused: dyntarget's exports never hold them, and a ``Loop`` can run
for 2**62 iterations."""


def check_onnx_file(path: Any) -> int:
    """Refuse an ONNX file before ONNX Runtime loads it: size, then its graph.

    The file must be a regular file of at most :data:`MAX_ONNX_BYTES`; its graph may
    hold at most :data:`MAX_ONNX_NODES` nodes and none of :data:`CONTROL_FLOW_OPS`
    (parsed with protobuf against the node-holding fields of ONNX's schema, on the full
    and the lean install alike: :func:`_onnx_ops`).

    Parameters
    ----------
    path : str or path
        The ``model.onnx``.

    Returns
    -------
    int
        The file's size in bytes.

    Raises
    ------
    ModelFileError
        Too large, not a regular file, too many nodes, or a control-flow operator.

    Examples
    --------
    >>> import os, tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "model.onnx"
    >>> os.mkfifo(p)  # would block a reader forever
    >>> check_onnx_file(p)
    Traceback (most recent call last):
    ...
    dyntarget.errors.ModelFileError: ...model.onnx: a FIFO (named pipe), not a regular file
    """
    from dyntarget.errors import DataFileError
    from dyntarget.io.safeopen import read_bytes

    try:
        data = read_bytes(path, max_bytes=MAX_ONNX_BYTES)
    except DataFileError as exc:
        raise ModelFileError(str(exc)) from None
    check_onnx_bytes(data, path)
    return len(data)


def check_onnx_bytes(data: bytes, where: Any) -> None:
    """Refuse an ONNX graph already read: too many nodes, or a control-flow operator.

    :func:`check_onnx_file`'s graph checks, for bytes read once and run as they are (so
    that what is checked is what runs).

    Parameters
    ----------
    data : bytes
        The serialized model.
    where : str or path
        Where it was read from (named in the refusal).

    Raises
    ------
    ModelFileError
        Unreadable, too many nodes, or a control-flow operator.

    Examples
    --------
    >>> check_onnx_bytes(b"", "empty.onnx") is None  # an empty graph: nothing to refuse
    True
    >>> check_onnx_bytes(b"\\x3a\\x08\\x0a\\x06\\x22\\x04Loop", "loop.onnx")  # graph { node { op_type: "Loop" } }
    Traceback (most recent call last):
    ...
    dyntarget.errors.ModelFileError: loop.onnx: the ONNX graph holds a Loop node; ...
    """
    ops = _onnx_ops(data, where)
    if len(ops) > MAX_ONNX_NODES:
        raise _fail(where, f"the ONNX graph has {len(ops):,} nodes, more than {MAX_ONNX_NODES:,}")
    for op in CONTROL_FLOW_OPS:
        if op in ops:
            raise _fail(
                where,
                f"the ONNX graph holds a {op} node; dyntarget's models never do "
                "(refused: it could run without end)",
            )


def _onnx_ops(data: bytes, where: Any) -> list[str]:
    """The ``op_type`` of every node, subgraphs and functions included.

    Parsed with protobuf (a dependency of onnxruntime, so on the lean install too) against
    the few fields of ONNX's schema that hold nodes (:func:`_node_schema`): the same parse
    as ``onnx.ModelProto``'s for those fields, without importing ``onnx`` (half a second of
    start-up: ``ml_dtypes``). Without protobuf, the raw bytes are scanned instead.
    """
    try:
        model_class = _node_schema()
    except ImportError:
        return _scan_ops(data)
    model = model_class()
    try:
        model.ParseFromString(data)
    except Exception as exc:  # protobuf's DecodeError
        raise _fail(where, f"not a readable ONNX model ({type(exc).__name__})") from None
    ops: list[str] = []
    graphs = [model.graph, *model.functions]
    while graphs:
        g = graphs.pop()
        for node in g.node:
            ops.append(node.op_type.decode("utf-8", errors="replace"))
            if len(ops) > MAX_ONNX_NODES:
                return ops
            for a in node.attribute:
                if a.HasField("g"):
                    graphs.append(a.g)
                graphs.extend(a.graphs)
    return ops


@functools.cache
def _node_schema() -> Any:
    """A protobuf message class for the part of ONNX's ``ModelProto`` that holds nodes.

    Field numbers are onnx.proto's: ``ModelProto.graph`` 7 and ``functions`` 25,
    ``GraphProto.node`` 1, ``NodeProto.op_type`` 4 and ``attribute`` 5,
    ``AttributeProto.g`` 6 and ``graphs`` 11, ``FunctionProto.node`` 7; every other field is
    skipped as unknown. ``op_type`` is read as bytes (no UTF-8 check to fail on).
    """
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    field = descriptor_pb2.FieldDescriptorProto
    schema = descriptor_pb2.FileDescriptorProto(
        name="dyntarget_onnx_nodes.proto", package="dyntarget_onnx_nodes", syntax="proto2"
    )
    messages: dict[str, list[tuple[str, int, bool, str | None]]] = {
        "Model": [("graph", 7, False, "Graph"), ("functions", 25, True, "Function")],
        "Graph": [("node", 1, True, "Node")],
        "Node": [("op_type", 4, False, None), ("attribute", 5, True, "Attribute")],
        "Attribute": [("g", 6, False, "Graph"), ("graphs", 11, True, "Graph")],
        "Function": [("node", 7, True, "Node")],
    }
    for name, fields in messages.items():
        message = schema.message_type.add(name=name)
        for fname, number, repeated, kind in fields:
            f = message.field.add(name=fname, number=number)
            f.label = field.LABEL_REPEATED if repeated else field.LABEL_OPTIONAL
            if kind is None:
                f.type = field.TYPE_BYTES
            else:
                f.type, f.type_name = field.TYPE_MESSAGE, f".dyntarget_onnx_nodes.{kind}"
    pool = descriptor_pool.DescriptorPool()
    pool.Add(schema)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("dyntarget_onnx_nodes.Model"))


def _scan_ops(data: bytes) -> list[str]:
    """Operator names found as ``op_type`` fields (tag 0x22) in the raw protobuf."""
    found = []
    for op in CONTROL_FLOW_OPS:
        if b"\x22" + bytes([len(op)]) + op.encode() in data:
            found.append(op)
    return found


def check_onnx_output(outputs: Any, kind: str, rows: int, where: Any = "model.onnx") -> None:
    """Refuse an ONNX run's outputs unless they have one finite row per input row.

    Parameters
    ----------
    outputs : list of numpy.ndarray
        What ``session.run`` returned.
    kind : {"pixel", "unet"}
        ``pixel``: ``label (rows,)`` and ``probabilities (rows, 2)`` in 0..1;
        ``unet``: ``logits (rows, 2, h, w)``.
    rows : int
        Rows (pixels or tiles) fed in.
    where : str or path
        Named in the error.

    Raises
    ------
    ModelFileError
        A row count other than ``rows`` (one row broadcast over every pixel), a wrong
        shape, or NaN/infinite values.

    Examples
    --------
    >>> check_onnx_output([np.zeros(3, np.int64), np.full((1, 2), 0.5, np.float32)], "pixel", 3)
    Traceback (most recent call last):
    ...
    dyntarget.errors.ModelFileError: model.onnx: ONNX output probabilities has shape (1, 2) for 3 input rows, expected (3, 2)
    """
    arrays = [np.asarray(o) for o in outputs]
    if kind == "unet":
        names, shapes = ["logits"], [(rows, 2)]  # type: list[str], list[tuple[int, ...]]
    else:
        names, shapes = ["label", "probabilities"], [(rows,), (rows, 2)]
    if len(arrays) != len(names):
        raise _fail(where, f"ONNX run returned {len(arrays)} outputs, expected {len(names)}")
    for name, want, a in zip(names, shapes, arrays, strict=True):
        if a.shape[: len(want)] != want or (kind != "unet" and a.ndim != len(want)):
            shown = (*want, "h", "w") if kind == "unet" else want
            raise _fail(
                where,
                f"ONNX output {name} has shape {a.shape} for {rows} input rows, "
                f"expected {tuple(shown)}".replace("'", ""),
            )
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            bad = int(a.size - np.count_nonzero(np.isfinite(a)))
            raise _fail(where, f"ONNX output {name} holds {bad:,} NaN or infinite value(s)")
    if kind != "unet":
        p = arrays[1]
        if p.size and (p.min() < -1e-4 or p.max() > 1 + 1e-4):
            raise _fail(
                where,
                f"ONNX output probabilities outside 0..1 ({float(p.min()):.3g} .. {float(p.max()):.3g})",
            )


def run_onnx(
    session: Any,
    feeds: Mapping[str, np.ndarray],
    kind: str,
    *,
    where: Any = "model.onnx",
    limit_s: float | None = None,
) -> list:
    """``session.run`` stopped after ``limit_s`` seconds, its outputs checked (:func:`check_onnx_output`).

    Parameters
    ----------
    session : onnxruntime.InferenceSession
        The loaded graph.
    feeds : mapping of str to numpy.ndarray
        Its one input.
    kind : {"pixel", "unet"}
        Which outputs are expected.
    where : str or path
        Named in the error.
    limit_s : float or None
        Run-time limit (default :data:`ONNX_RUN_LIMIT_S`).

    Returns
    -------
    list of numpy.ndarray
        The outputs.

    Raises
    ------
    ModelFileError
        The run took longer than the limit, failed, or returned bad outputs.
    """
    import threading

    import onnxruntime as ort

    limit = ONNX_RUN_LIMIT_S if limit_s is None else float(limit_s)
    options = ort.RunOptions()
    timer = threading.Timer(limit, lambda: setattr(options, "terminate", True))
    timer.daemon = True
    timer.start()
    try:
        outputs = session.run(None, dict(feeds), options)
    except Exception as exc:  # onnxruntime's own error types
        if options.terminate:
            raise _fail(
                where, f"the ONNX run took longer than {limit:g} s and was stopped"
            ) from None
        text = str(exc).strip().splitlines()
        raise _fail(
            where, f"the ONNX run failed ({text[0][:200] if text else type(exc).__name__})"
        ) from None
    finally:
        timer.cancel()
    rows = len(next(iter(feeds.values())))
    check_onnx_output(outputs, kind, rows, where)
    return outputs
