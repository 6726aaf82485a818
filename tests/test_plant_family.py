"""Identification on plants the estimator never saw: a family of plausible plants around
prototype.toml (masses ±30 %, the arcs' mass-centre radii ±15 %, μ 0.05–0.3, viscous
friction 0–0.4 N·m·s/rad, Coulomb 0–0.04 N·m, η 0.7–1, rotor inertia 0–5e-3 kg·m², Kp
20–60 and ωv 60–300 1/s), each run on the simulated robot, identified from its own
excitation log and judged against its truth: the plant's parameters, which the log does not
know."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import spm_opt as so
from spm_opt.base.errors import InputError
from spm_opt.execution import ExecutionSettings
from spm_opt.identify.validate import true_base_parameters
from spm_opt.model.params import load_robot
from spm_opt.model.regressor import BODIES
from spm_opt.studies.identified_plants import (
    NOISE_ROOM,
    PlantIdentification,
    coverage,
    identify_plant,
)
from spm_opt.verify.plant_family import COORDINATES, PlantFamily, PlantRanges

ROOT = Path(__file__).resolve().parents[1]
PRIOR = load_robot(ROOT / "problems" / "robots" / "prototype.toml")
FAMILY = PlantFamily(PRIOR)
IDENTIFICATION = ROOT / "problems" / "identification.toml"
FIT = {"duration_s": 30.0, "periods": 3, "harmonics": 5, "max_iterations": 60}
"""The fit's excitation: 3 periods of 10 s at the actuators' full speed, its design stopped
after 60 IPOPT iterations."""
VALIDATION = {"duration_s": 20.0, "periods": 2, "harmonics": 5, "seed": 7, "max_iterations": 60}
"""Another motion for the validation log."""
RUN = ExecutionSettings(
    rate_hz=100.0, current_reads_per_cycle=10, max_following_error_rad=np.radians(5.0)
)
"""100 Hz, ten current reads a period; a following error of up to 5°: a plant's Kp of 20 1/s
lags the goals led for the prior's 32 by 1.5° at the speed limit."""
SIGMAS = 4.0
"""An identified parameter lies within this many standard errors of its truth, or 10 % of
it, where the plant's own model holds (a normal error passes 4σ once in 16,000); the slow
sweep allows a few frictions beyond (:data:`MAX_MISSING_PLANTS`)."""
GAIN = 3.0
"""The identified robot predicts the validation torques this many times better than the
prior, unless within ``NOISE_ROOM`` times the plant's own model's error."""
COVERAGE = 0.8
"""Least share of identified parameters whose truth lies within two standard errors over a
batch's plants (0.95 for honest errors). Measured with this 30 s fit over the slow sweep's
two batches (CI's two BLAS threads): 90.1 and 87.4 %; 85.9 and 85.0 % while each read's
torque went on the side of its own sign (:mod:`spm_opt.execution.torque_sides`), and 84 of
121 (69 %) over the second batch before each plant step took the gear train's side from its
own power and the log kept the reads' sides. The excitation IPOPT designs differs with the
BLAS threads (93.0 and 88.8 % with one, own signs), and has differed between runs."""
MAX_MISSING_PLANTS = 4
"""Plants of a batch of 25 with an identified parameter beyond :data:`SIGMAS` standard
errors and 10 % of its truth, at most (measured: none; 5 and 1 with the reads' own signs)."""
FRICTIONS = {
    "rail_friction.upper",
    "rail_friction.lower",
    "coulomb_friction.theta1",
    "coulomb_friction.theta2",
    "gear_efficiency",
}
"""The parameters the reads' noise at zero torque biases (measured beyond 4 standard
errors while each read went on the side of its own sign: the upper rail's friction, the
second joint's Coulomb friction, η; on the family's lightest plant η still)."""
points = st.lists(
    st.floats(0.0, 1.0, allow_nan=False), min_size=len(COORDINATES), max_size=len(COORDINATES)
)


@given(point=points)
@settings(max_examples=40, deadline=None, derandomize=True)
def test_every_plant_lies_within_the_ranges_and_is_physical(point):
    plant = FAMILY.plant(point, noise_seed=0)
    ranges, robot = PlantRanges(), plant.robot
    for name in BODIES:
        body, prior = getattr(robot, name), getattr(PRIOR, name)
        scale = body.mass / prior.mass
        assert ranges.mass_scale[0] - 1e-12 <= scale <= ranges.mass_scale[1] + 1e-12
        assert np.allclose(body.inertia, scale * prior.inertia)
        moments = np.linalg.eigvalsh(body.inertia)
        assert moments.min() > 0.0
        assert moments.sum() - 2 * moments.max() >= -1e-12  # the triangle inequality
        radius = body.com_radius / prior.com_radius
        low, high = ranges.com_radius_scale if "arc" in name else (1.0, 1.0)
        assert low - 1e-12 <= radius <= high + 1e-12
    actuator = robot.actuator
    assert 0.7 <= actuator.gear_efficiency <= 1.0
    assert 0.0 <= actuator.rotor_inertia_kg_m2 <= 5e-3
    assert all(0.0 <= f <= 0.4 for f in actuator.viscous_friction_nm_s_rad)
    assert all(0.0 <= f <= 0.04 for f in actuator.coulomb_friction_nm)
    assert 0.05 <= robot.friction.mu <= 0.3
    # the loops asked for, to one unit of the control table's gains
    gain, bandwidth = plant.loops()
    asked = np.array(point)[[COORDINATES.index(f"position_loop_gain.theta{j}") for j in (1, 2)]]
    assert np.all(np.abs(gain - (20.0 + 40.0 * asked)) <= 0.5)
    assert np.all((bandwidth >= 59.0) & (bandwidth <= 301.0))
    # the prior's base parameters hold every plant (the same structure, other values)
    assert np.all(np.isfinite(true_base_parameters(PRIOR, robot)))


def test_a_point_outside_the_cube_or_a_range_upside_down_is_refused():
    with pytest.raises(InputError, match=r"point: expected 17 coordinates in \[0, 1\]"):
        FAMILY.plant([0.5] * 16)
    with pytest.raises(InputError, match=r"point: expected 17 coordinates in \[0, 1\]"):
        FAMILY.plant([0.5] * 16 + [1.5])
    with pytest.raises(InputError, match=r"mu = \(0.3, 0.05\): expected finite 0 <= low <= high"):
        PlantRanges(mu=(0.3, 0.05))
    with pytest.raises(InputError, match=r"gear_efficiency = \(0.7, 1.2\)"):
        PlantRanges(gear_efficiency=(0.7, 1.2))


def test_draws_are_reproducible_and_differ():
    one, again = (FAMILY.draw(np.random.default_rng(5)) for _ in range(2))
    other = FAMILY.draw(np.random.default_rng(6))
    assert np.array_equal(one.point, again.point) and one.settings == again.settings
    assert not np.array_equal(one.point, other.point)


@pytest.fixture(scope="module")
def plans():
    """The problem, its fit excitation and a validation excitation of another seed."""
    problem = so.load_problem(IDENTIFICATION, {"planner.excitation": FIT})
    validation = so.load_problem(IDENTIFICATION, {"planner.excitation": VALIDATION})
    return problem, so.plan(problem, "excitation"), so.plan(validation, "excitation")


def identified(plans, plant, replay: bool = True) -> PlantIdentification:
    """``plant`` identified; with ``replay``, its velocity loops from the log's replay too
    (about 10 s a plant, which the 25-plant sweep leaves out)."""
    problem, excitation, validation = plans
    with tempfile.TemporaryDirectory() as folder:
        return identify_plant(
            problem, plant.robot, plant.settings, excitation, validation, Path(folder), RUN, replay
        )


def misses(result: PlantIdentification) -> list[str]:
    """The identified parameters (η among them) further than :data:`SIGMAS` standard errors
    and 10 % from their truth."""
    ident = result.identification
    far = [
        f"{name}: {value:.4g} against {true:.4g} ± {error:.2g}"
        for name, value, true, error, ok, sigmas in zip(
            ident.names,
            ident.estimate,
            result.truth,
            ident.standard_error,
            ident.identified,
            result.sigmas(),
            strict=True,
        )
        if ok and sigmas > SIGMAS and abs(value - true) > 0.1 * abs(true)
    ]
    if ident.efficiency_identified and result.efficiency_sigmas() > SIGMAS:
        far.append(f"gear_efficiency: {ident.efficiency:.4g} against {result.efficiency:.4g}")
    return far


def check_plant(result: PlantIdentification) -> None:
    """What must hold on every plant: the identified robot predicts the validation torques
    :data:`GAIN` times better than the prior (or within the noise) and each loop estimate
    lies within its share of the plant's or is not carried: Kp 10 %; ωv from the replay
    15 %, for the replay's ωv is what makes the *identified* model's velocities the plant's
    and so takes up that model's errors too (the family's lightest corner, η 0.7 identified
    0.663: 67.3 and 64.4 1/s against 60.1 and 60.4)."""
    room = np.maximum(result.prior_rms / GAIN, NOISE_ROOM * result.plant_rms)
    assert np.all(result.identified_rms <= room), (
        result.prior_rms,
        result.identified_rms,
        result.plant_rms,
    )
    loops = result.loops
    carried = loops.robot(PRIOR).actuator
    for estimate, reasons, truth, share in (
        (carried.position_loop_gain_per_s, loops.gain_reason, result.plant_loops[0], 0.1),
        (
            carried.velocity_loop_bandwidth_per_s,
            loops.bandwidth_reason if loops.replay is None else loops.replay.reason,
            result.plant_loops[1],
            0.1 if loops.replay is None else 0.15,
        ),
    ):
        for joint in range(2):
            if reasons[joint]:  # not identifiable from this log: the prior kept
                continue
            assert abs(estimate[joint] - truth[joint]) <= share * truth[joint], (estimate, truth)


@pytest.mark.xdist_group("real time")  # as the slow sweep below, for the same reason
@given(point=points, seed=st.integers(0, 2**16))
@settings(
    max_examples=2,
    deadline=None,
    derandomize=True,
    phases=[Phase.explicit, Phase.generate],
    suppress_health_check=[HealthCheck.too_slow],
)
def test_a_random_plant_is_identified_within_its_errors_and_predicted_better(plans, point, seed):
    """:func:`check_plant`, and where the plant's own model predicts its torques within the
    noise (``model_holds``), no identified parameter but the frictions the reads' noise at
    zero torque biases (:data:`FRICTIONS`) further than :data:`SIGMAS` standard errors and
    10 % from its truth (a fresh clone's CI saw the second joint's Coulomb friction at
    0.02757 against 0.032 ± 0.001 on the second example). The first example is the
    family's lightest corner (every coordinate 0: η 0.7, masses 30 % lighter, no joint
    friction, μ 0.05), whose small torques put many reads near zero: its own model predicts
    to 0.0046 and 0.0042 N·m, and η comes out 0.688 ± 0.003 (0.0083, 0.0060 and 0.663
    while each read went on the side of its own sign)."""
    result = identified(plans, FAMILY.plant(point, seed))
    check_plant(result)
    if result.model_holds():
        names = {entry.split(":")[0] for entry in misses(result)}
        assert names <= FRICTIONS, misses(result)


BATCH = 6
"""Plants in the slow sweep's batch: the first 6 of the 25 whose numbers are quoted below (15
took 146 s of a 21 min CI run, past its 20; 8 took 19 min 51 s in all on a slower day; 6
pass in 48 s)."""


@pytest.mark.slow
@pytest.mark.xdist_group("real time")  # its fits load both cores (OpenBLAS): the emulator's
# real-time runs beside it stopped on a following error, so it runs where they run, in turn
@pytest.mark.parametrize("batch", range(1))
def test_plants_of_the_family_identified_with_honest_errors(plans, batch):
    """:data:`BATCH` plants a batch (one in CI; 25 plants took 4 min, 6 min on a slower
    day, and CI's whole run reached 21 min; the 25-plant batches are measured below): every one
    passes :func:`check_plant`; on nearly all the plant's own model predicts within the
    noise; over the batch at least :data:`COVERAGE` of the identified parameters' truths lie
    within two standard errors; and the identified parameters further than
    :data:`SIGMAS` standard errors and 10 % from their truth are few, and frictions: what
    the reads' noise at zero torque leaves, a bias like Coulomb friction. Measured, CI's
    two BLAS threads: the model held on 25 and 25 plants; 163 of 181 and 153 of 175
    identified within two standard errors (90.1 and 87.4 %); none beyond 4 standard errors
    and 10 % (while each read went on the side of its own sign: 24 of 25 held once, 85.9
    and 85.0 %, the upper rail's or the second joint's Coulomb friction beyond on 5 and 1
    plants, η on 0 and 1)."""
    rng = np.random.default_rng(1000 + batch)
    results = [identified(plans, FAMILY.draw(rng), replay=False) for _ in range(BATCH)]
    for result in results:
        check_plant(result)
    holds = sum(result.model_holds() for result in results)
    assert holds >= BATCH - 1, [r.plant_rms for r in results]
    within, counted = coverage(results, identified_only=True)
    assert counted >= BATCH and within >= COVERAGE * counted, (within, counted)
    missed = [misses(result) for result in results]
    assert sum(bool(m) for m in missed) <= MAX_MISSING_PLANTS, missed
    names = {entry.split(":")[0] for m in missed for entry in m}
    assert names <= FRICTIONS, names
