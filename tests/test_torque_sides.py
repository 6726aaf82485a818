"""A period's torque reads split into the side that drives the load and the side it drives
back: the split adds up to the reads' mean, a read near zero goes on its neighbours' side,
and near zero torque the reads' noise no longer biases the joint torque the sides give."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from spm_opt.execution.torque_sides import NEIGHBOURS, side_shares, sides

UNIT_A = 0.01611
"""One Present Current unit, A."""
NM_PER_A = 14.0 / 1.9
"""The L54's current map: 14 N·m at 1.9 A, through zero."""
NOISE_A = 0.008
"""The simulated robot's current noise, A."""


@given(
    arrays(int, st.tuples(st.integers(1, 20), st.just(2)), elements=st.integers(-6, 6)),
)
@settings(max_examples=200)
def test_the_two_sides_add_up_to_the_reads_mean(units):
    currents = units * UNIT_A
    positive, negative = sides(currents * NM_PER_A, side_shares(currents, UNIT_A))
    np.testing.assert_allclose(positive + negative, currents.mean(axis=0) * NM_PER_A, atol=1e-12)


def test_a_read_near_zero_goes_on_the_side_its_neighbours_sum_to():
    rng = np.random.default_rng(3)
    units = rng.integers(-3, 4, size=(10, 2))
    shares = side_shares(units * UNIT_A, UNIT_A)
    for i in range(10):
        for joint in range(2):
            read = units[i, joint]
            reach = min(i, 9 - i, NEIGHBOURS)
            total = sum(units[k, joint] for k in range(i - reach, i + reach + 1) if k != i)
            positive = read > 0 if abs(read) >= 2 or total == 0 else total > 0
            assert shares[i, joint] == positive, (i, joint, read, total)
    # a single read has no neighbours: its own sign
    np.testing.assert_array_equal(side_shares(np.array([[UNIT_A, -UNIT_A]]), UNIT_A), [[1, 0]])


@pytest.mark.parametrize(
    ("swing_nm", "largest_share"),
    [(0.0, 0.4), (0.1, 0.3), (0.33, 0.1)],
)
def test_near_zero_torque_the_reads_noise_biases_the_joint_torque_less(swing_nm, largest_share):
    """Ten reads a period of torques within ±0.05 N·m of zero, swinging by ``swing_nm``
    across the period (as the velocity loop's answer to a goal step does), with the
    simulated robot's noise and rounding; a joint turning forward, η 0.75: the joint
    torque η × positive side + negative side / η, against the truth from the torques
    themselves. Measured (bias by the reads' own signs → by this rule, N·m): no swing
    −0.0058 → −0.0019 (the first and last reads have no neighbours on both sides, and keep
    their own sign), 0.1 N·m −0.0046 → −0.0011, 0.33 N·m −0.0017 → 0.0000."""
    efficiency, periods = 0.75, 20_000
    rng = np.random.default_rng(11)
    centre = rng.uniform(-0.05, 0.05, (periods, 1))
    true_torque = centre + swing_nm * np.linspace(-0.5, 0.5, 10)[None, :]
    true = true_torque / NM_PER_A
    currents = UNIT_A * np.round((true + rng.normal(0.0, NOISE_A, true.shape)) / UNIT_A)
    torque = currents * NM_PER_A
    truth = np.mean(
        np.where(true_torque > 0.0, efficiency * true_torque, true_torque / efficiency), axis=1
    )

    def bias(shares: np.ndarray) -> float:
        positive = np.mean(torque * shares, axis=1)
        negative = np.mean(torque * (1.0 - shares), axis=1)
        return float(np.mean(efficiency * positive + negative / efficiency - truth))

    own = bias((currents > 0.0).astype(float))
    shares = np.stack([side_shares(period[:, None], UNIT_A)[:, 0] for period in currents])
    by_rule = bias(shares)
    assert own < -0.0015
    assert abs(by_rule) <= largest_share * abs(own), (own, by_rule)
