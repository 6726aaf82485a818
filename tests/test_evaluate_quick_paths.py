"""The evaluator's quick paths give the values of the straightforward computations they
stand for, to the bit: the trajectory's states together, the platform's directions, rates
and margins from one Jacobian, lengths of 3-vectors, and the angles from directions to the
contour's landmarks."""

import numpy as np
import pytest
from scipy.interpolate import BPoly, PPoly

import spm_opt as so
from spm_opt.cut import contour as contour_module
from spm_opt.cut.contour import direction_rates, row_lengths
from spm_opt.model import kinematics


def random_pieces(kind: type, degree: int, pieces: int, seed: int) -> BPoly | PPoly:
    """Random pieces of ``kind`` and ``degree`` over uneven breakpoints, 2 outputs."""
    rng = np.random.default_rng(seed)
    breaks = np.concatenate([[0.0], np.cumsum(rng.uniform(0.001, 0.5, pieces))])
    return kind(rng.normal(size=(degree + 1, pieces, 2)), breaks)


@pytest.mark.parametrize("samples", [50, 20_001])
@pytest.mark.parametrize("kind, degree", [(BPoly, 5), (BPoly, 3), (PPoly, 3)])
def test_states_are_the_single_evaluations_and_scipys(kind, degree, samples):
    poly = random_pieces(kind, degree, 200, seed=degree)
    trajectory = so.Trajectory(poly)
    end = trajectory.end_time
    t = np.sort(np.concatenate([np.linspace(0.0, end, samples), trajectory.breakpoints[:20]]))
    states = trajectory.states(t)
    singles = (
        trajectory.position(t),
        trajectory.velocity(t),
        trajectory.acceleration(t),
        trajectory.jerk(t),
    )
    for order, (together, alone) in enumerate(zip(states, singles, strict=True)):
        np.testing.assert_array_equal(together, alone)
        np.testing.assert_array_equal(together, poly.derivative(order)(t) if order else poly(t))


def test_motion_directions_are_the_three_functions():
    rng = np.random.default_rng(4)
    q = rng.uniform(-1.2, 1.2, size=(5000, 2))
    qd = rng.normal(size=(5000, 2))
    directions, rates, margins = kinematics.motion_directions(q, qd)
    np.testing.assert_array_equal(directions, kinematics.forward_kinematics(q, 1.0))
    np.testing.assert_array_equal(rates, direction_rates(q, qd))
    np.testing.assert_array_equal(margins, kinematics.singularity_margins(q))


def test_row_lengths_are_numpys_norm():
    vectors = np.random.default_rng(5).normal(size=(100_000, 3)) * 0.07
    np.testing.assert_array_equal(row_lengths(vectors), np.linalg.norm(vectors, axis=1))


def test_angles_to_the_arcs_ends_are_einsums():
    rng = np.random.default_rng(6)
    p = rng.normal(size=(100_000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    ends = rng.normal(size=(5, 3))
    ends /= np.linalg.norm(ends, axis=1, keepdims=True)
    cosine = np.clip(np.einsum("nk,ak->na", p, ends), -1.0, 1.0)
    np.testing.assert_array_equal(contour_module._angles_between(p, ends), np.arccos(cosine))
