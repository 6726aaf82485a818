"""Draw docs/guide/navigation_frames.png: the frames the navigation link works in (the
image's RAS, the robot's at the isocenter, the tool's at its tip on the skull), the
transforms between them and the messages, from the example problem's own registration
and meshes, with the tool where the plan starts (its first landmark).

    python docs/scripts/navigation_frames.py
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import trimesh
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch

from spm_opt import load_problem
from spm_opt.model import kinematics
from spm_opt.navigation import commands, scene
from spm_opt.navigation.igtl import STATUS_CODES
from spm_opt.navigation.link import INFO_RATE_HZ, POSE_RATE_HZ
from spm_opt.problem.problem import Problem

ROOT = Path(__file__).resolve().parents[2]
PROBLEM = ROOT / "problems" / "skull_flap.toml"
FIGURE = ROOT / "docs" / "guide" / "navigation_frames.png"
AXIS_MM = 24.0
"""Length of each frame's drawn axes, mm."""
TOOL_MM = 40.0
"""Length of the tool's shaft from its tip outward, mm (the model docs/guide/slicer_setup.py
builds)."""
AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")
"""x, y, z (for RAS: R, A, S), as Slicer colours them."""
VIEW = (0, 2)
"""The coronal view: RAS's R (drawn to the left, as Slicer's coronal view shows it from the
front) and S (up). A points at the reader."""
FONT = 15
REPLY_CODES = (
    commands.OK,
    commands.UNKNOWN_ERROR,
    commands.ACCESS_DENIED,
    commands.BUSY,
    commands.UNKNOWN_INSTRUCTION,
    commands.NOT_READY,
)
"""The STATUS codes a command is answered with (spm_opt/navigation/commands.py)."""


def poses(problem: Problem) -> dict[str, np.ndarray]:
    """The three frames in RAS (4, 4), mm: the image's, the robot's, the tool's at the
    plan's start."""
    to_ras = scene.robot_to_ras(scene.image_to_robot(problem))
    start = kinematics.inverse_kinematics(problem.platform_points[:1])
    return {
        "image RAS": np.eye(4),
        "robot": to_ras,
        "tool": scene.tool_to_ras(problem, start, to_ras)[0],
    }


def skull_slices(problem_file: Path, a_mm: float) -> dict[str, list[np.ndarray]]:
    """The problem's outer and inner meshes (RAS, mm) cut by the coronal plane A = a_mm:
    polylines (N, 3) of each."""
    skull = tomllib.loads(problem_file.read_text(encoding="utf-8"))["skull"]
    slices = {}
    for key in ("outer_mesh", "inner_mesh"):
        mesh = trimesh.load(problem_file.parent / skull[key], force="mesh")
        section = mesh.section(plane_origin=(0.0, a_mm, 0.0), plane_normal=(0.0, 1.0, 0.0))
        slices[key] = [] if section is None else list(section.discrete)
    return slices


def _xy(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polyline points (N, 3) in the view: the drawn x and y (N,)."""
    return points[:, VIEW[0]], points[:, VIEW[1]]


def _at(point: np.ndarray) -> tuple[float, float]:
    """A point (3,) in the view."""
    return float(point[VIEW[0]]), float(point[VIEW[1]])


def _arc_middle(start: np.ndarray, end: np.ndarray, bend: float) -> tuple[float, float]:
    """The middle of matplotlib's ``arc3`` curve from start to end (in the view; its x axis
    is drawn inverted, so the curve's side is worked out on the screen, x to the right)."""
    a = np.array([-start[VIEW[0]], start[VIEW[1]]])
    b = np.array([-end[VIEW[0]], end[VIEW[1]]])
    d = b - a
    middle = (a + b) / 2 + 0.5 * bend * np.array([d[1], -d[0]])
    return float(-middle[0]), float(middle[1])


def draw_frame(
    axis: Axes, pose: np.ndarray, letters: str, name: str, offset: tuple[float, float]
) -> None:
    """A frame's origin, its axes projected (one mostly along A is marked ⊙ towards the
    reader or ⊗ away) and its name, ``offset`` points from its origin."""
    origin = pose[:3, 3]
    for column, (letter, colour) in enumerate(zip(letters, AXIS_COLOURS, strict=True)):
        direction = pose[:3, column]
        axis.annotate(
            "",
            xy=_at(origin + AXIS_MM * direction),
            xytext=_at(origin),
            arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 3, "mutation_scale": 22},
            zorder=4,
        )
        mark = "" if abs(direction[1]) < 0.7 else (" ⊙" if direction[1] > 0 else " ⊗")
        end = origin + (AXIS_MM + 7) * direction
        seen = np.hypot(*(np.subtract(_at(end), _at(origin))))
        axis.annotate(
            letter + mark,
            _at(end),
            xytext=(0, 0) if seen > 10 else (-24, -20),  # an axis seen end-on: beside the dot
            textcoords="offset points",
            color=colour,
            fontsize=FONT,
            fontweight="bold",
            ha="center",
            va="center",
        )
    axis.plot(*_at(origin), "o", color="k", markersize=9, zorder=5)
    axis.annotate(
        name,
        _at(origin),
        xytext=offset,
        textcoords="offset points",
        fontsize=FONT,
        fontweight="bold",
        ha="center",
        va="center",
    )


def transform_arrow(
    axis: Axes,
    start: np.ndarray,
    end: np.ndarray,
    text: str,
    bend: float,
    offset: tuple[float, float],
    arrowstyle: str = "-|>",
    linestyle: str = "-",
) -> None:
    """A curved arrow from one frame's origin to another's, named (``offset`` points from
    the curve's middle) by the transform it is."""
    axis.add_patch(
        FancyArrowPatch(
            _at(start),
            _at(end),
            connectionstyle=f"arc3,rad={bend}",
            arrowstyle=arrowstyle,
            mutation_scale=24,
            lw=2.2,
            color="0.1",
            linestyle=linestyle,
            shrinkA=9,
            shrinkB=9,
            zorder=3,
        )
    )
    axis.annotate(
        text,
        _arc_middle(start, end, bend),
        xytext=offset,
        textcoords="offset points",
        fontsize=FONT - 1,
        ha="left" if offset[0] > 0 else "right",
        va="center",
        bbox={"boxstyle": "round", "fc": "white", "ec": "0.6"},
        zorder=6,
    )


def draw_view(axis: Axes, problem: Problem) -> None:
    """The coronal view: the skull's slices at the tool tip, the flap, the tool, the three
    frames and the transforms between them."""
    frames = poses(problem)
    image, robot, tool = (frames[name] for name in ("image RAS", "robot", "tool"))
    tip = tool[:3, 3]
    slices = skull_slices(PROBLEM, float(tip[1]))
    for key, style in (("outer_mesh", "-"), ("inner_mesh", "--")):
        for i, line in enumerate(slices[key]):
            label = f"skull, {key.split('_')[0]} surface (cut at A = {tip[1]:.0f} mm)"
            axis.plot(*_xy(line), style, color="0.6", lw=2, label=None if i else label)
    contour = scene.contour_points(problem, robot)
    axis.plot(*_xy(contour), color="tab:orange", lw=3, label="the flap's contour (projected)")
    shaft = np.stack([tip, tip + TOOL_MM * tool[:3, 2]])
    axis.plot(
        *_xy(shaft),
        color="0.8",
        lw=12,
        solid_capstyle="round",
        zorder=2,
        label=f"the tool, {TOOL_MM:.0f} mm from its tip outward",
    )
    axis.plot(
        *_xy(np.stack([robot[:3, 3], tip])),
        ":",
        color="0.3",
        lw=2,
        label="the tool's axis, through the isocenter",
    )
    draw_frame(axis, image, "RAS", "image RAS\n(its origin)", (85, -30))
    draw_frame(axis, robot, "xyz", "robot:\nisocenter", (-95, 18))
    draw_frame(axis, tool, "xyz", "tool:\ntip on the skull", (105, 40))
    transform_arrow(
        axis,
        robot[:3, 3],
        image[:3, 3],
        "RobotToRAS (sent)\nRASToRobot (received)",
        0.45,
        (-14, -14),
        arrowstyle="<|-|>",
    )
    transform_arrow(
        axis,
        tool[:3, 3],
        robot[:3, 3],
        "ToolToRobot\n(the joints; not sent)",
        0.35,
        (-12, 8),
        linestyle="--",
    )
    transform_arrow(axis, tip, image[:3, 3], "ToolToRAS\n(sent)", -0.45, (14, 0))
    axis.set_aspect("equal")
    axis.set_ylim(bottom=-30)
    axis.invert_xaxis()
    axis.set_xlabel("R (mm), drawn to the left: the view from the front", fontsize=FONT - 1)
    axis.set_ylabel("S (mm)", fontsize=FONT - 1)
    axis.tick_params(labelsize=FONT - 3)
    axis.set_title(
        "skull_flap.toml at the plan's start, seen from the front (⊙: towards you)\n"
        "ToolToRAS = RobotToRAS · ToolToRobot,  RobotToRAS = inverse(image_to_robot)",
        fontsize=FONT,
    )
    axis.legend(
        loc="upper center",
        bbox_to_anchor=(0.5, -0.1),
        ncols=2,
        fontsize=FONT - 3,
        frameon=False,
    )


def messages() -> list[tuple[str, str, str, str]]:
    """Every message the link sends and takes: device, type, direction, when (see
    spm_opt/navigation/link.py)."""
    sent, taken = "to Slicer", "from Slicer"
    return [
        ("ToolToRAS", "TRANSFORM", sent, f"{POSE_RATE_HZ:.0f} Hz during a run"),
        ("RobotToRAS", "TRANSFORM", sent, "connect, registration"),
        ("PlannedCut", "POLYDATA", sent, "connect, registration, PLAN"),
        ("Contour, TubeEdges", "POLYDATA", sent, "connect, registration, PLAN"),
        ("ExecutedCut", "POLYDATA", sent, f"{INFO_RATE_HZ:.0f} Hz during a run"),
        ("RunState", "STATUS", sent, "connect, each change"),
        ("RunInfo", "STRING", sent, f"{INFO_RATE_HZ:.0f} Hz, each change"),
        ("ACK_<id>", "STRING", sent, "at once: the command"),
        ("CMD_<id>", "STATUS", sent, "then: its outcome"),
        ("RASToRobot", "TRANSFORM", taken, "when Slicer sends it"),
        ("(any name)", "POINT", taken, "the flap, RAS mm"),
        ("CMD_<id>", "STRING", taken, "STOP, HOLD, RESUME, PLAN"),
    ]


def draw_table(axis: Axes) -> None:
    """The messages as a table."""
    axis.axis("off")
    rows = messages()
    table = axis.table(
        cellText=[list(row) for row in rows],
        colLabels=["device", "type", "direction", "when"],
        bbox=(0.0, 0.3, 1.0, 0.62),
        cellLoc="left",
        colLoc="left",
        colWidths=[0.27, 0.19, 0.18, 0.36],
    )
    table.auto_set_font_size(False)
    table.set_fontsize(FONT - 2)
    for (row, _column), cell in table.get_celld().items():
        cell.set_edgecolor("0.8")
        if row == 0:
            cell.set_text_props(fontweight="bold")
        elif rows[row - 1][2] == "from Slicer":
            cell.set_facecolor("0.92")
    axis.set_title("The messages (shaded: received; nothing received starts motion)", fontsize=FONT)
    codes = [f"{code} {STATUS_CODES[code]}" for code in REPLY_CODES]
    axis.text(
        0.0,
        0.24,
        "connect: when a client connects; registration: when a RASToRobot arrives.\n"
        "TRANSFORM and POLYDATA: RAS, mm. ToolToRAS's timestamp: the log's\n"
        "time (s since the loop's start), not the wall clock.\n"
        f"A command's STATUS codes: {', '.join(codes[:3])},\n{', '.join(codes[3:])}.\n"
        "START, RUN, MOVE... are refused (access denied).",
        transform=axis.transAxes,
        fontsize=FONT - 2,
        va="top",
        linespacing=1.5,
    )


def navigation_frames_figure(problem: Problem) -> Figure:
    """The figure: the frames in a coronal view beside the table of messages."""
    figure = Figure(figsize=(19, 9.5))
    draw_view(figure.add_axes((0.05, 0.2, 0.46, 0.7)), problem)
    draw_table(figure.add_axes((0.55, 0.05, 0.43, 0.85)))
    return figure


def main() -> None:
    figure = navigation_frames_figure(load_problem(PROBLEM))
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(FIGURE, dpi=150, metadata={"Software": None})
    print(FIGURE.relative_to(ROOT))


if __name__ == "__main__":
    main()
