"""Robot parameters, read from a robot TOML file (units in the keys, SI inside)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spm_opt.errors import UnreachableError
from spm_opt.fields import Table, read_toml
from spm_opt.model import kinematics
from spm_opt.model.actuator import ACTUATORS, Actuator

MM = 1e-3
DEG = math.pi / 180.0


@dataclass(frozen=True)
class Robot:
    """Geometry and limits of one spherical parallel manipulator.

    Attributes
    ----------
    name : str
    upper_platform_radius : float, m
        r_u, distance of the upper platform's mass centre B from the isocenter.
    lower_platform_radius : float, m
        r_L, distance of the lower platform's mass centre D = (r_L / r_u) B.
    upper_arc_radius, lower_arc_radius : float, m
        Radii of the two input arcs (rails).
    joint_range : ndarray, shape (2, 2), rad
        Rows (lower, upper) for θ1 and θ2.
    min_singularity_margin : float
        Smallest allowed value of :func:`kinematics.singularity_margin` (1 at θ = 0).
    actuator : Actuator
    """

    name: str
    upper_platform_radius: float
    lower_platform_radius: float
    upper_arc_radius: float
    lower_arc_radius: float
    joint_range: np.ndarray
    min_singularity_margin: float
    actuator: Actuator

    def unreachable_reason(self, q: np.ndarray) -> list[str | None]:
        """For joint angles (N, 2), rad: why each configuration cannot be taken, or None."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        margins = kinematics.singularity_margins(q)
        reasons: list[str | None] = []
        for (theta1, theta2), margin in zip(q, margins, strict=True):
            reason = None
            for joint, angle in ((0, theta1), (1, theta2)):
                low, high = self.joint_range[joint]
                if not low <= angle <= high:
                    reason = (
                        f"θ{joint + 1} = {angle / DEG:.2f}° is outside the joint range "
                        f"[{low / DEG:g}°, {high / DEG:g}°]"
                    )
                    break
            if reason is None and margin < self.min_singularity_margin:
                reason = (
                    f"too close to a singular configuration (margin {margin:.3f} < "
                    f"{self.min_singularity_margin:g})"
                )
            reasons.append(reason)
        return reasons

    def check_reachable(self, points: np.ndarray, names: list[str]) -> np.ndarray:
        """Joint angles (N, 2), rad, for platform points (N, 3), m, or an error naming one.

        Raises
        ------
        UnreachableError
            Naming the first point (by ``names``) that is at or below the isocenter plane,
            outside the joint range, or near the singular set.
        """
        points = np.atleast_2d(points)
        for name, point in zip(names, points, strict=True):
            if point[2] <= 0.0:
                raise UnreachableError(
                    f"landmark {name}: z = {point[2] / MM:g} mm lies at or below the "
                    "isocenter plane; the robot reaches only z > 0"
                )
        q = kinematics.inverse_kinematics(points)
        for name, reason in zip(names, self.unreachable_reason(q), strict=True):
            if reason is not None:
                raise UnreachableError(f"landmark {name}: {reason}")
        return q


def load_robot(path: str | Path) -> Robot:
    """Read and validate a robot file (see ``problems/robots/prototype.toml``)."""
    root = Table(read_toml(path), str(path))
    name = root.string("name")
    root.string("description", default="")
    upper_platform = root.table("upper_platform")
    lower_platform = root.table("lower_platform")
    upper_arc = root.table("upper_arc")
    lower_arc = root.table("lower_arc")
    joints = root.table("joints")
    actuator = root.table("actuator")
    positive = {"minimum": 0.0, "exclusive_minimum": True}
    robot = Robot(
        name=name,
        upper_platform_radius=upper_platform.number("com_radius_mm", **positive) * MM,
        lower_platform_radius=lower_platform.number("com_radius_mm", **positive) * MM,
        upper_arc_radius=upper_arc.number("rail_radius_mm", **positive) * MM,
        lower_arc_radius=lower_arc.number("rail_radius_mm", **positive) * MM,
        joint_range=np.array(
            [_joint_range(joints, "theta1_range_deg"), _joint_range(joints, "theta2_range_deg")]
        )
        * DEG,
        min_singularity_margin=joints.number(
            "min_singularity_margin", minimum=0.0, maximum=1.0, exclusive_minimum=True
        ),
        actuator=_actuator(actuator),
    )
    for table in (upper_platform, lower_platform, upper_arc, lower_arc, joints, actuator, root):
        table.finish()
    return robot


def _joint_range(joints: Table, key: str) -> np.ndarray:
    low, high = joints.vector(key, length=2, minimum=-89.0, maximum=89.0)
    if low >= high:
        raise joints.error(
            key, [float(low), float(high)], "expected [lower, upper] with lower < upper"
        )
    return np.array([low, high])


def _actuator(table: Table) -> Actuator:
    return ACTUATORS[table.string("model", choices=tuple(ACTUATORS))]
