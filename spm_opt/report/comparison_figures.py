"""The comparison's figures: every planner's plan on the same axes, one colour and line
style each.

They take the plans as :class:`Planned` objects (the comparison's ``Outcome`` is one),
each with a trajectory and the evaluator's report, and never import the comparison.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol

import numpy as np

from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.problem.problem import Problem
from spm_opt.report.columns import column
from spm_opt.report.figure_rules import mark_top_view
from spm_opt.report.planner_style import (
    Limit,
    contour_tubes,
    labelled_handles,
    metric_label,
    new_figure,
    planner_style,
)
from spm_opt.report.plots import moving_grid

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from spm_opt.problem.trajectory import Trajectory


class Measured(Protocol):
    """What the headline figure reads of a plan's evaluation (the evaluator's ``Report``)."""

    @property
    def duration_over_lower_bound(self) -> float: ...
    @property
    def duration_lower_bound_s(self) -> float: ...
    @property
    def max_contour_deviation_mm(self) -> float: ...
    @property
    def max_tool_speed_mm_s(self) -> float: ...
    @property
    def rms_jerk_rad_s3(self) -> Sequence[float]: ...
    @property
    def effort_n2m2s(self) -> float: ...
    @property
    def violations(self) -> Sequence[object]: ...


class Planned(Protocol):
    """One planner's plan and its evaluation; the figures take only plans that have both."""

    @property
    def planner(self) -> str: ...
    @property
    def trajectory(self) -> Trajectory | None: ...
    @property
    def report(self) -> Measured | None: ...


RATE_HZ = 200.0
"""Sampling rate of the drawn curves, Hz."""
FLOOR_MM = 1e-6
"""The deviation panels' floor, mm: a cut on the contour is drawn there."""
LIMIT_LINES = (("--", "dashed"), (":", "dotted"))
"""How a panel draws its limits, the first with the first style, and the style's name."""


def _style(index: int, samples: int) -> dict[str, object]:
    """The ``index``-th planner's line of ``samples`` points: its colour, line style and
    ten markers, shifted per planner so that no two planners' markers coincide."""
    step = max(1, samples // 10)
    return {
        **planner_style(index),
        "markevery": ((index * step // 7) % step, step),
        "markersize": 5,
        "markerfacecolor": "none",
    }


def _legend_below(figure: Figure, *axes: Axes) -> None:
    """The figure's legend, from ``axes``' labelled lines (each label once), below the
    panels."""
    handles = labelled_handles(axes)
    figure.legend(
        list(handles.values()), list(handles), loc="outside lower center", ncol=min(len(handles), 5)
    )


def _samples(
    outcome: Planned, moving: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """t (N,), s, and q, q̇, q̈ (N, 2) of a plan on the drawing grid; ``moving``: its ends
    just inside the plan, where it moves (:func:`spm_opt.report.plots.moving_grid`)."""
    trajectory = outcome.trajectory
    assert trajectory is not None
    t = moving_grid(trajectory, RATE_HZ) if moving else trajectory.time_grid(RATE_HZ)
    return t, trajectory.position(t), trajectory.velocity(t), trajectory.acceleration(t)


def _cut_progress(problem: Problem, outcome: Planned) -> tuple[np.ndarray, np.ndarray]:
    """Distance cut so far (N,), mm, and the tool speed (N,), mm/s, on the drawing grid."""
    t, q, qd, _ = _samples(outcome)
    speed = problem.contour.joint_tool_speed(q, qd) / MM
    distance = np.concatenate([[0.0], np.cumsum(np.diff(t) * (speed[1:] + speed[:-1]) / 2)])
    return distance, speed


def joints(problem: Problem, outcomes: Sequence[Planned]) -> Figure:
    """Joint angles (deg) over time (s), one colour per planner."""
    figure = new_figure((10, 6))
    axes = figure.subplots(2, 1, sharex=True)
    for index, outcome in enumerate(outcomes):
        t, q, _, _ = _samples(outcome)
        for joint, axis in enumerate(axes):
            axis.plot(t, q[:, joint] / DEG, **_style(index, len(t)), label=outcome.planner)
    for joint, axis in enumerate(axes):
        axis.set_ylabel(f"θ{joint + 1} (deg)")
        axis.grid(True, alpha=0.3)
    _legend_below(figure, axes[0])
    axes[1].set_xlabel("time (s)")
    figure.suptitle(f"{problem.name}: joint angles")
    return figure


def torques(problem: Problem, outcomes: Sequence[Planned]) -> Figure:
    """Actuator torques (N·m, the model with exact friction) over time (s), from the first
    instant of motion to the last (at rest, the friction has no direction)."""
    figure = new_figure((10, 6))
    axes = figure.subplots(2, 1, sharex=True)
    for index, outcome in enumerate(outcomes):
        t, q, qd, qdd = _samples(outcome, moving=True)
        torque = dynamics.actuator_torque(problem.robot, q, qd, qdd)
        for joint, axis in enumerate(axes):
            axis.plot(t, torque[:, joint], **_style(index, len(t)), label=outcome.planner)
    for joint, axis in enumerate(axes):
        axis.set_ylabel(f"τ{joint + 1} (N·m)")
        axis.grid(True, alpha=0.3)
    _legend_below(figure, axes[0])
    axes[1].set_xlabel("time (s)")
    figure.suptitle(
        f"{problem.name}: actuator torques (limit {problem.max_joint_torque:g} N·m, off scale)"
    )
    return figure


def tool_speed(problem: Problem, outcomes: Sequence[Planned]) -> Figure:
    """The tool's speed on the skull (mm/s) against the distance cut so far (mm), with the
    limit and the landmarks' places along the contour."""
    figure = new_figure((10, 4.5))
    axis = figure.subplots()
    for index, outcome in enumerate(outcomes):
        distance, speed = _cut_progress(problem, outcome)
        axis.plot(distance, speed, **_style(index, len(speed)), label=outcome.planner)
    for place, name in zip(
        problem.contour.landmark_arc_lengths / MM, problem.visit_names, strict=True
    ):
        axis.axvline(place, color="0.8", linewidth=0.8, zorder=0)
        axis.annotate(name, (place, 0.0), textcoords="offset points", xytext=(2, 2), fontsize=8)
    if problem.limits.max_tool_speed is not None:
        axis.axhline(
            problem.limits.max_tool_speed / MM, color="black", linestyle="--", label="limit"
        )
    axis.set_xlabel("distance cut so far (mm)")
    axis.set_ylabel("tool speed (mm/s)")
    axis.grid(True, alpha=0.3)
    _legend_below(figure, axis)
    axis.set_title(f"{problem.name}: tool speed along the cut")
    return figure


def cuts(problem: Problem, outcomes: Sequence[Planned]) -> Figure:
    """Left: every cut on the skull seen from above (mm), the planned contour drawn over
    them, the landmarks and the anterior direction. Right: each cut's distance from the
    contour (mm, log scale) against the place along the contour it is nearest to (mm),
    with the landmarks and the tubes a plan and an executed cut must keep within: cuts a
    tenth of a millimetre apart, one on the other at the left, stand apart there."""
    figure = new_figure((13, 7))
    top, off = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.3]})
    contour = problem.contour
    for index, outcome in enumerate(outcomes):
        _, q, _, _ = _samples(outcome)
        directions = kinematics.forward_kinematics(q, 1.0)
        near = contour.nearest(directions)
        radius = contour.surface.radius(directions)
        cut = radius[:, None] * directions / MM
        style = _style(index, len(q))
        top.plot(cut[:, 0], cut[:, 1], **style, linewidth=1, label=outcome.planner)
        along, deviation = contour.progress(near) / MM, contour.distance(near, radius) / MM
        off.semilogy(along, np.maximum(deviation, FLOOR_MM), **style, linewidth=1)
    _contour_from_above(top, problem)
    _deviation_axes(off, problem)
    _legend_below(figure, top, off)
    figure.suptitle(f"{problem.name}: the planned contour and every planner's cut")
    return figure


def _contour_from_above(axis: Axes, problem: Problem) -> None:
    """The planned contour over the cuts, the landmarks and the anterior arrow (x-y, mm)."""
    contour = problem.contour
    planned = contour.point_at(np.linspace(0.0, contour.length, 2000)) / MM
    axis.plot(*planned[:, :2].T, color="black", linewidth=1.2, zorder=4, label="planned contour")
    landmarks = problem.landmarks / MM
    axis.scatter(landmarks[:, 0], landmarks[:, 1], color="black", s=20, zorder=5)
    for name, (x, y, _) in zip(problem.landmark_names, landmarks, strict=True):
        axis.annotate(name, (x, y), textcoords="offset points", xytext=(5, 5))
    axis.set_aspect("equal")
    axis.set_xlabel("x (mm)")
    axis.set_ylabel("y (mm)")
    axis.set_title("seen from above (the contour in black, on top)", fontsize=10)
    axis.grid(True, alpha=0.3)
    mark_top_view(axis)


def _deviation_axes(axis: Axes, problem: Problem) -> None:
    """The deviation panel's landmarks, contour tubes, floor and words."""
    for place, name in zip(
        problem.contour.landmark_arc_lengths / MM, problem.visit_names, strict=True
    ):
        axis.axvline(place, color="0.75", linewidth=0.8, zorder=0)
        axis.annotate(
            name,
            (place, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(2, -10),
            textcoords="offset points",
            fontsize=8,
        )
    for (style, _), tube in zip(LIMIT_LINES, contour_tubes(problem), strict=False):
        axis.axhline(tube.value, color="black", linestyle=style, linewidth=1, label=tube.words)
    axis.set_xlabel("place along the planned contour (mm)")
    axis.set_ylabel("distance from the planned contour (mm)")
    axis.set_title(
        f"how far each cut strays (on the contour: drawn at {FLOOR_MM:g} mm)", fontsize=10
    )
    axis.grid(True, alpha=0.3)


_HEADLINES: tuple[tuple[str, Callable[[Measured], float], bool], ...] = (
    # (column, its value in a report, log scale)
    ("duration_over_lower_bound", lambda r: r.duration_over_lower_bound, False),
    ("max_contour_deviation_mm", lambda r: r.max_contour_deviation_mm, True),
    ("max_tool_speed_mm_s", lambda r: r.max_tool_speed_mm_s, False),
    ("rms_jerk_rad_s3", lambda r: max(r.rms_jerk_rad_s3), False),
    ("effort_n2m2s", lambda r: r.effort_n2m2s, False),
    ("violation_count", lambda r: len(r.violations), False),
)


def _headline_limits(problem: Problem, lower_bound_s: float) -> dict[str, list[Limit]]:
    """The limits the headline panels draw, by column, in the column's unit."""
    drawn = {
        "duration_over_lower_bound": [
            Limit(1.0, f"1, the lower bound ({lower_bound_s:.2f} s)"),
        ],
        "max_contour_deviation_mm": contour_tubes(problem),
    }
    speed = problem.limits.max_tool_speed
    if speed is not None:
        drawn["max_tool_speed_mm_s"] = [Limit(speed / MM, f"limit {speed / MM:.4g} mm/s")]
    return drawn


def _headline_notes(problem: Problem) -> dict[str, str]:
    """What the headline panels without a drawn limit say instead, by column."""
    jerk = problem.limits.max_joint_jerk
    return {
        "rms_jerk_rad_s3": "no limit: the RMS has none"
        + ("" if jerk is None else f" (the {jerk:.4g} rad/s³ limit bounds the peak)"),
        "effort_n2m2s": "no limit",
        "violation_count": "a clean plan has 0",
        "max_tool_speed_mm_s": "no limit: the problem sets none",
        "max_contour_deviation_mm": "no tube: the problem sets no contour tolerance",
    }


def _bars(axis: Axes, names: list[str], values: list[float], name: str, log: bool) -> None:
    """One bar per planner, each labelled with its value (a zero too); a log axis floors
    the bars at :data:`FLOOR_MM` and says so, a linear one starts at zero, a count's
    ticks are whole numbers."""
    from matplotlib.ticker import MaxNLocator

    drawn = np.maximum(values, FLOOR_MM) if log else values
    colours = [planner_style(k)["color"] for k in range(len(names))]
    bars = axis.bar(names, drawn, color=colours, log=log)
    shown = column(name)
    axis.bar_label(
        bars,
        [shown.show(value) for value in values],
        fontsize=7,
        padding=2,
        bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 0.5},
    )
    axis.margins(y=0.15)
    if all(isinstance(value, int) for value in values):
        axis.yaxis.set_major_locator(MaxNLocator(integer=True))
    label = metric_label(name)
    if log:
        axis.set_ylabel(f"{label}, log scale (under {FLOOR_MM:g}: at it)", fontsize=8)
    else:
        axis.set_ylim(bottom=0.0)
        axis.set_ylabel(label, fontsize=8)


def _limit_lines(axis: Axes, limits: list[Limit]) -> list[str]:
    """Draw each limit as a horizontal line; return the lines' words for the title."""
    words = []
    for (style, style_name), limit in zip(LIMIT_LINES, limits, strict=False):
        axis.axhline(limit.value, color="black", linestyle=style, linewidth=1)
        words.append(f"{style_name}: {limit.words}")
    return words


def headline(problem: Problem, outcomes: Sequence[Planned]) -> Figure:
    """Bars of the headline figures, one panel per figure, one bar per planner, each
    labelled with its value; the panels draw their limits and name them in their titles
    (a panel without one says so)."""
    figure = new_figure((14, 8.5))
    axes = figure.subplots(2, 3).ravel()
    names = [o.planner for o in outcomes]
    reports = [o.report for o in outcomes]
    limits = _headline_limits(problem, reports[0].duration_lower_bound_s)  # type: ignore[union-attr]
    notes = _headline_notes(problem)
    for axis, (name, value, log) in zip(axes, _HEADLINES, strict=True):
        _bars(axis, names, [value(r) for r in reports], name, log)  # type: ignore[arg-type]
        words = _limit_lines(axis, limits.get(name, [])) or [notes[name]]
        axis.set_title("\n".join([column(name).label, *words]), fontsize=9)
        axis.tick_params(axis="x", labelrotation=45, labelsize=8)
        axis.grid(True, axis="y", alpha=0.3)
    figure.suptitle(
        f"{problem.name}: headline figures (black lines: the limits; each title names its "
        "panel's, or says it has none)"
    )
    return figure
