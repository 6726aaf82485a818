"""The NLP's parameters for one problem: every number that is the problem's, not the NLP's
shape (the segments' arcs, the check points' places, the robot, the objective's weights and
scales)."""

from __future__ import annotations

import numpy as np

from spm_opt.model.joint_torque import dynamics_parameters
from spm_opt.model.params import MM
from spm_opt.problem.problem import Problem


def arcs(problem: Problem) -> np.ndarray:
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


def nlp_parameters(
    problem: Problem,
    fractions: np.ndarray,
    weights: list[float],
    scales: np.ndarray,
    with_torque: bool,
) -> np.ndarray:
    """p for one problem: arcs, check fractions (checks, M), dynamics, weights (time,
    energy, jerk) and scales (their values at the initial guess)."""
    return np.concatenate(
        [
            arcs(problem).ravel(),
            fractions.ravel(order="F"),
            # none without the torque rows: an unused input of the mapped interval function
            # swells the generated C of its derivatives (31 against 7 MB for minimum time)
            dynamics_parameters(problem.robot) if with_torque else np.zeros(0),
            weights,
            scales,
        ]
    )
