"""The Dynamixel PRO actuators that drive the input arcs (paper Table V).

Only the continuous ratings are here for now; the control-table units and the
current-to-torque map follow with the dynamics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

RPM = 2.0 * math.pi / 60.0
"""One revolution per minute in rad/s."""


@dataclass(frozen=True)
class Actuator:
    """Continuous ratings of one actuator model, at its output shaft (SI)."""

    model: str
    continuous_speed_rad_s: float
    continuous_torque_nm: float


ACTUATORS: dict[str, Actuator] = {
    "L54-50-S500-R": Actuator(
        model="L54-50-S500-R",
        continuous_speed_rad_s=13.7 * RPM,
        continuous_torque_nm=14.0,
    ),
}
"""Known actuator models by name (``shared/reference/dynamixel-l54.md``)."""
