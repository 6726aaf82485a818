"""The one Trajectory type: exact evaluation, resampling and the CSV round trip."""

import json

import numpy as np
import pytest
from scipy.interpolate import BPoly

import spm_opt as so
from spm_opt.problem.trajectory import COLUMNS


def test_csv_round_trip_reproduces_the_samples_exactly(tmp_path, baseline):
    path = tmp_path / "plan.csv"
    baseline.to_csv(path)
    first = so.Trajectory.from_csv(path)
    for written, read in zip(baseline.samples(), first.samples(), strict=True):
        np.testing.assert_array_equal(written, read)
    again = tmp_path / "again.csv"
    first.to_csv(again)
    assert again.read_text() == path.read_text()
    assert path.read_text().splitlines()[0] == ",".join(COLUMNS)


def test_read_back_cubic_is_the_same_polynomial_between_samples(tmp_path, baseline):
    """Quintic Hermite pieces through samples of a cubic are that cubic."""
    path = tmp_path / "plan.csv"
    baseline.to_csv(path, rate_hz=2.0)  # few samples: the pieces must carry the shape
    read = so.Trajectory.from_csv(path)
    t = np.linspace(0.0, 40.0, 4001)
    np.testing.assert_allclose(read.position(t), baseline.position(t), atol=1e-12)
    np.testing.assert_allclose(read.velocity(t), baseline.velocity(t), atol=1e-12)
    np.testing.assert_allclose(read.acceleration(t), baseline.acceleration(t), atol=1e-11)


def test_sidecar_records_planner_problem_and_version(tmp_path, baseline, paper_problem):
    path = tmp_path / "plan.csv"
    baseline.to_csv(path)
    sidecar = json.loads(path.with_suffix(".json").read_text())
    assert sidecar["planner"] == "cubic"
    assert sidecar["problem"]["sha256"] == paper_problem.source_sha256
    assert len(sidecar["problem"]["sha256"]) == 64
    assert sidecar["spm_opt_version"] == so.__version__
    assert sidecar["breakpoints_s"] == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert "solve_time_s" in sidecar["statistics"]
    read = so.Trajectory.from_csv(path)
    assert read.metadata["planner"] == "cubic"
    np.testing.assert_array_equal(read.landmark_times, [0.0, 10.0, 20.0, 30.0, 40.0])


def test_time_grid_keeps_every_breakpoint_and_the_end(baseline):
    grid = baseline.time_grid(3.0)
    assert set(baseline.breakpoints) <= set(grid)
    assert grid[0] == 0.0 and grid[-1] == 40.0
    assert np.all(np.diff(grid) > 0)


def test_resample_keeps_the_trajectory(baseline):
    coarse = baseline.resample(5.0)
    t = np.linspace(0, 40, 333)
    np.testing.assert_allclose(coarse.position(t), baseline.position(t), atol=1e-12)
    assert coarse.duration == baseline.duration


def test_outside_the_trajectory_it_holds_still(baseline):
    np.testing.assert_array_equal(baseline.position([-1.0, 41.0]), baseline.position([0.0, 40.0]))
    np.testing.assert_array_equal(baseline.velocity([-1.0, 41.0]), 0.0)


def test_derivatives_agree_with_finite_differences(baseline):
    t = np.linspace(0.5, 39.5, 77)
    t = t[np.min(np.abs(t[:, None] - baseline.breakpoints), axis=1) > 1e-3]  # jerk jumps there
    h = 1e-5
    np.testing.assert_allclose(
        (baseline.position(t + h) - baseline.position(t - h)) / (2 * h),
        baseline.velocity(t),
        atol=1e-9,
    )
    np.testing.assert_allclose(
        (baseline.velocity(t + h) - baseline.velocity(t - h)) / (2 * h),
        baseline.acceleration(t),
        atol=1e-9,
    )


def test_failed_write_leaves_nothing(tmp_path, baseline):
    blocker = tmp_path / "plan.json"
    blocker.mkdir()  # the sidecar's name is taken by a directory: the write must fail
    with pytest.raises(OSError):
        baseline.to_csv(tmp_path / "plan.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json"]


def test_quintic_pieces_are_scipys_hermite_interpolant():
    """The closed-form pieces of from_samples against scipy's BPoly.from_derivatives."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(1e-3, 0.5, size=40))
    q, qd, qdd = rng.normal(size=(3, 40, 2))
    ours = so.Trajectory.from_samples(t, q, qd, qdd)
    scipys = BPoly.from_derivatives(t, np.stack([q, qd, qdd], axis=1))
    grid = np.linspace(t[0], t[-1], 5001)
    np.testing.assert_allclose(ours.position(grid), scipys(grid), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ours.jerk(grid), scipys(grid, 3), rtol=1e-7, atol=1e-6)
