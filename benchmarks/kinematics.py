"""Throughput of the kinematics and the evaluator, measured in one run.

Prints a table and writes benchmarks/results/kinematics.json. Ratios are against the
CasADi face of the same expressions, called once per sample, measured in the same run.

    python benchmarks/kinematics.py [--samples N] [--repeats R]
"""

from __future__ import annotations

import argparse

import casadi as ca
import numpy as np
from timing import ROOT, throughput_table

import spm_opt as so
from spm_opt.model import kinematics


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.0, 1.0, size=(args.samples, 2))
    qd = rng.uniform(-1.0, 1.0, size=(args.samples, 2))

    symbolic = kinematics.symbolic()
    direction = ca.Function("direction", [symbolic.q], [symbolic.direction])
    per_sample_count = min(args.samples, 5_000)
    mapped = direction.map(args.samples)

    rows = {
        "forward (numpy, vectorised)": (
            args.samples,
            lambda: kinematics.forward_kinematics(q, 0.17133),
        ),
        "jacobian (numpy, vectorised)": (
            args.samples,
            lambda: kinematics.platform_jacobian(q, 1.0),
        ),
        "angular velocities (numpy)": (
            args.samples,
            lambda: kinematics.platform_angular_velocities(q, qd),
        ),
        "forward (CasADi map)": (args.samples, lambda: mapped(q.T)),
        "forward (CasADi, per sample)": (
            per_sample_count,
            lambda: [direction(row) for row in q[:per_sample_count]],
        ),
    }
    problem = so.load_problem(ROOT / "problems" / "craniotomy_bone_flap.toml")
    baseline = so.plan(problem, "cubic")
    grid = len(baseline.time_grid(1000.0))
    rows["evaluate cubic baseline (1 kHz grid)"] = (grid, lambda: so.evaluate(problem, baseline))

    throughput_table("kinematics", rows, "forward (CasADi, per sample)", args.repeats)


if __name__ == "__main__":
    main()
