"""spm_opt: plan, verify and execute trajectories for a spherical parallel manipulator
for brain surgery.

    import spm_opt as so
    problem = so.load_problem("problems/craniotomy_bone_flap.toml")
    trajectory = so.plan(problem, planner="cubic")
    report = so.evaluate(problem, trajectory)
    table = so.compare(problem)  # every planner, one row each (a pandas DataFrame)
    predicted = so.predict_cut(problem, trajectory)  # the closed-loop model's true cut
    compensated = so.compensate(problem, trajectory).plan  # corrected for what repeats
    slowed = so.slowed_for_breakaways(problem, trajectory).trajectory  # keeps the limits
    result = so.execute(trajectory, backend=so.SimulatedRobot(problem.robot,
                        start_rad=trajectory.position(0.0)), problem=problem, log="run.csv")

Each name is imported from its module when it is first used, so that importing the
package (and the ``spm-opt`` command, which lives in it) costs nothing until then.
"""

from __future__ import annotations

import importlib
import logging
from typing import TYPE_CHECKING, Any

from spm_opt.base.errors import (
    InputError,
    MissingDependency,
    PlanningError,
    SpmOptError,
    UnknownPlannerError,
    UnreachableError,
)

if TYPE_CHECKING:
    from spm_opt.cut.contour import Contour
    from spm_opt.execution import ExecutionSettings, SimulatedRobot, execute, read_log
    from spm_opt.judge.report import Report, Violation
    from spm_opt.model.dynamics import inverse_dynamics, mechanical_energy
    from spm_opt.model.params import Robot, load_robot
    from spm_opt.planners import PLANNERS, plan
    from spm_opt.problem.problem import Limits, Problem, load_problem
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.studies.comparison import compare
    from spm_opt.studies.sweep.results import load_sweep
    from spm_opt.verify.breakaway import slowed_for_breakaways
    from spm_opt.verify.compensation import compensate
    from spm_opt.verify.judgement import evaluate
    from spm_opt.verify.predicted_cut import predict_cut

_HOMES = {
    "compare": "spm_opt.studies.comparison",
    "Contour": "spm_opt.cut.contour",
    "Report": "spm_opt.judge.report",
    "Violation": "spm_opt.judge.report",
    "evaluate": "spm_opt.verify.judgement",
    "ExecutionSettings": "spm_opt.execution",
    "SimulatedRobot": "spm_opt.execution",
    "execute": "spm_opt.execution",
    "read_log": "spm_opt.execution",
    "inverse_dynamics": "spm_opt.model.dynamics",
    "mechanical_energy": "spm_opt.model.dynamics",
    "Robot": "spm_opt.model.params",
    "load_robot": "spm_opt.model.params",
    "PLANNERS": "spm_opt.planners",
    "plan": "spm_opt.planners",
    "Limits": "spm_opt.problem.problem",
    "Problem": "spm_opt.problem.problem",
    "load_problem": "spm_opt.problem.problem",
    "load_sweep": "spm_opt.studies.sweep.results",
    "predict_cut": "spm_opt.verify.predicted_cut",
    "compensate": "spm_opt.verify.compensation",
    "slowed_for_breakaways": "spm_opt.verify.breakaway",
    "Trajectory": "spm_opt.problem.trajectory",
}
"""The module each lazily imported name comes from."""


def __getattr__(name: str) -> Any:
    """Import a public name from its module on first use (PEP 562)."""
    if name == "__version__":
        from spm_opt.base.version import package_version

        return package_version()
    if name not in _HOMES:
        raise AttributeError(f"module 'spm_opt' has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_HOMES, "__version__"})


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
    "compensate",
    "evaluate",
    "execute",
    "inverse_dynamics",
    "mechanical_energy",
    "load_problem",
    "load_robot",
    "load_sweep",
    "plan",
    "slowed_for_breakaways",
    "predict_cut",
    "read_log",
]
