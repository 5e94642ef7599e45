"""Trajectory planning: planners (registry ``PLANNERS``) and the ``Trajectory``."""

from dyntarget.plan.planners import BASELINES, PLANNERS, PlanConfig, plan
from dyntarget.plan.trajectory import Trajectory

__all__ = ["BASELINES", "PLANNERS", "PlanConfig", "Trajectory", "plan"]
