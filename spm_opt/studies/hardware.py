"""The paper's hardware verification (Section 6), from an execution log.

Three comparisons, as in the paper:

- torques: the model's actuator torques along the plan against the torques the actuators'
  current gives through the current map (Figs. 19–20), with the RMS of their difference;
  the measured torque is also shown smoothed (a centred moving average), because Present
  Current is quantised in 16.11 mA steps, about 0.12 N·m at the output, the size of the
  torques themselves;
- joint paths: planned against measured (Fig. 15);
- the platform's path seen by motion capture (Figs. 25–26): the marker at the platform's
  centre, tracked in the camera frame, is brought into the manipulator frame through the
  rigid registration of 8 reference landmarks and compared with the planned path (the
  paper's centroid distance, and RMS and maximum closest-point distances). Without cameras
  the capture is synthetic: the measured joint path through the forward kinematics, seen
  from an unknown rigid transform with 0.3–0.6 mm noise.

A run the operator held or overrode (the feed) is compared at what was commanded: the plan
at each row's logged plan time and feed, against run time since the plan phase began; the
figures shade the holds, and the report lists them from the header's feed events. The
executed cut (the measured joints on the skull) is compared with the plan's cut, and
judged by the problem's rules as a plan is (:mod:`spm_opt.verify.executed_cut`): the
measured cut, and, given the plant's true state (a simulated robot's or the emulator's
trace), the true cut.

The comparisons are :mod:`spm_opt.studies.hardware_comparisons`'s, the figures
:mod:`spm_opt.studies.hardware_figures`'s; here they are written with the report.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from spm_opt.base.files import write_atomically
from spm_opt.base.markdown import markdown_table
from spm_opt.execution.log import read_log
from spm_opt.problem.problem import Problem
from spm_opt.problem.trajectory import Trajectory
from spm_opt.report.plots import to_png
from spm_opt.studies.hardware_comparisons import (
    SMOOTHING_S,
    RunSamples,
    capture_run,
    compare_cut,
    compare_motion_capture,
    compare_torques,
    compare_tracking,
    feed_summary,
    holds_from_events,
    override_count,
    verification_summary,
)
from spm_opt.studies.hardware_figures import (
    capture_figure,
    cut_figure,
    torque_figure,
    tracking_figure,
)
from spm_opt.verify.executed_cut import LogReports, evaluate_log


def write_verification(
    problem: Problem,
    trajectory: Trajectory,
    log_path: Path,
    out: Path,
    seed: int = 0,
    trace_path: Path | None = None,
) -> list[Path]:
    """Analyse a run's log (and the plant's true state in ``trace_path``, if given) and
    write the report and figures into ``out`` (all or none).

    Files: ``hardware_verification.md`` and ``.json`` (the three comparisons, the holds
    and overrides, the executed cut's deviation and its judgement), ``fig15_tracking.png``,
    ``fig19_torque_theta1.png``, ``fig20_torque_theta2.png``, ``fig25_motion_capture.png``,
    ``executed_cut.png``.
    """
    judged = evaluate_log(problem, log_path, trace_path)
    log, header = read_log(log_path)
    samples = RunSamples.from_log(trajectory, log)
    capture, landmarks = capture_run(problem, samples, seed)
    mocap, _, tracked = compare_motion_capture(problem, samples, capture, landmarks)
    events = header.get("feed_events", [])
    holds = holds_from_events(events, samples.start_s, float(log["time_s"].iloc[-1]))
    cut = compare_cut(problem, trajectory, samples)
    summary = verification_summary(
        compare_torques(problem, samples), compare_tracking(samples), mocap
    )
    summary.update(feed_summary(holds, override_count(events), cut))
    summary["judged"] = {
        "measured": judged.measured.to_dict(),
        "true": None if judged.true is None else judged.true.to_dict(),
    }
    summary["run"] = {key: header.get(key) for key in ("completed", "reason", "samples", "loop")}
    backend = header.get("backend", {})
    summary["run"]["backend"] = backend.get("backend")
    summary["run"]["plant_robot"] = backend.get("plant_robot")  # the simulated robot's
    files = {
        out / "hardware_verification.json": json.dumps(summary, indent=2) + "\n",
        out / "hardware_verification.md": _markdown(problem, summary)
        + "\n"
        + _judged_markdown(judged),
        out / "fig15_tracking.png": to_png(tracking_figure(samples)),
        out / "fig19_torque_theta1.png": to_png(torque_figure(problem, samples, 0)),
        out / "fig20_torque_theta2.png": to_png(torque_figure(problem, samples, 1)),
        out / "fig25_motion_capture.png": to_png(capture_figure(samples, problem, tracked, mocap)),
        out / "executed_cut.png": to_png(cut_figure(samples, cut, holds)),
    }
    write_atomically(files)
    return list(files)


def _markdown(problem: Problem, summary: dict[str, Any]) -> str:
    run, torques, tracking = summary["run"], summary["torques"], summary["tracking"]
    mocap = summary["motion_capture"]
    loop = run.get("loop") or {}
    lines = [
        f"# Hardware verification: {problem.name}",
        "",
        f"Backend: {run.get('backend')}"
        + (f" (plant: {run['plant_robot']})" if run.get("plant_robot") else "")
        + "; "
        + ("run completed" if run.get("completed") else f"safe stop: {run.get('reason')}")
        + f"; {run.get('samples')} samples at "
        f"{loop.get('achieved_rate_hz', float('nan')):.1f} Hz, period error p99 "
        f"{loop.get('period_error_p99_ms', float('nan')):.3f} ms.",
        "",
    ]
    rows = [
        ("model torque RMS, N·m", torques["model_rms_nm"]),
        ("measured torque RMS, N·m", torques["measured_rms_nm"]),
        ("RMS difference, N·m", torques["difference_rms_nm"]),
        (f"RMS difference, smoothed {SMOOTHING_S:g} s, N·m", torques["smoothed_difference_rms_nm"]),
        ("max tracking error, deg", tracking["max_error_deg"]),
        ("RMS tracking error, deg", tracking["rms_error_deg"]),
    ]
    lines += markdown_table(
        ["figure", "θ1", "θ2"], [[name, f"{a:.4f}", f"{b:.4f}"] for name, (a, b) in rows]
    )
    lines += [
        "",
        "Motion capture (synthetic: unknown rigid transform, noise "
        f"{mocap['noise_std_mm']:.3f} mm): registration RMS {mocap['registration_rms_mm']:.3f} mm "
        "(the paper: 0.587 mm); centroid distance "
        f"{mocap['centroid_distance_mm']:.3f} mm (the paper: 0.731 mm); closest-point distance "
        f"RMS {mocap['rms_distance_mm']:.3f} mm, max {mocap['max_distance_mm']:.3f} mm.",
        "",
        "Executed cut (measured joint angles on the skull): largest distance from the plan's "
        f"cut {summary['executed_cut']['max_distance_mm']:.3f} mm.",
        "",
        *_holds_markdown(summary["holds"]),
    ]
    return "\n".join(lines)


def _holds_markdown(holds: dict[str, Any]) -> list[str]:
    lines = ["## Holds and overrides", ""]
    if not holds["each"] and not holds["overrides"]:
        return [*lines, "No holds or overrides.", ""]
    if holds["each"]:
        lines += [
            "Run time since the plan phase began; durations from the request, s.",
            "",
            *markdown_table(
                [
                    "hold",
                    "asked, s",
                    "stopped at plan time, s",
                    "to feed 0, s",
                    "to rest, s",
                    "lasted, s",
                ],
                [_hold_row(number, hold) for number, hold in enumerate(holds["each"], start=1)],
            ),
            "",
        ]
    return [*lines, f"Overrides: {holds['overrides']}.", ""]


def _hold_row(number: int, hold: dict[str, Any]) -> list[str]:
    def seconds(value: float | None) -> str:
        return "—" if value is None else f"{value:.3f}"

    lasted = seconds(hold["lasted_s"]) + ("" if hold["resumed"] else " (not resumed)")
    return [
        str(number),
        seconds(hold["asked_s"]),
        seconds(hold["plan_time_s"]),
        seconds(hold["to_held_s"]),
        seconds(hold["to_rest_s"]),
        lasted,
    ]


def _judged_markdown(judged: LogReports) -> str:
    """The executed cut judged by the problem's rules: the measured cut's figures beside
    the true cut's (when a trace was given), then each one's violations."""
    reports = {"measured": judged.measured, "true": judged.true}
    reports = {name: report for name, report in reports.items() if report is not None}

    def figure(name: str, value: Any) -> list[str]:
        return [name, *(_format_figure(getattr(r, value)) for r in reports.values())]

    rows = [
        figure("max contour deviation, mm", "max_contour_deviation_mm"),
        figure("RMS contour deviation, mm", "rms_contour_deviation_mm"),
        figure("max landmark error, mm", "max_landmark_error_mm"),
        figure("coverage gap, mm", "coverage_gap_mm"),
        figure("max backtrack, mm", "max_backtrack_mm"),
        figure("max tracking error θ1, θ2, deg", "max_tracking_error_deg"),
        figure("RMS tracking error θ1, θ2, deg", "rms_tracking_error_deg"),
    ]
    for k, visit in enumerate(judged.measured.landmark_errors_mm):
        errors = [f"{r.landmark_errors_mm[k]['error_mm']:.4f}" for r in reports.values()]
        rows.append([f"landmark {visit['landmark']} error, mm", *errors])
    rows.append(["violations", *(str(len(r.violations)) for r in reports.values())])
    lines = [
        "## The executed cut, judged",
        "",
        "By the problem's rules, as a plan is judged (`spm-opt evaluate PROBLEM LOG.csv`), "
        "from the plan's start to the log's end"
        + (
            "; the true cut is the plant's own angles, without the encoder offsets the "
            "measured ones carry."
            if judged.true is not None
            else "."
        ),
        "",
        *markdown_table(["figure", *(f"{name} cut" for name in reports)], rows),
        "",
    ]
    for name, report in reports.items():
        broken = [f"- {v}" for v in report.violations] or ["- none"]
        lines += [f"Violations of the {name} cut:", "", *broken, ""]
    return "\n".join(lines)


def _format_figure(value: Any) -> str:
    if isinstance(value, list):
        return ", ".join(f"{v:.4f}" for v in value)
    return f"{value:.4f}"
