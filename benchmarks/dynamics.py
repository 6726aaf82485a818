"""Throughput of the inverse dynamics, measured in one run.

Prints a table and writes benchmarks/results/dynamics.json. The reference is the naive use
of the same function: ``spm_opt.inverse_dynamics`` called once per sample. Rows: the
batched call (compiled C over all cores, then on one thread), CasADi's interpreter on the
same expressions, and the second derivation (minimal coordinates, interpreter).

    python benchmarks/dynamics.py [--samples N] [--repeats R]
"""

from __future__ import annotations

import argparse
import ctypes
import ctypes.util

import numpy as np
from timing import ROOT, throughput_table

import spm_opt as so
from spm_opt.model import dynamics
from spm_opt.verify.minimal_coordinates import minimal_inverse_dynamics


def one_thread(work):
    """``work`` run with OpenMP limited to one thread (no-op without OpenMP)."""
    name = ctypes.util.find_library("gomp")
    if name is None:
        return work
    omp = ctypes.CDLL(name)

    def limited() -> None:
        threads = omp.omp_get_max_threads()
        omp.omp_set_num_threads(1)
        try:
            work()
        finally:
            omp.omp_set_num_threads(threads)

    return limited


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    robot = so.load_problem(ROOT / "problems" / "craniotomy_bone_flap.toml").robot
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.0, 1.0, size=(args.samples, 2))
    qd, qdd = rng.normal(size=(2, args.samples, 2))
    parameters = dynamics.parameter_vector(robot)
    interpreter = dynamics._model().torque
    per_sample = min(args.samples, 2_000)

    so.inverse_dynamics(robot, q[:1], qd[:1], qdd[:1])  # compile (or load the cached library)
    rows = {
        "inverse_dynamics, batched (compiled C)": (
            args.samples,
            lambda: so.inverse_dynamics(robot, q, qd, qdd),
        ),
        "inverse_dynamics, batched, one thread": (
            args.samples,
            one_thread(lambda: so.inverse_dynamics(robot, q, qd, qdd)),
        ),
        "CasADi interpreter, batched": (
            args.samples,
            lambda: interpreter(q.T, qd.T, qdd.T, parameters),
        ),
        "minimal coordinates, batched (interpreter)": (
            min(args.samples, 20_000),
            lambda: minimal_inverse_dynamics(robot, q[:20_000], qd[:20_000], qdd[:20_000]),
        ),
        "inverse_dynamics, once per sample": (
            per_sample,
            lambda: [so.inverse_dynamics(robot, q[k], qd[k], qdd[k]) for k in range(per_sample)],
        ),
    }
    throughput_table("dynamics", rows, "inverse_dynamics, once per sample", args.repeats)


if __name__ == "__main__":
    main()
