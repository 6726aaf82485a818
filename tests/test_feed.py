"""Feed hold, resume and override on the simulated robot: the tool stays on the planned path.

A run is judged by references that do not share the executor's code:

- the cut: the plant's TRUE joint angles (its trace: no quantisation, no noise) through
  the forward kinematics onto the skull, against the plan's own cut sampled at 10 kHz;
- the commanded motion: finite differences of the goals the log holds (means of the goal
  stream's derivatives, see :mod:`test_execution_faults`), against the problem's limits as
  the evaluator allows them;
- rest during a hold: the plant's true speeds and positions from the cycle the executor
  confirmed rest to the resume.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest
from conftest import HARDWARE_PROBLEM
from scipy.spatial import cKDTree
from test_execution_faults import LOG_DIGITS_ERROR, derivative_estimates

import spm_opt as so
from spm_opt.base.errors import InputError
from spm_opt.cli import main
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot, read_log
from spm_opt.execution.ceiling import feed_ceiling
from spm_opt.execution.dynamixel import DynamixelRobot
from spm_opt.execution.emulator import spawn_emulator
from spm_opt.execution.feed import FEED_STEP, MAX_FEED_JERK_PER_S2, FeedProfile, FeedRequests
from spm_opt.execution.plant import StateTrace
from spm_opt.judge.limits import RULES, path_tolerance
from spm_opt.judge.paced import PacedLimits
from spm_opt.model import dynamics, kinematics

SETTINGS = ExecutionSettings()
PLAN_PATH_RATE_HZ = 10_000.0


class ScriptedRobot(SimulatedRobot):
    """The simulated robot, with an operator acting at set times of the backend's clock
    after the plan's first cycle (simulated time runs faster than any thread could follow
    it); ``executor`` is the one running it."""

    script: list[tuple[float, Callable[[], object]]]
    executor: Executor
    _plan_start: float | None = None
    _last_read: float = 0.0

    def read(self) -> so.execution.Measurement:
        measurement = super().read()
        now, status = self.clock.now(), self.executor.status
        if self._plan_start is None and status is not None and status.phase == "plan":
            self._plan_start = self._last_read  # the plan's first cycle read there
        self._last_read = now
        while self._plan_start is not None and self.script:
            if now < self._plan_start + self.script[0][0]:
                break
            _, action = self.script.pop(0)
            action()
        return measurement


def scripted_run(problem, plan, tmp_path, script, **settings):
    """Run ``plan`` with ``script`` [(s after the plan's first cycle, executor → action)];
    returns the result, the log, its header and the plant's true trace (its arrays)."""
    backend = ScriptedRobot(problem.robot, start_rad=plan.position(plan.start_time))
    executor = backend.executor = Executor(problem, backend, ExecutionSettings(**settings))
    backend.script = [(t, (lambda act=act: act(executor))) for t, act in script]
    result = executor.run(plan, tmp_path / "run.csv")
    table, header = read_log(tmp_path / "run.csv")
    return result, table, header, backend.trace.arrays()


# ------------------------------------------------------------------ the judges
def plan_cut_tree(problem: so.Problem, plan: so.Trajectory) -> cKDTree:
    """The plan's cut on the skull, sampled at 10 kHz (m)."""
    t = np.arange(plan.start_time, plan.end_time, 1.0 / PLAN_PATH_RATE_HZ)
    return cKDTree(plan.cut_points(problem.contour, np.append(t, plan.end_time)))


def cut_distance(problem: so.Problem, tree: cKDTree, q: np.ndarray) -> np.ndarray:
    """Distance of the cut at joint angles q (N, 2) from the plan's cut, m."""
    directions = kinematics.forward_kinematics(q, 1.0)
    return tree.query(problem.contour.cut_points(directions))[0]


def assert_the_cut_stayed_on_the_plans_path(problem, plan, arrays: dict, table):
    """Every true sample from the plan's start to the end of the run: within the contour
    tolerance of the plan's cut (the 10 kHz sampling adds at most 6 µm here)."""
    start = table["time_s"].iloc[0]
    running = arrays["time_s"] >= start
    distance = cut_distance(problem, plan_cut_tree(problem, plan), arrays["position_rad"][running])
    assert np.max(distance) <= path_tolerance(problem), np.max(distance)
    return distance


def assert_commanded_within_limits(table: pd.DataFrame, problem: so.Problem) -> None:
    """The goals of the plan phase and the settle, by finite differences: speed,
    acceleration and jerk within the limits as the evaluator allows them."""
    rows = table[table["phase"].isin(["plan", "settle"])]
    t = rows["time_s"].to_numpy()
    q = rows[["reference_theta1_rad", "reference_theta2_rad"]].to_numpy()
    limits = SETTINGS.joint_limits(problem)
    rounding = LOG_DIGITS_ERROR * np.max(np.abs(q))
    for order, limit, rule in (
        (1, limits.speed, "joint speed"),
        (2, limits.acceleration, "joint acceleration"),
        (3, limits.jerk, "joint jerk"),
    ):
        spacing = np.min(t[order:] - t[:-order]) / order
        allowed = RULES[rule].allowed(limit) + 2**order * rounding / spacing**order
        worst = np.max(np.abs(derivative_estimates(t, q, order)))
        assert worst <= allowed, (rule, worst, allowed)


def holds(events: list[dict]) -> list[dict[str, float]]:
    """Each hold's times: asked, feed at 0, rest confirmed, resumed (s, the log's clock)."""
    found, current = [], None
    for event in events:
        name = event["event"]
        if name == "hold":
            current = {"asked": event["time_s"]}
        elif name in ("held", "at rest") and current is not None:
            current[name] = event["time_s"]
        elif name == "resume" and current is not None:
            current["resumed"] = event["time_s"]
            found.append(current)
            current = None
    return found


def assert_at_rest_during_holds(
    events: list[dict], arrays: dict, problem: so.Problem, expected: int
) -> None:
    """Each hold reached rest before its resume, and the plant's true state was at rest
    from the executor's confirmation to the resume: speeds under the rest speed, each
    joint within the rest pulses."""
    found = holds(events)
    assert len(found) == expected
    pulse = 2 * np.pi / problem.robot.actuator.pulses_per_rev
    for hold in found:
        assert hold["asked"] <= hold["held"] <= hold["at rest"] <= hold["resumed"]
        during = (arrays["time_s"] >= hold["at rest"]) & (arrays["time_s"] <= hold["resumed"])
        assert np.count_nonzero(during) >= 2
        assert np.max(np.abs(arrays["velocity_rad_s"][during])) < SETTINGS.rest_speed_rad_s
        span = np.ptp(arrays["position_rad"][during], axis=0)
        assert np.all(span < SETTINGS.rest_position_pulses * pulse), span


def assert_the_plan_was_completed(result, table, plan) -> None:
    assert result.completed and result.at_rest, result.reason
    plan_rows = table[table["phase"] == "plan"]
    assert plan_rows["plan_time_s"].iloc[-1] == pytest.approx(plan.duration)
    assert np.all(np.diff(plan_rows["plan_time_s"]) >= 0.0)  # never backwards


# ------------------------------------------------------------------ the runs
THREE_HOLDS_TWO_OVERRIDES = [
    (2.0, lambda ex: ex.hold()),
    (3.0, lambda ex: ex.resume()),
    (4.5, lambda ex: ex.set_feed(0.5)),
    (6.0, lambda ex: ex.hold()),
    (7.5, lambda ex: ex.resume()),
    (9.0, lambda ex: ex.set_feed(1.0)),
    (12.0, lambda ex: ex.hold()),
    (12.8, lambda ex: ex.resume()),
]


@pytest.fixture(scope="module")
def steered_run(hardware_problem, hardware_plan, tmp_path_factory):
    return scripted_run(
        hardware_problem,
        hardware_plan,
        tmp_path_factory.mktemp("steered"),
        THREE_HOLDS_TWO_OVERRIDES,
    )


def test_three_holds_and_two_overrides_complete_the_contour_on_the_path(
    steered_run, hardware_problem, hardware_plan
):
    result, table, header, arrays = steered_run
    assert_the_plan_was_completed(result, table, hardware_plan)
    assert_the_cut_stayed_on_the_plans_path(hardware_problem, hardware_plan, arrays, table)
    assert_commanded_within_limits(table, hardware_problem)
    assert_at_rest_during_holds(header["feed_events"], arrays, hardware_problem, expected=3)
    names = [e["event"] for e in header["feed_events"]]
    assert names.count("feed 50%") == 1 and names.count("feed 100%") == 1
    # the run took longer than the plan by the holds and the half-speed stretch
    assert table["time_s"].iloc[-1] - table["time_s"].iloc[0] > hardware_plan.duration + 2.5


class Operator(threading.Thread):
    """Acts on an executor from another thread, at wall-clock times after its first cycle,
    once the plan has begun."""

    def __init__(self, executor: Executor, script) -> None:
        super().__init__(daemon=True)
        self._executor, self._script = executor, script

    def run(self) -> None:
        while self._executor.status is None or self._executor.status.phase != "plan":
            time.sleep(0.001)
        start = time.monotonic() - self._executor.status.time_s
        for at, act in self._script:
            time.sleep(max(0.0, start + at - time.monotonic()))
            act(self._executor)


@pytest.mark.slow
@pytest.mark.real_time
def test_three_holds_and_two_overrides_through_the_sdk_and_the_emulator(
    hardware_problem, hardware_plan, tmp_path
):
    trace_path = tmp_path / "plant.npz"
    with spawn_emulator(problem_file=HARDWARE_PROBLEM, trace_path=trace_path) as emulator:
        backend = DynamixelRobot(hardware_problem.robot.actuator, emulator.device)
        executor = Executor(hardware_problem, backend, SETTINGS)
        operator = Operator(executor, THREE_HOLDS_TWO_OVERRIDES)
        operator.start()
        result = executor.run(hardware_plan, tmp_path / "run.csv")
        operator.join()
    table, header = read_log(tmp_path / "run.csv")
    arrays = StateTrace.load(trace_path, header["clock_origin_s"])
    assert header["backend"]["backend"] == "dynamixel"
    assert_the_plan_was_completed(result, table, hardware_plan)
    assert_the_cut_stayed_on_the_plans_path(hardware_problem, hardware_plan, arrays, table)
    assert_commanded_within_limits(table, hardware_problem)
    assert_at_rest_during_holds(header["feed_events"], arrays, hardware_problem, expected=3)


def test_the_log_rows_carry_the_plan_time_feed_and_target(steered_run, hardware_plan):
    result, table, header, _ = steered_run
    plan = table[table["phase"] == "plan"]
    assert plan[["plan_time_s", "feed", "feed_target"]].notna().all().all()
    assert table.loc[table["phase"] != "plan", "feed"].isna().all()
    # the goal is the plan at the logged plan time: the pace changed, never the path
    goals = plan[["reference_theta1_rad", "reference_theta2_rad"]].to_numpy()
    on_plan = hardware_plan.position(plan["plan_time_s"].to_numpy() + hardware_plan.start_time)
    np.testing.assert_allclose(goals, on_plan, atol=1e-8)
    # the plan time advances at the logged feed: the trapezoid rule's error is at most
    # h³/12 max|r̈| per cycle (and the log's 12 digits)
    t, tau, feed = (plan[c].to_numpy() for c in ("time_s", "plan_time_s", "feed"))
    advance = np.diff(tau) - 0.5 * (feed[1:] + feed[:-1]) * np.diff(t)
    assert np.all(np.abs(advance) <= np.diff(t) ** 3 / 12 * MAX_FEED_JERK_PER_S2 + 1e-9)
    # the header's events are the rows' targets
    for event in header["feed_events"]:
        row = plan.iloc[int(np.argmin(np.abs(plan["time_s"] - event["time_s"])))]
        assert row["feed_target"] == pytest.approx(event["feed_target"])
    assert result.feed_events == header["feed_events"]


def test_a_hold_longer_than_max_hold_ends_in_the_safe_stop(
    hardware_problem, hardware_plan, tmp_path
):
    result, table, header, trace = scripted_run(
        hardware_problem, hardware_plan, tmp_path, [(3.0, lambda ex: ex.hold())], max_hold_s=2.0
    )
    assert not result.completed and result.at_rest
    assert "feed held longer than max_hold_s (2 s)" in result.reason
    held = next(e["time_s"] for e in header["feed_events"] if e["event"] == "held")
    assert header["stop"]["fault_seen_s"] - held == pytest.approx(2.0, abs=0.02)
    assert header["stop"]["travel_deg"] is not None
    assert max(header["stop"]["travel_deg"]) < 0.01  # it was already at rest


def test_a_stop_request_from_the_operator_is_the_safe_stop(
    hardware_problem, hardware_plan, tmp_path
):
    result, table, _, _ = scripted_run(
        hardware_problem, hardware_plan, tmp_path, [(4.0, lambda ex: ex.stop("operator: q"))]
    )
    assert not result.completed and result.at_rest
    assert result.reason == "interrupted (operator: q)"
    assert table["phase"].iloc[-1] == "hold"


# ------------------------------------------------------------------ the feed alone
def run_profile(plan: so.Trajectory, problem: so.Problem, script, rate_hz: float = 1000.0):
    """Drive a :class:`FeedProfile` at ``rate_hz`` through ``script`` [(time s, target)];
    returns the times, the paces and the goals (position, rate, acceleration)."""
    limits = SETTINGS.joint_limits(problem)
    profile = FeedProfile(plan, limits, script[0][1], 0.5 / rate_hz, problem.limits.hold_within_s)
    times, paces, goals = [], [], []
    target, pending = script[0][1], list(script[1:])
    for k in range(int(10 * plan.duration * rate_hz)):
        t = k / rate_hz
        while pending and t >= pending[0][0]:
            target = pending.pop(0)[1]
        pace = profile.advance(t, target)
        times.append(t)
        paces.append(pace)
        goals.append(profile.goal(pace))
        if profile.finished(pace):
            break
    return np.array(times), paces, [np.array(g) for g in zip(*goals, strict=True)]


@pytest.fixture(scope="module")
def time_optimal_plan(hardware_problem):
    """A plan at its planner's bounds: toppra's, the joint limits less a hold's room
    (holds on time-optimal plans: test_hold.py)."""
    return so.plan(hardware_problem, "toppra")


@pytest.mark.parametrize("seed", range(6))
def test_feed_changes_never_break_a_limit_even_on_a_plan_at_the_limits(
    seed, hardware_problem, time_optimal_plan
):
    rng = np.random.default_rng(seed)
    plan = time_optimal_plan
    times = np.sort(rng.uniform(0.0, plan.duration, 6))
    script = [(0.0, 1.0)] + [(t, float(rng.choice([0.0, 0.3, 0.7, 1.0]))) for t in times]
    script.append((plan.duration + 0.5, 1.0))  # a hold at the end is released
    t, paces, (q, qd, qdd) = run_profile(plan, hardware_problem, script)
    tau = np.array([p.plan_time_s for p in paces])
    assert paces[-1].plan_time_s == pytest.approx(plan.duration)
    assert np.all(np.diff(tau) >= 0.0)
    np.testing.assert_allclose(q, plan.position(tau + plan.start_time), atol=1e-12)
    limits = SETTINGS.joint_limits(hardware_problem)
    for order, limit, rule in (
        (1, limits.speed, "joint speed"),
        (2, limits.acceleration, "joint acceleration"),
        (3, limits.jerk, "joint jerk"),
    ):
        worst = np.max(np.abs(derivative_estimates(t, q, order)))
        assert worst <= RULES[rule].allowed(limit), (rule, worst)
    # the goal's rate and acceleration (the safe stop starts from them) are the stream's
    np.testing.assert_allclose(derivative_estimates(t, q, 1), 0.5 * (qd[1:] + qd[:-1]), atol=2e-4)
    np.testing.assert_allclose(
        derivative_estimates(t, qd, 1), 0.5 * (qdd[1:] + qdd[:-1]), atol=0.02 * limits.acceleration
    )


def test_a_hold_on_a_gentle_plan_stops_within_a_few_hundredths_of_its_time(
    hardware_problem, hardware_plan
):
    _, paces, _ = run_profile(hardware_plan, hardware_problem, [(0.0, 1.0), (5.0, 0.0)], 100.0)
    held = next(k for k, p in enumerate(paces) if p.feed == 0.0)
    assert held * 0.01 - 5.0 < 0.15
    assert paces[held].plan_time_s - 5.0 < 0.1
    assert all(p.feed == 0.0 and p.plan_time_s == paces[held].plan_time_s for p in paces[held:])


def test_the_feed_ceiling_is_the_fastest_pace_the_evaluator_accepts(
    hardware_problem, hardware_plan
):
    ceiling = feed_ceiling(hardware_problem, hardware_plan, 2.0)
    assert 1.0 < ceiling < 2.0
    assert not so.evaluate(hardware_problem, hardware_plan.time_scaled(ceiling)).violations
    faster = so.evaluate(hardware_problem, hardware_plan.time_scaled(ceiling + 0.02))
    assert faster.violations
    assert feed_ceiling(hardware_problem, hardware_plan, 1.0) == 1.0


@pytest.mark.parametrize(
    "planner, broken_faster",
    [
        ("cubic", {"acceleration step"}),
        ("toppra", {"joint speed", "joint acceleration", "joint jerk", "hold acceleration"}),
    ],
)
def test_the_paced_limits_are_what_the_evaluator_finds_of_the_plan_run_faster(
    hardware_problem, planner, broken_faster
):
    plan = so.plan(hardware_problem, planner)
    paced = PacedLimits(hardware_problem, plan)
    found = set()
    for feed in (0.5, 1.0, 1.03, 1.07, 1.1, 1.3, 2.0, 3.0):
        judged = so.evaluate(hardware_problem, plan.time_scaled(feed)).violations
        assert paced.broken(feed) == {v.rule for v in judged}, feed
        found |= paced.broken(feed)
    assert broken_faster <= found


def test_the_paced_torques_are_the_models_at_the_faster_motion(hardware_problem, hardware_plan):
    paced = PacedLimits(hardware_problem, hardware_plan)
    for feed in (0.5, 1.0, 2.5):
        _, q, qd, qdd, _ = paced.states(feed)
        expected = dynamics.actuator_torque(hardware_problem.robot, q, qd, qdd)
        np.testing.assert_allclose(paced.torque(feed), expected, rtol=1e-9, atol=1e-12)


def test_operator_requests_are_checked_and_clipped():
    requests = FeedRequests(1.0, ceiling=1.2)
    for bad in (float("nan"), -0.1, "fast", float("inf")):
        with pytest.raises(InputError, match="feed = "):
            requests.set_feed(bad)
    assert requests.set_feed(3.0) == 1.2
    assert requests.step_feed(0.1) == pytest.approx(1.2)
    requests.set_feed(0.15)
    assert requests.step_feed(-0.1) == pytest.approx(0.1)
    assert requests.toggle_hold() and requests.requested() == (pytest.approx(0.1), True)
    requests.resume()
    assert requests.requested()[1] is False


@pytest.mark.parametrize(
    "settings, field",
    [
        ({"feed": -1.0}, "feed"),
        ({"feed": 2.0}, "feed"),
        ({"max_feed": 0.5}, "max_feed"),
        ({"max_hold_s": float("nan")}, "max_hold_s"),
    ],
)
def test_bad_feed_settings_are_one_line_errors(settings, field):
    with pytest.raises(InputError, match=f"^{field} = "):
        ExecutionSettings(**settings)


@pytest.mark.parametrize(
    "feed, shown", [(0, "0"), (0.0, "0.0"), (0.05, "0.05"), (np.float64(0.0), "0.0")]
)
def test_a_run_cannot_start_held(feed, shown):
    """A start at feed 0 only waits max_hold_s, then stops: the feed starts at FEED_STEP or
    more, and the message prints the value as a plain number."""
    with pytest.raises(InputError) as refused:
        ExecutionSettings(feed=feed)
    assert str(refused.value) == f"feed = {shown}: expected a number in [0.1, 4.0]"
    assert ExecutionSettings(feed=FEED_STEP).feed == FEED_STEP


def test_execute_refuses_feed_0_in_one_line_and_writes_nothing(tmp_path, capsys):
    plan = tmp_path / "plan.csv"
    assert main(["plan", str(HARDWARE_PROBLEM), "--planner", "cubic", "--out", str(plan)]) == 0
    capsys.readouterr()
    log = tmp_path / "run.csv"
    argv = ["execute", str(plan), "--problem", str(HARDWARE_PROBLEM), "--backend", "sim"]
    status = main([*argv, "--log", str(log), "--feed", "0"])
    err = capsys.readouterr().err
    assert status == 2
    assert err == "spm-opt: error: --feed: feed = 0.0: expected a number in [0.1, 4.0]\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.csv", "plan.json"]
