"""Ways the robot could move when it should not, each closed, on the simulated robot and
(for the stop asked for early, the backend's surprise and stale replies) through the real
``dynamixel-sdk`` against the emulator.

1. A plan that does not start or end at rest, or whose CSV is not what its sidecar
   records, is refused before anything is written.
2. A plan made for another problem (or recording none) is refused unless asked for.
3. A stop asked for from the first line of ``run()`` is never lost.
4. Any exception a backend raises is a fault: the safe stop still runs.
5. A run whose end is not proven at rest fails.
6. A late reply is never taken for the answer to a later request.
7. Every stop says how far the joints travelled; a feed above the plan's ceiling warns;
   every log starts at 0.

Each check looks at what the robot did (the plant's true state, the goals it received)
or at what the user sees (the exit status and the lines on stderr), not at the executor's
own account alone.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import HARDWARE_PROBLEM
from test_bad_inputs import assert_nothing_written, assert_one_error, run_cli
from test_execution_faults import (
    FAULT_AT_S,
    GOALS,
    PERIOD_S,
    SETTINGS,
    ScriptedRobot,
    assert_the_commanded_stop_kept_its_limits,
    run_on_the_wire,
    short_move,
    stop_bound,
)
from test_interactive import Terminal

import spm_opt as so
from spm_opt.base.errors import InputError, PreflightError, RunInterrupted
from spm_opt.cli import commands
from spm_opt.execution import Executor, SimulatedRobot, execute, preflight, read_log
from spm_opt.execution.dynamixel import DynamixelRobot
from spm_opt.execution.emulator import DelayReplies, Faults, Overload
from spm_opt.problem.provenance import check_plan_made_for

pytestmark = pytest.mark.real_time

DEG = np.pi / 180.0
POSITIONS = ["position_theta1_rad", "position_theta2_rad"]
LOG_FILES_WRITTEN_WITHIN_S = 0.5
"""How long a run's log files (the CSV's first line, the header, the room set aside) may take
to write on a loaded machine, s."""


def window(plan: so.Trajectory, start_s: float, end_s: float, problem: so.Problem):
    """``plan`` between two of its times, sampled at 1 kHz, made for ``problem``."""
    t = np.linspace(start_s, end_s, int(round((end_s - start_s) * 1000)) + 1)
    return so.Trajectory.from_samples(
        t - start_s,
        plan.position(t),
        plan.velocity(t),
        plan.acceleration(t),
        {"planner": "window", "problem": problem.record()},
    )


@pytest.fixture(scope="module")
def move(hardware_problem: so.Problem) -> so.Trajectory:
    return short_move(hardware_problem)


def true_rest_at_the_end(robot: SimulatedRobot) -> None:
    """The plant truly at rest when the run has ended."""
    assert np.all(np.abs(robot.true_state.velocity_rad_s) < SETTINGS.rest_speed_rad_s)


# ----------------------------------------------------------------- 1. rest at both ends
@pytest.mark.parametrize(("end", "span_s"), [("end", (0.0, 6.0)), ("start", (6.0, 16.0))])
def test_a_plan_not_at_rest_at_an_end_is_refused_before_anything_is_written(
    hardware_problem, hardware_plan, tmp_path, end, span_s
):
    moving = window(hardware_plan, *span_s, hardware_problem)
    at = moving.start_time if end == "start" else moving.end_time
    # the plan really moves there: a finite difference of its positions, 1 ms inward
    inward = 1e-3 if end == "start" else -1e-3
    speed = np.abs(moving.position([at + inward])[0] - moving.position([at])[0]) / 1e-3
    assert np.max(speed) > 0.05
    robot = SimulatedRobot(hardware_problem.robot, start_rad=moving.position(0.0))
    with pytest.raises(PreflightError, match=f"plan refused: it does not {end} at rest"):
        execute(moving, robot, hardware_problem, tmp_path / "run.csv")
    assert list(tmp_path.iterdir()) == []
    assert robot.plant.time_s == 0.0  # never connected, never advanced


def test_rest_means_joining_rest_within_one_period_keeps_the_limits(hardware_problem):
    """At the bound, stepping to rest within one period commands the limits (second and
    third differences of the goal stream written here); past it, it is refused."""
    limits = SETTINGS.joint_limits(hardware_problem)
    speed, acceleration = preflight.rest_bounds(limits, PERIOD_S)
    goals = np.array([-2.0, -1.0, 0.0, 0.0, 0.0]) * speed * PERIOD_S  # at speed, then rest
    second = np.diff(goals, 2) / PERIOD_S**2
    third = np.diff(goals, 3) / PERIOD_S**3
    assert np.max(np.abs(second)) <= limits.acceleration * 1.005 + 1e-12
    assert np.max(np.abs(third)) <= limits.jerk * 1.005 + 1e-9
    assert acceleration == pytest.approx(limits.jerk * 1.005 * PERIOD_S)
    t = np.array([0.0, 1.0])
    for v, expect_refused in ((0.99 * speed, False), (1.01 * speed, True)):
        q = np.array([[0.0, 0.0], [v, 0.0]])
        ending = so.Trajectory.from_samples(t, q, np.array([[0.0, 0.0], [v, 0.0]]), 0 * q)
        if expect_refused:
            with pytest.raises(PreflightError, match="does not end at rest"):
                preflight.check_at_rest(ending, limits, PERIOD_S)
        else:
            preflight.check_at_rest(ending, limits, PERIOD_S)


@pytest.fixture()
def plan_csv(tmp_path) -> Path:
    path = tmp_path / "plan" / "plan.csv"
    assert run_cli(["plan", str(HARDWARE_PROBLEM), "--out", str(path)])[0] == 0
    return path


def _without_the_prediction(monkeypatch: pytest.MonkeyPatch) -> None:
    """Pre-flight's predicted run drives a SimulatedRobot too: a test that makes every
    simulated robot misbehave leaves the prediction out, to see the run's own handling."""
    monkeypatch.setattr(commands, "_check_predicted_cut", lambda *_: None)


def _execute_argv(plan: Path, log: Path, *options: str) -> list[str]:
    return [
        "execute",
        str(plan),
        "--problem",
        str(HARDWARE_PROBLEM),
        "--backend",
        "sim",
        "--log",
        str(log),
        *options,
    ]


def test_a_plan_csv_cut_mid_line_is_refused_with_or_without_its_sidecar(plan_csv, tmp_path, capsys):
    """The 16 s plan cut after about 100 kB (``head -c``), inside the last number of a
    line, so that every line still has its seven values: a third of the plan, moving."""
    data = plan_csv.read_bytes()
    line_start = data.rindex(b"\n", 0, 100_000) + 1
    last_comma = data.index(b"\n", line_start) - 8  # inside the line's last value
    cut = data[: max(last_comma, data.rindex(b",", 0, data.index(b"\n", line_start)) + 4)]
    assert not cut.endswith(b"\n") and cut.rsplit(b"\n", 1)[1].count(b",") == 6
    plan_csv.write_bytes(cut)
    capsys.readouterr()
    log = tmp_path / "logs" / "run.csv"
    status, shown = run_cli(_execute_argv(plan_csv, log))
    assert_one_error(status, capsys.readouterr().err, ("plan.csv", "cut short"), tmp_path, shown)
    assert not log.parent.exists()
    # without its sidecar it records no problem; allowed, it still does not end at rest
    plan_csv.with_suffix(".json").unlink()
    status, shown = run_cli(_execute_argv(plan_csv, log))
    assert_one_error(
        status, capsys.readouterr().err, ("records no problem", "--other-problem"), tmp_path
    )
    status, shown = run_cli(_execute_argv(plan_csv, log, "--other-problem"))
    assert_one_error(status, capsys.readouterr().err, ("does not end at rest",), tmp_path)
    assert not log.parent.exists()


def test_a_plan_csv_edited_under_its_sidecar_is_refused(plan_csv, tmp_path, capsys):
    lines = plan_csv.read_text().splitlines(keepends=True)
    row = lines[500].split(",")
    row[1] = repr(float(row[1]) + 1e-6)  # one joint angle moved by a microradian
    lines[500] = ",".join(row)
    plan_csv.write_text("".join(lines))
    capsys.readouterr()
    log = tmp_path / "logs" / "run.csv"
    status, shown = run_cli(_execute_argv(plan_csv, log))
    assert_one_error(
        status, capsys.readouterr().err, ("not the CSV its sidecar", "edited"), tmp_path, shown
    )
    assert_nothing_written(log, tmp_path)


# ------------------------------------------------------------- 2. made for this problem
def test_a_plan_made_for_another_problem_is_refused_unless_asked_for(
    paper_problem, baseline, hardware_problem, tmp_path, capsys
):
    plan = tmp_path / "paper.csv"
    baseline.to_csv(plan)
    log = tmp_path / "logs" / "run.csv"
    status, shown = run_cli(_execute_argv(plan, log))
    assert_one_error(
        status,
        capsys.readouterr().err,
        ("made for craniotomy_bone_flap", "not for craniotomy_hardware"),
        tmp_path,
        shown,
    )
    assert_nothing_written(log, tmp_path)
    # a sidecar whose fingerprint was zeroed
    sidecar = json.loads(plan.with_suffix(".json").read_text())
    sidecar["problem"]["fingerprint"] = "0" * 64
    plan.with_suffix(".json").write_text(json.dumps(sidecar))
    with pytest.raises(PreflightError, match="made for craniotomy_bone_flap"):
        execute(so.Trajectory.from_csv(plan), SimulatedRobot(paper_problem.robot), paper_problem)


def test_the_fingerprint_is_what_the_plan_depends_on_not_the_files_bytes(tmp_path):
    text = HARDWARE_PROBLEM.read_text()
    (tmp_path / "robots").symlink_to(HARDWARE_PROBLEM.parent / "robots")
    same = tmp_path / "same.toml"
    same.write_text(
        "# a lab's copy, renamed and commented\n"
        + text.replace('name = "craniotomy_hardware"', 'name = "our_copy"').replace(
            "[4.0, 4.0, 4.0, 4.0]", "[5.0, 5.0, 5.0, 5.0]"
        )
    )
    slower = tmp_path / "slower.toml"
    slower.write_text(text.replace("max_joint_jerk_rad_s3 = 100.0", "max_joint_jerk_rad_s3 = 99.0"))
    moved = tmp_path / "moved.toml"
    moved.write_text(text.replace("[0.0, 0.0, 68.08]", "[0.0, 0.0, 68.09]"))
    reference = so.load_problem(HARDWARE_PROBLEM)
    assert so.load_problem(same).fingerprint == reference.fingerprint
    for changed in (slower, moved):
        assert so.load_problem(changed).fingerprint != reference.fingerprint
    plan = so.plan(reference, "cubic")
    check_plan_made_for(so.load_problem(same), plan, other_problem=False)
    with pytest.raises(InputError, match="made for craniotomy_hardware"):
        check_plan_made_for(so.load_problem(slower), plan, other_problem=False)


def test_a_plan_without_a_sidecar_runs_only_when_asked_for(plan_csv, tmp_path, capsys):
    plan_csv.with_suffix(".json").unlink()
    log = tmp_path / "logs" / "run.csv"
    status, shown = run_cli(_execute_argv(plan_csv, log))
    assert_one_error(status, capsys.readouterr().err, ("records no problem",), tmp_path, shown)
    status, _ = run_cli(_execute_argv(plan_csv, log, "--other-problem"))
    err = capsys.readouterr().err
    assert status == 0, err
    assert (
        err.startswith("spm-opt: warning: the plan records no problem") and "--other-problem" in err
    )
    assert read_log(log)[1]["settings"]["other_problem"] is True


# ------------------------------------------------------------------ 3. a stop never lost
class _StopsWhile(Executor):
    """An executor whose operator asks for a stop (or sends SIGINT) during pre-flight."""

    def __init__(self, *args, action, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._action = action

    def check_plan(self, trajectory: so.Trajectory) -> None:
        self._action(self)
        super().check_plan(trajectory)


@pytest.mark.parametrize(
    "action",
    [
        pytest.param(lambda executor: executor.stop("operator pressed q"), id="stop"),
        pytest.param(lambda _: os.kill(os.getpid(), signal.SIGINT), id="SIGINT"),
    ],
)
def test_a_stop_during_pre_flight_ends_the_run_before_anything_moves(
    hardware_problem, hardware_plan, tmp_path, action
):
    robot = SimulatedRobot(hardware_problem.robot, start_rad=hardware_plan.position(0.0))
    executor = _StopsWhile(hardware_problem, robot, action=action)
    with pytest.raises(RunInterrupted, match="during pre-flight"):
        executor.run(hardware_plan, tmp_path / "run.csv")
    assert list(tmp_path.iterdir()) == []
    assert robot.plant.time_s == 0.0
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_stop_asked_for_before_run_counts_and_is_forgotten_after_it(
    hardware_problem, hardware_plan, tmp_path
):
    """The console starts before ``run()``: a ``q`` typed then ends the run; the next run
    of the same executor starts clean."""
    robot = SimulatedRobot(hardware_problem.robot, start_rad=hardware_plan.position(0.0))
    executor = Executor(hardware_problem, robot)
    executor.stop("operator pressed q")
    with pytest.raises(RunInterrupted, match="operator pressed q"):
        executor.run(hardware_plan, tmp_path / "run.csv")
    assert executor.run(hardware_plan, tmp_path / "run.csv").succeeded


class _InterruptedAtConnect:
    """Mixed into a backend: SIGINT arrives while it connects."""

    def connect(self) -> None:
        super().connect()  # type: ignore[misc]
        os.kill(os.getpid(), signal.SIGINT)


class _SimulatedInterruptedAtConnect(_InterruptedAtConnect, SimulatedRobot):
    pass


class _DynamixelInterruptedAtConnect(_InterruptedAtConnect, DynamixelRobot):
    pass


def _assert_stopped_in_the_first_cycle(result, table, trace, start) -> None:
    """No goal of the plan went out: every goal is the start, the plant never moved."""
    assert result.reason == "interrupted (SIGINT)", result.reason
    assert set(table["phase"]) == {"stop", "hold"}  # the first cycle saw it and stopped
    assert result.at_rest and result.stop.stop_delivered
    goals = table[GOALS].to_numpy()
    np.testing.assert_allclose(goals, np.broadcast_to(start, goals.shape), atol=1e-9)
    assert np.max(np.abs(trace["position_rad"] - start)) < 0.01 * DEG


def test_a_stop_while_connecting_is_honoured_by_the_first_cycle(
    hardware_problem, hardware_plan, tmp_path
):
    start = hardware_plan.position(0.0)
    robot = _SimulatedInterruptedAtConnect(hardware_problem.robot, start_rad=start)
    result = execute(hardware_plan, robot, hardware_problem, tmp_path / "run.csv")
    table, _ = read_log(tmp_path / "run.csv")
    _assert_stopped_in_the_first_cycle(result, table, robot.trace.arrays(), start)


@pytest.mark.slow
def test_a_stop_while_connecting_is_honoured_through_the_sdk(
    hardware_problem, hardware_plan, tmp_path
):
    result, table, _, trace = run_on_the_wire(
        hardware_problem, hardware_plan, Faults(), tmp_path, _DynamixelInterruptedAtConnect
    )
    _assert_stopped_in_the_first_cycle(result, table, trace, hardware_plan.position(0.0))


@pytest.mark.slow
def test_q_pressed_at_once_in_an_interactive_run_is_not_lost(tmp_path):
    plan, log = tmp_path / "plan.csv", tmp_path / "run.csv"
    so.plan(so.load_problem(HARDWARE_PROBLEM), "cubic").to_csv(plan)
    command = [sys.executable, "-m", "spm_opt.cli", *_execute_argv(plan, log), "--interactive"]
    terminal = Terminal(command, tmp_path)
    try:
        terminal.wait_for(r"keys: space hold/resume")
        terminal.type("q")
        began = time.monotonic()
        terminal.wait_for(
            r"interrupted: stopped during pre-flight|safe stop: interrupted \(operator pressed q\)"
        )
    finally:
        status = terminal.close()
    assert time.monotonic() - began < 10.0  # the 16 s plan did not run on
    assert status in (130, 1)
    if status == 1:  # the q came after connecting: the loop's first cycle took it
        table, _ = read_log(log)
        assert table["plan_time_s"].max() < 1.0
    else:
        assert not log.exists()


# ------------------------------------------------------- 4. the backend's surprise is a fault
class _SurprisingRobot(ScriptedRobot):
    """Reads raise ``ValueError`` from ``FAULT_AT_S`` on (after the plant is sampled, so
    the true state is still traced), or writes do."""

    def __init__(self, *args, fails: str, until: float = float("inf"), **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.fails, self.until = fails, until

    def _surprise(self, what: str) -> None:
        if self.fails == what and FAULT_AT_S <= self.clock.now() < self.until:
            raise ValueError(f"{what} buffer garbled")

    def read(self):  # noqa: ANN201
        measurement = super().read()
        self._surprise("read")
        return measurement

    def write_goal(self, position_rad: np.ndarray) -> None:
        self._surprise("write")
        super().write_goal(position_rad)


@pytest.mark.parametrize("fails", ["read", "write"])
def test_an_unexpected_backend_error_ends_in_a_safe_stop_the_plant_confirms(
    hardware_problem, move, tmp_path, fails
):
    robot = _SurprisingRobot(hardware_problem.robot, move.position(0.0), fails=fails)
    result = execute(move, robot, hardware_problem, tmp_path / "run.csv", SETTINGS)
    assert not result.completed
    assert result.reason == f"the backend's {fails} raised ValueError: {fails} buffer garbled"
    table, header = read_log(tmp_path / "run.csv")
    seen = header["stop"]["fault_seen_s"]
    assert seen == pytest.approx(FAULT_AT_S)  # at once, not after the retry budget
    assert header["stop"]["stop_delivered"] is (fails == "read")
    if fails == "read":  # the stop's goals reached the plant, within the stop's limits
        assert_the_commanded_stop_kept_its_limits(
            table, hardware_problem, stop_bound(hardware_problem, move)
        )
        true_rest_at_the_end(robot)
        assert not result.at_rest  # no reading, no proof
        assert "read failed" in header["stop"]["rest"]


def test_an_unexpected_error_is_one_line_and_exit_status_1(
    hardware_problem, plan_csv, tmp_path, capsys, monkeypatch
):
    """Reads raise once, 1 s in: the stop, then rest proven; the line says how far each
    joint travelled after the fault and when rest was proven, as the header does."""
    original = SimulatedRobot.read

    def read(self):  # noqa: ANN001, ANN202
        measurement = original(self)
        if FAULT_AT_S <= self.clock.now() < FAULT_AT_S + PERIOD_S / 2:
            raise RuntimeError("driver bug")
        return measurement

    monkeypatch.setattr(SimulatedRobot, "read", read)
    _without_the_prediction(monkeypatch)
    log = tmp_path / "run.csv"
    status, _ = run_cli(_execute_argv(plan_csv, log))
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and len(lines) == 1, lines
    header = read_log(log)[1]
    stop = header["stop"]
    travel = ", ".join(f"theta{j + 1} {d:.2f} deg" for j, d in enumerate(stop["travel_deg"]))
    assert lines[0] == (
        "spm-opt: safe stop: the backend's read raised RuntimeError: driver bug; travel after "
        f"the fault {travel}; at rest {stop['duration_s']:.2f} s after it"
    )
    assert stop["at_rest"] and max(stop["travel_deg"]) > 0.0


def test_a_bug_in_the_loop_is_a_fault_too(hardware_problem, move, tmp_path, monkeypatch):
    from spm_opt.execution import feed

    original = feed.FeedProfile.goal
    calls = []

    def goal(self, pace):  # noqa: ANN001, ANN202
        calls.append(pace)
        if len(calls) == 100:
            raise ZeroDivisionError("division by zero")
        return original(self, pace)

    monkeypatch.setattr(feed.FeedProfile, "goal", goal)
    robot = SimulatedRobot(hardware_problem.robot, start_rad=move.position(0.0))
    result = execute(move, robot, hardware_problem, tmp_path / "run.csv", SETTINGS)
    assert result.reason == "internal error: ZeroDivisionError: division by zero"
    assert result.at_rest and result.stop.stop_delivered
    header = read_log(tmp_path / "run.csv")[1]
    assert "ZeroDivisionError" in "".join(header["exception"])
    true_rest_at_the_end(robot)


class _SurprisingDynamixel(DynamixelRobot):
    """The SDK backend whose reads raise ``ValueError`` from the 100th on."""

    reads = 0

    def read(self):  # noqa: ANN201
        self.reads += 1
        if self.reads >= 100:
            raise ValueError("read buffer garbled")
        return super().read()


@pytest.mark.slow
def test_an_unexpected_backend_error_through_the_sdk_still_stops_the_plant(
    hardware_problem, move, tmp_path
):
    result, table, header, trace = run_on_the_wire(
        hardware_problem, move, Faults(), tmp_path, _SurprisingDynamixel
    )
    assert result.reason == "the backend's read raised ValueError: read buffer garbled"
    assert header["stop"]["stop_delivered"]
    assert_the_commanded_stop_kept_its_limits(
        table, hardware_problem, stop_bound(hardware_problem, move)
    )
    last = trace["time_s"] >= trace["time_s"][-1] - SETTINGS.rest_window_s
    assert np.all(np.abs(trace["velocity_rad_s"][last]) < SETTINGS.rest_speed_rad_s)


# ------------------------------------------------------------ 5. rest proven, or failure
def test_a_settle_that_never_proves_rest_fails(hardware_problem, move, tmp_path, capsys):
    """θ2's reading creeps at 0.002 rad/s from the plan's end (0.11° over the settle,
    within the following-error limit at rest): the run completed but rest is not proven,
    which is a failure."""
    robot = ScriptedRobot(
        hardware_problem.robot, move.position(0.0), creep_rad_s=(move.duration, 0.002)
    )
    result = execute(move, robot, hardware_problem, tmp_path / "run.csv", SETTINGS)
    assert result.completed and not result.at_rest and not result.succeeded
    assert result.reason.startswith("completed, but rest not proven within the 1 s settle: ")
    assert "theta2 moved" in result.reason
    header = read_log(tmp_path / "run.csv")[1]
    assert header["reason"] == result.reason and header["at_rest"] is False


def test_an_unproven_rest_is_exit_status_1_with_one_line(plan_csv, tmp_path, capsys, monkeypatch):
    original = SimulatedRobot.read

    def read(self):  # noqa: ANN001, ANN202
        measurement = original(self)
        creep = 0.002 * max(self.clock.now() - 16.0, 0.0)
        return dataclasses.replace(
            measurement, position_rad=measurement.position_rad + np.array([0.0, creep])
        )

    monkeypatch.setattr(SimulatedRobot, "read", read)
    _without_the_prediction(monkeypatch)
    status, _ = run_cli(_execute_argv(plan_csv, tmp_path / "run.csv"))
    lines = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and len(lines) == 1, lines
    assert lines[0].startswith("spm-opt: completed, but rest not proven within the 1 s settle")


# ------------------------------------------------------------------ 6. no stale replies
READ_WINDOW_S = 0.02
"""A reading is fresh when the plant was there at some moment from its cycle's start to
this much later (a read takes about a millisecond; the rest is room for a loaded machine)."""


def _staleness(table, trace) -> np.ndarray:
    """For each reading logged "ok": how far it is from every true position the plant held
    from its cycle's start to ``READ_WINDOW_S`` later, at the nearest, rad."""
    ok = (table["status"] == "ok").to_numpy()
    times, measured = table["time_s"].to_numpy()[ok], table[POSITIONS].to_numpy()[ok]
    first = np.searchsorted(trace["time_s"], times)
    last = np.searchsorted(trace["time_s"], times + READ_WINDOW_S, side="right")
    return np.array(
        [
            np.min(np.max(np.abs(trace["position_rad"][a:b] - q), axis=1))
            for a, b, q in zip(first, np.maximum(last, first + 1), measured, strict=True)
        ]
    )


@pytest.mark.slow
def test_replies_50_ms_late_are_never_taken_for_fresh_ones(
    hardware_problem, hardware_plan, tmp_path
):
    """The emulator delays 30 replies by 50 ms from 1 s on, during the 16 s plan (joint
    speeds up to 0.17 rad/s: 50 ms stale is up to 0.5 deg)."""
    faults = Faults(delay=DelayReplies(seconds=0.05, at=FAULT_AT_S, count=30))
    result, table, header, trace = run_on_the_wire(
        hardware_problem, hardware_plan, faults, tmp_path
    )
    # fresh: within the encoder's resolution and the sag of the plant's true position
    assert np.max(_staleness(table, trace)) < 0.05 * DEG
    assert header["backend"]["stale_replies"] > 0
    assert result.at_rest, result.reason


@pytest.mark.slow
def test_a_late_reply_during_the_stop_is_no_hardware_error(hardware_problem, move, tmp_path):
    """30 replies 50 ms late from 0.95 s, and an overload at 1 s (its alert bit makes every
    read ask for the Hardware Error Status, a 1-byte reply): before, late 12-byte readings
    were read as that byte (0x2B: "input voltage, hall sensor, encoder, overload"); now the
    only error reported is the overload, and every reading logged "ok" is fresh."""
    faults = Faults(
        overload=(Overload(id=1, at=FAULT_AT_S),),
        delay=DelayReplies(seconds=0.05, at=FAULT_AT_S - 0.05, count=30),
    )
    result, table, header, trace = run_on_the_wire(hardware_problem, move, faults, tmp_path)
    assert not result.completed
    errors = table[["hardware_error_1", "hardware_error_2"]].dropna().to_numpy()
    assert set(np.unique(errors)) <= {0, 32}, np.unique(errors)
    assert header["stop"]["hardware_errors"] == ["actuator 1: overload"]
    assert np.max(_staleness(table, trace)) < 0.05 * DEG


# ------------------------------------------------------------- 7. what the user is told
def test_a_feed_above_the_plans_ceiling_warns(plan_csv, tmp_path, capsys):
    status, _ = run_cli(_execute_argv(plan_csv, tmp_path / "run.csv", "--feed", "1.4"))
    err = capsys.readouterr().err
    assert status == 0, err
    header = read_log(tmp_path / "run.csv")[1]
    ceiling = header["feed_ceiling"]
    assert 1.0 <= ceiling < 1.4
    assert err == (
        f"spm-opt: warning: feed 140% is above this plan's ceiling, {100 * ceiling:.0f}% "
        f"(the highest at which it keeps its limits): it starts at {100 * ceiling:.0f}%\n"
    )


def test_a_real_time_log_starts_at_0_with_the_clocks_origin_in_the_header(
    hardware_problem, move, tmp_path
):
    robot = SimulatedRobot(hardware_problem.robot, start_rad=move.position(0.0), realtime=True)
    short = window(move, 0.0, 3.0, hardware_problem)
    before = time.perf_counter()
    result = execute(short, robot, hardware_problem, tmp_path / "run.csv", SETTINGS)
    assert result.succeeded, result.reason
    table, header = read_log(tmp_path / "run.csv")
    # time 0 is the reading the loop starts from; its first cycle comes once the log's files
    # are written (a few ms)
    assert 0.0 < table["time_s"].iloc[0] < LOG_FILES_WRITTEN_WITHIN_S
    assert before < header["clock_origin_s"] < before + 5.0
    # on the log's clock, each cycle's reading falls between its start and the next's; the
    # readings before the loop (on connecting, and the one it starts from) before time 0
    read_at = robot.trace.arrays(header["clock_origin_s"])["time_s"]
    assert np.sum(read_at < 0.0) == 2
    read_at = read_at[read_at >= 0.0]
    begins = table["time_s"].to_numpy()
    assert np.all(read_at >= begins) and np.all(read_at[:-1] < begins[1:])


def test_the_log_headers_problem_and_clock_survive_json(hardware_problem, move, tmp_path):
    robot = SimulatedRobot(hardware_problem.robot, start_rad=move.position(0.0))
    execute(move, robot, hardware_problem, tmp_path / "run.csv", SETTINGS)
    header = json.loads((tmp_path / "run.json").read_text())
    assert header["problem"]["fingerprint"] == hardware_problem.fingerprint
    assert header["clock_origin_s"] == 0.0
    assert read_log(tmp_path / "run.csv")[0]["time_s"].iloc[0] == 0.0
