"""The options every evaluation entry point shares.

* :class:`TrainingConfig`: what the evaluations that train classifiers share (folds, seed,
  downsampling factor, U-Net epochs). :class:`~dyntarget.evaluate.crossval.CVConfig`,
  :class:`~dyntarget.evaluate.endtoend.E2EConfig`,
  :class:`~dyntarget.evaluate.agility.AgilityConfig` and
  :class:`~dyntarget.evaluate.dynamic.DynamicConfig` extend it.
* :class:`RunOptions`: how an evaluation runs, not what it computes (where trained models
  are kept, the progress bar, the Dask scheduler, the folder of finished parts). It never
  enters a result or a resume key: the same config gives the same bytes however it ran.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError


def _positive_int(name: str, value: object, least: int = 1) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        what = "a positive integer" if least == 1 else f"an integer >= {least}"
        raise InvalidParameterError(f"{name}: expected {what}, got {value!r}")


@dataclass(frozen=True)
class TrainingConfig:
    """Folds, seed, factor and epochs of an evaluation that trains classifiers.

    Parameters
    ----------
    folds : int
        Cross-validation folds (at least 2).
    seed : int
        Seed of the fold split and the training.
    factor : int
        High-res -> WFOV downsampling factor.
    epochs : int
        Training epochs of the U-Nets.

    Examples
    --------
    >>> TrainingConfig(folds=3).folds, TrainingConfig().epochs == defaults.EPOCHS
    (3, True)
    >>> TrainingConfig(folds=1)
    Traceback (most recent call last):
    ...
    dyntarget.errors.InvalidParameterError: folds: expected an integer >= 2, got 1
    """

    folds: int = defaults.FOLDS
    seed: int = defaults.SEED
    factor: int = defaults.FACTOR
    epochs: int = defaults.EPOCHS

    def __post_init__(self) -> None:
        _positive_int("folds", self.folds, least=2)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise InvalidParameterError(f"seed: expected an integer, got {self.seed!r}")
        _positive_int("factor", self.factor)
        _positive_int("epochs", self.epochs)


@dataclass(frozen=True)
class RunOptions:
    """How an evaluation runs: models kept, progress, scheduler, finished parts.

    Parameters
    ----------
    models_dir : path or None
        Where trained models are saved and, on a rerun, loaded from (``None``: not kept).
    progress : bool
        Show a progress bar on stderr.
    scheduler : str or None
        ``None`` runs the tasks here; ``"local"``, ``"processes"`` or a Dask scheduler
        address runs them on Dask (:func:`dyntarget.evaluate.distributed.run_tasks`).
    parts : path or None
        Folder where each finished task is kept, so that a rerun resumes.

    Examples
    --------
    >>> RunOptions(parts="out/parts").parts
    PosixPath('out/parts')
    """

    models_dir: Path | None = None
    progress: bool = True
    scheduler: str | None = None
    parts: Path | None = None

    def __post_init__(self) -> None:
        for name in ("models_dir", "parts"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, Path):
                object.__setattr__(self, name, Path(value))
