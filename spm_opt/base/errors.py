"""The project's exceptions, all in one place.

    SpmOptError                      root of every error this package raises on purpose
    ├── InputError (ValueError)      a user's input is wrong: file, key, value, argument
    │   ├── UnreachableError         a landmark or configuration the robot cannot take
    │   ├── UnknownPlannerError      a planner name that is not registered
    │   └── PreflightError           the executor refuses a plan, or a robot not at its start
    ├── PlanningError                a planner could not produce a plan for a valid problem
    ├── CommunicationError           a transaction with a device failed (timeout, corrupt reply)
    ├── DeviceError                  a device reports a fault (a hardware error at connection)
    ├── RunInterrupted               a run stopped before the robot moved (nothing written)
    ├── StopAsked                    SIGINT or SIGTERM stopped one run of several: make no more
    └── MissingDependency (ImportError)  an optional package is not installed

Messages are one line naming the field, the value and what is allowed; the command line
prints them as they are and exits with status 2. :func:`require` is the one place that
imports an optional package and turns its absence into :class:`MissingDependency`.
"""

from __future__ import annotations

import importlib
from types import ModuleType

OPTIONAL: dict[str, tuple[str, str]] = {
    "tqdm": ("tqdm", "sweep"),
    "pyarrow": ("pyarrow", "sweep"),
    "distributed": ("distributed", "sweep"),
    "threadpoolctl": ("threadpoolctl", "sweep"),
    "dynamixel_sdk": ("dynamixel-sdk", "hardware"),
    "serial": ("pyserial", "hardware"),
    "sksurgerynditracker.nditracker": ("scikit-surgerynditracker", "hardware"),
    "mujoco": ("mujoco", "verify"),
    "trimesh": ("trimesh", "skull"),
    "plotly": ("plotly", "skull"),
}
"""Every optional module: its package and the extra of pyproject.toml that installs it."""


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


class RunInterrupted(SpmOptError):
    """A stop was asked for (SIGINT, SIGTERM, ``Executor.stop``) during pre-flight: the
    run ended before connecting, so nothing moved and nothing was written."""


class StopAsked(SpmOptError):
    """SIGINT or SIGTERM stopped a run that a script or study makes among others: the run
    ended in its safe stop, and the script is to make no more runs
    (:meth:`~spm_opt.execution.results.ExecutionResult.raise_if_signalled`).

    Parameters
    ----------
    message : str
    signal_number : int
        The first signal the run received (``signal.SIGINT`` or ``signal.SIGTERM``).
    """

    def __init__(self, message: str, signal_number: int) -> None:
        super().__init__(message)
        self.signal_number = signal_number


class MissingDependency(SpmOptError, ImportError):
    """An optional package is not installed; the message names the extra to install.

    Parameters
    ----------
    module : str
        The module that could not be imported, one of :data:`OPTIONAL`.
    needed_by : str
        What needs it, to start the message ("the sweep", "--backend dynamixel").
    """

    def __init__(self, module: str, needed_by: str) -> None:
        package, extra = OPTIONAL[module]
        super().__init__(f'{needed_by} needs {package}: pip install -e ".[{extra}]"', name=module)


def require(module: str, needed_by: str) -> ModuleType:
    """Import the optional ``module`` (one of :data:`OPTIONAL`), or raise
    :class:`MissingDependency` naming its extra when it cannot be imported."""
    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise MissingDependency(module, needed_by) from error
