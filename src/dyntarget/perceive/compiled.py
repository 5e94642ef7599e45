"""A random forest predicted by dyntarget's own compiled kernel, bit-identical to scikit-learn.

scikit-learn walks each tree one pixel at a time through 64-byte node records. Here the
fitted forest is *packed* into a few flat arrays (:func:`pack_forest`) and walked by a
small C kernel (``_forest.c``, shipped with the package) that moves 16 pixels down a tree
at once with AVX-512 where the CPU has it, reads the first five levels of every tree from
registers and stops a group of pixels as soon as all of them sit on leaves. The kernel is
compiled once per machine with the C compiler found on the PATH (``cc -O2 -march=native``,
about a second) and cached under :func:`cache_dir`, keyed by a SHA-256 of its source, the
flags, the compiler's version and the CPU's feature flags. The forest itself is data, so
one library serves every forest, and nothing compiled is ever read from a model directory.

Layout (per tree, trees one after another): nodes in breadth-first order with the two
children of a node next to each other, so a pixel goes from node ``k`` to
``child(k) + (x[feature(k)] > threshold(k))``. ``code[k] = child << fshift | feature``;
``threshold[k]`` is the float64 threshold rounded *down* to float32, so ``x <= t`` in
float64 holds exactly when ``x <= threshold[k]`` in float32 (``x`` is float32, as in
scikit-learn); a leaf points to itself with threshold ``+inf``. Leaf values are
``tree_.value[k, 0, 1]``, summed per pixel in float64 in tree order and divided by the
number of trees, which is what ``RandomForestClassifier.predict_proba`` does, so the
probabilities are bit-identical (tested on both the AVX-512 and the portable code).

History: the previous backend generated C for every tree with Treelite + TL2cgen (17 s to
compile a 50-tree forest, 0.89 s for a 1024 px scene on one thread); this kernel predicts
the same scene in about a third of that and needs no extra package (docs/performance.md).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

import numpy as np

from dyntarget.errors import InvalidParameterError, MissingExtraError

PAD = 32
"""Entries after the last tree in ``threshold`` and ``code`` (the kernel's register table
reads a tree's first 32 nodes, past the end for a small last tree)."""

FLAGS = ("-O2", "-march=native", "-std=c11", "-shared", "-fPIC")
"""Compiler flags of the kernel; without ``-march=native`` when the compiler refuses it."""

_LOCK = threading.Lock()
_LOADED: dict[str, ctypes.CDLL] = {}


def cache_dir() -> Path:
    """Where the compiled kernel is kept: ``$DYNTARGET_CACHE`` or ``~/.cache/dyntarget``.

    Returns
    -------
    pathlib.Path
        ``.../forests``.

    Examples
    --------
    >>> cache_dir().name
    'forests'
    """
    root = os.environ.get("DYNTARGET_CACHE") or Path.home() / ".cache" / "dyntarget"
    return Path(root) / "forests"


def compiler() -> str | None:
    """The C compiler the kernel is built with: ``$CC``, else ``cc`` or ``gcc`` on the PATH.

    Returns
    -------
    str or None
        Its path, or ``None`` when there is none.

    Examples
    --------
    >>> compiler() is None or isinstance(compiler(), str)
    True
    """
    cc = os.environ.get("CC")
    return shutil.which(cc) if cc else shutil.which("cc") or shutil.which("gcc")


@dataclass(frozen=True)
class PackedForest:
    """A two-class scikit-learn forest as the flat arrays the kernel walks (see the module).

    Parameters
    ----------
    threshold : numpy.ndarray
        ``float32`` per node (+ :data:`PAD`): the split threshold rounded down, ``+inf`` at leaves.
    code : numpy.ndarray
        ``int32`` per node (+ :data:`PAD`): ``child << fshift | feature``; a leaf's child is itself.
    node : numpy.ndarray
        ``int64`` per node: ``code << 32 | bits(threshold)``, one load per node.
    value : numpy.ndarray
        ``float64`` per node: the leaf's fraction of plume (0 at internal nodes).
    roots : numpy.ndarray
        ``int32`` index of each tree's root.
    depth : int
        The deepest tree's depth.
    features : int
        Features per pixel.
    fshift : int
        Bits of ``code`` that hold the feature.
    """

    threshold: np.ndarray
    code: np.ndarray
    node: np.ndarray
    value: np.ndarray
    roots: np.ndarray
    depth: int
    features: int
    fshift: int


def _breadth_first(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Node ids of one tree in breadth-first order, the children of a node side by side."""
    order, frontier = [], np.array([0])
    while frontier.size:
        order.append(frontier)
        inner = frontier[left[frontier] != -1]
        frontier = np.column_stack([left[inner], right[inner]]).ravel()
    return np.concatenate(order)


def pack_forest(estimator) -> PackedForest:
    """Pack a fitted two-class ``RandomForestClassifier`` for the kernel.

    Parameters
    ----------
    estimator : sklearn.ensemble.RandomForestClassifier
        The fitted forest (two classes, at most 8 features).

    Returns
    -------
    PackedForest
        Its arrays (see the module for the layout).

    Examples
    --------
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> x = np.array([[0.0], [1.0], [2.0], [3.0]], np.float32)
    >>> est = RandomForestClassifier(n_estimators=2, random_state=0).fit(x, [0, 0, 1, 1])
    >>> packed = pack_forest(est)
    >>> packed.features, packed.fshift, len(packed.roots)
    (1, 0, 2)
    """
    from sklearn.ensemble import RandomForestClassifier

    if not isinstance(estimator, RandomForestClassifier) or len(estimator.classes_) != 2:
        raise InvalidParameterError(
            f"estimator: expected a fitted two-class RandomForestClassifier, got {estimator!r}"
        )
    nfeat = int(estimator.n_features_in_)
    if not 1 <= nfeat <= 8:
        raise InvalidParameterError(f"estimator: the kernel takes 1 to 8 features, not {nfeat}")
    fshift = (nfeat - 1).bit_length()
    total = sum(tree.tree_.node_count for tree in estimator.estimators_)
    if (total + PAD) << fshift >= 2**31:
        raise InvalidParameterError(f"estimator: {total} nodes are too many for the kernel")
    threshold = np.zeros(total + PAD, np.float32)
    code = np.zeros(total + PAD, np.int32)
    value = np.zeros(total, np.float64)
    roots, base = [], 0
    for tree in estimator.estimators_:
        t = tree.tree_
        order = _breadth_first(t.children_left, t.children_right)
        pos = np.empty(t.node_count, np.int64)
        pos[order] = np.arange(t.node_count)
        here = base + np.arange(t.node_count)  # the new index of order[i] is base + i
        leaf = t.children_left[order] == -1
        child = np.where(leaf, here, base + pos[np.where(leaf, 0, t.children_left[order])])
        code[here] = (child << fshift) | np.where(leaf, 0, t.feature[order])
        t64 = t.threshold[order]
        t32 = t64.astype(np.float32)
        t32 = np.where(t32 > t64, np.nextafter(t32, np.float32(-np.inf)), t32)
        threshold[here] = np.where(leaf, np.inf, t32)
        value[here] = np.where(leaf, t.value[order, 0, 1], 0.0)
        roots.append(base)
        base += t.node_count
    node = (code[:total].astype(np.int64) << 32) | threshold[:total].view(np.uint32)
    return PackedForest(
        threshold=threshold,
        code=code,
        node=node,
        value=value,
        roots=np.asarray(roots, np.int32),
        depth=max(tree.tree_.max_depth for tree in estimator.estimators_),
        features=nfeat,
        fshift=fshift,
    )


def _cpu() -> str:
    """The CPU's model and feature flags (part of the cache key: ``-march=native``)."""
    try:
        with open("/proc/cpuinfo") as fh:
            lines = [ln for ln in fh if ln.startswith(("model name", "flags", "Features"))]
        return "".join(sorted(set(lines)))
    except OSError:
        return f"{platform.machine()} {platform.processor()}"


def build_library(
    directory: str | os.PathLike[str] | None = None, *, portable: bool = False
) -> Path:
    """Compile the kernel for this machine (once; later calls find it in the cache).

    Parameters
    ----------
    directory : path, optional
        Cache directory (default :func:`cache_dir`).
    portable : bool
        Compile without ``-march=native`` (no AVX-512: the portable loop; for tests).

    Returns
    -------
    pathlib.Path
        The shared library.

    Raises
    ------
    MissingExtraError
        No C compiler, or the kernel does not compile.
    """
    cc = compiler()
    if cc is None:
        raise MissingExtraError("the compiled forest needs a C compiler (cc or gcc) on the PATH")
    source = files("dyntarget.perceive").joinpath("_forest.c").read_bytes()
    try:
        version = subprocess.run([cc, "--version"], capture_output=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        raise MissingExtraError(f"the C compiler {cc} does not run ({exc})") from None
    where = Path(directory) if directory is not None else cache_dir()
    attempts = [f for f in FLAGS if f != "-march=native"] if portable else list(FLAGS)
    for flags in (attempts, [f for f in attempts if f != "-march=native"]):
        key = b"\0".join([source, " ".join(flags).encode(), version, _cpu().encode()])
        lib = where / f"forest-kernel-{hashlib.sha256(key).hexdigest()[:24]}.so"
        if lib.is_file():
            return lib
        where.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=where) as tmp:
            src, part = Path(tmp) / "_forest.c", Path(tmp) / lib.name
            src.write_bytes(source)
            done = subprocess.run([cc, *flags, str(src), "-o", str(part)], capture_output=True)
            if done.returncode == 0:
                os.replace(part, lib)  # atomic: a reader never sees half a library
                return lib
        error = done.stderr.decode(errors="replace").strip().splitlines()
    raise MissingExtraError(f"the forest kernel does not compile with {cc}: {error[-1:]}")


def _load(lib: Path) -> ctypes.CDLL:
    with _LOCK:
        if str(lib) not in _LOADED:
            dll = ctypes.CDLL(str(lib))
            i32, i64, ptr = ctypes.c_int32, ctypes.c_int64, ctypes.c_void_p
            dll.dt_forest_predict.argtypes = [ptr, i64, i32, i32, i32, ptr, ptr, ptr, ptr, ptr]
            dll.dt_forest_predict.argtypes += [i32, ptr]
            dll.dt_forest_predict.restype = ctypes.c_int
            dll.dt_forest_avx512.restype = ctypes.c_int
            _LOADED[str(lib)] = dll
        return _LOADED[str(lib)]


def compile_forest(
    estimator, *, directory: str | os.PathLike[str] | None = None, portable: bool = False
) -> Callable[[np.ndarray], np.ndarray]:
    """The predictor of a fitted two-class ``RandomForestClassifier`` on the kernel.

    Parameters
    ----------
    estimator : sklearn.ensemble.RandomForestClassifier
        The fitted forest.
    directory : path, optional
        Cache directory of the kernel (default :func:`cache_dir`).
    portable : bool
        Use the kernel built without ``-march=native`` (see :func:`build_library`).

    Returns
    -------
    callable
        ``(n, features) float32 -> (n,) float32`` plume probability, bit-identical to
        ``estimator.predict_proba(x)[:, 1].astype(numpy.float32)``; single-threaded and
        free of the GIL (the pixel classifiers' chunk pool runs chunks in parallel). Its
        attribute ``vectorised`` says whether the kernel was built with AVX-512.

    Examples
    --------
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> x = np.random.default_rng(0).random((200, 4), dtype=np.float32)
    >>> est = RandomForestClassifier(n_estimators=3, random_state=0).fit(x, x[:, 0] > 0.5)
    >>> predict = compile_forest(est)
    >>> bool((predict(x) == est.predict_proba(x)[:, 1].astype(np.float32)).all())
    True
    """
    packed = pack_forest(estimator)
    dll = _load(build_library(directory, portable=portable))

    def predict(part: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(part, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != packed.features:
            raise InvalidParameterError(
                f"pixels: expected shape (n, {packed.features}), got {np.shape(part)}"
            )
        if not np.isfinite(x).all():
            raise InvalidParameterError("pixels: hold NaN or infinite values")
        out = np.empty(len(x), np.float64)
        rc = dll.dt_forest_predict(
            x.ctypes.data, len(x), packed.features, packed.fshift, packed.depth,
            packed.node.ctypes.data, packed.threshold.ctypes.data, packed.code.ctypes.data,
            packed.value.ctypes.data, packed.roots.ctypes.data, len(packed.roots),
            out.ctypes.data,
        )  # fmt: skip
        if rc != 0:
            raise InvalidParameterError(f"the forest kernel refused the forest (code {rc})")
        return out.astype(np.float32)

    predict.vectorised = bool(dll.dt_forest_avx512())  # type: ignore[attr-defined]
    return predict
