"""One task of a sweep: a problem with overrides, one planner, one row of results."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

from spm_opt.comparison import Outcome, run_planner
from spm_opt.planners import plan
from spm_opt.problem import load_problem
from spm_opt.trajectory import Trajectory


@dataclass(frozen=True)
class Task:
    """A planner on a problem whose values are overridden (see :func:`load_problem`).

    Attributes
    ----------
    key : str
        16 hex digits: the hash of the problem file's contents, the planner and the
        overrides; what makes a sweep resumable.
    sweep : str
    problem_path : str
        The base problem file (absolute).
    planner : str
    parameters : dict
        What the sweep varies, as people read it (``{"robot.friction.mu": 0.04}``,
        ``{"flap": 3, "flap_size_mm": 41.2}``).
    overrides : dict
        What :func:`load_problem` gets: the parameters' keys and values, and for a
        generated flap its landmarks and segment durations.
    anchor : dict or None
        The overrides of the neighbour whose plan warm-starts this one (the same cut with
        the swept values at the base problem's), for planners that take a warm start;
        None plans from the planner's own initial guess. Every worker plans the anchor
        from scratch once and keeps it, so a task's row does not depend on which worker
        ran it or what it ran before.
    """

    key: str
    sweep: str
    problem_path: str
    planner: str
    parameters: dict[str, Any] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)
    anchor: dict[str, Any] | None = None


def task_key(
    problem_sha256: str,
    planner: str,
    overrides: dict[str, Any],
    anchor: dict[str, Any] | None = None,
) -> str:
    """The task's identity: 16 hex digits of SHA-256 over what decides its result."""
    text = json.dumps([problem_sha256, planner, overrides, anchor], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def run_task(task: Task) -> dict[str, Any]:
    """Plan and evaluate one task; a failure (a bad override, an infeasible problem, a
    planner's error) is a row with status "failed" and the error, never an exception.

    The row: key, sweep, planner, parameters, then the comparison's columns
    (:data:`spm_opt.comparison.COLUMNS`: status, times, the evaluator's figures, the
    violations and the error; NaN where the planner failed).
    """
    try:
        problem = load_problem(task.problem_path, task.overrides)
    except Exception as error:  # noqa: BLE001 - an impossible combination is a row
        outcome = Outcome(task.planner, 0.0, error=f"{type(error).__name__}: {error}")
    else:
        warm_start = None
        if task.anchor is not None:
            warm_start = _anchor_plan(task.problem_path, task.planner, json.dumps(task.anchor))
        outcome = run_planner(problem, task.planner, warm_start)
    return {
        "key": task.key,
        "sweep": task.sweep,
        "planner": task.planner,
        "parameters": task.parameters,
        **outcome.row(),
    }


@lru_cache(maxsize=16)
def _anchor_plan(problem_path: str, planner: str, anchor: str) -> Trajectory | None:
    """The anchor's plan, from scratch, once per process (None if it cannot be planned)."""
    try:
        return plan(load_problem(problem_path, json.loads(anchor)), planner)
    except Exception:  # noqa: BLE001 - without an anchor the task starts cold
        return None
