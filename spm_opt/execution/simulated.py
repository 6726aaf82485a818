"""The simulated robot as a backend: the plant read and commanded in the actuators' units."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from spm_opt.execution.backend import Clock, Measurement, MonotonicClock, VirtualClock
from spm_opt.execution.plant import DynamixelPlant, PlantSettings, StateTrace, TrueState
from spm_opt.model.params import Robot


class SimulatedRobot:
    """A :class:`~spm_opt.execution.backend.Backend` on :class:`DynamixelPlant`.

    Parameters
    ----------
    robot : Robot
        The robot as the controller knows it (the actuators' units).
    start_rad : ndarray, shape (2,), rad, optional
        Where the robot rests at connection (default: θ = 0).
    settings : PlantSettings, optional
    realtime : bool
        False (default): simulated time jumps from one control period to the next, so a run
        takes as long as its computation. True: the plant follows the machine's clock.
    plant_robot : Robot, optional
        The robot the plant integrates (default ``robot``): a "real" robot that is not the
        planning model (other masses, friction, rotor inertia, gear losses, encoder offset).

    Attributes
    ----------
    plant : DynamixelPlant
    trace : StateTrace
        The plant's true state at every ``read``, on the backend's clock (the log's time).
    """

    def __init__(
        self,
        robot: Robot,
        start_rad: np.ndarray | None = None,
        settings: PlantSettings | None = None,
        realtime: bool = False,
        plant_robot: Robot | None = None,
    ) -> None:
        self.plant = DynamixelPlant(plant_robot or robot, settings, start_rad)
        self._actuator = robot.actuator
        self.realtime = realtime
        self.clock: Clock = MonotonicClock() if realtime else VirtualClock()
        self._epoch = self.clock.now()
        self.trace = StateTrace()

    @property
    def true_state(self) -> TrueState:
        """The plant's exact state now (no quantisation, no noise), on the backend's clock."""
        self.plant.advance_to(self.clock.now() - self._epoch)
        return self.plant.true_state(self.clock.now())

    def connect(self) -> None:
        """Enable torque on both actuators (each holds where it is)."""
        self._epoch = self.clock.now() - self.plant.time_s
        for joint in range(2):
            self.plant.enable_torque(joint, True)

    def read(self) -> Measurement:
        """The plant's state now, as the actuators report it (encoder offsets included)."""
        now = self.clock.now()
        self.plant.advance_to(now - self._epoch)
        self.trace.record(now, self.plant)
        a = self._actuator
        return Measurement(
            position_rad=a.angle(self.plant.present_position_pulses()),
            velocity_rad_s=a.rate(self.plant.present_velocity_units()),
            current_a=a.current(self.plant.present_current_units()),
            hardware_error=(int(self.plant.hardware_error[0]), int(self.plant.hardware_error[1])),
        )

    def read_current(self, timeout_s: float) -> np.ndarray:
        """The plant's Present Current now, A, as the actuators report it (no wait:
        ``timeout_s`` is moot)."""
        self.plant.advance_to(self.clock.now() - self._epoch)
        return self._actuator.current(self.plant.present_current_units())

    def write_goal(self, position_rad: np.ndarray) -> None:
        """Give both actuators new goals (2,), rad, rounded to whole pulses."""
        self.plant.advance_to(self.clock.now() - self._epoch)
        self.plant.goal_position_rad[:] = self._actuator.angle(self._actuator.pulses(position_rad))

    def close(self) -> None:
        """Nothing to release: the simulated actuators keep holding their goals."""

    def describe(self) -> dict[str, Any]:
        """The simulation's settings, for the log's header."""
        return {
            "backend": "simulated",
            "realtime": self.realtime,
            "plant": dataclasses.asdict(self.plant.settings),
            "plant_robot": self.plant.robot.name,
            "plant_time_s": self.plant.time_s,
        }
