"""End-to-end evaluation (the paper's Table 2): classify -> denoise -> plan -> observe.

For each fold of the same scene split as the classification cross-validation
(:func:`~dyntarget.evaluate.crossval.kfold_indices`), every classifier is
trained on the WFOV training scenes — or loaded from ``models_dir`` when the
classification evaluation already trained it — and for every held-out scene
and every look-ahead planner the pipeline (:func:`dyntarget.pipeline.plan_scene`)
runs on the WFOV image; the baselines run once per scene with no classifier
("N/A"). Observations are scored on the high-resolution truth. Rows are means
over all held-out scenes of all folds; Runtime is the wall time of classify +
denoise + plan for that scene (the paper's make-span).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from dyntarget.evaluate.crossval import (
    data_signature,
    kfold_indices,
    train_or_load,
)
from dyntarget.evaluate.distributed import check_scheduler, check_unique, run_tasks, task_key
from dyntarget.evaluate.options import RunOptions, TrainingConfig
from dyntarget.evaluate.tables import display
from dyntarget.observe import UtilityMaps, observe
from dyntarget.perceive import CLASSIFIERS
from dyntarget.pipeline import PipelineConfig, plan_scene
from dyntarget.plan import BASELINES, PAPER_PLANNERS, PLANNERS
from dyntarget.scene import Scene

TABLE2_COLUMNS = [
    "Trajectory Algorithm",
    "Classifier",
    "Pixels Observed",
    "Ratio Plume",
    "Intensity",
    "Gradient",
    "Runtime (s)",
]


@dataclass(frozen=True)
class E2EConfig(TrainingConfig):
    """Settings of the end-to-end evaluation.

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
        Classifiers (default: all registered).
    planners : tuple of str
        Planners, baselines included.
    pipeline : dyntarget.pipeline.PipelineConfig
        Settings of the pipeline.
    """

    classifiers: tuple[str, ...] = field(default_factory=lambda: tuple(CLASSIFIERS.available()))
    planners: tuple[str, ...] = PAPER_PLANNERS
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)

    def __post_init__(self) -> None:
        super().__post_init__()  # folds, seed, factor, epochs
        check_unique("classifiers", self.classifiers)
        for name in self.classifiers:
            CLASSIFIERS.get(name)
        check_unique("planners", self.planners)
        for name in self.planners:
            PLANNERS.get(name)


def evaluate_end_to_end(
    scenes: Sequence[Scene],
    config: E2EConfig = E2EConfig(),
    *,
    options: RunOptions = RunOptions(),
) -> dict[str, Any]:
    """Run the end-to-end evaluation; returns Table 2 rows and per-scene records.

    Classifiers are trained (or loaded) here, once per fold; then each held-out
    scene x classifier (and each scene for the baselines) is one task of
    :func:`~dyntarget.evaluate.distributed.run_tasks` (``scheduler``: here or on
    Dask; ``parts``: where finished tasks are kept so that a rerun resumes).
    Runtimes measured on a parallel scheduler include contention between tasks.

    Parameters
    ----------
    scenes : sequence of dyntarget.scene.Scene
        Labelled high-resolution scenes.
    config : E2EConfig
        Settings.
    options : RunOptions
        Models kept, progress bar, scheduler and finished parts
        (:class:`~dyntarget.evaluate.options.RunOptions`).

    Returns
    -------
    dict
        ``rows`` (Table 2, :func:`table2_rows`), ``records`` (per scene),
        ``config``, ``folds`` (scene ids per fold) and ``wfov_shape``.
    """
    models_dir, progress, scheduler, parts = (
        options.models_dir,
        options.progress,
        options.scheduler,
        options.parts,
    )
    check_scheduler(scheduler)  # before any training
    scenes = list(scenes)
    baselines = [p for p in config.planners if p in BASELINES]
    lookahead = [p for p in config.planners if p not in BASELINES]
    folds = [sorted(f.tolist()) for f in kfold_indices(len(scenes), config.folds, config.seed)]
    wfov = [s.to_wfov(config.factor) for s in scenes]
    models: dict[str, Any] = {}
    tasks: list[tuple[int, int, str]] = []
    for k, test in enumerate(folds):
        if baselines:
            tasks += [(k, i, "N/A") for i in test]
        train = [s for i, s in enumerate(wfov) if i not in set(test)]
        for cname in tqdm(
            config.classifiers, desc=f"models, fold {k + 1}", leave=False, disable=not progress
        ):
            model_dir = Path(models_dir) / f"fold-{k}" / cname if models_dir is not None else None
            models[f"{k}/{cname}"], _, _ = train_or_load(
                cname, train, seed=config.seed, epochs=config.epochs, model_dir=model_dir
            )
            tasks += [(k, i, cname) for i in test]
    run = task_key("end-to-end", _config_dict(config), data_signature(scenes))
    results = run_tasks(
        _e2e_task,
        tasks,
        key=lambda t: task_key(run, t[0], scenes[t[1]].id, t[2]),
        parts=Path(parts) if parts is not None else None,
        scheduler=scheduler,
        shared={
            "scenes": scenes,
            "wfov": wfov,
            "models": models,
            "config": config,
            "planners": {"baselines": baselines, "lookahead": lookahead},
        },
        progress=progress,
        desc="end-to-end",
    )
    records = [r for result in results for r in result]
    rows = table2_rows(records, baselines + lookahead, list(config.classifiers))
    return {
        "rows": rows,
        "records": records,
        "config": _config_dict(config),
        "folds": [[scenes[i].id for i in f] for f in folds],
        "wfov_shape": list(wfov[0].shape),
    }


def _e2e_task(
    task: tuple[int, int, str],
    *,
    scenes: Sequence[Scene],
    wfov: Sequence[Scene],
    models: dict[str, Any],
    config: E2EConfig,
    planners: dict[str, list[str]],
) -> list[dict[str, Any]]:
    """One held-out scene with one classifier (all look-ahead planners), or with the baselines."""
    k, i, cname = task
    maps = UtilityMaps.from_scene(scenes[i])
    image, valid = wfov[i].image, wfov[i].valid
    records = []
    if cname == "N/A":  # baselines: no classifier
        for name in planners["baselines"]:
            res = plan_scene(
                image,
                None,
                name,
                mask=np.zeros(wfov[i].shape, bool),
                valid=valid,
                config=config.pipeline,
            )
            records.append(
                _record(
                    k, scenes[i].id, name, "N/A", res.trajectory, maps, config, res.timings["plan"]
                )
            )
        return records
    t0 = time.perf_counter()
    proba = models[f"{k}/{cname}"].predict_proba(image)
    classify_s = time.perf_counter() - t0
    mask = proba >= config.pipeline.threshold
    for pname in planners["lookahead"]:
        res = plan_scene(image, None, pname, mask=mask, valid=valid, config=config.pipeline)
        runtime = classify_s + res.timings["denoise"] + res.timings["plan"]
        records.append(
            _record(k, scenes[i].id, pname, cname, res.trajectory, maps, config, runtime)
        )
    return records


def _record(
    fold, scene_id, planner, classifier, trajectory, maps, config, runtime
) -> dict[str, Any]:
    m = observe(trajectory, maps, factor=config.factor)
    return {
        "fold": fold,
        "scene": scene_id,
        "planner": planner,
        "classifier": classifier,
        **m.as_dict(),
        "pointings": len(trajectory),
        "runtime_s": runtime,
    }


def table2_rows(
    records: list[dict[str, Any]], planners: list[str], classifiers: list[str]
) -> list[dict[str, Any]]:
    """Mean over scenes for every (planner, classifier) pair, in the paper's row order.

    Parameters
    ----------
    records : list of dict
        Per-scene records.
    planners : list of str
        Planners, in row order.
    classifiers : list of str
        Classifiers, in row order within a planner (baselines: ``N/A`` only).

    Returns
    -------
    list of dict
        Pixels observed, ratio plume, intensity, gradient, runtime and the
        number of scenes per row.
    """
    rows = []
    for pname in planners:
        for cname in ["N/A"] if pname in BASELINES else classifiers:
            sel = [r for r in records if r["planner"] == pname and r["classifier"] == cname]
            if not sel:
                continue
            rows.append(
                {
                    "Trajectory Algorithm": display(pname),
                    "Classifier": "N/A" if cname == "N/A" else display(cname),
                    "planner": pname,
                    "classifier": cname,
                    "Pixels Observed": float(np.mean([r["pixels_observed"] for r in sel])),
                    "Ratio Plume": float(np.mean([r["ratio_plume"] for r in sel])),
                    "Intensity": float(np.mean([r["intensity"] for r in sel])),
                    "Gradient": float(np.mean([r["gradient"] for r in sel])),
                    "Runtime (s)": float(np.mean([r["runtime_s"] for r in sel])),
                    "scenes": len(sel),
                }
            )
    return rows


def _config_dict(config: E2EConfig) -> dict[str, Any]:
    d = asdict(config)
    d["classifiers"], d["planners"] = list(config.classifiers), list(config.planners)
    return d
