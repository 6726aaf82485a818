"""A log that fails never leaves the robot moving: the stop never waits on the disk.

Each run's disk fails (ENOSPC after a short write, EIO) or blocks in a chosen phase: the
approach, the plan, a stop, the settle. The failure is armed when the executor's status
shows that phase, and the run goes on only once the writer has met it (events, not the
clock). Every run must end with the plant's TRUE state at rest, the CSV holding whole lines
only, and the header the outcome (when the disk takes it). A real full disk and a disk
remounted read-only, on a small tmpfs in a private mount namespace, end the same way
through the command line.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import HARDWARE_PROBLEM
from test_execution_faults import (
    assert_the_commanded_stop_kept_its_limits,
    short_move,
    stop_bound,
)

import spm_opt as so
from spm_opt.base.errors import PreflightError
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot, read_log
from spm_opt.execution.log import COLUMNS, LogWriter

pytestmark = pytest.mark.real_time

DEG = np.pi / 180.0
SETTINGS = ExecutionSettings(approach=True, log_stall_s=0.2)
ARM_AT_PLAN_S = 1.5
"""How far along the 3 s move a disk that fails in the plan phase is armed, s."""
EVENT_TIMEOUT_S = 60.0
"""Longest wait for an event a run must reach (a failed test, never a pass, if it passes)."""


class FaultyDisk:
    """``os.write`` until armed; then ``kind``: "ENOSPC" (one short write that ends inside a
    line, then the error), "EIO" (the error at once) or "block" (until released)."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.armed = False
        self.met = threading.Event()
        self.release = threading.Event()
        self._short_write_done = False

    def write(self, fd: int, data: bytes) -> int:
        if not self.armed:
            return os.write(fd, data)
        self.met.set()
        if self.kind == "block":
            self.release.wait()
            return os.write(fd, data)
        if self.kind == "ENOSPC" and not self._short_write_done and len(data) > 1:
            self._short_write_done = True
            return os.write(fd, data[: len(data) // 2 + 7])
        code = errno.ENOSPC if self.kind == "ENOSPC" else errno.EIO
        raise OSError(code, os.strerror(code))


class PhaseTrigger(SimulatedRobot):
    """The simulated robot; when the executor's status shows ``phase`` (in the plan phase,
    ``ARM_AT_PLAN_S`` along the plan, in its fastest part), it arms the disk and, a cycle
    later, reads on only once the writer has met the failure (and a blocked write has been
    blocked longer than the stall limit). With ``stop_at_plan_s`` it also asks for a stop
    once the plan is that far along (s of its own time)."""

    executor: Executor
    phase: str
    disk: FaultyDisk
    stop_at_plan_s: float | None = None

    waited = False

    def read(self):  # noqa: ANN201 - the backend's
        status = self.executor.status
        if status is not None:
            if self.stop_at_plan_s is not None and status.plan_time_s >= self.stop_at_plan_s:
                self.executor.stop("operator stop")
            along = status.phase != "plan" or status.plan_time_s >= ARM_AT_PLAN_S
            if self.disk.armed and not self.waited:
                # a cycle after arming: its sample is queued, so the writer has a line to
                # write (the writer may have written every line before the arming)
                self.waited = True
                assert self.disk.met.wait(EVENT_TIMEOUT_S), "the writer never wrote"
                if self.disk.kind == "block":
                    time.sleep(1.5 * SETTINGS.log_stall_s)  # past the stall limit, surely
            elif status.phase == self.phase and along and not self.disk.armed:
                self.disk.armed = True
        return super().read()


@pytest.fixture(scope="module")
def move(hardware_problem: so.Problem) -> so.Trajectory:
    return short_move(hardware_problem)


def run_with_disk(problem, move, tmp_path, phase, kind):
    """Run ``move`` from 1 deg off its start (an approach first) with the disk failing in
    ``phase``: the result, the robot and the log's path."""
    start = move.position(0.0) + np.array([1.0, -0.5]) * DEG
    robot = PhaseTrigger(problem.robot, start_rad=start)
    robot.disk, robot.phase = FaultyDisk(kind), phase
    robot.stop_at_plan_s = 1.0 if phase == "stop" else None
    robot.executor = Executor(problem, robot, SETTINGS, log_write=robot.disk.write)
    log = tmp_path / "run.csv"
    try:
        result = robot.executor.run(move, log)
    finally:
        robot.disk.release.set()
    return result, robot, log


def assert_whole_lines(log: Path, lines: int) -> pd.DataFrame:
    """The CSV holds ``lines`` samples, every one whole."""
    text = log.read_bytes()
    assert text.endswith(b"\n")
    rows = text.decode().splitlines()
    assert rows[0] == ",".join(COLUMNS)
    assert all(row.count(",") == len(COLUMNS) - 1 for row in rows)
    table, _ = read_log(log)
    assert len(table) == lines
    assert table["time_s"].notna().all() and np.all(np.diff(table["time_s"]) > 0)
    return table


@pytest.mark.parametrize("kind", ["ENOSPC", "EIO", "block"])
@pytest.mark.parametrize("phase", ["approach", "plan", "stop", "settle"])
def test_a_failing_log_ends_in_a_stop_at_rest_whatever_the_disk_does(
    hardware_problem, move, tmp_path, phase, kind
):
    result, robot, log = run_with_disk(hardware_problem, move, tmp_path, phase, kind)
    # the plant is at rest, proven by the executor and by its true state
    assert result.at_rest and result.stop is not None and result.stop.at_rest
    assert np.all(np.abs(robot.true_state.velocity_rad_s) < SETTINGS.rest_speed_rad_s)
    assert not result.completed
    if phase == "stop":  # the stop was asked for; the log failed during it
        assert result.reason == "interrupted (operator stop)"
    else:
        assert result.reason.startswith("log failed: "), result.reason
        assert (
            "has not returned"
            if kind == "block"
            else os.strerror(errno.ENOSPC if kind == "ENOSPC" else errno.EIO)
        ) in result.reason
    report = result.log
    assert report.fault and report.samples == result.samples
    assert report.samples_written < report.samples
    if kind == "block":  # the writer is still blocked: its header comes once released
        assert not report.header_written
        robot.executor._writer._thread.join(EVENT_TIMEOUT_S)
        assert_whole_lines(log, result.samples)  # the disk came back: every sample
    else:
        assert report.header_written
        assert_whole_lines(log, report.samples_written)
    header = json.loads(log.with_suffix(".json").read_text())
    assert header["reason"] == result.reason and header["at_rest"]
    assert not log.with_name(".run.json.reserve").exists()


def test_samples_kept_in_memory_are_written_when_the_disk_comes_back(
    hardware_problem, move, tmp_path
):
    disk = FaultyDisk("EIO")

    class Recovering(PhaseTrigger):
        def write_goal(self, position_rad):  # the disk returns once the stop is under way
            if self.executor.status is not None and self.executor.status.phase == "stop":
                disk.armed = False
            super().write_goal(position_rad)

    robot = Recovering(hardware_problem.robot, start_rad=move.position(0.0))
    robot.disk, robot.phase = disk, "plan"
    robot.executor = Executor(hardware_problem, robot, SETTINGS, log_write=disk.write)
    result = robot.executor.run(move, tmp_path / "run.csv")
    assert result.reason.startswith("log failed: cannot write run.csv (Input/output error)")
    assert result.log.samples_written == result.samples
    table = assert_whole_lines(tmp_path / "run.csv", result.samples)
    assert_the_commanded_stop_kept_its_limits(
        table, hardware_problem, stop_bound(hardware_problem, move)
    )


def test_the_writer_never_blocks_the_caller_and_keeps_a_bounded_backlog(tmp_path, monkeypatch):
    monkeypatch.setattr("spm_opt.execution.log.MAX_PENDING_BYTES", 50_000)
    disk = FaultyDisk("block")
    disk.armed = True
    writer = LogWriter(tmp_path / "run.csv", {"plan": {}}, 0.01, 0.05, disk.write)
    q = np.array([0.1, -0.2])
    for k in range(2000):  # returns although every write blocks
        writer.append(k * 0.01, "plan", (k * 0.01, 1.0, 1.0), q, q, None, None, "ok")
    assert disk.met.wait(EVENT_TIMEOUT_S)
    time.sleep(0.1)  # past the 0.05 s stall limit
    assert writer.fault == "a write to run.csv has not returned for 0.05 s"
    report = writer.close({"completed": False})
    assert not report.header_written and report.samples == 2000
    disk.release.set()
    writer._thread.join(EVENT_TIMEOUT_S)
    table = assert_whole_lines(tmp_path / "run.csv", writer._written_lines)
    # what the bound kept is the first 50 kB of lines, in order; the rest is lost
    assert 50_000 / 100 < len(table) < 2000
    np.testing.assert_allclose(table["time_s"], np.arange(len(table)) * 0.01)


def test_a_run_whose_log_cannot_fit_is_refused_before_anything_moves(
    hardware_problem, move, tmp_path, monkeypatch
):
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(
        "spm_opt.execution.preflight.shutil.disk_usage",
        lambda _: usage._replace(free=100_000),
    )
    robot = SimulatedRobot(hardware_problem.robot, start_rad=move.position(0.0))
    with pytest.raises(PreflightError, match=r"run\.csv: a run of about \d\.\d s at 100 Hz needs"):
        so.execute(move, robot, hardware_problem, tmp_path / "run.csv")
    assert list(tmp_path.iterdir()) == []
    assert robot.plant.time_s == 0.0  # never advanced: nothing moved


# ------------------------------------------------------------------ a real small disk
def _private_tmpfs_works() -> bool:
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    probe = subprocess.run(
        ["unshare", "-m", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
        capture_output=True,
    )
    return probe.returncode == 0


needs_tmpfs = pytest.mark.skipif(
    not _private_tmpfs_works(), reason="needs root and unshare to mount a private tmpfs"
)

DISK_SCRIPT = """
set -u
mount -t tmpfs -o size={size} tmpfs {disk}
{command} > {out}/stdout 2> {out}/stderr &
pid=$!
{trigger}
wait $pid
echo $? > {out}/status
cp {disk}/run.csv {disk}/run.json {out}/ 2>/dev/null
ls -a {disk} > {out}/files
"""

WHEN_LOGGED = """
while [ ! -s {disk}/run.csv ] || [ $(stat -c %s {disk}/run.csv) -lt 8000 ]; do
  kill -0 $pid 2>/dev/null || break
  sleep 0.01
done
"""


def run_on_a_small_disk(tmp_path: Path, plan: Path, size: str, fault: str) -> dict:
    """``spm-opt execute`` on the simulated robot (on the machine's clock) with its log on
    a tmpfs of ``size`` in a private mount namespace, and ``fault`` (shell) run once the
    log holds 8 kB; what it printed and left."""
    disk, out = tmp_path / "disk", tmp_path / "out"
    disk.mkdir()
    out.mkdir()
    command = [sys.executable, "-m", "spm_opt.cli", "execute", str(plan)]
    command += ["--problem", str(HARDWARE_PROBLEM), "--backend", "sim", "--realtime"]
    command += ["--log", f"{disk}/run.csv", "--trace", f"{out}/trace.npz"]
    trigger = "" if not fault else WHEN_LOGGED.format(disk=disk) + fault.format(disk=disk)
    script = DISK_SCRIPT.format(
        size=size, disk=disk, out=out, command=" ".join(command), trigger=trigger
    )
    subprocess.run(["unshare", "-m", "sh", "-c", textwrap.dedent(script)], check=True)
    return {
        "status": int((out / "status").read_text()),
        "stderr": (out / "stderr").read_text(),
        "files": (out / "files").read_text().split(),
        "out": out,
    }


@pytest.fixture(scope="module")
def plan_file(move, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("plan") / "move.csv"
    move.to_csv(path)
    return path


@needs_tmpfs
def test_a_disk_that_fills_mid_run_ends_in_one_line_and_a_plant_at_rest(tmp_path, plan_file):
    fill = "dd if=/dev/zero of={disk}/filler bs=4k 2>/dev/null || true"
    run = run_on_a_small_disk(tmp_path, plan_file, "1m", fill)
    lines = run["stderr"].strip().splitlines()
    assert run["status"] == 1 and len(lines) == 1, run["stderr"]
    assert lines[0].startswith(
        "spm-opt: safe stop: log failed: cannot write run.csv (No space left on device)"
    )
    assert "at rest" in lines[0] and "; its header records the outcome" in lines[0]
    out = run["out"]
    trace = np.load(out / "trace.npz")
    assert np.all(np.abs(trace["velocity_rad_s"][-1]) < ExecutionSettings.rest_speed_rad_s)
    header = json.loads((out / "run.json").read_text())
    assert header["reason"].startswith("log failed") and header["at_rest"]
    written = header["log"]["samples_written"]
    assert f"the log holds {written} of {header['samples']} samples (whole lines)" in lines[0]
    assert_whole_lines(out / "run.csv", written)
    assert ".run.json.reserve" not in run["files"]


@needs_tmpfs
def test_a_disk_too_small_for_the_log_is_refused_before_anything_moves(tmp_path, plan_file):
    run = run_on_a_small_disk(tmp_path, plan_file, "24k", "")
    assert run["status"] == 2
    assert run["stderr"].startswith("spm-opt: error: log ")
    assert "needs" in run["stderr"] and run["stderr"].count("\n") == 1
    assert [f for f in run["files"] if f not in (".", "..")] == []
