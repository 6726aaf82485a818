"""The actuator's units and current-torque map against the reference's facts."""

import dataclasses
import math

import numpy as np
import pytest

from spm_opt.model.actuator import ACTUATORS, RPM, CurrentTorqueMap

L54 = ACTUATORS["L54-50-S500-R"]


def test_datasheet_ratings():
    assert L54.continuous_speed_rad_s == pytest.approx(1.4347, abs=1e-4)
    assert L54.continuous_torque_nm == 14.0


def test_position_units():
    """±180,692 pulse = ±180° (Max/Min Position Limit)."""
    assert L54.pulses(math.pi) == 180_692
    assert L54.pulses(-math.pi) == -180_692
    angles = np.linspace(-3.0, 3.0, 101)
    assert np.max(np.abs(L54.angle(L54.pulses(angles)) - angles)) <= math.pi / 361_384


def test_velocity_and_current_units():
    """Velocity Limit default 8000 ≈ 15.9 rpm; 16.11328 mA per current unit."""
    assert L54.rate(8000) / RPM == pytest.approx(15.94, abs=0.01)
    assert L54.velocity_units(L54.continuous_speed_rad_s) == round(13.7 / 0.00199234)
    assert L54.current(100) == pytest.approx(1.611328)
    assert L54.current_units(1.9) == 118


def test_default_current_map_is_the_continuous_ratio_and_odd():
    cmap = L54.current_map
    assert cmap.torque(1.9) == pytest.approx(14.0)
    assert cmap.torque(-0.95) == pytest.approx(-7.0)
    currents = np.linspace(-3, 3, 61)
    np.testing.assert_allclose(cmap.current(cmap.torque(currents)), currents, atol=1e-12)


def test_table_map_with_a_no_load_offset():
    cmap = CurrentTorqueMap(currents_a=(0.0, 0.7, 1.9), torques_nm=(0.0, 0.5, 14.0))
    assert cmap.torque(0.35) == pytest.approx(0.25)
    assert cmap.torque(1.3) == pytest.approx(0.5 + 13.5 * 0.6 / 1.2)
    assert cmap.torque(2.5) == pytest.approx(14.0 + 13.5 / 1.2 * 0.6)  # last piece extended


def test_drive_torque_is_the_load_by_default_and_costs_with_losses():
    """Samples (N, 2): θ1 drives, is driven back, drives backwards; θ2 the same, mirrored."""
    load = np.array([[1.0, -1.0], [-1.0, 1.0], [1.0, -1.0]])
    qd = np.array([[1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]])
    qdd = np.full((3, 2), 2.0)
    np.testing.assert_array_equal(L54.drive_torque(load, qd, qdd), load)
    lossy = dataclasses.replace(L54, gear_efficiency=0.8, rotor_inertia_kg_m2=0.1)
    theta1 = [1.2 / 0.8, -0.8 * 0.8, 1.2 * 0.8]  # τ = load + J q̈, then 1/η or η
    theta2 = [-0.8 / 0.8, 1.2 * 0.8, -0.8 * 0.8]
    np.testing.assert_allclose(lossy.drive_torque(load, qd, qdd), np.stack([theta1, theta2], 1))
    viscous = dataclasses.replace(L54, viscous_friction_nm_s_rad=(0.25, 0.5))
    np.testing.assert_allclose(
        viscous.drive_torque(load, qd, qdd), load + np.array([0.25, 0.5]) * qd
    )
    coulomb = dataclasses.replace(L54, coulomb_friction_nm=(0.1, 0.2))
    np.testing.assert_allclose(
        coulomb.drive_torque(load, qd, qdd), load + np.array([0.1, 0.2]) * np.sign(qd)
    )
