"""The hardware verification of a run with holds and overrides: the plan is compared at the
plan time each sample was commanded at, the holds are reported from the header's events,
and every file is written."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_feed import THREE_HOLDS_TWO_OVERRIDES, holds, scripted_run

from spm_opt.model.params import DEG
from spm_opt.studies.hardware import write_verification
from spm_opt.studies.hardware_comparisons import RunSamples, compare_tracking, holds_from_events

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
FILES = {
    "hardware_verification.json",
    "hardware_verification.md",
    "fig15_tracking.png",
    "fig19_torque_theta1.png",
    "fig20_torque_theta2.png",
    "fig25_motion_capture.png",
    "executed_cut.png",
}


@pytest.fixture(scope="module")
def steered(hardware_problem, hardware_plan, tmp_path_factory):
    """The scripted run with three holds and two overrides, its log, header and samples;
    the plant's true state is saved beside the log (true.npz)."""
    path = tmp_path_factory.mktemp("steered")
    _, table, header, trace = scripted_run(
        hardware_problem, hardware_plan, path, THREE_HOLDS_TWO_OVERRIDES
    )
    np.savez(path / "true.npz", **trace)
    return path, table, header, RunSamples.from_log(hardware_plan, table)


@pytest.fixture(scope="module")
def verification(steered, hardware_problem, hardware_plan):
    """The files write_verification wrote for the steered run, and its summary."""
    path = steered[0]
    out = path / "verification"
    written = write_verification(
        hardware_problem, hardware_plan, path / "run.csv", out, trace_path=path / "true.npz"
    )
    return out, written, json.loads((out / "hardware_verification.json").read_text())


def test_every_file_is_written_and_each_figure_is_a_real_png(verification):
    out, written, summary = verification
    assert {p.name for p in written} == FILES
    assert {p.name for p in out.iterdir()} == FILES
    for path in written:
        if path.suffix == ".png":
            data = path.read_bytes()
            assert data.startswith(PNG_SIGNATURE) and len(data) > 20_000, path.name
    assert summary["run"]["completed"]
    assert summary["executed_cut"]["max_distance_mm"] < 0.1
    report = (out / "hardware_verification.md").read_text()
    assert "## Holds and overrides" in report and "## The executed cut, judged" in report
    measured, true = summary["judged"]["measured"], summary["judged"]["true"]
    assert measured["angles"] == "measured" and true["angles"] == "true"
    assert measured["completed"] and measured["failed_reads_skipped"] == 0


def test_the_holds_section_is_the_headers_events(verification, steered):
    _, table, header, samples = steered
    summary = verification[2]["holds"]
    expected = holds(header["feed_events"])  # the feed tests' own reading of the events
    held = [e for e in header["feed_events"] if e["event"] == "held"]
    start = table.loc[table["phase"] == "plan", "time_s"].iloc[0]
    assert summary["overrides"] == 2
    assert len(summary["each"]) == len(expected) == len(held) == 3
    for got, times, stop in zip(summary["each"], expected, held, strict=True):
        assert got["asked_s"] == pytest.approx(times["asked"] - start)
        assert got["plan_time_s"] == pytest.approx(stop["plan_time_s"])
        assert got["to_held_s"] == pytest.approx(times["held"] - times["asked"])
        assert got["to_rest_s"] == pytest.approx(times["at rest"] - times["asked"])
        assert got["lasted_s"] == pytest.approx(times["resumed"] - times["asked"])
        assert got["resumed"]
    # the figures' shaded stretches begin where the feed reached 0
    begins = [begin for begin, _ in samples.held_intervals()]
    assert begins == pytest.approx([e["time_s"] - start for e in held])


def test_a_hold_the_log_ends_in_lasts_to_the_end_and_one_resumed_early_never_held():
    events = [
        {"time_s": 11.0, "event": "hold", "plan_time_s": 1.0},
        {"time_s": 11.05, "event": "resume", "plan_time_s": 1.04},
        {"time_s": 12.0, "event": "feed 50%", "plan_time_s": 2.0},
        {"time_s": 13.0, "event": "hold", "plan_time_s": 2.5},
        {"time_s": 13.1, "event": "held", "plan_time_s": 2.52},
    ]
    early, last = holds_from_events(events, start_s=10.0, end_s=15.0)
    assert early.to_held_s is None and early.plan_time_s is None and early.resumed
    assert last.asked_s == pytest.approx(3.0) and last.plan_time_s == 2.52
    assert last.to_rest_s is None and not last.resumed
    assert last.lasted_s == pytest.approx(2.0)
    assert holds_from_events([], 0.0, 1.0) == []


def test_the_plan_is_taken_at_the_logged_plan_time_and_feed(steered, hardware_plan):
    _, table, _, samples = steered
    plan = table[(table["phase"] == "plan") & table["position_theta1_rad"].notna()]
    tau = plan["plan_time_s"].to_numpy() + hardware_plan.start_time
    np.testing.assert_array_equal(samples.planned_q, hardware_plan.position(tau))
    goals = plan[["reference_theta1_rad", "reference_theta2_rad"]].to_numpy()
    np.testing.assert_allclose(samples.planned_q, goals, atol=1e-8)
    # the planned rate and acceleration are the commanded stream's (q′ r, q″ r² + q′ ṙ):
    # here within 1 mrad/s and 3 mrad/s² of its differences; without q′ ṙ, 1.9 rad/s² off
    rate = np.gradient(samples.planned_q, samples.t, axis=0)
    np.testing.assert_allclose(samples.planned_qd, rate, atol=0.002)
    acceleration = np.gradient(samples.planned_qd, samples.t, axis=0)
    np.testing.assert_allclose(samples.planned_qdd, acceleration, atol=0.01)
    assert samples.t[0] == 0.0 and samples.t[-1] > hardware_plan.duration + 2.5


def test_the_alignment_by_plan_time_is_what_makes_the_tracking_error_small(steered, hardware_plan):
    samples = steered[3]
    aligned = compare_tracking(samples)
    assert max(aligned.max_error_deg) < 0.5
    # plan time = run time, as before the feed override: off by the holds' delays
    by_run_time = hardware_plan.position(
        np.minimum(samples.t, hardware_plan.duration) + hardware_plan.start_time
    )
    naive = np.max(np.abs(samples.measured_q - by_run_time)) / DEG
    assert naive > 10.0
