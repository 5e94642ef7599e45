"""A random forest predicted by dyntarget's own compiled kernel, bit-identical to scikit-learn.

scikit-learn walks each tree one pixel at a time through 64-byte node records. Here the
fitted forest is *packed* into a few flat arrays (:func:`pack_forest`) and walked by a
small C kernel (``_forest.c``, shipped with the package) that moves 16 pixels down a tree
at once with AVX-512 where the CPU has it, reads the first five levels of every tree from
registers and stops a group of pixels as soon as all of them sit on leaves.

Trust: a model directory is data, never code. The kernel is loaded only from this user's
own cache (:func:`cache_dir`, ``0700``, this user's alone): compiled there with the C
compiler found on the PATH (``cc -O2`` with the ``-march=x86-64-v4``/``-v3`` level of the
widest path the CPU's CPUID reports, else ``-march=native``; 0.1-2.8 s,
docs/performance.md), named after a SHA-256 of its source, flags and compiler, with its
own SHA-256 recorded beside it; or put there by :func:`install_kernel`, the deliberate
act that gives a machine without a compiler a kernel built elsewhere
(``dyntarget export-onnx --targets x86-64-v3,x86-64-v4,aarch64`` builds them with
:func:`build_kernels`, ``cc -march=x86-64-v3`` etc. and the Debian cross compiler for
aarch64). A library is checked (owner, mode, architecture, SHA-256) and loaded through the
same file descriptor (:func:`_load`). Libraries found in a model directory are never loaded
(:func:`shipped_kernels` says so). Where no kernel can be had, a slower backend predicts
and stderr says why, once. The forest itself is data, so one library serves every forest.

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
import functools
import hashlib
import io
import json
import os
import platform
import shlex
import shutil
import stat
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path

import numpy as np

from dyntarget.errors import InvalidParameterError, MissingExtraError, ModelFileError

PAD = 32
"""Entries after the last tree in ``threshold`` and ``code`` (the kernel's register table
reads a tree's first 32 nodes, past the end for a small last tree)."""

FOREST_FILE = "forest.npz"
"""The packed forest in an exported model directory (beside ``model.onnx``): lets the
lean onboard install, which has no scikit-learn, run the kernel too."""

MAX_DEPTH = 64
"""Deepest tree the kernel takes."""

COMPILE_TIMEOUT_S = 300
"""Longest a compile of the kernel may take before the compiler is taken as broken."""

MAX_NODES = 1 << 24
"""Most nodes a packed forest may hold (16.8 million: 268 MB of arrays; every node index,
shifted by up to 3 feature bits, stays a positive int32)."""

MAX_TREES = 10_000
"""Most trees a packed forest may hold."""

MAX_STEPS = 65_536
"""Most levels summed over a forest's trees: the nodes one pixel passes (its work; a
50-tree forest 14 deep, the project's default, passes 700)."""

MAX_FOREST_BYTES = (MAX_NODES + PAD) * 16 + MAX_TREES * 4 + 65_536
"""Largest ``forest.npz`` read (its members at their limits, headers included)."""

FLAGS = ("-O2", "-march=native", "-std=c11", "-shared", "-fPIC")
"""Compiler flags of the kernel; ``-march=native`` is replaced by the x86-64 level of the
widest path CPUID reports (:func:`build_library`), and dropped where the compiler refuses it."""

ISAS = ("portable", "sse2", "neon", "avx2", "avx512")
"""The kernel's code paths, by the number its ``dt_forest_isa()`` returns (``_forest.c``)."""

FAST_ISAS = ("avx2", "avx512")
"""Paths measured faster than scikit-learn (docs/performance.md); ``"auto"`` runs these."""

FASTER_THAN_ONNXRUNTIME = ("sse2", "avx2", "avx512")
"""Paths measured faster than ONNX Runtime's tree ensemble on the same CPU (x86-64 with
AVX2, and with AVX-512; docs/performance.md): a forest's ONNX twin runs these where built
here. NEON is not in it: it could not be measured (no aarch64 hardware)."""

ISA_ENV = "DYNTARGET_FOREST_ISA"
"""Environment variable forcing the kernel's path: ``avx512``, ``avx2``, ``sse2``,
``neon``, ``portable`` or ``off`` (no kernel: what a machine without one runs, ONNX
Runtime's tree ensemble (:mod:`dyntarget.perceive.ensemble`) where onnxruntime is
installed, else scikit-learn; ``model.onnx`` for ``plan --onnx``); unset or
``auto``: the widest path this CPU runs (:func:`cpu_runs`)."""

ISA_FLAGS = {
    "avx512": ("-march=x86-64-v4",),
    "avx2": ("-march=x86-64-v3",),
    "sse2": ("-march=x86-64",),
    "neon": ("-march=armv8-a",),
    "portable": ("-DDT_FOREST_SCALAR",),
}
"""Compiler flags that select each forced path (they replace ``-march=native``)."""


def forced_isa() -> str | None:
    """The path :data:`ISA_ENV` forces (``None``: not forced).

    Returns
    -------
    str or None
        One of :data:`ISA_FLAGS` or ``"off"``.

    Examples
    --------
    >>> import os
    >>> forced_isa() if ISA_ENV not in os.environ else None
    """
    value = os.environ.get(ISA_ENV, "").strip().lower()
    if value in ("", "auto"):
        return None
    if value != "off" and value not in ISA_FLAGS:
        raise InvalidParameterError(
            f"{ISA_ENV}={value!r}: expected auto, off or one of {', '.join(ISA_FLAGS)}"
        )
    return value


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
        Its path (and the arguments ``$CC`` gives it), or ``None`` when there is none.

    Examples
    --------
    >>> compiler() is None or isinstance(compiler(), str)
    True
    """
    words = shlex.split(os.environ.get("CC", ""))  # e.g. "ccache gcc"
    if words:
        found = shutil.which(words[0])
        return shlex.join([found, *words[1:]]) if found else None
    return shutil.which("cc") or shutil.which("gcc")


@dataclass(frozen=True)
class PackedForest:
    """A two-class scikit-learn forest as the flat arrays the kernel walks (see the module).

    Parameters
    ----------
    threshold : numpy.ndarray
        ``float32`` per node (+ :data:`PAD`): the split threshold rounded down, ``+inf`` at leaves.
    code : numpy.ndarray
        ``int32`` per node (+ :data:`PAD`): ``child << fshift | feature``; a leaf's child is itself.
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
    source : pathlib.Path or None
        The ``forest.npz`` it was read from (:func:`load_forest`; ``None``: packed in
        memory); its folder is where :func:`fast_predictor` looks for exported kernels.
    sha256 : str or None
        Hex SHA-256 of the bytes of ``source`` as read.
    """

    threshold: np.ndarray
    code: np.ndarray
    value: np.ndarray
    roots: np.ndarray
    depth: int
    features: int
    fshift: int
    source: Path | None = field(default=None, compare=False)
    sha256: str | None = field(default=None, compare=False)

    @functools.cached_property
    def node(self) -> np.ndarray:
        """``int64`` per node: ``code << 32 | bits(threshold)``, one load per node.

        Returns
        -------
        numpy.ndarray
            Built once per forest from ``code`` and ``threshold``.
        """
        total = len(self.value)
        words = self.code[:total].astype(np.int64) << 32
        return words | self.threshold[:total].view(np.uint32)


def same_forest(a: PackedForest, b: PackedForest) -> bool:
    """Whether two packed forests hold the same arrays and numbers (wherever they came from).

    Parameters
    ----------
    a, b : PackedForest
        The forests.

    Returns
    -------
    bool
        ``True`` when every array and number is equal.
    """
    return all(
        np.array_equal(getattr(a, n), getattr(b, n))
        for n in ("threshold", "code", "value", "roots", "depth", "features", "fshift")
    )


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

    if (
        not isinstance(estimator, RandomForestClassifier)
        or getattr(estimator, "n_outputs_", 1) != 1
        or len(estimator.classes_) != 2
    ):
        raise InvalidParameterError(
            "estimator: expected a fitted single-output two-class RandomForestClassifier, "
            f"got {estimator!r}"
        )
    deepest = max(tree.tree_.max_depth for tree in estimator.estimators_)
    if deepest > MAX_DEPTH:
        raise InvalidParameterError(
            f"estimator: trees {deepest} deep; the kernel takes up to {MAX_DEPTH}"
        )
    nfeat = int(estimator.n_features_in_)
    if not 1 <= nfeat <= 8:
        raise InvalidParameterError(f"estimator: the kernel takes 1 to 8 features, not {nfeat}")
    fshift = (nfeat - 1).bit_length()
    total = sum(tree.tree_.node_count for tree in estimator.estimators_)
    if total > MAX_NODES:
        raise InvalidParameterError(f"estimator: {total} nodes are too many for the kernel")
    trees = len(estimator.estimators_)
    steps = sum(tree.tree_.max_depth for tree in estimator.estimators_)
    if trees > MAX_TREES or steps > MAX_STEPS:
        raise InvalidParameterError(
            f"estimator: {trees} trees {steps} levels deep in all; the kernel takes up to "
            f"{MAX_TREES} trees and {MAX_STEPS} levels in all"
        )
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
        split_on = t.feature[order][~leaf]
        if ((split_on < 0) | (split_on >= nfeat)).any():  # would spill into the child bits
            raise InvalidParameterError(
                f"estimator: a tree splits on a feature outside 0..{nfeat - 1}"
            )
        child = np.where(leaf, here, base + pos[np.where(leaf, 0, t.children_left[order])])
        code[here] = (child << fshift) | np.where(leaf, 0, t.feature[order])
        feat = t.feature[order]
        if ((feat < 0) | (feat >= nfeat))[~leaf].any():
            raise InvalidParameterError(f"estimator: a split on a feature outside 0..{nfeat - 1}")
        t64 = t.threshold[order]
        if np.isnan(t64)[~leaf].any():
            raise InvalidParameterError("estimator: a split threshold is NaN")
        # +inf: a split trained on missing values, every finite pixel goes left; as FLT_MAX
        t64 = np.where(np.isposinf(t64), float(np.finfo(np.float32).max), t64)
        with np.errstate(over="ignore"):  # beyond float32: rounds to inf, then down below
            t32 = t64.astype(np.float32)
        t32 = np.where(t32 > t64, np.nextafter(t32, np.float32(-np.inf)), t32)
        threshold[here] = np.where(leaf, np.inf, t32)
        value[here] = np.where(leaf, t.value[order, 0, 1], 0.0)
        roots.append(base)
        base += t.node_count
    return PackedForest(
        threshold=threshold,
        code=code,
        value=value,
        roots=np.asarray(roots, np.int32),
        depth=deepest,
        features=nfeat,
        fshift=fshift,
    )


def save_forest(
    packed: PackedForest, path: str | os.PathLike[str], *, model_sha256: str = ""
) -> Path:
    """Write a packed forest to ``path`` (``.npz``, no pickled objects; atomic).

    Parameters
    ----------
    packed : PackedForest
        From :func:`pack_forest`.
    path : path
        The file, usually ``MODEL_DIR/forest.npz`` (:data:`FOREST_FILE`).
    model_sha256 : str
        Hex SHA-256 of the ``model.onnx`` exported with it, so that a reader can refuse a
        forest that does not belong to the model beside it (empty: not bound).

    Returns
    -------
    pathlib.Path
        ``path``.

    Examples
    --------
    >>> import tempfile
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> x = np.array([[0.0], [1.0], [2.0], [3.0]], np.float32)
    >>> est = RandomForestClassifier(n_estimators=2, random_state=0).fit(x, [0, 0, 1, 1])
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = load_forest(save_forest(pack_forest(est), Path(tmp) / FOREST_FILE))
    >>> back.depth == pack_forest(est).depth
    True
    """
    from dyntarget.io.atomic import atomic_path

    path = Path(path)
    arrays = {n: getattr(packed, n) for n in ("threshold", "code", "value", "roots")}
    scalars = {n: np.int64(getattr(packed, n)) for n in ("depth", "features", "fshift")}
    bound = np.frombuffer(bytes.fromhex(model_sha256), np.uint8)
    import zipfile

    members = {**arrays, **scalars, "model_sha256": bound}
    # np.savez's layout (one .npy per member, stored), dated 1980: the same forest gives the
    # same bytes (np.savez dates each member now, so its bytes change from run to run)
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as archive:
        for name, value in members.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            with archive.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
    return path


def load_forest(path: str | os.PathLike[str], *, model_sha256: str | None = None) -> PackedForest:
    """Read and check a packed forest written by :func:`save_forest`.

    The kernel trusts the arrays (node indices are memory addresses to it), so every
    rule it relies on is checked first: the file's members, their dtypes and sizes
    (before they are read); tree roots as increasing offsets; each tree laid out
    breadth-first with the children of each internal node side by side and every node
    reached from its root once (so each tree is a tree: in range and acyclic); leaves
    pointing to themselves with threshold ``+inf``; no NaN threshold and feature indices
    below the feature count at internal nodes; leaf values in 0..1; the declared depth
    the trees' true depth.

    Parameters
    ----------
    path : path
        A ``forest.npz``.
    model_sha256 : str or None
        Hex SHA-256 of the ``model.onnx`` beside it: the file must have been saved bound
        to that model (``None``: not checked).

    Returns
    -------
    PackedForest
        The checked forest.

    Raises
    ------
    ModelFileError
        One line naming the first rule the file breaks.
    """
    import zipfile

    path = Path(path)

    def fail(why: str) -> ModelFileError:
        return ModelFileError(f"{path}: not a usable packed forest ({why})")

    expected = {"threshold": np.float32, "code": np.int32, "value": np.float64,
                "roots": np.int32, "depth": np.int64, "features": np.int64,
                "fshift": np.int64, "model_sha256": np.uint8}  # fmt: skip
    most = {"threshold": MAX_NODES + PAD, "code": MAX_NODES + PAD, "value": MAX_NODES,
            "roots": MAX_TREES, "depth": 1, "features": 1, "fshift": 1,
            "model_sha256": 32}  # fmt: skip
    limit = MAX_FOREST_BYTES
    try:
        size = os.stat(path).st_size
    except OSError as exc:
        raise fail(f"unreadable: {exc}") from None
    if size > limit:
        raise fail(f"{size:,} bytes, more than the {limit:,} a forest may hold")
    from dyntarget.errors import DataFileError
    from dyntarget.io.safeopen import read_bytes

    try:
        raw = read_bytes(path, max_bytes=limit)  # read once: what is checked is what was hashed
        archive = zipfile.ZipFile(io.BytesIO(raw))
        infos = archive.infolist()
    except (OSError, DataFileError, zipfile.BadZipFile, ValueError) as exc:
        raise fail(f"unreadable: {exc}") from None
    names = {f"{name}.npy" for name in expected}
    if len(infos) != len(names) or {i.filename for i in infos} != names:
        shown = sorted(i.filename for i in infos[:20])
        raise fail(
            f"members {shown}{' ...' if len(infos) > 20 else ''}, expected {sorted(names)}; "
            "a forest.npz of dyntarget's is rewritten by 'dyntarget export-onnx'"
        )
    for info in infos:  # from the headers, before anything is read or allocated
        name = info.filename[:-4]
        if info.compress_type != zipfile.ZIP_STORED or info.file_size != info.compress_size:
            raise fail(f"{name} is compressed; a forest's members are stored")
        try:
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                read_header = (
                    np.lib.format.read_array_header_1_0
                    if version == (1, 0)
                    else np.lib.format.read_array_header_2_0
                )
                shape, _, dtype = read_header(member, max_header_size=1024)
                offset = member.tell()
        except Exception as exc:  # numpy raises several types on a broken header
            raise fail(f"{name}: unreadable array header ({exc})") from None
        count = int(np.prod(shape, dtype=object))
        if dtype != expected[name]:
            raise fail(f"{name} is not {np.dtype(expected[name]).name}")
        if len(shape) > 1:
            raise fail(f"{name}: arrays must be one-dimensional")
        if most[name] == 1 and shape != ():
            raise fail("depth, features and fshift must be single numbers")
        if count > most[name]:
            raise fail(
                f"{name} holds {count:,} values, more than the {most[name]:,} a forest may "
                f"have ({MAX_NODES:,} nodes, {MAX_TREES:,} trees)"
            )
        if offset + count * dtype.itemsize != info.file_size:
            raise fail(f"{name}: its header declares {count:,} values, not what it holds")
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as npz:
            data = {k: npz[k] for k in expected}
    except Exception as exc:  # numpy raises several types on a corrupt archive
        raise fail(f"unreadable: {exc}") from None
    for name, want in expected.items():
        if data[name].dtype != want:
            raise fail(f"{name} is not {np.dtype(want).name}")
    threshold, code, value, roots = (data[n] for n in ("threshold", "code", "value", "roots"))
    if any(data[n].ndim != 0 for n in ("depth", "features", "fshift")):
        raise fail("depth, features and fshift must be single numbers")
    depth, features, fshift = (int(data[n]) for n in ("depth", "features", "fshift"))
    if model_sha256 is not None and data["model_sha256"].tobytes().hex() != model_sha256:
        raise ModelFileError(
            f"{path}: exported with another model.onnx than the one beside it; "
            "run 'dyntarget export-onnx' again"
        )
    if any(a.ndim != 1 for a in (threshold, code, value, roots)):
        raise fail("arrays must be one-dimensional")
    total = len(value)
    if not 1 <= features <= 8 or fshift != (features - 1).bit_length():
        raise fail(f"features {features} with fshift {fshift}")
    if len(threshold) != total + PAD or len(code) != total + PAD or total < 1:
        raise fail("threshold, code and value lengths disagree")
    if total > MAX_NODES or not 0 <= depth <= MAX_DEPTH:
        raise fail(f"{total} nodes of depth {depth} are out of the kernel's range")
    starts = roots.astype(np.int64)
    if len(starts) < 1 or starts[0] != 0 or (np.diff(starts) < 1).any() or starts[-1] >= total:
        raise fail("tree roots are not increasing offsets into the nodes")
    node = np.arange(total)
    thr, cod = threshold[:total], code[:total]
    leaf = np.isposinf(thr)
    child = (cod >> fshift).astype(np.int64)
    feature = cod & ((1 << fshift) - 1)
    if (leaf & ((child != node) | (feature != 0))).any():
        raise fail("a leaf does not point to itself")
    if np.isnan(thr[~leaf]).any():
        raise fail("an internal node has a NaN threshold")
    if (feature >= features)[~leaf].any():
        raise fail(f"an internal node splits on a feature out of range (features {features})")
    if not (np.isfinite(value) & (value >= 0) & (value <= 1)).all():
        raise fail("leaf values must lie in 0..1")
    # breadth-first, siblings side by side: in each tree the children of the internal
    # nodes, in order, are exactly the tree's other nodes, in order
    inner = np.flatnonzero(~leaf)
    others = np.setdiff1d(node, starts, assume_unique=True)
    sizes = np.diff(np.append(starts, total))
    if not np.array_equal(sizes - 1, 2 * np.add.reduceat(~leaf, starts)) or not np.array_equal(
        child[inner], others[0::2]
    ):
        raise fail("a tree is not laid out breadth-first")
    level = np.full(total, -1)
    level[starts] = 0
    deepest = 0
    while deepest <= MAX_DEPTH:  # from the roots down: every node must be reached
        parents = np.flatnonzero((level == deepest) & ~leaf)
        if not len(parents):
            break
        children = child[parents]
        deepest += 1
        level[children] = level[children + 1] = deepest
    if (level < 0).any():
        raise fail("a node is not reached from its tree's root")
    if depth != deepest:
        raise fail(f"declared depth {depth}, the trees are {deepest} deep")
    steps = int(np.maximum.reduceat(level, starts).sum())  # nodes a pixel passes, all trees
    if steps > MAX_STEPS:
        raise fail(
            f"{len(starts):,} trees {steps:,} levels deep in all, more than the {MAX_STEPS:,} "
            "a forest may have (the work per pixel)"
        )
    return PackedForest(
        threshold=threshold,
        code=code,
        value=value,
        roots=roots,
        depth=depth,
        features=features,
        fshift=fshift,
        source=path,
        sha256=hashlib.sha256(raw).hexdigest(),
    )


_NEEDS = {
    "avx512": ("avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl", "avx2", "fma", "bmi2"),
    "avx2": ("avx2", "fma", "bmi1", "bmi2", "f16c", "movbe", "abm"),
}
_NUMPY_NAMES = {"avx512f": "AVX512F", "avx512bw": "AVX512BW", "avx512cd": "AVX512CD",
                "avx512dq": "AVX512DQ", "avx512vl": "AVX512VL", "avx2": "AVX2", "fma": "FMA3",
                "bmi1": "BMI", "bmi2": "BMI2", "f16c": "F16C", "movbe": "MOVBE",
                "abm": "LZCNT"}  # fmt: skip


def _cpuid_features() -> dict[str, bool]:
    """numpy's run-time CPU features (read with CPUID and XGETBV at its import), ``{}`` if absent.

    Preferred to ``/proc/cpuinfo``: it is what the running code can execute, also where
    the CPU is emulated (``qemu-x86_64 -cpu Haswell`` passes the host's ``/proc/cpuinfo``).
    """
    import importlib

    for name in ("numpy._core._multiarray_umath", "numpy.core._multiarray_umath"):  # 2.x, 1.x
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        return dict(getattr(module, "__cpu_features__", {}))
    return {}


def cpu_runs(isa: str) -> bool:
    """Whether this CPU runs the kernel's path ``isa`` (a key of :data:`ISA_FLAGS`).

    Parameters
    ----------
    isa : str
        The path.

    Returns
    -------
    bool
        From the machine's architecture and ``/proc/cpuinfo``'s flags.

    Examples
    --------
    >>> cpu_runs("portable")
    True
    """
    machine = platform.machine().lower()
    if isa == "portable":
        return True
    if isa == "neon":
        return machine in ("aarch64", "arm64")
    if machine not in ("x86_64", "amd64"):
        return False
    needs = _NEEDS.get(isa, ())
    found = _cpuid_features()
    if all(_NUMPY_NAMES[f] in found for f in needs):
        return all(found[_NUMPY_NAMES[f]] for f in needs)
    flags = set(_cpu().replace(":", " ").split())  # an older numpy without some names
    return all(f in flags for f in needs)


def _best_isa() -> str | None:
    """The widest vectorised path this x86-64 CPU runs (:func:`cpu_runs`); ``None`` elsewhere."""
    if _arch() != "x86_64":
        return None
    return next((isa for isa in ("avx512", "avx2") if cpu_runs(isa)), None)


def _cpu() -> str:
    """The CPU's model and feature flags (part of the cache key: ``-march=native``)."""
    try:
        with open("/proc/cpuinfo") as fh:
            lines = [ln for ln in fh if ln.startswith(("model name", "flags", "Features"))]
        return "".join(sorted(set(lines)))
    except OSError:
        return f"{platform.machine()} {platform.processor()}"


_SAID: set[str] = set()


def _say_once(line: str) -> None:
    """Print ``line`` on stderr once per process (a fallback the user should know about)."""
    with _LOCK:
        if line not in _SAID:
            _SAID.add(line)
            print(line, file=sys.stderr)


def _digest_path(lib: Path) -> Path:
    return lib.with_name(lib.name + ".sha256")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _private_group(gid: int) -> bool:
    """Whether group ``gid`` is this user's own private group (named after the user, no members)."""
    try:
        import grp
        import pwd

        me = pwd.getpwuid(os.getuid())
        group = grp.getgrgid(gid)
    except (ImportError, KeyError, AttributeError):
        return False
    return gid == me.pw_gid and group.gr_name == me.pw_name and not group.gr_mem


def _private_stat(st: os.stat_result) -> str | None:
    """Why a file of this ``stat`` is not this user's alone (``None`` when it is)."""
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        return f"is owned by another user (uid {st.st_uid})"
    if st.st_mode & 0o002 or (st.st_mode & 0o020 and not _private_group(st.st_gid)):
        return f"is writable by others (mode {stat.S_IMODE(st.st_mode):o})"
    return None


def _private(path: Path) -> str | None:
    """Why ``path`` is not ours alone (``None`` when it is): owner, mode, kind."""
    try:
        st = os.lstat(path)
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    if stat.S_ISLNK(st.st_mode):
        return "is a symbolic link"
    return _private_stat(st)


def _check_private(where: Path) -> None:
    why = _private(where)
    if why is None and not where.is_dir():
        why = "is not a folder"
    if why is not None:
        raise MissingExtraError(f"the forest-kernel cache {where} {why}: not used")


def _recorded(lib: Path) -> str | None:
    """The SHA-256 recorded beside ``lib`` when dyntarget built or installed it (``None``: none)."""
    digest = _digest_path(lib)
    try:
        st = os.lstat(digest)
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode) or _private_stat(st) is not None or st.st_size > 128:
        return None
    try:
        return digest.read_text(errors="replace").strip()
    except OSError:
        return None


def _trusted(lib: Path) -> bool:
    """Whether ``lib`` looks like a kernel this user's dyntarget built: ours alone, hash recorded.

    A first look by path, to pick a library; what is loaded is checked again, and hashed,
    on the one descriptor it is loaded through (:func:`_load`). A library that is there but
    fails a check is never loaded (it is rebuilt where a compiler is, else the kernel is not
    used).
    """
    if not os.path.lexists(lib) or _private(lib) is not None:
        return False
    if not stat.S_ISREG(os.lstat(lib).st_mode):
        return False
    recorded = _recorded(lib)
    return recorded is not None and recorded == _sha256(lib)


_ELF_MACHINES = {62: "x86_64", 183: "aarch64", 3: "i386", 40: "arm", 243: "riscv64"}


def elf_arch(head: bytes) -> str | None:
    """The architecture an ELF shared library was built for, from its header.

    Parameters
    ----------
    head : bytes
        The file's first 20 bytes (or more).

    Returns
    -------
    str or None
        ``"x86_64"``, ``"aarch64"``, ... (``"machine N"`` for another), ``None`` when the
        bytes are not a little-endian ELF shared object.

    Examples
    --------
    >>> elf_arch(b"\\x7fELF\\x02\\x01" + bytes(10) + (3).to_bytes(2, "little") + (183).to_bytes(2, "little"))
    'aarch64'
    >>> elf_arch(b"MZ") is None
    True
    """
    if len(head) < 20 or head[:4] != b"\x7fELF" or head[5] != 1:
        return None
    if int.from_bytes(head[16:18], "little") != 3:  # ET_DYN
        return None
    machine = int.from_bytes(head[18:20], "little")
    return _ELF_MACHINES.get(machine, f"machine {machine}")


def _source_key(source: bytes, flags: list[str]) -> str:
    """The part of a cached kernel's name fixed by what it is built from, but the compiler:
    the source, the flags and, for ``-march=native``, this CPU (model and feature flags)."""
    where = _cpu() if "-march=native" in flags else _arch()
    key = b"\0".join([source, " ".join(flags).encode(), where.encode()])
    return hashlib.sha256(key).hexdigest()[:24]


def _compiler_key(cc: str) -> str:
    """The part of a cached kernel's name fixed by the compiler: its resolved path, size
    and modification time (an upgraded compiler builds anew), and the arguments ``$CC`` gives."""
    words = shlex.split(cc)
    real = os.path.realpath(words[0])
    try:
        st = os.stat(real)
        ident = f"{real}\0{st.st_size}\0{st.st_mtime_ns}\0{' '.join(words[1:])}"
    except OSError:
        ident = cc
    return hashlib.sha256(ident.encode()).hexdigest()[:12]


INSTALLED = "installed"
"""The compiler part of the name of a kernel put in the cache by :func:`install_kernel`."""

MAX_LIBRARY_BYTES = 16 << 20
"""Largest kernel library read (the kernel is about 50 kB)."""


def build_library(
    directory: str | os.PathLike[str] | None = None,
    *,
    portable: bool = False,
    isa: str | None = None,
) -> Path:
    """Compile the kernel for this machine (once; later calls find it in the cache).

    The cache (:func:`cache_dir`, created ``0700``) must be this user's alone; a library is
    named ``forest-kernel-SOURCE-COMPILER.so`` after a SHA-256 of what it was built from
    (the kernel's source, the flags, for ``-march=native`` this CPU, and the compiler) and
    has its own SHA-256 recorded beside it. Without a compiler, a library of the same
    source and flags built here earlier, or put here by :func:`install_kernel`, serves.

    Parameters
    ----------
    directory : path, optional
        Cache directory (default :func:`cache_dir`).
    portable : bool
        Compile for the baseline of the machine (SSE2 or NEON).
    isa : str, optional
        Force a path (a key of :data:`ISA_FLAGS`); default :func:`forced_isa`, else on
        x86-64 the widest path the CPU's CPUID reports (``-march=x86-64-v4`` or ``-v3``,
        the flags ``export-onnx`` builds that target with), elsewhere ``-march=native``;
        the baseline build is the fallback where the compiler refuses those flags.

    Returns
    -------
    pathlib.Path
        The shared library.

    Raises
    ------
    MissingExtraError
        No C compiler and no cached build, or the kernel does not compile.
    """
    source = files("dyntarget.perceive").joinpath("_forest.c").read_bytes()
    where = Path(directory) if directory is not None else cache_dir()
    isa = isa or forced_isa()
    if isa == "off":
        raise MissingExtraError(f"the forest kernel is off ({ISA_ENV}=off)")
    base = [f for f in FLAGS if f != "-march=native"]
    best = None if portable or isa else _best_isa()
    if isa:
        first = [*base, *ISA_FLAGS[isa]]
        portable = True  # a forced path has no fallback build
    elif best:  # the named level of the widest path CPUID reports, as export-onnx builds it
        first = [*base, *ISA_FLAGS[best]]
    else:
        first = base if portable else list(FLAGS)
    wanted = [first, base][: 2 if not portable else 1]  # the preferred first; the baseline
    cc = compiler()
    if where.exists() or os.path.lexists(where):
        _check_private(where)  # nothing is loaded from, or built into, a folder others can write
    if cc is None:  # a build of the same source and flags (any compiler), or an installed one
        lookups = list(wanted)
        if not isa and not portable:  # also a named level this CPU runs (installed kernels)
            named = [i for i in _PREFERENCE if i in ISA_FLAGS and i != "portable" and cpu_runs(i)]
            lookups[1:1] = [[*base, *ISA_FLAGS[i]] for i in named]
        for flags in lookups:
            for lib in sorted(where.glob(f"forest-kernel-{_source_key(source, flags)}-*.so")):
                if _trusted(lib):
                    return lib
        raise MissingExtraError(
            "the compiled forest needs a C compiler (cc or gcc) on the PATH, or a kernel "
            "installed into this user's cache ('dyntarget install-kernel')"
        )
    ckey = _compiler_key(cc)
    builds = [(f, where / f"forest-kernel-{_source_key(source, f)}-{ckey}.so") for f in wanted]
    if _trusted(builds[0][1]):
        return builds[0][1]
    for flags, lib in builds:
        if _trusted(lib):
            return lib
        where.mkdir(mode=0o700, parents=True, exist_ok=True)
        _check_private(where)
        with tempfile.TemporaryDirectory(dir=where) as tmp:
            src, part = Path(tmp) / "_forest.c", Path(tmp) / lib.name
            src.write_bytes(source)
            try:
                done = subprocess.run(
                    [*shlex.split(cc), *flags, str(src), "-o", str(part)],
                    capture_output=True,
                    timeout=COMPILE_TIMEOUT_S,
                )
            except (OSError, subprocess.SubprocessError) as exc:
                raise MissingExtraError(f"the C compiler {cc} does not run ({exc})") from None
            if done.returncode == 0:
                _publish(part, lib)
                return lib
        error = done.stderr.decode(errors="replace").strip().splitlines()
    raise MissingExtraError(f"the forest kernel does not compile with {cc}: {error[-1:]}")


def _publish(part: Path, lib: Path) -> None:
    """Move the library ``part`` (in a private temporary folder) to ``lib`` with its hash."""
    os.chmod(part, 0o755)
    digest = part.with_name("digest")
    digest.write_text(_sha256(part) + "\n")
    os.chmod(digest, 0o644)
    os.replace(part, lib)  # atomic: a reader never sees half a library
    os.replace(digest, _digest_path(lib))  # the hash of what we built


def install_kernel(
    library: str | os.PathLike[str],
    *,
    target: str | None = None,
    directory: str | os.PathLike[str] | None = None,
) -> Path:
    """Copy a kernel built elsewhere (``export-onnx --targets``) into this user's cache.

    The deliberate act that lets a machine without a compiler (a flight computer) run the
    kernel: a library is never loaded from a model directory, only from the cache, and
    this copies the bytes read (through one descriptor) into it, under the name a build of
    the same source and flags would have (:func:`build_library`), with their SHA-256. The
    library must be an ELF shared object for this machine's architecture and ``target``.

    Parameters
    ----------
    library : path
        The library, e.g. ``MODEL/forest-kernel-aarch64.so``.
    target : str, optional
        A key of :data:`TARGETS`; default: from the file name (``forest-kernel-TARGET.so``).
    directory : path, optional
        Cache directory (default :func:`cache_dir`).

    Returns
    -------
    pathlib.Path
        The installed library in the cache.

    Raises
    ------
    InvalidParameterError
        An unknown target, a file that is not a library, or a library for another
        architecture than the target's or this machine's (one line naming both).
    """
    from dyntarget.io.safeopen import read_bytes

    library = Path(library)
    if target is None:
        stem = library.name.removeprefix("forest-kernel-").removesuffix(".so")
        target = stem if stem in TARGETS and library.name.startswith("forest-kernel-") else None
        if target is None:
            raise InvalidParameterError(
                f"{library}: name the target ({', '.join(TARGETS)}); the file name does not"
            )
    if target not in TARGETS:
        raise InvalidParameterError(f"target {target!r}: expected one of {', '.join(TARGETS)}")
    _, arch, flags = TARGETS[target]
    data = read_bytes(library, max_bytes=MAX_LIBRARY_BYTES, what="kernel library")
    found = elf_arch(data[:20])
    if found is None:
        raise InvalidParameterError(f"{library}: not an ELF shared library")
    if found != arch or arch != _arch():
        raise InvalidParameterError(
            f"{library}: a library built for {found}; target {target} is {arch} and this "
            f"machine is {_arch()}: not installed"
        )
    source = files("dyntarget.perceive").joinpath("_forest.c").read_bytes()
    base = [f for f in FLAGS if f != "-march=native"]
    where = Path(directory) if directory is not None else cache_dir()
    lib = where / f"forest-kernel-{_source_key(source, [*base, *flags])}-{INSTALLED}.so"
    where.mkdir(mode=0o700, parents=True, exist_ok=True)
    _check_private(where)
    with tempfile.TemporaryDirectory(dir=where) as tmp:
        part = Path(tmp) / lib.name
        part.write_bytes(data)
        _publish(part, lib)
    return lib


def _between_check_and_load(fd: int, lib: Path) -> None:
    """Called after a library is checked on descriptor ``fd`` and before it is loaded from
    that descriptor (a no-op; tests replace ``lib`` on disk here to show the swap is not run)."""


def _read_fd(fd: int, limit: int) -> bytes:
    chunks: list[bytes] = []
    total = 0
    while True:
        block = os.read(fd, 1 << 20)
        if not block:
            return b"".join(chunks)
        chunks.append(block)
        total += len(block)
        if total > limit:
            raise MissingExtraError(f"a kernel library of more than {limit:,} bytes")


def _load(lib: Path) -> ctypes.CDLL:
    """``dlopen`` the kernel ``lib`` of the cache, checked and hashed on the descriptor loaded.

    The file is opened once (no link followed); on that descriptor its owner (this user),
    mode (not writable by others), kind (a regular file), architecture (ELF header) and
    SHA-256 (the one recorded when it was built or installed) are checked; then the library
    is loaded from ``/proc/self/fd/N``, the same open file, so a file swapped in at the path
    after the check is not what runs. The descriptor stays open while the library is loaded
    (the loader knows it by that name). Where there is no ``/proc/self/fd`` (not Linux),
    nothing is loaded: one ``MissingExtraError``, and the slower backends predict.
    """
    with _LOCK:
        _check_private(lib.parent)  # a folder others can write could swap the record too
        recorded = _recorded(lib)
        if recorded is None:
            raise MissingExtraError(f"{lib}: no SHA-256 recorded when it was built: not loaded")
        flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        try:
            fd = os.open(lib, flags)
        except OSError as exc:
            raise MissingExtraError(f"{lib}: cannot be opened ({exc.strerror})") from None
        keep = False
        try:
            st = os.fstat(fd)
            why = "is not a regular file" if not stat.S_ISREG(st.st_mode) else _private_stat(st)
            if why is not None:
                raise MissingExtraError(f"{lib} {why}: not loaded")
            data = _read_fd(fd, MAX_LIBRARY_BYTES)
            digest = hashlib.sha256(data).hexdigest()
            if digest != recorded:
                raise MissingExtraError(
                    f"{lib}: its SHA-256 is not the one recorded when it was built: not loaded"
                )
            arch = elf_arch(data[:20])
            if arch != _arch():
                raise MissingExtraError(
                    f"{lib}: a library built for {arch or 'no known architecture'}, this "
                    f"machine is {_arch()}: not loaded"
                )
            if digest in _LOADED:
                return _LOADED[digest]
            proc = f"/proc/self/fd/{fd}"
            if not os.path.exists(proc):
                raise MissingExtraError(
                    "this system has no /proc/self/fd to load the kernel through the "
                    "descriptor it was checked on: the kernel is not used"
                )
            _between_check_and_load(fd, lib)
            dll = ctypes.CDLL(proc)
            keep = True  # the loader names the library by this descriptor's number
        finally:
            if not keep:
                os.close(fd)
        i32, i64, ptr = ctypes.c_int32, ctypes.c_int64, ctypes.c_void_p
        try:
            predict, abi = dll.dt_forest_predict, dll.dt_forest_abi
        except AttributeError:
            raise MissingExtraError(f"{lib}: not a forest kernel (symbols missing)") from None
        predict.argtypes = [ptr, i64, i32, i32, i32, ptr, ptr, ptr, ptr, ptr, i32, ptr]
        predict.restype = ctypes.c_int
        if abi() != 2:
            raise MissingExtraError(f"{lib}: a forest kernel of another ABI")
        _LOADED[digest] = dll
        return dll


MANIFEST_FILE = "forest.json"
"""The manifest in a model directory: the packed forest's SHA-256, the SHA-256 of the
``model.skops`` it was packed from, and each kernel built ahead of time for a named target
(file, target, path, SHA-256 of the library and of the ``forest.npz`` it was built for)."""

MANIFEST_FORMAT = "dyntarget-forest"

TARGETS = {
    "x86-64-v4": ("avx512", "x86_64", ("-march=x86-64-v4",)),
    "x86-64-v3": ("avx2", "x86_64", ("-march=x86-64-v3",)),
    "x86-64": ("sse2", "x86_64", ("-march=x86-64",)),
    "aarch64": ("neon", "aarch64", ("-march=armv8-a",)),
}
"""Targets ``export-onnx --targets`` builds the kernel for: its path (:data:`ISAS`), the
architecture and the compiler flags."""

CROSS_COMPILERS = {
    "x86_64": "x86_64-linux-gnu-gcc",
    "aarch64": "aarch64-linux-gnu-gcc",
}
"""The Debian cross compiler of each architecture (packages ``gcc-x86-64-linux-gnu``,
``gcc-aarch64-linux-gnu``), used where the host is of another architecture."""

_PREFERENCE = ("avx512", "avx2", "neon", "sse2", "portable")


def _arch() -> str:
    machine = platform.machine().lower()
    return {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)


def cpu_class() -> str:
    """This CPU in the words the fallback messages use, e.g. ``"x86-64 with AVX2, no AVX-512"``.

    Returns
    -------
    str
        The architecture and the widest kernel path it runs.

    Examples
    --------
    >>> isinstance(cpu_class(), str)
    True
    """
    arch = _arch()
    if arch == "x86_64":
        if cpu_runs("avx512"):
            return "x86-64 with AVX-512"
        if cpu_runs("avx2"):
            return "x86-64 with AVX2, no AVX-512"
        return "x86-64 without AVX2"
    if arch == "aarch64":
        return "aarch64 (NEON)"
    return arch or "an unknown CPU"


def target_compiler(target: str) -> str | None:
    """The C compiler that builds the kernel for ``target`` on this machine.

    The host's compiler (:func:`compiler`) for the host's architecture, else the Debian
    cross compiler named in :data:`CROSS_COMPILERS` if it is on the PATH.

    Parameters
    ----------
    target : str
        A key of :data:`TARGETS`.

    Returns
    -------
    str or None
        The compiler, ``None`` when there is none.

    Examples
    --------
    >>> target_compiler("x86-64-v3") is None or isinstance(target_compiler("x86-64-v3"), str)
    True
    """
    arch = TARGETS[target][1]
    if arch == _arch():
        return compiler()
    return shutil.which(CROSS_COMPILERS[arch])


def available_targets() -> tuple[list[str], list[str]]:
    """The targets this machine has a compiler for, and why each other one is not built.

    ``export-onnx``'s default (``--targets auto``): every CPU class of :data:`TARGETS`
    whose compiler is here (:func:`target_compiler`), so that the onboard ``--onnx`` path
    finds a kernel on any x86-64 (baseline, AVX2, AVX-512) and on aarch64, and ONNX
    Runtime's slower tree ensemble is left for CPUs of no listed class.

    Returns
    -------
    list of str
        Keys of :data:`TARGETS`, in its order.
    list of str
        One line per target left out, naming the compiler it needs.

    Examples
    --------
    >>> built, left = available_targets()
    >>> sorted(built + [line.split(":")[0] for line in left]) == sorted(TARGETS)
    True
    """
    built, left = [], []
    for target, (_, arch, _) in TARGETS.items():
        if target_compiler(target) is not None:
            built.append(target)
        else:
            package = {"x86_64": "gcc-x86-64-linux-gnu", "aarch64": "gcc-aarch64-linux-gnu"}
            need = "cc or gcc" if arch == _arch() else CROSS_COMPILERS.get(arch, arch)
            left.append(
                f"{target}: no {need} on the PATH (Debian: apt-get install {package.get(arch, 'gcc')})"
            )
    return built, left


def parse_targets(text: str) -> list[str]:
    """``"x86-64-v3,aarch64"`` as a list of :data:`TARGETS`.

    ``"host"`` is this machine's best target; ``"auto"`` alone every target there is a
    compiler for (:func:`available_targets`); ``"none"`` or an empty string none.

    Parameters
    ----------
    text : str
        Comma-separated target names, or ``auto`` or ``none``.

    Returns
    -------
    list of str
        The targets, each once, in the order given.

    Examples
    --------
    >>> parse_targets("x86-64-v4, aarch64,x86-64-v4")
    ['x86-64-v4', 'aarch64']
    >>> parse_targets("none")
    []
    """
    word = text.strip().lower()
    if word == "auto":
        return available_targets()[0]
    if word == "none":
        return []
    out: list[str] = []
    for word in (w.strip().lower() for w in text.split(",")):
        if not word:
            continue
        if word == "host":
            word = next(
                (t for t, (isa, arch, _) in TARGETS.items() if arch == _arch() and cpu_runs(isa)),
                "",
            )
            if not word:
                raise InvalidParameterError(f"--targets host: no target for {cpu_class()}")
        if word not in TARGETS:
            raise InvalidParameterError(
                f"--targets: unknown target {word!r}; expected auto, none, or of "
                f"{', '.join(TARGETS)} and host"
            )
        if word not in out:
            out.append(word)
    return out


def _kernel_file(target: str) -> str:
    return f"forest-kernel-{target}.so"


def build_target(target: str, out: str | os.PathLike[str]) -> Path:
    """Compile the kernel for ``target`` into the shared library ``out`` (atomic).

    Parameters
    ----------
    target : str
        A key of :data:`TARGETS`.
    out : path
        The library to write.

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    InvalidParameterError
        No compiler for the target on this machine (one line naming the package).
    MissingExtraError
        The kernel does not compile.
    """
    cc = target_compiler(target)
    _, arch, flags = TARGETS[target]
    if cc is None:
        package = {"x86_64": "gcc-x86-64-linux-gnu", "aarch64": "gcc-aarch64-linux-gnu"}[arch]
        raise InvalidParameterError(
            f"--targets {target}: no C compiler for {arch} here "
            f"({CROSS_COMPILERS[arch]} not on the PATH; Debian: apt-get install {package})"
        )
    out = Path(out)
    source = files("dyntarget.perceive").joinpath("_forest.c").read_bytes()
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        src, part = Path(tmp) / "_forest.c", Path(tmp) / out.name
        src.write_bytes(source)
        argv = [*shlex.split(cc), "-O2", "-std=c11", "-shared", "-fPIC", *flags]
        try:
            done = subprocess.run(
                [*argv, str(src), "-o", str(part)], capture_output=True, timeout=COMPILE_TIMEOUT_S
            )
        except (OSError, subprocess.SubprocessError) as exc:
            raise MissingExtraError(f"the C compiler {cc} does not run ({exc})") from None
        if done.returncode != 0:
            error = done.stderr.decode(errors="replace").strip().splitlines()
            raise MissingExtraError(
                f"the forest kernel does not compile for {target}: {error[-1:]}"
            )
        os.chmod(part, 0o644)
        os.replace(part, out)
    return out


def build_kernels(
    model_dir: str | os.PathLike[str], targets: list[str], *, failed: list[str] | None = None
) -> list[dict]:
    """Build the kernel for each of ``targets`` into ``model_dir`` for its ``forest.npz``.

    Every compiler is looked for before anything is built; the libraries are
    ``forest-kernel-TARGET.so``.

    Parameters
    ----------
    model_dir : path
        A model directory holding ``forest.npz``.
    targets : list of str
        Keys of :data:`TARGETS`.
    failed : list of str, optional
        Where given, a target whose build fails is left out and a line saying why is
        appended here (``export-onnx``'s default targets); otherwise the failure raises.

    Returns
    -------
    list of dict
        The manifest's entries: ``file``, ``target``, ``isa``, ``arch``, ``sha256`` (of the
        library) and ``forest_sha256`` (of the ``forest.npz`` it is for).

    Raises
    ------
    InvalidParameterError
        A target with no compiler here (one line naming the Debian package).
    """
    model_dir = Path(model_dir)
    for target in targets:
        if target_compiler(target) is None:
            build_target(target, model_dir / _kernel_file(target))  # raises, naming the package
    forest_sha = _sha256(model_dir / FOREST_FILE)
    kernels = []
    for target in targets:
        try:
            lib = build_target(target, model_dir / _kernel_file(target))
        except MissingExtraError as exc:
            if failed is None:
                raise
            failed.append(f"{target}: {exc}")
            continue
        isa, arch, _ = TARGETS[target]
        kernels.append({"file": lib.name, "target": target, "isa": isa, "arch": arch,
                        "sha256": _sha256(lib), "forest_sha256": forest_sha})  # fmt: skip
    return kernels


def kernel_files(model_dir: str | os.PathLike[str]) -> list[Path]:
    """The exported kernel libraries in ``model_dir`` (``forest-kernel-TARGET.so``).

    Parameters
    ----------
    model_dir : path
        A model directory.

    Returns
    -------
    list of pathlib.Path
        Those present.
    """
    return [Path(model_dir) / _kernel_file(t) for t in TARGETS if
            os.path.lexists(Path(model_dir) / _kernel_file(t))]  # fmt: skip


def write_manifest(model_dir: str | os.PathLike[str], kernels: list[dict] | None = None) -> Path:
    """Bind ``forest.npz`` to its model: ``MODEL_DIR/forest.json``.

    Records the SHA-256 of ``forest.npz`` and of ``model.skops`` (when there) and the
    exported kernels (:func:`build_kernels`).

    Parameters
    ----------
    model_dir : path
        A model directory holding ``forest.npz``.
    kernels : list of dict, optional
        The kernels' entries; default: those of the manifest already there.

    Returns
    -------
    pathlib.Path
        The manifest.
    """
    from dyntarget.io.atomic import write_text

    model_dir = Path(model_dir)
    path = check_manifest_readable(model_dir)  # nothing rewrites a file it could not read
    if kernels is None:
        kernels = (read_manifest(model_dir) or {}).get("kernels", [])
    skops = model_dir / "model.skops"
    manifest = {
        "format": MANIFEST_FORMAT,
        "version": 1,
        "forest": {"file": FOREST_FILE, "sha256": _sha256(model_dir / FOREST_FILE)},
        "model_skops_sha256": _sha256(skops) if skops.is_file() else None,
        "kernels": kernels,
    }
    write_text(path, json.dumps(manifest, indent=2) + "\n")
    return path


def check_manifest_readable(model_dir: str | os.PathLike[str]) -> Path:
    """Refuse to go on where ``forest.json`` is there but cannot be read (it is never rewritten).

    Parameters
    ----------
    model_dir : path
        A model directory.

    Returns
    -------
    pathlib.Path
        The manifest's path (absent, or readable).

    Raises
    ------
    dyntarget.errors.DataFileError
        One line naming the file and why it cannot be read.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     check_manifest_readable(tmp).name
    'forest.json'
    """
    from dyntarget.errors import DataFileError

    path = Path(model_dir) / MANIFEST_FILE
    if os.path.lexists(path):
        try:
            with open(path, "rb"):
                pass
        except OSError as exc:
            raise DataFileError(
                f"{path}: cannot be read ({exc.strerror}); it is not rewritten"
            ) from None
    return path


def read_manifest(model_dir: str | os.PathLike[str]) -> dict | None:
    """The manifest of a model directory (:func:`write_manifest`), ``None`` when absent or broken.

    Parameters
    ----------
    model_dir : path
        The model directory.

    Returns
    -------
    dict or None
        The parsed manifest, its format checked.
    """
    path = Path(model_dir) / MANIFEST_FILE
    if not path.is_file():
        return None
    from dyntarget.io.safeopen import read_json

    try:
        data = read_json(path, max_bytes=1 << 16)
    except (OSError, ValueError):
        return None
    if (
        not isinstance(data, dict)
        or data.get("format") != MANIFEST_FORMAT
        or not isinstance(data.get("forest"), dict)
        or not isinstance(data.get("kernels"), list)
    ):
        return None
    return data


def bound_forest(model_dir: str | os.PathLike[str]) -> tuple[PackedForest | None, str]:
    """The packed forest of a native model directory, if it is the one of its ``model.skops``.

    Parameters
    ----------
    model_dir : path
        A model directory written by ``dyntarget train`` (random forest).

    Returns
    -------
    PackedForest or None
        The checked forest (:func:`load_forest`), ``None`` when there is none or it is not
        bound to this ``model.skops``.
    str
        Why it is ``None`` (empty otherwise).
    """
    model_dir = Path(model_dir)
    if not (model_dir / FOREST_FILE).is_file():
        return None, f"no {FOREST_FILE}"
    manifest = read_manifest(model_dir)
    if manifest is None:
        return None, f"no readable {MANIFEST_FILE}"
    skops = model_dir / "model.skops"
    if not skops.is_file() or manifest.get("model_skops_sha256") != _sha256(skops):
        return None, f"{FOREST_FILE} was not packed from this model.skops"
    packed = load_forest(model_dir / FOREST_FILE)
    if packed.sha256 != manifest["forest"].get("sha256"):
        return None, f"{FOREST_FILE} is not the one {MANIFEST_FILE} records"
    return packed, ""


def shipped_kernels(packed: PackedForest) -> str:
    """What a model directory ships as kernel libraries, which are never loaded from it.

    Parameters
    ----------
    packed : PackedForest
        A forest read by :func:`load_forest` (its folder is looked at).

    Returns
    -------
    str
        Empty when the folder holds no ``forest-kernel-TARGET.so``; else one clause naming
        them (and those built for another architecture) and how to install one.
    """
    if packed.source is None:
        return ""
    libs = kernel_files(packed.source.parent)
    if not libs:
        return ""
    names = []
    for lib in libs:
        arch = TARGETS[lib.name.removeprefix("forest-kernel-").removesuffix(".so")][1]
        names.append(
            lib.name + ("" if arch == _arch() else f" (for {arch}, this CPU is {_arch()})")
        )
    return (
        f"{packed.source.parent} ships {', '.join(names)}, not loaded from a model directory "
        "(a model is data, never code; 'dyntarget install-kernel FILE' installs one into "
        "this user's cache, docs/reliability.md)"
    )


def compile_forest(
    estimator,
    *,
    directory: str | os.PathLike[str] | None = None,
    portable: bool = False,
    isa: str | None = None,
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
    isa : str, optional
        Force a code path (a key of :data:`ISA_FLAGS`; default :func:`forced_isa`).

    Returns
    -------
    callable
        ``(n, features) float32 -> (n,) float32`` plume probability, bit-identical to
        ``estimator.predict_proba(x)[:, 1].astype(numpy.float32)``; single-threaded and
        free of the GIL (the pixel classifiers' chunk pool runs chunks in parallel). Its
        attribute ``isa`` names the kernel's code path (:data:`ISAS`) and ``vectorised``
        says whether it is one of :data:`FAST_ISAS` (AVX2 or AVX-512).

    Examples
    --------
    >>> from sklearn.ensemble import RandomForestClassifier
    >>> x = np.random.default_rng(0).random((200, 4), dtype=np.float32)
    >>> est = RandomForestClassifier(n_estimators=3, random_state=0).fit(x, x[:, 0] > 0.5)
    >>> predict = compile_forest(est, isa="portable")  # plain C: every CPU runs it
    >>> bool((predict(x) == est.predict_proba(x)[:, 1].astype(np.float32)).all())
    True
    """
    return forest_predictor(pack_forest(estimator), directory=directory, portable=portable, isa=isa)


def fast_predictor(
    packed: PackedForest, *, against: str = "scikit-learn"
) -> Callable[[np.ndarray], np.ndarray] | None:
    """The kernel's predictor where it is the faster path, else ``None``.

    A kernel installed by :func:`install_kernel` (a deliberate act: the user put it in the
    cache for this CPU class) whatever its path; else the kernel built here or found in
    this user's cache (:func:`build_library`) where it runs a path measured faster than the
    backend ``against`` (AVX2 or AVX-512 against scikit-learn; also SSE2 against ONNX
    Runtime); else ``None``, which says to use that backend. A
    library in the model directory is never loaded (:func:`shipped_kernels`). Where the
    kernel cannot be had, one line on stderr (once per process) names the CPU class and
    why. The policy of ``RandomForest``'s ``"auto"`` backend and of a forest's ONNX twin.

    Parameters
    ----------
    packed : PackedForest
        The forest.
    against : {"scikit-learn", "onnxruntime"}
        The backend a kernel built here must beat: :data:`FAST_ISAS` for scikit-learn,
        :data:`FASTER_THAN_ONNXRUNTIME` for ONNX Runtime (the ONNX twin).

    Returns
    -------
    callable or None
        As :func:`forest_predictor`'s, or ``None``.

    Raises
    ------
    InvalidParameterError
        :data:`ISA_ENV` holds a value that is not a path (:func:`forced_isa`).
    MissingExtraError
        A forced path that cannot be had here (no silent fallback).
    """
    fast = FASTER_THAN_ONNXRUNTIME if against == "onnxruntime" else FAST_ISAS
    forced = forced_isa()
    if forced == "off":
        return None
    if forced is not None:  # the user asked for this path: no silent fallback
        return forest_predictor(packed, isa=forced)
    shipped = shipped_kernels(packed)
    try:
        predictor = forest_predictor(packed)
    except (MissingExtraError, OSError) as exc:  # no compiler, an unwritable or unsafe cache
        why = f"{exc}; {shipped}" if shipped else str(exc)
        _say_once(
            f"dyntarget: the forest kernel is not used on this CPU ({cpu_class()}): {why}; "
            "a slower backend predicts"
        )
        return None
    # a kernel the user installed on purpose (install_kernel: built ahead of time for this
    # CPU class, as export-onnx --targets does for a flight computer) runs whatever its path
    installed = Path(predictor.source).name.endswith(f"-{INSTALLED}.so")  # type: ignore[attr-defined]
    runs = installed or predictor.isa in fast  # type: ignore[attr-defined]
    if shipped and not runs:
        _say_once(
            f"dyntarget: {shipped}; on this CPU ({cpu_class()}) the kernel built here "
            f"({predictor.isa} path) is not used, {against} predicts"  # type: ignore[attr-defined]
        )
    return predictor if runs else None


def forest_predictor(
    packed: PackedForest,
    *,
    directory: str | os.PathLike[str] | None = None,
    portable: bool = False,
    isa: str | None = None,
    library: Path | None = None,
) -> Callable[[np.ndarray], np.ndarray]:
    """The kernel's predictor for a packed forest (:func:`pack_forest` or :func:`load_forest`).

    Parameters
    ----------
    packed : PackedForest
        The forest.
    directory : path, optional
        Cache directory of the kernel (default :func:`cache_dir`).
    portable : bool
        Use the kernel built without ``-march=native``.
    isa : str, optional
        Force a code path (a key of :data:`ISA_FLAGS`; default :func:`forced_isa`).
    library : pathlib.Path, optional
        A kernel this user built elsewhere (e.g. a benchmark's older kernel) instead of
        the cache's: loaded under the same rules (:func:`_load`: a folder and a file of this
        user's alone, its SHA-256 recorded beside it as ``<name>.so.sha256``).

    Returns
    -------
    callable
        As :func:`compile_forest`'s, with ``source``: the library it runs.
    """
    if library is None:
        isa = isa or forced_isa()
        if isa not in (None, "off") and not cpu_runs(isa):
            raise MissingExtraError(f"the forest kernel's {isa} path does not run on this CPU")
        library = build_library(directory, portable=portable, isa=isa)
    dll = _load(library)

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

    isa = ISAS[dll.dt_forest_isa()]
    predict.isa = isa  # type: ignore[attr-defined]
    predict.vectorised = isa in FAST_ISAS  # type: ignore[attr-defined]
    predict.source = library  # type: ignore[attr-defined]
    return predict
