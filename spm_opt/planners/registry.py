"""The registry of planners: one signature, looked up by name."""

from __future__ import annotations

import dataclasses
import inspect
import math
import time
from typing import Any, Protocol, TypeVar

from spm_opt.base.errors import InputError, PlanningError, UnknownPlannerError
from spm_opt.base.fields import closest
from spm_opt.base.input_limits import excerpt
from spm_opt.base.version import package_version
from spm_opt.judge.depth import depth_setpoint
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory


class Planner(Protocol):
    """Turns a :class:`Problem` into a :class:`Trajectory`; never reports metrics.

    A planner whose plans do not cut the problem's contour (an excitation for
    identification) says so with a class attribute ``cuts_contour = False``."""

    name: str

    def plan(self, problem: Problem) -> Trajectory:
        """A trajectory for ``problem``, or PlanningError (InputError for bad options)."""


MAX_PLAN_DURATION_S = 3600.0
"""Longest plan accepted, s: a cut of an hour means a limit in the wrong units, and
evaluating it at 1 kHz would take gigabytes."""

PLANNERS: dict[str, Planner] = {}
"""Every registered planner by name."""


def register(planner: Planner) -> Planner:
    """Add a planner to :data:`PLANNERS` under its name."""
    PLANNERS[planner.name] = planner
    return planner


def get_planner(name: str) -> Planner:
    """The planner called ``name``, or an error suggesting the closest known name (a typo
    of it) and listing them all."""
    try:
        return PLANNERS[name]
    except KeyError:
        close = closest(name, sorted(PLANNERS)) if isinstance(name, str) else None
        hint = "" if close is None else f" (did you mean {close!r}?)"
        raise UnknownPlannerError(
            f"planner = {name!r}: unknown{hint}; expected one of {', '.join(sorted(PLANNERS))}"
        ) from None


def contour_planners() -> list[str]:
    """The names of the registered planners that plan the problem's cut, sorted."""
    return sorted(name for name, p in PLANNERS.items() if getattr(p, "cuts_contour", True))


def planner_options(problem: Problem, name: str, allowed: tuple[str, ...] = ()) -> dict:
    """The problem's ``[planner.NAME]`` table, refusing keys the planner does not know."""
    options = problem.planner_options.get(name, {})
    for key in options:
        if key not in allowed:
            where = f"{problem.source}: " if problem.source else ""
            known = ", ".join(allowed) or "none"
            raise InputError(f"{where}planner.{name}.{key}: unknown key (allowed: {known})")
    return options


Settings = TypeVar("Settings")


def settings_from_options(
    planner: str,
    defaults: Settings,
    options: dict[str, Any],
    ranges: dict[str, tuple[float, float]],
    choices: dict[str, tuple[str, ...]] | None = None,
) -> Settings:
    """``defaults`` (a frozen dataclass) with the values of a ``[planner.NAME]`` table: each
    one of its ``choices``, or a finite number in its range (an integer where the default
    is one); a one-line InputError naming the key and what is allowed otherwise."""
    values: dict[str, Any] = {}
    for key, value in options.items():
        where = f"planner.{planner}.{key} = {excerpt(value)}"
        if choices and key in choices:
            if value not in choices[key]:
                raise InputError(f"{where}: expected one of {', '.join(choices[key])}")
            values[key] = value
            continue
        low, high = ranges[key]
        integer = isinstance(getattr(defaults, key), int)
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not (math.isfinite(value) and low <= value <= high)
            or (integer and value != int(value))
        ):
            kind = "an integer" if integer else "a number"
            raise InputError(f"{where}: expected {kind} in [{low:g}, {high:g}]")
        values[key] = int(value) if integer else float(value)
    return dataclasses.replace(defaults, **values)  # type: ignore[type-var]


def takes_warm_start(planner: str) -> bool:
    """Whether the planner called ``planner`` starts from a given plan when offered one."""
    return "warm_start" in inspect.signature(get_planner(planner).plan).parameters


def plan(
    problem: Problem, planner: str = "cubic", warm_start: Trajectory | None = None
) -> Trajectory:
    """Plan ``problem`` with the planner called ``planner`` (any name in PLANNERS).

    ``warm_start``, a plan of a similar problem, is handed to planners that take one
    (:func:`takes_warm_start`) and ignored by the others. The trajectory's metadata records
    the planner, the problem (:meth:`Problem.record`), the package version and the planner's
    statistics, with its solve time in s.
    """
    chosen = get_planner(planner)
    start = time.perf_counter()
    if warm_start is not None and takes_warm_start(planner):
        trajectory = chosen.plan(problem, warm_start=warm_start)  # type: ignore[call-arg]
    else:
        trajectory = chosen.plan(problem)
    elapsed = time.perf_counter() - start
    if trajectory.duration > MAX_PLAN_DURATION_S:
        raise PlanningError(
            f"{chosen.name}: the plan lasts {trajectory.duration:.4g} s, more than "
            f"{MAX_PLAN_DURATION_S:g} s; are the limits in their units?"
        )
    statistics = dict(trajectory.metadata.get("statistics", {}))
    statistics.setdefault("solve_time_s", elapsed)
    trajectory.metadata.update(
        planner=chosen.name,
        problem=problem.record(),
        statistics=statistics,
        spm_opt_version=package_version(),
    )
    if problem.inner_radius is not None:
        margin = problem.skull.depth_margin
        trajectory.metadata["depth_setpoint"] = depth_setpoint(
            problem.inner_radius, margin, trajectory
        )
    return trajectory
