"""Observation: the NFOV simulator and utility metrics."""

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
    "UtilityMaps",
    "observe",
    "observe_at",
    "observed_pixels",
    "pointing_truth",
]
