"""Trajectory planning: planners (registry ``PLANNERS``) and the ``Trajectory``."""

from dyntarget.plan.planners import (
    BASELINES,
    KINEMATIC_PLANNERS,
    PAPER_PLANNERS,
    PLANNERS,
    PlanConfig,
    PlanContext,
    geometric_planners,
    plan,
)
from dyntarget.trajectory import Trajectory

__all__ = [
    "BASELINES",
    "KINEMATIC_PLANNERS",
    "PAPER_PLANNERS",
    "PLANNERS",
    "PlanConfig",
    "PlanContext",
    "Trajectory",
    "geometric_planners",
    "plan",
]
