"""Excitation plans for identifying the robot's parameters: the motion that tells the most
about them within every limit of the robot.

    [planner.excitation]
    duration_s = 60.0   # the whole plan, s
    periods = 4         # repeats of one period (so a period is 15 s)
    harmonics = 5       # sine terms per joint: the top one at harmonics × periods / duration Hz

Each joint follows a finite Fourier series about the problem's first landmark (Swevers,
Ganseman, Tükel, De Schutter and Van Brussel, IEEE Trans. Robotics and Automation 13(5),
1997), with T the period, ω = 2π/T and q0 the landmark's joint angles:

    q(t) = q0 + Σ_k a_k/(kω) sin kωt − b_k/(kω) (cos kωt − 1),
    q̇(t) = Σ_k a_k cos kωt + b_k sin kωt,

and Σ a_k = 0, Σ k b_k = 0 put it at rest (q̇ = q̈ = 0) at q0 at every whole period, so the
plan starts and ends at rest there. The coefficients maximise the information in the base
regressor (:mod:`spm_opt.model.regressor`, :mod:`spm_opt.model.base_parameters`) over one
period: log det(W_bᵀW_b) of the base columns stacked over :attr:`points_per_period` grid
points (D-optimal design), its columns scaled once by their norms at the start. The design
counts the base parameters a motion can bring out (:func:`designed`): not the products of
inertia, whose torques stay far below what the actuators' current resolves, nor the drives'
offsets, which every motion shows alike. Measured on the simulated robot with
prototype_plant.toml (identification.toml, 120 s): designed on those 14 of the 22, the
gravity terms' standard errors fell from 2.5–7 % to 1–3 %, the rails' and the joints'
Coulomb friction's from 8–20 % to 5–9 %, and the plan took 6 s instead of 25 s. The same
symbolic model as every planner's, solved by IPOPT (limited-memory Hessian; its
20 coefficients are few): the joint range (hard, :data:`RANGE_CLEARANCE_RAD` inside it),
the singularity margin, the joint speed, acceleration and jerk less ``margin`` and the
actuator torque (the optimal-control planners' joint side torque,
:func:`spm_opt.model.joint_torque.load_torque`) imposed at the grid points. The Coulomb column
is smoothed by tanh(q̇/:data:`COULOMB_SMOOTHING_RAD_S`) for the design only.

The plan ignores the contour: its metadata say so (``ignores_contour``) and the evaluator
judges it by the robot's limits alone. It is a :class:`Trajectory` like every plan, sampled
at :data:`SAMPLE_RATE_HZ` with its exact position, rate and acceleration.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cache
from typing import Any

import casadi as ca
import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.base.interrupt import solve
from spm_opt.judge.evaluate import evaluate
from spm_opt.judge.limits import planner_bounds
from spm_opt.model import dynamics, kinematics
from spm_opt.model.base_parameters import BaseParameters, base_parameters
from spm_opt.model.joint_torque import dynamics_parameters, load_torque, range_key
from spm_opt.model.regressor import (
    DRIVE_PARAMETERS,
    DRIVE_TERMS,
    STANDARD_PARAMETERS,
    drive_columns,
    link_function,
)
from spm_opt.planners.registry import planner_options, register, settings_from_options
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory

RANGE_CLEARANCE_RAD = np.deg2rad(0.5)
"""How far inside the joint range the grid points stay, rad: the range is hard, and the
motion between grid points must not reach it."""
SINGULARITY_CLEARANCE = 0.01
"""How far above the robot's smallest singularity margin the grid points stay."""
COULOMB_SMOOTHING_RAD_S = 0.01
"""Rate, rad/s, over which the design's Coulomb column goes from −1 to 1."""
SAMPLE_RATE_HZ = 200.0
"""Samples per second of the plan (each piece a quintic through exact q, q̇, q̈)."""
ACCEPTABLE_CHANGE = 1e-4
"""IPOPT stops once the objective (−log det) changes by less than this share of itself in
10 iterations in a row: the design is feasible throughout, and its information settles
long before L-BFGS's multipliers do."""
FEASIBLE_EXCESS = 1e-6
"""Largest excess over a grid point's bound (in the bound's unit; IPOPT relaxes bounds by
1e-8 of their size) of a design accepted however IPOPT stopped: the start is feasible and
so is every iterate, so a design stopped at the iteration limit is a plan too."""
START_SPEED_SHARE = 0.3
"""The start's peak joint speed and acceleration as a share of their limits."""


@dataclass(frozen=True)
class ExcitationSettings:
    """The ``[planner.excitation]`` table.

    Attributes
    ----------
    duration_s : float
        Length of the plan, s.
    periods : int
        Whole periods in it.
    harmonics : int
        Sine terms per joint.
    points_per_period : int
        Grid points per period where the limits are imposed and the information counted.
    margin : float
        Fraction of each rate-type limit kept in reserve.
    max_iterations : int
    seed : int
        Seed of the start's coefficients.
    print_level : int
        IPOPT's verbosity.
    """

    duration_s: float = 60.0
    periods: int = 4
    harmonics: int = 5
    points_per_period: int = 300
    margin: float = 0.05
    max_iterations: int = 300
    seed: int = 0
    print_level: int = 0

    RANGES = {
        "duration_s": (1.0, 3600.0),
        "periods": (1, 1000),
        "harmonics": (1, 20),
        "points_per_period": (20, 5000),
        "margin": (0.0, 0.5),
        "max_iterations": (1, 100_000),
        "seed": (0, 2**31 - 1),
        "print_level": (0, 12),
    }

    @property
    def period_s(self) -> float:
        """One period of the excitation, s."""
        return self.duration_s / self.periods


OPTION_KEYS = tuple(f.name for f in dataclasses.fields(ExcitationSettings))


@dataclass(frozen=True)
class FourierBasis:
    """q, q̇, q̈ and jerk of one joint on a time grid as linear maps of its coefficients
    (a_1..a_H, b_1..b_H): each (points, 2H), in rad, rad/s, rad/s², rad/s³ per rad/s."""

    position: np.ndarray
    rate: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray

    @classmethod
    def at(cls, t: np.ndarray, period_s: float, harmonics: int) -> FourierBasis:
        """The maps at times ``t`` (s) for a period (s) and ``harmonics`` terms."""
        k = np.arange(1, harmonics + 1)
        w = 2.0 * np.pi * k / period_s
        angle = np.outer(np.asarray(t, dtype=float), w)
        sin, cos = np.sin(angle), np.cos(angle)
        return cls(
            position=np.hstack([sin / w, (1.0 - cos) / w]),
            rate=np.hstack([cos, sin]),
            acceleration=np.hstack([-sin * w, cos * w]),
            jerk=np.hstack([-cos * w**2, -sin * w**2]),
        )


def rest_constraints(harmonics: int) -> np.ndarray:
    """Rows (2, 2H) that are zero for a joint's coefficients at rest at whole periods:
    Σ a_k (q̇) and Σ k b_k (q̈)."""
    k = np.arange(1, harmonics + 1, dtype=float)
    zeros = np.zeros(harmonics)
    return np.array([np.concatenate([np.ones(harmonics), zeros]), np.concatenate([zeros, k])])


@cache
def _design_columns(joint_range: bytes) -> ca.Function:
    """(q, q̇, q̈, fixed parameters) -> the 38 standard columns of Y (2 × 38), Coulomb
    smoothed (module docstring)."""
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    parameters = ca.SX.sym("parameters", len(dynamics.PARAMETER_NAMES))
    links, _ = link_function()(q, qd, qdd, parameters)
    drive = ca.SX.zeros(2, len(DRIVE_PARAMETERS))
    for joint in range(2):
        sliding = ca.tanh(qd[joint] / COULOMB_SMOOTHING_RAD_S)
        for k, value in enumerate(drive_columns(qd[joint], qdd[joint], sliding)):
            drive[joint, DRIVE_TERMS * joint + k] = value
    columns = ca.horzcat(ca.reshape(links, 2, -1), drive)
    assert columns.shape[1] == len(STANDARD_PARAMETERS)
    return ca.Function("design_columns", [q, qd, qdd, parameters], [columns])


DESIGN_LEAVES_OUT = (".inertia.xy", ".inertia.xz", ".inertia.yz", "offset.")
"""The base parameters the design does not count, by their leading standard parameter:
the products of inertia and the drives' offsets (module docstring)."""


def designed(base: BaseParameters) -> BaseParameters:
    """``base`` with only the base parameters the design counts (module docstring)."""
    keep = [
        row
        for row, index in enumerate(base.independent)
        if not any(part in STANDARD_PARAMETERS[index] for part in DESIGN_LEAVES_OUT)
    ]
    return dataclasses.replace(
        base, independent=base.independent[keep], combination=base.combination[keep]
    )


def _log_det(size: int) -> ca.Function:
    """F (size × size, symmetric positive definite) -> log det F, through its Cholesky
    factor."""
    f = ca.SX.sym("F", size, size)
    factor = ca.chol(f)
    return ca.Function("log_det", [f], [2.0 * ca.sum1(ca.log(ca.diag(factor)))])


class ExcitationPlanner:
    """The registered ``excitation`` planner (module docstring)."""

    name = "excitation"
    cuts_contour = False

    def settings(self, problem: Problem) -> ExcitationSettings:
        options = planner_options(problem, self.name, OPTION_KEYS)
        return settings_from_options(
            self.name, ExcitationSettings(), options, ExcitationSettings.RANGES
        )

    def plan(self, problem: Problem) -> Trajectory:
        settings = self.settings(problem)
        base = designed(base_parameters(problem.robot))
        centre = problem.landmark_angles[problem.visit_order[0]]
        t = np.linspace(0.0, settings.period_s, settings.points_per_period, endpoint=False)
        basis = FourierBasis.at(t, settings.period_s, settings.harmonics)
        design = _Design(problem, settings, base, centre, basis)
        coefficients, statistics = design.solve()
        trajectory = _trajectory(centre, coefficients, settings, statistics)
        # the evaluator decides whether the plan is refused (the robot's limits: it ignores
        # the contour); the report stays with the plan for whoever asked to judge it
        broken = evaluate(problem, trajectory).violations
        if broken:
            raise PlanningError(f"excitation: the plan breaks {broken[0]}")
        return trajectory


class _Design:
    """The NLP in the coefficients x = (joint 1's a, b, joint 2's a, b)."""

    def __init__(
        self,
        problem: Problem,
        settings: ExcitationSettings,
        base: BaseParameters,
        centre: np.ndarray,
        basis: FourierBasis,
    ) -> None:
        self.problem, self.settings, self.base = problem, settings, base
        self.centre, self.basis = np.asarray(centre, dtype=float), basis
        self.size = 2 * settings.harmonics

    def _motion(self, x: Any) -> tuple[Any, Any, Any, Any]:
        """q, q̇, q̈, jerk on the grid (points × 2) for coefficients x."""
        b, n = self.basis, self.size
        parts = []
        for matrix, offset in (
            (b.position, self.centre),
            (b.rate, None),
            (b.acceleration, None),
            (b.jerk, None),
        ):
            joints = [ca.mtimes(ca.DM(matrix), x[j * n : (j + 1) * n]) for j in range(2)]
            value = ca.horzcat(*joints)
            if offset is not None:
                value = value + ca.repmat(ca.DM(offset).T, value.shape[0], 1)
            parts.append(value)
        return tuple(parts)  # type: ignore[return-value]

    def _start(self) -> np.ndarray:
        """Seeded coefficients at rest at whole periods, scaled to
        :data:`START_SPEED_SHARE` of the speed and acceleration limits and a quarter of
        the room in the joint range."""
        rng = np.random.default_rng(self.settings.seed)
        rest = rest_constraints(self.settings.harmonics)
        projector = np.eye(self.size) - np.linalg.pinv(rest) @ rest
        limits = self.problem.limits
        low, high = self.problem.robot.joint_range[:, 0], self.problem.robot.joint_range[:, 1]
        room = np.minimum(self.centre - low, high - self.centre) - RANGE_CLEARANCE_RAD
        if np.any(room <= 0.0):
            raise PlanningError(
                "excitation: the first landmark lies within "
                f"{np.degrees(RANGE_CLEARANCE_RAD):g} deg of the joint range; there is no "
                "room to swing about it"
            )
        x = []
        for joint in range(2):
            coefficients = projector @ rng.normal(size=self.size)
            scale = min(
                START_SPEED_SHARE
                * limits.max_joint_speed
                / np.max(np.abs(self.basis.rate @ coefficients)),
                0.25 * room[joint] / np.max(np.abs(self.basis.position @ coefficients)),
            )
            for matrix, limit in (
                (self.basis.acceleration, limits.max_joint_acceleration),
                (self.basis.jerk, limits.max_joint_jerk),
            ):
                if limit is not None:
                    peak = np.max(np.abs(matrix @ coefficients))
                    scale = min(scale, START_SPEED_SHARE * limit / peak)
            x.append(scale * coefficients)
        return np.concatenate(x)

    def solve(self) -> tuple[np.ndarray, dict[str, Any]]:
        """The coefficients (4H,) and the solver's statistics."""
        problem, settings, base = self.problem, self.settings, self.base
        robot = problem.robot
        bounds = planner_bounds(problem, settings.margin, hold_room=False)  # it cuts nothing
        x = ca.MX.sym("x", 2 * self.size)
        q, qd, qdd, jerk = self._motion(x)
        points = settings.points_per_period
        fixed = ca.DM(dynamics.parameter_vector(robot))
        columns = _design_columns(range_key(robot.joint_range)).map(points, "serial")
        stacked = columns(q.T, qd.T, qdd.T, ca.repmat(fixed, 1, points))  # 2 × 38·points
        per_point = ca.reshape(stacked, 2 * len(STANDARD_PARAMETERS), points)
        rows = ca.vertcat(*(per_point[base.independent * 2 + j, :].T for j in range(2)))
        start = self._start()
        scale = self._column_norms(ca.Function("w", [x], [rows]), start)
        weighted = rows / ca.repmat(ca.DM(scale).T, rows.shape[0], 1)
        information = ca.mtimes(weighted.T, weighted) / rows.shape[0]
        objective = -_log_det(base.rank)(information)

        values = dynamics_parameters(robot)
        joint_torque = _joint_torque(range_key(robot.joint_range), len(values))
        torque = joint_torque.map("torques", "serial", points, [3], [])(q.T, qd.T, qdd.T, values)
        singular = _singularity_rows(bounds.min_singularity_margin + SINGULARITY_CLEARANCE)
        margin = singular.map(points, "serial")(q.T)
        rest = np.kron(np.eye(2), rest_constraints(settings.harmonics))
        g, low, high = [ca.mtimes(ca.DM(rest), x)], [np.zeros(4)], [np.zeros(4)]

        def add(values: Any, lower: float, upper: float) -> None:
            g.append(ca.vec(values))
            low.append(np.full(values.numel(), lower))
            high.append(np.full(values.numel(), upper))

        for joint in range(2):
            joint_low, joint_high = bounds.joint_range[joint]
            add(q[:, joint], joint_low + RANGE_CLEARANCE_RAD, joint_high - RANGE_CLEARANCE_RAD)
            add(qd[:, joint], -bounds.joint_speed, bounds.joint_speed)
            for values, limit in ((qdd, bounds.joint_acceleration), (jerk, bounds.joint_jerk)):
                if limit is not None:
                    add(values[:, joint], -limit, limit)
        add(torque, -bounds.load_torque, bounds.load_torque)
        add(margin, 0.0, np.inf)

        solver = ca.nlpsol(
            "excitation",
            "ipopt",
            {"x": x, "f": objective, "g": ca.vertcat(*g)},
            {
                "ipopt": {
                    "max_iter": settings.max_iterations,
                    "print_level": settings.print_level,
                    "hessian_approximation": "limited-memory",
                    "tol": 1e-6,
                    # the information stalls long before the multipliers settle: stop when
                    # log det has changed by less than 1e-4 of itself 10 times in a row
                    "acceptable_tol": 1e6,
                    "acceptable_dual_inf_tol": 1e10,
                    "acceptable_obj_change_tol": ACCEPTABLE_CHANGE,
                    "acceptable_iter": 10,
                    "sb": "yes",
                },
                "print_time": False,
            },
        )
        lbg, ubg = np.concatenate(low), np.concatenate(high)
        solution = solve(solver, x0=start, lbg=lbg, ubg=ubg)
        stats = solver.stats()
        values = np.asarray(solution["g"]).ravel()
        excess = float(np.max(np.maximum(lbg - values, values - ubg), initial=0.0))
        if excess > FEASIBLE_EXCESS:  # any feasible design is a plan; a better one is a bonus
            raise PlanningError(
                f"excitation: IPOPT stopped ({stats['return_status']}) after "
                f"{stats['iter_count']} iterations {excess:.3g} beyond a limit; try fewer "
                "harmonics or a longer period"
            )
        coefficients = np.asarray(solution["x"]).ravel()
        w = ca.Function("w", [x], [weighted])(coefficients).full()
        unit = w / np.linalg.norm(w, axis=0)
        statistics = {
            "iterations": int(stats["iter_count"]),
            "return_status": stats["return_status"],
            "log_det_information": float(-solution["f"]),
            "condition_number": float(np.linalg.cond(unit)),
        }
        return coefficients, statistics

    def _column_norms(self, rows: ca.Function, x: np.ndarray) -> np.ndarray:
        """Each base column's RMS over the grid at coefficients ``x`` (1 where it is 0)."""
        values = rows(x).full()
        norms = np.sqrt(np.mean(values**2, axis=0))
        return np.where(norms > 0.0, norms, 1.0)


def with_length(problem: Problem, seconds: float) -> Problem:
    """``problem`` with an excitation of about ``seconds``: whole periods of the length its
    ``[planner.excitation]`` gives them, its other settings kept."""
    settings = EXCITATION.settings(problem)
    periods = max(1, round(seconds / settings.period_s))
    table = problem.planner_options.get("excitation", {})
    options = {
        **problem.planner_options,
        "excitation": {**table, "duration_s": periods * settings.period_s, "periods": periods},
    }
    return dataclasses.replace(problem, planner_options=options)


@cache
def _joint_torque(joint_range: bytes, size: int) -> ca.Function:
    """The optimal-control planners' joint side torque (:func:`load_torque`) as a Function
    of (q, q̇, q̈, :func:`dynamics_parameters` (``size``))."""
    q, qd, qdd = ca.SX.sym("q", 2), ca.SX.sym("qd", 2), ca.SX.sym("qdd", 2)
    parameters = ca.SX.sym("parameters", size)
    torque = load_torque(joint_range)(q, qd, qdd, parameters)
    return ca.Function("joint_torque", [q, qd, qdd, parameters], [torque])


def _singularity_rows(minimum: float) -> ca.Function:
    """q -> two rows, both ≥ 0 exactly when the singularity margin is at least
    ``minimum``: with G = ∂bᵀ∂b/∂θ (2 × 2; the margin is √λ_min(G)), G − minimum² I is
    positive semi-definite: G₁₁ − minimum² ≥ 0 and det(G − minimum² I) ≥ 0. Smooth where
    the margin's own square root is not (at θ = 0)."""
    q = ca.SX.sym("q", 2)
    j1, j2 = (ca.vertcat(*v) for v in kinematics.direction_jacobian(q[0], q[1]))
    s = minimum**2
    a, b, c = ca.dot(j1, j1) - s, ca.dot(j1, j2), ca.dot(j2, j2) - s
    return ca.Function("singularity_rows", [q], [ca.vertcat(a, a * c - b * b)])


def fourier_motion(
    centre: np.ndarray, coefficients: np.ndarray, period_s: float, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, q̇, q̈ (len(t), 2), SI, of the series with ``coefficients`` (joint 1's a, b, then
    joint 2's) about ``centre`` (2,), rad, at times ``t``, s."""
    harmonics = len(coefficients) // 4
    basis = FourierBasis.at(t, period_s, harmonics)
    per_joint = np.asarray(coefficients, dtype=float).reshape(2, 2 * harmonics)
    return (
        np.asarray(centre) + basis.position @ per_joint.T,
        basis.rate @ per_joint.T,
        basis.acceleration @ per_joint.T,
    )


def _trajectory(
    centre: np.ndarray,
    coefficients: np.ndarray,
    settings: ExcitationSettings,
    statistics: dict[str, Any],
) -> Trajectory:
    samples = int(round(settings.duration_s * SAMPLE_RATE_HZ))
    t = np.linspace(0.0, settings.duration_s, samples + 1)
    q, qd, qdd = fourier_motion(centre, coefficients, settings.period_s, t)
    qd[[0, -1]], qdd[[0, -1]] = 0.0, 0.0  # at rest: exactly, not to round-off
    metadata = {
        "ignores_contour": True,
        "statistics": statistics,
        "excitation": {
            "centre_rad": np.asarray(centre).tolist(),
            "period_s": settings.period_s,
            "periods": settings.periods,
            "coefficients": np.asarray(coefficients).tolist(),
        },
    }
    return Trajectory.from_samples(t, q, qd, qdd, metadata)


EXCITATION = register(ExcitationPlanner())
