"""Algorithm 1 of the paper as one call: classify -> denoise -> plan."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Polygon

from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.perceive import denoise as denoising
from dyntarget.perceive.base import Classifier
from dyntarget.plan import PlanConfig, Trajectory, plan
from dyntarget.scene import check_image


@dataclass(frozen=True)
class DenoiseConfig:
    """Settings of Algorithm 2 (see :func:`dyntarget.perceive.denoise.denoise`)."""

    iterations: int = denoising.DEFAULT_ITERATIONS
    min_area_fraction: float = denoising.DEFAULT_MIN_AREA_FRACTION


@dataclass(frozen=True)
class PipelineConfig:
    plan: PlanConfig = field(default_factory=PlanConfig)
    denoise: DenoiseConfig = field(default_factory=DenoiseConfig)
    threshold: float = 0.5


@dataclass(frozen=True, eq=False)
class PlanResult:
    """What :func:`plan_scene` produced, with per-stage wall times in seconds."""

    probability: np.ndarray | None
    raw_mask: np.ndarray
    mask: np.ndarray
    polygons: list[Polygon]
    trajectory: Trajectory
    timings: dict[str, float]

    @property
    def runtime(self) -> float:
        """Total wall time of classify + denoise + plan."""
        return float(sum(self.timings.values()))


def plan_scene(
    image: np.ndarray,
    classifier: Classifier | None,
    planner: str,
    *,
    mask: np.ndarray | None = None,
    valid: np.ndarray | None = None,
    denoise: bool = True,
    config: PipelineConfig | None = None,
) -> PlanResult:
    """Plan an NFOV trajectory for a WFOV image (Algorithm 1).

    Parameters
    ----------
    image : float32 (4, H, W) WFOV image (R, G, B, NIR).
    classifier : a fitted classifier, or ``None`` when ``mask`` is given.
    planner : registered planner name (see ``dyntarget planners``).
    mask : a plume mask to plan on instead of classifying (e.g. a hand label).
    valid : ``False`` on nodata pixels (``Scene.valid``): never plume, never pointed at.
    denoise : apply Algorithm 2 before planning (as the paper does).
    """
    config = config or PipelineConfig()
    image = check_image(image)
    timings: dict[str, float] = {}
    probability = None
    t0 = time.perf_counter()
    if mask is None:
        if classifier is None:
            raise InvalidParameterError("plan_scene: give a classifier or a mask")
        probability = classifier.predict_proba(image)
        raw = probability >= config.threshold
    else:
        raw = denoising.check_mask(mask)
        if raw.shape != image.shape[1:]:
            raise InvalidSceneError(
                f"mask: shape {raw.shape} does not match the image's {image.shape[1:]}"
            )
    if valid is not None:
        if np.shape(valid) != raw.shape:
            raise InvalidSceneError(
                f"valid: shape {np.shape(valid)} does not match the image's {raw.shape}"
            )
        raw = raw & np.asarray(valid, bool)
    timings["classify"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if denoise:
        cfg = config.denoise
        result = denoising.denoise(
            raw, iterations=cfg.iterations, min_area_fraction=cfg.min_area_fraction
        )
        clean, polygons = result.mask, result.polygons
    else:
        clean, polygons = raw, denoising.mask_to_polygons(raw)
    timings["denoise"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    trajectory = plan(planner, clean, polygons, config.plan)
    if valid is not None and len(trajectory):
        rows = np.clip(np.floor(trajectory.points[:, 1] + 0.5).astype(int), 0, raw.shape[0] - 1)
        cols = np.clip(np.floor(trajectory.points[:, 0] + 0.5).astype(int), 0, raw.shape[1] - 1)
        trajectory = trajectory.without(
            ~np.asarray(valid, bool)[rows, cols]
        )  # never point at nodata
    timings["plan"] = time.perf_counter() - t0
    return PlanResult(probability, raw, clean, polygons, trajectory, timings)
