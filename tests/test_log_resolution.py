"""How finely a log's readings resolve what the judge measures: each bound against an
error pattern built here that reaches it, and against finite moves of the kinematics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import savgol_coeffs
from test_evaluate_execution import PERIOD, VELOCITY_QUANTUM, meridian_sweep, write_log

import spm_opt as so
from spm_opt.model import kinematics
from spm_opt.model.params import DEG, MM
from spm_opt.verify.executed_cut import evaluate_log
from spm_opt.verify.log_estimates import (
    ACCELERATION_SPAN_S,
    JERK_SPAN_S,
    filter_width,
    log_resolution,
    smoothed_derivatives,
)

PULSE = 2 * np.pi / 361_384  # rad: one L54 encoder pulse


@pytest.mark.parametrize(("order", "span"), [(1, ACCELERATION_SPAN_S), (2, JERK_SPAN_S)])
def test_the_worst_rounding_of_the_velocity_reaches_the_stated_resolution(
    paper_problem, order, span
):
    """Rounding errors of half a unit, each with the sign of its filter weight around one
    sample, move that sample's derivative by exactly the stated bound; no pattern moves
    it further (random ones stay within)."""
    resolution = log_resolution(paper_problem, np.zeros((3, 2)), PERIOD)
    bound = resolution.acceleration_rad_s2 if order == 1 else resolution.jerk_rad_s3
    width = filter_width(span, PERIOD)
    weights = savgol_coeffs(width, 2, deriv=order, delta=PERIOD, use="dot")
    t = np.arange(0.0, 1.0, PERIOD)
    middle = len(t) // 2
    error = np.zeros(len(t))
    error[middle - width // 2 : middle + width // 2 + 1] = 0.5 * VELOCITY_QUANTUM * np.sign(weights)
    derivatives = smoothed_derivatives(t, error[:, None], PERIOD)[order - 1]
    assert derivatives[middle, 0] == pytest.approx(bound, rel=1e-9)
    rng = np.random.default_rng(7)
    noise = rng.uniform(-0.5, 0.5, (len(t), 20)) * VELOCITY_QUANTUM
    assert np.max(np.abs(smoothed_derivatives(t, noise, PERIOD)[order - 1])) <= bound


@settings(max_examples=25, deadline=None)
@given(
    q1=st.floats(-0.5, 0.5),
    q2=st.floats(-0.5, 0.5),
    signs=st.tuples(st.sampled_from([-1, 1]), st.sampled_from([-1, 1])),
)
def test_the_cut_moves_no_more_than_the_resolution_for_half_a_pulse(paper_problem, q1, q2, signs):
    """The cut point on the skull, moved by half a pulse on each joint (finite moves of the
    forward kinematics here, not the Jacobian the bound uses)."""
    q = np.array([[q1, q2]])
    bound = log_resolution(paper_problem, q, PERIOD).cut_mm
    moved = q + 0.5 * PULSE * np.array(signs)
    contour = paper_problem.contour
    points = [contour.cut_points(kinematics.forward_kinematics(x, 1.0)) for x in (q, moved)]
    move = np.linalg.norm(points[1] - points[0]) / MM
    assert move <= bound * (1 + 1e-3)
    assert move >= 0.5 * bound / np.sqrt(2)  # the bound is no loose guess


def test_the_resolution_of_the_readings_is_stated_in_the_report(paper_problem, tmp_path):
    t, q, qd = meridian_sweep()
    report = evaluate_log(
        paper_problem, write_log(tmp_path / "run.csv", paper_problem, t, q, q, velocity=qd)
    ).measured
    resolution = report.resolution
    assert resolution["position_deg"] == pytest.approx(0.5 * PULSE / DEG)
    assert resolution["speed_rad_s"] == pytest.approx(0.5 * VELOCITY_QUANTUM)
    assert resolution["current_a"] == pytest.approx(0.5 * 0.01611328)
    slope = 14.0 / 1.9  # N·m/A: the L54's current map
    assert resolution["torque_nm"] == pytest.approx(0.5 * 0.01611328 * slope)
    assert "Resolution of the readings" in report.to_markdown()
    assert report.not_judged == []


def test_a_limit_finer_than_the_readings_is_not_judged_and_the_report_says_so(
    paper_problem, tmp_path
):
    """A jerk limit of 0.1 rad/s³ (the readings resolve jerk to about 0.2): the measured
    cut does not judge it, and says why; a limit of 1 rad/s³ is judged."""
    t, q, qd = meridian_sweep(duration=2.0)  # a quick quintic: peak jerk 60 · 0.4 / 2³ = 3 rad/s³
    fine = dataclasses.replace(
        paper_problem,
        limits=dataclasses.replace(paper_problem.limits, max_joint_jerk=0.1),
    )
    log = write_log(tmp_path / "run.csv", fine, t, q, q, velocity=qd)
    report = evaluate_log(fine, log).measured
    assert "joint jerk" not in {v.rule for v in report.violations}
    (why,) = report.not_judged
    assert why.startswith("joint jerk: the log resolves it to ±0.2")
    assert "Not judged, joint jerk: the log resolves it" in report.to_markdown()
    coarse = dataclasses.replace(
        paper_problem, limits=dataclasses.replace(paper_problem.limits, max_joint_jerk=1.0)
    )
    log = write_log(tmp_path / "coarse.csv", coarse, t, q, q, velocity=qd)
    assert "joint jerk" in {v.rule for v in evaluate_log(coarse, log).measured.violations}


def test_so_evaluate_of_the_same_log_agrees(paper_problem, tmp_path):
    t, q, qd = meridian_sweep()
    log = write_log(tmp_path / "run.csv", paper_problem, t, q, q, velocity=qd)
    assert (
        so.evaluate(paper_problem, log).to_dict()
        == evaluate_log(paper_problem, log).measured.to_dict()
    )
