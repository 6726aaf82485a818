"""Draw docs/img/frames.png: the base frame, the isocenter, what θ1 and θ2 turn, and the
paper's bone flap, from the model's own kinematics and the paper's problem file.

    python docs/scripts/frames_figure.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from spm_opt.model import kinematics
from spm_opt.problem.problem import Problem, load_problem
from spm_opt.report.figure_rules import mark_top_view
from spm_opt.report.plots import skull_wireframe

ROOT = Path(__file__).resolve().parents[2]
FIGURE = ROOT / "docs" / "img" / "frames.png"
POSE_LANDMARK = "A3"
"""The landmark at which the arcs are drawn."""
MM = 1e3


def _rotation_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rotation_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def arcs(problem: Problem, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two input arcs' rails (N, 3), mm, at joint angles q: the upper arc in the x–z
    plane turned about x by θ1, the lower arc in the y–z plane turned about y by θ2."""
    phi = np.linspace(0.0, np.pi, 90)
    half_circle_xz = np.stack([np.cos(phi), np.zeros_like(phi), np.sin(phi)], axis=1)
    half_circle_yz = np.stack([np.zeros_like(phi), np.cos(phi), np.sin(phi)], axis=1)
    robot = problem.robot
    upper = half_circle_xz @ _rotation_x(q[0]).T * robot.upper_arc.rail_radius * MM
    lower = half_circle_yz @ _rotation_y(q[1]).T * robot.lower_arc.rail_radius * MM
    return upper, lower


def contour_mm(problem: Problem) -> np.ndarray:
    """The planned cut (N, 3), mm."""
    contour = problem.contour
    return contour.point_at(np.linspace(0.0, contour.length, 400)) * MM


def draw_3d(axis: Axes, problem: Problem) -> None:
    """The arcs at the pose that cuts at :data:`POSE_LANDMARK`, the tool's line to the
    isocenter, the skull and the flap."""
    index = problem.landmark_names.index(POSE_LANDMARK)
    q = problem.landmark_angles[index]
    upper, lower = arcs(problem, q)
    b = kinematics.forward_kinematics(q[None, :], problem.robot.upper_platform_radius)[0] * MM
    skull_wireframe(axis, float(np.linalg.norm(problem.landmarks[0])) * MM)
    axis.plot(*upper.T, color="tab:blue", linewidth=2.5, label="upper arc (θ1, about x)")
    axis.plot(*lower.T, color="tab:orange", linewidth=2.5, label="lower arc (θ2, about y)")
    axis.plot(*np.stack([b, np.zeros(3)]).T, color="k", linestyle="--", label="tool, at B")
    axis.plot(*contour_mm(problem).T, color="tab:red", linewidth=2, label="the paper's flap")
    axis.scatter(*b, color="k", s=20)
    axis.scatter(0, 0, 0, color="tab:green", s=40, label="isocenter (origin)")
    for direction, name in zip(np.eye(3) * 120, "xyz", strict=True):
        axis.quiver(0, 0, 0, *direction, color="0.3", arrow_length_ratio=0.08)
        axis.text(*(direction * 1.12), name, fontsize=11)
    axis.text(-175, -40, 0, "anterior\n(−x, assumed)", color="tab:purple", ha="center")
    axis.set_title(f"The arcs where the tool cuts at {POSE_LANDMARK}")
    axis.set(xlabel="x (mm)", ylabel="y (mm)", zlabel="z (mm)")
    axis.set_box_aspect((2, 2, 1))
    axis.set(xlim=(-170, 170), ylim=(-170, 170), zlim=(0, 170))
    axis.view_init(elev=22, azim=-60)
    axis.legend(loc="upper left", fontsize=8)


def draw_top(axis: Axes, problem: Problem) -> None:
    """The flap seen from above, with the directions in which +θ1 and +θ2 move the cut."""
    skull = float(np.linalg.norm(problem.landmarks[0])) * MM
    angle = np.linspace(0.0, 2 * np.pi, 200)
    axis.plot(
        skull * np.cos(angle),
        skull * np.sin(angle),
        color="0.7",
        label="rim of a sphere through A1",
    )
    cut = contour_mm(problem)
    axis.plot(cut[:, 0], cut[:, 1], color="tab:red", linewidth=2, label="planned cut")
    for name, point in zip(problem.landmark_names, problem.landmarks * MM, strict=True):
        axis.plot(point[0], point[1], "o", color="tab:red")
        axis.annotate(name, point[:2], textcoords="offset points", xytext=(5, 5))
    arrow = {"width": 0.6, "head_width": 3.0, "length_includes_head": True}
    axis.arrow(0, 0, 0, -25, color="tab:blue", **arrow)
    axis.text(2, -30, "+θ1 moves the cut to −y", color="tab:blue")
    axis.arrow(0, 0, 25, 0, color="tab:orange", **arrow)
    axis.text(27, 2, "+θ2 moves\nthe cut to +x", color="tab:orange")
    axis.plot(0, 0, "+", color="tab:green", markersize=12, label="isocenter, 68 mm below A1")
    axis.set(xlabel="x (mm)", ylabel="y (mm)", aspect="equal")
    axis.set_title("Seen from above (z towards you; +y: the patient's right)")
    mark_top_view(axis)
    axis.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncols=3, fontsize=8)


def frames_figure(problem: Problem) -> Figure:
    """The figure: the arcs in 3-D beside the flap seen from above."""
    figure = Figure(figsize=(13, 6), layout="tight")
    draw_3d(figure.add_subplot(1, 2, 1, projection="3d"), problem)
    draw_top(figure.add_subplot(1, 2, 2), problem)
    return figure


def main() -> None:
    figure = frames_figure(load_problem(ROOT / "problems" / "craniotomy_bone_flap.toml"))
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(FIGURE, dpi=110, metadata={"Software": None})
    print(FIGURE.relative_to(ROOT))


if __name__ == "__main__":
    main()
