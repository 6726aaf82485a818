"""The identifiable (base) parameters: the combinations of the standard parameters π
(:mod:`spm_opt.model.regressor`) that the actuator torques determine.

Gautier and Khalil's numerical method (IEEE Trans. Robotics and Automation 6(3), 1990):
the regressor Y is stacked over random states, its zero columns dropped and the rest scaled
to unit norm; a QR decomposition with column pivoting gives the rank r (the diagonal of R
above ``RANK_TOLERANCE`` times its first entry) and the r independent columns. Every other
column is a fixed combination of those, Y_d = Y_b K, so τ = Y_b β + τ_payload with the
base parameters β = π_b + K π_d. A parameter whose column is zero (e.g. an arc's inertia
about an axis it never turns about) leaves no trace in the torques at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from spm_opt.model.params import Robot
from spm_opt.model.regressor import STANDARD_PARAMETERS, regressor

RANK_TOLERANCE = 1e-8
"""Relative size of R's diagonal (unit-norm columns) below which a column is dependent."""
ZERO_COLUMN = 1e-12
"""Norm (relative to the largest) below which a regressor column counts as zero."""
COMBINATION_ZERO = 1e-9
"""Entries of K below this are round-off (the dependences are exact)."""
SAMPLES = 400
"""Random states the structure is found from."""


@dataclass(frozen=True)
class BaseParameters:
    """Which combinations of π the torques determine.

    Attributes
    ----------
    independent : ndarray of int, shape (r,)
        Indices into π of the base columns, in π's order.
    dependent : ndarray of int, shape (d,)
        Indices of the other nonzero columns.
    unseen : ndarray of int
        Indices of the parameters whose columns are zero.
    combination : ndarray, shape (r, d)
        K: β = π[independent] + K π[dependent].
    """

    independent: np.ndarray
    dependent: np.ndarray
    unseen: np.ndarray
    combination: np.ndarray

    @property
    def rank(self) -> int:
        return len(self.independent)

    def values(self, standard: np.ndarray) -> np.ndarray:
        """β (r,) for standard parameters π (38,)."""
        return standard[self.independent] + self.combination @ standard[self.dependent]

    def columns(self, full: np.ndarray) -> np.ndarray:
        """Y_b: the base columns of a regressor (..., 38)."""
        return full[..., self.independent]

    def names(self, digits: int = 4) -> list[str]:
        """Each β as its combination of standard parameters, e.g.
        ``upper_arc.inertia.xx + 0.01038 upper_arc.mass``."""
        names = []
        for row, index in enumerate(self.independent):
            terms = [STANDARD_PARAMETERS[index]]
            for weight, other in zip(self.combination[row], self.dependent, strict=True):
                if abs(weight) > 1e-12:
                    sign = "-" if weight < 0 else "+"
                    terms.append(f"{sign} {abs(weight):.{digits}g} {STANDARD_PARAMETERS[other]}")
            names.append(" ".join(terms))
        return names


def random_states(robot: Robot, samples: int, seed: int = 0) -> tuple[np.ndarray, ...]:
    """q, q̇, q̈ (samples, 2): angles uniform in the joint range, rates and accelerations
    normal (1 rad/s, 5 rad/s²)."""
    rng = np.random.default_rng(seed)
    low, high = robot.joint_range[:, 0], robot.joint_range[:, 1]
    q = rng.uniform(low, high, (samples, 2))
    return q, rng.normal(0.0, 1.0, (samples, 2)), rng.normal(0.0, 5.0, (samples, 2))


def base_parameters(robot: Robot, samples: int = SAMPLES, seed: int = 0) -> BaseParameters:
    """The base parameters of robots with ``robot``'s lengths, gravity and payload."""
    y, _ = regressor(robot, *random_states(robot, samples, seed))
    return base_parameters_of(y.reshape(-1, y.shape[-1]))


def base_parameters_of(stacked: np.ndarray) -> BaseParameters:
    """The base parameters a stacked regressor (rows, 38) shows."""
    norms = np.linalg.norm(stacked, axis=0)
    seen = np.flatnonzero(norms > ZERO_COLUMN * np.max(norms))
    scaled = stacked[:, seen] / norms[seen]
    _, r, pivots = scipy.linalg.qr(scaled, mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(r))
    rank = int(np.sum(diagonal > RANK_TOLERANCE * diagonal[0]))
    base, rest = np.sort(pivots[:rank]), pivots[rank:]
    # Y_d = Y_b K in the unscaled columns: least squares on the (exact) dependence
    combination, *_ = np.linalg.lstsq(stacked[:, seen[base]], stacked[:, seen[rest]], rcond=None)
    combination[np.abs(combination) < COMBINATION_ZERO] = 0.0  # round-off of exact zeros
    order = np.argsort(seen[rest])
    return BaseParameters(
        independent=seen[base],
        dependent=seen[rest][order],
        unseen=np.setdiff1d(np.arange(stacked.shape[1]), seen),
        combination=combination[:, order],
    )
