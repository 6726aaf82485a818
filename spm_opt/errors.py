"""The project's exceptions, all in one place.

    SpmOptError                      root of every error this package raises on purpose
    ├── InputError (ValueError)      a user's input is wrong: file, key, value, argument
    │   ├── UnreachableError         a landmark or configuration the robot cannot take
    │   ├── UnknownPlannerError      a planner name that is not registered
    │   └── PreflightError           the executor refuses a plan, or a robot not at its start
    ├── PlanningError                a planner could not produce a plan for a valid problem
    ├── CommunicationError           a transaction with a device failed (timeout, corrupt reply)
    └── DeviceError                  a device reports a fault (a hardware error at connection)

Messages are one line naming the field, the value and what is allowed; the command line
prints them as they are and exits with status 2.
"""

from __future__ import annotations


class SpmOptError(Exception):
    """Root of every error raised on purpose by spm_opt."""


class InputError(SpmOptError, ValueError):
    """A user's input (file, key, value or argument) is not acceptable."""


class UnreachableError(InputError):
    """A landmark or configuration lies outside what the robot can take."""


class UnknownPlannerError(InputError):
    """A planner name that is not in the registry."""


class PlanningError(SpmOptError):
    """A planner failed on a valid problem; the message says why."""


class PreflightError(InputError):
    """The executor refuses a plan: it breaks a limit, or the robot is not at its start."""


class CommunicationError(SpmOptError):
    """A transaction with a device failed (timeout, corrupt reply, port error)."""


class DeviceError(SpmOptError):
    """A device reports a fault of its own (e.g. an actuator's hardware error status)."""
