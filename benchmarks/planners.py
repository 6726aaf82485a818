"""Solve time of every planner on one problem, beside the cubic baseline, in one run.

Prints a table (progress goes to stderr) and writes benchmarks/results/planners.json.

    python benchmarks/planners.py [--planners NAMES] [--skip NAMES] [--repeats R]
                                  [--problem PATH]

NAMES are comma-separated planner names (default: every registered planner). The cubic
baseline always runs, first: the ratios are against its median, measured in the same run.
``--skip ocp-min-energy`` leaves out the slowest planner (a few seconds a solve).

First, a warm-up timed on its own (printed above the table) pays for what the planners and
the evaluator share, so that no planner's cold call pays for it whatever the order: the
first ``load_problem`` (imports, robot file), the Lagrange dynamics model and the compiled
batch torque. Then, per planner, a freshly loaded problem and:

- construction s: for the optimal-control (ocp-*) planners, the NLP construction: the
  ``construction_time_s`` of the first plan after clearing the ocp package's caches
  (``nlp.interval``, ``nlp.symbolic_functions``, ``nlp.formulation_key``,
  ``nlp.build_nlp``, ``ipopt.solver``, ``refinement.probe``, and in path coordinates
  ``path_nlp.interval_functions``, ``path_nlp.landmark_functions``, ``path_solver.assembled_nlp``,
  ``path_solver.solver``, ``path_solver.formulation_key``): building the interval's
  functions, the NLP assembled from them and the solver (IPOPT or FATROP), and generating
  the C of the interval's functions (the compiler then runs in the background unless the
  library is already in the disk cache). The other planners build nothing ahead: for them it is the
  time of the ``load_problem`` of the fresh problem (the JSON has ``load_s`` for every
  planner).
- cached s (ocp-* only): the same construction once the compiled library is on disk (the
  in-process caches cleared again): what a second process or a sweep worker pays.
- first s: wall time of the first ``spm_opt.plan`` on the fresh problem (cold: with the
  construction above and the problem's lazily computed contour and inverse kinematics).
- median s: median wall time of ``--repeats`` further ``spm_opt.plan`` calls (warm).
- judge s: median wall time of ``spm_opt.judge.evaluate`` of a fresh ``copy.deepcopy`` of each
  warm plan (made outside the timing): the evaluator keeps each trajectory object's report,
  and a copy is judged anew (the JSON's ``judge_s`` has every call's).
- plan+judge s: median wall time of ``plan = spm_opt.plan(problem, name)`` then
  ``spm_opt.judge.evaluate(problem, plan)``, as a user runs them (the warm plans above, each
  judged after its plan's time was taken; ``plan_judge_s``): a planner that judged its own
  plan (the ocp-* planners do) leaves its report, and the second call only copies it.
- solver s: median of the statistics' ``solve_time_s`` (IPOPT's wall time for the ocp-*
  planners; the planner's own timing, or registry.plan's, for the others).
- f-eval s, iters (ocp-* only): median time IPOPT spent evaluating the NLP's functions and
  derivatives (``function_time_s``), and median IPOPT iterations.
- duration s, over bound: the plan's duration and ``duration_over_lower_bound``, from
  ``spm_opt.judge.evaluate`` of the cold plan, once, outside the timing.
- ratio: median s over the cubic's median s.

Under the table, for each ocp-* planner (its transcription, its solver and its NLP's size:
the KKT system's variables and constraint rows), the median plan wall time is split into
function evaluation, the solver's own work (IPOPT's or FATROP's: solve − function
evaluation: linear algebra, line search) and Python around the solve (wall − solve:
initial guess, bounds, constraint report, torque check, trajectory, registry). When an
ocp-* planner without an energy term has to solve again with the torque limit, its solve
time and iterations add both solves but its construction and function-evaluation times
are the second's only; the row is marked.
A planner that raises gets a row with its error; the others still run.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from pathlib import Path
from statistics import median
from typing import Any

import casadi as ca
from timing import ROOT, warm_up, write_results

import spm_opt as so
from spm_opt.planners.ocp import ipopt, nlp, nlp_library, path_nlp, path_solver, refinement
from spm_opt.planners.ocp.planner import OcpPlanner

REFERENCE = "cubic"


def progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def names_option(parser: argparse.ArgumentParser, text: str | None) -> list[str]:
    """The comma-separated planner names in ``text``, refusing unknown ones."""
    if not text:
        return []
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in so.PLANNERS]
    if unknown:
        parser.error(
            f"unknown planner(s) {', '.join(unknown)}; expected some of {', '.join(so.PLANNERS)}"
        )
    return names


def clear_ocp_caches() -> None:
    for cached in (
        nlp.interval,
        nlp.symbolic_functions,
        nlp.formulation_key,
        nlp.build_nlp,
        ipopt.solver,
        refinement.probe,
        path_nlp.interval_functions,
        path_nlp.landmark_functions,
        path_solver.assembled_nlp,
        path_solver.solver,
        path_solver.formulation_key,
    ):
        cached.cache_clear()


def measure(name: str, path: Path, repeats: int, phase: list[str]) -> dict[str, Any]:
    """Time one planner (see the module docstring); raises what the planner raises, with
    ``phase`` (one item) naming the step that was under way."""
    phase[:] = ["load"]
    is_ocp = isinstance(so.PLANNERS[name], OcpPlanner)
    if is_ocp:
        clear_ocp_caches()
    started = time.perf_counter()
    problem = so.load_problem(path)
    load = time.perf_counter() - started
    phase[:] = ["cold plan"]
    progress(f"{name}: cold plan ...")
    started = time.perf_counter()
    trajectory = so.plan(problem, name)
    first = time.perf_counter() - started
    cold = trajectory.metadata["statistics"]
    progress(f"{name}: cold plan {first:.4g} s")
    cached_load = None
    if is_ocp:  # the NLP's library, compiled in the background, loaded from disk
        nlp_library.wait_for_builds()
        clear_ocp_caches()
        phase[:] = ["plan from the disk cache"]
        cached_load = so.plan(problem, name).metadata["statistics"]["construction_time_s"]
    walls, judged, judges, runs = [], [], [], []
    for k in range(repeats):
        phase[:] = [f"warm plan {k + 1}"]
        started = time.perf_counter()
        again = so.plan(problem, name)
        walls.append(time.perf_counter() - started)
        so.evaluate(problem, again)
        judged.append(time.perf_counter() - started)
        runs.append(again.metadata["statistics"])
        phase[:] = [f"judge {k + 1}"]
        judges.append(judge_time(problem, again))
        progress(f"{name}: warm plan {k + 1}/{repeats} {walls[-1]:.4g} s, judge {judges[-1]:.4g} s")
    phase[:] = ["evaluate"]
    report = so.evaluate(problem, trajectory)
    solves = [float(s["solve_time_s"]) for s in runs]
    result: dict[str, Any] = {
        "ocp": is_ocp,
        "load_s": load,
        "construction_s": cold["construction_time_s"] if is_ocp else load,
        "cached_construction_s": cached_load,
        "first_plan_s": first,
        "plan_s": walls,
        "median_plan_s": median(walls) if walls else None,
        "judge_s": judges,
        "median_judge_s": median(judges) if judges else None,
        "plan_judge_s": judged,
        "median_plan_judge_s": median(judged) if judged else None,
        "solve_s": solves,
        "median_solve_s": median(solves) if solves else None,
        "duration_s": trajectory.duration,
        "duration_over_lower_bound": report.duration_over_lower_bound,
    }
    if is_ocp:
        functions = [float(s["function_time_s"]) for s in runs]
        iterations = [int(s["iterations"]) for s in runs]
        own = [solve - function for solve, function in zip(solves, functions, strict=True)]
        around = [wall - solve for wall, solve in zip(walls, solves, strict=True)]
        resolved = any(
            s.get("torque_in_nlp", False) and s["settings"]["energy_weight"] == 0.0
            for s in [cold, *runs]
        )
        result.update(
            function_s=functions,
            median_function_s=median(functions) if runs else None,
            iterations=iterations,
            median_iterations=median(iterations) if runs else None,
            median_ipopt_own_s=median(own) if runs else None,
            median_around_solve_s=median(around) if runs else None,
            cold_solve_s=float(cold["solve_time_s"]),
            cold_function_s=float(cold["function_time_s"]),
            cold_iterations=int(cold["iterations"]),
            torque_resolve=resolved,
            transcription=cold.get("transcription"),
            solver=cold.get("solver", "ipopt"),
            variables=cold.get("variables"),
            rows=cold.get("rows"),
        )
    return result


def judge_time(problem: so.Problem, trajectory: so.Trajectory) -> float:
    """Wall time, s, of ``spm_opt.judge.evaluate`` of a fresh copy of ``trajectory`` (its report
    not yet kept)."""
    fresh = copy.deepcopy(trajectory)
    started = time.perf_counter()
    so.evaluate(problem, fresh)
    return time.perf_counter() - started


def number(value: float | None, width: int = 9) -> str:
    return f"{'-':>{width}s}" if value is None else f"{value:{width}.4g}"


def print_table(results: dict[str, dict[str, Any]]) -> None:
    print(
        f"{'planner':16s} {'constr s':>9s} {'cached s':>9s} {'first s':>9s} {'median s':>9s} "
        f"{'judge s':>9s} {'plan+judge s':>12s} {'solver s':>9s} {'f-eval s':>9s} "
        f"{'iters':>6s} {'duration s':>10s} {'over bound':>10s} {'ratio':>9s}"
    )
    for name, r in results.items():
        if "error" in r:
            print(f"{name:16s} error ({r['phase']}): {r['error']}")
            continue
        iterations = r.get("median_iterations")
        ratio = r.get("ratio_to_cubic")
        label = name + (" *" if r.get("torque_resolve") else "")
        print(
            f"{label:16s} {number(r['construction_s'])} {number(r.get('cached_construction_s'))} "
            f"{number(r['first_plan_s'])} "
            f"{number(r['median_plan_s'])} {number(r['median_judge_s'])} "
            f"{number(r['median_plan_judge_s'], 12)} {number(r['median_solve_s'])} "
            f"{number(r.get('median_function_s'))} "
            f"{'-' if iterations is None else f'{iterations:g}':>6s} "
            f"{number(r['duration_s'], 10)} {number(r['duration_over_lower_bound'], 10)} "
            f"{'-' if ratio is None else f'{ratio:.1f}x':>9s}"
        )


def print_breakdown(results: dict[str, dict[str, Any]]) -> None:
    for name, r in results.items():
        if not r.get("ocp") or "error" in r or r["median_plan_s"] is None:
            continue
        wall = r["median_plan_s"]
        parts = (
            ("function evaluation", r["median_function_s"]),
            (f"{r['solver']}'s own", r["median_ipopt_own_s"]),
            ("Python around the solve", r["median_around_solve_s"]),
        )
        shares = ", ".join(f"{what} {s:.3g} s ({100 * s / wall:.0f} %)" for what, s in parts)
        size = f"{r['variables']} variables, {r['rows']} rows" if r.get("rows") else "size -"
        solved = f"{r.get('transcription')}, {r['solver']}; {size}"
        print(f"{name} ({solved}) median wall {wall:.3g} s: {shares}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--planners", help="comma-separated names (default: all registered)")
    parser.add_argument("--skip", help="comma-separated names to leave out")
    parser.add_argument("--repeats", type=int, default=5, help="warm solves per planner")
    parser.add_argument(
        "--problem", type=Path, default=ROOT / "problems" / "craniotomy_bone_flap.toml"
    )
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    chosen = names_option(parser, args.planners) or so.planners.contour_planners()
    skipped = names_option(parser, args.skip)
    if REFERENCE in skipped:
        parser.error(f"{REFERENCE} is the reference of the ratios; it always runs")
    names = [REFERENCE] + [n for n in dict.fromkeys(chosen) if n not in skipped + [REFERENCE]]

    load_before = os.getloadavg()
    progress(f"warm-up, then {', '.join(names)} (1 cold + {args.repeats} warm plans each)")
    warm = warm_up(args.problem)
    results: dict[str, dict[str, Any]] = {}
    for k, name in enumerate(names, 1):
        progress(f"[{k}/{len(names)}] {name}")
        phase = ["start"]
        try:
            results[name] = measure(name, args.problem, args.repeats, phase)
        except Exception as error:  # a failing planner gets its row; the others still run
            message = str(error).splitlines()[0] if str(error) else ""
            results[name] = {"error": f"{type(error).__name__}: {message}", "phase": phase[0]}
            progress(f"{name}: {results[name]['error']}")
    load_after = os.getloadavg()

    reference = results[REFERENCE].get("median_plan_s")
    for r in results.values():
        if "error" not in r and reference:
            r["ratio_to_cubic"] = r["median_plan_s"] / reference

    try:
        problem_name = str(args.problem.resolve().relative_to(ROOT))
    except ValueError:
        problem_name = str(args.problem)
    print(
        f"problem {problem_name}; warm-up "
        + ", ".join(f"{what} {s:.3g} s" for what, s in warm.items())
    )
    print_table(results)
    print(
        f"(median of {args.repeats} warm plans; ratio: median against '{REFERENCE}', "
        "measured in the same run)"
    )
    if any(r.get("torque_resolve") for r in results.values()):
        print("* solved again with the torque limit: constr s and f-eval s are the second NLP's")
    print_breakdown(results)
    print(
        f"load average (1/5/15 min) {' '.join(f'{v:.2f}' for v in load_before)} before, "
        f"{' '.join(f'{v:.2f}' for v in load_after)} after, on {os.cpu_count()} CPUs"
    )
    write_results(
        "planners",
        {
            "cpus": os.cpu_count(),
            "load_average_before": load_before,
            "load_average_after": load_after,
            "casadi": ca.__version__,
            "spm_opt": so.__version__,
            "problem": problem_name,
            "repeats": args.repeats,
            "warm_up_s": warm,
            "reference": REFERENCE,
            "results": results,
        },
    )


if __name__ == "__main__":
    main()
