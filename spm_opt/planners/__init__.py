"""Planners: one module per planner, one registry, one signature."""

from spm_opt.planners import cubic, ocp, ruckig, toppra
from spm_opt.planners.registry import PLANNERS, Planner, get_planner, plan, register

__all__ = [
    "PLANNERS",
    "Planner",
    "cubic",
    "get_planner",
    "ocp",
    "plan",
    "register",
    "ruckig",
    "toppra",
]
