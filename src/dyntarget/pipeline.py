"""Algorithm 1 of the paper as one call: classify -> denoise -> (predict) -> plan."""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from shapely.geometry import Polygon

from dyntarget import defaults
from dyntarget import denoise as denoising
from dyntarget.errors import InvalidParameterError, InvalidSceneError
from dyntarget.masks import check_mask, mask_to_polygons
from dyntarget.perceive.base import Predictor
from dyntarget.plan import PlanConfig, PlanContext, Trajectory, plan
from dyntarget.predict import Prediction
from dyntarget.predict import two_look_motion as two_look_motion  # moved (issue 39)
from dyntarget.scene import check_image
from dyntarget.schedule import (
    Agility,
    OrbitGeometry,
    ParallaxAim,
    iterate_on_prediction,
    make_feasible,
    schedule,
)
from dyntarget.schedule import schedule_on_prediction as schedule_on_prediction  # moved (issue 39)


@dataclass(frozen=True)
class DenoiseConfig:
    """Settings of Algorithm 2 (see :func:`dyntarget.denoise.denoise`).

    Parameters
    ----------
    iterations : int
        Number of 3x3 closing iterations (0 = no merging).
    min_area_fraction : float
        Smallest kept polygon as a fraction of the image area.
    """

    iterations: int = denoising.DEFAULT_ITERATIONS
    min_area_fraction: float = denoising.DEFAULT_MIN_AREA_FRACTION


@dataclass(frozen=True)
class PipelineConfig:
    """Settings of the whole pipeline: planner, denoising and the classification threshold.

    Parameters
    ----------
    plan : dyntarget.plan.PlanConfig
        Planner settings.
    denoise : DenoiseConfig
        Denoising settings.
    threshold : float
        Plume probability at or above which a pixel is plume.
    """

    plan: PlanConfig = field(default_factory=PlanConfig)
    denoise: DenoiseConfig = field(default_factory=DenoiseConfig)
    threshold: float = defaults.THRESHOLD


@dataclass(frozen=True, eq=False)
class PlanResult:
    """What :func:`plan_scene` produced, with per-stage wall times in seconds.

    Parameters
    ----------
    probability : numpy.ndarray or None
        ``(H, W)`` plume probability (``None`` when planned from a given mask).
    raw_mask : numpy.ndarray
        Boolean ``(H, W)`` mask before denoising.
    mask : numpy.ndarray
        Boolean ``(H, W)`` denoised mask.
    polygons : list of shapely.Polygon
        The polygons planned over.
    trajectory : dyntarget.trajectory.Trajectory
        The plan (timed when a schedule was flown).
    timings : dict of str to float
        Wall seconds per stage.
    path : list of str
        What ran, in order.
    deadline_s : float or None
        The deadline planning ran under, seconds.
    planner : str
        The planner that made the trajectory.
    schedule : dyntarget.schedule.Schedule or None
        The schedule flown, with ``kinematics``.
    prediction : dyntarget.predict.Prediction or None
        The motion and lead time the plan was drawn for.
    predicted_mask : numpy.ndarray or None
        The mask carried to ``prediction.lead_s``.
    """

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
    planner: str = ""
    """The planner that made the trajectory (the last resort's under a missed deadline)."""
    schedule: Any = None
    """With ``kinematics``: the :class:`dyntarget.schedule.Schedule` flown."""
    prediction: Prediction | None = None
    """The motion and lead time the plan was drawn for (``None``: the plume as seen)."""
    predicted_mask: np.ndarray | None = None
    """The (denoised) mask carried to ``prediction.lead_s``: what the planner planned on."""

    @property
    def deadline_met(self) -> bool | None:
        """Whether classify + denoise + plan finished within ``deadline_s`` (None: no deadline)."""
        return None if self.deadline_s is None else self.runtime <= self.deadline_s

    @property
    def runtime(self) -> float:
        """Total wall time of classify + denoise + plan."""
        return float(sum(self.timings.values()))


@dataclass(frozen=True)
class Kinematics:
    """What ``plan_scene`` schedules under (the observation geometry and agility), and the
    budgets of the kinematic planners (``utility-max``).

    Parameters
    ----------
    geometry : dyntarget.schedule.OrbitGeometry
        Where the scene lies and when the plan starts.
    agility : dyntarget.schedule.Agility or str
        The agility preset, or its name (``dyntarget agility``).
    budget_s : float or None
        Time budget from the start, seconds.
    objective : str
        What ``utility-max`` maximises.
    max_pointings : int or None
        Pointing budget of ``utility-max``.
    """

    geometry: OrbitGeometry
    agility: Agility | str
    budget_s: float | None = None
    objective: str = "gradient"
    max_pointings: int | None = None


@dataclass(frozen=True, eq=False)
class Segmentation:
    """Algorithm 1 up to the planner: the probability, the raw and denoised masks, the polygons.

    ``timings`` holds ``classify`` and ``denoise`` wall seconds.

    Parameters
    ----------
    probability : numpy.ndarray or None
        ``(H, W)`` plume probability (``None`` when a mask was given).
    raw_mask : numpy.ndarray
        Boolean ``(H, W)`` mask before denoising.
    mask : numpy.ndarray
        Boolean ``(H, W)`` denoised mask.
    polygons : list of shapely.Polygon
        The denoised mask's polygons.
    valid : numpy.ndarray or None
        Boolean ``(H, W)``, false on nodata; ``None`` when all pixels are valid.
    image : numpy.ndarray
        The ``(4, H, W)`` WFOV image.
    timings : dict of str to float
        Wall seconds per stage.
    """

    probability: np.ndarray | None
    raw_mask: np.ndarray
    mask: np.ndarray
    polygons: list[Polygon]
    valid: np.ndarray | None
    image: np.ndarray
    timings: dict[str, float]


def classify(image: np.ndarray, classifier: Predictor) -> np.ndarray:
    """Plume probability of ``image`` (the classify stage, timed by the callers).

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` WFOV image.
    classifier : dyntarget.perceive.Predictor
        Fitted (native or ONNX).

    Returns
    -------
    numpy.ndarray
        ``(H, W)`` float32 probability.
    """
    return classifier.predict_proba(image)


def clean(raw: np.ndarray, config: PipelineConfig, *, denoise: bool = True):
    """The denoise stage (Algorithm 2, settings from ``config``), or the raw mask's polygons.

    Parameters
    ----------
    raw : numpy.ndarray
        ``(H, W)`` bool mask.
    config : PipelineConfig
        Its ``denoise`` settings.
    denoise : bool
        ``False``: keep the mask, only find its polygons.

    Returns
    -------
    tuple
        ``(mask, polygons)``.
    """
    if not denoise:
        return raw, mask_to_polygons(raw)
    cfg = config.denoise
    result = denoising.denoise(
        raw, iterations=cfg.iterations, min_area_fraction=cfg.min_area_fraction
    )
    return result.mask, result.polygons


def segment(
    image: np.ndarray,
    classifier: Predictor | None = None,
    *,
    mask: np.ndarray | None = None,
    probability: np.ndarray | None = None,
    valid: np.ndarray | None = None,
    denoise: bool = True,
    config: PipelineConfig | None = None,
) -> Segmentation:
    """Algorithm 1 before planning: classify (or take a mask or probability), threshold,
    keep valid pixels, denoise.

    Parameters
    ----------
    image : numpy.ndarray
        ``(4, H, W)`` WFOV image.
    classifier : dyntarget.perceive.Predictor or None
        Fitted classifier; not needed with ``mask`` or ``probability``.
    mask : numpy.ndarray or None
        A plume mask to plan on instead of classifying.
    probability : numpy.ndarray or None
        A plume probability computed before (thresholded at ``config.threshold``).
    valid : numpy.ndarray or None
        ``False`` on nodata pixels: never plume.
    denoise : bool
        Apply Algorithm 2.
    config : PipelineConfig or None
        Threshold and denoising settings (defaults: the paper's).

    Returns
    -------
    Segmentation
        Probability, raw and denoised masks, polygons, stage timings.

    Examples
    --------
    >>> img = np.zeros((4, 40, 40), np.float32); m = np.zeros((40, 40), bool)
    >>> m[10:30, 5:35] = True; m[2, 2] = True       # a plume and a speck
    >>> seg = segment(img, mask=m)
    >>> len(seg.polygons), int(seg.mask.sum())
    (1, 600)
    """
    config = config or PipelineConfig()
    image = check_image(image)
    t0 = time.perf_counter()
    if mask is not None:
        raw = check_mask(mask)
        if raw.shape != image.shape[1:]:
            raise InvalidSceneError(
                f"mask: shape {raw.shape} does not match the image's {image.shape[1:]}"
            )
    else:
        if probability is None:
            if classifier is None:
                raise InvalidParameterError("plan_scene: give a classifier or a mask")
            probability = classify(image, classifier)
        elif np.shape(probability) != image.shape[1:]:
            raise InvalidSceneError(
                f"probability: shape {np.shape(probability)} does not match the image's "
                f"{image.shape[1:]}"
            )
        raw = probability >= config.threshold
    if valid is not None:
        if np.shape(valid) != raw.shape:
            raise InvalidSceneError(
                f"valid: shape {np.shape(valid)} does not match the image's {raw.shape}"
            )
        valid = np.asarray(valid, bool)
        raw = raw & valid
    timings = {"classify": time.perf_counter() - t0}
    t0 = time.perf_counter()
    clean_mask, polygons = clean(raw, config, denoise=denoise)
    timings["denoise"] = time.perf_counter() - t0
    return Segmentation(probability, raw, clean_mask, polygons, valid, image, timings)


def plan_segmentation(
    segmentation: Segmentation,
    planner: str,
    config: PipelineConfig | None = None,
    *,
    kinematics: Kinematics | None = None,
) -> Trajectory:
    """The plan stage: ``planner`` on a segmentation; pointings on nodata are dropped.

    Parameters
    ----------
    segmentation : Segmentation
        From :func:`segment`.
    planner : str
        Registered planner name.
    config : PipelineConfig or None
        Its ``plan`` settings.
    kinematics : Kinematics or None
        Needed by the kinematic planners (``utility-max``).

    Returns
    -------
    Trajectory
        The planned pointings.
    """
    config = config or PipelineConfig()
    seg = segmentation
    context = None
    if kinematics is not None:
        proba = seg.probability if seg.probability is not None else seg.raw_mask
        if seg.valid is not None:
            proba = np.where(seg.valid, proba, 0.0)
        context = PlanContext(
            probability=np.asarray(proba, np.float32),
            image=seg.image,
            geometry=kinematics.geometry,
            agility=kinematics.agility,
            objective=kinematics.objective,
            budget_s=kinematics.budget_s,
            max_pointings=kinematics.max_pointings,
        )
    trajectory = plan(planner, seg.mask, seg.polygons, config.plan, context)
    if seg.valid is not None and len(trajectory):
        shape = seg.raw_mask.shape
        rows = np.clip(np.floor(trajectory.points[:, 1] + 0.5).astype(int), 0, shape[0] - 1)
        cols = np.clip(np.floor(trajectory.points[:, 0] + 0.5).astype(int), 0, shape[1] - 1)
        trajectory = trajectory.without(~seg.valid[rows, cols])  # never point at nodata
    return trajectory


def schedule_plan(
    trajectory: Trajectory, shape: tuple[int, int], planner: str, kinematics: Kinematics
):
    """The schedule stage: time the pointings under the kinematics, keep the feasible.

    A planner that plans under the kinematics (``timed``) is flown as planned; the
    others fly the better of their own order and earliest-deadline-first
    (:func:`dyntarget.schedule.make_feasible`).

    Parameters
    ----------
    trajectory : Trajectory
        As planned.
    shape : tuple of int
        WFOV ``(H, W)``.
    planner : str
        The planner that made it.
    kinematics : Kinematics
        Geometry, agility, budget.

    Returns
    -------
    dyntarget.schedule.Schedule
        What is flown (``.trajectory``) and what was dropped.
    """
    from dyntarget.plan import PLANNERS

    if getattr(PLANNERS.get(planner), "timed", False):
        return schedule(trajectory, shape, kinematics.geometry, kinematics.agility)
    return schedule_feasible(trajectory, shape, kinematics)


def schedule_feasible(trajectory: Trajectory, shape: tuple[int, int], kinematics: Kinematics):
    """The schedule stage for pointings in any order: the better of their own order and
    earliest-deadline-first, the feasible kept (:func:`dyntarget.schedule.make_feasible`).

    Parameters
    ----------
    trajectory : Trajectory
        The pointings.
    shape : tuple of int
        WFOV ``(H, W)``.
    kinematics : Kinematics
        Geometry, agility, budget.

    Returns
    -------
    dyntarget.schedule.Schedule
        What is flown (``.trajectory``, ``.kept``) and what was dropped.

    Examples
    --------
    Two pointings 10 px apart across track, one pass of a 500 km orbit: both fit.

    >>> import numpy as np
    >>> from dyntarget.schedule import OrbitGeometry
    >>> t = Trajectory(np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([0, 1]), "two")
    >>> len(schedule_feasible(t, (1, 20), Kinematics(OrbitGeometry(), "fast")).kept)
    2
    """
    return make_feasible(
        trajectory, shape, kinematics.geometry, kinematics.agility, budget_s=kinematics.budget_s
    )


def plan_scene(
    image: np.ndarray,
    classifier: Predictor | None,
    planner: str,
    *,
    mask: np.ndarray | None = None,
    valid: np.ndarray | None = None,
    denoise: bool = True,
    config: PipelineConfig | None = None,
    deadline_s: float | None = None,
    fallback: Predictor | None = None,
    kinematics: Kinematics | None = None,
    prediction: Prediction | None = None,
    aim_height_m: float | None = None,
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
    config : threshold, denoising and planner settings.
    deadline_s : wall-clock seconds allowed for classify + denoise + plan. A plan
        is always returned; if the full path would overrun, cheaper ones are taken
        (see :func:`choose_path`), and ``PlanResult.path`` says which and why.
    fallback : a cheaper fitted classifier (e.g. ``band-threshold``) for the deadline.
    kinematics : schedule the plan under this geometry and agility
        (``PlanResult.schedule``); needed by ``utility-max``.
    prediction : plan on the plume as it will be ``prediction.lead_s`` seconds after
        the acquisition (:mod:`dyntarget.predict`): the denoised mask is advected
        there and the planner runs on it (``PlanResult.predicted_mask``). With
        ``kinematics``, each pointing is moved on to the plume at its own scheduled
        time (:func:`iterate_on_prediction`).
    aim_height_m : with ``kinematics``, correct every scheduled pointing for the
        parallax of a plume top this high (metres above sea level, constant over the
        frame: a prior): the image is the look-ahead's view from ``kinematics.geometry``
        (``look_ahead_m`` ahead at the acquisition), and each pointing is moved to where
        the NFOV meets that top at its own time (:class:`dyntarget.schedule.ParallaxAim`).
        The schedule's ``params`` record ``parallax_height_m``. ``None``: no correction.

    Returns
    -------
    PlanResult
        Masks, polygons, the trajectory, per-stage timings (and the schedule).
    """
    config = config or PipelineConfig()
    image = check_image(image)
    aim, aim_m = None, 0.0
    if aim_height_m is not None:
        if kinematics is None:
            raise InvalidParameterError(
                "aim_height_m: the parallax correction moves scheduled pointings; "
                "give kinematics as well"
            )
        aim = ParallaxAim.constant(kinematics.geometry, image.shape[1:], aim_height_m)
        aim_m = float(aim_height_m)
    if deadline_s is not None:
        result = _plan_with_deadline(
            image, classifier, planner, mask, valid, denoise, config, deadline_s, fallback,
            kinematics, prediction,
        )  # fmt: skip
    else:
        result = _plan_once(
            image, classifier, planner, mask, valid, denoise, config, kinematics, prediction
        )
    if kinematics is not None:
        shape = image.shape[1:]

        def fly(trajectory: Trajectory):
            return schedule_plan(trajectory, shape, result.planner, kinematics)

        if result.prediction is None and aim is None:
            flown = fly(result.trajectory)
        else:  # each pointing moved on to the plume at its own scheduled time
            p = result.prediction
            attached = None if p is None else p.attached_mask(result.mask)

            def in_order(trajectory: Trajectory):
                k = kinematics
                return schedule(trajectory, shape, k.geometry, k.agility, budget_s=k.budget_s)

            _, flown = iterate_on_prediction(  # with an aim: where the NFOV meets the top then
                result.trajectory, p, fly, attached=attached, aim=aim, in_order=in_order
            )
            if aim is not None:
                flown.trajectory.params["parallax_height_m"] = aim_m
        result = replace(result, schedule=flown)
    return result


def predict_segmentation(segmentation: Segmentation, prediction: Prediction) -> Segmentation:
    """The predict stage: the segmentation carried to ``prediction.lead_s`` (nodata stays off).

    The denoised mask is advected (:meth:`~dyntarget.predict.Prediction.mask`), its
    polygons found again, and the probability (if any) advected too, so every
    planner, ``utility-max`` included, plans on the plume as it will be.
    ``timings`` gains ``predict``.

    Parameters
    ----------
    segmentation : Segmentation
        The segmentation of the current image.
    prediction : dyntarget.predict.Prediction
        The motion and the lead time.

    Returns
    -------
    Segmentation
        A copy with the predicted probability, masks and polygons.

    Examples
    --------
    >>> from dyntarget.predict import Motion
    >>> m = np.zeros((40, 40), bool); m[10:20, 5:15] = True
    >>> seg = segment(np.zeros((4, 40, 40), np.float32), mask=m, denoise=False)
    >>> moved = predict_segmentation(seg, Prediction(Motion((1.0, 0.0)), 10.0))
    >>> int(np.argmax(moved.mask.any(axis=0)))   # the plume's west edge moved 10 px east
    15
    """
    t0 = time.perf_counter()
    predicted = prediction.mask(segmentation.mask)
    probability = segmentation.probability
    if probability is not None:
        probability = prediction.field(probability)
    raw = prediction.mask(segmentation.raw_mask)
    if segmentation.valid is not None:
        predicted &= segmentation.valid
        raw &= segmentation.valid
    timings = {**segmentation.timings, "predict": time.perf_counter() - t0}
    return replace(
        segmentation, mask=predicted, raw_mask=raw, polygons=mask_to_polygons(predicted),
        probability=probability, timings=timings,
    )  # fmt: skip


def _plan_once(
    image, classifier, planner, mask, valid, denoise, config, kinematics, prediction=None
) -> PlanResult:
    seg = segment(image, classifier, mask=mask, valid=valid, denoise=denoise, config=config)
    target = seg if prediction is None else predict_segmentation(seg, prediction)
    t0 = time.perf_counter()
    trajectory = plan_segmentation(target, planner, config, kinematics=kinematics)
    timings = {**target.timings, "plan": time.perf_counter() - t0}
    path = [f"classify: {classifier.name}" if mask is None else "classify: given mask"]
    if prediction is not None:
        m = prediction.motion
        path.append(f"predict: {m.regime}, {prediction.lead_s:g} s ahead ({m.source})")
    return PlanResult(
        seg.probability,
        seg.raw_mask,
        seg.mask,
        target.polygons,
        trajectory,
        timings,
        [*path, f"plan: {planner}"],
        planner=planner,
        prediction=prediction,
        predicted_mask=None if prediction is None else target.mask,
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


def estimate_classify_s(classifier: Predictor, image: np.ndarray) -> tuple[float, float]:
    """``(estimate, probe seconds)`` for classifying ``image``.

    The first time a classifier is seen, a crop of at most 128 x 128 px is timed
    (the probe; it counts against the deadline) and its cost per work unit
    (pixels; U-Net tiles) remembered; the estimate scales that to the image.
    Later calls reuse the remembered cost (probe 0 s). Call it once at start-up
    to calibrate a classifier before the first deadline.

    Parameters
    ----------
    classifier : dyntarget.perceive.Predictor
        The classifier to time.
    image : numpy.ndarray
        The ``(4, H, W)`` image it will classify.

    Returns
    -------
    estimate : float
        Estimated seconds to classify ``image``.
    probe : float
        Seconds spent timing the probe now (0 when the cost was known).
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
    image, classifier, planner, mask, valid, denoise, config, deadline_s, fallback, kinematics,
    prediction=None,
) -> PlanResult:  # fmt: skip
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
        result = _plan_once(
            image, None, LAST_RESORT, np.zeros(image.shape[1:], bool), valid, False, config, None
        )
        path = [*notes, "classify: none (no classifier fits the deadline)", f"plan: {LAST_RESORT}"]
    else:
        result = _plan_once(
            image, chosen, planner, mask, valid, denoise, config, kinematics, prediction
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
        planner=result.planner,
        prediction=result.prediction,
        predicted_mask=result.predicted_mask,
    )
