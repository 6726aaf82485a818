"""One task of a sweep: a problem with overrides, one planner, one row of results.

A task carries its problem and robot files' contents, not their paths: a worker on
another machine, with none of the files, writes them into a private temporary directory
(in the same relative layout) and loads the problem from there. Its key hashes those
contents, the planner, the overrides, the warm start's anchor and the code (the package's
version and a hash of its own source files), so that a sweep resumed after any of them
changed computes its rows again.

A failed row says whose failure it is: ``failure`` is :data:`MACHINE` for the machine's
(a worker killed, a lost connection, a timeout, out of memory: run again, it may succeed)
and :data:`RESULT` for the problem's (a :class:`~spm_opt.base.errors.PlanningError`, an
:class:`~spm_opt.base.errors.InputError`, any other error of the code: the same again).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from collections.abc import Iterator
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cache, lru_cache
from pathlib import Path
from typing import Any

from spm_opt.base.errors import InputError
from spm_opt.base.fields import parse_toml
from spm_opt.base.input_limits import MAX_TOML_BYTES, decode_text, excerpt, read_bytes
from spm_opt.base.version import package_version
from spm_opt.planners import plan
from spm_opt.problem.problem import load_problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.studies.comparison import Outcome, run_planner

MACHINE = "machine"
"""``failure`` of a row that failed for the machine's reasons: retried on resume."""
RESULT = "result"
"""``failure`` of a row that failed for the problem's reasons: a result, kept."""
_MACHINE_ERRORS = (OSError, MemoryError, BrokenProcessPool)  # OSError: TimeoutError too
_MACHINE_ERROR_NAMES = frozenset({"KilledWorker"})  # distributed's, named: it is optional


def failure_kind(error: BaseException) -> str:
    """:data:`MACHINE` for an error of the machine (an ``OSError``, ``TimeoutError``,
    ``MemoryError``, a dead worker: ``BrokenProcessPool``, Dask's ``KilledWorker``), else
    :data:`RESULT`."""
    names = {kind.__name__ for kind in type(error).__mro__}
    if isinstance(error, _MACHINE_ERRORS) or names & _MACHINE_ERROR_NAMES:
        return MACHINE
    return RESULT


@dataclass(frozen=True)
class ProblemFiles:
    """A problem file and its robot file, as text: what a worker needs to load the problem.

    Attributes
    ----------
    path : str
        Where the runner read the problem file (absolute): its name and, in error
        messages, its directory; never read by a worker.
    text : str
        The problem file's contents.
    robot : str
        The robot file's path as the problem file gives it, relative to the problem file.
    robot_text : str
        The robot file's contents.
    """

    path: str
    text: str
    robot: str
    robot_text: str

    def __post_init__(self) -> None:
        if Path(self.robot).is_absolute():
            raise InputError(
                f"{self.path}: robot = {excerpt(self.robot)}: a sweep needs the robot file's path "
                "relative to the problem file (its workers get both files' contents)"
            )

    @classmethod
    def read(cls, path: str | Path) -> ProblemFiles:
        """Read a (valid) problem file and the robot file it names."""
        path = Path(path).absolute()
        text = _read_text(path)
        robot = parse_toml(text, str(path)).get("robot")
        if not isinstance(robot, str):
            raise InputError(f"{path}: robot = {excerpt(robot)}: expected the robot file's path")
        return cls(str(path), text, robot, _read_text(path.parent / robot))

    @property
    def sha256(self) -> str:
        """SHA-256 of both files' contents."""
        return hashlib.sha256(json.dumps([self.text, self.robot_text]).encode()).hexdigest()

    def write(self, directory: Path) -> Path:
        """Write both files under ``directory``, the robot file where the problem file's
        relative path puts it (the problem file as deep as the path's leading ".." need);
        returns the problem file's path."""
        ups = 0
        for part in Path(os.path.normpath(self.robot)).parts:
            if part != "..":
                break
            ups += 1
        problem = directory.joinpath(*["up"] * ups, Path(self.path).name)
        problem.parent.mkdir(parents=True, exist_ok=True)
        problem.write_bytes(self.text.encode("utf-8"))
        robot = problem.parent / self.robot
        robot.parent.mkdir(parents=True, exist_ok=True)
        robot.write_bytes(self.robot_text.encode("utf-8"))
        return problem

    @contextmanager
    def written(self) -> Iterator[Path]:
        """The problem file's path in a private temporary directory, removed on exit."""
        with tempfile.TemporaryDirectory(prefix="spm-opt-task-") as scratch:
            yield self.write(Path(scratch))


def _read_text(path: Path) -> str:
    """The text of a TOML file of at most :data:`~spm_opt.base.input_limits.MAX_TOML_BYTES`."""
    return decode_text(read_bytes(path, "a TOML file", MAX_TOML_BYTES), path, "a TOML file")


def source_sha256(root: Path) -> str:
    """SHA-256 over every ``*.py`` file under ``root``: their relative paths and contents."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(f"{path.relative_to(root).as_posix()}\n".encode())
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


@cache
def code_identity() -> str:
    """This process's spm_opt: its version and 16 hex digits of :func:`source_sha256` of
    the package's own source files (read once per process), ``0.1.0+3f2a9c...``."""
    return f"{package_version()}+{source_sha256(Path(__file__).resolve().parents[1])[:16]}"


@dataclass(frozen=True)
class Task:
    """A planner on a problem whose values are overridden (see :func:`load_problem`).

    Attributes
    ----------
    key : str
        16 hex digits (:func:`task_key`): what makes a sweep resumable.
    sweep : str
    problem : ProblemFiles
        The base problem's files, contents included.
    planner : str
    code : str
        The :func:`code_identity` the key was made with; a worker with other code refuses
        the task (a failed row, :data:`MACHINE`).
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
    problem: ProblemFiles
    planner: str
    code: str
    parameters: dict[str, Any] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)
    anchor: dict[str, Any] | None = None


def task_key(
    problem_sha256: str,
    planner: str,
    overrides: dict[str, Any],
    anchor: dict[str, Any] | None = None,
    *,
    code: str,
) -> str:
    """The task's identity: 16 hex digits of SHA-256 over what decides its result (the
    files' :attr:`ProblemFiles.sha256`, the planner, the overrides, the anchor and the
    :func:`code_identity`)."""
    text = json.dumps([problem_sha256, planner, overrides, anchor, code], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def run_task(task: Task) -> dict[str, Any]:
    """Plan and evaluate one task; a failure (a bad override, an infeasible problem, a
    planner's error, other code on this worker) is a row with status "failed", the error
    and its ``failure`` kind, never an exception.

    The row: key, sweep, planner, parameters, then the comparison's columns
    (:data:`spm_opt.studies.comparison.COLUMNS`: status, times, the evaluator's figures, the
    violations and the error; NaN where the planner failed), and ``failure`` if it failed.
    """
    if task.code != code_identity():
        error = f"this worker runs spm_opt {code_identity()}, the task was made by {task.code}"
        outcome, failure = Outcome(task.planner, 0.0, error=error), MACHINE
    else:
        with task.problem.written() as path:
            outcome, failure = _outcome(task, path)
    row = {
        "key": task.key,
        "sweep": task.sweep,
        "planner": task.planner,
        "parameters": task.parameters,
        **outcome.row(),
    }
    if row["status"] == "failed":
        row["failure"] = failure
    return row


def _outcome(task: Task, path: Path) -> tuple[Outcome, str]:
    """The task's outcome with its problem file at ``path``, and its failure's kind (error
    messages name the runner's directory, not this worker's temporary one)."""
    try:
        problem = load_problem(path, task.overrides)
    except Exception as error:  # noqa: BLE001 - an impossible combination is a row
        outcome = Outcome(task.planner, 0.0, error=f"{type(error).__name__}: {error}")
        kind = failure_kind(error)
    else:
        warm_start = None
        if task.anchor is not None:
            warm_start = _anchor_plan(task.problem, task.planner, json.dumps(task.anchor))
        outcome = run_planner(problem, task.planner, warm_start)
        kind = RESULT if outcome.exception is None else failure_kind(outcome.exception)
    if outcome.error is not None:
        here, there = str(path.parent), str(Path(task.problem.path).parent)
        outcome = dataclasses.replace(outcome, error=outcome.error.replace(here, there))
    return outcome, kind


@lru_cache(maxsize=16)
def _anchor_plan(files: ProblemFiles, planner: str, anchor: str) -> Trajectory | None:
    """The anchor's plan, from scratch, once per process and files' contents (None if it
    cannot be planned)."""
    try:
        with files.written() as path:
            return plan(load_problem(path, json.loads(anchor)), planner)
    except Exception:  # noqa: BLE001 - without an anchor the task starts cold
        return None
