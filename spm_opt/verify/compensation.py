"""Compensating what repeats: the plan's stream corrected so that the executed cut, not
the stream, lies where the plan does.

The lead (:mod:`spm_opt.execution.tracking`) inverts the nominal position and velocity
loops exactly: through them, a led reference q comes out as q. What it leaves is what the
robot adds on top of the nominal loops, the same in every run of the same plan: the loops'
deflection under the load (the torque the dynamics, the friction and the gear losses ask
for), the velocity loop's departure from a first-order lag, encoder zeros a robot file
states. Iterative learning control removes it: a run of the stream q + δₖ shows the
error eₖ(s) = y(s) − q(s) of the joints' positions y against the plan q at each plan time s,
and the next stream is

    δₖ₊₁ = δₖ − Q[eₖ],

Q a zero-phase low-pass filter (a fourth-order Butterworth run forwards and backwards,
cut-off :data:`CUTOFF_HZ`) and δ tapered to nothing over the plan's first and last
:data:`TAPER_S` (the stream starts where the robot is and ends at rest, as the plan does).

**Stability.** With the lead, the led loop's response is 1 − Δ(jω), Δ what the nominal
model leaves out; the error then changes as eₖ₊₁ = (1 − Q)(·) + Q Δ eₖ and the iterations
converge monotonically where |Q(jω)| |Δ(jω)| < 1 at every frequency (the classical
criterion for learning gain 1). A half-period delay of the goals (5 ms at 100 Hz) alone
gives |Δ| = 2 |sin(ωT/4)|, which reaches 1 at 33 Hz; the velocity loop's own dynamics
are the file's ωv (87–150 1/s, 14–24 Hz). Q's cut-off of 2 Hz keeps |Q Δ| below 0.15
with both. The load's part of Δ is not linear (Coulomb friction, stick-slip), so each
iteration is also judged where it matters: by the predicted cut, the iteration whose cut
is nearest the contour kept, and the learning stops once an iteration's cut is not nearer.

**Two sources of the error.** :func:`compensate` runs the iterations on the closed-loop
model of a robot file (:func:`~spm_opt.verify.predicted_cut.predict_cut`, the model's
true state): its first iteration is the load's deflection fed forward, the next ones learn
what the first leaves. :func:`compensate_from_run` takes one iteration from a dry run on
the robot itself (the tool retracted): the log's measured positions and logged references,
which hold what no robot file knows, except the encoders' own zero errors.

The corrected stream is a plan like any other (a :class:`Trajectory`, written with its
sidecar), checked by pre-flight as any plan is, and its metadata's ``compensation``
records what it was learned from.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import make_interp_spline
from scipy.signal import butter, sosfiltfilt

from spm_opt.base.errors import InputError
from spm_opt.execution import ExecutionSettings
from spm_opt.execution.log import read_execution_log
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.limits import ROBOT_RULES
from spm_opt.model.params import Robot
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.verify.followed import Followed, followed_in_log
from spm_opt.verify.predicted_cut import PredictedCut, predict_cut

CUTOFF_HZ = 2.0
"""The learning filter Q's cut-off, Hz (see the module's docstring)."""
FILTER_ORDER = 4
"""Q's Butterworth order (run forwards and backwards: twice this)."""
TAPER_S = 0.5
"""The correction grows from nothing over the plan's first and falls to nothing over its
last this many seconds, s."""
LEAST_GAIN_MM = 0.001
"""A correction is kept only if its predicted cut is at least this much nearer the contour
than the last one kept, mm."""
LEARNED_AT = ("feed", "rate_hz", "tracking")
"""The run's settings a correction was learned at, which its record keeps."""
DEFAULT_ITERATIONS = 3
"""Runs of the model :func:`compensate` learns from by default."""


@dataclasses.dataclass(frozen=True)
class Iteration:
    """One run learned from: its cut's distance from the contour (mm, the model's true
    cut, None from a dry run's log) and its largest joint error against the plan (rad)."""

    deviation_mm: float | None
    largest_error_rad: float

    def record(self) -> dict[str, Any]:
        """The iteration as the plan's metadata holds it."""
        return {"deviation_mm": self.deviation_mm, "largest_error_rad": self.largest_error_rad}


@dataclasses.dataclass(frozen=True)
class Compensation:
    """A compensated plan and how it was learned.

    Attributes
    ----------
    plan : Trajectory
        The corrected stream (its metadata's ``compensation`` says how it was made).
    iterations : list of Iteration
        Every run learned from, the plan's own first (the lead alone).
    kept : int
        How many corrections the kept stream has had (0: none helped).
    predicted : PredictedCut or None
        The kept stream's predicted cut (None from a dry run's log).
    """

    plan: Trajectory
    iterations: list[Iteration]
    kept: int
    predicted: PredictedCut | None


def correction_of(base: Trajectory, followed: Followed) -> tuple[np.ndarray, np.ndarray]:
    """The next correction δₖ₊₁ (G, 2), rad, on a uniform grid of plan times (G,), s, from a
    run of the stream q + δₖ (``followed``): δₖ − Q[eₖ], tapered (see the module's
    docstring)."""
    grid, error, correction = _on_grid(base, followed)
    step = float(np.median(np.diff(grid)))
    sos = butter(FILTER_ORDER, CUTOFF_HZ, fs=1.0 / step, output="sos")
    taper = _taper(grid, base.start_time, base.end_time)[:, None]
    # the error tapered before the filter too: no transient of the filter's ends is learned
    learned = correction - sosfiltfilt(sos, taper * error, axis=0)
    return grid, learned * taper


def corrected_plan(
    base: Trajectory, grid: np.ndarray, correction: np.ndarray, record: dict[str, Any]
) -> Trajectory:
    """``base`` plus ``correction`` (G, 2), rad, on the uniform ``grid`` (G,), s, through a
    quintic spline at rest at both ends, sampled at the base's own sample times, with
    ``record`` as its metadata's ``compensation``."""
    times, q, qd, qdd = base.samples()
    at_rest = [(1, np.zeros(2)), (2, np.zeros(2))]
    spline = make_interp_spline(grid, correction, k=5, bc_type=(at_rest, at_rest))
    metadata = {**base.metadata, "compensation": record}
    metadata.pop("samples", None)  # the corrected samples are recorded when written
    return Trajectory.from_samples(
        times,
        q + spline(times),
        qd + spline.derivative(1)(times),
        qdd + spline.derivative(2)(times),
        metadata,
    )


SCALINGS = 6
"""How many times :func:`within_limits` halves a correction before it gives it up."""


def within_limits(
    problem: Problem,
    base: Trajectory,
    grid: np.ndarray,
    correction: np.ndarray,
    record: dict[str, Any],
) -> Trajectory:
    """:func:`corrected_plan`, the correction halved until the stream keeps every limit that
    judges the robot (what pre-flight checks; the base's own stream if none does); the
    ``record`` gains the ``scale`` kept."""
    for halvings in range(SCALINGS + 1):
        scale = 0.5**halvings
        plan = corrected_plan(base, grid, scale * correction, {**record, "scale": scale})
        if not robot_limits_broken(problem, plan):
            return plan
    return corrected_plan(base, grid, 0.0 * correction, {**record, "scale": 0.0})


def robot_limits_broken(problem: Problem, plan: Trajectory) -> list[str]:
    """The violations of the rules that judge the robot (joint range, speed, acceleration,
    jerk, torque, current, singularity) in ``plan``'s stream."""
    report = evaluate(problem, plan)
    return [str(v) for v in report.violations if v.rule in ROBOT_RULES]


def compensate(
    problem: Problem,
    base: Trajectory,
    robot: Robot | None = None,
    settings: ExecutionSettings | None = None,
    iterations: int = DEFAULT_ITERATIONS,
) -> Compensation:
    """Learn ``base``'s correction on the closed-loop model of ``robot`` (default: the
    problem's) run with the executor's ``settings``, up to ``iterations`` corrections; the
    stream whose predicted cut is nearest the contour is kept."""
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise InputError(f"iterations = {iterations!r}: expected a whole number of at least 1")
    base = _checked_base(base)
    robot = robot or problem.robot
    settings = settings or ExecutionSettings()
    stream, best = base, None
    history: list[Iteration] = []
    kept_stream, kept = base, 0
    for k in range(iterations + 1):
        predicted = predict_cut(problem, stream, robot, settings)
        followed = predicted.followed
        history.append(Iteration(predicted.deviation_mm, _largest_error(base, followed)))
        if best is not None and not _nearer(predicted, best):
            break
        best, kept_stream, kept = predicted, stream, k
        if k == iterations or not predicted.report.completed:
            break  # a run that stopped has no error to learn from along the whole plan
        grid, correction = correction_of(base, followed)
        stream = within_limits(problem, base, grid, correction, {})
    learned_at = {"feed": settings.feed, "rate_hz": settings.rate_hz, "tracking": settings.tracking}
    record = _record(base, "model", robot.name, learned_at, history, kept)
    record["scale"] = kept_stream.metadata.get("compensation", {}).get("scale", 0.0)
    metadata = {**base.metadata, "compensation": record}
    metadata.pop("samples", None)  # the corrected samples are recorded when written
    plan = Trajectory.from_samples(*kept_stream.samples(), metadata)
    return Compensation(plan, history, kept, best)


def compensate_from_run(problem: Problem, base: Trajectory, log_path: str | Path) -> Compensation:
    """One correction of ``base`` from the log of a dry run of ``base`` or of a stream
    compensated from it (see the module's docstring)."""
    base = _checked_base(base)
    table, header = read_execution_log(log_path)
    followed = followed_in_log(table)
    if followed.plan_time_s.size < 2:
        raise InputError(f"log {log_path}: fewer than 2 plan rows with a reading to learn from")
    _check_run_of(base, followed, header, log_path)
    ran = header.get("plan") or {}
    earlier = ran.get("compensation") or {}
    history = [Iteration(**item) for item in earlier.get("iterations", [])]
    history.append(Iteration(None, _largest_error(base, followed)))
    grid, correction = correction_of(base, followed)
    settings = header.get("settings") or {}
    record = _record(
        base,
        "dry run",
        (header.get("problem") or {}).get("robot", {}).get("name", "the robot"),
        {key: settings.get(key) for key in LEARNED_AT},
        history,
        len(history),
    )
    record["log"] = str(log_path)
    plan = within_limits(problem, base, grid, correction, record)
    return Compensation(plan, history, len(history), None)


RUN_OF_PLAN_RAD = np.radians(1.0)
"""A log's references further than this from the plan are not a run of it (nor of a
stream compensated from it), rad."""


def _check_run_of(base: Trajectory, followed: Followed, header: dict, log_path: str | Path) -> None:
    """Refuse a log that ran neither ``base`` nor a stream compensated from it: by the
    plans' samples hashes where both record them, and by its references."""
    ran = header.get("plan") or {}
    mine = (base.metadata.get("samples") or {}).get("sha256")
    theirs = {
        (ran.get("samples") or {}).get("sha256"),
        ((ran.get("compensation") or {}).get("of_plan") or {}).get("sha256"),
    }
    hashed = mine is not None and (ran.get("samples") or ran.get("compensation"))
    apart = np.max(np.abs(followed.reference_rad - base.position(followed.plan_time_s)))
    if (hashed and mine not in theirs) or apart > RUN_OF_PLAN_RAD:
        raise InputError(
            f"log {log_path}: a run of another plan (its references lie up to "
            f"{np.degrees(apart):.3g} deg from this plan's, and it records "
            f"{ran.get('planner', 'no')} plan); learn from a dry run of this plan or of a "
            "stream compensated from it"
        )


def _on_grid(base: Trajectory, followed: Followed) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A uniform grid of plan times (s) over ``base``, and on it the error against the plan
    and the stream's correction (each (G, 2), rad), from the cycles' last sample of each
    plan time."""
    order = np.argsort(followed.plan_time_s, kind="stable")
    plan_time = followed.plan_time_s[order]
    last = np.concatenate([plan_time[1:] != plan_time[:-1], [True]])
    plan_time = plan_time[last]
    position = followed.position_rad[order][last]
    reference = followed.reference_rad[order][last]
    planned = base.position(plan_time)
    step = max(float(np.median(np.diff(plan_time))), 1e-3) if plan_time.size > 1 else 1e-2
    grid = np.linspace(base.start_time, base.end_time, int(round(base.duration / step)) + 1)

    def resampled(values: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(grid, plan_time, values[:, j]) for j in range(2)])

    return grid, resampled(position - planned), resampled(reference - planned)


def _taper(times: np.ndarray, start: float, end: float) -> np.ndarray:
    """A weight (N,) rising from 0 to 1 over :data:`TAPER_S` after ``start`` and falling back
    over the last before ``end`` (s), smoothly to its second derivative."""

    def rise(x: np.ndarray) -> np.ndarray:
        x = np.clip(x, 0.0, 1.0)
        return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)

    span = min(TAPER_S, 0.25 * (end - start))
    return rise((times - start) / span) * rise((end - times) / span)


def _largest_error(base: Trajectory, followed: Followed) -> float:
    """The largest joint error against ``base`` over the run's plan-phase cycles, rad."""
    error = followed.position_rad - base.position(followed.plan_time_s)
    return float(np.max(np.abs(error))) if error.size else 0.0


def _nearer(predicted: PredictedCut, best: PredictedCut) -> bool:
    """Whether ``predicted`` is better than ``best``: a completed run whose cut is nearer
    the contour by :data:`LEAST_GAIN_MM` (or the first completed one)."""
    if not predicted.report.completed:
        return False
    if not best.report.completed:
        return True
    return predicted.deviation_mm < best.deviation_mm - LEAST_GAIN_MM


def _checked_base(base: Trajectory) -> Trajectory:
    """The plan the correction is of: refuses one that is itself compensated."""
    if "compensation" in base.metadata:
        raise InputError("plan: already compensated; learn from the plan it was compensated from")
    return base


def _record(
    base: Trajectory,
    source: str,
    robot: str,
    learned_at: dict[str, Any],
    history: list[Iteration],
    kept: int,
) -> dict[str, Any]:
    """The ``compensation`` metadata: what the correction was learned from and how."""
    return {
        "learned_from": source,
        "robot": robot,
        "of_plan": base.metadata.get("samples"),
        "planner": base.metadata.get("planner"),
        **learned_at,
        "cutoff_hz": CUTOFF_HZ,
        "taper_s": TAPER_S,
        "iterations": [item.record() for item in history],
        "corrections": kept,
    }
