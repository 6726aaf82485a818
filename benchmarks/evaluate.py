"""Time of the evaluator on every shipped problem and plan, cold and warm, in one run.

Prints a table (progress goes to stderr) and writes benchmarks/results/evaluate.json.

    python benchmarks/evaluate.py [--planners NAMES] [--repeats R] [--rate HZ]

NAMES are comma-separated planner names (default: cubic, toppra, ruckig, ocp-min-time).
First, a warm-up timed on its own (printed above the table) pays for what every call
shares: the first ``load_problem``, the Lagrange dynamics model and the compiled batch
torque. Then, for every ``problems/*.toml`` and every planner, one plan (not timed) and:

- samples: points of the evaluation grid at ``--rate`` (default 1 kHz, the evaluator's).
- cold ms: the first ``spm_opt.judge.evaluate`` of the plan on a freshly loaded problem, which
  pays for the problem's caches (its contour and the duration lower bound).
- best ms, median ms: the best and the median of ``--repeats`` further calls on the same
  problem, each on a fresh ``copy.deepcopy`` of the plan (made outside the timing): the
  evaluator keeps each trajectory object's report, and a copy is judged anew.
- cached ms: a call on a plan already judged (the kept report, copied): what whoever
  evaluates a plan its planner has judged pays.
- torque ms: the median of ``--repeats`` calls of the actuator torque alone on the same
  grid (``dynamics.actuator_torque``, compiled C), the part of a call outside the
  evaluator's own code; own ms: median ms less torque ms, the evaluator's own code.

A planner that raises on a problem gets a row with its error; the others still run.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from statistics import median
from typing import Any

from timing import ROOT, warm_up, write_results

import spm_opt as so
from spm_opt.model import dynamics

DEFAULT_PLANNERS = ("cubic", "toppra", "ruckig", "ocp-min-time")


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def seconds(work: Callable[[], object]) -> float:
    """Wall time, s, of one ``work()``."""
    started = time.perf_counter()
    work()
    return time.perf_counter() - started


def judge_time(problem: so.Problem, trajectory: so.Trajectory, rate_hz: float) -> float:
    """Wall time, s, of one ``spm_opt.judge.evaluate`` of a fresh copy of ``trajectory`` (its
    report not yet kept)."""
    fresh = copy.deepcopy(trajectory)
    return seconds(lambda: so.evaluate(problem, fresh, rate_hz))


def measure(path: Path, planner: str, repeats: int, rate_hz: float) -> dict[str, Any]:
    """Cold, warm, cached and torque-only times, s, of evaluating one planner's plan of one
    problem (see the module docstring)."""
    trajectory = so.plan(so.load_problem(path), planner)
    problem = so.load_problem(path)
    cold = judge_time(problem, trajectory, rate_hz)
    warm = [judge_time(problem, trajectory, rate_hz) for _ in range(repeats)]
    so.evaluate(problem, trajectory, rate_hz)
    cached = seconds(lambda: so.evaluate(problem, trajectory, rate_hz))
    t = trajectory.time_grid(rate_hz)
    q, qd, qdd, _ = trajectory.states(t)
    torque = median(
        seconds(lambda: dynamics.actuator_torque(problem.robot, q, qd, qdd)) for _ in range(repeats)
    )
    return {
        "samples": len(t),
        "cold_s": cold,
        "warm_s": warm,
        "best_warm_s": min(warm),
        "median_warm_s": median(warm),
        "cached_s": cached,
        "torque_s": torque,
        "own_s": median(warm) - torque,
    }


def planners_option(parser: argparse.ArgumentParser, text: str | None) -> list[str]:
    """The comma-separated planner names in ``text`` (default: :data:`DEFAULT_PLANNERS`)."""
    if not text:
        return list(DEFAULT_PLANNERS)
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in so.PLANNERS]
    if unknown:
        parser.error(
            f"unknown planner(s) {', '.join(unknown)}; expected some of {', '.join(so.PLANNERS)}"
        )
    return names


def print_table(results: dict[str, dict[str, dict[str, Any]]]) -> None:
    print(
        f"{'problem':28s} {'planner':14s} {'samples':>8s} {'cold ms':>9s} {'best ms':>9s} "
        f"{'median ms':>9s} {'cached ms':>9s} {'torque ms':>9s} {'own ms':>9s}"
    )
    for problem, rows in results.items():
        for planner, r in rows.items():
            if "error" in r:
                print(f"{problem:28s} {planner:14s} error: {r['error']}")
                continue
            print(
                f"{problem:28s} {planner:14s} {r['samples']:8d} {1e3 * r['cold_s']:9.1f} "
                f"{1e3 * r['best_warm_s']:9.1f} {1e3 * r['median_warm_s']:9.1f} "
                f"{1e3 * r['cached_s']:9.2f} {1e3 * r['torque_s']:9.1f} {1e3 * r['own_s']:9.1f}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--planners", help=f"comma-separated names (default: {','.join(DEFAULT_PLANNERS)})"
    )
    parser.add_argument("--repeats", type=int, default=10, help="warm calls per plan")
    parser.add_argument("--rate", type=float, default=1000.0, help="evaluation rate, Hz")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    planners = planners_option(parser, args.planners)
    paths = sorted((ROOT / "problems").glob("*.toml"))

    load_before = os.getloadavg()
    warm = warm_up(paths[0])
    results: dict[str, dict[str, dict[str, Any]]] = {}
    for path in paths:
        rows = results.setdefault(path.stem, {})
        for planner in planners:
            progress(f"{path.stem}: {planner} ...")
            try:
                rows[planner] = measure(path, planner, args.repeats, args.rate)
            except Exception as error:  # a failing planner gets its row; the others still run
                message = str(error).splitlines()[0] if str(error) else ""
                rows[planner] = {"error": f"{type(error).__name__}: {message}"}
    load_after = os.getloadavg()

    print("warm-up " + ", ".join(f"{what} {s:.3g} s" for what, s in warm.items()))
    print_table(results)
    print(
        f"(best, median: of {args.repeats} calls after the cold one, each on a fresh copy of "
        f"the plan; grid at {args.rate:g} Hz)"
    )
    print(
        f"load average (1/5/15 min) {' '.join(f'{v:.2f}' for v in load_before)} before, "
        f"{' '.join(f'{v:.2f}' for v in load_after)} after, on {os.cpu_count()} CPUs"
    )
    write_results(
        "evaluate",
        {
            "cpus": os.cpu_count(),
            "load_average_before": load_before,
            "load_average_after": load_after,
            "spm_opt": so.__version__,
            "rate_hz": args.rate,
            "repeats": args.repeats,
            "warm_up_s": warm,
            "results": results,
        },
    )


if __name__ == "__main__":
    main()
