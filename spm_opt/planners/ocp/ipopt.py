"""IPOPT on the optimal-control NLP: its options, the solver (cached per NLP), and what
continuing from a solution takes.

IPOPT (MUMPS) with an adaptive barrier, never falling back to the monotone mode (when it
was chosen, minimum time took 44, 40 and 50 iterations on the paper's, the five-landmark
and the large flaps against 63, 202 and 212 with IPOPT's default globalisation). Its
derivatives are the interval's compiled functions scattered into the NLP's sparse matrices
(:mod:`~spm_opt.planners.ocp.assembly`, :mod:`~spm_opt.planners.ocp.nlp_library`).
Starting the bound multipliers from a small barrier (``bound_mult_init_method`` mu-based,
``mu_init`` 1e-5–1e-3) was tried on 15 flaps from toppra's start: the median stayed at
41–52 iterations, better on some flaps and worse on others, so IPOPT's default start stays.

FATROP (CasADi's structure-exploiting interior-point solver), measured on the same
minimum-time problem made stage-wise (the phase durations carried as states; ``python
benchmarks/ocp_solvers.py``, interpreted, idle 2-core machine): with its defaults it
stopped after 972 iterations without converging; with a small initial barrier and bound
push (its barrier is monotone) it took 276 iterations and 1.8 s, against IPOPT's 40
iterations and 0.13 s on this package's NLP (IPOPT on the stage-wise NLP: 405 and 3.8 s).
IPOPT stays for the time domain: the stage-wise form costs IPOPT ten times the
iterations, and FATROP needs more still. In path coordinates, with no free durations,
FATROP does pay (:mod:`~spm_opt.planners.ocp.path_solver`).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.planners.ocp.assembly import HESSIAN, JACOBIAN, VALUE
from spm_opt.planners.ocp.nlp import build_nlp, formulation_key, symbolic_functions
from spm_opt.planners.ocp.nlp_library import Solver, nlp_solver
from spm_opt.planners.ocp.settings import OcpSettings

CONVERGED = "Solve_Succeeded"
"""The only IPOPT status that makes a plan."""
ACCEPTABLE = "Solved_To_Acceptable_Level"
"""IPOPT's early stop at its looser acceptable level (constraints within 1e-2 in their own
units: wider than the contour tube in mm²), which CasADi counts as a success."""
WARM_START = {
    "warm_start_init_point": "yes",
    "mu_init": 1e-6,
    "warm_start_bound_push": 1e-9,
    "warm_start_mult_bound_push": 1e-9,
}
"""IPOPT's options to continue from a solution and its multipliers (the strict re-solve)."""


def options(settings: OcpSettings, warm: bool, acceptable_iterations: int) -> dict[str, Any]:
    """IPOPT's options: ``settings``' limits, the adaptive barrier, and with ``warm`` those
    that continue from a solution and its multipliers."""
    return {
        "max_iter": settings.max_iterations,
        "tol": settings.tolerance,
        "print_level": settings.print_level,
        "sb": "yes",
        "mu_strategy": "adaptive",
        "adaptive_mu_globalization": "never-monotone-mode",
        "acceptable_iter": acceptable_iterations,
        **(WARM_START if warm else {}),
    }


@cache
def solver(
    segments: int,
    settings: OcpSettings,
    with_torque: bool,
    joint_range: bytes,
    demanded: frozenset[str],
    warm: bool,
) -> Solver:
    """IPOPT on :func:`~spm_opt.planners.ocp.nlp.build_nlp`'s problem, its derivatives
    assembled from the interval's compiled functions; ``warm``: continuing from a solution
    and its multipliers, strictly (never stopping at the acceptable level)."""
    chosen = options(settings, warm, 0 if warm else settings.acceptable_iterations)
    solver_options = {"ipopt": chosen, "print_time": False, "calc_lam_p": False}
    checks = settings.checks_per_interval
    nlp = build_nlp(segments, settings, with_torque, joint_range, demanded)

    def solver_parts(functions: list[ca.Function]) -> tuple[dict, dict]:
        assembled = nlp.assemble(functions)
        return assembled.problem, assembled.derivatives

    return nlp_solver(
        "ocp",
        "ipopt",
        formulation_key(checks, with_torque, joint_range, demanded),
        (VALUE, JACOBIAN, HESSIAN),
        lambda: symbolic_functions(checks, with_torque, joint_range, demanded),
        solver_parts,
        solver_options,
    )


def continuation(solution: dict[str, ca.DM]) -> dict[str, np.ndarray]:
    """IPOPT's warm start from a solution: its x and multipliers."""
    return {
        name: solution[key].full().ravel()
        for name, key in (("x0", "x"), ("lam_x0", "lam_x"), ("lam_g0", "lam_g"))
    }
