"""The classifier interface and registry, and pixel sampling.

A classifier maps a 4-band image ``(4, H, W)`` to a plume probability
``float32 (H, W)`` in 0..1. Every classifier is registered by name in
:data:`CLASSIFIERS` and passes the same contract test. :class:`Predictor` is what
planning needs of one: the native classifiers (:class:`Classifier`) and their ONNX
twins (:class:`dyntarget.perceive.onnx.OnnxClassifier`) both satisfy it. Model
directories are :mod:`dyntarget.perceive.modelfile`; the registry itself is
:mod:`dyntarget.perceive.names` (so that reading a model directory needs no classifier).
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from dyntarget.errors import InvalidParameterError, InvalidSceneError, ModelFileError
from dyntarget.perceive.modelfile import read_metadata, write_model_dir
from dyntarget.perceive.names import CLASSIFIERS
from dyntarget.scene import Scene, check_image

TRAIN_THREADS = 1
"""PyTorch intra-op threads while a U-Net trains, whatever the machine or scheduler.

Float reductions in convolutions (and their gradients) are summed in an order
that depends on the thread count, so a fixed count makes training give the same
bytes in-process, on Dask threads (``local``) and in worker processes
(``processes``). Recorded in every resume part (``evaluate.distributed``)."""

DEFAULT_MAX_PIXELS_PER_CLASS = 50_000
"""Training pixels drawn per class (plume / not plume) over all training scenes."""


@runtime_checkable
class Predictor(Protocol):
    """What planning needs of a classifier: the native ones and their ONNX twins.

    :func:`dyntarget.pipeline.plan_scene`, the pass loop and the evaluations take a
    ``Predictor``; training and saving need the full :class:`Classifier`.

    Examples
    --------
    >>> from dyntarget.perceive import make_classifier
    >>> isinstance(make_classifier("band-threshold"), Predictor)
    True
    """

    @property
    def name(self) -> str:
        """The classifier's registered name."""
        ...

    @property
    def kind(self) -> str:
        """``"threshold"``, ``"pixel"`` or ``"unet"``."""
        ...

    def predict_proba(self, image: np.ndarray) -> np.ndarray:
        """Plume probability of each pixel.

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` reflectance (R, G, B, NIR).

        Returns
        -------
        numpy.ndarray
            ``float32 (H, W)`` in 0..1.
        """
        ...

    def predict(self, image: np.ndarray, threshold: float = 0.5) -> np.ndarray:
        """Plume mask ``predict_proba(image) >= threshold``.

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` reflectance.
        threshold : float
            Probability at or above which a pixel is plume, 0..1.

        Returns
        -------
        numpy.ndarray
            Boolean ``(H, W)`` mask.
        """
        ...

    def work_units(self, shape: tuple[int, int]) -> float:
        """Work of classifying an image of ``shape``, in the classifier's own units.

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        float
            Pixels (pixel classifiers) or pixels run over in tiles (U-Nets): the deadline
            logic times a crop once and scales by this.
        """
        ...


class Classifier(ABC):
    """Base class: ``fit(scenes)``, ``predict_proba(image)``, ``predict(image)``, ``save``/``load``.

    Parameters
    ----------
    seed : int
        Seed of everything random in training (pixel samples, initial weights).
    """

    name: ClassVar[str]
    summary: ClassVar[str]
    kind: ClassVar[str]
    """Family: ``"threshold"``, ``"pixel"`` (scikit-learn) or ``"unet"`` (PyTorch)."""

    def __init__(self, *, seed: int = 0) -> None:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise InvalidParameterError(f"seed: expected an integer, got {seed!r}")
        self.seed = int(seed)
        self.fitted = False
        self.training: dict[str, Any] = {}

    # -- configuration -------------------------------------------------------------
    def get_config(self) -> dict[str, Any]:
        """Constructor arguments as JSON-able values (stored in the model's metadata).

        Returns
        -------
        dict
            Argument name to value; ``cls(**get_config())`` builds an unfitted twin.
        """
        return {"seed": self.seed}

    # -- learning ------------------------------------------------------------------
    def fit(self, scenes: Sequence[Scene]) -> Classifier:
        """Train on labelled scenes (already on the grid the classifier will see).

        Parameters
        ----------
        scenes : sequence of dyntarget.scene.Scene
            Labelled scenes holding both plume and background pixels.

        Returns
        -------
        Classifier
            This classifier, fitted.

        Raises
        ------
        dyntarget.errors.InvalidSceneError
            When a scene has no label, or the scenes hold no plume or no background pixel.
        """
        scenes = list(scenes)
        if not scenes:
            raise InvalidParameterError("scenes: expected at least one training scene, got none")
        for s in scenes:
            if s.label is None:
                raise InvalidSceneError(
                    f"scene {s.id!r} has no label; training needs labelled scenes"
                )
        if not any((s.label & s.valid_mask).any() for s in scenes):
            raise InvalidSceneError(
                "training scenes hold no plume pixel; cannot learn a plume class"
            )
        if all((s.label | ~s.valid_mask).all() for s in scenes):
            raise InvalidSceneError(
                "training scenes hold no background pixel; cannot learn two classes"
            )
        self._fit(scenes)
        self.fitted = True
        self.training = {"scenes": [s.id for s in scenes]}
        return self

    @abstractmethod
    def _fit(self, scenes: list[Scene]) -> None: ...

    def predict_proba(self, image: np.ndarray) -> np.ndarray:
        """Plume probability ``float32 (H, W)`` in 0..1 for a ``(4, H, W)`` image.

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` reflectance (R, G, B, NIR).

        Returns
        -------
        numpy.ndarray
            ``float32 (H, W)`` plume probability.
        """
        if not self.fitted:
            raise InvalidParameterError(f"{self.name}: call fit() or load() before predicting")
        image = check_image(image)
        proba = np.asarray(self._predict_proba(image), dtype=np.float32)
        return np.clip(proba, 0.0, 1.0, out=proba)

    @abstractmethod
    def _predict_proba(self, image: np.ndarray) -> np.ndarray: ...

    def work_units(self, shape: tuple[int, int]) -> float:
        """How much work predicting an image of ``shape`` is, in units whose cost is
        constant (here pixels); used to extrapolate a timed probe to a whole image.

        Parameters
        ----------
        shape : tuple of int
            The image's ``(H, W)``.

        Returns
        -------
        float
            The work, in the classifier's units.
        """
        return float(shape[0] * shape[1])

    def predict(self, image: np.ndarray, threshold: float = 0.5) -> np.ndarray:
        """Plume mask: ``predict_proba(image) >= threshold``.

        Parameters
        ----------
        image : numpy.ndarray
            ``(4, H, W)`` reflectance (R, G, B, NIR).
        threshold : float
            Probability at or above which a pixel is plume, 0..1.

        Returns
        -------
        numpy.ndarray
            Boolean ``(H, W)`` mask.
        """
        if not 0.0 <= float(threshold) <= 1.0:
            raise InvalidParameterError(
                f"threshold: expected a probability in 0..1, got {threshold!r}"
            )
        return self.predict_proba(image) >= threshold

    # -- persistence ---------------------------------------------------------------
    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the model directory ``path`` (replacing it atomically).

        Parameters
        ----------
        path : str or os.PathLike
            The model directory: free, an empty folder, or a model directory of ours.

        Returns
        -------
        pathlib.Path
            ``path``.
        """
        return write_model_dir(self, path)

    @abstractmethod
    def _save_weights(self, directory: Path) -> None: ...

    @abstractmethod
    def _load_weights(self, directory: Path) -> None: ...

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Classifier:
        """Load a model directory written by :meth:`save` (checking its metadata).

        Parameters
        ----------
        path : str or os.PathLike
            The model directory.

        Returns
        -------
        Classifier
            The fitted classifier.

        Raises
        ------
        dyntarget.errors.ModelFileError
            When the directory holds another classifier or its metadata does not fit this one.
        """
        meta = read_metadata(path)
        if meta["classifier"] != cls.name:
            raise ModelFileError(f"{path}: holds a {meta['classifier']!r} model, not {cls.name!r}")
        try:
            model = cls(**meta["config"])
        except (TypeError, InvalidParameterError) as exc:
            raise ModelFileError(
                f"{path}: metadata config does not fit {cls.name!r} ({exc})"
            ) from None
        model._load_weights(Path(path))
        model.fitted = True
        model.training = meta.get("training", {})
        return model


def make_classifier(name: str, **kwargs: Any) -> Classifier:
    """Construct a registered classifier by name.

    Parameters
    ----------
    name : str
        A registered classifier (``dyntarget classifiers`` lists them).
    **kwargs
        Constructor arguments of that classifier.

    Returns
    -------
    Classifier
        The unfitted classifier.
    """
    return CLASSIFIERS.get(name)(**kwargs)


def pixels(image: np.ndarray) -> np.ndarray:
    """``(4, H, W)`` image -> ``(H*W, 4)`` feature matrix (a view where possible).

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` image.

    Returns
    -------
    numpy.ndarray
        ``(H*W, 4)`` band values per pixel, in row-major pixel order.
    """
    return image.reshape(image.shape[0], -1).T


def sample_pixels(
    scenes: Sequence[Scene], *, max_per_class: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Class-balanced pixel sample over all scenes: ``(X (n, 4) float32, y (n,) int)``.

    From each class (plume, background) ``min(max_per_class, n_plume, n_background)``
    pixels are drawn without replacement, uniformly over all training pixels of
    that class, so both classes are equally represented. Nodata pixels are never drawn.

    Parameters
    ----------
    scenes : sequence of dyntarget.scene.Scene
        Labelled scenes.
    max_per_class : int
        Most pixels drawn per class.
    rng : numpy.random.Generator
        Source of the draws.

    Returns
    -------
    X : numpy.ndarray
        ``(n, 4)`` float32 band values, plume and background pixels in equal numbers.
    y : numpy.ndarray
        ``(n,)`` int64 class, 1 = plume.
    """
    feats = np.concatenate([pixels(s.image) for s in scenes])
    labels = np.concatenate([s.truth.ravel() for s in scenes])
    valid = np.concatenate([s.valid_mask.ravel() for s in scenes])
    pos = np.flatnonzero(labels & valid)
    neg = np.flatnonzero(~labels & valid)
    n = min(max_per_class, len(pos), len(neg))
    idx = np.concatenate([rng.choice(pos, n, replace=False), rng.choice(neg, n, replace=False)])
    idx.sort()
    return feats[idx].astype(np.float32), labels[idx].astype(np.int64)
