"""IPOPT against FATROP on the minimum-time problem of the paper's flap, from the same guess.

Prints a table and writes benchmarks/results/ocp_solvers.json.

    python benchmarks/ocp_solvers.py [--repeats R] [--problem PATH]

FATROP (shipped in CasADi's wheel) factorises stage by stage, so its NLP must be stage-wise:
variables x0, u0, x1, u1, …, each stage's rows reading only its own x and u. The phase
durations, which ``ocp-min-time`` keeps as D global variables, become states carried from
stage to stage (T_{k+1} = T_k), and the segment-duration rows stage-0 rows. Both solvers
are timed on that stage-wise NLP, built here from the planner's own interval function,
bounds and guess (the toppra plan), and IPOPT also on the planner's NLP (global durations),
the stage-wise ones interpreted (``expand``), the planner's on its compiled interval
functions as it plans. Rows: the median solve wall time over ``--repeats``, the
time in the NLP's functions, iterations, status and the total duration found.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from statistics import median
from typing import Any

import casadi as ca
import numpy as np
from timing import ROOT, write_results

import spm_opt as so
from spm_opt.judge.limits import planner_bounds
from spm_opt.model.joint_torque import range_key
from spm_opt.planners.ocp import ipopt, nlp_library
from spm_opt.planners.ocp.bounds import nlp_bounds
from spm_opt.planners.ocp.diagnostics import interval_rows
from spm_opt.planners.ocp.guess import initial_guess
from spm_opt.planners.ocp.nlp import build_nlp
from spm_opt.planners.ocp.parameters import arcs, nlp_parameters
from spm_opt.planners.ocp.transcription import STATE, default_fractions, interval_function


def stagewise(
    problem: so.Problem,
    nlp: Any,
    box: dict,
    x0: np.ndarray,
    fractions: np.ndarray,
    weights: list[float],
    scales: np.ndarray,
) -> tuple[dict, dict, list[bool]]:
    """The minimum-time NLP stage by stage: (problem, bounds and guess, equality flags)."""
    grid = nlp.grid
    m, d, segments = grid.intervals, 3 * grid.segments, grid.segments
    interval = interval_function(nlp.checks, False, None, 0)
    segment_arcs, dynamics = arcs(problem), np.zeros(0)  # no torque rows: no robot input
    states0, jerks0, durations0 = grid.split(x0)
    states_low, jerks_low, durations_low = grid.split(box["lbx"])
    states_high, jerks_high, durations_high = grid.split(box["ubx"])
    rows_low = interval_rows(nlp, box["lbg"])[:, STATE:]
    rows_high = interval_rows(nlp, box["ubg"])[:, STATE:]
    phases = grid.phase_of_interval
    x = [ca.MX.sym(f"x{k}", STATE + d) for k in range(m + 1)]
    u = [ca.MX.sym(f"u{k}", 2) for k in range(m)]
    g, lbg, ubg, equality = [], [], [], []
    objective = ca.sum1(x[0][STATE:]) * weights[0] / scales[0]
    for k in range(m):
        state, durations = x[k][:STATE], x[k][STATE:]
        phase = int(phases[k])
        h = durations[phase] / grid.counts[phase % 3]
        end, rows, integrals = interval(
            state, u[k], h, segment_arcs[grid.interval_segments[k]], fractions[:, k], dynamics
        )
        g.append(x[k + 1] - ca.vertcat(end, durations))
        lbg += [0.0] * (STATE + d)
        ubg += [0.0] * (STATE + d)
        equality += [True] * (STATE + d)
        if k == 0:
            g.append(ca.DM(grid.segment_matrix) @ durations)
            lbg += list(box["lbg"][-segments - 1 : -1])
            ubg += list(box["ubg"][-segments - 1 : -1])
            equality += [False] * segments
        g.append(rows)
        lbg += list(rows_low[k])
        ubg += list(rows_high[k])
        equality += [False] * rows.numel()
        objective += weights[2] * integrals[0] / scales[2]
    variables, lbx, ubx, guess = [], [], [], []
    for k in range(m + 1):
        variables.append(x[k])
        lbx += [*states_low[k], *durations_low]
        ubx += [*states_high[k], *durations_high]
        guess += [*states0[k], *durations0]
        if k < m:
            variables.append(u[k])
            lbx += list(jerks_low[k])
            ubx += list(jerks_high[k])
            guess += list(jerks0[k])
    form = {"x": ca.vertcat(*variables), "f": objective, "g": ca.vertcat(*g)}
    data = {"x0": guess, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
    return form, data, equality


FATROP_OPTIONS = {
    "defaults": {},
    "mu_init 1e-4, bound_push 1e-6": {"mu_init": 1e-4, "bound_push": 1e-6},
}
"""FATROP's options tried: its barrier is monotone, so a start near the optimum wants a
small initial barrier and little push off the bounds."""


def time_solver(
    label: str, solver: ca.Function, data: dict, repeats: int, total: Any
) -> dict[str, Any]:
    walls, stats, solution = [], {}, None
    for _ in range(repeats):
        started = time.perf_counter()
        solution = solver(**data)
        walls.append(time.perf_counter() - started)
        stats = solver.stats()
    return {
        "solver": label,
        "median_solve_s": median(walls),
        "function_s": sum(v for k, v in stats.items() if k.startswith("t_wall_nlp")),
        "iterations": int(stats.get("iter_count", -1)),
        "status": str(stats.get("return_status")),
        "duration_s": float(total(solution["x"])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--problem", type=Path, default=ROOT / "problems/craniotomy_bone_flap.toml")
    args = parser.parse_args()
    problem = so.load_problem(args.problem)
    planner = so.PLANNERS["ocp-min-time"]
    settings = planner.settings(problem)
    joint_range = range_key(problem.robot.joint_range)
    nlp = build_nlp(len(problem.segment_durations), settings, False, joint_range, frozenset())
    grid = nlp.grid
    start = so.plan(problem, "toppra")
    x0 = initial_guess(problem, grid, np.diff(start.metadata["landmark_times_s"]), start)
    fractions = np.tile(default_fractions(nlp.checks)[:, None], grid.intervals)
    weights = [settings.time_weight, settings.energy_weight, settings.jerk_weight]
    terms = nlp.terms(x0, nlp_parameters(problem, fractions, weights, np.ones(3), False))
    scales = np.maximum(np.abs([float(v) for v in terms]), 1e-9)
    box = nlp_bounds(
        problem, nlp, planner_bounds(problem, settings.margin), "free", grid.split(x0)[2]
    )
    ipopt_options = {
        "print_level": 0,
        "sb": "yes",
        "mu_strategy": "adaptive",
        "tol": settings.tolerance,
    }
    global_form = ipopt.solver(
        len(problem.segment_durations), settings, False, joint_range, frozenset(), warm=False
    )
    nlp_library.wait_for_builds()
    parameters = nlp_parameters(problem, fractions, weights, scales, False)
    d = 3 * grid.segments
    results = [
        time_solver(
            "IPOPT, the planner's NLP (global durations)",
            global_form,
            {"x0": x0, "p": parameters, **box},
            args.repeats,
            lambda x: np.sum(grid.split(x.full().ravel())[2]),
        )
    ]
    form, data, equality = stagewise(problem, nlp, box, x0, fractions, weights, scales)
    carried = lambda x: np.sum(x.full().ravel()[STATE : STATE + d])  # noqa: E731
    base = {"expand": True, "print_time": False}
    results.append(
        time_solver(
            "IPOPT, stage-wise NLP",
            ca.nlpsol("s", "ipopt", form, {**base, "ipopt": ipopt_options}),
            data,
            args.repeats,
            carried,
        )
    )
    for label, own in FATROP_OPTIONS.items():
        fatrop = {
            **base,
            "structure_detection": "auto",
            "equality": equality,
            "fatrop": {"print_level": 0, "tol": settings.tolerance, "max_iter": 1000, **own},
        }
        results.append(
            time_solver(
                f"FATROP, stage-wise NLP, {label}",
                ca.nlpsol("s", "fatrop", form, fatrop),
                data,
                args.repeats,
                carried,
            )
        )
    print(
        f"{'solver':46s} {'median s':>9s} {'f-eval s':>9s} {'iters':>6s} "
        f"{'duration s':>10s}  status"
    )
    for r in results:
        print(
            f"{r['solver']:46s} {r['median_solve_s']:9.3f} {r['function_s']:9.3f} "
            f"{r['iterations']:6d} {r['duration_s']:10.4f}  {r['status']}"
        )
    write_results("ocp_solvers", {"problem": str(args.problem), "results": results})


if __name__ == "__main__":
    main()
