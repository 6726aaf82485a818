"""spm_opt: plan, verify and execute trajectories for a spherical parallel manipulator
for brain surgery.

    import spm_opt as so
    problem = so.load_problem("problems/craniotomy_bone_flap.toml")
    trajectory = so.plan(problem, planner="cubic")
    report = so.evaluate(problem, trajectory)
    table = so.compare(problem)  # every planner, one row each (a pandas DataFrame)
    result = so.execute(trajectory, backend=so.SimulatedRobot(problem.robot,
                        start_rad=trajectory.position(0.0)), problem=problem, log="run.csv")
"""

import logging

from spm_opt.comparison import compare
from spm_opt.contour import Contour
from spm_opt.errors import (
    InputError,
    MissingDependency,
    PlanningError,
    SpmOptError,
    UnknownPlannerError,
    UnreachableError,
)
from spm_opt.evaluate import Report, Violation, evaluate
from spm_opt.execution import ExecutionSettings, SimulatedRobot, execute, read_log
from spm_opt.model.dynamics import inverse_dynamics, mechanical_energy
from spm_opt.model.params import Robot, load_robot
from spm_opt.planners import PLANNERS, plan
from spm_opt.problem import Limits, Problem, load_problem
from spm_opt.sweep.results import load_sweep
from spm_opt.trajectory import Trajectory, package_version

__version__ = package_version()

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
    "PLANNERS",
    "Contour",
    "InputError",
    "Limits",
    "ExecutionSettings",
    "MissingDependency",
    "PlanningError",
    "Problem",
    "Report",
    "Robot",
    "SimulatedRobot",
    "SpmOptError",
    "Trajectory",
    "UnknownPlannerError",
    "UnreachableError",
    "Violation",
    "compare",
    "evaluate",
    "execute",
    "inverse_dynamics",
    "mechanical_energy",
    "load_problem",
    "load_robot",
    "load_sweep",
    "plan",
    "read_log",
]
