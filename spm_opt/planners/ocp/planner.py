"""Optimal-control planners: minimum time, energy or jerk through the landmarks, on the cut,
within the actuators' limits (CasADi + IPOPT).

Transcription (:mod:`spm_opt.planners.ocp_transcription`): each segment between consecutive
landmark visits is three phases (``corner_nodes``, ``nodes_per_phase``, ``corner_nodes``
uniform intervals) whose durations are variables (see ``timing``); the state (q, q̇, q̈) is
integrated exactly under a constant jerk on each interval, so the returned
:class:`Trajectory` reproduces the solution exactly. Landmarks are reached exactly at phase
boundaries; the motion starts and ends at rest. One interval's function, holding every
constraint of :data:`~spm_opt.planners.ocp_transcription.CONSTRAINTS` (tool speed, contour
tube and the segment's ends at the node and at ``checks_per_interval`` check points, the
cut's progress along its arc never negative at the node, and at the check points once the
evaluator finds the cut running back between nodes, the joint speed exactly through q̇'s
Bernstein coefficients, the load torque at the two Gauss points), is mapped over the grid; joint
range, acceleration and jerk are bounds on the nodes and controls. Each limit keeps a
reserve of ``margin``; the acceleration and jerk bounds also keep a feed hold its room
(:func:`~spm_opt.limits.planner_bounds`, :mod:`spm_opt.hold_room`).

Every plan clean, by construction: after each solve the evaluator re-measures the plan; if
it finds a limit exceeded, each interval where the solution exceeds a bound between its
check points gets its nearest check point moved there (the check points' places are NLP
parameters: the same NLP, continued from the solution and its multipliers; a cut found
outside the tube there counts as the cause of the contour it left uncut), a limit with
on-demand rows (backtracking) gets them at the check points (a new NLP, solved from x),
and any other limit the evaluator finds exceeded gets its bound tightened by the excess;
up to :data:`REFINEMENTS` rounds, then a planning error.

Objectives: total time (``ocp-min-time``); ∫ τᵀτ dt (``ocp-min-energy``; with a linear
current map this is proportional to the copper losses ∫ I²R dt); ∫ jerkᵀjerk dt
(``ocp-min-jerk``); or a weighted mix (``ocp-mix``). Minimum time and the mix leave the
durations free; minimum energy keeps the problem's total duration as a maximum
("bounded": gravity holding dominates this robot's torques, so a shorter cut can cost less
effort); minimum jerk keeps the total ("total"; "segments" keeps every segment's).

Starts: ``ocp-min-time`` starts from toppra's time-optimal parameterisation of the contour
(:func:`~spm_opt.planners.toppra.time_optimal_guess`, ~10 ms), and from the contour-following
guess if IPOPT fails from there; the others start from the minimum-time plan re-timed to
their durations. On the paper's flap the near-optimal start finds 37.87 s (toppra 38.06 s)
where the contour-following one found 38.09 s.

Solver: IPOPT (MUMPS) with an adaptive barrier, never falling back to the monotone mode
(when it was chosen, minimum time took 44, 40 and 50 iterations on the paper's, the
five-landmark and the large flaps against 63, 202 and 212 with IPOPT's default
globalisation). Its derivatives are one interval's, compiled to C once per (check points,
torque rows, joint range) and scattered into the NLP's sparse matrices
(:mod:`ocp_assembly`, :mod:`nlp_library`); the torque model is the B-spline table of
:mod:`spm_opt.model.torque_table` (the robot an NLP parameter). Starting the bound
multipliers from a small barrier (``bound_mult_init_method`` mu-based, ``mu_init``
1e-5–1e-3) was tried on 15 flaps from toppra's start: the median stayed at 41–52
iterations, better on some flaps and worse on others, so IPOPT's default start stays.

FATROP (CasADi's structure-exploiting interior-point solver), measured on the same
minimum-time problem made stage-wise (the phase durations carried as states; ``python
benchmarks/ocp_solvers.py``, interpreted, idle 2-core machine): with its defaults it
stopped after 972 iterations without converging; with a small initial barrier and bound
push (its barrier is monotone) it took 276 iterations and 1.8 s, against IPOPT's 40
iterations and 0.13 s on this module's NLP (IPOPT on the stage-wise NLP: 405 and 3.8 s).
IPOPT stays, and FATROP is not offered: the stage-wise form costs IPOPT ten times the
iterations, and FATROP needs more still.

The NLP is built once per (segments, settings that shape it, joint range) with every
problem-dependent number (arcs, check places, robot, weights) as a parameter, so a second
problem of the same shape reuses it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.bounds import segment_lower_bounds
from spm_opt.errors import PlanningError
from spm_opt.evaluate import Violation, evaluate
from spm_opt.interrupt import solve
from spm_opt.limits import RELATIVE_TOLERANCE, PlannerBounds, contour_tube, planner_bounds
from spm_opt.model import dynamics, torque_table
from spm_opt.model.params import MM, Robot
from spm_opt.planners.contour_guess import segment_motion
from spm_opt.planners.nlp_library import Solver, nlp_solver
from spm_opt.planners.ocp_assembly import (
    HESSIAN,
    JACOBIAN,
    VALUE,
    AssembledNlp,
    assemble,
    interval_functions,
)
from spm_opt.planners.ocp_transcription import (
    ARC_PARAMETERS,
    GAUSS,
    GAUSS_FRACTIONS,
    INSIDE,
    NODE,
    ON_DEMAND,
    STATE,
    UNLIMITED,
    Grid,
    RowGroup,
    default_fractions,
    interval_function,
    row_groups,
)
from spm_opt.planners.registry import (
    planner_options,
    register,
    settings_from_options,
)
from spm_opt.planners.toppra import time_optimal_guess
from spm_opt.problem import Problem
from spm_opt.trajectory import Trajectory

MIN_CONTOUR_TOLERANCE = 1e-6
"""Narrowest contour tube the planners accept, m: a zero-width tube has no interior."""
MIN_INTERVAL_S = 1e-4
"""Shortest interval of the time grid, s. A phase squeezed to 1 ms in all (0.06 ms an
interval: a minimum-jerk re-solve on a random flap) leaves the plan's samples consistent
only to IPOPT's tolerance over a span too short for it, and the motion rebuilt from them
swings (5e5 rad/s³). Kept well below the intervals plans use, since IPOPT's path depends on
it: on the paper's flap, 41 and 92 iterations (minimum time, energy) at 0.1 ms, 64 and 208
at 1 ms."""


@dataclass(frozen=True)
class OcpSettings:
    """The transcription and solver settings, read from the problem's ``[planner.NAME]``.

    Attributes
    ----------
    nodes_per_phase : int
        Intervals along the middle of each segment.
    corner_nodes : int
        Intervals in each of the two short phases at a segment's ends.
    checks_per_interval : int
        Check points inside each interval where the path limits are imposed besides the
        nodes, evenly spaced at first (1: the midpoint) and moved where a solution exceeds
        a limit between them.
    margin : float
        Fraction of each limit kept in reserve for the motion between constraint points.
    timing : str
        "free" (every duration a variable: minimum time), "bounded" (the total duration at
        most the problem's), "total" (the problem's total duration kept, its split between
        segments free) or "segments" (each segment's duration as the problem gives it).
    max_iterations : int
    tolerance : float
        IPOPT's convergence tolerance.
    acceptable_iterations : int
        IPOPT's ``acceptable_iter``: after this many iterations in a row at its looser
        "acceptable" level it stops early; such a stop is never a plan, but the start of a
        strict re-solve (with 0: never stop early).
    time_weight, energy_weight, jerk_weight : float
        Weights of the total time (s), ∫τᵀτ dt and ∫jerk² dt, each divided by its value at
        the initial guess so that the weights compare like with like.
    print_level : int
        IPOPT's verbosity (0 silent, 5 every iteration).
    """

    nodes_per_phase: int = 10
    corner_nodes: int = 8
    checks_per_interval: int = 1
    margin: float = 0.005
    timing: str = "total"
    max_iterations: int = 300
    tolerance: float = 1e-7
    acceptable_iterations: int = 15
    time_weight: float = 0.0
    energy_weight: float = 0.0
    jerk_weight: float = 0.0
    print_level: int = 0

    _RANGES = {
        "nodes_per_phase": (1, 200),
        "corner_nodes": (1, 50),
        "checks_per_interval": (1, 9),
        "margin": (0.0, 0.5),
        "max_iterations": (1, 100_000),
        "acceptable_iterations": (0, 100_000),
        "tolerance": (1e-12, 1e-2),
        "time_weight": (0.0, 1e6),
        "energy_weight": (0.0, 1e6),
        "jerk_weight": (0.0, 1e6),
        "print_level": (0, 12),
    }

    @classmethod
    def from_options(cls, name: str, options: dict[str, Any], defaults: OcpSettings) -> OcpSettings:
        """Settings from a ``[planner.NAME]`` table over ``defaults``; one-line errors."""
        return settings_from_options(name, defaults, options, cls._RANGES, {"timing": TIMINGS})


TIMINGS = ("free", "bounded", "total", "segments")
OPTION_KEYS = tuple(f.name for f in dataclasses.fields(OcpSettings))


CONVERGED = "Solve_Succeeded"
"""The only IPOPT status that makes a plan."""
ACCEPTABLE = "Solved_To_Acceptable_Level"
"""IPOPT's early stop at its looser acceptable level (constraints within 1e-2 in their own
units: wider than the contour tube in mm²), which CasADi counts as a success."""
_WARM_START = {
    "warm_start_init_point": "yes",
    "mu_init": 1e-6,
    "warm_start_bound_push": 1e-9,
    "warm_start_mult_bound_push": 1e-9,
}
"""IPOPT's options to continue from a solution and its multipliers (the strict re-solve)."""


def _grid(segments: int, settings: OcpSettings) -> Grid:
    corner = settings.corner_nodes
    return Grid(segments, (corner, settings.nodes_per_phase, corner))


DRIVE_TERMS = 5
"""The drives' entries after the torque table's values in the NLP's robot: the rotor's J,
then each joint's viscous and each joint's Coulomb friction."""


def load_torque(joint_range: bytes) -> Callable[..., ca.SX]:
    """(q, q̇, q̈, parameters) -> the joint side of the actuators' torque, N·m, for robots
    of a joint range (its bytes): the load torque (smooth friction) plus the drives' J q̈,
    f_v q̇ and f_c σ(q̇), σ(v) = v / sqrt(v² + s²) with the friction's smoothing s (the
    table's last value); ``parameters``: :func:`dynamics_parameters`."""
    table = torque_table.torque_function(np.frombuffer(joint_range).reshape(2, 2))

    def torque(q: ca.SX, qd: ca.SX, qdd: ca.SX, parameters: ca.SX) -> ca.SX:
        values, drives = parameters[:-DRIVE_TERMS], parameters[-DRIVE_TERMS:]
        rotor, viscous, coulomb = drives[0], drives[1:3], drives[3:5]
        smoothing = values[-1]
        sliding = qd / ca.sqrt(qd**2 + smoothing**2)
        return table(q, qd, qdd, values) + rotor * qdd + viscous * qd + coulomb * sliding

    return torque


def joint_side_torque(robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """:func:`load_torque` in numpy over samples (N, 2), N·m, from the Lagrange model
    (not the table)."""
    actuator, smoothing = robot.actuator, robot.friction.smoothing
    load = dynamics.inverse_dynamics(robot, q, qd, qdd, exact=False)
    return (
        load
        + actuator.rotor_inertia_kg_m2 * qdd
        + np.asarray(actuator.viscous_friction_nm_s_rad) * qd
        + np.asarray(actuator.coulomb_friction_nm) * qd / np.sqrt(qd**2 + smoothing**2)
    )


def range_key(joint_range: np.ndarray) -> bytes:
    """A robot's joint range (2, 2), rad, as bytes: the torque table, and so the NLP,
    depend on it."""
    return np.ascontiguousarray(joint_range, dtype=float).tobytes()


def dynamics_parameters(robot: Robot) -> np.ndarray:
    """The robot as the NLP takes it: its torque table's values, then the drives' J, f_v
    (per joint) and f_c (per joint)."""
    actuator = robot.actuator
    drives = [
        actuator.rotor_inertia_kg_m2,
        *actuator.viscous_friction_nm_s_rad,
        *actuator.coulomb_friction_nm,
    ]
    return np.concatenate([torque_table.table_values(robot), drives])


@dataclass(frozen=True)
class _Nlp:
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
def _interval(
    checks: int, with_torque: bool, joint_range: bytes, demanded: frozenset[str]
) -> ca.Function:
    """One interval's function (:func:`interval_function`) for robots of ``joint_range``,
    with the on-demand rows of the constraints ``demanded``."""
    if not with_torque:
        return interval_function(checks, False, None, 0, demanded)
    table = torque_table.torque_function(np.frombuffer(joint_range).reshape(2, 2))
    n_dynamics = table.size1_in(3) + DRIVE_TERMS
    return interval_function(checks, True, load_torque(joint_range), n_dynamics, demanded)


@cache
def _interval_functions(
    checks: int, with_torque: bool, joint_range: bytes, demanded: frozenset[str]
) -> list[ca.Function]:
    """The interval's value, Jacobian and Hessian in SX (:func:`interval_functions`)."""
    return interval_functions(_interval(checks, with_torque, joint_range, demanded))


@cache
def _nlp(
    segments: int,
    settings: OcpSettings,
    with_torque: bool,
    joint_range: bytes,
    demanded: frozenset[str],
) -> _Nlp:
    """The NLP for ``segments`` segments, with or without the dynamics (cached per
    process), assembled from one interval's functions (:mod:`ocp_assembly`).

    g holds, interval by interval, the continuity rows and the constraint rows of
    :func:`row_groups`, then the segment durations and the total duration; p holds every
    segment's arc, the check points' fractions, the dynamics parameters, the weights and
    the scales.
    """
    checks = settings.checks_per_interval
    interval = _interval(checks, with_torque, joint_range, demanded)
    grid = _grid(segments, settings)
    groups, n_dynamics = row_groups(checks, with_torque, demanded), interval.size1_in(5)
    assembled = assemble(
        grid,
        _interval_functions(checks, with_torque, joint_range, demanded),
        ARC_PARAMETERS,
        checks,
        n_dynamics,
    )
    return _Nlp(assembled.problem, assembled.terms, grid, groups, checks, n_dynamics)


_FORMULATION_SOURCES = (
    "planners/ocp.py",
    "planners/ocp_assembly.py",
    "planners/ocp_transcription.py",
    "skull/arc_fit.py",
    "model/kinematics.py",
    "model/dynamics.py",
    "model/torque_table.py",
    "model/params.py",
)
"""The package's files whose code makes the interval's functions: a change to any of them
is a new library."""


@cache
def _interval_key(
    checks: int, with_torque: bool, joint_range: bytes, demanded: frozenset[str]
) -> str:
    """What identifies :func:`_interval`'s functions without building them: the code that
    builds them and the settings that shape them."""
    package = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for name in _FORMULATION_SOURCES:
        digest.update((package / name).read_bytes())
    digest.update(repr((checks, with_torque, sorted(demanded))).encode() + joint_range)
    return digest.hexdigest()


@cache
def _solver(
    segments: int,
    settings: OcpSettings,
    with_torque: bool,
    joint_range: bytes,
    demanded: frozenset[str],
    warm: bool,
) -> Solver:
    """IPOPT on :func:`_nlp`'s problem, its derivatives assembled from the interval's
    compiled functions (:mod:`nlp_library`, :mod:`ocp_assembly`); ``warm``: continuing from
    a solution and its multipliers, strictly (never stopping at the acceptable level)."""
    ipopt = {
        "max_iter": settings.max_iterations,
        "tol": settings.tolerance,
        "print_level": settings.print_level,
        "sb": "yes",
        "mu_strategy": "adaptive",
        "adaptive_mu_globalization": "never-monotone-mode",
        "acceptable_iter": 0 if warm else settings.acceptable_iterations,
        **(_WARM_START if warm else {}),
    }
    options = {"ipopt": ipopt, "print_time": False, "calc_lam_p": False}
    checks = settings.checks_per_interval
    nlp = _nlp(segments, settings, with_torque, joint_range, demanded)

    def solver_parts(functions: list[ca.Function]) -> tuple[dict, dict]:
        assembled = nlp.assemble(functions)
        return assembled.problem, assembled.derivatives

    return nlp_solver(
        "ocp",
        "ipopt",
        _interval_key(checks, with_torque, joint_range, demanded),
        (VALUE, JACOBIAN, HESSIAN),
        lambda: _interval_functions(checks, with_torque, joint_range, demanded),
        solver_parts,
        options,
    )


def _arcs(problem: Problem) -> np.ndarray:
    """Per segment (segments, ARC_PARAMETERS): the arc's a, w, n, n × end (the great circle
    the cut follows, as the Contour has it), and the fit of the skull's radius near it
    (φ_c, φ_h, o_h, C_kj in mm). Lengths in mm keep the squared rows of the path
    constraints near 1."""
    contour = problem.contour
    sweep = contour.sweep[:, None]
    end = contour.start * np.cos(sweep) + contour.inplane * np.sin(sweep)
    fits = problem.arc_radius_fits
    return np.concatenate(
        [
            contour.start,
            contour.inplane,
            contour.normal,
            np.cross(contour.normal, end),
            np.array([[fit.centre, fit.half_span, fit.across] for fit in fits]),
            np.array([fit.coefficients.ravel() / MM for fit in fits]),
        ],
        axis=1,
    )


def _parameters(
    problem: Problem,
    fractions: np.ndarray,
    weights: list[float],
    scales: np.ndarray,
    with_torque: bool,
) -> np.ndarray:
    """p for one problem: arcs, check fractions (checks, M), dynamics, weights, scales."""
    return np.concatenate(
        [
            _arcs(problem).ravel(),
            fractions.ravel(order="F"),
            # none without the torque rows: an unused input of the mapped interval function
            # swells the generated C of its derivatives (31 against 7 MB for minimum time)
            dynamics_parameters(problem.robot) if with_torque else np.zeros(0),
            weights,
            scales,
        ]
    )


def _visits(start: Trajectory | None, segments: int) -> np.ndarray | None:
    """The landmark times of ``start`` (s), if it visits ``segments`` + 1 landmarks."""
    visits = None if start is None else start.metadata.get("landmark_times_s")
    if visits is None or len(visits) != segments + 1:
        return None
    return np.asarray(visits, dtype=float)


def _retimed(
    start: Trajectory, visits: np.ndarray, t: np.ndarray, landmarks: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, q̇, q̈ (N, 2) at times t of ``start`` (landmark times ``visits``) stretched
    segment by segment onto the landmark times ``landmarks``."""
    segment = np.clip(np.searchsorted(landmarks, t, side="right") - 1, 0, len(landmarks) - 2)
    rate = np.diff(visits)[segment] / np.diff(landmarks)[segment]  # start's s per s
    source = np.clip(visits[segment] + (t - landmarks[segment]) * rate, visits[0], visits[-1])
    rate = rate[:, None]
    return (
        start.position(source),
        start.velocity(source) * rate,
        start.acceleration(source) * rate**2,
    )


def _guess(
    problem: Problem, grid: Grid, segment_durations: np.ndarray, start: Trajectory | None
) -> np.ndarray:
    """The initial x over ``segment_durations``: ``start`` re-timed onto them when it
    visits the same landmarks, else the contour-following motion."""
    phases = grid.phase_durations(segment_durations)
    t = grid.node_times(phases)
    landmarks = t[grid.landmark_nodes]
    visits = _visits(start, grid.segments)
    if start is not None and visits is not None:
        q, qd, qdd = _retimed(start, visits, t, landmarks)
    else:
        parts = []
        for k in range(grid.segments):
            inside = slice(grid.landmark_nodes[k], grid.landmark_nodes[k + 1] + 1)
            duration = landmarks[k + 1] - landmarks[k]
            tau = (t[inside] - landmarks[k]) / duration
            parts.append(np.hstack(segment_motion(problem, k, tau, duration))[:-1])
        last = np.hstack([problem.waypoint_angles[-1], np.zeros(4)])
        q, qd, qdd = np.hsplit(np.vstack([*parts, last]), [2, 4])
    jerks = np.diff(qdd, axis=0) / np.diff(t)[:, None]
    return np.concatenate([np.hstack([q, qd, qdd]).ravel(), jerks.ravel(), phases])


def _segment_durations(
    problem: Problem, timing: str, need: np.ndarray, start: Trajectory | None
) -> np.ndarray:
    """The segments' durations (s) the initial guess takes: the problem's when fixed,
    else the start's (scaled to the problem's total when that is kept or exceeded), else
    from the lower bounds ``need``."""
    given = float(np.sum(problem.segment_durations))
    visits = _visits(start, len(need))
    if timing == "segments":
        return problem.segment_durations
    if visits is None:
        return 1.3 * need if timing == "free" else need * given / np.sum(need)
    durations = np.diff(visits)
    if timing == "total" or (timing == "bounded" and np.sum(durations) > given):
        return durations * given / np.sum(durations)
    return durations


def _check_feasible_at_all(problem: Problem, timing: str, margin: float) -> np.ndarray:
    """Refuse what no solver can do, with the reason; return the segments' lower bounds."""
    limits, names = problem.limits, problem.visit_names
    tube = contour_tube(problem)
    if tube is not None and tube < MIN_CONTOUR_TOLERANCE:
        raise PlanningError(
            f"contour_tolerance_mm = {limits.contour_tolerance / MM:g} less "
            f"execution_reserve_mm = {limits.execution_reserve / MM:g}: the cut would have to "
            f"turn every corner exactly; leave a plan at least {MIN_CONTOUR_TOLERANCE / MM:g} mm"
        )
    torque_limit = planner_bounds(problem, margin).load_torque
    for visit in (0, len(names) - 1):
        holding = dynamics.gravity_torque(problem.robot, problem.waypoint_angles[visit])[0]
        if np.max(np.abs(holding)) > torque_limit:
            joint = int(np.argmax(np.abs(holding)))
            raise PlanningError(
                f"max_joint_torque_nm = {problem.max_joint_torque:g}: holding the robot at rest at "
                f"{names[visit]} takes {abs(holding[joint]):.4g} N·m on actuator {joint + 1} "
                "against gravity"
            )
    bounds = segment_lower_bounds(problem)
    need = bounds / (1 - margin)
    total = float(np.sum(problem.segment_durations))
    if timing == "total" and total < np.sum(need):
        raise PlanningError(
            f"segment_durations_s: the cut lasts {total:g} s in all but the joint- and "
            f"tool-speed limits (max_tool_speed_mm_s, max_joint_speed_rpm) need at least "
            f"{np.sum(need):.4g} s along the contour; lengthen it or raise the limits"
        )
    if timing == "segments":
        short = np.flatnonzero(problem.segment_durations < need)
        if short.size:
            k = int(short[0])
            raise PlanningError(
                f"segment_durations_s: segment {names[k]}→{names[k + 1]} lasts "
                f"{problem.segment_durations[k]:g} s but the joint- and tool-speed limits "
                f"(max_tool_speed_mm_s, max_joint_speed_rpm) need at least {need[k]:.4g} s "
                "along the contour; lengthen it or raise the limits"
            )
    return bounds


def _bounds(
    problem: Problem,
    nlp: _Nlp,
    bounds: PlannerBounds,
    timing: str,
    durations: np.ndarray,
) -> dict[str, np.ndarray]:
    """lbx, ubx, lbg, ubg for one problem within ``bounds`` (the problem's limits as
    :mod:`spm_opt.limits` translates them for a planner); ``durations``: the initial phase
    durations (D,), s."""
    speed = bounds.joint_speed
    acceleration = bounds.joint_acceleration or UNLIMITED
    jerk = bounds.joint_jerk or UNLIMITED
    grid = nlp.grid
    m = grid.intervals
    low = np.tile(
        [*bounds.joint_range[:, 0], -speed, -speed, -acceleration, -acceleration], (m + 1, 1)
    )
    high = -low
    high[:, 0:2] = bounds.joint_range[:, 1]
    landmarks = grid.landmark_nodes
    low[landmarks, 0:2] = high[landmarks, 0:2] = problem.waypoint_angles
    low[[0, -1], 2:6] = high[[0, -1], 2:6] = 0.0
    longest = 20.0 * np.max(durations) + 1.0
    shortest = MIN_INTERVAL_S * np.tile(grid.counts, grid.segments)
    lbx = np.concatenate([low.ravel(), np.full(2 * m, -jerk), shortest])
    ubx = np.concatenate([high.ravel(), np.full(2 * m, jerk), np.full(3 * grid.segments, longest)])

    limits = [group.constraint.limits(bounds) for group in nlp.groups]
    row_low = np.concatenate([np.zeros(STATE), *(low for low, _ in limits)])
    row_high = np.concatenate([np.zeros(STATE), *(high for _, high in limits)])
    interval_low, interval_high = np.tile(row_low, (m, 1)), np.tile(row_high, (m, 1))
    for group in nlp.groups:
        if group.place == NODE and not group.constraint.at_landmarks:
            columns = slice(STATE + group.start, STATE + group.start + group.size)
            interval_low[landmarks[:-1], columns] = -np.inf
            interval_high[landmarks[:-1], columns] = np.inf

    segments = (0.5 * segment_lower_bounds(problem), np.full(grid.segments, np.inf))
    total = (0.0, np.inf)
    given = float(np.sum(problem.segment_durations))
    if timing == "segments":
        segments = (problem.segment_durations, problem.segment_durations)
    elif timing == "total":
        total = (given, given)
    elif timing == "bounded":
        total = (0.0, given)
    return {
        "lbx": lbx,
        "ubx": ubx,
        "lbg": np.concatenate([interval_low.ravel(), segments[0], [total[0]]]),
        "ubg": np.concatenate([interval_high.ravel(), segments[1], [total[1]]]),
    }


def _place_offset(group: RowGroup, fractions: np.ndarray, interval: int) -> float:
    """Where in its interval a group's point sits, as a fraction of the interval."""
    if group.place == INSIDE:
        return float(fractions[group.point, interval])
    if group.place == GAUSS:
        return GAUSS_FRACTIONS[group.point]
    return 0.0 if group.place == NODE else 0.5


def _excess(values: np.ndarray, low: np.ndarray, high: np.ndarray, squared: bool) -> np.ndarray:
    """Excess of rows over their bounds, relative to the bound (−inf where unbounded);
    rows that hold squares are compared by their square roots."""
    if squared:
        values, low = np.sqrt(np.maximum(values, 0.0)), np.full_like(low, -np.inf)
        high = np.sqrt(high)
    limit = np.where(np.isfinite(high), high, low)
    relevant = np.isfinite(limit)
    excess = np.where(relevant, np.maximum(values - high, low - values), -np.inf)
    relative = np.full(values.shape, -np.inf)
    np.divide(excess, np.maximum(np.abs(limit), 1e-12), out=relative, where=relevant)
    return relative


def _interval_rows(nlp: _Nlp, vector: np.ndarray) -> np.ndarray:
    """The interval rows of g (or of its bounds) as (M, rows per interval)."""
    m = nlp.grid.intervals
    return np.reshape(vector[: m * nlp.rows_per_interval], (m, nlp.rows_per_interval))


def _worst_constraint(
    nlp: _Nlp,
    g: np.ndarray,
    box: dict[str, np.ndarray],
    fractions: np.ndarray,
    names: list[str],
) -> str:
    """The most violated constraint (or, with none violated, the nearest to binding), in
    words: what, its value and limit, and where."""
    values, low, high = (_interval_rows(nlp, v) for v in (g, box["lbg"], box["ubg"]))
    best: tuple[float, str] | None = None
    grid = nlp.grid
    for group in nlp.groups:
        columns = slice(STATE + group.start, STATE + group.start + group.size)
        squared = group.constraint.squared
        relative = _excess(values[:, columns], low[:, columns], high[:, columns], squared)
        interval, row = np.unravel_index(int(np.argmax(relative)), relative.shape)
        if not np.isfinite(relative[interval, row]):
            continue
        if best is not None and relative[interval, row] <= best[0]:
            continue
        value, bound = values[interval, columns][row], high[interval, columns][row]
        if not np.isfinite(bound):
            bound = low[interval, columns][row]
        if squared:
            value, bound = math.sqrt(max(value, 0.0)), math.sqrt(bound)
        segment = int(grid.interval_segments[interval])
        position = interval - segment * grid.per_segment + _place_offset(group, fractions, interval)
        unit = group.constraint.unit
        best = (
            relative[interval, row],
            f"{group.constraint.name} {value:.4g} {unit} against {bound:.4g} {unit} in "
            f"segment {names[segment]}→{names[segment + 1]}, "
            f"at {position:.3g} of its {grid.per_segment} intervals",
        )
    return "none" if best is None else best[1]


PROBE_EXCESS = 1e-6
"""Relative excess over a bound below which a probed point counts as within it."""
PROBE_POINTS = 24
"""Points inside each interval where a solution is probed for limits exceeded between its
check points."""


@cache
def _probe(segments: int, settings: OcpSettings) -> tuple[ca.Function, tuple[RowGroup, ...]]:
    """The interval function with :data:`PROBE_POINTS` check points, mapped over the grid,
    and its row groups."""
    grid = _grid(segments, settings)
    interval = interval_function(PROBE_POINTS, False, None, 0, ON_DEMAND)
    return interval.map(grid.intervals), row_groups(PROBE_POINTS, False, ON_DEMAND)


def _moved_check_points(
    problem: Problem,
    settings: OcpSettings,
    bounds: PlannerBounds,
    x: np.ndarray,
    fractions: np.ndarray,
    demanded: frozenset[str],
) -> tuple[np.ndarray, set[str]]:
    """The check fractions with, in every interval where x exceeds a bound between its
    check points, the check nearest to the worst place moved there; and the names of the
    constraints so exceeded (on-demand rows count once ``demanded``)."""
    grid = _grid(len(problem.segment_durations), settings)
    probe, groups = _probe(grid.segments, settings)
    states, jerks, durations = grid.split(x)
    places = default_fractions(PROBE_POINTS)
    _, rows, _ = probe(
        states[:-1].T,
        jerks.T,
        (grid.interval_matrix @ durations)[None, :],
        (_arcs(problem).T)[:, grid.interval_segments],
        np.tile(places[:, None], (1, grid.intervals)),
        np.zeros(0),
    )
    rows = rows.full().T  # (M, probe rows)
    worst = np.full((grid.intervals, PROBE_POINTS), -np.inf)
    found = set()
    for group in groups:
        if group.place != INSIDE or group.constraint.waiting(group.place, demanded):
            continue
        low, high = (np.asarray(v, dtype=float) for v in group.constraint.limits(bounds))
        values = rows[:, group.start : group.start + group.size]
        relative = np.max(
            _excess(values, low[None, :], high[None, :], group.constraint.squared), axis=1
        )
        if np.max(relative) > PROBE_EXCESS:
            found.add(group.constraint.name)
        worst[:, group.point] = np.maximum(worst[:, group.point], relative)
    exceeded = np.flatnonzero(np.max(worst, axis=1) > PROBE_EXCESS)
    moved = fractions.copy()
    for interval in exceeded:
        place = places[int(np.argmax(worst[interval]))]
        nearest = int(np.argmin(np.abs(moved[:, interval] - place)))
        moved[nearest, interval] = place
    return moved, found


@dataclass(frozen=True)
class OcpPlanner:
    """An optimal-control planner with fixed weights; see the module docstring."""

    name: str
    defaults: OcpSettings
    start: Callable[[Problem], Trajectory] | None = None

    def settings(self, problem: Problem) -> OcpSettings:
        return OcpSettings.from_options(
            self.name, planner_options(problem, self.name, OPTION_KEYS), self.defaults
        )

    def plan(self, problem: Problem, warm_start: Trajectory | None = None) -> Trajectory:
        """Solve; ``warm_start`` (a plan of a similar problem with the same landmark visits)
        replaces the contour-following initial guess.

        Without an energy term the dynamics enter only through the torque limit, which is
        far from binding on this robot: the NLP is first solved without it, and solved again
        with it (from the first solution) only if the model's torques at the constraint
        points exceed it. Both give the same optimum when it does not bind.
        """
        settings = self.settings(problem)
        need = _check_feasible_at_all(problem, settings.timing, settings.margin)
        need = need / (1 - settings.margin)
        grid = _grid(len(problem.segment_durations), settings)
        with_torque = settings.energy_weight > 0.0
        bounds = planner_bounds(problem, settings.margin)
        fractions = np.tile(
            default_fractions(settings.checks_per_interval)[:, None], grid.intervals
        )
        demanded: frozenset[str] = frozenset()
        shape = (
            len(problem.segment_durations),
            settings,
            with_torque,
            range_key(problem.robot.joint_range),
        )
        starts: list[Trajectory | _Solved | None] = (
            [warm_start] if warm_start is not None else self._starts(problem)
        )
        solved = _SOLVED.get(warm_start) if warm_start is not None else None
        if solved is not None and solved.shape == shape:
            starts.insert(0, solved)
        for number, start in enumerate(starts, 1):
            try:
                if isinstance(start, _Solved):  # its solution and multipliers: continue
                    fractions, demanded = start.fractions, start.demanded
                    solution = self._solve(
                        problem, settings, bounds, fractions, with_torque, demanded, start.solution
                    )
                else:
                    durations = _segment_durations(problem, settings.timing, need, start)
                    x0 = _guess(problem, grid, durations, start)
                    solution = self._solve(
                        problem, settings, bounds, fractions, with_torque, demanded, x0
                    )
                break
            except PlanningError:
                if number == len(starts):
                    raise
        statistics = {**solution.statistics, "starts_tried": number, "start": _start_kind(start)}
        # how far the radius the NLP reads strays from the skull's surface (a mesh's facets)
        fit_error = max(fit.max_error for fit in problem.arc_radius_fits)
        statistics["skull_fit_error_mm"] = fit_error / MM
        moved_checks = 0
        for round_ in range(1, REFINEMENTS + 2):
            if not with_torque and _torque_exceeded(problem, grid, bounds, solution.x):
                with_torque = True  # new rows: a fresh start from x
                solution = self._solve(
                    problem, settings, bounds, fractions, True, demanded, solution.x
                )
                statistics = _added(statistics, solution.statistics)
            statistics["refinements"] = round_ - 1
            statistics["check_points_moved"] = moved_checks
            trajectory = self._trajectory(problem, grid, solution.x, statistics, settings)
            broken = evaluate(problem, trajectory).violations
            if not broken:
                _SOLVED[trajectory] = _Solved(shape, fractions, demanded, solution)
                return trajectory
            if round_ > REFINEMENTS:
                break
            newly = {v.rule for v in broken if v.rule in ON_DEMAND} - demanded
            demanded |= newly  # its rows at the check points from now on
            moved, found = _moved_check_points(
                problem, settings, bounds, solution.x, fractions, demanded
            )
            moved_checks += int(np.sum(moved != fractions))
            fractions = moved
            if round_ == 1:  # later, what moved check points did not cure is tightened
                if "contour deviation" in found:  # the cut outside the tube: not swept in it
                    found.add("coverage")
                broken = [v for v in broken if v.rule not in found]
            broken = [v for v in broken if v.rule not in newly]
            if broken or newly:
                # from x alone: continuing with the multipliers of looser bounds as well
                # halves the iterations but ends in worse optima (five landmarks: ∫τᵀτ
                # 0.885 against 0.855); new rows have none
                bounds = _tightened(bounds, broken)
                solution = self._solve(
                    problem, settings, bounds, fractions, with_torque, demanded, solution.x
                )
            else:  # the same problem with a few check points moved: continue
                solution = self._solve(
                    problem, settings, bounds, fractions, with_torque, demanded, solution
                )
            statistics = _added(statistics, solution.statistics)
        raise PlanningError(
            f"{self.name}: the evaluator still finds {'; '.join(map(str, broken))} after "
            f"{REFINEMENTS} re-solves with check points moved and tighter bounds; raise "
            f"planner.{self.name}.checks_per_interval or margin"
        )

    def _starts(self, problem: Problem) -> list[Trajectory | None]:
        """The motions a solve starts from, in turn while IPOPT fails from them:
        :attr:`start` of the problem (unless it fails), then the contour-following guess
        (None). The near-optimal start finds the better optimum (the paper's flap 37.87 s
        against 38.09 s), the contour the more robust one (the five-landmark flap fails
        from the near-optimal start)."""
        if self.start is None:
            return [None]
        try:
            return [self.start(problem), None]
        except PlanningError:
            return [None]

    def _trajectory(
        self,
        problem: Problem,
        grid: Grid,
        x: np.ndarray,
        statistics: dict[str, Any],
        settings: OcpSettings,
    ) -> Trajectory:
        """The plan x describes, with its landmark times and the solver's statistics."""
        _, _, durations = grid.split(x)
        landmark_times = grid.node_times(durations)[grid.landmark_nodes]
        metadata = {
            "landmark_times_s": landmark_times.tolist(),
            "landmarks": problem.visit_names,
            "statistics": {**statistics, "settings": dataclasses.asdict(settings)},
        }
        return grid.trajectory(x, metadata)

    def _solve(
        self,
        problem: Problem,
        settings: OcpSettings,
        bounds: PlannerBounds,
        fractions: np.ndarray,
        with_torque: bool,
        demanded: frozenset[str],
        start: np.ndarray | _Solution,
    ) -> _Solution:
        """Solve from ``start``: an initial x, or a solution to continue from with its
        multipliers and objective scales (its NLP must have the same rows); ``demanded``:
        the constraints whose on-demand rows the NLP has. An early stop at IPOPT's
        acceptable level is continued strictly from there."""
        started = time.perf_counter()
        segments = len(problem.segment_durations)
        joint_range = range_key(problem.robot.joint_range)
        nlp = _nlp(segments, settings, with_torque, joint_range, demanded)
        continued = isinstance(start, _Solution)
        solver = _solver(segments, settings, with_torque, joint_range, demanded, warm=continued)
        construction = time.perf_counter() - started
        weights = [settings.time_weight, settings.energy_weight, settings.jerk_weight]
        if isinstance(start, _Solution):
            scales, guess = start.scales, start.continuation
        else:
            at_guess = nlp.terms(
                start, _parameters(problem, fractions, weights, np.ones(3), with_torque)
            )
            scales = np.maximum(np.abs([float(v) for v in at_guess]), 1e-9)
            guess = {"x0": start}
        parameters = _parameters(problem, fractions, weights, scales, with_torque)
        box = _bounds(problem, nlp, bounds, settings.timing, nlp.grid.split(guess["x0"])[2])
        started = time.perf_counter()
        solution = solve(solver, **guess, p=parameters, **box)
        stats = solver.stats()
        statuses, iterations = [stats["return_status"]], int(stats["iter_count"])
        if stats["return_status"] == ACCEPTABLE:  # loose: re-solve strictly from there
            solver = _solver(segments, settings, with_torque, joint_range, demanded, warm=True)
            solution = solve(solver, **_continuation(solution), p=parameters, **box)
            stats = solver.stats()
            statuses.append(stats["return_status"])
            iterations += int(stats["iter_count"])
        wall = time.perf_counter() - started
        x, g = solution["x"].full().ravel(), solution["g"].full().ravel()
        most = _worst_constraint(nlp, g, box, fractions, problem.visit_names)
        if stats["return_status"] != CONVERGED:
            raise PlanningError(
                f"{self.name}: IPOPT stopped with {' then '.join(statuses)} after "
                f"{iterations} iterations; most violated: {most}"
            )
        total_time, effort, jerk_integral = (float(v) for v in nlp.terms(x, parameters))
        return _Solution(
            x,
            _continuation(solution),
            scales,
            {
                "status": stats["return_status"],
                "statuses": statuses,
                "iterations": iterations,
                "solve_time_s": wall,
                "function_time_s": sum(v for k, v in stats.items() if k.startswith("t_wall_nlp")),
                "construction_time_s": construction,
                "constraint_violation": float(
                    max(np.max(box["lbg"] - g), np.max(g - box["ubg"]), 0.0)
                ),
                "most_binding": most,
                "torque_in_nlp": with_torque,
                "duration_s": total_time,
                "effort_n2m2s": effort if with_torque else None,
                "jerk_integral_rad2_s5": jerk_integral,
            },
        )


@dataclass(frozen=True)
class _Solution:
    """A converged solve: x, what continuing from it takes, and its statistics."""

    x: np.ndarray
    continuation: dict[str, np.ndarray]  # x0, lam_x0, lam_g0
    scales: np.ndarray  # the objective's terms at the solve's initial guess
    statistics: dict[str, Any]


def _start_kind(start: Trajectory | _Solved | None) -> str:
    """How a solve started: from a plan's "solution" and multipliers, a plan's "motion"
    re-timed, or the "contour"-following guess."""
    if isinstance(start, _Solved):
        return "solution"
    return "contour" if start is None else "motion"


@dataclass(frozen=True)
class _Solved:
    """A plan's last solve: what a similar problem's solve can continue from.

    Attributes
    ----------
    shape : tuple
        What makes its NLP: segments, settings, torque rows, joint range.
    fractions : ndarray, shape (checks, M)
        Its check points' places.
    demanded : frozenset of str
        The constraints whose on-demand rows its NLP had.
    solution : _Solution
    """

    shape: tuple
    fractions: np.ndarray
    demanded: frozenset[str]
    solution: _Solution


_SOLVED: weakref.WeakKeyDictionary[Trajectory, _Solved] = weakref.WeakKeyDictionary()
"""The last solve of each plan this process made and still holds: a plan given as another
problem's warm start (a sweep's anchor) hands over its solution and multipliers, not only
its motion, when the NLPs have the same shape. Minimum time on the paper's flap from its
plan at 3 mm/s: 17–27 iterations at 2–3.5 mm/s against 37–53 from scratch, but 88 and 108
at 3.75 and 4 mm/s against 44 and 74."""


def _continuation(solution: dict[str, ca.DM]) -> dict[str, np.ndarray]:
    """IPOPT's warm start from a solution: its x and multipliers."""
    return {
        name: solution[key].full().ravel()
        for name, key in (("x0", "x"), ("lam_x0", "lam_x"), ("lam_g0", "lam_g"))
    }


def _torque_exceeded(problem: Problem, grid: Grid, bounds: PlannerBounds, x: np.ndarray) -> bool:
    """Whether the joint side torques (:func:`joint_side_torque`) at the Gauss points of x's
    intervals (where the NLP would impose them) exceed ``bounds``' torque bound."""
    motion = grid.trajectory(x, {})
    nodes = grid.node_times(grid.split(x)[2])
    t = np.concatenate([nodes[:-1] + f * np.diff(nodes) for f in GAUSS_FRACTIONS])
    q, qd, qdd = motion.position(t), motion.velocity(t), motion.acceleration(t)
    torque = joint_side_torque(problem.robot, q, qd, qdd)
    return bool(np.max(np.abs(torque)) > bounds.load_torque)


REFINEMENTS = 5
"""Re-solves, each with check points moved and tighter bounds for whatever the evaluator
found exceeded between the constraint points, before the planner gives up. A minimum-energy
cut rides the tube's edge, and each re-solve may bulge out elsewhere: of 400 random flaps
two needed all of three rounds or more (varied flap 101: 0.063, 0.062, 0.058 mm against
0.057 mm, clean at the third)."""
_TIGHTENED = {  # the evaluator's rule: the bound that keeps it
    "joint speed": "joint_speed",
    "joint acceleration": "joint_acceleration",
    "joint jerk": "joint_jerk",
    "acceleration step": "joint_jerk",
    "hold acceleration": "joint_acceleration",
    "hold jerk": "joint_jerk",
    "actuator torque": "load_torque",
    "motor current": "load_torque",
    "tool speed": "tool_speed",
    "contour deviation": "contour_tolerance",
    "coverage": "contour_tolerance",
}
COVERAGE_TIGHTENING = 0.95
"""Factor on the contour bound when the cut leaves a stretch uncut without a deviation
beyond the tube (the gap's length says nothing about how much tighter to go)."""


def _tightened(bounds: PlannerBounds, violations: list[Violation]) -> PlannerBounds:
    """``bounds`` with each bound whose limit the evaluator found exceeded cut by the
    excess (worst / limit), and half the evaluator's tolerance more."""
    factors: dict[str, float] = {}
    for violation in violations:
        field = _TIGHTENED.get(violation.rule)
        if field is None:
            raise PlanningError(f"the plan breaks a limit no bound keeps: {violation}")
        factor = COVERAGE_TIGHTENING
        if violation.rule != "coverage":
            factor = abs(violation.allowed / violation.worst) * (1 - RELATIVE_TOLERANCE / 2)
        factors[field] = min(factors.get(field, 1.0), factor)
    return dataclasses.replace(
        bounds, **{name: getattr(bounds, name) * f for name, f in factors.items()}
    )


def _added(statistics: dict[str, Any], again: dict[str, Any]) -> dict[str, Any]:
    """The statistics of a re-solve, with the solve times and iterations of both."""
    summed = {
        k: statistics[k] + again[k] for k in ("solve_time_s", "function_time_s", "iterations")
    }
    return {**statistics, **again, **summed, "statuses": statistics["statuses"] + again["statuses"]}


MIN_TIME = register(
    OcpPlanner(
        "ocp-min-time",
        OcpSettings(timing="free", time_weight=1.0, jerk_weight=1e-6),
        start=time_optimal_guess,
    )
)
MIN_ENERGY = register(
    # min-time's margin, so that its plan (the start) is feasible here; the grid of
    # min-jerk: with min-time's (10 middle intervals, one check) the re-solves after a
    # tightened tube failed on the five-landmark and the large flaps (1000 iterations);
    # up to 1000 iterations a solve: on small flaps with tight tubes the effort falls
    # slowly, in short steps (IPOPT's steps cut to 5-50 % for a hundred iterations), and 3
    # of a sample of 18 varied flaps took 383-542 iterations in their two solves
    OcpPlanner(
        "ocp-min-energy",
        OcpSettings(
            energy_weight=1.0,
            jerk_weight=1e-4,
            timing="bounded",
            nodes_per_phase=16,
            checks_per_interval=3,
            max_iterations=1000,
        ),
        start=MIN_TIME.plan,
    )
)
MIN_JERK = register(
    # the smoothest cut bulges wide between points: shorter intervals, more checks, and
    # a wider reserve (one check and 0.5 %: ∫jerk² 0.123 against 0.265 rad²/s⁵ on the
    # paper's flap, but 0.23 mm off the contour on the large flap after three re-solves)
    OcpPlanner(
        "ocp-min-jerk",
        OcpSettings(jerk_weight=1.0, nodes_per_phase=16, checks_per_interval=3, margin=0.02),
        start=MIN_TIME.plan,
    )
)
MIX = register(
    OcpPlanner(
        "ocp-mix",
        # by default a quick and smooth cut; set the weights in [planner.ocp-mix]
        OcpSettings(
            timing="free",
            time_weight=1.0,
            jerk_weight=1.0,
            nodes_per_phase=16,
            checks_per_interval=3,
            margin=0.02,
        ),
        start=MIN_TIME.plan,
    )
)
