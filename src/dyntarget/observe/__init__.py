"""Observation: the NFOV simulator, utility metrics, the scores of a pass's pointings
(:func:`score_pointings`) and the true upper bound of a pass."""

from dyntarget.observe.bound import UpperBound, upper_bound_utility
from dyntarget.observe.nfov import (
    ObservationMetrics,
    observe,
    observe_at,
    observed_pixels,
    pointing_truth,
)
from dyntarget.observe.pointings import PointingScores, Sight, score_pointings
from dyntarget.utility import UtilityMaps  # a core type, scored against here

__all__ = [
    "ObservationMetrics",
    "PointingScores",
    "Sight",
    "UpperBound",
    "UtilityMaps",
    "observe",
    "observe_at",
    "observed_pixels",
    "pointing_truth",
    "score_pointings",
    "upper_bound_utility",
]
