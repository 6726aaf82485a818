"""The planner comparison: every planner on one problem, judged by the one evaluator.

    import spm_opt as so
    table = so.compare(so.load_problem("problems/craniotomy_bone_flap.toml"))

A planner that fails gets a row with its error; the others still run.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.base.files import write_atomically
from spm_opt.base.markdown import markdown_table
from spm_opt.judge import limits
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.report import Report
from spm_opt.model.params import MM
from spm_opt.planners import contour_planners, get_planner, plan
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.report.columns import COLUMN, COLUMNS
from spm_opt.report.planner_style import contour_tubes

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class Outcome:
    """One planner's result: its plan and the evaluator's report, or the error it raised
    (``error`` in words, ``exception`` itself); ``wall_time_s`` is the whole planning call
    (with any construction, without the evaluation)."""

    planner: str
    wall_time_s: float
    trajectory: Trajectory | None = None
    report: Report | None = None
    error: str | None = None
    exception: Exception | None = field(default=None, compare=False, repr=False)

    def row(self) -> dict[str, object]:
        """The outcome as a row of the comparison table (NaN where the planner failed)."""
        row: dict[str, object] = dict.fromkeys(COLUMNS, np.nan)
        row.update(planner=self.planner, status="failed", violations="", error=self.error or "")
        if self.report is None or self.trajectory is None:
            return row
        r = self.report
        statistics = self.trajectory.metadata.get("statistics", {})
        row.update(
            status="ok" if not r.violations else f"{len(r.violations)} violation(s)",
            solve_time_s=statistics.get("solve_time_s", self.wall_time_s),
            wall_time_s=self.wall_time_s,
            duration_s=r.duration_s,
            duration_over_lower_bound=r.duration_over_lower_bound,
            peak_torque_1_nm=r.peak_torque_nm[0],
            peak_torque_2_nm=r.peak_torque_nm[1],
            rms_torque_1_nm=r.rms_torque_nm[0],
            rms_torque_2_nm=r.rms_torque_nm[1],
            energy_j=r.energy_j,
            effort_n2m2s=r.effort_n2m2s,
            peak_joint_speed_over_limit=max(r.peak_joint_speed_rad_s) / r.joint_speed_limit_rad_s,
            max_contour_deviation_mm=r.max_contour_deviation_mm,
            rms_contour_deviation_mm=r.rms_contour_deviation_mm,
            max_tool_speed_mm_s=r.max_tool_speed_mm_s,
            mean_tool_speed_mm_s=r.mean_tool_speed_mm_s,
            tool_speed_cv=r.tool_speed_cv,
            rms_jerk_1_rad_s3=r.rms_jerk_rad_s3[0],
            rms_jerk_2_rad_s3=r.rms_jerk_rad_s3[1],
            max_landmark_error_mm=r.max_landmark_error_mm,
            violations="; ".join(str(v) for v in r.violations),
        )
        return row


Progress = Callable[[int, int, str, "Outcome | None"], None]
"""Called before each planner (outcome None) and after it: (index from 1, count, name,
outcome)."""


def progress_line(index: int, count: int, name: str, outcome: Outcome | None) -> str:
    """A :data:`Progress` call as one line for the user: "[2/6] toppra ..." before the
    planner, "[2/6] toppra: 38.06 s plan, 0 violation(s) (0.3 s)" after it."""
    if outcome is None:
        return f"[{index}/{count}] {name} ..."
    result = outcome.error or (
        f"{outcome.trajectory.duration:.2f} s plan, "  # type: ignore[union-attr]
        f"{len(outcome.report.violations)} violation(s)"  # type: ignore[union-attr]
    )
    return f"[{index}/{count}] {name}: {result} ({outcome.wall_time_s:.1f} s)"


def run_planner(problem: Problem, name: str, warm_start: Trajectory | None = None) -> Outcome:
    """Plan ``problem`` with one planner (from ``warm_start`` when it takes one) and
    evaluate the plan; the planner's failure is the outcome's error, never an exception."""
    started = time.perf_counter()
    try:
        trajectory = plan(problem, name, warm_start)
        return Outcome(
            name, time.perf_counter() - started, trajectory, evaluate(problem, trajectory)
        )
    except Exception as error:  # noqa: BLE001 - one planner's failure is a row
        return Outcome(
            name,
            time.perf_counter() - started,
            error=f"{type(error).__name__}: {error}",
            exception=error,
        )


def run_planners(
    problem: Problem, planners: Sequence[str] | None = None, progress: Progress | None = None
) -> list[Outcome]:
    """Plan ``problem`` with each planner (default: every registered planner that plans the
    cut, by name) and evaluate every plan. Unknown names are refused before anything runs."""
    names = contour_planners() if planners is None else list(planners)
    for name in names:
        get_planner(name)
    outcomes = []
    for index, name in enumerate(names, start=1):
        if progress is not None:
            progress(index, len(names), name, None)
        outcome = run_planner(problem, name)
        if progress is not None:
            progress(index, len(names), name, outcome)
        outcomes.append(outcome)
    return outcomes


def comparison_table(outcomes: Sequence[Outcome]) -> pd.DataFrame:
    """One row per planner, the columns of :data:`COLUMNS`."""
    import pandas as pd

    return pd.DataFrame([outcome.row() for outcome in outcomes], columns=list(COLUMNS))


def compare(problem: Problem, planners: Sequence[str] | None = None) -> pd.DataFrame:
    """Every planner (default: all registered) on ``problem``, as a table (see COLUMNS)."""
    return comparison_table(run_planners(problem, planners))


def _limits_lines(problem: Problem) -> list[str]:
    """The limits, one line each; the contour tolerance with the tubes a plan and an
    executed cut are judged against."""
    bounds = problem.limits
    tubes = "; ".join(tube.words for tube in contour_tubes(problem))

    def shown(value: float | None, scale: float, unit: str) -> str:
        return "not limited" if value is None else f"{value / scale:.4g} {unit}"

    return [
        f"- joint speed: {bounds.max_joint_speed:.4g} rad/s "
        f"({bounds.max_joint_speed * 60 / (2 * np.pi):.4g} rpm)",
        f"- joint acceleration: {shown(bounds.max_joint_acceleration, 1.0, 'rad/s²')}",
        f"- joint jerk: {shown(bounds.max_joint_jerk, 1.0, 'rad/s³')}",
        f"- actuator torque: {problem.max_joint_torque:.4g} N·m",
        f"- tool speed on the skull: {shown(bounds.max_tool_speed, MM, 'mm/s')}",
        f"- contour tolerance: {shown(bounds.contour_tolerance, MM, 'mm')}"
        + (f" — {tubes}" if tubes else ""),
    ]


SHOWN = (
    "planner",
    "status",
    "solve_time_s",
    "wall_time_s",
    "duration_s",
    "duration_over_lower_bound",
    "max_contour_deviation_mm",
    "rms_contour_deviation_mm",
    "max_tool_speed_mm_s",
    "mean_tool_speed_mm_s",
    "tool_speed_cv",
    "peak_joint_speed_over_limit",
    "peak_torque_1_nm",
    "peak_torque_2_nm",
    "rms_torque_1_nm",
    "rms_torque_2_nm",
    "energy_j",
    "effort_n2m2s",
    "rms_jerk_1_rad_s3",
    "rms_jerk_2_rad_s3",
)
"""The columns comparison.md shows, in its order (comparison.csv has every column)."""


SAME_DURATION_S = 1e-3
"""Plans whose durations differ by less than this, s, share a duration."""


def _shared_durations(outcomes: Sequence[Outcome]) -> list[str]:
    """Which plans share a duration (compare effort or smoothness only among those)."""
    groups: list[tuple[float, list[str]]] = []
    for outcome in outcomes:
        if outcome.trajectory is None:
            continue
        duration = outcome.trajectory.duration
        group = next((g for g in groups if abs(g[0] - duration) < SAME_DURATION_S), None)
        if group is None:
            groups.append((duration, [outcome.planner]))
        else:
            group[1].append(outcome.planner)
    shared = [f"{', '.join(names)} ({d:.2f} s)" for d, names in groups if len(names) > 1]
    if not shared:
        return ["No two plans share a duration (∫τᵀτ dt and ∫jerk² dt depend on it)."]
    return [
        "Plans that share a duration (∫τᵀτ dt and ∫jerk² dt compare fairly only among "
        f"them): {'; '.join(shared)}."
    ]


def _skull_lines(problem: Problem) -> list[str]:
    """What the summary says of a skull from imaging: its meshes, the registration's error
    and how far the landmarks moved onto the outer mesh."""
    skull = problem.skull
    if skull is None:
        return []
    lines = []
    if skull.outer_mesh is not None:
        inner = "" if skull.inner_mesh is None else f", inner {len(skull.inner_mesh.faces):,}"
        moved = float(np.max(np.abs(skull.landmark_shifts_mm)))
        lines.append(
            f"- the skull from imaging: outer mesh {len(skull.outer_mesh.faces):,} triangles"
            f"{inner}; landmarks moved onto it by at most {moved:.3f} mm"
        )
    if skull.registration_rms_mm is not None:
        line = f"- image-to-robot registration: RMS error {skull.registration_rms_mm:.3f} mm"
        if skull.fiducial_residuals_mm is not None:
            residuals = ", ".join(f"{r:.3f}" for r in skull.fiducial_residuals_mm)
            line += f" (each fiducial's residual: {residuals} mm)"
        lines.append(line)
    return lines


def comparison_markdown(problem: Problem, outcomes: Sequence[Outcome]) -> str:
    """The problem and its limits, the table, then each planner's violations or error."""
    report = next((o.report for o in outcomes if o.report is not None), None)
    lines = [
        f"# Planner comparison: {problem.name}",
        "",
        problem.description or "",
        "",
        f"- problem file: {problem.source or '(built in code)'}"
        + (f" (sha256 {problem.source_sha256[:12]}…)" if problem.source_sha256 else ""),
        f"- landmarks, in visiting order: {' → '.join(problem.visit_names)}",
        f"- contour length: {problem.contour.length / MM:.2f} mm; the limits allow no cut "
        "along it in less than "
        + (f"{report.duration_lower_bound_s:.2f} s" if report else "(no plan evaluated)"),
        f"- segment durations in the problem (fixed-time planners): "
        f"{', '.join(f'{d:g}' for d in problem.segment_durations)} s",
        *_skull_lines(problem),
        "",
        "Limits every plan is judged by:",
        "",
        *_limits_lines(problem),
        "",
        limits.tolerance_note(),
        "",
    ]
    rows = [outcome.row() for outcome in outcomes]
    lines += markdown_table(
        [COLUMN[name].heading for name in SHOWN],
        [[COLUMN[name].show(row[name]) for name in SHOWN] for row in rows],
    )
    lines += ["", *_shared_durations(outcomes)]
    lines += ["", "## Violations and failures", ""]
    for outcome in outcomes:
        if outcome.error:
            lines.append(f"- **{outcome.planner}** failed: {outcome.error}")
        elif outcome.report is not None and outcome.report.violations:
            found = "; ".join(str(v) for v in outcome.report.violations)
            lines.append(f"- **{outcome.planner}**: {found}")
        else:
            lines.append(f"- **{outcome.planner}**: no limit is violated")
    return "\n".join(lines) + "\n"


def write_comparison(
    problem: Problem, outcomes: Sequence[Outcome], out_dir: str | Path
) -> list[Path]:
    """Write comparison.csv, comparison.md and the figures into ``out_dir``, all or none;
    return the paths."""
    from spm_opt.report import comparison_figures as figures
    from spm_opt.report.plots import to_png

    out = Path(out_dir)
    contents: dict[Path, str | bytes] = {
        out / "comparison.csv": comparison_table(outcomes).to_csv(index=False),
        out / "comparison.md": comparison_markdown(problem, outcomes),
    }
    planned = [o for o in outcomes if o.trajectory is not None]
    if planned:
        drawn = {
            "joints.png": figures.joints(problem, planned),
            "torques.png": figures.torques(problem, planned),
            "tool_speed.png": figures.tool_speed(problem, planned),
            "cuts.png": figures.cuts(problem, planned),
            "headline.png": figures.headline(problem, planned),
        }
        contents.update({out / name: to_png(figure) for name, figure in drawn.items()})
    write_atomically(contents)
    return sorted(contents)
