"""k-fold cross-validation of the classifiers (the paper's Table 1).

Scenes are split into folds **by scene**, never by pixel: the scene order is
shuffled with the seed and fold ``k`` tests on every ``folds``-th scene from
position ``k``. For each fold every classifier is trained on the WFOV
versions of the training scenes and scored on the held-out WFOV scenes
against their WFOV labels, with and without denoising. Confusion counts are
summed over a fold's test pixels; the table shows the mean over folds.

Trained models can be kept in ``models_dir/fold-<k>/<classifier>/`` and are
reused when their metadata shows the same training scenes and configuration,
so an interrupted evaluation resumes, and the end-to-end evaluation can share
the training run.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget import defaults
from dyntarget.denoise import DEFAULT_ITERATIONS, DEFAULT_MIN_AREA_FRACTION, denoise
from dyntarget.errors import InvalidParameterError, ModelFileError
from dyntarget.evaluate.distributed import check_scheduler, check_unique, run_tasks, task_key
from dyntarget.evaluate.metrics import Confusion
from dyntarget.evaluate.options import RunOptions, TrainingConfig
from dyntarget.evaluate.tables import display
from dyntarget.perceive import (
    CLASSIFIERS,
    Classifier,
    load_classifier,
    make_classifier,
    read_metadata,
)
from dyntarget.scene import Scene

DEFAULT_FACTOR = defaults.FACTOR
"""High-res -> WFOV downsampling factor used by the evaluations (512 px scenes -> 128 px WFOV)."""

TABLE1_COLUMNS = ["Classifier", "Accuracy", "Precision", "Recall", "IoU"]


@dataclass(frozen=True)
class CVConfig(TrainingConfig):
    """Settings of the classification cross-validation.

    Parameters
    ----------
    folds : int
        Cross-validation folds.
    seed : int
        Seed of the fold split and the training.
    factor : int
        High-res -> WFOV downsampling factor.
    epochs : int
        Training epochs of the U-Nets.
    classifiers : tuple of str
        Classifiers to evaluate (default: all registered).
    denoise_iterations : int
        Closing iterations of the denoised rows.
    min_area_fraction : float
        Smallest kept polygon of the denoised rows, as a fraction of the image area.
    """

    classifiers: tuple[str, ...] = field(default_factory=lambda: tuple(CLASSIFIERS.available()))
    denoise_iterations: int = DEFAULT_ITERATIONS
    min_area_fraction: float = DEFAULT_MIN_AREA_FRACTION

    def __post_init__(self) -> None:
        super().__post_init__()  # folds, seed, factor, epochs
        if not self.classifiers:
            raise InvalidParameterError("classifiers: expected at least one classifier name")
        check_unique("classifiers", self.classifiers)
        for name in self.classifiers:
            CLASSIFIERS.get(name)  # raises UnknownNameError listing the valid names


def kfold_indices(n: int, folds: int, seed: int) -> list[np.ndarray]:
    """Test indices of each fold: a seeded permutation dealt round-robin into ``folds`` parts.

    Parameters
    ----------
    n : int
        Number of scenes.
    folds : int
        Number of folds (at most ``n``).
    seed : int
        Seed of the permutation.

    Returns
    -------
    list of numpy.ndarray
        The test indices of each fold.

    Examples
    --------
    >>> folds = kfold_indices(5, 2, seed=0)
    >>> [len(f) for f in folds], sorted(i for f in folds for i in f.tolist())
    ([3, 2], [0, 1, 2, 3, 4])
    """
    if folds > n:
        raise InvalidParameterError(f"folds: {folds} folds need at least {folds} scenes, got {n}")
    order = np.random.default_rng(seed).permutation(n)
    return [order[k::folds] for k in range(folds)]


def classifier_kwargs(name: str, *, seed: int, epochs: int) -> dict[str, Any]:
    """Constructor arguments of classifier ``name``: the seed, and the epochs for a U-Net.

    Parameters
    ----------
    name : str
        A registered classifier.
    seed : int
        Its seed.
    epochs : int
        Training epochs (U-Nets only).

    Returns
    -------
    dict
        Keyword arguments for :func:`~dyntarget.perceive.make_classifier`.
    """
    kwargs: dict[str, Any] = {"seed": seed}
    if CLASSIFIERS.get(name).kind == "unet":
        kwargs["epochs"] = epochs
    return kwargs


def train_or_load(
    name: str, train: Sequence[Scene], *, seed: int, epochs: int, model_dir: Path | None
) -> tuple[Classifier, float, bool]:
    """Train ``name`` on ``train`` (or reuse a matching saved model). Returns (model, seconds, reused).

    A saved model is reused when its classifier, configuration and training
    scene ids match; otherwise the model is trained and, with ``model_dir``, saved there.

    Parameters
    ----------
    name : str
        A registered classifier.
    train : sequence of dyntarget.scene.Scene
        Labelled training scenes.
    seed : int
        Its seed.
    epochs : int
        Training epochs (U-Nets only).
    model_dir : pathlib.Path or None
        Where the model is saved (``None``: not saved).

    Returns
    -------
    model : dyntarget.perceive.Classifier
        The fitted classifier.
    seconds : float
        Training time (0 when reused).
    reused : bool
        Whether the saved model was loaded.
    """
    kwargs = classifier_kwargs(name, seed=seed, epochs=epochs)
    ids = [s.id for s in train]
    if model_dir is not None and model_dir.exists():
        try:
            meta = read_metadata(model_dir)
            wanted = make_classifier(name, **kwargs).get_config()
            if (
                meta["classifier"] == name
                and meta["config"] == wanted
                and meta["training"].get("scenes") == ids
            ):
                return load_classifier(model_dir), 0.0, True
        except ModelFileError:
            pass  # unusable: retrain and overwrite
    t0 = time.perf_counter()
    model = make_classifier(name, **kwargs).fit(train)
    seconds = time.perf_counter() - t0
    if model_dir is not None:
        model.save(model_dir)
    return model, seconds, False


def data_signature(scenes: Sequence[Scene]) -> str:
    """A key over the scenes' ids, images, labels and valid masks (by content).

    Parameters
    ----------
    scenes : sequence of dyntarget.scene.Scene
        The scenes.

    Returns
    -------
    str
        A :func:`~dyntarget.evaluate.distributed.task_key`.
    """
    parts: list[Any] = [[s.id for s in scenes]]
    for s in scenes:
        parts += [s.image, s.label if s.label is not None else "unlabelled"]
        parts += [s.valid if s.valid is not None else "all-valid"]
    return task_key(*parts)


def _cv_task(
    task: tuple[int, str],
    *,
    wfov: Sequence[Scene],
    folds: list[list[int]],
    config: CVConfig,
    models_dir: str | None,
) -> dict[str, Any]:
    """One fold x classifier: train (or reuse), predict the held-out scenes, count, denoise, count."""
    k, name = task
    test_set = set(folds[k])
    train = [s for i, s in enumerate(wfov) if i not in test_set]
    model_dir = Path(models_dir) / f"fold-{k}" / name if models_dir is not None else None
    model, _, _ = train_or_load(
        name, train, seed=config.seed, epochs=config.epochs, model_dir=model_dir
    )
    raw, den, seconds = Confusion(), Confusion(), []
    for i in folds[k]:
        s = wfov[i]
        t0 = time.perf_counter()
        pred = model.predict(s.image)
        seconds.append(time.perf_counter() - t0)
        pred &= s.valid_mask
        raw = raw + Confusion.from_masks(pred, s.truth, s.valid)
        cleaned = denoise(
            pred, iterations=config.denoise_iterations, min_area_fraction=config.min_area_fraction
        ).mask
        den = den + Confusion.from_masks(cleaned, s.truth, s.valid)
    return {"raw": asdict(raw), "denoised": asdict(den), "predict_seconds": seconds}


def cross_validate(
    scenes: Sequence[Scene],
    config: CVConfig = CVConfig(),
    *,
    options: RunOptions = RunOptions(),
) -> dict[str, Any]:
    """Run the cross-validation; returns rows for Table 1 plus per-fold details.

    Each fold x classifier is one task of :func:`~dyntarget.evaluate.distributed.run_tasks`
    (``scheduler``: here, or on Dask; ``parts``: a folder where finished tasks are
    kept, so that a rerun resumes).

    Parameters
    ----------
    scenes : sequence of dyntarget.scene.Scene
        Labelled high-resolution scenes.
    config : CVConfig
        Settings.
    options : RunOptions
        Models kept, progress bar, scheduler and finished parts
        (:class:`~dyntarget.evaluate.options.RunOptions`).

    Returns
    -------
    dict
        ``rows`` (Table 1), ``config``, ``folds`` (scene ids per fold),
        ``wfov_shape`` and ``timing`` (median prediction seconds per scene).
    """
    models_dir, progress, scheduler, parts = (
        options.models_dir,
        options.progress,
        options.scheduler,
        options.parts,
    )
    check_scheduler(scheduler)  # before any training
    scenes = list(scenes)
    wfov = [s.to_wfov(config.factor) for s in scenes]
    folds = [sorted(f.tolist()) for f in kfold_indices(len(wfov), config.folds, config.seed)]
    run = task_key("classification", asdict(config), data_signature(wfov))
    tasks = [(k, name) for k in range(config.folds) for name in config.classifiers]
    results = run_tasks(
        _cv_task,
        tasks,
        key=lambda t: task_key(run, *t),
        parts=Path(parts) if parts is not None else None,
        scheduler=scheduler,
        shared={
            "wfov": wfov,
            "folds": folds,
            "config": config,
            "models_dir": str(models_dir) if models_dir is not None else None,
        },
        progress=progress,
        desc="cross-validation",
    )
    counts: dict[tuple[str, bool], list[Confusion]] = {}
    timing: dict[str, list[float]] = {n: [] for n in config.classifiers}
    for (_, name), result in zip(tasks, results, strict=True):
        counts.setdefault((name, False), []).append(Confusion(**result["raw"]))
        counts.setdefault((name, True), []).append(Confusion(**result["denoised"]))
        timing[name] += result["predict_seconds"]
    rows = []
    for name in config.classifiers:
        for denoised in (False, True):
            per_fold = [c.metrics() for c in counts[(name, denoised)]]
            mean = {m: float(np.mean([f[m] for f in per_fold])) for m in per_fold[0]}
            rows.append(
                {
                    "Classifier": "+ Denoising" if denoised else display(name),
                    "classifier": name,
                    "denoised": denoised,
                    "Accuracy": mean["accuracy"],
                    "Precision": mean["precision"],
                    "Recall": mean["recall"],
                    "IoU": mean["iou"],
                    "iou_background": mean["iou_background"],
                    "precision_background": mean["precision_background"],
                    "recall_background": mean["recall_background"],
                    "fold_iou": [f["iou"] for f in per_fold],
                }
            )
    return {
        "rows": rows,
        "config": asdict(config),
        "folds": [[scenes[i].id for i in f] for f in folds],
        "wfov_shape": list(wfov[0].shape),
        "timing": {
            "predict_seconds_per_scene": {n: float(np.median(t)) for n, t in timing.items()}
        },
    }
