"""toppra's time-optimal path speeds along a segment, from rest to rest, within precomputed
constraints (:mod:`spm_opt.planners.toppra.constraints`).

toppra works in σ = s / ℓ, ℓ the largest speed allowed (mm per s), so that σ̇ ≤ 1: with
ṡ² up to 1e4 mm²/s² its LP solver fails on the finest gridpoints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from spm_opt.base.errors import PlanningError
from spm_opt.planners.path import JointPath
from spm_opt.planners.toppra.constraints import Constraints


@cache
def _path_limits_class() -> type:
    """toppra's constraint interface over :class:`Constraints`, built on first use (toppra
    is imported lazily: its algorithm module imports matplotlib)."""
    from toppra.constraint import (
        DiscretizationType,
        LinearConstraint,
        canlinear_colloc_to_interpolate,
    )

    class PathLimits(LinearConstraint):
        """Precomputed coefficients, imposed in toppra's interpolation scheme."""

        def __init__(self, limits: Constraints) -> None:
            super().__init__()
            self.limits = limits
            self.set_discretization_type(DiscretizationType.Interpolation)

        def compute_constraint_params(self, path: Any, gridpoints: np.ndarray) -> tuple:
            k = self.limits
            m = k.a.shape[1]
            f = np.broadcast_to(np.vstack([np.eye(m), -np.eye(m)]), (len(gridpoints), 2 * m, m))
            g = np.hstack([k.high, -k.low])
            a, b, c, f, g, _, _ = canlinear_colloc_to_interpolate(
                k.a, k.b, k.c, f, g, None, None, gridpoints, identical=False
            )
            xbound = np.column_stack([np.zeros_like(k.x_max), k.x_max])
            return a, b, c, f, g, None, xbound  # toppra's order: ..., ubound, xbound

    return PathLimits


@dataclass(frozen=True)
class _Span:
    """All that toppra's algorithm reads of a path whose constraints come precomputed: the
    range of its parameter (a spline through the path would only cost its construction)."""

    path_interval: np.ndarray


def path_speeds(segment: JointPath, s: np.ndarray, limits: Constraints) -> np.ndarray:
    """toppra's time-optimal path speeds ṡ (N,), mm/s, at gridpoints s (N,), mm, from rest
    to rest; a PlanningError naming the place and the likely culprit if it fails (σ = s / ℓ,
    see the module docstring)."""
    import toppra
    from toppra.algorithm import ParameterizationReturnCode

    unit = math.sqrt(float(np.max(limits.x_max)))
    gridpoints = s / unit
    instance = toppra.algorithm.TOPPRA(
        [_path_limits_class()(limits.per_unit(unit))],
        _Span(gridpoints[[0, -1]]),
        gridpoints=gridpoints,
        solver_wrapper="seidel",
    )
    _, speed, _, controllable = instance.compute_parameterization(0.0, 0.0, return_data=True)
    code = instance.problem_data.return_code
    if code == ParameterizationReturnCode.Ok and np.all(np.isfinite(speed)):
        return np.asarray(speed, dtype=float) * unit
    lost = np.flatnonzero(np.any(np.isnan(controllable), axis=1))
    raise PlanningError(_failure(code.value, segment, s, limits, int(lost[-1]) if lost.size else 0))


def _failure(code: str, segment: JointPath, s: np.ndarray, limits: Constraints, where: int) -> str:
    """toppra's failure in words: where on the segment, and the likely culprit."""
    failing = limits.at_rest(where)
    culprit = (
        f"there, gravity and friction alone need {'; '.join(failing)}"
        if failing
        else "no limit fails there at rest: the joint acceleration and actuator torque "
        "limits together leave no path acceleration that keeps the motion going"
    )
    return (
        f"toppra: {code} in segment {segment.name} at {s[where]:.4g} mm of "
        f"{segment.length:.4g} mm; {culprit}"
    )
