"""The joint side of the actuators' torque, as the planners bound it: the load torque (with
smooth friction) plus the drives' rotor inertia J q̈, viscous friction f_v q̇ and Coulomb
friction f_c σ(q̇), N·m per joint (:func:`spm_opt.judge.limits.planner_bounds` translates the
actuators' torque and current limits to a bound on it).

In CasADi (:func:`load_torque`) it reads the B-spline torque table of
:mod:`spm_opt.model.torque_table`, with the robot given as numbers
(:func:`dynamics_parameters`), so one function serves every robot of a joint range; in
numpy (:func:`joint_side_torque`) it reads the Lagrange model.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from spm_opt.model import dynamics, torque_table
from spm_opt.model.params import Robot

DRIVE_ENTRIES = 5
"""The drives' entries after the torque table's values in :func:`dynamics_parameters`:
the rotor's J, then each joint's viscous and each joint's Coulomb friction."""


def load_torque(joint_range: bytes) -> Callable[..., ca.SX]:
    """(q, q̇, q̈, parameters) -> the joint side of the actuators' torque, N·m, for robots
    of a joint range (its bytes, :func:`range_key`): the load torque (smooth friction) plus
    the drives' J q̈, f_v q̇ and f_c σ(q̇), σ(v) = v / sqrt(v² + s²) with the friction's
    smoothing s (the table's last value); ``parameters``: :func:`dynamics_parameters`."""
    table = torque_table.torque_function(np.frombuffer(joint_range).reshape(2, 2))

    def torque(q: ca.SX, qd: ca.SX, qdd: ca.SX, parameters: ca.SX) -> ca.SX:
        values, drives = parameters[:-DRIVE_ENTRIES], parameters[-DRIVE_ENTRIES:]
        rotor, viscous, coulomb = drives[0], drives[1:3], drives[3:5]
        smoothing = values[-1]
        sliding = qd / ca.sqrt(qd**2 + smoothing**2)
        return table(q, qd, qdd, values) + rotor * qdd + viscous * qd + coulomb * sliding

    return torque


def joint_side_torque(robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """:func:`load_torque` in numpy over samples (N, 2), N·m, from the Lagrange model
    (not the table)."""
    actuator, smoothing = robot.actuator, robot.friction.smoothing
    load = dynamics.inverse_dynamics(robot, q, qd, qdd, exact=False)
    return (
        load
        + actuator.rotor_inertia_kg_m2 * qdd
        + np.asarray(actuator.viscous_friction_nm_s_rad) * qd
        + np.asarray(actuator.coulomb_friction_nm) * qd / np.sqrt(qd**2 + smoothing**2)
    )


def range_key(joint_range: np.ndarray) -> bytes:
    """A robot's joint range (2, 2), rad, as bytes: the torque table, and so every function
    of :func:`load_torque`, depend on it."""
    return np.ascontiguousarray(joint_range, dtype=float).tobytes()


def dynamics_parameters(robot: Robot) -> np.ndarray:
    """The robot as :func:`load_torque` takes it: its torque table's values, then the
    drives' J, f_v (per joint) and f_c (per joint)."""
    actuator = robot.actuator
    drives = [
        actuator.rotor_inertia_kg_m2,
        *actuator.viscous_friction_nm_s_rad,
        *actuator.coulomb_friction_nm,
    ]
    return np.concatenate([torque_table.table_values(robot), drives])
