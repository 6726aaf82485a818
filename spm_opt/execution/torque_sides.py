"""The two sides of a period's torque reads: which reads drive the load, which it drives back.

Where a gear train loses (η < 1), the load gets η τ from a motor that drives it and τ / η
from one it drives back, and the velocity loop's answer to each goal step swings the
torque across zero within a period. The log keeps the period's reads' torques in two
sides, positive and negative (the means of each read's share; the two add up to the reads'
mean), and identification weighs each by its own share of the gear train
(:meth:`spm_opt.identify.samples.Samples.joint_torque`).

A read belongs on the side of its true torque's sign, which its own value, noisy and rounded
to the Present Current unit, tells wrongly near zero: a torque at zero reads +1 unit as often
as −1, and putting each read on the side of its own sign adds (η − 1/η) E[|read|] / 2 to the
joint torque, −0.011 N·m per read at zero with η 0.75 (8 mA of noise, 16.11 mA units), a
bias like Coulomb friction. A read within :data:`OWN_SIGN_UNITS` of zero therefore goes on
the side of its neighbours' sum, whose noise is not its own: as many reads before it as
after it, up to :data:`NEIGHBOURS` (so that a torque swinging through zero across the
period is judged at the read's own instant). A read farther out, one whose neighbours sum
to zero and one with none (the first and the last of a period, a period of a single read)
go by their own sign.

Measured on reads drawn as the simulated robot makes them (8 mA of noise, 16.11 mA units,
ten a period, torques within ±0.05 N·m of zero, η 0.75; ``tests/test_torque_sides.py``),
the bias of the period's joint torque by the reads' own signs and by this rule: −0.0058 and
−0.0019 N·m without a swing, −0.0017 and 0.0000 swinging by 0.33 N·m across the period. On
the tests' family of plants (``tests/test_plant_family.py``'s slow sweep, two batches of 25,
30 s fits, two BLAS threads), against the reads' own signs: the plant's own model predicts
within 1.5 times the noise floor on 25 and 25 plants (25 and 24), 90.1 % and 87.4 % of the
identified parameters lie within two standard errors (85.9 and 85.0 %), and no plant has
one beyond 4 standard errors and 10 % (5 and 1 plants, frictions and η). On the family's
lightest plant (η 0.7, masses 30 % lighter, no joint friction), whose small torques put
many reads near zero, η comes out 0.688 ± 0.003 (0.663 before) and its own model predicts
its log to 0.0046 and 0.0042 N·m (0.0083 and 0.0060).
"""

from __future__ import annotations

import numpy as np

NEIGHBOURS = 2
"""Reads on each side of a read whose sum gives its side."""
OWN_SIGN_UNITS = 1.5
"""A read this many Present Current units from zero or more (two units, as the reads are
whole units) goes by its own sign: the simulated robot's noise, half a unit, flips a read
that far out once in about 700."""


def side_shares(currents_a: np.ndarray, unit_a: float) -> np.ndarray:
    """Each read's share of the positive side (k, joints): 1 or 0 (see the module's
    docstring); ``currents_a`` (k, joints), A, in the order they were read, in whole
    Present Current units of ``unit_a`` (A)."""
    units = np.rint(np.asarray(currents_a, dtype=float) / unit_a)
    count = len(units)
    running = np.concatenate([np.zeros((1, units.shape[1])), np.cumsum(units, axis=0)])
    index = np.arange(count)
    reach = np.minimum(np.minimum(index, count - 1 - index), NEIGHBOURS)
    low, high = index - reach, index + reach + 1
    neighbours = running[high] - running[low] - units
    own = (neighbours == 0.0) | (np.abs(units) >= OWN_SIGN_UNITS)
    return (np.where(own, units, neighbours) > 0.0).astype(float)


def sides(torques_nm: np.ndarray, shares: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The positive and the negative side (each (joints,), N·m): the means over the reads
    of ``torques_nm`` × ``shares`` and of ``torques_nm`` × (1 − ``shares``), each
    (k, joints)."""
    return np.mean(torques_nm * shares, axis=0), np.mean(torques_nm * (1.0 - shares), axis=0)
