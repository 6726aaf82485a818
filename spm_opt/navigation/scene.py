"""What the navigation link shows, in the image's RAS frame, mm: the tool's pose, the
planned and executed cuts, the contour and the tube's edges.

Frames: the robot's (origin at the isocenter, z up, mm here) and the image's RAS (3D
Slicer's scene). The registration ``image_to_robot`` (4×4, mm) takes RAS to the robot's
frame; a problem without one is shown with the robot's frame as RAS. The tool's frame
(``ToolToRAS``) has its origin at the tool tip, where the tool meets the skull, and its
axes those of the upper platform (paper Eq. 17): z along the tool, outward from the
isocenter; y the upper arc's normal; x = y × z.
"""

from __future__ import annotations

import numpy as np

from spm_opt.model import kinematics
from spm_opt.model.params import MM
from spm_opt.model.rigid import apply
from spm_opt.problem.problem import Problem


def image_to_robot(problem: Problem) -> np.ndarray:
    """The problem's registration (4, 4), RAS mm to robot mm; identity without one."""
    skull = problem.skull
    if skull is None or skull.image_to_robot_mm is None:
        return np.eye(4)
    return np.asarray(skull.image_to_robot_mm, dtype=float)


def robot_to_ras(image_to_robot_mm: np.ndarray) -> np.ndarray:
    """The inverse of a registration (4, 4): robot mm to RAS mm."""
    return np.linalg.inv(np.asarray(image_to_robot_mm, dtype=float))


def tool_to_robot(problem: Problem, q_rad: np.ndarray) -> np.ndarray:
    """The tool's poses in the robot's frame for joint angles (N, 2), rad: (N, 4, 4), mm."""
    q = np.atleast_2d(np.asarray(q_rad, dtype=float))
    upper, _ = kinematics.platform_frames(q)
    directions = upper[:, :, 2]
    poses = np.zeros((len(q), 4, 4))
    poses[:, :3, :3] = upper
    poses[:, :3, 3] = problem.contour.cut_points(directions) / MM
    poses[:, 3, 3] = 1.0
    return poses


def tool_to_ras(problem: Problem, q_rad: np.ndarray, robot_to_ras_mm: np.ndarray) -> np.ndarray:
    """The tool's poses in RAS for joint angles (N, 2), rad: (N, 4, 4), mm."""
    return robot_to_ras_mm @ tool_to_robot(problem, q_rad)


def in_ras(points_m: np.ndarray, robot_to_ras_mm: np.ndarray) -> np.ndarray:
    """Points (N, 3) of the robot's frame, m, in RAS, mm."""
    return apply(robot_to_ras_mm, np.asarray(points_m, dtype=float) / MM)


def cut_points(problem: Problem, q_rad: np.ndarray, robot_to_ras_mm: np.ndarray) -> np.ndarray:
    """Where the tool meets the skull at joint angles (N, 2), rad: points (N, 3) in RAS, mm."""
    directions = kinematics.forward_kinematics(np.atleast_2d(q_rad), 1.0)
    return in_ras(problem.contour.cut_points(directions), robot_to_ras_mm)


def _contour_samples(problem: Problem, step_mm: float) -> np.ndarray:
    """The contour's points every ``step_mm`` (mm) of its length, at least 8: (N, 3), m."""
    contour = problem.contour
    count = max(8, int(np.ceil(contour.length / (step_mm * MM))) + 1)
    return contour.point_at(np.linspace(0.0, contour.length, count))


def contour_points(
    problem: Problem, robot_to_ras_mm: np.ndarray, step_mm: float = 0.5
) -> np.ndarray:
    """The contour sampled every ``step_mm`` (mm) of its length: (N, 3) in RAS, mm."""
    return in_ras(_contour_samples(problem, step_mm), robot_to_ras_mm)


def tube_edges(
    problem: Problem, robot_to_ras_mm: np.ndarray, step_mm: float = 0.5
) -> np.ndarray | None:
    """The tube's two edges on the skull: the contour moved by the contour tolerance to
    either side, across the contour and along the skull; (2, N, 3) in RAS, mm (None for a
    problem without a contour tolerance)."""
    half_width = problem.limits.contour_tolerance
    if half_width is None:
        return None
    points = _contour_samples(problem, step_mm)
    across = np.cross(points, np.gradient(points, axis=0))
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    return np.stack(
        [in_ras(points + side * half_width * across, robot_to_ras_mm) for side in (1.0, -1.0)]
    )
