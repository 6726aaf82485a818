"""Execution: the one executor, its backends (simulated robot, Dynamixel actuators through
the official SDK), the Protocol 2.0 emulator and the execution log."""

from spm_opt.execution.backend import Backend, Measurement
from spm_opt.execution.executor import Executor, execute
from spm_opt.execution.log import read_log
from spm_opt.execution.plant import PlantSettings
from spm_opt.execution.results import ExecutionResult
from spm_opt.execution.settings import ExecutionSettings
from spm_opt.execution.simulated import SimulatedRobot

__all__ = [
    "Backend",
    "ExecutionResult",
    "ExecutionSettings",
    "Executor",
    "Measurement",
    "PlantSettings",
    "SimulatedRobot",
    "execute",
    "read_log",
]
