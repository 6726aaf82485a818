"""Serving in the calling thread until a signal, and an emulator in a child process (the
``spm-opt emulate`` command line)."""

from __future__ import annotations

import contextlib
import select
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spm_opt.execution.emulator.faults import Faults
from spm_opt.execution.emulator.server import Emulator
from spm_opt.execution.plant import PlantSettings, StateTrace
from spm_opt.execution.realtime import CONTROL_FIFO_PRIORITY, frozen_heap, raised_priority
from spm_opt.model.params import Robot

DEFAULT_ROBOT = Path(__file__).resolve().parents[3] / "problems" / "robots" / "prototype.toml"
"""Robot file a spawned emulator drives when given neither a robot nor a problem file."""


def serve(
    robot: Robot,
    ids: Sequence[int],
    start_rad: np.ndarray | Sequence[float],
    faults: Faults,
    seed: int,
    announce: Callable[[str], None],
    trace_path: str | Path | None = None,
) -> None:
    """Serve in the calling (main) thread until SIGINT or SIGTERM.

    Parameters
    ----------
    robot, ids, start_rad, faults
        As for :class:`Emulator`; ``start_rad`` in rad.
    seed : int
        Seed of the plant's sensor noise.
    announce : callable
        Called once with the device path, before serving.
    trace_path : path, optional
        Where to save the plant's true state (:class:`StateTrace`, ``.npz``) when serving
        ends.
    """
    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        trace = None if trace_path is None else StateTrace()
        emulator = Emulator(robot, ids, start_rad, faults, PlantSettings(seed=seed), trace=trace)
        try:
            # before the device is announced: collecting takes time; the plant stands for
            # hardware that never waits for a core, so it asks for the loop's priority too
            with frozen_heap(), raised_priority(fifo=CONTROL_FIFO_PRIORITY):
                announce(emulator.device)
                emulator.serve_forever(stop)
        finally:
            emulator.close()
            if trace is not None:
                trace.save(trace_path)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@dataclass(frozen=True)
class SpawnedEmulator:
    """An emulator running in a child process: its device path and the process."""

    device: str
    process: subprocess.Popen


@contextlib.contextmanager
def spawn_emulator(
    robot_file: str | Path | None = None,
    *,
    problem_file: str | Path | None = None,
    ids: Sequence[int] = (1, 2),
    start_deg: Sequence[float] = (0.0, 0.0),
    faults: Faults | None = None,
    seed: int = 0,
    trace_path: str | Path | None = None,
    startup_timeout_s: float = 30.0,
) -> Iterator[SpawnedEmulator]:
    """Run the emulator in a child process (out of this process's GIL) while in the block.

    Parameters
    ----------
    robot_file, problem_file : path, optional
        Robot TOML, or a problem TOML whose robot is used (default: the prototype).
    ids, start_deg, faults, seed
        As for :class:`Emulator`; ``start_deg`` in degrees.
    trace_path : path, optional
        Where the child saves the plant's true state when it ends (read it after the
        block with :meth:`StateTrace.load`).
    startup_timeout_s : float, s
        How long to wait for the child to announce its device.

    Yields
    ------
    SpawnedEmulator
        ``device`` to open, ``process`` to inspect; the child is terminated on exit.

    Raises
    ------
    RuntimeError
        The child did not announce a device in time (its stderr is in the message).
    """
    command = [sys.executable, "-m", "spm_opt.cli", "emulate"]
    if problem_file is not None:
        command += ["--problem", str(problem_file)]
    else:
        command += ["--plant-robot", str(robot_file or DEFAULT_ROBOT)]
    command += ["--ids", ",".join(str(i) for i in ids)]
    # one token: a first angle below zero would read as an option of its own
    command += ["--start-deg=" + ",".join(repr(float(a)) for a in start_deg), "--seed", str(seed)]
    for spec in (faults or Faults()).specs():
        command += ["--fault", spec]
    if trace_path is not None:
        command += ["--trace", str(trace_path)]
    with tempfile.TemporaryFile() as errors:
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=errors)
        try:
            ready, _, _ = select.select([process.stdout], [], [], startup_timeout_s)
            line = process.stdout.readline().decode().strip() if ready else ""
            if not line:
                process.kill()
                process.wait()
                errors.seek(0)
                message = errors.read().decode(errors="replace").strip().splitlines()
                raise RuntimeError(
                    "emulator child did not announce its device"
                    + (f": {message[-1]}" if message else "")
                )
            yield SpawnedEmulator(line, process)
        finally:
            if process.poll() is None:
                process.terminate()
                try:
                    process.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
            process.stdout.close()
