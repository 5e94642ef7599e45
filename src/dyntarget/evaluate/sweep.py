"""Parameter sweeps on Dask: held-out scenes x classifiers x a parameter grid, resumable.

Work is split into tasks of one held-out scene x one classifier x one point of
the parameter grid (all planners inside a task: they share the classification).
Tasks run through :func:`dyntarget.evaluate.distributed.run_tasks` on a
``dask.distributed`` cluster (``local`` threads, ``processes``, or a scheduler
address; a remote cluster's workers must see the data and model folders at the
same paths). Each finished task's rows are written at once to
``OUT/parts/<task key>.json``; a rerun skips tasks whose part exists, so an
interrupted sweep resumes without redoing finished work, and the final table
``OUT/sweep.csv`` (rows sorted by task key) is the same whatever the completion
order. A task's key covers the scene, classifier, grid point, the data set's
scene list, folds, seed, epochs and planners. Classifiers are trained once per fold and WFOV factor in the driver
(``OUT/models`` unless ``models_dir`` is given) and reused on resume.
"""

from __future__ import annotations

import csv
import io
import itertools
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.evaluate.distributed import (
    Interrupted,
    check_scheduler,
    check_unique,
    run_tasks,
    task_key,
)
from dyntarget.evaluate.options import RunOptions
from dyntarget.io.atomic import write_text
from dyntarget.schedule import AGILITY, get_agility

GRID_PARAMETERS: dict[str, type] = {
    "step_fraction": float,
    "denoise_iterations": int,
    "min_area_fraction": float,
    "factor": int,
    "agility": str,
}
DEFAULTS: dict[str, Any] = {
    "step_fraction": 0.01,
    "denoise_iterations": 1,
    "min_area_fraction": 0.01,
    "factor": 4,
    "agility": "unlimited",
}
METRICS = (
    "pixels_observed", "ratio_plume", "intensity", "gradient", "pointings", "feasible_fraction",
)  # fmt: skip
COLUMNS = (
    "task", "fold", "scene", "classifier", "planner", *GRID_PARAMETERS, *METRICS, "runtime_s",
)  # fmt: skip


def parse_grid(items: Sequence[str]) -> dict[str, list]:
    """``["step_fraction=0.005,0.01", "factor=2,4"]`` -> ``{"step_fraction": [0.005, 0.01], ...}``.

    The whole grid is validated (:func:`check_grid`) before it is returned; a
    parameter given twice is an error.

    Parameters
    ----------
    items : sequence of str
        ``NAME=V1,V2,...`` items (``-`` in a name reads as ``_``).

    Returns
    -------
    dict of str to list
        The grid.
    """
    grid: dict[str, list] = {}
    for item in items:
        name, _, values = item.partition("=")
        name = name.strip().replace("-", "_")
        if name not in GRID_PARAMETERS or not values:
            raise InvalidParameterError(
                f"grid: {item!r} is not NAME=V1,V2,...; NAME one of: {', '.join(GRID_PARAMETERS)}"
            )
        if name in grid:
            raise InvalidParameterError(
                f"grid: {name} is given twice; give all its values at once, e.g. {name}=V1,V2"
            )
        try:
            grid[name] = [GRID_PARAMETERS[name](v.strip()) for v in values.split(",")]
        except ValueError:
            raise InvalidParameterError(
                f"grid: {item!r} holds a value that is not a {GRID_PARAMETERS[name].__name__}"
            ) from None
    check_grid(grid)
    return grid


def check_grid(grid: dict[str, list]) -> None:
    """Refuse a grid with an unknown parameter, a repeated or out-of-range value, before any work.

    Ranges: ``step_fraction`` in (0, 1], ``denoise_iterations`` an integer >= 0,
    ``min_area_fraction`` in [0, 1), ``factor`` an integer >= 1, ``agility`` a preset.

    Parameters
    ----------
    grid : dict of str to list
        Parameter name to values.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        For an unknown parameter or a repeated or out-of-range value.

    Examples
    --------
    >>> check_grid({"factor": [2, 4]})
    >>> check_grid({"step_fraction": [-1.0]})
    Traceback (most recent call last):
    ...
    dyntarget.errors.InvalidParameterError: grid: step_fraction=-1.0 is out of range; expected a number in (0, 1]
    """
    import math

    ranges = {
        "step_fraction": (lambda v: 0 < v <= 1, "a number in (0, 1]"),
        "denoise_iterations": (lambda v: v >= 0, "an integer >= 0"),
        "min_area_fraction": (lambda v: 0 <= v < 1, "a number in [0, 1)"),
        "factor": (lambda v: v >= 1, "an integer >= 1"),
    }
    if not isinstance(grid, dict):
        raise InvalidParameterError(f"grid: expected a mapping NAME -> values, got {grid!r}")
    for name, values in grid.items():
        if name not in GRID_PARAMETERS:
            raise InvalidParameterError(
                f"grid: unknown parameter {name!r}; expected one of: {', '.join(GRID_PARAMETERS)}"
            )
        kind = GRID_PARAMETERS[name]
        if not isinstance(values, list | tuple) or not values:
            raise InvalidParameterError(f"grid: {name} needs a non-empty list of values")
        if len(set(values)) != len(values):
            raise InvalidParameterError(f"grid: {name} lists a value twice: {list(values)}")
        for v in values:
            if kind is str:
                get_agility(v)  # unknown presets are refused with the valid names
                continue
            if (
                isinstance(v, bool)
                or not isinstance(v, int | float)
                or (kind is int and not isinstance(v, int))
                or not math.isfinite(v)
            ):
                raise InvalidParameterError(f"grid: {name}={v!r} is not a finite {kind.__name__}")
            ok, expected = ranges[name]
            if not ok(v):
                raise InvalidParameterError(
                    f"grid: {name}={v!r} is out of range; expected {expected}"
                )


def expand(grid: dict[str, list]) -> list[dict[str, Any]]:
    """Every point of the grid (unswept parameters at their defaults), in a fixed order.

    Parameters
    ----------
    grid : dict of str to list
        Parameter name to values.

    Returns
    -------
    list of dict
        One dict per point, every parameter of :data:`GRID_PARAMETERS` set.
    """
    names = list(GRID_PARAMETERS)
    axes = [grid.get(n, [DEFAULTS[n]]) for n in names]
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*axes)]


@dataclass(frozen=True)
class SweepTask:
    """One sweep task: one scene, one classifier, one grid point.

    Parameters
    ----------
    fold : int
        Fold whose model classifies the scene.
    scene_path : str
        The scene's GeoTIFF.
    classifier : str
        The classifier.
    model_dir : str
        The fold's saved model.
    params : dict
        The grid point (see :data:`GRID_PARAMETERS`).
    run : str
        Signature of the data and training settings (part of the key).
    """

    fold: int
    scene_path: str
    classifier: str
    model_dir: str
    params: dict[str, Any] = field(hash=False)

    run: str = ""  # signature of the data and training settings (part of the key)

    @property
    def key(self) -> str:
        """The task's key in ``parts/`` (:func:`~dyntarget.evaluate.distributed.task_key`)."""
        return task_key("sweep", self.run, Path(self.scene_path).stem, self.classifier, self.params)


def run_task(task: SweepTask, planners: Sequence[str]) -> list[dict[str, Any]]:
    """One task, on a worker: classify once, then denoise, plan and observe for every planner.

    Parameters
    ----------
    task : SweepTask
        The task.
    planners : sequence of str
        Planners.

    Returns
    -------
    list of dict
        One row per planner: the task, fold, scene, classifier, planner, grid
        point, observation metrics, pointings, feasible fraction and runtime.
    """
    import time

    from dyntarget.io import read_scene
    from dyntarget.observe import UtilityMaps, observe
    from dyntarget.perceive import load_classifier
    from dyntarget.pipeline import (
        DenoiseConfig,
        PipelineConfig,
        plan_scene,
        schedule_on_prediction,
    )
    from dyntarget.plan import PlanConfig
    from dyntarget.schedule import OrbitGeometry

    p = task.params
    scene = read_scene(task.scene_path)
    wfov = scene.to_wfov(p["factor"])
    model = load_classifier(task.model_dir)
    maps = UtilityMaps.from_scene(scene)
    config = PipelineConfig(
        plan=PlanConfig(step_fraction=p["step_fraction"]),
        denoise=DenoiseConfig(
            iterations=p["denoise_iterations"], min_area_fraction=p["min_area_fraction"]
        ),
    )
    t0 = time.perf_counter()
    mask = model.predict(wfov.image)
    classify_s = time.perf_counter() - t0
    geometry = None
    if p["agility"] != "unlimited":
        if scene.gsd is None:
            raise InvalidSceneError(
                f"{task.scene_path}: no ground sampling distance; the agility presets need one"
            )
        geometry = OrbitGeometry(wfov_gsd_m=scene.gsd * p["factor"])
    rows = []
    for planner in planners:
        res = plan_scene(wfov.image, None, planner, mask=mask, valid=wfov.valid, config=config)
        flown, feasible = res.trajectory, 1.0
        if geometry is not None:  # fly what the kinematics allow (see dyntarget.schedule)
            sched = schedule_on_prediction(res.trajectory, wfov.shape, geometry, p["agility"], None)
            flown, feasible = sched.trajectory, sched.fraction_feasible
        m = observe(flown, maps, factor=p["factor"])
        rows.append(
            {
                "task": task.key,
                "fold": task.fold,
                "scene": scene.id,
                "classifier": task.classifier,
                "planner": planner,
                **p,
                **m.as_dict(),
                "pointings": len(flown),
                "feasible_fraction": feasible,
                "runtime_s": classify_s + res.timings["denoise"] + res.timings["plan"],
            }
        )
    return rows


def _csv(rows: list[dict[str, Any]]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


class SweepInterrupted(Exception):
    """Raised by ``stop_after`` (tests simulate a killed sweep with it)."""


RESULT_FILES = ("sweep.csv", "sweep.png")
"""The files of a sweep's result (:func:`sweep`, :func:`summary_figure`); ``parts/`` and
``models/`` are its resume state."""


SWEEP_RUN = RunOptions(scheduler="local")
"""A sweep's default :class:`~dyntarget.evaluate.options.RunOptions`: on local Dask threads."""


def sweep(
    data: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    classifiers: Sequence[str],
    planners: Sequence[str] | None = None,
    grid: dict[str, list] | None = None,
    folds: int = 5,
    seed: int = 0,
    epochs: int = 50,
    options: RunOptions = SWEEP_RUN,
    stop_after: int | None = None,
    into: str | os.PathLike[str] | None = None,
) -> Path:
    """Run (or resume) a sweep; returns the path of the tidy table ``OUT/sweep.csv``.

    The resume state (``OUT/parts``, ``OUT/models``) stays in ``out``; the table goes to
    ``into`` when given (a staging folder the command moves into ``out`` when complete).

    Parameters
    ----------
    data : str or os.PathLike
        Scene directory of labelled scenes.
    out : str or os.PathLike
        Output folder.
    classifiers : sequence of str
        Classifiers.
    planners : sequence of str or None
        Planners (default: the paper's).
    grid : dict of str to list or None
        The grid (:func:`parse_grid`); unswept parameters at their defaults.
    folds : int
        Cross-validation folds.
    seed : int
        Seed of the fold split and the training.
    epochs : int
        Training epochs of the U-Nets.
    options : RunOptions
        Where the fold models are kept (default ``OUT/models``), progress, and the scheduler
        (default ``"local"``: a sweep always runs on Dask); ``parts`` is ignored
        (``OUT/parts`` holds them).
    stop_after : int or None
        Stop after this many finished tasks (tests).
    into : str or os.PathLike or None
        Folder of ``sweep.csv`` (default ``out``).

    Returns
    -------
    pathlib.Path
        ``OUT/sweep.csv`` (``INTO/sweep.csv`` with ``into``).
    """
    from dyntarget.evaluate.crossval import kfold_indices, train_or_load
    from dyntarget.io import read_scene_dir, scene_ids
    from dyntarget.perceive import CLASSIFIERS
    from dyntarget.plan import PAPER_PLANNERS, PLANNERS

    models_dir, progress = options.models_dir, options.progress
    scheduler = options.scheduler or "local"
    check_scheduler(scheduler)
    check_grid(grid or {})  # all of it, before any training
    check_unique("classifiers", classifiers)
    for name in classifiers:
        CLASSIFIERS.get(name)
    planners = list(planners or PAPER_PLANNERS)
    check_unique("planners", planners)
    for name in planners:
        PLANNERS.get(name)
    out, data = Path(out), Path(data)
    parts = out / "parts"
    models = Path(models_dir) if models_dir else out / "models"
    points = expand(grid or {})
    ids = scene_ids(data)
    fold_idx = kfold_indices(len(ids), folds, seed)
    run = task_key(ids, folds, seed, epochs, planners)
    scenes = None
    tasks: list[SweepTask] = []
    for factor in sorted({p["factor"] for p in points}):
        for k, test in enumerate(fold_idx):
            test_ids = [ids[i] for i in sorted(test.tolist())]
            for cname in classifiers:
                model_dir = models / f"factor-{factor}" / f"fold-{k}" / cname
                here = [
                    SweepTask(k, str(data / f"{sid}.tif"), cname, str(model_dir), p, run)
                    for sid in test_ids
                    for p in points
                    if p["factor"] == factor
                ]
                tasks += here
                if all((parts / f"{t.key}.json").exists() for t in here):
                    continue  # nothing left to do for this model: do not even load the scenes
                if scenes is None:
                    scenes = {s.id: s for s in read_scene_dir(data, require_labels=True)}
                train = [scenes[sid].to_wfov(factor) for sid in ids if sid not in test_ids]
                train_or_load(cname, train, seed=seed, epochs=epochs, model_dir=model_dir)
    try:
        results = run_tasks(
            run_task,
            tasks,
            key=lambda t: t.key,
            parts=parts,
            scheduler=scheduler,
            shared={"planners": planners},
            progress=progress,
            desc="sweep",
            stop_after=stop_after,
        )
    except Interrupted as exc:
        raise SweepInterrupted(str(exc)) from None
    order = sorted(range(len(tasks)), key=lambda i: tasks[i].key)  # independent of run order
    dest = Path(into) if into is not None else out
    return write_text(dest / "sweep.csv", _csv([row for i in order for row in results[i]]))


def summary_figure(table: Path, path: Path) -> Path | None:
    """Mean ratio plume per planner against each swept parameter (one panel per parameter).

    Parameters
    ----------
    table : pathlib.Path
        The sweep's CSV table.
    path : pathlib.Path
        The PNG to write.

    Returns
    -------
    pathlib.Path or None
        The figure, or ``None`` when no parameter varies.
    """
    import numpy as np

    from dyntarget.evaluate.figures import PATH_COLOURS, save, subplots

    with open(table, encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    swept = [p for p in GRID_PARAMETERS if len({r[p] for r in rows}) > 1]
    if not swept:
        return None
    fig, axes = subplots(1, len(swept), figsize=(4.5 * len(swept), 3.6), squeeze=False)
    for ax, param in zip(axes[0], swept, strict=True):
        if GRID_PARAMETERS[param] is str:  # categorical (agility presets), in preset order
            present = {r[param] for r in rows}
            values: list[Any] = [v for v in AGILITY if v in present]

            def value(r, param=param):
                return r[param]
        else:
            values = sorted({float(r[param]) for r in rows})

            def value(r, param=param):
                return float(r[param])

        for planner in dict.fromkeys(r["planner"] for r in rows):
            means = [
                np.mean(
                    [
                        float(r["ratio_plume"])
                        for r in rows
                        if r["planner"] == planner and value(r) == v
                    ]
                )
                for v in values
            ]
            ax.plot(values, means, "o-", color=PATH_COLOURS.get(planner), label=planner)
        ax.set_xlabel(param)
        ax.set_ylabel("mean ratio plume")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return save(fig, path)
