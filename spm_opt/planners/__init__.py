"""Planners: one module per planner, one registry, one signature."""

from spm_opt.planners import cubic, excitation, ocp, ruckig, toppra
from spm_opt.planners.registry import (
    PLANNERS,
    Planner,
    contour_planners,
    get_planner,
    plan,
    register,
)

__all__ = [
    "PLANNERS",
    "Planner",
    "contour_planners",
    "cubic",
    "excitation",
    "get_planner",
    "ocp",
    "plan",
    "register",
    "ruckig",
    "toppra",
]
