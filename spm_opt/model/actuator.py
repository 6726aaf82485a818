"""The Dynamixel PRO L54-50-S500-R that drives each input arc (paper Table V).

Facts from ``docs/dynamixel.md``: continuous ratings, the control table's
units, and the current↔torque map. No torque constant is published (the curve exists only
as an image), so the map is an explicit, replaceable table: by default the line through
(0 A, 0 N·m) and the continuous rating (1.9 A, 14.0 N·m), 7.37 N·m/A. A robot file may
give its own table, and an optional reflected rotor inertia, gear efficiency and viscous
and Coulomb friction at the joint, which are off by default so that the paper's results
stay the paper's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

RPM = 2.0 * math.pi / 60.0
"""One revolution per minute in rad/s."""

LOOP_RATE_RANGE_PER_S = (1.0, 10_000.0)
"""The position loop gains and velocity loop bandwidths a robot file accepts, 1/s."""

VELOCITY_LIMIT_UNITS = 8000
"""The control table's default Velocity Limit (address 32), velocity units: the largest
rate command the position loop gives (15.9 rpm on the L54)."""


@dataclass(frozen=True)
class CurrentTorqueMap:
    """Torque at the output from motor current: piecewise linear through a table, odd in
    the current (a negative current gives the opposite torque).

    Attributes
    ----------
    currents_a : tuple of float, A, increasing from 0
    torques_nm : tuple of float, N·m, increasing from 0
    """

    currents_a: tuple[float, ...] = (0.0, 1.9)
    torques_nm: tuple[float, ...] = (0.0, 14.0)

    def torque(self, current_a: np.ndarray) -> np.ndarray:
        """Output torque, N·m, for motor currents, A (extrapolated along the last piece)."""
        return _odd_interp(current_a, self.currents_a, self.torques_nm)

    def current(self, torque_nm: np.ndarray) -> np.ndarray:
        """Motor current, A, that gives output torques, N·m (the map's inverse)."""
        return _odd_interp(torque_nm, self.torques_nm, self.currents_a)


def _odd_interp(x: np.ndarray, xs: tuple[float, ...], ys: tuple[float, ...]) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    magnitude = np.abs(x)
    inside = np.interp(magnitude, xs, ys)
    slope = (ys[-1] - ys[-2]) / (xs[-1] - xs[-2])
    beyond = ys[-1] + slope * (magnitude - xs[-1])
    return np.sign(x) * np.where(magnitude > xs[-1], beyond, inside)


@dataclass(frozen=True)
class Actuator:
    """One actuator model, at its output shaft (SI).

    Attributes
    ----------
    model : str
    continuous_speed_rad_s, continuous_torque_nm, continuous_current_a : float
        Datasheet continuous ratings.
    pulses_per_rev : int
        Encoder resolution at the output.
    velocity_unit_rpm, current_unit_a, acceleration_unit_rpm2 : float
        One unit of the control table's velocity, current and acceleration items.
    current_map : CurrentTorqueMap
    rotor_inertia_kg_m2 : float
        Rotor inertia reflected to the output (J_rotor × gear ratio²); 0 by default.
    gear_efficiency : float
        Efficiency of the gear train in (0, 1]; 1 by default (lossless).
    viscous_friction_nm_s_rad : pair of float
        Viscous friction of each joint (θ1, θ2) at the output, N·m per rad/s; 0 by
        default.
    coulomb_friction_nm : pair of float
        Coulomb friction of each joint at the output (the gear train's), N·m; 0 by
        default.
    position_loop_gain_per_s : pair of float
        The integrated position loop of each joint, 1/s: the P gain from position error to
        rate command, in physical units (a joint that follows a ramp at q̇ lags it by
        q̇ / gain). The executor leads its goals by this lag.
    velocity_loop_bandwidth_per_s : pair of float
        The closed velocity loop's bandwidth of each joint, 1/s (the rate follows its
        command as a first-order lag of this rate): a joint accelerating at q̈ lags a
        further q̈ / (position gain × bandwidth).
    """

    model: str
    continuous_speed_rad_s: float
    continuous_torque_nm: float
    continuous_current_a: float
    pulses_per_rev: int
    velocity_unit_rpm: float
    current_unit_a: float
    acceleration_unit_rpm2: float
    gear_ratio: float
    current_map: CurrentTorqueMap = field(default_factory=CurrentTorqueMap)
    rotor_inertia_kg_m2: float = 0.0
    gear_efficiency: float = 1.0
    viscous_friction_nm_s_rad: tuple[float, float] = (0.0, 0.0)
    coulomb_friction_nm: tuple[float, float] = (0.0, 0.0)
    position_loop_gain_per_s: tuple[float, float] = (32.0, 32.0)
    velocity_loop_bandwidth_per_s: tuple[float, float] = (150.0, 150.0)

    @property
    def velocity_limit_rad_s(self) -> float:
        """The default Velocity Limit at the output, rad/s."""
        return float(self.rate(VELOCITY_LIMIT_UNITS))

    def pulses(self, angle_rad: np.ndarray) -> np.ndarray:
        """Goal/present position units (pulses, rounded) for angles in rad."""
        return np.rint(np.asarray(angle_rad) * self.pulses_per_rev / (2 * math.pi)).astype(np.int64)

    def angle(self, pulses: np.ndarray) -> np.ndarray:
        """Angles in rad for position units (pulses)."""
        return np.asarray(pulses, dtype=float) * (2 * math.pi) / self.pulses_per_rev

    def velocity_units(self, rate_rad_s: np.ndarray) -> np.ndarray:
        """Velocity units (rounded) for joint rates in rad/s."""
        return np.rint(np.asarray(rate_rad_s) / (self.velocity_unit_rpm * RPM)).astype(np.int64)

    def rate(self, velocity_units: np.ndarray) -> np.ndarray:
        """Joint rates in rad/s for velocity units."""
        return np.asarray(velocity_units, dtype=float) * self.velocity_unit_rpm * RPM

    def current(self, current_units: np.ndarray) -> np.ndarray:
        """Motor current in A for current units (Present Current, Goal Torque)."""
        return np.asarray(current_units, dtype=float) * self.current_unit_a

    def current_units(self, current_a: np.ndarray) -> np.ndarray:
        """Current units (rounded) for motor currents in A."""
        return np.rint(np.asarray(current_a) / self.current_unit_a).astype(np.int64)

    def drive_torque(
        self, load_torque_nm: np.ndarray, qd: np.ndarray, qdd: np.ndarray
    ) -> np.ndarray:
        """Torque the motor side must deliver, N·m at the output, for a load torque.

        Adds the reflected rotor inertia J q̈ and the joint's viscous and Coulomb friction
        f_v q̇ + f_c sign(q̇); a gear efficiency η < 1 costs 1/η when the actuator drives the
        load (τ q̇ > 0) and η when the load drives it back.
        """
        torque = (
            np.asarray(load_torque_nm, dtype=float)
            + self.rotor_inertia_kg_m2 * np.asarray(qdd)
            + np.asarray(self.viscous_friction_nm_s_rad) * np.asarray(qd)
            + np.asarray(self.coulomb_friction_nm) * np.sign(qd)
        )
        if self.gear_efficiency == 1.0:
            return torque
        driving = torque * np.asarray(qd) > 0.0
        return np.where(driving, torque / self.gear_efficiency, torque * self.gear_efficiency)


ACTUATORS: dict[str, Actuator] = {
    "L54-50-S500-R": Actuator(
        model="L54-50-S500-R",
        continuous_speed_rad_s=13.7 * RPM,
        continuous_torque_nm=14.0,
        continuous_current_a=1.9,
        pulses_per_rev=361_384,
        velocity_unit_rpm=0.00199234,
        current_unit_a=0.01611328,
        acceleration_unit_rpm2=58_000.0,
        gear_ratio=501.923,
    ),
}
"""Known actuator models by name: the datasheet; a robot file may override the optional
parts (current map, rotor inertia, gear efficiency, viscous and Coulomb friction)."""
