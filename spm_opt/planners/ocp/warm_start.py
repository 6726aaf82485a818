"""The last solve of each plan this process made and still holds: a plan given as another
problem's warm start (a sweep's anchor) hands over its solution and multipliers, not only
its motion, when the NLPs have the same shape. Minimum time on the paper's flap from its
plan at 3 mm/s: 17–27 iterations at 2–3.5 mm/s against 37–53 from scratch, but 88 and 108
at 3.75 and 4 mm/s against 44 and 74."""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from spm_opt.planners.ocp.solve import Solution
from spm_opt.problem.trajectory import Trajectory


@dataclass(frozen=True)
class Solved:
    """A plan's last solve: what a similar problem's solve can continue from.

    Attributes
    ----------
    shape : tuple
        What makes its NLP: segments, settings, torque rows, joint range.
    fractions : ndarray, shape (checks, M)
        Its check points' places.
    demanded : frozenset of str
        The constraints whose on-demand rows its NLP had.
    solution : Solution
    """

    shape: tuple
    fractions: np.ndarray
    demanded: frozenset[str]
    solution: Solution


SOLVED: weakref.WeakKeyDictionary[Trajectory, Solved] = weakref.WeakKeyDictionary()
"""Each plan's :class:`Solved`, for as long as the plan lives."""
