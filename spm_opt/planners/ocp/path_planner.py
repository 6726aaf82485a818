"""The optimal-control plans in path coordinates (``transcription = "path"``): solve, rebuild
the motion, judge it, and solve again with tighter bounds until the evaluator finds it clean.

The NLP (:mod:`~spm_opt.planners.ocp.path_nlp`) has no free durations: its only
nonlinearities are √β in the jerk, torque and time terms and the offset's products with β,
so FATROP or IPOPT (:mod:`~spm_opt.planners.ocp.path_solver`) converges in 24-35
iterations from a start at :data:`START_SPEED` of the speed limits with d = 0 (the
time-domain transcription: ~55 for minimum time, from toppra's motion, and 103-111 for the
other objectives). The plan is
the motion x describes, sampled :data:`SAMPLES_PER_INTERVAL` times an interval (q = q₀ + d v;
q̇ and q̈ from the formulas; times by 8-point Gauss–Legendre quadrature of du / √β), as
quintic Hermite pieces through the samples.

Without the offset (the contour followed exactly, at rest at every landmark, the same map
at every segment's two ends), the paper's flap took 38.42 s in 27 iterations: the stops
cost 0.44 s against this transcription's 37.98 s, more than toppra's 38.20 s.
"""

from __future__ import annotations

import dataclasses
import time
import weakref
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.base import interrupt
from spm_opt.base.errors import PlanningError
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.limits import PlannerBounds
from spm_opt.model.params import MM
from spm_opt.planners.ocp import ipopt
from spm_opt.planners.ocp.constraints import UNLIMITED
from spm_opt.planners.ocp.path_assembly import PathLayout
from spm_opt.planners.ocp.path_geometry import (
    SegmentPath,
    path_map,
    path_terms,
    segment_paths,
)
from spm_opt.planners.ocp.path_nlp import (
    CONTROL,
    ENDS,
    MIN_BETA,
    OBJECTIVES,
    PLACES,
    STATE,
    TERMS,
    advance,
)
from spm_opt.planners.ocp.path_solver import FATROP, IPOPT, MONOTONE_IPOPT, assembled_nlp, solver
from spm_opt.planners.ocp.refinement import REFINEMENTS, tightened
from spm_opt.planners.ocp.settings import OcpSettings
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

PATH_SAMPLES = 200
"""Inverse-kinematics samples per segment through which q₀(s) runs."""
ZONES = (2.0, 0.5)
"""Lengths of the grid's end zones over a ramp's (:mod:`path_geometry`): where the cut
starts or stops, and at a landmark it passes (on the paper's flap, 8 intervals a zone and 4
between, evenly spaced: corner zones of 0.5, 0.75 and 1 ramp gave 37.984, 37.996 and
38.004 s; 0.25 ramp with 10 between, 38.67 s; the rest zone matters less: 1, 1.5, 3 ramps
gave 37.979, 37.983, 37.985 s)."""
START_SPEED = 0.8
"""The start's cut speed, as a fraction of the fastest the speed limits allow."""
MAX_OFFSET = 1.0
"""Widest offset from the contour, mm, where the problem has no tube (or a wider one): the
offset's model of the motion is first order in it (on the hardware run, which has no tube,
minimum energy's cut strayed 33 mm without it, where that model's ∫τᵀτ was a quarter of the
evaluator's)."""
JERK_TIE_BREAKER = 1e-4
"""The largest jerk weight beside time or effort that counts as a tie-breaker (minimum
energy's 1e-4: weighed here, it traded ∫τᵀτ for smoothness, so that on the skull flap the
minimum-energy plan took 0.03 % more effort than the minimum-time one)."""
SAMPLES_PER_INTERVAL = 4
"""Samples of the plan per interval of the grid."""
FATROP_CONVERGED = "Success"
"""The status a FATROP solve that converged leaves in the plan's statistics (IPOPT's is
its own, :data:`~spm_opt.planners.ocp.ipopt.CONVERGED`)."""


def objectives(settings: OcpSettings) -> tuple[str, ...]:
    """The objective's terms (of :data:`~spm_opt.planners.ocp.path_nlp.OBJECTIVES`) that
    ``settings`` weigh. A jerk weight of at most :data:`JERK_TIE_BREAKER` beside another
    term is the time domain's tie-breaker; here the offset's smoothing term is."""
    tie_breaker = settings.jerk_weight <= JERK_TIE_BREAKER
    others = settings.time_weight > 0.0 or settings.energy_weight > 0.0
    weighed = {
        "time": settings.time_weight,
        "effort": settings.energy_weight,
        "jerk": 0.0 if tie_breaker and others else settings.jerk_weight,
    }
    return tuple(name for name in OBJECTIVES if weighed[name] > 0.0)


def _weights(settings: OcpSettings, weighed: tuple[str, ...], at_start: np.ndarray) -> np.ndarray:
    """The objective's weights (:data:`OBJECTIVES`'s order), each over its term's value at
    the start, so that the settings' weights compare like with like; 0 but ``weighed``."""
    given = np.array([settings.time_weight, settings.energy_weight, settings.jerk_weight])
    return np.where(np.isin(OBJECTIVES, weighed), given / at_start, 0.0)


def _limits(problem: Problem, bounds: PlannerBounds) -> np.ndarray:
    """The NLP's limits: tool speed (mm/s), joint speed, acceleration, jerk, torque, the
    tube (mm) and the drives' viscous friction (N·m·s/rad)."""

    def given(value: float | None, unit: float = 1.0) -> float:
        return UNLIMITED if value is None else value / unit

    return np.array(
        [
            given(bounds.tool_speed, MM),
            bounds.joint_speed,
            given(bounds.joint_acceleration),
            given(bounds.joint_jerk),
            bounds.load_torque,
            min(given(bounds.contour_tolerance, MM), MAX_OFFSET),
            *problem.robot.actuator.viscous_friction_nm_s_rad,
        ]
    )


def _path_parameters(problem: Problem, paths: list[SegmentPath]) -> np.ndarray:
    """The NLP's p but its limits: per segment the terms at every place, the interval
    lengths and the ends' terms."""
    lengths = [np.diff(path.nodes) for path in paths]
    places = np.array([*PLACES, 1.0])
    us = [
        (path.nodes[:-1, None] + length[:, None] * places).ravel()
        for path, length in zip(paths, lengths, strict=True)
    ]
    blocks = []
    for path, length, u, terms in zip(
        paths, lengths, us, path_terms(problem, paths, us), strict=True
    ):
        blocks.append(np.column_stack([terms[name].reshape(len(u), -1) for name in TERMS]).ravel())
        blocks.append(length)
        ends = path.geometry(path.nodes[[0, -1]])
        blocks.append(path.ends_speed_factor)
        blocks += [ends[name].ravel() for name in ENDS]
    return np.concatenate(blocks)


def _start(paths: list[SegmentPath], limits: np.ndarray, layout: PathLayout) -> np.ndarray:
    """x at :data:`START_SPEED` of the speed limits along the contour (d = 0)."""
    states = []
    for path in paths:
        factor = np.maximum(path_map(path.nodes / path.length, path.zones)[1], 0.3)
        pace = np.max(np.abs(path.joints(path.nodes, 1)))  # rad/mm
        speed = START_SPEED * min(limits[0], limits[1] / pace)  # mm/s
        states.append(np.zeros((len(path.nodes), STATE)))
        states[-1][:, 0] = (speed / factor) ** 2
    return layout.join(states, [np.zeros((len(path.nodes) - 1, CONTROL)) for path in paths])


def _retimed(
    problem: Problem,
    layout: PathLayout,
    integrals: ca.Function,
    x: np.ndarray,
    parameters: np.ndarray,
    timing: str,
) -> np.ndarray:
    """x at the problem's durations where the timing keeps them: each segment's
    (``"segments"``), their total (``"total"``, and ``"bounded"`` when x is slower); β and
    its derivatives scaled by the square of each segment's speed-up (``integrals``: the
    NLP's, for each segment's time)."""
    if timing == "free":
        return x
    times = integrals(x, parameters)[1].full().ravel()
    given = problem.segment_durations
    speedup = times / given if timing == "segments" else np.sum(times) / np.sum(given)
    if timing == "bounded":
        speedup = max(speedup, 1.0)
    parts: list[list[np.ndarray]] = [[], []]
    for segment, faster in enumerate(np.broadcast_to(speedup, len(given))):
        states, controls = layout.split(x, segment)
        states[:, :2] *= faster**2
        controls[:, 0] *= faster**2
        parts[0].append(states)
        parts[1].append(controls)
    return layout.join(*parts)


def _box(layout: PathLayout, tube_mm: float) -> dict[str, np.ndarray]:
    """Variable bounds: β > 0, the offset within the tube and 0 at every landmark, at rest
    at the first and the last."""
    low, high = [], []
    for segment in range(layout.segments):
        states_low = np.full((layout.intervals + 1, STATE), -np.inf)
        states_high = np.full((layout.intervals + 1, STATE), np.inf)
        states_low[:, 0] = MIN_BETA
        states_low[:, 2], states_high[:, 2] = -tube_mm, tube_mm
        states_low[[0, -1], 2] = states_high[[0, -1], 2] = 0.0
        if segment == 0:
            states_low[0, 3:5] = states_high[0, 3:5] = 0.0
        if segment == layout.segments - 1:
            states_low[-1, 3:5] = states_high[-1, 3:5] = 0.0
        low.append(states_low)
        high.append(states_high)
    controls = [np.full((layout.intervals, CONTROL), np.inf)] * layout.segments
    return {
        "lbx": layout.join(low, [-c for c in controls]),
        "ubx": layout.join(high, controls),
    }


Continuation = tuple[tuple[int, int, tuple[str, ...], str], dict[str, np.ndarray]]
SOLVED: weakref.WeakKeyDictionary[Trajectory, Continuation] = weakref.WeakKeyDictionary()
"""Each plan's NLP shape (segments, intervals, objectives, timing) and last solution with
its multipliers: the start of a similar problem's solve (``warm_start``)."""


def plan_in_path_coordinates(
    problem: Problem,
    settings: OcpSettings,
    bounds: PlannerBounds,
    name: str,
    warm_start: Trajectory | None = None,
) -> Trajectory:
    """The plan of ``settings``' objective and timing within ``bounds`` (the problem's, at
    the settings' margin), clean under the evaluator, or a :class:`PlanningError` naming
    what IPOPT or the evaluator found. ``warm_start``, a plan of an NLP of the same shape,
    is continued from its solution and multipliers.

    The evaluator decides each round: a clean plan is returned (its report kept with it by
    :func:`spm_opt.judge.evaluate.evaluate`, so whoever asked judges it without measuring it
    again), a broken one solved again with the bounds it broke tightened."""
    started = time.perf_counter()
    limits = _limits(problem, bounds)
    paths = segment_paths(
        problem,
        (limits[0], limits[1], limits[2], limits[3]),
        PATH_SAMPLES,
        settings.path_grid,
        ZONES,
    )
    intervals = len(paths[0].nodes) - 1
    weighed = objectives(settings)
    layout, nlp = assembled_nlp(len(paths), intervals, weighed, settings.timing)
    shape = (len(paths), intervals, weighed, settings.timing)
    solved = SOLVED.get(warm_start) if warm_start is not None else None
    continued = solved is not None and solved[0] == shape
    along = _path_parameters(problem, paths)  # the limits change between rounds, not these
    unweighted = np.concatenate([along, limits, np.ones(len(OBJECTIVES))])
    start = _start(paths, limits, layout)
    start = _retimed(problem, layout, nlp.integrals, start, unweighted, settings.timing)
    weights = _weights(settings, weighed, nlp.integrals(start, unweighted)[0].full().ravel())
    guess = solved[1] if continued else {"x0": start}
    statistics: dict[str, Any] = {"iterations": 0, "solve_time_s": 0.0, "function_time_s": 0.0}
    statistics["construction_time_s"] = time.perf_counter() - started
    low, high = layout.row_bounds(problem.segment_durations, settings.timing)
    for round_ in range(REFINEMENTS + 1):
        arguments = {
            **guess,
            "p": np.concatenate([along, limits, weights]),
            **_box(layout, limits[5]),
            "lbg": low,
            "ubg": high,
        }
        solution = _solve(
            layout, settings, weighed, continued or round_ > 0, arguments, name, statistics
        )
        rows = solution["g"].full().ravel()
        statistics.update(
            refinements=round_,
            constraint_violation=float(max(np.max(low - rows), np.max(rows - high), 0.0)),
            transcription="path",
            variables=layout.size,
            rows=int(rows.size),
            settings=dataclasses.asdict(settings),
        )
        statistics["start"] = "solution" if continued else "speed limits"
        x = solution["x"].full().ravel()
        trajectory = _trajectory(problem, paths, layout, x, statistics)
        broken = evaluate(problem, trajectory).violations  # decides: return or refine
        if not broken:
            SOLVED[trajectory] = (shape, ipopt.continuation(solution))
            return trajectory
        bounds = tightened(bounds, broken)
        limits = _limits(problem, bounds)
        guess = ipopt.continuation(solution)
    raise PlanningError(
        f"{name}: the evaluator still finds {'; '.join(map(str, broken))} after "
        f"{REFINEMENTS} re-solves with tighter bounds in path coordinates"
    )


def _solve(
    layout: PathLayout,
    settings: OcpSettings,
    weighed: tuple[str, ...],
    warm: bool,
    arguments: dict[str, Any],
    name: str,
    statistics: dict[str, Any],
) -> dict[str, Any]:
    """The NLP solved by FATROP or IPOPT as ``settings`` choose ("auto" continues a
    ``warm`` solve, from a solution and its multipliers, with IPOPT: FATROP takes no
    multipliers); when FATROP stops without converging, by IPOPT from the same start, and
    when IPOPT's adaptive barrier does, by its monotone one. Its iterations, times, solver
    and status added to ``statistics``; a :class:`PlanningError` when none converges."""
    fatrop = settings.fatrop and not (warm and settings.solver == "auto")
    tried = []
    for method in (*([FATROP] if fatrop else []), IPOPT, MONOTONE_IPOPT):
        solving_with = solver(layout.segments, layout.intervals, settings, weighed, warm, method)
        solving = time.perf_counter()
        solution = interrupt.solve(solving_with, **arguments)
        stats = solving_with.stats()
        statistics["iterations"] += int(stats["iter_count"])
        statistics["solve_time_s"] += time.perf_counter() - solving
        statistics["function_time_s"] += sum(
            v for k, v in stats.items() if k.startswith("t_wall_nlp")
        )
        if method == FATROP:
            converged = bool(stats["success"])
            status = FATROP_CONVERGED if converged else f"return code {stats['return_status']}"
        else:
            status = stats["return_status"]
            converged = status == ipopt.CONVERGED
        statistics.update(solver=method, status=status)
        tried.append(f"{method} stopped with {status} after {stats['iter_count']} iterations")
        if converged:
            return solution
    raise PlanningError(f"{name}: {'; '.join(tried)} in path coordinates")


def _trajectory(
    problem: Problem,
    paths: list[SegmentPath],
    layout: PathLayout,
    x: np.ndarray,
    statistics: dict[str, Any],
) -> Trajectory:
    """The motion x describes, sampled :data:`SAMPLES_PER_INTERVAL` times an interval."""
    parts: list[list[np.ndarray]] = [[], [], [], []]
    visits, at = [0.0], 0.0
    for segment, path in enumerate(paths):
        states, controls = layout.split(x, segment)
        t, q, qd, qdd = _segment_samples(path, states, controls)
        first = slice(None) if segment == 0 else slice(1, None)
        for part, values in zip(parts, (at + t, q, qd, qdd), strict=True):
            part.append(values[first])
        at += float(t[-1])
        visits.append(at)
    metadata = {
        "landmark_times_s": visits,
        "landmarks": problem.visit_names,
        "statistics": {**statistics, "duration_s": at},
    }
    t, q, qd, qdd = (np.concatenate(part) for part in parts)
    return Trajectory.from_samples(t, q, qd, qdd, metadata=metadata)


def _segment_samples(
    path: SegmentPath, states: np.ndarray, controls: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Times from the segment's start (s), q, q̇, q̈ (rad, rad/s, rad/s²) at its samples."""
    intervals = len(path.nodes) - 1
    index = np.append(np.repeat(np.arange(intervals), SAMPLES_PER_INTERVAL), intervals - 1)
    fraction = np.append(
        np.tile(np.arange(SAMPLES_PER_INTERVAL) / SAMPLES_PER_INTERVAL, intervals), 1.0
    )
    offset = fraction * np.diff(path.nodes)[index]
    beta, slope, d, d1, d2 = advance(_columns(states[index]), _columns(controls[index]), offset)
    u = path.nodes[index] + offset
    middle, half = (u[1:] + u[:-1]) / 2, (u[1:] - u[:-1]) / 2
    points, weights = np.polynomial.legendre.leggauss(8)
    at = middle[:, None] + half[:, None] * points
    which = np.clip(np.searchsorted(path.nodes, at, side="right") - 1, 0, intervals - 1)
    beta_at = advance(_columns(states[which]), _columns(controls[which]), at - path.nodes[which])[0]
    t = np.concatenate(
        [[0.0], np.cumsum(np.sum(half[:, None] * weights / np.sqrt(beta_at), axis=1))]
    )
    terms = path.geometry(u)
    qu = terms["A1"] + d1[:, None] * terms["v"] + d[:, None] * terms["v1"]
    quu = (
        terms["A2"]
        + d2[:, None] * terms["v"]
        + 2 * d1[:, None] * terms["v1"]
        + d[:, None] * terms["v2"]
    )
    q = terms["q"] + d[:, None] * terms["v"]
    qd = qu * np.sqrt(beta)[:, None]
    qdd = qu * slope[:, None] / 2 + quu * beta[:, None]
    return t, q, qd, qdd


def _columns(values: np.ndarray) -> np.ndarray:
    """An array's last axis first: its components, for :func:`path_nlp.advance`."""
    return np.moveaxis(values, -1, 0)
