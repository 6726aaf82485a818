"""The 3-D review page of a plan: one self-contained HTML file (plotly, its JavaScript
inlined) that opens offline.

It shows, mm in the robot's frame (:mod:`spm_opt.report.review_scene`): the skull around
the flap, the landmarks, the planned contour, the planned cut coloured by its distance from
the contour, the executed cut of a log, and the robot (arcs, platforms, tool) at a time a
slider and a play button choose. Above the plot, the judge's verdicts
(:mod:`spm_opt.report.review_verdict`): the plan's, by ``spm-opt evaluate`` of the plan,
and the run's, by ``spm-opt evaluate`` of its log, each with the tube it is judged against,
its headline figures and its violations, which the plot marks on the cut; the same verdicts
as JSON in ``<script type="application/json" id="verdict">``.

What it is given is checked as ``spm-opt evaluate`` and ``spm-opt execute`` check it
(:func:`review_inputs`): a plan or a log made for another problem is drawn only when asked
for, and the page then says so above everything else.
"""

from __future__ import annotations

import html
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from spm_opt.errors import InputError, require
from spm_opt.model.params import MM
from spm_opt.provenance import PLAN_HINT, check_made_for, check_run_of, log_hint
from spm_opt.report.review_scene import Cut, ReviewScene, review_scene
from spm_opt.report.review_verdict import (
    PLAN,
    RUN,
    RUN_TRUE,
    Judged,
    judged_cuts,
    tube_text,
    verdict_json,
    verdict_line,
    violation_points,
)
from spm_opt.report.robot_geometry import robot_pose

if TYPE_CHECKING:
    import pandas as pd
    import plotly.graph_objects as go

    from spm_opt.evaluate import Report
    from spm_opt.evaluate_execution import LogReports
    from spm_opt.model.params import Robot
    from spm_opt.problem import Problem
    from spm_opt.skull.surface import Skull
    from spm_opt.trajectory import Trajectory

_LOG = logging.getLogger(__name__)

POSES = 90
"""Times the slider shows the robot at, over the plan's duration."""
BACKGROUND = "#ffffff"
"""The page's and the plot's background colour."""
SKULL_COLOUR = "#d9d9d9"
ASIDE_WIDTH = "430px"
"""The width (CSS) of the column of figures and verdicts at the page's left; the plot
fills the rest of the window."""
VIOLATION_COLOURS = {PLAN: "#9400d3", RUN: "#d62728", RUN_TRUE: "#8c564b"}
"""The colour of each judged cut's violation markers."""
CAMERA_DISTANCE = 1.3
"""The camera's distance from the middle of the robot's box, in the scene's normalised
units (the box 1 wide): far enough to see the whole robot."""
CAMERA_TILT = 30.0
"""How far (deg) the camera's line of sight tilts from the flap's direction, downwards."""
_PARTS = (
    ("upper_arc", "upper arc (θ1)", "#1f77b4", 6),
    ("lower_arc", "lower arc (θ2)", "#ff7f0e", 6),
    ("upper_platform", "upper platform", "#1f77b4", 9),
    ("lower_platform", "lower platform", "#ff7f0e", 9),
    ("tool", "tool", "#222222", 4),
)
"""Each of the robot's parts: its :class:`RobotPose` field, name, colour and line width."""


@dataclass(frozen=True)
class ReviewInputs:
    """What the review draws, checked (:func:`review_inputs`).

    Attributes
    ----------
    trajectory : Trajectory
        The plan.
    log : pandas.DataFrame or None
        The execution log's table, when one was given.
    warnings : tuple of str
        What ``other_problem`` let through, one line each, for the page.
    run : LogReports or None
        The judge's reports of that log (:func:`~spm_opt.evaluate_execution.evaluate_log`):
        given with ``log``.
    """

    trajectory: Trajectory
    log: pd.DataFrame | None = None
    warnings: tuple[str, ...] = ()
    run: LogReports | None = None


def review_inputs(
    problem: Problem,
    plan: Path,
    log: Path | None = None,
    other_problem: bool = False,
    trace: Path | None = None,
) -> ReviewInputs:
    """Read the plan, and the execution log when given, checked as ``spm-opt evaluate``
    and ``spm-opt execute`` check them: each must record ``problem`` as the one it was made
    for or ran under (:func:`spm_opt.provenance.check_made_for`; another, or none, only
    with ``other_problem``, then logged as a warning and returned for the page), and the
    log must be a run of the plan (:func:`spm_opt.provenance.check_run_of`). One-line
    :class:`~spm_opt.errors.InputError` naming the file otherwise. The log is judged as
    ``spm-opt evaluate LOG [--trace TRACE]`` judges it.

    Parameters
    ----------
    problem : Problem
    plan : path
        The plan's CSV (its JSON sidecar beside it).
    log : path, optional
        An execution log's CSV (its JSON header beside it).
    other_problem : bool
        Draw a plan or a log made for another problem, or recording none.
    trace : path, optional
        The plant's true state over the run (``spm-opt execute --trace``): its true cut is
        judged too. Only with ``log``.
    """
    from spm_opt.evaluate_execution import evaluate_log, read_log_checked
    from spm_opt.trajectory import Trajectory

    if trace is not None and log is None:
        raise InputError(f"trace {trace}: only with a log (the true state of its run)")

    trajectory = Trajectory.from_csv(plan)
    why = check_made_for(
        problem,
        trajectory.metadata,
        "plan",
        other_problem,
        refused=f"plan {plan} refused",
        hint=PLAN_HINT,
    )
    warnings = [f"plan {plan}: {why}"] if why else []
    table, run = None, None
    if log is not None:
        table, header = read_log_checked(log)
        why = check_made_for(
            problem,
            header,
            "log",
            other_problem,
            refused=f"log {log} refused",
            hint=log_hint("review"),
        )
        warnings += [f"log {log}: {why}"] if why else []
        check_run_of(trajectory, str(plan), header, str(log))
        run = evaluate_log(problem, log, trace, other_problem=other_problem)
    for warning in warnings:
        _LOG.warning("%s; reviewed under %s's limits as asked", warning, problem.name)
    return ReviewInputs(trajectory, table, tuple(warnings), run)


def review_page(
    problem: Problem, skull: Skull, given: ReviewInputs, report: Report | None = None
) -> str:
    """The review page, a whole HTML document (about 5 MB, plotly's JavaScript inlined).

    Parameters
    ----------
    problem : Problem
    skull : Skull
        The skull the cut lies on (its outer mesh, or its surface without one).
    given : ReviewInputs
        The plan, and a log with the judge's reports of it (:func:`review_inputs`); its
        warnings are shown above everything else.
    report : Report, optional
        The plan's report; by default ``evaluate(problem, trajectory)``.
    """
    from spm_opt.evaluate import evaluate

    require("plotly", "the review page")
    if (given.log is None) != (given.run is None):
        raise InputError("given: a log and the judge's reports of it go together")
    trajectory = given.trajectory
    report = evaluate(problem, trajectory) if report is None else report
    cuts = judged_cuts(problem, report, given.run)
    scene = review_scene(problem, skull, trajectory, given.log)
    figure = review_figure(problem, scene, trajectory, cuts)
    plot = figure.to_html(
        include_plotlyjs=True,
        full_html=False,
        auto_play=False,
        config={"responsive": True},
        default_height="100%",
    )
    title = f"{problem.name}: {report.planner or 'plan'}"
    return _DOCUMENT.format(
        title=html.escape(title),
        background=BACKGROUND,
        warnings="".join(
            f'<p class="warning">Warning: {html.escape(w)}; reviewed under '
            f"{html.escape(problem.name)}'s limits.</p>\n"
            for w in given.warnings
        ),
        table=_table(plan_rows(report, skull)),
        verdict=_verdict_table(cuts),
        violations="\n".join(_violations(cut) for cut in cuts),
        verdict_json=verdict_json(cuts),
        aside_width=ASIDE_WIDTH,
        plot=plot,
    )


def plan_rows(report: Report, skull: Skull | None = None) -> list[tuple[str, str]]:
    """The plan's figures the page's first table shows, as (what, value with its unit):
    the report's, and of a skull from imaging its registration's error, its largest
    fiducial residual and the landmarks' moves onto it."""
    rows = [
        ("planner", report.planner or "(unknown)"),
        ("duration", f"{report.duration_s:.2f} s"),
        ("over the duration's lower bound", f"{report.duration_over_lower_bound:.3f}"),
    ]
    if skull is not None and skull.registration_rms_mm is not None:
        rows.append(("registration RMS error", f"{skull.registration_rms_mm:.3f} mm"))
    if skull is not None and skull.fiducial_residuals_mm is not None:
        largest = float(np.max(skull.fiducial_residuals_mm))
        rows.append(("largest fiducial residual", f"{largest:.3f} mm"))
    if skull is not None and skull.landmark_shifts_mm is not None:
        moved = float(np.max(np.abs(skull.landmark_shifts_mm)))
        rows.append(("landmarks moved onto the mesh", f"≤ {moved:.3f} mm"))
    return rows


def cut_rows(cut: Judged) -> list[tuple[str, str]]:
    """A judged cut's figures, from its report, as (what, value with its unit): one row of
    the page's verdict table."""
    report = cut.report
    rows = [
        ("judged in the tube", tube_text(cut)),
        ("max off the contour", f"{report.max_contour_deviation_mm:.3f} mm"),
        ("RMS off the contour", f"{report.rms_contour_deviation_mm:.3f} mm"),
        ("max tool speed", f"{report.max_tool_speed_mm_s:.2f} mm/s"),
        ("contour never cut inside the tube", f"{report.coverage_gap_mm:.2f} mm"),
        ("max landmark error", f"{report.max_landmark_error_mm:.3f} mm"),
        ("max tool incidence", _shown(report.max_tool_incidence_deg, "{:.1f}°")),
        ("max depth speed", _shown(report.max_depth_speed_mm_s, "{:.2f} mm/s")),
        ("max depth acceleration", _shown(report.max_depth_acceleration_mm_s2, "{:.1f} mm/s²")),
        ("violations", str(len(report.violations))),
        ("run completed", _completed(cut)),
    ]
    return rows


def _completed(cut: Judged) -> str:
    if not cut.executed:
        return "—"
    return "yes" if getattr(cut.report, "completed", True) else "no"


def _shown(value: float | None, form: str) -> str:
    return "—" if value is None else form.format(value)


def review_figure(
    problem: Problem, scene: ReviewScene, trajectory: Trajectory, cuts: Sequence[Judged] = ()
) -> go.Figure:
    """The plotly figure of a scene: the skull, the cuts, the judged ``cuts``' violations
    (a marker at the cut's point at each one's time, its text on hover) and the robot,
    with frames of the robot over the plan (the last traces, one per part of
    :data:`_PARTS` and the cut point)."""
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
    """The planned cut coloured by its distance from the contour, and the executed cut."""
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
    if scene.executed is not None:
        cuts.append(_executed(scene.executed))
    return cuts


def _executed(cut: Cut) -> go.Scatter3d:
    import plotly.graph_objects as go

    return go.Scatter3d(
        **_xyz(cut.points),
        mode="lines",
        line={"color": "#17becf", "width": 4},
        customdata=np.column_stack([cut.t, cut.deviation]),
        hovertemplate="executed, t = %{customdata[0]:.2f} s: "
        "%{customdata[1]:.3f} mm off the contour<extra></extra>",
        name="executed cut (measured)",
    )


def _violation_markers(cut: Judged, scene: ReviewScene) -> go.Scatter3d:
    """A marker at each of a judged cut's violations: on the planned cut at its plan time,
    on the executed cut (the measured angles, for the true cut too) at its log time."""
    import plotly.graph_objects as go

    drawn = scene.executed if cut.executed and scene.executed is not None else scene.planned
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
        parts = [getattr(pose, field) / MM for field, *_ in _PARTS]
        poses.append([go.Scatter3d(**_xyz(part)) for part in [*parts, point[None, :]]])
    return poses


def _with_style(trace: go.Scatter3d, index: int) -> go.Scatter3d:
    """The first pose's ``index``-th trace with its part's name, colour and width."""
    if index == len(_PARTS):
        trace.update(
            mode="markers",
            marker={"size": 6, "color": "#d62728", "line": {"width": 1, "color": "#000000"}},
            name="cut point at the slider's time",
            hoverinfo="skip",
        )
        return trace
    _, name, colour, width = _PARTS[index]
    trace.update(mode="lines", line={"color": colour, "width": width}, name=name, hoverinfo="skip")
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


def _table(rows: list[tuple[str, str]]) -> str:
    """The plan's figures, a row each: what, then its value."""
    body = "".join(
        f"<tr><th>{html.escape(what)}</th><td>{html.escape(value)}</td></tr>\n"
        for what, value in rows
    )
    return f'<table class="plan">\n{body}</table>'


def _verdict_table(cuts: Sequence[Judged]) -> str:
    """The judged cuts' figures: a column per cut, a row per figure."""
    columns = [dict(cut_rows(cut)) for cut in cuts]
    heads = "".join(
        f'<th class="{"fail" if cut.failed else "pass"}">{html.escape(cut.label)}</th>'
        for cut in cuts
    )
    body = "".join(
        f"<tr><th>{html.escape(what)}</th>"
        + "".join(f"<td>{html.escape(column[what])}</td>" for column in columns)
        + "</tr>\n"
        for what in columns[0]
    )
    return f'<table class="verdict">\n<tr><th></th>{heads}</tr>\n{body}</table>'


def _violations(cut: Judged) -> str:
    """The judge's verdict on a cut in a sentence, then its violations, each a line."""
    line = f'<p class="{"fail" if cut.failed else "pass"}">{html.escape(verdict_line(cut))}</p>'
    if not cut.report.violations:
        return line
    items = "\n".join(f"<li>{html.escape(str(v))}</li>" for v in cut.report.violations)
    return f"{line}\n<ul>\n{items}\n</ul>"


_DOCUMENT = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ background: {background}; font-family: sans-serif; margin: 0; display: flex;
  height: 100vh; }}
aside {{ flex: 0 0 {aside_width}; overflow-y: auto; padding: 12px 14px;
  box-sizing: border-box; border-right: 1px solid #ddd; }}
main {{ flex: 1 1 auto; min-width: 0; height: 100vh; }}
main > div {{ height: 100%; }}
h1 {{ font-size: 17px; margin: 0 0 8px; }}
table {{ border-collapse: collapse; font-size: 12px; margin: 0 0 8px; }}
th, td {{ border: 1px solid #ccc; padding: 2px 6px; }}
th {{ font-weight: normal; color: #444; text-align: left; }}
td {{ text-align: center; }}
.fail {{ color: #b00000; font-weight: bold; }}
p, ul {{ font-size: 12px; margin: 6px 0; }}
ul {{ padding-left: 18px; }}
p.warning {{ color: #b00000; font-weight: bold; }}
</style>
</head>
<body>
<aside>
<h1>{title}</h1>
{warnings}{table}
{verdict}
{violations}
<script type="application/json" id="verdict">
{verdict_json}
</script>
</aside>
<main>
{plot}
</main>
</body>
</html>
"""
