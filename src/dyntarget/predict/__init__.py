"""Predictive targeting: how the plume moves, and where it will be.

Two looks (:func:`estimate_motion`, dense DIS optical flow) or a wind prior
(:func:`wind_motion`) give a :class:`Motion`; :func:`predict_mask` and
:func:`predict_field` carry the plume to any time after the current look
(detached clouds translate, attached plumes stretch from their vent). The
pipeline (:func:`dyntarget.pipeline.plan_scene` with ``prediction=``) plans on
the prediction. Method, assumptions and failure cases: ``docs/onboard.md``.
"""

from dyntarget.predict.advect import Prediction, check_lead, predict_field, predict_mask
from dyntarget.predict.motion import (
    CALM,
    LOW_CONFIDENCE,
    REGIMES,
    Motion,
    brightness,
    check_against_prior,
    check_interval,
    estimate_motion,
    wind_motion,
    wind_to_pixels,
)

__all__ = [
    "CALM",
    "LOW_CONFIDENCE",
    "REGIMES",
    "Motion",
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
