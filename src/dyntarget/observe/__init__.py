"""Observation: the NFOV simulator, utility metrics, and the true upper bound of a pass."""

from dyntarget.observe.bound import UpperBound, upper_bound_utility
from dyntarget.observe.nfov import (
    ObservationMetrics,
    UtilityMaps,
    observe,
    observe_at,
    observed_pixels,
    pointing_truth,
)

__all__ = [
    "ObservationMetrics",
    "UpperBound",
    "UtilityMaps",
    "observe",
    "observe_at",
    "observed_pixels",
    "pointing_truth",
    "upper_bound_utility",
]
