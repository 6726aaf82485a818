"""The hardware verification's figures: torques (Figs. 19–20), joint paths (Fig. 15), the
platform's path seen by motion capture (Figs. 25–26) and the executed cut, holds shaded or
marked."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from spm_opt.model import kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.problem.problem import Problem
from spm_opt.report.figure_rules import mark_top_view
from spm_opt.studies.hardware_comparisons import (
    SMOOTHING_S,
    CutComparison,
    Hold,
    MotionCaptureComparison,
    RunSamples,
    model_torque,
    smoothed,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


def shade_holds(axis: Axes, samples: RunSamples) -> None:
    """Shade each stretch of run time the feed was 0, labelled once "feed hold"."""
    for k, (begin, end) in enumerate(samples.held_intervals()):
        label = "feed hold" if k == 0 else "_nolegend_"
        axis.axvspan(begin, end, color="0.88", zorder=0, label=label)


def torque_figure(problem: Problem, samples: RunSamples, joint: int) -> Figure:
    """One actuator's model and measured torques over run time (the paper's Fig. 19 or
    20), holds shaded."""
    from matplotlib.figure import Figure

    model = model_torque(problem, samples)[:, joint]
    measured = samples.measured_torque[:, joint]
    figure = Figure(figsize=(8, 4.6), layout="constrained")
    axis = figure.subplots()
    shade_holds(axis, samples)
    axis.plot(samples.t, measured, color="0.6", linewidth=0.8, label="measured (from current)")
    axis.plot(
        samples.t,
        smoothed(samples.measured_torque, samples.t)[:, joint],
        color="tab:orange",
        label=f"measured, {SMOOTHING_S:g} s moving average",
    )
    axis.plot(samples.t, model, color="tab:blue", label="model (Lagrange, friction)")
    rms = float(np.sqrt(np.mean((measured - model) ** 2)))
    axis.set_title(f"actuator {joint + 1}: torque, RMS difference {rms:.3f} N·m")
    axis.set_xlabel("run time (s)")
    axis.set_ylabel("torque (N·m)")
    axis.grid(True, alpha=0.3)
    figure.legend(*axis.get_legend_handles_labels(), loc="outside lower center", ncol=2)
    return figure


def tracking_figure(samples: RunSamples) -> Figure:
    """Planned and measured joint angles and their difference over run time (the paper's
    Fig. 15), holds shaded; below them the feed and its target if it ever left 1."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8, 7.5 if samples.feed_changed else 6), layout="constrained")
    ratios = (3, 3, 1.5) if samples.feed_changed else (1, 1)
    axes = figure.subplots(len(ratios), 1, sharex=True, height_ratios=ratios)
    angles, errors = axes[:2]
    for joint, colour in enumerate(("tab:blue", "tab:orange")):
        angles.plot(
            samples.t, samples.planned_q[:, joint] / DEG, color=colour, label=f"θ{joint + 1} plan"
        )
        angles.plot(
            samples.t,
            samples.measured_q[:, joint] / DEG,
            color=colour,
            linestyle="--",
            label=f"θ{joint + 1} measured",
        )
        errors.plot(
            samples.t,
            (samples.measured_q[:, joint] - samples.planned_q[:, joint]) / DEG,
            color=colour,
            label=f"θ{joint + 1}",
        )
    angles.set_ylabel("joint angle (deg)")
    errors.set_ylabel("measured − plan (deg)")
    if samples.feed_changed:
        _feed_panel(axes[2], samples)
    axes[-1].set_xlabel("run time (s)")
    for axis in axes:
        shade_holds(axis, samples)
        axis.grid(True, alpha=0.3)
        axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)
    figure.suptitle("Joint angles, planned (at the logged plan time) and measured (Fig. 15)")
    return figure


def _feed_panel(axis: Axes, samples: RunSamples) -> None:
    axis.plot(samples.t, samples.feed, color="k", label="feed")
    axis.plot(samples.t, samples.feed_target, color="tab:red", linestyle="--", label="target")
    axis.set_ylabel("feed (-)")
    axis.set_ylim(-0.05, max(1.0, float(np.max(samples.feed_target))) + 0.1)


def cut_figure(samples: RunSamples, cut: CutComparison, holds: list[Hold]) -> Figure:
    """Left: the executed cut and the plan's seen from above (x, y, mm). Right: the executed
    cut's distance from the plan's cut (mm) along the plan's cut (mm), where the two,
    which coincide at the scale of the cut, stand apart. Both with a numbered marker where
    each hold's feed reached 0."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(12, 5.5), layout="constrained")
    top, off = figure.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.4]})
    planned, executed = cut.planned_m / MM, cut.executed_m / MM
    along, distance = _along_plan(samples, cut), cut.distance_m / MM
    top.plot(planned[:, 0], planned[:, 1], color="tab:blue", linewidth=2.0, label="plan")
    top.plot(executed[:, 0], executed[:, 1], color="tab:red", linewidth=0.7, label="executed")
    off.plot(along, distance, color="tab:red", linewidth=0.7)
    stops = [(number, int(np.argmin(np.abs(samples.t - at)))) for number, at in _stops(holds)]
    _mark_stops(top, executed[:, :2], stops, "hold: feed at 0")
    _mark_stops(off, np.column_stack([along, distance]), stops)
    top.set_title("seen from above", fontsize=10)
    top.set_xlabel("x (mm)")
    top.set_ylabel("y (mm)")
    top.set_aspect("equal")
    mark_top_view(top)
    off.set_title("the executed cut's distance from the plan's cut", fontsize=10)
    off.set_xlabel("distance along the plan's cut (mm)")
    off.set_ylabel("distance from the plan's cut (mm)")
    for axis in (top, off):
        axis.grid(True, alpha=0.3)
    figure.legend(*top.get_legend_handles_labels(), loc="outside lower center", ncol=3)
    figure.suptitle(f"Executed cut against the plan: largest distance {cut.max_distance_mm:.3f} mm")
    return figure


def _mark_stops(
    axis: Axes, points: np.ndarray, stops: list[tuple[int, int]], label: str = "_nolegend_"
) -> None:
    """A numbered white marker at ``points[index]`` (N, 2) for each (number, index) of
    ``stops``, the first labelled ``label``."""
    for k, (number, index) in enumerate(stops):
        point = tuple(points[index])
        shown = label if k == 0 else "_nolegend_"
        axis.plot(*point, "o", color="k", markerfacecolor="white", label=shown)
        axis.annotate(str(number), point, xytext=(4, 4), textcoords="offset points")


def _stops(holds: list[Hold]) -> list[tuple[int, float]]:
    """(number from 1, run time in s) of each hold whose feed reached 0."""
    return [
        (number, hold.asked_s + hold.to_held_s)
        for number, hold in enumerate(holds, start=1)
        if hold.to_held_s is not None
    ]


def _along_plan(samples: RunSamples, cut: CutComparison) -> np.ndarray:
    """How far along the plan's cut (N,), mm, each sample's commanded point lies: the
    length of the plan's cut through the points commanded up to it (at the planned angles,
    on the skull radius of the plan's nearest point), still while the feed is held."""
    planned = cut.planned_m[::10]
    radius = np.linalg.norm(planned, axis=1)
    directions = kinematics.forward_kinematics(samples.planned_q, 1.0)
    nearest = cKDTree(planned / radius[:, None]).query(directions)[1]
    points = directions * radius[nearest, None]
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)]) / MM


def capture_figure(
    samples: RunSamples,
    problem: Problem,
    tracked_m: np.ndarray,
    comparison: MotionCaptureComparison,
) -> Figure:
    """Desired and tracked platform paths seen from above (x, y, mm), with their centroids
    (the paper's Figs. 25–26); the legend below the plot, clear of the centroids."""
    from matplotlib.figure import Figure

    desired = kinematics.forward_kinematics(samples.planned_q, problem.robot.upper_platform_radius)
    figure = Figure(figsize=(7, 6.5), layout="constrained")
    axis = figure.subplots()
    axis.plot(desired[:, 0] / MM, desired[:, 1] / MM, color="tab:blue", label="desired")
    axis.plot(
        tracked_m[:, 0] / MM,
        tracked_m[:, 1] / MM,
        color="tab:red",
        linewidth=0.6,
        alpha=0.7,
        label="tracked (motion capture, registered)",
    )
    for points, colour, name in (
        (desired, "tab:blue", "desired"),
        (tracked_m, "tab:red", "tracked"),
    ):
        centre = points.mean(axis=0) / MM
        axis.plot(*centre[:2], marker="x", markersize=10, color=colour, label=f"centroid, {name}")
    d = comparison.deviation
    axis.set_title(
        f"platform path: centroids {d.centroid_distance_mm:.3f} mm apart, RMS "
        f"{d.rms_distance_mm:.3f} mm, max {d.max_distance_mm:.3f} mm "
        f"(registration RMS {comparison.registration_rms_mm:.3f} mm)",
        fontsize=9,
    )
    axis.set_xlabel("x (mm)")
    axis.set_ylabel("y (mm)")
    axis.set_aspect("equal")
    axis.grid(True, alpha=0.3)
    mark_top_view(axis)
    figure.legend(*axis.get_legend_handles_labels(), loc="outside lower center", ncol=2)
    return figure
