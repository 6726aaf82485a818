"""The path-coordinate NLP's solvers: FATROP or IPOPT on the stage-wise NLP
(:mod:`~spm_opt.planners.ocp.path_assembly`), its functions compiled to C and cached on
disk (:mod:`~spm_opt.planners.ocp.nlp_library`): for IPOPT the interval's and the
landmark's functions, once per objective; for FATROP the whole NLP with its derivatives
(:mod:`~spm_opt.planners.ocp.path_oracle`), once per grid.

FATROP replaces IPOPT's sparse factorisation with a Riccati recursion along the stages. On
the paper's flap (minimum time, 595 variables, 2,270 rows), IPOPT took 23 iterations and
0.12 s, FATROP 33 iterations and 0.046 s (0.023 s of it in the functions), to the same
duration within 1 ms of 38 s; with both interpreted, 0.15 and 0.06 s. FATROP reads only
rows of one stage, so a fixed timing's time row (every stage's time summed) rules it out;
those plans use IPOPT. FATROP takes no multipliers: a re-solve from a solution uses IPOPT.
Over the random_flaps sweep's 200 flaps from scratch, FATROP converged on 199 (median 35
iterations, at most 150), and IPOPT, tried next, on the last.
"""

from __future__ import annotations

import hashlib
from functools import cache
from pathlib import Path

import casadi as ca

from spm_opt.planners.ocp import ipopt
from spm_opt.planners.ocp.nlp_library import Solver, nlp_solver
from spm_opt.planners.ocp.path_assembly import AssembledPathNlp, PathLayout, assemble
from spm_opt.planners.ocp.path_nlp import (
    INTERVAL_FUNCTIONS,
    LANDMARK_FUNCTIONS,
    interval_functions,
    landmark_functions,
)
from spm_opt.planners.ocp.path_oracle import NAMES, oracle_functions
from spm_opt.planners.ocp.settings import OcpSettings

FORMULATION_SOURCES = ("planners/ocp/path_nlp.py",)
"""The package's files whose code makes the compiled interval and landmark functions: a
change is a new library."""
ORACLE_SOURCES = (
    *FORMULATION_SOURCES,
    "planners/ocp/path_assembly.py",
    "planners/ocp/path_oracle.py",
    "planners/ocp/assembly.py",
)
"""Those whose code makes the compiled NLP for FATROP (:mod:`path_oracle`)."""


def time_rows(timing: str, segments: int) -> int:
    """The NLP's time rows for ``timing``: none when free, one per segment for "segments",
    else one (the total)."""
    return {"free": 0, "segments": segments}.get(timing, 1)


@cache
def assembled_nlp(
    segments: int, intervals: int, objectives: tuple[str, ...], timing: str
) -> tuple[PathLayout, AssembledPathNlp]:
    """The layout and the NLP (its functions in SX) for ``segments`` segments of
    ``intervals`` intervals, the weighted ``objectives`` and ``timing``'s rows."""
    layout = PathLayout(segments, intervals, time_rows(timing, segments))
    return layout, assemble(layout, interval_functions(objectives), landmark_functions())


ORDERING = {"mumps_pivot_order": 0}
"""MUMPS's fill-reducing ordering for IPOPT: AMD. MUMPS's own choice scaled worse than the
NLP with the landmark count: on regular flaps of 4 and 12 landmarks, minimum energy took
0.16 and 0.63 s a plan with it, 0.15 and 0.37 s with AMD (minimum jerk 0.44 and 1.27 s
against 0.28 and 0.90 s)."""
MONOTONE = {"mu_strategy": "monotone"}
"""IPOPT's options when its adaptive barrier stopped without converging: on the varied
sweep's flap 49, minimum jerk (fixed total time) took more than 300 iterations with the
adaptive barrier and 72 with the monotone one."""


FATROP, IPOPT, MONOTONE_IPOPT = "fatrop", "ipopt", "ipopt, monotone barrier"
"""The ways :func:`solver` solves: FATROP, IPOPT, and IPOPT with :data:`MONOTONE`."""


@cache
def solver(
    segments: int,
    intervals: int,
    settings: OcpSettings,
    objectives: tuple[str, ...],
    warm: bool,
    method: str,
) -> Solver:
    """``method`` (:data:`FATROP`, :data:`IPOPT` or :data:`MONOTONE_IPOPT`) on
    :func:`assembled_nlp`'s NLP; ``warm`` (IPOPT only): continuing from a solution and its
    multipliers."""
    layout, nlp = assembled_nlp(segments, intervals, objectives, settings.timing)
    if method == FATROP:
        return _fatrop(layout, nlp, settings, objectives)
    chosen = ipopt.options(settings, warm, acceptable_iterations=0)
    options = {
        "ipopt": {**chosen, **ORDERING, **(MONOTONE if method == MONOTONE_IPOPT else {})},
        "print_time": False,
        "calc_lam_p": False,
    }

    def parts(functions: list[ca.Function]) -> tuple[dict, dict]:
        count = len(INTERVAL_FUNCTIONS)
        assembled = assemble(layout, functions[:count], functions[count:])
        return assembled.problem, assembled.derivatives

    return nlp_solver(
        "path",
        "ipopt",
        formulation_key(objectives),
        (*INTERVAL_FUNCTIONS, *LANDMARK_FUNCTIONS),
        lambda: [*interval_functions(objectives), *landmark_functions()],
        parts,
        options,
        reversed_=(0, len(INTERVAL_FUNCTIONS)),
    )


def _fatrop(
    layout: PathLayout, nlp: AssembledPathNlp, settings: OcpSettings, objectives: tuple[str, ...]
) -> Solver:
    """FATROP on a call of the NLP compiled with its derivatives (:mod:`path_oracle`, one
    library per grid, cached on disk); until that library is there, on the NLP expanded to
    SX, with CasADi's derivatives, in CasADi's interpreter."""
    low, high = layout.row_bounds()
    options = {
        "structure_detection": "auto",
        "equality": (low == high).tolist(),
        "print_time": False,
        "calc_lam_p": False,
        "fatrop": {
            "tol": settings.tolerance,
            "max_iter": settings.max_iterations,
            "print_level": settings.print_level,
        },
    }

    def parts(functions: list[ca.Function]) -> tuple[dict, dict]:
        x, p = (ca.MX.sym(name, nlp.problem[name].numel()) for name in "xp")
        f, g = functions[0](x, p)
        return {"x": x, "p": p, "f": f, "g": g}, {}

    shape = (layout.segments, layout.intervals, settings.timing)
    return nlp_solver(
        "path",
        "fatrop",
        formulation_key(objectives, ORACLE_SOURCES, shape),
        NAMES,
        lambda: oracle_functions(nlp),
        parts,
        options,
        reversed_=(),
        interpreted=lambda: ca.nlpsol("path", "fatrop", nlp.problem, {**options, "expand": True}),
    )


@cache
def formulation_key(
    objectives: tuple[str, ...], sources: tuple[str, ...] = FORMULATION_SOURCES, shape: tuple = ()
) -> str:
    """What identifies the compiled functions without building them: the code that builds
    them (the package's ``sources``), the objectives they weigh and the grid's ``shape``
    (for functions of the whole NLP)."""
    package = Path(__file__).resolve().parents[2]
    digest = hashlib.sha256()
    for name in sources:
        digest.update((package / name).read_bytes())
    digest.update(repr((objectives, shape)).encode())
    return digest.hexdigest()
