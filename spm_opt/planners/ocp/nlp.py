"""The optimal-control NLP, built once per process for each shape: one interval's function
(:func:`~spm_opt.planners.ocp.transcription.interval_function`, every constraint row of
:data:`~spm_opt.planners.ocp.constraints.LIMITS`) mapped over the grid and assembled with
its derivatives (:mod:`~spm_opt.planners.ocp.assembly`); joint range, acceleration and
jerk are bounds on the nodes and controls (:mod:`~spm_opt.planners.ocp.bounds`).

The NLP is built once per (segments, settings that shape it, torque rows, joint range,
on-demand rows) with every problem-dependent number (arcs, check places, robot, weights)
as a parameter, so a second problem of the same shape reuses it. Its derivatives are one
interval's, compiled to C once per (check points, torque rows, joint range, on-demand
rows) (:mod:`~spm_opt.planners.ocp.nlp_library`, keyed by :func:`formulation_key`); the
torque model is the B-spline table of :mod:`spm_opt.model.torque_table` (the robot an NLP
parameter, :mod:`spm_opt.model.joint_torque`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import casadi as ca
import numpy as np

from spm_opt.model import torque_table
from spm_opt.model.joint_torque import DRIVE_ENTRIES, load_torque
from spm_opt.planners.ocp.assembly import AssembledNlp, assemble, interval_functions
from spm_opt.planners.ocp.point import ARC_PARAMETERS
from spm_opt.planners.ocp.settings import OcpSettings
from spm_opt.planners.ocp.transcription import (
    STATE,
    Grid,
    RowGroup,
    interval_function,
    row_groups,
)


@dataclass(frozen=True)
class Nlp:
    """A built NLP: its CasADi form, the objective's terms, and the shapes to read it by."""

    problem: dict[str, ca.MX]  # x, p, f, g
    terms: ca.Function  # (x, p) -> total time (s), ∫τᵀτ dt (N²m²s), ∫jerk² dt (rad²/s⁵)
    grid: Grid
    groups: tuple[RowGroup, ...]
    checks: int
    n_dynamics: int

    @property
    def rows_per_interval(self) -> int:
        return STATE + sum(group.size for group in self.groups)

    def assemble(self, functions: list[ca.Function]) -> AssembledNlp:
        """This NLP from the interval's functions (SX or compiled)."""
        return assemble(self.grid, functions, ARC_PARAMETERS, self.checks, self.n_dynamics)


@cache
def interval(
    checks: int, with_torque: bool, joint_range: bytes, demanded: frozenset[str]
) -> ca.Function:
    """One interval's function (:func:`interval_function`) for robots of ``joint_range``,
    with the on-demand rows of the constraints ``demanded``."""
    if not with_torque:
        return interval_function(checks, False, None, 0, demanded)
    table = torque_table.torque_function(np.frombuffer(joint_range).reshape(2, 2))
    n_dynamics = table.size1_in(3) + DRIVE_ENTRIES
    return interval_function(checks, True, load_torque(joint_range), n_dynamics, demanded)


@cache
def symbolic_functions(
    checks: int, with_torque: bool, joint_range: bytes, demanded: frozenset[str]
) -> list[ca.Function]:
    """The interval's value, Jacobian and Hessian in SX (:func:`interval_functions`): what
    the library compiles."""
    return interval_functions(interval(checks, with_torque, joint_range, demanded))


@cache
def build_nlp(
    segments: int,
    settings: OcpSettings,
    with_torque: bool,
    joint_range: bytes,
    demanded: frozenset[str],
) -> Nlp:
    """The NLP for ``segments`` segments, with or without the dynamics (cached per
    process), assembled from one interval's functions (:mod:`~spm_opt.planners.ocp.assembly`).

    g holds, interval by interval, the continuity rows and the constraint rows of
    :func:`row_groups`, then the segment durations and the total duration; p holds every
    segment's arc, the check points' fractions, the dynamics parameters, the weights and
    the scales.
    """
    checks = settings.checks_per_interval
    function = interval(checks, with_torque, joint_range, demanded)
    grid = settings.grid(segments)
    groups, n_dynamics = row_groups(checks, with_torque, demanded), function.size1_in(5)
    assembled = assemble(
        grid,
        symbolic_functions(checks, with_torque, joint_range, demanded),
        ARC_PARAMETERS,
        checks,
        n_dynamics,
    )
    return Nlp(assembled.problem, assembled.terms, grid, groups, checks, n_dynamics)


FORMULATION_SOURCES = (
    "planners/ocp/nlp.py",
    "planners/ocp/assembly.py",
    "planners/ocp/transcription.py",
    "planners/ocp/constraints.py",
    "planners/ocp/point.py",
    "model/joint_torque.py",
    "skull/arc_fit.py",
    "model/kinematics.py",
    "model/dynamics.py",
    "model/torque_table.py",
    "model/params.py",
)
"""The package's files whose code makes the interval's functions: a change to any of them
is a new library."""


@cache
def formulation_key(
    checks: int, with_torque: bool, joint_range: bytes, demanded: frozenset[str]
) -> str:
    """What identifies :func:`interval`'s functions without building them: the code that
    builds them and the settings that shape them."""
    package = Path(__file__).resolve().parents[2]
    digest = hashlib.sha256()
    for name in FORMULATION_SOURCES:
        digest.update((package / name).read_bytes())
    digest.update(repr((checks, with_torque, sorted(demanded))).encode() + joint_range)
    return digest.hexdigest()
