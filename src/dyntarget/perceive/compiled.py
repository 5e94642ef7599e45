"""A random forest compiled to native code (Treelite + TL2cgen), as an opt-in backend.

scikit-learn walks each tree through an array of 64-byte node records; TL2cgen turns
every tree into nested ``if``/``else`` C code, compiled with the machine's C compiler
into a shared library. Measured on this project's machine (docs/performance.md), the
compiled forest gives the same probabilities as scikit-learn (bit-identical in the
tests); compiling a 50-tree forest (~70 000 nodes) takes about 17 s on one core (one
C file per tree at ``-O1``) and needs a C compiler at run time. Treelite's own interpreter
(GTIL) measured 8x *slower* than scikit-learn, and a numpy level-by-level traversal
costs several array passes per tree level (14 levels x 50 trees), so neither is offered.

The library is built from the (safe, skops-loaded) estimator on this machine and
cached under :func:`cache_dir` by a hash of the forest; a library is never read from
a model directory (a shared object from elsewhere would run arbitrary code).

Needs ``pip install treelite tl2cgen`` and a C compiler (``gcc``).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dyntarget.errors import InvalidParameterError, MissingExtraError


def cache_dir() -> Path:
    """Where compiled forests are kept: ``$DYNTARGET_CACHE`` or ``~/.cache/dyntarget``.

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


def _require():
    try:
        import tl2cgen
        import treelite
    except ImportError:
        raise MissingExtraError(
            "the compiled forest needs treelite and tl2cgen: pip install treelite tl2cgen"
        ) from None
    compiler = shutil.which("gcc") or shutil.which("cc")
    if compiler is None:
        raise MissingExtraError("the compiled forest needs a C compiler (gcc) on the PATH")
    return treelite, tl2cgen


def _recipe(trees: int) -> dict:
    """How the forest is compiled: one C file per tree, integer (quantized) thresholds,
    ``-O1``, one compiler per core. Measured on a 50-tree forest (docs/performance.md):
    17 s to compile on one core, against minutes with 8 files at ``-O3``, and no slower
    to predict than ``-O2``/``-O3`` (branchy code gains little from them)."""
    from dyntarget.perceive.base import available_cores

    return {
        "params": {"parallel_comp": max(1, int(trees)), "quantize": 1},
        "nthread": available_cores(),
        "options": ["-O1"],  # after tl2cgen's own -O3: the last -O wins
    }


def compile_forest(
    estimator, *, directory: str | os.PathLike[str] | None = None
) -> Callable[[np.ndarray], np.ndarray]:
    """Compile a fitted scikit-learn ``RandomForestClassifier`` (two classes) to a
    shared library and return its predictor.

    Parameters
    ----------
    estimator : sklearn.ensemble.RandomForestClassifier
        The fitted forest.
    directory : path, optional
        Cache directory (default :func:`cache_dir`); the library is named after a
        SHA-256 of the forest, so a changed forest compiles anew.

    Returns
    -------
    callable
        ``(n, 4) float32 -> (n,) float32`` plume probability, single-threaded (the
        pixel classifiers' chunk pool runs chunks in parallel).
    """
    from sklearn.ensemble import RandomForestClassifier

    if not isinstance(estimator, RandomForestClassifier) or len(estimator.classes_) != 2:
        raise InvalidParameterError(
            f"estimator: expected a fitted two-class RandomForestClassifier, got {estimator!r}"
        )
    treelite, tl2cgen = _require()
    model = treelite.sklearn.import_model(estimator)
    recipe = _recipe(len(estimator.estimators_))
    digest = hashlib.sha256(model.serialize_bytes() + repr(recipe).encode()).hexdigest()[:32]
    where = Path(directory) if directory is not None else cache_dir()
    lib = where / f"forest-{digest}.so"
    if not lib.is_file():
        where.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=where) as tmp:
            part = Path(tmp) / lib.name
            tl2cgen.export_lib(model, toolchain="gcc", libpath=str(part), **recipe)
            os.replace(part, lib)  # atomic: a reader never sees half a library
    predictor = tl2cgen.Predictor(str(lib), nthread=1)

    def predict(part: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(part, dtype=np.float32)
        out = np.asarray(predictor.predict(tl2cgen.DMatrix(x)))
        return out.reshape(len(x), -1)[:, -1].astype(np.float32)

    return predict
