"""The robot drawn as 3-D polylines at joint angles q: its two input arcs' rails, its two
platforms and the tool, in the robot's frame (docs/conventions.md), m.

The upper arc's rail is the half circle of its rail radius in the plane normal to
N_u = Rx(θ1) ŷ, from +x over the top to −x; the lower arc's in the plane normal to
N_L = Ry(θ2) x̂, from +y to −y. Each platform is a rectangle about its mass centre on the
radial line through B (at r_u and r_L), spanned by its frame's x and y axes (Eq. 17),
longer along its rail. The tool runs from the isocenter along B past the upper platform.
How the review page and its PNG draw each part is one table, :data:`ROBOT_PARTS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spm_opt.model import kinematics
from spm_opt.model.params import MM, Robot

ARC_SAMPLES = 61
"""Points along each arc's half circle."""
PLATFORM_SIZE = (0.04, 0.025)
"""A platform's rectangle as drawn, along its rail and across it, m."""
TOOL_OVERHANG = 0.03
"""How far the tool's line reaches past the upper platform, m."""


@dataclass(frozen=True)
class RobotPose:
    """The robot's parts at one pose as polylines (k, 3), m.

    Attributes
    ----------
    upper_arc, lower_arc : ndarray (ARC_SAMPLES, 3)
        The rails of the upper (θ1) and lower (θ2) input arcs.
    upper_platform, lower_platform : ndarray (5, 3)
        Each platform's rectangle, closed.
    tool : ndarray (2, 3)
        The tool's axis from the isocenter out past the upper platform.
    """

    upper_arc: np.ndarray
    lower_arc: np.ndarray
    upper_platform: np.ndarray
    lower_platform: np.ndarray
    tool: np.ndarray


@dataclass(frozen=True)
class DrawnPart:
    """How the review draws one of the robot's parts: its :class:`RobotPose` field, its name,
    and its colour and line width on the page (plotly, px) and in the PNG (matplotlib, pt)."""

    field: str
    name: str
    page_colour: str
    png_colour: str
    page_width: float
    png_width: float

    def points(self, pose: RobotPose) -> np.ndarray:
        """The part's polyline (k, 3) at ``pose``, mm."""
        return getattr(pose, self.field) / MM


ROBOT_PARTS = (
    DrawnPart("upper_arc", "upper arc (θ1)", "#1f77b4", "#1f77b4", 6, 2.5),
    DrawnPart("lower_arc", "lower arc (θ2)", "#ff7f0e", "#ff7f0e", 6, 2.5),
    DrawnPart("upper_platform", "upper platform", "#1f77b4", "#1f77b4", 9, 1.5),
    DrawnPart("lower_platform", "lower platform", "#ff7f0e", "#ff7f0e", 9, 1.5),
    DrawnPart("tool", "tool", "#222222", "0.15", 4, 1.5),
)
"""The robot's parts as the review page and its PNG draw them, in the legends' order."""


def robot_pose(robot: Robot, q: np.ndarray) -> RobotPose:
    """The robot's arcs, platforms and tool at joint angles q (2,), rad.

    Parameters
    ----------
    robot : Robot
        Its rail radii and platform radii, m.
    q : ndarray (2,)
        θ1, θ2, rad.
    """
    theta1, theta2 = (float(angle) for angle in np.asarray(q, dtype=float).reshape(2))
    normal_upper, normal_lower = (
        np.array(n, dtype=float) for n in kinematics.arc_normals(theta1, theta2)
    )
    b = np.array(kinematics.direction(theta1, theta2), dtype=float)
    upper_frame, lower_frame = kinematics.platform_frames(np.array([[theta1, theta2]]))
    x_axis, y_axis = np.eye(3)[0], np.eye(3)[1]
    upper_platform = _rectangle(
        robot.upper_platform_radius * b, upper_frame[0, :, 0], upper_frame[0, :, 1]
    )
    lower_platform = _rectangle(
        robot.lower_platform_radius * b, lower_frame[0, :, 1], lower_frame[0, :, 0]
    )
    return RobotPose(
        upper_arc=_half_circle(x_axis, np.cross(x_axis, normal_upper), robot.upper_arc.rail_radius),
        lower_arc=_half_circle(y_axis, np.cross(normal_lower, y_axis), robot.lower_arc.rail_radius),
        upper_platform=upper_platform,
        lower_platform=lower_platform,
        tool=np.stack([np.zeros(3), (robot.upper_platform_radius + TOOL_OVERHANG) * b]),
    )


def _half_circle(start: np.ndarray, top: np.ndarray, radius: float) -> np.ndarray:
    """The half circle (ARC_SAMPLES, 3), m, of ``radius`` from ``start`` over ``top`` to
    −``start`` (both unit vectors, orthogonal)."""
    phi = np.linspace(0.0, np.pi, ARC_SAMPLES)[:, None]
    return radius * (np.cos(phi) * start + np.sin(phi) * top)


def _rectangle(centre: np.ndarray, along: np.ndarray, across: np.ndarray) -> np.ndarray:
    """The closed rectangle (5, 3), m, of :data:`PLATFORM_SIZE` about ``centre``, its long
    side along the unit vector ``along`` and its short side along ``across``."""
    half_long, half_short = PLATFORM_SIZE[0] / 2, PLATFORM_SIZE[1] / 2
    corners = [(1, 1), (-1, 1), (-1, -1), (1, -1), (1, 1)]
    return np.array([centre + i * half_long * along + j * half_short * across for i, j in corners])
