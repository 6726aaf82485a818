"""The review's view for documents, drawn with matplotlib: the robot at the plan's start over
the skull, beside a close-up of the flap with the planned cut coloured by its distance from
the contour, the executed cut over it and the judge's violations marked, mm in the robot's
frame; under them, the judge's verdict on each cut with the tube it is judged against
(:mod:`spm_opt.report.review_verdict`) and the violations, numbered as marked."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.legend_handler import HandlerBase
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from spm_opt.model.params import MM
from spm_opt.report.planner_style import labelled_handles, new_figure
from spm_opt.report.review_scene import ReviewScene, decimate, review_scene
from spm_opt.report.review_verdict import (
    PLAN,
    PREDICTED,
    RUN,
    RUN_TRUE,
    Judged,
    judged_cuts,
    verdict_line,
    violation_points,
)
from spm_opt.report.robot_geometry import ROBOT_PARTS, robot_pose

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.legend import Legend
    from matplotlib.transforms import Transform
    from mpl_toolkits.mplot3d import Axes3D

    from spm_opt.judge.report import Report, Violation
    from spm_opt.problem.problem import Problem
    from spm_opt.problem.trajectory import Trajectory
    from spm_opt.report.review_inputs import ReviewInputs
    from spm_opt.skull.surface import Skull

MAX_DRAWN_FACES = 3000
"""The skull's patch is decimated to this many faces for matplotlib."""
SKULL_GREY = "0.82"
CUT_COLOURS = "plasma"
"""The colour map of the planned cut's distance from the contour."""
PLANNED_WIDTH = 4.0
"""The planned cut's line width, pt: the executed cut's thin line over it leaves its
colours showing on either side."""
EXECUTED = {"color": "black", "linewidth": 0.8, "linestyle": (0, (4, 2))}
"""How the executed cut is drawn over the planned one."""
PREDICTED_LINE = {"color": "tab:orange", "linewidth": 1.0, "linestyle": (0, (1, 1.5))}
"""How the predicted cut is drawn over the planned one."""
VIOLATION_COLOURS = {
    PLAN: "darkviolet",
    PREDICTED: "tab:pink",
    RUN: "tab:red",
    RUN_TRUE: "tab:brown",
}
"""The colour of each judged cut's violation markers and lines."""
ROBOT_ZOOM = 0.85
"""The robot's box drawn this much smaller than its panel, so that its z label stays in it."""
MAX_LISTED = 8
"""Most violations the figure numbers and lists (review.html lists them all)."""


def review_png(
    problem: Problem, skull: Skull, given: ReviewInputs, report: Report | None = None
) -> bytes:
    """The review's view as PNG bytes (:func:`review_png_figure` of the plan's scene and
    its judged cuts; with a log, its measured cut and the run's verdict too).

    Parameters
    ----------
    problem : Problem
    skull : Skull
    given : ReviewInputs
        The plan, and a log with the judge's reports of it
        (:func:`spm_opt.report.review_inputs.review_inputs`).
    report : Report, optional
        The plan's report; by default ``evaluate(problem, trajectory)``.
    """
    from spm_opt.judge.evaluate import evaluate
    from spm_opt.report.plots import to_png

    trajectory = given.trajectory
    report = evaluate(problem, trajectory) if report is None else report
    cuts = judged_cuts(problem, report, given.run, given.predicted)
    scene = review_scene(problem, skull, trajectory, given.log, given.predicted)
    return to_png(review_png_figure(problem, scene, trajectory, cuts))


def review_png_figure(
    problem: Problem, scene: ReviewScene, trajectory: Trajectory, cuts: Sequence[Judged]
) -> Figure:
    """The figure: the robot at the plan's start (left) and the flap close up (right) with
    the colour bar of the planned cut's distance from the contour, one legend below them,
    and under it the judge's verdict on each of ``cuts`` with its violations."""
    listed = _listed(cuts)
    text_height = 0.2 * (len(cuts) + len(listed)) + 0.3
    figure = new_figure((12.0, 6.4 + text_height))
    grid = figure.add_gridspec(2, 2, height_ratios=(6.4, text_height))
    robot_axis = figure.add_subplot(grid[0, 0], projection="3d")
    flap_axis = figure.add_subplot(grid[0, 1], projection="3d")
    flap_axis.patch.set_visible(False)  # its white would hide the robot's z label
    faces = _skull_polygons(scene)
    _draw_robot(robot_axis, problem, scene, trajectory, faces)
    colours = _draw_flap(flap_axis, scene, faces)
    _mark_violations(flap_axis, scene, listed)
    bar = figure.colorbar(colours, ax=flap_axis, shrink=0.6, pad=0.1)
    bar.set_label("planned cut: off the contour (mm)")
    handles = labelled_handles([robot_axis, flap_axis])
    figure.legend(
        handles.values(),
        handles.keys(),
        loc="outside lower center",
        ncols=5,
        fontsize=8,
        handler_map={Line3DCollection: _Gradient()},
    )
    _write_verdict(figure.add_subplot(grid[1, :]), cuts, listed)
    planner = trajectory.metadata.get("planner") or "plan"
    figure.suptitle(f"{problem.name}: the {planner} cut on the skull")
    return figure


def _listed(cuts: Sequence[Judged]) -> list[tuple[Judged, Violation]]:
    """The violations the figure numbers, in order: the cuts' first
    :data:`MAX_LISTED` in all."""
    every = [(cut, violation) for cut in cuts for violation in cut.report.violations]
    return every[:MAX_LISTED]


def _mark_violations(
    axis: Axes3D, scene: ReviewScene, listed: list[tuple[Judged, Violation]]
) -> None:
    """A numbered cross at the cut's point at each listed violation's time: on the planned
    cut for the plan's, on the executed cut for a run's, on the predicted cut for its."""
    for number, (cut, violation) in enumerate(listed, start=1):
        drawn = scene.drawn(cut.key)
        point = violation_points([violation], drawn.t, drawn.points)[0]
        axis.scatter(
            *point[:, None],
            color=VIOLATION_COLOURS[cut.key],
            marker="X",
            s=70,
            edgecolors="white",
            linewidths=0.6,
            depthshade=False,
            label=f"violations, {cut.label}",
        )
        axis.text(*point, f" {number}", color=VIOLATION_COLOURS[cut.key], fontsize=10)


def _write_verdict(
    axis: Axes, cuts: Sequence[Judged], listed: list[tuple[Judged, Violation]]
) -> None:
    """The judge's verdict on each cut, one line each, then the numbered violations."""
    axis.set_axis_off()
    axis.set(xticks=[], yticks=[])
    every = sum(len(cut.report.violations) for cut in cuts)
    lines = [(verdict_line(cut), "#b00000" if cut.failed else "black") for cut in cuts]
    lines += [
        (f"{number}. {cut.label}: {violation}", VIOLATION_COLOURS[cut.key])
        for number, (cut, violation) in enumerate(listed, start=1)
    ]
    if every > len(listed):
        lines.append((f"… and {every - len(listed)} more (review.html lists them all)", "black"))
    step = 1.0 / max(len(lines), 1)
    for row, (line, colour) in enumerate(lines):
        axis.text(0.0, 1.0 - row * step, line, color=colour, fontsize=9, va="top")


class _Gradient(HandlerBase):
    """A legend swatch for a line coloured by a colour map: the map along the swatch."""

    def create_artists(
        self,
        legend: Legend,
        orig_handle: Artist,
        xdescent: float,
        ydescent: float,
        width: float,
        height: float,
        fontsize: float,
        trans: Transform,
    ) -> list[Artist]:
        """One line across the swatch, in the handle's colour map's colours."""
        from matplotlib.collections import LineCollection

        x = np.linspace(-xdescent, width - xdescent, 17)
        y = np.full_like(x, 0.5 * height - ydescent)
        points = np.column_stack([x, y])
        swatch = LineCollection(
            np.stack([points[:-1], points[1:]], axis=1),
            cmap=orig_handle.get_cmap(),
            linewidth=PLANNED_WIDTH,
            transform=trans,
        )
        swatch.set_array(np.linspace(0.0, 1.0, len(x) - 1))
        return [swatch]


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
    for part in ROBOT_PARTS:
        axis.plot(
            *part.points(pose).T, color=part.png_colour, linewidth=part.png_width, label=part.name
        )
    axis.plot(*scene.contour.T, color="tab:green", linewidth=1.5, label="planned contour")
    reach = max(problem.robot.upper_arc.rail_radius, problem.robot.upper_platform_radius) / MM
    axis.set(xlim=(-reach, reach), ylim=(-reach, reach), zlim=(0.0, reach))
    axis.set_box_aspect((2.0, 2.0, 1.0), zoom=ROBOT_ZOOM)
    _finish(axis, scene, f"the robot at the plan's start, t = {trajectory.start_time:g} s")


def _draw_flap(axis: Axes3D, scene: ReviewScene, skull: np.ndarray) -> object:
    """The flap close up: the skull, the contour, the landmarks, the planned cut coloured
    by its distance from the contour, the predicted and the executed cut; returns the
    planned cut's lines (for the colour bar)."""
    planned = scene.planned
    cut = np.vstack([scene.contour, planned.points])
    middle = 0.5 * (cut.min(axis=0) + cut.max(axis=0))
    half = 0.6 * float(np.max(cut.max(axis=0) - cut.min(axis=0)))
    inside = np.all(np.abs(skull - middle) <= half, axis=(1, 2))
    _add_skull(axis, skull[inside])
    axis.plot(*scene.contour.T, color="tab:green", linewidth=1.2, linestyle="--")
    segments = np.stack([planned.points[:-1], planned.points[1:]], axis=1)
    lines = Line3DCollection(
        segments,
        cmap=CUT_COLOURS,
        linewidth=PLANNED_WIDTH,
        label="planned cut (colour: off the contour)",
    )
    lines.set_array(0.5 * (planned.deviation[:-1] + planned.deviation[1:]))
    lines.set_clim(0.0, max(float(np.max(planned.deviation)), 1e-3))
    axis.add_collection3d(lines)
    if scene.predicted is not None:
        axis.plot(*scene.predicted.points.T, **PREDICTED_LINE, label="predicted cut")
    if scene.executed is not None:
        axis.plot(*scene.executed.points.T, **EXECUTED, label="executed cut (measured)")
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
    others = [
        name
        for name, cut in (("predicted", scene.predicted), ("executed", scene.executed))
        if cut is not None
    ]
    drawn = f" and the {' and the '.join(others)} cut" if others else ""
    _finish(axis, scene, f"the flap: the planned cut{drawn}")
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
