"""Throughput of the kinematics and the evaluator, measured in one run.

Prints a table and writes benchmarks/results/kinematics.json. Ratios are against the
CasADi face of the same expressions, called once per sample, measured in the same run.

    python benchmarks/kinematics.py [--samples N] [--repeats R]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import casadi as ca
import numpy as np

import spm_opt as so
from spm_opt.model import kinematics

ROOT = Path(__file__).resolve().parents[1]


def best_of(repeats: int, work) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return min(times)


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

    results = {}
    for name, (count, work) in rows.items():
        seconds = best_of(args.repeats, work)
        results[name] = {"samples": count, "seconds": seconds, "samples_per_s": count / seconds}
    reference = results["forward (CasADi, per sample)"]["samples_per_s"]
    print(f"{'what':40s} {'samples':>9s} {'best s':>10s} {'samples/s':>12s} {'vs per-sample':>14s}")
    for name, r in results.items():
        ratio = r["samples_per_s"] / reference
        r["ratio_to_casadi_per_sample"] = ratio
        rate = r["samples_per_s"]
        print(f"{name:40s} {r['samples']:9d} {r['seconds']:10.4f} {rate:12.3g} {ratio:13.1f}x")
    out = ROOT / "benchmarks" / "results" / "kinematics.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps(
            {
                "machine": platform.platform(),
                "python": platform.python_version(),
                "results": results,
            },
            indent=2,
        )
        + "\n"
    )
    print(f"written {out.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
