"""Holds that always work: the problem's bound on a hold, the room the planners keep for it,
the evaluator's rule, and the executor's holds and resumes on plans at the limits.

A hold is judged by references that do not share the executor's code: the goal at each
cycle against the plan at the logged plan time, the goals' finite differences against the
limits, and, on the simulated robot whose plant is not the planning model, the plant's true
state (its speeds and its cut on the skull).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import ruckig
from conftest import HARDWARE_PROBLEM, ROOT
from test_execution_faults import derivative_estimates
from test_feed import ScriptedRobot, cut_distance, holds, plan_cut_tree

import spm_opt as so
from spm_opt.base.ruckig_local import calculate_locally
from spm_opt.execution import ExecutionSettings, Executor, read_log
from spm_opt.execution.feed import FeedProfile, NoRoom
from spm_opt.judge.hold_room import hold_stop
from spm_opt.judge.limits import RULES, path_tolerance
from spm_opt.problem.problem import DEFAULT_HOLD_WITHIN_S

PLANT = so.load_robot(ROOT / "problems" / "robots" / "prototype_plant.toml")
SETTINGS = ExecutionSettings()
RATE_HZ = SETTINGS.rate_hz
TIME_OPTIMAL = ("toppra", "ocp-min-time")
HOLD_RULES = {"hold acceleration", "hold jerk"}


@pytest.fixture(scope="module")
def plans(hardware_problem):
    """The time-optimal plans of the hardware problem, by planner."""
    return {name: so.plan(hardware_problem, name) for name in TIME_OPTIMAL}


@pytest.fixture(scope="module")
def roomless(hardware_problem):
    """toppra's plan of the hardware problem made without the hold's room (no bound)."""
    limits = dataclasses.replace(hardware_problem.limits, hold_within_s=None)
    return so.plan(dataclasses.replace(hardware_problem, limits=limits), "toppra")


# ------------------------------------------------------------------ the bound
def test_the_hold_bound_is_a_limit_of_the_problem_file(hardware_problem):
    assert hardware_problem.limits.hold_within_s == DEFAULT_HOLD_WITHIN_S == 1.0
    longer = so.load_problem(HARDWARE_PROBLEM, {"limits.hold_within_s": 2.5})
    assert longer.limits.hold_within_s == 2.5
    for bad in (0.0, -1.0, float("nan"), "1 s", 61.0):
        with pytest.raises(so.InputError, match=r"hold_within_s = .*: expected a") as error:
            so.load_problem(HARDWARE_PROBLEM, {"limits.hold_within_s": bad})
        assert "\n" not in str(error.value)


def test_a_bound_too_short_for_the_limits_is_a_planning_error():
    """Below 0.41 s no jerk is left to plan with on the hardware problem."""
    quick = so.load_problem(HARDWARE_PROBLEM, {"limits.hold_within_s": 0.3})
    with pytest.raises(so.PlanningError, match=r"^hold_within_s = 0.3: a hold that quick"):
        so.plan(quick, "toppra")


# ------------------------------------------------------------------ the plans
def test_the_evaluator_flags_a_plan_without_room_and_passes_the_planners(
    hardware_problem, plans, roomless
):
    for plan in plans.values():
        assert so.evaluate(hardware_problem, plan).violations == []
    assert so.evaluate(hardware_problem, so.plan(hardware_problem, "ruckig")).violations == []
    broken = {v.rule for v in so.evaluate(hardware_problem, roomless).violations}
    assert broken == HOLD_RULES
    # the rule judges the cut (the executor runs such a plan) and needs the limits it keeps
    assert all(RULES[rule].judges == "cut" for rule in HOLD_RULES)
    unlimited = dataclasses.replace(
        hardware_problem,
        limits=dataclasses.replace(
            hardware_problem.limits, max_joint_acceleration=None, max_joint_jerk=None
        ),
    )
    assert not {v.rule for v in so.evaluate(unlimited, roomless).violations} & HOLD_RULES


def reference_stop(plan: so.Trajectory, start_s: float, within_s: float) -> np.ndarray:
    """The reference stop from full feed at plan time ``start_s``, s, sampled at 0.1 ms:
    the joint angles q(τ(t)) (N, 2), rad, with τ(t) from ruckig's change of the feed."""
    stop = hold_stop(within_s)
    inp = ruckig.InputParameter(1)
    inp.control_interface = ruckig.ControlInterface.Velocity
    inp.current_position, inp.current_velocity = [start_s], [1.0]
    inp.current_acceleration, inp.target_velocity = [0.0], [0.0]
    inp.target_acceleration, inp.max_velocity = [0.0], [1.0]
    inp.max_acceleration, inp.max_jerk = [stop.rate_per_s], [stop.jerk_per_s2]
    motion = calculate_locally(inp, "test stop")
    assert motion.duration <= 0.9 * within_s + 1e-9
    t = np.arange(0.0, motion.duration + 0.02, 1e-4)
    tau = np.array([motion.at_time(x)[0][0] for x in t])
    return plan.position(np.minimum(tau, plan.duration) + plan.start_time)


@pytest.mark.parametrize("name", TIME_OPTIMAL)
def test_the_planners_room_lets_the_reference_stop_keep_the_limits(hardware_problem, plans, name):
    """The stop's joint acceleration and jerk, by finite differences of q(τ(t)) at 0.1 ms
    from 20 random points of the plan, within the limits as the evaluator allows them."""
    plan, limits = plans[name], hardware_problem.limits
    rng = np.random.default_rng(5)
    for start in rng.uniform(0.0, plan.duration, 20):
        q = reference_stop(plan, start, limits.hold_within_s)
        t = np.arange(len(q)) * 1e-4
        for order, limit, rule in (
            (2, limits.max_joint_acceleration, "joint acceleration"),
            (3, limits.max_joint_jerk, "joint jerk"),
        ):
            worst = np.max(np.abs(derivative_estimates(t, q, order)))
            assert worst <= RULES[rule].allowed(limit), (start, rule, worst)


# ------------------------------------------------------------------ holds, the feed alone
def hold_alone(
    plan: so.Trajectory, problem: so.Problem, hold_s: float
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Drive the feed at the control rate from full feed, a hold asked at ``hold_s`` (s);
    (time from the request to rest, s; the cycles' times (N,), s; plan times (N,), s;
    goals (N, 2), rad): at rest once the feed is 0 or the plan's end is reached."""
    profile = FeedProfile(
        plan, SETTINGS.joint_limits(problem), 1.0, 0.5 / RATE_HZ, problem.limits.hold_within_s
    )
    times, taus, goals = [], [], []
    for k in range(int((plan.duration + 2.0) * RATE_HZ)):
        t = k / RATE_HZ
        pace = profile.advance(t, 0.0 if t >= hold_s else 1.0)
        times.append(t)
        taus.append(pace.plan_time_s)
        goals.append(profile.goal(pace)[0])
        if t >= hold_s and (pace.feed == 0.0 or profile.finished(pace)):
            return t - hold_s, np.array(times), np.array(taus), np.array(goals)
    raise AssertionError(f"no rest after a hold at {hold_s} s")


@pytest.mark.parametrize("name", TIME_OPTIMAL)
def test_fifty_holds_on_a_time_optimal_plan_stop_on_the_path_within_the_bound(
    hardware_problem, plans, name
):
    """Holds at 50 random times, each from full feed: the commanded motion rests on the
    planned path within ``hold_within_s`` of the request, within the joint limits."""
    plan, limits = plans[name], SETTINGS.joint_limits(hardware_problem)
    bound = hardware_problem.limits.hold_within_s
    rng = np.random.default_rng(25)
    for hold_s in rng.uniform(0.0, plan.duration, 50):
        stop_s, t, tau, q = hold_alone(plan, hardware_problem, hold_s)
        assert stop_s <= bound, (hold_s, stop_s)
        np.testing.assert_allclose(q, plan.position(tau + plan.start_time), atol=1e-12)
        assert np.all(np.diff(tau) >= 0.0)
        for order, limit, rule in (
            (1, limits.speed, "joint speed"),
            (2, limits.acceleration, "joint acceleration"),
            (3, limits.jerk, "joint jerk"),
        ):
            worst = np.max(np.abs(derivative_estimates(t, q, order)))
            assert worst <= RULES[rule].allowed(limit), (hold_s, rule, worst)


# ------------------------------------------------------------------ holds on the robot
def run(problem, plan, tmp_path, script, plant=None, **settings):
    """Run ``plan`` on the simulated robot (``plant`` its plant, default the planning
    model) with ``script`` [(s after the plan's first cycle, executor → action)]; the
    result, the log, its header and the plant's true trace on the log's clock."""
    backend = ScriptedRobot(
        problem.robot, start_rad=plan.position(plan.start_time), plant_robot=plant
    )
    executor = backend.executor = Executor(problem, backend, ExecutionSettings(**settings))
    backend.script = [(t, (lambda act=act: act(executor))) for t, act in script]
    result = executor.run(plan, tmp_path / "run.csv")
    table, header = read_log(tmp_path / "run.csv")
    return result, table, header, backend.trace.arrays(header["clock_origin_s"])


@pytest.mark.parametrize("name", TIME_OPTIMAL)
def test_holds_bring_the_true_robot_to_rest_on_the_path_within_the_bound(
    hardware_problem, plans, name, tmp_path
):
    """Three holds per plan on the simulated robot whose plant is not the planning model:
    the plant's true speeds fall below the rest speed for good within the bound; its cut
    stops within the path tolerance of the plan's, and on the way strays no farther from it
    than the same plan's cut does without a hold (the plant's own tracking error, 0.23 mm
    on ocp-min-time's plan at 1.4 rad/s); the plan completes after the resume."""
    plan, bound = plans[name], hardware_problem.limits.hold_within_s
    tree, tolerance = plan_cut_tree(hardware_problem, plan), path_tolerance(hardware_problem)
    *_, trace = run(hardware_problem, plan, tmp_path, [], PLANT)
    tracking = np.max(cut_distance(hardware_problem, tree, trace["position_rad"]))
    for k, hold_s in enumerate(np.random.default_rng(7).uniform(0.0, 0.55 * plan.duration, 3)):
        script = [(hold_s, lambda ex: ex.hold()), (hold_s + 1.5, lambda ex: ex.resume())]
        (tmp_path / str(k)).mkdir()
        result, _, header, trace = run(hardware_problem, plan, tmp_path / str(k), script, PLANT)
        assert result.completed and result.at_rest, result.reason
        (hold,) = holds(header["feed_events"])
        assert hold["held"] - hold["asked"] <= bound
        t, speed = trace["time_s"], np.max(np.abs(trace["velocity_rad_s"]), axis=1)
        window = (t >= hold["asked"]) & (t <= hold["resumed"])
        moving = np.flatnonzero(window & (speed >= SETTINGS.rest_speed_rad_s))
        at_rest = t[moving[-1] + 1]
        assert at_rest - hold["asked"] <= bound, (hold_s, at_rest)
        distance = cut_distance(hardware_problem, tree, trace["position_rad"][window])
        assert np.max(distance) <= tracking
        rest = window & (t >= at_rest)
        assert (
            np.max(cut_distance(hardware_problem, tree, trace["position_rad"][rest])) <= tolerance
        )


def test_a_resume_near_the_start_of_the_papers_minimum_time_plan_reaches_full_feed(
    paper_problem, tmp_path
):
    """Where the plan's jerk peaks near its start (on the plan without the room, 9.95 of
    10 rad/s³, where no resume to 100 % ever found room): held there, resumed a second
    later, the feed is back at 100 % long before ``max_hold_s`` would have ended the run."""
    plan = so.plan(paper_problem, "ocp-min-time")
    t = np.linspace(0.0, 1.0, 1001)
    hold_s = float(t[np.argmax(np.max(np.abs(plan.jerk(t)), axis=1))])
    script = [
        (hold_s, lambda ex: ex.hold()),
        (hold_s + 1.0, lambda ex: ex.resume()),
        (hold_s + 3.0, lambda ex: ex.stop("enough")),
    ]
    result, table, header, _ = run(paper_problem, plan, tmp_path, script, max_hold_s=2.5)
    assert result.reason == "interrupted (enough)"
    (hold,) = holds(header["feed_events"])
    after = table[(table["phase"] == "plan") & (table["time_s"] >= hold["resumed"])]
    assert after["feed"].iloc[-1] == 1.0
    back = after["time_s"].iloc[int(np.argmax(after["feed"].to_numpy() == 1.0))]
    assert back - hold["resumed"] < 1.0


def test_a_resume_goes_in_stages_where_the_plan_leaves_no_room(hardware_problem, roomless):
    """On a plan made without the room, held at its start and resumed a second later: no
    room for 100 % at once, so the feed goes to 90 %, and on to 100 % where the plan gives
    room, never staying held."""
    limits, within = SETTINGS.joint_limits(hardware_problem), hardware_problem.limits.hold_within_s
    profile = FeedProfile(roomless, limits, 1.0, 0.5 / RATE_HZ, within)
    targets, feeds = [], []
    for k in range(int(3 * roomless.duration * RATE_HZ)):
        t = k / RATE_HZ
        pace = profile.advance(t, 0.0 if t < 1.0 else 1.0)
        if t >= 1.0:
            targets.append(pace.target)
            feeds.append(pace.feed)
        if profile.finished(pace):
            break
    assert targets[0] == pytest.approx(0.9) and targets[-1] == 1.0
    assert 1.0 in feeds  # reached before the plan's end


def no_room_at(plan: so.Trajectory, problem: so.Problem) -> float:
    """A plan time, s, where a hold from full feed finds no path-keeping stop, nor 20 ms
    either side of it."""
    limits, within = SETTINGS.joint_limits(problem), problem.limits.hold_within_s
    found = []
    for t in np.arange(0.0, plan.duration, 1.0 / RATE_HZ):
        try:
            FeedProfile(plan, limits, 1.0, 0.5 / RATE_HZ, within).advance(t, 0.0)
        except NoRoom:
            found.append(t)
            if len(found) >= 5 and found[-1] - found[-5] < 4.5 / RATE_HZ:
                return found[-3]
    raise AssertionError("the plan leaves a hold room everywhere")


def test_a_hold_without_room_is_the_safe_stop_at_once(hardware_problem, roomless, tmp_path):
    """A plan made without the room, run under the problem's bound (it keeps every limit
    of the robot, so the executor runs it): where no path-keeping stop fits, the hold is the
    safe stop in the cycle that saw it asked, and the log says so."""
    hold_s = no_room_at(roomless, hardware_problem) - 0.5 / RATE_HZ
    script = [(hold_s, lambda ex: ex.hold())]
    result, table, header, _ = run(hardware_problem, roomless, tmp_path, script, other_problem=True)
    assert not result.completed and result.at_rest
    assert result.reason.startswith("feed hold: no path-keeping stop fits at plan time")
    assert [e["event"] for e in header["feed_events"]] == ["hold", "no room: safe stop"]
    asked = header["feed_events"][0]["time_s"]
    assert header["stop"]["fault_seen_s"] == pytest.approx(asked)
    assert table.loc[table["time_s"] >= asked, "phase"].iloc[0] == "stop"
