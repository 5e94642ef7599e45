"""Modes of ``evaluate dynamic`` that plan for the plume as it will be (issue 16).

* ``predictive``: motion from the last two look-ahead frames
  (:func:`dyntarget.pipeline.two_look_motion`; the previous frame is segmented by
  the same classifier, or its true mask with ``true-mask``), the denoised mask
  advected to the start of pointing (the latency), planned on, and every pointing
  moved on to the plume at its own scheduled time
  (:func:`dyntarget.pipeline.iterate_on_prediction`).
* ``wind-prior``: the same with one look and the sequence's recorded wind
  (``meta["world"]["wind"]`` or ``meta["wind"]``: speed and direction it blows
  from), converted with the decision frame's georeference; regime ``detached``
  (see :func:`dyntarget.predict.wind_motion`). With synthetic sequences this is
  the *true* wind: an upper bound for a forecast wind.

Both return the moved trajectory; the evaluator schedules and scores it.
"""

from __future__ import annotations

import hashlib
import weakref
from typing import Any

import numpy as np

from dyntarget.errors import InvalidParameterError
from dyntarget.evaluate.dynamic import ModeContext, static_mode
from dyntarget.pipeline import (
    iterate_on_prediction,
    plan_segmentation,
    predict_segmentation,
    segment,
)
from dyntarget.predict import Motion, Prediction, plume_motion, wind_motion
from dyntarget.trajectory import Trajectory


def plan_on_motion(ctx: ModeContext, motion: Motion) -> Trajectory:
    """Plan on the plume predicted for the start of pointing, each pointing at its own time.

    The same stages as the ``static`` mode (segment, plan), with the predict stage
    between them (:func:`dyntarget.pipeline.predict_segmentation`).

    Parameters
    ----------
    ctx : dyntarget.evaluate.dynamic.ModeContext
        The decision frame, its mask, the planner, latency and schedule.
    motion : dyntarget.predict.Motion
        The plume's motion.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The pointings moved on to their times (untimed; the evaluator schedules them).
    """
    decision = ctx.frames.frames[-1]
    prediction = Prediction(motion, ctx.latency_s)
    seg = segment(decision.image, mask=ctx.mask, valid=decision.valid, config=ctx.pipeline)
    trajectory = plan_segmentation(predict_segmentation(seg, prediction), ctx.planner, ctx.pipeline)
    if len(trajectory) == 0:
        return trajectory
    attached = prediction.attached_mask(seg.mask)
    moved, _ = iterate_on_prediction(trajectory, prediction, ctx.schedule, attached=attached)
    return moved


def two_look_motion(ctx: ModeContext) -> Motion:
    """The motion between the last two frames of ``ctx`` (masks as the mode's classifier sees them).

    Parameters
    ----------
    ctx : dyntarget.evaluate.dynamic.ModeContext
        At least two frames.

    Returns
    -------
    dyntarget.predict.Motion
        The two-look estimate.

    Raises
    ------
    dyntarget.errors.InvalidParameterError
        With fewer than two frames, or (true mask) an unlabelled previous frame.
    """
    frames = ctx.frames
    if len(frames) < 2:
        raise InvalidParameterError(
            f"predictive mode: sequence {frames.id!r} has {len(frames)} frame(s); two looks needed"
        )
    prev, cur = frames.frames[-2], frames.frames[-1]
    interval = float(frames.times[-1] - frames.times[-2])
    if ctx.classifier is None and prev.label is None:
        raise InvalidParameterError(
            f"predictive mode: sequence {frames.id!r}: the previous frame has no label"
        )
    label = prev.label if ctx.classifier is None else None
    seen = segment(prev.image, ctx.classifier, mask=label, valid=prev.valid, config=ctx.pipeline)
    now = segment(cur.image, mask=ctx.mask, valid=cur.valid, config=ctx.pipeline)
    motion = plume_motion(None, (prev.image, cur.image, seen.mask, now.mask), interval)
    assert motion is not None  # two looks always give a motion
    return motion


_MOTIONS: weakref.WeakKeyDictionary[Any, dict[tuple, Motion]] = weakref.WeakKeyDictionary()
"""Motions already estimated (the same for every planner and latency of a scene), per
classifier: keyed on the classifier object itself (held weakly), never on its ``id()``,
which a later classifier may reuse once the first is gone."""
_TRUE_MASK_MOTIONS: dict[tuple, Motion] = {}
"""The same for the true-mask classifier."""


def predictive_mode(ctx: ModeContext) -> Trajectory:
    """Two looks: estimate the motion, plan for the plume as it will be.

    Parameters
    ----------
    ctx : dyntarget.evaluate.dynamic.ModeContext
        At least two frames.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The plan (:func:`plan_on_motion`).
    """
    key = (
        ctx.frames.id,
        tuple(np.asarray(ctx.frames.times).tolist()),
        ctx.pipeline,
        hashlib.sha1(np.packbits(ctx.mask).tobytes()).hexdigest(),
    )
    if ctx.classifier is None:
        cache = _TRUE_MASK_MOTIONS
    else:
        cache = _MOTIONS.setdefault(ctx.classifier, {})
    motion = cache.get(key)
    if motion is None:
        if len(cache) > 256:
            cache.clear()
        motion = cache[key] = two_look_motion(ctx)
    return plan_on_motion(ctx, motion)


def recorded_wind(meta: dict[str, Any]) -> tuple[float, float] | None:
    """``(speed_mps, from_deg)`` recorded with a sequence, or ``None``.

    Parameters
    ----------
    meta : dict
        A sequence's metadata (the world spec's wind first).

    Returns
    -------
    tuple of float or None
        The wind, or ``None``.

    Examples
    --------
    >>> recorded_wind({"wind": {"speed_mps": 5.0, "from_deg": 90.0}})
    (5.0, 90.0)
    """
    for source in (meta.get("world"), meta):
        wind = source.get("wind") if isinstance(source, dict) else None
        if isinstance(wind, dict) and "speed_mps" in wind and "from_deg" in wind:
            return float(wind["speed_mps"]), float(wind["from_deg"])
    return None


def wind_prior_mode(ctx: ModeContext) -> Trajectory:
    """One look and the recorded wind; the paper's static plan where no wind is recorded.

    Parameters
    ----------
    ctx : dyntarget.evaluate.dynamic.ModeContext
        The decision frame, its mask, the planner and the sequence's metadata.

    Returns
    -------
    dyntarget.trajectory.Trajectory
        The plan.
    """
    wind = recorded_wind(ctx.meta)
    if wind is None:
        return static_mode(ctx)
    decision = ctx.frames.frames[-1]
    motion = wind_motion(*wind, transform=decision.transform, gsd_m=decision.gsd)
    return plan_on_motion(ctx, motion)
