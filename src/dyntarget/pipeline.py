"""Algorithm 1 of the paper as one call: classify -> denoise -> plan."""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Polygon

from dyntarget import denoise as denoising
from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.masks import check_mask, mask_to_polygons
from dyntarget.perceive.base import Classifier
from dyntarget.plan import PlanConfig, Trajectory, plan
from dyntarget.scene import check_image


@dataclass(frozen=True)
class DenoiseConfig:
    """Settings of Algorithm 2 (see :func:`dyntarget.denoise.denoise`)."""

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
    path: list[str] = field(default_factory=list)
    """What ran, in order (``classify: NAME``, ``plan: NAME``), with the reason for any
    fallback a deadline forced."""
    deadline_s: float | None = None

    @property
    def deadline_met(self) -> bool | None:
        """Whether classify + denoise + plan finished within ``deadline_s`` (None: no deadline)."""
        return None if self.deadline_s is None else self.runtime <= self.deadline_s

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
    deadline_s: float | None = None,
    fallback: Classifier | None = None,
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
    deadline_s : wall-clock seconds allowed for classify + denoise + plan. A plan
        is always returned; if the full path would overrun, cheaper ones are taken
        (see :func:`choose_path`), and ``PlanResult.path`` says which and why.
    fallback : a cheaper fitted classifier (e.g. ``band-threshold``) for the deadline.
    """
    config = config or PipelineConfig()
    image = check_image(image)
    if deadline_s is not None:
        return _plan_with_deadline(
            image, classifier, planner, mask, valid, denoise, config, deadline_s, fallback
        )
    timings: dict[str, float] = {}
    probability = None
    t0 = time.perf_counter()
    if mask is None:
        if classifier is None:
            raise InvalidParameterError("plan_scene: give a classifier or a mask")
        probability = classifier.predict_proba(image)
        raw = probability >= config.threshold
    else:
        raw = check_mask(mask)
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
        clean, polygons = raw, mask_to_polygons(raw)
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
    path = [f"classify: {classifier.name}" if mask is None else "classify: given mask"]
    return PlanResult(
        probability, raw, clean, polygons, trajectory, timings, [*path, f"plan: {planner}"]
    )


SAFETY = 2.0
"""Estimated times are multiplied by this before they are compared with the time left."""
PLAN_RESERVE_S = 0.02
PLAN_RESERVE_PER_PIXEL_S = 2e-8
"""Time kept back for denoising and planning: ``PLAN_RESERVE_S`` plus this per WFOV pixel
(together 41 ms at 1024 x 1024 px, about twice what they take; see docs/performance.md)."""
LAST_RESORT = "straight-nadir"
"""The planner that needs no classification and runs in microseconds: always in time."""


_COST_PER_UNIT: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def estimate_classify_s(classifier: Classifier, image: np.ndarray) -> tuple[float, float]:
    """``(estimate, probe seconds)`` for classifying ``image``.

    The first time a classifier is seen, a crop of at most 128 x 128 px is timed
    (the probe; it counts against the deadline) and its cost per work unit
    (pixels; U-Net tiles) remembered; the estimate scales that to the image.
    Later calls reuse the remembered cost (probe 0 s). Call it once at start-up
    to calibrate a classifier before the first deadline.
    """
    h, w = image.shape[1:]
    probe = 0.0
    per_unit = _COST_PER_UNIT.get(classifier)
    if per_unit is None:
        crop = image[:, : min(h, 128), : min(w, 128)]
        t0 = time.perf_counter()
        classifier.predict_proba(crop)
        probe = time.perf_counter() - t0
        per_unit = probe / classifier.work_units(crop.shape[1:])
        _COST_PER_UNIT[classifier] = per_unit
    return per_unit * classifier.work_units((h, w)), probe


def _plan_with_deadline(
    image, classifier, planner, mask, valid, denoise, config, deadline_s, fallback
) -> PlanResult:
    """Algorithm 1 under a deadline: the full path, a cheaper classifier, or the last resort."""
    if not (np.isfinite(deadline_s) and deadline_s > 0):
        raise InvalidParameterError(f"deadline_s: expected seconds > 0, got {deadline_s!r}")
    start = time.perf_counter()
    notes: list[str] = []
    reserve = PLAN_RESERVE_S + PLAN_RESERVE_PER_PIXEL_S * image.shape[1] * image.shape[2]

    def left() -> float:
        return deadline_s - (time.perf_counter() - start)

    chosen = None
    if mask is None:
        if classifier is None:
            raise InvalidParameterError("plan_scene: give a classifier or a mask")
        for candidate in [c for c in (classifier, fallback) if c is not None]:
            if left() <= reserve:
                break
            estimate, _ = estimate_classify_s(candidate, image)
            if SAFETY * estimate + reserve <= left():
                chosen = candidate
                break
            notes.append(
                f"{candidate.name} skipped: estimated {estimate:.3f} s, {max(left(), 0):.3f} s left"
            )
    if mask is None and chosen is None:
        result = plan_scene(
            image, None, LAST_RESORT, mask=np.zeros(image.shape[1:], bool), valid=valid,
            denoise=False, config=config,
        )  # fmt: skip
        path = [*notes, "classify: none (no classifier fits the deadline)", f"plan: {LAST_RESORT}"]
    else:
        result = plan_scene(
            image, chosen, planner, mask=mask, valid=valid, denoise=denoise, config=config
        )
        path = [*notes, *result.path]
    timings = dict(result.timings)
    timings["overhead"] = (time.perf_counter() - start) - sum(result.timings.values())
    return PlanResult(
        result.probability,
        result.raw_mask,
        result.mask,
        result.polygons,
        result.trajectory,
        timings,
        path,
        deadline_s,
    )
