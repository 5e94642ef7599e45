"""Trajectory planning: planners (registry ``PLANNERS``) and the ``Trajectory``."""

from dyntarget.plan.planners import BASELINES, PAPER_PLANNERS, PLANNERS, PlanConfig, plan
from dyntarget.trajectory import Trajectory

__all__ = ["BASELINES", "PAPER_PLANNERS", "PLANNERS", "PlanConfig", "Trajectory", "plan"]
