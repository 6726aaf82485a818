"""The review's view for documents, drawn with matplotlib: the robot at the plan's start over
the skull, beside a close-up of the flap with the planned cut coloured by its distance from
the contour and the executed cut, mm in the robot's frame."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from spm_opt.model.params import MM
from spm_opt.report.planner_style import labelled_handles, new_figure
from spm_opt.report.review_scene import ReviewScene, decimate, review_scene
from spm_opt.report.robot_geometry import robot_pose

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d import Axes3D

    from spm_opt.problem import Problem
    from spm_opt.skull.surface import Skull
    from spm_opt.trajectory import Trajectory

MAX_DRAWN_FACES = 3000
"""The skull's patch is decimated to this many faces for matplotlib."""
SKULL_GREY = "0.82"
CUT_COLOURS = "plasma"
"""The colour map of the planned cut's distance from the contour."""
_PARTS = (
    ("upper_arc", "upper arc (θ1)", "tab:blue", 2.5),
    ("lower_arc", "lower arc (θ2)", "tab:orange", 2.5),
    ("upper_platform", "upper platform", "tab:blue", 1.5),
    ("lower_platform", "lower platform", "tab:orange", 1.5),
    ("tool", "tool", "0.15", 1.5),
)
"""Each of the robot's parts: its field, label, colour and line width."""


def review_png(
    problem: Problem, skull: Skull, trajectory: Trajectory, log: pd.DataFrame | None = None
) -> bytes:
    """The review's view as PNG bytes (:func:`review_png_figure` of the plan's scene; with
    ``log``, an execution log's table, its measured cut too)."""
    from spm_opt.plots import to_png

    return to_png(
        review_png_figure(problem, review_scene(problem, skull, trajectory, log), trajectory)
    )


def review_png_figure(problem: Problem, scene: ReviewScene, trajectory: Trajectory) -> Figure:
    """The figure: the robot at the plan's start (left) and the flap close up (right), one
    legend below them and the colour bar of the planned cut's distance from the contour."""
    figure = new_figure((12.0, 6.2))
    robot_axis = figure.add_subplot(1, 2, 1, projection="3d")
    flap_axis = figure.add_subplot(1, 2, 2, projection="3d")
    faces = _skull_polygons(scene)
    _draw_robot(robot_axis, problem, scene, trajectory, faces)
    colours = _draw_flap(flap_axis, scene, faces)
    bar = figure.colorbar(colours, ax=flap_axis, shrink=0.6, pad=0.08)
    bar.set_label("planned cut off the contour (mm)")
    handles = labelled_handles([robot_axis, flap_axis])
    figure.legend(handles.values(), handles.keys(), loc="outside lower center", ncols=5, fontsize=8)
    planner = trajectory.metadata.get("planner") or "plan"
    figure.suptitle(f"{problem.name}: the {planner} cut on the skull")
    return figure


def _skull_polygons(scene: ReviewScene) -> np.ndarray:
    """The skull's triangles (F, 3, 3), mm, at most :data:`MAX_DRAWN_FACES` of them."""
    vertices, faces = decimate(scene.skull_vertices, scene.skull_faces, MAX_DRAWN_FACES)
    return vertices[faces]


def _add_skull(axis: Axes3D, polygons: np.ndarray) -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    axis.add_collection3d(
        Poly3DCollection(
            polygons, facecolor=SKULL_GREY, edgecolor="0.7", linewidth=0.1, label="skull"
        )
    )


def _draw_robot(
    axis: Axes3D,
    problem: Problem,
    scene: ReviewScene,
    trajectory: Trajectory,
    skull: np.ndarray,
) -> None:
    """The robot at the plan's start over the skull and the planned contour."""
    _add_skull(axis, skull)
    pose = robot_pose(problem.robot, trajectory.position([trajectory.start_time])[0])
    for field, label, colour, width in _PARTS:
        axis.plot(*(getattr(pose, field) / MM).T, color=colour, linewidth=width, label=label)
    axis.plot(*scene.contour.T, color="tab:green", linewidth=1.5, label="planned contour")
    reach = max(problem.robot.upper_arc.rail_radius, problem.robot.upper_platform_radius) / MM
    axis.set(xlim=(-reach, reach), ylim=(-reach, reach), zlim=(0.0, reach))
    axis.set_box_aspect((2.0, 2.0, 1.0))
    _finish(axis, scene, f"the robot at the plan's start, t = {trajectory.start_time:g} s")


def _draw_flap(axis: Axes3D, scene: ReviewScene, skull: np.ndarray) -> object:
    """The flap close up: the skull, the contour, the landmarks, the planned cut coloured
    by its distance from the contour, the executed cut; returns the planned cut's lines
    (for the colour bar)."""
    from matplotlib import colormaps
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    planned = scene.planned
    cut = np.vstack([scene.contour, planned.points])
    middle = 0.5 * (cut.min(axis=0) + cut.max(axis=0))
    half = 0.6 * float(np.max(cut.max(axis=0) - cut.min(axis=0)))
    inside = np.all(np.abs(skull - middle) <= half, axis=(1, 2))
    _add_skull(axis, skull[inside])
    axis.plot(*scene.contour.T, color="tab:green", linewidth=1.2, linestyle="--")
    segments = np.stack([planned.points[:-1], planned.points[1:]], axis=1)
    lines = Line3DCollection(segments, cmap=CUT_COLOURS, linewidth=2.5)
    lines.set_array(0.5 * (planned.deviation[:-1] + planned.deviation[1:]))
    lines.set_clim(0.0, max(float(np.max(planned.deviation)), 1e-3))
    axis.add_collection3d(lines)
    proxy = colormaps[CUT_COLOURS](0.6)
    axis.plot([], [], [], color=proxy, linewidth=2.5, label="planned cut (colour: off the contour)")
    if scene.executed is not None:
        axis.plot(*scene.executed.points.T, color="tab:cyan", linewidth=1.2, label="executed cut")
    axis.scatter(*scene.landmarks.T, color="black", marker="D", s=18, label="landmarks")
    for name, point in zip(scene.landmark_names, scene.landmarks, strict=True):
        axis.text(*(point * 1.03), name, fontsize=9)
    axis.set(
        xlim=(middle[0] - half, middle[0] + half),
        ylim=(middle[1] - half, middle[1] + half),
        zlim=(middle[2] - half, middle[2] + half),
    )
    axis.set_box_aspect((1.0, 1.0, 1.0))
    axis.computed_zorder = False
    executed = "" if scene.executed is None else " and the executed cut"
    _finish(axis, scene, f"the flap: the planned cut{executed}")
    return lines


def _finish(axis: Axes3D, scene: ReviewScene, title: str) -> None:
    """Axis labels in mm, the title, and a view from outside, over the flap."""
    direction = scene.flap_direction
    azimuth = np.degrees(np.arctan2(direction[1], direction[0]))
    if np.hypot(direction[0], direction[1]) < 1e-6:
        azimuth = 180.0
    axis.view_init(elev=45.0, azim=float(azimuth))
    axis.set(xlabel="x (mm)", ylabel="y (mm)", zlabel="z (mm)")
    axis.set_title(title, fontsize=10)
