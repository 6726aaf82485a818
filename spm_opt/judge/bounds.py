"""The shortest time the limits allow along the planned contour: a lower bound for any plan
that follows it.

At each point of the contour the cut can go no faster than the tool-speed limit, nor faster
than the speed at which the first joint to reach its speed limit does so: the pace
(time per length) there is at least max(1 / v_tool, max_i |dθ_i/ds| / ω_max). Integrating the
pace along the contour gives a bound at least as tight as both "length over the tool-speed
limit" and "the joint-speed bound integrated along the contour". Accelerations, jerks and
torques only add time, and a plan inside the contour tolerance can save at most the
little that cutting a corner within the tolerance saves.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from spm_opt.problem.problem import SAMPLES_PER_SEGMENT

if TYPE_CHECKING:
    from spm_opt.problem.problem import Problem


def segment_lower_bounds(problem: Problem, samples: int = SAMPLES_PER_SEGMENT) -> np.ndarray:
    """Shortest time, s, for each segment between consecutive landmark visits (segments,);
    at the default sampling, the problem's own :attr:`Problem.segment_lower_bounds`,
    computed once per problem."""
    if samples == SAMPLES_PER_SEGMENT:
        return problem.segment_lower_bounds.copy()
    return sampled_segment_lower_bounds(problem, samples)


def sampled_segment_lower_bounds(problem: Problem, samples: int) -> np.ndarray:
    """Shortest time, s, for each segment (segments,), integrating the pace over ``samples``
    evenly spaced contour points per segment."""
    return problem.sampled_segment_lower_bounds(samples)


def duration_lower_bound(problem: Problem) -> float:
    """Shortest time, s, in which the limits allow the whole cut along the contour."""
    return float(np.sum(segment_lower_bounds(problem)))
