"""The registry of planners: one signature, looked up by name."""

from __future__ import annotations

import time
from typing import Protocol

from spm_opt.errors import InputError, UnknownPlannerError
from spm_opt.problem import Problem
from spm_opt.trajectory import Trajectory, package_version


class Planner(Protocol):
    """Turns a :class:`Problem` into a :class:`Trajectory`; never reports metrics."""

    name: str

    def plan(self, problem: Problem) -> Trajectory: ...


PLANNERS: dict[str, Planner] = {}
"""Every registered planner by name."""


def register(planner: Planner) -> Planner:
    """Add a planner to :data:`PLANNERS` under its name."""
    PLANNERS[planner.name] = planner
    return planner


def get_planner(name: str) -> Planner:
    """The planner called ``name``, or an error listing the known names."""
    try:
        return PLANNERS[name]
    except KeyError:
        raise UnknownPlannerError(
            f"planner = {name!r}: unknown; expected one of {', '.join(sorted(PLANNERS))}"
        ) from None


def planner_options(problem: Problem, name: str, allowed: tuple[str, ...] = ()) -> dict:
    """The problem's ``[planner.NAME]`` table, refusing keys the planner does not know."""
    options = problem.planner_options.get(name, {})
    for key in options:
        if key not in allowed:
            where = f"{problem.source}: " if problem.source else ""
            known = ", ".join(allowed) or "none"
            raise InputError(f"{where}planner.{name}.{key}: unknown key (allowed: {known})")
    return options


def plan(problem: Problem, planner: str = "cubic") -> Trajectory:
    """Plan ``problem`` with the planner called ``planner`` (any name in PLANNERS).

    The trajectory's metadata records the planner, the problem (file and hash), the
    package version and the planner's statistics, with its solve time in s.
    """
    chosen = get_planner(planner)
    start = time.perf_counter()
    trajectory = chosen.plan(problem)
    elapsed = time.perf_counter() - start
    statistics = dict(trajectory.metadata.get("statistics", {}))
    statistics.setdefault("solve_time_s", elapsed)
    trajectory.metadata.update(
        planner=chosen.name,
        problem={
            "name": problem.name,
            "file": None if problem.source is None else str(problem.source),
            "sha256": problem.source_sha256,
        },
        statistics=statistics,
        spm_opt_version=package_version(),
    )
    return trajectory
