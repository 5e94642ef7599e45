"""The five scikit-learn single-pixel classifiers on the four band values.

Training draws a class-balanced pixel sample (at most
:data:`~dyntarget.perceive.base.DEFAULT_MAX_PIXELS_PER_CLASS` per class over all
training scenes, uniformly); prediction is vectorised ``predict_proba`` over
fixed chunks of :data:`PREDICT_CHUNK` pixels, run in parallel on a thread pool
(identical to one call over the whole image; tested). Models are saved with skops and loaded with an
explicit list of trusted types, never with pickle.

Hyperparameters (chosen for speed on 2 cores and stable results, not tuned
per data set):

=====================  ===============================================================
naive-bayes            GaussianNB()
logistic-regression    StandardScaler -> LogisticRegression(C=1.0, max_iter=1000)
decision-tree          DecisionTreeClassifier(max_depth=12, min_samples_leaf=20)
random-forest          RandomForestClassifier(n_estimators=50, max_depth=14, min_samples_leaf=5)
mlp                    StandardScaler -> MLPClassifier((32, 32), early_stopping, max_iter=300)
=====================  ===============================================================
"""

from __future__ import annotations

import contextlib
import io
import re
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dyntarget.errors import InvalidParameterError, MissingExtraError, ModelFileError
from dyntarget.perceive.base import (
    CLASSIFIERS,
    DEFAULT_MAX_PIXELS_PER_CLASS,
    Classifier,
    pixels,
    sample_pixels,
)
from dyntarget.perceive.resources import available_cores
from dyntarget.perceive.validate import check_estimator

if TYPE_CHECKING:
    from sklearn.base import BaseEstimator

    from dyntarget.perceive.compiled import PackedForest

MODEL_FILE = "model.skops"
PREDICT_CHUNK = 1 << 18
"""Pixels per ``predict_proba`` call. Chunks are fixed, so the result does not depend
on the number of threads; scikit-learn's tree and numpy code release the GIL, so
chunks run in parallel on a thread pool (one thread per available core)."""


TRUSTED_TYPES = [
    "numpy.dtype",
    "numpy.ndarray",
    "sklearn.ensemble._forest.RandomForestClassifier",
    "sklearn.linear_model._logistic.LogisticRegression",
    "sklearn.naive_bayes.GaussianNB",
    "sklearn.neural_network._multilayer_perceptron.MLPClassifier",
    "sklearn.neural_network._stochastic_optimizers.AdamOptimizer",
    "sklearn.pipeline.Pipeline",
    "sklearn.preprocessing._data.StandardScaler",
    "sklearn.tree._classes.DecisionTreeClassifier",
    "sklearn.tree._tree.Tree",
]
"""The only non-builtin types a dyntarget scikit-learn model file may contain."""


def _canonical_skops(archive: bytes) -> bytes:
    """Make a skops archive byte-identical across runs.

    skops names each array file after the Python ``id()`` of the array, records
    object identities (``__id__``) as ``id()`` values, and dates zip entries with
    the current time; all change between runs. Array files are renamed ``0.npy,
    1.npy, ...`` and identities ``0, 1, ...`` in order of appearance (a bijection,
    so shared references stay shared) and every entry is dated 1980-01-01.
    """
    src = zipfile.ZipFile(io.BytesIO(archive))
    schema = src.read("schema.json").decode("utf-8")
    names: dict[str, str] = {}
    for match in re.finditer(r'"([0-9]+\.npy)"', schema):
        names.setdefault(match.group(1), f"{len(names)}.npy")
    schema = re.sub(r'"([0-9]+\.npy)"', lambda m: f'"{names[m.group(1)]}"', schema)
    ids: dict[str, str] = {}  # object identities (shared references): renumbered consistently
    schema = re.sub(
        r'"__id__": ([0-9]+)',
        lambda m: f'"__id__": {ids.setdefault(m.group(1), str(len(ids)))}',
        schema,
    )
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as dst:
        for info in sorted(
            src.infolist(),
            key=lambda i: (i.filename != "schema.json", names.get(i.filename, i.filename)),
        ):
            data = (
                schema.encode("utf-8")
                if info.filename == "schema.json"
                else src.read(info.filename)
            )
            fixed = zipfile.ZipInfo(
                names.get(info.filename, info.filename), date_time=(1980, 1, 1, 0, 0, 0)
            )
            fixed.compress_type = info.compress_type
            fixed.external_attr = info.external_attr
            dst.writestr(fixed, data)
    return out.getvalue()


def predict_in_chunks(image: np.ndarray, proba) -> np.ndarray:
    """Run a per-pixel predictor over an image in fixed chunks on a pool of threads.

    The chunks are :data:`PREDICT_CHUNK` pixels, one thread per available core, with
    BLAS and OpenMP inside each chunk held to one thread where threadpoolctl is
    installed (2 threads on 2 cores, not 2 x 2); each pixel's result depends on its own
    values only, so the output equals one call over all pixels (tested).

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` float32 image.
    proba : callable
        ``(n, 4) float32 -> (n,)`` plume probability; called from several threads.

    Returns
    -------
    numpy.ndarray
        ``float32 (H, W)``.

    Examples
    --------
    >>> image = np.zeros((4, 3, 2), np.float32)
    >>> image[3] = [[0, 1], [2, 3], [4, 5]]
    >>> predict_in_chunks(image, lambda px: px[:, 3] / 10)
    array([[0. , 0.1],
           [0.2, 0.3],
           [0.4, 0.5]], dtype=float32)
    """
    h, w = image.shape[1:]
    x = np.ascontiguousarray(pixels(image))
    out = np.empty(h * w, np.float32)
    starts = range(0, h * w, PREDICT_CHUNK)

    def chunk(start: int) -> None:
        part = x[start : start + PREDICT_CHUNK]
        out[start : start + len(part)] = proba(part)

    if len(starts) == 1:
        chunk(0)
    else:
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:  # the lean install: no BLAS-threaded predictor to hold back
            limits = contextlib.nullcontext()
        else:
            limits = threadpool_limits(limits=1)
        # the pool is the parallelism: BLAS / OpenMP inside each chunk stay on one
        # thread, so 2 cores run 2 threads, not 2 x 2
        with limits, ThreadPoolExecutor(max_workers=available_cores()) as pool:
            list(pool.map(chunk, starts))
    return out.reshape(h, w)


class PixelClassifier(Classifier):
    """A scikit-learn estimator over the four band values of each pixel.

    scikit-learn and skops are imported only when an estimator is built, trained,
    saved or loaded natively.

    Parameters
    ----------
    seed : int
        Seed of the training pixel sample (and of the estimator, where it draws).
    max_pixels_per_class : int
        Most training pixels drawn per class (at least 10).
    """

    kind = "pixel"

    def __init__(
        self, *, seed: int = 0, max_pixels_per_class: int = DEFAULT_MAX_PIXELS_PER_CLASS
    ) -> None:
        super().__init__(seed=seed)
        if (
            isinstance(max_pixels_per_class, bool)
            or not isinstance(max_pixels_per_class, int)
            or (max_pixels_per_class < 10)
        ):
            raise InvalidParameterError(
                f"max_pixels_per_class: expected an integer >= 10, got {max_pixels_per_class!r}"
            )
        self.max_pixels_per_class = max_pixels_per_class
        self.estimator: BaseEstimator | None = None

    def get_config(self) -> dict[str, Any]:
        """Constructor arguments as JSON-able values (stored in the model's metadata).

        Returns
        -------
        dict
            ``seed`` and ``max_pixels_per_class``.
        """
        return {"seed": self.seed, "max_pixels_per_class": self.max_pixels_per_class}

    def make_estimator(self) -> BaseEstimator:
        """A fresh, unfitted scikit-learn estimator (each subclass builds its own).

        Returns
        -------
        sklearn.base.BaseEstimator
            An estimator with ``fit(X, y)`` and ``predict_proba(X)``.
        """
        raise NotImplementedError

    def _fit(self, scenes) -> None:
        rng = np.random.default_rng(self.seed)
        x, y = sample_pixels(scenes, max_per_class=self.max_pixels_per_class, rng=rng)
        est = self.make_estimator()
        est.fit(x, y)
        self.estimator = est

    def _predict_proba(self, image: np.ndarray) -> np.ndarray:
        return predict_in_chunks(image, self.chunk_predictor())

    def chunk_predictor(self):
        """``(n, 4) float32 -> (n,)`` plume probability of a chunk of pixels.

        Returns
        -------
        callable
            The predictor of the fitted estimator.
        """
        return lambda part: self.estimator.predict_proba(part)[:, 1]

    def _save_weights(self, directory: Path) -> None:
        import skops.io as sio

        (directory / MODEL_FILE).write_bytes(_canonical_skops(sio.dumps(self.estimator)))

    def _load_weights(self, directory: Path) -> None:
        self.estimator = self._read_estimator(directory)

    def _read_estimator(self, directory: Path) -> BaseEstimator:
        """The checked estimator of ``directory/model.skops`` (imports scikit-learn and skops)."""
        import skops.io as sio

        path = directory / MODEL_FILE
        if not path.is_file():
            raise ModelFileError(f"{directory}: no {MODEL_FILE}")
        try:
            untrusted = sio.get_untrusted_types(file=path)
        except Exception as exc:  # skops raises several types on a corrupt archive
            raise ModelFileError(f"{path}: not a readable skops file ({exc})") from None
        foreign = sorted(set(untrusted) - set(TRUSTED_TYPES))
        if foreign:
            raise ModelFileError(f"{path}: refuses to load untrusted types: {', '.join(foreign)}")
        try:
            est = sio.load(path, trusted=untrusted)
        except Exception as exc:
            raise ModelFileError(f"{path}: could not load ({exc})") from None
        expected = type(self.make_estimator())
        if type(est) is not expected:
            raise ModelFileError(
                f"{path}: holds a {type(est).__name__}, expected {expected.__name__}"
            )
        check_estimator(est, path)
        return est


@CLASSIFIERS.register("naive-bayes")
class NaiveBayes(PixelClassifier):
    """Gaussian naive Bayes on the four band values (bands assumed independent).

    Parameters
    ----------
    seed : int
        Seed of the training pixel sample.
    max_pixels_per_class : int
        Most training pixels drawn per class (at least 10).
    """

    name = "naive-bayes"
    summary = "Gaussian naive Bayes on the 4 band values (bands assumed independent)"

    def make_estimator(self) -> BaseEstimator:
        """A fresh ``GaussianNB``.

        Returns
        -------
        sklearn.naive_bayes.GaussianNB
            The unfitted estimator.
        """
        from sklearn.naive_bayes import GaussianNB

        return GaussianNB()


@CLASSIFIERS.register("logistic-regression")
class LogisticRegressionClassifier(PixelClassifier):
    """A logistic regression on the standardised four band values.

    Parameters
    ----------
    seed : int
        Seed of the training pixel sample.
    max_pixels_per_class : int
        Most training pixels drawn per class (at least 10).
    """

    name = "logistic-regression"
    summary = "standardised logistic regression on the 4 band values"

    def make_estimator(self) -> BaseEstimator:
        """A fresh pipeline: ``StandardScaler`` then ``LogisticRegression(C=1.0)``.

        Returns
        -------
        sklearn.pipeline.Pipeline
            The unfitted pipeline.
        """
        from sklearn.linear_model import LogisticRegression
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        return make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=1000))


@CLASSIFIERS.register("decision-tree")
class DecisionTree(PixelClassifier):
    """A decision tree (depth at most 12, 20 pixels per leaf) on the four band values.

    Parameters
    ----------
    seed : int
        Seed of the training pixel sample and of the tree.
    max_pixels_per_class : int
        Most training pixels drawn per class (at least 10).
    """

    name = "decision-tree"
    summary = "decision tree (depth <= 12) on the 4 band values"

    def make_estimator(self) -> BaseEstimator:
        """A fresh ``DecisionTreeClassifier(max_depth=12, min_samples_leaf=20)``.

        Returns
        -------
        sklearn.tree.DecisionTreeClassifier
            Seeded with ``seed``.
        """
        from sklearn.tree import DecisionTreeClassifier

        return DecisionTreeClassifier(max_depth=12, min_samples_leaf=20, random_state=self.seed)


@CLASSIFIERS.register("random-forest")
class RandomForest(PixelClassifier):
    """A random forest (50 trees, depth at most 14) on the four band values.

    Parameters
    ----------
    seed : int
        Seed of the training pixel sample and of the forest.
    max_pixels_per_class : int
        Most training pixels drawn per class (at least 10).
    """

    name = "random-forest"
    summary = "random forest (50 trees, depth <= 14) on the 4 band values"

    backend: str = "auto"
    """``"auto"`` (default), ``"sklearn"`` or ``"compiled"`` (see :meth:`set_backend`)."""

    _estimator: BaseEstimator | None = None
    _packed: PackedForest | None = None
    _lazy_dir: Path | None = None

    @property
    def estimator(self) -> BaseEstimator | None:
        """The fitted ``RandomForestClassifier``; read from ``model.skops`` on first use
        when the model was loaded from its packed forest (which predicts without it).

        Returns
        -------
        sklearn.ensemble.RandomForestClassifier or None
            ``None`` before fitting.
        """
        if self._estimator is None and self._lazy_dir is not None:
            self._estimator = self._read_estimator(self._lazy_dir)
            self._lazy_dir = None
        return self._estimator

    @estimator.setter
    def estimator(self, value: BaseEstimator | None) -> None:
        self._estimator, self._packed, self._lazy_dir = value, None, None

    def packed(self) -> PackedForest:
        """The forest as the kernel's arrays (:func:`~dyntarget.perceive.compiled.pack_forest`).

        Returns
        -------
        dyntarget.perceive.compiled.PackedForest
            Read from ``forest.npz`` at load, else packed from the estimator (once).
        """
        if self._packed is None:
            from dyntarget.perceive.compiled import pack_forest

            self._packed = pack_forest(self.estimator)
        return self._packed

    def _save_weights(self, directory: Path) -> None:
        """``model.skops``, and the packed forest bound to it (``forest.npz``, ``forest.json``)."""
        super()._save_weights(directory)
        try:
            _write_packed(self, directory)
        except InvalidParameterError:  # beyond the kernel: scikit-learn predicts it
            pass

    def _load_weights(self, directory: Path) -> None:
        """The packed forest where ``forest.npz`` is bound to ``model.skops`` (no scikit-learn
        is imported: the estimator is read on first use), else ``model.skops``; an older
        model directory gets its ``forest.npz`` written now where it can be."""
        from dyntarget.perceive.compiled import bound_forest, forced_isa

        forced_isa()  # a DYNTARGET_FOREST_ISA that names no path is one line, on every path
        packed, why = bound_forest(directory)
        if packed is not None and packed.features == 4:
            self._estimator, self._packed, self._lazy_dir = None, packed, directory
            return
        self.estimator = self._read_estimator(directory)
        if packed is None:  # a directory from before forest.npz, or a stale binding: bind it
            try:
                _write_packed(self, directory)
            except InvalidParameterError:  # beyond the kernel: scikit-learn predicts it
                return
            except OSError as exc:
                print(
                    f"dyntarget: {directory}: {why}, and the packed forest cannot be bound "
                    f"({exc}); scikit-learn is loaded to predict ('dyntarget train' or "
                    "'dyntarget export-onnx' writes it)",
                    file=sys.stderr,
                )
            else:
                print(
                    f"dyntarget: {directory}: {why}; bound the packed forest to model.skops "
                    "(forest.npz, forest.json): later runs predict without loading scikit-learn",
                    file=sys.stderr,
                )

    def set_backend(self, backend: str) -> RandomForest:
        """Choose what predicts: scikit-learn, dyntarget's compiled forest kernel or ONNX Runtime.

        All three give the same probabilities bit for bit (:mod:`dyntarget.perceive.compiled`,
        :mod:`dyntarget.perceive.ensemble`).

        Parameters
        ----------
        backend : {"auto", "sklearn", "compiled", "onnxruntime"}
            ``"compiled"`` runs the kernel (built once per machine with the C compiler on
            the PATH, or installed with ``dyntarget install-kernel``, in this user's cache;
            never a library in the model directory); ``"onnxruntime"`` runs the forest as
            ONNX Runtime's tree ensemble (:func:`~dyntarget.perceive.ensemble.ensemble_predictor`);
            ``"auto"`` runs the kernel where its path was measured faster than the
            fallback (:func:`~dyntarget.perceive.compiled.fast_predictor`: SSE2, AVX2 or
            AVX-512 against ONNX Runtime where onnxruntime is installed, AVX2 or AVX-512
            against scikit-learn otherwise), else ONNX Runtime where onnxruntime is
            installed (at 1024 px its classification measured about 6× faster than
            scikit-learn's, the whole ``plan`` process 3.5×: docs/performance.md), else
            scikit-learn.

        Returns
        -------
        RandomForest
            This classifier.

        Examples
        --------
        >>> from dyntarget.perceive import make_classifier
        >>> make_classifier("random-forest").set_backend("sklearn").backend
        'sklearn'
        """
        if backend not in ("auto", "sklearn", "compiled", "onnxruntime"):
            raise InvalidParameterError(
                f"backend: expected 'auto', 'sklearn', 'compiled' or 'onnxruntime', got {backend!r}"
            )
        self.backend = backend
        self._compiled = None
        return self

    def chunk_predictor(self):
        """The compiled kernel, ONNX Runtime or scikit-learn (see :meth:`set_backend`).

        Returns
        -------
        callable
            ``(n, 4) float32 -> (n,)`` plume probability.
        """
        from dyntarget.perceive.compiled import forced_isa

        forced_isa()  # validated on every backend: a bad value is never ignored silently
        if self.backend == "sklearn":
            return super().chunk_predictor()
        key = self._packed if self._estimator is None else self._estimator
        cached = getattr(self, "_compiled", None)
        if cached is None or cached[0] is not key:  # refitted: pack anew
            from dyntarget.perceive.compiled import fast_predictor, forest_predictor
            from dyntarget.perceive.ensemble import ensemble_predictor

            if self.backend == "compiled":
                predictor = forest_predictor(self.packed())
            elif self.backend == "onnxruntime":
                predictor = ensemble_predictor(self.packed())
            else:
                import importlib.util

                # the kernel must beat what would predict instead: ONNX Runtime where it is
                # installed (the SSE2 path does too), else scikit-learn (AVX2 / AVX-512 only)
                against = (
                    "onnxruntime" if importlib.util.find_spec("onnxruntime") else "scikit-learn"
                )
                try:
                    predictor = fast_predictor(self.packed(), against=against)
                except InvalidParameterError:  # beyond the kernel, e.g. too deep
                    predictor = None
                if predictor is None:
                    predictor = _ensemble_or_none(self)
            self._compiled = cached = (key, predictor)
        return cached[1] or super().chunk_predictor()

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the loaded kernel (a worker process loads its own).

        Returns
        -------
        dict
            The instance's attributes but the kernel.
        """
        state = self.__dict__.copy()
        state.pop("_compiled", None)
        return state

    def make_estimator(self) -> BaseEstimator:
        """A fresh ``RandomForestClassifier`` (50 trees, depth at most 14, 5 pixels per leaf, one job).

        Returns
        -------
        sklearn.ensemble.RandomForestClassifier
            Seeded with ``seed``.
        """
        from sklearn.ensemble import RandomForestClassifier

        return RandomForestClassifier(
            n_estimators=50, max_depth=14, min_samples_leaf=5, random_state=self.seed, n_jobs=1
        )


def _ensemble_or_none(model: RandomForest):
    """ONNX Runtime's tree ensemble for ``model`` where it can run here, else ``None``.

    ``None`` (scikit-learn predicts) without onnxruntime, without both a cached graph and
    ``onnx``, or for a forest beyond the packed form.
    """
    from dyntarget.perceive.ensemble import ensemble_predictor

    try:
        return ensemble_predictor(model.packed())
    except (MissingExtraError, InvalidParameterError):
        return None


def _write_packed(model: RandomForest, directory: Path) -> None:
    """``forest.npz`` and ``forest.json`` beside ``model.skops``.

    A ``forest.npz`` already there with the same arrays (an ONNX export's, bound to its
    ``model.onnx``) is kept and only bound to ``model.skops`` in the manifest. Raises
    ``InvalidParameterError`` for a forest beyond the kernel (then nothing is written).
    """
    import hashlib

    from dyntarget.perceive.compiled import (
        FOREST_FILE,
        load_forest,
        same_forest,
        save_forest,
        write_manifest,
    )

    try:  # only a forest that loads from model.skops gets a packed form
        check_estimator(model.estimator, directory / MODEL_FILE)
    except ModelFileError:
        raise InvalidParameterError("the forest does not pass the model checks") from None
    packed = model.packed()
    path = directory / FOREST_FILE
    try:
        there = load_forest(path) if path.is_file() else None
    except ModelFileError:
        there = None
    if there is None or not same_forest(there, packed):
        skops = hashlib.sha256((directory / MODEL_FILE).read_bytes()).hexdigest()
        save_forest(packed, path, model_sha256=skops)
        write_manifest(directory, kernels=[])  # kernels of another forest.npz would be refused
    else:
        write_manifest(directory)


@CLASSIFIERS.register("mlp")
class MLP(PixelClassifier):
    """A multilayer perceptron (two hidden layers of 32) on the standardised four band values.

    Parameters
    ----------
    seed : int
        Seed of the training pixel sample and of the network's weights.
    max_pixels_per_class : int
        Most training pixels drawn per class (at least 10).
    """

    name = "mlp"
    summary = "multilayer perceptron (32, 32) on the standardised 4 band values"

    def make_estimator(self) -> BaseEstimator:
        """A fresh pipeline: ``StandardScaler`` then ``MLPClassifier((32, 32))`` with early stopping.

        Returns
        -------
        sklearn.pipeline.Pipeline
            The unfitted pipeline, the network seeded with ``seed``.
        """
        from sklearn.neural_network import MLPClassifier
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        return make_pipeline(
            StandardScaler(),
            MLPClassifier(
                hidden_layer_sizes=(32, 32),
                early_stopping=True,
                max_iter=300,
                random_state=self.seed,
            ),
        )

    def chunk_predictor(self):
        """The fitted network as three float32 matrix products, the scaler folded into the
        first layer (:func:`mlp_float32`); scikit-learn's own path otherwise.

        Returns
        -------
        callable
            ``(n, 4) float32 -> (n,)`` plume probability.
        """
        fast = mlp_float32(self.estimator)
        return fast if fast is not None else super().chunk_predictor()


def mlp_float32(pipeline):
    """A lean float32 forward pass of a ``StandardScaler -> MLPClassifier`` pipeline.

    The standardisation is folded into the first layer (``W' = W / scale``,
    ``b' = b - (mean / scale) @ W``), hidden layers run ReLU in place and the output
    is the logistic of the last layer, so a chunk of pixels costs three matrix
    products and no float64 temporaries. Equal to scikit-learn's ``predict_proba``
    to float32 rounding (1e-5, tested). Returns ``None`` for any other model shape
    (activation not ReLU, more than two classes), which then runs scikit-learn.

    Parameters
    ----------
    pipeline : sklearn.pipeline.Pipeline
        A fitted ``StandardScaler -> MLPClassifier`` pipeline.

    Returns
    -------
    callable or None
        ``(n, 4) float32 -> (n,) float32`` plume probability.

    Examples
    --------
    >>> import warnings
    >>> from sklearn.exceptions import ConvergenceWarning
    >>> from sklearn.neural_network import MLPClassifier
    >>> from sklearn.pipeline import make_pipeline
    >>> from sklearn.preprocessing import StandardScaler
    >>> x = np.random.default_rng(0).random((200, 4), dtype=np.float32)
    >>> est = make_pipeline(StandardScaler(), MLPClassifier((8,), max_iter=50, random_state=0))
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore", ConvergenceWarning)
    ...     est = est.fit(x, (x[:, 0] > 0.5).astype(int))
    >>> p = mlp_float32(est)(x)
    >>> p.dtype, bool(np.abs(p - est.predict_proba(x)[:, 1]).max() < 1e-5)
    (dtype('float32'), True)
    """
    from sklearn.neural_network import MLPClassifier
    from sklearn.preprocessing import StandardScaler

    scaler, mlp = pipeline[0], pipeline[-1]
    if (
        len(pipeline) != 2
        or not isinstance(scaler, StandardScaler)
        or not isinstance(mlp, MLPClassifier)
        or mlp.activation != "relu"
        or mlp.out_activation_ != "logistic"
        or mlp.coefs_[-1].shape[1] != 1
    ):
        return None
    scale = np.asarray(scaler.scale_ if scaler.with_std else 1.0, np.float64)
    mean = np.asarray(scaler.mean_ if scaler.with_mean else 0.0, np.float64)
    w0 = np.asarray(mlp.coefs_[0], np.float64)
    weights = [(w0 / np.broadcast_to(scale, (w0.shape[0],))[:, None]).astype(np.float32)]
    biases = [(mlp.intercepts_[0] - (mean / scale) @ w0).astype(np.float32)]
    weights += [np.asarray(w, np.float32) for w in mlp.coefs_[1:]]
    biases += [np.asarray(b, np.float32) for b in mlp.intercepts_[1:]]

    def forward(part: np.ndarray) -> np.ndarray:
        a = np.asarray(part, np.float32)
        for w, b in zip(weights[:-1], biases[:-1], strict=True):
            a = a @ w
            a += b
            np.maximum(a, 0.0, out=a)
        z = (a @ weights[-1])[:, 0]
        z += biases[-1][0]
        # logistic, as scikit-learn's expit
        np.negative(z, out=z)
        np.exp(z, out=z)
        z += 1.0
        return np.reciprocal(z, out=z)

    return forward
