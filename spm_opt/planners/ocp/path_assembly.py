"""The path-coordinate NLP assembled stage by stage from one interval's functions and one
landmark's (:mod:`~spm_opt.planners.ocp.path_nlp`), in SX or compiled alike.

x runs stage by stage, as a structure-exploiting solver (FATROP) reads it: per segment the
node states and the interval controls in turn, x₀ u₀ x₁ u₁ … x_N, and after every segment
but the last the state the next one starts from (its transition control t). g runs the same
way: per interval its gap (x_{i+1} − advance(x_i, u_i), +1 on the next state) and its limit
rows; after a segment the transition's gap (the next segment's x₀ − t) and the landmark's
continuity rows in (x_N, t); with fixed timing, the time rows last (IPOPT only: each reads
every interval of its segments). The Jacobian, the objective's gradient and the
Lagrangian's Hessian are the intervals' and the landmarks' own, scattered into the NLP's
sparse matrices (:class:`~spm_opt.planners.ocp.assembly.Scatter`), so one small library
serves every grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from spm_opt.planners.ocp.assembly import Scatter, derivative_functions, scatter
from spm_opt.planners.ocp.path_nlp import (
    CONTROL,
    INTERVAL_HIGH,
    INTERVAL_LOW,
    INTERVAL_PARAMETERS,
    LANDMARK_ROWS,
    LIMIT_PARAMETERS,
    OBJECTIVES,
    PER_END,
    STATE,
    Z,
)

ROWS = INTERVAL_LOW.size
"""Rows per interval."""


@dataclass(frozen=True)
class PathLayout:
    """Where each node's state, interval's control and transition sits in x, and each
    interval's and landmark's rows in g, for ``segments`` segments of ``intervals``
    intervals and ``timed`` time rows."""

    segments: int
    intervals: int
    timed: int

    @property
    def per_segment(self) -> int:
        """x's entries per segment, its transition included."""
        return STATE * (self.intervals + 1) + CONTROL * self.intervals + STATE

    @property
    def size(self) -> int:
        """x's length."""
        return self.segments * self.per_segment - STATE

    @property
    def rows(self) -> int:
        """g's length."""
        return self.segments * self.intervals * ROWS + (self.segments - 1) * 2 * STATE + self.timed

    def states(self) -> np.ndarray:
        """x's index of every node's state (segments, N + 1, 5)."""
        stage = np.arange(self.intervals + 1)[:, None] * Z + np.arange(STATE)
        return np.arange(self.segments)[:, None, None] * self.per_segment + stage

    def controls(self) -> np.ndarray:
        """x's index of every interval's control (segments, N, 2)."""
        return self.states()[:, :-1, :CONTROL] + STATE

    def transitions(self) -> np.ndarray:
        """x's index of every transition (segments − 1, 5)."""
        return self.states()[:-1, -1, :] + STATE

    def interval_rows(self) -> np.ndarray:
        """g's index of every interval's first row (segments, N)."""
        stage = np.arange(self.intervals) * ROWS
        return np.arange(self.segments)[:, None] * self.segment_rows + stage

    def landmark_rows(self) -> np.ndarray:
        """g's index of every landmark's first row (its transition's gap; segments − 1)."""
        return np.arange(self.segments - 1) * self.segment_rows + self.intervals * ROWS

    @property
    def segment_rows(self) -> int:
        return self.intervals * ROWS + 2 * STATE

    def split(self, x: np.ndarray, segment: int) -> tuple[np.ndarray, np.ndarray]:
        """Segment ``segment``'s node states (N + 1, 5) and controls (N, 2) in x (copies)."""
        return x[self.states()[segment]], x[self.controls()[segment]]

    def join(self, states: list[np.ndarray], controls: list[np.ndarray]) -> np.ndarray:
        """x from every segment's node states (N + 1, 5) and controls (N, 2); each
        transition is the next segment's first state."""
        x = np.empty(self.size)
        x[self.states()] = np.stack(states)
        x[self.controls()] = np.stack(controls)
        x[self.transitions()] = np.stack(states)[1:, 0]
        return x

    def row_bounds(
        self, durations: np.ndarray | None = None, timing: str = "free"
    ) -> tuple[np.ndarray, np.ndarray]:
        """Every row's bounds; the time rows' from ``timing`` ("bounded": at most the
        total, "total": the total, "segments": each) and the segment ``durations`` (s)."""
        low, high = np.zeros(self.rows), np.zeros(self.rows)
        at = (self.interval_rows()[..., None] + np.arange(ROWS)).ravel()
        low[at] = np.tile(INTERVAL_LOW, self.segments * self.intervals)
        high[at] = np.tile(INTERVAL_HIGH, self.segments * self.intervals)
        if self.timed:
            held = durations if timing == "segments" else np.array([np.sum(durations)])
            low[-self.timed :] = 0.0 if timing == "bounded" else held
            high[-self.timed :] = held
        return low, high


@dataclass(frozen=True)
class AssembledPathNlp:
    """The NLP (x, p, f, g), its integrals, and the solver's derivative functions for it."""

    problem: dict[str, ca.MX]
    integrals: ca.Function
    """(x, p) → the :data:`OBJECTIVES`' values (3,) and each segment's time (segments,)."""
    derivatives: dict[str, ca.Function]
    """grad_f, jac_g, hess_lag: nlpsol's options."""


def parameter_size(segments: int, intervals: int) -> int:
    """p's length: per segment the terms at every place, the interval lengths and the ends'
    terms, then the limits and the weights."""
    per_segment = intervals * INTERVAL_PARAMETERS + intervals + PER_END
    return segments * per_segment + LIMIT_PARAMETERS + len(OBJECTIVES)


def assemble(
    layout: PathLayout, interval: list[ca.Function], landmark: list[ca.Function]
) -> AssembledPathNlp:
    """The NLP on ``layout`` from the interval's and the landmark's functions
    (:func:`~spm_opt.planners.ocp.path_nlp.interval_functions`,
    :func:`~spm_opt.planners.ocp.path_nlp.landmark_functions`), with the layout's time rows
    (one per segment when it has as many, else one for the total)."""
    value, jacobian, hessian = interval
    landmark_value, landmark_jacobian, landmark_hessian = landmark
    segments, intervals = layout.segments, layout.intervals
    m, n, n_g = segments * intervals, layout.size, layout.rows
    x = ca.MX.sym("x", n)
    p = ca.MX.sym("p", parameter_size(segments, intervals))
    per_segment_p = (p.numel() - LIMIT_PARAMETERS - len(OBJECTIVES)) // segments
    limits = p[segments * per_segment_p : -len(OBJECTIVES)]
    weights = p[-len(OBJECTIVES) :]

    def gather(vector: ca.MX, index: np.ndarray) -> ca.MX:
        """vector's entries at ``index`` (rows, columns), as a matrix."""
        return ca.reshape(vector[index.ravel(order="F").tolist()], *index.shape)

    p_index = np.arange(segments)[:, None] * per_segment_p
    terms_at = (p_index[:, :, None] + np.arange(intervals * INTERVAL_PARAMETERS)).reshape(
        segments, intervals, INTERVAL_PARAMETERS
    )
    terms = gather(p, terms_at.reshape(m, -1).T)
    length_start = intervals * INTERVAL_PARAMETERS
    lengths = gather(p, (p_index + length_start + np.arange(intervals)).reshape(1, m))
    ends = p_index[:, 0, None] + length_start + intervals + np.arange(PER_END)
    z_index = np.concatenate([layout.states()[:, :-1, :], layout.controls()], axis=2)
    z_index = z_index.reshape(m, Z).T
    z = gather(x, z_index)
    arguments = [z, lengths, terms, limits, weights]

    w_index = np.concatenate([layout.states()[:-1, -1, :], layout.transitions()], axis=1).T
    landmark_arguments = [
        gather(x, w_index),
        gather(p, ends[:-1].T),
        gather(p, ends[1:].T),
        limits,
    ]

    rows, integrals, term = value.map(m)(*arguments)
    next_index = layout.states()[:, 1:, :].reshape(m, STATE).T
    next_states = ca.vertcat(gather(x, next_index), ca.DM.zeros(ROWS - STATE, m))
    interval_g = rows + next_states
    first_states = layout.states()[1:, 0, :].T
    landmark_g = ca.vertcat(
        gather(x, first_states) - gather(x, layout.transitions().T),
        *_mapped(landmark_value, segments - 1, landmark_arguments),
    )
    times = ca.reshape(integrals[0, :], intervals, segments)
    segment_times = ca.sum1(times).T
    timed = {0: [], segments: [segment_times]}.get(layout.timed, [ca.sum1(segment_times)])
    pieces = []
    for k in range(segments):
        pieces.append(ca.vec(interval_g[:, k * intervals : (k + 1) * intervals]))
        if k < segments - 1:
            pieces.append(landmark_g[:, k])
    g = ca.vertcat(*pieces, *timed)
    totals = ca.sum2(integrals)
    f = ca.sum2(term)

    # the Jacobian: intervals' nonzeros, landmarks', intervals' time gradients, then ±1
    row0, landmark0 = layout.interval_rows().ravel(), layout.landmark_rows()
    interval_rows = row0 + np.arange(ROWS)[:, None]
    continuity_rows = landmark0 + STATE + np.arange(LANDMARK_ROWS)[:, None]
    entries = [
        _block_triplets(jacobian.sparsity_out(2), interval_rows, z_index),
        _block_triplets(landmark_jacobian.sparsity_out(1), continuity_rows, w_index),
    ]
    time_rows = _time_rows(layout)
    if layout.timed:
        entries.append((np.repeat(time_rows, Z), z_index.T.ravel()))
    gaps = interval_rows[:STATE].T.ravel()
    landmark_gaps = (landmark0[:, None] + np.arange(STATE)).ravel()
    plus = [(gaps, next_index.T.ravel()), (landmark_gaps, first_states.T.ravel())]
    minus = [(landmark_gaps, layout.transitions().ravel())]
    _, _, jac_rows, grad_term, grad_time = jacobian.map(m)(*arguments)
    _, jac_landmarks = _mapped(landmark_jacobian, segments - 1, landmark_arguments)
    sources = [jac_rows.nz[:], jac_landmarks.nz[:]] + ([ca.vec(grad_time)] if layout.timed else [])
    counted = sum(len(r) for r, _ in entries)
    signs = [np.ones(len(r)) for r, _ in plus] + [-np.ones(len(r)) for r, _ in minus]
    jacobian_scatter = Scatter(
        np.concatenate([r for r, _ in entries + plus + minus]),
        np.concatenate([c for _, c in entries + plus + minus]),
        np.concatenate([np.ones(counted), *signs]),
        np.concatenate([np.arange(counted), np.full(sum(map(len, signs)), counted)]),
        (n_g, n),
        counted + 1,
    )
    jac_g = jacobian_scatter(ca.vertcat(*sources, 1.0))

    gradient = scatter(z_index.T.ravel(), np.zeros(Z * m, int), np.ones(Z * m), (n, 1))
    grad_f = ca.densify(gradient(ca.vec(grad_term)))  # IPOPT reads it dense

    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", n_g)
    multipliers = gather(lam_g, interval_rows)
    lam_time = gather(lam_g, time_rows[None, :]) if layout.timed else ca.DM.zeros(1, m)
    landmark_lam = gather(lam_g, continuity_rows)
    hess = hessian.map(m)(*arguments, lam_f, multipliers, lam_time)
    (hess_landmarks,) = _mapped(landmark_hessian, segments - 1, [*landmark_arguments, landmark_lam])
    blocks = [
        _block_triplets(hessian.sparsity_out(0), z_index, z_index),
        _block_triplets(landmark_hessian.sparsity_out(0), w_index, w_index),
    ]
    first, second = (np.concatenate(parts) for parts in zip(*blocks, strict=True))
    hess_lag = scatter(first, second, np.ones(len(first)), (n, n))(
        ca.vertcat(hess.nz[:], hess_landmarks.nz[:])
    )

    inputs = [x, p]
    return AssembledPathNlp(
        {"x": x, "p": p, "f": f, "g": g},
        ca.Function("integrals", inputs, [totals, segment_times]),
        derivative_functions(x, p, (f, grad_f), (g, jac_g), (lam_f, lam_g, hess_lag)),
    )


def _time_rows(layout: PathLayout) -> np.ndarray:
    """g's index of the time row each interval's time enters (M,): its segment's, or the
    one of the total (read only when the layout has time rows)."""
    segment = np.repeat(np.arange(layout.segments), layout.intervals)
    per_segment = layout.timed == layout.segments
    return layout.rows - layout.timed + (segment if per_segment else 0 * segment)


def _block_triplets(
    pattern: ca.Sparsity, rows: np.ndarray, columns: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The global (rows, columns) of ``pattern``'s nonzeros repeated over blocks, in the
    order a map's outputs hold them: block b's local row r is row rows[r, b], its local
    column c column columns[c, b]."""
    local_rows, local_columns = (np.asarray(v) for v in pattern.get_triplet())
    blocks = rows.shape[1]
    block = np.repeat(np.arange(blocks), pattern.nnz())
    return (
        rows[np.tile(local_rows, blocks), block],
        columns[np.tile(local_columns, blocks), block],
    )


def _mapped(function: ca.Function, count: int, arguments: list) -> list[ca.MX]:
    """``function``'s outputs over ``count`` columns of ``arguments``; with none (a cut of
    one segment passes no landmark), empty."""
    if count == 0:
        return [ca.MX(function.size1_out(k), 0) for k in range(function.n_out())]
    return function.map(count).call(arguments)
