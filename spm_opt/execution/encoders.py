"""The calibrated robot's encoders: the model's joint coordinates to and from the readings.

A robot file's ``[calibration]`` (:mod:`spm_opt.calibration`) says where the robot's tool
points for what its encoders read. :class:`CalibratedEncoders` wraps any backend so that
the executor, its checks and its log keep the model's joint coordinates, in which the
plan's tool direction is the ideal kinematics': each goal goes out as the readings that
put the built robot's tool there (:func:`spm_opt.model.geometry.encoder_readings`), and
each reading comes back as the model's coordinates of the tool's direction
(:func:`~spm_opt.model.geometry.model_from_readings`; rates through the two Jacobians).
Currents and hardware errors pass unchanged.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from spm_opt.execution.backend import Backend, Clock, Measurement
from spm_opt.model import geometry
from spm_opt.model.geometry import Geometry


class CalibratedEncoders:
    """A :class:`~spm_opt.execution.backend.Backend` that speaks the model's joint
    coordinates to a ``device`` whose encoders read the calibrated ``geometry``."""

    def __init__(self, device: Backend, calibration: Geometry) -> None:
        self.device = device
        self.calibration = calibration

    @property
    def clock(self) -> Clock:
        return self.device.clock

    def connect(self) -> None:
        """Open the device."""
        self.device.connect()

    def read(self) -> Measurement:
        """The device's state in the model's joint coordinates."""
        raw = self.device.read()
        g = self.calibration
        true = raw.position_rad - g.encoder_zero
        return Measurement(
            position_rad=geometry.model_joint_angles(true[None, :], g)[0],
            velocity_rad_s=geometry.model_joint_rates(
                true[None, :], raw.velocity_rad_s[None, :], g
            )[0],
            current_a=raw.current_a,
            hardware_error=raw.hardware_error,
        )

    def read_current(self, timeout_s: float) -> np.ndarray:
        """The device's Present Current (2,), A."""
        return self.device.read_current(timeout_s)

    def write_goal(self, position_rad: np.ndarray) -> None:
        """Send the readings that put the tool where the model's ``position_rad`` does."""
        q = np.asarray(position_rad, dtype=float)[None, :]
        self.device.write_goal(geometry.encoder_readings(q, self.calibration)[0])

    def close(self) -> None:
        """Release the device."""
        self.device.close()

    def describe(self) -> dict[str, Any]:
        """The device's description, and the calibration its readings go through (deg)."""
        return {**self.device.describe(), "calibration_deg": geometry.degrees(self.calibration)}


def calibrated(device: Backend, calibration: Geometry) -> Backend:
    """``device`` seen through ``calibration``; ``device`` itself when it is ideal."""
    return device if calibration.is_ideal else CalibratedEncoders(device, calibration)
