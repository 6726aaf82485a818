"""The feed's cost in the control loop and before it.

Per control cycle: the goal at the feed's pace (the plan's q, q′ and q″ at τ, what every
cycle computed before the feed existed: the reference), the pace itself when nothing
changes, the cycle in which a hold from full feed is planned (ruckig, its bounds from the
plan's derivatives, its check), and the costliest such cycle on toppra's time-optimal plan
(of 100 plan times: the change from the plan's derivatives finds no room and reference
stops are checked in turn, :mod:`spm_opt.judge.hold_room`). Once per run: the feed ceiling
(bisected on how the plan's limits scale with the feed, :mod:`spm_opt.judge.paced`, then
judged once by the evaluator at the pace found) and the executor's whole pre-flight (the
plan's check, then its ceiling, of a fresh copy of the plan), against one evaluation of the
plan.

    python benchmarks/feed.py [--repeats 5]

Prints a table and writes benchmarks/results/feed.json.
"""

from __future__ import annotations

import argparse

import numpy as np
from timing import ROOT, best_of, write_results

import spm_opt as so
from spm_opt.execution import ExecutionSettings, Executor, SimulatedRobot
from spm_opt.execution.ceiling import feed_ceiling
from spm_opt.execution.feed import FeedProfile
from spm_opt.execution.tracking import Lead

PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"
CYCLES = 200


def profile(problem: so.Problem, plan: so.Trajectory) -> FeedProfile:
    settings = ExecutionSettings()
    return FeedProfile(
        plan,
        settings.joint_limits(problem),
        1.0,
        0.5 / settings.rate_hz,
        problem.limits.hold_within_s,
    )


def per_cycle(repeats: int, work) -> float:
    """Best time of ``CYCLES`` calls of ``work(k)``, per call, µs."""
    return best_of(repeats, lambda: [work(k) for k in range(CYCLES)]) / CYCLES * 1e6


def costliest_hold(problem: so.Problem, plan: so.Trajectory) -> float:
    """The plan time (s), of 100, at which planning a hold from full feed takes longest."""
    times = np.linspace(0.0, plan.duration, 100, endpoint=False)
    costs = [best_of(1, lambda t=t: profile(problem, plan).advance(t, 0.0)) for t in times]
    return float(times[int(np.argmax(costs))])


def preflight(problem: so.Problem, plan: so.Trajectory) -> float:
    """The executor's pre-flight of ``plan``: its check, then its feed ceiling (the
    default settings' ``max_feed``, the goals' lead); returns the ceiling."""
    settings = ExecutionSettings()
    executor = Executor(problem, SimulatedRobot(problem.robot), settings)
    executor.check_plan(plan)
    lead = Lead.for_actuator(problem.robot.actuator, 1.0 / settings.rate_hz, settings.tracking)
    return feed_ceiling(problem, plan, settings.max_feed, lead)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    problem = so.load_problem(PROBLEM)
    cubic = so.plan(problem, "cubic")
    optimal = so.plan(problem, "toppra")
    steady = profile(problem, cubic)
    pace = steady.advance(5.0, 1.0)
    costliest_at = costliest_hold(problem, optimal)

    def hold_planned(_: int) -> None:
        fresh = profile(problem, cubic)
        fresh.advance(5.0, 0.0)

    def hold_costliest(_: int) -> None:
        fresh = profile(problem, optimal)
        fresh.advance(costliest_at, 0.0)

    cycle = {
        "goal at the pace (reference)": per_cycle(args.repeats, lambda _: steady.goal(pace)),
        "pace, nothing changes": per_cycle(args.repeats, lambda k: steady.advance(5.0 + k, 1.0)),
        "pace, a hold planned (cubic)": per_cycle(args.repeats, hold_planned),
        "pace, the costliest hold (toppra)": per_cycle(args.repeats, hold_costliest),
    }
    once = {
        # a fresh copy each time: the evaluator caches what it measured of a trajectory
        "evaluate the plan (reference)": best_of(
            args.repeats, lambda: so.evaluate(problem, cubic.time_scaled(1.0))
        ),
        "feed ceiling, up to 1.5": best_of(args.repeats, lambda: feed_ceiling(problem, cubic, 1.5)),
        "pre-flight: plan check + ceiling": best_of(
            args.repeats, lambda: preflight(problem, cubic.time_scaled(1.0))
        ),
    }
    results = {"per_cycle_us": {}, "per_run_s": {}}
    print(f"{'per control cycle':40s} {'µs':>10s} {'ratio':>8s}")
    reference = cycle["goal at the pace (reference)"]
    for label, us in cycle.items():
        results["per_cycle_us"][label] = {"us": us, "ratio_to_reference": us / reference}
        print(f"{label:40s} {us:10.1f} {us / reference:7.1f}x")
    print(f"\n{'per run':40s} {'s':>10s} {'ratio':>8s}")
    reference = once["evaluate the plan (reference)"]
    for label, seconds in once.items():
        results["per_run_s"][label] = {"s": seconds, "ratio_to_reference": seconds / reference}
        print(f"{label:40s} {seconds:10.4f} {seconds / reference:7.1f}x")
    print("(ratios: against the reference measured in the same run)")
    write_results("feed", {"problem": PROBLEM.name, "costliest_hold_at_s": costliest_at, **results})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
