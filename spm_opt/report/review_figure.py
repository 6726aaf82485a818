"""The review page's 3-D plotly figure, mm in the robot's frame
(:mod:`spm_opt.report.review_scene`): the skull around the flap, the landmarks, the planned
contour, the planned cut coloured by its distance from the contour, the executed cut of a
log, the judged cuts' violations marked on them, and the robot (arcs, platforms, tool) at
a time a slider and a play button choose."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.model.params import MM
from spm_opt.report.review_scene import Cut, ReviewScene
from spm_opt.report.review_verdict import PLAN, PREDICTED, RUN, RUN_TRUE, Judged, violation_points
from spm_opt.report.robot_geometry import ROBOT_PARTS, robot_pose

if TYPE_CHECKING:
    import plotly.graph_objects as go

    from spm_opt.model.params import Robot
    from spm_opt.problem.problem import Problem
    from spm_opt.problem.trajectory import Trajectory

POSES = 90
"""Times the slider shows the robot at, over the plan's duration."""
BACKGROUND = "#ffffff"
"""The page's and the plot's background colour."""
SKULL_COLOUR = "#d9d9d9"
"""The skull's colour."""
VIOLATION_COLOURS = {PLAN: "#9400d3", PREDICTED: "#e377c2", RUN: "#d62728", RUN_TRUE: "#8c564b"}
"""The colour of each judged cut's violation markers."""
CAMERA_DISTANCE = 1.3
"""The camera's distance from the middle of the robot's box, in the scene's normalised
units (the box 1 wide): far enough to see the whole robot."""
CAMERA_TILT = 30.0
"""How far (deg) the camera's line of sight tilts from the flap's direction, downwards."""


def review_figure(
    problem: Problem, scene: ReviewScene, trajectory: Trajectory, cuts: Sequence[Judged] = ()
) -> go.Figure:
    """The plotly figure of a scene: the skull, the cuts, the judged ``cuts``' violations
    (a marker at the cut's point at each one's time, its text on hover) and the robot,
    with frames of the robot over the plan (the last traces, one per part of
    :data:`~spm_opt.report.robot_geometry.ROBOT_PARTS` and the cut point)."""
    import plotly.graph_objects as go

    traces = [_skull(scene), *_flap(scene), *_cuts(scene)]
    traces += [_violation_markers(cut, scene) for cut in cuts if cut.report.violations]
    times = np.linspace(trajectory.start_time, trajectory.end_time, POSES)
    poses = _poses(problem.robot, scene, trajectory, times)
    moving = list(range(len(traces), len(traces) + len(poses[0])))
    traces += [_with_style(trace, index) for index, trace in enumerate(poses[0])]
    frames = [
        go.Frame(data=pose, traces=moving, name=_frame_name(t))
        for t, pose in zip(times, poses, strict=True)
    ]
    figure = go.Figure(data=traces, frames=frames)
    figure.update_layout(
        autosize=True,
        margin={"l": 0, "r": 0, "t": 10, "b": 10},
        paper_bgcolor=BACKGROUND,
        legend={"x": 0.01, "y": 0.98, "bgcolor": "rgba(255,255,255,0.7)"},
        scene=_scene_layout(problem, scene),
        sliders=[_slider(times)],
        updatemenus=[_play_buttons()],
    )
    return figure


def _skull(scene: ReviewScene) -> go.Mesh3d:
    import plotly.graph_objects as go

    vertices, faces = scene.skull_vertices.astype(np.float32), scene.skull_faces
    return go.Mesh3d(
        x=vertices[:, 0],
        y=vertices[:, 1],
        z=vertices[:, 2],
        i=faces[:, 0].astype(np.int32),
        j=faces[:, 1].astype(np.int32),
        k=faces[:, 2].astype(np.int32),
        color=SKULL_COLOUR,
        opacity=1.0,
        flatshading=False,
        lighting={"ambient": 0.45, "diffuse": 0.8, "specular": 0.05, "roughness": 0.9},
        lightposition={"x": -1e5, "y": 5e4, "z": 1e5},
        name="skull",
        showlegend=True,
        hoverinfo="skip",
    )


def _flap(scene: ReviewScene) -> list[go.Scatter3d]:
    """The landmarks with their names and the planned contour."""
    import plotly.graph_objects as go

    landmarks = scene.landmarks
    contour = go.Scatter3d(
        **_xyz(scene.contour),
        mode="lines",
        line={"color": "#2ca02c", "width": 3, "dash": "dash"},
        name="planned contour",
        hoverinfo="skip",
    )
    markers = go.Scatter3d(
        **_xyz(landmarks),
        mode="markers+text",
        marker={"size": 5, "color": "#000000", "symbol": "diamond"},
        text=list(scene.landmark_names),
        textposition="top center",
        textfont={"size": 14, "color": "#000000"},
        name="landmarks",
        hovertemplate="%{text}: (%{x:.1f}, %{y:.1f}, %{z:.1f}) mm<extra></extra>",
    )
    return [contour, markers]


def _cuts(scene: ReviewScene) -> list[go.Scatter3d]:
    """The planned cut coloured by its distance from the contour, the predicted cut and the
    executed cut."""
    import plotly.graph_objects as go

    planned = scene.planned
    cuts = [
        go.Scatter3d(
            **_xyz(planned.points),
            mode="lines",
            line={
                "color": planned.deviation,
                "colorscale": "Plasma",
                "cmin": 0.0,
                "cmax": max(float(np.max(planned.deviation)), 1e-3),
                "width": 5,
                "colorbar": {
                    "title": {"text": "planned cut<br>off the contour (mm)"},
                    "len": 0.6,
                    "x": 0.98,
                },
            },
            customdata=np.column_stack([planned.t, planned.deviation]),
            hovertemplate="planned, t = %{customdata[0]:.2f} s: "
            "%{customdata[1]:.3f} mm off the contour<extra></extra>",
            name="planned cut",
        )
    ]
    if scene.predicted is not None:
        predicted = ("predicted cut (before the run)", "predicted", "#ff7f0e", "dash")
        cuts.append(_run_cut(scene.predicted, *predicted))
    if scene.executed is not None:
        executed = ("executed cut (measured)", "executed", "#17becf", "solid")
        cuts.append(_run_cut(scene.executed, *executed))
    return cuts


def _run_cut(cut: Cut, name: str, hover: str, colour: str, dash: str) -> go.Scatter3d:
    """A run's cut (executed, or predicted) as a line of one ``colour`` and ``dash``,
    ``name`` in the legend, ``hover`` before each point's time."""
    import plotly.graph_objects as go

    return go.Scatter3d(
        **_xyz(cut.points),
        mode="lines",
        line={"color": colour, "width": 4, "dash": dash},
        customdata=np.column_stack([cut.t, cut.deviation]),
        hovertemplate=f"{hover}, t = %{{customdata[0]:.2f}} s: "
        "%{customdata[1]:.3f} mm off the contour<extra></extra>",
        name=name,
    )


def _violation_markers(cut: Judged, scene: ReviewScene) -> go.Scatter3d:
    """A marker at each of a judged cut's violations: on the planned cut at its plan time,
    on the executed cut (the measured angles, for the true cut too) at its log time, on the
    predicted cut at its predicted run's time."""
    import plotly.graph_objects as go

    drawn = scene.drawn(cut.key)
    violations = cut.report.violations
    points = violation_points(violations, drawn.t, drawn.points)
    return go.Scatter3d(
        **_xyz(points),
        mode="markers",
        marker={"size": 7, "color": VIOLATION_COLOURS[cut.key], "symbol": "x"},
        text=[str(v) for v in violations],
        hovertemplate=f"%{{text}}<extra>{cut.label}</extra>",
        name=f"{cut.label}: {len(violations)} violation(s)",
    )


def _poses(
    robot: Robot, scene: ReviewScene, trajectory: Trajectory, times: np.ndarray
) -> list[list[go.Scatter3d]]:
    """At each time, the robot's parts and the point being cut, as bare traces (only x, y
    and z: a frame changes nothing else)."""
    import plotly.graph_objects as go

    q = trajectory.position(times)
    planned = scene.planned
    at = np.searchsorted(planned.t, times).clip(0, len(planned.t) - 1)
    poses = []
    for angles, point in zip(q, planned.points[at], strict=True):
        pose = robot_pose(robot, angles)
        parts = [part.points(pose) for part in ROBOT_PARTS]
        poses.append([go.Scatter3d(**_xyz(part)) for part in [*parts, point[None, :]]])
    return poses


def _with_style(trace: go.Scatter3d, index: int) -> go.Scatter3d:
    """The first pose's ``index``-th trace with its part's name, colour and width."""
    if index == len(ROBOT_PARTS):
        trace.update(
            mode="markers",
            marker={"size": 6, "color": "#d62728", "line": {"width": 1, "color": "#000000"}},
            name="cut point at the slider's time",
            hoverinfo="skip",
        )
        return trace
    part = ROBOT_PARTS[index]
    line = {"color": part.page_colour, "width": part.page_width}
    trace.update(mode="lines", line=line, name=part.name, hoverinfo="skip")
    return trace


def _xyz(points: np.ndarray) -> dict[str, np.ndarray]:
    points = np.asarray(points, dtype=np.float32)
    return {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}


def _frame_name(t: float) -> str:
    return f"{t:.2f} s"


def _scene_layout(problem: Problem, scene: ReviewScene) -> dict:
    """Axes in mm over the whole robot, equal scales, and a camera that looks at the middle
    of the robot's box from the flap's side, far enough for the whole robot, its line of
    sight tilted :data:`CAMERA_TILT` down from the flap's direction."""
    robot = problem.robot
    reach = max(robot.upper_arc.rail_radius, robot.upper_platform_radius) / MM + 30.0
    ranges = np.array([[-reach, reach], [-reach, reach], [0.0, reach]])
    spans = ranges[:, 1] - ranges[:, 0]
    aspect = spans / spans.max()
    direction = scene.flap_direction
    horizontal = np.array([direction[0], direction[1], 0.0])
    if np.linalg.norm(horizontal) < 1e-6:
        horizontal = np.array([-1.0, 0.0, 0.0])  # above the vertex: from the front (−x)
    horizontal /= np.linalg.norm(horizontal)
    tilt = np.radians(CAMERA_TILT)
    elevation = min(np.arcsin(np.clip(direction[2], -1.0, 1.0)), np.radians(80.0))
    sight = np.cos(elevation - tilt) * horizontal + [0.0, 0.0, np.sin(elevation - tilt)]
    eye = CAMERA_DISTANCE * sight

    def axis(name: str, span: np.ndarray) -> dict:
        return {
            "title": {"text": f"{name} (mm)"},
            "range": span.tolist(),
            "backgroundcolor": BACKGROUND,
            "gridcolor": "#e5e5e5",
            "showbackground": True,
        }

    return {
        "xaxis": axis("x", ranges[0]),
        "yaxis": axis("y", ranges[1]),
        "zaxis": axis("z", ranges[2]),
        "aspectmode": "manual",
        "aspectratio": dict(zip("xyz", aspect.tolist(), strict=True)),
        "camera": {
            "center": {"x": 0.0, "y": 0.0, "z": 0.0},
            "eye": dict(zip("xyz", eye.tolist(), strict=True)),
            "up": {"x": 0, "y": 0, "z": 1},
        },
        "bgcolor": BACKGROUND,
    }


def _slider(times: np.ndarray) -> dict:
    steps = [
        {
            "method": "animate",
            "label": f"{t:.1f}",
            "args": [
                [_frame_name(t)],
                {
                    "mode": "immediate",
                    "frame": {"duration": 0, "redraw": True},
                    "transition": {"duration": 0},
                },
            ],
        }
        for t in times
    ]
    return {
        "active": 0,
        "steps": steps,
        "currentvalue": {"prefix": "plan time (s): "},
        "x": 0.1,
        "len": 0.88,
        "y": 0.0,
        "yanchor": "bottom",
        "pad": {"t": 10},
    }


def _play_buttons() -> dict:
    play = {
        "frame": {"duration": 60, "redraw": True},
        "fromcurrent": True,
        "transition": {"duration": 0},
    }
    pause = {"mode": "immediate", "frame": {"duration": 0, "redraw": False}}
    return {
        "type": "buttons",
        "direction": "left",
        "x": 0.09,
        "y": 0.0,
        "xanchor": "right",
        "yanchor": "bottom",
        "pad": {"b": 20},
        "buttons": [
            {"label": "play", "method": "animate", "args": [None, play]},
            {"label": "pause", "method": "animate", "args": [[None], pause]},
        ],
    }
