"""Pre-flight: what a plan must be before the executor lets it move the robot.

Each check raises a one-line :class:`~spm_opt.base.errors.PreflightError`, in this order:

1. **Made for this problem.** The plan's metadata records the problem it was planned for
   (:meth:`~spm_opt.problem.problem.Problem.record`); its fingerprint (the landmarks, the limits
   and the robot, not the file's bytes) must be this problem's
   (:func:`spm_opt.problem.provenance.check_made_for`, as ``review`` and ``evaluate`` check it).
   A plan that records none (no sidecar, or one written by hand) or another runs only
   when asked for on purpose (``other_problem``), and is then still judged by this
   problem's limits.
2. **At rest at both ends.** The executor joins the plan from rest and holds its last
   goal after it, so the plan's speed and acceleration at each end must be small enough
   that joining rest within one control period T keeps the limits every commanded motion
   keeps (acceleration a, jerk j; see
   :meth:`~spm_opt.execution.settings.ExecutionSettings.joint_limits`): a speed step v
   commands v/T of acceleration and v/T² of jerk, an acceleration step α commands α/T of
   jerk. So |q̇| ≤ min(a T, j T²) and |q̈| ≤ j T at both ends (with the evaluator's
   0.5 %): 1e-3 rad/s and 0.1 rad/s² under the paper's 1 rad/s² and 10 rad/s³ at 100 Hz.
   The planners end at rest exactly; the paper's cubic starts with an acceleration of
   0.014 rad/s².
3. **Within the robot's limits,** as the evaluator judges them: every rule that
   :mod:`spm_opt.judge.limits` says judges the robot (joint range, speed, acceleration, jerk,
   torque, current, singularity). The cut's own figures are the planner's business.
4. **Starting inside the joint range.**
5. **Led goals the actuators take.** The goals the executor sends lead the plan by the
   position loop's lag (:mod:`spm_opt.execution.tracking`): they must stay inside the
   joint range, and move no faster than the actuators' Velocity Limit, at 100 % feed
   (the feed ceiling keeps them so above it).

Once connected, before anything moves:

6. **Room for the log.** The disk that takes the log must have room for twice what a run
   of the plan at its starting feed (with its approach, settle, a stop and the hold)
   logs at the loop's rate (:func:`check_log_room`).

A CSV whose samples are not those its sidecar records never gets this far:
:meth:`~spm_opt.problem.trajectory.Trajectory.from_csv` refuses it.
"""

from __future__ import annotations

import logging
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from spm_opt.base.errors import PreflightError
from spm_opt.execution.feed import JointLimits
from spm_opt.execution.log import bytes_needed
from spm_opt.execution.tracking import Lead, led_goals_outside
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.limits import ROBOT_RULES, RULES
from spm_opt.model.params import DEG
from spm_opt.problem import provenance
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

_LOG = logging.getLogger(__name__)


def check_plan(
    problem: Problem,
    trajectory: Trajectory,
    limits: JointLimits,
    period_s: float,
    lead: Lead,
    other_problem: bool = False,
) -> None:
    """Refuse ``trajectory`` for ``problem`` (see the module's docstring); a plan let
    through by ``other_problem`` is named in a warning once every other check has passed.

    Parameters
    ----------
    problem : Problem
    trajectory : Trajectory
    limits : JointLimits
        The limits every commanded motion keeps (rad/s, rad/s², rad/s³).
    period_s : float, s
        The control period.
    lead : Lead
        How the goals lead the plan.
    other_problem : bool
        Run a plan made for another problem, or recording none, under ``problem``'s limits.
    """
    allowed = provenance.check_plan_made_for(
        problem, trajectory, other_problem, error=PreflightError
    )
    check_at_rest(trajectory, limits, period_s)
    report = evaluate(problem, trajectory)
    broken = [v for v in report.violations if v.rule in ROBOT_RULES]
    if broken:
        raise PreflightError(
            f"plan refused: {broken[0]}"
            + (f" and {len(broken) - 1} more limit(s) broken" if len(broken) > 1 else "")
        )
    start = trajectory.position(trajectory.start_time)
    low, high = problem.robot.joint_range[:, 0], problem.robot.joint_range[:, 1]
    if np.any(start < low) or np.any(start > high):
        raise PreflightError(f"plan refused: its start {degrees(start)} is out of range")
    outside = led_goals_outside(lead, trajectory, problem.robot)
    if outside:
        raise PreflightError(f"plan refused: {outside} (use --tracking none, or plan slower)")
    if allowed:
        _LOG.warning("%s; run under %s's limits as asked (--other-problem)", allowed, problem.name)


def rest_bounds(limits: JointLimits, period_s: float) -> tuple[float, float]:
    """The largest speed (rad/s) and acceleration (rad/s²) at which a plan's end counts as
    at rest: what joins rest within one control period ``period_s`` (s) keeping
    ``limits``, with the evaluator's tolerance."""
    acceleration = RULES["joint acceleration"].allowed(limits.acceleration)
    jerk = RULES["joint jerk"].allowed(limits.jerk)
    return min(acceleration * period_s, jerk * period_s**2), jerk * period_s


def check_at_rest(trajectory: Trajectory, limits: JointLimits, period_s: float) -> None:
    """Refuse a plan that does not start and end at rest (see :func:`rest_bounds`)."""
    speed_bound, acceleration_bound = rest_bounds(limits, period_s)
    for end, time_s in (("start", trajectory.start_time), ("end", trajectory.end_time)):
        speed = np.abs(trajectory.velocity([time_s])[0])
        acceleration = np.abs(trajectory.acceleration([time_s])[0])
        moving = (speed > speed_bound) | (acceleration > acceleration_bound)
        if np.any(moving):
            j = int(np.argmax(moving))
            raise PreflightError(
                f"plan refused: it does not {end} at rest: theta{j + 1} at {speed[j]:.3g} "
                f"rad/s and {acceleration[j]:.3g} rad/s^2 at t = {time_s:g} s (at rest: at "
                f"most {speed_bound:.3g} rad/s and {acceleration_bound:.3g} rad/s^2, what "
                f"joins rest within one {period_s * 1e3:g} ms control period under "
                f"{limits.acceleration:g} rad/s^2 and {limits.jerk:g} rad/s^3)"
            )


LOG_ROOM_MARGIN = 2.0
"""The log needs this many times its estimated size free on its disk."""


def check_log_room(log_path: Path, seconds: float, header: dict[str, Any]) -> None:
    """Refuse a run whose log, ``seconds`` long at ``header``'s control rate, would not fit
    :data:`LOG_ROOM_MARGIN` times over in the free space of ``log_path``'s disk."""
    rate_hz = header["settings"]["rate_hz"]
    needed = LOG_ROOM_MARGIN * bytes_needed(seconds * rate_hz, header)
    existing = next(folder for folder in log_path.absolute().parents if folder.exists())
    free = shutil.disk_usage(existing).free
    if free < needed:
        raise PreflightError(
            f"log {log_path}: a run of about {seconds:.1f} s at {rate_hz:g} Hz needs "
            f"{needed / 1e6:.2f} MB free ({LOG_ROOM_MARGIN:g} times its estimate), and its "
            f"disk has {free / 1e6:.2f} MB; free some space or log to another disk"
        )


def degrees(q: np.ndarray) -> str:
    """Joint angles (rad) as "(a, b) deg"."""
    return "(" + ", ".join(f"{v / DEG:.3f}" for v in q) + ") deg"
