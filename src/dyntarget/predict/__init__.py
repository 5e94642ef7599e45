"""Predictive targeting: how the plume moves, and where it will be.

Two looks (:func:`estimate_motion`: OpenCV Farneback optical flow by default,
a dense motion field, the velocity a histogram mode of the plume's flow votes,
``ground="auto" | "fixed" | "moving"``) or a wind prior (:func:`wind_motion`)
give a :class:`Motion`; :func:`predict_mask` and :func:`predict_field` carry
the plume to any time after the current look (detached plumes advected
semi-Lagrangian along the dense field, attached plumes stretch from their
vent; an estimate below :data:`LOW_CONFIDENCE` falls back to persistence). The
pipeline (:func:`dyntarget.pipeline.plan_scene` with ``prediction=``) plans on
the prediction. Method, assumptions and failure cases: ``docs/onboard.md``.
"""

from dyntarget.predict.advect import Prediction, check_lead, predict_field, predict_mask
from dyntarget.predict.motion import (
    CALM,
    GROUNDS,
    LOW_CONFIDENCE,
    MAX_LEAD_INTERVALS,
    REGIMES,
    Motion,
    MotionField,
    brightness,
    check_against_prior,
    check_interval,
    estimate_motion,
    wind_motion,
    wind_to_pixels,
)

__all__ = [
    "CALM",
    "GROUNDS",
    "LOW_CONFIDENCE",
    "MAX_LEAD_INTERVALS",
    "REGIMES",
    "Motion",
    "MotionField",
    "Prediction",
    "brightness",
    "check_against_prior",
    "check_interval",
    "check_lead",
    "estimate_motion",
    "predict_field",
    "predict_mask",
    "wind_motion",
    "wind_to_pixels",
]
