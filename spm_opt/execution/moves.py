"""The executor's moves off the plan: jerk-limited ruckig moves of both joints, the
approach to the plan's start and the stop to rest."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import ruckig

from spm_opt.base.errors import PreflightError
from spm_opt.base.ruckig_local import calculate_locally
from spm_opt.execution.cycle import Commanded
from spm_opt.execution.feed import JointLimits
from spm_opt.execution.preflight import degrees
from spm_opt.execution.settings import ExecutionSettings
from spm_opt.model.params import DEG


@dataclass(frozen=True)
class Segment:
    """A goal stream: ``at(t)`` gives position, rate and acceleration (each (2,), SI) at
    time t since its start, for t in [0, duration]."""

    duration: float
    at: Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]


def approach_move(
    settings: ExecutionSettings, limits: JointLimits, measured: np.ndarray, start: np.ndarray
) -> Segment | None:
    """The move from the robot at ``measured`` (rad) to the plan's ``start`` (rad): None
    within the start tolerance; a :class:`PreflightError` when it is needed and not asked
    for (``settings.approach``)."""
    distance = float(np.max(np.abs(measured - start)))
    if distance <= settings.start_tolerance_rad:
        return None
    if not settings.approach:
        raise PreflightError(
            f"robot at {degrees(measured)}, the plan starts at {degrees(start)}: "
            f"{distance / DEG:.3f} deg away (tolerance "
            f"{settings.start_tolerance_rad / DEG:.3f} deg); ask for an approach move "
            "(spm-opt execute --approach; ExecutionSettings(approach=True))"
        )
    return jerk_limited_move(
        "approach",
        Commanded(measured, np.zeros(2), np.zeros(2), measured),
        limits,
        target=start,
        speed=settings.approach_speed_rad_s,
    )


def jerk_limited_move(
    name: str,
    commanded: Commanded,
    limits: JointLimits,
    target: np.ndarray | None,
    speed: float = 0.0,
) -> Segment:
    """A jerk-limited move from the commanded state within ``limits``: to rest at
    ``target`` (rad) at no more than ``speed`` (rad/s), or (None) to rest as soon as the
    limits allow."""
    acceleration, jerk = limits.acceleration, limits.jerk
    inp = ruckig.InputParameter(2)
    inp.current_position = list(commanded.position)
    inp.current_velocity = list(commanded.velocity)
    inp.current_acceleration = list(np.clip(commanded.acceleration, -acceleration, acceleration))
    inp.max_acceleration = [acceleration] * 2
    inp.max_jerk = [jerk] * 2
    if target is None:
        inp.control_interface = ruckig.ControlInterface.Velocity
        inp.target_velocity = [0.0, 0.0]
        inp.max_velocity = [max(limits.speed, *np.abs(commanded.velocity))] * 2
    else:
        inp.target_position = list(target)
        inp.max_velocity = [min(speed, limits.speed)] * 2
    motion = calculate_locally(inp, name)

    def goal(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        position, velocity, acceleration = motion.at_time(t)
        return np.array(position), np.array(velocity), np.array(acceleration)

    return Segment(motion.duration, goal)
