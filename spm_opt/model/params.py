"""Robot parameters, read from a robot TOML file (units in the keys, SI inside)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from spm_opt.base.errors import UnreachableError
from spm_opt.base.fields import Table, apply_overrides, read_toml
from spm_opt.model import kinematics
from spm_opt.model.actuator import ACTUATORS, LOOP_RATE_RANGE_PER_S, Actuator, CurrentTorqueMap
from spm_opt.model.geometry import IDEAL, Geometry

MM = 1e-3
DEG = math.pi / 180.0


@dataclass(frozen=True)
class Body:
    """One rigid body of the robot.

    Attributes
    ----------
    mass : float, kg
    com_radius : float, m
        Distance of the mass centre from the isocenter: along B for the platforms, along the
        arc's symmetry axis (z at θ = 0) for the arcs.
    inertia : ndarray, shape (3, 3), kg·m²
        About the mass centre, in the body frame (Eq. 17 for platforms, Eq. 16 for arcs).
    rail_radius : float or None, m
        The arc's rail radius (arcs only).
    """

    mass: float
    com_radius: float
    inertia: np.ndarray
    rail_radius: float | None = None


@dataclass(frozen=True)
class Payload:
    """A tool carried rigidly by the upper platform: point mass, offset in its frame (m)."""

    mass: float = 0.0
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass(frozen=True)
class Friction:
    """Coulomb friction of the platforms on their rails (Section 5, Eqs. 20–22).

    ``mu`` is the friction coefficient; ``smoothing`` (rad/s) is the sliding rate below
    which optimisers see a smooth sign, v / sqrt(v² + smoothing²).
    """

    mu: float = 0.0
    smoothing: float = 1e-3


@dataclass(frozen=True)
class Robot:
    """Geometry, inertia, friction and limits of one spherical parallel manipulator.

    Attributes
    ----------
    name : str
    upper_platform, lower_platform, upper_arc, lower_arc : Body
    payload : Payload
    friction : Friction
    joint_range : ndarray, shape (2, 2), rad
        Rows (lower, upper) for θ1 and θ2.
    min_singularity_margin : float
        Smallest allowed value of :func:`kinematics.singularity_margin` (1 at θ = 0).
    actuator : Actuator
    gravity : float, m/s²
    encoder_offset : ndarray, shape (2,), rad
        What each encoder of the robot as built reads at θ = 0 (the encoders read
        θ + offset). Only the simulated robot applies it: a plant whose encoders are not
        where the model thinks.
    mechanism : Geometry
        The error angles of the mechanism as built (its encoder zeros are
        ``encoder_offset``; those of ``mechanism`` are 0). Only the simulated robot builds
        it: its tool points where :attr:`built_geometry` says.
    calibration : Geometry
        What the lab measured of the robot (``[calibration]``, :mod:`spm_opt.calibration`):
        the executor's goals and readings go through it (ideal: the model as it is).
    calibration_record : dict
        The calibration's provenance: date, data hash, tracker, fit and held-out errors.
    """

    name: str
    upper_platform: Body
    lower_platform: Body
    upper_arc: Body
    lower_arc: Body
    joint_range: np.ndarray
    min_singularity_margin: float
    actuator: Actuator
    payload: Payload = field(default_factory=Payload)
    friction: Friction = field(default_factory=Friction)
    gravity: float = 9.81
    encoder_offset: np.ndarray = field(default_factory=lambda: np.zeros(2))
    mechanism: Geometry = IDEAL
    calibration: Geometry = IDEAL
    calibration_record: dict[str, Any] = field(default_factory=dict)

    @property
    def built_geometry(self) -> Geometry:
        """The robot as built: :attr:`mechanism` with the encoders' ``encoder_offset``."""
        return dataclasses.replace(
            self.mechanism,
            encoder_zero_1=float(self.encoder_offset[0]),
            encoder_zero_2=float(self.encoder_offset[1]),
        )

    @property
    def upper_platform_radius(self) -> float:
        """r_u, m: distance of the upper platform's mass centre B from the isocenter."""
        return self.upper_platform.com_radius

    @property
    def lower_platform_radius(self) -> float:
        """r_L, m: the lower platform's mass centre is D = (r_L / r_u) B."""
        return self.lower_platform.com_radius

    @property
    def lower_arc_radius(self) -> float:
        """Rail radius of the lower arc, m: the head must fit inside it."""
        return self.lower_arc.rail_radius

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


def load_robot(path: str | Path, overrides: Mapping[str, Any] | None = None) -> Robot:
    """Read and validate a robot file (see ``problems/robots/prototype.toml``); ``overrides``
    replace values by dotted key before validation (``"friction.mu"``)."""
    data = read_toml(path)
    apply_overrides(data, overrides or {}, str(path))
    root = Table(data, str(path))
    name = root.string("name")
    root.string("description", default="")
    bodies = {key: _body(root.table(key), arc=key.endswith("_arc")) for key in _BODIES}
    joints = root.table("joints")
    joint_range = np.array(
        [_joint_range(joints, "theta1_range_deg"), _joint_range(joints, "theta2_range_deg")]
    )
    margin = joints.number(
        "min_singularity_margin", minimum=0.0, maximum=1.0, exclusive_minimum=True
    )
    encoder_offset = joints.vector(
        "encoder_offset_deg", length=2, minimum=-10.0, maximum=10.0, default=np.zeros(2)
    )
    joints.finish()
    robot = Robot(
        name=name,
        **bodies,
        joint_range=joint_range * DEG,
        min_singularity_margin=margin,
        actuator=_actuator(root.table("actuator")),
        payload=_payload(root.table("payload", required=False)),
        friction=_friction(root.table("friction", required=False)),
        encoder_offset=encoder_offset * DEG,
        mechanism=_geometry(root.table("mechanism", required=False), zeros=False),
        **_calibration(root.table("calibration", required=False)),
    )
    root.finish()
    return robot


_ANGLE_LIMIT_DEG = 5.0
"""Largest error angle a robot file takes, deg: calibration models small errors."""


def _geometry(table: Table, zeros: bool) -> Geometry:
    """Error angles from a ``[mechanism]`` or ``[calibration]`` table (deg in the file)."""
    limits = {"minimum": -_ANGLE_LIMIT_DEG, "maximum": _ANGLE_LIMIT_DEG}
    zero = (
        table.vector("encoder_zero_deg", length=2, default=np.zeros(2), **limits)
        if zeros
        else (0, 0)
    )
    twist = table.number("axis_twist_deg", default=0.0, **limits)
    arc = table.vector("arc_tilt_deg", length=2, default=np.zeros(2), **limits)
    tool = table.vector("tool_tilt_deg", length=2, default=np.zeros(2), **limits)
    return Geometry.from_vector(np.radians([*zero, twist, *arc, *tool]))


CALIBRATION_STRINGS = ("date", "data_sha256", "tracker", "method")
"""The text keys of a robot file's ``[calibration]`` provenance."""
CALIBRATION_NUMBERS = (
    "marker_distance_mm",
    "poses",
    "held_out_poses",
    "residual_rms_mm",
    "held_out_rms_mm",
    "held_out_max_mm",
    "predicted_tre_mm",
    "condition_number",
)
"""Its number keys (mm, counts, the condition number)."""


def _calibration(table: Table) -> dict[str, Any]:
    """The ``[calibration]`` table: the geometry and its provenance."""
    geometry = _geometry(table, zeros=True)
    record: dict[str, Any] = {}
    for key in CALIBRATION_STRINGS:
        if table.has(key):
            record[key] = table.string(key)
    for key in CALIBRATION_NUMBERS:
        if table.has(key):
            record[key] = table.number(key, minimum=0.0)
    if table.has("standard_error_deg"):
        errors = table.table("standard_error_deg")
        record["standard_error_deg"] = {k: errors.number(k, minimum=0.0) for k in errors.keys()}
        errors.finish()
    if table.has("unidentified"):
        record["unidentified"] = list(table.raw("unidentified"))
    table.finish()
    return {"calibration": geometry, "calibration_record": record}


def geometry_table(geometry: Geometry, zeros: bool) -> dict[str, Any]:
    """``geometry`` as a robot file's table (deg), as :func:`load_robot` reads it."""
    deg = np.degrees(geometry.vector()).tolist()
    table: dict[str, Any] = {"encoder_zero_deg": deg[:2]} if zeros else {}
    table.update(axis_twist_deg=deg[2], arc_tilt_deg=deg[3:5], tool_tilt_deg=deg[5:7])
    return table


_BODIES = ("upper_platform", "lower_platform", "upper_arc", "lower_arc")
_POSITIVE = {"minimum": 0.0, "exclusive_minimum": True}


def _body(table: Table, arc: bool) -> Body:
    body = Body(
        mass=table.number("mass_kg", minimum=0.0),
        com_radius=table.number("com_radius_mm", minimum=0.0) * MM,
        inertia=_inertia(table),
        rail_radius=table.number("rail_radius_mm", **_POSITIVE) * MM if arc else None,
    )
    table.finish()
    return body


def _inertia(table: Table) -> np.ndarray:
    key = "inertia_kg_m2"
    value = table.raw(key)
    rows = value if isinstance(value, list) and len(value) == 3 else None
    if rows is None or not all(isinstance(r, list) and len(r) == 3 for r in rows):
        raise table.error(key, value, "expected a 3×3 matrix [[..], [..], [..]]")
    flat = [v for row in rows for v in row]
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in flat) or not all(
        math.isfinite(v) for v in flat
    ):
        raise table.error(key, value, "expected finite numbers")
    inertia = np.array(rows, dtype=float)
    if not np.allclose(inertia, inertia.T, rtol=0.0, atol=1e-12):
        raise table.error(key, value, "expected a symmetric matrix")
    if np.min(np.linalg.eigvalsh(inertia)) < -1e-12:
        raise table.error(key, value, "expected a positive semi-definite matrix")
    return inertia


def _payload(table: Table) -> Payload:
    payload = Payload(
        mass=table.number("mass_kg", minimum=0.0, default=0.0),
        offset=table.vector("offset_mm", length=3, default=np.zeros(3)) * MM,
    )
    table.finish()
    return payload


def _friction(table: Table) -> Friction:
    friction = Friction(
        mu=table.number("mu", minimum=0.0, maximum=2.0, default=0.0),
        smoothing=table.number("smoothing_rad_s", default=1e-3, **_POSITIVE),
    )
    table.finish()
    return friction


def _joint_range(joints: Table, key: str) -> np.ndarray:
    low, high = joints.vector(key, length=2, minimum=-89.0, maximum=89.0)
    if low >= high:
        raise joints.error(
            key, [float(low), float(high)], "expected [lower, upper] with lower < upper"
        )
    return np.array([low, high])


def _actuator(table: Table) -> Actuator:
    datasheet = ACTUATORS[table.string("model", choices=tuple(ACTUATORS))]
    current_map = datasheet.current_map
    if table.has("current_a") or table.has("torque_nm"):
        currents = table.vector("current_a", minimum=0.0)
        torques = table.vector("torque_nm", minimum=0.0)
        if len(currents) != len(torques) or len(currents) < 2:
            raise table.error(
                "torque_nm", torques.tolist(), "expected one torque per current_a, at least 2"
            )
        for key, values in (("current_a", currents), ("torque_nm", torques)):
            if values[0] != 0.0 or np.any(np.diff(values) <= 0.0):
                raise table.error(key, values.tolist(), "expected values rising strictly from 0")
        current_map = CurrentTorqueMap(tuple(currents.tolist()), tuple(torques.tolist()))
    actuator = dataclasses.replace(
        datasheet,
        current_map=current_map,
        rotor_inertia_kg_m2=table.number("rotor_inertia_kg_m2", minimum=0.0, default=0.0),
        gear_efficiency=table.number(
            "gear_efficiency", minimum=0.0, maximum=1.0, exclusive_minimum=True, default=1.0
        ),
        viscous_friction_nm_s_rad=tuple(
            table.vector(
                "viscous_friction_nm_s_per_rad",
                length=2,
                minimum=0.0,
                maximum=10.0,
                default=np.zeros(2),
            ).tolist()
        ),
        coulomb_friction_nm=tuple(
            table.vector(
                "coulomb_friction_nm", length=2, minimum=0.0, maximum=10.0, default=np.zeros(2)
            ).tolist()
        ),
        position_loop_gain_per_s=_loop_rates(
            table, "position_loop_gain_per_s", datasheet.position_loop_gain_per_s
        ),
        velocity_loop_bandwidth_per_s=_loop_rates(
            table, "velocity_loop_bandwidth_per_s", datasheet.velocity_loop_bandwidth_per_s
        ),
    )
    table.finish()
    return actuator


def _loop_rates(table: Table, key: str, default: tuple[float, float]) -> tuple[float, float]:
    """A pair of loop rates, 1/s, each in :data:`LOOP_RATE_RANGE_PER_S`."""
    low, high = LOOP_RATE_RANGE_PER_S
    values = table.vector(key, length=2, minimum=low, maximum=high, default=np.array(default))
    return (float(values[0]), float(values[1]))


def robot_toml(robot: Robot, name: str, description: str = "") -> str:
    """``robot`` as the text of a robot file (what :func:`load_robot` reads back)."""
    document: dict[str, Any] = {"name": name, "description": description}
    for key in _BODIES:
        body = getattr(robot, key)
        table: dict[str, Any] = {}
        if body.rail_radius is not None:
            table["rail_radius_mm"] = body.rail_radius / MM
        table["com_radius_mm"] = body.com_radius / MM
        table["mass_kg"] = body.mass
        table["inertia_kg_m2"] = body.inertia.tolist()
        document[key] = table
    document["payload"] = {
        "mass_kg": robot.payload.mass,
        "offset_mm": (robot.payload.offset / MM).tolist(),
    }
    document["friction"] = {"mu": robot.friction.mu, "smoothing_rad_s": robot.friction.smoothing}
    document["joints"] = {
        "theta1_range_deg": (robot.joint_range[0] / DEG).tolist(),
        "theta2_range_deg": (robot.joint_range[1] / DEG).tolist(),
        "min_singularity_margin": robot.min_singularity_margin,
        "encoder_offset_deg": (robot.encoder_offset / DEG).tolist(),
    }
    actuator = robot.actuator
    document["actuator"] = {
        "model": actuator.model,
        "current_a": list(actuator.current_map.currents_a),
        "torque_nm": list(actuator.current_map.torques_nm),
        "rotor_inertia_kg_m2": actuator.rotor_inertia_kg_m2,
        "gear_efficiency": actuator.gear_efficiency,
        "viscous_friction_nm_s_per_rad": list(actuator.viscous_friction_nm_s_rad),
        "coulomb_friction_nm": list(actuator.coulomb_friction_nm),
        "position_loop_gain_per_s": list(actuator.position_loop_gain_per_s),
        "velocity_loop_bandwidth_per_s": list(actuator.velocity_loop_bandwidth_per_s),
    }
    if not robot.mechanism.is_ideal:
        document["mechanism"] = geometry_table(robot.mechanism, zeros=False)
    if not robot.calibration.is_ideal or robot.calibration_record:
        document["calibration"] = {
            **geometry_table(robot.calibration, zeros=True),
            **robot.calibration_record,
        }
    return tomli_w.dumps(document)
