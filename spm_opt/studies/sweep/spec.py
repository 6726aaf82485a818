"""Sweep specifications: a base problem, planners, and the axes to vary (TOML).

    name = "friction_payload"
    problem = "../craniotomy_bone_flap.toml"          # relative to this file
    planners = ["cubic", "toppra", "ocp-min-time"]

    [grid]                                            # every combination of the lists
    "robot.friction.mu" = [0.0025, 0.04, 0.24]
    "robot.payload.mass_kg" = [0.0, 0.25, 0.5]

    [random]                                          # samples drawn uniformly, seeded
    samples = 20
    seed = 1
    [random.ranges]
    "limits.max_tool_speed_mm_s" = [2.0, 6.0]

    [flaps]                                           # generated bone flaps, seeded
    count = 200
    seed = 7
    size_mm = [20.0, 50.0]
    landmarks = 4                                     # or [low, high], drawn per flap
    tool_speed_mm_s = 2.0                             # sets each flap's segment durations
    contour_tolerance_mm = [0.05, 0.2]                # optional: drawn per flap
    max_tool_speed_mm_s = [2.0, 4.0]                  # optional: drawn per flap

Keys are those of the problem file, in its units, with ``robot.`` before the robot file's
(see :func:`spm_opt.problem.problem.load_problem`). The tasks are every grid combination × every
random sample × every flap × every planner; more than ``max_tasks`` of them
(:data:`DEFAULT_MAX_TASKS` unless the caller allows more) are refused, counted before any
is made. Every axis is checked when the file is read: an unknown key, an empty axis, a
value the problem would refuse or a bad range is a one-line error naming it.

``[flaps]`` (:func:`spm_opt.studies.sweep.flaps.random_flaps`): ``landmarks`` is a count of 3 to
12, or an inclusive range of them each flap draws its count from; ``contour_tolerance_mm``
and ``max_tool_speed_mm_s``, ranges ``[low, high]`` with ``0 < low <= high``, draw each
flap's ``limits.`` value (the tolerance log-uniformly), which may then not be an axis of
``[grid]`` or ``[random]``. Each flap's segment durations give a mean tool speed of
``tool_speed_mm_s``, at most 2/3 of a drawn tool-speed limit
(:data:`~spm_opt.studies.sweep.flaps.DURATION_SPEED_FRACTION`). A task's parameters hold the flap's
index (``flap``), its size (``flap_size_mm``) and every drawn value: ``flap_landmarks``,
``limits.contour_tolerance_mm``, ``limits.max_tool_speed_mm_s``. The seed draws the same
flaps whichever of these keys are given.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.base.choices import DEFAULT_MAX_TASKS
from spm_opt.base.errors import InputError
from spm_opt.base.fields import Table, closest, read_toml
from spm_opt.base.input_limits import excerpt
from spm_opt.planners import PLANNERS
from spm_opt.planners.registry import takes_warm_start
from spm_opt.problem.problem import Problem, load_problem
from spm_opt.studies.sweep.task import ProblemFiles, Task, code_identity, task_key


@dataclass(frozen=True)
class RandomAxes:
    """``samples`` draws of every key, uniform in its (low, high) range, from ``seed``."""

    samples: int
    seed: int
    ranges: dict[str, tuple[float, float]]

    def draws(self) -> list[dict[str, float]]:
        rng = np.random.default_rng(self.seed)
        return [
            {key: float(rng.uniform(low, high)) for key, (low, high) in self.ranges.items()}
            for _ in range(self.samples)
        ]


FLAP_LIMITS = {
    "contour_tolerance_mm": "limits.contour_tolerance_mm",
    "max_tool_speed_mm_s": "limits.max_tool_speed_mm_s",
}
"""The ``[flaps]`` keys that draw a limit per flap, and the problem's key each sets."""
LANDMARKS = (3, 12)
"""The fewest and the most landmarks a ``[flaps]`` table may ask for."""


@dataclass(frozen=True)
class FlapAxis:
    """``count`` random bone flaps (:func:`spm_opt.studies.sweep.flaps.random_flaps`): sizes in mm,
    mean tool speed in mm/s, the ranges of the drawn limits in mm and mm/s (None: the base
    problem's limit)."""

    count: int
    seed: int
    size_range_mm: tuple[float, float]
    landmarks: int | tuple[int, int]
    tool_speed_mm_s: float
    contour_tolerance_mm: tuple[float, float] | None = None
    max_tool_speed_mm_s: tuple[float, float] | None = None

    def sets(self, problem: Problem) -> list[tuple[dict[str, Any], dict[str, Any]]]:
        """Per flap, (parameters, overrides): its index, size and drawn values (see the
        module's docstring); its landmarks, segment durations and drawn limits."""
        from spm_opt.studies.sweep.flaps import random_flaps

        flaps = random_flaps(
            problem,
            self.count,
            self.size_range_mm,
            self.landmarks,
            self.seed,
            contour_tolerance_mm=self.contour_tolerance_mm,
            max_tool_speed_mm_s=self.max_tool_speed_mm_s,
        )
        sets = []
        for index, flap in enumerate(flaps):
            parameters: dict[str, Any] = {"flap": index, "flap_size_mm": flap.size_mm}
            if isinstance(self.landmarks, tuple):
                parameters["flap_landmarks"] = len(flap.names)
            durations = flap.segment_durations_s(flap.mean_speed_mm_s(self.tool_speed_mm_s))
            overrides = {"landmarks": flap.landmark_overrides(), "segment_durations_s": durations}
            limits = flap.limit_overrides()
            sets.append(({**parameters, **limits}, {**overrides, **limits}))
        return sets


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep specification; :meth:`tasks` expands it into at most
    ``max_tasks`` tasks (:data:`DEFAULT_MAX_TASKS` unless its caller allows more)."""

    name: str
    description: str
    problem_path: Path
    planners: tuple[str, ...]
    grid: dict[str, list[Any]]
    random: RandomAxes | None
    flaps: FlapAxis | None
    source: Path
    max_tasks: int = DEFAULT_MAX_TASKS

    @property
    def task_count(self) -> int:
        """How many tasks :meth:`tasks` makes: grid points × random samples × flaps ×
        planners."""
        return self._grid_points * self._samples * self._flap_count * len(self.planners)

    @property
    def _grid_points(self) -> int:
        return math.prod(len(values) for values in self.grid.values())

    @property
    def _samples(self) -> int:
        return self.random.samples if self.random else 1

    @property
    def _flap_count(self) -> int:
        return self.flaps.count if self.flaps else 1

    def check_size(self) -> None:
        """Refuse a sweep of more than ``max_tasks`` tasks, before any is made."""
        count = self.task_count
        if count <= self.max_tasks:
            return
        sizes = {
            "grid points": self._grid_points,
            "random samples": self._samples,
            "flaps": self._flap_count,
            "planners": len(self.planners),
        }
        factors = " x ".join(f"{size:,} {what}" for what, size in sizes.items() if size > 1)
        raise InputError(
            f"{self.source}: {count:,} tasks ({factors}); expected at most {self.max_tasks:,} "
            "(spm-opt sweep --max-tasks raises the limit)"
        )

    def parameter_sets(
        self, problem: Problem
    ) -> list[tuple[dict[str, Any], dict[str, Any], dict[str, Any]]]:
        """Every (parameters, overrides, anchor) in a fixed order; the anchor is the same
        cut with the swept values at the base problem's (the flap's overrides alone)."""
        keys = list(self.grid)
        grid = [
            dict(zip(keys, values, strict=True))
            for values in itertools.product(*(self.grid[key] for key in keys))
        ]
        draws = self.random.draws() if self.random else [{}]
        flaps = self.flaps.sets(problem) if self.flaps else [({}, {})]
        sets = []
        for point, draw, (flap_parameters, flap_overrides) in itertools.product(grid, draws, flaps):
            parameters = {**point, **draw, **flap_parameters}
            sets.append((parameters, {**point, **draw, **flap_overrides}, flap_overrides))
        return sets

    def tasks(self) -> list[Task]:
        """Every task of the sweep: each parameter set with each planner; a planner that
        takes a warm start starts from the plan of the task's anchor (see :class:`Task`).
        Each task carries the problem's files (their contents) and this process's code.
        A sweep of more than ``max_tasks`` tasks is refused before any is made."""
        self.check_size()
        files = ProblemFiles.read(self.problem_path)
        code = code_identity()
        tasks = []
        for parameters, overrides, cut in self.parameter_sets(load_problem(self.problem_path)):
            for planner in self.planners:
                anchor = cut if takes_warm_start(planner) and overrides != cut else None
                tasks.append(
                    Task(
                        key=task_key(files.sha256, planner, overrides, anchor, code=code),
                        sweep=self.name,
                        problem=files,
                        planner=planner,
                        code=code,
                        parameters=parameters,
                        overrides=overrides,
                        anchor=anchor,
                    )
                )
        return tasks


def load_sweep_spec(path: str | Path, max_tasks: int = DEFAULT_MAX_TASKS) -> SweepSpec:
    """Read and validate a sweep specification (see the module's docstring); one of more
    than ``max_tasks`` tasks is refused, before its grid's values are each checked."""
    path = Path(path)
    if isinstance(max_tasks, bool) or not isinstance(max_tasks, int) or max_tasks < 1:
        raise InputError(f"max_tasks = {excerpt(max_tasks)}: expected a whole number >= 1")
    root = Table(read_toml(path), str(path))
    name = root.string("name")
    description = root.string("description", default="")
    problem_key = root.string("problem")
    problem_path = (path.parent / problem_key).resolve()
    if not problem_path.is_file():
        raise root.error("problem", problem_key, f"no problem file at {problem_path}")
    load_problem(problem_path)  # the base problem itself must be valid
    ProblemFiles.read(problem_path)  # and its robot file's path relative to it
    planners = root.raw("planners")
    if (
        not isinstance(planners, list)
        or not planners
        or not all(isinstance(p, str) and p in PLANNERS for p in planners)
    ):
        names = planners if isinstance(planners, list) else []
        unknown = next((p for p in names if isinstance(p, str) and p not in PLANNERS), "")
        close = closest(unknown, sorted(PLANNERS))
        hint = "" if close is None else f" ({unknown!r}: did you mean {close!r}?)"
        raise root.error(
            "planners",
            planners,
            f"expected a non-empty list of {', '.join(sorted(PLANNERS))}{hint}",
        )
    twice = next((name for i, name in enumerate(planners) if name in planners[:i]), None)
    if twice is not None:
        raise root.error("planners", planners, f"expected each planner once ({twice} twice)")
    grid_table = root.table("grid", required=False)
    grid = _grid(grid_table)
    random = _random(root.table("random", required=False), problem_path, grid)
    axes = {*grid, *(random.ranges if random else {})}
    flaps = _flaps(root.table("flaps", required=False), axes)
    root.finish()
    spec = SweepSpec(
        name, description, problem_path, tuple(planners), grid, random, flaps, path, max_tasks
    )
    spec.check_size()
    for key, values in grid.items():
        for value in values:
            _check_value(grid_table, key, value, problem_path)
    return spec


def _check_value(table: Table, key: str, value: Any, problem_path: Path) -> None:
    """The base problem with this one value must load: unknown keys and bad values fail;
    the robot file is not an axis (a task carries the base problem's robot file)."""
    if key == "robot":
        raise table.error(key, value, "the robot file cannot be swept; sweep its values, robot.KEY")
    try:
        load_problem(problem_path, {key: value})
    except InputError as error:
        raise InputError(f"{table.name(key)} = {excerpt(value)}: {error}") from None


def _grid(table: Table) -> dict[str, list[Any]]:
    """The ``[grid]`` table's axes, each a non-empty list of distinct values: numbers
    equal in value are one value, so ``[2, 2.0]`` is refused like ``[2, 2]`` (a problem
    reads both as 2.0, and the sweep would run that one problem twice). The values
    themselves are checked once the sweep's size is: :func:`_check_value`."""
    grid = {}
    for key in table.keys():
        values = table.raw(key)
        if not isinstance(values, list) or not values:
            raise table.error(key, values, "expected a non-empty list of values (an axis)")
        seen: dict[Any, Any] = {}
        for index, value in enumerate(values):
            first = values[seen.setdefault(_compared(value), index)]
            if seen[_compared(value)] != index:
                same = repr(first) == repr(value)
                again = (
                    f"{excerpt(value)} twice"
                    if same
                    else f"{excerpt(first)} and {excerpt(value)} are one value"
                )
                raise table.error(key, values, f"expected each value once ({again})")
        grid[key] = values
    table.finish()
    return grid


def _compared(value: Any) -> Any:
    """A grid value as repeats are found: numbers by value (2 and 2.0 are one; true is
    not 1), lists and tables item by item, anything else as it is."""
    if isinstance(value, bool):
        return ("boolean", value)
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, list):
        return tuple(_compared(item) for item in value)
    if isinstance(value, dict):
        return tuple(sorted((key, _compared(item)) for key, item in value.items()))
    return value


def _random(table: Table, problem_path: Path, grid: dict[str, list[Any]]) -> RandomAxes | None:
    if not table.keys():
        return None
    samples = _integer(table, "samples", 1, 100_000)
    seed = _integer(table, "seed", 0, 2**32 - 1, default=0)
    ranges_table = table.table("ranges")
    ranges = {}
    for key in ranges_table.keys():
        low, high = ranges_table.vector(key, length=2)
        if not low < high:
            raise ranges_table.error(key, [low, high], "expected [low, high] with low < high")
        if key in grid:
            raise ranges_table.error(key, [low, high], "already an axis of [grid]")
        for value in (low, high):
            _check_value(ranges_table, key, value, problem_path)
        ranges[key] = (float(low), float(high))
    if not ranges:
        raise table.error("ranges", {}, "expected at least one key = [low, high]")
    ranges_table.finish()
    table.finish()
    return RandomAxes(samples, seed, ranges)


def _flaps(table: Table, axes: set[str]) -> FlapAxis | None:
    """The ``[flaps]`` table; ``axes`` are the keys ``[grid]`` and ``[random]`` sweep."""
    if not table.keys():
        return None
    count = _integer(table, "count", 1, 100_000)
    seed = _integer(table, "seed", 0, 2**32 - 1, default=0)
    size_range = _range(table, "size_mm")
    landmarks = _landmarks(table)
    speed = table.number("tool_speed_mm_s", default=2.0, minimum=0.0, exclusive_minimum=True)
    limits: dict[str, tuple[float, float] | None] = {}
    for key, problem_key in FLAP_LIMITS.items():
        limits[key] = _range(table, key, required=False)
        if limits[key] is not None and problem_key in axes:
            raise table.error(
                key, list(limits[key]), f"{problem_key} is already an axis of [grid] or [random]"
            )
    table.finish()
    return FlapAxis(count, seed, size_range, landmarks, float(speed), **limits)


def _range(table: Table, key: str, required: bool = True) -> tuple[float, float] | None:
    """``key = [low, high]``, both positive, ``low <= high``; None if absent and not
    ``required`` (the key still taken: an unknown key's error suggests it)."""
    if not required and table.raw(key, default=None) is None:
        return None
    low, high = (float(v) for v in table.vector(key, length=2, minimum=0.0, exclusive_minimum=True))
    if not low <= high:
        raise table.error(key, [low, high], "expected [low, high] with low <= high")
    return low, high


def _landmarks(table: Table) -> int | tuple[int, int]:
    """``landmarks``: a count in :data:`LANDMARKS` (default 4), or ``[low, high]`` of them."""
    value = table.raw("landmarks", default=4)
    bounds = value if isinstance(value, list) else [value, value]
    fewest, most = LANDMARKS
    whole = all(
        isinstance(v, int | float) and not isinstance(v, bool) and float(v).is_integer()
        for v in bounds
    )
    if len(bounds) != 2 or not whole or not fewest <= bounds[0] <= bounds[1] <= most:
        raise table.error(
            "landmarks",
            value,
            f"expected a whole number in [{fewest}, {most}], or [low, high] of them with "
            "low <= high",
        )
    low, high = int(bounds[0]), int(bounds[1])
    return (low, high) if isinstance(value, list) else low


def _integer(table: Table, key: str, low: int, high: int, default: int | None = None) -> int:
    value = table.number(
        key, minimum=low, maximum=high, **({} if default is None else {"default": default})
    )
    if value != int(value):
        raise table.error(key, value, f"expected a whole number in [{low}, {high}]")
    return int(value)
