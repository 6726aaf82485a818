"""The optimal-control NLP assembled from one interval's functions and their derivatives.

Every nonlinear row of the NLP belongs to one interval and reads only that interval's
z = (x (6), u (2), h): its node state, its jerk and its length, which is one phase duration
over the phase's interval count. The rest (the next node's state in the continuity rows,
the segment and total durations, the total time in the objective) is linear. So the
constraints' Jacobian, the objective's gradient and the Lagrangian's Hessian of the whole
NLP are the interval's own, evaluated interval by interval (a map) and scattered into the
NLP's sparse matrices by constant sparse matrices; IPOPT takes them as its ``grad_f``,
``jac_g`` and ``hess_lag``. The interval's three functions (:func:`interval_functions`)
are small SX functions that compile to C in seconds whatever the grid (one library serves
every segment count), where the NLP's own derivatives, generated from the mapped graph, are
megabytes of C and, with the torque table, too big to compile.

Measured when the assembly replaced CasADi's derivatives of the whole NLP (minimum time
compiled from its MX graph, minimum energy interpreted in SX), on the paper's flap, one
solve from the same start, 2 idle cores, the formulation of that day (Simpson's rule for
the effort, no backtracking rows)::

    planner      iterations   functions            solve
    min-time     44 / 44      0.078 -> 0.023 s     0.23 -> 0.14 s
    min-jerk     83 / 72      0.43  -> 0.097 s     1.06 -> 0.50 s
    min-energy   122 / 117    3.3   -> 2.6 s       4.3  -> 3.6 s

(min-energy's interval then read the torque table at three points, 27 µs an interval; it
now reads it at two.)
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sparse

from spm_opt.planners.ocp.transcription import CONTROL, STATE, Grid

Z = STATE + CONTROL + 1
"""An interval's variables: its node state (q, q̇, q̈), its jerk and its length h."""
VALUE, JACOBIAN, HESSIAN = "interval_value", "interval_jacobian", "interval_hessian"
"""Names of the interval's three functions (and of their compiled C)."""


def interval_functions(interval: ca.Function) -> list[ca.Function]:
    """The interval's value, Jacobian and Lagrangian Hessian from ``interval``
    (:func:`~spm_opt.planners.ocp.transcription.interval_function`), in SX.

    All take z (9), the arc, the check fractions, the dynamics parameters and c (2): the
    objective's weights of ∫jerk² and ∫τᵀτ. Value: the interval's rows [−end; limit rows]
    and its objective term c·integrals, with its integrals. Jacobian: the rows, the
    objective term, the rows' Jacobian in z and the term's gradient. Hessian (inputs also
    σ, the objective's multiplier, and λ, the rows'): the upper triangle of
    ∇²_z(σ c·integrals + λᵀ rows).
    """
    z = ca.SX.sym("z", Z)
    arc = ca.SX.sym("arc", interval.size1_in(3))
    fractions = ca.SX.sym("fractions", interval.size1_in(4))
    dynamics = ca.SX.sym("dynamics", interval.size1_in(5))
    weights = ca.SX.sym("c", 2)
    end, rows, integrals = interval(z[0:6], z[6:8], z[8], arc, fractions, dynamics)
    constraint_rows = ca.vertcat(-end, rows)
    term = ca.dot(weights, integrals)
    sigma, lam = ca.SX.sym("sigma"), ca.SX.sym("lam", constraint_rows.numel())
    hessian = ca.triu(ca.hessian(sigma * term + ca.dot(lam, constraint_rows), z)[0])
    inputs = [z, arc, fractions, dynamics, weights]
    names = ["z", "arc", "fractions", "dynamics", "c"]
    return [
        ca.Function(VALUE, inputs, [constraint_rows, integrals], names, ["rows", "integrals"]),
        ca.Function(
            JACOBIAN,
            inputs,
            [constraint_rows, term, ca.jacobian(constraint_rows, z), ca.gradient(term, z)],
            names,
            ["rows", "term", "jac_rows", "grad_term"],
        ),
        ca.Function(HESSIAN, [*inputs, sigma, lam], [hessian], [*names, "sigma", "lam"], ["hess"]),
    ]


@dataclass(frozen=True)
class AssembledNlp:
    """The NLP (x, p, f, g), its terms, and IPOPT's derivative functions for it."""

    problem: dict[str, ca.MX]
    terms: ca.Function  # (x, p) -> total time (s), ∫τᵀτ dt (N²m²s), ∫jerk² dt (rad²/s⁵)
    derivatives: dict[str, ca.Function]  # grad_f, jac_g, hess_lag: nlpsol's options


def assemble(
    grid: Grid, functions: list[ca.Function], n_arc: int, checks: int, n_dynamics: int
) -> AssembledNlp:
    """The NLP on ``grid`` from the interval's ``functions`` (:func:`interval_functions`,
    in SX or compiled).

    x stacks the node states (6, M + 1), the jerks (2, M) and the phase durations (D,),
    column by column; p the arcs (n_arc, segments), the check fractions (checks, M), the
    dynamics parameters, the weights (3) and the scales (3) of total time, ∫τᵀτ dt and
    ∫jerk² dt. g holds, interval by interval, the continuity rows (next node − end) and the
    limit rows, then the segment durations and the total duration.
    """
    value, jacobian, hessian = functions
    m, segments, phases = grid.intervals, grid.segments, 3 * grid.segments
    n_states, n_jerks = STATE * (m + 1), CONTROL * m
    n = n_states + n_jerks + phases
    x = ca.MX.sym("x", n)
    p = ca.MX.sym("p", n_arc * segments + checks * m + n_dynamics + 6)
    states = ca.reshape(x[:n_states], STATE, m + 1)
    jerks = ca.reshape(x[n_states : n_states + n_jerks], CONTROL, m)
    durations = x[n_states + n_jerks :]
    offset = n_arc * segments + checks * m
    arcs = ca.reshape(p[: n_arc * segments], n_arc, segments)
    fractions = ca.reshape(p[n_arc * segments : offset], checks, m)
    dynamics = p[offset : offset + n_dynamics]
    weights, scales = p[offset + n_dynamics : offset + n_dynamics + 3], p[-3:]
    c = ca.vertcat(weights[2] / scales[2], weights[1] / scales[1])  # integrals: jerk, effort
    time_weight = weights[0] / scales[0]

    lengths = (ca.DM(grid.interval_matrix) @ durations).T
    z = ca.vertcat(states[:, :-1], jerks, lengths)
    interval_arcs = arcs @ ca.DM(np.eye(segments)[:, grid.interval_segments])
    arguments = [z, interval_arcs, fractions, dynamics, c]

    rows_per_interval = value.size1_out(0)
    rows, integrals = value.map(m)(*arguments)
    next_state = ca.vertcat(states[:, 1:], ca.DM.zeros(rows_per_interval - STATE, m))
    segment_matrix = grid.segment_matrix
    g = ca.vertcat(ca.vec(rows + next_state), ca.DM(segment_matrix) @ durations, ca.sum1(durations))
    total_time = ca.sum1(durations)
    jerk_integral, effort = ca.sum2(integrals[0, :]), ca.sum2(integrals[1, :])
    f = time_weight * total_time + ca.dot(c, ca.vertcat(jerk_integral, effort))

    columns, scale = _interval_columns(grid, n)
    n_g = m * rows_per_interval + segments + 1
    _, term, jac_rows, grad_term = jacobian.map(m)(*arguments)
    jac_g = _jacobian(grid, jacobian, columns, scale, n_g, n)(ca.vertcat(jac_rows.nz[:], 1.0))
    duration_gradient = ca.vertcat(ca.DM.zeros(n - phases), ca.DM.ones(phases))
    gradient = scatter(columns.ravel(), np.zeros(columns.size, int), scale.ravel(), (n, 1))
    grad_f = gradient(ca.vec(grad_term)) + time_weight * duration_gradient

    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", n_g)
    multipliers = ca.reshape(lam_g[: m * rows_per_interval], rows_per_interval, m)
    hess = hessian.map(m)(*arguments, lam_f, multipliers)
    hess_lag = _hessian(hessian, columns, scale, n)(hess.nz[:])

    inputs = [x, p]
    return AssembledNlp(
        {"x": x, "p": p, "f": f, "g": g},
        ca.Function("terms", inputs, [total_time, effort, jerk_integral]),
        derivative_functions(x, p, (f, grad_f), (g, jac_g), (lam_f, lam_g, hess_lag)),
    )


def derivative_functions(
    x: ca.MX,
    p: ca.MX,
    gradient: tuple[ca.MX, ca.MX],
    jacobian: tuple[ca.MX, ca.MX],
    hessian: tuple[ca.MX, ca.MX, ca.MX],
) -> dict[str, ca.Function]:
    """IPOPT's ``grad_f``, ``jac_g`` and ``hess_lag`` options: the functions of (x, p) that
    give (f, ∇f), (g, ∂g/∂x) and, with the multipliers (σ, λ), the Lagrangian's Hessian."""
    inputs, names = [x, p], ["x", "p"]
    lam_f, lam_g, hess_lag = hessian
    return {
        "grad_f": ca.Function("nlp_grad_f", inputs, [*gradient], names, ["f", "grad_f_x"]),
        "jac_g": ca.Function("nlp_jac_g", inputs, [*jacobian], names, ["g", "jac_g_x"]),
        "hess_lag": ca.Function(
            "nlp_hess_l",
            [x, p, lam_f, lam_g],
            [hess_lag],
            ["x", "p", "lam_f", "lam_g"],
            ["hess_gamma_x_x"],
        ),
    }


def _interval_columns(grid: Grid, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each interval's z as x's columns (M, 9), and the factor each column enters z by
    (1, or 1 / the phase's interval count for h)."""
    m = grid.intervals
    k = np.arange(m)
    columns = np.empty((m, Z), dtype=int)
    columns[:, :STATE] = STATE * k[:, None] + np.arange(STATE)
    columns[:, STATE : STATE + CONTROL] = STATE * (m + 1) + CONTROL * k[:, None] + np.arange(2)
    phase = grid.phase_of_interval
    columns[:, -1] = n - 3 * grid.segments + phase
    scale = np.ones((m, Z))
    scale[:, -1] = grid.interval_matrix[k, phase]
    return columns, scale


class Scatter:
    """global nonzeros = T @ source values, as an MX sparse matrix of a fixed sparsity."""

    def __init__(self, rows, cols, factors, sources, shape, n_sources) -> None:
        self.sparsity, positions = ca.Sparsity.triplet(
            shape[0], shape[1], rows.tolist(), cols.tolist(), True
        )
        matrix = sparse.csc_matrix(
            (factors, (np.asarray(positions), sources)), shape=(self.sparsity.nnz(), n_sources)
        )
        matrix.sum_duplicates()
        self.matrix = ca.DM(
            ca.Sparsity(*matrix.shape, matrix.indptr.tolist(), matrix.indices.tolist()),
            matrix.data,
        )

    def __call__(self, values: ca.MX) -> ca.MX:
        return ca.sparsity_cast(self.matrix @ values, self.sparsity)


def scatter(rows, cols, factors, shape) -> Scatter:
    """A scatter of one source value per triplet, in the triplets' order."""
    return Scatter(rows, cols, factors, np.arange(len(rows)), shape, len(rows))


def _jacobian(
    grid: Grid, jacobian: ca.Function, columns: np.ndarray, scale: np.ndarray, n_g: int, n: int
) -> Scatter:
    """The constraints' Jacobian from the intervals' (their nonzeros, then a 1 for the
    linear entries: +1 on the next node's state, the segment and total rows)."""
    pattern = jacobian.sparsity_out(2)
    local_rows, local_columns = (np.asarray(v) for v in pattern.get_triplet())
    per_interval, rows_per_interval = pattern.nnz(), pattern.size1()
    m, phases = grid.intervals, 3 * grid.segments
    k = np.repeat(np.arange(m), per_interval)
    rows = [k * rows_per_interval + np.tile(local_rows, m)]
    cols = [columns[k, np.tile(local_columns, m)]]
    factors = [scale[k, np.tile(local_columns, m)]]
    sources = [np.arange(m * per_interval)]
    one = m * per_interval
    k = np.repeat(np.arange(m), STATE)
    rows.append(k * rows_per_interval + np.tile(np.arange(STATE), m))
    cols.append(STATE * (k + 1) + np.tile(np.arange(STATE), m))
    segment_rows, segment_phases = np.nonzero(grid.segment_matrix)
    rows += [m * rows_per_interval + segment_rows, np.full(phases, n_g - 1)]
    cols += [n - phases + segment_phases, n - phases + np.arange(phases)]
    linear = len(rows[1]) + len(segment_rows) + phases
    factors.append(np.ones(linear))
    sources.append(np.full(linear, one))
    return Scatter(
        np.concatenate(rows),
        np.concatenate(cols),
        np.concatenate(factors),
        np.concatenate(sources),
        (n_g, n),
        one + 1,
    )


def _hessian(hessian: ca.Function, columns: np.ndarray, scale: np.ndarray, n: int) -> Scatter:
    """The Lagrangian's Hessian (upper triangle) from the intervals' (the phase durations'
    block sums its intervals'). x's columns grow along z, so upper stays upper."""
    pattern = hessian.sparsity_out(0)
    local_rows, local_columns = (np.asarray(v) for v in pattern.get_triplet())
    m, per_interval = columns.shape[0], pattern.nnz()
    k = np.repeat(np.arange(m), per_interval)
    first, second = np.tile(local_rows, m), np.tile(local_columns, m)
    return Scatter(
        columns[k, first],
        columns[k, second],
        scale[k, first] * scale[k, second],
        np.arange(m * per_interval),
        (n, n),
        m * per_interval,
    )
