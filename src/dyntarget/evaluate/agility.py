"""Planners under orbit kinematics and agility presets, with ``utility-max`` beside them.

For each fold a classifier is trained (or loaded from ``models_dir``, so the
models of ``dyntarget reproduce`` are reused); for every held-out scene its
plume probability is computed once, denoised, and every geometric planner
plans on it. Each plan is then timed under each agility preset
(:func:`dyntarget.schedule.schedule`): first in the planner's own order
(the fraction of the paper's points that would really be observed), then the
better of that and an earliest-deadline-first reordering
(:func:`~dyntarget.schedule.make_feasible`), which is what is flown and
scored on the high-resolution truth. ``utility-max`` plans directly under each
preset with the same visibility windows; with unlimited agility, where time
costs nothing, its pointing budget is the largest number of pointings any
geometric planner kept on that scene — equal budgets either way.

Totals are sums over the observed WFOV pixels (mean utility x pixels observed);
"per pointing" is the mean.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget import defaults
from dyntarget.errors import InvalidParameterError
from dyntarget.evaluate.crossval import data_signature, kfold_indices, train_or_load
from dyntarget.evaluate.distributed import check_scheduler, check_unique, run_tasks, task_key
from dyntarget.evaluate.options import RunOptions, TrainingConfig
from dyntarget.evaluate.tables import display
from dyntarget.observe import UtilityMaps, observe
from dyntarget.perceive import CLASSIFIERS
from dyntarget.pipeline import (
    Kinematics,
    PipelineConfig,
    plan_segmentation,
    schedule_on_prediction,
    schedule_plan,
    segment,
)
from dyntarget.plan import BASELINES, PAPER_PLANNERS, PLANNERS, PlanConfig
from dyntarget.scene import Scene
from dyntarget.schedule import AGILITY, OrbitGeometry, schedule

AGILITY_COLUMNS = [
    "Agility",
    "Trajectory Algorithm",
    "Planned",
    "Feasible as planned",
    "Observed",
    "Gradient per pointing",
    "Total gradient",
    "Intensity per pointing",
    "Total intensity",
    "Ratio Plume",
]


@dataclass(frozen=True)
class AgilityConfig(TrainingConfig):
    """Settings of the agility evaluation (see the module docstring).

    Parameters
    ----------
    folds : int
        Cross-validation folds.
    seed : int
        Seed of the fold split and the training.
    factor : int
        High-res -> WFOV downsampling factor.
    epochs : int
        Training epochs of a U-Net classifier.
    classifier : str
        The classifier planned on.
    presets : tuple of str
        Agility presets to time the plans under.
    planners : tuple of str
        Geometric planners (``utility-max`` is always added).
    objective : str
        What ``utility-max`` maximises.
    altitude_m, look_ahead_m : float
        Orbit geometry, metres.
    plan : dyntarget.plan.PlanConfig
        Planner settings.
    """

    classifier: str = defaults.AGILITY_CLASSIFIER
    presets: tuple[str, ...] = tuple(AGILITY)
    planners: tuple[str, ...] = field(
        default_factory=lambda: tuple(p for p in PAPER_PLANNERS if p not in BASELINES)
    )
    objective: str = defaults.OBJECTIVE
    altitude_m: float = defaults.ALTITUDE_M
    look_ahead_m: float = defaults.LOOK_AHEAD_M
    plan: PlanConfig = field(default_factory=PlanConfig)

    def __post_init__(self) -> None:
        super().__post_init__()  # folds, seed, factor, epochs
        CLASSIFIERS.get(self.classifier)
        check_unique("planners", self.planners)
        for name in self.planners:
            PLANNERS.get(name)
        check_unique("presets", self.presets)
        for name in self.presets:
            if name not in AGILITY:
                raise InvalidParameterError(
                    f"agility: unknown preset {name!r}; choose from {', '.join(AGILITY)}"
                )
        if self.objective not in defaults.OBJECTIVES:
            raise InvalidParameterError(
                f"objective: expected one of {', '.join(defaults.OBJECTIVES)}, got {self.objective!r}"
            )
        OrbitGeometry(altitude_m=self.altitude_m, look_ahead_m=self.look_ahead_m)  # validates


def _agility_task(
    task: tuple[int, int],
    *,
    scenes: Sequence[Scene],
    wfov: Sequence[Scene],
    models: dict[int, Any],
    config: AgilityConfig,
) -> list[dict[str, Any]]:
    k, i = task
    scene, w = scenes[i], wfov[i]
    if scene.gsd is None:
        raise InvalidParameterError(
            f"scene {scene.id!r}: no ground sampling distance; the orbit geometry needs one"
        )
    maps = UtilityMaps.from_scene(scene)
    pipeline = PipelineConfig(plan=config.plan)
    seg = segment(
        w.image, probability=models[k].predict_proba(w.image), valid=w.valid, config=pipeline
    )
    geometry = OrbitGeometry(
        altitude_m=config.altitude_m,
        look_ahead_m=config.look_ahead_m,
        wfov_gsd_m=scene.gsd * config.factor,
    )
    plans = {p: plan_segmentation(seg, p, pipeline) for p in config.planners}
    records = []

    def record(preset, planner, planned, as_planned, flown):
        m = observe(flown, maps, factor=config.factor)
        return {
            "fold": k,
            "scene": scene.id,
            "agility": preset,
            "planner": planner,
            "planned": planned,
            "feasible_as_planned": as_planned,
            "observed": m.pixels_observed,
            "gradient": m.gradient,
            "total_gradient": m.gradient * m.pixels_observed,
            "intensity": m.intensity,
            "total_intensity": m.intensity * m.pixels_observed,
            "ratio_plume": m.ratio_plume,
        }

    for preset in config.presets:
        kept = []
        for name, traj in plans.items():
            as_planned = schedule(traj, w.shape, geometry, preset)
            flown = schedule_on_prediction(
                traj, w.shape, geometry, preset, None, as_planned=as_planned
            )
            kept.append(len(flown.kept))
            records.append(
                record(preset, name, len(traj), as_planned.fraction_feasible, flown.trajectory)
            )
        budget = max(kept, default=0) if AGILITY[preset].unlimited else None
        kinematics = Kinematics(geometry, preset, objective=config.objective, max_pointings=budget)
        traj = plan_segmentation(seg, "utility-max", pipeline, kinematics=kinematics)
        flown = schedule_plan(traj, w.shape, "utility-max", kinematics)
        records.append(
            record(preset, "utility-max", len(traj), flown.fraction_feasible, flown.trajectory)
        )
    return records


def evaluate_agility(
    scenes: Sequence[Scene],
    config: AgilityConfig = AgilityConfig(),
    *,
    options: RunOptions = RunOptions(),
) -> dict[str, Any]:
    """Feasibility and utility of every planner under every agility preset (see module docstring).

    Parameters
    ----------
    scenes : sequence of dyntarget.scene.Scene
        Labelled high-resolution scenes.
    config : AgilityConfig
        Settings.
    options : RunOptions
        Models kept, progress bar, scheduler and finished parts
        (:class:`~dyntarget.evaluate.options.RunOptions`).

    Returns
    -------
    dict
        ``rows`` (:func:`agility_rows`), ``records`` (per scene, planner and
        preset), ``config`` and ``ground_speed_m_s``.
    """
    models_dir, progress, scheduler, parts = (
        options.models_dir,
        options.progress,
        options.scheduler,
        options.parts,
    )
    check_scheduler(scheduler)
    scenes = list(scenes)
    folds = [sorted(f.tolist()) for f in kfold_indices(len(scenes), config.folds, config.seed)]
    wfov = [s.to_wfov(config.factor) for s in scenes]
    models = {}
    for k, test in enumerate(folds):
        train = [s for i, s in enumerate(wfov) if i not in set(test)]
        model_dir = Path(models_dir) / f"fold-{k}" / config.classifier if models_dir else None
        models[k], _, _ = train_or_load(
            config.classifier, train, seed=config.seed, epochs=config.epochs, model_dir=model_dir
        )
    tasks = [(k, i) for k, test in enumerate(folds) for i in test]
    run = task_key("agility", asdict(config), data_signature(scenes))
    results = run_tasks(
        _agility_task,
        tasks,
        key=lambda t: task_key(run, t[0], scenes[t[1]].id),
        parts=Path(parts) if parts is not None else None,
        scheduler=scheduler,
        shared={"scenes": scenes, "wfov": wfov, "models": models, "config": config},
        progress=progress,
        desc="agility",
    )
    records = [r for result in results for r in result]
    return {
        "rows": agility_rows(records, list(config.presets), [*config.planners, "utility-max"]),
        "records": records,
        "config": asdict(config),
        "ground_speed_m_s": OrbitGeometry(altitude_m=config.altitude_m).ground_speed,
    }


def agility_rows(
    records: list[dict[str, Any]], presets: list[str], planners: list[str]
) -> list[dict[str, Any]]:
    """Table rows: means over scenes per agility preset and planner.

    Parameters
    ----------
    records : list of dict
        Per-scene records of :func:`evaluate_agility`.
    presets : list of str
        Agility presets, in row order.
    planners : list of str
        Planners, in row order within a preset.

    Returns
    -------
    list of dict
        One row per preset and planner with records: planned and observed
        pointings, the share feasible as planned, gradient and intensity per
        pointing and in total, ratio plume, and the number of scenes.
    """
    rows = []
    for preset in presets:
        for name in planners:
            sel = [r for r in records if r["agility"] == preset and r["planner"] == name]
            if not sel:
                continue

            def mean(key, sel=sel):
                return float(np.mean([r[key] for r in sel]))

            rows.append(
                {
                    "Agility": preset,
                    "Trajectory Algorithm": display(name)
                    if name != "utility-max"
                    else "Utility Max",
                    "agility": preset,
                    "planner": name,
                    "Planned": mean("planned"),
                    "Feasible as planned": mean("feasible_as_planned"),
                    "Observed": mean("observed"),
                    "Gradient per pointing": mean("gradient"),
                    "Total gradient": mean("total_gradient"),
                    "Intensity per pointing": mean("intensity"),
                    "Total intensity": mean("total_intensity"),
                    "Ratio Plume": mean("ratio_plume"),
                    "scenes": len(sel),
                }
            )
    return rows
