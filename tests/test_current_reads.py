"""Present Current read while each goal is held: one read in each equal part of the hold,
their mean logged, weighted with the cycle's own read; none in the stop; a bad count is
one line."""

from __future__ import annotations

import numpy as np
import pytest
from test_bad_inputs import assert_one_error, run_cli
from test_execution_faults import short_move

from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot, execute
from spm_opt.execution.log import read_execution_log

READS = 4
RATE_HZ = 100.0


class ReadRecorder(SimulatedRobot):
    """The simulated robot, noting the plant's time at each read and write and the current
    each current read returned."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)
        self.events: list[tuple[str, float, np.ndarray | None]] = []

    def read_current(self, timeout_s: float) -> np.ndarray:
        current = super().read_current(timeout_s)
        self.events.append(("current", self.clock.now() - self._epoch, current))
        return current

    def read(self):  # noqa: ANN201 - the backend's
        measurement = super().read()
        self.events.append(("read", self.clock.now() - self._epoch, measurement.current_a))
        return measurement

    def write_goal(self, position_rad: np.ndarray) -> None:
        super().write_goal(position_rad)
        self.events.append(("write", self.clock.now() - self._epoch, None))


def test_each_part_of_a_hold_is_read_once_and_the_log_holds_their_mean(hardware_problem, tmp_path):
    move = short_move(hardware_problem)
    robot = ReadRecorder(hardware_problem.robot, start_rad=move.position(0.0))
    settings = ExecutionSettings(rate_hz=RATE_HZ, current_reads_per_cycle=READS)
    log = tmp_path / "run.csv"
    result = execute(move, robot, hardware_problem, log, settings)
    assert result.completed, result.reason
    table, header = read_execution_log(log)
    assert header["current_reads"]["per_cycle"] == READS
    assert header["current_reads"]["missed"] == 0

    # between two writes: READS current reads, one in each quarter of the span from the
    # write to the next deadline (the simulated reads take no time), then the cycle's read
    writes = [k for k, (kind, _, _) in enumerate(robot.events) if kind == "write"]
    period = 1.0 / RATE_HZ
    logged = []
    for first, second in zip(writes[:-1], writes[1:], strict=True):
        between = robot.events[first + 1 : second]
        kinds = [kind for kind, _, _ in between]
        assert kinds == ["current"] * READS + ["read"], kinds
        written_at, deadline = robot.events[first][1], between[-1][1]
        assert deadline == pytest.approx(written_at + period, abs=1e-9)
        parts = [(time - written_at) / (period / READS) for _, time, _ in between[:READS]]
        assert [int(np.floor(p + 1e-9)) for p in parts] == list(range(READS)), parts
        logged.append(np.array([current for _, _, current in between[: READS + 1]]))
    # the log's current is the held reads' mean (the write takes no time: the own read's
    # share is 0), and its torque's sides the means of the held reads' torques on the
    # positive side and on the negative: a read of two units or more by its own sign, one
    # nearer zero by the sum of up to two reads before it and as many after it among the
    # held reads and the cycle's own (its own sign if they sum to zero, or it has none)
    currents = table[["current_theta1_a", "current_theta2_a"]].to_numpy()
    rows = np.flatnonzero(np.isfinite(currents[:, 0]))[1 : len(logged) + 1]
    held_means = [reads[:READS].mean(axis=0) for reads in logged]
    np.testing.assert_allclose(currents[rows], held_means, atol=1e-12)
    actuator = hardware_problem.robot.actuator
    expected = {"positive": [], "negative": []}
    for reads in logged:
        units = np.rint(reads / actuator.current_unit_a).astype(int)
        torques = actuator.current_map.torque(reads)
        sums = {"positive": [0.0, 0.0], "negative": [0.0, 0.0]}
        for i in range(READS):
            for j in (0, 1):
                reach = min(i, READS - i, 2)  # as many on each side, the own read last
                around = sum(units[k, j] for k in range(i - reach, i + reach + 1) if k != i)
                judged = units[i, j] if abs(units[i, j]) >= 2 or around == 0 else around
                sums["positive" if judged > 0 else "negative"][j] += torques[i, j] / READS
        for side in sums:
            expected[side].append(sums[side])
    for side, values in expected.items():
        columns = [f"torque_{side}_theta{joint}_nm" for joint in (1, 2)]
        np.testing.assert_allclose(table[columns].to_numpy()[rows], values, atol=1e-8)
    crossing = np.sum(
        (table["torque_positive_theta1_nm"] > 0) & (table["torque_negative_theta1_nm"] < 0)
    )
    assert crossing > 0  # some holds read the torque on both sides


def test_the_stop_makes_no_current_reads(hardware_problem, tmp_path):
    move = short_move(hardware_problem)

    class Stopping(ReadRecorder):
        executor: Executor
        phases: list[str]

        def read_current(self, timeout_s: float) -> np.ndarray:
            self.phases.append(self.executor._loop.phase)
            return super().read_current(timeout_s)

        def read(self):  # noqa: ANN201 - the backend's
            status = self.executor.status
            if status is not None and status.plan_time_s >= 1.0:
                self.executor.stop("operator stop")
            return super().read()

    robot = Stopping(hardware_problem.robot, start_rad=move.position(0.0))
    robot.phases = []
    settings = ExecutionSettings(rate_hz=RATE_HZ, current_reads_per_cycle=READS)
    robot.executor = Executor(hardware_problem, robot, settings)
    result = robot.executor.run(move, tmp_path / "run.csv")
    assert result.reason.startswith("interrupted"), result.reason
    table, _ = read_execution_log(tmp_path / "run.csv")
    assert np.sum(table["phase"] == "stop") >= 3
    assert "plan" in robot.phases and "stop" not in robot.phases, set(robot.phases)


@pytest.mark.parametrize("count", ["-1", "21", "2.5"])
def test_a_bad_current_read_count_is_one_line(count, tmp_path, capsys):
    status, shown = run_cli(
        [
            "execute",
            "plan.csv",
            "--problem",
            "problems/craniotomy_hardware.toml",
            "--backend",
            "sim",
            "--log",
            str(tmp_path / "run.csv"),
            "--current-reads",
            count,
        ]
    )
    assert_one_error(status, capsys.readouterr().err, ("--current-reads",), tmp_path, shown)
    assert not (tmp_path / "run.csv").exists()
