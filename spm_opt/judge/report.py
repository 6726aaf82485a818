"""The judge's report of a motion: the figures it measured (:class:`Report`) and the limits
broken (:class:`Violation`), as data for JSON and as a markdown table."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

from spm_opt.base.markdown import markdown_table


@dataclass(frozen=True)
class Violation:
    """One limit broken: the worst value, the limit (``allowed``, before the evaluator's
    tolerance) and when (units in ``unit``); ``rule`` names its entry in
    :data:`spm_opt.judge.limits.RULES`. ``reserve`` (in ``unit``), when not 0, says the limit is
    a plan's contour tube: the contour tolerance less this much kept for execution."""

    limit: str
    worst: float
    allowed: float
    unit: str
    time_s: float
    rule: str
    reserve: float = 0.0

    def __str__(self) -> str:
        limit = f"limit {self.allowed:.4g} {self.unit}"
        if self.reserve:
            limit += (
                f": the plan's tube, {self.allowed + self.reserve:.4g} {self.unit} less "
                f"{self.reserve:.4g} {self.unit} kept for execution"
            )
        return f"{self.limit}: {self.worst:.4g} {self.unit} at t = {self.time_s:.3f} s ({limit})"


@dataclass(frozen=True)
class Report:
    """What the evaluator measured. Units are in the names; per-joint values are lists.

    Torques are the model's inverse dynamics with exact friction, as the actuators deliver
    them (with their reflected rotor inertia and gear efficiency, when the robot has them).
    ``torque_margin`` is 1 − peak / continuous torque per actuator, ``current_margin`` the
    same for the motor current the actuator's current map gives; ``energy_j`` is
    ∫ Σ|τ·θ̇| dt (the mechanical work the actuators put in, braking counted as work too)
    and ``effort_n2m2s`` is ∫ τᵀτ dt. ``duration_lower_bound_s`` is the shortest time the
    limits allow along the contour (:mod:`spm_opt.judge.bounds`). ``max_acceleration_step_rad_s2``
    is the largest jump of q̈ (from rest at the start, to rest at the end, or between
    pieces): an unbounded jerk that the polynomials' own jerk does not show; with a jerk
    limit, a step larger than what that jerk reaches in one grid interval is a violation
    (None, "—": not measured, as of an executed run, whose smoothed jerk shows any step).
    """

    planner: str | None
    duration_s: float
    peak_joint_speed_rad_s: list[float]
    joint_speed_limit_rad_s: float
    peak_joint_acceleration_rad_s2: list[float]
    rms_jerk_rad_s3: list[float]
    max_acceleration_step_rad_s2: list[float] | None
    max_contour_deviation_mm: float
    rms_contour_deviation_mm: float
    max_tool_speed_mm_s: float
    mean_tool_speed_mm_s: float
    tool_speed_cv: float
    landmark_errors_mm: list[dict[str, Any]]
    max_landmark_error_mm: float
    coverage_gap_mm: float
    max_backtrack_mm: float
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
    contour_judged: bool = True
    max_tool_incidence_deg: float | None = None
    max_depth_speed_mm_s: float | None = None
    max_depth_acceleration_mm_s2: float | None = None

    _NOT_IN_TABLE: ClassVar[tuple[str, ...]] = (
        "planner",
        "violations",
        "landmark_errors_mm",
        "contour_judged",
    )
    """Fields the markdown's table leaves out (shown otherwise, or not at all)."""

    @property
    def accepted(self) -> bool:
        """Whether the judge accepts the cut: no limit is violated."""
        return not self.violations

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON; violations as dicts."""
        data = asdict(self)
        data["violations"] = [asdict(v) for v in self.violations]
        return data

    def to_markdown(self) -> str:
        """The report as a two-column markdown table, then the violations."""
        rows = [("planner", self.planner or "(unknown)")]
        for key, value in self.to_dict().items():
            if key in self._NOT_IN_TABLE:
                continue
            rows.append((key, _format(value)))
        for visit in self.landmark_errors_mm:
            rows.append(
                (
                    f"landmark error {visit['landmark']} at {visit['time_s']:.3f} s, mm",
                    _format(visit["error_mm"]),
                )
            )
        lines = [*markdown_table(("figure", "value"), rows), "", *self._notes()]
        if self.violations:
            lines.append(f"**{len(self.violations)} violation(s):**")
            lines += [f"- {v}" for v in self.violations]
        else:
            lines.append("No limit is violated.")
        return "\n".join(lines) + "\n"

    def _notes(self) -> list[str]:
        """Lines between the table and the violations."""
        if self.contour_judged:
            return []
        return ["The plan ignores the contour: only the robot's limits are judged."]


def _format(value: Any) -> str:
    """A figure as the table shows it: None as a dash, a list joined, a float to 6 digits."""
    if value is None:
        return "—"
    if isinstance(value, list):
        return ", ".join(_format(v) for v in value)
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)
