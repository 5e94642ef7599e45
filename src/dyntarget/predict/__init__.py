"""Predictive targeting: how the plume moves, and where it will be.

Two looks (:func:`estimate_motion`: OpenCV Farneback optical flow by default,
a dense motion field, the velocity a histogram mode of the plume's flow votes,
``ground="auto" | "fixed" | "moving"``) or a wind prior (:func:`wind_motion`)
give a :class:`Motion`; :func:`predict_mask` and :func:`predict_field` carry
the plume to any time after the current look (detached plumes advected
semi-Lagrangian along the dense field, attached plumes stretch from their
vent; an estimate below :data:`LOW_CONFIDENCE` falls back to persistence). The
pipeline (:func:`dyntarget.pipeline.plan_scene` with ``prediction=``) plans on
the prediction. :func:`plume_motion` is the stage's entry point (the motion for
a plan: two looks checked against a wind prior, or the prior), :func:`lucas_kanade`
the one wrapper of pysteps' Lucas-Kanade field. Method, assumptions and failure cases: ``docs/onboard.md``.
"""

from dyntarget.predict.advect import Prediction, check_lead, predict_field, predict_mask
from dyntarget.predict.forecast import plume_motion, two_look_motion
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
    lucas_kanade,
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
    "lucas_kanade",
    "plume_motion",
    "predict_field",
    "predict_mask",
    "two_look_motion",
    "wind_motion",
    "wind_to_pixels",
]
