"""What the executor needs from a device: the small ``Backend`` interface and its clock.

A backend is the only code that knows a device (the simulated robot, or Dynamixel
actuators through the official SDK). The executor streams goal positions to it and reads
the measured state back, once per control period, on the backend's clock.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from spm_opt.base.errors import CommunicationError

__all__ = [
    "CLOCK_EPSILON_S",
    "HARDWARE_ERROR_BITS",
    "Backend",
    "Clock",
    "CommunicationError",
    "Measurement",
    "MonotonicClock",
    "VirtualClock",
    "hardware_error_names",
]

HARDWARE_ERROR_BITS = {
    0: "input voltage",
    1: "hall sensor",
    2: "overheating",
    3: "encoder",
    4: "electrical shock",
    5: "overload",
}
"""Bits of the actuators' Hardware Error Status (control table address 892)."""


def hardware_error_names(status: int) -> list[str]:
    """Names of the bits set in one actuator's Hardware Error Status byte."""
    return [name for bit, name in HARDWARE_ERROR_BITS.items() if status >> bit & 1] or (
        [f"unknown bits 0x{status:02x}"] if status else []
    )


@dataclass(frozen=True)
class Measurement:
    """One reading of both actuators, at their output shafts.

    Attributes
    ----------
    position_rad : ndarray, shape (2,), rad
    velocity_rad_s : ndarray, shape (2,), rad/s
    current_a : ndarray, shape (2,), A (signed)
    hardware_error : tuple of int
        Hardware Error Status of each actuator (0: none); see :data:`HARDWARE_ERROR_BITS`.
    """

    position_rad: np.ndarray
    velocity_rad_s: np.ndarray
    current_a: np.ndarray
    hardware_error: tuple[int, int] = (0, 0)


CLOCK_EPSILON_S = 1e-9
"""Rounding of the loop's clock, s: a time this close to a boundary counts as on it."""


@runtime_checkable
class Clock(Protocol):
    """Time for the control loop, s, on a clock that never goes backwards."""

    def now(self) -> float: ...

    def sleep_until(self, deadline: float) -> None: ...


class MonotonicClock:
    """The machine's monotonic clock; sleeps coarsely, then spins the last ``spin_s``."""

    def __init__(self, spin_s: float = 0.0005) -> None:
        self.spin_s = spin_s

    def now(self) -> float:
        return time.perf_counter()

    def sleep_until(self, deadline: float) -> None:
        remaining = deadline - time.perf_counter()
        if remaining > self.spin_s:
            time.sleep(remaining - self.spin_s)
        while time.perf_counter() < deadline:
            pass


class VirtualClock:
    """Simulated time that jumps to each deadline: runs a simulation as fast as it can."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = start

    def now(self) -> float:
        return self._now

    def sleep_until(self, deadline: float) -> None:
        if math.isfinite(deadline):
            self._now = max(self._now, deadline)


@runtime_checkable
class Backend(Protocol):
    """A device with two position-controlled actuators.

    ``connect`` opens and checks the device and enables torque in position mode;
    ``read`` returns both actuators' state; ``read_current`` only their Present Current
    (the control loop reads it again between goals); ``write_goal`` sends both goal positions;
    ``close`` releases the device and leaves the actuators holding their last goal.
    ``read`` and ``write_goal`` raise :class:`CommunicationError` when a transaction
    fails; the executor takes a goal whose write raised as never delivered, and counts a
    failed write against the same retry budget as a failed read. ``describe`` is plain
    data for the log's header (device, settings, counters).
    """

    clock: Clock

    def connect(self) -> None:
        """Open and check the device; enable torque in position mode."""

    def read(self) -> Measurement:
        """Both actuators' state now (CommunicationError when the transaction fails)."""

    def read_current(self, timeout_s: float) -> np.ndarray:
        """Both actuators' Present Current now (2,), A, signed; CommunicationError when the
        transaction fails or its replies take longer than ``timeout_s`` (s)."""

    def write_goal(self, position_rad: np.ndarray) -> None:
        """Send both goal positions (2,), rad (CommunicationError when it fails)."""

    def close(self) -> None:
        """Release the device; the actuators keep holding their last goal."""

    def describe(self) -> dict[str, Any]:
        """Plain data for the log's header: device, settings, counters."""
