"""The one evaluator: every trajectory measured the same way, on a fine time grid.

A planner's own claims are never reported; these figures are. Any limit exceeded by more
than 0.5 % of the limit (0.01 mm for the contour tolerance) is a violation.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from spm_opt.bounds import duration_lower_bound
from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.problem import Problem
from spm_opt.trajectory import Trajectory

DEFAULT_RATE_HZ = 1000.0
RELATIVE_TOLERANCE = 0.005
CONTOUR_TOLERANCE_M = 0.01 * MM


@dataclass(frozen=True)
class Violation:
    """One limit broken: the worst value, the limit and when (units in ``unit``)."""

    limit: str
    worst: float
    allowed: float
    unit: str
    time_s: float

    def __str__(self) -> str:
        return (
            f"{self.limit}: {self.worst:.4g} {self.unit} at t = {self.time_s:.3f} s "
            f"(allowed {self.allowed:.4g} {self.unit})"
        )


@dataclass(frozen=True)
class Report:
    """What the evaluator measured. Units are in the names; per-joint values are lists.

    Torques are the model's inverse dynamics with exact friction, as the actuators deliver
    them (with their reflected rotor inertia and gear efficiency, when the robot has them).
    ``torque_margin`` is 1 − peak / continuous torque per actuator, ``current_margin`` the
    same for the motor current the actuator's current map gives; ``energy_j`` is
    ∫ Σ|τ·θ̇| dt (the mechanical work the actuators put in, braking counted as work too)
    and ``effort_n2m2s`` is ∫ τᵀτ dt. ``duration_lower_bound_s`` is the shortest time the
    limits allow along the contour (:mod:`spm_opt.bounds`). ``max_acceleration_step_rad_s2``
    is the largest jump of q̈ (from rest at the start, to rest at the end, or between
    pieces): an unbounded jerk that the polynomials' own jerk does not show; with a jerk
    limit, a step larger than what that jerk reaches in one grid interval is a violation.
    """

    planner: str | None
    duration_s: float
    peak_joint_speed_rad_s: list[float]
    joint_speed_limit_rad_s: float
    peak_joint_acceleration_rad_s2: list[float]
    rms_jerk_rad_s3: list[float]
    max_acceleration_step_rad_s2: list[float]
    max_contour_deviation_mm: float
    rms_contour_deviation_mm: float
    max_tool_speed_mm_s: float
    mean_tool_speed_mm_s: float
    tool_speed_cv: float
    landmark_errors_mm: list[dict[str, Any]]
    max_landmark_error_mm: float
    min_singularity_margin: float
    contour_length_mm: float
    duration_lower_bound_s: float
    duration_over_lower_bound: float
    peak_torque_nm: list[float]
    rms_torque_nm: list[float]
    torque_margin: list[float]
    peak_current_a: list[float]
    current_margin: list[float]
    energy_j: float
    effort_n2m2s: float
    violations: list[Violation] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON; violations as dicts."""
        data = asdict(self)
        data["violations"] = [asdict(v) for v in self.violations]
        return data

    def to_markdown(self) -> str:
        """The report as a two-column markdown table, then the violations."""
        rows = [("planner", self.planner or "(unknown)")]
        for key, value in self.to_dict().items():
            if key in ("planner", "violations", "landmark_errors_mm"):
                continue
            rows.append((key, _format(value)))
        for visit in self.landmark_errors_mm:
            rows.append(
                (
                    f"landmark error {visit['landmark']} at {visit['time_s']:.3f} s, mm",
                    _format(visit["error_mm"]),
                )
            )
        lines = ["| figure | value |", "|---|---|"] + [f"| {k} | {v} |" for k, v in rows]
        lines.append("")
        if self.violations:
            lines.append(f"**{len(self.violations)} violation(s):**")
            lines += [f"- {v}" for v in self.violations]
        else:
            lines.append("No limit is violated.")
        return "\n".join(lines) + "\n"


def _format(value: Any) -> str:
    if isinstance(value, list):
        return ", ".join(_format(v) for v in value)
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _time_mean(values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Time average over the grid (trapezoid rule), per column."""
    return np.trapezoid(values, t, axis=0) / (t[-1] - t[0])


def evaluate(problem: Problem, trajectory: Trajectory, rate_hz: float = DEFAULT_RATE_HZ) -> Report:
    """Measure ``trajectory`` against ``problem`` on a grid at ``rate_hz`` (with breakpoints).

    Parameters
    ----------
    problem : Problem
    trajectory : Trajectory
    rate_hz : float
        Sampling rate of the evaluation grid, Hz (default 1 kHz).
    """
    robot, limits, contour = problem.robot, problem.limits, problem.contour
    t = trajectory.time_grid(rate_hz)
    q = trajectory.position(t)
    qd = trajectory.velocity(t)
    qdd = trajectory.acceleration(t)
    jerk = trajectory.jerk(t)
    directions = kinematics.forward_kinematics(q, 1.0)
    deviation = contour.deviation(directions)
    tool_speed = contour.joint_tool_speed(q, qd)
    margins = kinematics.singularity_margins(q)
    torque = dynamics.actuator_torque(robot, q, qd, qdd)
    continuous_torque = robot.actuator.continuous_torque_nm
    torque_limit = problem.max_joint_torque
    peak_torque = np.max(np.abs(torque), axis=0)
    peak_current = np.max(np.abs(robot.actuator.current_map.current(torque)), axis=0)
    duration = t[-1] - t[0]
    mean_speed = float(_time_mean(tool_speed, t))
    speed_std = float(np.sqrt(_time_mean((tool_speed - mean_speed) ** 2, t)))
    landmark_errors = _landmark_errors(problem, trajectory, t, directions)
    lower_bound = duration_lower_bound(problem)
    step_times, steps = trajectory.acceleration_steps()

    checks = _Checks(t)
    for joint in range(2):
        name = f"theta{joint + 1}"
        low, high = robot.joint_range[joint]
        span = (high - low) * RELATIVE_TOLERANCE
        checks.above(f"{name} upper range", q[:, joint] / DEG, high / DEG, span / DEG, "deg")
        checks.below(f"{name} lower range", q[:, joint] / DEG, low / DEG, span / DEG, "deg")
        checks.relative(f"{name} speed", np.abs(qd[:, joint]), limits.max_joint_speed, "rad/s")
        checks.relative(
            f"{name} acceleration", np.abs(qdd[:, joint]), limits.max_joint_acceleration, "rad/s^2"
        )
        checks.relative(f"{name} jerk", np.abs(jerk[:, joint]), limits.max_joint_jerk, "rad/s^3")
        if limits.max_joint_jerk is not None:
            allowed = limits.max_joint_jerk / rate_hz
            step = np.abs(steps[:, joint])
            slack = RELATIVE_TOLERANCE * allowed
            checks.above(f"{name} acceleration step", step, allowed, slack, "rad/s^2", step_times)
        checks.relative(f"{name} torque", np.abs(torque[:, joint]), torque_limit, "N*m")
    if limits.max_tool_speed is not None:
        checks.relative("tool speed", tool_speed / MM, limits.max_tool_speed / MM, "mm/s")
    if limits.contour_tolerance is not None:
        checks.above(
            "contour deviation",
            deviation / MM,
            limits.contour_tolerance / MM,
            CONTOUR_TOLERANCE_M / MM,
            "mm",
        )
    checks.below(
        "singularity margin",
        margins,
        robot.min_singularity_margin,
        RELATIVE_TOLERANCE * robot.min_singularity_margin,
        "",
    )

    return Report(
        planner=trajectory.metadata.get("planner"),
        duration_s=trajectory.duration,
        peak_joint_speed_rad_s=np.max(np.abs(qd), axis=0).tolist(),
        joint_speed_limit_rad_s=limits.max_joint_speed,
        peak_joint_acceleration_rad_s2=np.max(np.abs(qdd), axis=0).tolist(),
        rms_jerk_rad_s3=np.sqrt(_time_mean(jerk**2, t)).tolist(),
        max_acceleration_step_rad_s2=np.max(np.abs(steps), axis=0).tolist(),
        max_contour_deviation_mm=float(np.max(deviation) / MM),
        rms_contour_deviation_mm=float(np.sqrt(_time_mean(deviation**2, t)) / MM),
        max_tool_speed_mm_s=float(np.max(tool_speed) / MM),
        mean_tool_speed_mm_s=float(mean_speed / MM),
        tool_speed_cv=float(speed_std / mean_speed) if mean_speed > 0 else float("nan"),
        landmark_errors_mm=landmark_errors,
        max_landmark_error_mm=max(v["error_mm"] for v in landmark_errors),
        min_singularity_margin=float(np.min(margins)),
        contour_length_mm=contour.length / MM,
        duration_lower_bound_s=lower_bound,
        duration_over_lower_bound=trajectory.duration / lower_bound,
        peak_torque_nm=peak_torque.tolist(),
        rms_torque_nm=np.sqrt(_time_mean(torque**2, t)).tolist(),
        torque_margin=(1.0 - peak_torque / continuous_torque).tolist(),
        peak_current_a=peak_current.tolist(),
        current_margin=(1.0 - peak_current / robot.actuator.continuous_current_a).tolist(),
        energy_j=float(np.trapezoid(np.sum(np.abs(torque * qd), axis=1), t)),
        effort_n2m2s=float(_time_mean(np.sum(torque**2, axis=1), t) * duration),
        violations=checks.found,
    )


class _Checks:
    """Collects violations: the worst sample above a limit plus its allowance."""

    def __init__(self, t: np.ndarray) -> None:
        self.t = t
        self.found: list[Violation] = []

    def above(
        self,
        limit: str,
        values: np.ndarray,
        allowed: float,
        slack: float,
        unit: str,
        times: np.ndarray | None = None,
    ) -> None:
        """Record the worst of ``values`` (at ``times``, default the grid) above the limit."""
        times = self.t if times is None else times
        worst = int(np.argmax(values))
        if values[worst] > allowed + slack:
            self.found.append(
                Violation(limit, float(values[worst]), float(allowed), unit, float(times[worst]))
            )

    def below(
        self, limit: str, values: np.ndarray, allowed: float, slack: float, unit: str
    ) -> None:
        worst = int(np.argmin(values))
        if values[worst] < allowed - slack:
            self.found.append(
                Violation(limit, float(values[worst]), float(allowed), unit, float(self.t[worst]))
            )

    def relative(self, limit: str, values: np.ndarray, allowed: float | None, unit: str) -> None:
        if allowed is not None:
            self.above(limit, values, allowed, RELATIVE_TOLERANCE * allowed, unit)


def _landmark_errors(
    problem: Problem, trajectory: Trajectory, t: np.ndarray, directions: np.ndarray
) -> list[dict[str, Any]]:
    """Distance on the skull from each landmark visit, at the time the plan claims for it,
    or at the closest approach when the plan does not say."""
    visits = problem.visit_order
    claimed = trajectory.landmark_times
    errors = []
    for k, index in enumerate(visits):
        landmark = problem.landmarks[index]
        radius = np.linalg.norm(landmark)
        unit = landmark / radius
        if claimed is not None and len(claimed) == len(visits):
            time = float(claimed[k])
            direction = kinematics.forward_kinematics(trajectory.position([time]), 1.0)[0]
            error = radius * np.linalg.norm(direction - unit)
        else:
            distances = radius * np.linalg.norm(directions - unit, axis=1)
            closest = int(np.argmin(distances))
            time, error = float(t[closest]), distances[closest]
        errors.append(
            {
                "landmark": problem.landmark_names[index],
                "time_s": time,
                "error_mm": float(error / MM),
            }
        )
    return errors
