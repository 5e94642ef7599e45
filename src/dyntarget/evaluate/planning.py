"""Planners on the true masks: the look-ahead planners' ceiling versus the baselines.

For each scene the WFOV label (majority downsampling, ``factor``) is denoised
as in the pipeline, every planner plans on it, and the NFOV simulator scores
the trajectory on the high-resolution truth. This isolates planning from
classification errors; the end-to-end table pairs planners with classifiers.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from tqdm import tqdm

from dyntarget.evaluate.tables import display
from dyntarget.observe import UtilityMaps, observe
from dyntarget.perceive.denoise import DEFAULT_ITERATIONS, DEFAULT_MIN_AREA_FRACTION, denoise
from dyntarget.plan import PLANNERS, PlanConfig, plan
from dyntarget.scene import Scene

PLANNING_COLUMNS = [
    "Trajectory Algorithm",
    "Pixels Observed",
    "Ratio Plume",
    "Intensity",
    "Gradient",
    "Plan (ms)",
]


def evaluate_planners_on_truth(
    scenes: Sequence[Scene],
    *,
    factor: int = 4,
    config: PlanConfig | None = None,
    planners: Sequence[str] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    config = config or PlanConfig()
    planners = list(planners or PLANNERS.available())
    per: dict[str, list[list[float]]] = {n: [] for n in planners}
    for scene in tqdm(scenes, desc="planning on true masks", unit="scene", disable=not progress):
        wfov = scene.to_wfov(factor)
        cleaned = denoise(
            wfov.label, iterations=DEFAULT_ITERATIONS, min_area_fraction=DEFAULT_MIN_AREA_FRACTION
        )
        maps = UtilityMaps.from_scene(scene)
        for name in planners:
            t0 = time.perf_counter()
            traj = plan(name, cleaned.mask, cleaned.polygons, config)
            ms = 1000 * (time.perf_counter() - t0)
            m = observe(traj, maps, factor=factor)
            per[name].append([m.pixels_observed, m.ratio_plume, m.intensity, m.gradient, ms])
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
