"""The executor's control loop: achieved rate and period error at 100, 250 and 500 Hz.

Runs a 6 s move (from the faster craniotomy plan's start to where that plan is after 6 s,
quintic, from rest to rest as the executor requires) through the real
``dynamixel-sdk`` against the emulator in a child process on a pseudo-terminal, and, as
the reference measured in the same run, through the simulated robot on the wall clock (the
same loop without serial I/O). Prints a table and writes benchmarks/results/executor.json.

    python benchmarks/executor.py [--rates 100,250,500] [--seconds 6]

Period error: |actual period − nominal| of each cycle; overruns: periods over 1.5 nominal.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np
from timing import ROOT, write_results

import spm_opt as so
from spm_opt.execution import ExecutionSettings, SimulatedRobot, execute
from spm_opt.execution.dynamixel import DynamixelRobot
from spm_opt.execution.emulator import spawn_emulator

PROBLEM = ROOT / "problems" / "craniotomy_hardware.toml"


def _move(problem: so.Problem, trajectory: so.Trajectory, seconds: float) -> so.Trajectory:
    """A quintic move from rest at the trajectory's start to rest where it is after
    ``seconds``, sampled at 1 kHz, made for ``problem``."""
    t = np.linspace(0.0, seconds, int(seconds * 1000) + 1)
    tau = t / seconds
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    ds = (30 * tau**2 - 60 * tau**3 + 30 * tau**4) / seconds
    dds = (60 * tau - 180 * tau**2 + 120 * tau**3) / seconds**2
    start, end = trajectory.position([0.0, seconds])
    span = end - start
    return so.Trajectory.from_samples(
        t,
        start + s[:, None] * span,
        ds[:, None] * span,
        dds[:, None] * span,
        {"planner": "quintic", "problem": problem.record()},
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", default="100,250,500", help="loop rates, Hz")
    parser.add_argument("--seconds", type=float, default=6.0, help="length of the move, s")
    args = parser.parse_args()
    rates = [float(r) for r in args.rates.split(",")]

    problem = so.load_problem(PROBLEM)
    move = _move(problem, so.plan(problem, "cubic"), args.seconds)
    start = move.position(0.0)
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for rate in rates:
            settings = ExecutionSettings(rate_hz=rate)
            for backend_name in ("simulated (reference)", "dynamixel-sdk + emulator"):
                print(f"{backend_name} at {rate:g} Hz ...", file=sys.stderr)
                log = Path(scratch) / f"run_{rate:g}.csv"
                if backend_name.startswith("simulated"):
                    backend = SimulatedRobot(problem.robot, start_rad=start, realtime=True)
                    result = execute(move, backend, problem, log, settings)
                else:
                    with spawn_emulator(problem_file=PROBLEM, start_deg=np.degrees(start)) as em:
                        backend = DynamixelRobot(problem.robot.actuator, em.device)
                        result = execute(move, backend, problem, log, settings)
                rows.append(
                    {
                        "backend": backend_name,
                        "rate_hz": rate,
                        "completed": result.completed,
                        **dataclasses.asdict(result.statistics),
                    }
                )

    header = (
        f"{'backend':26s} {'rate Hz':>8s} {'achieved':>9s} {'p50 ms':>8s} {'p99 ms':>8s} "
        f"{'max ms':>8s} {'overruns':>8s} {'cycles':>7s}"
    )
    print(header)
    for r in rows:
        print(
            f"{r['backend']:26s} {r['rate_hz']:8g} {r['achieved_rate_hz']:9.2f} "
            f"{r['period_error_p50_ms']:8.3f} {r['period_error_p99_ms']:8.3f} "
            f"{r['period_error_max_ms']:8.3f} {r['overruns']:8d} {r['cycles']:7d}"
        )
    write_results("executor", {"move_s": args.seconds, "results": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
