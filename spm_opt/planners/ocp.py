"""Optimal-control planners: minimum time, energy or jerk through the landmarks, on the cut,
within the actuators' limits (CasADi + IPOPT).

Transcription: each segment between consecutive landmark visits is three phases: a short one
at each end, where the cut starts, stops or turns a corner, and the middle, with
``corner_nodes``, ``nodes_per_phase`` and ``corner_nodes`` uniform intervals; the phases'
durations are variables (see ``timing``). The state is (q, q̇, q̈) and the control is the
jerk, constant on each interval, so the motion is integrated exactly: q is a piecewise cubic
in time, and the returned :class:`Trajectory` (quintic Hermite through the nodes) reproduces
it exactly. Landmarks are reached exactly at the phase boundaries; the motion starts and
ends at rest.

Constraints, from the one model and the problem's limits, at every node and at
``checks_per_interval`` evenly spaced points inside every interval (the torque, the costly
rows, at the nodes and midpoints): the load torque with the rotor's J q̈ (Lagrange model,
smooth friction, payload) within :mod:`spm_opt.limits`' bound for it; joint speed,
acceleration and jerk bounds; the joint range; the tool's speed on the skull
(|Ṗ|² = ρ²|ṗ|² + ρ̇², as the evaluator measures it) at most
``max_tool_speed``; and the cut point within ``contour_tolerance`` of the segment's
great-circle arc (the chord 2ρ sin(δ/2), δ the angle off the arc's plane) and between its
end landmarks. Each limit keeps a reserve of ``margin`` (a fraction) for what happens
between the points where it is imposed; the evaluator re-measures the plan on a fine grid.

Objectives: total time (``ocp-min-time``); ∫ τᵀτ dt (``ocp-min-energy``; with a linear
current map this is proportional to the copper losses ∫ I²R dt, without needing the
winding resistance nobody publishes); ∫ jerkᵀjerk dt (``ocp-min-jerk``); or a weighted mix
(``ocp-mix``; by default time and jerk). Durations are free for minimum time and the mix;
the others keep the problem's total duration and choose its split between segments
(``timing`` in the settings).

Solver: IPOPT with an adaptive barrier (61 iterations on the paper's minimum-time problem
against 265 with the monotone default); the path rows are expanded into one SX graph (each
iteration three times cheaper), the torque rows are not (expanding them takes ~40 s).

The NLP is built once per (number of phases, settings) with every problem-dependent number
(landmarks, arcs, robot parameters, weights) as a parameter, so a second problem of the
same shape reuses it.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from functools import cache
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.bounds import segment_lower_bounds
from spm_opt.errors import PlanningError
from spm_opt.evaluate import Violation, evaluate
from spm_opt.limits import RELATIVE_TOLERANCE, PlannerBounds, planner_bounds
from spm_opt.model import dynamics, kinematics
from spm_opt.model.params import MM
from spm_opt.planners.contour_guess import segment_motion
from spm_opt.planners.registry import planner_options, register, settings_from_options
from spm_opt.problem import Problem
from spm_opt.trajectory import Trajectory

UNLIMITED = 1e3
"""Stands in for a limit the problem leaves open (in the limit's SI unit)."""
MIN_CONTOUR_TOLERANCE = 1e-6
"""Narrowest contour tube the planners accept, m: a zero-width tube has no interior."""
_ARC_PARAMETERS = 14  # a, w, n, w_end (3 each), ρ0 (mm), ρ' (mm/rad)


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
        Points inside each interval where the limits are imposed besides the nodes (1: the
        midpoint; 3: the quarter points).
    margin : float
        Fraction of each limit kept in reserve for the motion between constraint points.
    timing : str
        "free" (every duration a variable: minimum time), "total" (the problem's total
        duration kept, its split between segments free) or "segments" (each segment's
        duration as the problem gives it).
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


TIMINGS = ("free", "total", "segments")
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

CORNER_SHARE = 0.05
"""Share of a segment's duration each corner phase takes in the initial guess."""


@dataclass(frozen=True)
class _Grid:
    """The time grid: each segment is three phases (corner, middle, corner) of uniform
    intervals; D = 3 × segments duration variables, M intervals, M + 1 nodes."""

    segments: int
    counts: tuple[int, int, int]

    @property
    def per_segment(self) -> int:
        return sum(self.counts)

    @property
    def intervals(self) -> int:
        return self.segments * self.per_segment

    @property
    def interval_matrix(self) -> np.ndarray:
        """(M, D): interval lengths = this @ phase durations."""
        matrix = np.zeros((self.intervals, 3 * self.segments))
        row = 0
        for phase in range(3 * self.segments):
            count = self.counts[phase % 3]
            matrix[row : row + count, phase] = 1.0 / count
            row += count
        return matrix

    @property
    def segment_matrix(self) -> np.ndarray:
        """(segments, D): segment durations = this @ phase durations."""
        return np.kron(np.eye(self.segments), np.ones((1, 3)))

    @property
    def landmark_nodes(self) -> np.ndarray:
        return np.arange(self.segments + 1) * self.per_segment

    def fractions(self, checks: int) -> np.ndarray:
        """Where the ``checks`` points inside each interval sit, as fractions of it."""
        return np.arange(1, checks + 1) / (checks + 1)

    def node_segments(self) -> np.ndarray:
        """Segment of every node (M + 1,); a landmark node belongs to the segment it starts
        (the last node to the last segment)."""
        return np.minimum(np.arange(self.intervals + 1) // self.per_segment, self.segments - 1)

    def inner_segments(self, checks: int) -> np.ndarray:
        """Segment of every inner point (checks × M,), ordered fraction by fraction."""
        return np.tile(np.arange(self.intervals) // self.per_segment, checks)

    def phase_durations(self, segment_durations: np.ndarray) -> np.ndarray:
        """The initial split of segment durations into phases (D,)."""
        shares = np.array([CORNER_SHARE, 1.0 - 2 * CORNER_SHARE, CORNER_SHARE])
        return np.outer(segment_durations, shares).ravel()

    def node_times(self, phase_durations: np.ndarray) -> np.ndarray:
        """Times (M + 1,), s, of the nodes from the start."""
        return np.concatenate([[0.0], np.cumsum(self.interval_matrix @ phase_durations)])

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The NLP's x as node states (M + 1, 6) = (q, q̇, q̈), jerks (M, 2) and phase
        durations (D,); x stacks them in that order."""
        n_states, n_jerks = 6 * (self.intervals + 1), 2 * self.intervals
        return (
            np.reshape(x[:n_states], (-1, 6)),
            np.reshape(x[n_states : n_states + n_jerks], (-1, 2)),
            x[n_states + n_jerks :],
        )

    def trajectory(self, x: np.ndarray, metadata: dict[str, Any]) -> Trajectory:
        """The motion x describes: exact, since each interval is a cubic in time."""
        states, _, durations = self.split(x)
        t = self.node_times(durations)
        return Trajectory.from_samples(
            t, states[:, 0:2], states[:, 2:4], states[:, 4:6], metadata=metadata
        )


@dataclass(frozen=True)
class _Layout:
    """Where things sit in the NLP: the grid (x) and the constraint groups (g)."""

    grid: _Grid
    checks: int  # points inside each interval
    groups: tuple[tuple[str, int, int, int], ...]  # (name, start, rows per point, points)

    def where(self, group: str, point: int) -> tuple[int, float]:
        """Segment of a constraint point of ``group``, and its place in it in intervals."""
        grid = self.grid
        if group.endswith("nodes"):
            segment = int(grid.node_segments()[point])
            return segment, float(point - segment * grid.per_segment)
        if group.endswith("midpoints"):
            segment = point // grid.per_segment
            return segment, point - segment * grid.per_segment + 0.5
        interval, which = point % grid.intervals, point // grid.intervals
        segment = interval // grid.per_segment
        place = interval - segment * grid.per_segment + grid.fractions(self.checks)[which]
        return segment, float(place)


def _grid(segments: int, settings: OcpSettings) -> _Grid:
    corner = settings.corner_nodes
    return _Grid(segments, (corner, settings.nodes_per_phase, corner))


PATH_ROWS = ("tool speed", "contour deviation", "segment start", "segment end")
"""The rows of the path constraints at each point, in order."""


@cache
def _path_function() -> ca.Function:
    """(q, q̇, arc) -> tool speed² (mm²/s²), chord² off the arc (mm²), and the two wedge
    conditions that keep the cut between the segment's end landmarks (≥ 0), at one point."""
    q, qd, arc = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("arc", _ARC_PARAMETERS)
    a, w, n, w_end = (arc[3 * k : 3 * k + 3] for k in range(4))
    rho0, slope = arc[12], arc[13]
    p = ca.vertcat(*kinematics.direction(q[0], q[1]))
    d1, d2 = kinematics.direction_jacobian(q[0], q[1])
    p_dot = ca.vertcat(*d1) * qd[0] + ca.vertcat(*d2) * qd[1]
    pa, pw = ca.dot(p, a), ca.dot(p, w)
    rho = rho0 + slope * ca.atan2(pw, pa)
    angle_rate = (ca.dot(p_dot, w) * pa - pw * ca.dot(p_dot, a)) / (pa**2 + pw**2)
    off_plane = ca.dot(p, n)
    rows = ca.vertcat(
        ca.sumsqr(p_dot) * rho**2 + (slope * angle_rate) ** 2,
        2 * rho**2 * (1 - ca.sqrt(1 - off_plane**2)),
        pw,
        -ca.dot(p, w_end),
    )
    return ca.Function("path", [q, qd, arc], [rows])


@cache
def _torque_function() -> ca.Function:
    """(q, q̇, q̈, robot) -> actuator torques with smooth friction (the optimisers' form)."""
    model = dynamics._model().torque
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    robot = ca.SX.sym("robot", model.size1_in(3))
    frictionless, smooth, _ = model(q, qd, qdd, robot)
    return ca.Function("torque", [q, qd, qdd, robot], [frictionless + smooth])


def _advance(x: ca.MX, u: ca.MX, h: ca.MX) -> ca.MX:
    """States (6 × M) after h (1 × M) under constant jerks u (2 × M): exact integration."""
    q, qd, qdd = x[0:2, :], x[2:4, :], x[4:6, :]
    h2 = ca.repmat(h, 2, 1)
    return ca.vertcat(
        q + h2 * qd + h2**2 / 2 * qdd + h2**3 / 6 * u,
        qd + h2 * qdd + h2**2 / 2 * u,
        qdd + h2 * u,
    )


@cache
def _nlp(
    segments: int, settings: OcpSettings, with_torque: bool
) -> tuple[ca.Function, ca.Function, _Layout]:
    """The solver, a function of the objective's three terms, and the layout, for
    ``segments`` segments, with or without the dynamics (cached per process).

    Constraints are imposed at the M + 1 nodes and at ``checks_per_interval`` points inside
    each interval, the torque's (the costly rows) at the nodes and midpoints only, where
    Simpson's rule also integrates τᵀτ; p holds every segment's arc, the robot, the
    weights and scales.
    """
    grid = _grid(segments, settings)
    m, checks = grid.intervals, settings.checks_per_interval
    fractions = grid.fractions(checks)
    states, jerks = ca.MX.sym("x", 6, m + 1), ca.MX.sym("u", 2, m)
    durations = ca.MX.sym("T", 3 * segments)
    n_robot = dynamics._model().torque.size1_in(3)
    arcs = ca.MX.sym("arcs", _ARC_PARAMETERS, segments)
    robot, weights, scales = ca.MX.sym("robot", n_robot), ca.MX.sym("w", 3), ca.MX.sym("s", 3)
    rotor = ca.MX.sym("rotor")  # the actuators' reflected rotor inertia, kg·m²
    node_arcs = arcs @ ca.DM(np.eye(segments)[:, grid.node_segments()])
    inner_arcs = arcs @ ca.DM(np.eye(segments)[:, grid.inner_segments(checks)])

    h = (ca.DM(grid.interval_matrix) @ durations).T  # 1 × M
    before = states[:, :-1]
    continuity = states[:, 1:] - _advance(before, jerks, h)
    inner = ca.horzcat(*(_advance(before, jerks, f * h) for f in fractions))  # 6 × checks·M
    path = _path_function()
    blocks = [
        ("continuity", ca.vec(continuity), 6, m),
        ("segment durations", ca.DM(grid.segment_matrix) @ durations, 1, segments),
        ("total duration", ca.sum1(durations), 1, 1),
        (
            "path at nodes",
            ca.vec(path.map(m + 1)(states[0:2, :], states[2:4, :], node_arcs)),
            4,
            m + 1,
        ),
        (
            "path inside intervals",
            ca.vec(path.map(checks * m)(inner[0:2, :], inner[2:4, :], inner_arcs)),
            4,
            checks * m,
        ),
        ("joint speed inside intervals", ca.vec(inner[2:4, :]), 2, checks * m),
    ]
    effort = ca.MX(0)
    if with_torque:
        torque = _torque_function()
        at_nodes = torque.map(m + 1)(states[0:2, :], states[2:4, :], states[4:6, :], robot)
        at_nodes += rotor * states[4:6, :]
        middle = _advance(before, jerks, h / 2)
        at_middle = torque.map(m)(middle[0:2, :], middle[2:4, :], middle[4:6, :], robot)
        at_middle += rotor * middle[4:6, :]
        blocks.append(("torque at nodes", ca.vec(at_nodes), 2, m + 1))
        blocks.append(("torque at midpoints", ca.vec(at_middle), 2, m))
        squares_nodes, squares_middle = ca.sum1(at_nodes**2), ca.sum1(at_middle**2)
        simpson = (squares_nodes[:-1] + 4 * squares_middle + squares_nodes[1:]) / 6
        effort = ca.sum2(h * simpson)
    jerk_integral = ca.sum2(h * ca.sum1(jerks**2))
    total_time = ca.sum1(durations)
    objective = (
        weights[0] * total_time / scales[0]
        + weights[1] * effort / scales[1]
        + weights[2] * jerk_integral / scales[2]
    )
    groups, start = [], 0
    for name, value, size, points in blocks:
        groups.append((name, start, size, points))
        start += value.numel()
    x = ca.vertcat(ca.vec(states), ca.vec(jerks), durations)
    parameters = ca.vertcat(ca.vec(arcs), robot, rotor, weights, scales)
    layout = _Layout(grid=grid, checks=checks, groups=tuple(groups))
    options = {
        "ipopt": {
            "max_iter": settings.max_iterations,
            "tol": settings.tolerance,
            "print_level": settings.print_level,
            "sb": "yes",
            "mu_strategy": "adaptive",
            "acceptable_iter": settings.acceptable_iterations,
            **(_WARM_START if settings.acceptable_iterations == 0 else {}),
        },
        "print_time": False,
        "expand": not with_torque,
    }
    g = ca.vertcat(*(value for _, value, _, _ in blocks))
    nlp = {"x": x, "p": parameters, "f": objective, "g": g}
    terms = ca.Function("terms", [x, parameters], [total_time, effort, jerk_integral])
    return ca.nlpsol("ocp", "ipopt", nlp, options), terms, layout


def _arcs(problem: Problem) -> np.ndarray:
    """Per segment (segments, 14): the arc's a, w, n, n × end, ρ0 (mm), ρ' (mm/rad) (the
    great circle the cut follows, as the Contour has it). Lengths in mm keep the squared
    rows of the path constraints near 1."""
    contour = problem.contour
    sweep = contour.sweep[:, None]
    end = contour.start * np.cos(sweep) + contour.inplane * np.sin(sweep)
    return np.concatenate(
        [
            contour.start,
            contour.inplane,
            contour.normal,
            np.cross(contour.normal, end),
            contour.start_radius[:, None] / MM,
            contour.radius_slope[:, None] / MM,
        ],
        axis=1,
    )


def _parameters(problem: Problem, weights: list[float], scales: np.ndarray) -> np.ndarray:
    robot = dynamics.parameter_vector(problem.robot).ravel()
    rotor = [problem.robot.actuator.rotor_inertia_kg_m2]
    return np.concatenate([_arcs(problem).ravel(), robot, rotor, weights, scales])


def _guess(
    problem: Problem, grid: _Grid, segment_durations: np.ndarray, warm_start: Trajectory | None
) -> np.ndarray:
    """The initial x: from the warm start when it visits the same landmarks, else the
    contour-following motion over ``segment_durations``."""
    phases = grid.phase_durations(segment_durations)
    visits = None if warm_start is None else warm_start.metadata.get("landmark_times_s")
    if visits is not None and len(visits) == grid.segments + 1:
        phases = grid.phase_durations(np.diff(np.asarray(visits, dtype=float)))
        t = grid.node_times(phases)
        q, qd, qdd = warm_start.position(t), warm_start.velocity(t), warm_start.acceleration(t)
    else:
        t = grid.node_times(phases)
        landmarks = t[grid.landmark_nodes]
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


def _check_feasible_at_all(problem: Problem, timing: str, margin: float) -> np.ndarray:
    """Refuse what no solver can do, with the reason; return the segments' lower bounds."""
    limits, names = problem.limits, problem.visit_names
    if limits.contour_tolerance is not None and limits.contour_tolerance < MIN_CONTOUR_TOLERANCE:
        raise PlanningError(
            f"contour_tolerance_mm = {limits.contour_tolerance / MM:g}: the cut would have to "
            f"turn every corner exactly; give at least {MIN_CONTOUR_TOLERANCE / MM:g} mm"
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
    problem: Problem, layout: _Layout, bounds: PlannerBounds, timing: str, durations: np.ndarray
) -> dict[str, np.ndarray]:
    """lbx, ubx, lbg, ubg for one problem within ``bounds`` (the problem's limits as
    :mod:`spm_opt.limits` translates them for a planner); ``durations``: the initial phase
    durations (D,), s."""
    speed = bounds.joint_speed
    acceleration = bounds.joint_acceleration or UNLIMITED
    jerk = bounds.joint_jerk or UNLIMITED
    grid = layout.grid
    m, inner = grid.intervals, layout.checks * grid.intervals
    low = np.tile(
        [*bounds.joint_range[:, 0], -speed, -speed, -acceleration, -acceleration], (m + 1, 1)
    )
    high = -low
    high[:, 0:2] = bounds.joint_range[:, 1]
    landmarks = grid.landmark_nodes
    low[landmarks, 0:2] = high[landmarks, 0:2] = problem.waypoint_angles
    low[[0, -1], 2:6] = high[[0, -1], 2:6] = 0.0
    longest = 20.0 * np.max(durations) + 1.0
    lbx = np.concatenate([low.ravel(), np.full(2 * m, -jerk), np.full(3 * grid.segments, 1e-3)])
    ubx = np.concatenate([high.ravel(), np.full(2 * m, jerk), np.full(3 * grid.segments, longest)])
    segments = (0.5 * segment_lower_bounds(problem), np.full(grid.segments, np.inf))
    total = (-np.inf, np.inf)
    if timing == "segments":
        segments = (problem.segment_durations, problem.segment_durations)
    elif timing == "total":
        total = (np.sum(problem.segment_durations),) * 2

    torque = bounds.load_torque
    tool = (bounds.tool_speed or UNLIMITED) / MM
    tolerance = (bounds.contour_tolerance or UNLIMITED) / MM
    path_low = np.array([-np.inf, -np.inf, 0.0, 0.0])
    path_high = np.array([tool**2, tolerance**2, np.inf, np.inf])
    node_low, node_high = np.tile(path_low, (m + 1, 1)), np.tile(path_high, (m + 1, 1))
    node_low[landmarks, 1:], node_high[landmarks, 1:] = -np.inf, np.inf  # fixed angles there
    rows = {
        "continuity": (np.zeros(6 * m), np.zeros(6 * m)),
        "segment durations": segments,
        "total duration": (np.array([total[0]]), np.array([total[1]])),
        "path at nodes": (node_low.ravel(), node_high.ravel()),
        "path inside intervals": (np.tile(path_low, inner), np.tile(path_high, inner)),
        "joint speed inside intervals": (np.full(2 * inner, -speed), np.full(2 * inner, speed)),
        "torque at nodes": (np.full(2 * (m + 1), -torque), np.full(2 * (m + 1), torque)),
        "torque at midpoints": (np.full(2 * m, -torque), np.full(2 * m, torque)),
    }
    lbg = [rows[name][0] for name, *_ in layout.groups]
    ubg = [rows[name][1] for name, *_ in layout.groups]
    return {"lbx": lbx, "ubx": ubx, "lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg)}


_ROW_NAMES = {
    "path at nodes": PATH_ROWS,
    "path inside intervals": PATH_ROWS,
    "joint speed inside intervals": ("joint speed",) * 2,
    "torque at nodes": ("actuator torque",) * 2,
    "torque at midpoints": ("actuator torque",) * 2,
    "continuity": ("continuity",) * 6,
}
_UNITS = {  # scale to the unit shown, unit, whether the row holds a square
    "tool speed": (1.0, "mm/s", True),
    "contour deviation": (1.0, "mm", True),
    "actuator torque": (1.0, "N·m", False),
    "joint speed": (1.0, "rad/s", False),
}


def _worst_constraint(
    layout: _Layout, g: np.ndarray, bounds: dict[str, np.ndarray], names: list[str]
) -> str:
    """The most violated path constraint (or, with none violated, the nearest to binding),
    in words: what, its value and limit, and where."""
    best: tuple[float, str] | None = None
    for group, start, size, points in layout.groups:
        if group in ("continuity", "segment durations", "total duration"):
            continue
        stop = start + size * points
        values, low, high = g[start:stop], bounds["lbg"][start:stop], bounds["ubg"][start:stop]
        limit = np.where(np.isfinite(high), high, low)
        relevant = np.isfinite(limit)
        excess = np.where(relevant, np.maximum(values - high, low - values), -np.inf)
        relative = np.full(values.shape, -np.inf)
        np.divide(excess, np.maximum(np.abs(limit), 1e-12), out=relative, where=relevant)
        row = int(np.argmax(relative))
        if not relevant[row] or (best is not None and relative[row] <= best[0]):
            continue
        point = row // size
        name = _ROW_NAMES[group][row % size]
        unit, label, squared = _UNITS.get(name, (1.0, "", False))
        value, bound = values[row], limit[row]
        if squared:
            value, bound = math.sqrt(max(value, 0.0)), math.sqrt(bound)
        segment, position = layout.where(group, point)
        best = (
            relative[row],
            f"{name} {value / unit:.4g} {label} against {bound / unit:.4g} {label} in "
            f"segment {names[segment]}→{names[segment + 1]}, "
            f"at {position:.3g} of its {layout.grid.per_segment} intervals",
        )
    return "none" if best is None else best[1]


@dataclass(frozen=True)
class OcpPlanner:
    """An optimal-control planner with fixed weights; see the module docstring."""

    name: str
    defaults: OcpSettings

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
        durations = {
            "segments": problem.segment_durations,
            "total": need * np.sum(problem.segment_durations) / np.sum(need),
            "free": 1.3 * need,
        }[settings.timing]
        grid = _grid(len(durations), settings)
        x0 = _guess(problem, grid, durations, warm_start)
        with_torque = settings.energy_weight > 0.0
        bounds = planner_bounds(problem, settings.margin)
        x, statistics = self._solve(problem, settings, bounds, with_torque, x0)
        for round_ in range(1, REFINEMENTS + 2):
            if not with_torque and _torque_exceeded(problem, grid, bounds, x):
                with_torque = True
                x, again = self._solve(problem, settings, bounds, with_torque, x)
                statistics = _added(statistics, again)
            statistics["refinements"] = round_ - 1
            trajectory = self._trajectory(problem, grid, x, statistics, settings)
            broken = evaluate(problem, trajectory).violations
            if not broken:
                return trajectory
            if round_ > REFINEMENTS:
                break
            # from x alone: continuing with its multipliers as well halves the iterations
            # but ends in worse optima (five landmarks: ∫τᵀτ 0.885 against 0.855)
            bounds = _tightened(bounds, broken)
            x, again = self._solve(problem, settings, bounds, with_torque, x)
            statistics = _added(statistics, again)
        raise PlanningError(
            f"{self.name}: the evaluator still finds {'; '.join(map(str, broken))} after "
            f"{REFINEMENTS} re-solves with tighter bounds; raise planner.{self.name}."
            "checks_per_interval or margin"
        )

    def _trajectory(
        self,
        problem: Problem,
        grid: _Grid,
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
        with_torque: bool,
        x0: np.ndarray,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Solve from ``x0``; the solution x and the statistics. An early stop at IPOPT's
        acceptable level is continued strictly from there (with its multipliers)."""
        started = time.perf_counter()
        solver, terms, layout = _nlp(len(problem.segment_durations), settings, with_torque)
        construction = time.perf_counter() - started
        weights = [settings.time_weight, settings.energy_weight, settings.jerk_weight]
        at_guess = terms(x0, _parameters(problem, weights, np.ones(3)))
        scales = np.maximum(np.abs([float(v) for v in at_guess]), 1e-9)  # terms at the guess
        parameters = _parameters(problem, weights, scales)
        box = _bounds(problem, layout, bounds, settings.timing, layout.grid.split(x0)[2])
        started = time.perf_counter()
        solution = solver(x0=x0, p=parameters, **box)
        stats = solver.stats()
        statuses, iterations = [stats["return_status"]], int(stats["iter_count"])
        if stats["return_status"] == ACCEPTABLE:  # loose: re-solve strictly from there
            strict = dataclasses.replace(settings, acceptable_iterations=0)
            solver = _nlp(len(problem.segment_durations), strict, with_torque)[0]
            solution = solver(**_continuation(solution), p=parameters, **box)
            stats = solver.stats()
            statuses.append(stats["return_status"])
            iterations += int(stats["iter_count"])
        wall = time.perf_counter() - started
        x, g = solution["x"].full().ravel(), solution["g"].full().ravel()
        most = _worst_constraint(layout, g, box, problem.visit_names)
        if stats["return_status"] != CONVERGED:
            raise PlanningError(
                f"{self.name}: IPOPT stopped with {' then '.join(statuses)} after "
                f"{iterations} iterations; most violated: {most}"
            )
        total_time, effort, jerk_integral = (float(v) for v in terms(x, parameters))
        return x, {
            "status": stats["return_status"],
            "statuses": statuses,
            "iterations": iterations,
            "solve_time_s": wall,
            "function_time_s": sum(v for k, v in stats.items() if k.startswith("t_wall_nlp")),
            "construction_time_s": construction,
            "constraint_violation": float(max(np.max(box["lbg"] - g), np.max(g - box["ubg"]), 0.0)),
            "most_binding": most,
            "torque_in_nlp": with_torque,
            "duration_s": total_time,
            "effort_n2m2s": effort if with_torque else None,
            "jerk_integral_rad2_s5": jerk_integral,
        }


def _continuation(solution: dict[str, ca.DM]) -> dict[str, ca.DM]:
    """IPOPT's warm start from a solution: its x and multipliers."""
    return {"x0": solution["x"], "lam_x0": solution["lam_x"], "lam_g0": solution["lam_g"]}


def _torque_exceeded(problem: Problem, grid: _Grid, bounds: PlannerBounds, x: np.ndarray) -> bool:
    """Whether the load torques (smooth friction, rotor inertia) at the nodes and midpoints
    of x (where the NLP would impose them) exceed ``bounds``' torque bound."""
    motion = grid.trajectory(x, {})
    nodes = grid.node_times(grid.split(x)[2])
    t = np.concatenate([nodes, (nodes[:-1] + nodes[1:]) / 2])
    q, qd, qdd = motion.position(t), motion.velocity(t), motion.acceleration(t)
    torque = dynamics.inverse_dynamics(problem.robot, q, qd, qdd, exact=False)
    return bool(np.max(np.abs(torque + bounds.rotor_inertia * qdd)) > bounds.load_torque)


REFINEMENTS = 3
"""Re-solves, each with tighter bounds for whatever the evaluator found exceeded between
the constraint points, before the planner gives up."""
_TIGHTENED = {  # the evaluator's rule: the bound that keeps it
    "joint speed": "joint_speed",
    "joint acceleration": "joint_acceleration",
    "joint jerk": "joint_jerk",
    "acceleration step": "joint_jerk",
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
    for key in ("solve_time_s", "function_time_s", "iterations"):
        again[key] += statistics[key]
    again["statuses"] = statistics["statuses"] + again["statuses"]
    return again


MIN_TIME = register(
    OcpPlanner(
        "ocp-min-time",
        OcpSettings(timing="free", time_weight=1.0, jerk_weight=1e-6),
    )
)
MIN_ENERGY = register(
    # its slow corners bulge between the points, as min-jerk's do (with min-time's grid the
    # tool reached 3.05 mm/s, and the cut 0.16 mm off the contour, between two points)
    OcpPlanner(
        "ocp-min-energy",
        OcpSettings(
            energy_weight=1.0,
            jerk_weight=1e-4,
            nodes_per_phase=16,
            checks_per_interval=3,
            margin=0.02,
        ),
    )
)
MIN_JERK = register(
    OcpPlanner(
        "ocp-min-jerk",
        # the smoothest cut bulges wide between points: shorter intervals, more checks
        OcpSettings(jerk_weight=1.0, nodes_per_phase=16, checks_per_interval=3, margin=0.02),
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
    )
)
