"""Plausible plants around a robot file: the robot a simulated plant integrates and its
actuators' loops, drawn within stated ranges, for tests of identification and for a lab that
wants to stress its setup on robots that are not its model.

A plant is a point of the unit cube, one coordinate per :data:`COORDINATES` entry, mapped
linearly onto :class:`PlantRanges` (:meth:`PlantFamily.plant`); :meth:`PlantFamily.draw`
takes the point from a random generator, and a property-based test from its own strategy.
Each body's mass is scaled with its inertia (a denser body of the same shape); the arcs'
mass-centre radii are scaled apart (the platforms' are the mechanism's lengths); the rails'
μ, each joint's viscous and Coulomb friction, the gear efficiency η and the reflected rotor
inertia are set within their ranges; the loops are the Position P and Velocity P Gains that
give Kp and ωv (:func:`~spm_opt.execution.plant.gains_for_rates`, rounded to control-table
units, so :meth:`Plant.loops` gives the plant's own). Lengths, payload and encoder offsets
stay the robot file's.

    >>> family = PlantFamily(load_robot("problems/robots/prototype.toml"))
    >>> plant = family.draw(np.random.default_rng(3))
    >>> SimulatedRobot(family.robot, plant_robot=plant.robot, settings=plant.settings)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from spm_opt.base.errors import InputError
from spm_opt.execution.plant import PlantSettings, gains_for_rates, loop_rates
from spm_opt.model.params import Body, Robot
from spm_opt.model.regressor import BODIES

__all__ = ["COORDINATES", "Plant", "PlantFamily", "PlantRanges"]

Pair = tuple[float, float]
ARCS = ("upper_arc", "lower_arc")
COORDINATES = (
    *(f"{body}.mass" for body in BODIES),
    *(f"{arc}.com_radius" for arc in ARCS),
    "friction.mu",
    "viscous_friction.theta1",
    "viscous_friction.theta2",
    "coulomb_friction.theta1",
    "coulomb_friction.theta2",
    "gear_efficiency",
    "rotor_inertia",
    "position_loop_gain.theta1",
    "position_loop_gain.theta2",
    "velocity_loop_bandwidth.theta1",
    "velocity_loop_bandwidth.theta2",
)
"""The unit cube's coordinates, in order (17)."""


@dataclass(frozen=True)
class PlantRanges:
    """The family's ranges, each (low, high).

    Attributes
    ----------
    mass_scale : each body's mass and inertia, times the robot file's
    com_radius_scale : each arc's mass-centre radius, times the robot file's
    mu : the rails' friction coefficient
    viscous_friction_nm_s_rad : each joint's, N·m·s/rad
    coulomb_friction_nm : each joint's gear train, N·m
    gear_efficiency : η
    rotor_inertia_kg_m2 : reflected at the output, kg·m²
    position_loop_gain_per_s : each joint's Kp, 1/s
    velocity_loop_bandwidth_per_s : each joint's ωv, 1/s
    """

    mass_scale: Pair = (0.7, 1.3)
    com_radius_scale: Pair = (0.85, 1.15)
    mu: Pair = (0.05, 0.3)
    viscous_friction_nm_s_rad: Pair = (0.0, 0.4)
    coulomb_friction_nm: Pair = (0.0, 0.04)
    gear_efficiency: Pair = (0.7, 1.0)
    rotor_inertia_kg_m2: Pair = (0.0, 5e-3)
    position_loop_gain_per_s: Pair = (20.0, 60.0)
    velocity_loop_bandwidth_per_s: Pair = (60.0, 300.0)

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            low, high = getattr(self, field.name)
            if not (np.isfinite(low) and np.isfinite(high) and 0.0 <= low <= high):
                raise InputError(
                    f"{field.name} = ({low!r}, {high!r}): expected finite 0 <= low <= high"
                )
        if self.gear_efficiency[1] > 1.0 or self.gear_efficiency[0] <= 0.0:
            raise InputError(f"gear_efficiency = {self.gear_efficiency}: expected within (0, 1]")


@dataclass(frozen=True)
class Plant:
    """One plant of a family.

    Attributes
    ----------
    robot : Robot
        What the plant integrates (``SimulatedRobot(..., plant_robot=robot)``).
    settings : PlantSettings
        Its actuators' gains and current noise (``SimulatedRobot(..., settings=settings)``).
    point : ndarray, shape (17,)
        Its place in the family's unit cube (:data:`COORDINATES`).
    """

    robot: Robot
    settings: PlantSettings
    point: np.ndarray

    def loops(self) -> tuple[np.ndarray, np.ndarray]:
        """The plant's own Kp and ωv per joint (2,), 1/s, from its rounded gains."""
        return loop_rates(self.robot, self.settings)


@dataclass(frozen=True)
class PlantFamily:
    """Plants around ``robot`` within ``ranges``; ``settings`` gives the plants' other
    assumptions (integration step, units of the gains, current noise)."""

    robot: Robot
    ranges: PlantRanges = PlantRanges()
    settings: PlantSettings = PlantSettings()

    def draw(self, rng: np.random.Generator, noise_seed: int | None = None) -> Plant:
        """A plant at a uniformly random point; its current noise seeded by ``noise_seed``
        (default: from ``rng``)."""
        point = rng.uniform(0.0, 1.0, len(COORDINATES))
        seed = int(rng.integers(2**31)) if noise_seed is None else noise_seed
        return self.plant(point, seed)

    def plant(self, point: Sequence[float], noise_seed: int = 0) -> Plant:
        """The plant at ``point`` of the unit cube (17,), each coordinate in [0, 1]."""
        at = np.asarray(point, dtype=float)
        if at.shape != (len(COORDINATES),) or not np.all((at >= 0.0) & (at <= 1.0)):
            raise InputError(
                f"point: expected {len(COORDINATES)} coordinates in [0, 1], got {at.tolist()}"
            )
        value = dict(zip(COORDINATES, at, strict=True))
        ranges = self.ranges

        def within(pair: Pair, fraction: float) -> float:
            return float(pair[0] + fraction * (pair[1] - pair[0]))

        def per_joint(pair: Pair, name: str) -> Pair:
            return within(pair, value[f"{name}.theta1"]), within(pair, value[f"{name}.theta2"])

        bodies = {}
        for name in BODIES:
            body: Body = getattr(self.robot, name)
            scale = within(ranges.mass_scale, value[f"{name}.mass"])
            radius = body.com_radius
            if name in ARCS:
                radius *= within(ranges.com_radius_scale, value[f"{name}.com_radius"])
            bodies[name] = dataclasses.replace(
                body, mass=body.mass * scale, inertia=body.inertia * scale, com_radius=radius
            )
        actuator = dataclasses.replace(
            self.robot.actuator,
            viscous_friction_nm_s_rad=per_joint(
                ranges.viscous_friction_nm_s_rad, "viscous_friction"
            ),
            coulomb_friction_nm=per_joint(ranges.coulomb_friction_nm, "coulomb_friction"),
            gear_efficiency=within(ranges.gear_efficiency, value["gear_efficiency"]),
            rotor_inertia_kg_m2=within(ranges.rotor_inertia_kg_m2, value["rotor_inertia"]),
        )
        friction = dataclasses.replace(
            self.robot.friction, mu=within(ranges.mu, value["friction.mu"])
        )
        robot = dataclasses.replace(
            self.robot,
            name=f"{self.robot.name}_plant",
            actuator=actuator,
            friction=friction,
            **bodies,
        )
        position, velocity = gains_for_rates(
            robot,
            self.settings,
            per_joint(ranges.position_loop_gain_per_s, "position_loop_gain"),
            per_joint(ranges.velocity_loop_bandwidth_per_s, "velocity_loop_bandwidth"),
        )
        settings = dataclasses.replace(
            self.settings, position_p_gain=position, velocity_p_gain=velocity, seed=noise_seed
        )
        return Plant(robot, settings, at)
