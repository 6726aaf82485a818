"""How long the identification's steps take: the excitation plan, the run on the simulated
robot, and `spm-opt identify`'s fit of its log, against the regressor over the same log.

    python benchmarks/identification.py [--seconds 40] [--repeats 3]

Plans an excitation of ``--seconds`` on problems/identification.toml (its other settings
kept), runs it on the simulated robot (plant prototype_plant.toml, 500 Hz), then times, best
of ``--repeats``: reading and filtering the log (``log_samples``), evaluating the regressor
over its samples (the compiled batch path), and the whole fit (``identify``: gear
efficiency search, weighted least squares, the robot file's bounded solve). Prints a table
and writes benchmarks/results/identification.json.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from timing import ROOT, best_of, write_results

import spm_opt as so
from spm_opt.execution import ExecutionSettings, SimulatedRobot, execute
from spm_opt.identify.estimate import identify
from spm_opt.identify.samples import log_samples
from spm_opt.model.params import load_robot
from spm_opt.model.regressor import regressor
from spm_opt.planners.excitation import with_length

PROBLEM = ROOT / "problems" / "identification.toml"
PLANT = ROOT / "problems" / "robots" / "prototype_plant.toml"
SETTINGS = (2.0, None, 0.02)
"""`spm-opt identify`'s defaults: cutoff (Hz), decimation, smallest joint rate (rad/s)."""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=40.0, help="excitation length, s")
    parser.add_argument("--repeats", type=int, default=3, help="runs per fit step, best kept")
    args = parser.parse_args()
    problem = with_length(so.load_problem(PROBLEM), args.seconds)

    started = time.perf_counter()
    trajectory = so.plan(problem, "excitation")
    plan_s = time.perf_counter() - started
    statistics = trajectory.metadata["statistics"]
    print(f"excitation planned in {plan_s:.1f} s", file=sys.stderr)
    with tempfile.TemporaryDirectory() as folder:
        log = Path(folder) / "excitation.csv"
        robot = SimulatedRobot(
            problem.robot, start_rad=trajectory.position(0.0), plant_robot=load_robot(PLANT)
        )
        started = time.perf_counter()
        execute(trajectory, robot, problem, log, ExecutionSettings(rate_hz=500.0))
        run_s = time.perf_counter() - started
        samples = log_samples([log], *SETTINGS)
        steps = {
            "log_samples": lambda: log_samples([log], *SETTINGS),
            "regressor over the log": lambda: regressor(
                problem.robot, samples.q, samples.qd, samples.qdd
            ),
            "identify": lambda: identify(problem.robot, samples),
        }
        fit = {name: best_of(args.repeats, work) for name, work in steps.items()}

    reference = fit["regressor over the log"]
    rows = {
        "excitation plan": plan_s,
        "run on the simulated robot": run_s,
        **fit,
    }
    print(f"{trajectory.duration:g} s of excitation, {len(samples.q)} log samples at 500 Hz")
    print(f"{'step':30s} {'s':>9s} {'ratio':>9s}")
    for name, seconds in rows.items():
        print(f"{name:30s} {seconds:9.3f} {seconds / reference:8.1f}x")
    print(
        f"(ratio: against 'regressor over the log', measured in the same run; plan: "
        f"{statistics['iterations']} iterations, {statistics['return_status']}, condition "
        f"number {statistics['condition_number']:.3g})"
    )
    write_results(
        "identification",
        {
            "excitation_s": trajectory.duration,
            "log_samples": len(samples.q),
            "plan_statistics": statistics,
            "seconds": rows,
            "reference": "regressor over the log",
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
