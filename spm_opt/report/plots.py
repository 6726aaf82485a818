"""The figures, drawn with matplotlib's object interface (no pyplot, no global state)."""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.model.params import DEG, MM
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.report.figure_rules import mark_top_view

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

_JOINT_COLOURS = ("tab:blue", "tab:orange")


def to_png(figure: Figure, dpi: int = 150) -> bytes:
    """The figure as PNG bytes."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    return buffer.getvalue()


REST_STEP = 0.01
"""How far inside a plan :func:`moving_grid` moves its two ends, a fraction of the grid's
interval (a plan's last piece may be far shorter than that: 1e-7 s)."""


def moving_grid(trajectory: Trajectory, rate_hz: float) -> np.ndarray:
    """The trajectory's time grid at ``rate_hz``, s, its two ends moved :data:`REST_STEP`
    of an interval inside (and any sample beyond them dropped): a plan starts and ends at
    rest, where the Coulomb friction has no direction (the model's sign of a rate is 0
    there, or the sign of a rounding residue), so torques drawn on the plain grid end in a
    drop to the torque at rest; on this grid they end in the torque that starts and stops
    the motion."""
    t = trajectory.time_grid(rate_hz)
    inside = REST_STEP / rate_hz
    return np.unique(np.clip(t, t[0] + inside, t[-1] - inside))


def _legend_beside(axis: Axes) -> None:
    """The axis's legend to its right, outside the plot: it covers no data."""
    axis.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8)


def joints_figure(trajectory: Trajectory, title: str, rate_hz: float = 200.0) -> Figure:
    """Joint angles (deg) and joint rates (deg/s) over time, as the paper's Fig. 8a."""
    from matplotlib.figure import Figure

    t = trajectory.time_grid(rate_hz)
    q, qd = trajectory.position(t) / DEG, trajectory.velocity(t) / DEG
    figure = Figure(figsize=(8, 6), layout="constrained")
    angles, rates = figure.subplots(2, 1, sharex=True)
    for joint, colour in enumerate(_JOINT_COLOURS):
        label = f"θ{joint + 1}"
        angles.plot(t, q[:, joint], color=colour, label=label)
        rates.plot(t, qd[:, joint], color=colour, label=f"dθ{joint + 1}/dt")
    landmark_times = trajectory.landmark_times
    for axis in (angles, rates):
        if landmark_times is not None:
            for time in landmark_times:
                axis.axvline(time, color="0.8", linewidth=0.8, zorder=0)
        axis.grid(True, alpha=0.3)
        axis.legend(loc="best")
    angles.set_ylabel("joint angle (deg)")
    rates.set_ylabel("joint rate (deg/s)")
    rates.set_xlabel("time (s)")
    figure.suptitle(title)
    return figure


def skull_wireframe(axis: Axes, radius_mm: float, label: str | None = None) -> None:
    """Draw the skull as the upper hemisphere of ``radius_mm`` about the isocenter, in grey,
    on a 3-D ``axis`` whose unit is mm."""
    azimuth, polar = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(0, np.pi / 2, 13))
    axis.plot_wireframe(
        radius_mm * np.cos(azimuth) * np.sin(polar),
        radius_mm * np.sin(azimuth) * np.sin(polar),
        radius_mm * np.cos(polar),
        color="0.75",
        linewidth=0.4,
        label=label,
    )


def path_figure(problem: Problem, trajectory: Trajectory, rate_hz: float = 50.0) -> Figure:
    """The platform path and its cut on the skull in 3-D, as the paper's Fig. 8b.

    Draws the skull (a sphere of the landmarks' mean radius), the planned contour, the cut,
    the platform path B(t) on its sphere, the landmarks A_i and their projections B_i.
    """
    from matplotlib.figure import Figure

    t = trajectory.time_grid(rate_hz)
    r_u = problem.robot.upper_platform_radius
    platform = trajectory.platform_points(t, r_u) / MM
    cut = trajectory.cut_points(problem.contour, t) / MM
    contour = problem.contour.point_at(np.linspace(0.0, problem.contour.length, 400)) / MM
    landmarks, projected = problem.landmarks / MM, problem.platform_points / MM

    figure = Figure(figsize=(15, 7), layout="constrained")
    axis = figure.add_subplot(1, 2, 1, projection="3d")
    skull_radius = float(np.mean(np.linalg.norm(landmarks, axis=1)))
    skull_wireframe(axis, skull_radius, label=f"skull (sphere, r = {skull_radius:.1f} mm)")
    axis.plot(*platform.T, color="tab:blue", label=f"platform path B(t), r_u = {r_u / MM:g} mm")
    axis.plot(*contour.T, color="tab:green", linestyle="--", linewidth=2, label="planned contour")
    axis.plot(*cut.T, color="tab:red", label="cut on the skull")
    for index, (name, a, b) in enumerate(
        zip(problem.landmark_names, landmarks, projected, strict=True)
    ):
        axis.plot(*np.stack([[0, 0, 0], b]).T, color="0.5", linewidth=0.6, linestyle=":")
        axis.text(*a, f" {name}", fontsize=9)
        axis.text(*b, f" B{index + 1}", fontsize=9)
    axis.scatter(*landmarks.T, color="black", s=18, label="landmarks A_i", depthshade=False)
    axis.scatter(
        *projected.T, color="tab:blue", s=18, marker="s", label="projections B_i", depthshade=False
    )
    axis.scatter([0], [0], [0], color="black", marker="+", s=60, label="isocenter")
    axis.set_xlabel("x (mm)")
    axis.set_ylabel("y (mm)")
    axis.set_zlabel("z (mm)")
    axis.set_box_aspect((1, 1, 0.6))
    axis.view_init(elev=35, azim=-120)
    axis.set_title(
        f"{problem.name}: platform path and its cut on the skull "
        f"({trajectory.metadata.get('planner', 'plan')})"
    )
    axis.legend(loc="upper left", fontsize=8)
    _top_view(figure.add_subplot(1, 2, 2), problem, contour, cut)
    return figure


def _top_view(axis, problem: Problem, contour: np.ndarray, cut: np.ndarray) -> None:  # noqa: ANN001
    """The cut and the planned contour seen from above (x-y, mm), with the landmarks."""
    landmarks = problem.landmarks / MM
    axis.plot(
        contour[:, 0],
        contour[:, 1],
        color="tab:green",
        linestyle="--",
        linewidth=2,
        label="planned contour",
    )
    axis.plot(cut[:, 0], cut[:, 1], color="tab:red", label="cut on the skull")
    axis.scatter(landmarks[:, 0], landmarks[:, 1], color="black", s=20, zorder=3)
    for name, (x, y, _) in zip(problem.landmark_names, landmarks, strict=True):
        axis.annotate(name, (x, y), textcoords="offset points", xytext=(5, 5))
    axis.set_aspect("equal")
    axis.grid(True, alpha=0.3)
    axis.set_xlabel("x (mm)")
    axis.set_ylabel("y (mm)")
    axis.set_title("seen from above")
    axis.legend(loc="best", fontsize=8)
    mark_top_view(axis)


def torques_figure(
    t: np.ndarray, torque: np.ndarray, with_friction: np.ndarray, differences: dict[str, np.ndarray]
) -> Figure:
    """Fig. 13: actuator torques without friction (and with the prototype's), and the
    differences to the independent checks, all in N·m over time in s."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10, 7), layout="constrained")
    axes = figure.subplots(2, 2, sharex=True)
    for joint, colour in enumerate(_JOINT_COLOURS):
        top, bottom = axes[0, joint], axes[1, joint]
        top.plot(t, torque[:, joint], color=colour, label="Lagrange, no friction (Table IV)")
        top.plot(
            t,
            with_friction[:, joint],
            color=colour,
            linestyle="--",
            alpha=0.7,
            label="with friction, μ = 0.24",
        )
        top.set_title(f"torque {joint + 1}")
        top.set_ylabel("torque (N·m)")
        top.legend(fontsize=8)
        for (name, difference), style in zip(differences.items(), ("-", ":"), strict=False):
            bottom.plot(t, difference[:, joint], linestyle=style, label=f"Lagrange − {name}")
        bottom.set_title(f"torque {joint + 1}: the independent checks' differences")
        bottom.set_ylabel("difference (N·m)")
        bottom.set_xlabel("time (s)")
        for axis in (top, bottom):
            axis.grid(True, alpha=0.3)
    figure.legend(*axes[1, 0].get_legend_handles_labels(), loc="outside lower center", ncol=2)
    figure.suptitle("Fig. 13: actuator torques over the paper's trajectory")
    return figure


def friction_figure(
    t: np.ndarray, upper: np.ndarray, lower: np.ndarray, torque: np.ndarray, mu: float
) -> Figure:
    """Fig. 14: friction forces on the platforms per unit μ (N at μ = 1, by component:
    friction is proportional to μ, so they read for any rail material), and the actuator
    torque they cost with the robot's own μ (N·m)."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10, 8), layout="constrained")
    axes = figure.subplots(3, 1, sharex=True)
    for axis, force, name in (
        (axes[0], upper, "F_fu, upper platform"),
        (axes[1], lower, "F_fl, lower platform"),
    ):
        for component, label in enumerate("xyz"):
            axis.plot(t, force[:, component], label=f"{label} component")
        axis.set_ylabel("force at μ = 1 (N)")
        axis.set_title(f"{name}: friction force per unit μ")
        _legend_beside(axis)
    for joint, colour in enumerate(_JOINT_COLOURS):
        axes[2].plot(t, torque[:, joint], color=colour, label=f"actuator {joint + 1}")
    axes[2].set_title(f"torque that friction costs the actuators at the robot's μ = {mu:g}")
    axes[2].set_ylabel("torque (N·m)")
    axes[2].set_xlabel("time (s)")
    _legend_beside(axes[2])
    for axis in axes:
        axis.grid(True, alpha=0.3)
    figure.suptitle(
        "Fig. 14: friction along the paper's trajectory\n"
        "forces at μ = 1 (friction is proportional to μ: scale them to any rail material); "
        f"torques at the robot's μ = {mu:g}",
        fontsize=11,
    )
    return figure
