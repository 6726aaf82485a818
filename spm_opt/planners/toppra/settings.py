"""The toppra planner's settings, read from the problem's ``[planner.toppra]`` table."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from spm_opt.planners.registry import planner_options, settings_from_options
from spm_opt.problem.problem import Problem

NAME = "toppra"
"""The planner's name, and its table's: ``[planner.toppra]``."""


@dataclass(frozen=True)
class ToppraSettings:
    """Discretisation settings, read from the problem's ``[planner.toppra]`` table.

    Attributes
    ----------
    gridpoints : int
        toppra's gridpoints per segment (clustered at the segment's ends).
    path_samples : int
        Inverse-kinematics samples per segment through which the joint-space spline runs.
    margin : float
        Fraction of the acceleration, torque and jerk limits kept in reserve for what the
        moving average and the gridding change.
    time_step_s : float
        Step of the uniform time grid on which the path acceleration is piecewise constant
        and the trajectory is sampled, s; the moving-average window is a whole number of
        steps.
    min_smoothing_s : float
        Shortest moving-average window, s: the only smoothing when jerk is not limited (a
        step in s̈ would be a step in the joint acceleration).
    """

    gridpoints: int = 800
    path_samples: int = 100
    margin: float = 0.01
    time_step_s: float = 0.005
    min_smoothing_s: float = 0.01

    _RANGES = {
        "gridpoints": (10, 100_000),
        "path_samples": (4, 100_000),
        "margin": (0.0, 0.5),
        "time_step_s": (1e-4, 0.1),
        "min_smoothing_s": (1e-4, 10.0),
    }

    @classmethod
    def from_options(cls, options: dict[str, Any]) -> ToppraSettings:
        """Settings from a ``[planner.toppra]`` table over the defaults; one-line errors."""
        return settings_from_options(NAME, cls(), options, cls._RANGES)


OPTION_KEYS = tuple(f.name for f in dataclasses.fields(ToppraSettings))


def toppra_settings(problem: Problem) -> ToppraSettings:
    """The problem's ``[planner.toppra]`` settings over the defaults."""
    return ToppraSettings.from_options(planner_options(problem, NAME, OPTION_KEYS))
