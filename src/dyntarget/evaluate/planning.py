"""Planners on the true masks: the look-ahead planners' ceiling versus the baselines.

For each scene the WFOV label (majority downsampling, ``factor``) is denoised
as in the pipeline, every planner plans on it, and the NFOV simulator scores
the trajectory on the high-resolution truth. This isolates planning from
classification errors; the end-to-end table pairs planners with classifiers.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from dyntarget.evaluate.crossval import data_signature
from dyntarget.evaluate.distributed import check_scheduler, run_tasks, task_key
from dyntarget.evaluate.options import RunOptions
from dyntarget.evaluate.tables import display
from dyntarget.observe import UtilityMaps, observe
from dyntarget.pipeline import PipelineConfig, plan_segmentation, segment
from dyntarget.plan import PAPER_PLANNERS, PlanConfig
from dyntarget.scene import Scene

PLANNING_COLUMNS = [
    "Trajectory Algorithm",
    "Pixels Observed",
    "Ratio Plume",
    "Intensity",
    "Gradient",
    "Plan (ms)",
]


def _planning_task(
    i: int, *, scenes: Sequence[Scene], factor: int, config: PlanConfig, planners: list[str]
) -> list[list[float]]:
    """One scene: denoise its WFOV label (the pipeline's Algorithm 1 on the true mask), then
    plan and observe with every planner."""
    scene = scenes[i]
    wfov = scene.to_wfov(factor)
    pipeline = PipelineConfig(plan=config)
    seg = segment(wfov.image, mask=wfov.label, valid=wfov.valid, config=pipeline)
    maps = UtilityMaps.from_scene(scene)
    out = []
    for name in planners:
        t0 = time.perf_counter()
        traj = plan_segmentation(seg, name, pipeline)
        ms = 1000 * (time.perf_counter() - t0)
        m = observe(traj, maps, factor=factor)
        out.append([m.pixels_observed, m.ratio_plume, m.intensity, m.gradient, ms])
    return out


def evaluate_planners_on_truth(
    scenes: Sequence[Scene],
    *,
    factor: int = 4,
    config: PlanConfig | None = None,
    planners: Sequence[str] | None = None,
    options: RunOptions = RunOptions(),
) -> dict[str, Any]:
    """Every planner on every scene's true mask; one task per scene (see ``run_tasks``).

    Parameters
    ----------
    scenes : sequence of dyntarget.scene.Scene
        Labelled high-resolution scenes.
    factor : int
        High-res -> WFOV downsampling factor.
    config : dyntarget.plan.PlanConfig or None
        Planner settings.
    planners : sequence of str or None
        Planners (default: the paper's).
    options : RunOptions
        Models kept, progress bar, scheduler and finished parts
        (:class:`~dyntarget.evaluate.options.RunOptions`).

    Returns
    -------
    dict
        ``rows`` (mean metrics and median planning time per planner), ``factor``
        and ``scenes`` (ids).
    """
    progress, scheduler, parts = options.progress, options.scheduler, options.parts
    check_scheduler(scheduler)  # before any training
    config = config or PlanConfig()
    planners = list(planners or PAPER_PLANNERS)
    run = task_key("planning", factor, asdict(config), planners, data_signature(scenes))
    results = run_tasks(
        _planning_task,
        list(range(len(scenes))),
        key=lambda i: task_key(run, scenes[i].id),
        parts=Path(parts) if parts is not None else None,
        scheduler=scheduler,
        shared={"scenes": list(scenes), "factor": factor, "config": config, "planners": planners},
        progress=progress,
        desc="planning on true masks",
    )
    per = {name: [result[j] for result in results] for j, name in enumerate(planners)}
    rows = []
    for name in planners:
        a = np.asarray(per[name], dtype=np.float64)
        mean = a.mean(axis=0)
        rows.append(
            {
                "Trajectory Algorithm": display(name),
                "planner": name,
                "Pixels Observed": float(mean[0]),
                "Ratio Plume": float(mean[1]),
                "Intensity": float(mean[2]),
                "Gradient": float(mean[3]),
                "Plan (ms)": float(np.median(a[:, 4])),
            }
        )
    return {"rows": rows, "factor": factor, "scenes": [s.id for s in scenes]}
